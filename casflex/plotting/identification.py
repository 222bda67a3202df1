"""Figures of an output-error identification: the measured motion against the identified model's,
the residuals, and their autocorrelation (what a reviewer asks to see before trusting the numbers).

Positions in m or rad, residuals in mm or mrad, time in s.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from casflex.identification.result import IdentificationResult
from casflex.plotting._figure import _close, _new_figure, _save

__all__ = ["plot_fit", "plot_residual_autocorrelation", "save_identification_figures"]


def _unit(channel: str) -> tuple[str, float]:
    """(residual unit, factor from the data's unit) for a channel."""
    return ("mrad", 1e3) if channel.startswith("theta") else ("mm", 1e3)


def plot_fit(result: IdentificationResult, experiment: int = 0, path: str | os.PathLike[str] | None = None) -> Figure:
    """Every channel of one experiment: measured samples and the identified model's motion (left),
    residuals measured - model with the +-2 RMS band (right)."""
    s = result.samples[experiment]
    tr = result.trajectories[experiment]
    names = s["channels"]
    fig = _new_figure((9.0, 1.9 * len(names) + 0.8))
    axes = fig.subplots(len(names), 2, sharex=True, squeeze=False, width_ratios=[3, 2])
    res = result.extra.get("experiments", {}).get(s["name"], {}).get("residuals", {})
    for c, name in enumerate(names):
        mine = s["channel"] == c
        t, y, ym = s["t"][mine], s["measured"][mine], s["model"][mine]
        left, right = axes[c]
        left.plot(t, y, ".", color="C3", ms=2.5, alpha=0.7, label="measured")
        left.plot(tr.t, tr.channel(name), color="C0", lw=1.0, zorder=3, label="identified model")
        unit = "rad" if name.startswith("theta") else "m"
        left.set_ylabel(f"{name} ({unit})")
        ru, k = _unit(name)
        r = k * (y - ym)
        right.plot(t, r, ".", color="C3", ms=2.5)
        rms = k * res[name]["rms"] if name in res else float(np.sqrt(np.mean(r**2)))
        right.axhspan(-2 * rms, 2 * rms, color="C0", alpha=0.12, lw=0)
        right.axhline(0.0, color="black", lw=0.6)
        fit = f"fit {100 * res[name]['fit']:.2f} %" if res.get(name, {}).get("fit") is not None else "no motion"
        white = "" if name not in res else ("white" if res[name]["white"] else "not white")
        right.set_title(f"residual, RMS {rms:.3g} {ru}; {fit}, {white}", fontsize="small")
        right.set_ylabel(ru)
        for ax in (left, right):
            ax.grid(True, alpha=0.3)
    axes[0][0].legend(loc="best", fontsize="small", frameon=False)
    for ax in axes[-1]:
        ax.set_xlabel("time t (s)")
    fig.suptitle(f"{tr.meta.get('scene', '')}: {s['name']}, measured and identified "
                 f"({'success' if result.success else 'NOT successful'})")
    _save(fig, path)
    return fig


def plot_residual_autocorrelation(result: IdentificationResult, path: str | os.PathLike[str] | None = None) -> Figure:
    """Autocorrelation of the residuals of every channel of every experiment, with the band
    +-1.96 / sqrt(n) inside which 95 % of a white sequence's values fall."""
    fig = _new_figure((7.0, 4.0))
    ax = fig.subplots()
    n_min = None
    for name, exp in result.extra.get("experiments", {}).items():
        for c, ch in exp.get("residuals", {}).items():
            acf = np.asarray(ch["acf"])
            ax.plot(np.arange(1, acf.size + 1), acf, marker="o", ms=3, lw=1, label=f"{name}: {c}")
            n_min = ch["samples"] if n_min is None else min(n_min, ch["samples"])
    if n_min:
        band = 1.96 / np.sqrt(n_min)
        ax.axhspan(-band, band, color="black", alpha=0.08, lw=0, label="white noise, 95 %")
    ax.axhline(0.0, color="black", lw=0.6)
    ax.set_xlabel("lag (samples)")
    ax.set_ylabel("autocorrelation of the residuals")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small", frameon=False, ncols=2)
    fig.suptitle("residual autocorrelation (model error shows as slow decay)")
    _save(fig, path)
    return fig


def save_identification_figures(result: IdentificationResult, out_dir: str | os.PathLike[str]) -> list[Path]:
    """``fit_<experiment>.png`` for every experiment and ``residual_autocorrelation.png`` into
    ``out_dir``; returns the paths (nothing for a result without samples, e.g. direct methods)."""
    out = Path(out_dir)
    paths = []
    for e, s in enumerate(result.samples):
        p = out / f"fit_{re.sub(r'[^A-Za-z0-9_-]+', '_', s['name'])}.png"
        _close(plot_fit(result, e, p))
        paths.append(p)
    if result.samples:
        p = out / "residual_autocorrelation.png"
        _close(plot_residual_autocorrelation(result, p))
        paths.append(p)
    return paths
