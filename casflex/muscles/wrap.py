"""A path segment wrapping over a cylinder whose axis is the plane's normal: a circle in the plane, as OpenSim's
``WrapCylinder::wrapLine`` computes it, in CasADi (exact, differentiable where the wrap does not switch).

Everything here is in the cylinder's frame: its axis is z, its centre the origin; a point is (x, y, depth), the
depth along the axis. For the two points P1, P2 of a path segment:

- no wrap where either point is inside the circle (OpenSim's ``insideRadius``);
- quadrant ``all`` (unconstrained): the segment wraps only where the straight line P1-P2 passes through the circle
  (its closest point to the axis nearer than the radius and strictly between P1 and P2: ``mandatoryWrap``), over
  the pair of tangent points (one from each point) closest to each other;
- a quadrant ``+x``, ``-y``, ... (constrained, the sign s of the axis k in the cylinder's frame): where P1 or P2
  lies on the active side (sign of its k-th coordinate = s, OpenSim's DSIGN taking 0 as +), the segment wraps if
  the line passes through the circle (mandatory), or if P1 and P2 lie on opposite sides and the line's closest
  point to the axis is not on the active side (``wrapped``); where neither point is on the active side it always
  wraps (``wrapped``) over the active side. The tangent points are chosen as OpenSim chooses them (which of each
  point's two lies on the active side), and the wrap goes the long way round where the sum of the tangent
  points' radii points against the sum of the path's pulls at them (OpenSim's ``long_wrap``).

Lengths. The arc between the tangent points r1, r2 is R theta, theta = atan2((r1 x r2) . z, r1 . r2) (2 pi less it
for a long wrap), |R theta| its length: OpenSim's ``_make_spiral_path`` with no axial distance, exact where both
points lie at one depth. Where the depths differ (a point off the circle's plane) OpenSim slides the tangent points
along the axis by an approximate construction; casflex takes the exact shortest path instead: its projection on the
plane is the planar wrap (tangent, arc, tangent), the depth grows linearly along it, so its length is
sqrt(L_plane^2 + (depth2 - depth1)^2) and the tangent points sit at the depths of that line (docs/muscles.md says
by how much OpenSim's differs).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca

from casflex.scene.muscles import QUADRANTS

__all__ = ["WrapSegment", "check_wraps", "circle_wrap", "quadrant_axis", "wrapped_pieces"]

def quadrant_axis(quadrant: str) -> tuple[int, int]:
    """(axis, sign) of OpenSim's quadrant name; ValueError for a name OpenSim refuses."""
    if quadrant not in QUADRANTS:
        raise ValueError(f"quadrant {quadrant!r} is none of OpenSim's (all, +x, -x, +y, -y, +z, -z)")
    return QUADRANTS[quadrant]


@dataclass(frozen=True)
class WrapSegment:
    """A segment's wrap (CasADi expressions, cylinder frame): ``code`` 0 no wrap, 1 wrapped, 2 mandatory (OpenSim's
    WrapAction); ``r1``, ``r2`` the tangent points (3,), ``arc`` the length on the cylinder between them (m),
    ``length`` the wrapped segment's whole length P1-r1-arc-r2-P2 (m)."""

    code: ca.SX
    r1: ca.SX
    r2: ca.SX
    arc: ca.SX
    length: ca.SX


def _dsign(x):
    return ca.if_else(x >= 0, 1, -1)


def _tangents(p, r: float) -> tuple[ca.SX, ca.SX]:
    """OpenSim's two candidate tangent points (x, y) from p on the circle of radius r (r1a, r1b)."""
    rho = ca.sqrt(p[0] ** 2 + p[1] ** 2)
    v = ca.vertcat(p[0], p[1]) / rho
    dist = r * r / rho
    h = ca.sqrt(r * r - dist * dist)
    u = ca.vertcat(-v[1], v[0])  # z x v
    return dist * v + h * u, dist * v - h * u


def _component(xy, depth, axis: int):
    return depth if axis == 2 else xy[axis]


def _constrained_choice(a, b, t1, t2, axis: int, sign: int):
    """OpenSim's choice of the tangent points on a constrained cylinder: 1 for (r1a, r2b), 0 for (r1b, r2a)."""
    (r1a, r1b), (r2a, r2b) = t1, t2
    on = [_dsign(_component(t, d, axis)) == sign for t, d in ((r1a, a[2]), (r1b, a[2]), (r2a, b[2]), (r2b, b[2]))]
    alpha_gt_beta = ca.dot(r1a, r2b) < ca.dot(r1b, r2a)  # acos decreasing; |r1a| = ... = r
    none_on = ca.if_else(on[2], 0, ca.if_else(on[3], 1, alpha_gt_beta))
    return ca.if_else(on[0], ca.if_else(on[1], 1 - on[2], 1), ca.if_else(on[1], 0, none_on))


