"""Table 3 of the seed paper: how accurately does the adapted direct procedure (Eq. 14) give the
rotations and the node-1 torsion multiplier on the instant set [0.4 1.1 1.6 1.9 2.3] s?

Run: ``python studies/table3.py`` (``--quick``). Set-up and why the numbers are what they are: docs/studies/table3.md.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _study import Banner, assert_checks, checks, cli, table, write_outputs

from casflex.data import MeasurementSet, measured_set
from casflex.identification import identify_adapted_direct
from casflex.model import assemble
from casflex.scene.io import load_scene
from casflex.simulate import simulated_set

INSTANTS = [0.4, 1.1, 1.6, 1.9, 2.3]
ROTS = ("theta2", "theta3", "theta4", "theta5")
#: the paper's Table 3 (x 1e-3): theta2, theta3, theta4, theta5, lambda; None where the OCR is unreadable
PAPER = {0.4: (0.05, 0.1, 0.1, 0.04, 1.68), 1.1: (0.06, 0.07, 0.05, None, 5.68), 1.6: (0.01, 0.06, 0.04, None, 1.88),
         1.9: (0.01, 0.03, 0.03, None, 3.42), 2.3: (0.1, 0.19, 0.17, None, 4.05)}


def errors(model, truth: MeasurementSet, data: MeasurementSet, instants: list[float]) -> dict:
    """Identify on ``data`` (start p*); relative errors against ``truth`` (the simulated set)."""
    r = identify_adapted_direct(model, data, instants, start=1.0)
    k_lam, cols = model.constraint_names.index("support1.theta"), [model.dof_names.index(d) for d in ROTS]
    kt1_err = r.parameters["kt1"] / model.p_nominal[1] - 1.0
    rows = []
    for k, t in enumerate(r.instants):
        i, rot = truth.index(t), r.extra["rotations"][f"{t:.10g}"]
        true = np.array([[truth.q[i, c], truth.qd[i, c], truth.qdd[i, c]] for c in cols]).T  # theta, theta', theta''
        est = np.array([rot[d] for d in ROTS]).T
        rows.append({"t": t, "err": np.abs(est - true) / np.abs(true), "abs_rot": np.abs(est[0] - true[0]),
                     "lam_err": abs(float(r.multipliers[k][k_lam]) / float(truth.meta["lam"][i, k_lam]) - 1.0)})
    # the multiplier's relative error is kt1's plus theta2's (docs/studies/table3.md): how far from |kt1's|
    return {"rows": rows, "p": r.p, "kt1_err": kt1_err, "status": r.status, "success": r.success,
            "iterations": r.iterations, "wall_s": r.wall_s,
            "lam_vs_kt": max(abs(row["lam_err"] - abs(kt1_err)) for row in rows),
            "abs_rot": max(float(row["abs_rot"].max()) for row in rows),
            "rel_rot": max(float(row["err"][0].max()) for row in rows)}


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("table3", quick)
    model = assemble(load_scene("twobar"))
    instants = INSTANTS[:2] if quick else INSTANTS
    sim = simulated_set(model, t_end=1.2 if quick else 3.0)
    runs = {label: errors(model, sim, data, instants) for label, data in
            (("simulated set (exact derivatives)", sim), ("measured set (central differences)", measured_set(sim)))}
    s, m = runs.values()

    def x3(v: float) -> str:
        return f"{1e3 * v:.2g}"

    def cells(row: dict, what: int) -> str:  # theta2..theta5's relative errors of theta (0), theta' (1), theta'' (2)
        return " / ".join(map(x3, row["err"][what]))

    paper = [PAPER.get(round(row["t"], 6)) for row in s["rows"]]
    check_lines, failed = checks([
        ("solver success on both data sets", f"{s['status']} / {m['status']}", s["success"] and m["success"]),
        ("rotations from exact data: max rel. error < 1e-4", f"{s['rel_rot']:.1e}", s["rel_rot"] < 1e-4),
        ("exact data: multiplier's rel. error = abs(kt1's) to 1e-5", f"{s['lam_vs_kt']:.1e}", s["lam_vs_kt"] < 1e-5)])
    page = [
        "# Table 3: identified rotations and torsion multiplier", "",
        f"{banner.line()} Instants {instants} s. Relative errors, **x 1e-3**; the set-up and why the numbers are what "
        "they are: [studies/table3.md](../studies/table3.md).", "", "## Rotations and multiplier (x 1e-3)", "",
        *table(["t (s)", "paper theta2 / theta3 / theta4 / theta5", "paper lambda",
                "ours, simulated set: theta2 / theta3 / theta4 / theta5", "lambda",
                "ours, measured set: theta2 / theta3 / theta4 / theta5", "lambda"],
               [[f"{rs['t']:.2f}", " / ".join("?" if v is None else f"{v:g}" for v in pp[:4]) if pp else "-",
                 f"{pp[4]:g}" if pp else "-", cells(rs, 0), x3(rs["lam_err"]), cells(rm, 0), x3(rm["lam_err"])]
                for rs, rm, pp in zip(s["rows"], m["rows"], paper, strict=True)], "rlrlrlr"),
        "", "## Rotation rates and accelerations (ours only, x 1e-3)", "",
        *table(["t (s)", "data", "theta' 2 / 3 / 4 / 5", "theta'' 2 / 3 / 4 / 5"],
               [[f"{row['t']:.2f}", label.split(" (")[0], cells(row, 1), cells(row, 2)]
                for label, res in runs.items() for row in res["rows"]], "rlll"),
        "", "## Per data set", "",
        *table(["data", "iterations", "time (ms)", "largest abs. rotation error (rad)", "abs(kt1 error) (x 1e-3)",
                "max over instants of abs(lambda error - abs(kt1 error))"],
               [[label, res["iterations"], f"{res['wall_s'] * 1e3:.0f}", f"{res['abs_rot']:.1e}",
                 x3(abs(res["kt1_err"])), f"{res['lam_vs_kt']:.1e}"] for label, res in runs.items()], "lrrrrr"),
        "", *check_lines]
    write_outputs("table3", out_dir, quick, "\n".join(page))
    assert_checks(failed)
    return {"runs": runs, "wall_s": banner.wall}


if __name__ == "__main__":
    cli(__doc__, main)
