"""The gallery (``examples/plot_*.py``, rendered by ``make docs``) runs: every script
executes on its small twin without error, so the documentation never goes stale."""

from __future__ import annotations

import runpy
from pathlib import Path

import matplotlib
import pytest

EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "examples").glob("plot_*.py"))


def test_the_gallery_has_the_documented_examples():
    """One example per item of the documentation's gallery list."""
    names = {p.stem for p in EXAMPLES}
    assert {"plot_characterize_array", "plot_focused_field", "plot_export",
            "plot_bowl_hologram", "plot_spurious_modes",
            "plot_hydrophone_deconvolution"} <= names


@pytest.mark.parametrize("script", EXAMPLES, ids=lambda p: p.stem)
def test_example_runs(script, tmp_path, monkeypatch):
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    monkeypatch.chdir(tmp_path)
    try:
        namespace = runpy.run_path(str(script), run_name="__main__")
    finally:
        plt.close("all")
    # what a notebook would show for the results the example made (e.g. the HologramRun
    # of the bowl example): an HTML table with at least one value
    shown = [v._repr_html_() for v in namespace.values()
             if type(v).__module__.startswith("holoprobe.") and hasattr(v, "_repr_html_")]
    assert all("<table" in html and "<td" in html for html in shown), script
