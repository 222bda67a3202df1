"""Basins of convergence: which starting factors in [0.3, 3] x p* lead each method (direct, adapted
direct, indirect by single and multiple shooting) to p*?

Set-up and how to read the page: docs/studies/basins.md. Run: ``python studies/basins.py`` (about 53 min; ``--quick``:
horizon 0.05 s, factors 0.5 and 2; ``--record DIR``, ``--scheduler ADDRESS``, ``--raw FILE``, ``--render FILE``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _shared import PAPER_NLP, capped_ipopt
from _study import Banner, cli, fmt_p, save_raw, sweep, table, write_outputs

from casflex.model import assemble
from casflex.scene_io import load_scene

TOL = 1e-6  # max relative error of p (indirect, direct)
TOL_ADAPTED = 1e-4  # max relative error of k1, k3 (adapted direct)
T1 = 0.69
ADAPTED_INSTANTS = [0.4, 1.1, 1.6, 1.9, 2.3]
FACTORS = [0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.1, 1.2, 1.5, 2.0, 2.5, 3.0]
QUICK_FACTORS = [0.5, 2.0]
EDGE_FACTORS = [0.1, 0.2, 5.0, 10.0]  # full mode, for methods that converge from every factor above
# IPOPT wall-time cap per indirect run (s): a stalled run would otherwise go on for IPOPT's 500
# iterations (~40 min); converging runs take well under it. A capped run counts as not converged.
WALL_CAP = 180.0
MUST_SHOW = (0.5, 2.0)  # the claim: multiple shooting, positions, 0..0.69 s converges from all of these

# key: (label, paper's range, paper's range as numbers or None, kind, options)
METHODS = {
    "direct": ("direct, simulated set, t = 0.69 s", "converges from near p* on the simulated set", None,
               "direct", {}),
    "adapted": ("adapted direct, instants [0.4 1.1 1.6 1.9 2.3] s (k1, k3 within 1e-4)",
                "k1, k3 from 0.3 p* (kt weakly determined)", (0.3, None), "adapted", {}),
    "ss-pos": ("indirect Eq. 16, single shooting", "0.90-1.18 (Eq. 16, t1)", (0.90, 1.18), "indirect",
               {"transcription": "single-shooting", "residue": "positions", **PAPER_NLP}),
    "ms-pos": ("indirect Eq. 16, multiple shooting", "0.90-1.18 (Eq. 16, t1)", (0.90, 1.18), "indirect",
               {"transcription": "multiple-shooting", "residue": "positions", **PAPER_NLP}),
    "ms-pos-log": ("indirect Eq. 16, multiple shooting, log transform", "0.90-1.18 (Eq. 16, t1)", (0.90, 1.18),
                   "indirect", {"transcription": "multiple-shooting", "residue": "positions", "transform": "log",
                                **PAPER_NLP}),
    "ss-full": ("indirect Eq. 17, single shooting", "0.93-1.10 (Eq. 17, t1)", (0.93, 1.10), "indirect",
                {"transcription": "single-shooting", "residue": "full", **PAPER_NLP}),
    "ms-full": ("indirect Eq. 17, multiple shooting", "0.93-1.10 (Eq. 17, t1)", (0.93, 1.10), "indirect",
                {"transcription": "multiple-shooting", "residue": "full", **PAPER_NLP}),
}


def one_run(*, method: str, factor: float, horizon: float, t_end: float) -> dict:
    """One identification of the grid (a sweep run, on any worker)."""
    from casflex.sweep import identification_run

    kind, opts = METHODS[method][3:]
    common = {"start": factor, "scene": "twobar", "t_end": t_end, "data": "simulated"}
    if kind == "direct":
        return identification_run(method="direct", instants=(T1,), **common)
    if kind == "adapted":
        return identification_run(method="adapted-direct", instants=tuple(ADAPTED_INSTANTS), **common)
    return identification_run(method="indirect", horizon=horizon, solver_options=capped_ipopt(WALL_CAP), **opts,
                              **common)


def cell(key: str, factor: float, out: dict, p_star: np.ndarray) -> dict:
    """A recorded run as a cell of the basin table (a run that raised counts as not converged)."""
    if "error" in out:
        return {"method": key, "factor": factor, "p": [float("nan")] * p_star.size, "err": float("inf"),
                "err_k": float("inf"), "err_kt": float("inf"), "metric": float("inf"), "success": False,
                "status": "error", "iterations": -1, "wall_s": 0.0, "converged": False, "false_success": False,
                "message": str(out["error"]).splitlines()[-1][:200]}
    p = np.array([float(v) for v in out["parameters"].values()])
    rel = np.abs(p / p_star - 1.0)
    err_k, err_kt, err = float(rel[[0, 2]].max()), float(rel[[1, 3]].max()), float(rel.max())
    adapted = METHODS[key][3] == "adapted"
    metric = err_k if adapted else err
    conv = bool(out["success"] and metric <= (TOL_ADAPTED if adapted else TOL))
    return {"method": key, "factor": factor, "p": p.tolist(), "err": err, "err_k": err_k, "err_kt": err_kt,
            "metric": metric, "success": bool(out["success"]), "status": out["status"],
            "iterations": out["iterations"], "wall_s": float(out["wall_s"]), "converged": conv,
            "false_success": bool(out["success"] and not conv), "message": ""}


def grid(pairs: list[tuple[str, float]], horizon: float, t_end: float, p_star: np.ndarray, **kw) -> dict:
    """Run the (method, factor) pairs through the sweep; cells per method, in the pairs' order."""
    plan = [{"method": k, "factor": f, "horizon": horizon, "t_end": t_end} for k, f in pairs]
    cells: dict[str, list[dict]] = {}
    for run, out in sweep("basins", plan, lambda r: f"{r['method']}_f{r['factor']:g}_h{horizon:g}_T{t_end:g}",
                          one_run, **kw):
        c = cell(run["method"], run["factor"], out, p_star)
        cells.setdefault(run["method"], []).append(c)
        print(f"{c['method']:<11s} start {c['factor']:>4g} x p*: {'OK ' if c['converged'] else 'no '} "
              f"err {c['err']:.2e} {c['status']}, {c['iterations']} it, {c['wall_s']:.1f} s", flush=True)
    return cells


