"""What a 200-trial ``casflex study`` costs (issue 49, goal 3): trials per minute on 1 and 2 workers, on the
command's own local cluster and on an external ``dask scheduler`` with ``dask worker`` processes; the per-trial
overhead against one trial's work in one process; the same command again on its finished outputs.

The study is synthetic: Hamner's subject 02 running (tests/data/lab: 1 s at 60 Hz, 41 markers, two plates) on the
planar whole-body model, replicated as 10 subjects x 20 trials, each subject's model its masses scaled to its own
mass (55 to 82 kg: casflex.inverse.calibrate.with_mass, inertias with them), with ``--quick`` 4 x 5. The same
motion for every trial: the machinery's cost, not 200 answers.

Timed, each a new process and a new output (record) folder, as a user runs it: ``casflex study STUDY --out NEW
--workers W --quiet`` for W = 1 and 2, taken in turn (twice, ``--quick`` once); then the same command on its
finished outputs (best of 3); then on an external scheduler (``dask scheduler`` and ``dask worker --nthreads 1``
processes started here on a free port of localhost, with the settings docs/lab.md gives for a cluster that runs
studies, casflex.study.sweep.QUIET_CLUSTER's, in their environment): ``--scheduler ADDRESS`` with one worker, then
with two. The
scheduler's task stream (each task's start and stop and its worker) is read for the external runs, the records'
modification times (each trial's record written as it finishes) for the local ones: the start-up before the first
record, the steady stream of records, the table and figures after the last. CPU time: the commands' and their
workers' (the local clusters' workers are the command's children; the external workers' read from /proc). The
machine's load is sampled through the run: with other work on the machine the second worker's gain is bounded by
the idle core, which the page states beside the ratio.

Where the CPU goes: each process's CPU (its main thread and its others apart) sampled from /proc through each
command, against the trials' own work (one trial's CPU in one process, times the trials); the activities within
them (figures, records, imports, dask) as measured once with each function's CPU: docs/studies/bench_study200.md.
From the one-off costs, the most a second worker can give (the arithmetic on the page).

A second configuration, beside the goal's 1 s trials without bands and not in their place: the same trials with
their bands (``bands = true``, six segment masses uncertain by 10 %), 10 subjects x 20 trials (``--quick`` 2 x 2),
on 1 and 2 local workers, one command each.

The per-trial overhead (the goal: below 10 % of a trial's work) is the steady stream's: the wall s a worker spends
per record less one trial's work, over the work. A trial's work is what its records say its run cost in its worker
(the run's thread's CPU, casflex.study.sweep.RUN_TIME: the mean over the command's trials), measured where and
while the study ran; beside it, against one trial in one process apart (the median of repeated calls, before and
after the commands: this machine's speed drifts by a quarter over minutes, and a reference taken apart drifts with
it). The one-off costs
of a study (the start-up to the first record, the outputs after the last) are columns of their own, and the whole
command's wall per trial less the work is reported beside them.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the dask workers run (distributed's pre-spawn environ)

import json  # noqa: E402
import shutil  # noqa: E402
import signal  # noqa: E402
import socket  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from _study import Banner, assert_checks, checks, cli, png, table, write_outputs  # noqa: E402
from bench_study import FILES, LAB, UNCERTAIN, LoadSampler, _busy_s, _own_s, _uptime  # noqa: E402

from casflex.study.sweep import RUN_TIME  # noqa: E402


def study_text(subjects: int, trials: int, bands: bool = False) -> str:
    """The synthetic study: ``subjects`` x ``trials`` of the same 1 s of running, each subject's masses scaled to
    its own mass (55 kg, then 3 kg more per subject, wrapping at 82); ``bands``: with the bands (marker noise and
    six segment masses uncertain by 10 %, as studies/bench_study.py's)."""
    lines = ['name = "bench200"', "", "[options]", 'plane = "X,Y"', "cutoff = 6.0", 'tasks = "hamner_tasks_ik.xml"']
    lines += ["bands = true"] if bands else []
    for s in range(subjects):
        lines += ["", "[[subjects]]", f'name = "s{s + 1:02d}"', 'model = "hamner_subject02_planar.osim"',
                  f"mass = {55 + 3 * (s % 10)}"]
        lines += ["uncertain = [" + ", ".join(f'"{u}"' for u in UNCERTAIN) + "]"] if bands else []
        for t in range(trials):
            lines += ["", "[[subjects.trials]]", f'name = "run{t + 1:02d}"', 'markers = "hamner_running_whole.trc"',
                      'grf = "hamner_running_whole_grf.mot"']
    return "\n".join(lines) + "\n"


def _bands_runs(folder: Path, env: dict, subjects: int, trials: int, repeat: int) -> dict:
    """The second configuration: the study with its bands, on 1 and 2 local workers (one command each), and one such
    trial's work in one process."""
    study = folder / "bands.toml"
    study.write_text(study_text(subjects, trials, bands=True))
    (folder / "one_bands.toml").write_text(study_text(1, 1, bands=True))
    one = _trial_work(folder, repeat, "one_bands.toml")
    runs = {w: _command(study, folder / f"bands{w}", env, "--workers", str(w)) for w in (1, 2)}
    return {"work": one["median"], "work_cpu": one["cpu"], "runs": runs, "subjects": subjects, "trials": trials}


def _bands_section(bands: dict) -> list[str]:
    """The page's section on the second configuration (the bands)."""
    n, r = bands["subjects"] * bands["trials"], bands["runs"]
    rows = []
    for w in (1, 2):
        rec = r[w]["records"]
        rows.append([f"local, {w} worker{'s' if w > 1 else ''}", f"{r[w]['wall']:.1f}", f"{r[w]['cpu']:.1f}",
                     f"{60.0 * n / r[w]['wall']:.1f}", f"{rec[0]:.1f}" if rec else "-",
                     f"{_steady(rec):.3f}" if rec else "-",
                     f"{_own_work(r[w]):.3f}", f"{_steady_overhead(rec, w, _own_work(r[w])):+.0f} %" if rec else "-",
                     f"{r[w]['wall'] - rec[-1]:.1f}" if rec else "-"])
    return ["## The second configuration: the same trials with their bands", "",
            f"The study as above with its bands (``bands = true``, six segment masses uncertain by 10 % per subject: "
            f"anthropometry and marker-noise bands on every load), {bands['subjects']} x {bands['trials']} = {n} "
            f"trials: a lab's study that reports its loads' uncertainty. One trial's work in one process: "
            f"{bands['work']:.3f} s ({bands['work_cpu']:.3f} s CPU), "
            f"{bands['work'] / max(bands.get('plain', bands['work']), 1e-9):.1f} x the trial without bands. One "
            "command each, not repeated: beside the 1 s study without bands, which answers the goal, not in its "
            "place.", "",
            *table(["cluster", "wall s", "CPU s (all processes)", "trials per minute", "start-up: first record s",
                    "s per record (steady)", "a trial's own CPU s (its records)",
                    "steady stream: overhead per trial (of its own CPU)", "after the last record s"], rows,
                  "lrrrrrrrr"), "",
            f"- 2 workers against 1: **{r[1]['wall'] / r[2]['wall']:.2f} x** (local cluster).", ""]


def _env(folder: Path) -> dict:
    """The commands' environment: a new CASFLEX_CACHE, dask's scratch space here; Python writes its bytecode (a
    user's install has it: PYTHONDONTWRITEBYTECODE, set in some shells, would make every command compile casflex)."""
    env = dict(os.environ, CASFLEX_CACHE=str(folder / "cache"), DASK_TEMPORARY_DIRECTORY=str(folder / "dask"))
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def _children_cpu() -> float:
    t = os.times()
    return t.children_user + t.children_system


_TICK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def _stat_cpu(path: str) -> float | None:
    """CPU s (user + system) of /proc's ``path`` (``PID`` or ``PID/task/TID``), None where it is gone."""
    try:
        f = Path(f"/proc/{path}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(f[11]) + int(f[12])) / _TICK
    except (OSError, IndexError, ValueError):
        return None


class TreeCPU:
    """The CPU s of a process tree, sampled every 0.05 s from /proc in a thread: {pid: {"role", "main" (its main
    thread: a worker's event loop and imports, the command's casflex code), "threads" (its others: a worker's task,
    the command's dask scheduler, nannies and client)}}, each process's last sample (at most 0.05 s short)."""

    def __init__(self, roots: dict[int, str]) -> None:
        import psutil

        self.roots, self.procs, self._psutil = roots, {}, psutil
        self._sample()
        self.base = {pid: dict(d["tids"]) for pid, d in self.procs.items() if roots.get(pid) != "command"}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _sample(self) -> None:
        for pid, role in list(self.roots.items()):
            try:
                kids = self._psutil.Process(pid).children(recursive=True)
            except self._psutil.Error:
                kids = []
            for q in [(pid, role), *((k.pid, None) for k in kids)]:
                tids = {}
                try:
                    for tid in os.listdir(f"/proc/{q[0]}/task"):
                        c = _stat_cpu(f"{q[0]}/task/{tid}")
                        if c is not None:
                            tids[tid] = c
                except OSError:
                    continue
                d = self.procs.setdefault(q[0], {"role": q[1] or _role(q[0]), "tids": {}})
                d["tids"].update(tids)  # a thread that ended keeps its last sample

    def _run(self) -> None:
        while not self._stop.wait(0.05):
            self._sample()

    def stop(self) -> dict[int, dict]:
        self._stop.set()
        self._thread.join()
        self._sample()
        out = {}
        for pid, d in self.procs.items():  # less what the processes there before (an external cluster's) had spent
            tids = {t: c - self.base.get(pid, {}).get(t, 0.0) for t, c in d["tids"].items()}
            out[pid] = {"role": d["role"], "main": tids.get(str(pid), 0.0),
                        "threads": sum(c for t, c in tids.items() if t != str(pid))}
        return out


def _role(pid: int) -> str:
    """A process's role from its command line: a local cluster's worker (multiprocessing's spawn, or forked from
    its fork server: the server, which imports the workers' modules once, counted with them), its resource tracker,
    an external dask worker or scheduler."""
    try:
        cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return "?"
    for key, role in (("resource_tracker", "tracker"), ("multiprocessing.forkserver", "worker"),
                      ("spawn_main", "worker"), ("dask worker", "worker"), ("dask-worker", "worker"),
                      ("scheduler", "scheduler")):
        if key in cmd:
            return role
    return "worker" if " worker " in cmd else "other"


#: CPU s of this benchmark's commands' processes that it does not reap (the fork server and its workers), so that
#: the machine's other load (/proc/stat's busy time less this benchmark's) leaves them out
_UNREAPED = [0.0]


def _command(study: Path, out: Path, env: dict, *options: str, others: dict[int, str] | None = None) -> dict:
    """One ``casflex study`` command into ``out``: wall s, CPU s (the command's and its local workers'), its
    stdout, the records' modification times (s after the start) of its trials, and the CPU of each process
    (:class:`TreeCPU`: the command's tree and ``others``, an external scheduler's and workers' pids)."""
    cmd = [sys.executable, "-m", "casflex", "study", str(study), "--out", str(out), "--quiet", *options]
    c0, t0, w0 = _children_cpu(), time.time(), time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    tree = TreeCPU({proc.pid: "command", **(others or {})})
    stdout, stderr = proc.communicate()
    wall, cpu = time.perf_counter() - w0, _children_cpu() - c0
    procs = tree.stop()
    # the local workers are forked by a fork server that the command does not wait for as it exits (init reaps it):
    # their CPU never reaches this process's children's; /proc's samples of the tree have it
    unreaped = 0.0 if others else max(0.0, sum(d["main"] + d["threads"] for d in procs.values()) - cpu)
    _UNREAPED[0] += unreaped
    cpu += unreaped
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}: exit {proc.returncode}\n{stdout[-2000:]}\n{stderr[-2000:]}")
    files = sorted((out / "record").glob("trial-*.json")) if (out / "record").is_dir() else []
    stamps = sorted(p.stat().st_mtime - t0 for p in files)
    costs = [json.loads(p.read_text()).get(RUN_TIME) for p in files]
    return {"wall": wall, "cpu": cpu, "stdout": stdout, "records": stamps, "procs": procs,
            "run_cpu": [c["cpu_s"] for c in costs if c], "run_wall": [c["wall_s"] for c in costs if c]}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class External:
    """A ``dask scheduler`` and its ``dask worker`` processes (one single-threaded worker each) on localhost."""

    def __init__(self, folder: Path, env: dict) -> None:
        from casflex.study.sweep import QUIET_CLUSTER

        # started as docs/lab.md tells a cluster that runs studies to start: the local cluster's settings
        quiet = {"DASK_" + k.upper().replace(".", "__").replace("-", "_"): str(v) for k, v in QUIET_CLUSTER.items()}
        self.folder, self.env, self.procs = folder, dict(env, **quiet), []
        exe = Path(sys.executable).with_name("dask")
        self.dask = str(exe) if exe.exists() else shutil.which("dask") or "dask"
        self.address = f"tcp://127.0.0.1:{_free_port()}"
        self._spawn("scheduler", "--host", "127.0.0.1", "--port", self.address.rpartition(":")[2], "--no-dashboard")
        from distributed import Client

        self.client = Client(self.address, timeout="120s")
        self.client.get_task_stream()  # the scheduler's task stream plugin from here on

    def _spawn(self, *args: str) -> None:
        log = open(self.folder / f"dask{len(self.procs)}.log", "w")  # noqa: SIM115 (open while the process runs)
        self.procs.append(subprocess.Popen([self.dask, *args], stdout=log, stderr=subprocess.STDOUT, env=self.env,
                                           cwd=self.folder, start_new_session=True))

    def add_worker(self) -> None:
        n = len(self.procs)
        self._spawn("worker", self.address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard", "--host",
                    "127.0.0.1", "--name", f"w{n}", "--local-directory", str(self.folder / f"w{n}"))
        self.client.wait_for_workers(n, timeout=300)

    def workers_cpu(self) -> float:
        """CPU s of the worker processes (and their nannies' children) so far."""
        import psutil

        total = 0.0
        for p in self.procs[1:]:
            try:
                proc = psutil.Process(p.pid)
                for q in [proc, *proc.children(recursive=True)]:
                    t = q.cpu_times()
                    total += t.user + t.system
            except psutil.Error:
                pass
        return total

    def tasks(self, since: float) -> list[dict]:
        """The tasks since ``since`` (time.time()): kind ("trial", "calibrate", "figure"), worker, start and stop
        (s, wall clock)."""
        out = []
        for ts in self.client.get_task_stream(start=since):
            key = str(ts["key"])
            kind = next((k for k in ("trial", "calibrate") if key.startswith(f"casflex-{k}-")),
                        "figure" if key.startswith("draw_figure") else None)
            compute = [s for s in ts["startstops"] if s["action"] == "compute"]
            if kind and compute:
                out.append({"kind": kind, "worker": ts["worker"], "start": compute[0]["start"],
                            "stop": compute[-1]["stop"]})
        return out

    def close(self) -> None:
        self.client.close()
        for p in reversed(self.procs):
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in self.procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)


