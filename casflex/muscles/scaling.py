"""A model's muscles on its subject: the .osim's muscles carried onto the subject's calibrated scene
(:func:`casflex.inverse.calibrate.calibrate`), as OpenSim's ScaleTool carries them.

The calibration scales each segment (a cluster of the kinematic tree) by one factor s about its proximal joint's
centre and moves the centre with the parent segment: a point P fixed in the segment goes to C' + s (P - C), C and
C' the centre before and after (in the plane; casflex reads C, C' and s off the two scenes: every node, centre of
mass and child joint point of the segment obeys it, checked to 1e-9 m). Each muscle then follows, as OpenSim's
ScaleTool does with a body's scale factors (here one factor, the same along the body's three axes):

- every path point's location in its body's frame is scaled by its body's factor (a MovingPathPoint's functions
  multiplied by it, OpenSim's ``MovingPathPoint::extendScale``), the body's frame carried with the segment: in the
  plane the point lands where the calibrated scene's segment carries it; out of the plane its z goes to
  Z' + s (z - Z), Z the z of the segment's proximal joint frame's origin, Z' where the parent segment carries it
  (the root's: as it is);
- a wrap cylinder's centre likewise, its radius times the factor;
- each muscle's optimal fibre length and tendon slack length are multiplied by the ratio of its muscle-tendon
  length after to before, both at the default pose (OpenSim's ``Muscle::extendPostScale``), so that a muscle of a
  scaled segment works on the same part of its force-length curve; its maximum isometric force is kept (as the
  ScaleTool keeps it).

A calibration without scaling (``scale = false``: markers placed, masses scaled) leaves every segment as it is:
the muscles are the model's.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from casflex.scene.functions import Multiplier

__all__ = ["SegmentScales", "segment_scales", "scaled_muscles"]

#: m: how far a point of a segment may land from C' + s (P - C) before the scenes are said to differ by more than a
#: scaling (the scenes' numbers are printed to 1e-16 relative; a metre-sized model rounds to 1e-15 m)
TOLERANCE = 1e-9


@dataclasses.dataclass(frozen=True)
class SegmentScales:
    """Each node's segment's scaling (module docstring): node -> (s, C (2,), C' (2,), Z, Z') with C, C' m in the
    plane, Z, Z' m the z of the segment's proximal joint frame's origin before and after."""

    of: dict[str, tuple[float, np.ndarray, np.ndarray, float, float]]

    def point(self, node: str, p) -> np.ndarray:
        """The point p (3,) m (ground, default pose) of ``node``'s segment after the scaling."""
        s, c, c1, z, z1 = self.of[node]
        p = np.asarray(p, dtype=float)
        return np.array([*(c1 + s * (p[:2] - c)), z1 + s * (p[2] - z)])

    def factor(self, node: str) -> float:
        return self.of[node][0]

    @property
    def scaled(self) -> bool:
        return any(abs(v[0] - 1.0) > 1e-12 for v in self.of.values())


def _segments(tree) -> tuple[dict[int, tuple[str | None, np.ndarray]], dict[int, int | None]]:
    """cluster -> (its proximal hinge or None for the root's, its centre (2,) m), and cluster -> parent cluster."""
    sc, idx = tree.model.scene, tree.model.node_names.index
    root = tree.cluster[idx(tree.root)]
    r = next(n for n in sc.nodes if n.name == tree.root)
    centre = {root: (None, np.array([r.x, r.y], dtype=float))}
    parent: dict[int, int | None] = {root: None}
    for h in tree.hinges:
        j = sc.item(h)
        a, b = (tree.cluster[idx(n)] for n in j.nodes)
        centre[b] = (h, np.asarray(sc.joint_point(j), dtype=float))
        parent[b] = a
    return centre, parent


def _fixed_points(scene, tree, cluster: int) -> list[tuple[str, np.ndarray]]:
    """(what, P (2,)) of the points fixed in ``cluster``: its nodes, its bodies' centres of mass, its child joints'
    points (markers are left out: the calibration places them on the static trial)."""
    idx = tree.model.node_names.index
    out = [(f"node {n.name!r}", np.array([n.x, n.y], dtype=float)) for n in scene.nodes
           if tree.cluster[idx(n.name)] == cluster]
    nodes = {n.name: n for n in scene.nodes}
    for b in scene.bodies:
        if tree.cluster[idx(b.node)] == cluster:
            n = nodes[b.node]
            out.append((f"body {b.name!r}", np.array([n.x if b.com_x is None else b.com_x,
                                                      n.y if b.com_y is None else b.com_y], dtype=float)))
    for h in tree.hinges:
        j = scene.item(h)
        if tree.cluster[idx(j.nodes[0])] == cluster and j.point is not None:
            out.append((f"joint {h!r}", np.asarray(scene.joint_point(j), dtype=float)))
    return out


