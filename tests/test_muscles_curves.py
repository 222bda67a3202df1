"""casflex.muscles.curves: OpenSim's muscle curves at their defining points, their shape, numpy and CasADi
alike, AD against finite differences, the rigid-tendon muscle and the refusals. OpenSim's own values:
tests/test_peers_opensim_curves.py."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from casflex.muscles.curves import PROPERTY_TAGS, DeGrooteCurves, ThelenCurves, muscle_curves, pennation, rigid_tendon
from casflex.scene.muscles import Muscle

KINDS = ("Millard2012EquilibriumMuscle", "Thelen2003Muscle", "DeGrooteFregly2016Muscle")
CURVES = ("active_force_length", "passive_force_length", "force_velocity", "tendon_force_length")
#: each curve's points, across and beyond its domain
DOMAIN = {"active_force_length": np.linspace(0.1, 2.3, 221), "passive_force_length": np.linspace(0.6, 2.2, 161),
          "force_velocity": np.linspace(-1.4, 1.4, 282), "tendon_force_length": np.linspace(0.96, 1.12, 161)}


def muscle(kind: str, properties=(), *, phi: float = 0.3, name: str = "vasti") -> Muscle:
    return Muscle(name, kind, 1500.0, 0.09, 0.22, phi, 10.0, (), tuple(properties))


def slope(f, x: np.ndarray) -> np.ndarray:
    """dy/dx by CasADi's AD of f on an SX symbol."""
    s = ca.SX.sym("x")
    return np.array(ca.Function("d", [s], [ca.jacobian(f(s), s)]).map(x.size)(x)).ravel()


def test_thelens_curves_at_their_defining_points():
    c = ThelenCurves()
    assert c.active_force_length(1.0) == 1.0
    assert c.passive_force_length(1.0 + c.muscle_strain) == pytest.approx(1.0, rel=1e-15)
    assert np.all(c.passive_force_length(np.linspace(0.3, 1.0, 8)) == 0.0)
    assert c.tendon_force_length(1.0 + c.tendon_strain) == pytest.approx(1.0, rel=1e-14)
    assert c.tendon_force_length(1.0) == 0.0
    assert c.force_velocity(0.0) == 1.0
    assert c.force_velocity(-1.0) == 0.0 and c.force_velocity(-3.0) == 0.0  # a = 1: v_max at -1
    assert c.force_velocity(-0.25, activation=0.0) == 0.0  # c = 0.25 + 0.75 a
    # the eccentric branch reaches Flen * threshold where the linear extension starts, with the same slope
    k = (2 + 2 / c.af) / (c.flen - 1)
    v_th = (c.flen * c.fv_threshold - 1) / (k * (c.flen - c.flen * c.fv_threshold))
    assert c.force_velocity(v_th) == pytest.approx(c.flen * c.fv_threshold, rel=1e-14)
    d = slope(c.force_velocity, np.array([v_th - 1e-7, v_th + 1e-7]))
    assert d[0] == pytest.approx(d[1], rel=1e-5)  # C1 at the switch (1e-7 apart: the slope moves by ~1e-6)


def test_degrootes_published_constants():
    c = DeGrooteCurves()
    assert c.active_force_length(1.0) == pytest.approx(1.0, abs=1e-15)  # b11 set so that f(1) = 1
    assert c.force_velocity(-1.0) == pytest.approx(0.0, abs=1e-15)  # d1, d4 solved through (-1, 0), (0, 1)
    assert c.force_velocity(0.0) == pytest.approx(1.0, abs=1e-15)
    assert c.force_velocity(1.0) == pytest.approx(1.794, abs=1e-3)  # the documented range [0, 1.794]
    assert c.passive_force_length(0.2) == pytest.approx(0.0, abs=1e-15)
    assert c.passive_force_length(1.6) == pytest.approx(1.0, rel=1e-15)  # 1 + passive strain 0.6
    assert c.tendon_force_length(1.0) == pytest.approx(0.0, abs=1e-15)  # c2 = c3: no force at slack
    assert c.tendon_force_length(1.049) == pytest.approx(1.0, rel=1e-14)
    wide = DeGrooteCurves(width_scale=2.0)
    assert wide.active_force_length(1.4) == pytest.approx(c.active_force_length(1.2), rel=1e-15)


