"""The convex-array twin: the curved face against an independently built quadrature,
the flat limit, and the truth it records."""

from __future__ import annotations

import math

import numpy as np
import pytest

from _shared import gaussian_ir
from holoprobe.errors import InputError
from holoprobe.geometry import ArrayGeometry, Medium, PlaneGrid, Pose
from holoprobe.measurement import DriveSignal
from holoprobe.simulate import ArrayModel, simulate_scan

MEDIUM = Medium()
FS_IR = 50e6
IR = gaussian_ir(FS_IR, 1.5e6, 0.3e-6, 2.0e-6)


def _model(**kw) -> ArrayModel:
    base = dict(element_count=3, pitch=1.2e-3, element_width=1.0e-3, element_height=3e-3,
                lens_focus=0.03, transmit_ir=IR, receive_ir=IR, ir_sampling_rate=FS_IR,
                drive=DriveSignal([1.0], FS_IR), radius_of_curvature=8e-3,
                apodization=[1.0, 0.5, 0.8], delays=[0.0, 0.2e-6, -0.1e-6])
    base.update(kw)
    return ArrayModel(**base)


def _record_spectrum(data: np.ndarray, fs: float, f: float) -> np.ndarray:
    n = data.shape[-1]
    k = round(f * n / fs)
    return np.conj(np.fft.rfft(data, axis=-1)[..., k]) / fs


def test_convex_scan_agrees_with_a_gauss_quadrature_of_the_exact_curved_elements():
    from holoprobe.propagation import rayleigh_integral
    from holoprobe.signal import continuous_spectrum

    model = _model()  # strongly curved: the outer elements face ±8.6° off the axis
    pose = Pose.from_degrees(2.0, -4.0, 7.0, (0.3e-3, -0.2e-3, 5e-3))
    grid = PlaneGrid.centered(6, 4, 1.2e-3, 1.5e-3, pose)
    fs, n = 20e6, 400
    scan, truth = simulate_scan(model, grid=grid, sampling_rate=fs, n_samples=n,
                                calibration=None, snr_db=None, dtype=np.float64)
    # independent source: Gauss–Legendre cells on the faces built by ArrayGeometry
    geo = ArrayGeometry.convex(3, 1.2e-3, 8e-3, 1.0e-3, 3e-3)
    src = geo.surface(0.08e-3, layout="gauss", order=3)
    y = src.points[:, 1]
    tau = (math.hypot(1.5e-3, 0.03) - np.hypot(y, 0.03)) / MEDIUM.sound_speed \
        + np.array([0.0, 0.2e-6, -0.1e-6])[src.element]
    f = np.array([1.0e6, 1.5e6, 2.0e6])
    u = model.surface_velocity(MEDIUM)
    v = continuous_spectrum(u, FS_IR, f)[None, :] * np.exp(2j * np.pi * np.outer(tau, f)) \
        * np.array([1.0, 0.5, 0.8])[src.element][:, None]
    ref = rayleigh_integral(v, src, grid.to_surface(), f, MEDIUM, kernel="fwd_vp",
                            backend="numpy")
    got = np.stack([_record_spectrum(scan.data.reshape(-1, n), fs, fi) for fi in f], -1)
    assert np.abs(got - ref).max() / np.abs(ref).max() < 5e-3
    # the truth holds the geometry
    p = truth.parameters["probe"]
    assert p["geometry"] == "convex" and p["radius_of_curvature_m"] == 8e-3
    assert np.allclose(p["element_angles_deg"], np.degrees([-0.15, 0.0, 0.15]))
    assert np.allclose(truth.arrays["element_positions"], geo.positions)
    assert np.allclose(truth.arrays["element_normals"], geo.normals)


def test_a_very_large_radius_gives_the_flat_array():
    grid = PlaneGrid.centered(5, 3, 1e-3, 1e-3, Pose(origin=(0.0, 0.0, 4e-3)))
    kw = dict(grid=grid, sampling_rate=20e6, n_samples=300, calibration=None, snr_db=None,
              dtype=np.float64)
    curved, _ = simulate_scan(_model(radius_of_curvature=1e4), **kw)
    flat, _ = simulate_scan(_model(radius_of_curvature=None), **kw)
    assert np.abs(curved.data - flat.data).max() < 1e-5 * np.abs(flat.data).max()


def test_convex_model_rejects_an_arc_longer_than_the_circle():
    with pytest.raises(InputError, match="radius_of_curvature"):
        _model(radius_of_curvature=0.5e-3)
    with pytest.raises(InputError, match="radius_of_curvature"):
        _model(radius_of_curvature=-1.0)
