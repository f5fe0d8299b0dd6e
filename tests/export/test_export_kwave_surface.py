"""k-Wave source of a reconstructed surface, without k-wave-python (NumPy part)."""

from __future__ import annotations

import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.export import kwave_surface_source, scan_to_kwave
from holoprobe.geometry import Medium, Pose, Surface
from holoprobe.io import SourceVelocity


def _disc(velocity: complex = 0.1 + 0.05j) -> SourceVelocity:
    surface = Surface.disc(6e-3, spacing=0.1e-3).moved(Pose(origin=(0.0, 0.0, -5e-3)))
    vel = np.full((surface.size, 1), velocity)
    return SourceVelocity(surface, [1e6], vel, Medium(), kind="flat-disc",
                          aperture=(6e-3, 6e-3), apex=np.array([0.0, 0.0, -5e-3]))


def test_monopole_disc_is_one_voxel_plane_with_rho_c_u():
    src = _disc()
    step = 0.2e-3
    origin = scan_to_kwave([-4e-3, -4e-3, -6e-3])  # k-Wave (x, y, z) = scan (z, x, y)
    dt, nt = 1e-8, 400
    mask, p = kwave_surface_source(src, (20, 41, 41), (step, step, step), origin, dt, nt,
                                   ramp_cycles=0.0)
    # the plane z_scan = −5 mm is k-Wave x index (−5 + 6) / 0.2 = 5
    assert np.nonzero(mask.any(axis=(1, 2)))[0].tolist() == [5]
    # its voxels cover the disc (staircase rim: within a step of the edge)
    assert np.pi * (3e-3 - step) ** 2 / step**2 < mask.sum()
    assert mask.sum() < np.pi * (3e-3 + step) ** 2 / step**2
    t = np.arange(nt) * dt
    expected = Medium().impedance * np.real((0.1 + 0.05j) * np.exp(-2j * np.pi * 1e6 * t))
    np.testing.assert_allclose(p, np.broadcast_to(expected, p.shape), atol=1e-9)


def test_dipole_splits_the_velocity_along_the_normal():
    src = _disc(0.2)
    step = 0.2e-3
    _, (ux, uy, uz) = kwave_surface_source(src, (20, 41, 41), (step,) * 3,
                                           scan_to_kwave([-4e-3, -4e-3, -6e-3]), 1e-8, 10,
                                           representation="dipole", ramp_cycles=0.0)
    np.testing.assert_allclose(ux[:, 0], 0.2)  # the disc's normal is the beam axis (k-Wave x)
    assert np.abs(uy).max() == 0 and np.abs(uz).max() == 0


def test_surface_outside_the_grid_is_one_clear_error():
    with pytest.raises(InputError, match="outside the k-Wave grid"):
        kwave_surface_source(_disc(), (4, 4, 4), (0.2e-3,) * 3, np.zeros(3), 1e-8, 10)
