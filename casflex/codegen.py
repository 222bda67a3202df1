"""C code generation: export CasADi Functions to C, compile with the system C compiler, load.

Compiled libraries are cached by the SHA-256 of the generated source, the compiler, its flags and
the target they compile for, in ``$CASFLEX_CACHE`` (default ``~/.cache/casflex``); a library is
built in a temporary directory and renamed into the cache, so concurrent or interrupted builds
never leave a broken file behind.

The reproducibility contract (README, "Compiled and interpreted runs"):

- Every build gets ``-ffp-contract=off`` (no fused multiply-adds) and, by default, the compiler's
  generic target (no ``-march``): the compiled code then performs the same IEEE-754 operations in
  the same order as CasADi's interpreter, and a compiled run is bitwise the interpreted one on any
  x86-64 processor (:func:`bitwise_expected`). ``-march=native`` is not the default: gcc 12's
  vectoriser fuses multiply-adds for AVX2 and AVX-512 targets even under ``-ffp-contract=off``
  (and for AVX-512 even with ``-mno-fma``), which made compiled twobar runs differ from
  interpreted ones in the last bit on an AVX-512 Xeon.
- ``$CASFLEX_CFLAGS`` adds flags after casflex's own (a later ``-O`` or ``-march`` wins), e.g.
  ``-march=native`` for speed or ``-O0 -march=x86-64``. With flags beyond the optimisation level,
  tuning and FMA-free x86-64 targets, bitwise equality is not promised; what holds for any flags
  is that every compiled step solves the interpreted HHT equations to the Newton tolerance
  (tested in tests/test_codegen.py).
- The cache key holds what the library was compiled for (gcc's resolved target: ``-march`` and
  every instruction-set switch), so a cache shared by machines (a network home) never loads code
  built for another processor, while builds for the generic target are shared.

Everything casflex compiles goes through :func:`compile_functions`: simulation steps,
sensitivities, and the functions of identification NLPs (:func:`compiled`,
:func:`compiled_nlpsol`), so a later process pays no compile. The same directory keeps CasADi
Functions built (not compiled) from a model, which a later process loads instead of building them
again (:func:`load_built`, :func:`store_built`: the inverse's model and kinematic tree,
:mod:`casflex.inverse.built`). ``casflex cache`` shows the cache and ``casflex cache --clear``
empties it (:func:`clear_cache`).
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import logging
import os
import pickle
import platform
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
import zlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from casflex.results import atomic_write_bytes

__all__ = ["BufferedCall", "CompiledLibrary", "compile_functions", "compiled", "compiled_nlpsol", "generate_c",
           "cache_dir", "cache_entries", "built_entries", "clear_cache", "CodegenError", "CFLAGS", "FLAGS_ENV",
           "user_flags", "build_flags", "bitwise_expected", "built_key", "is_cached", "load_built", "store_built"]

#: Flags of every build: no fused multiply-adds (the interpreter has none), a shared library.
CFLAGS = ("-ffp-contract=off", "-fPIC", "-shared")
#: The environment variable whose flags (split like a shell) follow casflex's own in every build.
FLAGS_ENV = "CASFLEX_CFLAGS"
#: What ``casflex export`` writes (:func:`casflex.simulate.export.export_c`): here, where the command line's parser
#: takes them without importing the simulator.
EXPORTS = ("step", "simulate", "direct", "indirect")
#: Flags that keep the bitwise promise: optimisation level, tuning, debug information, and x86-64
#: targets without FMA instructions (x86-64, x86-64-v2).
_BITWISE_SAFE = re.compile(r"-O[0-3sg]?|-g[0-3]?|-pipe|-mtune=[\w.-]+|-march=x86-64(-v2)?|-mno-fma")

#: Progress of the long phases (code generation, compilation), at level INFO; the command line shows it.
log = logging.getLogger("casflex")


class CodegenError(RuntimeError):
    """The C compiler is missing or failed."""


def cache_dir() -> Path:
    return Path(os.environ.get("CASFLEX_CACHE", Path.home() / ".cache" / "casflex"))


def generate_c(functions: list[ca.Function], out_dir: str | os.PathLike[str], stem: str) -> tuple[Path, Path]:
    """Write ``<stem>.c`` and ``<stem>.h`` with all ``functions`` into ``out_dir``."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    cg = ca.CodeGenerator(f"{stem}.c", {"with_header": True})
    for f in functions:
        cg.add(f)
    cg.generate(str(out_dir) + os.sep)
    return out_dir / f"{stem}.c", out_dir / f"{stem}.h"


