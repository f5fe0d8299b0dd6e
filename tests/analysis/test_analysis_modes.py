"""Spurious-mode analysis (paper section III D): synthetic surface velocities with a known
antisymmetric tail, and the digital twin scanned, back-projected and analysed."""

from __future__ import annotations

import json
import math
import re

import h5py
import numpy as np
import pytest
from typer.testing import CliRunner

from _shared import gaussian_ir
from holoprobe.analysis import analyse_modes, modes_figures
from holoprobe.cli.analyse import app
from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid, Pose
from holoprobe.measurement import DriveSignal

FS = 25e6
NT = 300
X = np.arange(-8, 9) * 0.3e-3
Y = np.arange(-30, 31) * 0.15e-3
H, W = 7e-3, 4.8e-3


def burst(fs: float) -> np.ndarray:
    """The twin's impulse response: a 2.5 MHz Gaussian burst at sampling rate ``fs``."""
    return gaussian_ir(fs, 2.5e6, 0.25e-6, 1e-6)


def synthetic_velocity(amplitude: float, *, frequency: float = 3.3e6, speed: float = 2500.0,
                       noise: float = 0.01, seed: int = 0) -> np.ndarray:
    """A 2.5 MHz thickness-mode pulse on a W × H rectangle plus, inside it, a Gaussian
    tone burst leaving both y edges at 1.5 µs and running inward at ``speed`` with opposite
    signs on the two halves; white noise of ``noise`` × the pulse peak. Built here in the
    time domain, independently of the simulator."""
    rng = np.random.default_rng(seed)
    xx, yy, tt = np.meshgrid(X, Y, np.arange(NT) / FS, indexing="ij")
    inside = (np.abs(xx) <= W / 2) & (np.abs(yy) <= H / 2)
    s = tt - 1.0e-6
    v = inside * np.exp(-0.5 * (s / 0.25e-6) ** 2) * np.cos(2 * np.pi * 2.5e6 * s)
    sigma = 2 / frequency
    tm = tt - 1.5e-6 - (H / 2 - np.abs(yy)) / speed
    v = v + amplitude * inside * np.sign(yy) * np.exp(-0.5 * (tm / sigma) ** 2) \
        * np.sin(2 * np.pi * frequency * tm)
    return v + noise * rng.standard_normal(v.shape)


def test_antisymmetric_tail_frequency_strength_and_phase_velocity_are_recovered():
    r = analyse_modes(synthetic_velocity(0.1), (X, Y), FS)
    assert r.present
    assert abs(r.frequency - 3.3e6) < 0.05e6
    assert abs(r.strength_db - 20 * math.log10(0.1)) < 1.5
    # non-dispersive wave: ω/k is its speed at every frequency of the branch
    assert abs(r.phase_velocity - 2500.0) < 0.05 * 2500.0
    near = np.abs(r.branch_frequency - 3.3e6) < 0.5e6
    assert near.sum() >= 3
    np.testing.assert_allclose(r.branch_phase_velocity[near], 2500.0, rtol=0.08)
    # the aperture estimated from the RMS map is the rectangle (within one grid step)
    assert abs(r.aperture.height - H) <= 0.15e-3 and abs(r.aperture.width - W) <= 0.3e-3
    # the main pulse is even: its frequency comes from the even part
    assert abs(r.main_frequency - 2.5e6) < 0.1e6


def test_no_tail_is_reported_absent_and_a_symmetric_tail_is_not_a_mode():
    r = analyse_modes(synthetic_velocity(0.0), (X, Y), FS)
    assert not r.present
    assert r.strength_db < -35.0
    # a ringing that is the same on both halves (even) is not an antisymmetric mode
    v = synthetic_velocity(0.0)
    tt = np.arange(NT) / FS - 3e-6
    ring = 0.1 * np.exp(-0.5 * (tt / 0.6e-6) ** 2) * np.sin(2 * np.pi * 3.3e6 * tt)
    inside = (np.abs(X)[:, None] <= W / 2) & (np.abs(Y)[None, :] <= H / 2)
    r2 = analyse_modes(v + inside[..., None] * ring, (X, Y), FS)
    assert not r2.present


