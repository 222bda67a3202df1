"""``casflex identify``: the identification methods from the command line (usage and data file
formats in ``docs/data-format.md``); exit status 1 when the identification does not succeed."""

from __future__ import annotations

import argparse
import math
import sys
from typing import TYPE_CHECKING, Any

import numpy as np

from casflex.cli._base import OptionError, Outputs, integer, load_model, non_negative, positive

if TYPE_CHECKING:
    from casflex.data import MeasurementSet
    from casflex.identification import IdentificationResult
    from casflex.model import Model

IDENTIFY_METHODS = ("direct", "adapted-direct", "indirect")
#: instants of the direct methods when --instants is not given: this many, evenly spread over the data
DEFAULT_INSTANT_COUNT = 5
#: options of the indirect method only (attribute -> option), and of the direct methods only
_INDIRECT_ONLY = {"transcription": "--transcription", "horizon": "--horizon", "residue": "--residue",
                  "dofs": "--dofs", "interval": "--interval"}
_DIRECT_ONLY = {"instants": "--instants"}


def _check_options(args: argparse.Namespace) -> None:
    """Reject options that do not apply to the chosen method or data, naming the option."""
    direct = args.method != "indirect"
    for attr, opt in (_INDIRECT_ONLY if direct else _DIRECT_ONLY).items():
        if getattr(args, attr) is not None:
            where = "the indirect method" if direct else "the direct methods (direct, adapted-direct)"
            raise OptionError(f"{opt}: applies to {where} only, not to --method {args.method}")
    if args.interval is not None and args.transcription == "single-shooting":
        raise OptionError("--interval: applies to --transcription multiple-shooting only")
    if args.start is not None and args.start_values is not None:
        raise OptionError("--start and --start-values: give one or the other, not both")
    if args.noise is not None and args.data == "simulated":
        raise OptionError("--noise: the simulated set is exact; use --data measured or --data FILE to add noise "
                          "to the positions")
    if args.seed is not None and args.noise is None:
        raise OptionError("--seed: seeds the noise; give --noise SIGMA too")
    import casadi as ca

    if not ca.has_nlpsol(args.solver):
        raise OptionError(f"--solver: {args.solver!r} is not an available CasADi nlpsol plugin (e.g. ipopt, "
                          "sqpmethod)")


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


def _data(model: Model, args: argparse.Namespace) -> tuple[MeasurementSet, dict[str, Any]]:
    """(MeasurementSet, description dict) for --data simulated | measured | FILE."""
    from casflex.data import add_position_noise, load_measurements, measured_set, simulated_set

    seed = args.seed
    if args.noise and seed is None:  # a fresh seed, reported so that the run can be repeated
        seed = int(np.random.default_rng().integers(2**31))
    if args.data not in ("simulated", "measured"):
        data = load_measurements(args.data)
        info = {"kind": "file", "path": str(args.data), "samples": int(data.t.size),
                "channels": list(data.channels)}
        if args.noise:
            data = add_position_noise(data, args.noise, seed)
            info.update(noise=args.noise, seed=seed)
        return data, info
    run = model.scene.run
    dt = run.dt
    # to the end of what the method reads: the horizon, or the last instant and one sample after it
    until = args.horizon if args.method == "indirect" else (max(args.instants) + dt if args.instants else run.t_end)
    if until is None:
        until = run.t_end
    if args.method == "indirect" and abs(until / dt - round(until / dt)) > 1e-6:
        raise OptionError(f"--horizon: {until:g} s is not a whole number of the scene's steps dt = {dt:g} s")
    # one sample beyond what the method reads; measured_set drops the first and last samples
    extra = 1 if args.data == "simulated" else 2
    steps = math.ceil(until / dt - 1e-9) + extra
    data = simulated_set(model, t_end=steps * dt, dt=dt, alpha=0.0)
    info = {"kind": args.data, "t_end": steps * dt, "dt": dt, "alpha": 0.0}
    if args.data == "measured":
        data = measured_set(data, noise=args.noise or 0.0, seed=seed)
        info.update(noise=args.noise or 0.0, seed=seed if args.noise else None)
    info["samples"] = int(data.t.size)
    return data, info


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


def _casadi_reason(exc: RuntimeError) -> str:
    """The informative line of a CasADi error (its first lines only locate the failing call)."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    useful = [ln for ln in lines if not ln.startswith("Error in Function::call") and "Assertion" not in ln]
    reason = (useful or lines or [type(exc).__name__])[0]
    return reason if len(reason) <= 200 else reason[:197] + "..."


def _identify(model: Model, data: MeasurementSet, args: argparse.Namespace, start: float | np.ndarray,
              dofs: list[str] | None) -> IdentificationResult:
    """Call the chosen identification method with the command's options."""
    from casflex.identification import identify_adapted_direct, identify_direct, identify_indirect

    common = {"start": start, "solver": args.solver, "transform": args.transform, "compiled": args.compiled,
              "verbose": not args.quiet}
    if args.hessian is not None:
        common["hessian"] = args.hessian
    if args.method == "direct":
        return identify_direct(model, data, args.instants, **common)
    if args.method == "adapted-direct":
        return identify_adapted_direct(model, data, args.instants, **common)
    return identify_indirect(model, data, args.horizon, transcription=args.transcription, residue=args.residue,
                             dofs=dofs, interval=args.interval, **common)


