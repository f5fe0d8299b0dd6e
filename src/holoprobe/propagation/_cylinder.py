"""Projection of a plane's data onto a cylinder by the cylinder's symmetry.

The plane-wave sum of :class:`~holoprobe.propagation.ProjectionPlan` (the angular
spectrum of the data on its plane, propagating waves only) evaluated on the cylinder of
radius R whose axis is the y axis through C = (0, ·, −R), at the points
``r(s, y) = (R sin φ, y, R cos φ − R)``, φ = s/R, of an (s, y) grid.

Waves on a lattice that shares the cylinder's symmetry. The continuous plane-wave
integral is discretised on a regular lattice of wave numbers (k''_x, k''_y) in a frame
whose y axis is the cylinder axis (the source plane's x axis made normal to y; for a
plane without tilt or turn about its normal, the plane's own frame). The change of
variables from the plane's (κx, κy) costs the Jacobian |k_z| / |k''_z| of the two
projections of the wave sphere, and the data's spectrum at the new wave numbers is its
Fourier sum there (a 2-D type-2 NUFFT of the data: exact for the sampled, windowed data,
as the plan's FFT is at its lattice). By Poisson summation the lattice sum is the field
of the data repeated every L'' along the new frame's axes, L'' the padded lengths of
the padding rule (``propagation.padded_shape``): the same images the plan's FFT has.

Each column of the lattice is one q_y = k''_y; its waves have q = (κ sin α, q_y, κ cos α),
κ = √(k² − q_y²), and ``q·r = q·C + q_y y + κR cos(φ − α)``. Along the arc a column's sum
is a circular convolution of the wave strengths with the kernel

    G(θ) = e^{iκR cos θ}                      (pressure)
    G(θ) = κ cos θ/(k ρ0c0) · e^{iκR cos θ}   (radial velocity: q·n = κ cos(φ − α)),

whose Fourier coefficients are those of G sampled on N > 2(κR + 10 (κR/2)^{1/3} + 16)
angles (one FFT; the neglected Bessel orders J_m(κR) are below 1e-8). So per column

    S(φ) = Σ_m Ĝ_m e^{imφ} Σ_w B_w e^{−imα_w}

is a 1-D type-1 NUFFT (waves → modes) and a 1-D type-2 NUFFT (modes → the arc), and the
sum over the columns at the grid's y a small dense product. No 3-D fine grid over the
cylinder's bounding box (the cost of ``ProjectionPlan.project``'s type-3 transform):
~5× less CPU per bin on a C5-2's face (0.34 s against 1.58 s at eps 1e-4), the same
numbers to the NUFFT tolerance and the images of the padding.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe._progress import progress_iter
from holoprobe.errors import InputError
from holoprobe.geometry import PlaneGrid, Surface
from holoprobe.propagation._plan import (
    ProjectionPlan,
    Quantity,
    _direction,
    _target_local,
    padded_shape,
)
from holoprobe.signal import Threads, blas_threads, next_fast_length, workers

__all__ = ["project_cylinder"]


def _cylinder_points(radius: float, s: NDArray, y: NDArray) -> Surface:
    ss, yy = np.meshgrid(s / radius, y, indexing="ij")
    sn, cs = np.sin(ss.ravel()), np.cos(ss.ravel())
    pts = np.stack([radius * sn, yy.ravel(), radius * (cs - 1.0)], axis=-1)
    return Surface(pts, np.stack([sn, np.zeros_like(sn), cs], axis=-1), np.ones(sn.size))


def _axis_frame(source: PlaneGrid) -> NDArray[np.float64]:
    """Axes (columns) of the lattice frame: y along the cylinder axis, x the source
    plane's x axis made normal to it."""
    normal = source.pose.normal
    ey = np.array([0.0, 1.0, 0.0])
    ez = normal - (normal @ ey) * ey
    norm = float(np.linalg.norm(ez))
    frame = np.stack([np.cross(ey, ez / norm), ey, ez / norm], axis=-1) if norm > 0 else None
    if frame is None or frame[:, 2] @ normal <= 0.5:
        raise InputError("the source plane is turned more than 60° from a plane through the "
                         "cylinder axis", field="pose")
    return frame


