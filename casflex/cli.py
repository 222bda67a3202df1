"""The ``casflex`` command: thin over the Python API (parse, call, print).

Errors print one line, ``casflex: error: ...``, and exit with status 2; Ctrl-C exits with 130
and leaves no half-written file. ``casflex identify`` exits with 1 when the solver does not
succeed (usage examples in ``docs/data-format.md``).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import signal
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from casflex.data import MeasurementSet
    from casflex.identification import IdentificationResult
    from casflex.model import Model

__all__ = ["main"]


def _model(args):
    from casflex.model import assemble
    from casflex.scene_io import load_scene

    return assemble(load_scene(args.scene), inertia=getattr(args, "inertia", None))


def _print_node_table(traj, node: str, times) -> None:
    print(f"  node {node}:      t (s)       x (m)       y (m)   theta (rad)")
    for t in times:
        i = traj.at(t)
        print(f"           {traj.t[i]:9.3f} {traj.dof('x' + node)[i]:11.5f} {traj.dof('y' + node)[i]:11.5f} "
              f"{traj.dof('theta' + node)[i]:12.5f}")


def _summary(model, traj) -> None:
    st = traj.stats
    how = "compiled C" if traj.meta.get("compiled") else "interpreted"
    print(f"scene {model.scene.name}: {model.n_dof} dofs, {model.n_con} constraints, {len(traj.t) - 1} steps of "
          f"dt = {traj.meta['dt']:g} s, alpha = {traj.meta['alpha']:g}, inertia {model.inertia}")
    extra = f", {st['newton_iterations'] / max(st['steps'], 1):.2f} Newton iterations/step" \
        if st.get("newton_iterations") is not None else ""
    comp = f" (+ {st['compile_s']:.2f} s compile{', cached' if st.get('compile_cached') else ''})" \
        if traj.meta.get("compiled") else ""
    print(f"  run: {st['run_s'] * 1e3:.1f} ms {how}{comp}{extra}")
    node = "5" if "x5" in model.dof_names else model.node_names[len(model.scene.nodes) - 1]
    times = [t for t in (0.69, 2.83) if t <= traj.t[-1]] or [traj.t[-1]]
    _print_node_table(traj, node, times)
    print("  peak joint outputs (max |value| over the run):")
    for name in traj.output_names:
        if name.endswith((".force", ".moment")) or name.startswith(tuple(s.name + "." for s in model.scene.supports)):
            v = traj.output(name)
            i = int(np.argmax(np.abs(v)))
            unit = "N m" if name.endswith((".moment", ".theta")) else "N"
            print(f"    {name:<22s} {v[i]:12.4f} {unit} at t = {traj.t[i]:.3f} s")
    e = traj.energies
    print(f"  energy: E(0) = {e['total'][0]:.6f} J, E(end) = {e['total'][-1]:.6f} J, work of loads "
          f"{e['work_external'][-1]:.6f} J, removed by numerical damping {e['dissipated'][-1]:.3e} J "
          f"(max |.| {np.abs(e['dissipated']).max():.3e} J)")


def cmd_simulate(args) -> int:
    from casflex.simulate import simulate

    model = _model(args)
    traj = simulate(model, args.t_end, dt=args.dt, alpha=args.alpha, compiled=args.compiled,
                    progress=not args.quiet)
    _summary(model, traj)
    if args.out:
        print(f"  wrote {traj.save(args.out)}")
    if args.plots:
        from casflex.plotting import save_standard_figures

        for path in save_standard_figures(model, traj, args.plots, animation=not args.no_animation):
            print(f"  wrote {path}")
    return 0


def cmd_static(args) -> int:
    from casflex.results import atomic_write_bytes
    from casflex.statics import equilibrium

    model = _model(args)
    res = equilibrium(model, steps=args.steps)
    print(f"static equilibrium of {model.scene.name}: {res.iterations} Newton iterations "
          f"over {len(res.load_factors)} load steps")
    for k, name in enumerate(model.node_names[:len(model.scene.nodes)]):
        print(f"  node {name:<6s} x = {res.q[3 * k]:11.6f} m  y = {res.q[3 * k + 1]:11.6f} m  "
              f"theta = {res.q[3 * k + 2]:10.6f} rad")
    for name, lam in zip(model.constraint_names, res.lam, strict=True):
        print(f"  reaction {name:<18s} {-lam:12.4f}")
    if args.out:
        import io

        buf = io.BytesIO()
        np.savez(buf, q=res.q, lam=res.lam, dof_names=np.array(model.dof_names),
                 constraint_names=np.array(model.constraint_names))
        print(f"  wrote {atomic_write_bytes(args.out, buf.getvalue())}")
    return 0


def cmd_modes(args) -> int:
    from casflex.results import atomic_write_bytes
    from casflex.statics import equilibrium, modes

    model = _model(args)
    q = equilibrium(model).q if args.about == "equilibrium" else None
    res = modes(model, q=q, count=args.count)
    where = "the static equilibrium" if q is not None else "the initial configuration"
    print(f"natural frequencies of {model.scene.name} linearised about {where}:")
    for k, f in enumerate(res.freq_hz, 1):
        print(f"  mode {k:3d}: {f:14.6f} Hz")
    if args.out:
        import io

        buf = io.BytesIO()
        np.savez(buf, freq_hz=res.freq_hz, shapes=res.shapes, dof_names=np.array(model.dof_names))
        print(f"  wrote {atomic_write_bytes(args.out, buf.getvalue())}")
    return 0


def cmd_demo(args) -> int:
    import shutil

    from casflex.plotting import save_standard_figures
    from casflex.simulate import simulate

    args.scene, args.inertia = "twobar", None
    model = _model(args)
    compiled = shutil.which("gcc") is not None
    print("casflex demo: the seed paper's two-bar flexible chain, 3 s under gravity (HHT-alpha, "
          + ("compiled C" if compiled else "interpreted: no gcc found") + ")")
    traj = simulate(model, 3.0, compiled=compiled, progress=True)
    _summary(model, traj)
    out = Path(args.out)
    print(f"  wrote {traj.save(out / 'twobar.npz')}")
    for path in save_standard_figures(model, traj, out, animation=not args.no_animation):
        print(f"  wrote {path}")
    return 0


def cmd_export(args) -> int:
    from casflex.export import export_c

    model = _model(args)
    e = export_c(model, args.out, what=args.what, alpha=args.alpha, dt=args.dt, t_end=args.t_end)
    print(f"casflex export ({args.what}) of scene {model.scene.name!r}: {', '.join(e.functions)}")
    for f in e.files:
        print(f"  wrote {f}")
    if args.build:
        print(f"  built {e.build()}")
    else:
        print(f"  build with: make -C {e.out_dir}")
    return 0


# --------------------------------------------------------------------------------------------
# casflex identify

IDENTIFY_METHODS = ("direct", "adapted-direct", "indirect")
#: default instants (s): the seed paper's instant for the direct method, its third set for the adapted one
DEFAULT_INSTANTS = {"direct": (0.69,), "adapted-direct": (0.4, 1.1, 1.6, 1.9, 2.3)}
DEFAULT_HORIZON = 0.69  # s, indirect method
#: options of the indirect method only (attribute -> option), and of the direct methods only
_INDIRECT_ONLY = {"transcription": "--transcription", "horizon": "--horizon", "residue": "--residue",
                  "dofs": "--dofs", "interval": "--interval"}
_DIRECT_ONLY = {"instants": "--instants"}


def _check_identify_options(args: argparse.Namespace) -> None:
    """Reject options that do not apply to the chosen method or data, naming the option."""
    direct = args.method != "indirect"
    for attr, opt in (_INDIRECT_ONLY if direct else _DIRECT_ONLY).items():
        if getattr(args, attr) is not None:
            where = "the indirect method" if direct else f"the direct methods ({', '.join(DEFAULT_INSTANTS)})"
            raise ValueError(f"{opt}: applies to {where} only, not to --method {args.method}")
    if args.interval is not None and args.transcription == "single-shooting":
        raise ValueError("--interval: applies to --transcription multiple-shooting only")
    if args.start is not None and args.start_values is not None:
        raise ValueError("--start and --start-values: give one or the other, not both")
    if args.noise is not None and args.data == "simulated":
        raise ValueError("--noise: the simulated set is exact; use --data measured or --data FILE to add noise "
                         "to the positions")
    if args.seed is not None and args.noise is None:
        raise ValueError("--seed: seeds the noise; give --noise SIGMA too")
    if args.noise is not None and not (math.isfinite(args.noise) and args.noise >= 0):
        raise ValueError(f"--noise: expected a standard deviation >= 0 (m, rad), got {args.noise:g}")
    if args.horizon is not None and not (math.isfinite(args.horizon) and args.horizon > 0):
        raise ValueError(f"--horizon: expected a positive time (s), got {args.horizon:g}")
    if args.instants is not None and not all(math.isfinite(t) and t >= 0 for t in args.instants):
        raise ValueError(f"--instants: expected times >= 0 (s), got {args.instants}")
    if args.interval is not None and args.interval < 1:
        raise ValueError(f"--interval: expected a number of steps >= 1, got {args.interval}")
    if args.start is not None and not (math.isfinite(args.start) and args.start > 0):
        raise ValueError(f"--start: expected a positive factor of the nominal values, got {args.start:g}")
    import casadi as ca

    if not ca.has_nlpsol(args.solver):
        raise ValueError(f"--solver: {args.solver!r} is not an available CasADi nlpsol plugin (e.g. ipopt, sqpmethod)")


def _identify_start(model: Model, args: argparse.Namespace) -> float | np.ndarray:
    """The start: a factor of the nominal values (--start, default 1) or one value per parameter."""
    if args.start_values is None:
        return 1.0 if args.start is None else float(args.start)
    names = model.parameter_names
    if len(args.start_values) != len(names):
        raise ValueError(f"--start-values: expected {len(names)} values, one per parameter in the scene's order "
                         f"({', '.join(names)}), got {len(args.start_values)}")
    return np.array(args.start_values, dtype=float)


def _identify_dofs(model: Model, args: argparse.Namespace) -> list[str] | None:
    """The --dofs list, each checked against the model's dofs (None: every measured dof)."""
    if args.dofs is None:
        return None
    names = [d.strip() for d in args.dofs.split(",")]
    for d in names:
        if not d:
            raise ValueError(f"--dofs: empty name in {args.dofs!r} (expected a comma list such as x3,y3,x5,y5)")
        if d not in model.dof_names:
            raise ValueError(f"--dofs: unknown dof {d!r}; the model's dofs are {', '.join(model.dof_names)}")
    return names


