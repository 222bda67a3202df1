"""NLP solver comparison: which CasADi nlpsol plugin, with which Hessian, solves each identification NLP
(direct, adapted, indirect by single and multiple shooting) from the most starts, and fastest?
Run: ``python studies/solvers.py [--quick] [--record DIR] [--scheduler ADDRESS] [--raw FILE | --render FILE]``
(about 40 min; ``--quick``: IPOPT and sqpmethod on direct, 2 starts). Set-up, measures, tolerances, notes on the
plugins and the rule for the library default: docs/studies/solvers.md.
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
CAP = 120.0  # wall-time cap per run (s): the solver's own option where it has one, else the process is killed
HARD_MARGIN = 30.0  # ... at CAP + HARD_MARGIN s (build, start-up, a solver without a cap)
QP_TOL = 1e-10  # QP subproblem tolerance of the iterative QP solvers (osqp, proxqp, piqp, ipqp, superscs)
P_TOL = 1e-6  # p is right: max_j |p_j / p*_j - 1| <= P_TOL ...
P_TOL_ADAPTED = 1e-4  # ... adapted direct: k1, k3 within this (kt1, kt3 are weakly identifiable by design)
P_STAR = [700.0, 0.5, 400.0, 0.5]  # twobar's nominal parameters (checked against the model in main)
HORIZON, T_DATA = 0.1, 2.4  # indirect horizon; the simulated set's 0..T_DATA s covers the adapted instants + dt
STARTS, QUICK_STARTS = [0.8, 1.2, 0.5, 2.0], [0.8, 2.0]  # nearest first: after a capped start, farther ones skip
_IND = {"residue": "positions", "newton_tol": 1e-14, "model_error": "none"}  # the seed paper's NLP formulation
PROBLEMS = {  # key: (label, casflex.identification function, its instants or horizon, keyword arguments)
    "direct": ("direct, t = 0.69 s", "identify_direct", [0.69], {}),
    "adapted": ("adapted direct, [0.4 1.1 1.6 1.9 2.3] s", "identify_adapted_direct", [0.4, 1.1, 1.6, 1.9, 2.3], {}),
    **{k: (f"indirect Eq. 16, {tr} shooting, 0..{HORIZON:g} s", "identify_indirect", HORIZON,
           dict(_IND, transcription=f"{tr}-shooting")) for k, tr in (("ss", "single"), ("ms", "multiple"))},
}
QUICK_CONFIGS = ["ipopt", "sqp-qpoases"]
NOT_DEFAULT = {"bonmin"}  # not candidates for the library default (why: docs/studies/solvers.md)
#: the library's current default per problem (identify_*'s solver and hessian arguments)
CURRENT = {"direct": "ipopt", "adapted": "ipopt", "ss": "ipopt-gn", "ms": "ipopt-gn"}
SPEEDUP, SAVING = 1.5, 0.1  # a faster solver must be this many times and this many seconds faster per run
_Q = {"print_time": False}
_QUIET_QP = {"print_iter": False, "print_header": False, "print_info": False}
QP = {  # sqpmethod's QP solvers and their options
    "qpoases": {"printLevel": "none"}, "qrqp": _QUIET_QP, "daqp": {}, "hpipm": {},
    "osqp": {"osqp": {"verbose": False, "eps_abs": QP_TOL, "eps_rel": QP_TOL, "max_iter": 100000, "polish": True}},
    "proxqp": {"proxqp": {"eps_abs": QP_TOL, "max_iter": 100000, "verbose": False}},
    "highs": {"highs": {"output_flag": False}}, "superscs": {"superscs": {"eps": QP_TOL, "verbose": 0}},
    "piqp": {"piqp": {"eps_abs": QP_TOL, "eps_rel": QP_TOL, "verbose": False}},
    "ipqp": dict(_QUIET_QP, constr_viol_tol=QP_TOL, dual_inf_tol=QP_TOL),
    "nlpsol": {"nlpsol": "ipopt", "nlpsol_options": dict(_Q, **{"ipopt.print_level": 0, "ipopt.sb": "yes",
                                                                "ipopt.tol": QP_TOL})},
}
_IPOPT = dict(_Q, ipopt={"print_level": 0, "sb": "yes", "tol": TOL, "acceptable_iter": 0, "mu_strategy": "adaptive",
                         "max_iter": MAX_ITER, "max_wall_time": CAP})
_SQP = dict(_Q, print_header=False, print_iteration=False, tol_pr=TOL, tol_du=TOL, max_iter=MAX_ITER)
_FATROP = dict(_Q, fatrop={"tol": TOL, "max_iter": MAX_ITER, "print_level": 0})
_BLOCKSQP = dict(_Q, print_header=False, print_iteration=False, print_maxit_reached=False, opttol=TOL,
                 nlinfeastol=TOL, max_iter=MAX_ITER)


def _sqp(qp: str, **extra) -> dict:  # error_on_fail False: a failed QP is sqpmethod's to handle
    return dict(_SQP, print_status=False, qpsol=qp, qpsol_options=dict(QP[qp], error_on_fail=False), **extra)


#: key: (nlpsol plugin, the API's hessian argument, solver_options); what each is: docs/studies/solvers.md
CONFIGS = {
    "ipopt": ("ipopt", "exact", _IPOPT), "ipopt-gn": ("ipopt", "gauss-newton", _IPOPT),
    "ipopt-lbfgs": ("ipopt", "exact", dict(_IPOPT, ipopt=dict(_IPOPT["ipopt"],
                                                             hessian_approximation="limited-memory"))),
    "sqp-qpoases": ("sqpmethod", "gauss-newton", _sqp("qpoases")),
    "sqp-qpoases-exact": ("sqpmethod", "exact", _sqp("qpoases")),
    "sqp-lbfgs": ("sqpmethod", "exact", _sqp("qpoases", hessian_approximation="limited-memory")),
    **{f"sqp-{k}": ("sqpmethod", "gauss-newton", _sqp(k))
       for k in ("qrqp", "osqp", "proxqp", "daqp", "highs", "piqp", "ipqp", "superscs", "nlpsol", "hpipm")},
    "feasiblesqp": ("feasiblesqpmethod", "gauss-newton", _sqp("qpoases", optim_tol=TOL, feas_tol=TOL)),
    "qrsqp": ("qrsqp", "exact", _SQP),
    "fatrop": ("fatrop", "exact", _FATROP),
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

    fn, arg, kw = PROBLEMS[problem][1:]
    plugin, hessian, opts = CONFIGS[config]
    r = getattr(ident, fn)(casflex.assemble(casflex.load_scene("twobar")), load_measurements(data), arg, start=start,
                           solver=plugin, hessian=hessian, solver_options=opts, **kw)
    own = r.extra.get("nlp", r.extra)["solver_parameters"]  # the indirect method keeps its NLP's under "nlp"
    return {"success": bool(r.success), "status": str(r.status), "iterations": int(r.iterations),
            "build_s": r.wall_build_s, "solve_s": r.wall_solve_s, "p": r.p.tolist(), "p_solver": list(own.values())}


def run_pair(*, problem: str, config: str, starts: list[float], data: str) -> dict:
    """One sweep run: ``config`` on ``problem`` from each start in a fresh process (``--worker``), so that a crash
    or a stall is recorded, not fatal; killed at CAP + HARD_MARGIN s; the starts after a capped one skipped."""
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


def _err(pb: str, p) -> float:
    """The largest relative error of p (adapted direct: of k1 and k3); nan where there is no p."""
    if p is None:
        return math.nan
    rel = np.abs(np.asarray(p, dtype=float) / P_STAR - 1.0)  # dtype: JSON records hold nan as "nan"
    return float(rel[[0, 2]].max() if pb == "adapted" else rel.max())


def _right(pb: str, p) -> bool:
    return _err(pb, p) <= (P_TOL_ADAPTED if pb == "adapted" else P_TOL)


def _flag(config: str, r: dict) -> bool:
    # SLEQP's CasADi interface reports success whatever its status: for SLEQP only 'optimal' counts
    return r.get("status") == "optimal" if config == "sleqp" else bool(r.get("success"))


def main(quick: bool = False, out_dir: Path | None = None, record: Path | None = None,
         scheduler: str | None = None, raw_path: Path | None = None) -> dict:
    import casflex
    from casflex.data import save_measurements, simulated_set

    banner = Banner("solvers", quick)
    starts, configs = (QUICK_STARTS, QUICK_CONFIGS) if quick else (STARTS, list(CONFIGS))
    problems = ["direct"] if quick else ["direct", "adapted", "ss", "ms"]

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


def _analyse(raw: dict) -> dict:
    """Per (problem, config) counts and measures; per problem the configurations ranked (most starts solved,
    fewest successes at a wrong p, the smallest median build + solve); the spread of p among flagged runs."""
    rows = {}
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
    an = {"rows": rows, "ranked": {}, "recommend": {}, "spread": {}}
    for pb in raw["problems"]:
        an["ranked"][pb] = sorted((row for (p2, _), row in rows.items() if p2 == pb),
                                  key=lambda x: (-x["solved"], x["wrong"], x["total"]))
        an["recommend"][pb] = _recommend(an["ranked"][pb], pb)
        flagged = [r for (p2, cf), row in rows.items() if p2 == pb for r in row["runs"] if _flag(cf, r) and "p" in r]
        if len(flagged) >= 2:
            P, Ps = (np.array([r[k] for r in flagged], dtype=float) for k in ("p", "p_solver"))
            ref = np.median(P, axis=0)
            an["spread"][pb] = {"n": len(P), "median_p": ref.tolist(), "final": np.abs(P / ref - 1.0).max(axis=0),
                                "solver": np.abs(Ps / ref - 1.0).max(axis=0)}
    return an


def _recommend(ranked: list[dict], pb: str) -> str:
    """The library default on one problem by the rule of docs/studies/solvers.md#default-solver."""
    cands = [x for x in ranked if x["solved"] and x["cf"] not in NOT_DEFAULT]
    cur = next((x for x in cands if x["cf"] == CURRENT[pb]), None)
    if cur is None:
        return cands[0]["cf"] if cands else CURRENT[pb]
    b = cands[0]
    faster = cur["total"] > SPEEDUP * b["total"] and cur["total"] - b["total"] > SAVING
    return b["cf"] if (b["solved"], -b["wrong"]) > (cur["solved"], -cur["wrong"]) or faster else cur["cf"]


