"""``casflex identify``: the identification methods from the command line (usage and data file
formats in ``docs/data-format.md``); exit status 1 when the identification does not succeed."""

from __future__ import annotations

import argparse
import math
import sys
from typing import TYPE_CHECKING, Any

import numpy as np

from casflex.cli._base import (
    OptionError,
    Outputs,
    alpha_value,
    integer,
    load_model,
    non_negative,
    output_path,
    positive,
)
from casflex.cli._base import uncertain_option as _uncertain
from casflex.identification.choices import METHODS

if TYPE_CHECKING:
    from casflex.data import MeasurementSet
    from casflex.identification import IdentificationResult
    from casflex.model import Model

IDENTIFY_METHODS = METHODS  # the parser takes them from the light choices module, without loading the methods
#: instants of the direct methods when --instants is not given: this many, evenly spread over the data
DEFAULT_INSTANT_COUNT = 5
#: options of the indirect method only (attribute -> option), and of the direct methods only
_INDIRECT_ONLY = {"transcription": "--transcription", "horizon": "--horizon", "residue": "--residue",
                  "dofs": "--dofs", "interval": "--interval", "initial_state": "--initial-state", "dt": "--dt",
                  "alpha": "--alpha", "sigma": "--sigma", "max_iter": "--max-iter", "max_time": "--max-time",
                  "model_error": "--model-error", "plots": "--plots", "form": "--form", "vary": "--vary",
                  "alternatives": "--alternatives", "loss": "--loss", "uncertain": "--uncertain"}
_DIRECT_ONLY = {"instants": "--instants", "smoothing": "--smoothing", "cutoff": "--cutoff", "window": "--window",
                "beam_forces": "--beam-forces"}


def _check_options(args: argparse.Namespace) -> None:
    """Reject options that do not apply to the chosen method or data, naming the option."""
    args.data = args.data or ["simulated"]
    direct = args.method != "indirect"
    defaults = {"max_iter": 100, "max_time": 600.0}
    for attr, opt in (_INDIRECT_ONLY if direct else _DIRECT_ONLY).items():
        if getattr(args, attr) not in (None, defaults.get(attr)):
            where = "the indirect method" if direct else "the direct methods (direct, adapted-direct)"
            raise OptionError(f"{opt}: applies to {where} only, not to --method {args.method}")
    if args.interval is not None and args.transcription == "single-shooting":
        raise OptionError("--interval: applies to --transcription multiple-shooting only")
    if args.start is not None and args.start_values is not None:
        raise OptionError("--start and --start-values: give one or the other, not both")
    files = [d for d in args.data if d not in ("simulated", "measured")]
    if len(args.data) > 1 and len(files) < len(args.data):
        raise OptionError("--data: several recordings must all be files (simulated and measured are one set each)")
    if len(args.data) > 1 and args.method != "indirect":
        raise OptionError(f"--data: several recordings: the indirect method only, not --method {args.method}")
    if args.noise is not None and args.data == ["simulated"]:
        raise OptionError("--noise: the simulated set is exact; use --data measured or --data FILE to add noise "
                          "to the positions")
    if args.seed is not None and args.noise is None and args.starts == 1:
        raise OptionError("--seed: seeds the noise and the multi-start; give --noise SIGMA or --starts N too")
    if args.window is not None and args.method != "adapted-direct":
        raise OptionError(f"--window: applies to --method adapted-direct only, not to --method {args.method}")
    if args.cutoff is not None and args.smoothing != "butterworth":
        raise OptionError("--cutoff: applies to --smoothing butterworth only")
    from casflex.identification import Solver

    try:  # the library's rule of what a solver is; the option's own words
        Solver(args.solver)
    except ValueError:
        raise OptionError(f"--solver: {args.solver!r} is neither gauss-newton nor an available CasADi nlpsol plugin "
                          "(e.g. ipopt, sqpmethod)") from None
    if args.method == "indirect" and args.solver == "gauss-newton" and (
            args.transcription == "multiple-shooting" or args.residue == "full"):
        raise OptionError("--solver gauss-newton: single shooting on positions only; use --solver ipopt for "
                          "--transcription multiple-shooting or --residue full")
    nlp = args.transcription == "multiple-shooting" or args.residue == "full" or args.solver not in (None,
                                                                                                   "gauss-newton")
    if args.method == "indirect" and args.hessian is not None and not nlp:
        raise OptionError("--hessian: the NLP solver's Hessian; the indirect method here is single shooting by "
                          "gauss-newton: give --solver ipopt (or another nlpsol) or leave --hessian out")
    if args.initial_state == "velocities" and nlp:
        raise OptionError("--initial-state velocities: estimated velocities need single shooting on positions with "
                          "the gauss-newton solver")
    if args.initial_state == "estimate" and args.residue == "full":
        raise OptionError("--initial-state estimate: an estimated state needs --residue positions")


