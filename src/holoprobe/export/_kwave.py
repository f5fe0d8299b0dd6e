"""Equivalent sources and sensors of a virtual transducer for k-wave-python.

k-wave-python is an optional extra (``pip install holoprobe[kwave]``) and is imported
lazily, only inside :func:`kwave_source`, :func:`kwave_sensor` and
:func:`kwave_element_pressure`; everything else here is NumPy. Offline use (its import
downloads native binaries) is described in ``docs/kwave.md``
(:func:`prepare_kwave_offline`).

Axes: k-Wave's x is the propagation direction, y lateral, z elevation (as in
PROTEUS, :func:`holoprobe.export.to_proteus_axes`); the array face lies in the plane
``x = source_x`` of the k-Wave grid, its aperture centre at y = z = 0. A convex face
(``VirtualTransducer.array``) has its apex plane there and curves back towards −x:
each element (strip) is its tangent rectangle turned about the elevation axis by the
azimuth angle of its normal; the default ``source_x`` keeps the whole arc inside.

Each element is cut into ``n_strips`` strips along the elevation, each strip a
rectangle w × H/n_strips that carries the element's signal delayed by its transmit
delay and by the lens delay of the strip centre (paper eq. lens-delays). The strips
are placed off-grid as ``kWaveArray`` rectangles (band-limited interpolation onto the
grid), so elements need not sit on grid points.

Equivalent sources (paper section II C): a **monopole** source drives the pressure,
``source.p = ρ0 c0 u``; a **dipole** source drives the normal particle velocity,
``source.ux = p / (ρ0 c0) = u``, with u(t) = (h_T ⊛ E_T)(t) / (ρ0 c0) the surface
velocity (paper eq. transmit-impulse-response).
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import Medium

__all__ = [
    "KWAVE_TIME_OFFSET",
    "KwavePlaneField",
    "kwave_element_pressure",
    "kwave_element_strips",
    "kwave_grid_mask",
    "kwave_grid_source",
    "kwave_plane_field",
    "kwave_sensor",
    "kwave_source",
    "kwave_source_signals",
    "prepare_kwave_offline",
]

_REPRESENTATIONS = ("monopole", "dipole")


def _check_vt(vt: Any) -> None:
    from holoprobe.transducer import VirtualTransducer

    if not isinstance(vt, VirtualTransducer):
        raise InputError("expected a holoprobe.transducer.VirtualTransducer", field="vt")


def kwave_element_strips(vt: Any, n_strips: int, *, medium: Medium | None = None
                         ) -> dict[str, NDArray]:
    """Element strips of the array face: centres, sizes, lens delays.

    Parameters
    ----------
    vt : VirtualTransducer
        The model.
    n_strips : int
        Strips per element along the elevation (≥ 1).
    medium : Medium, optional
        c0 of the lens delays (default ``vt.medium``).

    Returns
    -------
    dict
        ``"centers"`` (N·n_strips, 3) in m, holoprobe axes (element-major order:
        strip k of element i is row ``i·n_strips + k``); ``"element"`` (N·n_strips,)
        element index; ``"lens_delay"`` (N·n_strips,) in s; ``"width"`` (w) and
        ``"height"`` (H / n_strips) in m, as 0-d arrays; ``"angle"`` (N·n_strips,)
        azimuth angle in rad of the strip's normal (0 on a flat face; on a convex face
        each strip is the element's tangent rectangle, turned about the elevation axis).
    """
    from holoprobe.lens import lens_delays

    _check_vt(vt)
    n = int(n_strips)
    if n < 1:
        raise InputError(f"expected at least one strip, got {n_strips!r}", field="n_strips")
    c0 = (medium or vt.medium).sound_speed
    h = vt.element_height
    v = (np.arange(n) + 0.5) / n * h - h / 2
    tau = (lens_delays(v, vt.lens_focus, h, c0) if math.isfinite(vt.lens_focus)
           else np.zeros(n))
    el = vt.element_centers()
    centers = np.repeat(el, n, axis=0)
    centers[:, 1] += np.tile(v, vt.element_count)
    return {"centers": centers, "element": np.repeat(np.arange(vt.element_count), n),
            "lens_delay": np.tile(tau, vt.element_count), "width": np.array(vt.element_width),
            "height": np.array(h / n), "angle": np.repeat(_element_angles(vt), n)}


def _element_angles(vt: Any) -> NDArray[np.float64]:
    """Azimuth angle (rad) of each element's normal; zeros for a flat face."""
    if vt.array is None:
        return np.zeros(vt.element_count)
    return np.asarray(vt.array.element_angles, dtype=float)


