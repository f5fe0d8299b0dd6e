"""A small HTML table for Jupyter (``_repr_html_`` of the result objects).

Every layer may use it (it imports nothing from holoprobe): the values arrive as
text, already formatted by the caller.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from html import escape

__all__ = ["html_table"]

_TABLE = ("border-collapse:collapse;font-size:0.92em;margin:0.3em 0;"
          "font-family:system-ui,-apple-system,'Segoe UI',Roboto,Arial,sans-serif")
_CELL = "padding:2px 10px;border-bottom:1px solid #e3e7ec;text-align:left;"
_GROUP = "padding:6px 10px 2px;text-align:left;color:#1f5fa8;font-weight:600;"


def html_table(title: str, rows: Iterable[Sequence[str]], *,
               header: Sequence[str] = ("parameter", "value"),
               notes: Iterable[str] = ()) -> str:
    """An HTML table with a title, grouped rows and a list of notes (warnings).

    Parameters
    ----------
    title : str
        Shown above the table.
    rows : iterable of sequence of str
        One row per parameter, as many cells as ``header``. A dotted first cell
        (``"aperture.width"``) is grouped under its prefix (``aperture``).
    header : sequence of str
        Column titles.
    notes : iterable of str
        Shown as a list below the table (e.g. the run's warnings).

    Returns
    -------
    str
        The HTML fragment (inline styles only, no scripts).

    Examples
    --------
    >>> html = html_table("run", [("aperture.width", "4.71 mm")])
    >>> "<th" in html and "aperture" in html and "4.71 mm" in html
    True
    """
    out = [f'<div class="holoprobe-repr"><strong>{escape(title)}</strong>',
           f'<table style="{_TABLE}"><thead><tr>']
    out += [f'<th style="{_CELL}">{escape(h)}</th>' for h in header]
    out.append("</tr></thead><tbody>")
    group = None
    for row in rows:
        head, _, leaf = str(row[0]).rpartition(".")
        if head != group:
            group = head
            if head:
                out.append(f'<tr><th colspan="{len(header)}" style="{_GROUP}">'
                           f"{escape(head)}</th></tr>")
        cells = [leaf or str(row[0]), *(str(c) for c in row[1:])]
        out.append("<tr>" + "".join(f'<td style="{_CELL}">{escape(c)}</td>' for c in cells)
                   + "</tr>")
    out.append("</tbody></table>")
    notes = list(notes)
    if notes:
        out.append('<ul style="margin:0.2em 0;color:#8a5a00">')
        out += [f"<li>{escape(str(n))}</li>" for n in notes]
        out.append("</ul>")
    out.append("</div>")
    return "".join(out)
