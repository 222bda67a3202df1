"""Force plates that contradict the body are refused, naming the file, the plate and what was seen
(casflex.lab.plate_checks through casflex.inverse: ``casflex inverse`` and the Python API a study's trials call).

Each bad file is the Hamner stride's plate table (or the walking2 C3D excerpt) with one thing changed; each of
these gave loads with exit status 0 before: a vertical column negated, a -300 N offset through the swing, a C3D
plate's corners in mirrored order, one plate given to two nodes (on the command line or in an ExternalLoads
file), a centre of pressure half a metre from the foot, forces in kN, a one-sample spike of 11.6 kN. The
repo's real trials pass every check.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

from casflex.cli import main

sys.path.insert(0, str(Path(__file__).parent))

LAB = Path(__file__).parent / "data" / "lab"
TRC, GRF = LAB / "hamner_running_stride.trc", LAB / "hamner_running_stride_grf.mot"
BASE = ["inverse", "hamner_leg", "--root", "pelvis", "--cutoff", "10", "--quiet", "--data", TRC]
VY, PX = 2, 4  # the stride table's columns (time first): ground_force_vy, ground_force_px


def _mot(tmp_path: Path, edit, name: str = "grf.mot") -> Path:
    """A copy of the stride's plate table with ``edit(values)`` applied to its rows (n, 10: time first)."""
    lines = GRF.read_text().splitlines()
    end = lines.index("endheader") + 2
    values = np.array([[float(v) for v in ln.split("\t")] for ln in lines[end:] if ln.strip()])
    edit(values)
    path = tmp_path / name
    path.write_text("\n".join(lines[:end] + ["\t".join(repr(float(v)) for v in r) for r in values]) + "\n")
    return path


def _refused(argv: list, capsys, match: str, out: Path | None = None) -> str:
    """The command's one line of refusal (exit 2, nothing written), which must match ``match``."""
    code = main([str(a) for a in argv] + (["--out", str(out)] if out else []))
    _, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("casflex: error: "), (code, err)
    assert re.search(match, lines[0]), lines[0]
    assert out is None or not out.exists()
    return lines[0]


def test_a_vertical_column_negated_is_refused(tmp_path, capsys):
    def flip(v):
        v[:, VY] *= -1

    line = _refused(
        [*BASE, "--loads", _mot(tmp_path, flip), "--plate", "ankle=ground_"],
        capsys,
        r"grf.mot: plate 'ground_': its vertical force pulls the foot down: -1455 N at t = 0.517 s",
        tmp_path / "loads.csv",
    )
    assert "its largest upward force 0 N" in line and "a sign flipped" in line


def test_an_offset_of_minus_300_n_through_the_swing_is_refused(tmp_path, capsys):
    def offset(v):
        v[:, VY] -= 300.0

    line = _refused(
        [*BASE, "--loads", _mot(tmp_path, offset), "--plate", "ankle=ground_"],
        capsys,
        r"pulls the foot down: -300 N at t = 0.683 s, below -115 N at 68 % of its samples",
    )
    assert "largest upward force 1155 N" in line and "an offset not zeroed" in line


def test_a_c3d_plate_with_its_corners_in_mirrored_order_is_refused(tmp_path):
    """ezc3d turns the plate's forces by its corners: numbered the other way round, the plate's normal points
    down (-Z) and its vertical force with it; the reader keeps what the file says, the body refuses it."""
    ezc3d = pytest.importorskip("ezc3d")
    from lab_scenes import C3D, PLANE, walking2_leg

    from casflex.inverse import Trial, inverse_dynamics
    from casflex.scene import loads_scene

    c = ezc3d.c3d(str(C3D))
    corners = np.array(c["parameters"]["FORCE_PLATFORM"]["CORNERS"]["value"])
    corners[:, :, 0] = corners[:, ::-1, 0]  # plate 1's corners 4, 3, 2, 1
    c["parameters"]["FORCE_PLATFORM"]["CORNERS"]["value"] = corners
    path = tmp_path / "mirrored.c3d"
    c.write(str(path))
    leg = loads_scene(walking2_leg())
    match = (
        r"mirrored.c3d: plate 'ground_': its vertical force pulls the foot down: -951 N at t = 2.795 s.*"
        r"its corners give it the upward normal -Z: numbered in mirrored order\?"
    )
    with pytest.raises(ValueError, match=match):
        inverse_dynamics(leg, Trial(str(path), grf=str(path), plates={"ankle": "ground_"}, plane=PLANE))


