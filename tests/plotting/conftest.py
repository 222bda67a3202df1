"""Trajectories shared by the plotting tests (simulated once for the package)."""

from __future__ import annotations

import pytest

import casflex
from casflex.simulate import Stepping, simulate


@pytest.fixture(scope="package")
def twobar():
    model = casflex.assemble(casflex.load_scene("twobar"))
    return model, simulate(model, 0.2, stepping=Stepping(dt=1e-3))


@pytest.fixture(scope="package")
def twobar_soft(twobar):
    model, _ = twobar
    return simulate(model, 0.2, stepping=Stepping(dt=1e-3), p={"k1": 500.0, "kt1": 0.3})
