"""An image scraper for sphinx-gallery (used by ``conf.py``)."""

from __future__ import annotations


class FigureScraper:
    """Images of the figures an example built without pyplot (holoprobe's report
    functions return :class:`matplotlib.figure.Figure` objects that pyplot does not
    know): every such figure reachable from the example's variables (also inside
    lists, tuples and dicts) is saved once, in the order found."""

    def __repr__(self) -> str:  # a stable repr keeps Sphinx's environment cache valid
        return "FigureScraper"

    def __call__(self, block, block_vars, gallery_conf):
        import matplotlib.pyplot as plt
        from matplotlib.figure import Figure
        from sphinx_gallery.scrapers import figure_rst

        seen = gallery_conf.setdefault("_holoprobe_seen", {}).setdefault(
            block_vars["src_file"], set())
        # pyplot's figures are the "matplotlib" scraper's (this one runs first)
        seen.update(id(plt.figure(n)) for n in plt.get_fignums())
        found: list = []

        def walk(value, depth=0):
            if isinstance(value, Figure):
                if id(value) not in seen:
                    seen.add(id(value))
                    found.append(value)
            elif depth < 3 and isinstance(value, list | tuple):
                for item in value:
                    walk(item, depth + 1)
            elif depth < 3 and isinstance(value, dict):
                for item in value.values():
                    walk(item, depth + 1)

        for name, value in list(block_vars["example_globals"].items()):
            if not name.startswith("__"):
                walk(value)
        paths = []
        for fig, path in zip(found, block_vars["image_path_iterator"], strict=False):
            fig.savefig(path, dpi=110, bbox_inches="tight")
            paths.append(path)
        return figure_rst(paths, gallery_conf["src_dir"])

