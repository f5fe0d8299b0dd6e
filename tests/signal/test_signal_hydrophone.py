"""Complex hydrophone calibrations and GUM deconvolution (holoprobe.signal._hydrophone,
holoprobe.exposure._pulse, holoprobe.io._hydrophone, ``holoprobe hydrophone deconvolve``).

The synthetic measurement is made in the time domain with a different model than the
deconvolver's: a known pressure pulse (fundamental + second harmonic, p_r ≠ p_c) is
convolved, at 8× the sampling rate, with the impulse response of a resonant 2nd-order
hydrophone (40 MHz, ζ = 0.3) behind a 60 ns cable delay, decimated, and given white noise
and a 20 mV DC offset. The calibration file holds the analytic complex sensitivity at
1–60 MHz in the FFT convention, as a certificate would.
"""

import json

import numpy as np
import pytest
from scipy.signal import fftconvolve

pytest.importorskip("PyDynamic")

from holoprobe.errors import InputError
from holoprobe.exposure import (
    acoustic_working_frequency,
    hydrophone_pulse,
    pulse_duration,
    pulse_intensity_integral,
)
from holoprobe.io import read_waveform_csv, write_calibration_h5
from holoprobe.measurement import HydrophoneCalibration
from holoprobe.signal import (
    HydrophoneDeconvolutionConfig,
    deconvolve_hydrophone,
    deconvolve_records,
    frequency_axis,
    load_calibration,
    regularised_inverse,
    to_frequency,
    to_time,
    voltage_from_pressure,
)
from holoprobe.signal._hydrophone import _time_variance

FS = 250e6
UP = 8
M0 = 5e-8  # V/Pa (50 mV/MPa)
FN, ZETA, DELAY = 40e6, 0.3, 60e-9
HEADER = "frequency_Hz,magnitude_V_per_Pa,phase_rad,u_magnitude_V_per_Pa,u_phase_rad"


def _true_pressure(t, t0=2.0e-6, f0=5e6, tau=0.25e-6, amp=1.0e6):
    x = (t - t0) / tau
    env = np.exp(-x**2)
    return amp * env * (np.sin(2 * np.pi * f0 * (t - t0))
                        + 0.35 * env * np.cos(4 * np.pi * f0 * (t - t0)))


def _hydrophone_ir(t, delay):
    wn = 2 * np.pi * FN
    wd = wn * np.sqrt(1 - ZETA**2)
    td = t - delay
    return np.where(td >= 0, wn**2 / wd * np.exp(-ZETA * wn * td) * np.sin(wd * td), 0.0)


def _sensitivity_fft(f, delay):
    """∫ h(t) e^{−iωt} dt of the impulse response above: numpy's FFT convention."""
    w, wn = 2 * np.pi * f, 2 * np.pi * FN
    return M0 * wn**2 / (wn**2 - w**2 + 2j * ZETA * wn * w) * np.exp(-1j * w * delay)


def _record(n=2048, noise=0.4e-3, offset=0.02, seed=1, delay=DELAY):
    fine = FS * UP
    tf = np.arange(n * UP) / fine
    h = _hydrophone_ir(np.arange(int(1.5e-6 * fine)) / fine, delay)
    v = (M0 * fftconvolve(_true_pressure(tf), h)[:tf.size] / fine)[::UP]
    t = np.arange(n) / FS
    rng = np.random.default_rng(seed)
    return t, v + offset + noise * rng.standard_normal(n), _true_pressure(t)


def _write_calibration(path, *, delay=DELAY, phase_sign=1.0, uncertainties=True):
    f = np.arange(1e6, 60.01e6, 0.5e6)
    m = _sensitivity_fft(f, delay)
    cols = [f, np.abs(m), phase_sign * np.unwrap(np.angle(m))]
    header = HEADER
    if uncertainties:
        cols += [0.03 * np.abs(m), np.full(f.size, 0.03)]
    else:
        header = ",".join(HEADER.split(",")[:3])
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=header, comments="")
    return path


