"""Basins of convergence: which starting factors in [0.3, 3] x p* lead each method (direct, adapted
direct, indirect by single and multiple shooting) to p*?

Run: ``python studies/basins.py`` (about 53 min; ``--quick``: horizon 0.05 s, factors 0.5 and 2; ``--record DIR``,
``--scheduler ADDRESS``, ``--raw FILE``, ``--render FILE``). Set-up and what the outcomes mean: docs/studies/basins.md.
"""

from __future__ import annotations

from itertools import groupby
from pathlib import Path

import numpy as np
from _shared import paper_nlp
from _study import Banner, assert_checks, checks, cli, fmt_p, save_raw, sweep, table, write_outputs

from casflex.identification import Shooting
from casflex.model import assemble
from casflex.scene.io import load_scene

TOL = 1e-6  # max relative error of p (indirect, direct)
TOL_ADAPTED = 1e-4  # max relative error of k1, k3 (adapted direct)
T1 = 0.69
FACTORS = [0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.1, 1.2, 1.5, 2.0, 2.5, 3.0]
# IPOPT wall-time cap per indirect run (s): a stalled run would otherwise go on for IPOPT's 500
# iterations (~40 min); converging runs take well under it. A capped run counts as not converged.
WALL_CAP = 180.0
MUST_SHOW = (0.5, 2.0)  # the claim: multiple shooting, positions, 0..0.69 s converges from all of these

INDIRECT = {"method": "indirect"}
# key: (label, paper's range, identification_run's keywords)
METHODS = {
    "direct": ("direct, simulated set, t = 0.69 s", "converges from near p* on the simulated set",
               {"method": "direct", "instants": (T1,)}),
    "adapted": ("adapted direct, instants [0.4 1.1 1.6 1.9 2.3] s (k1, k3 within 1e-4)",
                "k1, k3 from 0.3 p* (kt weakly determined)",
                {"method": "adapted-direct", "instants": (0.4, 1.1, 1.6, 1.9, 2.3)}),
    "ss-pos": ("indirect Eq. 16, single shooting", "0.90-1.18 (Eq. 16, t1)",
               {**INDIRECT, "shooting": Shooting("single-shooting", residue="positions")}),
    "ms-pos": ("indirect Eq. 16, multiple shooting", "0.90-1.18 (Eq. 16, t1)",
               {**INDIRECT, "shooting": Shooting("multiple-shooting", residue="positions")}),
    "ms-pos-log": ("indirect Eq. 16, multiple shooting, log transform", "0.90-1.18 (Eq. 16, t1)",
                   {**INDIRECT, "shooting": Shooting("multiple-shooting", residue="positions"),
                    "transform": "log"}),
    "ss-full": ("indirect Eq. 17, single shooting", "0.93-1.10 (Eq. 17, t1)",
                {**INDIRECT, "shooting": Shooting("single-shooting", residue="full")}),
    "ms-full": ("indirect Eq. 17, multiple shooting", "0.93-1.10 (Eq. 17, t1)",
                {**INDIRECT, "shooting": Shooting("multiple-shooting", residue="full")}),
}


def one_run(*, method: str, factor: float, horizon: float, t_end: float) -> dict:
    """One identification of the grid (a sweep run, on any worker)."""
    from casflex.study.sweep import identification_run

    opts = METHODS[method][2]
    if opts["method"] == "indirect":
        own = {k: v for k, v in opts.items() if k != "transform"}
        opts = {**own, "horizon": horizon, **paper_nlp(WALL_CAP, opts.get("transform", "linear"))}
    return identification_run(**opts, start=factor, scene="twobar", t_end=t_end, data="simulated")


def cell(key: str, factor: float, out: dict, p_star: np.ndarray) -> dict:
    """A recorded run as a cell of the basin table (a run that raised counts as not converged)."""
    if "error" in out:
        out = {"parameters": dict.fromkeys(range(p_star.size), float("inf")), "success": False, "status": "error",
               "iterations": -1, "wall_s": 0.0}
    p = np.array([float(v) for v in out["parameters"].values()])
    rel = np.abs(p / p_star - 1.0)
    err_k, err = float(rel[[0, 2]].max()), float(rel.max())
    conv = bool(out["success"] and (err_k <= TOL_ADAPTED if key == "adapted" else err <= TOL))
    return {"method": key, "factor": factor, "p": p.tolist(), "err": err, "err_k": err_k,
            "err_kt": float(rel[[1, 3]].max()), "success": bool(out["success"]), "status": out["status"],
            "iterations": out["iterations"], "wall_s": float(out["wall_s"]), "converged": conv}


