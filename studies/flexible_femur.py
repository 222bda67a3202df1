"""The hip contact force with a flexible femur: what the muscles' forces and the joint's reaction become when the thigh
bends (issue 47, item 6).

Hamner's subject 02, one right running stride (tests/data/lab, 60 Hz, the plate on the foot), the pelvis and right
leg: rigid (built-in hamner_leg) and with the thigh a chain of four damped cortical-bone beams (built-in
hamner_leg_flexible, its shank made 1000 times stiffer so that only the femur bends), the femur's modulus E at
cortical bone's (17 GPa) and 3, 10, 100 and 1000 times it. The same 43 muscles of the right leg
(tests/data/muscles/hamner_subject02_planar_muscles.osim, the same subject, default pose and joint centres: its
femur's points carried by the thigh's beams by their shape functions, casflex.muscles.flexible; the left leg's and
the trunk's muscles have no body here), static optimization (p = 2, 1 N m reserves) on each run's net joint moments
and the hip's reaction (the net force plus every muscle crossing it) in body weights.

The difference to the rigid result splits in two: the deformed femur's geometry (moment arms, directions of pull:
the flexible run's configurations with the rigid run's loads) and the loads of the bending, vibrating thigh (the
flexible run's loads on the rigid geometry); the flexible runs at 1000 x E measure what the driven HHT run itself
adds (its step, 1 ms).
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
from _study import Banner, assert_checks, checks, cli, png, table, write_outputs

ROOT_DIR = Path(__file__).resolve().parents[1]
LAB, DATA = ROOT_DIR / "tests" / "data" / "lab", ROOT_DIR / "tests" / "data" / "muscles"
TRC, GRF = LAB / "hamner_running_stride.trc", LAB / "hamner_running_stride_grf.mot"
MODEL = DATA / "hamner_subject02_planar_muscles.osim"
STIFFER = (1.0, 3.0, 10.0, 100.0, 1000.0)  # the femur's modulus, times cortical bone's
SHANK = 1000.0  # the shank's modulus, times cortical bone's: as good as rigid (deflection below 0.1 mm)
COORDINATES = {"hip_flexion_r": ("hip", 1.0, 0.0), "knee_angle_r": ("knee", 1.0, 0.0),
               "ankle_angle_r": ("ankle", 1.0, 0.0)}
FOOT = {"pelvis": "pelvis", "talus_r": "ankle", "calcn_r": "ankle", "toes_r": "ankle"}
RIGID = FOOT | {"femur_r": "hip", "tibia_r": "knee"}
FLEXIBLE = FOOT | {"femur_r": tuple(f"thigh_bone_{i}" for i in range(1, 5)),
                   "tibia_r": tuple(f"shank_bone_{i}" for i in range(1, 5))}


def _scene(femur: float | None):
    from casflex import load_scene

    if femur is None:
        return load_scene("hamner_leg")
    sc = load_scene("hamner_leg_flexible")
    return dataclasses.replace(sc, beams=tuple(dataclasses.replace(b, E=b.E * (femur if b.name.startswith("thigh")
                                                                               else SHANK)) for b in sc.beams))


def _run(femur: float | None):
    """(inverse result, paths) of the rigid leg (None) or the flexible femur at ``femur`` x E."""
    from casflex.inverse import Filter, Trial, inverse_dynamics, inverse_model
    from casflex.inverse.tree import kinematic_tree
    from casflex.muscles.flexible import FlexiblePaths, carried_muscles
    from casflex.scene.from_osim import scene_from_osim

    sc = _scene(femur)
    res = inverse_dynamics(sc, Trial(TRC, grf=GRF, plates={"ankle": "ground_"}, root="pelvis"), filter=Filter(10.0))
    osim = scene_from_osim(MODEL, muscles=True)
    bodies = RIGID if femur is None else FLEXIBLE
    muscles, _ = carried_muscles(osim, bodies)
    paths = FlexiblePaths(kinematic_tree(inverse_model(sc, "pelvis"), "pelvis"), muscles, bodies, COORDINATES)
    return res, paths


def _hip(paths, q, qd, loads, weight: float) -> dict:
    from casflex.muscles.flexible import solve_muscles

    out = solve_muscles(paths, q, qd, loads, body_weight=weight)
    r = out["reactions"]["hip"]
    return {"hip": np.hypot(r[:, 0], r[:, 1]), "arms": out["arms"][:, :, 0], "reserve": out["so"].reserve_share,
            "forces": out["so"].forces}


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    from casflex.lab.plate_checks import scene_mass
    from casflex.scene.from_osim import scene_from_osim

    banner = Banner("flexible_femur", quick)
    weight = scene_mass(scene_from_osim(MODEL).scene) * 9.80665
    t0 = time.perf_counter()
    rigid, rpaths = _run(None)
    base = _hip(rpaths, rigid.q, rigid.qd, rigid.loads, weight)
    wall_rigid = time.perf_counter() - t0
    peak = float(base["hip"].max())
    runs, rows, curves = {}, [], {"rigid": base["hip"]}
    for k in STIFFER[:3] if quick else STIFFER:
        t1 = time.perf_counter()
        res, paths = _run(k)
        full = _hip(paths, res.q, res.qd, res.loads, weight)
        geometry = _hip(paths, res.q, res.qd, rigid.loads, weight)  # the deformed femur, the rigid loads
        loads = _hip(rpaths, rigid.q, rigid.qd, res.loads, weight)  # the flexible loads, the rigid femur
        wall = time.perf_counter() - t1
        bend = float(res.report[-1].split("deflection ")[-1].split()[0]) if "deflection" in res.report[-1] else \
            float("nan")
        pct = {n: 100 * np.sqrt(np.mean((v["hip"] - base["hip"]) ** 2)) / peak
               for n, v in (("full", full), ("geometry", geometry), ("loads", loads))}
        worst = 100 * float(np.abs(full["hip"] - base["hip"]).max()) / peak
        arm = 1e3 * float(np.abs(full["arms"] - base["arms"]).max())
        runs[k] = {"pct": pct, "worst": worst, "peak": float(full["hip"].max()), "deflection": bend, "arm": arm,
                   "wall": wall}
        curves[f"{k:g} x E"] = full["hip"]
        rows.append([f"{k:g}", f"{bend:.2f}", f"{arm:.1f}", f"{full['hip'].max():.2f}", f"{pct['full']:.1f}",
                     f"{worst:.1f}", f"{pct['geometry']:.1f}", f"{pct['loads']:.1f}", f"{wall:.1f}"])
    t = rigid.t
    page = ["# The hip contact force with a flexible femur (Hamner subject 02, a running stride)", "",
            f"{banner.line()} What is computed and why: [docs/muscles.md](../muscles.md), \"A flexible femur\".", "",
            f"![hip contact force, rigid and flexible femurs](../figures/flexible_femur{'_quick' * quick}.png)", "",
            f"One right stride, t = {t[0]:.3f}..{t[-1]:.3f} s ({t.size} frames), {len(rpaths.muscles)} muscles of the "
            f"right leg. Rigid leg: the hip contact force peaks at {peak:.2f} BW (body weight {weight:.0f} N); the "
            f"rigid run with its muscles took {wall_rigid:.1f} s.", "",
            "## The difference to the rigid result, % of the rigid peak", "",
            *table(["femur's E (x 17 GPa)", "femur's largest deflection (mm)", "hip moment arms, largest change (mm)",
                    "peak (BW)", "RMS, all", "largest, all", "RMS, geometry alone", "RMS, loads alone", "run (s)"],
                   rows, "rrrrrrrrr"), "",
            "*geometry alone*: the flexible run's deformed configurations with the rigid run's net loads; *loads "
            "alone*: the flexible run's net loads (the bending, vibrating thigh's inertia) on the rigid femur. The "
            "two do not add up exactly: static optimization is not linear.", ""]
    ks = list(runs)
    lines, failed = checks([
        ("the stiffer the femur, the smaller its deflection", ", ".join(f"{runs[k]['deflection']:.2f} mm" for k in ks),
         all(runs[a]["deflection"] > runs[b]["deflection"] for a, b in zip(ks, ks[1:], strict=False))),
        ("the stiffest femur's contact force within 5 % of the rigid one's peak (RMS: the driven run's own error)",
         f"{runs[ks[-1]]['pct']['full']:.2f} %", runs[ks[-1]]["pct"]["full"] < 5.0),
        ("the softest femur moves the contact force more than the stiffest",
         f"{runs[ks[0]]['pct']['full']:.1f} % vs {runs[ks[-1]]['pct']['full']:.1f} %",
         runs[ks[0]]["pct"]["full"] > runs[ks[-1]]["pct"]["full"])])
    write_outputs("flexible_femur", out_dir, quick, "\n".join(page + lines), _figure(t, curves))
    assert_checks(failed)
    return {"runs": runs, "peak": peak}


def _figure(t, curves: dict) -> bytes:
    from casflex.plotting._figure import _new_figure

    fig = _new_figure((8, 4.2))
    ax = fig.subplots()
    for i, (name, v) in enumerate(curves.items()):
        ax.plot(t, v, color="k" if name == "rigid" else f"C{i}", lw=1.6 if name == "rigid" else 1.0,
                ls="-" if name == "rigid" else "--", label=f"femur {name}" if name != "rigid" else "rigid femur")
    ax.set(xlabel="t (s)", ylabel="hip contact force (body weights)",
           title="Hamner subject 02, running: the hip's contact force, rigid and flexible femurs")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return png(fig)


if __name__ == "__main__":
    cli(__doc__, main)
