"""Hologram files: the community MATLAB layout (v5, v7.3) and the native HDF5 one."""

import h5py
import numpy as np
import pytest
import scipy.io

from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid, Pose, SourceGeometry
from holoprobe.io import (
    measurement_kind,
    read_hologram,
    read_hologram_any,
    read_hologram_mat,
    read_scan_any,
    save_mat,
    write_hologram,
    write_hologram_mat,
)
from holoprobe.measurement import Hologram
from holoprobe.signal import cw_amplitude, extract_cw

BOWL = SourceGeometry("spherical-cap", 40e-3, 40e-3, 40e-3)
MEDIUM = Medium(density=1000.0, sound_speed=1490.0)


def _field(x, y):
    """A pressure that encodes its position (Pa): checks positions, not indices."""
    xx, yy = np.meshgrid(x, y, indexing="ij")
    return (1e3 + xx * 1e5) * np.exp(1j * yy * 3e2)


def _cw(nx=7, ny=5):
    grid = PlaneGrid(np.arange(nx) * 0.5e-3 - 1e-3, np.arange(ny) * 0.4e-3 + 2e-3,
                     Pose(origin=(0.0, 0.0, 25e-3)))
    return Hologram(_field(grid.x, grid.y), grid, MEDIUM, frequency=1.1e6, geometry=BOWL)


def _transient(nx=6, ny=4, nt=16):
    grid = PlaneGrid.centered(nx, ny, 0.3e-3, pose=Pose(origin=(0.0, 0.0, 20e-3)))
    rng = np.random.default_rng(1)
    return Hologram(rng.normal(size=(nx, ny, nt)), grid, MEDIUM, sampling_rate=25e6,
                    start_time=3e-6, geometry=SourceGeometry("flat-disc", 20e-3, 20e-3))


def _same(a, b):
    assert np.allclose(a.grid.x, b.grid.x, rtol=0, atol=1e-15)
    assert np.allclose(a.grid.y, b.grid.y, rtol=0, atol=1e-15)
    assert a.z_position == b.z_position and a.medium == b.medium and a.geometry == b.geometry
    assert np.array_equal(a.pressure, b.pressure)


@pytest.mark.parametrize("version", ["5", "7.3"])
@pytest.mark.parametrize("layout", ["meshgrid", "vectors", "nodes", "flattened"])
@pytest.mark.parametrize("descending", [(False, False), (True, True), (True, False)])
def test_cw_mat_round_trip_keeps_values_at_their_positions(tmp_path, version, layout,
                                                          descending):
    if version == "7.3":
        pytest.importorskip("hdf5storage")
    h = _cw()
    path = write_hologram_mat(tmp_path / "h.mat", h, version=version, grid_layout=layout,
                              descending=descending, exp_sign=1 if layout != "nodes" else -1)
    back = read_hologram_mat(path)
    assert np.allclose(back.grid.x, h.grid.x, atol=1e-15)
    assert np.allclose(back.pressure, _field(back.grid.x, back.grid.y), rtol=1e-13)
    assert back.frequency == h.frequency and back.geometry == BOWL
    assert back.source == str(path)


@pytest.mark.parametrize("version", ["5", "7.3"])
@pytest.mark.parametrize("layout", ["meshgrid", "vectors", "nodes", "flattened"])
def test_transient_mat_round_trip(tmp_path, version, layout):
    if version == "7.3":
        pytest.importorskip("hdf5storage")
    h = _transient()
    back = read_hologram_mat(write_hologram_mat(tmp_path / "t.mat", h, version=version,
                                                grid_layout=layout, descending=(True, False)))
    assert back.is_transient and back.sampling_rate == pytest.approx(25e6, rel=1e-12)
    assert back.start_time == pytest.approx(3e-6, rel=1e-12)
    _same(back, h)


def test_native_round_trips_are_bitwise(tmp_path):
    for h in (_cw(), _transient()):
        back = read_hologram(write_hologram(tmp_path / f"{h.is_transient}.h5", h))
        _same(back, h)
        assert back.frequency == h.frequency and back.sampling_rate == h.sampling_rate
        assert read_hologram_any(tmp_path / f"{h.is_transient}.h5").is_transient == \
            h.is_transient
    with h5py.File(tmp_path / "False.h5") as f:
        assert (f.attrs["format"], f.attrs["kind"], f.attrs["schema_version"]) == \
            ("holoprobe", "cw_hologram", 1)


