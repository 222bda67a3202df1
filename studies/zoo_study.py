"""A public multi-subject gait study run end to end by ``casflex study``: biomechZoo's sample study (12 children,
Vicon Plug-in Gait markers, two plates), against the lab's own software's joint moments.

The data: PhilD001/biomechZoo-help, ``sample study/Data/raw c3d files`` (Dixon, Loh, Michaud-Paquette and
Pearsall 2017, "biomechZoo: An open-source toolbox for the processing, analysis, and visualization of
biomechanical movement data", Computer Methods and Programs in Biomedicine 140:1-10; the toolbox is Apache-2.0).
Not copied into casflex: the environment's BIOMECHZOO_HELP names a clone (or a bare git directory) of it. Per
child: a static trial, a straight walk and a walk with a 90-degree turn, each with the child's mass, Vicon's gait
events and Plug-in Gait's own outputs (joint centres; joint moments in N mm/kg).

The study file this writes, as a lab would: one model for all (the built-in ``pig``: the planar gait2392 of
tests/data/lab with Plug-in Gait's markers and joint centres, the arms locked to the torso), each child scaled
on its static trial (segments by the joint centres' and markers' distances, masses to the child's, read from its
C3D), the skin markers weighed alike and the joint centres left out of the fit (the model's weights),
``plane = "auto"`` (the children walk
the walkway both ways and stand facing its end), each trial cut to the span of its marked gait events
+- 0.1 s by casflex itself (the study file gives no window), the cut-off 6 Hz, the table and figures per kg. The
turns are expected to be refused (a planar model cannot follow them: casflex.study.direction); the straight walks
run.

Compared, per straight walk, foot and joint: casflex's sagittal moment and Plug-in Gait's (its X component, signs
mapped to OpenSim's: PiG's hip and ankle X are extensor and plantarflexor positive, its knee X flexor
positive), per kg, over each gait cycle (foot strike to foot strike, as the lab marked them): their correlation and
their peaks' ratio. Not a test of casflex's mechanics (tests/test_peers_opensim_tools.py is): the two differ in model
(planar gait2392 scaled from an adult, against Plug-in Gait's 3-D segments and Dempster's anthropometry) and in
filtering; the study shows what a lab gets from casflex on its own files, and how near its usual software.
"""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
import tempfile
import time
import unittest
from pathlib import Path

import numpy as np
from _study import Banner, assert_checks, checks, cli, table, write_outputs

ROOT = Path(__file__).resolve().parents[1]
RAW = "sample study/Data/raw c3d files"
#: casflex's load -> (Plug-in Gait's point, the sign that maps its X component to OpenSim's convention)
QUICK = ("HC030A", "HC036A")  # --quick: two children, one walking each way
PIG = {f"{j}_{s}_moment": (f"{s.upper()}{p}Moment", sign) for s in "rl"
       for j, p, sign in (("hip_flexion", "Hip", -1.0), ("knee_angle", "Knee", 1.0), ("ankle_angle", "Ankle", -1.0))}


def _data(work: Path, quick: bool) -> Path:
    """The sample study's C3D folder: BIOMECHZOO_HELP's (a clone) or extracted from it (a bare git directory)."""
    src = os.environ.get("BIOMECHZOO_HELP")
    if not src:
        why = "BIOMECHZOO_HELP: set it to a clone (or bare git directory) of PhilD001/biomechZoo-help"
        if quick:  # the test suite's run: casflex ships none of the data, so there is nothing to run
            raise unittest.SkipTest(why)
        sys.exit(why)
    if (Path(src) / RAW).is_dir():
        return Path(src) / RAW
    archive = subprocess.run(["git", f"--git-dir={src}", "archive", "HEAD", RAW], check=True, capture_output=True)
    subprocess.run(["tar", "-x", "-C", str(work)], input=archive.stdout, check=True)
    return work / RAW


def write_study(data: Path, work: Path, subjects: tuple[str, ...] | None = None) -> Path:
    """The model, the task file and the study file in ``work`` (module docstring), of every child or of
    ``subjects``; the study file's path."""
    lines = ['name = "biomechZoo sample study"', "", "[options]", 'plane = "auto"', 'vertical = "Z"',
             "scale = true", "cutoff = 6.0", 'normalise = "mass"', ""]
    for folder in sorted(p for p in data.iterdir() if p.is_dir() and (subjects is None or p.name in subjects)):
        static = next((folder / "Static").glob("*.c3d"))
        lines += ["[[subjects]]", f'name = "{folder.name}"', 'model = "pig"', f'static = "{static}"', ""]
        for kind in ("Straight", "Turn"):
            for f in sorted((folder / kind).glob("*.c3d")):
                lines += ["[[subjects.trials]]", f'name = "{kind.lower()}"', f'markers = "{f}"']
                lines.append("")
    (work / "study.toml").write_text("\n".join(lines))
    return work / "study.toml"


@functools.lru_cache(maxsize=8)
def _pig_points(path: str) -> tuple[list[str], np.ndarray]:
    """A C3D's point labels (both LABELS and LABELS2) and its points' X components (k, n), read once per file."""
    import ezc3d

    c = ezc3d.c3d(path)
    p = c["parameters"]["POINT"]
    return list(p["LABELS"]["value"]) + list(p.get("LABELS2", {}).get("value", [])), c["data"]["points"][0]


def _pig_moment(path: str, point: str) -> np.ndarray:
    """(n,) N m/kg: Plug-in Gait's ``point`` X component (N mm/kg in the file), NaN where it wrote none."""
    labels, x = _pig_points(path)
    x = x[labels.index(point)] / 1e3
    return np.where(x == 0.0, np.nan, x)


