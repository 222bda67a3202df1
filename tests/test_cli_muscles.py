"""``casflex muscles``: OpenSim's static optimization and joint reaction files from a lab trial, and bad input refused
in one line before any work (exit status 2, nothing written)."""

from __future__ import annotations

from pathlib import Path

import pytest

from casflex.cli import main
from casflex.lab.tables import read_sto

DATA = Path(__file__).parent / "data" / "muscles"
LAB = Path(__file__).parent / "data" / "lab"
MODEL = DATA / "hamner_subject02_planar_muscles.osim"  # Hamner's subject 02, planar, 92 Thelen muscles
TRIAL = ["--data", str(LAB / "hamner_running_whole.trc"), "--loads", str(LAB / "hamner_running_whole_grf.mot"),
         "--plate", "calcn_r=ground_", "--plate", "calcn_l=1_ground_", "--tasks", str(LAB / "hamner_tasks_ik.xml"),
         "--cutoff", "10", "--t-end", "0.6"]
RESERVES = str(DATA / "hamner_reserve_actuators.xml")


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
    err = [line for line in capsys.readouterr().err.splitlines() if not line.startswith("casflex: warning: ")]
    assert code == 2 and len(err) == 1 and message in err[0], err  # one line (the trial's warnings apart)
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
    _refused(tmp_path, capsys, [str(MODEL), *TRIAL, "--joints", "hip_r,knee_r,hip_r"], "joints: 'hip_r' given twice")
    _refused(tmp_path, capsys, [str(MODEL), *TRIAL, "--activation-bounds", "0.01:5"],  # activations to 2.88, exit 0
             "--activation-bounds: expected 0 <= lower < upper <= 1")
    _refused(tmp_path, capsys, [str(MODEL), *TRIAL, "--exponent", "20"],  # IPOPT stopped: a traceback
             "--exponent: expected a number >= 1 and at most 10")
    _refused(tmp_path, capsys, ["hamner_leg", *TRIAL], "model: expected an OpenSim model (.osim)")


def test_bad_muscles_and_actuators_are_refused_naming_them(tmp_path, capsys):
    nan = _edited(tmp_path, "<max_isometric_force>", "<max_isometric_force>nan ")
    _refused(tmp_path, capsys, [nan, *TRIAL, "--reserves", "1"], "max_isometric_force")
    acts = tmp_path / "acts.xml"
    acts.write_text(Path(RESERVES).read_text().replace("<coordinate>knee_angle_r</coordinate>",
                                                       "<coordinate>knee_bend_r</coordinate>"))
    _refused(tmp_path, capsys, [str(MODEL), *TRIAL, "--actuators", str(acts)],
             "coordinate: no coordinate 'knee_bend_r' in the model")
    acts.write_text(Path(RESERVES).read_text().replace('name="knee_angle_l_reserve"', 'name="soleus_r"'))
    _refused(tmp_path, capsys, [str(MODEL), *TRIAL, "--actuators", str(acts)],  # its control was the muscle's column
             "CoordinateActuator 'soleus_r': a muscle of the model has that name")
    text = MODEL.read_text()
    at = text.index("<socket_parent_frame>/bodyset/tibia_r</socket_parent_frame>", text.index("<PathPointSet"))
    missing = tmp_path / "missing.osim"  # a path point's body, not a joint's
    missing.write_text(text[:at] + text[at:].replace("/bodyset/tibia_r<", "/bodyset/tibia_x<", 1))
    _refused(tmp_path, capsys, [str(missing), *TRIAL, "--reserves", "1"], "tibia_x")


def test_a_frame_no_activation_can_carry_is_refused_naming_it(tmp_path, capsys):
    """Activations held below 5 % and reserves on the arms only (which no muscle crosses): the legs' moments are out
    of reach; the first frames named with the coordinate and the moment missing."""
    text = Path(RESERVES).read_text()
    a = text.index('<CoordinateActuator name="hip_flexion_r_reserve">')
    keep = "".join(text[text.index(f'<CoordinateActuator name="{c}_reserve">'):].split("</CoordinateActuator>")[0]
                   + "</CoordinateActuator>" for c in ("arm_flex_r", "arm_flex_l", "elbow_flex_r", "elbow_flex_l"))
    lumbar = tmp_path / "arms.xml"
    lumbar.write_text(text[:a] + keep + text[text.rindex("</CoordinateActuator>") + len("</CoordinateActuator>"):])
    _refused(tmp_path, capsys, [str(MODEL), *TRIAL, "--actuators", str(lumbar), "--activation-bounds", "0.01:0.05"],
             "no activation within the bounds carries its moment")


def test_ipopt_stopping_short_is_one_line_naming_the_frames_and_what_to_try(tmp_path, capsys, monkeypatch):
    """IPOPT stopping short on moments the activations can carry (an exponent other than 2 at a hard frame, here
    made to stop at every solve): a RuntimeError's traceback before; now the frames one by one, those that fail
    named with their times and what to try, in one line (exit 2, the statics' and the simulator's convention for a
    solver that fails), nothing written."""
    from casflex.muscles import static_optimization as so

    solve = so._Problem.solve

    def stopping(self, target, qp=True):
        x, it, _, stats = solve(self, target, qp)  # p = 3: IPOPT's every time
        return x, it, False, {**stats, "return_status": "Maximum_Iterations_Exceeded"}

    monkeypatch.setattr(so._Problem, "solve", stopping)
    _refused(tmp_path, capsys, [str(MODEL), *TRIAL, "--actuators", RESERVES, "--exponent", "3"],
             "static optimization (exponent 3): IPOPT stopped (Maximum_Iterations_Exceeded) at t = 0.2 s (frame 0), "
             "t = 0.216667 s (frame 1), t = 0.233333 s (frame 2) and 22 more frames, on moments the activations can "
             "carry: try exponent 2")