@pytest.mark.parametrize("damping", [0.1, 0.0])
def test_millards_curves_pass_through_their_defining_points(damping):
    m = muscle("Millard2012EquilibriumMuscle", [("fiber_damping", damping)])
    c = muscle_curves(m)
    low = 0.0 if damping else 0.1  # the damped model's minimum is 0, the undamped elastic-tendon one's 0.1
    afl, fpe, fv, fse = (getattr(c, k) for k in CURVES)
    assert afl(1.0) == pytest.approx(1.0, abs=1e-15)
    assert afl(0.4441) == pytest.approx(low, abs=1e-15) and afl(1.8123) == pytest.approx(low, abs=1e-15)
    assert afl(0.2) == pytest.approx(low, abs=1e-15) and afl(2.2) == pytest.approx(low, abs=1e-15)
    assert fv(0.0) == pytest.approx(1.0, abs=1e-15)
    assert fv(1.0) == pytest.approx(1.4, abs=1e-14)  # max eccentric multiplier at +vmax; round-off of the Bezier
    assert fv(-1.0) == pytest.approx(0.0, abs=1e-15)
    # the Bezier's round-off: 1e-13
    assert fpe(1.0) == pytest.approx(0.0, abs=1e-15) and fpe(1.7) == pytest.approx(1.0, abs=1e-13)
    assert fse(1.0) == pytest.approx(0.0, abs=1e-15) and fse(1.049) == pytest.approx(1.0, abs=1e-13)
    # the slopes OpenSim's factory sets: 0 at the optimum, the isometric slope 5 at v = 0, kIso = 2 / 0.7
    assert slope(afl, np.array([1.0]))[0] == pytest.approx(0.0, abs=1e-12)
    assert slope(fv, np.array([0.0]))[0] == pytest.approx(5.0, rel=1e-12)
    assert slope(fpe, np.array([1.7]))[0] == pytest.approx(2.0 / 0.7, rel=1e-12)
    # slopes at +-vmax: 0 in the damped model, half the slopes near vmax in the undamped one
    assert slope(fv, np.array([-1.0, 1.0])) == pytest.approx([0.0, 0.0] if damping else [0.125, 0.075], abs=1e-12)


@pytest.mark.parametrize("kind", KINDS)
def test_the_curves_are_monotone_where_opensims_are(kind):
    c = muscle_curves(muscle(kind))
    fal = c.active_force_length(DOMAIN["active_force_length"])
    top = int(np.argmax(fal))
    assert DOMAIN["active_force_length"][top] == pytest.approx(1.0, abs=0.011)
    # where a curve is flat (beyond its ends) neighbours differ by round-off only
    assert np.all(np.diff(fal[: top + 1]) >= -1e-14) and np.all(np.diff(fal[top:]) <= 1e-14)
    for k in ("passive_force_length", "force_velocity", "tendon_force_length"):
        assert np.all(np.diff(getattr(c, k)(DOMAIN[k])) >= -1e-14), k
        assert np.sum(np.diff(getattr(c, k)(DOMAIN[k])) > 1e-6) > 20, k  # and rising somewhere


def _joints(curve) -> list[float]:
    return [seg[0] for seg in curve.ctrl_x[1:]] + [curve.x0, curve.x1]


