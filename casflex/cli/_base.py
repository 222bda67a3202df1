"""What every ``casflex`` command shares: one-line option errors, option types, the outputs of a
command (checked and reserved before any work, moved into place together at the end, all or
none) and progress messages on stderr (Ctrl-C, SIGTERM, SIGHUP: :mod:`casflex.interrupt`)."""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import os
import re
import secrets
import shutil
import sys
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

if TYPE_CHECKING:
    from casflex.model import Model

#: A value that starts with a minus sign and is no option: a number as a user types it, sign and exponent
#: included ("-1e-3", "-.5", "2E+3"), or a plane of two lab axes ("-Z,Y", docs/lab.md).
_NUMBER = re.compile(r"^([-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?|[-+]?[XYZxyz]\s*,\s*[-+]?[XYZxyz])$")


class CliParser(argparse.ArgumentParser):
    """argparse with one-line errors (``casflex: error: argument --dt: ...``, exit 2) and
    negative numbers and planes read as values: argparse's own test takes ``-1e-3`` and ``-Z,Y`` for options."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NUMBER  # argparse's attribute for "looks like a negative number"
        self.register("action", None, _StoreOnce)
        self.register("action", "store", _StoreOnce)

    def parse_known_args(self, args=None, namespace=None):  # noqa: ANN001, ANN201 (argparse's signature)
        parsed, rest = super().parse_known_args(args, namespace)
        parsed.__dict__.pop(_StoreOnce.SEEN, None)
        return parsed, rest

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"casflex: error: {message}\n")


class _StoreOnce(argparse._StoreAction):
    """argparse's "store", refusing an option given twice: argparse keeps the last value without a word, so
    ``--dt 1e-3 ... --dt 1e-2`` (an edited command line, a script's defaults before the user's) ran with one of
    two values the user wrote. Options meant to repeat use "append"."""

    SEEN = "_casflex_options_seen"

    def __call__(self, parser, namespace, values, option_string=None) -> None:  # noqa: ANN001
        seen = namespace.__dict__.setdefault(self.SEEN, {})
        if option_string is not None and self.dest in seen:
            raise argparse.ArgumentError(self, f"given twice ({seen[self.dest]} and {option_string} {_shown(values)}):"
                                               " give it once")
        if option_string is not None:
            seen[self.dest] = f"{option_string} {_shown(values)}"
        super().__call__(parser, namespace, values, option_string)


def _shown(values: object) -> str:
    return " ".join(map(str, values)) if isinstance(values, list) else str(values)


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


#: casflex's optional extras (pyproject's optional-dependencies) by the module each brings, and what needs it.
EXTRAS = {"distributed": ("sweep", "runs a study on dask"), "dask": ("sweep", "runs a study on dask"),
          "ezc3d": ("lab", "reads C3D files"), "opensim": ("peers", "runs OpenSim"), "exudyn": ("peers", "runs Exudyn")}


def _extra_line(module: str, needed_by: str) -> str:
    extra, does = EXTRAS[module]
    return (f"{needed_by} needs casflex's {extra!r} extra (the {module} package, which {does}), not installed: "
            f"pip install 'casflex[{extra}]'")


def need_extra(module: str, needed_by: str) -> None:
    """OptionError in one line naming the extra to install where ``module`` (a key of :data:`EXTRAS`) cannot be
    imported; ``needed_by`` says who needs it ("casflex study"). Called before any work."""
    import importlib

    try:
        importlib.import_module(module)
    except ImportError:
        raise OptionError(_extra_line(module, needed_by)) from None


def missing_extra(exc: BaseException) -> str | None:
    """The one line for an ImportError of an extra's module met during the work (a C3D file read deep in a
    command), or None where ``exc`` is no such error: the command says what to install instead of a traceback."""
    if not isinstance(exc, ImportError):
        return None
    top = (exc.name or "").partition(".")[0]
    if top in EXTRAS:
        return _extra_line(top, "this command")
    text = str(exc)
    return text if "pip install 'casflex[" in text else None


def uncertain_option(text: str):
    """--uncertain TARGET=SD, TARGET=P% (relative) or TARGET=LOWER:UPPER (argparse type): a casflex.scene.Uncertain
    (``casflex identify --uncertain``, ``casflex inverse --uncertain``; :func:`casflex.scene.uncertain.parse`)."""
    from casflex.scene.uncertain import parse

    try:
        return parse(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def output_path(text: str) -> str:
    """Option type: where an output goes (--out, --plots). An empty name would write nothing
    without a word (the commands skip an output not given), so it is refused."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"expected a path, got {text!r}")
    return text


def _umask() -> int:
    """The process's umask (read by setting it: called before the work, while no thread writes)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _prefix(target: Path) -> str:
    """A staging path's name start: the target's name and this process's id (:func:`_clear_abandoned`)."""
    return f".{target.name}.{os.getpid()}."


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process: alive
        return True
    return True


