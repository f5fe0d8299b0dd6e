"""One self-contained HTML page: parameters, warnings, figures, provenance.

:func:`build_report` writes the page; :func:`append_report_section` adds (or replaces) a
section of figures in a page it wrote. The page carries stable HTML-comment markers that
the second function relies on (user text is always escaped, so it can never contain
``<!--``): ``<!-- holoprobe-report 1 -->`` after the doctype; the figure count of the
header between ``<!-- hp:figure-count -->`` and ``<!-- /hp:figure-count -->``; each entry
of the table of contents between ``<!-- hp:toc id="ID" -->`` and ``<!-- /hp:toc -->``,
then ``<!-- hp:toc-end -->``; each figure section between ``<!-- hp:section id="ID" -->``
and ``<!-- /hp:section -->``, then ``<!-- hp:sections-end -->``; figure numbers in
``<span class="fignum">Figure N.</span>``.
"""

from __future__ import annotations

import base64
import datetime as _dt
import html
import json
import math
import os
import re
import struct
from collections.abc import Iterable, Mapping, Sequence
from numbers import Integral, Real
from pathlib import Path
from typing import Any

from matplotlib.figure import Figure

from holoprobe._html import html_table
from holoprobe._png import png_bytes as _png_bytes
from holoprobe.errors import InputError
from holoprobe.io import atomic_write
from holoprobe.report._figures import figure_caption

__all__ = ["DEFAULT_UNITS", "append_report_section", "build_report", "format_quantity",
           "summary_html"]

#: Units (SI) of the leaf names of ``summary.json``, used when ``parameters`` is a
#: nested dict; names ending in ``_deg`` are in degrees, a ``timings`` group in s.
DEFAULT_UNITS: dict[str, str] = {
    "x0": "m", "y0": "m", "z0": "m",
    "width": "m", "height": "m", "center_x": "m", "center_y": "m", "pitch": "m",
    "lens_focus": "m", "sensor_x0": "m", "sensor_z0": "m", "reflector_distance": "m",
    "onset": "s", "peak_frequency": "Hz", "bandwidth_6db": "Hz",
    "count": "", "reflection_coefficient": "",
}

_PREFIXES = {-12: "p", -9: "n", -6: "µ", -3: "m", 0: "", 3: "k", 6: "M", 9: "G"}
_AUTO_PREFIX_UNITS = {"s", "Hz", "Pa", "V"}

_CSS = """
:root{--fg:#1d2733;--muted:#5b6776;--line:#d9dee5;--bg:#ffffff;--panel:#f6f8fa;
--accent:#1f5fa8;--warn-bg:#fff6e0;--warn-line:#e0a100;--ok-bg:#eef8f0;--ok-line:#3c9a5f}
*{box-sizing:border-box}
body{margin:0;background:var(--bg);color:var(--fg);
font:15px/1.5 system-ui,-apple-system,"Segoe UI",Roboto,"Helvetica Neue",Arial,sans-serif}
main{max-width:1080px;margin:0 auto;padding:28px 24px 48px}
h1{font-size:1.7em;margin:0 0 4px}
h2{font-size:1.25em;margin:36px 0 12px;padding-bottom:4px;border-bottom:1px solid var(--line)}
.sub{color:var(--muted);margin:0 0 16px}
nav{background:var(--panel);border:1px solid var(--line);border-radius:6px;padding:8px 14px;
font-size:.93em}
nav a{color:var(--accent);text-decoration:none;margin-right:14px;white-space:nowrap}
nav a:hover{text-decoration:underline}
.warnings{background:var(--warn-bg);border-left:5px solid var(--warn-line);border-radius:4px;
padding:10px 16px;margin:18px 0}
.warnings h2{border:0;margin:4px 0 6px;font-size:1.1em}
.warnings ul{margin:4px 0 6px;padding-left:20px}
.notes{background:var(--warn-bg);border-left:4px solid var(--warn-line);border-radius:4px;
padding:4px 14px;margin:10px 0;font-size:.93em}
.notes ul{margin:4px 0;padding-left:20px}
.ok{background:var(--ok-bg);border-left:5px solid var(--ok-line);border-radius:4px;
padding:8px 16px;margin:18px 0}
table{border-collapse:collapse;width:100%;font-size:.95em}
th,td{text-align:left;padding:5px 10px;border-bottom:1px solid var(--line);vertical-align:top}
thead th{background:var(--panel);font-weight:600}
tr.group th{background:#eef2f7;color:var(--muted);font-weight:600;font-size:.9em;
text-transform:uppercase;letter-spacing:.04em}
td.value{font-variant-numeric:tabular-nums;white-space:nowrap}
td.name{font-family:ui-monospace,SFMono-Regular,Menlo,Consolas,monospace;font-size:.92em}
figure{margin:18px 0 26px;text-align:center}
figure img{max-width:100%;height:auto;border:1px solid var(--line);border-radius:4px}
figcaption{color:var(--muted);font-size:.92em;margin:6px auto 0;max-width:820px;text-align:left}
.fignum{font-weight:600;color:var(--fg)}
dl.meta{display:grid;grid-template-columns:max-content 1fr;gap:4px 18px;margin:0}
dl.meta dt{font-weight:600}
dl.meta dd{margin:0;overflow-wrap:anywhere}
pre{margin:0;background:var(--panel);padding:6px 8px;border-radius:4px;font-size:.85em;
white-space:pre-wrap;overflow-wrap:anywhere}
footer{margin-top:40px;color:var(--muted);font-size:.85em}
@media print{nav{display:none}figure{break-inside:avoid}}
"""


