"""What the inverse builds from a scene alone, built once (casflex.inverse.built): kept in the process by the
scene's content (another subject's mass or length never gets another's functions), kept on disk in $CASFLEX_CACHE
(the same numbers to the last bit loaded as built; a damaged or truncated entry built again and replaced; a changed
scene a new entry), the cache's files written whole or not at all."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np
import pytest
from inverse_scenes import A, W, pendulum

from casflex import codegen
from casflex.inverse import Filter, Trial, inverse_dynamics, inverse_model, kinematic_tree
from casflex.inverse import built as built_mod
from casflex.inverse.built import inverse_tree
from casflex.inverse.rigid import rigid_loads
from casflex.lab import LabMarkers
from casflex.model.markers import marker_positions
from casflex.scene.io import loads_scene

LAB = Path(__file__).resolve().parent / "data" / "lab"


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """An empty $CASFLEX_CACHE and an empty memo (what another process would start with), both reset after."""
    monkeypatch.setenv("CASFLEX_CACHE", str(tmp_path / "cache"))
    built_mod._kept.cache_clear()
    yield tmp_path / "cache"
    built_mod._kept.cache_clear()


def _swing(t: np.ndarray):
    z = np.zeros((t.size, 4))
    zd, zdd = np.zeros_like(z), np.zeros_like(z)
    z[:, 1] = 1.0
    z[:, 3], zd[:, 3], zdd[:, 3] = A * np.sin(W * t), A * W * np.cos(W * t), -A * W * W * np.sin(W * t)
    return z, zd, zdd


def _loads(tree) -> np.ndarray:
    t = np.linspace(0.0, 1.0, 41)
    return rigid_loads(tree, t, *_swing(t), tree.model.p_nominal)["pivot.moment"]


def _changed(scene, what: str):
    """``scene`` with the arm's mass 1 % more, or the arm 1 cm longer (its centre of mass 1 cm farther from the
    pivot)."""
    if what == "mass":
        return dataclasses.replace(scene, bodies=tuple(dataclasses.replace(b, mass=1.01 * b.mass) if b.name == "arm"
                                                       else b for b in scene.bodies))
    arm = next(b for b in scene.bodies if b.name == "arm")
    return dataclasses.replace(scene, bodies=tuple(dataclasses.replace(b, com_y=b.com_y - 0.01) if b is arm else b
                                                   for b in scene.bodies))


@pytest.mark.parametrize("what", ["mass", "length"])
def test_scenes_differing_in_one_mass_or_length_get_their_own_functions(cache, what):
    scene = loads_scene(pendulum())
    other = _changed(scene, what)
    first = _loads(inverse_tree(scene))
    kept = inverse_tree(other)  # built after the first: a memo keyed by name or shape would hand it the first's
    fresh = kinematic_tree(inverse_model(other))  # built from nothing
    assert np.array_equal(_loads(kept), _loads(fresh))
    assert np.abs(_loads(kept) - first).max() > 1e-3 * np.abs(first).max()  # the change shows in the moment
    assert kept.model.scene == other and kept is not inverse_tree(scene)
    assert len(codegen.built_entries()) == 2  # and on disk: a new entry


def test_one_scene_is_built_once_in_a_process(cache):
    scene = loads_scene(pendulum())
    tree = inverse_tree(scene)
    again = loads_scene(pendulum())  # read again (a study's next trial): equal, not the same object
    assert again is not scene and inverse_tree(again) is tree
    assert inverse_tree(scene, "base") is tree  # the root named: the default's


def _pendulum_trial():
    scene = loads_scene(pendulum())
    tree = kinematic_tree(inverse_model(scene))
    t = np.arange(0.0, 0.6 + 1e-9, 0.01)
    q = np.array(tree.forward.map(t.size)(_swing(t)[0].T)).T
    y = marker_positions(tree.model, q).reshape(t.size, -1, 2) + 1e-3 * np.sin(7.0 * t)[:, None, None]
    lab = LabMarkers(t, ("BASE.1", "BASE.2", "ARM.1", "ARM.2"), np.concatenate([y, np.zeros_like(y[..., :1])], 2),
                     100.0, "m", "synthetic")
    return scene, lab


def _arrays(res) -> dict[str, np.ndarray]:
    out = {k: getattr(res, k) for k in ("t", "z", "zd", "zdd", "q", "qd", "qdd", "marker_rms", "marker_misfit")}
    out |= {f"load {k}": v for k, v in res.loads.items()}
    out |= {f"band {k} {part}": v for k, b in res.bands.items() for part, v in b.items()}
    return out


def _same_bits(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for k in a:
        assert np.array_equal(a[k], b[k], equal_nan=True), k


def test_the_numbers_are_the_same_to_the_last_bit_built_kept_or_loaded(cache):
    scene, lab = _pendulum_trial()

    def run():
        return _arrays(inverse_dynamics(scene, Trial(lab), filter=Filter(cutoff=8.0), bands=_bands()))

    built = run()  # built, and stored
    assert len(codegen.built_entries()) == 2  # the inverse's model and the bands' (the masses as parameters)
    kept = run()  # the same process: the memo's
    built_mod._kept.cache_clear()
    loaded = run()  # a new process's: from the disk
    _same_bits(built, kept)
    _same_bits(built, loaded)
    assert any(k.startswith("band ") for k in built)


def _bands():
    from casflex.inverse import Bands
    from casflex.scene.uncertain import parse

    return Bands([parse("arm.mass=10%")], 0.002)


def test_the_lab_trial_is_the_same_to_the_last_bit_from_the_cache(cache):
    from casflex.inverse import prepare, solve
    from casflex.peers.opensim_tools import external_loads

    loads = external_loads(cache.parent / "loads.xml", LAB / "hamner_running_whole_grf.mot",
                           {"calcn_r": "ground_", "calcn_l": "1_ground_"})
    trial = Trial(str(LAB / "hamner_running_whole.trc"), grf=loads, t_start=0.3, t_end=0.6,
                  tasks=str(LAB / "hamner_tasks_ik.xml"))

    def run():
        return _arrays(solve(prepare(str(LAB / "hamner_subject02_planar.osim"), trial, filter=Filter(8.0, None))))

    built = run()
    built_mod._kept.cache_clear()
    _same_bits(built, run())


def _entry(cache: Path) -> Path:
    (path,) = codegen.built_entries()
    return path


@pytest.mark.parametrize("damage", ["truncated", "a byte changed", "empty", "another value"])
def test_a_damaged_entry_is_built_again_and_replaced(cache, damage):
    scene = loads_scene(pendulum())
    want = _loads(inverse_tree(scene))
    path = _entry(cache)
    whole = path.read_bytes()
    if damage == "truncated":
        path.write_bytes(whole[:len(whole) // 2])
    elif damage == "a byte changed":
        path.write_bytes(whole[:-100] + bytes([whole[-100] ^ 1]) + whole[-99:])
    elif damage == "empty":
        path.write_bytes(b"")
    else:  # a whole file, checksum and all, of something else: read, then refused for its shape
        codegen.store_built("inverse", path.name.split("-")[1].split(".")[0], {"model": "not a model"})
    built_mod._kept.cache_clear()
    assert np.array_equal(_loads(inverse_tree(scene)), want)
    assert path.read_bytes() != b"" and codegen.load_built("inverse", path.name.split("-")[1].split(".")[0])["model"]
    built_mod._kept.cache_clear()
    assert np.array_equal(_loads(inverse_tree(scene)), want)  # the replaced entry reads


def test_the_entry_is_keyed_by_the_code_that_builds_it(cache, monkeypatch):
    scene = loads_scene(pendulum())
    inverse_tree(scene)
    monkeypatch.setattr(built_mod, "_source_digest", lambda: "another casflex")  # an edited model module
    built_mod._kept.cache_clear()
    inverse_tree(scene)
    assert len(codegen.built_entries()) == 2


def test_an_entry_is_written_whole_or_not_at_all(cache, monkeypatch):
    real = os.fdopen

    class Stopped:  # the write stopped half-way by a Ctrl-C
        def __init__(self, fh):
            self.fh = fh

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

        def write(self, data):
            self.fh.write(data[:len(data) // 2])
            raise KeyboardInterrupt

    monkeypatch.setattr(codegen.os, "fdopen", lambda fd, mode: Stopped(real(fd, mode)))
    with pytest.raises(KeyboardInterrupt):
        codegen.store_built("inverse", "k" * 24, {"x": 1})
    assert not cache.exists() or list(cache.iterdir()) == []  # no entry, no temporary file
    monkeypatch.setattr(codegen.os, "fdopen", real)
    codegen.store_built("inverse", "k" * 24, {"x": 1})
    assert codegen.load_built("inverse", "k" * 24) == {"x": 1}


def test_a_cache_that_cannot_be_written_leaves_the_run_as_it_is(tmp_path, monkeypatch):
    blocked = tmp_path / "file"
    blocked.write_text("not a folder")
    monkeypatch.setenv("CASFLEX_CACHE", str(blocked / "cache"))
    built_mod._kept.cache_clear()
    try:
        scene = loads_scene(pendulum())
        assert np.array_equal(_loads(inverse_tree(scene)), _loads(kinematic_tree(inverse_model(scene))))
    finally:
        built_mod._kept.cache_clear()


def test_the_cache_command_counts_and_clears_the_built_entries(cache, capsys):
    from casflex.cli import main

    inverse_tree(loads_scene(pendulum()))
    assert main(["cache"]) == 0
    out = capsys.readouterr().out
    assert "0 compiled libraries, 1 built entry (OpenSim models read, inverse dynamics' models" in out
    assert main(["cache", "--clear"]) == 0
    assert codegen.built_entries() == []


def test_an_opensim_model_is_read_again_when_its_file_changes(cache, tmp_path):
    from casflex.inverse.built import osim_scene

    path = tmp_path / "model.osim"
    text = (LAB / "hamner_subject02_planar.osim").read_text()
    path.write_text(text)
    first, _ = osim_scene(path)
    assert osim_scene(path)[0] == first  # the kept one
    path.write_text(text.replace("<mass>10.325396529749399</mass>", "<mass>11.325396529749399</mass>", 1))
    pelvis = next(b for b in osim_scene(path)[0].bodies if b.name == "pelvis")
    assert pelvis.mass == 11.325396529749399  # the file's new mass, not the kept scene's
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "model.osim").write_text(path.read_text())  # the same bytes elsewhere: its own entry
    osim_scene(tmp_path / "other" / "model.osim")
    assert len([p for p in codegen.built_entries() if p.name.startswith("osim-")]) == 3


_WRITER = """
import sys
from casflex import codegen
value = {"payload": bytes(range(256)) * 4000, "n": 1}
for _ in range(int(sys.argv[1])):
    codegen.store_built("inverse", "c" * 24, value)
