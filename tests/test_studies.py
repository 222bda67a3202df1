"""Every study runs in quick mode and passes its own self-checks (outputs go to a temp dir)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parents[1] / "studies"
STUDIES = sorted(p for p in HERE.glob("*.py") if not p.name.startswith("_"))  # _study.py: their shared parts
#: The quick runs left to ``pytest -m long`` (the suite's budget, ~10 minutes on 2 cores): the benchmarks, whose
#: timings are never asserted, the leg study, whose identification tests/test_leg_scene.py covers, and the hip over
#: the walk's cycle (108 s on a busy machine; its muscle path and bands: test_muscles_bands, test_peers_*_walk), the
#: basins (46 s; each method's convergence from far starts: tests/test_identification_*.py) and the uncertain
#: properties' fits (30 s; tests/test_identification_priors.py).
LONG = {"leg", "hip_contact_walk", "basins", "uncertain"}


def _param(p: Path):
    long = p.stem.startswith("bench_") or p.stem in LONG
    return pytest.param(p, id=p.stem, marks=[pytest.mark.long] if long else [])


@pytest.mark.parametrize("path", [_param(p) for p in STUDIES])
def test_study_quick(path, tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(HERE))  # as ``python studies/<name>.py`` has it
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # as an import would: dataclasses and pickling look the module up
    spec.loader.exec_module(mod)
    mod.main(quick=True, out_dir=tmp_path)
    assert any(tmp_path.rglob("*.md")), "a study writes at least one table"
