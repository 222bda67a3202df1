"""Table 2 of the seed paper: adapted direct identification (Eq. 14) on three instant sets.

The data are the simulated set (x, y of every node with exact velocities and accelerations from
the HHT run; the rotations are unknowns). For each of the paper's instant sets and each start
(0.3, 1.0, 3.0 x p*) the identified [k1 kt1 k3 kt3] are set beside the paper's, with relative
errors, solver status, iterations, wall time and the identifiability report. Then:

- the same with the log transform of the parameters (a second solver path);
- the measured set (central-difference velocities and accelerations, no noise), the data the
  paper's values are closest to;
- a noise experiment on the third set: position noise sigma in {1e-6, 1e-5, 1e-4} m, several
  seeds; identified p and whether |p - p*| <= 3 SE (the reported standard errors cover the truth);
- early instants [0.1 0.2] s, where the joints have hardly rotated;
- the reasons the numbers differ from the paper's, computed from the data.

Writes docs/tables/table2.md. Run: ``python studies/table2.py`` (``--quick`` for the CI version).
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

from casflex.data import MeasurementSet, measured_set, simulated_set
from casflex.identification import identify_adapted_direct
from casflex.model import assemble
from casflex.results import atomic_write_text
from casflex.scene_io import load_scene

ROOT = Path(__file__).resolve().parents[1]

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


def _run(model, data: MeasurementSet, instants, start, transform="linear", solver_options=None) -> dict:
    r = identify_adapted_direct(model, data, instants, start=start, transform=transform,
                                solver_options=solver_options)
    idf = r.identifiability
    return {"p": r.p, "rel_err": r.p / model.p_nominal - 1.0, "success": r.success, "status": r.status,
            "iterations": r.iterations, "wall_s": r.wall_s, "build_s": r.wall_build_s, "solve_s": r.wall_solve_s,
            "objective": r.objective, "se": np.array(list(r.std_errors.values())), "weak": list(idf["weak"]),
            "rel_sens": np.array(list(idf["relative_sensitivity"].values())),
            "rel_se": np.array(list(idf["relative_std_errors"].values())),
            "collinearity": idf["collinearity_index"], "pcond": idf["parameter_condition"],
            "polish": r.extra["gauss_newton_polish"], "start": start, "transform": transform}


def _p(v) -> str:
    return "[" + " ".join(f"{x:.6g}" for x in v) + "]"


def _pct(v) -> str:
    return " / ".join(f"{100 * x:+.2g}" for x in v)


def _e(v) -> str:
    return " / ".join(f"{x:.1e}" for x in v)


def _chord_rotations(model, q: np.ndarray) -> dict[str, np.ndarray]:
    """Rotation of each bar's chord since t = 0 at its two nodes (rows of q: time samples)."""
    names = model.dof_names
    q0 = model.q0
    out = {}
    for a, b in (("2", "3"), ("4", "5")):
        ia, ib = names.index(f"x{a}"), names.index(f"x{b}")
        r = q[:, ib:ib + 2] - q[:, ia:ia + 2]
        r0 = q0[ib:ib + 2] - q0[ia:ia + 2]
        ang = np.arctan2(r0[0] * r[:, 1] - r0[1] * r[:, 0], r[:, 0] * r0[0] + r[:, 1] * r0[1])
        out[f"theta{a}"] = out[f"theta{b}"] = ang
    return out


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    out_dir = ROOT / "docs" if out_dir is None else Path(out_dir)
    print("=" * 78)
    print("table2: adapted direct identification (Eq. 14), paper's Table 2 and beyond")
    print("=" * 78)
    t_start = time.perf_counter()
    load0 = os.getloadavg()[0]
    model = assemble(load_scene("twobar"))
    names = model.parameter_names
    p_star = model.p_nominal
    t_end = 1.2 if quick else 3.0
    sets = SETS[:1] if quick else SETS
    starts = [0.3, 1.0] if quick else [0.3, 1.0, 3.0]
    sigmas = [1e-6] if quick else [1e-6, 1e-5, 1e-4]
    seeds = [0] if quick else [0, 1, 2, 3, 4]
    noise_set = sets[-1]

    t0 = time.perf_counter()
    sim = simulated_set(model, t_end=t_end)
    sim_s = time.perf_counter() - t0
    meas = measured_set(sim)
    print(f"simulated set 0..{t_end} s in {sim_s:.2f} s")

    # -- Table 2 proper: simulated set, linear and log transforms, every start --------------------
    main_rows, log_rows = [], []
    for label, inst, paper in sets:
        for st in starts:
            for transform, rows in (("linear", main_rows), ("log", log_rows)):
                r = _run(model, sim, inst, st, transform)
                r.update(label=label, paper=np.array(paper, dtype=float))
                rows.append(r)
                print(f"{label:24s} start {st:3.1f} x p* {transform:6s}: {_p(r['p'])} {r['status']} "
                      f"({r['iterations']} it, {r['wall_s'] * 1e3:.0f} ms, objective {r['objective']:.2e}) "
                      f"weak {r['weak']}")
    best_obj = {label: min(r["objective"] for r in main_rows + log_rows if r["label"] == label)
                for label, *_ in sets}

    # -- measured set (central differences, no noise) ----------------------------------------------
    meas_rows = []
    for label, inst, paper in sets:
        r = _run(model, meas, inst, 1.0)
        r.update(label=label, paper=np.array(paper, dtype=float))
        meas_rows.append(r)
        print(f"measured set {label:24s}: {_p(r['p'])} {r['status']}")
    idx = [meas.index(t) for _, inst, _ in sets for t in inst]
    idx_sim = [sim.index(float(meas.t[i])) for i in idx]
    trans = ~model.is_rotation
    fd_acc_err = float(np.abs(meas.qdd[idx][:, trans] - sim.qdd[idx_sim][:, trans]).max())
    fd_vel_err = float(np.abs(meas.qd[idx][:, trans] - sim.qd[idx_sim][:, trans]).max())
    acc_max = float(np.abs(sim.qdd[idx_sim][:, trans]).max())
    vel_max = float(np.abs(sim.qd[idx_sim][:, trans]).max())

    # -- noise experiment on the last set -----------------------------------------------------------
    n_label, n_inst, _ = noise_set
    n_idx = [meas.index(t) for t in n_inst]
    acc_rms = float(np.sqrt(np.mean(meas.qdd[n_idx][:, trans] ** 2)))
    noise_rows = []
    for sigma in sigmas:
        for seed in seeds:
            noisy = measured_set(sim, noise=sigma, seed=seed)
            acc_noise = float(np.std(noisy.qdd[:, trans] - meas.qdd[:, trans]))
            r = _run(model, noisy, n_inst, 1.0)
            r.update(sigma=sigma, seed=seed, acc_noise=acc_noise,
                     covered=np.abs(r["p"] - p_star) <= 3 * r["se"])
            noise_rows.append(r)
            print(f"noise {sigma:.0e} m seed {seed}: {_p(r['p'])} {r['status']} covered {r['covered'].tolist()}")

    # -- early instants -----------------------------------------------------------------------------
    early_rows = []
    for transform in ("linear", "log"):
        for st in ([1.0] if quick else starts):
            for tight in ((False,) if quick else (False, True)):
                r = _run(model, sim, EARLY, st, transform, TIGHT if tight else None)
                r.update(tight=tight)
                early_rows.append(r)
                print(f"early {EARLY} start {st} {transform} {'tight' if tight else 'default'}: {_p(r['p'])} "
                      f"objective {r['objective']:.2e} weak {r['weak']}")
    early_floor = min(r["objective"] for r in early_rows)

    # -- physical scales ----------------------------------------------------------------------------
    beam = load_scene("twobar").beams[0]
    ia, ib = model.dof_names.index("x2"), model.dof_names.index("x3")
    L = float(np.linalg.norm(model.q0[ib:ib + 2] - model.q0[ia:ia + 2]))
    k_bend = 4 * beam.E * beam.I / L
    rel_rot = {}
    for t in sorted({t for _, inst, _ in sets for t in inst} | set(EARLY)):
        i = sim.index(t)
        th = {d: sim.q[i, model.dof_names.index(d)] for d in ("theta1", "theta2", "theta3", "theta4")}
        rel_rot[t] = (th["theta2"] - th["theta1"], th["theta4"] - th["theta3"])
    all_idx = [sim.index(t) for _, inst, _ in sets for t in inst]
    chords = _chord_rotations(model, sim.q[all_idx])
    chord_err = max(float(np.abs(chords[d] - sim.q[all_idx, model.dof_names.index(d)]).max())
                    for d in ("theta2", "theta3", "theta4", "theta5"))
    total_s = time.perf_counter() - t_start
    load = (load0, os.getloadavg()[0])
    load = (min(load), max(load))

    # -- the page -----------------------------------------------------------------------------------
    suffix = "_quick" if quick else ""
    L_ = []
    L_ += [
        "# Table 2: adapted direct identification",
        "",
        f"Generated by `python studies/table2.py{' --quick' if quick else ''}` on {platform.machine()} "
        f"(Python {platform.python_version()}, {os.cpu_count()} CPUs, load average {load[0]:.1f} .. "
        f"{load[1]:.1f} during the run: wall times vary with the machine's load) in {total_s:.1f} s. "
        f"Scene `twobar`, p* = {_p(p_star)} "
        f"({', '.join(names)}). Data: the **simulated set** (HHT, alpha = 0, dt = 1e-3 s, 0..{t_end} s): "
        "x, y of every node with their exact velocities and accelerations; the rotations, their "
        "derivatives, the multipliers and p are unknowns (Eq. 14). Solver: IPOPT with exact (SX) "
        "derivatives, then Gauss-Newton polish (`identify_adapted_direct`). Bounds: stiffnesses >= 0, "
        "so a negative kt like the paper's -0.47 cannot occur here. Times are build + solve of one call.",
        "",
        "## Identified parameters (linear transform)",
        "",
        "Relative errors in %, in the order k1 / kt1 / k3 / kt3.",
        "",
        "| instant set (s) | start | paper [k1 kt1 k3 kt3] | paper rel. err. (%) | ours | ours rel. err. (%) "
        "| success (status) | iter. | time (ms) | objective |",
        "|---|---:|---|---|---|---|---|---:|---:|---:|",
    ]
    for r in main_rows:
        L_.append(f"| {r['label']} | {r['start']:g} p* | {_p(r['paper'])} | {_pct(r['paper'] / p_star - 1)} | "
                  f"{_p(r['p'])} | {_pct(r['rel_err'])} | {r['success']} ({r['status']}) | {r['iterations']} | "
                  f"{r['wall_s'] * 1e3:.0f} | {r['objective']:.2e} |")
    L_ += ["", "## Identifiability report", "",
           "From `r.identifiability` at the solution (the same from every start, shown for start 1.0 p*). "
           "Relative sensitivity: |dr/d ln p_j| with the rotations and multipliers profiled out, over the "
           "largest; a parameter is flagged weak below 1e-2 or above 10 % relative standard error.", "",
           "| instant set (s) | weak | rel. sensitivity k1 / kt1 / k3 / kt3 | rel. std. error k1 / kt1 / k3 / kt3 "
           "| collinearity index | parameter condition |",
           "|---|---|---|---|---:|---:|"]
    for r in main_rows:
        if r["start"] == 1.0:
            L_.append(f"| {r['label']} | {', '.join(r['weak']) or '-'} | {_e(r['rel_sens'])} | {_e(r['rel_se'])} | "
                      f"{r['collinearity']:.3g} | {r['pcond']:.3g} |")
    L_ += ["", "## Log transform (p = scale exp(theta))", "",
           "Same problems with log-scaled parameters. 'stalled' marks a reported success whose objective is "
           f"over {STALL:g} x the lowest found for that set (a stop on a flat valley, not a minimum; the "
           "objective's floor is reproduced to 3 digits by every run that reaches it).", "",
           "| instant set (s) | start | ours | rel. err. (%) | status | iter. | time (ms) | objective "
           "| objective / best |",
           "|---|---:|---|---|---|---:|---:|---:|---:|"]
    for r in log_rows:
        ratio = r["objective"] / best_obj[r["label"]]
        flag = " **stalled**" if ratio > STALL else ""
        L_.append(f"| {r['label']} | {r['start']:g} p* | {_p(r['p'])} | {_pct(r['rel_err'])} | {r['status']} | "
                  f"{r['iterations']} | {r['wall_s'] * 1e3:.0f} | {r['objective']:.2e} | {ratio:.3g}{flag} |")
    stalled_log = [r for r in log_rows if r["objective"] > STALL * best_obj[r["label"]]]
    stalled_lin = [r for r in main_rows if r["objective"] > STALL * best_obj[r["label"]]]

    L_ += ["", "## Measured set: derivatives by central differences (no noise)", "",
           "Positions only, velocities and accelerations by 2nd-order central differences (h = 1e-3 s), "
           "start 1.0 p*, linear transform. "
           f"At the instants the difference quotients are off by up to {fd_vel_err:.2e} m/s (of "
           f"{vel_max:.3g}) in velocity and {fd_acc_err:.2e} m/s^2 (of {acc_max:.3g}) in acceleration.", "",
           "| instant set (s) | paper | paper rel. err. (%) | ours, measured set | rel. err. (%) | status | weak |",
           "|---|---|---|---|---|---|---|"]
    for r in meas_rows:
        L_.append(f"| {r['label']} | {_p(r['paper'])} | {_pct(r['paper'] / p_star - 1)} | {_p(r['p'])} | "
                  f"{_pct(r['rel_err'])} | {r['status']} | {', '.join(r['weak']) or '-'} |")

    L_ += ["", f"## Noise experiment: instant set {n_label}", "",
           "Measured set with Gaussian position noise sigma (m; seeds as listed), central differences, start "
           "1.0 p*, linear transform. 'covered' lists, per parameter, whether |p - p*| <= 3 SE with the "
           "reported Gauss-Newton standard error. The acceleration noise is the measured std of the "
           f"difference-quotient accelerations' error (theory sqrt(6) sigma / h^2); the RMS translational "
           f"acceleration at the instants is {acc_rms:.3g} m/s^2.", "",
           "| sigma (m) | seed | accel. noise (m/s^2) | identified [k1 kt1 k3 kt3] | SE | covered k1 kt1 k3 kt3 "
           "| status | iter. | weak |",
           "|---:|---:|---:|---|---|---|---|---:|---|"]
    for r in noise_rows:
        cov = " ".join("yes" if c else "**no**" for c in r["covered"])
        L_.append(f"| {r['sigma']:.0e} | {r['seed']} | {r['acc_noise']:.3g} | {_p(r['p'])} | {_e(r['se'])} | "
                  f"{cov} | {r['status']} | {r['iterations']} | {', '.join(r['weak']) or '-'} |")
    cover_rate = {nm: np.mean([r["covered"][j] for r in noise_rows]) for j, nm in enumerate(names)}
    k_lo = min(float(r["p"][[0, 2]].min()) for r in noise_rows)
    k_hi = max(float(r["p"][[0, 2]].max()) for r in noise_rows)
    kt_lo = min(float(r["p"][[1, 3]].min()) for r in noise_rows)
    kt_hi = max(float(r["p"][[1, 3]].max()) for r in noise_rows)
    n_bound = sum(bool(np.any(r["p"] < 1e-6 * p_star)) for r in noise_rows)
    k_rse = float(np.median([r["se"][j] / max(abs(r["p"][j]), 1e-300) for r in noise_rows for j in (0, 2)
                             if abs(r["p"][j]) > 1e-3 * p_star[j]] or [np.nan]))
    worst_k = max(float(np.abs(r["rel_err"][[0, 2]]).max()) for r in noise_rows)
    L_ += ["", "Coverage over all noisy runs: " + ", ".join(f"{nm} {100 * v:.0f} %" for nm, v in cover_rate.items())
           + f"; largest linear-stiffness error {100 * worst_k:.3g} %; successes "
           f"{sum(r['success'] for r in noise_rows)} of {len(noise_rows)}."]

    L_ += ["", f"## Early instants {EARLY} s", "",
           "Relative joint rotations (rad) theta2 - theta1 / theta4 - theta3 at "
           + ", ".join(f"{t:g} s: {a:+.2e} / {b:+.2e}" for t, (a, b) in rel_rot.items()) + ". "
           "The torsion moment is kt times these. 'default': the library's IPOPT settings (tol 1e-9); "
           "'tight': tol 1e-16, up to 3000 iterations.", "",
           "| transform | start | solver | identified [k1 kt1 k3 kt3] | status | iter. | objective | weak "
           "| rel. sensitivity kt1 / kt3 | rel. SE kt1 / kt3 | collinearity |",
           "|---|---:|---|---|---|---:|---:|---|---|---|---:|"]
    for r in early_rows:
        L_.append(f"| {r['transform']} | {r['start']:g} p* | {'tight' if r['tight'] else 'default'} | {_p(r['p'])} | "
                  f"{r['status']} | {r['iterations']} | {r['objective']:.2e} | {', '.join(r['weak']) or '-'} | "
                  f"{_e(r['rel_sens'][[1, 3]])} | {_e(r['rel_se'][[1, 3]])} | {r['collinearity']:.3g} |")
    lin_def = [r for r in early_rows if r["transform"] == "linear" and not r["tight"]]
    kt_range = (min(float(r["p"][[1, 3]].min()) for r in lin_def), max(float(r["p"][[1, 3]].max()) for r in lin_def))
    low = [r for r in early_rows if r["objective"] <= 100 * early_floor]
    low_range = (min(float(r["p"][[1, 3]].min()) for r in low), max(float(r["p"][[1, 3]].max()) for r in low))
    lin_obj = min(r["objective"] for r in lin_def)
    all_success = all(r["success"] for r in lin_def)
    undetermined = low_range[1] / max(low_range[0], 1e-300) > 1.1
    L_ += ["",
           f"With the default settings and the linear transform, kt converges to {kt_range[0]:.3g} .. "
           f"{kt_range[1]:.3g} N m/rad depending on the start (k1, k3 stay within "
           f"{max(float(np.abs(r['rel_err'][[0, 2]]).max()) for r in lin_def):.1e} relative), "
           f"{'every run reports success' if all_success else 'not every run reports success'}, and "
           "the identifiability report flags kt1 and kt3 as weak (relative sensitivity < 1e-2), though their "
           "relative standard errors are tiny: the residual at the 'solution' is near zero, so s^2 and with "
           "it the SEs are too; here the SEs say nothing, the sensitivity does."]
    if lin_obj > 100 * early_floor:
        L_ += ["",
               "But those runs are **not** least-squares minima: their objective (>= "
               f"{lin_obj:.2e}) is {lin_obj / early_floor:.2g} x the lowest found ({early_floor:.2e}). "
               f"Every run within 100 x of that floor has kt in {low_range[0]:.3g} .. {low_range[1]:.3g} N m/rad"
               + (": at these instants kt is undetermined over that range at round-off level, and the values "
                  "far above it are stops of the solver on the flat valley (IPOPT's tolerance met, the "
                  "Gauss-Newton polish taking "
                  + ", ".join(str(r["polish"]) for r in lin_def) + " steps)." if undetermined else
                  ": the floor itself pins kt; the values far above it are stops of the solver on the flat "
                  "valley.")]
    L_ += [""]

    # -- why ours differ from the paper --------------------------------------------------------------
    sim_kt_err = [float(np.abs(r["rel_err"][[1, 3]]).max()) for r in main_rows if r["start"] == 1.0]
    sim_k_err = max(float(np.abs(r["rel_err"][[0, 2]]).max()) for r in main_rows)
    meas_kt_err = [float(np.abs(r["rel_err"][[1, 3]]).max()) for r in meas_rows]
    paper_kt_err = [float(np.abs(np.array(pp)[[1, 3]] / p_star[[1, 3]] - 1).max()) for *_, pp in sets]
    kt_sens = [float(r["rel_sens"][[1, 3]].max()) for r in main_rows if r["start"] == 1.0]
    spread = max(float(np.ptp([r["p"] for r in main_rows if r["label"] == lab], axis=0)[[1, 3]].max())
                 for lab, *_ in sets)
    L_ += ["## Why our numbers differ from the paper's", "",
           f"1. **Linear stiffnesses**: exact in both (ours within {sim_k_err:.1e} relative from every start, "
           "0.3 p* included), as the paper says.",
           "2. **Torsional stiffnesses are almost invisible in the residual.** Their profiled relative "
           "sensitivity is " + " / ".join(f"{v:.1e}" for v in kt_sens) + " (per set): once the unknown "
           "rotations re-adjust, a 1 % change of kt moves the residual about a millionth of what 1 % of k1 "
           "does. The physics: the moment kt (theta2 - theta1) (<= "
           f"{max(abs(a) for a, _ in rel_rot.values()) * p_star[1]:.2f} N m) competes at the node with the "
           f"bar's end moment, stiffness 4EI/L = {k_bend:.3g} N m/rad, so kt/(4EI/L) = {p_star[1] / k_bend:.1e}: "
           "a sub-microradian change of the unknown nodal rotation absorbs any change of kt. Whatever "
           "perturbs the residual at the 1e-6 level (data derivatives, Jacobian approximation, stopping "
           "rule) moves kt by O(1).",
           "3. **Exact derivatives vs finite differences.** Our simulated set carries the integrator's exact "
           "velocities and accelerations and the solver uses exact (AD) Jacobians and Hessians; then kt "
           "comes out within " + " / ".join(f"{100 * v:.2g} %" for v in sim_kt_err) + " (per set). The "
           "remaining error is the cubic's (Eq. 14) truncation over one step, the only residual left. "
           "Feeding central-difference derivatives instead (no noise) the kt error becomes "
           + " / ".join(f"{100 * v:.2g} %" for v in meas_kt_err) + ", against the paper's "
           + " / ".join(f"{100 * v:.3g} %" for v in paper_kt_err) + ". Both are orders of magnitude above "
           "the exact-data errors; the paper's are larger still, consistent with its further perturbations "
           "at the same level: the Jacobian dz/dp by central finite differences (Eq. 13) and a Gauss-Newton "
           "stop in a direction this flat (items 2 and 5). A negative kt, as in the paper's first set, "
           "cannot occur here (bound kt >= 0).",
           f"4. **Starting point.** The rotations start from the bars' chord angles, within {chord_err:.1e} "
           "rad of the true nodal rotations at every instant (the bars are nearly rigid), so the NLP starts "
           "next to the answer in the rotations; from " + ", ".join(f"{s_:g}" for s_ in starts)
           + f" x p* the linear transform lands on the same kt to {spread:.1e} N m/rad. "
           "The paper does not say how it started the rotation "
           "coefficients; a poorer start leaves the Gauss-Newton path in the flat kt direction at the mercy "
           "of the stopping rule.",
           f"5. **Stopping on the flat valley.** {len(stalled_log)} of {len(log_rows)} log-transform runs and "
           f"{len(stalled_lin)} of {len(main_rows)} linear runs above report a converged status with an "
           f"objective over {STALL:g} x the best for their set (marked 'stalled')"
           + (", with kt off by up to "
              + f"{100 * max(float(np.abs(r['rel_err'][[1, 3]]).max()) for r in stalled_log + stalled_lin):.3g} %"
              + ": a reported success is no proof of a minimum in kt; comparing objectives across starts is."
              if stalled_log + stalled_lin else "."),
           "6. **Noise.** sigma = " + (f"{sigmas[0]:g} m on the positions becomes {noise_rows[0]['acc_noise']:.2g}"
                                       if noise_rows else "?")
           + f" m/s^2 of acceleration noise through the 1/h^2 of the difference quotient, against an RMS "
           f"acceleration of {acc_rms:.2g} m/s^2 at the instants; the equilibrium residual is then dominated "
           f"by noise: over the noisy runs k1 and k3 come out anywhere in {k_lo:.3g} .. {k_hi:.3g} N/m and kt in "
           f"{kt_lo:.3g} .. {kt_hi:.3g} N m/rad ({n_bound} of {len(noise_rows)} runs with a parameter at its "
           "bound 0). The reported 3 SE intervals cover the truth for "
           + ", ".join(f"{nm} {100 * v:.0f} %" for nm, v in cover_rate.items())
           + f" of the runs, but the k1, k3 coverage is vacuous (median relative SE {k_rse:.2g}, i.e. the "
           "intervals span zero to twice the value) and kt's SE collapses at the bound or at huge values. "
           "The paper's future work (noisy positions) needs smoothed derivatives before "
           "this method can be used on such data.",
           ""]
    table = atomic_write_text(out_dir / "tables" / f"table2{suffix}.md", "\n".join(L_))
    print(f"wrote {table} ({total_s:.1f} s)")

    # self-checks: the claims the page makes
    for r in main_rows:
        assert np.abs(r["rel_err"][[0, 2]]).max() < 1e-6, f"linear stiffnesses not exact: {r['p']}"
        assert {"kt1", "kt3"} <= set(r["weak"]), f"kt not flagged weak: {r['weak']}"
    for r in early_rows:
        assert {"kt1", "kt3"} <= set(r["weak"]), f"early instants: kt not flagged weak: {r['weak']}"
    assert max(kt_sens) < 1e-4, kt_sens
    return {"main": main_rows, "log": log_rows, "measured": meas_rows, "noise": noise_rows, "early": early_rows,
            "wall_s": total_s}


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    main(quick=ap.parse_args().quick)
