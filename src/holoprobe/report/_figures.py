"""Figures of the characterization report (paper Figs. 3, 5, 6, 7 and 10a).

Every function takes plain NumPy arrays and floats in SI units (m, s, Hz, Pa,
rad) and returns a :class:`matplotlib.figure.Figure` built directly (no
``pyplot``, so no global figure registry and no GUI backend). Axes are scaled
for reading: positions in mm, times in µs, delays in ns, frequencies in MHz,
wavenumbers in rad/mm; every axis label names its unit in parentheses.

Each figure carries a short caption with the numbers it shows; read it with
:func:`figure_caption`. :data:`CAPTIONS` holds the generic caption of each
function (the first sentence of the per-figure caption).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from holoprobe.errors import InputError

__all__ = [
    "CAPTIONS",
    "figure_caption",
    "plot_aperture_fit",
    "plot_array_geometry",
    "plot_averaged_rf",
    "plot_deconvolution_spectra",
    "plot_element_map",
    "plot_element_rf",
    "plot_hydrophone_deconvolution",
    "plot_impulse_response",
    "plot_lens_fit",
    "plot_mean_velocity",
    "plot_orientation",
    "plot_plane_amplitude_phase",
    "plot_receive_geometry",
    "plot_receive_pressure",
    "plot_transfer_functions",
]

_MM = 1e3
_US = 1e6
_NS = 1e9
_MHZ = 1e-6
_RAD_PER_MM = 1e-3

#: Generic caption of each figure function (the figure's own caption adds its numbers).
CAPTIONS: dict[str, str] = {
    "plot_hydrophone_deconvolution": "Hydrophone deconvolution: voltage, pressure with its "
    "uncertainty band, and the spectra with the calibration.",
    "plot_plane_amplitude_phase": "Amplitude and phase of one frequency component on a plane.",
    "plot_aperture_fit": "Band-limited rectangle fit to the source amplitude (paper Fig. 6a).",
    "plot_lens_fit": "Parabolic fit to the phase delays along the elevation (paper Fig. 6b).",
    "plot_mean_velocity": "Source-averaged signal after reversing the lens delays, "
    "with the onset t0 (paper Fig. 6c).",
    "plot_impulse_response": "Impulse response and its spectrum with the −6 dB band "
    "(paper Figs. 6d, 7f).",
    "plot_orientation": "Angular spectrum with the fitted integration curves (paper Fig. 3).",
    "plot_receive_geometry": "Geometry of the receive experiment (paper Fig. 7a).",
    "plot_array_geometry": "Element layout of the array (a convex arc seen along the "
    "elevation axis, or a matrix grid seen from the front, every element a rectangle of "
    "its size), every element coloured by its value, dead ones crossed, weak ones circled.",
    "plot_element_map": "Per-element map: relative transmit amplitude, delay and receive "
    "gain of every element, dead ones marked.",
    "plot_element_rf": "Element RF of the reflector echo with the fitted arrival line "
    "(paper Fig. 7b).",
    "plot_averaged_rf": "Averaged receive RF with the onset t0 (paper Fig. 7c).",
    "plot_receive_pressure": "Element receive pressure from forward projection (paper Fig. 7d).",
    "plot_deconvolution_spectra": "Spectra of the receive deconvolution (paper Fig. 7e).",
    "plot_transfer_functions": "Normalised transmit and receive transfer functions "
    "(paper Fig. 10a).",
}

_CAPTION_ATTR = "_holoprobe_caption"
_FIXED_ATTR = "_holoprobe_fixed_layout"
_FIXED_TICK_CHARS = 6
"""Longest tick label (characters, e.g. ``−12500``) the fixed margins of :func:`_figure`
leave room for beside a vertical axis; a figure with longer ones gets matplotlib's
constrained layout instead."""


def figure_caption(fig: Figure) -> str:
    """The caption a figure function of this module attached to ``fig`` ('' if none)."""
    return str(getattr(fig, _CAPTION_ATTR, ""))


def _finish(fig: Figure, name: str, details: str = "") -> Figure:
    if getattr(fig, _FIXED_ATTR, False) and not _fits_fixed_layout(fig):
        fig.set_layout_engine("constrained")  # wider tick labels than the margins allow
    caption = CAPTIONS[name]
    if details:
        caption = f"{caption} {details}"
    setattr(fig, _CAPTION_ATTR, caption)
    return fig


def _figure(figsize: tuple[float, float], *, left: float = 0.95, right: float = 0.2,
            bottom: float = 0.55, top: float = 0.4, wspace: float = 0.0, hspace: float = 0.0,
            ncols: int = 1, nrows: int = 1) -> Figure:
    """A figure without a layout engine whose subplots get fixed margins (inches; the
    default ``left`` leaves room for tick labels of up to six characters, e.g.
    ``−75000``, and the axis label; ``top`` for the title).

    Drawing a constrained-layout figure measures every axis' ticks and labels about
    four more times (two layout passes, each asking every axes and its siblings for its
    bounding box): ≈ 60 % more CPU than the draw itself (issue 14: 1.6 → 1.0 s for the 15
    figures of a full-size report). ``wspace`` / ``hspace`` are the gaps between the
    ``ncols`` columns / ``nrows`` rows of :meth:`Figure.subplots`, in inches. A figure
    too small for these margins (they would take more than 60 % of its width or height)
    gets the constrained layout.
    """
    w, h = figsize
    if left + right + (ncols - 1) * wspace > 0.6 * w or \
            bottom + top + (nrows - 1) * hspace > 0.6 * h:  # a small figure
        return Figure(figsize=figsize, layout="constrained")
    fig = Figure(figsize=figsize)
    kw = {"left": left / w, "right": 1.0 - right / w, "bottom": bottom / h,
          "top": 1.0 - top / h}
    if ncols > 1:  # matplotlib's wspace: the gap over the mean axes width
        kw["wspace"] = wspace / ((w - left - right - (ncols - 1) * wspace) / ncols)
    if nrows > 1:
        kw["hspace"] = hspace / ((h - bottom - top - (nrows - 1) * hspace) / nrows)
    fig.subplots_adjust(**kw)
    setattr(fig, _FIXED_ATTR, True)
    return fig


def _fits_fixed_layout(fig: Figure) -> bool:
    """Whether every vertical axis' tick labels (colour bars' too) have at most
    :data:`_FIXED_TICK_CHARS` characters, the width :func:`_figure`'s margins leave room
    for: the labels the locator and formatter will draw at the current limits, without
    drawing (≈ 1 ms a figure)."""
    for ax in fig.axes:
        axis = ax.yaxis
        if not (axis.get_visible() and ax.get_visible()):
            continue
        lo, hi = sorted(ax.get_ylim())
        tol = 1e-9 * (hi - lo)
        locs = [v for v in axis.get_major_locator()() if lo - tol <= v <= hi + tol]
        if locs and max(map(len, axis.get_major_formatter().format_ticks(locs))) \
                > _FIXED_TICK_CHARS:
            return False
    return True


# ----------------------------------------------------------------- validation


def _array(name: str, value, *, ndim: int | tuple[int, ...], complex_ok: bool = False):
    try:
        arr = np.asarray(value)
    except Exception as exc:  # pragma: no cover - exotic objects
        raise InputError(f"expected an array, got {type(value).__name__}", field=name) from exc
    ndims = (ndim,) if isinstance(ndim, int) else ndim
    if arr.ndim not in ndims:
        want = " or ".join(f"{d}-D" for d in ndims)
        raise InputError(f"expected a {want} array, got shape {arr.shape}", field=name)
    if arr.size == 0:
        raise InputError("expected a non-empty array", field=name)
    if np.iscomplexobj(arr):
        if not complex_ok:
            raise InputError("expected real values, got a complex array", field=name)
        return arr.astype(complex, copy=False)
    if not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise InputError(f"expected numbers, got dtype {arr.dtype}", field=name)
    return arr.astype(float, copy=False)


def _length(name: str, arr: np.ndarray, n: int, what: str) -> None:
    if arr.shape[-1] != n:
        raise InputError(
            f"expected {n} values along the last axis (the length of {what}), "
            f"got shape {arr.shape}",
            field=name,
        )


def _finite_float(name: str, value) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError) as exc:
        raise InputError(f"expected a number, got {value!r}", field=name) from exc
    if not math.isfinite(out):
        raise InputError(f"expected a finite number, got {out}", field=name)
    return out


def _optional_float(name: str, value) -> float | None:
    return None if value is None else _finite_float(name, value)


def _fmt(value: float, digits: int = 4) -> str:
    return f"{value:.{digits}g}"


def _extent(x: np.ndarray, y: np.ndarray, scale: float
            ) -> tuple[float, float, float, float]:
    """imshow extent so that pixel centres sit on the sample positions."""
    dx = (x[-1] - x[0]) / (x.size - 1) if x.size > 1 else 1.0 / scale
    dy = (y[-1] - y[0]) / (y.size - 1) if y.size > 1 else 1.0 / scale
    return (
        float((x[0] - dx / 2) * scale),
        float((x[-1] + dx / 2) * scale),
        float((y[0] - dy / 2) * scale),
        float((y[-1] + dy / 2) * scale),
    )


def _to_db(magnitude: np.ndarray, *, floor_db: float) -> np.ndarray:
    peak = float(np.nanmax(magnitude)) if magnitude.size else 0.0
    if not peak > 0:
        return np.full(magnitude.shape, floor_db)
    with np.errstate(divide="ignore"):
        level = 20.0 * np.log10(magnitude / peak)
    return np.maximum(level, floor_db)


# ------------------------------------------------------------------- figures


def plot_plane_amplitude_phase(
    field_2d,
    x,
    y,
    *,
    title: str,
    frequency: float,
    overlay: Mapping[str, object] | None = None,
    db: bool = True,
    dynamic_range_db: float = 40.0,
    amplitude_unit: str = "Pa·s",
    phase_mask_db: float | None = None,
    figsize: tuple[float, float] = (9.0, 3.6),
) -> Figure:
    """Amplitude and phase maps of one frequency component on a plane (paper Fig. 5).

    Parameters
    ----------
    field_2d : array_like, complex, shape (nx, ny)
        The field at ``frequency`` (e.g. the scan-plane pressure, or ρ0c0 times
        the reconstructed source velocity, both in Pa·s in the frequency domain).
    x, y : array_like, shape (nx,), (ny,)
        Sample positions along the first and second axis of ``field_2d`` (m),
        uniformly spaced and increasing.
    title : str
        Shown above the panels ("scan plane", "reconstructed source", ...).
    frequency : float
        The frequency of the component (Hz); shown in the title.
    overlay : mapping, optional
        Shapes drawn on both panels, all in m in the plane's (x, y):

        * ``"rectangle"``: ``(center_x, center_y, width, height)``, e.g. the
          fitted aperture (dashed white).
        * ``"points"``: array of shape (n, 2), e.g. the estimated centre of the
          scan plane (red dots).
        * ``"outline"``: array of shape (n, 2) or a list of them, closed
          polygons, e.g. the scan plane before rotation (red dashed).
    db : bool
        Amplitude in dB relative to the maximum (default) or linear.
    dynamic_range_db : float
        Lowest level shown when ``db`` is true (dB below the maximum, > 0).
    amplitude_unit : str
        Unit of the linear amplitude (used when ``db`` is false).
    phase_mask_db : float, optional
        If given, blank the phase where the amplitude is more than this many dB
        below the maximum (noise-only phase is meaningless).
    figsize : (float, float)
        Figure size in inches.

    Returns
    -------
    matplotlib.figure.Figure
        Two panels (amplitude, phase) with colour bars; caption via
        :func:`figure_caption`.
    """
    field = _array("field_2d", field_2d, ndim=2, complex_ok=True)
    xs = _array("x", x, ndim=1)
    ys = _array("y", y, ndim=1)
    if field.shape != (xs.size, ys.size):
        raise InputError(
            f"expected shape (len(x), len(y)) = ({xs.size}, {ys.size}), got {field.shape}",
            field="field_2d",
        )
    f0 = _finite_float("frequency", frequency)
    if not dynamic_range_db > 0:
        raise InputError(f"expected > 0, got {dynamic_range_db}", field="dynamic_range_db")

    magnitude = np.abs(field)
    phase = np.angle(field)
    if phase_mask_db is not None:
        level = _to_db(magnitude, floor_db=-np.inf)
        phase = np.where(level >= -abs(float(phase_mask_db)), phase, np.nan)

    fig = _figure(figsize, left=0.7, right=0.75, top=0.65, wspace=1.1, ncols=2)
    ax_a, ax_p = fig.subplots(1, 2, sharex=True, sharey=True)
    extent = _extent(xs, ys, _MM)
    if db:
        amp = _to_db(magnitude, floor_db=-dynamic_range_db)
        im_a = ax_a.imshow(amp.T, origin="lower", extent=extent, cmap="viridis",
                           vmin=-dynamic_range_db, vmax=0.0, aspect="equal",
                           interpolation="nearest")
        amp_label = "amplitude (dB re max)"
    else:
        im_a = ax_a.imshow(magnitude.T, origin="lower", extent=extent, cmap="viridis",
                           aspect="equal", interpolation="nearest")
        amp_label = f"amplitude ({amplitude_unit})"
    im_p = ax_p.imshow(phase.T, origin="lower", extent=extent, cmap="twilight",
                       vmin=-np.pi, vmax=np.pi, aspect="equal", interpolation="nearest")
    # narrow colour-bar slots (fixed layout: the images keep their width)
    fig.colorbar(im_a, ax=ax_a, shrink=0.9, fraction=0.06, pad=0.03).set_label(amp_label)
    cbar_p = fig.colorbar(im_p, ax=ax_p, shrink=0.9, fraction=0.06, pad=0.03,
                          ticks=[-np.pi, 0, np.pi])
    cbar_p.ax.set_yticklabels(["−π", "0", "π"])
    cbar_p.set_label("phase (rad)")
    for ax, what in ((ax_a, "amplitude"), (ax_p, "phase")):
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_title(what)
        _draw_overlay(ax, overlay)
    fig.suptitle(f"{title} — {f0 * _MHZ:.3g} MHz")
    return _finish(fig, "plot_plane_amplitude_phase",
                   f"{title[:1].upper()}{title[1:]} at {f0 * _MHZ:.3g} MHz; peak amplitude "
                   f"{_fmt(float(magnitude.max()), 3)} {amplitude_unit}.")


def _draw_overlay(ax, overlay: Mapping[str, object] | None) -> None:
    if overlay is None:
        return
    if not isinstance(overlay, Mapping):
        raise InputError("expected a mapping with keys 'rectangle', 'points', 'outline'",
                         field="overlay")
    unknown = set(overlay) - {"rectangle", "points", "outline"}
    if unknown:
        raise InputError(f"unknown keys {sorted(unknown)}; expected 'rectangle', 'points', "
                         "'outline'", field="overlay")
    if overlay.get("rectangle") is not None:
        rect = _array("overlay['rectangle']", overlay["rectangle"], ndim=1)
        if rect.size != 4:
            raise InputError("expected (center_x, center_y, width, height) in m",
                             field="overlay['rectangle']")
        cx, cy, w, h = rect * _MM
        ax.add_patch(Rectangle((cx - w / 2, cy - h / 2), w, h, fill=False, edgecolor="white",
                               linestyle="--", linewidth=1.2))
    if overlay.get("points") is not None:
        pts = np.atleast_2d(_array("overlay['points']", overlay["points"], ndim=(1, 2)))
        if pts.shape[-1] != 2:
            raise InputError(f"expected shape (n, 2) in m, got {pts.shape}",
                             field="overlay['points']")
        ax.plot(pts[:, 0] * _MM, pts[:, 1] * _MM, "o", color="red", markersize=4)
    outline = overlay.get("outline")
    if outline is not None:
        polys = outline if isinstance(outline, list | tuple) else [outline]
        for poly in polys:
            p = _array("overlay['outline']", poly, ndim=2)
            if p.shape[1] != 2:
                raise InputError(f"expected polygons of shape (n, 2) in m, got {p.shape}",
                                 field="overlay['outline']")
            closed = np.vstack([p, p[:1]]) * _MM
            ax.plot(closed[:, 0], closed[:, 1], "--", color="red", linewidth=1.0)


def plot_aperture_fit(
    x,
    profile_x,
    model_x,
    y,
    profile_y,
    model_y,
    *,
    width: float,
    height: float,
    center_x: float,
    center_y: float,
    unit: str = "Pa·s",
    figsize: tuple[float, float] = (9.0, 3.2),
) -> Figure:
    """Band-limited rectangle fit to the source amplitude (paper Fig. 6a).

    Parameters
    ----------
    x, profile_x, model_x : array_like, shape (nx,)
        Lateral positions (m), the measured amplitude profile along x and the
        fitted band-limited rectangle (paper eq. for V_fit) on the same points.
    y, profile_y, model_y : array_like, shape (ny,)
        The same along the elevation y.
    width, height : float
        Fitted aperture width W and height H (m).
    center_x, center_y : float
        Fitted aperture centre (xc, yc) (m).
    unit : str
        Unit of the amplitude (ρ0c0·|V| in the frequency domain: Pa·s).
    figsize : (float, float)
        Figure size in inches.

    Returns
    -------
    matplotlib.figure.Figure
        Two panels (x and y profiles); the fitted edges are dotted lines.
    """
    w = _finite_float("width", width)
    h = _finite_float("height", height)
    cx = _finite_float("center_x", center_x)
    cy = _finite_float("center_y", center_y)
    fig = _figure(figsize, wspace=1.0, right=0.15, ncols=2)
    axes = fig.subplots(1, 2)
    for ax, (pos_name, pos, prof_name, prof, mod_name, mod, c, size, axis) in zip(
        axes,
        (
            ("x", x, "profile_x", profile_x, "model_x", model_x, cx, w, "x"),
            ("y", y, "profile_y", profile_y, "model_y", model_y, cy, h, "y"),
        ),
        strict=True,
    ):
        p = _array(pos_name, pos, ndim=1)
        m = np.abs(_array(prof_name, prof, ndim=1, complex_ok=True))
        f = np.abs(_array(mod_name, mod, ndim=1, complex_ok=True))
        _length(prof_name, m, p.size, pos_name)
        _length(mod_name, f, p.size, pos_name)
        ax.plot(p * _MM, m, ".", color="0.35", markersize=3, label="measured")
        ax.plot(p * _MM, f, "-", color="tab:red", linewidth=1.4, label="fit")
        for edge in (c - size / 2, c + size / 2):
            ax.axvline(edge * _MM, color="tab:red", linestyle=":", linewidth=1.0)
        ax.set_xlabel(f"{axis} (mm)")
        ax.set_ylabel(f"amplitude ({unit})")
        label = "W" if axis == "x" else "H"
        ax.set_title(f"{label} = {size * _MM:.2f} mm, {axis}c = {c * _MM:.2f} mm")
        ax.legend(loc="upper right", fontsize="small")
    return _finish(fig, "plot_aperture_fit",
                   f"W = {w * _MM:.2f} mm, H = {h * _MM:.2f} mm, "
                   f"centre ({cx * _MM:.2f}, {cy * _MM:.2f}) mm.")


def plot_lens_fit(
    y,
    delay_measured,
    delay_model,
    *,
    focus: float,
    weights=None,
    figsize: tuple[float, float] = (6.0, 3.6),
) -> Figure:
    """Phase delays along the elevation and the lens-delay fit (paper Fig. 6b).

    Parameters
    ----------
    y : array_like, shape (ny,)
        Elevation positions (m).
    delay_measured : array_like, shape (ny,) or (n_columns, ny)
        Measured phase delays τ = phase/ω (s); several rows (e.g. one per
        lateral column of the source plane) are drawn as thin grey lines.
    delay_model : array_like, shape (ny,)
        The fitted lens delays (paper eq. lens-delays or its paraxial form
        lens-delays-paraxial) on the same points (s).
    focus : float
        Fitted lens focus F (m); ``inf`` for an unfocused lens.
    weights : array_like, shape like ``delay_measured``, optional
        Fit weights (e.g. amplitude); marker size scales with them.
    figsize : (float, float)
        Figure size in inches.

    Returns
    -------
    matplotlib.figure.Figure
    """
    ys = _array("y", y, ndim=1)
    meas = _array("delay_measured", delay_measured, ndim=(1, 2))
    model = _array("delay_model", delay_model, ndim=1)
    _length("delay_measured", meas, ys.size, "y")
    _length("delay_model", model, ys.size, "y")
    try:
        f = float(focus)
    except (TypeError, ValueError) as exc:
        raise InputError(f"expected a number (m), got {focus!r}", field="focus") from exc
    if math.isnan(f):
        raise InputError("expected a number (m), got NaN", field="focus")
    rows = np.atleast_2d(meas)
    fig = _figure(figsize, right=0.15)
    ax = fig.add_subplot()
    if rows.shape[0] > 1:  # one line broken by NaN (one artist per row: ≈ 0.1 s CPU)
        gap = np.full((rows.shape[0], 1), np.nan)
        ax.plot(np.hstack([np.broadcast_to(ys * _MM, rows.shape), gap]).ravel(),
                np.hstack([rows * _NS, gap]).ravel(), "-", color="0.75", linewidth=0.6)
    if weights is not None:
        wts = np.atleast_2d(np.abs(_array("weights", weights, ndim=(1, 2))))
        if wts.shape != rows.shape:
            raise InputError(f"expected shape {meas.shape} (like delay_measured), got "
                             f"{np.shape(weights)}", field="weights")
        wmax = float(np.nanmax(wts)) if np.any(wts > 0) else 1.0
        wrow = wts.mean(axis=0) / wmax
        sizes = 4.0 + 30.0 * wrow / max(float(wrow.max()), 1e-300)
    else:
        sizes = np.full(ys.size, 10.0)
    center = np.nanmedian(rows, axis=0) if rows.shape[0] > 1 else rows[0]
    ax.scatter(ys * _MM, center * _NS, s=sizes, color="0.25", label="measured", zorder=3)
    ax.plot(ys * _MM, model * _NS, "-", color="tab:red", linewidth=1.5, label="fit", zorder=4)
    ax.set_xlabel("y (mm)")
    ax.set_ylabel("phase delay (ns)")
    focus_text = "F = ∞" if math.isinf(f) else f"F = {f * _MM:.1f} mm"
    ax.set_title(focus_text)
    ax.legend(loc="best", fontsize="small")
    return _finish(fig, "plot_lens_fit", f"{focus_text}.")


def plot_array_geometry(
    positions,
    normals,
    values,
    *,
    widths=None,
    heights=None,
    dead: Sequence[int] = (),
    weak: Sequence[int] = (),
    label: str = "relative amplitude (1)",
    figsize: tuple[float, float] = (7.0, 4.0),
    empty=None,
) -> Figure:
    """The array drawn where its elements are, each coloured by a per-element value.

    A curved array (normals not all parallel) is drawn in its xz plane: every element a
    segment of its width across its normal, the normals as short ticks; a flat array
    (a matrix) is drawn in its xy plane as a picture of the grid: every element a filled
    rectangle of its width × height at its centre (the kerfs left blank).

    Parameters
    ----------
    positions, normals : array_like, shape (N, 3)
        Element centres (m) and unit normals (:class:`holoprobe.geometry.ArrayGeometry`).
    values : array_like, shape (N,)
        The colour of each element (e.g. the relative transmit amplitude).
    widths : array_like, shape (N,), optional
        Element widths in m (along the arc, or along x for a flat array; default the
        spacing of the centres, × 0.9 for a flat array).
    heights : array_like, shape (N,), optional
        Element heights along y in m (flat arrays; default as ``widths`` along y).
    dead, weak : sequence of int
        0-based indices marked with red crosses / orange circles.
    label : str
        Colour-bar label with its unit.
    figsize : (float, float)
        Inches.
    empty : array_like, shape (M, 2), optional
        Flat arrays: centres (m) of the lattice positions a sparse array leaves empty,
        drawn as grey outlines of the elements' size (no colour value).

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib
    from matplotlib.collections import LineCollection, PolyCollection

    p = _array("positions", positions, ndim=2)
    n = _array("normals", normals, ndim=2)
    v = _array("values", values, ndim=1)
    _length("values", v, p.shape[0], "positions")
    dead_i = np.asarray(list(dead), int)
    fig = Figure(figsize=figsize, layout="constrained")
    ax = fig.subplots()
    curved = not np.allclose(n, n[:1])
    if curved:
        w = (np.full(v.size, np.median(np.linalg.norm(np.diff(p, axis=0), axis=1)))
             if widths is None else _array("widths", widths, ndim=1))
        tangent = np.stack([n[:, 2], np.zeros(v.size), -n[:, 0]], axis=-1)
        ends = np.stack([p - 0.5 * w[:, None] * tangent, p + 0.5 * w[:, None] * tangent], 1)
        segs = ends[:, :, [0, 2]] * _MM
        lines = LineCollection(list(segs), array=v, cmap="viridis", linewidths=6)
        ax.add_collection(lines)
        tick = np.stack([p, p + 1.5 * np.median(w) * n], axis=1)[:, :, [0, 2]] * _MM
        ax.add_collection(LineCollection(list(tick), colors="0.6", linewidths=0.6))
        fig.colorbar(lines, ax=ax, label=label)
        xy = p[:, [0, 2]] * _MM
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("z (mm)")
        ax.autoscale()
        angle = np.degrees(np.arctan2(n[[0, -1], 0], n[[0, -1], 2]))
        title = (f"{v.size} elements on an arc from {angle[0]:.1f}° to {angle[1]:.1f}°")
    else:
        xy = p[:, :2] * _MM
        cells = _grid_cells(xy, widths, heights, v.size)
        # the colour scale spans the live elements; dead ones (and NaN) are grey
        cmap = matplotlib.colormaps["viridis"].with_extremes(under="0.75", bad="0.75")
        coll = PolyCollection(list(cells), array=v, cmap=cmap, edgecolors="none")
        live = np.isfinite(v) & ~np.isin(np.arange(v.size), dead_i)
        if np.any(live):
            lo, hi = float(v[live].min()), float(v[live].max())
            coll.set_clim(lo, hi if hi > lo else lo + 1e-12)
        ax.add_collection(coll)
        fig.colorbar(coll, ax=ax, label=label)
        title = f"{v.size} elements"
        holes = None if empty is None else _array("empty", empty, ndim=2)
        if holes is not None and holes.size:
            size = np.median(cells.max(axis=1) - cells.min(axis=1), axis=0)
            ax.add_collection(PolyCollection(
                list(_grid_cells(holes[:, :2] * _MM, [size[0] / _MM] * len(holes),
                                 [size[1] / _MM] * len(holes), len(holes))),
                facecolors="none", edgecolors="0.75", linewidths=0.5))
            title += f" on {v.size + len(holes)} lattice positions (sparse)"
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.autoscale()
    weak_i = np.setdiff1d(np.asarray(list(weak), int), dead_i)
    if weak_i.size:
        ax.plot(xy[weak_i, 0], xy[weak_i, 1], "o", mfc="none", color="tab:orange", ms=7,
                mew=1.5, label="weak")
    if dead_i.size:
        ax.plot(xy[dead_i, 0], xy[dead_i, 1], "x", color="red", ms=8, mew=2, label="dead")
    if dead_i.size or weak_i.size:
        ax.legend(loc="best", fontsize=7)
    ax.set_aspect("equal", adjustable="datalim")
    title += f", dead: {list(map(int, dead_i)) or 'none'}"
    ax.set_title(title)
    return _finish(fig, "plot_array_geometry", title + ".")


