"""Time histories: node motion, energies, joint forces, and comparisons of several runs.

Time in s on the horizontal axis; units of the series in the axis labels.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from casflex.plotting._figure import _fit_column, _new_figure, _save
from casflex.plotting.joints import _trailing_number, joint_elements
from casflex.plotting.series import _ENERGY_LABELS, KINDS, _check_kind, _node_names, _series
from casflex.results import Trajectory


def _title(traj: Trajectory, what: str) -> str:
    scene = traj.meta.get("scene")
    title = f"{scene}: {what}" if scene else what
    if not traj.success:
        title += f"\n(run stopped early at t = {traj.t[-1]:.4g} s: {traj.status})"
    return title


def _legend_above(ax: Axes, ncols: int) -> None:
    """Legend in a row above the right end of ``ax`` (never over the curves)."""
    ax.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), ncols=max(ncols, 1), fontsize="small",
              frameon=False, borderaxespad=0.2, handlelength=2.5, columnspacing=1.2)


def _plain_numbers(ax: Axes) -> None:
    """Tick labels without an offset (``-3.131e2`` above the axis): values read directly."""
    try:
        ax.ticklabel_format(axis="y", useOffset=False)
    except AttributeError:  # not a ScalarFormatter (e.g. log axis)
        pass


def _finish_time_axes(axes: Sequence[Axes], traj_t: np.ndarray) -> None:
    for ax in axes:
        _plain_numbers(ax)
        ax.grid(True, alpha=0.3)
        ax.set_xlim(float(traj_t[0]), float(traj_t[-1]) if traj_t[-1] > traj_t[0] else float(traj_t[0]) + 1.0)
    axes[-1].set_xlabel("time t (s)")


# -- time histories ---------------------------------------------------------------------------

def plot_node(traj: Trajectory, node: str = "5", *, kind: str = "q",
              path: str | os.PathLike[str] | None = None) -> Figure:
    """x (m), y (m) and theta (rad) of ``node`` over time, on three stacked axes.

    ``kind`` selects displacements ``"q"`` (m, rad), velocities ``"qd"`` (m/s, rad/s) or
    accelerations ``"qdd"`` (m/s^2, rad/s^2). Raises ValueError for an unknown node or kind.
    """
    _check_kind(kind)
    node = str(node)
    nodes = _node_names(traj)
    if node not in nodes:
        raise ValueError(f"unknown node {node!r}; nodes are {nodes}")
    fig = _new_figure((7.0, 6.5), layout=None)
    axes = fig.subplots(3, 1, sharex=True)
    for ax, d in zip(axes, ("x", "y", "theta"), strict=True):
        values, label, unit = _series(traj, f"{d}{node}", kind)
        ax.plot(traj.t, values, color="C0", lw=1.4)
        ax.set_ylabel(f"{label} ({unit})")
    fig.suptitle(_title(traj, f"node {node} {KINDS[kind][0]}"))
    _finish_time_axes(axes, traj.t)
    _fit_column(fig, list(axes))
    _save(fig, path)
    return fig


def plot_energies(traj: Trajectory, path: str | os.PathLike[str] | None = None) -> Figure:
    """Energies (J) over time.

    Top: kinetic, elastic, gravity potential and total energy. Bottom, on its own scale: the
    energy balance error E(t) - E(0) - W_ext(t) + W_d(t) (at alpha = 0 the integration error, of
    either sign and O(dt^2); at alpha < 0 mostly the energy numerical damping removed, negative),
    the work of the external loads and the energy the dampers dissipated, when there are any.
    """
    fig = _new_figure((7.0, 5.8), layout=None)
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=[3, 1.4])
    e = traj.energies
    styles = {"kinetic": ("C0", "-"), "elastic": ("C2", "-"), "gravity": ("C1", "-"), "total": ("black", "--")}
    for key, (color, ls) in styles.items():
        top.plot(traj.t, e[key], color=color, ls=ls, lw=1.4, label=_ENERGY_LABELS[key])
    top.set_ylabel("energy (J)")
    _legend_above(top, 4)
    bottom.plot(traj.t, e["balance_error"], color="C3", lw=1.4, label=_ENERGY_LABELS["balance_error"])
    for key, color in (("work_external", "C4"), ("work_dampers", "C5")):
        work = e.get(key)
        if work is not None and np.any(work != 0.0):
            bottom.plot(traj.t, work, color=color, lw=1.2, ls="-.", label=_ENERGY_LABELS[key])
    bottom.set_ylabel("energy (J)")
    _legend_above(bottom, 2)
    alpha = traj.meta.get("alpha")
    what = "energies" + (f" (HHT alpha = {alpha:g})" if isinstance(alpha, (int, float)) else "")
    fig.suptitle(_title(traj, what))
    _finish_time_axes([top, bottom], traj.t)
    _fit_column(fig, [top, bottom], [3, 1.4])
    _save(fig, path)
    return fig


def plot_joint_forces(traj: Trajectory, element: str | int | Sequence[str] = "1",
                      path: str | os.PathLike[str] | None = None) -> Figure:
    """Forces (N) and moment (N m) of a joint over time.

    ``element``: see :func:`joint_elements` (``"1"`` -> spring1 and torsion1). For every linear
    spring: its axial force (tension positive) and the components F_x, F_y of the force it
    exerts on its second node; for every torsion spring: the moment it carries. Springs and
    torsion springs get separate axes. Raises ValueError naming the available joints.
    """
    springs, torsions = joint_elements(traj, element)
    n_ax = int(bool(springs)) + int(bool(torsions))
    fig = _new_figure((7.0, 2.6 + 2.2 * n_ax), layout=None)
    axes = list(np.atleast_1d(fig.subplots(n_ax, 1, sharex=True)))
    ax_iter = iter(axes)
    if springs:
        ax = next(ax_iter)
        for i, s in enumerate(springs):
            color = f"C{i}" if len(springs) > 1 else None
            tag = f"{s}: " if len(springs) > 1 else ""
            ax.plot(traj.t, traj.output(f"{s}.force"), lw=1.6, color=color or "black",
                    label=f"{tag}axial force (tension > 0)")
            ax.plot(traj.t, traj.output(f"{s}.fx"), lw=1.2, ls="--", color=color or "C0",
                    label=f"{tag}$F_x$ on 2nd node")
            ax.plot(traj.t, traj.output(f"{s}.fy"), lw=1.2, ls=":" if color else "-.", color=color or "C3",
                    label=f"{tag}$F_y$ on 2nd node")
        ax.set_ylabel("force (N)")
        ax.set_title(", ".join(springs), fontsize="medium", loc="left")
        _legend_above(ax, 3)
    if torsions:
        ax = next(ax_iter)
        for i, s in enumerate(torsions):
            ax.plot(traj.t, traj.output(f"{s}.moment"), lw=1.4, color=f"C{i + 4}", label=f"{s}: moment")
        ax.set_ylabel("moment (N m)")
        ax.set_title(", ".join(torsions), fontsize="medium", loc="left")
        _legend_above(ax, 3)
    numbers = {_trailing_number(e) for e in springs + torsions}
    what = f"joint {numbers.pop()}" if len(numbers) == 1 and None not in numbers else "joint"
    fig.suptitle(_title(traj, f"{what} forces ({', '.join(springs + torsions)})"))
    _finish_time_axes(axes, traj.t)
    _fit_column(fig, list(axes))
    _save(fig, path)
    return fig


def plot_comparison(trajs: Mapping[str, Trajectory], quantity: str | Sequence[str], *, kind: str = "q",
                    title: str | None = None, path: str | os.PathLike[str] | None = None) -> Figure:
    """Overlay several trajectories: one axes per series in ``quantity``, one line per trajectory.

    ``trajs`` maps legend labels to trajectories (their time grids may differ). Series names are
    described in :mod:`casflex.plotting.series`; plain dof names use ``kind`` (``"q"``, ``"qd"`` or
    ``"qdd"``), so ``plot_comparison(runs, ["x5", "y5", "theta5"], kind="qd")`` compares
    node-5 velocities, and ``["spring1.fx", "spring1.fy", "torsion1.moment"]`` the forces
    of the first joint. Units in the axis labels.
    """
    if not trajs:
        raise ValueError("trajs: expected at least one {label: Trajectory}")
    _check_kind(kind)
    names = [quantity] if isinstance(quantity, str) else list(quantity)
    if not names:
        raise ValueError("quantity: expected at least one series name")
    fig = _new_figure((7.0, 1.2 + 2.1 * len(names)), layout=None)
    axes = list(np.atleast_1d(fig.subplots(len(names), 1, sharex=True)))
    styles = ["-", "--", "-.", ":"]
    t_lo, t_hi = math.inf, -math.inf
    for ax, name in zip(axes, names, strict=True):
        label = unit = ""
        for i, (run, traj) in enumerate(trajs.items()):
            values, label, unit = _series(traj, name, kind)
            ax.plot(traj.t, values, color=f"C{i % 10}", ls=styles[(i // 10) % len(styles)], lw=1.3, label=str(run))
            t_lo, t_hi = min(t_lo, float(traj.t[0])), max(t_hi, float(traj.t[-1]))
        ax.set_ylabel(f"{label} ({unit})" if unit else label)
        ax.grid(True, alpha=0.3)
        _plain_numbers(ax)
    _legend_above(axes[0], min(len(trajs), 4))
    for ax in axes:
        ax.set_xlim(t_lo, t_hi if t_hi > t_lo else t_lo + 1.0)
    axes[-1].set_xlabel("time t (s)")
    if title is None:
        title = f"comparison: {', '.join(names)}" + (f" ({KINDS[kind][0]})" if kind != "q" else "")
    fig.suptitle(title)
    _fit_column(fig, list(axes))
    _save(fig, path)
    return fig
