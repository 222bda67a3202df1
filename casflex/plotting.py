"""Figures and animations of simulated motions (matplotlib, Agg, no pyplot state).

Every function builds its own :class:`matplotlib.figure.Figure` on an Agg canvas (so nothing
depends on, or changes, pyplot's global state or the interactive backend), returns it, and
optionally writes it to ``path`` atomically: the image is rendered into memory and written with
:func:`casflex.results.atomic_write_bytes` (format from the file suffix, PNG by default).

Units: time s; positions m; rotations rad; velocities m/s and rad/s; accelerations m/s^2 and
rad/s^2; forces N; moments N m; energies J.

Series names (:func:`plot_comparison`): a dof name (``"y5"``, its displacement, or its velocity /
acceleration with ``kind="qd"`` / ``"qdd"``), a dof name with an explicit prefix
(``"q:y5"``, ``"qd:y5"``, ``"qdd:y5"``), a joint output name (``"spring1.force"``,
``"torsion1.moment"``, ``"support1.x"``, ``"bar2.1.N"``), or an energy (``"energy:total"``,
keys of :attr:`Trajectory.energies <casflex.results.Trajectory>`).
"""

from __future__ import annotations

import io
import math
import os
import re
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.animation import PillowWriter
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

from casflex.model import Model
from casflex.results import Trajectory, atomic_write_bytes

__all__ = [
    "plot_node", "plot_energies", "plot_joint_forces", "plot_comparison", "plot_configuration",
    "animate", "save_standard_figures", "joint_elements", "KINDS",
]

#: Dof series kinds: trajectory attribute -> (description, unit of x/y, unit of theta).
KINDS: dict[str, tuple[str, str, str]] = {
    "q": ("displacement", "m", "rad"),
    "qd": ("velocity", "m/s", "rad/s"),
    "qdd": ("acceleration", "m/s$^2$", "rad/s$^2$"),
}

#: Resolution of saved PNG figures (dots per inch).
DPI = 120

_ENERGY_LABELS = {
    "kinetic": "kinetic",
    "elastic": "elastic (springs, beams)",
    "gravity": "gravity potential",
    "total": "total",
    "work_external": "work of external loads",
    "dissipated": "removed by numerical damping",
}

_OUTPUT_UNITS = {"force": "N", "fx": "N", "fy": "N", "length": "m", "moment": "N m",
                 "x": "N", "y": "N", "theta": "N m", "N": "N", "V": "N", "Ma": "N m", "Mb": "N m"}

_BEAM_COLOR = "#1f4e79"
_SPRING_COLOR = "#c0392b"
_TORSION_COLOR = "#8e44ad"
_NODE_COLOR = "black"
_SUPPORT_MARKERS = {"clamp": "s", "pin": "^", "x": ">", "y": "v", "theta": "D"}
_SUPPORT_LABELS = {"clamp": "clamp", "pin": "pin", "x": "x support", "y": "y support", "theta": "rotation support"}


# -- helpers ----------------------------------------------------------------------------------

def _new_figure(figsize: tuple[float, float]) -> Figure:
    fig = Figure(figsize=figsize, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: str | os.PathLike[str] | None, dpi: float = DPI) -> None:
    """Render ``fig`` into memory and write it atomically to ``path`` (format from the suffix)."""
    if path is None:
        return
    path = Path(path)
    fmt = path.suffix.lstrip(".").lower() or "png"
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=dpi)
    atomic_write_bytes(path, buf.getvalue())


def _math_name(name: str) -> str | None:
    """``name`` as mathtext subscript content, or None if it has characters mathtext would mangle."""
    return name if re.fullmatch(r"[A-Za-z0-9.+\-]+", name) else None


