"""VirtualTransducer: construction checks, HDF5 round trip, schema errors, presets."""

from __future__ import annotations

import math
import tomllib

import h5py
import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.geometry import Medium
from holoprobe.io import packaged_data_path
from holoprobe.transducer import Provenance, VirtualTransducer


def _full_model() -> VirtualTransducer:
    rng = np.random.default_rng(7)
    return VirtualTransducer(
        element_count=8,
        pitch=0.3e-3,
        element_width=0.25e-3,
        element_height=14.3e-3,
        transmit_impulse_response=rng.normal(size=300) * 1e11,
        transmit_sampling_rate=250e6,
        lens_focus=0.0812345678901234,
        aperture_center=(1.25e-5, -3.5e-6),
        aperture_width=2.36e-3,
        aperture_height=14.29e-3,
        receive_impulse_response=rng.normal(size=211) * 1e6,
        receive_sampling_rate=125e6,
        receive_units="V/(Pa*s)",
        medium=Medium(density=1000.5, sound_speed=1490.25),
        element_sensitivity=1 + 0.01 * rng.normal(size=8),
        element_delay=1e-9 * rng.normal(size=8),
        parameters={"aperture.width": 2.36e-3, "lens_focus": 0.0812345678901234,
                    "scan_plane.theta_x": 1.234e-3},
        uncertainties={"aperture.width": 1e-6, "lens_focus": 2e-3},
        provenance=Provenance(input_files={"scan.h5": "ab" * 32},
                              config='[aperture]\nthreshold = 0.5\n', config_format="toml",
                              notes="synthetic µ-test ✓"),
        name="test probe",
    )


