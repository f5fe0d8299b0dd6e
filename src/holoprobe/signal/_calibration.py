"""Hydrophone calibration: read a sensitivity curve, convert voltage ↔ pressure.

The hydrophone output voltage and the acoustic pressure are related, frequency by
frequency, by the complex sensitivity ``S(f)`` (V/Pa) in holoprobe's Fourier convention
(``P(ω) = conj(FFT{p})``, paper eq. complex-conjugate-fourier)::

    V(f) = polarity · S(f) · P(f),     S(f) = |S(f)| · exp(i φ(f)).

A pure delay τ of the hydrophone chain reads ``φ(f) = +2π f τ`` in this convention.
"""

from __future__ import annotations

import csv
import re
from importlib import resources
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.measurement import HydrophoneCalibration
from holoprobe.plausibility import PlausibilityConfig
from holoprobe.signal._fourier import frequency_axis, to_frequency, to_time
from holoprobe.signal._resample import _axis_index

__all__ = [
    "default_calibration",
    "load_calibration",
    "pressure_from_voltage",
    "pressure_spectrum_from_voltage",
    "sensitivity_response",
    "voltage_from_pressure",
]

_DEFAULT_FILE = "hydrophone_sensitivity.csv"
_POLARITY_RE = re.compile(r"polarity\s*[:=]\s*([+-]?1)\b", re.IGNORECASE)

BelowRule = Literal["hold", "extrapolate", "zero"]
AboveRule = Literal["zero", "taper", "hold", "extrapolate"]


# --------------------------------------------------------------------------- reading
def _read_csv(path: Path) -> tuple[dict[str, NDArray], int | None]:
    polarity = None
    rows: list[list[str]] = []
    header: list[str] | None = None
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the file ({exc})", file=str(path)) from None
    for line in text.splitlines():
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            match = _POLARITY_RE.search(stripped)
            if match:
                polarity = int(match.group(1))
            continue
        if header is None:
            header = [h.strip() for h in next(csv.reader([stripped]))]
            continue
        rows.append([c.strip() for c in next(csv.reader([stripped]))])
    if header is None:
        raise InputError("no header line with column names (frequency_Hz, "
                         "sensitivity_V_per_Pa[, phase_rad])", file=str(path))
    columns: dict[str, NDArray] = {}
    for j, name in enumerate(header):
        values = []
        for i, row in enumerate(rows):
            if len(row) != len(header):
                raise InputError(f"line {i + 1} of the data has {len(row)} values, expected "
                                 f"{len(header)} (one per column)", file=str(path))
            try:
                values.append(float(row[j]))
            except ValueError:
                raise InputError(f"row {i + 1}: expected a number, got {row[j]!r}",
                                 file=str(path), field=name) from None
        columns[name] = np.asarray(values, float)
    return columns, polarity


def _read_mat(path: Path) -> dict[str, NDArray]:
    """Variables of a MATLAB v5 or v7.3 file (:func:`holoprobe.io.load_mat`)."""
    from holoprobe.io import load_mat

    return load_mat(path)


def _column(data: dict, names: tuple[str, ...], path: Path, *, required: bool = True):
    for name in names:
        if name in data:
            try:
                arr = np.asarray(data[name], dtype=float)
            except (TypeError, ValueError):
                raise InputError("expected a numeric vector", file=str(path),
                                 field=name) from None
            if arr.ndim > 1 and sum(s > 1 for s in arr.shape) > 1:
                raise InputError(f"expected a vector, got shape {arr.shape}", file=str(path),
                                 field=name)
            arr = arr.reshape(-1)
            if arr.size < 2:
                raise InputError(f"expected at least 2 values, got {arr.size}",
                                 file=str(path), field=name)
            if not np.all(np.isfinite(arr)):
                raise InputError("contains NaN or inf", file=str(path), field=name)
            return name, arr
    if required:
        raise InputError(f"missing field; expected one of {', '.join(names)} "
                         f"(found: {', '.join(sorted(data)) or 'nothing'})", file=str(path),
                         field=names[0])
    return None, None