@pytest.mark.parametrize("name", CURVES)
def test_millards_slopes_are_continuous_at_the_segment_joints(name):
    curve = getattr(muscle_curves(muscle("Millard2012EquilibriumMuscle")), name)
    for x in _joints(curve):
        h = 1e-9 * max(1.0, abs(x))
        left, right = slope(curve, np.array([x - h, x + h]))
        values = curve(np.array([x - h, x, x + h]))
        # over 2e-9 the value moves by slope * 1e-9 and the slope by curvature * 1e-9: both well below 1e-6
        assert abs(left - right) < 1e-6 * max(1.0, abs(left)), (x, left, right)
        assert abs(values[2] - values[0]) < 1e-6, (x, values)


@pytest.mark.parametrize("kind", KINDS)
def test_numpy_and_casadi_give_the_same_values(kind):
    c = muscle_curves(muscle(kind))
    for k, x in DOMAIN.items():
        mine = getattr(c, k)(x)
        sx = ca.SX.sym("x", x.size)
        f = ca.Function("f", [sx], [getattr(c, k)(sx)])
        mx = ca.MX.sym("x", 1, x.size)
        g = ca.Function("g", [mx], [getattr(c, k)(mx)])
        for other in (np.array(f(x)).ravel(), np.array(g(x)).ravel(), np.array(getattr(c, k)(ca.DM(x))).ravel()):
            # round-off only: Millard's u found from another start (numpy: a table; CasADi: bisection), both
            # Newton-converged, differ by eps-level amounts the slope (up to 28) amplifies
            assert np.allclose(other, mine, rtol=1e-12, atol=1e-13), (k, np.max(np.abs(other - mine)))


def _kinks(c, name: str) -> list[float]:
    """Where a curve's slope (Thelen's) or its curvature (Millard's joints) jumps: finite differences straddling
    them measure the jump, not the slope."""
    if isinstance(c, ThelenCurves):
        e_toe = 99 * c.tendon_strain * math.exp(3) / (166 * math.exp(3) - 67)
        return {"passive_force_length": [1.0], "force_velocity": [-1.0, 0.0], "tendon_force_length": [1.0, 1.0 + e_toe]
                }.get(name, [-9.0])
    if isinstance(c, DeGrooteCurves):
        return [-9.0]
    return _joints(getattr(c, name))


@pytest.mark.parametrize("kind", KINDS)
def test_ad_gives_the_finite_differences(kind):
    c = muscle_curves(muscle(kind))
    h = 1e-6
    for k, x in DOMAIN.items():
        f = getattr(c, k)
        x = x[np.min(np.abs(x[:, None] - np.array(_kinks(c, k))[None, :]), axis=1) > 10 * h]
        fd = (f(x + h) - f(x - h)) / (2 * h)
        # central differences: error ~ h^2 f''' + eps / h ~ 1e-10 of the slopes (up to ~30)
        assert np.allclose(slope(f, x), fd, rtol=1e-6, atol=1e-7), (k, np.max(np.abs(slope(f, x) - fd)))


def test_the_bezier_inversion_holds_to_round_off():
    curve = muscle_curves(muscle("Millard2012EquilibriumMuscle")).active_force_length
    from casflex.muscles._ops import ops  # noqa: PLC0415
    from casflex.muscles.bezier import _slope, _solve_u, _value  # noqa: PLC0415

    for seg in curve.ctrl_x:
        x = np.linspace(seg[0], seg[5], 1001)
        u = _solve_u(x, list(seg), ops(x))
        # the power form's round-off: its terms reach 30 x the control points, 1e-13 bounds 500 eps of them
        assert np.max(np.abs(_value(u, list(seg)) - x)) < 1e-13
        assert np.all(_slope(u, list(seg)) > 0)


