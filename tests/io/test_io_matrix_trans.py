"""2-D matrix arrays in the Verasonics ``Trans`` struct (issue 16): ``ElementPos`` with
distinct y on a flat grid reads as ``ProbeInfo.array`` of kind "matrix"."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.io
from test_io_reference import _toolkit_files
from test_io_support import make_scan

from holoprobe.errors import InputError
from holoprobe.geometry import ArrayGeometry
from holoprobe.io import read_reference_scan, write_reference_scan


def test_matrix_round_trip_through_the_reference_files(tmp_path):
    grid = ArrayGeometry.matrix(4, 3, 0.3e-3, 0.35e-3, 0.27e-3, 0.32e-3)
    scan = make_scan()
    probe = dataclasses.replace(scan.probe, element_count=12, pitch=0.3e-3,
                                element_width=0.27e-3, element_height=0.32e-3, array=grid)
    write_reference_scan(tmp_path, dataclasses.replace(scan, probe=probe))
    got = read_reference_scan(tmp_path).probe
    assert got.is_matrix and got.array.grid_shape == (4, 3)
    np.testing.assert_allclose(got.array.positions, grid.positions, atol=1e-12)
    np.testing.assert_array_equal(got.array.grid_position, grid.grid_position)
    assert got.array.pitch == pytest.approx((0.3e-3, 0.35e-3))
    assert got.element_height == pytest.approx(0.32e-3)


def test_verasonics_element_positions_with_distinct_y_are_a_matrix(tmp_path):
    _toolkit_files(tmp_path)
    lam_mm = 1540 / 3e6 * 1e3
    # 3 × 2 grid, x fastest, not centred on 0 (offset 1 mm), one element missing
    ix, iy = np.meshgrid(np.arange(3), np.arange(2))
    keep = np.ones(6, bool)
    keep[4] = False
    x = (ix.ravel()[keep] * 0.3 + 1.0) / lam_mm
    y = (iy.ravel()[keep] * 0.4) / lam_mm
    pos = np.zeros((5, 5))
    pos[:, 0], pos[:, 1] = x, y
    trans = {"numelements": 5.0, "frequency": 3.0, "spacingMm": 0.3, "spacing": 0.3 / lam_mm,
             "elementWidth": 0.27 / lam_mm, "elevationApertureMm": 0.7, "ElementPos": pos}
    scipy.io.savemat(tmp_path / "TransmitData.mat", {"Trans": trans})
    probe = read_reference_scan(tmp_path).probe
    a = probe.array
    assert a.kind == "matrix" and a.grid_shape == (3, 2)
    np.testing.assert_array_equal(a.grid_position, np.c_[ix.ravel(), iy.ravel()][keep])
    assert a.pitch == pytest.approx((0.3e-3, 0.4e-3))
    # centred on the full grid; the whole-aperture 0.7 mm became a 0.36 mm element
    np.testing.assert_allclose(a.positions[0], [-0.3e-3, -0.2e-3, 0.0], atol=1e-12)
    assert probe.element_height == pytest.approx(0.27e-3 * 0.4 / 0.3)
    # off-grid positions are refused, naming the field
    pos[1, 0] += 0.05 / lam_mm
    trans["ElementPos"] = pos
    scipy.io.savemat(tmp_path / "TransmitData.mat", {"Trans": trans})
    with pytest.raises(InputError, match="ElementPos"):
        read_reference_scan(tmp_path)


def test_sparse_lattice_round_trip_through_trans_element_positions(tmp_path):
    """A sparse lattice (20 of 8 × 8 positions) is written as ``Trans.ElementPos`` and
    read back as a matrix with holes (layout "sparse"): same element order, same
    spacing, positions centred on the populated lattice's bounding box."""
    from holoprobe.geometry import sparse_layout

    mask = sparse_layout(8, 8, 20, layout="spiral", taper=0.5)
    grid = ArrayGeometry.matrix(8, 8, 0.3e-3, None, 0.27e-3, 0.27e-3, active=mask)
    scan = make_scan()
    probe = dataclasses.replace(scan.probe, element_count=grid.count, pitch=0.3e-3,
                                element_width=0.27e-3, element_height=0.27e-3, array=grid)
    write_reference_scan(tmp_path, dataclasses.replace(scan, probe=probe))
    got = read_reference_scan(tmp_path).probe.array
    assert got.layout == "sparse" and got.count == 20
    lo = grid.grid_position.min(axis=0)
    np.testing.assert_array_equal(got.grid_position, grid.grid_position - lo)
    assert got.grid_shape == tuple(int(v) for v in np.ptp(grid.grid_position, axis=0) + 1)
    np.testing.assert_allclose(np.diff(got.positions, axis=0), np.diff(grid.positions, axis=0),
                               atol=1e-12)
    np.testing.assert_allclose(got.widths, 0.27e-3)
    np.testing.assert_allclose(got.heights, 0.27e-3)
