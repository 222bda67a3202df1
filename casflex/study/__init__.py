"""Many runs at once, on dask, resumable, one record per run:

- :mod:`casflex.study.sweep`: sweeps of identifications (Monte Carlo over noise, grids);
  :mod:`casflex.study.multistart`: an identification from several starts;
- :mod:`casflex.study.study_file`, :mod:`casflex.study.runner`: a lab's whole study from one file (``casflex study``):
  subjects calibrated, every trial's inverse dynamics, one tidy table and the figures;
- :mod:`casflex.study.events`: a trial's gait events (plates' contacts, the foot over each plate, gait cycles).

The package is also the verb: ``casflex.study("study.toml", "records")`` runs a study file (:func:`run`).
"""

from __future__ import annotations

import os
import sys
import types
from pathlib import Path

__all__ = ["run"]


def run(study, record: str | os.PathLike[str], **options) -> dict:
    """A lab's whole study: ``study`` a study file's path (read and checked first:
    :func:`casflex.study.study_file.load_study`, a StudyError naming the field) or a loaded
    :class:`~casflex.study.study_file.Study`; ``record`` the directory of the runs' records (resumed from);
    ``options`` :func:`casflex.study.runner.run_study`'s (``scheduler``, ``n_workers``, ``progress``,
    ``retry_failed``). Returns run_study's dict (subjects, trials, failed, interrupted, records)."""
    from casflex.study.runner import run_study
    from casflex.study.study_file import Study, load_study

    return run_study(study if isinstance(study, Study) else load_study(os.fspath(study)), Path(record), **options)


class _Verb(types.ModuleType):
    """This package, callable as :func:`run` (``casflex.study("study.toml", "records")``): the name ``casflex.study``
    is bound to the package as soon as anything imports it, so the verb is the package."""

    def __call__(self, study, record: str | os.PathLike[str], **options) -> dict:
        return run(study, record, **options)


sys.modules[__name__].__class__ = _Verb
