"""Outputs of the transmit characterization: summary.json, virtual_transducer.h5,
source_velocity.h5 and report.html, each written atomically into one directory.

``summary.json`` has exactly these keys (SI units; degrees where the name says
``_deg``; ``null`` for a value that does not exist, e.g. an infinite focus)::

    scan_plane   theta_x_deg, theta_y_deg, theta_z_deg, x0, y0, z0
    aperture     width, height, center_x, center_y; for an array with an element map
                 also active_width (outer-edge span of the non-dead elements; width is
                 the physical (N−1)·p + w)
    elements     count, pitch, width; for an array with an element map also
                 relative_amplitude [N], delay [N] (s), dead [0-based indices, RF column
                 order], receive_gain [N] (null without a receive result); a 2-D matrix
                 array also grid_shape [n_x, n_y] (element index iy·n_x + ix, the order
                 of every per-element list; a sparse lattice lists its present elements
                 only), layout ("full" | "sparse"), grid_position [N][2] (ix, iy),
                 pitch_y, height (element y size) and
                 positions [N][2] (element centres x, y on the source frame, m)
    lens_focus
    transmit     onset, peak_frequency, bandwidth_6db
    receive      theta_x_deg, theta_y_deg, sensor_x0, sensor_z0, reflector_distance,
                 reflection_coefficient, onset, peak_frequency, bandwidth_6db,
                 transfer_function {frequency [nf] (Hz), magnitude [nf] (|H_R(f)| in
                 unit), unit} (only with a receive result)
    medium       sound_speed (the value used), sound_speed_from_data,
                 sound_speed_from_data_uncertainty (m/s; null when not estimated)
    scan_positioning  noise_rms, noise_rms_uncertainty: effective rms scan-position
                 error along the beam from the phase residuals (m; null when the scan
                 does not allow it)
    uncertainty  the same tree: standard uncertainties (null where none is estimated)
    timings      seconds per step
    warnings     list of strings
"""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from holoprobe.characterize import (
    MatrixElementMap,
    ReceiveResult,
    TransmitResult,
    matrix_array,
    transfer_function_estimate,
)
from holoprobe.errors import InputError
from holoprobe.io import file_sha256, json_default, write_json, write_source_velocity
from holoprobe.lens import lens_delays
from holoprobe.signal import frequency_axis, next_fast_length, to_frequency
from holoprobe.transducer import Provenance, VirtualTransducer
from holoprobe.workflow._row_column import row_column_section, row_column_summary

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "OUTPUT_FILES",
    "SOURCE_VELOCITY_FILE",
    "SUMMARY_FILE",
    "report_figures",
    "summary_dict",
    "virtual_transducer",
    "write_outputs",
]

SUMMARY_FILE = "summary.json"
SOURCE_VELOCITY_FILE = "source_velocity.h5"
VIRTUAL_TRANSDUCER_FILE = "virtual_transducer.h5"
REPORT_FILE = "report.html"
OUTPUT_FILES = (SUMMARY_FILE, VIRTUAL_TRANSDUCER_FILE, SOURCE_VELOCITY_FILE, REPORT_FILE)
"""Every file :func:`write_outputs` may write into the output directory."""


