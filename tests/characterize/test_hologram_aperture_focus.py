"""The focal maximum radiated by the reconstructed aperture (hologram.focus_estimator =
"aperture", issue 13): its field against the dense Rayleigh integral, its linear noise σ
against re-estimated noise draws, and the pipeline's focus against the twin's truth (dense
Rayleigh from the twin's own ring quadrature, refined by quadratic fits)."""

from __future__ import annotations

import numpy as np
import pytest

from holoprobe.characterize import HologramConfig, characterize_hologram
from holoprobe.characterize._aperture_focus import _RadiatedField, aperture_focus
from holoprobe.characterize._hologram_field import hologram_grid
from holoprobe.errors import InputError
from holoprobe.geometry import Medium, SourceGeometry, Surface
from holoprobe.propagation import rayleigh_integral
from holoprobe.simulate import VelocityMap, simulate_hologram

BOWL = SourceGeometry("spherical-cap", 0.02, 0.02, 0.03)
POSE = dict(z_position=0.018, tilt=(0.01, -0.02), offset=(0.5e-3, -0.3e-3), shape=(41, 41))


def test_radiated_field_is_the_rayleigh_integral_and_its_derivatives():
    """p ∝ the fwd_vp Rayleigh integral (one constant at every point); ∇p and ∇∇p against
    central differences of it."""
    medium, f = Medium(), 1e6
    k = 2 * np.pi * f / medium.sound_speed
    cap = Surface.spherical_cap(0.02, 0.03, spacing=0.4e-3, layout="rings", order=3)
    v = np.exp(1j * cap.points[:, 0] * 300.0) * (1 + cap.points[:, 1] * 20)
    rad = _RadiatedField(cap.points, cap.weights * v, k)
    pts = np.array([[0.1e-3, -0.2e-3, 0.028], [0.5e-3, 0.3e-3, 0.031], [0.0, 0.0, 0.02]])
    tgt = Surface(pts, np.tile([0.0, 0.0, 1.0], (3, 1)), np.ones(3))
    want = rayleigh_integral(v[:, None], cap, tgt, [f], medium, kernel="fwd_vp")[:, 0]
    got = np.array([rad.derivatives(x)[0] for x in pts])
    ratio = got / want
    assert np.abs(ratio / ratio[0] - 1).max() < 1e-9
    h = 0.5e-6  # central differences: (kh)²/6 = 7e-7 of the derivative
    x = pts[0]
    _, g, hess = rad.derivatives(x)
    for a in range(3):
        e = np.zeros(3)
        e[a] = h
        pp, gp, _ = rad.derivatives(x + e)
        pm, gm, _ = rad.derivatives(x - e)
        assert abs((pp - pm) / (2 * h) - g[a]) < 1e-5 * np.abs(g).max()
        assert np.abs((gp - gm) / (2 * h) - hess[a]).max() < 1e-5 * np.abs(hess).max()


@pytest.fixture(scope="module")
def twin():
    clean, truth = simulate_hologram(BOWL, velocity=VelocityMap(dead_sectors=((0.5, 1.2),)),
                                     power=False, **POSE)
    return clean, truth.parameters["alignment"]


def test_linear_sigma_matches_re_estimated_noise_draws(twin):
    """σ of aperture_focus (linear propagation through the expansion, the velocity and the
    integral) against the spread of 40 re-estimations on noise draws (±11 % at 1σ)."""
    clean, _ = twin
    res = characterize_hologram(clean)
    rec, g = res.reconstruction, res.reconstruction.geometry
    grid, p3 = hologram_grid(clean.grid.x, clean.grid.y, np.asarray(clean.pressure))
    s = rec.unrolled.surface
    rel = s.points - g.apex
    keep = np.linalg.norm(rel - (rel @ g.axis)[:, None] * g.axis, axis=1) <= 0.0115
    sigma = 0.01 * np.abs(p3).max()
    args = (grid, res.frequency, clean.medium, s.points, s.normals, s.weights, keep)
    base, u = aperture_focus(p3[:, :, 0], *args, res.alignment.focus, noise_level=sigma)
    rng = np.random.default_rng(5)
    shifts = []
    for _ in range(40):
        n = sigma / np.sqrt(2) * (rng.standard_normal(grid.shape)
                                  + 1j * rng.standard_normal(grid.shape))
        shifts.append(aperture_focus(p3[:, :, 0] + n, *args, base)[0] - base)
    sd = np.std(np.array(shifts), axis=0, ddof=1)
    assert np.all(np.abs(sd / u - 1) < 0.35), (sd, u)


