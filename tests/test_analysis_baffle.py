"""Source representation (paper sections II C, IV C): Rayleigh vs angular spectrum on axis,
monopole vs dipole differing in the edge waves only."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from typer.testing import CliRunner

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
    return analyse_baffle(small_vt, distance=5e-3)


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


def test_baffle_command_prints_differences(tmp_path, small_vt):
    small_vt.save(tmp_path / "vt.h5")
    res = CliRunner().invoke(app, ["baffle", str(tmp_path / "vt.h5"), "--distance", "5e-3"])
    assert res.exit_code == 0, res.output
    assert "monopole" in res.output and "%" in res.output
    assert (tmp_path / "report_baffle.html").exists()


def test_bad_distance_is_an_input_error(small_vt):
    with pytest.raises(InputError, match="distance"):
        analyse_baffle(small_vt, distance=-1.0)


def test_baffle_figure_axes_have_units_and_the_section_joins_report_html(tmp_path, result,
                                                                           small_vt):
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
