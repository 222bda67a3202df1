"""The record of an identification (any method): values, uncertainty, diagnostics; JSON output."""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from casflex.results import atomic_write_json

__all__ = ["IdentificationResult", "COLLINEAR"]

#: A collinearity index above this: the parameters of the least determined combination cannot be told apart
#: (Brun et al. 2001, Water Res. 35(4):1018), said in the summary
COLLINEAR = 15.0


@dataclass(frozen=True)
class IdentificationResult:
    """The outcome of an identification (any method).

    parameters: identified values {name: value} (units of the scene's parameters);
    std_errors: the standard errors the method stands by (output-error fits: the noise part, the
    larger of the autocorrelation-consistent (HAC) and plain Gauss-Newton ones, and the model's
    parts, its discretisation error and its form's, in quadrature; ``extra["uncertainty"]`` holds
    each part, ``extra["forms"]`` the alternative forms compared; other methods: Gauss-Newton); correlation,
    identifiability: the report at the solution (rank, condition, collinearity, ``weak``);
    success: the solver converged *and* the fit is plausible (``message`` says why not);
    multipliers: lambda at each instant; wall_build_s / wall_solve_s: problem construction and
    solve time (s); objective: 1/2 |residual|^2 at the reported parameters; ``extra``: the
    method's details (solver parameters and time, residual analysis, initial states, data).
    ``trajectories``: the identified model's motion per experiment (output-error fits), for
    plots and joint forces; ``samples``: per experiment {"name", "channels", "t", "channel",
    "measured", "model"} at the samples (arrays); neither is written to JSON.
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
    trajectories: tuple = field(default=(), repr=False, compare=False)
    samples: tuple = field(default=(), repr=False, compare=False)

    @property
    def p(self) -> np.ndarray:
        return np.array(list(self.parameters.values()))

    @property
    def wall_s(self) -> float:
        return self.wall_build_s + self.wall_solve_s

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop("trajectories")
        d.pop("samples")
        d["wall_s"] = self.wall_s
        return d

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the result as JSON, atomically."""
        return atomic_write_json(path, self.to_dict())

    def interval(self, k: float = 3.0) -> dict[str, tuple[float, float]]:
        """{name: (value - k SE, value + k SE)}: the interval the result stands by at k standard errors."""
        return {n: (v - k * self.std_errors[n], v + k * self.std_errors[n]) for n, v in self.parameters.items()}

    def summary(self) -> str:
        unc = self.extra.get("uncertainty")
        lines = [f"{self.method} identification with {self.solver}: {self.status} in {self.iterations} iterations "
                 f"({self.wall_build_s:.2f} s build, {self.wall_solve_s:.2f} s solve)"]
        for k, v in self.parameters.items():
            se = self.std_errors.get(k, math.nan)
            flag = "  (at a bound)" if self.at_bound.get(k) else ""
            parts = ""
            if unc:  # the parts of the standard error, as each method reports them
                labels = {"hac": "HAC", "model_error": "model error", "model_form": "model form",
                          "uncertain_properties": "uncertain properties", "instant_robust": "instant-clustered",
                          "gauss_newton": "plain Gauss-Newton"}
                parts = "  [" + ", ".join(f"{lab} {unc[key][k]:.2g}" for key, lab in labels.items() if key in unc) + "]"
            lines.append(f"  {k:<8s} = {v:14.6g}  +- {se:.2g}{parts} (start {self.start[k]:.6g}){flag}")
        idf = self.identifiability
        lines.append(f"  identifiability: rank {idf['rank']} of {idf['n_unknowns']} unknowns, "
                     f"parameter condition number {idf['parameter_condition']:.3g}, "
                     f"collinearity index {idf.get('collinearity_index', math.nan):.3g}")
        ci, weakest = idf.get("collinearity_index", math.nan), idf.get("weakest_direction") or {}
        if ci > COLLINEAR:  # Brun et al. 2001: the parameters cannot be told apart, whatever their errors say
            combo = " ".join(f"{w:+.2f} {k}" for k, w in weakest.items() if abs(w) > 0.05)
            lines.append(f"  hardly separable (collinearity index {ci:.3g} > {COLLINEAR:g}): the data determine "
                         f"least the combination {combo} (scaled parameters)")
        if idf.get("weak"):
            lines.append(f"  weakly identifiable (relative standard error > 10 %): {', '.join(idf['weak'])}")
        for name, exp in self.extra.get("experiments", {}).items():
            res = exp.get("residuals", {})
            moving = {c: ch for c, ch in res.items() if ch["fit"] is not None}
            text = ", ".join(f"{c} {100 * ch['fit']:.2f} % fit, RMS {ch['rms']:.3g}"
                             + ("" if ch["white"] else " (not white)") for c, ch in moving.items())
            lines.append(f"  {name}: {text}")
            if exp.get("noise"):
                lines.append(f"    noise: {exp['noise']['source']}")
        rebuilt = self.extra.get("from_markers")
        if rebuilt:
            lines.append(f"  dofs from markers {', '.join(rebuilt['markers'])} at {rebuilt['samples']} samples: "
                         f"{rebuilt['note']}")
        for target, u in self.extra.get("uncertain", {}).get("properties", {}).items():
            lines.append(f"  uncertain {target}: prior {u['prior_mean']:.6g} +- {u['prior_sd']:.2g}, estimate "
                         f"{u['estimate']:.6g} +- {u['std_error']:.2g} (moved {u['moved_sd']:+.2f} prior sd; "
                         + (f"pinned by {', '.join(u['pinned_by'])}, held: the fit cannot separate them)"
                            if u.get("pinned_by") else f"{100 * u['left_of_prior']:.0f} % of its prior spread left)"))
        for f in self.extra.get("forms", []):
            d = f.get("delta_aic")
            lines.append(f"  form {f['name']}: {f['verdict']}" + ("" if d is None else f" (delta AIC {d:+.1f})"))
        if self.message:
            lines.append(f"  note: {self.message}")
        return "\n".join(lines)
