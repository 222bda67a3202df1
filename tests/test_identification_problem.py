"""Shared pieces of the identification methods: Gauss-Newton statistics and the polish."""

from __future__ import annotations

import math

import numpy as np
import pytest

import casflex
from casflex.identification import Solver
from casflex.identification.problem import gauss_newton_polish, gauss_newton_statistics

NAMES = ("a", "b", "c")


def test_covariance_equals_the_inverse_normal_matrix_block():
    # independent truth: s^2 [(J^T J)^-1]_pp on a well-conditioned problem with nuisance unknowns
    rng = np.random.default_rng(0)
    J = rng.normal(size=(40, 6))
    r = rng.normal(size=40)
    st = gauss_newton_statistics(J, r, 3, NAMES)
    s2 = r @ r / (40 - 6)
    cov = s2 * np.linalg.inv(J.T @ J)[:3, :3]
    np.testing.assert_allclose(list(st["std_errors"].values()), np.sqrt(np.diag(cov)), rtol=1e-10)
    np.testing.assert_allclose(st["correlation"], cov / np.outer(np.sqrt(np.diag(cov)), np.sqrt(np.diag(cov))),
                               rtol=1e-9, atol=1e-12)


def test_undetermined_parameters_get_infinite_standard_errors_and_are_weak():
    # b and c enter only through b + c: neither is determined; a is. Inverting J^T J gave
    # negative variances clipped to 0 (a confident zero error) on such problems.
    rng = np.random.default_rng(1)
    x = rng.normal(size=(30, 3))
    J = np.column_stack([x[:, 0], x[:, 1], x[:, 1], x[:, 2]])  # a, b, c, one nuisance unknown
    st = gauss_newton_statistics(J, rng.normal(size=30) * 1e-3, 3, NAMES, p=np.ones(3))
    se = st["std_errors"]
    assert math.isfinite(se["a"]) and se["a"] > 0
    assert se["b"] == math.inf and se["c"] == math.inf
    assert set(st["weak"]) == {"b", "c"}


def test_polish_keeps_a_non_finite_start():
    def zJ(w):
        return np.array([w[0] - 1.0]), np.array([[1.0]])

    w, taken = gauss_newton_polish(zJ, np.array([np.nan]), np.array([-np.inf]), np.array([np.inf]))
    assert taken == 0 and np.isnan(w[0])
    w, taken = gauss_newton_polish(zJ, np.array([3.0]), np.array([-np.inf]), np.array([np.inf]))
    assert taken == 1 and w[0] == 1.0


def test_polish_returns_a_point_inside_the_bounds():
    # least squares optimum at w = -1, below the bound 0: IPOPT stops a relaxed hair outside
    def zJ(w):
        return np.array([w[0] + 1.0, w[1] - 2.0]), np.eye(2)

    w, taken = gauss_newton_polish(zJ, np.array([-3e-9, 1.5]), np.array([0.0, -np.inf]), np.array([np.inf, np.inf]))
    assert w[0] == 0.0  # at its bound, not outside it; the step towards -1 is refused
    assert taken == 0  # the full Gauss-Newton step leaves the bounds, so none is taken


def test_one_option_path_checks_every_front_end_before_any_work():
    """The direct, adapted direct, indirect and shooting-NLP front ends share the Solver value: a bad option
    is named before the model is touched (None stands in for the model and data here)."""
    from casflex.identification import identify_adapted_direct, identify_direct, identify_indirect
    from casflex.identification.shooting_nlp import identify_nlp

    calls = {"identify_direct": lambda **o: identify_direct(None, None, [0.1], **o),
             "identify_adapted_direct": lambda **o: identify_adapted_direct(None, None, [0.1], **o),
             "identify_nlp": lambda **o: identify_nlp(None, None, 1.0, **o)}
    for name, call in calls.items():
        with pytest.raises(TypeError, match=rf"{name}\(\) got an unexpected keyword argument 'solvr'"):
            call(solvr="ipopt")
        with pytest.raises(ValueError, match="solver 'nosuch': not"):
            call(solver=Solver("nosuch"))
        with pytest.raises(ValueError, match="transform: expected one of"):
            call(solver=Solver(transform="exp"))
        with pytest.raises(ValueError, match="hessian: expected one of"):
            call(solver=Solver(hessian="bfgs"))
        with pytest.raises(ValueError, match="compiled: expected True or False"):
            call(solver=Solver(compiled="yes"))
        with pytest.raises(ValueError, match="solver 'gauss-newton': the indirect method's single shooting"):
            call(solver=Solver("gauss-newton"))
    with pytest.raises(ValueError, match="solver_options: expected a dict"):
        identify_indirect(None, None, solver=Solver(options=["tol", 1]))


def test_nlp_options_record_and_defaults():
    o = Solver(transform="log", compiled=None).nlp_options("f", hessian="exact")
    assert (o.solver, o.transform, o.hessian, o.compiled) == ("ipopt", "log", "exact", None)
    assert o.record() == {"transform": "log", "hessian": "exact", "compiled": False}


def test_nlp_options_given_to_gauss_newton_are_refused():
    from casflex.identification import identify_indirect

    for key, value in (("solver_options", {"ipopt": {"max_wall_time": 60}}), ("hessian", "exact")):
        with pytest.raises(ValueError, match=rf"{key}: an NLP solver's option, and the solver is 'gauss-newton'"):
            identify_indirect(None, None, solver=Solver(**{key.removeprefix("solver_"): value}))


def test_a_rest_angle_is_scaled_by_a_radian_at_least():
    """An offset near zero is no typical magnitude: a rest angle of 0.06 rad scaled by 0.06 made the fit
    crawl (issue 26); its decision variable is the angle in radians then, the stiffness's its nominal."""
    import dataclasses

    from casflex.identification.problem import parameter_scale

    scene = casflex.load_scene("twobar")
    ts = [dataclasses.replace(t, rest_angle=0.06) if t.name == "torsion1" else t for t in scene.torsion_springs]
    scene = dataclasses.replace(scene, torsion_springs=tuple(ts), parameters=(
        *scene.parameters, casflex.Parameter("rest1", "torsion1.rest_angle")))
    scale = parameter_scale(casflex.assemble(scene))
    assert scale[-1] == 1.0 and np.array_equal(scale[:-1], casflex.assemble(casflex.load_scene("twobar")).p_nominal)