def test_weak_mode_below_threshold_is_absent_and_threshold_is_honoured():
    v = synthetic_velocity(0.02, noise=0.001)  # −34 dB
    assert not analyse_modes(v, (X, Y), FS).present
    r = analyse_modes(v, (X, Y), FS, threshold_db=-40.0)
    assert r.present and abs(r.frequency - 3.3e6) < 0.05e6


@pytest.mark.parametrize("amplitude", [0.15, 0.0])
def test_twin_edge_mode_is_found_at_3_3_mhz_and_absent_when_switched_off(amplitude):
    from holoprobe.propagation import project
    from holoprobe.signal import frequency_axis, to_frequency, to_time
    from holoprobe.simulate import ArrayModel, EdgeMode, simulate_scan

    fs_ir = 250e6
    # phase speed above c0: the mode radiates (a slower wave is evanescent in water and
    # no hydrophone scan can see it)
    em = EdgeMode(amplitude=amplitude, frequency=3.3e6, cycles=2, phase_speed=3000.0,
                  delay=1.2e-6) if amplitude else None
    model = ArrayModel(element_count=6, pitch=0.5e-3, element_width=0.45e-3,
                       element_height=6e-3, lens_focus=0.06, transmit_ir=burst(fs_ir),
                       receive_ir=burst(fs_ir), ir_sampling_rate=fs_ir,
                       drive=DriveSignal([1.0], fs_ir), edge_mode=em)
    scan_grid = PlaneGrid.centered(40, 68, 0.15e-3, 0.15e-3, Pose(origin=(0, 0, 2e-3)))
    band = (0.3e6, 4.9e6)
    scan, _ = simulate_scan(model, grid=scan_grid, sampling_rate=FS, n_samples=256,
                            calibration=None, snr_db=40.0, seed=1, band=band,
                            dtype=np.float64)
    n = scan.data.shape[-1]
    f = frequency_axis(n, FS)
    sel = (f > band[0]) & (f < band[1])
    pressure = to_frequency(scan.data)[..., sel] / FS
    source = PlaneGrid.centered(40, 68, 0.15e-3, 0.15e-3)
    vel = project(pressure, scan_grid, source, f[sel], Medium(), quantity="normal_velocity",
                  method="angular_spectrum")
    full = np.zeros((*scan.data.shape[:2], f.size), complex)
    full[..., sel] = vel * FS
    velocity = to_time(full, n)
    r = analyse_modes(velocity, source, FS)
    if amplitude:
        assert r.present
        assert abs(r.frequency - 3.3e6) < 0.05e6
        assert abs(r.phase_velocity - 3000.0) < 0.1 * 3000.0
    else:
        assert not r.present


def test_cli_modes_adds_summary_entry_and_report(tmp_path):
    v = synthetic_velocity(0.1).astype(np.float32)
    with h5py.File(tmp_path / "source_velocity.h5", "w") as f:
        f["velocity"] = v
        f["x"] = X
        f["y"] = Y
        f["sampling_rate"] = FS
    (tmp_path / "summary.json").write_text(json.dumps(
        {"aperture": {"width": W, "height": H, "center_x": 0.0, "center_y": 0.0},
         "lens_focus": 0.1}))
    res = CliRunner().invoke(app, ["modes", str(tmp_path)])
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["lens_focus"] == 0.1  # other entries kept
    m = summary["modes"]
    assert m["present"] is True and abs(m["frequency_hz"] - 3.3e6) < 0.05e6
    assert m["aperture_source"] == "summary.json"
    html = (tmp_path / "report_modes.html").read_text()
    assert "Dispersion map" in html and "data:image/png;base64" in html


def test_bad_velocity_shape_is_an_input_error():
    with pytest.raises(InputError, match="velocity"):
        analyse_modes(np.zeros((3, 4)), (X, Y), FS)
    with pytest.raises(InputError, match="grid"):
        analyse_modes(np.zeros((X.size + 1, Y.size, 64)), (X, Y), FS)


UNIT_LABEL = re.compile(r"\S.*\([^()]*\S[^()]*\)")  # "name (unit)"


