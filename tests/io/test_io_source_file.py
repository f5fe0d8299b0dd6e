"""The self-describing source file: round trip, waveforms, one-line errors."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.geometry import Medium, Surface
from holoprobe.io import SourceVelocity, read_source, write_source


def _source(spectral: bool = False) -> SourceVelocity:
    surface = Surface.disc(10e-3, spacing=1e-3)
    rng = np.random.default_rng(0)
    freqs = np.array([1e6, 1.1e6]) if spectral else np.array([1e6])
    vel = rng.standard_normal((surface.size, freqs.size)) + 1j * rng.standard_normal(
        (surface.size, freqs.size))
    extra = dict(spectral=True, sampling_rate=20e6, n_time=200) if spectral else {}
    return SourceVelocity(surface, freqs, vel, Medium(1000.0, 1500.0), kind="flat-disc",
                          aperture=(10e-3, 10e-3), apex=np.array([0.0, 0.0, -0.02]), **extra)


@pytest.mark.parametrize("spectral", [False, True])
def test_source_file_round_trip(tmp_path, spectral):
    src = _source(spectral)
    write_source(tmp_path / "s.h5", src)
    back = read_source(tmp_path / "s.h5")
    np.testing.assert_array_equal(back.velocity, src.velocity)
    np.testing.assert_array_equal(back.surface.points, src.surface.points)
    np.testing.assert_array_equal(back.surface.weights, src.surface.weights)
    assert back.medium == src.medium and back.kind == "flat-disc"
    assert back.radius_of_curvature is None and back.spectral == spectral
    with h5py.File(tmp_path / "s.h5") as f:
        assert f["velocity"].attrs["units"] == ("m/s*s" if spectral else "m/s")
        assert f["surface/areas"].attrs["units"] == "m^2"


def test_waveforms_of_a_single_bin_are_a_tone():
    src = _source(spectral=True)
    w = src.waveforms()
    t = np.arange(200) / 20e6
    # one bin at 1 MHz (bin 10 of 200 at 20 MHz): v(t) = 2 Re{V e^{−iωt}} fs/n … per convention
    spec = np.zeros(101, complex)
    spec[10] = src.velocity[0, 0]
    spec[11] = src.velocity[0, 1]
    expected = np.fft.irfft(np.conj(spec), 200) * 20e6
    np.testing.assert_allclose(w[0], expected, atol=1e-9)
    assert w.shape == (src.surface.size, t.size)


def test_source_file_errors_name_the_dataset(tmp_path):
    write_source(tmp_path / "s.h5", _source())
    with h5py.File(tmp_path / "s.h5", "a") as f:
        f["velocity"][0, 0] = np.nan
    with pytest.raises(InputError, match=r"velocity.*NaN"):
        read_source(tmp_path / "s.h5")
    with pytest.raises(InputError, match="expected shape"):
        SourceVelocity(Surface.disc(5e-3, spacing=1e-3), [1e6], np.zeros((3, 1)))
    with pytest.raises(InputError, match="exists"):
        write_source(tmp_path / "s.h5", _source())
