"""OpenSim 4.6's muscle curves and its rigid-tendon muscle, for numpy arrays and CasADi symbols alike.

For each of OpenSim's three muscle models (:data:`casflex.scene.muscles.MUSCLE_KINDS`):

- :func:`muscle_curves` (muscle) -> its normalised curves: ``active_force_length`` and
  ``passive_force_length`` of the normalised fibre length l / l_opt, ``force_velocity`` of the normalised
  fibre velocity v / (l_opt v_max) (lengthening positive; -1: maximum shortening velocity),
  ``tendon_force_length`` of the normalised tendon length l_t / l_ts; each force normalised by the maximum
  isometric force. Millard2012EquilibriumMuscle's are quintic Bezier curves (:mod:`casflex.muscles.millard`),
  Thelen2003Muscle's and DeGrooteFregly2016Muscle's closed forms, all as OpenSim's source computes them;
- :class:`Pennation` -> the fixed-width pennation model (MuscleFixedWidthPennationModel, or DeGroote's);
- :func:`rigid_tendon` (muscle, lmt, vmt) -> the muscle with its tendon at its slack length: fibre length,
  pennation, normalised velocity and the forces along the tendon that static optimization uses.

Each function takes a number, a numpy array (any shape; the result has its shape) or a CasADi SX / MX / DM
(the result is a CasADi expression, differentiable: Thelen's passive curve and the pennation model's clamps
are OpenSim's kinks and switches, kept as they are).

A muscle's properties are its .osim's (``Muscle.properties``: (tag, value) pairs; booleans 1 / 0), OpenSim's
defaults where a tag is absent. Values OpenSim refuses, and NaN, infinite or negative ones where a positive
is needed, raise ValueError naming the muscle and the property.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import casadi as ca
import numpy as np

from casflex.muscles._ops import ops, symbolic
from casflex.muscles.millard import MillardCurves, _flag, _number, _Refuse, millard_curves
from casflex.scene.muscles import MUSCLE_KINDS, Muscle

__all__ = ["PROPERTY_TAGS", "DeGrooteCurves", "MillardCurves", "Pennation", "RigidTendon", "ThelenCurves",
           "muscle_curves", "pennation", "rigid_tendon"]

#: The .osim tags (``Muscle.properties``) each kind's curves, pennation and rigid-tendon muscle read, beyond
#: the five common properties; booleans (``ignore_*``) as 1 / 0. Absent tags take OpenSim 4.6's defaults.
PROPERTY_TAGS: dict[str, tuple[str, ...]] = {
    "Millard2012EquilibriumMuscle": (
        "fiber_damping", "maximum_pennation_angle", "ignore_tendon_compliance",
        *(f"ActiveForceLengthCurve.{t}" for t in ("min_norm_active_fiber_length", "transition_norm_fiber_length",
                                                  "max_norm_active_fiber_length", "shallow_ascending_slope",
                                                  "minimum_value")),
        *(f"ForceVelocityCurve.{t}" for t in ("concentric_slope_at_vmax", "concentric_slope_near_vmax",
                                              "isometric_slope", "eccentric_slope_at_vmax", "eccentric_slope_near_vmax",
                                              "max_eccentric_velocity_force_multiplier", "concentric_curviness",
                                              "eccentric_curviness")),
        *(f"FiberForceLengthCurve.{t}" for t in ("strain_at_zero_force", "strain_at_one_norm_force",
                                                 "stiffness_at_low_force", "stiffness_at_one_norm_force", "curviness")),
        *(f"TendonForceLengthCurve.{t}" for t in ("strain_at_one_norm_force", "stiffness_at_one_norm_force",
                                                  "norm_force_at_toe_end", "curviness"))),
    "Thelen2003Muscle": ("FmaxTendonStrain", "FmaxMuscleStrain", "KshapeActive", "KshapePassive", "Af", "Flen",
                         "fv_linear_extrap_threshold", "maximum_pennation_angle"),
    "DeGrooteFregly2016Muscle": ("active_force_width_scale", "fiber_damping", "passive_fiber_strain_at_one_norm_force",
                                 "tendon_strain_at_one_norm_force", "ignore_passive_fiber_force"),
}

_EPS = float(np.finfo(float).eps)
_SIGNIFICANT = _EPS ** 0.875  # SimTK::SignificantReal


def _arg(x):
    return x if symbolic(x) else np.asarray(x, dtype=float)


@dataclass(frozen=True)
class ThelenCurves:
    """Thelen2003Muscle's curves (Thelen 2003 as OpenSim 4.6 codes them; the .osim's tags in brackets):
    strain of the tendon at one normalised force [FmaxTendonStrain], of the fibre's passive element
    [FmaxMuscleStrain], the active Gaussian's width [KshapeActive], the passive exponential's shape
    [KshapePassive], the force-velocity shape [Af], the maximum eccentric multiplier [Flen] and the
    fraction of it beyond which the curve is extended linearly [fv_linear_extrap_threshold]."""

    tendon_strain: float = 0.04
    muscle_strain: float = 0.6
    k_active: float = 0.45
    k_passive: float = 5.0
    af: float = 0.25
    flen: float = 1.4
    fv_threshold: float = 0.95

    def active_force_length(self, lce_n):
        """exp(-(l - 1)^2 / KshapeActive)."""
        lce_n = _arg(lce_n)
        return ops(lce_n).exp(-((lce_n - 1.0) * (lce_n - 1.0)) / self.k_active)

    def passive_force_length(self, lce_n):
        """(exp(KshapePassive (l - 1) / FmaxMuscleStrain) - 1) / (exp(KshapePassive) - 1) above l = 1, else 0."""
        lce_n = _arg(lce_n)
        o = ops(lce_n)
        with np.errstate(over="ignore"):
            return o.where(lce_n > 1.0, (o.exp(self.k_passive * (lce_n - 1.0) / self.muscle_strain) - 1.0)
                           / (math.exp(self.k_passive) - 1.0), 0.0)

    def force_velocity(self, v_n, activation: float = 1.0):
        """The force-velocity multiplier at ``activation`` (Thelen's depends on it): OpenSim's calcfvInv inverts
        the velocity of Thelen's eqs 6-7 (and their linear extensions) by Newton to 1e-6; this is that
        inverse in closed form, 0 at and below v_n = -(0.25 + 0.75 a)."""
        v_n = _arg(v_n)
        o = ops(v_n)
        c = 0.25 + 0.75 * activation
        k = (2.0 + 2.0 / self.af) / (self.flen - 1.0)
        f_th = self.flen * self.fv_threshold
        v_th = c * (f_th - 1.0) / (k * (self.flen - f_th))
        s_th = c * (self.flen - 1.0) / (k * (self.flen - f_th) ** 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            concentric = (c + v_n) / (c - v_n / self.af)
            eccentric = (c + k * self.flen * v_n) / (c + k * v_n)
        linear = f_th + (v_n - v_th) / s_th
        return o.where(v_n <= -c, 0.0, o.where(v_n <= 0.0, concentric, o.where(v_n < v_th, eccentric, linear)))

    def tendon_force_length(self, lt_n):
        """Thelen's tendon: exponential toe to normalised force 0.33, linear beyond (OpenSim's calcfse)."""
        lt_n = _arg(lt_n)
        o = ops(lt_n)
        x, e0, k_toe, f_toe = lt_n - 1.0, self.tendon_strain, 3.0, 33.0 / 100.0
        t1 = math.exp(3.0)
        e_toe = (99.0 * e0 * t1) / (166.0 * t1 - 67.0)
        k_lin = (67.0 / 100.0) * 1.0 / (e0 - (99.0 * e0 * t1) / (166.0 * t1 - 67.0))
        with np.errstate(over="ignore"):
            toe = (f_toe / (math.exp(k_toe) - 1.0)) * (o.exp(k_toe * x / e_toe) - 1.0)
        return o.where(x > e_toe, k_lin * (x - e_toe) + f_toe, o.where(x > 0.0, toe, 0.0))


#: DeGrooteFregly2016Muscle's constants (De Groote et al. 2016, as OpenSim 4.6 sets them)
_B = ((0.8150671134243542, 1.055033428970575, 0.162384573599574, 0.063303448465465),
      (0.433004984392647, 0.716775413397760, -0.029947116970696, 0.200356847296188),
      (0.1, 1.0, 0.353553390593274, 0.0))
_KPE, _C1, _C2, _C3 = 4.0, 0.200, 1.0, 0.200
_D1, _D2, _D3, _D4 = -0.3211346127989808, -8.149, -0.374, 0.8825327733249912
_DG_MIN_NORM_FIBER_LENGTH = 0.2


@dataclass(frozen=True)
class DeGrooteCurves:
    """DeGrooteFregly2016Muscle's curves: the active curve's width scale [active_force_width_scale], the
    fibre's passive strain at one normalised force [passive_fiber_strain_at_one_norm_force], the tendon's
    [tendon_strain_at_one_norm_force], the passive curve off [ignore_passive_fiber_force] and the fibre's
    damping [fiber_damping] (normalised force per normalised velocity, in its passive force)."""

    width_scale: float = 1.0
    passive_strain: float = 0.6
    tendon_strain: float = 0.049
    ignore_passive: bool = False
    fiber_damping: float = 0.0

    def active_force_length(self, lce_n):
        """The sum of three Gaussian-like curves, b1 exp(-(x - b2)^2 / (2 (b3 + b4 x)^2)), x scaled about 1."""
        lce_n = _arg(lce_n)
        o = ops(lce_n)
        x = (lce_n - 1.0) / self.width_scale + 1.0
        total = 0.0
        for b1, b2, b3, b4 in _B:
            d = b3 + b4 * x
            total = total + b1 * o.exp(-0.5 * ((x - b2) * (x - b2)) / (d * d))
        return total

    def passive_force_length(self, lce_n):
        """(exp(4 (l - 1) / e0) - offset) / (exp(4) - offset), 0 at l = 0.2 (negative below); 0 if ignored."""
        lce_n = _arg(lce_n)
        if self.ignore_passive:
            return 0.0 * lce_n
        e0 = self.passive_strain
        offset = math.exp(_KPE * (_DG_MIN_NORM_FIBER_LENGTH - 1.0) / e0)
        with np.errstate(over="ignore"):
            return (ops(lce_n).exp(_KPE * (lce_n - 1.0) / e0) - offset) / (math.exp(_KPE) - offset)

    def force_velocity(self, v_n):
        """d1 log(d2 v + d3 + sqrt((d2 v + d3)^2 + 1)) + d4: 0 at v = -1, 1 at 0, 1.794 at 1."""
        v_n = _arg(v_n)
        o = ops(v_n)
        t = _D2 * v_n + _D3
        return _D1 * o.log(t + o.sqrt(t * t + 1.0)) + _D4

    def tendon_force_length(self, lt_n):
        """c1 exp(kT (l - c2)) - c3, kT from the tendon's strain at one normalised force."""
        lt_n = _arg(lt_n)
        kt = math.log((1.0 + _C3) / _C1) / (1.0 + self.tendon_strain - _C2)
        with np.errstate(over="ignore"):
            return _C1 * ops(lt_n).exp(kt * (lt_n - _C2)) - _C3


