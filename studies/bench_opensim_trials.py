"""What one trial costs against OpenSim: the whole ``casflex inverse`` command and OpenSim 4.6's IK + ID on the
same files and trial, on public trials from 1 s to 10 s, and the command's start-up (``casflex inverse --help``).

The trials (opensim-org/opensim-models at studies/opensim_gait.py's COMMIT; setups as studies/opensim_gait.py
makes them, its :func:`commands` run):
- Hamner's subject 02 running, 1 s (61 frames at 60 Hz): the excerpt in tests/data/lab (its planar model, tasks
  and plates), coordinates at 10 Hz, as ``opensim_gait.py --quick``;
- the Rajagopal pipeline's walk, 1.65 s (166 frames at 100 Hz): tests/data/muscles (the planar model of 80
  muscles, the pipeline's IK tasks and ExternalLoads), coordinates at 6 Hz;
- Hamner's run, 5 s and its whole 10 s (300 and 600 frames): the repository's trial (``OPENSIM_MODELS``, a clone
  or bare git directory of opensim-models; without it these two are left out), its model made planar by
  studies/_planar_osim.py, as opensim_gait.py runs it.
Each command is a fresh process (interpreter, imports, files, work, output), with the interpreters' bytecode
written (a first run of each, not counted, as an installed package has it); the two tools run in turn, A B A B,
``repeat`` times; the page gives each one's best wall and CPU time (user + system, the OS's account of the
finished process) and the ratios of the best and the median of the pairs' ratios; and, fitted over the trials,
each tool's time as fixed + per second of trial, whose ratio the long trials' ratio tends to. OpenSim runs in its
own interpreter: ``OPENSIM_PYTHON`` (a Python with OpenSim 4.6, the peers extra), else this one if it has OpenSim.

casflex runs with its own new ``CASFLEX_CACHE`` (a folder of the run's): the untimed first run reads the model and
builds its functions and keeps them there (casflex.inverse.built), so the timed runs find them, as a user's runs
after the first do (the warm cache: the columns "casflex"); the cold column times the same command with that
cache emptied before each run (a user's first run of a model, or after ``casflex cache --clear``), in turn with
the others.
"""

from __future__ import annotations

import importlib.util
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from _study import Banner, assert_checks, checks, cli, png, table, write_outputs
from opensim_gait import TRIALS, Trial, _files, commands

MUSCLES = Path(__file__).resolve().parents[1] / "tests" / "data" / "muscles"
GOAL_RATIO, GOAL_START = 0.3, 0.15  # issue 49: the command at most 0.3x OpenSim's IK + ID; --help under 0.15 s
WALK = Trial("Rajagopal pipeline's subject, walking (cut)", "walk", "rajagopal_walk_planar_muscles.osim",
             "rajagopal_walk.trc", "rajagopal_walk_grf.mot", "rajagopal_walk_ik_tasks.xml", (0.1, 1.75), 100.0, 6.0,
             loads="rajagopal_walk_grf.xml")


def _opensim_python() -> str | None:
    """The interpreter that runs OpenSim (module docstring), or None."""
    given = os.environ.get("OPENSIM_PYTHON")
    if given:
        return given
    return sys.executable if importlib.util.find_spec("opensim") is not None else None


def _walk_files(tmp: Path) -> dict:
    """The cut walk's files from tests/data/muscles; its ExternalLoads copied with the data file's full path (both
    tools then read it from any folder)."""
    tree = ET.parse(MUSCLES / WALK.loads)
    tree.getroot().find(".//datafile").text = str(MUSCLES / WALK.grf)
    tree.write(tmp / "walk_loads.xml", encoding="UTF-8", xml_declaration=True)
    return {"model": MUSCLES / WALK.model, "markers": MUSCLES / WALK.markers, "tasks": MUSCLES / WALK.tasks,
            "loads": tmp / "walk_loads.xml"}


