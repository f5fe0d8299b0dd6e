"""Tests of the dense Rayleigh integrals against analytic fields and independent paths."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import exp1

from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid, Pose, Surface
from holoprobe.propagation import rayleigh_integral, rayleigh_time_domain
from holoprobe.signal import frequency_axis, to_frequency, to_time

MEDIUM = Medium()
RHO_C = MEDIUM.impedance


# --------------------------------------------------------------------------- helpers
def ring_disk(radius: float, n_rings: int, n_angles: int, z: float = 0.0) -> Surface:
    """Midpoint-rule quadrature of a disk in concentric rings (normals +z)."""
    dr = radius / n_rings
    r = (np.arange(n_rings) + 0.5) * dr
    phi = 2 * np.pi * (np.arange(n_angles) + 0.5) / n_angles
    rr, pp = np.meshgrid(r, phi, indexing="ij")
    pts = np.stack([rr * np.cos(pp), rr * np.sin(pp), np.full(rr.shape, z)], -1).reshape(-1, 3)
    w = np.repeat(2 * np.pi * r * dr / n_angles, n_angles)
    return Surface(pts, np.tile([0.0, 0.0, 1.0], (pts.shape[0], 1)), w)


def axis_points(z: np.ndarray) -> Surface:
    pts = np.stack([np.zeros_like(z), np.zeros_like(z), z], -1)
    return Surface(pts, np.tile([0.0, 0.0, 1.0], (z.size, 1)), np.ones(z.size))


def complex_source_beam(points: np.ndarray, k: float, z_src: float, b: float):
    """Field e^{ikR}/R of a point source at the complex position (0, 0, z_src + ib).

    An exact outgoing solution of the Helmholtz equation for z > z_src: a Gaussian
    beam along +z (waist at z_src, Rayleigh range b), so it decays quickly across a
    plane and carries practically no evanescent waves (weight e^{-kb}). Returns the
    pressure (npts,) and its gradient (npts, 3).
    """
    d = points - np.array([0.0, 0.0, z_src])
    zeta = d[:, 2] - 1j * b
    big_r = np.sqrt(d[:, 0] ** 2 + d[:, 1] ** 2 + zeta**2)
    p = np.exp(1j * k * big_r - k * b) / big_r
    dp = (1j * k - 1.0 / big_r) * p / big_r
    grad = np.stack([dp * d[:, 0], dp * d[:, 1], dp * zeta], -1)
    return p, grad


def normal_velocity(grad: np.ndarray, normals: np.ndarray, k: float) -> np.ndarray:
    """V = ∇p·n / (ikρ0c0) (Euler's equation for e^{-iωt})."""
    return np.einsum("nk,nk->n", grad, normals) / (1j * k * RHO_C)


def rel_err(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def gaussian_pulse(t: np.ndarray, f0: float = 2e6, t_c: float = 1.5e-6,
                   sigma: float = 0.4e-6) -> np.ndarray:
    return np.exp(-(((t - t_c) / sigma) ** 2)) * np.sin(2 * np.pi * f0 * (t - t_c))


# --------------------------------------------------------------------------- analytic piston
@pytest.mark.parametrize("baffle", ["rigid", "soft", "free"])
def test_baffled_piston_on_axis_matches_analytic_pressure(baffle):
    a, u0 = 3e-3, 0.01
    src = ring_disk(a, 300, 12)
    z = np.concatenate([np.linspace(1e-3, 5e-3, 9), np.linspace(6e-3, 40e-3, 12)])
    f = np.array([1.0e6, 2.5e6, 4.0e6])
    k = MEDIUM.wavenumber(f)[None, :]
    p = rayleigh_integral(np.full((src.size, f.size), u0, dtype=complex), src, axis_points(z),
                          f, MEDIUM, kernel="fwd_vp", baffle=baffle)
    zz = z[:, None]
    ra = np.sqrt(zz**2 + a**2)
    rigid = RHO_C * u0 * (np.exp(1j * k * zz) - np.exp(1j * k * ra))
    # soft baffle (β = cos θ = z/R): -ikρc u0 z ∫_z^{Ra} e^{ikR}/R dR
    soft = -1j * k * RHO_C * u0 * zz * (exp1(-1j * k * zz) - exp1(-1j * k * ra))
    truth = {"rigid": rigid, "soft": soft, "free": 0.5 * (rigid + soft)}[baffle]
    err = np.abs(p - truth) / np.abs(truth).max(axis=0)
    assert err.max() < 2e-3


# --------------------------------------------------------------------------- kernel pairs
def test_fwd_vp_and_fwd_pp_both_reproduce_field_of_source_behind_plane():
    f = np.array([2.0e6, 2.5e6, 3.0e6])
    k = MEDIUM.wavenumber(f)
    z_src, b = -2e-3, 2e-3
    plane = PlaneGrid.centered(101, 101, 0.1e-3).to_surface()  # Σ1, n1 = +z
    targets = Surface([[0, 0, 1e-3], [0.5e-3, -0.3e-3, 3e-3], [-1e-3, 0.8e-3, 6e-3],
                       [0.2e-3, 0.1e-3, 2e-3]], np.tile([0, 0, 1.0], (4, 1)), np.ones(4))
    p_plane = np.empty((plane.size, f.size), complex)
    v_plane = np.empty_like(p_plane)
    truth = np.empty((targets.size, f.size), complex)
    for n, kn in enumerate(k):
        p, grad = complex_source_beam(plane.points, kn, z_src, b)
        p_plane[:, n] = p
        v_plane[:, n] = normal_velocity(grad, plane.normals, kn)
        truth[:, n] = complex_source_beam(targets.points, kn, z_src, b)[0]
    p_vp = rayleigh_integral(v_plane, plane, targets, f, MEDIUM, kernel="fwd_vp")
    p_pp = rayleigh_integral(p_plane, plane, targets, f, MEDIUM, kernel="fwd_pp")
    assert rel_err(p_vp, truth) < 1e-4
    assert rel_err(p_pp, truth) < 1e-4
    assert rel_err(p_vp, p_pp) < 1e-4


def test_backprojection_from_tilted_plane_recovers_pressure_and_normal_velocity():
    """bwd_pp and bwd_pv from a 10°-tilted scan plane onto a nearer plane z = 0.5 mm."""
    f = np.array([2.5e6, 3.0e6])
    k = MEDIUM.wavenumber(f)
    z_src, b = -2e-3, 2e-3
    scan = PlaneGrid.centered(141, 141, 0.1e-3,
                              pose=Pose.from_degrees(0.0, 10.0, 0.0, (0.2e-3, 0.0, 4e-3)))
    sigma2 = scan.to_surface(flip_normal=True)  # n2 points back towards the source
    sigma1 = PlaneGrid.centered(9, 9, 0.3e-3, pose=Pose(origin=(0, 0, 0.5e-3))).to_surface()
    p_scan = np.empty((sigma2.size, f.size), complex)
    p_true = np.empty((sigma1.size, f.size), complex)
    v_true = np.empty_like(p_true)
    for n, kn in enumerate(k):
        p_scan[:, n] = complex_source_beam(sigma2.points, kn, z_src, b)[0]
        p, grad = complex_source_beam(sigma1.points, kn, z_src, b)
        p_true[:, n] = p
        v_true[:, n] = normal_velocity(grad, sigma1.normals, kn)
    p_back = rayleigh_integral(p_scan, sigma2, sigma1, f, MEDIUM, kernel="bwd_pp")
    v_back = rayleigh_integral(p_scan, sigma2, sigma1, f, MEDIUM, kernel="bwd_pv")
    assert rel_err(p_back, p_true) < 2e-3
    assert rel_err(v_back, v_true) < 2e-3


def test_bwd_pp_and_bwd_pv_agree_with_forward_pair_round_trip():
    """Forward with fwd_pp then backward with bwd_pp returns the source pressure."""
    f = np.array([2.5e6])
    k = MEDIUM.wavenumber(f)[0]
    z_src, b = -1.5e-3, 2.5e-3
    sigma1 = PlaneGrid.centered(101, 101, 0.1e-3).to_surface()
    scan = PlaneGrid.centered(121, 121, 0.1e-3, pose=Pose(origin=(0, 0, 3e-3)))
    sigma2_fwd = scan.to_surface()
    sigma2 = scan.to_surface(flip_normal=True)
    p1, _ = complex_source_beam(sigma1.points, k, z_src, b)
    p_scan = rayleigh_integral(p1[:, None], sigma1, sigma2_fwd, f, MEDIUM, kernel="fwd_pp")
    probe = PlaneGrid.centered(7, 7, 0.25e-3).to_surface()
    p_back = rayleigh_integral(p_scan, sigma2, probe, f, MEDIUM, kernel="bwd_pp")
    v_back = rayleigh_integral(p_scan, sigma2, probe, f, MEDIUM, kernel="bwd_pv")
    p_true, g_true = complex_source_beam(probe.points, k, z_src, b)
    assert rel_err(p_back[:, 0], p_true) < 2e-3
    assert rel_err(v_back[:, 0], normal_velocity(g_true, probe.normals, k)) < 2e-3


# --------------------------------------------------------------------------- backends
def _random_case(rng, n_src=150, n_dst=70):
    src = PlaneGrid.centered(15, 10, 0.3e-3, pose=Pose.from_degrees(2, -3, 1)).to_surface()
    tgt_pts = rng.uniform([-3e-3, -3e-3, 2e-3], [3e-3, 3e-3, 30e-3], size=(n_dst, 3))
    tgt_n = rng.normal(size=(n_dst, 3)) + np.array([0.0, 0.0, 3.0])
    return src, Surface(tgt_pts, tgt_n, rng.uniform(1e-8, 2e-8, n_dst))


@pytest.mark.parametrize("kernel", ["fwd_vp", "fwd_pp", "bwd_pp", "bwd_pv"])
def test_numba_and_numpy_backends_agree_for_every_kernel(kernel):
    rng = np.random.default_rng(3)
    src, dst = _random_case(rng)
    f = np.array([0.7e6, 1.3e6, 2.9e6, 4.4e6])  # not uniform: direct evaluation
    values = rng.normal(size=(src.size, 4)) + 1j * rng.normal(size=(src.size, 4))
    common = dict(kernel=kernel, baffle="free", time_origin=2.5e-3)
    ref = rayleigh_integral(values, src, dst, f, MEDIUM, backend="numpy", **common)
    fast = rayleigh_integral(values, src, dst, f, MEDIUM, backend="numba", **common)
    f32 = rayleigh_integral(values, src, dst, f, MEDIUM, backend="numba", dtype=np.float32,
                            **common)
    np32 = rayleigh_integral(values, src, dst, f, MEDIUM, backend="numpy", dtype=np.float32,
                             **common)
    assert fast.dtype == np.complex128 and f32.dtype == np.complex64
    assert rel_err(fast, ref) < 1e-12
    assert rel_err(f32, ref) < 2e-5
    assert rel_err(np32, ref) < 2e-5


def test_phasor_recurrence_over_1000_bins_matches_direct_evaluation():
    rng = np.random.default_rng(4)
    src, _ = _random_case(rng)
    far = Surface(rng.uniform([-5e-3, -5e-3, 60e-3], [5e-3, 5e-3, 80e-3], (30, 3)),
                  np.tile([0, 0, 1.0], (30, 1)), np.ones(30))
    f = 0.5e6 + 10e3 * np.arange(1000)  # uniform: recurrence; kR up to ~3400 rad
    values = rng.normal(size=(src.size, f.size)) + 1j * rng.normal(size=(src.size, f.size))
    direct = rayleigh_integral(values, src, far, f, MEDIUM, kernel="fwd_pp", backend="numpy")
    rec = rayleigh_integral(values, src, far, f, MEDIUM, kernel="fwd_pp", backend="numba")
    rec32 = rayleigh_integral(values, src, far, f, MEDIUM, kernel="fwd_pp", backend="numba",
                              dtype=np.float32)
    scale = np.abs(direct).max(axis=0)
    assert np.max(np.abs(rec - direct) / scale) < 1e-10
    assert np.max(np.abs(rec32 - direct) / scale) < 2e-5


@pytest.mark.parametrize("backend", ["numba", "numpy"])
def test_tiny_max_memory_gives_same_result_as_unchunked(backend):
    rng = np.random.default_rng(5)
    src, dst = _random_case(rng, n_dst=25)
    f = 1e6 + 0.25e6 * np.arange(6)
    values = rng.normal(size=(src.size, f.size)) + 0j
    full = rayleigh_integral(values, src, dst, f, MEDIUM, kernel="bwd_pv", backend=backend)
    tiny = rayleigh_integral(values, src, dst, f, MEDIUM, kernel="bwd_pv", backend=backend,
                             max_memory=1000)
    np.testing.assert_allclose(tiny, full, rtol=1e-13, atol=1e-13 * np.abs(full).max())


# --------------------------------------------------------------------------- time domain
def test_time_domain_matches_frequency_domain_for_delayed_piston_pulse():
    fs, nt, n_rec = 40e6, 128, 512
    grid = PlaneGrid.centered(31, 31, 0.1e-3)
    keep = np.hypot(*grid.local_points()[:, :2].T) <= 1.5e-3
    full = grid.to_surface()
    src = Surface(full.points[keep], full.normals[keep], full.weights[keep])
    tau = (src.points[:, 0] ** 2 + src.points[:, 1] ** 2) / (2 * 20e-3 * MEDIUM.sound_speed)
    tau += 40e-9 * src.points[:, 0] / 1.5e-3  # a steering term: asymmetric delays
    tgt = Surface([[0, 0, 5e-3], [1e-3, 0, 8e-3], [-0.5e-3, 1e-3, 3e-3]],
                  np.tile([0, 0, 1.0], (3, 1)), np.ones(3))
    t = np.arange(nt) / fs
    v = 0.02 * gaussian_pulse(t)
    r0 = 2e-3  # record starts at t = r0/c0
    p_td = rayleigh_time_domain(v, src, tgt, fs, MEDIUM, delays=tau, n_samples=n_rec,
                                start_time=r0 / MEDIUM.sound_speed, baffle="soft")
    f = frequency_axis(n_rec, fs)
    spec = to_frequency(v, n=n_rec)
    values = spec[None, 1:] * np.exp(1j * 2 * np.pi * f[None, 1:] * tau[:, None])
    p_f = rayleigh_integral(values, src, tgt, f[1:], MEDIUM, kernel="fwd_vp",
                            time_origin=r0, baffle="soft")
    p_fd = to_time(np.concatenate([np.zeros((tgt.size, 1)), p_f], axis=1), n_rec)
    assert rel_err(p_td, p_fd) < 1e-3
    assert np.abs(p_fd).max() > 100.0  # tens of kPa for 2 cm/s: not a trivially zero field


def test_transient_piston_on_axis_matches_analytic_edge_and_plane_waves():
    fs, nt = 50e6, 200
    a = 2e-3
    src = ring_disk(a, 400, 8)
    z = np.array([1e-3, 3e-3, 10e-3])
    t_v = np.arange(nt) / fs
    p = rayleigh_time_domain(0.01 * gaussian_pulse(t_v), src, axis_points(z), fs, MEDIUM,
                             n_samples=700)
    t = np.arange(700) / fs
    c = MEDIUM.sound_speed
    truth = RHO_C * 0.01 * (gaussian_pulse(t[None, :] - z[:, None] / c)
                            - gaussian_pulse(t[None, :] - np.hypot(z, a)[:, None] / c))
    assert rel_err(p, truth) < 1e-3


def test_time_domain_per_point_velocity_equals_shared_velocity_with_delays():
    """Per-point records that are delayed copies give the same field as delays=."""
    fs, nt = 40e6, 160
    src = PlaneGrid.centered(6, 5, 0.2e-3).to_surface()
    tgt = Surface([[0.3e-3, 0, 4e-3]], [[0, 0, 1.0]], [1.0])
    tau = np.linspace(0, 0.3e-6, src.size)
    t = np.arange(nt) / fs
    per_point = np.stack([gaussian_pulse(t - d) for d in tau])
    a = rayleigh_time_domain(per_point, src, tgt, fs, MEDIUM, n_samples=400, max_memory=20000)
    b = rayleigh_time_domain(gaussian_pulse(t), src, tgt, fs, MEDIUM, delays=tau, n_samples=400)
    assert rel_err(a, b) < 1e-4


def test_cubic_interpolation_error_of_time_domain_is_as_documented():
    """A tone at fs/5, one source point: relative error ≤ 0.0235 (2πf/(U fs))⁴."""
    fs, nt = 40e6, 400
    f0 = fs / 5
    t = np.arange(nt) / fs
    env = np.exp(-(((t - 5e-6) / 1.2e-6) ** 2))
    v = env * np.sin(2 * np.pi * f0 * t)
    src = Surface([[0, 0, 0]], [[0, 0, 1.0]], [1.0])
    tgt = Surface([[0, 0, 1.23456e-3]], [[0, 0, 1.0]], [1.0])
    for upsample in (4, 8):
        p = rayleigh_time_domain(v, src, tgt, fs, MEDIUM, upsample=upsample, n_samples=nt)
        delay = 1.23456e-3 / MEDIUM.sound_speed
        tt = t - delay
        # ρ0/(2πR) v̇(t − R/c0), v̇ analytic
        env_d = np.exp(-(((tt - 5e-6) / 1.2e-6) ** 2))
        dv = (env_d * 2 * np.pi * f0 * np.cos(2 * np.pi * f0 * tt)
              - 2 * (tt - 5e-6) / 1.2e-6**2 * env_d * np.sin(2 * np.pi * f0 * tt))
        truth = MEDIUM.density / (2 * np.pi * 1.23456e-3) * dv
        bound = 0.0235 * (2 * np.pi * f0 / (upsample * fs)) ** 4
        assert rel_err(p[0], truth) < 1.5 * bound + 1e-6


# --------------------------------------------------------------------------- errors
def _small():
    src = PlaneGrid.centered(3, 3, 1e-3).to_surface()
    dst = PlaneGrid.centered(2, 2, 1e-3, pose=Pose(origin=(0, 0, 5e-3))).to_surface()
    return src, dst


@pytest.mark.parametrize(
    ("change", "field"),
    [
        (dict(values=np.ones((8, 2))), "values"),
        (dict(values=np.full((9, 2), np.nan)), "values"),
        (dict(frequencies=[0.0, 1e6]), "frequencies"),
        (dict(frequencies=[-1e6, 1e6]), "frequencies"),
        (dict(frequencies=[np.inf, 1e6]), "frequencies"),
        (dict(kernel="fwd_vv"), "kernel"),
        (dict(baffle="hard"), "baffle"),
        (dict(backend="cuda"), "backend"),
        (dict(dtype=np.int32), "dtype"),
        (dict(max_memory=0), "max_memory"),
        (dict(max_memory=1.5), "max_memory"),
        (dict(time_origin=np.nan), "time_origin"),
    ],
)
def test_bad_input_raises_input_error_naming_the_field(change, field):
    src, dst = _small()
    args = dict(values=np.ones((9, 2)), frequencies=[1e6, 2e6], kernel="fwd_vp")
    args.update(change)
    with pytest.raises(InputError) as info:
        rayleigh_integral(args.pop("values"), src, dst, args.pop("frequencies"), MEDIUM, **args)
    assert info.value.field == field


@pytest.mark.parametrize("backend", ["numba", "numpy"])
def test_coincident_points_are_reported_by_index(backend):
    src, _ = _small()
    dst = Surface([[0, 0, 5e-3], src.points[4]], [[0, 0, 1.0]] * 2, [1.0, 1.0])
    with pytest.raises(InputError, match=r"point 1 of to_surface coincides with point 4"):
        rayleigh_integral(np.ones((9, 1)), src, dst, [1e6], MEDIUM, kernel="fwd_pp",
                          backend=backend)
    with pytest.raises(InputError, match=r"point 1 of target coincides with point 4"):
        rayleigh_time_domain(np.ones(10), src, dst, 1e7, MEDIUM)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        (dict(velocity=np.ones((4, 10))), "velocity"),
        (dict(velocity=np.full(10, np.inf)), "velocity"),
        (dict(sampling_rate=-1.0), "sampling_rate"),
        (dict(delays=np.zeros(8)), "delays"),
        (dict(apodization=[np.nan] * 9), "apodization"),
        (dict(baffle="none"), "baffle"),
        (dict(n_samples=0), "n_samples"),
        (dict(upsample=0), "upsample"),
    ],
)
def test_bad_time_domain_input_raises_input_error(kwargs, field):
    src, dst = _small()
    args = dict(velocity=np.ones(10), sampling_rate=1e7)
    args.update(kwargs)
    with pytest.raises(InputError) as info:
        rayleigh_time_domain(args.pop("velocity"), src, dst, args.pop("sampling_rate"), MEDIUM,
                             **args)
    assert info.value.field == field


