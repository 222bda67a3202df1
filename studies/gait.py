"""Joint loads over a running stride: hip, knee and ankle net moments and the hip's intersegmental force.

The public trial of OpenSim's Hamner pipeline (subject 02, one right stride, 60 Hz markers and plate:
tests/data/lab), the built-in scenes scaled to that subject (hamner_leg: rigid segments on hinges;
hamner_leg_flexible: the thigh and shank as damped cortical-bone beams, same masses and inertias),
``casflex inverse`` from the pelvis with the first plate on the foot. A band around the nominal run
(rigid, 10 Hz cut-off): the cut-off (6 and 15 Hz), marker noise (1 mm, seeded replicates) and the
segments' flexibility (the bones' modulus at cortical bone's and 10 and 100 times it: the net joint
moment applied at the bones' ends bends them with all of it, where in vivo the muscles carry much of
it along the bone, so that the physiological effective stiffness lies above bone's); and OpenSim
4.6's inverse dynamics of the same model, motion and plate (the peers extra), the independent code.
What is measured and what the numbers mean: docs/studies/gait.md.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from _study import Banner, assert_checks, checks, cli, png, table, write_outputs

LAB = Path(__file__).resolve().parents[1] / "tests" / "data" / "lab"
TRC, GRF = LAB / "hamner_running_stride.trc", LAB / "hamner_running_stride_grf.mot"
PLATES, ROOT, CUTOFF = {"ankle": "ground_"}, "pelvis", 10.0
JOINTS = ("hip", "knee", "ankle")
NOISE_M = 1e-3  # marker noise (m, each coordinate): optical systems' ~0.5-1 mm


STIFFER = (1.0, 10.0, 100.0)  # the flexible bones' modulus, times cortical bone's


def _flexible(times: float):
    """hamner_leg_flexible with its bones' E multiplied by ``times``."""
    from dataclasses import replace

    from casflex.scene.io import load_scene

    sc = load_scene("hamner_leg_flexible")
    return replace(sc, beams=tuple(replace(b, E=b.E * times) for b in sc.beams))


def _run(scene, cutoff: float = CUTOFF, markers=None):
    from casflex.inverse import Filter, Trial, inverse_dynamics

    t0 = time.perf_counter()
    res = inverse_dynamics(scene, Trial(TRC if markers is None else markers, grf=GRF, plates=PLATES, root=ROOT),
                           filter=Filter(cutoff=cutoff))
    return res, time.perf_counter() - t0


def _noisy(seed: int):
    from dataclasses import replace

    from casflex.lab import read_trc

    lab = read_trc(TRC)
    return replace(lab, xyz=lab.xyz + np.random.default_rng(seed).normal(0.0, NOISE_M, lab.xyz.shape))


def _series(res) -> dict[str, np.ndarray]:
    out = {f"{j} moment": res.load(f"{j}.moment") for j in JOINTS}
    out["hip force"] = np.hypot(res.load("hip.fx"), res.load("hip.fy"))
    return out


