"""C code generation: export CasADi Functions to C, compile with the system C compiler, load.

Compiled libraries are cached by the SHA-256 of the generated source and the compiler
command, in ``$CASFLEX_CACHE`` (default ``~/.cache/casflex``); a library is built in a
temporary directory and renamed into the cache, so concurrent or interrupted builds never
leave a broken file behind.

``-ffp-contract=off`` (and ``-mno-fma`` beside ``-march=native``) keep the compiler from fusing
multiply-adds, so compiled results are bitwise identical to CasADi's interpreted evaluation on
x86-64. ``-march=native`` (where the compiler accepts it) makes twobar's compiled simulation ~15 %
faster; as the library is then tied to the processor, the processor's description is part of the
cache key.

CasADi's own JIT, which compiles an identification NLP's functions (``compiled=True``), is set
up by :func:`jit_options` in a per-process scratch directory.
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import hashlib
import logging
import os
import platform
import shutil
import subprocess
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from casflex.results import atomic_write_text

__all__ = ["BufferedCall", "CompiledLibrary", "compile_functions", "generate_c", "cache_dir", "CodegenError", "CFLAGS",
           "jit_options", "jit_working_directory"]

CFLAGS = ("-ffp-contract=off", "-fPIC", "-shared")

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


@functools.lru_cache(maxsize=4)
def _native_flags(cc: str) -> tuple[str, ...]:
    """The first of ("-march=native", "-mno-fma"), ("-march=native",), () that ``cc`` accepts; probed
    once per compiler and processor (a compile of ~35 ms), the answer kept in the cache directory.

    -mno-fma: gcc's SLP vectoriser fuses multiply-adds into FMA instructions even under
    -ffp-contract=off (gcc 12, x86-64 with FMA: one Jacobian entry of twobar's HHT step differed
    from CasADi's interpreted value in the last bit, and compiled runs drifted from interpreted ones).
    """
    note = cache_dir() / f"native2-{hashlib.sha256((cc + _processor()).encode()).hexdigest()[:16]}.txt"
    if note.is_file():
        return tuple(note.read_text().split())
    flags: tuple[str, ...] = ()
    with tempfile.TemporaryDirectory(prefix="casflex-cc-") as tmp:
        src = Path(tmp) / "t.c"
        src.write_text("int f(void) { return 0; }\n")
        for candidate in (("-march=native", "-mno-fma"), ("-march=native",)):
            proc = subprocess.run([cc, *candidate, "-c", str(src), "-o", str(Path(tmp) / "t.o")], capture_output=True)
            if proc.returncode == 0:
                flags = candidate
                break
    atomic_write_text(note, " ".join(flags))
    return flags


@functools.lru_cache(maxsize=1)
def _processor() -> str:
    """What -march=native compiles for: the model and feature flags of the first processor."""
    try:
        info = Path("/proc/cpuinfo").read_text(errors="replace").split("\n\n")[0]
    except OSError:
        info = ""
    keep = [ln for ln in info.splitlines() if ln.split(":")[0].strip() in ("model name", "flags", "Features",
                                                                             "CPU part", "CPU implementer")]
    return "\n".join(keep) or f"{platform.machine()} {platform.processor()}"


def compile_functions(functions: list[ca.Function], *, stem: str = "casflex", optimise: str = "-O3") -> CompiledLibrary:
    """Generate, compile (or take from the cache) and load ``functions``.

    ``optimise``: gcc's optimisation level. -O3 for code run millions of times (HHT steps); -O1
    for large code run a few dozen times per use (the sensitivities: twobar refined to 2 elements
    per bar compiles in 7 s instead of 60 s and runs 20 % slower).

    Returns a :class:`CompiledLibrary` whose ``functions`` map each name to a ``ca.external``.
    """
    t0 = time.perf_counter()
    cc = _compiler()
    with tempfile.TemporaryDirectory(prefix="casflex-cg-") as tmp:
        log.info("generating C for %s (%s)", stem, ", ".join(f.name() for f in functions))
        c_file, _ = generate_c(functions, tmp, stem)
        source = c_file.read_bytes()
        flags = (optimise, *CFLAGS, *_native_flags(cc))
        digest = hashlib.sha256(source + " ".join((cc, *flags, _processor())).encode()).hexdigest()[:24]
        target = cache_dir() / f"{stem}-{digest}.so"
        cached = target.is_file()
        if cached:
            log.info("using the compiled %s from the cache (%s)", stem, target)
        else:
            target.parent.mkdir(parents=True, exist_ok=True)
            built = Path(tmp) / f"{stem}.so"
            cmd = [cc, *flags, str(c_file), "-o", str(built), "-lm"]
            log.info("compiling %s.c (%d kB) with %s; the library is cached in %s for later runs",
                     stem, len(source) // 1024, cc, target.parent)
            proc = subprocess.run(cmd, capture_output=True, text=True)
            if proc.returncode != 0:
                raise CodegenError(f"compiling {stem}.c failed ({' '.join(cmd)}):\n{proc.stderr[-2000:]}")
            fd, tmp_target = tempfile.mkstemp(dir=target.parent, suffix=".so.tmp")
            os.close(fd)
            shutil.copyfile(built, tmp_target)
            os.replace(tmp_target, target)
            log.info("compiled %s in %.1f s", stem, time.perf_counter() - t0)
    loaded = {f.name(): ca.external(f.name(), str(target)) for f in functions}
    return CompiledLibrary(target, loaded, time.perf_counter() - t0, cached)


# -- CasADi's JIT (identification NLPs) ----------------------------------------------------
@functools.cache
def _jit_directory() -> str:
    """One scratch directory per process for the JIT's sources and objects (never the user's
    working directory), removed at exit; a loaded library survives the removal of its file."""
    path = tempfile.mkdtemp(prefix="casflex-jit-")
    atexit.register(shutil.rmtree, path, True)
    return path


@contextlib.contextmanager
def jit_working_directory(active: bool) -> Iterator[None]:
    """Run a block in the JIT scratch directory: CasADi 3.8 writes the source of an nlpsol's
    JIT-compiled oracle to the working directory whatever the compiler's ``directory`` option
    says (plain Functions honour it). Not thread-safe: the working directory is per process."""
    if not active:
        yield
        return
    old = os.getcwd()
    os.chdir(_jit_directory())
    try:
        yield
    finally:
        os.chdir(old)


def jit_options() -> dict:
    """Function/nlpsol options that generate C for every function the solver calls and compile
    it with the system compiler (CasADi's 'shell' JIT)."""
    return {"jit": True, "compiler": "shell", "jit_name": "casflex_jit",
            "jit_options": {"compiler": _compiler(), "flags": ["-O1"], "verbose": False,
                            "directory": _jit_directory()}}
