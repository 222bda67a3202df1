"""What users throw at the command line: every wrong option gives one line naming it, exit status 2,
and writes nothing (the working directory is left as it was)."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

from casflex.cli import main

TRIAL = str(Path(__file__).parent / "data" / "lab" / "hamner_running_stride.trc")

CASES = [
    # (arguments, the one line must match this)
    ("identify twobar --method indirect --initial-state estimate --residue full",
     r"--initial-state estimate: an estimated state needs --residue positions"),
    ("identify twobar --method indirect --initial-state velocities --transcription multiple-shooting",
     r"--initial-state velocities: estimated velocities need single shooting"),
    ("identify twobar --method indirect --hessian exact", r"--hessian: the NLP solver's Hessian; .*--solver ipopt"),
    ("identify twobar --method indirect --vary bar2.Q=1:2", r"--vary bar2.Q: 'bar2' has no numeric property 'Q'"),
    ("identify twobar --method indirect --vary bar2.E=3e11:2e11", r"--vary bar2.E: expected finite lower < upper"),
    ("identify twobar --method indirect --vary bar2.E=1e11:1.5e11", r"--vary bar2.E: the range 1e\+11..1.5e\+11 "
                                                                   r"excludes the scene's value 2.1e\+11"),
    ("identify twobar --method indirect --vary torsion3.kt=1:2", r"--vary torsion3.kt: it is parameter 'kt3', fitted"),
    ("identify twobar --method indirect --vary bar2.E", r"argument --vary: expected TARGET=LOWER:UPPER"),
    ("identify twobar --method indirect --alternatives leg", r"--alternatives: scene 'leg' does not declare the "
                                                            r"parameter\(s\) k1, kt1, k3, kt3"),
    ("identify twobar --method direct --form none", r"--form: applies to the indirect method only"),
    ("identify twobar --method direct --loss huber", r"--loss: applies to the indirect method only"),
    ("identify twobar --method indirect --loss cauchy", r"argument --loss: invalid choice: 'cauchy'"),
    ("identify twobar --method indirect --sigma x3=1e-3,y3", r"argument --sigma: expected SIGMA or CHANNEL=SIGMA"),
    ("identify twobar --method indirect --sigma x3=-1", r"argument --sigma: x3: expected a standard deviation > 0"),
    ("identify twobar --method indirect --dofs x3,y3 --sigma x3=1e-3", r"--sigma: 'y3' has no value; give one per "
                                                                        r"compared channel \(x3, y3\)"),
    ("simulate twobar --t-end 1e9", r"--t-end: 1e\+09 s at --dt = 0.001 s is 1,000,000,000,000 steps .* needs about "
                                    r".*PiB of memory .* available; shorten --t-end or raise --dt"),
    ("simulate twobar --dt 1e-9", r"--t-end: .* TiB of memory"),
    ("simulate twobar --out x.csv", r"--out: 'x.csv' must end in .npz"),
    ("simulate twobar --out nosuch/dir/x.npz", r"--out: directory 'nosuch/dir' does not exist"),
    ("simulate twobar --out adir.npz", r"--out: 'adir.npz' is a directory"),
    ("simulate twobar --plots /proc/figs", r"--plots: cannot write into '/proc'"),
    ("simulate twobar --plots afile.txt", r"--plots: 'afile.txt' exists and is not a directory"),
    ("simulate twobar --out a.npz --plots a.npz", r"--plots: 'a.npz' is already the target of another option"),
    ("simulate twobar --dt -1e-3", r"argument --dt: must be a time step in s > 0, got -1e-3"),
    ("simulate twobar --dt abc", r"argument --dt: expected a number, got 'abc'"),
    ("simulate twobar --t-end -2", r"argument --t-end: must be a duration in s > 0, got -2"),
    ("simulate twobar --alpha 0.5", r"argument --alpha: HHT alpha must lie in \[-1/3, 0\]"),
    ("simulate twobar --dt 0.0007 --t-end 0.01", r"--t-end: 0.01 s is not a whole number of steps --dt = 0.0007 s"),
    ("simulate nosuch.toml", r"scene 'nosuch.toml': no such file, and not a built-in scene"),
    ("static twobar --steps -3", r"argument --steps: must be .* >= 1, got -3"),
    ("modes twobar --count 0", r"argument --count: must be .* >= 1, got 0"),
    ("identify twobar --method direct --out r.npz", r"--out: 'r.npz' must end in .json"),
    ("identify twobar --method direct --start -2", r"argument --start: must be a factor of the nominal values > 0"),
    ("identify twobar --method indirect --interval 0", r"argument --interval: must be a number of steps >= 1"),
    ("identify twobar --method direct --data measured --noise 1e-3 --seed -1", r"argument --seed: must be a seed >= 0"),
    ("export twobar --out nosuch/x", r"--out: directory 'nosuch' does not exist"),
    ("export twobar --out e --dt 0.0007", r"--t-end: 3 s is not a whole number of steps --dt = 0.0007 s"),
    # argparse keeps a repeated option's last value without a word: one of two values the user wrote
    ("simulate twobar --dt 1e-3 --out a.npz --dt=2e-3", r"argument --dt: given twice \(--dt 0.001 and --dt 0.002\)"),
    ("identify twobar --method direct --method indirect", r"argument --method: given twice"),
    ("static twobar --steps 3 --ste 4", r"argument --steps: given twice"),
]


def test_compiler_flags_the_compiler_rejects_are_one_line_before_any_work(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("CASFLEX_CFLAGS", "-march=no-such-cpu")
    assert main("simulate twobar --compiled --out run.npz".split()) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and re.match(r"casflex: error: CASFLEX_CFLAGS='-march=no-such-cpu': .* rejects", err[0]), err
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("argv, match", CASES, ids=[c[0] for c in CASES])
def test_a_wrong_option_is_one_line_exit_2_and_writes_nothing(argv, match, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "adir.npz").mkdir()
    (tmp_path / "afile.txt").write_text("mine\n")
    before = sorted(p.name for p in tmp_path.rglob("*"))
    code = main(argv.split())
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("casflex: error: "), err
    assert re.search(match, err[0]), err[0]
    assert sorted(p.name for p in tmp_path.rglob("*")) == before  # no file, no staging left behind
    assert (tmp_path / "afile.txt").read_text() == "mine\n"


#: An empty output path: each command that takes --out or --plots (the commands skipped one not given).
EMPTY = [
    (["simulate", "twobar", "--out", ""], "--out"),
    (["simulate", "twobar", "--t-end", "0.01", "--plots", " "], "--plots"),
    (["demo", "--out", ""], "--out"),
    (["static", "twobar", "--out", ""], "--out"),
    (["modes", "twobar", "--out", ""], "--out"),
    (["identify", "twobar", "--method", "direct", "--out", ""], "--out"),
    (["identify", "twobar", "--method", "indirect", "--plots", ""], "--plots"),
    (["inverse", "hamner_leg", "--data", TRIAL, "--out", ""], "--out"),
    (["inverse", "hamner_leg", "--data", TRIAL, "--plots", ""], "--plots"),
    (["calibrate", "hamner_leg", "--static", TRIAL, "--out", ""], "--out"),
    (["export", "twobar", "--out", ""], "--out"),
]


@pytest.mark.parametrize("argv, option", EMPTY, ids=[" ".join(a[:1] + a[-2:]) for a, _ in EMPTY])
def test_an_empty_output_path_is_one_line_exit_2(argv, option, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err == [f"casflex: error: argument {option}: expected a path, got {argv[-1]!r}"], err
    assert not list(tmp_path.iterdir())


def _scene_file(tmp_path: Path) -> Path:
    from casflex import dumps_scene, load_scene

    path = tmp_path / "leg.toml"
    path.write_text(dumps_scene(load_scene("hamner_leg")))
    return path


@pytest.mark.parametrize("out", ["leg.toml", "sub/../leg.toml", "hard.toml", "link.toml"])
def test_an_output_that_is_an_input_of_the_command_is_one_line_exit_2(out, tmp_path, monkeypatch, capsys):
    # calibrate SCENE --out SCENE replaced its own scene without a word
    monkeypatch.chdir(tmp_path)
    scene = _scene_file(tmp_path)
    (tmp_path / "sub").mkdir()
    os.link(scene, tmp_path / "hard.toml")
    (tmp_path / "link.toml").symlink_to("leg.toml")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    code = main(["calibrate", "leg.toml", "--static", TRIAL, "--out", out])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err == [f"casflex: error: --out: {out!r} is an input of the command (the scene); give another name (it "
                   "would be replaced)"], err
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hard.toml", "leg.toml", "link.toml", "sub"]


def test_an_input_is_protected_in_every_command_not_only_calibrate(tmp_path, monkeypatch, capsys):
    # one rule for every command's inputs: here a scene file named as simulate's --out may be (.npz)
    from casflex import dumps_scene, load_scene

    monkeypatch.chdir(tmp_path)
    Path("scene.npz").write_text(dumps_scene(load_scene("twobar")))
    assert main(["simulate", "scene.npz", "--t-end", "0.01", "--quiet", "--out", "scene.npz"]) == 2
    assert capsys.readouterr().err.strip() == ("casflex: error: --out: 'scene.npz' is an input of the command (the "
                                               "scene); give another name (it would be replaced)")
    assert Path("scene.npz").read_text() == dumps_scene(load_scene("twobar"))
    assert sorted(os.listdir()) == ["scene.npz"]
