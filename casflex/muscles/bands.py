"""How much of a trial's muscle forces, activations and joint reactions is known: each output's band (one standard
deviation) from three independent sources, and beside it (not in it) the spread between optimisation criteria.

Every output at frame k is a function of that frame's coordinates (z, z', z''), of the model's properties p and
of the muscles' (:meth:`casflex.muscles.analysis.TrialMuscles.solve`), so the inverse's bands
(:mod:`casflex.inverse.bands`) carry over with the muscle outputs in place of the loads:

- **muscles**: each declared uncertain muscle property (:class:`~casflex.muscles.options.MuscleUncertainty`,
  a relative SD, independent between muscles and properties) moved by +SD and -SD, the trial re-solved: its part
  is (out(+SD) - out(-SD)) / 2 (a secant over +-1 SD; on the Rajagopal walk, 10 % on every tendon slack length,
  against a Monte Carlo of 300 draws it is closer than the derivative at 45 of the 51 muscles' peak forces of
  50 N or more, e.g. gasmed_r's: Monte Carlo 713 N, secant 721 N, derivative 1636 N; not at the joint reactions'
  peaks, where neither is: docs/muscles.md, "Bands");
- **anthropometry**: the inverse's ``[[uncertain]]`` properties (its :class:`~casflex.inverse.bands.BandSpec`),
  each moved by +-SD, the loads of the model with those properties as parameters fed to the muscles
  (:func:`casflex.inverse.bands.anthropometry` with the muscles' outputs as its function);
- **markers**: the markers' noise through the fit, the filter and the outputs, to first order
  (:func:`casflex.inverse.bands.marker_part`), the outputs differenced along z by 1e-4 (rad, m: static
  optimization solved on its active set in closed form, exact; 1e-4 keeps the solver's 1e-10 out of the slope).

``total`` = the root-sum-square of the three. Static optimization's solution is piecewise smooth: where an
activation reaches or leaves its bound between the +h and -h solutions the part is a secant across the kink; the
report counts those frames per source (where the linearisation is least trustworthy) and says how far from
linear each muscle property is (the largest second difference over the first).

The perturbed problems are solved on the nominal solution's active set (closed form, exact, the QP only for the
frames whose set changed: :func:`~casflex.muscles.static_optimization.solve_static_optimization`'s ``near``):
the Rajagopal walk's 80 muscles x 3 properties x 2 signs (480 problems of 166 frames) in 24 s CPU, where one
such problem solved whole takes 0.46 s.

**Criteria** (a modelling choice, not noise: never in the SD): the same outputs with other exponents p of
static optimization's cost (OpenSim's activation_exponent; 3 beside the trial's 2), and their differences.

Output names (as OpenSim's files name their columns; units ``MuscleBands.units``):

- ``<muscle>``: its force (N; OpenSim's static optimization force file);
- ``<muscle>.activation``: its activation (0-1; the activation file's column ``<muscle>``);
- ``<joint>_on_<body>_in_<frame>_fx``, ``_fy``, ``_mz``: the joint reaction as
  :class:`~casflex.muscles.reaction.JointReaction` asks (OpenSim's JointReaction columns; N and N m, or body
  weights where it gives ``body_weight``);
- ``<joint>_resultant``: |F| = hypot(fx, fy) of that reaction (the same on either body, in any frame).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from casflex.inverse.bands import anthropometry, marker_part, rigid_load_function
from casflex.muscles.options import MuscleUncertainty
from casflex.muscles.static_optimization import AT_BOUND

__all__ = ["MuscleBands", "monte_carlo", "muscle_bands", "muscle_outputs", "output_units"]

#: m/s^2: a body weight is the model's mass times this (N)
GRAVITY = 9.81
#: rad or m: the step along the coordinates for the markers' part
STEP = 1e-4
#: Draws of the muscles' Monte Carlo where ``draws="auto"`` asks for one (:func:`muscle_bands`).
AUTO_DRAWS = 100


def _reaction_names(trial, joint: str) -> tuple[str, str]:
    """(body, frame) of a joint's reaction as OpenSim names its columns ``<joint>_on_<body>_in_<frame>_fx``."""
    parent, child, _ = trial.osim.joint_frames[joint]
    body = child if trial.reaction.on == "child" else parent
    frame = {"child": child, "parent": parent, "ground": "ground"}[trial.reaction.frame]
    return body, frame