MuscleCurves = MillardCurves | ThelenCurves | DeGrooteCurves


def _positive(muscle: Muscle, tag: str, default: float, *, above: float = 0.0) -> float:
    value = _number(muscle, tag, default)
    if not value > above:
        raise _Refuse(muscle)(tag, f"must be > {above:g}, got {value:g}")
    return value


def _thelen(muscle: Muscle) -> ThelenCurves:
    flen = _positive(muscle, "Flen", 1.4, above=1.0)
    return ThelenCurves(
        _positive(muscle, "FmaxTendonStrain", 0.04), _positive(muscle, "FmaxMuscleStrain", 0.6),
        _positive(muscle, "KshapeActive", 0.45), _positive(muscle, "KshapePassive", 5.0), _positive(muscle, "Af", 0.25),
        flen, _positive(muscle, "fv_linear_extrap_threshold", 0.95, above=1.0 / flen))


def _degroote(muscle: Muscle) -> DeGrooteCurves:
    damping = _number(muscle, "fiber_damping", 0.0)
    if damping < 0:
        raise _Refuse(muscle)("fiber_damping", f"must be >= 0, got {damping:g}")
    scale = _number(muscle, "active_force_width_scale", 1.0)
    if not scale >= 1.0:
        raise _Refuse(muscle)("active_force_width_scale", f"must be >= 1 (OpenSim's bound), got {scale:g}")
    return DeGrooteCurves(scale, _positive(muscle, "passive_fiber_strain_at_one_norm_force", 0.6),
                          _positive(muscle, "tendon_strain_at_one_norm_force", 0.049),
                          _flag(muscle, "ignore_passive_fiber_force"), damping)


