"""Benchmark against Exudyn: the same twobar system in both codes, side by side in one run.

Questions: (1) do the two codes solve the same problem? (2) at the same mesh and step, which is
faster, from 1 to 32 elements per bar? (3) for a required accuracy of node 5, which is cheaper
(the error-against-time fronts of both codes, 1e-3 to 1e-6 m)?

casflex: the scene file ``casflex/scenes/twobar.toml`` meshed into n co-rotational Euler-Bernoulli
elements per bar, HHT alpha = 0, compiled, whole ``simulate()`` calls (energies and joint outputs
included). Exudyn (C++, ``pip install exudyn``), built here from the same scene data, with both of
its planar beams:

- ``ancf``: ``ObjectANCFCable2D`` on ``NodePoint2DSlope1`` nodes (Euler-Bernoulli, cubic Hermite
  positions, consistent mass: the same continuum as casflex's beam);
- ``ge``: ``ObjectBeamGeometricallyExact2D`` on ``NodeRigidBody2D`` nodes (Simo-Reissner, linear
  interpolation: shear stiffness 5/6 G A with nu = 0.3; rotary inertia 1e-3 rho I: casflex's beam,
  like the seed paper's, has none, and this element needs some for a regular mass matrix; with
  rho I itself its converged motion is 1.2e-5 m from the Euler-Bernoulli one over 0.3 s, with
  1e-3 rho I 2.5e-8 m, measured);

node 1 clamped by coordinate constraints (Lagrange multipliers, as in casflex); the joints an
``ObjectConnectorSpringDamper`` (k, rest length) and an ``ObjectConnectorTorsionalSpringDamper`` (kt)
without damping; gravity by ``LoadMassProportional``; implicit generalized-alpha with spectral radius 1
(the trapezoidal rule, as HHT alpha = 0), Exudyn's default modified Newton; node 5 recorded at every
step by an internal sensor, no solution file; the time is the ``SolveDynamic`` call (model setup apart).

Errors: max over t = 0, 0.01, ..., t_end of the distance of node 5 from a converged casflex reference.
Writes docs/tables/bench_exudyn.md and docs/figures/bench_exudyn.png (``--quick``: *_quick.*, 0.3 s).
Run: ``python studies/bench_exudyn.py`` (about 15 min). Without Exudyn the casflex side still runs.
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import math
import os
import platform
import time
from pathlib import Path

import numpy as np

import casflex
from casflex.results import atomic_write_bytes, atomic_write_text
from casflex.simulate import compiled_library, integrator_for, simulate

ROOT = Path(__file__).resolve().parents[1]
GRID = 1e-2  # errors on t = 0, 0.01, ...
#: Physics check, node 5 (m): converged Exudyn (both beams) against the converged casflex reference;
#: the reference's own error is about 1e-7 m over 3 s (printed), so 1e-6 m separates discretisation
#: noise from a different problem (at h = 1e-3 the codes' errors are 3e-5 .. 1e-4 m).
TOL_PHYSICS = 1e-6
CODES = ("casflex", "ancf", "ge")
LEVELS = (1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6)  # accuracy levels of the fronts (m)


def _plan(quick: bool) -> dict:
    if quick:
        return {"t_end": 0.3, "meshes": (1, 2), "ref": (4, 1e-4), "checks": ((4, 2e-4), (2, 1e-4)),
                "converged": {"ancf": (4, 1e-4), "ge": (8, 1e-4)}, "front_meshes": {c: (1, 2) for c in CODES},
                "front_hs": (1e-3, 5e-4), "repeat": 2}
    return {"t_end": 3.0, "meshes": (1, 2, 4, 8, 16, 32), "ref": (16, 2.5e-5), "checks": ((8, 2.5e-5), (16, 5e-5)),
            "converged": {"ancf": (8, 5e-5), "ge": (32, 5e-5)},
            "front_meshes": {"casflex": (1, 2, 4, 8), "ancf": (1, 2, 4, 8), "ge": (4, 8, 16, 32)},
            "front_hs": (2e-3, 1e-3, 5e-4, 2.5e-4, 1e-4), "repeat": 5}


def _node5_grid(p5: np.ndarray, h: float, t_end: float) -> np.ndarray:
    return p5[np.round(np.arange(0.0, t_end + 1e-12, GRID) / h).astype(int)]


def _best(fn, repeat: int):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        res = fn()
        if time.perf_counter() - t0 < best:
            best, out = time.perf_counter() - t0, res
        if best > 2.0:  # long runs: one is enough, their spread is a few percent
            break
    return best, out


# -- casflex --------------------------------------------------------------------------------------
def _model(elements: int):
    scene = casflex.load_scene("twobar")
    return casflex.assemble(dataclasses.replace(
        scene, beams=tuple(dataclasses.replace(b, elements=elements) for b in scene.beams)))


def run_casflex(elements: int, h: float, t_end: float, repeat: int = 1) -> dict:
    model = _model(elements)
    compiled_library(integrator_for(model, alpha=0.0))  # built (or loaded) once, not timed
    t, tr = _best(lambda: simulate(model, t_end, dt=h, alpha=0.0, compiled=True), repeat)
    p5 = np.stack([tr.dof("x5"), tr.dof("y5")], axis=1)
    return {"time": t, "run_s": tr.stats["run_s"], "p5": _node5_grid(p5, h, t_end), "ok": tr.success}


# -- Exudyn ---------------------------------------------------------------------------------------
def _exudyn():
    try:
        import exudyn
    except ImportError:
        return None
    return exudyn


def build_exudyn(exu, kind: str, elements: int, h: float, t_end: float, *, converged: bool = False):
    """The twobar scene as an Exudyn model with ``kind`` ('ancf' or 'ge') beams: (mbs, settings, sensor)."""
    from exudyn import itemInterface as ii

    scene = casflex.load_scene("twobar")
    xy = {n.name: (n.x, n.y) for n in scene.nodes}
    assert all(s.kind == "clamp" for s in scene.supports) and not scene.loads
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    node_of, angle = {}, {}
    for b in scene.beams:
        (xa, ya), (xb, yb) = xy[b.nodes[0]], xy[b.nodes[1]]
        L, beta = math.hypot(xb - xa, yb - ya), math.atan2(yb - ya, xb - xa)
        pts = [(xa + k / elements * (xb - xa), ya + k / elements * (yb - ya)) for k in range(elements + 1)]
        if kind == "ancf":
            chain = [mbs.AddNode(ii.NodePoint2DSlope1(referenceCoordinates=[x, y, math.cos(beta), math.sin(beta)]))
                     for x, y in pts]
        else:
            chain = [mbs.AddNode(ii.NodeRigidBody2D(referenceCoordinates=[x, y, beta])) for x, y in pts]
        node_of[b.nodes[0]], node_of[b.nodes[1]] = chain[0], chain[-1]
        angle[b.nodes[0]] = angle[b.nodes[1]] = beta
        for k in range(elements):
            if kind == "ancf":
                obj = ii.ObjectANCFCable2D(nodeNumbers=chain[k:k + 2], length=L / elements, massPerLength=b.rho * b.A,
                                           bendingStiffness=b.E * b.I, axialStiffness=b.E * b.A)
            else:
                obj = ii.ObjectBeamGeometricallyExact2D(
                    nodeNumbers=chain[k:k + 2], physicsLength=L / elements, physicsMassPerLength=b.rho * b.A,
                    physicsCrossSectionInertia=1e-3 * b.rho * b.I, physicsBendingStiffness=b.E * b.I,
                    physicsAxialStiffness=b.E * b.A, physicsShearStiffness=5 / 6 * b.E / 2.6 * b.A,
                    includeReferenceRotations=True)
            mark = mbs.AddMarker(ii.MarkerBodyMass(bodyNumber=mbs.AddObject(obj)))
            mbs.AddLoad(ii.LoadMassProportional(markerNumber=mark, loadVector=[*scene.gravity, 0.0]))
    ground = mbs.AddNode(ii.NodePointGround())
    for s in scene.supports:  # a clamped joint node that is no bar end: a node along the bar it holds
        n = s.node
        if n not in node_of:
            other = next(b for sp in scene.springs if n in sp.nodes for b in sp.nodes if b != n)
            angle[n] = angle[other]
            c, sn = math.cos(angle[n]), math.sin(angle[n])
            node_of[n] = mbs.AddNode(ii.NodePoint2DSlope1(referenceCoordinates=[*xy[n], c, sn]) if kind == "ancf"
                                     else ii.NodeRigidBody2D(referenceCoordinates=[*xy[n], angle[n]]))
        for coord in range(4 if kind == "ancf" else 3):  # slope nodes: the massless slope's length is held too
            mbs.AddObject(ii.CoordinateConstraint(markerNumbers=[
                mbs.AddMarker(ii.MarkerNodeCoordinate(nodeNumber=ground, coordinate=0)),
                mbs.AddMarker(ii.MarkerNodeCoordinate(nodeNumber=node_of[n], coordinate=coord))]))
    for s in scene.springs:
        rest = math.dist(xy[s.nodes[0]], xy[s.nodes[1]]) if s.rest_length is None else s.rest_length
        mbs.AddObject(ii.ObjectConnectorSpringDamper(markerNumbers=[
            mbs.AddMarker(ii.MarkerNodePosition(nodeNumber=node_of[n])) for n in s.nodes], referenceLength=rest,
            stiffness=s.k, damping=0.0))
    for s in scene.torsion_springs:
        assert abs(angle[s.nodes[1]] - angle[s.nodes[0]]) < 1e-12 and not s.rest_angle, "straight joints only"
        mbs.AddObject(ii.ObjectConnectorTorsionalSpringDamper(markerNumbers=[
            mbs.AddMarker(ii.MarkerNodeRigid(nodeNumber=node_of[n])) for n in s.nodes], stiffness=s.kt, damping=0.0))
    sensor = mbs.AddSensor(ii.SensorNode(nodeNumber=node_of["5"], storeInternal=True, writeToFile=False,
                                         outputVariableType=exu.OutputVariableType.Position))
    mbs.Assemble()
    ss = exu.SimulationSettings()
    ti = ss.timeIntegration
    ti.numberOfSteps, ti.endTime, ti.verboseMode = int(round(t_end / h)), t_end, 0
    ti.generalizedAlpha.spectralRadius = 1.0  # no numerical damping: trapezoidal rule, as HHT alpha = 0
    if converged:  # reference quality: Newton on the increment to 1e-10
        ti.newton.residualMode = 1
        ti.newton.relativeTolerance = ti.newton.absoluteTolerance = 1e-10
    ss.solution.file.write = False
    ss.solution.sensors.writePeriod = h
    ss.show.computationTime = ss.show.statistics = False
    return mbs, ss, sensor


def run_exudyn(exu, kind: str, elements: int, h: float, t_end: float, repeat: int = 1, converged: bool = False) -> dict:
    def once():
        mbs, ss, sensor = build_exudyn(exu, kind, elements, h, t_end, converged=converged)
        t0 = time.perf_counter()
        ok = mbs.SolveDynamic(ss)
        return time.perf_counter() - t0, ok, np.asarray(mbs.GetSensorStoredData(sensor))

    best = None
    for _ in range(repeat):
        out = once()
        if best is None or out[0] < best[0]:
            best = out
        if best[0] > 2.0:
            break
    t, ok, data = best
    n = int(round(t_end / h))
    p5 = data[:, 1:3] if data.ndim == 2 and data.shape[0] >= n + 1 else np.full((n + 1, 2), np.nan)
    return {"time": t, "p5": _node5_grid(p5, h, t_end), "ok": bool(ok)}


# -- the study ------------------------------------------------------------------------------------
def _err(p5: np.ndarray, ref: np.ndarray) -> float:
    e = np.linalg.norm(p5 - ref, axis=1)
    return float(e.max()) if np.isfinite(e).all() else math.inf


def front(points: list[tuple[float, float]], level: float) -> float:
    """The least time among (time, error) points with error <= level (inf if none)."""
    return min((t for t, e in points if e <= level), default=math.inf)


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    out_dir = ROOT / "docs" if out_dir is None else Path(out_dir)
    plan = _plan(quick)
    T = plan["t_end"]
    load0 = os.getloadavg()
    print("=" * 78)
    print(f"bench_exudyn: twobar over {T} s, casflex (compiled) vs Exudyn (ANCF cable, geometrically exact)")
    print("=" * 78, flush=True)
    exu = _exudyn()
    codes = CODES if exu else ("casflex",)
    print(f"exudyn: {exu.__version__ if exu else 'NOT INSTALLED (casflex side only)'}")

    ne, h = plan["ref"]
    ref = run_casflex(ne, h, T)["p5"]
    ref_err = max(_err(run_casflex(n2, h2, T)["p5"], ref) for n2, h2 in plan["checks"])
    print(f"reference: casflex {ne} el./bar, dt = {h:g}; against {plan['checks']}: {ref_err:.1e} m", flush=True)
    physics = {}
    if exu:
        for kind, (n2, h2) in plan["converged"].items():
            physics[kind] = _err(run_exudyn(exu, kind, n2, h2, T, converged=True)["p5"], ref)
            print(f"Exudyn {kind} {n2} el./bar, h = {h2:g}, converged: {physics[kind]:.2e} m from the reference")

    rows = []  # the meshes at h = 1e-3
    for n in plan["meshes"]:
        row = {"elements": n}
        for code in codes:
            r = (run_casflex(n, 1e-3, T, plan["repeat"]) if code == "casflex"
                 else run_exudyn(exu, code, n, 1e-3, T, plan["repeat"]))
            row[code] = r["time"]
            row[f"{code}_err"] = _err(r["p5"], ref)
        rows.append(row)
        print(f"{n:2d} el./bar, h = 1e-3: " + ", ".join(f"{c} {row[c] * 1e3:8.1f} ms ({row[c + '_err']:.1e} m)"
                                                       for c in codes), flush=True)
    pts: dict[str, list[tuple[float, float, int, float]]] = {c: [] for c in codes}
    for code in codes:
        for n in plan["front_meshes"][code]:
            for hh in plan["front_hs"]:
                r = (run_casflex(n, hh, T, plan["repeat"]) if code == "casflex"
                     else run_exudyn(exu, code, n, hh, T, plan["repeat"]))
                pts[code].append((r["time"], _err(r["p5"], ref), n, hh))
        print(f"front of {code}: {len(pts[code])} settings", flush=True)
    fronts = {c: [front([(t, e) for t, e, _, _ in pts[c]], lv) for lv in LEVELS] for c in codes}
    for lv, *ts in zip(LEVELS, *(fronts[c] for c in codes), strict=True):
        print(f"error <= {lv:.0e} m: " + ", ".join(f"{c} {t * 1e3:.1f} ms" for c, t in zip(codes, ts, strict=True)))

    suffix = "_quick" if quick else ""
    page = _page(plan, rows, pts, fronts, physics, ref_err, codes, exu, load0, quick)
    print("wrote", atomic_write_text(out_dir / "tables" / f"bench_exudyn{suffix}.md", page))
    print("wrote", atomic_write_bytes(out_dir / "figures" / f"bench_exudyn{suffix}.png", _figure(rows, pts, codes)))
    # self-checks: every casflex run finite and converging with the mesh; ANCF is the same physics
    assert all(math.isfinite(r["casflex_err"]) for r in rows)
    for kind, e in physics.items():
        assert e <= TOL_PHYSICS, f"Exudyn's {kind} model is {e:.2e} m from casflex's: not the same problem"
    return {"rows": rows, "points": pts, "fronts": fronts, "physics": physics}


def _page(plan, rows, pts, fronts, physics, ref_err, codes, exu, load0, quick) -> str:
    T = plan["t_end"]
    cpu = next((ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                if ln.startswith("model name")), platform.processor()) if Path("/proc/cpuinfo").exists() else ""
    L = ["# casflex vs Exudyn: twobar", "",
         f"Generated by `python studies/bench_exudyn.py{' --quick' if quick else ''}` on {cpu} ({os.cpu_count()} "
         f"CPUs), casflex {casflex.__version__}, Exudyn {exu.__version__ if exu else 'not installed'}; load average "
         f"{load0[0]:.2f} at the start, {os.getloadavg()[0]:.2f} at the end. Horizon {T:g} s. The models and the "
         "measurement are described in the script's docstring; both codes run the trapezoidal rule.", "",
         "## The same problem", "",
         f"Reference: casflex {plan['ref'][0]} elements per bar, dt = {plan['ref'][1]:g} s; its own error, against "
         f"{', '.join(f'{n} el. at {h:g} s' for n, h in plan['checks'])}: {ref_err:.1e} m."]
    for kind, e in physics.items():
        n, h = plan["converged"][kind]
        L.append(f"Exudyn {kind}, {n} elements per bar at h = {h:g} s, Newton to 1e-10: **{e:.2e} m** from it "
                 f"(the physics check, tolerance {TOL_PHYSICS:g} m).")
    L += ["", "## Same mesh, same step (h = 1e-3 s): time of the whole run", "",
          "| el./bar | " + " | ".join(f"{c} (ms) | {c} error (m)" for c in codes)
          + (" | ANCF / casflex | GE / casflex |" if exu else " |"),
          "|---:|" + "---:|---:|" * len(codes) + ("---:|---:|" if exu else "")]
    for r in rows:
        cells = " | ".join(f"{r[c] * 1e3:.1f} | {r[c + '_err']:.1e}" for c in codes)
        ratio = f" | **{r['ancf'] / r['casflex']:.1f}** | **{r['ge'] / r['casflex']:.1f}** |" if exu else " |"
        L.append(f"| {r['elements']} | {cells}{ratio}")
    meshes = ", ".join(f"{c}: {list(plan['front_meshes'][c])}" for c in codes)
    L += ["", "## Accuracy against time", "",
          f"For each accuracy, the least time each code needs among its settings (elements per bar {meshes}; steps "
          f"{', '.join(f'{h:g}' for h in plan['front_hs'])} s); '-': no setting reaches it.", "",
          "| error of node 5 at most (m) | " + " | ".join(f"{c} (ms)" for c in codes)
          + (" | best Exudyn / casflex |" if exu else " |"), "|---:|" + "---:|" * len(codes) + ("---:|" if exu else "")]
    for i, lv in enumerate(LEVELS):
        ts = [fronts[c][i] for c in codes]
        cells = " | ".join("-" if not math.isfinite(t) else f"{t * 1e3:.1f}" for t in ts)
        best_x = min(ts[1:]) if exu else math.inf
        ratio = (f" | **{best_x / ts[0]:.1f}** |" if math.isfinite(best_x) and math.isfinite(ts[0]) else " | - |") \
            if exu else " |"
        L.append(f"| {lv:.0e} | {cells}{ratio}")
    L += ["", "Every setting measured (time in ms, error in m):", ""]
    for c in codes:
        L.append(f"- {c}: " + "; ".join(f"{n} el. h {h:g}: {t * 1e3:.1f} ms, {e:.1e}" for t, e, n, h in pts[c]))
    return "\n".join(L) + "\n"


def _figure(rows, pts, codes) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4.2))
    FigureCanvasAgg(fig)
    ax1, ax2 = fig.subplots(1, 2)
    style = {"casflex": "o-", "ancf": "s--", "ge": "^:"}
    for c in codes:
        ax1.loglog([r["elements"] for r in rows], [r[c] for r in rows], style[c], label=c)
        p = sorted((t, e) for t, e, _, _ in pts[c] if math.isfinite(e))
        ax2.loglog([t for t, _ in p], [e for _, e in p], style[c][0], alpha=0.35)
        fr = [(t, e) for i, (t, e) in enumerate(p) if all(e < e2 for _, e2 in p[:i])]  # the Pareto front
        ax2.loglog([t for t, _ in fr], [e for _, e in fr], style[c], label=f"{c} front")
    ax1.set(xlabel="elements per bar", ylabel="time of 3 s at h = 1e-3 (s)", title="same mesh, same step")
    ax2.set(xlabel="time (s)", ylabel="max error of node 5 (m)", title="accuracy against time")
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out-dir", type=Path)
    a = ap.parse_args()
    main(quick=a.quick, out_dir=a.out_dir)