class _CylinderTransform:
    """One frequency of the data summed on the cylinder's (s, y) grid (module notes)."""

    def __init__(self, plan: ProjectionPlan, radius: float, s: NDArray, y: NDArray,
                 lengths: tuple[float, float], *, velocity: bool, time_origin: float,
                 taper: tuple[float, float] | None = None):
        src = plan.source
        self.taper = taper
        self.field, self.medium, self.eps = plan.field, plan.medium, max(plan.eps, 1e-14)
        self.frame = _axis_frame(src)
        self.rot = src.pose.rotation
        self.radius, self.s, self.y = radius, s, y
        self.step = (src.dx, src.dy)
        self.dk = (2 * np.pi / lengths[0], 2 * np.pi / lengths[1])
        # the data's Fourier sum is referred to its middle sample (finufft's mode 0)
        nx, ny = src.shape
        self.middle = np.array([src.x[0] + (nx // 2) * src.dx, src.y[0] + (ny // 2) * src.dy])
        self.offset = np.array([0.0, 0.0, -radius]) - src.pose.origin_array  # C − r0
        self.velocity, self.time_origin = velocity, time_origin

    def _waves(self, k: float):
        """The kept lattice waves (propagating, towards the source plane's front, within
        its sampled band and the taper), as flat arrays: source-frame q (3, M),
        scan-frame κ (3, M), their column (index into ``ky``), the Jacobian weight, and
        the lattice's q_y of every column. Only the disc |k''| < k is built (the
        undersampled data keep a fraction of it at the top of a band: the whole
        rectangle's temporaries were a third of a projection's CPU)."""
        mx, my = int(k / self.dk[0]), int(k / self.dk[1])
        kx1 = self.dk[0] * np.arange(-mx, mx + 1)
        ky1 = self.dk[1] * np.arange(-my, my + 1)
        ix, iy = np.nonzero(kx1[:, None] ** 2 + ky1[None, :] ** 2 < k * k)
        kz0 = np.sqrt(k * k - kx1[ix] ** 2 - ky1[iy] ** 2)
        # both hemispheres of the lattice frame: the source plane's waves tilted past its
        # grazing angle lie in the lower one. The plane's normal is (0, b, a) in the
        # lattice frame (its x axis is normal to it), so a lower wave reaches the plane's
        # front (κz = b k_y − a |k_z| > 0) only where |k_z| < (b/a) k_y: a thin rim
        normal = self.frame.T @ self.rot[:, 2]
        low = kz0 * normal[2] < normal[1] * ky1[iy]
        kx = np.concatenate([kx1[ix], kx1[ix[low]]])
        ky = np.concatenate([ky1[iy], ky1[iy[low]]])
        kz, col = np.concatenate([kz0, -kz0[low]]), np.concatenate([iy, iy[low]])
        kap = (self.rot.T @ self.frame) @ np.stack([kx, ky, kz])  # along the plane's axes
        # the plan's FFT lattice spans [−π, π) per step: the same waves of undersampled data
        ux, uy = kap[0] * self.step[0] / np.pi, kap[1] * self.step[1] / np.pi
        lo, hi = -1.0 - 1e-9, 1.0 - 1e-9
        keep = (kap[2] > 0) & (ux >= lo) & (ux < hi) & (uy >= lo) & (uy < hi)
        weight = kap[2] / np.abs(kz)
        if self.taper is not None:  # the plan's image taper (ProjectionPlan.taper_range)
            s_in, s_out = self.taper
            sin = np.hypot(kap[0], kap[1]) / k
            keep &= sin < s_out
            weight *= 0.5 + 0.5 * np.cos(np.pi * np.clip((sin - s_in) / (s_out - s_in),
                                                        0.0, 1.0))
        q = self.frame @ np.stack([kx[keep], ky[keep], kz[keep]])
        return q, kap[:, keep], col[keep], weight[keep], ky1

    def _strengths(self, n: int, k: float):
        """Strengths of the kept waves (M,), their angle about the cylinder axis (M,),
        their column (M,) and the columns' q_y."""
        import finufft

        q, kap, col, weight, qy = self._waves(k)
        dx, dy = self.step
        spec = finufft.nufft2d2(np.ascontiguousarray(kap[0] * dx),
                                np.ascontiguousarray(kap[1] * dy),
                                np.ascontiguousarray(self.field[:, :, n], dtype=np.complex128),
                                isign=-1, eps=self.eps)
        phase = (-kap[0] * self.middle[0] - kap[1] * self.middle[1] + self.offset @ q
                 - k * self.time_origin)
        scale = dx * dy * self.dk[0] * self.dk[1] / (4 * np.pi**2)
        strength = spec * weight * scale * np.exp(1j * phase)
        return strength, np.arctan2(q[0], q[2]), col, qy

    def _kernels(self, kappa: NDArray, k: float, n: int) -> NDArray[np.complex128]:
        """Fourier coefficients (nc, n) of each column's kernel, in FFT order."""
        ct = np.cos(2 * np.pi * np.arange(n) / n)[None, :]
        g = np.exp(1j * (kappa[:, None] * self.radius) * ct)
        if self.velocity:
            g *= (kappa[:, None] / (k * self.medium.impedance)) * ct
        return np.fft.fft(g, axis=1) / n

    def __call__(self, n: int, frequency: float) -> NDArray[np.complex128]:
        import finufft

        k = 2 * np.pi * frequency / self.medium.sound_speed
        strength, alpha, col, qy = self._strengths(n, k)
        out = np.zeros((self.s.size, self.y.size), dtype=np.complex128)
        if col.size == 0:
            return out
        order = np.argsort(col, kind="stable")
        strength, alpha, col = strength[order], alpha[order], col[order]
        present, starts = np.unique(col, return_index=True)
        # columns whose waves are all weaker than the tolerance add nothing it keeps
        norm = np.sqrt(np.add.reduceat(np.abs(strength) ** 2, starts))
        ends = np.append(starts[1:], col.size)
        use = np.flatnonzero(norm > self.eps * norm.max())
        if use.size == 0:
            return out
        cols = present[use]
        kappa = np.sqrt(np.maximum(k * k - qy[cols] ** 2, 0.0))
        modes_n = int(next_fast_length(2 * int(np.ceil(
            k * self.radius + 10.0 * (0.5 * k * self.radius) ** (1 / 3) + 16))))
        modes = np.empty((cols.size, modes_n), dtype=np.complex128)
        plan1 = finufft.Plan(1, (modes_n,), eps=self.eps, isign=-1, nthreads=1, modeord=1)
        for i, u in enumerate(use):
            rows = slice(starts[u], ends[u])
            plan1.setpts(np.ascontiguousarray(alpha[rows]))
            modes[i] = plan1.execute(np.ascontiguousarray(strength[rows]))
        modes *= self._kernels(kappa, k, modes_n)
        plan2 = finufft.Plan(2, (modes_n,), n_trans=cols.size, eps=self.eps, isign=1,
                             nthreads=1, modeord=1)
        plan2.setpts(np.ascontiguousarray(self.s / self.radius))
        arc = plan2.execute(modes)  # (nc, ns)
        return arc.T @ np.exp(1j * np.outer(qy[cols], self.y))


def project_cylinder(plan: ProjectionPlan, radius: float, s: ArrayLike, y: ArrayLike, *,
                     quantity: Quantity = "normal_velocity", time_origin: float = 0.0,
                     progress: bool | None = False) -> NDArray[np.complex128]:
    """Field of a plan's data on a cylinder, on its unrolled (s, y) grid.

    Parameters
    ----------
    plan : ProjectionPlan
        The data; its source pose places the plane in the cylinder's frame (its NUFFT
        tolerance, guard angle, padding and ``image_taper`` apply — the taper weighs
        each lattice wave by its sin θ from the source normal, as the plan's blocks;
        its cached spectra are not used).
    radius : float
        R in m; the cylinder's axis is the y axis through (0, ·, −R), the point
        ``(R sin(s/R), y, R cos(s/R) − R)`` lies at arc length s from the apex (origin).
    s, y : array_like, shape (ns,), (ny,)
        Arc positions (within ±πR/2) and elevations in m.
    quantity : {"pressure", "normal_velocity"}
        Pressure (Pa·s) or the radial velocity (outwards, m/s·s).
    time_origin : float
        Distance r0 in m: results are multiplied by ``exp(−i k r0)``.
    progress : bool or None
        Progress bars.

    Returns
    -------
    ndarray, complex128, shape (ns, ny, nf)
        What ``plan.project`` gives on the cylinder's points (its 3-D type-3 transform),
        to the NUFFT tolerance and the images of the padding.
    """
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"expected a positive radius of curvature in m, got {radius!r}",
                         field="radius")
    if quantity not in ("pressure", "normal_velocity"):
        raise InputError("expected 'pressure' or 'normal_velocity'", field="quantity")
    s_arr = np.asarray(s, dtype=float).reshape(-1)
    y_arr = np.asarray(y, dtype=float).reshape(-1)
    if not np.all(np.abs(s_arr) <= 0.5 * np.pi * radius):
        raise InputError("expected arc positions within ±πR/2", field="s")
    surface = _cylinder_points(radius, s_arr, y_arr)
    _direction(_target_local(plan.source, surface))
    npx, npy = padded_shape(plan.source, surface, guard_angle=plan.guard_angle,
                            padding=plan.padding)
    transform = _CylinderTransform(plan, radius, s_arr, y_arr,
                                   (npx * plan.source.dx, npy * plan.source.dy),
                                   velocity=quantity == "normal_velocity",
                                   time_origin=time_origin,
                                   taper=plan.taper_range(surface, (npx, npy)))
    freqs = plan.frequencies
    out = np.zeros((s_arr.size, y_arr.size, freqs.size), dtype=np.complex128)

    def work(n: int) -> None:
        out[:, :, n] = transform(n, float(freqs[n]))

    n_threads = workers()
    step = 4 * n_threads
    # threads over the bins; each bin's last product (ns × nc by nc × ny) with BLAS
    # threads of its own oversubscribed the cores (their spinning cost 1.5 s of 7.9 s
    # CPU of the 128-element C5-2's whole-band projection at load 12)
    with blas_threads(1), Threads(n_threads) as threads:
        for start in progress_iter(range(0, freqs.size, step), description="projecting",
                                   enabled=progress):
            threads.map(work, range(start, min(start + step, freqs.size)))
    return out
