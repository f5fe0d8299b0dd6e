"""The nouns of a holography measurement: probe datasheet, drive, calibration, scan, echo.

These are plain frozen dataclasses; reading and writing them is
:mod:`holoprobe.io`, making synthetic ones is :mod:`holoprobe.simulate`.
Units are SI (V, Pa, s, Hz, m) unless a field says otherwise.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import ArrayGeometry, Medium, PlaneGrid, SourceGeometry

__all__ = [
    "DriveSignal",
    "EchoRecording",
    "Hologram",
    "HydrophoneCalibration",
    "HydrophoneScan",
    "ProbeInfo",
    "adopt_read_only",
]


# arrays a reader made and handed over (no one else holds them): kept without a copy
_ADOPTED: weakref.WeakValueDictionary[int, NDArray] = weakref.WeakValueDictionary()


def adopt_read_only(array: NDArray) -> NDArray:
    """Mark a freshly read array that no one else holds as the measurement's own.

    For readers in :mod:`holoprobe.io`: the array is made read-only, and a measurement
    built from it keeps it as it is instead of copying it (132 MB for a full-size scan).
    Any other array given to a measurement is copied, so that the caller's later writes
    cannot change the frozen object.

    Parameters
    ----------
    array : numpy.ndarray
        An array that owns its memory and that the caller drops after building the
        measurement.

    Returns
    -------
    numpy.ndarray
        The same array, read-only.
    """
    array.setflags(write=False)
    _ADOPTED[id(array)] = array
    return array


def _finite_array(value: object, name: str, ndim: int | None = None) -> NDArray:
    # a reader's adopted array is kept as it is; any other input is copied
    adopted = isinstance(value, np.ndarray) and _ADOPTED.get(id(value)) is value
    arr: NDArray = value if adopted else np.array(value)  # type: ignore[assignment]  # ndarray when adopted
    if ndim is not None and arr.ndim != ndim:
        raise InputError(f"expected a {ndim}-D array, got shape {arr.shape}", field=name)
    if arr.size == 0:
        raise InputError("array is empty", field=name)
    if not np.issubdtype(arr.dtype, np.number):
        raise InputError(f"expected numbers, got dtype {arr.dtype}", field=name)
    if not np.all(np.isfinite(arr)):
        raise InputError("contains NaN or inf", field=name)
    arr.setflags(write=False)
    return arr


def _positive(value: float, name: str) -> float:
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise InputError(f"expected a positive number, got {value!r}", field=name)
    return value


@dataclass(frozen=True)
class ProbeInfo:
    """Nominal (datasheet) description of a linear or phased array.

    Parameters
    ----------
    element_count : int
        Number of elements.
    pitch : float
        Element pitch in m.
    element_width : float
        Element width (lateral, x) in m; kerf = pitch − width.
    element_height : float
        Element height (elevation, y) in m.
    center_frequency : float
        Nominal centre frequency in Hz.
    lens_focus : float
        Nominal elevation lens focus in m (``inf``: no lens).
    name : str
        A label, e.g. ``"P4-1"``.
    array : ArrayGeometry, optional
        Every element's position, normal and size (convex, 2-D matrix or any other
        layout); None: the flat 1-D array of ``element_count`` elements at ``pitch``
        along x (:meth:`geometry`). ``element_count`` must equal ``array.count``; for
        a matrix ``pitch``/``element_width``/``element_height`` are the x pitch and the
        element's x and y size.
    """

    element_count: int
    pitch: float
    element_width: float
    element_height: float
    center_frequency: float
    lens_focus: float = float("inf")
    name: str = ""
    array: ArrayGeometry | None = None

    def __post_init__(self) -> None:
        if int(self.element_count) < 1:
            raise InputError("expected at least one element", field="element_count")
        object.__setattr__(self, "element_count", int(self.element_count))
        for name in ("pitch", "element_width", "element_height", "center_frequency"):
            object.__setattr__(self, name, _positive(getattr(self, name), name))
        if self.element_width > self.pitch * (1 + 1e-9) and self.element_count > 1:
            raise InputError(
                f"element width {self.element_width:g} m exceeds the pitch {self.pitch:g} m",
                field="element_width",
            )
        if not (self.lens_focus > 0):
            raise InputError("expected a positive focus in m (inf for no lens)",
                             field="lens_focus")
        if self.array is not None:
            if not isinstance(self.array, ArrayGeometry):
                raise InputError("expected a holoprobe.geometry.ArrayGeometry or None",
                                 field="array")
            if self.array.count != self.element_count:
                raise InputError(f"the array describes {self.array.count} elements, the "
                                 f"probe {self.element_count}", field="element_count")

    @property
    def is_matrix(self) -> bool:
        """True for a 2-D matrix array (``array.kind == "matrix"``)."""
        return self.array is not None and self.array.kind == "matrix"

    def geometry(self) -> ArrayGeometry:
        """The element layout: :attr:`array`, or the flat 1-D array it implies."""
        if self.array is not None:
            return self.array
        return ArrayGeometry.linear(self.element_count, self.pitch, self.element_width,
                                    self.element_height)

    @property
    def aperture_width(self) -> float:
        """Lateral width of the active aperture (N−1)·pitch + width, in m (a matrix:
        (n_x − 1)·p_x + w along x)."""
        if self.is_matrix:
            assert self.array is not None and self.array.grid_shape is not None
            return (self.array.grid_shape[0] - 1) * self.pitch + self.element_width
        return (self.element_count - 1) * self.pitch + self.element_width

    @property
    def aperture_height(self) -> float:
        """Elevation extent of the active aperture in m: the element height, or for a
        matrix (n_y − 1)·p_y + h."""
        if self.is_matrix:
            assert self.array is not None and self.array.grid_shape is not None
            pitch_y = self.array.pitch[1] if self.array.pitch is not None else self.pitch
            return (self.array.grid_shape[1] - 1) * pitch_y + self.element_height
        return self.element_height

    @property
    def kerf(self) -> float:
        """Gap between elements, pitch − width, in m."""
        return self.pitch - self.element_width

    def element_centers(self) -> NDArray[np.float64]:
        """Lateral centres of the elements in m, shape (element_count,), centred on 0."""
        n = self.element_count
        return (np.arange(n) - (n - 1) / 2).astype(np.float64) * self.pitch


@dataclass(frozen=True)
class DriveSignal:
    """A sampled drive voltage.

    Parameters
    ----------
    voltage : array_like, shape (n,)
        Voltage in V.
    sampling_rate : float
        Sampling rate in Hz.
    """

    voltage: NDArray[np.float64]
    sampling_rate: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "voltage",
                           _finite_array(np.asarray(self.voltage, float).reshape(-1), "voltage"))
        object.__setattr__(self, "sampling_rate", _positive(self.sampling_rate, "sampling_rate"))

    @property
    def area(self) -> float:
        """Time integral of the voltage in V·s."""
        return float(np.sum(self.voltage) / self.sampling_rate)

    @property
    def peak(self) -> float:
        """Largest absolute voltage in V."""
        return float(np.max(np.abs(self.voltage)))

    @property
    def duration(self) -> float:
        """Record length in s."""
        return self.voltage.size / self.sampling_rate


@dataclass(frozen=True)
class HydrophoneCalibration:
    """Hydrophone sensitivity versus frequency.

    Parameters
    ----------
    frequency : array_like, shape (m,)
        Calibration frequencies in Hz, increasing.
    sensitivity : array_like, shape (m,)
        Sensitivity magnitude in V/Pa.
    phase : array_like, shape (m,), optional
        Phase of the sensitivity in rad, in holoprobe's Fourier convention
        (``P(ω) = conj(FFT{p})``); ``None`` for a magnitude-only calibration.
    polarity : {1, -1}
        Sign of the output voltage for a positive pressure.
    name : str
        A label (model, serial number, source of the data).
    u_sensitivity : array_like, shape (m,), optional
        Standard uncertainty (k = 1) of the magnitude in V/Pa.
    u_phase : array_like, shape (m,), optional
        Standard uncertainty (k = 1) of the phase in rad.

    Notes
    -----
    Calibration certificates and PyDynamic give the phase of ``M(f) = U(f)/P(f)`` in
    the FFT convention (``numpy.fft``, ``exp(−i2πft)``); it is the negative of
    holoprobe's. :meth:`from_fft_phase` and :attr:`phase_fft` are the one place where
    the two are converted.
    """

    frequency: NDArray[np.float64]
    sensitivity: NDArray[np.float64]
    phase: NDArray[np.float64] | None = None
    polarity: int = 1
    name: str = ""
    u_sensitivity: NDArray[np.float64] | None = None
    u_phase: NDArray[np.float64] | None = None

    @classmethod
    def from_fft_phase(cls, frequency: NDArray, magnitude: NDArray, phase_fft: NDArray | None,
                       **kwargs: object) -> HydrophoneCalibration:
        """Build from a phase in the FFT convention (``M = FFT{u} / FFT{p}``, numpy's
        ``exp(−i2πft)``): holoprobe's phase is ``−phase_fft``."""
        phase = None if phase_fft is None else -np.asarray(phase_fft, float)
        return cls(frequency=frequency, sensitivity=magnitude, phase=phase,
                   # (type: ignore below) the remaining dataclass fields, checked by __post_init__
                   **kwargs)  # type: ignore[arg-type]

    @property
    def phase_fft(self) -> NDArray[np.float64] | None:
        """The phase in the FFT convention (``−phase``), rad; None without a phase."""
        return None if self.phase is None else -self.phase

    def __post_init__(self) -> None:
        f = _finite_array(np.asarray(self.frequency, float), "frequency", ndim=1)
        s = _finite_array(np.asarray(self.sensitivity, float), "sensitivity", ndim=1)
        if s.shape != f.shape:
            raise InputError(f"expected {f.size} values like 'frequency', got {s.size}",
                             field="sensitivity")
        if np.any(np.diff(f) <= 0):
            raise InputError("frequencies must increase", field="frequency")
        if np.any(s <= 0):
            raise InputError("sensitivity magnitudes must be positive (V/Pa)",
                             field="sensitivity")
        object.__setattr__(self, "frequency", f)
        object.__setattr__(self, "sensitivity", s)
        if self.phase is not None:
            ph = _finite_array(np.asarray(self.phase, float), "phase", ndim=1)
            if ph.shape != f.shape:
                raise InputError(f"expected {f.size} values like 'frequency'", field="phase")
            object.__setattr__(self, "phase", ph)
        if self.polarity not in (1, -1):
            raise InputError("expected 1 or -1", field="polarity")
        for name in ("u_sensitivity", "u_phase"):
            value = getattr(self, name)
            if value is None:
                continue
            u = _finite_array(np.asarray(value, float), name, ndim=1)
            if u.shape != f.shape or np.any(u < 0):
                raise InputError(f"expected {f.size} non-negative values like 'frequency'",
                                 field=name)
            object.__setattr__(self, name, u)
        if self.u_phase is not None and self.phase is None:
            raise InputError("a phase uncertainty needs a phase", field="u_phase")