def _free_choice(t1, t2):
    """OpenSim's choice on an unconstrained cylinder: the pair of tangent points nearest in angle."""
    (r1a, r1b), (r2a, r2b) = t1, t2
    d1, d2, d3, d4 = ca.dot(r1a, r2a), ca.dot(r1a, r2b), ca.dot(r1b, r2a), ca.dot(r1b, r2b)
    first = (d1 > d2) * (d1 > d3) * (d1 > d4)
    second = (d2 > d3) * (d2 > d4)
    r1 = ca.if_else(first + (1 - first) * second, r1a, r1b)
    r2 = ca.if_else(first, r2a, ca.if_else(second, r2b, ca.if_else(d3 > d4, r2a, r2b)))
    return r1, r2


def circle_wrap(a, b, radius: float, axis: int = 0, sign: int = 0) -> WrapSegment:
    """The wrap of the segment from ``a`` to ``b`` (3, cylinder frame; module docstring) over the cylinder of
    ``radius`` (m), its quadrant (``axis``, ``sign``: :func:`quadrant_axis`)."""
    r2_ = radius * radius
    inside = ((a[0] ** 2 + a[1] ** 2) < r2_) + ((b[0] ** 2 + b[1] ** 2) < r2_) > 0
    # the geometry below is evaluated at harmless stand-ins where a point is inside (its branch is not taken; a
    # NaN there would still reach the derivatives through the branch's zero weight)
    a = ca.if_else(inside, ca.DM([10 * radius, 0, a[2]]), a)
    b = ca.if_else(inside, ca.DM([0, 10 * radius, b[2]]), b)
    d = b - a
    t12 = -(a[0] * d[0] + a[1] * d[1]) / (d[0] ** 2 + d[1] ** 2)
    near = a + t12 * d
    hits = (near[0] ** 2 + near[1] ** 2 < r2_) * (t12 > 0) * (t12 < 1)
    t1, t2 = _tangents(a, radius), _tangents(b, radius)
    if sign == 0:
        code = ca.if_else(inside, 0, 2 * hits)
        r1, r2 = _free_choice(t1, t2)
        long = 0
    else:
        sa, sb = _dsign(a[axis]), _dsign(b[axis])
        either = (sa == sign) + (sb == sign) > 0
        opposite = (sa != sb) * (_dsign(near[axis]) != sign)
        code = ca.if_else(inside, 0, ca.if_else(either, ca.if_else(hits, 2, opposite), 1))
        pick = _constrained_choice(a, b, t1, t2, axis, sign)
        r1 = ca.if_else(pick, t1[0], t1[1])
        r2 = ca.if_else(pick, t2[1], t2[0])
        musc = (r1 - a[:2]) + (r2 - b[:2])
        long = ca.dot(r1 + r2, musc) < 0
    theta = ca.atan2(r1[0] * r2[1] - r1[1] * r2[0], ca.dot(r1, r2))
    theta = ca.if_else(long, 2 * math.pi - theta, theta)
    arc = radius * ca.fabs(theta)
    s1, s2 = ca.norm_2(a[:2] - r1), ca.norm_2(b[:2] - r2)
    plane = s1 + arc + s2
    dz = b[2] - a[2]
    z1, z2 = a[2] + dz * s1 / plane, a[2] + dz * (s1 + arc) / plane
    return WrapSegment(code, ca.vertcat(r1, z1), ca.vertcat(r2, z2), ca.sqrt(arc ** 2 + (z2 - z1) ** 2),
                       ca.sqrt(plane ** 2 + dz ** 2))


# -- a muscle's path with its wrap ------------------------------------------------------------------------------
def check_wraps(m, nodes: set[str]) -> None:
    """ValueError naming the muscle and the wrap for what :func:`wrapped_pieces` cannot compute: a wrap on no node
    of the scene, a radius not > 0, an axis not the plane's normal, a quadrant OpenSim refuses, a range outside the
    path, more than one wrap on a path."""
    if len(m.wraps) > 1:
        raise ValueError(f"muscle {m.name!r}: {len(m.wraps)} wraps on its path ({[w.name for w in m.wraps]}): OpenSim "
                         "iterates between several until the length settles; casflex computes one")
    for w in m.wraps:
        where = f"muscle {m.name!r} wrap {w.name!r}"
        if w.node not in nodes:
            raise ValueError(f"{where}: node {w.node!r} is no node of the scene")
        if not (math.isfinite(w.radius) and w.radius > 0):
            raise ValueError(f"{where}: radius {w.radius:g} m: must be > 0")
        if abs(abs(w.frame[8]) - 1) > 1e-9:
            raise ValueError(f"{where}: its axis {w.frame[2:9:3]} is not the plane's normal (0, 0, 1)")
        try:
            quadrant_axis(w.quadrant)
        except ValueError as e:
            raise ValueError(f"{where}: {e}") from None
        lo, hi = w.points
        if (lo >= 1 and lo > len(m.path)) or (hi >= 1 and (hi > len(m.path) or hi < lo)):
            raise ValueError(f"{where}: points {w.points} outside the path's {len(m.path)} points")


