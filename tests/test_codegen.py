"""casflex.codegen: compiler flags, the library cache, the JIT scratch directory."""

from __future__ import annotations

import os
import platform
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import twobar_meshed

import casflex
from casflex import codegen
from casflex.simulate import Stepping, simulate

pytestmark = pytest.mark.skipif(shutil.which(os.environ.get("CC", "gcc")) is None, reason="needs a C compiler")


def _same_function(tmp_path, monkeypatch, flags: str):
    import casadi as ca

    monkeypatch.setenv("CASFLEX_CACHE", str(tmp_path))
    monkeypatch.setenv(codegen.FLAGS_ENV, flags)
    x = ca.SX.sym("x", 2)
    return codegen.compile_functions([ca.Function("flags_probe", [x], [x[0] * x[1]])], stem="flags_probe")


def test_casflex_cflags_follow_casflex_flags_and_the_target_is_in_the_cache_key(tmp_path, monkeypatch):
    lib = _same_function(tmp_path, monkeypatch, "-O0 -march=x86-64")
    assert codegen.build_flags("-O3")[-2:] == ("-O0", "-march=x86-64")  # after casflex's own: they win
    assert codegen.bitwise_expected() == (platform.machine() in ("x86_64", "AMD64"))
    again = _same_function(tmp_path, monkeypatch, "-O0 -march=x86-64")
    assert again.cached and again.path == lib.path
    native = _same_function(tmp_path, monkeypatch, "-O0 -march=native")  # what it was built for is in the key
    assert not native.cached and native.path != lib.path and not codegen.bitwise_expected()
    assert float(native["flags_probe"]([3.0, 4.0])) == 12.0


def test_flags_the_compiler_rejects_are_named_before_any_work(monkeypatch):
    monkeypatch.setenv(codegen.FLAGS_ENV, "-march=no-such-cpu")
    with pytest.raises(codegen.CodegenError, match="CASFLEX_CFLAGS='-march=no-such-cpu'.*rejects"):
        codegen.build_flags("-O1")
    monkeypatch.setenv(codegen.FLAGS_ENV, "-O2 'unclosed")
    with pytest.raises(codegen.CodegenError, match="CASFLEX_CFLAGS: cannot split"):
        codegen.user_flags()


@pytest.mark.skipif(not codegen.bitwise_expected(), reason="bitwise equality is promised on x86-64 with the default "
                    "flags (or CASFLEX_CFLAGS of optimisation level, tuning and FMA-free targets only)")
@pytest.mark.parametrize("alpha, elements", [(0.0, 1), (-0.05, 1), (0.0, 16)])
def test_compiled_steps_are_bitwise_the_interpreted_ones(alpha, elements):
    # alpha = -0.05 differed in the last bit from step 7 when gcc's vectoriser fused multiply-adds
    # (-march=native, with or without -mno-fma on AVX-512); 16 elements per bar run the mapped kernels
    model = casflex.assemble(twobar_meshed(elements))
    a = simulate(model, 0.3, stepping=Stepping(dt=1e-3, alpha=alpha))
    b = simulate(model, 0.3, stepping=Stepping(dt=1e-3, alpha=alpha, compiled=True))
    for x, y in ((a.q, b.q), (a.qd, b.qd), (a.qdd, b.qdd), (a.lam, b.lam), (a.outputs, b.outputs)):
        assert np.array_equal(x, y)


@pytest.mark.skipif(not codegen.bitwise_expected(), reason="bitwise equality is promised on x86-64 with the default "
                    "flags (or CASFLEX_CFLAGS of optimisation level, tuning and FMA-free targets only)")
def test_a_time_dependent_scene_stays_bitwise_past_the_first_chunk():
    """A moving support (a pendulum driven at an angle) over two compiled chunks of 250 steps and a tail: the
    second chunk's steps' times (chunk start + k dt: 0.25 + 0.038) differed from n dt (0.288) in the last bit
    until the interpreted run took them the same way (q then differed by an ulp from step 288)."""
    from inverse_scenes import driven_pendulum

    from casflex.simulate import CHUNK

    model = casflex.assemble(casflex.loads_scene(driven_pendulum()))
    a = simulate(model, (2 * CHUNK + 20) * 1e-3, stepping=Stepping(dt=1e-3, alpha=-0.1))
    b = simulate(model, (2 * CHUNK + 20) * 1e-3, stepping=Stepping(dt=1e-3, alpha=-0.1, compiled=True))
    for x, y in ((a.q, b.q), (a.lam, b.lam)):
        assert np.array_equal(x, y)