def _dof_symbol(dof: str, kind: str) -> str:
    """Axis label symbol of a dof (``"y5"`` -> ``$\\dot{y}_{5}$``)."""
    base = "theta" if dof.startswith("theta") else dof[:1]
    node = dof[len(base):]
    sym = r"\theta" if base == "theta" else base
    sym = {"q": sym, "qd": rf"\dot{{{sym}}}", "qdd": rf"\ddot{{{sym}}}"}[kind]
    sub = _math_name(node)
    if sub is None:
        prefix = {"q": "", "qd": "d/dt ", "qdd": "d²/dt² "}[kind]
        return f"{prefix}{dof}"
    return rf"${sym}_{{\mathrm{{{sub}}}}}$"


def _dof_unit(dof: str, kind: str) -> str:
    _, lin, rot = KINDS[kind]
    return rot if dof.startswith("theta") else lin


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise ValueError(f"kind: expected one of {list(KINDS)} (displacement, velocity, acceleration), got {kind!r}")


def _node_names(traj: Trajectory) -> list[str]:
    return [d[1:] for d in traj.dof_names if d.startswith("x")]


def _series(traj: Trajectory, name: str, kind: str = "q") -> tuple[np.ndarray, str, str]:
    """(values (n,), label, unit) of the series called ``name`` (see the module docstring)."""
    prefix, sep, rest = name.partition(":")
    if sep:
        if prefix in KINDS:
            if rest not in traj.dof_names:
                raise ValueError(f"unknown dof {rest!r} in series {name!r}; dofs are {list(traj.dof_names)}")
            return _series(traj, rest, prefix)
        if prefix == "energy":
            if rest not in traj.energies:
                raise ValueError(f"unknown energy {rest!r}; energies are {list(traj.energies)}")
            return traj.energies[rest], f"energy: {_ENERGY_LABELS.get(rest, rest)}", "J"
        raise ValueError(f"series {name!r}: unknown prefix {prefix!r}; use one of {[*KINDS, 'energy']}")
    if name in traj.dof_names:
        _check_kind(kind)
        values = getattr(traj, kind)[:, traj.dof_names.index(name)]
        return values, _dof_symbol(name, kind), _dof_unit(name, kind)
    if name in traj.output_names:
        unit = _OUTPUT_UNITS.get(name.rsplit(".", 1)[-1], "")
        return traj.outputs[:, traj.output_names.index(name)], name, unit
    raise ValueError(
        f"unknown series {name!r}: expected a dof ({', '.join(traj.dof_names[:6])}, ...), "
        f"optionally prefixed 'q:', 'qd:' or 'qdd:', a joint output ({', '.join(traj.output_names)}) "
        f"or 'energy:<{'|'.join(traj.energies)}>'"
    )


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
    fig = _new_figure((7.0, 6.5))
    axes = fig.subplots(3, 1, sharex=True)
    for ax, d in zip(axes, ("x", "y", "theta"), strict=True):
        values, label, unit = _series(traj, f"{d}{node}", kind)
        ax.plot(traj.t, values, color="C0", lw=1.4)
        ax.set_ylabel(f"{label} ({unit})")
    fig.suptitle(_title(traj, f"node {node} {KINDS[kind][0]}"))
    _finish_time_axes(axes, traj.t)
    fig.align_ylabels(axes)
    _save(fig, path)
    return fig


def plot_energies(traj: Trajectory, path: str | os.PathLike[str] | None = None) -> Figure:
    """Energies (J) over time.

    Top: kinetic, elastic, gravity potential and total energy. Bottom, on its own scale: the
    energy removed by numerical damping, E(0) + W_ext - E(t) (zero up to round-off and
    Newton tolerance when alpha = 0), and the work of the external loads when there is any.
    """
    fig = _new_figure((7.0, 5.8))
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=[3, 1.4])
    e = traj.energies
    styles = {"kinetic": ("C0", "-"), "elastic": ("C2", "-"), "gravity": ("C1", "-"), "total": ("black", "--")}
    for key, (color, ls) in styles.items():
        top.plot(traj.t, e[key], color=color, ls=ls, lw=1.4, label=_ENERGY_LABELS[key])
    top.set_ylabel("energy (J)")
    _legend_above(top, 4)
    bottom.plot(traj.t, e["dissipated"], color="C3", lw=1.4, label=_ENERGY_LABELS["dissipated"])
    work = e.get("work_external")
    if work is not None and np.any(work != 0.0):
        bottom.plot(traj.t, work, color="C4", lw=1.2, ls="-.", label=_ENERGY_LABELS["work_external"])
    bottom.set_ylabel("energy (J)")
    _legend_above(bottom, 2)
    alpha = traj.meta.get("alpha")
    what = "energies" + (f" (HHT alpha = {alpha:g})" if isinstance(alpha, (int, float)) else "")
    fig.suptitle(_title(traj, what))
    _finish_time_axes([top, bottom], traj.t)
    fig.align_ylabels([top, bottom])
    _save(fig, path)
    return fig


