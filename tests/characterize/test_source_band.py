"""Transient band back-projected on the bins of a shortened record (characterize._source_band)
against every bin of the record (the previous path, band_decimation = 1)."""

from __future__ import annotations

import numpy as np
import pytest

from holoprobe.characterize import (
    HologramConfig,
    characterize_hologram,
    propagation_guard_angle,
)
from holoprobe.characterize._source_band import (
    band_spectra,
    folded_energy_outside,
    project_band,
)
from holoprobe.geometry import SourceGeometry
from holoprobe.signal import to_frequency
from holoprobe.simulate import simulate_hologram
from holoprobe.workflow import source_velocity

GEOMETRY = SourceGeometry("spherical-cap", 0.02, 0.02, 0.03)
POSE = dict(z_position=0.018, tilt=(0.01, -0.02), offset=(0.5e-3, -0.3e-3), shape=(41, 41))


@pytest.fixture(scope="module")
def pulsed():
    holo, _ = simulate_hologram(GEOMETRY, frequency=1e6, signal="transient", cycles=2,
                                power=False, focus=False, band_db=-30, snr_db=40, **POSE)
    every = characterize_hologram(holo, HologramConfig(band_decimation=1))
    folded = characterize_hologram(holo, HologramConfig())
    return holo, every, folded


def test_band_spectra_are_the_records_fourier_integral():
    holo, _ = simulate_hologram(GEOMETRY, frequency=1e6, signal="transient", cycles=3,
                                power=False, focus=False, shape=(9, 9), z_position=0.018)
    fs, n = float(holo.sampling_rate), holo.n_samples
    wave = np.asarray(holo.pressure, float)
    bins = np.array([3, 7, 11])
    expected = to_frequency(wave)[..., bins] / fs \
        * np.exp(2j * np.pi * bins * fs / n * holo.start_time)
    np.testing.assert_allclose(band_spectra(holo, bins * fs / n), expected,
                               rtol=1e-9, atol=1e-12 * np.abs(expected).max())


def test_folded_energy_outside_tells_a_pulse_from_a_long_wave():
    record = 64
    t = np.arange(record)
    bins = np.arange(1, record // 2)
    pulse = np.exp(-0.5 * ((t - 20) / 3) ** 2) * np.cos(0.9 * t)
    long = np.cos(0.9 * t) * (1 + 0.3 * np.sin(2 * np.pi * t / record))
    for wave, expect_small in ((pulse, True), (long, False)):
        spec = to_frequency(np.tile(wave, (5, 1)))[:, bins]
        share = folded_energy_outside(spec, bins, record)
        assert (share < 1e-6) if expect_small else (share > 0.2)


def test_a_pulse_is_projected_on_a_shortened_record(pulsed):
    holo, every, folded = pulsed
    assert every.band_decimation == 1 and every.velocity_band.size == every.band.size
    assert folded.band_decimation > 1
    assert folded.velocity_band.size < every.velocity_band.size / 1.9
    assert folded.velocity_record * folded.band_decimation >= holo.n_samples


def test_shortened_record_keeps_the_surface_power_and_waveforms(pulsed):
    _, every, folded = pulsed
    # the hologram's own power does not depend on the surface bins
    assert folded.power_hologram == every.power_hologram
    assert folded.power_surface == pytest.approx(every.power_surface, rel=1e-3)
    assert folded.inside_aperture_fraction == pytest.approx(every.inside_aperture_fraction,
                                                            abs=1e-3)
    # exported as the waveforms of the shortened record
    waves = source_velocity(folded).waveforms()
    assert waves.shape == (every.reconstruction.unrolled.surface.size,
                           folded.velocity_record)


def test_a_bin_of_the_shortened_record_is_the_records_bin(pulsed):
    """D = 2 on an even record: every other bin of the record, the same velocity there."""
    holo, every, _ = pulsed
    rec, cfg = every.reconstruction, HologramConfig(band_decimation=2)
    guard = propagation_guard_angle(every.pressure, every.grid, every.frequency, holo.medium,
                                    energy=cfg.guard_energy, margin_deg=cfg.guard_margin_deg)
    halved = project_band(holo, rec.unrolled, every.grid, every.band,
                          band_spectra(holo, every.band), rec.inside, guard_angle=guard,
                          cfg=cfg)
    assert halved.decimation == 2 and halved.record * 2 == holo.n_samples
    common, i_h, i_e = np.intersect1d(np.rint(halved.frequencies), np.rint(every.band),
                                      return_indices=True)
    assert common.size >= 10
    ref = every.band_velocity[:, i_e]
    np.testing.assert_allclose(halved.velocity[:, i_h], ref, rtol=0,
                               atol=1e-9 * np.abs(ref).max())
