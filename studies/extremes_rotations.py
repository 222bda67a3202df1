"""Rotations at the extremes: do the absolute rotation dofs carry the chain through full turns, does a
finer mesh keep the local rotations in range, and where is the round-off floor of the tolerance?
Run: ``python studies/extremes_rotations.py [--quick]`` (about 1 min); set-up and reading: docs/studies/extremes.md.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
from _extremes import ALPHAS, CAUSES, DRIFT_TOL, HORIZONS, energy, finite, omega_max_of, reason, run_case
from _shared import twobar
from _study import Banner, assert_checks, checks, cli, table, write_outputs

import casflex
from casflex.simulate import Stepping, integrator_for, simulate

SPIN_OMEGA, SPIN_SPRING_SCALE = 10.0, 1e3  # rad/s; springs x1e3: centrifugal forces stretch them by mm, not m
EPS = float(np.finfo(float).eps)


def full_turns(quick: bool) -> dict:
    """The chain spun about the clamp: the rigid-body velocity field v = omega x r, omega at every node."""
    model = casflex.assemble(casflex.load_scene("twobar"))
    qd0 = np.zeros(model.n_dof)
    for i in range(1, model.n_dof // 3):  # node 1 is clamped
        qd0[3 * i:3 * i + 3] = (-SPIN_OMEGA * model.q0[3 * i + 1], SPIN_OMEGA * model.q0[3 * i], SPIN_OMEGA)
    p = model.p_nominal * np.array([SPIN_SPRING_SCALE, 1.0, SPIN_SPRING_SCALE, 1.0])
    om, rows = omega_max_of(model, p), []
    for a, dt, T in [(a, 1e-3, 3.0) for a in ALPHAS] if quick else \
            [(a, dt, T) for a in ALPHAS for dt in (1e-3, 1e-4) for T in HORIZONS]:
        row, tr = run_case(model, k_scale=SPIN_SPRING_SCALE, e_scale=1.0, alpha=a, dt=dt, t_end=T, omega_max=om,
                           qd0=qd0, p=p)
        th = {k: tr.dof(k) for k in ("theta2", "theta3", "theta4", "theta5")}
        chord = np.unwrap(np.arctan2(tr.dof("y5") - tr.dof("y4"), tr.dof("x5") - tr.dof("x4")))
        m1 = tr.output("torsion1.moment")
        rows.append({**row,  # a 2 pi jump of a rotation dof would show in max step and in rotation vs chord (~6.3)
                     "turns": float(np.ptp(th["theta5"]) / (2 * math.pi)),
                     "net_turns": float((th["theta5"][-1] - th["theta5"][0]) / (2 * math.pi)),
                     "max_step": float(np.abs(np.diff(np.column_stack(list(th.values())), axis=0)).max()),
                     "rot_vs_chord": float(np.abs(th["theta5"] - th["theta5"][0] - (chord - chord[0])).max()),
                     "m1_max": float(np.abs(m1).max()),
                     "m1_vs_kt": float(np.abs(m1 - p[1] * (tr.dof("theta2") - tr.dof("theta1"))).max()),
                     "spring1_max": float(tr.output("spring1.length").max())})
    return {"rows": rows, "omega_max": om}


def roundoff_probe(quick: bool) -> list[dict]:
    """The scene translated far from the origin: physically identical, numerically not (the residual cannot
    be computed below ~eps |q| / l). Does each converge, and how far is its motion from the original's?"""
    base, t_end, rows, ref = casflex.load_scene("twobar"), 0.2 if quick else 1.0, [], None
    for shift in (0.0, 1e4) if quick else (0.0, 1e3, 1e4, 1e5, 1e6):
        model = casflex.assemble(dataclasses.replace(base, nodes=tuple(dataclasses.replace(n, x=n.x + shift)
                                                                       for n in base.nodes)))
        tr = simulate(model, t_end, stepping=Stepping(dt=1e-3, alpha=0.0), raise_on_failure=False)
        it, ref = tr.newton_iterations, tr if ref is None else ref
        k, rot = min(len(tr.t), len(ref.t)), np.asarray(model.is_rotation)
        dq = tr.q[:k] - ref.q[:k]
        dq[:, 0::3] -= shift  # translated back
        rows.append({"shift": shift, "t_end": t_end, "success": bool(tr.success), "steps": int(tr.stats["steps"]),
                     "result": "ok" if tr.success else f"{tr.status} at t = {tr.t[-1]:.4g} s",
                     "sound": finite(tr) and (tr.success or CAUSES[tr.status][0] in tr.message),
                     "accepted_tol": float(integrator_for(model, alpha=0.0).tolerance(tr.q).max()),
                     "newton": f"{it.mean():.2f} ({it.max()})" if it.size else "- (-)", "drift": energy(tr)["drift"],
                     "max_dpos": float(np.abs(dq[:, ~rot]).max()), "max_drot": float(np.abs(dq[:, rot]).max()),
                     "max_dqd": float(np.abs(tr.qd[:k] - ref.qd[:k]).max()), "max_qd": float(np.abs(ref.qd[:k]).max())})
    return rows