def compare(study_file: Path, record: Path, clean_only: bool = False) -> list[dict]:
    """Per straight walk, load and cycle: casflex against Plug-in Gait (module docstring); ``clean_only``: the
    cycles whose stance is wholly on the foot's plate (loads.csv's clean flag) alone."""
    from casflex.lab import read_c3d
    from casflex.study.events import normalise
    from casflex.study.study_file import load_study

    study = load_study(str(study_file))
    rows = []
    for s, t in study.trials():
        found = sorted(record.glob(f"trial-{s.name}-{t.name}-*.json"), key=lambda p: p.stat().st_mtime)
        rec = json.loads(found[-1].read_text()) if found else {}  # the newest: this run's (a fresh record dir)
        if "loads" not in rec:
            continue
        time_axis = read_c3d(t.markers, plates=False)[0].t
        for name, (point, sign) in PIG.items():
            ld = rec["loads"].get(name)
            flags = (ld.get("clean") or [True] * len(ld["cycles"])) if ld else ()
            for cyc, val, ok_cycle in zip(ld["cycles"], ld["value"], flags, strict=True) if ld else ():
                if clean_only and not ok_cycle:
                    continue
                pig = sign * normalise(time_axis, _pig_moment(t.markers, point), *cyc)
                ours = np.asarray(val) / s.mass
                ok = np.isfinite(pig)
                if ok.mean() < 0.9:  # Plug-in Gait writes no moment where it lacks a marker
                    continue
                rows.append({"subject": s.name, "load": name, "cycle": cyc,
                             "r": float(np.corrcoef(ours[ok], pig[ok])[0, 1]),
                             "peak_ratio": float(np.abs(ours[ok]).max() / np.abs(pig[ok]).max())})
    return rows


def _summary(rows: list[dict]) -> list[list]:
    out = []
    for joint in ("hip_flexion", "knee_angle", "ankle_angle"):
        sel = [r for r in rows if r["load"].startswith(joint)]
        if sel:
            r, k = np.array([x["r"] for x in sel]), np.array([x["peak_ratio"] for x in sel])
            out.append([joint, len(sel), f"{np.median(r):.2f} ({r.min():.2f}-{r.max():.2f})",
                        f"{np.median(k):.2f} ({k.min():.2f}-{k.max():.2f})"])
    return out


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("zoo_study", quick)
    with tempfile.TemporaryDirectory(prefix="casflex-zoo-") as tmp:
        work = Path(tmp)
        study_file = write_study(_data(work, quick), work, QUICK if quick else None)
        t0 = time.perf_counter()
        run = subprocess.run([sys.executable, "-m", "casflex", "study", str(study_file), "--out", str(work / "out"),
                              "--quiet"], capture_output=True, text=True)
        wall = time.perf_counter() - t0
        out_summary = work / "out" / "summary.txt"
        summary = out_summary.read_text().replace(str(work), "...") if out_summary.is_file() else ""
        rows = compare(study_file, work / "out" / "record")
        figure = (work / "out" / "group.png").read_bytes()
        n_rows = max(0, len((work / "out" / "loads.csv").read_text().splitlines()) - 1)
        excerpt = "\n".join(study_file.read_text().splitlines()[:22]).replace(str(work), "...")
    failed = [ln.strip() for ln in summary.splitlines() if ln.startswith("  ") and "Error" in ln]
    n = len(QUICK) if quick else 12
    r_ankle = [x["r"] for x in rows if x["load"].startswith("ankle")]
    check_rows = [
        ("the command ran to its end (exit 1: some trials refused, reported)", f"exit {run.returncode}",
         run.returncode in (0, 1)),
        ("every turn refused (a planar model cannot follow it)", f"{sum(' turn:' in f for f in failed)} of {n}",
         sum(" turn:" in f for f in failed) == n),
        ("straight walks done (a refused one says why, above)", f"{n - sum(' straight:' in f for f in failed)} "
         f"of {n}", True, False),
        ("the ankle's moment follows Plug-in Gait's (correlation > 0.9 in every cycle)",
         f"min {min(r_ankle, default=float('nan')):.2f}", bool(r_ankle) and min(r_ankle) > 0.9)]
    check_lines, failures = checks(check_rows)
    page = "\n".join([
        f"# A whole study: biomechZoo's sample study ({n} children), by `casflex study`", "",
        banner.line(), "",
        f"`casflex study` on {2 * n} trials ({n} straight walks, {n} turns): {wall:.0f} s wall on 2 local workers, "
        f"{n_rows} rows in loads.csv. The study file's start (paths shortened):", "", "```toml", excerpt, "```", "",
        "## What ran, and what was refused", "", "```", summary.strip(), "```", "",
        "## casflex against Plug-in Gait's own moments (per kg, per gait cycle; median and range)", "",
        *table(["joint", "cycles", "correlation", "peak ratio casflex / PiG"], _summary(rows)), "",
        "Peak ratio below 1: casflex's planar model (an adult's segments scaled to the child) against Plug-in "
        "Gait's 3-D segments and Dempster's anthropometry; see docs/studies/zoo_study.md.", "",
        *check_lines, "",
        "![the subjects' means over the gait cycle](../figures/zoo_study.png)", ""])
    write_outputs("zoo_study", out_dir, quick, page, figure)
    assert_checks(failures)
    return {"wall": wall, "rows": rows}


if __name__ == "__main__":
    cli(__doc__, main)
