"""``casflex scene``: the built-in scenes, listed (``scene list``) or written out to edit (``scene show NAME >
my.toml``: the scene file as shipped, comments and sources included, on stdout)."""

from __future__ import annotations

import argparse
import sys

from casflex.cli._base import OptionError, Outputs


def cmd_scene_show(args: argparse.Namespace, outputs: Outputs) -> int:
    from casflex.scene import SceneError
    from casflex.scene.io import builtin_scene_text

    try:
        text = builtin_scene_text(args.name)
    except SceneError as exc:
        raise OptionError(f"NAME: {exc}") from None
    sys.stdout.write(text if text.endswith("\n") else text + "\n")
    return 0


def cmd_scene_list(args: argparse.Namespace, outputs: Outputs) -> int:
    from casflex.scene.io import builtin_scenes

    print("\n".join(builtin_scenes()))
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("scene", help="the built-in scenes: list them, or write one out to edit (scene show NAME > "
                                     "my.toml)")
    verbs = s.add_subparsers(dest="verb", required=True)
    show = verbs.add_parser("show", help="write a built-in scene's TOML file on stdout, as shipped (comments kept): "
                                         "casflex scene show leg > my_leg.toml, then edit it")
    show.add_argument("name", help="the built-in scene's name (casflex scene list)")
    show.set_defaults(func=cmd_scene_show)
    names = verbs.add_parser("list", help="the built-in scenes' names")
    names.set_defaults(func=cmd_scene_list)