@dataclass(frozen=True)
class HydrophoneScan:
    """A raster scan of the transmitted field on a plane in front of the transducer.

    Parameters
    ----------
    data : array_like, shape (nx, ny, nt)
        Hydrophone output in V (``quantity="voltage"``) or pressure in Pa
        (``quantity="pressure"``), time last.
    grid : PlaneGrid
        In-plane scan coordinates in m. Its pose is the nominal placement
        (identity when unknown); the characterization estimates the true pose.
    sampling_rate : float
        Sampling rate of the time axis in Hz.
    start_time : float
        Time of the first sample relative to the transmit event, in s.
    quantity : {"voltage", "pressure"}
        What ``data`` holds.
    medium : Medium
        The propagation medium.
    calibration : HydrophoneCalibration, optional
        Needed to convert voltage to pressure.
    probe : ProbeInfo, optional
        Nominal description of the transducer.
    drive : DriveSignal, optional
        Drive voltage of the transmit event (for the transmit impulse response).
    source : str
        Where the data came from (a file path, ``"simulated"``).
    """

    data: NDArray
    grid: PlaneGrid
    sampling_rate: float
    start_time: float = 0.0
    quantity: Literal["voltage", "pressure"] = "voltage"
    medium: Medium = field(default_factory=Medium)
    calibration: HydrophoneCalibration | None = None
    probe: ProbeInfo | None = None
    drive: DriveSignal | None = None
    source: str = ""

    def __post_init__(self) -> None:
        data = _finite_array(self.data, "data", ndim=3)
        if data.shape[:2] != self.grid.shape:
            raise InputError(
                f"expected shape {(*self.grid.shape, data.shape[2])} to match the grid "
                f"(nx, ny) = {self.grid.shape}, got {data.shape}",
                field="data",
            )
        if data.shape[2] < 2:
            raise InputError("expected at least 2 time samples", field="data")
        object.__setattr__(self, "data", data)
        object.__setattr__(self, "sampling_rate", _positive(self.sampling_rate, "sampling_rate"))
        if self.quantity not in ("voltage", "pressure"):
            raise InputError("expected 'voltage' or 'pressure'", field="quantity")

    @property
    def n_samples(self) -> int:
        """Number of time samples nt."""
        return int(self.data.shape[2])

    @property
    def time(self) -> NDArray[np.float64]:
        """Sample times in s, shape (nt,)."""
        return self.start_time + np.arange(self.n_samples) / self.sampling_rate


