"""The hologram twin: CW and transient holograms of bowls and discs with a known truth.

The source (a :class:`~holoprobe.geometry.SourceGeometry`: spherical cap or flat disc)
vibrates with a normal velocity map (:class:`VelocityMap`: amplitude, dead sectors,
phase patches), sits behind the scan plane with a pose (tilt and lateral offset), and
radiates by the **dense Rayleigh integral** (``fwd_vp``) from a *rings* quadrature with
Gauss–Legendre nodes across the rings (``Surface.spherical_cap(layout="rings",
order=3)``) — a finer and structurally different discretisation than the Cartesian
grid an estimator back-projects onto (no inverse crime). See ``docs/simulator.md``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid, Pose, SourceGeometry, Surface
from holoprobe.measurement import Hologram
from holoprobe.propagation import rayleigh_integral
from holoprobe.signal import continuous_spectrum, frequency_axis, to_frequency, to_time
from holoprobe.simulate._focus import focal_truth
from holoprobe.simulate._noise import noise_std_for_snr
from holoprobe.simulate._truth import SimulationTruth, pose_parameters

_MIN_GAP_WAVELENGTHS = 7.0  # O'Neil on axis < 0.5 % from 6.75 λ in front of the apex (tests)

__all__ = ["VelocityMap", "acoustic_power_far_field", "ring_averaged_velocity",
           "simulate_hologram", "source_pose", "tone_burst"]


@dataclass(frozen=True)
class VelocityMap:
    """Complex normal velocity amplitude on a source, in source coordinates.

    Parameters
    ----------
    amplitude : float
        Uniform velocity amplitude u0 in m/s (along the normal, into the medium).
    phase : float
        Uniform phase in rad (holoprobe's convention, ``v(t) = Re{V e^{−iωt}}``).
    dead_sectors : tuple of (float, float)
        Angular sectors (φ_start, φ_end) in rad, φ measured in the source's (x, y)
        plane from +x towards +y, where the velocity is zero.
    phase_patches : tuple of (x, y, radius, phase)
        Discs of the projected (x, y) plane (m) whose velocity is multiplied by
        ``e^{i·phase}`` (rad).
    sector_gains : tuple of complex
        A segmented bowl driven together with unequal segments: n equal sectors, the
        first starting at ``sector_start`` (rad), whose velocity is multiplied by
        these gains (e.g. one weak sector: ``(1, 1, 0.5, 1, 1, 1)``).
    sector_start : float
        Angle of the first sector's start in rad.

    Notes
    -----
    Defects are sharp (no tapering). The twin puts ring borders of its quadrature on
    the radii of patches centred on the axis and averages the map over each point's
    arc (:func:`ring_averaged_velocity`), so sector edges and centred patches
    integrate accurately; the edge of an off-axis patch is resolved to the spacing.
    """

    amplitude: float = 0.1
    phase: float = 0.0
    dead_sectors: tuple[tuple[float, float], ...] = ()
    phase_patches: tuple[tuple[float, float, float, float], ...] = ()
    sector_gains: tuple[complex, ...] = ()
    sector_start: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "sector_gains", tuple(complex(g) for g in self.sector_gains))
        if not all(np.isfinite(g) for g in self.sector_gains):
            raise InputError("expected finite complex gains", field="sector_gains")
        if not (np.isfinite(self.amplitude) and self.amplitude > 0):
            raise InputError(f"expected a positive velocity in m/s, got {self.amplitude!r}",
                             field="amplitude")
        object.__setattr__(self, "dead_sectors",
                           tuple((float(a), float(b)) for a, b in self.dead_sectors))
        object.__setattr__(self, "phase_patches",
                           tuple(tuple(float(v) for v in p) for p in self.phase_patches))
        for p in self.phase_patches:
            if len(p) != 4 or not p[2] > 0:
                raise InputError("expected (x, y, radius > 0, phase) per patch",
                                 field="phase_patches")

    def __call__(self, points: NDArray) -> NDArray[np.complex128]:
        """The velocity (m/s) at points (n, 3) given in source coordinates."""
        x, y = points[:, 0], points[:, 1]
        v = np.full(x.shape, self.amplitude * np.exp(1j * self.phase))
        phi = np.arctan2(y, x)
        for a, b in self.dead_sectors:
            v[np.mod(phi - a, 2 * np.pi) < np.mod(b - a, 2 * np.pi)] = 0.0
        for xc, yc, r, ph in self.phase_patches:
            v[np.hypot(x - xc, y - yc) < r] *= np.exp(1j * ph)
        if self.sector_gains:
            n = len(self.sector_gains)
            idx = np.floor(np.mod(phi - self.sector_start, 2 * np.pi) / (2 * np.pi / n))
            v *= np.asarray(self.sector_gains)[np.clip(idx.astype(int), 0, n - 1)]
        return v

    @property
    def radial_edges(self) -> tuple[float, ...]:
        """Projected radii (m) of the edges of patches centred on the axis."""
        return tuple(r for x, y, r, _ in self.phase_patches if x == 0 and y == 0)

    def describe(self) -> dict[str, Any]:
        """JSON-ready parameters (SI; angles also in degrees)."""
        return {
            "amplitude_m_s": self.amplitude, "phase_rad": self.phase,
            "dead_sectors_deg": [[math.degrees(a), math.degrees(b)]
                                 for a, b in self.dead_sectors],
            "phase_patches": [{"center_m": [x, y], "radius_m": r, "phase_rad": p}
                              for x, y, r, p in self.phase_patches],
            "sector_gains": [[g.real, g.imag] for g in self.sector_gains],
            "sector_start_deg": math.degrees(self.sector_start),
            "frame": "source coordinates: apex at the origin, axis +z; sectors and patches "
                     "in the projected (x, y) plane; v(t) = Re{V exp(-i omega t)} along the "
                     "normal into the medium",
        }


def source_pose(z_position: float, *, tilt: tuple[float, float] = (0.0, 0.0),
                offset: tuple[float, float] = (0.0, 0.0)) -> Pose:
    """Pose of the source in scan coordinates: apex at (x, y, −z_position), tilted.

    Parameters
    ----------
    z_position : float
        Distance of the apex behind the scan plane, m.
    tilt : (float, float)
        Rotations θx, θy (rad) of the source's axis; ``R = Ry(θy) Rx(θx)``.
    offset : (float, float)
        Lateral position (x, y) of the apex in scan coordinates, m.
    """
    return Pose(theta_x=tilt[0], theta_y=tilt[1],
                origin=(float(offset[0]), float(offset[1]), -float(z_position)))


def tone_burst(frequency: float, cycles: float, sampling_rate: float, n: int
               ) -> NDArray[np.float64]:
    """A Hann-windowed tone burst starting at t = 0, ``n`` samples (unit amplitude)."""
    t = np.arange(n) / sampling_rate
    duration = cycles / frequency
    env = np.where(t < duration, np.sin(np.pi * t / duration) ** 2, 0.0)
    return env * np.sin(2 * np.pi * frequency * t)


def _rectangle_quadrature(width: float, height: float, spacing: float) -> Surface:
    """A flat rectangle (width along x, height along y) on 3 × 3 Gauss–Legendre nodes per
    cell of side ≤ ``spacing``: not the estimator's midpoint grid (no inverse crime)."""
    t, w = np.polynomial.legendre.leggauss(3)
    axes = []
    for length in (width, height):
        n = math.ceil(length / spacing)
        h = length / n
        centres = (np.arange(n) + 0.5) * h - 0.5 * length
        axes.append(((centres[:, None] + 0.5 * h * t).ravel(), np.tile(0.5 * h * w, n)))
    (x, wx), (y, wy) = axes
    xx, yy = np.meshgrid(x, y, indexing="ij")
    pts = np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], axis=-1)
    return Surface(pts, np.tile([0.0, 0.0, 1.0], (xx.size, 1)), np.outer(wx, wy).ravel())


