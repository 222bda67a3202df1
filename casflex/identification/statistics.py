"""Uncertainty that stays honest when the model is inexact, and the analysis of residuals.

The plain Gauss-Newton covariance s^2 (J^T J)^-1 (:func:`~casflex.identification.problem.
gauss_newton_statistics`) assumes independent residuals of equal variance. Fitted to a real
system, the residuals of an output-error fit are not: what the model gets wrong is smooth in time,
so neighbouring residuals are correlated and the plain standard errors are too small (on twobar
data from another code, the truth lay more than 3 of them away). Two corrections:

- :func:`sandwich_covariance`: the heteroscedasticity and autocorrelation consistent (HAC)
  covariance (J^T J)^-1 Omega (J^T J)^-1, Omega the long-run covariance of the scores
  g_t = J_t^T r_t summed over the channels of each sample time, with Bartlett weights up to a
  bandwidth chosen from the data (Andrews 1991, AR(1) plug-in, Newey and West 1994);
- a discretisation error estimate from a refit on a refined model (output_error.py), since a
  bias is not a variance and no covariance of the residuals can hold it.

The direct methods' residuals are equations of motion at a few instants, whose positions,
velocities and accelerations come from smoothed measurements: one instant's errors enter all its
equations together, with dof-dependent sizes. :func:`instant_robust_std_errors` clusters the
sandwich by instant and reports the larger of it and Gauss-Newton's (threelink at 1 mm: the truth
lay up to 3.9 Gauss-Newton standard errors away in 6 of 10 successful direct fits).

:func:`residual_analysis` reports, per channel, the RMS (the noise level the fit implies), the
autocorrelation and the Ljung-Box whiteness test.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy import stats

__all__ = ["sandwich_covariance", "bartlett_bandwidth", "residual_analysis", "instant_robust_std_errors"]


def bartlett_bandwidth(scores: np.ndarray) -> int:
    """Andrews' (1991) bandwidth for the Bartlett kernel with an AR(1) plug-in: 1.1447 (a n)^(1/3),
    a = 4 rho^2 / (1 - rho^2)^2 from the lag-1 autocorrelation rho of each score column (weighted
    by their variances); at least 1, at most n - 1. scores: (n, k), in time order."""
    n = scores.shape[0]
    if n < 3:
        return max(n - 1, 0)
    x = scores - scores.mean(axis=0)
    var = (x**2).sum(axis=0)
    ok = var > 0
    if not ok.any():
        return 1
    rho = np.clip((x[1:, ok] * x[:-1, ok]).sum(axis=0) / var[ok], -0.99, 0.99)
    w = var[ok] / var[ok].sum()
    a = float(np.sum(w * 4 * rho**2 / (1 - rho**2) ** 2))
    return int(min(n - 1, max(1, math.ceil(1.1447 * (a * n) ** (1 / 3)))))


def sandwich_covariance(J: np.ndarray, r: np.ndarray, groups: list[np.ndarray], bandwidth: int | None = None,
                        bread: np.ndarray | None = None,
                        information: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, Any]]:
    """HAC covariance of all unknowns of a least-squares fit.

    J : (m, n) Jacobian of the residuals r (m,) at the optimum. groups : for every experiment,
    the rows of each of its sample times in time order (a list of index arrays per experiment,
    flattened as ``groups[e][t]``); experiments are independent. ``bread`` : (m,) factors of the
    rows in the sandwich's bread J^T diag(bread) J, for an M-estimator fitted by reweighting (J, r
    reweighted): psi'(u) / w(u) per row, 1 for least squares (Huber's loss: 0 where a sample is
    weighted down). ``information`` : (n, n) the priors' information (rows of J that no group holds, e.g. a
    maximum a posteriori fit's prior rows): its own term of the meat, as they are independent of the data's
    residuals and of unit variance by construction. Returns the (n, n) covariance (pseudo-inverse where the
    bread is singular: such directions are reported by the Gauss-Newton statistics) and {"bandwidth": per experiment,
    "scores_lag1": lag-1 autocorrelation}.
    """
    n = J.shape[1]
    U, s, Vt = np.linalg.svd(J if bread is None else np.sqrt(bread)[:, None] * J, full_matrices=False)
    keep = s > max(J.shape) * np.finfo(float).eps * (s[0] if s.size else 0.0)
    Hinv = (Vt[keep].T / s[keep] ** 2) @ Vt[keep]
    omega = np.zeros((n, n)) if information is None else np.array(information, dtype=float)
    info: dict[str, Any] = {"bandwidth": [], "scores_lag1": []}
    for exp_groups in groups:
        g = np.array([J[rows].T @ r[rows] for rows in exp_groups])  # (T, n) scores per sample time
        L = bartlett_bandwidth(g) if bandwidth is None else int(bandwidth)
        x = g
        omega += x.T @ x
        for lag in range(1, min(L, len(g) - 1) + 1):
            gamma = x[lag:].T @ x[:-lag]
            omega += (1 - lag / (L + 1)) * (gamma + gamma.T)
        info["bandwidth"].append(L)
        c = g - g.mean(axis=0)
        den = (c**2).sum()
        info["scores_lag1"].append(float((c[1:] * c[:-1]).sum() / den) if den > 0 else 0.0)
    m = J.shape[0]
    # small-sample factor m / (m - n), as the plain estimate's s^2 = r^T r / (m - n)
    return Hinv @ omega @ Hinv * (m / max(m - n, 1)), info


def instant_robust_std_errors(J: np.ndarray, r: np.ndarray, n_instants: int, se_gn: np.ndarray,
                              dp_dtheta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(standard errors, cluster-robust ones) of the first len(se_gn) unknowns of a direct fit.

    J (m, n), r (m,): the residuals at the optimum, ``n_instants`` equal blocks of rows in order
    (one per instant). The cluster-robust sandwich (one cluster per instant, factor G/(G-1) on
    top of m/(m-n), Cameron and Miller 2015) allows correlated, unequal errors within an instant;
    with few instants it is itself uncertain, so the reported error is the larger of the two,
    per parameter. An undetermined parameter (Gauss-Newton's infinite error) stays undetermined.
    """
    m, n_p = J.shape[0], se_gn.size
    rows = m // n_instants
    if n_instants < 2 or rows * n_instants != m:
        return se_gn.copy(), np.full(n_p, np.nan)
    groups = [[np.arange(i * rows, (i + 1) * rows)] for i in range(n_instants)]  # instants independent
    C, _ = sandwich_covariance(J, r, groups, bandwidth=0)
    se_cl = np.sqrt(np.maximum(np.diag(C)[:n_p], 0.0) * n_instants / (n_instants - 1)) * np.abs(dp_dtheta)
    se = np.where(np.isinf(se_gn), np.inf, np.fmax(se_gn, se_cl))
    return se, se_cl


