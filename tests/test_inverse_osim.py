"""casflex inverse on an OpenSim model file: marker weights from a task file, the lab's names, OpenSim's .sto,
the plates' own cut-off, and ``casflex import``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from casflex.inverse import Filter, Fit, Trial, inverse_dynamics
from casflex.lab import read_sto
from casflex.lab.setups import read_tasks

DATA = Path(__file__).parent / "data" / "lab"
LEG, TRC = DATA / "hamner_subject02_leg.osim", DATA / "hamner_running_stride.trc"
GRF = DATA / "hamner_running_stride_grf.mot"
TASKS = """<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000"><IKTaskSet name="tasks"><objects>
{rows}
<IKCoordinateTask name="knee_angle_r"><apply>true</apply><weight>1</weight></IKCoordinateTask>
</objects></IKTaskSet></OpenSimDocument>
"""


def _tasks(tmp_path, weights: dict[str, float], name="tasks.xml") -> Path:
    rows = "\n".join(f'<IKMarkerTask name="{k}"><apply>{"true" if w else "false"}</apply><weight>{w or 5}</weight>'
                     "</IKMarkerTask>" for k, w in weights.items())
    path = tmp_path / name
    path.write_text(TASKS.format(rows=rows))
    return path


@pytest.fixture(scope="module")
def plain():
    return inverse_dynamics(LEG, Trial(TRC, grf=GRF, plates={"calcn_r": "ground_"}))


def test_loads_take_the_model_s_coordinate_names_and_signs(plain):
    for c in ("hip_flexion_r", "knee_angle_r", "ankle_angle_r"):
        hinge = c.split("_")[0] + "_r"
        assert np.array_equal(plain.load(f"{c}_moment"), plain.load(f"{hinge}.moment"))  # sign +1 here
    assert np.array_equal(plain.load("pelvis_ty_force"), plain.load("root.fy"))
    assert plain.settings["moments"] == ["hip_flexion_r_moment", "knee_angle_r_moment", "ankle_angle_r_moment"]
    assert any(line.startswith("markers' misfit RMS/largest, mm: R.ASIS") for line in plain.report)


def test_task_weights_are_a_weighted_fit_and_a_task_less_marker_is_left_out(tmp_path, plain):
    labels = plain.marker_labels
    uniform = read_tasks(_tasks(tmp_path, {k: 7.0 for k in labels}))
    assert uniform.coordinate_tasks == ("knee_angle_r",)
    same = inverse_dynamics(LEG, Trial(TRC, grf=GRF, plates={"calcn_r": "ground_"}, tasks=uniform))
    # one weight for all: the same minimiser (LM's steps scale alike; converged to 1e-10 rad)
    assert np.max(np.abs(same.z - plain.z)) < 1e-8
    heavy = {k: (100.0 if k.startswith("R.Shank") else 1.0) for k in labels} | {"R.Toe.Tip": 0.0}
    res = inverse_dynamics(LEG, Trial(TRC, grf=GRF, plates={"calcn_r": "ground_"},
                                      tasks=_tasks(tmp_path, heavy, "h.xml")))
    k = {lb: i for i, lb in enumerate(labels)}
    shank = [k[lb] for lb in labels if lb.startswith("R.Shank")]
    rms = lambda r: np.sqrt(np.nanmean(r.marker_misfit[:, shank] ** 2))  # noqa: E731
    assert rms(res) < 0.7 * rms(plain)  # the weighted markers fitted closer (measured: 7.1 -> 3.0 mm)
    assert "R.Toe.Tip" not in res.marker_labels  # applied false: left out, as OpenSim's IK leaves it
    missing = {lb: 1.0 for lb in labels if lb != "R.Heel"} | {"L.Knee": 2.0}
    res = inverse_dynamics(LEG, Trial(TRC, grf=GRF, plates={"calcn_r": "ground_"}, tasks=missing))
    assert any("['R.Heel'] have no task or a weight of 0: left out" in w for w in res.warnings)
    assert any("tasks of markers the scene does not have, ignored: ['L.Knee']" in w for w in res.warnings)


def test_a_model_marker_with_no_task_need_not_be_in_the_trial(plain):
    import dataclasses

    from casflex.scene import Marker
    from casflex.scene.from_osim import scene_from_osim

    sc = scene_from_osim(LEG).scene
    m = sc.markers[3]
    extra = dataclasses.replace(sc, markers=(*sc.markers, Marker("R_Knee_Lat", m.on, m.x + 0.05, m.y, "R.Knee.Lat")))
    lacked = inverse_dynamics(extra, Trial(TRC, grf=GRF, plates={"calcn_r": "ground_"}))  # before: refused
    assert np.max(np.abs(lacked.z - plain.z)) < 1e-8  # left out, as OpenSim's IK does, and said
    assert any("the scene's markers ['R.Knee.Lat'] are not in the trial: left out of the fit" in w
               for w in lacked.warnings)
    res = inverse_dynamics(extra, Trial(TRC, grf=GRF, plates={"calcn_r": "ground_"},
                                        tasks={m: 1.0 for m in plain.marker_labels}))  # the lab's tasks leave it out
    assert np.max(np.abs(res.z - plain.z)) < 1e-8 and "R.Knee.Lat" not in res.marker_labels


def test_one_plate_given_to_two_feet_is_refused():
    # its force acted on both (the ground reaction counted twice), without a word
    whole = Path(__file__).resolve().parent / "data" / "lab"
    with pytest.raises(ValueError, match="plate 'ground_' is given to both 'calcn_r' and 'calcn_l'"):
        inverse_dynamics(str(whole / "hamner_subject02_planar.osim"), Trial(
            str(whole / "hamner_running_whole.trc"), grf=str(whole / "hamner_running_whole_grf.mot"),
            plates={"calcn_r": "ground_", "calcn_l": "ground_"}, tasks=str(whole / "hamner_tasks_ik.xml")))


def test_bad_task_files_are_refused_in_one_line(tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text("<IKTaskSet><objects><IKMarkerTask name='A'><weight>-3</weight></IKMarkerTask></objects>"
                   "</IKTaskSet>")
    with pytest.raises(ValueError, match=r"bad.xml: task 'A': weight must be a number >= 0, got '-3'"):
        read_tasks(bad)
    bad.write_text("<IKTaskSet><objects/></IKTaskSet>")
    with pytest.raises(ValueError, match="no IKMarkerTask"):
        read_tasks(bad)
    with pytest.raises(ValueError, match="no task weights any of the scene's markers"):
        inverse_dynamics(LEG, Trial(TRC, tasks={"X": 1.0}))


def test_the_plates_own_cut_off_changes_only_what_the_plates_reach(plain):
    raw = inverse_dynamics(LEG, Trial(TRC, grf=GRF, plates={"calcn_r": "ground_"}), filter=Filter(cutoff_plates=None))
    assert np.array_equal(raw.z, plain.z)  # the coordinates filtered alike
    d = np.abs(raw.load("ankle_angle_r_moment") - plain.load("ankle_angle_r_moment"))
    stance, swing = raw.t < 0.667, (raw.t > 0.79) & (raw.t < 0.95)  # toe-off at 0.667 s, the next strike 1.117 s
    # in stance the filter rounds the impact (36 N m at most, measured); in mid-swing only the 6 Hz filter's
    # ringing of the plate (a few N after toe-off) differs: 0.64 N m measured, bound at 3 % of stance's
    assert d[swing].max() < 0.03 * d[stance].max() and d[stance].max() > 10.0
    assert "filtered not at all" in "\n".join(raw.report)


def test_sto_output_and_import_from_the_command_line(tmp_path):
    cli = [sys.executable, "-m", "casflex"]
    toml = tmp_path / "leg.toml"
    p = subprocess.run([*cli, "import", str(LEG), "--out", str(toml)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert "a coupled hinge" in p.stdout and toml.read_text().startswith("# Made by casflex import")
    sto = tmp_path / "loads.sto"
    p = subprocess.run([*cli, "inverse", str(toml), "--data", str(TRC), "--loads", str(GRF), "--plate",
                        "calcn_r=ground_", "--cutoff-plates", "none", "--quiet", "--out", str(sto)],
                       capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    table = read_sto(sto)
    assert "knee_angle_r_moment" in table.names and table.t.size == 44
    assert "units: time s; pelvis_tilt_moment N m; pelvis_tx_force N" in sto.read_text()
    expect = "--cutoff-plates: expected a frequency in Hz (> 0), 'none' or 'same'"
    for bad, said in ((["--cutoff-plates", "fast"], expect),
                      (["--tasks", str(tmp_path / "none.xml")], "none.xml: cannot read it")):
        p = subprocess.run([*cli, "inverse", str(toml), "--data", str(TRC), "--quiet", *bad], capture_output=True,
                           text=True)
        assert p.returncode == 2 and said in p.stderr and p.stderr.count("\n") == 1, p.stderr
    p = subprocess.run([*cli, "import", str(TRC), "--out", str(tmp_path / "x.toml")], capture_output=True, text=True)
    assert p.returncode == 2 and "must be an OpenSim model (.osim)" in p.stderr


EXTERNAL = """<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="30516"><ExternalLoads name="loads"><objects>
<ExternalForce name="right"><applied_to_body>calcn_r</applied_to_body>
<force_expressed_in_body>{frame}</force_expressed_in_body><point_expressed_in_body>ground</point_expressed_in_body>
<force_identifier>ground_force_v</force_identifier><point_identifier>ground_force_p</point_identifier>
<torque_identifier>{torque}</torque_identifier><data_source_name>grf</data_source_name></ExternalForce>
</objects><datafile>{data}</datafile></ExternalLoads></OpenSimDocument>
"""


def _external(tmp_path, name="loads.xml", frame="ground", torque="ground_torque_", data=None) -> Path:
    path = tmp_path / name
    path.write_text(EXTERNAL.format(frame=frame, torque=torque, data=data or GRF.name))
    return path


def test_opensims_external_loads_file_names_the_plates(tmp_path, plain):
    import shutil

    shutil.copy(GRF, tmp_path / GRF.name)  # the data file, named relative to the loads file
    loads = _external(tmp_path)
    res = inverse_dynamics(LEG, Trial(TRC, grf=loads))
    assert np.array_equal(res.loads["ankle_angle_r_moment"], plain.loads["ankle_angle_r_moment"])
    setup = tmp_path / "id_setup.xml"  # an ID setup naming it
    setup.write_text("<OpenSimDocument><InverseDynamicsTool><external_loads_file>loads.xml</external_loads_file>"
                     "</InverseDynamicsTool></OpenSimDocument>")
    assert np.array_equal(inverse_dynamics(LEG, Trial(TRC, grf=setup)).loads["hip_flexion_r_moment"],
                          plain.loads["hip_flexion_r_moment"])
    for path, match in ((_external(tmp_path, "a.xml", frame="calcn_r"), "force_expressed_in_body is 'calcn_r'"),
                        (_external(tmp_path, "b.xml", torque="1_ground_torque_"), "no column '1_ground_torque_x'"),
                        (setup, "plates: .* says which body")):
        with pytest.raises(ValueError, match=match):
            inverse_dynamics(LEG, Trial(TRC, grf=path, plates={"calcn_r": "ground_"} if path == setup else None))
    cli = subprocess.run([sys.executable, "-m", "casflex", "inverse", str(LEG), "--data", str(TRC), "--loads",
                          str(loads)], capture_output=True, text=True)  # not --quiet: the report on stdout
    assert cli.returncode == 0 and "plates 'ground_' on calcn_r" in cli.stdout, cli.stderr


def test_what_an_id_setup_asks_beyond_its_plates_and_is_not_done_is_said(tmp_path):
    # an ID setup given as the plates' file: its cut-off and time range were left out without a word (the loads
    # then differ from OpenSim's ID tool run on that setup); said where they differ from the options
    import shutil

    shutil.copy(GRF, tmp_path / GRF.name)
    _external(tmp_path)
    setup = tmp_path / "id_setup.xml"
    tool = ("<OpenSimDocument><InverseDynamicsTool><external_loads_file>loads.xml</external_loads_file>{}"
            "</InverseDynamicsTool></OpenSimDocument>")
    for extra, said in (("", []),
                        ("<lowpass_cutoff_frequency_for_coordinates>6</lowpass_cutoff_frequency_for_coordinates>"
                         "<time_range> 0 2</time_range>", []),
                        ("<lowpass_cutoff_frequency_for_coordinates>10</lowpass_cutoff_frequency_for_coordinates>"
                         "<time_range> 0.5 0.9</time_range>",
                         ["its lowpass_cutoff_frequency_for_coordinates 10 Hz is not applied: the coordinates are "
                          "filtered at 6 Hz (--cutoff 10",
                          "its time_range 0.5-0.9 s is not applied: the loads cover 0.4-1.11667 s (--t-start 0.5 "
                          "--t-end 0.9"]),
                        ("<lowpass_cutoff_frequency_for_coordinates>-1</lowpass_cutoff_frequency_for_coordinates>",
                         ["its lowpass_cutoff_frequency_for_coordinates -1 (unfiltered) is not applied"])):
        setup.write_text(tool.format(extra))
        warnings = inverse_dynamics(LEG, Trial(TRC, grf=setup)).warnings
        got = [w for w in warnings if w.startswith(f"{setup}: its ")]
        assert len(got) == len(said), warnings
        assert all(g.startswith(f"{setup}: {s}") for g, s in zip(got, said, strict=True)), warnings
    ik = tmp_path / "ik_setup.xml"  # an IK setup naming the task file: its time range likewise
    shutil.copy(DATA / "hamner_tasks_ik.xml", tmp_path / "tasks.xml")
    for extra, n in (("", 0), ("<time_range> 0.4 1.2</time_range>", 0), ("<time_range> 0.6 1.0</time_range>", 1)):
        ik.write_text(f'<OpenSimDocument><InverseKinematicsTool><IKTaskSet file="tasks.xml"/>{extra}'
                      "</InverseKinematicsTool></OpenSimDocument>")
        warnings = inverse_dynamics(LEG, Trial(TRC, grf=GRF, plates={"calcn_r": "ground_"}, tasks=ik)).warnings
        got = [w for w in warnings if w.startswith(f"{ik}: its time_range 0.6-1 s is not applied")]
        assert len(got) == n, warnings


def test_external_forces_whose_columns_carry_the_side_in_their_names(tmp_path, plain):
    # Rajagopal's grf_walk.xml: ground_force_r_v, ground_force_r_p, ground_torque_r_ (no common prefix)
    text = GRF.read_text().replace("ground_force_v", "ground_force_r_v").replace("ground_force_p", "ground_force_r_p") \
        .replace("ground_torque_", "ground_torque_r_")
    (tmp_path / GRF.name).write_text(text)
    loads = tmp_path / "side.xml"
    loads.write_text(EXTERNAL.format(frame="ground", torque="ground_torque_r_", data=GRF.name)
                     .replace("ground_force_v<", "ground_force_r_v<").replace("ground_force_p<", "ground_force_r_p<"))
    res = inverse_dynamics(LEG, Trial(TRC, grf=loads))
    assert np.array_equal(res.loads["ankle_angle_r_moment"], plain.loads["ankle_angle_r_moment"])
    assert any("plates 'calcn_r_' on calcn_r" in line for line in res.report)


def _force(name: str, body: str, stems: tuple[str, str, str]) -> str:
    return (f'<ExternalForce name="{name}"><applied_to_body>{body}</applied_to_body><force_expressed_in_body>ground'
            "</force_expressed_in_body><point_expressed_in_body>ground</point_expressed_in_body>"
            f"<force_identifier>{stems[0]}</force_identifier><point_identifier>{stems[1]}</point_identifier>"
            f"<torque_identifier>{stems[2]}</torque_identifier></ExternalForce>")


def test_an_external_loads_file_with_two_plates_on_one_foot_sums_them_as_opensim(tmp_path):
    # an overground walk's ExternalLoads: the right foot on one plate, a stride later on another (two ExternalForces
    # on calcn_r, which OpenSim sums); before: refused, "two external forces act on 'calcn_r'". Hamner's right plate
    # split at 0.9 s, between the right stances (0.39-0.67 s, 1.10 s-end), into two plates, the second's columns
    # named without a common prefix: the loads are the unsplit plate's (the filter is linear)
    table = read_sto(DATA / "hamner_running_whole_grf.mot")
    late = table.t >= 0.9
    names, cols = list(table.names), [table.values]
    for stem, new in (("ground_force_v", "late_force_v"), ("ground_force_p", "late_point_"),
                      ("ground_torque_", "late_torque_")):
        for axis in "xyz":
            v = table.column(f"{stem}{axis}")
            cols.append(np.where(late, v, 0.0)[:, None])
            if stem != "ground_force_p":  # the first plate's centre of pressure kept where it is unloaded
                cols[0][late, names.index(f"{stem}{axis}")] = 0.0
            names.append(f"{new}{axis}")
    lines = ["name split", f"datacolumns {len(names) + 1}", f"datarows {table.t.size}", "endheader",
             "\t".join(["time", *names])]
    values = np.hstack(cols)
    lines += ["\t".join(repr(float(x)) for x in (t, *row)) for t, row in zip(table.t, values, strict=True)]
    (tmp_path / "split.mot").write_text("\n".join(lines) + "\n")
    loads = tmp_path / "loads.xml"
    loads.write_text('<?xml version="1.0" encoding="UTF-8" ?><OpenSimDocument Version="30516"><ExternalLoads '
                     'name="loads"><objects>'
                     + _force("r1", "calcn_r", ("ground_force_v", "ground_force_p", "ground_torque_"))
                     + _force("l", "calcn_l", ("1_ground_force_v", "1_ground_force_p", "1_ground_torque_"))
                     + _force("r2", "calcn_r", ("late_force_v", "late_point_", "late_torque_"))
                     + "</objects><datafile>split.mot</datafile></ExternalLoads></OpenSimDocument>")
    model, markers = DATA / "hamner_subject02_planar.osim", DATA / "hamner_running_whole.trc"
    fit = Fit(max_misfit=0.2)
    split = inverse_dynamics(model, Trial(markers, grf=loads), fit=fit)
    whole = inverse_dynamics(model, Trial(markers, grf=DATA / "hamner_running_whole_grf.mot",
                                          plates={"calcn_r": "ground_", "calcn_l": "1_ground_"}), fit=fit)
    for name in ("ankle_angle_r_moment", "knee_angle_r_moment", "hip_flexion_r_moment", "root.fy"):
        peak = np.abs(whole.loads[name]).max()
        assert np.abs(split.loads[name] - whole.loads[name]).max() < 1e-9 * peak, name  # rounding in the sum
    assert any("'calcn_r_2_' on calcn_r" in line for line in split.report), split.report


def _clamped_knee(tmp_path, upper: float) -> Path:
    """The leg with its knee's range [-2.0944, upper] rad, clamped (the file's other coordinates as they are)."""
    text = LEG.read_text()
    start = text.index('<Coordinate name="knee_angle_r">')
    end = text.index("</Coordinate>", start)
    block = text[start:end]
    new = block.replace(block[block.index("<range>"):block.index("</range>")], f"<range>-2.0944 {upper!r}")
    new = new.replace("<clamped>false</clamped>", "<clamped>true</clamped>")
    path = tmp_path / "clamped.osim"
    path.write_text(text[:start] + new + text[end:])
    return path


def test_a_clamped_coordinate_is_held_in_its_range_at_the_bounded_least_squares(tmp_path):
    """OpenSim's IK keeps a clamped coordinate in its range; so does casflex's fit. The knee's range cut at the
    median of the stride's knee angle: the knee stays in it, is held at the limit where the unbounded fit
    left it, and each such frame is the bounded least-squares minimum that scipy's trust-region reflective
    solver finds from the same data (an independent algorithm)."""
    from scipy.optimize import least_squares

    from casflex.inverse.fit import coordinate_bounds
    from casflex.scene.coordinates import to_lab
    from casflex.scene.from_osim import scene_from_osim

    scene = scene_from_osim(LEG).scene
    knee = next(c for c in scene.coordinates if c.name == "knee_angle_r")
    unfiltered = inverse_dynamics(LEG, Trial(TRC, grf=GRF, plates={"calcn_r": "ground_"}),
                                  filter=Filter(cutoff=None))  # the fit's z
    free = to_lab(scene, knee, unfiltered.z[:, unfiltered.coordinate_names.index(knee.scene_coordinate())])
    upper = float(np.median(free))
    res = inverse_dynamics(_clamped_knee(tmp_path, upper), Trial(TRC, grf=GRF, plates={"calcn_r": "ground_"}),
                           filter=Filter(cutoff=None))
    held = to_lab(scene, knee, res.z[:, res.coordinate_names.index(knee.scene_coordinate())])
    assert held.max() <= upper + 1e-12  # projected on the limit: at it to rounding, never beyond
    at = held >= upper - 1e-12
    assert at.sum() > 0.3 * at.size and any(line.startswith("held at a limit of its range (frames): knee_angle_r in")
                                            for line in res.report)
    assert np.array_equal(at[np.abs(free - upper) > 0.05], (free > upper)[np.abs(free - upper) > 0.05])
    # one frame held at the limit: the fit's z against scipy's bounded minimiser on the same residuals
    from casflex.inverse.inputs import inverse_model
    from casflex.inverse.tree import kinematic_tree
    from casflex.lab import read_trc
    from casflex.scene.from_osim import scene_from_osim as read

    tree = kinematic_tree(inverse_model(read(_clamped_knee(tmp_path, upper)).scene))
    lo, hi = coordinate_bounds(tree)
    i = int(np.flatnonzero(at)[len(np.flatnonzero(at)) // 2])
    trc = read_trc(TRC)
    y = np.concatenate([trc.marker(m.label)[i, :2] for m in tree.model.scene.markers])
    seen = np.isfinite(y)
    z = res.z[i, [res.coordinate_names.index(n) for n in tree.names]]
    fit = least_squares(lambda v: (np.array(tree.marker_fit(v)[0]).ravel() - y)[seen], np.clip(z + 0.02, lo, hi),
                        jac=lambda v: np.array(tree.marker_fit(v)[1])[seen], bounds=(lo, hi), xtol=1e-15,
                        ftol=1e-15, gtol=1e-15)
    # both converged to ~1e-10 (casflex's step) on a well-conditioned problem: 1e-7 rad or m is a wide margin
    np.testing.assert_allclose(z, fit.x, rtol=0, atol=1e-7)


def test_a_range_too_narrow_for_the_trial_is_named_in_the_misfit_refusal(tmp_path):
    """The knee clamped below -1.5 rad (the stride's knee is straighter): the fit holds it there, the markers
    end far off, and the refusal names the held coordinate before the usual causes."""
    with pytest.raises(ValueError, match=r"knee_angle_r held at a limit of its range \(the model's clamped range: "
                                         r"widen it, or unclamp it\)"):
        inverse_dynamics(_clamped_knee(tmp_path, -1.5), Trial(TRC, grf=GRF, plates={"calcn_r": "ground_"}),
                         fit=Fit(max_misfit=0.03))