def _joint_catalogue(traj: Trajectory) -> tuple[list[str], list[str]]:
    """Names of the linear springs and of the torsion springs with outputs in ``traj``."""
    outs = set(traj.output_names)
    springs, torsions = [], []
    for name in traj.output_names:
        owner, _, key = name.rpartition(".")
        if key == "force" and {f"{owner}.fx", f"{owner}.fy"} <= outs and owner not in springs:
            springs.append(owner)
        elif key == "moment" and owner not in torsions:
            torsions.append(owner)
    return springs, torsions


def _trailing_number(name: str) -> str | None:
    m = re.search(r"(\d+)$", name)
    return m.group(1) if m else None


def joint_elements(traj: Trajectory, element: str | int | Sequence[str]) -> tuple[list[str], list[str]]:
    """Resolve a joint designation to (linear spring names, torsion spring names).

    ``element`` is a spring or torsion spring name (``"spring1"``), a joint number as in the
    paper (``"1"`` or ``1``: every spring and torsion spring whose name ends in that number,
    e.g. ``spring1`` and ``torsion1``), or a list of such. Raises ValueError naming the
    available joints when nothing matches.
    """
    springs, torsions = _joint_catalogue(traj)
    keys = [element] if isinstance(element, (str, int)) else list(element)
    chosen: list[str] = []
    for key in keys:
        key = str(key)
        if key in springs or key in torsions:
            found = [key]
        else:
            found = [e for e in springs + torsions if _trailing_number(e) == key]
        if not found:
            numbers: dict[str, list[str]] = {}
            for e in springs + torsions:
                n = _trailing_number(e)
                if n is not None:
                    numbers.setdefault(n, []).append(e)
            listing = "; ".join(f"{n!r} ({', '.join(v)})" for n, v in numbers.items()) or "none"
            raise ValueError(
                f"unknown joint element {key!r}. Available joints by number: {listing}; "
                f"or by name: springs {springs}, torsion springs {torsions}"
            )
        chosen += [e for e in found if e not in chosen]
    return [e for e in chosen if e in springs], [e for e in chosen if e in torsions]


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
    fig = _new_figure((7.0, 2.6 + 2.2 * n_ax))
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
    fig.align_ylabels(axes)
    _save(fig, path)
    return fig


