"""A report figure's files: the PNG the Markdown shows and, beside it, the vector copies a paper takes."""

from __future__ import annotations

import contextvars
import os
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from workbench.atomic import atomic_path

__all__ = ["DPI", "VECTOR_FORMATS", "save_figure", "vector_figures"]

DPI = 300
#: The vector formats written beside every PNG (a paper takes these; the PNG is for the Markdown).
VECTOR_FORMATS = ("svg", "pdf")

#: Whether :func:`save_figure` writes the vector formats (off for the demo: ~5.5 s of its 30 s budget).
vector_figures = contextvars.ContextVar("vector_figures", default=True)


def save_figure(fig: Figure, path: str | os.PathLike) -> Path:
    """Render ``fig`` to a PNG at ``path`` and to SVG and PDF beside it (:data:`VECTOR_FORMATS`), each atomically."""
    path = Path(path)
    FigureCanvasAgg(fig)  # the Agg canvas: no pyplot, no global backend
    with atomic_path(path) as tmp:
        # the figure's own size, not a tight crop: a paper's column (3.5 in) or two (7.16 in) exactly
        fig.savefig(tmp, dpi=DPI, format="png")
    vector = VECTOR_FORMATS if vector_figures.get() else ()
    if not vector:
        return path
    # The layout the PNG was drawn with, kept for the vector copies: each savefig would otherwise run the
    # constrained layout again. The caller's figure gets its layout engine back.
    engine = fig.get_layout_engine()
    fig.set_layout_engine("none")
    try:
        for fmt in vector:
            with atomic_path(path.with_suffix(f".{fmt}")) as tmp:
                fig.savefig(tmp, format=fmt)
    finally:
        fig.set_layout_engine(engine)
    return path
