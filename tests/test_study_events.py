"""Gait events (casflex.study.events): contacts on a force with known crossings, plates assigned to the feet of
Hamner's running trial as the pipeline's External_Loads.xml assigns them, the refusals, strides from the plates
and the heel markers, and the cycle normalisation."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

from casflex.lab import LabTable, read_sto, read_trc
from casflex.study.events import (
    _side,
    assign_plates,
    contacts,
    cycles,
    feet,
    foot_strikes,
    gait_cycles,
    marked_strikes,
    marker_strikes,
    normalise,
    plate_contacts,
)

LAB = Path(__file__).parent / "data" / "lab"
OSIM, TRC, GRF = (LAB / "hamner_subject02_planar.osim", LAB / "hamner_running_whole.trc",
                  LAB / "hamner_running_whole_grf.mot")
#: opensim-models 20a888b, Pipelines/Hamner/External_Loads.xml: ExternalForce externalforce_right applied_to_body
#: calcn_r, force_identifier ground_force_v; externalforce_left calcn_l, 1_ground_force_v.
EXTERNAL_LOADS = {"calcn_r": "ground_", "calcn_l": "1_ground_"}


@pytest.fixture(scope="module")
def hamner():
    import casflex

    return casflex.load_scene(OSIM), read_trc(TRC), read_sto(GRF)


def test_contacts_are_the_threshold_crossings_exactly():
    """A piecewise linear force with its corners on the samples: each crossing of 20 N is where the line
    crosses it; a 30 ms blip dropped; loaded at the start and at the end: strike, off None; NaN left out."""
    t = np.round(np.arange(0.0, 2.0 + 1e-9, 0.01), 12)
    corners = ([0.0, 0.1, 0.2, 0.5, 0.6, 0.8, 0.81, 0.83, 0.84, 1.3, 1.4, 2.0],
               [800.0, 800.0, 0.0, 0.0, 500.0, 500.0, 0.0, 0.0, 0.0, 0.0, 1000.0, 1000.0])
    fv = np.interp(t, *corners)
    fv[(t > 0.9) & (t < 0.93)] = 100.0  # a blip above 20 N: 0.91, 0.92 (20 ms between its crossings)
    fv[t == 0.7] = np.nan
    got = contacts(t, fv)
    want = [(None, 0.2 - 0.1 * 20 / 800), (0.5 + 0.1 * 20 / 500, 0.81 - 0.01 * 20 / 500), (1.3 + 0.1 * 20 / 1000, None)]
    assert [a is None for a, _ in got] == [a is None for a, _ in want]
    assert [b is None for _, b in got] == [b is None for _, b in want]
    flat = np.array([x for iv in got for x in iv if x is not None])
    assert np.abs(flat - [x for iv in want for x in iv if x is not None]).max() < 1e-12
    assert len(contacts(t, fv, min_duration=0.0)) == 4  # the blip kept when nothing is too short
    assert contacts(t, np.zeros_like(t)) == []
    with pytest.raises(ValueError, match="times must increase"):
        contacts(t[::-1], fv)


def test_the_feet_of_the_whole_body_are_the_distal_bodies_with_markers(hamner):
    scene, _, _ = hamner
    assert set(feet(scene)) == {"calcn_r", "calcn_l", "radius_r", "radius_l"}  # toes and hands carry none
    assert "R.Heel" in feet(scene)["calcn_r"]


def test_plates_go_to_the_feet_external_loads_names(hamner):
    """Both plates of Hamner's trial, from the data alone, under the feet OpenSim's pipeline applies them to;
    the contacts' times and the feet's distances (the other foot, the wrists: far or too high)."""
    scene, lab, grf = hamner
    plates, lines = assign_plates(scene, lab, grf, "X,Y")
    assert plates == EXTERNAL_LOADS
    assert lines[0].startswith("plate 'ground_' -> calcn_r: 2 contact(s) 0.390-0.665 s, 1.101-[end] s")
    assert lines[1].startswith("plate '1_ground_' -> calcn_l: 2 contact(s) [start]-0.327 s, 0.751-1.010 s")
    found = plate_contacts(scene, lab, grf, "X,Y")
    assert [(c.plate, c.foot) for c in found] == [("ground_", "calcn_r")] * 2 + [("1_ground_", "calcn_l")] * 2
    assert found[0].strike == pytest.approx(0.3897, abs=1e-4) and found[1].off is None
    assert found[2].strike is None and found[3].strike == pytest.approx(0.7510, abs=1e-4)
    for c in found:
        assert c.distance < 0.06 and c.height < 0.06
        assert all(o[1] > 0.15 or o[2] > 0.9 for o in c.others)  # the other foot or a wrist


def test_a_plate_far_from_every_foot_is_refused(hamner):
    scene, lab, grf = hamner
    values = grf.values.copy()
    values[:, grf.names.index("1_ground_force_px")] += 1.0  # the left plate's centre of pressure 1 m forward
    with pytest.raises(ValueError, match=r"plate '1_ground_', contact \[start\]-0.327 s: no foot within 0.3 m"):
        assign_plates(scene, lab, dataclasses.replace(grf, values=values), "X,Y")


def test_one_leg_takes_its_own_plate_and_refuses_the_other_foots():
    """The right leg alone (built-in hamner_leg): the left plate has no foot over it, named in one line; the
    right plate given alone goes to the leg's foot."""
    import casflex

    leg, lab, grf = casflex.load_scene("hamner_leg"), read_trc(TRC), read_sto(GRF)
    with pytest.raises(ValueError, match=r"plate '1_ground_'.*nearest: ankle, 0.17 m and 0.15 m"):
        assign_plates(leg, lab, grf)
    plates, _ = assign_plates(leg, TRC, GRF, prefixes=["ground_"])
    assert plates == {"ankle": "ground_"}


