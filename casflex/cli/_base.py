"""What every ``casflex`` command shares: one-line option errors, option types, the outputs of a
command (checked and reserved before any work, moved into place together at the end) and
progress messages on stderr (Ctrl-C: :mod:`casflex.interrupt`)."""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import os
import re
import shutil
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

if TYPE_CHECKING:
    from casflex.model import Model

#: A number as a user types it, sign and exponent included ("-1e-3", "-.5", "2E+3").
_NUMBER = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


class CliParser(argparse.ArgumentParser):
    """argparse with one-line errors (``casflex: error: argument --dt: ...``, exit 2) and
    negative numbers read as values: argparse's own test takes ``-1e-3`` for an option."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NUMBER  # argparse's attribute for "looks like a negative number"

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"casflex: error: {message}\n")


def _parse_number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None


def positive(what: str) -> Callable[[str], float]:
    """Option type: a finite number > 0 (``what`` says what it is, e.g. "a time step in s")."""
    def parse(text: str) -> float:
        v = _parse_number(text)
        if not (math.isfinite(v) and v > 0):
            raise argparse.ArgumentTypeError(f"must be {what} > 0, got {text}")
        return v
    parse.__name__ = "positive"
    return parse


def non_negative(what: str) -> Callable[[str], float]:
    """Option type: a finite number >= 0."""
    def parse(text: str) -> float:
        v = _parse_number(text)
        if not (math.isfinite(v) and v >= 0):
            raise argparse.ArgumentTypeError(f"must be {what} >= 0, got {text}")
        return v
    parse.__name__ = "non_negative"
    return parse


def alpha_value(text: str) -> float:
    """Option type: HHT's alpha in [-1/3, 0]."""
    v = _parse_number(text)
    if not (-1.0 / 3.0 - 1e-12 <= v <= 0.0):
        raise argparse.ArgumentTypeError(f"HHT alpha must lie in [-1/3, 0] (0: no numerical damping), got {text}")
    return v


def integer(low: int, what: str) -> Callable[[str], int]:
    """Option type: an integer >= ``low``."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number ({what}), got {text!r}") from None
        if v < low:
            raise argparse.ArgumentTypeError(f"must be {what} >= {low}, got {text}")
        return v
    parse.__name__ = "integer"
    return parse


class OptionError(ValueError):
    """A command-line option is wrong; the message starts with the option's name."""


class Outputs:
    """Everything one command writes.

    Each target is checked when the command registers it, before any work: its suffix, its
    directory (which must exist: nothing is created silently) and that a file can be created
    there, by creating the staging file (or directory) the command then writes to. :meth:`commit`
    moves every staged output to its target at the end; :meth:`discard` removes them (Ctrl-C,
    errors), so an interrupted or failed command leaves nothing behind.
    """

    def __init__(self) -> None:
        self._staged: list[tuple[Path, Path]] = []  # (staging, target)

    @staticmethod
    def _parent(option: str, target: Path) -> Path:
        parent = target.parent
        if not parent.exists():
            raise OptionError(f"{option}: directory {str(parent)!r} does not exist (casflex does not create it)")
        if not parent.is_dir():
            raise OptionError(f"{option}: {str(parent)!r} is not a directory")
        return parent

    def file(self, option: str, path: str, suffixes: tuple[str, ...], what: str) -> Path:
        """Reserve the file ``path`` (suffix one of ``suffixes``; ``what`` names its content);
        returns the staging path to write it to."""
        target = Path(path)
        if target.suffix.lower() not in suffixes:
            raise OptionError(f"{option}: {path!r} must end in {' or '.join(suffixes)} (the {what} is written in "
                              "that format)")
        if target.is_dir():
            raise OptionError(f"{option}: {path!r} is a directory; give a file name ending in {suffixes[0]}")
        if self._taken(target):
            raise OptionError(f"{option}: {path!r} is already the target of another option")
        parent = self._parent(option, target)
        try:
            fd, staging = tempfile.mkstemp(dir=parent, prefix=f".{target.name}.", suffix=".casflex-tmp")
        except OSError as exc:
            raise OptionError(f"{option}: cannot write into {str(parent)!r} ({exc.strerror})") from None
        os.close(fd)
        self._staged.append((Path(staging), target))
        return Path(staging)

    def directory(self, option: str, path: str) -> Path:
        """Reserve the directory ``path`` (new, or existing: its files of the same names are
        replaced); returns the staging directory to write into."""
        target = Path(path)
        if target.exists() and not target.is_dir():
            raise OptionError(f"{option}: {path!r} exists and is not a directory")
        if self._taken(target):
            raise OptionError(f"{option}: {path!r} is already the target of another option")
        where = target if target.is_dir() else self._parent(option, target)
        try:
            staging = tempfile.mkdtemp(dir=where, prefix=f".{target.name}.", suffix=".casflex-tmp")
        except OSError as exc:
            raise OptionError(f"{option}: cannot write into {str(where)!r} ({exc.strerror})") from None
        self._staged.append((Path(staging), target))
        return Path(staging)

    def _taken(self, target: Path) -> bool:
        return any(t.resolve() == target.resolve() for _, t in self._staged)

    def commit(self) -> list[Path]:
        """Move every staged output into place; returns the files written."""
        written: list[Path] = []
        for staging, target in self._staged:
            if staging.is_dir():
                if not target.exists():
                    os.replace(staging, target)
                    written += sorted(target / f.name for f in target.iterdir())
                    continue
                for f in sorted(staging.iterdir()):
                    os.replace(f, target / f.name)
                    written.append(target / f.name)
                staging.rmdir()
            elif staging.stat().st_size > 0:  # an empty staging file was reserved but not written
                os.replace(staging, target)
                written.append(target)
            else:
                staging.unlink()
        self._staged.clear()
        return written

    def discard(self) -> None:
        """Remove every staged output (nothing reaches its target)."""
        for staging, _ in self._staged:
            if staging.is_dir():
                shutil.rmtree(staging, ignore_errors=True)
            else:
                staging.unlink(missing_ok=True)
        self._staged.clear()


@contextlib.contextmanager
def progress_messages(show: bool) -> Iterator[None]:
    """Show the library's progress messages (logger ``casflex``, level INFO: code generation,
    compilation, NLP construction) on stderr for a block."""
    log = logging.getLogger("casflex")
    if not show:
        yield
        return
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("casflex: %(message)s"))
    level = log.level
    log.addHandler(handler)
    log.setLevel(logging.INFO)
    try:
        yield
    finally:
        log.removeHandler(handler)
        log.setLevel(level)


def load_model(scene: str, inertia: str | None = None) -> Model:
    """The assembled model of a built-in scene name or a scene file."""
    from casflex.model import assemble
    from casflex.scene_io import load_scene

    return assemble(load_scene(scene), inertia=inertia)