def _num(value: Any) -> float | None:
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def summary_dict(result: TransmitResult, receive: ReceiveResult | None = None
                 ) -> dict[str, Any]:
    """The ``summary.json`` tree of a :class:`TransmitResult` (see module docstring),
    with the ``receive`` section of a :class:`ReceiveResult` when given.

    ``aperture.width`` is the outer-edge width W = (N−1)·p + w; ``aperture.center_x``
    and ``center_y`` are the aperture centre found by the last fit (in the
    coordinates of the last back-projection; the final origin has been moved by it).
    ``transmit.onset`` is t0 of the last iteration (s from the emission).
    ``receive.onset`` is t0 of the tilt-aligned averaged echo (s from the emission);
    ``receive.theta_x_deg`` is 0 (not observable with a linear array, no uncertainty);
    ``receive.sensor_x0``/``sensor_z0`` are x0', z0' of the virtual sensor.
    """
    pose, ap, el, u = result.pose, result.aperture, result.elements, result.uncertainties
    tx, ty, tz = pose.angles_deg
    x0, y0, z0 = pose.origin
    spec = result.ir_spectrum

    def deg(v: float) -> float | None:
        return _num(np.degrees(v)) if v is not None else None

    out: dict[str, Any] = {
        "scan_plane": {"theta_x_deg": tx, "theta_y_deg": ty, "theta_z_deg": tz,
                       "x0": x0, "y0": y0, "z0": z0},
        "aperture": {"width": _num(result.aperture_width),
                     "height": _num(result.aperture_height if math.isfinite(
                         result.aperture_height) else ap.height),
                     "center_x": _num(ap.center_x), "center_y": _num(ap.center_y)},
        "elements": {"count": int(el.count), "pitch": _num(el.pitch), "width": _num(el.width)},
        "lens_focus": _num(result.lens_focus),
        "transmit": {"onset": _num(result.onset), "peak_frequency": _num(spec.peak_frequency),
                     "bandwidth_6db": _num(spec.bandwidth)},
        "uncertainty": {
            "scan_plane": {"theta_x_deg": deg(u["theta_x"]), "theta_y_deg": deg(u["theta_y"]),
                           "theta_z_deg": deg(u["theta_z"]), "x0": _num(u["x0"]),
                           "y0": _num(u["y0"]), "z0": _num(u["z0"])},
            "aperture": {"width": _num(u["width"]), "height": _num(u["height"]),
                         "center_x": _num(u["center_x"]), "center_y": _num(u["center_y"])},
            "elements": {"count": 0, "pitch": _num(u["pitch"]),
                         "width": _num(u["element_width"])},
            "lens_focus": _num(u["lens_focus"]),
            "transmit": {"onset": _num(u["onset"]), "peak_frequency": None,
                         "bandwidth_6db": None},
        },
        "timings": {k: float(v) for k, v in result.timings.items()},
        "warnings": list(result.warnings),
    }
    out["medium"] = {
        "sound_speed": _num(result.medium.sound_speed),
        "sound_speed_from_data": _num(result.extras.get("sound_speed_from_data")),
        "sound_speed_from_data_uncertainty": _num(
            result.extras.get("sound_speed_from_data_uncertainty"))}
    out["scan_positioning"] = {
        "noise_rms": _num(result.extras.get("positioning_noise")),
        "noise_rms_uncertainty": _num(result.extras.get("positioning_noise_uncertainty"))}
    if result.element_map is not None:
        _element_summary(out, result, receive)
    if (rc := row_column_summary(result, receive)) is not None:
        out["row_column"] = rc
    if receive is not None:
        out["receive"], out["uncertainty"]["receive"] = _receive_summary(
            receive, receive.config.transfer_function_floor)
        out["timings"].update({f"receive.{k}": float(v) for k, v in receive.timings.items()})
        out["warnings"] += [f"receive: {w}" for w in receive.warnings]
    return out


def _floats(values) -> list[float | None]:
    return [_num(v) for v in np.asarray(values, dtype=float)]


def _element_summary(out: dict[str, Any], result: TransmitResult,
                     receive: ReceiveResult | None) -> None:
    """Add the element map (issue 11 keys) to ``elements`` and its uncertainties."""
    m = result.element_map
    if m is None:
        return
    gain = _receive_gain(receive, m.count)
    u_gain = None
    if gain is not None and receive is not None:
        u = getattr(receive.sensitivity, "amplitude_uncertainty", None)
        u_gain = None if u is None else _floats(u)
    # the physical width W = (N−1)·p + w stays in ``width``; the span of the elements
    # that radiate (a dead edge element shortens it) is reported beside it, with W's σ
    # (both are (k−1)·p + w of the same fitted p and w, k ≤ N: W's σ covers it)
    out["aperture"]["active_width"] = _num(m.active_width)
    out["uncertainty"]["aperture"]["active_width"] = out["uncertainty"]["aperture"]["width"]
    out["elements"].update({
        "relative_amplitude": _floats(m.relative_amplitude), "delay": _floats(m.delay),
        "dead": [int(i) for i in m.dead],
        "receive_gain": None if gain is None else _floats(gain)})
    out["uncertainty"]["elements"].update({
        "relative_amplitude": _floats(m.amplitude_uncertainty),
        "delay": _floats(m.delay_uncertainty), "dead": None, "receive_gain": u_gain})
    positions = m.positions if isinstance(m, MatrixElementMap) else None
    if isinstance(m, MatrixElementMap) and positions is not None:  # a 2-D matrix array
        out["elements"].update({
            "grid_shape": [int(v) for v in m.grid_shape], "layout": m.layout,
            "grid_position": None if m.grid_position is None
            else [[int(a), int(b)] for a, b in np.asarray(m.grid_position)],
            "pitch_y": _num(m.pitch_y),
            "height": _num(m.element_height),
            "positions": [[float(a), float(b)] for a, b in positions]})
        out["uncertainty"]["elements"].update({
            "grid_shape": None, "layout": None, "grid_position": None,
            "pitch_y": _num(m.pitch_y_uncertainty),
            "height": _num(m.height_uncertainty), "positions": None})