def _merged(grf) -> LabTable:
    """The two plates' samples merged into one plate both feet step on in turn (the runner's feet never share a
    moment on the ground)."""
    kinds = [n[len("ground_"):] for n in grf.names if n.startswith("ground_")]
    right = grf.column("ground_force_vy") > 0
    merged = np.column_stack([np.where(right, grf.column("ground_" + k), grf.column("1_ground_" + k)) for k in kinds])
    return LabTable(grf.t, tuple("ground_" + k for k in kinds), merged, source="merged")


def test_a_plate_under_both_feet_in_turn_has_no_node_per_trial_and_two_plates_under_one_foot_are_both_its(hamner):
    """One plate both feet step on: refused per trial in one line pointing to plates="auto", and plate_contacts
    gives the foot of each contact; the right plate copied as a third plate: both under calcn_r (before: refused,
    "one plate per node")."""
    scene, lab, grf = hamner
    kinds = [n[len("ground_"):] for n in grf.names if n.startswith("ground_")]
    one = _merged(grf)
    with pytest.raises(ValueError, match=r"plate 'ground_' is stepped on by calcn_l \(\[start\]-0.327 s, 0.751-1.010 "
                                         r"s\) and calcn_r \(0.390-0.665 s, 1.101-\[end\] s\): .*plates=\"auto\""):
        assign_plates(scene, lab, one)
    assert [c.foot for c in plate_contacts(scene, lab, one)] == ["calcn_l", "calcn_r", "calcn_l", "calcn_r"]
    three = LabTable(grf.t, grf.names + tuple("2_ground_" + k for k in kinds),
                     np.hstack([grf.values, np.column_stack([grf.column("ground_" + k) for k in kinds])]))
    plates, lines = assign_plates(scene, lab, three)
    assert plates == {"calcn_r": ["ground_", "2_ground_"], "calcn_l": "1_ground_"}
    assert len(lines) == 3


def test_a_plate_s_samples_are_shared_among_its_feet_halfway_across_each_unloaded_gap(hamner):
    from casflex.study.events import plate_shares

    scene, lab, grf = hamner
    found = plate_contacts(scene, lab, _merged(grf))
    shares = plate_shares(found)
    # contacts: calcn_l [start]-0.327, calcn_r 0.390-0.665, calcn_l 0.751-1.010, calcn_r 1.101-[end]
    (l_a, l_b), (r_a, r_b) = shares[("ground_", "calcn_l")], shares[("ground_", "calcn_r")]
    assert l_a[0] is None and r_b[1] is None
    assert l_a[1] == r_a[0] == pytest.approx(0.5 * (0.327 + 0.390), abs=1e-3)  # the contacts' 3 digits
    assert r_a[1] == l_b[0] == pytest.approx(0.5 * (0.665 + 0.751), abs=1e-3)
    assert l_b[1] == r_b[0] == pytest.approx(0.5 * (1.010 + 1.101), abs=1e-3)
    assert plate_shares(plate_contacts(scene, lab, grf)) == {("ground_", "calcn_r"): ((None, None),),
                                                               ("1_ground_", "calcn_l"): ((None, None),)}


