"""Figures of an inverse dynamics run (:class:`casflex.inverse.InverseResult`): net joint moments,
intersegmental forces, the root's loads and the marker fit."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from casflex.plotting._figure import _new_figure, _save

__all__ = ["plot_inverse", "save_inverse_figures"]


def plot_inverse(res, path: str | os.PathLike[str] | None = None) -> Figure:
    """Three panels over time: the net joint moments (N m; their bands, one standard deviation, shaded where
    ``res.bands`` has them), the hinges' intersegmental forces (N, x and y, global) and the root's loads (N; its
    moment N m on the right axis)."""
    fig = _new_figure((7.5, 8.0))
    ax_m, ax_f, ax_r = fig.subplots(3, 1, sharex=True)
    for k, name in enumerate(res.settings.get("moments", ())):
        ax_m.plot(res.t, res.loads[name], color=f"C{k}", lw=1.4, label=name.removesuffix(".moment"))
        band = getattr(res, "bands", {}).get(name)
        if band is not None:  # one standard deviation, anthropometry and markers together
            v = res.loads[name]
            ax_m.fill_between(res.t, v - band["total"], v + band["total"], color=f"C{k}", alpha=0.25, lw=0)
        h = name.removesuffix(".moment")
        for comp, ls in (("fx", "--"), ("fy", "-")):
            if f"{h}.{comp}" in res.loads:
                ax_f.plot(res.t, res.loads[f"{h}.{comp}"], color=f"C{k}", ls=ls, lw=1.2, label=f"{h} {comp[1]}")
    ax_m.set_ylabel("net joint moment (N m)")
    ax_m.legend(fontsize=8, ncols=4, loc="upper left")
    ax_f.set_ylabel("intersegmental force (N)")
    ax_f.legend(fontsize=7, ncols=4, loc="upper left")
    ax_r.plot(res.t, res.loads["root.fx"], color="C0", lw=1.2, label="root fx")
    ax_r.plot(res.t, res.loads["root.fy"], color="C1", lw=1.2, label="root fy")
    ax_r.set_ylabel("root force (N)")
    twin = ax_r.twinx()
    twin.plot(res.t, res.loads["root.mz"], color="C3", lw=1.2, ls=":", label="root mz")
    twin.set_ylabel("root moment (N m)")
    ax_r.legend(fontsize=8, loc="upper left")
    twin.legend(fontsize=8, loc="upper right")
    ax_r.set_xlabel("t (s)")
    for ax in (ax_m, ax_f, ax_r):
        ax.axhline(0.0, color="0.6", lw=0.6)
        ax.grid(alpha=0.3)
    cut = res.settings.get("cutoff_hz")
    fig.suptitle(f"inverse dynamics: {res.settings.get('scene', '')}"
                 + (f", filtered at {cut:g} Hz" if cut else ", unfiltered"))
    _save(fig, path)
    return fig


def plot_marker_fit(res, path: str | os.PathLike[str] | None = None) -> Figure:
    """The markers' RMS misfit (mm) per frame of the kinematic fit."""
    fig = _new_figure((7.0, 3.0))
    ax = fig.subplots()
    ax.plot(res.frame_t, 1e3 * np.asarray(res.marker_rms), color="C0", lw=1.2)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("marker misfit RMS (mm)")
    ax.grid(alpha=0.3)
    _save(fig, path)
    return fig


#: The files :func:`save_inverse_figures` writes (the second where markers were fitted).
FIGURES = ("inverse_loads.png", "marker_fit.png")


def save_inverse_figures(res, directory: str | os.PathLike[str]) -> list[Path]:
    """``inverse_loads.png`` and ``marker_fit.png`` (where markers were fitted) in ``directory``."""
    d = Path(directory)
    paths = [d / name for name in FIGURES]
    plot_inverse(res, paths[0])
    if not res.marker_labels:  # coordinates given: no marker fit to show
        return paths[:1]
    plot_marker_fit(res, paths[1])
    return paths
