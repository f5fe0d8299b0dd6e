"""W, H and F without the biases of the scan window and of the back-projection plane
(holoprobe.characterize._aperture_bias; issue 10).

The measurement is the reduced P4-1 twin of ``tests/conftest.py`` (16 elements, midpoint
quadrature of the element strips and the dense Rayleigh integral: not the estimator's
angular-spectrum model of a rectangle), back-projected onto a plane 150 µm behind the
true face — what the onset convention does to the pipeline's plane.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from tests.conftest import TWIN_POSE

from holoprobe.characterize import (
    CharacterizationConfig,
    face_plane,
    fit_aperture,
    fit_lens_focus,
    scan_pressure,
    scan_window_bias,
    signal_band,
    source_grid,
)
from holoprobe.propagation import ProjectionPlan
from holoprobe.signal import frequency_axis, to_frequency

BEHIND = 150e-6  # m: the back-projection plane lies this far behind the face


@pytest.fixture(scope="module")
def behind_face(reduced):
    """The twin back-projected onto a plane ``BEHIND`` behind its face, with the fits."""
    scan, truth = reduced
    cfg = CharacterizationConfig()
    spectrum = to_frequency(scan_pressure(scan, None, [], cfg))
    band = signal_band(spectrum, frequency_axis(scan.n_samples, scan.sampling_rate),
                       scan.grid, scan.sampling_rate, scan.medium.sound_speed, cfg, [])
    x0, y0, z0 = TWIN_POSE.origin
    pose = dataclasses.replace(TWIN_POSE, origin=(x0, y0, z0 + BEHIND))
    grid = source_grid(scan.grid, pose, cfg.backprojection.margin)
    plan = ProjectionPlan(band.spectrum, scan.grid, band.frequencies, scan.medium,
                          allow_undersampled=True)
    velocity = plan.with_pose(pose).project(grid, quantity="normal_velocity")
    ac, lc = cfg.aperture, cfg.lens
    a_opt = dict(threshold_db=ac.threshold_db, profile=ac.profile, fit_offset=ac.fit_offset,
                 start_level=ac.start_level)
    l_opt = dict(threshold_db=lc.threshold_db, margin_wavelengths=lc.margin_wavelengths,
                 significance=lc.significance, max_bins=lc.max_bins)
    ap = fit_aperture(velocity, grid, band.frequencies, scan.medium, **a_opt)
    lens = fit_lens_focus(velocity, grid, band.frequencies, scan.medium, ap, **l_opt)
    probe = truth.parameters["probe"]
    strips = (np.ones(probe["element_count"]), probe["kerf_m"])
    return dict(scan=scan, probe=probe, pose=pose, grid=grid, velocity=velocity,
                f=band.frequencies, aperture=ap, lens=lens, a_opt=a_opt, l_opt=l_opt,
                strips=strips)


def test_face_plane_and_window_bias_give_w_h_f_of_the_twin(behind_face):
    b = behind_face
    probe, medium = b["probe"], b["scan"].medium
    width, height, focus = (probe["element_count"] * probe["pitch_m"],
                            probe["aperture_height_m"], probe["lens_focus_m"])
    # the plain fits on that plane are off by far more than their σ (the old code)
    # measured: W +14 µm, H +19 µm, F −0.49 % (window bias −12 µm, defocus +27 µm)
    assert b["aperture"].width - width > 8e-6
    assert b["aperture"].height - height > 12e-6
    assert abs(b["lens"].focus / focus - 1) > 0.003
    face = face_plane(b["velocity"], b["grid"], b["f"], medium, b["aperture"], b["lens"],
                      b["scan"].grid.with_pose(b["pose"]), aperture_options=b["a_opt"],
                      lens_options=b["l_opt"], strips=b["strips"])
    assert face.distance == pytest.approx(BEHIND, abs=30e-6)
    assert face.uncertainty < 30e-6
    fit, bias = face.aperture, face.bias
    assert bias.width < -5e-6 and bias.height < -5e-6  # the window shortens W and H
    # measured: face 154 ± 10 µm, W −2.5 µm, H +0.4 µm, F −0.056 %
    assert abs(fit.width - bias.width - width) < 7e-6
    assert abs(fit.height - bias.height - height) < 7e-6
    at_face = fit_lens_focus(face.velocity, b["grid"], b["f"], medium, fit, **b["l_opt"])
    assert abs((at_face.focus - bias.focus) / focus - 1) < 0.001


def test_scan_window_bias_vanishes_for_a_scan_much_larger_than_the_aperture(behind_face):
    """The same noise-free model seen through a scan window 15 mm wider on every side: the
    fits of its back-projection come back to the model's W and H (the bias is the
    window's)."""
    from holoprobe.geometry import PlaneGrid

    b = behind_face
    g = b["scan"].grid
    step = g.dx
    pad = round(15e-3 / step)
    big = PlaneGrid(g.x[0] + step * np.arange(-pad, g.x.size + pad),
                    g.y[0] + step * np.arange(-pad, g.y.size + pad), b["pose"])
    small = scan_window_bias(g.with_pose(b["pose"]), b["grid"], b["scan"].medium,
                             b["aperture"], None, aperture_options=b["a_opt"],
                             lens_options=b["l_opt"], max_bins=3, seed=None)
    wide = scan_window_bias(big, b["grid"], b["scan"].medium, b["aperture"], None,
                            aperture_options=b["a_opt"], lens_options=b["l_opt"], max_bins=3,
                            seed=None)
    # measured: −40.5 / −7.6 µm through the scan's window, +0.0 / −2.2 µm through the wide one
    assert small.width < -8e-6
    assert abs(wide.width) < 0.3 * abs(small.width)
    assert abs(wide.height) < 0.3 * abs(small.height)


