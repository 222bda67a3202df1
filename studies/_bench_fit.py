"""Identification against simulation, measured side by side in one process (bench_identification's second part).

Every operation is timed in one warm process (compiled code on disk, in-process caches filled by a first
call), best of ``REPEAT`` calls, interleaved so that a drifting host slows all alike; a fit's cost is also
given in simulations of the same scene over the same span (its wall time over the simulation's). Instruction
counts come from valgrind's callgrind: a process that does the set-up and the operation once, and one that
does it 1 + CALLS times; their difference over CALLS is one operation's instructions, whatever the host's load.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from _shared import exudyn_recording

REPEAT = 5
NOISE, SEED, START, SPAN, DT = 5e-4, 0, 0.8, 3.0, 1e-3
MARKERS = {"twobar": ("x3", "y3", "x5", "y5"), "threelink": ("x3", "y3", "x5", "y5", "x7", "y7")}
#: the default fit's uncertain properties (issue 37): both bars' densities (5 %) and moduli (3 %), as
#: studies/uncertain.py declares them: (target, relative standard deviation)
UNCERTAIN = (("bar2.rho", 0.05), ("bar4.rho", 0.05), ("bar2.E", 0.03), ("bar4.E", 0.03))
#: the ways before issue 49, switched off in casflex.identification.output_error for a row: "chord" (the model-error
#: refit and the alternative forms' rejection by chord steps on the fit's Jacobian, CHORD_STEPS) and "continue" (each
#: growing-horizon stage's first run carried on from the last stage's, CONTINUE_STAGES)
BEFORE = {"chord": "CHORD_STEPS", "continue": "CONTINUE_STAGES"}
#: name: (scene, elements per bar or None, identify_indirect's Uncertainty fields or None for a simulation; the key
#: "before" lists the BEFORE switches off)
OPS = {
    "simulation, 3 s": ("twobar", None, None),
    "model run without sensitivities, 3 s": ("twobar", None, "states"),
    "model run with sensitivities (4 directions), 3 s": ("twobar", None, "sensitivities"),
    "default fit": ("twobar", None, {}),
    "default fit as before issue 49 (exact refits, every stage from t0)": (
        "twobar", None, {"before": ("chord", "continue")}),
    "default fit without chord steps (exact refits)": ("twobar", None, {"before": ("chord",)}),
    "default fit without continued stages": ("twobar", None, {"before": ("continue",)}),
    "without model-error refit": ("twobar", None, {"model_error": "none"}),
    "without model-error refit or form comparison": ("twobar", None, {"model_error": "none", "form": "none"}),
    "default fit, 4 uncertain properties": ("twobar", None, {"uncertain": UNCERTAIN}),
}
#: the default fit's variants compared with the way before (BEFORE), to 1/100 of a noise SE
AS_BEFORE = "default fit as before issue 49 (exact refits, every stage from t0)"
#: the reference for the estimates: every stage of the growing horizon to the full tolerance (the way before)
REFERENCE = {"model_error": "none", "form": "none"}
#: the operation whose options the reference shares (timed in turn with the others, est.STAGE_SE off)
REFERENCE_OPS = ("without model-error refit or form comparison",)
MESH = (1, 2, 4, 8)
CALLGRIND = ("simulation, 3 s", "model run with sensitivities (4 directions), 3 s", "default fit", AS_BEFORE,
             "without model-error refit", "without model-error refit or form comparison",
             "default fit, 4 uncertain properties")


def _model(scene: str, elements: int | None):
    import dataclasses

    import casflex

    sc = casflex.load_scene(scene)
    if elements is not None:
        sc = dataclasses.replace(sc, beams=tuple(dataclasses.replace(b, elements=elements) for b in sc.beams))
    return casflex.assemble(sc)


def _leg_data():
    import leg

    from casflex.data import MeasurementSet

    t, q, _ = leg._truth(2.2)
    return MeasurementSet(t, tuple(f"{c}{m}" for m in leg.MARKERS for c in "xy"),
                          q + np.random.default_rng(SEED).normal(0, leg.NOISE, q.shape), None, None)


def operation(scene: str, elements: int | None, what):
    """A zero-argument callable doing the operation once, and the scene's 3 s simulation as another."""
    from casflex.identification import Experiment, ModelRun, Uncertainty, identify_indirect
    from casflex.identification.sensitivity import run_sensitivities, run_states
    from casflex.simulate import Stepping, initial_state, integrator_for, simulate

    model = _model(scene, elements)
    span = 2.2 if scene == "leg" else SPAN

    def sim():
        return simulate(model, span, stepping=Stepping(dt=DT, compiled=True))

    if what is None:
        return sim, sim
    if what in ("sensitivities", "states"):
        integ = integrator_for(model, alpha=model.scene.run.alpha)
        x0, n = initial_state(integ, model.p_nominal), int(round(span / DT))
        seed = (np.zeros((integ.nx, model.n_p)), np.eye(model.n_p))
        if what == "states":
            return (lambda: run_states(integ, x0, model.p_nominal, 0.0, DT, n, np.arange(0, n + 1, 10))), sim
        return (lambda: run_sensitivities(integ, x0, model.p_nominal, 0.0, DT, n, np.arange(0, n + 1, 10),
                                          seed=seed)), sim
    data = (_leg_data() if scene == "leg"
            else exudyn_recording(f"{scene}_exudyn", MARKERS[scene], 0.0, span, NOISE, SEED))
    exp, start = (Experiment(data), 0.7) if scene == "leg" else (Experiment(data, noise=NOISE), START)
    if "uncertain" in what:
        from casflex.scene import Uncertain

        what = {**what, "uncertain": [Uncertain(t, relative=r) for t, r in what["uncertain"]]}
    before = what.get("before", ())
    what = {k: v for k, v in what.items() if k != "before"}

    def fit():
        import casflex.identification.output_error as oe

        saved = {BEFORE[b]: getattr(oe, BEFORE[b]) for b in before}
        try:
            for name in saved:
                setattr(oe, name, False)
            return identify_indirect(model, exp, start=start, run=ModelRun(dt=DT), uncertainty=Uncertainty(**what))
        finally:
            for name, v in saved.items():
                setattr(oe, name, v)

    return fit, sim


