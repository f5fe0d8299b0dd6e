"""Field prediction of the rows of a row-column array (issue 16 stretch): the virtual
transducer of a set lives in the set's own frame (x' along its line of elements; for
the rows x' = y, y' = −x of the probe), where it is a flat 1-D array of long strips."""

from __future__ import annotations

import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.geometry import Medium, Surface
from holoprobe.simulate import ArrayModel, synthesize_pressure
from holoprobe.transducer import TransmitSetting, VirtualTransducer, predict_field

MEDIUM = Medium(998.0, 1481.0)
N = 6


def test_rows_field_in_their_own_frame_matches_the_twin_in_absolute_pressure():
    """The 1-D model of the rows (midpoint sub-elements, its own Rayleigh sum) at
    (x', y', z) against the twin (Gauss–Legendre cells on the rows' exact strips, dense
    Rayleigh sum) at the probe point (−y', x', z), for a focus off both axes."""
    model = ArrayModel.row_column(N, transmit="rows").with_element_variation(
        amplitude_rms=0.1, seed=4)
    rows = model.array.strip_set == 1
    amp = np.asarray(model.apodization)[rows]
    vt = VirtualTransducer(
        element_count=N, pitch=0.3e-3, element_width=model.element_width,
        element_height=model.element_height, transmit_impulse_response=model.transmit_ir,
        transmit_sampling_rate=model.ir_sampling_rate, medium=MEDIUM,
        element_transmit_amplitude=amp)
    setting = TransmitSetting.focused((0.4e-3, -0.5e-3, 6e-3), drive=model.drive)
    apod, tau = vt.transmit_weights(setting)
    full_apod, full_tau = np.zeros(2 * N), np.zeros(2 * N)
    full_apod[rows], full_tau[rows] = apod, tau
    twin = model.replace(delays=full_tau, apodization=full_apod)
    rng = np.random.default_rng(1)
    view = np.c_[rng.uniform(-2e-3, 2e-3, (8, 2)), rng.uniform(4e-3, 9e-3, 8)]
    probe = np.c_[-view[:, 1], view[:, 0], view[:, 2]]
    expected = synthesize_pressure(
        twin, twin.sample_surface(MEDIUM.sound_speed / 6e6 / 4),
        Surface(probe, np.tile([0, 0, 1.0], (8, 1)), np.ones(8)), sampling_rate=250e6,
        n_samples=2500, start_time=0.0, band=(0.3e6, 6e6), medium=MEDIUM, dtype=np.float64)
    got = predict_field(vt, setting, view, sampling_rate=250e6)
    np.testing.assert_allclose(got.peak_positive, expected.max(axis=1), rtol=0.02)
    # the rows described in the probe's frame are refused, not mis-modelled
    with pytest.raises(InputError, match="width axis is not x"):
        VirtualTransducer(
            element_count=N, pitch=0.3e-3, element_width=model.element_width,
            element_height=model.element_height, transmit_impulse_response=model.transmit_ir,
            transmit_sampling_rate=model.ir_sampling_rate, medium=MEDIUM,
            array=model.array.subset(rows))
