"""UFF v0.3, Verasonics Trans and PyMUST param exports (holoprobe.export._probes).

The impulse responses are Gaussian-modulated cosines, whose spectra are Gaussians known in
closed form: centre f0, amplitude ``exp(−(f − f0)² / (2 σ_f²))`` with ``σ_f = 1/(2π σ_t)``.
"""

import json
import math

import numpy as np
import pytest
import scipy.io

from holoprobe.errors import InputError
from holoprobe.export import (
    export_uff,
    export_verasonics,
    pymust_param,
    to_pymust,
    uff_probe_dict,
    verasonics_trans,
)
from holoprobe.geometry import Medium
from holoprobe.transducer import VirtualTransducer

F0, SIGMA_T = 3e6, 0.15e-6
SIGMA_F = 1 / (2 * np.pi * SIGMA_T)


def _gauss(t, t0=1.5e-6, amplitude=1e11, f0=F0, sigma=SIGMA_T):
    return amplitude * np.exp(-((t - t0) ** 2) / (2 * sigma**2)) * np.cos(
        2 * np.pi * f0 * (t - t0))


def _vt(receive=False, fs=100e6):
    t = np.arange(round(4e-6 * fs)) / fs
    return VirtualTransducer(
        element_count=8, pitch=0.3e-3, element_width=0.25e-3, element_height=12e-3,
        transmit_impulse_response=_gauss(t), transmit_sampling_rate=fs, lens_focus=0.07,
        receive_impulse_response=_gauss(t, amplitude=1e6, f0=2.5e6) if receive else None,
        receive_sampling_rate=fs if receive else None, medium=Medium(1000.0, 1480.0),
        name="test probe")


def test_pymust_fc_and_bandwidth_match_the_analytic_gaussian_pulse_echo_spectrum():
    # pulse-echo spectrum |H_T|² = exp(−(f − f0)²/σ_f²): −6 dB (half amplitude) at
    # f0 ± σ_f √ln 2, so fc = f0 and bandwidth = 200 σ_f √ln2 / f0 %
    p = pymust_param(_vt())
    assert p["fc"] == pytest.approx(F0, rel=1e-3)
    assert p["bandwidth"] == pytest.approx(200 * SIGMA_F * math.sqrt(math.log(2)) / F0,
                                           rel=0.01)
    assert (p["Nelements"], p["pitch"], p["width"], p["height"], p["focus"]) == (
        8, 0.3e-3, 0.25e-3, 12e-3, 0.07)
    assert p["kerf"] == pytest.approx(0.05e-3)
    assert p["baffle"] == "rigid" and p["c"] == 1480.0
    # with a receive IR at 2.5 MHz: the product of two Gaussians of equal width is a
    # Gaussian centred at the mean frequency, with the same −6 dB width
    q = pymust_param(_vt(receive=True))
    assert q["fc"] == pytest.approx(2.75e6, rel=1e-3)
    assert q["bandwidth"] * q["fc"] == pytest.approx(p["bandwidth"] * p["fc"], rel=0.01)
    with pytest.raises(InputError, match="baffle"):
        pymust_param(_vt(), baffle="wobbly")


def test_to_pymust_param_drives_pymust_functions():
    pymust = pytest.importorskip("pymust")
    param = to_pymust(_vt())
    xe, *_ = param.getElementPositions()
    np.testing.assert_allclose(xe.ravel(), (np.arange(8) - 3.5) * 0.3e-3)
    # MUST's own pulse-echo spectrum is −6 dB at fc(1 ± bandwidth/200), as ours
    spectrum = param.getProbeFunction()
    for edge in (1 - param.bandwidth / 200, 1 + param.bandwidth / 200):
        assert spectrum(2 * np.pi * param.fc * edge) ** 2 == pytest.approx(0.5, rel=0.02)
    x, z = np.array([0.0]), np.array([0.03])
    p, *_ = pymust.pfield(x, np.zeros(1), z, np.zeros((1, 8)), param)
    assert np.all(np.isfinite(p)) and p[0] > 0


