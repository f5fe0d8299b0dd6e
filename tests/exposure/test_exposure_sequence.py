"""Transmit sequences: the file reader, the sequence noun, the acoustic output over a frame.

The aggregates are checked against closed forms: a Gaussian burst's pulse intensity
integral ∫p²/(ρc) dt = A² σ √π (1 − e^{−ω²σ²}) / (2ρc), so the temporal-average
intensity of a frame is frame_rate · Σ_t A_t² (…) at each point.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.exposure import exposure_metrics, sequence_exposure
from holoprobe.geometry import Medium
from holoprobe.io import read_transmit_sequence
from holoprobe.transducer import TransmitSequence

MEDIUM = Medium(density=998.0, sound_speed=1481.0)
F0, SIGMA, FS = 2.5e6, 0.6e-6, 200e6
DRIVE = '[common.drive]\nkind = "burst"\nfrequency = 2.5e6\ncycles = 2\namplitude = 10.0\n'


def _pii(amplitude):
    w = 2 * np.pi * F0
    return amplitude**2 * SIGMA * math.sqrt(math.pi) * (1 - math.exp(-(w * SIGMA) ** 2)) / (
        2 * MEDIUM.impedance)


def _bursts(amplitudes):
    """(n_points, nt) Gaussian bursts with the given peak amplitudes per point."""
    t = np.arange(-8 * SIGMA, 8 * SIGMA, 1 / FS)
    shape = np.exp(-t**2 / (2 * SIGMA**2)) * np.sin(2 * np.pi * F0 * t)
    return np.asarray(amplitudes, float)[:, None] * shape[None, :]


def test_plane_wave_sweep_reads_every_angle_with_the_common_tables(tmp_path):
    path = tmp_path / "pw.toml"
    path.write_text('format = "holoprobe-transmit-sequence"\nname = "PW"\nprf = 7500.0\n'
                    '[sweep]\nkind = "plane_wave"\n'
                    'angles_deg = {start = -15.0, stop = 15.0, count = 75}\n'
                    '[common.apodization]\nkind = "tukey"\nalpha = 0.25\n' + DRIVE)
    data = read_transmit_sequence(path)
    assert len(data["transmits"]) == 75
    angles = [t["delays"]["angle_deg"] for t in data["transmits"]]
    np.testing.assert_allclose(angles, np.linspace(-15, 15, 75))
    assert data["frame_rate"] == pytest.approx(7500.0 / 75)
    seq = TransmitSequence.from_file(path)
    assert len(seq) == 75 and seq.prf == 7500.0
    assert seq.settings[0].apodization.alpha == 0.25
    assert seq.settings[74].delays.angle == pytest.approx(math.radians(15.0))
    assert seq.settings[3].drive.sampling_rate > 0


def test_focused_lines_and_explicit_transmits(tmp_path):
    lines = tmp_path / "lines.toml"
    lines.write_text('format = "holoprobe-transmit-sequence"\nprf = 4000.0\n'
                     'frame_rate = 20.0\n[sweep]\nkind = "focused"\ndepth = 0.05\n'
                     'x = {start = -0.02, stop = 0.02, count = 128}\n' + DRIVE)
    seq = TransmitSequence.from_file(lines)
    assert len(seq) == 128 and seq.frame_rate == 20.0
    np.testing.assert_allclose(seq.settings[-1].delays.point, (0.02, 0.0, 0.05))
    listed = tmp_path / "two.toml"
    listed.write_text('format = "holoprobe-transmit-sequence"\nprf = 1000.0\n' + DRIVE
                      + '[[transmit]]\nname = "a"\n[transmit.delays]\nkind = "focused"\n'
                      'point = [0.0, 0.0, 0.03]\n[[transmit]]\n[transmit.drive]\n'
                      'kind = "pulse"\namplitude = 5.0\nduration = 1e-7\n')
    seq = TransmitSequence.from_file(listed)
    assert [s.name for s in seq.settings] == ["a", "transmit 2"]
    assert seq.settings[0].drive.voltage.max() == pytest.approx(10.0, rel=1e-3)
    assert seq.settings[1].drive.voltage.max() == pytest.approx(5.0)  # its own drive


@pytest.mark.parametrize(("text", "field"), [
    ('format = "holoprobe-transmit"\nprf = 1.0\n[sweep]\nkind = "plane_wave"\n'
     'angles_deg = [0.0]\n', "format"),
    ('format = "holoprobe-transmit-sequence"\n[sweep]\nkind = "plane_wave"\n'
     'angles_deg = [0.0]\n', "prf"),
    ('format = "holoprobe-transmit-sequence"\nprf = 100.0\nframe_rate = 60.0\n[sweep]\n'
     'kind = "plane_wave"\nangles_deg = [0.0, 1.0]\n', "frame_rate"),
    ('format = "holoprobe-transmit-sequence"\nprf = 100.0\n[sweep]\nkind = "zigzag"\n',
     "sweep.kind"),
    ('format = "holoprobe-transmit-sequence"\nprf = 100.0\n[sweep]\nkind = "focused"\n'
     'depth = 0.05\n', "sweep.x"),
])
def test_bad_sequence_files_name_the_key(tmp_path, text, field):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        read_transmit_sequence(path)
    assert info.value.field == field and str(path) in str(info.value)


def test_sequence_output_sums_pulse_intensity_over_the_frame():
    # 3 points on the axis, 2 transmits: the first strongest at point 0, the second at 2
    pts = np.array([[0.0, 0.0, 0.01], [0.0, 0.0, 0.02], [0.0, 0.0, 0.03]])
    amps = [[2.0e6, 1.0e6, 0.2e6], [0.5e6, 1.2e6, 1.6e6]]
    frame_rate, prf = 50.0, 200.0
    res = sequence_exposure((_bursts(a) for a in amps), FS, pts, MEDIUM, prf=prf,
                            frame_rate=frame_rate, names=["near", "far"],
                            attenuation_db_cm_mhz=0.0)
    expected = frame_rate * (_pii(np.array(amps[0])) + _pii(np.array(amps[1])))
    np.testing.assert_allclose(res.temporal_average_intensity, expected, rtol=1e-6)
    assert res.ispta == pytest.approx(expected.max(), rel=1e-6)
    # Σ A²: 2.0² + 0.5² = 4.25 at point 0, 2.44 at point 1, 2.6 at point 2
    assert res.ispta_position == (0.0, 0.0, 0.01)
    # worst-case per-pulse quantities come from the single transmits
    single = [exposure_metrics(_bursts(a), FS, pts, MEDIUM, attenuation_db_cm_mhz=0.0)
              for a in amps]
    assert res.mechanical_index == pytest.approx(max(m.mechanical_index for m in single))
    assert res.names[res.mechanical_index_transmit] == "near"
    assert res.isppa == pytest.approx(max(m.isppa for m in single))
    assert res.per_transmit[1].ispta == pytest.approx(frame_rate * _pii(1.6e6), rel=1e-6)
    d = json.loads(json.dumps(res.to_dict()))
    assert d["worst_case"]["mechanical_index_transmit"] == 0 and len(d["per_transmit"]) == 2


def test_sequence_output_rejects_an_impossible_frame_rate():
    pts = np.array([[0.0, 0.0, 0.01]])
    with pytest.raises(InputError, match="frame_rate"):
        sequence_exposure([_bursts([1e6]), _bursts([1e6])], FS, pts, prf=100.0,
                          frame_rate=60.0)


def test_output_cli_over_a_sequence_matches_its_transmits_one_by_one(tmp_path):
    from typer.testing import CliRunner

    from holoprobe.cli import app
    from holoprobe.exposure import pulse_intensity_integral
    from holoprobe.transducer import VirtualTransducer, predict_field

    vt = VirtualTransducer.from_preset("p4-1").replace(element_count=8)
    vt_path = vt.save(tmp_path / "vt.h5")
    seq_path = tmp_path / "seq.toml"
    seq_path.write_text('format = "holoprobe-transmit-sequence"\nprf = 2000.0\n'
                        'frame_rate = 500.0\n[sweep]\nkind = "focused"\ndepth = 0.015\n'
                        'x = [-0.001, 0.001]\n' + DRIVE)
    res = CliRunner().invoke(app, ["output", str(vt_path), "--sequence", str(seq_path),
                                   "--out", str(tmp_path / "o.json"), "--depth-mm", "8", "20",
                                   "--lateral-mm", "3", "--plane-step-mm", "1"])
    assert res.exit_code == 0, res.output
    d = json.loads((tmp_path / "o.json").read_text())
    worst = d["worst_case"]
    # the spatial peak of the frame's temporal average, recomputed from the transmits
    seq = TransmitSequence.from_file(seq_path)
    point = np.array([worst["ispta_position"]])
    fs = d["sampling_rate"]
    total = sum(pulse_intensity_integral(
        predict_field(vt, s, point, sampling_rate=fs, time_window="local").pressure, fs,
        vt.medium)[0] for s in seq.settings)
    assert worst["ispta"] == pytest.approx(500.0 * total, rel=1e-3)
    assert len(d["per_transmit"]) == 2 and d["frame_rate"] == 500.0
    assert worst["mechanical_index"] == max(m["mechanical_index"] for m in d["per_transmit"])
