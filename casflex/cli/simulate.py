"""``casflex simulate`` and ``casflex demo``: an HHT run, its summary, its files."""

from __future__ import annotations

import argparse
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from casflex.cli._base import OptionError, Outputs, alpha_value, load_model, output_path, positive

if TYPE_CHECKING:
    from casflex.simulate import Stepping

#: the seed paper's instants (s), printed by the demo (its Table 3 and Fig. 2)
PAPER_INSTANTS = (0.69, 2.83)
#: The command line's flag of each field of :class:`casflex.simulate.Stepping`: a value refused is said by its flag.
FLAGS = {"dt": "--dt", "alpha": "--alpha", "newton": "--newton", "compiled": "--compiled"}


def stepping_options(args: argparse.Namespace, *, compiled: bool) -> Stepping:
    """The :class:`casflex.simulate.Stepping` of the flags (--dt, --alpha, --newton; None: the scene's); a value it
    refuses is an OptionError naming the flag (``--alpha: must lie in [-1/3, 0], got 0.1``)."""
    from casflex.simulate import Stepping

    try:
        return Stepping(dt=getattr(args, "dt", None), alpha=getattr(args, "alpha", None),
                        newton=getattr(args, "newton", "exact"), compiled=compiled)
    except ValueError as exc:  # "<field>: <reason>", the field as the Python API calls it
        field, _, reason = str(exc).partition(": ")
        raise OptionError(f"{FLAGS.get(field, field)}: {reason}") from None


def _print_node_table(traj, node: str, times: Sequence[float]) -> None:
    print(f"  node {node}:      t (s)       x (m)       y (m)   theta (rad)")
    for t in times:
        i = traj.at(t)
        print(f"           {traj.t[i]:9.3f} {traj.dof('x' + node)[i]:11.5f} {traj.dof('y' + node)[i]:11.5f} "
              f"{traj.dof('theta' + node)[i]:12.5f}")


def summary(model, traj, times: Sequence[float] | None = None) -> None:
    """Print a run: sizes and cost, the tip node (:attr:`Model.tip_node`) at ``times`` (default the
    quarters of the run), peak joint outputs and the energy balance."""
    st = traj.stats
    how = "compiled C" if traj.meta.get("compiled") else "interpreted"
    print(f"scene {model.scene.name}: {model.n_dof} dofs, {model.n_con} constraints, {len(traj.t) - 1} steps of "
          f"dt = {traj.meta['dt']:g} s, alpha = {traj.meta['alpha']:g}, inertia {model.inertia}")
    extra = f", {st['newton_iterations'] / max(st['steps'], 1):.2f} Newton iterations/step" \
        if st.get("newton_iterations") is not None else ""
    comp = f" (+ {st['compile_s']:.2f} s compile{', cached' if st.get('compile_cached') else ''})" \
        if traj.meta.get("compiled") else ""
    print(f"  run: {st['run_s'] * 1e3:.1f} ms {how}{comp}{extra}")
    t_end = float(traj.t[-1])
    times = [t for t in times if t <= t_end] if times is not None else [t_end * k / 4 for k in range(1, 5)]
    _print_node_table(traj, model.tip_node, times or [t_end])
    print("  peak joint outputs (max |value| over the run):")
    for name in traj.output_names:
        if name.endswith((".force", ".moment")) or name.startswith(tuple(s.name + "." for s in model.scene.supports)):
            v = traj.output(name)
            i = int(np.argmax(np.abs(v)))
            unit = "N m" if name.endswith((".moment", ".theta")) else "N"
            print(f"    {name:<22s} {v[i]:12.4f} {unit} at t = {traj.t[i]:.3f} s")
    e = traj.energies
    err = e["balance_error"]
    what = "integration error" if traj.meta["alpha"] == 0 else "integration error and numerical damping"
    wd = e.get("work_dampers")
    damped = wd is not None and wd[-1] > 0.0
    print(f"  energy: E(0) = {e['total'][0]:.6f} J, E(end) = {e['total'][-1]:.6f} J, work of loads "
          f"{e['work_external'][-1]:.6f} J" + (f", dissipated by the dampers {wd[-1]:.6f} J" if damped else "")
          + f"; balance E - E(0) - W{' + W_d' if damped else ''} = {err[-1]:.3e} J at the end, max |.| "
          f"{np.abs(err).max():.3e} J ({what})")


