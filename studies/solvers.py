"""NLP solver comparison: which CasADi nlpsol plugin, with which Hessian, solves each identification NLP
(direct, adapted, indirect by single and multiple shooting) from the most starts, and fastest?
Run: ``python studies/solvers.py [--quick] [--record DIR] [--scheduler ADDRESS] [--raw FILE | --render FILE]``
(about 40 min); set-up, measures, tolerances, plugin notes and the default rule: docs/studies/solvers.md.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from _study import Banner, assert_checks, checks, cli, fnum, med_range, png, save_raw, sweep, table, write_outputs

TOL, MAX_ITER = 1e-8, 200  # the one optimality tolerance, mapped onto every solver, and the iteration cap
CAP, HARD_MARGIN = 120.0, 30.0  # per run (s): the solver's own wall-time option, else the process is killed at the sum
QP_TOL = 1e-10  # QP subproblem tolerance of the iterative QP solvers (osqp, proxqp, piqp, ipqp, superscs)
P_TOL, P_TOL_ADAPTED = 1e-6, 1e-4  # p is right: max |p / p* - 1| <= P_TOL (adapted: k1, k3; kt weakly identifiable)
P_STAR = [700.0, 0.5, 400.0, 0.5]  # twobar's nominal parameters (checked against the model in main)
HORIZON, T_DATA = 0.1, 2.4  # indirect horizon; the simulated set's 0..T_DATA s covers the adapted instants + dt
STARTS, QUICK_STARTS = [0.8, 1.2, 0.5, 2.0], [0.8, 2.0]  # nearest first: after a capped start, farther ones skip
PROBLEMS = {  # key: (label, casflex.identification function, its instants or horizon, the indirect's transcription)
    "direct": ("direct, t = 0.69 s", "identify_direct", [0.69], None),
    "adapted": ("adapted direct, [0.4 1.1 1.6 1.9 2.3] s", "identify_adapted_direct", [0.4, 1.1, 1.6, 1.9, 2.3], None),
    **{k: (f"indirect Eq. 16, {tr} shooting, 0..{HORIZON:g} s", "identify_indirect", HORIZON, f"{tr}-shooting")
       for k, tr in (("ss", "single"), ("ms", "multiple"))},
}
QUICK_CONFIGS = ["ipopt", "sqp-qpoases"]
NOT_DEFAULT = {"bonmin"}  # not candidates for the library default (why: docs/studies/solvers.md)
CURRENT = {"direct": "ipopt", "adapted": "ipopt", "ss": "ipopt-gn", "ms": "ipopt-gn"}  # the library's defaults
SPEEDUP, SAVING = 1.5, 0.1  # a faster solver must be this many times and this many seconds faster per run
_Q, _QUIET_QP = {"print_time": False}, {"print_iter": False, "print_header": False, "print_info": False}
QP = {  # sqpmethod's QP solvers and their options
    "qpoases": {"printLevel": "none"}, "qrqp": _QUIET_QP, "daqp": {}, "hpipm": {},
    "osqp": {"osqp": {"verbose": False, "eps_abs": QP_TOL, "eps_rel": QP_TOL, "max_iter": 100000, "polish": True}},
    "proxqp": {"proxqp": {"eps_abs": QP_TOL, "max_iter": 100000, "verbose": False}},
    "highs": {"highs": {"output_flag": False}}, "superscs": {"superscs": {"eps": QP_TOL, "verbose": 0}},
    "piqp": {"piqp": {"eps_abs": QP_TOL, "eps_rel": QP_TOL, "verbose": False}},
    "ipqp": dict(_QUIET_QP, constr_viol_tol=QP_TOL, dual_inf_tol=QP_TOL),
    "nlpsol": {"nlpsol": "ipopt", "nlpsol_options": dict(_Q, ipopt={"print_level": 0, "sb": "yes", "tol": QP_TOL})},
}
_IPOPT = dict(_Q, ipopt={"print_level": 0, "sb": "yes", "tol": TOL, "acceptable_iter": 0, "mu_strategy": "adaptive",
                         "max_iter": MAX_ITER, "max_wall_time": CAP})
_SQP = dict(_Q, print_header=False, print_iteration=False, tol_pr=TOL, tol_du=TOL, max_iter=MAX_ITER)
_FATROP = dict(_Q, fatrop={"tol": TOL, "max_iter": MAX_ITER, "print_level": 0})
_BLOCKSQP = dict(_Q, print_header=False, print_iteration=False, print_maxit_reached=False, opttol=TOL,
                 nlinfeastol=TOL, max_iter=MAX_ITER)


def _sqp(qp: str, **extra) -> dict:  # error_on_fail False: a failed QP is sqpmethod's to handle
    return dict(_SQP, print_status=False, qpsol=qp, qpsol_options=dict(QP[qp], error_on_fail=False), **extra)


CONFIGS = {  # key: (nlpsol plugin, the API's hessian argument, solver_options); what each is: docs/studies/solvers.md
    "ipopt": ("ipopt", "exact", _IPOPT), "ipopt-gn": ("ipopt", "gauss-newton", _IPOPT),
    "ipopt-lbfgs": ("ipopt", "exact", dict(_IPOPT, ipopt=dict(_IPOPT["ipopt"],
                                                             hessian_approximation="limited-memory"))),
    "sqp-qpoases": ("sqpmethod", "gauss-newton", _sqp("qpoases")),
    "sqp-qpoases-exact": ("sqpmethod", "exact", _sqp("qpoases")),
    "sqp-lbfgs": ("sqpmethod", "exact", _sqp("qpoases", hessian_approximation="limited-memory")),
    **{f"sqp-{k}": ("sqpmethod", "gauss-newton", _sqp(k))
       for k in ("qrqp", "osqp", "proxqp", "daqp", "highs", "piqp", "ipqp", "superscs", "nlpsol", "hpipm")},
    "feasiblesqp": ("feasiblesqpmethod", "gauss-newton", _sqp("qpoases", optim_tol=TOL, feas_tol=TOL)),
    "qrsqp": ("qrsqp", "exact", _SQP), "fatrop": ("fatrop", "exact", _FATROP),
    "fatrop-auto": ("fatrop", "exact", dict(_FATROP, structure_detection="auto")),
    **{f"uno-{k}": ("uno", "exact", dict(_Q, uno={"preset": k})) for k in ("filtersqp", "ipopt")},
    "sleqp": ("sleqp", "exact", dict(_Q, print_level=0, max_iter=MAX_ITER, max_wall_time=CAP,
                                     sleqp={"stat_tol": TOL, "feas_tol": TOL, "slack_tol": TOL})),
    "alpaqa": ("alpaqa", "exact", _Q),
    "bonmin": ("bonmin", "gauss-newton", dict(_Q, bonmin={"tol": TOL, "acceptable_iter": 0, "max_iter": MAX_ITER,
                                                          "print_level": 0, "time_limit": CAP})),
    "blocksqp": ("blocksqp", "exact", dict(_BLOCKSQP, linsol="ldl")), "blocksqp-ma27": ("blocksqp", "exact", _BLOCKSQP),
}


def _worker(data: str, start: float, config: str, problem: str) -> dict:
    """One identification in this (fresh) process: outcome, times, p and the solver's own p (before the polish)."""
    import casflex
    import casflex.identification as ident
    from casflex.data import load_measurements

    fn, arg, transcription = PROBLEMS[problem][1:]
    plugin, hessian, opts = CONFIGS[config]
    # the indirect problems: the seed paper's NLP formulation (Eq. 16, model Newton tolerance 1e-14, no refit)
    kw = {} if transcription is None else {"shooting": ident.Shooting(transcription, residue="positions"),
                                           "run": ident.ModelRun(newton_tol=1e-14),
                                           "uncertainty": ident.Uncertainty(model_error="none")}
    r = getattr(ident, fn)(casflex.assemble(casflex.load_scene("twobar")), load_measurements(data), arg, start=start,
                           solver=ident.Solver(plugin, options=opts, hessian=hessian), **kw)
    own = r.extra.get("nlp", r.extra)["solver_parameters"]  # the indirect method keeps its NLP's under "nlp"
    return {"success": bool(r.success), "status": str(r.status), "iterations": int(r.iterations),
            "build_s": r.wall_build_s, "solve_s": r.wall_solve_s, "p": r.p.tolist(), "p_solver": list(own.values())}


