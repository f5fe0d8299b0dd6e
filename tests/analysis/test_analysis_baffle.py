"""Source representation (paper sections II C, IV C): Rayleigh vs angular spectrum (and
k-wave-python when the optional extra is importable) on axis, monopole vs dipole differing
in the edge waves only.

The k-Wave test runs only where k-wave-python is installed (never in CI), e.g.
``PYTHONPATH=src /tmp/kwenv/bin/python -m pytest tests/test_analysis_baffle.py``; the
other tests leave k-Wave out (``kwave=False``, or ``kwave_available`` patched for the
command), so that they stay fast there too.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from typer.testing import CliRunner

import holoprobe.analysis._baffle as baffle_module
from _shared import delay_and_correlation
from holoprobe.analysis import analyse_baffle, baffle_figure
from holoprobe.cli.analyse import app
from holoprobe.errors import InputError
from holoprobe.transducer import VirtualTransducer

FS = 250e6


@pytest.fixture(scope="module")
def small_vt() -> VirtualTransducer:
    t = np.arange(round(1.2e-6 * FS)) / FS
    ir = np.exp(-0.5 * ((t - 0.6e-6) / 0.15e-6) ** 2) * np.cos(2 * np.pi * 3e6 * (t - 0.6e-6))
    return VirtualTransducer(element_count=16, pitch=0.4e-3, element_width=0.35e-3,
                             element_height=6e-3, transmit_impulse_response=ir,
                             transmit_sampling_rate=FS)


@pytest.fixture(scope="module")
def result(small_vt):
    return analyse_baffle(small_vt, distance=5e-3, kwave=False)


@pytest.fixture
def no_kwave(monkeypatch):
    """The command as where the [kwave] extra is missing (CI), also in a k-Wave venv."""
    monkeypatch.setattr(baffle_module, "kwave_available", lambda: False)


def test_rayleigh_and_angular_spectrum_agree_on_axis(result):
    assert result.method_difference_percent["monopole"] < 3.0
    assert result.method_difference_percent["dipole"] < 3.0


def test_monopole_and_dipole_share_the_primary_wavefront_but_not_the_edge_waves(result):
    mono = result.pressure["monopole/rayleigh"]
    # the primary wave is a plane wave of amplitude ρ0c0·u on axis for both
    assert result.primary_difference_percent < 5.0
    assert result.representation_difference_percent > 2 * result.primary_difference_percent
    assert result.representation_difference_percent > 2.0
    # the primary wave reaches the point at d/c0 (plus the pulse's own delay)
    t_peak = result.time[np.argmax(np.abs(mono))]
    assert t_peak == pytest.approx(5e-3 / 1481.0 + 0.6e-6 + 0.5 / 3e6 / 2, abs=0.3e-6)


def test_without_kwave_two_methods_one_pair_and_a_note(small_vt, no_kwave):
    r = analyse_baffle(small_vt, distance=5e-3, points_per_wavelength=3.0)
    assert r.methods == ["rayleigh", "angular_spectrum"]
    assert not any(k.endswith("/kwave") for k in r.pressure)
    for rep in ("monopole", "dipole"):
        assert list(r.pairwise_difference_percent[rep]) == ["rayleigh-angular_spectrum"]
        assert r.pairwise_difference_percent[rep]["rayleigh-angular_spectrum"] == \
            r.method_difference_percent[rep]
    assert any("not available" in n for n in r.notes)
    assert r.summary()["kwave_step_m"] is None
    with pytest.raises(InputError, match="kwave"):
        analyse_baffle(small_vt, distance=5e-3, kwave=True)


def test_baffle_command_prints_differences(tmp_path, small_vt, no_kwave):
    small_vt.save(tmp_path / "vt.h5")
    res = CliRunner().invoke(app, ["baffle", str(tmp_path / "vt.h5"), "--distance", "5e-3"])
    assert res.exit_code == 0, res.output
    assert "monopole" in res.output and "%" in res.output
    assert (tmp_path / "report_baffle.html").exists()


def test_bad_distance_is_an_input_error(small_vt):
    with pytest.raises(InputError, match="distance"):
        analyse_baffle(small_vt, distance=-1.0)


def test_baffle_figure_axes_have_units_and_the_section_joins_report_html(tmp_path, result,
                                                                           small_vt, no_kwave):
    from matplotlib.figure import Figure

    from holoprobe.report import build_report

    fig, caption = baffle_figure(result)
    for label in (fig.axes[0].get_xlabel(), fig.axes[0].get_ylabel()):
        assert re.fullmatch(r"\S.*\([^()]*\S[^()]*\)", label.strip()), label
    assert "%" in caption and "primary wavefront" in caption
    # a model in a characterize output directory: its report gains the section
    small_vt.save(tmp_path / "virtual_transducer.h5")
    own = Figure(figsize=(2, 1.5))
    own.add_subplot().plot([0, 1], [0, 1])
    build_report(tmp_path / "report.html", title="t", sections=[("Transmit", [own])], dpi=30)
    (tmp_path / "summary.json").write_text("{}")
    for _ in range(2):
        res = CliRunner().invoke(app, ["baffle", str(tmp_path / "virtual_transducer.h5")])
        assert res.exit_code == 0, res.output
    text = (tmp_path / "report.html").read_text(encoding="utf-8")
    assert text.count('<section id="analysis-baffle">') == 1
    assert text.count('href="#analysis-baffle"') == 1
    assert text.count('<img src="data:image/png;base64,') == 2
    assert not (tmp_path / "report_baffle.html").exists()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["baffle"]["report"] == "report.html#analysis-baffle"


def test_kwave_monopole_and_dipole_on_axis_match_rayleigh_within_3_percent():
    from holoprobe.export import prepare_kwave_offline

    prepare_kwave_offline()  # placeholders for its C++ binaries: `import kwave` offline
    pytest.importorskip("kwave", reason="k-wave-python (optional extra [kwave]) not installed")
    t = np.arange(round(1.2e-6 * FS)) / FS
    ir = np.exp(-0.5 * ((t - 0.6e-6) / 0.15e-6) ** 2) * np.cos(2 * np.pi * 3e6 * (t - 0.6e-6))
    vt = VirtualTransducer(element_count=4, pitch=0.4e-3, element_width=0.35e-3,
                           element_height=1.6e-3, transmit_impulse_response=ir,
                           transmit_sampling_rate=FS)
    r = analyse_baffle(vt, distance=5e-3, kwave_step=0.1e-3)
    assert r.methods == ["rayleigh", "angular_spectrum", "kwave"]
    dt = 0.3 * 0.1e-3 / vt.medium.sound_speed
    fs = 1.0 / (r.time[1] - r.time[0])
    for rep in ("monopole", "dipole"):
        pair = r.pairwise_difference_percent[rep]
        print(rep, {k: round(v, 2) for k, v in pair.items()})
        assert pair["rayleigh-kwave"] <= 3.0
        assert pair["angular_spectrum-kwave"] <= 3.0
        assert r.method_difference_percent[rep] == max(pair.values())
        # time axes: no delay left after KWAVE_TIME_OFFSET (half a step would be 0.5)
        lag, _ = delay_and_correlation(r.pressure[f"{rep}/kwave"], r.pressure[f"{rep}/rayleigh"],
                                       upsample=64)
        lag = lag / fs / dt
        assert abs(lag) <= 0.1
    fig, _ = baffle_figure(r)
    labels = fig.axes[0].get_legend_handles_labels()[1]
    assert sum("k-Wave" in lab for lab in labels) == 2