def _compiled_steps_solve_the_interpreted_equations(model, alpha: float, t_end: float = 0.3, dt: float = 1e-3):
    """Every step of a compiled run, its start and end fed to the interpreted residual: at most the
    tolerance it was accepted at, plus the residual's own round-off floor (ROUNDOFF_FLOOR eps max|q/l|,
    the accuracy to which two evaluations of the scaled residual can agree)."""
    from casflex.integrators.hht import ROUNDOFF_FLOOR
    from casflex.simulate import integrator_for

    b = simulate(model, t_end, stepping=Stepping(dt=dt, alpha=alpha, compiled=True))
    hht = integrator_for(model, alpha=alpha)
    X = np.hstack([b.q, b.qd, b.qdd, b.lam])
    d = np.array(hht.scale(b.q[0], b.qd[0], b.p, dt)).ravel()
    ell = np.where(model.is_rotation, 1.0, model.length_scale)
    worst = 0.0
    for k in range(len(b.t) - 1):
        r = hht.step_residual(X[k], X[k + 1], b.t[k], b.p, dt, d)
        bound = float(hht.tolerance(b.q[k + 1])) + ROUNDOFF_FLOOR * np.finfo(float).eps * max(
            1.0, np.abs(b.q[k + 1] / ell).max())
        worst = max(worst, r / bound)
    assert worst <= 1.0, f"a compiled step leaves {worst:.2f} x the accepted residual in the interpreted equations"
    return b, worst


@pytest.mark.parametrize("alpha, elements", [(-0.05, 1), (0.0, 16)])
def test_compiled_steps_solve_the_interpreted_equations_with_the_flags_in_force(alpha, elements):
    """The promise for any CASFLEX_CFLAGS and processor: a compiled run is an HHT run of this model."""
    _compiled_steps_solve_the_interpreted_equations(casflex.assemble(twobar_meshed(elements)), alpha)


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"), reason="-march=native's FMA is an x86-64 case")
def test_a_native_build_keeps_the_promise_where_it_is_not_bitwise(tmp_path, monkeypatch):
    monkeypatch.setenv("CASFLEX_CACHE", str(tmp_path))
    monkeypatch.setenv(codegen.FLAGS_ENV, "-march=native")
    b, _ = _compiled_steps_solve_the_interpreted_equations(casflex.assemble(twobar_meshed(1)), -0.05)
    assert b.meta.get("compiled") and any(tmp_path.glob("casflex_hht-*.so"))


_BUILD_ONE = """
import casadi as ca, sys
from casflex import codegen
x = ca.SX.sym("x", 3)
f = ca.Function("cache_probe", [x], [ca.sin(x) * float(sys.argv[1])])
lib = codegen.compile_functions([f], stem="cache_probe", optimise="-O1")
print("cached" if lib.cached else "built", float(lib["cache_probe"](ca.DM([1, 2, 3]))[1]))
"""


def test_two_processes_build_a_library_once_and_a_third_pays_nothing(tmp_path):
    import subprocess
    import sys

    env = dict(os.environ, CASFLEX_CACHE=str(tmp_path))
    cmd = [sys.executable, "-c", _BUILD_ONE, "2.5"]
    procs = [subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, text=True) for _ in range(2)]
    outs = sorted(p.communicate(timeout=300)[0].split()[0] for p in procs)
    assert outs == ["built", "cached"]  # the second waited on the lock and loaded the first's library
    again = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True).stdout.split()
    assert again[0] == "cached" and float(again[1]) == pytest.approx(2.5 * np.sin(2.0), rel=1e-15)
    assert len(list(tmp_path.glob("cache_probe-*.so"))) == 1 and not list(tmp_path.glob("*.tmp"))


def test_is_cached_answers_by_the_library_key_without_compiling(tmp_path, monkeypatch):
    import casadi as ca

    monkeypatch.setenv("CASFLEX_CACHE", str(tmp_path))
    x = ca.SX.sym("x")
    f, g = ca.Function("probe_f", [x], [2 * ca.sin(x)]), ca.Function("probe_f", [x], [3 * ca.sin(x)])
    assert not codegen.is_cached([f], stem="probe", optimise="-O1") and not list(tmp_path.iterdir())
    codegen.compile_functions([f], stem="probe", optimise="-O1")
    assert codegen.is_cached([f], stem="probe", optimise="-O1")
    # another function, level or stem is another library
    assert not codegen.is_cached([g], stem="probe", optimise="-O1")
    assert not codegen.is_cached([f], stem="probe", optimise="-O3")
    assert not codegen.is_cached([f], stem="probe2", optimise="-O1")
    monkeypatch.setenv("CC", "no-such-compiler")
    assert not codegen.is_cached([f], stem="probe", optimise="-O1")  # no compiler: nothing to load


