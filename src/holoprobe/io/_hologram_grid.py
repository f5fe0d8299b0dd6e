"""Scan grids as users store them: axis vectors, meshgrid matrices or node lists.

One routine turns the ``xGrid``/``yGrid`` of a hologram file and the shape of its
data into increasing, uniform x and y axes (m) and the index map that puts the data
into holoprobe's (nx, ny, ...) order. Positions are always the grid's values: a
decreasing or shuffled axis reorders the data, never relabels it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from holoprobe.errors import InputError

__all__ = ["GridLayout", "resolve_grid"]


@dataclass(frozen=True)
class GridLayout:
    """Where each point of the file's data goes on the uniform grid.

    Attributes
    ----------
    x, y : ndarray
        Uniform, increasing axes in m (least-squares fit of the file's positions).
    order : ndarray of int, shape (nx, ny)
        ``data_points.reshape(-1, ...)[order]`` is the data in (nx, ny, ...) order,
        where ``data_points`` is the data with its point dimensions flattened in C order
        after the transpose ``transpose``.
    transpose : bool
        Swap the first two dimensions of matrix-shaped data before flattening.
    point_dims : int
        Number of leading data dimensions that index points (2: matrix, 1: node list).
    flattened : {"x", "y"} or None
        Data of nx·ny points on axis vectors: the index that runs fastest (None: the
        data are not flattened that way).
    """

    x: NDArray[np.float64]
    y: NDArray[np.float64]
    order: NDArray[np.int64]
    transpose: bool
    point_dims: int
    flattened: str | None = None

    def apply(self, data: NDArray) -> NDArray:
        """Data of the file → (nx, ny, ...) in increasing x and y."""
        if self.transpose:
            data = np.swapaxes(data, 0, 1)
        flat = data.reshape((-1, *data.shape[self.point_dims:]))
        return np.ascontiguousarray(flat[self.order])


class _Err:
    def __init__(self, file: str, xname: str, yname: str, dname: str):
        self.file, self.xname, self.yname, self.dname = file, xname, yname, dname

    def __call__(self, message: str, field: str) -> InputError:
        return InputError(message, file=self.file, field=field)


def _uniform(values: NDArray, name: str, tol: float, err: _Err) -> tuple[NDArray, NDArray]:
    """Increasing uniform axis through sorted ``values`` and the sort order."""
    order = np.argsort(values, kind="stable")
    v = values[order]
    n = v.size
    if n < 2:
        raise err(f"a hologram needs at least 2 distinct positions along each axis, got {n}",
                  name)
    i = np.arange(n)
    step, start = np.polyfit(i, v, 1)
    resid = np.abs(v - (start + step * i))
    if step <= 0 or np.max(resid) > tol * step:
        gaps = np.diff(v)
        raise err(f"grid is not uniform: steps range from {gaps.min() * 1e3:.4g} to "
                  f"{gaps.max() * 1e3:.4g} mm (positions deviate up to "
                  f"{np.max(resid) / max(step, 1e-300):.2g} steps from a uniform grid; "
                  f"tolerance {tol:g})", name)
    return start + step * i, order


def _matrix_axes(xg: NDArray, yg: NDArray, tol: float, err: _Err
                 ) -> tuple[NDArray, NDArray, bool]:
    """Axis values of meshgrid/ndgrid matrices and whether x runs along dimension 1."""
    def spread(a: NDArray, axis: int) -> float:
        return float(np.max(np.ptp(a, axis=axis))) if a.shape[axis] > 1 else 0.0
    x_along_1 = spread(xg, 1) >= spread(xg, 0)
    ax_x = 1 if x_along_1 else 0
    ax_y = 1 - ax_x
    x_line, y_line = xg.mean(axis=ax_y), yg.mean(axis=ax_x)
    for line, mat, across, name, what in ((x_line, xg, ax_y, err.xname, "x"),
                                          (y_line, yg, ax_x, err.yname, "y")):
        step = np.ptp(line) / max(line.size - 1, 1)
        if step <= 0 or spread(mat, across) > tol * step:
            raise err(f"is not a Cartesian grid of shape {mat.shape}: {what} varies along both "
                      "dimensions (a rotated grid? resample it onto x/y axes)", name)
    return x_line, y_line, x_along_1


def _node_axes(xg: NDArray, yg: NDArray, tol: float, err: _Err
               ) -> tuple[NDArray, NDArray, NDArray]:
    """Axes and index map of a node list (one x, y per point)."""
    def cluster(v: NDArray, name: str) -> tuple[NDArray, NDArray]:
        s = np.sort(v)
        gaps = np.diff(s)
        big = gaps.max() if gaps.size else 0.0
        if big <= 0:
            raise err("all positions are equal: a hologram needs a 2-D grid", name)
        edges = gaps > 0.5 * big
        labels_sorted = np.concatenate([[0], np.cumsum(edges)])
        centres = np.array([s[labels_sorted == k].mean() for k in range(labels_sorted[-1] + 1)])
        labels = np.searchsorted((centres[1:] + centres[:-1]) / 2, v)
        return centres, labels
    xc, xi = cluster(xg, err.xname)
    yc, yi = cluster(yg, err.yname)
    x, _ = _uniform(xc, err.xname, tol, err)
    y, _ = _uniform(yc, err.yname, tol, err)
    for vals, axis, lab, name in ((xg, x, xi, err.xname), (yg, y, yi, err.yname)):
        dev = np.max(np.abs(vals - axis[lab]))
        if dev > tol * (axis[1] - axis[0]):
            raise err(f"grid is not uniform: a node lies {dev * 1e3:.3g} mm from its grid "
                      f"line (tolerance {tol:g} steps)", name)
    order = np.full((x.size, y.size), -1, dtype=np.int64)
    order[xi, yi] = np.arange(xg.size)
    counts = np.zeros((x.size, y.size), dtype=np.int64)
    np.add.at(counts, (xi, yi), 1)
    if np.any(counts != 1):
        missing, twice = int(np.sum(counts == 0)), int(np.sum(counts > 1))
        raise err(f"the {xg.size} nodes do not fill a {x.size} × {y.size} grid once each "
                  f"({missing} nodes missing, {twice} repeated)", err.xname)
    return x, y, order


def resolve_grid(xgrid: NDArray, ygrid: NDArray, data_shape: tuple[int, ...],
                 point_dims_hint: int, *, file: str, xname: str, yname: str, dname: str,
                 tolerance: float = 0.01, flattened_order: str = "x") -> GridLayout:
    """Match a file's grid to its data; return uniform axes and the reordering.

    Parameters
    ----------
    xgrid, ygrid : ndarray
        The file's grid: axis vectors (lengths nx, ny), meshgrid/ndgrid matrices of
        the data's first two dimensions, or node lists (one position per point). Data
        with one point dimension of nx·ny points on axis vectors are flattened with
        ``flattened_order`` running fastest.
    data_shape : tuple of int
        Shape of the data (after the reader squeezed singleton dimensions).
    point_dims_hint : int
        Number of trailing non-point dimensions (0 for CW, 1 for waveforms).
    file, xname, yname, dname : str
        Names for errors (``"HologramSf.xGrid"`` ...).
    tolerance : float
        Largest deviation of a position from a uniform grid, in steps.
    flattened_order : {"x", "y"}
        Flattened points on axis vectors: "x" fastest (MATLAB's ``reshape(p, [], nt)``
        of an [nx, ny, nt] array: point ``ix + nx·iy``) or "y" fastest (of a
        meshgrid-shaped [ny, nx, nt] array: point ``iy + ny·ix``).

    Raises
    ------
    InputError
        When the grid and the data cannot be matched, whichever way round, or the
        grid is not uniform and Cartesian.
    """
    err = _Err(file, xname, yname, dname)
    xg, yg = np.asarray(xgrid, float), np.asarray(ygrid, float)
    point_dims = len(data_shape) - point_dims_hint
    pts = tuple(data_shape[:point_dims])
    if xg.ndim == 2 and yg.ndim == 2:
        if xg.shape != yg.shape or xg.shape != pts:
            raise err(f"meshgrid matrices of shape {xg.shape} (x) and {yg.shape} (y) do not "
                      f"match {dname} of shape {tuple(data_shape)}", xname)
        x_line, y_line, x_along_1 = _matrix_axes(xg, yg, tolerance, err)
        transpose = x_along_1
    elif xg.ndim == 1 and yg.ndim == 1 and point_dims == 2:
        if pts == (xg.size, yg.size):
            transpose = False
        elif pts == (yg.size, xg.size):
            transpose = True
        else:
            raise err(f"{xg.size} x and {yg.size} y positions do not match {dname} of shape "
                      f"{tuple(data_shape)}: expected ({xg.size}, {yg.size}) or "
                      f"({yg.size}, {xg.size}) points", xname)
        x_line, y_line = xg, yg
    elif xg.ndim == 1 and yg.ndim == 1 and point_dims == 1:
        if xg.size == yg.size == pts[0]:
            x, y, order = _node_axes(xg, yg, tolerance, err)
            return GridLayout(x, y, order, False, 1)
        if xg.size * yg.size == pts[0]:   # axis vectors, points flattened
            if flattened_order not in ("x", "y"):
                raise InputError(f"expected 'x' or 'y', got {flattened_order!r}",
                                 field="flattened_order")
            x, ox = _uniform(xg, xname, tolerance, err)
            y, oy = _uniform(yg, yname, tolerance, err)
            order = (ox[:, None] + xg.size * oy[None, :] if flattened_order == "x"
                     else oy[None, :] + yg.size * ox[:, None]).astype(np.int64)
            return GridLayout(x, y, order, False, 1, flattened_order)
        raise err(f"{xg.size} x and {yg.size} y positions do not match the {pts[0]} points "
                  f"of {dname} (shape {tuple(data_shape)}): expected node lists of "
                  f"{pts[0]} positions each or axis vectors with nx × ny = {pts[0]}", xname)
    else:
        raise err(f"cannot match a grid of shapes {xg.shape} (x), {yg.shape} (y) to {dname} of "
                  f"shape {tuple(data_shape)}", xname)
    x, ox = _uniform(x_line, xname, tolerance, err)
    y, oy = _uniform(y_line, yname, tolerance, err)
    ny_file = pts[0] if transpose else pts[1]
    order = (ox[:, None] * ny_file + oy[None, :]).astype(np.int64)
    return GridLayout(x, y, order, transpose, 2)
