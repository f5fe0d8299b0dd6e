"""holoprobe.workflow: the results object of a run and what its save() writes."""

from __future__ import annotations

import dataclasses
import json
import math
import types

import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.geometry import Pose
from holoprobe.io import read_source_velocity
from holoprobe.transducer import VirtualTransducer
from holoprobe.workflow import OUTPUT_FILES, CharacterizationRun, characterize


def test_saved_files_hold_what_the_run_object_holds(reduced_result, tmp_path):
    run = CharacterizationRun(reduced_result, timings={"read": 0.25})
    written = run.save(tmp_path, report=False)
    assert set(written) == {"summary", "virtual_transducer", "source_velocity"}
    assert {p.name for p in written.values()} <= set(OUTPUT_FILES)

    saved = json.loads(written["summary"].read_text())
    expected = run.summary
    assert saved["timings"]["read"] == 0.25 and saved["timings"]["write"] > 0
    for key in ("scan_plane", "aperture", "elements", "lens_focus", "transmit",
                "uncertainty", "warnings"):
        assert saved[key] == expected[key], key

    sv = read_source_velocity(written["source_velocity"])
    np.testing.assert_array_equal(sv["velocity"], reduced_result.source_velocity)
    np.testing.assert_array_equal(sv["x"], reduced_result.source_grid.x)
    assert sv["sampling_rate"] == reduced_result.sampling_rate

    vt = VirtualTransducer.load(written["virtual_transducer"])
    model = run.virtual_transducer
    assert model is not None
    np.testing.assert_array_equal(vt.transmit_impulse_response,
                                  model.transmit_impulse_response)
    assert vt.parameters == pytest.approx(model.parameters)
    assert vt.element_count == reduced_result.elements.count

    with pytest.raises(InputError, match="exist"):  # no silent overwrite
        run.save(tmp_path, report=False)


def test_characterize_checks_its_inputs_before_computing(reduced, tmp_path):
    with pytest.raises(InputError, match="Rp"):
        characterize(reduced[0], reflection_coefficient=1.5)
    with pytest.raises(InputError, match=r"missing\.h5"):
        characterize(reduced[0], echo=tmp_path / "missing.h5")



@dataclasses.dataclass(frozen=True)
class _FakeTransmit:
    """Stands for a TransmitResult where only ``extras`` and what the sound speed's σ
    scales (``with_sound_speed_uncertainty``) and what the angle lever reads
    (``with_angle_lever``: the centre fit's σ) are read."""

    extras: dict
    medium: object = None
    pose: object = None
    lens_focus: float = 0.06
    aperture: object = dataclasses.field(default_factory=lambda: types.SimpleNamespace(
        center_x_uncertainty=1e-6, center_y_uncertainty=2e-6))
    uncertainties: dict = dataclasses.field(default_factory=lambda: {
        "theta_x": 0.0, "theta_y": 0.0, "theta_z": 0.0, "z0": 0.0, "lens_focus": 0.0,
        "x0": 1e-6, "y0": 2e-6, "center_x": 1e-6, "center_y": 2e-6})


def test_sound_speed_from_data_turns_the_estimate_on_for_its_first_pass(reduced, monkeypatch):
    """``sound_speed="from-data"`` estimates c0 in the first pass (even when
    elements.fit_sound_speed is off in the configuration), then characterizes again at
    the estimated c0 without estimating it again (the first pass's value is reported)."""
    import holoprobe.workflow._run as run_module

    calls = []

    def fake_transmit(scan, cfg, **_):
        calls.append((scan.medium.sound_speed, cfg.elements.fit_sound_speed))
        fitted = 1487.0 if cfg.elements.fit_sound_speed else float("nan")
        return _FakeTransmit({"sound_speed_from_data": fitted,
                              "sound_speed_from_data_uncertainty": 6.0}, scan.medium,
                             Pose.from_degrees(0.0, 2.0, 0.0, (0.0, 0.0, 0.03)))

    monkeypatch.setattr(run_module, "characterize_transmit", fake_transmit)
    scan = reduced[0]
    run = characterize(scan, sound_speed="from-data")
    assert calls == [(scan.medium.sound_speed, True), (1487.0, False)]
    assert run.transmit.extras["sound_speed_from_data"] == 1487.0
    # the c0 used is the data's: its own σ joins what c0 scales (F, z0, tilts)
    u = run.transmit.uncertainties
    assert run.transmit.extras["sound_speed_uncertainty"] == 6.0
    assert u["lens_focus"] == pytest.approx(0.06 * 6.0 / 1487.0)
    assert u["z0"] == pytest.approx(0.03 * 6.0 / 1487.0)
    assert u["theta_y"] == pytest.approx(math.tan(math.radians(2.0)) * 6.0 / 1487.0)
    assert u["theta_x"] == 0.0
    # ... and reaches x0 (and the aperture centre) over the lever z0: a frame turned by
    # δθy moves the scan origin by z0·δθy, on top of the centre fit's 1 µm
    lever = math.hypot(1e-6, 0.03 * u["theta_y"])
    assert u["x0"] == pytest.approx(lever) and u["center_x"] == pytest.approx(lever)
    assert u["y0"] == pytest.approx(2e-6)  # θx, θz: no σ here


def test_each_input_file_is_hashed_once_for_the_model_and_the_report(reduced_result, tmp_path,
                                                                     monkeypatch):
    """The SHA-256 of an input (a full-size scan: 130 MB) is read once per save: the
    report's provenance takes the model's hashes."""
    import hashlib

    import holoprobe.workflow._outputs as outputs

    scan_file = tmp_path / "scan.h5"
    scan_file.write_bytes(b"not a real scan, only hashed")
    calls = []
    original = outputs.file_sha256

    def counting(path, **kw):
        calls.append(str(path))
        return original(path, **kw)

    monkeypatch.setattr(outputs, "file_sha256", counting)
    written = outputs.write_outputs(reduced_result, tmp_path / "out", inputs=[scan_file])
    digest = hashlib.sha256(scan_file.read_bytes()).hexdigest()
    assert calls == [str(scan_file)]
    assert VirtualTransducer.load(written["virtual_transducer"]).provenance.input_files == {
        "scan.h5": digest}
    assert digest in written["report"].read_text(encoding="utf-8")
