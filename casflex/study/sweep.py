"""Sweeps: many independent runs (basins, multi-start, Monte Carlo over noise, grids) on
dask.distributed, resumable.

Each run has a unique key and keyword arguments for one importable function. Its result (a
JSON-serialisable dict) is written atomically to ``<record>/<key>.json`` as soon as it
finishes, with its key in the field ``"run"`` (:data:`IDENTITY`), so an interrupted sweep restarted with
the same record directory redoes only the runs without a valid record: a file that is no JSON object, that
names another run (a record copied by hand under another name) or that lacks a field the run's record holds
(:attr:`Run.fields`) is not taken as done, and said on stderr. A run that raises is recorded too, with
``{"error": "..."}``, and is not retried unless ``retry_failed=True``. Each record says what its run cost in its
worker (:data:`RUN_TIME`: its thread's CPU s and its wall s, from the call to the return).

By default the runs go to a ``LocalCluster`` of ``n_workers`` single-threaded processes (at most
:func:`max_workers`: the machine's cores and memory; once started they ignore Ctrl-C, which the sweep's
process handles by closing them);
``scheduler="tcp://host:8786"`` sends them to an existing cluster (the workers must have
casflex installed). A cluster that has lost every worker for :data:`NO_WORKERS_S` seconds (a
worker gone with its nanny, as happens under heavy load) is started anew, up to
:data:`REVIVALS` times, for the runs still pending; an existing cluster is not, and those runs
are recorded as failed. A sweep never waits for workers that will not come.

``identification_run`` is the run function for identification sweeps: the model and the
simulated data are built once per worker process and cached.
"""

from __future__ import annotations

import functools
import json
import logging
import os
import re
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from casflex.results import atomic_write_json

__all__ = ["Run", "SweepResult", "Session", "run_sweep", "identification_run", "max_workers", "unreachable", "IDENTITY",
           "RUN_TIME"]

_KEY = re.compile(r"^[A-Za-z0-9_.=+-]{1,200}$")
#: s with no worker at all on the scheduler before the pending runs are given up on this cluster (a
#: nanny restarting a worker that a run killed takes seconds, more on a loaded machine)
NO_WORKERS_S = 60.0
#: how many times a sweep's own LocalCluster is started anew after it lost every worker
REVIVALS = 3
_POLL_S = 2.0  # s between checks of the workers while no run finishes
_WAKE_S = 0.02  # s between looks for finished runs while none is (a record written at most this late)
#: the field of a record that names its run (its key): a record is taken only under its own name
IDENTITY = "run"
#: the field of a record (the runs run in this version) with the run's own cost in its worker: ``{"cpu_s": its
#: thread's CPU s, "wall_s": its wall s}`` from the run function's call to its return (not dask's transfers, the
#: result's pickling or the record's writing): what a run's work is, measured where and while the sweep ran it
RUN_TIME = "run_time"
#: bytes of memory allowed a local worker: one peaked at 0.10 GB resident in tests/test_study.py's study (Hamner's
#: running trial, ps every 0.25 s); 10 x that for longer trials, bands, compiled models and the scheduler's share
WORKER_BYTES = 1 << 30


@dataclass(frozen=True)
class Run:
    """One run of a sweep: ``fn(**kwargs)`` recorded under ``key`` (letters, digits, ``_.=+-``); ``fields``: those
    its record holds when it did not fail (a record without one of them is not taken as done)."""

    key: str
    fn: Callable[..., dict]
    kwargs: dict
    fields: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not _KEY.match(self.key):
            raise ValueError(f"run key {self.key!r}: use 1-200 letters, digits or _.=+- (it names a file)")


@dataclass(frozen=True)
class SweepResult:
    """results: {key: recorded dict} for every run of the sweep that has a record;
    executed: keys run in this call; reused: keys taken from earlier records."""

    results: dict[str, dict]
    executed: tuple[str, ...]
    reused: tuple[str, ...]
    interrupted: bool
    wall_s: float


