"""The published MATLAB toolkit's layout: round trips, hand-written files, errors."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from test_io_support import (
    assert_same_echo,
    assert_same_probe,
    assert_same_scan,
    make_echo,
    make_scan,
)

from _shared import SHARED_DATA
from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid, Pose
from holoprobe.io import (
    read_echo,
    read_echo_any,
    read_reference_calibration,
    read_reference_echo,
    read_reference_scan,
    read_scan,
    read_scan_any,
    write_echo,
    write_reference_echo,
    write_reference_scan,
    write_scan,
)
from holoprobe.measurement import (
    DriveSignal,
    EchoRecording,
    HydrophoneCalibration,
    HydrophoneScan,
    ProbeInfo,
)

VERSIONS = ["5", pytest.param("7.3", marks=pytest.mark.skipif(
    importlib.util.find_spec("hdf5storage") is None, reason="hdf5storage not installed"))]
# mV -> V, mV/MPa -> V/Pa and mm -> m are exact scalings up to one rounding each.
ROUNDING = 4e-16


@pytest.mark.parametrize("version", VERSIONS)
def test_reference_scan_round_trip_recovers_everything_to_rounding(tmp_path, version):
    scan = make_scan()
    files = write_reference_scan(tmp_path, scan, version=version)
    assert [f.name for f in files] == ["ScanData.mat", "sensitivity.mat", "TransmitData.mat"]
    back = read_reference_scan(tmp_path)
    assert_same_scan(back, scan, rtol=ROUNDING)
    assert back.source == str(tmp_path / "ScanData.mat")
    rel = np.max(np.abs(back.data - scan.data) / np.abs(scan.data))
    assert rel <= ROUNDING
    # the width goes through Verasonics wavelengths (three roundings)
    assert_same_probe(back.probe, scan.probe, rtol=1e-15)


@pytest.mark.parametrize("version", VERSIONS)
def test_reference_echo_round_trip_is_exact_and_rf_is_stored_samples_by_channels(
        tmp_path, version):
    rec = make_echo(dtype=np.int16)
    path = write_reference_echo(tmp_path, rec, version=version)
    raw = scipy.io.loadmat(path)["Receive"][0, 0]["RF"] if version == "5" else None
    if raw is not None:
        assert raw.shape == (64, 8) and np.array_equal(raw, rec.rf.T)
    back = read_reference_echo(tmp_path)
    assert_same_echo(back, rec)
    assert_same_probe(back.probe, rec.probe, rtol=1e-15)


def _toolkit_files(directory: Path):
    """Write the four files as the MATLAB toolkit lays them out (no holoprobe extras).

    Values are chosen so that the unit conversions are exact (mV values k/1024·1000,
    MHz integers), and the expected SI objects are written out independently.
    """
    rng = np.random.default_rng(7)
    nx, ny, nt = 6, 3, 20
    dx, dy, dt = 1.5e-4, 2.5e-4, 4e-8
    x = (np.arange(nx) - 2) * dx
    y = (np.arange(ny) - 1) * dy
    counts = rng.integers(-2000, 2000, size=(nx, ny, nt))
    volt_mv = counts / 1024 * 1000  # exact in binary
    grid = {"x": x, "y": y, "z": 0.0, "Nx": nx, "Ny": ny, "Nz": 1, "dx": dx, "dy": dy,
            "dz": dx, "Nt": nt, "dt": dt, "full_size": np.array([[nx], [ny], [1]])}
    scipy.io.savemat(directory / "ScanData.mat", {
        "Grid": grid, "voltage_mV": volt_mv,
        "medium": {"sound_speed": 1481.0, "density": 998.0}})
    sens_mv_per_mpa = np.linspace(90.0, 290.0, 30)
    scipy.io.savemat(directory / "sensitivity.mat", {
        "Frequency": np.arange(1, 31, dtype=np.uint8).reshape(-1, 1),  # as MATLAB stores it
        "Sensitivity": sens_mv_per_mpa.reshape(-1, 1)})
    lam_mm = 1540.0 / 2.5e6 * 1e3  # Verasonics wavelength at Trans.frequency
    trans = {"name": "P4-1", "units": "wavelengths", "numelements": 96.0, "frequency": 2.5,
             "spacingMm": 0.295, "spacing": 0.295 / lam_mm, "elementWidth": 0.245 / lam_mm,
             "elevationApertureMm": 16.0, "elevationFocusMm": 110.0,
             "ConnectorES": np.arange(1, 97).reshape(-1, 1)}
    tx_volt = np.r_[np.zeros(3), np.full(3, 30.0), np.zeros(3)]
    scipy.io.savemat(directory / "TransmitData.mat", {
        "Trans": trans, "Transmit": {"SamplingRate": 250e6, "VoltageSignal": tx_volt}})
    rf = rng.integers(-500, 500, size=(40, 96)).astype(np.int16)  # [Nsamp, Nch]
    rx_volt = np.r_[0.0, 5.0, -5.0, 0.0]
    scipy.io.savemat(directory / "ReceiveData.mat", {
        "Trans": trans, "Transmit": {"SamplingRate": 250e6, "VoltageSignal": rx_volt},
        "Receive": {"RF": rf, "SamplingRate": 62.5e6}})

    probe = ProbeInfo(96, 0.295 / 1000, 0.245 / 1000, 16.0 / 1000, 2.5e6, 110.0 / 1000,
                      name="P4-1")
    scan = HydrophoneScan(
        data=volt_mv / 1000, grid=PlaneGrid(x, y, Pose()), sampling_rate=1 / dt,
        start_time=0.0, quantity="voltage", medium=Medium(998.0, 1481.0),
        calibration=HydrophoneCalibration(np.arange(1.0, 31.0) * 1e6, sens_mv_per_mpa / 1e9,
                                          polarity=-1,
                                          name=str(directory / "sensitivity.mat")),
        probe=probe, drive=DriveSignal(tx_volt, 250e6))
    rec = EchoRecording(rf=rf.T, sampling_rate=62.5e6, unit="ADCL",
                        drive=DriveSignal(rx_volt, 250e6), probe=probe,
                        medium=Medium(998.0, 1481.0))
    return scan, rec


def test_toolkit_written_scan_reads_identical_to_the_native_file(tmp_path):
    ref_dir = tmp_path / "ref"
    ref_dir.mkdir()
    expected, _ = _toolkit_files(ref_dir)
    native = read_scan(write_scan(tmp_path / "scan.h5", expected))
    from_ref = read_reference_scan(ref_dir)
    assert_same_scan(from_ref, native)  # bitwise, apart from the width below
    assert from_ref.calibration.polarity == -1  # the toolkit inverts the hydrophone sign
    assert from_ref.probe.element_width == pytest.approx(0.245e-3, rel=1e-15)
    assert read_scan_any(ref_dir / "ScanData.mat").data.shape == (6, 3, 20)
    assert np.array_equal(read_scan_any(tmp_path / "scan.h5").data, from_ref.data)


def test_toolkit_written_echo_reads_identical_to_the_native_file(tmp_path):
    ref_dir = tmp_path / "ref"
    ref_dir.mkdir()
    _, expected = _toolkit_files(ref_dir)
    native = read_echo(write_echo(tmp_path / "echo.h5", expected))
    from_ref = read_reference_echo(ref_dir)
    assert from_ref.rf.shape == (96, 40)  # elements first, time last
    assert_same_echo(from_ref, native)
    assert from_ref.medium == Medium(998.0, 1481.0)  # taken from the neighbouring ScanData.mat
    assert np.array_equal(read_echo_any(ref_dir).rf, native.rf)


def test_verasonics_wavelength_units_without_spacing_mm_use_1540_m_per_s(tmp_path):
    ref_dir = tmp_path / "ref"
    ref_dir.mkdir()
    _toolkit_files(ref_dir)
    trans = {"numelements": 96.0, "frequency": 2.5, "spacing": 0.5, "elementWidth": 0.4,
             "elevationApertureMm": 14.0}
    scipy.io.savemat(ref_dir / "TransmitData.mat", {"Trans": trans})
    probe = read_reference_scan(ref_dir).probe
    assert probe.pitch == pytest.approx(0.5 * 1540 / 2.5e6, rel=1e-14)  # 0.308 mm
    assert probe.element_width == pytest.approx(0.4 * 1540 / 2.5e6, rel=1e-14)
    assert probe.lens_focus == np.inf


def test_squeezed_singleton_elevation_axis_is_restored(tmp_path):
    x = np.arange(4) * 1e-4
    volt = np.arange(4 * 1 * 8, dtype=float).reshape(4, 1, 8) + 1
    scipy.io.savemat(tmp_path / "ScanData.mat", {
        "Grid": {"x": x, "y": 0.0, "z": 0.0, "Nx": 4, "Ny": 1, "Nt": 8, "dt": 1e-7},
        "voltage_mV": volt, "medium": {"sound_speed": 1500.0, "density": 1000.0}})
    scan = read_reference_scan(tmp_path)
    assert scan.data.shape == (4, 1, 8)
    assert np.array_equal(scan.data * 1000, volt)


def test_real_toolkit_sensitivity_file_converts_mv_per_mpa_to_v_per_pa():
    path = SHARED_DATA / "sensitivity.mat"
    if not path.is_file():  # published calibration; only on the development machines
        pytest.skip("reference data not available")
    cal = read_reference_calibration(path)
    assert cal.frequency.shape == (30,)
    assert cal.frequency[0] == 1e6 and cal.frequency[-1] == 30e6
    # reference_spec section 4: 91.29414 mV/MPa at 1 MHz, 290.3261 at 30 MHz
    assert cal.sensitivity[0] == pytest.approx(91.29414e-9, rel=1e-12)
    assert cal.sensitivity[-1] == pytest.approx(290.3261e-9, rel=1e-12)
    assert cal.polarity == -1


def _write_scan_dir(directory, **changes):
    x = np.arange(4) * 1e-4
    y = np.arange(3) * 1e-4
    variables = {
        "Grid": {"x": x, "y": y, "z": 0.0, "Nx": 4, "Ny": 3, "dx": 1e-4, "dy": 1e-4,
                 "Nt": 8, "dt": 1e-7},
        "voltage_mV": np.ones((4, 3, 8)),
        "medium": {"sound_speed": 1481.0, "density": 998.0},
    }
    for key, value in changes.items():
        if "." in key:
            struct, field = key.split(".")
            if value is None:
                del variables[struct][field]
            else:
                variables[struct][field] = value
        elif value is None:
            del variables[key]
        else:
            variables[key] = value
    scipy.io.savemat(directory / "ScanData.mat", variables)
    return directory / "ScanData.mat"


@pytest.mark.parametrize(
    ("changes", "field", "message"),
    [
        ({"voltage_mV": None}, "voltage_mV", "missing"),
        ({"Grid.dt": None}, "Grid.dt", "missing"),
        ({"medium": None}, "medium", "missing"),
        ({"voltage_mV": np.ones((4, 3, 7))}, "voltage_mV", "expected shape"),
        ({"voltage_mV": np.full((4, 3, 8), np.nan)}, "voltage_mV", "NaN"),
        ({"Grid.x": np.array([0.0, 1e-4, 3e-4, 4e-4])}, "Grid.x", "not uniform"),
        ({"Grid.dx": 2e-4}, "Grid.dx", "step"),
        ({"Grid.Nx": 5}, "Grid.Nx", "values"),
        ({"Grid.z": np.zeros(3)}, "Grid.z", "scalar"),
        ({"medium.density": -1.0}, "medium.density", "positive"),
    ],
)
def test_malformed_toolkit_scan_error_names_file_and_field(tmp_path, changes, field, message):
    path = _write_scan_dir(tmp_path, **changes)
    with pytest.raises(InputError, match=message) as err:
        read_reference_scan(tmp_path)
    assert err.value.file == str(path)
    assert err.value.field == field


def test_receive_rf_with_wrong_channel_count_names_receive_rf(tmp_path):
    write_reference_echo(tmp_path, make_echo())
    d = scipy.io.loadmat(tmp_path / "ReceiveData.mat")
    d = {k: v for k, v in d.items() if not k.startswith("__")}
    d["Receive"][0, 0]["RF"] = np.zeros((64, 7))
    scipy.io.savemat(tmp_path / "ReceiveData.mat", d)
    with pytest.raises(InputError, match="one column per element") as err:
        read_reference_echo(tmp_path)
    assert err.value.field == "Receive.RF"


def test_pressure_scans_and_unknown_files_are_refused_clearly(tmp_path):
    with pytest.raises(InputError, match="voltage"):
        write_reference_scan(tmp_path, make_scan(quantity="pressure"))
    write_reference_scan(tmp_path, make_scan())
    with pytest.raises(InputError, match="already exists"):
        write_reference_scan(tmp_path, make_scan())
    other = tmp_path / "scan.csv"
    other.write_text("1,2,3")
    with pytest.raises(InputError, match="unknown file type"):
        read_scan_any(other)
    notmat = tmp_path / "broken.mat"
    notmat.write_bytes(b"\x00" * 200)
    with pytest.raises(InputError, match="MATLAB") as err:
        read_scan_any(notmat)
    assert err.value.file == str(notmat)
    with pytest.raises(InputError, match=r"no ReceiveData\.mat"):
        read_echo_any(tmp_path)


def test_convex_verasonics_trans_gives_the_arc_from_radius_or_element_positions(tmp_path):
    import dataclasses

    from holoprobe.geometry import ArrayGeometry

    # C5-2-like: 128 elements, pitch 0.508 mm, R = 49.6 mm; written by holoprobe
    # (radiusMm + ElementPos), read back as a convex ArrayGeometry
    arc = ArrayGeometry.convex(128, 0.508e-3, 49.6e-3, 0.45e-3, 13.5e-3)
    scan = make_scan()
    probe = dataclasses.replace(scan.probe, element_count=128, pitch=0.508e-3,
                                element_width=0.45e-3, element_height=13.5e-3, array=arc)
    write_reference_scan(tmp_path / "a", dataclasses.replace(scan, probe=probe))
    got = read_reference_scan(tmp_path / "a").probe.array
    assert got.kind == "convex"
    assert got.radius_of_curvature == pytest.approx(49.6e-3, rel=1e-12)
    assert np.allclose(got.positions, arc.positions, atol=1e-12)
    # a Verasonics file with only ElementPos (x, y, z in wavelengths, angle in rad)
    ref_dir = tmp_path / "b"
    ref_dir.mkdir()
    _toolkit_files(ref_dir)
    lam_mm = 1540 / 3.6e6 * 1e3
    phi = (np.arange(128) - 63.5) * 0.508 / 49.6
    pos = np.zeros((128, 5))
    pos[:, 0] = 49.6 * np.sin(phi) / lam_mm
    pos[:, 2] = 49.6 * (np.cos(phi) - 1) / lam_mm
    pos[:, 3] = phi
    trans = {"numelements": 128.0, "frequency": 3.6, "spacingMm": 0.508,
             "spacing": 0.508 / lam_mm, "elementWidth": 0.45 / lam_mm,
             "elevationApertureMm": 13.5, "ElementPos": pos}
    scipy.io.savemat(ref_dir / "TransmitData.mat", {"Trans": trans})
    got = read_reference_scan(ref_dir).probe.array
    assert got.radius_of_curvature == pytest.approx(49.6e-3, rel=1e-9)
    # angles that contradict the pitch are refused, naming the field
    trans["ElementPos"] = pos * [1, 1, 1, 1.05, 1]
    trans["radiusMm"] = 49.6
    scipy.io.savemat(ref_dir / "TransmitData.mat", {"Trans": trans})
    with pytest.raises(InputError, match="ElementPos"):
        read_reference_scan(ref_dir)
