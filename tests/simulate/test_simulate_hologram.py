"""The hologram twin against closed forms: O'Neil on axis, piston power, defects."""

import json

import numpy as np
import pytest
from scipy.special import j1

from holoprobe.geometry import Medium, SourceGeometry
from holoprobe.io import read_hologram_any
from holoprobe.simulate import (
    VelocityMap,
    read_truth,
    simulate_hologram,
    source_pose,
    tone_burst,
    write_simulation,
)

MEDIUM = Medium()
F = 1.0e6
K = 2 * np.pi * F / MEDIUM.sound_speed
ROC, AP = 40e-3, 40e-3
BOWL = SourceGeometry("spherical-cap", AP, AP, ROC)
U0 = 0.1


def _oneil(z, aperture=AP, roc=ROC):
    """O'Neil (1949): on-axis pressure of a uniform bowl, holoprobe's convention."""
    a = aperture / 2
    h = roc - np.sqrt(roc**2 - a**2)
    return MEDIUM.impedance * U0 / (1 - z / roc) * (
        np.exp(1j * K * z) - np.exp(1j * K * np.sqrt((z - h) ** 2 + a**2)))


def _centre(h):
    nx, ny = h.grid.shape
    assert h.grid.x[nx // 2] == pytest.approx(0, abs=1e-12)
    return h.pressure[nx // 2, ny // 2]


def test_tilted_offset_bowl_on_its_axis_matches_oneil_and_truth_geometry():
    tilt = (np.radians(3.0), np.radians(-2.0))
    axis = source_pose(0.0, tilt=tilt).normal
    zp = 22e-3
    s = zp / axis[2]                               # apex → scan plane along the axis
    offset = (-s * axis[0], -s * axis[1])          # the axis crosses the plane at x = y = 0
    h, truth = simulate_hologram(BOWL, z_position=zp, tilt=tilt, offset=offset,
                                 shape=(9, 9), power=False)
    assert abs(_centre(h) / _oneil(s) - 1) < 5e-3
    al = truth.parameters["alignment"]
    apex = np.r_[offset, -zp]
    assert np.allclose(al["geometric_axis"], axis)
    assert np.allclose(al["geometric_focus"], apex + ROC * axis)
    # the focal maximum of a uniform bowl lies on its axis, where O'Neil's |p(z)| peaks
    assert np.degrees(np.arccos(min(1.0, np.dot(al["axis_direction"], axis)))) < 1e-3
    rel = np.asarray(al["focus_position"]) - apex
    assert np.linalg.norm(rel - (rel @ axis) * axis) < 1e-6
    z = np.linspace(0.9 * ROC, 0.999 * ROC, 20001)   # O'Neil's form is 0/0 at z = R
    amp = np.abs(_oneil(z))
    i = int(np.argmax(amp))
    z_max = z[i] + 0.5 * (z[1] - z[0]) * (amp[i - 1] - amp[i + 1]) / (
        amp[i - 1] - 2 * amp[i] + amp[i + 1])
    assert rel @ axis == pytest.approx(z_max, abs=1e-6)
    assert al["focal_pressure_pa"] == pytest.approx(amp[i], rel=5e-3)
    assert h.z_position == zp and h.geometry == BOWL


def test_dead_half_and_central_phase_patch_on_axis():
    z = 20e-3
    dead = VelocityMap(U0, dead_sectors=((0.0, np.pi),))
    h, truth = simulate_hologram(BOWL, z_position=z, shape=(5, 5), velocity=dead, power=False,
                                 focus=False)
    assert abs(_centre(h) / (0.5 * _oneil(z)) - 1) < 5e-3
    vmap = truth.arrays["velocity_map"]
    y = truth.arrays["velocity_map_y"]
    assert np.all(vmap[:, y > 1e-3][np.isfinite(vmap[:, y > 1e-3])] == 0)
    rp = 8e-3                                       # a centred disc with phase π
    patch = VelocityMap(U0, phase_patches=((0.0, 0.0, rp, np.pi),))
    h, _ = simulate_hologram(BOWL, z_position=z, shape=(5, 5), velocity=patch, power=False,
                             focus=False)
    expected = _oneil(z) - 2 * _oneil(z, aperture=2 * rp)
    assert abs(_centre(h) / expected - 1) < 5e-3


def test_sector_gains_add_up_on_axis():
    """Six sectors driven together, one at half amplitude: on axis each is 1/6 of the bowl."""
    z = 25e-3
    weak = VelocityMap(U0, sector_gains=(1, 1, 0.5, 1, 1, 1), sector_start=-np.pi / 6 - 2.0943951)
    h, truth = simulate_hologram(BOWL, z_position=z, shape=(5, 5), velocity=weak, focus=False)
    assert abs(_centre(h) / (5.5 / 6 * _oneil(z)) - 1) < 5e-3
    assert truth.parameters["velocity"]["sector_gains"][2] == [0.5, 0.0]
    # the weak sector (centred on +x) sends less power towards −x: the power-weighted
    # direction leans to +x, in the x-z plane
    d = truth.parameters["alignment"]["power_direction"]
    assert d[0] > 1e-3 and abs(d[1]) < 1e-6


def test_disc_power_matches_the_baffled_piston_and_noise_has_the_stated_snr():
    disc = SourceGeometry("flat-disc", 20e-3, 20e-3)
    h, truth = simulate_hologram(disc, shape=(21, 21), snr_db=30.0, seed=3)
    ka = K * 10e-3
    exact = 0.5 * MEDIUM.impedance * U0**2 * np.pi * 1e-4 * (1 - j1(2 * ka) / ka)
    power = truth.parameters["acoustic_power"]
    assert abs(power["hologram"] - exact) < max(power["uncertainty"], 1e-3 * exact)
    # a finite scan window (15.5 mm square, 15 mm in front) sees less than the half-space
    assert 0.5 * exact < power["scan_window"] < exact
    clean, _ = simulate_hologram(disc, shape=(21, 21), power=False, focus=False)
    noise = h.pressure - clean.pressure
    sigma = truth.parameters["noise"]["sigma_pa"]
    assert sigma == pytest.approx(np.max(np.abs(clean.pressure)) * 10 ** (-30 / 20))
    assert np.std(noise) == pytest.approx(sigma, rel=0.1)


def test_transient_disc_on_axis_is_plane_wave_minus_edge_wave():
    disc = SourceGeometry("flat-disc", 12e-3, 12e-3)
    z, a, c = 15e-3, 6e-3, MEDIUM.sound_speed
    h, _ = simulate_hologram(disc, signal="transient", z_position=z, shape=(3, 3),
                             cycles=3, band_db=-80.0, power=False, focus=False)
    t = h.time
    duration = 3 / F

    def u(tt):                                     # the burst of tone_burst, continuous
        inside = (tt >= 0) & (tt < duration)
        return np.where(inside, U0 * np.sin(np.pi * tt / duration) ** 2
                        * np.sin(2 * np.pi * F * tt), 0.0)
    assert np.allclose(u(np.arange(30) / 1e7), U0 * tone_burst(F, 3, 1e7, 30), atol=1e-15)
    exact = MEDIUM.impedance * (u(t - z / c) - u(t - np.sqrt(z * z + a * a) / c))
    got = h.pressure[1, 1]
    assert np.max(np.abs(got - exact)) < 0.01 * np.max(np.abs(exact))


@pytest.mark.parametrize("fmt", ["native", "reference-mat"])
def test_twin_files_read_back_with_the_truth(tmp_path, fmt):
    h, truth = simulate_hologram(BOWL, shape=(11, 9), power=False, focus=False,
                                 velocity=VelocityMap(U0, phase=0.3))
    files = write_simulation(tmp_path, h, truth, format=fmt,
                             mat_options={"descending": (True, False)})
    back = read_hologram_any(files[0])
    assert np.allclose(back.pressure, h.pressure, rtol=1e-12, atol=0)
    params = json.loads((tmp_path / "truth.json").read_text())
    assert set(params["alignment"]) >= {"axis_direction", "focus_position",
                                        "geometric_focus", "geometric_axis"}
    assert params["source"]["radius_of_curvature"] == ROC
    assert params["source"]["aperture_diameter"] == AP
    arrays = read_truth(tmp_path).arrays
    assert np.array_equal(arrays["velocity_map"], truth.arrays["velocity_map"], equal_nan=True)
    inside = np.isfinite(arrays["velocity_map"])
    assert np.allclose(arrays["velocity_map"][inside], U0 * np.exp(0.3j))


def test_cli_simulate_hologram_writes_a_readable_mat_file_and_truth(tmp_path):
    from typer.testing import CliRunner

    from holoprobe.cli.simulate import app

    res = CliRunner().invoke(app, [
        "hologram", "--out", str(tmp_path), "--points", "9", "7", "--tilt-deg", "1", "0",
        "--dead-sector-deg", "0", "90", "--format", "mat", "--snr-db", "inf", "--no-power",
        "--sector-gains", "1,0.5,1,1", "--no-focus", "--quiet"])
    assert res.exit_code == 0, res.output
    h = read_hologram_any(tmp_path / "hologram.mat")
    params = json.loads((tmp_path / "truth.json").read_text())
    assert h.grid.shape == (9, 7) and h.geometry == BOWL
    assert params["alignment"]["geometric_axis"][1] == pytest.approx(-np.sin(np.radians(1)))
    assert params["alignment"]["focus_position"] is None      # --no-focus
    assert params["velocity"]["dead_sectors_deg"] == [[0.0, 90.0]]
    assert params["velocity"]["sector_gains"][1] == [0.5, 0.0]
    assert params["acoustic_power"] is None


def test_a_scan_plane_too_close_to_the_source_warns_and_one_behind_it_fails():
    from holoprobe.errors import InputError

    disc = SourceGeometry("flat-disc", 5e-3, 5e-3)
    with pytest.warns(UserWarning, match="wavelengths from the nearest source point"):
        simulate_hologram(disc, z_position=3e-3, shape=(3, 3), power=False, focus=False)
    with pytest.raises(InputError, match="reaches the scan plane"):
        simulate_hologram(BOWL, z_position=3e-3, tilt=(0.5, 0.0), shape=(3, 3), power=False,
                          focus=False)


def test_rectangle_twin_far_field_and_power_truth():
    """A 2 × 1 mm piston 60 mm away: on axis the Fraunhofer pressure ρ0c0 k u0 A / (2π r)
    (the twin: Gauss–Legendre cells, dense Rayleigh); its power truth against the
    rectangle's analytic far-field directivity integrated over the half-space."""
    rect = SourceGeometry("flat-rectangle", 1e-3, 2e-3)
    holo, truth = simulate_hologram(rect, frequency=F, z_position=60e-3, shape=(3, 3),
                                    velocity=VelocityMap(amplitude=U0))
    area, r = 2e-3 * 1e-3, 60e-3
    fraunhofer = MEDIUM.impedance * K * U0 * area / (2 * np.pi * r)
    assert abs(_centre(holo)) == pytest.approx(fraunhofer, rel=0.005)
    # power: the analytic Fraunhofer directivity of a baffled rectangle, integrated over
    # the half-space (Gauss-Legendre in cos θ, uniform in φ)
    mu, w = np.polynomial.legendre.leggauss(64)
    mu, w = 0.5 * (mu + 1), 0.5 * w
    phi = np.linspace(0, 2 * np.pi, 256, endpoint=False)
    st = np.sqrt(1 - mu**2)[:, None]
    d = (MEDIUM.impedance * K * U0 * area / (2 * np.pi)
         * np.sinc(K * 2e-3 * st * np.cos(phi) / (2 * np.pi))
         * np.sinc(K * 1e-3 * st * np.sin(phi) / (2 * np.pi)))
    analytic = float(np.sum(d**2 * w[:, None]) * (2 * np.pi / phi.size)
                     / (2 * MEDIUM.impedance))
    assert truth.parameters["acoustic_power"]["hologram"] == pytest.approx(analytic, rel=2e-3)
    assert truth.parameters["source"]["kind"] == "flat-rectangle"
    vmap = truth.arrays["velocity_map"]
    assert np.isfinite(vmap).sum() * (truth.arrays["velocity_map_x"][1]
                                      - truth.arrays["velocity_map_x"][0]) ** 2 == \
        pytest.approx(area, rel=0.35)


@pytest.mark.parametrize("args, field", [
    (["--height-mm", "5"], "--height-mm"),                                  # a bowl
    (["--source", "flat-rectangle", "--opening-mm", "2"], "--opening-mm"),
])
def test_cli_simulate_hologram_refuses_an_option_its_source_would_ignore(tmp_path, args, field):
    from typer.testing import CliRunner

    from holoprobe.cli.simulate import app
    from holoprobe.errors import InputError

    res = CliRunner().invoke(app, ["hologram", "--out", str(tmp_path), "--points", "5", "5",
                                   "--quiet", *args])
    assert res.exit_code != 0 and isinstance(res.exception, InputError)
    assert field in str(res.exception)
    assert not any(tmp_path.iterdir())  # nothing written