def _clear_abandoned(where: Path, name: str) -> None:
    """Remove the staging files and folders of ``name`` that a command killed outright (SIGKILL, a lost machine)
    left in ``where``: those whose process (its id in the name, :func:`_prefix`) no longer runs."""
    for p in where.glob(f".{name}.*.casflex-tmp"):
        pid = p.name[len(name) + 2:].split(".", 1)[0]
        if pid.isdigit() and not _alive(int(pid)):
            shutil.rmtree(p, ignore_errors=True) if p.is_dir() else p.unlink(missing_ok=True)


class Outputs:
    """Everything one command writes: all of it, or none.

    Each target is checked when the command registers it, before any work: its suffix, its
    directory (which must exist: nothing is created silently), that it is none of the command's
    input files (:meth:`protect`) and that a file can be created there, by creating the staging
    file (or directory) the command then writes to. :meth:`commit` moves every staged output to
    its target at the end as one transaction; :meth:`discard` removes them (Ctrl-C, errors), so an
    interrupted or failed command leaves nothing behind and the earlier outputs as they were.
    """

    def __init__(self) -> None:
        self._staged: list[tuple[str, Path, Path]] = []  # (option, staging, target)
        self._places: list[tuple[Path, str]] = []  # (folder, target name): where this process stages (discard)
        self._inputs: list[tuple[str, Path]] = []  # (what, path): the files the command reads

    def protect(self, what: str, paths: Iterable[str | os.PathLike[str]]) -> None:
        """Refuse any output that is one of ``paths``, files the command reads (``what`` names them
        in the error: "the scene", "--data"): writing it would replace the input. A name that is
        no file (a built-in scene, ``simulated``) is skipped."""
        for p in paths:
            if p and os.path.isfile(p):
                self._inputs.append((what, Path(p)))
        for option, _, target in self._staged:  # reserved before
            self._refuse_input(option, target)

    def _refuse_input(self, option: str, target: Path) -> None:
        for what, path in self._inputs:
            with contextlib.suppress(OSError):  # a target that does not exist is no input
                if os.path.samefile(path, target):
                    raise OptionError(f"{option}: {str(target)!r} is an input of the command ({what}); give another "
                                      "name (it would be replaced)")

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
        self._refuse_input(option, target)
        parent = self._parent(option, target)
        _clear_abandoned(parent, target.name)
        self._places.append((parent, target.name))
        try:
            fd, staging = tempfile.mkstemp(dir=parent, prefix=_prefix(target), suffix=".casflex-tmp")
        except OSError as exc:
            raise OptionError(f"{option}: cannot write into {str(parent)!r} ({exc.strerror})") from None
        os.close(fd)
        os.chmod(staging, 0o666 & ~_umask())  # mkstemp's 0600 would reach the target: ordinary permissions
        self._staged.append((option, Path(staging), target))
        return Path(staging)

    def directory(self, option: str, path: str, names: Iterable[str] = ()) -> Path:
        """Reserve the directory ``path`` (new, or existing: its files of the same names are
        replaced); returns the staging directory to write into. ``names``: the files the command
        will write there, where known before the work: none may be a directory there (a file is
        never replaced by one, so :meth:`commit` would refuse it after the work) nor an input."""
        target = Path(path)
        if target.exists() and not target.is_dir():
            raise OptionError(f"{option}: {path!r} exists and is not a directory")
        for name in names:
            if (target / name).is_dir() and not (target / name).is_symlink():
                raise OptionError(f"{option}: {str(target / name)!r} is a directory; the figure {name!r} would go "
                                  "there: give another directory")
            self._refuse_input(option, target / name)
        if self._taken(target):
            raise OptionError(f"{option}: {path!r} is already the target of another option")
        where = target if target.is_dir() else self._parent(option, target)
        for place in {where, target.parent}:  # a killed first run staged beside the target, a later one in it
            _clear_abandoned(place, target.name)
        self._places.append((where, target.name))
        try:
            staging = tempfile.mkdtemp(dir=where, prefix=_prefix(target), suffix=".casflex-tmp")
        except OSError as exc:
            raise OptionError(f"{option}: cannot write into {str(where)!r} ({exc.strerror})") from None
        os.chmod(staging, 0o777 & ~_umask())  # mkdtemp's 0700 would reach a new target: ordinary permissions
        self._staged.append((option, Path(staging), target))
        return Path(staging)

    def folder(self, option: str, path: str) -> Path:
        """Check the folder ``path`` that the command writes into as it goes, outside the all-or-none outputs
        (``casflex study --record``: each run's record kept as it finishes): refused, as an output is, where its
        parent does not exist (nothing is created silently), where it is a file, one of the command's inputs or
        another option's target; it is created where it does not exist by whoever first writes into it."""
        target = Path(path)
        self._refuse_input(option, target)
        if target.exists() and not target.is_dir():
            raise OptionError(f"{option}: {path!r} exists and is not a directory")
        for other, _, t in self._staged:
            if t.resolve() == target.resolve():
                raise OptionError(f"{option}: {path!r} is also the {other} folder; give another folder")
        if not target.exists():
            self._parent(option, target)
        return target

    def _taken(self, target: Path) -> bool:
        return any(t.resolve() == target.resolve() for _, _, t in self._staged)

    def _moves(self) -> list[tuple[str, Path, Path]]:
        """(option, staged, target) of every move :meth:`commit` makes, each checked first: an
        OptionError naming the option and the path if one cannot be made, before anything moves."""
        moves = []
        for option, staging, target in self._staged:
            if not staging.exists():
                raise OptionError(f"{option}: its staging place {str(staging)!r} was removed during the run; nothing "
                                  "was written")
            if staging.is_dir() and not os.path.lexists(target):  # a new directory: moved as a whole
                moves.append((option, staging, target))
            elif staging.is_dir():
                if not target.is_dir():
                    raise OptionError(f"{option}: {str(target)!r} is no longer a directory; nothing was written")
                moves += [(option, f, target / f.name) for f in sorted(staging.iterdir())]
            elif staging.stat().st_size > 0:  # an empty staging file was reserved but not written
                moves.append((option, staging, target))
        seen: set[Path] = set()
        for option, _, target in moves:
            if target.is_dir() and not target.is_symlink():  # only files are replaced, never a directory
                raise OptionError(f"{option}: {str(target)!r} is a directory; nothing was written")
            if not os.access(target.parent, os.W_OK | os.X_OK):
                raise OptionError(f"{option}: cannot write into {str(target.parent)!r} (permission denied); "
                                  "nothing was written")
            if target.resolve() in seen:
                raise OptionError(f"{option}: {str(target)!r} would be written twice; nothing was written")
            seen.add(target.resolve())
            self._refuse_input(option, target)
        return moves

    def commit(self) -> list[Path]:
        """Move every staged output into place, all or nothing; returns the files written.

        Every move is checked first (:meth:`_moves`). The targets that exist are then renamed
        aside (hidden backups next to them) and every output moved in. If a rename fails, those
        made are undone and the backups restored, so the earlier outputs are as they were, and the
        failure is an OptionError naming the option and the path (the staged outputs stay for
        :meth:`discard`). The backups are removed once every output is in place."""
        moves = self._moves()
        backups: list[tuple[Path, Path]] = []  # (backup, target)
        done: list[tuple[Path, Path]] = []  # (staging, target)
        failing = ("", Path())  # the option and the path of the rename under way, for the error
        try:
            for option, _, path in moves:
                failing = option, path
                if os.path.lexists(path):
                    aside = path.with_name(f".{path.name}.{secrets.token_hex(4)}.casflex-bak")
                    os.replace(path, aside)
                    backups.append((aside, path))
            for option, staging, path in moves:
                failing = option, path
                os.replace(staging, path)
                done.append((staging, path))
        except BaseException as exc:
            kept = self._undo(done, backups)
            if not isinstance(exc, OSError):
                raise
            why = exc.strerror or type(exc).__name__  # the reason, without errno's number and Python's repr
            msg = f"{failing[0]}: cannot write {str(failing[1])!r} ({why}); nothing was written{kept}"
            raise OptionError(msg) from None
        for aside, _ in backups:
            with contextlib.suppress(OSError):  # every output is in place: a backup left is no failure
                aside.unlink()
        written = [f for _, target in done for f in (sorted(target.iterdir()) if target.is_dir() else [target])]
        self.discard()  # what is left: emptied staging directories, staging files reserved but not written
        return written

    @staticmethod
    def _undo(done: list[tuple[Path, Path]], backups: list[tuple[Path, Path]]) -> str:
        """Take back the moves made and restore the backups; returns what could not be restored."""
        for staging, target in reversed(done):
            with contextlib.suppress(OSError):  # then the backup, if any, is renamed over it
                os.replace(target, staging)
        kept = []
        for aside, target in reversed(backups):
            try:
                os.replace(aside, target)
            except OSError:
                kept.append(f"; the earlier {str(target)!r} is kept as {str(aside)!r}")
        return "".join(kept)

    def discard(self) -> None:
        """Remove every staged output (nothing reaches its target), also one a signal left unrecorded (it came
        between the staging's creation and its entry here: found by this process's id in its name)."""
        leaked = [p for where, name in self._places for p in where.glob(f"{_prefix(Path(name))}*.casflex-tmp")]
        for staging in [s for _, s, _ in self._staged] + leaked:
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
    from casflex.scene.io import load_scene

    return assemble(load_scene(scene), inertia=inertia)
