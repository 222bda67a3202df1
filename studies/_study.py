"""What the sweep studies share: their command line, the sweep of their runs, and writing their page
and figure (``--quick``: ``*_quick.*``) atomically. Not a study itself (no ``main``)."""

from __future__ import annotations

import argparse
import tempfile
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def sweep(name: str, plan: list[dict], key: Callable[[dict], str], fn: Callable[..., dict], *,
          record: Path | None, quick: bool) -> list[tuple[dict, dict]]:
    """Every run of ``plan`` (``fn(**run)``) through casflex.sweep on 2 workers, recorded under
    ``record`` (an interrupted study resumes there; default a temporary directory): (run, result) pairs."""
    from casflex.sweep import Run, run_sweep

    runs = [Run(key(r), fn, r) for r in plan]
    with tempfile.TemporaryDirectory(prefix=f"casflex-{name}-") as tmp:
        done = run_sweep(runs, Path(record) if record is not None else Path(tmp), n_workers=2, progress=not quick)
        if done.interrupted:
            raise KeyboardInterrupt
        return [(r, done.results[run.key]) for r, run in zip(plan, runs, strict=True)]


def write_outputs(name: str, out_dir: Path | None, quick: bool, page: str, figure: Callable[[Path], None]) -> None:
    """docs/tables/<name>.md and docs/figures/<name>.png (or under ``out_dir``), atomically."""
    from casflex.results import atomic_write_text

    out = ROOT / "docs" if out_dir is None else Path(out_dir)
    suffix = "_quick" if quick else ""
    (out / "tables").mkdir(parents=True, exist_ok=True)
    (out / "figures").mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "tables" / f"{name}{suffix}.md", page)
    figure(out / "figures" / f"{name}{suffix}.png")


def cli(doc: str, main: Callable[..., object]) -> None:
    """``--quick``, ``--out-dir``, ``--record``, then ``main`` with them."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out-dir", type=Path)
    ap.add_argument("--record", type=Path, help="sweep record directory: an interrupted study resumes there")
    a = ap.parse_args()
    main(quick=a.quick, out_dir=a.out_dir, record=a.record)
