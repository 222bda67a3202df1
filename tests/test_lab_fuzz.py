"""Corrupted copies of the TRC, .mot and C3D excerpts through ``casflex inverse``: every one refused in one
line (exit 2) or accepted with a finite answer (exit 0), no traceback, no hang.

The copies (tests/lab_fuzz.py) carry one to three faults each, seeded: cells not numbers, empty, infinite or
absurd, lines lost, repeated or swapped, files cut short, bytes that are not text, header fields that lie,
times shifted; in the C3D, bytes of its header, parameters and data overwritten. One worker process runs them
all (casflex imported once); a case that takes longer than :data:`HANG` seconds is a hang. A refusal must name
the file it read (or an option): a line that names nothing is not "one clear line". ``CASFLEX_FUZZ`` sets the
number of cases per file (default :data:`CASES`; thousands were run while fixing, see CHANGELOG).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from lab_fuzz import corrupt_c3d, corrupt_text, judge, run_all  # noqa: E402

LAB = Path(__file__).parent / "data" / "lab"
TRC, GRF, C3D = LAB / "hamner_running_stride.trc", LAB / "hamner_running_stride_grf.mot", LAB / "walking2_excerpt.c3d"
#: cases per file: 40 x 3 run in about 30 s on 2 cores; ``CASFLEX_FUZZ_SEED`` shifts the seeds (other copies)
CASES = int(os.environ.get("CASFLEX_FUZZ", "40"))
SEED = int(os.environ.get("CASFLEX_FUZZ_SEED", "0"))
#: s: a case's bound. A clean run takes 0.1-0.5 s; a busy 2-core machine, 10x that; a hang, forever.
HANG = 60.0


def _cases(tmp_path: Path) -> list[dict]:
    from lab_scenes import walking2_leg

    scene = tmp_path / "walking2_leg.toml"
    scene.write_text(walking2_leg())
    leg = ["inverse", "hamner_leg", "--root", "pelvis", "--plate", "ankle=ground_", "--cutoff", "10", "--quiet"]
    cases = []
    for k in range(CASES):
        for kind in ("trc", "mot", "c3d"):
            name = f"{kind}{k}"
            path = tmp_path / f"{name}.{kind}"
            out = str(tmp_path / f"{name}.npz")
            if kind == "trc":
                path.write_bytes(corrupt_text(TRC.read_text(), SEED + 1000 + k))
                argv = [*leg, "--data", str(path), "--loads", str(GRF)]
            elif kind == "mot":
                path.write_bytes(corrupt_text(GRF.read_text(), SEED + 2000 + k))
                argv = [*leg, "--data", str(TRC), "--loads", str(path)]
            else:
                path.write_bytes(corrupt_c3d(C3D.read_bytes(), SEED + 3000 + k))
                argv = ["inverse", str(scene), "--data", str(path), "--loads", str(path), "--plate", "ankle=ground_",
                        "--plane", "X,Z", "--root", "pelvis", "--cutoff", "10", "--quiet"]
            cases.append({"name": name, "file": path.name, "argv": [*argv, "--out", out], "out": out})
    return cases


def _run_all(cases: list[dict]) -> list[dict]:
    """Each case's result from one worker; pytest.fail naming the case that hangs."""
    return run_all(cases, HANG, pytest.fail)


@pytest.mark.slow
def test_corrupted_lab_files_are_refused_in_one_line_or_give_finite_loads(tmp_path):
    pytest.importorskip("ezc3d")
    cases = _cases(tmp_path)
    results = _run_all(cases)
    assert len(results) == len(cases)
    problems, accepted, _ = judge(cases, results, option_ok=True)
    assert not problems, "\n".join(problems)
    # the corruptions are not all fatal: some copies must still be accepted (a harmless header field, a
    # marker gap filled), and most refused
    assert 0 < accepted < len(cases)