def _face_depth(vt: Any) -> float:
    """How far (m) the face reaches behind the plane z = 0 (the apex plane of a convex
    array: its outer element edges); 0 for a flat face."""
    if not vt.is_curved:
        return 0.0
    from holoprobe.transducer import element_profile

    c, u, _, nrm = vt.element_frames()
    hw = 0.5 * vt.element_width
    along, depth = element_profile(vt, np.array([-hw, hw]))
    z = (c[:, None, 2] + along[None, :] * u[:, None, 2] + depth[None, :] * nrm[:, None, 2])
    return max(0.0, -float(z.min()))


def kwave_source_signals(vt: Any, setting: Any, dt: float, nt: int, *, n_strips: int = 1,
                         representation: str = "monopole", medium: Medium | None = None
                         ) -> NDArray[np.float64]:
    """Source signals of the element strips on k-Wave's time axis ``t = n·dt``.

    Strip k of element i carries ``a_i · s(t − τ_i − τ_lens,k)`` with a_i the
    apodization, τ_i the transmit delay, τ_lens the lens delay of the strip centre and
    ``s = ρ0 c0 u`` (monopole, Pa) or ``s = u`` (dipole, m/s), u the surface velocity
    ``(h_T ⊛ E_T)/(ρ0 c0)_vt``. Delays are applied exactly in the frequency domain
    (band-limited fractional delays) on a record long enough not to wrap.

    Parameters
    ----------
    vt, setting : VirtualTransducer, TransmitSetting
        Model and transmit.
    dt : float
        k-Wave time step in s.
    nt : int
        Number of time steps.
    n_strips : int
        Strips per element (see :func:`kwave_element_strips`).
    representation : {"monopole", "dipole"}
        Pressure (``source.p``) or normal velocity (``source.ux``) signals.
    medium : Medium, optional
        ρ0, c0 of the k-Wave medium (default ``vt.medium``).

    Returns
    -------
    ndarray, shape (N·n_strips, nt)
        Signals in Pa (monopole) or m/s (dipole), rows in strip order.
    """
    from holoprobe.signal import next_fast_length, to_time
    from holoprobe.transducer import drive_spectrum

    _check_vt(vt)
    if representation not in _REPRESENTATIONS:
        raise InputError(f"expected one of {_REPRESENTATIONS}, got {representation!r}",
                         field="representation")
    dt = float(dt)
    if not (math.isfinite(dt) and dt > 0):
        raise InputError(f"expected a positive time step in s, got {dt!r}", field="dt")
    nt = int(nt)
    if nt < 2:
        raise InputError("expected at least 2 time steps", field="nt")
    med = medium or vt.medium
    strips = kwave_element_strips(vt, n_strips, medium=med)
    tau_el = setting.element_delays(vt.element_centers(), med.sound_speed)
    apod = setting.element_weights(vt.element_count)
    tau = tau_el[strips["element"]] + strips["lens_delay"]
    tail = (vt.transmit_impulse_response.size / vt.transmit_sampling_rate
            + setting.drive.duration + float(tau.max()))
    n = next_fast_length(nt + math.ceil(tail / dt) + 1)
    f = np.fft.rfftfreq(n, dt)
    u = drive_spectrum(vt, setting, f)  # m/s·s, continuous spectrum
    if representation == "monopole":
        u = u * med.impedance
    spec = (apod[strips["element"]][:, None] * u[None, :]
            * np.exp(2j * np.pi * tau[:, None] * f[None, :]))
    return to_time(spec / dt, n, axis=-1)[:, :nt]


