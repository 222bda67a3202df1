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
