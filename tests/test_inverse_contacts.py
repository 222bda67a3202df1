"""A node's ground reaction from different plates over a trial (casflex.inverse.contacts, plates="auto" and
{node: [prefixes]}): on Hamner's whole-body running trial, its two plates (right foot on ``ground_``, left on
``1_ground_``) rewritten so that one plate carries both feet in turn, the left foot lands on two plates in two
strides, or the right stance straddles two plates; each gives the loads of the original two plates, to round-off
(the shares partition each plate's samples and the filter is linear)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from casflex.lab import LabTable, read_sto, read_trc

LAB = Path(__file__).parent / "data" / "lab"
OSIM, TRC, GRF, TASKS = (LAB / "hamner_subject02_planar.osim", LAB / "hamner_running_whole.trc",
                         LAB / "hamner_running_whole_grf.mot", LAB / "hamner_tasks_ik.xml")
ORIGINAL = {"calcn_r": "ground_", "calcn_l": "1_ground_"}  # Pipelines/Hamner/External_Loads.xml's
KINDS = ("force_vx", "force_vy", "force_vz", "force_px", "force_py", "force_pz", "torque_x", "torque_y", "torque_z")
FORCES = ("force_vx", "force_vy", "force_vz", "torque_x", "torque_y", "torque_z")  # scaled by a share; p is not


def _table(grf: LabTable, plates: dict[str, np.ndarray], name: str) -> LabTable:
    names = tuple(f"{p}{k}" for p in plates for k in KINDS)
    return LabTable(grf.t, names, np.column_stack([plates[p] for p in plates]), source=name)


def _plate(grf: LabTable, prefix: str, share: np.ndarray | float = 1.0) -> np.ndarray:
    """(n, 9) the plate ``prefix``'s columns with its forces and free moments times ``share`` (n,)."""
    share = np.broadcast_to(np.asarray(share, dtype=float), grf.t.shape)
    return np.column_stack([grf.column(prefix + k) * (share if k in FORCES else 1.0) for k in KINDS])


@pytest.fixture(scope="module")
def hamner():
    from casflex import load_scene

    return load_scene(OSIM), read_trc(TRC), read_sto(GRF)


def _moments(scene, lab, grf, plates) -> dict[str, np.ndarray]:
    from casflex.inverse import Trial, inverse_dynamics

    res = inverse_dynamics(scene, Trial(lab, grf=grf, plates=plates, tasks=str(TASKS)))
    return {k: res.loads[k] for k in res.settings["moments"]} | {"root.fy": res.loads["root.fy"]}


@pytest.fixture(scope="module")
def original(hamner):
    scene, lab, grf = hamner
    return _moments(scene, lab, grf, ORIGINAL)


def _same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for k in a:  # round-off of the sums of the shares' filtered wrenches: 1e-9 of the moment's peak
        assert np.allclose(a[k], b[k], rtol=0, atol=1e-9 * max(1.0, np.abs(b[k]).max())), k


def test_one_plate_both_feet_step_on_in_turn_gives_the_two_plates_loads(hamner, original):
    # before: refused ("plate 'ground_' is stepped on by calcn_l ... and calcn_r ...: one node per plate")
    scene, lab, grf = hamner
    right = grf.column("ground_force_vy") > 0
    one = _table(grf, {"ground_": np.where(right[:, None], _plate(grf, "ground_"), _plate(grf, "1_ground_"))}, "one")
    _same(_moments(scene, lab, one, "auto"), original)
    from casflex.inverse import Trial, prepare

    inputs = prepare(scene, Trial(lab, grf=one, plates="auto", tasks=str(TASKS)))
    assert sorted((p.name, p.node) for p in inputs.plates) == [("ground_", "calcn_l"), ("ground_", "calcn_r")]
    assert inputs.settings["plates"] == {"calcn_l": "ground_", "calcn_r": "ground_"}
    said = [ln for ln in inputs.report if "(plates=\"auto\")" in ln]
    assert said == ["plate 'ground_' -> calcn_l (plates=\"auto\"): contact(s) start-0.327 s, 0.751-1.010 s",
                    "plate 'ground_' -> calcn_r (plates=\"auto\"): contact(s) 0.390-0.665 s, 1.101-end s"]


def test_a_foot_on_two_plates_in_two_strides(hamner, original):
    # the left foot's first contact (loaded at the start, to 0.327 s) on plate 2, its next (0.751-1.010 s) on plate 1
    scene, lab, grf = hamner
    early = (grf.t < 0.5).astype(float)
    two = _table(grf, {"ground_": _plate(grf, "ground_"), "1_ground_": _plate(grf, "1_ground_", 1 - early),
                       "2_ground_": _plate(grf, "1_ground_", early)}, "two")
    _same(_moments(scene, lab, two, "auto"), original)
    _same(_moments(scene, lab, two, {"calcn_r": "ground_", "calcn_l": ["1_ground_", "2_ground_"]}), original)


