"""C export: the generated example builds with the system compiler and reproduces Python."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

import casflex
from casflex.simulate import Stepping, simulate
from casflex.simulate.export import export_c

needs_cc = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")


@pytest.fixture(scope="module")
def twobar():
    return casflex.assemble(casflex.load_scene("twobar"))


@needs_cc
def test_exported_simulation_matches_python(twobar, tmp_path):
    e = export_c(twobar, tmp_path, what="simulate", t_end=0.3, dt=1e-3, alpha=-0.05)
    exe = e.build()
    subprocess.run([str(exe)], check=True, cwd=tmp_path, timeout=60)
    csv = np.loadtxt(tmp_path / "trajectory.csv", delimiter=",", skiprows=1)
    header = (tmp_path / "trajectory.csv").read_text().splitlines()[0].split(",")
    assert header == ["t", *twobar.dof_names]
    tr = simulate(twobar, 0.3, stepping=Stepping(dt=1e-3, alpha=-0.05))
    assert csv.shape == (301, 1 + twobar.n_dof)
    # 1e-10 m: the bar; the same generated code runs in both, so it is ~0 in practice
    np.testing.assert_allclose(csv[:, 0], tr.t, atol=1e-12)
    np.testing.assert_allclose(csv[:, 1:], tr.q, atol=1e-10)
    assert (tmp_path / "README.md").read_text().count("hht_step(") == 1


@needs_cc
def test_exported_slider_crank_starts_where_python_does_and_matches_it(tmp_path):
    # ideal joints and a moving support: the example starts from simulate()'s consistent state (the
    # support on its path, the joints' velocities projected), not from the scene's node velocities
    model = casflex.assemble(casflex.load_scene("slidercrank"))
    exe = export_c(model, tmp_path, what="simulate", t_end=0.2, dt=1e-3).build()
    subprocess.run([str(exe)], check=True, cwd=tmp_path, timeout=60)
    csv = np.loadtxt(tmp_path / "trajectory.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(csv[:, 1:], simulate(model, 0.2, stepping=Stepping(dt=1e-3)).q, atol=1e-10)  # as above


@needs_cc
def test_exported_direct_residual_builds_and_lists_functions(twobar, tmp_path):
    e = export_c(twobar, tmp_path, what="direct")
    assert e.functions == ("equilibrium", "jac_equilibrium")
    assert e.build().name == "libcasflex_model.a"
    assert "jac_equilibrium" in (tmp_path / "casflex_model.h").read_text()


def test_bad_export_options(twobar, tmp_path):
    with pytest.raises(ValueError, match="what"):
        export_c(twobar, tmp_path, what="everything")
    with pytest.raises(ValueError, match="whole number of steps"):
        export_c(twobar, tmp_path, t_end=0.0105, dt=1e-3)


@needs_cc
def test_cli_export_writes_and_builds(tmp_path, capsys):
    from casflex.cli import main

    assert main(["export", "twobar", "--out", str(tmp_path), "--what", "simulate", "--t-end", "0.05", "--build"]) == 0
    out = capsys.readouterr().out
    assert "hht_step" in out and (tmp_path / "simulate").exists()
    assert main(["export", "twobar", "--out", str(tmp_path), "--t-end", "0.0105"]) == 2
    assert "whole number of steps" in capsys.readouterr().err