def plot_comparison(trajs: Mapping[str, Trajectory], quantity: str | Sequence[str], *, kind: str = "q",
                    title: str | None = None, path: str | os.PathLike[str] | None = None) -> Figure:
    """Overlay several trajectories: one axes per series in ``quantity``, one line per trajectory.

    ``trajs`` maps legend labels to trajectories (their time grids may differ). Series names are
    described in the module docstring; plain dof names use ``kind`` (``"q"``, ``"qd"`` or
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
    fig = _new_figure((7.0, 1.2 + 2.1 * len(names)))
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
    fig.align_ylabels(axes)
    _save(fig, path)
    return fig


# -- configuration drawings -------------------------------------------------------------------

class _Drawer:
    """Geometry of a model's drawing: beams as Hermite curves, springs as zigzags, for any q."""

    N_BEAM = 13  # points per beam element curve
    N_COILS = 6

    def __init__(self, model: Model):
        self.model = model
        q0 = np.asarray(model.q0, dtype=float)
        beams = [(a, b) for kind, _, a, b in model.segments if kind == "beam"]
        springs = [(a, b) for kind, _, a, b in model.segments if kind == "spring"]
        self.beam_a = np.array([a for a, _ in beams], dtype=int)
        self.beam_b = np.array([b for _, b in beams], dtype=int)
        self.spring_a = np.array([a for a, _ in springs], dtype=int)
        self.spring_b = np.array([b for _, b in springs], dtype=int)
        xy0 = q0.reshape(-1, 3)
        self.extent = max(float(np.ptp(xy0[:, 0])), float(np.ptp(xy0[:, 1])), model.length_scale, 1e-3)
        d0 = xy0[self.beam_b, :2] - xy0[self.beam_a, :2]
        self.beta0 = np.arctan2(d0[:, 1], d0[:, 0])
        self.th0_a = xy0[self.beam_a, 2]
        self.th0_b = xy0[self.beam_b, 2]
        # spring drawing width: proportional to the spring's initial (or rest) length, bounded
        rest = {s.name: s.rest_length for s in model.scene.springs}
        names = [name for kind, name, _, _ in model.segments if kind == "spring"]
        ls0 = np.linalg.norm(xy0[self.spring_b, :2] - xy0[self.spring_a, :2], axis=1)
        ref = np.array([rest.get(n) or ls0[i] for i, n in enumerate(names)], dtype=float)
        ref = np.where(ref > 0, ref, 0.05 * self.extent)
        self.spring_width = np.clip(0.12 * ref, 0.004 * self.extent, 0.025 * self.extent)
        idx = {n: i for i, n in enumerate(model.node_names)}
        self.torsion_pairs = np.array([(idx[t.nodes[0]], idx[t.nodes[1]]) for t in model.scene.torsion_springs],
                                      dtype=int).reshape(-1, 2)
        self.supports: dict[str, list[int]] = {}
        for s in model.scene.supports:
            self.supports.setdefault(s.kind, []).append(idx[s.node])
        self.n_user = len(model.scene.nodes)

    def beams(self, q: np.ndarray) -> np.ndarray:
        """(k, 2) polyline of all beam elements (Hermite cubics), NaN-separated."""
        if not len(self.beam_a):
            return np.empty((0, 2))
        xy = q.reshape(-1, 3)
        pa, pb = xy[self.beam_a, :2], xy[self.beam_b, :2]
        d = pb - pa
        beta = np.arctan2(d[:, 1], d[:, 0])
        L = np.hypot(d[:, 0], d[:, 1])
        wrap = lambda a: np.arctan2(np.sin(a), np.cos(a))  # noqa: E731
        tha = wrap(xy[self.beam_a, 2] - self.th0_a + self.beta0 - beta)
        thb = wrap(xy[self.beam_b, 2] - self.th0_b + self.beta0 - beta)
        s = np.linspace(0.0, 1.0, self.N_BEAM)
        v = L[:, None] * (tha[:, None] * (s - 2 * s**2 + s**3) + thb[:, None] * (s**3 - s**2))
        e = np.stack([np.cos(beta), np.sin(beta)], axis=1)
        n = np.stack([-e[:, 1], e[:, 0]], axis=1)
        pts = pa[:, None, :] + (s[None, :, None] * d[:, None, :]) + v[:, :, None] * n[:, None, :]
        pts = np.concatenate([pts, np.full((len(L), 1, 2), np.nan)], axis=1)
        return pts.reshape(-1, 2)

    def springs(self, q: np.ndarray) -> np.ndarray:
        """(k, 2) polyline of all linear springs (zigzags), NaN-separated."""
        if not len(self.spring_a):
            return np.empty((0, 2))
        xy = q.reshape(-1, 3)
        pa, pb = xy[self.spring_a, :2], xy[self.spring_b, :2]
        d = pb - pa
        L = np.hypot(d[:, 0], d[:, 1])
        safe = np.where(L > 0, L, 1.0)
        e = d / safe[:, None]
        n = np.stack([-e[:, 1], e[:, 0]], axis=1)
        m = 2 * self.N_COILS
        s = np.concatenate([[0.0, 0.15], 0.15 + 0.7 * (np.arange(m) + 0.5) / m, [0.85, 1.0]])
        off = np.concatenate([[0.0, 0.0], np.where(np.arange(m) % 2 == 0, 1.0, -1.0), [0.0, 0.0]])
        w = np.where(L > 0, self.spring_width, 0.0)
        side = (w[:, None] * off[None, :])[:, :, None] * n[:, None, :]
        pts = pa[:, None, :] + s[None, :, None] * d[:, None, :] + side
        pts = np.concatenate([pts, np.full((len(L), 1, 2), np.nan)], axis=1)
        return pts.reshape(-1, 2)

    def torsions(self, q: np.ndarray) -> np.ndarray:
        """(k, 2) midpoints of the torsion springs' node pairs."""
        xy = q.reshape(-1, 3)[:, :2]
        return 0.5 * (xy[self.torsion_pairs[:, 0]] + xy[self.torsion_pairs[:, 1]])

    def limits(self, qs: np.ndarray, margin: float = 0.08) -> tuple[tuple[float, float], tuple[float, float]]:
        """Axis limits (m) covering the node positions of all rows of ``qs`` (n, n_dof)."""
        qs = np.atleast_2d(qs)
        x, y = qs[:, 0::3], qs[:, 1::3]
        pad = margin * self.extent + (float(self.spring_width.max()) if len(self.spring_width) else 0.0)
        return ((float(x.min()) - pad, float(x.max()) + pad), (float(y.min()) - pad, float(y.max()) + pad))

    def draw(self, ax: Axes, q: np.ndarray, *, labels: bool = True) -> dict[str, object]:
        """Draw configuration ``q`` on ``ax``; returns the artists (for animation updates)."""
        xy = q.reshape(-1, 3)
        art: dict[str, object] = {}
        b = self.beams(q)
        art["beams"], = ax.plot(b[:, 0], b[:, 1], color=_BEAM_COLOR, lw=4.5, solid_capstyle="round",
                                label="beam" if len(b) else "_beam", zorder=2)
        sp = self.springs(q)
        art["springs"], = ax.plot(sp[:, 0], sp[:, 1], color=_SPRING_COLOR, lw=1.1,
                                  label="spring" if len(sp) else "_spring", zorder=3)
        tp = self.torsions(q)
        art["torsions"], = ax.plot(tp[:, 0], tp[:, 1], ls="none", marker="o", ms=11, mfc="none", mew=1.6,
                                   color=_TORSION_COLOR, label="torsion spring" if len(tp) else "_torsion", zorder=4)
        art["nodes"], = ax.plot(xy[:self.n_user, 0], xy[:self.n_user, 1], ls="none", marker="o", ms=5,
                                color=_NODE_COLOR, label="node", zorder=6)
        art["mesh_nodes"], = ax.plot(xy[self.n_user:, 0], xy[self.n_user:, 1], ls="none", marker="o", ms=2.5,
                                     color=_NODE_COLOR, label="_mesh node", zorder=6)
        for kind, nodes in self.supports.items():
            art[f"support:{kind}"], = ax.plot(xy[nodes, 0], xy[nodes, 1], ls="none", marker=_SUPPORT_MARKERS[kind],
                                              ms=12, color="0.45", mec="black", label=_SUPPORT_LABELS[kind], zorder=5)
        if labels:
            for i, name in enumerate(self.model.node_names[:self.n_user]):
                ax.annotate(name, (xy[i, 0], xy[i, 1]), xytext=(6, 4), textcoords="offset points",
                            fontsize="small", color="0.2", zorder=7)
        return art

    def update(self, art: dict[str, object], q: np.ndarray) -> None:
        xy = q.reshape(-1, 3)
        for key, pts in (("beams", self.beams(q)), ("springs", self.springs(q)), ("torsions", self.torsions(q))):
            art[key].set_data(pts[:, 0], pts[:, 1])  # type: ignore[attr-defined]
        art["nodes"].set_data(xy[:self.n_user, 0], xy[:self.n_user, 1])  # type: ignore[attr-defined]
        art["mesh_nodes"].set_data(xy[self.n_user:, 0], xy[self.n_user:, 1])  # type: ignore[attr-defined]
        for kind, nodes in self.supports.items():
            art[f"support:{kind}"].set_data(xy[nodes, 0], xy[nodes, 1])  # type: ignore[attr-defined]