def _trials(tmp: Path, quick: bool) -> list[tuple[str, Trial, dict]]:
    """(label, trial, files) of each trial timed (module docstring), shortest first."""
    (tmp / "short").mkdir()
    short_files, _, short = _files(TRIALS[0], tmp / "short", True)
    out = [("Hamner run, 1 s", short, short_files), ("Rajagopal walk, 1.65 s", WALK, _walk_files(tmp))]
    if quick or not os.environ.get("OPENSIM_MODELS"):
        return out
    (tmp / "run").mkdir()
    files, _, run = _files(TRIALS[0], tmp / "run", False)
    five = Trial(**{**run.__dict__, "window": (0.0, 5.0)})
    return out + [("Hamner run, 5 s", five, files), ("Hamner run, 10 s", run, files)]


#: casflex's cache during the run (module docstring): set by :func:`run`, emptied before each cold run
_CACHE: dict[str, Path] = {}
#: the name in :func:`side_by_side`'s commands of the run on an emptied cache
COLD = "casflex, cold cache"


def _env() -> dict:
    """The commands' environment: bytecode written and read, as an installed package's (a first run writes it);
    casflex's cache the run's own (module docstring)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    if "dir" in _CACHE:
        env["CASFLEX_CACHE"] = str(_CACHE["dir"])
    return env


def _timed(cmd: list[str], cwd: Path, cold: bool = False) -> tuple[float, float]:
    """(wall, CPU) s of one run of ``cmd`` in a fresh process; CPU: its user + system time as the OS counts it.
    ``cold``: casflex's cache emptied first (what the run then builds is kept for the next warm one)."""
    if cold and "dir" in _CACHE:
        shutil.rmtree(_CACHE["dir"], ignore_errors=True)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=cwd, env=_env())
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd[:4])} ... failed ({done.returncode}): {done.stderr[-2000:]}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def side_by_side(cmds: dict[str, list[str]], cwd: Path, repeat: int) -> dict:
    """Each command once untimed, then in turn ``repeat`` times: {name: [(wall, cpu), ...]}."""
    for cmd in cmds.values():
        _timed(cmd, cwd)
    runs: dict[str, list[tuple[float, float]]] = {name: [] for name in cmds}
    for _ in range(repeat):
        for name, cmd in cmds.items():
            runs[name].append(_timed(cmd, cwd, cold=name == COLD))
    return runs


def _summary(label: str, trial: Trial, runs: dict) -> dict:
    cf, osim, cold = np.array(runs["casflex"]), np.array(runs["opensim"]), np.array(runs[COLD])
    t0, t1 = trial.window
    return {"trial": label, "seconds": t1 - t0, "frames": int(round((t1 - t0) * trial.rate)) + 1,
            "cf_wall": float(cf[:, 0].min()), "cf_cpu": float(cf[:, 1].min()),
            "cold_wall": float(cold[:, 0].min()), "cold_cpu": float(cold[:, 1].min()),
            "os_wall": float(osim[:, 0].min()), "os_cpu": float(osim[:, 1].min()),
            "ratio_pairs": float(statistics.median(cf[:, 0] / osim[:, 0])), "runs": runs}


def run(quick: bool, repeat: int) -> dict:
    opensim = _opensim_python()
    out: dict = {"trials": [], "opensim": opensim is not None}
    with tempfile.TemporaryDirectory(prefix="casflex-bench-opensim-") as tmp:
        tmp = Path(tmp)
        _CACHE["dir"] = tmp / "cache"  # the run's own (module docstring), gone with the folder
        help_runs = side_by_side({"help": [sys.executable, "-m", "casflex", "inverse", "--help"],
                                  "python": [sys.executable, "-c", "pass"]}, tmp, 3 * repeat)
        out["help"] = {k: [min(v[0] for v in r), min(v[1] for v in r)] for k, r in help_runs.items()}
        if opensim is None:
            return out
        for label, trial, files in _trials(tmp, quick):
            work = tmp / f"out_{len(out['trials'])}"
            work.mkdir()
            cmds = commands(files, trial, work, sys.executable, opensim)
            cmds[COLD] = cmds["casflex"]  # the same command, its cache emptied first (_timed)
            out["trials"].append(_summary(label, trial, side_by_side(cmds, work, repeat)))
            shutil.rmtree(work, ignore_errors=True)
    _CACHE.clear()
    return out


