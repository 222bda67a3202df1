"""Segments a trial's marker set does not cover, locked where they hang (a whole-body model on lower-body markers).

A lab that records Plug-in Gait's lower body has no marker on the trunk: a whole-body model's lumbar hinge is
then decided by nothing, and the marker fit would refuse the trial. As lower-limb gait models take the trunk
(the head, arms and trunk one segment riding on the pelvis), :func:`lock_unmarked` welds each hinge whose
whole subtree (the segment and everything it carries) has markers in the scene of which the trial records
none, at the scene's initial configuration (the coordinates' default values), and says so, naming the segment,
its joint and coordinate and the markers the trial lacks. Its mass still loads the segment it hangs on.

Only markers the trial lacks altogether count: a segment whose markers are in the file but unseen in the window
is a gap the marker fit refuses by name (:func:`casflex.inverse.fit.check_decided`), not a marker set without it;
a segment with no marker in the scene at all is the scene's to decide (a massless frame, or a hand welded by the
model already).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable

__all__ = ["lock_unmarked"]


def _subtrees(scene) -> dict[str, set[str]]:
    """Each node -> the nodes it carries (itself included), along the scene's two-node joints (a -> b)."""
    children: dict[str, list[str]] = {}
    for j in scene.joints:
        if len(j.nodes) == 2:
            children.setdefault(j.nodes[0], []).append(j.nodes[1])
    out: dict[str, set[str]] = {}

    def walk(n: str) -> set[str]:
        if n not in out:
            out[n] = {n}
            for c in children.get(n, ()):
                out[n] |= walk(c)
        return out[n]

    for n in scene.nodes:
        walk(n.name)
    return out


def lock_unmarked(scene, recorded: Iterable[str], source: str = "the trial") -> tuple[object, list[str]]:
    """(the scene with every hinge welded whose subtree's weighted markers the trial records none of, and those
    markers left out, a line per locked joint): module docstring. ``recorded``: the trial's marker labels. The
    scene as it is where nothing is locked."""
    recorded = set(recorded)
    node_of = {b.name: b.node for b in scene.bodies} | {b.name: b.nodes[0] for b in scene.beams}
    marks: dict[str, list] = {}
    for m in scene.markers:
        if m.weight > 0:
            marks.setdefault(node_of.get(m.on, m.on), []).append(m)
    below = _subtrees(scene)
    locked, riding, lines = set(), set(), []
    for j in scene.joints:
        if j.kind != "hinge" or len(j.nodes) != 2 or j.nodes[1] in locked:
            continue
        carried = below[j.nodes[1]]
        on = [m for n in carried for m in marks.get(n, ())]
        if not on or any(m.lab_label in recorded for m in on):
            continue
        hinges = [h for h in scene.joints if h.kind == "hinge" and len(h.nodes) == 2 and h.nodes[1] in carried]
        locked |= {h.nodes[1] for h in hinges}
        riding |= carried
        coords = [c.name for c in scene.coordinates if c.of in {h.name for h in hinges}]
        lines.append(f"segment {j.nodes[1]!r}: {source} has none of its markers {[m.lab_label for m in on]}: its "
                     f"joint{'s' * (len(hinges) > 1)} {', '.join(repr(h.name) for h in hinges)}"
                     + (f" ({', '.join(coords)})" if coords else "") + " locked at the model's default pose (the "
                     f"segment rides on {j.nodes[0]!r}, its mass with it)")
    if not lines:
        return scene, []
    welded = tuple(dataclasses.replace(j, kind="weld", axis=None, shift_x=None, shift_y=None)
                   if j.kind == "hinge" and len(j.nodes) == 2 and j.nodes[1] in locked else j for j in scene.joints)
    gone = {j.name for j, w in zip(scene.joints, welded, strict=True) if w is not j}
    lost = {m.name for n in riding for m in marks.get(n, ())}  # the trial has none of them: nothing to fit
    return dataclasses.replace(scene, joints=welded,
                               coordinates=tuple(c for c in scene.coordinates if c.of not in gone),
                               markers=tuple(m for m in scene.markers if m.name not in lost)), lines