def _check_q(model: Model, q: np.ndarray | None) -> np.ndarray:
    q = np.asarray(model.q0 if q is None else q, dtype=float).reshape(-1)
    if q.shape != (model.n_dof,):
        raise ValueError(f"q: expected {model.n_dof} values ({', '.join(model.dof_names[:3])}, ...), got {q.shape}")
    return q


def plot_configuration(model: Model, q: np.ndarray | None = None, ax: Axes | None = None, *,
                       labels: bool = True, legend: bool = True, title: str | None = None,
                       path: str | os.PathLike[str] | None = None) -> Figure:
    """Draw the system in configuration ``q`` (n_dof,), default the initial one ``model.q0``.

    Beams are thick lines (each element a cubic Hermite curve through its end rotations, so
    bending shows at true scale), linear springs zigzags, torsion springs rings at the middle
    of their node pair, nodes dots (user nodes labelled), supports grey markers (square clamp,
    triangle pin). Axes in m with equal aspect. Draws into ``ax`` if given, else a new figure;
    returns the figure.
    """
    q = _check_q(model, q)
    if ax is None:
        fig = _new_figure((6.0, 6.0))
        ax = fig.add_subplot()
    else:
        fig = ax.figure
        fig = getattr(fig, "figure", None) or fig  # the root figure when ax is in a SubFigure
    drawer = _Drawer(model)
    drawer.draw(ax, q, labels=labels)
    (x0, x1), (y0, y1) = drawer.limits(q[None, :])
    ax.update_datalim([(x0, y0), (x1, y1)])
    ax.margins(0.0)
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, alpha=0.25)
    if legend:
        ax.legend(loc="best", fontsize="small")
    ax.set_title(title if title is not None else f"{model.scene.name}: configuration")
    _save(fig, path)
    return fig