def _truth(p):
    return {"p_c_Pa": p.max(), "p_r_Pa": -p.min(),
            "pii_J_per_m2": float(pulse_intensity_integral(p, FS)),
            "pulse_duration_s": float(pulse_duration(p, FS)),
            "f_awf_Hz": float(acoustic_working_frequency(p, FS))}


def _errors(values, truth):
    return {k: values[k] / truth[k] - 1.0 for k in truth}


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("hydrophone")
    t, v, p = _record()
    cal = load_calibration(_write_calibration(tmp / "cal.csv"))
    return {"t": t, "v": v, "p": p, "cal": cal, "dir": tmp,
            "result": hydrophone_pulse(v, FS, cal, n_draws=60)}


def test_complex_csv_phase_is_read_in_the_fft_convention_and_converted_once(tmp_path):
    # a pure delay τ reads φ_fft = −2πfτ in a certificate; holoprobe's convention is +2πfτ
    tau = 100e-9
    f = np.linspace(1e6, 20e6, 39)
    np.savetxt(tmp_path / "c.csv", np.column_stack([f, np.full(f.size, 1e-7),
                                                     -2 * np.pi * f * tau]),
               delimiter=",", header="frequency_Hz,magnitude_V_per_Pa,phase_rad", comments="")
    cal = load_calibration(tmp_path / "c.csv")
    np.testing.assert_allclose(cal.phase, 2 * np.pi * f * tau)
    np.testing.assert_allclose(cal.phase_fft, -2 * np.pi * f * tau)
    # physics: the voltage of a pressure pulse through this calibration arrives τ later
    n, t0 = 1024, 1e-6
    t = np.arange(n) / FS
    pulse = np.exp(-((t - t0) / 0.1e-6) ** 2) * np.cos(2 * np.pi * 8e6 * (t - t0))
    v = voltage_from_pressure(pulse, FS, cal, below="hold", above="hold")
    lag = (np.argmax(np.correlate(v, pulse, "full")) - (n - 1)) / FS
    assert lag == pytest.approx(tau, abs=0.5 / FS)
    # HDF5 round trip keeps phase and uncertainties
    full = load_calibration(_write_calibration(tmp_path / "u.csv"))
    write_calibration_h5(tmp_path / "u.h5", full)
    back = load_calibration(tmp_path / "u.h5")
    np.testing.assert_allclose(back.phase, full.phase)
    np.testing.assert_allclose(back.u_sensitivity, full.u_sensitivity)
    np.testing.assert_allclose(back.u_phase, full.u_phase)


def test_deconvolution_recovers_a_known_pulse_through_a_resonant_hydrophone(synthetic):
    res = synthetic["result"]
    p = synthetic["p"]
    assert np.corrcoef(res.pressure.pressure, p)[0, 1] >= 0.995
    truth = _truth(p)
    err = _errors(res.parameters.values, truth)
    for key in ("p_c_Pa", "p_r_Pa", "pii_J_per_m2", "pulse_duration_s"):
        assert abs(err[key]) < 0.03, (key, err[key])
    assert abs(err["f_awf_Hz"]) < 0.05
    # amplitudes in absolute units and uncertainties that cover the error (k = 3)
    assert res.parameters.values["p_r_Pa"] == pytest.approx(1.2845e6, rel=0.03)
    for key in ("p_c_Pa", "p_r_Pa", "pii_J_per_m2"):
        assert abs(res.parameters.values[key] - truth[key]) < 3 * res.parameters.uncertainties[key]
    assert res.pressure.offset == pytest.approx(0.02, abs=5e-5)
    assert res.pressure.noise_sigma == pytest.approx(0.4e-3, rel=0.1)


def test_conjugate_phase_mistake_fails_the_recovery(synthetic, tmp_path):
    # the calibration's phase read with the wrong sign (holoprobe's convention mistaken
    # for the certificate's): the pulse is distorted and shifted by twice the delay
    wrong = load_calibration(_write_calibration(tmp_path / "w.csv", phase_sign=-1.0))
    dec = deconvolve_hydrophone(synthetic["v"], FS, wrong)
    corr = np.corrcoef(dec.pressure, synthetic["p"])[0, 1]
    assert corr < 0.9, corr