def test_one_plate_given_to_two_nodes_is_refused(tmp_path, capsys):
    _refused(
        [*BASE, "--loads", GRF, "--plate", "ankle=ground_", "--plate", "knee=ground_"],
        capsys,
        r"plates: .*hamner_running_stride_grf.mot: plate 'ground_' is given to both 'ankle' and 'knee': its "
        "load would be counted twice",
    )


def test_one_plate_on_two_bodies_in_an_external_loads_file_is_refused(tmp_path):
    from casflex.inverse import Trial, inverse_dynamics

    force = """<ExternalForce name="{side}"><applied_to_body>{body}</applied_to_body>
<force_expressed_in_body>ground</force_expressed_in_body><point_expressed_in_body>ground</point_expressed_in_body>
<force_identifier>ground_force_v</force_identifier><point_identifier>ground_force_p</point_identifier>
<torque_identifier>ground_torque_</torque_identifier></ExternalForce>"""
    loads = tmp_path / "loads.xml"
    loads.write_text(
        f'<?xml version="1.0"?><OpenSimDocument><ExternalLoads name="loads"><objects>'
        f"{force.format(side='right', body='calcn_r')}{force.format(side='left', body='talus_r')}"
        f"</objects><datafile>{GRF}</datafile></ExternalLoads></OpenSimDocument>"
    )
    with pytest.raises(
        ValueError,
        match=r"loads.xml: the external forces on 'calcn_r' and 'talus_r' both take the "
        r"columns 'ground_force_v': one plate's load would be counted twice",
    ):
        inverse_dynamics(LAB / "hamner_subject02_leg.osim", Trial(TRC, grf=loads))


def test_a_centre_of_pressure_half_a_metre_from_its_foot_is_refused(tmp_path, capsys):
    """The stride's centre of pressure moved 0.5 m forward (a plate's origin wrong): its force passes 0.61 m
    from the ankle; as recorded, 0.11 m (median over the stance), the other foot's plate 0.54 m (walking2)."""

    def shift(v):
        v[:, PX] += 0.5

    line = _refused(
        [*BASE, "--loads", _mot(tmp_path, shift), "--plate", "ankle=ground_"],
        capsys,
        r"grf.mot: plate 'ground_': its force passes 0.6\d m from 'ankle' over its stance",
        tmp_path / "loads.csv",
    )
    assert "(the limit is 0.4 m)" in line


def test_forces_in_kn_are_refused(tmp_path, capsys):
    def kilo(v):
        v[:, 1:4] /= 1e3
        v[:, 7:10] /= 1e3

    line = _refused(
        [*BASE, "--loads", _mot(tmp_path, kilo), "--plate", "ankle=ground_"],
        capsys,
        r"grf.mot: plate 'ground_': its vertical force peaks at 1.45 N \(t = 0.517 s\) over its whole "
        r"record, 0.64 % of the model's weight \(227 N",
    )
    assert "forces in kN read as N" in line


def test_a_window_the_plate_carries_no_load_in_is_said_not_refused(tmp_path, capsys):
    """The swing of the stride (0.75..1.05 s): the plate's load is zero there, as computed; the line says so."""
    code = main(
        [str(a) for a in [*BASE, "--loads", GRF, "--plate", "ankle=ground_", "--t-start", "0.75", "--t-end", "1.05"]]
    )
    _, err = capsys.readouterr()
    assert code == 0, err
    assert "plate 'ground_': no load in the window 0.75..1.05 s (its vertical force at most 0 N)" in err


