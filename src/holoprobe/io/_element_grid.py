"""The element grid of a sparse 2-D matrix probe as a CSV file (``ix,iy``)."""

from __future__ import annotations

import os

import numpy as np
from numpy.typing import NDArray

from holoprobe.errors import InputError
from holoprobe.io._hydrophone import read_csv_columns

__all__ = ["read_element_grid"]


def read_element_grid(path: str | os.PathLike) -> NDArray[np.int64]:
    """Read which lattice positions a sparse matrix probe populates.

    Parameters
    ----------
    path : str or PathLike
        CSV with ``#`` comment lines, a header ``ix,iy`` and one row per element in
        the RF channel order: 0-based column (x) and row (y) of the element on its
        lattice (docs/formats.md, "Element grid CSV").

    Returns
    -------
    ndarray of int64, shape (N, 2)
        ``(ix, iy)`` per element.

    Raises
    ------
    InputError
        Missing column, a value that is not a non-negative integer (the message names
        the file, the column and the row), two elements on one position.
    """
    columns, _ = read_csv_columns(path)
    out = []
    for name in ("ix", "iy"):
        if name not in columns:
            raise InputError(f"missing column (have {sorted(columns)}; expected ix, iy)",
                             file=str(path), field=name)
        v = columns[name]
        bad = ~(np.isfinite(v) & (v >= 0) & (np.mod(v, 1) == 0))
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            raise InputError(f"data row {row + 1}: {float(v[row]):g} is not a "
                             "non-negative integer grid index", file=str(path), field=name)
        out.append(v.astype(np.int64))
    gp = np.stack(out, axis=-1)
    if gp.shape[0] < 1:
        raise InputError("no element rows", file=str(path))
    key = gp[:, 1] * (int(gp[:, 0].max()) + 1) + gp[:, 0]
    _, first, counts = np.unique(key, return_index=True, return_counts=True)
    if np.any(counts > 1):
        a = int(first[np.flatnonzero(counts > 1)[0]])
        b = int(np.flatnonzero(key == key[a])[1])
        raise InputError(f"data rows {a + 1} and {b + 1} both place an element at "
                         f"(ix, iy) = ({int(gp[a, 0])}, {int(gp[a, 1])})", file=str(path),
                         field="ix, iy")
    return gp
