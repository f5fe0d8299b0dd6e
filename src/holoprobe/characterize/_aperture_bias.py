"""Bias of the aperture and lens-focus fits that the finite scan leaves (issue 10).

The back-projected source is not the ideally band-limited source that
:func:`fit_aperture` and :func:`fit_lens_focus` model: a scan of finite extent at a
finite distance records, from a point near the aperture's edge, only the waves that
reach the scan, so the outward-travelling steep waves of each edge are missing. The
edges of the reconstruction are blurred asymmetrically (less light outside the
aperture is recorded than inside) and the fitted W and H come out short; the lens
focus, fitted from the elevation phase, depends on how far the scan extends in y.
On a 32-element P4-1 twin scanned 2.5 mm beyond the aperture at 4.8 mm, W and H were
−15 and −17 µm and F −0.55 % at the true face without noise; with a scan 10 mm wider
on each side, −3 µm and −0.01 %.

:func:`scan_window_bias` measures that bias by doing to a model source what the
measurement and the pipeline did to the real one: the fitted rectangle (the probe's
strips with their element-map amplitudes for an array) with the fitted lens is
radiated onto the posed scan grid (exact angular spectrum, no evanescent waves), the
scan window keeps what it covers, the result is back-projected onto the same source
grid and refitted with the same settings. The difference between the refit and the
model is the bias at the fitted parameters; subtracting it is one step of an
iterated bias correction (the bias varies slowly with the parameters).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.fft
from numpy.typing import NDArray

from holoprobe.characterize._aperture import ApertureFit, fit_aperture
from holoprobe.characterize._lens import LensFit, fit_lens_focus
from holoprobe.errors import FitError, InputError
from holoprobe.geometry import Medium, PlaneGrid, Pose
from holoprobe.signal import workers

__all__ = ["ApertureBias", "FacePlane", "defocus", "face_plane", "model_source_spectrum",
           "model_velocity", "refocus", "scan_window_bias", "window_round_trip"]


@dataclass(frozen=True)
class ApertureBias:
    """Bias of the fitted aperture and focus that the scan window causes (m).

    Attributes
    ----------
    width, height : float
        Refit minus model of W and H.
    center_x, center_y : float
        Refit minus model of the aperture centre.
    focus : float
        Refit minus model of the lens focus F (NaN without a lens fit).
    frequencies : ndarray, shape (nb,)
        Frequencies (Hz) of the simulation.
    """

    width: float
    height: float
    center_x: float
    center_y: float
    focus: float
    frequencies: NDArray[np.float64]


Strips = tuple[NDArray, float] | tuple[NDArray, float, NDArray]
"""An array's lateral model: element amplitudes (N,), kerf (m) and optionally element
delays (N,) in s (conjugate convention ``e^{+iωτ}``, as the lens and the element map)."""


def _strips(grid: PlaneGrid, aperture: ApertureFit, strips: Strips | None,
            kx: NDArray[np.float64], frequency: float = 0.0) -> NDArray[np.complex128]:
    """Continuous Fourier transform ``∫ X(x) e^{−iκx x} dx`` of the lateral model (at
    ``frequency`` in Hz when the strips carry delays)."""
    half = 0.5 * kx

    def sinc_width(w: float) -> NDArray[np.float64]:
        return w * np.sinc(half * w / np.pi)

    if strips is None:
        return sinc_width(aperture.width) * np.exp(-1j * kx * aperture.center_x)
    amplitudes, kerf = strips[0], strips[1]
    n = amplitudes.size
    pitch = aperture.width / n
    centers = aperture.center_x + (np.arange(n) - 0.5 * (n - 1)) * pitch
    weights = np.asarray(amplitudes, dtype=np.complex128)
    if len(strips) == 3:
        weights = weights * np.exp(2j * np.pi * frequency * np.asarray(strips[2], float))
    phases = np.exp(-1j * np.outer(kx, centers)) @ weights
    return sinc_width(pitch - kerf) * phases


def model_source_spectrum(
    grid: PlaneGrid, frequencies: NDArray[np.float64], medium: Medium,
    aperture: ApertureFit, focus: float, lens_center_y: float,
    shape: tuple[int, int], *, strips: Strips | None = None,
    oversample: int = 8,
) -> tuple[NDArray[np.complex128], NDArray[np.float64], NDArray[np.float64]]:
    """Angular spectrum of the model source's velocity on a periodic grid.

    The model: unit normal velocity on the rectangle ``W × H`` at ``(x_c, y_c)``
    (``strips``: N strips of width ``W/N − kerf`` with the given amplitudes instead of
    the uniform width W), lens delays ``τ(y − y_L)`` (conjugate convention
    ``e^{+iωτ}``). Lateral part analytic, elevation part by an FFT of the rectangle
    sampled ``oversample`` times finer than ``grid.dy`` with exact cell overlaps.

    Returns
    -------
    spectrum : ndarray, complex, shape (npx, npy, nf)
        ``V̂(κx, κy) = ∫∫ V e^{−i(κx x + κy y)} dx dy`` on the DFT lattice of a period
        ``shape × (dx, dy)`` (FFT order).
    kx, ky : ndarray
        The lattice (rad/m).
    """
    from holoprobe.characterize._aperture import aperture_weights
    from holoprobe.lens import lens_delays

    npx, npy = shape
    kx = np.asarray(2 * np.pi * np.fft.fftfreq(npx, grid.dx), dtype=np.float64)
    ky = np.asarray(2 * np.pi * np.fft.fftfreq(npy, grid.dy), dtype=np.float64)
    delayed = strips is not None and len(strips) == 3
    xhat = _strips(grid, aperture, strips, kx)
    m = npy * oversample
    dyf = grid.dy / oversample
    yf = np.asarray(aperture.center_y + (np.arange(m) - m // 2) * dyf, dtype=np.float64)
    pair = PlaneGrid(np.array([-dyf, 0.0, dyf]), yf)
    box = aperture_weights(pair, width=dyf, height=aperture.height,
                           center_y=aperture.center_y)[1]
    tau = (lens_delays(yf - lens_center_y, focus, aperture.height, medium.sound_speed)
           if math.isfinite(focus) else np.zeros(m))
    index = np.round(ky * npy * grid.dy / (2 * np.pi)).astype(int) % m
    # each bin's plane contiguous (the window model reads them one by one)
    out: NDArray[np.complex128] = np.empty((frequencies.size, npx, npy), np.complex128)
    for i, f in enumerate(frequencies):
        yhat = np.fft.fft(box * np.exp(2j * np.pi * f * tau))[index] * dyf
        if delayed:
            xhat = _strips(grid, aperture, strips, kx, float(f))
        np.multiply.outer(xhat, yhat * np.exp(-1j * ky * yf[0]), out=out[i])
    return np.moveaxis(out, 0, -1), kx, ky


SpectrumModel = Callable[[tuple[int, int]], tuple[NDArray[np.complex128],
                                                  NDArray[np.float64], NDArray[np.float64]]]


def _model_scan(scan_grid: PlaneGrid, source: PlaneGrid, frequencies: NDArray,
                medium: Medium, spectrum: SpectrumModel, guard_angle: float,
                eps: float) -> NDArray[np.complex128]:
    """Pressure spectrum (Pa·s up to a common factor) on ``scan_grid`` of the source
    whose velocity spectrum ``spectrum(shape)`` gives (as :func:`model_source_spectrum`
    returns it, on the DFT lattice of a period ``shape × (dx, dy)`` of ``source``)."""
    from holoprobe.propagation import ProjectionPlan
    from holoprobe.signal import next_fast_length

    corners = scan_grid.points().reshape(-1, 3)
    z_max = float(np.max(np.abs(corners[:, 2])))
    reach = 2.0 * z_max * math.tan(guard_angle)
    span_x = max(source.x[-1], corners[:, 0].max()) - min(source.x[0], corners[:, 0].min())
    span_y = max(source.y[-1], corners[:, 1].max()) - min(source.y[0], corners[:, 1].min())
    npx = next_fast_length(math.ceil((span_x + reach) / source.dx) + 2)
    npy = next_fast_length(math.ceil((span_y + reach) / source.dy) + 2)
    vhat, kx, ky = spectrum((npx, npy))
    x = source.x[0] + source.dx * np.arange(npx)
    y = source.y[0] + source.dy * np.arange(npy)
    # pressure on z = 0 of the propagating waves below the guard angle:
    # P̂ = ρ0 c0 k / kz · V̂ (the plan's velocity factor inverted), as the DFT of the
    # pressure on the periodic plane (x, y) — the plan takes it as it is (no inverse FFT
    # to the plane and forward FFT back); only the waves below the guard angle are kept
    shift_x = np.exp(1j * kx * x[0]) / (source.dx * source.dy)
    shift_y = np.exp(1j * ky * y[0])
    blocks = []
    for n, f in enumerate(np.asarray(frequencies, float)):
        k = 2 * np.pi * f / medium.sound_speed
        k_max = k * math.sin(guard_angle)
        rows = np.flatnonzero(np.abs(kx) < k_max)
        cols = np.flatnonzero(np.abs(ky) < k_max)
        kappa2 = kx[rows, None] ** 2 + ky[None, cols] ** 2
        keep = kappa2 < k_max**2
        kz = np.sqrt(np.where(keep, k * k - kappa2, 1.0))
        factor = np.where(keep, k / kz, 0.0) * shift_x[rows, None] * shift_y[None, cols]
        blocks.append((rows, cols, vhat[:, :, n][np.ix_(rows, cols)] * factor))
    plan = ProjectionPlan.from_spectrum(blocks, PlaneGrid(x, y, Pose()), frequencies, medium,
                                        eps=eps)
    return plan.project(scan_grid, quantity="pressure")


def _model_bins(aperture: ApertureFit, lens: LensFit | None, max_bins: int
                ) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64],
                           float, float]:
    """A window model's bins and what it is built from: the picked indices of
    ``max_bins`` of the aperture fit's bins (:func:`_pick`), their frequencies (Hz),
    their lateral amplitudes, the lens focus (m;
    inf without a significant lens) and its elevation centre (m; the aperture's
    without one)."""
    pick = _pick(aperture, max_bins)
    f = np.asarray(aperture.frequencies, float)[pick]
    amplitudes = np.asarray(aperture.amplitude_x, float)[pick]
    has_lens = lens is not None and lens.significant
    focus = lens.focus if has_lens and lens is not None else math.inf
    lens_y = lens.center_y if has_lens and lens is not None else aperture.center_y
    return pick, f, amplitudes, float(focus), float(lens_y)


def _pick(aperture: ApertureFit, max_bins: int) -> NDArray[np.intp]:
    """Indices of ``max_bins`` of the aperture fit's bins, evenly spread."""
    if max_bins < 1:
        raise InputError(f"expected at least 1 bin, got {max_bins}", field="max_bins")
    n = aperture.frequencies.size
    return np.unique(np.round(np.linspace(0, n - 1, min(max_bins, n)))).astype(np.intp)


