"""Millard2012EquilibriumMuscle's four curves as OpenSim 4.6 makes them (SmoothSegmentedFunctionFactory).

Each curve is a :class:`~casflex.muscles.bezier.SegmentedCurve` built from the muscle's curve properties
(the .osim's tags under ``ActiveForceLengthCurve``, ``ForceVelocityCurve``, ``FiberForceLengthCurve``,
``TendonForceLengthCurve``; OpenSim's defaults where a tag is absent) after the adjustments the muscle makes
when it is finalized (Millard2012EquilibriumMuscle::extendFinalizeFromProperties):

- fibre damping below 0.001 is 0 (the undamped model);
- the damped model or a rigid tendon (``ignore_tendon_compliance``): the active force-length curve's
  ``minimum_value`` is 0 and the force-velocity curve's slopes at +-vmax are 0 where they were above;
- the undamped model with an elastic tendon: ``minimum_value`` at least 0.1 and the slopes at +-vmax at
  least half the slopes near vmax.

Parameters OpenSim's factory refuses are refused here: ValueError naming the muscle and the property.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from casflex.muscles.bezier import SegmentedCurve, corner
from casflex.scene.items import SceneError
from casflex.scene.muscles import Muscle

__all__ = ["MillardCurves", "millard_curves"]

_ROOT_EPS = math.sqrt(np.finfo(float).eps)
_MIN_DAMPING = 0.001  # OpenSim's MIN_NONZERO_DAMPING_COEFFICIENT
AFL, FV, FPE, FSE = "ActiveForceLengthCurve", "ForceVelocityCurve", "FiberForceLengthCurve", "TendonForceLengthCurve"


class _Refuse:
    """Raises the error naming the muscle and one of its properties."""

    def __init__(self, muscle: Muscle) -> None:
        self.owner = f"muscle {muscle.name!r}"

    def __call__(self, tag: str, reason: str) -> SceneError:
        return SceneError.at(self.owner, tag, reason)


def _number(muscle: Muscle, tag: str, default: float) -> float:
    value = muscle.property(tag, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _Refuse(muscle)(tag, f"must be a finite number, got {value!r}")
    return float(value)


def _scale(curviness: float) -> float:
    return 0.1 + 0.8 * curviness


def _curviness(refuse: _Refuse, tag: str, value: float) -> float:
    if not 0.0 <= value <= 1.0:
        raise refuse(tag, f"must be within [0, 1] (OpenSim's factory), got {value:g}")
    return _scale(value)


def _corners(refuse: _Refuse, tag: str, points: list[tuple[float, float, float]], curvinesses: list[float]):
    """The corners between consecutive (x, y, dydx) points, each with its (scaled) curviness."""
    xs, ys = [], []
    for (a, b, c) in zip(points[:-1], points[1:], curvinesses, strict=True):
        pts = corner(*a, *b, c)
        if pts is None:
            raise refuse(tag, "these parameters do not make the curve's C-shaped corners (OpenSim's factory "
                              "refuses them); use values nearer OpenSim's defaults")
        xs.append(pts[0])
        ys.append(pts[1])
    return tuple(xs), tuple(ys)


def active_force_length(refuse: _Refuse, x0: float, x1: float, x3: float, ylow: float, dydx: float
                        ) -> SegmentedCurve:
    """createFiberActiveForceLengthCurve(x0, x1, 1, x3, ylow, dydx, curviness 1)."""
    x2 = 1.0
    if not x0 >= 0:
        raise refuse(f"{AFL}.min_norm_active_fiber_length", f"must be >= 0, got {x0:g}")
    if not (x1 > x0 + _ROOT_EPS and x2 > x1 + _ROOT_EPS):
        raise refuse(f"{AFL}.transition_norm_fiber_length",
                     f"must lie between min_norm_active_fiber_length ({x0:g}) and 1, got {x1:g}")
    if not x3 > x2 + _ROOT_EPS:
        raise refuse(f"{AFL}.max_norm_active_fiber_length", f"must be > 1, got {x3:g}")
    if not ylow >= 0:
        raise refuse(f"{AFL}.minimum_value", f"must be >= 0, got {ylow:g}")
    upper = (1 - ylow) / (x2 - x1)
    if not 0 <= dydx < upper:
        raise refuse(f"{AFL}.shallow_ascending_slope", f"must be within [0, {upper:g}), got {dydx:g}")
    c = _scale(1.0)
    dx = 0.05 * x2
    xs = x2 - dx
    y0, y1 = 0.0, 1 - dydx * (xs - x1)
    dydx01 = 1.25 * (y1 - y0) / (x1 - x0)
    x01, y01 = x0 + 0.5 * (x1 - x0), y0 + 0.5 * (y1 - y0)
    x1s, y1s = x1 + 0.5 * (xs - x1), y1 + 0.5 * (1 - y1)
    y2, y3 = 1.0, 0.0
    x23, y23 = (x2 + dx) + 0.5 * (x3 - (x2 + dx)), y2 + 0.5 * (y3 - y2)
    dydx23 = (y3 - y2) / ((x3 - dx) - (x2 + dx))
    points = [(x0, ylow, 0.0), (x01, y01, dydx01), (x1s, y1s, dydx), (x2, y2, 0.0), (x23, y23, dydx23),
              (x3, ylow, 0.0)]
    cx, cy = _corners(refuse, AFL, points, [c] * 5)
    return SegmentedCurve("millard_active_force_length", cx, cy, x0, x3, ylow, ylow, 0.0, 0.0)


def force_velocity(refuse: _Refuse, p: dict[str, float]) -> SegmentedCurve:
    """createFiberForceVelocityCurve from the ForceVelocityCurve's properties ``p`` (tags without prefix)."""
    fmax, dc, dnc = p["max_eccentric_velocity_force_multiplier"], p["concentric_slope_at_vmax"], \
        p["concentric_slope_near_vmax"]
    diso, de, dne = p["isometric_slope"], p["eccentric_slope_at_vmax"], p["eccentric_slope_near_vmax"]
    checks = (("max_eccentric_velocity_force_multiplier", fmax > 1.0, "must be > 1"),
              ("concentric_slope_at_vmax", 0.0 <= dc < 1, "must be within [0, 1)"),
              ("concentric_slope_near_vmax", dc < dnc <= 1, "must be within (concentric_slope_at_vmax, 1]"),
              ("isometric_slope", diso > 1, "must be > 1"),
              ("eccentric_slope_at_vmax", 0.0 <= de < fmax - 1, f"must be within [0, {fmax - 1:g})"),
              ("eccentric_slope_near_vmax", de <= dne < fmax - 1,
               f"must be within [eccentric_slope_at_vmax, {fmax - 1:g})"))
    for tag, ok, what in checks:
        if not ok:
            raise refuse(f"{FV}.{tag}", f"{what} (OpenSim's factory), got {p[tag]:g}")
    cc = _curviness(refuse, f"{FV}.concentric_curviness", p["concentric_curviness"])
    ce = _curviness(refuse, f"{FV}.eccentric_curviness", p["eccentric_curviness"])
    xc, yc, xnc, xe, yne_x = -1.0, 0.0, -0.9, 1.0, 0.9
    ync = yc + 0.5 * dnc * (xnc - xc) + 0.5 * dc * (xnc - xc)
    yne = fmax + 0.5 * dne * (yne_x - xe) + 0.5 * de * (yne_x - xe)
    points = [(xc, yc, dc), (xnc, ync, dnc), (0.0, 1.0, diso), (yne_x, yne, dne), (xe, fmax, de)]
    cx, cy = _corners(refuse, FV, points, [cc, cc, ce, ce])
    return SegmentedCurve("millard_force_velocity", cx, cy, xc, xe, yc, fmax, dc, de)