def _run(model, args: argparse.Namespace, *, t_end: float, compiled: bool, progress: bool,
         times: Sequence[float] | None = None, out: Path | None = None, plots: Path | None = None) -> None:
    """Simulate, print the summary, write the trajectory and figures into their staging places."""
    from casflex.simulate import check_memory, simulate, step_count

    stepping = stepping_options(args, compiled=compiled)
    dt, _ = stepping.of(model.scene)
    n_steps = step_count(t_end, dt, names=("--t-end", "--dt"))
    check_memory(model, n_steps, dt, names=("--t-end", "--dt"))
    traj = simulate(model, t_end, stepping=stepping, progress=progress)
    summary(model, traj, times)
    if out is not None:
        traj.save(out)
    if plots is not None:
        from casflex.plotting import save_standard_figures

        save_standard_figures(model, traj, plots, animation=not args.no_animation)


def cmd_simulate(args: argparse.Namespace, outputs: Outputs) -> int:
    out = outputs.file("--out", args.out, (".npz",), "trajectory") if args.out else None
    plots = outputs.directory("--plots", args.plots) if args.plots else None
    model = load_model(args.scene, args.inertia)
    t_end = model.scene.run.t_end if args.t_end is None else args.t_end
    _run(model, args, t_end=t_end, compiled=args.compiled, progress=not args.quiet, out=out, plots=plots)
    return 0


def cmd_demo(args: argparse.Namespace, outputs: Outputs) -> int:
    out = outputs.directory("--out", args.out)
    model = load_model("twobar")
    compiled = shutil.which("gcc") is not None
    print("casflex demo: the seed paper's two-bar flexible chain, 3 s under gravity (HHT-alpha, "
          + ("compiled C" if compiled else "interpreted: no gcc found") + ")")
    _run(model, args, t_end=3.0, compiled=compiled, progress=True, times=PAPER_INSTANTS,
         out=out / "twobar.npz", plots=out)
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("simulate", help="simulate a scene with HHT-alpha")
    s.add_argument("scene", help="built-in scene name (twobar) or a TOML file")
    s.add_argument("--dt", type=positive("a time step in s"), help="time step, s (default: the scene's)")
    s.add_argument("--t-end", type=positive("a duration in s"), help="horizon, s (default: the scene's)")
    s.add_argument("--alpha", type=alpha_value, help="HHT alpha in [-1/3, 0] (default: the scene's)")
    s.add_argument("--inertia", choices=("lagrange", "seed"), help="inertia form (default: the scene's)")
    s.add_argument("--compiled", action="store_true", help="run generated C code (needs gcc)")
    s.add_argument("--newton", choices=("exact", "modified"), default="exact",
                   help="exact: a Jacobian per step (default); modified: the factorised Jacobian kept while it "
                        "converges the steps (faster at small steps of some scenes, docs/tables/bench_simulate.md)")
    s.add_argument("--out", type=output_path, metavar="FILE.npz", help="write the trajectory to this .npz file")
    s.add_argument("--plots", type=output_path, metavar="DIR",
                   help="write figures and an animation into this directory")
    s.add_argument("--no-animation", action="store_true", help="with --plots: skip the GIF")
    s.add_argument("--quiet", action="store_true", help="no progress bar or progress messages")
    s.set_defaults(func=cmd_simulate)

    s = sub.add_parser("demo", help="simulate the built-in two-bar scene, print a summary, write figures")
    s.add_argument("--out", type=output_path, default="casflex-demo", metavar="DIR",
                   help="output directory (default ./casflex-demo)")
    s.add_argument("--no-animation", action="store_true", help="skip the GIF")
    s.set_defaults(func=cmd_demo)
