"""Muscle paths on a planar scene: each muscle's length, its moment arms about the lab's coordinates and the load
a unit tension puts on each hinge's distal part, as CasADi functions of the kinematic tree's coordinates z.

The points move with their nodes (:mod:`casflex.scene.muscles`): a point at P0 (m, ground, the default pose) on
the node at (x0, y0, theta0) there is, at the tree's configuration q = forward(z), at (x, y) + R(theta -
theta0) (P0_xy - (x0, y0)) in the plane and at P0_z out of it. A MovingPathPoint's P0 follows its lab
coordinate's value (its function of the value clamped to the coordinate's range, as OpenSim does); a
ConditionalPathPoint is on the path while its coordinate is within [lower - 1e-5, upper + 1e-5] (OpenSim's
``ConditionalPathPoint::isActive``), switched by CasADi's ``if_else``. The length is the sum of the 3D
distances between consecutive points on the path (OpenSim's ``GeometryPath``), a segment in a wrap's range that
wraps replaced by its tangent lines and its arc on the cylinder (:mod:`casflex.muscles.wrap`).

Moment arms are OpenSim's, -dL/d(value) along each lab coordinate (``scene.coordinates`` order; m for a
rotation, dimensionless for a translation), exact by AD: a lab coordinate's value is value0 + sign (own -
own0) (:mod:`casflex.scene.coordinates`), so the moment arm is -sign dL/d(own).

Unit loads. For each hinge (``tree.hinges`` order) the force (fx, fy; N per N of tension, ground axes) and the
moment about the hinge's centre (its point carried by its child node, i.e. the point of the scene joint;
N m per N, counter-clockwise about the plane's normal positive) that a muscle's unit tension applies to the
hinge's distal part (the bodies beyond it from the root): each path segment with one end on the distal part and
one off it pulls that end towards the other (a wrapped segment's tangent points are on the cylinder's node, so
the cylinder's body takes the wrap's pull there). By virtual work the moment equals -dL/d(own angle) of the hinge
(the moment arm about the scene's own angle; for a lab coordinate of sign s, s times its moment arm) where the
hinge's centre is fixed on its parent and the muscle's points are fixed on their bodies; a coupled hinge's
centre rolls with its angle, and its generalised force is that moment plus (fx, fy) . d(centre)/d(angle); a
MovingPathPoint adds its pull along its own motion in its body (d(location)/d(angle)), which moves no body: the
moment arm holds it, the moment does not. The out-of-plane component of the pull and its moments about the
plane's axes are left out (the planar inverse dynamics has none). Two points at one place give a segment of
length 0 whose derivative and pull are taken as 0 (not 0/0).
"""

from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from casflex.elements.joints import spline_of
from casflex.muscles.wrap import check_wraps, wrapped_pieces
from casflex.scene.coordinates import to_lab
from casflex.scene.functions import Clamped, Constant, Linear, Multiplier, Polynomial, SimmSpline

__all__ = ["MusclePaths", "symbolic"]

#: OpenSim's tolerance on a ConditionalPathPoint's range (rad or m): ConditionalPathPoint::isActive.
CONDITION_TOLERANCE = 1e-5


def symbolic(f, x):
    """The function ``f`` (:mod:`casflex.scene.functions`) of the CasADi expression x."""
    if isinstance(f, Constant):
        return 0.0 * x + f.value
    if isinstance(f, Linear):
        return f.slope * x + f.intercept
    if isinstance(f, Polynomial):
        out = 0.0 * x
        for c in f.coefficients:
            out = out * x + c
        return out
    if isinstance(f, SimmSpline):
        return spline_of(f, x)
    if isinstance(f, Multiplier):
        return f.scale * symbolic(f.inner, x)
    if isinstance(f, Clamped):
        return symbolic(f.inner, ca.fmin(ca.fmax(x, f.lower), f.upper))
    raise ValueError(f"a {type(f).__name__} is not evaluated symbolically by casflex")


def _rot(th, v):
    c, s = ca.cos(th), ca.sin(th)
    return ca.vertcat(c * v[0] - s * v[1], s * v[0] + c * v[1])


def _distance(a, b):
    """|b - a| (m), its derivative 0 where the points coincide (two points at one place on one body: the length
    does not change there), not NaN."""
    d2 = ca.sumsqr(b - a)
    return ca.if_else(d2 > 0, ca.sqrt(d2), 0)


def _direction(a, b):
    """The unit vector from a to b, zeros where they coincide (the segment pulls neither point)."""
    d2 = ca.sumsqr(b - a)
    return ca.if_else(d2 > 0, (b - a) / ca.sqrt(d2), ca.SX.zeros(3))