def _esc(value: object) -> str:
    return html.escape(str(value), quote=True)


# ----------------------------------------------------------------- markers

_SIGNATURE = "<!-- holoprobe-report 1 -->"
_COUNT_OPEN, _COUNT_CLOSE = "<!-- hp:figure-count -->", "<!-- /hp:figure-count -->"
_TOC_CLOSE, _TOC_END = "<!-- /hp:toc -->", "<!-- hp:toc-end -->"
_SECTION_CLOSE, _SECTIONS_END = "<!-- /hp:section -->", "<!-- hp:sections-end -->"
_ID = re.compile(r"[A-Za-z][A-Za-z0-9_-]*")
_COUNT_RE = re.compile(re.escape(_COUNT_OPEN) + r"\d+" + re.escape(_COUNT_CLOSE))
_FIGNUM_RE = re.compile(r'<span class="fignum">Figure \d+\.</span>')
_RESERVED_IDS = frozenset({"warnings", "parameters", "provenance"})


def _toc_item(section_id: str, heading: str) -> str:
    return (f'<!-- hp:toc id="{section_id}" --><a href="#{section_id}">{_esc(heading)}</a>'
            f"{_TOC_CLOSE}")


def _toc_re(section_id: str) -> re.Pattern[str]:
    return re.compile(re.escape(f'<!-- hp:toc id="{section_id}" -->') + ".*?"
                      + re.escape(_TOC_CLOSE), re.DOTALL)


def _section_re(section_id: str) -> re.Pattern[str]:
    return re.compile(re.escape(f'<!-- hp:section id="{section_id}" -->') + ".*?"
                      + re.escape(_SECTION_CLOSE) + "\n?", re.DOTALL)


def _figure_html(fig: Figure, caption: str, number: int, dpi: float) -> str:
    png = _png_bytes(fig, dpi)
    width, height = _png_size(png)
    data = base64.b64encode(png).decode("ascii")
    return (f'<figure><img src="data:image/png;base64,{data}" width="{width}" '
            f'height="{height}" alt="{_esc(caption)}">'
            f'<figcaption><span class="fignum">Figure {number}.</span> '
            f"{_esc(caption)}</figcaption></figure>\n")


# --------------------------------------------------------------- quantities


def _prefix_exponent(magnitude: float) -> int:
    if magnitude == 0 or not math.isfinite(magnitude):
        return 0
    e = 3 * math.floor(math.log10(magnitude) / 3)
    return max(min(e, 9), -12)