def _grid_cells(xy: np.ndarray, widths, heights, n: int) -> np.ndarray:
    """(N, 4, 2) corners (mm) of each flat element's rectangle about its centre ``xy``
    (mm): the given sizes (m), else 0.9 × the smallest spacing of the centres along x
    (y) (0.9 × the other one for a single row or column)."""
    def spacing(axis: int) -> float:
        u = np.unique(np.round(xy[:, axis], 6))
        return float(np.min(np.diff(u))) if u.size > 1 else math.nan

    sx, sy = spacing(0), spacing(1)
    sx, sy = (sx if math.isfinite(sx) else sy), (sy if math.isfinite(sy) else sx)
    base = 0.9 * (sx if math.isfinite(sx) else 1.0)
    w = (np.full(n, base) if widths is None
         else _array("widths", widths, ndim=1) * _MM)
    h = (np.full(n, 0.9 * sy if math.isfinite(sy) else base) if heights is None
         else _array("heights", heights, ndim=1) * _MM)
    _length("widths", w, n, "values")
    _length("heights", h, n, "values")
    corner = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    return xy[:, None, :] + corner[None] * np.stack([w, h], axis=-1)[:, None, :]


def plot_element_map(
    amplitude,
    delay,
    *,
    dead: Sequence[int] = (),
    weak: Sequence[int] = (),
    amplitude_uncertainty=None,
    receive_gain=None,
    figsize: tuple[float, float] = (7.0, 4.6),
) -> Figure:
    """Stem charts of every element's relative amplitude (and receive gain) and delay.

    Parameters
    ----------
    amplitude : array_like, shape (N,)
        Relative transmit amplitude (live mean 1).
    delay : array_like, shape (N,)
        Element delay in s (live mean 0); not drawn for dead elements.
    dead, weak : sequence of int
        0-based indices (RF column order), drawn as red crosses / orange dots.
    amplitude_uncertainty : array_like, shape (N,), optional
        Standard uncertainties drawn as error bars.
    receive_gain : array_like, shape (N,), optional
        Relative receive gain, drawn beside the amplitude.
    figsize : (float, float)
        Inches.

    Returns
    -------
    matplotlib.figure.Figure
    """
    a = _array("amplitude", amplitude, ndim=1)
    d = _array("delay", delay, ndim=1)
    _length("delay", d, a.size, "amplitude")
    idx = np.arange(a.size)
    dead_i = np.asarray(list(dead), int)
    weak_i = np.asarray(list(weak), int)
    fig = _figure(figsize, right=0.15, hspace=0.5, nrows=2)
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    ax1.stem(idx, a, basefmt=" ", label="transmit amplitude")
    if amplitude_uncertainty is not None:
        u = _array("amplitude_uncertainty", amplitude_uncertainty, ndim=1)
        ax1.errorbar(idx, a, yerr=u, fmt="none", ecolor="0.4", lw=0.8)
    if receive_gain is not None:
        g = _array("receive_gain", receive_gain, ndim=1)
        _length("receive_gain", g, a.size, "amplitude")
        ax1.plot(idx, g, "s", ms=3, color="tab:green", label="receive gain")
    ax1.axhline(1.0, color="0.6", lw=0.8)
    if dead_i.size:
        ax1.plot(dead_i, a[dead_i], "x", color="red", ms=9, mew=2, label="dead")
    if weak_i.size:
        ax1.plot(weak_i, a[weak_i], "o", mfc="none", color="tab:orange", ms=9, label="weak")
    ax1.set_ylabel("relative amplitude (1)")
    ax1.set_xlabel("element (0-based, RF column order)")
    ax1.legend(loc="lower center", fontsize=7, ncol=4)
    live = np.ones(a.size, bool)
    live[dead_i] = False
    ax2.stem(idx[live], d[live] * _NS, basefmt=" ")
    for i in dead_i:
        ax2.axvline(i, color="red", lw=1.0, ls=":")
    ax2.set_ylabel("delay (ns)")
    ax2.set_xlabel("element (0-based, RF column order)")
    title = f"{a.size} elements, dead: {list(map(int, dead_i)) or 'none'}"
    if weak_i.size:
        title += f", weak: {list(map(int, weak_i))}"
    # a long list would run off the figure: the title counts, the caption lists them
    ax1.set_title(title if len(title) <= 72 else
                  f"{a.size} elements, {dead_i.size} dead, {weak_i.size} weak (see caption)")
    spread = float(np.std(a[live & ~np.isin(idx, weak_i)])) if live.any() else float("nan")
    return _finish(fig, "plot_element_map", f"{title}; amplitude spread {spread:.1%} rms.")


