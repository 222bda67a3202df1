"""The command line's start: a command imports its own module alone, ``casflex inverse --help`` and a refused
input load no numpy, CasADi or scipy, and ``casflex inverse`` none of the identification's or the statics' modules.
Checked in fresh processes by what they imported (``sys.modules``), not by time."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from casflex import cli, codegen
from casflex.cli import COMMANDS, _known_errors, _parser
from casflex.cli.inverse import FILTER_METAVAR

ROOT = Path(__file__).resolve().parents[1]
LAB = ROOT / "tests" / "data" / "lab"
#: What no command's start-up needs: the numerical libraries and the commands' heavy packages.
HEAVY = ("numpy", "casadi", "scipy", "casflex.identification", "casflex.statics", "casflex.inverse", "casflex.model",
         "casflex.cli.identify", "casflex.cli.statics", "casflex.cli.study", "casflex.cli.simulate")


def _imported(argv: list[str], cwd: Path) -> tuple[int, str, list[str]]:
    """(exit status, stderr, the modules loaded) of ``casflex ARGV`` run through the script's entry point in a
    fresh process, without ``$CASFLEX_CFLAGS`` (flags set there are tried on the compiler before any command, which
    loads CasADi: tests/test_codegen.py covers that check)."""
    code = ("import json, sys\nsys.argv = ['casflex', *json.loads(sys.argv[1])]\nfrom casflex._entry import main\n"
            "try:\n    code = main()\nexcept SystemExit as exc:\n    code = exc.code\n"
            "print(json.dumps(sorted(sys.modules)), file=sys.stdout)\nsys.exit(code)\n")
    env = {k: v for k, v in os.environ.items() if k != "CASFLEX_CFLAGS"}
    out = subprocess.run([sys.executable, "-c", code, json.dumps(argv)], capture_output=True, text=True, cwd=cwd,
                         env=env)
    return out.returncode, out.stderr, json.loads(out.stdout.splitlines()[-1])


def test_inverse_help_imports_neither_numpy_nor_casadi_nor_another_command(tmp_path):
    code, err, modules = _imported(["inverse", "--help"], tmp_path)
    assert code == 0, err
    assert not [m for m in modules if m.startswith(HEAVY)]
    assert "casflex.cli.inverse" in modules


def test_a_refused_input_is_said_before_numpy_loads(tmp_path):
    argv = ["inverse", str(LAB / "hamner_subject02_planar.osim"), "--data", str(LAB / "hamner_running_whole.trc"),
            "--loads", str(LAB / "hamner_running_whole_grf.mot"), "--out", str(tmp_path / "x.sto")]
    code, err, modules = _imported(argv, tmp_path)
    assert code == 2 and err.startswith("casflex: error: --loads: say which node each plate acts on") and \
        err.count("\n") == 1
    assert not [m for m in modules if m.startswith(HEAVY)]
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_inverse_loads_neither_the_identification_nor_the_statics(tmp_path):
    argv = ["inverse", str(LAB / "hamner_subject02_planar.osim"), "--data", str(LAB / "hamner_running_whole.trc"),
            "--loads", str(LAB / "hamner_running_whole_grf.mot"), "--plate", "auto", "--t-start", "0.3", "--t-end",
            "0.6", "--out", str(tmp_path / "x.sto"), "--quiet"]
    code, err, modules = _imported(argv, tmp_path)
    assert code == 0, err
    assert (tmp_path / "x.sto").exists()
    unneeded = ("scipy", "casflex.identification", "casflex.statics", "casflex.cli.identify", "casflex.cli.statics",
                "casflex.cli.study", "casflex.study", "matplotlib")
    assert not [m for m in modules if m.startswith(unneeded)]


def test_every_command_is_listed_with_the_module_that_builds_it():
    every = _parser([])._subparsers._group_actions[0].choices  # no command named: every module's parsers
    assert list(every) == list(COMMANDS)  # the order of casflex --help
    for word, module in COMMANDS.items():
        built = _parser([word, "--help"])._subparsers._group_actions[0].choices
        assert word in built and f"casflex.cli.{module}" in sys.modules


@pytest.mark.parametrize("argv", [["--version"], ["bogus"], []])
def test_a_line_naming_no_command_gets_the_whole_list(argv, capsys):
    code = cli.main(argv)
    out, err = capsys.readouterr()
    if argv == ["--version"]:
        assert code == 0 and out.startswith("casflex ")
    elif not argv:
        assert code == 2 and "the following arguments are required: command" in err
    else:
        assert code == 2 and "inverse" in err and "identify" in err and "study" in err


def test_the_constants_read_without_their_modules_are_theirs():
    from casflex.inverse.options import FILTERS

    assert FILTER_METAVAR == "{" + ",".join(FILTERS) + "}"
    assert cli._FLAGS_ENV == codegen.FLAGS_ENV


def test_a_module_s_documented_error_is_known_once_it_is_loaded():
    from casflex.simulate import SimulationError
    from casflex.statics import StaticsError

    known = _known_errors()
    assert StaticsError in known and SimulationError in known and codegen.CodegenError in known