def format_quantity(
    value: Any,
    uncertainty: Any = None,
    unit: str = "",
    *,
    digits: int = 5,
    uncertainty_digits: int = 2,
    prefixes: bool = True,
) -> str:
    """Text of a value with its standard uncertainty and unit, e.g. ``28.54 ± 0.03 mm``.

    Parameters
    ----------
    value : number or any
        The value in SI units (a non-number is returned as text).
    uncertainty : number, optional
        Its standard uncertainty, same unit; omitted when None, NaN or ≤ 0.
    unit : str
        SI unit of ``value``. Lengths in m are shown in mm; s, Hz, Pa and V get
        an SI prefix chosen from the magnitude; other units are kept.
    digits : int
        Significant digits of ``value`` when there is no uncertainty.
    uncertainty_digits : int
        Significant digits of the uncertainty; the value is rounded to the
        same decimal place.
    prefixes : bool
        Apply the unit scaling above (otherwise show SI as given).

    Returns
    -------
    str
    """
    if isinstance(value, bool) or not isinstance(value, Real):
        return str(value)
    v = float(value)
    u = None
    if isinstance(uncertainty, Real) and not isinstance(uncertainty, bool):
        uf = float(uncertainty)
        if math.isfinite(uf) and uf > 0:
            u = uf
    scale, shown_unit = 1.0, unit
    if prefixes and unit == "m" and (abs(v) < 10.0 or not math.isfinite(v)):
        scale, shown_unit = 1e3, "mm"
    elif prefixes and unit in _AUTO_PREFIX_UNITS:
        ref = abs(v) if (v != 0 and math.isfinite(v)) else (u or 0.0)
        e = _prefix_exponent(ref)
        scale, shown_unit = 10.0 ** (-e), _PREFIXES[e] + unit
    sv = v * scale
    if isinstance(value, Integral) and scale == 1.0:
        text = str(int(value))
    elif not math.isfinite(sv):
        text = str(sv)
    elif u is not None:
        su = u * scale
        decimals = uncertainty_digits - 1 - math.floor(math.log10(su))
        decimals = max(0, min(decimals, 15))
        text = f"{sv:.{decimals}f} ± {su:.{decimals}f}"
    else:
        text = f"{sv:.{digits}g}"
    if shown_unit == "°":
        return f"{text}°" if u is None else f"({text})°"
    return f"{text} {shown_unit}".rstrip()


# ------------------------------------------------------------- parameters


