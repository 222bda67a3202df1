"""``casflex study`` on a cluster (issue 38): the same table (loads.csv) from the default local cluster, from an
external ``dask scheduler`` with two ``dask worker`` processes, and after the command was killed halfway (SIGKILL:
no clean shut-down; SIGINT: Ctrl-C at a terminal, to the whole process group) and started again.

The study is tests/test_study.py's (Hamner's subject 02 running, 1 s, on the planar whole-body model: three trials of
two "subjects"), its text and files imported from there. Its uninterrupted table on the default local cluster is
computed once per session (:func:`reference`), shared by the tests (and by pytest-xdist's workers, under a lock).

The tables are compared exactly, as text: the same machine, the same code and the same inputs, with one BLAS
thread in every process (tests/conftest.py sets OPENBLAS_NUM_THREADS=1 before numpy loads; the command's and the
workers' processes inherit it), do the same floating-point operations in the same order wherever a trial runs, and
loads.csv writes each value by ``repr`` (the shortest text that reads back to the same double): equal text is
equal bits. The rigid inverse runs no compiled code (CASFLEX_CACHE plays no part). So a tolerance would only hide
a difference that is not round-off: a record reused from another run, a trial cut at other frames, a worker
holding state across trials. (Machines with other CPUs or BLAS builds in one cluster would differ in the last
bits; not this test's case.)

"Halfway" is made certain, not a matter of timing: the killed runs' workers preload :data:`HOLD` (through dask's
config, DASK_DISTRIBUTED__WORKER__PRELOAD), which holds the study's one trial with a window (``s02 run_late``) inside
``casflex.inverse.inverse_dynamics`` until a file that never appears exists, and says so by a file of its own. The
other trials run as usual; the command is killed once one of them is recorded and the held trial is held, while the
other worker computes or holds. Then, as a writer killed in the middle of a record would leave it, one calibration's
record is cut short. The run again has no preload and must redo exactly the runs without a valid record: that
calibration (the same scene again, so its trials' records stay theirs) and the trials not recorded.
"""

from __future__ import annotations

import csv
import fcntl
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from test_study import FILES, LAB, STUDY

from casflex.cli import main

pytest.importorskip("distributed")
pytestmark = pytest.mark.skipif(os.name != "posix" or not Path("/proc/self/stat").exists(),
                                reason="process groups and /proc (Linux): the kills and the clean-up check")

#: generous: the suite runs on 2 busy cores; a normal run records its first trial in ~5 s
TIMEOUT_S = 300.0
#: a dask worker preload: the trial whose window starts at $CASFLEX_TEST_HOLD_T_START says it is held (creates
#: $CASFLEX_TEST_HELD) and waits in inverse_dynamics until $CASFLEX_TEST_GATE exists (never, here).
#: It patches casflex.inverse (imported inside trial_run's body, so found at run time whether the sweep ships
#: trial_run by reference or by value); once per process, as dask may import a preload file twice.
HOLD = '''
import os, time
import casflex.inverse as inv

def _hold(original):
    def inverse_dynamics(*args, **kwargs):
        if args[1].t_start == float(os.environ["CASFLEX_TEST_HOLD_T_START"]):  # (scene, trial)
            open(os.environ["CASFLEX_TEST_HELD"], "w").close()
            end = time.monotonic() + 900.0
            while not os.path.exists(os.environ["CASFLEX_TEST_GATE"]) and time.monotonic() < end:
                time.sleep(0.05)
        return original(*args, **kwargs)
    inverse_dynamics.held = True
    return inverse_dynamics

if not getattr(inv.inverse_dynamics, "held", False):
    inv.inverse_dynamics = _hold(inv.inverse_dynamics)
'''


def _held(study: Path) -> tuple[str, float]:
    """The trial the killed runs hold: the study's only one with a window (its run's name, its window's start)."""
    from casflex.study.study_file import load_study

    (s, t), = [(s, t) for s, t in load_study(str(study)).trials() if t.window is not None]
    return f"trial-{s.name}-{t.name}", t.window[0]


def _without_cost(rec: dict) -> dict:
    """A record without what its run cost (the same run costs other seconds each time)."""
    from casflex.study.sweep import RUN_TIME

    return {k: v for k, v in rec.items() if k != RUN_TIME}


