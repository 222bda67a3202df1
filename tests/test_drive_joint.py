"""The ``drive`` joint (an actuated hinge driven at an angle by a driver node): its moment on a
driven pendulum against the closed form, its outputs and its refusals."""

from __future__ import annotations

import numpy as np
import pytest
from inverse_scenes import INERTIA, A, C, M, W, driven_pendulum, pendulum

from casflex.scene import SceneError
from casflex.scene.io import loads_scene
from casflex.simulate import Stepping, simulate


def test_drive_moment_is_the_closed_form():
    tr = simulate(loads_scene(driven_pendulum()), 1.0, stepping=Stepping(dt=1e-3, alpha=-0.1))
    th, thdd = A * np.sin(W * tr.t), -A * W * W * np.sin(W * tr.t)
    tau = (INERTIA + M * C * C) * thdd + M * 9.81 * C * np.sin(th)
    assert np.abs(tr.output("act.angle") - th).max() < 1e-6  # the path's spline through 100 Hz rows
    late = tr.t > 0.1  # past the start's O(dt) transient of the index-3 multipliers
    # the spline's acceleration error (h^2/12 A W^4 (I + m c^2) = 0.006 N m) and HHT's first-order multiplier
    # error at alpha = -0.1 (measured 0.011 N m in all at dt = 1e-3): bound 4x that, 0.7 % of the peak
    assert np.abs(tr.output("act.moment") - tau)[late].max() < 0.05
    # the drive, not the hinge, holds the moment: the hinge's force is the arm's weight and inertia only
    assert np.abs(tr.output("pivot.fy")).max() < 2 * M * (9.81 + C * (A * W) ** 2 + C * A * W * W)


def test_drive_needs_three_different_nodes():
    with pytest.raises(SceneError, match=r"expected \[a, b, driver\]"):
        loads_scene(pendulum('[[joints]]\nname = "act"\nkind = "drive"\nnodes = ["base", "link"]\n'))
    with pytest.raises(SceneError, match="the nodes must differ"):
        loads_scene(pendulum('[[joints]]\nname = "act"\nkind = "drive"\nnodes = ["base", "link", "base"]\n'))
    with pytest.raises(SceneError, match="point: does not apply to a drive"):
        loads_scene(pendulum('[[nodes]]\nname = "d"\nx = 0.0\ny = 0.0\n[[joints]]\nname = "act"\nkind = "drive"\n'
                             'nodes = ["base", "link", "d"]\npoint = [0.0, 0.0]\n'))
