"""The output-error solver's convergence test: distance to the least-squares solution in standard errors."""

import numpy as np
from scipy.optimize import least_squares

from casflex.identification.output_error import OFFSET_TOL, Budget, chord_fit, fit, offset_in_se


def test_offset_is_the_mahalanobis_distance_of_linear_regression():
    # closed form: for r = A w - y, the distance of w to w_hat in the metric A^T A / s^2
    rng = np.random.default_rng(0)
    A = rng.normal(size=(50, 3))
    y = A @ np.array([1.0, -2.0, 0.5]) + rng.normal(0, 0.1, 50)
    w_hat = np.linalg.lstsq(A, y, rcond=None)[0]
    s = np.linalg.norm(A @ w_hat - y) / np.sqrt(50 - 3)
    w = w_hat + np.array([0.01, -0.02, 0.03])
    d, step = offset_in_se(A @ w - y, A, np.arange(3))
    assert np.isclose(d, np.sqrt((w - w_hat) @ A.T @ A @ (w - w_hat)) / s, rtol=1e-10)
    assert np.allclose(w + step, w_hat, atol=1e-12)
    # a unknown held on its bound does not count
    d_held, step_held = offset_in_se(A @ w - y, A, np.arange(2))
    assert step_held[2] == 0.0 and d_held < d


class _Decay:
    """y = a exp(-b t) + c with noise: a small nonlinear least-squares problem in fit's interface."""

    evaluations = 0

    def __init__(self, seed: int):
        self.t = np.linspace(0.0, 4.0, 80)
        self.y = 2.0 * np.exp(-1.3 * self.t) + 0.2 + np.random.default_rng(seed).normal(0, 0.01, self.t.size)

    def bounds(self):
        return np.array([0.0, 0.0, -np.inf]), np.array([np.inf, 10.0, np.inf])

    def evaluate(self, w):
        self.evaluations += 1
        e = np.exp(-w[1] * self.t)
        return w[0] * e + w[2] - self.y, np.column_stack([e, -w[0] * self.t * e, np.ones_like(e)])


def test_fit_ends_within_a_hundredth_of_a_standard_error():
    for seed in range(5):
        prob = _Decay(seed)
        f = fit(prob, np.array([1.0, 0.5, 0.0]), Budget(max_iterations=50))
        assert f.converged and f.offset <= OFFSET_TOL, (seed, f.status, f.offset)
        # the reference: scipy at its tightest tolerances, then measured in standard errors
        ref = least_squares(lambda w, pr=prob: pr.evaluate(w)[0], f.w, jac=lambda w, pr=prob: pr.evaluate(w)[1],
                            xtol=1e-15, ftol=1e-15, gtol=1e-15).x
        J = prob.evaluate(ref)[1]
        s = np.linalg.norm(prob.evaluate(ref)[0]) / np.sqrt(prob.t.size - 3)
        se = s * np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
        assert np.all(np.abs(f.w - ref) <= OFFSET_TOL * se), (seed, (f.w - ref) / se)


class _Nearby(_Decay):
    """The decay seen through a slightly other model (a factor 1 + eps t, as a refined mesh or another form
    changes a model's motion): its own least-squares solution, a Jacobian near _Decay's; runs counted by kind."""

    def __init__(self, seed: int, eps: float):
        super().__init__(seed)
        self.eps, self.plain = eps, 0

    def evaluate(self, w, jacobian=True):
        self.plain += not jacobian
        r, J = super().evaluate(w)
        f = 1 + self.eps * self.t
        e = np.exp(-w[1] * self.t) * f
        return w[0] * e + w[2] - self.y, (np.column_stack([e, -w[0] * self.t * e, np.ones_like(e)]) if jacobian
                                          else None)


def test_chord_fit_reaches_the_nearby_problems_own_solution_with_plain_runs():
    for seed in range(3):
        base = _Decay(seed)
        f = fit(base, np.array([1.0, 0.5, 0.0]), Budget(max_iterations=50))
        near = _Nearby(seed, 1e-2)  # moves the solution by more than a standard error
        g = chord_fit(near, f.w, f.J, Budget(max_iterations=30))
        exact = fit(_Nearby(seed, 1e-2), f.w, Budget(max_iterations=50), near=True)
        r, J = _Nearby(seed, 1e-2).evaluate(exact.w)
        se = np.linalg.norm(r) / np.sqrt(r.size - 3) * np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
        assert g is not None and g.converged and g.status == "chord", (seed, g)
        assert np.max(np.abs(exact.w - f.w) / se) > 1.0  # the nearby solution is elsewhere, so the test bites
        # within the fit's own tolerance of the exact fit: the fixed point's offset is eps-sized in SE
        assert np.all(np.abs(g.w - exact.w) <= OFFSET_TOL * se), (seed, (g.w - exact.w) / se)
        assert near.plain == near.evaluations == g.iterations + 1  # no run with sensitivities


def test_chord_fit_gives_way_where_the_borrowed_jacobian_is_far():
    base = _Decay(0)
    f = fit(base, np.array([1.0, 0.5, 0.0]), Budget(max_iterations=50))
    # a Jacobian 3 x too large: each step a third of the way, not the fall CHORD_RATE asks for
    assert chord_fit(_Nearby(0, 2e-3), f.w, 3 * f.J, Budget(max_iterations=30)) is None
