"""Static equilibrium with the default options (casflex.statics.equilibrium): a pinned steel chain
hangs, a column buckles, unstable equilibria are reported, increments adapt, and errors speak
the caller's language. Truths: statics of a hanging chain, the elastica of a clamped-free column
(elliptic integrals). Every tolerance carries a one-line reason.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from conftest import STEEL, cantilever
from scipy.optimize import brentq
from scipy.special import ellipe, ellipk
from statics_scenes import BAR, CHAIN, three_link_chain

import casflex
from casflex.cli import main
from casflex.cli.statics import NAMES
from casflex.statics import StabilityWarning, StaticOptions, StaticsError, equilibrium

G = 9.81
E, I = STEEL["E"], STEEL["I"]
EI = E * I


# -- pinned three-link chain --------------------------------------------------------------------


def hanging_chain() -> tuple[np.ndarray, np.ndarray]:
    """Truth: the chain hangs straight down below the pin. Each spring stretches by the weight
    below it over k; each bar (one linear element: nodally exact in pure extension) by its axial
    force, weight below + half its own weight, times L / EA. Returns y of A, B1, B2, C1, C2, D (m)
    and the pin's reaction (x, y) (N)."""
    L, gap, (k1, k2) = CHAIN["bar"], CHAIN["gap"], CHAIN["k"]
    EA = BAR["E"] * BAR["A"]
    w = BAR["rho"] * BAR["A"] * L * G  # weight of one bar
    drops = [L + 2.5 * w * L / EA, gap + 2 * w / k1, L + 1.5 * w * L / EA, gap + w / k2, L + 0.5 * w * L / EA]
    return -np.concatenate([[0.0], np.cumsum(drops)]), np.array([0.0, 3 * w])


def check_hanging(q: np.ndarray, lam: np.ndarray) -> None:
    y_true, reaction = hanging_chain()
    nodes = q.reshape(-1, 3)
    # Positions: the final Newton update leaves an error ~update^2; measured 4e-16 m (round-off).
    assert np.max(np.abs(nodes[:, 0])) <= 1e-12
    assert np.max(np.abs(nodes[:, 1] - y_true)) <= 1e-12
    # Every bar (and node) points straight down, modulo full turns; measured 2e-16 rad.
    assert np.max(np.abs(np.angle(np.exp(1j * (nodes[:, 2] + math.pi / 2))))) <= 1e-12
    # The pin carries the total weight 287 N; round-off of a steel bar's axial force is
    # eps EA = 1.2e-7 N (measured 5e-8 N).
    assert np.allclose(-lam, reaction, rtol=0.0, atol=2e-7)


@pytest.mark.parametrize("degrees", [60, 150])
def test_pinned_chain_hangs_straight_down_with_the_defaults(degrees):
    # Started straight and stress-free, inclined 60 (or 150, above the horizontal) degrees from the
    # downward vertical: a mechanism of stiff bars on soft springs, which plain Newton with 10 or 40
    # equal load steps did not bring down.
    model = casflex.assemble(three_link_chain(math.radians(degrees)))
    res = equilibrium(model)
    assert res.success and res.load_factors == (1.0,) and res.cuts == 0
    check_hanging(res.q, res.lam)
    assert res.stable and res.stability.kind == "stable"
    assert res.iterations <= 30  # measured 15 and 22


def test_pinned_chain_through_the_command_line(tmp_path, capsys):
    path = tmp_path / "chain3.toml"
    casflex.save_scene(three_link_chain(math.radians(60)), path)
    assert main(["static", str(path), "--out", str(tmp_path / "eq.npz")]) == 0
    out = capsys.readouterr()
    assert "stable (smallest tangent eigenvalue" in out.out and out.err == ""
    with np.load(tmp_path / "eq.npz") as z:
        check_hanging(z["q"], z["lam"])
        assert bool(z["stable"]) and list(z["load_factors"]) == [1.0]


# -- a column past its buckling load ----------------------------------------------------------


def elastica_column(ratio: float) -> tuple[float, float, float]:
    """Clamped-free inextensible column under an axial tip load P = ratio * P_cr, P_cr = pi^2 EI /
    (4 L^2): sqrt(P / EI) L = K(k), k = sin(alpha / 2). Returns the tip rotation alpha (rad), the
    lateral tip deflection 2 k L / K and the tip's distance from the clamp along the axis, L (2
    E(k) / K(k) - 1), lengths in units of L."""
    K = math.sqrt(ratio) * math.pi / 2
    m = brentq(lambda m: ellipk(m) - K, 0.0, 1.0 - 1e-15)  # m = k^2
    k = math.sqrt(m)
    return 2 * math.asin(k), 2 * k / K, 2 * ellipe(m) / ellipk(m) - 1


def column(n: int):
    # A deep section (A L^2 / I = 1e8): axial strain P / EA = 4e-8, negligible next to the mesh error,
    # so the inextensible elastica is the truth. The load is 1.5 times the continuous Euler load; the
    # mesh's own buckling load is within 0.1 % of it at n = 8 (test_statics_path), far from the 50 % margin.
    P = 1.5 * math.pi**2 * EI / 4
    return casflex.assemble(cantilever(n, 1.0, E, 0.1, I, load=(-P, 0.0, 0.0)))