def _timeline(tasks: list[dict]) -> dict:
    """From a run's trial tasks: their number, the sum of their compute s, the span from the first start to the
    last stop, the workers, and the share of that span in which two or more tasks computed at once."""
    if not tasks:
        return {"n": 0, "busy": 0.0, "span": 0.0, "workers": 0, "overlap": 0.0}
    t0, t1 = min(t["start"] for t in tasks), max(t["stop"] for t in tasks)
    grid = np.linspace(t0, t1, 2000)
    running = sum(((grid >= t["start"]) & (grid < t["stop"])).astype(int) for t in tasks)
    return {"n": len(tasks), "busy": float(sum(t["stop"] - t["start"] for t in tasks)), "span": t1 - t0,
            "workers": len({t["worker"] for t in tasks}), "overlap": float(np.mean(running >= 2)),
            "first": t0, "last": t1}


def _external_runs(folder: Path, study: Path, env: dict) -> tuple[dict, dict]:
    """The command on an external scheduler with one worker, then two: ({workers: the command's numbers and its
    tasks' timeline}, {workers: the tasks})."""
    ext = External(folder, env)
    runs, tasks = {}, {}
    try:
        for w in (1, 2):
            ext.add_worker()
            cpu0, since = ext.workers_cpu(), time.time()
            r = _command(study, folder / f"ext{w}", env, "--scheduler", ext.address,
                         others={p.pid: "scheduler" if k == 0 else "nanny" for k, p in enumerate(ext.procs)})
            r["cpu"] += ext.workers_cpu() - cpu0
            tasks[w] = [dict(t, start=t["start"] - since, stop=t["stop"] - since) for t in ext.tasks(since)]
            r["timeline"] = _timeline([t for t in tasks[w] if t["kind"] == "trial"])
            runs[w] = r
    finally:
        ext.close()
    return runs, tasks


