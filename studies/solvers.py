"""NLP solver comparison: which CasADi nlpsol plugin, with which Hessian, solves each identification NLP
(direct, adapted, indirect by single and multiple shooting) from the most starts, and fastest?

Set-up, measures, the tolerance each plugin gets and notes on the plugins: docs/studies/solvers.md.
Run: ``python studies/solvers.py [--quick] [--record DIR] [--scheduler ADDRESS] [--raw FILE | --render FILE]``
(about 40 min on a shared 2-core machine; ``--quick``: IPOPT and sqpmethod on direct, 2 starts).
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
from _isolated import run_isolated
from _study import Banner, cli, fnum, med_range, png, save_raw, sweep, table, write_outputs

TOL = 1e-8  # the one optimality tolerance, mapped onto every solver
MAX_ITER = 200  # iteration cap (solvers that take one)
CAP = 120.0  # wall-time cap per run (s): the solver's own option where it has one, else the process is killed
HARD_MARGIN = 30.0  # ... at CAP + HARD_MARGIN s (build, start-up, a solver without a cap)
QP_TOL = 1e-10  # QP subproblem tolerance of the iterative QP solvers (osqp, proxqp, piqp, ipqp, superscs)
P_TOL = 1e-6  # p is right: max_j |p_j / p*_j - 1| <= P_TOL ...
P_TOL_ADAPTED = 1e-4  # ... adapted direct: k1, k3 within this (kt1, kt3 are weakly identifiable by design)
P_STAR = [700.0, 0.5, 400.0, 0.5]  # twobar's nominal parameters (checked against the model in main)
HORIZON = 0.1
T_DATA = 2.4  # simulated set 0..T_DATA s (covers the adapted instants and their t + dt)
STARTS = [0.8, 1.2, 0.5, 2.0]  # nearest first: after a start hits the cap, the farther ones are skipped
QUICK_STARTS = [0.8, 2.0]
_IND = {"method": "indirect", "horizon": HORIZON, "residue": "positions"}
#: key: (label, method's name, identify_* keyword arguments)
PROBLEMS = {
    "direct": ("direct, t = 0.69 s", "direct", {"method": "direct", "instants": [0.69]}),
    "adapted": ("adapted direct, [0.4 1.1 1.6 1.9 2.3] s", "adapted direct",
                {"method": "adapted", "instants": [0.4, 1.1, 1.6, 1.9, 2.3]}),
    "ss": (f"indirect Eq. 16, single shooting, 0..{HORIZON:g} s", "indirect, single shooting",
           dict(_IND, transcription="single-shooting")),
    "ms": (f"indirect Eq. 16, multiple shooting, 0..{HORIZON:g} s", "indirect, multiple shooting",
           dict(_IND, transcription="multiple-shooting")),
}
QUICK_CONFIGS = ["ipopt", "sqp-qpoases"]
NOT_DEFAULT = {"bonmin"}  # not candidates for the library default (why: docs/studies/solvers.md)
#: the library's current default per problem (identify_*'s solver and hessian arguments)
CURRENT = {"direct": "ipopt", "adapted": "ipopt", "ss": "ipopt-gn", "ms": "ipopt-gn"}
SPEEDUP, SAVING = 1.5, 0.1  # a faster solver must be this many times and this many seconds faster per run
_QUIET_QP = {"print_iter": False, "print_header": False, "print_info": False}
#: sqpmethod's QP solvers: (name on the page, options)
QP = {
    "qpoases": ("qpOASES", {"printLevel": "none"}), "qrqp": ("qrqp", _QUIET_QP),
    "osqp": ("OSQP", {"osqp": {"verbose": False, "eps_abs": QP_TOL, "eps_rel": QP_TOL, "max_iter": 100000,
                               "polish": True}}),
    "proxqp": ("ProxQP", {"proxqp": {"eps_abs": QP_TOL, "max_iter": 100000, "verbose": False}}),
    "daqp": ("DAQP", {}), "highs": ("HiGHS", {"highs": {"output_flag": False}}),
    "piqp": ("PIQP", {"piqp": {"eps_abs": QP_TOL, "eps_rel": QP_TOL, "verbose": False}}),
    "ipqp": ("ipqp", dict(_QUIET_QP, constr_viol_tol=QP_TOL, dual_inf_tol=QP_TOL)),
    "superscs": ("SuperSCS", {"superscs": {"eps": QP_TOL, "verbose": 0}}),
    "nlpsol": ("IPOPT as QP solver", {"nlpsol": "ipopt", "nlpsol_options": {
        "print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes", "ipopt.tol": QP_TOL}}),
    "hpipm": ("HPIPM", {}),
}


def _ipopt(**extra) -> dict:
    return {"print_time": False, "ipopt": {"print_level": 0, "sb": "yes", "tol": TOL, "acceptable_iter": 0,
                                           "mu_strategy": "adaptive", "max_iter": MAX_ITER, "max_wall_time": CAP,
                                           **extra}}


def _sqp(qp: str, **extra) -> dict:
    # error_on_fail False: a failed QP is sqpmethod's to handle
    return {"print_time": False, "print_header": False, "print_iteration": False, "print_status": False,
            "tol_pr": TOL, "tol_du": TOL, "max_iter": MAX_ITER, "qpsol": qp,
            "qpsol_options": dict(QP[qp][1], error_on_fail=False), **extra}


_Q = {"print_time": False}
_FATROP = dict(_Q, fatrop={"tol": TOL, "max_iter": MAX_ITER, "print_level": 0})
_BLOCKSQP = dict(_Q, print_header=False, print_iteration=False, print_maxit_reached=False, opttol=TOL,
                 nlinfeastol=TOL, max_iter=MAX_ITER)
#: key: (plugin, linear/QP solver; Hessian as given to the solver; nlpsol plugin; the API's hessian argument;
#: solver_options)
CONFIGS = {
    "ipopt": ("IPOPT, MUMPS", "exact (CasADi AD)", "ipopt", "exact", _ipopt()),
    "ipopt-gn": ("IPOPT, MUMPS", "Gauss-Newton J^T J", "ipopt", "gauss-newton", _ipopt()),
    "ipopt-lbfgs": ("IPOPT, MUMPS", "L-BFGS", "ipopt", "exact", _ipopt(hessian_approximation="limited-memory")),
    "sqp-qpoases": ("sqpmethod + qpOASES", "Gauss-Newton", "sqpmethod", "gauss-newton", _sqp("qpoases")),
    "sqp-qpoases-exact": ("sqpmethod + qpOASES", "exact", "sqpmethod", "exact", _sqp("qpoases")),
    "sqp-lbfgs": ("sqpmethod + qpOASES", "BFGS (limited-memory)", "sqpmethod", "exact",
                  _sqp("qpoases", hessian_approximation="limited-memory")),
    **{f"sqp-{k}": (f"sqpmethod + {QP[k][0]}", "Gauss-Newton", "sqpmethod", "gauss-newton", _sqp(k))
       for k in ("qrqp", "osqp", "proxqp", "daqp", "highs", "piqp", "ipqp", "superscs", "nlpsol", "hpipm")},
    "feasiblesqp": ("feasiblesqpmethod + qpOASES", "Gauss-Newton", "feasiblesqpmethod", "gauss-newton",
                    _sqp("qpoases", optim_tol=TOL, feas_tol=TOL)),
    "qrsqp": ("qrsqp (SQP + qrqp)", "exact", "qrsqp", "exact", dict(
        _Q, print_header=False, print_iteration=False, tol_pr=TOL, tol_du=TOL, max_iter=MAX_ITER)),
    "fatrop": ("fatrop, no structure (one stage)", "exact", "fatrop", "exact", _FATROP),
    "fatrop-auto": ("fatrop, structure detection 'auto'", "exact", "fatrop", "exact",
                    dict(_FATROP, structure_detection="auto")),
    **{f"uno-{k}": (f"Uno, preset {k}", "exact", "uno", "exact", dict(_Q, uno={"preset": k}))
       for k in ("filtersqp", "ipopt")},
    "sleqp": ("SLEQP", "as the CasADi interface sets it (not an option)", "sleqp", "exact", dict(
        _Q, print_level=0, max_iter=MAX_ITER, max_wall_time=CAP, sleqp={"stat_tol": TOL, "feas_tol": TOL,
                                                                        "slack_tol": TOL})),
    "alpaqa": ("alpaqa (ALM + PANOC)", "L-BFGS (inside PANOC)", "alpaqa", "exact", _Q),
    "bonmin": ("Bonmin (continuous: IPOPT inside)", "Gauss-Newton", "bonmin", "gauss-newton", dict(
        _Q, bonmin={"tol": TOL, "acceptable_iter": 0, "max_iter": MAX_ITER, "print_level": 0, "time_limit": CAP})),
    "blocksqp": ("blockSQP, linsol ldl", "SR1/BFGS blockwise", "blocksqp", "exact", dict(_BLOCKSQP, linsol="ldl")),
    "blocksqp-ma27": ("blockSQP, its default linsol ma27", "SR1/BFGS blockwise", "blocksqp", "exact", _BLOCKSQP),
}


def run_pair(*, problem: str, config: str, starts: list[float], data: str) -> dict:
    """One sweep run: ``config`` on ``problem`` from each start, each in a fresh Python process killed at
    CAP + HARD_MARGIN s; a start after one that hit the cap is skipped."""
    runs, capped = [], None
    for st in starts:
        if capped is not None:
            runs.append({"start": st, "skipped": f"start {capped:g} hit the {CAP:g} s cap", "success": False})
            continue
        plugin, hessian, opts = CONFIGS[config][2:]
        res = run_isolated({"data": data, "start": st, "solver": plugin, "hessian": hessian, "solver_options": opts,
                            "problem": PROBLEMS[problem][2]}, CAP + HARD_MARGIN)
        res["start"] = st
        s = str(res.get("status", "")).lower()
        if res.get("killed") or ("time" in s and ("exceed" in s or "limit" in s)) or res.get("solve_s", 0.0) >= CAP:
            capped = st
        runs.append(res)
    return {"runs": runs}


# -- the study ----------------------------------------------------------------------------------

def _right(problem: str, e: float) -> bool:
    """A relative error of p within the criterion (adapted direct: of k1 and k3)."""
    return math.isfinite(e) and e <= (P_TOL_ADAPTED if problem == "adapted" else P_TOL)


def _criterion(problem: str, r: dict) -> bool:
    """p (as the library returns it, after its Gauss-Newton polish) is right."""
    return "err" in r and _right(problem, r["err_k" if problem == "adapted" else "err"])


def _flag(config: str, r: dict) -> bool:
    """The solver's success flag. SLEQP's CasADi interface sets success = true whatever its status
    (e.g. 'iteration limit'), so for SLEQP the flag is its status 'optimal'."""
    return r.get("status") == "optimal" if config == "sleqp" else bool(r.get("success"))


def _solver_err(problem: str, r: dict) -> float:
    """Relative error of the solver's own p: over k1, k3 for the adapted direct problem, else over all."""
    if "p_solver" not in r:
        return math.nan
    rel = np.abs(np.asarray(r["p_solver"], dtype=float) / np.asarray(P_STAR) - 1.0)
    return float(rel[[0, 2]].max()) if problem == "adapted" else float(rel.max())