def test_column_buckles_by_default_and_reports_the_straight_equilibrium_it_left():
    alpha, delta, x_tip = elastica_column(1.5)
    got = {}
    for n in (8, 16):
        model = column(n)
        res = equilibrium(model)
        x, y, th = res.q[3:6]  # the tip node
        got[n] = np.array([abs(th), abs(y), x])
        assert res.stable  # the buckled column is a minimum
        # ... reached through the straight column, a saddle: recorded with its negative eigenvalue.
        (left,) = res.left
        assert left.load_factor == 1.0 and left.min_eigenvalue < 0.0
        assert np.max(np.abs(left.q[1::3])) <= 1e-12 and np.max(np.abs(left.q[2::3])) <= 1e-12  # straight
        assert "left 1 unstable equilibrium" in res.message
    truth = np.array([alpha, delta, x_tip])
    e8, e16 = np.abs(got[8] - truth), np.abs(got[16] - truth)
    # Co-rotational discretisation error, second order: measured 8.4e-4 rad, 1.9e-4 L, 1.1e-3 L at n = 16.
    assert np.all(e16 <= [1e-3, 2.5e-4, 1.3e-3])
    assert np.all((e8 / e16 > 3.8) & (e8 / e16 < 4.2))  # O(h^2): measured ratios 3.99-4.02
    # Richardson extrapolation leaves O(h^4): measured 4.5e-6 at most, so the mesh converges to the elastica.
    assert np.max(np.abs((4 * got[16] - got[8]) / 3 - truth)) <= 1e-5


def test_column_with_seek_nearest_returns_the_straight_unstable_equilibrium_with_a_warning():
    model = column(8)
    with pytest.warns(StabilityWarning, match="UNSTABLE"):
        res = equilibrium(model, seek="nearest")
    assert not res.stable and res.stability.kind == "unstable" and res.stability.negative == 1
    assert res.stability.min_eigenvalue < -res.stability.threshold
    assert np.max(np.abs(res.q[1::3])) <= 1e-12  # straight: plain Newton never leaves the axis
    # The critical mode is the buckling mode: lateral, largest at the tip, rotations all of one sign.
    mode = res.stability.mode
    assert np.argmax(np.abs(mode[1::3])) == 1 and np.all(mode[5::3] * mode[5] >= 0)


# -- adaptive load stepping and messages --------------------------------------------------------


def circle(n: int = 16):
    return casflex.assemble(cantilever(n, load=(0.0, 0.0, 2 * math.pi * EI / 1.0)))


def test_a_failed_increment_is_cut_and_the_next_grows():
    # With only 8 iterations per increment the full end moment (12 iterations) fails; halved
    # increments converge and the same circle results.
    model = circle()
    ref = equilibrium(model)
    res = equilibrium(model, max_iter=8)
    assert res.cuts >= 1 and res.load_factors[-1] == 1.0
    assert all(b > a for a, b in zip(res.load_factors, res.load_factors[1:], strict=False))
    steps = np.diff((0.0,) + res.load_factors)
    assert steps.max() > steps.min()  # the increments adapted (measured 0.25 ... 0.5)
    assert np.max(np.abs(res.q - ref.q)) <= 1e-9  # both converged to tol (measured 3e-15)


def test_failure_names_what_to_try_in_the_callers_terms():
    model = circle()
    with pytest.raises(StaticsError) as info:
        equilibrium(model, max_iter=1)
    msg = str(info.value)
    assert "load increment" in msg and "cut 10 times" in msg and "scaled residual" in msg
    assert "max_iter=4" in msg and "min_increment=1e-05" in msg
    with pytest.raises(StaticsError) as info:
        equilibrium(model, max_iter=1, names=NAMES)
    msg = str(info.value)
    assert "--max-iter 4" in msg and "--min-increment 1e-05" in msg
    assert "max_iter" not in msg and "q_start" not in msg and "steps=" not in msg


def test_no_equilibrium_without_a_support_against_the_load():
    sc = cantilever(2, load=(0.0, -1.0, 0.0))
    sc = type(sc)(**{**sc.__dict__, "supports": ()})
    with pytest.raises(StaticsError, match="no support fixes any y dof.*net y component of -1 N.*singular"):
        equilibrium(casflex.assemble(sc))


def test_options_are_checked_by_name():
    model = circle(2)
    for bad, match in [({"seek": "lowest"}, "seek"), ({"tol": 0.0}, "tol"), ({"max_iter": 0}, "max_iter"),
                       ({"min_increment": 2.0}, "min_increment"), ({"steps": 1.5}, "steps")]:
        with pytest.raises(ValueError, match=match):
            equilibrium(model, **bad)
    with pytest.raises(TypeError, match="unknown static option"):
        equilibrium(model, step=3)
    opts = StaticOptions(tol=1e-12)
    assert equilibrium(model, options=opts, max_iter=60).success  # options and overrides combine


def test_a_stable_result_does_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = equilibrium(casflex.assemble(three_link_chain()))
    assert res.stable
