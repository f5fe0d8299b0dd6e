"""MATLAB .mat files: read v5 and v7.3 into nested dicts, write either version.

MATLAB v5 files are read with :func:`scipy.io.loadmat` (``mat_dtype=True`` so
that whole-number doubles, which MATLAB stores as uint8, come back as
doubles; ``simplify_cells=True`` so that structs become dicts). v7.3 files are
HDF5 (signature at byte 512) and are read with :mod:`pymatreader`. Writing uses
:func:`scipy.io.savemat` (v5) or :mod:`hdf5storage` (v7.3, MATLAB-compatible,
uncompressed). The accessors below validate values and name the file and the
MATLAB field (``Grid.dx``) in every error.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from holoprobe.errors import InputError
from holoprobe.io._atomic import atomic_write

__all__ = ["MatStruct", "load_mat", "mat_variable_names", "save_mat"]

_MAT_VERSIONS = ("5", "7.3")


def load_mat(path: str | os.PathLike, *, variable_names: list[str] | None = None,
             mat_dtype: bool = True) -> dict[str, Any]:
    """Read a MATLAB v5 or v7.3 file into a dict of NumPy arrays and nested dicts.

    Parameters
    ----------
    path : str or PathLike
        The .mat file.
    variable_names : list of str, optional
        Read only these variables.
    mat_dtype : bool
        v5 only: return arrays in their MATLAB class (whole-number doubles, which
        MATLAB stores as uint8, come back as float64). **scipy then drops the
        imaginary part of complex arrays** (scipy 1.17, with a ComplexWarning): pass
        False for files with complex data (arrays keep their stored dtype, complex
        stays complex; accessors of :class:`MatStruct` accept integer storage).

    Returns
    -------
    dict
        Variables by name; structs are dicts, arrays keep MATLAB's index order
        (``A[i, j, k]`` is ``A(i+1, j+1, k+1)``), singleton dimensions squeezed.

    Raises
    ------
    InputError
        If the file does not exist or is not a MATLAB file.
    """
    def read(p: Path) -> dict[str, Any]:
        if h5py.is_hdf5(p):
            from pymatreader import read_mat

            return read_mat(str(p), variable_names=variable_names)
        import scipy.io

        return scipy.io.loadmat(str(p), mat_dtype=mat_dtype, simplify_cells=True,
                                variable_names=variable_names)
    data = _guarded(path, read)
    return {k: v for k, v in data.items() if not k.startswith("__")}


def _guarded(path: str | os.PathLike, read: Any) -> Any:
    """``read(Path)`` of an existing file; any reader failure is a bad user file."""
    p = Path(path)
    if not p.is_file():
        raise InputError("no such file", file=str(p))
    try:
        return read(p)
    except Exception as exc:
        raise InputError(f"cannot read as a MATLAB file: {exc}", file=str(p)) from None


def mat_variable_names(path: str | os.PathLike) -> list[str]:
    """Names of the top-level variables of a MATLAB v5 or v7.3 file, without reading them.

    Raises
    ------
    InputError
        If the file does not exist or is not a MATLAB file.
    """
    def names(p: Path) -> list[str]:
        if h5py.is_hdf5(p):
            with h5py.File(p, "r") as f:
                return [k for k in f if not k.startswith("#")]
        import scipy.io

        return [name for name, _, _ in scipy.io.whosmat(str(p))]
    return _guarded(path, names)


def save_mat(path: str | os.PathLike, variables: Mapping[str, Any], *, version: str = "5",
             overwrite: bool = False, protect: tuple[str, ...] = ()) -> Path:
    """Write variables (dicts become structs) to a MATLAB file, atomically.

    Parameters
    ----------
    path : str or PathLike
        Output .mat file.
    variables : mapping
        Variable name -> array, number, string or dict (struct).
    version : {"5", "7.3"}
        MAT-file version: v5 with :func:`scipy.io.savemat`, v7.3 (HDF5) with
        :mod:`hdf5storage` (MATLAB-compatible, no Python metadata, uncompressed).
    overwrite : bool
        Replace an existing file.
    protect : tuple of str
        Input files that must never be overwritten.

    Returns
    -------
    pathlib.Path
        The written file.
    """
    if version not in _MAT_VERSIONS:
        raise InputError(f"expected one of {_MAT_VERSIONS}, got {version!r}", field="version")
    target = Path(path)
    with atomic_write(target, overwrite=overwrite, protect=protect) as tmp:
        if version == "5":
            import scipy.io

            scipy.io.savemat(str(tmp), dict(variables), appendmat=False, format="5",
                             long_field_names=True, do_compression=False, oned_as="row")
        else:
            try:
                import hdf5storage
            except ImportError:  # pragma: no cover - optional dependency
                raise InputError("writing MATLAB v7.3 needs the optional package hdf5storage "
                                 "(pip install 'holoprobe[mat73]')", field="version") from None
            options = hdf5storage.Options(matlab_compatible=True, store_python_metadata=False,
                                          compress=False)
            tmp.unlink()  # hdf5storage creates the file (with MATLAB's 512-byte header)
            hdf5storage.writes(dict(variables), filename=str(tmp), options=options)
    return target


class MatStruct:
    """Validating view of one MATLAB struct (or the file's top level).

    Parameters
    ----------
    values : dict
        Field name -> value, as returned by :func:`load_mat`.
    file : str
        The file (for error messages).
    prefix : str
        Field path of this struct (``"Grid"``); empty for the top level.
    """

    def __init__(self, values: Any, file: str, prefix: str = ""):
        if not isinstance(values, dict):
            raise InputError(f"expected a struct, got {type(values).__name__}",
                             file=file, field=prefix or None)
        self.values = values
        self.file = file
        self.prefix = prefix

    def name(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def error(self, message: str, key: str | None = None) -> InputError:
        return InputError(message, file=self.file,
                          field=self.name(key) if key else (self.prefix or None))

    def __contains__(self, key: str) -> bool:
        return key in self.values

    def struct(self, key: str) -> MatStruct:
        if key not in self.values:
            raise self.error("missing struct", key)
        return MatStruct(self.values[key], self.file, self.name(key))

    def optional_struct(self, key: str) -> MatStruct | None:
        return self.struct(key) if key in self.values else None

    def array(self, key: str, *, shape: tuple[int, ...] | None = None,
              allow_inf: bool = False) -> NDArray:
        """A real numeric array; ``shape`` restores dimensions MATLAB readers squeezed."""
        if key not in self.values:
            raise self.error("missing field", key)
        raw = self.values[key]
        arr = np.asarray(raw)
        if arr.dtype == bool:
            arr = arr.astype(np.uint8)
        if not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
            raise self.error(f"expected real numbers, got {type(raw).__name__} "
                             f"(dtype {arr.dtype})", key)
        if shape is not None and arr.shape != tuple(shape):
            if arr.size == int(np.prod(shape)) and \
                    tuple(n for n in arr.shape if n != 1) == tuple(n for n in shape if n != 1):
                arr = arr.reshape(shape)
            else:
                raise self.error(f"expected shape {tuple(shape)}, got {arr.shape}", key)
        if np.issubdtype(arr.dtype, np.floating):
            bad = np.isnan(arr) if allow_inf else ~np.isfinite(arr)
            if np.any(bad):
                idx = tuple(int(i) for i in np.argwhere(np.atleast_1d(bad))[0])
                raise self.error(f"contains NaN{'' if allow_inf else ' or inf'} "
                                 f"(first at index {idx})", key)
        return np.ascontiguousarray(arr)

    def vector(self, key: str, *, length: int | None = None) -> NDArray:
        """A 1-D array (row or column vector in MATLAB)."""
        arr = self.array(key)
        if arr.ndim > 1 and sum(n != 1 for n in arr.shape) <= 1:
            arr = arr.reshape(-1)
        arr = np.atleast_1d(arr)
        if arr.ndim != 1:
            raise self.error(f"expected a vector, got shape {arr.shape}", key)
        if length is not None and arr.size != length:
            raise self.error(f"expected {length} values, got {arr.size}", key)
        return arr

    def scalar(self, key: str, *, positive: bool = False, allow_inf: bool = False) -> float:
        arr = self.array(key, allow_inf=allow_inf)
        if arr.size != 1:
            raise self.error(f"expected a scalar, got shape {arr.shape}", key)
        value = float(arr.reshape(()))
        if positive and not value > 0:
            raise self.error(f"expected a positive number, got {value!r}", key)
        return value

    def integer(self, key: str, *, minimum: int | None = None) -> int:
        value = self.scalar(key)
        if value != int(value):
            raise self.error(f"expected a whole number, got {value!r}", key)
        if minimum is not None and value < minimum:
            raise self.error(f"expected at least {minimum}, got {int(value)}", key)
        return int(value)

    def string(self, key: str, *, default: str | None = None) -> str:
        if key not in self.values:
            if default is None:
                raise self.error("missing field", key)
            return default
        value = self.values[key]
        if isinstance(value, np.ndarray) and value.size == 0:
            return ""
        if isinstance(value, np.ndarray) and value.dtype.kind == "U":
            value = "".join(value.reshape(-1).tolist())
        if not isinstance(value, str):
            raise self.error(f"expected a character array, got {type(value).__name__}", key)
        return value
