"""The muscles of a trial as a result: the activations, forces and reserves of static optimization and the joint
reactions, written as OpenSim's StaticOptimization and JointReaction write them, and said in a few lines.

Files (:meth:`MuscleResult.save`, in one directory, named as OpenSim's AnalyzeTool names them):

- ``<name>_StaticOptimization_activation.sto``: time, each muscle's activation, then each actuator's control;
- ``<name>_StaticOptimization_force.sto``: time, each muscle's force (N), then each actuator's (N or N m);
- ``<name>_JointReaction_ReactionLoads.sto``: time and, per joint, ``<joint>_on_<body>_in_<frame>_fx, fy, fz``
  (N), ``mx, my, mz`` (N m) and ``px, py, pz`` (m: the point the load acts at, in that frame), OpenSim's
  labels; the planar model's fz, mx, my are 0;
- with bands, beside each (``<name>_..._sd.sto``): the same columns, each output's standard deviation.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from casflex.lab.tables import write_sto

__all__ = ["MuscleResult", "file_names"]

#: OpenSim's column suffixes of a joint's reaction, in its order.
REACTION_COLUMNS = ("fx", "fy", "fz", "mx", "my", "mz", "px", "py", "pz")


def file_names(name: str, bands: bool = False) -> tuple[str, ...]:
    """The files :meth:`MuscleResult.save` writes for a trial ``name`` (known before the work)."""
    base = tuple(f"{name}_{s}.sto" for s in ("StaticOptimization_activation", "StaticOptimization_force",
                                              "JointReaction_ReactionLoads"))
    return base + (tuple(b.replace(".sto", "_sd.sto") for b in base) if bands else ())


@dataclass(frozen=True, eq=False)
class MuscleResult:
    """A trial's muscles (module docstring).

    t (k,) s; ``muscles`` (n_m,) names, ``activations`` and ``forces`` (k, n_m) (N); ``actuators`` (n_a,) the
    reserves' and residuals' names, ``controls`` and ``actuator_forces`` (k, n_a) (N or N m); ``coordinates`` the
    joints' lab coordinates static optimization balanced and ``reserve_share`` (n_c,) each one's reserve moment
    over its moment (RMS over the trial); ``reactions``: OpenSim's column label -> (k,) (N, N m, m);
    ``resultants``: joint -> (k,) N the reaction force's magnitude; ``body_weight`` N; ``report`` what was done,
    a line each; ``settings`` the options; ``bands``: output -> (k,) one standard deviation (where asked; the
    outputs of :func:`casflex.muscles.bands.muscle_outputs`: ``<muscle>`` its force, ``<muscle>.activation``,
    the reactions' column labels, ``<joint>_resultant``); ``spread``: output -> (k,) the same output under
    another criterion minus this one (where asked); ``lines``: the bands' summary lines.
    """

    t: np.ndarray
    muscles: tuple[str, ...]
    activations: np.ndarray
    forces: np.ndarray
    actuators: tuple[str, ...]
    controls: np.ndarray
    actuator_forces: np.ndarray
    coordinates: tuple[str, ...]
    reserve_share: np.ndarray
    reactions: Mapping[str, np.ndarray]
    resultants: Mapping[str, np.ndarray]
    body_weight: float
    report: tuple[str, ...] = ()
    settings: Mapping = field(default_factory=dict)
    bands: Mapping[str, np.ndarray] = field(default_factory=dict)
    spread: Mapping[str, np.ndarray] = field(default_factory=dict)
    #: the coordinates no muscle crosses (their reserves carry all of their moments)
    uncrossed: tuple[str, ...] = ()
    lines: tuple[str, ...] = ()

    def tables(self, name: str) -> dict[str, tuple[str, dict[str, np.ndarray], dict[str, str]]]:
        """file name -> (title, columns, units) of each file :meth:`save` writes."""
        units = {**{m: "" for m in self.muscles}, **{a: "" for a in self.actuators}}
        act = {**dict(zip(self.muscles, self.activations.T, strict=True)),
               **dict(zip(self.actuators, self.controls.T, strict=True))}
        force = {**dict(zip(self.muscles, self.forces.T, strict=True)),
                 **dict(zip(self.actuators, self.actuator_forces.T, strict=True))}
        react_units = {c: {"f": "N", "m": "N m", "p": "m"}[c.rsplit("_", 1)[1][0]] for c in self.reactions}
        files = {f"{name}_StaticOptimization_activation.sto": ("Static Optimization", act, units),
                 f"{name}_StaticOptimization_force.sto": ("Static Optimization", force,
                                                          {**{m: "N" for m in self.muscles},
                                                           **{a: "N or N m" for a in self.actuators}}),
                 f"{name}_JointReaction_ReactionLoads.sto": ("Joint Reaction Loads", dict(self.reactions),
                                                             react_units)}
        if self.bands:
            for fname, (title, cols, u) in list(files.items()):
                key = (lambda c: f"{c}.activation") if "activation" in fname else (lambda c: c)
                sd = {c: self.bands[key(c)] for c in cols if key(c) in self.bands}
                files[fname.replace(".sto", "_sd.sto")] = (f"{title}: one standard deviation", sd,
                                                           {c: u[c] for c in sd})
        return files

    def save(self, directory: str | Path, name: str) -> list[Path]:
        """Write the files (module docstring) into ``directory`` (which exists), each atomically."""
        return [write_sto(Path(directory) / fname, self.t, cols, title=title, units=units)
                for fname, (title, cols, units) in self.tables(name).items()]

    def summary(self) -> str:
        """A few lines: the joint reactions' peaks in N and body weights (the hip first), the strongest muscles,
        the reserves' share, what the report says."""
        w = self.body_weight
        lines = ["joint reactions (peak force, N and body weights):"]
        for joint, r in sorted(self.resultants.items(), key=lambda kv: (not kv[0].startswith("hip"), kv[0])):
            k = int(np.argmax(r))
            band = self.bands.get(f"{joint}_resultant")
            sd = f" +- {band[k] / w:.2f}" if band is not None else ""
            other = self.spread.get(f"{joint}_resultant")
            alt = f"; other criterion {(r[k] + other[k]) / w:.2f} BW" if other is not None else ""
            lines.append(f"  {joint}: {r[k]:.0f} N, {r[k] / w:.2f}{sd} BW at t = {self.t[k]:.3f} s{alt}")
        peak = self.forces.max(axis=0)
        top = np.argsort(peak)[::-1][:5]
        lines.append("strongest muscles (peak force): " + ", ".join(f"{self.muscles[i]} {peak[i]:.0f} N" for i in top))
        shares = [(c, s) for c, s in zip(self.coordinates, self.reserve_share, strict=True)
                  if np.isfinite(s) and c not in self.uncrossed]
        if shares:
            c, s = max(shares, key=lambda cs: cs[1])
            lines.append(f"reserves: largest share {100 * s:.1f} % of {c}'s moment (RMS)")
        if self.uncrossed:
            lines.append(f"no muscle crosses {', '.join(self.uncrossed)}: the reserves carry their moments")
        return "\n".join([*lines, *self.lines, *self.report])
