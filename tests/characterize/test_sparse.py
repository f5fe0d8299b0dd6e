"""Sparse 2-D matrix arrays (issue 16 stretch): a lattice with only some positions
populated, characterized on the present elements only.

One 8 × 8 lattice with 40 elements drawn by :func:`sparse_layout` (density-tapered random
layout), ±5 % element amplitudes, 3 ns rms delays, two dead elements, 40 dB noise and a
tilted scan plane; the twin integrates Gauss–Legendre rectangles with the dense Rayleigh
sum, the estimator uses the analytic rectangle spectrum on the angular spectrum (no
inverse crime).
"""

from __future__ import annotations

import numpy as np
import pytest

from _shared import acoustic_axis_angles, delay_and_correlation, element_ir_errors
from holoprobe.errors import InputError
from holoprobe.geometry import ArrayGeometry, Pose, sparse_layout

N, COUNT = 8, 40
DEAD = (3, 17)
POSE = Pose.from_degrees(0.8, -0.6, 1.2, (0.1e-3, -0.05e-3, 2e-3))


def _fill(mask, r0, r1):
    """Populated share of the lattice positions at r0 <= r < r1 (lattice units)."""
    ny, nx = mask.shape
    iy, ix = np.mgrid[:ny, :nx]
    r = np.hypot(ix - 0.5 * (nx - 1), iy - 0.5 * (ny - 1))
    ring = (r >= r0) & (r < r1)
    return mask[ring].mean()


def test_sparse_layouts_place_count_elements_with_the_density_taper():
    # spiral: density 1 − aρ² on the inscribed disc (ρ = r/16): mean over ρ² < 1/4 is
    # 1 − a/8, over 1/4 < ρ² < 1 it is 1 − 5a/8; untapered it is uniform
    for taper, want in ((0.6, (1 - 0.6 / 8) / (1 - 0.6 * 5 / 8)), (0.0, 1.0)):
        mask = sparse_layout(32, 32, 256, layout="spiral", taper=taper)
        assert mask.shape == (32, 32) and mask.sum() == 256
        assert _fill(mask, 0, 8) / _fill(mask, 8, 16) == pytest.approx(want, rel=0.12)
    # random: density 1 − aρ² with ρ over the half diagonal (≈ 1.34 expected, a = 0.9)
    mask = sparse_layout(32, 32, 256, layout="random", taper=0.9, seed=4)
    assert mask.sum() == 256 and _fill(mask, 0, 8) / _fill(mask, 8, 16) > 1.15
    np.testing.assert_array_equal(sparse_layout(16, 8, 50, layout="random", seed=1),
                                  sparse_layout(16, 8, 50, layout="random", seed=1))
    assert sparse_layout(4, 4, 16).all()  # every position when count = n_x n_y
    with pytest.raises(InputError, match="do not fit"):
        sparse_layout(4, 4, 17)
    with pytest.raises(InputError, match="layout"):
        sparse_layout(4, 4, 3, layout="poisson")


def test_matrix_geometry_with_holes_is_sparse():
    mask = sparse_layout(6, 5, 11, seed=0)
    geo = ArrayGeometry.matrix(6, 5, 0.3e-3, active=mask)
    assert geo.layout == "sparse" and geo.count == 11 and geo.grid_shape == (6, 5)
    iy, ix = np.nonzero(mask)  # row-major: the element order iy·n_x + ix
    np.testing.assert_array_equal(geo.grid_position, np.c_[ix, iy])
    np.testing.assert_allclose(geo.positions[:, 0], (ix - 2.5) * 0.3e-3)
    np.testing.assert_allclose(geo.positions[:, 1], (iy - 2.0) * 0.3e-3)
    assert ArrayGeometry.matrix(6, 5, 0.3e-3).layout == "full"
    assert ArrayGeometry.linear(4, 0.3e-3, 0.25e-3, 5e-3).layout == "linear"


@pytest.fixture(scope="module")
def twin():
    from holoprobe.simulate import ArrayModel, simulate_scan

    mask = sparse_layout(N, N, COUNT, layout="random", seed=3)
    model = ArrayModel.matrix(N, active=mask).with_element_variation(
        amplitude_rms=0.05, delay_rms=3e-9, dead=DEAD, seed=1)
    half = 0.5 * N * 0.3e-3 + 3e-3
    scan, truth = simulate_scan(model, pose=POSE, size=(2 * half, 2 * half),
                                step=(0.15e-3, 0.15e-3), sampling_rate=40e6, n_samples=512,
                                snr_db=40.0, seed=2, calibration=None,
                                points_per_wavelength=2)
    return model, scan, truth