def test_waveforms_n_by_nt_on_axis_vectors_are_flattened_x_fastest(tmp_path):
    """[n, nt] waveforms with xGrid/yGrid axis vectors (n = nx·ny), as MATLAB's
    ``reshape(p, [], nt)`` of an [nx, ny, nt] array leaves them (x fastest), with a
    decreasing y axis: every waveform lands at its own position (built by hand, not by
    the writer)."""
    x, y = np.arange(5) * 0.5e-3, np.arange(3)[::-1] * 0.4e-3        # y decreasing
    t = 2e-6 + np.arange(8) / 20e6
    nodes = [(xi, yi) for yi in y for xi in x]                        # x fastest
    waves = np.array([np.sin(2e6 * t * (1 + 1e3 * xi)) + 1e3 * yi for xi, yi in nodes])
    path = save_mat(tmp_path / "n.mat", {
        "Medium": {"soundSpeed": 1480.0, "density": 998.0},
        "HologramTr": {"xGrid": x, "yGrid": y, "zPosition": 0.02, "dx": 0.5e-3,
                       "dy": 0.4e-3, "time": t, "pressureWaveforms": waves}})
    h = read_hologram_mat(path)
    assert h.grid.shape == (5, 3) and np.all(np.diff(h.grid.y) > 0)
    for i, xi in enumerate(h.grid.x):
        for j, yi in enumerate(h.grid.y):
            assert np.allclose(h.pressure[i, j], np.sin(2e6 * t * (1 + 1e3 * xi)) + 1e3 * yi)
    waves_bad = waves[:-1]
    save_mat(tmp_path / "bad.mat", {
        "Medium": {"soundSpeed": 1480.0, "density": 998.0},
        "HologramTr": {"xGrid": x, "yGrid": y, "zPosition": 0.02, "time": t,
                       "pressureWaveforms": waves_bad}})
    with pytest.raises(InputError, match=r"HologramTr\.xGrid: 5 x and 3 y positions do not "
                                         r"match the 14 points"):
        read_hologram_mat(tmp_path / "bad.mat")


def _xddx_file(tmp_path, name="x.mat", drop=(), **changes):
    """A CW file as MATLAB users write it: meshgrid (ny, nx), expSign +1."""
    x = np.linspace(5e-3, -5e-3, 11)                 # a scanner that runs x downwards
    y = np.linspace(-3e-3, 3e-3, 7)
    xx, yy = np.meshgrid(x, y)
    amp = np.conj(_field(x, y).T)                    # MATLAB fft convention
    sf = {"xGrid": xx, "yGrid": yy, "zPosition": 30e-3, "dx": 1e-3, "dy": 1e-3,
          "frequency": 1e6, "expSign": 1.0, "complexPressureAmplitude": amp}
    variables = {"Medium": {"soundSpeed": 1480.0, "density": 998.0}, "HologramSf": sf,
                 "Geometry": {"apertureMin": 40e-3, "apertureMax": 40e-3,
                              "radiusOfCurvature": 40e-3}}
    for key, value in changes.items():
        struct, field = key.split("__") if "__" in key else ("HologramSf", key)
        variables[struct][field] = value
    for key in drop:
        if "__" in key:
            struct, field = key.split("__")
            del variables[struct][field]
        else:
            del variables[key]
    return save_mat(tmp_path / name, variables)


def test_matlab_meshgrid_with_decreasing_x_and_exp_sign_plus_one(tmp_path):
    h = read_hologram_mat(_xddx_file(tmp_path))
    assert np.all(np.diff(h.grid.x) > 0) and h.grid.shape == (11, 7)
    assert np.allclose(h.pressure, _field(h.grid.x, h.grid.y), rtol=1e-13)
    assert h.geometry == BOWL and h.medium == Medium(998.0, 1480.0)
    x, y = np.linspace(5e-3, -5e-3, 11), np.linspace(-3e-3, 3e-3, 7)
    xx, yy = np.meshgrid(x, y, indexing="ij")        # ndgrid: x along the rows
    nd = read_hologram_mat(_xddx_file(tmp_path, "nd.mat", xGrid=xx, yGrid=yy,
                                      complexPressureAmplitude=np.conj(_field(x, y))))
    assert np.allclose(nd.pressure, _field(nd.grid.x, nd.grid.y), rtol=1e-13)
    flat = read_hologram_mat(_xddx_file(tmp_path, "f.mat", Geometry__radiusOfCurvature=[]))
    assert flat.geometry.kind == "flat-disc" and flat.geometry.radius_of_curvature is None
    assert measurement_kind(tmp_path / "f.mat") == "hologram"


