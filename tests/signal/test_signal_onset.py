"""Onset detection: the first zero crossing before the pulse leaves the noise
(holoprobe.signal._onset)."""

import numpy as np
import pytest

from holoprobe.errors import FitError, InputError
from holoprobe.signal import detect_onset, noise_sigma

FS, N, F0 = 25e6, 500, 2.5e6
S_ENV, T_C = 0.25e-6, 0.9e-6


def pulse(t):
    """Band-limited pulse whose first lobe above the noise starts with a true zero crossing
    at t = 0: lobes grow ~18× per half period, so the lobe before t = 0 stays far below the
    detection level while the one after it is far above."""
    return np.sin(2 * np.pi * F0 * t) * np.exp(-((t - T_C) ** 2) / (2 * S_ENV**2))


def test_noise_free_onset_is_the_zero_crossing_to_a_hundredth_of_a_sample():
    for t0 in (3e-6 + 0.37 / FS, 5e-6 + 0.81 / FS):
        x = pulse(np.arange(N) / FS - t0)
        assert (detect_onset(x, FS, noise=1e-4, threshold=10) - t0) * FS == pytest.approx(
            0, abs=1e-2)


@pytest.mark.parametrize("polarity", ["either", "positive", "negative"])
def test_noisy_delayed_pulses_of_both_signs_give_sub_sample_onsets(polarity):
    rng = np.random.default_rng(7)
    errors = []
    for _ in range(40):
        t0 = 6e-6 + rng.uniform(0, 1) / FS
        sign = rng.choice([-1, 1])
        x = sign * pulse(np.arange(N) / FS - t0) + 2e-4 * rng.standard_normal(N)
        same = polarity == "either" or (polarity == "positive") == (sign > 0)
        truth = t0 if same else t0 + 0.5 / F0  # opposite polarity: the next lobe
        errors.append((detect_onset(x, FS, polarity=polarity, threshold=10) - truth) * FS)
    errors = np.array(errors)
    assert np.sqrt(np.mean(errors**2)) < 0.35
    assert np.max(np.abs(errors)) < 1.0
    assert abs(np.mean(errors)) < 0.1


def test_noise_sigma_is_robust_to_the_pulse_and_window_estimate_agrees():
    rng = np.random.default_rng(1)
    x = 0.01 * rng.standard_normal(N) + pulse(np.arange(N) / FS - 12e-6)
    assert noise_sigma(x, FS) == pytest.approx(0.01, rel=0.15)
    assert noise_sigma(x, FS, noise_window=(0, 8e-6)) == pytest.approx(0.01, rel=0.15)


def test_pulse_starting_before_the_record_wraps_to_a_negative_onset():
    t0 = -0.05e-6  # the first lobe above 10 σ starts 1.25 samples before the record
    t = np.arange(N) / FS
    x = pulse(t - t0) + pulse(t - t0 - N / FS)  # periodic record: the onset lies at its end
    t = detect_onset(x, FS, noise=1e-4, threshold=10)
    assert t == pytest.approx(t0, abs=0.02 / FS)
    with pytest.raises(FitError, match="zero crossing"):
        detect_onset(x, FS, noise=1e-4, threshold=10, allow_wrap=False)


def test_signal_that_never_exceeds_the_threshold_raises_a_clear_error():
    rng = np.random.default_rng(2)
    with pytest.raises(FitError, match="no onset: the signal never exceeds 5 σ"):
        detect_onset(rng.standard_normal(N), FS, noise=1.0)


def test_a_failed_onset_is_a_fit_error_not_an_input_error():
    from holoprobe.errors import HoloprobeError

    with pytest.raises(FitError) as err:
        detect_onset(np.zeros(64), FS, noise=1.0)
    assert not isinstance(err.value, InputError)
    assert isinstance(err.value, HoloprobeError) and err.value.field == "signal"
    with pytest.raises(InputError, match="polarity"):  # a wrong argument stays InputError
        detect_onset(np.zeros(64), FS, polarity="sideways")


def test_a_noise_free_record_with_a_smooth_drift_has_its_onset_at_the_true_crossing():
    """A simulated, noise-free record: before the pulse only a smooth drift of 1e-8 of
    the peak (a high-pass's residual), so the noise estimate is ~1e-12 and every pre-pulse
    sample is "above the noise" with no zero crossing before it (this raised FitError
    before σ had a floor 80 dB below the peak). The onset is the pulse's true crossing."""
    t = np.arange(N) / FS
    for t0 in (3e-6 + 0.37 / FS, 5e-6 + 0.81 / FS):
        x = pulse(t - t0) + 1e-8 * (1 + 0.01 * np.sin(2 * np.pi * t / (N / FS)))
        assert noise_sigma(x, FS) < 1e-10
        onset = detect_onset(x, FS, allow_wrap=False, threshold=10)
        assert (onset - t0) * FS == pytest.approx(0, abs=1e-2)
        with pytest.raises(FitError, match="no zero crossing"):
            detect_onset(x, FS, allow_wrap=False, dynamic_range=np.inf)


def test_the_noise_floor_leaves_noisy_records_unchanged():
    rng = np.random.default_rng(3)
    x = pulse(np.arange(N) / FS - 4e-6) + 1e-3 * rng.standard_normal(N)
    assert detect_onset(x, FS) == detect_onset(x, FS, dynamic_range=np.inf)
