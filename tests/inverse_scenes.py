"""Small scenes for tests/test_inverse.py: a pendulum on a base, with markers (TOML text)."""

from __future__ import annotations

import numpy as np

#: pendulum: arm mass (kg), centre of mass below the pivot (m), inertia about it (kg m^2)
M, C, INERTIA = 2.0, 0.3, 0.05
#: the base's mass and inertia
M_BASE, I_BASE = 1.0, 0.01
#: a driven swing: A sin(W t) (rad)
A, W = 0.7, 2 * np.pi * 1.3


def pendulum(extra: str = "") -> str:
    """A base node (body, two markers) and an arm hanging from a hinge at the base node (two markers)."""
    return f"""
name = "pendulum"
gravity = [0.0, -9.81]
[[nodes]]
name = "base"
x = 0.0
y = 1.0
[[nodes]]
name = "link"
x = 0.0
y = 1.0
theta = {-np.pi / 2!r}
[[bodies]]
name = "base"
node = "base"
mass = {M_BASE}
inertia = {I_BASE}
[[bodies]]
name = "arm"
node = "link"
mass = {M}
inertia = {INERTIA}
com_x = 0.0
com_y = {1.0 - C}
[[joints]]
name = "pivot"
kind = "hinge"
nodes = ["base", "link"]
[[markers]]
name = "b1"
on = "base"
x = 0.1
y = 1.0
label = "BASE.1"
[[markers]]
name = "b2"
on = "base"
x = -0.1
y = 1.05
label = "BASE.2"
[[markers]]
name = "m1"
on = "arm"
x = 0.0
y = 0.2
label = "ARM.1"
[[markers]]
name = "m2"
on = "arm"
x = 0.05
y = 0.6
label = "ARM.2"
{extra}"""


def driven_pendulum(dt_table: float = 0.01) -> str:
    """The pendulum driven through a ``drive`` joint at the angle A sin(W t) (a driver node turned by a
    moving clamp), its base clamped."""
    ts = np.arange(0.0, 1.2 + 1e-9, dt_table)
    motion = ", ".join(f"[{t:.6f}, 0.0, 0.0, {float(A * np.sin(W * t))!r}]" for t in ts)
    return pendulum(f"""
[[nodes]]
name = "drv"
x = 0.0
y = 0.0
omega = {A * W!r}
[[supports]]
name = "ground"
node = "base"
kind = "clamp"
[[supports]]
name = "drv"
node = "drv"
kind = "clamp"
motion = [{motion}]
[[joints]]
name = "act"
kind = "drive"
nodes = ["base", "link", "drv"]
""").replace('name = "link"\nx = 0.0\ny = 1.0\n', f'name = "link"\nx = 0.0\ny = 1.0\nomega = {A * W!r}\n')
