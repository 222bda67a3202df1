"""A command whose optional extra is not installed says, in one line, which extra to install (issue 48, item 10):
the extra's module is blocked here as a missing package is (``sys.modules[name] = None``: its import fails)."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

from casflex.cli import main
from casflex.cli._base import missing_extra

LAB = Path(__file__).resolve().parent / "data" / "lab"


def _study(folder: Path, markers: str, grf: str) -> Path:
    path = folder / "study.toml"
    path.write_text(f'name = "s"\n[options]\nplane = "X,Y"\n\n[[subjects]]\nname = "s"\n'
                    f'model = "hamner_subject02_planar.osim"\n\n[[subjects.trials]]\nname = "t"\n'
                    f'markers = "{markers}"\ngrf = "{grf}"\nplates = {{ calcn_r = "ground_" }}\n')
    return path


def _one_line(capsys) -> str:
    out, err = capsys.readouterr()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    return err


def test_study_without_the_sweep_extra_says_so_in_one_line_before_any_work(tmp_path, capsys, monkeypatch):
    for f in ("hamner_subject02_planar.osim", "hamner_running_whole.trc", "hamner_running_whole_grf.mot"):
        shutil.copy(LAB / f, tmp_path / f)
    study = _study(tmp_path, "hamner_running_whole.trc", "hamner_running_whole_grf.mot")
    monkeypatch.setitem(sys.modules, "distributed", None)
    assert main(["study", str(study), "--out", str(tmp_path / "res")]) == 2
    assert _one_line(capsys) == ("casflex: error: casflex study needs casflex's 'sweep' extra (the distributed "
                                 "package, which runs a study on dask), not installed: pip install 'casflex[sweep]'\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["study.toml", "hamner_subject02_planar.osim",
                                                                 "hamner_running_whole.trc",
                                                                 "hamner_running_whole_grf.mot"])  # nothing made


def test_a_c3d_file_without_the_lab_extra_says_so_in_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ezc3d", None)
    c3d = str(LAB / "walking2_excerpt.c3d")
    assert main(["inverse", "hamner_leg", "--data", c3d, "--out", str(tmp_path / "id.csv")]) == 2
    assert _one_line(capsys) == (f"casflex: error: --data {c3d!r} (a C3D file) needs casflex's 'lab' extra (the "
                                 "ezc3d package, which reads C3D files), not installed: pip install 'casflex[lab]'\n")
    assert not list(tmp_path.iterdir())


def test_a_c3d_file_named_by_a_study_without_the_lab_extra_is_one_line_before_any_run(tmp_path, capsys, monkeypatch):
    # the workers would fail each trial on it (a reason per trial in the summary, exit 1): said once, before
    for f in ("walking2_excerpt.c3d", "hamner_subject02_planar.osim"):
        shutil.copy(LAB / f, tmp_path / f)
    study = _study(tmp_path, "walking2_excerpt.c3d", "walking2_excerpt.c3d")
    monkeypatch.setitem(sys.modules, "ezc3d", None)
    assert main(["study", str(study), "--out", str(tmp_path / "res")]) == 2
    assert "pip install 'casflex[lab]'" in _one_line(capsys)
    assert not (tmp_path / "res").exists()


@pytest.mark.parametrize("exc, said", [
    (ModuleNotFoundError("No module named 'distributed'", name="distributed.client"),
     "this command needs casflex's 'sweep' extra (the distributed package, which runs a study on dask), not "
     "installed: pip install 'casflex[sweep]'"),
    (ModuleNotFoundError("read_c3d needs the ezc3d package: pip install 'casflex[lab]'"),
     "read_c3d needs the ezc3d package: pip install 'casflex[lab]'"),
    (ModuleNotFoundError("No module named 'yaml'", name="yaml"), None),  # no extra's: a traceback, a bug to report
    (ValueError("pip install 'casflex[lab]'"), None),
])
def test_an_extra_s_import_error_met_during_the_work_is_one_line(exc, said):
    assert missing_extra(exc) == said
