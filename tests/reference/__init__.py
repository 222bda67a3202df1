"""Independent reference solutions (plain numpy, no casflex) used by the tests."""
