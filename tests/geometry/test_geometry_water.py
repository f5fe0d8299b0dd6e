"""Pure-water sound speed (Marczak 1997) against published measurements."""

from __future__ import annotations

import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.geometry import Medium, water_sound_speed

# Del Grosso & Mader, J. Acoust. Soc. Am. 52, 1442 (1972): speed of sound in pure water
# at atmospheric pressure, m/s (measured; Marczak's polynomial is a fit to these and two
# other data sets, stated to agree within about 0.04 m/s)
DEL_GROSSO_MADER = {0.0: 1402.388, 10.0: 1447.269, 20.0: 1482.343, 30.0: 1509.123,
                    40.0: 1528.883}


@pytest.mark.parametrize(("temperature", "speed"), sorted(DEL_GROSSO_MADER.items()))
def test_water_sound_speed_matches_del_grosso_and_mader(temperature, speed):
    assert float(water_sound_speed(temperature)) == pytest.approx(speed, abs=0.06)


def test_two_degrees_warmer_water_is_about_six_metres_per_second_faster():
    # the example: 1481 m/s in the file, the tank 2 °C warmer
    dc = np.diff(water_sound_speed([19.0, 21.0]))[0]
    assert 5.5 < dc < 6.5
    assert Medium.water(20.0).sound_speed == pytest.approx(1482.38, abs=0.01)


def test_water_temperature_outside_the_fit_is_refused():
    with pytest.raises(InputError, match="water_temperature"):
        water_sound_speed(120.0)