def model_velocity(
    scan_grid: PlaneGrid, source: PlaneGrid, medium: Medium, aperture: ApertureFit,
    lens: LensFit | None, *, strips: Strips | None = None,
    max_bins: int = 12, guard_angle: float = np.deg2rad(80.0), eps: float = 1e-6,
    seed: int | None = 0, noise_axis: str = "x",
) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """The model source measured on ``scan_grid`` and back-projected onto ``source``.

    The model (:func:`model_source_spectrum`: the fitted W × H at the fitted centre,
    or N strips with ``strips = (amplitudes, kerf)``, with the fitted lens when it is
    significant, each bin scaled by the aperture fit's amplitude) is radiated onto the
    posed scan grid (exact angular spectrum of the propagating waves up to
    ``guard_angle``), cut to the scan's window and projected back onto the source
    grid as :func:`estimate_source` does with the data. With a ``seed``, noise is
    added whose mean magnitude matches the data's fitted noise floor (``offset_x`` of
    the aperture fit, relative to each bin's profile peak; ``noise_axis="y"``: the
    elevation profile's ``offset_y``): a noise floor widens the magnitude profiles'
    edges, and the bias being measured must include that.

    Returns
    -------
    velocity : ndarray, complex, shape (nx, ny, nb)
        Back-projected normal velocity of the model (arbitrary common scale).
    frequencies : ndarray, shape (nb,)
        The ``max_bins`` frequencies (Hz) used, spread over the aperture fit's bins.
    """
    pick, f, amplitudes, focus, lens_y = _model_bins(aperture, lens, max_bins)

    def spectrum(shape: tuple[int, int]) -> tuple[NDArray, NDArray, NDArray]:
        vhat, kx, ky = model_source_spectrum(source, f, medium, aperture, focus, lens_y,
                                             shape, strips=strips)
        vhat *= amplitudes
        return vhat, kx, ky

    velocity = window_round_trip(scan_grid, source, f, medium, spectrum,
                                 guard_angle=guard_angle, eps=eps)
    return _with_noise_floor(velocity, aperture, pick, seed, noise_axis), f


