"""``casflex static`` and ``casflex modes``: equilibrium and small vibrations."""

from __future__ import annotations

import argparse
import io

import numpy as np

from casflex.cli._base import Outputs, integer, load_model


def _write_npz(path, **arrays) -> None:
    from casflex.results import atomic_write_bytes

    buf = io.BytesIO()
    np.savez(buf, **arrays)
    atomic_write_bytes(path, buf.getvalue())


def cmd_static(args: argparse.Namespace, outputs: Outputs) -> int:
    from casflex.statics import equilibrium

    out = outputs.file("--out", args.out, (".npz",), "equilibrium") if args.out else None
    model = load_model(args.scene)
    res = equilibrium(model, steps=args.steps)
    print(f"static equilibrium of {model.scene.name}: {res.iterations} Newton iterations "
          f"over {len(res.load_factors)} load steps")
    for k, name in enumerate(model.node_names[:len(model.scene.nodes)]):
        print(f"  node {name:<6s} x = {res.q[3 * k]:11.6f} m  y = {res.q[3 * k + 1]:11.6f} m  "
              f"theta = {res.q[3 * k + 2]:10.6f} rad")
    for name, lam in zip(model.constraint_names, res.lam, strict=True):
        print(f"  reaction {name:<18s} {-lam:12.4f}")
    if out is not None:
        _write_npz(out, q=res.q, lam=res.lam, dof_names=np.array(model.dof_names),
                   constraint_names=np.array(model.constraint_names))
    return 0


def cmd_modes(args: argparse.Namespace, outputs: Outputs) -> int:
    from casflex.statics import equilibrium, modes

    out = outputs.file("--out", args.out, (".npz",), "modes") if args.out else None
    model = load_model(args.scene)
    q = equilibrium(model).q if args.about == "equilibrium" else None
    res = modes(model, q=q, count=args.count)
    where = "the static equilibrium" if q is not None else "the initial configuration"
    print(f"natural frequencies of {model.scene.name} linearised about {where}:")
    for k, f in enumerate(res.freq_hz, 1):
        print(f"  mode {k:3d}: {f:14.6f} Hz")
    if out is not None:
        _write_npz(out, freq_hz=res.freq_hz, shapes=res.shapes, dof_names=np.array(model.dof_names))
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("static", help="static equilibrium under gravity and loads")
    s.add_argument("scene", help="built-in scene name (twobar) or a TOML file")
    s.add_argument("--steps", type=integer(1, "a number of load steps"), default=10, help="load steps (default 10)")
    s.add_argument("--out", metavar="FILE.npz", help="write q, lam, dof_names to this .npz file")
    s.set_defaults(func=cmd_static)

    s = sub.add_parser("modes", help="natural frequencies and mode shapes")
    s.add_argument("scene", help="built-in scene name (twobar) or a TOML file")
    s.add_argument("--count", type=integer(1, "a number of modes"), default=6, help="number of modes (default 6)")
    s.add_argument("--about", choices=("initial", "equilibrium"), default="initial",
                   help="linearise about the initial configuration (default) or the static equilibrium")
    s.add_argument("--out", metavar="FILE.npz", help="write freq_hz, shapes, dof_names to this .npz file")
    s.set_defaults(func=cmd_modes)
