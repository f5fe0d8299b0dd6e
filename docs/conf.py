"""Sphinx configuration of the holoprobe documentation (``make docs``).

The API pages are written here from each public module's ``__all__`` so that the
reference can never miss a public name; the gallery runs ``examples/*.py``.
"""

from __future__ import annotations

import importlib
import re
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "src"))

import holoprobe  # noqa: E402

sys.path.insert(0, str(HERE))
from gallery_scraper import FigureScraper  # noqa: E402

project = "holoprobe"
author = "holoprobe developers"
copyright = "2026, holoprobe developers"
release = version = holoprobe.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
    "sphinx_design",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "auto_examples/*.ipynb",
                    "auto_examples/*.py", "auto_examples/*.zip", "**.codeobj.json"]
templates_path = ["_templates"]
html_static_path = ["_static"]

# ---------------------------------------------------------------- API reference
#: The public modules documented in the API reference, in layer order (top first).
API_MODULES = [
    ("holoprobe.workflow", "Workflow: one characterization run"),
    ("holoprobe.analysis", "Analyses of a characterized probe"),
    ("holoprobe.report", "Figures and the HTML report"),
    ("holoprobe.exposure", "Acoustic output (IEC)"),
    ("holoprobe.export", "Exports to simulators and scanners"),
    ("holoprobe.transducer", "The virtual transducer"),
    ("holoprobe.characterize", "Estimation steps"),
    ("holoprobe.simulate", "Digital twins with known truth"),
    ("holoprobe.propagation", "Propagation"),
    ("holoprobe.signal", "Signal processing"),
    ("holoprobe.io", "Files"),
    ("holoprobe.measurement", "Measurement nouns"),
    ("holoprobe.geometry", "Geometry and medium"),
    ("holoprobe.lens", "Lens law"),
    ("holoprobe.errors", "Errors"),
]


def _write_api_pages() -> None:
    """Write ``api/<module>.rst`` (an autosummary of every name in ``__all__``) and the
    API index; files are rewritten only when their text changes (incremental builds)."""
    out = HERE / "api"
    out.mkdir(exist_ok=True)
    index = ["API reference", "=============", "",
             "Every public name of holoprobe, module by module, generated from the",
             "docstrings (numpydoc: parameters with their units and shapes). The modules",
             "are listed in layer order: a module imports only from those below it",
             "(:doc:`../architecture`).", "", ".. toctree::", "   :maxdepth: 1", ""]
    for name, title in API_MODULES:
        module = importlib.import_module(name)
        names = sorted(n for n in getattr(module, "__all__", []) if not n.startswith("__"))
        heading = f"``{name}``: {title}"
        lines = [heading, "=" * len(heading), "", f".. automodule:: {name}", "   :no-members:",
                 "", f".. currentmodule:: {name}", ""]
        if names:
            lines += [".. autosummary::", "   :toctree: generated", "   :nosignatures:", ""]
            lines += [f"   {n}" for n in names]
            lines.append("")
        _write_if_changed(out / f"{name}.rst", "\n".join(lines))
        index.append(f"   {name}")
    _write_if_changed(out / "index.rst", "\n".join(index) + "\n")
    # a name removed from an __all__ leaves its stub behind (autosummary never deletes)
    current = {f"{name}.{n}" for name, _ in API_MODULES
               for n in getattr(importlib.import_module(name), "__all__", [])}
    for stub in (out / "generated").glob("*.rst"):
        if stub.stem not in current:
            stub.unlink()


def _write_if_changed(path: Path, text: str) -> None:
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


_write_api_pages()

autosummary_generate = True
autosummary_imported_members = True
autodoc_default_options = {"members": True, "inherited-members": False,
                           "show-inheritance": False}
autodoc_typehints = "none"
autoclass_content = "class"
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set[str] = set()

# ---------------------------------------------------------------- markdown pages
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist"]
myst_heading_anchors = 3

# ---------------------------------------------------------------- gallery



sphinx_gallery_conf = {
    "examples_dirs": str(HERE.parent / "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "ignore_pattern": r"__init__\.py",
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "show_memory": False,
    "matplotlib_animations": False,
    "image_scrapers": (FigureScraper(), "matplotlib"),
    "capture_repr": ("_repr_html_",),
    "write_computation_times": False,
    "min_reported_time": 1,
}



# ---------------------------------------------------------------- HTML
html_theme = "pydata_sphinx_theme"
html_title = f"holoprobe {release}"
html_show_sourcelink = False
html_css_files = ["holoprobe.css"]
html_theme_options = {
    "navbar_align": "left",
    "header_links_before_dropdown": 6,
    "show_toc_level": 2,
    "navigation_with_keys": False,
    "secondary_sidebar_items": ["page-toc"],
    "footer_start": ["copyright"],
    "footer_end": ["sphinx-version"],
    "logo": {"text": "holoprobe"},
}
html_sidebars = {"index": [], "**": ["sidebar-nav-bs"]}
html_context = {"default_mode": "light"}


# ---------------------------------------------------------------- docstring text
_LITERAL = re.compile(r"(``.*?``|`[^`]*`)")


def _escape_bars(app, what, name, obj, options, lines: list[str]) -> None:
    """holoprobe's docstrings write magnitudes as |p| (plain text, as in the terminal);
    reStructuredText would read them as substitutions. Escape every bar outside
    literals and roles."""
    for i, line in enumerate(lines):
        if "|" in line:
            parts = _LITERAL.split(line)
            lines[i] = "".join(p if j % 2 else p.replace("|", r"\|") for j, p in enumerate(parts))


def setup(app):
    app.connect("autodoc-process-docstring", _escape_bars, priority=600)
