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


def test_jit_scratch_directory_is_the_working_directory_only_inside_the_block():
    cwd = os.getcwd()
    with codegen.jit_working_directory(True):
        inside = os.getcwd()
    assert inside != cwd and os.getcwd() == cwd
    assert codegen.jit_options()["jit_options"]["directory"] == inside
    with codegen.jit_working_directory(False):
        assert os.getcwd() == cwd