def _profile(raw: dict, rows: dict, key: str) -> np.ndarray:
    """Dolan-More ratios [config, problem instance], inf or nan where not solved (``key``: "solve" or "total")."""
    inst = [(pb, st) for pb in raw["problems"] for st in raw["starts"]]
    T = np.full((len(raw["configs"]), len(inst)), np.inf)
    for (pb, cf), row in rows.items():
        for r in (r for r, o in zip(row["runs"], row["ok"], strict=True) if o):
            T[raw["configs"].index(cf), inst.index((pb, r["start"]))] = r["solve_s"] + r["build_s"] * (key == "total")
    with np.errstate(invalid="ignore"):
        return T / T.min(axis=0)


def _page(raw: dict, an: dict) -> list[str]:
    L = ["# NLP solver comparison" + (" (quick mode)" if raw["quick"] else ""), "", raw["banner"], "",
         f"Starts {', '.join(f'{s:g}' for s in raw['starts'])} x p*. Set-up, measures, tolerances and the rule for "
         "the library default: [studies/solvers.md](../studies/solvers.md).", ""]
    for pb in raw["problems"]:
        rec, cur = an["recommend"][pb], CURRENT[pb]
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
              role.get(x["cf"], "")] for i, x in enumerate(an["ranked"][pb])], "rlcccccrrrrrrll"), ""]
    R, Rt = _profile(raw, an["rows"], "solve"), _profile(raw, an["rows"], "total")
    return L + ["## Cross-solver consistency", "", *table(
        ["problem", "runs reporting success", "their median p = [k1 kt1 k3 kt3]",
         "max deviation, final p (per parameter)", "max deviation, solvers' own p (per parameter)"],
        [[f"`{pb}`", sp["n"], f"[{' '.join(f'{v:.7g}' for v in sp['median_p'])}]",
          *(f"{fnum(d.max(), '.1e', '–')} ({' / '.join(f'{v:.1e}' for v in d)})" for d in (sp["final"], sp["solver"]))]
         for pb, sp in an["spread"].items()], "lrlll"),
        "", "## Performance profile", "", f"![profile](../figures/solvers{'_quick' * raw['quick']}.png)", "", *table(
            ["configuration", "solved", "fastest (solve)", "within 2x", "within 10x", "fastest (build + solve)"],
            [[f"`{raw['configs'][i]}`", f"{np.isfinite(R[i]).sum()}/{R.shape[1]}", (R[i] <= 1.0).sum(),
              (R[i] <= 2).sum(), (R[i] <= 10).sum(), (Rt[i] <= 1.0).sum()]
             for i in sorted(range(len(R)), key=lambda i: (-np.isfinite(R[i]).sum(), -(R[i] <= 2).sum()))], "lrrrrr"),
        ""]


