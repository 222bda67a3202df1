"""``casflex muscles``: OpenSim's static optimization and joint reaction files from a lab trial, and bad input refused
in one line before any work (exit status 2, nothing written)."""

from __future__ import annotations

from pathlib import Path

import pytest

from casflex.cli import main
from casflex.lab.tables import read_sto

DATA = Path(__file__).parent / "data" / "muscles"
MODEL = DATA / "gait10dof18musc_subject01.osim"
TRIAL = ["--coordinates", str(DATA / "subject01_walk_IK.mot"), "--loads", str(DATA / "subject01_walk_grf.xml"),
         "--filter", "opensim", "--cutoff-plates", "none", "--t-end", "0.6"]
RESERVES = str(DATA / "gait10dof_Reserve_Actuators.xml")


def test_the_command_writes_opensims_files_and_figures(tmp_path, capsys):
    out, plots = tmp_path / "out", tmp_path / "plots"
    out.mkdir()
    code = main(["muscles", str(MODEL), *TRIAL, "--actuators", RESERVES, "--joints", "hip_r,knee_r",
                 "--in", "child", "--name", "walk", "--out", str(out), "--plots", str(plots), "--quiet"])
    text = capsys.readouterr().out
    assert code == 0 and text.splitlines()[1].startswith("  hip_r: ")
    so = read_sto(out / "walk_StaticOptimization_force.sto")
    assert "soleus_r" in so.names and "FX" in so.names and so.t[-1] == pytest.approx(0.6, abs=0.02)
    jr = read_sto(out / "walk_JointReaction_ReactionLoads.sto")
    assert [n for n in jr.names if n.endswith("_fx")] == ["hip_r_on_femur_r_in_femur_r_fx",
                                                        "knee_r_on_tibia_r_in_tibia_r_fx"]
    assert sorted(p.name for p in plots.iterdir()) == ["activations.png", "joint_reactions.png"]


def _refused(tmp_path, capsys, argv, message):
    out = tmp_path / "out"
    code = main(["muscles", *argv, "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and message in err, err
    assert not out.exists() or not any(out.iterdir())


def _edited(tmp_path, old: str, new: str, name: str = "model.osim") -> str:
    text = MODEL.read_text()
    assert old in text
    path = tmp_path / name
    path.write_text(text.replace(old, new, 1))
    return str(path)


def test_bad_options_are_refused_naming_them(tmp_path, capsys):
    _refused(tmp_path, capsys, [str(MODEL), *TRIAL, "--exponent", "0.5"], "--exponent: expected a number >= 1")
    _refused(tmp_path, capsys, [str(MODEL), *TRIAL, "--activation-bounds", "1:0.5"], "--activation-bounds: ")
    _refused(tmp_path, capsys, [str(MODEL), *TRIAL, "--joints", "hip_x"], "joints: no hinge 'hip_x'")
    _refused(tmp_path, capsys, ["hamner_leg", *TRIAL], "model: expected an OpenSim model (.osim)")


def test_bad_muscles_and_actuators_are_refused_naming_them(tmp_path, capsys):
    nan = _edited(tmp_path, "<max_isometric_force>", "<max_isometric_force>nan ")
    _refused(tmp_path, capsys, [nan, *TRIAL], "max_isometric_force")
    acts = tmp_path / "acts.xml"
    acts.write_text(Path(RESERVES).read_text().replace("<coordinate>knee_angle_r</coordinate>",
                                                       "<coordinate>knee_bend_r</coordinate>"))
    _refused(tmp_path, capsys, [str(MODEL), *TRIAL, "--actuators", str(acts)],
             "coordinate: no coordinate 'knee_bend_r' in the model")
    missing = _edited(tmp_path, "<socket_parent_frame>/bodyset/tibia_r</socket_parent_frame>",
                      "<socket_parent_frame>/bodyset/tibia_x</socket_parent_frame>")
    _refused(tmp_path, capsys, [missing, *TRIAL], "tibia_x")


def test_a_frame_no_activation_can_carry_is_refused_naming_it(tmp_path, capsys):
    """Activations held below 5 % and no reserves: the walk's moments are out of reach; the first frames named."""
    _refused(tmp_path, capsys, [str(MODEL), *TRIAL, "--activation-bounds", "0.01:0.05"],
             "no activation within the bounds carries its moment")


def test_the_command_imports_neither_the_simulator_nor_identification_nor_plotting(tmp_path):
    """What ``casflex muscles`` loads from markers to reactions (a new process, as a user runs it): none of the
    simulator, identification's methods, the studies, the figures or scipy.sparse (they cost it 0.3 s of imports)."""
    import subprocess
    import sys

    heavy = ("casflex.simulate", "casflex.integrators", "casflex.identification.problem", "casflex.study",
             "casflex.plotting", "dask", "matplotlib", "scipy.sparse")
    argv = ["muscles", str(MODEL), "--data", str(DATA / "subject01_walk.trc"), "--tasks",
            str(DATA / "walk_ik_tasks.xml"), "--loads", str(DATA / "subject01_walk_grf.xml"), "--filter", "opensim",
            "--cutoff-plates", "none", "--t-end", "0.6", "--actuators", RESERVES, "--joints", "knee_r", "--quiet",
            "--out", str(tmp_path)]
    code = (f"import sys\nfrom casflex.cli import main\nassert main({argv!r}) == 0\n"
            f"print(sorted(m for m in sys.modules if m.startswith({heavy!r})))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "[]"
