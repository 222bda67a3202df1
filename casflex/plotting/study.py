"""A study's figures (``casflex study``): each load over the gait cycle, per subject the mean and spread of its
cycles, and the group's mean and spread over the subjects' means, as labs report gait."""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from casflex.plotting._figure import _finish_panels, _panel_grid

__all__ = ["plot_cycles"]


def plot_cycles(percent: np.ndarray, curves: dict[str, dict[str, np.ndarray]], title: str,
                path: str | os.PathLike[str], loads: Sequence[str] | None = None,
                units: dict[str, str] | None = None) -> None:
    """One panel per load: for every label (a subject, or the group), the mean (line) and +- one standard
    deviation (shaded) of its curves (m, 101) over ``percent`` (0-100 % of the gait cycle). ``curves``:
    load -> label -> (m, 101) in the load's unit (``units[load]``; default N for a force, else N m)."""
    names = list(loads or curves)
    fig, axes = _panel_grid(len(names), 3, (4.2, 3.0))
    for ax, name in zip(axes, names, strict=False):
        for label, c in curves[name].items():
            c = np.atleast_2d(c)
            mean, sd = c.mean(axis=0), c.std(axis=0, ddof=1) if c.shape[0] > 1 else np.zeros(c.shape[1])
            line, = ax.plot(percent, mean, label=f"{label} ({c.shape[0]})")
            ax.fill_between(percent, mean - sd, mean + sd, color=line.get_color(), alpha=0.2, lw=0)
        unit = (units or {}).get(name) or ("N" if name.endswith(("_force", "fx", "fy")) else "N m")
        ax.set(title=name, xlabel="gait cycle (%)", ylabel=unit)
        ax.axhline(0.0, color="0.6", lw=0.6)
        ax.grid(True, alpha=0.3)
    _finish_panels(fig, axes, len(names), title, path)