def window_round_trip(scan_grid: PlaneGrid, source: PlaneGrid, frequencies: NDArray,
                      medium: Medium, spectrum: SpectrumModel, *,
                      guard_angle: float = np.deg2rad(80.0), eps: float = 1e-6
                      ) -> NDArray[np.complex128]:
    """A model source measured on ``scan_grid`` and back-projected onto ``source``.

    The source's velocity spectrum (``spectrum(shape)`` → ``(V̂, κx, κy)`` on the DFT
    lattice of a period ``shape × (dx, dy)`` of ``source``, ``V̂ = ∫∫ V e^{−iκ·r}``,
    shape (npx, npy, nf)) is radiated onto the posed scan grid (exact angular spectrum
    of the propagating waves up to ``guard_angle``), cut to the scan's window and
    projected back onto ``source`` as :func:`estimate_source` does with the data. What
    the estimator then fits differs from the model only by the scan window: the basis
    of :func:`scan_window_bias` (1-D arrays, rectangles) and of the matrix pitch
    correction (:func:`holoprobe.characterize.matrix_window_step`).

    Returns
    -------
    ndarray, complex, shape (nx, ny, nf)
        Back-projected normal velocity on ``source`` (the model's scale).
    """
    from holoprobe.propagation import ProjectionPlan

    f = np.asarray(frequencies, float)
    pressure = _model_scan(scan_grid, source, f, medium, spectrum, guard_angle, eps)
    plan = ProjectionPlan(pressure, scan_grid, f, medium, eps=eps, guard_angle=guard_angle,
                          allow_undersampled=True)
    return plan.project(source, quantity="normal_velocity")


