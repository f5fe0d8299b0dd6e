"""Tests of holoprobe.propagation.project against analytic fields and the Rayleigh oracle.

Analytic truth: a point source e^{ikR}/R placed at a *complex* depth
(z_s = −a + i b, Deschamps' complex source point) is an exact outgoing solution
of the Helmholtz equation in front of the source; it is a Gaussian-like beam whose
field is captured by a finite scan. A real point source (b = 0) is also tested:
its grazing waves are never captured by a finite scan, which bounds how well
*any* back-projection can do (error ~ √(λ/L)); there we check the method against
the dense Rayleigh oracle on the same truncated data and the error against the
analytic field with a tolerance stating that physics.
"""

from __future__ import annotations

import numpy as np
import pytest

import holoprobe as hp
from holoprobe.errors import InputError
from holoprobe.propagation import padded_shape, project

MEDIUM = hp.Medium()


class PointSource:
    """e^{ikR}/R with R = |r − r_s|, r_s possibly complex (complex source point)."""

    def __init__(self, position: complex | np.ndarray):
        self.position = np.asarray(position, dtype=complex)

    def pressure(self, points: np.ndarray, k: float) -> np.ndarray:
        d = points.astype(complex) - self.position
        r = np.sqrt(np.sum(d * d, axis=1))
        # e^{−k Im z_s} keeps a complex source's beam of order one (no overflow)
        return np.exp(1j * k * r - k * self.position[2].imag) / r

    def normal_velocity(self, points: np.ndarray, normals: np.ndarray, k: float) -> np.ndarray:
        """V = ∇P·n / (i ω ρ0) in holoprobe's e^{−iωt} convention."""
        d = points.astype(complex) - self.position
        r = np.sqrt(np.sum(d * d, axis=1))
        dp_dr = (1j * k - 1 / r) * self.pressure(points, k)
        return dp_dr * np.sum(d * normals, axis=1) / r / (1j * k * MEDIUM.impedance)


def beam_source(frequency: float, waist: float, depth: float = 5e-3,
                lateral=(0.5e-3, -0.3e-3)) -> PointSource:
    """Complex source point whose beam has 1/e amplitude radius ``waist`` at its waist."""
    k = 2 * np.pi * frequency / MEDIUM.sound_speed
    b = 0.5 * k * waist**2
    return PointSource(np.array([lateral[0], lateral[1], -depth + 1j * b]))


def scan_field(source: PointSource, grid: hp.PlaneGrid, freqs: np.ndarray) -> np.ndarray:
    pts = grid.points()
    ks = MEDIUM.wavenumber(freqs)
    return np.stack([source.pressure(pts, k) for k in ks], axis=-1).reshape(*grid.shape, -1)


