"""The virtual transducer: the model a characterization produces (paper section II).

A :class:`VirtualTransducer` holds what is needed to predict the field of the probe
for any transmit setting and its RF for any incoming field: the element geometry,
the estimated active aperture, the elevation lens focus, the transmit (and
optionally receive) impulse response, the medium, the estimated parameters with
their uncertainties and the provenance of the numbers. Its file format
(``virtual_transducer.h5``) is :mod:`holoprobe.transducer._schema`; the format is
documented in ``docs/formats.md``.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from holoprobe._html import html_table
from holoprobe.errors import InputError
from holoprobe.geometry import ArrayGeometry, Medium

__all__ = [
    "RECEIVE_UNITS",
    "TRANSMIT_UNITS",
    "Provenance",
    "VirtualTransducer",
]

TRANSMIT_UNITS = ("Pa/(V*s)",)
"""Accepted units of the transmit impulse response: surface pressure ρ0·c0·u per
volt-second of drive (reference_spec 2.8), so ``u(t) = (h_T ⊛ E_T)(t) / (ρ0 c0)``
with the convolution integral taken in seconds."""
RECEIVE_UNITS = ("ADCL/(Pa*s)", "V/(Pa*s)")
"""Accepted units of the receive impulse response: ADC levels (or volts) per
pascal-second of element-averaged pressure, ``E_R(t) = (h_R ⊛ p_R)(t)``."""


def _holoprobe_version() -> str:
    try:
        from holoprobe import __version__
    except ImportError:  # pragma: no cover - partial installs
        return "unknown"
    return str(__version__)


def _now_utc() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def _positive(value: object, name: str, unit: str) -> float:
    try:
        # (type: ignore below) any object: float() raises for a non-number (caught below)
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InputError(f"expected a positive number in {unit}, got {value!r}",
                         field=name) from None
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"expected a positive finite number in {unit}, got {v!r}", field=name)
    return v


def _finite(value: object, name: str, unit: str) -> float:
    try:
        # (type: ignore below) any object: float() raises for a non-number (caught below)
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InputError(f"expected a number in {unit}, got {value!r}", field=name) from None
    if not math.isfinite(v):
        raise InputError(f"expected a finite number in {unit}, got {v!r}", field=name)
    return v


def _signal(value: object, name: str) -> NDArray[np.float64]:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError("expected a 1-D array of real numbers", field=name) from None
    if arr.ndim != 1 or arr.size < 2:
        raise InputError(f"expected a 1-D array of at least 2 samples, got shape {arr.shape}",
                         field=name)
    if not np.all(np.isfinite(arr)):
        raise InputError("contains NaN or inf", field=name)
    arr.setflags(write=False)
    return arr


def _per_element(value: object, n: int, name: str) -> NDArray[np.float64] | None:
    if value is None:
        return None
    try:
        arr = np.array(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(f"expected {n} real numbers (one per element)", field=name) from None
    if arr.shape != (n,):
        raise InputError(f"expected {n} values (one per element), got {arr.size}", field=name)
    if not np.all(np.isfinite(arr)):
        raise InputError("contains NaN or inf", field=name)
    arr.setflags(write=False)
    return arr


def _float_dict(value: object, name: str) -> dict[str, float]:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise InputError("expected a mapping of names to numbers", field=name)
    out: dict[str, float] = {}
    for key, v in value.items():
        if not isinstance(key, str) or not key or "/" in key:
            raise InputError(f"expected non-empty names without '/', got {key!r}", field=name)
        if isinstance(v, bool):
            raise InputError(f"expected a number, got {v!r}", field=f"{name}.{key}")
        try:
            out[key] = float(v)
        except (TypeError, ValueError):
            raise InputError(f"expected a number, got {v!r}", field=f"{name}.{key}") from None
    return out


@dataclass(frozen=True, eq=False)
class Provenance:
    """Where a virtual transducer came from.

    Parameters
    ----------
    holoprobe_version : str
        Version of holoprobe that made the model (default: the running one).
    created_utc : str
        Creation time, ISO 8601 in UTC (default: now).
    input_files : dict of str to str
        Input file name (or path) → SHA-256 of its bytes (64 hex digits); see
        :func:`holoprobe.io.file_sha256`.
    config : str
        The configuration used, as text (TOML or JSON).
    config_format : {"toml", "json", ""}
        Language of ``config`` (empty when there is none).
    notes : str
        Free text (how the model was made, warnings, data source and license).
    """

    holoprobe_version: str = field(default_factory=_holoprobe_version)
    created_utc: str = field(default_factory=_now_utc)
    input_files: dict[str, str] = field(default_factory=dict)
    config: str = ""
    config_format: str = ""
    notes: str = ""

    def __post_init__(self) -> None:
        for name in ("holoprobe_version", "created_utc", "config", "config_format", "notes"):
            if not isinstance(getattr(self, name), str):
                raise InputError(f"expected text, got {type(getattr(self, name)).__name__}",
                                 field=f"provenance.{name}")
        if self.config_format not in ("toml", "json", ""):
            raise InputError(f"expected 'toml', 'json' or '', got {self.config_format!r}",
                             field="provenance.config_format")
        if not isinstance(self.input_files, dict):
            raise InputError("expected a mapping of file names to SHA-256 hex digests",
                             field="provenance.input_files")
        files: dict[str, str] = {}
        for key, digest in self.input_files.items():
            digest = str(digest).lower()
            if len(digest) != 64 or any(c not in "0123456789abcdef" for c in digest):
                raise InputError(f"expected 64 hexadecimal digits (SHA-256), got {digest!r}",
                                 field=f"provenance.input_files[{key!r}]")
            files[str(key)] = digest
        object.__setattr__(self, "input_files", files)

    @classmethod
    def from_files(cls, paths: list[str | os.PathLike], **kwargs: Any) -> Provenance:
        """Provenance with the SHA-256 of each file in ``paths`` (keyed by file name).

        Other fields are passed through ``kwargs``.
        """
        from holoprobe.io import file_sha256

        hashes = {Path(p).name: file_sha256(p) for p in paths}
        return cls(input_files=hashes, **kwargs)


@dataclass(frozen=True, eq=False)
class VirtualTransducer:
    """A characterized (or datasheet-built) linear/phased array probe.

    Coordinates: origin at the centroid of the virtual transducer surface (the
    source plane z = 0), x lateral across the elements, y elevation along them,
    z into the medium (``docs/conventions.md``).

    Parameters
    ----------
    element_count : int
        Number of elements N.
    pitch : float
        Element centre-to-centre distance in m.
    element_width : float
        Lateral (x) width w of one element in m (≤ pitch).
    element_height : float
        Active elevation (y) height H of the elements in m: the estimated aperture
        height for a characterized probe. It is the H of the lens delays (paper
        eq. lens-delays) and of the radiating surface.
    transmit_impulse_response : array_like, shape (n_t,)
        h_T in ``transmit_units``; sample n at time n / ``transmit_sampling_rate``.
        The normal surface velocity of an element driven by E_T(t) is
        ``u(t) = (h_T ⊛ E_T)(t) / (ρ0 c0)`` (paper eq. transmit-impulse-response,
        convolution integral in seconds), before the lens delays.
    transmit_sampling_rate : float
        Sampling rate of h_T in Hz.
    transmit_units : str
        ``"Pa/(V*s)"`` (ρ0·c0·u per volt-second, reference_spec 2.8).
    lens_focus : float
        Elevation lens focal distance F in m (``inf``: no lens).
    aperture_center : (float, float)
        Centre (x_c, y_c) of the estimated active aperture in m (0 after the
        characterization moved the origin onto it).
    aperture_width, aperture_height : float, optional
        Estimated active aperture W × H in m. Default: ``(N − 1)·pitch + w`` and
        ``element_height``.
    receive_impulse_response : array_like, shape (n_r,), optional
        h_R in ``receive_units``: ``E_R(t) = (h_R ⊛ p_R)(t)`` with p_R the
        element-averaged pressure (paper eq. receive-impulse-response).
    receive_sampling_rate : float, optional
        Sampling rate of h_R in Hz (required with ``receive_impulse_response``).
    receive_units : str
        ``"ADCL/(Pa*s)"`` or ``"V/(Pa*s)"``.
    medium : Medium
        Medium of the characterization (ρ0, c0).
    element_sensitivity : array_like, shape (N,), optional
        Relative receive amplitude of each element (dimensionless, 1 = mean).
    element_delay : array_like, shape (N,), optional
        Extra receive delay of each element in s.
    element_transmit_amplitude : array_like, shape (N,), optional
        Relative transmit amplitude of each element (live mean 1, 0 for a dead element),
        from the element map; multiplies the apodization of every transmit setting.
    element_transmit_delay : array_like, shape (N,), optional
        Extra transmit delay of each element in s (element map), added to the setting's.
    parameters : dict of str to float
        Estimated parameters by name, SI units (e.g. ``"aperture.width"``).
    uncertainties : dict of str to float
        Standard uncertainty of (some of) ``parameters``, same names and units.
    provenance : Provenance
        Version, creation time, input hashes, configuration, notes.
    name : str
        A label (probe model, serial number).
    array : ArrayGeometry, optional
        Element layout about the aperture centre (a 2-D matrix array, a convex array, or
        any layout whose elements are not the flat 1-D row above): element ``i`` is
        centred at ``array.positions[i] + (x_c, y_c, 0)`` and faces ``array.normals[i]``
        (every normal with a positive z component; a flat layout on z = 0);
        ``element_width``/``element_height`` are then each element's size along its
        width and height directions (arc length for a convex element, which the field
        code models as the flat rectangle tangent at its centre). None: the 1-D row.
    """

    element_count: int
    pitch: float
    element_width: float
    element_height: float
    transmit_impulse_response: NDArray[np.float64]
    transmit_sampling_rate: float
    transmit_units: str = TRANSMIT_UNITS[0]
    lens_focus: float = math.inf
    aperture_center: tuple[float, float] = (0.0, 0.0)
    aperture_width: float | None = None
    aperture_height: float | None = None
    receive_impulse_response: NDArray[np.float64] | None = None
    receive_sampling_rate: float | None = None
    receive_units: str = RECEIVE_UNITS[0]
    medium: Medium = field(default_factory=Medium)
    element_sensitivity: NDArray[np.float64] | None = None
    element_delay: NDArray[np.float64] | None = None
    element_transmit_amplitude: NDArray[np.float64] | None = None
    element_transmit_delay: NDArray[np.float64] | None = None
    parameters: dict[str, float] = field(default_factory=dict)
    uncertainties: dict[str, float] = field(default_factory=dict)
    provenance: Provenance = field(default_factory=Provenance)
    name: str = ""
    array: ArrayGeometry | None = None

    def transmit_weights(self, setting) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Apodization and delays (s) of every element for a transmit setting, with this
        probe's own element map (``element_transmit_amplitude`` / ``_delay``) applied."""
        apod = np.asarray(setting.element_weights(self.element_count), dtype=float)
        tau = np.asarray(setting.element_delays(self.element_centers(),
                                                self.medium.sound_speed), dtype=float)
        if self.element_transmit_amplitude is not None:
            apod = apod * self.element_transmit_amplitude
        if self.element_transmit_delay is not None:
            tau = tau + self.element_transmit_delay
        return apod, tau

    def __post_init__(self) -> None:
        count = self.element_count
        if isinstance(count, bool) or not isinstance(count, int | np.integer) or count < 1:
            raise InputError(f"expected a positive integer, got {count!r}",
                             field="element_count")
        set_ = object.__setattr__
        set_(self, "element_count", int(count))
        for name in ("pitch", "element_width", "element_height"):
            set_(self, name, _positive(getattr(self, name), name, "m"))
        if self.element_count > 1 and self.element_width > self.pitch * (1 + 1e-9):
            raise InputError(f"element width {self.element_width:g} m exceeds the pitch "
                             f"{self.pitch:g} m", field="element_width")
        set_(self, "transmit_impulse_response",
             _signal(self.transmit_impulse_response, "transmit_impulse_response"))
        set_(self, "transmit_sampling_rate",
             _positive(self.transmit_sampling_rate, "transmit_sampling_rate", "Hz"))
        if self.transmit_units not in TRANSMIT_UNITS:
            raise InputError(f"expected one of {TRANSMIT_UNITS}, got {self.transmit_units!r}",
                             field="transmit_units")
        focus = float(self.lens_focus)
        if not focus > 0:
            raise InputError(f"expected a positive focal distance in m (inf: no lens), got "
                             f"{focus!r}", field="lens_focus")
        set_(self, "lens_focus", focus)
        try:
            center = tuple(float(v) for v in np.asarray(self.aperture_center,
                                                        dtype=float).reshape(-1))
        except (TypeError, ValueError):
            center = ()
        if len(center) != 2 or not all(math.isfinite(c) for c in center):
            raise InputError("expected two finite coordinates (x_c, y_c) in m",
                             field="aperture_center")
        set_(self, "aperture_center", center)
        if self.array is not None:
            self._check_array()
        width = (self.element_count - 1) * self.pitch + self.element_width
        set_(self, "aperture_width", width if self.aperture_width is None
             else _positive(self.aperture_width, "aperture_width", "m"))
        set_(self, "aperture_height", self.element_height if self.aperture_height is None
             else _positive(self.aperture_height, "aperture_height", "m"))
        if self.receive_impulse_response is None:
            if self.receive_sampling_rate is not None:
                raise InputError("given without a receive_impulse_response",
                                 field="receive_sampling_rate")
        else:
            set_(self, "receive_impulse_response",
                 _signal(self.receive_impulse_response, "receive_impulse_response"))
            if self.receive_sampling_rate is None:
                raise InputError("required with a receive_impulse_response",
                                 field="receive_sampling_rate")
            set_(self, "receive_sampling_rate",
                 _positive(self.receive_sampling_rate, "receive_sampling_rate", "Hz"))
        if self.receive_units not in RECEIVE_UNITS:
            raise InputError(f"expected one of {RECEIVE_UNITS}, got {self.receive_units!r}",
                             field="receive_units")
        if not isinstance(self.medium, Medium):
            raise InputError("expected a holoprobe.Medium", field="medium")
        set_(self, "element_sensitivity",
             _per_element(self.element_sensitivity, self.element_count, "element_sensitivity"))
        set_(self, "element_delay",
             _per_element(self.element_delay, self.element_count, "element_delay"))
        for name in ("element_transmit_amplitude", "element_transmit_delay"):
            set_(self, name, _per_element(getattr(self, name), self.element_count, name))
        set_(self, "parameters", _float_dict(self.parameters, "parameters"))
        set_(self, "uncertainties", _float_dict(self.uncertainties, "uncertainties"))
        if not isinstance(self.provenance, Provenance):
            raise InputError("expected a holoprobe.transducer.Provenance", field="provenance")
        if not isinstance(self.name, str):
            raise InputError("expected text", field="name")

    def _check_array(self) -> None:
        """The :attr:`array` is one this model can predict the field of."""
        if not isinstance(self.array, ArrayGeometry) \
                or self.array.count != self.element_count:
            raise InputError(f"expected an ArrayGeometry of {self.element_count} "
                             "elements", field="array")
        if not np.all(self.array.normals[:, 2] > 0):
            raise InputError("expected every element normal to face the medium "
                             "(positive z component)", field="array")
        if not self.is_curved and not np.allclose(
                np.abs(self.array.width_directions[:, 0]), 1.0):
            raise InputError("flat elements whose width axis is not x (the rows of a "
                             "row-column array) are not modelled: describe the set in "
                             "its own frame (x along its line of elements)", field="array")
        if not self.is_curved and not np.allclose(self.array.positions[:, 2], 0.0):
            raise InputError("a flat face lies on z = 0: expected element centres on "
                             "z = 0", field="array")

    # ------------------------------------------------------------------ geometry
    @property
    def is_curved(self) -> bool:
        """True when the elements do not all face +z (a convex array): each element then
        radiates along its own normal (:attr:`array`)."""
        return self.array is not None and not np.allclose(self.array.normals,
                                                          [0.0, 0.0, 1.0])

    def element_frames(self) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                      NDArray[np.float64], NDArray[np.float64]]:
        """Centre and local axes of every element, each of shape (N, 3).

        Returns
        -------
        centers, width_directions, height_directions, normals : ndarray
            Element centres in m (:meth:`element_centers`) and the unit vectors along
            each element's width (u), height (v) and normal (into the medium): x, y, z
            for a flat face, the :attr:`array`'s directions otherwise.
        """
        n = self.element_count
        if self.array is not None:
            return (self.element_centers(), np.asarray(self.array.width_directions),
                    np.asarray(self.array.height_directions), np.asarray(self.array.normals))
        return (self.element_centers(), np.tile([1.0, 0.0, 0.0], (n, 1)),
                np.tile([0.0, 1.0, 0.0], (n, 1)), np.tile([0.0, 0.0, 1.0], (n, 1)))

    @property
    def kerf(self) -> float:
        """Gap between neighbouring elements, pitch − width, in m."""
        return self.pitch - self.element_width

    def face_extent(self) -> tuple[float, float, float, float]:
        """Bounding rectangle ``(x_lo, x_hi, y_lo, y_hi)`` in m of the element faces."""
        c = self.element_centers()
        hw, hh = 0.5 * self.element_width, 0.5 * self.element_height
        return (float(c[:, 0].min() - hw), float(c[:, 0].max() + hw),
                float(c[:, 1].min() - hh), float(c[:, 1].max() + hh))

    def element_centers(self) -> NDArray[np.float64]:
        """Centres of the elements in m, shape (N, 3): ``(x_i, y_c, 0)``.

        ``x_i = x_c + (i − (N − 1)/2)·pitch`` about the aperture centre (x_c, y_c);
        with an :attr:`array`, its positions moved to the aperture centre.
        """
        n = self.element_count
        xc, yc = self.aperture_center
        if self.array is not None:
            return np.asarray(self.array.positions) + np.array([xc, yc, 0.0])
        x = xc + (np.arange(n) - (n - 1) / 2) * self.pitch
        return np.stack([x, np.full(n, yc), np.zeros(n)], axis=-1)

    @property
    def transmit_time(self) -> NDArray[np.float64]:
        """Sample times of the transmit impulse response in s, shape (n_t,)."""
        return np.arange(self.transmit_impulse_response.size) / self.transmit_sampling_rate

    @property
    def receive_time(self) -> NDArray[np.float64] | None:
        """Sample times of the receive impulse response in s, or None."""
        if self.receive_impulse_response is None or self.receive_sampling_rate is None:
            return None
        return np.arange(self.receive_impulse_response.size) / self.receive_sampling_rate

    def element_transmit_impulse_responses(self) -> tuple[NDArray[np.float64],
                                                           NDArray[np.float64]]:
        """Each element's transmit impulse response: ``A_e h(t − τ_e)``, the mean (live
        element) IR ``h`` scaled by the element's relative amplitude and delayed by its
        delay (``element_transmit_amplitude`` / ``_delay``; 1 and 0 without a map; a dead
        element's is zero).

        The element map resolves the elements only in the part of the band where the
        scan's capture angle separates them, so an element differs from the mean by a
        gain and a delay, not by a spectral shape of its own (what a transmit scan can
        tell; the twin's elements share one IR).

        Returns
        -------
        times : ndarray, shape (n_t,)
            s, on the mean IR's time axis (``transmit_time``), extended before 0 and after
            its end by the largest advance and delay.
        irs : ndarray, shape (element_count, n_t)
            In the units of ``transmit_impulse_response``.
        """
        from holoprobe.signal import fractional_delay  # signal is above transducer

        fs = self.transmit_sampling_rate
        n = self.element_count
        amp = (np.ones(n) if self.element_transmit_amplitude is None
               else np.asarray(self.element_transmit_amplitude, float))
        tau = (np.zeros(n) if self.element_transmit_delay is None
               else np.asarray(self.element_transmit_delay, float))
        before = math.ceil(max(0.0, -float(tau.min())) * fs) + 1
        after = math.ceil(max(0.0, float(tau.max())) * fs) + 1
        h = np.concatenate([np.zeros(before), self.transmit_impulse_response,
                            np.zeros(after)])
        irs = fractional_delay(np.broadcast_to(h, (n, h.size)), tau, fs) * amp[:, None]
        return (np.arange(h.size) - before) / fs, irs

    @property
    def has_receive(self) -> bool:
        """Whether a receive impulse response is present."""
        return self.receive_impulse_response is not None

    def replace(self, **changes: Any) -> VirtualTransducer:
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    def _repr_html_(self) -> str:
        """The model as a table (Jupyter): geometry, lens, impulse responses, medium and
        the estimated parameters with their standard uncertainties."""
        mm = 1e3
        rows = [
            ("geometry.element_count", f"{self.element_count}"),
            ("geometry.pitch", f"{self.pitch * mm:.4g} mm"),
            ("geometry.element_width", f"{self.element_width * mm:.4g} mm"),
            ("geometry.aperture", f"{float(self.aperture_width or 0) * mm:.4g} × "
                                  f"{float(self.aperture_height or 0) * mm:.4g} mm (W × H)"),
            ("geometry.lens_focus", "none" if math.isinf(self.lens_focus)
             else f"{self.lens_focus * mm:.4g} mm"),
            ("impulse_responses.transmit",
             f"{self.transmit_impulse_response.size} samples at "
             f"{self.transmit_sampling_rate / 1e6:.4g} MHz ({self.transmit_units})"),
            ("impulse_responses.receive",
             "none" if self.receive_impulse_response is None else
             f"{self.receive_impulse_response.size} samples ({self.receive_units})"),
            ("medium.sound_speed", f"{self.medium.sound_speed:.6g} m/s"),
        ]
        for key, value in sorted(self.parameters.items()):
            unc = self.uncertainties.get(key)
            text = f"{value:.6g}" if unc is None or not unc > 0 else f"{value:.6g} ± {unc:.2g}"
            rows.append((f"parameters (SI).{key}", text))
        title = f"VirtualTransducer {self.name}".rstrip()
        return html_table(title, rows)

    # ------------------------------------------------------------------ files
    def save(self, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
        """Write the model to ``virtual_transducer.h5`` (schema in ``docs/formats.md``).

        The file is written atomically (temporary file, then rename).

        Parameters
        ----------
        path : str or PathLike
            Output file.
        overwrite : bool
            Replace an existing file (default: refuse with :class:`InputError`).

        Returns
        -------
        pathlib.Path
            The written file.
        """
        from holoprobe.transducer._schema import write_virtual_transducer

        return write_virtual_transducer(path, self, overwrite=overwrite)

    @classmethod
    def load(cls, path: str | os.PathLike) -> VirtualTransducer:
        """Read a model written by :meth:`save`, validating every dataset.

        Raises
        ------
        InputError
            Not a holoprobe virtual transducer file, a newer schema, or a missing
            or malformed dataset (the message names the file and the dataset).
        """
        from holoprobe.transducer._schema import read_virtual_transducer

        return read_virtual_transducer(path)

    @classmethod
    def from_preset(cls, name_or_path: str | os.PathLike, *,
                    values: str = "published") -> VirtualTransducer:
        """Build a model from a probe preset (datasheet / published values + packaged IRs).

        Parameters
        ----------
        name_or_path : str or PathLike
            A packaged preset name (``"p4-1"``) or the path of a preset ``.toml``
            (format in ``docs/formats.md``, "Probe presets").
        values : {"published", "datasheet"}
            Which description of the geometry: the published characterization
            results (aperture height H, fitted focus F) or the manufacturer's
            nominal values. A preset without a ``[published]`` table falls back
            to ``"datasheet"`` only when asked for it explicitly.

        Returns
        -------
        VirtualTransducer
            Element geometry and lens from the preset; the impulse responses from
            the preset's ``[impulse_responses]`` file; the medium from
            ``[published.medium]`` (default water); parameters from the chosen
            table; provenance with the SHA-256 of the preset and the IR file.

        Raises
        ------
        InputError
            Unknown preset, a table missing, or a preset without impulse responses.
        """
        from holoprobe.io import (
            file_sha256,
            load_probe_preset,
            probe_info_from_preset,
            read_impulse_responses,
        )

        preset = load_probe_preset(name_or_path)
        file = str(preset["path"])
        info = probe_info_from_preset(preset, values=values)
        irs_table = preset.get("impulse_responses")
        if not isinstance(irs_table, dict) or "path" not in irs_table:
            raise InputError("the preset has no [impulse_responses] file; a virtual transducer "
                             "needs a transmit impulse response", file=file,
                             field="impulse_responses.file")
        ir_path = Path(irs_table["path"])
        if not ir_path.is_file():
            raise InputError("impulse response file not found", file=file,
                             field="impulse_responses.file")
        irs = read_impulse_responses(ir_path)
        table = preset[values]
        medium = irs.medium
        med = table.get("medium") if isinstance(table, dict) else None
        if isinstance(med, dict):
            try:
                medium = Medium(density=med["density"], sound_speed=med["sound_speed"])
            except (KeyError, InputError) as exc:
                raise InputError(f"expected density and sound_speed ({exc})", file=file,
                                 field=f"{values}.medium") from None
        width = table.get("aperture_width")
        parameters = {key: float(table[key]) for key in
                      ("pitch", "element_width", "element_height", "lens_focus",
                       "center_frequency", "aperture_width")
                      if isinstance(table.get(key), int | float)
                      and not isinstance(table.get(key), bool)}
        provenance = Provenance(
            input_files={Path(file).name: file_sha256(file),
                         ir_path.name: file_sha256(ir_path)},
            notes=(f"built from probe preset {preset.get('name', '')!r} ({values} values); "
                   f"geometry source: {table.get('source', '')}; impulse responses: "
                   f"{irs.source} {irs.license}").strip(),
        )
        return cls(
            element_count=info.element_count,
            pitch=info.pitch,
            element_width=info.element_width,
            element_height=info.element_height,
            transmit_impulse_response=irs.transmit,
            transmit_sampling_rate=irs.sampling_rate,
            transmit_units=irs.transmit_units,
            lens_focus=info.lens_focus,
            aperture_width=None if width is None else float(width),
            receive_impulse_response=irs.receive,
            receive_sampling_rate=irs.sampling_rate,
            receive_units=irs.receive_units,
            medium=medium,
            parameters=parameters,
            provenance=provenance,
            name=info.name,
        )