def _same_model(rows: list[dict]) -> list[dict]:
    """The trials of one model and trial (Hamner's run, its windows): the trend in length alone."""
    return [r for r in rows if r["trial"].startswith("Hamner")]


def _trend(rows: list[dict], key: str) -> tuple[float, float]:
    """(fixed s, s per second of trial) of ``key`` over the trials, least squares."""
    T = np.array([r["seconds"] for r in rows])
    slope, fixed = np.polyfit(T, np.array([r[key] for r in rows]), 1)
    return float(fixed), float(slope)


def figure(res: dict) -> bytes:
    from casflex.plotting._figure import _new_figure

    rows = res["trials"]
    same = _same_model(rows)
    fig = _new_figure((10, 4))
    a, b = fig.subplots(1, 2)
    for key, name, color in (("cf_cpu", "casflex inverse (whole command)", "C0"),
                             ("os_cpu", "OpenSim 4.6 IK + ID (one script)", "k")):
        a.plot([r["seconds"] for r in same], [r[key] for r in same], "o", color=color, label=f"{name}, Hamner run")
        a.plot([r["seconds"] for r in rows if r not in same], [r[key] for r in rows if r not in same], "^",
               color=color, mfc="none", label=f"{name}, Rajagopal walk")
        if len(same) > 1:
            fixed, slope = _trend(same, key)
            span = np.linspace(0.0, max(r["seconds"] for r in rows) * 1.05, 20)
            a.plot(span, fixed + slope * span, "-", color=color, lw=0.8, alpha=0.7)
    a.set(xlabel="trial length (s)", ylabel="CPU time, best of the runs (s)", xlim=(0, None), ylim=(0, None))
    a.legend(fontsize=7)
    a.grid(alpha=0.3)
    T = [r["seconds"] for r in rows]
    b.plot(T, [r["cf_wall"] / r["os_wall"] for r in rows], "o", color="C0", label="wall, best / best")
    b.plot(T, [r["ratio_pairs"] for r in rows], "s", color="C1", mfc="none", label="wall, median of the pairs")
    b.plot(T, [r["cf_cpu"] / r["os_cpu"] for r in rows], "x", color="C2", label="CPU, best / best")
    b.axhline(GOAL_RATIO, color="C3", ls="--", lw=1.0, label=f"goal {GOAL_RATIO:g}")
    b.set(xlabel="trial length (s)", ylabel="casflex / OpenSim", xlim=(0, None), ylim=(0, None))
    b.legend(fontsize=7)
    b.grid(alpha=0.3)
    return png(fig)