@dataclass(frozen=True)
class EchoRecording:
    """Element RF of the reflector experiment (pulse-echo from a flat plate).

    Parameters
    ----------
    rf : array_like, shape (n_elements, n_samples)
        Received signal per element (time last), in ``unit``.
    sampling_rate : float
        Sampling rate in Hz.
    start_time : float
        Time of the first sample relative to the transmit event, in s.
    unit : str
        ``"ADCL"`` (analogue-to-digital converter levels) or ``"V"``.
    drive : DriveSignal, optional
        Drive voltage used in this (receive) experiment.
    probe : ProbeInfo, optional
        Nominal description of the transducer.
    medium : Medium
        The propagation medium.
    source : str
        Where the data came from.
    """

    rf: NDArray
    sampling_rate: float
    start_time: float = 0.0
    unit: str = "ADCL"
    drive: DriveSignal | None = None
    probe: ProbeInfo | None = None
    medium: Medium = field(default_factory=Medium)
    source: str = ""

    def __post_init__(self) -> None:
        rf = _finite_array(self.rf, "rf", ndim=2)
        object.__setattr__(self, "rf", rf)
        object.__setattr__(self, "sampling_rate", _positive(self.sampling_rate, "sampling_rate"))
        if self.probe is not None and rf.shape[0] != self.probe.element_count:
            raise InputError(
                f"expected {self.probe.element_count} channels (one per element) along the "
                f"first axis, got shape {rf.shape}",
                field="rf",
            )

    @property
    def n_samples(self) -> int:
        """Number of time samples."""
        return int(self.rf.shape[1])

    @property
    def time(self) -> NDArray[np.float64]:
        """Sample times in s, shape (n_samples,)."""
        return self.start_time + np.arange(self.n_samples) / self.sampling_rate


