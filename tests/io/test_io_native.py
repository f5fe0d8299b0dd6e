"""Native HDF5 files: exact round trips and clear errors for malformed files."""

import h5py
import numpy as np
import pytest
from test_io_support import assert_same_echo, assert_same_scan, make_echo, make_scan

from holoprobe.errors import InputError
from holoprobe.io import (
    SCHEMA_VERSION,
    read_echo,
    read_file_kind,
    read_scan,
    write_echo,
    write_scan,
)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_scan_round_trip_is_bitwise_exact_with_all_metadata(tmp_path, dtype):
    scan = make_scan(dtype=dtype)
    path = write_scan(tmp_path / "scan.h5", scan)
    back = read_scan(path)
    assert back.data.dtype == dtype
    assert_same_scan(back, scan)
    assert back.source == str(path)
    with h5py.File(path) as f:
        assert f.attrs["format"] == "holoprobe"
        assert f.attrs["kind"] == "hydrophone_scan"
        assert f.attrs["schema_version"] == SCHEMA_VERSION
        assert f.attrs["source"] == "simulated"
        assert f["data"].attrs["units"] == "V"
        assert [d.label for d in f["data"].dims] == ["x", "y", "t"]
        assert f["calibration/sensitivity"].attrs["units"] == "V/Pa"


def test_pressure_scan_without_optional_groups_round_trips_with_gzip(tmp_path):
    scan = make_scan(quantity="pressure", extras=False)
    path = write_scan(tmp_path / "p.h5", scan, compression="gzip", chunk_bytes=256)
    back = read_scan(path)
    assert_same_scan(back, scan)
    assert back.calibration is None and back.probe is None and back.drive is None
    with h5py.File(path) as f:
        assert f["data"].attrs["units"] == "Pa"
        assert f["data"].compression == "gzip"
        assert f["data"].chunks[2] == scan.n_samples  # time axis kept whole in a chunk


@pytest.mark.parametrize("dtype", [np.float64, np.int16])
def test_echo_round_trip_is_bitwise_exact(tmp_path, dtype):
    rec = make_echo(dtype=dtype)
    path = write_echo(tmp_path / "echo.h5", rec)
    back = read_echo(path)
    assert_same_echo(back, rec)
    assert back.probe == rec.probe
    assert read_file_kind(path) == "echo_recording"


def test_existing_output_is_refused_and_input_is_protected(tmp_path):
    path = write_scan(tmp_path / "scan.h5", make_scan())
    with pytest.raises(InputError, match="already exists"):
        write_scan(path, make_scan())
    write_scan(path, make_scan(seed=5), overwrite=True)
    scan = read_scan(path)  # source is this file
    with pytest.raises(InputError, match="input"):
        write_scan(path, scan, overwrite=True)


def _corrupt(path, edit):
    with h5py.File(path, "r+") as f:
        edit(f)


def _replace(name, value, units):
    def edit(f):
        attrs = {k: v for k, v in f[name].attrs.items() if k in ("quantity",)}
        del f[name]
        f[name] = value
        f[name].attrs.update(attrs)
        f[name].attrs["units"] = units
    return edit


def _scan_file(tmp_path):
    return write_scan(tmp_path / "scan.h5", make_scan())


@pytest.mark.parametrize(
    ("edit", "field", "message"),
    [
        (lambda f: f.__delitem__("x"), "/x", "missing dataset"),
        (lambda f: f.__delitem__("medium/density"), "/medium/density", "missing dataset"),
        (lambda f: f.__delitem__("calibration/sensitivity"), "/calibration/sensitivity",
         "missing"),
        (_replace("data", np.zeros((6, 4, 16)), "V"), "/data", "expected shape"),
        (_replace("pose/theta", np.zeros(2), "rad"), "/pose/theta", "expected shape"),
        (_replace("data", np.full((5, 4, 16), np.nan), "V"), "/data", "NaN"),
        (_replace("x", np.array([0.0, 1e-4, 3e-4, 4e-4, 5e-4]), "m"), "/x", "not uniform"),
        (_replace("sampling_rate", 25e6, "MHz"), "/sampling_rate", "units"),
        (_replace("sampling_rate", -1.0, "Hz"), "/sampling_rate", "positive"),
        (lambda f: f.attrs.__setitem__("kind", "echo_recording"), "/", "expected"),
        (lambda f: f.attrs.__setitem__("schema_version", SCHEMA_VERSION + 1), "/", "newer"),
        (lambda f: f.attrs.__setitem__("format", "other"), "/", "not a holoprobe file"),
        (_replace("calibration/polarity", 2, "1"), "/calibration/polarity", "1 or -1"),
    ],
)
def test_malformed_scan_file_error_names_file_and_dataset(tmp_path, edit, field, message):
    path = _scan_file(tmp_path)
    _corrupt(path, edit)
    with pytest.raises(InputError, match=message) as err:
        read_scan(path)
    assert err.value.file == str(path)
    assert err.value.field == field
    assert str(path) in str(err.value) and field in str(err.value)


