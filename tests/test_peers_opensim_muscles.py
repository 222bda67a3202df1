"""casflex.muscles.path against OpenSim 4.6 (casflex.peers.opensim_muscles, in OpenSim's worker process):
gait10dof18musc's 18 Millard muscles (conditional and moving points, a rolling knee) and Hamner's subject 02 made
planar with its 92 Thelen muscles (tests/data/muscles/README.md), at 20 random poses inside the coordinates'
ranges: each muscle's length (``getLength``) and its moment arm about every unlocked coordinate
(``computeMomentArm``) equal OpenSim's to 1e-9 m (measured: 6e-16 m on gait10dof18musc, 2e-15 m on Hamner's)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from casflex.inverse import inverse_model, kinematic_tree
from casflex.muscles.path import MusclePaths
from casflex.scene.coordinates import from_lab
from casflex.scene.from_osim import scene_from_osim
from casflex.scene.osim import read_osim

needs_opensim = pytest.mark.skipif(importlib.util.find_spec("opensim") is None, reason="OpenSim is not installed")

DATA = Path(__file__).parent / "data" / "muscles"
GAIT, HAMNER = DATA / "gait10dof18musc.osim", DATA / "hamner_subject02_planar_muscles.osim"


def _poses(model: Path, n: int, seed: int = 47) -> list[dict[str, float]]:
    """n poses with every unlocked coordinate uniform in its range (the pelvis's translations within 1 m of the
    origin)."""
    rng = np.random.default_rng(seed)
    ranges = {c.name: c.range for j in read_osim(model).joints for c in j.coordinates if not c.locked}
    out = []
    for _ in range(n):
        out.append({c: float(rng.uniform(max(lo, -1.0), min(hi, 1.0)) if c in ("pelvis_tx", "pelvis_ty") else
                             rng.uniform(lo, hi)) for c, (lo, hi) in ranges.items()})
    return out


@needs_opensim
@pytest.mark.parametrize("model, n_muscles", [(GAIT, 18), (HAMNER, 92)])
def test_lengths_and_moment_arms_equal_opensims_at_random_poses(model, n_muscles):
    from casflex.peers.opensim_muscles import muscle_geometry

    poses = _poses(model, 20)
    ref = muscle_geometry(model, poses)
    s = scene_from_osim(model, muscles=True)
    assert len(s.muscles) == n_muscles
    sc = s.scene
    tree = kinematic_tree(inverse_model(sc))
    mp = MusclePaths(tree, s.muscles)
    assert ref["muscles"] == list(mp.names) and sorted(ref["coordinates"]) == sorted(c.name for c in sc.coordinates)
    z = np.array([[0.0] * tree.n for _ in poses])
    for k, pose in enumerate(poses):
        for c in sc.coordinates:
            z[k, tree.names.index(c.scene_coordinate())] = from_lab(sc, c, pose[c.name])
    out = mp.evaluate(z)
    order = [ref["coordinates"].index(c.name) for c in sc.coordinates]
    r_ref = ref["moment_arms"][:, :, order]
    assert np.abs(out["lengths"] - ref["lengths"]).max() < 1e-9  # the bar; measured 6e-16, 7e-16 m
    assert np.abs(out["moment_arms"] - r_ref).max() < 1e-9  # measured 6e-16, 2e-15 m
    assert np.abs(r_ref).max() > 0.05  # the poses give real moment arms (knee extensors ~0.05 m)
    conditions = [p.condition for m in s.muscles for p in m.path if p.condition]
    on = {lo - 1e-5 <= pose[c] <= hi + 1e-5 for pose in poses for c, lo, hi in conditions}
    assert on == {True, False}  # the poses switch conditional points both on and off the path
