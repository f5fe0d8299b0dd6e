"""Tests of holoprobe.propagation.ProjectionPlan: reuse, adjoint (dot tests), physics.

The dot test (PyLops' ``dottest``) checks ⟨A x, y⟩ = ⟨x, A^H y⟩ for random x on the
source grid and y on the target, with A the plan's forward projection and A^H its
``adjoint``: this fails for any sign, phase-origin, scatter or weight error in the
adjoint. Separately, between parallel planes with the same padded grid, the
*backward projection* computed by ``project`` (a different code path: the padded
FFT of the target-plane data, the kernel with w < 0) must equal A^H, because every
propagating backward plane wave is the conjugate of the forward one.
"""

from __future__ import annotations

import numpy as np
import pytest

import holoprobe as hp
from holoprobe.errors import InputError
from holoprobe.propagation import ProjectionPlan, project

MEDIUM = hp.Medium()
FREQS = np.array([0.8e6, 1.5e6, 2.2e6])
STEP = 0.3e-3  # λ/2 at 2.5 MHz


def _random(shape, seed):
    rng = np.random.default_rng(seed)
    return rng.standard_normal(shape) + 1j * rng.standard_normal(shape)


def _source():
    return hp.PlaneGrid.centered(20, 16, STEP, pose=hp.Pose.from_degrees(
        1.0, -2.0, 3.0, (0.2e-3, -0.1e-3, 2e-3)))


