"""Series of a trajectory by name: values, axis label and unit.

Series names: a dof name (``"y5"``, its displacement, or its velocity / acceleration with
``kind="qd"`` / ``"qdd"``), a dof name with an explicit prefix (``"q:y5"``, ``"qd:y5"``,
``"qdd:y5"``), a joint output name (``"spring1.force"``, ``"torsion1.moment"``,
``"support1.x"``, ``"bar2.1.N"``), or an energy (``"energy:total"``, keys of
:attr:`Trajectory.energies <casflex.results.Trajectory>`).

Units: positions m; rotations rad; velocities m/s and rad/s; accelerations m/s^2 and rad/s^2;
forces N; moments N m; energies J.
"""

from __future__ import annotations

import re

import numpy as np

from casflex.results import Trajectory

#: Dof series kinds: trajectory attribute -> (description, unit of x/y, unit of theta).
KINDS: dict[str, tuple[str, str, str]] = {
    "q": ("displacement", "m", "rad"),
    "qd": ("velocity", "m/s", "rad/s"),
    "qdd": ("acceleration", "m/s$^2$", "rad/s$^2$"),
}


_ENERGY_LABELS = {
    "kinetic": "kinetic",
    "elastic": "elastic (springs, beams)",
    "gravity": "gravity potential",
    "total": "total",
    "work_external": "work of external loads",
    "work_dampers": "energy dissipated by the dampers",
    "balance_error": "balance error E - E(0) - W + W_d (integration; numerical damping if < 0)",
}

_OUTPUT_UNITS = {"force": "N", "fx": "N", "fy": "N", "length": "m", "moment": "N m",
                 "x": "N", "y": "N", "theta": "N m", "N": "N", "V": "N", "Ma": "N m", "Mb": "N m"}


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