def test_kept_offset_mistake_fails_the_recovery(synthetic):
    cfg = HydrophoneDeconvolutionConfig(remove_offset=False)
    res = hydrophone_pulse(synthetic["v"], FS, synthetic["cal"], config=cfg, n_draws=20)
    err = _errors(res.parameters.values, _truth(synthetic["p"]))
    assert abs(err["p_c_Pa"]) > 0.2 and abs(err["pii_J_per_m2"]) > 0.2, err


def test_pydynamic_path_equals_the_holoprobe_convention_filter(synthetic):
    # PyDynamic works in numpy's FFT convention, regularised_inverse in holoprobe's:
    # the same offset-free voltage must give the same pressure
    d = synthetic["result"].pressure
    f = frequency_axis(d.voltage.size, FS)
    direct = to_time(to_frequency(d.voltage) * regularised_inverse(d.calibration, f,
                                                                   d.cutoff_hz, d.config),
                     d.voltage.size)
    np.testing.assert_allclose(d.pressure, direct, atol=1e-9 * np.abs(direct).max())
    scan, cutoff = deconvolve_records(synthetic["v"][None, None, :] + np.zeros((2, 1, 1)), FS,
                                      synthetic["cal"], config=d.config)
    assert cutoff == pytest.approx(d.cutoff_hz)
    np.testing.assert_allclose(scan[1, 0], d.pressure, atol=1e-6 * np.abs(direct).max())


def test_noise_uncertainty_matches_monte_carlo_of_the_voltage_noise(synthetic):
    d = synthetic["result"].pressure
    no_cal_unc = HydrophoneCalibration(d.calibration.frequency, d.calibration.sensitivity,
                                       d.calibration.phase)
    draws = type(d)(**{**d.__dict__, "calibration": no_cal_unc}).draws(300, seed=3)
    mc = draws.std(axis=0, ddof=1)
    # the analytic GUM propagation (PyDynamic, white noise + offset) vs the empirical spread
    assert np.median(mc / d.u_pressure_noise) == pytest.approx(1.0, abs=0.06)
    assert np.all(d.u_pressure >= d.u_pressure_noise - 1e-9)


def test_time_variance_equals_pydynamic_gum_idft_diagonal():
    from PyDynamic.uncertainty.propagate_DFT import GUM_iDFT

    rng = np.random.default_rng(0)
    for n in (16, 17):
        m = n // 2 + 1
        rr, ii = rng.uniform(0.5, 2.0, m), rng.uniform(0.5, 2.0, m)
        ri = rng.uniform(-0.4, 0.4, m)
        uf = np.zeros((2 * m, 2 * m))
        uf[:m, :m] = np.diag(rr)
        uf[m:, m:] = np.diag(ii)
        uf[:m, m:] = uf[m:, :m] = np.diag(ri)
        _, ux = GUM_iDFT(np.zeros(2 * m), uf, Nx=n)
        np.testing.assert_allclose(_time_variance(rr, ri, ii, n), np.diag(ux), rtol=1e-10)


def test_voltage_dft_equals_pydynamic_gum_dft_for_white_noise():
    from PyDynamic.uncertainty.propagate_DFT import GUM_DFT

    from holoprobe.signal import voltage_dft

    rng = np.random.default_rng(1)
    for n in (64, 65):
        x = rng.standard_normal(n)
        y, uy = voltage_dft(x, 0.3)
        y_ref, uy_ref = GUM_DFT(x, 0.3)
        np.testing.assert_allclose(y, y_ref, atol=1e-12)
        np.testing.assert_allclose(uy, uy_ref, rtol=1e-9, atol=1e-12)


