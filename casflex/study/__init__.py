"""Many runs at once: a sweep of identifications on dask (:mod:`casflex.study.sweep`), resumable, one
record per run. Where a lab's whole study (subjects, trials, uncertainty draws) will run."""
