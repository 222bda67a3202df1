"""casflex.codegen: compiler flags, the library cache, the JIT scratch directory."""

from __future__ import annotations

import os
import platform
import shutil

import numpy as np
import pytest
from conftest import twobar_meshed

import casflex
from casflex import codegen
from casflex.simulate import simulate

pytestmark = pytest.mark.skipif(shutil.which(os.environ.get("CC", "gcc")) is None, reason="needs a C compiler")


def test_the_native_flag_probe_is_remembered_per_compiler_and_processor(tmp_path, monkeypatch):
    monkeypatch.setenv("CASFLEX_CACHE", str(tmp_path))
    codegen._native_flags.cache_clear()
    flags = codegen._native_flags("gcc")
    assert flags in ((), ("-march=native",), ("-march=native", "-mno-fma"))
    (note,) = tmp_path.glob("native2-*.txt")
    assert note.read_text().split() == list(flags)
    note.write_text("-O0")  # a later process reads the note instead of probing again
    codegen._native_flags.cache_clear()
    assert codegen._native_flags("gcc") == ("-O0",)
    codegen._native_flags.cache_clear()


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"), reason="bitwise equality is claimed on x86-64")
@pytest.mark.parametrize("alpha, elements", [(0.0, 1), (-0.05, 1), (0.0, 16)])
def test_compiled_steps_are_bitwise_the_interpreted_ones(alpha, elements):
    # alpha = -0.05 differed in the last bit at step 14 when gcc's vectoriser fused multiply-adds
    # (-march=native without -mno-fma); 16 elements per bar run the mapped element kernels
    model = casflex.assemble(twobar_meshed(elements))
    a = simulate(model, 0.3, dt=1e-3, alpha=alpha)
    b = simulate(model, 0.3, dt=1e-3, alpha=alpha, compiled=True)
    for x, y in ((a.q, b.q), (a.qd, b.qd), (a.qdd, b.qdd), (a.lam, b.lam), (a.outputs, b.outputs)):
        assert np.array_equal(x, y)


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