def test_reading_a_scan_file_as_echo_names_the_right_reader(tmp_path):
    path = _scan_file(tmp_path)
    with pytest.raises(InputError, match="read_scan") as err:
        read_echo(path)
    assert err.value.file == str(path)


def test_echo_with_channel_count_unlike_probe_is_rejected(tmp_path):
    path = write_echo(tmp_path / "echo.h5", make_echo())
    _corrupt(path, _replace("rf", np.zeros((7, 64)), "ADCL"))
    with pytest.raises(InputError, match="expected shape") as err:
        read_echo(path)
    assert err.value.field == "/rf"


def test_non_hdf5_and_missing_files_are_clear_errors(tmp_path):
    bogus = tmp_path / "scan.h5"
    bogus.write_text("not hdf5")
    with pytest.raises(InputError, match="not an HDF5 file"):
        read_scan(bogus)
    with pytest.raises(InputError, match="no such file"):
        read_scan(tmp_path / "absent.h5")


def test_a_directory_written_by_holoprobe_simulate_is_read_through_its_native_file(tmp_path):
    # `holoprobe simulate scan --out DIR` writes DIR/scan.h5 (+ truth): a new user passes
    # DIR to `holoprobe characterize`; it used to say "directory holds no ScanData.mat"
    from holoprobe.io import measurement_kind, read_echo_any, read_scan_any

    scan_dir, echo_dir, empty = tmp_path / "scan", tmp_path / "echo", tmp_path / "empty"
    for d in (scan_dir, echo_dir, empty):
        d.mkdir()
    write_scan(scan_dir / "scan.h5", make_scan())
    write_echo(echo_dir / "echo.h5", make_echo())
    assert_same_scan(read_scan_any(scan_dir), make_scan())
    assert_same_echo(read_echo_any(echo_dir), make_echo())
    assert measurement_kind(scan_dir) == "hydrophone_scan"
    assert measurement_kind(echo_dir) == "echo_recording"
    with pytest.raises(InputError, match=r"holds no ScanData\.mat"):
        read_scan_any(empty)
    with pytest.raises(InputError, match=r"holds no ReceiveData\.mat"):
        read_echo_any(scan_dir)


def test_a_read_scan_holds_its_data_frozen_and_a_given_array_is_copied(tmp_path):
    """The reader's fresh array goes into the scan as it is (read-only, no second copy of
    the record); an array a caller passes is copied, so writing to it later leaves the
    scan unchanged."""
    import dataclasses

    from holoprobe.measurement import HydrophoneScan

    scan = make_scan(dtype=np.float32)
    path = write_scan(tmp_path / "s.h5", scan)
    back = read_scan(path)
    assert not back.data.flags.writeable and back.data.base is None
    mine = np.array(back.data)  # writable, the caller's
    given = dataclasses.replace(back, data=mine)
    mine[0, 0, 0] += 1.0
    assert given.data is not mine and given.data[0, 0, 0] == back.data[0, 0, 0]
    assert not given.data.flags.writeable
    assert isinstance(given, HydrophoneScan)
    # review (session 11): a caller's read-only array that owns its memory was kept
    # as it is, so the caller could turn writes back on and change the frozen scan
    frozen = np.array(back.data)
    frozen.setflags(write=False)
    held = dataclasses.replace(back, data=frozen)
    frozen.setflags(write=True)
    frozen[0, 0, 0] += 1.0
    assert held.data[0, 0, 0] == back.data[0, 0, 0]


@pytest.mark.parametrize(
    ("write", "message"),
    [
        ("io.write_scan", "scan: expected a HydrophoneScan, got dict"),
        ("io.write_echo", "rec: expected an EchoRecording, got dict"),
        ("io.write_hologram", "hologram: expected a Hologram, got dict"),
        ("io.write_reference_scan", "scan: expected a HydrophoneScan, got dict"),
        ("io.write_reference_echo", "rec: expected an EchoRecording, got dict"),
        ("io.write_hologram_mat", "hologram: expected a Hologram, got dict"),
        ("io.write_source", "source: expected a SourceVelocity, got dict"),
        ("transducer.write_virtual_transducer", "vt: expected a VirtualTransducer, got dict"),
    ],
)
def test_writers_name_a_wrong_argument_type(tmp_path, write, message):
    import importlib

    module, name = write.split(".")
    with pytest.raises(InputError) as err:
        getattr(importlib.import_module(f"holoprobe.{module}"), name)(tmp_path / "out", {})
    assert str(err.value) == message
    assert not (tmp_path / "out").exists()
