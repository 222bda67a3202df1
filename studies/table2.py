"""Table 2 of the seed paper: what does the adapted direct identification (Eq. 14) give on its
three instant sets, and why does it differ from the paper?

Set-up and how to read the page: docs/studies/table2.md. Run: ``python studies/table2.py`` (``--quick``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _study import Banner, cli, fmt_p, table, write_outputs

from casflex.data import MeasurementSet, measured_set, simulated_set
from casflex.identification import identify_adapted_direct
from casflex.model import assemble
from casflex.scene_io import load_scene

#: (label, instants (s), the paper's identified [k1 kt1 k3 kt3])
SETS = [
    ("[0.5 1.0]", [0.5, 1.0], [700, -0.47, 400, 5.10]),
    ("[0.6 0.95 1.4 2.1 2.7]", [0.6, 0.95, 1.4, 2.1, 2.7], [700, 0.42, 400, 0.58]),
    ("[0.4 1.1 1.6 1.9 2.3]", [0.4, 1.1, 1.6, 1.9, 2.3], [700, 0.51, 400, 0.58]),
]
EARLY = [0.1, 0.2]
#: a converged run whose objective exceeds STALL x the best of its instant set stopped on the flat valley
STALL = 10.0
#: IPOPT options of the "tight" runs: tolerance at the round-off floor of the objective
TIGHT = {"ipopt": {"print_level": 0, "sb": "yes", "tol": 1e-16, "acceptable_tol": 1e-14, "acceptable_iter": 15,
                   "mu_strategy": "adaptive", "max_iter": 3000}}
K, KT = [0, 2], [1, 3]  # the linear and the torsional stiffnesses in p


def run(model, data: MeasurementSet, instants, start, transform="linear", solver_options=None, **tags) -> dict:
    """One identification and its identifiability report."""
    r = identify_adapted_direct(model, data, instants, start=start, transform=transform,
                                solver_options=solver_options)
    idf = r.identifiability
    out = {"p": r.p, "rel_err": r.p / model.p_nominal - 1.0, "success": r.success, "status": r.status,
           "iterations": r.iterations, "wall_s": r.wall_s, "objective": r.objective,
           "se": np.array(list(r.std_errors.values())), "weak": list(idf["weak"]),
           "rel_sens": np.array(list(idf["relative_sensitivity"].values())),
           "rel_se": np.array(list(idf["relative_std_errors"].values())),
           "collinearity": idf["collinearity_index"], "pcond": idf["parameter_condition"],
           "polish": r.extra["gauss_newton_polish"], "start": start, "transform": transform, **tags}
    print({k: v for k, v in tags.items() if k != "paper"}, f"start {start} {transform}: {fmt_p(r.p)} {r.status}")
    return out


def _pct(v) -> str:
    return " / ".join(f"{100 * x:+.2g}" for x in v)


def _e(v) -> str:
    return " / ".join(f"{x:.1e}" for x in v)


def _weak(r: dict) -> str:
    return ", ".join(r["weak"]) or "-"


def chord_rotations(model, q: np.ndarray) -> dict[str, np.ndarray]:
    """Rotation of each bar's chord since t = 0 at its two nodes (rows of q: time samples)."""
    names, q0, out = model.dof_names, model.q0, {}
    for a, b in (("2", "3"), ("4", "5")):
        ia, ib = names.index(f"x{a}"), names.index(f"x{b}")
        r, r0 = q[:, ib:ib + 2] - q[:, ia:ia + 2], q0[ib:ib + 2] - q0[ia:ia + 2]
        out[f"theta{a}"] = out[f"theta{b}"] = np.arctan2(r0[0] * r[:, 1] - r0[1] * r[:, 0],
                                                         r[:, 0] * r0[0] + r[:, 1] * r0[1])
    return out