def _of(records: dict[str, Path], name: str) -> list[str]:
    """The records (file stems) of the runs ``name`` (casflex.study.runner: ``<name>-<fingerprint of the inputs>``),
    or of every trial where ``name`` is "trial-"."""
    pattern = r"trial-.+" if name == "trial-" else re.escape(name) + r"(-[0-9a-f]+)?"
    return sorted(k for k in records if re.fullmatch(pattern, k))


def _study(folder: Path) -> Path:
    """tests/test_study.py's study (three trials, no failing one) and its files in ``folder``: the study file."""
    folder.mkdir(parents=True, exist_ok=True)
    for f in FILES:
        shutil.copy(LAB / f, folder / f)
    path = folder / "study.toml"
    path.write_text(STUDY.replace("{extra}", ""))
    return path


@pytest.fixture(scope="session")
def reference(tmp_path_factory) -> str:
    """loads.csv of the uninterrupted study on the default local cluster (2 workers), computed once per session:
    under pytest-xdist, once for all its workers (their shared temporary folder, a lock)."""
    base = tmp_path_factory.getbasetemp()
    shared = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    folder = shared / "study_cluster_reference"
    with open(shared / "study_cluster_reference.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        table = folder / "out" / "loads.csv"
        if not table.exists():
            study = _study(folder)
            assert main(["study", str(study), "--out", str(folder / "out"), "--quiet"]) == 0
        return table.read_text()


def _same_table(got: str, want: str) -> None:
    """The same rows (subject, trial, load, foot, cycle, percent) in the same order and the same values and bands,
    bit for bit (the module docstring says why exactly); a failure says where they part."""
    if got == want:
        return
    a, b = list(csv.reader(got.splitlines())), list(csv.reader(want.splitlines()))
    assert [r[:6] for r in a] == [r[:6] for r in b], "the rows differ (subject, trial, load, foot, cycle, percent)"
    diff = [(r[:6], float(r[6]) - float(s[6])) for r, s in zip(a[1:], b[1:], strict=True) if r[6:] != s[6:]]
    raise AssertionError(f"{len(diff)} values differ; the first: {diff[:3]}")


def _default_signals() -> None:
    """In the child: the signals' default dispositions, as in a terminal, whatever runs the test."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_DFL)


def _spawn(cmd: list[str], log: Path, env: dict | None = None, cwd: Path | None = None) -> subprocess.Popen:
    """``cmd`` as the leader of a new process group (its dask processes join it), output to ``log``."""
    with log.open("wb") as f:
        return subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, env=env, cwd=cwd, start_new_session=True,
                                preexec_fn=_default_signals)


def _members(pgid: int) -> list[int]:
    """The live (not zombie) processes of the process group ``pgid``."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            state, _, group = stat.read_text().rpartition(")")[2].split()[:3]
        except (OSError, ValueError):
            continue  # gone meanwhile
        if int(group) == pgid and state != "Z":
            out.append(int(stat.parent.name))
    return out


def _wait_gone(pgid: int, timeout: float = 60.0) -> list[int]:
    """Wait until the group ``pgid`` has no live process; those still there after ``timeout``."""
    end = time.monotonic() + timeout
    while (left := _members(pgid)) and time.monotonic() < end:
        time.sleep(0.1)
    return left


def _stop(proc: subprocess.Popen, sig: int = signal.SIGKILL) -> None:
    """End ``proc`` and every process of its group (a test's clean-up, whatever happened)."""
    for s in (sig, signal.SIGKILL):
        if _members(proc.pid):
            try:
                os.killpg(proc.pid, s)
            except ProcessLookupError:
                pass
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            continue
        if not _wait_gone(proc.pid, 20):
            return


def _wait_for(what: Callable[[], object], procs: list[subprocess.Popen], logs: list[Path], why: str):
    """Poll ``what()`` until it is true (its value), failing after TIMEOUT_S or when one of ``procs`` ends."""
    end = time.monotonic() + TIMEOUT_S
    while time.monotonic() < end:
        if got := what():
            return got
        if any(p.poll() is not None for p in procs):
            break
        time.sleep(0.05)
    tails = "\n".join(f"--- {log.name}:\n{log.read_text(errors='replace')[-3000:]}" for log in logs)
    pytest.fail(f"{why}: not within {TIMEOUT_S:g} s, or a process ended (exit {[p.poll() for p in procs]})\n{tails}")


