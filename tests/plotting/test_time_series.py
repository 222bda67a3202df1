"""casflex.plotting.time_series: node, energy, joint-force and comparison figures are written
(atomically, valid PNG), carry the expected lines, labels and units, and bad names fail with
helpful messages."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import pendulum
from matplotlib.figure import Figure

from casflex import plotting
from casflex.simulate import Stepping, simulate

from .helpers import assert_clean, assert_png, legend_texts


@pytest.mark.parametrize(("kind", "units"), [("q", ("m", "m", "rad")), ("qd", ("m/s", "m/s", "rad/s")),
                                             ("qdd", ("m/s$^2$", "m/s$^2$", "rad/s$^2$"))])
def test_plot_node(twobar, tmp_path, kind, units):
    _, tr = twobar
    path = tmp_path / f"node5_{kind}.png"
    fig = plotting.plot_node(tr, "5", kind=kind, path=path)
    assert isinstance(fig, Figure)
    assert_png(path)
    assert_clean(tmp_path)
    axes = fig.axes
    assert len(axes) == 3
    for ax, unit, d in zip(axes, units, ("x", "y", "theta"), strict=True):
        assert len(ax.lines) == 1
        assert ax.get_ylabel().endswith(f"({unit})")
        np.testing.assert_array_equal(ax.lines[0].get_ydata(), getattr(tr, kind)[:, tr.dof_names.index(f"{d}5")])
    assert axes[-1].get_xlabel() == "time t (s)"
    assert "node 5" in fig.get_suptitle()


def test_plot_node_errors(twobar):
    _, tr = twobar
    with pytest.raises(ValueError, match=r"unknown node '9'; nodes are \['1', '2', '3', '4', '5'\]"):
        plotting.plot_node(tr, "9")
    with pytest.raises(ValueError, match="kind: expected one of"):
        plotting.plot_node(tr, "5", kind="v")


def test_plot_energies(twobar, tmp_path):
    _, tr = twobar
    path = tmp_path / "energies.png"
    fig = plotting.plot_energies(tr, path)
    assert_png(path)
    top, bottom = fig.axes
    assert len(top.lines) == 4 and len(bottom.lines) == 1  # no external loads: no work line
    assert legend_texts(top) == ["kinetic", "elastic (springs, beams)", "gravity potential", "total"]
    assert legend_texts(bottom) == ["balance error E - E(0) - W + W_d (integration; numerical damping if < 0)"]
    assert top.get_ylabel() == bottom.get_ylabel() == "energy (J)"
    np.testing.assert_array_equal(top.lines[3].get_ydata(), tr.energies["total"])


def test_plot_energies_with_loads(tmp_path):
    tr = simulate(pendulum(2, load=(1.0, 0.0, 0.0)), 0.05, stepping=Stepping(dt=1e-3))
    fig = plotting.plot_energies(tr, tmp_path / "e.png")
    assert len(fig.axes[1].lines) == 2
    assert "work of external loads" in legend_texts(fig.axes[1])


@pytest.mark.parametrize("element", ["1", 1])
def test_plot_joint_forces_by_number(twobar, tmp_path, element):
    _, tr = twobar
    path = tmp_path / "joint1.png"
    fig = plotting.plot_joint_forces(tr, element, path=path)
    assert_png(path)
    forces, moment = fig.axes
    assert len(forces.lines) == 3 and len(moment.lines) == 1
    assert forces.get_ylabel() == "force (N)" and moment.get_ylabel() == "moment (N m)"
    np.testing.assert_array_equal(forces.lines[0].get_ydata(), tr.output("spring1.force"))
    np.testing.assert_array_equal(forces.lines[1].get_ydata(), tr.output("spring1.fx"))
    np.testing.assert_array_equal(forces.lines[2].get_ydata(), tr.output("spring1.fy"))
    np.testing.assert_array_equal(moment.lines[0].get_ydata(), tr.output("torsion1.moment"))
    assert "joint 1" in fig.get_suptitle()


def test_plot_joint_forces_by_name(twobar):
    _, tr = twobar
    fig = plotting.plot_joint_forces(tr, "spring3")
    assert len(fig.axes) == 1 and len(fig.axes[0].lines) == 3
    fig = plotting.plot_joint_forces(tr, "torsion3")
    assert len(fig.axes) == 1 and len(fig.axes[0].lines) == 1
    assert fig.axes[0].get_ylabel() == "moment (N m)"
    fig = plotting.plot_joint_forces(tr, ["spring1", "torsion3"])
    assert [len(ax.lines) for ax in fig.axes] == [3, 1]


def test_plot_joint_forces_unknown(twobar):
    _, tr = twobar
    with pytest.raises(ValueError) as exc:
        plotting.plot_joint_forces(tr, "7")
    msg = str(exc.value)
    assert "unknown joint element '7'" in msg
    assert "'1' (spring1, torsion1)" in msg and "'3' (spring3, torsion3)" in msg
    with pytest.raises(ValueError, match="springs \\['spring1', 'spring3'\\]"):
        plotting.plot_joint_forces(tr, "bar2")


def test_plot_comparison(twobar, twobar_soft, tmp_path):
    _, tr = twobar
    runs = {"nominal": tr, "k1 = 500 N/m": twobar_soft}
    path = tmp_path / "cmp.png"
    names = ["y5", "qd:y5", "qdd:theta5", "spring1.force", "torsion1.moment", "energy:total"]
    fig = plotting.plot_comparison(runs, names, path=path)
    assert_png(path)
    assert len(fig.axes) == len(names)
    assert all(len(ax.lines) == 2 for ax in fig.axes)
    assert legend_texts(fig.axes[0]) == list(runs)
    units = ["(m)", "(m/s)", "(rad/s$^2$)", "(N)", "(N m)", "(J)"]
    for ax, unit in zip(fig.axes, units, strict=True):
        assert ax.get_ylabel().endswith(unit), ax.get_ylabel()
    np.testing.assert_array_equal(fig.axes[1].lines[1].get_ydata(), twobar_soft.qd[:, tr.dof_names.index("y5")])
    # kind applies to plain dof names
    fig = plotting.plot_comparison(runs, ["x5", "y5", "theta5"], kind="qdd")
    assert [ax.get_ylabel()[-9:] for ax in fig.axes] == ["(m/s$^2$)", "(m/s$^2$)", "ad/s$^2$)"]


def test_plot_comparison_errors(twobar):
    _, tr = twobar
    with pytest.raises(ValueError, match="unknown series 'z5'.*spring1.force"):
        plotting.plot_comparison({"a": tr}, ["z5"])
    with pytest.raises(ValueError, match="unknown dof 'y9'"):
        plotting.plot_comparison({"a": tr}, ["qd:y9"])
    with pytest.raises(ValueError, match="at least one"):
        plotting.plot_comparison({}, ["y5"])


def _drawn_tick_labels(ax, which: str = "xy") -> list:
    """The tick labels drawn (those of ticks within the view; matplotlib keeps others, not drawn)."""
    out = []
    for axis in {"y": [ax.yaxis], "xy": [ax.xaxis, ax.yaxis]}[which]:
        lo, hi = sorted(axis.get_view_interval())
        tol = 1e-9 * (hi - lo)
        out += [t.label1 for t in axis.get_major_ticks() if lo - tol <= t.get_loc() <= hi + tol
                and t.label1.get_visible() and t.label1.get_text()]
    return out


@pytest.mark.parametrize("draw", ["node", "energies", "joint", "comparison", "configuration"])
def test_figures_laid_out_by_hand_hold_their_texts_in_the_figure_apart(twobar, draw):
    # _fit_column lays the panels out where the constrained layout did (one measurement, not the constrained
    # layout's three passes): every text inside the figure, a panel's y label left of its tick labels and clear of
    # them, the y labels aligned, the figure's title above every panel's title and legend

    from casflex.plotting._figure import PAD

    model, tr = twobar
    fig = {"node": lambda: plotting.plot_node(tr, "5", kind="qdd"), "energies": lambda: plotting.plot_energies(tr),
           "joint": lambda: plotting.plot_joint_forces(tr, "1"),
           "comparison": lambda: plotting.plot_comparison({"a": tr, "b": tr}, ["x5", "spring1.force"]),
           "configuration": lambda: plotting.plot_configuration(model)}[draw]()
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    page = fig.bbox
    axes = [ax for ax in fig.axes if ax.get_visible()]
    texts = [fig._suptitle] if fig._suptitle is not None else []
    for ax in axes:
        texts += [ax.title, ax._left_title, ax.xaxis.label, ax.yaxis.label, *(ax.get_legend().get_texts()
                                                                             if ax.get_legend() else [])]
        texts += _drawn_tick_labels(ax)
    texts = [t for t in texts if t.get_visible() and t.get_text()]
    for t in texts:
        box = t.get_window_extent(renderer)
        assert page.x0 - 0.5 <= box.x0 and box.x1 <= page.x1 + 0.5 and page.y0 - 0.5 <= box.y0 and \
            box.y1 <= page.y1 + 0.5, (t.get_text(), box, page)
    inks = [ax.get_tightbbox(renderer) for ax in axes]
    assert min(b.x0 for b in inks) == pytest.approx(PAD * fig.dpi, abs=1.0)  # the left margin: the pad, no more
    labels = [ax.yaxis.label.get_window_extent(renderer) for ax in axes]
    assert max(b.x1 for b in labels) - min(b.x1 for b in labels) < 0.5  # aligned (their side facing the panels)
    for ax, label in zip(axes, labels, strict=True):
        ticks = [t.get_window_extent(renderer) for t in _drawn_tick_labels(ax, "y")]
        assert label.x1 < min(b.x0 for b in ticks), ax.get_ylabel()
    for upper, lower in zip(inks, inks[1:], strict=False):
        assert lower.y1 < upper.y0  # no panel's texts over another's
    title = fig._suptitle.get_window_extent(renderer) if fig._suptitle is not None else None
    if title is not None:
        assert inks[0].y1 < title.y0