def run_pair(*, problem: str, config: str, starts: list[float], data: str) -> dict:
    """``config`` on ``problem`` from each start in a fresh process (``--worker``: a crash or a stall is recorded,
    not fatal), killed at CAP + HARD_MARGIN s; the starts after a capped one are skipped."""
    runs, capped = [], None
    for st in starts:
        if capped is not None:
            runs.append({"start": st, "skipped": f"start {capped:g} hit the {CAP:g} s cap", "success": False})
            continue
        with tempfile.TemporaryDirectory() as tmp:
            out, spec = Path(tmp) / "out.json", {"data": data, "start": st, "config": config, "problem": problem}
            try:
                rc = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker", json.dumps(spec),
                                     str(out)], cwd=tmp, capture_output=True, timeout=CAP + HARD_MARGIN).returncode
                res = json.loads(out.read_text()) if out.exists() else {
                    "status": f"crashed ({f'signal {-rc}' if rc < 0 else f'exit status {rc}'})"}
            except subprocess.TimeoutExpired:
                res = {"killed": True, "status": f"killed at the cap ({CAP + HARD_MARGIN:g} s of wall time)"}
        runs.append(res := {"success": False, **res, "start": st})
        s = str(res.get("status", "")).lower()
        if res.get("killed") or ("time" in s and ("exceed" in s or "limit" in s)) or res.get("solve_s", 0.0) >= CAP:
            capped = st
    return {"runs": runs}


