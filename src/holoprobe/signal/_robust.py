"""Robust statistics: the median absolute deviation as a noise level."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["MAD_TO_SIGMA", "mad_sigma"]

MAD_TO_SIGMA = 1.482602218505602
"""1 / Φ⁻¹(3/4): the factor that turns a median absolute deviation into σ for Gaussian noise."""


def mad_sigma(values: ArrayLike, *, axis: int | None = None) -> NDArray[np.float64] | float:
    """Standard deviation estimated from the median absolute deviation, ``1.4826·MAD``.

    Parameters
    ----------
    values : array_like
        Samples (any unit u).
    axis : int, optional
        Axis along which to take the medians (``None``: all samples).

    Returns
    -------
    float or ndarray
        σ in u; an array without ``axis`` when ``axis`` is given.

    Examples
    --------
    >>> round(float(mad_sigma([-1.0, 0.0, 1.0])), 4)
    1.4826
    """
    x = np.asarray(values, dtype=float)
    if axis is None:
        return float(MAD_TO_SIGMA * np.median(np.abs(x - np.median(x))))
    med = np.median(x, axis=axis, keepdims=True)
    return MAD_TO_SIGMA * np.median(np.abs(x - med), axis=axis)
