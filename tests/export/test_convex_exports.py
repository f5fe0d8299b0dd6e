"""Exports of a convex virtual transducer (issue 16): UFF element positions and
orientations, Verasonics curved ``Trans``, k-Wave elements on the arc, PROTEUS refused."""

from __future__ import annotations

import sys
import types

import numpy as np
import pytest

from _shared import gaussian_ir
from holoprobe.errors import InputError
from holoprobe.geometry import ArrayGeometry, Medium
from holoprobe.measurement import DriveSignal
from holoprobe.transducer import TransmitSetting, VirtualTransducer

N, PITCH, WIDTH, HEIGHT, R = 10, 0.5e-3, 0.45e-3, 2e-3, 6e-3
DRIVE = DriveSignal([1.0, 1.0], 50e6)
PHI = (np.arange(N) - (N - 1) / 2) * PITCH / R  # written out here, not taken from the code


@pytest.fixture(scope="module")
def vt():
    fs = 50e6
    return VirtualTransducer(
        element_count=N, pitch=PITCH, element_width=WIDTH, element_height=HEIGHT,
        transmit_impulse_response=gaussian_ir(fs, 3e6, 0.2e-6, 0.8e-6) * 1e10,
        transmit_sampling_rate=fs, lens_focus=15e-3, medium=Medium(998.0, 1481.0),
        array=ArrayGeometry.convex(N, PITCH, R, WIDTH, HEIGHT), name="arc")


def _rot(axis: str, deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
            "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


def test_uff_elements_sit_on_the_arc_and_face_along_its_normals(vt):
    from holoprobe.export import uff_probe_dict

    uff = uff_probe_dict(vt)
    els = list(uff["element"].values())
    pos = np.array([[e["transform"]["translation"][k] for k in "xyz"] for e in els])
    np.testing.assert_allclose(pos, np.c_[R * np.sin(PHI), np.zeros(N),
                                          R * (np.cos(PHI) - 1)], atol=1e-15)
    for e, phi in zip(els, PHI, strict=True):
        rot = e["transform"]["rotation"]
        turned = _rot("y", np.degrees(rot["y"])) @ [0.0, 0.0, 1.0]  # the element's +z
        np.testing.assert_allclose(turned, [np.sin(phi), 0.0, np.cos(phi)], atol=1e-12)
        assert rot["x"] == rot["z"] == 0.0


def test_verasonics_trans_is_curved_with_element_angles(vt):
    from holoprobe.export import verasonics_trans

    trans = verasonics_trans(vt, sound_speed=1540.0)
    lam = 1540.0 / (trans["frequency"] * 1e6)
    assert trans["type"] == 1.0
    assert trans["radiusMm"] == pytest.approx(R * 1e3)
    assert trans["radius"] == pytest.approx(R / lam)
    pos = np.asarray(trans["ElementPos"])
    np.testing.assert_allclose(pos[:, 0] * lam, R * np.sin(PHI), atol=1e-12)
    np.testing.assert_allclose(pos[:, 2] * lam, R * (np.cos(PHI) - 1), atol=1e-12)
    np.testing.assert_allclose(pos[:, 3], PHI, atol=1e-12)


def test_kwave_grid_mask_follows_the_arc_with_element_labels(vt):
    from holoprobe.export import kwave_grid_mask, kwave_grid_source

    d = 0.05e-3
    shape = (40, 141, 61)
    mask, label = kwave_grid_mask(vt, shape, (d, d, d))
    idx = np.argwhere(mask)
    x = (idx - np.array(shape) // 2) * d  # k-Wave coordinates
    depth = R * (1 - np.cos(PHI[-1] + 0.5 * WIDTH / R))  # behind the apex, outer edges
    apex = (1 - shape[0] // 2) * d + depth
    # model coordinates (x lateral, y elevation, z depth) of the masked points
    xm, ym, zm = x[:, 1], x[:, 2], x[:, 0] - apex
    radial = np.hypot(xm, zm + R) - R
    assert np.abs(radial).max() <= 0.5 * np.sqrt(2) * d + 1e-12  # on the cylinder
    assert np.abs(ym).max() <= 0.5 * HEIGHT + 1e-12
    assert set(label) == set(range(N))
    ang = np.arctan2(xm, zm + R)
    assert np.all(np.abs(ang - PHI[label]) <= 0.5 * WIDTH / R + d / R)
    assert zm.min() >= -depth - d
    setting = TransmitSetting.focused((0, 0, 8e-3), drive=DRIVE)
    signals = kwave_grid_source(vt, setting, shape, (d, d, d), d / 1481 / 3, 60)[1]
    assert signals.shape == (idx.shape[0], 60) and np.abs(signals).max() > 0


def test_kwave_off_grid_rectangles_are_tangent_to_the_arc(vt, monkeypatch):
    """The rectangles handed to kWaveArray, turned by R = Rz·Ry·Rx (k-wave-python's
    make_cart_rect convention), have their normal and width along the element's."""
    from holoprobe.export import kwave_element_strips
    from holoprobe.export._kwave import _kwave_array

    calls = []

    class FakeArray:
        def __init__(self, **kw):
            pass

        def add_rect_element(self, pos, lx, ly, theta):
            calls.append((np.asarray(pos), lx, ly, np.asarray(theta)))

    module = types.ModuleType("kwave.utils.kwave_array")
    module.kWaveArray = FakeArray
    for name in ("kwave", "kwave.utils"):
        monkeypatch.setitem(sys.modules, name, types.ModuleType(name))
    monkeypatch.setitem(sys.modules, "kwave.utils.kwave_array", module)
    strips = kwave_element_strips(vt, 2)
    _kwave_array(vt, strips, 1e-3, 0.05, 10)
    assert len(calls) == 2 * N
    for (pos, lx, ly, theta), phi, k in zip(calls, np.repeat(PHI, 2), range(2 * N),
                                            strict=True):
        rot = _rot("z", theta[2]) @ _rot("y", theta[1]) @ _rot("x", theta[0])
        # k-Wave axes (x = model z, y = model x, z = model y)
        np.testing.assert_allclose(rot @ [0, 0, 1.0], [np.cos(phi), np.sin(phi), 0],
                                   atol=1e-12)
        np.testing.assert_allclose(rot @ [0, 1.0, 0], [-np.sin(phi), np.cos(phi), 0],
                                   atol=1e-12)
        assert (lx, ly) == pytest.approx((HEIGHT / 2, WIDTH))
        v = (k % 2 - 0.5) * HEIGHT / 2
        np.testing.assert_allclose(pos, [1e-3 + R * (np.cos(phi) - 1), R * np.sin(phi), v],
                                   atol=1e-15)


def test_proteus_and_the_plane_check_refuse_a_convex_model(vt, tmp_path):
    from holoprobe.export import export_proteus, kwave_plane_field

    with pytest.raises(InputError, match="convex"):
        export_proteus(vt, tmp_path)
    with pytest.raises(InputError, match="flat face"):
        kwave_plane_field(vt, TransmitSetting.focused((0, 0, 8e-3), drive=DRIVE), distance=2e-3,
                          step=0.1e-3)