def figure(tpm: dict[str, float], tasks: list[dict], n: int, wall: float) -> bytes:
    """Trials per minute by workers and cluster; the external two-worker run's tasks over its ``wall`` s."""
    from casflex.plotting._figure import _new_figure

    fig = _new_figure((12, 4))
    a, b = fig.subplots(1, 2, width_ratios=[1, 1.6])
    bars = a.bar(np.arange(len(tpm)), list(tpm.values()), 0.6, color=["C0", "C0", "C1", "C1"][:len(tpm)])
    a.bar_label(bars, fmt="%.0f", fontsize="small")
    a.set_xticks(np.arange(len(tpm)), list(tpm), fontsize="small")
    a.set(ylabel="trials per minute (whole command)", title=f"casflex study, {n} trials")
    workers = sorted({t["worker"] for t in tasks})
    colours = {"calibrate": "0.6", "trial": "C0", "figure": "C3"}
    for t in tasks:
        b.barh(workers.index(t["worker"]), t["stop"] - t["start"], left=t["start"], height=0.6,
               color=colours[t.get("kind", "trial")], edgecolor="white", lw=0.3)
    for kind, c in colours.items():
        b.barh(0, 0, color=c, label={"calibrate": "a calibration", "trial": "a trial", "figure": "a figure"}[kind])
    b.set_yticks(range(len(workers)), [f"worker {k + 1}" for k in range(len(workers))])
    b.set_xlim(0, wall)
    b.legend(loc="upper left", fontsize="small", ncols=3)
    b.set(xlabel="s after the command's start (its end: the axis's)",
          title="external scheduler, 2 workers: each task")
    return png(fig)