def _peer(res) -> dict[str, np.ndarray] | None:
    """OpenSim's inverse dynamics of the nominal run, or None without OpenSim."""
    import importlib.util

    if importlib.util.find_spec("opensim") is None:
        return None
    from casflex.inverse import inverse_model
    from casflex.peers import opensim as osp

    F, Mo = res.plates[0].at(res.t)  # the plate as the inverse applied it
    out = osp.inverse_dynamics(inverse_model("hamner_leg").scene, ROOT, res.t, res.q, res.qd, res.qdd,
                               plates=[("ankle", F, np.zeros_like(F), Mo)])
    return {f"{j} moment": out[f"{j}.moment"] for j in JOINTS}


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("gait", quick)
    nominal, wall = _run("hamner_leg")
    runs = {"nominal": _series(nominal)}
    for c in (6.0, 15.0):
        runs[f"cut-off {c:g} Hz"] = _series(_run("hamner_leg", c)[0])
    noisy = [_series(_run("hamner_leg", markers=_noisy(s))[0]) for s in range(3 if quick else 10)]
    flex, deflection = {}, {}
    for k in STIFFER:
        res, flex_wall = _run(_flexible(k))
        flex[k], deflection[k] = _series(res), float(res.report[-1].split("deflection ")[-1].split()[0])
        runs[f"flexible {k:g}E"] = flex[k]
    peer = _peer(nominal)
    t = nominal.t
    rows, band = [], {}
    for name, ref in runs["nominal"].items():
        peak = np.abs(ref).max()
        rms = lambda a, r=ref: float(np.sqrt(np.mean((a - r) ** 2)))  # noqa: E731
        cut = max(rms(runs[k][name]) for k in runs if k.startswith("cut-off"))
        noise = float(np.sqrt(np.mean(np.std([n[name] for n in noisy], axis=0) ** 2)))
        fl = {k: rms(flex[k][name]) for k in STIFFER}
        os_ = rms(peer[name]) if peer is not None and name in peer else None
        band[name] = {"peak": peak, "cutoff": cut, "noise": noise, "flexible": fl, "opensim": os_}
        rows.append([name, f"{peak:.0f}", f"{100 * cut / peak:.1f}", f"{100 * noise / peak:.2f}",
                     *(f"{100 * fl[k] / peak:.1f}" for k in STIFFER), "-" if os_ is None else f"{os_ / peak:.1e}"])
    unit = {"hip force": "N"}
    page = ["# Joint loads over a running stride (Hamner subject 02)", "",
            f"{banner.line()} What is measured and what the numbers mean: "
            "[studies/gait.md](../studies/gait.md).", "",
            f"![moments and hip force over the stride](../figures/gait{'_quick' * quick}.png)", "",
            f"One right stride, t = {t[0]:.3f}..{t[-1]:.3f} s ({t.size} frames at 60 Hz), stance to "
            f"{_stance_end(nominal):.3f} s. Nominal: rigid segments, {CUTOFF:g} Hz cut-off: `casflex inverse` took "
            f"{wall:.2f} s in this process; a flexible run {flex_wall:.2f} s (HHT). Marker fit: "
            f"{nominal.report[0].split(': ', 1)[1]}.", "",
            "## The nominal loads and what moves them (RMS over the stride, % of the peak)", "",
            *table(["load", "peak (N m; N)", "cut-off 6 or 15 Hz", f"marker noise {1e3 * NOISE_M:g} mm",
                    *(f"flexible bones, {k:g} x E" for k in STIFFER), "OpenSim, same model (fraction)"], rows,
                   "lrrr" + "r" * len(STIFFER) + "r"), "",
            "The bones' largest deflection (from where the rigid fit puts their nodes): "
            + ", ".join(f"{deflection[k]:.1f} mm at {k:g} x E" for k in STIFFER) + ".", ""]
    lines, failed = checks([
        ("OpenSim's moments on the same model within 5 % of the peak (RMS)",
         "skipped: OpenSim not installed" if peer is None else
         ", ".join(f"{k.split()[0]} {band[k]['opensim'] / band[k]['peak']:.1e}" for k in peer),
         peer is None or all(band[k]["opensim"] < 0.05 * band[k]["peak"] for k in peer)),
        ("the knee's peak moment is a runner's (100-400 N m)", f"{band['knee moment']['peak']:.0f} N m",
         100 < band["knee moment"]["peak"] < 400),
        ("the marker fit's median misfit is below 15 mm (skin markers, out-of-plane motion)",
         f"{1e3 * np.nanmedian(nominal.marker_rms):.1f} mm", np.nanmedian(nominal.marker_rms) < 0.015),
        ("stiffer bones deflect less and move the moments less (towards the rigid inverse)",
         ", ".join(f"{deflection[k]:.1f} mm" for k in STIFFER),
         all(deflection[a] > deflection[b] for a, b in zip(STIFFER, STIFFER[1:], strict=False))
         and all(band[n]["flexible"][STIFFER[0]] > band[n]["flexible"][STIFFER[-1]] for n in band))])
    write_outputs("gait", out_dir, quick, "\n".join(page + lines), figure(t, runs, noisy, unit))
    assert_checks(failed)
    return {"band": band, "wall": wall}


def _stance_end(res) -> float:
    from casflex.lab import read_sto

    g = read_sto(GRF)
    on = g.column("ground_force_vy") > 20.0  # the first stance: from the first loaded row to the first unloaded
    first = int(np.argmax(on))
    off = np.flatnonzero(~on[first:])
    return float(g.t[first + off[0] - 1]) if on.any() and off.size else float("nan")


def figure(t, runs: dict, noisy: list, unit: dict) -> bytes:
    from casflex.plotting._figure import _new_figure

    fig = _new_figure((11, 7))
    axes = fig.subplots(2, 2, sharex=True).ravel()
    for ax, name in zip(axes, runs["nominal"], strict=True):
        lo = np.min([r[name] for k, r in runs.items() if k.startswith("cut-off")] + [runs["nominal"][name]], axis=0)
        hi = np.max([r[name] for k, r in runs.items() if k.startswith("cut-off")] + [runs["nominal"][name]], axis=0)
        ax.fill_between(t, lo, hi, color="C0", alpha=0.25, lw=0, label="cut-off 6-15 Hz")
        sd = np.std([n[name] for n in noisy], axis=0)
        ax.fill_between(t, runs["nominal"][name] - 2 * sd, runs["nominal"][name] + 2 * sd, color="C2", alpha=0.35,
                        lw=0, label="marker noise, 2 sd")
        ax.plot(t, runs["nominal"][name], color="k", lw=1.4, label="rigid, 10 Hz")
        for i, k in enumerate(STIFFER):
            ax.plot(t, runs[f"flexible {k:g}E"][name], color=f"C{3 + i}", lw=1.0, ls="--", label=f"flexible {k:g} x E")
        ax.set(title=name, ylabel=unit.get(name, "N m"))
        ax.axhline(0.0, color="0.6", lw=0.6)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    for ax in axes[2:]:
        ax.set_xlabel("t (s)")
    return png(fig)


if __name__ == "__main__":
    cli(__doc__, main)