def _clean(x):
    """Undo the JSON form of non-finite numbers ("nan", "inf")."""
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_clean(v) for v in x]
    return float(x) if isinstance(x, str) and x in ("nan", "inf", "-inf") else x


def _stage(pairs: list[tuple[str, str]], starts: list[float], data: Path, record: Path,
           scheduler: str | None, quick: bool) -> dict:
    """{(problem, config): runs} of one sweep over (problem, config) pairs."""
    plan = [{"problem": pb, "config": cf, "starts": list(starts), "data": str(data)} for pb, cf in pairs]
    out = {}
    for run, v in sweep("solvers", plan, lambda r: f"{r['problem']}--{r['config']}", run_pair, record=record,
                        quick=quick, scheduler=scheduler):
        if "error" in v:  # the pair's function itself raised (not a solver failure)
            v = {"runs": [{"start": s, "success": False, "status": "sweep error", "tail": v["error"]} for s in starts]}
        out[(run["problem"], run["config"])] = _clean(v["runs"])
    return out


def main(quick: bool = False, out_dir: Path | None = None, record: Path | None = None,
         scheduler: str | None = None, raw_path: Path | None = None) -> dict:
    """Run both stages, write the page and the performance profile, check the key numbers."""
    from casflex.data import save_measurements, simulated_set
    from casflex.model import assemble
    from casflex.scene_io import load_scene

    banner = Banner("solvers", quick)
    starts, configs = (QUICK_STARTS, QUICK_CONFIGS) if quick else (STARTS, list(CONFIGS))
    problems = ["direct"] if quick else ["direct", "adapted", "ss", "ms"]
    with tempfile.TemporaryDirectory(prefix="casflex-solvers-") as tmp:
        rec = Path(record) if record is not None else Path(tmp)
        rec.mkdir(parents=True, exist_ok=True)
        data = rec / "simulated_set.npz"
        if not data.exists():
            model = assemble(load_scene("twobar"))
            assert np.allclose(model.p_nominal, P_STAR), "twobar's nominal parameters changed: update P_STAR"
            save_measurements(simulated_set(model, T_DATA), data)
        results = _stage([(pb, cf) for pb in problems[:2] for cf in configs], starts, data, rec, scheduler, quick)
        screened = [cf for cf in configs if any(_flag(cf, r) and _criterion("direct", r)
                                                for r in results[("direct", cf)])]
        if not quick:
            pairs = [(pb, cf) for pb in ("ss", "ms") for cf in screened]
            if "fatrop-auto" not in screened:
                pairs.append(("ms", "fatrop-auto"))  # its structure detection is meant for multiple shooting
            results.update(_stage(pairs, starts, data, rec, scheduler, quick))
    raw = {"banner": banner.line(), "quick": quick, "starts": starts, "configs": configs, "problems": problems,
           "screened": screened, "results": {f"{pb}--{cf}": runs for (pb, cf), runs in results.items()}}
    save_raw(raw, raw_path)
    an = render(raw, out_dir)

    for st in starts:
        r = next(x for x in results[("direct", "ipopt")] if x["start"] == st)
        assert r.get("success") and _criterion("direct", r), f"IPOPT must solve the direct problem from {st:g} x p*"
    for pb, sp in an["spread"].items():
        if pb != "adapted":  # the consensus of the runs that report success is p*
            dev = float(np.abs(np.asarray(sp["median_p"]) / np.asarray(P_STAR) - 1.0).max())
            assert dev <= P_TOL, f"{pb}: the median p of the runs that report success is {dev:.1e} off p*"
    return {"raw": raw, "summary": an}


