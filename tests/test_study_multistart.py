"""Multi-start in the library (casflex.study.multistart): every start a sweep run in a worker
process, the best one fitted again, every start's record in the result."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("distributed")

import casflex  # noqa: E402
from casflex.identification import Solver  # noqa: E402
from casflex.simulate import simulated_set  # noqa: E402
from casflex.study.multistart import (  # noqa: E402
    EveryStartFailed,
    draw_starts,
    multistart,  # noqa: E402
)


def test_the_starts_run_in_workers_and_the_best_is_fitted_again():
    model = casflex.assemble(casflex.load_scene("twobar"))
    sim = simulated_set(model, 0.6)
    r = multistart("twobar", sim, 2, method="direct", seed=1, progress=False, instants=[0.3, 0.5],
                   solver=Solver("ipopt"))
    ms = r.extra["multistart"]
    assert [s["start"] for s in ms["starts"]] == [s.tolist() for s in draw_starts(model.p_nominal, 2, 1)]
    assert all(s["success"] for s in ms["starts"]) and ms["best"] in (0, 1)
    assert r.success and r.method == "direct"
    np.testing.assert_allclose(r.p, model.p_nominal, rtol=1e-6)  # exact data: p* from either start (measured 1e-9)


def test_every_start_failing_is_one_error_with_the_records():
    sim = simulated_set(casflex.assemble(casflex.load_scene("twobar")), 0.1)
    with pytest.raises(EveryStartFailed, match="starts: every start failed .start 0: .*no sample there") as exc:
        multistart("twobar", sim, 2, method="direct", seed=1, progress=False, instants=[7.0])
    assert len(exc.value.records) == 2 and all("error" in r for r in exc.value.records)
    with pytest.raises(ValueError, match="method: expected one of"):
        multistart("twobar", sim, 2, method="collocation")