def study(quick: bool) -> dict:
    """Every run of the page, and the scales that explain them."""
    model = assemble(load_scene("twobar"))
    t_end = 1.2 if quick else 3.0
    sets = SETS[:1] if quick else SETS
    starts = [0.3, 1.0] if quick else [0.3, 1.0, 3.0]
    sim = simulated_set(model, t_end=t_end)
    meas = measured_set(sim)
    d = {"model": model, "t_end": t_end, "sets": sets, "starts": starts,
         "sigmas": [1e-6] if quick else [1e-6, 1e-5, 1e-4], "main": [], "log": []}
    for label, inst, paper in sets:  # Table 2 proper: simulated set, linear and log transforms, every start
        for st in starts:
            for transform in ("linear", "log"):
                d["main" if transform == "linear" else "log"].append(
                    run(model, sim, inst, st, transform, label=label, paper=np.array(paper, dtype=float)))
    d["best"] = {label: min(r["objective"] for r in d["main"] + d["log"] if r["label"] == label)
                 for label, *_ in sets}
    d["measured"] = [run(model, meas, inst, 1.0, label=label, paper=np.array(paper, dtype=float), set="measured")
                     for label, inst, paper in sets]
    idx = [meas.index(t) for _, inst, _ in sets for t in inst]
    idx_sim = [sim.index(float(meas.t[i])) for i in idx]
    trans = ~model.is_rotation
    for what in ("qd", "qdd"):  # the difference quotients' error at the instants, and the scale it compares with
        exact = getattr(sim, what)[idx_sim][:, trans]
        d[f"fd_{what}"] = (float(np.abs(getattr(meas, what)[idx][:, trans] - exact).max()), float(np.abs(exact).max()))
    d["noise_label"], n_inst = sets[-1][:2]
    d["acc_rms"] = float(np.sqrt(np.mean(meas.qdd[[meas.index(t) for t in n_inst]][:, trans] ** 2)))
    d["noise"] = []
    for sigma in d["sigmas"]:
        for seed in [0] if quick else [0, 1, 2, 3, 4]:
            noisy = measured_set(sim, noise=sigma, seed=seed)
            r = run(model, noisy, n_inst, 1.0, sigma=sigma, seed=seed,
                    acc_noise=float(np.std(noisy.qdd[:, trans] - meas.qdd[:, trans])))
            r["covered"] = np.abs(r["p"] - model.p_nominal) <= 3 * r["se"]
            d["noise"].append(r)
    d["early"] = [run(model, sim, EARLY, st, transform, TIGHT if tight else None, early=EARLY, tight=tight)
                  for transform in ("linear", "log") for st in ([1.0] if quick else starts)
                  for tight in ((False,) if quick else (False, True))]
    beam = load_scene("twobar").beams[0]
    ia, ib = model.dof_names.index("x2"), model.dof_names.index("x3")
    d["k_bend"] = 4 * beam.E * beam.I / float(np.linalg.norm(model.q0[ib:ib + 2] - model.q0[ia:ia + 2]))
    col = {n: model.dof_names.index(n) for n in ("theta1", "theta2", "theta3", "theta4", "theta5")}
    d["rel_rot"] = {t: (sim.q[sim.index(t), col["theta2"]] - sim.q[sim.index(t), col["theta1"]],
                        sim.q[sim.index(t), col["theta4"]] - sim.q[sim.index(t), col["theta3"]])
                    for t in sorted({t for _, inst, _ in sets for t in inst} | set(EARLY))}
    all_idx = [sim.index(t) for _, inst, _ in sets for t in inst]
    chords = chord_rotations(model, sim.q[all_idx])
    d["chord_err"] = max(float(np.abs(chords[n] - sim.q[all_idx, col[n]]).max())
                         for n in ("theta2", "theta3", "theta4", "theta5"))
    return d


def tables(d: dict) -> list[str]:
    """The measured tables (how to read each: docs/studies/table2.md)."""
    p_star, best, noise = d["model"].p_nominal, d["best"], d["noise"]
    (fd_v, v_max), (fd_a, a_max) = d["fd_qd"], d["fd_qdd"]
    return [
        "## Identified parameters (linear transform)", "", "Relative errors in %, in the order k1 / kt1 / k3 / kt3.",
        "", *table(["instant set (s)", "start", "paper [k1 kt1 k3 kt3]", "paper rel. err. (%)", "ours",
                    "ours rel. err. (%)", "success (status)", "iter.", "time (ms)", "objective"],
                   [[r["label"], f"{r['start']:g} p*", fmt_p(r["paper"]), _pct(r["paper"] / p_star - 1), fmt_p(r["p"]),
                     _pct(r["rel_err"]), f"{r['success']} ({r['status']})", r["iterations"], f"{r['wall_s'] * 1e3:.0f}",
                 f"{r['objective']:.2e}"] for r in d["main"]], "lrlllllrrr"),
        "", "## Identifiability report", "", "At the solution, start 1.0 p*.", "",
        *table(["instant set (s)", "weak", "rel. sensitivity k1 / kt1 / k3 / kt3",
                "rel. std. error k1 / kt1 / k3 / kt3", "collinearity index", "parameter condition"],
               [[r["label"], _weak(r), _e(r["rel_sens"]), _e(r["rel_se"]), f"{r['collinearity']:.3g}",
                 f"{r['pcond']:.3g}"] for r in d["main"] if r["start"] == 1.0], "llllrr"),
        "", "## Log transform (p = scale exp(theta))", "",
        f"'stalled': a reported success whose objective is over {STALL:g} x the lowest found for that set.", "",
        *table(["instant set (s)", "start", "ours", "rel. err. (%)", "status", "iter.", "time (ms)", "objective",
                "objective / best"],
               [[r["label"], f"{r['start']:g} p*", fmt_p(r["p"]), _pct(r["rel_err"]), r["status"], r["iterations"],
                 f"{r['wall_s'] * 1e3:.0f}", f"{r['objective']:.2e}",
                 f"{ratio:.3g}" + (" **stalled**" if ratio > STALL else "")]
                for r in d["log"] for ratio in [r["objective"] / best[r["label"]]]], "lrlllrrrr"),
        "", "## Measured set: derivatives by central differences (no noise)", "",
        f"At the instants the difference quotients are off by up to {fd_v:.2e} m/s (of {v_max:.3g}) in velocity and "
        f"{fd_a:.2e} m/s^2 (of {a_max:.3g}) in acceleration.", "",
        *table(["instant set (s)", "paper", "paper rel. err. (%)", "ours, measured set", "rel. err. (%)", "status",
                "weak"],
               [[r["label"], fmt_p(r["paper"]), _pct(r["paper"] / p_star - 1), fmt_p(r["p"]), _pct(r["rel_err"]),
                 r["status"], _weak(r)] for r in d["measured"]]),
        "", f"## Noise experiment: instant set {d['noise_label']}", "",
        f"The RMS translational acceleration at the instants is {d['acc_rms']:.3g} m/s^2.", "",
        *table(["sigma (m)", "seed", "accel. noise (m/s^2)", "identified [k1 kt1 k3 kt3]", "SE",
                "covered k1 kt1 k3 kt3", "status", "iter.", "weak"],
               [[f"{r['sigma']:.0e}", r["seed"], f"{r['acc_noise']:.3g}", fmt_p(r["p"]), _e(r["se"]),
                 " ".join("yes" if c else "**no**" for c in r["covered"]), r["status"], r["iterations"], _weak(r)]
                for r in noise], "rrrllllrl"),
        "", "Coverage over all noisy runs: " + coverage(d) + "; largest linear-stiffness error "
        f"{100 * max(float(np.abs(r['rel_err'][K]).max()) for r in noise):.3g} %; successes "
        f"{sum(r['success'] for r in noise)} of {len(noise)}.",
        "", f"## Early instants {EARLY} s", "", "Relative joint rotations (rad) theta2 - theta1 / theta4 - theta3 at "
        + ", ".join(f"{t:g} s: {a:+.2e} / {b:+.2e}" for t, (a, b) in d["rel_rot"].items()) + ".", "",
        *table(["transform", "start", "solver", "identified [k1 kt1 k3 kt3]", "status", "iter.", "objective", "weak",
                "rel. sensitivity kt1 / kt3", "rel. SE kt1 / kt3", "collinearity"],
               [[r["transform"], f"{r['start']:g} p*", "tight" if r["tight"] else "default", fmt_p(r["p"]),
                 r["status"], r["iterations"], f"{r['objective']:.2e}", _weak(r), _e(r["rel_sens"][KT]),
                 _e(r["rel_se"][KT]), f"{r['collinearity']:.3g}"] for r in d["early"]], "lrlllrrlllr")]


def coverage(d: dict) -> str:
    """How often the 3-SE intervals of the noisy runs hold the truth, per parameter."""
    return ", ".join(f"{nm} {100 * np.mean([r['covered'][j] for r in d['noise']]):.0f} %"
                     for j, nm in enumerate(d["model"].parameter_names))


def _span(rows: list[dict], cols: list[int]) -> tuple[float, float]:
    return min(float(r["p"][cols].min()) for r in rows), max(float(r["p"][cols].max()) for r in rows)


def findings(d: dict) -> list[str]:
    """The measured numbers behind the reasons of docs/studies/table2.md that the tables do not hold."""
    p_star, early, noise = d["model"].p_nominal, d["early"], d["noise"]
    lin_def = [r for r in early if r["transform"] == "linear" and not r["tight"]]
    floor, lin_obj = min(r["objective"] for r in early), min(r["objective"] for r in lin_def)
    low_lo, low_hi = _span([r for r in early if r["objective"] <= 100 * floor], KT)
    rel_se_k = [r["se"][j] / max(abs(r["p"][j]), 1e-300) for r in noise for j in K if abs(r["p"][j]) > 1e-3 * p_star[j]]
    return ["", "## Why our numbers differ from the paper's", "",
            "The reasons, item by item: [studies/table2.md](../studies/table2.md#why-the-numbers-differ-from-the-"
            "papers); their numbers are in the tables above, and these:", "",
            f"- (2) the torsion moment (<= {max(abs(a) for a, _ in d['rel_rot'].values()) * p_star[1]:.2f} N m) "
            f"against the bar's end stiffness 4EI/L = {d['k_bend']:.3g} N m/rad: kt/(4EI/L) = "
            f"{p_star[1] / d['k_bend']:.1e}.",
            f"- (4) the chord angles start the rotations within {d['chord_err']:.1e} rad of the truth.",
            f"- (6) {sum(bool(np.any(r['p'] < 1e-6 * p_star)) for r in noise)} of {len(noise)} noisy runs have a "
            f"parameter at its bound 0; median relative SE of k1, k3: {float(np.median(rel_se_k or [np.nan])):.2g}.",
            f"- Early instants: the default linear runs' objective (>= {lin_obj:.2e}) is {lin_obj / floor:.2g} x the "
            f"lowest found ({floor:.2e}); every run within 100 x of that floor has kt in {low_lo:.3g} .. {low_hi:.3g} "
            "N m/rad; the Gauss-Newton polish took " + ", ".join(str(r["polish"]) for r in lin_def) + " steps.", ""]


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("table2", quick)
    d = study(quick)
    p_star = d["model"].p_nominal
    head = ["# Table 2: adapted direct identification", "",
            f"{banner.line()} p* = {fmt_p(p_star)} ({', '.join(d['model'].parameter_names)}); simulated set over "
            f"0..{d['t_end']} s. Set-up and how to read the tables: [studies/table2.md](../studies/table2.md).", ""]
    write_outputs("table2", out_dir, quick, "\n".join(head + tables(d) + findings(d)))
    # self-checks: the claims the page makes
    for r in d["main"]:
        assert np.abs(r["rel_err"][K]).max() < 1e-6, f"linear stiffnesses not exact: {r['p']}"
        assert {"kt1", "kt3"} <= set(r["weak"]), f"kt not flagged weak: {r['weak']}"
    for r in d["early"]:
        assert {"kt1", "kt3"} <= set(r["weak"]), f"early instants: kt not flagged weak: {r['weak']}"
    kt_sens = [float(r["rel_sens"][KT].max()) for r in d["main"] if r["start"] == 1.0]
    assert max(kt_sens) < 1e-4, kt_sens
    return {k: d[k] for k in ("main", "log", "measured", "noise", "early")} | {"wall_s": banner.wall}


if __name__ == "__main__":
    cli(__doc__, main)
