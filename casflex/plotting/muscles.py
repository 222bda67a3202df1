"""Figures of a trial's muscles (:class:`casflex.muscles.result.MuscleResult`): the joints' reaction forces in body
weights with their bands, and the muscles' activations."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from casflex.plotting._figure import _new_figure, _save

__all__ = ["FIGURES", "plot_activations", "plot_reactions", "save_muscle_figures"]

#: The files :func:`save_muscle_figures` writes.
FIGURES = ("joint_reactions.png", "activations.png")


def plot_reactions(res, path: str | os.PathLike[str] | None = None) -> Figure:
    """Each joint's reaction force (the magnitude, in body weights) over the trial, its band (one standard
    deviation, shaded) where the result has one and the other criterion's (dashed) where asked; the hip first."""
    fig = _new_figure((7.5, 4.0))
    ax = fig.subplots()
    w = res.body_weight
    joints = sorted(res.resultants, key=lambda j: (not j.startswith("hip"), j))
    for k, joint in enumerate(joints):
        v = res.resultants[joint] / w
        ax.plot(res.t, v, color=f"C{k}", lw=1.6 if k == 0 else 1.1, label=joint)
        band = res.bands.get(f"{joint}_resultant")
        if band is not None:
            ax.fill_between(res.t, v - band / w, v + band / w, color=f"C{k}", alpha=0.25, lw=0)
        other = res.spread.get(f"{joint}_resultant")
        if other is not None:
            ax.plot(res.t, v + other / w, color=f"C{k}", lw=0.9, ls="--")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("joint reaction force (body weights)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    fig.suptitle("joint reactions" + (" (shaded: 1 SD)" if res.bands else "")
                 + (" (dashed: other criterion)" if res.spread else ""))
    _save(fig, path)
    return fig


def plot_activations(res, path: str | os.PathLike[str] | None = None, emg=None) -> Figure:
    """Each muscle's activation over the trial, one small panel each; ``emg`` (muscle -> (k,) the EMG's envelope
    at the frames, normalised to its peak: :func:`casflex.muscles.emg.emg_envelopes`) drawn beside it, grey, for
    its timing (on or off), not its height."""
    emg = emg or {}
    n = len(res.muscles)
    cols = min(n, 4)
    rows = int(np.ceil(n / cols))
    w, h = 2.2 * cols + 1.0, 1.5 * rows + 0.8
    fig = _new_figure((w, h), layout=None)  # by hand: shared axes and the constrained layout are quadratic in panels
    fig.subplots_adjust(left=0.7 / w, right=1 - 0.3 / w, bottom=0.75 / h, top=1 - 0.7 / h, wspace=0.12,
                        hspace=0.45 * 1.5 / 1.2)
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    t0, t1 = float(res.t[0]), float(res.t[-1])
    span = (t0, t1) if t1 > t0 else (t0 - 0.5, t0 + 0.5)  # one frame: a second around it
    for i, ax in enumerate(axes):
        if i >= n:
            ax.set_visible(False)
            continue
        ax.plot(res.t, res.activations[:, i], color="C0", lw=1.0)
        if res.muscles[i] in emg:
            ax.fill_between(res.t, 0.0, emg[res.muscles[i]], color="0.6", alpha=0.4, lw=0)
        ax.set_title(res.muscles[i], fontsize=8)
        ax.set(xlim=span, ylim=(0.0, 1.0), yticks=(0.0, 0.5, 1.0))
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.tick_params(labelsize=7, labelleft=i % cols == 0, labelbottom=i + cols >= n)  # the outer panels' labels
        ax.grid(alpha=0.3)
    fig.supxlabel("t (s)", y=0.25 / h)
    fig.supylabel("activation")
    if emg:
        fig.suptitle("grey: EMG envelope over its peak (timing only)", fontsize=9, y=1 - 0.3 / h)
    _save(fig, path)
    return fig


def save_muscle_figures(res, directory: str | os.PathLike[str], emg=None) -> list[Path]:
    """:data:`FIGURES` in ``directory`` (``emg``: :func:`plot_activations`')."""
    d = Path(directory)
    paths = [d / name for name in FIGURES]
    plot_reactions(res, paths[0])
    plot_activations(res, paths[1], emg)
    return paths
