"""Receive of a 2-D matrix array (no lens) from a flat reflector (issue 16).

Geometry
--------
Source frame of the matrix (:meth:`holoprobe.geometry.ArrayGeometry.matrix`): the
elements on z = 0 at ``x_i = (x_i, y_i, 0)``, normals +z. The plate's front face passes
through ``p0 = (0, 0, d)`` with the unit normal
``n = (sin(θy'/2) cos(θx'/2), −sin(θx'/2), cos(θy'/2) cos(θx'/2))``
(:func:`holoprobe.geometry.plate_plane` with its second tilt); the mirror is
``M(p) = p − 2((p − p0)·n) n``. By the image method the echo of the whole array received
by element i is Rp times the field the array radiates without the plate, averaged over
the mirror image of element i's face: the virtual receiver is the mirrored 2-D grid,
tilted by (θx', θy'), its centre at ``M(0) = 2 d n_z n``.

Arrivals. The echo at element i is the array's field at ``M(x_i)``: it arrives after
the group delay of that field (:func:`matrix_echo_delays`: the Fresnel sum over the
element centres, averaged over the band), plus a common delay t_c (the transmit and
receive impulse responses, the arrival estimator's reference). For a plate far beyond
the array's near field that is ``|M(x_i)|/c0`` (the distance from the array centre to
the image of the element):

    t_i = t_c + |M(x_i)|/c0 = t_c + (2 d n_z − n·x_i + O(r²/d))/c0,

a plane across the grid, sloping towards the image of the centre,
``−sin(θy'/2) cos(θx'/2)/c0`` along x and ``+sin(θx'/2)/c0`` along y (half the tilts),
whose spherical curvature ≈ r²/(4d) alone separates d from t_c. Inside the near field
(the images in the aperture's shadow) the echo is the plane wave the plate reflects,
``M(x_i)_z/c0``: the arrivals slope by the whole tilts (the 32 × 32, 9.6 mm matrix and
a plate at 15 mm lie between the two; a far-field model there doubled the tilts and put
d at 0.32 m). For a flat 1-D array the onset is used instead, which needs the receive
IR to start at 0 (a matrix twin's Gaussian IR does not). :func:`fit_matrix_echo_pose`
fits (t_c, d, θx', θy') by robust least squares. The model ignores the element
directivity and is only as good as the Fresnel sum; the predicted pressures carry the
rest: :func:`refine_matrix_pose` compares every element's RF with its own predicted pressure
(:func:`element_sensitivity` delays δ_i) and fits the model again to
``t_i(pose) + δ_i``, ``receive.pose_iterations`` times (as the convex path does).

Near field (:func:`fresnel_number` > :data:`NEAR_FIELD_FRESNEL`): the pattern of δ_i
that a change of d makes is weak and not the model's (32 × 32 at 15 mm, Fresnel number
3.1: 0.8 ns rms per 0.5 mm against the model's 7.2 ns, uncorrelated), so the model's d
column put σ(d) at 8.5 µm for a 2.3 mm error. There the d column is measured on a
second prediction at d + 10 % (:func:`distance_column`; again once d has moved more than
a quarter of that chord, and the near-field test is made at the current d, not only at the
arrival fit's band-dependent start), its scale follows the secant of the d steps (a step
is cut to twice the last one), up to twice ``receive.pose_iterations`` steps are taken
while d still moves by more than its σ, and the last step joins σ of the pose.
The column is a chord, not a local slope: the delays' d dependence holds a short
structure on top of its trend (32 × 32: measured over 0.3 mm the column was ~6× the
chord over 2 mm, and d went 2570 → 2136 → 1776 → 1054 µm; over 1.5 mm: 2570 → 395 →
−49 → −71 µm, σ 32 µm).

Element pressure: the measured scan forward-projected (type-3 NUFFT,
:meth:`SensorPredictor.on_surface`) onto midpoint cells of the mirrored element faces
(:func:`matrix_mirrored_faces`), averaged per element. Receive IR: the RF and the
pressure aligned by the same delays ``t_i − min t_i`` and averaged over the used
elements, one regularised deconvolution (:func:`receive_ir_step`); per-element receive
gains and delays by :func:`sensitivity_step`, as for a flat array.
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Literal, cast

import numpy as np
import scipy.optimize
from numpy.typing import ArrayLike, NDArray

from holoprobe.characterize._alignment import hologram_noise_level
from holoprobe.characterize._config import CharacterizationConfig
from holoprobe.characterize._convex_receive import (
    _AtDistance,
    _candidates,
    _fit_options,
    faces_sensor_predictor,
)
from holoprobe.characterize._elements import steering_uncertainty
from holoprobe.characterize._matrix import MatrixElementMap
from holoprobe.characterize._pipeline import TransmitResult, _Timer
from holoprobe.characterize._receive import ReceiveConfig
from holoprobe.characterize._receive_ir import ElementSensitivity, element_sensitivity
from holoprobe.characterize._receive_pipeline import (
    ReceiveResult,
    SensorPredictor,
    SensorProjection,
    _echo_rf,
    _receive_config,
    noise_options,
    receive_ir_step,
    reflection_step,
    sensitivity_step,
)
from holoprobe.characterize._virtual_receiver import (
    SensorLayout,
    VirtualReceiver,
    aligned_average,
    average_onset,
    echo_arrivals,
    echo_search_window,
)
from holoprobe.errors import FitError, InputError
from holoprobe.geometry import ArrayGeometry, Pose, Surface, plate_plane
from holoprobe.measurement import EchoRecording, HydrophoneCalibration, HydrophoneScan
from holoprobe.signal import (
    fractional_delay,
    frequency_axis,
    mad_sigma,
    spectrum_summary,
    to_frequency,
)

__all__ = [
    "MatrixEchoPose",
    "MatrixFace",
    "characterize_matrix_receive",
    "fit_matrix_echo_pose",
    "fresnel_number",
    "lattice_coordinates",
    "matrix_array",
    "matrix_echo_delays",
    "matrix_face_offset",
    "matrix_mirrored_faces",
    "matrix_sensor_predictor",
    "pose_gain_uncertainty",
    "prediction_noise_pose",
    "refine_matrix_pose",
]


# --------------------------------------------------------------------------- nouns
@dataclass(frozen=True)
class MatrixFace:
    """What the receive step needs from the transmit characterization of a matrix.

    Attributes
    ----------
    geometry : ArrayGeometry
        The matrix (kind ``"matrix"``, centred on the origin of the source frame, z = 0).
    scan_pose : Pose
        The scan plane in that source frame: its z0 is the geometric distance from the
        face (not the transmit pose's onset convention, see :meth:`from_transmit`).
    band : (float, float)
        Signal band in Hz (the projection's frequencies).
    focus : float
        Always ``inf`` (no lens).
    face_uncertainty : float
        Standard uncertainty (m) of the face's position along z in that frame; half of
        it joins σ(d) (the image grid lies 2d from the face).
    window_corrected : bool
        False when the face was placed by a defocus that still holds the scan window's
        bias (the transmit fit's window correction was off or failed): the receive
        then says so in its warnings, since ``face_uncertainty`` does not cover it.
    steering : (float, float)
        Standard uncertainties (rad) of the beam steering about x and y that the
        element delays may hold while the transmit shows none (its acoustic-axis
        convention, :func:`~holoprobe.characterize.steering_uncertainty` of the map's
        delays along y and x); (0, 0) for a face given in the array's own frame. A
        plate in the array's near field reflects the transmitted beam, so the fitted
        tilts follow the scan pose's frame, not the elements': on the 32 × 32 twins at
        10 and 15 mm θx', θy' were off by the true delays' trend angles (+0.0019°,
        +0.0030° on seed 1; −0.0027°/+0.0031° and +0.0020°/+0.0005° on seeds 3, 2).
        Joined to σ(θx'), σ(θy') when the near-field path runs (far field: 0.11× the
        steering on the 8 × 8 twin, left out).
    """

    geometry: ArrayGeometry
    scan_pose: Pose
    band: tuple[float, float]
    focus: float = math.inf
    face_uncertainty: float = 0.0
    window_corrected: bool = True
    steering: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        _matrix(self.geometry)
        if not isinstance(self.scan_pose, Pose):
            raise InputError("expected a holoprobe.Pose", field="scan_pose")
        f_lo, f_hi = (float(v) for v in self.band)
        if not (0 <= f_lo < f_hi and math.isfinite(f_hi)):
            raise InputError(f"expected a band (f_low, f_high) in Hz with f_low < f_high, "
                             f"got {self.band!r}", field="band")
        if not math.isinf(self.focus):
            raise InputError(f"a matrix array has no lens: expected focus inf, got "
                             f"{self.focus!r}", field="focus")
        if not (math.isfinite(self.face_uncertainty) and self.face_uncertainty >= 0):
            raise InputError(f"expected a face uncertainty >= 0 in m, got "
                             f"{self.face_uncertainty!r}", field="face_uncertainty")
        if len(self.steering) != 2 or not all(math.isfinite(v) and v >= 0
                                               for v in self.steering):
            raise InputError(f"expected two steering uncertainties >= 0 in rad, got "
                             f"{self.steering!r}", field="steering")

    @property
    def height(self) -> float:
        """Element height in m."""
        return float(self.geometry.heights[0])

    @classmethod
    def from_transmit(cls, result: TransmitResult) -> MatrixFace:
        """From :func:`characterize_transmit`'s result of a matrix scan: the grid of its
        element map (:func:`matrix_array`), the scan pose and its frequencies' band.

        The transmit pose's z0 is the onset convention's (the transmit IR starts at
        t = 0): it holds c0 × the IR's onset delay (0.62 mm on the 3 MHz 8 × 8 twin),
        which put the virtual receiver that far too: d came out 0.31 mm long. The face
        is where the map's defocus δ puts it (:func:`matrix_face_offset`), so the scan
        pose here is the transmit pose moved back by that offset along z."""
        geo = matrix_array(result.element_map)
        if geo is None:
            raise InputError("the transmit characterization has no matrix element map "
                             "(not a matrix array, or elements.enabled = false)",
                             field="element_map")
        offset, u_offset = matrix_face_offset(result)
        pose = result.pose
        x0, y0, z0 = pose.origin
        scan_pose = dataclasses.replace(pose, origin=(x0, y0, z0 - offset))
        f = np.asarray(result.frequencies, dtype=float)
        emap = result.element_map
        assert isinstance(emap, MatrixElementMap) and emap.positions is not None  # as geo
        live, c0 = emap.live, result.medium.sound_speed
        steering = tuple(steering_uncertainty(emap.delay[live], emap.positions[live, axis], c0)
                         if live.sum() >= 3 else 0.0 for axis in (1, 0))
        return cls(geo, scan_pose, (float(f.min()), float(f.max())),
                   face_uncertainty=u_offset, window_corrected=_window_corrected(result),
                   steering=(float(steering[0]), float(steering[1])))


def matrix_face_offset(result: TransmitResult) -> tuple[float, float]:
    """Where the face of a matrix array lies along +z of the transmit pose's source
    frame, and its standard uncertainty (m).

    The element map's defocus δ (:class:`MatrixElementMap` ``focus_offset``, the scan
    window's bias removed) is measured from the plane the map was back-projected onto;
    the pipeline's last update ``z0 += c0 t0`` moved the pose after that pass, by
    ``history[-1]["update"][2]``, which adds to it. The uncertainty is δ's (its
    Gauss–Newton σ, with the window correction's share).

    When the transmit fit did not correct the map for the scan window
    (``aperture.window_correction`` off, or its refit failed: the result's
    ``extras["face_offset"]`` is NaN), δ still holds that bias (8.2 µm, 6 σ, on the
    8 × 8 twin of the tests) and a ``UserWarning`` says so."""
    emap = result.element_map
    if not isinstance(emap, MatrixElementMap):
        raise InputError("the transmit characterization has no matrix element map",
                         field="element_map")
    if not _window_corrected(result):
        warnings.warn(_UNCORRECTED_FACE, UserWarning, stacklevel=2)
    last = float(result.history[-1]["update"][2]) if result.history else 0.0
    u = float(emap.focus_offset_uncertainty)
    return float(emap.focus_offset) + last, (u if math.isfinite(u) else 0.0)


_UNCORRECTED_FACE = ("the matrix face is placed by an element-map defocus not corrected for "
                     "the scan window (aperture.window_correction off or its refit failed): "
                     "the face position, hence the plate distance d, carries that bias "
                     "(several µm), which its uncertainty does not include")


def _window_corrected(result: TransmitResult) -> bool:
    """Whether the transmit fit's matrix window step ran (it records a finite
    ``face_offset``)."""
    value = result.extras.get("face_offset", math.nan) if result.extras else math.nan
    return bool(np.isfinite(value))


def matrix_array(element_map: object) -> ArrayGeometry | None:
    """The element layout of a matrix map in the source frame: the lattice (fitted
    pitches, the map's element size) centred on the origin and aligned with x, where
    the transmit characterization put it (its last pose update moved the origin onto the
    lattice centre and turned θz by the lattice rotation); None for another map."""
    if not isinstance(element_map, MatrixElementMap):
        return None
    m = element_map
    grid_position = m.grid_position
    if grid_position is None:
        return None
    nx, ny = m.grid_shape
    u = grid_position[:, 0] - 0.5 * (nx - 1)
    v = grid_position[:, 1] - 0.5 * (ny - 1)
    n = u.size
    pos = np.stack([u * m.pitch, v * m.pitch_y, np.zeros(n)], axis=-1)
    return ArrayGeometry(pos, np.tile([0.0, 0.0, 1.0], (n, 1)), np.tile([1.0, 0.0, 0.0], (n, 1)),
                         np.full(n, m.element_width), np.full(n, m.element_height),
                         kind="matrix",
                         grid_shape=(int(nx), int(ny)), grid_position=grid_position,
                         pitch=(float(m.pitch), float(m.pitch_y)))


@dataclass(frozen=True)
class MatrixEchoPose:
    """Plate pose fitted to the echo arrivals of a matrix (:func:`fit_matrix_echo_pose`).

    Attributes
    ----------
    distance : float
        d in m (array centre to the plate along z).
    tilt_x, tilt_y : float
        θx', θy' in rad (:func:`holoprobe.geometry.plate_plane`).
    offset : float
        Common delay t_c in s.
    distance_uncertainty, tilt_x_uncertainty, tilt_y_uncertainty, offset_uncertainty
        Standard uncertainties (least squares, residual scatter).
    used : ndarray of bool, shape (n_el,)
        Elements of the final fit.
    residual_rms : float
        RMS residual in s.
    """

    distance: float
    tilt_x: float
    tilt_y: float
    offset: float
    distance_uncertainty: float = 0.0
    tilt_x_uncertainty: float = 0.0
    tilt_y_uncertainty: float = 0.0
    offset_uncertainty: float = 0.0
    used: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))
    residual_rms: float = 0.0


# --------------------------------------------------------------------------- geometry
RECEIVE_KINDS = ("matrix", "row-column")
"""Array kinds of the 2-D receive: a matrix, or a row-column array whose every strip
(both sets) has a channel (:func:`lattice_coordinates`)."""


def _matrix(geometry: object) -> ArrayGeometry:
    if not isinstance(geometry, ArrayGeometry) or geometry.kind not in RECEIVE_KINDS:
        raise InputError("expected a matrix or row-column holoprobe.geometry.ArrayGeometry",
                         field="geometry")
    if geometry.kind == "row-column" and np.unique(geometry.strip_set).size < 2:
        raise InputError("expected a row-column array with both sets of strips (its "
                         "transmit lattice is the columns' x by the rows' y)",
                         field="geometry")
    return geometry


def lattice_coordinates(geometry: ArrayGeometry, axis: int
                        ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The transmitting lattice's coordinates along x (``axis`` 0) or y (1) and how
    many elements share each (m; the weights of :func:`matrix_echo_delays`' sums).

    A matrix: its element centres. A row-column array: whichever set transmits, the
    radiating surface is the columns' x by the rows' y (a column is a strip along y
    through every row's y, sampled there at the row pitch; a row the same along x), so
    x comes from the columns (strip set 0), y from the rows (set 1), each once."""
    pos = geometry.positions[:, axis]
    if geometry.kind == "row-column":
        pos = pos[geometry.strip_set == axis]
    coords, counts = np.unique(np.round(pos, 12), return_counts=True)
    return coords, counts


ARRIVAL_FREQUENCIES = 6  # points of the band over which the arrival model is averaged


def matrix_echo_delays(geometry: ArrayGeometry, distance: float, tilt_x: float,
                       tilt_y: float, *, sound_speed: float, band: tuple[float, float]
                       ) -> NDArray[np.float64]:
    """Echo arrival of every element in s (no common delay): the group delay of the
    array's field at the image of the element centre in the plate (module notes), in
    the near field as in the far field.

    The field of the array at an image point M = (X, Y, Z) (array frame) is taken as
    the sum over the element centres, with the Fresnel distance
    ``R ≈ Z + ((x − X)² + (y − Y)²)/(2Z)``, so it factors into a sum over the lattice's
    columns and one over its rows (each weighted by its share of the elements). Its
    group delay ``Re(Σ R g / Σ g)/c0`` (``g = e^{ikR}``), averaged over
    :data:`ARRIVAL_FREQUENCIES` frequencies of ``band`` weighted by |U|², is
    ``(Z + Re(A_x/S_x) + Re(A_y/S_y))/c0`` with ``S = Σ w e^{ik(x − X)²/(2Z)}`` and
    ``A = Σ w (x − X)²/(2Z) e^{ik(x − X)²/(2Z)}``. Far from the array (Fresnel number
    ≪ 1) this is ``|M|/c0`` (the distance from the array centre to the image: the
    arrivals slope by half the tilts); close to it (the image inside the aperture's
    shadow) ``Z/c0`` (the plane wave reflected by the plate: the whole tilts). Used as
    the pose model of the fits; the model-based refinement compares predicted
    pressures, so its error moves only the convergence, not the fixed point.
    """
    geo = _matrix(geometry)
    p0, n = plate_plane(distance, tilt_y, tilt_x)
    img = geo.mirrored(p0, n).positions
    f_lo, f_hi = (float(v) for v in band)
    k = 2 * np.pi * np.linspace(f_lo, f_hi, ARRIVAL_FREQUENCIES) / float(sound_speed)
    z = img[:, 2][:, None]
    terms = []
    for axis in (0, 1):
        coords, counts = lattice_coordinates(geo, axis)
        q = np.hypot(z, coords[None, :] - img[:, axis][:, None]) - z  # (n, m)
        g = np.exp(1j * k[0] * q) * (counts / counts.sum())
        turn = np.exp(1j * (k[1] - k[0]) * q) if k.size > 1 else g  # next frequency
        s_sum = np.empty((q.shape[0], k.size), complex)
        a_sum = np.empty_like(s_sum)
        for j in range(k.size):
            s_sum[:, j], a_sum[:, j] = g.sum(axis=1), (g * q).sum(axis=1)
            g *= turn
        terms.append((s_sum, a_sum))  # S, A: (n, nf)
    (sx, ax), (sy, ay) = terms
    weight = np.abs(sx * sy) ** 2
    delay = img[:, 2][:, None] + np.real(ax / sx) + np.real(ay / sy)
    return np.asarray(np.sum(weight * delay, axis=1) / np.sum(weight, axis=1)
                      / float(sound_speed), dtype=np.float64)


def matrix_mirrored_faces(geometry: ArrayGeometry, distance: float, tilt_x: float,
                          tilt_y: float, *, spacing: float, base: Surface | None = None
                          ) -> tuple[Surface, SensorLayout]:
    """The element faces of the image grid (the virtual receiver), sampled.

    Midpoint cells of at most ``spacing`` (m) on every element's face
    (:meth:`ArrayGeometry.surface`, ``layout="grid"``) of the array, mirrored
    (``p − 2((p − p0)·n) n``, as :meth:`ArrayGeometry.mirrored`): the images of the real
    faces' points, normals pointing back to the array. The layout's ``u``/``v`` are the
    real points' x and their y relative to the element centre (no lens: v only labels).
    ``base``: that sampling of the real faces, when the caller keeps it for several
    poses (it does not depend on the plate).
    """
    geo = _matrix(geometry)
    p0, n = plate_plane(distance, tilt_y, tilt_x)
    real_faces = geo.surface(float(spacing), layout="grid") if base is None else base
    real = real_faces.points
    surf = Surface(real - 2.0 * ((real - p0) @ n)[:, None] * n[None, :],
                   real_faces.normals - 2.0 * (real_faces.normals @ n)[:, None] * n[None, :],
                   real_faces.weights, real_faces.element)
    lab = np.asarray(surf.element)
    counts = np.bincount(lab, minlength=geo.count)
    if np.any(counts != counts[0]):
        raise InputError("expected elements of one size (the same cells per element)",
                         field="geometry")
    layout = SensorLayout(element_count=geo.count, points_per_element=int(counts[0]),
                          u=real[:, 0], v=real[:, 1] - geo.positions[lab, 1],
                          weights=np.asarray(surf.weights, dtype=float),
                          height=float(geo.heights[0]), center_y=0.0)
    return surf, layout


# --------------------------------------------------------------------------- pose fit
def _plane_start(geo: ArrayGeometry, t: NDArray, used: NDArray, c0: float
                 ) -> tuple[float, float]:
    """(θx', θy') from a least-squares plane through the arrivals (module notes: the
    far-field slopes −sin(θy'/2) cos(θx'/2)/c0 and sin(θx'/2)/c0)."""
    xy = geo.positions[used, :2]
    a = np.c_[np.ones(xy.shape[0]), xy]
    _, bx, by = np.linalg.lstsq(a, t[used], rcond=None)[0]
    tx = 2.0 * math.asin(float(np.clip(c0 * by, -0.5, 0.5)))
    ty = 2.0 * math.asin(float(np.clip(-c0 * bx / math.cos(0.5 * tx), -0.5, 0.5)))
    return tx, ty


def _time_of_flight_start(geo: ArrayGeometry, arrivals: tuple[NDArray, NDArray], c0: float,
                          rc: ReceiveConfig) -> tuple[float, float, float] | None:
    """Row-column arrays: the arrival fit's start (d, θx', θy') with d from the echo's
    time of flight (``c0 · min arrival / 2``, which holds the IRs' delays: a little long)
    and d held there (a row-column fit without a d column gets a zero one: the model is
    then d's at the start); None for a matrix (the fit's own start, d free). The strips'
    arrivals hardly see d (their curvature is the centres' model's only in part): fitted,
    d went to 29.3 mm for 15 mm on the 32 + 32 twin and 13.1 mm for 10 mm on the
    12 + 12; the refinement's measured d column takes it from there."""
    if geo.kind != "row-column":
        return None
    t, q = (np.asarray(a, dtype=float).reshape(-1) for a in arrivals)
    cand = _candidates(t, q, rc.min_quality, rc.min_relative_quality, 6)
    return (0.5 * c0 * float(np.min(t[cand])), *_plane_start(geo, t, cand, c0))


def fit_matrix_echo_pose(geometry: ArrayGeometry, arrival_times: ArrayLike,
                         quality: ArrayLike, *, sound_speed: float, band: tuple[float, float],
                         start: tuple[float, float, float] | None = None,
                         distance_column: tuple[float, NDArray] | None = None,
                         min_quality: float = 10.0, min_relative_quality: float = 0.25,
                         outlier_threshold: float = 4.0, loss: str = "soft_l1",
                         max_iterations: int = 10) -> MatrixEchoPose:
    """Plate distance d, tilts (θx', θy') and common delay t_c from the echo arrivals.

    Robust least squares of ``t_c + t_i(d, θx', θy')`` (:func:`matrix_echo_delays`) to
    the usable elements (``quality ≥ max(min_quality, min_relative_quality · max)``),
    started from a plane fit (tilts) and ``d = c0 · min arrival / 2``; elements beyond
    ``outlier_threshold`` robust σ are rejected; a final ordinary fit's residual scatter
    gives the covariance (at least 6 elements).

    Parameters
    ----------
    geometry : ArrayGeometry
        The matrix.
    arrival_times, quality : array_like, shape (n_el,)
        Arrivals in s and peak SNR (:func:`echo_arrivals`).
    sound_speed : float
        c0 in m/s.
    band : (float, float)
        Signal band in Hz (of the arrival model, :func:`matrix_echo_delays`).
    start : (float, float, float), optional
        Starting (d, θx', θy').
    distance_column : (float, ndarray of shape (n_el,)), optional
        (d_ref, ∂t_e/∂d in s/m): the arrivals' change with d as the estimator of the
        element delays sees it on predicted pressures (:func:`distance_column`); the
        model is then ``t_c + t_e(d_ref, θx', θy') + (d − d_ref) ∂t_e/∂d``. In the
        near field the model's own d dependence is not what that estimator sees.
    min_quality, min_relative_quality, outlier_threshold, loss, max_iterations
        As :func:`fit_convex_echo_pose`.

    Returns
    -------
    MatrixEchoPose
    """
    geo = _matrix(geometry)
    t = np.asarray(arrival_times, dtype=float).reshape(-1)
    q = np.asarray(quality, dtype=float).reshape(-1)
    if not (t.size == q.size == geo.count):
        raise InputError(f"expected {geo.count} arrivals and qualities, got {t.size} "
                         f"and {q.size}", field="arrival_times")
    c0 = float(sound_speed)
    cand = _candidates(t, q, min_quality, min_relative_quality, 6)
    if start is None:
        d0 = 0.5 * c0 * float(np.min(t[cand]))
        start = (d0, *_plane_start(geo, t, cand, c0))
    d0 = float(start[0])
    hold = geo.kind == "row-column" and distance_column is None
    if hold:  # d held at the start (_time_of_flight_start)
        distance_column = (d0, np.zeros(geo.count))
    if not d0 > 0:
        raise FitError(f"the echo arrives at {np.min(t[cand]):g} s: no plate in front of "
                       f"the array", field="rf")
    unit = np.array([1e-6, 1e-3, 1e-3, 1e-3])  # µs, mm, mrad: residuals in ns

    def resid(x: NDArray, m: NDArray) -> NDArray:
        p = x * unit
        model = p[0] + _pose_model(geo, p[1:], c0, band, distance_column)
        return ((t - model) * 1e9)[m]

    x = np.array([0.0, d0, float(start[1]), float(start[2])]) / unit
    x[0] = float(np.median(resid(x, cand))) * 1e-9 / unit[0]
    span = (1 - 1e-9, 1 + 1e-9) if hold else (0.05, 20.0)
    bounds = ([-np.inf, span[0] * d0 / unit[1], -700.0, -700.0],
              [np.inf, span[1] * d0 / unit[1], 700.0, 700.0])
    used = cand.copy()
    for _ in range(int(max_iterations)):
        f_scale = max(float(mad_sigma(resid(x, used))) if used.sum() > 4 else 0.0, 1e-6)
        x = scipy.optimize.least_squares(resid, x, args=(used,), loss=loss, f_scale=f_scale,
                                         bounds=bounds).x
        r = resid(x, np.ones(t.size, bool))
        sig = max(float(mad_sigma(r[used])), f_scale)
        new = cand & (np.abs(r) <= float(outlier_threshold) * sig)
        if new.sum() < 6 or np.array_equal(new, used):
            break
        used = new
    sol = scipy.optimize.least_squares(resid, x, args=(used,), bounds=bounds)
    res = sol.fun * 1e-9
    u = np.sqrt(_arrival_variances(sol.jac * 1e-9 / unit[None, :], res))
    p = sol.x * unit
    return MatrixEchoPose(float(p[1]), float(p[2]), float(p[3]), float(p[0]),
                          float(u[1]), float(u[2]), float(u[3]), float(u[0]), used,
                          float(np.sqrt(np.mean(res**2))))


def _pose_model(geometry: ArrayGeometry, pose: ArrayLike, c0: float,
                band: tuple[float, float],
                distance_column: tuple[float, NDArray] | None) -> NDArray[np.float64]:
    """Arrivals (s) at pose (d, θx', θy'): :func:`matrix_echo_delays`, or with a
    measured d column (:func:`fit_matrix_echo_pose`) its linearisation in d."""
    d, tx, ty = (float(v) for v in np.asarray(pose, dtype=float).reshape(3))
    if distance_column is None:
        return matrix_echo_delays(geometry, d, tx, ty, sound_speed=c0, band=band)
    d_ref, col = distance_column
    return matrix_echo_delays(geometry, d_ref, tx, ty, sound_speed=c0,
                              band=band) + (d - d_ref) * np.asarray(col, dtype=float)


def _arrival_variances(jac: NDArray, res: NDArray) -> NDArray[np.float64]:
    """Parameter variances of a least-squares fit from its residuals: the larger
    of the classical ``σ̂² (JᵀJ)⁻¹`` and the HC3 sandwich ``(JᵀJ)⁻¹ Jᵀ diag(r_i²/(1 −
    h_i)²) J (JᵀJ)⁻¹`` (h the leverages), which holds when the arrivals' noise differs
    from element to element (the grid's edges see a weaker echo and weigh most in the
    tilts)."""
    m, k = jac.shape
    inv = np.linalg.pinv(jac.T @ jac)
    classical = inv * float(res @ res) / max(m - k, 1)
    lever = np.clip(np.einsum("ij,jk,ik->i", jac, inv, jac), 0.0, 0.99)
    meat = (jac * (res / (1.0 - lever))[:, None] ** 2).T @ jac
    sandwich = inv @ meat @ inv
    return np.maximum(np.maximum(np.diag(classical), np.diag(sandwich)), 0.0)


def refine_matrix_pose(pose: MatrixEchoPose, rf: NDArray, pressure: NDArray,
                       sampling_rate: float, *, geometry: ArrayGeometry, quality: NDArray,
                       pressure_rate: float, rf_start_time: float,
                       pressure_start_time: float, sound_speed: float,
                       band: tuple[float, float], band_db: float = -12.0,
                       distance_column: tuple[float, NDArray] | None = None, **fit: Any
                       ) -> tuple[MatrixEchoPose, NDArray[np.float64]]:
    """One model-based step of the plate pose: the delays δ_i of every element's RF
    against its own predicted pressure at ``pose`` (:func:`element_sensitivity`),
    then :func:`fit_matrix_echo_pose` on ``t_i(pose) + δ_i`` started at ``pose``
    (elements outside ``pose.used`` get quality 0). ``rf`` (n_el, nt) and ``pressure``
    (n_el, m) as :func:`refine_convex_pose`; ``distance_column`` as
    :func:`fit_matrix_echo_pose`'s; returns the new pose and δ (s)."""
    sens = element_sensitivity(rf, pressure, sampling_rate, pressure_rate=pressure_rate,
                               rf_start_time=rf_start_time,
                               pressure_start_time=pressure_start_time, used=pose.used,
                               band_db=band_db)
    t_model = _pose_model(geometry, (pose.distance, pose.tilt_x, pose.tilt_y), sound_speed,
                          band, distance_column)
    q = np.where(pose.used, quality, 0.0)
    new = fit_matrix_echo_pose(geometry, t_model + sens.delay, q, sound_speed=sound_speed,
                               band=band, start=(pose.distance, pose.tilt_x, pose.tilt_y),
                               distance_column=distance_column, **fit)
    return new, np.asarray(sens.delay, dtype=np.float64)


# --------------------------------------------------------------------------- pipeline
def _alignment(geo: ArrayGeometry, pose: MatrixEchoPose, c0: float,
               band: tuple[float, float]) -> NDArray[np.float64]:
    t = matrix_echo_delays(geo, pose.distance, pose.tilt_x, pose.tilt_y, sound_speed=c0,
                           band=band)
    return np.asarray(t - np.min(t[pose.used]), dtype=np.float64)


def _receiver(pose: MatrixEchoPose, echo: EchoRecording, face: MatrixFace, c0: float,
              window: tuple[float, float], rc: ReceiveConfig,
              arrivals: tuple[NDArray, NDArray]) -> VirtualReceiver:
    """The :class:`VirtualReceiver` record of a matrix pose: the tilts, d, the image of
    the array centre ``M(0) = 2 d n_z n``, the aligned high-passed RF average, its onset.

    The echo's arrival (where the onset's noise segment ends) is the arrival model at the
    pose plus the median offset of the measured ``arrivals`` from it, not ``pose.offset``:
    after the model-based refinement that offset belongs to the refinement's linearised
    model (a d column measured near the final d left it 1.7 µs short on the 32 × 32 seed 2
    at 15 mm, and the onset search then failed)."""
    geo = face.geometry
    t_geo = matrix_echo_delays(geo, pose.distance, pose.tilt_x, pose.tilt_y, sound_speed=c0,
                               band=face.band)
    offset = float(np.median((np.asarray(arrivals[0], dtype=float) - t_geo)[pose.used]))
    rf = echo.rf - echo.rf.mean(axis=1, keepdims=True)
    avg = aligned_average(rf, echo.sampling_rate, _alignment(geo, pose, c0, face.band),
                          used=pose.used)
    avg, t0, u_t0 = average_onset(
        avg, echo.sampling_rate, start_time=echo.start_time, window=window,
        arrival=offset + float(np.min(t_geo[pose.used])), noise_guard=rc.noise_guard,
        highpass_cutoff=rc.highpass_cutoff, highpass_order=rc.highpass_order,
        onset_threshold=rc.onset_threshold, onset_upsample=rc.onset_upsample)
    d = pose.distance
    u_d = math.hypot(pose.distance_uncertainty, 0.5 * face.face_uncertainty)
    c, u_c = _image_centre(pose, u_d)
    return VirtualReceiver(
        theta_y=pose.tilt_y, x0=float(c[0]), z0=float(c[2]), onset=t0, distance=d,
        theta_y_uncertainty=pose.tilt_y_uncertainty, x0_uncertainty=float(u_c[0]),
        z0_uncertainty=float(u_c[2]), onset_uncertainty=u_t0, distance_uncertainty=u_d,
        used=pose.used, arrival_times=arrivals[0], quality=arrivals[1], averaged_rf=avg,
        start_time=float(echo.start_time), sampling_rate=echo.sampling_rate,
        theta_x=pose.tilt_x, y0=float(c[1]))


def _image_centre(pose: MatrixEchoPose, u_d: float
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The image of the array centre ``M(0) = 2 d n_z n`` (m) and its standard
    uncertainties (x, y, z; σ(d) = ``u_d`` and the tilts' σ)."""
    d = pose.distance
    _, n = plate_plane(d, pose.tilt_y, pose.tilt_x)
    u_c = np.abs(2.0 * n[2] * n) * u_d + d * np.array([
        abs(math.cos(pose.tilt_y)) * pose.tilt_y_uncertainty,
        abs(math.cos(pose.tilt_x)) * pose.tilt_x_uncertainty,
        math.hypot(math.sin(pose.tilt_y) * pose.tilt_y_uncertainty,
                   math.sin(pose.tilt_x) * pose.tilt_x_uncertainty)])
    return np.asarray(2.0 * d * n[2] * n, dtype=np.float64), u_c


def _refine(pose: MatrixEchoPose, receiver: VirtualReceiver, rf: NDArray, face: MatrixFace,
            predict: SensorPredictor, echo: EchoRecording, rc: ReceiveConfig
            ) -> tuple[MatrixEchoPose, NDArray, float, dict[str, Any],
                       tuple[float, NDArray] | None]:
    """Predictions and model-based pose steps (``receive.pose_iterations``); the last
    step's change of the arrivals is applied to the pressure as element delays.

    In the near field (:func:`fresnel_number` above :data:`NEAR_FIELD_FRESNEL` at the
    current d) the model's d column is not what the delay estimator sees: it is measured
    on a second prediction (:func:`distance_column`), again whenever d has moved more
    than :data:`MATRIX_REMEASURE` of d (:func:`_needs_column`), rescaled by the secant
    of the d steps (:func:`_secant_step`) and returned (else None); that path takes up
    to twice ``receive.pose_iterations`` steps, stopping after ``pose_iterations`` once a
    d step is within σ(d); the last step then joins the pose's σ (the refinement is not
    converged further than that). Row-column strips always take the measured column
    (again after :data:`REMEASURE` of d) and at least
    :data:`ROW_COLUMN_POSE_ITERATIONS` steps."""
    c0, geo = predict.medium.sound_speed, face.geometry
    spacing = predict.projection.spacing

    base = geo.surface(float(spacing), layout="grid")  # the real faces, every pose's

    def predict_at(p: MatrixEchoPose) -> tuple[NDArray, float]:
        return predict.on_surface(*matrix_mirrored_faces(geo, p.distance, p.tilt_x,
                                                         p.tilt_y, spacing=spacing,
                                                         base=base))

    p_time, t_p0 = predict_at(pose)
    history = [(pose.distance, pose.tilt_x, pose.tilt_y)]
    if not rc.refine_pose:
        return pose, p_time, t_p0, {"history": history}, None
    column: tuple[float, NDArray] | None = None
    strips = geo.kind == "row-column"
    kw = {"geometry": geo, "quality": receiver.quality, "pressure_rate": predict.sampling_rate,
          "rf_start_time": echo.start_time, "sound_speed": c0, "band": face.band,
          "band_db": rc.sensitivity_band_db, **_fit_options(rc)}
    delays, scale, trail = np.zeros(geo.count), 1.0, list[tuple[float, float, float]]()
    steps, columns = max(1, int(rc.pose_iterations)), 0
    most = max(steps, ROW_COLUMN_POSE_ITERATIONS) if strips else 2 * steps
    for i in range(most):
        if i:
            p_time, t_p0 = predict_at(pose)
        if _needs_column(geo, pose.distance, face.band, c0, column):
            step_d = DISTANCE_STEP * pose.distance
            moved = predict_at(dataclasses.replace(pose, distance=pose.distance + step_d))
            column = distance_column((p_time, t_p0), moved, step_d, pose.distance,
                                     predict.sampling_rate, pose.used, rc.sensitivity_band_db)
            scale, trail, columns = 1.0, [], columns + 1
        scaled = None if column is None else (column[0], column[1] * scale)
        before = pose.distance
        pose, delays = refine_matrix_pose(pose, rf, p_time, echo.sampling_rate,
                                          pressure_start_time=t_p0, distance_column=scaled,
                                          **kw)
        if column is not None:
            pose, scale = _secant_step(pose, before, scale, trail,
                                       DISTANCE_STEP * column[0] if strips else math.inf)
        history.append((pose.distance, pose.tilt_x, pose.tilt_y))
        if strips:
            if i >= 2 and _settled(history):
                break
        # the near-field path goes on (at most twice the steps) while d still moves
        # by more than its σ: its steps start from an arrival model that may put d
        # millimetres off, and the d dependence it follows is weak
        elif i + 1 >= steps and (
                column is None or abs(pose.distance - before) <= pose.distance_uncertainty):
            break
    column = None if column is None else (column[0], column[1] * scale)
    step = (_pose_model(geo, history[-1], c0, face.band, column)
            - _pose_model(geo, history[-2], c0, face.band, column))
    p_time = fractional_delay(p_time, step, predict.sampling_rate)
    if column is not None:  # near field: the last step, the hidden steering
        last = np.abs(np.subtract(history[-1], history[-2]))
        pose = dataclasses.replace(
            pose, distance_uncertainty=math.hypot(pose.distance_uncertainty, last[0]),
            tilt_x_uncertainty=math.hypot(pose.tilt_x_uncertainty, last[1],
                                          face.steering[0]),
            tilt_y_uncertainty=math.hypot(pose.tilt_y_uncertainty, last[2],
                                          face.steering[1]))
    used = pose.used
    return pose, p_time, t_p0, {
        "history": history, "element_delay_rms": float(np.std(delays[used])),
        "predictions": len(history) - 1 + columns,
        "last_step_rms": float(np.std(step[used])),
        "distance_column": column is not None, "column_remeasured": max(columns - 1, 0)}, column


def _settled(history: list[tuple[float, float, float]]) -> bool:
    """Whether the last pose step moved d by less than :data:`SETTLED` × d and the tilts
    by less than 1e-5 rad (row-column arrays stop their pose steps there)."""
    step = np.abs(np.subtract(history[-1], history[-2]))
    return bool(step[0] < SETTLED * history[-1][0] and np.all(step[1:] < 1e-5))


SETTLED = 1e-4


def _secant_step(pose: MatrixEchoPose, before: float, scale: float,
                 trail: list[tuple[float, float, float]], limit: float = math.inf
                 ) -> tuple[MatrixEchoPose, float]:
    """One near-field d step of :func:`_refine` checked, and the d column's next scale.

    ``trail`` gains (d before the step, the step the unscaled measured column would
    have made, the step made). Linear in d the second is ``−g (d − d*)``, g the ratio
    of the arrivals' true d slope to the measured column: the secant of the last two
    entries gives g, the next scale (kept unless 0.05 < g < 3). A step more than twice
    the last one is cut to that (the d dependence is weak and not linear over
    millimetres). ``limit`` (m): no step beyond it (row-column arrays: the measured
    column's chord, :data:`DISTANCE_STEP` × d, over which it is a valid linearisation)."""
    step = pose.distance - before
    wanted = step * scale
    cap = min(2 * abs(trail[-1][2]) if trail else math.inf, limit)
    if abs(step) > cap:
        step = math.copysign(cap, step)
        pose = dataclasses.replace(pose, distance=before + step)
    trail.append((before, wanted, step))
    if len(trail) >= 2 and trail[-1][0] != trail[-2][0]:
        g = -(trail[-1][1] - trail[-2][1]) / (trail[-1][0] - trail[-2][0])
        scale = g if 0.05 < g < 3.0 else scale
    return pose, scale


ROW_COLUMN_POSE_ITERATIONS = 10
"""Row-column arrays: up to this many model-based pose steps (``receive.
pose_iterations`` if more; they stop from the third on once a step is below
:data:`SETTLED` × d and 1e-5 rad). The strips' echo delays depend on d only weakly (their
arrival fit started the 12 + 12 twin's plate at 13.1 mm for 10 mm) and the near-field
steps are capped at twice the last one: 3 steps left d 1.1 mm off, 10 within ~0.15 mm."""

REMEASURE = 0.05
"""Row-column arrays: the measured d column of :func:`_refine` is measured again at the
current pose once d has moved more than this share of the d it was measured at (the
column is a chord of d's dependence there, not valid millimetres away)."""

DISTANCE_STEP = 0.1  # of d: the chord of the second prediction that measures ∂t/∂d
MATRIX_REMEASURE = 0.025
"""Full and sparse matrices: the share of d (a quarter of the chord
:data:`DISTANCE_STEP`) that d may move from where its column was measured before
:func:`_refine` measures it again (row-column strips: :data:`REMEASURE`)."""


def _needs_column(geometry: ArrayGeometry, distance: float, band: tuple[float, float],
                  sound_speed: float, column: tuple[float, NDArray] | None) -> bool:
    """Whether :func:`_refine` measures the d column (again) at ``distance``: in the
    near field (:func:`fresnel_number` above :data:`NEAR_FIELD_FRESNEL` at the current
    d, not only at the arrival fit's start, which depends on the band of the arrival
    model: 8 × 8 at 1.5 mm with a 2–4 MHz face started at 3.3 mm, Fresnel number < 1,
    and ended 633 µm off at σ 28 µm on the model's column; row-column strips always)
    when there is none yet or d has moved more than :data:`MATRIX_REMEASURE` (strips:
    :data:`REMEASURE`) × the d it was measured at (the column's shape changes with d: on
    the 32 × 32 at 10 mm from a start 2 mm long a column measured once led d to
    10.27 mm in 8 steps, σ 98 µm)."""
    strips = geometry.kind == "row-column"
    if not strips and fresnel_number(geometry, distance, band, sound_speed) \
            <= NEAR_FIELD_FRESNEL:
        return False
    share = REMEASURE if strips else MATRIX_REMEASURE
    return column is None or abs(distance - column[0]) > share * column[0]


def distance_column(base: tuple[NDArray, float], moved: tuple[NDArray, float], step: float,
                    distance: float, rate: float, used: NDArray, band_db: float
                    ) -> tuple[float, NDArray[np.float64]]:
    """(d, ∂t_e/∂d in s/m) of every element, measured on two predicted pressures: at
    the plate distance d (``base``: pressure (n_el, m) and its start time, s) and at
    d + ``step`` (``moved``; :data:`DISTANCE_STEP` × d, a chord over the delays' short
    structure in d: module notes), by the estimator of the element delays
    (:func:`element_sensitivity`, the same band). In the near field of a large matrix
    (the 32 × 32 at 15 mm, Fresnel number 3.1) that estimator sees a d dependence of
    the arrivals' pattern ~8× weaker than the group delay of the array's field
    (:func:`matrix_echo_delays`) and uncorrelated with it; with the model's column
    the refinement stayed where the arrival fit put d (+2.3 mm, σ 8.5 µm)."""
    sens = element_sensitivity(moved[0], base[0], rate, pressure_rate=rate,
                               rf_start_time=moved[1], pressure_start_time=base[1],
                               used=used, band_db=band_db)
    column = (np.asarray(sens.delay, dtype=float) + (moved[1] - base[1])) / float(step)
    return float(distance), np.asarray(column, dtype=np.float64)


def prediction_noise_pose(pose: MatrixEchoPose, predict: SensorPredictor,
                          pressure: NDArray, pressure_start_time: float, *,
                          geometry: ArrayGeometry, scan_samples: int, draws: int,
                          band: tuple[float, float], seed: int = 0, band_db: float = -12.0,
                          distance_column: tuple[float, NDArray] | None = None
                          ) -> NDArray[np.float64]:
    """Standard uncertainties of (d, θx', θy') from the scan's noise carried by the
    predicted element pressures (Monte-Carlo, ``draws`` realisations).

    The forward projection keeps only the plane waves within its guard angle, so the
    noise it carries onto the mirrored grid is correlated over neighbouring elements
    (a 30° guard: over ≈ λ) and moves the fitted pose as a whole; the arrivals'
    residual scatter does not show it. Each draw: white Gaussian noise on the scan's
    samples (``scan_samples`` per point), transformed like the scan (zero-padded to the
    projection's record, its bins) and scaled per bin to the scan spectrum's own noise
    (:func:`hologram_noise_level`: the evanescent part, |κ| > 1.1 k; a bin without that
    region takes its nearest neighbour's), projected onto the faces at ``pose`` by a
    copy of ``predict`` onto one point per element (the face centres: the noise's
    correlation length, ≈ λ, exceeds a face, and the projection costs a fraction of the
    prediction's). Its effect on the pose is taken to first order: the delay the
    noise N gives element e's fit to its pressure P (:func:`element_sensitivity`'s
    |P|²-weighted phase slope over its band) is ``−Σ ω Im(N P*) / Σ ω² |P|²``, and the
    pose moves by the least-squares solution of those delays on the Jacobian of
    ``t_c + t_e(d, θx', θy')`` (:func:`fit_matrix_echo_pose`'s model) over the used
    elements.

    Parameters
    ----------
    pose : MatrixEchoPose
        The fitted pose (its ``used`` elements).
    predict : SensorPredictor
        The predictor of the pose refinement (its projection spectrum, plan options).
    pressure : ndarray, shape (n_el, m)
        The predicted element pressure at ``pose``, first sample at
        ``pressure_start_time`` (s, scan clock), at ``predict.sampling_rate``.
    geometry : ArrayGeometry
        The matrix.
    scan_samples : int
        Samples per scan point of the record the spectrum came from.
    draws : int
        Monte-Carlo draws (one projection each); 0 returns zeros.
    band : (float, float)
        Signal band in Hz of the arrival model (:func:`matrix_echo_delays`).
    distance_column : (float, ndarray), optional
        The pose model's measured d column (:func:`fit_matrix_echo_pose`).
    seed : int
        Of the noise generator.
    band_db : float
        Band level of the delay fit (``receive.sensitivity_band_db``).

    Returns
    -------
    ndarray, shape (3,)
        Rms pose change: d (m), θx', θy' (rad); zeros when the scan does not sample
        the evanescent region (step ≥ λ/2.2) at any bin.
    """
    n_draws = int(draws)
    if n_draws < 0 or n_draws != draws:
        raise InputError(f"expected a whole number of draws >= 0, got {draws!r}",
                         field="receive.pose_noise_draws")
    sp, grid, c0 = predict.projection, predict.scan_grid, predict.medium.sound_speed
    dx, dy = abs(float(grid.x[1] - grid.x[0])), abs(float(grid.y[1] - grid.y[0]))
    var = np.array([hologram_noise_level(sp.spectrum[:, :, b], dx, dy, 2 * np.pi * f / c0)
                    for b, f in enumerate(sp.frequencies)]) ** 2
    ok = np.flatnonzero(var > 0)
    if n_draws == 0 or ok.size == 0:
        return np.zeros(3)
    var = var[ok[np.argmin(np.abs(np.arange(var.size)[:, None] - ok[None, :]), axis=1)]]
    spectrum, weight = _delay_weights(pressure, predict.sampling_rate, pose.used, band_db)
    sel = np.isin(sp.bins, spectrum[1])  # only the delay fit's band matters
    nt = int(scan_samples)  # unit white noise → its bins: E|X|² = nt, hence the scale
    factor = band_noise_factor(nt, sp.record_length, sp.bins[sel], np.sqrt(var[sel] / nt))
    # a Monte-Carlo σ of a few draws is good to ~1/√(2 draws): the noise's projection
    # needs no finer NUFFT tolerance than NOISE_EPS (noise_options; ~8× cheaper than 1e-4)
    noisy = dataclasses.replace(predict, ratio=predict.ratio[sel], projection=SensorProjection(
        sp.spectrum[:, :, sel], sp.frequencies[sel], sp.bins[sel], sp.record_length,
        sp.spacing, sp.distances, sp.sensor_points),
        options=noise_options(predict.options))
    # one point per element face (its centre): the noise is correlated over ≈ λ, so a
    # face average changes little of it, and the projection costs ~1/cells as much
    faces = matrix_mirrored_faces(geometry, pose.distance, pose.tilt_x, pose.tilt_y,
                                  spacing=float(max(np.max(geometry.widths),
                                                    np.max(geometry.heights))))
    solve = _delay_to_pose(geometry, pose, c0, band, distance_column)
    rng = np.random.default_rng(seed)
    nx, ny = sp.spectrum.shape[:2]
    deltas = []
    for _ in range(n_draws):
        noise = band_noise(rng, nx * ny, factor).reshape(nx, ny, -1)
        draw = dataclasses.replace(noisy, projection=dataclasses.replace(
            noisy.projection, spectrum=noise))
        p_noise, t_noise = draw.on_surface(*faces)  # on the pressure's clock:
        p_noise = fractional_delay(p_noise, t_noise - pressure_start_time,
                                   predict.sampling_rate)
        n_spec = to_frequency(p_noise)[:, spectrum[1]]
        delay = -np.sum(weight * np.imag(n_spec * np.conj(spectrum[0])), axis=1)
        deltas.append(solve @ delay[pose.used])
    return np.asarray(np.sqrt(np.mean(np.square(deltas), axis=0)), dtype=np.float64)


def band_noise_factor(samples: int, record_length: int, bins: ArrayLike, scale: ArrayLike
                      ) -> NDArray[np.float64]:
    """Factor F of the spectrum of white noise at a few bins, for :func:`band_noise`.

    Unit white Gaussian noise x on ``samples`` samples, zero-padded to
    ``record_length`` and transformed like the scan (:func:`to_frequency`, bin b:
    ``Σ_t x_t e^{+2πi t b/record_length}``), times ``scale`` per bin, is the real vector
    ``y = x D`` of its real and imaginary parts (D: samples × 2 nb). Its covariance
    ``DᵀD = FᵀF`` with F the triangular factor of D (QR) when 2 nb < samples, so
    ``y = z F`` with z of 2 nb unit normals has the same distribution: drawing costs
    (points × 2 nb) numbers instead of (points × samples) and their product with D.

    Parameters
    ----------
    samples : int
        Samples of the scan record (before padding).
    record_length : int
        Padded transform length.
    bins : array_like of int, shape (nb,)
        One-sided bins of that transform.
    scale : array_like, shape (nb,)
        Factor of each bin (e.g. the noise level ÷ √samples).

    Returns
    -------
    ndarray, shape (min(samples, 2 nb), 2 nb)
    """
    b = np.asarray(bins, dtype=float).reshape(-1)
    phase = 2 * np.pi * np.outer(np.arange(int(samples)), b) / int(record_length)
    s = np.asarray(scale, dtype=float).reshape(-1)
    d = np.concatenate([np.cos(phase) * s, np.sin(phase) * s], axis=1)
    if d.shape[1] >= d.shape[0]:
        return np.asarray(d, dtype=np.float64)
    return np.asarray(np.linalg.qr(d, mode="r"), dtype=np.float64)


def band_noise(rng: np.random.Generator, points: int, factor: NDArray) -> NDArray:
    """``points`` independent draws of the band noise of :func:`band_noise_factor`:
    complex, shape (points, nb)."""
    y = rng.standard_normal((int(points), factor.shape[0])) @ factor
    nb = factor.shape[1] // 2
    return y[:, :nb] + 1j * y[:, nb:]


def _delay_weights(pressure: NDArray, rate: float, used: NDArray, band_db: float
                   ) -> tuple[tuple[NDArray, NDArray], NDArray]:
    """The band of :func:`element_sensitivity` (contiguous bins where the used
    elements' mean |P|² is within ``band_db`` of its peak), the pressure's spectrum
    there (n_el, nb) and the weights ``ω / Σ ω² |P|²`` of the linearised delay."""
    p_spec = to_frequency(np.asarray(pressure, dtype=float))
    pm = np.mean(np.abs(p_spec[used]) ** 2, axis=0)
    idx = np.flatnonzero(pm >= pm.max() * 10 ** (band_db / 10))
    band = np.arange(idx.min(), idx.max() + 1)
    omega = 2 * np.pi * frequency_axis(np.shape(pressure)[1], rate)[band]
    p_band = p_spec[:, band]
    norm = np.sum(omega**2 * np.abs(p_band) ** 2, axis=1, keepdims=True)
    return (p_band, band), omega[None, :] / np.where(norm > 0, norm, np.inf)


def _delay_to_pose(geometry: ArrayGeometry, pose: MatrixEchoPose, c0: float,
                   band: tuple[float, float],
                   distance_column: tuple[float, NDArray] | None = None
                   ) -> NDArray[np.float64]:
    """(3, n_used): arrival changes of the used elements → (d, θx', θy') change, the
    least-squares solution on the Jacobian (central differences) of
    ``t_c + t_e(d, θx', θy')`` (t_c solved for and dropped)."""
    x0 = np.array([pose.distance, pose.tilt_x, pose.tilt_y])
    steps = np.array([1e-6, 1e-5, 1e-5])
    cols = [np.ones(int(pose.used.sum()))]
    for k in range(3):
        lo, hi = x0.copy(), x0.copy()
        lo[k] -= steps[k]
        hi[k] += steps[k]
        t = [_pose_model(geometry, v, c0, band, distance_column)[pose.used]
             for v in (lo, hi)]
        cols.append((t[1] - t[0]) / (2 * steps[k]))
    return np.asarray(np.linalg.pinv(np.stack(cols, axis=1))[1:], dtype=np.float64)


def characterize_matrix_receive(
    echo: EchoRecording,
    face: MatrixFace,
    scan: HydrophoneScan,
    config: CharacterizationConfig | ReceiveConfig | None = None,
    *,
    reflection_coefficient: float | None = None,
    calibration: HydrophoneCalibration | None = None,
    progress: bool | None = None,
) -> ReceiveResult:
    """Receive characterization of a 2-D matrix array from a flat-reflector echo.

    Parameters
    ----------
    echo : EchoRecording
        Element RF (n_el, nt) of the reflector experiment, with its drive.
    face : MatrixFace
        The grid, the scan pose and the band of the transmit characterization.
    scan : HydrophoneScan
        The hydrophone scan of the transmit characterization.
    config : CharacterizationConfig or ReceiveConfig, optional
        Its ``receive`` section (and ``backprojection`` eps / precision).
    reflection_coefficient : float, optional
        Rp (default: from the echo train, as for a flat 1-D array).
    calibration : HydrophoneCalibration, optional
        Hydrophone sensitivity of a voltage scan.
    progress : bool or None
        Progress bars of the projections.

    Returns
    -------
    ReceiveResult
        As for a flat array; ``receiver`` holds θx' (``theta_x``), θy', d and the image
        of the array centre (``x0``, ``y0``, ``z0``); ``element_x`` the elements' x;
        ``extras``: ``element_delays`` (alignment delays, s), ``pose_refinement``,
        ``ir_shift`` (s), ``offset`` (t_c, s), ``theta_x_uncertainty`` (rad),
        ``element_y`` (m), ``array`` = the geometry's kind (``"matrix"`` or
        ``"row-column"``).

    Notes
    -----
    Module notes of :mod:`holoprobe.characterize._matrix_receive`.
    """
    t_total = time.perf_counter()
    _check_inputs(echo, face, scan)
    rc = _receive_config(config)
    cfg = config if isinstance(config, CharacterizationConfig) else CharacterizationConfig()
    timer, notes = _Timer(), list[str]()
    if not face.window_corrected:
        notes.append(_UNCORRECTED_FACE)
    c0, fs, fs_s = scan.medium.sound_speed, echo.sampling_rate, scan.sampling_rate
    with timer("virtual_receiver"):
        window = rc.window if rc.window is not None else echo_search_window(
            echo.rf, fs, start_time=echo.start_time)
        method = cast(Literal["envelope", "xcorr"], rc.arrival_method)
        arrivals = echo_arrivals(echo.rf, fs, start_time=echo.start_time, window=window,
                                 method=method, noise_guard=rc.noise_guard)
        pose = fit_matrix_echo_pose(face.geometry, *arrivals, sound_speed=c0, band=face.band,
                                    start=_time_of_flight_start(face.geometry, arrivals, c0, rc),
                                    **_fit_options(rc))
        receiver = _receiver(pose, echo, face, c0, window, rc, arrivals)
    with timer("reflection"):
        rp, u_rp, reflection, sigma_rf = reflection_step(
            receiver, window, fs, echo.start_time, reflection_coefficient, rc, notes)
    with timer("scan_spectrum"):
        geo = face.geometry
        predict = matrix_sensor_predictor(echo, face, scan, pose.distance, config=cfg,
                                          receive=rc, calibration=calibration,
                                          progress=progress, notes=notes)
    with timer("element_pressure"):
        pose, p_time, t_p0, refinement, column = _refine(
            pose, receiver, _echo_rf(echo, window), face, predict, echo, rc)
        strips = geo.kind == "row-column"  # the plan serves the gains' pose term too
        if not strips:
            predict.__dict__.pop("plan", None)  # frees the plan's spectra
    with timer("pose_noise"):
        pose = _with_prediction_noise(pose, predict, geo, (p_time, t_p0), scan, rc,
                                      refinement, notes, column)
    _near_field_note(geo, pose.distance, face.band, c0, notes, refinement)
    with timer("alignment"):
        receiver = _receiver(pose, echo, face, c0, window, rc, arrivals)
        delays = _alignment(geo, pose, c0, face.band)
        p_avg = aligned_average(p_time, fs_s, delays, used=pose.used)
    with timer("receive_ir"):
        ir = receive_ir_step(receiver, p_avg, echo, window, pressure_rate=fs_s,
                             pressure_start=t_p0, rp=rp, reflection=reflection, config=rc,
                             notes=notes, delays=delays)
    with timer("element_sensitivity"):
        sens = sensitivity_step(echo, p_time * rp, fs_s, t_p0, receiver, rc)
        if strips:
            sens = pose_gain_uncertainty(sens, echo, rp, predict, geo, pose, rc)
            predict.__dict__.pop("plan", None)
    timer.times["total"] = time.perf_counter() - t_total
    return _result(receiver, pose, (rp, u_rp, reflection, sigma_rf), ir, sens,
                   (p_time, t_p0, p_avg, delays), predict, geo, echo, rc, notes,
                   dict(timer.times), refinement)


def pose_gain_uncertainty(sens: ElementSensitivity, echo: EchoRecording, rp: float,
                          predict: SensorPredictor, geometry: ArrayGeometry,
                          pose: MatrixEchoPose, rc: ReceiveConfig) -> ElementSensitivity:
    """``sens`` with the plate pose's uncertainty in every gain's σ: the pressure is
    predicted again at the pose moved by σ(d), σ(θx'), σ(θy') in turn and each change of
    the gains (:func:`element_sensitivity`, absolute amplitudes) joins their σ in
    quadrature (as the flat pipeline's distance and steering terms,
    :func:`sensitivity_step`). Three predictions. Row-column arrays (the receive
    switches it on for them): a strip averages the field over its whole length, so a
    tilt error across it moves its gain, and along a set the gains took a trend from the
    tilt across the strips (12 + 12 twin at 15 mm: −1.0 … +2.1 % across the rows with
    θx' 0.03° off, σ 0.04°; the gains' σ, 0.6 %, held only the noise)."""
    if sens.amplitude_uncertainty is None:
        return sens
    rf = echo.rf - echo.rf.mean(axis=1, keepdims=True)
    spacing = predict.projection.spacing
    base = geometry.surface(float(spacing), layout="grid")
    x0 = np.array([pose.distance, pose.tilt_x, pose.tilt_y])
    sig = np.array([pose.distance_uncertainty, pose.tilt_x_uncertainty,
                    pose.tilt_y_uncertainty])
    u = np.asarray(sens.amplitude_uncertainty, dtype=float)
    for k in np.flatnonzero(np.isfinite(sig) & (sig > 0)):
        moved = x0.copy()
        moved[k] += sig[k]
        p, t0 = predict.on_surface(*matrix_mirrored_faces(
            geometry, *moved, spacing=float(spacing), base=base))
        other = element_sensitivity(rf, p * rp, echo.sampling_rate,
                                    pressure_rate=predict.sampling_rate,
                                    rf_start_time=echo.start_time, pressure_start_time=t0,
                                    used=pose.used, band_db=rc.sensitivity_band_db)
        u = np.hypot(u, np.nan_to_num(np.abs(other.amplitude - sens.amplitude)))
    return dataclasses.replace(sens, amplitude_uncertainty=u)


def matrix_sensor_predictor(echo: EchoRecording, face: MatrixFace, scan: HydrophoneScan,
                            distance: float, *, config: CharacterizationConfig,
                            receive: ReceiveConfig,
                            calibration: HydrophoneCalibration | None = None,
                            progress: bool | None = None, notes: list[str] | None = None
                            ) -> SensorPredictor:
    """The predictor of the element pressure on the mirrored faces of a matrix array.

    :func:`faces_sensor_predictor` for a plate at ``distance`` (m; padded for up to
    1.1 d), NUFFT tolerance :data:`PREDICTION_EPS` unless ``receive.eps`` is set, and
    the image taper ``receive.image_taper`` (default on): the padded scan's periodic
    images reach the mirrored faces through the 30° guard, and the scan's plane waves
    steeper than any line from the scan to the faces carry nothing else. On the 8 × 8
    receive twin (plate 10 mm) the untapered prediction was 4.6 % of its peak off a 70°
    guard's (7.2 % rms on the worst element), the tapered one 0.19 % (0.34 %); on the
    32 × 32 at 15 mm the receive gains went 1.36 → 0.85 % rms and the predictions cost
    about half (benchmarks/RESULTS.md, matrix session 11).
    ``predictor.on_surface(*matrix_mirrored_faces(face.geometry, d, θx', θy',
    spacing=predictor.projection.spacing))`` gives the element pressure (Pa, unit
    reflection, (n_el, record_length)) and its start time (s)."""
    geo = face.geometry

    def sample(dist: float, spacing: float) -> tuple[Surface, SensorLayout]:
        return matrix_mirrored_faces(geo, dist, 0.0, 0.0, spacing=spacing)

    return faces_sensor_predictor(echo, _AtDistance(face, float(distance)), scan, sample,
                                  config=config, receive=_prediction_config(receive),
                                  calibration=calibration, progress=progress, notes=notes,
                                  image_taper=receive.image_taper)


PREDICTION_EPS = 1e-4
"""NUFFT tolerance of the matrix receive's predictions when ``receive.eps`` is None
(else that): on the 32 × 32 at 15 mm, 1e-4 instead of 1e-6 (``backprojection.eps``
before session 12) moves the element pressures by 6.7e-4 of their peak and their
energies by 7e-5 rms (gains ~4e-5, against 1.4 % errors from the scan noise), at 3.2
instead of 5.8 s CPU per prediction (5 per receive in the near field)."""


def _prediction_config(rc: ReceiveConfig) -> ReceiveConfig:
    """``rc`` with ``eps`` = :data:`PREDICTION_EPS` when it is None."""
    return rc if rc.eps is not None else dataclasses.replace(rc, eps=PREDICTION_EPS)


def _with_prediction_noise(pose: MatrixEchoPose, predict: SensorPredictor,
                           geometry: ArrayGeometry, prediction: tuple[NDArray, float],
                           scan: HydrophoneScan, rc: ReceiveConfig,
                           refinement: dict[str, Any], notes: list[str],
                           column: tuple[float, NDArray] | None = None) -> MatrixEchoPose:
    """``pose`` with :func:`prediction_noise_pose`'s σ joined in quadrature to σ(d),
    σ(θx'), σ(θy') (``receive.pose_noise_draws``; only after a model-based refinement,
    whose fit the predicted pressures enter); ``refinement`` gains ``prediction_noise``
    (the three σ: m, rad, rad); a note when the scan's noise level is unknown."""
    if not rc.refine_pose or rc.pose_noise_draws == 0:
        return pose
    u = prediction_noise_pose(pose, predict, *prediction, geometry=geometry,
                              band=(float(predict.projection.frequencies.min()),
                                    float(predict.projection.frequencies.max())),
                              scan_samples=scan.n_samples, draws=rc.pose_noise_draws,
                              band_db=rc.sensitivity_band_db, distance_column=column)
    refinement["prediction_noise"] = [float(v) for v in u]
    if not np.any(u > 0):
        notes.append("the scan's noise level could not be measured (no evanescent region: "
                     "scan step >= lambda/2.2): the plate pose's uncertainty leaves out the "
                     "noise of the predicted pressures")
    return dataclasses.replace(
        pose, distance_uncertainty=math.hypot(pose.distance_uncertainty, u[0]),
        tilt_x_uncertainty=math.hypot(pose.tilt_x_uncertainty, u[1]),
        tilt_y_uncertainty=math.hypot(pose.tilt_y_uncertainty, u[2]))


NEAR_FIELD_FRESNEL = 1.0  # above it the d column of the pose model is measured (_refine)


def fresnel_number(geometry: ArrayGeometry, distance: float, band: tuple[float, float],
                   sound_speed: float) -> float:
    """Fresnel number ``a²/(λ 2d)`` of the image grid of a plate at ``distance`` (m):
    ``a`` the half-diagonal of the grid, λ at the band centre (``band`` in Hz)."""
    pos = geometry.positions
    if geometry.kind == "row-column":  # the strips' ends: the columns' x, the rows' y
        ext = [np.ptp(lattice_coordinates(geometry, a)[0]) + geometry.widths[
            geometry.strip_set == a].max() for a in (0, 1)]
        half = 0.5 * math.hypot(*ext)
    else:
        half = 0.5 * np.hypot(np.ptp(pos[:, 0]) + geometry.widths.max(),
                              np.ptp(pos[:, 1]) + geometry.heights.max())
    return float(half**2 * (0.5 * sum(band)) / sound_speed / (2 * distance))


def _near_field_note(geometry: ArrayGeometry, distance: float, band: tuple[float, float],
                     c0: float, notes: list[str], refinement: dict[str, Any]) -> None:
    """A note when the plate lies in the array's near field (:func:`fresnel_number`
    above :data:`NEAR_FIELD_FRESNEL`): d is weakly observable there, and whether its
    column was measured (:func:`_refine`)."""
    fresnel = fresnel_number(geometry, distance, band, c0)
    if fresnel > NEAR_FIELD_FRESNEL:
        how = ("its column of the pose fit was measured on a second prediction and σ(d) "
               "holds the refinement's last step" if refinement.get("distance_column")
               else "d and its σ are not reliable (no measured d column)")
        notes.append(f"the plate ({distance * 1e3:.2f} mm) lies in the array's near field "
                     f"(Fresnel number {fresnel:.2f}): the echo arrivals depend only weakly "
                     f"on d; {how}")


def _check_inputs(echo: object, face: object, scan: object) -> None:
    if not isinstance(echo, EchoRecording):
        raise InputError("expected a holoprobe.measurement.EchoRecording", field="echo")
    if not isinstance(face, MatrixFace):
        raise InputError("expected a MatrixFace", field="face")
    if not isinstance(scan, HydrophoneScan):
        raise InputError("expected a holoprobe.measurement.HydrophoneScan", field="scan")
    if echo.rf.shape[0] != face.geometry.count:
        raise InputError(f"expected {face.geometry.count} channels (one per element), got "
                         f"{echo.rf.shape[0]}", field="rf")


def _result(receiver: VirtualReceiver, pose: MatrixEchoPose, reflection_terms: tuple,
            ir: Any, sens: Any, pressures: tuple[NDArray, float, NDArray, NDArray],
            predict: SensorPredictor, geo: ArrayGeometry, echo: EchoRecording,
            rc: ReceiveConfig, notes: list[str], timings: dict[str, float],
            refinement: dict[str, Any]) -> ReceiveResult:
    """The :class:`ReceiveResult` of :func:`characterize_matrix_receive`."""
    rp, u_rp, reflection, sigma_rf = reflection_terms
    p_time, t_p0, p_avg, delays = pressures
    u = {"theta_y": receiver.theta_y_uncertainty, "theta_x": pose.tilt_x_uncertainty,
         "x0": receiver.x0_uncertainty, "z0": receiver.z0_uncertainty,
         "y0": float(_image_centre(pose, receiver.distance_uncertainty)[1][1]),
         "distance": receiver.distance_uncertainty, "onset": receiver.onset_uncertainty,
         "reflection_coefficient": u_rp}
    sp = predict.projection
    kb = int(np.argmax(np.abs(to_frequency(p_avg)[sp.bins])))
    return ReceiveResult(
        receiver=receiver, reflection_coefficient=float(rp), reflection_uncertainty=u_rp,
        reflection=reflection, drive_ratio=float(np.abs(predict.ratio[kb])),
        impulse_response=ir, ir_spectrum=spectrum_summary(ir.ir, ir.sampling_rate),
        element_x=geo.positions[:, 0].copy(), element_pressure=p_time * rp,
        averaged_pressure=p_avg * rp, pressure_start_time=float(t_p0),
        pressure_rate=float(predict.sampling_rate), sensor_points=sp.sensor_points,
        sensitivity=sens, rf_unit=echo.unit, uncertainties=u, warnings=notes,
        timings=timings, config=rc, source=echo.source, rf=echo.rf,
        extras={"rf_noise_sigma": sigma_rf, "pose_refinement": refinement,
                "element_delays": delays, "ir_shift": float(ir.shift),
                "offset": pose.offset, "offset_uncertainty": pose.offset_uncertainty,
                "theta_x_uncertainty": pose.tilt_x_uncertainty,
                "element_y": geo.positions[:, 1].copy(),
                "projection_bins": int(sp.frequencies.size),
                "record_length": sp.record_length, "scan_sensor_distance": sp.distances,
                "sensor_spacing": sp.spacing, "array": geo.kind})