def _needed_until(args: argparse.Namespace, dt: float) -> float:
    """The last time (s) the method reads from the data: the sample after the last instant, or the horizon."""
    if args.method == "indirect":
        return args.horizon
    return max(args.instants) + dt


def _identify_data(model: Model, args: argparse.Namespace) -> tuple[MeasurementSet, dict[str, Any]]:
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
    dt = model.scene.run.dt
    if args.method == "indirect" and abs(args.horizon / dt - round(args.horizon / dt)) > 1e-6:
        raise ValueError(f"--horizon: {args.horizon:g} s is not a whole number of the scene's steps dt = {dt:g} s")
    # one sample beyond what the method reads; measured_set drops the first and last samples
    extra = 1 if args.data == "simulated" else 2
    steps = math.ceil(_needed_until(args, dt) / dt - 1e-9) + extra
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


@contextlib.contextmanager
def _interrupt_flag() -> Iterator[list[int]]:
    """Record Ctrl-C: CasADi turns a KeyboardInterrupt inside a solver into a failed solve, so
    the handler notes the signal (the list is non-empty afterwards) before raising."""
    hits: list[int] = []

    def handler(signum, frame):
        hits.append(signum)
        raise KeyboardInterrupt

    try:
        previous = signal.signal(signal.SIGINT, handler)
    except ValueError:  # not the main thread: leave the handler alone
        yield hits
        return
    try:
        yield hits
    finally:
        signal.signal(signal.SIGINT, previous)


