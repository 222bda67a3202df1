"""Export a scene's model as standalone C: generated sources, a header, a Makefile, an example.

``export_c(model, out_dir, what=...)`` writes into ``out_dir``:

- ``casflex_model.c`` / ``casflex_model.h``: CasADi-generated C of the Functions below
  (dependency-free, C99, link with -lm);
- ``Makefile``: builds ``libcasflex_model.a`` and, for ``simulate``, the example program;
- ``main.c`` (``simulate`` only): runs the scene's HHT simulation and writes ``trajectory.csv``
  (columns t, then every dof, in ``model.dof_names`` order, 17 significant digits);
- ``README.md``: what each function computes, its inputs and outputs with shapes and units.

``what``:

- ``step``: ``hht_step(x0, t0, p, h, d) -> (x1, res)`` (one HHT-alpha step, Eqs. 4-10),
  ``hht_initial(q, qd, t, p) -> (qdd, lam)`` (consistent start), ``hht_scale(q, qd, p, h) -> d``
  (Newton scaling), ``hht_post(x, t, p) -> y`` (energies, powers, joint outputs, local rotations);
- ``simulate``: the same plus ``main.c``;
- ``direct``: ``equilibrium(q, qd, qdd, lam, t, p) -> (r, phi)`` (Eq. 1, the residual of the
  direct method, Eq. 11) and ``jac_equilibrium`` (its exact Jacobian in every input);
- ``indirect``: ``hht_step`` and ``jac_hht_step`` (dx1/d(x0, t0, p, h) by the implicit-function
  theorem: the sensitivities output-error identification chains through a trajectory).
"""

from __future__ import annotations

import os
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from casflex.codegen import EXPORTS, CodegenError, generate_c
from casflex.model import Model
from casflex.results import atomic_write_text
from casflex.simulate.run import step_count

__all__ = ["export_c", "ExportedCode", "EXPORTS"]

STEM = "casflex_model"


@dataclass(frozen=True)
class ExportedCode:
    """Paths of an export; ``build()`` compiles it there."""

    out_dir: Path
    files: tuple[Path, ...]
    functions: tuple[str, ...]
    what: str

    def build(self) -> Path:
        """Compile as the Makefile does (the C compiler directly, so make is not needed):
        returns the example program (``simulate``) or the static library."""
        cc = os.environ.get("CC", "gcc")
        if shutil.which(cc) is None:
            raise CodegenError(f"building the export needs a C compiler: {cc!r} not found (install gcc or set CC)")
        flags = ["-O2", "-ffp-contract=off"]
        d = self.out_dir
        cmds = [[cc, *flags, "-c", f"{STEM}.c", "-o", f"{STEM}.o"], ["ar", "rcs", f"lib{STEM}.a", f"{STEM}.o"]]
        if self.what == "simulate":
            cmds.append([cc, *flags, "main.c", f"lib{STEM}.a", "-lm", "-o", "simulate"])
        for cmd in cmds:
            proc = subprocess.run(cmd, cwd=d, capture_output=True, text=True)
            if proc.returncode != 0:
                raise CodegenError(f"building the export in {d} failed ({' '.join(cmd)}):\n{proc.stderr[-2000:]}")
        return d / ("simulate" if self.what == "simulate" else f"lib{STEM}.a")


def _functions(model: Model, what: str, alpha: float, tol: float) -> list[ca.Function]:
    from casflex.simulate.run import integrator_for

    integ = integrator_for(model, alpha=alpha, tol=tol)
    if what in ("step", "simulate"):
        return [integ.step, integ.initial, integ.scale, integ.post]
    if what == "direct":
        eq = model.equilibrium
        return [eq, eq.jacobian()]
    step = integ.step
    return [step, step.jacobian()]