def output_units(trial) -> dict[str, str]:
    """name -> unit of every output of ``trial`` (module docstring)."""
    bw = trial.reaction.body_weight is not None
    units = {m.name: "N" for m in trial.muscles} | {f"{m.name}.activation": "" for m in trial.muscles}
    for j in trial.joints:
        body, frame = _reaction_names(trial, j)
        stem = f"{j}_on_{body}_in_{frame}"
        units |= {f"{stem}_fx": "BW" if bw else "N", f"{stem}_fy": "BW" if bw else "N",
                  f"{stem}_mz": "BW m" if bw else "N m", f"{j}_resultant": "BW" if bw else "N"}
    return units


def muscle_outputs(trial, out, bounds: bool = False) -> dict[str, np.ndarray]:
    """name -> (k,): the outputs (module docstring) of :meth:`TrialMuscles.solve`'s ``out``; ``bounds``: with
    ``_bound.<muscle>`` (-1 at its lower bound, 1 at its upper, 0 between: the active set, whose central
    difference is not 0 where it changed)."""
    so = out.so
    res = {m.name: so.forces[:, i] for i, m in enumerate(trial.muscles)}
    res |= {f"{m.name}.activation": so.activations[:, i] for i, m in enumerate(trial.muscles)}
    for j in trial.joints:
        body, frame = _reaction_names(trial, j)
        stem, L = f"{j}_on_{body}_in_{frame}", out.reactions[j].loads[:, 0, :]
        res |= {f"{stem}_fx": L[:, 0], f"{stem}_fy": L[:, 1], f"{stem}_mz": L[:, 2],
                f"{j}_resultant": np.hypot(L[:, 0], L[:, 1])}
    if bounds:
        a = so.activations
        lo, hi = trial.optimization.bounds(a.shape[1])
        flags = np.where(a <= lo + AT_BOUND, -1.0, np.where(a >= hi - AT_BOUND, 1.0, 0.0))
        res |= {f"_bound.{m.name}": flags[:, i] for i, m in enumerate(trial.muscles)}
    return res


def _changed(parts) -> np.ndarray | None:
    """(k,) bool: the frames where some part's active set differs between its + and - solutions."""
    out = None
    for part in parts:
        for name, v in part.items():
            if name.startswith("_bound."):
                out = (v != 0) if out is None else out | (v != 0)
    return out