def animate(model: Model, traj: Trajectory, path: str | os.PathLike[str], *, fps: float = 25,
            duration: float | None = None, dpi: float = 80) -> Path:
    """Write a GIF of the deformed system moving along ``traj``; returns the path.

    Frames are sampled from ``traj`` at equal time intervals (nearest stored time point):
    ``fps`` frames per second of playback, for a playback lasting ``duration`` seconds
    (default: the simulated time span, i.e. real time; a shorter duration plays faster).
    The axis limits are fixed from the whole motion; a label shows the simulated time (s).
    The GIF is written to a temporary file in the target directory and renamed over ``path``.
    """
    if traj.q.shape[1] != model.n_dof:
        raise ValueError(f"traj has {traj.q.shape[1]} dofs, the model {model.n_dof}: not a motion of this model")
    if not (fps > 0 and math.isfinite(fps)):
        raise ValueError(f"fps: must be a positive number, got {fps!r}")
    path = Path(path)
    t = traj.t
    span = float(t[-1] - t[0])
    play = span if duration is None else float(duration)
    if not (play >= 0 and math.isfinite(play)):
        raise ValueError(f"duration: must be a non-negative number of seconds, got {duration!r}")
    n_frames = max(2, int(round(play * fps)) + 1)
    n_frames = min(n_frames, len(t)) if len(t) > 1 else 1
    times = np.linspace(float(t[0]), float(t[-1]), n_frames)
    right = np.clip(np.searchsorted(t, times), 1, max(len(t) - 1, 1)) if len(t) > 1 else np.zeros(1, dtype=int)
    left = np.maximum(right - 1, 0)
    nearest = np.where(np.abs(times - t[left]) <= np.abs(t[right] - times), left, right)
    frames = np.unique(nearest)

    drawer = _Drawer(model)
    (x0, x1), (y0, y1) = drawer.limits(traj.q)
    w, h = x1 - x0, y1 - y0
    width = 6.0
    height = float(np.clip(width * h / max(w, 1e-12), 3.0, 8.0))
    fig = _new_figure((width, height))
    fig.set_dpi(dpi)
    ax = fig.add_subplot()
    art = drawer.draw(ax, traj.q[frames[0]], labels=False)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, alpha=0.25)
    ax.set_title(f"{model.scene.name}", fontsize="medium")
    label = ax.text(0.02, 0.97, "", transform=ax.transAxes, va="top", ha="left", family="monospace",
                    bbox={"boxstyle": "round", "fc": "white", "ec": "0.7", "alpha": 0.9}, zorder=10)
    # lay out once, then drop the engine: every frame has the same geometry
    fig.get_layout_engine().execute(fig)
    fig.set_layout_engine(None)
    moving = sorted([*art.values(), label], key=lambda a: a.get_zorder())  # type: ignore[attr-defined]

    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp.gif")
    os.close(fd)
    try:
        writer = _BlitPillowWriter(moving, fps=fps)
        with writer.saving(fig, tmp, dpi):
            for k in frames:
                drawer.update(art, traj.q[k])
                label.set_text(f"t = {t[k]:6.3f} s")
                writer.grab_frame()
        atomic_write_bytes(path, Path(tmp).read_bytes())
    finally:
        Path(tmp).unlink(missing_ok=True)
    return path


