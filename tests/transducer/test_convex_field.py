"""Field prediction of a convex-array virtual transducer (issue 16): every element on the
cylinder, facing its own normal (``VirtualTransducer.array``), checked in absolute Pa
against the twin's true field (its own quadrature of the exact curved elements and
dense Rayleigh sum) and against a Gauss–Legendre quadrature built from the geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from _shared import gaussian_ir
from holoprobe.errors import InputError
from holoprobe.geometry import ArrayGeometry, Medium
from holoprobe.measurement import DriveSignal
from holoprobe.simulate import ArrayModel, simulate_field
from holoprobe.transducer import TransmitSetting, VirtualTransducer, predict_field

MEDIUM = Medium(998.0, 1481.0)
FS = 50e6
N, PITCH, WIDTH, HEIGHT, R, F = 12, 0.5e-3, 0.45e-3, 3e-3, 8e-3, 20e-3


@pytest.fixture(scope="module")
def pair():
    ir = gaussian_ir(FS, 3e6, 0.2e-6, 0.8e-6) * 1e10
    model = ArrayModel(element_count=N, pitch=PITCH, element_width=WIDTH,
                       element_height=HEIGHT, lens_focus=F, transmit_ir=ir, receive_ir=ir,
                       ir_sampling_rate=FS, drive=DriveSignal([1.0, 1.0], FS),
                       radius_of_curvature=R, center_frequency=3e6)
    model = model.with_element_variation(amplitude_rms=0.1, delay_rms=0.0, seed=3)
    vt = VirtualTransducer(
        element_count=N, pitch=PITCH, element_width=WIDTH, element_height=HEIGHT,
        transmit_impulse_response=ir, transmit_sampling_rate=FS, lens_focus=F,
        medium=MEDIUM, array=ArrayGeometry.convex(N, PITCH, R, WIDTH, HEIGHT),
        element_transmit_amplitude=np.asarray(model.apodization))
    return model, vt


def _points(seed: int, n: int) -> np.ndarray:
    """Targets in front of the arc, some far off its axis (up to 50° from the apex)."""
    rng = np.random.default_rng(seed)
    ang = rng.uniform(-0.9, 0.9, n)
    rad = rng.uniform(4e-3, 12e-3, n)
    return np.c_[(R + rad) * np.sin(ang), rng.uniform(-1.5e-3, 1.5e-3, n),
                 (R + rad) * np.cos(ang) - R]


@pytest.mark.parametrize("kind", ["focused", "plane_wave"])
def test_convex_field_matches_the_twin_in_absolute_pressure(pair, kind):
    """Time series (Pa) of the model, whose elements are strips of its cylinder sampled
    at λ/4 of its band, against the twin's true field (finer midpoint cells of the bent
    face, its own delay and record code) for the same transmit."""
    model, vt = pair
    setting = (TransmitSetting.focused((2e-3, 0.0, 9e-3), drive=model.drive)
               if kind == "focused" else
               TransmitSetting.plane_wave(math.radians(10.0), drive=model.drive))
    apod, tau = vt.transmit_weights(setting)
    twin = model.replace(delays=tau, apodization=apod)
    pts = _points(1, 8)
    t, expected = simulate_field(twin, pts, medium=MEDIUM, sampling_rate=100e6,
                                 band=(0.2e6, 7e6), points_per_wavelength=10.0)
    got = predict_field(vt, setting, pts, sampling_rate=100e6, start_time=float(t[0]),
                        n_samples=t.size, band_threshold_db=-60.0,
                        points_per_wavelength=6.0)
    assert got.method == "lattice" or got.method == "element"
    scale = np.abs(expected).max(axis=1)
    err = np.abs(got.pressure - expected).max(axis=1) / scale
    assert err.max() < 0.02, err
    np.testing.assert_allclose(got.peak_positive, expected.max(axis=1), rtol=0.01)


def test_convex_field_matches_a_gauss_quadrature_of_the_curved_faces(pair):
    """Spectra at three frequencies against the dense Rayleigh sum over Gauss–Legendre
    cells of the exact faces (``ArrayGeometry.surface``), delays and lens written here."""
    from holoprobe.propagation import rayleigh_integral
    from holoprobe.signal import continuous_spectrum

    model, vt = pair
    setting = TransmitSetting.focused((-1.5e-3, 0.0, 10e-3), drive=model.drive)
    apod, tau_el = vt.transmit_weights(setting)
    geo = ArrayGeometry.convex(N, PITCH, R, WIDTH, HEIGHT)
    src = geo.surface(0.05e-3, layout="gauss", order=3)
    y = src.points[:, 1]
    c0 = MEDIUM.sound_speed
    tau = (math.hypot(HEIGHT / 2, F) - np.hypot(y, F)) / c0 + tau_el[src.element]
    f = np.array([2.0e6, 3.0e6, 4.0e6])
    u = (continuous_spectrum(model.transmit_ir, FS, f)
         * continuous_spectrum(model.drive.voltage, FS, f) / MEDIUM.impedance)
    v = u[None, :] * np.exp(2j * np.pi * np.outer(tau, f)) * apod[src.element][:, None]
    pts = _points(2, 6)
    from holoprobe.geometry import Surface

    ref = rayleigh_integral(v, src, Surface(pts, np.tile([0, 0, 1.0], (6, 1)), np.ones(6)),
                            f, MEDIUM, kernel="fwd_vp", backend="numpy")
    n, fs = 5000, 100e6  # the three frequencies fall on bins
    got = predict_field(vt, setting, pts, sampling_rate=fs, start_time=0.0, n_samples=n,
                        band_threshold_db=-80.0, points_per_wavelength=8.0)
    spec = np.conj(np.fft.rfft(got.pressure, axis=-1))[:, np.round(f * n / fs).astype(int)] / fs
    assert np.abs(spec - ref).max() / np.abs(ref).max() < 3e-3


def test_convex_model_checks_and_refuses_the_angular_spectrum(pair):
    model, vt = pair
    assert vt.is_curved
    c, u, v, nrm = vt.element_frames()
    np.testing.assert_allclose(np.einsum("ij,ij->i", u, nrm), 0.0, atol=1e-15)
    np.testing.assert_allclose(v, np.tile([0.0, 1.0, 0.0], (N, 1)), atol=1e-15)
    np.testing.assert_allclose(c[:, 2], R * (np.cos((np.arange(N) - 5.5) * PITCH / R) - 1))
    from holoprobe.geometry import PlaneGrid, Pose

    plane = PlaneGrid.centered(4, 4, 0.5e-3, 0.5e-3, Pose(origin=(0.0, 0.0, 5e-3)))
    with pytest.raises(InputError, match="flat face"):
        predict_field(vt, TransmitSetting(drive=model.drive), plane, method="angular_spectrum")
    flipped = ArrayGeometry(vt.array.positions, -vt.array.normals,
                            vt.array.width_directions, WIDTH, HEIGHT, kind="convex",
                            radius_of_curvature=R)
    with pytest.raises(InputError, match="normal"):
        vt.replace(array=flipped)


def test_convex_rf_matches_a_quadrature_of_the_curved_faces(pair):
    """Per-element RF spectra (absolute, receive units) of a point scatterer against the
    chain written out here on Gauss–Legendre cells of the exact faces: transmit field
    at the scatterer, spherical re-radiation, the lens-delayed average over each curved
    element face, the receive IR (the model's transmit element map applies)."""
    from holoprobe.geometry import Surface
    from holoprobe.propagation import rayleigh_integral
    from holoprobe.signal import continuous_spectrum
    from holoprobe.transducer import simulate_rf

    model, vt = pair
    vt = vt.replace(receive_impulse_response=model.receive_ir, receive_sampling_rate=FS)
    setting = TransmitSetting.focused((1e-3, 0.0, 9e-3), drive=model.drive)
    apod, tau_el = vt.transmit_weights(setting)
    scat, amp = np.array([[1.2e-3, 0.3e-3, 8e-3]]), 1e-4
    n, fs = 5000, 100e6
    rf = simulate_rf(vt, setting, scat, [amp], sampling_rate=fs, n_samples=n,
                     band_threshold_db=-80.0, points_per_wavelength=8.0)
    f = np.array([2.0e6, 3.0e6, 4.0e6])
    got = np.conj(np.fft.rfft(rf, axis=-1))[:, np.round(f * n / fs).astype(int)] / fs
    geo = ArrayGeometry.convex(N, PITCH, R, WIDTH, HEIGHT)
    src = geo.surface(0.05e-3, layout="gauss", order=3)
    c0, k = MEDIUM.sound_speed, 2 * np.pi * f / MEDIUM.sound_speed
    lens = (math.hypot(HEIGHT / 2, F) - np.hypot(src.points[:, 1], F)) / c0
    u = (continuous_spectrum(model.transmit_ir, FS, f)
         * continuous_spectrum(model.drive.voltage, FS, f) / MEDIUM.impedance)
    v = (u[None, :] * np.exp(2j * np.pi * np.outer(lens + tau_el[src.element], f))
         * apod[src.element][:, None])
    p_inc = rayleigh_integral(v, src, Surface(scat, [[0, 0, 1.0]], [1.0]), f, MEDIUM,
                              kernel="fwd_vp", backend="numpy")[0]
    d = np.linalg.norm(src.points - scat, axis=1)[:, None]
    p_face = amp * p_inc[None, :] * np.exp(1j * d * k) / d * np.exp(
        2j * np.pi * np.outer(lens, f))
    p_rx = np.stack([np.sum(src.weights[src.element == e, None] * p_face[src.element == e],
                            axis=0) / (WIDTH * HEIGHT) for e in range(N)])
    ref = p_rx * continuous_spectrum(model.receive_ir, FS, f)[None, :]
    assert np.abs(got - ref).max() < 5e-3 * np.abs(ref).max()


def test_convex_model_runs_through_the_rf_and_output_commands(pair, tmp_path, capsys):
    """virtual_transducer.h5 of a convex model keeps the arc; ``holoprobe rf``, ``output``
    (no thermal indices: the plane power integral needs a flat face) run."""
    import json

    from _shared import run_cli

    model, vt = pair
    vt = vt.replace(receive_impulse_response=model.receive_ir, receive_sampling_rate=FS)
    path = vt.save(tmp_path / "vt.h5")
    back = VirtualTransducer.load(path)
    np.testing.assert_allclose(back.array.normals, vt.array.normals)
    assert back.is_curved and back.array.radius_of_curvature == R
    tx = tmp_path / "tx.toml"
    tx.write_text('prf = 4000.0\n[delays]\nkind = "focused"\npoint = [0.001, 0.0, 0.009]\n'
                  '[drive]\nkind = "pulse"\namplitude = 1.0\nduration = 1e-7\n')
    scat = tmp_path / "scat.csv"
    scat.write_text("x,y,z,amplitude\n1.0,0.0,9.0,1e-4\n")
    code, _, err = run_cli(["rf", str(path), "--transmit", str(tx), "--scatterers",
                            str(scat), "--out", str(tmp_path / "rf"), "--quiet"], capsys)
    assert code == 0, err
    code, _, err = run_cli(["output", str(path), "--transmit", str(tx), "--out",
                            str(tmp_path / "out.json"), "--depth-mm", "4", "12"], capsys)
    assert code == 0, err
    summary = json.loads((tmp_path / "out.json").read_text())
    assert "convex" in summary["thermal_indices_note"]
    assert summary["mechanical_index"] > 0