def test_separable_source_with_delays_equals_general_per_frequency_values():
    """values_i · e^{iωτ_i} given as (weights, delays) must equal the general (n, nf) form."""
    rng = np.random.default_rng(11)
    src = PlaneGrid.centered(12, 9, 0.2e-3).to_surface()
    dst = PlaneGrid.centered(7, 6, 0.5e-3, pose=Pose.from_degrees(3, -2, 1, (0, 0, 4e-3))
                                ).to_surface()
    freqs = np.linspace(1e6, 3e6, 21)  # uniform: phasor recurrence path
    medium = Medium()
    weights = rng.standard_normal(src.size) + 1j * rng.standard_normal(src.size)
    delays = rng.uniform(0, 200e-9, src.size)
    general = weights[:, None] * np.exp(1j * 2 * np.pi * freqs[None, :] * delays[:, None])
    reference = rayleigh_integral(general, src, dst, freqs, medium, kernel="fwd_vp",
                                  backend="numpy")
    for backend in ("numba", "numpy"):
        separable = rayleigh_integral(weights, src, dst, freqs, medium, kernel="fwd_vp",
                                      source_delays=delays, backend=backend)
        assert np.max(np.abs(separable - reference)) < 1e-11 * np.max(np.abs(reference))
    with pytest.raises(InputError, match="forward"):
        rayleigh_integral(weights, src, dst, freqs, medium, kernel="bwd_pp",
                          source_delays=delays)