def test_reserves_by_option_and_the_root_left_unbalanced_said(tmp_path, capsys):
    """--reserves 1: OpenSim's reserve file's actuators made by option (one on each joint coordinate, FX, FY, MZ):
    the same activations as the file's (the file's residuals sit 3.4 cm behind the pelvis' origin: the root's
    balance differs, the joints' does not); reserves without residuals: the summary says the root is left; none at
    all: the arms' joints, which no muscle crosses, are refused by name."""
    for flag, name in ((["--reserves", "1"], "opt"), (["--actuators", RESERVES], "file")):
        out = tmp_path / name
        out.mkdir()
        assert main(["muscles", str(MODEL), *TRIAL, *flag, "--name", "w", "--out", str(out), "--quiet"]) == 0
    joints_only = tmp_path / "joints.xml"
    text = Path(RESERVES).read_text()
    joints_only.write_text(text[:text.index("<PointActuator")] + text[text.index("<CoordinateActuator"):])
    (tmp_path / "j").mkdir()
    assert main(["muscles", str(MODEL), *TRIAL, "--actuators", str(joints_only), "--out", str(tmp_path / "j"),
                 "--quiet"]) == 0
    assert capsys.readouterr().out.count("no residual actuator on the root") == 1
    _refused(tmp_path, capsys, [str(MODEL), *TRIAL], "arm_flex_r, arm_flex_l, elbow_flex_r, elbow_flex_l: no muscle "
                                                     "crosses it and no reserve")
    a, b = (read_sto(tmp_path / n / "w_StaticOptimization_activation.sto") for n in ("opt", "file"))
    assert abs(a.column("soleus_r") - b.column("soleus_r")).max() < 1e-6  # the QP's tolerance
    assert "FX" in a.names and "hip_flexion_r_reserve" in a.names


def test_bands_are_written_beside_the_outputs_and_said(tmp_path, capsys):
    """--muscle-uncertainty: each output's SD in <name>_..._sd.sto (OpenSim's labels), the hip's said with its band
    and the other criterion's peak; a fibre or tendon length uncertain: the muscles' part by a Monte Carlo."""
    out = tmp_path / "out"
    out.mkdir()
    assert main(["muscles", str(MODEL), *TRIAL[:-1], "0.45", "--actuators", RESERVES, "--joints", "hip_r",
                 "--muscle-uncertainty", "max_isometric_force=10%", "--muscle-uncertainty", "tendon_slack_length=2%",
                 "--draws", "10", "--name", "w", "--out", str(out), "--quiet"]) == 0
    text = capsys.readouterr().out
    assert " +- " in text.splitlines()[1] and "other criterion" in text.splitlines()[1]
    assert "the muscles' part is the Monte Carlo's (10 draws" in text
    sd = read_sto(out / "w_StaticOptimization_force_sd.sto")
    assert "soleus_r" in sd.names and (sd.column("soleus_r") >= 0).all() and sd.column("soleus_r").max() > 0
    jr = read_sto(out / "w_JointReaction_ReactionLoads_sd.sto")
    assert "hip_r_on_femur_r_in_ground_fx" in jr.names
    act = read_sto(out / "w_StaticOptimization_activation_sd.sto")
    assert act.column("soleus_r").max() < 1.0  # an activation's SD, not a force's


def test_bad_band_options_are_refused(tmp_path, capsys):
    _refused(tmp_path, capsys, [str(MODEL), *TRIAL, "--muscle-uncertainty", "mass=10%"],
             "--muscle-uncertainty: expected PROPERTY=P%")
    _refused(tmp_path, capsys, [str(MODEL), *TRIAL, "--muscle-uncertainty", "tendon_slack_length=60%"],
             "--muscle-uncertainty: tendon_slack_length: expected a relative standard deviation in [0, 0.5)")
    _refused(tmp_path, capsys, [str(MODEL), *TRIAL, "--criteria", "2"], "--criteria: expected exponents >= 1 other")
    _refused(tmp_path, capsys, [str(MODEL), *TRIAL, "--criteria", "20"],  # the spread's solve stopped, after the work
             "--criteria: expected exponents >= 1 other than --exponent (2) and at most 10, got 20")


def test_the_command_imports_neither_the_simulator_nor_identification_nor_plotting(tmp_path):
    """What ``casflex muscles`` loads from markers to reactions (a new process, as a user runs it): none of the
    simulator, identification's methods, the studies, the figures or scipy.sparse (they cost it 0.3 s of imports)."""
    import subprocess
    import sys

    heavy = ("casflex.simulate", "casflex.integrators", "casflex.identification.problem", "casflex.study",
             "casflex.plotting", "dask", "matplotlib", "scipy.sparse")
    argv = ["muscles", str(MODEL), *TRIAL, "--actuators", RESERVES, "--joints", "knee_r", "--quiet",
            "--out", str(tmp_path)]
    code = (f"import sys\nfrom casflex.cli import main\nassert main({argv!r}) == 0\n"
            f"print(sorted(m for m in sys.modules if m.startswith({heavy!r})))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "[]"