def _sigma(text: str) -> float | dict[str, float]:
    """--sigma SIGMA or CH=SIGMA,... (argparse type): a standard deviation > 0, or one per channel."""
    def value(v: str, where: str) -> float:
        try:
            x = float(v)
        except ValueError:
            x = math.nan
        if not (math.isfinite(x) and x > 0):
            raise argparse.ArgumentTypeError(f"{where}expected a standard deviation > 0 (m, rad), got {v!r}")
        return x

    if "=" not in text:
        return value(text, "")
    out = {}
    for item in text.split(","):
        name, eq, v = item.partition("=")
        if not (eq and name.strip()):
            raise argparse.ArgumentTypeError(f"expected SIGMA or CHANNEL=SIGMA,..., e.g. x3=2e-4,y3=2e-4, got {text!r}")
        out[name.strip()] = value(v, f"{name.strip()}: ")
    return out


def _vary(text: str) -> tuple[str, tuple[float, float]]:
    """--vary TARGET=LOWER:UPPER (argparse type)."""
    target, eq, bounds = text.partition("=")
    lo, colon, hi = bounds.partition(":")
    try:
        if not (eq and colon and target):
            raise ValueError
        return target.strip(), (float(lo), float(hi))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected TARGET=LOWER:UPPER, e.g. bar2.E=1.5e11:2.5e11, got {text!r}") \
            from None


def _check_forms(model: Model, args: argparse.Namespace) -> None:
    """--vary, --alternatives and --uncertain checked against the scene before any work (one line naming the
    option)."""
    from casflex.identification.form import declared_alternatives
    from casflex.scene.uncertain import declared_uncertain

    try:  # the scenes only: the models are assembled once, by the fit
        declared_alternatives(model, form="none", vary=dict(args.vary or ()), alternatives=args.alternatives or ())
    except ValueError as exc:  # the library's message names "vary <target>" or "alternatives"
        raise OptionError(f"--{exc}") from None
    try:
        scene = declared_uncertain(model.scene, args.uncertain)
    except ValueError as exc:
        raise OptionError(f"--uncertain: {exc}") from None
    both = sorted({t for t, _ in args.vary or ()} & {u.target for u in scene.uncertain})
    if both:
        raise OptionError(f"--vary {both[0]}: it is declared uncertain (--uncertain or the scene's [[uncertain]]), "
                          "estimated with its prior, not a form to vary")


def _start(model: Model, args: argparse.Namespace) -> float | np.ndarray:
    """The start: a factor of the nominal values (--start, default 1) or one value per parameter."""
    if args.start_values is None:
        return 1.0 if args.start is None else float(args.start)
    names = model.parameter_names
    if len(args.start_values) != len(names):
        raise OptionError(f"--start-values: expected {len(names)} values, one per parameter in the scene's order "
                          f"({', '.join(names)}), got {len(args.start_values)}")
    return np.array(args.start_values, dtype=float)