def plot_mean_velocity(
    time,
    signal,
    onset: float,
    *,
    threshold: float | None = None,
    ylabel: str = "ρ0c0 · mean velocity (Pa)",
    figsize: tuple[float, float] = (6.0, 3.2),
) -> Figure:
    """Source-averaged signal after lens-delay reversal, with the onset t0 (paper Fig. 6c).

    Parameters
    ----------
    time : array_like, shape (nt,)
        Sample times (s).
    signal : array_like, shape (nt,)
        ρ0c0 times the mean normal velocity over the aperture (Pa), or any
        signal named by ``ylabel``.
    onset : float
        Estimated onset t0 (s); marked with a red circle on the curve.
    threshold : float, optional
        Noise threshold used by the onset detector (same unit as ``signal``);
        drawn as ±threshold dotted lines.
    ylabel : str
        Label of the vertical axis, including its unit in parentheses.
    figsize : (float, float)
        Figure size in inches.

    Returns
    -------
    matplotlib.figure.Figure
    """
    return _onset_figure("plot_mean_velocity", time, signal, onset, threshold, ylabel, figsize)


def _onset_figure(kind: str, time, signal, onset: float, threshold: float | None,
                  ylabel: str, figsize: tuple[float, float]) -> Figure:
    """One trace with its onset t0 marked (the figure of plot_mean_velocity and
    plot_averaged_rf); ``kind`` names the figure for its caption."""
    t = _array("time", time, ndim=1)
    s = _array("signal", signal, ndim=1)
    _length("signal", s, t.size, "time")
    t0 = _finite_float("onset", onset)
    thr = _optional_float("threshold", threshold)
    fig = _figure(figsize, right=0.15)
    ax = fig.add_subplot()
    _trace_with_onset(ax, t, s, t0, thr)
    ax.set_xlabel("time (µs)")
    ax.set_ylabel(ylabel)
    ax.set_title(f"t0 = {t0 * _US:.3f} µs")
    return _finish(fig, kind, f"t0 = {t0 * _US:.3f} µs.")