def test_a_one_sample_spike_of_11_6_kn_is_refused_naming_its_time(tmp_path, capsys):
    def spike(v):
        v[9, VY] = 11600.0  # t = 0.55 s, mid-stance (1306 N before)

    _refused(
        [*BASE, "--loads", _mot(tmp_path, spike), "--plate", "ankle=ground_"],
        capsys,
        r"grf.mot: plate 'ground_': a single sample of 1.16e\+04 N at t = 0.55 s stands 1.0\d*e\+04 N above "
        r"both its neighbours' \(1455 and 1306 N, 0.017 s apart\)",
    )


def test_the_repo_s_real_trials_pass_every_plate_check():
    """Hamner's running (the stride on the leg, both plates of the whole trial on the planar body: peaks of 2.25
    body weights, an impact peak at 60 Hz) and walking2.c3d's right foot at 2000 Hz: no refusal, no warning."""
    pytest.importorskip("ezc3d")
    from lab_scenes import C3D, PLANE, walking2_leg

    from casflex.inverse import Filter, Trial, inverse_dynamics
    from casflex.scene import loads_scene

    runs = [
        ("hamner_leg", TRC, GRF, {"ankle": "ground_"}, {"root": "pelvis"}),
        (
            LAB / "hamner_subject02_planar.osim",
            LAB / "hamner_running_whole.trc",
            LAB / "hamner_running_whole_grf.mot",
            {"calcn_r": "ground_", "calcn_l": "1_ground_"},
            {"tasks": LAB / "hamner_tasks_ik.xml"},
        ),
        (loads_scene(walking2_leg()), C3D, C3D, {"ankle": "ground_"}, {"plane": PLANE}),
    ]
    for scene, markers, grf, plates, kw in runs:
        res = inverse_dynamics(scene, Trial(str(markers), grf=str(grf), plates=plates, **kw), filter=Filter(10))
        assert not [w for w in res.warnings if "plate '" in w], res.warnings


def test_a_filtered_record_s_ringing_below_zero_is_no_pull(tmp_path, capsys):
    """A record filtered before export rings below zero after the stance (the zero-lag Butterworth's step
    response: 3.4 % of the jump): -110 N after the stride's 1455 N peak is within a tenth of it, not refused."""

    def ring(v):
        v[17:20, VY] = [-110.0, -60.0, -20.0]  # t = 0.683..0.717 s, just after toe-off

    code = main([str(a) for a in [*BASE, "--loads", _mot(tmp_path, ring), "--plate", "ankle=ground_"]])
    _, err = capsys.readouterr()
    assert code == 0 and "error" not in err, err


def test_a_sample_dropped_to_zero_mid_stance_is_refused_naming_its_time(tmp_path, capsys):
    def dropped(v):
        v[7, 1:4] = 0.0  # t = 0.517 s, the stance's peak (1455 N): a lost sample written as 0

    _refused(
        [*BASE, "--loads", _mot(tmp_path, dropped), "--plate", "ankle=ground_"],
        capsys,
        r"grf.mot: plate 'ground_': a single sample of 0 N at t = 0.517 s stands 1412 N below both its "
        r"neighbours' \(1412 and 1455 N.*the limit 0.75\): no foot unloads and reloads a plate so in one sample",
    )


def test_a_plate_given_to_the_knee_is_refused_naming_the_foot(tmp_path, capsys):
    """The knee stands over the foot (its line of force passes 0.1 m from it): only its height tells it, 0.5 m
    above the plate's surface; the ankle, 0.07 m (median over the stance), is named instead."""
    line = _refused(
        [*BASE, "--loads", GRF, "--plate", "knee=ground_"],
        capsys,
        r"hamner_running_stride_grf.mot: plate 'ground_': it is applied to 'knee', whose node lies 0.4\d m above "
        r"the plate's surface over its stance",
        tmp_path / "loads.csv",
    )
    assert "within 0.25 m of the floor" in line and "the nodes near its centre of pressure are 'ankle' (0.07 m" in line


