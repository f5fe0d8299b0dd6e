"""A uniform spherical cap radiated onto the scan window: the model of the window's bias.

The focus and axis of a focused source are estimated from a finite, tapered scan window;
what the window cuts off (and the taper changes) moves them by a few µm and a few
thousandths of a degree. The same estimator run on the hologram a *uniform* cap of the
file's geometry, placed at the estimated focus and axis, would radiate onto the same
window gives that bias directly (the model's own focus and axis are known exactly), so it
can be removed (see :func:`holoprobe.characterize.align_focused`).

The model hologram is the dense Rayleigh integral of the cap (Gauss–Legendre rings,
``spacing`` λ/``source_points_per_wavelength``) evaluated on a table over the cap's own
cylindrical coordinates (ρ from the axis, ζ along it from the apex) that the scan points
cover, and interpolated by quintic splines (nodes λ/``table_points_per_wavelength``): the
field of a uniform cap is axially symmetric, so ~10³–10⁴ table points replace the
10⁴–10⁵ scan points (and the table, in one meridian plane, needs half the cap).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import RectBivariateSpline, make_interp_spline
from scipy.optimize import minimize_scalar

from holoprobe.errors import FitError, InputError
from holoprobe.geometry import Medium, SourceGeometry, Surface
from holoprobe.propagation import rayleigh_integral

__all__ = ["cap_axial_maximum", "cap_hologram"]


def _cap_axial_amplitude(z: NDArray, a: float, b: float, radius: float, k: float) -> NDArray:
    """|p| / (ρc u0) on the axis of a uniform cap of rim radius a and opening radius b
    (O'Neil 1949, exact for the Rayleigh integral): 2 |sin(k (r_a − r_b) / 2)| / |1 − z/R|,
    r_a, r_b the distances to the rim and to the opening's edge (r_b = z without one)."""
    def edge(c: float) -> NDArray:
        h = radius - np.sqrt(radius**2 - c**2)
        return np.sqrt((z - h) ** 2 + c**2)
    return 2 * np.abs(np.sin(k * (edge(a) - edge(b)) / 2)) / np.abs(1 - z / radius)


def cap_axial_maximum(geometry: SourceGeometry, wavenumber: float) -> float:
    """Distance (m) from the apex of the on-axis pressure maximum of a uniform cap.

    Parameters
    ----------
    geometry : SourceGeometry
        A spherical cap (``aperture_diameter``, ``radius_of_curvature``,
        ``opening_diameter``).
    wavenumber : float
        rad/m.

    Returns
    -------
    float
        The maximum of O'Neil's exact axial field between 0.3 R and 1.5 R (a uniform
        cap's focal maximum lies on its axis by symmetry); for a weakly focused cap
        whose maximum lies nearer (R = 200 mm, 20 mm aperture at 1 MHz: 0.25 R), between
        0.02 R and 1.5 R.

    Raises
    ------
    FitError
        No maximum inside either range (the field still rises at its end).
    """
    if geometry.radius_of_curvature is None:
        raise InputError("expected a spherical cap (a radius of curvature), got a flat source",
                         field="radius_of_curvature")
    radius = float(geometry.radius_of_curvature)
    a, b = 0.5 * geometry.aperture_diameter, 0.5 * geometry.opening_diameter
    for start in (0.3, 0.02):
        z = np.linspace(start * radius, 1.5 * radius, 20_001) + 1.1e-9 * radius  # never R
        amp = _cap_axial_amplitude(z, a, b, radius, wavenumber)
        i = int(np.argmax(amp))
        if 0 < i < z.size - 1:
            break
    else:
        raise FitError(f"no on-axis maximum of the cap between 0.02 R and 1.5 R "
                       f"(R = {radius * 1e3:.1f} mm)")
    best = minimize_scalar(lambda q: -float(_cap_axial_amplitude(np.asarray(q), a, b, radius,
                                                                 wavenumber)),
                           bracket=(z[i - 1], z[i], z[i + 1]), tol=1e-12)
    return float(best.x)


def cap_hologram(points: NDArray, apex: NDArray, axis: NDArray, geometry: SourceGeometry,
                 frequency: float, medium: Medium, *, source_points_per_wavelength: float = 4.0,
                 table_points_per_wavelength: tuple[float, float] = (8.0, 8.0)
                 ) -> NDArray[np.complex128]:
    """Pressure (Pa) of a uniform cap (normal velocity 1 m/s) at ``points``.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Field points in m (in front of the cap).
    apex, axis : ndarray, shape (3,)
        The cap's apex (m) and unit axis (towards its centre of curvature).
    geometry : SourceGeometry
        A spherical cap.
    frequency : float
        Hz.
    medium : Medium
    source_points_per_wavelength : float
        Rings quadrature spacing, as a fraction of a wavelength.
    table_points_per_wavelength : (float, float)
        Spline table steps across (ρ) and along (ζ) the axis, as fractions of a
        wavelength (quintic splines: ~2e-5 of the peak against the dense integral at
        every scan point on a 61² twin at λ/10; the λ/3 quadrature's own error is
        ~1e-3 and smooth: the bias on that twin moves by 0.02 µm).

    Returns
    -------
    ndarray, complex, shape (n,)
        exp(−iωt) convention, as the hologram readers deliver.
    """
    wavelength = float(medium.wavelength(frequency))
    d = np.asarray(points, float) - np.asarray(apex, float)
    zeta = d @ axis
    rho = np.linalg.norm(d - zeta[:, None] * axis, axis=1)
    h, hz = (wavelength / n for n in table_points_per_wavelength)
    r_nodes = np.arange(0.0, rho.max() + 4 * h, h)
    flat = np.ptp(zeta) <= 1e-6 * wavelength      # a plane across the axis: ζ is one value
    n_z = 1 if flat else max(int(np.ceil(np.ptp(zeta) / hz)) + 7, 6)
    z_nodes = zeta.mean() if flat else zeta.min() - 3 * hz + hz * np.arange(n_z)
    rr, zz = np.meshgrid(r_nodes, z_nodes, indexing="ij")
    table_points = np.stack([rr.ravel(), np.zeros(rr.size), zz.ravel()], axis=1)
    target = Surface(table_points, np.tile([0.0, 0.0, 1.0], (rr.size, 1)), np.ones(rr.size))
    cap = Surface.spherical_cap(geometry.aperture_diameter, geometry.radius_of_curvature,
                                spacing=wavelength / source_points_per_wavelength,
                                opening_diameter=geometry.opening_diameter, layout="rings",
                                order=3)
    # the table lies in the plane y = 0, the cap is symmetric in y: one half, twice
    tiny = 1e-9 * geometry.aperture_diameter
    half = cap.points[:, 1] > -tiny
    weights = np.where(cap.points[half, 1] > tiny, 2.0, 1.0) * cap.weights[half]
    cap = Surface(cap.points[half], cap.normals[half], weights)
    table = rayleigh_integral(np.ones((cap.size, 1), complex), cap, target, [frequency],
                              medium, kernel="fwd_vp")[:, 0].reshape(rr.shape)
    if flat:
        return make_interp_spline(r_nodes, table[:, 0], k=5)(rho).astype(complex)
    out = np.empty(rho.size, complex)
    out.real = RectBivariateSpline(r_nodes, z_nodes, table.real, kx=5, ky=5)(rho, zeta,
                                                                             grid=False)
    out.imag = RectBivariateSpline(r_nodes, z_nodes, table.imag, kx=5, ky=5)(rho, zeta,
                                                                             grid=False)
    return out
