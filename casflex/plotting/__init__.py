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

Modules (everything public is re-exported here, so ``from casflex.plotting import X`` works):

- :mod:`~casflex.plotting.series`: series names -> values, labels, units (``KINDS``);
- :mod:`~casflex.plotting.joints`: joint designations -> springs and torsion springs
  (:func:`joint_elements`);
- :mod:`~casflex.plotting.time_series`: :func:`plot_node`, :func:`plot_energies`,
  :func:`plot_joint_forces`, :func:`plot_comparison`;
- :mod:`~casflex.plotting.configuration`: :func:`plot_configuration`;
- :mod:`~casflex.plotting.animation`: :func:`animate` (GIF);
- ``_figure``: Agg figures, atomic saving, ``DPI``;
- this package: :func:`save_standard_figures`, the standard set of a run.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from casflex.model import Model
from casflex.plotting._figure import DPI as DPI
from casflex.plotting._figure import _close
from casflex.plotting.animation import animate
from casflex.plotting.configuration import _Drawer as _Drawer
from casflex.plotting.configuration import plot_configuration
from casflex.plotting.joints import _trailing_number, joint_elements
from casflex.plotting.series import KINDS
from casflex.plotting.time_series import plot_comparison, plot_energies, plot_joint_forces, plot_node
from casflex.results import Trajectory

__all__ = [
    "plot_node", "plot_energies", "plot_joint_forces", "plot_comparison", "plot_configuration",
    "animate", "save_standard_figures", "joint_elements", "KINDS",
]


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
      accelerations of the node farthest from the supports (:attr:`Model.tip_node`);
    - ``configuration.png``: the initial configuration;
    - ``energies.png``;
    - ``joint<k>.png`` for every joint (springs and torsion springs on the same node pair);
    - ``animation.gif`` (with ``animation=True``), real time, but sped up to play in at most
      ``max_gif_seconds`` seconds.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: list[Path] = []
    node = model.tip_node
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
