"""What ``casflex study`` costs (issue 38): throughput in trials per minute on 1 and 2 local workers, and the bands'
cost per trial.

The study: Hamner's subject 02 running (tests/data/lab: 1 s at 60 Hz, 41 markers, two plates) on the planar
whole-body model, as 2 subjects x 4 trials (the same model and the same trial eight times: the machinery's cost, not
eight answers; 2 x 1 with ``--quick``). Timed: the command ``casflex study STUDY --out NEW --workers W --quiet`` as a
user runs it, a new process and a new output (record) folder each time, for 1 and 2 workers, without bands and with
them (``bands = true`` and six segment masses uncertain by 10 %: anthropometry and marker-noise bands), the four
taken in turn, twice, so that a drifting host slows all alike; the first command of all apart (a first process);
the same command on its finished outputs (up to date: nothing run, nothing written); a local cluster's
start and close; and one trial's work in this process without dask, without and with bands. The machine's load is
sampled through the run. What is measured and what the numbers mean: docs/studies/bench_study.md.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the dask workers run (distributed's pre-spawn environ)

import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from _study import Banner, assert_checks, best_of, checks, cli, png, table, write_outputs  # noqa: E402

LAB = Path(__file__).resolve().parents[1] / "tests" / "data" / "lab"
FILES = ("hamner_subject02_planar.osim", "hamner_running_whole.trc", "hamner_running_whole_grf.mot",
         "hamner_tasks_ik.xml")
#: the anthropometry the bands' study declares uncertain, per subject (TARGET=SD: casflex.scene.uncertain)
UNCERTAIN = ["pelvis.mass=10%", "torso.mass=10%", "femur_r.mass=10%", "femur_l.mass=10%", "tibia_r.mass=10%",
             "tibia_l.mass=10%"]
CONFIGS = [(1, False), (2, False), (1, True), (2, True)]  # (workers, bands), taken in turn


def study_text(subjects: int, trials: int, bands: bool, uncertain: list[str]) -> str:
    """The study file: ``subjects`` x ``trials`` of the same 1 s of running, ``bands`` its option, each subject's
    ``uncertain`` properties. (The study without bands declares none: a subject's uncertain properties ask for its
    bands whatever ``bands`` says, casflex.inverse.bands.band_spec.)"""
    lines = ['name = "bench"', "", "[options]", 'plane = "X,Y"', "cutoff = 6.0", 'tasks = "hamner_tasks_ik.xml"',
             f"bands = {str(bands).lower()}"]
    for s in range(subjects):
        lines += ["", "[[subjects]]", f'name = "s{s + 1}"', 'model = "hamner_subject02_planar.osim"']
        if uncertain:
            lines.append("uncertain = [" + ", ".join(f'"{u}"' for u in uncertain) + "]")
        for t in range(trials):
            lines += ["", "[[subjects.trials]]", f'name = "run{t + 1}"', 'markers = "hamner_running_whole.trc"',
                      'grf = "hamner_running_whole_grf.mot"']
    return "\n".join(lines) + "\n"


class LoadSampler:
    """The 1-minute load average, sampled every ``every`` s in a thread while the study runs."""

    def __init__(self, every: float = 5.0) -> None:
        self.samples: list[float] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(every,), daemon=True)
        self._thread.start()

    def _run(self, every: float) -> None:
        while True:
            self.samples.append(os.getloadavg()[0])
            if self._stop.wait(every):
                return

    def stop(self) -> list[float]:
        self._stop.set()
        self._thread.join()
        return self.samples


def _busy_s() -> float | None:
    """CPU seconds the whole machine has been busy (all cores, /proc/stat), or None where there is no /proc."""
    try:
        ticks = [int(x) for x in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    except (OSError, ValueError):
        return None
    idle = ticks[3] + ticks[4]  # idle, iowait
    return (sum(ticks[:8]) - idle) / os.sysconf("SC_CLK_TCK")


def _own_s() -> float:
    """CPU seconds of this process and of its children that have ended (the commands, their dask workers)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _uptime() -> str:
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "load average: " + ", ".join(f"{x:.2f}" for x in os.getloadavg())


def _command(study: Path, out: Path, workers: int, env: dict) -> tuple[float, str]:
    """(wall s, loads.csv) of one ``casflex study`` command into the new folder ``out``."""
    cmd = [sys.executable, "-m", "casflex", "study", str(study), "--out", str(out), "--workers", str(workers),
           "--quiet"]
    t0 = time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}: exit {done.returncode}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}")
    return wall, (out / "loads.csv").read_text()


def _cluster_start(workers: int) -> float:
    """s to start a local cluster as casflex.study.sweep does (``workers`` single-threaded processes) and close it."""
    from distributed import Client, LocalCluster

    t0 = time.perf_counter()
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=40)
    client = Client(cluster)
    client.close()
    cluster.close()
    return time.perf_counter() - t0