def _grid_vec(n: int, d: float) -> NDArray[np.float64]:
    """k-Wave grid coordinates: (i − ⌊n/2⌋)·d."""
    return (np.arange(n, dtype=np.float64) - n // 2) * d


def kwave_grid_mask(vt: Any, shape: tuple[int, int, int], spacing: tuple[float, float, float],
                    *, source_x: float | None = None) -> tuple[NDArray[np.bool_], NDArray]:
    """On-grid (staircase) mask of the array face on a k-Wave grid, with element labels.

    Parameters
    ----------
    vt : VirtualTransducer
        The model.
    shape : (Nx, Ny, Nz)
        Grid size (k-Wave axes: x propagation, y lateral, z elevation).
    spacing : (dx, dy, dz)
        Grid steps in m.
    source_x : float, optional
        x of the array face in k-Wave coordinates (m); default the grid plane with
        index 1 (one step inside the domain).

    Returns
    -------
    mask : ndarray of bool, shape (Nx, Ny, Nz)
        Grid points whose (y, z) fall inside an element (y within w/2 of the element
        centre's x, z within H/2 of its y: any layout of rectangles on the face, e.g. a
        2-D matrix array) in the plane nearest to ``source_x``.
    element : ndarray of int, shape (mask.sum(),)
        The element index of each masked point, in C order of the mask (the row
        order of ``source.p`` in k-wave-python ≥ 0.6.1).
    """
    _check_vt(vt)
    try:
        nx, ny, nz = (int(v) for v in shape)
        dx, dy, dz = (float(v) for v in spacing)
    except (TypeError, ValueError):
        raise InputError("expected shape (Nx, Ny, Nz) and spacing (dx, dy, dz)",
                         field="shape") from None
    x = _grid_vec(nx, dx)
    if vt.is_curved:
        return _curved_grid_mask(vt, (nx, ny, nz), (dx, dy, dz), source_x)
    ix = 1 if source_x is None else int(np.argmin(np.abs(x - float(source_x))))
    y = _grid_vec(ny, dy)
    z = _grid_vec(nz, dz)
    # element rectangles on the (y, z) plane: model x → k-Wave y, model y → k-Wave z
    centers = vt.element_centers()[:, :2] - np.asarray(vt.aperture_center)
    half_w, half_h = 0.5 * vt.element_width, 0.5 * vt.element_height
    tol = 1e-9 * max(dy, dz)
    dist_y = np.abs(y[:, None] - centers[None, :, 0])          # (Ny, N)
    dist_z = np.abs(z[:, None] - centers[None, :, 1])          # (Nz, N)
    inside = (dist_y <= half_w + tol)[:, None, :] & (dist_z <= half_h + tol)[None, :, :]
    plane = inside.any(axis=-1)
    # the nearest element centre among those whose rectangle holds the point
    score = np.where(inside, dist_y[:, None, :] + dist_z[None, :, :], np.inf)
    label = np.argmin(score, axis=-1)
    mask = np.zeros((nx, ny, nz), dtype=bool)
    mask[ix] = plane
    element = label[plane]
    return mask, element


def _curved_grid_mask(vt: Any, shape: tuple[int, int, int],
                      spacing: tuple[float, float, float], source_x: float | None
                      ) -> tuple[NDArray[np.bool_], NDArray]:
    """:func:`kwave_grid_mask` of a curved face: the grid points nearest to samples of
    each element's face (steps ≤ a third of the grid step), labelled by the element
    whose samples fall there most often (ties: the lower index)."""
    nx, ny, nz = shape
    dx, dy, dz = spacing
    x0 = (float(_grid_vec(nx, dx)[1]) + _face_depth(vt) if source_x is None
          else float(source_x))
    face = vt.array.surface(min(dx, dy, dz) / 3.0, layout="grid")
    pts = face.points + np.array([*vt.aperture_center, 0.0])
    idx = np.stack([np.rint((x0 + pts[:, 2]) / dx) + nx // 2,
                    np.rint((pts[:, 0] - vt.aperture_center[0]) / dy) + ny // 2,
                    np.rint((pts[:, 1] - vt.aperture_center[1]) / dz) + nz // 2],
                   axis=-1).astype(np.int64)
    inside = np.all((idx >= 0) & (idx < np.array(shape)), axis=1)
    if not np.all(inside):
        raise InputError("the face does not fit in the grid (give a larger grid or "
                         "source_x)", field="shape")
    flat = np.ravel_multi_index(idx.T, shape)
    el = np.asarray(face.element, dtype=np.int64)
    n_el = vt.element_count
    cells, votes = np.unique(flat * n_el + el, return_counts=True)
    cell, element = np.divmod(cells, n_el)
    order = np.lexsort((element, -votes, cell))  # per cell: most votes, lowest index
    cell, element = cell[order], element[order]
    first = np.r_[True, cell[1:] != cell[:-1]]
    mask = np.zeros(shape, dtype=bool)
    mask.reshape(-1)[cell[first]] = True
    return mask, element[first]


def kwave_grid_source(vt: Any, setting: Any, shape: tuple[int, int, int],
                      spacing: tuple[float, float, float], dt: float, nt: int, *,
                      representation: str = "monopole", medium: Medium | None = None,
                      source_x: float | None = None
                      ) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
    """On-grid (staircase) source of the array face: mask and one signal per point.

    NumPy only (no k-wave-python needed). Each masked point carries the signal of its
    element (:func:`kwave_source_signals`) delayed by the lens delay at its elevation
    z (band-limited, frequency domain).

    Parameters
    ----------
    vt, setting : VirtualTransducer, TransmitSetting
        Model and transmit.
    shape, spacing, source_x
        See :func:`kwave_grid_mask`.
    dt, nt : float, int
        k-Wave time step (s) and number of steps.
    representation, medium
        See :func:`kwave_source_signals`.

    Returns
    -------
    mask : ndarray of bool, shape (Nx, Ny, Nz)
        The source points.
    signals : ndarray, shape (mask.sum(), nt)
        Pa (monopole, ``source.p``) or m/s (dipole, ``source.ux``), C order of the mask.
    """
    mask, element = kwave_grid_mask(vt, shape, spacing, source_x=source_x)
    zs = _grid_vec(int(shape[2]), float(spacing[2]))[np.argwhere(mask)[:, 2]]
    per_el = kwave_source_signals(vt, setting, dt, nt, n_strips=1,
                                  representation=representation, medium=medium)
    return mask, _lens_shift(vt, per_el[element], zs, dt, medium)


def _kwave_array(vt: Any, strips: dict[str, NDArray], source_x: float,
                 bli_tolerance: float, upsampling_rate: int) -> Any:
    from kwave.utils.kwave_array import kWaveArray

    arr = kWaveArray(bli_tolerance=bli_tolerance, upsampling_rate=upsampling_rate)
    xc, yc = vt.aperture_center
    w, h = float(strips["width"]), float(strips["height"])
    for c, a in zip(strips["centers"], strips["angle"], strict=True):
        # k-Wave axes: (x prop, y lateral, z elevation); a rect element lies in its
        # local x-y plane (R = Rz(θz)·Ry(θy)·Rx(θx), degrees): 90° about y puts its normal
        # along x, then the azimuth angle about z turns it along the arc (convex face:
        # normal (cos a, sin a, 0), width direction (−sin a, cos a, 0))
        pos = [float(source_x + c[2]), float(c[0] - xc), float(c[1] - yc)]
        arr.add_rect_element(pos, h, w, [0.0, 90.0, float(np.degrees(a))])
    return arr


def _source_x(kgrid: Any, source_x: float | None, vt: Any) -> float:
    """x of the face's z = 0 plane (the apex of a convex face) in k-Wave coordinates:
    given, or one grid step inside the domain behind the deepest point of the face."""
    if source_x is not None:
        return float(source_x)
    return float(kgrid.x_vec.reshape(-1)[1]) + _face_depth(vt)


def kwave_source(vt: Any, setting: Any, kgrid: Any, *, representation: str = "monopole",
                 medium: Medium | None = None, source_x: float | None = None,
                 n_strips: int | None = None, off_grid: bool = True,
                 bli_tolerance: float = 0.05, upsampling_rate: int = 10) -> Any:
    """A k-wave-python ``kSource`` for a transmit of the virtual transducer.

    Parameters
    ----------
    vt, setting : VirtualTransducer, TransmitSetting
        Model and transmit.
    kgrid : kwave.kgrid.kWaveGrid
        3-D grid with its time array set (``kgrid.dt``, ``kgrid.Nt``).
    representation : {"monopole", "dipole"}
        ``source.p = ρ0 c0 u`` or ``source.ux = u`` (paper section II C).
    medium : Medium, optional
        ρ0, c0 of the simulation (default ``vt.medium``).
    source_x : float, optional
        x of the array face in m (k-Wave coordinates); default ``kgrid.x_vec[1]``.
    n_strips : int, optional
        Strips per element along the elevation (default: one per grid step dz, ≥ 1).
    off_grid : bool
        Place the strips with ``kWaveArray`` (band-limited, any position; default) or
        as a staircase mask (:func:`kwave_grid_mask`, element signal with lens delays
        per grid point).
    bli_tolerance, upsampling_rate
        Passed to ``kWaveArray``.

    Returns
    -------
    kwave.ksource.kSource
        With ``p_mask``/``p`` (monopole) or ``u_mask``/``ux`` (dipole), rows in C order
        of the mask.
    """
    from kwave.ksource import kSource

    _check_vt(vt)
    dt, nt = float(kgrid.dt), int(kgrid.Nt)
    dz = float(kgrid.dz)
    n = max(1, math.ceil(vt.element_height / dz)) if n_strips is None else int(n_strips)
    x0 = _source_x(kgrid, source_x, vt)
    source = kSource()
    if off_grid:
        strips = kwave_element_strips(vt, n, medium=medium)
        signals = kwave_source_signals(vt, setting, dt, nt, n_strips=n,
                                       representation=representation, medium=medium)
        arr = _kwave_array(vt, strips, x0, bli_tolerance, upsampling_rate)
        mask = arr.get_array_binary_mask(kgrid)
        dist = arr.get_distributed_source_signal(kgrid, signals, order="C")
    else:
        shape = (int(kgrid.Nx), int(kgrid.Ny), int(kgrid.Nz))
        mask, dist = kwave_grid_source(vt, setting, shape, (kgrid.dx, kgrid.dy, dz), dt, nt,
                                       representation=representation, medium=medium,
                                       source_x=x0)
    if representation == "monopole":
        source.p_mask = mask
        source.p = dist
    else:
        source.u_mask = mask
        source.ux = dist
    return source


def _lens_shift(vt: Any, signals: NDArray, z: NDArray, dt: float,
                medium: Medium | None) -> NDArray[np.float64]:
    """Delay each row by the lens delay at elevation z (band-limited, frequency domain).

    ``signals`` were computed with one strip per element (lens delay of the element
    centre); the difference to the delay at z is applied here.
    """
    from holoprobe.lens import lens_delays
    from holoprobe.signal import next_fast_length, to_frequency, to_time

    if not math.isfinite(vt.lens_focus):
        return signals
    c0 = (medium or vt.medium).sound_speed
    h = vt.element_height
    d = lens_delays(z, vt.lens_focus, h, c0) - lens_delays(0.0, vt.lens_focus, h, c0)
    nt = signals.shape[1]
    n = next_fast_length(2 * nt)
    f = np.fft.rfftfreq(n, dt)
    spec = to_frequency(signals, n=n, axis=-1) * np.exp(2j * np.pi * d[:, None] * f[None, :])
    return to_time(spec, n, axis=-1)[:, :nt]


def kwave_sensor(vt: Any, kgrid: Any, *, source_x: float | None = None,
                 n_strips: int | None = None, bli_tolerance: float = 0.05,
                 upsampling_rate: int = 10) -> tuple[Any, Any]:
    """A k-wave-python sensor on the array face for receive, with its ``kWaveArray``.

    Record ``p`` with the returned ``kSensor``; :func:`kwave_element_pressure` turns
    the recorded data into the element-averaged pressure p_R of paper eq.
    receive-impulse-response (lens delays reversed, averaged over each element).

    Returns
    -------
    sensor : kwave.ksensor.kSensor
        Mask of the grid points that carry the strips (off-grid weights), record "p".
    array : kwave.utils.kwave_array.kWaveArray
        The strips (needed to combine the sensor data).
    """
    from kwave.ksensor import kSensor

    _check_vt(vt)
    n = (max(1, math.ceil(vt.element_height / float(kgrid.dz))) if n_strips is None
         else int(n_strips))
    strips = kwave_element_strips(vt, n)
    arr = _kwave_array(vt, strips, _source_x(kgrid, source_x, vt), bli_tolerance,
                       upsampling_rate)
    sensor = kSensor(arr.get_array_binary_mask(kgrid))
    sensor.record = ["p"]
    return sensor, arr


def kwave_element_pressure(vt: Any, kgrid: Any, array: Any, sensor_data: NDArray, *,
                           medium: Medium | None = None) -> NDArray[np.float64]:
    """Element-averaged received pressure from k-Wave sensor data of :func:`kwave_sensor`.

    The strip signals (``array.combine_sensor_data``, C order) are delayed by their
    lens delays (the lens delays the wave on reception as on transmit: a wave from the
    elevation focus reaches every strip at the same time after the lens) and averaged
    over the strips of each element.

    Returns
    -------
    ndarray, shape (N, nt)
        Pressure in Pa per element on k-Wave's time axis.
    """
    from holoprobe.signal import next_fast_length, to_frequency, to_time

    strip_data = np.asarray(array.combine_sensor_data(kgrid, sensor_data, order="C"))
    n = strip_data.shape[0] // vt.element_count
    strips = kwave_element_strips(vt, n, medium=medium)
    nt = strip_data.shape[1]
    m = next_fast_length(2 * nt)
    f = np.fft.rfftfreq(m, float(kgrid.dt))
    # conjugate Fourier convention: a delay τ multiplies the spectrum by exp(+2πifτ)
    spec = to_frequency(strip_data, n=m, axis=-1) * np.exp(
        2j * np.pi * strips["lens_delay"][:, None] * f[None, :])
    shifted = to_time(spec, m, axis=-1)[:, :nt]
    return shifted.reshape(vt.element_count, n, nt).mean(axis=1)


def prepare_kwave_offline(*, binary_version: str = "v1.4.1",
                          url_base: str = "https://github.com/waltsims/") -> list[Path]:
    """Let ``import kwave`` succeed offline: placeholder binaries with their metadata.

    k-wave-python (0.6.x) downloads its C++ binaries at import time unless files with
    a matching ``<name>_metadata.json`` (URL and MD5 of the file) exist in
    ``kwave/bin/<platform>/``. This writes placeholder scripts there (they exit with
    an error if the C++ backend is ever called) so that the pure-Python backend
    (``kspaceFirstOrder(..., backend="python")``) can run without network. Nothing is
    downloaded; the package files are found without importing kwave.

    Parameters
    ----------
    binary_version : str
        ``kwave.BINARY_VERSION`` of the installed release (v1.4.1 for 0.6.2).
    url_base : str
        ``kwave.URL_BASE``.

    Returns
    -------
    list of Path
        The files written (empty if k-wave-python is not installed).

    Notes
    -----
    Linux and macOS only (Windows needs DLL names of another release). See
    ``docs/kwave.md``.
    """
    import hashlib
    import platform

    spec = importlib.util.find_spec("kwave")
    if spec is None or not spec.submodule_search_locations:
        return []
    system = platform.system().lower()
    if system not in ("linux", "darwin"):
        raise InputError(f"offline placeholders are for linux/darwin, not {system}",
                         field="platform")
    bin_dir = Path(next(iter(spec.submodule_search_locations))) / "bin" / system
    bin_dir.mkdir(parents=True, exist_ok=True)
    kinds = ["OMP"] + (["CUDA"] if system == "linux" else [])
    repo = {"linux": "kspaceFirstOrder-{k}-linux", "darwin": "k-wave-omp-darwin"}[system]
    written = []
    for kind in kinds:
        name = f"kspaceFirstOrder-{kind}"
        url = f"{url_base}{repo.format(k=kind)}/releases/download/{binary_version}/{name}"
        path = bin_dir / name
        if not path.exists():
            path.write_text("#!/bin/sh\necho 'k-wave C++ binary not installed (offline "
                            "placeholder from holoprobe); use backend=\"python\"' >&2\n"
                            "exit 1\n")
            os.chmod(path, 0o755)
        digest = hashlib.md5(path.read_bytes()).hexdigest()
        meta = bin_dir / f"{name}_metadata.json"
        meta.write_text(json.dumps({"url": url, "version": binary_version,
                                    "file_hash": digest}, indent=4))
        written += [path, meta]
    return written


#: Time of sample n of k-Wave's recorded pressure, in steps, relative to n·dt on the
#: time axis of the source signals (``t = n·dt``), per source representation; measured
#: by cross-correlation with the Rayleigh integral (k-wave-python 0.6.2, 4-element test
#: probe, 5 mm, dx ≈ 0.1 mm: −0.503 dt monopole, −0.998 dt dipole; ignoring them gives
#: 18 % and 36 % on-axis differences). docs/kwave.md, "Time axis", has the monopole.
KWAVE_TIME_OFFSET = {"monopole": 0.5, "dipole": 1.0}


@dataclass(frozen=True)
class KwavePlaneField:
    """Pressure that k-wave-python computed on a plane parallel to the array face.

    Attributes
    ----------
    pressure : ndarray, shape (ny, nz, nt)
        Pa, on the plane at ``distance`` from the (effective) source plane; k-Wave axes
        y (lateral, holoprobe x) and z (elevation, holoprobe y).
    time : ndarray, shape (nt,)
        Time of each sample on the source signals' axis (t = 0: the drive starts), s:
        ``(n + KWAVE_TIME_OFFSET[representation])·dt``.
    lateral, elevation : ndarray, shape (ny,), (nz,)
        Coordinates of the plane's points relative to the aperture centre, m.
    axis_index : (int, int)
        Indices of the on-axis point (lateral = elevation = 0).
    distance : float
        Distance of the plane from the effective source plane, m.
    step, dt : float
        Grid step (m) and time step (s).
    grid : (int, int, int)
        Grid size without the PML.
    seconds_source, seconds_kwave : float
        Wall time to build the source and to run k-Wave.
    """

    pressure: NDArray[np.float64]
    time: NDArray[np.float64]
    lateral: NDArray[np.float64]
    elevation: NDArray[np.float64]
    axis_index: tuple[int, int]
    distance: float
    step: float
    dt: float
    grid: tuple[int, int, int]
    seconds_source: float
    seconds_kwave: float

    @property
    def axis(self) -> NDArray[np.float64]:
        """On-axis pressure, shape (nt,), Pa."""
        return self.pressure[self.axis_index]


def kwave_plane_field(vt: Any, setting: Any, *, distance: float, step: float,
                      representation: str = "monopole", duration: float | None = None,
                      lateral_margin: float = 1e-3, elevation_margin: float = 1e-3,
                      beyond: int = 2, cfl: float = 0.3, pml: int = 10,
                      dtype: Any = np.float32, quiet: bool = True) -> KwavePlaneField:
    """Run k-wave-python (pure-Python backend, CPU) for a transmit and record a plane.

    The 3-D grid has one step ``dx`` in every direction (k-Wave axes: x propagation, y
    lateral, z elevation): x from one step behind the array face (``x_vec[1]``, see
    :func:`kwave_source`) to ``beyond`` steps past the recorded plane, y and z the
    aperture plus the margins on each side, a PML of ``pml`` points outside. The
    recorded plane lies exactly ``distance`` from the effective source plane:

    * monopole (``source.p = ρ0c0 u``, paper eq. rayleigh-fwd-vp): the source sits on
      the pressure grid at ``x_vec[1]``; ``dx = distance / m``.
    * dipole (``source.ux = u``, i.e. the pressure ρ0c0u of paper eq. rayleigh-fwd-pp):
      k-Wave's particle velocity lives on the staggered grid, so the source acts at
      ``x_vec[1] + dx/2``; ``dx = distance / (m + ½)``.

    m is the whole number that brings dx closest to ``step``. Time axis: sample n of the
    recorded pressure is the field at ``(n + KWAVE_TIME_OFFSET[representation])·dt`` of
    the source signals' time axis (monopole ½: the additive mass source of sample n
    acts over ((n − 1)·dt, n·dt]; dipole 1: the velocity source of sample n is added to
    u at (n − ½)·dt, over ((n − 3/2)·dt, (n − ½)·dt]); ``time`` holds these times.

    Parameters
    ----------
    vt, setting : VirtualTransducer, TransmitSetting
        Model and transmit.
    distance : float
        Distance of the recorded plane from the source plane, m.
    step : float
        Wanted grid step, m (e.g. λ/6 at the top frequency).
    representation : {"monopole", "dipole"}
        Source representation (:func:`kwave_source`).
    duration : float, optional
        Record length in s; default: the last arrival from the aperture corners plus the
        impulse response, drive and transmit delays.
    lateral_margin, elevation_margin : float
        Grid beyond the aperture on each side, m.
    beyond : int
        Grid planes past the recorded plane.
    cfl : float
        ``dt = cfl·dx/c0``.
    pml : int
        PML thickness in grid points (outside the grid).
    dtype : numpy dtype
        k-Wave's floating-point type.
    quiet : bool
        Silence k-Wave.

    Returns
    -------
    KwavePlaneField
    """
    import time as _time

    _check_vt(vt)
    if representation not in _REPRESENTATIONS:
        raise InputError(f"expected one of {_REPRESENTATIONS}, got {representation!r}",
                         field="representation")
    if vt.is_curved:
        raise InputError("the plane-field check needs a flat face (its plane lies at a "
                         "distance from the face); this model's elements face different "
                         "ways (convex)", field="vt")
    distance, step = float(distance), float(step)
    if not (math.isfinite(distance) and math.isfinite(step) and 0 < step <= distance):
        raise InputError(f"expected 0 < step <= distance in m, got step {step!r}, distance "
                         f"{distance!r}", field="step")
    from kwave.data import Vector
    from kwave.kgrid import kWaveGrid
    from kwave.kmedium import kWaveMedium
    from kwave.ksensor import kSensor
    from kwave.kspaceFirstOrder import kspaceFirstOrder

    from holoprobe.lens import lens_delays

    half = 0.5 if representation == "dipole" else 0.0
    m = max(1, round(distance / step - half))
    dx = distance / (m + half)
    ix_plane = 1 + m + (1 if half else 0)
    c0 = vt.medium.sound_speed
    half_y = 0.5 * ((vt.element_count - 1) * vt.pitch + vt.element_width) + lateral_margin
    half_z = 0.5 * vt.element_height + elevation_margin
    nx = ix_plane + 1 + int(beyond)
    ny, nz = 2 * math.ceil(half_y / dx) + 1, 2 * math.ceil(half_z / dx) + 1
    kgrid = kWaveGrid(Vector([nx, ny, nz]), Vector([dx, dx, dx]))
    dt = cfl * dx / c0
    if duration is None:
        far = math.sqrt(distance**2 + (2 * half_y) ** 2 + (2 * half_z) ** 2)
        tau = setting.element_delays(vt.element_centers(), c0)
        lens = (float(np.ptp(lens_delays(np.array([0.0, 0.5 * vt.element_height]),
                                         vt.lens_focus, vt.element_height, c0)))
                if math.isfinite(vt.lens_focus) else 0.0)
        duration = (far / c0 + vt.transmit_impulse_response.size / vt.transmit_sampling_rate
                    + setting.drive.duration + float(np.ptp(tau)) + lens)
    nt = math.ceil(float(duration) / dt) + 1
    kgrid.setTime(nt, dt)

    t0 = _time.perf_counter()
    source = kwave_source(vt, setting, kgrid, representation=representation)
    seconds_source = _time.perf_counter() - t0
    mask = np.zeros((nx, ny, nz), dtype=bool)
    mask[ix_plane] = True
    sensor = kSensor(mask)
    sensor.record = ["p"]
    t0 = _time.perf_counter()
    out = kspaceFirstOrder(kgrid, kWaveMedium(sound_speed=c0, density=vt.medium.density),
                           source, sensor, backend="python", device="cpu", pml_size=int(pml),
                           pml_inside=False, dtype=dtype, quiet=quiet)
    seconds_kwave = _time.perf_counter() - t0
    p = np.asarray(out["p"], dtype=float).reshape(ny, nz, nt)
    return KwavePlaneField(
        pressure=p, time=(np.arange(nt) + KWAVE_TIME_OFFSET[representation]) * dt,
        lateral=np.asarray(kgrid.y_vec, float).reshape(-1),
        elevation=np.asarray(kgrid.z_vec, float).reshape(-1), axis_index=(ny // 2, nz // 2),
        distance=distance, step=dx, dt=dt, grid=(nx, ny, nz), seconds_source=seconds_source,
        seconds_kwave=seconds_kwave)
