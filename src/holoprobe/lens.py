"""The acoustic lens law (paper eq. lens-delays): the one place it is written.

A cylindrical focusing lens delays the signal along the elevation y of an element by

    τ(y) = (√((H/2)² + F²) − √(y² + F²)) / c0,

zero at the aperture edges y = ±H/2 and largest in the centre. Every layer that needs
the law (the simulator, the characterization, the virtual transducer, the exports and
the analyses) imports it from here; this module depends on nothing but NumPy and
:mod:`holoprobe.errors`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError

__all__ = ["lens_delays", "lens_delays_from_curvature"]


def lens_delays_from_curvature(
    y: ArrayLike, curvature: float, half_height: float, sound_speed: float
) -> NDArray[np.float64]:
    """Exact lens delays parameterised by the curvature κ = 1/F (regular at κ = 0).

    ``τ(y) = κ((H/2)² − y²) / (c0 (√(1 + κ²(H/2)²) + √(1 + κ²y²)))``, the form of
    :func:`lens_delays` without the cancellation of its difference of square roots.
    No checks: the focus fit calls it in its inner loop.

    Parameters
    ----------
    y : array_like
        Elevation relative to the lens centre in m (any shape).
    curvature : float
        κ = 1/F in 1/m (0: no lens; negative: a diverging lens).
    half_height : float
        H/2 in m.
    sound_speed : float
        c0 in m/s.

    Returns
    -------
    ndarray
        Delays τ in s, same shape as ``y``.

    Examples
    --------
    >>> float(lens_delays_from_curvature(0.0, 0.0, 7e-3, 1481.0))
    0.0
    """
    kappa = float(curvature)
    a2 = half_height**2
    y2 = np.asarray(y, dtype=float) ** 2
    k2 = kappa * kappa
    return kappa * (a2 - y2) / (sound_speed * (np.sqrt(1.0 + k2 * a2) + np.sqrt(1.0 + k2 * y2)))


def lens_delays(
    y: ArrayLike, focus: float, height: float, sound_speed: float
) -> NDArray[np.float64]:
    """Exact lens delays along the elevation (paper eq. lens-delays).

    ``τ(y) = (√((H/2)² + F²) − √(y² + F²)) / c0``, evaluated as
    ``κ((H/2)² − y²) / (c0 (√(1 + κ²(H/2)²) + √(1 + κ²y²)))`` with κ = 1/F, which
    has no cancellation for weak lenses and gives 0 for F = ±∞.

    Parameters
    ----------
    y : array_like
        Elevation coordinate relative to the lens centre, in m (any shape).
    focus : float
        Focal distance F in m; ``inf`` for no lens; a negative F describes a
        diverging lens (delays of the opposite sign).
    height : float
        Aperture height H in m (delays are zero at ``y = ±H/2``).
    sound_speed : float
        c0 in m/s.

    Returns
    -------
    ndarray
        Delays τ in s, same shape as ``y``.

    Raises
    ------
    InputError
        For F = 0 or NaN, a non-positive height or sound speed.

    Examples
    --------
    >>> tau = lens_delays([0.0, 7.14e-3], 0.1807, 14.28e-3, 1481.0)
    >>> [round(float(t) * 1e9, 2) for t in tau]
    [95.21, 0.0]
    """
    focus = float(focus)
    if focus == 0 or np.isnan(focus):
        raise InputError(f"expected a non-zero focal distance in m (inf: no lens), got {focus!r}",
                         field="focus")
    if not (np.isfinite(height) and height > 0):
        raise InputError(f"expected a positive height in m, got {height!r}", field="height")
    if not (np.isfinite(sound_speed) and sound_speed > 0):
        raise InputError(f"expected a positive sound speed in m/s, got {sound_speed!r}",
                         field="sound_speed")
    return lens_delays_from_curvature(np.asarray(y, dtype=float), 1.0 / focus,
                                      0.5 * float(height), float(sound_speed))