def _page(banner: Banner, res: dict, repeat: int) -> tuple[str, list[str]]:
    rows = res["trials"]
    lines = ["# One trial: the whole `casflex inverse` command against OpenSim's IK + ID", "",
             res.get("banner") or banner.line(), "",
             "Each command a fresh process, the two tools in turn (A B A B), best of "
             f"{repeat} runs each after an untimed first one; CPU = user + system time of the process. The machine "
             "is shared (the load average above): the ratios, taken side by side in one run, are the figures to "
             "read; the absolute times move with the load. What each trial is: studies/bench_opensim_trials.py.", "",
             "casflex's columns are its runs as a user sees them after the first: the model read and its functions "
             "built once, by the untimed first run, and kept in its cache (`CASFLEX_CACHE`, a new folder of this "
             "run's); the cold column is the same command with that cache emptied before each run (a first run of "
             "a model), timed in turn with the others.", ""]
    if not res["opensim"]:
        lines += ["Skipped the trials: no Python with OpenSim (set OPENSIM_PYTHON, or install the peers extra).", ""]
    else:
        lines += ["## The trials", "", *table(
            ["trial", "length (s)", "frames", "casflex wall (s)", "casflex CPU (s)", "casflex CPU, cold cache (s)",
             "OpenSim wall (s)", "OpenSim CPU (s)", "ratio, wall (best)", "ratio, wall (median of pairs)",
             "ratio, CPU"],
            [[r["trial"], f"{r['seconds']:.2f}", r["frames"], f"{r['cf_wall']:.2f}", f"{r['cf_cpu']:.2f}",
              f"{r['cold_cpu']:.2f}" if "cold_cpu" in r else "-",
              f"{r['os_wall']:.2f}", f"{r['os_cpu']:.2f}", f"{r['cf_wall'] / r['os_wall']:.2f}",
              f"{r['ratio_pairs']:.2f}", f"{r['cf_cpu'] / r['os_cpu']:.2f}"] for r in rows], "lrrrrrrrrrr"), ""]
        same = _same_model(rows)
        if len(same) > 1:
            (cf0, cf1), (os0, os1) = _trend(same, "cf_cpu"), _trend(same, "os_cpu")
            lengths = ", ".join(f"{r['seconds']:g}" for r in same)
            lines += ["## The trend in the trial's length", "",
                      f"Fitted over Hamner's run at {lengths} s (one model and trial; least squares on the CPU "
                      f"times, which the load moves less than the walls): casflex {cf0:.2f} s + {cf1:.3f} s per "
                      f"second of trial, OpenSim {os0:.2f} s + {os1:.3f} s per second. The ratio falls from the "
                      "short trial's, where both tools' fixed costs weigh (interpreter, libraries, the model read "
                      f"and built), towards {cf1 / os1:.2f}, the ratio of the per-second costs (casflex's marker "
                      "fit and loads against OpenSim's IK and ID, frame by frame). The walk is another model "
                      "(80 muscles, which OpenSim builds and casflex reads past) at 100 Hz: its point stands "
                      "beside the line.", "",
                      "![casflex against OpenSim](../figures/bench_opensim_trials.png)", ""]
    hp, py = res["help"]["help"], res["help"]["python"]
    lines += ["## Start-up", "", *table(["command", "wall (s), best", "CPU (s), best"],
              [["`python -m casflex inverse --help`", f"{hp[0]:.3f}", f"{hp[1]:.3f}"],
               ["`python -c pass` (the interpreter alone)", f"{py[0]:.3f}", f"{py[1]:.3f}"]], "lrr"), ""]
    worst = max((r["cf_wall"] / r["os_wall"] for r in rows), default=float("nan"))
    rows_checks = [(f"`casflex inverse --help` under {GOAL_START:g} s of CPU (its wall equals it on an idle machine)",
                    f"{hp[1]:.3f} s (wall {hp[0]:.3f} s)", hp[1] < GOAL_START, False)]  # timings: reported
    if rows:
        rows_checks.append((f"the whole command at most {GOAL_RATIO:g}x OpenSim's IK + ID on every trial (wall, best "
                            "against best)", f"largest {worst:.2f}", worst <= GOAL_RATIO, False))
    check_lines, failed = checks(rows_checks)
    return "\n".join(lines + check_lines), failed


def render(res: dict, out_dir: Path | None, banner: Banner | None = None, quick: bool = False) -> None:
    banner = banner or Banner("bench_opensim_trials", quick)
    page, failed = _page(banner, res, res.get("repeat", 0))
    write_outputs("bench_opensim_trials", out_dir, quick, page, figure(res) if res["trials"] else None)
    assert_checks(failed)


def main(quick: bool = False, out_dir: Path | None = None, raw_path: Path | None = None) -> dict:
    from _study import save_raw

    banner = Banner("bench_opensim_trials", quick)
    repeat = 2 if quick else 5
    res = {**run(quick, repeat), "repeat": repeat}
    res["banner"] = banner.line(OpenSim="4.6")  # the run's machine and load, kept for a re-render
    save_raw(res, raw_path)
    render(res, out_dir, banner, quick)
    return res


if __name__ == "__main__":
    cli(__doc__, main, render)
