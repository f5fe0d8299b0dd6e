"""The nouns of holoprobe's geometry: medium, pose, planar grid and surface.

Conventions (one set, everywhere; see ``docs/conventions.md``):

* SI units: m, s, Hz, Pa, kg/m³, m/s. Angles are radians; degrees only at the
  user boundary, with a ``_deg`` suffix.
* Coordinates: origin at the centroid of the virtual transducer surface; x
  lateral (across elements), y elevation (along elements), z the propagation axis.
* A plane is placed by rotation angles (θx, θy, θz) and an origin r0:
  ``R = Rz(θz) @ Ry(θy) @ Rx(θx)``; the in-plane point (u, v, 0) lies at
  ``R @ (u, v, 0) + r0`` (paper section II D).
* Arrays on a plane grid are laid out ``(nx, ny, ...)``: the first axis follows
  ``x``, the second ``y``; flattened points are in C order (``x`` slowest).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe import _quadrature as _quad
from holoprobe.errors import InputError

__all__ = [
    "ARRAY_KINDS",
    "SOURCE_KINDS",
    "SPARSE_LAYOUTS",
    "ArrayGeometry",
    "Medium",
    "PlaneGrid",
    "Pose",
    "SourceGeometry",
    "Surface",
    "plate_plane",
    "rotation_matrix",
    "sparse_layout",
    "uniform_axis_step",
    "water_sound_speed",
]

_UNIFORM_RTOL = 1e-6


def rotation_matrix(theta_x: float, theta_y: float, theta_z: float) -> NDArray[np.float64]:
    """Rotation matrix ``R = Rz(θz) @ Ry(θy) @ Rx(θx)`` (right-handed, radians).

    Parameters
    ----------
    theta_x, theta_y, theta_z : float
        Rotation angles about x, y and z in radians, applied in that order.

    Returns
    -------
    ndarray, shape (3, 3)
        The rotation matrix.

    Examples
    --------
    >>> R = rotation_matrix(0.0, 0.0, np.pi / 2)
    >>> np.round(R @ [1.0, 0.0, 0.0], 12)
    array([0., 1., 0.])
    """
    cx, sx = np.cos(theta_x), np.sin(theta_x)
    cy, sy = np.cos(theta_y), np.sin(theta_y)
    cz, sz = np.cos(theta_z), np.sin(theta_z)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
    ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    rz = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry @ rx


_MARCZAK_1997 = (1.402385e3, 5.038813, -5.799136e-2, 3.287156e-4, -1.398845e-6,
                 2.787860e-9)


def plate_plane(distance: float, virtual_tilt: float, virtual_tilt_x: float = 0.0
                ) -> tuple[NDArray, NDArray]:
    """Point and unit normal of a flat reflector's front face (the receive experiment).

    The face passes through (0, 0, d) on the probe's axis and is rotated by θy'/2 about
    y, so that the mirror image of the probe (the virtual sensor) is tilted by θy'
    (paper section III B; :meth:`ArrayGeometry.mirrored` gives the image of an array).

    Parameters
    ----------
    distance : float
        d in m, from the origin of the probe's frame (the face centre; the apex of a
        convex array) along z.
    virtual_tilt : float
        θy' in rad.
    virtual_tilt_x : float
        θx' in rad (a 2-D matrix array's second tilt; 0 for 1-D arrays): the normal
        is e_z turned by θx'/2 about x, then by θy'/2 about y; the image of the array
        is tilted by θx' about x and θy' about y.

    Returns
    -------
    point, normal : ndarray, shape (3,)
        ``(0, 0, d)`` and ``(sin(θy'/2) cos(θx'/2), −sin(θx'/2), cos(θy'/2) cos(θx'/2))``
        (``(sin(θy'/2), 0, cos(θy'/2))`` for θx' = 0).
    """
    a, b = 0.5 * float(virtual_tilt), 0.5 * float(virtual_tilt_x)
    return (np.array([0.0, 0.0, float(distance)]),
            np.array([math.sin(a) * math.cos(b), -math.sin(b), math.cos(a) * math.cos(b)]))


def water_sound_speed(temperature: ArrayLike) -> NDArray[np.float64]:
    """Speed of sound in pure water at atmospheric pressure (Marczak 1997), in m/s.

    ``c(T) = Σ_i a_i T^i`` (T in °C, i = 0…5) with the coefficients of W. Marczak,
    "Water as a standard in the measurements of speed of sound in liquids",
    J. Acoust. Soc. Am. 102(5), 2776–2779 (1997), doi:10.1121/1.420332: a fit to the
    measurements of Del Grosso & Mader, Kroebel & Mahrt and Fujii & Masui, valid from
    0 to 95 °C within about 0.04 m/s.

    Parameters
    ----------
    temperature : array_like
        Water temperature in °C.

    Returns
    -------
    ndarray
        m/s, same shape.

    Examples
    --------
    >>> round(float(water_sound_speed(20.0)), 2)
    1482.38
    """
    t = np.asarray(temperature, dtype=float)
    if not np.all(np.isfinite(t)) or np.any((t < 0.0) | (t > 95.0)):
        raise InputError(f"expected a water temperature in [0, 95] °C, got {temperature!r}",
                         field="water_temperature")
    return np.polynomial.polynomial.polyval(t, _MARCZAK_1997)


@dataclass(frozen=True)
class Medium:
    """A homogeneous, lossless fluid.

    Parameters
    ----------
    density : float
        Mass density ρ0 in kg/m³ (default: water at 20 °C, 998).
    sound_speed : float
        Speed of sound c0 in m/s (default: water at 20 °C, 1481).
    """

    density: float = 998.0
    sound_speed: float = 1481.0

    def __post_init__(self) -> None:
        for name in ("density", "sound_speed"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise InputError(f"expected a positive finite number, got {value!r}", field=name)

    @classmethod
    def water(cls, temperature: float, *, density: float = 998.0) -> Medium:
        """Pure water at ``temperature`` °C: c0 from :func:`water_sound_speed`
        (Marczak 1997); ρ0 as given (default 998 kg/m³)."""
        return cls(density=float(density), sound_speed=float(water_sound_speed(temperature)))

    @property
    def impedance(self) -> float:
        """Characteristic acoustic impedance ρ0·c0 in kg/(m²·s) (Pa·s/m)."""
        return self.density * self.sound_speed

    def wavenumber(self, frequency: ArrayLike) -> NDArray[np.float64]:
        """Wavenumber k = 2πf/c0 in rad/m for frequencies in Hz."""
        return 2.0 * np.pi * np.asarray(frequency, dtype=float) / self.sound_speed

    def wavelength(self, frequency: ArrayLike) -> NDArray[np.float64]:
        """Wavelength λ = c0/f in m for frequencies in Hz."""
        return self.sound_speed / np.asarray(frequency, dtype=float)


@dataclass(frozen=True)
class Pose:
    """Orientation and position of a plane (scan plane, virtual sensor).

    Parameters
    ----------
    theta_x, theta_y, theta_z : float
        Rotation angles in radians; ``R = Rz(θz) @ Ry(θy) @ Rx(θx)``.
    origin : array_like, shape (3,)
        Position r0 of the plane's in-plane origin in m (transducer coordinates).

    Notes
    -----
    The in-plane point (u, v, w) is at ``R @ (u, v, w) + r0``. The plane's unit
    normal ``R @ (0, 0, 1)`` points away from the transducer for a scan plane in
    front of it.
    """

    theta_x: float = 0.0
    theta_y: float = 0.0
    theta_z: float = 0.0
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        origin = np.asarray(self.origin, dtype=float).reshape(-1)
        if origin.shape != (3,):
            raise InputError(f"expected 3 coordinates (x0, y0, z0) in m, got {origin.size}",
                             field="origin")
        if not np.all(np.isfinite(origin)):
            raise InputError("expected finite coordinates", field="origin")
        for name in ("theta_x", "theta_y", "theta_z"):
            if not np.isfinite(getattr(self, name)):
                raise InputError("expected a finite angle in radians", field=name)
        object.__setattr__(self, "origin", tuple(float(v) for v in origin))
        for name in ("theta_x", "theta_y", "theta_z"):
            object.__setattr__(self, name, float(getattr(self, name)))

    @classmethod
    def from_degrees(
        cls,
        theta_x_deg: float = 0.0,
        theta_y_deg: float = 0.0,
        theta_z_deg: float = 0.0,
        origin: ArrayLike = (0.0, 0.0, 0.0),
    ) -> Pose:
        """Build a pose from angles in degrees and an origin in m."""
        return cls(
            np.deg2rad(theta_x_deg),
            np.deg2rad(theta_y_deg),
            np.deg2rad(theta_z_deg),
            tuple(np.asarray(origin, dtype=float).reshape(3)),
        )

    @classmethod
    def from_matrix(cls, rotation: ArrayLike, origin: ArrayLike = (0.0, 0.0, 0.0)) -> Pose:
        """The pose of a rotation matrix ``Rz(θz) Ry(θy) Rx(θx)``, shape (3, 3), and an
        origin in m."""
        r = np.asarray(rotation, dtype=float)
        theta_y = float(-np.arcsin(np.clip(r[2, 0], -1.0, 1.0)))
        theta_x = float(np.arctan2(r[2, 1], r[2, 2]))
        theta_z = float(np.arctan2(r[1, 0], r[0, 0]))
        return cls(theta_x, theta_y, theta_z, tuple(np.asarray(origin, dtype=float).reshape(3)))

    @property
    def angles_deg(self) -> tuple[float, float, float]:
        """(θx, θy, θz) in degrees."""
        tx, ty, tz = (float(np.rad2deg(a)) for a in (self.theta_x, self.theta_y, self.theta_z))
        return tx, ty, tz

    @property
    def rotation(self) -> NDArray[np.float64]:
        """Rotation matrix R, shape (3, 3)."""
        return rotation_matrix(self.theta_x, self.theta_y, self.theta_z)

    @property
    def origin_array(self) -> NDArray[np.float64]:
        """Origin r0 as an array, shape (3,), in m."""
        return np.asarray(self.origin, dtype=float)

    @property
    def normal(self) -> NDArray[np.float64]:
        """Unit normal R @ (0, 0, 1) of the plane, shape (3,)."""
        return self.rotation[:, 2].copy()

    def to_global(self, local: ArrayLike) -> NDArray[np.float64]:
        """Map in-plane coordinates (u, v, w), shape (..., 3), to transducer coordinates."""
        local = np.asarray(local, dtype=float)
        return local @ self.rotation.T + self.origin_array

    def to_local(self, points: ArrayLike) -> NDArray[np.float64]:
        """Map transducer coordinates, shape (..., 3), to in-plane coordinates (u, v, w)."""
        points = np.asarray(points, dtype=float)
        return (points - self.origin_array) @ self.rotation

    def replace(self, **changes: object) -> Pose:
        """A copy with some fields changed (``origin`` in m, angles in radians)."""
        values = {
            "theta_x": self.theta_x,
            "theta_y": self.theta_y,
            "theta_z": self.theta_z,
            "origin": self.origin,
        }
        values.update(changes)
        # (type: ignore below) the Pose's own fields as a dict; the dataclass checks them
        return Pose(**values)  # type: ignore[arg-type]


def uniform_axis_step(axis: ArrayLike, name: str) -> float:
    """Check that a 1-D coordinate vector is uniform and increasing; return its step.

    Parameters
    ----------
    axis : array_like, shape (n,)
        Coordinates in m.
    name : str
        Name used in error messages (e.g. ``"x"``).

    Returns
    -------
    float
        The step in m (``nan`` for a single point).

    Raises
    ------
    InputError
        If the vector is not 1-D, not finite, not increasing or not uniform.
    """
    axis = np.asarray(axis, dtype=float)
    if axis.ndim != 1 or axis.size == 0:
        raise InputError(f"expected a non-empty 1-D coordinate vector, got shape {axis.shape}",
                         field=name)
    if not np.all(np.isfinite(axis)):
        raise InputError("coordinates contain NaN or inf", field=name)
    if axis.size == 1:
        return float("nan")
    steps = np.diff(axis)
    if np.any(steps <= 0):
        raise InputError("coordinates must increase monotonically", field=name)
    step = (axis[-1] - axis[0]) / (axis.size - 1)
    if np.max(np.abs(steps - step)) > _UNIFORM_RTOL * step + 1e-15:
        raise InputError(
            f"grid is not uniform: steps range from {steps.min():.6g} to {steps.max():.6g} m",
            field=name,
        )
    return float(step)


@dataclass(frozen=True)
class PlaneGrid:
    """A uniform rectangular grid on a plane with a pose.

    Parameters
    ----------
    x, y : array_like, shape (nx,), (ny,)
        Uniform, increasing in-plane coordinates in m.
    pose : Pose
        Placement of the plane (identity: the source plane z = 0).

    Notes
    -----
    Fields on the grid have shape ``(nx, ny, ...)``. Flattened points follow C
    order (``x`` index slowest), matching ``field.reshape(nx * ny, ...)``.
    """

    x: NDArray[np.float64]
    y: NDArray[np.float64]
    pose: Pose = field(default_factory=Pose)

    def __post_init__(self) -> None:
        x = np.array(self.x, dtype=float).reshape(-1) if np.ndim(self.x) <= 1 else self.x
        y = np.array(self.y, dtype=float).reshape(-1) if np.ndim(self.y) <= 1 else self.y
        uniform_axis_step(x, "x")
        uniform_axis_step(y, "y")
        x.setflags(write=False)
        y.setflags(write=False)
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "y", y)
        if not isinstance(self.pose, Pose):
            raise InputError("expected a holoprobe.Pose", field="pose")

    @classmethod
    def centered(cls, nx: int, ny: int, dx: float, dy: float | None = None,
                 pose: Pose | None = None) -> PlaneGrid:
        """A grid of nx × ny points with steps dx, dy (m), centred on the pose origin."""
        dy = dx if dy is None else dy
        x = (np.arange(nx) - (nx - 1) / 2).astype(np.float64) * dx
        y = (np.arange(ny) - (ny - 1) / 2).astype(np.float64) * dy
        return cls(x, y, pose or Pose())

    @property
    def shape(self) -> tuple[int, int]:
        """(nx, ny)."""
        return (self.x.size, self.y.size)

    @property
    def size(self) -> int:
        """Number of points nx·ny."""
        return self.x.size * self.y.size

    @property
    def dx(self) -> float:
        """Step along x in m."""
        return uniform_axis_step(self.x, "x")

    @property
    def dy(self) -> float:
        """Step along y in m."""
        return uniform_axis_step(self.y, "y")

    @property
    def cell_area(self) -> float:
        """Area dx·dy of one grid cell in m²."""
        return self.dx * self.dy

    def local_points(self) -> NDArray[np.float64]:
        """In-plane coordinates (u, v, 0) of all points, shape (nx·ny, 3), C order."""
        u, v = np.meshgrid(self.x, self.y, indexing="ij")
        return np.stack([u.ravel(), v.ravel(), np.zeros(u.size)], axis=-1)

    def points(self) -> NDArray[np.float64]:
        """Transducer coordinates of all points, shape (nx·ny, 3), C order."""
        return self.pose.to_global(self.local_points())

    def corners(self) -> NDArray[np.float64]:
        """Transducer coordinates of the four corner points, shape (4, 3): (x₀, y₀),
        (x₀, y₋₁), (x₋₁, y₀), (x₋₁, y₋₁). Any affine function of the points (a distance
        to a plane, a coordinate) and any convex one (a distance to a point) takes its
        extremes over the grid at them."""
        return self.pose.to_global(np.array([[u, v, 0.0] for u in (self.x[0], self.x[-1])
                                             for v in (self.y[0], self.y[-1])]))

    def to_surface(self, *, flip_normal: bool = False) -> Surface:
        """The grid as a :class:`Surface` (rectangle-rule weights dx·dy).

        Parameters
        ----------
        flip_normal : bool
            Use ``-R @ (0, 0, 1)`` as the normal (e.g. a sensor facing the source).
        """
        n = self.pose.normal * (-1.0 if flip_normal else 1.0)
        normals = np.broadcast_to(n, (self.size, 3)).copy()
        weights = np.full(self.size, self.cell_area if self.size > 1 else 1.0)
        return Surface(self.points(), normals, weights)

    def with_pose(self, pose: Pose) -> PlaneGrid:
        """The same in-plane grid with another pose."""
        return PlaneGrid(self.x, self.y, pose)


def _positive_length(value: object, name: str) -> float:
    try:
        # (type: ignore below) any object: float() raises for a non-number (caught below)
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InputError(f"expected a length in m, got {value!r}", field=name) from None
    if not (np.isfinite(v) and v > 0):
        raise InputError(f"expected a positive finite length in m, got {value!r}", field=name)
    return v


def _count(value: object, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer) \
            or int(value) != value or int(value) < 1:
        raise InputError(f"expected a whole number ≥ 1, got {value!r}", field=name)
    return int(value)


@dataclass(frozen=True)
class Surface:
    """A sampled surface: points, unit normals and integration (area) weights.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        Positions in m.
    normals : array_like, shape (n, 3)
        Unit normals (normalised on construction). For a source: pointing into the
        medium (towards the field).
    weights : array_like, shape (n,)
        Area weights in m² (quadrature weights of a surface integral).
    element : array_like of int, shape (n,), optional
        Label of the element (array element, bowl segment, mesh facet) each point
        belongs to; None when the surface is one piece.

    Notes
    -----
    Factories build the quadrature of the usual sources in their own coordinates
    (apex — the centre of the radiating face — at the origin, acoustic axis +z):
    :meth:`disc`, :meth:`rectangle`, :meth:`spherical_cap` (bowls, with a central
    opening and sector/annular segments), :meth:`linear_array`, :meth:`from_mesh`.
    :meth:`moved` places a surface with a :class:`Pose`. Weights converge to the exact
    area (cells cut by the rim or a kerf are integrated with refined sub-samples).
    """

    points: NDArray[np.float64]
    normals: NDArray[np.float64]
    weights: NDArray[np.float64]
    element: NDArray[np.int64] | None = None

    def __post_init__(self) -> None:
        points = np.array(self.points, dtype=float)
        normals = np.array(self.normals, dtype=float)
        weights = np.array(self.weights, dtype=float).reshape(-1)
        if points.ndim != 2 or points.shape[1] != 3:
            raise InputError(f"expected shape (n, 3), got {points.shape}", field="points")
        n = points.shape[0]
        if normals.shape != (n, 3):
            raise InputError(f"expected shape ({n}, 3), got {normals.shape}", field="normals")
        if weights.shape != (n,):
            raise InputError(f"expected shape ({n},), got {weights.shape}", field="weights")
        for name, arr in (("points", points), ("normals", normals), ("weights", weights)):
            if not np.all(np.isfinite(arr)):
                raise InputError("contains NaN or inf", field=name)
        lengths = np.linalg.norm(normals, axis=1)
        if np.any(lengths == 0):
            raise InputError("normals must have non-zero length", field="normals")
        normals = normals / lengths[:, None]
        arrays = [points, normals, weights]
        if self.element is not None:
            element = np.array(self.element).reshape(-1)
            if element.shape != (n,) or not np.issubdtype(element.dtype, np.integer):
                raise InputError(f"expected {n} integer labels, got {element.shape} "
                                 f"{element.dtype}", field="element")
            element = element.astype(np.int64)
            arrays.append(element)
            object.__setattr__(self, "element", element)
        for arr in arrays:
            arr.setflags(write=False)
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "normals", normals)
        object.__setattr__(self, "weights", weights)

    @property
    def size(self) -> int:
        """Number of points."""
        return self.points.shape[0]

    @property
    def area(self) -> float:
        """Total area Σ weights in m²."""
        return float(self.weights.sum())

    @classmethod
    def concatenate(cls, surfaces: list[Surface]) -> Surface:
        """Join several surfaces into one (element labels kept when all have them)."""
        labels = [s.element for s in surfaces if s.element is not None]
        element = np.concatenate(labels) if len(labels) == len(surfaces) else None
        return cls(
            np.concatenate([s.points for s in surfaces]),
            np.concatenate([s.normals for s in surfaces]),
            np.concatenate([s.weights for s in surfaces]),
            element,
        )

    def moved(self, pose: Pose) -> Surface:
        """The surface placed by ``pose``: points ``R p + r0``, normals ``R n``."""
        if not isinstance(pose, Pose):
            raise InputError("expected a holoprobe.Pose", field="pose")
        rot = pose.rotation
        return Surface(self.points @ rot.T + pose.origin_array, self.normals @ rot.T,
                       self.weights, self.element)

    def subset(self, mask: ArrayLike) -> Surface:
        """The points where ``mask`` (bool, shape (n,)) is true."""
        m = np.asarray(mask, dtype=bool)
        if m.shape != (self.size,):
            raise InputError(f"expected a boolean mask of shape ({self.size},)", field="mask")
        return Surface(self.points[m], self.normals[m], self.weights[m],
                       None if self.element is None else self.element[m])

    # ------------------------------------------------------------------ factories
    @classmethod
    def disc(cls, diameter: float, *, spacing: float, opening_diameter: float = 0.0,
             layout: str = "grid", order: int = 1) -> Surface:
        """A flat circular piston of ``diameter`` (m) in the plane z = 0, normals +z.

        ``spacing`` is the largest distance between neighbouring points (m); a central
        opening, the layout and the order are as for :meth:`spherical_cap`.
        """
        return cls.spherical_cap(diameter, None, spacing=spacing,
                                 opening_diameter=opening_diameter, layout=layout, order=order)

    @classmethod
    def rectangle(cls, width: float, height: float, *, spacing: float) -> Surface:
        """A flat rectangular piston width (x) × height (y) in m centred on the origin.

        Midpoint grid with steps ≤ ``spacing`` (m); normals +z; exact area.
        """
        arrays = _quad.rectangle_cells(_positive_length(width, "width"),
                                       _positive_length(height, "height"),
                                       _positive_length(spacing, "spacing"))
        return cls(*arrays[:3])

    @classmethod
    def spherical_cap(cls, aperture_diameter: float, radius_of_curvature: float | None, *,
                      spacing: float, opening_diameter: float = 0.0, rings: int = 1,
                      sectors: int = 1, kerf: float = 0.0, sector_start: float = 0.0,
                      layout: str = "grid", order: int = 1,
                      radial_edges: tuple[float, ...] = ()) -> Surface:
        """A spherical cap (focused bowl), optionally with a central opening and segments.

        Parameters
        ----------
        aperture_diameter : float
            Outer diameter in m, projected on the plane normal to the axis (the chord
            of the rim).
        radius_of_curvature : float or None
            Radius of curvature R in m, ≥ aperture_diameter / 2 (None: a flat disc).
            The apex is at the origin, the centre of curvature (geometric focus) at
            (0, 0, R); the surface is ``z = R − √(R² − x² − y²)``.
        spacing : float
            Largest distance between neighbouring points along the surface, in m
            (e.g. λ/4).
        opening_diameter : float
            Diameter of a central opening in m (projected; 0: none).
        rings, sectors : int
            Segments driven together: ``rings`` annuli of equal projected width
            between the opening and the rim, each split into ``sectors`` equal
            sectors starting at ``sector_start`` (rad, from +x towards +y).
            ``element`` labels = ring · sectors + sector.
        kerf : float
            Width in m of the inactive gaps between segments (0: none).
        layout : {"grid", "rings"}
            ``"grid"``: points on a Cartesian grid of projected (x, y) (maps of the
            surface are images on that grid); ``"rings"``: rings of equal arc width
            split into sectors with exact cell areas — a structurally different
            quadrature (the twin synthesises with it, so that no estimator that uses
            the grid commits an inverse crime).
        order : int
            ``"rings"`` without kerf: Gauss–Legendre nodes across each ring (the
            rings are ``order`` × ``spacing`` wide, uniform points around them:
            error O((k·width)^(2·order)) instead of the midpoint rule's O((k·h)²)).
            Ignored by the grid layout.
        radial_edges : tuple of float
            ``"rings"``: more projected radii (m) on which ring borders must fall
            (e.g. edges of a velocity defect).

        Returns
        -------
        Surface
            Normals point towards the centre of curvature (+z for a flat disc); the
            weights sum to the cap area 2πR·(h_out − h_in) (sagitta h) to ~1e-6.
        """
        aperture = _positive_length(aperture_diameter, "aperture_diameter")
        step = _positive_length(spacing, "spacing")
        roc = None if radius_of_curvature is None else \
            _positive_length(radius_of_curvature, "radius_of_curvature")
        if roc is not None and aperture > 2 * roc * (1 + 1e-12):
            raise InputError(f"aperture diameter {aperture:g} m exceeds twice the radius of "
                             f"curvature {roc:g} m (more than a hemisphere)",
                             field="aperture_diameter")
        opening = float(opening_diameter)
        if not (np.isfinite(opening) and 0 <= opening < aperture):
            raise InputError(f"expected 0 ≤ opening diameter < aperture ({aperture:g} m), "
                             f"got {opening_diameter!r}", field="opening_diameter")
        if layout not in ("grid", "rings"):
            raise InputError(f"expected 'grid' or 'rings', got {layout!r}", field="layout")
        if not (np.isfinite(kerf) and kerf >= 0):
            raise InputError(f"expected a kerf ≥ 0 in m, got {kerf!r}", field="kerf")
        rings, sectors = _count(rings, "rings"), _count(sectors, "sectors")
        arrays = _quad.cap_cells(aperture, roc, step, opening_diameter=opening, rings=rings,
                                 sectors=sectors, kerf=float(kerf), phi0=float(sector_start),
                                 layout=layout, order=_count(order, "order"),
                                 radial_edges=tuple(float(r) for r in radial_edges))
        return cls(*arrays[:3], arrays[3] if rings * sectors > 1 else None)

    @classmethod
    def linear_array(cls, element_count: int, pitch: float, element_width: float,
                     element_height: float, *, spacing: float) -> Surface:
        """A flat 1-D array: elements along x (centred on 0), height along y, normals +z.

        Each element is a midpoint grid with steps ≤ ``spacing`` (m); ``element`` holds
        the element index (element-major order).
        """
        n = _count(element_count, "element_count")
        pitch = _positive_length(pitch, "pitch")
        width = _positive_length(element_width, "element_width")
        if n > 1 and width > pitch * (1 + 1e-9):
            raise InputError(f"element width {width:g} m exceeds the pitch {pitch:g} m",
                             field="element_width")
        return cls(*_quad.linear_array_cells(
            n, pitch, width, _positive_length(element_height, "element_height"),
            _positive_length(spacing, "spacing")))

    @classmethod
    def from_mesh(cls, vertices: ArrayLike, faces: ArrayLike, *,
                  spacing: float | None = None) -> Surface:
        """Any meshed surface: triangles → centroids, unit normals and exact areas.

        Parameters
        ----------
        vertices : array_like, shape (nv, 3)
            Vertex positions in m.
        faces : array_like of int, shape (nt, 3)
            Vertex indices of each triangle; the normal is (v1 − v0) × (v2 − v0)
            (counter-clockwise seen from the medium).
        spacing : float, optional
            Subdivide each triangle into m² congruent ones so that edges are
            ≤ ``spacing`` (m); the points stay on the flat facets.

        Returns
        -------
        Surface
            ``element`` holds the index of the original triangle of each point.
        """
        v = np.asarray(vertices, dtype=float)
        f = np.asarray(faces)
        if v.ndim != 2 or v.shape[1] != 3 or not np.all(np.isfinite(v)):
            raise InputError(f"expected finite vertices of shape (nv, 3), got {v.shape}",
                             field="vertices")
        if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer) \
                or f.size == 0 or f.min() < 0 or f.max() >= v.shape[0]:
            raise InputError(f"expected triangles as integer vertex indices < {v.shape[0]}, "
                             f"shape (nt, 3), got {f.shape} {f.dtype}", field="faces")
        step = None if spacing is None else _positive_length(spacing, "spacing")
        pts, nrm, w, lab = _quad.mesh_cells(v, f.astype(np.int64), step)
        if np.any(w <= 0):
            bad = int(lab[np.flatnonzero(w <= 0)[0]])
            raise InputError(f"triangle {bad} has zero area", field="faces")
        return cls(pts, nrm, w, lab)


SOURCE_KINDS = ("spherical-cap", "flat-disc", "flat-rectangle", "array", "mesh")
"""Kinds of :class:`SourceGeometry` (the ``--source`` choices of the CLI)."""


@dataclass(frozen=True)
class SourceGeometry:
    """Nominal description of a single-element (or segmented) source.

    Parameters
    ----------
    kind : {"spherical-cap", "flat-disc", "flat-rectangle", "array", "mesh"}
        The source model.
    aperture_min, aperture_max : float
        Characteristic smallest and largest aperture in m (equal for circular
        sources: the diameter; a rectangle's height and width). The holography
        community's ``Geometry.apertureMin/apertureMax``.
    radius_of_curvature : float or None
        Radius of curvature in m of a spherical cap; None for a flat source.
    opening_diameter : float
        Diameter in m of a central opening (0: none).

    Notes
    -----
    Source coordinates: the apex (centre of the radiating face) at the origin, the
    acoustic axis along +z; a bowl's geometric focus is at (0, 0, R).
    """

    kind: str
    aperture_min: float
    aperture_max: float
    radius_of_curvature: float | None = None
    opening_diameter: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in SOURCE_KINDS:
            raise InputError(f"expected one of {SOURCE_KINDS}, got {self.kind!r}", field="kind")
        lo = _positive_length(self.aperture_min, "aperture_min")
        hi = _positive_length(self.aperture_max, "aperture_max")
        if lo > hi * (1 + 1e-12):
            raise InputError(f"aperture_min {lo:g} m exceeds aperture_max {hi:g} m",
                             field="aperture_min")
        object.__setattr__(self, "aperture_min", lo)
        object.__setattr__(self, "aperture_max", hi)
        roc = self.radius_of_curvature
        if self.kind == "spherical-cap":
            if roc is None:
                raise InputError("a spherical cap needs a radius of curvature in m",
                                 field="radius_of_curvature")
            roc = _positive_length(roc, "radius_of_curvature")
            if hi > 2 * roc * (1 + 1e-12):
                raise InputError(f"aperture {hi:g} m exceeds twice the radius of curvature "
                                 f"{roc:g} m", field="radius_of_curvature")
        elif roc is not None:
            raise InputError(f"a {self.kind} source has no radius of curvature (got {roc!r}); "
                             "use kind='spherical-cap'", field="radius_of_curvature")
        object.__setattr__(self, "radius_of_curvature", roc)
        opening = float(self.opening_diameter)
        if not (np.isfinite(opening) and 0 <= opening < lo):
            raise InputError(f"expected 0 ≤ opening diameter < aperture ({lo:g} m), got "
                             f"{self.opening_diameter!r}", field="opening_diameter")
        object.__setattr__(self, "opening_diameter", opening)

    @property
    def is_focused(self) -> bool:
        """True for a spherical cap."""
        return self.radius_of_curvature is not None

    @property
    def aperture_diameter(self) -> float:
        """The largest aperture (the diameter of a circular source) in m."""
        return self.aperture_max

    @property
    def rim_depth(self) -> float:
        """Sagitta h of the rim in m: z of the rim above the apex (0 when flat)."""
        if self.radius_of_curvature is None:
            return 0.0
        r = self.radius_of_curvature
        return r - float(np.sqrt(r * r - (0.5 * self.aperture_max) ** 2))

    def surface(self, spacing: float, *, layout: str = "grid") -> Surface:
        """The quadrature of this source (see :meth:`Surface.spherical_cap`) in m.

        Circular kinds use ``aperture_max`` as the diameter; a rectangle is
        ``aperture_max`` (x) × ``aperture_min`` (y). Arrays and meshes need more
        than this description: build them with :meth:`Surface.linear_array` /
        :meth:`Surface.from_mesh`.
        """
        if self.kind in ("spherical-cap", "flat-disc"):
            return Surface.spherical_cap(self.aperture_max, self.radius_of_curvature,
                                         spacing=spacing,
                                         opening_diameter=self.opening_diameter,
                                         layout=layout)
        if self.kind == "flat-rectangle":
            return Surface.rectangle(self.aperture_max, self.aperture_min, spacing=spacing)
        raise InputError(f"a {self.kind!r} source needs its own description: use "
                         "Surface.linear_array or Surface.from_mesh", field="kind")


ARRAY_KINDS = ("linear", "convex", "matrix", "row-column", "custom")
"""Kinds of :class:`ArrayGeometry`."""


def _unit_rows(value: ArrayLike, n: int, name: str) -> NDArray[np.float64]:
    arr = np.array(value, dtype=float)
    if arr.shape != (n, 3) or not np.all(np.isfinite(arr)):
        raise InputError(f"expected finite values of shape ({n}, 3), got {arr.shape}",
                         field=name)
    length = np.linalg.norm(arr, axis=1)
    if np.any(length == 0):
        raise InputError("expected non-zero vectors", field=name)
    return arr / length[:, None]


def _grid_indices(grid_position: ArrayLike, nx: int, ny: int
                  ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """``(ix, iy)`` of distinct elements inside an ``nx × ny`` grid."""
    gp = np.asarray(grid_position)
    if gp.ndim != 2 or gp.shape[1] != 2 or gp.shape[0] < 1 \
            or not np.all(np.equal(np.mod(gp, 1), 0)):
        raise InputError(f"expected integer (ix, iy) of shape (N, 2), got {gp.shape}",
                         field="grid_position")
    gp = gp.astype(np.int64)
    bad = (gp[:, 0] < 0) | (gp[:, 0] >= nx) | (gp[:, 1] < 0) | (gp[:, 1] >= ny)
    if bad.any():
        e = int(np.flatnonzero(bad)[0])
        raise InputError(f"element {e} (data row {e + 1}) at (ix, iy) = "
                         f"({int(gp[e, 0])}, {int(gp[e, 1])}) lies outside the {nx} x {ny} "
                         f"grid (ix 0…{nx - 1}, iy 0…{ny - 1})", field="grid_position")
    key = gp[:, 1] * nx + gp[:, 0]
    _, first, counts = np.unique(key, return_index=True, return_counts=True)
    if np.any(counts > 1):
        a = int(first[np.flatnonzero(counts > 1)[0]])
        b = int(np.flatnonzero(key == key[a])[1])
        raise InputError(f"elements {a} and {b} (data rows {a + 1} and {b + 1}) share "
                         f"(ix, iy) = ({int(gp[a, 0])}, {int(gp[a, 1])})",
                         field="grid_position")
    return gp[:, 0], gp[:, 1]


def _lengths(value: ArrayLike, n: int, name: str) -> NDArray[np.float64]:
    arr = np.array(np.broadcast_to(np.asarray(value, dtype=float), (n,)))
    if not np.all(np.isfinite(arr) & (arr > 0)):
        raise InputError(f"expected {n} positive finite lengths in m", field=name)
    return arr


@dataclass(frozen=True)
class ArrayGeometry:
    """Element layout of an array probe: where each element is, how it faces, its size.

    One description for linear, convex (curvilinear) and 2-D matrix arrays, in the
    probe's own coordinates (the centre of the face — the apex of a convex array — at the
    origin, beam axis +z, azimuth along x, elevation along y).

    Parameters
    ----------
    positions : array_like, shape (n, 3)
        Element centres in m.
    normals : array_like, shape (n, 3)
        Unit normals at the centres, pointing into the medium (normalised here).
    width_directions : array_like, shape (n, 3)
        Unit vectors along each element's width (its azimuth axis u); the height axis
        is ``v = normal × u``. Made orthogonal to the normal here.
    widths, heights : array_like, shape (n,) or scalar
        Element size along u (arc length for a convex array) and along v, in m.
    kind : {"linear", "convex", "matrix", "row-column", "custom"}
        The layout; ``"convex"`` elements are strips of the cylinder of radius
        ``radius_of_curvature`` whose axis is their v (exact curved faces in
        :meth:`surface`).
    radius_of_curvature : float, optional
        Radius of the convex face in m (convex arrays only).
    grid_shape : (int, int), optional
        ``(n_x, n_y)`` of a matrix array's full grid.
    grid_position : array_like of int, shape (n, 2), optional
        ``(ix, iy)`` of each element on that grid (a sparse grid keeps its holes).
    pitch : (float, float), optional
        Nominal pitch (x, y) in m (x: the arc-length pitch of a convex array).

    Notes
    -----
    Convex: element i sits at the angle ``φ_i = (i − (n−1)/2)·pitch/R`` from the apex,
    at ``(R sin φ_i, 0, R cos φ_i − R)`` with normal ``(sin φ_i, 0, cos φ_i)`` (centre
    of curvature at (0, 0, −R)). Matrix: element index ``iy·n_x + ix`` (x fastest),
    ``iy = 0`` at the most negative y.
    """

    positions: NDArray[np.float64]
    normals: NDArray[np.float64]
    width_directions: NDArray[np.float64]
    widths: NDArray[np.float64]
    heights: NDArray[np.float64]
    kind: str = "custom"
    radius_of_curvature: float | None = None
    grid_shape: tuple[int, int] | None = None
    grid_position: NDArray[np.int64] | None = None
    pitch: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        pos = np.array(self.positions, dtype=float)
        if pos.ndim != 2 or pos.shape[1] != 3 or pos.shape[0] < 1 \
                or not np.all(np.isfinite(pos)):
            raise InputError(f"expected finite element centres of shape (n, 3), got "
                             f"{pos.shape}", field="positions")
        n = pos.shape[0]
        nrm = _unit_rows(self.normals, n, "normals")
        u = _unit_rows(self.width_directions, n, "width_directions")
        u = u - np.sum(u * nrm, axis=1)[:, None] * nrm
        if np.any(np.linalg.norm(u, axis=1) < 1e-6):
            raise InputError("width directions parallel to the normals",
                             field="width_directions")
        u /= np.linalg.norm(u, axis=1)[:, None]
        if self.kind not in ARRAY_KINDS:
            raise InputError(f"expected one of {ARRAY_KINDS}, got {self.kind!r}", field="kind")
        roc = self.radius_of_curvature
        if self.kind == "convex":
            roc = _positive_length(roc, "radius_of_curvature")
        elif roc is not None:
            raise InputError(f"a {self.kind} array has no radius of curvature (got {roc!r})",
                             field="radius_of_curvature")
        grid_pos = None
        if self.grid_position is not None:
            grid_pos = np.array(self.grid_position).astype(np.int64).reshape(n, 2)
            grid_pos.setflags(write=False)
        arrays = {"positions": pos, "normals": nrm, "width_directions": u,
                  "widths": _lengths(self.widths, n, "widths"),
                  "heights": _lengths(self.heights, n, "heights")}
        for name, arr in arrays.items():
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "radius_of_curvature", None if roc is None else float(roc))
        object.__setattr__(self, "grid_position", grid_pos)
        if self.grid_shape is not None:
            object.__setattr__(self, "grid_shape", tuple(int(v) for v in self.grid_shape))
        if self.pitch is not None:
            object.__setattr__(self, "pitch", tuple(float(v) for v in self.pitch))

    # ------------------------------------------------------------------ views
    @property
    def count(self) -> int:
        """Number of elements."""
        return int(self.positions.shape[0])

    @property
    def layout(self) -> str:
        """``"sparse"`` for a matrix array that populates only some positions of its
        grid (``count < n_x·n_y``), ``"full"`` for a complete matrix, else :attr:`kind`."""
        if self.kind != "matrix":
            return self.kind
        shape = self.grid_shape
        if shape is not None and self.count < shape[0] * shape[1]:
            return "sparse"
        return "full"

    @property
    def strip_set(self) -> NDArray[np.int64]:
        """Row-column arrays: per element 0 for a column (a strip along y, placed along x:
        its width axis u is x) or 1 for a row (a strip along x, u along y); every other
        kind: 0 for all elements."""
        if self.kind != "row-column":
            return np.zeros(self.count, dtype=np.int64)
        return (np.abs(self.width_directions[:, 1])
                > np.abs(self.width_directions[:, 0])).astype(np.int64)

    @property
    def height_directions(self) -> NDArray[np.float64]:
        """Unit vectors ``v = normal × u`` along each element's height, shape (n, 3)."""
        return np.cross(self.normals, self.width_directions)

    @property
    def element_angles(self) -> NDArray[np.float64]:
        """Angle of each normal from +z in the xz plane (rad, positive towards +x)."""
        return np.arctan2(self.normals[:, 0], self.normals[:, 2])

    # ------------------------------------------------------------------ factories
    @classmethod
    def linear(cls, count: int, pitch: float, width: float, height: float) -> ArrayGeometry:
        """A flat 1-D array: elements along x centred on 0, normals +z."""
        n = _count(count, "count")
        p = _positive_length(pitch, "pitch")
        x = (np.arange(n) - (n - 1) / 2) * p
        pos = np.stack([x, np.zeros(n), np.zeros(n)], axis=-1)
        return cls(pos, np.tile([0.0, 0.0, 1.0], (n, 1)), np.tile([1.0, 0.0, 0.0], (n, 1)),
                   np.full(n, float(width)), np.full(n, float(height)), kind="linear",
                   pitch=(p, float(height)))

    @classmethod
    def convex(cls, count: int, pitch: float, radius_of_curvature: float, width: float,
               height: float) -> ArrayGeometry:
        """A convex (curvilinear) array: ``count`` elements on an arc in the xz plane.

        ``pitch`` and ``width`` are arc lengths in m; the apex (middle of the arc) is at
        the origin, the centre of curvature at (0, 0, −R).
        """
        n = _count(count, "count")
        p = _positive_length(pitch, "pitch")
        roc = _positive_length(radius_of_curvature, "radius_of_curvature")
        phi = (np.arange(n) - (n - 1) / 2) * p / roc
        if phi[-1] - phi[0] + _positive_length(width, "width") / roc >= 2 * np.pi:
            raise InputError(f"{n} elements of pitch {p:g} m do not fit on a circle of "
                             f"radius {roc:g} m", field="radius_of_curvature")
        s, c = np.sin(phi), np.cos(phi)
        zero = np.zeros(n)
        pos = np.stack([roc * s, zero, roc * (c - 1.0)], axis=-1)
        return cls(pos, np.stack([s, zero, c], axis=-1), np.stack([c, zero, -s], axis=-1),
                   np.full(n, float(width)), np.full(n, float(height)), kind="convex",
                   radius_of_curvature=roc,
                   pitch=(p, float(height)))

    @classmethod
    def matrix(cls, n_x: int, n_y: int, pitch_x: float, pitch_y: float | None = None,
               width: float | None = None, height: float | None = None, *,
               active: ArrayLike | None = None,
               grid_position: ArrayLike | None = None) -> ArrayGeometry:
        """A flat 2-D matrix array on z = 0 (index ``iy·n_x + ix``, x fastest), centred
        on its grid.

        ``width``/``height`` default to the pitches; ``active`` (bool, shape
        (n_y, n_x)) keeps only some elements (a sparse grid) in that order;
        ``grid_position`` (int, shape (N, 2): ``(ix, iy)`` of each element, distinct,
        inside the grid) gives them in any order instead (e.g. the RF channel order of a
        sparse probe).
        """
        nx, ny = _count(n_x, "n_x"), _count(n_y, "n_y")
        px = _positive_length(pitch_x, "pitch_x")
        py = px if pitch_y is None else _positive_length(pitch_y, "pitch_y")
        iy2, ix2 = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
        ix, iy = ix2.ravel(), iy2.ravel()
        if grid_position is not None:
            ix, iy = _grid_indices(grid_position, nx, ny)
        elif active is not None:
            mask = np.asarray(active, dtype=bool)
            if mask.shape != (ny, nx):
                raise InputError(f"expected a boolean mask of shape ({ny}, {nx})",
                                 field="active")
            keep = mask.ravel()
            ix, iy = ix[keep], iy[keep]
        n = ix.size
        if n == 0:
            raise InputError("no active element", field="active")
        pos = np.stack([(ix - (nx - 1) / 2) * px, (iy - (ny - 1) / 2) * py, np.zeros(n)],
                       axis=-1)
        return cls(pos, np.tile([0.0, 0.0, 1.0], (n, 1)), np.tile([1.0, 0.0, 0.0], (n, 1)),
                   np.full(n, px if width is None else float(width)),
                   np.full(n, py if height is None else float(height)), kind="matrix",
                   grid_shape=(nx, ny),
                   grid_position=np.stack([ix, iy], axis=-1), pitch=(px, py))

    @classmethod
    def row_column(cls, n_x: int, n_y: int | None = None, pitch_x: float = 0.2e-3,
                   pitch_y: float | None = None, kerf: float = 0.0) -> ArrayGeometry:
        """A flat row-column array on z = 0: ``n_x`` columns then ``n_y`` rows.

        Column ``i`` (element ``i``) is a strip along y at ``x_i = (i − (n_x−1)/2) p_x``,
        width ``p_x − kerf`` along x and length ``n_y p_y − kerf`` (the whole aperture)
        along y; row ``j`` (element ``n_x + j``) is a strip along x at
        ``y_j = (j − (n_y−1)/2) p_y``, width ``p_y − kerf`` along y (its u) and length
        ``n_x p_x − kerf`` along x. The two sets cross (on a real probe they lie on the
        two faces of the piezo plate; both radiate from z = 0 here). ``grid_shape`` is
        ``(n_x, n_y)``, ``grid_position`` ``(i, −1)`` for a column and ``(−1, j)`` for a
        row; :attr:`strip_set` tells them apart.
        """
        nx = _count(n_x, "n_x")
        ny = nx if n_y is None else _count(n_y, "n_y")
        px = _positive_length(pitch_x, "pitch_x")
        py = px if pitch_y is None else _positive_length(pitch_y, "pitch_y")
        k = float(kerf)
        if not (0.0 <= k < min(px, py)):
            raise InputError(f"expected 0 <= kerf < the pitch, got {kerf!r}", field="kerf")
        xc = (np.arange(nx) - 0.5 * (nx - 1)) * px
        yr = (np.arange(ny) - 0.5 * (ny - 1)) * py
        pos = np.zeros((nx + ny, 3))
        pos[:nx, 0], pos[nx:, 1] = xc, yr
        u = np.zeros((nx + ny, 3))
        u[:nx, 0], u[nx:, 1] = 1.0, 1.0
        widths = np.r_[np.full(nx, px - k), np.full(ny, py - k)]
        lengths = np.r_[np.full(nx, ny * py - k), np.full(ny, nx * px - k)]
        grid = np.r_[np.c_[np.arange(nx), np.full(nx, -1)],
                     np.c_[np.full(ny, -1), np.arange(ny)]]
        return cls(pos, np.tile([0.0, 0.0, 1.0], (nx + ny, 1)), u, widths, lengths,
                   kind="row-column", grid_shape=(nx, ny), grid_position=grid,
                   pitch=(px, py))

    # ------------------------------------------------------------------ derived
    def subset(self, mask: ArrayLike) -> ArrayGeometry:
        """The elements where ``mask`` (bool, shape (n,)) is true (kind kept)."""
        m = np.asarray(mask, dtype=bool)
        if m.shape != (self.count,) or not m.any():
            raise InputError(f"expected a boolean mask of shape ({self.count},) with at "
                             "least one true value", field="mask")
        return ArrayGeometry(self.positions[m], self.normals[m], self.width_directions[m],
                             self.widths[m], self.heights[m], self.kind,
                             self.radius_of_curvature, self.grid_shape,
                             None if self.grid_position is None else self.grid_position[m],
                             self.pitch)

    def moved(self, pose: Pose) -> ArrayGeometry:
        """The array placed by ``pose``: centres ``R p + r0``, directions ``R d``."""
        if not isinstance(pose, Pose):
            raise InputError("expected a holoprobe.Pose", field="pose")
        rot = pose.rotation
        return ArrayGeometry(self.positions @ rot.T + pose.origin_array, self.normals @ rot.T,
                             self.width_directions @ rot.T, self.widths, self.heights,
                             self.kind, self.radius_of_curvature, self.grid_shape,
                             self.grid_position, self.pitch)

    def mirrored(self, point: ArrayLike, normal: ArrayLike) -> ArrayGeometry:
        """The mirror image of the array across the plane through ``point`` (m) with
        unit ``normal``: the array a receiving element sees in a flat reflector.

        Centres and directions are reflected (``p − 2((p − p0)·n) n``); the image is
        left-handed, so its height axis ``normal × width`` points the other way than
        the reflected height axis: element faces are the same sets of points.
        """
        p0 = np.asarray(point, dtype=float).reshape(3)
        n = np.asarray(normal, dtype=float).reshape(3)
        n = n / np.linalg.norm(n)

        def reflect(v: NDArray, *, offset: bool) -> NDArray:
            d = (v - p0) @ n if offset else v @ n
            return v - 2.0 * d[:, None] * n[None, :]

        return ArrayGeometry(reflect(self.positions, offset=True),
                             reflect(self.normals, offset=False),
                             reflect(self.width_directions, offset=False), self.widths,
                             self.heights, self.kind, self.radius_of_curvature,
                             self.grid_shape, self.grid_position, self.pitch)

    def surface(self, spacing: float, *, layout: str = "grid", order: int = 3) -> Surface:
        """Quadrature of every element's face, labelled by element (element-major).

        Parameters
        ----------
        spacing : float
            Largest step in m along the face (arc length on a convex element).
        layout : {"grid", "gauss"}
            ``"grid"``: midpoint cells (the estimators'); ``"gauss"``: cells of
            ``order`` × ``spacing`` with ``order`` Gauss–Legendre nodes per axis (the
            twin's, a structurally different rule: no inverse crime).
        order : int
            Gauss–Legendre order of the ``"gauss"`` layout.

        Returns
        -------
        Surface
            Points on the exact faces (convex: on the cylinder, normals radial), area
            weights (exact element area: the cylinder is developable).
        """
        step = _positive_length(spacing, "spacing")
        if layout not in ("grid", "gauss"):
            raise InputError(f"expected 'grid' or 'gauss', got {layout!r}", field="layout")
        m = 1 if layout == "grid" else _count(order, "order")
        if m == 1:
            nodes, gw = np.zeros(1), np.full(1, 2.0)
        else:
            nodes, gw = np.polynomial.legendre.leggauss(m)
        pts, nrm, wts, lab = [], [], [], []
        v_dir = self.height_directions
        for e in range(self.count):
            w, h = self.widths[e], self.heights[e]
            nu = max(1, int(np.ceil(w / (m * step) - 1e-9)))
            nv = max(1, int(np.ceil(h / (m * step) - 1e-9)))
            du, dv = w / nu, h / nv
            a = (((np.arange(nu) + 0.5)[:, None] + 0.5 * nodes[None, :]) * du - 0.5 * w)
            b = (((np.arange(nv) + 0.5)[:, None] + 0.5 * nodes[None, :]) * dv - 0.5 * h)
            wa = np.tile(0.5 * gw * du, nu)
            wb = np.tile(0.5 * gw * dv, nv)
            aa, bb = np.meshgrid(a.ravel(), b.ravel(), indexing="ij")
            aa, bb = aa.ravel(), bb.ravel()
            n0, u0 = self.normals[e], self.width_directions[e]
            if self.radius_of_curvature is not None:
                ang = aa / self.radius_of_curvature
                along = self.radius_of_curvature * np.sin(ang)
                back = self.radius_of_curvature * (1.0 - np.cos(ang))
                normal = np.cos(ang)[:, None] * n0 + np.sin(ang)[:, None] * u0
            else:
                along, back = aa, np.zeros_like(aa)
                normal = np.broadcast_to(n0, (aa.size, 3))
            pts.append(self.positions[e] + along[:, None] * u0 + bb[:, None] * v_dir[e]
                       - back[:, None] * n0)
            nrm.append(normal)
            wts.append(np.outer(wa, wb).ravel())
            lab.append(np.full(aa.size, e, dtype=np.int64))
        return Surface(np.concatenate(pts), np.concatenate(nrm), np.concatenate(wts),
                       np.concatenate(lab))


SPARSE_LAYOUTS = ("spiral", "random")
"""Layouts of :func:`sparse_layout`."""


def sparse_layout(n_x: int, n_y: int, count: int, *, layout: str = "spiral",
                  taper: float = 0.5, seed: int = 0) -> NDArray[np.bool_]:
    """Which positions of an ``n_x × n_y`` lattice a sparse matrix array populates.

    Parameters
    ----------
    n_x, n_y : int
        Lattice size.
    count : int
        Elements to place (1 ≤ count ≤ n_x·n_y).
    layout : {"spiral", "random"}
        ``"spiral"``: a density-tapered Fermat spiral (golden-angle steps) on the disc
        inscribed in the lattice, each point snapped to the nearest free position, in
        order; ``"random"``: positions drawn without replacement with probability
        proportional to the density.
    taper : float
        Density ``1 − taper·ρ²`` (0 ≤ taper < 1), ρ the distance from the lattice centre
        over the disc radius (the half diagonal for ``"random"``).
    seed : int
        Random seed (``"random"`` only).

    Returns
    -------
    ndarray of bool, shape (n_y, n_x)
        The mask for :meth:`ArrayGeometry.matrix` (``active=``), ``count`` true values.
    """
    nx, ny = _count(n_x, "n_x"), _count(n_y, "n_y")
    n = _count(count, "count")
    if n > nx * ny:
        raise InputError(f"{n} elements do not fit on a {nx} x {ny} lattice", field="count")
    if layout not in SPARSE_LAYOUTS:
        raise InputError(f"expected one of {SPARSE_LAYOUTS}, got {layout!r}", field="layout")
    a = float(taper)
    if not 0.0 <= a < 1.0:
        raise InputError(f"expected 0 <= taper < 1, got {taper!r}", field="taper")
    iy, ix = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    u, v = (ix - 0.5 * (nx - 1)).ravel(), (iy - 0.5 * (ny - 1)).ravel()
    free = np.ones(nx * ny, dtype=bool)
    if layout == "random":
        rho2 = (u * u + v * v) / (0.25 * ((nx - 1) ** 2 + (ny - 1) ** 2) or 1.0)
        w = 1.0 - a * rho2
        pick = np.random.default_rng(seed).choice(nx * ny, size=n, replace=False,
                                                  p=w / w.sum())
        free[pick] = False
    else:
        # radius where the tapered density's cumulative share reaches (i + 1/2)/n:
        # ∫ (1 − aρ²) 2ρ dρ = ρ² − aρ⁴/2, solved for ρ²
        share = (np.arange(n) + 0.5) / n * (1.0 - 0.5 * a)
        rho2 = share if a == 0 else (1.0 - np.sqrt(1.0 - 2.0 * a * share)) / a
        radius = 0.5 * min(nx, ny) * np.sqrt(rho2)
        angle = np.arange(n) * np.pi * (3.0 - np.sqrt(5.0))
        for r, t in zip(radius, angle, strict=True):
            d = np.where(free, (u - r * np.cos(t)) ** 2 + (v - r * np.sin(t)) ** 2, np.inf)
            free[int(np.argmin(d))] = False
    return (~free).reshape(ny, nx)
