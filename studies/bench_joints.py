"""Hinges against bushings: the rigid leg on ideal hinges and on stiff bushings, cost and accuracy.

The built-in leg_rigid (hip and knee as 2e5 N/m zero-length springs with dampers: bushings) and the
same leg on ideal hinges (tests/leg_hinged.py, foot fixed to the shank as in leg_rigid), both over
the first 0.5 s of the swing, compiled. Per step size: the wall time of the step (best of several
runs, both models side by side) and the error of the markers and of the hip force against each
model's own reference at a step 20 times below the smallest. What each costs for a given accuracy.
What is measured and what the numbers mean: docs/studies/bench_joints.md.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
from _study import Banner, assert_checks, best_of, checks, cli, png, table, write_outputs

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the hinged leg's derivation

T_END, DTS, QUICK_DTS = 0.5, (1e-2, 5e-3, 2e-3, 1e-3, 5e-4), (4e-3, 2e-3, 1e-3)


def models() -> dict:
    """{label: (model, hip force series of a trajectory)}: bushings and hinges, nodes at the path's rates."""
    from leg_hinged import hinged_leg

    import casflex

    rigid = casflex.load_scene("leg_rigid")
    v = casflex.assemble(rigid).supports_at(0.0)[1]  # no jerk at the start for either model
    rigid = dataclasses.replace(rigid, nodes=tuple(dataclasses.replace(
        n, vx=v[0], vy=v[1], omega=v[2] if n.name == "pelvis" else 0.0) for n in rigid.nodes))
    hinged = hinged_leg(rigid, casflex.load_scene("leg"), ankle=False)
    return {"bushings": (casflex.assemble(rigid), lambda tr: tr.output("hip_joint.force")),
            "hinges": (casflex.assemble(hinged), lambda tr: np.hypot(tr.output("hip_pin.fx"), tr.output("hip_pin.fy")))}


def run(model, force, dt: float, ref, repeat: int) -> dict:
    """One model at one step: best wall time of simulate(), and the errors against ``ref`` on its grid."""
    from casflex.model.markers import marker_positions
    from casflex.simulate import SimulationError, Stepping, simulate

    try:
        wall, tr = best_of(lambda: simulate(model, T_END,
                                            stepping=Stepping(dt=dt, compiled=True)), repeat, float("inf"))
    except SimulationError as exc:
        return {"dt": dt, "ok": False, "why": str(exc).split(":")[0]}
    k = np.round(tr.t / ref["dt"]).astype(int)
    return {"dt": dt, "ok": True, "ms": 1e3 * wall, "us_step": 1e6 * tr.stats["run_s"] / tr.stats["steps"],
            "marker_mm": 1e3 * float(np.abs(marker_positions(model, tr.q) - ref["markers"][k]).max()),
            "force_n": float(np.abs(force(tr) - ref["force"][k]).max()),
            "late_n": float(np.abs(force(tr) - ref["force"][k])[tr.t >= 0.1].max())}


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    from casflex.model.markers import marker_positions
    from casflex.simulate import Stepping, simulate

    banner = Banner("bench_joints", quick)
    dts = QUICK_DTS if quick else DTS
    rows = {}
    for label, (model, force) in models().items():
        fine = min(dts) / 20
        tr = simulate(model, T_END, stepping=Stepping(dt=fine, compiled=True))
        ref = {"dt": fine, "markers": marker_positions(model, tr.q), "force": force(tr)}
        rows[label] = [run(model, force, dt, ref, 2 if quick else 7) for dt in dts]
    ok = {k: [r for r in v if r["ok"]] for k, v in rows.items()}
    same = [(b, h) for b, h in zip(rows["bushings"], rows["hinges"], strict=True) if b["ok"] and h["ok"]]
    ratio = [h["us_step"] / b["us_step"] for b, h in same]
    body = []
    for label, rs in rows.items():
        body += [[label, f"{r['dt']:g}", *((f"{r['ms']:.1f}", f"{r['us_step']:.1f}", f"{r['marker_mm']:.2g}",
                                           f"{r['force_n']:.2g}", f"{r['late_n']:.2g}") if r["ok"]
                                         else ("fails", r["why"], "-", "-", "-"))]
                 for r in rs]
    page = ["# Hinges against bushings: the rigid leg", "", f"{banner.line()} What is measured and what the numbers "
            "mean: [studies/bench_joints.md](../studies/bench_joints.md).", "",
            f"![cost and accuracy against dt](../figures/bench_joints{'_quick' * quick}.png)", "",
            f"The hinged step costs **{min(ratio):.2f}-{max(ratio):.2f}** times the bushings' (per step, same dt, "
            "measured side by side).", "", f"## Cost and error over {T_END:g} s (compiled)", "",
            *table(["joints", "dt (s)", "simulate (ms)", "per step (us)", "markers: max error (mm)",
                    "hip force: max error (N)", "hip force after 0.1 s (N)"], body, "lrrrrrr"), ""]
    lines, failed = checks([
        ("every run of the hinged leg converges", f"{len(ok['hinges'])} / {len(dts)}", len(ok["hinges"]) == len(dts)),
        ("the hinged leg's hip force error at the coarsest step is below the bushings'",
         f"{rows['hinges'][0].get('force_n', np.nan):.2g} vs {rows['bushings'][0].get('force_n', np.inf):.2g} N",
         rows["hinges"][0]["ok"] and rows["hinges"][0]["force_n"] < rows["bushings"][0].get("force_n", np.inf))])
    write_outputs("bench_joints", out_dir, quick, "\n".join(page + lines), figure(rows))
    assert_checks(failed)
    return {"rows": rows, "ratio": ratio}


def figure(rows: dict) -> bytes:
    from casflex.plotting._figure import _new_figure

    fig = _new_figure((11, 4))
    for ax, key, label in zip(fig.subplots(1, 3), ("us_step", "marker_mm", "force_n"),
                              ("per step (us)", "markers: max error (mm)", "hip force: max error (N)"), strict=True):
        for name, rs in rows.items():
            ok = [r for r in rs if r["ok"]]
            ax.loglog([r["dt"] for r in ok], [r[key] for r in ok], "o-", label=name)
        ax.set(xlabel="dt (s)", title=label)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    return png(fig)


if __name__ == "__main__":
    cli(__doc__, main)