def _err(pb: str, p) -> float:  # the largest relative error of p (adapted: of k1, k3); nan where there is no p
    rel = np.abs(np.asarray(np.nan if p is None else p, dtype=float) / P_STAR - 1.0)  # JSON holds nan as "nan"
    return float(rel[[0, 2]].max() if pb == "adapted" else rel.max())


def _right(pb: str, p) -> bool:
    return _err(pb, p) <= (P_TOL_ADAPTED if pb == "adapted" else P_TOL)


def _flag(config: str, r: dict) -> bool:  # SLEQP's interface reports success whatever its status: 'optimal' counts
    return r.get("status") == "optimal" if config == "sleqp" else bool(r.get("success"))


def main(quick: bool = False, out_dir: Path | None = None, record: Path | None = None,
         scheduler: str | None = None, raw_path: Path | None = None) -> dict:
    import casflex
    from casflex.data import save_measurements
    from casflex.simulate import simulated_set

    banner, problems = Banner("solvers", quick), ["direct"] if quick else list(PROBLEMS)
    starts, configs = (QUICK_STARTS, QUICK_CONFIGS) if quick else (STARTS, list(CONFIGS))

    def stage(pairs: list[tuple[str, str]]) -> dict:  # {(problem, config): runs}; a run that raised failed all starts
        plan = [{"problem": pb, "config": cf, "starts": list(starts), "data": str(data)} for pb, cf in pairs]
        done = sweep("solvers", plan, lambda r: f"{r['problem']}--{r['config']}", run_pair, record=record,
                     quick=quick, scheduler=scheduler)
        return {(run["problem"], run["config"]): v.get("runs") or [
            {"start": s, "success": False, "status": f"sweep error: {v['error']}"} for s in starts] for run, v in done}

    with tempfile.TemporaryDirectory(prefix="casflex-solvers-") as tmp:
        data, model = Path(tmp) / "simulated_set.npz", casflex.assemble(casflex.load_scene("twobar"))
        assert np.allclose(model.p_nominal, P_STAR), "twobar's nominal parameters changed: update P_STAR"
        save_measurements(simulated_set(model, T_DATA), data)
        results = stage([(pb, cf) for pb in problems[:2] for cf in configs])
        if not quick:  # stage 2: the configurations that solved the direct problem from at least one start
            results |= stage([(pb, cf) for pb in ("ss", "ms") for cf in configs
                              if any(_flag(cf, r) and _right("direct", r.get("p")) for r in results[("direct", cf)])])
    raw = {"banner": banner.line(), "quick": quick, "starts": starts, "configs": configs, "problems": problems,
           "results": {f"{pb}--{cf}": runs for (pb, cf), runs in results.items()}}
    save_raw(raw, raw_path)
    an = render(raw, out_dir)
    assert_checks(an["failed"])
    return {"raw": raw, "summary": an}


