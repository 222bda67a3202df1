"""The loads' bands (casflex.inverse.bands, casflex.inverse.marker_band): the anthropometry's against the closed form
of a pendulum, against the scene re-solved with each property moved and against a Monte Carlo over the priors; the
markers' against the brute-force propagation of each marker sample through the whole chain and against the spread
of independent noisy copies of a trial; segments against the whole record; the outputs; the refusals."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from inverse_scenes import INERTIA, C, M, pendulum

from casflex.inverse import Bands, Filter, Trial, inverse_dynamics, inverse_model, kinematic_tree, prepare, solve
from casflex.inverse.bands import BandError, rigid_load_function
from casflex.inverse.fit import FittedMotion, filtered_rates, fit_markers, fit_pose
from casflex.inverse.inputs import weighted
from casflex.inverse.marker_band import marker_band, memory, residual_noise
from casflex.inverse.plates import plate_loads
from casflex.inverse.rigid import rigid_loads
from casflex.lab import LabMarkers
from casflex.model import assemble
from casflex.model.markers import marker_positions
from casflex.scene import Uncertain
from casflex.scene.io import loads_scene

G = 9.81
A, W = 0.7, 2 * np.pi * 1.3  # the pendulum's swing, rad and rad/s
LABELS = ("BASE.1", "BASE.2", "ARM.1", "ARM.2")
LAB = Path(__file__).parent / "data" / "lab"
TRC, GRF = LAB / "hamner_running_stride.trc", LAB / "hamner_running_stride_grf.mot"
HAMNER = {"grf": GRF, "plates": {"ankle": "ground_"}, "root": "pelvis"}
TABLE = [Uncertain(f"{b}.{p}", relative=0.15) for b in ("pelvis", "thigh", "shank", "foot")
         for p in ("mass", "inertia")]
SPRING = """
[[torsion_springs]]
name = "tk"
nodes = ["base", "link"]
kt = 5.0
ct = 0.4
[[uncertain]]
target = "arm.mass"
sd = 0.2
[[uncertain]]
target = "arm.inertia"
relative = 0.1
[[uncertain]]
target = "tk.kt"
sd = 1.0
[[uncertain]]
target = "tk.ct"
range = [0.2, 0.6]
"""


def _trial(h: float = 0.01, duration: float = 1.0, noise: float = 0.0, seed: int = 0, moving: bool = False,
           extra: str = "") -> LabMarkers:
    """The pendulum's markers over its swing A sin(W t) (the base still or moving), with white noise (m)."""
    model = inverse_model(loads_scene(pendulum(extra)))
    tree = kinematic_tree(model)
    t = np.arange(0.0, duration + h / 2, h)
    z = np.zeros((t.size, 4))
    z[:, 1], z[:, 3] = 1.0, A * np.sin(W * t)
    if moving:
        z[:, 0], z[:, 1], z[:, 2] = 0.05 * np.sin(3 * t), 1.0 + 0.02 * np.cos(5 * t), 0.1 * np.sin(2 * t)
    y = marker_positions(model, np.array(tree.forward.map(t.size)(z.T)).T).reshape(t.size, -1, 2)
    y = y + noise * np.random.default_rng(seed).standard_normal(y.shape)
    return LabMarkers(t, LABELS, np.concatenate([y, np.zeros_like(y[..., :1])], 2), 1.0 / h, "m", "synthetic")


def test_pendulum_band_is_the_closed_form():
    """tau = (I + M C^2) theta'' + M g C sin(theta) + kt theta + ct theta' (the drive leaves the spring its share):
    d tau / dM = C^2 theta'' + g C sin(theta), d/dI = theta'', d/dkt = theta, d/dct = theta', at the pipeline's own
    kinematics; the scene's [[uncertain]] and uncertain= (arm.mass's replaced, the base's mass added)."""
    res = inverse_dynamics(loads_scene(pendulum(SPRING)), Trial(_trial(extra=SPRING)), filter=Filter(None),
                           bands=Bands([Uncertain("arm.mass", sd=0.3), Uncertain("base.mass", sd=0.1)]))
    th, thd, thdd = res.z[:, 3], res.zd[:, 3], res.zdd[:, 3]
    want = {"arm.mass": 0.3 * (C * C * thdd + G * C * np.sin(th)), "arm.inertia": 0.1 * INERTIA * thdd,
            "tk.kt": 1.0 * th, "tk.ct": 0.4 / np.sqrt(12) * thd, "base.mass": 0.0 * th}
    assert sorted(res.band_parts) == sorted(want)
    tau = res.load("pivot.moment")
    for target, part in want.items():  # exact but for the base's fitted pose: still to 1e-11 m, differenced twice
        assert np.abs(res.band_parts[target]["pivot.moment"] - part).max() < 1e-9 * np.abs(tau).max(), target
    band = res.bands["pivot.moment"]
    assert np.allclose(band["anthropometry"], np.sqrt(sum(p**2 for p in want.values())), rtol=1e-9, atol=1e-9)
    assert np.allclose(res.band_parts["base.mass"]["root.fy"], 0.1 * G)  # the base still: its weight, no more
    assert band["markers"].max() < 1e-6 * band["anthropometry"].max()  # exact markers: no noise in the residuals
    assert np.allclose(band["total"], np.hypot(band["anthropometry"], band["markers"]))
    assert any("the loads linear in each (second derivatives within" in line for line in res.report)
    assert "pivot.moment" in res.summary().split("bands at each moment's peak")[1]


