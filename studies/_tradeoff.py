"""The runs of studies/tradeoff.py and the errors measured on them: the settings (elements per bar, inertia
form, HHT alpha) x dt of the plan, each run compiled over the horizon (best-of timing) and, where asked,
interpreted over its first steps; the error of each against the converged reference and against the same model
at the finest dt; convergence orders in dt; the reference's own error by self-convergence. Also the page's
number formats and its dt x setting table. Not a study itself (no ``main``)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from _shared import twobar
from _study import best_of

import casflex
from casflex.results import Trajectory
from casflex.simulate import compiled_library, integrator_for, simulate

ALPHAS = (0.0, -0.05, -0.1, -0.3, -1.0 / 3.0)
NODES = ("3", "5")
FORCES = ("spring1.force", "spring3.force", "torsion1.moment", "torsion3.moment")
GRID_STEP = 1e-2  # the common time grid: every multiple of the coarsest step
NAN = {"pos": np.nan, "force_rel": np.nan}


class Config(NamedTuple):
    """One setting: elements per bar, inertia form, HHT alpha."""

    elements: int
    inertia: str
    alpha: float

    @property
    def label(self) -> str:
        return f"{self.elements} el., {self.inertia}, alpha {fmt_alpha(self.alpha)}"


CENTRE = Config(1, "lagrange", 0.0)


def fmt_alpha(alpha: float) -> str:
    return "-1/3" if abs(alpha + 1.0 / 3.0) < 1e-12 else f"{alpha:g}"


def plan_for(quick: bool) -> dict:
    if quick:
        return {"t_end": 0.5, "dts": [1e-2, 5e-3, 2e-3, 1e-3, 5e-4], "dt_fine": 5e-5, "alphas": (0.0, -1.0 / 3.0),
                "meshes": (1, 2), "mesh_dts": [1e-2, 1e-3], "alt_alpha": None, "seed_alphas": (0.0,),
                "seed_meshes": (1,), "window": 300, "fit": (5e-4, 2e-3), "fit_small": None, "validate_dt": 5e-4}
    return {"t_end": 3.0, "dts": [1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4, 5e-5, 2e-5], "dt_fine": 1e-5,
            "alphas": ALPHAS, "meshes": (1, 2, 4, 8), "mesh_dts": [1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4],
            "alt_alpha": -0.05, "seed_alphas": ALPHAS, "seed_meshes": (1, 2, 4, 8), "window": 3000,
            "fit": (1e-4, 2e-3), "fit_small": (5e-5, 2e-4), "validate_dt": 1e-4}


def tasks_for(plan: dict) -> list[tuple[Config, float, bool]]:
    """(config, dt, time the interpreted path too) in run order; the reference first."""
    fine, ref = plan["dt_fine"], Config(plan["meshes"][-1], "lagrange", 0.0)
    tasks = [(ref, fine, True), (ref, 2 * fine, True)]
    for a in plan["alphas"]:
        tasks += [(Config(1, "lagrange", a), dt, True) for dt in [*plan["dts"], fine]]
    for a in plan["seed_alphas"]:
        tasks += [(Config(1, "seed", a), dt, a == 0.0) for dt in [*plan["dts"], fine]]
    for ne in plan["meshes"][1:]:
        tasks += [(Config(ne, "lagrange", 0.0), dt, True) for dt in [*plan["mesh_dts"], fine]]
        if plan["alt_alpha"] is not None:
            tasks += [(Config(ne, "lagrange", plan["alt_alpha"]), dt, False) for dt in plan["mesh_dts"]]
        if ne in plan["seed_meshes"]:
            tasks.append((Config(ne, "seed", 0.0), fine, False))
    first: dict = {}
    for t in tasks:
        first.setdefault(t[:2], t)
    return list(first.values())


class Models:
    """Models and integrators built once per setting; the one-off build times, for the page."""

    def __init__(self) -> None:
        self.models: dict[tuple[int, str], casflex.Model] = {}
        self.builds: dict[Config, dict] = {}

    def __call__(self, cfg: Config) -> casflex.Model:
        key = (cfg.elements, cfg.inertia)
        if key not in self.models:
            self.models[key] = twobar(cfg.elements, inertia=cfg.inertia)
        m = self.models[key]
        if cfg not in self.builds:
            t_i, integ = best_of(lambda: integrator_for(m, alpha=cfg.alpha), 1)
            t_l, lib = best_of(lambda: compiled_library(integ), 1)
            self.builds[cfg] = {"integrator_s": t_i, "library_s": t_l, "cached": lib.cached, "n_dof": m.n_dof}
        return m


def sample(tr: Trajectory, t_end: float) -> dict:
    """Node positions (k, 2 nodes, 2), joint forces (k, 4) and energy drift on the common grid."""
    idx = np.round(np.arange(0.0, t_end + 1e-12, GRID_STEP) / tr.meta["dt"]).astype(int)
    pos = np.stack([np.stack([tr.dof(f"x{n}")[idx], tr.dof(f"y{n}")[idx]], axis=1) for n in NODES], axis=1)
    energy = tr.energies["total"][idx]
    return {"pos": pos, "forces": np.stack([tr.output(k)[idx] for k in FORCES], axis=1),
            "drift": float(np.abs(energy - energy[0]).max())}


def diff(s: dict, ref: dict) -> dict:
    """Max over the grid: position distance (m), force errors (% of the reference's peak)."""
    rel = 100.0 * np.abs(s["forces"] - ref["forces"]).max(axis=0) / np.abs(ref["forces"]).max(axis=0)
    return {"pos": float(np.linalg.norm(s["pos"] - ref["pos"], axis=2).max()), "force_rel": float(rel.max())}


def run(cfg: Config, dt: float, interp: bool, plan: dict, m: casflex.Model) -> tuple[dict, dict | None]:
    """(row, samples or None): the compiled run over the horizon, and the interpreted one over the
    first ``window`` steps checked against it."""
    t_end = plan["t_end"]
    steps = int(round(t_end / dt))
    w = min(steps, plan["window"])
    t_c, tr = best_of(lambda: simulate(m, t_end, dt=dt, alpha=cfg.alpha, compiled=True, raise_on_failure=False), 3)
    row = {"cfg": cfg, "dt": dt, "steps": steps, "ok": tr.success, "message": tr.message,
           "compiled_s": t_c if tr.success else None, "interp_s": None, "interp_projected": False, "interp_steps": 0,
           "newton_per_step": None, "paths_diff": None, "is_ref": cfg.elements == plan["meshes"][-1]
           and cfg.inertia == "lagrange" and cfg.alpha == 0.0 and dt == plan["dt_fine"]}
    if not tr.success:
        return row, None
    smp, q, y = sample(tr, t_end), tr.q[:w + 1].copy(), tr.outputs[:w + 1].copy()
    del tr
    if interp:
        t_i, ti = best_of(lambda: simulate(m, w * dt, dt=dt, alpha=cfg.alpha, raise_on_failure=False), 3)
        if ti.success:
            dy = (np.abs(ti.outputs - y).max(axis=0) / np.maximum(np.abs(y).max(axis=0), 1e-300)).max()
            row.update(interp_s=t_i / w * steps, interp_projected=w < steps, interp_steps=w,
                       newton_per_step=ti.stats["newton_iterations"] / max(ti.stats["steps"], 1),
                       paths_diff=max(float(np.abs(ti.q - q).max()), float(dy)))
    print(f"  {cfg.label:34s} dt {dt:7.0e}: compiled {ms(t_c)}"
          + (f", interpreted {ms(row['interp_s'])}" if row["interp_s"] else ""), flush=True)
    return row, smp


def fit_order(dts, errs, lo: float, hi: float) -> float:
    """Least-squares slope of log(error) vs log(dt) over lo <= dt <= hi."""
    d, e = np.asarray(dts), np.asarray(errs)
    m = (d >= lo * (1 - 1e-9)) & (d <= hi * (1 + 1e-9)) & np.isfinite(e) & (e > 0)
    return float(np.polyfit(np.log(d[m]), np.log(e[m]), 1)[0]) if m.sum() >= 2 else float("nan")


def measure(plan: dict, rows: list[dict], samples: dict) -> dict:
    """The errors of every row (set in the rows), the orders in dt, the reference's own error, seed vs lagrange."""
    fine, meshes = plan["dt_fine"], plan["meshes"]
    ref_cfg = Config(meshes[-1], "lagrange", 0.0)
    ref = samples[(ref_cfg, fine)]
    for r in rows:
        s, base = samples.get((r["cfg"], r["dt"])), samples.get((r["cfg"]._replace(alpha=0.0), fine))
        r["err"] = diff(s, ref) if s is not None else NAN
        r["err_dt"] = diff(s, base) if s is not None and base is not None else NAN  # time discretisation alone
        r["drift"] = s["drift"] if s is not None else np.nan
    orders = {}
    for cfg in dict.fromkeys(r["cfg"] for r in rows):
        rs = [r for r in rows if r["cfg"] == cfg and r["dt"] != fine]
        dts, ep, ef = [r["dt"] for r in rs], [r["err_dt"]["pos"] for r in rs], [r["err_dt"]["force_rel"] for r in rs]
        lo, hi = plan["fit"]
        small = plan["fit_small"]
        orders[cfg] = {"pos": fit_order(dts, ep, lo, hi), "force": fit_order(dts, ef, lo, hi),
                       "n": sum(lo * (1 - 1e-9) <= d <= hi * (1 + 1e-9) for d in dts),
                       "pos_small": fit_order(dts, ep, *small) if small else np.nan,
                       "force_small": fit_order(dts, ef, *small) if small else np.nan}
    # the reference's own error: time (same mesh at 2 dt, order 2: e = d / (2^2 - 1)) and mesh (geometric)
    d_time = diff(samples[(ref_cfg, 2 * fine)], ref)
    ref_time = {k: d_time[k] / 3.0 for k in NAN}
    mesh_d = {ne: diff(samples[(Config(ne, "lagrange", 0.0), fine)], ref) for ne in meshes[:-1]}
    mesh_ratio, ref_mesh = {}, dict(NAN)
    if len(meshes) >= 3:
        d_ab = diff(samples[(Config(meshes[-3], "lagrange", 0.0), fine)], samples[(Config(meshes[-2], "lagrange",
                                                                                           0.0), fine)])
        for k in NAN:
            mesh_ratio[k] = d_ab[k] / mesh_d[meshes[-2]][k]
            ref_mesh[k] = mesh_d[meshes[-2]][k] / (mesh_ratio[k] - 1.0) if mesh_ratio[k] > 1.0 else np.inf
    ref_err = {k: ref_time[k] + (ref_mesh[k] if np.isfinite(ref_mesh[k]) else 0.0) for k in NAN}
    seed_cmp = []
    for ne in meshes:
        s_seed, s_lag = samples.get((Config(ne, "seed", 0.0), fine)), samples.get((Config(ne, "lagrange", 0.0), fine))
        if s_seed is not None and s_lag is not None:
            seed_cmp.append({"ne": ne, "diff": diff(s_seed, s_lag), "seed_err": diff(s_seed, ref),
                             "lag_err": diff(s_lag, ref) if ne != meshes[-1] else None})
    return {"orders": orders, "d_time": d_time, "ref_time": ref_time, "ref_mesh": ref_mesh, "ref_err": ref_err,
            "mesh_d": mesh_d, "mesh_ratio": mesh_ratio, "seed_cmp": seed_cmp}


def ms(s: float | None) -> str:
    return "" if s is None or not np.isfinite(s) else (f"{s * 1e3:.1f} ms" if s < 10 else f"{s:.1f} s")


def fmt_e(v: float | None, fmt: str = ".2e") -> str:
    return "" if v is None or not np.isfinite(v) else format(v, fmt)


def grid(title: str, cols: list[Config], heads: list[str], dts, rowmap: dict, fmt, t_end: float | None = None):
    """A table of fmt(row) over dt (rows) and settings (columns); ``t_end``: with a column of steps."""
    out = [f"**{title}**", "", "| dt (s) | " + ("steps | " if t_end else "") + " | ".join(heads) + " |",
           "|---:|" + ("---:|" if t_end else "") + "---:|" * len(cols)]
    for dt in dts:
        cells = ["" if (r := rowmap.get((c, dt))) is None else "failed" if not r["ok"] else
                 "reference" if r["is_ref"] else fmt(r) for c in cols]
        out.append(f"| {dt:g} | " + (f"{int(round(t_end / dt))} | " if t_end else "") + " | ".join(cells) + " |")
    return out + [""]


