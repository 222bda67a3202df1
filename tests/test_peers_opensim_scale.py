"""The muscles of a scaled subject (casflex.muscles.scaling) against OpenSim 4.6's own ``Model::scale`` with the
same factor per body: Hamner's subject 02, planar, 92 muscles (tests/data/muscles)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from casflex.inverse.calibrate import _scaled_scene
from casflex.inverse.inputs import inverse_model
from casflex.inverse.tree import kinematic_tree
from casflex.muscles.path import MusclePaths
from casflex.muscles.scaling import scaled_muscles
from casflex.scene.from_osim import node_name, scene_from_osim

needs_opensim = pytest.mark.skipif(importlib.util.find_spec("opensim") is None, reason="OpenSim is not installed")
MODEL = Path(__file__).parent / "data" / "muscles" / "hamner_subject02_planar_muscles.osim"


@needs_opensim
def test_scaled_muscles_equal_opensims_model_scale():
    """Each segment scaled by its own factor in 0.9-1.1 (seeded): every muscle's optimal fibre and tendon slack
    length and its muscle-tendon length at the default pose equal OpenSim's after ``Model::scale`` with those
    factors per body (the segment's bodies alike), maximum isometric forces kept by both."""
    from casflex.peers.opensim_scale import scaled_muscles as opensims

    osim = scene_from_osim(MODEL, muscles=True)
    tree = kinematic_tree(inverse_model(osim.scene, None))
    cluster = {n: tree.cluster[i] for i, n in enumerate(tree.model.node_names)}
    rng = np.random.default_rng(0)
    factor = {c: float(rng.uniform(0.9, 1.1)) for c in sorted(set(tree.cluster))}
    after = _scaled_scene(tree, factor)
    moved, _ = scaled_muscles(osim, after)
    ref = opensims(MODEL, {b: factor[cluster[node_name(b)]] for b in osim.frames if b != "ground"})
    t1 = kinematic_tree(inverse_model(after, None))
    lengths = np.asarray(MusclePaths(t1, moved.muscles).length(t1.coordinates(np.asarray(t1.model.q0).ravel())))
    for m, L in zip(moved.muscles, lengths.ravel(), strict=True):
        L_ref, l_opt, l_ts, f_iso = ref[m.name]
        assert m.optimal_fiber_length == pytest.approx(l_opt, rel=1e-12)  # both: the same products, to round-off
        assert m.tendon_slack_length == pytest.approx(l_ts, rel=1e-12)
        assert L == pytest.approx(L_ref, abs=1e-12)  # m: a metre-long path summed to 1e-16 relative
        assert m.max_isometric_force == f_iso


@needs_opensim
def test_a_scaled_subject_s_markers_are_where_opensims_scaled_model_puts_them_coupled_knee_included(tmp_path):
    """Hamner's leg, each segment by its own factor (femur 1.2, shank 0.9, foot 1.1), at 8 random poses (the knee
    to -2 rad, the ankle at 0: its axis is projected): every marker where OpenSim 4.6's ``Model::scale`` of the
    same file puts it, to round-off. The knee's rolling (OpenSim multiplies a custom joint's translation functions by
    its parent's factor) was left unscaled: the shank's and foot's markers 5.2 mm off."""
    from casflex.peers.opensim import file_kinematics
    from casflex.peers.opensim_scale import write_scaled
    from casflex.scene.coordinates import from_lab

    path = Path(__file__).parent / "data" / "lab" / "hamner_subject02_leg.osim"
    factors = {"pelvis": 1.0, "femur_r": 1.2, "tibia_r": 0.9, "talus_r": 1.1, "calcn_r": 1.1, "toes_r": 1.1}
    sc = scene_from_osim(path).scene
    tree = kinematic_tree(inverse_model(sc, "pelvis"), "pelvis")
    after = _scaled_scene(tree, {tree.cluster[i]: factors[n] for i, n in enumerate(tree.model.node_names)})
    ref_file = write_scaled(path, factors, tmp_path / "scaled.osim")
    rng = np.random.default_rng(7)
    n = 8
    values = {"pelvis_tilt": rng.uniform(-0.3, 0.3, n), "pelvis_tx": rng.uniform(-1, 1, n),
              "pelvis_ty": rng.uniform(0.8, 1.1, n), "hip_flexion_r": rng.uniform(-0.5, 1.2, n),
              "knee_angle_r": rng.uniform(-2.0, 0.0, n), "ankle_angle_r": np.zeros(n)}
    t1 = kinematic_tree(inverse_model(after, "pelvis"), "pelvis")
    by = {c.scene_coordinate(): c for c in after.coordinates}
    z = np.array([[from_lab(after, by[nm], values[by[nm].name][k]) for nm in t1.names] for k in range(n)])
    ours = np.array([np.array(t1.marker_fit(zk)[0]).reshape(-1, 2) for zk in z])
    ref = file_kinematics(ref_file, values)
    theirs = np.stack([ref[f"marker:{m.label}"][:, :2] for m in after.markers], axis=1)
    assert np.max(np.abs(ours - theirs)) < 1e-12  # m: metre-sized sums of the same products, to round-off
