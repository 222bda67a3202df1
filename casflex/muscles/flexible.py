"""Muscles on flexible segments (issue 47, item 6): a model's muscles carried onto a scene whose bones are beams,
their paths on the deformed bones.

A muscle's path points sit on the bodies of its OpenSim model (:mod:`casflex.scene.muscles`). On another scene of
the same subject (the same default pose and joint centres, e.g. built-in ``hamner_leg_flexible``, whose thigh and
shank are chains of co-rotational Euler-Bernoulli beams, :mod:`casflex.elements.beam`), each body is carried either
by a node (a rigid segment: the point moves with the node) or by a chain of beams end to end:

- the point's default position P0 is projected on the chain's straight reference line; it lies on the element whose
  chord holds the projection, at xi in [0, 1] along it, off the line by P0 - c0(xi);
- at a configuration q the element's chord runs from node a to node b (length L, angle beta); its local end
  rotations are theta_a = (phi_a - phi0_a) - (beta - beta0) and likewise at b (wrapped to [-pi, pi), as the
  element's own, :func:`casflex.elements.beam.wrap_angle`); the centre line is the element's shape functions: the
  chord's linear interpolation plus the transverse Hermite cubic v(xi) = L0 ((xi - 2 xi^2 + xi^3) theta_a +
  (xi^3 - xi^2) theta_b) along the chord's normal; the cross-section turns by (beta - beta0) + v'(xi) (plane sections
  stay normal to the centre line: Euler-Bernoulli), and the point is c(xi) plus the turned offset;
- a point beyond the chain's ends (the bone's ends: the femoral neck and condyles beyond its shaft) moves rigidly
  with the end node's section;
- out of the plane the point's z stays its default (as on a rigid segment).

A MovingPathPoint's location follows its coordinate (the hinge's relative angle here) and sits on the section of its
default projection; a ConditionalPathPoint is on the path as OpenSim tests it.

The paths' lengths, speeds and each hinge's unit loads (the force and the moment about the hinge's centre that a
unit tension puts on the hinge's distal part, :mod:`casflex.muscles.path`'s) are CasADi functions of the scene's
configuration q (every node's x, y, theta), so they take the flexible inverse's deformed q
(:func:`casflex.inverse.flexible.driven_loads`) as they take a rigid one. The moment about a fixed hinge centre of
a unit tension on the distal part is the muscle's moment arm about the hinge with the deformation held.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from casflex.elements.beam import wrap_angle
from casflex.muscles.path import CONDITION_TOLERANCE, distal_nodes, symbolic

__all__ = ["BeamSite", "FlexiblePaths"]


def _rot(th, v):
    c, s = ca.cos(th), ca.sin(th)
    return ca.vertcat(c * v[0] - s * v[1], s * v[0] + c * v[1])


@dataclass(frozen=True)
class BeamSite:
    """Where a point sits on a chain: element ``a``-``b`` (node indices of the scene's model), at ``xi`` in [0, 1]
    along its chord, or (``a`` = ``b``) rigidly on the end node ``a``."""

    a: int
    b: int
    xi: float


class FlexiblePaths:
    """The paths of ``muscles`` (:class:`casflex.scene.muscles.Muscle`, on their model's nodes) on ``tree``
    (:class:`casflex.inverse.tree.KinematicTree` of the target scene), each model body (node name) carried by
    ``bodies[body]``: a node of the scene or a tuple of its beams end to end, proximal first (module docstring);
    ``coordinates``: each lab coordinate a moving or conditional point follows -> (the scene's hinge, sign, value0).
    ValueError naming the muscle for a point on a body not carried, a coordinate not given."""

    def __init__(self, tree, muscles, bodies: dict[str, str | tuple[str, ...]],
                 coordinates: dict[str, tuple[str, float, float]] | None = None) -> None:
        self.tree, self.muscles = tree, tuple(muscles)
        self.model, self.scene = tree.model, tree.model.scene
        self.names = tuple(m.name for m in self.muscles)
        self.coordinates = dict(coordinates or {})
        self.q = ca.SX.sym("q", self.model.n_dof)
        self.q0 = np.asarray(self.model.q0, dtype=float).ravel()
        self._bodies = {b: self._chain(b, c) for b, c in bodies.items()}
        for m in self.muscles:
            for p in m.path:
                if p.node not in self._bodies:
                    raise ValueError(f"muscle {m.name!r} path point {p.name!r}: on {p.node!r}, which no node or beam "
                                     f"of the scene carries (bodies given: {sorted(self._bodies)})")
                for c in ([p.condition[0]] if p.condition else []) + [c for _, c, _ in p.moving]:
                    if c not in self.coordinates:
                        raise ValueError(f"muscle {m.name!r} path point {p.name!r}: follows {c!r}, which no hinge of "
                                         "the scene is given for")

    def _chain(self, body: str, carrier) -> tuple[int, ...]:
        """The node indices along the carrier: one node, or the chain's nodes proximal to distal."""
        idx = self.model.node_names.index
        if isinstance(carrier, str):
            return (idx(carrier),)
        beams = {b.name: b for b in self.scene.beams}
        nodes = []
        for name in carrier:
            if name not in beams:
                raise ValueError(f"bodies: {body}: {name!r} is no beam of the scene")
            a, b = beams[name].nodes
            if nodes and nodes[-1] != a:
                raise ValueError(f"bodies: {body}: beam {name!r} does not start where the one before it ends")
            nodes += [a, b] if not nodes else [b]
        return tuple(idx(n) for n in nodes)

    def _x0(self, i: int) -> np.ndarray:
        return self.q0[3 * i: 3 * i + 3]

    def site(self, body: str, P0) -> BeamSite:
        """Where the default point P0 (3,) m of ``body`` sits on its carrier (module docstring)."""
        chain = self._bodies[body]
        if len(chain) == 1:
            return BeamSite(chain[0], chain[0], 0.0)
        P = np.asarray(P0, dtype=float)[:2]
        for a, b in zip(chain[:-1], chain[1:], strict=True):
            xa, c0 = self._x0(a)[:2], self._x0(b)[:2] - self._x0(a)[:2]
            xi = float(np.dot(P - xa, c0) / np.dot(c0, c0))
            if 0.0 <= xi <= 1.0:
                return BeamSite(a, b, xi)
        first = float(np.dot(P - self._x0(chain[0])[:2], self._x0(chain[1])[:2] - self._x0(chain[0])[:2]))
        end = chain[0] if first < 0 else chain[-1]
        return BeamSite(end, end, 0.0)

    def _rigid(self, i: int, P0) -> ca.SX:
        x0 = self._x0(i)
        return self.q[3 * i: 3 * i + 2] + _rot(self.q[3 * i + 2] - x0[2], P0[:2] - ca.DM(x0[:2]))

    def _on_beam(self, s: BeamSite, P0) -> ca.SX:
        """The point at P0 (default, ground) on element a-b at xi (module docstring), at q."""
        xa0, xb0 = self._x0(s.a), self._x0(s.b)
        c0 = xb0[:2] - xa0[:2]
        L0, beta0 = float(np.linalg.norm(c0)), math.atan2(c0[1], c0[0])
        qa, qb = self.q[3 * s.a: 3 * s.a + 3], self.q[3 * s.b: 3 * s.b + 3]
        c = qb[:2] - qa[:2]
        beta = ca.atan2(c[1], c[0])
        ta = wrap_angle((qa[2] - xa0[2]) - (beta - beta0))
        tb = wrap_angle((qb[2] - xb0[2]) - (beta - beta0))
        xi = s.xi
        v = L0 * ((xi - 2 * xi ** 2 + xi ** 3) * ta + (xi ** 3 - xi ** 2) * tb)
        slope = (1 - 4 * xi + 3 * xi ** 2) * ta + (3 * xi ** 2 - 2 * xi) * tb
        normal = ca.vertcat(-ca.sin(beta), ca.cos(beta))
        centre = qa[:2] + xi * c + v * normal
        offset = P0[:2] - ca.DM(xa0[:2] + xi * c0)
        return centre + _rot(beta - beta0 + slope, offset)

    def _value(self, coordinate: str):
        hinge, sign, value0 = self.coordinates[coordinate]
        a, b = (self.model.node_names.index(n) for n in self.scene.item(hinge).nodes)
        rel = self.q[3 * b + 2] - self.q[3 * a + 2]
        return value0 + sign * (rel - float(self.q0[3 * b + 2] - self.q0[3 * a + 2]))

    def _point(self, p) -> ca.SX:
        loc = ca.SX(ca.DM([float(v) for v in p.location]))
        for axis, c, f in p.moving:
            loc[axis] = symbolic(f, self._value(c))
        R = np.array(p.frame[:9], dtype=float).reshape(3, 3)
        P0 = ca.DM(p.frame[9:12]) + ca.mtimes(ca.DM(R), loc)
        default = np.asarray(p.frame[9:12], dtype=float) + R @ np.asarray(p.location, dtype=float)
        s = self.site(p.node, default)
        xy = self._rigid(s.a, P0) if s.a == s.b else self._on_beam(s, P0)
        return ca.vertcat(xy, P0[2])

    def _active(self, p):
        if p.condition is None:
            return 1
        c, lo, hi = p.condition
        v = self._value(c)
        return (v >= lo - CONDITION_TOLERANCE) * (v <= hi + CONDITION_TOLERANCE)

    def node_of(self, p) -> int:
        """The node whose segment (cluster) carries the point."""
        return self._bodies[p.node][0]

    @functools.cached_property
    def _geometry(self):
        out = []
        for m in self.muscles:
            act = [self._active(p) for p in m.path]
            segs = []
            for i in range(len(m.path)):
                between = 1
                for j in range(i + 1, len(m.path)):
                    segs.append((i, j, act[i] * act[j] * between))
                    if m.path[j].condition is None:
                        break
                    between = between * (1 - act[j])
            out.append(([self._point(p) for p in m.path], segs))
        return out

    @functools.cached_property
    def _lengths(self) -> ca.SX:
        out = []
        for pts, segs in self._geometry:
            L = 0
            for i, j, on in segs:
                d2 = ca.sumsqr(pts[j] - pts[i])
                d = ca.if_else(d2 > 0, ca.sqrt(d2), 0)
                L = L + (d if isinstance(on, int) else ca.if_else(on, d, 0))
            out.append(L)
        return ca.vertcat(*out)

    @functools.cached_property
    def rates(self) -> ca.Function:
        """``rates(q, qd) -> (L, Ld)``: each muscle's length (m) and lengthening speed (m/s)."""
        qd = ca.SX.sym("qd", self.model.n_dof)
        return ca.Function("flexible_muscle_rates", [self.q, qd],
                           [self._lengths, ca.jtimes(self._lengths, self.q, qd)])

    def _distal(self, hinge: str) -> set[int]:
        return distal_nodes(self.tree, self.scene, hinge)

    def centre(self, hinge: str) -> ca.SX:
        """The hinge's point (2,) at q, carried by its child node."""
        j = self.scene.item(hinge)
        i = self.model.node_names.index(j.nodes[1])
        return self._rigid(i, ca.DM(np.asarray(self.scene.joint_point(j), dtype=float)))

    @functools.cached_property
    def unit_loads(self) -> ca.Function:
        """``unit_loads(q) -> (3 n_hinges, n_m)``: per hinge (``tree.hinges``) fx, fy (N/N, ground) and the moment
        about its centre (N m/N) a unit tension of each muscle puts on the hinge's distal part."""
        cols = []
        hinges = [(self._distal(h), self.centre(h)) for h in self.tree.hinges]
        for m, (pts, segs) in zip(self.muscles, self._geometry, strict=True):
            nodes = [self.node_of(p) for p in m.path]
            col = []
            for D, C in hinges:
                F, M = ca.SX.zeros(2), 0
                for i, j, on in segs:
                    if (nodes[i] in D) == (nodes[j] in D):
                        continue
                    a, b = (i, j) if nodes[i] in D else (j, i)
                    d = pts[b] - pts[a]
                    d2 = ca.sumsqr(d)
                    u = ca.if_else(d2 > 0, d / ca.sqrt(d2), ca.SX.zeros(3))
                    f = u[:2] if isinstance(on, int) else ca.if_else(on, u[:2], ca.SX.zeros(2))
                    arm = pts[a][:2] - C
                    F, M = F + f, M + arm[0] * f[1] - arm[1] * f[0]
                col.append(ca.vertcat(F, M))
            cols.append(ca.vertcat(*col))
        return ca.Function("flexible_unit_loads", [self.q], [ca.horzcat(*cols)])

    def evaluate(self, q: np.ndarray, qd: np.ndarray) -> dict[str, np.ndarray]:
        """Over k frames (q, qd (k, n_dof)): ``lengths``, ``speeds`` (k, n_m) m, m/s and ``unit`` (k, 3 n_h, n_m)."""
        q, qd = np.atleast_2d(q), np.atleast_2d(qd)
        k, n_m = q.shape[0], len(self.muscles)
        L, Ld = self.rates.map(k)(q.T, qd.T)
        U = np.array(self.unit_loads.map(k)(q.T)).reshape(-1, n_m, k, order="F").transpose(2, 0, 1)
        return {"lengths": np.array(L).T.reshape(k, n_m), "speeds": np.array(Ld).T.reshape(k, n_m), "unit": U}


def carried_muscles(osim, bodies: dict[str, object]) -> tuple[tuple, list[str]]:
    """(the muscles of ``osim`` whose every point's body is in ``bodies``, report lines naming those left out)."""
    keep, out = [], []
    for m in osim.muscles:
        (keep if all(p.node in bodies for p in m.path) else out).append(m)
    lines = [f"muscles left out (a point on a body the scene does not carry): {', '.join(m.name for m in out)}"] \
        if out else []
    return tuple(keep), lines


def solve_muscles(paths: FlexiblePaths, q: np.ndarray, qd: np.ndarray, loads: dict[str, np.ndarray], *,
                  reserve: float = 1.0, optimization=None, body_weight: float | None = None) -> dict:
    """Static optimization over the scene's hinges and their reactions at the frames' configurations q, qd (k,
    n_dof) with the inverse's ``loads`` (``<hinge>.moment``, ``.fx``, ``.fy``; rigid or flexible): each muscle's
    moment arm is its unit load's moment about the hinge's centre on the deformed geometry (module docstring); a
    reserve of ``reserve`` N m on each hinge. Returns {"so": the result, "reactions": hinge -> (k, 3) fx, fy, mz
    (BW with ``body_weight`` N, else N), "arms" (k, n_m, n_h), "lengths" (k, n_m)}."""
    from casflex.muscles.curves import rigid_tendon
    from casflex.muscles.reaction import JointReaction, joint_reactions
    from casflex.muscles.static_optimization import solve_static_optimization

    hinges = list(paths.tree.hinges)
    geo = paths.evaluate(q, qd)
    arms = geo["unit"][:, 2::3, :].transpose(0, 2, 1)  # (k, n_m, n_h): the moments about the centres
    moments = np.column_stack([loads[f"{h}.moment"] for h in hinges])
    cap = [rigid_tendon(m, geo["lengths"][:, i], geo["speeds"][:, i]) for i, m in enumerate(paths.muscles)]
    active, passive = np.column_stack([c.active for c in cap]), np.column_stack([c.passive for c in cap])
    so = solve_static_optimization(moments, arms, active, passive, np.full(len(hinges), reserve), optimization,
                                   coordinates=hinges, max_isometric=[m.max_isometric_force for m in paths.muscles])
    net = np.stack([np.column_stack([loads[f"{h}.fx"], loads[f"{h}.fy"], loads[f"{h}.moment"]]) for h in hinges],
                   axis=1)
    r = joint_reactions(net, geo["unit"], so.forces, options=JointReaction(frame="ground", body_weight=body_weight))
    return {"so": so, "reactions": {h: r.loads[:, i, :] for i, h in enumerate(hinges)}, "arms": arms,
            "lengths": geo["lengths"]}