@dataclass(frozen=True, eq=False)
class MuscleBands:
    """The bands of a trial's muscle outputs (module docstring).

    t (k,) s; values: name -> (k,) the outputs (``units``); bands: name -> {"muscles", "anthropometry",
    "markers", "total"} -> (k,) one SD; parts: "<muscle>.<property>" -> name -> (k,) the signed change when that
    property moves by +SD (the anthropometry's: ``anthropometry_parts``, by target); criteria: "p3" -> name ->
    (k,) the outputs with that exponent; spread: name -> "p3" -> (k,) their difference from ``values``;
    changed: source -> (k,) bool the frames whose active set changed between +h and -h; body_weight N; report:
    what was done, one line each; seconds: source -> wall time; monte_carlo: name -> (k,) the muscles' part by a
    Monte Carlo where asked (``draws``)."""

    t: np.ndarray
    values: dict[str, np.ndarray]
    units: dict[str, str]
    bands: dict[str, dict[str, np.ndarray]]
    parts: dict[str, dict[str, np.ndarray]]
    anthropometry_parts: dict[str, dict[str, np.ndarray]]
    criteria: dict[str, dict[str, np.ndarray]]
    spread: dict[str, dict[str, np.ndarray]]
    changed: dict[str, np.ndarray]
    body_weight: float
    report: list[str] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    monte_carlo: dict[str, np.ndarray] = field(default_factory=dict)
    #: name -> (k,): the muscles' first-order part where the Monte Carlo's replaced it in ``bands``
    first_order: dict[str, np.ndarray] = field(default_factory=dict)

    def contributors(self, name: str, frame: int, n: int = 3) -> list[tuple[str, float]]:
        """The ``n`` muscle properties whose parts are largest in ``name`` at ``frame``: (property, |part|)."""
        ranked = sorted(((k, abs(float(v[name][frame]))) for k, v in self.parts.items()), key=lambda x: -x[1])
        return ranked[:n]

    def summary(self, names=None) -> list[str]:
        """One line per output (default: each joint's resultant, then each muscle's force) at its peak, e.g.
        "hip_r resultant: peak 3.97 BW (3314 N) at t = 0.81 s +- 0.348 BW (muscles 0.348, anthropometry 0.00999,
        markers 0; largest soleus_r.tendon_slack_length 0.23, ...); p=3: peak 4.05 BW, max |diff| 0.334, RMS 0.0957"
        (the Rajagopal walk's, first order)."""
        if names is None:
            names = [n for n in self.values if n.endswith("_resultant")] + \
                    [n for n in self.values if f"{n}.activation" in self.values]
        return [self._line(n) for n in names]

    def _line(self, name: str) -> str:
        v, unit = self.values[name], self.units[name]
        i = int(np.argmax(np.abs(v)))
        b = {k: float(x[i]) for k, x in self.bands[name].items()}
        label = f"{name[:-len('_resultant')]} resultant" if name.endswith("_resultant") else name
        force = f"{name}.activation" not in self.values and name.endswith(("_fx", "_fy", "_resultant"))
        scale, shown, other = 1.0, f" {unit}" if unit else "", ""
        if force and unit == "N":
            scale, shown, other = 1.0 / self.body_weight, " BW", f" ({v[i]:.0f} N)"
        elif force:
            other = f" ({v[i] * self.body_weight:.0f} N)"

        def f(x: float) -> str:
            return f"{x * scale:.3g}"

        top = ", ".join(f"{k} {f(x)}" for k, x in self.contributors(name, i) if x > 0)
        line = (f"{label}: peak {f(v[i])}{shown}{other} at t = {self.t[i]:.3g} s +- {f(b['total'])}{shown} "
                f"(muscles {f(b['muscles'])}"
                + (f" [first order {f(self.first_order[name][i])}]" if self.first_order else
                   f" [Monte Carlo {f(self.monte_carlo[name][i])}]" if self.monte_carlo else "")
                + f", anthropometry {f(b['anthropometry'])}, markers {f(b['markers'])}"
                + (f"; largest {top})" if top else ")"))
        for key, crit in self.criteria.items():
            c, d = crit[name], self.spread[name][key]
            j = int(np.argmax(np.abs(c)))
            line += (f"; {key[0]}={key[1:]}: peak {f(c[j])}{shown}, max |diff| {f(np.abs(d).max())}, "
                     f"RMS {f(np.sqrt(np.mean(d ** 2)))}")
        return line


def _check(trial, inputs, z, zd, zdd, uncertainty, criteria, draws) -> None:
    """ValueError in one line for what cannot be honoured, before any work."""
    if isinstance(draws, bool) or not isinstance(draws, int) or draws < 0 or draws == 1:
        raise ValueError(f"draws: expected 0 (no Monte Carlo) or a number of draws >= 2, got {draws!r}")
    if not isinstance(uncertainty, MuscleUncertainty):
        raise ValueError(f"uncertainty: expected a MuscleUncertainty (relative SDs), got {type(uncertainty).__name__}")
    k, n = trial.t.size, trial.tree.n
    for name, a in (("z", z), ("zd", zd), ("zdd", zdd)):
        if np.shape(a) != (k, n):
            raise ValueError(f"{name}: expected ({k}, {n}) (the trial's frames, its tree's coordinates), got "
                             f"{np.shape(a)}")
    if inputs is None:
        raise ValueError("inputs: the inverse's inputs the trial was made from are needed (their bands' settings)")
    if inputs.t.size != k or not np.allclose(inputs.t, trial.t):
        raise ValueError(f"inputs: their {inputs.t.size} frames are not the trial's {k}: give the inverse inputs "
                         "the trial was made from")
    for p in criteria:
        if isinstance(p, bool) or not isinstance(p, (int, float)) or not p >= 1.0:
            raise ValueError(f"criteria: expected exponents >= 1 (OpenSim's activation_exponent), got {p!r}")
        if p == trial.optimization.exponent:
            raise ValueError(f"criteria: {p:g} is the trial's own exponent; give the others to compare with it")


