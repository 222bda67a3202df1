"""Other codes that simulate casflex scenes, for cross-checks and reference data (optional
installs: the extra ``peers``)."""
