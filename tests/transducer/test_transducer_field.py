"""Surface velocity and field prediction of the virtual transducer.

Checked against what the code under test does not compute: a direct time-domain
convolution, the exact lens formula, the independent time-domain Rayleigh
integral (delay-and-sum) on a finer source sampling, the analytic far field of a
small element, and the geometry of a focused beam.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from holoprobe.geometry import Medium, PlaneGrid, Pose, Surface
from holoprobe.propagation import rayleigh_time_domain
from holoprobe.signal import to_time
from holoprobe.transducer import (
    TransmitSetting,
    VirtualTransducer,
    burst,
    predict_field,
    rectangular_pulse,
    surface_velocity,
)

FS = 100e6
MEDIUM = Medium()
F0 = 2.0e6
SIGMA = 0.35e-6
TC = 1.0e-6


def _ir(t):
    """Gaussian-modulated sine, Pa/(V*s), and its time derivative (closed form)."""
    a = 1e11
    s = (t - TC) / SIGMA
    g = np.exp(-(s**2))
    h = a * g * np.sin(2 * np.pi * F0 * (t - TC))
    dh = a * g * (2 * np.pi * F0 * np.cos(2 * np.pi * F0 * (t - TC))
                  - 2 * s / SIGMA * np.sin(2 * np.pi * F0 * (t - TC)))
    return h, dh


def _model(n=1, width=0.25e-3, height=1e-3, focus=math.inf, pitch=0.3e-3):
    t = np.arange(400) / FS
    h, _ = _ir(t)
    return VirtualTransducer(element_count=n, pitch=pitch, element_width=width,
                             element_height=height, transmit_impulse_response=h,
                             transmit_sampling_rate=FS, lens_focus=focus, medium=MEDIUM)


def test_single_element_velocity_is_ir_convolved_with_drive_over_rho_c():
    vt = _model()
    t = np.arange(400) / FS
    h = vt.transmit_impulse_response - vt.transmit_impulse_response.mean()  # zero DC
    vt = vt.replace(transmit_impulse_response=h)
    drive = burst(1.5e6, 2, 10.0, sampling_rate=FS)
    tx = TransmitSetting(drive)
    n = 1024
    f = np.fft.rfftfreq(n, 1 / FS)
    surface, v = surface_velocity(vt, tx, f[1:], lens=False)
    assert surface.area == pytest.approx(0.25e-3 * 1e-3)
    # one element, no lens: the same velocity everywhere
    np.testing.assert_allclose(v, np.broadcast_to(v[:1], v.shape), rtol=1e-12)
    u = to_time(np.concatenate([[0.0], v[0]]) * FS, n)
    expected = np.convolve(h, drive.voltage)[:n] / FS / MEDIUM.impedance
    expected = np.pad(expected, (0, n - expected.size))
    assert np.max(np.abs(u - expected)) < 1e-10 * np.max(np.abs(expected))
    assert t.size == 400


def test_lens_delays_on_the_surface_follow_the_exact_lens_formula():
    focus, height = 0.05, 8e-3
    vt = _model(focus=focus, height=height)
    tx = TransmitSetting(rectangular_pulse(1.0, 1 / FS, sampling_rate=FS))
    f = np.array([1.0e6, 2.0e6])
    surface, v = surface_velocity(vt, tx, f)
    y = surface.points[:, 1]
    tau = (math.sqrt((height / 2) ** 2 + focus**2) - np.sqrt(y**2 + focus**2)) / 1481.0
    phase = np.angle(v[:, 0] / v[np.argmax(np.abs(y)), 0])
    expected = np.angle(np.exp(2j * np.pi * f[0] * (tau - tau[np.argmax(np.abs(y))])))
    np.testing.assert_allclose(phase, expected, atol=1e-9)
    assert tau.max() > 0.1 / f[0]  # the lens delay is a visible fraction of a period
    # sub-sampling is at most a quarter wavelength of the highest frequency
    dy = np.diff(np.unique(np.round(y, 12)))
    assert dy.max() <= 1481.0 / f.max() / 4 * (1 + 1e-9)


def test_on_axis_far_field_of_one_element_matches_the_analytic_derivative():
    vt = _model(width=0.25e-3, height=0.5e-3)
    amp = 5.0
    tx = TransmitSetting(rectangular_pulse(amp, 1 / FS, sampling_rate=FS))  # one sample
    r = 40e-3
    res = predict_field(vt, tx, [[0.0, 0.0, r]], sampling_rate=FS, band_threshold_db=-100.0)
    # far field of a baffled piston: p = ρ0 A/(2π R) du/dt(t − R/c0), u = h ⊛ E/(ρ0 c0)
    area = 0.25e-3 * 0.5e-3
    _, dh = _ir(res.time - r / 1481.0)
    expected = MEDIUM.density * area / (2 * np.pi * r) * (amp / FS) * dh / MEDIUM.impedance
    err = np.max(np.abs(res.pressure[0] - expected)) / np.max(np.abs(expected))
    assert err < 0.01


def _fine_source(vt, tx, step):
    """Sub-element points, weights and delays built here, independently, at `step`."""
    c0 = vt.medium.sound_speed
    nx = math.ceil(vt.element_width / step)
    ny = math.ceil(vt.element_height / step)
    ux = (np.arange(nx) + 0.5) / nx * vt.element_width - vt.element_width / 2
    uy = (np.arange(ny) + 0.5) / ny * vt.element_height - vt.element_height / 2
    xe = (np.arange(vt.element_count) - (vt.element_count - 1) / 2) * vt.pitch
    fx, fz = tx.delays.point[0], tx.delays.point[2]
    r = np.hypot(xe - fx, fz)
    tau_el = (r.max() - r) / c0
    a, f = vt.element_height / 2, vt.lens_focus
    tau_lens = (math.sqrt(a * a + f * f) - np.sqrt(uy**2 + f * f)) / c0
    X, Y = np.meshgrid(xe[:, None] + ux[None, :], uy, indexing="ij")
    pts = np.stack([X.ravel(), np.tile(uy, X.shape[0]), np.zeros(X.size)], axis=-1)
    assert np.allclose(pts[:, 1], Y.ravel())
    delays = np.repeat(tau_el, nx * ny) + np.tile(tau_lens, vt.element_count * nx)
    src = Surface(pts, np.tile([0, 0, 1.0], (pts.shape[0], 1)),
                  np.full(pts.shape[0], vt.element_width / nx * vt.element_height / ny))
    return src, delays


def test_focused_array_with_lens_matches_time_domain_rayleigh_on_a_finer_source():
    vt = _model(n=8, height=3e-3, focus=0.02)
    tx = TransmitSetting.focused((1e-3, 0.0, 15e-3), drive=burst(2e6, 1, 10.0, sampling_rate=FS))
    targets = np.array([[1e-3, 0.0, 15e-3], [0.0, 0.5e-3, 8e-3], [-2e-3, 0.0, 20e-3]])
    res = predict_field(vt, tx, targets, sampling_rate=FS, band_threshold_db=-100.0)
    u = np.convolve(vt.transmit_impulse_response, tx.drive.voltage) / FS / MEDIUM.impedance
    src, delays = _fine_source(vt, tx, step=1481.0 / 8e6 / 8)
    tgt = Surface(targets, np.tile([0, 0, 1.0], (3, 1)), np.ones(3))
    ref = rayleigh_time_domain(u, src, tgt, FS, MEDIUM, delays=delays,
                               n_samples=res.time.size, start_time=res.time[0])
    err = np.max(np.abs(res.pressure - ref), axis=1) / np.max(np.abs(ref), axis=1)
    assert np.all(err < 0.01), err


def test_focused_beam_peaks_at_its_lateral_focus_and_near_its_depth():
    vt = _model(n=32, height=2e-3)
    focus = np.array([2e-3, 0.0, 15e-3])
    tx = TransmitSetting.focused(focus, drive=burst(2e6, 2, 10.0, sampling_rate=FS))
    x = np.linspace(-4e-3, 8e-3, 49)
    lateral = np.stack([x, np.zeros_like(x), np.full_like(x, 15e-3)], axis=-1)
    pk = predict_field(vt, tx, lateral).peak_positive
    assert abs(x[np.argmax(pk)] - 2e-3) <= 0.25e-3
    z = np.linspace(5e-3, 30e-3, 51)
    axial = np.stack([np.full_like(z, 2e-3), np.zeros_like(z), z], axis=-1)
    pz = predict_field(vt, tx, axial).peak_positive
    # aperture 9.6 mm, λ = 0.74 mm: a weak focal shift towards the probe is expected
    assert 0.75 * 15e-3 <= z[np.argmax(pz)] <= 1.05 * 15e-3


def test_angular_spectrum_path_agrees_with_rayleigh_on_a_parallel_plane():
    vt = _model(n=8, height=3e-3, focus=0.03)
    tx = TransmitSetting.focused((0.0, 0.0, 10e-3), drive=burst(2e6, 2, 10.0, sampling_rate=FS))
    plane = PlaneGrid.centered(33, 21, 0.2e-3, pose=Pose(origin=(0.0, 0.0, 8e-3)))
    a = predict_field(vt, tx, plane, method="angular_spectrum", sampling_rate=FS)
    b = predict_field(vt, tx, plane, method="rayleigh", sampling_rate=FS)
    assert a.time.shape == b.time.shape
    err = np.max(np.abs(a.pressure - b.pressure)) / np.max(np.abs(b.pressure))
    assert err < 0.02, err  # measured 1.3 % (padding rule of _angular_spectrum_field)
