"""Figures of a hologram characterization: focal profiles and the aligned geometry.

Plain NumPy inputs in SI units; positions shown in mm, pressures in MPa.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import ArrayLike

__all__ = ["plot_aligned_geometry", "plot_focal_profiles", "plot_focal_volume"]

_MM = 1e3


def plot_focal_profiles(axial_coordinate: ArrayLike, axial: ArrayLike,
                        transverse_coordinate: ArrayLike, transverse_e1: ArrayLike,
                        transverse_e2: ArrayLike, *, axial_length: float,
                        widths: tuple[float, float]) -> Figure:
    """Axial and transverse pressure-amplitude profiles through the focus.

    Parameters
    ----------
    axial_coordinate, axial : array_like, shape (n,)
        Distance from the focus along the axis (m) and |p| (Pa).
    transverse_coordinate, transverse_e1, transverse_e2 : array_like, shape (m,)
        Distance from the focus across the axis (m) and |p| along e1, e2 (Pa).
    axial_length, widths : float, (float, float)
        −6 dB extents (m), shown in the caption and the legend.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig = Figure(figsize=(9.0, 3.4))
    a1, a2 = fig.subplots(1, 2)
    a1.plot(np.asarray(axial_coordinate) * _MM, np.asarray(axial) * 1e-6)
    a1.set_xlabel("distance from the focus along the axis (mm)")
    a1.set_ylabel("|p| (MPa)")
    a1.set_title(f"axial, −6 dB length {axial_length * _MM:.3g} mm")
    s = np.asarray(transverse_coordinate) * _MM
    a2.plot(s, np.asarray(transverse_e1) * 1e-6, label=f"e1, −6 dB {widths[0] * _MM:.3g} mm")
    a2.plot(s, np.asarray(transverse_e2) * 1e-6, "--",
            label=f"e2, −6 dB {widths[1] * _MM:.3g} mm")
    a2.set_xlabel("distance from the focus across the axis (mm)")
    a2.set_ylabel("|p| (MPa)")
    a2.legend(fontsize=8)
    fig.tight_layout()
    # (type: ignore below) the caption travels with the Figure to the report
    fig._holoprobe_caption = (  # type: ignore[attr-defined]
        f"Axial and transverse profiles through the focus: −6 dB length "
        f"{axial_length * _MM:.4g} mm, widths {widths[0] * _MM:.4g} × {widths[1] * _MM:.4g} mm.")
    return fig


def plot_focal_volume(axes: tuple[ArrayLike, ArrayLike, ArrayLike], volume: ArrayLike, *,
                      dynamic_range_db: float = 30.0) -> Figure:
    """Three orthogonal slices through the focus of the 3-D focal field, |p| in dB.

    Parameters
    ----------
    axes : (array_like, array_like, array_like)
        Distances from the focus (m) along e1, e2 and the axis, shapes (n1,), (n2,), (n3,).
    volume : array_like, complex, shape (n1, n2, n3)
        Pressure in Pa on that grid.
    dynamic_range_db : float
        Colour range below the peak.

    Returns
    -------
    matplotlib.figure.Figure
    """
    a1, a2, a3 = (np.asarray(a, float) * _MM for a in axes)
    amp = np.abs(np.asarray(volume))
    peak = float(amp.max()) if amp.size else 1.0
    db = 20 * np.log10(np.maximum(amp / (peak or 1.0), 10 ** (-dynamic_range_db / 20)))
    i, j, k = (n // 2 for n in amp.shape)
    fig = Figure(figsize=(11.0, 3.6))
    panels = fig.subplots(1, 3)
    views = ((db[:, :, k].T, a1, a2, "e1 (mm)", "e2 (mm)", "focal plane"),
             (db[:, j, :].T, a1, a3, "e1 (mm)", "along the axis (mm)", "e1–axis plane"),
             (db[i, :, :].T, a2, a3, "e2 (mm)", "along the axis (mm)", "e2–axis plane"))
    images = []
    for ax, (img, x, y, xl, yl, title) in zip(panels, views, strict=True):
        images.append(ax.pcolormesh(x, y, img, shading="nearest", vmin=-dynamic_range_db,
                                    vmax=0, cmap="viridis"))
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.set_title(title, fontsize=9)
    cbar = fig.colorbar(images[-1], ax=list(panels))
    cbar.set_label("|p| re peak (dB)")
    # (type: ignore below) the caption travels with the Figure to the report
    fig._holoprobe_caption = (  # type: ignore[attr-defined]
        f"3-D focal field (focal_volume.h5): slices through the focus, peak "
        f"{peak * 1e-6:.4g} MPa, {dynamic_range_db:.0f} dB range.")
    return fig


def plot_aligned_geometry(scan_x: ArrayLike, scan_y: ArrayLike, surface_points: ArrayLike,
                          axis: ArrayLike, apex: ArrayLike,
                          focus: ArrayLike | None = None) -> Figure:
    """Side views (x–z and y–z, scan coordinates) of the scan plane and the aligned source.

    Parameters
    ----------
    scan_x, scan_y : array_like
        Scan grid axes (m); the plane is z = 0.
    surface_points : array_like, shape (n, 3)
        Source surface points (m).
    axis, apex : array_like, shape (3,)
        Acoustic axis (unit) and the source apex (m).
    focus : array_like, shape (3,), optional
        Focal maximum (m).

    Returns
    -------
    matplotlib.figure.Figure
    """
    pts = np.asarray(surface_points) * _MM
    axis = np.asarray(axis, float)
    apex = np.asarray(apex, float)
    focus = None if focus is None else np.asarray(focus, float)
    end = apex + axis * (abs(apex[2]) * 2 + (0 if focus is None else abs(focus[2])))
    fig = Figure(figsize=(9.0, 3.6))
    for ax, (i, name, grid) in zip(fig.subplots(1, 2), ((0, "x", scan_x), (1, "y", scan_y)),
                                   strict=True):
        g = np.asarray(grid) * _MM
        ax.plot([g.min(), g.max()], [0, 0], "k-", lw=3, label="scan plane")
        step = max(pts.shape[0] // 3000, 1)
        ax.plot(pts[::step, i], pts[::step, 2], ".", ms=1, color="tab:blue", label="source")
        ax.plot([apex[i] * _MM, end[i] * _MM], [apex[2] * _MM, end[2] * _MM], "r--",
                label="axis")
        if focus is not None:
            ax.plot(focus[i] * _MM, focus[2] * _MM, "r*", ms=10, label="focus")
        ax.set_xlabel(f"{name} (mm)")
        ax.set_ylabel("z (mm)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=7)
    fig.tight_layout()
    tilt = np.degrees(np.arccos(min(abs(axis[2]), 1.0)))
    # (type: ignore below) the caption travels with the Figure to the report
    fig._holoprobe_caption = (  # type: ignore[attr-defined]
        f"Aligned geometry in scan coordinates: apex at ({apex[0] * _MM:.3f}, "
        f"{apex[1] * _MM:.3f}, {apex[2] * _MM:.3f}) mm, axis tilted {tilt:.3f}° from the "
        "scan normal.")
    return fig
