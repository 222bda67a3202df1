"""``casflex cache``: where the compiled libraries and the built entries (:func:`casflex.codegen.store_built`) are kept,
how many, how large; ``--clear`` empties it."""

from __future__ import annotations

import argparse

from casflex.cli._base import Outputs


def cmd_cache(args: argparse.Namespace, outputs: Outputs) -> int:
    from casflex.codegen import built_entries, cache_dir, cache_entries, clear_cache

    entries, built = cache_entries(), built_entries()
    size = 0
    for f in (*entries, *built):
        try:
            size += f.stat().st_size
        except FileNotFoundError:  # replaced or removed by another process meanwhile
            pass
    print(f"casflex cache: {cache_dir()} (set CASFLEX_CACHE to move it): {len(entries)} compiled libraries, "
          f"{len(built)} built {'entry' if len(built) == 1 else 'entries'} (OpenSim models read, inverse dynamics' "
          f"models and their functions), {size / 2**20:.1f} MiB")
    if args.clear:
        count, freed = clear_cache()
        print(f"  removed {count} files ({freed / 2**20:.1f} MiB); the next runs build what they need again")
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("cache", help="show (or --clear) the cache of compiled libraries and built models")
    s.add_argument("--clear", action="store_true", help="remove every compiled library and built entry from the "
                                                        "cache")
    s.set_defaults(func=cmd_cache)