def export_c(model: Model, out_dir: str | os.PathLike[str], *, what: str = "simulate", alpha: float | None = None,
             dt: float | None = None, t_end: float | None = None, p: np.ndarray | dict | None = None,
             tol: float = 1e-12, names: tuple[str, str] = ("t_end", "dt")) -> ExportedCode:
    """Write the C export of ``model`` into ``out_dir`` (see the module docstring).

    alpha, dt, t_end default to the scene's run settings; p (parameters baked into the
    example) to the nominal values; tol is the HHT Newton tolerance compiled into the step;
    ``names`` are how errors call t_end and dt.
    """
    if what not in EXPORTS:
        raise ValueError(f"what: expected one of {EXPORTS}, got {what!r}")
    run = model.scene.run
    alpha = float(run.alpha if alpha is None else alpha)
    dt = float(run.dt if dt is None else dt)
    t_end = float(run.t_end if t_end is None else t_end)
    n_steps = step_count(t_end, dt, names=names)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    funcs = _functions(model, what, alpha, tol)
    c_file, h_file = generate_c(funcs, out, STEM)
    files = [c_file, h_file]
    names = tuple(f.name() for f in funcs)
    files.append(atomic_write_text(out / "Makefile", _makefile(what)))
    if what == "simulate":
        files.append(atomic_write_text(out / "main.c", _main_c(model, model.params(p), alpha, dt, n_steps)))
    files.append(atomic_write_text(out / "README.md", _readme(model, funcs, what, alpha, dt, t_end, tol)))
    return ExportedCode(out, tuple(files), names, what)


def _makefile(what: str) -> str:
    lines = ["CC ?= gcc", "CFLAGS ?= -O2 -ffp-contract=off", "",
             f"all: lib{STEM}.a" + (" simulate" if what == "simulate" else ""), "",
             f"lib{STEM}.a: {STEM}.c {STEM}.h", f"\t$(CC) $(CFLAGS) -c {STEM}.c -o {STEM}.o",
             f"\tar rcs $@ {STEM}.o", ""]
    if what == "simulate":
        lines += [f"simulate: main.c lib{STEM}.a", f"\t$(CC) $(CFLAGS) main.c lib{STEM}.a -lm -o $@", ""]
    lines += ["clean:", f"\trm -f {STEM}.o lib{STEM}.a simulate trajectory.csv", "", ".PHONY: all clean", ""]
    return "\n".join(lines)


def _c_array(name: str, v: np.ndarray) -> str:
    vals = ", ".join(f"{x:.17g}" for x in np.asarray(v, dtype=float).ravel()) or "0"
    return f"static const casadi_real {name}[{max(v.size, 1)}] = {{{vals}}};"