@pytest.mark.parametrize("kind", KINDS)
def test_the_rigid_tendon_muscle(kind):
    m = muscle(kind)
    lmt = np.linspace(0.25, 0.36, 12).reshape(3, 4)
    vmt = np.linspace(-0.5, 0.5, 12).reshape(3, 4)
    r = rigid_tendon(m, lmt, vmt)
    active, passive = r
    assert active.shape == passive.shape == r.fiber_length.shape == (3, 4)
    pen = pennation(m)
    assert np.allclose(np.cos(r.pennation_angle) * r.fiber_length, lmt - m.tendon_slack_length, rtol=1e-14)
    assert np.allclose(np.sin(r.pennation_angle) * r.fiber_length, pen.width, rtol=1e-14)
    assert np.allclose(r.norm_fiber_velocity, vmt * np.cos(r.pennation_angle) / (0.09 * 10.0), rtol=1e-14)
    off = rigid_tendon(m, lmt, vmt, force_length_velocity=False)
    assert np.all(off.active == 1500.0) and np.all(off.passive == 0.0)
    # the active force static optimization uses, as each kind's calcInextensibleTendonActiveFiberForce has it
    cos = np.cos(r.pennation_angle)
    if kind == "Millard2012EquilibriumMuscle":  # the pennation of the normalised length taken as a length
        quirk = np.cos(np.arcsin(pen.width / r.norm_fiber_length))
        assert np.allclose(active, r.active_along_tendon / cos * quirk, rtol=1e-13)
        assert np.all(active >= r.active_along_tendon) and np.max(active / r.active_along_tendon) > 1.3
    elif kind == "DeGrooteFregly2016Muscle":  # the fibre's force, not along the tendon
        assert np.allclose(active, r.active_along_tendon / cos, rtol=1e-14)
    else:
        assert np.allclose(active, r.active_along_tendon, rtol=1e-14)
    sx, sv = ca.SX.sym("l", 3, 4), ca.SX.sym("v", 3, 4)
    f = ca.Function("r", [sx, sv], list(rigid_tendon(m, sx, sv)))
    for mine, theirs in zip(f(lmt, vmt), (active, passive), strict=True):
        assert np.allclose(np.array(mine), theirs, rtol=1e-13, atol=1e-9)  # N: round-off


def test_millards_fibre_stops_at_its_minimum_length():
    m = muscle("Millard2012EquilibriumMuscle", [("ignore_tendon_compliance", 1)], phi=0.0)
    r = rigid_tendon(m, np.array([0.22 + 0.02, 0.22 + 0.02, 0.22 + 0.1]), np.array([-0.3, 0.3, -0.3]))
    lmin = 0.4441 * 0.09
    assert r.fiber_length[0] == r.fiber_length[1] == pytest.approx(lmin, rel=1e-15)
    assert r.active[0] == r.active[1] == 0.0 and r.active[2] > 0
    assert r.norm_fiber_velocity[0] == 0.0 and r.force_velocity[0] == 1.0  # clamped: no velocity
    assert r.passive[0] == 0.0


def _refusal(kind: str, properties, match: str, **common):
    m = Muscle("soleus_r", kind, *[common.get(k, v) for k, v in (
        ("max_isometric_force", 1000.0), ("optimal_fiber_length", 0.05), ("tendon_slack_length", 0.25),
        ("pennation_angle_at_optimal", 0.4), ("max_contraction_velocity", 10.0))], (), tuple(properties))
    with pytest.raises(ValueError, match=match) as info:
        rigid_tendon(m, 0.3, 0.0)
    message = str(info.value)
    assert "\n" not in message and message.startswith("muscle 'soleus_r'.")