def _one_trial(folder: Path, repeat: int, cases: tuple[str, ...]) -> dict:
    """One trial's work in this process, without dask (casflex.study.runner.trial_run): s for the first call, then
    the best of ``repeat`` more (the first where none), for each of ``cases``: "none" (no bands), "markers" (the
    markers' band alone: bands = true, nothing uncertain) and "markers+masses" (the cluster runs' bands)."""
    from casflex.study import runner
    from casflex.study.study_file import load_study

    out = {}
    for case, bands, uncertain in (("none", False, []), ("markers", True, []), ("markers+masses", True, UNCERTAIN)):
        if case not in cases:
            continue
        path = folder / f"one_{case}.toml"
        path.write_text(study_text(1, 1, bands, uncertain))
        st = load_study(str(path))
        s = st.subjects[0]
        cal = runner.calibrate_run(model=s.model, static=None, plane=st.options.trials.plane,
                                   root=st.options.trials.root, calibrate=False, scale=False, mass=None)
        kwargs = {"scene": cal["scene"], "trial": s.trials[0],  # as casflex study sends it
                  "options": st.options.trials, "uncertain": tuple(s.uncertain)}

        def call(kwargs=kwargs) -> dict:
            return runner.trial_run(**kwargs)

        t0 = time.perf_counter()
        rec = call()
        first = time.perf_counter() - t0
        best = best_of(call, repeat, float("inf"))[0] if repeat else first
        band = next(iter(rec["loads"].values()))["band"]
        out[case] = {"first": first, "best": best, "band": band is not None}
    return out


def figure(rows: dict, n: int, one: dict) -> bytes:
    """Trials per minute by workers, without and with bands; one trial's work in one process."""
    from casflex.plotting._figure import _new_figure

    fig = _new_figure((11, 4))
    a, b = fig.subplots(1, 2)
    x = np.arange(2)
    for dx, bands, label in ((-0.2, False, "no bands"), (0.2, True, "bands (markers + 6 masses)")):
        if (1, bands) not in rows:
            continue
        tpm = [60.0 * n / min(rows[(w, bands)]) for w in (1, 2)]
        bars = a.bar(x + dx, tpm, 0.4, label=label)
        a.bar_label(bars, fmt="%.1f", fontsize="small")
    a.set_xticks(x, ["1 worker", "2 workers"])
    a.set(ylabel="trials per minute (whole command, best)", title=f"casflex study, {n} trials")
    a.legend()
    cases = list(one)
    bars = b.bar(np.arange(len(cases)), [one[c]["best"] for c in cases], 0.6)
    b.bar_label(bars, fmt="%.2f s", fontsize="small")
    b.set_xticks(np.arange(len(cases)), [{"none": "no bands", "markers": "markers' band",
                                          "markers+masses": "markers + 6 masses"}[c] for c in cases])
    b.set(ylabel="s per trial (best)", title="one trial's work in one process, no dask")
    return png(fig)


