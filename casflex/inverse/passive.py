"""A passive joint fitted to a net joint moment: how much of it a torsion spring-damper explains.

Over a window of an inverse dynamics run (:class:`casflex.inverse.InverseResult`), the hinge's net
moment on segment b, M(t), is fitted by the moment a torsion spring-damper across the hinge would
exert there (``[[torsion_springs]]``: -kt (psi - rest_angle) - ct psi'):

    M(t) ~ -kt psi(t) + kt rest_angle - ct psi'(t)

by linear least squares in (kt, kt rest_angle, ct), psi the hinge's angle (rad, from the scene's
configuration) and psi' its rate. The report says how much of the moment that explains (R^2, the
residual's RMS against the moment's) and what the data cannot pin down: the standard errors come
from the residual, with the number of samples cut to the effective number of independent ones
(n (1 - rho) / (1 + rho), rho the residuals' lag-1 autocorrelation: filtered data and a wrong model
both leave correlated residuals; the naive errors would be too small by sqrt of that factor; where
the residual is smooth, a filter's, they are conservative).

``passive`` (the verdict) needs all of: the joint explains at least ``explained`` (default 0.8) of
the moment; a stiffness and a damping that a passive joint can have (kt > 0, ct >= 0, each within
2 standard errors); a stiffness the window decides (its standard error under half of it) from at
least 10 independent samples. A window where muscles act (stance) fails some of these, and the
summary says which: a smooth muscle moment can look 90 % "explained" by a spring with negative
damping over a few independent samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PassiveFit", "fit_passive"]


@dataclass(frozen=True)
class PassiveFit:
    """kt (N m/rad), ct (N m s/rad), rest_angle (rad) with standard errors (``se``: the same keys);
    r2: the fraction of the net moment's variance the joint explains; rms_moment, rms_residual (N m);
    n, n_effective: samples and independent ones; passive: the verdict (module docstring), ``why``: the
    reasons it is not; window (t0, t1) s."""

    hinge: str
    kt: float
    ct: float
    rest_angle: float
    se: dict
    r2: float
    rms_moment: float
    rms_residual: float
    n: int
    n_effective: float
    passive: bool
    why: tuple[str, ...]
    window: tuple[float, float]

    def summary(self) -> str:
        verdict = "passive enough" if self.passive else "not a passive joint: " + "; ".join(self.why)
        return (f"passive {self.hinge} over t = {self.window[0]:g}..{self.window[1]:g} s: kt = {self.kt:.4g} "
                f"+- {self.se['kt']:.2g} N m/rad, ct = {self.ct:.4g} +- {self.se['ct']:.2g} N m s/rad, rest angle "
                f"{self.rest_angle:.4g} +- {self.se['rest_angle']:.2g} rad (1 SE, {self.n_effective:.0f} of {self.n} "
                f"samples independent); explains {100 * self.r2:.1f} % of the net moment (RMS {self.rms_moment:.3g} "
                f"N m, residual {self.rms_residual:.3g} N m): {verdict}")


def fit_passive(res, hinge: str, t_start: float | None = None, t_end: float | None = None, *,
                explained: float = 0.8) -> PassiveFit:
    """The torsion spring-damper that best explains ``<hinge>.moment`` of ``res`` over the window (module
    docstring). ValueError naming the hinge or the window when they are not in the run."""
    if f"{hinge}.moment" not in res.loads or f"{hinge}.angle" not in res.coordinate_names:
        hinges = [n.removesuffix(".angle") for n in res.coordinate_names if n.endswith(".angle")]
        raise ValueError(f"passive: no hinge {hinge!r} in the run; its hinges are {hinges}")
    lo = res.t[0] if t_start is None else t_start
    hi = res.t[-1] if t_end is None else t_end
    w = (res.t >= lo - 1e-9) & (res.t <= hi + 1e-9)
    if w.sum() < 8:
        raise ValueError(f"passive: the window {lo:g}..{hi:g} s holds {int(w.sum())} frames; at least 8 are needed")
    k = res.coordinate_names.index(f"{hinge}.angle")
    psi, psid, m = res.z[w, k], res.zd[w, k], res.loads[f"{hinge}.moment"][w]
    X = np.column_stack([-psi, np.ones_like(psi), -psid])
    beta, *_ = np.linalg.lstsq(X, m, rcond=None)
    r = m - X @ beta
    n = int(w.sum())
    rho = float(np.clip(np.corrcoef(r[:-1], r[1:])[0, 1], 0.0, 0.99)) if np.std(r) > 0 else 0.0
    n_eff = max(n * (1 - rho) / (1 + rho), 4.0)
    s2 = float(r @ r) / max(n_eff - 3, 1.0)
    cov = s2 * np.linalg.inv(X.T @ X) * n / n_eff
    kt, c0, ct = beta
    # rest = c0 / kt: its variance by the delta method
    g = np.array([-c0 / kt**2, 1.0 / kt, 0.0])
    se = {"kt": float(np.sqrt(cov[0, 0])), "ct": float(np.sqrt(cov[2, 2])), "rest_angle": float(np.sqrt(g @ cov @ g))}
    ss = float(np.sum((m - m.mean()) ** 2))
    r2 = 1.0 - float(r @ r) / ss if ss > 0 else 0.0
    why = []
    if r2 < explained:
        why.append(f"it explains {100 * r2:.0f} % (< {100 * explained:.0f} %): the rest is the muscles'")
    if kt <= 2 * se["kt"] or ct < -2 * se["ct"]:
        why.append("no stiffness and damping a passive joint has (kt > 0, ct >= 0 within 2 SE): the moment "
                   "leads the motion, as a muscle's does")
    if n_eff < 10 or se["kt"] > 0.5 * abs(kt):
        why.append(f"the window does not decide it ({n_eff:.0f} independent samples): take a longer one")
    rms = (float(np.sqrt(np.mean(m**2))), float(np.sqrt(np.mean(r**2))))
    return PassiveFit(hinge, float(kt), float(ct), float(c0 / kt), se, r2, *rms, n, n_eff, not why, tuple(why),
                      (float(res.t[w][0]), float(res.t[w][-1])))