@pytest.mark.parametrize(("kind", "properties", "common", "match"), [
    ("Millard2012EquilibriumMuscle", [("fiber_damping", math.nan)], {}, r"\.fiber_damping: must be a finite number"),
    ("Millard2012EquilibriumMuscle", [], {"max_isometric_force": -5.0}, r"\.max_isometric_force: must be a finite"),
    ("Thelen2003Muscle", [], {"optimal_fiber_length": 0.0}, r"\.optimal_fiber_length: must be a finite number > 0"),
    ("DeGrooteFregly2016Muscle", [], {"tendon_slack_length": math.inf}, r"\.tendon_slack_length: must be"),
    ("Thelen2003Muscle", [], {"pennation_angle_at_optimal": 1.6}, r"\.pennation_angle_at_optimal: must be within"),
    ("Millard2012EquilibriumMuscle", [("ForceVelocityCurve.concentric_curviness", 1.5)], {},
     r"\.ForceVelocityCurve\.concentric_curviness: must be within \[0, 1\]"),
    ("Millard2012EquilibriumMuscle", [("ForceVelocityCurve.max_eccentric_velocity_force_multiplier", 1.0)], {},
     r"max_eccentric_velocity_force_multiplier: must be > 1"),
    ("Millard2012EquilibriumMuscle", [("ActiveForceLengthCurve.transition_norm_fiber_length", 0.3)], {},
     r"\.ActiveForceLengthCurve\.transition_norm_fiber_length: must lie between"),
    ("Millard2012EquilibriumMuscle", [("ActiveForceLengthCurve.minimum_value", -0.1)], {},
     r"\.ActiveForceLengthCurve\.minimum_value: must be >= 0"),
    ("Millard2012EquilibriumMuscle", [("FiberForceLengthCurve.curviness", 0.5)], {},
     r"\.FiberForceLengthCurve\.stiffness_at_low_force: OpenSim takes .* all together or none"),
    ("Millard2012EquilibriumMuscle", [("TendonForceLengthCurve.strain_at_one_norm_force", 0.0)], {},
     r"\.TendonForceLengthCurve\.strain_at_one_norm_force: must be > 0"),
    # equal to strain_at_zero_force: the default stiffness 2 / (e1 - e0) raised ZeroDivisionError (a traceback)
    ("Millard2012EquilibriumMuscle", [("FiberForceLengthCurve.strain_at_one_norm_force", 0.0)], {},
     r"\.FiberForceLengthCurve\.strain_at_one_norm_force: must be > strain_at_zero_force \(0\), got 0"),
    ("Millard2012EquilibriumMuscle", [("ignore_tendon_compliance", 0.5)], {}, r"\.ignore_tendon_compliance: must be 0"),
    ("Millard2012EquilibriumMuscle", [("maximum_pennation_angle", -0.1)], {}, r"\.maximum_pennation_angle: must be"),
    ("Thelen2003Muscle", [("Flen", 1.0)], {}, r"\.Flen: must be > 1"),
    ("Thelen2003Muscle", [("fv_linear_extrap_threshold", 0.5)], {}, r"\.fv_linear_extrap_threshold: must be > 0\.71"),
    ("Thelen2003Muscle", [("KshapeActive", -0.45)], {}, r"\.KshapeActive: must be > 0"),
    ("DeGrooteFregly2016Muscle", [("active_force_width_scale", 0.5)], {}, r"\.active_force_width_scale: must be >= 1"),
    ("DeGrooteFregly2016Muscle", [("passive_fiber_strain_at_one_norm_force", 0.0)], {},
     r"\.passive_fiber_strain_at_one_norm_force: must be > 0"),
])
def test_bad_parameters_are_refused_naming_the_muscle_and_property(kind, properties, common, match):
    _refusal(kind, properties, match, **common)


def test_an_unknown_kind_is_refused():
    with pytest.raises(ValueError, match=r"muscle 'soleus_r'\.kind: 'RigidTendonMuscle' is not a muscle model"):
        muscle_curves(Muscle("soleus_r", "RigidTendonMuscle", 1000.0, 0.05, 0.25, 0.0, 10.0, ()))


def test_opensims_adjustments_of_millards_curves():
    base = [("ActiveForceLengthCurve.minimum_value", 0.05), ("ForceVelocityCurve.concentric_slope_at_vmax", 0.1)]
    damped = muscle_curves(muscle("Millard2012EquilibriumMuscle", base))
    classic = muscle_curves(muscle("Millard2012EquilibriumMuscle", [*base, ("fiber_damping", 0.0009)]))
    rigid = muscle_curves(muscle("Millard2012EquilibriumMuscle", [*base, ("fiber_damping", 0.0),
                                                                   ("ignore_tendon_compliance", 1)]))
    assert damped.fiber_damping == 0.1 and classic.fiber_damping == 0.0  # below 0.001: undamped
    assert damped.active_force_length.y0 == 0.0 and rigid.active_force_length.y0 == 0.0
    assert classic.active_force_length.y0 == 0.1  # raised to 0.1 for the classic elastic-tendon model
    assert damped.force_velocity.dydx0 == 0.0 == rigid.force_velocity.dydx0
    assert classic.force_velocity.dydx0 == 0.125  # at least half the slope near vmax (0.25)


