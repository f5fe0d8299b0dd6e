"""PNG bytes of a matplotlib figure drawn once (shared by the report and the CLI figures)."""

from __future__ import annotations

import io

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.image import imsave

__all__ = ["PNG_COMPRESS_LEVEL", "png_bytes"]

PNG_COMPRESS_LEVEL = 1  # zlib level of the PNGs (0-9)


class _SavingCanvas(FigureCanvasAgg):
    """An Agg canvas that draws as ``savefig`` does (animated artists included)."""

    def is_saving(self) -> bool:
        return True


# (type: ignore below) matplotlib's PNG writer drops a key whose value is None; its stubs say str
_NO_SOFTWARE_TAG: dict[str, str] = {"Software": None}  # type: ignore[dict-item]


def png_bytes(fig: Figure, dpi: float) -> bytes:
    """The figure as PNG bytes (white background, no ``Software`` tag), drawn once.

    ``fig.savefig`` draws a figure that has a layout engine twice (once with drawing
    disabled to lay it out, then again with the layout switched off); one Agg draw, which
    lays the figure out first, makes the same pixels at half the cost. The figure's dpi,
    face colour and canvas are restored afterwards.
    """
    canvas, old_dpi, old_face = fig.canvas, fig.dpi, fig.get_facecolor()
    agg = _SavingCanvas(fig)
    try:
        fig.set_dpi(dpi)
        fig.set_facecolor("white")
        agg.draw()
        buf = io.BytesIO()
        # zlib level 1, not Pillow's 6: half the encoding time (15 figures of a full-size
        # report: 0.41 -> 0.21 s CPU) for 13 % more bytes
        imsave(buf, agg.buffer_rgba(), format="png", origin="upper", dpi=dpi,
               metadata=_NO_SOFTWARE_TAG, pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})
    finally:
        fig.set_dpi(old_dpi)
        fig.set_facecolor(old_face)
        fig.set_canvas(canvas)
    return buf.getvalue()
