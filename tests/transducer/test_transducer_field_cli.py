"""``holoprobe field`` and ``holoprobe rf`` end to end on a tiny virtual transducer.

The model is built here (16 elements, short IRs); the files written are read back
and checked against the physics they show (the focus of the map, the echo depth).
"""

from __future__ import annotations

import subprocess
import sys

import h5py
import numpy as np
import pytest

from _shared import run_cli
from holoprobe.geometry import Medium
from holoprobe.transducer import VirtualTransducer

FS = 100e6


def _pulse(fc, tc, sigma, a, n=200):
    t = np.arange(n) / FS
    return a * np.exp(-(((t - tc) / sigma) ** 2)) * np.sin(2 * np.pi * fc * (t - tc))


@pytest.fixture
def files(tmp_path):
    vt = VirtualTransducer(
        element_count=16, pitch=0.3e-3, element_width=0.25e-3, element_height=2e-3,
        transmit_impulse_response=_pulse(3e6, 0.5e-6, 0.2e-6, 1e11),
        transmit_sampling_rate=FS, lens_focus=0.006, medium=Medium(),
        receive_impulse_response=_pulse(3e6, 0.5e-6, 0.2e-6, 1e6), receive_sampling_rate=FS,
        receive_units="V/(Pa*s)")
    vt_path = vt.save(tmp_path / "vt.h5")
    no_rx = vt.replace(receive_impulse_response=None, receive_sampling_rate=None)
    no_rx_path = no_rx.save(tmp_path / "vt_tx_only.h5")
    tx = tmp_path / "tx.toml"
    tx.write_text('[delays]\nkind = "focused"\npoint = [0.0, 0.0, 0.006]\n'
                  '[drive]\nkind = "burst"\nfrequency = 3e6\ncycles = 1\namplitude = 10.0\n'
                  'sampling_rate = 100e6\n')
    scat = tmp_path / "scatterers.csv"
    scat.write_text("x_mm, y_mm, z_mm, amplitude_mm\n0.0, 0.0, 6.0, 0.1\n0.5, 0.0, 9.0\n")
    return vt_path, no_rx_path, tx, scat


def test_field_cli_writes_a_plane_whose_peak_lies_at_the_focus(files, tmp_path, capsys):
    vt_path, _, tx, _ = files
    out = tmp_path / "field"
    code, _, err = run_cli(["field", str(vt_path), "--transmit", str(tx), "--plane", "xz",
                            "--extent", "-2", "2", "2", "10", "--step", "0.15",
                            "--out", str(out), "--quiet"], capsys)
    assert code == 0, err
    for name in ("field.h5", "peak_pressure_xz.png", "on_axis_profile.png", "waveform.png"):
        assert (out / name).is_file(), name
    with h5py.File(out / "field.h5") as f:
        p = f["pressure"][...]
        x, z = f["axis_0"][...], f["axis_1"][...]
        assert p.shape[:2] == (x.size, z.size) and p.shape[2] == f["time"].size
        assert f["pressure"].attrs["units"] == "Pa"
        assert "focused" in f.attrs["transmit_setting_toml"]
        assert np.allclose(np.diff(x), 0.15e-3)  # 0.15 mm divides the 0.3 mm pitch
    i, j = np.unravel_index(np.argmax(p.max(axis=2)), p.shape[:2])
    assert abs(x[i]) <= 0.3e-3
    assert 3.5e-3 <= z[j] <= 6.5e-3  # focal shift towards the probe (4.8 mm aperture)


def test_field_cli_on_points_from_a_csv(files, tmp_path, capsys):
    vt_path, _, tx, _ = files
    pts = tmp_path / "points.csv"
    pts.write_text("# x, y, z in mm\n0, 0, 6\n1, 0.5, 8\n")
    code, _, err = run_cli(["field", str(vt_path), "--transmit", str(tx), "--points",
                            str(pts), "--out", str(tmp_path / "o"), "--quiet"], capsys)
    assert code == 0, err
    with h5py.File(tmp_path / "o" / "field.h5") as f:
        assert f["pressure"].shape[0] == 2
        np.testing.assert_allclose(f["points"][...], [[0, 0, 6e-3], [1e-3, 0.5e-3, 8e-3]])
        pressure = f["pressure"][...]
    assert {p.name for p in (tmp_path / "o").iterdir()} == {
        "field.h5", "on_axis_profile.png", "waveform.png"}
    # --no-figures: the same field.h5, and nothing else
    code, _, err = run_cli(["field", str(vt_path), "--transmit", str(tx), "--points",
                            str(pts), "--out", str(tmp_path / "n"), "--quiet", "--no-figures"],
                           capsys)
    assert code == 0, err
    assert [p.name for p in (tmp_path / "n").iterdir()] == ["field.h5"]
    with h5py.File(tmp_path / "n" / "field.h5") as f:
        np.testing.assert_array_equal(f["pressure"][...], pressure)