def _check_common(muscle: Muscle) -> None:
    """The five properties every muscle has: finite, positive, the pennation within [0, pi/2)."""
    refuse = _Refuse(muscle)
    if muscle.kind not in MUSCLE_KINDS:
        raise refuse("kind", f"{muscle.kind!r} is not a muscle model casflex computes; known: "
                             f"{', '.join(MUSCLE_KINDS)}")
    for tag in ("max_isometric_force", "optimal_fiber_length", "tendon_slack_length", "max_contraction_velocity"):
        value = getattr(muscle, tag)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise refuse(tag, f"must be a finite number > 0, got {value!r}")
    phi = muscle.pennation_angle_at_optimal
    if not (isinstance(phi, (int, float)) and 0.0 <= phi <= math.pi / 2 - _SIGNIFICANT):
        raise refuse("pennation_angle_at_optimal", f"must be within [0, pi/2) rad, got {phi!r}")


def muscle_curves(muscle: Muscle) -> MuscleCurves:
    """The normalised curves of ``muscle``, by its kind (see the module's docstring)."""
    _check_common(muscle)
    if muscle.kind == "Millard2012EquilibriumMuscle":
        return millard_curves(muscle)
    if muscle.kind == "Thelen2003Muscle":
        return _thelen(muscle)
    return _degroote(muscle)