def _casadi_reason(exc: RuntimeError) -> str:
    """The informative line of a CasADi error (its first lines only locate the failing call)."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    useful = [ln for ln in lines if not ln.startswith("Error in Function::call") and "Assertion" not in ln]
    reason = (useful or lines or [type(exc).__name__])[0]
    return reason if len(reason) <= 200 else reason[:197] + "..."


def _run_identification(model: Model, data: MeasurementSet, args: argparse.Namespace, start: float | np.ndarray,
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


def _fill_identify_defaults(args: argparse.Namespace) -> None:
    """Method-dependent defaults of the options left out (None)."""
    if args.method == "indirect":
        args.horizon = DEFAULT_HORIZON if args.horizon is None else args.horizon
        args.transcription = args.transcription or "multiple-shooting"
        args.residue = args.residue or "positions"
    else:
        args.instants = list(DEFAULT_INSTANTS[args.method] if args.instants is None else args.instants)


def _identify_heading(model: Model, args: argparse.Namespace, start: float | np.ndarray) -> str:
    """One line: what is identified, how, and from where."""
    start_text = (f"{start:g} x nominal" if isinstance(start, float)
                  else ", ".join(f"{k} = {v:g}" for k, v in zip(model.parameter_names, start, strict=True)))
    where = (f"instants {', '.join(f'{t:g}' for t in args.instants)} s" if args.method != "indirect" else
             f"horizon {args.horizon:g} s, {args.transcription}, residue {args.residue}")
    return (f"identify {', '.join(model.parameter_names)} of scene {model.scene.name}: {args.method} method, "
            f"{where}, start {start_text}, solver {args.solver}")


def cmd_identify(args: argparse.Namespace) -> int:
    _check_identify_options(args)
    model = _model(args)
    if model.n_p == 0:
        raise ValueError(f"scene {model.scene.name}: declares no parameters to identify ([[parameters]])")
    _fill_identify_defaults(args)
    start, dofs = _identify_start(model, args), _identify_dofs(model, args)
    print(_identify_heading(model, args, start))
    data, info = _identify_data(model, args)
    print(f"  {_describe_data(info)}")
    sys.stdout.flush()
    with _interrupt_flag() as interrupted:
        try:
            result = _run_identification(model, data, args, start, dofs)
        except RuntimeError as exc:  # CasADi: e.g. a solver plugin that needs a missing library
            if interrupted:
                raise KeyboardInterrupt from None
            raise ValueError(f"--solver {args.solver}: the solver failed: {_casadi_reason(exc)}") from None
    if interrupted:
        raise KeyboardInterrupt
    result.extra["data"] = info
    print(result.summary())
    if args.out:
        print(f"  wrote {result.save(args.out)}")
    if not result.success:
        why = f"{result.status}; {result.message}" if result.message else result.status
        print(f"casflex: identification did not succeed ({why})", file=sys.stderr)
        return 1
    return 0


def _add_identify_parser(sub: argparse._SubParsersAction) -> None:
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
    s.add_argument("--instants", type=float, nargs="+", metavar="T",
                   help="direct methods: times, s (default 0.69; adapted-direct 0.4 1.1 1.6 1.9 2.3)")
    s.add_argument("--horizon", type=float, metavar="T", help="indirect: compared window [0, T], s (default 0.69)")
    s.add_argument("--start", type=float, metavar="F", help="start at F times the nominal values (default 1)")
    s.add_argument("--start-values", type=float, nargs="+", metavar="V",
                   help="start values, one per scene parameter in the scene's order")
    s.add_argument("--residue", choices=RESIDUES, help="indirect: Eq. 16 positions (default) or Eq. 17 full")
    s.add_argument("--dofs", help="indirect: comma list of compared dofs, e.g. x3,y3,x5,y5 (default: all measured)")
    s.add_argument("--noise", type=float, metavar="SIGMA",
                   help="Gaussian noise std on the positions, m and rad (--data measured or FILE)")
    s.add_argument("--seed", type=int, metavar="N", help="seed of the noise (default: a fresh one, printed)")
    s.add_argument("--solver", default="ipopt", help="CasADi nlpsol plugin (default ipopt)")
    s.add_argument("--transform", choices=TRANSFORMS, default="linear",
                   help="decision variables p/scale (linear, default) or log(p/scale)")
    s.add_argument("--hessian", choices=HESSIANS,
                   help="solver's Hessian: exact or gauss-newton (default: exact for direct, gauss-newton for "
                        "adapted-direct and indirect)")
    s.add_argument("--compiled", action="store_true",
                   help="generate and compile C for the solver's functions (needs gcc; longer build, faster solve)")
    s.add_argument("--interval", type=int, metavar="STEPS",
                   help="indirect multiple shooting: steps per shooting interval (default 20)")
    s.add_argument("--out", metavar="FILE.json", help="write the result as JSON")
    s.add_argument("--quiet", action="store_true", help="no solver iteration log")
    s.set_defaults(func=cmd_identify)


def _parser() -> argparse.ArgumentParser:
    from casflex import __version__

    ap = argparse.ArgumentParser(
        prog="casflex", description="Planar flexible multibody dynamics and parameter identification on CasADi.")
    ap.add_argument("--version", action="version", version=f"casflex {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)

    s = sub.add_parser("simulate", help="simulate a scene with HHT-alpha")
    s.add_argument("scene", help="built-in scene name (twobar) or a TOML file")
    s.add_argument("--dt", type=float, help="time step, s (default: the scene's)")
    s.add_argument("--t-end", type=float, help="horizon, s (default: the scene's)")
    s.add_argument("--alpha", type=float, help="HHT alpha in [-1/3, 0] (default: the scene's)")
    s.add_argument("--inertia", choices=("lagrange", "seed"), help="inertia form (default: the scene's)")
    s.add_argument("--compiled", action="store_true", help="run generated C code (needs gcc)")
    s.add_argument("--out", help="write the trajectory to this .npz file")
    s.add_argument("--plots", help="write figures and an animation into this directory")
    s.add_argument("--no-animation", action="store_true", help="with --plots: skip the GIF")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=cmd_simulate)

    s = sub.add_parser("static", help="static equilibrium under gravity and loads")
    s.add_argument("scene")
    s.add_argument("--steps", type=int, default=10, help="load steps (default 10)")
    s.add_argument("--out", help="write q, lam, dof_names to this .npz file")
    s.set_defaults(func=cmd_static)

    s = sub.add_parser("modes", help="natural frequencies and mode shapes")
    s.add_argument("scene")
    s.add_argument("--count", type=int, default=6, help="number of modes (default 6)")
    s.add_argument("--about", choices=("initial", "equilibrium"), default="initial",
                   help="linearise about the initial configuration (default) or the static equilibrium")
    s.add_argument("--out", help="write freq_hz, shapes, dof_names to this .npz file")
    s.set_defaults(func=cmd_modes)

    s = sub.add_parser("demo", help="simulate the built-in two-bar scene, print a summary, write figures")
    s.add_argument("--out", default="casflex-demo", help="output directory (default ./casflex-demo)")
    s.add_argument("--no-animation", action="store_true", help="skip the GIF")
    s.set_defaults(func=cmd_demo)

    _add_identify_parser(sub)

    from casflex.export import EXPORTS

    s = sub.add_parser("export", help="write standalone C (sources, header, Makefile, example main.c)")
    s.add_argument("scene", help="built-in scene name (twobar) or a TOML file")
    s.add_argument("--out", required=True, help="output directory")
    s.add_argument("--what", choices=EXPORTS, default="simulate",
                   help="step | simulate (default: step functions plus an example program) | direct | indirect")
    s.add_argument("--dt", type=float, help="example's time step, s (default: the scene's)")
    s.add_argument("--t-end", type=float, help="example's horizon, s (default: the scene's)")
    s.add_argument("--alpha", type=float, help="HHT alpha compiled into the step (default: the scene's)")
    s.add_argument("--inertia", choices=("lagrange", "seed"), help="inertia form (default: the scene's)")
    s.add_argument("--build", action="store_true", help="also compile it (needs gcc)")
    s.set_defaults(func=cmd_export)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    from casflex.codegen import CodegenError
    from casflex.scene import SceneError
    from casflex.simulate import SimulationError

    known: tuple[type[BaseException], ...] = (SceneError, SimulationError, CodegenError, ValueError, KeyError, OSError)
    try:
        from casflex.statics import StaticsError

        known += (StaticsError,)
    except ImportError:  # pragma: no cover
        pass
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("\ncasflex: interrupted; nothing half-written was left behind", file=sys.stderr)
        return 130
    except SimulationError as exc:
        if "interrupted" in str(exc):
            print(f"\ncasflex: {exc}; nothing half-written was left behind", file=sys.stderr)
            return 130
        print(f"casflex: error: {exc}", file=sys.stderr)
        return 2
    except known as exc:
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        print(f"casflex: error: {msg}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