MUSCLES = Path(__file__).parent / "data" / "muscles"
HAMNER_IK = MUSCLES / "hamner_run_ik.mot"  # OpenSim's IK of Hamner's run on the planar model with its muscles
WHOLE_GRF = LAB / "hamner_running_whole_grf.mot"


def _external_loads(tmp_path: Path, right: str, left: str) -> Path:
    """An OpenSim ExternalLoads file applying the whole run's plates to the bodies ``right`` and ``left``."""
    force = """<ExternalForce name="{body}"><applied_to_body>{body}</applied_to_body>
<force_expressed_in_body>ground</force_expressed_in_body><point_expressed_in_body>ground</point_expressed_in_body>
<force_identifier>{p}ground_force_v</force_identifier><point_identifier>{p}ground_force_p</point_identifier>
<torque_identifier>{p}ground_torque_</torque_identifier></ExternalForce>"""
    loads = tmp_path / "loads.xml"
    loads.write_text(
        f'<?xml version="1.0"?><OpenSimDocument><ExternalLoads name="loads"><objects>'
        f"{force.format(body=right, p='')}{force.format(body=left, p='1_')}"
        f"</objects><datafile>{WHOLE_GRF}</datafile></ExternalLoads></OpenSimDocument>"
    )
    return loads


def test_an_external_loads_file_applying_the_plate_to_the_femur_is_refused_by_casflex_muscles(tmp_path, capsys):
    """applied_to_body femur_r: the hip 0.88 m above the plate (it stands over the foot: 0.02 m across the
    floor); casflex muscles gave exit 0 with the hip contact force at 4.7 body weights for 9.4 (on calcn_r)."""
    model = MUSCLES / "hamner_subject02_planar_muscles.osim"
    line = _refused(
        ["muscles", model, "--coordinates", HAMNER_IK, "--loads", _external_loads(tmp_path, "femur_r", "calcn_l"),
         "--actuators", MUSCLES / "hamner_reserve_actuators.xml", "--joints", "hip_r", "--quiet"],
        capsys,
        r"hamner_running_whole_grf.mot: plate 'ground_': it is applied to 'femur_r', whose node lies 0.88 m above "
        r"the plate's surface over its stance \(median of 17 samples at t = 0.43\d*..1.2 s; 0.8\d..0.9\d m\)",
        tmp_path / "out",
    )
    assert "an ExternalLoads file's applied_to_body" in line
    assert "'toes_r' (0.01 m high)" in line and "'calcn_r' (0.0" in line  # the right foot's nodes named


def test_a_plate_on_the_toes_or_the_heel_is_taken():
    """The toes (their node at the metatarsophalangeal joint) bear a plate as the heel does: 0.006-0.014 m and
    0.026-0.040 m above the plate's surface (medians over the stances of Hamner's run), far under the limit."""
    from casflex.inverse import Filter, Trial, inverse_dynamics

    model = MUSCLES / "hamner_subject02_planar_muscles.osim"
    moments = []
    for foot in ("toes", "calcn"):
        trial = Trial(coordinates=str(HAMNER_IK), grf=str(WHOLE_GRF),
                      plates={f"{foot}_r": "ground_", f"{foot}_l": "1_ground_"})
        res = inverse_dynamics(model, trial, filter=Filter(10))
        moments.append(res.loads["knee_angle_r_moment"])
    # the plate's moment about the origin is moved exactly to either node: the same knee moment to round-off
    assert np.abs(moments[0] - moments[1]).max() < 1e-9 * np.abs(moments[1]).max()