class _Palette:
    """Maps RGB frames to the 256 most frequent colours of a reference frame (exactly where a
    colour is in the palette, else to the nearest palette colour); numpy, so exact white stays
    white (Pillow's own palette mapping rounds colours to 6 bits per channel)."""

    def __init__(self, rgb: np.ndarray):
        keys, counts = np.unique(self._keys(rgb), return_counts=True)
        top = np.sort(keys[np.argsort(counts, kind="stable")[::-1][:256]])
        self.keys = top
        self.colors = np.stack([(top >> 16) & 255, (top >> 8) & 255, top & 255], axis=1).astype(np.int32)
        self.flat = self.colors.astype(np.uint8).ravel().tolist() + [0] * (768 - 3 * len(top))

    @staticmethod
    def _keys(rgb: np.ndarray) -> np.ndarray:
        rgb = rgb.astype(np.int32)
        return (rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]

    def index(self, rgb: np.ndarray) -> np.ndarray:
        """(h, w) uint8 palette indices of an (h, w, 3) uint8 frame."""
        keys = self._keys(rgb).ravel()
        pos = np.clip(np.searchsorted(self.keys, keys), 0, len(self.keys) - 1)
        miss = self.keys[pos] != keys
        if miss.any():
            uniq, inv = np.unique(keys[miss], return_inverse=True)
            cols = np.stack([(uniq >> 16) & 255, (uniq >> 8) & 255, uniq & 255], axis=1)
            near = np.empty(len(uniq), dtype=np.intp)
            for i in range(0, len(uniq), 4096):  # bounded memory: 4096 x 256 distances at a time
                c = cols[i:i + 4096]
                near[i:i + 4096] = np.argmin(((c[:, None, :] - self.colors[None, :, :]) ** 2).sum(axis=2), axis=1)
            pos[miss] = near[inv]
        return pos.astype(np.uint8).reshape(rgb.shape[:2])