def test_a_running_stride_from_the_plates_and_the_heel_markers(hamner):
    """The right stride 0.390-1.101 s (0.712 s) from the plates; the heels' lowest points -4 to +21 ms from the
    plates' strikes; the left foot's one plate strike gives no stride in the record, and the report says so."""
    scene, lab, grf = hamner
    found = plate_contacts(scene, lab, grf)
    strikes = foot_strikes(found)
    assert list(strikes) == ["calcn_r", "calcn_l"] and len(strikes["calcn_r"]) == 2 and len(strikes["calcn_l"]) == 1
    (t0, t1), = cycles(strikes["calcn_r"])
    assert t1 - t0 == pytest.approx(0.7118, abs=1e-4)
    heel = {"calcn_r": marker_strikes(lab.t, lab.marker("R.Heel")[:, 1]),
            "calcn_l": marker_strikes(lab.t, lab.marker("L.Heel")[:, 1])}
    assert len(heel["calcn_r"]) == 2 and len(heel["calcn_l"]) == 1
    lag = np.array(heel["calcn_r"] + heel["calcn_l"]) - np.array(strikes["calcn_r"] + strikes["calcn_l"])
    assert np.all(np.abs(lag) < 0.025), lag  # 1.5 frames at 60 Hz
    by, lines = gait_cycles(found, scene, lab, "X,Y")
    assert by == {"calcn_r": [(t0, t1)], "calcn_l": []}
    assert lines[1] == "calcn_l: 0 cycle(s) from L.Heel's strikes at 0.747 s (1 plate strike(s): 0.751 s)"
    assert cycles([1.0, 0.2, 3.4, 2.6], max_duration=1.0) == [(0.2, 1.0), (2.6, 3.4)]  # 1.0-2.6: one missed


def test_the_strikes_the_lab_marked_come_first(hamner):
    """Events marked in the file (a C3D's, LabMarkers.events) decide the cycles where a foot has two: the left
    foot's one plate strike gave none; marked strikes give its stride, and the right foot's marked ones replace
    its plates'. Sides from the feet's names (calcn_l) or, where the names say none, their markers' (LHEE)."""
    scene, lab, grf = hamner
    found = plate_contacts(scene, lab, grf)
    marked = dataclasses.replace(lab, events=(("Left", "Foot Strike", 0.30), ("Right", "Foot Strike", 0.40),
                                              ("Left", "Foot Off", 0.55), ("Left", "Foot Strike", 0.75),
                                              ("Right", "Foot Strike", 1.10), ("General", "Foot Strike", 0.9)))
    got = marked_strikes(marked, scene)  # every foot-like node's (the wrists too: no plate is under them)
    assert (got["calcn_r"], got["calcn_l"]) == ([0.40, 1.10], [0.30, 0.75])
    by, lines = gait_cycles(found, scene, marked, "X,Y")
    assert by == {"calcn_r": [(0.40, 1.10)], "calcn_l": [(0.30, 0.75)]}
    assert lines[1].startswith("calcn_l: 1 cycle(s) from the marked events' strikes at 0.300, 0.750 s")
    assert _side("foot", ("LHEE", "LTOE")) == "Left" and _side("foot", ("RHEE", "LTOE")) is None
    assert _side("r_foot", ()) == "Right" and _side("LeftFoot", ()) == "Left"


def test_a_c3d_s_events_are_read_on_its_markers_times(tmp_path):
    ezc3d = pytest.importorskip("ezc3d")
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = ("RHEE",)
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    c["data"]["points"] = np.ones((4, 1, 50))
    c.add_parameter("EVENT", "USED", [2])
    c.add_parameter("EVENT", "LABELS", ["Foot Strike", "Foot Off"])
    c.add_parameter("EVENT", "CONTEXTS", ["Right", "Right"])
    c.add_parameter("EVENT", "TIMES", np.array([[0.0, 1.0], [0.12, 0.05]]))  # (minutes, seconds)
    c.write(str(tmp_path / "events.c3d"))
    from casflex.lab import read_c3d

    lab = read_c3d(tmp_path / "events.c3d", plates=False)[0]
    assert lab.events == (("Right", "Foot Strike", pytest.approx(0.12)), ("Right", "Foot Off", pytest.approx(60.05)))
    assert lab.t[0] == 0.0


