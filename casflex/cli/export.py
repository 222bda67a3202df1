"""``casflex export``: standalone C of a scene's model."""

from __future__ import annotations

import argparse

from casflex.cli._base import Outputs, alpha_value, load_model, output_path, positive


def cmd_export(args: argparse.Namespace, outputs: Outputs) -> int:
    from casflex.simulate.export import export_c

    staging = outputs.directory("--out", args.out)
    model = load_model(args.scene, args.inertia)
    e = export_c(model, staging, what=args.what, alpha=args.alpha, dt=args.dt, t_end=args.t_end,
                 names=("--t-end", "--dt"))
    print(f"casflex export ({args.what}) of scene {model.scene.name!r}: {', '.join(e.functions)}")
    if args.build:
        built = e.build()
        print(f"  built {built.name} (in {args.out})")
    else:
        print(f"  build with: make -C {args.out}")
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    from casflex.codegen import EXPORTS  # not casflex.simulate.export: the simulator is 0.07 s of imports

    s = sub.add_parser("export", help="write standalone C (sources, header, Makefile, example main.c)")
    s.add_argument("scene", help="built-in scene name (twobar) or a TOML file")
    s.add_argument("--out", type=output_path, required=True, metavar="DIR", help="output directory")
    s.add_argument("--what", choices=EXPORTS, default="simulate",
                   help="step | simulate (default: step functions plus an example program) | direct | indirect")
    s.add_argument("--dt", type=positive("a time step in s"), help="example's time step, s (default: the scene's)")
    s.add_argument("--t-end", type=positive("a duration in s"), help="example's horizon, s (default: the scene's)")
    s.add_argument("--alpha", type=alpha_value, help="HHT alpha compiled into the step (default: the scene's)")
    s.add_argument("--inertia", choices=("lagrange", "seed"), help="inertia form (default: the scene's)")
    s.add_argument("--build", action="store_true", help="also compile it (needs gcc)")
    s.set_defaults(func=cmd_export)