def best(fns: dict, repeat: int = REPEAT) -> dict:
    """{name: (best wall s, last result)} of zero-argument callables, each called once to warm up, then
    ``repeat`` times in turn."""
    import time

    out = {k: (np.inf, f()) for k, f in fns.items()}
    for _ in range(repeat):
        for k, f in fns.items():
            t0 = time.perf_counter()
            res = f()
            out[k] = (min(out[k][0], time.perf_counter() - t0), res)
    return out


def best_cpu(fns: dict, repeat: int = REPEAT) -> dict:
    """{name: (best wall s, best CPU s of this process, last result)}, as :func:`best`: the CPU time holds on a
    host whose other processes take turns on the cores (the wall time then waits for them)."""
    import time

    out = {k: (np.inf, np.inf, f()) for k, f in fns.items()}
    for _ in range(repeat):
        for k, f in fns.items():
            t0, c0 = time.perf_counter(), time.process_time()
            res = f()
            c1, t1 = time.process_time(), time.perf_counter()
            out[k] = (min(out[k][0], t1 - t0), min(out[k][1], c1 - c0), res)
    return out


def _fit_record(r, wall: float, sim: float, cpu: float | None = None, sim_cpu: float | None = None) -> dict:
    names = list(r.parameters)
    u = r.extra["uncertainty"]
    return {"wall_s": wall, "sims": wall / sim, "runs": int(r.iterations), "success": bool(r.success),
            **({} if cpu is None else {"cpu_s": cpu, "sims_cpu": cpu / sim_cpu}),
            "p": [r.parameters[k] for k in names], "se": [r.std_errors[k] for k in names],
            "se_noise": [u["noise"][k] for k in names], "model_error": [u["model_error"][k] for k in names],
            "verdicts": [f["verdict"] for f in r.extra["forms"]], "names": names}


def twobar_side_by_side() -> dict:
    """The twobar operations of OPS and the reference fit, in one process."""
    import casflex.identification.estimate as est

    ops = {k: operation(*v)[0] for k, v in OPS.items()}
    saved = est.STAGE_SE

    def reference():
        est.STAGE_SE = None  # every stage to the full tolerance
        try:
            return ops[next(iter(REFERENCE_OPS))]()
        finally:
            est.STAGE_SE = saved

    ops["reference"] = reference
    res = best_cpu(ops, 2 * REPEAT)  # twice the rounds: on a loaded host the best of 5 drifts by 20 %
    sim, sim_cpu = res["simulation, 3 s"][:2]
    out = {"simulation_s": sim, "simulation_cpu_s": sim_cpu}
    for k, (wall, cpu, r) in res.items():
        out[k] = ({"wall_s": wall, "sims": wall / sim, "cpu_s": cpu, "sims_cpu": cpu / sim_cpu}
                  if not hasattr(r, "parameters") else _fit_record(r, wall, sim, cpu, sim_cpu))
    return out


