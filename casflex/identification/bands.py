"""The identified model's outputs (joint forces, markers, energies) with the band its parameters'
uncertainty gives them: the noise, model-error and model-form parts alike, as ``std_errors`` holds
them (docs/identification.md, steps 6-8)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from casflex.identification.result import IdentificationResult
from casflex.model import Model

__all__ = ["output_band"]


def output_band(model: Model, result: IdentificationResult, outputs: Sequence[str] | None = None, *,
                experiment: int = 0, draws: int = 40, level: float = 0.95, seed: int = 0) -> dict:
    """The outputs of the identified model over an experiment, with a pointwise band.

    Parameters are drawn from the normal distribution of the result (its values, its correlation and
    its total standard errors, the model's parts included), clipped to the scene's bounds; where the fit
    estimated uncertain properties (:mod:`.priors`), they are drawn with the parameters from their joint
    distribution and the model carries them (a joint force moves with a segment's mass); each
    draw is simulated from the experiment's identified initial state with the result's step and
    alpha. The band holds ``level`` of the draws at each instant (percentiles); a draw the model
    does not run through is counted and left out.

    Returns {"t": (n,) s, "names": output names, "value": (n, k) at the estimate, "lo", "hi": (n, k),
    "draws": used, "failed": draws that did not run}. Units: the outputs' (N, N m, m, J).
    """
    from casflex.simulate import Start, Stepping, simulate

    if not result.trajectories:
        raise ValueError("result: no trajectories (an output-error fit's result is needed)")
    if not 0 < level < 1:
        raise ValueError(f"level: expected a fraction in (0, 1), got {level!r}")
    tr = result.trajectories[experiment]
    names = list(tr.output_names if outputs is None else outputs)
    unknown = [n for n in names if n not in tr.output_names]
    if unknown:
        raise ValueError(f"outputs: unknown output {unknown[0]!r}; the model's outputs are {list(tr.output_names)}")
    cols = [tr.output_names.index(n) for n in names]
    model, mean, se, corr = _joint(model, result)
    cov = corr * np.outer(se, se)
    lo_b = np.array([p.lower for p in model.scene.parameters])
    hi_b = np.array([p.upper for p in model.scene.parameters])
    rng = np.random.default_rng(seed)
    samples = np.clip(rng.multivariate_normal(mean, cov, size=draws), lo_b, hi_b)
    dt, alpha = result.extra["dt"], result.extra["alpha"]
    runs = []
    for p in samples:
        d = simulate(model, tr.t[-1] - tr.t[0], stepping=Stepping(dt=dt, alpha=alpha, compiled=result.extra.get(
            "compiled", False)), p=p, start=Start(q0=tr.q[0], qd0=tr.qd[0], t0=float(tr.t[0])), raise_on_failure=False)
        if d.success and d.t.size == tr.t.size:
            runs.append(np.asarray(d.outputs)[:, cols])
    if not runs:
        raise ValueError("no parameter draw ran through the experiment: the band cannot be drawn")
    tail = 50 * (1 - level)
    lo, hi = np.percentile(np.array(runs), [tail, 100 - tail], axis=0)
    return {"t": tr.t, "names": names, "value": np.asarray(tr.outputs)[:, cols], "lo": lo, "hi": hi,
            "draws": len(runs), "failed": draws - len(runs)}


def _joint(model: Model, result: IdentificationResult) -> tuple[Model, np.ndarray, np.ndarray, np.ndarray]:
    """(the model to simulate, the mean, total standard errors and correlation to draw from): the result's
    parameters, or, where it estimated uncertain properties, the model with them and their joint distribution."""
    joint = result.extra.get("uncertain", {}).get("joint")
    if not joint:
        return (model, np.asarray(result.p), np.array([result.std_errors[k] for k in model.parameter_names]),
                np.asarray(result.correlation))
    import dataclasses

    from casflex.model import assembled
    from casflex.scene.uncertain import Uncertain, with_uncertain_estimated

    declared = tuple(Uncertain(**d) for d in result.extra["uncertain"]["declared"])
    scene = with_uncertain_estimated(dataclasses.replace(model.scene, uncertain=declared))
    model_u = assembled(scene, inertia=model.inertia)
    if list(model_u.parameter_names) != joint["names"]:
        raise ValueError(f"model: its parameters and uncertain properties {list(model_u.parameter_names)} are not the "
                         f"result's {joint['names']}: pass the model the result was identified with")
    return model_u, np.asarray(joint["values"]), np.asarray(joint["std_errors"]), np.asarray(joint["correlation"])