@pytest.fixture(scope="module")
def run(twin):
    from holoprobe.workflow import characterize

    return characterize(twin[1])


def test_sparse_pose_element_map_and_absolute_transmit_ir(twin, run):
    from holoprobe.signal import continuous_spectrum

    model, scan, truth = twin
    assert model.array.layout == "sparse" and model.name == f"sparse-{COUNT}of{N}x{N}"
    tx = run.transmit
    expected = acoustic_axis_angles(model, POSE, scan.medium.sound_speed)
    err = np.abs(np.array(tx.pose.angles_deg) - np.array(expected))
    u = np.degrees([tx.uncertainties[k] for k in ("theta_x", "theta_y", "theta_z")])
    print("angle errors (deg)", err, "σ", u)
    assert err[0] <= 0.01 and err[1] <= 0.01 and np.all(err <= 3 * u)
    # the map holds the present elements only, in the file's order; dead ones found
    m = tx.element_map
    assert m.count == COUNT and m.grid_shape == (N, N) and m.layout == "sparse"
    np.testing.assert_array_equal(m.grid_position, model.array.grid_position)
    assert m.dead == DEAD
    amp = np.asarray(model.apodization)
    live = amp > 0
    a_err = m.relative_amplitude[live] - amp[live] / amp[live].mean()
    print("amplitude errors: rms", np.sqrt(np.mean(a_err**2)), "max", np.abs(a_err).max())
    assert np.abs(a_err).max() <= 0.03
    assert np.all(np.abs(a_err) <= 3 * m.amplitude_uncertainty[live])
    grid = m.amplitude_grid()
    holes = ~sparse_layout(N, N, COUNT, layout="random", seed=3)
    assert np.all(np.isnan(grid[holes])) and np.all(np.isfinite(grid[~holes]))
    # the transmit IR in absolute units: the mean over the present elements, not over
    # the lattice's envelope (which would read it 40/64 low)
    ir = tx.impulse_response
    _, corr = delay_and_correlation(ir.ir, truth.arrays["transmit_ir"], ir.sampling_rate)
    f = np.linspace(2.4e6, 3.6e6, 7)
    ratio = (np.abs(continuous_spectrum(ir.ir, ir.sampling_rate, f))
             / np.abs(continuous_spectrum(truth.arrays["transmit_ir"], model.ir_sampling_rate,
                                          f)))
    print("IR correlation", corr, "in-band ratio", ratio)
    assert corr >= 0.995
    # (the matrix path's in-band shape: noise-free, this twin and the full 8 × 8 one both
    # read −2.6…−2.9 % at 3.4 MHz; the 40 dB noise adds ±1 %)
    np.testing.assert_allclose(ratio, 1.0, atol=0.035)


def test_sparse_per_element_transmit_impulse_responses(twin, run):
    """The present elements' IRs against the twin's: correlation, timing, absolute
    in-band amplitude (the holes have no IR: the model has only the present elements)."""
    model, _, truth = twin
    corrs, lags, gains = element_ir_errors(model, truth, run.virtual_transducer)
    assert len(corrs) == COUNT - len(DEAD)
    assert np.min(corrs) >= 0.995
    assert np.std(lags) <= 1e-9
    np.testing.assert_allclose(gains, 1.0, atol=0.06)  # amplitude (≤ 2.4 %) × mean IR