def test_a_surface_the_table_writes_half_a_metre_low_refuses_nothing(tmp_path, capsys):
    """A plate in a stair's step whose centres of pressure a table writes at the floor's height: the ankle lies
    0.57 m above that surface, but no node of the leg lies lower near the line of force; taken (a knee given the
    plate is still refused: the ankle lies under it)."""

    def low(v):
        v[:, PX + 1] -= 0.5  # ground_force_py

    code = main([str(a) for a in [*BASE, "--loads", _mot(tmp_path, low), "--plate", "ankle=ground_"]])
    _, err = capsys.readouterr()
    assert code == 0 and "error" not in err, err
    _refused([*BASE, "--loads", _mot(tmp_path, low), "--plate", "knee=ground_"], capsys,
             r"it is applied to 'knee', whose node lies 0.9\d m above the plate's surface")


def test_a_plate_whose_force_along_the_floor_has_its_sign_flipped_is_refused():
    """The Rajagopal walk (overground, 1.23 m/s) with the right plate's ground_force_vx negated: exit 0 with every
    moment wrong (the right hip's off by up to 290 N m on Hamner's; here the stance propels then brakes). Refused,
    naming the plate and the stance; the walk as recorded brakes (-0.086 W over each stance's first half) then
    propels (+0.079 W): taken. Hamner's run (on a treadmill: the body travels at 0.1 m/s) is not checked."""
    from casflex.inverse import Trial, inverse_dynamics
    from casflex.lab import LabTable, read_sto, read_trc

    grf = read_sto(MUSCLES / "rajagopal_walk_grf.mot")
    kinds = ("force_vx", "force_vy", "force_vz", "force_px", "force_py", "force_pz", "torque_x", "torque_y", "torque_z")
    names = [f"{p}{k}" for p in ("ground_", "1_ground_") for k in kinds]
    side = {s: {k: "ground_" + k.replace("force_", f"force_{s}_").replace("torque_", f"torque_{s}_") for k in kinds}
            for s in "rl"}  # the walk's columns, ground_force_r_vx ...: one a foot
    values = np.column_stack([grf.column(side[s][k]) for s in "rl" for k in kinds])
    lab = read_trc(MUSCLES / "rajagopal_walk.trc")
    plates = {"calcn_r": "ground_", "calcn_l": "1_ground_"}
    tasks = str(MUSCLES / "rajagopal_walk_ik_tasks.xml")
    model = MUSCLES / "rajagopal_walk_planar_muscles.osim"
    inverse_dynamics(model, Trial(lab, grf=LabTable(grf.t, tuple(names), values, source="walk"), plates=plates,
                                  tasks=tasks))
    values[:, 0] *= -1
    with pytest.raises(ValueError, match=r"walk: plate 'ground_': over its stance at t = 0.26..1.02 s its force along "
                                         r"the floor pushes the body on \(72 N .* then holds it back \(-66 N .* the "
                                         r"body travelling at 1.23 m/s: .* sign is flipped"):
        inverse_dynamics(model, Trial(lab, grf=LabTable(grf.t, tuple(names), values, source="walk"), plates=plates,
                                      tasks=tasks))


def test_a_treadmill_s_single_plate_given_to_one_foot_is_refused():
    """The Rajagopal walk's two feet's ground reactions on one plate (a treadmill's), given to calcn_r by name: the
    median line of force passed 0.16 m from it (under the 0.4 m limit) and the left foot's load went to the right
    foot, exit 0. Refused: the line passes farther than 0.4 m at 20 % of the stance's samples (a foot alone: none;
    at most 0.27 m on the repo's trials)."""
    sys.path.insert(0, str(Path(__file__).parent))
    from test_inverse_contacts import _wrench

    from casflex.inverse import Trial, inverse_dynamics
    from casflex.lab import LabTable, read_sto, read_trc

    grf = read_sto(MUSCLES / "rajagopal_walk_grf.mot")

    def cols(kind: str) -> np.ndarray:
        return np.column_stack([grf.column(kind.format(a)) for a in "xyz"])

    feet = [(cols(f"ground_force_{s}_v{{}}"), cols(f"ground_force_{s}_p{{}}"), cols(f"ground_torque_{s}_{{}}"))
            for s in "rl"]
    kinds = ("force_vx", "force_vy", "force_vz", "force_px", "force_py", "force_pz", "torque_x", "torque_y", "torque_z")
    one = LabTable(grf.t, tuple(f"ground_{k}" for k in kinds), _wrench(feet), source="one")
    with pytest.raises(ValueError, match=r"^one: plate 'ground_': its force passes more than 0.4 m from 'calcn_r' at "
                                         r"20 % of its stance's 144 samples \(up to 0.59 m at t = 0.99 s; median 0.16"):
        inverse_dynamics(MUSCLES / "rajagopal_walk_planar_muscles.osim",
                         Trial(read_trc(MUSCLES / "rajagopal_walk.trc"), grf=one, plates={"calcn_r": "ground_"},
                               tasks=str(MUSCLES / "rajagopal_walk_ik_tasks.xml")))