def _receive_summary(rx: ReceiveResult, floor: float = 0.0,
                     ) -> tuple[dict[str, Any], dict[str, Any]]:
    """``receive`` and its uncertainties; ``floor``: ``receive.transfer_function_floor``."""
    vr, u, s = rx.receiver, rx.uncertainties, rx.ir_spectrum
    values: dict[str, Any] = {
        "theta_x_deg": float(np.degrees(vr.theta_x)),
        "theta_y_deg": float(np.degrees(vr.theta_y)),
        "sensor_x0": _num(vr.x0), "sensor_z0": _num(vr.z0),
        "reflector_distance": _num(vr.distance),
        "reflection_coefficient": _num(rx.reflection_coefficient),
        "onset": _num(vr.onset), "peak_frequency": _num(s.peak_frequency),
        "bandwidth_6db": _num(s.bandwidth)}
    uncs: dict[str, Any] = {
        "theta_x_deg": _num(np.degrees(u.get("theta_x", math.nan))),
        "theta_y_deg": _num(np.degrees(u["theta_y"])),
        "sensor_x0": _num(u["x0"]), "sensor_z0": _num(u["z0"]),
        "reflector_distance": _num(u["distance"]),
        "reflection_coefficient": _num(u["reflection_coefficient"]),
        "onset": _num(u["onset"]), "peak_frequency": None, "bandwidth_6db": None}
    if rx.extras.get("array") == "matrix":  # the image of the grid centre is off y = 0
        values["sensor_y0"], uncs["sensor_y0"] = _num(vr.y0), _num(u.get("y0", math.nan))
    values["transfer_function"], uncs["transfer_function"] = _transfer_function(rx, floor)
    return values, uncs


def _transfer_function(rx: ReceiveResult, floor: float,
                       ) -> tuple[dict[str, Any], dict[str, Any]]:
    """``receive.transfer_function``: |H_R(f)| of the receive IR where its band is
    passed whole, with σ per frequency (noise of the deconvolution, σ(Rp)/Rp and the
    relative ``floor``); empty lists for an IR made without its per-bin SNR."""
    rp = rx.reflection_coefficient
    u_rel = rx.reflection_uncertainty / abs(rp) if rp and math.isfinite(
        rx.reflection_uncertainty) else 0.0
    ir = rx.impulse_response
    if ir.snr is None or ir.gain is None:  # an IR made without them (e.g. by hand)
        f, mag, unc, unit = np.empty(0), np.empty(0), np.empty(0), ""
    else:
        tf = transfer_function_estimate(ir, scale_uncertainty=u_rel, relative_floor=floor)
        f, mag, unc, unit = tf.frequencies, tf.magnitude, tf.uncertainty, tf.unit
    return ({"frequency": _floats(f), "magnitude": _floats(mag), "unit": unit},
            {"frequency": None, "magnitude": _floats(unc), "unit": None})


def _flatten(tree: dict[str, Any], prefix: str = "") -> dict[str, float]:
    out: dict[str, float] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(_flatten(value, name + "."))
        elif isinstance(value, int | float) and not isinstance(value, bool) \
                and math.isfinite(value):
            out[name] = float(value)
    return out