def _dofs(model: Model, args: argparse.Namespace) -> list[str] | None:
    """The --dofs list, each checked against the model's dofs (None: every measured dof)."""
    if args.dofs is None:
        return None
    names = [d.strip() for d in args.dofs.split(",")]
    for d in names:
        if not d:
            raise OptionError(f"--dofs: empty name in {args.dofs!r} (expected a comma list such as x3,y3,x5,y5)")
        if d not in model.dof_names:
            raise OptionError(f"--dofs: unknown dof {d!r}; the model's dofs are {', '.join(model.dof_names)}")
    return names


def _default_instants(t: np.ndarray, method: str) -> list[float]:
    """DEFAULT_INSTANT_COUNT sample times evenly spread over the data (adapted direct: each
    with a sample after it)."""
    last = t.size - (2 if method == "adapted-direct" else 1)
    idx = np.round(np.linspace(0, last, 2 * DEFAULT_INSTANT_COUNT + 1)[1::2]).astype(int)
    return [float(t[i]) for i in np.unique(idx)]


def _plane(text: str):
    """argparse type of --plane: a casflex.lab.Plane, or the one-line error."""
    from casflex.lab import Plane

    try:
        return Plane.parse(text, option="--plane")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--plane: ")) from None


def _data(model: Model, args: argparse.Namespace) -> tuple[list[MeasurementSet], list[dict[str, Any]]]:
    """The recordings and a description of each for --data simulated | measured | FILE [FILE ...]."""
    from casflex.data import add_position_noise, load_measurements, measured_set
    from casflex.simulate import simulated_set

    seed = args.seed
    if args.noise and seed is None:  # a fresh seed, reported so that the run can be repeated
        seed = int(np.random.default_rng().integers(2**31))
    if args.data[0] not in ("simulated", "measured"):
        sets, infos = [], []
        for i, path in enumerate(args.data):
            if str(path).lower().endswith((".trc", ".c3d")):  # a lab trial: the scene's markers by their labels
                from casflex.lab import trial_markers

                data = trial_markers(model, path, args.plane)
            else:
                data = load_measurements(path)
            info = {"kind": "file", "path": str(path), "samples": int(data.t.size), "channels": list(data.channels)}
            if args.noise:
                data = add_position_noise(data, args.noise, seed + i)
                info.update(noise=args.noise, seed=seed + i)
            sets.append(data)
            infos.append(info)
        return sets, infos
    run = model.scene.run
    dt = run.dt
    # to the end of what the method reads: the horizon, or the last instant and one sample after it
    until = args.horizon if args.method == "indirect" else (max(args.instants) + dt if args.instants else run.t_end)
    if until is None:
        until = run.t_end
    if args.method == "indirect" and abs(until / dt - round(until / dt)) > 1e-6:
        raise OptionError(f"--horizon: {until:g} s is not a whole number of the scene's steps dt = {dt:g} s")
    # one sample beyond what the method reads; measured_set drops the first and last samples
    kind = args.data[0]
    extra = 1 if kind == "simulated" else 2
    steps = math.ceil(until / dt - 1e-9) + extra
    data = simulated_set(model, t_end=steps * dt, dt=dt, alpha=0.0)
    info = {"kind": kind, "t_end": steps * dt, "dt": dt, "alpha": 0.0}
    if kind == "measured":
        data = measured_set(data, noise=args.noise or 0.0, seed=seed)
        info.update(noise=args.noise or 0.0, seed=seed if args.noise else None)
    info["samples"] = int(data.t.size)
    return [data], [info]


