"""Fields on dask (threaded and distributed) and the chunked Zarr store vs in-process.

The reference is one in-process :func:`predict_fields` call on every point; the
dask graph splits points and transmits into chunks computed separately (with the
job's record length and band), so agreement checks the chunking, the block
geometry of volumes and the per-chunk time offsets.
"""

from __future__ import annotations

import numpy as np
import pytest

from _shared import FS, tiny_transducer
from holoprobe.errors import InputError
from holoprobe.transducer import TransmitSetting, burst, field_dataset, predict_fields

pytest.importorskip("dask")
xr = pytest.importorskip("xarray")
pytest.importorskip("zarr")

from holoprobe.io import read_field_zarr, write_field_zarr  # noqa: E402


@pytest.fixture(scope="module")
def case():
    vt = tiny_transducer(n=6)
    drive = burst(2e6, 2, 10.0, sampling_rate=FS)
    txs = [TransmitSetting.focused((0.5e-3, 0.0, 5e-3), drive=drive, name="left"),
           TransmitSetting.focused((-0.5e-3, 0.0, 6e-3), drive=drive, name="right")]
    x = np.linspace(-1.5e-3, 1.5e-3, 7)
    y = np.array([-0.3e-3, 0.4e-3])
    z = np.linspace(2e-3, 7e-3, 11)
    g = np.meshgrid(x, y, z, indexing="ij")
    pts = np.stack([a.ravel() for a in g], axis=-1)  # 154 points
    ref = list(predict_fields(vt, txs, pts, sampling_rate=FS))
    return vt, txs, (x, y, z), pts, ref


def _check(p, off, ref, shape):
    for k, r in enumerate(ref):
        want = r.pressure.reshape(*shape, -1)
        scale = np.max(np.abs(want))
        assert p.shape[1:] == want.shape
        assert np.max(np.abs(p[k] - want)) <= 1e-5 * scale  # float32 rounding
        np.testing.assert_allclose(off[k], r.time_offset.reshape(shape), rtol=0, atol=1e-15)


def test_threaded_volume_and_points_equal_the_in_process_result(case):
    vt, txs, axes, pts, ref = case
    vol = field_dataset(vt, txs, volume=axes, sampling_rate=FS, chunk_bytes=150e3,
                        transmit_chunk=1)
    assert len(vol.pressure.data.chunks[1]) > 1 and vol.pressure.data.chunks[0] == (1, 1)
    assert vol.time.size == ref[0].time.size
    _check(vol.pressure.values, vol.time_offset.values, ref, (7, 2, 11))
    listed = field_dataset(vt, txs, points=pts, sampling_rate=FS, chunk_bytes=100e3)
    assert len(listed.pressure.data.chunks[1]) > 1
    _check(listed.pressure.values, listed.time_offset.values, ref, (154,))
    with pytest.raises(InputError, match="exactly one"):
        field_dataset(vt, txs, sampling_rate=FS)


def test_zarr_store_is_written_chunk_by_chunk_and_reads_with_xarray(case, tmp_path):
    vt, txs, axes, _, ref = case
    ds = field_dataset(vt, txs, volume=axes, sampling_rate=FS, chunk_bytes=50e3)
    chunk_mb = ds.pressure.data.chunksize
    assert np.prod(chunk_mb) * 4 <= 50e3 < ds.pressure.nbytes  # chunks within the budget
    path = write_field_zarr(tmp_path / "field.zarr", ds, num_workers=2)
    store = xr.open_zarr(path)
    assert store.pressure.dims == ("transmit", "x", "y", "z", "time")
    assert store.pressure.attrs["units"] == "Pa" and store.time_offset.attrs["units"] == "s"
    assert all(store[k].attrs["units"] == "m" for k in "xyz")
    assert store.time.attrs["units"] == "s"
    np.testing.assert_array_equal(store.x.values, axes[0])
    np.testing.assert_allclose(np.diff(store.time.values), 1 / FS, rtol=1e-9)
    assert store.pressure.encoding["chunks"] == chunk_mb  # one zarr chunk per dask chunk
    _check(store.pressure.values, store.time_offset.values, ref, (7, 2, 11))
    back = read_field_zarr(path)
    assert back.attrs["transmit_names"] == ["left", "right"]
    with pytest.raises(InputError, match="already exists"):
        write_field_zarr(path, ds)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporaries


def test_distributed_local_cluster_gives_the_same_store(case, tmp_path):
    distributed = pytest.importorskip("distributed")
    vt, txs, _, pts, ref = case
    ds = field_dataset(vt, txs, points=pts, sampling_rate=FS, chunk_bytes=400e3)
    assert len(ds.pressure.data.chunks[1]) == 3
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                                  dashboard_address=None) as cluster:
        path = write_field_zarr(tmp_path / "field.zarr", ds, scheduler=cluster.scheduler_address)
    store = read_field_zarr(path)
    assert store.pressure.dims == ("transmit", "point", "time")
    _check(store.pressure.values, store.time_offset.values, ref, (154,))
    np.testing.assert_array_equal(store.point_z.values, pts[:, 2])


def test_field_cli_sequence_volume_writes_field_zarr(case, tmp_path, capsys):
    from _shared import run_cli

    vt, _, _, _, _ = case
    vt_path = vt.save(tmp_path / "vt.h5")
    seq = tmp_path / "seq.toml"
    seq.write_text('format = "holoprobe-transmit-sequence"\nprf = 4000.0\n'
                   '[sweep]\nkind = "focused"\ndepth = 0.005\n'
                   'x = {start = -0.0005, stop = 0.0005, count = 2}\n'
                   '[common.drive]\nkind = "burst"\nfrequency = 2e6\ncycles = 2\n'
                   'amplitude = 10.0\n')
    code, _, err = run_cli(["field", str(vt_path), "--sequence", str(seq), "--volume", "-1",
                            "1", "0.2", "0.2", "3", "6", "--step", "0.5", "--sampling-rate",
                            "100", "--chunk-mb", "0.1", "--out", str(tmp_path / "o"),
                            "--quiet"], capsys)
    assert code == 0, err
    store = read_field_zarr(tmp_path / "o" / "field.zarr")
    assert store.pressure.shape[:4] == (2, 5, 1, 7)
    from holoprobe.transducer import TransmitSequence

    g = np.meshgrid(store.x.values, store.y.values, store.z.values, indexing="ij")
    pts = np.stack([a.ravel() for a in g], axis=-1)
    ref = list(predict_fields(vt, TransmitSequence.from_file(seq).settings, pts,
                              sampling_rate=FS, n_samples=store.time.size))
    _check(store.pressure.values, store.time_offset.values, ref, (5, 1, 7))


def test_output_sequence_on_a_cluster_from_dask_config_equals_in_process(tmp_path, capsys):
    """``holoprobe output --sequence`` with a scheduler (here dask's config key
    ``scheduler-address``, what ``--scheduler`` sets too) runs the fields on the cluster
    and gives the in-process JSON to float32 rounding."""
    import json

    import dask

    distributed = pytest.importorskip("distributed")
    from _shared import run_cli
    from holoprobe.io import scheduler_address
    from holoprobe.transducer import VirtualTransducer

    vt_path = VirtualTransducer.from_preset("p4-1").replace(element_count=6).save(
        tmp_path / "vt.h5")
    seq = tmp_path / "seq.toml"
    seq.write_text('format = "holoprobe-transmit-sequence"\nprf = 2000.0\n[sweep]\n'
                   'kind = "focused"\ndepth = 0.012\nx = [-0.001, 0.001]\n[common.drive]\n'
                   'kind = "burst"\nfrequency = 2.5e6\ncycles = 2\namplitude = 10.0\n')
    args = ["output", str(vt_path), "--sequence", str(seq), "--depth-mm", "8", "14",
            "--lateral-mm", "2", "--plane-step-mm", "1"]
    assert run_cli([*args, "--out", str(tmp_path / "a.json")], capsys)[0] == 0
    with distributed.LocalCluster(n_workers=1, processes=False, threads_per_worker=2,
                                  dashboard_address=None) as cluster, \
            dask.config.set({"scheduler-address": cluster.scheduler_address}):
        assert scheduler_address(None) == cluster.scheduler_address
        code, out, err = run_cli([*args, "--out", str(tmp_path / "b.json")], capsys)
        assert code == 0, out + err
        assert cluster.scheduler.task_prefixes  # the cluster computed the fields
    a, b = (json.loads((tmp_path / f"{k}.json").read_text()) for k in "ab")
    for key in ("mechanical_index", "isppa", "ispta"):
        assert b["worst_case"][key] == pytest.approx(a["worst_case"][key], rel=1e-5)
    assert b["worst_case"]["ispta_position"] == a["worst_case"]["ispta_position"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporaries
