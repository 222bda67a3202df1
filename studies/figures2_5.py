"""Figures 2-5 of the seed paper: how sensitive are the motion and the first joint's forces to the
parameter sets p*, p1 = [663 0.49 379 0.49] and p2 = [757 0.50 465 0.53]?

Run: ``python studies/figures2_5.py`` (``--quick``: 0.5 s horizon). Set-up, how to read the page and the paper's
statements read as thresholds: docs/studies/figures2_5.md.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _study import Banner, assert_checks, checks, cli, png, table, write_outputs

from casflex.model import assemble
from casflex.scene.io import load_scene
from casflex.simulate import Stepping, simulate

PARAMS = {"p*": None, "p1": [663, 0.49, 379, 0.49], "p2": [757, 0.50, 465, 0.53]}
NODE5 = ("x5", "y5", "theta5")
#: (figure file stem, title, kind, series, units)
FIGURES = [
    ("fig2_displacements", "Fig. 2: node-5 displacements", "q", NODE5, ("m", "m", "rad")),
    ("fig3_velocities", "Fig. 3: node-5 velocities", "qd", NODE5, ("m/s", "m/s", "rad/s")),
    ("fig4_accelerations", "Fig. 4: node-5 accelerations", "qdd", NODE5, ("m/s^2", "m/s^2", "rad/s^2")),
    ("fig5_joint_forces", "Fig. 5: forces and torque in the first joint", "out",
     ("spring1.fx", "spring1.fy", "torsion1.moment"), ("N", "N", "N m")),
]
KIND_WORD = {"q": "displacement", "qd": "velocity", "qdd": "acceleration", "out": "joint force"}
DT = 1e-3


def series(tr, kind: str, name: str) -> np.ndarray:
    return tr.output(name) if kind == "out" else getattr(tr, kind)[:, tr.dof_names.index(name)]


def rms(v: np.ndarray) -> float:
    return float(np.sqrt(np.mean(v ** 2)))


def figure(trajs: dict, title: str, kind: str, names, units) -> bytes:
    """One of the paper's figures: the runs (left), their differences from p* (right)."""
    from casflex.plotting._figure import _new_figure

    fig = _new_figure((11, 7.5))
    axes = fig.subplots(len(names), 2, sharex=True)
    pre = {"q": "", "qd": "d/dt ", "qdd": "d²/dt² ", "out": ""}[kind]
    for (ax, axd), name, unit in zip(axes, names, units, strict=True):
        ref = series(trajs["p*"], kind, name)
        for i, (label, tr) in enumerate(trajs.items()):
            ax.plot(tr.t, series(tr, kind, name), color=f"C{i}", lw=1.2, ls=["-", "--", "-."][i % 3],
                    label=f"{label} = [{' '.join(f'{v:g}' for v in tr.p)}]")
            if label != "p*":
                axd.plot(tr.t, series(tr, kind, name) - ref, color=f"C{i}", lw=1.0, label=f"{label} - p*")
        ax.set_ylabel(f"{pre}{name} ({unit})")
        axd.set_ylabel(f"difference ({unit})")
        for a in (ax, axd):
            a.grid(True, alpha=0.3)
    for top, bottom, head in zip(axes[0], axes[-1], ("runs", "difference from the p* run"), strict=True):
        top.legend(fontsize="small", loc="best")
        top.set_title(head, fontsize="medium")
        bottom.set_xlabel("time t (s)")
    fig.suptitle(f"twobar, {title} for p*, p1, p2")
    return png(fig)


def differences(trajs: dict, windows: list[float]) -> list[dict]:
    """Per plotted series: p*'s peak and RMS, each run's differences from it, level ratios and growth with T."""
    ref, rows = trajs["p*"], []
    for stem, _title, kind, names, units in FIGURES:
        for name, unit in zip(names, units, strict=True):
            r = series(ref, kind, name)
            row = {"fig": stem, "kind": kind, "name": name, "unit": unit, "ref_max": float(np.abs(r).max()),
                   "ref_rms": rms(r)}
            for label in ("p1", "p2"):
                x = series(trajs[label], kind, name)
                d = np.abs(x - r)
                row[label] = {"max": float(d.max()), "rms": rms(d), "rel_max": float(d.max()) / row["ref_max"],
                              "rel_rms": rms(d) / row["ref_rms"], "peak_ratio": float(np.abs(x).max()) / row["ref_max"],
                              "rms_ratio": rms(x) / row["ref_rms"],
                              "window": {w: float(d[ref.t <= w + 1e-12].max()) / row["ref_max"] for w in windows}}
            rows.append(row)
    return rows


def paper_checks(rows: list[dict], quick: bool) -> list[tuple]:
    """The paper's statement read as thresholds (docs/studies/figures2_5.md); only the full run asserts the order."""
    def rel(kind: str) -> list[float]:
        return [row[lab]["rel_max"] for row in rows if row["kind"] == kind for lab in ("p1", "p2")]

    order = [rows[j][lab][m] < rows[3 + j][lab][m] < rows[6 + j][lab][m]
             for j in range(3) for lab in ("p1", "p2") for m in ("rel_max", "rel_rms")]
    level = max(abs(row[lab][k] - 1.0) for row in rows if row["kind"] == "out" for lab in ("p1", "p2")
                for k in ("peak_ratio", "rms_ratio"))
    return [("displacement < velocity < acceleration (rel. max and RMS diff., x5, y5, theta5, p1 and p2)",
             f"{sum(order)} of {len(order)}", all(order), not quick),
            ("'displacements barely change': largest rel. max diff. < 5 %", f"{100 * max(rel('q')):.3g} %",
             max(rel("q")) < 0.05, False),
            ("'accelerations strongly': smallest rel. max diff. > 50 %", f"{100 * min(rel('qdd')):.3g} %",
             min(rel("qdd")) > 0.5, False),
            ("'force levels stay similar': joint forces' peak and RMS within 15 % of p*'s", f"{100 * level:.3g} %",
             level < 0.15, False)]


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("figures2_5", quick)
    t_end = 0.5 if quick else 3.0
    model = assemble(load_scene("twobar"))
    trajs = {label: simulate(model, t_end, stepping=Stepping(dt=DT),
                             p=model.p_nominal if p is None else np.array(p, dtype=float))
             for label, p in PARAMS.items()}
    windows = [w for w in (0.5, 1.0, 2.0, 3.0) if w <= t_end + 1e-12]
    rows = differences(trajs, windows)
    check_lines, failed = checks([("every simulation succeeds", "", all(tr.success for tr in trajs.values())),
                                  *paper_checks(rows, quick)])
    page = [
        "# Figures 2-5: sensitivity to the parameter sets p*, p1, p2", "",
        f"{banner.line()} dt = {DT:g} s, 0..{t_end:g} s; p = [k1 kt1 k3 kt3]: p* = {model.p_nominal.tolist()}, "
        f"p1 = {PARAMS['p1']}, p2 = {PARAMS['p2']}. The figures and how to read the tables: "
        "[studies/figures2_5.md](../studies/figures2_5.md).", "", "## Differences from the p* run", "",
        *table(["figure", "quantity", "unit", "p* peak", "p* RMS",
                *(f"{lab} {h}" for lab in ("p1", "p2") for h in ("max diff", "RMS diff", "rel. max / RMS (%)",
                                                                 "level ratio peak / RMS"))],
               [[row["fig"].split("_")[0], f"{KIND_WORD[row['kind']]} {row['name']}", row["unit"],
                 f"{row['ref_max']:.3g}", f"{row['ref_rms']:.3g}", *(v for d in (row["p1"], row["p2"]) for v in (
                     f"{d['max']:.3g}", f"{d['rms']:.3g}", f"{100 * d['rel_max']:.3g} / {100 * d['rel_rms']:.3g}",
                     f"{d['peak_ratio']:.3f} / {d['rms_ratio']:.3f}"))] for row in rows], "lllrr" + "rrll" * 2),
        "", "## Growth with the horizon (relative max difference within 0..T, %)", "",
        *table(["quantity", "run", *(f"T = {w:g} s" for w in windows)],
               [[f"{KIND_WORD[row['kind']]} {row['name']}", lab,
                 *(f"{100 * row[lab]['window'][w]:.3g}" for w in windows)] for row in rows for lab in ("p1", "p2")],
               "ll" + "r" * len(windows)), "", *check_lines]
    write_outputs("figures2_5", out_dir, quick, "\n".join(page),
                  {stem: figure(trajs, title, kind, names, units) for stem, title, kind, names, units in FIGURES})
    assert_checks(failed)
    return {"rows": rows, "wall_s": banner.wall}


if __name__ == "__main__":
    cli(__doc__, main)
