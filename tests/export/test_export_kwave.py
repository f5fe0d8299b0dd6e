"""k-wave-python equivalent sources: signals and mask geometry (NumPy), kwave parts if present."""

from __future__ import annotations

import math

import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.export import (
    kwave_element_strips,
    kwave_grid_mask,
    kwave_source_signals,
)
from holoprobe.geometry import Medium
from holoprobe.lens import lens_delays
from holoprobe.measurement import DriveSignal
from holoprobe.signal import to_frequency
from holoprobe.transducer import TransmitSetting, VirtualTransducer

FS = 250e6


def _vt(n=4, focus=math.inf):
    t = np.arange(200) / FS
    ir = 1e11 * np.exp(-((t - 0.3e-6) ** 2) / (2 * 0.12e-6**2)) * np.sin(
        2 * np.pi * 2.5e6 * (t - 0.3e-6))
    return VirtualTransducer(element_count=n, pitch=0.3e-3, element_width=0.25e-3,
                             element_height=2e-3, transmit_impulse_response=ir,
                             transmit_sampling_rate=FS, lens_focus=focus,
                             medium=Medium(998.0, 1481.0))


def _drive():
    v = np.zeros(40)
    v[3:6] = 30.0  # a 12 ns, 30 V pulse
    return DriveSignal(v, FS)


def test_monopole_signal_is_rho_c_times_velocity_by_direct_convolution():
    vt = _vt(n=1)
    tx = TransmitSetting(_drive())
    kw_medium = Medium(1000.0, 1500.0)
    nt = 300
    sig = kwave_source_signals(vt, tx, 1 / FS, nt, representation="monopole",
                               medium=kw_medium)
    # u = (h_T ⊛ E_T)/(ρ0c0)_vt  (convolution integral: sum / fs)
    u = np.zeros(nt)
    conv = np.convolve(vt.transmit_impulse_response, _drive().voltage)
    u[:conv.size] = conv / FS / (998 * 1481)
    assert sig.shape == (1, nt)
    np.testing.assert_allclose(sig[0], kw_medium.impedance * u,
                               atol=1e-9 * np.abs(kw_medium.impedance * u).max())
    dip = kwave_source_signals(vt, tx, 1 / FS, nt, representation="dipole", medium=kw_medium)
    np.testing.assert_allclose(dip[0], u, atol=1e-9 * np.abs(u).max())


def test_strip_signals_carry_transmit_and_lens_delays():
    vt = _vt(n=3, focus=0.02)
    tx = TransmitSetting.focused((0.0, 0.0, 0.01), drive=_drive(), apodization=[1.0, 0.5, 1.0])
    dt, nt = 1 / FS, 600
    sig = kwave_source_signals(vt, tx, dt, nt, n_strips=4)
    ref = kwave_source_signals(_vt(n=1), TransmitSetting(_drive()), dt, nt)[0]
    strips = kwave_element_strips(vt, 4)
    tau_el = tx.element_delays(vt.element_centers(), 1481.0)
    v = strips["centers"][:4, 1]
    expected_lens = lens_delays(v, 0.02, 2e-3, 1481.0)
    np.testing.assert_allclose(strips["lens_delay"][:4], expected_lens, rtol=1e-12)
    # delay = phase slope against the undelayed element signal at 2.5 MHz
    f = np.fft.rfftfreq(4096, dt)
    k = int(np.argmin(np.abs(f - 2.5e6)))
    r = to_frequency(ref, n=4096)[k]
    for row in range(12):
        el = row // 4
        s = to_frequency(sig[row], n=4096)[k]
        ratio = s / r
        assert abs(ratio) == pytest.approx([1.0, 0.5, 1.0][el], rel=1e-4)
        tau = np.angle(ratio) / (2 * np.pi * f[k])
        assert tau == pytest.approx(tau_el[el] + expected_lens[row % 4], abs=1e-11)


def test_grid_mask_covers_element_footprints():
    vt = _vt(n=4)
    mask, element = kwave_grid_mask(vt, (8, 16, 31), (0.1e-3, 0.1e-3, 0.1e-3))
    # centres ±0.15, ±0.45 mm, half width 0.125 mm: y = 0.1, 0.2 mm etc. -> 2 per
    # element; |z| ≤ 1 mm -> 21 points
    assert mask.sum() == 4 * 2 * 21
    assert np.array_equal(np.flatnonzero(mask.any(axis=(1, 2))), [1])
    ys = (np.arange(16) - 8) * 0.1e-3
    rows = np.flatnonzero(mask[1].any(axis=1))
    np.testing.assert_allclose(ys[rows], [-0.5e-3, -0.4e-3, -0.2e-3, -0.1e-3,
                                          0.1e-3, 0.2e-3, 0.4e-3, 0.5e-3], atol=1e-12)
    # C order: y slowest, so labels come in blocks of 21
    np.testing.assert_array_equal(element, np.repeat([0, 0, 1, 1, 2, 2, 3, 3], 21))


def test_bad_representation_is_an_input_error():
    with pytest.raises(InputError, match="representation"):
        kwave_source_signals(_vt(), TransmitSetting(_drive()), 1e-8, 10,
                             representation="quadrupole")


