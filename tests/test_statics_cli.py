"""``casflex static`` and ``casflex modes`` with the statics options: wrong options are one line
(exit 2, nothing written), failures name command-line options only, and an unstable but
converged equilibrium exits 0 with one warning line."""

from __future__ import annotations

import math
import re

import pytest
from conftest import STEEL, cantilever

import casflex
from casflex.cli import main

CASES = [
    ("static twobar --tol 0", r"argument --tol: must be a tolerance > 0, got 0"),
    ("static twobar --seek fastest", r"argument --seek: invalid choice: 'fastest'"),
    ("static twobar --min-increment 2", r"argument --min-increment: must be a share of the full load in \(0, 1\]"),
    ("static twobar --max-iter 0", r"argument --max-iter: must be a number of iterations >= 1, got 0"),
    ("static twobar --to-factor 2", r"--to-factor: only with --path"),
    ("static twobar --path spline", r"argument --path: invalid choice: 'spline'"),
    ("static twobar --path arc-length --max-points 1", r"argument --max-points: must be a number of points >= 2"),
    ("static twobar --path arc-length --monitor nosuch", r"--monitor: unknown dof 'nosuch'; dofs are \['x1'"),
    ("static twobar --path arc-length --out p.csv", r"--out: 'p.csv' must end in .npz"),
    ("modes twobar --max-iter 3", r"--max-iter: only with --about equilibrium"),
    ("modes twobar --count 100", r"--count: twobar has 12 free motions, so at most 12 modes; got 100"),
]


@pytest.mark.parametrize("argv, match", CASES, ids=[c[0] for c in CASES])
def test_a_wrong_statics_option_is_one_line_exit_2_and_writes_nothing(argv, match, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code = main(argv.split())
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("casflex: error: "), err
    assert re.search(match, err[0]), err[0]
    assert list(tmp_path.iterdir()) == []


def test_a_failure_names_command_line_options_only(tmp_path, capsys):
    scene = tmp_path / "circle.toml"
    EI = STEEL["E"] * STEEL["I"]
    casflex.save_scene(cantilever(16, load=(0.0, 0.0, 2 * math.pi * EI)), scene)
    assert main(["static", str(scene), "--max-iter", "1", "--out", str(tmp_path / "x.npz")]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("casflex: error: static equilibrium not reached")
    assert "--max-iter 4" in line and "--min-increment 1e-05" in line
    for python_name in ("max_iter", "min_increment=", "steps=", "q_start", "seek="):
        assert python_name not in line
    assert not (tmp_path / "x.npz").exists()
    # path following's last resort names its options the same way
    assert main(["static", "twobar", "--path", "arc-length"]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "singular or not positive definite" in line and "q_start" not in line


def test_an_unstable_equilibrium_exits_0_with_one_warning_line(tmp_path, capsys):
    scene = tmp_path / "column.toml"
    P = 1.5 * math.pi**2 * STEEL["E"] * STEEL["I"] / 4
    casflex.save_scene(cantilever(8, 1.0, STEEL["E"], 0.1, STEEL["I"], load=(-P, 0.0, 0.0)), scene)
    assert main(["static", str(scene), "--seek", "nearest"]) == 0
    out = capsys.readouterr()
    (line,) = out.err.strip().splitlines()
    assert line.startswith("casflex: warning: the static equilibrium is UNSTABLE: smallest tangent eigenvalue -")
    assert line.endswith("--seek stable looks for a stable one")
    assert "  UNSTABLE: smallest tangent eigenvalue" in out.out
    # By default the column buckles; the straight equilibrium it left is reported, and nothing warns.
    assert main(["static", str(scene)]) == 0
    out = capsys.readouterr()
    assert out.err == "" and "  stable (smallest" in out.out
    assert "passed an unstable equilibrium at load factor 1 (smallest tangent eigenvalue -" in out.out
