"""Hydrophone calibration: reading curves, voltage ↔ pressure (holoprobe.signal._calibration)."""

import numpy as np
import pytest
import scipy.io

from holoprobe.errors import InputError
from holoprobe.measurement import HydrophoneCalibration
from holoprobe.signal import (
    default_calibration,
    frequency_axis,
    load_calibration,
    pressure_from_voltage,
    pressure_spectrum_from_voltage,
    to_frequency,
    to_time,
    voltage_from_pressure,
)

# reference_spec 2.1 [calc]: the published code's inverse sensitivity (kPa/mV, including its
# polarity −1) at 0 / 1 / 2.5 / 5 / 10 / 12.5 MHz, PCHIP extrapolated below 1 MHz.
REF_F = np.array([0.0, 1.0, 2.5, 5.0, 10.0, 12.5]) * 1e6
REF_SINV_KPA_PER_MV = np.array([-11.8624, -10.9536, -9.1405, -6.2562, -4.4268, -4.1315])


def _impulse_transfer(cal, fs, n, **kw):
    x = np.zeros(n)
    x[0] = 1.0
    return frequency_axis(n, fs), to_frequency(pressure_from_voltage(x, fs, cal, **kw))


def test_packaged_curve_is_the_toolkit_curve_in_si_units_with_inverting_polarity():
    cal = default_calibration()
    assert cal.polarity == -1
    assert cal.frequency[0] == 1e6 and cal.frequency[-1] == 30e6 and cal.frequency.size == 30
    # sensitivity.mat: 91.29414 mV/MPa at 1 MHz, 290.3261 at 30 MHz (1 mV/MPa = 1e-9 V/Pa)
    assert cal.sensitivity[0] == pytest.approx(91.29414e-9, rel=1e-9)
    assert cal.sensitivity[-1] == pytest.approx(290.3261e-9, rel=1e-9)


def test_impulse_transfer_matches_published_inverse_sensitivity_values():
    cal = default_calibration()
    f, h = _impulse_transfer(cal, 250e6, 1000, below="extrapolate")  # 0.25 MHz bins
    k = np.rint(REF_F / (f[1] - f[0])).astype(int)
    np.testing.assert_allclose(h[k].real, REF_SINV_KPA_PER_MV * 1e6, rtol=2e-5)
    np.testing.assert_allclose(h[k].imag, 0, atol=1e-3)


def test_impulse_transfer_is_inverse_sensitivity_at_calibrated_frequencies_and_band_rules():
    f_cal = np.array([1e6, 2e6, 4e6, 8e6])
    s_cal = np.array([2e-8, 3e-8, 5e-8, 4e-8])
    cal = HydrophoneCalibration(frequency=f_cal, sensitivity=s_cal)
    f, h = _impulse_transfer(cal, 100e6, 400)  # 0.25 MHz bins, hold below / zero above
    for fc, sc in zip(f_cal, s_cal, strict=True):
        assert h[np.argmin(np.abs(f - fc))].real == pytest.approx(1 / sc, rel=1e-9)
    assert np.allclose(h[f < 1e6].real, 1 / s_cal[0])  # held edge value down to DC
    assert np.all(np.abs(h[f > 8e6]) < 1e-12 / s_cal[-1])
    _, h_taper = _impulse_transfer(cal, 100e6, 400, above="taper", taper_width=2e6)
    k9 = np.argmin(np.abs(f - 9e6))
    assert h_taper[k9].real == pytest.approx(0.5 / s_cal[-1], rel=1e-9)  # half-way down
    assert np.all(np.abs(h_taper[f >= 10e6]) < 1e-12 / s_cal[-1])
    _, h_band = _impulse_transfer(cal, 100e6, 400, min_frequency=2e6, max_frequency=4e6)
    assert np.all(np.abs(h_band[(f < 2e6) | (f > 4e6)]) < 1e-12 / s_cal[-1])


def test_voltage_pressure_round_trip_in_band_on_scan_shaped_array():
    cal = default_calibration()
    fs, nt = 25e6, 256
    rng = np.random.default_rng(0)
    p = rng.standard_normal((5, 4, nt))
    f = frequency_axis(nt, fs)
    spec = to_frequency(p)
    spec[..., (f < 1e6) | (f > 12e6)] = 0  # keep the calibrated band
    p = to_time(spec, nt)  # band-limited test pressure
    v = voltage_from_pressure(p, fs, cal, chunk_traces=3)
    back = pressure_from_voltage(v, fs, cal, chunk_traces=7)
    np.testing.assert_allclose(back, p, atol=1e-12 * np.abs(p).max())
    # the voltage is ~ −S·p: 1e-7 V/Pa scale, inverted
    assert np.corrcoef(v.ravel(), p.ravel())[0, 1] < -0.9