def _env(tmp: Path, **extra: str) -> dict:
    """This process's environment (one BLAS thread: tests/conftest.py) with dask's scratch space in ``tmp``."""
    return {**os.environ, "DASK_TEMPORARY_DIRECTORY": str(tmp / "dask-scratch"), **extra}


def _dask() -> list[str]:
    exe = Path(sys.executable).with_name("dask")
    found = str(exe) if exe.exists() else shutil.which("dask")
    if found is None:
        pytest.skip("the `dask` command (distributed's command line: dask scheduler, dask worker) is not installed "
                    "next to this Python nor on PATH")
    return [found]


def test_an_external_scheduler_with_two_workers_gives_the_local_clusters_table(reference, tmp_path):
    from distributed import Client

    dask = _dask()
    study = _study(tmp_path / "study")
    env = _env(tmp_path)
    sched_file, procs, logs = tmp_path / "scheduler.json", [], []

    def address() -> str | None:
        try:
            return json.loads(sched_file.read_text())["address"]
        except (OSError, ValueError, KeyError):
            return None  # not there yet, or half written

    try:
        logs.append(tmp_path / "scheduler.log")
        procs.append(_spawn([*dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                             "--scheduler-file", str(sched_file)], logs[-1], env, tmp_path))
        addr = _wait_for(address, procs, logs, "the scheduler's address in its --scheduler-file")
        for i in range(2):
            logs.append(tmp_path / f"worker{i}.log")
            procs.append(_spawn([*dask, "worker", addr, "--nworkers", "1", "--nthreads", "1", "--no-dashboard",
                                 "--host", "127.0.0.1", "--name", f"w{i}", "--local-directory",
                                 str(tmp_path / f"w{i}")], logs[-1], env, tmp_path))
        with Client(addr, timeout="60s") as client:
            client.wait_for_workers(2, timeout=TIMEOUT_S)
            out = tmp_path / "out"
            assert main(["study", str(study), "--out", str(out), "--scheduler", addr, "--quiet"]) == 0
            # which worker ran which trial: each worker's own log of its tasks
            ran = client.run(lambda dask_worker: sorted({str(e[0]) for e in dask_worker.state.log
                                                         if str(e[0]).startswith("casflex-trial-")}))
        _same_table((out / "loads.csv").read_text(), reference)
        assert len(ran) == 2 and all(ran.values()), f"each of the two workers ran trials: {ran}"
    finally:
        for p in reversed(procs):
            _stop(p, signal.SIGTERM)
    assert not any(_members(p.pid) for p in procs)