def _assert_same(a: VirtualTransducer, b: VirtualTransducer) -> None:
    for name in ("element_count", "pitch", "element_width", "element_height",
                 "transmit_sampling_rate", "transmit_units", "lens_focus", "aperture_center",
                 "aperture_width", "aperture_height", "receive_sampling_rate", "receive_units",
                 "medium", "parameters", "uncertainties", "name"):
        assert getattr(a, name) == getattr(b, name), name
    for name in ("transmit_impulse_response", "receive_impulse_response",
                 "element_sensitivity", "element_delay"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            assert np.array_equal(x, y), name  # bit-exact
    assert vars(a.provenance) == vars(b.provenance)


def test_save_load_round_trip_is_bit_exact(tmp_path):
    vt = _full_model()
    path = vt.save(tmp_path / "virtual_transducer.h5")
    _assert_same(vt, VirtualTransducer.load(path))


def test_round_trip_without_receive_and_without_lens(tmp_path):
    vt = VirtualTransducer(element_count=1, pitch=1e-3, element_width=1e-3,
                           element_height=5e-3, transmit_impulse_response=[0.0, 1.0, -0.5],
                           transmit_sampling_rate=50e6)
    back = VirtualTransducer.load(vt.save(tmp_path / "vt.h5"))
    _assert_same(vt, back)
    assert back.lens_focus == math.inf
    assert not back.has_receive
    with h5py.File(tmp_path / "vt.h5") as f:
        assert f.attrs["format"] == "holoprobe"
        assert f.attrs["kind"] == "virtual_transducer"
        assert f.attrs["schema_version"] == 1
        assert "receive" not in f
        assert f["transmit/impulse_response"].attrs["units"] == "Pa/(V*s)"


def test_save_refuses_to_overwrite_unless_asked(tmp_path):
    vt = _full_model()
    path = vt.save(tmp_path / "vt.h5")
    with pytest.raises(InputError, match="already exists"):
        vt.save(path)
    vt.replace(name="second").save(path, overwrite=True)
    assert VirtualTransducer.load(path).name == "second"


def test_element_centers_are_pitch_spaced_about_the_aperture_centre():
    vt = _full_model()
    c = vt.element_centers()
    assert c.shape == (8, 3)
    np.testing.assert_allclose(np.diff(c[:, 0]), 0.3e-3, rtol=1e-12)
    assert c[:, 0].mean() == pytest.approx(1.25e-5, abs=1e-15)
    assert np.all(c[:, 1] == -3.5e-6) and np.all(c[:, 2] == 0)


def test_default_aperture_follows_the_elements():
    vt = VirtualTransducer(element_count=4, pitch=1e-3, element_width=0.8e-3,
                           element_height=5e-3, transmit_impulse_response=[1.0, 0.0],
                           transmit_sampling_rate=1e8)
    assert vt.aperture_width == pytest.approx(3.8e-3)
    assert vt.aperture_height == 5e-3


@pytest.mark.parametrize(("changes", "field"), [
    ({"element_count": 0}, "element_count"),
    ({"pitch": -1.0}, "pitch"),
    ({"element_width": 0.5e-3}, "element_width"),  # wider than the pitch
    ({"transmit_impulse_response": [1.0, np.nan, 0.0]}, "transmit_impulse_response"),
    ({"transmit_units": "Pa/V"}, "transmit_units"),
    ({"lens_focus": -0.05}, "lens_focus"),
    ({"receive_sampling_rate": None}, "receive_sampling_rate"),
    ({"receive_units": "V"}, "receive_units"),
    ({"element_sensitivity": np.ones(7)}, "element_sensitivity"),
    ({"parameters": {"a/b": 1.0}}, "parameters"),
])
def test_invalid_fields_are_rejected_with_their_name(changes, field):
    with pytest.raises(InputError) as info:
        _full_model().replace(**changes)
    assert info.value.field == field


def test_provenance_rejects_a_malformed_hash():
    with pytest.raises(InputError, match="SHA-256"):
        Provenance(input_files={"scan.h5": "not-a-hash"})


def _corrupt(path, edit):
    with h5py.File(path, "r+") as f:
        edit(f)


@pytest.mark.parametrize(("edit", "dataset", "message"), [
    (lambda f: f.attrs.__setitem__("kind", "hydrophone_scan"), "/", "not a holoprobe virtual"),
    (lambda f: f.attrs.__setitem__("schema_version", 99), "/schema_version", "upgrade"),
    (lambda f: f.__delitem__("transmit/impulse_response"), "/transmit/impulse_response",
     "missing"),
    (lambda f: f.__delitem__("transmit"), "/transmit", "missing group"),
    (lambda f: f["transmit/impulse_response"].__setitem__(3, np.nan),
     "/transmit/impulse_response", "NaN"),
    (lambda f: f["transmit/impulse_response"].attrs.__setitem__("units", "Pa"),
     "/transmit/impulse_response", "units"),
    (lambda f: f["transmit/sampling_rate"].__setitem__((), -1.0), "/transmit/sampling_rate",
     "positive"),
    (lambda f: (f.__delitem__("elements/sensitivity"),
                f["elements"].create_dataset("sensitivity", data=np.ones(3)).attrs.__setitem__(
                    "units", "1")), "/elements/sensitivity", "shape"),
    (lambda f: f["elements/width"].__setitem__((), 1.0), "/elements/width", "exceeds the pitch"),
    (lambda f: f.__delitem__("medium/sound_speed"), "/medium/sound_speed", "missing"),
    (lambda f: f.__delitem__("provenance/input_sha256"), "/provenance/input_sha256", "missing"),
])
def test_malformed_file_names_file_and_dataset(tmp_path, edit, dataset, message):
    path = _full_model().save(tmp_path / "vt.h5")
    _corrupt(path, edit)
    with pytest.raises(InputError, match=message) as info:
        VirtualTransducer.load(path)
    assert info.value.file == str(path)
    assert info.value.field == dataset


def test_load_of_a_non_hdf5_file_is_a_clear_error(tmp_path):
    path = tmp_path / "vt.h5"
    path.write_text("hello")
    with pytest.raises(InputError, match="not a readable HDF5"):
        VirtualTransducer.load(path)
    with pytest.raises(InputError, match="no such file"):
        VirtualTransducer.load(tmp_path / "absent.h5")


def test_p4_1_preset_model_carries_the_published_geometry_and_packaged_irs():
    toml = tomllib.loads(packaged_data_path("probes", "p4-1.toml").read_text())
    pub = toml["published"]
    vt = VirtualTransducer.from_preset("p4-1")
    assert vt.element_count == 96
    assert vt.pitch == pub["pitch"]
    assert vt.element_height == pub["element_height"]
    assert vt.lens_focus == pub["lens_focus"]
    assert vt.aperture_width == pytest.approx(pub["aperture_width"])
    # the aperture width is consistent with the element geometry, (N-1) p + w
    assert vt.aperture_width == pytest.approx(95 * vt.pitch + vt.element_width, rel=1e-6)
    with h5py.File(packaged_data_path("p4-1_impulse_responses.h5")) as f:
        tx, rx, fs = f["transmit"][()], f["receive"][()], float(f["sampling_rate"][()])
    assert np.array_equal(vt.transmit_impulse_response, tx)
    assert np.array_equal(vt.receive_impulse_response, rx)
    assert vt.transmit_sampling_rate == fs == 250e6
    # the published extrema of the transmit IR (preset table) are in the packaged data
    irt = pub["transmit_impulse_response"]
    assert vt.transmit_impulse_response.max() == pytest.approx(irt["maximum"], rel=1e-4)
    assert set(vt.provenance.input_files) == {"p4-1.toml", "p4-1_impulse_responses.h5"}


def test_datasheet_preset_uses_nominal_values():
    vt = VirtualTransducer.from_preset("P4-1", values="datasheet")
    assert vt.element_height == 0.016
    assert vt.lens_focus == 0.11


def test_unknown_preset_is_a_clear_error():
    with pytest.raises(InputError, match="no packaged probe preset"):
        VirtualTransducer.from_preset("no-such-probe")