class _BlitPillowWriter(PillowWriter):
    """PillowWriter that redraws only the moving artists over a cached background.

    The static parts (axes, ticks, grid, labels) are rendered once; every frame restores
    them and draws the moving artists (a full ``savefig`` per frame spends most of its
    time on tick labels). Frames are mapped to the palette of the first frame
    (:class:`_Palette`), so the GIF encoder does not quantize each frame again. The frames
    go to PillowWriter's frame list ``_frames`` (as its own ``grab_frame`` does); if that
    attribute is missing (another matplotlib version) or the figure's dpi differs from the
    writer's, it falls back to PillowWriter's own frame grabbing.
    """

    def __init__(self, moving: list, **kwargs):
        super().__init__(**kwargs)
        self._moving = moving
        self._background = None
        self._palette: _Palette | None = None

    def grab_frame(self, **savefig_kwargs):
        canvas = self.fig.canvas
        frames = getattr(self, "_frames", None)
        if savefig_kwargs or frames is None or self.fig.dpi != self.dpi:
            return super().grab_frame(**savefig_kwargs)
        if self._background is None:
            for a in self._moving:
                a.set_animated(True)
            canvas.draw()
            self._background = canvas.copy_from_bbox(self.fig.bbox)
        canvas.restore_region(self._background)
        renderer = canvas.get_renderer()
        for a in self._moving:
            a.draw(renderer)
        rgb = np.asarray(canvas.buffer_rgba())[..., :3]
        if self._palette is None:
            self._palette = _Palette(rgb)
        idx = self._palette.index(rgb)
        im = Image.frombytes("P", (idx.shape[1], idx.shape[0]), idx.tobytes())
        im.putpalette(self._palette.flat)
        frames.append(im)


# -- standard set -----------------------------------------------------------------------------

def _joint_groups(model: Model) -> list[list[str]]:
    """Springs and torsion springs grouped by the (unordered) node pair they connect."""
    groups: dict[frozenset[str], list[str]] = {}
    for s in (*model.scene.springs, *model.scene.torsion_springs):
        groups.setdefault(frozenset(s.nodes), []).append(s.name)
    return list(groups.values())


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_-]+", "_", name)


def save_standard_figures(model: Model, traj: Trajectory, out_dir: str | os.PathLike[str], *,
                          animation: bool = True, max_gif_seconds: float = 10.0) -> list[Path]:
    """Write the standard figures of a run into ``out_dir``; returns the paths written.

    - ``node<N>_q.png``, ``node<N>_qd.png``, ``node<N>_qdd.png``: displacements, velocities,
      accelerations of node "5" if the scene has one, else of its last user node;
    - ``configuration.png``: the initial configuration;
    - ``energies.png``;
    - ``joint<k>.png`` for every joint (springs and torsion springs on the same node pair);
    - ``animation.gif`` (with ``animation=True``), real time, but sped up to play in at most
      ``max_gif_seconds`` seconds.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: list[Path] = []
    user = [n.name for n in model.scene.nodes]
    node = "5" if "5" in user else user[-1]
    for kind in KINDS:
        p = out / f"node{_safe(node)}_{kind}.png"
        _close(plot_node(traj, node, kind=kind, path=p))
        paths.append(p)
    p = out / "configuration.png"
    _close(plot_configuration(model, model.q0, path=p))
    paths.append(p)
    p = out / "energies.png"
    _close(plot_energies(traj, path=p))
    paths.append(p)
    for group in _joint_groups(model):
        numbers = {_trailing_number(e) for e in group}
        stem = f"joint{numbers.pop()}" if len(numbers) == 1 and None not in numbers else "joint_" + "_".join(group)
        p = out / f"{_safe(stem)}.png"
        _close(plot_joint_forces(traj, group, path=p))
        paths.append(p)
    if animation and len(traj.t) > 1:
        span = float(traj.t[-1] - traj.t[0])
        p = animate(model, traj, out / "animation.gif", duration=min(span, max_gif_seconds))
        paths.append(p)
    return paths


def _close(fig: Figure) -> None:
    """Drop a figure's artists (figures are not registered anywhere, so this only frees memory sooner)."""
    fig.clear()

