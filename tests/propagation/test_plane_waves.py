"""Rayleigh integral at scattered points by plane waves (Weyl expansion + type-3 NUFFTs).

Checked against what it did not compute: the analytic field of one baffled point
source, and the dense Rayleigh sum (``rayleigh_integral``) of an extended source,
at targets from 0.5 mm (evanescent waves dominate the error there) to far off-axis.
"""

from __future__ import annotations

import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.geometry import Medium, Surface
from holoprobe.propagation import plane_wave_cost, rayleigh_integral, rayleigh_plane_waves


def _targets(rng, n, z_lo=0.5e-3, z_hi=20e-3):
    pts = np.stack([rng.uniform(-6e-3, 6e-3, n), rng.uniform(-3e-3, 3e-3, n),
                    np.exp(rng.uniform(np.log(z_lo), np.log(z_hi), n))], axis=-1)
    return pts


def test_one_point_source_gives_the_analytic_baffled_monopole():
    medium = Medium()
    rng = np.random.default_rng(0)
    src = np.array([[0.4e-3, -0.3e-3, 0.0]])
    area = np.array([1e-8])
    f = np.array([1.5e6, 3e6])
    v = np.array([[2.0 - 1.0j, 0.5 + 1.5j]])
    pts = _targets(rng, 40)
    p = rayleigh_plane_waves(v, src, area, pts, f, medium)
    k = 2 * np.pi * f / medium.sound_speed
    r = np.linalg.norm(pts - src, axis=1)[:, None]
    exact = (-1j * k * medium.density * medium.sound_speed / (2 * np.pi)) * v * area[0] \
        * np.exp(1j * k * r) / r
    err = np.abs(p - exact) / np.abs(exact)
    assert err.max() < 2e-4, err.max()  # relative at every point, not only at the peak


def test_extended_source_matches_the_dense_rayleigh_sum_near_and_far():
    medium = Medium()
    rng = np.random.default_rng(1)
    xs, ys = np.meshgrid(np.arange(-2e-3, 2e-3, 0.1e-3), np.arange(-1e-3, 1e-3, 0.1e-3),
                         indexing="ij")
    n_src = xs.size
    src = Surface(np.stack([xs.ravel(), ys.ravel(), np.zeros(n_src)], axis=-1),
                  np.tile([0.0, 0.0, 1.0], (n_src, 1)), np.full(n_src, 1e-8))
    f = np.array([1e6, 3e6])
    # a steered, apodized source: phase across x, Hann in y
    v = (np.exp(1j * 2 * np.pi * f[None, :] * 2e-7 * src.points[:, :1] / 1e-3)
         * (1 + np.cos(np.pi * src.points[:, 1:2] / 1e-3))[:, :1])
    pts = _targets(rng, 40)
    tgt = Surface(pts, np.tile([0.0, 0.0, 1.0], (pts.shape[0], 1)), np.ones(pts.shape[0]))
    dense = rayleigh_integral(v, src, tgt, f, medium, kernel="fwd_vp", baffle="rigid")
    fast = rayleigh_plane_waves(v, src.points, src.weights, pts, f, medium)
    err = np.abs(fast - dense).max(axis=0) / np.abs(dense).max(axis=0)
    assert np.all(err < 1e-4), err
    near = pts[:, 2] < 1.5e-3
    assert near.sum() >= 5  # evanescent waves matter there: without them ~1e-1
    nodes, terms = plane_wave_cost(src.points, pts, f, medium)
    assert nodes > 0 and terms >= pts.shape[0] * f.size


def test_bad_inputs_are_refused():
    medium = Medium()
    src = np.array([[0.0, 0.0, 0.0]])
    with pytest.raises(InputError, match="z > 0"):
        rayleigh_plane_waves(np.ones((1, 1)), src, [1e-8], [[0, 0, 0.0]], [1e6], medium)
    with pytest.raises(InputError, match="plane z = 0"):
        rayleigh_plane_waves(np.ones((1, 1)), [[0, 0, 1e-3]], [1e-8], [[0, 0, 1e-3]], [1e6],
                             medium)
    with pytest.raises(InputError, match="frequencies"):
        rayleigh_plane_waves(np.ones((1, 1)), src, [1e-8], [[0, 0, 1e-3]], [-1.0], medium)