def load_calibration(path: str | Path, *, polarity: int | None = None,
                     name: str | None = None,
                     plausibility: PlausibilityConfig | None = None) -> HydrophoneCalibration:
    """Read a hydrophone sensitivity curve.

    Three formats are understood:

    * **complex calibration** (CSV whose header names ``magnitude_V_per_Pa``, or
      HDF5): magnitude, phase in the FFT convention (converted here) and optional
      uncertainties, see :func:`holoprobe.io.read_complex_calibration`;

    * **CSV** (any other suffix): ``#`` comment lines, then a header line with the
      columns ``frequency_Hz, sensitivity_V_per_Pa`` and optionally ``phase_rad``
      (phase in holoprobe's convention, paper eq. complex-conjugate-fourier). A comment
      line ``# polarity: -1`` declares an inverting hydrophone system.
    * **MATLAB** ``.mat`` (v5 via SciPy, v7.3 via pymatreader) in the layout of the
      published toolkit: ``Frequency`` in MHz and ``Sensitivity`` in mV/MPa (magnitude);
      an optional ``Phase`` in rad is read in holoprobe's convention.

    Parameters
    ----------
    path : str or Path
        The file.
    polarity : {1, -1}, optional
        Sign of the voltage for a positive pressure. Default: the file's ``polarity``
        comment for CSV (1 when absent); −1 for a toolkit ``.mat`` file, whose
        ``voltage_to_pressure`` multiplies by −1 (the fibre-optic system inverts).
    name : str, optional
        A label; default the file name.
    plausibility : PlausibilityConfig, optional
        Ranges of sensitivity and frequency (:mod:`holoprobe.plausibility`): a value
        outside (mV/MPa read as V/Pa, MHz as Hz) is an InputError naming file and field.

    Returns
    -------
    HydrophoneCalibration
        Frequencies in Hz, sensitivity in V/Pa.

    Raises
    ------
    InputError
        Missing file or field, wrong shapes, non-increasing frequencies, non-positive
        sensitivities; the message names the file and the field.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("no such file", file=str(path))
    from holoprobe.io import check_measurement, is_complex_calibration, read_complex_calibration

    if is_complex_calibration(path):
        return check_measurement(read_complex_calibration(path, polarity=polarity, name=name),
                                 plausibility, file=str(path))
    file_polarity: int | None
    if path.suffix.lower() == ".mat":
        data = _read_mat(path)
        fname, f = _column(data, ("Frequency", "frequency"), path)
        sname, s = _column(data, ("Sensitivity", "sensitivity"), path)
        pname, ph = _column(data, ("Phase", "phase"), path, required=False)
        f = f * 1e6
        s = s * 1e-9  # mV/MPa -> V/Pa
        file_polarity = -1
    else:
        data, file_polarity = _read_csv(path)
        fname, f = _column(data, ("frequency_Hz",), path)
        sname, s = _column(data, ("sensitivity_V_per_Pa",), path)
        pname, ph = _column(data, ("phase_rad",), path, required=False)
        if file_polarity is None:
            file_polarity = 1
    if s.size != f.size:
        raise InputError(f"expected {f.size} values (one per frequency), got {s.size}",
                         file=str(path), field=sname)
    if ph is not None and ph.size != f.size:
        raise InputError(f"expected {f.size} values (one per frequency), got {ph.size}",
                         file=str(path), field=pname)
    if np.any(np.diff(f) <= 0):
        k = int(np.argmax(np.diff(f) <= 0))
        raise InputError(f"frequencies must strictly increase (value {k + 2} is not larger "
                         f"than value {k + 1})", file=str(path), field=fname)
    if np.any(f < 0):
        raise InputError("frequencies must be non-negative", file=str(path), field=fname)
    if np.any(s <= 0):
        raise InputError("sensitivity magnitudes must be positive", file=str(path),
                         field=sname)
    pol = file_polarity if polarity is None else polarity
    if pol not in (1, -1):
        raise InputError(f"expected 1 or -1, got {pol!r}", field="polarity")
    cal = HydrophoneCalibration(frequency=f, sensitivity=s, phase=ph, polarity=int(pol),
                                name=path.name if name is None else name)
    return check_measurement(cal, plausibility, file=str(path))


def default_calibration() -> HydrophoneCalibration:
    """The packaged hydrophone calibration (``holoprobe/data/hydrophone_sensitivity.csv``).

    The fibre-optic needle hydrophone calibration published with the
    transducer-characterization toolkit (N. Blanken, LGPL-3.0, Zenodo
    10.5281/zenodo.17095584): magnitude at 1–30 MHz, no phase, **polarity −1**
    (the toolkit inverts the sign of the voltage; a positive pressure gives a negative
    output voltage).
    """
    ref = resources.files("holoprobe") / "data" / _DEFAULT_FILE
    with resources.as_file(ref) as path:
        return load_calibration(path, name="fibre-optic needle hydrophone (Blanken toolkit)")


# --------------------------------------------------------------------------- transfer
def _check_rules(below: str, above: str, taper_width: float) -> None:
    if below not in ("hold", "extrapolate", "zero"):
        raise InputError(f"expected 'hold', 'extrapolate' or 'zero', got {below!r}",
                         field="below")
    if above not in ("zero", "taper", "hold", "extrapolate"):
        raise InputError(f"expected 'zero', 'taper', 'hold' or 'extrapolate', got {above!r}",
                         field="above")
    if above == "taper" and not taper_width > 0:
        raise InputError(f"expected a positive width in Hz, got {taper_width!r}",
                         field="taper_width")


def sensitivity_response(calibration: HydrophoneCalibration, frequency: ArrayLike, *,
                         inverse: bool = True, below: BelowRule = "hold",
                         above: AboveRule = "zero", taper_width: float = 2e6,
                         min_frequency: float | None = None,
                         max_frequency: float | None = None) -> NDArray[np.complex128]:
    """Inverse sensitivity ``polarity / S(f)`` (Pa/V), or ``polarity · S(f)``, at any frequency.

    ``1/|S|`` and the unwrapped phase are interpolated with PCHIP in frequency (as the
    published toolkit does for ``1/S``). ``S`` itself is ``1 / (interpolated 1/S)``, so the
    two directions are exact inverses wherever both are non-zero.

    Parameters
    ----------
    calibration : HydrophoneCalibration
        The sensitivity curve.
    frequency : array_like
        Frequencies in Hz (≥ 0).
    inverse : bool
        True: return ``polarity / S`` (Pa/V); False: ``polarity · S`` (V/Pa).
    below : {"hold", "extrapolate", "zero"}
        Below the lowest calibrated frequency: hold the edge magnitude (default),
        extrapolate the PCHIP curve down to DC (the toolkit's behaviour), or zero. The
        phase below the band is ``φ(f_min) · f / f_min`` (a constant phase delay, real at DC).
    above : {"zero", "taper", "hold", "extrapolate"}
        Above the highest calibrated frequency: zero (default, the toolkit's behaviour),
        a raised-cosine taper from the edge value to zero over ``taper_width``, hold, or
        extrapolate the PCHIP curve (floored at a tenth of the edge value of ``1/|S|``).
    taper_width : float
        Width in Hz of the taper for ``above="taper"``.
    min_frequency, max_frequency : float, optional
        Additionally zero all frequencies below / above these (Hz).

    Returns
    -------
    ndarray, complex, same shape as ``frequency``
    """
    from scipy.interpolate import PchipInterpolator  # ~1 s of start-up: only when used

    _check_rules(below, above, taper_width)
    f = np.asarray(frequency, dtype=float)
    fc = np.asarray(calibration.frequency, float)
    inv_mag = 1.0 / np.asarray(calibration.sensitivity, float)
    f_lo, f_hi = fc[0], fc[-1]
    mag_interp = PchipInterpolator(fc, inv_mag, extrapolate=True)
    fin = np.clip(f, f_lo, f_hi)
    mag = mag_interp(fin)
    low = f < f_lo
    high = f > f_hi
    if below == "extrapolate":
        mag[low] = mag_interp(f[low])
    if above == "extrapolate":  # PCHIP's edge polynomial, kept at least 1/10 of the edge
        mag[high] = np.maximum(mag_interp(f[high]), 0.1 * inv_mag[-1])
    elif below == "zero":
        mag[low] = 0.0
    if above == "zero":
        mag[high] = 0.0
    elif above == "taper":
        x = np.clip((f[high] - f_hi) / taper_width, 0.0, 1.0)
        mag[high] = mag[high] * 0.5 * (1.0 + np.cos(np.pi * x))
    if calibration.phase is None:
        phase = np.zeros_like(f)
    else:
        ph = np.unwrap(np.asarray(calibration.phase, float))
        phase = -PchipInterpolator(fc, ph)(fin)  # phase of 1/S
        edge_lo, edge_hi = -ph[0], -ph[-1]
        if f_lo > 0:
            phase[low] = edge_lo * f[low] / f_lo
        else:
            phase[low] = edge_lo
        phase[high] = edge_hi * f[high] / f_hi
    if min_frequency is not None:
        mag[f < min_frequency] = 0.0
    if max_frequency is not None:
        mag[f > max_frequency] = 0.0
    inv = mag * np.exp(1j * phase)
    if inverse:
        return calibration.polarity * inv
    out = np.zeros_like(inv)
    nz = mag > 0
    out[nz] = 1.0 / inv[nz]
    return calibration.polarity * out


def _checked_signal(signal: ArrayLike, sampling_rate: float, field: str) -> NDArray:
    """``signal`` as an array after checking it is real with a time axis and the rate."""
    x = np.asarray(signal)
    if not np.issubdtype(x.dtype, np.number) or np.iscomplexobj(x):
        raise InputError(f"expected real numbers, got dtype {x.dtype}", field=field)
    if x.ndim == 0:
        raise InputError("expected an array with a time axis", field=field)
    if not (np.isfinite(sampling_rate) and sampling_rate > 0):
        raise InputError(f"expected a positive rate in Hz, got {sampling_rate!r}",
                         field="sampling_rate")
    return x


def _apply_transfer(signal: ArrayLike, sampling_rate: float, transfer_fn, *, axis: int,
                    chunk_traces: int, n_fft: int | None, field: str) -> NDArray:
    x = _checked_signal(signal, sampling_rate, field)
    axis = _axis_index(axis, x.ndim)
    nt = x.shape[axis]
    n = nt if n_fft is None else int(n_fft)
    if n < nt:
        raise InputError(f"expected n_fft ≥ the {nt} samples", field="n_fft")
    out_dtype = np.float32 if x.dtype == np.float32 else np.float64
    transfer = transfer_fn(frequency_axis(n, sampling_rate))
    xm = np.moveaxis(x, axis, -1)
    lead = xm.shape[:-1]
    flat = xm.reshape(-1, nt)
    out = np.empty(flat.shape, dtype=out_dtype)
    step = max(1, int(chunk_traces))
    for start in range(0, flat.shape[0], step):
        block = flat[start:start + step]
        spec = to_frequency(block, n=n, axis=-1)
        spec *= transfer
        out[start:start + step] = to_time(spec, n, axis=-1)[:, :nt]
    return np.moveaxis(out.reshape(*lead, nt), -1, axis)


def pressure_from_voltage(voltage: ArrayLike, sampling_rate: float,
                          calibration: HydrophoneCalibration, *, axis: int = -1,
                          min_frequency: float | None = None,
                          max_frequency: float | None = None, below: BelowRule = "hold",
                          above: AboveRule = "zero", taper_width: float = 2e6,
                          n_fft: int | None = None, chunk_traces: int = 4096) -> NDArray:
    """Hydrophone voltage (V) → acoustic pressure (Pa) by deconvolving the sensitivity.

    In holoprobe's convention (paper eq. complex-conjugate-fourier)
    ``P(f) = polarity · V(f) / S(f)``, with ``1/S`` interpolated by PCHIP (see
    :func:`sensitivity_response` for the rules outside the calibrated band). The division
    is done by FFT over ``n_fft`` samples, i.e. circularly when ``n_fft`` equals the record
    length (the toolkit's choice); pass a larger ``n_fft`` to zero-pad.

    Parameters
    ----------
    voltage : array_like, real, e.g. shape (nx, ny, nt)
        Hydrophone output in V; time along ``axis``.
    sampling_rate : float
        Sampling rate in Hz.
    calibration : HydrophoneCalibration
        Sensitivity curve (V/Pa vs Hz), e.g. :func:`default_calibration`.
    axis : int
        Time axis.
    min_frequency, max_frequency : float, optional
        Zero the spectrum below / above these frequencies (Hz).
    below, above, taper_width
        Rules outside the calibrated band (defaults: hold the edge value below, zero
        above), see :func:`sensitivity_response`.
    n_fft : int, optional
        FFT length (≥ nt); default nt.
    chunk_traces : int
        Number of traces transformed at once (bounds the memory to a few times
        ``chunk_traces · n_fft`` complex values).

    Returns
    -------
    ndarray, same shape as ``voltage``
        Pressure in Pa (float32 for float32 input, float64 otherwise).
    """
    def transfer(f):
        return sensitivity_response(calibration, f, inverse=True, below=below, above=above,
                                    taper_width=taper_width, min_frequency=min_frequency,
                                    max_frequency=max_frequency)
    return _apply_transfer(voltage, sampling_rate, transfer, axis=axis,
                           chunk_traces=chunk_traces, n_fft=n_fft, field="voltage")


def pressure_spectrum_from_voltage(voltage: ArrayLike, sampling_rate: float,
                                   calibration: HydrophoneCalibration) -> NDArray:
    """The pressure spectrum ``to_frequency(pressure_from_voltage(voltage, ...))`` (the
    default band rules, ``n_fft`` the record length) straight from the voltage's: ``P(f) =
    polarity · V(f) / S(f)``, without the inverse FFT to the pressure and the FFT back.

    Parameters
    ----------
    voltage : array_like, real, shape (..., nt)
        Hydrophone output in V, time along the last axis.
    sampling_rate : float
        Hz.
    calibration : HydrophoneCalibration
        Sensitivity curve (V/Pa vs Hz).

    Returns
    -------
    ndarray, complex, shape (..., nt // 2 + 1)
        Pa per bin in the conjugate convention (unscaled, as :func:`to_frequency`);
        complex64 for float32 input. The zero-frequency (and, for an even ``nt``, the
        Nyquist) bin is real, as the spectrum of a real pressure record is: the same
        numbers as the round trip through time, up to its rounding.
    """
    x = _checked_signal(voltage, sampling_rate, "voltage")
    nt = x.shape[-1]
    spec = to_frequency(x)
    spec *= sensitivity_response(calibration, frequency_axis(nt, sampling_rate),
                                 inverse=True)
    spec[..., 0].imag = 0.0
    if nt % 2 == 0:
        spec[..., -1].imag = 0.0
    return spec


def voltage_from_pressure(pressure: ArrayLike, sampling_rate: float,
                          calibration: HydrophoneCalibration, *, axis: int = -1,
                          min_frequency: float | None = None,
                          max_frequency: float | None = None, below: BelowRule = "hold",
                          above: AboveRule = "zero", taper_width: float = 2e6,
                          n_fft: int | None = None, chunk_traces: int = 4096) -> NDArray:
    """Acoustic pressure (Pa) → hydrophone voltage (V): the inverse of
    :func:`pressure_from_voltage` (``V(f) = polarity · S(f) · P(f)``), for simulators.

    Parameters are those of :func:`pressure_from_voltage`; the band rules act on ``S``
    the same way, so that the two functions are exact inverses inside the band where
    the transfer is non-zero.

    Returns
    -------
    ndarray, same shape as ``pressure``
        Voltage in V.
    """
    def transfer(f):
        return sensitivity_response(calibration, f, inverse=False, below=below, above=above,
                                    taper_width=taper_width, min_frequency=min_frequency,
                                    max_frequency=max_frequency)
    return _apply_transfer(pressure, sampling_rate, transfer, axis=axis,
                           chunk_traces=chunk_traces, n_fft=n_fft, field="pressure")