BAD = [
    ({"complexPressureAmplitude": np.zeros((0, 0))}, (), "complexPressureAmplitude: is empty"),
    ({"complexPressureAmplitude": np.ones((7, 10))}, (), "do not match"),
    ({"xGrid": np.linspace(0, 1e-2, 11), "yGrid": np.linspace(0, 1e-2, 8)}, (),
     "do not match"),
    ({}, ("Medium",), "Medium: missing struct"),
    ({"expSign": 0.5}, (), "expSign: expected \\+1"),
    ({"expSign": 0.0}, (), "expSign"),
    ({"zPosition": 0.0}, (), "zPosition: .*in front"),
    ({"zPosition": -5e-3}, (), "zPosition"),
    ({"zPosition": 1e-3, "Geometry__radiusOfCurvature": 10e-3,
      "Geometry__apertureMin": 20e-3, "Geometry__apertureMax": 20e-3}, (), "inside the bowl"),
    ({"complexPressureAmplitude": np.full((7, 11), np.nan)}, (), "NaN"),
    ({"xGrid": np.meshgrid(np.r_[0, 1, 2, 3, 5, 6, 7, 8, 9, 10, 11] * 1e-3,
                           np.linspace(0, 6e-3, 7))[0]}, (), "not uniform"),
    ({"Medium__soundSpeed": 1.48}, (), "Medium.soundSpeed: .*implausible"),
    ({"Medium__density": 1.0}, (), "Medium.density: .*implausible"),
    ({"frequency": 1.0}, (), "HologramSf.frequency: .*implausible"),
    ({"dx": 2e-3}, (), "HologramSf.dx"),
    ({}, ("HologramSf__complexPressureAmplitude",), "missing field"),
]