# -- analysis, page and figure ------------------------------------------------------------------

def _med(v) -> float:
    v = [x for x in v if x is not None and math.isfinite(x)]
    return float(np.median(v)) if v else math.nan


def _analyse(raw: dict) -> dict:
    """Per (problem, config) counts and measures; the cross-solver spread of p among flagged runs."""
    rows = {}
    for k, runs in raw["results"].items():
        pb, cf = k.split("--")
        ok = [_flag(cf, r) and _criterion(pb, r) for r in runs]
        m = [r for r in runs if "err" in r]
        rows[(pb, cf)] = {
            "n": len(runs), "solved": sum(ok), "flag": sum(_flag(cf, r) for r in runs),
            "wrong": sum(_flag(cf, r) and not o for r, o in zip(runs, ok, strict=True)),
            "rescued": sum(not _flag(cf, r) and _criterion(pb, r) for r in runs),
            "solver_off": sum(_flag(cf, r) and not _right(pb, _solver_err(pb, r)) for r in runs),
            "it": [r["iterations"] for r in m], "build": [r["build_s"] for r in m], "solve": [r["solve_s"] for r in m],
            "err": [r["err_k" if pb == "adapted" else "err"] for r in m], "err_solver": [_solver_err(pb, r) for r in m],
            "statuses": sorted({str(r.get("status") or r.get("skipped") or r.get("error", "?"))[:60] for r in runs}),
            "runs": runs, "ok": ok}
    spread = {}
    for pb in raw["problems"]:
        flagged = [r for (p2, cf), row in rows.items() if p2 == pb for r in row["runs"] if _flag(cf, r) and "p" in r]
        if len(flagged) < 2:
            continue
        P, Ps = np.array([r["p"] for r in flagged]), np.array([r["p_solver"] for r in flagged if "p_solver" in r])
        ref = np.median(P, axis=0)
        rel, rels = np.abs(P / ref - 1.0), np.abs(Ps / ref - 1.0) if len(Ps) else None
        spread[pb] = {"n": len(P), "median_p": ref.tolist(), "final": float(rel.max()),
                      "final_per_param": rel.max(axis=0).tolist(),
                      "solver": float(rels.max()) if rels is not None else math.nan,
                      "solver_per_param": rels.max(axis=0).tolist() if rels is not None else None}
    return {"rows": rows, "spread": spread}