def _muscle_parts(trial, z, zd, zdd, uncertainty, base, base_out):
    """(parts {"<muscle>.<property>": {name: (k,)}}, bend {property: float}): each declared property of each
    muscle moved by +-SD, all solved at once on the nominal solution's active set."""
    variants, keys = [], []
    for prop, sd in uncertainty.declared:
        for i, m in enumerate(trial.muscles):
            for sign in (1.0, -1.0):
                ms = list(trial.muscles)
                ms[i] = dataclasses.replace(m, **{prop: getattr(m, prop) * (1.0 + sign * sd)})
                variants.append(tuple(ms))
            keys.append((f"{m.name}.{prop}", prop))
    outs = trial.solve_variants(z, zd, zdd, variants, near=base) if variants else []
    parts, first, second = {}, {}, {}
    for j, (key, prop) in enumerate(keys):
        up, down = (muscle_outputs(trial, o, bounds=True) for o in outs[2 * j:2 * j + 2])
        parts[key] = {n: 0.5 * (up[n] - down[n]) for n in up}
        for n in base_out:
            s = float(np.max(np.abs(base_out[n])))  # each output relative to its own peak
            if not n.startswith("_") and s > 1e-6:  # not a pin's moment, 0 but for rounding
                first[prop] = max(first.get(prop, 0.0), float(np.max(np.abs(up[n] - down[n]))) / s)
                second[prop] = max(second.get(prop, 0.0), float(np.max(np.abs(up[n] + down[n] - 2 * base_out[n]))) / s)
    bend = {p: second[p] / first[p] if first.get(p) else 0.0 for p in first}
    return parts, bend


def monte_carlo(trial, z: np.ndarray, zd: np.ndarray, zdd: np.ndarray, uncertainty: MuscleUncertainty,
                draws: int, seed: int = 0) -> dict[str, np.ndarray]:
    """name -> (k,): each output's standard deviation over ``draws`` draws of every declared muscle property from
    its prior (normal, independent), each draw solved (on the nominal solution's active set where it holds): the
    check of the muscles' first-order part where the outputs are far from linear (relative standard error of an
    SD from n draws: 1 / sqrt(2 (n - 1)))."""
    rng = np.random.default_rng(seed)
    base = trial.solve(z, zd, zdd)
    variants = []
    for _ in range(int(draws)):
        x = rng.standard_normal((len(trial.muscles), len(uncertainty.declared)))
        variants.append(tuple(dataclasses.replace(m, **{p: getattr(m, p) * (1.0 + sd * x[i, j])
                                                       for j, (p, sd) in enumerate(uncertainty.declared)})
                              for i, m in enumerate(trial.muscles)))
    outs = [muscle_outputs(trial, o) for o in trial.solve_variants(z, zd, zdd, variants, near=base)]
    return {n: np.std([o[n] for o in outs], axis=0, ddof=1) for n in outs[0]} if outs else {}


def _fit(inputs):
    """The inverse's marker fit again (:func:`casflex.inverse.solve` does not keep it), None where given."""
    from casflex.inverse.fit import fit_markers

    if inputs.z is not None:
        return None
    return fit_markers(inputs.tree, inputs.t, inputs.y, max_gap=inputs.fit.max_gap, max_misfit=inputs.fit.misfit,
                       labels=inputs.labels, source=inputs.settings["source"])


