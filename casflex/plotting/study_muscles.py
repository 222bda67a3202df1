"""A study's muscle figure (``casflex study`` with ``[options.muscles]``): each reported joint's contact force
(the reaction's resultant, body weights) over the gait cycle, per subject the mean of its cycles with the mean of
their bands (1 SD: the muscles' parameters, the anthropometry, the markers, where the study asks for bands), and
the group's mean over the subjects."""

from __future__ import annotations

import os

import numpy as np

from casflex.plotting._figure import _finish_panels, _panel_grid

__all__ = ["plot_contact"]


def plot_contact(percent: np.ndarray, curves: dict[str, dict[str, tuple[np.ndarray, np.ndarray | None]]], title: str,
                 path: str | os.PathLike[str]) -> None:
    """One panel per joint: for every subject its cycles' mean (line) with the mean band shaded (where given), and
    the group's mean (black). ``curves``: joint -> subject -> (values (m, 101) BW, bands (m, 101) or None)."""
    names = list(curves)
    fig, axes = _panel_grid(len(names), 2, (5.0, 3.4))
    for ax, name in zip(axes, names, strict=False):
        means = []
        for subject, (v, b) in curves[name].items():
            mean = np.atleast_2d(v).mean(axis=0)
            means.append(mean)
            line, = ax.plot(percent, mean, lw=1.0, label=f"{subject} ({np.atleast_2d(v).shape[0]})")
            if b is not None:
                sd = np.atleast_2d(b).mean(axis=0)
                ax.fill_between(percent, mean - sd, mean + sd, color=line.get_color(), alpha=0.2, lw=0)
        if len(means) > 1:
            ax.plot(percent, np.mean(means, axis=0), color="k", lw=1.8, label="group")
        ax.set(title=f"{name.removesuffix('_resultant')}: contact force", xlabel="gait cycle (%)",
               ylabel="body weights")
        ax.grid(True, alpha=0.3)
    _finish_panels(fig, axes, len(names), title, path)