def _profile(raw: dict, rows: dict, key: str) -> np.ndarray:
    """Dolan-More ratios [config, problem instance], inf where not solved (``key``: "solve" or "total")."""
    inst = [(pb, st) for pb in raw["problems"] for st in raw["starts"]]
    T = np.full((len(raw["configs"]), len(inst)), np.inf)
    for i, cf in enumerate(raw["configs"]):
        for j, (pb, st) in enumerate(inst):
            row = rows.get((pb, cf))
            for r, o in zip(row["runs"], row["ok"], strict=True) if row else ():
                if r["start"] == st and o:
                    T[i, j] = r["solve_s"] + (r["build_s"] if key == "total" else 0.0)
    best = T.min(axis=0)
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(T) & np.isfinite(best), T / np.where(best > 0, best, 1.0), np.inf)


def _choice(raw: dict, rows: dict, pb: str) -> list[tuple]:
    """Ranking on one problem: most starts solved, fewest successes at a wrong p, then the smallest median
    build + solve time of the solved starts. Entries: (config, solved, n, median time, wrong, starts whose
    own p (before the polish) is right)."""
    ranked = []
    for cf in raw["configs"]:
        row = rows.get((pb, cf))
        if row is None or row["solved"] == 0:
            continue
        solved = [r for r, o in zip(row["runs"], row["ok"], strict=True) if o]
        own = sum(_right(pb, _solver_err(pb, r)) for r in solved)
        ranked.append((cf, row["solved"], row["n"], float(np.median([r["build_s"] + r["solve_s"] for r in solved])),
                       row["wrong"], own))
    return sorted(ranked, key=lambda x: (-x[1], x[4], x[3]))