def _source_velocity(velocity: VelocityMap, surface: Surface, geometry: SourceGeometry
                     ) -> NDArray[np.complex128]:
    """The velocity at the quadrature nodes: arc-averaged on rings, sampled on a
    rectangle's Gauss–Legendre nodes."""
    if geometry.kind == "flat-rectangle":
        return np.asarray(velocity(surface.points), dtype=np.complex128)
    return ring_averaged_velocity(velocity, surface)


def _synthesis_surface(geometry: SourceGeometry, spacing: float,
                       velocity: VelocityMap | None = None) -> Surface:
    if geometry.kind == "flat-rectangle":
        return _rectangle_quadrature(geometry.aperture_max, geometry.aperture_min, spacing)
    if geometry.kind not in ("spherical-cap", "flat-disc"):
        raise InputError(f"the hologram twin simulates spherical caps, flat discs and "
                         f"rectangles, not {geometry.kind!r}", field="geometry")
    return Surface.spherical_cap(geometry.aperture_max, geometry.radius_of_curvature,
                                 spacing=spacing, opening_diameter=geometry.opening_diameter,
                                 layout="rings", order=3,
                                 radial_edges=() if velocity is None else velocity.radial_edges)


def ring_averaged_velocity(velocity: VelocityMap, surface: Surface, *, m: int = 16
                           ) -> NDArray[np.complex128]:
    """The velocity averaged over each point's arc of its ring (rings layout).

    Points of one ring share their projected radius; each stands for an arc of
    2π/n_ring. Averaging the (piecewise constant) map over ``m`` sub-angles of that
    arc integrates a dead sector's edges (discontinuities in φ) to O(1/m²) of one
    cell; radial discontinuities are best put on ring borders (``radial_edges``).
    """
    p = surface.points
    rho = np.hypot(p[:, 0], p[:, 1])
    _, inverse, counts = np.unique(np.round(rho * 1e9), return_inverse=True,
                                   return_counts=True)
    dphi = 2 * np.pi / counts[inverse]
    phi = np.arctan2(p[:, 1], p[:, 0])
    acc = np.zeros(surface.size, dtype=complex)
    for j in range(m):
        a = phi + ((j + 0.5) / m - 0.5) * dphi
        acc += velocity(np.stack([rho * np.cos(a), rho * np.sin(a), p[:, 2]], axis=-1))
    return np.asarray(acc / m, dtype=np.complex128)


