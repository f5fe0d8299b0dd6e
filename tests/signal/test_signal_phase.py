"""Phase tools: minimum phase, filter phase from group delay, phase compensation
(holoprobe.signal._phase)."""


import numpy as np
import pytest
import scipy.signal

from _shared import SHARED_DATA
from holoprobe.errors import InputError
from holoprobe.signal import (
    compensate_phase,
    filter_phase_from_group_delay,
    minimum_phase,
)


def test_first_order_low_pass_minimum_phase_is_minus_atan_in_fft_convention():
    w = np.logspace(-2, 2, 200)  # ω/ω0; given only over four decades
    mag = 1 / np.sqrt(1 + w**2)
    sel = (w >= 0.1) & (w <= 10)
    fft = minimum_phase(w, mag, convention="fft", extrapolation="slope")
    np.testing.assert_allclose(fft[sel], -np.arctan(w[sel]), rtol=1e-2)
    hp = minimum_phase(w, mag, extrapolation="slope")  # holoprobe (conjugate) convention
    np.testing.assert_allclose(hp[sel], np.arctan(w[sel]), rtol=1e-2)
    # the published code gives +0.45325 at ω = 1 for ω0 = 2 (truth in FFT convention −0.46365)
    w2 = np.logspace(-3, 3, 300)
    at1 = minimum_phase(w2, 1 / np.sqrt(1 + (w2 / 2) ** 2), at=[1.0], convention="fft",
                        extrapolation="slope")
    assert at1[0] == pytest.approx(-np.arctan(0.5), rel=1e-3)


def test_minimum_phase_of_an_analog_butterworth_matches_its_true_phase():
    b, a = scipy.signal.butter(3, 2 * np.pi * 15e6, analog=True)  # minimum phase
    f = np.logspace(5, 9, 300)
    _, h = scipy.signal.freqs(b, a, worN=2 * np.pi * f)
    est = minimum_phase(f, np.abs(h), convention="fft", extrapolation="slope")
    sel = (f > 1e6) & (f < 1e8)
    np.testing.assert_allclose(est[sel], np.unwrap(np.angle(h))[sel], atol=2e-3)


def test_group_delay_arrays_give_linear_phase_for_constant_delay():
    resp = filter_phase_from_group_delay(([1e6, 10e6, 30e6], [50e-9, 50e-9, 50e-9]))
    f = np.array([0.0, 2e6, 20e6, 40e6])
    np.testing.assert_allclose(resp(f, convention="fft"), -2 * np.pi * f * 50e-9, atol=1e-12)
    np.testing.assert_allclose(resp(f), 2 * np.pi * f * 50e-9, atol=1e-12)


def test_minicircuits_datasheet_is_parsed_from_its_header(tmp_path):
    # the format of BLP-15+.txt: a source line, a header with two frequency columns
    text = ("Data source: datasheet\n"
            "Frequency (MHz), Insertion Loss (dB), Standard Deviation (dB), Return Loss (dB),"
            " Frequency (MHz), Group Delay (nsec)\n"
            "1.00, 0.21, 0.04, 24.91, 1.00, 48.00\n"
            "3.00, 0.26, 0.04, 20.32, 2.00, 48.00\n"
            "5.00, 0.30, 0.04, 20.46, 4.00, 48.00\n")
    path = tmp_path / "filter.txt"
    path.write_text(text)
    resp = filter_phase_from_group_delay(path)
    assert resp(3e6, convention="fft") == pytest.approx(-2 * np.pi * 3e6 * 48e-9, rel=1e-9)
    bad = tmp_path / "bad.txt"
    bad.write_text("Frequency (MHz), Loss (dB)\n1, 2\n")
    with pytest.raises(InputError, match="Group Delay"):
        filter_phase_from_group_delay(bad)


def test_shipped_blp15_datasheet_phase_if_reference_data_present():
    # reads shared/ (beside the repository) only to check the real file's layout; skipped elsewhere
    path = SHARED_DATA / "BLP-15+.txt"
    if not path.is_file():
        pytest.skip("reference data not available")
    resp = filter_phase_from_group_delay(path)
    # 48.07 ns at 1 MHz, held down to DC: φ(1 MHz) = −2π · 1 MHz · 48.07 ns
    assert resp(1e6, convention="fft") == pytest.approx(-2 * np.pi * 1e6 * 48.07e-9, rel=1e-6)


@pytest.mark.parametrize("direction", [1, -1])
def test_compensating_a_filtered_ir_recovers_it_and_the_sign_matters(direction):
    fs, n = 250e6, 4096
    t = np.arange(n) / fs
    ir = np.exp(-((t - 3e-6) / 0.25e-6) ** 2) * np.sin(2 * np.pi * 2.5e6 * (t - 3e-6))
    # a real causal filter (Bessel low-pass, ~flat group delay in band), applied in time
    b, a = scipy.signal.bessel(6, 6e6, fs=fs, norm="delay")  # 26 ns group delay
    w, gd = scipy.signal.group_delay((b, a), w=np.linspace(0.1e6, 30e6, 300), fs=fs)
    phase = filter_phase_from_group_delay((w, gd / fs))
    if direction == 1:  # the filter is in the measured IR: remove it
        measured = scipy.signal.lfilter(b, a, ir)
        truth = ir
    else:  # the filter entered inversely: applying it reproduces the filtered IR
        measured = ir
        truth = scipy.signal.lfilter(b, a, ir)
    out = compensate_phase(measured, fs, phase, direction=direction, pad=256)
    assert np.corrcoef(out, truth)[0, 1] > 0.9999
    wrong = compensate_phase(measured, fs, phase, direction=-direction, pad=256)
    assert np.corrcoef(wrong, truth)[0, 1] < 0.8  # twice the delay: the sign error
