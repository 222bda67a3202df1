"""casflex's Axes (casflex.plotting._axes): each axis's ticks found once a draw and their grid lines and marks drawn
as one line each, the pixels of matplotlib's own axes (issue 49: a study's gait figures' CPU)."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.axes import Axes as MplAxes

from casflex.plotting import _axes
from casflex.plotting._figure import _new_figure, render


def _figure(axes_class, restyle=None) -> bytes:
    """Six panels of curves, grids, ticks on all four sides in and out, labels on every side, an offset text."""
    rng = np.random.default_rng(3)
    fig = _new_figure((8.0, 7.0), layout=None)
    axes = fig.subplots(3, 2, subplot_kw={"axes_class": axes_class}).ravel()
    for k, ax in enumerate(axes):
        x = np.linspace(0.0, 100.0, 101)
        ax.plot(x, np.cumsum(rng.normal(0.0, 1.0 + 3 * k, x.size)) + (1e5 if k == 5 else 0.0))
        ax.fill_between(x, -k, k + 1, alpha=0.2)
        ax.grid(True, alpha=0.3 + 0.1 * k, which="both" if k == 3 else "major")
        ax.set_title(f"panel {k}")
        ax.set_ylabel("N m")
        if k % 2:
            ax.tick_params(direction="in" if k == 1 else "inout", right=True, top=True, labelright=True,
                           labeltop=k == 3, length=6)
        if k == 3:
            ax.minorticks_on()
    axes[-1].set_xlabel("gait cycle (%)")
    if restyle is not None:
        render(fig)  # the ticks made, then one of them styled on its own
        restyle(axes)
    return render(fig)


def test_an_axis_s_ticks_drawn_at_once_are_matplotlib_s_pixels():
    # each axis's grid lines one line, its marks one line of markers, found and measured once: the same PNG
    assert _figure(_axes.Axes) == _figure(MplAxes)


@pytest.mark.parametrize("restyle", [
    lambda axes: axes[0].yaxis.get_major_ticks()[1].gridline.set_color("red"),
    lambda axes: axes[2].xaxis.get_major_ticks()[2].tick1line.set_markersize(12.0),
    lambda axes: axes[1].yaxis.get_major_ticks()[0].set_visible(False),
])
def test_a_tick_styled_on_its_own_is_drawn_as_matplotlib_draws_it(restyle):
    assert _figure(_axes.Axes, restyle) == _figure(MplAxes, restyle)


def test_the_ticks_are_found_once_a_draw(monkeypatch):
    from matplotlib import axis

    calls = {"n": 0}
    found = axis.Axis._update_ticks

    def counted(self):
        calls["n"] += 1
        return found(self)

    monkeypatch.setattr(axis.Axis, "_update_ticks", counted)
    fig = _new_figure((4.0, 3.0), layout=None)
    ax = fig.add_subplot(axes_class=_axes.Axes)
    ax.plot([0.0, 1.0], [0.0, 2.0])
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    render(fig)
    assert calls["n"] == 2  # once for each axis (matplotlib's own: three times each)