def fiber_force_length(refuse: _Refuse, e0: float, e1: float, k_low: float, k_iso: float, curviness: float
                       ) -> SegmentedCurve:
    """createFiberForceLengthCurve(eZero, eIso, kLow, kIso, curviness)."""
    tag = f"{FPE}.strain_at_one_norm_force"
    if not e1 > e0:
        raise refuse(tag, f"must be > strain_at_zero_force ({e0:g}), got {e1:g}")
    if not k_iso > 1.0 / (e1 - e0):
        raise refuse(f"{FPE}.stiffness_at_one_norm_force", f"must be > {1.0 / (e1 - e0):g} (1 / the strain "
                                                             f"from zero to one norm force), got {k_iso:g}")
    if not 0.0 < k_low < 1 / (e1 - e0):
        raise refuse(f"{FPE}.stiffness_at_low_force", f"must be within (0, {1 / (e1 - e0):g}), got {k_low:g}")
    c = _curviness(refuse, f"{FPE}.curviness", curviness)
    x_zero, x_iso = 1 + e0, 1 + e1
    dx = min(0.1 * (1.0 / k_iso), 0.1 * (x_iso - x_zero))
    x_low = x_zero + dx
    x_foot = x_zero + 0.5 * (x_low - x_zero)
    y_low = k_low * (x_low - x_foot)
    cx, cy = _corners(refuse, FPE, [(x_zero, 0.0, 0.0), (x_low, y_low, k_low), (x_iso, 1.0, k_iso)], [c, c])
    return SegmentedCurve("millard_fiber_force_length", cx, cy, x_zero, x_iso, 0.0, 1.0, 0.0, k_iso)


