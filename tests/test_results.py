"""casflex.results: atomic writes and JSON conversion."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from casflex.results import atomic_write_bytes, atomic_write_json, jsonable


def test_jsonable_converts_numpy_and_non_finite_values():
    obj = {1: np.arange(3), "f": np.float32(0.5), "i": np.int64(7), "b": np.bool_(True),
           "t": (math.nan, -math.inf, 2.0), "nested": [{"x": np.array([[1.0, math.inf]])}]}
    out = jsonable(obj)
    assert out == {"1": [0, 1, 2], "f": 0.5, "i": 7, "b": True, "t": ["nan", "-inf", 2.0],
                   "nested": [{"x": [[1.0, "inf"]]}]}
    json.dumps(out, allow_nan=False)  # strict JSON


def test_atomic_write_json_round_trip(tmp_path):
    path = atomic_write_json(tmp_path / "sub" / "r.json", {"p": np.array([1.5, 2.5]), "ok": np.bool_(False)})
    assert json.loads(path.read_text()) == {"p": [1.5, 2.5], "ok": False}
    assert [p.name for p in path.parent.iterdir()] == ["r.json"]


def test_a_write_is_flushed_to_the_disk_unless_not_durable(tmp_path, monkeypatch):
    synced = []
    monkeypatch.setattr("os.fsync", synced.append)
    atomic_write_bytes(tmp_path / "a.bin", b"x")
    assert len(synced) == 1
    path = atomic_write_json(tmp_path / "b.json", {"p": np.array([1.5])}, durable=False, indent=None)
    assert len(synced) == 1  # a sweep's record: its reader refuses a partial one
    assert path.read_text() == '{"p": [1.5]}\n'


def test_an_interrupted_write_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    path = tmp_path / "a.bin"
    atomic_write_bytes(path, b"old")

    def interrupted(fd):
        raise KeyboardInterrupt

    monkeypatch.setattr("os.fsync", interrupted)
    with pytest.raises(KeyboardInterrupt):
        atomic_write_bytes(path, b"new")
    assert path.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["a.bin"]


def test_json_text_skips_the_walk_where_the_encoder_takes_the_object_as_it_is(monkeypatch):
    # a sweep's record (lists of floats, 38 kB for a trial) was walked by jsonable before its encoding: 1.3 ms of 3
    import casflex.results as results

    plain = {"loads": {"hip": [[0.1, 2.5e-17, -3.0], [1.0]]}, "t": (0.0, 1.0), "n": 3, "ok": True, "none": None}
    mixed = {1: np.arange(3), "f": np.float32(0.5), "t": (math.nan, 2.0), "x": [{"y": np.float64(0.25)}]}
    expected = {id(o): [json.dumps(jsonable(o), indent=i) for i in (None, 2)] for o in (plain, mixed)}
    walked = []
    monkeypatch.setattr(results, "jsonable", lambda x: walked.append(x) or jsonable(x))  # its top-level calls
    for o in (plain, mixed):
        assert [results.json_text(o, i) for i in (None, 2)] == expected[id(o)]  # the same text either way
    assert not any(w is plain for w in walked) and any(w is mixed for w in walked)  # the plain record not walked
