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

import numpy as np
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


def render(fig: Figure, fmt: str = "png", dpi: float = DPI) -> bytes:
    """``fig`` rendered into memory in format ``fmt`` (a PNG by :mod:`casflex.plotting._png`, the canvas's)."""
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=dpi)
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


#: the margins' and gaps' padding of :func:`_fit_column` (inches): the constrained layout's default (3 points)
#: and a little more
PAD = 4.0 / 72.0


def _fit_column(fig: Figure, axes: list, height_ratios: list[float] | None = None) -> None:
    """Lay out ``axes``, one column of panels top to bottom, by hand where the constrained layout would: every
    margin and gap just holding the panels' tick labels, axis labels, titles and legends (:data:`PAD` beside them),
    the y axes' labels aligned left of every panel's tick labels, the figure's title (``suptitle``, if any) above.
    Each panel measured once, and again where its new size gave it other ticks (the constrained layout
    measures each twice and draws the figure once more to do so; ``align_ylabels`` measures every panel's tick
    labels for every panel's label at each draw). At the figure's saved dpi (:data:`DPI`): the same pixels."""
    fig.set_dpi(DPI)
    renderer = fig.canvas.get_renderer()
    n, inch = len(axes), DPI
    # first placed where such figures' panels end up (tick labels of 4-5 characters, maybe a title or legend above
    # the first panel, the time axis's labels under the last), so that the panels measured there keep their ticks
    _place(fig, axes, renderer, (-0.42 * inch, 0.6 * inch, 0.1 * inch, *[0.1 * inch] + [0.0] * (n - 1),
                                 *[0.05 * inch] * (n - 1) + [0.45 * inch]), height_ratios)
    for _ in range(3):  # a panel's new size may give it other ticks (other labels' widths): measured again
        ticks = _ticks(axes)
        _place(fig, axes, renderer, _margins(axes, renderer), height_ratios)
        if _ticks(axes) == ticks:
            break


def _ticks(axes: list) -> list[tuple]:
    """Each panel's ticks (where its locators put them for its size and limits)."""
    return [(tuple(ax.xaxis.get_majorticklocs()), tuple(ax.yaxis.get_majorticklocs())) for ax in axes]


def _margins(axes: list, renderer) -> tuple[float, ...]:
    """(the y labels' anchor left of the panels, the margin left of them, right of them, then above and below each
    panel) in pixels, as they are now, each y label's placed at the anchor (its right edge: the label's side
    facing the panel)."""
    dpi = renderer.dpi
    anchor = 0.0
    for ax in axes:
        box = ax.get_window_extent(renderer)
        shown = ax.yaxis.label.get_visible()
        ax.yaxis.label.set_visible(False)  # the tick labels' and the offset's extent, without the label
        ticks = ax.yaxis.get_tightbbox(renderer)
        ax.yaxis.label.set_visible(shown)
        left = min(box.x0, ticks.x0) if ticks is not None else box.x0
        anchor = min(anchor, left - box.x0 - ax.yaxis.labelpad * dpi / 72)
    for ax in axes:
        ax.yaxis.set_label_coords(anchor / ax.get_window_extent(renderer).width, 0.5)
    boxes = [(ax.get_window_extent(renderer).frozen(), ax.get_tightbbox(renderer)) for ax in axes]
    return (anchor, max(box.x0 - tight.x0 for box, tight in boxes),
            max(0.0, max(tight.x1 - box.x1 for box, tight in boxes)),
            *(max(0.0, tight.y1 - box.y1) for box, tight in boxes),  # titles, legends above a panel
            *(max(0.0, box.y0 - tight.y0) for box, tight in boxes))  # tick labels and axis label under it


def _place(fig: Figure, axes: list, renderer, needed: tuple[float, ...], height_ratios: list[float] | None) -> None:
    """The panels placed for the margins ``needed`` (:func:`_margins`), the y labels at their anchor."""
    width, height = fig.get_size_inches() * DPI
    pad = PAD * DPI
    n = len(axes)
    anchor, left, right = needed[:3]
    above, below = needed[3:3 + n], needed[3 + n:]
    title = fig._suptitle.get_window_extent(renderer).height + pad if fig._suptitle is not None else 0.0
    top, bottom = pad + title + above[0], below[-1] + pad
    gaps = [below[i] + above[i + 1] + pad for i in range(n - 1)]
    ratios = np.asarray(height_ratios or [1.0] * n, dtype=float)
    heights = (height - top - bottom - sum(gaps)) * ratios / ratios.sum()
    w = width - left - right - 2 * pad
    y = height - top
    for i, ax in enumerate(axes):
        y -= heights[i]
        ax.set_position([(left + pad) / width, y / height, w / width, heights[i] / height])
        ax.yaxis.set_label_coords(anchor / w, 0.5)
        y -= gaps[i] if i < len(gaps) else 0.0
    if fig._suptitle is not None:
        fig._suptitle.set_y(1.0 - pad / height)
