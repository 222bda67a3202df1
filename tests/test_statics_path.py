"""Equilibrium paths by arc-length continuation (casflex.statics.equilibrium_path and ``casflex
static --path``): snap-through of a von Mises truss against its closed form, the limit point of a
shallow two-beam frame, the bifurcation of a straight column. Every tolerance carries a reason."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import STEEL, cantilever
from statics_scenes import three_link_chain, two_beam_frame, von_mises_truss

import casflex
from casflex.cli import main
from casflex.statics import StaticsError, equilibrium, equilibrium_path

# von Mises truss: half-span a, rise h (m), spring stiffness k (N/m), reference load P (N).
A_, H, K, P = 1.0, 0.5, 1000.0, 100.0
L0 = math.hypot(A_, H)


def truss_load(u: np.ndarray) -> np.ndarray:
    """Closed form: the apex load P(w) = 2 k (L0 - L)(h - w) / L at apex height u = h - w (N)."""
    L = np.hypot(A_, u)
    return 2 * K * (L0 - L) * u / L


#: The limit point: dP/du = 2 k (L0 a^2 / (a^2 + u^2)^(3/2) - 1) = 0 at u*.
U_LIMIT = math.sqrt((L0 * A_**2) ** (2 / 3) - A_**2)
P_LIMIT = float(truss_load(np.array(U_LIMIT)))


def test_von_mises_truss_snaps_through_along_its_closed_form():
    model = casflex.assemble(von_mises_truss(A_, H, K, P))
    to = 2 * P_LIMIT / P  # twice the limit load: the stable equilibrium there is on the inverted branch
    path = equilibrium_path(model, to_factor=to)
    u = path.q[:, model.dof("yapex")]
    # Every point is on the closed-form curve: tol bounds the force error by tol k l = 2e-7 N
    # (5e-9 of the limit load); measured 3e-15 of it (round-off).
    assert np.max(np.abs(path.load_factors * P - truss_load(u))) <= 5e-9 * P_LIMIT
    assert np.max(np.abs(path.q[:, model.dof("xapex")])) <= 1e-12  # symmetric: no sway (exactly 0)
    # Past the limit point, through the flat position and the lower limit point, to the inverted branch.
    assert path.status == "reached" and path.load_factors[-1] == to
    assert u[-1] < -H and u.min() < -U_LIMIT < U_LIMIT < u.max()
    # Stability along the path is the sign of the truss's own stiffness dP/dw = -dP/du > 0.
    stiff = 2 * K * (L0 * A_**2 / (A_**2 + u**2) ** 1.5 - 1) < 0
    assert np.array_equal(path.stable, stiff)
    assert path.stable[0] and path.stable[-1] and not path.stable.all()
    # Both limit points are located: loads +-P* to round-off (measured 1e-15 relative), at u = +-u*.
    upper, lower = path.critical
    assert upper.kind == lower.kind == "limit"
    assert upper.load_factor * P == pytest.approx(P_LIMIT, rel=1e-9)
    assert lower.load_factor * P == pytest.approx(-P_LIMIT, rel=1e-9)
    # The eigenvalue crosses zero linearly in u, so u* is located as closely as the eigenvalue's zero
    # (measured 3e-16 m).
    assert upper.q[model.dof("yapex")] == pytest.approx(U_LIMIT, abs=1e-9)
    assert lower.q[model.dof("yapex")] == pytest.approx(-U_LIMIT, abs=1e-9)
    assert abs(upper.eigenvalue) <= 1e-12 and abs(lower.eigenvalue) <= 1e-12
    # Solved at that load directly, from the unloaded start, the minimiser snaps to the same inverted
    # state (both converged to tol; measured 2e-16 m apart).
    st = equilibrium(casflex.assemble(von_mises_truss(A_, H, K, to * P)))
    assert st.stable and st.q[model.dof("yapex")] == pytest.approx(u[-1], abs=1e-12)


def test_two_beam_frame_is_traced_through_its_limit_point():
    model = casflex.assemble(two_beam_frame())
    path = equilibrium_path(model)
    # Every point is an equilibrium, checked with the model's own force Functions (not the statics
    # code): |f_int + B^T lam - s (f_ext + g)| at most 1e-6 N against loads of 1000 N (tol bounds it
    # by 1e-10 EA/L l = 4e-3 N; measured 1.6e-8 N).
    f_ext = np.asarray(model.load(0.0, model.p_nominal)).ravel()
    for s, q, lam in zip(path.load_factors, path.q, path.lam, strict=True):
        _, f_int, g = (np.asarray(v).ravel() for v in model.forces(q, np.zeros(model.n_dof), model.p_nominal))
        B = np.asarray(model.constraint(q)[1])
        assert np.max(np.abs(f_int + B.T @ lam - s * (f_ext + g))) <= 1e-6
    first = path.critical[0]
    assert first.kind == "limit" and path.status == "reached"
    i = first.after
    # The limit load is the largest load on the way up (measured 0.6156, 1.3 % above the point before it).
    assert first.load_factor >= path.load_factors[: i + 2].max()
    assert path.stable[: i + 1].all() and not path.stable[i + 1]
    # Independent check by load control: just below the limit load the minimiser stays on the near
    # branch (apex above the limit point's height), just above it the frame snaps through.
    y_lim = first.q[model.dof("yapex")]
    below = equilibrium(casflex.assemble(two_beam_frame(P=1000.0 * 0.999 * first.load_factor)))
    above = equilibrium(casflex.assemble(two_beam_frame(P=1000.0 * 1.001 * first.load_factor)))
    assert below.q[model.dof("yapex")] > y_lim > 0.0 > above.q[model.dof("yapex")]


def test_straight_column_bifurcates_at_the_mesh_buckling_load():
    # Along the straight path of a perfect column the stability changes without a turn of the load:
    # a bifurcation, at the discrete Euler load of the mesh, which converges to P_cr = pi^2 EI / (4 L^2)
    # from above at second order (co-rotational Hermite elements): measured +1.29 % and +0.315 %.
    EI = STEEL["E"] * STEEL["I"]
    P_cr = math.pi**2 * EI / 4
    excess = []
    for n in (4, 8):
        model = casflex.assemble(cantilever(n, 1.0, STEEL["E"], 0.1, STEEL["I"], load=(-P_cr, 0.0, 0.0)))
        path = equilibrium_path(model, to_factor=1.5)
        (bif,) = path.critical
        assert bif.kind == "bifurcation"
        assert np.max(np.abs(path.q[:, 1::3])) <= 1e-12  # the path stays straight
        assert path.stable[path.load_factors < bif.load_factor].all()
        assert not path.stable[path.load_factors > bif.load_factor].any()
        excess.append(bif.load_factor - 1.0)
    assert 0.0 < excess[1] < 0.004 and 3.8 < excess[0] / excess[1] < 4.4


def test_a_path_from_a_mechanism_at_rest_is_refused():
    with pytest.raises(StaticsError, match="singular or not positive definite"):
        equilibrium_path(casflex.assemble(three_link_chain()))


def test_path_arguments_are_checked():
    model = casflex.assemble(von_mises_truss())
    for kw, match in [({"to_factor": 0.0}, "to_factor"), ({"max_points": 1}, "max_points"),
                      ({"arc_length": -1.0}, "arc_length")]:
        with pytest.raises(ValueError, match=match):
            equilibrium_path(model, **kw)


def test_path_stops_at_max_points():
    path = equilibrium_path(casflex.assemble(von_mises_truss()), max_points=5)
    assert path.status == "max_points" and len(path.load_factors) == 5 and "stopped after 5 points" in path.message


def test_static_path_command(tmp_path, capsys):
    scene = tmp_path / "vonmises.toml"
    casflex.save_scene(von_mises_truss(A_, H, K, P), scene)
    to = 2 * P_LIMIT / P
    assert main(["static", str(scene), "--path", "arc-length", "--to-factor", f"{to:.17g}",
                 "--out", str(tmp_path / "path.npz")]) == 0
    out = capsys.readouterr().out
    assert out.count("<- limit point") == 2 and "yapex (m)" in out and "UNSTABLE (1)" in out
    with np.load(tmp_path / "path.npz") as z:
        k = z["load_factors"].size
        assert z["q"].shape == (k, 9) and z["stable"].shape == (k,) and str(z["monitor"]) == "yapex"
        assert list(z["critical_kind"]) == ["limit", "limit"]
        assert z["critical_load_factor"][0] * P == pytest.approx(P_LIMIT, rel=1e-9)  # as in the API test