def _with_noise_floor(velocity: NDArray, aperture: ApertureFit, pick: NDArray[np.intp],
                      seed: int | None, axis: str = "x") -> NDArray[np.complex128]:
    """``velocity`` plus circular Gaussian noise whose mean magnitude, relative to the
    peak of each bin's lateral profile, is the data's fitted floor (``offset_x``): the
    magnitude profiles of noisy data are ``E|s + n|``, not ``|s| + E|n|``, which
    widens the edges; the model must see the same. No noise for ``seed=None`` or a
    zero floor. ``axis="y"`` takes the floor of the elevation profile instead (when
    the lateral fit is not a rectangle's: an array with a dead element, whose x
    profile fit reads the far side of the hole as floor)."""
    v = np.asarray(velocity, dtype=np.complex128)
    if seed is None:
        return v
    lateral = axis == "x"
    floor = np.asarray(aperture.offset_x if lateral else aperture.offset_y, float)[pick]
    peak = np.asarray(aperture.profile_x if lateral else aperture.profile_y,
                      float)[pick].max(axis=1)
    ratio = np.clip(floor / np.where(peak > 0, peak, np.inf), 0.0, None)
    if not np.any(ratio > 0):
        return v
    model_peak = np.abs(v).mean(axis=1 if lateral else 0).max(axis=0)
    # E|n| = s·√π/2 for circular Gaussian noise of E|n|² = s²
    s = 2.0 * ratio * model_peak / np.sqrt(np.pi)
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal(v.shape) + 1j * rng.standard_normal(v.shape)
    return v + noise * (s / np.sqrt(2.0))