def test_a_centre_of_pressure_above_the_foot_is_refused(tmp_path, capsys):
    """The stride's COP columns py and pz swapped (a Y-up file whose vertical coordinate now holds the sideways
    position, here 0.18-0.20 m: a plate to the side of the lab's origin): every moment 39 N m off with exit 0. A
    centre of pressure lies on the surface the foot stands on: as recorded 0.001-0.051 m below the foot's lowest
    marker (medians over the stances of the repo's trials), here 0.14 m above it: refused. A COP metres below (mm
    read as m, -5 m) is refused by the line of force (it passes metres from the foot); half a metre below (a stair's
    plate written at the floor's height) is taken (test_a_surface_the_table_writes_half_a_metre_low_refuses_nothing)."""

    def swap(v):
        v[:, [PX + 1, PX + 2]] = np.column_stack([v[:, PX + 2] + 0.3, v[:, PX + 1]])

    _refused([*BASE, "--loads", _mot(tmp_path, swap), "--plate", "ankle=ground_"], capsys,
             r"grf.mot: plate 'ground_': its centre of pressure lies 0.14 m above the lowest point of 'ankle' \(its "
             r"node and its markers\) over its stance at t = 0.433333..0.616667 s .*columns swapped",
             tmp_path / "loads.csv")

    def deep(v):
        v[:, PX + 1] -= 5.0

    _refused([*BASE, "--loads", _mot(tmp_path, deep), "--plate", "ankle=ground_"], capsys,
             r"grf.mot: plate 'ground_': its force passes \d+\.\d\d m from 'ankle'")


def test_a_fore_aft_force_swapped_with_the_sideways_one_is_said(tmp_path):
    """The stride's vx and vz swapped (a Y-up file's fore-aft and sideways forces): the planar model drops the force
    across its plane, here the fore-aft one: the moments off by up to 204 N m (the hip's) with exit 0. Over a straight
    stance the force across carries 0.07-0.55 of the fore-aft force's impulse (Hamner's run, walking2.c3d, the
    Rajagopal walk, biomechZoo's straight walks), swapped 1.8-14 times: said above 1 (a warning: a turn's step carries
    up to 3.2)."""
    from casflex.inverse import Filter, Trial, inverse_dynamics

    def swap(v):
        v[:, [VY - 1, VY + 1]] = v[:, [VY + 1, VY - 1]]

    res = inverse_dynamics("hamner_leg", Trial(str(TRC), grf=str(_mot(tmp_path, swap)), plates={"ankle": "ground_"},
                                               root="pelvis"), filter=Filter(10))
    said = [w for w in res.warnings if "across the model's plane" in w]
    assert len(said) == 1 and re.search(
        r"grf.mot: plate 'ground_': over its stance at t = 0.4..0.65 s its force across the model's plane carries "
        r"30.2 N s, more than its force along the floor \(12.3 N s; .*columns swapped", said[0]), said
    res = inverse_dynamics("hamner_leg", Trial(str(TRC), grf=str(GRF), plates={"ankle": "ground_"}, root="pelvis"),
                           filter=Filter(10))
    assert not [w for w in res.warnings if "across" in w], res.warnings