def _heading(model: Model, args: argparse.Namespace, start: float | np.ndarray) -> str:
    """One line: what is identified, how, and from where."""
    start_text = (f"{start:g} x nominal" if isinstance(start, float)
                  else ", ".join(f"{k} = {v:g}" for k, v in zip(model.parameter_names, start, strict=True)))
    where = (f"instants {', '.join(f'{t:g}' for t in args.instants)} s" if args.method != "indirect" else
             f"horizon {args.horizon:g} s, {args.transcription}, residue {args.residue}")
    return (f"identify {', '.join(model.parameter_names)} of scene {model.scene.name}: {args.method} method, "
            f"{where}, start {start_text}, solver {args.solver}")


def cmd_identify(args: argparse.Namespace, outputs: Outputs) -> int:
    _check_options(args)
    out = outputs.file("--out", args.out, (".json",), "result") if args.out else None
    model = load_model(args.scene)
    if model.n_p == 0:
        raise OptionError(f"scene {model.scene.name}: declares no parameters to identify ([[parameters]])")
    start, dofs = _start(model, args), _dofs(model, args)
    if args.method == "indirect":
        args.transcription = args.transcription or "multiple-shooting"
        args.residue = args.residue or "positions"
    data, info = _data(model, args)
    if args.method == "indirect" and args.horizon is None:
        args.horizon = float(data.t[-1])  # the whole data
    elif args.method != "indirect" and args.instants is None:
        args.instants = _default_instants(data.t, args.method)
    print(_heading(model, args, start))
    print(f"  {_describe_data(info)}")
    sys.stdout.flush()
    try:
        result = _identify(model, data, args, start, dofs)
    except RuntimeError as exc:  # CasADi: e.g. a solver plugin that needs a missing library
        raise OptionError(f"--solver {args.solver}: the solver failed: {_casadi_reason(exc)}") from None
    result.extra["data"] = info
    print(result.summary())
    if out is not None:
        result.save(out)
    if not result.success:
        why = f"{result.status}; {result.message}" if result.message else result.status
        print(f"casflex: identification did not succeed ({why})", file=sys.stderr)
        return 1
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """The ``identify`` subcommand's options (method-specific ones default to None = not given)."""
    from casflex.identification import HESSIANS, RESIDUES, TRANSCRIPTIONS, TRANSFORMS

    s = sub.add_parser("identify", help="identify the scene's parameters from simulated, measured or file data",
                       description="Identify the scene's [[parameters]] from kinematic data. Examples and the data "
                                   "file formats: docs/data-format.md.")
    s.add_argument("scene", help="built-in scene name (twobar) or a TOML file")
    s.add_argument("--method", required=True, choices=IDENTIFY_METHODS)
    s.add_argument("--transcription", choices=TRANSCRIPTIONS,
                   help="indirect only (default multiple-shooting)")
    s.add_argument("--data", default="simulated", metavar="simulated|measured|FILE",
                   help="the exact simulated set (default), the measured set (positions, central differences), "
                        "or a .npz/.csv file")
    s.add_argument("--instants", type=non_negative("a time in s"), nargs="+", metavar="T",
                   help=f"direct methods: times, s (default: {DEFAULT_INSTANT_COUNT} samples evenly spread over the "
                        "data)")
    s.add_argument("--horizon", type=positive("a time in s"), metavar="T",
                   help="indirect: compared window [0, T], s (default: the whole data; the scene's t_end for the "
                        "simulated and measured sets)")
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
    s.add_argument("--solver", default="ipopt", help="CasADi nlpsol plugin (default ipopt)")
    s.add_argument("--transform", choices=TRANSFORMS, default="linear",
                   help="decision variables p/scale (linear, default) or log(p/scale)")
    s.add_argument("--hessian", choices=HESSIANS,
                   help="solver's Hessian: exact or gauss-newton (default: exact for direct, gauss-newton for "
                        "adapted-direct and indirect)")
    s.add_argument("--compiled", action="store_true",
                   help="generate and compile C for the solver's functions (needs gcc; longer build, faster solve)")
    s.add_argument("--interval", type=integer(1, "a number of steps"), metavar="STEPS",
                   help="indirect multiple shooting: steps per shooting interval (default 20)")
    s.add_argument("--out", metavar="FILE.json", help="write the result as JSON")
    s.add_argument("--quiet", action="store_true", help="no solver iteration log or progress messages")
    s.set_defaults(func=cmd_identify)
