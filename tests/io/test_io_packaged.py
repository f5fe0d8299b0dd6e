"""Packaged P4-1 impulse responses and the probe preset (holoprobe.io._packaged)."""

from pathlib import Path

import numpy as np
import pytest

from _shared import SHARED_DATA
from holoprobe.errors import InputError
from holoprobe.io import (
    ImpulseResponses,
    impulse_responses_from_proteus,
    load_packaged_impulse_responses,
    load_probe_preset,
    probe_info_from_preset,
    read_impulse_responses,
    write_impulse_responses,
)

PROTEUS = SHARED_DATA / "P4-1_measured_settings_PROTEUS.mat"


def test_packaged_p4_1_responses_match_the_published_extrema():
    irs = load_packaged_impulse_responses("p4-1")
    assert irs.sampling_rate == 250e6
    assert irs.transmit.shape == irs.receive.shape == (500,)  # first 2 us
    assert irs.transmit_units == "Pa/(V*s)" and irs.receive_units == "ADCL/(Pa*s)"
    assert "Blanken" in irs.source and irs.license == "LGPL-3.0"
    # reference_spec section 4 (analysis/GUI_output_parameters.mat)
    t = irs.transmit_time
    assert irs.transmit.max() == pytest.approx(9.5337e10, rel=1e-4)
    assert t[irs.transmit.argmax()] == pytest.approx(0.632e-6, abs=1e-12)
    assert irs.transmit.min() == pytest.approx(-1.19166e11, rel=1e-5)
    assert t[irs.transmit.argmin()] == pytest.approx(0.460e-6, abs=1e-12)
    assert irs.transmit[0] == pytest.approx(-5.0255e7, rel=1e-4)
    assert irs.receive.max() == pytest.approx(1.16193e6, rel=1e-5)
    assert irs.receive_time[irs.receive.argmax()] == pytest.approx(0.512e-6, abs=1e-12)
    assert irs.receive.min() == pytest.approx(-1.86351e6, rel=1e-5)
    assert irs.receive_time[irs.receive.argmin()] == pytest.approx(0.344e-6, abs=1e-12)
    assert irs.receive[0] == pytest.approx(35474.39, rel=1e-6)


def test_transmit_response_spectrum_peaks_near_the_published_2_55_mhz():
    irs = load_packaged_impulse_responses()
    n = 1 << 16  # zero-padded for a fine frequency grid
    spectrum = np.abs(np.fft.rfft(irs.transmit - irs.transmit.mean(), n))
    f = np.fft.rfftfreq(n, 1 / irs.sampling_rate)
    # 2 us truncation broadens the peak; published value 2.55 MHz (full-length IR)
    assert f[spectrum.argmax()] == pytest.approx(2.55e6, abs=0.15e6)


def test_extraction_from_the_proteus_file_reproduces_the_packaged_file(tmp_path):
    if not PROTEUS.is_file():  # the published PROTEUS settings; development machines only
        pytest.skip("reference data not available")
    irs = impulse_responses_from_proteus(PROTEUS, duration=2e-6)
    packaged = load_packaged_impulse_responses()
    assert np.array_equal(irs.transmit, packaged.transmit)
    assert np.array_equal(irs.receive, packaged.receive)
    assert irs.medium.sound_speed == 1480.0  # what the PROTEUS file lists


def test_impulse_response_file_round_trip_and_validation(tmp_path):
    irs = ImpulseResponses(np.arange(5.0), -np.arange(4.0), 100e6, source="test",
                           license="MIT")
    path = write_impulse_responses(tmp_path / "ir.h5", irs)
    back = read_impulse_responses(path)
    assert np.array_equal(back.transmit, irs.transmit)
    assert np.array_equal(back.receive, irs.receive)
    assert (back.sampling_rate, back.source, back.license) == (100e6, "test", "MIT")
    with pytest.raises(InputError, match="no packaged impulse responses"):
        load_packaged_impulse_responses("no-such-probe")


def test_p4_1_preset_datasheet_values_describe_the_manufacturer_probe():
    probe = probe_info_from_preset(load_probe_preset("P4-1"))
    assert probe.element_count == 96
    assert probe.pitch == pytest.approx(0.295e-3)
    assert probe.kerf == pytest.approx(0.05e-3)
    assert probe.element_height == pytest.approx(16e-3)
    assert probe.lens_focus == pytest.approx(0.11)
    assert probe.center_frequency == 2.5e6


def test_p4_1_published_values_are_consistent_with_the_fitted_aperture():
    preset = load_probe_preset("p4-1")
    probe = probe_info_from_preset(preset, values="published")
    # reference_spec 8.12: W = 28.5354208 mm, kerf 0.05 mm, N = 96 => pitch, width
    w_fit = preset["published"]["aperture_width"]
    assert probe.aperture_width == pytest.approx(w_fit, rel=1e-9)
    assert probe.aperture_width == pytest.approx(28.5354208e-3, rel=1e-7)
    assert probe.kerf == pytest.approx(0.05e-3, rel=1e-9)
    assert probe.element_width == pytest.approx((w_fit - 95 * 0.05e-3) / 96, rel=1e-8)
    assert probe.element_height == pytest.approx(14.28e-3, abs=1e-5)
    assert probe.lens_focus == pytest.approx(0.1807, abs=1e-4)
    # the receiver pose: x0' = z0' sin(theta) / (1 + cos(theta)), d = z0' / (1 + cos(theta))
    rx = preset["published"]["virtual_receiver"]
    theta = np.deg2rad(rx["theta_y_deg"])
    z0 = rx["origin"][2]
    assert rx["origin"][0] == pytest.approx(z0 * np.sin(theta) / (1 + np.cos(theta)), rel=1e-9)
    assert rx["reflector_distance"] == pytest.approx(z0 / (1 + np.cos(theta)), rel=1e-6)
    ir_path = Path(preset["impulse_responses"]["path"])
    assert ir_path.is_file()
    assert np.array_equal(read_impulse_responses(ir_path).transmit,
                          load_packaged_impulse_responses().transmit)


def test_broken_presets_are_clear_errors(tmp_path):
    with pytest.raises(InputError, match="available"):
        load_probe_preset("no-such-probe")
    bad = tmp_path / "probe.toml"
    bad.write_text('format = "holoprobe-probe-preset"\nschema_version = 1\nname = "x"\n'
                   "[datasheet]\nelement_count = 8\npitch = 3e-4\n")
    with pytest.raises(InputError, match="missing key") as err:
        load_probe_preset(bad)
    assert err.value.field == "datasheet.element_width" and err.value.file == str(bad)
    bad.write_text('format = "holoprobe-probe-preset"\nschema_version = 1\nname = "x"\n'
                   "[datasheet]\nelement_count = 8\npitch = 3e-4\nelement_width = 4e-4\n"
                   "element_height = 5e-3\ncenter_frequency = 5e6\nlens_focus = inf\n")
    with pytest.raises(InputError, match="exceeds the pitch") as err:
        probe_info_from_preset(bad)
    assert err.value.field == "datasheet.element_width"
    bad.write_text("format = [")
    with pytest.raises(InputError, match="TOML"):
        load_probe_preset(bad)