def test_a_stance_straddling_two_plates_is_their_sum(hamner, original):
    # the right stance (0.390-0.665 s) from the heel on plate 0 to the toes on plate 3: the force shared w, 1 - w
    # (w from 1 to 0 over the stance), the centre of pressure alike: the sum is the one plate's
    from casflex.study.events import AUTO, clean_cycles, cycles, foot_strikes, plate_contacts

    scene, lab, grf = hamner
    w = np.clip((0.665 - grf.t) / (0.665 - 0.39), 0.0, 1.0)
    straddle = _table(grf, {"ground_": _plate(grf, "ground_", w), "1_ground_": _plate(grf, "1_ground_"),
                            "3_ground_": _plate(grf, "ground_", 1 - w)}, "straddle")
    found = plate_contacts(scene, lab, straddle)
    r = [c for c in found if c.foot == "calcn_r"]
    # the heel's plate 0.390-0.6 s, the toes' from 0.40 s (and the next stance, from 1.101 s, on it alone)
    assert [c.plate for c in r] == ["ground_", "3_ground_", "3_ground_"] and r[0].strike < r[1].strike < r[0].off
    strikes = foot_strikes(found)["calcn_r"]
    assert strikes == [r[0].strike, r[2].strike]  # the straddling stance strikes once
    (ok, why), = clean_cycles(found, "calcn_r", cycles(strikes), AUTO)
    assert ok and why == f"stance on 'ground_' and '3_ground_' {r[0].strike:.3f}-{r[1].off:.3f} s"
    (ok, why), = clean_cycles(found, "calcn_r", cycles(strikes), "ground_")  # the toes' plate not applied
    assert not ok and "calcn_r on '3_ground_'" in why and why.endswith("not applied to it")
    _same(_moments(scene, lab, straddle, "auto"), original)
    _same(_moments(scene, lab, straddle, {"calcn_r": ["ground_", "3_ground_"], "calcn_l": "1_ground_"}), original)


def test_plates_auto_is_refused_with_coordinates_given_and_a_plate_on_two_nodes_still_is(hamner):
    from casflex.inverse import OptionRefused, Trial, prepare

    scene, lab, grf = hamner
    with pytest.raises(OptionRefused, match="plates: \"auto\" takes the foot over each plate from the markers"):
        Trial(coordinates=str(LAB / "hamner_running_stride_ik.mot"), grf=grf, plates="auto")
    with pytest.raises(ValueError, match="plate 'ground_' is given to both 'calcn_r' and 'calcn_l'"):
        prepare(scene, Trial(lab, grf=grf, plates={"calcn_r": ["ground_"], "calcn_l": ["1_ground_", "ground_"]},
                             tasks=str(TASKS)))
    for bad in ("automatic", {"calcn_r": []}, {"calcn_r": ["ground_", "ground_"]}, ["ground_"]):
        with pytest.raises(OptionRefused, match="plates: expected node -> the plate's column prefix"):
            Trial(lab, grf=grf, plates=bad)


MUSCLES = Path(__file__).parent / "data" / "muscles"


def _wrench(parts) -> np.ndarray:
    """(n, 9) one plate carrying the loads ``parts`` [(F, P, T) (n, 3) each] together: the force summed, the centre of
    pressure their vertical forces' mean on the floor (y = 0, where the walk's plates write theirs), the torque the
    rest of the moment about the origin."""
    F = sum(f for f, _, _ in parts)
    M = sum(np.cross(p, f) + tq for f, p, tq in parts)
    P = np.zeros_like(F)
    fy = np.where(F[:, 1] > 0, F[:, 1], np.inf)
    for a in (0, 2):
        P[:, a] = sum(np.where(f[:, 1] > 0, p[:, a] * f[:, 1], 0.0) for f, p, _ in parts) / fy
    return np.column_stack([F, P, M - np.cross(P, F)])


