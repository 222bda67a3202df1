"""casflex.muscles.curves against OpenSim 4.6's own (casflex.peers.opensim_curves): Millard's curve objects as
the muscle finalizes them, DeGroote's calc* methods, and each kind alone in a model, its length set by a
slider, at activation 1: the multipliers, the pennation, the passive force along the tendon and
calcInextensibleTendonActiveFiberForce(s, 1.0), for OpenSim's default parameters and others.

The agreement measured (max over the points of |casflex - OpenSim| / max(|OpenSim|, 1e-3 of the curve's or
force's scale)): Millard's curves 2e-12 (active), 2e-13 (passive, force-velocity), 3e-12 (tendon), their slopes
(casflex's AD through its Newton steps against OpenSim's dy/du / dx/du) 4e-11 of the largest slope: OpenSim stops
its Newton iteration for the Bezier's u at |x(u) - x| <= 2.2e-14, casflex runs its 4 steps to round-off;
DeGroote's 0 (the same closed forms, the same operations); the rigid-tendon muscles 5e-13 (Millard), 2e-16
(DeGroote), 7e-12 (Thelen's active force: OpenSim inverts the force-velocity relation by Newton to 1e-6 in
velocity, whose last step lands within ~1e-12 of the closed form casflex uses). The bound, 1e-10, leaves that
room and is far below any modelling difference.
"""

from __future__ import annotations

import importlib.util
import xml.etree.ElementTree as ET
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from casflex.muscles.curves import PROPERTY_TAGS, muscle_curves, rigid_tendon
from casflex.scene.muscles import Muscle

needs_opensim = pytest.mark.skipif(importlib.util.find_spec("opensim") is None, reason="OpenSim is not installed")

RTOL = 1e-10
POINTS = {"active_force_length": np.linspace(0.0, 2.5, 251), "passive_force_length": np.linspace(0.5, 2.5, 201),
          "force_velocity": np.linspace(-1.5, 1.5, 301), "tendon_force_length": np.linspace(0.95, 1.15, 201)}

_AFL, _FV = "ActiveForceLengthCurve", "ForceVelocityCurve"
_FPE, _FSE = "FiberForceLengthCurve", "TendonForceLengthCurve"
MILLARD_OTHER = (
    (f"{_AFL}.min_norm_active_fiber_length", 0.5), (f"{_AFL}.transition_norm_fiber_length", 0.8),
    (f"{_AFL}.max_norm_active_fiber_length", 1.7), (f"{_AFL}.shallow_ascending_slope", 0.5),
    (f"{_FV}.concentric_slope_near_vmax", 0.3), (f"{_FV}.isometric_slope", 4.0),
    (f"{_FV}.eccentric_slope_near_vmax", 0.2), (f"{_FV}.max_eccentric_velocity_force_multiplier", 1.6),
    (f"{_FV}.concentric_curviness", 0.4), (f"{_FV}.eccentric_curviness", 0.7),
    (f"{_FPE}.strain_at_zero_force", 0.05), (f"{_FPE}.strain_at_one_norm_force", 0.6),
    (f"{_FPE}.stiffness_at_low_force", 0.3), (f"{_FPE}.stiffness_at_one_norm_force", 4.0), (f"{_FPE}.curviness", 0.6),
    (f"{_FSE}.strain_at_one_norm_force", 0.06), (f"{_FSE}.stiffness_at_one_norm_force", 30.0),
    (f"{_FSE}.norm_force_at_toe_end", 0.6), (f"{_FSE}.curviness", 0.4), ("fiber_damping", 0.05),
    ("maximum_pennation_angle", 1.2))
CASES = {
    "millard": ("Millard2012EquilibriumMuscle", ()),
    "millard_undamped": ("Millard2012EquilibriumMuscle", (("fiber_damping", 0.0),)),
    "millard_other": ("Millard2012EquilibriumMuscle", MILLARD_OTHER),
    "degroote": ("DeGrooteFregly2016Muscle", ()),
    "degroote_other": ("DeGrooteFregly2016Muscle", (("active_force_width_scale", 1.5), ("fiber_damping", 0.05),
                                                    ("passive_fiber_strain_at_one_norm_force", 0.5),
                                                    ("tendon_strain_at_one_norm_force", 0.06))),
    "degroote_no_passive": ("DeGrooteFregly2016Muscle", (("ignore_passive_fiber_force", 1),)),
    "thelen": ("Thelen2003Muscle", ()),
    "thelen_hamner": ("Thelen2003Muscle", (("FmaxTendonStrain", 0.033), ("KshapeActive", 0.5), ("KshapePassive", 4.0),
                                           ("Af", 0.3), ("Flen", 1.8), ("fv_linear_extrap_threshold", 0.9),
                                           ("maximum_pennation_angle", 1.0))),
}


def make(case: str, *, phi: float = 0.3, rigid: bool = False) -> Muscle:
    kind, properties = CASES[case]
    extra = (("ignore_tendon_compliance", 1.0),) if rigid and kind != "Thelen2003Muscle" else ()
    return Muscle(f"m_{case}", kind, 1200.0, 0.08, 0.25, phi, 10.0, (), (*properties, *extra))