def _kinds(tasks: list[dict]) -> list[str]:
    """The page's line on the external two-worker run's tasks by kind: how many, their compute s, each's mean."""
    parts = []
    for kind in ("calibrate", "trial", "figure"):
        d = [t["stop"] - t["start"] for t in tasks if t.get("kind", "trial") == kind]
        if d:
            parts.append(f"{len(d)} {kind} tasks {sum(d):.1f} s ({np.mean(d):.2f} s each)")
    return [f"- The external two-worker run's tasks by kind (compute s, the figure's part includes each worker's "
            f"first import of matplotlib): {'; '.join(parts)}."] if parts else []


def _overhead(wall: float, n: int, work: float) -> float:
    """The whole command's overhead per trial in % of one trial's work: its wall per trial less the work (the
    one-off costs, start-up and the outputs after the last record, spread over the trials)."""
    return 100.0 * (wall / n - work) / work


def _steady(records: list[float]) -> float:
    """s per record in the steady stream: from the first record to the last, over the records between."""
    return (records[-1] - records[0]) / (len(records) - 1) if len(records) > 1 else float("nan")


def _own_work(run: dict) -> float:
    """A trial's own work in a command: the mean of its trials' runs' CPU s in their workers, from their records
    (casflex.study.sweep.RUN_TIME; nan where the records do not say)."""
    return float(np.mean(run["run_cpu"])) if run.get("run_cpu") else float("nan")