def acoustic_power_far_field(surface: Surface, velocity: NDArray, frequency: float,
                             medium: Medium, *, axis: tuple[float, float, float] = (0.0, 0.0, 1.0),
                             oversampling: float = 1.5, return_direction: bool = False
                             ) -> float | tuple[float, NDArray[np.float64]]:
    """Power (W) radiated into the half-space ahead of a plane normal to ``axis``.

    The Rayleigh (monopole) field of the velocity on ``surface`` is evaluated in the
    far field, ``p ≈ D(û) e^{ikr}/r``, and ``|D|²/(2ρ0c0)`` integrated over the
    hemisphere û·axis > 0 (Gauss–Legendre in cos θ, uniform in φ). With every source
    point behind the plane, this is exactly the power crossing it. The angular
    resolution follows the source's extent (``oversampling`` × the band limit).
    """
    k = 2 * np.pi * frequency / medium.sound_speed
    centre = np.average(surface.points, axis=0, weights=surface.weights)
    extent = float(np.max(np.linalg.norm(surface.points - centre, axis=1)))
    n_mu = max(32, math.ceil(oversampling * k * extent))
    n_phi = max(64, 2 * n_mu)
    mu, wmu = np.polynomial.legendre.leggauss(n_mu)
    mu, wmu = 0.5 * (mu + 1), 0.5 * wmu
    phi = 2 * np.pi * np.arange(n_phi) / n_phi
    st = np.sqrt(1 - mu**2)
    local = np.stack([np.outer(st, np.cos(phi)), np.outer(st, np.sin(phi)),
                      np.outer(mu, np.ones(n_phi))], axis=-1).reshape(-1, 3)
    ax = np.asarray(axis, float) / np.linalg.norm(axis)
    helper = np.array([1.0, 0, 0]) if abs(ax[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(ax, helper)
    e1 /= np.linalg.norm(e1)
    basis = np.stack([e1, np.cross(ax, e1), ax], axis=1)
    far = 1e3 * max(extent, 1e-3) * max(1.0, k * extent)
    targets = Surface(centre + far * local @ basis.T, np.tile(ax, (local.shape[0], 1)),
                      np.ones(local.shape[0]))
    p = rayleigh_integral(velocity, surface, targets, [frequency], medium, kernel="fwd_vp",
                          time_origin=far)[:, 0] * far
    d_omega = np.repeat(wmu, n_phi) * (2 * np.pi / n_phi)
    radiance = np.abs(p) ** 2 * d_omega / (2 * medium.impedance)
    if return_direction:
        direction = (radiance[:, None] * (local @ basis.T)).sum(axis=0)
        return float(radiance.sum()), direction / np.linalg.norm(direction)
    return float(radiance.sum())


@dataclass(frozen=True)
class _Setup:
    geometry: SourceGeometry
    pose: Pose
    grid: PlaneGrid
    medium: Medium
    velocity: VelocityMap
    surface: Surface                # source coordinates
    values: NDArray                 # velocity at the surface points
    targets: Surface = field(init=False)

    def __post_init__(self) -> None:
        pts = self.grid.local_points()
        object.__setattr__(self, "targets", Surface(
            pts, np.tile([0.0, 0.0, -1.0], (pts.shape[0], 1)), np.ones(pts.shape[0])))

    @property
    def placed(self) -> Surface:
        return self.surface.moved(self.pose)


def _cw(setup: _Setup, frequency: float) -> NDArray[np.complex128]:
    p = rayleigh_integral(setup.values, setup.placed, setup.targets, [frequency],
                          setup.medium, kernel="fwd_vp")[:, 0]
    return np.asarray(p, dtype=np.complex128).reshape(setup.grid.shape)


def _transient(setup: _Setup, frequency: float, cycles: float, sampling_rate: float,
               band_db: float) -> tuple[NDArray, float]:
    """Waveforms (nx, ny, nt) and the start time of a tone-burst velocity u0·burst(t)."""
    placed = setup.placed
    c = setup.medium.sound_speed
    from scipy.spatial import cKDTree

    nearest, _ = cKDTree(placed.points).query(setup.targets.points)
    nx, ny = setup.grid.shape
    corners = setup.targets.points.reshape(nx, ny, 3)[[0, 0, -1, -1], [0, -1, 0, -1]]
    farthest = np.linalg.norm(corners[:, None, :] - placed.points[None, :, :], axis=-1).max()
    margin = 3.0 / frequency
    t0 = max(0.0, float(nearest.min()) / c - margin)
    t1 = float(farthest) / c + cycles / frequency + 2 * margin
    nt = math.ceil((t1 - t0) * sampling_rate)
    nt += nt % 2
    spectrum = to_frequency(tone_burst(frequency, cycles, sampling_rate, nt))
    f = frequency_axis(nt, sampling_rate)
    keep = (np.abs(spectrum) >= np.abs(spectrum).max() * 10 ** (band_db / 20)) & (f > 0)
    p_f = rayleigh_integral(setup.values, placed, setup.targets, f[keep], setup.medium,
                            kernel="fwd_vp", time_origin=c * t0)
    full = np.zeros((setup.targets.size, f.size), dtype=complex)
    full[:, keep] = p_f * spectrum[keep]
    return to_time(full, nt).reshape((*setup.grid.shape, nt)), t0


def _band_top(frequency: float, cycles: float, sampling_rate: float, band_db: float) -> float:
    """Highest frequency (Hz) where the burst spectrum is within ``band_db`` of its peak."""
    n = math.ceil(64 * cycles * sampling_rate / frequency)
    spectrum = np.abs(to_frequency(tone_burst(frequency, cycles, sampling_rate, n)))
    f = frequency_axis(n, sampling_rate)
    return float(f[spectrum >= spectrum.max() * 10 ** (band_db / 20)].max())


def _window_power(setup: _Setup, frequency: float) -> float:
    """Power (W) through the part of the scan plane the scan's cells cover."""
    g, lam = setup.grid, float(setup.medium.wavelength(frequency))
    nodes = []
    for axis, step in ((g.x, g.dx), (g.y, g.dy)):
        lo, hi = axis[0] - 0.5 * step, axis[-1] + 0.5 * step
        n = math.ceil(3 * (hi - lo) / lam) + 8
        t, w = np.polynomial.legendre.leggauss(n)
        nodes.append((0.5 * (lo + hi) + 0.5 * (hi - lo) * t, 0.5 * (hi - lo) * w))
    (x, wx), (y, wy) = nodes
    xx, yy = np.meshgrid(x, y, indexing="ij")
    delta = lam * 1e-3
    p = []
    for z in (0.0, delta, -delta):
        pts = np.stack([xx.ravel(), yy.ravel(), np.full(xx.size, z)], -1)
        tgt = Surface(pts, np.tile([0.0, 0.0, 1.0], (pts.shape[0], 1)), np.ones(xx.size))
        p.append(rayleigh_integral(setup.values, setup.placed, tgt, [frequency], setup.medium,
                                   kernel="fwd_vp")[:, 0])
    omega = 2 * np.pi * frequency
    vz = (p[1] - p[2]) / (2 * delta) / (1j * omega * setup.medium.density)
    intensity = 0.5 * np.real(p[0] * np.conj(vz))
    return float(np.sum(intensity * np.outer(wx, wy).ravel()))


def _power_truth(setup: _Setup, frequency: float) -> tuple[dict[str, Any], list[float]]:
    """Power through the scan plane and the power-weighted direction, λ/4 vs λ/3."""
    lam = float(setup.medium.wavelength(frequency))
    results = [acoustic_power_far_field(src.moved(setup.pose),
                                        _source_velocity(setup.velocity, src, setup.geometry),
                                        frequency, setup.medium, oversampling=1.0,
                                        return_direction=True)
               for src in (_synthesis_surface(setup.geometry, lam / 4, setup.velocity),
                           _synthesis_surface(setup.geometry, lam / 3, setup.velocity))]
    # (type: ignore below) two (power, directivity) pairs, one per quadrature
    (p4, d4), (p3, d3) = results  # type: ignore[misc]
    power = {"hologram": p4, "uncertainty": abs(p4 - p3),
             "method": "far-field hemisphere integral of the Rayleigh field (half-space "
                       "ahead of the scan plane), CW at frequency_hz with the velocity map, "
                       "source quadrature lambda/4; uncertainty: difference to lambda/3 "
                       "(measured error of lambda/4 vs lambda/6: 1e-4)",
             "scan_window": _window_power(setup, frequency),
             "scan_window_area": "the rectangle the scan's cells cover, [x0 - dx/2, "
                                 "x_end + dx/2] x [y0 - dy/2, y_end + dy/2]: what a finite "
                                 "hologram can see (Gauss-Legendre integral of the normal "
                                 "intensity of the Rayleigh field)"}
    angle = math.degrees(math.acos(min(1.0, float(d4 @ d3))))
    return power, [*d4.tolist(), max(angle, 1e-6)]


def _pulse_band(frequency: float, cycles: float, sampling_rate: float, band_db: float,
                nodes: int = 24) -> tuple[NDArray, NDArray]:
    """Gauss–Legendre nodes (Hz) over the simulated band and weights |B(f)|² dw (s²·Hz).

    B is the burst's continuous spectrum (not the record's bins: the truth's own
    quadrature of ∫ |B|² |p_f|² df); the band is where |B| is within ``band_db`` of its
    peak, as in :func:`_transient`.
    """
    n = math.ceil(64 * cycles * sampling_rate / frequency)
    burst = tone_burst(frequency, cycles, sampling_rate, n)
    spectrum = np.abs(to_frequency(burst))
    f = frequency_axis(n, sampling_rate)
    inside = f[(spectrum >= spectrum.max() * 10 ** (band_db / 20)) & (f > 0)]
    t, w = np.polynomial.legendre.leggauss(nodes)
    lo, hi = float(inside.min()), float(inside.max())
    freqs = 0.5 * (lo + hi) + 0.5 * (hi - lo) * t
    b = continuous_spectrum(burst, sampling_rate, freqs)
    return freqs, np.abs(b) ** 2 * 0.5 * (hi - lo) * w


def _alignment_truth(setup: _Setup, frequency: float, with_focus: bool,
                     band: tuple[NDArray, NDArray] | None = None) -> dict[str, Any]:
    """Geometric axis and focus; the focal maximum and lobe axis of the field (focused):
    CW at ``frequency``, or of a pulse's ``band`` (:func:`_pulse_band`)."""
    g, pose = setup.geometry, setup.pose
    out: dict[str, Any] = {
        "axis_direction": pose.normal.tolist(), "focus_position": None,
        "geometric_axis": pose.normal.tolist(), "apex_position": pose.origin_array.tolist(),
        "frame": "scan coordinates: origin at the grid's x = 0, y = 0 on the scan plane, "
                 "x/y along the grid axes, z normal to the plane pointing away from the "
                 "source"}
    if g.radius_of_curvature is None:
        return out
    centre = pose.origin_array + g.radius_of_curvature * pose.normal
    out["geometric_focus"] = centre.tolist()
    if not with_focus:
        out["axis_direction"] = None
        return out
    lam = float(setup.medium.wavelength(frequency))
    found = []
    for sp in (lam / 4, lam / 3):
        src = _synthesis_surface(g, sp, setup.velocity)
        found.append(focal_truth(src.moved(pose), ring_averaged_velocity(setup.velocity, src),
                                 frequency, setup.medium, centre, pose.normal, band=band))
    best, check = found
    out.update({
        "axis_direction": best.axis.tolist(), "focus_position": best.focus.tolist(),
        "focus_uncertainty_m": float(np.linalg.norm(best.focus - check.focus)) + 1e-8,
        "axis_uncertainty_deg": math.degrees(math.acos(min(1.0, float(best.axis @ check.axis))))
        + 1e-6,
        "focal_pressure_pa": best.pressure, "axial_extent_m": list(best.axial_extent),
        "definition": "focus_position: the focal pressure maximum; axis_direction: the "
                      "least-squares line through the in-plane pressure maxima in 9 planes "
                      "across the focal lobe spanning 0.8 of its -6 dB axial extent each "
                      "side (3 re-orientations); CW at frequency_hz"})
    if band is not None:
        out["definition"] = (
            "transient: focus_position: the maximum of the pulse-pressure-squared integral "
            "(integral of p(t)^2 dt = 2 * integral of |B(f)|^2 |p_f|^2 df over the simulated "
            f"band, {band[0].size} Gauss-Legendre nodes); axis_direction: the least-squares "
            "line through its in-plane maxima in 9 planes across the lobe spanning 0.8 of "
            "its -6 dB (half-amplitude of the root) axial extent each side (3 "
            "re-orientations); focal_pressure_pa: the root of the weighted sum (Pa s)")
    return out


def _velocity_map(setup: _Setup, step: float) -> dict[str, NDArray]:
    g = setup.geometry
    xs = np.arange(-0.5 * g.aperture_max, 0.5 * g.aperture_max + 1e-12, step)
    xx, yy = np.meshgrid(xs, xs, indexing="ij")
    pts = np.stack([xx.ravel(), yy.ravel(), 0 * xx.ravel()], -1)
    rho = np.hypot(xx, yy)
    inside = (rho <= 0.5 * g.aperture_max) & (rho >= 0.5 * g.opening_diameter)
    if g.kind == "flat-rectangle":   # width (aperture_max) along x, height along y
        inside = (np.abs(xx) <= 0.5 * g.aperture_max) & (np.abs(yy) <= 0.5 * g.aperture_min)
    vmap = np.where(inside, setup.velocity(pts).reshape(xx.shape), np.nan + 0j)
    return {"velocity_map": vmap, "velocity_map_x": xs, "velocity_map_y": xs}


def _truth(setup: _Setup, frequency: float, signal: str, noise: dict[str, Any],
           spacing: float, with_power: bool, with_focus: bool,
           band: tuple[NDArray, NDArray] | None = None) -> SimulationTruth:
    g, pose = setup.geometry, setup.pose
    alignment = _alignment_truth(setup, frequency, with_focus, band)
    power = None
    if with_power:
        power, direction = _power_truth(setup, frequency)
        alignment["power_direction"] = direction[:3]
        alignment["power_direction_uncertainty_deg"] = direction[3]
    params = {
        "kind": "hologram", "signal": signal, "frequency_hz": frequency,
        "medium": {"density_kg_m3": setup.medium.density,
                   "sound_speed_m_s": setup.medium.sound_speed},
        "source": {"kind": g.kind, "radius_of_curvature": g.radius_of_curvature,
                   "aperture_diameter": g.aperture_max, "opening_diameter": g.opening_diameter},
        "alignment": alignment,
        "pose": pose_parameters(pose),
        "z_position_m": -pose.origin[2],
        "acoustic_power": power,
        "velocity": setup.velocity.describe(),
        "grid": {"nx": setup.grid.shape[0], "ny": setup.grid.shape[1], "dx_m": setup.grid.dx,
                 "dy_m": setup.grid.dy},
        "noise": noise,
        "synthesis": {"method": "dense Rayleigh fwd_vp (holoprobe.propagation."
                                "rayleigh_integral) from the source quadrature",
                      "quadrature": ("3 x 3 Gauss-Legendre nodes per cell of a rectangle "
                                     "(width along x)" if g.kind == "flat-rectangle" else
                                     "rings of equal arc width, 3 Gauss-Legendre nodes across "
                                     "each, uniform around (Surface.spherical_cap(layout="
                                     "'rings', order=3))"),
                      "spacing_m": spacing, "points": setup.surface.size,
                      "min_distance_to_scan_plane_m": float(-setup.placed.points[:, 2].max())},
    }
    lam = float(setup.medium.wavelength(frequency))
    return SimulationTruth(params, _velocity_map(setup, lam / 4))


def simulate_hologram(
    geometry: SourceGeometry,
    *,
    frequency: float = 1.0e6,
    signal: str = "cw",
    z_position: float | None = None,
    tilt: tuple[float, float] = (0.0, 0.0),
    offset: tuple[float, float] = (0.0, 0.0),
    shape: tuple[int, int] = (61, 61),
    step: tuple[float, float] | None = None,
    velocity: VelocityMap | None = None,
    medium: Medium | None = None,
    snr_db: float | None = None,
    seed: int = 0,
    spacing: float | None = None,
    cycles: float = 5.0,
    sampling_rate: float | None = None,
    band_db: float = -40.0,
    power: bool = True,
    focus: bool = True,
    band_focus: bool = False,
) -> tuple[Hologram, SimulationTruth]:
    """Simulate a CW or transient hologram of a bowl, a disc or a rectangle with a known truth.

    Parameters
    ----------
    geometry : SourceGeometry
        ``spherical-cap`` or ``flat-disc`` (with an optional central opening), or
        ``flat-rectangle`` (width ``aperture_max`` along x, height ``aperture_min`` along
        y; 3 × 3 Gauss–Legendre nodes per cell).
    frequency : float
        CW frequency, or the centre frequency of the transient tone burst, Hz.
    signal : {"cw", "transient"}
        CW complex amplitude or waveforms of a Hann tone burst of ``cycles`` cycles
        (velocity ``u0 · burst(t)`` with the map's spatial pattern).
    z_position : float, optional
        Distance of the apex behind the scan plane, m (default: half the radius of
        curvature of a bowl, 10 wavelengths for a disc).
    tilt, offset : (float, float)
        Pose of the source relative to the scan plane: rotations θx, θy of its axis
        (rad) and the lateral position of its apex (m), see :func:`source_pose`.
    shape, step : (int, int), (float, float)
        Scan grid (nx, ny) centred on x = y = 0, steps in m (default λ/2).
    velocity : VelocityMap
        Normal velocity (default uniform 0.1 m/s).
    medium : Medium
        Default water at 20 °C.
    snr_db : float, optional
        Peak SNR (``20 log10(max|p| / σ)``) of additive white Gaussian noise; for CW σ
        is the std of the complex noise (σ/√2 per component). None: no noise.
    seed : int
        Noise seed.
    spacing : float, optional
        Twin quadrature spacing in m (default λ/4 at the highest simulated frequency).
    cycles, sampling_rate, band_db : float
        Transient only: burst length, sampling rate (default 10 × frequency) and the
        level (dB re the peak of the burst spectrum) that delimits the simulated band.
    power : bool
        Compute the true acoustic power and power-weighted direction (a few seconds;
        ``acoustic_power`` is null without it).
    focus : bool
        Compute the true focal maximum and focal-lobe axis of a bowl (a few seconds;
        without it ``focus_position`` and ``axis_direction`` are null for a bowl).
    band_focus : bool
        Transient bowls: the truth's focus and lobe axis are those of the pulse (the
        maximum of the pulse-pressure-squared integral ∫ p² dt over the simulated band,
        24 Gauss–Legendre frequencies: ~24× the CW truth's cost), the definition of
        ``hologram.transient_focus = "band"``; False (default): CW at ``frequency``.

    Returns
    -------
    (Hologram, SimulationTruth)
        The hologram (its grid has the *nominal* pose: apex on the axis at
        ``z_position``; the true pose is in the truth) and the truth (``truth.json``
        parameters, ``truth.h5`` velocity map).
    """
    if signal not in ("cw", "transient"):
        raise InputError(f"expected 'cw' or 'transient', got {signal!r}", field="signal")
    medium = medium or Medium()
    velocity = velocity or VelocityMap()
    lam = float(medium.wavelength(frequency))
    if z_position is None:
        roc = geometry.radius_of_curvature
        z_position = 10 * lam if roc is None else 0.5 * roc
    step = step or (lam / 2, lam / 2)
    grid = PlaneGrid.centered(shape[0], shape[1], step[0], step[1])
    fs = sampling_rate or 10.0 * frequency
    f_max = _band_top(frequency, cycles, fs, band_db) if signal == "transient" else frequency
    spacing = spacing or float(medium.wavelength(f_max)) / 4
    surface = _synthesis_surface(geometry, spacing, velocity)
    setup = _Setup(geometry, source_pose(z_position, tilt=tilt, offset=offset), grid, medium,
                   velocity, surface, _source_velocity(velocity, surface, geometry))
    if np.any(setup.placed.points[:, 2] >= 0):
        raise InputError("the source reaches the scan plane: increase z_position or reduce "
                         "the tilt", field="z_position")
    gap = float(-setup.placed.points[:, 2].max())
    if gap < _MIN_GAP_WAVELENGTHS * lam:
        warnings.warn(f"the scan plane is {gap / lam:.1f} wavelengths from the nearest source "
                      f"point: the twin's quadrature (spacing {spacing * 1e3:.3g} mm) is "
                      f"verified to 0.5 % from {_MIN_GAP_WAVELENGTHS} wavelengths on",
                      UserWarning, stacklevel=2)
    rng = np.random.default_rng(seed)
    nominal = grid.with_pose(Pose(origin=(0.0, 0.0, z_position)))
    if signal == "cw":
        data = _cw(setup, frequency)
        sigma = 0.0 if snr_db is None else noise_std_for_snr(data, snr_db)
        data = data + sigma / np.sqrt(2) * (rng.standard_normal(data.shape)
                                            + 1j * rng.standard_normal(data.shape))
        holo = Hologram(data, nominal, medium, frequency=frequency, geometry=geometry,
                        source="simulated")
    else:
        data, t0 = _transient(setup, frequency, cycles, fs, band_db)
        sigma = 0.0 if snr_db is None else noise_std_for_snr(data, snr_db)
        data = data + sigma * rng.standard_normal(data.shape)
        holo = Hologram(data, nominal, medium, sampling_rate=fs, start_time=t0,
                        geometry=geometry, source="simulated")
    noise = {"snr_db": snr_db, "sigma_pa": sigma, "seed": seed}
    band = _pulse_band(frequency, cycles, fs, band_db) \
        if signal == "transient" and band_focus else None
    truth = _truth(setup, frequency, signal, noise, spacing, power, focus, band)
    if signal == "transient":
        truth.parameters.update({"cycles": cycles, "sampling_rate_hz": holo.sampling_rate,
                                 "start_time_s": holo.start_time,
                                 "velocity_waveform": "u0 * hann(t/T)^2 sin(2 pi f t), "
                                                      "T = cycles/f, from t = 0"})
    return holo, truth
