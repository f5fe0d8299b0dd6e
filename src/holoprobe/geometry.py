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

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError

__all__ = [
    "Medium",
    "PlaneGrid",
    "Pose",
    "Surface",
    "rotation_matrix",
    "uniform_axis_step",
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

    @property
    def angles_deg(self) -> tuple[float, float, float]:
        """(θx, θy, θz) in degrees."""
        return tuple(float(np.rad2deg(a)) for a in (self.theta_x, self.theta_y, self.theta_z))

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
        x = (np.arange(nx) - (nx - 1) / 2) * dx
        y = (np.arange(ny) - (ny - 1) / 2) * dy
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


@dataclass(frozen=True)
class Surface:
    """A sampled surface: points, unit normals and integration (area) weights.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        Positions in m.
    normals : array_like, shape (n, 3)
        Unit normals (normalised on construction).
    weights : array_like, shape (n,)
        Area weights in m² (quadrature weights of a surface integral).
    """

    points: NDArray[np.float64]
    normals: NDArray[np.float64]
    weights: NDArray[np.float64]

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
        for arr in (points, normals, weights):
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
        """Join several surfaces into one."""
        return cls(
            np.concatenate([s.points for s in surfaces]),
            np.concatenate([s.normals for s in surfaces]),
            np.concatenate([s.weights for s in surfaces]),
        )
