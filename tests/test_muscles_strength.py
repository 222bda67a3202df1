"""A muscle's max isometric force against its body's weight (casflex.muscles.strength): the absurd refused before
the inverse dynamics, the implausible said on stderr and in the report, the repo's models neither."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from casflex.cli import main
from casflex.lab.plate_checks import scene_mass
from casflex.muscles.strength import ABSURD, STRONG, check_strength
from casflex.scene.from_osim import scene_from_osim

DATA = Path(__file__).parent / "data" / "muscles"
LAB = Path(__file__).parent / "data" / "lab"
MODEL = DATA / "hamner_subject02_planar_muscles.osim"  # soleus_r 3549 N on 65.9 kg: 5.5 body weights
TRIAL = ["--coordinates", str(DATA / "hamner_run_ik.mot"), "--loads", str(LAB / "hamner_running_whole_grf.mot"),
         "--plate", "calcn_r=ground_", "--plate", "calcn_l=1_ground_", "--actuators",
         str(DATA / "hamner_reserve_actuators.xml"), "--joints", "hip_r", "--t-end", "0.6", "--quiet"]


def _soleus(tmp_path: Path, force: str) -> str:
    """Hamner's model with soleus_r's max isometric force (3549 N) replaced by ``force``."""
    text = MODEL.read_text()
    i = text.index("<max_isometric_force>", text.index('name="soleus_r"'))
    j = text.index("</max_isometric_force>", i)
    assert text[i:j].endswith(">3549")
    path = tmp_path / "model.osim"
    path.write_text(f"{text[:i]}<max_isometric_force>{force}{text[j:]}")
    return str(path)


@pytest.mark.parametrize("name", ["hamner_subject02_planar_muscles.osim", "gait10dof18musc.osim",
                                  "rajagopal_walk_planar_muscles.osim", "rajagopal_planar_wraps.osim"])
def test_the_repo_s_models_are_neither_refused_nor_said(name):
    """Their strongest muscles pull 5.5, 7.0, 7.4 and 8.4 times the model's weight (limits 20 and 100)."""
    osim = scene_from_osim(DATA / name, muscles=True)
    weight = scene_mass(osim.scene) * float(np.hypot(*osim.scene.gravity))
    assert check_strength(osim.muscles, weight) == []
    top = max(m.max_isometric_force for m in osim.muscles) / weight
    assert 5.0 < top < 9.0 < STRONG  # the margin the docstring states


def test_a_force_of_3_5e8_n_is_refused_before_any_work(tmp_path, capsys):
    """It gave exit 0 with the ankle's reaction at 7875 body weights and the reserves at 3e5 % of its moment."""
    out = tmp_path / "out"
    code = main(["muscles", _soleus(tmp_path, "3.5e8"), *TRIAL, "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 2 and not captured.out and not out.exists()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0] == (
        f"casflex: error: {tmp_path / 'model.osim'}: ForceSet: Thelen2003Muscle 'soleus_r'.max_isometric_force: "
        "3.5e+08 N, 5.42e+05 times the model's weight (646 N): no muscle pulls more than 100 times its body's weight "
        "and 20000 N (a human's strongest 5-9 body weights, some 6 kN): a typo or another unit; give the force in N")


def test_a_force_ten_times_too_large_is_said_on_stderr_and_in_the_report(tmp_path, capsys):
    """35490 N: 55 body weights, a human muscle's force typed with a digit too many; the run goes on."""
    out = tmp_path / "out"
    code = main(["muscles", _soleus(tmp_path, "35490"), *TRIAL, "--out", str(out)])
    captured = capsys.readouterr()
    said = ("ForceSet: Thelen2003Muscle 'soleus_r'.max_isometric_force: 3.549e+04 N, 54.9 times the model's weight "
            "(646 N); a human's strongest muscles pull 5-9 body weights")
    assert code == 0
    assert [ln for ln in captured.err.splitlines() if said in ln][0].startswith("casflex: warning: ")
    assert said in captured.out  # the report's summary


def test_a_model_of_a_leg_is_measured_against_a_third_of_its_plates():
    """A leg's 25 kg (246 N) with its soleus of 5137 N is 21 times its own weight; a stance of 1500 N (two body
    weights of a 76 kg runner) makes the weight 500 N: 10 times, not said. Below 20 kN nothing is refused, whatever
    the weight (a finger's flexor)."""
    from casflex.scene.muscles import Muscle

    soleus = Muscle("soleus_r", "Thelen2003Muscle", 5137.0, 0.05, 0.25, 0.44, 10.0, (), ())
    assert check_strength([soleus], 246.0)[0].startswith("Thelen2003Muscle 'soleus_r'.max_isometric_force: 5137 N, "
                                                         "20.9 times the model's weight (246 N)")
    assert check_strength([soleus], 246.0, plates=1500.0) == []
    finger = Muscle("fdp", "Thelen2003Muscle", 300.0, 0.05, 0.25, 0.0, 10.0, (), ())
    assert "times the model's weight (0 N)" in check_strength([finger], 0.49)[0]  # said, not refused
    with pytest.raises(ValueError, match=r"'soleus_r'.max_isometric_force: 2.5e\+04 N, 102 times"):
        check_strength([Muscle("soleus_r", "Thelen2003Muscle", ABSURD * 246.0 + 400.0, 0.05, 0.25, 0.0, 10.0, (),
                               ())], 246.0)