def _halfway(tmp_path: Path) -> tuple[Path, subprocess.Popen, Path, str]:
    """``casflex study`` started on the study in ``tmp_path`` with its workers holding :func:`_held`'s trial (the
    module docstring), returned once a first trial is recorded and that one held: (the study file, the process,
    its log, the held run's name)."""
    study = _study(tmp_path)
    log, record = tmp_path / "killed.log", tmp_path / "out" / "record"
    held, t_start = _held(study)
    (tmp_path / "hold.py").write_text(HOLD)
    env = _env(tmp_path, DASK_DISTRIBUTED__WORKER__PRELOAD=json.dumps([str(tmp_path / "hold.py")]),
               CASFLEX_TEST_HOLD_T_START=repr(t_start), CASFLEX_TEST_HELD=str(tmp_path / "held"),
               CASFLEX_TEST_GATE=str(tmp_path / "never"))
    proc = _spawn([sys.executable, "-m", "casflex", "study", str(study), "--out", str(tmp_path / "out")], log, env,
                  tmp_path)
    try:
        _wait_for(lambda: list(record.glob("trial-*.json")) and (tmp_path / "held").exists(), [proc], [log],
                  f"a first trial's record, and {held} held")
    except BaseException:
        _stop(proc)
        raise
    return study, proc, log, held


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT], ids=["SIGKILL", "SIGINT"])
def test_a_study_killed_halfway_and_run_again_redoes_only_the_unrecorded_trials(reference, tmp_path, capsys, sig):
    out = tmp_path / "out"
    record = out / "record"
    study, proc, log, held = _halfway(tmp_path)
    try:
        os.killpg(proc.pid, sig)  # the whole group, as a terminal's Ctrl-C (and the kill a crash would be)
        code = proc.wait(TIMEOUT_S)
        left = _wait_gone(proc.pid)
    finally:
        _stop(proc)
    said = log.read_text(errors="replace")
    assert not left, f"processes of the killed command still running: {left}"
    if sig == signal.SIGKILL:
        assert code == -signal.SIGKILL
    else:
        assert code == 130, said  # casflex's Ctrl-C status (casflex._entry)
        assert "interrupted" in said
        # the workers took the terminal's Ctrl-C too: each printed its KeyboardInterrupt's traceback
        assert "Traceback" not in said and "KeyboardInterrupt" not in said, said
        # the outputs' staging folder removed: nothing but the records and the study's own files
        assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == [], said
    assert not (out / "loads.csv").exists() and not list(tmp_path.rglob("loads.csv")), "no table from a killed run"

    # What the kill left: valid records only (each written whole, then renamed), never the held trial's; at most
    # a writer's temporary file (.<name>.json.*.tmp), which no run reads.
    names = sorted(p.name for p in record.iterdir())
    done = {p.stem: p for p in record.glob("*.json")}
    assert all(json.loads(p.read_text()) for p in done.values())
    assert all(n in {f"{k}.json" for k in done} or (n.startswith(".") and n.endswith(".tmp")) for n in names), names
    assert _of(done, "calibrate-s02") and _of(done, "calibrate-s02_again") and not _of(done, held), names
    assert 1 <= len(_of(done, "trial-")) < 3, names

    # What a writer killed in the middle of a record would leave (had it written in place, or before its rename):
    # the held trial's subject's calibration record cut short, and a temporary file. Neither may pass for a finished
    # run: the calibration is done again (the same scene: its trials' records still theirs), and nothing else.
    cut, = _of(done, "calibrate-s02")
    whole = done.pop(cut).read_bytes()
    (record / f"{cut}.json").write_bytes(whole[:len(whole) // 2])
    (record / f".{cut}.json.x1y2z3.tmp").write_bytes(whole[:len(whole) // 3])
    before = {k: (p.stat().st_ino, p.stat().st_mtime_ns, p.read_bytes()) for k, p in done.items()}

    capsys.readouterr()
    assert main(["study", str(study), "--out", str(out)]) == 0
    progress = capsys.readouterr().err
    ran = {line.partition("(last: ")[2].partition(")")[0].strip() for line in progress.replace("\r", "\n").splitlines()}
    ran.discard("")
    assert not {k for k in before if k[:40] in ran}, f"recorded before the kill, and run again: {ran}"
    assert cut[:40] in ran, progress  # the cut record was not taken as done
    assert any(k.startswith(f"{held}-") for k in ran), progress
    for k, (ino, mtime, data) in before.items():
        p = record / f"{k}.json"
        assert (p.stat().st_ino, p.stat().st_mtime_ns, p.read_bytes()) == (ino, mtime, data), f"{k} rewritten"
    after = {p.stem: p for p in record.glob("*.json")}
    again, first = (_without_cost(json.loads(t)) for t in (after[cut].read_text(), whole))
    assert again == first, "the calibration done again, the same"
    assert all("loads" in json.loads(after[k].read_text()) for k in _of(after, "trial-"))
    assert len(_of(after, "trial-")) == 3
    _same_table((out / "loads.csv").read_text(), reference)


def test_a_second_ctrl_c_while_the_cluster_closes_exits_at_once(tmp_path):
    # the first Ctrl-C closes the cluster (seconds: a held worker is stopped by its nanny); a second one stopped
    # that close, and dask's exit handler closed it again, for up to 10 s. Now out within 2 s, one line, no process
    # left (the workers end with their parent: each watches a pipe from it).
    _, proc, log, _ = _halfway(tmp_path)
    try:
        os.killpg(proc.pid, signal.SIGINT)
        time.sleep(0.3)  # into the close (about 4 s here with the held worker)
        second = time.monotonic()
        os.killpg(proc.pid, signal.SIGINT)
        code = proc.wait(TIMEOUT_S)
        took = time.monotonic() - second
        left = _wait_gone(proc.pid)
    finally:
        _stop(proc)
    said = log.read_text(errors="replace")
    assert code == 130 and took < 2.0, (code, took, said)  # 2 s: an exit, not a close, on a busy machine
    assert not left, f"processes of the stopped command still running: {left}"
    assert said.count("casflex: interrupted") == 1 and "Traceback" not in said and "Warning" not in said, said
