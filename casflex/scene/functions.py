"""The functions of one coordinate that OpenSim models use in their joints (a knee's translation as a
spline of the knee angle): constant, linear, polynomial, SIMM's cubic spline and a multiplier of one of
these. Numbers only; :meth:`Function.__call__` takes floats or numpy arrays. The symbolic model's coupled
joints evaluate a spline's knots and coefficients as CasADi expressions in :mod:`casflex.elements.joints`.

``SimmSpline`` is the cubic spline of Forsythe, Malcolm and Moler (Computer Methods for Mathematical
Computations, 1977, ``spline``/``seval``) that OpenSim's ``SimmSpline`` computes: end conditions that
match the third derivative of the cubics through the first and last four knots, linear continuation
beyond the knots with the end slopes.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

__all__ = ["Function", "Constant", "Linear", "Polynomial", "SimmSpline", "Multiplier", "Clamped"]


class Function:
    """f(x) of one coordinate (x a float or an array)."""

    def __call__(self, x):
        raise NotImplementedError

    def is_constant(self) -> bool:
        return False


@dataclass(frozen=True)
class Constant(Function):
    value: float

    def __call__(self, x):
        return 0.0 * x + self.value

    def is_constant(self) -> bool:
        return True


@dataclass(frozen=True)
class Linear(Function):
    """slope * x + intercept (OpenSim's LinearFunction, coefficients ``slope intercept``)."""

    slope: float
    intercept: float = 0.0

    def __call__(self, x):
        return self.slope * x + self.intercept

    def is_constant(self) -> bool:
        return self.slope == 0.0


@dataclass(frozen=True)
class Polynomial(Function):
    """sum c_i x^(n-1-i) (OpenSim's PolynomialFunction: the highest power first)."""

    coefficients: tuple[float, ...]

    def __call__(self, x):
        out = 0.0 * x
        for c in self.coefficients:
            out = out * x + c
        return out

    def is_constant(self) -> bool:
        return all(c == 0.0 for c in self.coefficients[:-1])


@dataclass(frozen=True)
class Multiplier(Function):
    """scale * inner(x) (OpenSim's MultiplierFunction)."""

    inner: Function
    scale: float

    def __call__(self, x):
        return self.scale * self.inner(x)

    def is_constant(self) -> bool:
        return self.scale == 0.0 or self.inner.is_constant()


@dataclass(frozen=True)
class Clamped(Function):
    """inner(x clamped to [lower, upper]): a MovingPathPoint's location, which OpenSim evaluates at its
    coordinate's value clamped to the coordinate's range."""

    inner: Function
    lower: float
    upper: float

    def __call__(self, x):
        return self.inner(np.clip(x, self.lower, self.upper))

    def is_constant(self) -> bool:
        return self.inner.is_constant()


@dataclass(frozen=True)
class SimmSpline(Function):
    """The cubic spline through the knots (x, y), x increasing (module docstring)."""

    x: tuple[float, ...]
    y: tuple[float, ...]

    def __post_init__(self) -> None:
        x = np.asarray(self.x, dtype=float)
        if x.size < 2 or x.size != len(self.y) or not (np.diff(x) > 0).all():
            raise ValueError(f"SimmSpline: needs two or more knots with x increasing, got x = {list(self.x)}")

    @functools.cached_property
    def _coefficients(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self._solve()

    def coefficients(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(b, c, d) (n,) each: computed once per spline (copies)."""
        return tuple(v.copy() for v in self._coefficients)

    def _solve(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(b, c, d) (n,) each: y_k + b_k s + c_k s^2 + d_k s^3, s = x - x_k, on [x_k, x_k+1]."""
        x, y = np.asarray(self.x, dtype=float), np.asarray(self.y, dtype=float)
        n = x.size
        b, c, d = np.zeros(n), np.zeros(n), np.zeros(n)
        if n < 3:
            b[:] = (y[1] - y[0]) / (x[1] - x[0])
            return b, c, d
        nm1 = n - 1
        d[0] = x[1] - x[0]
        c[1] = (y[1] - y[0]) / d[0]
        for i in range(1, nm1):
            d[i] = x[i + 1] - x[i]
            b[i] = 2.0 * (d[i - 1] + d[i])
            c[i + 1] = (y[i + 1] - y[i]) / d[i]
            c[i] = c[i + 1] - c[i]
        b[0], b[nm1] = -d[0], -d[n - 2]
        c[0] = c[nm1] = 0.0
        if n > 3:
            c[0] = c[2] / (x[3] - x[1]) - c[1] / (x[2] - x[0])
            c[nm1] = c[n - 2] / (x[nm1] - x[n - 3]) - c[n - 3] / (x[n - 2] - x[n - 4])
            c[0] = c[0] * d[0] * d[0] / (x[3] - x[0])
            c[nm1] = -c[nm1] * d[n - 2] * d[n - 2] / (x[nm1] - x[n - 4])
        for i in range(1, n):  # forward elimination
            t = d[i - 1] / b[i - 1]
            b[i] -= t * d[i - 1]
            c[i] -= t * c[i - 1]
        c[nm1] /= b[nm1]  # back substitution
        for i in range(n - 2, -1, -1):
            c[i] = (c[i] - d[i] * c[i + 1]) / b[i]
        b[nm1] = (y[nm1] - y[n - 2]) / d[n - 2] + d[n - 2] * (c[n - 2] + 2.0 * c[nm1])
        for i in range(nm1):
            b[i] = (y[i + 1] - y[i]) / d[i] - d[i] * (c[i + 1] + 2.0 * c[i])
            d[i] = (c[i + 1] - c[i]) / d[i]
            c[i] = 3.0 * c[i]
        c[nm1] = 3.0 * c[nm1]
        d[nm1] = d[n - 2]
        return b, c, d

    def __call__(self, x):
        b, c, d = self._coefficients
        xk, yk = np.asarray(self.x, dtype=float), np.asarray(self.y, dtype=float)
        xa = np.asarray(x, dtype=float)
        k = np.clip(np.searchsorted(xk, xa, side="right") - 1, 0, xk.size - 2)
        s = xa - xk[k]
        inside = yk[k] + s * (b[k] + s * (c[k] + s * d[k]))
        below = yk[0] + (xa - xk[0]) * b[0]
        above = yk[-1] + (xa - xk[-1]) * b[-1]
        out = np.where(xa < xk[0], below, np.where(xa > xk[-1], above, inside))
        return float(out) if np.ndim(out) == 0 else out

    def is_constant(self) -> bool:
        return bool(np.ptp(np.asarray(self.y, dtype=float)) == 0.0)