def model_metadata(summary: dict[str, Any], inputs: list[str] | tuple[str, ...] | tuple[
        Path, ...], config_toml: str, what: str
                   ) -> tuple[dict[str, float], dict[str, float], Provenance]:
    """Parameters, uncertainties and provenance of a virtual transducer from a run's
    summary tree: every finite number outside ``uncertainty``/``timings``/``warnings``
    by its dotted name, the uncertainties of those names, the SHA-256 of each existing
    file of ``inputs``, the configuration (TOML) and ``what`` with the warnings."""
    hashes = {}
    for p in inputs:
        if Path(p).is_file():
            hashes[Path(p).name] = file_sha256(p)
    notes = f"{what}; warnings: " + "; ".join(summary["warnings"])
    prov = Provenance(input_files=hashes, config=config_toml, config_format="toml",
                      notes=notes)
    params = _flatten({k: v for k, v in summary.items()
                       if k not in ("uncertainty", "timings", "warnings")})
    uncs = {k: v for k, v in _flatten(summary["uncertainty"]).items() if k in params}
    return params, uncs, prov


def element_transmit_weights(element_map: Any, count: int) -> dict[str, Any]:
    """``element_transmit_amplitude``/``_delay`` of a virtual transducer from an element
    map of ``count`` elements (a dead element radiates nothing); empty without one."""
    if element_map is None or element_map.count != count:
        return {}
    dead = list(element_map.dead)
    amp, tau = element_map.relative_amplitude.copy(), element_map.delay.copy()
    amp[dead], tau[dead] = 0.0, 0.0  # a dead element does not radiate
    return {"element_transmit_amplitude": amp, "element_transmit_delay": tau}


def receive_model_fields(receive: ReceiveResult | None, count: int) -> dict[str, Any]:
    """``receive_impulse_response``/``_sampling_rate``/``_units`` and, with one gain per
    element, ``element_sensitivity``/``element_delay`` of a virtual transducer from a
    receive result (flat or convex); empty without one."""
    if receive is None:
        return {}
    h = receive.impulse_response
    rx: dict[str, Any] = {"receive_impulse_response": h.ir,
                          "receive_sampling_rate": h.sampling_rate,
                          "receive_units": f"{receive.rf_unit}/(Pa*s)"}
    if receive.sensitivity is not None and receive.sensitivity.amplitude.size == count:
        rx["element_sensitivity"] = receive.sensitivity.amplitude
        rx["element_delay"] = receive.sensitivity.delay
    return rx


def virtual_transducer(result: TransmitResult, summary: dict[str, Any],
                       inputs: list[str] | tuple[str, ...] = (),
                       receive: ReceiveResult | None = None) -> VirtualTransducer:
    """The :class:`VirtualTransducer` of a characterization (model, parameters,
    uncertainties and provenance: the SHA-256 of each existing file of ``inputs``).

    ``summary`` is :func:`summary_dict` of the same results. Needs a transmit impulse
    response (a drive).
    """
    ir = result.impulse_response
    if ir is None:
        raise InputError("no transmit impulse response (no drive): no virtual transducer",
                         field="drive")
    el = result.elements
    kind = "transmit + receive" if receive is not None else "transmit"
    params, uncs, prov = model_metadata(summary, inputs, result.config.to_toml(),
                                        f"holoprobe characterize ({kind})")
    rx = receive_model_fields(receive, el.count)
    rx.update(element_transmit_weights(result.element_map, el.count))
    array = matrix_array(result.element_map)
    height = result.aperture.height if array is None else float(array.heights[0])
    return VirtualTransducer(
        element_count=el.count, pitch=el.pitch, element_width=min(el.width, el.pitch),
        element_height=height,
        transmit_impulse_response=ir.ir, transmit_sampling_rate=ir.sampling_rate,
        lens_focus=result.lens_focus, aperture_center=(0.0, 0.0),
        aperture_width=result.aperture_width,
        aperture_height=(result.aperture.height if array is None
                         else result.aperture_height),
        medium=result.medium, parameters=params, uncertainties=uncs, provenance=prov,
        name=Path(result.source).stem if result.source else "", array=array, **rx)


def report_figures(result: TransmitResult, receive: ReceiveResult | None = None
                   ) -> list[tuple[str, list[Figure]]]:
    """The figures of ``report.html``, section by section, as matplotlib figures.

    Parameters
    ----------
    result : TransmitResult
        From :func:`holoprobe.characterize.characterize_transmit`.
    receive : ReceiveResult, optional
        Adds the receive sections (paper Figs. 7 and 10a).

    Returns
    -------
    list of (str, list of matplotlib.figure.Figure)
        Section heading and its figures, in the report's order.
    """
    sections = _report_sections(result) + _element_sections(result, receive)
    if receive is not None:
        sections += _receive_sections(result, receive)
    return sections


