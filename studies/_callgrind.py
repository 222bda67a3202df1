"""Instructions per call of a compiled CasADi Function, counted by valgrind's callgrind: deterministic, unlike
wall or CPU time on a shared machine. A small C driver loads the library, calls the Function once to warm up and
once more, and callgrind counts the instructions inside the Function's symbol (its callees included)."""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

DRIVER = r"""
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
typedef long long int ci;
typedef int (*eval_t)(const double**, double**, ci*, double*, int);
typedef int (*work_t)(ci*, ci*, ci*, ci*);
typedef ci (*nio_t)(void);
typedef const ci* (*sp_t)(ci);
static ci nnz(const ci* sp) { return sp[2] ? sp[0] * sp[1] : sp[2 + sp[1]]; }
static void* sym(void* h, const char* f, const char* s) {
  char b[512]; snprintf(b, sizeof b, "%s%s", f, s); return dlsym(h, b);
}
int main(int argc, char** argv) {  /* drv LIB FUNC INPUT_FILE... */
  void* h = dlopen(argv[1], RTLD_NOW); if (!h) { fprintf(stderr, "%s\n", dlerror()); return 1; }
  const char* f = argv[2];
  eval_t ev = (eval_t)sym(h, f, ""); work_t wk = (work_t)sym(h, f, "_work");
  nio_t nin = (nio_t)sym(h, f, "_n_in"), nout = (nio_t)sym(h, f, "_n_out");
  sp_t spin = (sp_t)sym(h, f, "_sparsity_in"), spout = (sp_t)sym(h, f, "_sparsity_out");
  ci sa, sr, si, sw; wk(&sa, &sr, &si, &sw);
  const double** arg = calloc(sa, sizeof(double*)); double** res = calloc(sr, sizeof(double*));
  ci* iw = calloc(si + 1, sizeof(ci)); double* w = calloc(sw + 1, sizeof(double));
  for (ci i = 0; i < nin(); i++) {
    ci k = nnz(spin(i)); double* a = calloc(k + 1, sizeof(double));
    FILE* fp = fopen(argv[3 + i], "rb");
    if (!fp || (ci)fread(a, sizeof(double), k, fp) != k) { fprintf(stderr, "input %lld\n", i); return 1; }
    fclose(fp); arg[i] = a;
  }
  for (ci i = 0; i < nout(); i++) res[i] = calloc(nnz(spout(i)) + 1, sizeof(double));
  for (int r = 0; r < 2; r++) if (ev(arg, res, iw, w, 0)) return 1;
  return 0;
}
"""


def instructions(library: Path, name: str, args: list[np.ndarray]) -> float | None:
    """Instructions of one call of the Function ``name`` of the compiled ``library`` on the inputs ``args``
    (the mean of two calls); None without valgrind or a C compiler."""
    if shutil.which("valgrind") is None or shutil.which("gcc") is None:
        return None
    with tempfile.TemporaryDirectory(prefix="casflex-cg-") as tmp:
        src, drv = Path(tmp) / "drv.c", Path(tmp) / "drv"
        src.write_text(DRIVER)
        subprocess.run(["gcc", "-O2", "-o", str(drv), str(src), "-ldl"], check=True, capture_output=True)
        files = []
        for i, a in enumerate(args):
            files.append(str(Path(tmp) / f"in{i}.bin"))
            np.ascontiguousarray(a, dtype=float).ravel().tofile(files[-1])
        out = subprocess.run(["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null",
                              f"--toggle-collect={name}", str(drv), str(library), name, *files],
                             capture_output=True, text=True)
    found = re.search(r"Collected : (\d+)", out.stderr)
    return int(found.group(1)) / 2 if out.returncode == 0 and found else None


def _owners(c_file: Path) -> dict[int, str]:
    """Line of the generated C -> the CasADi Function it belongs to (the comment CasADi writes before each
    Function's code, ``/* name:(inputs)->(outputs) */``) or the runtime helper (casadi_copy, ...)."""
    owner, cur = {}, "runtime"
    for i, line in enumerate(c_file.read_text().splitlines(), 1):
        if found := re.match(r"/\* (\S+?):\(", line):
            cur = found.group(1)
        elif (found := re.match(r"(?:static |CASADI_SYMBOL_EXPORT )?(?:casadi_real|casadi_int|int|void) (casadi_\w+)\(",
                                line)) and not found.group(1).startswith("casadi_f"):
            cur = found.group(1)
        owner[i] = cur
    return owner


def per_function(c_file: Path, name: str, args: list[np.ndarray], flags: tuple[str, ...]) -> dict[str, float] | None:
    """Instructions of one call of ``name`` from the generated C ``c_file``, per CasADi Function of that C (the
    lines gcc inlined into a caller counted where they are written; built with ``flags`` plus -g) and per
    function of the libraries it calls ("ext:atan2", ...). None without valgrind or a C compiler."""
    if shutil.which("valgrind") is None or shutil.which("gcc") is None or shutil.which("callgrind_annotate") is None:
        return None
    with tempfile.TemporaryDirectory(prefix="casflex-cg-") as tmp:
        lib, drv, out = Path(tmp) / "lib.so", Path(tmp) / "drv", Path(tmp) / "cg.out"
        subprocess.run(["gcc", *flags, "-g", str(c_file), "-o", str(lib), "-lm"], check=True, capture_output=True)
        (Path(tmp) / "drv.c").write_text(DRIVER)
        subprocess.run(["gcc", "-O2", "-o", str(drv), str(Path(tmp) / "drv.c"), "-ldl"], check=True,
                       capture_output=True)
        files = []
        for i, a in enumerate(args):
            files.append(str(Path(tmp) / f"in{i}.bin"))
            np.ascontiguousarray(a, dtype=float).ravel().tofile(files[-1])
        subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", f"--toggle-collect={name}",
                        str(drv), str(lib), name, *files], check=True, capture_output=True)
        ann = subprocess.run(["callgrind_annotate", "--auto=yes", "--context=0", "--threshold=100",
                              "--show-percs=no", str(out)], capture_output=True, text=True, check=True).stdout
    owner, per, source, line = _owners(c_file), {}, False, None
    for text in ann.splitlines():
        if found := re.match(r"-- Auto-annotated source: (.*)", text):
            source = found.group(1).strip().endswith("lib.c")
        elif found := re.match(r"-- line (\d+) ", text):
            line = int(found.group(1))
        elif "events annotated" in text or "could not be found" in text:
            source = False
        elif source and line is not None and "=>" not in text and (found := re.match(r"\s*([\d,]+|\.)\s", text)):
            if found.group(1) != ".":  # a line's own instructions (a call's, "=>", are its callee's)
                per[owner.get(line, "?")] = per.get(owner.get(line, "?"), 0) + int(found.group(1).replace(",", ""))
            line += 1
        elif (found := re.match(r"\s*([\d,]+)\s+(\S+):(\S+)", text)) and "lib.c" not in found.group(2) \
                and "PROGRAM" not in text and not source:  # the summary's functions outside the library
            key = "ext:" + found.group(3).split("_fma")[0]
            per[key] = per.get(key, 0) + int(found.group(1).replace(",", ""))
    return {k: v / 2 for k, v in per.items()}  # the driver calls twice