def test_a_centre_of_mass_the_loads_are_quadratic_in_is_said_and_its_part_is_the_derivative():
    """The arm's centre of mass 2 cm up or down (its com_y, the pivot 1 - com_y above it): tau is quadratic in the
    distance c, (I + M c^2) theta'' + M g c sin(theta), so the central difference is the derivative exactly,
    -sd (2 M c theta'' + M g sin(theta)); the report names the property as not linear."""
    res = inverse_dynamics(loads_scene(pendulum()), Trial(_trial()), filter=Filter(None),
                           bands=Bands([Uncertain("arm.com_y", sd=0.02)]))
    th, thdd = res.z[:, 3], res.zdd[:, 3]
    want = -0.02 * (2 * M * C * thdd + M * G * np.sin(th))
    tau = res.load("pivot.moment")
    assert np.abs(res.band_parts["arm.com_y"]["pivot.moment"] - want).max() < 1e-9 * np.abs(tau).max()
    assert any("the loads linear in all but ['arm.com_y']: their parts are first-order changes" in line
               for line in res.report)


@pytest.fixture(scope="module")
def hamner():
    """The Hamner stride's inverse with 15 % on every segment's mass and inertia, and its checked inputs."""
    inputs = prepare("hamner_leg", Trial(TRC, **HAMNER), filter=Filter(10.0), bands=Bands(TABLE))
    return inputs, solve(inputs)


def test_anthropometry_band_is_the_scene_re_solved_with_each_property_moved(hamner):
    """Each part against the loads of the scene with that property set to its value +- 1 sd (a model assembled
    anew, no parameters): the same to round-off, and the loads linear in it (the one-sided change the same)."""
    inputs, res = hamner
    scene = dataclasses.replace(inputs.model.scene, uncertain=())
    for u in TABLE:
        value = scene.property_value(u.target)
        moved = []
        for v in (value + u.relative * value, value - u.relative * value):
            model = assemble(scene.with_property(u.target, v))
            tree = kinematic_tree(model, "pelvis")
            out = rigid_loads(tree, res.t, res.z, res.zd, res.zdd, model.p_nominal,
                              lambda tt, q, m=model: plate_loads(m, list(inputs.plates), tt, q))
            moved.append(out)
        for name in ("hip.moment", "knee.moment", "ankle.moment", "root.fy", "knee.fx"):
            scale = np.abs(res.loads[name]).max()
            part = res.band_parts[u.target][name]
            assert np.abs(part - 0.5 * (moved[0][name] - moved[1][name])).max() < 1e-10 * scale, (u.target, name)
            assert np.abs(part - (moved[0][name] - res.loads[name])).max() < 1e-10 * scale, (u.target, name)


def test_anthropometry_band_is_the_spread_of_a_monte_carlo_over_the_priors(hamner):
    """200 draws of the 8 properties from their priors: each draw's loads are the parts' sum exactly (linear), and
    their spread at each moment's peak is the band within its sampling error (a standard deviation from 200 draws:
    5.0 % relative SE; bound 3 SE)."""
    inputs, res = hamner
    spec = inputs.band_spec
    loads = rigid_load_function(spec.tree, res.t, inputs.plates, spec.model.p_nominal)
    xi = np.random.default_rng(7).standard_normal((200, spec.sd.size))
    names = ("hip.moment", "knee.moment", "ankle.moment")
    draws = np.zeros((200, res.t.size, len(names)))
    for d, x in enumerate(xi):
        p = spec.model.p_nominal.copy()
        p[spec.index] += spec.sd * x
        out = loads(res.z, res.zd, res.zdd, p)
        for k, name in enumerate(names):
            draws[d, :, k] = out[name]
            linear = res.loads[name] + sum(xj * res.band_parts[t][name] for xj, t in zip(x, spec.targets, strict=True))
            assert np.abs(out[name] - linear).max() < 1e-10 * np.abs(res.loads[name]).max()
    spread = draws.std(axis=0, ddof=1)
    for k, name in enumerate(names):
        i = int(np.argmax(np.abs(res.loads[name])))
        band = res.bands[name]["anthropometry"][i]
        assert abs(spread[i, k] / band - 1) < 3 * 0.050, (name, spread[i, k], band)