def _trace_with_onset(ax, t, s, t0, threshold) -> None:
    ax.plot(t * _US, s, "-", color="tab:blue", linewidth=1.0)
    ax.plot([t0 * _US], [np.interp(t0, t, s)], "o", markerfacecolor="none",
            markeredgecolor="tab:red", markersize=9, markeredgewidth=1.5, label="t0")
    if threshold is not None:
        for level in (threshold, -threshold):
            ax.axhline(level, color="0.5", linestyle=":", linewidth=0.9)
    ax.axhline(0.0, color="0.8", linewidth=0.6, zorder=0)
    ax.legend(loc="upper right", fontsize="small")


def plot_impulse_response(
    time,
    ir,
    frequency,
    spectrum_db,
    *,
    label: str,
    unit: str,
    peak_frequency: float,
    band: tuple[float, float],
    level_db: float = -6.0,
    max_frequency: float | None = None,
    figsize: tuple[float, float] = (9.0, 3.2),
) -> Figure:
    """Impulse response and its spectrum with the band above ``level_db`` (paper Figs. 6d, 7f).

    Parameters
    ----------
    time : array_like, shape (nt,)
        Sample times (s).
    ir : array_like, shape (nt,)
        The impulse response in ``unit`` (e.g. ρ0c0 times the transmit IR in
        Pa/(V·s), or the receive IR in V/(Pa·s)).
    frequency : array_like, shape (nf,)
        Frequencies of the spectrum (Hz).
    spectrum_db : array_like, shape (nf,)
        Magnitude spectrum in dB (normalised to 0 dB at the peak, or not).
    label : str
        What it is ("transmit", "receive").
    unit : str
        Unit of ``ir``.
    peak_frequency : float
        Frequency of the spectral peak (Hz).
    band : (float, float)
        Lower and upper edge of the band above ``level_db`` (Hz).
    level_db : float
        The level that defines ``band`` relative to the peak (dB), drawn as a line.
    max_frequency : float, optional
        Upper limit of the spectrum axis (Hz); default: the last frequency.
    figsize : (float, float)
        Figure size in inches.

    Returns
    -------
    matplotlib.figure.Figure
    """
    t = _array("time", time, ndim=1)
    h = _array("ir", ir, ndim=1)
    _length("ir", h, t.size, "time")
    f = _array("frequency", frequency, ndim=1)
    spec = _array("spectrum_db", spectrum_db, ndim=1)
    _length("spectrum_db", spec, f.size, "frequency")
    fp = _finite_float("peak_frequency", peak_frequency)
    b = _array("band", band, ndim=1)
    if b.size != 2 or not np.all(np.isfinite(b)) or b[0] > b[1]:
        raise InputError(f"expected (lower, upper) in Hz with lower <= upper, got {band!r}",
                         field="band")
    fig = _figure(figsize, wspace=0.95, right=0.15, ncols=2)
    ax_t, ax_f = fig.subplots(1, 2)
    ax_t.plot(t * _US, h, "-", color="tab:blue", linewidth=1.0)
    ax_t.axhline(0.0, color="0.8", linewidth=0.6, zorder=0)
    ax_t.set_xlabel("time (µs)")
    ax_t.set_ylabel(f"impulse response ({unit})")
    ax_t.set_title(label)
    ax_f.plot(f * _MHZ, spec, "-", color="tab:blue", linewidth=1.0)
    ax_f.axvspan(b[0] * _MHZ, b[1] * _MHZ, color="tab:green", alpha=0.15,
                 label=f"{level_db:g} dB band".replace("-", "−"))
    peak_level = float(np.interp(fp, f, spec))
    ax_f.axhline(peak_level + level_db, color="0.5", linestyle=":", linewidth=0.9)
    ax_f.plot([fp * _MHZ], [peak_level], "v", color="tab:red", label="peak")
    ax_f.set_xlabel("frequency (MHz)")
    ax_f.set_ylabel("magnitude (dB)")
    fmax = f[-1] if max_frequency is None else _finite_float("max_frequency", max_frequency)
    ax_f.set_xlim(max(f[0], 0.0) * _MHZ, fmax * _MHZ)
    finite = spec[np.isfinite(spec)]
    if finite.size:
        ax_f.set_ylim(max(float(finite.min()), peak_level - 60.0) - 3.0, peak_level + 3.0)
    ax_f.legend(loc="upper right", fontsize="small")
    level_text = f"{level_db:g}".replace("-", "−")
    details = (f"{label.capitalize()}: peak {fp * _MHZ:.2f} MHz, {level_text} dB band "
               f"{b[0] * _MHZ:.2f}–{b[1] * _MHZ:.2f} MHz.")
    ax_f.set_title(f"peak {fp * _MHZ:.2f} MHz, band {b[0] * _MHZ:.2f}–{b[1] * _MHZ:.2f} MHz")
    return _finish(fig, "plot_impulse_response", details)


