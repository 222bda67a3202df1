"""A second public gait collection run by ``casflex study`` from one study file written from the docs alone:
the Plug-in Gait walks of BTKData (Biomechanical-ToolKit/BTKData, commit 6aee093, ``Input/C3DSamples/PiG``;
BSD-3-Clause, Copyright.txt: files "from users or companies" gathered for BTK's tests), against the labs' own
Plug-in Gait moments.

The collection: three subjects' sessions, each a static trial and walks over 2 or 3 plates, with the lab's gait
events and Plug-in Gait's outputs (joint moments, N mm/kg) and the subject's mass in PROCESSING:Bodymass:
``PiG_Calibration-FlatFoot-Full`` / ``PiG_Motion-FlatFoot-Full`` (47.5 kg, 2 plates), ``PiG_Calibration-
FlatFoot-Hole`` / ``PiG_Motion-FlatFoot-Hole`` and ``-One`` (66.5 kg, 2 plates), ``PiG_Calibration3_noFF`` /
``PiG_Motion3_FF``, ``PiG_Motion3_noFF`` (74 kg, 3 plates). Their markers are Plug-in Gait's with the two PSIS
(no SACR). Not copied into casflex: BTKDATA names a folder holding ``Input/C3DSamples/PiG`` (fetch it with
``git clone https://github.com/Biomechanical-ToolKit/BTKData`` and ``git checkout 6aee093``; the PiG folder is
9 MB).

The study file, as docs/lab.md describes it: the built-in ``pig_psis`` model, each subject calibrated and
scaled on its static trial, its mass read from the C3D (the study file gives none), ``plane = "auto"``,
``vertical = "Z"``, no window (casflex cuts each walk to its marked events' span +- 0.1 s), 6 Hz, per kg. The
comparison is studies/zoo_study.py's (per cycle and joint: correlation and peak ratio with Plug-in Gait's X
moment, signs mapped to OpenSim's). The plates are assigned per contact (a foot on two plates in one walk:
their wrenches summed); the page records what ran, each cycle left out and why.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
import unittest
from pathlib import Path

import numpy as np
from _study import Banner, assert_checks, checks, cli, table, write_outputs
from zoo_study import _summary, compare

PIG = "Input/C3DSamples/PiG"
#: subject -> (its static trial, its walks), file stems in PIG (module docstring)
SESSIONS = {"full": ("PiG_Calibration-FlatFoot-Full", ("PiG_Motion-FlatFoot-Full",)),
            "hole": ("PiG_Calibration-FlatFoot-Hole", ("PiG_Motion-FlatFoot-Hole", "PiG_Motion-FlatFoot-One")),
            "s3": ("PiG_Calibration3_noFF", ("PiG_Motion3_FF", "PiG_Motion3_noFF"))}
QUICK = ("full",)


def _data(quick: bool) -> Path:
    src = os.environ.get("BTKDATA")
    if not src or not (Path(src) / PIG).is_dir():
        why = f"BTKDATA: set it to a folder holding {PIG} (a checkout of Biomechanical-ToolKit/BTKData)"
        if quick:
            raise unittest.SkipTest(why)
        sys.exit(why)
    return Path(src) / PIG


def write_study(data: Path, work: Path, subjects: tuple[str, ...] | None = None) -> Path:
    """The study file in ``work`` (module docstring), of every subject or of ``subjects``; its path."""
    lines = ['name = "BTKData Plug-in Gait walks"', "", "[options]", 'plane = "auto"', 'vertical = "Z"',
             "scale = true", "cutoff = 6.0", 'normalise = "mass"', ""]
    for name, (static, walks) in SESSIONS.items():
        if subjects is not None and name not in subjects:
            continue
        lines += ["[[subjects]]", f'name = "{name}"', 'model = "pig_psis"', f'static = "{data / static}.c3d"', ""]
        for w in walks:
            f = data / f"{w}.c3d"
            lines += ["[[subjects.trials]]", f'name = "{w.removeprefix("PiG_").replace("-", "_")}"',
                      f'markers = "{f}"', ""]
    (work / "study.toml").write_text("\n".join(lines))
    return work / "study.toml"


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("labs_study", quick)
    data = _data(quick)
    with tempfile.TemporaryDirectory(prefix="casflex-labs-") as tmp:
        work = Path(tmp)
        study_file = write_study(data, work, QUICK if quick else None)
        t0 = time.perf_counter()
        run = subprocess.run([sys.executable, "-m", "casflex", "study", str(study_file), "--out", str(work / "out"),
                              "--quiet"], capture_output=True, text=True)
        wall = time.perf_counter() - t0
        summary = (work / "out" / "summary.txt").read_text() if (work / "out" / "summary.txt").is_file() else ""
        rows = compare(study_file, work / "out" / "record", clean_only=True) if summary else []
        figure = (work / "out" / "group.png").read_bytes() if (work / "out" / "group.png").is_file() else b""
        excerpt = "\n".join(study_file.read_text().splitlines()[:16]).replace(str(data), "...")
    n = sum(len(SESSIONS[s][1]) for s in (QUICK if quick else SESSIONS))
    med = {j: float(np.median([r["r"] for r in rows if r["load"].startswith(j)] or [np.nan]))
           for j in ("hip_flexion", "knee_angle", "ankle_angle")}
    check_rows = [("every walk ran (exit 0), the plates of each assigned per contact", f"exit {run.returncode}",
                   run.returncode == 0),
                  ("each joint's median correlation with the labs' own moments at least 0.8 over the clean cycles "
                   "(another model, segment parameters and filter: the clinical peer, not the truth)",
                   ", ".join(f"{j} {v:.2f}" for j, v in med.items()), all(v >= 0.8 for v in med.values()))]
    check_lines, failures = checks(check_rows)
    page = "\n".join([
        f"# A second public collection: BTKData's Plug-in Gait walks ({n} walks), by `casflex study`", "",
        banner.line(), "", f"`casflex study`: {wall:.0f} s wall. The study file's start (paths shortened):", "",
        "```toml", excerpt, "```", "", "## What ran, and what was refused", "", "```",
        (summary or run.stderr).strip().replace(str(data), "..."), "```", "",
        "## casflex against Plug-in Gait's own moments (per kg, per clean gait cycle; median and range)", "",
        *table(["joint", "cycles", "correlation", "peak ratio casflex / PiG"], _summary(rows)), "",
        *check_lines, "", *(["![the subjects' means over the gait cycle](../figures/labs_study.png)", ""]
                            if figure else [])])
    write_outputs("labs_study", out_dir, quick, page, figure or None)
    assert_checks(failures)
    return {"wall": wall, "rows": rows}


if __name__ == "__main__":
    cli(__doc__, main)