def test_verasonics_trans_is_in_wavelengths_and_loads_with_scipy(tmp_path):
    vt = _vt(receive=True)
    path = export_verasonics(vt, tmp_path / "Trans.mat")
    m = scipy.io.loadmat(path, squeeze_me=True, struct_as_record=False)
    tr = m["Trans"]
    assert tr.units == "wavelengths"
    lam = 1540.0 / (tr.frequency * 1e6)
    assert tr.frequency == pytest.approx(2.75, rel=1e-3)
    assert tr.elementWidth * lam == pytest.approx(0.25e-3, rel=1e-9)
    assert tr.spacing * lam == pytest.approx(0.3e-3, rel=1e-9)
    assert tr.spacingMm == pytest.approx(0.3)
    assert tr.elevationApertureMm == pytest.approx(12.0)
    assert tr.elevationFocusMm == pytest.approx(70.0)
    assert tr.ElementPos.shape == (8, 5)
    np.testing.assert_allclose(tr.ElementPos[:, 0] * lam, (np.arange(8) - 3.5) * 0.3e-3)
    # one-way IR at 250 MHz: the transmit Gaussian pulse; its peak at 1.5 µs
    ir1 = np.asarray(tr.IR1wy)
    assert np.argmax(np.abs(ir1)) / 250e6 == pytest.approx(1.5e-6, abs=8e-9)
    spec = np.abs(np.fft.rfft(ir1, 8 * ir1.size))
    assert spec.max() == pytest.approx(1.0, rel=1e-9)
    assert np.fft.rfftfreq(8 * ir1.size, 1 / 250e6)[np.argmax(spec)] == pytest.approx(
        F0, rel=0.01)
    # Bandwidth (MHz) = the two-way −6 dB band: Gaussian of σ_f centred at 2.75 MHz
    half = SIGMA_F * math.sqrt(math.log(2)) * 1e-6
    np.testing.assert_allclose(tr.Bandwidth, [2.75 - half, 2.75 + half], rtol=0.01)
    gain = m["holoprobe"].IR1wy_gain
    np.testing.assert_allclose(ir1 * gain * 250e6,
                               _gauss(np.arange(ir1.size) / 250e6), atol=1e-3 * 1e11)
    assert verasonics_trans(_vt())["IR2wy"].size == 2 * ir1.size - 1


def _uff_reader():
    try:
        import uff
        from uff.utils import load_uff_dict
    except ImportError:
        pytest.skip("uff-reader is not installed")
    except ValueError as exc:  # uff-reader 0.0.2 fails to import on Python ≥ 3.11
        pytest.skip(f"uff-reader cannot be imported here ({exc})")
    return uff, load_uff_dict


def test_uff_file_layout_is_uff_v03_hdf5(tmp_path):
    import h5py

    vt = _vt(receive=True)
    path = export_uff(vt, tmp_path / "probe.uff")
    with h5py.File(path, "r") as f:
        assert [int(f["version"][k][()]) for k in ("major", "minor", "patch")] == [0, 3, 0]
        probe = f["uff.probe"]
        assert probe["element"].attrs["array_size"] == 8
        assert probe["element_impulse_response"].attrs["array_size"] == 2
        ir = probe["element_impulse_response/00000001"]
        assert ir["units"].dtype == np.dtype("|S1")
        assert b"".join(ir["units"][()].ravel()).decode() == "Pa/(V*s)"
        assert ir["sampling_frequency"][()] == 100e6
        np.testing.assert_array_equal(ir["data"][()], vt.transmit_impulse_response)
        x = [probe[f"element/{i:08d}/transform/translation/x"][()] for i in range(1, 9)]
        np.testing.assert_allclose(x, (np.arange(8) - 3.5) * 0.3e-3)
        assert probe["focal_length"][()] == 0.07


def test_uff_probe_round_trips_through_uff_reader(tmp_path):
    uff, load_uff_dict = _uff_reader()

    vt = _vt(receive=True)
    path = export_uff(vt, tmp_path / "probe.uff")
    data = load_uff_dict(path)
    assert (data["version"]["major"], data["version"]["minor"]) == (0, 3)
    probe = uff.Probe.deserialize(data["probe"])
    assert probe.number_elements == 8 and probe.focal_length == pytest.approx(0.07)
    assert len(probe.element) == 8
    x = [e.transform.translation.x for e in probe.element]
    np.testing.assert_allclose(x, (np.arange(8) - 3.5) * 0.3e-3)
    ir = probe.element_impulse_response[0]
    assert ir.units == "Pa/(V*s)" and ir.sampling_frequency == 100e6
    np.testing.assert_allclose(ir.data, vt.transmit_impulse_response)
    assert probe.element_impulse_response[1].units == vt.receive_units
    corners = probe.element_geometry[0].perimeter.position
    assert max(c.x for c in corners) - min(c.x for c in corners) == pytest.approx(0.25e-3)
    assert max(c.y for c in corners) - min(c.y for c in corners) == pytest.approx(12e-3)
    # the same object built with uff-reader's own classes is equal
    expected = uff.Probe.deserialize(uff_probe_dict(vt))
    assert probe.element_impulse_response[0] == expected.element_impulse_response[0]


def test_export_cli_writes_the_three_formats(tmp_path):
    from typer.testing import CliRunner

    from holoprobe.cli import app

    vt_path = _vt().save(tmp_path / "vt.h5")
    runner = CliRunner()
    for kind, name in (("uff", "p.uff"), ("verasonics", "t.mat"), ("pymust", "m.json")):
        res = runner.invoke(app, ["export", kind, str(vt_path), "--out", str(tmp_path / name)])
        assert res.exit_code == 0, res.output
    assert json.loads((tmp_path / "m.json").read_text())["Nelements"] == 8
    assert "Trans" in scipy.io.loadmat(tmp_path / "t.mat")
