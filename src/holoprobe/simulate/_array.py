"""The simulated probe: a linear/phased array with an exact cylindrical lens.

The model is the *truth* of the digital twin. It is deliberately richer than the
virtual transducer the characterization recovers (paper section II E): every element is
sampled by its own sub-element midpoint quadrature at ≤ λ/4, the lens delays are the
exact ones (paper eq. lens-delays) rather than a fitted paraxial parabola, and an
optional antisymmetric edge mode (paper section III D) can be added.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import ArrayGeometry, Medium, Surface
from holoprobe.lens import lens_delays
from holoprobe.measurement import DriveSignal, ProbeInfo

if TYPE_CHECKING:
    from holoprobe.io import ImpulseResponses

__all__ = [
    "ArrayModel",
    "EdgeMode",
    "SourceSampling",
    "gaussian_impulse_response",
    "rectangular_pulse",
]


def rectangular_pulse(amplitude: float = 30.0, duration: float = 12e-9,
                      sampling_rate: float = 250e6) -> DriveSignal:
    """A rectangular drive pulse (default: the 12 ns, 30 V pulse of paper section II E).

    Parameters
    ----------
    amplitude : float
        Voltage in V.
    duration : float
        Pulse length in s (rounded to whole samples, at least one).
    sampling_rate : float
        Sampling rate in Hz.
    """
    n = max(1, round(duration * sampling_rate))
    return DriveSignal(np.full(n, float(amplitude)), sampling_rate)


def gaussian_impulse_response(center_frequency: float, *, fractional_bandwidth: float = 0.6,
                              peak: float = 1.2e11, sampling_rate: float = 250e6,
                              phase: float = 0.0) -> NDArray[np.float64]:
    """A Gaussian-modulated impulse response (a stand-in for a probe without a measured one).

    ``h(t) = peak · exp(−(t − t_c)²/(2σ²)) · cos(2π f_c (t − t_c) + phase)`` with σ set
    by the −6 dB fractional bandwidth ``B`` of the amplitude spectrum
    (``σ = √(2 ln 2)/(π B f_c)``), sampled from t = 0 with ``t_c = 4σ``.

    Parameters
    ----------
    center_frequency : float
        f_c in Hz.
    fractional_bandwidth : float
        −6 dB bandwidth over f_c (0 < B ≤ 2).
    peak : float
        Peak value (the P4-1's transmit IR peaks at ≈ 1.2e11 Pa/(V·s)).
    sampling_rate : float
        Hz.
    phase : float
        Carrier phase in rad (0: symmetric pulse).

    Returns
    -------
    ndarray, shape (n,)

    Examples
    --------
    The samples miss the exact peak at t_c by less than half a sample:

    >>> h = gaussian_impulse_response(3e6, fractional_bandwidth=0.6, peak=1.0)
    >>> round(float(abs(h).max()), 3)
    1.0
    """
    fc = _positive_number(center_frequency, "center_frequency")
    band = _positive_number(fractional_bandwidth, "fractional_bandwidth")
    fs = _positive_number(sampling_rate, "sampling_rate")
    if band > 2.0 or fs < 4.0 * fc:
        raise InputError(f"expected 0 < B ≤ 2 and fs ≥ 4 f_c, got B = {band:g}, "
                         f"fs = {fs:g} Hz", field="fractional_bandwidth")
    sigma = math.sqrt(2.0 * math.log(2.0)) / (math.pi * band * fc)
    tc = 4.0 * sigma
    t = np.arange(round(2.0 * tc * fs) + 1) / fs
    return float(peak) * np.exp(-0.5 * ((t - tc) / sigma) ** 2) * np.cos(
        2.0 * np.pi * fc * (t - tc) + phase)


def _positive_number(value: object, name: str) -> float:
    # (type: ignore below) callers pass numbers; float() raises for anything else
    number = float(value)  # type: ignore[arg-type]
    if not (np.isfinite(number) and number > 0):
        raise InputError(f"expected a positive number, got {value!r}", field=name)
    return number


@dataclass(frozen=True)
class EdgeMode:
    """A spurious antisymmetric surface wave launched at the element ends (paper III D).

    A narrowband tone burst leaves the element ends ``y = ±H/2`` at ``delay`` and travels
    along y with ``phase_speed``: inward over the element (towards y = 0) and, when
    ``outside_extent > 0``, outward beyond the active aperture. Its normal velocity is
    antisymmetric in y, ``v(x, −y, t) = −v(x, y, t)``, so it averages out over an element.

    Parameters
    ----------
    amplitude : float
        Peak velocity of the burst relative to the peak of the main surface velocity
        (dimensionless; 0 switches the mode off).
    frequency : float
        Carrier frequency in Hz (paper: about 3.3 MHz).
    cycles : float
        Gaussian envelope standard deviation in carrier cycles (narrowband: several).
    phase_speed : float
        Speed along y in m/s (an assumed value; the paper reports no number). It must
        exceed c0 for the mode to radiate: a surface wave slower than sound only makes
        evanescent waves, which no hydrophone scan a few millimetres away can see. The
        default, 3000 m/s, radiates at asin(c0/3000) ≈ 30° from the normal.
    delay : float
        Time at which the envelope peak leaves the element ends, in s.
    decay_length : float
        Amplitude e-folding length along the path in m (``inf``: no decay).
    direction : {"both", "inward", "outward"}
        Which waves exist.
    outside_extent : float
        How far beyond ±H/2 the outward wave is modelled, in m (0: not at all).
    """

    amplitude: float = 0.1
    frequency: float = 3.3e6
    cycles: float = 2.0
    phase_speed: float = 3000.0
    delay: float = 1.5e-6
    decay_length: float = math.inf
    direction: Literal["both", "inward", "outward"] = "both"
    outside_extent: float = 0.0

    def __post_init__(self) -> None:
        for name in ("frequency", "cycles", "phase_speed", "decay_length"):
            value = float(getattr(self, name))
            if not value > 0:
                raise InputError(f"expected a positive number, got {value!r}",
                                 field=f"edge_mode.{name}")
        if not np.isfinite(self.amplitude):
            raise InputError("expected a finite number", field="edge_mode.amplitude")
        if self.outside_extent < 0:
            raise InputError("expected ≥ 0 m", field="edge_mode.outside_extent")
        if self.direction not in ("both", "inward", "outward"):
            raise InputError("expected 'both', 'inward' or 'outward'",
                             field="edge_mode.direction")

    def waveform(self, sampling_rate: float) -> NDArray[np.float64]:
        """The burst g(t) (unit peak envelope) sampled from t = 0, shape (n,)."""
        sigma = self.cycles / self.frequency
        t_c = 4.0 * sigma
        t = np.arange(round(2 * t_c * sampling_rate) + 1) / sampling_rate
        return np.exp(-0.5 * ((t - t_c) / sigma) ** 2) * np.sin(2 * np.pi * self.frequency
                                                                 * (t - t_c))

    @property
    def waveform_offset(self) -> float:
        """Time of the envelope peak within :meth:`waveform`, in s."""
        return 4.0 * self.cycles / self.frequency


@dataclass(frozen=True)
class SourceSampling:
    """Midpoint quadrature of the array face (finer than any reconstruction grid).

    Attributes
    ----------
    surface : Surface
        Points on z = 0, normals +z, area weights (m²); shape (n,).
    element : ndarray of int, shape (n,)
        Element index of each point.
    y : ndarray, shape (n,)
        Elevation coordinate in m.
    active : ndarray of bool, shape (n,)
        True on the active aperture |y| ≤ H/2; False on the outward edge-mode strips.
    spacing : float
        Largest quadrature step in m.
    """

    surface: Surface
    element: NDArray[np.int64]
    y: NDArray[np.float64]
    active: NDArray[np.bool_]
    spacing: float


def _as_vector(value: ArrayLike | None, n: int, default: float, name: str) -> NDArray:
    if value is None:
        return np.full(n, default)
    arr = np.asarray(value, dtype=float).reshape(-1)
    if arr.size == 1:
        arr = np.full(n, float(arr[0]))
    if arr.shape != (n,):
        raise InputError(f"expected {n} values (one per element), got {arr.size}", field=name)
    if not np.all(np.isfinite(arr)):
        raise InputError("contains NaN or inf", field=name)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class ArrayModel:
    """The simulated probe: geometry, lens, excitation and impulse responses.

    Parameters
    ----------
    element_count : int
        Number of elements N.
    pitch : float
        Element pitch in m.
    element_width : float
        Element width (x) in m; kerf = pitch − width.
    element_height : float
        Active element height H (y) in m.
    lens_focus : float
        Elevation focus F in m of the exact lens (paper eq. lens-delays); ``inf``: none.
    transmit_ir : ndarray, shape (m,)
        Transmit impulse response in Pa/(V·s), defined as ρ0c0·u per volt
        (reference_spec 2.8): ``u(t) = (h_T ⊛ E_T)(t) / (ρ0 c0)`` with ``⊛`` the
        continuous convolution (``np.convolve / ir_sampling_rate``).
    receive_ir : ndarray, shape (m',)
        Receive impulse response in ADCL/(Pa·s): ``E_R = h_R ⊛ p_R``.
    ir_sampling_rate : float
        Sampling rate of both impulse responses and of the drive in Hz; sample 0 is t = 0.
    drive : DriveSignal
        Drive voltage E_T (sample 0 at the transmit event t = 0).
    apodization : array_like, shape (N,), optional
        Per-element transmit amplitude (default 1).
    delays : array_like, shape (N,), optional
        Per-element electronic transmit delays in s (default 0).
    receive_gains : array_like, shape (N,), optional
        Per-element receive gain (dimensionless, default 1): element e records
        ``g_e (h_R ⊛ p_e)``. A dead element has apodization 0 and receive gain 0.
    edge_mode : EdgeMode, optional
        Spurious antisymmetric edge wave (paper section III D); None: absent.
    center_frequency : float
        Nominal centre frequency in Hz (metadata for :class:`ProbeInfo`).
    name : str
        Label, e.g. ``"P4-1"``.
    radius_of_curvature : float, optional
        A convex (curvilinear) array: the face is the cylinder of this radius in m about
        the y axis through (0, 0, −R); ``pitch`` and ``element_width`` are arc lengths.
        None: a flat array.
    array : ArrayGeometry, optional
        Element layout of a 2-D matrix (or other) array; None: the 1-D array above.
        With one, ``element_count`` is ``array.count``, each element is the exact
        rectangle ``widths × heights`` of the geometry integrated by Gauss–Legendre
        cells (:meth:`ArrayGeometry.surface`, ``layout="gauss"``: not the estimators'
        midpoint rule), and there is no lens and no edge mode.

    Notes
    -----
    Coordinates: the aperture centroid is the origin, elements are centred at
    ``x_e = (e − (N−1)/2)·pitch``, span ``|y| ≤ H/2`` and radiate into z > 0 from a rigid
    baffle at z = 0. A convex array is the same strip bent onto its cylinder: the point
    at arc length x lies at ``(R sin(x/R), y, R cos(x/R) − R)`` with the radial normal
    ``(sin(x/R), 0, cos(x/R))`` (:meth:`holoprobe.geometry.ArrayGeometry.convex`); its
    field is the Rayleigh integral of that curved face (each point radiating as a
    baffled monopole of twice its normal velocity — the usual curved-array model).
    With ``array`` the elements sit at its ``positions`` (a flat 2-D grid).
    """

    element_count: int
    pitch: float
    element_width: float
    element_height: float
    lens_focus: float
    transmit_ir: NDArray[np.float64]
    receive_ir: NDArray[np.float64]
    ir_sampling_rate: float
    drive: DriveSignal = field(default_factory=rectangular_pulse)
    apodization: NDArray[np.float64] | None = None
    delays: NDArray[np.float64] | None = None
    receive_gains: NDArray[np.float64] | None = None
    edge_mode: EdgeMode | None = None
    center_frequency: float = 2.5e6
    name: str = ""
    radius_of_curvature: float | None = None
    array: ArrayGeometry | None = None

    def __post_init__(self) -> None:
        n = int(self.element_count)
        if n < 1:
            raise InputError("expected at least one element", field="element_count")
        object.__setattr__(self, "element_count", n)
        for name in ("pitch", "element_width", "element_height", "ir_sampling_rate",
                     "center_frequency"):
            value = float(getattr(self, name))
            if not (np.isfinite(value) and value > 0):
                raise InputError(f"expected a positive number, got {value!r}", field=name)
            object.__setattr__(self, name, value)
        if n > 1 and self.element_width > self.pitch * (1 + 1e-9):
            raise InputError(f"element width {self.element_width:g} m exceeds the pitch "
                             f"{self.pitch:g} m", field="element_width")
        if not float(self.lens_focus) > 0:
            raise InputError("expected a positive focus in m (inf: no lens)",
                             field="lens_focus")
        object.__setattr__(self, "lens_focus", float(self.lens_focus))
        for name in ("transmit_ir", "receive_ir"):
            arr = np.array(getattr(self, name), dtype=float).reshape(-1)
            if arr.size == 0 or not np.all(np.isfinite(arr)):
                raise InputError("expected a non-empty finite 1-D array", field=name)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if not isinstance(self.drive, DriveSignal):
            raise InputError("expected a holoprobe DriveSignal", field="drive")
        if not np.isclose(self.drive.sampling_rate, self.ir_sampling_rate, rtol=1e-9):
            raise InputError(f"the drive is sampled at {self.drive.sampling_rate:g} Hz; "
                             f"expected the impulse-response rate {self.ir_sampling_rate:g} Hz",
                             field="drive")
        object.__setattr__(self, "apodization",
                           _as_vector(self.apodization, n, 1.0, "apodization"))
        object.__setattr__(self, "delays", _as_vector(self.delays, n, 0.0, "delays"))
        object.__setattr__(self, "receive_gains",
                           _as_vector(self.receive_gains, n, 1.0, "receive_gains"))
        if self.edge_mode is not None and not isinstance(self.edge_mode, EdgeMode):
            raise InputError("expected an EdgeMode or None", field="edge_mode")
        if self.radius_of_curvature is not None:
            roc = float(self.radius_of_curvature)
            arc = self.aperture_width + (self.edge_mode.outside_extent
                                         if self.edge_mode is not None else 0.0)
            if not (np.isfinite(roc) and roc > 0 and arc < 2 * np.pi * roc):
                raise InputError(f"expected a radius of curvature in m larger than the arc "
                                 f"{arc:g} m / 2π, got {self.radius_of_curvature!r}",
                                 field="radius_of_curvature")
            object.__setattr__(self, "radius_of_curvature", roc)
        if self.array is not None:
            self._check_array()

    def _check_array(self) -> None:
        array = self.array
        if not isinstance(array, ArrayGeometry):
            raise InputError("expected a holoprobe.geometry.ArrayGeometry or None",
                             field="array")
        if array.count != self.element_count:
            raise InputError(f"the array has {array.count} elements, element_count is "
                             f"{self.element_count}", field="element_count")
        if math.isfinite(self.lens_focus) or self.edge_mode is not None \
                or self.radius_of_curvature is not None:
            raise InputError("an ArrayModel with an element layout (array=) has no lens, "
                             "no edge mode and no radius of curvature", field="array")
        if not np.allclose(array.normals, [0.0, 0.0, 1.0]) or \
                not np.allclose(array.positions[:, 2], 0.0):
            raise InputError("the twin radiates from a flat face on z = 0 (rigid baffle): "
                             "expected element normals +z and centres on z = 0",
                             field="array")

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_preset(cls, preset: str = "p4-1", *, values: str = "published",
                    **overrides: object) -> ArrayModel:
        """The model of a packaged probe preset, with optional field overrides.

        Parameters
        ----------
        preset : str
            Preset name (``"p4-1"``): geometry from the preset data file
            (``holoprobe/data/probes/<name>.toml``), impulse responses from the packaged
            measured ones (:func:`holoprobe.io.load_packaged_impulse_responses`).
        values : {"published", "datasheet"}
            Which geometry of the preset: the published characterization (default; it
            belongs with the measured impulse responses) or the manufacturer's values.
        **overrides
            Any field of :class:`ArrayModel` (e.g. ``element_count=8``, ``edge_mode=...``).
        """
        from holoprobe.io import load_packaged_impulse_responses, load_probe_preset

        info = load_probe_preset(preset)
        irs = load_packaged_impulse_responses(str(info.get("impulse_responses", {})
                                                  .get("name", preset)))
        fields = _preset_fields(info, irs, values)
        unknown = set(overrides) - set(cls.__dataclass_fields__)
        if unknown:
            raise InputError(f"unknown field(s) {sorted(unknown)}", field="overrides")
        fields.update(overrides)
        # (type: ignore below) the preset's fields; the dataclass checks their types
        return cls(**fields)  # type: ignore[arg-type]

    @classmethod
    def matrix(cls, n_x: int = 32, n_y: int | None = None, pitch: float = 0.3e-3, *,
               pitch_y: float | None = None, kerf: float = 0.03e-3,
               center_frequency: float = 3e6, fractional_bandwidth: float = 0.6,
               ir_sampling_rate: float = 250e6, name: str = "",
               active: ArrayLike | None = None, **overrides: object) -> ArrayModel:
        """A flat 2-D matrix array without a lens (issue 16: 32 × 32, 3 MHz, 0.3 mm).

        Elements ``(p − kerf)`` square on an ``n_x × n_y`` grid (index ``iy·n_x + ix``,
        x fastest, see :meth:`ArrayGeometry.matrix`); Gaussian-modulated transmit and
        receive impulse responses at ``center_frequency``
        (:func:`gaussian_impulse_response`, peaks 1.2e11 Pa/(V·s) and 2e6 ADCL/(Pa·s),
        receive with a quarter-cycle phase so the two differ); the 12 ns, 30 V drive.

        Parameters
        ----------
        n_x, n_y : int
            Elements along x and y (``n_y`` default ``n_x``).
        pitch, pitch_y : float
            Pitch along x and y in m (``pitch_y`` default ``pitch``).
        kerf : float
            Gap between elements in m (both directions).
        center_frequency, fractional_bandwidth : float
            Of both impulse responses (Hz, −6 dB bandwidth over f_c).
        ir_sampling_rate : float
            Hz (also the drive's).
        name : str
            Label (default ``"matrix-<n_x>x<n_y>"``, ``"sparse-<n>of<n_x>x<n_y>"``).
        active : array_like of bool, shape (n_y, n_x), optional
            The populated positions of a sparse array (e.g.
            :func:`holoprobe.geometry.sparse_layout`); default all.
        **overrides
            Any other field of :class:`ArrayModel` (e.g. ``apodization``).
        """
        ny = n_x if n_y is None else n_y
        py = pitch if pitch_y is None else pitch_y
        width, height = pitch - kerf, py - kerf
        if not (width > 0 and height > 0):
            raise InputError(f"kerf {kerf:g} m leaves no element of pitch {pitch:g} × "
                             f"{py:g} m", field="kerf")
        array = ArrayGeometry.matrix(n_x, ny, pitch, py, width, height, active=active)
        fields = _flat_array_fields(array, center_frequency, fractional_bandwidth,
                                    ir_sampling_rate)
        fields.update(pitch=float(pitch), element_width=width, element_height=height,
                      name=name or (f"matrix-{n_x}x{ny}" if array.layout == "full"
                                    else f"sparse-{array.count}of{n_x}x{ny}"))
        fields.update(overrides)
        # (type: ignore below) the preset's fields; the dataclass checks their types
        return cls(**fields)  # type: ignore[arg-type]

    @classmethod
    def row_column(cls, n_x: int = 32, n_y: int | None = None, pitch: float = 0.3e-3, *,
                   pitch_y: float | None = None, kerf: float = 0.03e-3,
                   transmit: str = "columns", center_frequency: float = 3e6,
                   fractional_bandwidth: float = 0.6, ir_sampling_rate: float = 250e6,
                   name: str = "", **overrides: object) -> ArrayModel:
        """A flat row-column array (:meth:`ArrayGeometry.row_column`) transmitting with
        one of its two sets of strips; no lens.

        ``transmit`` = ``"columns"`` (the ``n_x`` strips along y, elements 0…n_x−1) or
        ``"rows"`` (the ``n_y`` strips along x, elements n_x…): the other set has
        apodization 0 (it still receives: not dead). Impulse responses and drive as
        :meth:`matrix`; ``pitch``/``element_width``/``element_height`` are the
        transmitting set's (pitch, strip width, strip length).
        """
        array = ArrayGeometry.row_column(n_x, n_y, pitch, pitch_y, kerf)
        if transmit not in ("columns", "rows"):
            raise InputError(f"expected 'columns' or 'rows', got {transmit!r}",
                             field="transmit")
        on = array.strip_set == (0 if transmit == "columns" else 1)
        nx, ny = array.grid_shape or (n_x, n_x)
        fields = _flat_array_fields(array, center_frequency, fractional_bandwidth,
                                    ir_sampling_rate)
        fields.update(pitch=array.pitch[int(transmit == "rows")] if array.pitch else pitch,
                      element_width=float(array.widths[on][0]),
                      element_height=float(array.heights[on][0]),
                      apodization=on.astype(float),
                      name=name or f"row-column-{nx}x{ny}-{transmit}")
        fields.update(overrides)
        # (type: ignore below) the preset's fields; the dataclass checks their types
        return cls(**fields)  # type: ignore[arg-type]

    def replace(self, **changes: object) -> ArrayModel:
        """A copy with some fields changed.

        Changing ``element_count`` keeps a uniform apodization / delay (one value for all
        elements); a non-uniform one must be given again.
        """
        if "element_count" in changes:
            for name in ("apodization", "delays", "receive_gains"):
                current = np.asarray(getattr(self, name))
                if name not in changes:
                    if np.all(current == current[0]):
                        changes[name] = float(current[0])
                    else:
                        raise InputError("the element count changes: give a new per-element "
                                         "vector", field=name)
        # (type: ignore below) per-field changes; the dataclass checks their types
        return replace(self, **changes)  # type: ignore[arg-type]

    def with_element_variation(self, *, amplitude_rms: float = 0.0,
                               delay_rms: float = 0.0, receive_gain_rms: float = 0.0,
                               dead: tuple[int, ...] | list[int] = (),
                               seed: int | None = 0) -> ArrayModel:
        """A copy whose elements differ like those of a real, worn probe.

        Every element's transmit apodization is multiplied by ``1 + amplitude_rms·n``,
        its receive gain by ``1 + receive_gain_rms·n'`` and its delay shifted by
        ``delay_rms·n''`` (independent standard normal draws, seeded); the ``dead``
        elements (0-based) get apodization 0 and receive gain 0.

        Parameters
        ----------
        amplitude_rms, receive_gain_rms : float
            Relative rms variation (e.g. 0.05 for ±5 %).
        delay_rms : float
            Rms delay variation in s (e.g. 8e-9).
        dead : sequence of int
            Indices of dead elements.
        seed : int or None
            Seed of the draws.
        """
        n = self.element_count
        for name, value in (("amplitude_rms", amplitude_rms), ("delay_rms", delay_rms),
                            ("receive_gain_rms", receive_gain_rms)):
            if not (np.isfinite(value) and 0 <= value < (0.5 if name != "delay_rms"
                                                          else 1e-6)):
                raise InputError(f"expected a small non-negative rms, got {value!r}",
                                 field=name)
        dead_idx = np.asarray(list(dead), dtype=int).reshape(-1)
        if np.any((dead_idx < 0) | (dead_idx >= n)):
            raise InputError(f"expected element indices in [0, {n}), got {list(dead)}",
                             field="dead")
        rng = np.random.default_rng(seed)
        amp = np.asarray(self.apodization) * (1.0 + amplitude_rms * rng.standard_normal(n))
        gain = np.asarray(self.receive_gains) * (1.0 + receive_gain_rms
                                                 * rng.standard_normal(n))
        delay = np.asarray(self.delays) + delay_rms * rng.standard_normal(n)
        amp[dead_idx] = 0.0
        gain[dead_idx] = 0.0
        return replace(self, apodization=amp, receive_gains=gain, delays=delay)

    @property
    def dead_elements(self) -> list[int]:
        """0-based indices of the elements that neither transmit nor receive."""
        return [int(i) for i in np.flatnonzero((np.asarray(self.apodization) == 0)
                                               & (np.asarray(self.receive_gains) == 0))]

    # ------------------------------------------------------------------ geometry
    @property
    def aperture_width(self) -> float:
        """Lateral extent W = (N−1)·pitch + width of the active aperture, in m (x)."""
        return self.probe_info().aperture_width

    @property
    def aperture_height(self) -> float:
        """Elevation extent of the active aperture in m (y)."""
        return self.probe_info().aperture_height

    def element_centers(self) -> NDArray[np.float64]:
        """Lateral element centres x_e in m, shape (N,), centred on 0 (arc length on a
        convex array)."""
        if self.array is not None:
            return np.asarray(self.array.positions[:, 0], dtype=np.float64)
        n = self.element_count
        return (np.arange(n, dtype=np.float64) - (n - 1) / 2) * self.pitch

    @property
    def is_convex(self) -> bool:
        """True for a convex (curvilinear) array."""
        return self.radius_of_curvature is not None

    def array_geometry(self) -> ArrayGeometry:
        """The element layout (:class:`holoprobe.geometry.ArrayGeometry`): element
        centres, normals and sizes of the flat, convex or matrix array."""
        if self.array is not None:
            return self.array
        if self.radius_of_curvature is None:
            return ArrayGeometry.linear(self.element_count, self.pitch, self.element_width,
                                        self.element_height)
        return ArrayGeometry.convex(self.element_count, self.pitch, self.radius_of_curvature,
                                    self.element_width, self.element_height)

    def bend(self, points: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Points of the unrolled face (x = arc length, y, z = height above the face) on
        the real face, and the face normals there; shape (n, 3) each.

        The identity (normals +z) for a flat array; on a convex array
        ``(x, y, z) → ((R + z) sin(x/R), y, (R + z) cos(x/R) − R)``.
        """
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        if self.radius_of_curvature is None:
            return p.copy(), np.tile([0.0, 0.0, 1.0], (p.shape[0], 1))
        r = self.radius_of_curvature
        ang = p[:, 0] / r
        s, c = np.sin(ang), np.cos(ang)
        rho = r + p[:, 2]
        return (np.stack([rho * s, p[:, 1], rho * c - r], axis=-1),
                np.stack([s, np.zeros_like(s), c], axis=-1))

    def probe_info(self) -> ProbeInfo:
        """The datasheet view of this model (what a measurement file records)."""
        return ProbeInfo(self.element_count, self.pitch, self.element_width,
                         self.element_height, self.center_frequency, self.lens_focus,
                         self.name, self.array if self.array is not None or not self.is_convex
                         else self.array_geometry())

    def lens_delays(self, y: ArrayLike, medium: Medium) -> NDArray[np.float64]:
        """Exact lens delays τ(y) in s (paper eq. lens-delays), see :func:`lens_delays`."""
        return lens_delays(y, self.lens_focus, self.element_height, medium.sound_speed)

    def sample_surface(self, spacing: float, *, z: float = 0.0) -> SourceSampling:
        """Midpoint quadrature of every element with steps ≤ ``spacing``.

        Parameters
        ----------
        spacing : float
            Largest allowed step in m (e.g. λ/4 at the highest simulated frequency).
        z : float
            Plane of the face in m (0: the virtual transducer surface).

        Returns
        -------
        SourceSampling
            Element-major points; strips beyond ±H/2 for an outward edge mode are appended
            with ``active=False``. On a convex array the cells are the midpoint cells of
            the unrolled face placed on the cylinder (:meth:`bend`; exact areas: the
            cylinder is developable) and ``z`` is a height above the face.
        """
        if not (np.isfinite(spacing) and spacing > 0):
            raise InputError(f"expected a positive step in m, got {spacing!r}",
                             field="spacing")
        if self.array is not None:
            surf = self.array.surface(spacing, layout="gauss", order=3)
            assert surf.element is not None
            pts = surf.points + np.array([0.0, 0.0, float(z)])
            surf = Surface(pts, surf.normals, surf.weights, surf.element)
            return SourceSampling(surf, np.asarray(surf.element), pts[:, 1],
                                  np.ones(surf.size, bool), float(spacing))
        w, h = self.element_width, self.element_height
        nxs = max(1, math.ceil(w / spacing - 1e-9))
        nys = max(1, math.ceil(h / spacing - 1e-9))
        dx, dy = w / nxs, h / nys
        xs = (np.arange(nxs) + 0.5) * dx - 0.5 * w
        ys = (np.arange(nys) + 0.5) * dy - 0.5 * h
        yl = [ys]
        act = [np.ones(nys, bool)]
        em = self.edge_mode
        if em is not None and em.amplitude != 0 and em.outside_extent > 0 \
                and em.direction in ("both", "outward"):
            nout = max(1, math.ceil(em.outside_extent / dy - 1e-9))
            ext = 0.5 * h + (np.arange(nout) + 0.5) * (em.outside_extent / nout)
            yl += [-ext[::-1], ext]
            act += [np.zeros(nout, bool)] * 2
            dy_out = em.outside_extent / nout
        else:
            dy_out = dy
        y_el = np.concatenate(yl)
        active_el = np.concatenate(act)
        dy_el = np.where(active_el, dy, dy_out)
        order = np.argsort(y_el, kind="stable")
        y_el, active_el, dy_el = y_el[order], active_el[order], dy_el[order]
        centers = self.element_centers()
        ex, sx, sy = np.meshgrid(np.arange(self.element_count), xs, np.arange(y_el.size),
                                 indexing="ij")
        ex, sx, sy = ex.ravel(), sx.ravel(), sy.ravel()
        pts, normals = self.bend(np.stack([centers[ex] + sx, y_el[sy],
                                           np.full(ex.size, float(z))], axis=-1))
        weights = dx * dy_el[sy]
        return SourceSampling(Surface(pts, normals, weights), ex.astype(np.int64), y_el[sy],
                              active_el[sy], float(max(dx, dy)))

    # ------------------------------------------------------------------ signals
    def surface_velocity(self, medium: Medium) -> NDArray[np.float64]:
        """Uniform (thickness-mode) surface velocity u(t) in m/s per unit apodization.

        ``u = (h_T ⊛ E_T) / (ρ0 c0)`` (paper eq. transmit-impulse-response with the
        reference_spec 2.8 scaling), sampled at :attr:`ir_sampling_rate` from t = 0 at
        the element ends (zero lens delay). Shape ``(len(h_T) + len(E_T) − 1,)``.
        """
        u = np.convolve(self.transmit_ir, self.drive.voltage) / self.ir_sampling_rate
        return u / medium.impedance


def _preset_fields(info: dict, irs: ImpulseResponses, values: str) -> dict[str, object]:
    """ArrayModel fields from a preset table (:func:`holoprobe.io.load_probe_preset`)."""
    table = info.get(values)
    if not isinstance(table, dict):
        raise InputError(f"the preset has no [{values}] table (expected 'published' or "
                         "'datasheet')", field="values")
    fs = float(irs.sampling_rate)
    return {
        "element_count": int(table["element_count"]),
        "pitch": float(table["pitch"]),
        "element_width": float(table["element_width"]),
        "element_height": float(table["element_height"]),
        "lens_focus": float(table.get("lens_focus", math.inf)),
        "center_frequency": float(table.get("center_frequency", 2.5e6)),
        "name": str(info.get("name", "")),
        "radius_of_curvature": (float(table["radius_of_curvature"])
                                if "radius_of_curvature" in table else None),
        "transmit_ir": np.asarray(irs.transmit, dtype=np.float64),
        "receive_ir": np.asarray(irs.receive, dtype=np.float64),
        "ir_sampling_rate": fs,
        "drive": rectangular_pulse(sampling_rate=fs),
    }


def _flat_array_fields(array: ArrayGeometry, center_frequency: float,
                       fractional_bandwidth: float, ir_sampling_rate: float
                       ) -> dict[str, object]:
    """The fields a flat 2-D twin (matrix, sparse, row-column) shares: Gaussian transmit
    and receive IRs (peaks 1.2e11 Pa/(V·s), 2e6 ADCL/(Pa·s), the receive a quarter
    cycle apart), the 12 ns drive, no lens."""
    fs = float(ir_sampling_rate)
    return {
        "element_count": array.count, "lens_focus": math.inf,
        "transmit_ir": gaussian_impulse_response(
            center_frequency, fractional_bandwidth=fractional_bandwidth, peak=1.2e11,
            sampling_rate=fs),
        "receive_ir": gaussian_impulse_response(
            center_frequency, fractional_bandwidth=fractional_bandwidth, peak=2e6,
            sampling_rate=fs, phase=-0.5 * math.pi),
        "ir_sampling_rate": fs, "drive": rectangular_pulse(sampling_rate=fs),
        "center_frequency": float(center_frequency), "array": array}