def tendon_force_length(refuse: _Refuse, e_iso: float, k_iso: float, f_toe: float, curviness: float
                        ) -> SegmentedCurve:
    """createTendonForceLengthCurve(eIso, kIso, fToe, curviness)."""
    if not e_iso > 0:
        raise refuse(f"{FSE}.strain_at_one_norm_force", f"must be > 0, got {e_iso:g}")
    if not 0 < f_toe < 1:
        raise refuse(f"{FSE}.norm_force_at_toe_end", f"must be within (0, 1), got {f_toe:g}")
    if not k_iso > 1 / e_iso:
        raise refuse(f"{FSE}.stiffness_at_one_norm_force", f"must be > {1 / e_iso:g} (1 / strain_at_one_norm_"
                                                             f"force), got {k_iso:g}")
    c = _curviness(refuse, f"{FSE}.curviness", curviness)
    x_iso = 1.0 + e_iso
    x_toe = (f_toe - 1) / k_iso + x_iso
    x_foot = 1.0 + (x_toe - 1.0) / 10.0
    y_toe_mid = f_toe * 0.5
    x_toe_mid = (y_toe_mid - 1.0) / k_iso + x_iso
    dydx_toe_mid = (y_toe_mid - 0.0) / (x_toe_mid - x_foot)
    x_ctrl = x_foot + 0.5 * (x_toe_mid - x_foot)
    y_ctrl = dydx_toe_mid * (x_ctrl - x_foot)
    points = [(1.0, 0.0, 0.0), (x_ctrl, y_ctrl, dydx_toe_mid), (x_toe, f_toe, k_iso)]
    cx, cy = _corners(refuse, FSE, points, [c, c])
    return SegmentedCurve("millard_tendon_force_length", cx, cy, 1.0, x_toe, 0.0, f_toe, 0.0, k_iso)


@dataclass(frozen=True)
class MillardCurves:
    """A Millard2012EquilibriumMuscle's curves as OpenSim finalizes them: call each on normalised fibre length
    (``active_force_length``, ``passive_force_length``), normalised fibre velocity (``force_velocity``,
    optimal fibre lengths / s over max_contraction_velocity, lengthening positive) or normalised tendon length
    (``tendon_force_length``). ``fiber_damping``: the damping in use (0 below 0.001); ``min_active_norm_length``:
    the active curve's lower end (OpenSim's minimum fibre length is this times the optimal fibre length, or the
    pennation model's where longer)."""

    active_force_length: SegmentedCurve
    passive_force_length: SegmentedCurve
    force_velocity: SegmentedCurve
    tendon_force_length: SegmentedCurve
    fiber_damping: float
    min_active_norm_length: float


def _optional_trio(muscle: Muscle, refuse: _Refuse, curve: str, tags: tuple[str, str, str],
                   fitted: tuple[float, float, float]) -> tuple[float, float, float]:
    """OpenSim's optional properties: all three given, or none (the fitted values)."""
    given = [f"{curve}.{t}" for t in tags if any(k == f"{curve}.{t}" for k, _ in muscle.properties)]
    if not given:
        return fitted
    if len(given) < 3:
        missing = [f"{curve}.{t}" for t in tags if f"{curve}.{t}" not in given]
        raise refuse(missing[0], f"OpenSim takes {', '.join(tags)} all together or none; the model gives "
                                 f"{', '.join(given)} only: add the others or remove these")
    return tuple(_number(muscle, f"{curve}.{t}", 0.0) for t in tags)  # type: ignore[return-value]