def worst(mine, theirs, scale: float) -> float:
    """max |mine - theirs| / max(|theirs|, 1e-3 scale); inf where only one of the two is NaN (OpenSim's NaN:
    DeGroote's fibre of zero length, without pennation at the tendon's slack length)."""
    mine, theirs = np.asarray(mine, dtype=float), np.asarray(theirs, dtype=float)
    if np.any(np.isnan(mine) != np.isnan(theirs)):
        return np.inf
    both = ~np.isnan(theirs)
    return float(np.max(np.abs(mine - theirs)[both] / np.maximum(np.abs(theirs[both]), 1e-3 * scale)))


def _points(curves, name: str) -> np.ndarray:
    x = POINTS[name]
    joints = [seg[0] for seg in getattr(curves, name).ctrl_x] if hasattr(getattr(curves, name), "ctrl_x") else []
    return np.sort(np.r_[x, joints, getattr(getattr(curves, name), "x1", 1.0)])


@needs_opensim
@pytest.mark.parametrize("case", ["millard", "millard_undamped", "millard_other", "degroote", "degroote_other",
                                  "degroote_no_passive"])
def test_the_curves_are_opensims(case):
    from casflex.peers.opensim_curves import curve_values

    m = make(case)
    curves = muscle_curves(m)
    x = {name: _points(curves, name) for name in POINTS}
    ref = curve_values(m, x)
    for name, xs in x.items():
        mine = getattr(curves, name)(xs)
        assert worst(mine, ref[name]["value"], 1.0) < RTOL, (name, worst(mine, ref[name]["value"], 1.0))
        if "slope" in ref[name]:  # Millard's: OpenSim's dy/dx against casflex's AD through its Newton steps
            s = ca.SX.sym("x")
            d = ca.Function("d", [s], [ca.jacobian(getattr(curves, name)(s), s)]).map(xs.size)
            theirs = np.array(ref[name]["slope"])
            err = worst(np.array(d(xs)).ravel(), theirs, float(np.max(np.abs(theirs))))
            assert err < 1e-9, (name, err)  # dy/du / dx/du at OpenSim's u: its round-off is the slope's


def _grid(m: Muscle) -> tuple[np.ndarray, np.ndarray]:
    """Lengths from a buckled tendon to twice the optimal fibre length past slack, speeds to +-1.5 vmax."""
    lmt = m.tendon_slack_length + m.optimal_fiber_length * np.linspace(-0.2, 2.2, 25)
    vmt = m.optimal_fiber_length * m.max_contraction_velocity * np.linspace(-1.5, 1.5, 9)
    lengths, speeds = np.meshgrid(lmt, vmt)
    return lengths.ravel(), speeds.ravel()


@needs_opensim
@pytest.mark.parametrize(("case", "phi"), [("millard", 0.3), ("millard", 0.0), ("millard_undamped", 0.3),
                                           ("millard_other", 0.45), ("degroote", 0.3), ("degroote_other", 0.0),
                                           ("thelen", 0.3), ("thelen_hamner", 0.2)])
def test_the_rigid_tendon_muscle_is_opensims(case, phi):
    from casflex.peers.opensim_curves import muscle_values

    m = make(case, phi=phi, rigid=True)
    lmt, vmt = _grid(m)
    mine = rigid_tendon(m, lmt, vmt)
    thelen = m.kind == "Thelen2003Muscle"
    ref = {k: np.array(v) for k, v in muscle_values(m, lmt, vmt, fiber_length=mine.fiber_length if thelen else None
                                                    ).items()}
    assert np.allclose(ref["length"], lmt, rtol=1e-14)  # the slider sets the path's length
    f = m.max_isometric_force
    assert worst(mine.active, ref["active"], f) < RTOL  # calcInextensibleTendonActiveFiberForce(s, 1.0)
    for field, key in (("fiber_length", "lce"), ("pennation_angle", "phi"), ("active_force_length", "fal"),
                       ("passive_force_length", "fpe")):
        assert worst(getattr(mine, field), ref[key], 1.0) < RTOL, field
    assert worst(mine.passive_elastic, ref["passive"] if thelen else ref["elastic"], f) < RTOL
    if thelen:  # no rigid tendon in OpenSim's Thelen2003Muscle: its velocity state is not the rigid one
        return
    for field, key in (("norm_fiber_velocity", "v_n"), ("force_velocity", "fv")):
        assert worst(getattr(mine, field), ref[key], 1.0) < RTOL, field
    # OpenSim's rigid-tendon Millard muscle keeps its total fibre force >= 0 by changing its damping force
    total = mine.active_along_tendon + mine.passive
    kept = total >= 0 if m.kind == "Millard2012EquilibriumMuscle" else np.ones(lmt.shape, bool)
    assert np.sum(kept) > 100
    assert worst(mine.passive[kept], ref["passive"][kept], f) < RTOL
    assert worst(mine.passive_damping[kept], ref["damping"][kept], f) < RTOL
    assert np.allclose(ref["passive"][~kept], -mine.active_along_tendon[~kept], rtol=1e-10, atol=1e-9)