def _main_c(model: Model, p: np.ndarray, alpha: float, dt: float, n_steps: int) -> str:
    from casflex.simulate.run import initial_state, integrator_for

    n, nc = model.n_dof, model.n_con
    # the start simulate() takes: moving supports on their paths, the joints closed (casflex.model.consistent)
    x0 = initial_state(integrator_for(model, alpha=alpha), p)
    header = "t," + ",".join(model.dof_names)
    return f"""/* Example: simulate scene '{model.scene.name}' with HHT-alpha (alpha = {alpha:g}), dt = {dt:g} s,
   {n_steps} steps; writes trajectory.csv (t, then the dofs {', '.join(model.dof_names[:3])}, ...).
   Generated by casflex. Build: make; run: ./simulate [output.csv] */
#include <stdio.h>
#include <stdlib.h>
#include "{STEM}.h"

#define N_DOF {n}
#define N_CON {nc}
#define NX (3 * N_DOF + N_CON)
#define N_STEPS {n_steps}
{_c_array("Q0", x0[:n])}
{_c_array("QD0", x0[n:2 * n])}
{_c_array("P", p)}
static const casadi_real DT = {dt:.17g};

typedef int (*eval_t)(const casadi_real**, casadi_real**, casadi_int*, casadi_real*, int);
typedef int (*work_t)(casadi_int*, casadi_int*, casadi_int*, casadi_int*);
typedef int (*checkout_t)(void);
typedef void (*release_t)(int);

/* Evaluate a generated function with freshly allocated work memory. */
static int call(eval_t f, work_t work, checkout_t co, release_t rel, const casadi_real** in, casadi_real** out) {{
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real** arg = malloc((sz_arg + 1) * sizeof(casadi_real*));
  casadi_real** res = malloc((sz_res + 1) * sizeof(casadi_real*));
  casadi_int* iw = malloc((sz_iw + 1) * sizeof(casadi_int));
  casadi_real* w = malloc((sz_w + 1) * sizeof(casadi_real));
  for (casadi_int i = 0; i < sz_arg; ++i) arg[i] = in[i];
  for (casadi_int i = 0; i < sz_res; ++i) res[i] = out[i];
  int mem = co();
  int flag = f(arg, res, iw, w, mem);
  rel(mem);
  free(arg); free(res); free(iw); free(w);
  return flag;
}}

int main(int argc, char** argv) {{
  const char* path = argc > 1 ? argv[1] : "trajectory.csv";
  static casadi_real x[NX], x1[NX], d[N_DOF];
  casadi_real t = 0, res = 0, zero = 0, h = DT;
  for (int i = 0; i < N_DOF; ++i) {{ x[i] = Q0[i]; x[N_DOF + i] = QD0[i]; }}
  {{ /* consistent accelerations and multipliers, then the Newton scaling */
    const casadi_real* in[] = {{Q0, QD0, &zero, P}};
    casadi_real* out[] = {{x + 2 * N_DOF, x + 3 * N_DOF}};
    if (call(hht_initial, hht_initial_work, hht_initial_checkout, hht_initial_release, in, out)) return 1;
    const casadi_real* in2[] = {{Q0, QD0, P, &h}};
    casadi_real* out2[] = {{d}};
    if (call(hht_scale, hht_scale_work, hht_scale_checkout, hht_scale_release, in2, out2)) return 1;
  }}
  FILE* fp = fopen(path, "w");
  if (!fp) {{ fprintf(stderr, "cannot write %s\\n", path); return 1; }}
  fprintf(fp, "{header}\\n");
  for (int k = 0; k <= N_STEPS; ++k) {{
    fprintf(fp, "%.17g", t);
    for (int i = 0; i < N_DOF; ++i) fprintf(fp, ",%.17g", x[i]);
    fprintf(fp, "\\n");
    if (k == N_STEPS) break;
    const casadi_real* in[] = {{x, &t, P, &h, d}};
    casadi_real* out[] = {{x1, &res}};
    if (call(hht_step, hht_step_work, hht_step_checkout, hht_step_release, in, out) || !(res <= 1e-6)) {{
      fprintf(stderr, "step %d (t = %g s) failed: scaled Newton residual %g\\n", k, t, res);
      fclose(fp);
      return 2;
    }}
    for (int i = 0; i < NX; ++i) x[i] = x1[i];
    t = (k + 1) * DT;
  }}
  fclose(fp);
  return 0;
}}
"""


def _readme(model: Model, funcs: list[ca.Function], what: str, alpha: float, dt: float, t_end: float,
            tol: float) -> str:
    lines = [f"# C export of scene `{model.scene.name}` ({what})", "",
             f"Generated by casflex. HHT alpha = {alpha:g}, Newton tolerance {tol:g} (scaled), "
             f"example step dt = {dt:g} s over {t_end:g} s.", "",
             f"dofs (n = {model.n_dof}): {', '.join(model.dof_names)}", "",
             f"multipliers (m = {model.n_con}): {', '.join(model.constraint_names)}", "",
             f"parameters p ({model.n_p}): {', '.join(model.parameter_names)}", "",
             "States x = [q, qd, qdd, lambda] (3 n + m). Units SI (m, rad, s, N, N m).", "",
             "Build: `make` (CC and CFLAGS may be overridden).", "", "## Functions", ""]
    for f in funcs:
        ins = ", ".join(f"{f.name_in(i)}[{f.size1_in(i)}x{f.size2_in(i)}]" for i in range(f.n_in()))
        outs = ", ".join(f"{f.name_out(i)}[{f.size1_out(i)}x{f.size2_out(i)}]" for i in range(f.n_out()))
        lines.append(f"- `{f.name()}({ins}) -> ({outs})`")
    if any(f.name() == "hht_post" for f in funcs):
        lines += ["", "`hht_post` y = [kinetic, elastic, gravity energy (J), power of the loads (W), power "
                  "dissipated by the dampers (W), joint outputs ("
                  + ", ".join(model.output_names) + "), local rotations of the beam elements in rad ("
                  + ", ".join(model.local_rotation_names) + ")]."]
    lines += ["", "Outputs are column-major and dense unless the header's sparsity says otherwise "
              "(see `<name>_sparsity_out`).", ""]
    return "\n".join(lines)