def _loads_of(tree, t, Z, cutoff, names):
    z, zd, zdd = filtered_rates(t, Z, cutoff, "butterworth")
    out = rigid_loads(tree, t, z, zd, zdd, tree.model.p_nominal)
    return np.column_stack([out[n] for n in names])


@pytest.mark.parametrize("cutoff", [6.0, None])
def test_marker_band_is_the_brute_force_propagation_of_every_sample(cutoff):
    """2 mm of noise on the moving pendulum's markers, one marker weighted 4, a frame whose arm markers are lost (a
    gap the spline fills): every channel of every frame moved by 1e-5 m, the pose refitted, the coordinates filled,
    filtered and differenced, the loads solved, sum (sigma dL/dy)^2 against the band: the same to 1e-4 of its peak
    (measured 4e-6, the brute force's own error; 9e-4 without the residuals' curvature in the fit's derivative)."""
    lab = _trial(duration=0.4, noise=0.002, seed=3, moving=True)
    xyz = lab.xyz.copy()
    xyz[12, 2:] = np.nan
    lab = dataclasses.replace(lab, xyz=xyz)
    tasks = {"BASE.1": 1.0, "BASE.2": 1.0, "ARM.1": 4.0, "ARM.2": 1.0}
    sigma = 0.001
    res = inverse_dynamics(loads_scene(pendulum()), Trial(lab, tasks=tasks), filter=Filter(cutoff),
                           bands=Bands(marker_noise=sigma))
    assert any(line.startswith("gaps: 1 frames") for line in res.report)
    tree = kinematic_tree(inverse_model(weighted(loads_scene(pendulum()), tasks)[0]))
    names = ["pivot.moment", "pivot.fx", "pivot.fy", "root.fx", "root.fy", "root.mz"]
    Y = lab.xyz[:, :, :2].reshape(lab.t.size, -1)
    fit = fit_markers(tree, lab.t, Y)
    L0, var, eps = _loads_of(tree, lab.t, fit.z, cutoff, names), 0.0, 1e-5
    good = np.isfinite(fit.rms)
    from scipy.interpolate import CubicSpline

    for i in np.flatnonzero(good):
        for j in np.flatnonzero(np.isfinite(Y[i])):
            y = Y[i].copy()
            y[j] += eps
            Z = fit.z.copy()
            Z[i] = fit_pose(tree, y, fit.z[i])[0]
            Z[~good] = CubicSpline(lab.t[good], Z[good], axis=0)(lab.t[~good])
            var = var + ((_loads_of(tree, lab.t, Z, cutoff, names) - L0) * sigma / eps) ** 2
    band = np.column_stack([res.bands[n]["markers"] for n in names])
    assert np.abs(band - np.sqrt(var)).max(axis=0).max() < 1e-4 * np.sqrt(var).max()


def test_marker_band_is_zero_for_exact_markers_and_the_spread_of_noisy_copies():
    """Exact markers: the residuals show no noise, no band. 1 mm of white noise on 30 independent copies of the
    swing on a moving base: the noise the residuals show is the noise (their mean within 2 %: 404 degrees of freedom
    a copy, 2.5 % each, 0.46 % the mean's SE; measured -1.2 %), and the spread of the copies' moments is the band
    (their variances over the frames away from the ends, within 15 %: 30 copies of 4 filter-correlated stretches
    each; measured +3 %, +1 %, +3 %). Markers declared exact: no band."""
    res = inverse_dynamics(loads_scene(pendulum()), Trial(_trial(moving=True)), filter=Filter(6.0),
                           bands=Bands(asked=True))
    assert res.bands["pivot.moment"]["markers"].max() < 1e-9 * np.abs(res.loads["pivot.moment"]).max()
    assert res.settings["bands"]["marker_noise_m"] < 1e-9
    copies = [inverse_dynamics(loads_scene(pendulum()), Trial(_trial(noise=1e-3, seed=s, moving=True)),
                               filter=Filter(6.0))
              for s in range(30)]
    tree = kinematic_tree(inverse_model(loads_scene(pendulum())))
    sigma = np.array([residual_noise(tree, FittedMotion(c.t, c.z, c.marker_rms, np.zeros(0), [], c.marker_misfit))
                      for c in copies])
    assert abs(sigma.mean() / 1e-3 - 1) < 0.02
    declared = inverse_dynamics(loads_scene(pendulum()), Trial(_trial(noise=1e-3, moving=True)), filter=Filter(6.0),
                                bands=Bands(marker_noise=1e-3))
    inner = slice(10, -10)
    for name in ("pivot.moment", "root.fx", "root.mz"):
        spread = np.array([c.loads[name] for c in copies]).var(axis=0, ddof=1)[inner]
        band = declared.bands[name]["markers"][inner] ** 2
        assert abs(spread.mean() / band.mean() - 1) < 0.15, (name, spread.mean() / band.mean())
    exact = inverse_dynamics(loads_scene(pendulum()), Trial(_trial(noise=1e-3, moving=True)), filter=Filter(6.0),
                             bands=Bands(marker_noise=0.0))
    assert exact.bands["pivot.moment"]["markers"].max() == 0 and any("declared exact" in ln for ln in exact.report)


