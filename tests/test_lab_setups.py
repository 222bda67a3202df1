"""casflex.lab.setups: OpenSim's setup files that name other files. A setup that names itself, or two that name
each other, is refused in one line naming the file and the element (it recursed until Python's RecursionError)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from casflex.cli import main
from casflex.lab.setups import read_external_loads, read_tasks

DATA = Path(__file__).parent / "data" / "lab"
LEG, TRC = DATA / "hamner_subject02_leg.osim", DATA / "hamner_running_stride.trc"
IK = (
    '<OpenSimDocument Version="40000"><InverseKinematicsTool><IKTaskSet file="{}"/></InverseKinematicsTool>'
    "</OpenSimDocument>"
)
ID = (
    '<OpenSimDocument Version="40000"><InverseDynamicsTool><external_loads_file>{}</external_loads_file>'
    "</InverseDynamicsTool></OpenSimDocument>"
)


def test_an_ik_setup_naming_itself_is_refused_naming_the_file(tmp_path, capsys):
    setup = tmp_path / "ik_setup.xml"
    setup.write_text(IK.format("ik_setup.xml"))
    with pytest.raises(
        ValueError, match=re.escape(f"{setup}: IKTaskSet file names 'ik_setup.xml', a file already on the way here")
    ):
        read_tasks(setup)
    code = main(["inverse", str(LEG), "--data", str(TRC), "--tasks", str(setup), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "a loop of setup files" in err
    good = tmp_path / "named.xml"  # a setup naming the repo's task file is read through
    good.write_text(IK.format(str(DATA / "hamner_tasks_ik.xml")))
    assert read_tasks(good).weights["R.ASIS"] == 50.0


def test_two_id_setups_naming_each_other_are_refused_naming_the_loop(tmp_path):
    a, b = tmp_path / "a.xml", tmp_path / "b.xml"
    a.write_text(ID.format("b.xml"))
    b.write_text(ID.format("a.xml"))
    with pytest.raises(
        ValueError,
        match=re.escape(
            f"{b}: external_loads_file names 'a.xml', a file already on the way "
            f"here ({a} -> {b} -> {tmp_path / 'a.xml'}): a loop of setup files"
        ),
    ):
        read_external_loads(a)


MUSCLES = Path(__file__).parent / "data" / "muscles"
_R_ASIS_WEIGHT = "<weight>      50.00000000 </weight>"  # the first task's, R.ASIS's, in hamner_tasks_ik.xml


@pytest.mark.parametrize("edit, said", [
    (lambda t: t.replace(_R_ASIS_WEIGHT, _R_ASIS_WEIGHT + "<weight>1</weight>", 1),
     "IKMarkerTask 'R.ASIS': weight given 2 times; give it once"),
    (lambda t: t.replace("</IKMarkerTask>", '</IKMarkerTask><IKMarkerTask name="R.ASIS"><apply>true</apply>'
                         "<weight>1</weight></IKMarkerTask>", 1),
     "two tasks named 'R.ASIS'; give each marker or coordinate one task"),
])
def test_a_task_given_twice_is_refused_naming_it(tmp_path, edit, said):
    # OpenSim reads a property given twice first-wins without a word, and a second task of one name was taken last
    # (which weight was meant is a guess): refused; the repo's task files read as before
    text = (DATA / "hamner_tasks_ik.xml").read_text()
    assert _R_ASIS_WEIGHT in text and read_tasks(DATA / "hamner_tasks_ik.xml").weights["R.ASIS"] == 50.0
    bad = tmp_path / "tasks.xml"
    bad.write_text(edit(text))
    with pytest.raises(ValueError, match=re.escape(f"{bad}: {said}")):
        read_tasks(bad)
    assert read_tasks(MUSCLES / "rajagopal_walk_ik_tasks.xml").weights


def test_an_external_force_property_given_twice_is_refused_naming_it(tmp_path):
    text = (MUSCLES / "rajagopal_walk_grf.xml").read_text()
    good = read_external_loads(MUSCLES / "rajagopal_walk_grf.xml")
    body = next(iter(good.plates))
    tag = f"<applied_to_body>{body}</applied_to_body>"
    assert tag in text
    bad = tmp_path / "grf.xml"
    bad.write_text(text.replace(tag, tag + "<applied_to_body>femur_r</applied_to_body>", 1))
    with pytest.raises(ValueError, match=re.escape(f"{bad}: ExternalForce ") + ".*applied_to_body given 2 times"):
        read_external_loads(bad)