def test_a_plate_carrying_both_feet_at_once_is_refused_not_given_to_the_nearer():
    """The Rajagopal walk's feet's ground reactions (per foot, from its lab) on one plate (a treadmill's), or the left
    foot's first 0.15 s of stance on the right's plate (a double support on one plate): the contact was given whole
    to calcn_r (exit 0: the left's load on the right foot); refused, naming the plate, the time and both feet. Each
    foot on its own plate: as the lab's file gives them."""
    import dataclasses

    import casflex
    from casflex.study.events import plate_contacts

    scene = casflex.load_scene(MUSCLES / "rajagopal_walk_planar_muscles.osim")
    lab, grf = read_trc(MUSCLES / "rajagopal_walk.trc"), read_sto(MUSCLES / "rajagopal_walk_grf.mot")
    def cols(kind: str) -> np.ndarray:
        return np.column_stack([grf.column(kind.format(a)) for a in "xyz"])

    foot = {s: (cols(f"ground_force_{s}_v{{}}"), cols(f"ground_force_{s}_p{{}}"), cols(f"ground_torque_{s}_{{}}"))
            for s in "rl"}
    apart = _table(grf, {"ground_": _wrench([foot["r"]]), "1_ground_": _wrench([foot["l"]])}, "apart")
    xyz = lab.xyz.copy()
    xyz[np.ix_((lab.t > 0.9) & (lab.t < 0.95), [lab.labels.index(m) for m in ("R.Toe", "R.MT5", "R.Heel")])] = np.nan
    for seen in (lab, dataclasses.replace(lab, xyz=xyz)):  # the right foot unseen in double support: no matter
        assert [(c.plate, c.foot) for c in plate_contacts(scene, seen, apart)] == [
            ("ground_", "calcn_r"), ("ground_", "calcn_r"), ("1_ground_", "calcn_l")]
    one = _table(grf, {"ground_": _wrench([foot["r"], foot["l"]])}, "one")
    with pytest.raises(ValueError, match=r"^one: plate 'ground_', contact 0.268-\[end\] s: its centre of pressure lies "
                                         r"0.48 m across the floor from calcn_r's nearest marker at t = 1.020 s .*"
                                         r"nearer calcn_l's .*both feet on the plate at once"):
        plate_contacts(scene, lab, one)
    early = (grf.t < 0.836 + 0.15)[:, None]  # the left foot strikes at 0.836 s
    F, P, T = foot["l"]
    on, off = ((np.where(early, F, 0.0), P, np.where(early, T, 0.0)),
               (np.where(early, 0.0, F), P, np.where(early, 0.0, T)))
    part = _table(grf, {"ground_": _wrench([foot["r"], on]), "1_ground_": _wrench([off])}, "part")
    with pytest.raises(ValueError, match=r"^part: plate 'ground_', contact 0.268-1.023 s: .* at t = 0.985 s .*"
                                         r"nearer calcn_l"):
        plate_contacts(scene, lab, part)


def test_a_plate_grazed_by_a_foot_for_less_than_a_stance_is_refused(hamner):
    """The left foot's load at 0.800 and 0.817 s (936 and 1049 N) written to the right foot's plate too: a 49 ms
    contact, dropped as too short, whose samples went to the plate's only foot, calcn_r, in its swing (exit 0)."""
    from casflex.study.events import plate_contacts

    scene, lab, grf = hamner
    two = (grf.t > 0.79) & (grf.t < 0.82)
    tap = _table(grf, {"ground_": np.where(two[:, None], _plate(grf, "1_ground_"), _plate(grf, "ground_")),
                       "1_ground_": _plate(grf, "1_ground_")}, "tap")
    with pytest.raises(ValueError, match=r"^tap: plate 'ground_': a contact of 49 ms at t = 0.783-0.833 s peaking at "
                                         r"1049 N, shorter than a stance \(0.05 s\) and above noise \(100 N\)"):
        plate_contacts(scene, lab, tap)


def test_a_stance_the_record_cuts_short_goes_to_its_own_foot(hamner):
    """Both feet on one plate in turn (as above) from t = 0.300 s: the left foot's stance then has 2 samples (0.300,
    0.317 s: 27 ms) in the record, which was dropped as too short and given to calcn_r, the plate's next foot (its
    ankle moment off by 61 N m, exit 0). Kept, it goes to calcn_l: the loads are the two plates'."""
    import dataclasses

    scene, lab, grf = hamner
    i = int(np.argmax(grf.t >= 0.3))
    grf, lab = dataclasses.replace(grf, t=grf.t[i:], values=grf.values[i:]), \
        dataclasses.replace(lab, t=lab.t[i:], xyz=lab.xyz[i:])
    right = grf.column("ground_force_vy") > 0
    one = _table(grf, {"ground_": np.where(right[:, None], _plate(grf, "ground_"), _plate(grf, "1_ground_"))}, "one")
    _same(_moments(scene, lab, one, "auto"), _moments(scene, lab, grf, ORIGINAL))