def _describe_data(info: dict[str, Any]) -> str:
    """One line on where the data came from."""
    if info["kind"] == "file":
        text = f"data: {info['path']}, {info['samples']} samples of {', '.join(info['channels'])}"
        if info.get("noise"):
            text += (f"; Gaussian noise of std {info['noise']:g} (m, rad) added to the positions "
                     f"(seed {info['seed']}), velocities and accelerations from the file unchanged")
        return text
    text = (f"data: {info['kind']} set, HHT simulation at the nominal parameters to {info['t_end']:.6g} s, "
            f"dt = {info['dt']:g} s, alpha = 0, {info['samples']} samples")
    if info["kind"] == "measured":
        text += ", velocities and accelerations by central differences"
        if info.get("noise"):
            text += f", Gaussian noise of std {info['noise']:g} (m, rad) on the positions (seed {info['seed']})"
    return text


def _options(args: argparse.Namespace) -> dict[str, Any]:
    """The chosen method's option values (:mod:`casflex.identification.options`) from the command's options;
    each value is checked by its object."""
    from casflex.identification import Budget, ModelRun, Shooting, Smoothing, Solver, Uncertainty

    indirect = args.method == "indirect"
    # the NLP solvers' iteration logs unless --quiet; Gauss-Newton reports its stages as progress messages
    solver = Solver(args.solver, hessian=args.hessian, transform=args.transform,
                    verbose=not args.quiet and not indirect, compiled=(args.compiled or None) if indirect else
                    args.compiled, budget=Budget(args.max_iter, args.max_time) if indirect else None,
                    loss=args.loss or "linear")
    if not indirect:
        out = {"solver": solver, "smoothing": Smoothing(args.smoothing or "spline", args.cutoff),
               "beam_forces": args.beam_forces, "instants": args.instants}
        return out | ({"window": args.window} if args.method == "adapted-direct" else {})
    return {"horizon": args.horizon, "solver": solver,
            "shooting": Shooting(args.transcription, interval=args.interval, residue=args.residue),
            "run": ModelRun(args.dt, args.alpha),
            "uncertainty": Uncertainty(args.model_error, args.form, vary=dict(args.vary or ()),
                                       alternatives=args.alternatives or (), uncertain=args.uncertain)}


def _recordings(sets: list[MeasurementSet], args: argparse.Namespace, dofs: list[str] | None) -> Any:
    """What the method reads: the first set (direct methods), or each set as an Experiment (indirect)."""
    from casflex.identification import Experiment

    if args.method != "indirect":
        return sets[0]
    return [Experiment(d, initial_state=args.initial_state, channels=None if dofs is None else tuple(dofs),
                       noise=args.sigma, name=f"recording {i + 1}" if len(sets) > 1 else "data")
            for i, d in enumerate(sets)]


def _identify(model: Model, sets: list[MeasurementSet], args: argparse.Namespace, start: float | np.ndarray,
              dofs: list[str] | None) -> IdentificationResult:
    """Call the chosen identification method with the command's options."""
    from casflex.identification import method_function

    return method_function(args.method)(model, _recordings(sets, args, dofs), start=start, **_options(args))


def _multistart(sets: list[MeasurementSet], args: argparse.Namespace, start: float | np.ndarray,
                dofs: list[str] | None) -> IdentificationResult:
    """--starts N: the given start and N - 1 drawn within a factor 3 of it (seeded by --seed), run on 2
    worker processes (:func:`casflex.study.multistart.multistart`); the best successful start is
    fitted again for the full result, which lists every start."""
    from casflex.study.multistart import WORKERS, EveryStartFailed, multistart
    from casflex.study.sweep import max_workers

    workers = min(WORKERS, args.starts, max_workers()[0])  # a one-core machine runs one
    print(f"  multi-start: {args.starts} starts on {workers} worker process(es)", flush=True)
    try:
        result = multistart(args.scene, _recordings(sets, args, dofs), args.starts, method=args.method, start=start,
                            seed=args.seed, progress=not args.quiet, **_options(args))
    except EveryStartFailed as exc:
        _print_starts(exc.records)
        raise OptionError("--starts: every start failed; see the errors above") from None
    records, best = result.extra["multistart"]["starts"], result.extra["multistart"]["best"]
    _print_starts(records)
    good = any(r.get("success") for r in records)
    print(f"  best: start {best}{'' if good else ' (none succeeded)'}; fitted again for the full report", flush=True)
    return result


