"""Phase tools (paper section IV B): minimum phase from an amplitude response, filter
phase from a datasheet group delay, and compensation of a known phase in an impulse
response.

Conventions, stated once: a linear system's transfer function is written in
**holoprobe's convention** (paper eq. complex-conjugate-fourier, ``X(ω) = conj(FFT{x})``)
unless ``convention="fft"`` is asked for, in which case it is the engineering / FFT
convention (``X(ω) = FFT{x}``, time factor ``e^{+iωt}``). The two phases are negatives of
each other. A pure delay τ has phase ``−ωτ`` in the FFT convention and ``+ωτ`` in
holoprobe's; a causal first-order low-pass ``1/(1 + iω/ω0)`` (FFT convention) has phase
``−atan(ω/ω0)`` there and ``+atan(ω/ω0)`` in holoprobe's.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import scipy.special
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.signal._fourier import frequency_axis, to_frequency, to_time
from holoprobe.signal._resample import _axis_index, _positive, _real_signal

__all__ = [
    "PhaseResponse",
    "compensate_phase",
    "filter_phase_from_group_delay",
    "minimum_phase",
]

Convention = Literal["holoprobe", "fft"]
_QUARTER_PI2 = np.pi**2 / 4


def _convention_sign(convention: str) -> float:
    if convention == "holoprobe":
        return -1.0
    if convention == "fft":
        return 1.0
    raise InputError(f"expected 'holoprobe' or 'fft', got {convention!r}", field="convention")


def _kernel_integral(x: NDArray) -> NDArray:
    """``A(x) = ∫_0^x ln coth(|v|/2) dv`` (odd, A(±∞) = ±π²/4), via dilogarithms."""
    e = np.exp(-np.abs(x))
    tail = scipy.special.spence(1.0 - e) - scipy.special.spence(1.0 + e)  # ∫_|x|^∞
    return np.sign(x) * (_QUARTER_PI2 - tail)


def minimum_phase(frequency: ArrayLike, magnitude: ArrayLike, *,
                  at: ArrayLike | None = None, convention: Convention = "holoprobe",
                  extrapolation: Literal["constant", "slope"] = "constant",
                  edge_points: int = 3, n_grid: int = 2000) -> NDArray[np.float64]:
    """Phase of the minimum-phase system with a given amplitude response (Bode's gain–phase
    relation).

    With ``u = ln(f)`` and ``M(u) = ln|G|``, the minimum phase in the FFT convention is

        φ(u) = (1/π) ∫ M'(u') ln coth(|u − u'| / 2) du'.

    ``M`` is interpolated by PCHIP onto ``n_grid`` points uniform in ``u`` between the
    first and last given frequency and taken piecewise linear there; outside that band
    ``M`` continues with a constant slope (``extrapolation="constant"``: slope 0, the
    magnitude held at the edge values; ``"slope"``: the log–log slope fitted to the
    ``edge_points`` outermost samples, i.e. power-law asymptotes). For piecewise-linear
    ``M`` the integral is evaluated exactly (closed form in dilogarithms), so there is no
    truncation of the infinite log-frequency range (unlike the published code, which cuts
    it at ±4 and carries a 2–5 % bias).

    Parameters
    ----------
    frequency : array_like, shape (m,)
        Increasing frequencies in Hz (> 0; a leading 0 is ignored).
    magnitude : array_like, shape (m,)
        |G| at those frequencies (> 0, any unit).
    at : array_like, optional
        Frequencies (Hz, ≥ 0) where the phase is wanted; default ``frequency``. The phase
        at 0 Hz is ``slope_low · π/2`` (0 with constant extrapolation).
    convention : {"holoprobe", "fft"}
        Convention of the returned phase (see the module notes): holoprobe's conjugate
        convention (default) or the FFT / engineering one.
    extrapolation : {"constant", "slope"}
        How ``ln|G|`` continues beyond the given band (see above).
    edge_points : int
        Number of end samples used to fit the edge slopes (``"slope"``).
    n_grid : int
        Number of interpolation points in log frequency.

    Returns
    -------
    ndarray, shape of ``at`` (or ``frequency``)
        Phase in rad.

    References
    ----------
    J. Bechhoefer, "Kramers–Kronig, Bode, and the meaning of zero", Am. J. Phys. 79,
    1053 (2011), doi:10.1119/1.3614039.
    """
    sign = _convention_sign(convention)
    f = np.asarray(frequency, dtype=float).reshape(-1)
    g = np.asarray(magnitude, dtype=float).reshape(-1)
    if f.shape != g.shape:
        raise InputError(f"expected {f.size} values (one per frequency), got {g.size}",
                         field="magnitude")
    if not (np.all(np.isfinite(f)) and np.all(np.isfinite(g))):
        raise InputError("frequency and magnitude must be finite", field="magnitude")
    if f.size and f[0] == 0:
        f, g = f[1:], g[1:]
    if f.size < 2:
        raise InputError("expected at least 2 positive frequencies", field="frequency")
    if np.any(f <= 0) or np.any(np.diff(f) <= 0):
        raise InputError("expected positive, strictly increasing frequencies",
                         field="frequency")
    if np.any(g <= 0):
        raise InputError("expected positive magnitudes", field="magnitude")
    if extrapolation not in ("constant", "slope"):
        raise InputError(f"expected 'constant' or 'slope', got {extrapolation!r}",
                         field="extrapolation")
    u = np.log(f)
    m = np.log(g)
    ug = np.linspace(u[0], u[-1], max(int(n_grid), 2))
    from scipy.interpolate import PchipInterpolator  # ~1 s of start-up: only when used

    mg = PchipInterpolator(u, m)(ug)
    slopes = np.diff(mg) / np.diff(ug)
    if extrapolation == "slope":
        k = int(min(max(edge_points, 2), u.size))
        s_lo = float(np.polyfit(u[:k], m[:k], 1)[0])
        s_hi = float(np.polyfit(u[-k:], m[-k:], 1)[0])
    else:
        s_lo = s_hi = 0.0
    # summation by parts: φ = (1/π)[Σ_j A(u − u_j)(s_j − s_{j−1}) + (s_lo + s_hi) π²/4]
    jumps = np.diff(np.concatenate([[s_lo], slopes, [s_hi]]))
    fe = f if at is None else np.asarray(at, dtype=float)
    if np.any(fe < 0) or not np.all(np.isfinite(fe)):
        raise InputError("expected finite frequencies ≥ 0", field="at")
    flat = fe.reshape(-1)
    out = np.empty(flat.size)
    zero = flat == 0
    out[zero] = s_lo * np.pi / 2
    ue = np.log(flat[~zero])
    res = np.empty(ue.size)
    step = max(1, 2_000_000 // ug.size)
    for i in range(0, ue.size, step):
        a = _kernel_integral(ue[i:i + step, None] - ug[None, :])
        res[i:i + step] = a @ jumps
    out[~zero] = (res + (s_lo + s_hi) * _QUARTER_PI2) / np.pi
    return sign * out.reshape(fe.shape)


@dataclass(frozen=True)
class PhaseResponse:
    """A phase response φ(f) tabulated on a fine grid, callable at any frequency.

    Attributes
    ----------
    frequency : ndarray, shape (k,)
        Grid in Hz, from 0.
    phase_fft : ndarray, shape (k,)
        Phase in rad in the FFT convention on that grid.
    slope_fft : float
        dφ/df (rad/Hz, FFT convention) used beyond the grid (−2π × group delay there).
    name : str
        Where it came from.
    """

    frequency: NDArray[np.float64]
    phase_fft: NDArray[np.float64]
    slope_fft: float
    name: str = ""

    def __call__(self, frequency: ArrayLike, *,
                 convention: Convention = "holoprobe") -> NDArray[np.float64]:
        """Phase in rad at ``frequency`` (Hz, ≥ 0) in the given convention."""
        sign = _convention_sign(convention)
        f = np.abs(np.asarray(frequency, dtype=float))
        ph = np.interp(f, self.frequency, self.phase_fft)
        beyond = f > self.frequency[-1]
        ph = np.where(beyond, self.phase_fft[-1] + self.slope_fft * (f - self.frequency[-1]),
                      ph)
        return sign * ph


_UNIT_SCALE = {"hz": 1.0, "khz": 1e3, "mhz": 1e6, "ghz": 1e9,
               "s": 1.0, "sec": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "usec": 1e-6,
               "ns": 1e-9, "nsec": 1e-9, "ps": 1e-12, "psec": 1e-12}


def _read_group_delay_file(path: Path) -> tuple[NDArray, NDArray]:
    """Mini-Circuits datasheet text: free text lines, one header line of comma-separated
    'Name (unit)' columns, then numbers. The group delay column is the one named
    'Group Delay'; its frequencies are the nearest 'Frequency' column to its left."""
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError as exc:
        raise InputError(f"cannot read the file ({exc})", file=str(path)) from None
    header_idx = next((i for i, ln in enumerate(lines) if "group delay" in ln.lower()), None)
    if header_idx is None:
        raise InputError("no header line with a 'Group Delay (ns)' column", file=str(path),
                         field="Group Delay")
    names = [c.strip() for c in lines[header_idx].split(",")]
    j_tau = next(j for j, c in enumerate(names) if c.lower().startswith("group delay"))
    j_f = next((j for j in range(j_tau - 1, -1, -1)
                if names[j].lower().startswith("frequency")), None)
    if j_f is None:
        raise InputError("no 'Frequency' column before the 'Group Delay' column",
                         file=str(path), field="Frequency")

    def unit(name: str, field: str) -> float:
        if "(" not in name or ")" not in name:
            raise InputError(f"no unit in parentheses in column {name!r}", file=str(path),
                             field=field)
        key = name[name.index("(") + 1:name.index(")")].strip().lower()
        if key not in _UNIT_SCALE:
            raise InputError(f"unknown unit {key!r}", file=str(path), field=field)
        return _UNIT_SCALE[key]

    sf = unit(names[j_f], "Frequency")
    st = unit(names[j_tau], "Group Delay")
    freq, tau = [], []
    for k, ln in enumerate(lines[header_idx + 1:], start=header_idx + 2):
        if not ln.strip():
            continue
        cells = [c.strip() for c in ln.split(",")]
        if len(cells) <= max(j_f, j_tau) or not cells[j_f] or not cells[j_tau]:
            continue
        try:
            freq.append(float(cells[j_f]) * sf)
            tau.append(float(cells[j_tau]) * st)
        except ValueError:
            raise InputError(f"line {k}: expected numbers", file=str(path),
                             field="Group Delay") from None
    return np.asarray(freq), np.asarray(tau)


def filter_phase_from_group_delay(source: str | Path | tuple[ArrayLike, ArrayLike], *,
                                  n_grid: int = 4001, name: str | None = None
                                  ) -> PhaseResponse:
    """Phase response of a filter from its group delay τ(f): ``φ(f) = −2π ∫_0^f τ df'``
    (FFT convention; ``+2π ∫ τ df`` in holoprobe's).

    τ is interpolated by PCHIP between the given frequencies, held at its first value
    down to DC (so φ(0) = 0) and at its last value beyond the last frequency (linear phase
    there), then integrated by the trapezoid rule on ``n_grid`` points.

    Parameters
    ----------
    source : path or (frequency, group_delay)
        A Mini-Circuits datasheet text file (e.g. ``BLP-15+.txt``: a source line, a header
        ``Frequency (MHz), …, Frequency (MHz), Group Delay (nsec)``, then comma-separated
        rows; units are read from the header), or arrays of frequencies in Hz and group
        delays in s.
    n_grid : int
        Points of the integration grid from 0 to the last frequency.
    name : str, optional
        A label (default the file name).

    Returns
    -------
    PhaseResponse
        Callable: ``phase(f, convention="holoprobe")``.
    """
    if isinstance(source, (str, Path)):
        path = Path(source)
        if not path.is_file():
            raise InputError("no such file", file=str(path))
        f, tau = _read_group_delay_file(path)
        label = path.name if name is None else name
        where = str(path)
    else:
        try:
            f_raw, tau_raw = source
        except (TypeError, ValueError):
            raise InputError("expected a file path or (frequency_Hz, group_delay_s)",
                             field="source") from None
        f = np.asarray(f_raw, dtype=float).reshape(-1)
        tau = np.asarray(tau_raw, dtype=float).reshape(-1)
        label = "" if name is None else name
        where = None
    if f.size != tau.size:
        raise InputError(f"{f.size} frequencies but {tau.size} group delays", file=where,
                         field="group_delay")
    if f.size < 2:
        raise InputError("expected at least 2 (frequency, group delay) pairs", file=where,
                         field="group_delay")
    if not (np.all(np.isfinite(f)) and np.all(np.isfinite(tau))):
        raise InputError("contains NaN or inf", file=where, field="group_delay")
    if np.any(f < 0) or np.any(np.diff(f) <= 0):
        raise InputError("frequencies must be non-negative and strictly increasing",
                         file=where, field="frequency")
    grid = np.linspace(0.0, f[-1], max(int(n_grid), 2))
    from scipy.interpolate import PchipInterpolator

    tg = PchipInterpolator(f, tau)(np.clip(grid, f[0], f[-1]))
    phase = -2 * np.pi * np.concatenate(
        [[0.0], np.cumsum(0.5 * (tg[1:] + tg[:-1]) * np.diff(grid))])
    return PhaseResponse(frequency=grid, phase_fft=phase, slope_fft=float(-2 * np.pi * tau[-1]),
                         name=label)


def compensate_phase(ir: ArrayLike, sampling_rate: float,
                     phase_fn: Callable[[NDArray], NDArray] | ArrayLike, *,
                     direction: Literal[1, -1] = 1, convention: Convention = "holoprobe",
                     axis: int = -1, pad: int = 0) -> NDArray:
    """Remove (or apply) a known phase response from impulse responses.

    With φ the phase in holoprobe's convention, the spectrum (holoprobe's convention) is
    multiplied by ``exp(−i · direction · φ(f))``:

    * ``direction=+1``: the phase φ is *contained* in ``ir`` (a system with that phase was
      in series with the measured output, e.g. the hydrophone chain for a transmit IR) and
      is removed. A pure delay τ (φ = +2πfτ) is advanced by τ.
    * ``direction=−1``: the phase entered inversely (the system was in series with the
      measured *input*, e.g. the hydrophone chain behind the pressure used to deconvolve a
      receive IR); it is applied.

    (The published analysis code adds a conj-convention minimum phase to an FFT-convention
    filter phase; here every phase carries its convention explicitly.)

    Parameters
    ----------
    ir : array_like, real
        Impulse responses; time along ``axis``.
    sampling_rate : float
        Sampling rate in Hz.
    phase_fn : callable or array_like
        φ(f) in rad: a callable of frequency in Hz (e.g. a :class:`PhaseResponse`), or
        values on the ``n // 2 + 1`` bins of the (padded) record.
    direction : {1, -1}
        See above.
    convention : {"holoprobe", "fft"}
        Convention of the phase that ``phase_fn`` returns.
    axis : int
        Time axis.
    pad : int
        Zeros appended before the FFT (and removed after) so that the shift does not wrap.

    Returns
    -------
    ndarray, same shape as ``ir``
    """
    x = _real_signal(ir, "ir").astype(float, copy=False)
    fs = _positive(sampling_rate, "sampling_rate")
    if direction not in (1, -1):
        raise InputError(f"expected +1 or -1, got {direction!r}", field="direction")
    _convention_sign(convention)  # validates the name
    ax = _axis_index(axis, x.ndim)
    xm = np.moveaxis(x, ax, -1)
    n = xm.shape[-1]
    if int(pad) < 0:
        raise InputError("expected a non-negative number of samples", field="pad")
    nf = n + int(pad)
    f = frequency_axis(nf, fs)
    if callable(phase_fn):
        if isinstance(phase_fn, PhaseResponse):
            phi = phase_fn(f, convention=convention)
        else:
            phi = phase_fn(f)
        phi = np.asarray(phi, dtype=float)
    else:
        phi = np.asarray(phase_fn, dtype=float)
    if phi.shape[-1:] != f.shape:
        raise InputError(f"expected {f.size} phase values (one per bin), got shape "
                         f"{phi.shape}", field="phase_fn")
    phi_h = phi if convention == "holoprobe" else -phi
    rot = np.exp(-1j * direction * phi_h)
    if nf % 2 == 0:
        rot[..., -1] = np.cos(phi_h[..., -1])
    spec = to_frequency(xm, n=nf, axis=-1) * rot
    out = to_time(spec, nf, axis=-1)[..., :n]
    return np.moveaxis(out, -1, ax)
