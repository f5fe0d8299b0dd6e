"""The Hologram noun: CW and transient, validation of bad inputs."""

import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid, Pose, SourceGeometry
from holoprobe.measurement import Hologram

BOWL = SourceGeometry("spherical-cap", 40e-3, 40e-3, 40e-3)


def _grid(z=20e-3, n=5, d=1e-3):
    return PlaneGrid.centered(n, n, d, pose=Pose(origin=(0.0, 0.0, z)))


def test_cw_and_transient_holograms():
    cw = Hologram(np.ones((5, 5)), _grid(), frequency=1e6, geometry=BOWL)
    assert cw.pressure.dtype == np.complex128 and not cw.is_transient
    assert cw.z_position == pytest.approx(20e-3)
    tr = Hologram(np.zeros((5, 5, 8)), _grid(), sampling_rate=20e6, start_time=1e-6)
    assert tr.is_transient and tr.n_samples == 8
    assert tr.time[1] == pytest.approx(1e-6 + 5e-8)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"pressure": np.ones((0, 5))}, "empty"),
    ({"pressure": np.ones((5, 4))}, "match the grid"),
    ({"pressure": np.full((5, 5), np.nan)}, "NaN"),
    ({"frequency": 1.0}, "implausible"),
    ({"medium": Medium(density=1.0)}, "implausible"),
    ({"medium": Medium(sound_speed=1.48)}, "implausible"),
    ({"grid": _grid(z=0.0)}, "front of the source"),
    ({"grid": _grid(z=-1e-3)}, "front of the source"),
    ({"grid": _grid(z=2e-3, d=8e-3), "geometry": BOWL}, "inside the bowl"),
])
def test_bad_hologram_is_one_clear_line(kwargs, match):
    args = {"pressure": np.ones((5, 5)), "grid": _grid(), "frequency": 1e6}
    args.update(kwargs)
    with pytest.raises(InputError, match=match) as info:
        Hologram(**args)
    assert "\n" not in str(info.value)


def test_plane_inside_the_cavity_is_accepted_when_the_scan_fits():
    h = Hologram(np.ones((5, 5)), _grid(z=2e-3, n=5), frequency=1e6, geometry=BOWL)
    assert h.z_position < BOWL.rim_depth