@dataclass(frozen=True)
class Pennation:
    """The fixed-width pennation model: the fibres keep the width h = l_opt sin(phi_opt) (m) while their
    length l (m) changes, phi = asin(h / l). ``maximum_angle`` (rad): Millard's and Thelen's
    MuscleFixedWidthPennationModel, which keeps the fibre at least ``minimum_fiber_length`` long (h / sin of
    the maximum angle; 1% of l_opt where that angle is 0) and the angle at most the maximum; None:
    DeGroote's, without limits (a fibre shorter along the tendon than zero has cos(phi) < 0)."""

    optimal_fiber_length: float
    angle_at_optimal: float
    maximum_angle: float | None = math.acos(0.1)

    @property
    def width(self) -> float:
        """h (m)."""
        return self.optimal_fiber_length * math.sin(self.angle_at_optimal)

    @property
    def minimum_fiber_length(self) -> float:
        """m (0 without limits)."""
        if self.maximum_angle is None:
            return 0.0
        if self.maximum_angle > _SIGNIFICANT:
            return self.width / math.sin(self.maximum_angle)
        return self.optimal_fiber_length * 0.01

    def fiber_length(self, lmt, lt):
        """The fibre's length (m) where the muscle-tendon unit is ``lmt`` long and its tendon ``lt`` (m)."""
        lmt = _arg(lmt)
        o, at = ops(lmt), lmt - lt
        if self.maximum_angle is None:
            return o.sqrt(at * at + self.width ** 2)
        at_min = self.minimum_fiber_length * math.cos(self.maximum_angle)
        return o.where(at >= at_min, o.sqrt(self.width ** 2 + at * at), self.minimum_fiber_length)

    def angle(self, lce):
        """The pennation angle (rad) of a fibre ``lce`` long (m)."""
        lce = _arg(lce)
        o = ops(lce)
        with np.errstate(divide="ignore", invalid="ignore"):
            sin_phi = self.width / lce
            if self.maximum_angle is None:
                return o.asin(sin_phi)
            if not self.angle_at_optimal > _EPS:
                return 0.0 * lce
            top = self.maximum_angle
            return o.where(lce > self.minimum_fiber_length,
                           o.where(sin_phi < math.sin(top), o.asin(sin_phi), top), top)


def pennation(muscle: Muscle) -> Pennation:
    """The pennation model of ``muscle`` (its ``maximum_pennation_angle``, OpenSim's default acos(0.1))."""
    _check_common(muscle)
    if muscle.kind == "DeGrooteFregly2016Muscle":
        return Pennation(muscle.optimal_fiber_length, muscle.pennation_angle_at_optimal, None)
    top = _number(muscle, "maximum_pennation_angle", math.acos(0.1))
    if not 0.0 <= top <= math.pi / 2:
        raise _Refuse(muscle)("maximum_pennation_angle", f"must be within [0, pi/2] rad, got {top:g}")
    return Pennation(muscle.optimal_fiber_length, muscle.pennation_angle_at_optimal, top)