def test_sparse_summary_report_and_virtual_transducer(run, tmp_path):
    from matplotlib.collections import PolyCollection

    from holoprobe.transducer import VirtualTransducer

    el = run.summary["elements"]
    assert el["layout"] == "sparse" and el["count"] == COUNT and el["grid_shape"] == [N, N]
    assert len(el["positions"]) == len(el["grid_position"]) == COUNT
    figs = dict(run.figures())["Element grid (matrix array)"]
    ax = figs[0].axes[0]
    cells, holes = [c for c in ax.collections if isinstance(c, PolyCollection)]
    assert len(cells.get_paths()) == COUNT  # one coloured cell per present element
    assert cells.get_array() is not None and holes.get_array() is None
    # the empty positions, outlined, at their lattice places (pitch 0.3 mm from the
    # present elements' centres: each hole's nearest element is a multiple of the pitch)
    assert len(holes.get_paths()) == N * N - COUNT and "sparse" in ax.get_title()
    hole_c = np.array([p.vertices[:4].mean(axis=0) for p in holes.get_paths()])
    cell_c = np.array([p.vertices[:4].mean(axis=0) for p in cells.get_paths()])
    steps = (hole_c[:, None, :] - cell_c[None]) / (el["pitch"] * 1e3)
    nearest = steps[np.arange(len(hole_c)), np.argmin(np.abs(steps).sum(axis=2), axis=1)]
    np.testing.assert_allclose(nearest, np.round(nearest), atol=0.05)  # θz ≈ 1.2° residue
    vt = run.virtual_transducer
    back = VirtualTransducer.load(vt.save(tmp_path / "vt.h5"))
    assert back.array.layout == "sparse"
    np.testing.assert_array_equal(back.array.grid_position, vt.array.grid_position)
    np.testing.assert_array_equal(back.element_centers(), vt.element_centers())


def test_cli_sparse_layout_from_an_element_csv_in_channel_order(twin, tmp_path, capsys):
    """``--array sparse --grid 8x8 --elements FILE`` on a file described only as a row
    of 40 elements; the CSV lists the elements in a shuffled channel order: the map
    follows it (the dead elements found under their channel numbers)."""
    import dataclasses
    import json

    from _shared import run_cli
    from holoprobe.io import write_scan
    from holoprobe.measurement import ProbeInfo

    model, scan, _ = twin
    flat = ProbeInfo(COUNT, 0.3e-3, 0.27e-3, 0.27e-3, 3e6)
    write_scan(tmp_path / "no_layout.h5", dataclasses.replace(scan, probe=flat))
    order = np.random.default_rng(0).permutation(COUNT)  # channel c is element order[c]
    gp = model.array.grid_position[order]
    (tmp_path / "elements.csv").write_text(
        "# sparse 8x8 test probe\nix,iy\n" + "".join(f"{a},{b}\n" for a, b in gp))
    out = tmp_path / "out"
    args = ["characterize", str(tmp_path / "no_layout.h5"), "--out", str(out), "--quiet",
            "--array", "sparse", "--grid", "8x8", "--pitch", "0.0003", "--no-report"]
    code, _, err = run_cli([*args, "--elements", str(tmp_path / "elements.csv")], capsys)
    assert code == 0, err
    el = json.loads((out / "summary.json").read_text())["elements"]
    assert el["layout"] == "sparse" and el["grid_position"] == gp.tolist()
    assert el["dead"] == sorted(int(np.flatnonzero(order == d)[0]) for d in DEAD)
    # a file without a sparse description and no --elements; a position off the grid
    code, _, err = run_cli([*args[:5], "--array", "sparse", "--no-report", "--overwrite"], capsys)
    assert code == 2 and "not a sparse matrix" in err
    (tmp_path / "bad.csv").write_text("ix,iy\n0,0\n8,1\n")
    code, _, err = run_cli([*args, "--overwrite", "--elements", str(tmp_path / "bad.csv")],
                           capsys)
    assert code == 2 and "outside the 8 x 8 grid" in err and "bad.csv" in err
    # the element's data row and position as plain numbers (review: numpy reprs)
    assert "data row 2" in err and "(8, 1)" in err and "np." not in err
    (tmp_path / "dup.csv").write_text("ix,iy\n0,0\n1,1\n0,0\n")
    code, _, err = run_cli([*args, "--overwrite", "--elements", str(tmp_path / "dup.csv")],
                           capsys)
    assert code == 2 and "dup.csv" in err and "data rows 1 and 3" in err and "(0, 0)" in err
    (tmp_path / "frac.csv").write_text("ix,iy\n0,0\n1.5,1\n")
    code, _, err = run_cli([*args, "--overwrite", "--elements", str(tmp_path / "frac.csv")],
                           capsys)
    assert code == 2 and "frac.csv" in err and "ix" in err and "data row 2: 1.5" in err
    # --elements without --array sparse was ignored without a word (review)
    code, _, err = run_cli([*args[:5], "--grid", "8x8", "--no-report", "--overwrite",
                            "--elements", str(tmp_path / "elements.csv")], capsys)
    assert code == 2 and "--elements" in err and "--array sparse" in err
