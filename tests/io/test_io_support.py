"""Small synthetic measurements shared by the io tests (helpers only, no tests)."""

import numpy as np

from holoprobe.geometry import Medium, PlaneGrid, Pose
from holoprobe.measurement import (
    DriveSignal,
    EchoRecording,
    HydrophoneCalibration,
    HydrophoneScan,
    ProbeInfo,
)


def make_probe(n=8):
    return ProbeInfo(element_count=n, pitch=3.0e-4, element_width=2.5e-4,
                     element_height=1.4e-2, center_frequency=2.5e6, lens_focus=0.18,
                     name="test-array")


def make_scan(*, dtype=np.float64, quantity="voltage", seed=1, extras=True):
    rng = np.random.default_rng(seed)
    pose = Pose(0.01, -0.02, 0.005, (1e-4, -2e-4, 3.5e-3))
    grid = PlaneGrid.centered(5, 4, 1.5e-4, 2.0e-4, pose=pose)
    data = rng.standard_normal((5, 4, 16)).astype(dtype) * 0.01
    kwargs = {}
    if extras:
        f = np.arange(1.0, 31.0) * 1e6
        kwargs = {
            "calibration": HydrophoneCalibration(
                f, 1e-7 * (1 + 0.01 * np.arange(30)), phase=0.01 * np.arange(30),
                polarity=-1, name="needle"),
            "probe": make_probe(),
            "drive": DriveSignal(np.r_[0.0, 30.0, 30.0, 30.0, 0.0], 250e6),
        }
    return HydrophoneScan(data=data, grid=grid, sampling_rate=25e6, start_time=1.2e-6,
                          quantity=quantity, medium=Medium(997.0, 1482.5),
                          source="simulated", **kwargs)


def make_echo(*, dtype=np.float64, seed=2):
    rng = np.random.default_rng(seed)
    rf = (rng.standard_normal((8, 64)) * 100).astype(dtype)
    return EchoRecording(rf=rf, sampling_rate=62.5e6, start_time=2e-6, unit="ADCL",
                         drive=DriveSignal(np.r_[0.0, 20.0, -20.0, 0.0], 250e6),
                         probe=make_probe(), medium=Medium(998.0, 1481.0), source="simulated")


def assert_same_scan(a, b, *, rtol=0.0):
    """Field-by-field comparison (``source`` excluded); rtol=0 means bitwise equal."""
    def close(u, v):
        u, v = np.asarray(u), np.asarray(v)
        assert u.shape == v.shape
        if rtol == 0:
            assert np.array_equal(u, v)
        else:
            np.testing.assert_allclose(u, v, rtol=rtol, atol=0)

    close(a.data, b.data)
    close(a.grid.x, b.grid.x)
    close(a.grid.y, b.grid.y)
    assert a.grid.pose == b.grid.pose
    close(a.sampling_rate, b.sampling_rate)
    assert a.start_time == b.start_time
    assert a.quantity == b.quantity
    assert a.medium == b.medium
    for name in ("calibration", "probe", "drive"):
        assert (getattr(a, name) is None) == (getattr(b, name) is None), name
    if a.calibration is not None:
        close(a.calibration.frequency, b.calibration.frequency)
        close(a.calibration.sensitivity, b.calibration.sensitivity)
        assert (a.calibration.phase is None) == (b.calibration.phase is None)
        if a.calibration.phase is not None:
            close(a.calibration.phase, b.calibration.phase)
        assert a.calibration.polarity == b.calibration.polarity
        assert a.calibration.name == b.calibration.name
    if a.probe is not None:
        assert_same_probe(a.probe, b.probe, rtol=rtol)
    if a.drive is not None:
        close(a.drive.voltage, b.drive.voltage)
        assert a.drive.sampling_rate == b.drive.sampling_rate


def assert_same_probe(a, b, *, rtol=0.0):
    assert a.element_count == b.element_count and a.name == b.name
    for name in ("pitch", "element_width", "element_height", "center_frequency", "lens_focus"):
        u, v = getattr(a, name), getattr(b, name)
        if rtol == 0 or np.isinf(u):
            assert u == v, name
        else:
            assert abs(u - v) <= rtol * abs(v), (name, u, v)


def assert_same_echo(a, b):
    assert a.rf.dtype == b.rf.dtype
    assert np.array_equal(a.rf, b.rf)
    assert a.sampling_rate == b.sampling_rate
    assert a.start_time == b.start_time
    assert a.unit == b.unit
    assert a.medium == b.medium
    assert (a.probe is None) == (b.probe is None)
    assert (a.drive is None) == (b.drive is None)
    if a.drive is not None:
        assert np.array_equal(a.drive.voltage, b.drive.voltage)
        assert a.drive.sampling_rate == b.drive.sampling_rate
