"""The hologram run (workflow.characterize_hologram_file) via ``holoprobe characterize``.

The layout is detected from the file and the documented keys are written.
"""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest
from typer.testing import CliRunner

from _hologram_twin import make_twin
from holoprobe.cli import app
from holoprobe.errors import InputError
from holoprobe.geometry import Medium, Surface
from holoprobe.io import FOCAL_VOLUME_FORMAT, read_results_h5, read_source, write_hologram_mat
from holoprobe.propagation import rayleigh_integral


@pytest.fixture(scope="module")
def mat_file(tmp_path_factory):
    twin = make_twin(n=61, descending=True)
    path = tmp_path_factory.mktemp("holo") / "bowl.mat"
    write_hologram_mat(path, twin.hologram, exp_sign=1, descending=(True, False))
    return twin, path


def _summary(path, out, *options: str) -> dict:
    """summary.json of ``holoprobe characterize PATH --out OUT --quiet OPTIONS``."""
    res = CliRunner().invoke(app, ["characterize", str(path), "--out", str(out), "--quiet",
                                   *options])
    assert res.exit_code == 0, res.output
    return json.loads((out / "summary.json").read_text())


def test_cli_characterizes_a_matlab_hologram_with_decreasing_x(mat_file, tmp_path):
    twin, path = mat_file
    s = _summary(path, tmp_path / "o", "--set", "hologram.monte_carlo=2")
    axis = np.array(s["alignment"]["axis_direction"])
    assert np.degrees(np.arccos(axis @ twin.axis)) < 0.05
    assert s["source"]["kind"] == "spherical-cap"
    assert s["source"]["radius_of_curvature"] == pytest.approx(0.04, rel=0.005)
    assert s["source"]["aperture_diameter"] == pytest.approx(0.03, abs=0.3e-3)
    pw = s["acoustic_power"]
    assert pw["surface"] == pytest.approx(pw["hologram"], rel=0.01)
    assert (tmp_path / "o" / "report.html").stat().st_size > 10_000
    src = read_source(tmp_path / "o" / "source.h5")
    assert src.kind == "spherical-cap" and src.velocity.shape[1] == 1
    # the 3-D focal field is written and holds the twin's own (dense Rayleigh) field, Pa
    vol = read_results_h5(tmp_path / "o" / "focal_volume.h5", FOCAL_VOLUME_FORMAT)
    assert vol["pressure"].shape == (*vol["axis_e1"].shape, *vol["axis_e2"].shape,
                                     *vol["axis_along"].shape)
    pts = vol["points"].reshape(-1, 3)[::997]
    truth = rayleigh_integral(twin.velocity[:, None], twin.surface,
                              Surface(pts, np.tile([0, 0, 1.0], (len(pts), 1)),
                                      np.ones(len(pts))), [1e6], Medium(),
                              kernel="fwd_vp")[:, 0]
    got = vol["pressure"].reshape(-1)[::997]
    assert np.max(np.abs(got - truth)) < 0.01 * np.abs(vol["pressure"]).max()


def test_cli_bad_aperture_override_is_one_line(mat_file, tmp_path, monkeypatch, capsys):
    from holoprobe.cli import main

    _, path = mat_file
    monkeypatch.setattr(sys, "argv", ["holoprobe", "characterize", str(path), "--out",
                                      str(tmp_path / "o"), "--quiet", "--aperture", "0.03",
                                      "--aperture", "0.03", "--aperture", "0.01"])
    with pytest.raises(SystemExit) as exc:
        main()
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--aperture" in err
    assert not (tmp_path / "o").exists()


def test_cli_source_overrides_a_file_without_geometry(mat_file, tmp_path):
    """A file without a Geometry struct is characterized from --source,
    --radius-of-curvature and --aperture; without them it is one clear line."""
    import dataclasses

    twin, _ = mat_file
    path = write_hologram_mat(tmp_path / "bare.mat",
                              dataclasses.replace(twin.hologram, geometry=None, source=""))
    bare = CliRunner().invoke(app, ["characterize", str(path), "--out", str(tmp_path / "b"),
                                    "--quiet"])
    message = str(bare.exception)       # holoprobe's main() prints it as one line, exit 2
    assert isinstance(bare.exception, InputError) and "\n" not in message
    assert "Geometry" in message and "--source" in message
    s = _summary(path, tmp_path / "o", "--source", "spherical-cap",
                 "--radius-of-curvature", "0.04", "--aperture", "0.03")
    assert s["source"]["kind"] == "spherical-cap"
    assert s["source"]["radius_of_curvature"] == pytest.approx(0.04, rel=0.005)
    axis = np.array(s["alignment"]["axis_direction"])
    assert np.degrees(np.arccos(axis @ twin.axis)) < 0.05


def test_cli_flattened_order_reads_y_fastest_data(mat_file, tmp_path):
    """[n] data on a square grid flattened y fastest (a meshgrid-shaped array reshaped):
    read x fastest they are the transpose (the tilted twin's axis would come out with x
    and y swapped); --flattened-order y reads them right, and no assumption is reported."""
    twin, _ = mat_file
    path = write_hologram_mat(tmp_path / "flat.mat", twin.hologram, grid_layout="flattened-y")
    s = _summary(path, tmp_path / "o", "--flattened-order", "y")
    axis = np.array(s["alignment"]["axis_direction"])
    assert np.degrees(np.arccos(axis @ twin.axis)) < 0.05
    assert not any("flattened" in w for w in s["warnings"])