def plot_orientation(
    kx,
    ky,
    spectrum_db,
    curves: Sequence[np.ndarray] = (),
    *,
    wavenumber: float | None = None,
    dynamic_range_db: float = 40.0,
    angles_deg: tuple[float, float, float] | None = None,
    figsize: tuple[float, float] = (5.0, 4.2),
) -> Figure:
    """Angular spectrum of the scan with the fitted integration curves (paper Fig. 3).

    Parameters
    ----------
    kx, ky : array_like, shape (nkx,), (nky,)
        Wavenumbers of the spectrum's first and second axis (rad/m), increasing.
    spectrum_db : array_like, shape (nkx, nky)
        Angular spectrum magnitude in dB.
    curves : sequence of array_like, each shape (n, 2)
        The fitted integration curves (kx, ky) in rad/m (e.g. the rotated
        kx = 0 and ky = 0 curves of paper section II D).
    wavenumber : float, optional
        k = ω/c0 (rad/m); draws the circle kx² + ky² = k².
    dynamic_range_db : float
        Colour range below the maximum (dB).
    angles_deg : (float, float, float), optional
        Estimated (θx, θy, θz) in degrees, shown in the title and caption.
    figsize : (float, float)
        Figure size in inches.

    Returns
    -------
    matplotlib.figure.Figure
    """
    kxs = _array("kx", kx, ndim=1)
    kys = _array("ky", ky, ndim=1)
    spec = _array("spectrum_db", spectrum_db, ndim=2)
    if spec.shape != (kxs.size, kys.size):
        raise InputError(f"expected shape (len(kx), len(ky)) = ({kxs.size}, {kys.size}), "
                         f"got {spec.shape}", field="spectrum_db")
    fig = _figure(figsize, left=0.7, right=0.8)
    ax = fig.add_subplot()
    top = float(np.nanmax(spec))
    im = ax.imshow(spec.T, origin="lower", extent=_extent(kxs, kys, _RAD_PER_MM),
                   cmap="magma", vmin=top - dynamic_range_db, vmax=top, aspect="equal",
                   interpolation="nearest")
    fig.colorbar(im, ax=ax, shrink=0.9).set_label("magnitude (dB)")
    for i, curve in enumerate(curves):
        c = _array(f"curves[{i}]", curve, ndim=2)
        if c.shape[1] != 2:
            raise InputError(f"expected shape (n, 2) in rad/m, got {c.shape}",
                             field=f"curves[{i}]")
        ax.plot(c[:, 0] * _RAD_PER_MM, c[:, 1] * _RAD_PER_MM, "-", color="tab:red",
                linewidth=1.2)
    if wavenumber is not None:
        k = _finite_float("wavenumber", wavenumber) * _RAD_PER_MM
        phi = np.linspace(0.0, 2.0 * np.pi, 361)
        ax.plot(k * np.cos(phi), k * np.sin(phi), "-", color="white", linewidth=0.8)
    ax.set_xlim(kxs[0] * _RAD_PER_MM, kxs[-1] * _RAD_PER_MM)
    ax.set_ylim(kys[0] * _RAD_PER_MM, kys[-1] * _RAD_PER_MM)
    ax.set_xlabel("kx (rad/mm)")
    ax.set_ylabel("ky (rad/mm)")
    details = ""
    if angles_deg is not None:
        a = _array("angles_deg", angles_deg, ndim=1)
        if a.size != 3:
            raise InputError("expected (θx, θy, θz) in degrees", field="angles_deg")
        details = f"Estimated θx = {a[0]:.3f}°, θy = {a[1]:.3f}°, θz = {a[2]:.3f}°."
        ax.set_title(f"θ = ({a[0]:.2f}°, {a[1]:.2f}°, {a[2]:.2f}°)")
    return _finish(fig, "plot_orientation", details)