def axis_labels(fig):
    """The label of every axis of ``fig`` (a colorbar: its long axis)."""
    for ax in fig.axes:
        if hasattr(ax, "_colorbar"):
            yield ax._colorbar.long_axis.get_label_text()
        else:
            yield ax.get_xlabel()
            yield ax.get_ylabel()


def test_every_axis_of_the_mode_figures_has_a_label_with_a_unit():
    figs = modes_figures(analyse_modes(synthetic_velocity(0.1), (X, Y), FS))
    assert len(figs) == 4
    for fig, caption in figs:
        labels = list(axis_labels(fig))
        assert len(labels) >= 2
        for label in labels:
            assert UNIT_LABEL.fullmatch(label.strip()), label
        assert "paper Fig. 9" in caption


def characterize_like_dir(directory):
    """What 'holoprobe characterize' leaves in DIR, in small: source_velocity.h5 (the
    synthetic velocity with a 3.3 MHz mode), virtual_transducer.h5 with a receive IR,
    summary.json and a report.html written by build_report with a section of its own."""
    from matplotlib.figure import Figure

    from holoprobe.report import build_report
    from holoprobe.transducer import VirtualTransducer

    with h5py.File(directory / "source_velocity.h5", "w") as f:
        f["velocity"] = synthetic_velocity(0.1).astype(np.float32)
        f["x"] = X
        f["y"] = Y
        f["sampling_rate"] = FS
    fs_ir = 250e6
    t = np.arange(400) / fs_ir
    VirtualTransducer(element_count=4, pitch=0.3e-3, element_width=0.25e-3,
                      element_height=5e-3,
                      transmit_impulse_response=burst(fs_ir)[:400],
                      transmit_sampling_rate=fs_ir,
                      receive_impulse_response=np.roll(burst(fs_ir)[:400], -20)
                      * np.exp(-t / 2e-6),
                      receive_sampling_rate=fs_ir).save(directory / "virtual_transducer.h5")
    summary = {"aperture": {"width": W, "height": H, "center_x": 0.0, "center_y": 0.0},
               "lens_focus": 0.1}
    (directory / "summary.json").write_text(json.dumps(summary))
    fig = Figure(figsize=(2, 1.5))
    fig.add_subplot().plot([0, 1], [0, 1])
    build_report(directory / "report.html", title="characterization",
                 parameters=summary, sections=[("Transmit (paper Fig. 6)", [(fig, "own")])],
                 dpi=30)


def test_cli_modes_and_phase_add_their_sections_to_report_html(tmp_path):
    characterize_like_dir(tmp_path)
    runner = CliRunner()
    for _ in range(2):  # the second run replaces the sections, never duplicates them
        for command in ("modes", "phase"):
            res = runner.invoke(app, [command, str(tmp_path)])
            assert res.exit_code == 0, res.output
            assert "report.html" in res.output
    text = (tmp_path / "report.html").read_text(encoding="utf-8")
    for sid, heading in (("analysis-modes", "Spurious modes of oscillation"),
                         ("analysis-phase", "Phase compensation and reciprocity")):
        assert text.count(f'<section id="{sid}">') == 1
        assert text.count(f'href="#{sid}"') == 1  # listed once in the contents
        assert text.count(f"<h2>{heading}") == 1
    assert text.index("Transmit (paper Fig. 6)</h2>") < text.index(
        '<section id="analysis-modes">') < text.index('<section id="analysis-phase">')
    assert "Dispersion map" in text and "paper Fig. 10b" in text
    # 1 figure of characterize + 4 (modes) + 4 (phase), all embedded, numbered 1..9
    assert text.count('<img src="data:image/png;base64,') == 9
    assert re.findall(r'<span class="fignum">Figure (\d+)\.</span>', text) == [
        str(k) for k in range(1, 10)]
    assert not list(tmp_path.glob("report_*.html"))  # no separate pages
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["modes"]["report"] == "report.html#analysis-modes"
    assert summary["phase"]["report"] == "report.html#analysis-phase"
    assert summary["modes"]["present"] is True and summary["lens_focus"] == 0.1
