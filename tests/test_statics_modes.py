"""Modes about a configuration that is, or is not, a static equilibrium (casflex.statics.modes);
the frequencies themselves are checked against Euler-Bernoulli and the physical pendulum in
test_statics.py."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from conftest import pendulum
from statics_scenes import three_link_chain

import casflex
from casflex.cli import main
from casflex.statics import StabilityWarning, equilibrium, modes


def test_modes_about_a_configuration_that_is_not_an_equilibrium_warn():
    # The chain straight and inclined at 60 degrees is stress-free and swings under gravity: the
    # "frequencies" about it include a negative one that is only the missing preload.
    model = casflex.assemble(three_link_chain(math.radians(60)))
    with pytest.warns(StabilityWarning, match="not a static equilibrium.*largest on.*small vibrations"):
        res = modes(model, count=3)
    assert not res.equilibrium and res.residual > 1e-6  # measured 3.9e-6 (scaled)
    assert res.freq_hz[0] < 0.0


def test_modes_about_an_equilibrium_do_not_warn():
    model = casflex.assemble(three_link_chain(math.radians(60)))
    st = equilibrium(model)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = modes(model, q=st.q, count=3)
    assert res.equilibrium and res.residual <= 1e-10  # converged to tol = 1e-10 (measured ~1e-17)
    # Hanging at rest every mode is a vibration, the lowest a pendulum swing of the whole chain:
    # measured 0.392 Hz. Not a truth, a magnitude check: a uniform rigid rod as long as the hanging
    # chain (2.2 m) swings at sqrt(3 g / (2 * 2.2 m)) / 2 pi = 0.41 Hz.
    assert 0.3 < res.freq_hz[0] < 0.5 and np.all(np.diff(res.freq_hz) > 0)


def test_modes_warn_when_the_supports_are_violated():
    model = casflex.assemble(pendulum(2))
    q = equilibrium(model).q
    q[0] += 1e-3  # the pinned node moved: not an admissible configuration
    with pytest.warns(StabilityWarning, match="supports are not satisfied.*xpivot"):
        modes(model, q=q, count=1)


def test_modes_command_warns_about_the_initial_configuration(tmp_path, capsys):
    path = tmp_path / "chain3.toml"
    casflex.save_scene(three_link_chain(math.radians(60)), path)
    assert main(["modes", str(path), "--count", "3"]) == 0
    out = capsys.readouterr()
    (line,) = out.err.strip().splitlines()
    assert line.startswith("casflex: warning: modes about a configuration that is not a static equilibrium")
    assert line.endswith("(--about equilibrium)")
    assert "Hz" in out.out
    assert main(["modes", str(path), "--count", "3", "--about", "equilibrium", "--max-iter", "40"]) == 0
    out = capsys.readouterr()
    assert out.err == "" and "stable (smallest tangent eigenvalue" in out.out


def test_modes_command_too_many_modes_is_one_line(capsys):
    assert main(["modes", "twobar", "--count", "100"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--count: twobar has 12 free motions" in err[0]
