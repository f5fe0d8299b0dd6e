"""The scan window's bias of a convex array's W, H and F, with the model on the arc.

:func:`scan_window_bias` lays a convex array flat on the apex's tangent plane: along y
the face is straight, but along the arc a flat model radiates through the scan window
unlike a ±37° arc (its end strips face the scan, the arc's look 37° away from it), and
the H and F the pipeline fits from the whole aperture mix both directions. Here the
model is the fitted source on the fitted cylinder itself: the strips (element-map
amplitudes, the file's kerf) along the arc at the fitted W and centre, the fitted H
and lens along y, radiated as the twin and a baffled curved face do (the Rayleigh
monopole integral ``p = −iωρ0/(2π) ∫ v_n e^{ikr}/r dS`` over the arc), measured on the
posed scan grid, cut to its window, projected back onto the cylinder by the
pipeline's own projection (:func:`project_on_cylinder`) and refitted with the same
settings. Refit minus model is the bias at the fitted parameters.

The radiated field is written as an angular spectrum on the apex's tangent plane
z = 0 (the scan lies above it, the arc below): by Weyl's expansion a monopole at
(x', y', z') contributes ``(2πi/kz) e^{−i(κx x' + κy y' − kz z')}`` (z > z'), so the
pressure spectrum on z = 0 is ``P̂ = ρ0 c0 k/kz · V̂`` with the arc's velocity spectrum
``V̂(κx, κy) = ∫∫ v_n e^{−i(κx X(s) + κy y + kz Z(s))} ds dy`` (X = R sin(s/R),
Z = R cos(s/R) − R; the flat face's V̂ when R → ∞). The y factor is the flat model's
(:func:`model_source_spectrum`); the arc factor is a 2-D type-3 NUFFT (finufft) from
the strips' midpoint samples to the lattice waves (κx, kz).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from holoprobe.characterize._aperture import ApertureFit
from holoprobe.characterize._aperture_bias import (
    ApertureBias,
    Strips,
    _model_bias,
    _model_bins,
    _model_scan,
    _with_noise_floor,
    model_source_spectrum,
)
from holoprobe.characterize._lens import LensFit
from holoprobe.geometry import Medium, PlaneGrid, Pose

__all__ = ["arc_model_velocity", "arc_source_spectrum", "arc_window_bias"]


def _arc_samples(aperture: ApertureFit, strips: Strips | None, spacing: float
                 ) -> tuple[NDArray[np.float64], NDArray[np.complex128], NDArray[np.intp]]:
    """Midpoint samples of the lateral model along the arc: arc positions s (m), their
    weights (amplitude × ds) and their strip (index into the strips' delays; 0 for a
    plain rectangle). At most ``spacing`` apart."""
    if strips is None:
        n, width, amps = 1, aperture.width, np.ones(1)
        centers = np.array([aperture.center_x])
    else:
        amps = np.asarray(strips[0], float)
        n = amps.size
        pitch = aperture.width / n
        width = pitch - float(strips[1])
        centers = aperture.center_x + (np.arange(n) - 0.5 * (n - 1)) * pitch
    m = max(1, math.ceil(width / spacing))
    offsets = (np.arange(m) + 0.5) * width / m - 0.5 * width
    s = (centers[:, None] + offsets[None, :]).reshape(-1)
    weights = np.repeat(amps * width / m, m).astype(np.complex128)
    return s, weights, np.repeat(np.arange(n), m)


def arc_source_spectrum(
    grid: PlaneGrid, frequencies: NDArray[np.float64], medium: Medium,
    aperture: ApertureFit, focus: float, lens_center_y: float, radius: float,
    shape: tuple[int, int], *, strips: Strips | None = None, eps: float = 1e-6,
    level: float = 1e-5,
) -> tuple[NDArray[np.complex128], NDArray[np.float64], NDArray[np.float64]]:
    """The arc's velocity spectrum on the apex's tangent plane (module notes).

    ``aperture``'s width and centre are along the arc (the unrolled grid's s), its
    height and centre along y; ``radius`` R (m) of the cylinder, the apex at the origin
    and the centre of curvature at (0, 0, −R). The waves whose elevation factor is
    below ``level`` of its peak at that frequency are left out (zero).

    Returns
    -------
    spectrum : ndarray, complex, shape (npx, npy, nf)
        ``V̂(κx, κy)`` (zero for evanescent waves) on the DFT lattice of a period
        ``shape × (grid.dx, grid.dy)`` (FFT order), as :func:`model_source_spectrum`
        returns the flat model's.
    kx, ky : ndarray
        The lattice (rad/m).
    """
    import finufft

    npx, npy = shape
    kx = np.asarray(2 * np.pi * np.fft.fftfreq(npx, grid.dx), dtype=np.float64)
    ky = np.asarray(2 * np.pi * np.fft.fftfreq(npy, grid.dy), dtype=np.float64)
    # the elevation factor: the flat model's at κx = 0 over its width
    flat = dataclasses.replace(aperture, center_x=0.0)
    yhat = model_source_spectrum(grid, frequencies, medium, flat, focus, lens_center_y,
                                 (1, npy))[0][0] / aperture.width
    c0 = medium.sound_speed
    lam = c0 / float(np.max(frequencies))
    s, weights, strip = _arc_samples(aperture, strips, lam / 8)
    xs, zs = radius * np.sin(s / radius), radius * np.cos(s / radius) - radius
    delays = (np.asarray(strips[2], float)[strip] if strips is not None and len(strips) == 3
              else None)
    kappa2 = kx[:, None] ** 2 + ky[None, :] ** 2
    # the arc factor depends on κy only through kz: each row −κy is row κy's copy
    partner = (-np.arange(npy)) % npy
    own = np.arange(npy) <= partner
    out = np.zeros((npx, npy, frequencies.size), np.complex128)
    for i, f in enumerate(np.asarray(frequencies, float)):
        k = 2 * np.pi * f / c0
        # the elevation factor's rows below ``level`` of its peak are left zero
        rows = np.abs(yhat[:, i]) > level * np.abs(yhat[:, i]).max()
        ix, iy = np.nonzero((kappa2 < k * k) & (rows | rows[partner])[None, :]
                            & own[None, :])
        kz = np.sqrt(k * k - kappa2[ix, iy])
        c = weights if delays is None else weights * np.exp(2j * np.pi * f * delays)
        xhat = np.zeros((npx, npy), np.complex128)
        xhat[ix, iy] = finufft.nufft2d3(xs, zs, np.ascontiguousarray(c), kx[ix], kz,
                                        isign=-1, eps=eps, nthreads=1)
        xhat[:, ~own] = xhat[:, partner[~own]]
        out[:, :, i] = xhat * np.where(rows, yhat[:, i], 0.0)[None, :]
    return out, kx, ky


def arc_model_velocity(
    scan_grid: PlaneGrid, grid: PlaneGrid, medium: Medium, radius: float,
    aperture: ApertureFit, lens: LensFit | None, project: Any, *,
    strips: Strips | None = None, max_bins: int = 12,
    guard_angle: float = np.deg2rad(80.0), eps: float = 1e-6, seed: int | None = 0,
) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """The model on the arc measured on ``scan_grid`` and projected back onto the
    cylinder (module notes; parameters as :func:`arc_window_bias`).

    Returns
    -------
    velocity : ndarray, complex, shape (ns, ny, nb)
        The model's back-projected normal velocity on ``grid`` (arbitrary common scale,
        with the data's noise floor for a ``seed``).
    frequencies : ndarray, shape (nb,)
        Its ``max_bins`` frequencies (Hz), spread over the aperture fit's bins.
    """
    pick, f, amplitudes, focus, lens_y = _model_bins(aperture, lens, max_bins)
    half = 0.5 * aperture.width + abs(aperture.center_x)
    phi = min(half / radius, 0.5 * np.pi)
    depth = radius * (1.0 - math.cos(phi))
    reach = radius * math.sin(phi) + depth * math.tan(guard_angle)
    nx = 2 * math.ceil(reach / grid.dx) + 1
    plane = PlaneGrid(np.asarray(grid.dx * (np.arange(nx) - nx // 2), np.float64), grid.y,
                      Pose())

    def spectrum(shape: tuple[int, int]) -> tuple[NDArray, NDArray, NDArray]:
        vhat, kx, ky = arc_source_spectrum(plane, f, medium, aperture, focus, lens_y,
                                           radius, shape, strips=strips, eps=eps)
        return vhat * amplitudes, kx, ky

    pressure = _model_scan(scan_grid, plane, f, medium, spectrum, guard_angle, eps)
    return _with_noise_floor(project(pressure, f), aperture, pick, seed), f


def arc_window_bias(
    scan_grid: PlaneGrid, grid: PlaneGrid, medium: Medium, radius: float,
    aperture: ApertureFit, lens: LensFit | None, project: Any, *,
    aperture_options: dict[str, Any], lens_options: dict[str, Any],
    strips: Strips | None = None, max_bins: int = 12,
    guard_angle: float = np.deg2rad(80.0), eps: float = 1e-6, seed: int | None = 0,
) -> ApertureBias:
    """Bias of the convex fits of W, H and F for this scan window (module notes):
    :func:`arc_model_velocity` refitted, minus the model.

    Parameters
    ----------
    scan_grid : PlaneGrid
        The scan grid posed in the source frame (apex at the origin, axis +z, centre of
        curvature at (0, 0, −R)).
    grid : PlaneGrid
        The unrolled grid (s, y) of the cylinder the pipeline fits on.
    medium : Medium
        c0, ρ0.
    radius : float
        R (m).
    aperture, lens
        The fits (the model's W, H, centre, per-bin amplitudes; F and y_L when the lens
        is significant).
    project : callable
        ``project(pressure, frequencies) -> velocity``: the pipeline's projection of a
        (nx, ny, nf) pressure spectrum on ``scan_grid`` onto ``grid`` (normal velocity,
        (ns, ny, nf)).
    aperture_options, lens_options : dict
        The pipeline's :func:`fit_aperture` / :func:`fit_lens_focus` keywords.
    strips : (ndarray, float[, ndarray]), optional
        The elements' amplitudes (N,), kerf (m) (and delays, s).
    max_bins, guard_angle, eps, seed
        As :func:`scan_window_bias` (``guard_angle``: the steepest wave radiated from
        the tangent plane; the arc's own depth is added to the padding).

    Returns
    -------
    ApertureBias
    """
    velocity, f = arc_model_velocity(scan_grid, grid, medium, radius, aperture, lens,
                                     project, strips=strips, max_bins=max_bins,
                                     guard_angle=guard_angle, eps=eps, seed=seed)
    return _model_bias(velocity, grid, f, medium, aperture, lens, aperture_options,
                       lens_options)
