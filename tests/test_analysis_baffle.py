"""Source representation (paper sections II C, IV C): Rayleigh vs angular spectrum on axis,
monopole vs dipole differing in the edge waves only."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from holoprobe.analysis import analyse_baffle
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