@pytest.mark.parametrize(("changes", "drop", "match"), BAD)
def test_bad_hologram_files_fail_with_one_clear_line(tmp_path, changes, drop, match):
    path = _xddx_file(tmp_path, drop=drop, **changes)
    with pytest.raises(InputError, match=match) as info:
        read_hologram_mat(path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(str(path))


def test_node_lists_that_do_not_fill_a_grid_are_rejected(tmp_path):
    x = np.repeat(np.arange(4) * 1e-3, 3)
    y = np.tile(np.arange(3) * 1e-3, 4)
    y[5] = y[4]                                       # one node twice, one missing
    path = save_mat(tmp_path / "n.mat", {
        "Medium": {"soundSpeed": 1480.0, "density": 998.0},
        "HologramSf": {"xGrid": x, "yGrid": y, "zPosition": 0.03, "frequency": 1e6,
                       "expSign": -1.0, "complexPressureAmplitude": np.ones(12) + 0j}})
    with pytest.raises(InputError, match="missing, 1 repeated"):
        read_hologram_mat(path)


def test_transient_time_axis_errors(tmp_path):
    h = _transient()
    path = write_hologram_mat(tmp_path / "t.mat", h)
    data = {k: v for k, v in scipy.io.loadmat(path, simplify_cells=True).items()
            if not k.startswith("__")}
    data["HologramTr"]["time"] = data["HologramTr"]["time"][:-1]
    save_mat(tmp_path / "bad.mat", data)
    with pytest.raises(InputError, match=r"HologramTr\.time: has 15 samples"):
        read_hologram_mat(tmp_path / "bad.mat")
    data["HologramTr"]["time"] = np.r_[0, 1, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15,
                                       16] * 1e-7
    save_mat(tmp_path / "bad2.mat", data)
    with pytest.raises(InputError, match="uniformly"):
        read_hologram_mat(tmp_path / "bad2.mat")
    # a float32 time vector (rounding ~1e-7 of t) is uniform enough
    data["HologramTr"]["time"] = (1e-4 + np.arange(16) / 25e6).astype(np.float32)
    save_mat(tmp_path / "f32.mat", data)
    assert read_hologram_mat(tmp_path / "f32.mat").sampling_rate == pytest.approx(25e6,
                                                                                  rel=1e-5)


def test_dispatch_tells_holograms_from_scans(tmp_path):
    path = _xddx_file(tmp_path)
    assert measurement_kind(path) == "hologram"
    with pytest.raises(InputError, match="is a hologram"):
        read_scan_any(path)
    native = write_hologram(tmp_path / "h.h5", _cw())
    assert measurement_kind(native) == "hologram"
    with pytest.raises(InputError, match="read_hologram"):
        from holoprobe.io import read_scan
        read_scan(native)


def test_extract_cw_recovers_a_known_tone_at_any_frequency():
    fs, nt, t0 = 20e6, 400, 2.5e-6
    t = t0 + np.arange(nt) / fs
    amp = 1.7e5 * np.exp(0.6j)
    for f, methods in ((1.0e6, ("dft", "fit")), (1.0137e6, ("fit",))):
        p = np.real(amp * np.exp(-2j * np.pi * f * t)) + 30.0    # a DC offset too
        for method in methods:
            got = cw_amplitude(p[None, :], t, f, method=method)[0]
            assert abs(got / amp - 1) < 1e-9, (f, method)
    grid = PlaneGrid.centered(3, 2, 1e-3, pose=Pose(origin=(0, 0, 0.02)))
    wave = np.real(amp * np.exp(-2j * np.pi * 1e6 * t))
    h = Hologram(np.broadcast_to(wave, (3, 2, nt)).copy(), grid, MEDIUM, sampling_rate=fs,
                 start_time=t0)
    cw = extract_cw(h, 1e6)
    assert cw.frequency == 1e6 and np.allclose(cw.pressure, amp, rtol=1e-9)
    with pytest.raises(InputError, match="Nyquist"):
        extract_cw(h, 11e6)


@pytest.mark.parametrize("layout", ["flattened", "flattened-y"])
def test_flattened_points_on_a_non_square_grid_are_read_in_their_order(tmp_path, layout):
    """[n] data on axis vectors of a 24 × 17 grid, flattened x fastest or y fastest: the
    wrong reading shears rows into columns (a rough image), so "auto" takes the smooth one
    without a note; an explicit order is taken as given."""
    h = _cw(24, 17)
    path = write_hologram_mat(tmp_path / "f.mat", h, grid_layout=layout, descending=(True, False))
    auto = read_hologram_mat(path)
    assert np.allclose(auto.pressure, _field(auto.grid.x, auto.grid.y), rtol=1e-13)
    assert auto.notes == ()
    given = read_hologram_mat(path, flattened_order="y" if layout == "flattened-y" else "x")
    assert np.array_equal(given.pressure, auto.pressure) and given.notes == ()


def test_flattened_points_on_a_square_grid_are_read_x_fastest_with_a_note(tmp_path):
    """Review: on a square grid the two flattenings are each other's transpose, which no
    file can tell apart; y-fastest data were silently transposed. Now "auto" reads x
    fastest and says so in Hologram.notes (the characterization repeats it among its
    warnings); flattened_order="y" reads them right."""
    h = _cw(16, 16)
    path = write_hologram_mat(tmp_path / "s.mat", h, grid_layout="flattened-y")
    auto = read_hologram_mat(path)
    assert len(auto.notes) == 1
    assert "square grid" in auto.notes[0] and "hologram.flattened_order" in auto.notes[0]
    assert np.allclose(auto.pressure, _field(auto.grid.x, auto.grid.y).T, rtol=1e-13)
    right = read_hologram_mat(path, flattened_order="y")
    assert np.allclose(right.pressure, _field(right.grid.x, right.grid.y), rtol=1e-13)
    assert right.notes == ()
    with pytest.raises(InputError, match="flattened_order: expected 'auto', 'x' or 'y'"):
        read_hologram_mat(path, flattened_order="z")


def test_flattened_noise_on_a_non_square_grid_keeps_x_fastest_with_a_note(tmp_path):
    """Neither reading of unstructured data is smoother: x fastest, with a note."""
    path = write_hologram_mat(tmp_path / "r.mat", _transient(), grid_layout="flattened")
    back = read_hologram_mat(path)
    _same(back, _transient())
    assert len(back.notes) == 1 and "clearly smoother" in back.notes[0]