def _report_sections(result: TransmitResult) -> list[tuple[str, list]]:
    from holoprobe import report as rp
    ap, c0, fc = result.aperture, result.medium.sound_speed, result.center_frequency
    sg, src = result.scan_grid, result.source_grid
    sections = []
    figs = []
    u = sg.x
    v = sg.y
    # red dashed: the scan plane outline before rotation, red dot: its centre
    outline = np.array([[u[0], v[0]], [u[-1], v[0]], [u[-1], v[-1]], [u[0], v[-1]]]) \
        + np.array(result.pose.origin[:2])
    figs.append(rp.plot_plane_amplitude_phase(
        result.scan_field, sg.x, sg.y, title="scan plane", frequency=fc, phase_mask_db=30.0))
    figs.append(rp.plot_plane_amplitude_phase(
        result.source_field, src.x, src.y, title="reconstructed source (ρ0c0·V)",
        frequency=fc, phase_mask_db=30.0,
        overlay={"rectangle": (ap.center_x, ap.center_y, ap.width, ap.height),
                 "points": np.array([result.pose.origin[:2]]), "outline": outline}))
    sections.append(("Back-projection (paper Fig. 5)", figs))

    figs = []
    figs.append(rp.plot_aperture_fit(
        ap.x, ap.profile_x[0] if ap.profile_x.shape[0] == 1 else
        np.average(ap.profile_x, axis=0, weights=ap.amplitude_x),
        np.average(ap.model_x(), axis=0, weights=ap.amplitude_x),
        ap.y, np.average(ap.profile_y, axis=0, weights=ap.amplitude_y),
        np.average(ap.model_y(), axis=0, weights=ap.amplitude_y),
        width=ap.width, height=ap.height, center_x=ap.center_x, center_y=ap.center_y,
        unit="m/s·s"))
    lens = result.lens
    if lens is not None and lens.significant:
        margin = c0 / fc
        ix = np.flatnonzero(np.abs(src.x - ap.center_x) <= 0.5 * ap.width - margin)
        iy = np.flatnonzero(np.abs(src.y - ap.center_y) <= 0.5 * ap.height - margin)
        if ix.size >= 1 and iy.size >= 3:
            block = result.source_field[np.ix_(ix, iy)]
            omega = 2 * np.pi * fc
            measured = np.unwrap(np.angle(block), axis=1) / omega
            model = lens_delays(src.y[iy] - lens.center_y, lens.focus, ap.height, c0)
            w = np.abs(block)
            measured -= (np.sum(w * (measured - model), axis=1) / np.sum(w, axis=1))[:, None]
            figs.append(rp.plot_lens_fit(src.y[iy], measured, model, focus=lens.focus,
                                         weights=w))
    vel = result.medium.impedance * result.mean_velocity_raw
    t = result.start_time + np.arange(vel.size) / result.sampling_rate
    figs.append(rp.plot_mean_velocity(t, vel, result.onset,
                                      threshold=result.medium.impedance
                                      * result.onset_threshold))
    ir = result.impulse_response
    if ir is not None:
        n = next_fast_length(4 * ir.ir.size)
        spec = np.abs(to_frequency(ir.ir, n=n))
        with np.errstate(divide="ignore"):
            db = 20 * np.log10(np.maximum(spec / spec.max(), 1e-12))
        s = result.ir_spectrum
        figs.append(rp.plot_impulse_response(
            np.arange(ir.ir.size) / ir.sampling_rate, ir.ir, frequency_axis(n, ir.sampling_rate),
            db, label="transmit impulse response", unit="Pa/(V·s)",
            peak_frequency=s.peak_frequency, band=(s.f_low, s.f_high),
            max_frequency=min(3 * s.f_high, 0.5 * ir.sampling_rate)))
    sections.append(("Model parameters and transmit impulse response (paper Fig. 6)", figs))

    # angular spectrum of the scan at the centre frequency with the rotated lines
    field = result.scan_field
    nx, ny = field.shape
    spec2 = np.fft.fftshift(np.abs(np.fft.fft2(field, s=(2 * nx, 2 * ny))))
    kx = np.fft.fftshift(2 * np.pi * np.fft.fftfreq(2 * nx, sg.dx))
    ky = np.fft.fftshift(2 * np.pi * np.fft.fftfreq(2 * ny, sg.dy))
    k = 2 * np.pi * fc / c0
    alpha = np.linspace(-np.pi / 3, np.pi / 3, 121)
    rot = result.pose.rotation
    curves = []
    for vecs in (np.stack([np.sin(alpha), 0 * alpha, np.cos(alpha)]),
                 np.stack([0 * alpha, np.sin(alpha), np.cos(alpha)])):
        q = rot.T @ (k * vecs)
        curves.append(np.stack([q[0], q[1]], axis=1))
    with np.errstate(divide="ignore"):
        sdb = 20 * np.log10(np.maximum(spec2 / spec2.max(), 1e-12))
    sections.append(("Scan-plane orientation (paper Fig. 3)", [rp.plot_orientation(
        kx, ky, sdb, curves, wavenumber=k, angles_deg=result.pose.angles_deg)]))
    return sections