def test_refocus_moves_plane_waves_by_their_own_phase_and_drops_evanescent_ones():
    """Two bins on a 40 × 30 periodic grid: a propagating plane wave of the lattice
    gains e^{+i kz d} (holoprobe's conjugate convention, written out here), an
    evanescent one (|κ| > k) is dropped; the bins are refocused independently. The
    transforms run in single precision by default (float32 rounding, 1e-6 of the unit
    waves), in double with ``single_precision=False`` (1e-12: review A, session 12,
    backprojection.single_precision = false no longer bought double there; fails on the
    old code)."""
    from holoprobe.characterize import refocus
    from holoprobe.geometry import Medium, PlaneGrid

    medium = Medium(sound_speed=1480.0)
    grid = PlaneGrid(0.1e-3 * np.arange(40), 0.12e-3 * np.arange(30))
    x, y = np.meshgrid(grid.x, grid.y, indexing="ij")
    f = np.array([2.0e6, 3.0e6])
    kx1, ky1 = 2 * np.pi * 3 / (40 * 0.1e-3), 2 * np.pi * -2 / (30 * 0.12e-3)
    kx2 = 2 * np.pi * 19 / (40 * 0.1e-3)  # beyond k = 12.7 rad/mm at 3 MHz
    wave1 = np.exp(1j * (kx1 * x + ky1 * y))
    v = np.stack([(0.5 - 0.2j) * wave1, wave1 + np.exp(1j * kx2 * x)], axis=-1)
    d = 0.37e-3
    single = refocus(v, grid, f, medium, d)
    double = refocus(v, grid, f, medium, d, single_precision=False)
    for i, fi in enumerate(f):
        k = 2 * np.pi * fi / medium.sound_speed
        assert kx2**2 > k**2 > kx1**2 + ky1**2
        kz = np.sqrt(k**2 - kx1**2 - ky1**2)
        expected = (0.5 - 0.2j if i == 0 else 1.0) * np.exp(1j * kz * d) * wave1
        np.testing.assert_allclose(single[:, :, i], expected, rtol=0, atol=1e-6)
        np.testing.assert_allclose(double[:, :, i], expected, rtol=0, atol=1e-12)
    assert np.abs(single - double).max() > 1e-9  # the default did run in float32
    assert single.dtype == double.dtype == np.complex128


@pytest.mark.parametrize("single", [True, False])
def test_the_window_step_refocuses_in_the_back_projections_precision(monkeypatch, single):
    """backprojection.single_precision reaches face_plane (and so refocus): review A,
    session 12 (the refocus was complex64 whatever the setting; fails on the old code)."""
    from types import SimpleNamespace

    import holoprobe.characterize._pipeline as pipeline
    from holoprobe.characterize import CharacterizationConfig
    from holoprobe.errors import FitError
    from holoprobe.geometry import Medium, PlaneGrid, Pose

    seen = []

    def spy(*args, **kwargs):
        seen.append(kwargs.get("single_precision"))
        raise FitError("spy: no face plane")

    monkeypatch.setattr(pipeline, "face_plane", spy)
    grid = PlaneGrid(0.1e-3 * np.arange(8), 0.1e-3 * np.arange(8))
    est = SimpleNamespace(aperture=SimpleNamespace(width=1e-3), profile_width=np.nan,
                          element_map=None, velocity=np.zeros((8, 8, 2), complex), grid=grid,
                          lens=None, pose=Pose())
    scan = SimpleNamespace(probe=None, grid=grid, medium=Medium())
    band = SimpleNamespace(frequencies=np.array([2e6, 3e6]))
    cfg = CharacterizationConfig().with_overrides(
        [f"backprojection.single_precision={str(single).lower()}"])
    warnings: list[str] = []
    pipeline.window_bias_step(est, band, scan, cfg, 0.05, warnings)
    assert seen == [single] and "face plane" in warnings[0]
