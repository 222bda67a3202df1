"""The ``casflex`` command: thin over the Python API (parse, call, print).

Errors print one line, ``casflex: error: ...``, and exit with status 2; Ctrl-C exits with 130
and leaves no half-written file.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

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


def _parser() -> argparse.ArgumentParser:
    from casflex import __version__

    ap = argparse.ArgumentParser(prog="casflex", description="Planar flexible multibody dynamics on CasADi.")
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