def _db(spec: np.ndarray) -> np.ndarray:
    a = np.abs(spec)
    with np.errstate(divide="ignore"):
        return 20 * np.log10(np.maximum(a / max(float(a.max()), 1e-300), 1e-12))


def _element_sections(result: TransmitResult, rx: ReceiveResult | None
                      ) -> list[tuple[str, list]]:
    """The per-element map chart (dead elements marked), when there is a map; for a 2-D
    matrix array first a page of grid pictures (:func:`_grid_section`)."""
    from holoprobe import report as rp

    m = result.element_map
    if m is None:
        return []
    gain = _receive_gain(rx, m.count)
    fig = rp.plot_element_map(m.relative_amplitude, m.delay, dead=m.dead, weak=m.weak,
                              amplitude_uncertainty=m.amplitude_uncertainty,
                              receive_gain=gain)
    return [*_grid_section(m, gain), *row_column_section(result),
            ("Element map (dead and weak elements)", [fig])]


def _grid_section(m: MatrixElementMap | Any, gain: np.ndarray | None
                  ) -> list[tuple[str, list]]:
    """A matrix array's grid as pictures (every element a rectangle of its fitted size at
    its fitted place, dead ones crossed, weak ones circled): the relative transmit
    amplitude, its uncertainty, the transmit delay and, with an echo, the relative
    receive gain; [] for another array."""
    from holoprobe import report as rp

    array = matrix_array(m)
    if array is None:
        return []
    values = [(m.relative_amplitude, "relative transmit amplitude (1)"),
              (m.amplitude_uncertainty, "transmit amplitude uncertainty (1)"),
              (np.where(m.relative_amplitude > 0, m.delay * 1e9, np.nan),
               "transmit delay (ns)")]
    if gain is not None:
        values.append((gain, "relative receive gain (1)"))
    empty = _empty_positions(array)
    figs = [rp.plot_array_geometry(array.positions, array.normals, v, widths=array.widths,
                                   heights=array.heights, dead=m.dead, weak=m.weak,
                                   label=label, empty=empty)
            for v, label in values if v is not None]
    return [("Element grid (matrix array)", figs)]


def _empty_positions(array: Any) -> np.ndarray | None:
    """Centres (m, shape (M, 2)) of the lattice positions a sparse matrix leaves empty:
    the lattice ``c + ix a₁ + iy a₂`` fitted to the elements' centres (exact on a
    lattice, whatever its rotation); None for a full grid."""
    if array.layout != "sparse" or array.grid_position is None:
        return None
    nx, ny = array.grid_shape
    gp = np.asarray(array.grid_position, dtype=float)
    design = np.c_[np.ones(len(gp)), gp]
    coef = np.linalg.lstsq(design, array.positions[:, :2], rcond=None)[0]
    full = np.zeros((ny, nx), dtype=bool)
    full[array.grid_position[:, 1], array.grid_position[:, 0]] = True
    iy, ix = np.nonzero(~full)
    return np.c_[np.ones(ix.size), ix, iy] @ coef


def _receive_gain(rx: ReceiveResult | None, count: int) -> np.ndarray | None:
    """Relative receive gain per element (live mean 1) or None."""
    if rx is None or rx.sensitivity is None or rx.sensitivity.amplitude.size != count:
        return None
    return np.asarray(rx.sensitivity.amplitude, dtype=float)


