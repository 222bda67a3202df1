"""Uncertain properties that the data pin only against a property held at its scene value (issue 45).

Declared uncertain alone, one of two bars' densities is fitted to a fraction of a percent: the motion fixes the
ratio of the bars' masses (and of masses to stiffnesses), and the other bar's density, not declared, is held
exact at its scene value. The small standard error then says how well the ratio is known, not the property: the
fit cannot separate the two. This module finds such cases: for each uncertain property it frees, one at a time,
the same property of the scene's other elements of its kind (its *siblings*: ``bar4.rho`` beside ``bar2.rho``,
another body's ``mass``), with the declared property's relative prior, in the Gauss-Newton information at the
fit, and reports a sibling that multiplies its standard error by :data:`PINNED_RATIO` or more.
"""

from __future__ import annotations

import numpy as np

from casflex.identification.initial_state import initial_states
from casflex.identification.output_error import Fit, OutputError
from casflex.identification.problem import ParameterMap
from casflex.model import assembled
from casflex.scene import Scene
from casflex.scene.uncertain import Uncertain, declared_uncertain, with_uncertain_estimated

__all__ = ["pinned", "siblings", "PINNED_RATIO"]

#: A held sibling pins a property when freeing it multiplies the property's standard error by at least this:
#: a property the data see on its own keeps its error within ~1.5 x (twobar's densities with the data's own
#: information), one pinned by a held sibling gains a factor of hundreds (bar 2's density: 0.2 % -> 71 %)
PINNED_RATIO = 3.0
_KINDS = ("beams", "springs", "torsion_springs", "bodies")


def siblings(scene: Scene) -> dict[str, list[str]]:
    """Each uncertain property's siblings: ``<other element>.<field>`` for the other elements of its kind that
    have the field with a non-zero value and are neither parameters nor declared uncertain."""
    taken = {p.target for p in scene.parameters} | {u.target for u in scene.uncertain}
    out: dict[str, list[str]] = {}
    for u in scene.uncertain:
        owner, _, field = u.target.partition(".")
        kind = next((k for k in _KINDS if any(it.name == owner for it in getattr(scene, k))), None)
        if kind is None:
            continue
        found = []
        for it in getattr(scene, kind):
            target = f"{it.name}.{field}"
            if it.name != owner and target not in taken and getattr(it, field, None):
                found.append(target)
        if found:
            out[u.target] = found
    return out


def _relative(scene: Scene, u: Uncertain) -> float:
    mean, sd = u.prior(scene.property_value(u.target))
    return sd / abs(mean) if mean else 0.0


def _se(info: np.ndarray, keep: np.ndarray, j: int) -> float:
    """The standard error of unknown ``j`` from the information's rows and columns ``keep`` (j among them)."""
    sub = info[np.ix_(keep, keep)]
    cov = np.linalg.pinv(sub, rcond=1e-12, hermitian=True)
    return float(np.sqrt(max(cov[np.searchsorted(keep, j), np.searchsorted(keep, j)], 0.0)))


def pinned(problem: OutputError, f: Fit, scene: Scene) -> dict[str, dict]:
    """The uncertain properties of ``scene`` (the fit's, with them declared) that the data pin only against a
    held sibling: ``{target: {"by": [sibling, ...], "left_if_free": share}}``, ``share`` the part of its prior
    standard deviation left when every sibling is as uncertain as it (relatively). ``problem``, ``f``: the
    maximum a posteriori fit (:func:`casflex.identification.priors.map_fit`), its parameters the scene's
    followed by the uncertain properties."""
    found = siblings(scene)
    if not found:
        return {}
    rel = {}
    for u in scene.uncertain:
        for s in found.get(u.target, ()):
            rel[s] = max(rel.get(s, 0.0), _relative(scene, u))
    extra = [Uncertain(s, relative=r) for s, r in rel.items() if r > 0]
    if not extra:
        return {}
    model = problem.model
    model_x = assembled(with_uncertain_estimated(declared_uncertain(scene, extra)), inertia=model.inertia)
    pmap = ParameterMap.of(model_x, problem.pmap.transform)
    p = np.concatenate([problem.pmap.p(f.w[:model.n_p]), model_x.p_nominal[model.n_p:]])
    states = [problem.state(f.w, e) for e in range(len(problem.experiments))]
    prob = OutputError(model_x, problem.experiments, dt=problem.dt, alpha=problem.integ.alpha, pmap=pmap,
                       compiled=problem.compiled, newton_tol=problem.integ.tol,
                       initial=initial_states(model_x, problem.experiments, p, states))
    _, J = prob.evaluate(prob.pack(pmap.theta(p)))
    info = J.T @ J
    n_x, n_p = model_x.n_p, model.n_p
    column = {par.target: j for j, par in enumerate(model_x.parameters)}
    others = np.arange(n_x, prob.n_unknowns)  # the initial states' unknowns
    held = np.r_[0:n_p, others]
    out = {}
    for target, sibs in found.items():
        j = column.get(target)
        if j is None or j >= n_p:
            continue
        se_held = _se(info, held, j)
        by = [s for s in sibs if s in column
              and _se(info, np.sort(np.r_[held, column[s]]), j) >= PINNED_RATIO * se_held]
        if by:
            free = np.sort(np.r_[held, [column[s] for s in sibs if s in column]])
            dp = float(pmap.dp_dtheta(pmap.theta(p))[j])  # the information is in theta; the prior in p
            out[target] = {"by": by, "left_if_free": _se(info, free, j) * abs(dp) / model_x.parameters[j].prior[1]}
    return out