def range_text(cells: list[dict]) -> str:
    """Converging factors as runs of consecutive tested factors, e.g. '0.3-0.9, 1.2-3'."""
    cells = sorted(cells, key=lambda c: c["factor"])
    if all(c["converged"] for c in cells):
        return f"all tested ({cells[0]['factor']:g}-{cells[-1]['factor']:g})"
    runs, cur = [], []
    for c in cells + [{"converged": False}]:
        if c["converged"]:
            cur.append(c["factor"])
        elif cur:
            runs.append(cur)
            cur = []
    return ", ".join(f"{r[0]:g}-{r[-1]:g}" if len(r) > 1 else f"{r[0]:g}" for r in runs) or "none"


def block(cells: list[dict]) -> tuple[float | None, float | None]:
    """The contiguous block (lo, hi) of converging factors around 1."""
    lo = hi = None
    for c in sorted((c for c in cells if c["factor"] < 1), key=lambda c: -c["factor"]):
        if not c["converged"]:
            break
        lo = c["factor"]
    for c in sorted((c for c in cells if c["factor"] > 1), key=lambda c: c["factor"]):
        if not c["converged"]:
            break
        hi = c["factor"]
    return lo, hi


def main(quick: bool = False, out_dir: Path | None = None, raw_path: Path | None = None,
         record: Path | None = None, scheduler: str | None = None) -> dict:
    banner = Banner("basins", quick)
    p_star = assemble(load_scene("twobar")).p_nominal
    t_end, factors, horizon = (2.4, QUICK_FACTORS, 0.05) if quick else (3.0, FACTORS, T1)
    keys = ["direct", "adapted", "ss-pos"] if quick else list(METHODS)
    kw = {"record": record, "quick": quick, "scheduler": scheduler}
    results = grid([(k, f) for k in keys for f in factors], horizon, t_end, p_star, **kw)
    wide = [] if quick else [k for k in keys if all(c["converged"] for c in results[k])]
    edge = grid([(k, f) for k in wide for f in EDGE_FACTORS], horizon, t_end, p_star, **kw) if wide else {}
    must = None
    if "ms-pos" in results:
        cells = [c for c in results["ms-pos"] if MUST_SHOW[0] <= c["factor"] <= MUST_SHOW[1]]
        failed = [c for c in cells if not c["converged"]]
        must = {"holds": not failed, "factors": [c["factor"] for c in cells],
                "failed": [(c["factor"], c["err"], c["status"]) for c in failed]}
    raw = {"quick": quick, "factors": factors, "horizon": horizon, "keys": keys, "results": results, "edge": edge,
           "must_show": must, "total_s": banner.wall, "banner": banner.line()}
    save_raw(raw, raw_path)
    render(raw, out_dir)
    # self-check: the direct problem is linear in p, so every start must give p*
    assert all(c["converged"] for c in results["direct"]), "direct identification must converge from every start"
    return raw


def render(raw: dict, out_dir: Path | None) -> None:
    """The page from the raw numbers of a run (``main`` or a ``--raw`` file)."""
    write_outputs("basins", out_dir, raw["quick"], "\n".join(page(raw)))


def _mark(c: dict) -> str:
    return "✓" if c["converged"] else ("✗!" if c["false_success"] else "✗")


