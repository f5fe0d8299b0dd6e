"""The fast (element-superposition) field path against the dense Rayleigh sum.

The dense path sums every sub-element of the whole array; the element path
evaluates one element's field at distinct offsets and shifts, weights and delays
it. They share only the sub-element rule, so agreement checks the offset folding,
the superposition and the per-point time windows.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from _shared import FS, tiny_transducer
from holoprobe.transducer import (
    TransmitSetting,
    burst,
    element_offsets,
    predict_field,
)


def _grid(vt, step, x_half, z_range, y=None):
    xe = vt.element_centers()[:, 0]
    x = xe[0] + np.arange(-200, 200) * step
    x = x[np.abs(x - vt.aperture_center[0]) <= x_half]
    z = np.arange(*z_range)
    X, Z = np.meshgrid(x, z, indexing="ij")
    yy = vt.aperture_center[1] if y is None else y
    return np.stack([X.ravel(), np.full(X.size, yy), Z.ravel()], axis=-1)


def test_element_superposition_equals_dense_rayleigh_of_the_whole_array():
    vt = tiny_transducer()
    tx = TransmitSetting.focused((1e-3, 0.0, 6e-3), drive=burst(2e6, 2, 10.0, sampling_rate=FS),
                                 apodization="hann")
    pts = np.concatenate([_grid(vt, vt.pitch / 2, 2e-3, (2e-3, 8e-3, 0.5e-3)),
                          [[0.3e-3, 1.1e-3, 5e-3], [-1.7e-3, -0.6e-3, 3e-3]]])
    fast = predict_field(vt, tx, pts, method="element", sampling_rate=FS)
    dense = predict_field(vt, tx, pts, method="rayleigh", sampling_rate=FS)
    assert fast.method == "element"
    err = np.max(np.abs(fast.pressure - dense.pressure)) / np.max(np.abs(dense.pressure))
    assert err < 0.01 and err < 1e-9, err  # same quadrature: agreement to rounding
    fast32 = predict_field(vt, tx, pts, sampling_rate=FS, dtype=np.float32)
    err32 = np.max(np.abs(fast32.pressure - dense.pressure)) / np.max(np.abs(dense.pressure))
    assert fast32.pressure.dtype == np.float32 and err32 < 1e-4, err32


def test_offsets_of_a_plane_whose_step_divides_the_pitch_fold_to_few_distinct_ones():
    vt = tiny_transducer(n=16)
    m = 2
    pts = _grid(vt, vt.pitch / m, 3e-3, (1e-3, 4e-3, 1e-3))
    nz = 3
    nx = pts.shape[0] // nz
    offsets, index = element_offsets(vt, pts, np.arange(16))
    # every (element, point) pair maps to its own |Δx|, |Δy|, z
    xe = vt.element_centers()[:, 0]
    expected = np.stack(np.broadcast_arrays(np.abs(pts[None, :, 0] - xe[:, None]),
                                            np.abs(pts[None, :, 1] - 0.2e-3),
                                            pts[None, :, 2]), axis=-1)
    np.testing.assert_allclose(offsets[index], expected, atol=2e-9)
    # lateral offsets lie on a grid of step pitch/m: at most (nx + m(N − 1)) per depth,
    # folded by |Δx| to about half of it
    assert offsets.shape[0] <= nz * ((nx + m * 15) // 2 + 1)
    assert offsets.shape[0] < 16 * pts.shape[0] / 10


def test_local_time_windows_keep_each_waveform_and_shorten_the_record():
    vt = tiny_transducer()
    tx = TransmitSetting.focused((0.0, 0.0, 10e-3), drive=burst(2e6, 2, 10.0, sampling_rate=FS))
    pts = np.array([[0.1e-3, 0.2e-3, 3e-3], [2e-3, 0.2e-3, 25e-3], [-1e-3, 1.0e-3, 12e-3]])
    common = predict_field(vt, tx, pts, sampling_rate=FS)
    local = predict_field(vt, tx, pts, sampling_rate=FS, time_window="local")
    assert local.time.size < common.time.size / 2
    assert np.all(common.time_offset == 0)
    # each local record starts before its first arrival and holds the whole pulse:
    # same energy (Parseval) and the same peak
    e_c = np.sum(common.pressure**2, axis=1)
    e_l = np.sum(local.pressure**2, axis=1)
    np.testing.assert_allclose(e_l, e_c, rtol=1e-3)  # bins differ at the -40 dB band edges
    np.testing.assert_allclose(local.peak_positive, common.peak_positive, rtol=0.01)
    # and at the same absolute time of the peak
    t_c = common.time[np.argmax(common.pressure, axis=1)]
    t_l = local.time_offset + local.time[np.argmax(local.pressure, axis=1)]
    np.testing.assert_allclose(t_l, t_c, atol=1.5 / FS)
    r = np.linalg.norm(pts - [0.0, 0.2e-3, 0.0], axis=1)
    assert np.all(local.time_offset < r / 1481.0)


def test_bad_method_and_window_are_refused():
    from holoprobe.errors import InputError

    vt = tiny_transducer(n=2)
    tx = TransmitSetting(burst(2e6, 2, 10.0, sampling_rate=FS))
    with pytest.raises(InputError, match="time_window"):
        predict_field(vt, tx, [[0, 0, 1e-2]], time_window="global")
    with pytest.raises(InputError, match="dtype"):
        predict_field(vt, tx, [[0, 0, 1e-2]], dtype=np.int32)
    assert math.isfinite(predict_field(vt, tx, [[0, 0, 1e-2]]).peak_positive[0])


def test_fields_of_a_sequence_share_the_element_response_and_equal_dense_rayleigh():
    from holoprobe.transducer import predict_fields

    vt = tiny_transducer()
    drive = burst(2e6, 2, 10.0, sampling_rate=FS)
    silent_first = np.ones(vt.element_count)
    silent_first[0] = 0.0
    settings = [TransmitSetting.focused((1e-3, 0.0, 6e-3), drive=drive, apodization="hann"),
                TransmitSetting.plane_wave(math.radians(10.0), drive=drive,
                                           apodization=silent_first),
                TransmitSetting.diverging(5e-3, drive=drive)]
    pts = np.concatenate([_grid(vt, 0.4e-3, 2e-3, (2e-3, 7e-3, 1e-3)),
                          [[0.3e-3, 1.1e-3, 5e-3]]])
    fields = list(predict_fields(vt, settings, pts, sampling_rate=FS, dtype=np.float64,
                                 method="element"))
    assert len(fields) == 3
    n = fields[0].time.size
    for setting, fast in zip(settings, fields, strict=True):
        dense = predict_field(vt, setting, pts, method="rayleigh", time_window="local",
                              sampling_rate=FS, n_samples=n)
        np.testing.assert_allclose(fast.time_offset, dense.time_offset, rtol=0, atol=1e-15)
        err = np.max(np.abs(fast.pressure - dense.pressure)) / np.max(np.abs(dense.pressure))
        assert err < 1e-9, err


def test_lattice_kernel_interpolates_band_limited_functions():
    from holoprobe.transducer import lattice_kernel, lattice_step

    rng = np.random.default_rng(3)
    for band, taps, bound in ((0.45, 16, 3e-8), (0.6, 20, 2e-7)):
        kappa = np.concatenate([[-band * np.pi, band * np.pi],
                                rng.uniform(-band * np.pi, band * np.pi, 60)])
        amp = rng.normal(size=kappa.size) + 1j * rng.normal(size=kappa.size)

        def f(x, kappa=kappa, amp=amp):
            return np.exp(1j * np.multiply.outer(x, kappa)) @ amp

        x = rng.uniform(10.0, 11.0, 200)
        nodes = np.floor(x)[:, None] + np.arange(1 - taps // 2, taps // 2 + 1)
        est = np.sum(lattice_kernel(x[:, None] - nodes, taps, band) * f(nodes), axis=1)
        assert np.max(np.abs(est - f(x))) <= bound * np.sum(np.abs(amp))
    # the lattice divides the pitch, is at most λ/3.2, and picks the kernel
    m, h, band, taps = lattice_step(0.3e-3, 0.33e-3)
    assert m == 3 and h == pytest.approx(0.1e-3) and band <= 0.625 and taps == 20


def test_lattice_path_matches_dense_rayleigh_at_arbitrary_points():
    """Lines of targets off the element lattice (x step 0.23 mm, pitch 0.3 mm) at several
    (y, z), lone targets and one target nearer the face than the interpolation allows:
    interpolated from the element lattice they agree with the dense Rayleigh sum."""
    from holoprobe.transducer import element_plan, predict_fields

    vt = tiny_transducer(n=16)
    tx = TransmitSetting.focused((1e-3, 0.0, 6e-3), drive=burst(2e6, 2, 10.0, sampling_rate=FS),
                                 apodization="hann")
    x = np.arange(-4e-3, 4e-3, 0.23e-3)
    lines = [(0.2e-3, 1e-3), (0.2e-3, 4.3e-3), (0.9e-3, 7.7e-3), (-0.5e-3, 3e-3)]
    pts = np.concatenate([np.stack([x, np.full_like(x, y), np.full_like(x, z)], axis=-1)
                          for y, z in lines]
                         + [[[0.31e-3, 1.1e-3, 5e-3], [-1.7e-3, -0.6e-3, 0.2e-3]]])
    fast = predict_field(vt, tx, pts, sampling_rate=FS, time_window="local")
    dense = predict_field(vt, tx, pts, method="rayleigh", sampling_rate=FS,
                          time_window="local", n_samples=fast.time.size)
    assert fast.method == "lattice"
    scale = np.max(np.abs(dense.pressure))
    assert np.max(np.abs(fast.pressure - dense.pressure)) <= 1e-5 * scale
    seq = next(predict_fields(vt, [tx], pts, sampling_rate=FS, dtype=np.float64,
                              n_samples=fast.time.size))
    assert seq.method == "lattice"
    assert np.max(np.abs(seq.pressure - dense.pressure)) <= 1e-5 * scale
    # the lines need far fewer element responses than target-element pairs
    plan = element_plan(vt, pts, np.arange(16), 4e6, element_samples=20)
    assert plan.interpolated == 4 * x.size
    assert plan.offsets.shape[0] < 16 * pts.shape[0] / 4
    assert np.all(plan.weights[-2:, 1:] == 0)  # lone and near-face targets: direct


def test_element_response_from_column_tables_matches_the_direct_sum():
    """The element response interpolated from tables over ρ (one per elevation v) against
    the direct sum over its sub-elements, at off-grid offsets at several v and depths."""
    from holoprobe.transducer import column_tables_field, element_field

    vt = tiny_transducer(n=4, height=6e-3, focus=0.03)
    rng = np.random.default_rng(7)
    n = 600
    off = np.stack([rng.uniform(0, 8e-3, n), rng.choice([0.0, 0.7e-3, 2.9e-3], n),
                    rng.uniform(0.3e-3, 20e-3, n)], axis=-1)
    f = np.linspace(1e6, 4e6, 40)
    direct = element_field(vt, off, f)
    tab = column_tables_field(vt, off, f)
    assert tab is not None
    near = np.isnan(tab[:, 0])
    assert np.all(near == (off[:, 2] < 3 * 1481.0 / 4e6)) and near.sum() < n / 10
    scale = np.abs(direct).max()
    assert np.max(np.abs(tab[~near] - direct[~near])) <= 1e-5 * scale
    both = element_field(vt, off, f, tables=True)  # near-face rows summed directly
    assert np.max(np.abs(both - direct)) <= 1e-5 * scale


def test_arrival_bounds_of_a_flat_face_bracket_every_point_of_the_elements():
    """Earliest/latest arrivals against a brute-force sampling of each element's
    rectangle (corners included: the latest arrival is exact, the earliest within
    the sampling)."""
    from holoprobe.transducer._field import _arrival_bounds

    vt = tiny_transducer()
    rng = np.random.default_rng(5)
    els = np.arange(0, vt.element_count, 2)
    tau = rng.uniform(0, 2e-6, els.size)
    span = float(np.ptp(vt.element_centers()[:, 0]))
    pts = rng.uniform([-span, -3e-3, 0.5e-3], [span, 3e-3, 30e-3], size=(300, 3))
    t_min, t_max = _arrival_bounds(vt, pts, els, tau, False)
    u = np.linspace(-0.5, 0.5, 101)
    c0 = vt.medium.sound_speed
    arrivals = []
    for e, t in zip(els, tau, strict=True):
        xc, yc, _ = vt.element_centers()[e]
        gx, gy = np.meshgrid(xc + u * vt.element_width, yc + u * vt.element_height)
        d = np.sqrt((pts[:, None, 0] - gx.ravel()) ** 2 + (pts[:, None, 1] - gy.ravel()) ** 2
                    + pts[:, None, 2] ** 2)
        arrivals.append((d.min(axis=1) / c0 + t, d.max(axis=1) / c0 + t))
    lo = np.min([a[0] for a in arrivals], axis=0)
    hi = np.max([a[1] for a in arrivals], axis=0)
    cell = math.hypot(vt.element_width, vt.element_height) / 100 / c0
    assert np.all(t_min <= lo + 1e-15) and np.all(lo - t_min <= cell)
    np.testing.assert_allclose(t_max, hi, rtol=0, atol=1e-15)


def test_unique_pairs_agrees_with_numpy_row_unique():
    """The 1-D-key shortcut against np.unique(axis=0), keys of every size and sign, and
    the row sort it falls back to when the pairs' ranges overflow one int64 key."""
    from holoprobe.transducer import unique_pairs

    rng = np.random.default_rng(11)
    cases = [rng.integers(-5, 5, size=(int(rng.integers(1, 300)), 2)) * scale
             for scale in (1, 3, 10**8, 10**9) for _ in range(3)]
    cases.append(np.array([[2**61, 0], [-2**61, 5], [2**61, 0]]))
    for keys in cases:
        want = np.unique(keys, axis=0, return_index=True, return_inverse=True,
                         return_counts=True)[1:]
        got = unique_pairs(keys)
        for w, g in zip(want, got, strict=True):
            assert np.array_equal(w.reshape(-1), g)


@pytest.mark.parametrize("bins", [[3, 4, 5, 6, 7, 8], [3, 5, 9, 10, 17, 30]])
def test_records_are_the_band_limited_sum_of_the_spectra_from_each_start(bins):
    """Consecutive bins take the phasor recurrence, others one phasor per bin; both give
    p(t) = (2 fs / N) Re Σ_b P_b e^{−iω_b (s + t)} for a record starting at s."""
    from holoprobe.transducer._field import _records

    rng = np.random.default_rng(1)
    n, fs = 64, 20e6
    band = np.asarray(bins)
    fb = band * fs / n
    spec = rng.normal(size=(7, band.size)) + 1j * rng.normal(size=(7, band.size))
    start = rng.uniform(0.0, 30e-6, 7)
    got = _records(spec, fb, band, n, fs, 0.0, start, np.dtype(np.float64))
    t = start[:, None, None] + np.arange(n)[None, None, :] / fs
    want = (2 * fs / n) * np.real(np.einsum("pb,pbn->pn", spec,
                                            np.exp(-2j * np.pi * fb[None, :, None] * t)))
    assert np.max(np.abs(got - want)) <= 1e-12 * np.max(np.abs(want))