def _steady_overhead(records: list[float], workers: int, work: float) -> float:
    """The per-trial overhead in the steady stream, in % of one trial's work: the wall s a worker spends per
    record (s per record x workers) less the trial's own work (what each trial costs beyond its work, once the
    study runs: dask's round trip, the record written, the worker's share of the machine)."""
    return 100.0 * (_steady(records) * workers - work) / work


#: the account's columns: (role, the process's main thread or its other threads) -> the column's head
_PARTS = {("command", "main"): "command: casflex (its main thread: checks, records, figures, table)",
          ("command", "threads"): "command: dask's threads (local: scheduler, nannies, client)",
          ("scheduler", None): "dask scheduler (external)", ("nanny", None): "nannies (external)",
          ("worker", "threads"): "workers: the tasks (calibrations, trials)",
          ("worker", "main"): "workers: their event loops and imports", ("tracker", None): "resource tracker"}


def _parts(procs: dict) -> dict[str, float]:
    """A run's CPU s by :data:`_PARTS`' column."""
    out = dict.fromkeys(_PARTS.values(), 0.0)
    for d in procs.values():
        for part in ("main", "threads"):
            key = (d["role"], part) if (d["role"], part) in _PARTS else (d["role"], None)
            if key in _PARTS:
                out[_PARTS[key]] += d[part]
    return out


def _account(raw: dict, best: dict, n: int) -> list[str]:
    """The page's account of each run's CPU: by process and thread (/proc, sampled), against the trials' own work
    (n x one trial's CPU in one process)."""
    runs = [("local, 1 worker", best[1]), ("local, 2 workers", best[2]), ("external, 1 worker", raw["ext"][1]),
            ("external, 2 workers", raw["ext"][2])]
    if not all("procs" in r for _, r in runs):
        return []
    work = n * raw["work_cpu"]
    rows = []
    for name, r in runs:
        parts = _parts(r["procs"])
        total = sum(parts.values())
        rows.append([name, *(f"{v:.1f}" for v in parts.values()), f"{total:.1f}", f"{work:.1f}",
                     f"{total - work:.1f} ({100 * (total - work) / work:.0f} %)"])
    return ["## Where the CPU goes", "",
            f"CPU s of each process of a run, its main thread and its others apart (/proc, sampled every 0.05 s), "
            f"against the trials' own work: {n} x {raw['work_cpu']:.3f} s, one trial's CPU in one process (the "
            "median of the repeated calls). What the rest is made of, activity by activity (figures, records, "
            "imports, dask), was measured with each function's CPU: [docs/studies/bench_study200.md]"
            "(../studies/bench_study200.md).", "",
            *table(["run", *_PARTS.values(), "all", "the trials' own work", "the rest (of the work)"], rows,
                   "l" + "r" * (len(_PARTS) + 3)), ""]


