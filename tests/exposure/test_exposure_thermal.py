"""Acoustic power and thermal indices (holoprobe.exposure._thermal) against closed forms."""

import math

import numpy as np
import pytest
from scipy.special import j1

from holoprobe.errors import InputError
from holoprobe.exposure import (
    beam_area,
    plane_pulse_energy,
    source_pulse_energy,
    thermal_indices,
)
from holoprobe.geometry import Medium, PlaneGrid, Surface
from holoprobe.propagation import plane_power, rayleigh_integral, source_power
from holoprobe.signal import frequency_axis, to_frequency

MED = Medium()
F = 3e6
LAM = MED.sound_speed / F
A = 2e-3  # piston radius: ka = 25
U0 = 0.01  # m/s


def _piston_exact():
    """Radiated power of a baffled piston: ½ρc|u|²A [1 − J1(2ka)/(ka)]."""
    ka = 2 * math.pi / LAM * A
    return 0.5 * MED.impedance * U0**2 * math.pi * A**2 * (1 - j1(2 * ka) / ka)


def _disc_fraction(step, supersample=8):
    n = math.ceil(2.2 * A / step)
    x = (np.arange(n) - (n - 1) / 2) * step
    sub = (np.arange(supersample) - (supersample - 1) / 2) / supersample * step
    xx = x[:, None, None, None] + sub[None, None, :, None]
    yy = x[None, :, None, None] + sub[None, None, None, :]
    return PlaneGrid(x, x), ((xx**2 + yy**2) <= A**2).mean(axis=(2, 3))


def test_source_power_of_a_baffled_piston_is_its_radiation_resistance():
    grid, frac = _disc_fraction(LAM / 8)
    exact = _piston_exact()
    far_field = 0.5 * MED.impedance * U0**2 * math.pi * A**2  # ka ≫ 1 limit
    assert exact == pytest.approx(far_field, rel=1e-3)  # J1(2ka)/(ka) = 6e-4 at ka = 25
    assert source_power(U0 * frac, grid, F, MED) == pytest.approx(exact, rel=0.01)


def test_power_through_a_plane_of_the_rayleigh_field_equals_the_piston_power():
    # the field on a plane 2 mm away by the dense Rayleigh integral (an independent method)
    step = LAM / 10
    n = math.ceil(2 * A / step)
    xs = (np.arange(n) - (n - 1) / 2) * step
    xx, yy = np.meshgrid(xs, xs, indexing="ij")
    inside = xx**2 + yy**2 <= A**2
    m = int(inside.sum())
    src = Surface(np.stack([xx[inside], yy[inside], np.zeros(m)], -1),
                  np.tile([0.0, 0.0, 1.0], (m, 1)), np.full(m, step**2))
    dp = LAM / 2.2
    nn = int(2 * 8e-3 / dp) + 1
    xp = (np.arange(nn) - (nn - 1) / 2) * dp
    px, py = np.meshgrid(xp, xp, indexing="ij")
    tgt = Surface(np.stack([px.ravel(), py.ravel(), np.full(px.size, 2e-3)], -1),
                  np.tile([0.0, 0.0, 1.0], (px.size, 1)), np.full(px.size, dp**2))
    p = rayleigh_integral(np.full(m, U0), src, tgt, [F], MED, kernel="fwd_vp")
    grid = PlaneGrid(xp, xp)
    field = p[:, 0].reshape(nn, nn)
    assert plane_power(field, grid, F, MED) == pytest.approx(_piston_exact(), rel=0.01)
    # the plane-wave approximation over-counts the oblique near-field energy
    assert plane_power(field, grid, F, MED, method="plane_wave") > 1.02 * _piston_exact()


def test_pulse_energy_of_a_wide_gaussian_beam_matches_the_closed_form():
    # p = exp(−r²/w²) s(t), kw = 50: energy = (π w²/2) ∫ s² dt / (ρc) up to 1/(kw)²
    fs, nt, w = 50e6, 256, 4e-3
    t = np.arange(nt) / fs
    s = 1e5 * np.exp(-(((t - 2.5e-6) / 0.4e-6) ** 2)) * np.sin(2 * np.pi * F * (t - 2.5e-6))
    x = (np.arange(64) - 31.5) * 0.25e-3
    grid = PlaneGrid(x, x)
    r2 = x[:, None] ** 2 + x[None, :] ** 2
    p = np.exp(-r2 / w**2)[:, :, None] * s[None, None, :]
    exact = math.pi * w**2 / 2 * np.sum(s**2) / fs / MED.impedance
    assert plane_pulse_energy(p, grid, fs, MED) == pytest.approx(exact, rel=0.01)
    assert plane_pulse_energy(p, grid, fs, MED, method="plane_wave") == pytest.approx(
        exact, rel=0.01)
    # the same pulse as a velocity source: energy leaving the plane = the same closed form
    f = frequency_axis(nt, fs)[1:]
    spec = to_frequency(s)[1:] / fs / MED.impedance
    u = np.exp(-r2 / w**2)[:, :, None] * spec[None, None, :]
    assert source_pulse_energy(u[..., ::4], grid, f[::4], MED) == pytest.approx(
        exact, rel=0.02)


