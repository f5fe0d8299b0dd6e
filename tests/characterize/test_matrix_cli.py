"""``holoprobe characterize`` on a 2-D matrix array (issue 16): the layout from
``--array matrix --grid NXxNY --pitch`` for a file that does not carry it (a file with
/probe/array is detected by the pipeline itself: ``ProbeInfo.is_matrix``)."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from _shared import run_cli
from holoprobe.geometry import Pose

ECHO_D, ECHO_TX, ECHO_TY = 8e-3, 1.0, -1.5  # plate distance (m), θx', θy' (degrees)


@pytest.fixture(scope="module")
def scan_files(tmp_path_factory):
    from holoprobe.io import write_echo, write_scan
    from holoprobe.measurement import ProbeInfo
    from holoprobe.simulate import ArrayModel, simulate_echo, simulate_scan

    model = ArrayModel.matrix(4, 4, 0.3e-3).with_element_variation(dead=(5,), seed=3)
    scan, _ = simulate_scan(model, pose=Pose.from_degrees(0.5, -0.4, 0.8, (0, 0, 1.5e-3)),
                            size=(6e-3, 6e-3), step=(0.15e-3, 0.15e-3), sampling_rate=40e6,
                            n_samples=384, snr_db=40.0, calibration=None,
                            points_per_wavelength=2)
    d = tmp_path_factory.mktemp("matrix_cli")
    # the data described only as a flat row of 16 elements (no layout)
    flat = ProbeInfo(16, 0.3e-3, 0.27e-3, 0.27e-3, 3e6)
    write_scan(d / "no_layout.h5", dataclasses.replace(scan, probe=flat))
    # the scan with its layout (/probe/array) and the plate echo of the same array
    write_scan(d / "scan.h5", scan)
    echo, _ = simulate_echo(model, plate_distance=ECHO_D, virtual_tilt=math.radians(ECHO_TY),
                            virtual_tilt_x=math.radians(ECHO_TX), reflection_coefficient=0.78,
                            back_wall=True, plate_thickness=6e-3, snr_db=40, seed=4,
                            band=(1.5e6, 4.5e6), points_per_wavelength=2, start_time=6e-6,
                            n_samples=640, sampling_rate=40e6)
    write_echo(d / "echo.h5", echo)
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


def test_cli_matrix_receive_writes_the_receive_section_model_and_report(scan_files, tmp_path,
                                                                        capsys):
    """``characterize SCAN --receive ECHO`` on a matrix scan whose file carries the
    layout: the transmit fit's grid and face feed the matrix receive (end to end through
    the CLI; the receive step alone is tested against the truth in
    test_matrix_receive.py); θx', θy', d and the image centre with their σ reach
    summary.json and the printed table, the receive gains the virtual transducer and
    the grid page of report.html. ``--set receive.pose_noise_draws=2`` (fewer draws
    than the default 8, for time) reaches the Monte-Carlo σ."""
    from holoprobe.transducer import VirtualTransducer

    out = tmp_path / "out"
    code, stdout, err = run_cli(["characterize", str(scan_files / "scan.h5"), "--receive",
                                 str(scan_files / "echo.h5"), "--out", str(out),
                                 "--set", "receive.pose_noise_draws=2"], capsys)
    assert code == 0, err
    s = json.loads((out / "summary.json").read_text())
    r, u = s["receive"], s["uncertainty"]["receive"]
    print(f"CLI matrix receive: d {(r['reflector_distance'] - ECHO_D) * 1e6:+.1f} µm "
          f"(σ {u['reflector_distance'] * 1e6:.1f}), θx' {r['theta_x_deg'] - ECHO_TX:+.4f}° "
          f"(σ {u['theta_x_deg']:.4f}), θy' {r['theta_y_deg'] - ECHO_TY:+.4f}° "
          f"(σ {u['theta_y_deg']:.4f})")
    # 16 elements: σ(d) is 0.4-0.7 mm (one draw: −61 µm with the far-field arrival
    # model, −348 µm with the near-field-valid one, both within 1 σ)
    assert abs(r["reflector_distance"] - ECHO_D) < 3 * u["reflector_distance"] < 2.5e-3
    for key, want in (("theta_x_deg", ECHO_TX), ("theta_y_deg", ECHO_TY)):
        assert abs(r[key] - want) < min(3 * u[key], 0.1)
    for key in ("sensor_x0", "sensor_y0", "sensor_z0"):
        assert r[key] is not None and u[key] > 0
    # the twin's mirror image of the face centre: 2 d cos²(θx'/2) cos²(θy'/2) from the face
    half_x, half_y = math.radians(ECHO_TX) / 2, math.radians(ECHO_TY) / 2
    z_true = 2 * ECHO_D * (math.cos(half_x) * math.cos(half_y)) ** 2
    print(f"sensor_z0 {(r['sensor_z0'] - z_true) * 1e6:+.1f} µm (σ {u['sensor_z0'] * 1e6:.1f})")
    assert abs(r["sensor_z0"] - z_true) < 3 * u["sensor_z0"]  # 2 d: −123 / −696 µm (above)
    assert len(s["elements"]["receive_gain"]) == 16 and s["elements"]["dead"] == [5]
    assert abs(s["elements"]["receive_gain"][5]) < 0.1  # the dead element hears nothing
    assert "receive.theta_x_deg" in stdout and "receive.sensor_y0" in stdout
    vt = VirtualTransducer.load(out / "virtual_transducer.h5")
    assert vt.receive_impulse_response is not None and vt.array.grid_shape == (4, 4)
    np.testing.assert_allclose(vt.element_sensitivity, s["elements"]["receive_gain"])
    html = (out / "report.html").read_text()
    assert "Element grid (matrix array)" in html