def _print_starts(records: list[dict[str, Any]]) -> None:
    for k, rec_k in enumerate(records):
        what = (f"{'success' if rec_k['success'] else 'no success'}, objective {rec_k['objective']:.6g}"
                if "error" not in rec_k else f"error: {rec_k['error'][:100]}")
        print(f"    start {k}: " + ", ".join(f"{v:.4g}" for v in rec_k.get("start", [])) + f": {what}")


def _heading(model: Model, args: argparse.Namespace, start: float | np.ndarray) -> str:
    """One line: what is identified, how, and from where."""
    start_text = (f"{start:g} x nominal" if isinstance(start, float)
                  else ", ".join(f"{k} = {v:g}" for k, v in zip(model.parameter_names, start, strict=True)))
    if args.method != "indirect":
        where = f"instants {', '.join(f'{t:g}' for t in args.instants)} s"
    else:
        run = model.scene.run
        window = "the whole data" if args.horizon is None else f"horizon {args.horizon:g} s"
        where = (f"{window}, {args.transcription}, residue {args.residue}, initial state {args.initial_state}, model "
                 f"dt = {args.dt or run.dt:g} s, alpha = {run.alpha if args.alpha is None else args.alpha:g}")
    solver = args.solver or ("gauss-newton" if args.method == "indirect" and args.transcription == "single-shooting"
                             and args.residue == "positions" else "ipopt")
    return (f"identify {', '.join(model.parameter_names)} of scene {model.scene.name}: {args.method} method, "
            f"{where}, start {start_text}, solver {solver}")