def test_normalise_is_exact_on_a_linear_signal():
    t = np.cumsum(np.r_[0.0, np.linspace(0.005, 0.02, 80)])  # uneven samples
    y = np.stack([3.0 + 2.0 * t, -t], axis=1)[:, :, None] * [1.0, 10.0]  # (n, 2, 2)
    t0, t1 = 0.1234, 0.9876
    out = normalise(t, y, t0, t1)
    s = np.linspace(t0, t1, 101)
    want = np.stack([3.0 + 2.0 * s, -s], axis=1)[:, :, None] * [1.0, 10.0]
    assert out.shape == (101, 2, 2) and np.abs(out - want).max() < 1e-12
    assert normalise(t, t, t[0], t[-1], n=11)[[0, -1]].tolist() == [t[0], t[-1]]
    with pytest.raises(ValueError, match="not within the signal's times"):
        normalise(t, y, t0, t[-1] + 0.01)


def test_the_c3d_walking_trials_right_plate_goes_to_the_right_foot():
    """walking2.c3d's excerpt (lab Z up, plane X,Z) with a right leg: plate 1 under its foot, its stance as the
    README gives it (2.674-3.244 s); plate 2 (the left foot's) refused, the right foot 0.49 m away across."""
    pytest.importorskip("ezc3d")
    from casflex.scene.io import loads_scene

    sys.path.insert(0, str(Path(__file__).parent))
    from lab_scenes import C3D, PLANE, walking2_leg

    leg = loads_scene(walking2_leg())
    (c,) = plate_contacts(leg, C3D, None, PLANE, ["ground_"])
    assert (c.foot, round(c.strike, 3), round(c.off, 3)) == ("ankle", 2.674, 3.244)
    with pytest.raises(ValueError, match=r"plate '1_ground_', contact \[start\]-2.751 s.*nearest: ankle, 0.49 m"):
        assign_plates(leg, C3D, None, PLANE)


def test_a_study_trial_s_plate_whose_force_pulls_is_refused_not_left_out():
    """A plate whose vertical column is negated has no contact above 20 N: the study left it out and the foot's
    stance went without its ground reaction (exit 0). It is refused, naming the plate and what was seen."""
    pytest.importorskip("ezc3d")

    from casflex.lab import read_c3d
    from casflex.scene.io import loads_scene

    sys.path.insert(0, str(Path(__file__).parent))
    from lab_scenes import C3D, PLANE, walking2_leg

    lab, table = read_c3d(C3D)
    values = table.values.copy()
    values[:, table.names.index("ground_force_vz")] *= -1
    flipped = dataclasses.replace(table, values=values)
    with pytest.raises(ValueError, match=r"walking2_excerpt.c3d: plate 'ground_': its vertical force pulls the foot "
                                         r"down: -951 N at t = 2.795 s"):
        assign_plates(loads_scene(walking2_leg()), lab, flipped, PLANE)


def test_a_cycle_is_clean_only_where_its_stance_stands_wholly_on_the_foot_s_plate():
    from casflex.study.events import Contact, clean_cycles

    def c(plate, a, b, foot="calcn_r"):
        return Contact(plate, a, b, foot, 0.05, 0.04)

    spans = [(0.39, 1.10)]
    good = [c("ground_", 0.39, 0.665)]
    assert clean_cycles(good, "calcn_r", spans, "ground_") == [(True, "stance on 'ground_' 0.390-0.665 s")]
    cases = {  # what makes it unclean -> what the reason says
        "off every plate": ([], "the foot off every plate"),
        "heel strike 60 ms before the plate's": ([c("ground_", 0.45, 0.665)], "0.390 s (its contact 0.450-0.665 s"),
        "on a plate not applied to it": ([c("1_ground_", 0.39, 0.665)],
                                         "on '1_ground_' 0.390-0.665 s during its stance 0.390-0.665 s: not applied"),
        "on two plates": ([*good, c("1_ground_", 0.5, 0.6)], "calcn_r on '1_ground_' 0.500-0.600 s during"),
        "the other foot on its plate": ([*good, c("ground_", 0.6, 0.9, "calcn_l")], "calcn_l on 'ground_'"),
        "still loaded at the cycle's end": ([c("ground_", 0.39, None)], "does not end within the cycle"),
    }
    for what, (found, why) in cases.items():
        (ok, said), = clean_cycles(found, "calcn_r", spans, "ground_")
        assert not ok and why in said, (what, said)
    assert clean_cycles(good, "calcn_r", spans, None)[0][0] is False  # no plate applied to the foot