def test_amplitude_only_calibration_uses_the_minimum_phase(tmp_path):
    # the resonant hydrophone without cable delay is minimum phase: its magnitude alone
    # (the old file format) determines its phase
    _, v, p = _record(delay=0.0, seed=4)
    f = np.arange(1e6, 60.01e6, 0.5e6)
    np.savetxt(tmp_path / "a.csv", np.column_stack([f, np.abs(_sensitivity_fft(f, 0.0))]),
               delimiter=",", header="frequency_Hz,sensitivity_V_per_Pa", comments="")
    cal = load_calibration(tmp_path / "a.csv")
    assert cal.phase is None
    good = deconvolve_hydrophone(v, FS, cal)
    flat = deconvolve_hydrophone(v, FS, cal, config=HydrophoneDeconvolutionConfig(
        amplitude_only_phase="zero"))
    assert np.corrcoef(good.pressure, p)[0, 1] >= 0.995
    assert np.std(good.pressure - p) < 0.5 * np.std(flat.pressure - p)


def test_cli_writes_pressure_csv_pulse_json_and_figure(synthetic):
    from typer.testing import CliRunner

    from holoprobe.cli import app

    tmp = synthetic["dir"]
    np.savetxt(tmp / "wave.csv", np.column_stack([synthetic["t"], synthetic["v"]]),
               delimiter=",", header="time_s,voltage_V", comments="")
    res = CliRunner().invoke(app, ["hydrophone", "deconvolve", str(tmp / "wave.csv"),
                                   "--calibration", str(tmp / "cal.csv"), "--out",
                                   str(tmp / "out"), "--draws", "20", "--quiet"])
    assert res.exit_code == 0, res.output
    assert (tmp / "out" / "pressure.csv").read_text().splitlines()[0] == \
        "time_s,pressure_Pa,u_pressure_Pa"
    table = np.loadtxt(tmp / "out" / "pressure.csv", delimiter=",", skiprows=1)
    assert np.corrcoef(table[:, 1], synthetic["p"])[0, 1] >= 0.995
    pulse = json.loads((tmp / "out" / "pulse.json").read_text())
    for key in ("p_c_Pa", "p_r_Pa", "pii_J_per_m2", "pulse_duration_s", "f_awf_Hz"):
        assert pulse[key] > 0 and pulse["u_" + key] > 0
    assert (tmp / "out" / "deconvolution.png").stat().st_size > 10_000


def test_bad_waveform_and_calibration_files_name_file_and_field(tmp_path):
    t = np.arange(100) / FS
    t[50] += 0.3 / FS
    np.savetxt(tmp_path / "w.csv", np.column_stack([t, t]), delimiter=",",
               header="time_s,voltage_V", comments="")
    with pytest.raises(InputError, match=r"w\.csv: time_s: expected uniformly"):
        read_waveform_csv(tmp_path / "w.csv")
    (tmp_path / "c.csv").write_text(HEADER.split(",u_")[0] + "\n1e6,5e-8,0\n2e6,-5e-8,0\n")
    with pytest.raises(InputError, match=r"c\.csv: magnitude_V_per_Pa: expected magnitudes"):
        load_calibration(tmp_path / "c.csv")


def test_characterize_deconvolves_a_voltage_scan_with_a_complex_calibration(synthetic):
    from holoprobe.characterize import CharacterizationConfig
    from holoprobe.characterize._pipeline import _pressure
    from holoprobe.geometry import PlaneGrid
    from holoprobe.measurement import HydrophoneScan

    data = np.stack([synthetic["v"], 0.5 * synthetic["v"]]).reshape(2, 1, -1)
    scan = HydrophoneScan(data=data.astype(np.float32), grid=PlaneGrid(
        x=np.array([0.0, 1e-3]), y=np.array([0.0])), sampling_rate=FS)
    cfg = CharacterizationConfig().with_overrides(["hydrophone.cutoff_hz=15e6"])
    pressure = _pressure(scan, synthetic["cal"], [], cfg)
    assert np.corrcoef(pressure[0, 0], synthetic["p"])[0, 1] >= 0.995
    assert pressure[0, 0].min() == pytest.approx(synthetic["p"].min(), rel=0.03)
    # each trace loses its own offset: the half-amplitude trace carries half the pressure
    np.testing.assert_allclose(pressure[1, 0], 0.5 * pressure[0, 0],
                               atol=0.01 * np.abs(pressure[0, 0]).max())