def _figure(raw: dict, rows: dict) -> bytes:
    """Dolan-More performance profiles of the solve time and of build + solve time."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(13, 6.5))
    axes = fig.subplots(1, 2, sharey=True)
    inst = [(pb, st) for pb in raw["problems"] for st in raw["starts"]]  # the problem instances
    for ax, total, title in ((axes[0], False, "solve time"), (axes[1], True, "build + solve time")):
        T = np.full((len(raw["configs"]), len(inst)), np.inf)  # time [config, instance], inf where not solved
        for (pb, cf), row in rows.items():
            for r in (r for r, o in zip(row["runs"], row["ok"], strict=True) if o):
                T[raw["configs"].index(cf), inst.index((pb, r["start"]))] = r["solve_s"] + r["build_s"] * total
        with np.errstate(invalid="ignore"):
            R = T / T.min(axis=0)  # Dolan-More ratios (nan where nobody solved the instance)
        taus = np.logspace(0, math.log10(max(2.0, 1.5 * np.max(R[np.isfinite(R)], initial=1.0))), 400)
        # legend order: most instances solved, then the most often within 4x of the best; 10 colours a line style
        order = sorted((i for i in range(len(R)) if np.isfinite(R[i]).any()),
                       key=lambda i: (-np.isfinite(R[i]).sum(), -(R[i] <= 4).sum()))
        for rank, i in enumerate(order):
            ax.step(taus, [(R[i] <= t).mean() for t in taus], where="post", label=raw["configs"][i],
                    color=f"C{rank % 10}", ls=("-", "--", ":")[rank // 10 % 3],
                    lw=2.4 if rank < 8 or raw["configs"][i] in ("ipopt", "ipopt-gn") else 1.0)
        ax.set(xscale="log", xlabel="tau (time / best time on the instance)", ylim=(-0.02, 1.02))
        ax.set_title(f"Dolan-More profile: {title}\n{R.shape[1]} instances = {len(raw['problems'])} problems x "
                     f"{len(raw['starts'])} starts", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("fraction of instances solved within tau x best")
    fig.legend(*axes[0].get_legend_handles_labels(), loc="center right", fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0, 0.84, 1))
    return png(fig)


def render(raw: dict, out_dir: Path | None) -> dict:
    """The page (with its self-checks) and the figure from the raw numbers (of this run, or of a ``--raw`` file)."""
    rows = {}  # per (problem, config): the counts and measures of docs/studies/solvers.md#measures
    for k, runs in raw["results"].items():
        pb, cf = k.split("--")
        flag = [_flag(cf, r) for r in runs]
        ok = [f and _right(pb, r.get("p")) for f, r in zip(flag, runs, strict=True)]
        m = [r for r in runs if "p" in r]
        times = [r["build_s"] + r["solve_s"] for r, o in zip(runs, ok, strict=True) if o]
        rows[(pb, cf)] = {
            "cf": cf, "n": len(runs), "solved": sum(ok), "flag": sum(flag), "wrong": sum(flag) - sum(ok),
            "rescued": sum(not f and _right(pb, r.get("p")) for f, r in zip(flag, runs, strict=True)),
            "solver_off": sum(f and not _right(pb, r.get("p_solver")) for f, r in zip(flag, runs, strict=True)),
            "it": [r["iterations"] for r in m], "build": [r["build_s"] for r in m], "solve": [r["solve_s"] for r in m],
            "total": float(np.median(times)) if times else math.inf,  # median build + solve of the solved starts
            "err": [_err(pb, r["p"]) for r in m], "err_solver": [_err(pb, r.get("p_solver")) for r in m],
            "statuses": sorted({str(r.get("status") or r.get("skipped") or r.get("error", "?"))[:60] for r in runs}),
            "runs": runs, "ok": ok}
    an = {"rows": rows, "recommend": {}, "median_p": {}}
    L = ["# NLP solver comparison" + (" (quick mode)" if raw["quick"] else ""), "", raw["banner"], "",
         f"Starts {', '.join(f'{s:g}' for s in raw['starts'])} x p*. Set-up, measures, tolerances and the rule for "
         "the library default: [studies/solvers.md](../studies/solvers.md).", ""]
    for pb in raw["problems"]:  # ranked: most starts solved, then fewest ✗!, then the smallest build + solve
        ranked = sorted((row for (p2, _), row in rows.items() if p2 == pb),
                        key=lambda x: (-x["solved"], x["wrong"], x["total"]))
        # the library default (rule: docs/studies/solvers.md#default-solver): the best candidate replaces the current
        # one if that one solved nothing, or if it solves more starts (as many: fewer ✗!), or is clearly faster
        cands, cur = [x for x in ranked if x["solved"] and x["cf"] not in NOT_DEFAULT], CURRENT[pb]
        best, now = (cands or [None])[0], next((x for x in cands if x["cf"] == cur), None)
        better = now is None or (best["solved"], -best["wrong"]) > (now["solved"], -now["wrong"]) or (
            now["total"] > SPEEDUP * best["total"] and now["total"] - best["total"] > SAVING)
        rec = an["recommend"][pb] = best["cf"] if best and better else cur
        role = {cf: "not a candidate" for cf in NOT_DEFAULT} | {rec: "**recommend**"}
        role[cur] = "default: keep" if rec == cur else "default: replace"
        L += [f"## {PROBLEMS[pb][0]}", "", *table(
            ["rank", "configuration", "solved", "flag", "✗!", "rescued", "flag, solver's p off", "iterations",
             "build (s)", "solve (s)", "build + solve, solved (s)", "error of p (final)", "solver's p error",
             "status", "library default"],
            [[i + 1 if x["solved"] else "", f"`{x['cf']}`", f"{x['solved']}/{x['n']}", x["flag"], x["wrong"] or "",
              x["rescued"] or "", x["solver_off"] or "", med_range(x["it"], "g", "–"),
              *(med_range(x[k], ".3g", "–") for k in ("build", "solve")), fnum(x["total"], ".3g", "–"),
              *(med_range(x[k], ".1e", "–") for k in ("err", "err_solver")), "; ".join(x["statuses"])[:160],
              role.get(x["cf"], "")] for i, x in enumerate(ranked)], "rlcccccrrrrrrll"), ""]
        P = [r["p"] for (p2, cf), row in rows.items() if p2 == pb for r in row["runs"] if _flag(cf, r) and "p" in r]
        if len(P) >= 2:  # the median p of the runs that report success, any solver, any start
            an["median_p"][pb] = np.median(np.array(P, dtype=float), axis=0)
    L += ["## Performance profile", "", f"![profile](../figures/solvers{'_quick' * raw['quick']}.png)", ""]
    ipopt = {r["start"]: r for r in rows[("direct", "ipopt")]["runs"]}
    dev = {pb: float(np.abs(p / P_STAR - 1.0).max()) for pb, p in an["median_p"].items()}
    lines, an["failed"] = checks(
        [(f"IPOPT solves the direct problem from {st:g} x p*", ipopt[st].get("status", "-"),
          bool(ipopt[st].get("success")) and _right("direct", ipopt[st].get("p"))) for st in raw["starts"]]
        + [(f"{pb}: the median p of the runs that report success is p* (to {P_TOL:g})", f"{d:.1e}", d <= P_TOL)
           for pb, d in dev.items() if pb != "adapted"])  # adapted: kt1, kt3 weakly identifiable by design
    write_outputs("solvers", out_dir, raw["quick"], "\n".join(L + lines), _figure(raw, rows))
    return an


if __name__ == "__main__":
    if sys.argv[1:2] == ["--worker"]:  # hidden: run_pair's fresh process; the result or the error as JSON
        try:
            res = _worker(**json.loads(sys.argv[2]))
        except Exception as exc:  # noqa: BLE001 - the failure is the measurement
            res = {"error": f"{type(exc).__name__}: {' '.join(str(exc).split())}"[:300]}
        Path(sys.argv[3]).write_text(json.dumps(res))
    else:
        cli(__doc__, main, render)
