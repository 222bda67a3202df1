"""Corrupted copies of the repo's OpenSim models (tests/osim_fuzz.py) through ``casflex import`` and the reader's
Python API (``scene_from_osim``, the scene assembled), the leg's first few also through ``casflex inverse``: every
one refused in one line naming the file (exit 2, the API's ValueError) or read into a scene whose numbers are all
finite (an inverse's loads too); no traceback, no hang, and nothing left in the output folder by a refusal. One
worker process runs them all (tests/lab_fuzz.py); ``CASFLEX_FUZZ_OSIM`` sets the cases per model and way (default
:data:`CASES`), ``CASFLEX_FUZZ_OSIM_INVERSE`` the inverse ones, ``CASFLEX_FUZZ_SEED`` shifts the seeds.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from lab_fuzz import judge, run_all  # noqa: E402
from osim_fuzz import corrupt_osim  # noqa: E402

LAB = Path(__file__).parent / "data" / "lab"
MODELS = (LAB / "hamner_subject02_leg.osim", LAB / "hamner_subject02_planar.osim")
#: cases per model and way (import, API): 30 x 2 x 2 and 4 inverse ones run in 10-20 s on a busy 2-core machine
CASES = int(os.environ.get("CASFLEX_FUZZ_OSIM", "30"))
SEED = int(os.environ.get("CASFLEX_FUZZ_SEED", "0"))
#: of them, the leg's first ones also through ``casflex inverse`` (a third of its running stride: about 1 s each)
INVERSE = int(os.environ.get("CASFLEX_FUZZ_OSIM_INVERSE", "4"))
TRC, GRF = LAB / "hamner_running_stride.trc", LAB / "hamner_running_stride_grf.mot"
#: s: a case's bound; a clean import takes 0.1-0.3 s, an inverse 1 s
HANG = 30.0


def _cases(tmp_path: Path) -> list[dict]:
    cases = []
    for m, model in enumerate(MODELS):
        text = model.read_text()
        for k in range(CASES):
            name = f"m{m}_{k}"
            path = tmp_path / f"{name}.osim"
            path.write_bytes(corrupt_osim(text, SEED + 1000 * m + k))
            folder = tmp_path / name
            folder.mkdir()
            out = str(folder / "scene.toml")
            cases.append(
                {
                    "name": name,
                    "file": path.name,
                    "folder": str(folder),
                    "out": out,
                    "argv": ["import", str(path), "--out", out],
                }
            )
            cases.append(
                {
                    "name": f"{name}_api",
                    "file": path.name,
                    "folder": str(folder),
                    "out": out,
                    "api": True,
                    "argv": ["api", str(path)],
                }
            )
            if m == 0 and k < INVERSE:
                folder = tmp_path / f"{name}_inv"
                folder.mkdir()
                out = str(folder / "id.npz")
                argv = ["inverse", str(path), "--data", str(TRC), "--loads", str(GRF), "--plate", "calcn_r=ground_"]
                cases.append(
                    {
                        "name": f"{name}_inv",
                        "file": path.name,
                        "also": [TRC.name, GRF.name],  # a model's fault can show as the trial's misfit
                        "folder": str(folder),
                        "out": out,
                        "argv": [*argv, "--t-end", "0.6", "--quiet", "--out", out],
                    }
                )
    return cases


def test_corrupted_models_are_refused_in_one_line_or_read_finite(tmp_path):
    cases = _cases(tmp_path)
    results = run_all(cases, HANG, pytest.fail)
    assert len(results) == len(cases)
    problems, accepted, refused = judge(cases, results)
    assert not problems, "\n".join(problems)
    # the faults are not all fatal (a changed comment-like field, a duplicated number the reader skips): some
    # copies are read, most refused
    assert accepted > 0 and refused > len(cases) // 3