def test_thermal_indices_of_a_collimated_beam_match_the_iec_formulas_by_hand():
    # collimated beam of area 0.5 cm² (< 1 cm²): I_ta·1 cm² > P_α, so TIS uses P_α at
    # the break-point depth z_bp = 1.5 D_eq; 2 MHz, 100 mW, A_aprt = 0.8 cm²
    p_w, f, area_b, a_aprt = 0.1, 2e6, 0.5e-4, 0.8e-4
    z = np.linspace(0.0, 0.1, 2001)
    ita = np.full(z.size, p_w / area_b)
    ti = thermal_indices(power=p_w, frequency=f, depths=z, intensity_ta=ita,
                         aperture_area=a_aprt)
    d_eq_cm = math.sqrt(4 * 0.8 / math.pi)  # 1.0093 cm
    z_bp_cm = 1.5 * d_eq_cm
    pa = 100.0 * 10 ** (-0.3 * 2 * z_bp_cm / 10)  # mW at z_bp
    assert ti.breakpoint_depth == pytest.approx(z_bp_cm / 100, rel=1e-9)
    assert ti.tis == pytest.approx(pa * 2 / 210, rel=0.01)
    # TIB: min(sqrt(P_α I_ta,α)/50, P_α/4.4) with I_ta,α = P_α / 0.5 cm²
    assert ti.tib == pytest.approx(min(math.sqrt(pa * pa / 0.5) / 50, pa / 4.4), rel=0.01)
    assert ti.tic == pytest.approx(100.0 / (d_eq_cm * 40), rel=1e-9)
    # scanning mode: surface formulas with the bounded power P_1
    sc = thermal_indices(power=p_w, frequency=f, depths=z, intensity_ta=ita,
                         aperture_area=a_aprt, mode="scanning", power_1cm=0.04,
                         aperture_area_1cm=0.3e-4)
    assert sc.tis == pytest.approx(40.0 * 2 / 210, rel=1e-9) and sc.tib == sc.tis
    assert sc.tic == pytest.approx(40.0 / (math.sqrt(4 * 0.3 / math.pi) * 40), rel=1e-9)
    # a wide beam (4 cm²): I_ta·1 cm² < P_α, the intensity term sets TIS
    wide = thermal_indices(power=p_w, frequency=f, depths=z,
                           intensity_ta=np.full(z.size, p_w / 4e-4), aperture_area=a_aprt)
    assert wide.tis == pytest.approx(pa / 4 * 2 / 210, rel=0.01)
    with pytest.raises(InputError, match="break-point"):
        thermal_indices(power=p_w, frequency=f, depths=z[:50], intensity_ta=ita[:50],
                        aperture_area=a_aprt)


def test_beam_area_of_a_uniform_disc():
    grid, frac = _disc_fraction(LAM / 8)
    area = beam_area(frac**2, grid.dx * grid.dy, level_db=-3.0)
    assert area == pytest.approx(math.pi * A**2, rel=0.02)


def _array(n=8, height=2e-3, fs=100e6):
    from holoprobe.transducer import VirtualTransducer

    t = np.arange(200) / fs
    ir = 1e11 * np.exp(-((t - 0.5e-6) ** 2) / (2 * 0.12e-6**2)) * np.sin(
        2 * np.pi * 3e6 * (t - 0.5e-6))
    return VirtualTransducer(element_count=n, pitch=0.3e-3, element_width=0.3e-3,
                             element_height=height, transmit_impulse_response=ir,
                             transmit_sampling_rate=fs, medium=MED)


def test_output_cli_power_of_an_unsteered_array_and_its_thermal_indices(tmp_path):
    import json

    from typer.testing import CliRunner

    from holoprobe.cli import app

    # 8 contiguous elements without kerf, no lens, no delays: a 2.4 × 2 mm rectangular
    # piston moving with u = h_T ⊛ E / (ρc); for kL ≫ 1 it radiates ρc A ∫u² dt per pulse
    vt = _array()
    path = vt.save(tmp_path / "vt.h5")
    (tmp_path / "tx.toml").write_text(
        'prf = 1000.0\n[drive]\nkind = "burst"\nfrequency = 3e6\ncycles = 1\n'
        'amplitude = 10.0\n')
    res = CliRunner().invoke(app, ["output", str(path), "--transmit", str(tmp_path / "tx.toml"),
                                   "--out", str(tmp_path / "o.json"), "--depth-mm", "2", "20",
                                   "--axial-step-mm", "1", "--lateral-step-mm", "0.25",
                                   "--power-depth-mm", "1"])
    assert res.exit_code == 0, res.output
    d = json.loads((tmp_path / "o.json").read_text())
    power, ti = d["acoustic_power"], d["thermal_indices"]
    from holoprobe.transducer import TransmitSetting

    drive = TransmitSetting.from_toml(tmp_path / "tx.toml").drive
    u = np.convolve(vt.transmit_impulse_response,
                    np.interp(np.arange(0, drive.duration, 1e-8),
                              np.arange(drive.voltage.size) / drive.sampling_rate,
                              drive.voltage)) * 1e-8 / MED.impedance
    limit = MED.impedance * 2.4e-3 * 2e-3 * np.sum(u**2) * 1e-8 * 1000.0  # W
    assert power["power_source"] == pytest.approx(limit, rel=0.03)  # kL ≈ 30: edge terms
    assert power["power_plane"] == pytest.approx(power["power_source"], rel=0.02)
    assert power["aperture_area"] == pytest.approx(2.4e-3 * 2e-3, rel=0.1)
    # the indices follow from the reported power, f_awf and A_aprt by the IEC formulas
    f_mhz = d["acoustic_working_frequency"] * 1e-6
    d_eq_cm = math.sqrt(4 * power["aperture_area"] / math.pi) * 100
    assert ti["tic"] == pytest.approx(power["power_plane"] * 1e3 / (d_eq_cm * 40), rel=1e-9)
    assert 0 < ti["tis"] <= power["power_plane"] * 1e3 * f_mhz / 210
    print(f"power plane/source/limit: {power['power_plane']:.6g} {power['power_source']:.6g} "
          f"{limit:.6g}; TIS {ti['tis']:.4g} TIB {ti['tib']:.4g} TIC {ti['tic']:.4g}")