@pytest.mark.parametrize("nt", [400, 401])
def test_pressure_spectrum_from_voltage_is_the_inverse_sensitivity_times_the_voltage(nt):
    """An impulse's spectrum is 1/S at the calibrated frequencies (the published values'
    test above, through the direct path), real at DC (and Nyquist); random records give
    the spectrum of pressure_from_voltage's pressure, float32 in complex64."""
    f_cal = np.array([1e6, 2e6, 4e6, 8e6])
    s_cal = np.array([2e-8, 3e-8, 5e-8, 4e-8])
    cal = HydrophoneCalibration(frequency=f_cal, sensitivity=s_cal, polarity=-1)
    x = np.zeros(nt)
    x[0] = 1.0
    f, h = frequency_axis(nt, 100e6), pressure_spectrum_from_voltage(x, 100e6, cal)
    for fc, sc in zip(f_cal, s_cal, strict=True):
        if nt == 400:  # 0.25 MHz bins: the calibrated frequencies are bins
            assert h[np.argmin(np.abs(f - fc))].real == pytest.approx(-1 / sc, rel=1e-9)
    assert np.all(np.abs(h[f > 8e6]) < 1e-12 / s_cal[-1])
    v = np.random.default_rng(4).standard_normal((3, 2, nt)).astype(np.float32) * 1e-3
    direct = pressure_spectrum_from_voltage(v, 100e6, cal)
    assert direct.dtype == np.complex64 and direct[..., 0].imag.max() == 0
    via_time = to_frequency(pressure_from_voltage(v, 100e6, cal))
    np.testing.assert_allclose(direct, via_time, rtol=0, atol=2e-6 * np.abs(via_time).max())
    with pytest.raises(InputError, match="real"):
        pressure_spectrum_from_voltage(v + 1j, 100e6, cal)


def test_calibration_phase_of_a_pure_delay_shifts_the_pulse_by_that_delay():
    tau = 80e-9
    f_cal = np.linspace(0.5e6, 20e6, 40)
    cal = HydrophoneCalibration(frequency=f_cal, sensitivity=np.full(40, 1e-7),
                                phase=2 * np.pi * f_cal * tau)  # delay in holoprobe convention
    fs, n = 100e6, 512
    t = np.arange(n) / fs
    pulse = np.exp(-((t - 2e-6) / 0.2e-6) ** 2) * np.sin(2 * np.pi * 3e6 * (t - 2e-6))
    v = voltage_from_pressure(pulse, fs, cal)
    expected_v = 1e-7 * np.exp(-((t - 2e-6 - tau) / 0.2e-6) ** 2) * np.sin(
        2 * np.pi * 3e6 * (t - 2e-6 - tau))
    np.testing.assert_allclose(v, expected_v, atol=2e-3 * 1e-7)
    np.testing.assert_allclose(pressure_from_voltage(v, fs, cal), pulse, atol=2e-3)


def test_load_csv_with_polarity_comment_and_phase(tmp_path):
    path = tmp_path / "cal.csv"
    path.write_text("# my hydrophone\n# polarity: -1\nfrequency_Hz,sensitivity_V_per_Pa,"
                    "phase_rad\n1e6,1e-7,0.1\n2e6,2e-7,0.2\n")
    cal = load_calibration(path)
    assert cal.polarity == -1 and cal.phase is not None
    np.testing.assert_allclose(cal.sensitivity, [1e-7, 2e-7])
    assert load_calibration(path, polarity=1).polarity == 1


def test_load_toolkit_mat_v5_converts_mhz_and_mv_per_mpa(tmp_path):
    path = tmp_path / "sensitivity.mat"
    scipy.io.savemat(path, {"Frequency": np.array([[1.0], [2.0], [3.0]]),
                            "Sensitivity": np.array([[100.0], [150.0], [200.0]])})
    cal = load_calibration(path)
    np.testing.assert_allclose(cal.frequency, [1e6, 2e6, 3e6])
    np.testing.assert_allclose(cal.sensitivity, [1e-7, 1.5e-7, 2e-7])
    assert cal.polarity == -1


def test_load_toolkit_mat_v73(tmp_path):
    hdf5storage = pytest.importorskip("hdf5storage")
    path = tmp_path / "sensitivity73.mat"
    hdf5storage.savemat(str(path), {"Frequency": np.array([[1.0], [2.0]]),
                                    "Sensitivity": np.array([[100.0], [150.0]])},
                        format="7.3", matlab_compatible=True)
    cal = load_calibration(path)
    np.testing.assert_allclose(cal.sensitivity, [1e-7, 1.5e-7])


@pytest.mark.parametrize(
    ("content", "field"),
    [
        ("frequency_Hz,wrong\n1e6,1e-7\n2e6,2e-7\n", "sensitivity_V_per_Pa"),
        ("frequency_Hz,sensitivity_V_per_Pa\n2e6,1e-7\n1e6,2e-7\n", "frequency_Hz"),
        ("frequency_Hz,sensitivity_V_per_Pa\n1e6,1e-7\n2e6,abc\n", "sensitivity_V_per_Pa"),
        ("frequency_Hz,sensitivity_V_per_Pa\n1e6,1e-7\n2e6,-2e-7\n", "sensitivity_V_per_Pa"),
    ],
)
def test_bad_csv_raises_input_error_naming_file_and_field(tmp_path, content, field):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    with pytest.raises(InputError) as err:
        load_calibration(path)
    assert err.value.field == field and "bad.csv" in str(err.value)


def test_bad_mat_raises_input_error_for_missing_field_and_shape(tmp_path):
    path = tmp_path / "s.mat"
    scipy.io.savemat(path, {"Frequency": np.array([1.0, 2.0])})
    with pytest.raises(InputError, match="Sensitivity"):
        load_calibration(path)
    scipy.io.savemat(path, {"Frequency": np.ones((2, 2)), "Sensitivity": np.ones(4)})
    with pytest.raises(InputError, match="shape"):
        load_calibration(path)
    with pytest.raises(InputError, match="no such file"):
        load_calibration(tmp_path / "missing.csv")
