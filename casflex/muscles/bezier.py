"""OpenSim's SmoothSegmentedFunction: a curve y(x) made of quintic Bezier segments, linear outside its domain.

Each segment is a pair of quintic Bezier polynomials x(u), y(u), u in [0, 1] (OpenSim's
SegmentedQuinticBezierToolkit). Evaluating y at x needs u such that x(u) = x: OpenSim starts from a
cubic spline of u(x) fitted to 100 samples and runs Newton until |x(u) - x| <= 100 eps (2.2e-14). Here
the start is, for CasADi, u bracketed by 16 bisection steps (|u - u*| < 1.6e-5; x(u) is monotone on each
segment of the curves OpenSim's factory makes, so the bracket holds), for numpy u interpolated linearly in
x(u) sampled at 101 values of u (error ~1e-4); then 4 Newton steps (quadratic: to
round-off). A fixed number of steps keeps the evaluation one expression, and AD through the Newton steps
gives dy/dx = y'(u) / x'(u) (and its second derivative) exactly once the steps have converged. Outside
[x0, x1] the curve is OpenSim's line y0 + dydx0 (x - x0) (and at x1).
"""

from __future__ import annotations

import functools
import hashlib
from dataclasses import dataclass

import casadi as ca
import numpy as np

from casflex.muscles._ops import ops

__all__ = ["SegmentedCurve", "corner"]

_BISECTIONS, _NEWTON_STEPS = 16, 4


def corner(x0: float, y0: float, dydx0: float, x1: float, y1: float, dydx1: float, curviness: float
           ) -> tuple[tuple[float, ...], tuple[float, ...]] | None:
    """OpenSim's calcQuinticBezierCornerControlPoints: the control points (x, y) of the quintic Bezier corner
    from (x0, y0) with slope dydx0 to (x1, y1) with slope dydx1; None where the two tangents do not make the
    C-shaped corner OpenSim requires (its factory refuses such parameters)."""
    root_eps = float(np.sqrt(np.finfo(float).eps))
    xc = (y1 - y0 - x1 * dydx1 + x0 * dydx0) / (dydx0 - dydx1) if abs(dydx0 - dydx1) > root_eps else (x1 + x0) / 2
    yc = (xc - x1) * dydx1 + y1
    a = (xc - x0) ** 2 + (yc - y0) ** 2
    b = (xc - x1) ** 2 + (yc - y1) ** 2
    c = (x1 - x0) ** 2 + (y1 - y0) ** 2
    if not (c > a and c > b):
        return None
    x0m, y0m = x0 + curviness * (xc - x0), y0 + curviness * (yc - y0)
    x1m, y1m = x1 + curviness * (xc - x1), y1 + curviness * (yc - y1)
    return (x0, x0m, x0m, x1m, x1m, x1), (y0, y0m, y0m, y1m, y1m, y1)


def _value(u, p):
    """OpenSim's calcQuinticBezierCurveVal (its polynomial form, term for term)."""
    u4 = u
    u3 = u4 * u
    u2 = u3 * u
    u1 = u2 * u
    u0 = u1 * u
    t2, t3, t4, t5 = u1 * 5.0, u2 * 10.0, u3 * 10.0, u4 * 5.0
    t9, t10, t11, t15 = u0 * 5.0, u1 * 20.0, u2 * 30.0, u0 * 10.0
    return (p[0] * (u0 * -1.0 + t2 - t3 + t4 - t5 + 1.0) + p[1] * (t9 - t10 + t11 + u3 * -20.0 + t5)
            + p[2] * (-t15 + u1 * 30.0 - t11 + t4) + p[3] * (t15 - t10 + t3) + p[4] * (-t9 + t2) + p[5] * u0)


def _slope(u, p):
    """OpenSim's calcQuinticBezierCurveDerivU, order 1: dx/du."""
    t1 = u * u
    t2 = t1 * t1
    t4 = t1 * u
    t5, t6, t7 = t4 * 20.0, t1 * 30.0, u * 20.0
    t10, t11, t12, t16 = t2 * 25.0, t4 * 80.0, t1 * 90.0, t2 * 50.0
    return (p[0] * (t2 * -5.0 + t5 - t6 + t7 - 5.0) + p[1] * (t10 - t11 + t12 + u * -40.0 + 5.0)
            + p[2] * (-t16 + t4 * 120.0 - t12 + t7) + p[3] * (t16 - t11 + t6) + p[4] * (-t10 + t5) + p[5] * t2 * 5.0)