def test_pipeline_focus_against_the_truth(twin):
    """Noise-free, the aperture focus (the uniform cap's bias removed) lies within 1 µm of
    the truth on a bowl with a dead 60° sector; at 40 dB its error lies within 2σ and its
    noise σ z is well below the lobe estimate's."""
    clean, truth = twin
    focus = np.array(truth["focus_position"])
    cfg = HologramConfig(focus_estimator="aperture")
    free = characterize_hologram(clean, cfg).alignment
    assert free is not None
    assert np.all(np.abs(free.focus - focus) < 1e-6)
    # review (session 11): "auto" took the aperture estimate wherever the lobe's σ
    # exceeded 10 µm, here only the lobe's window-model term (29 µm), and gave a σ of
    # 88 µm (the aperture's own model term) for data without noise; it now keeps the
    # surer of the two
    auto = characterize_hologram(clean).alignment
    assert auto is not None and auto.estimator == "lobe"
    assert np.max(auto.focus_uncertainty) < np.max(free.focus_uncertainty)
    assert np.all(np.abs(auto.focus - focus) <= 2 * auto.focus_uncertainty)
    noisy, _ = simulate_hologram(BOWL, velocity=VelocityMap(dead_sectors=((0.5, 1.2),)),
                                 power=False, focus=False, snr_db=40.0, seed=7, **POSE)
    ap = characterize_hologram(noisy, cfg).alignment
    lobe = characterize_hologram(noisy, HologramConfig(focus_estimator="lobe")).alignment
    assert ap is not None and lobe is not None
    assert ap.estimator == "aperture" and lobe.estimator == "lobe"
    assert np.all(np.abs(ap.focus - focus) <= 2 * ap.focus_uncertainty)
    assert np.abs(ap.focus - focus)[2] < 0.5 * lobe.focus_uncertainty[2]


def _degrees_off(axis, truth):
    return float(np.degrees(np.arccos(min(1.0, abs(float(np.asarray(axis) @ truth))))))


def test_pipeline_axis_against_the_truth(twin):
    """Where the aperture focus is taken, so is the axis of the field the aperture
    radiates: on the 41² dead-sector bowl at 40 dB (seeds 8-10; the plane-wave axis is
    0.037-0.074° off there; over seeds 7-26 see benchmarks/RESULTS.md) its error is
    within 2σ and its RMS under 0.6× the plane-wave axis's (0.029 vs 0.060°). Fails on
    the old code (the axis stayed the lobe's). Noise-free its error (0.026°: the
    reconstructed velocity's own, not the window's) lies within 2σ."""
    clean, truth = twin
    ta = np.array(truth["axis_direction"])
    free = characterize_hologram(clean, HologramConfig(focus_estimator="aperture")).alignment
    assert free is not None and free.axis_estimator == "aperture"
    assert _degrees_off(free.axis, ta) <= 2 * np.degrees(free.axis_uncertainty)
    errs = []
    for seed in (8, 9, 10):
        noisy, _ = simulate_hologram(BOWL, velocity=VelocityMap(dead_sectors=((0.5, 1.2),)),
                                     power=False, focus=False, snr_db=40.0, seed=seed, **POSE)
        ap = characterize_hologram(noisy).alignment
        lobe = characterize_hologram(noisy, HologramConfig(focus_estimator="lobe")).alignment
        assert ap is not None and lobe is not None and lobe.axis_estimator == "lobe"
        errs.append((_degrees_off(ap.axis, ta), _degrees_off(lobe.axis, ta)))
        assert errs[-1][0] <= 2 * np.degrees(ap.axis_uncertainty), (seed, errs[-1])
    rms = np.sqrt(np.mean(np.square(errs), axis=0))
    assert rms[0] < 0.6 * rms[1], errs


def test_focus_estimator_setting_is_checked():
    from holoprobe.characterize import CharacterizationConfig

    with pytest.raises(InputError, match="focus_estimator"):
        CharacterizationConfig.from_dict({"hologram": {"focus_estimator": "peak"}})
    with pytest.raises(InputError, match="aperture_margin"):
        CharacterizationConfig.from_dict({"hologram": {"aperture_margin_wavelengths": -1}})


def test_an_aperture_focus_that_cannot_be_made_says_so(twin):
    """Review (session 11): focus_estimator = "aperture" without the window model (its
    bias model) fell back to the lobe estimate without a word."""
    clean, _ = twin
    res = characterize_hologram(clean, HologramConfig(focus_estimator="aperture",
                                                      window_model=False))
    assert res.alignment is not None and res.alignment.estimator == "lobe"
    assert any("focus_estimator" in w and "lobe estimate is kept" in w
               for w in res.warnings)
