"""Multi-start: one identification from several starts, run in parallel on a local dask cluster
(:mod:`casflex.study.sweep`), the best successful start (least objective) fitted again for the full result.

The starts are the given one and ``starts - 1`` drawn log-uniformly within a factor :data:`SPREAD` of it,
from ``seed``. Each start runs in a worker process (:func:`run_start`, a sweep run: the scene is loaded
there again by its name or file); the record of every start is in the result's ``extra["multistart"]``.
"""

from __future__ import annotations

import dataclasses
import tempfile
from typing import Any

import numpy as np

from casflex.identification import method_function
from casflex.identification.result import IdentificationResult

__all__ = ["multistart", "run_start", "draw_starts", "EveryStartFailed", "SPREAD"]

#: the drawn starts lie within this factor of the given one (log-uniformly)
SPREAD = 3.0
#: worker processes of the local cluster (fewer on a machine that runs fewer: casflex.study.sweep.max_workers)
WORKERS = 2


def _model(scene: str) -> Any:
    from casflex.model import assemble
    from casflex.scene.io import load_scene

    return assemble(load_scene(scene))


class EveryStartFailed(ValueError):
    """No start of a multi-start ran to an answer; ``records`` holds what each one did."""

    def __init__(self, message: str, records: list[dict[str, Any]]):
        super().__init__(message)
        self.records = records


def run_start(*, scene: str, method: str, data: Any, start: list[float], options: dict[str, Any]) -> dict[str, Any]:
    """One start of a multi-start (a sweep run, in a worker process, its solver quiet): the fit's summary record."""
    if options.get("solver") is not None:
        options = {**options, "solver": dataclasses.replace(options["solver"], verbose=False)}
    r = method_function(method)(_model(scene), data, start=np.array(start), **options)
    return {"start": start, "success": r.success, "status": r.status, "objective": r.objective,
            "parameters": r.parameters, "message": r.message}


def draw_starts(p0: np.ndarray, starts: int, seed: int | None) -> list[np.ndarray]:
    """``p0`` and ``starts - 1`` parameter vectors drawn log-uniformly within a factor SPREAD of it."""
    rng = np.random.default_rng(seed)
    spread = np.log(SPREAD)
    return [p0] + [p0 * np.exp(rng.uniform(-spread, spread, p0.size)) for _ in range(starts - 1)]


def multistart(scene: str, data: Any, starts: int, *, method: str = "indirect",
               start: float | dict[str, float] | np.ndarray | None = None, seed: int | None = None,
               progress: bool = True, **options: Any) -> IdentificationResult:
    """Identify the parameters of ``scene`` (a built-in name or a scene file) from ``data`` by ``method`` from
    ``starts`` starts (module docstring) and return the best one's full result.

    ``options`` are the method's other arguments (``horizon`` or ``instants``, ``shooting``, ``solver``, ``run``,
    ``uncertainty``, ...: :func:`.identify_indirect`, :func:`.identify_direct`, :func:`.identify_adapted_direct`).
    ``extra["multistart"]``: ``{"best": index, "starts": [record of each start]}``, a record holding ``start``,
    ``success``, ``status``, ``objective``, ``parameters`` and ``message``, or ``error``. ValueError when every
    start failed (:class:`EveryStartFailed`, with the records); KeyboardInterrupt when the sweep was interrupted.
    """
    from casflex.identification.problem import start_values
    from casflex.study.sweep import Run, max_workers, run_sweep

    if not (isinstance(starts, int) and starts >= 1):
        raise ValueError(f"starts: expected a whole number >= 1, got {starts!r}")
    identify = method_function(method)
    model = _model(scene)
    drawn = draw_starts(start_values(model, start), starts, seed)
    runs = [Run(f"start{k}", run_start, {"scene": scene, "method": method, "data": data, "start": s.tolist(),
                                         "options": options}) for k, s in enumerate(drawn)]
    with tempfile.TemporaryDirectory(prefix="casflex-starts-") as rec:
        sweep = run_sweep(runs, rec, n_workers=min(WORKERS, len(runs), max_workers()[0]), progress=progress)
    if sweep.interrupted:
        raise KeyboardInterrupt
    records = [sweep.results[r.key] for r in runs]
    good = [k for k, r in enumerate(records) if r.get("success")]
    pool = good or [k for k, r in enumerate(records) if "error" not in r]
    if not pool:
        raise EveryStartFailed(f"starts: every start failed (start 0: {records[0].get('error', '?')[:200]})", records)
    best = min(pool, key=lambda k: records[k]["objective"])
    result = identify(model, data, start=drawn[best], **options)
    result.extra["multistart"] = {"best": best, "starts": records}
    return result