def scan_window_bias(
    scan_grid: PlaneGrid, source: PlaneGrid, medium: Medium, aperture: ApertureFit,
    lens: LensFit | None, *, aperture_options: dict[str, Any], lens_options: dict[str, Any],
    strips: Strips | None = None, max_bins: int = 12,
    guard_angle: float = np.deg2rad(80.0), eps: float = 1e-6, seed: int | None = 0,
) -> ApertureBias:
    """Bias of :func:`fit_aperture` / :func:`fit_lens_focus` for this scan window.

    :func:`model_velocity` of the fitted aperture and lens, refitted with the same
    options; the bias is refit minus model.

    Parameters
    ----------
    scan_grid : PlaneGrid
        The scan grid posed relative to the source plane (its window is what the
        model is cut to).
    source : PlaneGrid
        The source-plane grid of the back-projection (z = 0).
    medium : Medium
        c0 and ρ0.
    aperture : ApertureFit
        The fitted aperture (the model's W, H, centre; its per-bin amplitudes).
    lens : LensFit or None
        The fitted lens (its F and y_L); None or not significant: no lens.
    aperture_options, lens_options : dict
        Keyword arguments the pipeline gave :func:`fit_aperture` and
        :func:`fit_lens_focus` (the refit uses the same).
    strips : (ndarray, float[, ndarray]), optional
        An array's element amplitudes (N,) and kerf (m) (and element delays (N,) in s):
        the lateral model is N strips.
    max_bins : int
        Frequencies simulated (evenly spread over the aperture fit's bins).
    guard_angle, eps : float
        Steepest wave of the model (rad) and the NUFFT tolerance.
    seed : int or None
        Seed of the model's noise (the data's floor); None: a noise-free model.

    Returns
    -------
    ApertureBias
    """
    velocity, f = model_velocity(scan_grid, source, medium, aperture, lens, strips=strips,
                                 max_bins=max_bins, guard_angle=guard_angle, eps=eps,
                                 seed=seed)
    return _model_bias(velocity, source, f, medium, aperture, lens, aperture_options,
                       lens_options)


def refocus(velocity: NDArray, grid: PlaneGrid, frequencies: NDArray, medium: Medium,
            distance: float, *, single_precision: bool = True) -> NDArray[np.complex128]:
    """The source velocity on the plane ``distance`` (m) further along +z.

    Angular-spectrum propagation on the grid (periodic; evanescent waves dropped),
    holoprobe's conjugate convention (waves going to +z gain ``e^{+i kz d}``). With
    ``single_precision`` (default; the pipelines pass ``backprojection.single_precision``)
    the transforms run in complex64 (the back-projected velocity is single-precision
    data; an FFT of 166 = 2·83 points along y costs 3× as much in double), else in
    complex128; the result is complex128.
    """
    cdtype = np.complex64 if single_precision else np.complex128
    kx = 2 * np.pi * np.fft.fftfreq(grid.x.size, grid.dx)
    ky = 2 * np.pi * np.fft.fftfreq(grid.y.size, grid.dy)
    k = 2 * np.pi * np.asarray(frequencies, float) / medium.sound_speed
    kk = (k * k)[None, :]
    # every bin's 2-D transforms in one batched call (threads over the bins' lines)
    spec = scipy.fft.fft2(np.asarray(velocity).astype(cdtype), axes=(0, 1),
                          workers=workers(), overwrite_x=True)
    kept: dict[int, NDArray[np.complexfloating]] = {}  # rows ±κx share their propagator
    for i in range(kx.size):  # row by row: (ny, nf) contiguous, every bin at once
        row = min(i, kx.size - i)
        if row == i:  # the first of the rows ±κx
            kappa2 = (kx[i] ** 2 + ky**2)[:, None]
            kz = np.sqrt(np.clip(kk - kappa2, 0.0, None))
            prop = np.where(kappa2 < kk, np.exp(1j * kz * distance), 0.0)
            kept[row] = prop.astype(cdtype)
        spec[i] *= kept[row] if row == i else kept.pop(row)
    out = scipy.fft.ifft2(spec, axes=(0, 1), workers=workers(), overwrite_x=True)
    return out.astype(np.complex128)


