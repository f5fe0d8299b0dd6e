"""TransmitSetting: delay laws, apodizations, drives, TOML loading."""

from __future__ import annotations

import math

import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.measurement import DriveSignal
from holoprobe.transducer import (
    Apodization,
    TransmitSetting,
    apodization_weights,
    burst,
    diverging_delays,
    focused_delays,
    plane_wave_delays,
    rectangular_pulse,
)

C0 = 1481.0
X = (np.arange(16) - 7.5) * 0.3e-3
POS = np.stack([X, np.zeros(16), np.zeros(16)], axis=-1)


def test_focused_delays_equalise_the_arrival_times_at_the_focus():
    focus = np.array([2e-3, 0.0, 30e-3])
    tau = focused_delays(POS, focus, C0)
    arrival = tau + np.hypot(X - focus[0], focus[2]) / C0
    np.testing.assert_allclose(arrival, arrival[0], rtol=0, atol=1e-15)
    assert tau.min() == 0.0
    # the path differences over c0: the outer element farthest from the focus fires first
    assert np.argmin(tau) == 0
    nearest = np.argmin(np.abs(X - 2e-3))
    assert np.argmax(tau) == nearest
    assert tau.max() == pytest.approx((math.hypot(X[0] - 2e-3, 30e-3)
                                       - math.hypot(X[nearest] - 2e-3, 30e-3)) / C0, rel=1e-12)


def test_plane_wave_delays_are_linear_in_x_with_slope_sin_theta_over_c0():
    theta = math.radians(12.0)
    tau = plane_wave_delays(POS, theta, C0)
    np.testing.assert_allclose(np.diff(tau), 0.3e-3 * math.sin(theta) / C0, rtol=1e-12)
    assert tau.min() == 0.0


def test_diverging_delays_make_a_spherical_wavefront_centred_on_the_virtual_source():
    src = np.array([0.0, 0.0, -35e-3])
    tau = diverging_delays(POS, src, C0)
    # each element fires when a sphere from the virtual source would pass it
    r = np.hypot(X, 35e-3)
    np.testing.assert_allclose(tau, (r - r.min()) / C0, atol=1e-18)
    np.testing.assert_allclose(diverging_delays(POS, 35e-3, C0), tau)
    with pytest.raises(InputError, match="behind the probe"):
        diverging_delays(POS, (0.0, 0.0, 5e-3), C0)


def test_apodization_windows():
    assert np.all(apodization_weights(16) == 1.0)
    hann = apodization_weights(16, "hann")
    n = np.arange(1, 17)
    np.testing.assert_allclose(hann, np.sin(np.pi * n / 17) ** 2, atol=1e-15)
    tukey = apodization_weights(16, "tukey", alpha=0.5)
    np.testing.assert_allclose(tukey, tukey[::-1])
    assert np.all(tukey[5:11] == 1.0) and 0 < tukey[0] < 0.2
    np.testing.assert_allclose(apodization_weights(16, "tukey", alpha=1.0), hann, atol=1e-15)
    np.testing.assert_allclose(apodization_weights(16, "tukey", alpha=0.0), 1.0)
    from scipy.signal.windows import tukey as scipy_tukey  # the definition (NumPy inside)

    for count in (1, 2, 7, 96, 128):
        for alpha in (0.1, 0.25, 0.5, 0.99):
            np.testing.assert_allclose(apodization_weights(count, "tukey", alpha=alpha),
                                       scipy_tukey(count + 2, alpha)[1:-1], atol=1e-14)
    with pytest.raises(InputError, match="16 weights"):
        apodization_weights(16, "explicit", values=np.ones(3))


def test_burst_has_n_cycles_at_f0_and_the_given_amplitude():
    d = burst(2.5e6, 3, 20.0, sampling_rate=250e6)
    assert isinstance(d, DriveSignal)
    assert d.peak == pytest.approx(20.0, rel=1e-3)
    nonzero = np.flatnonzero(np.abs(d.voltage) > 1e-9)
    assert (nonzero[-1] + 1) / 250e6 == pytest.approx(3 / 2.5e6, abs=2 / 250e6)
    spec = np.abs(np.fft.rfft(d.voltage, 1 << 16))
    f = np.fft.rfftfreq(1 << 16, 1 / 250e6)
    assert f[np.argmax(spec)] == pytest.approx(2.5e6, rel=0.02)