def plot_receive_geometry(
    *,
    source: Sequence[float],
    scan_plane: Sequence[float],
    reflector: Sequence[float],
    sensor: Sequence[float],
    path=None,
    lateral_axis: str = "x",
    figsize: tuple[float, float] = (6.0, 4.0),
) -> Figure:
    """Side view of the receive experiment (paper Fig. 7a).

    Each object is drawn as a line segment in the (lateral, z) plane.

    Parameters
    ----------
    source, scan_plane, reflector, sensor : sequence of 4 floats
        ``(center_lateral, center_z, length, tilt)`` of the virtual source,
        the measurement plane, the reflector and the virtual sensor: centre
        (m), extent along the drawing's lateral axis (m), and the rotation
        about the axis normal to the drawing (rad; positive turns the
        segment's +lateral end towards −z, like θy for the x axis).
    path : array_like, shape (n, 2), optional
        The fastest path between source and sensor, (lateral, z) points in m;
        drawn red.
    lateral_axis : str
        Name of the drawing's horizontal axis ("x" or "y").
    figsize : (float, float)
        Figure size in inches.

    Returns
    -------
    matplotlib.figure.Figure
    """
    objects = {"source": source, "scan_plane": scan_plane, "reflector": reflector,
               "sensor": sensor}
    styles = {
        "source": ("virtual source", "tab:blue", "-"),
        "scan_plane": ("measurement plane", "tab:green", "--"),
        "reflector": ("reflector", "0.3", "-"),
        "sensor": ("virtual sensor", "tab:purple", "-"),
    }
    fig = _figure(figsize, left=0.7, right=0.15, top=0.15)
    ax = fig.add_subplot()
    for name, spec in objects.items():
        s = _array(name, spec, ndim=1)
        if s.size != 4 or not np.all(np.isfinite(s)):
            raise InputError("expected (center_lateral, center_z, length, tilt) in m, m, m, "
                             f"rad, got {spec!r}", field=name)
        c_lat, c_z, length, tilt = s
        half = 0.5 * length * np.array([-1.0, 1.0])
        lat = c_lat + half * np.cos(tilt)
        z = c_z - half * np.sin(tilt)
        label, color, style = styles[name]
        ax.plot(lat * _MM, z * _MM, style, color=color, linewidth=2.5 if name == "reflector"
                else 1.8, label=label)
        ax.plot([c_lat * _MM], [c_z * _MM], ".", color=color)
    if path is not None:
        p = _array("path", path, ndim=2)
        if p.shape[1] != 2:
            raise InputError(f"expected shape (n, 2) in m, got {p.shape}", field="path")
        ax.plot(p[:, 0] * _MM, p[:, 1] * _MM, "-", color="tab:red", linewidth=1.0,
                label="fastest path")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"{lateral_axis} (mm)")
    ax.set_ylabel("z (mm)")
    ax.legend(loc="best", fontsize="small")
    refl_z = float(np.asarray(reflector, dtype=float)[1])
    sens = np.asarray(sensor, dtype=float)
    details = (f"Reflector at z = {refl_z * _MM:.2f} mm; virtual sensor centre "
               f"({sens[0] * _MM:.2f}, {sens[1] * _MM:.2f}) mm, tilt "
               f"{math.degrees(sens[3]):.3f}°.")
    return _finish(fig, "plot_receive_geometry", details)