def _read(path: Path, run: Run) -> dict | None:
    """The record of ``run`` at ``path`` (without its :data:`IDENTITY`), or None: there is none, or it is not a
    valid record of this run (said on stderr): the run is done again, never a record taken on trust."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError) as exc:
        return _invalid(path, f"cannot be read ({getattr(exc, 'strerror', None) or exc})")
    try:
        rec = json.loads(text)
    except ValueError:
        return _invalid(path, "is not JSON (a write cut short?)")
    if not isinstance(rec, dict):
        return _invalid(path, f"holds a JSON {type(rec).__name__}, not a run's record")
    named = rec.pop(IDENTITY, None)
    if named != run.key:
        return _invalid(path, f"is the record of {named!r}, not of {run.key!r} (copied under another name?)"
                        if named is not None else f"does not name its run (no {IDENTITY!r} field)")
    missing = [f for f in run.fields if f not in rec] if "error" not in rec else []
    if missing:
        return _invalid(path, f"lacks the field {missing[0]!r} of its run's record")
    return rec


def _invalid(path: Path, why: str) -> None:
    print(f"casflex sweep: the record {path} {why}: not taken as done, the run is done again", file=sys.stderr)
    return None


def max_workers() -> tuple[int, str]:
    """(the most local workers this machine runs at once, why): one per core this process may use, and
    :data:`WORKER_BYTES` of the machine's memory each; more only queue for the cores and can exhaust the memory."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):  # no sysconf (Windows): the cores alone
        return cores, f"{cores} core(s)"
    limit = max(1, min(cores, memory // WORKER_BYTES))
    return limit, f"{cores} core(s), {memory / 2**30:.1f} GiB of memory at {WORKER_BYTES / 2**30:g} GiB a worker"


#: s: a record's temporary file this old was left by a writer killed mid-write (a write takes milliseconds)
ABANDONED_S = 60.0


def _clear_abandoned(rec: Path) -> None:
    """Remove the temporary files of records whose writer was killed (casflex.results.atomic_write_bytes's
    ``.<key>.json.*.tmp``) older than :data:`ABANDONED_S`: never a record, and never one being written."""
    now = time.time()
    for tmp in rec.glob(".*.json.*.tmp"):
        try:
            if now - tmp.stat().st_mtime > ABANDONED_S:
                tmp.unlink()
        except OSError:  # gone meanwhile, or not ours to remove: harmless either way
            pass


def _importable(name: str) -> bool:
    """Whether a worker started from this environment finds the top-level module ``name``: asked of the import
    system's finders themselves (an editable install's finder as well as sys.path's), not of sys.modules, which
    also holds a study script loaded from its file."""
    return any(f.find_spec(name, None) is not None for f in sys.meta_path if hasattr(f, "find_spec"))


def _ship_by_value(fns: Iterable[Callable[..., Any]]) -> dict[Callable[..., Any], bytes]:
    """Each run function pickled by cloudpickle, by value when its module cannot be imported
    from sys.path (a study script run as a file, or loaded from its path): a worker that cannot
    import a function by reference fails to unpickle it, and the sweep would wait forever."""
    import cloudpickle

    out = {}
    for fn in fns:
        mod = sys.modules.get(getattr(fn, "__module__", "") or "")
        if mod is not None and mod.__name__ != "__main__" and not _importable(mod.__name__.split(".")[0]):
            cloudpickle.register_pickle_by_value(mod)
        out[fn] = cloudpickle.dumps(fn)
    return out


#: bytes: a worker's heap keeps up to this much freed memory for its next run, and serves blocks up to half of it from
#: the heap (:func:`worker_malloc`)
WORKER_HEAP_KEEP = 64 << 20


@functools.lru_cache(maxsize=1)
def worker_malloc() -> bool:
    """Undo, once per worker process, what dask's nanny sets for its workers' memory (``MALLOC_TRIM_THRESHOLD_=65536``
    in distributed.nanny.pre-spawn-environ): under it glibc returns every freed block above 64 KiB to the system
    and no longer raises its mmap threshold (128 KiB) as a run's arrays grow, so that each of a trial's many
    temporary arrays is mapped anew and faulted in page by page: 10 500 page faults and +35 % of CPU per trial
    of the 200-trial study (docs/tables/bench_study200.md), against 200 here. Blocks up to half of
    :data:`WORKER_HEAP_KEEP` from the heap, up to that much kept: the worker's memory reported to its nanny is
    at most that much above what it uses. The allocator's policy only: the numbers computed are the same. True
    where applied (glibc; elsewhere nothing is done)."""
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (macOS, Windows, musl without mallopt): its own policy stands
        return False
    m_trim_threshold, m_mmap_threshold = -1, -3  # glibc's malloc.h
    return bool(mallopt(m_mmap_threshold, WORKER_HEAP_KEEP // 2)) & bool(mallopt(m_trim_threshold, WORKER_HEAP_KEEP))


def _call(fn: Callable[..., dict] | bytes, kwargs: dict) -> bytes:
    """``fn(**kwargs)`` in a worker: its record, pickled (:func:`_result`), or ``{"error": ...}`` where it failed;
    with its cost (:data:`RUN_TIME`) where it returned.

    Returned as bytes, not as the dict: dask then holds and sends an opaque buffer, where a dict's result is
    walked by dask's sizeof (twice) and its serializer on the worker (a trial's record: 2600 numbers in nested
    lists); measured with 300 tasks returning a 38 kB record, the worker's CPU a task 8.1 -> 5.9 ms."""
    worker_malloc()
    try:
        if isinstance(fn, bytes):
            import cloudpickle

            fn = cloudpickle.loads(fn)
        cpu, wall = time.thread_time(), time.perf_counter()
        out = fn(**kwargs)
        if not isinstance(out, dict):
            out = {"error": f"run function returned {type(out).__name__}, expected a dict"}
        out[RUN_TIME] = {"cpu_s": time.thread_time() - cpu, "wall_s": time.perf_counter() - wall}
    except Exception as exc:  # noqa: BLE001 - a failed run is a result of the sweep, recorded
        out = {"error": f"{type(exc).__name__}: {exc}"}
    import pickle

    return pickle.dumps(out, protocol=pickle.HIGHEST_PROTOCOL)


def _result(value: Any) -> dict:
    """A run's record from what its task returned (:func:`_call`: the pickled dict)."""
    import pickle

    return pickle.loads(value) if isinstance(value, bytes) else value


def run_sweep(runs: Iterable[Run], record: str | os.PathLike[str], *, scheduler: str | None = None,
              n_workers: int | None = None, retry_failed: bool = False,
              progress: bool | Callable[[int, int, str], None] = True, session: Session | None = None,
              on_record: Callable[[str, dict, bool], None] | None = None) -> SweepResult:
    """Run every run without a valid record on dask.distributed; return all recorded results.

    ``n_workers``: the local cluster's processes (default 2, at most :func:`max_workers`; ValueError beyond,
    before any work). The record directory is created (with its parents) once there is a run to do and the
    cluster answers: a scheduler that cannot be reached leaves nothing behind. Ctrl-C cancels the pending runs,
    keeps every finished record and returns with ``interrupted=True``; calling again with the same ``record``
    resumes. ``session``: the :class:`Session` to run on (its cluster started at its first run, and kept for the
    caller's next sweep; ``scheduler`` and ``n_workers`` are then the session's), else one of the sweep's own.
    ``on_record(key, record, executed)``: called with each run's record as it is known, those recorded before
    (``executed`` False) before any run, each run's as soon as it is written (in this process, while the others
    run: the caller's work on it overlaps theirs).
    """
    t0 = time.perf_counter()
    runs = list(runs)
    keys = [r.key for r in runs]
    if len(set(keys)) != len(keys):
        dup = sorted({k for k in keys if keys.count(k) > 1})
        raise ValueError(f"run keys must be unique; repeated: {dup[:5]}")
    if session is None:
        n_workers = _workers(n_workers, scheduler)
    rec = Path(record)
    if rec.is_dir():
        _clear_abandoned(rec)
    results, reused, todo = {}, [], []
    for r in runs:
        old = _read(rec / f"{r.key}.json", r)
        if old is not None and not (retry_failed and "error" in old):
            results[r.key] = old
            reused.append(r.key)
        else:
            todo.append(r)
    for key in reused if on_record else ():
        on_record(key, results[key], False)
    report = progress if callable(progress) else (_text_progress if progress else None)
    executed: list[str] = []
    interrupted = False
    if todo:
        own = session is None  # a sweep of its own: its cluster closed here whatever happens (Ctrl-C included)
        session = Session(scheduler, n_workers) if own else session
        try:
            client = session.client()
        except BaseException:
            if own:
                session.close()
            raise
        rec.mkdir(parents=True, exist_ok=True)
        blobs = _ship_by_value({r.fn for r in todo})

        def finished(key: str, out: dict) -> None:
            # Neither flushed to the disk nor indented (7 -> 2 ms of this process's CPU a trial's record, 55 kB): a
            # record a crash cut short or lost is refused by _read and its run done again, as an interrupted one is
            atomic_write_json(rec / f"{key}.json", {IDENTITY: key, **{k: v for k, v in out.items() if k != IDENTITY}},
                              durable=False, indent=None)
            results[key] = out
            executed.append(key)
            if report:
                report(len(reused) + len(executed), len(runs), key)
            if on_record:
                on_record(key, out, True)

        try:
            for revival in range(REVIVALS + 1):
                try:
                    killed = _execute(client, todo, blobs, finished, batch=len(todo))
                    # A worker that dies takes every run assigned to it along (a single-threaded
                    # worker holds up to two), and dask gives up on a run after its third such
                    # death: an innocent neighbour of a crashing run may be declared killed,
                    # depending on timing. Runs that died with their worker are run again one at a
                    # time, so only a run that kills a worker on its own is recorded as crashed.
                    _execute(client, [r for r in todo if r.key in killed], blobs, finished, batch=1, last=True)
                    break
                except _NoWorkers as lost:
                    todo = [r for r in todo if r.key in lost.keys]
                    if session.scheduler is not None or revival == REVIVALS:
                        why = (f"NoWorkers: no worker on the scheduler for {NO_WORKERS_S:g} s"
                               + (f" ({session.scheduler}): start workers, then run again with retry_failed=True"
                                  if session.scheduler is not None else f", {REVIVALS} new local clusters lost "
                                  "theirs too: run this run alone to see whether it kills its worker"))
                        for r in todo:
                            finished(r.key, {"error": why})
                        break
                    client = session.restart()
        except KeyboardInterrupt:
            interrupted = True
        finally:
            if own:
                session.close()
    return SweepResult({k: results[k] for k in keys if k in results}, tuple(executed), tuple(reused), interrupted,
                       time.perf_counter() - t0)


def unreachable(address: str, timeout: float = 10.0) -> str | None:
    """Why nothing answers at a dask scheduler's ``address`` (``tcp://host:port`` or ``host:port``), or None where
    a connection is made (or the address is of another protocol, not tried here). A TCP connection alone: quick,
    where dask's client waits its connect timeout (30 s) before it fails."""
    import socket
    from urllib.parse import urlsplit

    scheme, _, rest = address.rpartition("://")
    if scheme not in ("", "tcp"):
        return None
    try:
        parts = urlsplit(f"tcp://{rest}")
        host, port = parts.hostname, parts.port
    except ValueError as exc:
        return f"not an address tcp://HOST:PORT ({exc})"
    if not host or port is None:
        return "not an address tcp://HOST:PORT"
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as exc:
        return exc.strerror or str(exc) or type(exc).__name__
    return None


def _workers(n_workers: int | None, scheduler: str | None) -> int:
    """The local cluster's number of workers: ``n_workers`` checked (ValueError naming it and the limit), or the
    default, 2 where the machine runs 2 (an external scheduler's workers are its own: not checked)."""
    limit, why = max_workers()
    if n_workers is None:
        return min(2, limit)
    if not (isinstance(n_workers, int) and n_workers >= 1):
        raise ValueError(f"n_workers: expected an integer >= 1, got {n_workers!r}")
    if scheduler is None and n_workers > limit:
        raise ValueError(f"n_workers: {n_workers} is more local workers than this machine runs at once (at most "
                         f"{limit}: {why}); give at most {limit}, or a scheduler with its own workers")
    return n_workers


class Session:
    """The cluster of one or more sweeps (a study's calibrations, trials and figures): a local cluster of
    ``n_workers`` processes (checked: :func:`_workers`), or the scheduler at ``scheduler``, connected at the first
    :meth:`client` only (a study with nothing to do starts none) and closed by :meth:`close` (or the ``with``
    block's end, whatever happens). One cluster for all: a local cluster's start is about a second, and its workers
    keep their imports and caches from one sweep to the next."""

    def __init__(self, scheduler: str | None = None, n_workers: int | None = None) -> None:
        self.scheduler = scheduler
        self.n_workers = _workers(n_workers, scheduler)
        self._started: list[Any] = []  # the local clusters started, the last one live
        self._client: Any = None

    def client(self) -> Any:
        """The session's dask Client, connected (its local cluster started) at the first call."""
        if self._client is None:
            if self.scheduler is None:  # its imports under way on another core while this process imports dask's
                from casflex.study.fork_server import fork_server

                fork_server()
            from distributed import Client

            quiet_sync_cancel()

            cluster = None if self.scheduler is not None else _local_cluster(self.n_workers, self._started)
            try:
                self._client = Client(self.scheduler if self.scheduler is not None else cluster)
            except BaseException:
                self.close()
                raise
        return self._client

    @property
    def connected(self) -> bool:
        """Whether the session has its cluster (a run or a figure asked for it)."""
        return self._client is not None

    def restart(self) -> Any:
        """A new local cluster for one that lost every worker: its Client."""
        self.close()
        return self.client()

    def close(self) -> None:
        _close(self._client, self._started[-1] if self._started else None)
        self._client = None
        self._started.clear()

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _SyncCancelRace(logging.Filter):
    """Drops one log record of dask's, a bug of its ``distributed.utils.sync`` (2026.8): a Ctrl-C in the moment
    between a blocking call's start and its coroutine's first step makes the loop run ``cancel()``, which reads the
    coroutine's ``future`` before it is assigned. Tornado logs the NameError with a traceback on stderr (the
    interrupted command already says "interrupted" in one line); every other record passes."""

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        return not (isinstance(exc, NameError) and "'future'" in str(exc) and exc.__traceback__ is not None
                    and _innermost(exc.__traceback__).tb_frame.f_code.co_name == "cancel")


def _innermost(tb: Any) -> Any:
    while tb.tb_next is not None:
        tb = tb.tb_next
    return tb


def quiet_sync_cancel() -> None:
    """Install :class:`_SyncCancelRace` on tornado's application logger, once per process."""
    log = logging.getLogger("tornado.application")
    if not any(isinstance(f, _SyncCancelRace) for f in log.filters):
        log.addFilter(_SyncCancelRace())


#: dask's settings for the sweeps' own local clusters, whose scheduler and nannies share the sweep's process: their
#: periodic looks less often (each server's event-loop tick, every 20 ms by default; the nannies' look at their
#: workers' memory, every 100 ms: a nanny still stops a worker past its memory within a second; the machine's
#: load), and no statistical profile of the workers' runs (their stack looked at every 10 ms, for the dashboard).
#: An idle two-worker cluster cost this process 9.2 % of a core and each worker 6.5 %; with these 2.0 and 0.6 %.
#: No work stealing: a sweep's runs are alike and queued on the scheduler (distributed.scheduler.worker-saturation),
#: so a worker has at most one waiting to steal, and the stealing's bookkeeping costs the scheduler at every task.
QUIET_CLUSTER = {"distributed.worker.memory.monitor-interval": "1s", "distributed.admin.system-monitor.interval": "2s",
                 "distributed.worker.profile.enabled": False, "distributed.admin.tick.interval": "500ms",
                 "distributed.scheduler.work-stealing": False}


def _local_cluster(n_workers: int, started: list) -> Any:
    """A LocalCluster of ``n_workers`` single-threaded processes, appended to ``started`` before this returns.

    Its workers preload :mod:`casflex.study._worker` (besides dask's configured preloads): they ignore SIGINT,
    which a Ctrl-C at a terminal sends to the whole process group, and this process handles by closing them.
    The workers are forked from the fork server (:mod:`casflex.study.fork_server`), which ignores SIGINT from its
    first module on, so that a worker does from its first moment. (A worker spawned, where there is no fork server
    or its nanny restarts it, ignores it from the preload, once it has imported dask, about a second in; under the
    ``casflex`` command, casflex._entry does it as soon as the worker's Python has started.)"""
    import dask
    from distributed import LocalCluster

    preload = dask.config.get("distributed.worker.preload") or []
    preload = [preload] if isinstance(preload, str) else list(preload)
    argv = dask.config.get("distributed.worker.preload-argv") or []
    argv = [argv] * len(preload) if argv and isinstance(argv[0], str) else list(argv) or [[]] * len(preload)
    from casflex.study.fork_server import changed_env, fork_server

    forked = fork_server()
    if forked:  # dask's get_mp_context would set its own list of modules for the server (this one is started)
        import distributed.utils

        distributed.utils._forkserver_preload_set = True
    method = {"distributed.worker.multiprocessing-method": "forkserver"} if forked else {}
    env = {"env": changed_env()} if forked else {}
    with dask.config.set({**QUIET_CLUSTER, **method}):
        started.append(LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, **env,
                                    dashboard_address=":0", silence_logs=40,
                                    preload=[*preload, "casflex.study._worker"], preload_argv=[*argv, []]))
    return started[-1]


def _close(client: Any, cluster: Any) -> None:
    """Close the client and the sweep's own cluster. Every finished run is recorded by then, so an error
    of dask's teardown is reported on stderr, not raised: on a busy machine a nanny still restarting
    the worker that a crashing run killed fails with "can only join a started process"."""
    for part in (client, cluster):
        try:
            if part is not None:
                part.close()
        except Exception as exc:  # noqa: BLE001 (any teardown error: the records are safe)
            print(f"casflex sweep: closing the {type(part).__name__} failed ({type(exc).__name__}: {exc}); "
                  "every finished run is recorded", file=sys.stderr)


class _NoWorkers(Exception):
    """The scheduler had no worker for NO_WORKERS_S: ``keys``, the runs not finished."""

    def __init__(self, keys: set[str]) -> None:
        super().__init__(f"{len(keys)} runs pending without workers")
        self.keys = keys


def _execute(client: Any, runs: list[Run], blobs: dict, finished: Callable[[str, dict], None], *, batch: int,
             last: bool = False) -> set[str]:
    """Run ``runs`` on ``client``, ``batch`` at a time, calling ``finished(key, record)`` as each
    completes; returns the keys of runs whose worker died (recorded as failed only when
    ``last``). Raises _NoWorkers when the scheduler has had no worker for NO_WORKERS_S while
    runs were pending. Ctrl-C cancels what is pending and propagates."""
    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    killed: set[str] = set()
    for i in range(0, len(runs), batch):
        part = runs[i:i + batch]  # one message to the scheduler for them all (client.submit sends one each)
        futures = dict(zip(client.map(_call, [blobs[r.fn] for r in part], [r.kwargs for r in part], pure=False,
                                      key=[f"casflex-{r.key}-{os.getpid()}-{last}" for r in part]),
                           [r.key for r in part], strict=True))
        # as_completed hands over each future as it finishes, where distributed.wait waited anew on every pending
        # future at each finished run (O(runs) a run, small beside dask's own work per task at 200 runs)
        pending, alone_since, checked, handled = as_completed(futures), None, time.monotonic(), set()
        try:
            while not pending.is_empty():
                done = pending.next_batch(block=False)
                if not done:
                    time.sleep(_WAKE_S)
                got = False
                for fut in done:
                    key = futures[fut]
                    try:
                        out = _result(fut.result(timeout=_POLL_S))
                    except TimeoutError:
                        # its result not fetched: lost with the worker that held it (a run that killed that worker
                        # next) and computed again, which needs a worker; waited for as a pending run, so that the
                        # watch below still sees a cluster left without one (a blocking result() waited forever)
                        pending.add(fut)
                        continue
                    except KilledWorker as exc:
                        out = {"error": f"KilledWorker: {exc}"} if last else None
                    except Exception as exc:  # noqa: BLE001 - any other failure of the run is its result
                        out = {"error": f"{type(exc).__name__}: {exc}"}
                    handled.add(fut)
                    got = True
                    if out is None:
                        killed.add(key)
                    else:
                        finished(key, out)
                if got:  # runs finish: workers there (a look at the scheduler's workers is a round trip through it)
                    alone_since, checked = None, time.monotonic()
                    continue
                if time.monotonic() - checked < _POLL_S:
                    continue
                checked = time.monotonic()
                # dask waits for workers forever: a cluster that lost them all would hang the sweep
                if client.nthreads():
                    alone_since = None
                elif alone_since is None:
                    alone_since = time.monotonic()
                elif time.monotonic() - alone_since > NO_WORKERS_S:
                    left = [f for f in futures if f not in handled]
                    client.cancel(left)
                    raise _NoWorkers({futures[f] for f in left} | {r.key for r in runs[i + batch:]} | killed)
        except KeyboardInterrupt:
            client.cancel(list(futures))
            raise
    return killed


def _text_progress(done: int, total: int, key: str) -> None:
    from casflex.interrupt import progress

    progress(f"  sweep: {done}/{total} runs  (last: {key[:40]})" + " " * 10, done, total, each=True)


@functools.lru_cache(maxsize=8)
def _setup(scene: str, t_end: float, noise: float, seed: int | None, data: str, method: str):
    """The model and the recording: the simulated set, or positions with noise. The direct methods take
    the measured set (central differences, from the second sample); the indirect method the noisy
    positions from the first, the scene's initial state (the measured set's first sample, one step
    into the motion, would start the model one step behind the data)."""
    from casflex.data import MeasurementSet, measured_set
    from casflex.model import assemble
    from casflex.scene.io import load_scene
    from casflex.simulate import simulated_set

    model = assemble(load_scene(scene))
    sim = simulated_set(model, t_end=t_end)
    if data != "measured" and noise <= 0:
        return model, sim
    if method == "indirect":
        q = sim.q + (np.random.default_rng(seed).normal(0.0, noise, sim.q.shape) if noise > 0 else 0.0)
        return model, MeasurementSet(sim.t, sim.channels, q, None, None, source="measured",
                                     meta={"noise": noise, "seed": seed, "from": sim.source})
    return model, measured_set(sim, noise=noise, seed=seed)


def identification_run(*, method: str, start: float, scene: str = "twobar", instants: tuple[float, ...] = (0.69,),
                       horizon: float = 0.69, t_end: float = 3.0, noise: float = 0.0, seed: int | None = None,
                       data: str = "simulated", **options: Any) -> dict:
    """One identification of a sweep (runs in a worker): returns the parameters, success,
    iterations, wall time, standard errors, the relative error against the nominal values
    and the weakly identifiable parameters. ``options``: the method's option values (``solver=Solver(...)``,
    ``shooting=Shooting(...)``, ...: :mod:`casflex.identification.options`)."""
    from casflex.identification import method_function

    identify = method_function(method)
    model, dat = _setup(scene, float(t_end), float(noise), seed, data, method)
    r = identify(model, dat, horizon, start=start, **options) if method == "indirect" else \
        identify(model, dat, list(instants), start=start, **options)
    rel = np.abs(r.p / model.p_nominal - 1.0)
    return {"parameters": r.parameters, "success": r.success, "status": r.status, "iterations": r.iterations,
            "wall_s": r.wall_s, "std_errors": r.std_errors, "max_rel_error": float(rel.max()),
            "weak": r.identifiability.get("weak", []), "method": method, "start": start, "noise": noise,
            "seed": seed}