def page(raw: dict) -> list[str]:
    """The basin table, the claim, the probes further out, every run and the measured findings."""
    quick, factors, horizon, keys, results = raw["quick"], raw["factors"], raw["horizon"], raw["keys"], raw["results"]
    edge, must = raw.get("edge") or {}, raw["must_show"]
    banner = raw.get("banner") or f"Generated by `python studies/basins.py{' --quick' if quick else ''}`."
    L = ["# Basins of convergence" + (" (quick mode)" if quick else ""), "",
         f"{banner} Indirect methods compare every sample of the horizon 0..{horizon:g} s"
         + (" (quick mode: the CI check, not the paper's horizon 0..0.69 s)" if quick else "")
         + f". Converged (✓): max_j |p_j/p*_j - 1| <= {TOL:g} and solver success; adapted direct: k1 and k3 within "
         f"{TOL_ADAPTED:g}" + ("" if quick else f"; each indirect run is capped at {WALL_CAP:.0f} s of solver wall "
                                "time (a capped run counts as not converged)")
         + ". Set-up and what the outcomes mean: [studies/basins.md](../studies/basins.md).", "",
         "## Converged starts", "",
         *table(["method", *(f"{f:g}" for f in factors), "converged range", "paper's range"],
                [[METHODS[k][0], *map(_mark, results[k]), range_text(results[k]), METHODS[k][1]] for k in keys],
                "l" + "c" * len(factors) + "ll"),
         "", "✗! = the solver reported success, but p misses the criterion (see the notes below).", ""]
    claim = (f"**Claim: \"Indirect, multiple shooting, positions only, horizon 0 to {horizon:g} s: converges to p* "
             "(1e-6 relative) from every start factor in [0.5, 2]\" — ")
    if must is not None and must["holds"]:
        L += [claim + f"HOLDS** (tested factors {_factors(must['factors'])}).", ""]
    elif must is not None:
        L += [claim + "DOES NOT HOLD**: " + "; ".join(f"{f:g}: error {e:.1e} ({s})" for f, e, s in must["failed"])
              + ".", ""]
    if edge:
        L += ["## Further out", "", f"Methods that converge from every factor above, probed at {_factors(EDGE_FACTORS)}"
              " x p* (max relative error in brackets):", "",
              *table(["method", *(f"{f:g}" for f in EDGE_FACTORS)],
                     [[METHODS[k][0], *(f"{_mark(c)} ({c['err']:.0e})" for c in cells)] for k, cells in edge.items()],
                     "l" + "c" * len(EDGE_FACTORS)), ""]
    L += ["## Every run", "", *table(
        ["method", "start", "identified p = [k1 kt1 k3 kt3]", "max rel. error", "k1, k3 error", "kt1, kt3 error",
         "success (status)", "iterations", "wall (s)", "converged"],
        [[k, f"{c['factor']:g}", fmt_p(c["p"]), f"{c['err']:.2e}", f"{c['err_k']:.1e}", f"{c['err_kt']:.1e}",
          f"{'yes' if c['success'] else 'no'} ({c['status']})", c["iterations"], f"{c['wall_s']:.1f}",
          "✓" if c["converged"] else "✗"]
         for k in keys for c in sorted(results[k] + edge.get(k, []), key=lambda c: c["factor"])], "lrlrrrlrrc")]
    return L + ["", "## What the numbers say", "", *findings(quick, keys, results, edge), ""]


def findings(quick: bool, keys: list[str], results: dict, edge: dict) -> list[str]:
    """Per method: the basin against the paper's range, and the runs that stop short of p* or claim a wrong p
    (the counts, ranges and times are in the tables)."""
    out = []
    for key in keys:
        label, _paper, rng, kind, _ = METHODS[key]
        cells, more, s = results[key], results[key] + edge.get(key, []), ""
        if rng is not None and kind != "adapted" and not quick and None not in (b := block(cells)):
            s += (f" Against the paper's {rng[0]:.2f}-{rng[1]:.2f}: "
                  + ("wider on both sides." if b[0] < rng[0] and b[1] > rng[1] else "not wider on both sides."))
        tol = TOL_ADAPTED if kind == "adapted" else TOL
        flagged = {  # the runs a reader should look at in the table of every run
            "Success short of the criterion, close to p*, from": [c["factor"] for c in more if c["false_success"]
                                                                   and c["metric"] < 1e-4],
            "**Success reported at a wrong p** from": [c["factor"] for c in more if c["false_success"]
                                                       and c["metric"] >= 1e-4],
            "Failures that ended within the criterion of p*:": [c["factor"] for c in more if not c["success"]
                                                                and c["metric"] <= tol]}
        s += "".join(f" {what} {_factors(fs)}." for what, fs in flagged.items() if fs)
        out += [f"- **{label}**:{s}"] if s else []
    return out or ["- Every run is in the tables above; no basin edge against the paper's, no flagged run."]


def _factors(factors) -> str:
    return ", ".join(f"{f:g}" for f in factors)


if __name__ == "__main__":
    cli(__doc__, main, render)