def _bound(raw: dict, best: dict, n: int) -> list[str]:
    """What the second worker can give at most: the one-off costs (start-up, after the last record) stay whatever
    the workers; the trials' work halves at best; a 2-core machine's wall is at least the run's CPU over 2."""
    rec1, rec2 = best[1]["records"], best[2]["records"]
    if not rec1 or not rec2:
        return []
    once = rec1[0] + best[1]["wall"] - rec1[-1]
    work = n * raw["work"]
    ideal = (once + work) / (once + work / 2)
    cpu2 = sum(_parts(best[2].get("procs", {})).values())
    return ["**What the second worker can give.** The 1-worker run's one-off costs (start-up to the first "
            f"record and after the last) are {once:.1f} s of its wall; the trials' work {n} x {raw['work']:.3f} = "
            f"{work:.1f} s. With every other cost cut to nothing and the one-off costs as they are, 2 workers give "
            f"at most ({once:.1f} + {work:.1f}) / ({once:.1f} + {work / 2:.1f}) = **{ideal:.2f} x**; 1.8 x needs the "
            f"one-off costs below {work / 8:.1f} s ((S + W) / (S + W/2) >= 1.8: S <= "
            "W / 8). "
            + (f"The 2-worker run spent {cpu2:.1f} s of CPU in all: on 2 cores its wall is at least {cpu2 / 2:.1f} "
               f"s, at most {best[1]['wall'] / (cpu2 / 2):.2f} x faster than the 1-worker run's "
               f"{best[1]['wall']:.1f} s." if cpu2 else "")]


def _trial_work(folder: Path, repeat: int, name: str = "one.toml") -> dict:
    """One trial's work in this process, without dask (casflex.study.runner.trial_run, the subject's scene read
    once as a worker reads it): wall s of the first call, then the best and the median of ``repeat`` more (the
    median: the steady stream's records are a mean over calls, under the same load)."""
    from casflex.study import runner
    from casflex.study.study_file import load_study

    path = folder / name
    if not path.exists():
        path.write_text(study_text(1, 1))
    st = load_study(str(path))
    s = st.subjects[0]
    cal = runner.calibrate_run(**runner._calibration_kwargs(st, s))  # the subject's masses scaled, as the study's
    kwargs = {"scene": cal["scene"], "trial": s.trials[0], "options": st.options.trials, "uncertain": ()}
    times, cpus = [], []
    for _ in range(repeat + 1):
        t0, c0 = time.perf_counter(), time.process_time()
        runner.trial_run(**kwargs)
        times.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return {"first": times[0], "best": min(times[1:]), "median": float(np.median(times[1:])),
            "cpu": float(np.median(cpus[1:])), "times": times[1:], "cpus": cpus[1:]}


def _pooled(before: dict, after: dict) -> dict:
    """One trial's work measured before the commands and after the local ones, pooled: this machine's speed drifts
    by a quarter over minutes (a process's repeated calls 135-227 ms), and the steady stream's records span both."""
    times, cpus = before["times"] + after["times"], before["cpus"] + after["cpus"]
    return {"first": before["first"], "best": min(times), "median": float(np.median(times)),
            "cpu": float(np.median(cpus)), "medians": (before["median"], after["median"])}


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("bench_study200", quick)
    up0, load, busy0, own0 = _uptime(), LoadSampler(2.0 if quick else 5.0), _busy_s(), _own_s()
    subjects, trials, rounds = (4, 5, 1) if quick else (10, 20, 2)
    local: dict[int, list[dict]] = {1: [], 2: []}
    with tempfile.TemporaryDirectory(prefix="casflex-bench-study200-") as tmp:
        folder = Path(tmp)
        for f in FILES:
            shutil.copy(LAB / f, folder / f)
        study = folder / "study.toml"
        study.write_text(study_text(subjects, trials))
        env = _env(folder)
        one = _trial_work(folder, 5 if quick else 15)
        (folder / "warm.toml").write_text(study_text(1, 1))
        _command(folder / "warm.toml", folder / "warm", env, "--workers", "2")  # bytecode written, caches warm
        k = 0
        for _ in range(rounds):
            for w in (1, 2):
                k += 1
                local[w].append(_command(study, folder / f"out{k}", env, "--workers", str(w)))
        one = _pooled(one, _trial_work(folder, 5 if quick else 15))
        again = [_command(study, folder / "out1", env, "--workers", "1") for _ in range(3)]
        ext, ext_tasks = _external_runs(folder, study, env)
        bands = _bands_runs(folder, env, *((2, 2) if quick else (10, 20)), 2 if quick else 5)
        bands["plain"] = one["median"]
        tables = {name: (folder / name / "loads.csv").read_text()
                  for name in [f"out{i + 1}" for i in range(k)] + ["ext1", "ext2"]}
    samples, up1, busy1, own1 = load.stop(), _uptime(), _busy_s(), _own_s() + _UNREAPED[0]
    others = None if busy0 is None or busy1 is None else max(0.0, (busy1 - busy0) - (own1 - own0)) / banner.wall
    return render({"quick": quick, "subjects": subjects, "trials": trials, "work": one["median"],
                   "work_best": one["best"], "work_first": one["first"], "work_cpu": one["cpu"], "local": local,
                   "work_medians": one["medians"],
                   "again": again, "ext": ext,
                   "ext_tasks": ext_tasks, "bands": bands,
                   "same_tables": len(set(tables.values())) == 1, "n_tables": len(tables),
                   "load": {"up0": up0, "up1": up1, "samples": samples, "others": others}}, out_dir, banner)