def test_a_cycle_between_two_plate_strikes_with_a_stride_off_the_plates_between_is_left_out(hamner):
    """Hamner's right stride (0.390-1.101 s) three times over, its stance on a plate in the first and the third only:
    the plate strikes 0.390 and 1.823 s made one 1.43 s "cycle" of two strides, clean (its stance on the plate) and
    normalised as one (exit 0). The heel marker strikes at 1.129 s inside it: it is left out, and the report says
    so; with the middle stance on a plate too, the two cycles are kept. The lab's marked strikes missing the middle
    one: left out alike."""
    scene, lab, grf = hamner
    (first, *_), (r0, r1) = plate_contacts(scene, lab, grf), (0.390, 1.101)
    period = round((r1 - r0) * 60) / 60  # 43 frames at 60 Hz: the stride's frames tiled end to end
    rows = np.flatnonzero((lab.t >= r0 - 1e-9) & (lab.t < r0 + period - 1e-9))
    shift = lab.xyz[rows[-1] + 1] - lab.xyz[rows[0]]  # the stride's advance, so that the markers run on
    xyz = np.concatenate([lab.xyz[rows] + k * np.nanmedian(shift, axis=0) * [1, 0, 1] for k in range(3)])
    t = np.concatenate([lab.t[rows] + k * period for k in range(3)])
    tiled = dataclasses.replace(lab, t=t, xyz=xyz)
    found = [first, dataclasses.replace(first, strike=first.strike + 2 * period, off=first.off + 2 * period)]
    by, lines = gait_cycles(found, scene, tiled, "X,Y")
    assert by["calcn_r"] == []  # before: [(0.390, 1.823)]
    assert lines[0] == ("calcn_r: 0 cycle(s) from the plates' strikes at 0.390, 1.823 s; 0.390-1.823 s left out: "
                        "R.Heel strikes at 1.129 s inside it (a stride off the plates)")
    three = [*found[:1], dataclasses.replace(first, strike=first.strike + period, off=first.off + period), found[1]]
    assert gait_cycles(three, scene, tiled, "X,Y")[0]["calcn_r"] == cycles([c.strike for c in three])
    marked = dataclasses.replace(tiled, events=(("Right", "Foot Strike", 0.39), ("Right", "Foot Strike", 1.823)))
    by, lines = gait_cycles(three, scene, marked, "X,Y")  # the middle strike not marked: left out likewise
    assert by["calcn_r"] == [] and lines[0].endswith("R.Heel strikes at 1.129 s inside it (a strike not marked)")


def test_a_stance_on_a_plate_s_edge_is_not_clean(hamner):
    """The right foot on the edge of its plate, its heel on the floor: the plate records a fifth of its load (a peak
    of 291 N, 0.45 of the body's weight, for 1455 N): the cycle was clean, its loads below the hip without four
    fifths of the ground reaction (exit 0). Not clean now, said; the recorded stance (2.25 W) is clean."""
    from casflex.lab.plate_checks import scene_mass
    from casflex.study.events import AUTO, clean_cycles

    scene, lab, grf = hamner
    weight = scene_mass(scene) * 9.80665
    values = grf.values.copy()
    for k in ("force_vx", "force_vy", "force_vz", "torque_x", "torque_y", "torque_z"):
        values[:, grf.names.index(f"ground_{k}")] *= 0.2
    edge = plate_contacts(scene, lab, dataclasses.replace(grf, values=values))
    spans = cycles(foot_strikes(edge)["calcn_r"])
    assert clean_cycles(edge, "calcn_r", spans, AUTO) == [(True, "stance on 'ground_' 0.403-0.649 s")]  # before
    (ok, why), = clean_cycles(edge, "calcn_r", spans, AUTO, weight=weight)
    assert not ok and why.startswith("its stance on 'ground_' 0.403-0.649 s peaks at 291 N, 0.45 of the body's weight")
    whole = plate_contacts(scene, lab, grf)
    assert clean_cycles(whole, "calcn_r", spans, "ground_", weight=weight)[0][0]
