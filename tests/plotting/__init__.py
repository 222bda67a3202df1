"""Tests of :mod:`casflex.plotting`, one file per module of the package."""