def muscle_bands(trial, inputs, fit, z: np.ndarray, zd: np.ndarray, zdd: np.ndarray, *,
                 uncertainty: MuscleUncertainty, criteria=(3.0,), spec=None, draws: int | str = 0,
                 seed: int = 0) -> MuscleBands:
    """The bands of ``trial``'s outputs (module docstring) at its filtered coordinates z, z', z'' (k, n_z), from
    the declared muscle ``uncertainty``, the inverse's ``inputs`` (:class:`~casflex.inverse.inputs.InverseInputs`;
    its ``band_spec``, or ``spec``, gives the anthropometry's uncertain properties and the markers' noise: none,
    no such part) and its marker ``fit`` (None: fitted again where the inputs are markers); the spread of the
    exponents ``criteria`` beside the trial's; ``draws`` > 0: the muscles' part checked by a Monte Carlo of that
    many draws (:func:`monte_carlo`, ``MuscleBands.monte_carlo``), "auto": :data:`AUTO_DRAWS` where an optimal
    fibre or tendon slack length is uncertain (the outputs are far from linear in them: on the Rajagopal walk, 10 %
    on every tendon slack length, the secants understate the band of the knee's peak contact force twofold and
    the ankle's tenfold), none otherwise; where drawn, the Monte Carlo's
    SD is the muscles' part (the first-order one said beside it). ValueError in one line for what cannot be
    honoured."""
    if draws == "auto":
        draws = AUTO_DRAWS if any(p != "max_isometric_force" for p, _ in uncertainty.declared) else 0
    _check(trial, inputs, z, zd, zdd, uncertainty, criteria, draws)
    spec = inputs.band_spec if spec is None else spec
    seconds, report = {}, []
    start = time.perf_counter()
    base = trial.solve(z, zd, zdd)
    out0 = muscle_outputs(trial, base, bounds=True)
    names = [n for n in out0 if not n.startswith("_")]
    k = trial.t.size
    zero = np.zeros(k)
    parts, bend = _muscle_parts(trial, z, zd, zdd, uncertainty, base, out0)
    seconds["muscles"] = time.perf_counter() - start
    musc = {n: np.sqrt(sum(p[n] ** 2 for p in parts.values())) if parts else zero for n in names}
    changed = {"muscles": _changed(parts.values())}
    report += _muscle_lines(trial, uncertainty, bend, len(parts), seconds["muscles"])
    anth, mark, anth_parts = {n: zero for n in names}, {n: zero for n in names}, {}
    if spec is None:
        report.append("muscle bands: the inverse was asked for no bands (uncertain=, marker_noise= or bands=True "
                      "to prepare): the anthropometry's and markers' parts are 0")
    else:
        def function(z, zd, zdd, p):
            loads = rigid_load_function(spec.tree, trial.t, trial.plates, p)(z, zd, zdd)
            return muscle_outputs(trial, trial.solve(z, zd, zdd, loads=loads, near=base), bounds=True)

        start = time.perf_counter()
        if spec.targets:
            anth_parts, _ = anthropometry(spec, trial.t, z, zd, zdd, function=function)
            anth = {n: np.sqrt(sum(p[n] ** 2 for p in anth_parts.values())) for n in names}
            changed["anthropometry"] = _changed(anth_parts.values())
        seconds["anthropometry"] = time.perf_counter() - start
        start = time.perf_counter()
        fit = _fit(inputs) if fit is None and not spec.given and spec.marker_noise != 0 else fit
        flags = [n for n in out0 if n.startswith("_bound.")]
        sd, lines, _ = marker_part(spec, inputs, fit, z, zd, zdd, names + flags,
                                   lambda z, zd, zdd: function(z, zd, zdd, spec.model.p_nominal), step=STEP)
        mark = {n: sd[n] for n in names}
        if not (spec.given or spec.marker_noise == 0):
            changed["markers"] = np.any([sd[f] > 0 for f in flags], axis=0) if flags else np.zeros(k, bool)
        seconds["markers"] = time.perf_counter() - start
        report += [line.replace("bands", "muscle bands", 1) for line in lines]
    changed = {s: (c if c is not None else np.zeros(k, bool)) for s, c in changed.items()}
    report.append(_changed_line(changed, k))
    bands = {n: {"muscles": musc[n], "anthropometry": anth[n], "markers": mark[n],
                 "total": np.sqrt(musc[n] ** 2 + anth[n] ** 2 + mark[n] ** 2)} for n in names}
    start = time.perf_counter()
    mc = monte_carlo(trial, z, zd, zdd, uncertainty, draws, seed) if draws and uncertainty.declared else {}
    if mc:
        seconds["monte_carlo"] = time.perf_counter() - start
        report.append(_monte_carlo_line(names, out0, musc, mc, draws))
        report.append(f"muscle bands: the muscles' part is the Monte Carlo's ({draws} draws; an SD's relative standard "
                      f"error {1 / np.sqrt(2 * (draws - 1)):.0%}), not the first order's")
        first = {n: bands[n]["muscles"] for n in names}
        for n in names:
            b = bands[n]
            b["muscles"] = mc[n]
            b["total"] = np.sqrt(mc[n] ** 2 + b["anthropometry"] ** 2 + b["markers"] ** 2)
    start = time.perf_counter()
    crit, spread = _criteria(trial, z, zd, zdd, criteria, out0, names)
    seconds["criteria"] = time.perf_counter() - start
    if criteria:
        report.append(f"criteria: static optimization with exponent {', '.join(f'{p:g}' for p in criteria)} beside "
                      f"{trial.optimization.exponent:g}: a modelling choice, not noise; beside the bands, not in them")
    bw = trial.reaction.body_weight or GRAVITY * sum(b.mass for b in trial.scene.bodies)
    return MuscleBands(trial.t, {n: out0[n] for n in names}, output_units(trial), bands, parts, anth_parts, crit,
                       spread, changed, float(bw), report, seconds, {n: mc[n] for n in names} if mc else {},
                       first if mc else {})


