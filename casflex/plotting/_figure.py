"""Figure plumbing shared by every plot: an Agg figure outside pyplot, atomic saving, release.

:func:`_new_figure` builds a :class:`matplotlib.figure.Figure` on its own Agg canvas (nothing
depends on, or changes, pyplot's global state or the interactive backend); :func:`_save` renders
it into memory and writes it with :func:`casflex.results.atomic_write_bytes` (format from the
file suffix, PNG by default).
"""

from __future__ import annotations

import io
import os
from pathlib import Path

from matplotlib.figure import Figure

from casflex import interrupt
from casflex.plotting._canvas import Canvas
from casflex.results import atomic_write_bytes

#: Resolution of saved PNG figures (dots per inch).
DPI = 120


def _new_figure(figsize: tuple[float, float], layout: str | None = "constrained") -> Figure:
    """A figure of ``figsize`` (inches) on its own Agg canvas (its texts rasterised once in the process:
    :mod:`casflex.plotting._canvas`); ``layout`` None for a grid laid out by hand (the constrained layout's cost
    grows with the square of the panels: minutes for a hundred)."""
    fig = Figure(figsize=figsize, layout=layout)
    Canvas(fig)
    return fig


#: zlib's level for PNG files: 1, not Pillow's 6, the same pixels in a file about 5 % larger, encoded in half the time
#: (a study's gait figure, 1080 x 2016 pixels: 0.13 -> 0.07 s of CPU)
PNG_COMPRESS_LEVEL = 1


def render(fig: Figure, fmt: str = "png", dpi: float = DPI) -> bytes:
    """``fig`` rendered into memory in format ``fmt`` (PNG at :data:`PNG_COMPRESS_LEVEL`)."""
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=dpi, **({"pil_kwargs": {"compress_level": PNG_COMPRESS_LEVEL}}
                                             if fmt == "png" else {}))
    interrupt.check()  # a Ctrl-C that matplotlib swallowed while rendering
    return buf.getvalue()


def _save(fig: Figure, path: str | os.PathLike[str] | None, dpi: float = DPI) -> None:
    """Render ``fig`` into memory and write it atomically to ``path`` (format from the suffix)."""
    if path is None:
        return
    path = Path(path)
    atomic_write_bytes(path, render(fig, path.suffix.lstrip(".").lower() or "png", dpi))


def _panel_grid(n: int, cols: int, size: tuple[float, float]) -> tuple[Figure, list]:
    """A figure of ``n`` panels, at most ``cols`` in a row, each ``size`` (inches): the figure and its axes in
    reading order (the grid's spare axes after the ``n`` used ones, for :func:`_finish_panels`)."""
    import numpy as np

    cols = min(cols, n)
    rows = -(-n // cols)
    fig = _new_figure((size[0] * cols, size[1] * rows))
    return fig, list(np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel())


def _finish_panels(fig: Figure, axes: list, n: int, title: str, path: str | os.PathLike[str] | None) -> None:
    """Hide the grid's spare axes, put the legend on the first panel, title the figure and save it."""
    for ax in axes[n:]:
        ax.set_visible(False)
    axes[0].legend(fontsize="x-small")
    fig.suptitle(title)
    _save(fig, path)


def _close(fig: Figure) -> None:
    """Drop a figure's artists (figures are not registered anywhere, so this only frees memory sooner)."""
    fig.clear()