@dataclass(frozen=True)
class CompiledLibrary:
    """A compiled shared library and the Functions loaded from it."""

    path: Path
    functions: dict[str, ca.Function]
    build_s: float
    cached: bool

    def __getitem__(self, name: str) -> ca.Function:
        return self.functions[name]


class BufferedCall:
    """Evaluate a Function directly on numpy memory (CasADi's ``Function.buffer``).

    Converting numpy arrays to and from ``DM`` costs about as much as a compiled chunk of
    HHT steps; binding the arrays avoids it. Arrays must be float64 and C-contiguous; a
    matrix output (n x m) is written column-major, i.e. into a numpy array of shape (m, n).
    """

    def __init__(self, f: ca.Function):
        self.f = f
        self._buf, self._eval = f.buffer()
        self._n_in = [f.nnz_in(i) for i in range(f.n_in())]
        self._n_out = [f.nnz_out(i) for i in range(f.n_out())]

    def __call__(self, args: list, res: list) -> None:
        for i, a in enumerate(args):
            if a.dtype != np.float64 or not a.flags.c_contiguous or a.size != self._n_in[i]:
                raise ValueError(f"{self.f.name()}: input {i} needs {self._n_in[i]} contiguous float64 values")
            self._buf.set_arg(i, memoryview(a))
        for i, r in enumerate(res):
            if r.dtype != np.float64 or not r.flags.c_contiguous or r.size != self._n_out[i]:
                raise ValueError(f"{self.f.name()}: output {i} needs {self._n_out[i]} contiguous float64 values")
            self._buf.set_res(i, memoryview(r))
        self._eval()


def _compiler() -> str:
    cc = os.environ.get("CC", "gcc")
    if shutil.which(cc) is None:
        raise CodegenError(f"C compiler {cc!r} not found: install gcc (or set CC) to use compiled=True")
    return cc


def user_flags() -> tuple[str, ...]:
    """The flags of ``$CASFLEX_CFLAGS``, split like a shell would (empty when unset)."""
    try:
        return tuple(shlex.split(os.environ.get(FLAGS_ENV, "")))
    except ValueError as exc:
        raise CodegenError(f"{FLAGS_ENV}: cannot split {os.environ.get(FLAGS_ENV)!r} into flags ({exc})") from None


def bitwise_expected() -> bool:
    """Whether compiled code is promised bitwise equal to CasADi's interpreted evaluation: on x86-64,
    with no flag in ``$CASFLEX_CFLAGS`` beyond :data:`_BITWISE_SAFE` (the default build)."""
    return platform.machine() in ("x86_64", "AMD64") and all(_BITWISE_SAFE.fullmatch(f) for f in user_flags())


def build_flags(optimise: str, cc: str | None = None) -> tuple[str, ...]:
    """The flags of a build at ``optimise`` (e.g. "-O3"): casflex's, then ``$CASFLEX_CFLAGS``'s.
    The first call per compiler and flag set compiles an empty file with them (~30 ms): flags the
    compiler rejects raise :class:`CodegenError` naming ``$CASFLEX_CFLAGS``, before any work."""
    flags = (optimise, *CFLAGS, *user_flags())
    _target(cc or _compiler(), flags)
    return flags


@functools.lru_cache(maxsize=16)
def _target(cc: str, flags: tuple[str, ...]) -> str:
    """What ``cc`` with ``flags`` compiles for, part of every cache key: gcc's ``-Q --help=target``
    (the resolved -march, e.g. "rocketlake" for native, and every instruction-set switch), or, for a
    compiler without it, the processor's description when a flag names the native target."""
    with tempfile.TemporaryDirectory(prefix="casflex-cc-") as tmp:
        src = Path(tmp) / "t.c"
        src.write_text("int f(void) { return 0; }\n")
        proc = subprocess.run([cc, *flags, "-c", str(src), "-o", str(Path(tmp) / "t.o")], capture_output=True,
                              text=True)
    if proc.returncode != 0:
        why = (proc.stderr.strip().splitlines() or ["no message"])[0]
        raise CodegenError(f"{FLAGS_ENV}={os.environ.get(FLAGS_ENV, '')!r}: the C compiler {cc!r} rejects the "
                           f"flags {' '.join(flags)!r}: {why}")
    try:
        q = subprocess.run([cc, *flags, "-Q", "--help=target"], capture_output=True, text=True, timeout=60)
        described = q.stdout if q.returncode == 0 and "-march=" in q.stdout else ""
    except (OSError, subprocess.SubprocessError):
        described = ""
    if not described and any("native" in f for f in flags):
        described = _processor()
    return described or platform.machine()