class MusclePaths:
    """The paths of ``muscles`` (:class:`casflex.scene.muscles.Muscle`) on the kinematic tree ``tree``
    (:class:`casflex.inverse.tree.KinematicTree`; module docstring): ``length``, ``moment_arms``, ``unit_loads``
    (CasADi Functions of z) and :meth:`evaluate` (numpy, many frames). ValueError naming the muscle for a point
    on no node of the tree, or a condition or moving point of no lab coordinate of the scene."""

    def __init__(self, tree, muscles):
        self.tree = tree
        self.muscles = tuple(muscles)
        self.scene = tree.model.scene
        self.coordinates = tuple(self.scene.coordinates)
        self.names = tuple(m.name for m in self.muscles)
        self._check()
        self.z = ca.SX.sym("z", tree.n)
        self.q = tree.forward(self.z)
        self.values = {c.name: to_lab(self.scene, c, self.z[tree.names.index(c.scene_coordinate())])
                       for c in self.coordinates}

    def _check(self) -> None:
        nodes, lab = set(self.tree.model.node_names), {c.name for c in self.coordinates}
        missing = [c.scene_coordinate() for c in self.coordinates if c.scene_coordinate() not in self.tree.names]
        if missing:
            raise ValueError(f"coordinates: {missing[0]!r} is no coordinate of the kinematic tree "
                             f"{list(self.tree.names)}")
        for m in self.muscles:
            for p in m.path:
                where = f"muscle {m.name!r} path point {p.name!r}"
                if p.node not in nodes:
                    raise ValueError(f"{where}: node {p.node!r} is no node of the scene")
                used = ([p.condition[0]] if p.condition else []) + [c for _, c, _ in p.moving]
                for c in used:
                    if c not in lab:
                        raise ValueError(f"{where}: follows {c!r}, no coordinate of the scene ([[coordinates]]: "
                                         f"{sorted(lab)})")
            if len(m.path) < 2:
                raise ValueError(f"muscle {m.name!r}: {len(m.path)} path point(s); a path needs two or more")
            check_wraps(m, nodes)

    # -- geometry -------------------------------------------------------------------------
    def _point(self, p) -> ca.SX:
        """The point's position (3,) in the ground at z."""
        loc = ca.SX(ca.DM([float(v) for v in p.location]))
        for axis, c, f in p.moving:
            loc[axis] = symbolic(f, self.values[c])
        R = np.array(p.frame[:9], dtype=float).reshape(3, 3)
        P0 = ca.DM(p.frame[9:12]) + ca.mtimes(ca.DM(R), loc)
        i = self.tree.model.node_names.index(p.node)
        x0 = self.tree.model.q0[3 * i: 3 * i + 3]
        xy = self.q[3 * i: 3 * i + 2] + _rot(self.q[3 * i + 2] - x0[2], P0[:2] - ca.DM(x0[:2]))
        return ca.vertcat(xy, P0[2])

    def _active(self, p):
        """1 where the point is on the path (a ConditionalPathPoint's test), a CasADi expression."""
        if p.condition is None:
            return 1
        c, lo, hi = p.condition
        v = self.values[c]
        return (v >= lo - CONDITION_TOLERANCE) * (v <= hi + CONDITION_TOLERANCE)

    def _segments(self, m) -> list[tuple[int, int, object]]:
        """(i, j, on): the path's possible segments from point i to the next point j on the path, ``on`` the
        condition (1 or an expression) that i and j are on it and every point between them is not."""
        act = [self._active(p) for p in m.path]
        out = []
        for i in range(len(m.path)):
            between = 1
            for j in range(i + 1, len(m.path)):
                out.append((i, j, act[i] * act[j] * between))
                if m.path[j].condition is None:
                    break
                between = between * (1 - act[j])
        return out

    @functools.cached_property
    def _geometry(self) -> list[list[tuple]]:
        """Each muscle's pieces (a, node a, b, node b, on, length): the straight segments between its points and,
        where a wrap applies, the wrapped segment's tangent lines and arc (:mod:`casflex.muscles.wrap`)."""
        out = []
        for m in self.muscles:
            pts, segs = [self._point(p) for p in m.path], self._segments(m)
            nodes = [self.tree.model.node_names.index(p.node) for p in m.path]
            out.append(wrapped_pieces(self, m, pts, nodes, segs))
        return out

    @functools.cached_property
    def _lengths(self) -> ca.SX:
        out = []
        for pieces in self._geometry:
            L = 0
            for *_, on, d in pieces:
                L = L + (d if isinstance(on, int) else ca.if_else(on, d, 0))
            out.append(L)
        return ca.vertcat(*out) if out else ca.SX(0, 1)

    # -- functions -------------------------------------------------------------------------
    @functools.cached_property
    def length(self) -> ca.Function:
        """``length(z) -> (n_m,)``: each muscle's path length (m)."""
        return ca.Function("muscle_length", [self.z], [self._lengths], ["z"], ["L"])

    @functools.cached_property
    def _dz_dvalue(self) -> ca.DM:
        """(n_z, n_c): d(own)/d(value) = sign on the coordinate's own row."""
        S = np.zeros((self.tree.n, len(self.coordinates)))
        for k, c in enumerate(self.coordinates):
            S[self.tree.names.index(c.scene_coordinate()), k] = c.sign
        return ca.DM(S)

    @functools.cached_property
    def moment_arms(self) -> ca.Function:
        """``moment_arms(z) -> (n_m, n_c)``: OpenSim's -dL/d(value) of each muscle along each lab coordinate
        (scene.coordinates order; m for rotations, dimensionless for translations)."""
        r = -ca.mtimes(ca.jacobian(self._lengths, self.z), self._dz_dvalue)
        return ca.Function("muscle_moment_arms", [self.z], [r], ["z"], ["r"])

    @functools.cached_property
    def rates(self) -> ca.Function:
        """``rates(z, zd) -> (L, Ld, r)``: lengths (m), lengthening speeds dL/dz zd (m/s) and moment arms."""
        zd = ca.SX.sym("zd", self.tree.n)
        Ld = ca.jtimes(self._lengths, self.z, zd)
        return ca.Function("muscle_rates", [self.z, zd], [self._lengths, Ld, self.moment_arms(self.z)],
                           ["z", "zd"], ["L", "Ld", "r"])

    def evaluate(self, z: np.ndarray, zd: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Over k frames (z, zd (k, n_z)): ``lengths`` (k, n_m) m, ``speeds`` (k, n_m) m/s (zeros without zd),
        ``moment_arms`` (k, n_m, n_c)."""
        z = np.atleast_2d(np.asarray(z, dtype=float))
        zd = np.zeros_like(z) if zd is None else np.atleast_2d(np.asarray(zd, dtype=float))
        k, n_m, n_c = z.shape[0], len(self.muscles), len(self.coordinates)
        L, Ld, r = self.rates.map(k)(z.T, zd.T)
        r = np.array(r).reshape(n_m, k, n_c) if n_m else np.zeros((0, k, n_c))
        return {"lengths": np.array(L).T.reshape(k, n_m), "speeds": np.array(Ld).T.reshape(k, n_m),
                "moment_arms": np.transpose(r, (1, 0, 2))}

    @functools.cached_property
    def unit_loads(self) -> ca.Function:
        """``unit_loads(z) -> (3 n_hinges, n_m)``: per hinge (tree.hinges order) fx, fy (N/N) and the moment
        about its centre (N m/N) a unit tension of each muscle applies to the hinge's distal part (module
        docstring)."""
        cols = []
        distal = [self._distal(h) for h in self.tree.hinges]
        centres = [self._centre(h) for h in self.tree.hinges]
        for pieces in self._geometry:
            col = []
            for D, C in zip(distal, centres, strict=True):
                F, M = ca.SX.zeros(2), 0
                for pa, na, pb, nb, on, _ in pieces:
                    if (na in D) == (nb in D):
                        continue
                    a, b = (pa, pb) if na in D else (pb, pa)
                    u = _direction(a, b)
                    f = u[:2] if isinstance(on, int) else ca.if_else(on, u[:2], ca.SX.zeros(2))
                    arm = a[:2] - C
                    F, M = F + f, M + arm[0] * f[1] - arm[1] * f[0]
                col.append(ca.vertcat(F, M))
            cols.append(ca.vertcat(*col) if col else ca.SX(0, 1))
        out = ca.horzcat(*cols) if cols else ca.SX(3 * len(self.tree.hinges), 0)
        return ca.Function("muscle_unit_loads", [self.z], [out], ["z"], ["loads"])

    def _distal(self, hinge: str) -> set[int]:
        """The model nodes beyond ``hinge`` from the root."""
        return distal_nodes(self.tree, self.scene, hinge)

    def _centre(self, hinge: str) -> ca.SX:
        """The hinge's point (2,) at z, carried by its child node."""
        j = self.scene.item(hinge)
        i = self.tree.model.node_names.index(j.nodes[1])
        x0 = self.tree.model.q0[3 * i: 3 * i + 3]
        P = np.asarray(self.scene.joint_point(j), dtype=float)
        return self.q[3 * i: 3 * i + 2] + _rot(self.q[3 * i + 2] - x0[2], ca.DM(P - x0[:2]))


def distal_nodes(tree, scene, hinge: str) -> set[int]:
    """The model nodes of ``tree`` beyond ``hinge`` (a hinge of ``scene``) from the tree's root."""
    idx = tree.model.node_names.index
    parent = {tree.cluster[idx(scene.item(h).nodes[1])]: tree.cluster[idx(scene.item(h).nodes[0])]
              for h in tree.hinges}
    top = tree.cluster[idx(scene.item(hinge).nodes[1])]

    def beyond(c: int) -> bool:
        while c in parent:
            if c == top:
                return True
            c = parent[c]
        return c == top

    return {n for n in range(len(tree.cluster)) if beyond(tree.cluster[n])}
