"""Plausible physical inputs (holoprobe.plausibility, io.check_measurement; issue 10 item 8).

A value outside its range (a unit mistake) is one InputError line naming the file, the
field, the value and the range; a deliberate ``--set plausibility.<name>=[min, max]``
widens it.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.io
from test_io_support import make_echo, make_scan

from holoprobe.characterize import CharacterizationConfig
from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid
from holoprobe.io import (
    check_measurement,
    read_echo,
    read_reference_scan,
    read_scan,
    write_echo,
    write_scan,
)
from holoprobe.plausibility import DEFAULT_PLAUSIBILITY, PlausibilityConfig
from holoprobe.signal import load_calibration


def _scan_dir(directory, sound_speed=1481.0, density=998.0, dt=1e-7, step=1e-4):
    x = np.arange(4) * step
    y = np.arange(3) * step
    scipy.io.savemat(directory / "ScanData.mat", {
        "Grid": {"x": x, "y": y, "z": 0.0, "Nx": 4, "Ny": 3, "dx": step, "dy": step,
                 "Nt": 8, "dt": dt},
        "voltage_mV": np.ones((4, 3, 8)),
        "medium": {"sound_speed": sound_speed, "density": density}})
    return directory / "ScanData.mat"


def test_scan_with_sound_speed_in_km_per_s_is_refused_naming_file_field_value_range(tmp_path):
    path = _scan_dir(tmp_path, sound_speed=1.481)
    with pytest.raises(InputError) as err:
        read_reference_scan(tmp_path)
    e = err.value
    assert e.file == str(path) and e.field == "medium.sound_speed"
    line = str(e)
    assert "\n" not in line and "1.481 m/s" in line and "[1300, 1700]" in line
    assert "plausibility.sound_speed" in line


@pytest.mark.parametrize(("kwargs", "field", "value"), [
    ({"density": 0.998}, "medium.density", "0.998 kg/m^3"),           # g/cm³
    ({"dt": 0.1}, "sampling_rate", "10 Hz"),                           # dt in µs as s
    ({"step": 0.1}, "grid.dx", "0.1 m"),                               # mm as m
])
def test_other_unit_mistakes_in_a_toolkit_scan_are_refused(tmp_path, kwargs, field, value):
    _scan_dir(tmp_path, **kwargs)
    with pytest.raises(InputError, match="implausible") as err:
        read_reference_scan(tmp_path)
    assert err.value.field == field and value in str(err.value)


def test_a_deliberately_widened_range_accepts_the_value(tmp_path):
    _scan_dir(tmp_path, sound_speed=1100.0)  # e.g. a fluorinated coupling liquid
    with pytest.raises(InputError):
        read_reference_scan(tmp_path)
    cfg = CharacterizationConfig().with_overrides(["plausibility.sound_speed=[1000, 2000]"])
    scan = read_reference_scan(tmp_path, plausibility=cfg.plausibility)
    assert scan.medium.sound_speed == 1100.0


def test_native_scan_and_echo_are_checked(tmp_path):
    scan = make_scan()
    bad = dataclasses.replace(scan, grid=PlaneGrid.centered(5, 4, 0.15, 0.2))  # mm as m
    write_scan(tmp_path / "scan.h5", bad)
    with pytest.raises(InputError, match="implausible") as err:
        read_scan(tmp_path / "scan.h5")
    assert err.value.field == "grid.dx" and err.value.file == str(tmp_path / "scan.h5")
    echo = dataclasses.replace(make_echo(), medium=Medium(1.0, 1481.0))
    write_echo(tmp_path / "echo.h5", echo)
    with pytest.raises(InputError, match="implausible") as err:
        read_echo(tmp_path / "echo.h5")
    assert err.value.field == "medium.density"


def test_calibration_in_mv_per_mpa_read_as_v_per_pa_is_refused(tmp_path):
    path = tmp_path / "cal.csv"
    path.write_text("frequency_Hz,sensitivity_V_per_Pa\n1e6,50\n2e6,52\n")
    with pytest.raises(InputError, match="implausible") as err:
        load_calibration(path)
    assert err.value.field == "sensitivity" and err.value.file == str(path)
    path.write_text("frequency_Hz,sensitivity_V_per_Pa\n1e6,5e-8\n2e6,5.2e-8\n")
    assert load_calibration(path).sensitivity[0] == 5e-8


def test_drive_voltage_and_nested_nouns_are_checked():
    scan = make_scan()
    check_measurement(scan)  # the plausible test scan passes
    from holoprobe.measurement import DriveSignal

    with pytest.raises(InputError, match=r"drive\.voltage"):
        check_measurement(dataclasses.replace(scan, drive=DriveSignal(np.r_[0, 3e4, 0], 250e6)))


def test_every_range_has_a_unit_and_bad_ranges_are_input_errors():
    for f in dataclasses.fields(PlausibilityConfig):
        lo, hi = getattr(DEFAULT_PLAUSIBILITY, f.name)
        assert lo < hi
        assert DEFAULT_PLAUSIBILITY.check(f.name, lo) == lo
    with pytest.raises(InputError, match="min < max"):
        PlausibilityConfig(sound_speed=(1700.0, 1300.0))
    with pytest.raises(InputError):
        CharacterizationConfig().with_overrides(["plausibility.density=5"])


def test_cli_names_file_field_value_and_range_in_one_line(tmp_path, capsys, monkeypatch):
    from holoprobe.cli import main

    _scan_dir(tmp_path, sound_speed=1.481)
    monkeypatch.setattr("sys.argv", ["holoprobe", "characterize", str(tmp_path), "--out",
                                     str(tmp_path / "out"), "--quiet"])
    with pytest.raises(SystemExit) as exc:
        main()
    assert exc.value.code == 2
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln]
    assert len(lines) == 1, lines
    assert "ScanData.mat" in lines[0] and "medium.sound_speed" in lines[0]
    assert "1.481" in lines[0] and "[1300, 1700]" in lines[0]