def _rotate(th, v):
    c, s = ca.cos(th), ca.sin(th)
    return ca.vertcat(c * v[0] - s * v[1], s * v[0] + c * v[1])


def _distance(a, b):
    """|b - a| (m), 0 (and its derivative 0, not NaN) where the points coincide."""
    d2 = ca.sumsqr(b - a)
    return ca.if_else(d2 > 0, ca.sqrt(d2), 0)


def _cylinder(paths, w):
    """The cylinder's (to the cylinder's frame, back to the ground, node index) at the tree's configuration."""
    R = [float(v) for v in w.frame[:9]]
    c0 = [float(v) for v in w.frame[9:12]]
    i = paths.tree.model.node_names.index(w.node)
    x0 = paths.tree.model.q0[3 * i: 3 * i + 3]
    turn = paths.q[3 * i + 2] - x0[2]
    centre = paths.q[3 * i: 3 * i + 2] + _rotate(turn, ca.DM([c0[0] - x0[0], c0[1] - x0[1]]))
    ex, ey = _rotate(turn, ca.DM([R[0], R[3]])), _rotate(turn, ca.DM([R[1], R[4]]))
    sz = 1.0 if R[8] > 0 else -1.0

    def to_cyl(p):
        d = p[:2] - centre
        return ca.vertcat(ca.dot(ex, d), ca.dot(ey, d), sz * (p[2] - c0[2]))

    def to_ground(r):
        return ca.vertcat(centre + r[0] * ex + r[1] * ey, c0[2] + sz * r[2])

    return to_cyl, to_ground, i


def _chosen(mand: list, wrapped: list, change: list) -> list:
    """OpenSim's choice among a range's segments (GeometryPath::applyWrapObjects): the first that must wrap, else
    the wrapped one that lengthens the path least (the first of equals); 1 for the chosen, 0 for the others."""
    before, first = 0, []
    for m in mand:
        first.append(m * (1 - before))
        before = before + m - before * m
    out = []
    for k, m in enumerate(first):
        best = wrapped[k]
        for j in range(len(wrapped)):
            if j != k:
                best = best * (1 - wrapped[j] * (change[j] <= change[k] if j < k else change[j] < change[k]))
        out.append(m + (1 - before) * best)
    return out


def wrapped_pieces(paths, m, pts: list, nodes: list[int], segs: list) -> list[tuple]:
    """The muscle's pieces (a, node of a, b, node of b, on, length; ``paths`` a :class:`casflex.muscles.path.
    MusclePaths`, ``pts`` its points at the tree's configuration, ``segs`` its segments (i, j, on)): each segment
    straight, except in its wrap's range, where the chosen segment (:func:`_chosen`) becomes the tangent line to
    r1, the arc on the cylinder and the tangent line from r2, r1 and r2 on the cylinder's node."""
    straight = [(pts[i], nodes[i], pts[j], nodes[j], on, _distance(pts[i], pts[j])) for i, j, on in segs]
    if not m.wraps:
        return straight
    w = m.wraps[0]
    lo = 0 if w.points[0] < 1 else w.points[0] - 1
    hi = len(pts) - 1 if w.points[1] < 1 else w.points[1] - 1
    to_cyl, to_ground, node = _cylinder(paths, w)
    axis, sign = quadrant_axis(w.quadrant)
    cands = [k for k, (i, j, _) in enumerate(segs) if lo <= i and j <= hi]
    wraps, mand, wrapped, change = [], [], [], []
    for k in cands:
        i, j, on = segs[k]
        a, b = to_cyl(pts[i]), to_cyl(pts[j])
        ws = circle_wrap(a, b, w.radius, axis, sign)
        code = ws.code
        if math.isfinite(w.length):  # both points beyond the cylinder's ends: no wrap (OpenSim's test)
            code = ca.if_else((ca.fabs(a[2]) > w.length / 2) * (ca.fabs(b[2]) > w.length / 2), 0, code)
        wraps.append(ws)
        mand.append(on * (code == 2))
        wrapped.append(on * (code == 1))
        change.append(ws.length - straight[k][5])
    out = [p for k, p in enumerate(straight) if k not in cands]
    for k, ws, c in zip(cands, wraps, _chosen(mand, wrapped, change), strict=True):
        i, j, on = segs[k]
        r1, r2 = to_ground(ws.r1), to_ground(ws.r2)
        out += [(pts[i], nodes[i], pts[j], nodes[j], on * (1 - c), straight[k][5]),
                (pts[i], nodes[i], r1, node, on * c, _distance(pts[i], r1)),
                (r1, node, r2, node, on * c, ws.arc),
                (r2, node, pts[j], nodes[j], on * c, _distance(r2, pts[j]))]
    return out