def test_kwave_source_and_sensor_build_with_kwave():
    pytest.importorskip("kwave")  # optional extra; see docs/kwave.md
    from kwave.data import Vector
    from kwave.kgrid import kWaveGrid

    from holoprobe.export import kwave_element_pressure, kwave_sensor, kwave_source

    vt = _vt(n=4, focus=0.02)
    kgrid = kWaveGrid(Vector([24, 24, 40]), Vector([0.1e-3, 0.1e-3, 0.1e-3]))
    kgrid.setTime(50, 1 / FS)
    tx = TransmitSetting(_drive())
    src = kwave_source(vt, tx, kgrid, representation="monopole")
    assert src.p_mask.shape == (24, 24, 40) and src.p.shape == (int(src.p_mask.sum()), 50)
    dip = kwave_source(vt, tx, kgrid, representation="dipole")
    assert dip.ux.shape[1] == 50
    sensor, arr = kwave_sensor(vt, kgrid)
    data = np.ones((int(sensor.mask.sum()), 50))
    p = kwave_element_pressure(vt, kgrid, arr, data)
    assert p.shape == (4, 50)


def test_grid_source_points_carry_the_lens_delay_of_their_elevation():
    from holoprobe.export import kwave_grid_source

    vt = _vt(n=2, focus=0.02)
    tx = TransmitSetting(_drive())
    dt, nt = 1 / FS, 500
    mask, sig = kwave_grid_source(vt, tx, (4, 8, 21), (0.1e-3, 0.1e-3, 0.1e-3), dt, nt)
    assert sig.shape == (mask.sum(), nt)
    ref = kwave_source_signals(_vt(n=1), tx, dt, nt)[0]  # no lens, no delay
    z = np.broadcast_to(((np.arange(21) - 10) * 0.1e-3)[None, :], (8, 21))[mask[1]]
    f = np.fft.rfftfreq(4096, dt)
    k = int(np.argmin(np.abs(f - 2.5e6)))
    r = to_frequency(ref, n=4096)[k]
    for row in (0, 5, 10, 20):
        tau = np.angle(to_frequency(sig[row], n=4096)[k] / r) / (2 * np.pi * f[k])
        assert tau == pytest.approx(float(lens_delays(z[row], 0.02, 2e-3, 1481.0)), abs=1e-11)


def test_export_kwave_cli_writes_mask_and_signals(tmp_path):
    import h5py
    from typer.testing import CliRunner

    from holoprobe.cli import app

    vt = _vt(n=4)
    path = vt.save(tmp_path / "vt.h5")
    (tmp_path / "tx.toml").write_text(
        '[drive]\nkind = "pulse"\namplitude = 30.0\nduration = 12e-9\n')
    res = CliRunner().invoke(app, ["export", "kwave", str(path), "--transmit",
                                   str(tmp_path / "tx.toml"), "--grid", "8", "16", "31",
                                   "--spacing-mm", "0.1", "--dt-ns", "4", "--nt", "64",
                                   "--out", str(tmp_path / "kw.h5")])
    assert res.exit_code == 0, res.output
    with h5py.File(tmp_path / "kw.h5") as f:
        assert f["mask"][()].sum() == 4 * 2 * 21
        assert f["signals"].shape == (168, 64) and f.attrs["representation"] == "monopole"
        assert f.attrs["format"] == "holoprobe-kwave-source" and f.attrs["kind"] == "kwave-source"
        assert f["signals"].attrs["units"] == "Pa"


def test_received_point_source_at_the_elevation_focus_adds_in_phase_on_every_strip():
    """The lens delays a received wave as it delays a transmitted one (no [kwave] needed).

    A point source in front of each element at the elevation focus (x_i, 0, F) reaches
    strip k after √(v_k² + F²)/c0; the lens delay τ(v_k) makes every strip arrive at
    √((H/2)² + F²)/c0, so the element average is the undistorted pulse at that time.
    """
    from types import SimpleNamespace

    from holoprobe.export import kwave_element_pressure

    focus, height, c0, n_strips = 0.01, 6e-3, 1481.0, 24
    vt = VirtualTransducer(element_count=2, pitch=0.3e-3, element_width=0.25e-3,
                           element_height=height, transmit_impulse_response=np.ones(4),
                           transmit_sampling_rate=FS, lens_focus=focus,
                           medium=Medium(998.0, c0))
    dt, nt = 1 / FS, 4096
    t = np.arange(nt) * dt
    sigma = 30e-9
    v = kwave_element_strips(vt, n_strips)["centers"][:, 1]
    arrival = np.sqrt(v**2 + focus**2) / c0  # (2·n_strips,) point source per element
    strip_data = np.exp(-((t[None, :] - arrival[:, None]) ** 2) / (2 * sigma**2))

    class StripArray:  # stands in for kWaveArray: the sensor data are the strip signals
        def combine_sensor_data(self, kgrid, data, order="C"):
            return data

    p = kwave_element_pressure(vt, SimpleNamespace(dt=dt), StripArray(), strip_data)
    expected = np.exp(-((t - np.sqrt((height / 2) ** 2 + focus**2) / c0) ** 2)
                      / (2 * sigma**2))
    assert p.shape == (2, nt)
    np.testing.assert_allclose(p, np.broadcast_to(expected, p.shape), atol=2e-3)