def self_checks(raw: dict) -> list[tuple]:
    """(check, value, passed) rows of the page's self-checks."""
    turns, mesh, ro = raw["turns"]["rows"], raw["mesh"], raw["roundoff"]
    near = [r for r in ro if r["shift"] <= 1e4]
    out = [("full turns: every run converges through more than 2 turns, rotations continuous (no 2 pi jump, no local-"
            "rotation wrap) following the unwrapped chord, energy drift at alpha = 0 below 1e-3 (3 s), 1e-2 (30 s)",
            f"{len(turns)} runs", all(r["success"] and r["finite"] and not r["wraps"] and r["max_step"] < 0.5
                                      and r["rot_vs_chord"] < 0.1 and r["turns"] > 2
                                      and (r["alpha"] != 0 or r["energy"]["drift"] < DRIFT_TOL[r["t_end"]])
                                      for r in turns)),
           ("round-off probe: the scene translated by up to 1e4 m runs to the end", f"{len(near) - 1} translated runs",
            all(r["sound"] for r in ro) and ro[0]["shift"] == 0
            and all(r["success"] for r in near))]
    if mesh:
        m1, m8 = mesh["1"], mesh["8"]
        out.append(("E x1e-6: one element per bar stops with element_range, the wrap confirmed by the study in the "
                    "rejected step; eight elements per bar run the 3 s without a wrap",
                    f"{m1['status']}; {m8['status']}", m1["status"] == "element_range"
                    and bool(m1["flagged"]["wrap"]) and m8["success"] and not m8["wraps"]))
    return out


def page(raw: dict, check_lines: list[str]) -> str:
    turns, mesh, ro = raw["turns"], raw["mesh"] or {}, raw["roundoff"]
    sections = [  # (title, head, align, rows)
        (f"Full turns (spun at {SPIN_OMEGA:g} rad/s about node 1, springs x{SPIN_SPRING_SCALE:g}, f_max = "
         f"{turns['omega_max'] / (2 * math.pi):.4g} Hz)",
         ["alpha", "dt (s)", "horizon (s)", "converged", "theta5 spans (turns)", "net turns",
          "max step of a rotation (rad)", "rotation vs chord (rad)", "local-rotation wraps",
          "torsion1 max moment (N m)", "moment vs kt dtheta", "spring1 max length (m)", "energy drift"],
         "lrrlrrrrrrrrr",
         [["0" if r["alpha"] == 0 else "-1/3", f"{r['dt']:g}", f"{r['t_end']:g}", "yes" if r["success"] else "no",
           f"{r['turns']:.2f}", f"{r['net_turns']:+.2f}", f"{r['max_step']:.3g}", f"{r['rot_vs_chord']:.2e}",
           r["wraps"], f"{r['m1_max']:.3g}", f"{r['m1_vs_kt']:.1e}", f"{r['spring1_max']:.4f}",
           f"{r['energy']['drift']:.1e}"] for r in turns["rows"]]),
        ("Co-rotational local rotations through +-pi (E x1e-6, alpha = 0, dt = 1e-4, 3 s; full mode only)",
         ["elements per bar", "result", "stopped at t (s)", "message", "energy drift (returned states)",
          "wraps in the returned states", "max abs local rotation (rad)", "study: wraps, rejected step"], "rlrlrrrl",
         [[ne, "success" if m["success"] else m["status"], "-" if m["success"] else f"{m['t_reached']:.4g}",
           "-" if m["success"] else reason(m["message"]), f"{m['energy']['drift']:.2e}", m["wraps"],
           f"{m['max_local_rot']:.3f}", ", ".join(k for k, *_ in m["flagged"]["wrap"]) or "none" if "flagged" in m
           else "-"] for ne, m in mesh.items()]),
        (f"Round-off floor of the Newton tolerance (alpha = 0, dt = 1e-3, {ro[0]['t_end']:g} s, tol = 1e-12, "
         "interpreted path)",
         ["shift (m)", "result", "steps", "accepted residual (max over the run)", "Newton it./step mean (max)",
          "max abs position difference (m)", "in eps x shift", "max abs rotation difference (rad)",
          "max abs velocity difference (m/s, rad/s)", "max speed (m/s, rad/s)", "energy drift"], "rlrrrrrrrrr",
         [[f"{r['shift']:g}", r["result"], r["steps"], f"{r['accepted_tol']:.2g}", r["newton"], f"{r['max_dpos']:.2g}",
           f"{r['max_dpos'] / (EPS * r['shift']):.2g}" if r["shift"] else "-", f"{r['max_drot']:.2g}",
           f"{r['max_dqd']:.2g}", f"{r['max_qd']:.2g}", f"{r['drift']:.1e}"] for r in ro])]
    lines = ["# Rotations at the extremes" + (" (quick mode)" if raw["quick"] else ""), "", raw["banner"], "",
             "What is run, how to read it and what it shows: [docs/studies/extremes.md](../studies/extremes.md).", ""]
    for title, head, align, body in sections:
        lines += [f"## {title}", "", *table(head, body, align), ""] if body else []
    return "\n".join(lines + check_lines)


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("extremes_rotations", quick)
    mesh = None if quick else {str(ne): run_case(  # E x1e-6, whose single elements wrap: 1 and 8 elements per bar
        twobar(ne, e_scale=1e-6), k_scale=1.0, e_scale=1e-6, alpha=0.0, dt=1e-4, t_end=3.0,
        omega_max=math.nan)[0] for ne in (1, 8)}
    raw = {"quick": quick, "turns": full_turns(quick), "mesh": mesh, "roundoff": roundoff_probe(quick)}
    raw["banner"] = banner.line()
    check_lines, failed = checks(self_checks(raw))
    write_outputs("extremes_rotations", out_dir, quick, page(raw, check_lines))
    assert_checks(failed)
    return raw


if __name__ == "__main__":
    cli(__doc__, main)
