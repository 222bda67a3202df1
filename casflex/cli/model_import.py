"""``casflex import``: a lab's OpenSim model (.osim) written out as a casflex scene (TOML) to edit."""

from __future__ import annotations

import argparse
import sys

from casflex.cli._base import OptionError, Outputs, output_path


def cmd_import(args: argparse.Namespace, outputs: Outputs) -> int:
    from casflex.scene.from_osim import scene_from_osim
    from casflex.scene.io import dumps_scene

    if not args.model.lower().endswith(".osim"):
        raise OptionError(f"model: {args.model!r} must be an OpenSim model (.osim)")
    out = outputs.file("--out", args.out, (".toml",), "scene")
    made = scene_from_osim(args.model, name=args.name)
    print("\n".join(made.report))
    for line in made.warnings:
        print(f"casflex: warning: {line}", file=sys.stderr)
    header = "".join(f"# {line}\n" for line in ("Made by casflex import from an OpenSim model; its report:",
                                                 *made.report))
    out.write_text(header + dumps_scene(made.scene))
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("import", help="write an OpenSim model (.osim) as a casflex scene (TOML), with a report of "
                                      "what was kept, projected and ignored")
    s.add_argument("model", help="the OpenSim model file (.osim, format 4.x)")
    s.add_argument("--out", required=True, type=output_path, metavar="FILE", help="the scene file to write (.toml)")
    s.add_argument("--name", help="the scene's name (default: the model's)")
    s.set_defaults(func=cmd_import)
