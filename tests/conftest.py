"""Fixtures shared by the tests of several packages (helpers: ``tests/_shared.py``).

The tests mirror the package: ``tests/<subpackage>/test_*.py`` tests
``holoprobe.<subpackage>``; ``tests/test_architecture.py`` checks the structure.
"""

from __future__ import annotations

import pytest

from holoprobe.geometry import Pose

#: The pose of the P4-1 twin's scan plane in the transmit tests (θ in degrees, origin m).
TWIN_POSE = Pose.from_degrees(0.5, -0.8, 0.6, (0.1e-3, -0.05e-3, 3.5e-3))


@pytest.fixture(scope="session")
def reduced():
    """A reduced P4-1 twin scan and its truth: 16 of the 96 elements, 9.6 × 19.2 mm at
    0.15 mm, 192 samples, peak SNR 40 dB (the regular suite's transmit measurement)."""
    from holoprobe.simulate import ArrayModel, simulate_scan

    model = ArrayModel.from_preset("p4-1", element_count=16)
    scan, truth = simulate_scan(model, pose=TWIN_POSE, size=(9.6e-3, 19.2e-3), n_samples=192,
                                snr_db=40.0, seed=1)
    return scan, truth


@pytest.fixture(scope="session")
def reduced_result(reduced):
    """The transmit characterization of :func:`reduced` with the default configuration."""
    from holoprobe.characterize import characterize_transmit

    return characterize_transmit(reduced[0], progress=False)
