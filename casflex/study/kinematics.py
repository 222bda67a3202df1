"""A trial's joint angles over its gait cycles and each cycle's toe-off (:func:`casflex.study.runner.trial_run`),
for the gait report's figures (``casflex study``, :mod:`casflex.plotting.study`).

Each angle is the lab's coordinate (:func:`casflex.inverse.lab_names.lab_coordinates`: ``knee_angle_r`` as the
model defines it, or the tree's ``knee.angle``), as filtered for the inverse dynamics, in degrees, cut into the
cycles of its joint's moment (the same foot, cycles and clean flags: an angle goes with its moment). A cycle's
toe-off is the foot's first foot off within it (:func:`casflex.study.events.swing_phases`: the lab's marked "Foot
Off", else its plate's), in % of the cycle.
"""

from __future__ import annotations

import numpy as np

from casflex.study.records import CycleLoad

__all__ = ["cycle_angles", "toe_offs"]


def _moment_of(name: str) -> tuple[str, ...]:
    """The names the moment along the coordinate ``name`` goes by (the lab's, or the scene's own)."""
    return (f"{name}_moment", f"{name.removesuffix('.angle')}.moment") if name.endswith(".angle") else \
        (f"{name}_moment",)


def cycle_angles(scene, res, loads: dict[str, CycleLoad]) -> dict[str, CycleLoad]:
    """coordinate -> its angle (deg) over the cycles of its moment in ``loads`` (module docstring); a coordinate
    with no moment there (the root's) is left out."""
    from casflex.inverse.lab_names import lab_coordinates
    from casflex.study.events import normalise

    values, units = lab_coordinates(scene, res.coordinate_names, res.z)
    out = {}
    for name, v in values.items():
        load = next((loads[m] for m in _moment_of(name) if m in loads), None)
        if units[name] != "rad" or load is None:
            continue
        deg = np.degrees(v)
        out[name] = CycleLoad(load.foot, load.cycles, load.clean,
                              tuple(tuple(normalise(res.t, deg, *c).tolist()) for c in load.cycles))
    return out


def toe_offs(found, scene, lab, feet: dict[str, list]) -> dict[str, tuple[float | None, ...]]:
    """foot -> each of its cycles' toe-off, % of the cycle (None where the cycle has no foot off)."""
    from casflex.study.events import swing_phases

    out = {}
    for foot, spans in feet.items():
        swings = swing_phases(found or [], scene, lab, foot, spans)
        out[foot] = tuple(next((100.0 * (a - c0) / (c1 - c0) for a, _ in swings if c0 < a < c1), None)
                          for c0, c1 in spans)
    return out