@pytest.mark.parametrize("kind", KINDS)
def test_property_tags_lists_every_tag_read(kind, monkeypatch):
    read = []
    original = Muscle.property
    monkeypatch.setattr(Muscle, "property", lambda self, tag, default: read.append(tag) or original(self, tag, default))
    optional = (("FiberForceLengthCurve.stiffness_at_low_force", 0.2), ("FiberForceLengthCurve.curviness", 0.75),
                ("FiberForceLengthCurve.stiffness_at_one_norm_force", 2.0 / 0.7),
                ("TendonForceLengthCurve.stiffness_at_one_norm_force", 1.375 / 0.049),
                ("TendonForceLengthCurve.norm_force_at_toe_end", 2 / 3), ("TendonForceLengthCurve.curviness", 0.5))
    given = optional if kind == "Millard2012EquilibriumMuscle" else ()  # read only where given (all or none)
    rigid_tendon(muscle(kind, given), 0.3, 0.1)
    assert set(read) == set(PROPERTY_TAGS[kind])


@pytest.mark.parametrize("name", CURVES)
def test_millards_second_derivatives_are_the_slopes_derivatives(name):
    """AD's second derivative through the Newton steps (an NLP's Hessian) against central differences of the
    AD slope, inside the segments (the curvature jumps at the joints)."""
    curve = getattr(muscle_curves(muscle("Millard2012EquilibriumMuscle")), name)
    s = ca.SX.sym("x")
    d1 = ca.Function("d1", [s], [ca.jacobian(curve(s), s)])
    d2 = ca.Function("d2", [s], [ca.hessian(curve(s), s)[0]])
    for seg in curve.ctrl_x:
        x = np.linspace(seg[0], seg[5], 13)[1:-1]
        h = 1e-6 * (seg[5] - seg[0])
        fd = (np.array(d1.map(x.size)(x + h)) - np.array(d1.map(x.size)(x - h))).ravel() / (2 * h)
        ad = np.array(d2.map(x.size)(x)).ravel()
        # central differences of a slope: error ~ h^2 f'''' + eps f' / h, ~1e-6 of curvatures up to ~1e4
        assert np.allclose(ad, fd, rtol=1e-5, atol=1e-5 * np.max(np.abs(ad))), (name, np.max(np.abs(ad - fd)))


def test_millards_curves_are_one_named_function_each(tmp_path, monkeypatch):
    """A distinct curve, a distinct name (CasADi's names become C symbols); the same curve, the same Function."""
    a = muscle_curves(muscle("Millard2012EquilibriumMuscle")).active_force_length
    b = muscle_curves(muscle("Millard2012EquilibriumMuscle", [("ActiveForceLengthCurve.minimum_value", 0.0),
                                                               ("fiber_damping", 0.0)])).active_force_length
    again = muscle_curves(muscle("Millard2012EquilibriumMuscle", name="other")).active_force_length
    assert a.function is again.function and a.function.name() != b.function.name()
    x = ca.MX.sym("x", 3)
    f = ca.Function("both", [x], [a(x) + b(x)])
    monkeypatch.chdir(tmp_path)
    f.generate("both.c", {"with_header": False})  # no clash of the two curves' C symbols
    assert (tmp_path / "both.c").stat().st_size > 0
    assert float(f(ca.DM([1.0, 1.0, 1.0]))[0]) == pytest.approx(2.0, abs=1e-14)