def _solve_u(x, px, o):
    """u in [0, 1] with x(u) = x on the segment of control points px (x within the segment)."""
    lo, hi = 0.0 * x, 0.0 * x + 1.0
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        below = _value(mid, px) < x
        lo, hi = o.where(below, mid, lo), o.where(below, hi, mid)
    u = 0.5 * (lo + hi)
    for _ in range(_NEWTON_STEPS):
        u = u - (_value(u, px) - x) / _slope(u, px)
    return u


@dataclass(frozen=True)
class SegmentedCurve:
    """A SmoothSegmentedFunction: ``ctrl_x``, ``ctrl_y`` the segments' control points (n x 6), the domain
    [x0, x1] with y0, y1 and the slopes dydx0, dydx1 of the lines beyond it; ``name`` a C identifier (the
    CasADi Function's). Call it on a number, a numpy array (any shape) or a CasADi SX / MX / DM."""

    name: str
    ctrl_x: tuple[tuple[float, ...], ...]
    ctrl_y: tuple[tuple[float, ...], ...]
    x0: float
    x1: float
    y0: float
    y1: float
    dydx0: float
    dydx1: float

    def __call__(self, x):
        if isinstance(x, (ca.SX, ca.MX, ca.DM)):
            return _map(self.function, x)
        x = np.asarray(x, dtype=float)
        return self._numpy(x)[()] if x.ndim == 0 else self._numpy(x)

    def _numpy(self, x: np.ndarray) -> np.ndarray:
        cx, cy = np.asarray(self.ctrl_x), np.asarray(self.ctrl_y)
        xc = np.clip(x, self.x0, self.x1)
        # OpenSim's calcIndex: the segment with x in [start, end), the last one at x1 itself
        idx = np.clip(np.searchsorted(cx[:, 0], xc, side="right") - 1, 0, len(cx) - 1)
        px, py = [cx[idx, k] for k in range(6)], [cy[idx, k] for k in range(6)]
        u = np.empty_like(xc)
        for s, (tx, tu) in enumerate(self._tables):  # the start: u interpolated in x(u) sampled (error ~1e-4)
            here = idx == s
            u[here] = np.interp(xc[here], tx, tu)
        for _ in range(_NEWTON_STEPS):  # then as for CasADi: 1e-4 -> 1e-8 -> 1e-16
            u = u - (_value(u, px) - xc) / _slope(u, px)
        y = _value(u, py)
        return np.where(x < self.x0, self.y0 + self.dydx0 * (x - self.x0),
                        np.where(x > self.x1, self.y1 + self.dydx1 * (x - self.x1), y))

    @functools.cached_property
    def _tables(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Each segment's x(u) at 101 values of u (numpy's starting guesses)."""
        u = np.linspace(0.0, 1.0, 101)
        return [(_value(u, list(seg)), u) for seg in self.ctrl_x]

    @property
    def function(self) -> ca.Function:
        """The curve as a scalar CasADi Function ``<name>_<digest>(x) -> y`` (SX inside; mapped over vectors):
        one Function per distinct curve, its name unique to its control points (names become C symbols)."""
        return _function(self)


@functools.lru_cache(maxsize=256)
def _function(curve: SegmentedCurve) -> ca.Function:
    x = ca.SX.sym("x")
    xc = ca.if_else(x < curve.x0, curve.x0, ca.if_else(x > curve.x1, curve.x1, x))
    px, py = list(curve.ctrl_x[0]), list(curve.ctrl_y[0])
    for seg_x, seg_y in zip(curve.ctrl_x[1:], curve.ctrl_y[1:], strict=True):
        start = xc >= seg_x[0]
        px = [ca.if_else(start, a, b) for a, b in zip(seg_x, px, strict=True)]
        py = [ca.if_else(start, a, b) for a, b in zip(seg_y, py, strict=True)]
    y = _value(_solve_u(xc, px, ops(xc)), py)
    y = ca.if_else(x < curve.x0, curve.y0 + curve.dydx0 * (x - curve.x0),
                   ca.if_else(x > curve.x1, curve.y1 + curve.dydx1 * (x - curve.x1), y))
    digest = hashlib.sha1(repr((curve.ctrl_x, curve.ctrl_y, curve.x0, curve.x1, curve.y0, curve.y1, curve.dydx0,
                                curve.dydx1)).encode()).hexdigest()[:10]
    return ca.Function(f"{curve.name}_{digest}", [x], [y], ["x"], ["y"])


def _map(f: ca.Function, x):
    """The scalar Function f applied to each element of the CasADi matrix x (same shape)."""
    if x.is_scalar():
        return f(x)
    n1, n2 = x.shape
    return ca.reshape(f.map(n1 * n2)(ca.reshape(x, 1, n1 * n2)), n1, n2)