def _random_record(n: int, gap: int, seed: int):
    """(t at 100 Hz, decided (a 4-frame gap at ``gap``), the fit's covariances C (n, 3, 3), the loads' sensitivities
    D (3, n, 2, 3)) of a random record of n frames, 3 coordinates and 2 loads."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    decided = np.ones(n, dtype=bool)
    decided[gap:gap + 4] = False
    R = rng.standard_normal((n, 3, 5))
    C = R @ R.transpose(0, 2, 1) * decided[:, None, None]
    return t, decided, C, rng.standard_normal((3, n, 2, 3))


@pytest.mark.parametrize("how", ["butterworth", "opensim"])
def test_segments_give_the_whole_record_s_band(how):
    """A long record taken in segments of 60 frames (with the filter's memory as margins) against the whole at
    once: the same to 1e-12, a gap in it."""
    n = 700
    t, decided, C, D = _random_record(n, 300, seed=0)
    whole = marker_band(t, decided, C, D, 6.0, how, core=n)
    parts = marker_band(t, decided, C, D, 6.0, how, core=60)
    assert memory(t, 6.0, how) < 300  # margins shorter than the record: the segments are real
    assert np.abs(parts - whole).max() < 1e-12 * whole.max()


@pytest.mark.parametrize(("how", "cutoff"), [("butterworth", 6.0), ("opensim", 6.0), ("butterworth", None)])
def test_the_interior_s_convolution_gives_the_whole_record_s_band(how, cutoff):
    """Frames farther than the filter's memory from the ends and from a gap are taken by a convolution with the
    interior's operator (FFT): the same as the whole record's operator built from impulses, to 1e-12 of the band's
    peak (round-off of the FFT and of the impulses' sums; measured 2e-13 to 3e-13)."""
    from casflex.inverse.marker_band import _interior, _segment

    n = 1500
    t, decided, C, D = _random_record(n, 700, seed=1)
    margin = memory(t, cutoff, how)
    assert 300 < _interior(decided, margin).sum() < n - 4 * margin  # both routes are taken
    whole = np.sqrt(np.maximum(_segment(t, decided, C, D, (0, n), margin, cutoff, how), 0.0))
    assert np.abs(marker_band(t, decided, C, D, cutoff, how) - whole).max() < 1e-12 * whole.max()


def test_outputs_carry_the_bands_only_when_asked(hamner, tmp_path):
    _, res = hamner
    plain = dataclasses.replace(res, bands={}, band_parts={})
    for r, tag in ((res, "b"), (plain, "p")):
        csv, sto, npz = (r.save(tmp_path / f"{tag}.{ext}") for ext in ("csv", "sto", "npz"))
        header = [h.partition(" [")[0] for h in csv.read_text().splitlines()[0].split(",")]  # the names, no units
        table = np.loadtxt(csv, delimiter=",", skiprows=1)
        names = sto.read_text().split("endheader\n")[1].splitlines()[0].split("\t")
        with np.load(npz) as z:
            keys = set(z.files)
            if r is res:
                k = [str(s) for s in z["load_names"]].index("knee.moment")
                assert np.allclose(z["sd_total"][:, k], res.bands["knee.moment"]["total"])
                assert z["band_parts"].shape == (8, res.t.size, len(res.loads))
        if r is res:
            for col in ("knee.moment_sd", "knee.moment_sd_anthropometry", "knee.moment_sd_markers"):
                assert col in header and col in names
            assert np.allclose(table[:, header.index("knee.moment_sd_markers")], res.bands["knee.moment"]["markers"])
            assert "bands at each moment's peak" in res.summary()
        else:
            assert not [c for c in header + names if "_sd" in c] and not keys & {"sd_total", "band_parts"}
            assert "bands at each moment" not in plain.summary()


def test_given_coordinates_have_no_markers_part_and_lab_names_get_bands(tmp_path):
    leg = LAB / "hamner_subject02_leg.osim"
    fitted = inverse_dynamics(leg, Trial(TRC, grf=GRF, plates={"calcn_r": "ground_"}), filter=Filter(None))
    from casflex.scene.coordinates import to_lab
    from casflex.scene.from_osim import scene_from_osim

    scene = scene_from_osim(leg).scene
    cols = {c.name: to_lab(scene, c, fitted.z[:, fitted.coordinate_names.index(c.scene_coordinate())])
            for c in scene.coordinates}
    rows = ["\t".join(f"{v:.15g}" for v in row) for row in np.column_stack([fitted.t, *cols.values()])]
    mot = tmp_path / "ik.mot"
    mot.write_text("\n".join(["ik", "inDegrees=no", "endheader", "\t".join(["time", *cols]), *rows]) + "\n")
    res = inverse_dynamics(leg, Trial(coordinates=mot, grf=GRF, plates={"calcn_r": "ground_"}), filter=Filter(6.0),
                           bands=Bands([Uncertain("tibia_r.mass", relative=0.1)]))
    band = res.bands["knee_angle_r_moment"]
    assert band["markers"].max() == 0 and band["anthropometry"].max() > 0
    sign = next(c.sign for c in scene.coordinates if c.name == "knee_angle_r")
    part = res.band_parts["tibia_r.mass"]
    assert np.array_equal(part["knee_angle_r_moment"], sign * part["knee_r.moment"])
    assert any("the markers' part is left out" in line for line in res.report)
    assert "knee_angle_r_moment" in res.summary().split("bands at each moment's peak")[1]


@pytest.mark.parametrize(("trial", "bands", "match"), [
    ({}, {"uncertain": [Uncertain("nobody.mass", sd=1.0)]}, r"uncertain: .*unknown element or load 'nobody'"),
    ({}, {"uncertain": [Uncertain("pivot.kt", sd=1.0)]}, r"uncertain: .*'pivot' is a joint"),
    ({}, {"uncertain": [Uncertain("arm.length", sd=1.0)]}, r"uncertain: .*'arm' has no numeric property 'length'"),
    ({}, {"uncertain": ["arm.mass"]}, "uncertain: expected casflex.scene.Uncertain entries"),
    ({}, {"uncertain": [Uncertain("arm.mass", sd=1.0)], "asked": False}, "bands: not asked"),
    ({}, {"marker_noise": -1.0}, "marker_noise: must be a distance >= 0 m"),
    ({"coordinates": "x.mot", "markers": None}, {"marker_noise": 0.001}, "marker_noise: the coordinates were given"),
    ({"tasks": {"BASE.1": 1.0, "ARM.1": 1.0}}, {"asked": True}, "marker_noise: the 2 markers give no more channels"),
])
def test_bands_refused_before_the_trial_is_read(trial, bands, match):
    """One line naming the option (the trial's file does not exist: nothing was read)."""
    trial = {"markers": "no_such_trial.trc"} | trial
    with pytest.raises(BandError, match=match) as err:
        prepare(loads_scene(pendulum()), Trial(**trial), bands=Bands(**bands))
    assert "\n" not in str(err.value)


def test_flexible_segments_are_refused():
    with pytest.raises(BandError, match=r"bands: for rigid segments only: the beams \[.*make this a flexible"):
        prepare("hamner_leg_flexible", Trial("no_such_trial.trc", root="pelvis"), bands=Bands(asked=True))


def test_solve_s_options_replace_what_prepare_was_asked(hamner):
    inputs, res = hamner
    assert solve(inputs, bands=Bands(asked=False)).bands == {}
    plain = dataclasses.replace(inputs, band_spec=None)
    again = solve(plain, bands=Bands([Uncertain("shank.mass", relative=0.15)], marker_noise=0.0))
    assert list(again.band_parts) == ["shank.mass"] and again.bands["knee.moment"]["markers"].max() == 0
    assert np.allclose(again.band_parts["shank.mass"]["knee.moment"], res.band_parts["shank.mass"]["knee.moment"],
                       rtol=1e-12, atol=0)
    with pytest.raises(BandError, match="uncertain: .*unknown element or load 'shin'"):
        solve(plain, bands=Bands([Uncertain("shin.mass", sd=1.0)]))
