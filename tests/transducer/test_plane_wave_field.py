"""Fields at scattered points by plane waves against the exact element superposition."""

from __future__ import annotations

import numpy as np
import pytest

from _shared import FS, tiny_transducer
from holoprobe.errors import InputError
from holoprobe.transducer import (
    TransmitSetting,
    VirtualTransducer,
    burst,
    plane_wave_targets,
    predict_field,
)


def test_plane_waves_equal_the_element_superposition_at_scattered_points():
    vt = tiny_transducer()
    tx = TransmitSetting.focused((1e-3, 0.0, 6e-3), drive=burst(2e6, 2, 10.0, sampling_rate=FS),
                                 apodization="hann")
    rng = np.random.default_rng(4)
    n = 20
    pts = np.stack([rng.uniform(-3e-3, 3e-3, n), rng.uniform(-2e-3, 2e-3, n),
                    rng.uniform(1e-3, 8e-3, n)], axis=-1)
    pts[:6, 2] = rng.uniform(1.2e-3, 1.8e-3, 6)  # near the face: evanescent waves count
    kw = dict(sampling_rate=12.5e6, time_window="local", band_threshold_db=-12.0)
    waves = predict_field(vt, tx, pts, method="plane_waves", **kw)
    exact = predict_field(vt, tx, pts, method="element", n_samples=waves.pressure.shape[1],
                          **kw)
    assert waves.method == "plane_waves"
    peak = np.max(np.abs(exact.pressure))
    err = np.max(np.abs(waves.pressure - exact.pressure)) / peak
    assert err < 1e-4, err
    assert np.max(np.abs(waves.pressure[:6] - exact.pressure[:6])) / peak < 1e-4


def test_auto_sends_many_scattered_points_to_plane_waves_and_lines_to_the_lattice():
    vt = VirtualTransducer.from_preset("p4-1")
    rng = np.random.default_rng(5)
    n = 40000
    scattered = np.stack([rng.uniform(-25e-3, 25e-3, n), rng.uniform(-3e-3, 3e-3, n),
                          rng.uniform(5e-3, 100e-3, n)], axis=-1)
    f = np.linspace(0.4e6, 4.5e6, 100)
    assert plane_wave_targets(vt, scattered, 96, f, 4 * 171).all()
    # the same number of points on 200 lines along x: the lattice's domain
    lines = scattered.copy()
    lines[:, 1:] = scattered[np.arange(n) % 200, 1:]
    assert not plane_wave_targets(vt, lines, 96, f, 4 * 171).any()
    # a few scattered points: the element superposition is cheaper
    assert not plane_wave_targets(vt, scattered[:100], 96, f, 4 * 171).any()


def test_plane_waves_refuse_targets_behind_the_face():
    vt = tiny_transducer()
    tx = TransmitSetting.focused((0.0, 0.0, 6e-3), drive=burst(2e6, 2, 10.0, sampling_rate=FS))
    with pytest.raises(InputError, match="z > 0"):
        predict_field(vt, tx, [[0.0, 0.0, 0.0], [0.0, 0.0, 1e-3]], method="plane_waves")