def defocus(velocity: NDArray, grid: PlaneGrid, frequencies: NDArray, medium: Medium, *,
            search: float = 1.5e-3, max_angle: float = np.deg2rad(70.0),
            level: float = 1e-4) -> tuple[float, NDArray[np.float64]]:
    """Distance (m) along +z from the plane of ``velocity`` to where its x profile is
    in focus, per bin and combined.

    For a source that is real up to a constant phase per frequency, the lateral
    spectrum ``U(κx)`` of the y-integrated velocity satisfies
    ``arg U(κx) U(−κx) = 2 φ_f`` at its plane; on a plane a distance d before it (the
    field propagated by −d) the product gains ``−2 kz d``. Per bin, d maximises
    ``|Σ_κx U(κx) U(−κx) e^{+2i (kz − k) d}|`` over the κx with signal (no phase
    unwrapping; sinc zeros flip both factors). Biased by anything that is not in the
    model (the scan window cuts the steep waves of each edge): calibrate it on a
    model (:func:`window_bias_step` does).
    """
    v = np.asarray(velocity)
    u = v.sum(axis=1)  # (nx, nf)
    spec = np.fft.fft(u, axis=0)
    kx = 2 * np.pi * np.fft.fftfreq(grid.x.size, grid.dx)
    pos = kx > 0
    neg_index = (-np.arange(kx.size)) % kx.size
    # the score varies over ≥ π/(2k(1 − cos max_angle)) ≈ 0.1 mm at 5 MHz: 10 µm steps
    # and a parabolic peak
    ds = np.linspace(-search, search, round(2 * search / 10e-6) + 1)
    per_bin = np.full(v.shape[2], np.nan)
    weights = np.zeros(v.shape[2])
    for i, f in enumerate(np.asarray(frequencies, float)):
        k = 2 * np.pi * f / medium.sound_speed
        prod = spec[:, i] * spec[neg_index, i]
        sel = pos & (kx < k * np.sin(max_angle))
        sel &= np.abs(prod) >= level * np.abs(prod[sel]).max()
        if np.count_nonzero(sel) < 3:
            continue
        kz = np.sqrt(k * k - kx[sel] ** 2) - k
        score = np.abs(np.exp(2j * np.outer(ds, kz)) @ prod[sel])
        j = int(np.argmax(score))
        if 0 < j < ds.size - 1:
            y0, y1, y2 = score[j - 1:j + 2]
            j_f = j + 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2)
        else:
            j_f = float(j)
        per_bin[i] = -search + j_f * (ds[1] - ds[0])
        # information on d: curvature of the score, Σ |U U'| (2(kz − k))²
        weights[i] = float(np.sum(np.abs(prod[sel]) * (2 * kz) ** 2))
    ok = np.isfinite(per_bin)
    if not np.any(ok):
        raise FitError("no bin with a lateral spectrum to focus on", field="velocity")
    return float(np.sum(weights[ok] * per_bin[ok]) / np.sum(weights[ok])), per_bin