@dataclass(frozen=True)
class RigidTendon:
    """A muscle whose tendon keeps its slack length, at muscle-tendon lengths lmt and lengthening speeds vmt:
    each field has lmt's shape (or is a CasADi expression). Unpacks as (active, passive).

    active : N, OpenSim's ``Muscle::calcInextensibleTendonActiveFiberForce(state, 1.0)``, the force a fully
        activated muscle carries that static optimization scales by the activation, as each kind codes it:
        Millard: F_iso f_L f_V cos(phi), 0 at or below the minimum fibre length, but with phi computed
        from the normalised fibre length taken as a length (its code passes l / l_opt to the pennation
        model), so cos(phi) is near 1 where the fibre's pennation is not; Thelen: F_iso f_L f_V cos(phi), 0
        at or below the pennation model's minimum fibre length; DeGroote: F_iso f_L f_V, the fibre's force,
        not along the tendon (no cos(phi)). See ``active_along_tendon`` for F_iso f_L f_V cos(phi) alike.
    passive : N along the tendon, ``passive_elastic + passive_damping`` (OpenSim's
        getPassiveFiberForceAlongTendon where the fibre's total force is not negative; OpenSim's static
        optimization leaves passive forces out)
    fiber_length : m (Millard: at least its minimum fibre length, as its rigid-tendon muscle clamps it)
    norm_fiber_length : fiber_length / optimal_fiber_length
    pennation_angle : rad
    norm_fiber_velocity : the fibre's lengthening speed vmt cos(phi) over l_opt v_max (Millard: 0 where its
        fibre is clamped at its minimum length or its tendon would be slack)
    active_force_length, force_velocity, passive_force_length : the curves' multipliers there
    passive_elastic, passive_damping : N along the tendon, F_iso f_PE cos(phi) and F_iso beta v_n cos(phi)
        (beta the fibre damping: Millard's and DeGroote's; Millard's are 0 where its fibre is clamped)
    active_along_tendon : N, F_iso f_L f_V cos(phi) from the fields above
    """

    active: object
    passive: object
    fiber_length: object
    norm_fiber_length: object
    pennation_angle: object
    norm_fiber_velocity: object
    active_force_length: object
    force_velocity: object
    passive_force_length: object
    passive_elastic: object
    passive_damping: object
    active_along_tendon: object

    def __iter__(self):
        yield self.active
        yield self.passive


def _millard(m: Muscle, c: MillardCurves, pen: Pennation, lmt, vmt):
    """Millard2012EquilibriumMuscle with ignore_tendon_compliance (calcMuscleLengthInfo, calcFiberVelocityInfo,
    calcMuscleDynamicsInfo) and its calcInextensibleTendonActiveFiberForce."""
    o = ops(lmt, vmt)
    lopt, vmax = m.optimal_fiber_length, m.max_contraction_velocity
    lmin = max(_SIGNIFICANT, max(c.min_active_norm_length * lopt, pen.minimum_fiber_length))
    raw = pen.fiber_length(lmt, m.tendon_slack_length)
    lce = o.where(raw > lmin, raw, lmin)
    cos = o.cos(pen.angle(lce))
    dlce = vmt * cos
    buckled = (lmt - lce * cos) < m.tendon_slack_length - _SIGNIFICANT
    dlce = o.where(buckled, 0.0, dlce)
    clamped = o.where(lce <= lmin, o.where(dlce <= 0.0, 1.0, 0.0), 0.0) > 0.5  # lce < lmin: never, it is clamped
    still = o.where(buckled, 1.0, o.where(clamped, 1.0, 0.0)) > 0.5
    v_n = o.where(still, 0.0, dlce / (lopt * vmax))
    fv = o.where(still, 1.0, c.force_velocity(v_n))
    fal, fpe = c.active_force_length(lce / lopt), c.passive_force_length(lce / lopt)
    elastic = o.where(clamped, 0.0, m.max_isometric_force * fpe * cos)
    damping = o.where(clamped, 0.0, m.max_isometric_force * c.fiber_damping * v_n * cos)
    raw_cos = o.cos(pen.angle(raw))
    quirk = o.cos(pen.angle(raw / lopt))  # OpenSim passes the normalised length to calcPennationAngle
    active = o.where(raw <= lmin, 0.0, m.max_isometric_force * c.active_force_length(raw / lopt)
                     * c.force_velocity(vmt * raw_cos / (lopt * vmax)) * quirk)
    return active, lce, v_n, fal, fv, fpe, elastic, damping, cos