def _figure(raw: dict, rows: dict) -> bytes:
    """Dolan-More performance profiles of the solve time and of build + solve time."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(13, 6.5))
    axes = fig.subplots(1, 2, sharey=True)
    for ax, key, title in ((axes[0], "solve", "solve time"), (axes[1], "total", "build + solve time")):
        R = _profile(raw, rows, key)
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
    an = _analyse(raw)
    ipopt = {r["start"]: r for r in an["rows"][("direct", "ipopt")]["runs"]}
    dev = {pb: float(np.abs(np.asarray(sp["median_p"]) / P_STAR - 1.0).max()) for pb, sp in an["spread"].items()}
    lines, an["failed"] = checks(
        [(f"IPOPT solves the direct problem from {st:g} x p*", ipopt[st].get("status", "-"),
          bool(ipopt[st].get("success")) and _right("direct", ipopt[st].get("p"))) for st in raw["starts"]]
        + [(f"{pb}: the median p of the runs that report success is p* (to {P_TOL:g})", f"{d:.1e}", d <= P_TOL)
           for pb, d in dev.items() if pb != "adapted"])  # adapted: kt1, kt3 weakly identifiable by design
    write_outputs("solvers", out_dir, raw["quick"], "\n".join(_page(raw, an) + lines), _figure(raw, an["rows"]))
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
