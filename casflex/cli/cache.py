"""``casflex cache``: where the compiled libraries are kept, how many, how large; ``--clear`` empties it."""

from __future__ import annotations

import argparse

from casflex.cli._base import Outputs


def cmd_cache(args: argparse.Namespace, outputs: Outputs) -> int:
    from casflex.codegen import cache_dir, cache_entries, clear_cache

    entries = cache_entries()
    size = sum(f.stat().st_size for f in entries)
    print(f"casflex cache: {cache_dir()} (set CASFLEX_CACHE to move it): {len(entries)} compiled libraries, "
          f"{size / 2**20:.1f} MiB")
    if args.clear:
        count, freed = clear_cache()
        print(f"  removed {count} files ({freed / 2**20:.1f} MiB); the next runs build what they need again")
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("cache", help="show (or --clear) the cache of compiled libraries")
    s.add_argument("--clear", action="store_true", help="remove every compiled library from the cache")
    s.set_defaults(func=cmd_cache)
