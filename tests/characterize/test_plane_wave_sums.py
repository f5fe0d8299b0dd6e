"""The fast plane-wave sums of the alignment against the direct sums they replace.

``grid_sums`` / ``grid_adjoint`` (type-1 / type-2 NUFFT on regular lines, planes and
volumes) and the fused derivative kernel behind ``PlaneWaveField.derivatives`` are checked
against Σ c e^{ik·r} written out term by term (NumPy, no NUFFT).
"""

from __future__ import annotations

import numpy as np
import pytest

from holoprobe.characterize._hologram_field import (
    PlaneWaveField,
    _regular_ticks,
    grid_adjoint,
    grid_sums,
)
from holoprobe.geometry import Medium


def _waves(m: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(m, 3))
    d[:, 2] = np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=1)[:, None]
    k = 2 * np.pi * 1e6 / 1500.0
    return k * d, rng.normal(size=(m, 2)) + 1j * rng.normal(size=(m, 2))


@pytest.mark.parametrize("counts", [(160,), (17, 16), (7, 8, 5)])
def test_grid_sums_and_adjoint_match_the_direct_sums(counts: tuple[int, ...]) -> None:
    kv, c = _waves(3000)
    # steps up to 2 mm (k·step up to 8 rad: the phases wrap modulo 2π)
    axes = [np.linspace(-3e-3 * (i + 1), 2e-3 + i * 1e-2, n) for i, n in enumerate(counts)]
    mesh = np.meshgrid(*axes, indexing="ij")
    local = np.stack([g.ravel() for g in mesh], axis=1)
    ticks = _regular_ticks(local)
    assert ticks is not None
    kp = kv[:, :len(counts)]
    phases = np.exp(1j * local @ kp.T)
    direct = phases @ c
    assert np.abs(grid_sums(kp, c, ticks, 1e-12) - direct).max() < 1e-10 * np.abs(direct).max()
    left = np.random.default_rng(2).normal(size=(local.shape[0], 2)) + 0j
    want = left.T @ phases
    got = grid_adjoint(kp, left, ticks, 1e-12)
    assert np.abs(got - want).max() < 1e-10 * np.abs(want).max()


def test_irregular_points_are_not_taken_for_a_grid() -> None:
    assert _regular_ticks(np.array([[0.0], [1.0], [3.0]])) is None
    assert _regular_ticks(np.linspace(1.0, 0.0, 5)[:, None]) is None  # decreasing
    pts = np.stack(np.meshgrid([0.0, 1.0], [0.0, 1.0, 2.0], indexing="xy"), -1).reshape(-1, 2)
    assert _regular_ticks(pts) is None                                # not 'ij' order


def test_pressure_on_a_line_and_derivatives_match_the_direct_sums() -> None:
    kv, c = _waves(40_000)
    field = PlaneWaveField(kv, c[:, 0], 1e6, Medium(), 1.0)
    origin, axis = np.array([1e-3, -2e-3, 30e-3]), np.array([0.1, 0.2, 0.97])
    axis /= np.linalg.norm(axis)
    t = np.linspace(-5e-3, 5e-3, 101)                        # 4e6 terms: the NUFFT path
    want = np.exp(1j * (origin + t[:, None] * axis) @ kv.T) @ c[:, 0]
    got = field.pressure_local(origin, axis[None, :], t[:, None])
    assert np.abs(got - want).max() < 1e-8 * np.abs(want).max()
    terms = c[:, 0] * np.exp(1j * kv @ origin)
    p, grad, hess = field.derivatives(origin)
    assert abs(p - terms.sum()) < 1e-12 * np.abs(terms).sum()
    assert np.abs(grad - 1j * kv.T @ terms).max() < 1e-12 * np.abs(kv).max() * np.abs(terms).sum()
    want_h = -(kv.T * terms) @ kv
    assert np.abs(hess - want_h).max() < 1e-12 * np.abs(kv).max() ** 2 * np.abs(terms).sum()