def test_rectangular_pulse_area():
    d = rectangular_pulse(30.0, 20e-9, sampling_rate=250e6)
    assert d.area == pytest.approx(30.0 * 20e-9)


def test_setting_builders_and_element_numbers():
    drive = burst(2.5e6, 2, 30.0)
    tx = TransmitSetting.focused((0.0, 30e-3), drive=drive, apodization="hann", prf=1e3)
    assert tx.delays.point == (0.0, 0.0, 30e-3)
    np.testing.assert_allclose(tx.element_delays(POS, C0), focused_delays(POS, (0, 0, 30e-3), C0))
    np.testing.assert_allclose(tx.element_weights(16), apodization_weights(16, "hann"))
    tx = TransmitSetting.diverging(35e-3, drive=drive, apodization=Apodization("tukey", 0.3))
    assert tx.delays.point == (0.0, 0.0, -35e-3)
    tx = TransmitSetting.plane_wave(0.1, drive=drive, apodization=np.linspace(0, 1, 16))
    assert tx.apodization.kind == "explicit"
    with pytest.raises(InputError):
        TransmitSetting.focused((0.0, 0.0, -1e-3), drive=drive)
    with pytest.raises(InputError, match="prf"):
        TransmitSetting(drive, prf=-1.0)


def test_from_toml_reads_every_part(tmp_path):
    (tmp_path / "drive.csv").write_text("# V\n0\n1\n-1\n0\n")
    path = tmp_path / "tx.toml"
    path.write_text("""
format = "holoprobe-transmit"
name = "diverging"
prf = 2000.0
[delays]
kind = "diverging"
distance = 0.035
[apodization]
kind = "tukey"
alpha = 0.25
[drive]
kind = "file"
file = "drive.csv"
sampling_rate = 100e6
""")
    tx = TransmitSetting.from_toml(path)
    assert tx.name == "diverging" and tx.prf == 2000.0
    np.testing.assert_allclose(tx.element_delays(POS, C0), diverging_delays(POS, 35e-3, C0))
    np.testing.assert_allclose(tx.element_weights(16), apodization_weights(16, "tukey",
                                                                           alpha=0.25))
    np.testing.assert_array_equal(tx.drive.voltage, [0, 1, -1, 0])
    assert tx.drive.sampling_rate == 100e6

    path.write_text("""
[delays]
kind = "plane_wave"
angle_deg = 10.0
[drive]
kind = "burst"
frequency = 2.5e6
cycles = 2
amplitude = 30.0
""")
    tx = TransmitSetting.from_toml(path)
    assert tx.delays.angle == pytest.approx(math.radians(10.0))
    assert tx.drive.peak == pytest.approx(30.0, rel=1e-3)


@pytest.mark.parametrize(("text", "field"), [
    ("[drive]\nkind = 'burst'\nfrequency = 2.5e6\namplitude = 1.0\n", "drive.cycles"),
    ("[delays]\nkind = 'focused'\n[drive]\nkind='pulse'\namplitude=1.0\nduration=1e-8\n",
     "delays.point"),
    ("[delays]\nkind = 'zigzag'\n[drive]\nkind='pulse'\namplitude=1.0\nduration=1e-8\n",
     "delays.kind"),
    ("[drive]\nkind = 'pulse'\namplitude = 'high'\nduration = 1e-8\n", "drive.amplitude"),
    ("name = 'no drive'\n", "drive"),
    ("[drive\n", None),
])
def test_from_toml_errors_name_file_and_key(tmp_path, text, field):
    path = tmp_path / "tx.toml"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        TransmitSetting.from_toml(path)
    assert info.value.file == str(path)
    assert info.value.field == field