def segment_scales(before, after, root: str | None, joint_z: dict[str, float], root_z: float) -> SegmentScales:
    """The segments' scaling from the model's scene ``before`` to the subject's ``after`` (module docstring);
    ``joint_z``: each hinge's proximal joint frame's origin z (m, default pose), ``root_z`` the root body's. ValueError
    in one line where ``after`` is not ``before`` scaled segment by segment (another model, or a hand-edited scene)."""
    from casflex.inverse.inputs import inverse_model
    from casflex.inverse.tree import kinematic_tree

    t0, t1 = (kinematic_tree(inverse_model(sc, root), root) for sc in (before, after))
    if t0.names != t1.names or [n.name for n in before.nodes] != [n.name for n in after.nodes]:
        raise ValueError(f"the subject's scene ({after.name}) is not its model's ({before.name}): its nodes or "
                         "coordinates differ")
    (c0, parent), (c1, _) = _segments(t0), _segments(t1)
    pts0 = {c: dict(_fixed_points(before, t0, c)) for c in c0}
    pts1 = {c: dict(_fixed_points(after, t1, c)) for c in c0}
    s = {}
    for c in c0:
        ratios = [np.linalg.norm(pts1[c][k] - c1[c][1]) / d for k, p in pts0[c].items()
                  if (d := np.linalg.norm(p - c0[c][1])) > 1e-6]
        s[c] = float(np.median(ratios)) if ratios else 1.0
        for k, p in pts0[c].items():
            miss = np.linalg.norm(c1[c][1] + s[c] * (p - c0[c][1]) - pts1[c][k])
            if miss > TOLERANCE:
                raise ValueError(f"the subject's scene ({after.name}): its {k} lies {1e3 * miss:.3g} mm from where "
                                 f"scaling its segment by {s[c]:.4g} about its joint puts it: not the model's scene "
                                 "scaled segment by segment (casflex calibrate); its muscles cannot follow it")
    z: dict[int, tuple[float, float]] = {}
    for c in _parents_first(parent):
        h = c0[c][0]
        if h is None:
            z[c] = (root_z, root_z)
        else:
            zp0, zp1 = z[parent[c]]
            z[c] = (joint_z[h], zp1 + s[parent[c]] * (joint_z[h] - zp0))
    idx = t0.model.node_names.index
    return SegmentScales({n.name: (s[k], c0[k][1], c1[k][1], *z[k])
                          for n in before.nodes for k in [t0.cluster[idx(n.name)]]})


def _parents_first(parent: dict[int, int | None]) -> list[int]:
    order, todo = [], dict(parent)
    while todo:
        ready = [c for c, p in todo.items() if p is None or p in order]
        order += ready
        for c in ready:
            del todo[c]
    return order


def _point(p, scales: SegmentScales):
    """A path point on the subject (module docstring)."""
    s = scales.factor(p.node)
    R = np.array(p.frame[:9], dtype=float).reshape(3, 3)
    origin = scales.point(p.node, p.frame[9:12])
    moving = tuple((axis, c, Multiplier(f, s)) for axis, c, f in p.moving)
    return dataclasses.replace(p, location=tuple(float(s * v) for v in p.location),
                               frame=(*(float(v) for v in R.ravel()), *(float(v) for v in origin)), moving=moving)


def _wrap(w, scales: SegmentScales):
    return dataclasses.replace(w, radius=w.radius * scales.factor(w.node),
                               centre=tuple(float(v) for v in scales.point(w.node, w.centre)),
                               frame=(*w.frame[:9], *(float(v) for v in scales.point(w.node, w.frame[9:12]))))


def scaled_muscles(osim, after, root: str | None = None):
    """(the OsimScene ``osim`` (:func:`casflex.scene.from_osim.scene_from_osim` with its muscles) carried onto the
    subject's calibrated scene ``after``, report lines): its muscles, body frames and joint frames scaled with the
    segments (module docstring). ValueError in one line where ``after`` is not ``osim``'s scene scaled."""
    from casflex.inverse.inputs import inverse_model
    from casflex.inverse.tree import kinematic_tree
    from casflex.muscles.path import MusclePaths
    from casflex.scene.from_osim import node_name

    before = osim.scene
    root = root or before.nodes[0].name
    joint_z = {h: float(f[2][2]) for h, f in osim.joint_frames.items()}
    body = next((b for b in osim.frames if node_name(b) == root), None)
    scales = segment_scales(before, after, root, joint_z, float(osim.frames[body][1][2]) if body else 0.0)
    if not scales.scaled:
        return dataclasses.replace(osim, scene=after), ["muscles: the subject's segments are the model's: its "
                                                        "muscles as the model gives them"]
    muscles = tuple(dataclasses.replace(m, path=tuple(_point(p, scales) for p in m.path),
                                        wraps=tuple(_wrap(w, scales) for w in m.wraps)) for m in osim.muscles)
    lengths = []
    for sc, ms in ((before, osim.muscles), (after, muscles)):
        tree = kinematic_tree(inverse_model(sc, root), root)
        z0 = tree.coordinates(np.asarray(tree.model.q0, dtype=float).ravel())
        lengths.append(np.asarray(MusclePaths(tree, ms).length(z0), dtype=float).ravel())
    ratio = lengths[1] / lengths[0]
    muscles = tuple(dataclasses.replace(m, optimal_fiber_length=m.optimal_fiber_length * r,
                                        tendon_slack_length=m.tendon_slack_length * r)
                    for m, r in zip(muscles, ratio, strict=True))
    frames = {b: (R, p if b == "ground" or node_name(b) not in scales.of else scales.point(node_name(b), p))
              for b, (R, p) in osim.frames.items()}
    joints = {h: (pa, ch, o if pa == "ground" else scales.point(node_name(pa), o))
              for h, (pa, ch, o) in osim.joint_frames.items()}
    lo, hi = int(np.argmin(ratio)), int(np.argmax(ratio))
    report = [f"muscles: their path points scaled with their segments, optimal fibre and tendon slack lengths by "
              f"the ratio of the muscle-tendon length after to before at the default pose (OpenSim's ScaleTool): "
              f"{ratio.min():.4f} ({muscles[lo].name}) to {ratio.max():.4f} ({muscles[hi].name}); maximum "
              "isometric forces kept"]
    return dataclasses.replace(osim, scene=after, muscles=muscles, frames=frames, joint_frames=joints), report
