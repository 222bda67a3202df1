"""The ``casflex`` command: thin over the Python API (parse, call, print).

Every option is checked before any work starts. Errors print one line, ``casflex: error: ...``
naming the option, field or time step, and exit with status 2. Every file a command writes is
reserved before the work (its directory must exist and be writable, it may not be one of the
command's input files), written to a staging place and moved into place when the command has
finished, all outputs together or none (:class:`~casflex.cli._base.Outputs`): a command that fails
leaves the earlier outputs as they were. Ctrl-C at any moment before that exits with 130, SIGTERM
with 143 and SIGHUP with 129 (:mod:`casflex.interrupt`), and leaves nothing behind. ``casflex
identify`` exits with 1 when the identification does not succeed (its record is still written).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from casflex import interrupt
from casflex.cli._base import CliParser, OptionError, Outputs, missing_extra, progress_messages

__all__ = ["main"]

#: Each command and the module (casflex.cli.<module>) whose ``add_parsers`` builds its options and runs it, in the
#: order ``casflex --help`` lists them. A command line naming one imports that module alone: the others' imports
#: (numpy, CasADi, the identification's choices) are not the command's start-up (``casflex inverse --help``).
COMMANDS = {"simulate": "simulate", "demo": "simulate", "static": "statics", "modes": "statics",
            "identify": "identify", "inverse": "inverse", "calibrate": "inverse", "muscles": "muscles",
            "import": "model_import", "export": "export", "cache": "cache", "study": "study", "scene": "scene"}


def _command_word(argv: list[str]) -> str | None:
    """The command named on the command line (its first word that is no option: casflex's own options take no
    value), or None."""
    return next((a for a in argv if not a.startswith("-")), None)


def _parser(argv: list[str] | None = None) -> CliParser:
    """The parser of the command ``argv`` names, or of every command where it names none (``casflex --help``, a
    misspelt command: their lists name every command)."""
    from casflex import __version__

    ap = CliParser(prog="casflex",
                   description="Planar flexible multibody dynamics and parameter identification on CasADi.")
    ap.add_argument("--version", action="version", version=f"casflex {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    word = _command_word(sys.argv[1:] if argv is None else argv)
    modules = [COMMANDS[word]] if word in COMMANDS else list(dict.fromkeys(COMMANDS.values()))
    for name in modules:
        importlib.import_module(f"casflex.cli.{name}").add_parsers(sub)
    return ap


#: The errors of casflex's modules that are a documented failure (module, class): named where the module was
#: imported, since only then can the command have raised one (importing casflex.statics to name its error would
#: load scipy, 0.6 s, on every refused input).
_MODULE_ERRORS = (("casflex.codegen", "CodegenError"), ("casflex.simulate", "SimulationError"),
                  ("casflex.statics", "StaticsError"),
                  ("casflex.muscles.static_optimization", "StaticOptimizationError"))


def _known_errors() -> tuple[type[BaseException], ...]:
    """The exceptions that are the user's input or a documented failure: one line, exit 2."""
    loaded = (getattr(sys.modules.get(module), name, None) for module, name in _MODULE_ERRORS)
    return (OptionError, *(e for e in loaded if e is not None), ValueError, KeyError, OSError)


#: casflex.codegen.FLAGS_ENV, read here without importing casflex.codegen (it loads CasADi and numpy: not for a
#: command refused before any work); tests/test_cli_startup.py holds them equal.
_FLAGS_ENV = "CASFLEX_CFLAGS"


def _check_compiler_flags() -> None:
    """``$CASFLEX_CFLAGS``, when set and a compiler is there: CodegenError naming it if rejected."""
    import shutil

    if os.environ.get(_FLAGS_ENV) and shutil.which(os.environ.get("CC", "gcc")):
        from casflex import codegen

        codegen.build_flags("-O1")


#: The arguments (argparse destinations) that name files a command reads, and how an error names them:
#: no output may replace one of them.
_INPUTS = {"scene": "the scene", "data": "--data", "loads": "--loads", "static": "--static",
           "alternatives": "--alternatives", "coordinates": "--coordinates", "tasks": "--tasks", "study": "the study",
           "model": "the model", "actuators": "--actuators", "normative": "--normative"}


def _protect_inputs(args: argparse.Namespace, outputs: Outputs) -> None:
    """Tell ``outputs`` the command's input files (a built-in scene name or ``simulated`` is none)."""
    for dest, what in _INPUTS.items():
        value = getattr(args, dest, None)
        outputs.protect(what, [value] if isinstance(value, str) else value or [])


def main(argv: list[str] | None = None) -> int:
    try:
        args = _parser(argv).parse_args(argv)  # one line on a bad option, before any work
    except SystemExit as exc:  # 2 for a bad option, 0 for --help and --version
        return int(exc.code or 0)
    outputs = Outputs()
    with interrupt.guard() as interrupts, progress_messages(not getattr(args, "quiet", False)):
        try:
            if args.command != "cache":  # flags the compiler rejects: one line before any work
                _check_compiler_flags()
            _protect_inputs(args, outputs)
            code = int(args.func(args, outputs) or 0)
            interrupt.check()  # a signal that a library swallowed
            interrupts.armed = False  # the work is done: from here a signal no longer stops the command
            for path in outputs.commit():
                if not getattr(args, "quiet", False):
                    print(f"  wrote {path}")
            return code
        except BaseException as exc:
            interrupts.armed = False  # a second signal does not cut the clean-up short
            outputs.discard()
            if interrupts.count or isinstance(exc, KeyboardInterrupt):  # Terminated too (SIGTERM, SIGHUP)
                signum = interrupts.stopped_by(exc)
                interrupt.tell(f"\ncasflex: {interrupt.describe(signum)}")
                return interrupt.exit_status(signum)
            if (line := missing_extra(exc)) is not None:  # an extra not installed: what to install, no traceback
                print(f"casflex: error: {line}", file=sys.stderr)
                return 2
            if isinstance(exc, _known_errors()):
                msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
                print(f"casflex: error: {msg}", file=sys.stderr)
                return 2
            raise


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