"""


def test_two_processes_writing_one_entry_leave_it_whole_for_its_readers(cache):
    import subprocess
    import sys

    value = {"payload": bytes(range(256)) * 4000, "n": 1}  # 1 MB: a write takes a while
    env = dict(os.environ, CASFLEX_CACHE=str(cache))
    writers = [subprocess.Popen([sys.executable, "-c", _WRITER, "40"], env=env) for _ in range(2)]
    seen = []
    while any(w.poll() is None for w in writers):
        got = codegen.load_built("inverse", "c" * 24)  # None: no entry yet, or a damaged (half-written) one
        seen.append("none" if got is None else "value" if got == value else "other")
    assert [w.wait() for w in writers] == [0, 0]
    first = seen.index("value") if "value" in seen else len(seen)
    assert "other" not in seen and "none" not in seen[first:]  # once there, always whole
    assert codegen.load_built("inverse", "c" * 24) == value
    assert sorted(p.name for p in cache.iterdir()) == [f"inverse-{'c' * 24}.built"]  # no temporary file left


def test_without_the_code_s_sources_nothing_is_kept_on_disk(cache, monkeypatch):
    monkeypatch.setattr(built_mod, "_PACKAGE", cache.parent / "no casflex here")  # an installation without sources
    built_mod._source_digest.cache_clear()
    try:
        scene = loads_scene(pendulum())
        assert np.array_equal(_loads(inverse_tree(scene)), _loads(kinematic_tree(inverse_model(scene))))
        assert codegen.built_entries() == []
    finally:
        built_mod._source_digest.cache_clear()


def test_the_cache_keeps_the_entries_used_last_up_to_its_bound(cache, monkeypatch):
    monkeypatch.setattr(codegen, "MAX_BUILT", 3)
    for k, key in enumerate("abc"):
        codegen.store_built("inverse", key * 24, {"n": k})
    for k, path in enumerate(codegen.built_entries()):  # a, b, c: written long ago, in that order
        os.utime(path, (1.0 + k, 1.0 + k))
    assert codegen.load_built("inverse", "a" * 24) == {"n": 0}  # the first written, used now
    codegen.store_built("inverse", "d" * 24, {"n": 3})  # one too many: the one used longest ago goes, b
    assert codegen.load_built("inverse", "b" * 24) is None
    assert [codegen.load_built("inverse", k * 24)["n"] for k in "acd"] == [0, 2, 3]


def test_an_opensim_path_that_is_no_file_is_the_reader_s_to_refuse(cache, tmp_path):
    from casflex.inverse.built import osim_scene

    folder = tmp_path / "model.osim"
    folder.mkdir()
    pipe = tmp_path / "pipe.osim"
    os.mkfifo(pipe)  # opened for its bytes, it would wait for a writer for ever
    for path in (folder, tmp_path / "missing.osim"):
        with pytest.raises(ValueError, match=f"^{path}: "):
            osim_scene(path)
    from casflex.inverse.built import _file_digest

    assert _file_digest(str(pipe)) is None and codegen.built_entries() == []