def rel_l2(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


FREQS = np.array([1.0e6, 1.6e6])
TILTED = hp.Pose.from_degrees(8.0, -10.0, 5.0, (0.4e-3, 0.2e-3, 7e-3))


@pytest.fixture(scope="module")
def tilted_beam_scan():
    source = beam_source(FREQS[0], waist=4e-3)
    scan = hp.PlaneGrid.centered(110, 100, 0.42e-3, pose=TILTED)
    return source, scan, scan_field(source, scan, FREQS)


@pytest.mark.parametrize("method", ["nufft", "rayleigh"])
def test_backprojection_of_tilted_beam_matches_analytic_pressure_and_velocity(
        tilted_beam_scan, method):
    source, scan, field = tilted_beam_scan
    target = hp.PlaneGrid.centered(48, 40, 0.5e-3)  # the source plane z = 0
    pts = target.points()
    normals = np.tile([0.0, 0.0, 1.0], (target.size, 1))
    p = project(field, scan, target, FREQS, MEDIUM, method=method)
    v = project(field, scan, target, FREQS, MEDIUM, method=method, quantity="normal_velocity")
    for i, k in enumerate(MEDIUM.wavenumber(FREQS)):
        p_true = source.pressure(pts, k).reshape(target.shape)
        v_true = source.normal_velocity(pts, normals, k).reshape(target.shape)
        assert rel_l2(p[:, :, i], p_true) < 1e-3
        assert rel_l2(v[:, :, i], v_true) < 1e-3


def test_nufft_backprojection_of_captured_beam_is_accurate_to_nufft_tolerance(
        tilted_beam_scan):
    source, scan, field = tilted_beam_scan
    target = hp.PlaneGrid.centered(48, 40, 0.5e-3)
    p = project(field, scan, target, FREQS, MEDIUM, eps=1e-9)
    for i, k in enumerate(MEDIUM.wavenumber(FREQS)):
        assert rel_l2(p[:, :, i], source.pressure(target.points(), k).reshape(48, 40)) < 1e-6


def test_nufft_and_rayleigh_agree_from_tilted_plane_to_plane(tilted_beam_scan):
    _, scan, field = tilted_beam_scan
    target = hp.PlaneGrid.centered(40, 36, 0.5e-3,
                                   pose=hp.Pose.from_degrees(0.0, 3.0, 0.0, (0, 0, 1e-3)))
    fast = project(field, scan, target, FREQS, MEDIUM, method="nufft")
    exact = project(field, scan, target, FREQS, MEDIUM, method="rayleigh")
    assert rel_l2(fast, exact) < 1e-4


def curved_surface(radius: float, z_apex: float, facing: float = 1.0) -> hp.Surface:
    """A cylindrical strip (curved-array face) bulging towards +z, apex at z_apex."""
    theta = np.linspace(-0.3, 0.3, 36)
    y = np.linspace(-6e-3, 6e-3, 25)
    t, yy = np.meshgrid(theta, y, indexing="ij")
    points = np.stack([radius * np.sin(t).ravel(), yy.ravel(),
                       (radius * np.cos(t) - radius + z_apex).ravel()], axis=-1)
    normals = facing * np.stack([np.sin(t).ravel(), 0 * t.ravel(), np.cos(t).ravel()], axis=-1)
    weights = np.full(points.shape[0], radius * 0.6 / 35 * 12e-3 / 24)
    return hp.Surface(points, normals, weights)


@pytest.mark.parametrize("quantity", ["pressure", "normal_velocity"])
def test_backprojection_onto_curved_surface_matches_analytic_and_rayleigh(
        tilted_beam_scan, quantity):
    source, scan, field = tilted_beam_scan
    surface = curved_surface(radius=30e-3, z_apex=0.5e-3)
    fast = project(field, scan, surface, FREQS, MEDIUM, quantity=quantity)
    exact = project(field, scan, surface, FREQS, MEDIUM, quantity=quantity, method="rayleigh")
    assert rel_l2(fast, exact) < 1e-4
    for i, k in enumerate(MEDIUM.wavenumber(FREQS)):
        if quantity == "pressure":
            truth = source.pressure(surface.points, k)
        else:
            truth = source.normal_velocity(surface.points, surface.normals, k)
        assert rel_l2(fast[:, i], truth) < 1e-5


def test_forward_projection_onto_curved_surface_in_front_matches_rayleigh(tilted_beam_scan):
    source, scan, field = tilted_beam_scan
    surface = curved_surface(radius=25e-3, z_apex=14e-3)
    fast = project(field, scan, surface, FREQS, MEDIUM)
    exact = project(field, scan, surface, FREQS, MEDIUM, method="rayleigh")
    assert rel_l2(fast, exact) < 1e-4
    k = MEDIUM.wavenumber(FREQS[1])
    assert rel_l2(fast[:, 1], source.pressure(surface.points, k)) < 1e-5


def test_forward_then_backward_returns_the_band_limited_source():
    freqs = np.array([1.2e6])
    k = MEDIUM.wavenumber(freqs[0])
    source_plane = hp.PlaneGrid.centered(96, 96, 0.4e-3)
    rng = np.random.default_rng(3)
    # a random band-limited source: random angular spectrum inside |κ| < 0.7 k, smooth edges
    kx = 2 * np.pi * np.fft.fftfreq(96, 0.4e-3)
    kr = np.hypot(kx[:, None], kx[None, :])
    spectrum = (rng.standard_normal((96, 96)) + 1j * rng.standard_normal((96, 96)))
    spectrum *= kr < 0.7 * k
    u = source_plane.x
    envelope = np.exp(-(u[:, None] ** 2 + u[None, :] ** 2) / (2 * (3.5e-3) ** 2))
    field0 = (np.fft.ifft2(spectrum) * envelope)[:, :, None]
    mid = hp.PlaneGrid.centered(120, 110, 0.4e-3,
                                pose=hp.Pose.from_degrees(4.0, -6.0, 2.0, (0, 0, 6e-3)))
    forward = project(field0, source_plane, mid, freqs, MEDIUM, eps=1e-10)
    back = project(forward, mid, source_plane, freqs, MEDIUM, eps=1e-10)
    # reference: the source without its evanescent part
    spec0 = np.fft.fft2(field0[:, :, 0], s=(384, 384))
    kx4 = 2 * np.pi * np.fft.fftfreq(384, 0.4e-3)
    band = np.hypot(kx4[:, None], kx4[None, :]) < k
    limited = np.fft.ifft2(spec0 * band)[:96, :96]
    assert rel_l2(back[:, :, 0], limited) < 1e-4


def test_angular_spectrum_method_matches_nufft_on_parallel_plane():
    source = beam_source(FREQS[0], waist=3e-3)
    scan = hp.PlaneGrid.centered(90, 80, 0.4e-3, pose=hp.Pose(origin=(0, 0, 4e-3)))
    field = scan_field(source, scan, FREQS)
    target = hp.PlaneGrid(scan.x[10:70], scan.y[5:60])  # z = 0, on the scan lattice
    by_as = project(field, scan, target, FREQS, MEDIUM, method="angular_spectrum")
    by_nufft = project(field, scan, target, FREQS, MEDIUM, method="nufft")
    truth = np.stack([source.pressure(target.points(), k).reshape(target.shape)
                      for k in MEDIUM.wavenumber(FREQS)], axis=-1)
    assert rel_l2(by_nufft, truth) < 1e-5
    assert rel_l2(by_as, truth) < 1e-3
    with pytest.raises(InputError, match="parallel"):
        project(field, scan, hp.PlaneGrid.centered(10, 10, 0.33e-3), FREQS, MEDIUM,
                method="angular_spectrum")


def test_time_origin_shifts_phase_by_propagation_distance(tilted_beam_scan):
    _, scan, field = tilted_beam_scan
    target = hp.PlaneGrid.centered(20, 20, 0.5e-3)
    r0 = 2.5e-3
    plain = project(field, scan, target, FREQS, MEDIUM)
    shifted = project(field, scan, target, FREQS, MEDIUM, time_origin=r0)
    expected = plain * np.exp(-1j * MEDIUM.wavenumber(FREQS) * r0)
    assert np.allclose(shifted, expected, rtol=1e-10, atol=1e-12 * np.abs(plain).max())


def test_automatic_padding_keeps_periodic_images_away_from_the_target():
    # a real point source fills the scan edges with oblique waves: without padding
    # their periodic images leak into the target; the automatic rule matches a
    # much larger padding closely
    freqs = np.array([1.0e6])
    point = PointSource(np.array([2e-3, 0.0, -4e-3]))
    scan = hp.PlaneGrid.centered(64, 64, 0.4e-3, pose=hp.Pose(origin=(0, 0, 6e-3)))
    field = scan_field(point, scan, freqs)
    target = hp.PlaneGrid.centered(50, 50, 0.4e-3)
    reference = project(field, scan, target, freqs, MEDIUM, padding=(512, 512))
    auto = project(field, scan, target, freqs, MEDIUM)
    tight = project(field, scan, target, freqs, MEDIUM, padding=1.0)
    assert padded_shape(scan, target)[0] > 64
    assert rel_l2(tight, reference) > 1e-2
    assert rel_l2(auto, reference) < 0.1 * rel_l2(tight, reference)


def test_real_point_source_backprojection_is_limited_by_the_uncaptured_grazing_field():
    """A real point source: both methods see the same truncated data and agree; the
    error against e^{ikR}/R shrinks as the scan grows (slowly: grazing waves)."""
    freqs = np.array([1.0e6])
    k = MEDIUM.wavenumber(freqs[0])
    point = PointSource(np.array([0.5e-3, -0.3e-3, -10e-3]))
    target = hp.PlaneGrid.centered(20, 20, 0.5e-3)
    truth = point.pressure(target.points(), k).reshape(20, 20)
    errors = []
    for n in (80, 200):
        scan = hp.PlaneGrid.centered(n, n, 0.45e-3,
                                     pose=hp.Pose.from_degrees(5, -4, 3, (0, 0, 5e-3)))
        field = scan_field(point, scan, freqs)
        fast = project(field, scan, target, freqs, MEDIUM)[:, :, 0]
        errors.append(rel_l2(fast, truth))
        if n == 80:
            exact = project(field, scan, target, freqs, MEDIUM, method="rayleigh")[:, :, 0]
            assert rel_l2(fast, exact) < 0.05 * rel_l2(exact, truth) + 1e-3
    assert errors[1] < errors[0] < 0.3
    assert errors[1] < 0.1


def test_single_precision_stays_within_its_stated_error(
        tilted_beam_scan):
    source, scan, field = tilted_beam_scan
    target = hp.PlaneGrid.centered(30, 30, 0.5e-3)
    truth = source.pressure(target.points(), MEDIUM.wavenumber(FREQS[0])).reshape(30, 30)
    single = project(field, scan, target, FREQS, MEDIUM, single_precision=True)[:, :, 0]
    assert rel_l2(single, truth) < 1e-4


class TestErrors:
    def test_mismatched_shape(self, tilted_beam_scan):
        _, scan, field = tilted_beam_scan
        with pytest.raises(InputError, match=r"field.*expected shape"):
            project(field[:, :-1], scan, hp.PlaneGrid.centered(4, 4, 1e-3), FREQS, MEDIUM)
        with pytest.raises(InputError, match="field"):
            project(field, scan, hp.PlaneGrid.centered(4, 4, 1e-3), FREQS[:1], MEDIUM)

    def test_nan_in_field(self, tilted_beam_scan):
        _, scan, field = tilted_beam_scan
        bad = field.copy()
        bad[3, 4, 1] = np.nan
        with pytest.raises(InputError, match="NaN"):
            project(bad, scan, hp.PlaneGrid.centered(4, 4, 1e-3), FREQS, MEDIUM)

    def test_non_uniform_or_non_monotonic_grid(self):
        with pytest.raises(InputError, match="not uniform"):
            hp.PlaneGrid(np.array([0.0, 1e-3, 2.5e-3]), np.arange(3) * 1e-3)
        with pytest.raises(InputError, match="monoton"):
            hp.PlaneGrid(np.array([0.0, 2e-3, 1e-3]), np.arange(3) * 1e-3)

    def test_target_straddling_the_source_plane(self, tilted_beam_scan):
        _, scan, field = tilted_beam_scan
        straddling = hp.PlaneGrid.centered(10, 10, 1e-3, pose=hp.Pose(origin=(0, 0, 7e-3)))
        straddling = straddling.with_pose(hp.Pose.from_degrees(0, 30, 0, (0, 0, 7e-3)))
        with pytest.raises(InputError, match="straddles"):
            project(field, scan, straddling, FREQS, MEDIUM)

    def test_scan_coarser_than_half_wavelength(self):
        scan = hp.PlaneGrid.centered(8, 8, 1e-3, pose=hp.Pose(origin=(0, 0, 3e-3)))
        field = np.ones((8, 8, 1), complex)
        target = hp.PlaneGrid.centered(4, 4, 1e-3)
        with pytest.raises(InputError, match="coarser than λ/2"):
            project(field, scan, target, [1e6], MEDIUM)
        project(field, scan, target, [1e6], MEDIUM, allow_undersampled=True)

    def test_rayleigh_forward_velocity_and_on_plane_target_are_refused(self, tilted_beam_scan):
        _, scan, field = tilted_beam_scan
        front = hp.PlaneGrid.centered(4, 4, 1e-3, pose=hp.Pose(origin=(0, 0, 30e-3)))
        with pytest.raises(InputError, match="backward"):
            project(field, scan, front, FREQS, MEDIUM, method="rayleigh",
                    quantity="normal_velocity")
        with pytest.raises(InputError, match="singular"):
            project(field, scan, scan, FREQS, MEDIUM, method="rayleigh")

    def test_bad_frequencies_and_options(self, tilted_beam_scan):
        _, scan, field = tilted_beam_scan
        target = hp.PlaneGrid.centered(4, 4, 1e-3)
        with pytest.raises(InputError, match="positive"):
            project(field, scan, target, [-1e6, 1e6], MEDIUM)
        with pytest.raises(InputError, match="method"):
            project(field, scan, target, FREQS, MEDIUM, method="magic")
        with pytest.raises(InputError, match="quantity"):
            project(field, scan, target, FREQS, MEDIUM, quantity="intensity")


def test_field_on_the_source_plane_itself_is_returned_unchanged(tilted_beam_scan):
    _, scan, field = tilted_beam_scan
    inner = hp.PlaneGrid(scan.x[20:80], scan.y[20:70], scan.pose)
    same = project(field, scan, inner, FREQS, MEDIUM, eps=1e-10)
    assert rel_l2(same, field[20:80, 20:70]) < 1e-6
