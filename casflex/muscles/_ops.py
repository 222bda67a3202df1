"""The few elementwise operations the muscle curves need, for numpy arrays and for CasADi matrices alike."""

from __future__ import annotations

import casadi as ca
import numpy as np


class _Numpy:
    exp, log, sqrt, sin, cos, asin = np.exp, np.log, np.sqrt, np.sin, np.cos, np.arcsin
    where = staticmethod(np.where)


class _Casadi:
    exp, log, sqrt, sin, cos, asin = ca.exp, ca.log, ca.sqrt, ca.sin, ca.cos, ca.asin

    @staticmethod
    def where(c, a, b):
        """Elementwise c ? a : b, scalars a, b broadcast to c's shape."""
        one = ca.DM.ones(c.shape)
        return ca.if_else(c, one * a, one * b)


def symbolic(*xs) -> bool:
    """Whether any of xs is a CasADi matrix (SX, MX or DM): the curves then build CasADi expressions."""
    return any(isinstance(x, (ca.SX, ca.MX, ca.DM)) for x in xs)


def ops(*xs):
    """The namespace of operations for xs: numpy's, or CasADi's where any of xs is a CasADi matrix."""
    return _Casadi if symbolic(*xs) else _Numpy