def _same_values(x: str, y: str) -> bool:
    """The value columns of two tables are the same (the bands' column aside)."""
    rx, ry = ([ln.split(",")[:7] for ln in s.splitlines()] for s in (x, y))
    return rx == ry


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("bench_study", quick)
    up0, load, busy0, own0 = _uptime(), LoadSampler(2.0 if quick else 5.0), _busy_s(), _own_s()
    subjects, trials, rounds = (2, 1, 1) if quick else (2, 4, 2)
    configs = CONFIGS[:2] if quick else CONFIGS
    n = subjects * trials
    walls: dict[tuple[int, bool], list[float]] = {c: [] for c in configs}
    tables: dict[tuple[int, bool], str] = {}
    with tempfile.TemporaryDirectory(prefix="casflex-bench-study-") as tmp:
        folder = Path(tmp)
        for f in FILES:
            shutil.copy(LAB / f, folder / f)
        for bands in (False, True):
            (folder / f"study_{bands}.toml").write_text(study_text(subjects, trials, bands, UNCERTAIN if bands else []))
        env = dict(os.environ, CASFLEX_CACHE=str(folder / "cache"))  # new and empty: what a first run compiles
        # the first command of all apart (--quick: the first of the table's, no run of its own)
        first = None if quick else _command(folder / "study_False.toml", folder / "first", 2, env)[0]
        k = 0
        for _ in range(rounds):
            for w, bands in configs:
                k += 1
                wall, tables[(w, bands)] = _command(folder / f"study_{bands}.toml", folder / f"out{k}", w, env)
                walls[(w, bands)].append(wall)
        first = walls[configs[0]][0] if first is None else first
        cache_files = len(list((folder / "cache").rglob("*"))) if (folder / "cache").exists() else 0
        # fixed costs (not with --quick: the suite's budget)
        again = None if quick else best_of(lambda: _command(folder / "study_False.toml", folder / "out1", 1, env), 2,
                                           float("inf"))[0]
        clusters = {} if quick else {w: best_of(lambda w=w: _cluster_start(w), 2, float("inf"))[0] for w in (1, 2)}
        one = _one_trial(folder, 0 if quick else 3, ("none", "markers+masses") if quick else
                         ("none", "markers", "markers+masses"))
    samples, up1, busy1, own1 = load.stop(), _uptime(), _busy_s(), _own_s()
    # the cores the machine's other processes kept busy on average (its busy time less this benchmark's own)
    others = None if busy0 is None or busy1 is None else max(0.0, (busy1 - busy0) - (own1 - own0)) / banner.wall

    best = {c: min(v) for c, v in walls.items()}
    tpm = {c: 60.0 * n / b for c, b in best.items()}
    rows = [[f"{w} worker{'s' * (w > 1)}", "yes" if bands else "no", " / ".join(f"{v:.1f}" for v in walls[(w, bands)]),
             f"{best[(w, bands)]:.1f}", f"{tpm[(w, bands)]:.1f}", f"{best[(w, bands)] / n:.2f}"]
            for w, bands in configs]
    speed = {bands: best[(1, bands)] / best[(2, bands)] for bands in (False, True) if (2, bands) in best}
    page = ["# What `casflex study` costs", "",
            f"{banner.line()} What is measured and what the numbers mean: "
            "[studies/bench_study.md](../studies/bench_study.md).", "",
            f"**The machine's load.** The machine ({os.cpu_count()} cores) is shared with another engineer's work. "
            f"`uptime` before: `{up0}`; after: `{up1}`. The 1-minute load average sampled every {2 if quick else 5} "
            f"s through the run ({len(samples)} samples): min {min(samples):.2f}, median {np.median(samples):.2f}, "
            f"max {max(samples):.2f}, the benchmark's own processes included (a command keeps about one core busy "
            "per worker). "
            + ("" if others is None else f"The machine's other processes kept {others:.2f} cores busy on average "
               "(the cores' busy time, /proc/stat, less this benchmark's and its commands' CPU time)."), "",
            "![trials per minute, and one trial's work without and with bands](../figures/bench_study.png)", "",
            f"The study: {subjects} subjects x {trials} trials, the same 1 s of Hamner's running (61 frames at 60 Hz, "
            "41 markers, two plates) on the planar whole-body model (no static trial: no calibration work); the "
            "bands' study also declares six segment masses uncertain by 10 % per subject.", "",
            "## The command, a new process and a new record folder each time", "",
            *table(["workers", "bands", "wall s (each round)", "best s", "trials per minute", "wall s per trial"],
                   rows, "llrrrr"), "",
            f"- The first command of all (a first process, a new empty CASFLEX_CACHE; {1 if quick else 2} worker(s), "
            f"no bands): {first:.1f} s; the cache holds {cache_files} files after all the commands (the rigid inverse "
            "compiles nothing).",
            *([] if again is None else [
                f"- The same command on its finished outputs (up to date: process, imports, study check, the records' "
                f"and outputs' sizes and times; nothing run, nothing written): {again:.2f} s.",
                f"- A local cluster's start and close, as the sweep makes it: {clusters[1]:.1f} s (1 worker), "
                f"{clusters[2]:.1f} s (2 workers); a study starts one (its calibrations, trials and figures), "
                "none where everything is recorded and drawn."]),
            *(f"- 2 workers against 1, {'with' if b else 'without'} bands: {s:.2f} x the trials per minute"
              for b, s in speed.items()), "",
            "## One trial's work in one process (no dask, no new process)", "",
            *table(["bands", "first call s", "best s", "against no bands"],
                   [[c, f"{v['first']:.2f}", f"{v['best']:.2f}", f"{v['best'] / one['none']['best']:.1f} x"]
                    for c, v in one.items()], "lrrr"), ""]
    if (1, True) in best:
        per_trial = (best[(1, True)] - best[(1, False)]) / n
        page += [f"The bands' cost per trial: {per_trial:.2f} s from the commands on 1 worker (the difference of the "
                 f"best walls over {n} trials), {one['markers+masses']['best'] - one['none']['best']:.2f} s in one "
                 f"process; of which the markers' band {one['markers']['best'] - one['none']['best']:.2f} s.", ""]
    same = [tables[c] == tables[(1, c[1])] for c in configs]
    rows_ok = [("the table is the same, bit for bit, from 1 and 2 workers", f"{sum(same)} of {len(same)} runs",
                all(same))]
    if (1, True) in tables:
        rows_ok.append(("the bands leave the loads as they are (value columns equal, with and without)",
                        str(_same_values(tables[(1, True)], tables[(1, False)])),
                        _same_values(tables[(1, True)], tables[(1, False)])))
    rows_ok += [("each trial's band computed where asked, none where not",
                 ", ".join(f"{c}: {v['band']}" for c, v in one.items()),
                 all(v["band"] == (c != "none") for c, v in one.items())),
                ("2 workers give more trials per minute than 1", " / ".join(f"{s:.2f} x" for s in speed.values()),
                 all(s > 1.0 for s in speed.values()), False)]
    lines, failed = checks(rows_ok)
    write_outputs("bench_study", out_dir, quick, "\n".join(page + lines), figure(walls, n, one))
    assert_checks(failed)
    return {"walls": {f"{w}-{b}": v for (w, b), v in walls.items()}, "first": first, "again": again,
            "clusters": clusters, "one": one, "load": samples, "others_cores": others}


if __name__ == "__main__":
    cli(__doc__, main)