@dataclass(frozen=True)
class FacePlane:
    """Where the back-projected source is in focus (:func:`face_plane`).

    Attributes
    ----------
    distance, uncertainty : float
        Distance (m) along +z from the back-projection plane to the face, and its
        standard uncertainty (scatter of the per-bin estimates).
    velocity : ndarray, complex, shape (nx, ny, nf)
        The velocity refocused onto the face (all bins).
    aperture : ApertureFit
        :func:`fit_aperture` of ``velocity``.
    nearby : ApertureFit
        ``aperture`` moved by the change of the fit on the model's bins one uncertainty
        further (the face's share of the uncertainty of W, H and the centre).
    bias : ApertureBias
        :func:`scan_window_bias` of the last pass's model (lens fitted on the model
        when ``lens_options`` were given).
    """

    distance: float
    uncertainty: float
    velocity: NDArray[np.complex128]
    aperture: ApertureFit
    nearby: ApertureFit
    bias: ApertureBias


def _shifted(grid: PlaneGrid, distance: float) -> PlaneGrid:
    """``grid`` seen from a source frame moved by ``distance`` along its +z."""
    x0, y0, z0 = grid.pose.origin
    return grid.with_pose(dataclasses.replace(grid.pose, origin=(x0, y0, z0 - distance)))


def _lateral_of(fit: ApertureFit, source: ApertureFit) -> ApertureFit:
    """``fit`` with the lateral width and centre (and their uncertainties) of
    ``source``."""
    return dataclasses.replace(fit, width=source.width, center_x=source.center_x,
                               width_uncertainty=source.width_uncertainty,
                               center_x_uncertainty=source.center_x_uncertainty)


def _model_bias(model: NDArray, grid: PlaneGrid, f: NDArray, medium: Medium,
                fit: ApertureFit, lens: LensFit | None, aperture_options: dict[str, Any],
                lens_options: dict[str, Any] | None, keep_lateral: bool = False
                ) -> ApertureBias:
    """Refit of a model velocity minus the model's parameters (``keep_lateral``: the
    model's width and centre along x are taken as known, their bias is 0)."""
    refit = fit_aperture(model, grid, f, medium, **aperture_options)
    if keep_lateral:
        refit = _lateral_of(refit, fit)
    d_focus = float("nan")
    if lens_options is not None and lens is not None and lens.significant:
        try:
            d_focus = fit_lens_focus(model, grid, f, medium, refit,
                                     **lens_options).focus - lens.focus
        except (InputError, FitError):
            pass
    return ApertureBias(width=refit.width - fit.width, height=refit.height - fit.height,
                        center_x=refit.center_x - fit.center_x,
                        center_y=refit.center_y - fit.center_y,
                        focus=float(d_focus), frequencies=f)


