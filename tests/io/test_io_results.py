"""io: source_velocity.h5 and drive files, round trips and errors naming file and field."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.io import read_drive, read_source_velocity, write_source_velocity


def test_source_velocity_round_trip_and_kind_check(tmp_path):
    v = np.random.default_rng(0).normal(size=(3, 4, 5)).astype(np.float32)
    x, y = np.linspace(-1e-3, 1e-3, 3), np.linspace(-2e-3, 2e-3, 4)
    path = write_source_velocity(tmp_path / "sv.h5", v, x, y, 50e6, (1e6, 4e6))
    back = read_source_velocity(path)
    np.testing.assert_array_equal(back["velocity"], v)
    np.testing.assert_array_equal(back["y"], y)
    assert back["sampling_rate"] == 50e6 and back["start_time"] == 0.0
    with pytest.raises(InputError, match="exist"):
        write_source_velocity(path, v, x, y, 50e6, (1e6, 4e6))
    # float64 input is stored as the documented float32, contiguous (faster to write)
    write_source_velocity(tmp_path / "sv64.h5", v.astype(np.float64), x, y, 50e6, (1e6, 4e6))
    with h5py.File(tmp_path / "sv64.h5") as f:
        assert f["velocity"].dtype == np.float32 and f["velocity"].chunks is None
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f.attrs["kind"] = "holoprobe_something_else"
        f["velocity"] = v
    with pytest.raises(InputError, match=r"other\.h5.*kind"):
        read_source_velocity(tmp_path / "other.h5")


def test_drive_from_csv_and_errors(tmp_path):
    t = np.arange(6) / 250e6
    path = tmp_path / "drive.csv"
    np.savetxt(path, np.column_stack([t, [0, 1, 2, 1, 0, 0]]), delimiter=",",
               header="time_s, voltage_V")
    drive = read_drive(path)
    assert drive.sampling_rate == pytest.approx(250e6, rel=1e-9)
    np.testing.assert_array_equal(drive.voltage, [0, 1, 2, 1, 0, 0])
    bad = tmp_path / "bad.csv"
    np.savetxt(bad, np.column_stack([t[::-1], np.ones(6)]), delimiter=",")
    with pytest.raises(InputError, match=r"bad\.csv.*time_s"):
        read_drive(bad)
    with pytest.raises(InputError, match="--drive"):
        read_drive(tmp_path / "missing.csv")


def test_field_and_rf_files_round_trip_with_one_tagging_scheme(tmp_path):
    from holoprobe.io import read_results_h5, write_field, write_rf

    rng = np.random.default_rng(1)
    p = rng.normal(size=(3, 2, 16)).astype(np.float32)
    pts = rng.normal(size=(3, 2, 3))
    path = write_field(tmp_path / "field.h5", p, np.arange(16) / 1e7, np.zeros((3, 2)), pts,
                       np.abs(p).max(axis=-1), sampling_rate=1e7,
                       frequency_band=(1e6, 3e6), method="element", plane="xz",
                       axes=(np.arange(3.0), np.arange(2.0)), provenance={"transmit_file": "t"})
    back = read_results_h5(path, "holoprobe-field")
    np.testing.assert_array_equal(back["pressure"], p)
    np.testing.assert_array_equal(back["points"], pts)
    assert back["kind"] == "field" and back["schema_version"] == 1
    assert back["transmit_file"] == "t" and back["plane"] == "xz"
    rf = write_rf(tmp_path / "rf.h5", rng.normal(size=(4, 8)), np.arange(8) / 1e7,
                  np.zeros((1, 3)), np.ones(1), unit="V/Pa", sampling_rate=1e7)
    assert read_results_h5(rf, "holoprobe-rf")["rf"].shape == (4, 8)
    with pytest.raises(InputError, match="format"):
        read_results_h5(rf, "holoprobe-field")
