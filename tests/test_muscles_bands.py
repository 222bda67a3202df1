"""The muscle outputs' bands (casflex.muscles.bands): one muscle about one hinge against the closed form F = M / r;
two muscles against a Monte Carlo over the muscle priors; on a 12-frame window of Hamner's subject 02 run (92 muscles),
the parts against the trial re-solved with each property moved, their growth with the declared SD, the report, the
p = 3 spread; the refusals."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from test_muscles_path import THIGH, model, muscle, point

from casflex.inverse import Bands, Filter, Trial, prepare, solve
from casflex.lab.tables import LabTable
from casflex.muscles.analysis import TrialMuscles
from casflex.muscles.bands import muscle_bands, muscle_outputs
from casflex.muscles.options import MuscleUncertainty
from casflex.muscles.reaction import JointReaction
from casflex.scene import Uncertain
from casflex.scene.from_osim import scene_from_osim
from casflex.scene.osim_actuators import read_actuators

DATA = Path(__file__).parent / "data" / "muscles"
RUN = DATA / "hamner_subject02_planar_muscles.osim"
#: an extensor behind the knee's line (origin on the thigh, insertion on the shank, m from each body's origin)
BACK = point("o", "thigh", -0.05, 0.2 - THIGH) + point("i", "shank", -0.04, -0.12)
FRONT = point("o", "thigh", -0.03, 0.25 - THIGH) + point("i", "shank", -0.06, -0.08)


def _knee(tmp_path: Path, muscles: str, path: Path | None = None):
    """The thigh held (its free joint at rest), the knee swinging over 0.3 s: the checked inputs with the shank's
    mass 10 % uncertain, the inverse, the trial (no reserve, no residual actuator)."""
    path = path or model(tmp_path, muscles)
    t = np.arange(0.0, 0.3, 0.01)
    q = -0.6 + 0.4 * np.sin(2 * np.pi * 1.5 * t)
    coords = LabTable(t, ("rz", "tx", "ty", "knee_angle"), np.column_stack([0 * t, 0 * t, 1 + 0 * t, q]),
                      in_degrees=False, source="knee.mot")
    inputs = prepare(path, Trial(coordinates=coords), filter=Filter(None, None),
                     bands=Bands([Uncertain("shank.mass", relative=0.1)]))
    res = solve(inputs)
    trial = TrialMuscles(scene_from_osim(path, muscles=True), inputs.tree, res.t, res.plates)
    return inputs, res, trial


def test_one_muscle_carries_the_moment_over_its_arm_and_its_band_is_the_moments_over_the_arm(tmp_path):
    """F = M / r (one muscle, one hinge, no reserve): the anthropometry's band of F is the inverse's band of M over
    |r| (exact on the active set: round-off); the max isometric force's leaves F unchanged (0) and moves the
    activation a = F / (Fmax f) by the secant a s / (1 - s^2); p = 3 carries the same F (the only way)."""
    inputs, res, trial = _knee(tmp_path, muscle("m", BACK))
    mb = muscle_bands(trial, inputs, None, res.z, res.zd, res.zdd,
                      uncertainty=MuscleUncertainty(max_isometric_force=0.1))
    out = trial.solve(res.z, res.zd, res.zdd)
    M, r = res.loads["knee_angle_moment"], out.arms[:, 0, 0]
    F, a = mb.values["m"], mb.values["m.activation"]
    assert np.allclose(F, M / r, rtol=1e-9) and ((a > 0.02) & (a < 0.9)).all()  # every frame off its bounds
    band = mb.bands["m"]
    assert np.allclose(band["anthropometry"], res.bands["knee_angle_moment"]["anthropometry"] / np.abs(r),
                       rtol=1e-9, atol=0)
    assert band["muscles"].max() < 1e-9 * F.max()  # rounding only
    s = 0.1
    assert np.allclose(mb.bands["m.activation"]["muscles"], a * s / (1 - s * s), rtol=1e-9, atol=0)
    assert np.allclose(mb.parts["m.max_isometric_force"]["m.activation"], -a * s / (1 - s * s), rtol=1e-9)
    assert np.allclose(band["total"], np.hypot(band["anthropometry"], band["muscles"]), rtol=1e-12)
    assert np.abs(mb.spread["m"]["p3"]).max() < 1e-6 * F.max()  # IPOPT's tolerance (1e-10 of the moments' scale)
    assert not any(c.any() for c in mb.changed.values())
    assert mb.units["m"] == "N" and mb.units["knee_resultant"] == "N"


def test_two_muscles_bands_are_the_spread_of_a_monte_carlo_over_the_muscle_priors(tmp_path):
    """Two muscles share the knee's moment (p = 2): 300 draws of their 6 properties from 3 % priors, each draw's
    outputs solved; their spread at each output's peak against the band: the standard deviation of 300 draws has
    4.1 % relative standard error, bound 3 SE (the secant's error at 3 % is below 0.1 %)."""
    inputs, res, trial = _knee(tmp_path, muscle("back", BACK) + muscle("front", FRONT))
    sd = 0.03
    unc = MuscleUncertainty(max_isometric_force=sd, optimal_fiber_length=sd, tendon_slack_length=sd)
    mb = muscle_bands(trial, inputs, None, res.z, res.zd, res.zdd, uncertainty=unc, criteria=())
    rng = np.random.default_rng(11)
    props = ("max_isometric_force", "optimal_fiber_length", "tendon_slack_length")
    variants = []
    for _ in range(300):
        x = rng.standard_normal((2, 3))
        variants.append(tuple(dataclasses.replace(m, **{p: getattr(m, p) * (1 + sd * x[i, j])
                                                         for j, p in enumerate(props)})
                              for i, m in enumerate(trial.muscles)))
    draws = [muscle_outputs(trial, o) for o in trial.solve_variants(res.z, res.zd, res.zdd, variants)]
    checked = muscle_bands(trial, inputs, None, res.z, res.zd, res.zdd, uncertainty=unc, criteria=(), draws=300)
    for name in ("back", "front", "back.activation", "knee_resultant"):
        i = int(np.argmax(np.abs(mb.values[name])))
        spread = np.std([d[name][i] for d in draws], ddof=1)
        band = mb.bands[name]["muscles"][i]
        assert abs(spread / band - 1) < 3 * 0.041, (name, spread, band)
        assert abs(checked.monte_carlo[name][i] / band - 1) < 3 * 0.041, name  # the option's own draws
    assert mb.values["back"].min() > 0 and mb.values["front"].min() > 0  # both carry load everywhere
    assert any(x.startswith("muscle bands: a Monte Carlo of 300 draws") for x in checked.report)
    assert "[first order " in checked.summary(["back"])[0]  # the Monte Carlo's part, the first order's beside it
    assert checked.bands["back"]["muscles"] is checked.monte_carlo["back"]


def test_one_muscles_marker_band_is_the_markers_chain_through_the_moment_over_the_arm(tmp_path):
    """Four markers on the thigh and shank with 0.2 mm of noise, 1 mm declared: the markers' part of the force (the
    trial re-solved at each coordinate moved) against the inverse's markers' chain (:func:`marker_part`) applied
    to M(z, z', z'') / r(z) computed without static optimization: the same to 1e-9 (measured 8e-13: static
    optimization on the active set is exact)."""
    from casflex.inverse.bands import marker_part, rigid_load_function
    from casflex.inverse.fit import fit_markers
    from casflex.lab.tables import LabMarkers
    from casflex.model.markers import marker_positions

    path = model(tmp_path, muscle("m", BACK))
    where = (("T1", "thigh", 0.05, -0.1), ("T2", "thigh", -0.04, -0.3), ("S1", "shank", 0.04, -0.1),
             ("S2", "shank", -0.03, -0.35))
    marks = "".join(f'<Marker name="{n}"><socket_parent_frame>/bodyset/{b}</socket_parent_frame><location>{x} {y} 0'
                    "</location></Marker>" for n, b, x, y in where)
    path.write_text(path.read_text().replace("</Model>", f"<MarkerSet><objects>{marks}</objects></MarkerSet></Model>"))
    given, _, _ = _knee(tmp_path, muscle("m", BACK), path=path)
    t = given.t
    y = marker_positions(given.model, np.array(given.tree.forward.map(t.size)(given.z.T)).T).reshape(t.size, -1, 2)
    y = y + 0.0002 * np.random.default_rng(2).standard_normal(y.shape)
    lab = LabMarkers(t, tuple(m.name for m in given.model.scene.markers),
                     np.concatenate([y, np.zeros_like(y[..., :1])], 2), 100.0, "m", "synthetic")
    inputs = prepare(path, Trial(lab), filter=Filter(6.0), bands=Bands(marker_noise=0.001))
    res = solve(inputs)
    trial = TrialMuscles(scene_from_osim(path, muscles=True), inputs.tree, res.t, res.plates)
    mb = muscle_bands(trial, inputs, None, res.z, res.zd, res.zdd, uncertainty=MuscleUncertainty(), criteria=())
    knee = [c.name for c in trial.scene.coordinates].index("knee_angle")

    def force(z, zd, zdd):
        M = rigid_load_function(inputs.tree, t, (), inputs.model.p_nominal)(z, zd, zdd)["knee_angle_moment"]
        return {"F": M / trial.paths.evaluate(z, zd)["moment_arms"][:, 0, knee]}

    want = marker_part(inputs.band_spec, inputs, fit_markers(inputs.tree, t, inputs.y), res.z, res.zd, res.zdd,
                       ["F"], force, step=1e-4)[0]["F"]
    got = mb.bands["m"]["markers"]
    assert got.min() > 0 and np.abs(got / want - 1).max() < 1e-9
    assert any("markers' noise 1.00 mm per axis (declared" in line for line in mb.report)
    assert not mb.changed["markers"].any()


@pytest.fixture(scope="module")
def run():
    """12 frames (0.2 s, the right stance) of Hamner's subject 02 run from OpenSim's IK of it and its plates,
    the reserves and residuals of tests/data/muscles, the pelvis', femur's, tibia's and torso's masses 10 %
    uncertain."""
    table = [Uncertain(f"{b}.mass", relative=0.1) for b in ("pelvis", "femur_r", "tibia_r", "torso")]
    inputs = prepare(RUN, Trial(coordinates=DATA / "hamner_run_ik.mot",
                                grf=DATA.parent / "lab" / "hamner_running_whole_grf.mot",
                                plates={"calcn_r": "ground_", "calcn_l": "1_ground_"}, t_start=0.4, t_end=0.59),
                     filter=Filter(10.0, None, "opensim"), bands=Bands(table))
    res = solve(inputs)
    trial = TrialMuscles(scene_from_osim(RUN, muscles=True), inputs.tree, res.t, res.plates,
                         read_actuators(DATA / "hamner_reserve_actuators.xml"),
                         reaction=JointReaction(on="child", frame="child"), joints=("hip_r", "knee_r", "ankle_r"))
    unc = MuscleUncertainty(max_isometric_force=0.1, optimal_fiber_length=0.1, tendon_slack_length=0.1)
    return inputs, res, trial, muscle_bands(trial, inputs, None, res.z, res.zd, res.zdd, uncertainty=unc)


def test_run_bands_are_finite_every_part_present_and_the_criteria_beside_them(run):
    inputs, res, trial, mb = run
    assert res.t.size == 12
    names = set(mb.values)
    assert {"soleus_r", "soleus_r.activation", "hip_r_on_femur_r_in_femur_r_fx", "knee_r_on_tibia_r_in_tibia_r_mz",
            "ankle_r_resultant"} <= names and not any(n.startswith("_") for n in names)
    for name, b in mb.bands.items():
        assert all(np.isfinite(v).all() for v in b.values()), name
        assert np.allclose(b["total"], np.sqrt(b["muscles"] ** 2 + b["anthropometry"] ** 2 + b["markers"] ** 2))
        assert not b["markers"].any()  # the coordinates given: no marker noise known
    hip = mb.bands["hip_r_resultant"]
    assert hip["muscles"].max() > 0 and hip["anthropometry"].max() > 0
    assert len(mb.parts) == 92 * 3 and sorted(mb.anthropometry_parts) == ["femur_r.mass", "pelvis.mass",
                                                                         "tibia_r.mass", "torso.mass"]
    # p = 3 moves the forces (measured: soleus_r's by 3.4 % of its peak at some frame) and is not in the SD
    d = mb.spread["soleus_r"]["p3"]
    assert np.abs(d).max() > 0.01 * np.abs(mb.values["soleus_r"]).max()
    assert np.allclose(mb.criteria["p3"]["soleus_r"] - mb.values["soleus_r"], d)


def test_run_muscle_parts_are_the_trial_re_solved_with_each_property_moved(run):
    """Three properties: the part against two plain solves (the QP, no active set carried over) at +-SD: the same
    within the QP's precision, 1e-5 of each output's peak (measured 1.3e-6, the hip's at one frame: an interior
    point's iterate beside a nearly active bound, activations up to 2.4e-5 apart between two solves of one frame:
    test_muscles_static_optimization's near= test)."""
    inputs, res, trial, mb = run
    for muscle_name, prop in (("soleus_r", "tendon_slack_length"), ("vas_int_r", "optimal_fiber_length"),
                              ("semimem_r", "max_isometric_force")):
        i = [m.name for m in trial.muscles].index(muscle_name)
        moved = []
        for sign in (1, -1):
            ms = list(trial.muscles)
            ms[i] = dataclasses.replace(ms[i], **{prop: getattr(ms[i], prop) * (1 + 0.1 * sign)})
            moved.append(muscle_outputs(trial, trial.solve(res.z, res.zd, res.zdd, muscles=tuple(ms))))
        for name in ("soleus_r", "vas_int_r", "semimem_r.activation", "hip_r_resultant",
                     "knee_r_on_tibia_r_in_tibia_r_fy"):
            want = 0.5 * (moved[0][name] - moved[1][name])
            got = mb.parts[f"{muscle_name}.{prop}"][name]
            assert np.abs(got - want).max() < 1e-5 * np.abs(mb.values[name]).max(), (muscle_name, prop, name)


def test_run_muscle_part_grows_with_the_declared_sd_where_smooth(run):
    """1 % on every max isometric force against 2 %: twice, within 0.2 % on every frame whose active set holds in
    both (the secant's s^2 terms, 4e-4 at 2 %; measured 3.7e-4; 6 of the 12 frames hold: at 5-10 % one of the run's
    92 muscles reaches or leaves a bound at nearly every frame); the tendon slack lengths are far from linear over
    +-10 % and the report says so."""
    inputs, res, trial, _ = run
    r = {s: muscle_bands(trial, inputs, None, res.z, res.zd, res.zdd, criteria=(),
                         uncertainty=MuscleUncertainty(max_isometric_force=s)) for s in (0.01, 0.02)}
    steady = ~(r[0.01].changed["muscles"] | r[0.02].changed["muscles"])
    assert steady.sum() >= 4
    for name in ("hip_r_resultant", "knee_r_resultant", "ankle_r_resultant", "soleus_r", "vas_int_r", "med_gas_r"):
        ratio = r[0.02].bands[name]["muscles"][steady] / r[0.01].bands[name]["muscles"][steady]
        assert np.abs(ratio / 2 - 1).max() < 2e-3, (name, ratio.min(), ratio.max())
    line = next(x for x in run[3].report if x.startswith("muscle bands (1 SD)"))
    bend = float(line.rsplit("tendon_slack_length ", 1)[1])
    assert bend > 0.1  # TSL: the report calls the band a secant


def test_run_report_and_summary_lines(run):
    _, res, trial, mb = run
    assert any(x.startswith("active set: ") and "of 12 frames" in x for x in mb.report)
    assert any(x.startswith("muscle bands: the coordinates were given") for x in mb.report)
    lines = mb.summary()
    assert lines[0].startswith("hip_r resultant: peak ") and " BW (" in lines[0] and "; p=3: peak " in lines[0]
    assert "largest " in lines[0] and "tendon_slack_length" in lines[0]
    assert len(lines) == 3 + 92 and lines[3].startswith("glut_med1_r: peak ")
    assert mb.body_weight == pytest.approx(9.81 * sum(b.mass for b in trial.scene.bodies))


@pytest.mark.parametrize("change, pattern", [
    ({"uncertainty": 0.1}, "uncertainty: expected a MuscleUncertainty"),
    ({"criteria": (2.0,)}, "criteria: 2 is the trial's own exponent"),
    ({"criteria": (0.5,)}, r"criteria: expected exponents >= 1"),
    ({"z": "short"}, r"z: expected \(12, "),
    ({"inputs": None}, r"inputs: the inverse's inputs the trial was made from are needed"),
    ({"draws": 1}, r"draws: expected 0 \(no Monte Carlo\) or a number of draws >= 2, got 1"),
])
def test_bad_options_are_refused_in_one_line_before_any_work(run, change, pattern):
    inputs, res, trial, _ = run
    kw = {"uncertainty": MuscleUncertainty(max_isometric_force=0.1), "criteria": (3.0,), "draws": 0}
    z = res.z[:-1] if change.get("z") == "short" else res.z
    inputs = change["inputs"] if "inputs" in change else inputs
    kw |= {k: v for k, v in change.items() if k in kw}
    with pytest.raises(ValueError, match=pattern):
        muscle_bands(trial, inputs, None, z, res.zd, res.zdd, **kw)