def face_plane(
    velocity: NDArray, grid: PlaneGrid, frequencies: NDArray[np.float64], medium: Medium,
    aperture: ApertureFit, lens: LensFit | None, scan_grid: PlaneGrid, *,
    aperture_options: dict[str, Any], lens_options: dict[str, Any] | None = None,
    strips: Strips | None = None, max_bins: int = 12, iterations: int = 2,
    guard_angle: float = np.deg2rad(80.0), eps: float = 1e-6, keep_lateral: bool = False,
    single_precision: bool = True,
) -> FacePlane:
    """The plane where the back-projected source is in focus, and the window bias there.

    The onset convention (z0 ← z0 + c0 t0) puts the back-projection plane where a
    threshold crossing of the mean velocity says, up to a millimetre from the face; W
    and H change by about 0.2 µm per µm of defocus. :func:`defocus` of the data, minus
    :func:`defocus` of the model of :func:`model_velocity` (which carries the
    estimator's window bias but is in focus by construction), moves the plane towards
    the face; the velocity is refocused there (:func:`refocus`), refitted and the model
    remade, ``iterations`` times (on the model's bins; the last fit on all bins).

    Parameters
    ----------
    velocity : ndarray, complex, shape (nx, ny, nf)
        Back-projected normal velocity on ``grid`` (z = 0 of the source frame).
    grid : PlaneGrid
        The source-plane grid.
    frequencies : ndarray, shape (nf,)
        Its bins (Hz).
    medium : Medium
        c0.
    aperture, lens
        The fits at the back-projection plane (start of the model).
    scan_grid : PlaneGrid
        The scan grid posed relative to the source frame.
    aperture_options, lens_options : dict
        Keyword arguments of :func:`fit_aperture` / :func:`fit_lens_focus` (the
        refits of the model; no lens refit without ``lens_options``).
    strips, max_bins, guard_angle, eps
        As :func:`model_velocity`.
    iterations : int
        Refocus passes (2–3 converge to a few µm on the twins).
    keep_lateral : bool
        Keep ``aperture``'s width and centre along x through the refits (an array
        whose width is its nominal N·p because dead elements cut its lateral profile:
        a profile refit would lock onto one side of the hole and shrink the model's
        strips); only H, y_c and the lens are refitted then, and the returned fits
        carry ``aperture``'s lateral values.
    single_precision : bool
        The refocusing transforms in complex64 (:func:`refocus`; the pipelines pass
        ``backprojection.single_precision``), else complex128.

    Returns
    -------
    FacePlane
    """
    f = np.asarray(frequencies, float)
    sel = np.searchsorted(f, np.asarray(aperture.frequencies, float)[_pick(aperture, max_bins)])
    fm, v_sub = f[sel], np.asarray(velocity)[:, :, sel]
    face, fit, per_bin_diff = 0.0, aperture, np.zeros(1)
    single = bool(single_precision)  # the model's bins on the plane:
    at_face = refocus(v_sub, grid, fm, medium, face, single_precision=single)
    passes = max(1, int(iterations))
    for n in range(passes):
        model, _ = model_velocity(_shifted(scan_grid, face), grid, medium, fit, lens,
                                  strips=strips, max_bins=max_bins,
                                  guard_angle=guard_angle, eps=eps,
                                  noise_axis="y" if keep_lateral else "x")
        model_fit = fit
        d_data, pb_data = defocus(at_face, grid, fm, medium)
        d_model, pb_model = defocus(model, grid, fm, medium)
        face += d_data - d_model
        per_bin_diff = pb_data - pb_model
        if n == passes - 1:  # every bin refocused once; the model's are among them
            focused = refocus(velocity, grid, f, medium, face, single_precision=single)
            at_face = np.ascontiguousarray(focused[:, :, sel])
        else:
            at_face = refocus(v_sub, grid, fm, medium, face, single_precision=single)
        sub = fit_aperture(at_face, grid, fm, medium, **aperture_options)
        if keep_lateral:
            sub = _lateral_of(sub, aperture)
        # the model keeps the all-bin fit's per-bin amplitudes
        fit = dataclasses.replace(fit, width=sub.width, height=sub.height,
                                  center_x=sub.center_x, center_y=sub.center_y)
    ok = np.isfinite(per_bin_diff)
    spread = float(np.std(per_bin_diff[ok])) if np.count_nonzero(ok) > 1 else 0.0
    sigma = spread / math.sqrt(max(int(np.count_nonzero(ok)) - 1, 1))
    bias = _model_bias(model, grid, fm, medium, model_fit, lens, aperture_options,
                       lens_options, keep_lateral)
    final = fit_aperture(focused, grid, f, medium, **aperture_options)
    nearby = fit_aperture(refocus(v_sub, grid, fm, medium, face + sigma,
                                  single_precision=single), grid, fm, medium,
                          **aperture_options)
    if keep_lateral:
        final, nearby, sub = (_lateral_of(final, aperture), _lateral_of(nearby, aperture),
                              _lateral_of(sub, aperture))
    nearby = dataclasses.replace(nearby, width=final.width + nearby.width - sub.width,
                                 height=final.height + nearby.height - sub.height,
                                 center_x=final.center_x + nearby.center_x - sub.center_x,
                                 center_y=final.center_y + nearby.center_y - sub.center_y)
    return FacePlane(float(face), float(sigma), focused, final, nearby, bias)