def _thelen_rigid(m: Muscle, c: ThelenCurves, pen: Pennation, lmt, vmt):
    """Thelen2003Muscle's calcInextensibleTendonActiveFiberForce; its length info at that fibre length."""
    o = ops(lmt, vmt)
    lce = pen.fiber_length(lmt, m.tendon_slack_length)
    cos = o.cos(pen.angle(lce))
    v_n = vmt * cos / (m.optimal_fiber_length * m.max_contraction_velocity)
    fal, fv = c.active_force_length(lce / m.optimal_fiber_length), c.force_velocity(v_n)
    fpe = c.passive_force_length(lce / m.optimal_fiber_length)
    active = o.where(lce > pen.minimum_fiber_length, m.max_isometric_force * fal * fv * cos, 0.0)
    return active, lce, v_n, fal, fv, fpe, m.max_isometric_force * fpe * cos, 0.0 * v_n, cos


def _degroote_rigid(m: Muscle, c: DeGrooteCurves, pen: Pennation, lmt, vmt):
    """DeGrooteFregly2016Muscle's calcMuscleLengthInfoHelper, calcFiberVelocityInfoHelper and
    calcMuscleDynamicsInfoHelper with ignore_tendon_compliance, as its calcInextensibleTendonActiveFiberForce."""
    lce = pen.fiber_length(lmt, m.tendon_slack_length)
    cos = (lmt - m.tendon_slack_length) / lce
    v_n = vmt * cos / (m.max_contraction_velocity * m.optimal_fiber_length)
    fal, fv = c.active_force_length(lce / m.optimal_fiber_length), c.force_velocity(v_n)
    fpe = c.passive_force_length(lce / m.optimal_fiber_length)
    fiso = m.max_isometric_force
    return fiso * fal * fv, lce, v_n, fal, fv, fpe, fiso * fpe * cos, fiso * c.fiber_damping * v_n * cos, cos


def rigid_tendon(muscle: Muscle, lmt, vmt, *, force_length_velocity: bool = True) -> RigidTendon:
    """``muscle`` at muscle-tendon lengths ``lmt`` (m) and lengthening speeds ``vmt`` (m/s; same shape, or a
    number) with its tendon at its slack length (see :class:`RigidTendon`). ``force_length_velocity=False``:
    as OpenSim's StaticOptimization with ``use_muscle_physiology`` false, ``active`` is the maximum isometric
    force and ``passive`` 0 (the other fields are still the muscle's)."""
    curves, pen = muscle_curves(muscle), pennation(muscle)
    lmt, vmt = _arg(lmt), _arg(vmt)
    if symbolic(lmt, vmt):  # a number or array beside a CasADi symbol: a CasADi matrix of its own
        lmt, vmt = (x if symbolic(x) else ca.DM(x) for x in (lmt, vmt))
    else:
        lmt, vmt = np.broadcast_arrays(lmt, vmt)
    compute = {"Millard2012EquilibriumMuscle": _millard, "Thelen2003Muscle": _thelen_rigid,
               "DeGrooteFregly2016Muscle": _degroote_rigid}[muscle.kind]
    with np.errstate(divide="ignore", invalid="ignore"):
        active, lce, v_n, fal, fv, fpe, elastic, damping, cos = compute(muscle, curves, pen, lmt, vmt)
    values = {"active": active, "passive": elastic + damping, "fiber_length": lce,
              "norm_fiber_length": lce / muscle.optimal_fiber_length,
              "pennation_angle": pen.angle(lce), "norm_fiber_velocity": v_n, "active_force_length": fal,
              "force_velocity": fv,
              "passive_force_length": fpe, "passive_elastic": elastic, "passive_damping": damping,
              "active_along_tendon": muscle.max_isometric_force * fal * fv * cos}
    if not force_length_velocity:
        values["active"] = muscle.max_isometric_force + 0.0 * lmt
        values["passive"] = 0.0 * lmt
    if not symbolic(lmt, vmt):
        values = {k: np.broadcast_to(np.asarray(v, dtype=float), lmt.shape).copy() for k, v in values.items()}
    return RigidTendon(**{f.name: values[f.name] for f in fields(RigidTendon)})
