"""A study's two panel figures (casflex.plotting.study, casflex.plotting.study_muscles): a panel per load or joint
in a grid, the spare ones hidden, one legend, saved atomically as PNG."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from casflex.plotting import _figure
from casflex.plotting.study import plot_cycles
from casflex.plotting.study_muscles import plot_contact

from .helpers import assert_clean, assert_png, legend_texts

PERCENT = np.linspace(0.0, 100.0, 101)


def _kept(monkeypatch) -> list[Figure]:
    """The figures the plots save, kept for inspection."""
    saved, save = [], _figure._save
    monkeypatch.setattr(_figure, "_save", lambda fig, path, *a: (saved.append(fig), save(fig, path, *a)))
    return saved


def test_plot_cycles_one_panel_per_load_spares_hidden(tmp_path, monkeypatch):
    saved = _kept(monkeypatch)
    wave = np.sin(PERCENT / 100.0 * 2 * np.pi)
    curves = {f"load{i}": {"s01": np.vstack([wave, 1.1 * wave]), "s02": wave[None]} for i in range(4)}
    plot_cycles(PERCENT, curves, "four loads", tmp_path / "cycles.png")
    assert_png(tmp_path / "cycles.png")
    assert_clean(tmp_path)
    axes = saved[0].axes
    assert len(axes) == 6 and [ax.get_visible() for ax in axes] == [True] * 4 + [False] * 2  # 2 rows of 3
    assert [ax.get_title() for ax in axes[:4]] == list(curves)
    assert legend_texts(axes[0]) == ["s01 (2)", "s02 (1)"]


def test_plot_contact_group_mean_over_subjects(tmp_path, monkeypatch):
    saved = _kept(monkeypatch)
    bw = 2.0 + np.sin(PERCENT / 100.0 * 2 * np.pi)
    curves = {"hip_r_resultant": {"s01": (bw[None], 0.1 * np.ones((1, 101))), "s02": (2 * bw[None], None)}}
    plot_contact(PERCENT, curves, "hip", tmp_path / "contact.png")
    assert_png(tmp_path / "contact.png")
    axes = saved[0].axes
    assert len(axes) == 1 and axes[0].get_title() == "hip_r: contact force"
    assert legend_texts(axes[0]) == ["s01 (1)", "s02 (1)", "group"]
    group = axes[0].get_lines()[-1].get_ydata()
    assert np.allclose(group, 1.5 * bw)  # the mean of the two subjects' means