def _medians(raw: dict) -> str:
    m = raw.get("work_medians")
    return f": their medians {m[0]:.3f} and {m[1]:.3f} s, this machine's speed drifts" if m else ""


def render(raw: dict, out_dir: Path | None, banner: Banner | None = None) -> dict:
    n, work = raw["subjects"] * raw["trials"], raw["work"]
    best = {w: min(raw["local"][w], key=lambda r: r["wall"]) for w in (1, 2)}
    ext = raw["ext"]
    walls = {"local, 1 worker": best[1]["wall"], "local, 2 workers": best[2]["wall"],
             "external, 1 worker": ext[1]["wall"], "external, 2 workers": ext[2]["wall"]}
    tpm = {k.replace(", ", "\n"): 60.0 * n / v for k, v in walls.items()}
    speed_local, speed_ext = best[1]["wall"] / best[2]["wall"], ext[1]["wall"] / ext[2]["wall"]
    again = min(r["wall"] for r in raw["again"])
    again_walls = " / ".join(f"{r['wall']:.2f}" for r in raw["again"])
    rows = []
    for name, r, workers in (("local, 1 worker", best[1], 1), ("local, 2 workers", best[2], 2),
                             ("external, 1 worker", ext[1], 1), ("external, 2 workers", ext[2], 2)):
        rec, own = r["records"], _own_work(r)
        rows.append([name, f"{r['wall']:.1f}", f"{r['cpu']:.1f}", f"{60.0 * n / r['wall']:.1f}",
                     f"{r['wall'] / n:.3f}", f"{_overhead(r['wall'], n, work):+.0f} %",
                     f"{rec[0]:.1f}" if rec else "-", f"{_steady(rec):.3f}", f"{own:.3f}",
                     f"{_steady_overhead(rec, workers, own):+.0f} %" if rec else "-",
                     f"{_steady_overhead(rec, workers, work):+.0f} %" if rec else "-",
                     f"{r['wall'] - rec[-1]:.1f}" if rec else "-"])
    tl = {w: ext[w]["timeline"] for w in (1, 2)}
    rec1 = best[1]["records"]
    steady1 = _steady(rec1)
    own1 = _own_work(best[1])
    per_trial = _steady_overhead(rec1, 1, own1) if rec1 else float("nan")
    per_trial_apart = _steady_overhead(rec1, 1, work) if rec1 else float("nan")
    whole = _overhead(best[1]["wall"], n, work)
    work_best = raw.get("work_best", work)
    ld = raw["load"]
    s = ld["samples"]
    head = "# What a 200-trial `casflex study` costs" if not raw["quick"] else "# What a `casflex study` costs (quick)"
    page = [head,
            "", (banner.line() if banner else "Re-rendered from raw numbers.")
            + " What is measured: the docstring of [studies/bench_study200.py](../../studies/bench_study200.py).", "",
            f"**The machine's load.** {os.cpu_count()} cores. `uptime` before: `{ld['up0']}`; after: `{ld['up1']}`. "
            f"The 1-minute load average through the run ({len(s)} samples): min {min(s):.2f}, median "
            f"{np.median(s):.2f}, max {max(s):.2f}, this benchmark's own processes included. "
            + ("" if ld["others"] is None else f"The machine's other processes kept {ld['others']:.2f} cores busy on "
               "average (/proc/stat's busy time less this benchmark's CPU time): the second worker's gain is "
               "bounded by the core they leave idle."), "",
            "![trials per minute; the external two-worker run's tasks](../figures/bench_study200.png)", "",
            f"The study: {raw['subjects']} subjects x {raw['trials']} trials = {n}, the same 1 s of Hamner's running "
            "(61 frames at 60 Hz, 41 markers, two plates) on the planar whole-body model, each subject's masses "
            "scaled to its own mass; no bands. One trial's work in one process (casflex.study.runner.trial_run, no "
            f"dask, the subject's scene read once as a worker reads it): {work:.3f} s (the median of repeated calls, "
            f"as the steady stream's records are a mean over calls under the same load, taken before the commands "
            f"and after the local ones and pooled{_medians(raw)}; the best {work_best:.3f} s, the first call "
            f"{raw['work_first']:.2f} s).", "",
            "## The command, a new process and a new record folder each time", "",
            *table(["cluster", "wall s", "CPU s (all processes)", "trials per minute", "wall s per trial",
                    "whole command: overhead per trial (of the work)", "start-up: first record s",
                    "s per record (steady)", "a trial's own CPU s (its records)",
                    "steady stream: overhead per trial (of its own CPU)",
                    "steady stream: overhead per trial (of one process's)",
                    "after the last record s (table, figures)"], rows, "lrrrrrrrrrrr"), "",
            "What each part costs: the **steady stream**'s overhead per trial is the wall s a worker spends per record "
            "(s per record x workers) less one trial's work, over the work: what a trial costs beyond its own work "
            "once the study runs (dask's round trip, the record written, the worker's share of the machine with the "
            "command's process). A trial's work is what its records say its run cost (the run's thread's CPU in its "
            "worker, from the call to the return: casflex.study.sweep.RUN_TIME; the mean over the command's trials, "
            "a subject's first trial with its model's build), measured where and while the study ran; beside it, "
            "against one trial in one process apart (above: this machine's speed drifts between the two). The "
            "**one-off costs** of a study, whatever its size: the start-up (process, "
            "imports, study check, the cluster's start, the workers' imports, the calibrations, and a first trial) "
            "and the time after the last record (the last subject's figure, the group's, the table, the summary). "
            "The **whole command**'s overhead per trial spreads them over this study's trials.", "",
            f"- 2 workers against 1: **{speed_local:.2f} x** on the local cluster, **{speed_ext:.2f} x** on the "
            "external scheduler.",
            f"- The overhead per trial on 1 local worker: **{per_trial:+.0f} %** of a trial's work in the steady "
            f"stream ({steady1:.3f} s per record against {own1:.3f} s of a trial's own CPU in its worker, its "
            f"records' mean; {per_trial_apart:+.0f} % against one process's {work:.3f} s, "
            f"{100 * (steady1 - work_best) / work_best:+.0f} % against its best call); the one-off costs: the "
            f"start-up {rec1[0]:.1f} s to the first record, {best[1]['wall'] - rec1[-1]:.1f} s after the last "
            f"({raw['subjects'] + 1} figures, {raw['subjects']} of them drawn while the trials ran; the table, its "
            "subjects' lines made while they ran; the "
            f"summary); over the whole command {whole:+.0f} % per trial."
            if rec1 else "- No record times (none written?).",
            f"- The same command on its finished outputs (nothing to run; process, imports, study check, freshness "
            f"check of the records and outputs): **{again:.2f} s** (best of {len(raw['again'])}: "
            f"{again_walls}); it said up to date: "
            f"{all('up to date' in r['stdout'] for r in raw['again'])}.",
            f"- The external scheduler's task stream (the trials' tasks): 1 worker {tl[1]['n']} tasks, "
            f"{tl[1]['busy']:.1f} s of compute in a span of {tl[1]['span']:.1f} s; 2 workers {tl[2]['n']} tasks on "
            f"{tl[2]['workers']} workers, {tl[2]['busy']:.1f} s of compute in {tl[2]['span']:.1f} s, two tasks at "
            f"once {100 * tl[2]['overlap']:.0f} % of the span: the compute's sum is the same work (a core's "
            f"contention shows as a longer sum), the span its spread over the workers "
            f"({tl[1]['span'] / max(tl[2]['span'], 1e-9):.2f} x).",
            *_kinds(raw["ext_tasks"][2]), "", *_account(raw, best, n), *_bound(raw, best, n), "",
            *(_bands_section(raw["bands"]) if raw.get("bands") else [])]
    rows_ok = [("the table is the same, bit for bit, from every run", f"{raw['n_tables']} runs", raw["same_tables"]),
               ("the rerun on finished outputs ran nothing", str(all("up to date" in r["stdout"]
                                                                    for r in raw["again"])),
                all("up to date" in r["stdout"] for r in raw["again"])),
               ("the external run's tasks ran on both workers", f"{tl[2]['workers']} workers", tl[2]["workers"] == 2),
               ("2 workers give at least 1.8 x (local / external)", f"{speed_local:.2f} x / {speed_ext:.2f} x",
                min(speed_local, speed_ext) >= 1.8, False),
               ("the per-trial overhead is below 10 % of a trial's work (the steady stream, local, 1 worker: the "
                "cost per trial beyond its work; the one-off costs in the table beside it)", f"{per_trial:+.0f} %",
                per_trial < 10, False),
               ("the same over the whole command, one-off costs included (reported, no goal)", f"{whole:+.0f} %",
                True, False),
               ("the rerun takes less than 1 s", f"{again:.2f} s", again < 1.0, False)]
    if raw.get("bands"):
        br = raw["bands"]["runs"]
        rows_ok.append(("the study with its bands: 2 workers give at least 1.8 x (local; the second configuration, "
                        "not the goal's answer)", f"{br[1]['wall'] / br[2]['wall']:.2f} x",
                        br[1]["wall"] / br[2]["wall"] >= 1.8, False))
    lines, failed = checks(rows_ok)
    write_outputs("bench_study200", out_dir, raw["quick"], "\n".join(page + lines),
                  figure(tpm, raw["ext_tasks"][2], n, ext[2]["wall"]))
    assert_checks(failed)
    return raw


if __name__ == "__main__":
    cli(__doc__, main)