def cmd_identify(args: argparse.Namespace, outputs: Outputs) -> int:
    _check_options(args)
    out = outputs.file("--out", args.out, (".json",), "result") if args.out else None
    model = load_model(args.scene)
    if model.n_p == 0:
        raise OptionError(f"scene {model.scene.name}: declares no parameters to identify ([[parameters]])")
    plots = outputs.directory("--plots", args.plots) if args.plots else None
    start, dofs = _start(model, args), _dofs(model, args)
    if args.method == "indirect":
        args.transcription = args.transcription or "single-shooting"
        args.residue = args.residue or "positions"
        args.initial_state = args.initial_state or "scene"
        args.model_error = args.model_error or "refine"
        args.form = args.form or "auto"
        _check_forms(model, args)
    sets, infos = _data(model, args)
    if isinstance(args.sigma, dict):  # one value per compared channel, checked before any fit
        for d in sets:
            names = dofs or d.channels
            bad = [c for c in args.sigma if c not in names] or [c for c in names if c not in args.sigma]
            if bad:
                what = "is not a compared channel" if bad[0] in args.sigma else "has no value"
                raise OptionError(f"--sigma: {bad[0]!r} {what}; give one per compared channel ({', '.join(names)})")
    if args.method != "indirect" and args.instants is None:
        args.instants = _default_instants(sets[0].t, args.method)
    print(_heading(model, args, start))
    for info in infos:
        print(f"  {_describe_data(info)}")
    sys.stdout.flush()
    try:
        if args.starts > 1:
            result = _multistart(sets, args, start, dofs)
        else:
            result = _identify(model, sets, args, start, dofs)
    except RuntimeError as exc:  # CasADi: e.g. a solver plugin that needs a missing library
        from casflex.identification.problem import casadi_reason

        solver = args.solver or ("gauss-newton" if args.method == "indirect" else "ipopt")
        raise OptionError(f"--solver {solver}: the solver failed: {casadi_reason(exc)}") from None
    result.extra["data"] = infos[0] if len(infos) == 1 else infos
    print(result.summary())
    if out is not None:
        result.save(out)
    if plots is not None:
        from casflex.plotting.identification import save_identification_figures

        save_identification_figures(result, plots)
    if not result.success:
        why = f"{result.status}; {result.message}" if result.message else result.status
        print(f"casflex: identification did not succeed ({why})", file=sys.stderr)
        return 1
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """The ``identify`` subcommand's options (method-specific ones default to None = not given)."""
    from casflex.identification.choices import (
        BEAM_FORCES,
        FORMS,
        HESSIANS,
        INITIAL_STATES,
        LOSSES,
        MODEL_ERRORS,
        RESIDUES,
        SMOOTHERS,
        TRANSCRIPTIONS,
        TRANSFORMS,
    )

    s = sub.add_parser("identify", help="identify the scene's parameters from simulated, measured or file data",
                       description="Identify the scene's [[parameters]] from kinematic data. Examples and the data "
                                   "file formats: docs/data-format.md.")
    s.add_argument("scene", help="built-in scene name (twobar) or a TOML file")
    s.add_argument("--method", required=True, choices=IDENTIFY_METHODS)
    s.add_argument("--transcription", choices=TRANSCRIPTIONS,
                   help="indirect only (default single-shooting)")
    s.add_argument("--plane", type=_plane, default="X,Y", metavar="AXES",
                   help="for a .trc or .c3d trial: the lab axes that become the model's x and y, e.g. X,Y (default: "
                        "OpenSim's X forward, Y up: seen from +Z) or -Z,Y")
    s.add_argument("--data", action="append", metavar="simulated|measured|FILE",
                   help="the exact simulated set (default), the measured set (positions, central differences), "
                        "or a .npz/.csv file, or a lab trial's .trc or .c3d (the scene's markers by their label, see "
                        "--plane); repeat --data FILE for several recordings (indirect)")
    s.add_argument("--initial-state", choices=INITIAL_STATES,
                   help="indirect: the state at the first sample: the scene's (default), the scene's positions with "
                        "estimated velocities, or estimated")
    s.add_argument("--dt", type=positive("a time step in s"),
                   help="indirect: the model's time step, s (default: the scene's, never the samples' spacing)")
    s.add_argument("--alpha", type=alpha_value, help="indirect: the model's HHT alpha (default: the scene's)")
    s.add_argument("--sigma", type=_sigma, metavar="SIGMA|CH=SIGMA,...",
                   help="indirect: the data's noise, if known: one value for every channel (m) or one per channel "
                        "(x3=2e-4,y3=2e-4,...; m or rad). It weights the channels, and a fit whose residual RMS on "
                        "a channel exceeds 3 SIGMA does not succeed. Default: each channel's noise estimated from "
                        "the residuals, the channels weighted by it when they differ by more than 20 %%")
    s.add_argument("--max-iter", type=integer(1, "a number of iterations"), default=100,
                   help="indirect: Gauss-Newton iterations per stage of the growing horizon (default 100)")
    s.add_argument("--max-time", type=positive("a time in s"), default=600.0,
                   help="indirect: wall-time budget of the solve, s (default 600); the best point is reported")
    s.add_argument("--model-error", choices=MODEL_ERRORS,
                   help="indirect: estimate the discretisation error by a refit on a refined model (refine, "
                        "default) or not (none)")
    s.add_argument("--form", choices=FORMS,
                   help="indirect: auto (default): refit with the other beam theory too (beams with or without the "
                        "section's rotary inertia) and report how far the parameters move; none: only --vary and "
                        "--alternatives")
    s.add_argument("--vary", type=_vary, action="append", metavar="TARGET=LO:HI",
                   help="indirect: a scene property known within a range, e.g. bar2.E=1.5e11:2.5e11: refit at both "
                        "ends; the parameters' move joins their standard errors (repeatable)")
    s.add_argument("--uncertain", type=_uncertain, action="append", metavar="TARGET=SD|P%|LO:HI",
                   help="indirect: a scene property known only within an uncertainty (e.g. shank.mass=10%%, "
                        "bar2.E=5e9, shank.inertia=0.12:0.18), estimated with that prior beside the parameters; "
                        "repeatable, added to the scene's [[uncertain]]")
    s.add_argument("--alternatives", nargs="+", metavar="SCENE",
                   help="indirect: other forms of the model (scene files declaring the same parameters), each "
                        "refitted and compared with the scene by AIC")
    s.add_argument("--loss", choices=LOSSES,
                   help="indirect: linear (least squares, default) or huber: robust to marker artefacts, the "
                        "samples far from the model weighted down (reported)")
    s.add_argument("--plots", type=output_path, metavar="DIR",
                   help="indirect: write measured-vs-fitted figures with the residuals")
    s.add_argument("--instants", type=non_negative("a time in s"), nargs="+", metavar="T",
                   help=f"direct methods: times, s (default: {DEFAULT_INSTANT_COUNT} samples evenly spread over the "
                        "data)")
    s.add_argument("--horizon", type=positive("a time in s"), metavar="T",
                   help="indirect: compared window [t0, t0 + T] from the first sample t0, s (default: the whole "
                        "data; the scene's t_end for the simulated and measured sets)")
    s.add_argument("--start", type=positive("a factor of the nominal values"), metavar="F",
                   help="start at F times the nominal values (default 1)")
    s.add_argument("--start-values", type=float, nargs="+", metavar="V",
                   help="start values, one per scene parameter in the scene's order")
    s.add_argument("--residue", choices=RESIDUES, help="indirect: Eq. 16 positions (default) or Eq. 17 full")
    s.add_argument("--dofs", help="indirect: comma list of compared dofs, e.g. x3,y3,x5,y5 (default: all measured)")
    s.add_argument("--noise", type=non_negative("a standard deviation (m, rad)"), metavar="SIGMA",
                   help="Gaussian noise std on the positions, m and rad (--data measured or FILE)")
    s.add_argument("--seed", type=integer(0, "a seed"), metavar="N",
                   help="seed of the noise (default: a fresh one, printed)")
    s.add_argument("--solver", help="gauss-newton (indirect single shooting, default) or a CasADi nlpsol plugin "
                                    "(default ipopt)")
    s.add_argument("--transform", choices=TRANSFORMS, default="linear",
                   help="decision variables p/scale (linear, default) or log(p/scale)")
    s.add_argument("--hessian", choices=HESSIANS,
                   help="solver's Hessian: exact or gauss-newton (default: exact for direct, gauss-newton for "
                        "adapted-direct and indirect)")
    s.add_argument("--compiled", action="store_true",
                   help="generate and compile C for the solver's functions (needs gcc; longer build, faster solve)")
    s.add_argument("--interval", type=integer(1, "a number of steps"), metavar="STEPS",
                   help="indirect multiple shooting: steps per shooting interval (default 20)")
    s.add_argument("--starts", type=integer(1, "a number of starts"), default=1,
                   help="multi-start: the start and N - 1 drawn within a factor 3 of it (seeded by --seed), run in "
                        "parallel; the best successful fit is reported (default 1)")
    s.add_argument("--smoothing", choices=SMOOTHERS,
                   help="direct methods on positions-only data: how velocities and accelerations are obtained "
                        "(spline with cross-validation, default, or butterworth)")
    s.add_argument("--cutoff", type=positive("a frequency in Hz"), help="--smoothing butterworth: cutoff, Hz")
    s.add_argument("--window", type=integer(2, "a number of samples"),
                   help="adapted-direct: samples per instant (default: the paper's 2, more when translations "
                        "are unknown)")
    s.add_argument("--beam-forces", choices=BEAM_FORCES,
                   help="direct methods: beam deformation forces solved for (unknown; default for positions-only "
                        "data) or computed from the positions (model; the paper)")
    s.add_argument("--out", type=output_path, metavar="FILE.json", help="write the result as JSON")
    s.add_argument("--quiet", action="store_true", help="no solver iteration log or progress messages")
    s.set_defaults(func=cmd_identify, data=None)