def _criteria(trial, z, zd, zdd, criteria, out0, names):
    """({"p3": {name: (k,)}}, {name: {"p3": (k,)}}): the outputs with each exponent, and their differences from
    ``out0``'s."""
    crit, spread = {}, {n: {} for n in names}
    for p in criteria:
        key = f"p{p:g}"
        other = muscle_outputs(trial, trial.solve(z, zd, zdd, optimization=dataclasses.replace(
            trial.optimization, exponent=float(p))))
        crit[key] = {n: other[n] for n in names}
        for n in names:
            spread[n][key] = other[n] - out0[n]
    return crit, spread


def _muscle_lines(trial, uncertainty, bend, n_parts, seconds) -> list[str]:
    if not uncertainty.declared:
        return ["muscle bands: no muscle property declared uncertain: the muscles' part is 0"]
    props = ", ".join(f"{p} {100 * s:g} %" for p, s in uncertainty.declared)
    far = ", ".join(f"{p} {b:.2g}" for p, b in bend.items())
    return [f"muscle bands (1 SD): each muscle's {props} (relative, independent) moved by +-SD and the trial re-solved"
            f" ({n_parts} properties, {2 * n_parts} problems of {trial.t.size} frames, {seconds:.1f} s); the "
            f"outputs' largest second difference over their first (0: linear; past 0.1 the band is a secant, "
            f"not a derivative): {far}"]


def _monte_carlo_line(names, values, first, mc, draws: int) -> str:
    """The Monte Carlo's SD over the first-order part at each force's peak (the muscles' and the reactions'
    resultants: a pin's moment is its reserve's, near 0): the range of the ratios."""
    ratios = []
    for n in (n for n in names if n.endswith("_resultant") or f"{n}.activation" in names):
        i = int(np.argmax(np.abs(values[n])))
        if first[n][i] > 0:
            ratios.append((mc[n][i] / first[n][i], n))
    lo, hi = min(ratios), max(ratios)
    return (f"muscle bands: a Monte Carlo of {draws} draws of the muscle properties (relative SE of an SD "
            f"{1 / np.sqrt(2 * (draws - 1)):.0%}): its SD over the first-order part at each force's peak "
            f"{lo[0]:.2f} ({lo[1]}) to {hi[0]:.2f} ({hi[1]})")


def _changed_line(changed: dict[str, np.ndarray], k: int) -> str:
    any_ = np.any(list(changed.values()), axis=0) if changed else np.zeros(k, bool)
    each = ", ".join(f"{s} {int(c.sum())}" for s, c in changed.items())
    return (f"active set: {int(any_.sum())} of {k} frames have an activation reach or leave its bound between the "
            f"+h and -h solutions ({each}): there a part is a secant across static optimization's kink")