def _plausible(value: float, name: str) -> float:
    """Noun-level check against the default ranges (:mod:`holoprobe.plausibility`)."""
    from holoprobe.plausibility import DEFAULT_PLAUSIBILITY

    return DEFAULT_PLAUSIBILITY.check(name, value)


@dataclass(frozen=True)
class Hologram:
    """A hologram: the pressure on a plane in front of a source, CW or transient.

    Parameters
    ----------
    pressure : array_like
        CW (``frequency`` set): complex pressure amplitude in Pa, shape (nx, ny), in
        holoprobe's Fourier convention: the pressure is ``p(t) = Re{P e^{−iωt}}``
        (``P`` is the conjugate of the amplitude in MATLAB's ``fft`` convention).
        Transient (``sampling_rate`` set): real waveforms in Pa, shape (nx, ny, nt).
    grid : PlaneGrid
        The scan grid: uniform, increasing x and y in m (positions, never indices).
        Its pose is the nominal placement of the plane in source coordinates (apex
        at the origin, axis +z): identity rotation, origin (0, 0, z_position).
    medium : Medium
        The propagation medium.
    frequency : float, optional
        Frequency of a CW hologram in Hz.
    sampling_rate : float, optional
        Sampling rate of a transient hologram in Hz.
    start_time : float
        Time of sample 0 of a transient hologram in s.
    geometry : SourceGeometry, optional
        Nominal description of the source.
    source : str
        Where the data came from (file path, ``"simulated"``).
    notes : tuple of str
        Assumptions the reader made that the file could not settle (one line each; the
        characterization repeats them among its warnings).

    Notes
    -----
    Scan coordinates: origin at the grid's x = 0, y = 0 on the scan plane, x and y
    along the grid axes, z normal to the plane pointing away from the source.
    ``z_position`` is the nominal distance of the plane from the source's apex along
    the beam (the holography community's ``zPosition``).
    """

    pressure: NDArray
    grid: PlaneGrid
    medium: Medium = field(default_factory=Medium)
    frequency: float | None = None
    sampling_rate: float | None = None
    start_time: float = 0.0
    geometry: SourceGeometry | None = None
    source: str = ""
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if (self.frequency is None) == (self.sampling_rate is None):
            raise InputError("give either a frequency (CW) or a sampling rate (transient)",
                             field="frequency")
        if not isinstance(self.grid, PlaneGrid):
            raise InputError("expected a holoprobe.PlaneGrid", field="grid")
        if not isinstance(self.medium, Medium):
            raise InputError("expected a holoprobe.Medium", field="medium")
        _plausible(self.medium.sound_speed, "sound_speed")
        _plausible(self.medium.density, "density")
        if self.geometry is not None and not isinstance(self.geometry, SourceGeometry):
            raise InputError("expected a holoprobe.geometry.SourceGeometry", field="geometry")
        cw = self.frequency is not None
        raw = np.asarray(self.pressure)
        if raw.size == 0:
            raise InputError("is empty", field="pressure")
        if cw:
            if raw.dtype.kind not in "iufc":
                raise InputError(f"expected numbers, got dtype {raw.dtype}", field="pressure")
            raw = raw.astype(np.complex128) if raw.dtype.kind != "c" else raw
        elif raw.dtype.kind == "c":
            raise InputError("transient waveforms must be real", field="pressure")
        data = _finite_array(raw, "pressure", ndim=2 if cw else 3)
        if data.shape[:2] != self.grid.shape:
            raise InputError(f"expected (nx, ny) = {self.grid.shape} to match the grid, got "
                             f"shape {data.shape}", field="pressure")
        object.__setattr__(self, "pressure", data)
        if self.frequency is not None:
            object.__setattr__(self, "frequency",
                               _plausible(_positive(self.frequency, "frequency"), "frequency"))
        elif self.sampling_rate is not None:
            if data.shape[2] < 2:
                raise InputError("expected at least 2 time samples", field="pressure")
            object.__setattr__(self, "sampling_rate",
                               _positive(self.sampling_rate, "sampling_rate"))
            if not np.isfinite(self.start_time):
                raise InputError("expected a finite time in s", field="start_time")
            object.__setattr__(self, "start_time", float(self.start_time))
        if self.z_position <= 0:
            raise InputError(f"zPosition = {self.z_position:g} m: the hologram must lie in "
                             "front of the source's apex (z > 0)", field="z_position")
        self._check_not_inside_bowl()

    def _check_not_inside_bowl(self) -> None:
        """A plane closer than the rim must fit inside the bowl's cavity at that depth."""
        g = self.geometry
        z = self.z_position
        if g is None or not g.is_focused or z >= g.rim_depth:
            return
        # (type: ignore below) a focused geometry has a radius of curvature
        roc = float(g.radius_of_curvature)  # type: ignore[arg-type]
        cavity = 2.0 * np.sqrt(max(roc * roc - (roc - z) ** 2, 0.0))
        lx = self.grid.x[-1] - self.grid.x[0]
        ly = self.grid.y[-1] - self.grid.y[0]
        if np.hypot(lx, ly) > cavity:
            raise InputError(
                f"zPosition = {z * 1e3:.3g} mm is inside the bowl (rim at {g.rim_depth * 1e3:.3g}"
                f" mm from the apex), where its cavity is {cavity * 1e3:.3g} mm wide: a "
                f"{lx * 1e3:.3g} × {ly * 1e3:.3g} mm scan there would reach behind the source",
                field="z_position")

    @property
    def is_transient(self) -> bool:
        """True for waveforms (nx, ny, nt), False for a CW amplitude (nx, ny)."""
        return self.frequency is None

    @property
    def z_position(self) -> float:
        """Nominal distance of the plane from the source's apex along the beam, in m."""
        return float(self.grid.pose.origin[2])

    @property
    def n_samples(self) -> int:
        """Number of time samples (1 for a CW hologram)."""
        return int(self.pressure.shape[2]) if self.is_transient else 1

    @property
    def time(self) -> NDArray[np.float64]:
        """Sample times in s, shape (nt,) (transient only)."""
        if self.sampling_rate is None:
            raise InputError("a CW hologram has no time axis", field="time")
        return self.start_time + np.arange(self.n_samples) / self.sampling_rate
