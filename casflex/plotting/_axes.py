"""Axes whose axes draw their ticks in fewer Python calls: the same renderer calls' pixels as matplotlib's.

matplotlib's :meth:`matplotlib.axis.Axis.draw` finds the axis's ticks (locator, formatter, each tick moved and
relabelled) three times a draw (for the ticks, for the axis label's place, for the spine's extent beside it), measures
the tick labels twice, and draws each tick's grid line, tick mark and labels as artists of their own: a study's gait
figure (12 panels, 24 axes, 130 ticks) spent half its drawing there. :class:`Axes` draws each axis as matplotlib
does but with its ticks found and their labels measured once a draw, and the ticks' grid lines as one line and
their marks as one line of markers (each part drawn with the first tick's artist, its data the ticks' together):
Agg rasterises the grid lines' segments, which do not overlap, and stamps each mark as it does one by one, so the
pixels are the same (a test compares a figure with matplotlib's own axes). Where the ticks' parts differ in
anything but their place (a tick styled on its own), each tick is drawn as matplotlib draws it.
"""

from __future__ import annotations

import numpy as np
from matplotlib import axis as maxis
from matplotlib.axes import Axes as _MplAxes

#: what makes a tick part's pixels besides its data, compared on every tick before they are drawn as one line (the
#: rest, a line's caps, joins, snapping, clipping, effects, is what the axis gives every tick: set on a tick's line
#: alone it is not compared)
_STYLE = ("get_visible", "get_color", "get_alpha", "get_linewidth", "get_linestyle", "get_marker", "get_markersize",
          "get_markeredgewidth", "get_transform", "get_clip_box")


def _same_style(lines: list) -> bool:
    first = lines[0]
    for getter in _STYLE:
        want = getattr(first, getter)()
        if any(not _equal(getattr(ln, getter)(), want) for ln in lines[1:]):
            return False
    return True


def _equal(a, b) -> bool:
    if a is b:
        return True
    try:
        same = a == b
        return bool(np.all(same)) if not isinstance(same, bool) else same
    except (TypeError, ValueError):
        return False


def _draw_part(lines: list, renderer, axis_name: str) -> None:
    """The ticks' lines of one part (their grid lines, or their marks) drawn as the first one's line through all
    their places (NaN between them: separate segments, as drawn one by one)."""
    first = lines[0]
    if len(lines) == 1 or not _same_style(lines):
        for ln in lines:
            ln.draw(renderer)
        return
    xs, ys = first.get_xdata(orig=True), first.get_ydata(orig=True)
    n = max(len(np.atleast_1d(xs)), len(np.atleast_1d(ys)))
    across = np.broadcast_to(np.asarray(ys if axis_name == "x" else xs, dtype=float), (n,))
    places = [float(np.atleast_1d(ln.get_xdata(orig=True) if axis_name == "x" else ln.get_ydata(orig=True))[0])
              for ln in lines]
    gap = [np.nan] if n > 1 else []  # a mark's single point needs no break: markers are stamped point by point
    along = np.concatenate([[p] * n + gap for p in places])
    other = np.concatenate([[*across] + gap for _ in places])
    try:
        first.set_data((along, other) if axis_name == "x" else (other, along))
        first.draw(renderer)
    finally:
        first.set_data(xs, ys)


class _Once:
    """An axis drawn as :meth:`matplotlib.axis.Axis.draw` draws it (module docstring), its ticks found and their
    labels measured once."""

    def draw(self, renderer) -> None:  # noqa: D102 - matplotlib's
        if not self.get_visible():
            return
        renderer.open_group(maxis.__name__, gid=self.get_gid())
        ticks = self._update_ticks()
        boxes = self._get_ticklabel_bboxes(ticks, renderer)
        self._update_ticks = lambda: ticks  # what the label's and the spine's places ask for again in this draw
        self._get_ticklabel_bboxes = lambda t, r: boxes if t is ticks and r is renderer else \
            type(self)._get_ticklabel_bboxes(self, t, r)
        try:
            self._draw_ticks(ticks, renderer)
            self._update_label_position(renderer)
            self.label.draw(renderer)
            self._update_offset_text_position(*boxes)
            self.offsetText.set_text(self.major.formatter.get_offset())
            self.offsetText.draw(renderer)
        finally:
            del self._update_ticks, self._get_ticklabel_bboxes
        renderer.close_group(maxis.__name__)
        self.stale = False

    def _draw_ticks(self, ticks: list, renderer) -> None:
        shown = [t for t in ticks if t.get_visible()]
        if any(t.get_rasterized() or t.get_agg_filter() is not None or t.get_gid() is not None for t in shown):
            for t in shown:  # drawn by matplotlib's decorator, one by one
                t.draw(renderer)
            return
        for part in ("gridline", "tick1line", "tick2line"):
            lines = [getattr(t, part) for t in shown]
            lines = [ln for ln in lines if ln.get_visible()]
            if lines:
                _draw_part(lines, renderer, self.axis_name)
        for t in shown:
            t.label1.draw(renderer)
            t.label2.draw(renderer)
        for t in ticks:
            t.stale = False


class XAxis(_Once, maxis.XAxis):
    """matplotlib's x axis, drawn by :class:`_Once`."""


class YAxis(_Once, maxis.YAxis):
    """matplotlib's y axis, drawn by :class:`_Once`."""


class Axes(_MplAxes):
    """matplotlib's Axes with :class:`XAxis` and :class:`YAxis` (module docstring)."""

    def _init_axis(self) -> None:
        self.xaxis = XAxis(self, clear=False)
        self.spines.bottom.register_axis(self.xaxis)
        self.spines.top.register_axis(self.xaxis)
        self.yaxis = YAxis(self, clear=False)
        self.spines.left.register_axis(self.yaxis)
        self.spines.right.register_axis(self.yaxis)
