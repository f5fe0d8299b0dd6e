"""``holoprobe field``: pressure field of the virtual transducer for a transmit setting.

A thin shell over :func:`holoprobe.transducer.predict_field` (element
superposition, per-point time windows, float32); ``--points`` goes through
:class:`holoprobe.transducer.FieldStream` chunk by chunk into ``field.h5``
(:func:`holoprobe.io.field_writer`), so memory stays bounded for 10⁶ points. Lengths are
in mm at this boundary (``--extent``, ``--step``, ``--depth``, the points CSV), SI inside and in
``field.h5``.

``field.h5`` (written atomically) holds ``pressure`` (Pa, float32; (nx, nz, nt)
for a plane, (n_points, nt) for points), ``time`` (nt,) s and ``time_offset`` (same
shape as the grid) s — sample n of a point is at ``time_offset + time[n]`` —,
``points`` (…, 3) m, the plane's axes (``axis_0``, ``axis_1``, m), and attributes:
units, plane, the transmit setting (its TOML text) and the input files.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

from holoprobe.cli._app import OutputDirectory, VirtualTransducerPath

__all__ = ["field", "peak_pressures", "read_points_csv", "reuse_freed_memory"]

_PLANES = {"xz": (0, 2), "yz": (1, 2), "xy": (0, 1)}


def read_points_csv(path: Path, *, columns: int = 3, name: str = "--points") -> np.ndarray:
    """Rows of ``columns`` numbers from a CSV file ('#' comments, an optional header)."""
    from holoprobe.errors import InputError

    if not path.is_file():
        raise InputError("no such file", file=str(path), field=name)
    if columns == 3:  # fast path (10⁶ points in < 1 s); anything unusual: the checks below
        try:
            fast = np.loadtxt(path, delimiter=",", comments="#", ndmin=2, dtype=float)
        except ValueError:
            fast = None
        if fast is not None and fast.shape[0] and fast.shape[1] == 3 and np.all(
                np.isfinite(fast)):
            return fast
    rows: list[list[float]] = []
    for k, line in enumerate(path.read_text(encoding="utf-8").splitlines()):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        parts = [p.strip() for p in text.replace(";", ",").split(",")]
        try:
            values = [float(p) for p in parts]
        except ValueError:
            if not rows and k == 0:
                continue  # a header line
            raise InputError(f"line {k + 1}: expected numbers, got {line!r}", file=str(path),
                             field=name) from None
        if len(values) < 3 or len(values) > columns or not all(map(math.isfinite, values)):
            raise InputError(f"line {k + 1}: expected 3 to {columns} finite numbers",
                             file=str(path), field=name)
        rows.append(values + [math.nan] * (columns - len(values)))
    if not rows:
        raise InputError("no points in the file", file=str(path), field=name)
    return np.asarray(rows, dtype=float)


def peak_pressures(pressure: np.ndarray, *, band: float | None = None, upsample: int = 4,
                   chunk: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """Peak compressional and rarefactional pressure of band-limited periodic records.

    The peaks of the band-limited interpolant, so that they do not depend on where the
    samples fall (sampled peaks of a 2.5 MHz pulse at 36 MHz vary by up to 2.4 %): with
    ``band`` (the top of the signal band as a fraction of the Nyquist frequency, ≤ 0.5)
    refined around the sampled extremes (:func:`holoprobe.signal.band_limited_peaks`,
    ≲ 1e-6); otherwise the maximum of each record interpolated ``upsample`` times by
    zero-padding its spectrum (exact for a band-limited record that holds its whole
    pulse, up to the 1/upsample grid: ≲ 0.5 %).
    """
    from holoprobe.signal import PEAK_MAX_BAND, band_limited_peaks

    n = pressure.shape[-1]
    if band is not None and band <= PEAK_MAX_BAND and n >= 16:
        return band_limited_peaks(pressure, band)
    from scipy import fft

    flat = pressure.reshape(-1, n)
    pos = np.empty(flat.shape[0])
    neg = np.empty(flat.shape[0])
    for s0 in range(0, flat.shape[0], chunk):
        up = fft.irfft(fft.rfft(flat[s0:s0 + chunk], axis=-1), n * upsample, axis=-1)
        up *= upsample
        pos[s0:s0 + chunk] = up.max(axis=-1)
        neg[s0:s0 + chunk] = -up.min(axis=-1)
    return pos.reshape(pressure.shape[:-1]), neg.reshape(pressure.shape[:-1])


def lattice_axis(lo: float, hi: float, step: float, anchor: float) -> np.ndarray:
    """Grid lo..hi with ``step`` through ``anchor`` (so offsets to the elements repeat)."""
    k0 = math.ceil((lo - anchor) / step - 1e-9)
    k1 = math.floor((hi - anchor) / step + 1e-9)
    return anchor + np.arange(k0, k1 + 1) * step


def field(
    virtual_transducer: VirtualTransducerPath,
    out: OutputDirectory,
    transmit: Annotated[Path | None, typer.Option(
        "--transmit", help="Transmit setting (TOML).")] = None,
    sequence: Annotated[Path | None, typer.Option(
        "--sequence", help="Transmit sequence (TOML, docs/formats.md) instead of --transmit: "
                           "field.zarr with every transmit.")] = None,
    volume: Annotated[tuple[float, float, float, float, float, float] | None, typer.Option(
        "--volume", help="x0 x1 y0 y1 z0 z1 in mm: a 3-D grid at --step (field.zarr).")
    ] = None,
    zarr: Annotated[bool, typer.Option(
        "--zarr", help="Write field.zarr (chunked, on dask) instead of field.h5.")] = False,
    scheduler: Annotated[str | None, typer.Option(
        "--scheduler", help="Address of a running dask.distributed scheduler (default: "
                            "dask's config key scheduler-address / DASK_SCHEDULER_ADDRESS "
                            "for field.zarr, else dask's local threaded scheduler).")] = None,
    chunk_mb: Annotated[float, typer.Option(
        "--chunk-mb", help="Largest chunk of the Zarr output in MB.")] = 64.0,
    plane: Annotated[str | None, typer.Option(
        "--plane", help="xz (lateral), yz (elevation) or xy (at --depth).")] = None,
    extent: Annotated[tuple[float, float, float, float] | None, typer.Option(
        "--extent", help="a0 a1 b0 b1 in mm along the plane's two axes (xz: x0 x1 z0 z1).")
    ] = None,
    step: Annotated[float | None, typer.Option(
        "--step", help="Grid step in mm (default λ/2 at the band centre; on x rounded down "
                       "to pitch/m).")] = None,
    depth: Annotated[float | None, typer.Option(
        "--depth", help="z of an xy plane, or x (yz) / y (xz) of the plane, in mm.")] = None,
    points: Annotated[Path | None, typer.Option(
        "--points", help="CSV of target points x,y,z in mm (instead of --plane).")] = None,
    sampling_rate: Annotated[float | None, typer.Option(
        "--sampling-rate", help="Output sampling rate in MHz (default 8 × band top).")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bar.")] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace existing outputs.")] = False,
    figures: Annotated[bool, typer.Option(
        "--figures/--no-figures", help="Write the PNG figures (peak map, on-axis profile, "
                                       "waveform); --no-figures writes field.h5 only and "
                                       "skips the profile's and the waveform's predictions "
                                       "and matplotlib (≈ 2 s of CPU).")] = True,
) -> None:
    """Pressure time series on a plane or points, peak-pressure maps and profiles (PNG).

    With ``--volume``, ``--sequence``, ``--zarr`` or ``--scheduler`` the field is computed
    chunk by chunk on dask and streamed to ``field.zarr`` (no figures).
    """
    if (transmit is None) == (sequence is None):
        from holoprobe.errors import InputError

        raise InputError("give either --transmit or --sequence", field="--transmit")
    if volume is not None or sequence is not None or zarr or scheduler is not None:
        _field_zarr(virtual_transducer, transmit, sequence, out, volume, points, plane, step,
                    sampling_rate, scheduler, chunk_mb, quiet, overwrite)
        return
    assert transmit is not None
    from holoprobe._progress import progress_task
    from holoprobe.errors import InputError
    from holoprobe.transducer import (
        TransmitSetting,
        VirtualTransducer,
        predict_field,
        signal_band,
    )

    if (plane is None) == (points is None):
        raise InputError("give either --plane with --extent, or --points", field="--plane")
    vt = VirtualTransducer.load(virtual_transducer)
    setting = TransmitSetting.from_toml(transmit)
    f_lo, f_hi = signal_band(vt, setting)
    fs = 8.0 * f_hi if sampling_rate is None else sampling_rate * 1e6
    axes: tuple[np.ndarray, np.ndarray] | None = None
    provenance = {"virtual_transducer": str(virtual_transducer),
                  "transmit_file": str(transmit),
                  "transmit_setting_toml": Path(transmit).read_text(encoding="utf-8")}
    protect = [virtual_transducer, transmit]
    with progress_task(1.0, description="field", enabled=False if quiet else None) as advance:
        state = {"done": 0.0}

        def report(done: int, total: int) -> None:
            frac = done / max(total, 1)
            advance(max(0.0, frac - state["done"]))
            state["done"] = frac

        if plane is not None:
            pts, axes = _plane_points(vt, plane, extent, step, depth, (f_lo, f_hi))
            targets = pts.reshape(-1, 3)
            pred = predict_field(vt, setting, targets, sampling_rate=fs, time_window="local",
                                 dtype=np.float32, progress=report)
            peak, _ = peak_pressures(pred.pressure, band=2 * pred.frequency_band[1] / fs)
            n_samples = pred.time.size
            _write_field_h5(out / "field.h5", pred, peak, pts.shape[:-1], axes, plane,
                            provenance, overwrite, protect)
        else:
            assert points is not None
            targets = read_points_csv(points) * 1e-3
            if np.any(targets[:, 2] <= 0):
                raise InputError("points must lie in front of the probe (z > 0 mm)",
                                 file=str(points), field="--points")
            if targets.shape[0] > STREAM_CHUNK:
                reuse_freed_memory()
            peak, n_samples = _stream_points(out / "field.h5", vt, setting, targets, fs,
                                             report, provenance, overwrite, protect)
            pts = targets
    i_max = int(np.argmax(peak))
    if figures:
        _figures(out, plane, axes, peak.reshape(pts.shape[:-1]), targets, i_max, vt, setting,
                 fs, overwrite, protect=protect)
    if not quiet:
        typer.echo(f"field: {targets.shape[0]} points × {n_samples} samples at "
                   f"{fs / 1e6:.3g} MHz; peak {peak[i_max] / 1e6:.3g} MPa at "
                   f"({', '.join(f'{v * 1e3:.2f}' for v in targets[i_max])}) mm -> {out}")


def reuse_freed_memory() -> bool:
    """Take large arrays from the heap and keep freed memory for reuse (glibc ``mallopt``).

    A streamed job allocates the same ~131 MB arrays per chunk; from fresh ``mmap`` pages
    (glibc's default above 32 MB) the kernel zeroes every page on first touch: 5–10 % of
    the CPU of 200 000 points (13.9 → 12.5–13.2 s, load 17). For the whole process, so
    only for jobs of several chunks; False (nothing done) where glibc is not found.
    """
    import ctypes

    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):
        return False
    m_trim_threshold, m_mmap_max = -1, -4
    return bool(mallopt(m_mmap_max, 0)) and bool(mallopt(m_trim_threshold, 2**31 - 1))


#: points per chunk of a streamed ``--points`` job
STREAM_CHUNK = 1 << 16


def _stream_points(path: Path, vt: Any, setting: Any, targets: np.ndarray, fs: float,
                   report: Any, provenance: dict[str, str], overwrite: bool,
                   protect: list[Path], chunk: int = STREAM_CHUNK) -> tuple[np.ndarray, int]:
    """Predict the field at ``targets`` chunk by chunk into ``path`` (bounded memory);
    return the peak positive pressure per point and the record length."""
    from concurrent.futures import Future

    from holoprobe.io import field_writer
    from holoprobe.signal import Threads
    from holoprobe.transducer import FieldStream

    stream = FieldStream(vt, setting, targets, sampling_rate=fs, dtype=np.float32,
                         chunk=chunk)
    peak = np.empty(targets.shape[0])
    methods: list[str] = []
    # each chunk is written by a second thread while the next one is computed (h5py
    # releases the GIL in its writes, the kernels release it too); one write in flight
    with field_writer(path, (targets.shape[0],), stream.time, sampling_rate=fs,
                      frequency_band=stream.frequency_band, provenance=provenance,
                      overwrite=overwrite, protect=protect) as writer, \
            Threads(1, name="holoprobe-writer") as pool:
        pending: Future | None = None
        for s0, pred in stream.run(report):
            pk, _ = peak_pressures(pred.pressure, band=2 * stream.frequency_band[1] / fs)
            peak[s0:s0 + pk.size] = pk
            if pending is not None:
                pending.result()
            pending = pool.submit(writer.write, s0, pred.pressure, pred.time_offset,
                                  pred.points, pk)
            methods += [m for m in pred.method.split("+") if m not in methods]
        if pending is not None:
            pending.result()
        writer.method = "+".join(methods)
    return peak, stream.time.size


def _plane_points(vt: Any, plane: str, extent: tuple[float, float, float, float] | None,
                  step: float | None, depth: float | None, band: tuple[float, float]
                  ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """The points (na, nb, 3) in m of ``--plane`` over ``--extent`` (mm) and its two
    axes; x on the element lattice (pitch/m), the other axes through the aperture
    centre (y) or the face (z), at ``--step`` (default λ/2 at the band centre)."""
    from holoprobe.errors import InputError

    if plane not in _PLANES:
        raise InputError(f"expected one of {sorted(_PLANES)}, got {plane!r}",
                         field="--plane")
    if extent is None:
        raise InputError("required with --plane", field="--extent")
    a0, a1, b0, b1 = (v * 1e-3 for v in extent)
    if not (a1 > a0 and b1 > b0):
        raise InputError(f"expected a0 < a1 and b0 < b1, got {extent}", field="--extent")
    xc, yc = vt.aperture_center
    lam2 = vt.medium.sound_speed / (0.5 * (band[0] + band[1])) / 2
    h = lam2 if step is None else step * 1e-3
    if not (math.isfinite(h) and h > 0):
        raise InputError(f"expected a positive step in mm, got {step!r}", field="--step")
    ia, ib = _PLANES[plane]
    x0 = vt.element_centers()[0, 0]
    hx = vt.pitch / math.ceil(vt.pitch / h - 1e-9)
    first = lattice_axis(a0, a1, hx, x0) if ia == 0 else lattice_axis(a0, a1, h, yc)
    second = lattice_axis(b0, b1, h, 0.0) if ib == 2 else lattice_axis(b0, b1, h, yc)
    if first.size < 2 or second.size < 2:
        raise InputError("the extent holds fewer than 2 × 2 grid points", field="--extent")
    if plane == "xy" and depth is None:
        raise InputError("required with --plane xy (z of the plane, mm)", field="--depth")
    fixed = {"xz": yc, "yz": xc, "xy": 0.0}[plane] if depth is None else depth * 1e-3
    g0, g1 = np.meshgrid(first, second, indexing="ij")
    pts = np.empty((*g0.shape, 3))
    pts[..., 3 - ia - ib] = fixed
    pts[..., ia], pts[..., ib] = g0, g1
    if np.any(pts[..., 2] <= 0):
        raise InputError("the plane must lie in front of the probe (z > 0)",
                         field="--extent")
    return pts, (first, second)


def _field_zarr(vt_path: Path, transmit: Path | None, sequence: Path | None, out: Path,
                volume, points: Path | None, plane: str | None, step: float | None,
                sampling_rate: float | None, scheduler: str | None, chunk_mb: float,
                quiet: bool, overwrite: bool) -> None:
    """Volume or points, one transmit or a sequence, on dask -> ``out/field.zarr``."""
    from holoprobe.errors import InputError
    from holoprobe.io import scheduler_address, write_field_zarr
    from holoprobe.transducer import (
        TransmitSequence,
        TransmitSetting,
        VirtualTransducer,
        field_dataset,
        union_band,
    )

    if plane is not None or (volume is None) == (points is None):
        raise InputError("with field.zarr give either --volume or --points", field="--volume")
    vt = VirtualTransducer.load(vt_path)
    source = sequence if sequence is not None else transmit
    assert source is not None
    settings = (TransmitSequence.from_file(source).settings if sequence is not None
                else (TransmitSetting.from_toml(source),))
    kw: dict[str, Any] = {"sampling_rate": None if sampling_rate is None else sampling_rate * 1e6,
          "chunk_bytes": chunk_mb * 1e6,
          "attrs": {"virtual_transducer": str(vt_path), "transmit_file": str(source)}}
    if volume is not None:
        lo, hi = np.asarray(volume[::2]) * 1e-3, np.asarray(volume[1::2]) * 1e-3
        if not np.all(hi >= lo):
            raise InputError(f"expected x0 <= x1, y0 <= y1, z0 <= z1, got {volume}",
                             field="--volume")
        f_lo, f_hi = union_band(vt, settings)
        h = (vt.medium.sound_speed / (0.5 * (f_lo + f_hi)) / 2 if step is None
             else step * 1e-3)
        if not (math.isfinite(h) and h > 0):
            raise InputError(f"expected a positive step in mm, got {step!r}", field="--step")
        axes = tuple(a + np.arange(math.floor((b - a) / h + 1e-9) + 1) * h
                     for a, b in zip(lo, hi, strict=True))
        ds = field_dataset(vt, settings, volume=axes, **kw)
    else:
        assert points is not None
        ds = field_dataset(vt, settings, points=read_points_csv(points) * 1e-3, **kw)
    out.mkdir(parents=True, exist_ok=True)
    path = write_field_zarr(out / "field.zarr", ds, scheduler=scheduler_address(scheduler),
                            progress=False if quiet else None, overwrite=overwrite,
                            protect=[vt_path, source])
    if not quiet:
        dims = " × ".join(f"{k} {v}" for k, v in ds.pressure.sizes.items())
        typer.echo(f"field: {dims} ({ds.pressure.nbytes / 1e9:.3g} GB float32, "
                   f"{ds.attrs['sampling_rate'] / 1e6:.3g} MHz) -> {path}")


def _write_field_h5(path, pred, peak, shape, axes, plane, provenance, overwrite, protect):
    from holoprobe.io import write_field

    write_field(path, pred.pressure, pred.time, pred.time_offset, pred.points,
                peak.reshape(shape), sampling_rate=pred.sampling_rate,
                frequency_band=pred.frequency_band, method=pred.method, plane=plane,
                axes=axes, provenance=provenance, overwrite=overwrite, protect=protect)


def _save(fig, path: Path, overwrite: bool, protect) -> None:
    from holoprobe._png import png_bytes
    from holoprobe.io import atomic_write

    data = png_bytes(fig, 120)  # one draw (savefig draws a laid-out figure twice)
    with atomic_write(path, overwrite=overwrite, protect=protect) as tmp:
        Path(tmp).write_bytes(data)


def _figures(out, plane, axes, peak, targets, i_max, vt, setting, fs, overwrite, protect):
    """The peak map of a plane, the on-axis profile and the waveform at the focus (or at
    the largest peak), each predicted here (float32) and written as a PNG."""
    from matplotlib.figure import Figure

    from holoprobe.transducer import predict_field

    xc, yc = vt.aperture_center
    z_max = float(targets[:, 2].max())
    z_min = max(float(targets[:, 2].min()), 0.5e-3)
    axis_z = np.linspace(z_min, z_max, max(2, math.ceil((z_max - z_min) / 0.25e-3) + 1))
    on_axis = np.stack([np.full_like(axis_z, xc), np.full_like(axis_z, yc), axis_z], axis=-1)
    profile = predict_field(vt, setting, on_axis, sampling_rate=fs, time_window="local",
                            dtype=np.float32)
    if (setting.delays.kind == "focused" and setting.delays.point is not None
            and setting.delays.point[2] > 0):
        focus = np.array(setting.delays.point, dtype=float)
        label = "focus"
    else:
        focus, label = targets[i_max], "maximum"
    wave = predict_field(vt, setting, focus[None, :], sampling_rate=fs, time_window="local",
                         dtype=np.float32)  # the float32 kernels the other predictions use

    if axes is not None:
        fig = Figure(figsize=(6.4, 5.2), layout="constrained")
        ax = fig.add_subplot()
        a, b = axes
        names = {"xz": ("x (mm)", "z (mm)"), "yz": ("y (mm)", "z (mm)"),
                 "xy": ("x (mm)", "y (mm)")}[plane]
        im = ax.imshow(peak.T / 1e6, origin="lower" if plane == "xy" else "upper",
                       extent=[a[0] * 1e3, a[-1] * 1e3,
                               *((b[0] * 1e3, b[-1] * 1e3) if plane == "xy"
                                 else (b[-1] * 1e3, b[0] * 1e3))],
                       aspect="equal", cmap="inferno")
        ax.set_xlabel(names[0])
        ax.set_ylabel(names[1])
        what = {"xz": "lateral (xz)", "yz": "elevation (yz)", "xy": "transverse (xy)"}[plane]
        ax.set_title(f"peak compressional pressure, {what} plane")
        fig.colorbar(im, ax=ax, label="peak pressure (MPa)")
        _save(fig, out / f"peak_pressure_{plane}.png", overwrite, protect)
    fig = Figure(figsize=(6.4, 4.0), layout="constrained")
    ax = fig.add_subplot()
    z = profile.points[:, 2] * 1e3
    pos, neg = peak_pressures(profile.pressure,
                              band=2 * profile.frequency_band[1] / profile.sampling_rate)
    ax.plot(z, pos / 1e6, label="compressional")
    ax.plot(z, neg / 1e6, label="rarefactional")
    ax.set_xlabel("z (mm)")
    ax.set_ylabel("peak pressure (MPa)")
    ax.set_title("on-axis peak pressure")
    ax.legend()
    ax.grid(alpha=0.3)
    _save(fig, out / "on_axis_profile.png", overwrite, protect)
    fig = Figure(figsize=(6.4, 4.0), layout="constrained")
    ax = fig.add_subplot()
    ax.plot((wave.time_offset[0] + wave.time) * 1e6, wave.pressure[0] / 1e6)
    ax.set_xlabel("time (µs)")
    ax.set_ylabel("pressure (MPa)")
    ax.set_title(f"waveform at the {label} ({', '.join(f'{v * 1e3:.1f}' for v in focus)}) mm")
    ax.grid(alpha=0.3)
    _save(fig, out / "waveform.png", overwrite, protect)