def _survey_text(row: dict | None) -> str:
    """The direct problem's outcome of one configuration, for the survey table."""
    if row is None:
        return "not run"
    runs = row["runs"]
    crashed = next((r for r in runs if r.get("crashed")), None)
    if crashed is not None:
        sig = crashed["status"].replace("crashed (", "").rstrip(")")
        return (f"**crashes**: {sig}{' (segmentation fault)' if sig == 'signal 11' else ''}"
                + (f": {crashed['tail'][:160]}" if crashed.get("tail") else ""))
    errs = [r for r in runs if "error" in r]
    if len(errs) == len(runs):
        return f"**cannot run**: {errs[0]['error'].split(' [CasADi:')[0][:200]}"
    s = f"solved {row['solved']}/{row['n']}" + (f", {row['wrong']} ✗!" if row["wrong"] else "")
    return s + (" (" + "; ".join(row["statuses"])[:140] + ")" if row["solved"] < row["n"] else "")


def _page(raw: dict, an: dict) -> list[str]:
    rows, spread, quick = an["rows"], an["spread"], raw["quick"]
    L = ["# NLP solver comparison" + (" (quick mode)" if quick else ""), "", raw["banner"], "",
         f"Starts {', '.join(f'{s:g}' for s in sorted(raw['starts']))} x p*, run nearest first "
         f"({', '.join(f'{s:g}' for s in raw['starts'])}). The set-up, the measures (*solved*, *flag*, ✗!, "
         "*rescued*, the solver's own p), the tolerance given to each plugin and notes on the plugins: "
         "[studies/solvers.md](../studies/solvers.md).", "", "Problems:", ""]
    L += [f"- `{pb}`: {PROBLEMS[pb][0]}" for pb in raw["problems"]]
    L += ["", "## Which plugins work here", "", *table(
        ["configuration", "plugin, linear/QP solver", "Hessian", "direct problem (stage 1)"],
        [[f"`{cf}`", *CONFIGS[cf][:2], _survey_text(rows.get(("direct", cf)))] for cf in raw["configs"]])]
    if not quick:
        dropped = ", ".join(f"`{c}`" for c in raw["configs"] if c not in raw["screened"])
        L += ["", f"Stage 2 (indirect problems) runs the {len(raw['screened'])} configurations that solved the direct "
              "problem from at least one start" + (f"; not run there: {dropped}." if dropped else ".")]
    L.append("")
    for pb in raw["problems"]:
        L += [f"## {PROBLEMS[pb][0]}", "", *table(
            ["configuration", "solved", "flag", "✗!", "rescued", "flag, solver's p off", "iterations", "build (s)",
             "solve (s)", "error of p (final)", "solver's p error", "status"],
            [[f"`{cf}`", f"{row['solved']}/{row['n']}", row["flag"], row["wrong"] or "", row["rescued"] or "",
              row["solver_off"] or "", med_range(row["it"], "g", "–"), fnum(_med(row["build"]), ".3g", "–"),
              med_range(row["solve"], ".3g", "–"), med_range(row["err"], ".1e", "–"),
              med_range(row["err_solver"], ".1e", "–"), "; ".join(row["statuses"])[:160]]
             for cf in raw["configs"] if (row := rows.get((pb, cf))) is not None], "lcccccrrrrrl"),
              "", "Cells: median (min-max) over the starts that ran to the end"
              + ("; errors of p: of k1 and k3." if pb == "adapted" else "."), ""]
    L += ["## Cross-solver consistency", "",
          "Among all runs that report success on a problem (any solver, any start): the median p, and the largest "
          "relative deviation from it, of the final p and of the solvers' own p (before the polish).", "", *table(
              ["problem", "runs", "median p = [k1 kt1 k3 kt3]", "max deviation, final p (per parameter)",
               "max deviation, solvers' own p (per parameter)"],
              [[f"`{pb}`", sp["n"], f"[{' '.join(f'{v:.7g}' for v in sp['median_p'])}]",
                f"{sp['final']:.1e} ({' / '.join(f'{v:.1e}' for v in sp['final_per_param'])})",
                f"{fnum(sp['solver'], '.1e', '–')} ("
                + (" / ".join(f"{v:.1e}" for v in sp["solver_per_param"]) if sp["solver_per_param"] else "–") + ")"]
               for pb, sp in spread.items()], "lrlll")]
    R, Rt = _profile(raw, rows, "solve"), _profile(raw, rows, "total")
    L += ["", "## Performance profile", "", f"![performance profile](../figures/solvers{'_quick' * quick}.png)", "",
          *table(["configuration", "solved", "fastest (solve)", "within 2x", "within 10x", "fastest (build + solve)"],
                 [[f"`{raw['configs'][i]}`", f"{np.isfinite(R[i]).sum()}/{R.shape[1]}", (R[i] <= 1.0).sum(),
                   (R[i] <= 2).sum(), (R[i] <= 10).sum(), (Rt[i] <= 1.0).sum()]
                  for i in sorted(range(len(R)), key=lambda i: (-np.isfinite(R[i]).sum(), -(R[i] <= 2).sum()))],
                 "lrrrrr")]
    return L + ["", "## What the numbers say", "", *_conclusions(raw, rows), "", "### Default solver", "",
                *_default_text(raw, rows), "", "The rule for replacing a default is in "
                "[studies/solvers.md](../studies/solvers.md#default-solver).", ""]