def _receive_sections(result: TransmitResult, rx: ReceiveResult) -> list[tuple[str, list]]:
    """The paper's Fig. 7 panels and Fig. 10a for a receive result."""
    from holoprobe import report as rp

    vr = rx.receiver
    width = result.aperture_width
    d = vr.distance
    sg = result.scan_grid
    # side view: virtual source, scan plane, reflector (tilted θy'/2), virtual sensor
    scan_len = float(sg.x[-1] - sg.x[0])
    ox, _, oz = result.pose.origin
    path = np.array([[-0.5 * width, 0.0], [vr.x0 - 0.5 * width * math.cos(vr.theta_y),
                                           vr.z0 + 0.5 * width * math.sin(vr.theta_y)]])
    figs = [rp.plot_receive_geometry(
        source=(0.0, 0.0, width, 0.0), scan_plane=(ox, oz, scan_len, result.pose.theta_y),
        reflector=(0.0, d, 1.2 * width, 0.5 * vr.theta_y),
        sensor=(vr.x0, vr.z0, width, vr.theta_y), path=path)]
    line = vr.arrival_times[vr.used].mean() + vr.slope * (rx.element_x
                                                          - rx.element_x[vr.used].mean())
    figs += receive_signal_figures(rx, line)
    sections = [("Receive characterization (paper Fig. 7)", figs)]
    tx = result.impulse_response
    if tx is not None:
        sections.append(transfer_function_section(tx, rx))
    return sections


def receive_signal_figures(rx: ReceiveResult, line: np.ndarray) -> list:
    """Element RF with its arrivals and the fitted arrival ``line`` (s, one per
    element), the aligned average with its onset, the predicted element pressure, the
    deconvolution spectra and the receive IR (paper Fig. 7b–f)."""
    from holoprobe import report as rp

    vr = rx.receiver
    fs = vr.sampling_rate
    n_rf = vr.averaged_rf.size
    t_rf = vr.start_time + np.arange(n_rf) / fs
    arrivals = np.where(vr.used, vr.arrival_times, np.nan)
    lo = float(np.nanmin(arrivals)) - 2e-6
    hi = float(np.nanmax(arrivals)) + 4e-6
    figs = []
    if rx.rf is not None:
        figs.append(rp.plot_element_rf(t_rf, rx.rf, arrivals, line, unit=rx.rf_unit,
                                       time_window=(lo, hi)))
    figs.append(rp.plot_averaged_rf(t_rf, vr.averaged_rf, vr.onset, unit=rx.rf_unit))
    t_p = rx.pressure_start_time + np.arange(rx.element_pressure.shape[1]) / rx.pressure_rate
    figs.append(rp.plot_receive_pressure(t_p, rx.element_pressure))
    ir = rx.impulse_response
    s = rx.ir_spectrum
    fmax = min(3 * s.f_high, 0.5 * ir.sampling_rate, float(ir.frequencies[-1]))
    figs.append(rp.plot_deconvolution_spectra(
        ir.frequencies, _db(ir.voltage_spectrum), _db(ir.pressure_spectrum),
        _db(ir.transfer_function), band=(s.f_low, s.f_high), max_frequency=fmax))
    n = next_fast_length(4 * ir.ir.size)
    figs.append(rp.plot_impulse_response(
        np.arange(ir.ir.size) / ir.sampling_rate, ir.ir, frequency_axis(n, ir.sampling_rate),
        _db(to_frequency(ir.ir, n=n)), label="receive impulse response",
        unit=ir.unit, peak_frequency=s.peak_frequency, band=(s.f_low, s.f_high),
        max_frequency=fmax))
    return figs


def transfer_function_section(tx: Any, rx: ReceiveResult) -> tuple[str, list]:
    """The transmit and receive transfer functions (paper Fig. 10a) of a transmit IR
    (``.ir``, ``.sampling_rate``) and a receive result."""
    from holoprobe import report as rp

    ir, s = rx.impulse_response, rx.ir_spectrum
    fmax = min(3 * s.f_high, 0.5 * ir.sampling_rate, float(ir.frequencies[-1]))
    rate = min(tx.sampling_rate, ir.sampling_rate)
    n = next_fast_length(int(4 * max(tx.ir.size * rate / tx.sampling_rate,
                                     ir.ir.size * rate / ir.sampling_rate)))
    f = frequency_axis(n, rate)
    keep = f <= fmax
    ht = to_frequency(tx.ir, n=round(n * tx.sampling_rate / rate))[:f.size]
    hr = to_frequency(ir.ir, n=round(n * ir.sampling_rate / rate))[:f.size]
    return ("Transmit and receive transfer functions (paper Fig. 10a)",
            [rp.plot_transfer_functions(f[keep], ht[keep], hr[keep], max_frequency=fmax)])