def look_at(c: dict) -> str:
    """Why a run that did not converge is worth a look (docs/studies/basins.md)."""
    metric, tol = (c["err_k"], TOL_ADAPTED) if c["method"] == "adapted" else (c["err"], TOL)
    if c["converged"]:
        return ""
    if c["success"]:
        return "success short of the criterion, near p*" if metric < 1e-4 else "**success at a wrong p**"
    return "failure within the criterion" if metric <= tol else ""


def range_text(cells: list[dict]) -> str:
    """Converging factors (``cells`` in the order of the factors) as runs of consecutive ones, e.g. '0.3-0.9, 1.2-3'."""
    if all(c["converged"] for c in cells):
        return f"all tested ({cells[0]['factor']:g}-{cells[-1]['factor']:g})"
    runs = [[c["factor"] for c in g] for ok, g in groupby(cells, key=lambda c: c["converged"]) if ok]
    return ", ".join(f"{r[0]:g}-{r[-1]:g}" if len(r) > 1 else f"{r[0]:g}" for r in runs) or "none"


def main(quick: bool = False, out_dir: Path | None = None, raw_path: Path | None = None,
         record: Path | None = None, scheduler: str | None = None) -> dict:
    banner = Banner("basins", quick)
    p_star = assemble(load_scene("twobar")).p_nominal
    t_end, factors, horizon = (2.4, [0.5, 2.0], 0.05) if quick else (3.0, FACTORS, T1)
    keys = ["direct", "adapted", "ss-pos"] if quick else list(METHODS)
    plan = [{"method": k, "factor": f, "horizon": horizon, "t_end": t_end} for k in keys for f in factors]
    results: dict[str, list[dict]] = {}
    for run, out in sweep("basins", plan, lambda r: f"{r['method']}_f{r['factor']:g}_h{horizon:g}_T{t_end:g}", one_run,
                          record=record, quick=quick, scheduler=scheduler):
        results.setdefault(run["method"], []).append(cell(run["method"], run["factor"], out, p_star))
    raw = {"quick": quick, "factors": factors, "horizon": horizon, "keys": keys, "results": results,
           "total_s": banner.wall, "banner": banner.line()}
    save_raw(raw, raw_path)
    assert_checks(render(raw, out_dir))
    return raw


def render(raw: dict, out_dir: Path | None) -> list[str]:
    """The page from the raw numbers of a run (``main`` or a ``--raw`` file); the failed self-checks."""
    factors, horizon, keys, results = raw["factors"], raw["horizon"], raw["keys"], raw["results"]
    must = [c for c in results.get("ms-pos", []) if MUST_SHOW[0] <= c["factor"] <= MUST_SHOW[1]]
    rows = [("direct (linear in p) converges from every start", range_text(results["direct"]),
             all(c["converged"] for c in results["direct"]))]
    if must:  # reported, not asserted
        rows.append((f"claim: indirect Eq. 16, multiple shooting, 0..{horizon:g} s converges from every start in "
                     f"[{MUST_SHOW[0]:g}, {MUST_SHOW[1]:g}]", "; ".join(
                         f"{c['factor']:g}: error {c['err']:.1e} ({c['status']})" for c in must if not c["converged"])
                     or "all converge", all(c["converged"] for c in must), False))
    check_lines, failed = checks(rows)

    def mark(c: dict) -> str:
        return "✓" if c["converged"] else "✗!" if c["success"] else "✗"  # ✗!: success, but p misses the criterion

    page = [
        "# Basins of convergence" + (" (quick mode)" if raw["quick"] else ""), "",
        f"{raw['banner']} Indirect methods compare every sample of the horizon 0..{horizon:g} s. Set-up, criteria and "
        "what the outcomes mean: [studies/basins.md](../studies/basins.md).", "", "## Converged starts", "",
        *table(["method", *(f"{f:g}" for f in factors), "converged range", "paper's range"],
               [[METHODS[k][0], *map(mark, results[k]), range_text(results[k]), METHODS[k][1]] for k in keys],
               "l" + "c" * len(factors) + "ll"),
        "", "## Every run", "", *table(
        ["method", "start", "identified p = [k1 kt1 k3 kt3]", "max rel. error", "k1, k3 error", "kt1, kt3 error",
         "success (status)", "iterations", "wall (s)", "converged", "look at"],
        [[k, f"{c['factor']:g}", fmt_p(c["p"]), f"{c['err']:.2e}", f"{c['err_k']:.1e}", f"{c['err_kt']:.1e}",
          f"{'yes' if c['success'] else 'no'} ({c['status']})", c["iterations"], f"{c['wall_s']:.1f}",
          "✓" if c["converged"] else "✗", look_at(c)]
         for k in keys for c in results[k]], "lrlrrrlrrcl"),
        "", *check_lines]
    write_outputs("basins", out_dir, raw["quick"], "\n".join(page))
    return failed


if __name__ == "__main__":
    cli(__doc__, main, render)