def mesh_rows() -> list[dict]:
    """Simulation, a model run with sensitivities and the fit without refit at MESH elements per bar."""
    rows = []
    for ne in MESH:
        fit, sim = operation("twobar", ne, {"model_error": "none"})
        sens, _ = operation("twobar", ne, "sensitivities")
        res = best({"sim": sim, "sens": sens, "fit": fit}, 3)
        s = res["sim"][0]
        rows.append({"elements": ne, "sim_s": s, "sens_s": res["sens"][0], "sens_sims": res["sens"][0] / s,
                     **{f"fit_{k}": v for k, v in _fit_record(res["fit"][1], res["fit"][0], s).items()}})
    return rows


def scene_rows() -> list[dict]:
    """The default fit of threelink (Exudyn's recording, 3 s) and of the leg (its study's 2.2 s, seed 0)."""
    rows = []
    for scene in ("twobar", "threelink", "leg"):
        fit, sim = operation(scene, None, {})
        res = best({"sim": sim, "fit": fit}, 2)
        rows.append({"scene": scene, "sim_s": res["sim"][0],
                     **_fit_record(res["fit"][1], res["fit"][0], res["sim"][0])})
    return rows


#: calls in callgrind's second process beyond its first's: processes differ by some 1e7 instructions
#: (allocation, collection), a 3 s simulation takes 5e7
CALLS = 10


def instructions(script: str, case: str) -> float | None:
    """Instructions of one ``case`` (OPS) by callgrind: (a process doing it 1 + CALLS times minus one doing it
    once) / CALLS, both after the same set-up and warm-up call; None without valgrind."""
    if shutil.which("valgrind") is None:
        return None
    counts = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in (1, 1 + CALLS):
            out = Path(tmp) / f"cg{k}"
            env = dict(os.environ, PYTHONHASHSEED="0")
            subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", sys.executable, script,
                            "--count", case, str(k)], env=env, check=True, capture_output=True, timeout=3600)
            summary = next(ln for ln in out.read_text().splitlines() if ln.startswith(("summary:", "totals:")))
            counts.append(int(summary.split()[1]))
    return (counts[1] - counts[0]) / CALLS


def count_worker(case: str, k: int) -> None:
    """The callgrind worker: set-up, one warm-up call, then ``k`` calls."""
    fn, _ = operation(*OPS[case])
    fn()
    for _ in range(k):
        fn()


def expand_rows() -> list[dict]:
    """Per simulated step (us) and build (s) of 250 compiled steps, flat SX code against the mapped kernels' MX,
    at 4 and 8 elements per bar: what the expand threshold (8 beam elements, ``HHT.expand``) trades."""
    import time

    from casflex.codegen import BufferedCall, compile_functions
    from casflex.integrators.hht import HHT
    from casflex.simulate import initial_state

    rows = []
    for ne in (4, 8):
        model = _model("twobar", ne)
        for flat in (True, False):
            integ = HHT(model, alpha=model.scene.run.alpha, expand=flat)
            x0, f = initial_state(integ, model.p_nominal), integ.trajectory(250)
            with tempfile.TemporaryDirectory() as cache:  # a build, not a load from the cache
                saved, os.environ["CASFLEX_CACHE"] = os.environ.get("CASFLEX_CACHE"), cache
                try:
                    t0 = time.perf_counter()
                    call = BufferedCall(compile_functions([f], stem="casflex_bench_expand")[f.name()])
                    build = time.perf_counter() - t0
                finally:
                    os.environ.pop("CASFLEX_CACHE") if saved is None else os.environ.update(CASFLEX_CACHE=saved)
            n = model.n_dof
            args = [x0, np.zeros(1), model.p_nominal.copy(), np.array([DT]),
                    np.array(integ.scale(x0[:n], x0[n:2 * n], model.p_nominal, DT)).ravel()]
            outs = [np.empty(integ.nx * 250), np.empty(250)]
            wall, _ = best({"run": lambda call=call, args=args, outs=outs: call(args, outs)}, 20)["run"]
            rows.append({"elements": ne, "code": "flat SX" if flat else "mapped kernels (MX)",
                         "step_us": 1e6 * wall / 250, "build_s": build})
    return rows
