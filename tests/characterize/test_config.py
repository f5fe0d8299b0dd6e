"""CharacterizationConfig: TOML round trip, --set overrides, unknown keys and bad types."""

from __future__ import annotations

import pytest

from holoprobe.characterize._config import CharacterizationConfig
from holoprobe.errors import InputError


def test_defaults_round_trip_through_toml(tmp_path):
    cfg = CharacterizationConfig()
    path = tmp_path / "c.toml"
    path.write_text(cfg.to_toml(), encoding="utf-8")
    assert CharacterizationConfig.from_toml(path) == cfg
    assert cfg.iterations.count == 2
    assert cfg.transmit.output_rate == 250e6


def test_toml_file_sets_values_and_keeps_other_defaults(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('[iterations]\ncount = 3\ninitial_z0 = 4e-3\n'
                    '[band]\nband = [1e6, 4e6]\n[transmit]\nmethod = "wiener"\n',
                    encoding="utf-8")
    cfg = CharacterizationConfig.from_toml(path)
    assert cfg.iterations.count == 3
    assert cfg.iterations.initial_z0 == pytest.approx(4e-3)
    assert cfg.band.band == (1e6, 4e6)
    assert cfg.transmit.method == "wiener"
    assert cfg.onset.threshold == CharacterizationConfig().onset.threshold


def test_unknown_key_names_the_key_and_file(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text("[iterations]\ncont = 3\n", encoding="utf-8")
    with pytest.raises(InputError) as err:
        CharacterizationConfig.from_toml(path)
    assert "iterations.cont" in str(err.value) and str(path) in str(err.value)


def test_unknown_section_is_rejected(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text("[iteration]\ncount = 3\n", encoding="utf-8")
    with pytest.raises(InputError, match="iteration"):
        CharacterizationConfig.from_toml(path)


@pytest.mark.parametrize("text, field", [
    ('[iterations]\ncount = "two"\n', "iterations.count"),
    ('[transmit]\nmethod = "magic"\n', "transmit.method"),
    ("[band]\nband = [1e6]\n", "band.band"),
    ("[iterations]\ncount = 0\n", "iterations.count"),
    ("[receive]\neps = 0.5\n", "receive.eps"),
    ("[receive]\npose_tolerance = -1.0\n", "receive.pose_tolerance"),
    ("[receive]\ntransfer_function_floor = -0.01\n", "receive.transfer_function_floor"),
    ("[receive]\nir_out_of_band_weight = -1e-3\n", "receive.ir_out_of_band_weight"),
    ("[receive]\nir_noise_tail = -2.0\n", "receive.ir_noise_tail"),
    ("[aperture]\nwindow_bins = 0\n", "aperture.window_bins"),
    ("[receive]\nplan_cache_mb = inf\n", "receive.plan_cache_mb"),
    ("[elements]\nedge_silent_threshold = 1.5\n", "elements.edge_silent_threshold"),
    ("[receive]\npose_noise_draws = -1\n", "receive.pose_noise_draws"),
    ("[receive]\nband_decimation = -2\n", "receive.band_decimation"),
    ("[receive]\nband_alias_tolerance = 0.0\n", "receive.band_alias_tolerance"),
    ("[receive]\ntaper_band = 1.5\n", "receive.taper_band"),
    ("[hologram]\nwindow_model_source_points = 0\n", "hologram.window_model_source_points"),
    ("[hologram]\nvelocity_gate_level = 1.0\n", "hologram.velocity_gate_level"),
    ("[hologram]\nflattened_order = \"z\"\n", "hologram.flattened_order"),
])
def test_wrong_types_and_values_name_the_field(tmp_path, text, field):
    path = tmp_path / "c.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(InputError, match=field.replace(".", r"\.")):
        CharacterizationConfig.from_toml(path)


def test_resolve_takes_a_path_an_object_or_none_and_applies_overrides_last(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text("[iterations]\ncount = 3\n[onset]\npolarity = \"negative\"\n",
                    encoding="utf-8")
    cfg = CharacterizationConfig.resolve(path, ["iterations.count=5"])
    assert cfg.iterations.count == 5              # the override wins over the file
    assert cfg.onset.polarity == "negative"       # the file's value is kept
    assert CharacterizationConfig.resolve() == CharacterizationConfig()
    given = CharacterizationConfig().with_overrides(["iterations.count=2"])
    assert CharacterizationConfig.resolve(given) is given
    with pytest.raises(InputError, match="no such configuration file"):
        CharacterizationConfig.resolve(tmp_path / "missing.toml")


def test_set_overrides_parse_toml_values():
    cfg = CharacterizationConfig().with_overrides(
        ["iterations.count=4", "band.band=[0.5e6, 5e6]", "backprojection.single_precision=false",
         "onset.polarity=positive"])
    assert cfg.iterations.count == 4
    assert cfg.band.band == (0.5e6, 5e6)
    assert cfg.backprojection.single_precision is False
    assert cfg.onset.polarity == "positive"


@pytest.mark.parametrize("assignment", ["iterations.nope=1", "nosection.count=1", "count=1",
                                        "iterations.count"])
def test_bad_set_assignments_are_input_errors(assignment):
    with pytest.raises(InputError):
        CharacterizationConfig().with_overrides([assignment])


def test_dump_holds_every_section_including_receive():
    data = CharacterizationConfig().to_dict()
    assert set(data) == {"band", "orientation", "backprojection", "aperture", "lens", "onset",
                         "iterations", "transmit", "warnings", "hydrophone", "hologram",
                         "elements", "plausibility", "receive", "convex"}
    assert "[receive]" in CharacterizationConfig().to_toml()


def test_receive_section_is_typed_and_checked_like_the_others():
    from holoprobe.characterize import ReceiveConfig

    cfg = CharacterizationConfig().with_overrides(["receive.onset_threshold=7.5"])
    assert isinstance(cfg.receive, ReceiveConfig) and cfg.receive.onset_threshold == 7.5
    assert CharacterizationConfig.from_dict(cfg.to_dict()) == cfg  # round trip
    with pytest.raises(InputError, match=r"receive\.no_such_knob"):
        CharacterizationConfig().with_overrides(["receive.no_such_knob=1"])