@needs_opensim
@pytest.mark.parametrize("case", ["millard_undamped", "millard_other"])
def test_the_active_force_of_an_elastic_tendon_muscle_is_opensims(case):
    """calcInextensibleTendonActiveFiberForce, as static optimization calls it on the model as it is (here the
    undamped elastic-tendon Millard, whose curves OpenSim adjusts: minimum 0.1, slopes at vmax)."""
    from casflex.peers.opensim_curves import muscle_values

    m = make(case)
    lmt, vmt = _grid(m)
    mine = rigid_tendon(m, lmt, vmt)
    ref = muscle_values(m, lmt, vmt, fiber_length=mine.fiber_length)
    assert worst(mine.active, ref["active"], m.max_isometric_force) < RTOL


@needs_opensim
@pytest.mark.parametrize("case", ["thelen", "thelen_hamner"])
def test_thelens_tendon_is_opensims(case):
    """Thelen's tendon curve through the muscle's tendon force: the fibre held at its optimal length, the path
    as long as the tendon to stretch plus the fibre along it."""
    from casflex.peers.opensim_curves import muscle_values

    m = make(case)
    curves = muscle_curves(m)
    lt_n = POINTS["tendon_force_length"]
    along = m.optimal_fiber_length * np.cos(np.arcsin(np.sin(m.pennation_angle_at_optimal)))
    lmt = lt_n * m.tendon_slack_length + along
    ref = muscle_values(m, lmt, 0.0 * lmt, fiber_length=np.full(lmt.shape, m.optimal_fiber_length))
    theirs = np.array(ref["tendon_force"]) / m.max_isometric_force
    assert worst(curves.tendon_force_length(lt_n), theirs, 1.0) < RTOL


@needs_opensim
@pytest.mark.parametrize("kind", list(PROPERTY_TAGS))
def test_the_tags_read_are_opensims_property_names(kind):
    from casflex.peers.opensim_curves import property_names

    names = property_names(kind)
    assert set(PROPERTY_TAGS[kind]) <= set(names), set(PROPERTY_TAGS[kind]) - set(names)
    common = ("max_isometric_force", "optimal_fiber_length", "tendon_slack_length", "pennation_angle_at_optimal",
              "max_contraction_velocity")
    assert set(common) <= set(names)


DATA = Path(__file__).parent / "data" / "muscles" / "curves"
_COMMON = {"max_isometric_force": 1000.0, "optimal_fiber_length": 0.1, "tendon_slack_length": 0.2,
           "pennation_angle_at_optimal": 0.0, "max_contraction_velocity": 10.0}  # OpenSim's Muscle defaults


def _from_xml(element: ET.Element) -> Muscle:
    """A muscle element's numbers as (tag, value) pairs, a curve object's children as ``<Curve>.<tag>``,
    true / false as 1 / 0: what the .osim reader is to give (tests only)."""
    def number(text: str) -> float | None:
        text = (text or "").strip()
        if text in ("true", "false"):
            return float(text == "true")
        try:
            return float(text)
        except ValueError:
            return None

    pairs = []
    for child in element:
        if child.tag.endswith("Curve"):
            pairs += [(f"{child.tag}.{c.tag}", number(c.text)) for c in child if number(c.text) is not None]
        elif len(child) == 0 and number(child.text) is not None:
            pairs.append((child.tag, number(child.text)))
    values = dict(pairs)
    common = [values.pop(k, d) for k, d in _COMMON.items()]
    return Muscle(element.get("name"), element.tag, *common, (), tuple(values.items()))


@needs_opensim
@pytest.mark.parametrize("file", ["gait10dof18musc_muscles.xml", "hamner_thelen_muscles.xml"])
def test_the_models_muscles_as_opensim_reads_them(file):
    """The muscles of OpenSim's gait10dof18musc (Millard, damped, elastic tendon) and of Hamner's model
    (Thelen) as their .osim gives them (tests/data/muscles/curves/README.md): the tags as written, OpenSim's
    defaults for those left out, against the muscles OpenSim reads from the same XML."""
    from casflex.peers.opensim_curves import file_muscle_values

    elements = list(ET.parse(DATA / file).getroot().iter())
    muscles = [_from_xml(e) for e in elements if e.tag in ("Millard2012EquilibriumMuscle", "Thelen2003Muscle")]
    assert len(muscles) == (18 if file.startswith("gait") else 6)
    for m in muscles:
        lmt = m.tendon_slack_length + m.optimal_fiber_length * np.linspace(0.3, 1.8, 7)
        vmt = m.optimal_fiber_length * m.max_contraction_velocity * np.linspace(-0.8, 0.8, 7)
        mine = rigid_tendon(m, lmt, vmt)
        ref = file_muscle_values(DATA / file, m.kind, m.name, lmt, vmt, fiber_length=mine.fiber_length)
        assert worst(mine.active, ref["active"], m.max_isometric_force) < RTOL, m.name
        for field, key in (("pennation_angle", "phi"), ("active_force_length", "fal"), ("passive_force_length", "fpe")):
            assert worst(getattr(mine, field), ref[key], 1.0) < RTOL, (m.name, field)
