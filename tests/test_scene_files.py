"""casflex.scene.files: supports' motions and loads' tables read from .mot/.sto and CSV files."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from casflex.scene import SceneError
from casflex.scene.io import dumps_scene, load_scene, loads_scene

LAB = Path(__file__).parent / "data" / "lab"

SCENE = """
name = "from_files"
[[nodes]]
name = "a"
x = 0.0
y = 0.0
[[nodes]]
name = "b"
x = 0.5
y = 0.0
[[beams]]
name = "bar"
nodes = ["a", "b"]
E = 1e9
A = 1e-4
I = 1e-8
rho = 1000.0
[[supports]]
name = "s"
node = "a"
kind = "theta"
motion = {MOTION}
[[supports]]
name = "p"
node = "a"
kind = "pin"
[[loads]]
name = "push"
node = "b"
table = {TABLE}
"""


def _scene(tmp_path, motion: str, table: str = '{ file = "push.csv", fy = "-f" }'):
    (tmp_path / "push.csv").write_text("time,f\n0.0,1.0\n0.5,3.0\n1.0,2.0\n")
    shutil.copy(LAB / "hamner_running_stride_ik.mot", tmp_path / "ik.mot")
    path = tmp_path / "s.toml"
    path.write_text(SCENE.replace("{MOTION}", motion).replace("{TABLE}", table))
    return path


def test_motion_from_a_mot_file_in_degrees_with_offset(tmp_path):
    sc = load_scene(_scene(tmp_path, '{ file = "ik.mot", dtheta = "knee_angle_r", offset = -0.4 }'))
    rows = np.array(sc.supports[0].motion)
    ik = np.loadtxt(LAB / "hamner_running_stride_ik.mot", skiprows=7)
    assert np.allclose(rows[:, 0], ik[:, 0] - 0.4)  # the file's times plus the offset
    assert np.allclose(rows[:, 3], np.radians(ik[:, 3] - ik[0, 3]), atol=1e-12)  # degrees, from the first row
    assert np.allclose(np.array(sc.loads[0].table)[:, 2], [-1.0, -3.0, -2.0])  # negated, N
    again = loads_scene(dumps_scene(sc))  # saved with the rows inline: self-contained
    assert again == sc


def test_motion_filtered_at_a_cutoff(tmp_path):
    t = np.arange(0.0, 2.0 + 1e-9, 0.01)
    slow, fast = 0.3 * np.sin(2 * np.pi * t), 0.05 * np.sin(2 * np.pi * 20 * t)
    lines = (f"{a!r},{b!r}" for a, b in zip(t.tolist(), (slow + fast).tolist(), strict=True))
    (tmp_path / "wave.csv").write_text("time,th\n" + "\n".join(lines))
    rows = np.array(load_scene(_scene(tmp_path, '{ file = "wave.csv", dtheta = "th", cutoff = 6.0 }'))
                    .supports[0].motion)
    mid = slice(50, 150)  # away from the ends' padding
    # the 2nd-order Butterworth run twice: |H|^2 = 1 / (1 + (f / fc)^4) (prewarped): 0.9992 at 1 Hz, 0.006 at 20 Hz;
    # what is left of the 20 Hz wave is under 1 % of it, the 1 Hz one loses under 0.2 %
    got = rows[mid, 3] - rows[mid, 3].mean()  # the motion starts from the first (filtered) row: no constant
    err = got - (slow[mid] - slow[mid].mean())
    assert np.abs(err).max() < 0.01 * 0.05 + 0.002 * 0.3


@pytest.mark.parametrize(("motion", "match"), [
    ('{ file = "none.mot", dtheta = "x" }', r"supports\[0\].motion.file: no such file"),
    ('{ file = "ik.mot", dtheta = "knee" }', r"motion.dtheta: no column 'knee' in the file; its columns are"),
    ('{ file = "ik.mot", fy = "knee_angle_r" }', r"motion: unknown field 'fy'; a table from a file takes"),
    ('{ dtheta = "knee_angle_r" }', "missing field 'file'"),
    ('{ file = "ik.mot", dtheta = "knee_angle_r", cutoff = 40.0 }', "motion.cutoff: cutoff: must lie between 0 and"),
    ('{ file = "ik.mot", dtheta = "knee_angle_r", offset = "soon" }', "motion.offset: expected a number"),
])
def test_bad_file_inputs_are_one_line(tmp_path, motion, match):
    with pytest.raises(SceneError, match=match):
        load_scene(_scene(tmp_path, motion))
