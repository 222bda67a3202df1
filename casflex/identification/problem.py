"""What every identification method shares: parameter scaling, starts, the result record and
the Gauss-Newton statistics (standard errors, correlations, identifiability)."""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from casflex.model import Model
from casflex.results import atomic_write_json

__all__ = ["IdentificationResult", "parameter_scale", "start_values", "bound_flags", "gauss_newton_statistics"]


def parameter_scale(model: Model) -> np.ndarray:
    """Typical magnitude of each parameter: its declared ``scale``, else |nominal|, else 1.
    Decision variables are p / scale, so they are O(1)."""
    out = []
    for par, nom in zip(model.parameters, model.p_nominal, strict=True):
        out.append(par.scale if par.scale else (abs(nom) if nom != 0 else 1.0))
    return np.array(out, dtype=float)


def start_values(model: Model, start: float | dict[str, float] | np.ndarray | None) -> np.ndarray:
    """Starting parameters: None (nominal), a factor times nominal, a dict, or an array."""
    if start is None:
        return model.p_nominal.copy()
    if isinstance(start, (int, float)) and not isinstance(start, bool):
        if not (math.isfinite(start) and start > 0):
            raise ValueError(f"start: a factor must be a positive number, got {start!r}")
        return model.p_nominal * float(start)
    return model.params(start)


def bound_flags(model: Model, p: np.ndarray, scale: np.ndarray) -> dict[str, bool]:
    """{name: True} for parameters within 1e-8 of their scale from a bound."""
    return {par.name: bool(min(abs(v - par.lower), abs(v - par.upper)) <= 1e-8 * s)
            for v, par, s in zip(p, model.parameters, scale, strict=True)}


def gauss_newton_statistics(J: np.ndarray, r: np.ndarray, n_p: int, names: tuple[str, ...]) -> dict[str, Any]:
    """Standard errors and correlations of the first ``n_p`` unknowns of a least-squares fit.

    J : (m, n) Jacobian of the residual r (m,) in the unknowns' own units. Covariance
    s^2 (J^T J)^-1 with s^2 = r^T r / (m - n) (Gauss-Newton). The identifiability report
    gives the rank and condition number of J's columns after scaling them to unit norm, and
    the parameter combination the data pin down least (the last right singular vector).
    """
    m, n = J.shape
    norms = np.linalg.norm(J, axis=0)
    norms[norms == 0] = 1.0
    Js = J / norms
    sv = np.linalg.svd(Js, compute_uv=False)
    tol = max(m, n) * np.finfo(float).eps * (sv[0] if sv.size else 0.0)
    rank = int((sv > tol).sum())
    cond = float(sv[0] / sv[-1]) if sv.size and sv[-1] > 0 else math.inf
    dof = m - n
    s2 = float(r @ r) / dof if dof > 0 else math.nan
    try:
        cov = s2 * np.linalg.pinv(J.T @ J)[:n_p, :n_p]
    except np.linalg.LinAlgError:
        cov = np.full((n_p, n_p), math.nan)
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se, se)
    # the parameter block alone: how well the data separate the parameters from each other
    _, svp, vtp = np.linalg.svd(Js[:, :n_p], full_matrices=False)
    weakest = {nm: float(v) for nm, v in zip(names, vtp[-1], strict=True)} if n_p else {}
    return {
        "std_errors": {nm: float(v) for nm, v in zip(names, se, strict=True)},
        "correlation": np.nan_to_num(corr).tolist(),
        "rank": rank, "n_unknowns": n, "condition": cond,
        "parameter_condition": float(svp[0] / svp[-1]) if n_p and svp[-1] > 0 else math.inf,
        "weakest_direction": weakest, "residual_variance": s2,
    }


@dataclass(frozen=True)
class IdentificationResult:
    """The outcome of an identification (any method).

    parameters: identified values {name: value} (units of the scene's parameters);
    std_errors, correlation, rank, condition: Gauss-Newton statistics at the solution
    (``identifiability`` holds the full report); multipliers: lambda at each instant;
    wall_build_s / wall_solve_s: problem construction and solver time (s).
    """

    method: str
    solver: str
    parameters: dict[str, float]
    start: dict[str, float]
    success: bool
    status: str
    message: str
    iterations: int
    wall_build_s: float
    wall_solve_s: float
    objective: float
    std_errors: dict[str, float]
    correlation: list[list[float]]
    at_bound: dict[str, bool]
    identifiability: dict[str, Any]
    instants: list[float] = field(default_factory=list)
    multipliers: list[list[float]] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def p(self) -> np.ndarray:
        return np.array(list(self.parameters.values()))

    @property
    def wall_s(self) -> float:
        return self.wall_build_s + self.wall_solve_s

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["wall_s"] = self.wall_s
        return d

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the result as JSON, atomically."""
        return atomic_write_json(path, _jsonable(self.to_dict()))

    def summary(self) -> str:
        lines = [f"{self.method} identification with {self.solver}: {self.status} in {self.iterations} iterations "
                 f"({self.wall_build_s * 1e3:.0f} ms build, {self.wall_solve_s * 1e3:.0f} ms solve)"]
        for k, v in self.parameters.items():
            se = self.std_errors.get(k, math.nan)
            flag = "  (at a bound)" if self.at_bound.get(k) else ""
            lines.append(f"  {k:<8s} = {v:14.6g}  +- {se:.2g} (start {self.start[k]:.6g}){flag}")
        idf = self.identifiability
        lines.append(f"  identifiability: rank {idf['rank']} of {idf['n_unknowns']} unknowns, "
                     f"parameter condition number {idf['parameter_condition']:.3g}")
        return "\n".join(lines)


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(x) else str(float(x))
    if isinstance(x, np.integer):
        return int(x)
    return x
