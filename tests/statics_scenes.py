"""Scenes of the statics tests (plain functions, imported as ``from statics_scenes import ...``
under pytest's default import mode, like ``conftest``)."""

from __future__ import annotations

import math

from casflex import Beam, Load, Node, Scene, Spring, Support, TorsionSpring

#: Steel bars of the three-link chain (twobar's section): E (Pa), A (m^2), I (m^4), rho (kg/m^3).
BAR = {"E": 2.1e11, "A": 25e-4, "I": 52.1e-8, "rho": 7800.0}
#: Chain geometry: bar length and joint gap (m), joint spring stiffnesses k (N/m) and kt (N m/rad).
CHAIN = {"bar": 0.5, "gap": 0.1, "k": (700.0, 400.0), "kt": 0.5}


def three_link_chain(angle: float = math.pi / 3) -> Scene:
    """Three steel bars of 0.5 m pinned at the top node ``A`` (0, 0), started straight and stress-free
    at ``angle`` (rad) from the downward vertical, under gravity.

    The joints are twobar's: a linear spring (rest length 0.1 m, the gap) and a torsion spring
    between the end of one bar and the start of the next. Nodes along the chain: A - bar1 - B1 ~
    s1/t1 ~ B2 - bar2 - C1 ~ s2/t2 ~ C2 - bar3 - D. Every bar is one element.
    """
    bar, gap = CHAIN["bar"], CHAIN["gap"]
    d = (math.sin(angle), -math.cos(angle))
    arc = (0.0, bar, bar + gap, 2 * bar + gap, 2 * bar + 2 * gap, 3 * bar + 2 * gap)
    names = ("A", "B1", "B2", "C1", "C2", "D")
    th = angle - math.pi / 2  # direction of the chain
    nodes = tuple(Node(nm, s * d[0], s * d[1], theta=th) for nm, s in zip(names, arc, strict=True))
    beams = tuple(Beam(f"bar{i + 1}", (names[2 * i], names[2 * i + 1]), **BAR) for i in range(3))
    springs = (Spring("s1", ("B1", "B2"), k=CHAIN["k"][0]), Spring("s2", ("C1", "C2"), k=CHAIN["k"][1]))
    torsion = (TorsionSpring("t1", ("B1", "B2"), kt=CHAIN["kt"]), TorsionSpring("t2", ("C1", "C2"), kt=CHAIN["kt"]))
    return Scene(name="chain3", nodes=nodes, beams=beams, springs=springs, torsion_springs=torsion,
                 supports=(Support("pin", "A", "pin"),), gravity=(0.0, -9.81))


def von_mises_truss(a: float = 1.0, h: float = 0.5, k: float = 1000.0, P: float = 100.0) -> Scene:
    """Two linear springs (stiffness k, N/m) from supports at (-a, 0) and (a, 0) to the apex (0, h),
    loaded by P (N) downwards at the apex. Springs do not act on rotations: the supports are
    clamps and the apex's rotation has a support of its own. No gravity."""
    return Scene(
        name="vonmises",
        nodes=(Node("L", -a, 0.0), Node("R", a, 0.0), Node("apex", 0.0, h)),
        springs=(Spring("left", ("L", "apex"), k=k), Spring("right", ("R", "apex"), k=k)),
        supports=(Support("pinL", "L", "clamp"), Support("pinR", "R", "clamp"), Support("noturn", "apex", "theta")),
        loads=(Load("P", "apex", fy=-P),),
        gravity=(0.0, 0.0),
    )


def two_beam_frame(a: float = 1.0, h: float = 0.04, P: float = 1000.0, elements: int = 4) -> Scene:
    """A shallow frame: two steel beams from pinned supports at (-a, 0) and (a, 0) to the apex (0, h),
    joined rigidly there (they share its rotation), loaded by P (N) downwards at the apex. Section
    A = 1e-4 m^2, I = 1e-8 m^4 (radius of gyration 1 cm, rise h / r = 4): shallow enough for the
    symmetric limit point to come before any asymmetric bifurcation. No gravity."""
    th = math.atan2(h, a)
    sec = {"E": 2.1e11, "A": 1e-4, "I": 1e-8, "rho": 7800.0, "elements": elements}
    return Scene(
        name="frame",
        nodes=(Node("L", -a, 0.0, theta=th), Node("R", a, 0.0, theta=-th), Node("apex", 0.0, h)),
        beams=(Beam("left", ("L", "apex"), **sec), Beam("right", ("apex", "R"), **sec)),
        supports=(Support("pinL", "L", "pin"), Support("pinR", "R", "pin")),
        loads=(Load("P", "apex", fy=-P),),
        gravity=(0.0, 0.0),
    )
