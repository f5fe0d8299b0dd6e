"""PROTEUS export: field names and units of the reference files, lossless round trips."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.io

from _shared import SHARED_DATA
from holoprobe.errors import InputError
from holoprobe.export import (
    PROTEUS_TRANSDUCER_FIELDS,
    export_proteus,
    from_proteus_axes,
    import_proteus,
    to_proteus_axes,
)
from holoprobe.geometry import Medium
from holoprobe.transducer import VirtualTransducer

REFERENCE = SHARED_DATA / "P4-1_measured_settings_PROTEUS.mat"


def _gauss_pulse(t, f0=2.5e6, sigma=0.25e-6, t0=1.5e-6, amplitude=1e11):
    return amplitude * np.exp(-((t - t0) ** 2) / (2 * sigma**2)) * np.cos(
        2 * np.pi * f0 * (t - t0))


def _vt(fs=250e6, receive=True):
    t = np.arange(round(4e-6 * fs)) / fs  # 4 µs: the pulse (1.5 µs ± 6σ) fits
    return VirtualTransducer(
        element_count=64, pitch=0.3e-3, element_width=0.25e-3, element_height=12e-3,
        transmit_impulse_response=_gauss_pulse(t), transmit_sampling_rate=fs,
        lens_focus=0.07,
        receive_impulse_response=_gauss_pulse(t, amplitude=1e6) if receive else None,
        receive_sampling_rate=fs if receive else None, medium=Medium(1000.0, 1480.0))


def _struct_fields(path):
    m = scipy.io.loadmat(path)
    return m, list(m["Transducer"].dtype.names)


def test_transducer_struct_has_the_proteus_field_names_units_and_ir_files(tmp_path):
    vt = _vt()
    files = export_proteus(vt, tmp_path)
    m, names = _struct_fields(files["transducer"])
    assert names == list(PROTEUS_TRANSDUCER_FIELDS)
    tr = m["Transducer"][0, 0]
    assert str(tr["Type"][0]) == "Custom linear"
    assert str(tr["ImpulseResponseType"][0]) == "Load file"
    # metres, Hz, Pa/(V·s) like the reference file (Pitch 2.98e-4, SamplingRate 2.5e8)
    assert tr["Pitch"][0, 0] == 0.3e-3 and tr["ElementHeight"][0, 0] == 12e-3
    assert tr["ElevationFocus"][0, 0] == 0.07 and tr["NumberOfElements"][0, 0] == 64
    assert tr["SamplingRate"][0, 0] == 250e6
    # Gaussian-modulated cosine: amplitude spectrum exp(−(2π Δf σ)²/2) around f0, so
    # the −6 dB band is f0 ± √(0.6 ln 10)/(2π σ) = f0 ± 0.750 MHz
    half = math.sqrt(0.6 * math.log(10)) / (2 * math.pi * 0.25e-6)
    assert tr["CenterFrequency"][0, 0] == pytest.approx(2.5e6, rel=1e-3)
    assert tr["BandwidthLow"][0, 0] == pytest.approx(2.5e6 - half, rel=5e-3)
    assert tr["BandwidthHigh"][0, 0] == pytest.approx(2.5e6 + half, rel=5e-3)
    np.testing.assert_array_equal(tr["TransmitImpulseResponse"],
                                  vt.transmit_impulse_response[None, :])
    for key, ir in (("transmit", vt.transmit_impulse_response),
                    ("receive", vt.receive_impulse_response)):
        f = scipy.io.loadmat(files[key])
        assert {k for k in f if not k.startswith("__")} == {"IR", "Fs"}
        assert f["IR"].shape == (1, ir.size) and f["Fs"][0, 0] == 250e6
        np.testing.assert_array_equal(f["IR"][0], ir)


@pytest.mark.skipif(not REFERENCE.is_file(),
                    reason="needs the reference PROTEUS settings file (shared/ beside the repo)")
def test_field_names_equal_those_of_the_reference_proteus_settings_file(tmp_path):
    ref = scipy.io.loadmat(REFERENCE)
    files = export_proteus(_vt(), tmp_path)
    _, names = _struct_fields(files["transducer"])
    assert names == list(ref["Transducer"].dtype.names)


def test_band_limited_resampling_of_an_ir_to_250_mhz(tmp_path):
    vt = _vt(fs=62.5e6)
    files = export_proteus(vt, tmp_path)
    f = scipy.io.loadmat(files["transmit"])
    ir = f["IR"][0]
    assert ir.size == 4 * vt.transmit_impulse_response.size
    t = np.arange(ir.size) / 250e6
    err = np.max(np.abs(ir - _gauss_pulse(t))) / np.max(np.abs(ir))
    assert err < 1e-6


def _write_proteus_by_hand(directory, ir_t, ir_r, band=(1.5e6, 3.5e6, 2.5e6)):
    directory.mkdir()
    struct = {
        "Type": "Custom linear", "Configuration": "Linear", "NumberOfElements": 96.0,
        "Pitch": 2.977648e-4, "ElementWidth": 2.477648e-4, "ElementHeight": 1.42790297e-2,
        "ElevationFocus": 1.806689295e-1, "BandwidthLow": band[0], "BandwidthHigh": band[1],
        "CenterFrequency": band[2], "ImpulseResponseType": "Load file",
        "SamplingRate": 250e6, "TransmitImpulseResponse": ir_t[None, :],
        "ReceiveImpulseResponse": ir_r[None, :]}
    scipy.io.savemat(directory / "Transducer.mat", {"Transducer": struct})
    scipy.io.savemat(directory / "IR_transmit.mat", {"IR": ir_t[None, :], "Fs": 250e6})
    scipy.io.savemat(directory / "IR_receive.mat", {"IR": ir_r[None, :], "Fs": 250e6})


def test_round_trip_proteus_holoprobe_proteus_is_lossless(tmp_path):
    rng = np.random.default_rng(3)
    ir_t, ir_r = rng.normal(size=300) * 1e10, rng.normal(size=280) * 1e5
    _write_proteus_by_hand(tmp_path / "in", ir_t, ir_r)
    vt = import_proteus(tmp_path / "in")
    assert vt.element_count == 96 and vt.pitch == 2.977648e-4
    export_proteus(vt, tmp_path / "out")
    for name in ("Transducer.mat", "IR_transmit.mat", "IR_receive.mat"):
        a = scipy.io.loadmat(tmp_path / "in" / name)
        b = scipy.io.loadmat(tmp_path / "out" / name)
        keys = sorted(k for k in a if not k.startswith("__"))
        assert keys == sorted(k for k in b if not k.startswith("__"))
        for key in keys:
            if a[key].dtype.names:
                assert a[key].dtype.names == b[key].dtype.names
                for field in a[key].dtype.names:
                    np.testing.assert_array_equal(a[key][0, 0][field], b[key][0, 0][field])
            else:
                np.testing.assert_array_equal(a[key], b[key])


def test_holoprobe_proteus_holoprobe_keeps_geometry_irs_and_focus(tmp_path):
    vt = _vt()
    export_proteus(vt, tmp_path)
    back = import_proteus(tmp_path, medium=vt.medium)
    for name in ("element_count", "pitch", "element_width", "element_height", "lens_focus",
                 "transmit_sampling_rate", "receive_sampling_rate"):
        assert getattr(back, name) == getattr(vt, name), name
    np.testing.assert_array_equal(back.transmit_impulse_response,
                                  vt.transmit_impulse_response)
    np.testing.assert_array_equal(back.receive_impulse_response, vt.receive_impulse_response)


@pytest.mark.skipif(not REFERENCE.is_file(),
                    reason="needs the reference PROTEUS settings file (shared/ beside the repo)")
def test_import_of_the_reference_settings_file_reads_medium_and_struct_values(tmp_path):
    vt = import_proteus(REFERENCE)
    assert vt.medium == Medium(1000.0, 1480.0)
    assert vt.element_count == 96 and vt.transmit_impulse_response.size == 500
    assert vt.lens_focus == pytest.approx(0.1806689295, rel=1e-9)
    files = export_proteus(vt, tmp_path)
    ref = scipy.io.loadmat(REFERENCE, mat_dtype=True)["Transducer"][0, 0]
    out = scipy.io.loadmat(files["transducer"])["Transducer"][0, 0]
    for field in PROTEUS_TRANSDUCER_FIELDS:
        if field == "Type":
            continue
        np.testing.assert_array_equal(np.asarray(out[field]), np.asarray(ref[field]), field)


def test_axes_mapping_puts_holoprobe_depth_on_proteus_x():
    pts = np.array([[1.0, 2.0, 3.0], [-0.5, 0.25, 0.07]])
    prot = to_proteus_axes(pts)
    np.testing.assert_array_equal(prot[0], [3.0, 1.0, 2.0])
    np.testing.assert_array_equal(from_proteus_axes(prot), pts)


def test_proteus_errors_name_the_file(tmp_path):
    scipy.io.savemat(tmp_path / "x.mat", {"Other": 1.0})
    with pytest.raises(InputError, match=r"x\.mat.*Transducer"):
        import_proteus(tmp_path / "x.mat")
    export_proteus(_vt(receive=False), tmp_path / "o")
    assert not (tmp_path / "o" / "IR_receive.mat").exists()
    with pytest.raises(InputError, match="already exists"):
        export_proteus(_vt(), tmp_path / "o")


def test_export_proteus_cli_writes_loadable_files(tmp_path):
    from typer.testing import CliRunner

    from holoprobe.cli import app

    vt = _vt()
    path = vt.save(tmp_path / "vt.h5")
    res = CliRunner().invoke(app, ["export", "proteus", str(path), "--out", str(tmp_path / "p")])
    assert res.exit_code == 0, res.output
    _, names = _struct_fields(tmp_path / "p" / "Transducer.mat")
    assert names == list(PROTEUS_TRANSDUCER_FIELDS)
    back = import_proteus(tmp_path / "p")
    np.testing.assert_array_equal(back.transmit_impulse_response, vt.transmit_impulse_response)
