"""Source representation: monopole (rigid baffle) vs dipole (soft baffle) sources, by two
propagation methods (paper sections II C and IV C, Fig. 2).

The virtual transducer's surface velocity U (paper eqs. transmit-impulse-response,
lens-delays) radiates either as monopoles, ``P = Σ K_vp^fwd U dΣ`` (rigid baffle, paper eq.
rayleigh-fwd-vp), or as dipoles from the pressure ``ρ0 c0 U`` on the aperture, ``P = Σ
K_pp^fwd ρ0c0U dΣ`` (soft baffle, paper eq. rayleigh-fwd-pp). Both are evaluated on axis by
the dense Rayleigh sum and by the angular spectrum (averaged propagators of the paper's
appendix, kinds "vp" and "pp") from the *same* sampled source, so that their difference is
the method's, not the discretisation's. The primary wavefront is nearly the same for both
representations; the edge waves differ (a dipole radiates ∝ cos θ).

When k-wave-python (optional extra ``[kwave]``) is importable, the same transmit is also
run through its pure-Python backend on a small 3-D grid around the axis
(:func:`holoprobe.export.kwave_plane_field`): monopole ``source.p = ρ0c0 u``, dipole
``source.ux = u`` (= p/(ρ0c0)). k-Wave's velocity source lives on the staggered grid, half
a step downstream of the pressure grid; the grid step is chosen so that the recorded
point lies exactly ``distance`` from the effective source plane in both cases. Its time
axis is that of :data:`holoprobe.export.KWAVE_TIME_OFFSET` (sample n at (n + ½)·dt for
the monopole, (n + 1)·dt for the dipole; measured by cross-correlation, docs/kwave.md).
The k-Wave record is band-limited to the analysis band like the other curves (its
spectrum on the same frequencies), so all methods are compared on one time axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import PlaneGrid, Surface
from holoprobe.signal import continuous_spectrum, frequency_axis, next_fast_length, to_time

__all__ = ["BaffleResult", "analyse_baffle", "baffle_figure", "kwave_available"]

_US, _MM = 1e6, 1e3


def kwave_available() -> bool:
    """Whether ``import kwave`` (the optional ``[kwave]`` extra) succeeds here (offline
    too: :func:`holoprobe.export.prepare_kwave_offline` runs first)."""
    try:
        from holoprobe.export import prepare_kwave_offline

        prepare_kwave_offline()
        import kwave  # noqa: F401
    except Exception:  # ImportError, or its download of binaries failing offline
        return False
    return True


@dataclass(frozen=True)
class BaffleResult:
    """Result of :func:`analyse_baffle`.

    Attributes
    ----------
    time : ndarray, shape (nt,)
        Sample times in s (t = 0: the drive starts).
    pressure : dict of str to ndarray, shape (nt,)
        On-axis pressure in Pa, keyed ``"<representation>/<method>"`` with representation
        ``monopole`` / ``dipole`` and method ``rayleigh`` / ``angular_spectrum`` /
        ``kwave`` (the last when k-wave-python ran).
    point : (float, float, float)
        The field point in m.
    method_difference_percent : dict of str to float
        Per representation: the largest difference between any two methods, in % of the
        largest amplitude of those curves (paper: 2.1 % monopole, 1.5 % dipole).
    representation_difference_percent : float
        Largest monopole − dipole difference (Rayleigh), % of the monopole maximum.
    primary_difference_percent : float
        The same before the first edge wave can arrive (``t < primary_end``).
    primary_end : float
        Earliest arrival (s) of an edge wave from the aperture rim (time of flight from
        the nearest edge plus the onset of the surface velocity).
    grid_step : float
        Source sampling step in m.
    frequency_band : (float, float)
        Hz.
    methods : list of str
    notes : list of str
    pairwise_difference_percent : dict of str to dict of str to float
        Per representation, per pair ``"<method>-<method>"``: the largest difference
        between the two curves in % of the largest amplitude of that representation's
        curves (the maximum over pairs is ``method_difference_percent``).
    kwave_step : float or None
        k-Wave grid step per representation is close to this, m (None: k-Wave not run).
    """

    time: NDArray[np.float64]
    pressure: dict[str, NDArray[np.float64]]
    point: tuple[float, float, float]
    method_difference_percent: dict[str, float]
    representation_difference_percent: float
    primary_difference_percent: float
    primary_end: float
    grid_step: float
    frequency_band: tuple[float, float]
    methods: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    pairwise_difference_percent: dict[str, dict[str, float]] = field(default_factory=dict)
    kwave_step: float | None = None

    def summary(self) -> dict[str, object]:
        """JSON-ready numbers (``baffle`` entry of ``summary.json``)."""
        return {"distance_m": float(self.point[2]),
                "method_difference_percent": dict(self.method_difference_percent),
                "representation_difference_percent": self.representation_difference_percent,
                "primary_difference_percent": self.primary_difference_percent,
                "primary_end_s": self.primary_end, "grid_step_m": self.grid_step,
                "frequency_band_hz": list(self.frequency_band), "methods": self.methods,
                "pairwise_difference_percent": {k: dict(v) for k, v in
                                                self.pairwise_difference_percent.items()},
                "kwave_step_m": self.kwave_step, "notes": list(self.notes)}


def _overlap(centres: NDArray, step: float, lo: NDArray, hi: NDArray) -> NDArray:
    """Length of [c − step/2, c + step/2] ∩ [lo_j, hi_j], shape (n_centres, n_intervals)."""
    a = np.maximum(centres[:, None] - 0.5 * step, lo[None, :])
    b = np.minimum(centres[:, None] + 0.5 * step, hi[None, :])
    return np.clip(b - a, 0.0, None)


def _pairwise_percent(curves: dict[str, NDArray]) -> dict[str, float]:
    """Largest |a − b| per pair of curves, % of the largest amplitude of all of them."""
    ref = max(float(np.max(np.abs(c))) for c in curves.values())
    names = list(curves)
    return {f"{a}-{b}": (100.0 * float(np.max(np.abs(curves[a] - curves[b]))) / ref
                         if ref > 0 else math.nan)
            for i, a in enumerate(names) for b in names[i + 1:]}


def analyse_baffle(
    vt: object,
    *,
    distance: float = 5e-3,
    setting: object | None = None,
    sampling_rate: float | None = None,
    points_per_wavelength: float = 4.0,
    band_threshold_db: float = -40.0,
    padding: float | None = None,
    margin: float = 0.2,
    onset_level: float = 0.01,
    kwave: bool | None = None,
    kwave_step: float | None = None,
    kwave_points_per_wavelength: float = 6.0,
    kwave_margin: float = 0.5e-3,
    kwave_pml: int = 10,
    kwave_cfl: float = 0.3,
) -> BaffleResult:
    """On-axis field of monopole and dipole source representations by Rayleigh and by the
    angular spectrum (paper Fig. 2).

    The aperture (elements of width w at pitch p, height H about the aperture centre) is
    sampled on a uniform grid of step ``c0 / f_max / points_per_wavelength``; each cell
    carries the fraction of its area covered by an element (box-filtered source), the
    element apodization and delay of ``setting`` and the exact lens delay at its centre.
    That one source is propagated to ``(x_c, y_c, distance)`` by
    :func:`holoprobe.propagation.rayleigh_integral` (``fwd_vp`` rigid / ``fwd_pp`` with
    p = ρ0c0U) and :func:`holoprobe.propagation.propagate_parallel` (kinds "vp" / "pp",
    averaged propagators, no evanescent filter: forward propagation needs the evanescent
    part close to the source). The time record runs from the emission to ``1 + margin``
    times the last arrival from the aperture corners plus the pulse length.

    Parameters
    ----------
    vt : VirtualTransducer
        The model.
    distance : float
        Distance of the on-axis point from the source plane, m (paper: 5 mm).
    setting : TransmitSetting, optional
        Default: all elements, no delays, a one-cycle 1 V burst at the peak frequency of
        the transmit IR (as the PROTEUS default of the paper's comparison).
    sampling_rate : float, optional
        Rate of the output records (Hz); default 8 × the upper band edge.
    points_per_wavelength : float
        Source sampling at the upper band edge.
    band_threshold_db : float
        Band of the transmitted spectrum (dB re peak) that is propagated.
    padding : float, optional
        Zero-padding factor of the angular spectrum. Default (automatic): per axis, the
        padded period is at least ``L/2 + c0·T`` (L the grid length, T the record
        length), so that the periodic images of the source implied by the discrete
        wavenumbers arrive after the record; at least 3. (Measured on a 6.4 × 6 mm
        aperture at 5 mm: factor 2 → 4.0 % monopole difference, 3 → 1.8 %, 4 → 1.0 %.)
    margin : float
        Extra fraction of record length.
    onset_level : float
        Relative level that defines the onset t_on of the surface velocity; the primary
        window ends at ``√(d² + r²)/c0 + t_on`` with r the distance from the axis to the
        nearest aperture edge (the first edge wave cannot arrive earlier).
    kwave : bool, optional
        Also run k-wave-python (both representations). Default: when it is importable
        (:func:`kwave_available`); True without it is an InputError.
    kwave_step : float, optional
        k-Wave grid step in m; default ``c0 / f_max / kwave_points_per_wavelength``.
        Adjusted slightly so that the field point lies on the grid (see
        :func:`holoprobe.export.kwave_plane_field`). Cost grows as step⁻⁴.
    kwave_points_per_wavelength : float
        Grid points per wavelength at the upper band edge (default step λ/6).
    kwave_margin : float
        k-Wave grid beyond the aperture on each side (lateral, elevation), m; the PML
        lies outside.
    kwave_pml : int
        PML thickness in grid points.
    kwave_cfl : float
        k-Wave time step ``cfl·dx/c0``.

    Returns
    -------
    BaffleResult
    """
    from holoprobe.signal import spectrum_summary
    from holoprobe.transducer import TransmitSetting, VirtualTransducer, burst, signal_band

    if not isinstance(vt, VirtualTransducer):
        raise InputError("expected a VirtualTransducer", field="vt")
    if not (math.isfinite(distance) and distance > 0):
        raise InputError(f"expected a positive distance in m, got {distance!r}",
                         field="distance")
    c0 = vt.medium.sound_speed
    if setting is None:
        fc = spectrum_summary(vt.transmit_impulse_response, vt.transmit_sampling_rate
                              ).peak_frequency
        setting = TransmitSetting(drive=burst(fc, 1.0, 1.0,
                                              sampling_rate=vt.transmit_sampling_rate))
    elif not isinstance(setting, TransmitSetting):
        raise InputError("expected a TransmitSetting", field="setting")
    f_lo, f_hi = signal_band(vt, setting, threshold_db=band_threshold_db)
    fs = 8.0 * f_hi if sampling_rate is None else float(sampling_rate)
    if not fs > 2 * f_hi:
        raise InputError(f"expected a rate above 2 × {f_hi:.4g} Hz", field="sampling_rate")
    src = _baffled_source(vt, setting, distance, (f_lo, f_hi), fs,
                          points_per_wavelength, margin)
    pressures = _reference_pressures(src, vt.medium, distance, padding)
    methods = ["rayleigh", "angular_spectrum"]
    notes: list[str] = []
    available = kwave_available()
    if kwave and not available:
        raise InputError("k-wave-python is not importable (optional extra [kwave])",
                         field="kwave")
    kw_step = None
    if kwave or (kwave is None and available):
        kw_step = (c0 / f_hi / kwave_points_per_wavelength if kwave_step is None
                   else float(kwave_step))
        for rep in ("monopole", "dipole"):
            kw = _kwave_axis(vt, setting, distance=distance, step=kw_step, representation=rep,
                             duration=src.duration, margin=kwave_margin,
                             pml=kwave_pml, cfl=kwave_cfl)
            pressures[f"{rep}/kwave"], note = _kwave_record(src, kw, rep, kwave_pml)
            notes.append(note)
        methods.append("kwave")
    else:
        notes.append("k-wave-python not available (optional extra [kwave]): compared "
                     "Rayleigh and angular spectrum only")
    return _baffle_result(src, pressures, methods, notes, distance, c0, onset_level,
                          (float(f_lo), float(f_hi)), kw_step)


@dataclass(frozen=True)
class _BaffledSource:
    """The transmit's surface velocity on a box-filtered grid of the baffled aperture."""

    grid: PlaneGrid
    center: tuple[float, float]
    step: float
    source: NDArray[np.complex128]  # (nx, ny, nf) m/s·s
    u0: NDArray[np.complex128]  # (nf,) drive spectrum, m/s·s
    f_all: NDArray[np.float64]
    sel: NDArray[np.intp]
    fs: float
    n: int
    duration: float  # emission to the last corner arrival plus the pulse, s
    width: float
    height: float

    @property
    def frequencies(self) -> NDArray[np.float64]:
        return self.f_all[self.sel]

    def record(self, spec: NDArray) -> NDArray[np.float64]:
        """The time record (n samples at fs) of a spectrum on :attr:`frequencies`."""
        full = np.zeros(self.f_all.size, complex)
        full[self.sel] = spec
        return to_time(full * self.fs, self.n)


def _baffled_source(vt, setting, distance: float, band: tuple[float, float], fs: float,
                    points_per_wavelength: float, margin: float) -> _BaffledSource:
    """Sample the elements (box filter, lens and element delays) on a λ/ppw grid."""
    from holoprobe.lens import lens_delays
    from holoprobe.transducer import drive_spectrum

    f_lo, f_hi = band
    c0 = vt.medium.sound_speed
    n_el = vt.element_count
    xc, yc = vt.aperture_center
    h = vt.element_height
    centres = vt.element_centers()[:, 0]
    width_total = (n_el - 1) * vt.pitch + vt.element_width
    step = c0 / f_hi / points_per_wavelength
    nx = 2 * math.ceil(0.5 * width_total / step) + 3
    ny = 2 * math.ceil(0.5 * h / step) + 3
    grid = PlaneGrid.centered(nx, ny, step, step)
    gx, gy = grid.x + xc, grid.y + yc
    cover_x = _overlap(gx, step, centres - 0.5 * vt.element_width,
                       centres + 0.5 * vt.element_width) / step  # (nx, N)
    cover_y = _overlap(gy, step, np.array([yc - 0.5 * h]), np.array([yc + 0.5 * h]))[:, 0] / step
    tau_el = setting.element_delays(vt.element_centers(), c0)
    apod = setting.element_weights(n_el)
    tau_lens = (lens_delays(np.clip(gy - yc, -0.5 * h, 0.5 * h), vt.lens_focus, h, c0)
                if math.isfinite(vt.lens_focus) else np.zeros(ny))
    # record: emission to the last corner arrival + pulse + lens/element delays
    corner = math.sqrt((0.5 * width_total + step) ** 2 + (0.5 * h + step) ** 2 + distance**2)
    pulse = (vt.transmit_impulse_response.size / vt.transmit_sampling_rate
             + setting.drive.duration + float(np.max(tau_lens)) + float(np.ptp(tau_el)))
    n = next_fast_length(math.ceil((1 + margin) * (corner / c0 + pulse) * fs))
    f_all = frequency_axis(n, fs)
    sel = np.flatnonzero((f_all >= f_lo) & (f_all <= f_hi) & (f_all > 0))
    f = f_all[sel]
    omega = 2 * np.pi * f
    ux = cover_x @ (apod[:, None] * np.exp(1j * np.outer(tau_el, omega)))  # (nx, nf)
    uy = cover_y[:, None] * np.exp(1j * np.outer(tau_lens, omega))  # (ny, nf)
    u0 = drive_spectrum(vt, setting, f)  # m/s·s
    source = ux[:, None, :] * uy[None, :, :] * u0[None, None, :]  # (nx, ny, nf)
    return _BaffledSource(grid=grid, center=(float(xc), float(yc)), step=step, source=source,
                          u0=u0, f_all=f_all, sel=sel, fs=fs, n=n,
                          duration=corner / c0 + pulse, width=width_total, height=h)


def _reference_pressures(src: _BaffledSource, medium, distance: float,
                         padding: float | None) -> dict[str, NDArray[np.float64]]:
    """Monopole and dipole pressure at the field point by the Rayleigh integrals and the
    angular spectrum (rigid baffle: monopole; soft: dipole)."""
    from holoprobe.propagation import propagate_parallel, rayleigh_integral

    grid, step, f, source = src.grid, src.step, src.frequencies, src.source
    nx, ny = grid.shape
    xc, yc = src.center
    point = (xc, yc, float(distance))
    target = Surface(np.array([point]), np.array([[0.0, 0.0, 1.0]]), np.ones(1))
    active = np.flatnonzero((np.abs(source).sum(axis=-1) > 0).reshape(-1))
    src_surface = Surface(grid.points()[active] + np.array([xc, yc, 0.0]),
                          np.tile([0.0, 0.0, 1.0], (active.size, 1)),
                          np.full(active.size, step * step))
    flat = source.reshape(-1, f.size)[active]
    z0 = medium.impedance
    centre = (nx // 2, ny // 2)
    pad_shape: float | tuple[int, ...]
    if padding is None:
        reach = medium.sound_speed * src.n / src.fs
        pad_shape = tuple(next_fast_length(max(3 * m, math.ceil((0.5 * m * step + reach)
                                                                 / step)))
                          for m in (nx, ny))
    else:
        pad_shape = padding
    return {
        "monopole/rayleigh": src.record(rayleigh_integral(
            flat, src_surface, target, f, medium, kernel="fwd_vp", baffle="rigid")[0]),
        "dipole/rayleigh": src.record(rayleigh_integral(
            z0 * flat, src_surface, target, f, medium, kernel="fwd_pp")[0]),
        "monopole/angular_spectrum": src.record(propagate_parallel(
            source, grid, f, medium, distance, kind="vp", averaged=True, evanescent=None,
            padding=pad_shape)[centre]),
        "dipole/angular_spectrum": src.record(propagate_parallel(
            z0 * source, grid, f, medium, distance, kind="pp", averaged=True, evanescent=None,
            padding=pad_shape)[centre]),
    }


def _kwave_record(src: _BaffledSource, kw, representation: str,
                  pml: int) -> tuple[NDArray[np.float64], str]:
    """k-Wave's pressure on the analysis record (its spectrum on the analysis frequencies,
    to_frequency convention, Pa·s) and a note on its grid."""
    spec = continuous_spectrum(kw.axis, 1.0 / kw.dt, src.frequencies,
                               start_time=float(kw.time[0]))
    note = (f"k-Wave {representation}: grid {kw.grid[0]}×{kw.grid[1]}×{kw.grid[2]} + PML "
            f"{pml}, step {kw.step * _MM:.4f} mm, {kw.time.size} steps "
            f"of {kw.dt * 1e9:.2f} ns, {kw.seconds_kwave:.0f} s")
    return src.record(spec), note


def _baffle_result(src: _BaffledSource, pressures: dict[str, NDArray[np.float64]],
                   methods: list[str], notes: list[str], distance: float, c0: float,
                   onset_level: float, band: tuple[float, float],
                   kw_step: float | None) -> BaffleResult:
    """Differences between the methods and between the representations (whole record,
    and before the rim's arrival)."""
    pairwise = {rep: _pairwise_percent({m: pressures[f"{rep}/{m}"] for m in methods})
                for rep in ("monopole", "dipole")}
    diffs = {rep: max(pairwise[rep].values()) for rep in ("monopole", "dipole")}
    for rep in ("monopole", "dipole"):
        notes.append(f"{rep}, max difference per pair of methods: " + ", ".join(
            f"{k.replace('_', ' ').replace('-', ' vs ')} {v:.2f} %"
            for k, v in pairwise[rep].items()))
    t = np.arange(src.n) / src.fs
    mono, dip = pressures["monopole/rayleigh"], pressures["dipole/rayleigh"]
    peak = float(np.max(np.abs(mono)))
    u_t = src.record(src.u0)
    onset = float(t[np.flatnonzero(np.abs(u_t) >= onset_level * np.max(np.abs(u_t)))[0]])
    rim = min(0.5 * src.width, 0.5 * src.height)
    primary_end = math.sqrt(distance**2 + rim**2) / c0 + onset
    early = t < primary_end
    rep_full = 100.0 * float(np.max(np.abs(mono - dip))) / peak
    rep_primary = 100.0 * float(np.max(np.abs(mono - dip)[early])) / peak if early.any() \
        else math.nan
    return BaffleResult(time=t, pressure=pressures, point=(*src.center, float(distance)),
                        method_difference_percent=diffs,
                        representation_difference_percent=rep_full,
                        primary_difference_percent=rep_primary, primary_end=primary_end,
                        grid_step=src.step, frequency_band=band,
                        methods=methods, notes=notes, pairwise_difference_percent=pairwise,
                        kwave_step=kw_step)


def _kwave_axis(vt: object, setting: object, *, distance: float, step: float,
                representation: str, duration: float, margin: float, pml: int,
                cfl: float) -> object:
    """k-Wave's field on the plane at ``distance`` (see kwave_plane_field), offline-safe."""
    from holoprobe.export import kwave_plane_field, prepare_kwave_offline

    prepare_kwave_offline()
    return kwave_plane_field(vt, setting, distance=distance, step=step,
                             representation=representation, duration=duration,
                             lateral_margin=margin, elevation_margin=margin, pml=pml,
                             cfl=cfl)


def baffle_figure(result: BaffleResult) -> tuple[Figure, str]:
    """One plot of every on-axis curve (paper Fig. 2) with the differences in its caption."""
    r = result
    fig = Figure(figsize=(8.0, 3.6), layout="constrained")
    ax = fig.subplots()
    styles = {"rayleigh": "-", "angular_spectrum": "--", "kwave": ":"}
    names = {"rayleigh": "Rayleigh", "angular_spectrum": "angular spectrum", "kwave": "k-Wave"}
    colours = {"monopole": "tab:blue", "dipole": "tab:red"}
    for key, p in r.pressure.items():
        rep, method = key.split("/")
        ax.plot(r.time * _US, p, styles.get(method, "-"), color=colours[rep], linewidth=1.0,
                label=f"{rep}, {names.get(method, method)}")
    ax.axvline(r.primary_end * _US, color="k", linestyle=":", linewidth=0.8,
               label="first edge-wave arrival")
    ax.set_xlabel("time (µs)")
    ax.set_ylabel("pressure (Pa)")
    ax.legend(loc="best", fontsize="small")
    d = r.method_difference_percent
    ax.set_title(f"max difference between methods: monopole {d['monopole']:.2f} %, "
                 f"dipole {d['dipole']:.2f} %", fontsize="small")
    caption = (f"On-axis pressure {r.point[2] * _MM:.1f} mm from the source for monopole "
               "(rigid baffle, velocity) and dipole (soft baffle, pressure) representations "
               f"by {' and '.join(names.get(m, m) for m in r.methods)} (paper Fig. 2). "
               + ("" if "kwave" in r.methods else "k-Wave not included (see the notes). ")
               + "Largest "
               f"difference between methods: {d['monopole']:.2f} % (monopole), "
               f"{d['dipole']:.2f} % (dipole) of the maximum amplitude (paper: 2.1 %, 1.5 % "
               "with k-Wave). Look at the primary wavefront (before the dotted line), which "
               "should be nearly the same for both representations "
               f"({r.primary_difference_percent:.1f} % here), and at the later edge waves, "
               f"which differ ({r.representation_difference_percent:.1f} % overall).")
    return fig, caption