def test_streamed_points_are_written_while_the_next_chunk_is_computed(files, tmp_path,
                                                                      monkeypatch):
    """Five chunks through the writer thread: field.h5 equals the dense Rayleigh sum;
    a failing write reaches the caller and leaves no file."""
    from holoprobe.cli.field import _stream_points
    from holoprobe.io._results import FieldWriter
    from holoprobe.transducer import TransmitSetting, predict_field

    vt = VirtualTransducer.load(files[0])
    tx = TransmitSetting.from_toml(files[2])
    rng = np.random.default_rng(5)
    pts = np.stack([rng.uniform(-2e-3, 2e-3, 13), rng.uniform(-0.8e-3, 0.8e-3, 13),
                    rng.uniform(2e-3, 9e-3, 13)], axis=-1)
    peak, n = _stream_points(tmp_path / "field.h5", vt, tx, pts, 25e6, lambda d, t: None, {},
                             False, [], chunk=3)
    dense = predict_field(vt, tx, pts, sampling_rate=25e6, time_window="local",
                          n_samples=n, method="rayleigh", dtype=np.float64)
    with h5py.File(tmp_path / "field.h5") as f:
        p, offsets = f["pressure"][...], f["time_offset"][...]
        np.testing.assert_array_equal(f["points"][...], pts)
        np.testing.assert_array_equal(f["peak_positive_pressure"][...], peak)
    scale = np.max(np.abs(dense.pressure))
    assert scale > 1e3 and np.max(np.abs(p - dense.pressure)) / scale < 1e-4
    np.testing.assert_allclose(offsets, dense.time_offset, rtol=0, atol=1e-15)
    calls = []

    def failing(self, start, *args):
        calls.append(start)
        if len(calls) == 2:
            raise OSError("disk full")
        return original(self, start, *args)

    original = FieldWriter.write
    monkeypatch.setattr(FieldWriter, "write", failing)
    with pytest.raises(OSError, match="disk full"):
        _stream_points(tmp_path / "other.h5", vt, tx, pts, 25e6, lambda d, t: None, {},
                       False, [], chunk=3)
    assert calls[:2] == [0, 3] and not (tmp_path / "other.h5").exists()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc mallopt")
@pytest.mark.parametrize("reuse", [False, True])
def test_reuse_freed_memory_keeps_a_freed_large_array_for_the_next_one(reuse):
    """In a fresh interpreter: a freed 100 MB array goes back to the system (its pages
    are zeroed again when the next one touches them) unless the heap keeps it."""
    code = ("import numpy as np, os\n"
            "from holoprobe.cli.field import reuse_freed_memory\n"
            f"assert reuse_freed_memory() if {reuse} else True\n"
            "rss = lambda: int(open('/proc/self/statm').read().split()[1]) "
            "* os.sysconf('SC_PAGE_SIZE')\n"
            "a = np.ones(25_000_000, np.float32); r0 = rss(); del a\n"
            "print((r0 - rss()) / 1e6)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    released = float(done.stdout.split()[-1])  # MB
    assert (released < 10) if reuse else (released > 80), released


def test_rf_cli_writes_the_echo_at_its_depth(files, tmp_path, capsys):
    vt_path, _, tx, scat = files
    out = tmp_path / "rf"
    code, _, err = run_cli(["rf", str(vt_path), "--transmit", str(tx), "--scatterers",
                            str(scat), "--out", str(out), "--quiet"], capsys)
    assert code == 0, err
    assert (out / "rf.png").is_file()
    with h5py.File(out / "rf.h5") as f:
        rf, t = f["rf"][...], f["time"][...]
        assert rf.shape == (16, t.size) and f["rf"].attrs["units"] == "V"
        np.testing.assert_allclose(f["amplitudes"][...], [1e-4, 1e-4])
    # the strongest echo (the scatterer at the focus) arrives near 2 × 6 mm / c0 + pulse
    t_peak = t[np.argmax(np.abs(rf).max(axis=0))]
    assert 2 * 6e-3 / 1481 < t_peak < 2 * 6.2e-3 / 1481 + 2.5e-6


@pytest.mark.parametrize("command, which, needle", [
    ("field", "missing_vt", "nope.h5"),
    ("field", "no_plane", "--plane"),
    ("rf", "no_receive", "receive_impulse_response"),
    ("rf", "missing_scatterers", "--scatterers"),
])
def test_bad_input_exits_2_with_one_line(files, tmp_path, capsys, command, which, needle):
    vt_path, no_rx, tx, scat = files
    vt_arg = {"missing_vt": str(tmp_path / "nope.h5"), "no_receive": str(no_rx)}.get(
        which, str(vt_path))
    args = [command, vt_arg, "--transmit", str(tx), "--out", str(tmp_path / "o"), "--quiet"]
    if command == "field" and which != "no_plane":
        args += ["--plane", "xz", "--extent", "-1", "1", "2", "4"]
    if command == "rf":
        args += ["--scatterers", str(tmp_path / "none.csv") if which == "missing_scatterers"
                 else str(scat)]
    code, _, err = run_cli(args, capsys)
    assert code == 2
    lines = [ln for ln in err.strip().splitlines() if ln]
    assert len(lines) == 1, err
    assert needle in lines[0]


@pytest.mark.parametrize(("band", "rtol"), [(None, 2e-3), (0.3, 1e-5)])
def test_interpolated_peaks_of_a_sampled_pulse_do_not_depend_on_the_sampling_phase(band, rtol):
    """FFT-upsampled peaks (no band) and the band-limited peak search (band 0.3 of Nyquist)."""
    from holoprobe.cli.field import peak_pressures

    t = np.arange(256)
    shifts = 128 + np.linspace(0, 1, 9)[:, None]  # pulse centre between samples
    # 14.4 samples per period (2.5 MHz at 36 MHz), Gaussian envelope: true peak +2
    tones = 2.0 * np.cos(2 * np.pi * (t - shifts) / 14.4) * np.exp(-(((t - shifts) / 20) ** 2))
    fine = np.linspace(0, 256, 256 * 64, endpoint=False)
    dense = 2.0 * np.cos(2 * np.pi * (fine - shifts) / 14.4) * np.exp(
        -(((fine - shifts) / 20) ** 2))
    pos, neg = peak_pressures(tones, band=band)
    np.testing.assert_allclose(pos, 2.0, rtol=rtol)
    np.testing.assert_allclose(neg, -dense.min(axis=1), rtol=rtol)
    assert tones.max(axis=1).min() < 0.98 * 2.0  # the raw samples miss the peak by 2.4 %