def millard_curves(muscle: Muscle) -> MillardCurves:
    """The four curves of the Millard2012EquilibriumMuscle ``muscle`` (see the module's docstring)."""
    refuse = _Refuse(muscle)
    damping = _number(muscle, "fiber_damping", 0.1)
    if damping < 0:
        raise refuse("fiber_damping", f"must be >= 0, got {damping:g}")
    damping = 0.0 if damping < _MIN_DAMPING else damping
    rigid = _flag(muscle, "ignore_tendon_compliance")
    afl = {t: _number(muscle, f"{AFL}.{t}", d) for t, d in (
        ("min_norm_active_fiber_length", 0.47 - 0.0259), ("transition_norm_fiber_length", 0.73),
        ("max_norm_active_fiber_length", 1.8123), ("shallow_ascending_slope", 0.8616), ("minimum_value", 0.1))}
    fv = {t: _number(muscle, f"{FV}.{t}", d) for t, d in (
        ("concentric_slope_at_vmax", 0.0), ("concentric_slope_near_vmax", 0.25), ("isometric_slope", 5.0),
        ("eccentric_slope_at_vmax", 0.0), ("eccentric_slope_near_vmax", 0.15),
        ("max_eccentric_velocity_force_multiplier", 1.4), ("concentric_curviness", 0.6),
        ("eccentric_curviness", 0.9))}
    for side in ("concentric", "eccentric"):
        if fv[f"{side}_slope_near_vmax"] < math.sqrt(np.finfo(float).eps):
            raise refuse(f"{FV}.{side}_slope_near_vmax", f"must be >= 1.49e-8, got {fv[f'{side}_slope_near_vmax']:g}")
    if rigid or damping > 0:
        afl["minimum_value"] = min(afl["minimum_value"], 0.0)
        for side in ("concentric", "eccentric"):
            fv[f"{side}_slope_at_vmax"] = min(fv[f"{side}_slope_at_vmax"], 0.0)
    else:
        afl["minimum_value"] = max(afl["minimum_value"], 0.1)
        for side in ("concentric", "eccentric"):
            fv[f"{side}_slope_at_vmax"] = max(fv[f"{side}_slope_at_vmax"], 0.5 * fv[f"{side}_slope_near_vmax"])
    e0 = _number(muscle, f"{FPE}.strain_at_zero_force", 0.0)
    e1 = _number(muscle, f"{FPE}.strain_at_one_norm_force", 0.7)
    if not e1 > e0:  # before the default stiffness 2 / (e1 - e0) divides by it
        raise refuse(f"{FPE}.strain_at_one_norm_force", f"must be > strain_at_zero_force ({e0:g}), got {e1:g}")
    k_low, k_iso, c_pe = _optional_trio(muscle, refuse, FPE, ("stiffness_at_low_force", "stiffness_at_one_norm_force",
                                                              "curviness"), (0.2, 2.0 / (e1 - e0), 0.75))
    et = _number(muscle, f"{FSE}.strain_at_one_norm_force", 0.049)
    if not et > 0:
        raise refuse(f"{FSE}.strain_at_one_norm_force", f"must be > 0, got {et:g}")
    kt, ftoe, c_se = _optional_trio(muscle, refuse, FSE, ("stiffness_at_one_norm_force", "norm_force_at_toe_end",
                                                          "curviness"), (1.375 / et, 2.0 / 3.0, 0.5))
    return MillardCurves(
        active_force_length(refuse, afl["min_norm_active_fiber_length"], afl["transition_norm_fiber_length"],
                            afl["max_norm_active_fiber_length"], afl["minimum_value"], afl["shallow_ascending_slope"]),
        fiber_force_length(refuse, e0, e1, k_low, k_iso, c_pe), force_velocity(refuse, fv),
        tendon_force_length(refuse, et, kt, ftoe, c_se), damping, afl["min_norm_active_fiber_length"])


def _flag(muscle: Muscle, tag: str) -> bool:
    """A boolean property (the .osim's true / false as 1 / 0; absent: OpenSim's default false)."""
    value = muscle.property(tag, 0.0)
    if value not in (0, 1):
        raise _Refuse(muscle)(tag, f"must be 0 or 1 (false or true), got {value!r}")
    return bool(value)