def _flatten(tree: Mapping[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    out: list[tuple[str, Any]] = []
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.extend(_flatten(value, f"{name}."))
        else:
            out.append((name, value))
    return out


def _unit_for(name: str, units: Mapping[str, str]) -> str:
    if name in units:
        return units[name]
    leaf = name.rsplit(".", 1)[-1]
    if leaf in units:
        return units[leaf]
    if leaf.endswith("_deg"):
        return "°"
    if name.startswith("timings."):
        return "s"
    return ""


def _rows_from_parameters(parameters, units: Mapping[str, str]) -> list[tuple[str, Any, Any, str]]:
    if parameters is None:
        return []
    if isinstance(parameters, Mapping):
        body = {k: v for k, v in parameters.items() if k not in ("uncertainty", "warnings")}
        unc_tree = parameters.get("uncertainty", {})
        if not isinstance(unc_tree, Mapping):
            raise InputError("expected a nested dict like the values",
                             field="parameters.uncertainty")
        uncertainties = dict(_flatten(unc_tree))
        rows = []
        for name, value in _flatten(body):
            if isinstance(value, tuple) and len(value) == 3:
                v, u, unit = value
            else:
                v, u, unit = value, uncertainties.get(name), _unit_for(name, units)
            rows.append((name, v, u, unit))
        return rows
    rows = []
    for i, row in enumerate(parameters):
        if isinstance(row, str | bytes) or not isinstance(row, Sequence) or len(row) != 4:
            raise InputError(f"expected rows (name, value, uncertainty, unit), row {i} is {row!r}",
                             field="parameters")
        name, value, unc, unit = row
        rows.append((str(name), value, unc, "" if unit is None else str(unit)))
    return rows


def _parameter_table(rows: list[tuple[str, Any, Any, str]]) -> str:
    if not rows:
        return '<p class="sub">No parameters.</p>'
    parts = ['<table class="params"><thead><tr><th>parameter</th><th>value ± standard '
             "uncertainty</th><th>SI value</th></tr></thead><tbody>"]
    group = None
    for name, value, unc, unit in rows:
        head, _, leaf = name.rpartition(".")
        if head != group:
            group = head
            if head:
                parts.append(f'<tr class="group"><th colspan="3">{_esc(head)}</th></tr>')
        shown = format_quantity(value, unc, unit)
        raw = format_quantity(value, unc, unit, prefixes=False, digits=8)
        parts.append(f'<tr><td class="name">{_esc(leaf or name)}</td>'
                     f'<td class="value">{_esc(shown)}</td>'
                     f'<td class="value">{_esc(raw)}</td></tr>')
    parts.append("</tbody></table>")
    return "".join(parts)


def summary_html(summary: Mapping[str, Any], *, title: str,
                 units: Mapping[str, str] | None = None) -> str:
    """A ``summary.json``-like tree as an HTML table (value ± standard uncertainty),
    with its warnings: what the result objects show in Jupyter (``_repr_html_``).

    Parameters
    ----------
    summary : mapping
        Nested values in SI units, uncertainties in a parallel ``"uncertainty"`` tree,
        ``"warnings"`` a list of str; ``"timings"`` is left out.
    title : str
        Shown above the table.
    units : mapping of str to str, optional
        Units by dotted or leaf name; default :data:`DEFAULT_UNITS`.

    Returns
    -------
    str
        An HTML fragment with inline styles.

    Examples
    --------
    >>> html = summary_html({"lens_focus": 0.0603, "uncertainty": {"lens_focus": 0.0004},
    ...                      "warnings": ["scan clipped"]}, title="run")
    >>> "60.30 ± 0.40 mm" in html and "scan clipped" in html
    True
    """
    tree = {k: v for k, v in summary.items() if k != "timings"}
    def text(value: Any, unc: Any, unit: str) -> str:
        if isinstance(value, list | tuple):  # a short vector: 4 significant digits each
            return "(" + ", ".join(format_quantity(v, None, unit, digits=4)
                                   for v in value) + ")"
        return format_quantity(value, unc, unit)

    rows = [(name, text(value, unc, unit))
            for name, value, unc, unit in _rows_from_parameters(
                tree, DEFAULT_UNITS if units is None else units)
            if not isinstance(value, list | tuple) or 0 < len(value) <= 4]
    return html_table(title, rows, header=("parameter", "value ± standard uncertainty"),
                      notes=summary.get("warnings", ()))


# ----------------------------------------------------------------- figures


def _png_size(data: bytes) -> tuple[int, int]:
    width, height = struct.unpack(">II", data[16:24])
    return int(width), int(height)


def _normalise_sections(sections) -> list[tuple[str, list[tuple[Figure, str]]]]:
    out = []
    for i, section in enumerate(sections or ()):
        if not (isinstance(section, Sequence) and len(section) == 2):
            raise InputError(f"expected (heading, [(Figure, caption), ...]), item {i} is "
                             f"{type(section).__name__}", field="sections")
        heading, entries = section
        out.append((str(heading), _normalise_figures(entries, f"section {i} entry ",
                                                     "sections")))
    return out


def _normalise_figures(entries, where: str, field: str) -> list[tuple[Figure, str]]:
    figs = []
    for j, entry in enumerate(entries):
        if isinstance(entry, Figure):
            fig, caption = entry, None
        elif (isinstance(entry, Sequence) and len(entry) == 2
              and isinstance(entry[0], Figure)):
            fig, caption = entry
        else:
            raise InputError(f"expected a Figure or (Figure, caption), {where}{j} is "
                             f"{type(entry).__name__}", field=field)
        figs.append((fig, figure_caption(fig) if caption is None else str(caption)))
    return figs


# ---------------------------------------------------------------- metadata


def _metadata_block(metadata: Mapping[str, Any]) -> str:
    if not metadata:
        return '<p class="sub">No provenance recorded.</p>'
    parts = ['<dl class="meta">']
    for key, value in metadata.items():
        if isinstance(value, Mapping | list | tuple):
            text = json.dumps(value, indent=1, default=str, ensure_ascii=False)
            body = f"<pre>{_esc(text)}</pre>"
        else:
            body = f"<code>{_esc(value)}</code>" if isinstance(value, str) and len(value) >= 32 \
                else _esc(value)
        parts.append(f"<dt>{_esc(key)}</dt><dd>{body}</dd>")
    parts.append("</dl>")
    return "".join(parts)


# ------------------------------------------------------------------ report


def build_report(
    path: str | os.PathLike,
    *,
    title: str,
    parameters: Sequence[Sequence[Any]] | Mapping[str, Any] | None = None,
    sections: Iterable[tuple[str, Sequence[Figure | tuple[Figure, str | None]]]] = (),
    warnings: Iterable[str] = (),
    metadata: Mapping[str, Any] | None = None,
    units: Mapping[str, str] | None = None,
    dpi: float = 110.0,
    overwrite: bool = False,
    protect: Iterable[str | os.PathLike] = (),
    timestamp: bool = True,
) -> Path:
    """Write the characterization report: one self-contained HTML page.

    The page holds, in order: the title, the warnings (prominent, at the top),
    the parameter table (value ± standard uncertainty with units, and the
    plain SI value), one block per section with its figures (PNG embedded as
    base64 ``data:`` URIs) and captions, and the provenance block. It loads
    nothing from outside (inline CSS, no scripts, no links to the network).
    All text is HTML-escaped.

    The file is written atomically (:func:`holoprobe.io.atomic_write`):
    figures are rendered while a temporary file in the same directory is
    written, which is renamed onto ``path`` only when everything succeeded;
    on any error no file (partial or temporary) is left behind.

    Parameters
    ----------
    path : str or PathLike
        The output file (conventionally ``DIR/report.html``).
    title : str
        Page title.
    parameters : list of (name, value, uncertainty, unit) or nested dict, optional
        Rows: values in SI units (``unit`` names it: lengths in m are shown in
        mm, s / Hz / Pa / V with an SI prefix; ``uncertainty`` None for none).
        Or a nested dict shaped like ``summary.json``: dotted names become
        rows grouped by their parent key, a top-level ``"uncertainty"`` subtree
        gives the uncertainty of the same dotted name, a top-level
        ``"warnings"`` key is ignored (pass those as ``warnings``); leaves may
        also be ``(value, uncertainty, unit)`` tuples. Units of plain leaves
        come from ``units``.
    sections : iterable of (heading, [Figure or (Figure, caption), ...])
        Figure blocks. A bare Figure (or caption None) uses the caption its
        figure function attached (:func:`holoprobe.report.figure_caption`).
    warnings : iterable of str
        Shown at the top of the page.
    metadata : mapping, optional
        Provenance (input files and their SHA-256, configuration, versions,
        timings...). Nested values are shown as JSON.
    units : mapping, optional
        Units for dict-style ``parameters`` by dotted or leaf name; default
        :data:`DEFAULT_UNITS` (names ending in ``_deg`` are degrees).
    dpi : float
        Resolution of the embedded PNGs.
    overwrite : bool
        Replace an existing ``path`` (default: refuse, like all holoprobe outputs).
    protect : iterable of path
        Input files that ``path`` must never be.
    timestamp : bool
        Add the generation time (UTC) and holoprobe version to the provenance.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    InputError
        For malformed ``parameters`` or ``sections``, or an output path that
        :func:`holoprobe.io.atomic_write` refuses.
    """
    rows = _rows_from_parameters(parameters, DEFAULT_UNITS if units is None else units)
    figure_sections = _normalise_sections(sections)
    if isinstance(warnings, str):
        warnings = [warnings]
    warning_list = [str(w) for w in warnings]
    meta: dict[str, Any] = dict(metadata or {})
    if timestamp:
        from holoprobe import __version__

        meta.setdefault("holoprobe version", __version__)
        meta.setdefault("report generated (UTC)",
                        _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S"))
    if not float(dpi) > 0:
        raise InputError(f"expected a positive resolution, got {dpi}", field="dpi")

    nav = ['<a href="#parameters">Parameters</a>']
    for k, (heading, _) in enumerate(figure_sections):
        nav.append(_toc_item(f"section-{k + 1}", heading))
    nav.append(_TOC_END)
    nav.append('<a href="#provenance">Provenance</a>')
    n_figures = sum(len(f) for _, f in figure_sections)

    head = (
        f'<!DOCTYPE html>\n{_SIGNATURE}\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
        f"<title>{_esc(title)}</title>\n<style>{_CSS}</style>\n</head>\n<body>\n<main>\n"
        f"<header><h1>{_esc(title)}</h1>\n"
        f'<p class="sub">{len(rows)} parameters · {_COUNT_OPEN}{n_figures}{_COUNT_CLOSE} '
        "figures · "
        f"{len(warning_list)} warning{'s' if len(warning_list) != 1 else ''}</p></header>\n"
        f"<nav>{''.join(nav)}</nav>\n"
    )
    if warning_list:
        items = "".join(f"<li>{_esc(w)}</li>" for w in warning_list)
        warn_block = (f'<section class="warnings" id="warnings" role="alert">'
                      f"<h2>⚠ Warnings ({len(warning_list)})</h2><ul>{items}</ul></section>\n")
    else:
        warn_block = '<section class="ok" id="warnings">No warnings.</section>\n'
    param_block = (f'<section id="parameters"><h2>Parameters</h2>'
                   f"{_parameter_table(rows)}</section>\n")

    target = Path(path)
    with atomic_write(target, overwrite=overwrite, protect=protect) as tmp, \
            open(tmp, "w", encoding="utf-8") as fh:
        fh.write(head)
        fh.write(warn_block)
        fh.write(param_block)
        number = 0
        for k, (heading, figs) in enumerate(figure_sections):
            section_id = f"section-{k + 1}"
            fh.write(f'<!-- hp:section id="{section_id}" -->\n<section id="{section_id}">'
                     f"<h2>{_esc(heading)}</h2>\n")
            for fig, caption in figs:
                number += 1
                fh.write(_figure_html(fig, caption, number, float(dpi)))
            fh.write(f"</section>\n{_SECTION_CLOSE}\n")
        fh.write(f"{_SECTIONS_END}\n")
        fh.write(f'<section id="provenance"><h2>Provenance</h2>{_metadata_block(meta)}'
                 "</section>\n")
        fh.write("<footer>Written by holoprobe. Self-contained page: all figures are "
                 "embedded.</footer>\n</main>\n</body>\n</html>\n")
    return target


# ------------------------------------------------------------ add a section


def _slug(heading: str) -> str:
    words = re.findall(r"[a-z0-9]+", heading.lower())
    return "sec-" + ("-".join(words) or "section")


def _write_text(path: Path, text: str, *, chunk_chars: int = 1 << 20) -> None:
    with open(path, "w", encoding="utf-8") as fh:
        for start in range(0, len(text), chunk_chars):
            fh.write(text[start:start + chunk_chars])


def append_report_section(
    path: str | os.PathLike,
    heading: str,
    figures: Sequence[Figure | tuple[Figure, str | None]],
    *,
    parameters: Sequence[Sequence[Any]] | Mapping[str, Any] | None = None,
    replace: bool = True,
    section_id: str | None = None,
    notes: Iterable[str] = (),
    details: Mapping[str, Any] | None = None,
    units: Mapping[str, str] | None = None,
    dpi: float = 110.0,
    protect: Iterable[str | os.PathLike] = (),
) -> Path:
    """Add a section of figures to a report written by :func:`build_report`, or replace it.

    The section goes just before the provenance block (or where the section with the
    same id already is, when ``replace``), and gets an entry in the page's table of
    contents. Figures are numbered on from the page's figures (all figure numbers and
    the header's figure count are brought up to date). The page stays self-contained:
    PNGs embedded as base64 ``data:`` URIs, all text HTML-escaped. The page is located
    by its markers (see the module docstring), never by parsing its HTML otherwise.

    The file is rewritten atomically (:func:`holoprobe.io.atomic_write`): the figures
    are rendered first, the new page is written to a temporary file in the same
    directory and renamed onto ``path``; on any error ``path`` is left unchanged. Two
    processes appending to the same page at the same time may lose one of the sections
    (last writer wins); each stays a complete page.

    Parameters
    ----------
    path : str or PathLike
        A page written by :func:`build_report` (conventionally ``DIR/report.html``).
    heading : str
        Section heading (also the table-of-contents entry).
    figures : sequence of Figure or (Figure, caption)
        The section's figures; a bare Figure (or caption None) uses the caption its
        figure function attached (:func:`holoprobe.report.figure_caption`).
    parameters : list of (name, value, uncertainty, unit) or nested dict, optional
        A parameter table shown above the figures, as in :func:`build_report`.
    replace : bool
        If the page already has a section with this id, replace it in place (re-running
        an analysis never duplicates its section); if false, refuse with InputError.
    section_id : str, optional
        The section's HTML id (letters, digits, ``-``, ``_``; starting with a letter).
        Default ``"sec-"`` followed by the words of ``heading``: the same heading finds
        the same section.
    notes : iterable of str
        Remarks shown in a highlighted box under the heading (e.g. an analysis'
        warnings).
    details : mapping, optional
        Provenance of the section (inputs, criteria...), shown under its figures;
        nested values as JSON.
    units : mapping, optional
        Units for dict-style ``parameters``; default :data:`DEFAULT_UNITS`.
    dpi : float
        Resolution of the embedded PNGs.
    protect : iterable of path
        Input files that ``path`` must never be.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    InputError
        If ``path`` is missing or not a page written by this version of
        :func:`build_report` (its markers are missing), if the section exists and
        ``replace`` is false, or for a malformed ``heading``, ``section_id``,
        ``figures`` or ``parameters``.
    """
    target = Path(path)
    heading = str(heading)
    if not heading.strip():
        raise InputError("expected a non-empty heading", field="heading")
    sid = _slug(heading) if section_id is None else str(section_id)
    if not _ID.fullmatch(sid) or sid in _RESERVED_IDS:
        raise InputError(f"expected an id of letters, digits, '-' or '_' starting with a "
                         f"letter, other than {sorted(_RESERVED_IDS)}, got {sid!r}",
                         field="section_id")
    if isinstance(figures, Figure) or not isinstance(figures, Sequence):
        raise InputError("expected a list of Figure or (Figure, caption)", field="figures")
    figs = _normalise_figures(figures, "entry ", "figures")
    rows = _rows_from_parameters(parameters, DEFAULT_UNITS if units is None else units)
    if isinstance(notes, str):
        notes = [notes]
    note_list = [str(n) for n in notes]
    if not float(dpi) > 0:
        raise InputError(f"expected a positive resolution, got {dpi}", field="dpi")

    if not target.is_file():
        raise InputError("no report to add a section to (write it with build_report, e.g. "
                         "by 'holoprobe characterize')", file=str(target))
    try:
        text = target.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the report ({exc})", file=str(target)) from None
    for marker in (_SIGNATURE, _TOC_END, _SECTIONS_END):
        if text.count(marker) != 1:
            raise InputError(f"not a report written by holoprobe's build_report (marker "
                             f"{marker!r} missing or repeated); write it again with this "
                             "version", file=str(target))
    if len(_COUNT_RE.findall(text)) != 1:
        raise InputError("not a report written by holoprobe's build_report (figure-count "
                         "marker missing or repeated)", file=str(target))
    old_section = _section_re(sid).search(text)
    if old_section is not None and not replace:
        raise InputError(f"the report already has a section {sid!r}; pass replace=True to "
                         "replace it", file=str(target), field="section_id")

    # render everything before touching the file; numbers are fixed up below
    parts = [f'<!-- hp:section id="{sid}" -->\n<section id="{sid}"><h2>{_esc(heading)}</h2>\n']
    if note_list:
        items = "".join(f"<li>{_esc(n)}</li>" for n in note_list)
        parts.append(f'<div class="notes"><ul>{items}</ul></div>\n')
    if rows:
        parts.append(_parameter_table(rows) + "\n")
    parts.extend(_figure_html(fig, caption, 0, float(dpi)) for fig, caption in figs)
    if details:
        parts.append(_metadata_block(details) + "\n")
    parts.append(f"</section>\n{_SECTION_CLOSE}\n")
    block = "".join(parts)

    if old_section is not None:
        text = text[:old_section.start()] + block + text[old_section.end():]
    else:
        text = text.replace(_SECTIONS_END, block + _SECTIONS_END, 1)
    toc = _toc_item(sid, heading)
    old_toc = _toc_re(sid).search(text)
    if old_toc is not None:
        text = text[:old_toc.start()] + toc + text[old_toc.end():]
    else:
        text = text.replace(_TOC_END, toc + _TOC_END, 1)

    counter = 0

    def renumber(_: re.Match[str]) -> str:
        nonlocal counter
        counter += 1
        return f'<span class="fignum">Figure {counter}.</span>'

    text = _FIGNUM_RE.sub(renumber, text)
    text = _COUNT_RE.sub(f"{_COUNT_OPEN}{counter}{_COUNT_CLOSE}", text, count=1)

    with atomic_write(target, overwrite=True, protect=protect) as tmp:
        _write_text(tmp, text)
    return target
