"""Notebook display: the result objects render as HTML tables (``_repr_html_``)."""

from __future__ import annotations

import re

from holoprobe.report import format_quantity, summary_html
from holoprobe.transducer import VirtualTransducer
from holoprobe.workflow import CharacterizationRun


def _cells(html: str) -> list[str]:
    return re.findall(r"<td[^>]*>(.*?)</td>", html)


def test_summary_table_shows_values_with_uncertainties_units_and_warnings():
    html = summary_html({"lens_focus": 0.0603, "aperture": {"width": 0.0287, "height": 0.0142},
                         "uncertainty": {"lens_focus": 0.0004,
                                         "aperture": {"width": 2e-5, "height": 3e-5}},
                         "axis": [0.0201347557, -0.01, 0.9997], "empty": [],
                         "timings": {"read": 1.0},
                         "warnings": ["scan clipped at x <b>"]}, title="run")
    cells = _cells(html)
    assert cells[cells.index("lens_focus") + 1] == "60.30 ± 0.40 mm"
    assert cells[cells.index("width") + 1] == "28.700 ± 0.020 mm"
    assert cells[cells.index("axis") + 1] == "(0.02013, -0.01, 0.9997)"
    assert "read" not in cells and "empty" not in cells  # timings are not parameters
    assert "scan clipped at x &lt;b&gt;" in html     # escaped
    assert ">aperture<" in html                      # grouped


def test_virtual_transducer_renders_its_geometry():
    vt = VirtualTransducer.from_preset("p4-1")
    cells = _cells(vt._repr_html_())
    assert cells[cells.index("element_count") + 1] == "96"
    assert cells[cells.index("pitch") + 1] == f"{vt.pitch * 1e3:.4g} mm"


def test_characterization_run_renders_its_summary_and_returns_its_figures(reduced_result):
    from matplotlib.figure import Figure

    run = CharacterizationRun(transmit=reduced_result)
    html = run._repr_html_()
    summary = run.summary
    cells = _cells(html)
    assert cells[cells.index("lens_focus") + 1] == format_quantity(
        summary["lens_focus"], summary["uncertainty"]["lens_focus"], "m")
    sections = run.figures()
    assert sections and all(isinstance(f, Figure) for _, figs in sections for f in figs)
