"""``casflex identify``: the three methods from the command line, data files, option errors and exit codes."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import signal
import time

import pytest

import casflex
from casflex.cli import main
from casflex.data import load_measurements, save_measurements
from casflex.simulate import simulated_set

K1 = 700.0  # N/m, twobar's nominal spring1.k


@pytest.fixture(scope="module")
def twobar_data(tmp_path_factory):
    """The simulated set of twobar to 0.692 s, written as .csv and .npz: {suffix: path}."""
    model = casflex.assemble(casflex.load_scene("twobar"))
    data = simulated_set(model, t_end=0.692, dt=1e-3)
    d = tmp_path_factory.mktemp("identify-data")
    return {ext: save_measurements(data, d / f"twobar.{ext}") for ext in ("csv", "npz")}


def _run(argv: list[str], capsys) -> tuple[int, str, str]:
    code = main(["identify", "twobar", *argv])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def test_direct_on_the_simulated_set(tmp_path, capsys):
    out = tmp_path / "direct.json"
    code, text, _ = _run(["--method", "direct", "--instants", "0.69", "--start", "1.2", "--out", str(out)], capsys)
    assert code == 0
    assert "EXIT: Optimal Solution Found" in text  # IPOPT's log is shown without --quiet
    assert "direct identification with ipopt" in text and f"wrote {out}" in text
    res = json.loads(out.read_text())
    for key in ("parameters", "start", "success", "status", "iterations", "wall_s", "solver", "method", "instants"):
        assert key in res
    assert res["method"] == "direct" and res["solver"] == "ipopt" and res["success"] is True
    assert res["start"]["k1"] == pytest.approx(1.2 * K1)
    assert res["parameters"]["k1"] == pytest.approx(K1, rel=1e-6)
    assert res["instants"] == pytest.approx([0.69])
    assert res["extra"]["data"]["kind"] == "simulated"


def test_adapted_direct(tmp_path, capsys):
    out = tmp_path / "adapted.json"
    code, text, _ = _run(["--method", "adapted-direct", "--instants", "0.4", "1.1", "--start", "1.2", "--quiet",
                          "--out", str(out)], capsys)
    assert code == 0
    assert "EXIT:" not in text and "adapted-direct identification with ipopt" in text  # --quiet: no solver log
    res = json.loads(out.read_text())
    assert res["method"] == "adapted-direct" and res["success"] is True
    assert res["parameters"]["k1"] == pytest.approx(K1, rel=1e-5)
    assert res["instants"] == pytest.approx([0.4, 1.1])


def test_indirect_single_shooting(tmp_path, capsys):
    out = tmp_path / "indirect.json"
    code, text, _ = _run(["--method", "indirect", "--transcription", "single-shooting", "--horizon", "0.05",
                          "--start", "1.2", "--dofs", "x3,y3,x5,y5", "--quiet", "--out", str(out)], capsys)
    assert code == 0, text
    assert "horizon 0.05 s, single-shooting, residue positions" in text
    res = json.loads(out.read_text())
    assert res["method"] == "indirect" and res["success"] is True
    assert res["extra"]["transcription"] == "single-shooting" and res["extra"]["dofs"] == ["x3", "y3", "x5", "y5"]
    assert res["extra"]["steps"] == 50
    assert res["parameters"]["k1"] == pytest.approx(K1, rel=1e-6)


@pytest.mark.parametrize("ext", ["csv", "npz"])
def test_data_file_round_trip(ext, twobar_data, tmp_path, capsys):
    out = tmp_path / "file.json"
    path = twobar_data[ext]
    assert load_measurements(path).t.size == 693
    code, text, _ = _run(["--method", "direct", "--data", str(path), "--start", "0.8", "--quiet", "--out", str(out)],
                         capsys)
    assert code == 0
    assert f"data: {path}, 693 samples of x1, y1, theta1" in text
    res = json.loads(out.read_text())
    assert res["parameters"]["k1"] == pytest.approx(K1, rel=1e-6)
    assert res["extra"]["data"] == {"kind": "file", "path": str(path), "samples": 693,
                                    "channels": list(load_measurements(path).channels)}


def test_noise_on_a_data_file_is_seeded_and_reported(twobar_data, tmp_path, capsys):
    outs = [tmp_path / "a.json", tmp_path / "b.json"]
    for out in outs:
        code, text, _ = _run(["--method", "direct", "--data", str(twobar_data["npz"]), "--noise", "1e-9",
                              "--seed", "3", "--quiet", "--out", str(out)], capsys)
        assert code in (0, 1)
        assert "Gaussian noise of std 1e-09 (m, rad) added to the positions (seed 3)" in text
    a, b = (json.loads(o.read_text()) for o in outs)
    assert a["parameters"] == b["parameters"]
    assert a["extra"]["data"]["noise"] == 1e-9 and a["extra"]["data"]["seed"] == 3


@pytest.mark.parametrize("argv, match", [
    (["--method", "direct", "--horizon", "0.1"], "--horizon: applies to the indirect method only"),
    (["--method", "adapted-direct", "--transcription", "single-shooting"], "--transcription: applies to the indirect"),
    (["--method", "direct", "--dofs", "x5"], "--dofs: applies to the indirect"),
    (["--method", "indirect", "--instants", "0.1"], "--instants: applies to the direct methods"),
    (["--method", "indirect", "--transcription", "single-shooting", "--interval", "5"], "--interval: applies to"),
    (["--method", "direct", "--start", "1.2", "--start-values", "1", "2", "3", "4"], "--start and --start-values"),
    (["--method", "direct", "--start-values", "700", "0.5", "400"], r"--start-values: expected 4 values.*got 3"),
    (["--method", "direct", "--start", "-1"], "argument --start: must be a factor of the nominal values > 0, got -1"),
    (["--method", "indirect", "--dofs", "x5,z9"], "--dofs: unknown dof 'z9'"),
    (["--method", "indirect", "--dofs", "x5,,y5"], "--dofs: empty name"),
    (["--method", "direct", "--solver", "nosuch"], "--solver: 'nosuch' is neither gauss-newton nor an available"),
    (["--method", "direct", "--noise", "1e-3"], "--noise: the simulated set is exact"),
    (["--method", "direct", "--data", "measured", "--noise", "-1"], "argument --noise: must be a standard deviation"),
    (["--method", "direct", "--data", "measured", "--seed", "1"], "--seed: seeds the noise"),
    (["--method", "indirect", "--horizon", "0.0505"], "--horizon: 0.0505 s is not a whole number"),
    (["--method", "indirect", "--horizon", "-1"], "argument --horizon: must be a time in s > 0, got -1"),
    (["--method", "direct", "--instants", "-0.5"], "argument --instants: must be a time in s >= 0, got -0.5"),
    (["--method", "direct", "--data", "nosuch.csv"], "nosuch.csv: no such file"),
    (["--method", "direct", "--data", "data.txt"], "data.txt: unknown extension '.txt'"),
])
def test_bad_options_exit_2_with_one_line(argv, match, capsys):
    code, _, err = _run(argv, capsys)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1
    assert lines[0].startswith("casflex: error:")
    assert re.search(match, lines[0]), lines[0]


def test_bad_method_is_an_argparse_error(capsys):
    assert main(["identify", "twobar", "--method", "bogus"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("casflex: error: argument --method: invalid choice: 'bogus'")


def test_unknown_channel_in_a_file(tmp_path, capsys):
    path = tmp_path / "bad.csv"
    path.write_text("t,x5,x9\n0,1,2\n0.001,1,2\n")
    code, _, err = _run(["--method", "indirect", "--data", str(path), "--horizon", "0.001"], capsys)
    assert code == 2 and "unknown channels ['x9']" in err


@pytest.fixture(scope="module")
def direct_result():
    """A real result of the direct method (exact data), to stand in for slow or failing solves."""
    model = casflex.assemble(casflex.load_scene("twobar"))
    from casflex.identification import identify_direct

    return identify_direct(model, simulated_set(model, t_end=0.01, dt=1e-3), [0.005])


def test_failed_identification_exits_1(direct_result, monkeypatch, tmp_path, capsys):
    failed = dataclasses.replace(direct_result, success=False, status="Maximum_Iterations_Exceeded")
    monkeypatch.setattr("casflex.identification.identify_direct", lambda *a, **k: failed)
    out = tmp_path / "failed.json"
    code, text, err = _run(["--method", "direct", "--instants", "0.005", "--quiet", "--out", str(out)], capsys)
    assert code == 1
    assert "Maximum_Iterations_Exceeded" in text and "did not succeed (Maximum_Iterations_Exceeded)" in err
    assert json.loads(out.read_text())["success"] is False  # the record is still written


def test_ctrl_c_exits_130_without_output(direct_result, monkeypatch, tmp_path, capsys):
    def swallowed(*args, **kwargs):  # as CasADi does: the solver stops and returns a failed result
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)  # the handler runs here
        except KeyboardInterrupt:
            pass
        return dataclasses.replace(direct_result, success=False, status="NonIpopt_Exception_Thrown")

    monkeypatch.setattr("casflex.identification.identify_direct", swallowed)
    before = signal.getsignal(signal.SIGINT)
    out = tmp_path / "interrupted.json"
    code, _, err = _run(["--method", "direct", "--instants", "0.005", "--quiet", "--out", str(out)], capsys)
    assert code == 130 and "interrupted" in err
    assert not out.exists()
    assert signal.getsignal(signal.SIGINT) is before  # the command's handler is gone


def test_measured_set_with_noise_for_the_indirect_method(tmp_path, capsys):
    out = tmp_path / "measured.json"
    code, text, _ = _run(["--method", "indirect", "--transcription", "single-shooting", "--horizon", "0.02",
                          "--residue", "full", "--data", "measured", "--noise", "1e-7", "--seed", "1", "--quiet",
                          "--out", str(out)], capsys)
    assert code in (0, 1)
    assert "velocities and accelerations by central differences, Gaussian noise of std 1e-07" in text
    assert "(seed 1)" in text
    res = json.loads(out.read_text())
    # measured_set drops the first and last samples of a simulation to 0.022 s: t = 0.001 .. 0.021 s
    assert res["extra"]["data"] == {"kind": "measured", "t_end": pytest.approx(0.022), "dt": 1e-3, "alpha": 0.0,
                                    "noise": 1e-7, "seed": 1, "samples": 21}
    assert res["extra"]["residue"] == "full" and res["extra"]["samples"] == 20


def test_solver_runtime_error_is_one_line(monkeypatch, capsys):
    def broken(*args, **kwargs):
        raise RuntimeError("Error in Function::call for 'direct' [Blocksqp] at .../function.cpp:1655:\n"
                           ".../casadi_os.cpp:335: Assertion \"handle!=nullptr\" failed:\n"
                           "PluginInterface::load_plugin: Cannot load shared library 'libcasadi_linsol_ma27.so':\n")

    monkeypatch.setattr("casflex.identification.identify_direct", broken)
    code, _, err = _run(["--method", "direct", "--instants", "0.005", "--quiet"], capsys)
    assert code == 2
    assert err.strip() == ("casflex: error: --solver ipopt: the solver failed: PluginInterface::load_plugin: "
                           "Cannot load shared library 'libcasadi_linsol_ma27.so':")


def test_scene_without_parameters(tmp_path, capsys):
    from conftest import cantilever

    path = tmp_path / "cantilever.toml"
    path.write_text(casflex.dumps_scene(cantilever(2)))
    code = main(["identify", str(path), "--method", "direct"])
    assert code == 2 and "declares no parameters to identify" in capsys.readouterr().err


def test_forms_and_per_channel_noise_reach_the_fit(tmp_path, capsys):
    """--vary and --sigma per channel from the command line: both ends refitted beside the other beam
    theory, the declared noise per channel recorded and checked against the residuals."""
    out = tmp_path / "forms.json"
    sigma = "x3=1e-3,y3=1e-3,x5=1e-3,y5=1e-3"
    code, text, _ = _run(["--method", "indirect", "--horizon", "0.05", "--dofs", "x3,y3,x5,y5", "--quiet",
                          "--model-error", "none", "--vary", "bar2.E=1.5e11:2.5e11", "--sigma", sigma,
                          "--out", str(out)], capsys)
    res = json.loads(out.read_text())
    assert [f["name"] for f in res["extra"]["forms"]] == [
        "beams with the section's rotary inertia (rotary_inertia = true)", "bar2.E = 1.5e+11", "bar2.E = 2.5e+11"]
    assert "form bar2.E = 1.5e+11:" in text
    noise = res["extra"]["experiments"]["data"]["noise"]
    assert noise == {"source": "declared", "channels": dict.fromkeys(("x3", "y3", "x5", "y5"), 1e-3)}
    assert code == (0 if res["success"] else 1)