def _element_image(fig, ax, time, data, *, name: str, clabel: str, cmap: str = "RdBu_r"):
    t = _array("time", time, ndim=1)
    d = _array(name, data, ndim=2)
    _length(name, d, t.size, "time")
    n_el = d.shape[0]
    vmax = float(np.nanmax(np.abs(d))) or 1.0
    extent = [0.5, n_el + 0.5, *(_extent(t, t, _US)[2:])]
    im = ax.imshow(d.T, origin="lower", extent=extent, cmap=cmap, vmin=-vmax, vmax=vmax,
                   aspect="auto", interpolation="nearest")
    fig.colorbar(im, ax=ax, shrink=0.9).set_label(clabel)
    ax.set_xlabel("element (index)")
    ax.set_ylabel("time (µs)")
    return t, d


def plot_element_rf(
    time,
    rf,
    arrival_times,
    fitted_line,
    *,
    unit: str = "V",
    time_window: tuple[float, float] | None = None,
    figsize: tuple[float, float] = (6.0, 4.0),
) -> Figure:
    """Element RF of the reflector echo with the fitted arrival line (paper Fig. 7b).

    Parameters
    ----------
    time : array_like, shape (nt,)
        Sample times (s).
    rf : array_like, shape (n_elements, nt)
        RF per element (time last), in ``unit``.
    arrival_times : array_like, shape (n_elements,)
        Estimated echo arrival per element (s); NaN for elements left out of
        the fit.
    fitted_line : array_like, shape (n_elements,)
        The fitted arrival line evaluated at every element (s).
    unit : str
        Unit of the RF ("V", "ADCL").
    time_window : (float, float), optional
        Time range to show (s); default: all of ``time``.
    figsize : (float, float)
        Figure size in inches. Elements are numbered from 1.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig = _figure(figsize, left=0.7, right=1.0, top=0.15)
    ax = fig.add_subplot()
    _, d = _element_image(fig, ax, time, rf, name="rf", clabel=f"RF ({unit})")
    n_el = d.shape[0]
    arr = _array("arrival_times", arrival_times, ndim=1)
    line = _array("fitted_line", fitted_line, ndim=1)
    _length("arrival_times", arr, n_el, "the element axis of rf")
    _length("fitted_line", line, n_el, "the element axis of rf")
    elements = np.arange(1, n_el + 1)
    ax.plot(elements, arr * _US, ".", color="black", markersize=3, label="arrival")
    ax.plot(elements, line * _US, "-", color="tab:green", linewidth=1.3, label="line fit")
    if time_window is not None:
        tw = _array("time_window", time_window, ndim=1)
        if tw.size != 2:
            raise InputError("expected (start, stop) in s", field="time_window")
        ax.set_ylim(tw[0] * _US, tw[1] * _US)
    ax.legend(loc="upper right", fontsize="small")
    used = int(np.count_nonzero(np.isfinite(arr)))
    slope = (line[-1] - line[0]) / max(n_el - 1, 1)
    return _finish(fig, "plot_element_rf",
                   f"{used} of {n_el} elements used; fitted slope "
                   f"{slope * _NS:.3f} ns per element.")


def plot_averaged_rf(
    time,
    signal,
    onset: float,
    *,
    threshold: float | None = None,
    unit: str = "V",
    figsize: tuple[float, float] = (6.0, 3.2),
) -> Figure:
    """Averaged (tilt-aligned) receive RF with the onset t0 (paper Fig. 7c).

    Parameters
    ----------
    time : array_like, shape (nt,)
        Sample times (s).
    signal : array_like, shape (nt,)
        The averaged RF in ``unit``.
    onset : float
        Onset t0 of the echo (s).
    threshold : float, optional
        Noise threshold of the onset detector (``unit``).
    unit : str
        Unit of the RF.
    figsize : (float, float)
        Figure size in inches.

    Returns
    -------
    matplotlib.figure.Figure
    """
    return _onset_figure("plot_averaged_rf", time, signal, onset, threshold,
                         f"averaged RF ({unit})", figsize)


def plot_receive_pressure(
    time,
    pressure_per_element,
    *,
    unit: str = "Pa",
    figsize: tuple[float, float] = (6.0, 4.0),
) -> Figure:
    """Receive pressure per element from the forward projection (paper Fig. 7d).

    Parameters
    ----------
    time : array_like, shape (nt,)
        Sample times (s).
    pressure_per_element : array_like, shape (n_elements, nt)
        Pressure averaged over each element's surface after lens-delay
        reversal (Pa).
    unit : str
        Unit of the pressure.
    figsize : (float, float)
        Figure size in inches.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig = _figure(figsize, left=0.7, right=1.0, top=0.15)
    ax = fig.add_subplot()
    _, d = _element_image(fig, ax, time, pressure_per_element, name="pressure_per_element",
                          clabel=f"pressure ({unit})")
    peak = float(np.nanmax(np.abs(d)))
    return _finish(fig, "plot_receive_pressure",
                   f"{d.shape[0]} elements; peak |p| = {_fmt(peak, 3)} {unit}.")


def plot_deconvolution_spectra(
    frequency,
    Y_db,
    P_db,
    H_db,
    *,
    band: tuple[float, float] | None = None,
    labels: tuple[str, str, str] = ("Y: received voltage", "P: received pressure",
                                    "H: receive transfer function"),
    max_frequency: float | None = None,
    dynamic_range_db: float | None = 80.0,
    figsize: tuple[float, float] = (6.0, 3.6),
) -> Figure:
    """The three spectra of the receive deconvolution (paper Fig. 7e, eq. deconvolution-receive).

    Parameters
    ----------
    frequency : array_like, shape (nf,)
        Frequencies (Hz).
    Y_db, P_db, H_db : array_like, shape (nf,)
        Magnitudes in dB of the received voltage spectrum Y, the received
        pressure spectrum P and the receive transfer function H = Y/P/(…)
        (each normalised as the caller prefers, e.g. to its own maximum).
    band : (float, float), optional
        Band of the result (Hz), shaded.
    labels : (str, str, str)
        Legend entries of Y, P and H.
    max_frequency : float, optional
        Upper limit of the frequency axis (Hz).
    dynamic_range_db : float, optional
        Show levels down to this many dB below the highest curve (None: all).
    figsize : (float, float)
        Figure size in inches.

    Returns
    -------
    matplotlib.figure.Figure
    """
    f = _array("frequency", frequency, ndim=1)
    fig = _figure(figsize, left=0.7, right=0.15, top=0.15)
    ax = fig.add_subplot()
    top = -np.inf
    for name, values, label, color in zip(
        ("Y_db", "P_db", "H_db"), (Y_db, P_db, H_db), labels,
        ("tab:blue", "tab:orange", "tab:red"), strict=True,
    ):
        v = _array(name, values, ndim=1)
        _length(name, v, f.size, "frequency")
        ax.plot(f * _MHZ, v, "-", color=color, linewidth=1.1, label=label)
        if np.any(np.isfinite(v)):
            top = max(top, float(np.nanmax(v[np.isfinite(v)])))
    if dynamic_range_db is not None and np.isfinite(top):
        ax.set_ylim(top - abs(float(dynamic_range_db)), top + 5.0)
    if band is not None:
        b = _array("band", band, ndim=1)
        if b.size != 2:
            raise InputError("expected (lower, upper) in Hz", field="band")
        ax.axvspan(b[0] * _MHZ, b[1] * _MHZ, color="tab:green", alpha=0.12)
    if max_frequency is not None:
        ax.set_xlim(0.0, _finite_float("max_frequency", max_frequency) * _MHZ)
    ax.set_xlabel("frequency (MHz)")
    ax.set_ylabel("magnitude (dB)")
    ax.legend(loc="best", fontsize="small")
    return _finish(fig, "plot_deconvolution_spectra")