def test_a_plate_whose_unloaded_reading_chatters_around_the_threshold_is_refused(hamner):
    """The right plate reading 20 +- 5 N unloaded (an offset not zeroed, noise): its contacts chattered (this draw:
    the second stance struck at 1.045 s for 1.101, the cycle's end 56 ms early, and a 55 ms contact 0.667-0.722 s
    after the first, exit 0; other draws: a strike 30 ms early, the noise given to calcn_l, or a refusal saying no
    foot was over the noise). Refused, naming the plate and its unloaded reading; the recorded plates (0 N unloaded,
    the Rajagopal walk's up to 9 N; walking2.c3d's -14 and -19 N, robust standard deviations 0.8 and 1.3 N) pass."""
    import dataclasses

    from casflex.study.events import plate_contacts

    scene, lab, grf = hamner
    values, i = grf.values.copy(), grf.names.index("ground_force_vy")
    unloaded = values[:, i] < 20.0
    values[unloaded, i] = 20.0 + 5.0 * np.random.default_rng(9).standard_normal(unloaded.sum())
    with pytest.raises(ValueError, match=r"hamner_running_whole_grf.mot: plate 'ground_': unloaded it reads 19.8 "
                                         r"\+- 5.4 N \(median and robust standard deviation of its 34 samples under "
                                         r"100 N away from its stances"):
        plate_contacts(scene, lab, dataclasses.replace(grf, values=values))


def test_a_plate_a_foot_stands_on_but_applied_to_no_node_is_said(hamner):
    """The right stance straddling plates 0 and 3 (as above) with only plate 0 applied to calcn_r (and plate 1 to
    calcn_l): the toes' plate's load (836 N) was left out of the foot's ground reaction without a word (exit 0).
    Said now, naming the plate, the foot and its contact; a plate under no foot of the scene (walking2.c3d's left
    plate with a right leg) says nothing (tests/test_lab_plate_checks.py)."""
    from casflex.inverse import Trial, prepare

    scene, lab, grf = hamner
    w = np.clip((0.665 - grf.t) / (0.665 - 0.39), 0.0, 1.0)
    straddle = _table(grf, {"ground_": _plate(grf, "ground_", w), "1_ground_": _plate(grf, "1_ground_"),
                            "3_ground_": _plate(grf, "ground_", 1 - w)}, "straddle")
    inputs = prepare(scene, Trial(lab, grf=straddle, plates=ORIGINAL, tasks=str(TASKS)))
    said = [ln for ln in inputs.warnings if ln.startswith("plate '")]
    assert said == ["plate '3_ground_' (straddle): calcn_r stands on it 0.410-0.665 s inside the window, but it is "
                    "applied to no node: its load (836 N) is left out of calcn_r's ground reaction; apply it (--plate "
                    "calcn_r=3_ground_, a node may take two plates) or --plate auto"]
    assert sum(ln in said for ln in inputs.report) == 1
    full = prepare(scene, Trial(lab, grf=straddle, plates=ORIGINAL | {"calcn_r": ["ground_", "3_ground_"]},
                                tasks=str(TASKS)))
    assert not [ln for ln in full.warnings if ln.startswith("plate '")]


def test_an_unused_plate_s_offset_refuses_nothing(hamner):
    """A third plate no foot steps on, reading 18-20.5 N (an offset not zeroed; 19 +- 0.7 N, median and robust SD):
    no contact (its samples above 20 N last under 0.05 s), and the chatter check, for plates carrying a stance, leaves
    it be (a trial was refused for a plate it does not use)."""
    from casflex.study.events import plate_contacts

    scene, lab, grf = hamner
    idle = _plate(grf, "ground_", 0.0)
    idle[:, 1] = np.array([18.0, 19.0, 20.5, 19.0])[np.arange(grf.t.size) % 4]  # one sample above 20 N in four
    three = _table(grf, {"ground_": _plate(grf, "ground_"), "1_ground_": _plate(grf, "1_ground_"), "2_ground_": idle},
                   "three")
    assert [c.plate for c in plate_contacts(scene, lab, three)] == ["ground_"] * 2 + ["1_ground_"] * 2


def test_a_window_between_a_foot_s_contacts_keeps_its_filtered_share(hamner):
    """Both feet on one plate in turn, cut to 0.70-1.05 s: the right foot's contacts (0.390-0.665, 1.101-end s) lie
    outside, so its share was left out, but the plates' filter spreads its stance into the window (the two plates,
    named: its load there): the ankle moment was 14.8 N m off at 0.70 s (exit 0). Kept within two periods of the
    cut-off: the two plates' loads again."""
    from casflex.inverse import Trial, inverse_dynamics

    scene, lab, grf = hamner
    right = grf.column("ground_force_vy") > 0
    one = _table(grf, {"ground_": np.where(right[:, None], _plate(grf, "ground_"), _plate(grf, "1_ground_"))}, "one")
    cut = {"t_start": 0.70, "t_end": 1.05, "tasks": str(TASKS)}
    got, want = (inverse_dynamics(scene, Trial(lab, grf=g, plates=p, **cut)) for g, p in ((one, "auto"),
                                                                                          (grf, ORIGINAL)))
    _same({k: got.loads[k] for k in want.settings["moments"]}, {k: want.loads[k] for k in want.settings["moments"]})
    assert got.settings["plates"] == {"calcn_l": "ground_", "calcn_r": "ground_"}
