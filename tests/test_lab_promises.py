"""The README's promises for the lab commands ("What `import`, `inverse` and `study` promise"), one scenario each:
a bad file is one line naming the file and what is wrong, exit status 2, before any work where its files can tell,
and the outputs an earlier run wrote stay as they were, byte for byte. Each refusal's own tests are in
test_osim_refusals.py, test_lab_checks.py, test_lab_plate_checks.py, test_inverse_given.py and test_study*.py;
the fuzz tests in test_osim_fuzz.py and test_study_file.py."""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from casflex.cli import main

LAB = Path(__file__).resolve().parent / "data" / "lab"
OSIM, TRC, GRF = (LAB / f for f in ("hamner_subject02_leg.osim", "hamner_running_stride.trc",
                                    "hamner_running_stride_grf.mot"))
INVERSE = ["inverse", str(OSIM), "--plate", "calcn_r=ground_", "--cutoff", "10", "--quiet"]


def _refused(argv: list[str], capsys, *said: str) -> str:
    """The command's one line: exit 2, ``casflex: error: `` and each of ``said`` in it, no traceback."""
    code = main(argv)
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("casflex: error: "), (code, err)
    assert "Traceback" not in err
    for s in said:
        assert s in lines[0], (s, lines[0])
    return lines[0]


def _plates(tmp_path: Path, edit) -> Path:
    """The stride's plate table with ``edit(values)`` applied (rows: time first)."""
    lines = GRF.read_text().splitlines()
    end = lines.index("endheader") + 2
    values = np.array([[float(v) for v in ln.split("\t")] for ln in lines[end:] if ln.strip()])
    edit(values)
    path = tmp_path / "grf.mot"
    path.write_text("\n".join(lines[:end] + ["\t".join(repr(float(v)) for v in r) for r in values]) + "\n")
    return path


def test_import_refuses_a_model_it_cannot_hold_and_leaves_the_earlier_scene(tmp_path, capsys):
    out = tmp_path / "leg.toml"
    assert main(["import", str(OSIM), "--out", str(out)]) == 0
    before = out.read_bytes()
    capsys.readouterr()
    text = OSIM.read_text()
    a = text.index('<Body name="femur_r">')
    b = text.index("</Body>", a) + len("</Body>")
    bad = tmp_path / "twice.osim"
    bad.write_text(text[:b] + text[a:b] + text[b:])  # a second femur_r: it replaced the first (exit 0) before
    _refused(["import", str(bad), "--out", str(out)], capsys, f"{bad}: BodySet: two bodies named 'femur_r'")
    assert out.read_bytes() == before


def test_inverse_refuses_inputs_that_are_not_what_they_claim_before_any_work(tmp_path, capsys):
    out = tmp_path / "id.sto"
    base = [*INVERSE, "--data", str(TRC), "--out", str(out)]
    assert main([*base, "--loads", str(GRF)]) == 0
    before = out.read_bytes()
    capsys.readouterr()
    link = tmp_path / "zero.trc"
    os.symlink("/dev/zero", link)  # read until memory ran out before
    cases = [
        ([*INVERSE, "--data", str(link), "--loads", str(GRF), "--out", str(out)], (str(link), "not a regular file")),
        ([*base, "--loads", str(_plates(tmp_path, lambda v: v.__setitem__((slice(None), 2), -v[:, 2])))],
         ("grf.mot: plate 'ground_': its vertical force pulls the foot down",)),
    ]
    for argv, said in cases:
        _refused(argv, capsys, *said)
        assert out.read_bytes() == before


@pytest.fixture()
def study(tmp_path: Path) -> Path:
    """A study of one subject and one trial (Hamner's running, the planar whole-body model)."""
    for f in ("hamner_subject02_planar.osim", "hamner_running_whole.trc", "hamner_running_whole_grf.mot"):
        shutil.copy(LAB / f, tmp_path / f)
    path = tmp_path / "study.toml"
    path.write_text('name = "promise"\n[options]\nplane = "X,Y"\n\n[[subjects]]\nname = "s02"\n'
                    'model = "hamner_subject02_planar.osim"\n\n[[subjects.trials]]\nname = "run"\n'
                    'markers = "hamner_running_whole.trc"\ngrf = "hamner_running_whole_grf.mot"\n'
                    "window = [0.25, 1.15]\n")
    return path


def test_a_study_file_is_checked_before_any_process_starts(study, capsys):
    study.write_text(study.read_text().replace("window = [0.25, 1.15]", "window = [0.25, 3.0]"))
    out = study.parent / "out"
    line = _refused(["study", str(study), "--out", str(out), "--quiet"], capsys, str(study),
                    "subjects[0].trials[0].window")
    assert re.search(r"not within the markers' times", line)
    assert not out.exists()


def test_a_study_asks_no_more_workers_than_the_machine_has(study, capsys):
    out = study.parent / "out"
    _refused(["study", str(study), "--out", str(out), "--workers", "100000"], capsys, "--workers")
    assert not out.exists()
