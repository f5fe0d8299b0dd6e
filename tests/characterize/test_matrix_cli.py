"""``holoprobe characterize`` on a 2-D matrix array (issue 16): the layout from
``--array matrix --grid NXxNY --pitch`` for a file that does not carry it (a file with
/probe/array is detected by the pipeline itself: ``ProbeInfo.is_matrix``)."""

from __future__ import annotations

import dataclasses
import json

import pytest

from _shared import run_cli
from holoprobe.geometry import Pose


@pytest.fixture(scope="module")
def scan_files(tmp_path_factory):
    from holoprobe.io import write_scan
    from holoprobe.measurement import ProbeInfo
    from holoprobe.simulate import ArrayModel, simulate_scan

    model = ArrayModel.matrix(4, 4, 0.3e-3).with_element_variation(dead=(5,), seed=3)
    scan, _ = simulate_scan(model, pose=Pose.from_degrees(0.5, -0.4, 0.8, (0, 0, 1.5e-3)),
                            size=(6e-3, 6e-3), step=(0.15e-3, 0.15e-3), sampling_rate=40e6,
                            n_samples=384, snr_db=40.0, calibration=None,
                            points_per_wavelength=2)
    d = tmp_path_factory.mktemp("matrix_cli")
    # the data described only as a flat row of 16 elements (no layout)
    flat = ProbeInfo(16, 0.3e-3, 0.27e-3, 0.27e-3, 3e6)
    write_scan(d / "no_layout.h5", dataclasses.replace(scan, probe=flat))
    return d


def test_cli_characterizes_a_matrix_described_by_the_options(scan_files, tmp_path, capsys):
    out = tmp_path / "out"
    code, _, err = run_cli(["characterize", str(scan_files / "no_layout.h5"), "--out",
                            str(out), "--quiet", "--array", "matrix", "--grid", "4x4",
                            "--pitch", "0.0003"], capsys)
    assert code == 0, err
    s = json.loads((out / "summary.json").read_text())
    assert s["elements"]["grid_shape"] == [4, 4] and s["elements"]["dead"] == [5]
    # the pitch the options give starts the fit, the data set it (0.5 µm off on 4 × 4)
    assert s["elements"]["pitch_y"] == pytest.approx(0.3e-3, abs=2e-6)


def test_cli_refuses_a_bad_grid(scan_files, tmp_path, capsys):
    code, _, err = run_cli(["characterize", str(scan_files / "no_layout.h5"), "--out",
                            str(tmp_path / "o"), "--array", "matrix", "--grid", "4by4"],
                           capsys)
    assert code == 2 and "--grid" in err