def _conclusions(raw: dict, rows: dict) -> list[str]:
    """Per problem: how many configurations solve it, the best, IPOPT's rank, and those that stopped at the
    solution without declaring success (the flags, ✗! and rescued counts are in the tables)."""
    out = []
    for pb in raw["problems"]:
        ranked, n_cfg, what = _choice(raw, rows, pb), sum(1 for k in rows if k[0] == pb), PROBLEMS[pb][1]
        if not ranked:
            out.append(f"- **{what}** (`{pb}`): none of the {n_cfg} configurations solved it.")
            continue
        top = ", ".join(f"`{c}` {s_}/{n} in {t:.3g} s" for c, s_, n, t, _w, _o in ranked[:6])
        s = (f"- **{what}** (`{pb}`): {len(ranked)} of {n_cfg} configurations solve it from at least one "
             f"start. Best (starts solved, then median build + solve time of the solved starts): {top}.")
        for x in (x for name in ("ipopt", "ipopt-gn") for x in ranked if x[0] == name):
            s += f" `{x[0]}`: {x[1]}/{x[2]} in {x[3]:.3g} s (rank {ranked.index(x) + 1})."
        near = [cf for cf in raw["configs"] if rows.get((pb, cf), {}).get("rescued") and all(
            _right(pb, _solver_err(pb, r)) for r in rows[(pb, cf)]["runs"] if not _flag(cf, r) and _criterion(pb, r))]
        if near:
            s += (" " + ", ".join(f"`{c}`" for c in near) + " had their own p right where they did not declare "
                  "success: they reached the solution but stopped without it (line search stalled, or the "
                  "iteration cap on a stationarity test they could not meet at this problem's round-off floor).")
        out.append(s)
    return out


def _default_text(raw: dict, rows: dict) -> list[str]:
    """Per problem: keep the library's default solver, or recommend another (rule: docs/studies/solvers.md)."""
    out = []
    for pb in raw["problems"]:
        cands = [x for x in _choice(raw, rows, pb) if x[0] not in NOT_DEFAULT]
        cur = CURRENT[pb]
        x_cur = next((x for x in cands if x[0] == cur), None)
        head = f"- **{PROBLEMS[pb][1]}** (library default `{cur}`): "
        if not cands:
            out.append(head + "nothing solved it; keep the default.")
            continue
        b = cands[0]
        if x_cur is None:
            out.append(head + f"the default solved no start; **recommend `{b[0]}`** ({b[1]}/{b[2]} starts, median "
                       f"{b[3]:.3g} s).")
        elif (b[1], -b[4]) > (x_cur[1], -x_cur[4]):
            out.append(head + f"**recommend `{b[0]}`**: {b[1]}/{b[2]} starts solved against {x_cur[1]}/{x_cur[2]}.")
        elif b[0] != cur and x_cur[3] > SPEEDUP * b[3] and x_cur[3] - b[3] > SAVING:
            out.append(head + f"**recommend `{b[0]}`**: as robust ({b[1]}/{b[2]} starts) and faster, median "
                       f"{b[3]:.3g} s against {x_cur[3]:.3g} s build + solve ({x_cur[3] / b[3]:.1f}x, "
                       f"{x_cur[3] - b[3]:.2g} s per run).")
        else:
            why = "it is the best" if b[0] == cur else (
                f"the fastest at equal robustness, `{b[0]}` ({b[3]:.3g} s), saves {x_cur[3] - b[3]:.2g} s per run "
                f"({x_cur[3] / b[3]:.1f}x)")
            out.append(head + f"**keep it**: {x_cur[1]}/{x_cur[2]} starts, median {x_cur[3]:.3g} s build + solve; "
                       f"{why}.")
    return out


def _figure(raw: dict, rows: dict) -> bytes:
    """Dolan-More performance profiles of the solve time and of build + solve time."""
    import matplotlib
    from matplotlib.figure import Figure

    fig = Figure(figsize=(13, 6.5))
    axes = fig.subplots(1, 2, sharey=True)
    c10, c20 = matplotlib.colormaps["tab10"], matplotlib.colormaps["tab20b"]
    for ax, key, title in ((axes[0], "solve", "solve time"), (axes[1], "total", "build + solve time")):
        R = _profile(raw, rows, key)
        finite = R[np.isfinite(R)]
        taus = np.logspace(0, math.log10(max(2.0, float(finite.max()) * 1.5) if finite.size else 10.0), 400)
        # legend order: most instances solved, then the most often within 4x of the best
        order = sorted((i for i in range(len(R)) if np.isfinite(R[i]).any()),
                       key=lambda i: (-np.isfinite(R[i]).sum(), -(R[i] <= 4).sum()))
        for rank, i in enumerate(order):
            main = rank < 8 or raw["configs"][i] in ("ipopt", "ipopt-gn")
            ax.step(taus, [(R[i] <= t).sum() / R.shape[1] for t in taus], where="post", label=raw["configs"][i],
                    color=c10(rank) if rank < 10 else c20((rank - 10) % 20), ls="-" if rank < 10 else "--",
                    lw=2.4 if main else 1.0, alpha=1.0 if main else 0.6)
        ax.set_xscale("log")
        ax.set_xlabel("tau (time / best time on the instance)")
        ax.set_title(f"Dolan-More profile: {title}\n{R.shape[1]} instances = {len(raw['problems'])} problems x "
                     f"{len(raw['starts'])} starts", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.set_ylim(-0.02, 1.02)
    axes[0].set_ylabel("fraction of instances solved within tau x best")
    fig.legend(*axes[0].get_legend_handles_labels(), loc="center right", fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0, 0.84, 1))
    return png(fig)


def render(raw: dict, out_dir: Path | None) -> dict:
    """The page and the figure from the raw numbers (of this run, or of a ``--raw`` file)."""
    raw = _clean(raw)
    an = _analyse(raw)
    write_outputs("solvers", out_dir, raw["quick"], "\n".join(_page(raw, an)), _figure(raw, an["rows"]))
    return an


if __name__ == "__main__":
    cli(__doc__, main, render)
