"""Validated access to the datasets of one open HDF5 file (shared by holoprobe's readers).

:class:`HDF5Reader` is the one reader behind every holoprobe HDF5 format (native
measurements, packaged impulse responses, ``virtual_transducer.h5``). Each
accessor checks what it reads (presence, node type, ``units`` attribute, shape,
dtype, finiteness) and raises :class:`~holoprobe.errors.InputError` naming the
file and the dataset.
"""

from __future__ import annotations

from typing import Any

import h5py
import numpy as np
from numpy.typing import DTypeLike, NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import ArrayGeometry

__all__ = ["HDF5Reader"]

_TEXT_KINDS = ("O", "S", "U")


def _decode(value: Any) -> Any:
    return value.decode("utf-8") if isinstance(value, bytes) else value


class HDF5Reader:
    """Validating accessors on an open HDF5 file; every error names file and dataset.

    Parameters
    ----------
    f : h5py.File
        The open file (read access is enough).
    file : str
        The file's name as the user gave it; put into every error.
    """

    def __init__(self, f: h5py.File, file: str):
        self.f = f
        self.file = file

    def error(self, message: str, name: str | None) -> InputError:
        """An :class:`InputError` naming this file and the dataset ``name``."""
        return InputError(message, file=self.file, field=name)

    def node(self, name: str, *, group: bool = False) -> Any:
        """The dataset (with ``group=True``: the group) at ``name``; missing or wrong type raise."""
        if name not in self.f:
            what = "group" if group else "dataset"
            raise self.error(f"missing {what}", name)
        obj = self.f[name]
        if group and not isinstance(obj, h5py.Group):
            raise self.error("expected a group", name)
        if not group and not isinstance(obj, h5py.Dataset):
            raise self.error("expected a dataset", name)
        return obj

    def units(self, ds: h5py.Dataset, name: str, expected: str | tuple[str, ...] | None) -> str:
        """The ``units`` attribute of ``ds``, checked against ``expected``.

        ``expected`` is one unit, a tuple of allowed units, or None (any unit,
        but the attribute must be there).
        """
        units = _decode(ds.attrs.get("units"))
        if units is None:
            raise self.error("missing attribute 'units'", name)
        if isinstance(expected, str) and units != expected:
            raise self.error(f"expected units {expected!r}, got {units!r}", name)
        if isinstance(expected, tuple) and units not in expected:
            raise self.error(f"expected units in {expected}, got {units!r}", name)
        return str(units)

    def array(self, name: str, *, units: str | tuple[str, ...] | None, ndim: int,
              shape: tuple[int | None, ...] | None = None, allow_inf: bool = False,
              dtype: DTypeLike | None = None) -> NDArray:
        """A real numeric dataset with ``ndim`` dimensions, free of NaN (and of inf).

        Parameters
        ----------
        name : str
            Dataset path, e.g. ``"/pose/theta"``.
        units : str, tuple of str or None
            Allowed ``units`` attribute (see :meth:`units`).
        ndim : int
            Required number of dimensions.
        shape : tuple of (int or None), optional
            Required shape; None entries match any length.
        allow_inf : bool
            Accept ±inf (NaN is always rejected).
        dtype : dtype, optional
            Convert to this dtype; default: keep the stored dtype.

        Returns
        -------
        numpy.ndarray
            C-contiguous (a 0-D array for ``ndim=0``).
        """
        ds = self.node(name)
        self.units(ds, name, units)
        if ds.ndim != ndim:
            raise self.error(f"expected a {ndim}-D array, got shape {ds.shape}", name)
        if shape is not None and any(
                s is not None and s != n for s, n in zip(shape, ds.shape, strict=True)):
            want = tuple("any" if s is None else s for s in shape)
            raise self.error(f"expected shape {want}, got {ds.shape}", name)
        if not (np.issubdtype(ds.dtype, np.integer) or np.issubdtype(ds.dtype, np.floating)):
            raise self.error(f"expected real numbers, got dtype {ds.dtype}", name)
        arr = ds[()]
        bad = np.isnan(arr) if allow_inf else ~np.isfinite(arr)
        if np.issubdtype(arr.dtype, np.floating) and np.any(bad):
            idx = tuple(int(i) for i in np.argwhere(bad)[0])
            raise self.error(f"contains NaN{'' if allow_inf else ' or inf'} (first at index "
                             f"{idx})", name)
        if dtype is not None:
            arr = np.asarray(arr, dtype=dtype)
        return np.ascontiguousarray(arr) if arr.ndim else np.asarray(arr)

    def complex_array(self, name: str, *, units: str | tuple[str, ...] | None,
                      shape: tuple[int | None, ...]) -> NDArray[np.complex128]:
        """A finite real or complex dataset of the given shape (None: any length), as complex."""
        ds = self.node(name)
        self.units(ds, name, units)
        if len(ds.shape) != len(shape) or any(
                s is not None and s != n for s, n in zip(shape, ds.shape, strict=True)):
            want = tuple("any" if s is None else s for s in shape)
            raise self.error(f"expected shape {want}, got {ds.shape}", name)
        if ds.dtype.kind not in "fc":
            raise self.error(f"expected complex numbers, got dtype {ds.dtype}", name)
        arr = np.asarray(ds[()], dtype=complex)
        if not np.all(np.isfinite(arr)):
            idx = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
            raise self.error(f"contains NaN or inf (first at index {idx})", name)
        return arr

    def scalar(self, name: str, *, units: str | tuple[str, ...] | None, positive: bool = False,
               allow_inf: bool = False, integer: bool = False) -> float | int:
        """A 0-D real dataset as a float (or, with ``integer=True``, an int).

        ``positive`` requires a value > 0; ``allow_inf`` accepts ±inf; an
        ``integer`` may be stored as an integral float.
        """
        arr = self.array(name, units=units, ndim=0, allow_inf=allow_inf)
        value = arr[()]
        if integer:
            if not np.issubdtype(arr.dtype, np.integer) and float(value) != int(value):
                raise self.error(f"expected an integer, got {value!r}", name)
            return int(value)
        number = float(value)
        if positive and not number > 0:
            raise self.error(f"expected a positive number, got {number!r}", name)
        return number

    def integer(self, name: str, *, units: str | tuple[str, ...] | None = "1") -> int:
        """A 0-D integer dataset (an integral float is accepted) with the given ``units``."""
        return int(self.scalar(name, units=units, integer=True))

    def attr_str(self, obj: Any, key: str, name: str, *, default: str | None = None) -> str:
        """The string attribute ``key`` of ``obj`` (``default`` when absent, else an error)."""
        value = _decode(obj.attrs.get(key, default))
        if value is None:
            raise self.error(f"missing attribute {key!r}", name)
        if not isinstance(value, str):
            raise self.error(f"attribute {key!r}: expected a string, got {value!r}", name)
        return value

    def text(self, name: str, *, default: str | None = None) -> str:
        """A scalar text dataset (``default`` when absent, else an error)."""
        if default is not None and name not in self.f:
            return default
        ds = self.node(name)
        if ds.shape != () or ds.dtype.kind not in _TEXT_KINDS:
            raise self.error("expected a text scalar", name)
        return str(_decode(ds[()]))

    def texts(self, name: str) -> list[str]:
        """A 1-D text dataset as a list of str."""
        ds = self.node(name)
        if ds.ndim != 1 or ds.dtype.kind not in _TEXT_KINDS:
            raise self.error("expected a 1-D array of text", name)
        return [str(_decode(v)) for v in ds[()]]

    def floats(self, name: str) -> dict[str, float]:
        """A group of scalar numeric datasets as ``{key: value}`` (no units required)."""
        group = self.node(name, group=True)
        out: dict[str, float] = {}
        for key, ds in group.items():
            full = f"{name}/{key}"
            if not isinstance(ds, h5py.Dataset) or ds.shape != () or not (
                    np.issubdtype(ds.dtype, np.integer) or np.issubdtype(ds.dtype, np.floating)):
                raise self.error("expected a scalar number", full)
            out[key] = float(ds[()])
        return out

    def array_geometry(self, prefix: str) -> ArrayGeometry:
        """An :class:`ArrayGeometry` from the group ``prefix`` (see ``_write_array``)."""
        g = self.node(prefix, group=True)
        pos = self.array(f"{prefix}/positions", units="m", ndim=2, shape=(None, 3))
        n = pos.shape[0]
        values: dict[str, Any] = {
            "positions": pos,
            "normals": self.array(f"{prefix}/normals", units="1", ndim=2, shape=(n, 3)),
            "width_directions": self.array(f"{prefix}/width_directions", units="1", ndim=2,
                                           shape=(n, 3)),
            "widths": self.array(f"{prefix}/widths", units="m", ndim=1, shape=(n,)),
            "heights": self.array(f"{prefix}/heights", units="m", ndim=1, shape=(n,)),
            "kind": self.attr_str(g, "kind", prefix),
        }
        if "radius_of_curvature" in g:
            values["radius_of_curvature"] = self.scalar(f"{prefix}/radius_of_curvature",
                                                        units="m", positive=True)
        if "pitch" in g:
            values["pitch"] = tuple(self.array(f"{prefix}/pitch", units="m", ndim=1,
                                               shape=(2,)))
        if "grid_shape" in g:
            values["grid_shape"] = tuple(int(v) for v in self.array(
                f"{prefix}/grid_shape", units="1", ndim=1, shape=(2,)))
        if "grid_position" in g:
            values["grid_position"] = self.array(f"{prefix}/grid_position", units="1",
                                                 ndim=2, shape=(n, 2), dtype=np.int64)
        try:
            return ArrayGeometry(**values)
        except InputError as exc:
            raise self.error(exc.detail, f"{prefix}/{exc.field}" if exc.field else prefix
                             ) from None
