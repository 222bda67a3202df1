"""Many runs at once, on dask, resumable, one record per run:

- :mod:`casflex.study.sweep`: sweeps of identifications (multi-start, Monte Carlo over noise, grids);
- :mod:`casflex.study.study_file`, :mod:`casflex.study.runner`: a lab's whole study from one file (``casflex study``):
  subjects calibrated, every trial's inverse dynamics, one tidy table and the figures;
- :mod:`casflex.study.events`: a trial's gait events (plates' contacts, the foot over each plate, gait cycles)."""