def write_outputs(
    result: TransmitResult,
    out_dir: str | os.PathLike,
    *,
    inputs: list[str | os.PathLike] | tuple = (),
    overwrite: bool = False,
    report: bool = True,
    extra_timings: dict[str, float] | None = None,
    receive: ReceiveResult | None = None,
) -> dict[str, Path]:
    """Write summary.json, virtual_transducer.h5, source_velocity.h5 and report.html.

    Parameters
    ----------
    result : TransmitResult
        From :func:`characterize_transmit`.
    out_dir : str or PathLike
        Output directory (created when missing).
    inputs : sequence of path
        Input files: hashed (SHA-256) into the provenance, and never overwritten.
    overwrite : bool
        Replace existing output files (default: refuse with InputError).
    report : bool
        Write report.html (needs matplotlib).
    extra_timings : dict, optional
        More ``step → seconds`` for ``summary.json`` (e.g. reading the input);
        the time spent writing is added as ``"write"``.
    receive : ReceiveResult, optional
        From :func:`characterize_receive`: adds the ``receive`` section to the summary,
        ``/receive`` to virtual_transducer.h5 and the paper's Fig. 7 and Fig. 10a panels
        to the report.

    Returns
    -------
    dict of str to Path
        The files written, by kind (``"summary"``, ``"virtual_transducer"``,
        ``"source_velocity"``, ``"report"``). ``virtual_transducer.h5`` is skipped when
        there is no impulse response (no drive); a warning in the summary says so.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError("expected a directory", file=str(out), field="--out")
    out.mkdir(parents=True, exist_ok=True)
    protect = [str(p) for p in inputs]
    t_start = time.perf_counter()
    summary = summary_dict(result, receive)
    summary["timings"].update({k: float(v) for k, v in (extra_timings or {}).items()})
    written: dict[str, Path] = {}
    hashes: dict[str, str] | None = None  # the inputs' SHA-256, read once
    if result.impulse_response is not None:
        vt = virtual_transducer(result, summary, protect, receive)
        hashes = dict(vt.provenance.input_files)
        path = out / VIRTUAL_TRANSDUCER_FILE
        for p in protect:
            if path.exists() and Path(p).exists() and os.path.samefile(p, path):
                raise InputError("refusing to overwrite an input file", file=str(path))
        written["virtual_transducer"] = vt.save(path, overwrite=overwrite)
    else:
        summary["warnings"].append("virtual_transducer.h5 not written: no transmit impulse "
                                   "response without a drive voltage")
    g = result.source_grid
    written["source_velocity"] = write_source_velocity(
        out / SOURCE_VELOCITY_FILE, result.source_velocity, g.x, g.y, result.sampling_rate,
        tuple(result.extras["band"]), overwrite=overwrite, protect=protect)
    if report:
        from holoprobe.report import build_report

        metadata: dict[str, Any] = {
            "scan": result.source,
            "input files (SHA-256)": hashes if hashes is not None else {
                Path(p).name: file_sha256(p) for p in protect if Path(p).is_file()},
            "configuration": result.config.to_dict(),
            "iterations": result.history,
            "signal band (Hz)": list(result.extras["band"]),
            "timings (s)": result.timings,
        }
        params = {k: v for k, v in summary.items() if k not in ("timings",)}
        sections = report_figures(result, receive)
        title = "holoprobe transmit characterization"
        if receive is not None:
            title = "holoprobe transmit and receive characterization"
            metadata["receive"] = {"echo": receive.source,
                                   "reflection_method": (receive.reflection.method
                                                         if receive.reflection else "given"),
                                   "timings (s)": receive.timings, **receive.extras}
        written["report"] = build_report(
            out / REPORT_FILE, title=title,
            parameters=params, sections=sections,
            warnings=summary["warnings"], metadata=json.loads(json.dumps(
                metadata, default=json_default)), overwrite=overwrite, protect=protect)
    summary["timings"]["write"] = time.perf_counter() - t_start
    path = out / SUMMARY_FILE
    write_json(path, summary, overwrite=overwrite, protect=protect)
    written["summary"] = path
    return written