@functools.lru_cache(maxsize=1)
def _processor() -> str:
    """The model and feature flags of the first processor (for compilers that cannot describe -march=native)."""
    try:
        info = Path("/proc/cpuinfo").read_text(errors="replace").split("\n\n")[0]
    except OSError:
        info = ""
    keep = [ln for ln in info.splitlines() if ln.split(":")[0].strip() in ("model name", "flags", "Features",
                                                                             "CPU part", "CPU implementer")]
    return "\n".join(keep) or f"{platform.machine()} {platform.processor()}"


@functools.lru_cache(maxsize=4)
def _compiler_identity(cc: str) -> str:
    """``cc --version``'s first line: part of the cache key, so a new compiler builds anew."""
    try:
        proc = subprocess.run([cc, "--version"], capture_output=True, text=True, timeout=30)
        return (proc.stdout.splitlines() or [""])[0]
    except (OSError, subprocess.SubprocessError):
        return ""


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    """An exclusive lock on ``path`` (created if needed) for the block: concurrent processes that
    want the same library wait for the one that builds it instead of building it again."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as fh:
        try:
            import fcntl

            fcntl.flock(fh, fcntl.LOCK_EX)
        except (ImportError, OSError):  # no advisory locks here: the atomic rename still keeps the cache sound
            pass
        yield


def compile_functions(functions: list[ca.Function], *, stem: str = "casflex", optimise: str = "-O3",
                      key: str | None = None) -> CompiledLibrary:
    """Generate, compile (or take from the cache) and load ``functions``.

    ``optimise``: gcc's optimisation level. -O3 for code run millions of times (HHT steps); -O1
    for large code run a few dozen times per use (sensitivities, NLP functions).

    The cache key is the SHA-256 of the generated source, the compiler (command and version),
    its flags and the processor, or ``key`` when the caller has one that identifies the functions
    before they are generated (:func:`compiled_nlpsol`). A library is built in a temporary directory and renamed into
    the cache under a lock, so concurrent processes build it once and never see a partial file.
    Returns a :class:`CompiledLibrary` whose ``functions`` map each name to a ``ca.external``.
    """
    t0 = time.perf_counter()
    cc = _compiler()
    with tempfile.TemporaryDirectory(prefix="casflex-cg-") as tmp:
        log.info("generating C for %s (%s)", stem, ", ".join(f.name() for f in functions))
        c_file, _ = generate_c(functions, tmp, stem)
        source = c_file.read_bytes()
        flags = build_flags(optimise, cc)
        digest = key or _digest(source, cc, flags)
        target = cache_dir() / f"{stem}-{digest}.so"
        cached = target.is_file()
        if not cached:
            with _locked(cache_dir() / f".{stem}-{digest}.lock"):
                cached = target.is_file()  # built by another process while this one waited
                if not cached:
                    _build(cc, flags, c_file, Path(tmp) / f"{stem}.so", target, stem, len(source))
        if cached:
            log.info("using the compiled %s from the cache (%s)", stem, target)
        else:
            log.info("compiled %s in %.1f s (once: cached in %s)", stem, time.perf_counter() - t0, target.parent)
    loaded = {f.name(): ca.external(f.name(), str(target)) for f in functions}
    return CompiledLibrary(target, loaded, time.perf_counter() - t0, cached)


def _digest(source: bytes, cc: str, flags: tuple[str, ...]) -> str:
    """The cache key of a library compiled from ``source`` by ``cc`` with ``flags`` (see :func:`compile_functions`)."""
    build = " ".join((cc, _compiler_identity(cc), *flags, _target(cc, flags)))
    return hashlib.sha256(source + build.encode()).hexdigest()[:24]


def is_cached(functions: list[ca.Function], *, stem: str = "casflex", optimise: str = "-O3") -> bool:
    """Whether :func:`compile_functions` (same arguments) would load ``functions`` from the cache without
    compiling: their C is generated (tens of ms: twobar's HHT library, 170 kB, in 35 ms) for its key, nothing is
    compiled. False when there is no C compiler or it rejects ``$CASFLEX_CFLAGS``."""
    try:
        cc = _compiler()
        flags = build_flags(optimise, cc)
    except CodegenError:
        return False
    with tempfile.TemporaryDirectory(prefix="casflex-cg-") as tmp:
        source = generate_c(functions, tmp, stem)[0].read_bytes()
    return (cache_dir() / f"{stem}-{_digest(source, cc, flags)}.so").is_file()


def _build(cc: str, flags: tuple[str, ...], c_file: Path, built: Path, target: Path, stem: str, size: int) -> None:
    cmd = [cc, *flags, str(c_file), "-o", str(built), "-lm"]
    log.info("building %s.c (%d kB) with %s: once, the library is cached for later runs", stem, size // 1024, cc)
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise CodegenError(f"compiling {stem}.c failed ({' '.join(cmd)}):\n{proc.stderr[-2000:]}")
    # the shared atomic write (its temporary file removed on any failure, a Ctrl-C too); not flushed to the disk, as
    # before (a library a power cut left short fails to load, naming its file: `casflex cache --clear` removes it)
    atomic_write_bytes(target, built.read_bytes(), durable=False)


def compiled(f: ca.Function, *, optimise: str = "-O1") -> ca.Function:
    """``f`` generated as C, compiled (or taken from the cache) and loaded: same inputs, outputs
    and numbers."""
    return compile_functions([f], stem=f.name(), optimise=optimise)[f.name()]


def compiled_nlpsol(name: str, plugin: str, nlp: dict, opts: dict, *, interpreted: ca.Function | None = None,
                    extra: Sequence[ca.Function] = (),
                    replace: Callable[[str, ca.Function], ca.Function] | None = None,
                    ) -> ca.Function | tuple[ca.Function, dict[str, ca.Function]]:
    """``ca.nlpsol(name, plugin, nlp, opts)`` with every function the solver evaluates compiled
    (gcc -O1) and cached on disk: the solver is set up interpreted, its functions (the NLP and the
    derivatives it asked for, those given as options such as ``hess_lag`` included) are generated as
    one C library, and the solver is made anew on that library (CasADi's documented route for
    compiled NLPs).

    A later process finds the library by the NLP itself (its serialised expressions, the options and
    the Functions given as options, CasADi's version), before any set-up: for twobar's multiple
    shooting over 0.69 s the set-up alone took 7 s. ``interpreted``: the solver already set up;
    ``replace(name, f)``: the Function to compile in the solver's ``f`` of that name (its own, or one
    that derives less); ``extra``: further Functions in the same library, returned beside the solver
    as {name: compiled Function} (then the result is that pair).
    """
    sym = ca.MX if isinstance(nlp["x"], ca.MX) else ca.SX
    p = nlp.get("p", sym(0, 1))
    problem = ca.Function("nlp", [nlp["x"], p], [nlp.get("f", 0), nlp.get("g", sym(0, 1))])
    fn_opts = {k: v for k, v in opts.items() if isinstance(v, ca.Function)}
    lib_opts = {k: v for k, v in opts.items() if k not in fn_opts}
    cc = _compiler()
    flags = build_flags("-O1", cc)
    key = hashlib.sha256("\n".join([
        problem.serialize(), *(f"{k}: {fn_opts[k].serialize()}" for k in sorted(fn_opts)),
        *(f.serialize() for f in extra), "" if replace is None else "replaced",
        plugin, repr(sorted(lib_opts.items(), key=str)), ca.__version__, cc, _compiler_identity(cc), *flags,
        _target(cc, flags)]).encode()).hexdigest()[:24]
    target = cache_dir() / f"{name}_nlp-{key}.so"
    if target.is_file():
        log.info("using the compiled %s NLP from the cache (%s)", name, target)
    else:
        interpreted = interpreted if interpreted is not None else ca.nlpsol(name, plugin, nlp, opts)
        funcs = [interpreted.oracle()]
        for fname in interpreted.get_function():
            f = interpreted.get_function(fname)
            if replace is not None:
                f = replace(fname, f)
            if f.name() != fname:  # a Function given as an option: the library must hold it under the name sought
                args = f.mx_in()
                f = ca.Function(fname, args, f.call(args), f.name_in(), f.name_out())
            funcs.append(f)
        target = compile_functions(funcs + list(extra), stem=f"{name}_nlp", optimise="-O1", key=key).path
    solver = ca.nlpsol(name, plugin, str(target), lib_opts)
    if not extra:
        return solver
    return solver, {f.name(): ca.external(f.name(), str(target)) for f in extra}


#: A built entry's file: its first line is this and the SHA-256 of the rest (the pickled value), which is read
#: only when they agree: a truncated or damaged file is rebuilt, never fed to the unpickler.
BUILT_SUFFIX, _BUILT_HEAD = ".built", b"casflex-built 1 "
#: The built entries the cache keeps: beyond, a store removes those used longest ago (their files' times, renewed
#: by each load): entries of scenes no longer run and of casflex's earlier code (a new key) do not pile up
#: (Hamner's model's is 131 kB; 256 of them 34 MB).
MAX_BUILT = 256


def built_key(*parts: str) -> str:
    """The cache key (24 hex digits) of an entry built from ``parts`` (the content it is made of and the code
    that makes it, the caller's) and of what else its build and its loading depend on: CasADi's, numpy's and
    Python's versions, the machine and its C library (whose cos and sin gave the constants a build folds in)."""
    where = (ca.__version__, np.__version__, sys.version, platform.machine(), _libc())
    return hashlib.sha256("\n".join((*parts, *where)).encode()).hexdigest()[:24]


@functools.lru_cache(maxsize=1)
def _libc() -> str:
    try:
        return os.confstr("CS_GNU_LIBC_VERSION") or ""
    except (AttributeError, ValueError, OSError):  # not a GNU system: its platform string
        return platform.platform()


def _built_path(stem: str, key: str) -> Path:
    return cache_dir() / f"{stem}-{key}{BUILT_SUFFIX}"


def load_built(stem: str, key: str) -> object | None:
    """The value :func:`store_built` kept under ``stem`` and ``key``, or None where there is none or it cannot
    be read whole (truncated, damaged, unreadable, or not unpickled): the caller builds it again and stores it,
    replacing the bad file. Values are pickled (a CasADi Function by its own serialisation): the cache is the
    user's, as are the compiled libraries beside it, which run as code."""
    path = _built_path(stem, key)
    try:
        data = path.read_bytes()
    except OSError:
        return None
    head, _, body = data.partition(b"\n")
    if head != _BUILT_HEAD + hashlib.sha256(body).hexdigest().encode():
        log.info("%s: damaged (its checksum disagrees): built again", path)
        return None
    try:
        value = pickle.loads(zlib.decompress(body))
    except Exception as exc:  # noqa: BLE001 - any failure to read the entry back means: build it again
        log.info("%s: not read (%s): built again", path, exc)
        return None
    with contextlib.suppress(OSError):  # used now: the last the cache's bound removes (a read-only cache: kept as is)
        os.utime(path)
    return value


def store_built(stem: str, key: str, value: object) -> None:
    """Keep ``value`` (pickled, zlib-compressed) under ``stem`` and ``key`` in the cache, written atomically
    (:func:`casflex.results.atomic_write_bytes`: a reader sees a whole file or none, whoever writes it at the same
    time or stops half-way, a Ctrl-C), not flushed to the disk: a damaged entry is built again (:func:`load_built`
    checks its checksum). A cache that cannot be written (read-only, full) is passed over: the next run builds
    again."""
    body = zlib.compress(pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL), 1)  # 1/6 of the size, 5 ms to read
    path = _built_path(stem, key)
    try:
        atomic_write_bytes(path, _BUILT_HEAD + hashlib.sha256(body).hexdigest().encode() + b"\n" + body,
                           durable=False)
        _bound_built(path.parent)
    except OSError as exc:
        log.info("%s: not written (%s): the next run builds it again", path, exc)


def _bound_built(d: Path) -> None:
    """The built entries in ``d`` beyond :data:`MAX_BUILT` removed, those used longest ago first (another process
    reading one meanwhile finds none and builds it again)."""
    entries = []
    for f in d.glob(f"*{BUILT_SUFFIX}"):
        with contextlib.suppress(OSError):
            entries.append((f.stat().st_mtime, f))
    for _, f in sorted(entries)[:max(0, len(entries) - MAX_BUILT)]:
        with contextlib.suppress(OSError):
            f.unlink()


def cache_entries() -> list[Path]:
    """The compiled libraries in the cache directory."""
    d = cache_dir()
    return sorted(d.glob("*.so")) if d.is_dir() else []


def built_entries() -> list[Path]:
    """The built Functions' files in the cache directory (:func:`store_built`)."""
    d = cache_dir()
    return sorted(d.glob(f"*{BUILT_SUFFIX}")) if d.is_dir() else []


def clear_cache() -> tuple[int, int]:
    """Remove every compiled library and built entry (and lock, probe and temporary file) from the cache:
    (files, bytes)."""
    count = size = 0
    d = cache_dir()
    if not d.is_dir():
        return 0, 0
    for f in [*d.glob("*.so"), *d.glob(".*.lock"), *d.glob("native*.txt"), *d.glob("*.so.tmp"),
              *d.glob(f"*{BUILT_SUFFIX}"), *d.glob(f".*{BUILT_SUFFIX}.*.tmp")]:
        try:  # a file another process renames or removes meanwhile is not this one's to count
            size += f.stat().st_size
            f.unlink()
        except FileNotFoundError:
            continue
        count += 1
    return count, size