def _targets():
    tilted = hp.PlaneGrid.centered(12, 10, 0.25e-3, pose=hp.Pose.from_degrees(
        4.0, 3.0, -10.0, (0.5e-3, 0.3e-3, 8e-3)))
    behind = hp.PlaneGrid.centered(18, 14, STEP, pose=hp.Pose.from_degrees(
        0.5, -1.0, 0.0, (0.0, 0.0, 0.0)))
    rng = np.random.default_rng(5)
    pts = rng.uniform([-3e-3, -2e-3, 5e-3], [3e-3, 2e-3, 9e-3], size=(40, 3))
    normals = rng.standard_normal((40, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    cloud = hp.Surface(pts, normals, np.ones(40))
    return {"tilted plane": tilted, "plane behind": behind, "points": cloud}


@pytest.mark.parametrize("name", ["tilted plane", "plane behind", "points"])
@pytest.mark.parametrize("quantity", ["pressure", "normal_velocity"])
def test_dot_test_forward_and_adjoint_projections(name, quantity):
    src = _source()
    target = _targets()[name]
    x = _random((*src.shape, FREQS.size), 1)
    plan = ProjectionPlan(x, src, FREQS, MEDIUM, eps=1e-12)
    ax = plan.project(target, quantity=quantity, time_origin=1e-3)
    y = _random(ax.shape, 2)
    aty = plan.adjoint(y, target, quantity=quantity, time_origin=1e-3)
    lhs, rhs = np.vdot(y, ax), np.vdot(aty, x)
    assert abs(lhs) > 0
    assert abs(lhs - rhs) <= 1e-9 * abs(lhs)


@pytest.mark.parametrize("quantity", ["pressure", "normal_velocity"])
def test_backward_projection_between_parallel_planes_is_the_adjoint(quantity):
    pose = hp.Pose.from_degrees(0.7, -1.2, 2.0, (0.1e-3, 0.2e-3, 1e-3))
    src = hp.PlaneGrid.centered(18, 16, STEP, pose=pose)
    # a parallel plane 4 mm in front, same steps, shifted by whole steps laterally
    front = hp.PlaneGrid(src.x + 3 * STEP, src.y - 2 * STEP, hp.Pose.from_degrees(
        0.7, -1.2, 2.0, pose.to_global(np.array([[0.0, 0.0, 4e-3]]))[0]))
    shape = (64, 60)
    y = _random((*front.shape, FREQS.size), 3)
    plan = ProjectionPlan(np.zeros((*src.shape, FREQS.size), complex), src, FREQS, MEDIUM,
                          eps=1e-12, padding=shape)
    adjoint = plan.adjoint(y, front, quantity=quantity)
    backward = project(y, front, src, FREQS, MEDIUM, quantity=quantity, eps=1e-12,
                       padding=shape)
    err = np.linalg.norm(backward - adjoint) / np.linalg.norm(adjoint)
    assert err < 1e-9


def test_plan_reuses_its_spectra_and_matches_one_call_projections(monkeypatch):
    src = _source()
    x = _random((*src.shape, FREQS.size), 4)
    targets = _targets()
    plan = ProjectionPlan(x, src, FREQS, MEDIUM)
    calls = []
    original = ProjectionPlan._transform

    def counting(self, shape, progress, first=0):
        calls.append(shape)
        return original(self, shape, progress, first)

    monkeypatch.setattr(ProjectionPlan, "_transform", counting)
    # the farthest target needs the widest padding: the nearer ones reuse its spectra
    order = ["points", "tilted plane", "plane behind"]
    results = {name: plan.project(targets[name]) for name in order}
    assert len(calls) == 1 and plan.nbytes > 0
    for name in order:
        one_call = project(x, src, targets[name], FREQS, MEDIUM, padding=plan.shape)
        np.testing.assert_allclose(results[name], one_call, rtol=0, atol=1e-12 * np.abs(
            one_call).max())


def test_plan_rejects_bad_input():
    src = _source()
    with pytest.raises(InputError, match="shape"):
        ProjectionPlan(np.zeros((3, 3, 3)), src, FREQS)
    plan = ProjectionPlan(np.zeros((*src.shape, FREQS.size)), src, FREQS)
    with pytest.raises(InputError, match="PlaneGrid or"):
        plan.project("not a target")  # type: ignore[arg-type]  # the bad input under test
    with pytest.raises(InputError, match="shape"):
        plan.adjoint(np.zeros((2, 2, 3)), _targets()["tilted plane"])


def test_exact_padding_plan_gives_the_one_call_numbers_bit_for_bit(monkeypatch):
    """``exact_padding``: every target gets the padding rule's own size, so a plan reused
    over many targets (the receive pose refinement, the hologram fits) returns exactly
    what ``project()`` returns for each; the spectra are transformed once per distinct
    size, and those of an earlier size are dropped first (one set held at a time)."""
    src = _source()
    x = _random((*src.shape, FREQS.size), 6)
    targets = _targets()
    plan = ProjectionPlan(x, src, FREQS, MEDIUM, exact_padding=True)
    calls = []
    original = ProjectionPlan._transform

    def counting(self, shape, progress, first=0):
        if self is plan:  # not the one-call projections' own plans
            calls.append((shape, self.nbytes))
        return original(self, shape, progress, first)

    monkeypatch.setattr(ProjectionPlan, "_transform", counting)
    shapes = [plan.padded_shape(targets[name]) for name in ("points", "tilted plane")]
    assert shapes[0] != shapes[1]  # the case under test: two different sizes
    assert plan.prepare(targets["points"]) == shapes[0]  # then reused by the first call
    for name, quantity in (("points", "pressure"), ("tilted plane", "normal_velocity"),
                           ("points", "pressure")):
        one_call = project(x, src, targets[name], FREQS, MEDIUM, quantity=quantity,
                           time_origin=1e-3)
        assert np.array_equal(plan.project(targets[name], quantity=quantity,
                                           time_origin=1e-3), one_call)
    assert [shape for shape, _ in calls] == [shapes[0], shapes[1], shapes[0]]
    assert [held for _, held in calls] == [0, 0, 0]


def test_a_cache_budget_keeps_the_first_frequencies_and_transforms_the_rest(monkeypatch):
    """``max_cache_bytes``: the spectra of the first frequencies that fit are kept, the
    others transformed again at each projection; the numbers stay project()'s."""
    src = _source()
    x = _random((*src.shape, FREQS.size), 7)
    target = _targets()["tilted plane"]
    full = ProjectionPlan(x, src, FREQS, MEDIUM, exact_padding=True)
    full.prepare(target)
    first = full._blocks[0].values.nbytes
    plan = ProjectionPlan(x, src, FREQS, MEDIUM, exact_padding=True,
                          max_cache_bytes=first)
    firsts = []
    original = ProjectionPlan._transform

    def counting(self, shape, progress, first=0):
        if self is plan:
            firsts.append(first)
        return original(self, shape, progress, first)

    monkeypatch.setattr(ProjectionPlan, "_transform", counting)
    one_call = project(x, src, target, FREQS, MEDIUM)
    for _ in range(2):
        assert np.array_equal(plan.project(target), one_call)
    assert firsts == [0, 1] and plan.nbytes == first
    with pytest.raises(InputError, match="byte count"):
        ProjectionPlan(x, src, FREQS, MEDIUM, max_cache_bytes=-1)


@pytest.mark.parametrize("name", ["tilted plane", "points"])
def test_a_complex64_result_holds_the_single_precision_numbers(name):
    """``project(dtype=np.complex64)`` of a single-precision plan stores exactly the
    numbers of the default complex128 result (the transforms are complex64 either way),
    in half the memory; other types are refused."""
    src = _source()
    x = _random((*src.shape, FREQS.size), 8)
    target = _targets()[name]
    plan = ProjectionPlan(x, src, FREQS, MEDIUM, single_precision=True)
    wide = plan.project(target, time_origin=1e-3)
    narrow = plan.project(target, time_origin=1e-3, dtype=np.complex64)
    assert wide.dtype == np.complex128 and narrow.dtype == np.complex64
    assert np.abs(wide).max() > 0
    assert np.array_equal(narrow.astype(np.complex128), wide)
    with pytest.raises(InputError, match="complex64 or complex128"):
        plan.project(target, dtype=np.float32)


def test_image_taper_keeps_the_padded_images_away_from_a_far_target():
    """A point source 1.5 mm behind a 12 mm scan fills it with steep waves; a small
    target 25–40 mm away sees the scan within ~20°, so with a 30° (or even 60°) guard
    the steep waves of the periodic images dominate there. The image taper fades the
    waves out between the steepest scan→target line and the nearest image's direction:
    it must then agree with the dense Rayleigh integral of the same (non-periodic)
    data, which has no images at all."""
    from tests.propagation.test_project import PointSource, rel_l2, scan_field

    freqs = np.array([1.2e6, 1.6e6])
    scan = hp.PlaneGrid.centered(40, 36, 0.3e-3)
    field = scan_field(PointSource(np.array([0.3e-3, -0.2e-3, -1.5e-3])), scan, freqs)
    target = hp.PlaneGrid.centered(6, 5, 0.3e-3, pose=hp.Pose.from_degrees(
        0.0, 4.0, 0.0, (0.0, 0.5e-3, 25e-3)))
    exact = project(field, scan, target, freqs, MEDIUM, method="rayleigh")
    for guard in (30.0, 60.0):
        kw = {"eps": 1e-9, "guard_angle": np.deg2rad(guard)}
        plain = ProjectionPlan(field, scan, freqs, MEDIUM, **kw).project(target)
        plan = ProjectionPlan(field, scan, freqs, MEDIUM, image_taper=True, **kw)
        tapered = plan.project(target)
        s_in, s_out = plan.taper_range(target, plan.padded_shape(target))
        assert 0.3 < s_in < s_out < 1.0
        assert rel_l2(plain, exact) > 0.1  # the images
        assert rel_l2(tapered, exact) < 1e-2


@pytest.mark.parametrize("name", ["tilted plane", "points"])
def test_dot_test_with_the_image_taper(name):
    src = _source()
    far = hp.Pose.from_degrees(4.0, 3.0, -10.0, (0.5e-3, 0.3e-3, 30e-3))
    rng = np.random.default_rng(5)
    normals = rng.standard_normal((30, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    target = (hp.PlaneGrid.centered(8, 6, 0.25e-3, pose=far) if name == "tilted plane"
              else hp.Surface(rng.uniform([-1e-3, -1e-3, 28e-3], [1e-3, 1e-3, 31e-3],
                                          size=(30, 3)), normals, np.ones(30)))
    x = _random((*src.shape, FREQS.size), 1)
    plan = ProjectionPlan(x, src, FREQS, MEDIUM, eps=1e-12, guard_angle=np.deg2rad(20.0),
                          image_taper=True)
    assert plan.taper_range(target, plan.padded_shape(target)) is not None
    ax = plan.project(target, time_origin=1e-3)
    y = _random(ax.shape, 2)
    aty = plan.adjoint(y, target, time_origin=1e-3)
    lhs, rhs = np.vdot(y, ax), np.vdot(aty, x)
    assert abs(lhs) > 0
    assert abs(lhs - rhs) <= 1e-9 * abs(lhs)
    untapered = ProjectionPlan(x, src, FREQS, MEDIUM, eps=1e-12,
                               guard_angle=np.deg2rad(20.0)).project(target, time_origin=1e-3)
    assert np.linalg.norm(ax - untapered) > 1e-3 * np.linalg.norm(untapered)


@pytest.mark.parametrize("groups, m, single", [(4, 3, False), (3, 4, False), (5, 1, True)])
@pytest.mark.parametrize("quantity", ["pressure", "normal_velocity"])
def test_reduced_projection_is_the_weighted_sum_of_the_grid(groups, m, single, quantity):
    """``project_reduced`` (two 1-D NUFFTs per plane wave, no target grid) gives the
    column-kernel × row-weight sums of ``project``'s grid (the 2-D NUFFT) to the
    tolerance: an error in a mode index, a group phase or the kernel's orientation
    moves the result by O(1). Odd and even group counts, kernel sizes and rows."""
    src = _source()
    x = _random((*src.shape, FREQS.size), 9)
    ny = 7 if groups % 2 else 6
    target = hp.PlaneGrid.centered(groups * m, ny, 0.25e-3, pose=hp.Pose.from_degrees(
        4.0, 3.0, -10.0, (0.5e-3, 0.3e-3, 8e-3)))
    rng = np.random.default_rng(3)
    kernel = rng.uniform(0.0, 1.0, m)
    rows = np.exp(1j * rng.uniform(0.0, 2 * np.pi, (FREQS.size, ny)))
    plan = ProjectionPlan(x, src, FREQS, MEDIUM, eps=1e-6 if single else 1e-9,
                          single_precision=single)
    grid = plan.project(target, quantity=quantity, time_origin=7e-3)
    expected = np.einsum("gkjf,k,fj->gf", grid.reshape(groups, m, ny, -1), kernel, rows)
    reduced = plan.project_reduced(target, kernel, rows, quantity=quantity, time_origin=7e-3)
    assert reduced.shape == (groups, FREQS.size)
    error = np.abs(reduced - expected).max() / np.abs(expected).max()
    assert error <= (2e-5 if single else 1e-8)
    with pytest.raises(InputError, match="divides"):
        plan.project_reduced(target, np.ones(groups * m + 1), rows)
    with pytest.raises(InputError, match="row weights"):
        plan.project_reduced(target, kernel, rows[:, 1:])


def test_reduced_projection_applies_the_image_taper():
    """With ``image_taper`` the reduced sums are those of the tapered grid."""
    src = _source()
    x = _random((*src.shape, FREQS.size), 4)
    target = hp.PlaneGrid.centered(12, 6, 0.25e-3, pose=hp.Pose.from_degrees(
        4.0, 3.0, -10.0, (0.5e-3, 0.3e-3, 30e-3)))
    plan = ProjectionPlan(x, src, FREQS, MEDIUM, eps=1e-9, guard_angle=np.deg2rad(20.0),
                          image_taper=True)
    assert plan.taper_range(target, plan.padded_shape(target)) is not None
    kernel, rows = np.ones(3), np.ones((FREQS.size, 6))
    expected = plan.project(target).reshape(4, 3, 6, -1).sum(axis=(1, 2))
    reduced = plan.project_reduced(target, kernel, rows)
    assert np.abs(reduced - expected).max() <= 1e-8 * np.abs(expected).max()
    plain = ProjectionPlan(x, src, FREQS, MEDIUM, eps=1e-9, guard_angle=np.deg2rad(20.0))
    assert np.abs(plain.project_reduced(target, kernel, rows) - expected).max() > (
        1e-3 * np.abs(expected).max())  # the taper matters here


@pytest.mark.parametrize("quantity", ["pressure", "normal_velocity"])
def test_a_plan_from_the_spectrum_projects_the_data_it_transforms(quantity):
    """``from_spectrum``: two point sources on a 40 × 36 period, given by their DFT
    written analytically (Σ_s a_s e^{−iκ·(r_s − r_0)}, no FFT), project as the plan made
    from the same points on that plane (its own padded FFT), on targets in front of it
    and behind; blocks cut to the rows and columns |κ| < k carry every wave."""
    shape = (40, 36)  # FFT-friendly: the period of the plane as given
    plane = hp.PlaneGrid(STEP * (np.arange(shape[0]) - 20.0), STEP * (np.arange(shape[1]) - 18.0),
                         hp.Pose.from_degrees(1.0, -2.0, 3.0, (0.2e-3, -0.1e-3, 2e-3)))
    points = [(12, 20, 1.0 + 0.5j), (27, 9, -0.7 + 0.2j)]
    data = np.zeros((*shape, FREQS.size), complex)
    for i, j, a in points:
        data[i, j] = a * np.array([1.0, 0.6 - 0.3j, 0.2j])
    kx = 2 * np.pi * np.fft.fftfreq(shape[0], STEP)
    ky = 2 * np.pi * np.fft.fftfreq(shape[1], STEP)
    blocks = []
    for n, f in enumerate(FREQS):
        k = 2 * np.pi * f / MEDIUM.sound_speed
        rows, cols = np.flatnonzero(np.abs(kx) < k), np.flatnonzero(np.abs(ky) < k)
        values = sum(data[i, j, n] * np.exp(-1j * STEP * np.add.outer(kx[rows] * i, ky[cols] * j))
                     for i, j, _ in points)
        blocks.append((rows, cols, values))
    from_spectrum = ProjectionPlan.from_spectrum(blocks, plane, FREQS, MEDIUM, eps=1e-12)
    from_data = ProjectionPlan(data, plane, FREQS, MEDIUM, eps=1e-12, padding=shape)
    for name in ("tilted plane", "plane behind", "points"):
        target = _targets()[name]
        expected = from_data.project(target, quantity=quantity)
        got = from_spectrum.project(target, quantity=quantity)
        assert np.abs(expected).max() > 0
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-11 * np.abs(expected).max())


def test_a_plan_from_the_spectrum_rejects_bad_input():
    plane = hp.PlaneGrid.centered(41, 36, STEP)  # 41 = a prime: not a period the plan keeps
    blocks = [(np.arange(3), np.arange(3), np.ones((3, 3)))] * FREQS.size
    with pytest.raises(InputError, match="FFT-friendly"):
        ProjectionPlan.from_spectrum(blocks, plane, FREQS, MEDIUM)
    with pytest.raises(InputError, match="one block per frequency"):
        ProjectionPlan.from_spectrum(blocks[:2], hp.PlaneGrid.centered(40, 36, STEP), FREQS)


def test_a_plan_from_the_spectrum_refuses_to_transform_its_placeholder_data():
    """Review (session 11): a from_spectrum plan holds zeros as its data; moved to a
    slower medium (or asked for another padded size) it transformed them and projected
    zeros without a word. It now refuses, naming the field; a faster medium still works."""
    shape = (40, 36)
    plane = hp.PlaneGrid.centered(*shape, STEP)
    kx = 2 * np.pi * np.fft.fftfreq(shape[0], STEP)
    ky = 2 * np.pi * np.fft.fftfreq(shape[1], STEP)
    blocks = []
    for f in FREQS:
        k = 2 * np.pi * f / MEDIUM.sound_speed
        rows, cols = np.flatnonzero(np.abs(kx) < k), np.flatnonzero(np.abs(ky) < k)
        blocks.append((rows, cols, np.ones((rows.size, cols.size), complex)))
    plan = ProjectionPlan.from_spectrum(blocks, plane, FREQS, MEDIUM)
    target = _targets()["tilted plane"]
    faster = plan.with_medium(hp.Medium(MEDIUM.density, MEDIUM.sound_speed + 20.0))
    assert np.abs(faster.project(target)).max() > 0
    with pytest.raises(InputError, match="slower medium"):
        plan.with_medium(hp.Medium(MEDIUM.density, MEDIUM.sound_speed - 20.0))
    with pytest.raises(InputError, match="no data to transform"):
        list(plan._chunks((2 * shape[0], 2 * shape[1]), False))


@pytest.mark.parametrize("taper", [False, True])
def test_with_medium_shares_the_spectra_and_projects_as_a_plan_made_for_that_medium(taper):
    """Issue 14: the receive predicts the sensor again at c0 + u_c (the gains' sound-speed
    term); that plan was built anew (the scan transformed again, its spectra held twice).
    ``with_medium`` re-keys the cached spectra to the new wave numbers: for a faster
    medium every projection (grid, reduced, points, and the adjoint) equals one by a plan
    made from the data for that medium, and no spectrum is computed again; for a slower
    one it transforms the data again (same numbers as well)."""
    src = _source()
    targets = _targets()
    x = _random((*src.shape, FREQS.size), 7)
    plan = ProjectionPlan(x, src, FREQS, MEDIUM, eps=1e-9, image_taper=taper)
    plan.project(targets["tilted plane"])  # caches the spectra
    for speed in (MEDIUM.sound_speed + 15.0, MEDIUM.sound_speed - 15.0):
        medium = hp.Medium(MEDIUM.density, speed)
        shared = plan.with_medium(medium)
        fresh = ProjectionPlan(x, src, FREQS, medium, eps=1e-9, image_taper=taper)
        same = speed > MEDIUM.sound_speed
        assert (shared.nbytes == plan.nbytes) == same
        if same:
            assert all(a.values is b.values for a, b in zip(shared._blocks, plan._blocks,
                                                            strict=True))
        for name, target in targets.items():
            for quantity in ("pressure", "normal_velocity"):
                a = shared.project(target, quantity=quantity, time_origin=1e-3)
                b = fresh.project(target, quantity=quantity, time_origin=1e-3)
                assert np.abs(a - b).max() <= 1e-12 * np.abs(b).max(), (name, quantity)
        grid = targets["tilted plane"]
        weights = _random((FREQS.size, grid.shape[1]), 8)
        kernel = np.array([1.0, 0.5, 0.0, 0.25, 1.0, 0.5])
        a = shared.project_reduced(grid, kernel, weights)
        b = fresh.project_reduced(grid, kernel, weights)
        assert np.abs(a - b).max() <= 1e-12 * np.abs(b).max()
        y = _random((*grid.shape, FREQS.size), 9)
        a, b = shared.adjoint(y, grid), fresh.adjoint(y, grid)
        assert np.abs(a - b).max() <= 1e-12 * np.abs(b).max()
    assert plan.medium == MEDIUM  # the original keeps its medium and wave numbers
    assert all(b.k == 2 * np.pi * FREQS[b.n] / MEDIUM.sound_speed for b in plan._blocks)