def test_a_compiled_nlp_solver_follows_the_interpreted_iterates_and_is_cached(tmp_path, monkeypatch):
    import casadi as ca

    monkeypatch.setenv("CASFLEX_CACHE", str(tmp_path))
    w = ca.MX.sym("w", 2)
    nlp = {"x": w, "f": (1 - w[0]) ** 2 + 100 * (w[1] - w[0] ** 2) ** 2}
    opts = {"ipopt.print_level": 0, "print_time": False}
    a = ca.nlpsol("rosen", "ipopt", nlp, opts)(x0=[-1.2, 1.0])
    S = codegen.compiled_nlpsol("rosen", "ipopt", nlp, opts)
    b = S(x0=[-1.2, 1.0])
    assert np.array_equal(np.array(a["x"]), np.array(b["x"]))  # the same iterates: bitwise the same answer
    assert len(codegen.cache_entries()) == 1
    codegen.compiled_nlpsol("rosen", "ipopt", nlp, opts)
    assert len(codegen.cache_entries()) == 1  # found, not built again
    count, size = codegen.clear_cache()
    assert count >= 1 and size > 0 and codegen.cache_entries() == []


_SESSION_PROBE = """
import os
from pathlib import Path

from casflex import codegen


def test_store():
    codegen.store_built("session_probe", "k", {"a": 1})
    Path(os.environ["PROBE_OUT"]).write_text(str(codegen.cache_dir()))
"""


@pytest.mark.parametrize("user_cache", [False, True])
def test_a_test_session_writes_its_cache_to_a_temporary_folder_unless_casflex_cache_is_set(tmp_path, user_cache):
    """tests/conftest.py: with CASFLEX_CACHE unset a test session caches in a folder of its own, removed at its end,
    never in ~/.cache/casflex (HOME here is a new folder); a CASFLEX_CACHE the caller set (.ci/any-machine) is kept."""
    import subprocess
    import sys

    home, out, probe = tmp_path / "home", tmp_path / "cache_dir.txt", tmp_path / "test_probe.py"
    home.mkdir()
    probe.write_text(_SESSION_PROBE)
    env = {k: v for k, v in os.environ.items() if k != "CASFLEX_CACHE"} | {
        "HOME": str(home), "PROBE_OUT": str(out),
        "PYTHONPATH": os.pathsep.join([str(os.path.dirname(__file__)), os.environ.get("PYTHONPATH", "")])}
    if user_cache:
        env["CASFLEX_CACHE"] = str(tmp_path / "mine")
    # the repository's conftest as a plugin, from tmp_path: no ini file, so no -n 2 of pyproject's addopts
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "conftest", "-p", "no:cacheprovider",
                          str(probe)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    used = Path(out.read_text())
    assert not (home / ".cache").exists(), sorted(str(p) for p in home.rglob("*"))
    if user_cache:
        assert used == tmp_path / "mine" and list(used.glob("session_probe-*"))  # kept, with what was stored
    else:
        assert used.name.startswith("casflex-test-cache-") and not used.exists()  # the session's own, removed


def test_a_built_entry_is_written_by_the_shared_atomic_write_unflushed_and_its_leftovers_cleared(tmp_path, monkeypatch):
    """store_built writes through results.atomic_write_bytes (one copy of the temporary-file-and-rename code),
    durable=False (a damaged entry is built again: no fsync); a temporary file of that writer left by a killed
    process is one ``casflex cache --clear`` removes."""
    from casflex import results

    monkeypatch.setenv("CASFLEX_CACHE", str(tmp_path))
    assert codegen.atomic_write_bytes is results.atomic_write_bytes
    calls, synced = [], []
    real = results.atomic_write_bytes
    monkeypatch.setattr(codegen, "atomic_write_bytes", lambda *a, **k: calls.append(k) or real(*a, **k))
    monkeypatch.setattr("os.fsync", synced.append)
    codegen.store_built("probe", "k" * 24, {"x": 1})
    assert calls == [{"durable": False}] and synced == [] and codegen.load_built("probe", "k" * 24) == {"x": 1}
    entry = codegen.built_entries()[0]
    left = tmp_path / f".{entry.name}.x1y2z3.tmp"  # as atomic_write_bytes names its temporary file (mkstemp)
    left.write_bytes(b"half")
    assert codegen.clear_cache()[0] == 2 and list(tmp_path.iterdir()) == []


def test_a_library_whose_write_fails_leaves_no_temporary_file(tmp_path, monkeypatch):
    """The compiled library reaches the cache through results.atomic_write_bytes, whose temporary file is removed
    when the rename fails (its own copy-and-rename left a .so.tmp behind)."""
    import casadi as ca

    monkeypatch.setenv("CASFLEX_CACHE", str(tmp_path))
    x = ca.SX.sym("x")
    real = os.replace

    def refuse(src, dst, *a, **k):
        if str(dst).endswith(".so"):
            raise OSError("disk full (simulated)")
        return real(src, dst, *a, **k)

    monkeypatch.setattr(os, "replace", refuse)
    with pytest.raises(OSError, match="disk full"):
        codegen.compiled(ca.Function("probe_write", [x], [x * x]))
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")] == []