def residual_analysis(r: np.ndarray, channel: np.ndarray, names: tuple[str, ...], groups: list[np.ndarray],
                      noise: float | Mapping[str, float] | None = None, lags: int = 20) -> dict[str, Any]:
    """Per channel: RMS (the noise level the fit implies, in the data's units), its ratio to the
    declared ``noise`` (if any: one value, or one per channel name), the autocorrelation at lags
    1..``lags`` and the Ljung-Box test of whiteness (Q statistic, p-value; white at the 1 % level
    when p > 0.01).

    r : (m,) residuals in the data's units; channel : (m,) index into ``names`` of each residual;
    groups : the rows of each experiment in time order (one array per experiment).
    """
    out: dict[str, Any] = {}
    for c, name in enumerate(names):
        series = [r[rows][channel[rows] == c] for rows in groups]
        series = [x for x in series if x.size]
        if not series:
            continue
        allr = np.concatenate(series)
        rms = float(np.sqrt(np.mean(allr**2)))
        n = sum(x.size for x in series)
        h = int(min(lags, max(1, min(x.size for x in series) // 5)))
        acf = np.zeros(h)
        den = sum(float(((x - x.mean()) ** 2).sum()) for x in series)
        for k in range(1, h + 1):
            acf[k - 1] = sum(float(((x[k:] - x.mean()) * (x[:-k] - x.mean())).sum()) for x in series if x.size > k) \
                / den if den > 0 else 0.0
        q = n * (n + 2) * float(np.sum(acf**2 / (n - np.arange(1, h + 1))))
        p = float(stats.chi2.sf(q, h))
        declared = noise.get(name) if isinstance(noise, Mapping) else noise
        out[name] = {"rms": rms, "samples": n, "noise_ratio": rms / declared if declared else None,
                     "acf": acf.tolist(), "ljung_box_q": q, "ljung_box_lags": h, "ljung_box_p": p,
                     "white": bool(p > 0.01)}
    return out