def plot_transfer_functions(
    frequency,
    transmit,
    receive,
    *,
    floor_db: float = -40.0,
    max_frequency: float | None = None,
    figsize: tuple[float, float] = (9.0, 3.2),
) -> Figure:
    """Normalised transmit and receive transfer functions side by side (paper Fig. 10a).

    Parameters
    ----------
    frequency : array_like, shape (nf,)
        Frequencies (Hz).
    transmit, receive : array_like, shape (nf,)
        H_T and H_R: complex transfer functions, or magnitudes. Each is
        normalised to its own maximum magnitude.
    floor_db : float
        Lowest level shown (dB, < 0).
    max_frequency : float, optional
        Upper limit of the frequency axis (Hz).
    figsize : (float, float)
        Figure size in inches.

    Returns
    -------
    matplotlib.figure.Figure
        Magnitude (dB) on the left; if both inputs are complex, the unwrapped
        phase (rad) over the band above ``floor_db`` on the right, otherwise
        the linear normalised magnitude.
    """
    f = _array("frequency", frequency, ndim=1)
    ht = _array("transmit", transmit, ndim=1, complex_ok=True)
    hr = _array("receive", receive, ndim=1, complex_ok=True)
    _length("transmit", ht, f.size, "frequency")
    _length("receive", hr, f.size, "frequency")
    if not floor_db < 0:
        raise InputError(f"expected a negative level in dB, got {floor_db}", field="floor_db")
    fig = _figure(figsize, left=0.75, right=0.15, top=0.15, wspace=0.85, ncols=2)
    ax_m, ax_2 = fig.subplots(1, 2, sharex=True)
    with_phase = np.iscomplexobj(ht) and np.iscomplexobj(hr)
    peaks = []
    for h, label, color in ((ht, "transmit |H_T|", "tab:blue"),
                            (hr, "receive |H_R|", "tab:red")):
        mag = np.abs(h)
        level = _to_db(mag, floor_db=floor_db)
        ax_m.plot(f * _MHZ, level, "-", color=color, linewidth=1.2, label=label)
        peaks.append(float(f[int(np.argmax(mag))]))
        if with_phase:
            keep = level > floor_db
            phase = np.full(f.size, np.nan)
            if np.any(keep):
                idx = np.flatnonzero(keep)
                seg = slice(idx[0], idx[-1] + 1)
                phase[seg] = np.unwrap(np.angle(h[seg]))
            ax_2.plot(f * _MHZ, phase, "-", color=color, linewidth=1.2,
                      label=label.split()[0])
        else:
            peak = float(mag.max()) or 1.0
            ax_2.plot(f * _MHZ, mag / peak, "-", color=color, linewidth=1.2,
                      label=label.split()[0])
    ax_m.set_ylim(floor_db - 2.0, 3.0)
    ax_m.set_xlabel("frequency (MHz)")
    ax_m.set_ylabel("normalised magnitude (dB)")
    ax_m.legend(loc="best", fontsize="small")
    ax_2.set_xlabel("frequency (MHz)")
    if with_phase:
        ax_2.set_ylabel("phase (rad)")
    else:
        ax_2.set_ylabel("normalised magnitude (1)")
    ax_2.legend(loc="best", fontsize="small")
    if max_frequency is not None:
        ax_m.set_xlim(0.0, _finite_float("max_frequency", max_frequency) * _MHZ)
    return _finish(fig, "plot_transfer_functions",
                   f"Peaks: transmit {peaks[0] * _MHZ:.2f} MHz, "
                   f"receive {peaks[1] * _MHZ:.2f} MHz.")


def plot_hydrophone_deconvolution(
    time,
    voltage,
    pressure,
    u_pressure,
    frequency,
    voltage_db,
    pressure_db,
    calibration_frequency,
    calibration_db,
    *,
    cutoff_hz: float | None = None,
    coverage: float = 2.0,
    figsize: tuple[float, float] = (7.0, 7.5),
) -> Figure:
    """Voltage, deconvolved pressure with a ±k·u band, and the spectra (IEC 62127-1).

    Parameters
    ----------
    time : array_like, shape (n,)
        Sample times (s).
    voltage, pressure, u_pressure : array_like, shape (n,)
        Offset-free voltage (V), pressure (Pa) and its standard uncertainty (Pa).
    frequency : array_like, shape (nf,)
        Frequencies of the spectra (Hz).
    voltage_db, pressure_db : array_like, shape (nf,)
        Spectrum magnitudes in dB (each re its own maximum).
    calibration_frequency, calibration_db : array_like, shape (m,)
        Calibration frequencies (Hz) and sensitivity magnitude in dB re 1 V/Pa.
    cutoff_hz : float, optional
        −3 dB frequency of the regularising filter, marked.
    coverage : float
        Coverage factor k of the shaded band.
    figsize : (float, float)
        Inches.

    Returns
    -------
    matplotlib.figure.Figure
    """
    t = _array("time", time, ndim=1)
    f = _array("frequency", frequency, ndim=1)
    fig = Figure(figsize=figsize, layout="constrained")
    ax_v, ax_p, ax_f = fig.subplots(3, 1)
    v = _array("voltage", voltage, ndim=1)
    p = _array("pressure", pressure, ndim=1)
    u = _array("u_pressure", u_pressure, ndim=1)
    for name, arr in (("voltage", v), ("pressure", p), ("u_pressure", u)):
        _length(name, arr, t.size, "time")
    ax_v.plot(t * _US, v * 1e3, color="tab:blue", linewidth=0.9)
    ax_v.set_xlabel("time (µs)")
    ax_v.set_ylabel("voltage (mV)")
    ax_p.fill_between(t * _US, (p - coverage * u) * 1e-6, (p + coverage * u) * 1e-6,
                      color="tab:orange", alpha=0.3, linewidth=0,
                      label=f"±{coverage:g} u (k = {coverage:g})")
    ax_p.plot(t * _US, p * 1e-6, color="tab:orange", linewidth=0.9, label="pressure")
    ax_p.set_xlabel("time (µs)")
    ax_p.set_ylabel("pressure (MPa)")
    ax_p.legend(loc="best", fontsize="small")
    for name, values, label, color in (("voltage_db", voltage_db, "voltage", "tab:blue"),
                                       ("pressure_db", pressure_db, "pressure", "tab:orange")):
        arr = _array(name, values, ndim=1)
        _length(name, arr, f.size, "frequency")
        ax_f.plot(f * _MHZ, arr, color=color, linewidth=1.0, label=label)
    ax_f.set_ylim(-80.0, 5.0)
    ax_f.set_xlabel("frequency (MHz)")
    ax_f.set_ylabel("spectrum (dB re max)")
    ax_c = ax_f.twinx()
    fc = _array("calibration_frequency", calibration_frequency, ndim=1)
    cdb = _array("calibration_db", calibration_db, ndim=1)
    _length("calibration_db", cdb, fc.size, "calibration_frequency")
    ax_c.plot(fc * _MHZ, cdb, color="tab:green", linewidth=1.0, label="calibration |M|")
    ax_c.set_ylabel("sensitivity (dB re 1 V/Pa)", color="tab:green")
    ax_c.set_xlabel("frequency (MHz)")  # the twin's x axis is hidden; labelled for readers
    details = ""
    if cutoff_hz is not None:
        fcut = _finite_float("cutoff_hz", cutoff_hz)
        ax_f.axvline(fcut * _MHZ, color="k", linestyle=":", linewidth=1.0,
                     label="filter −3 dB")
        details = f"Filter −3 dB at {_fmt(fcut * _MHZ)} MHz."
    ax_f.set_xlim(0.0, float(max(f[-1], fc[-1])) * _MHZ)
    ax_f.legend(loc="lower left", fontsize="small")
    return _finish(fig, "plot_hydrophone_deconvolution", details)
