"""casflex.muscles.path against OpenSim 4.6 (casflex.peers.opensim_muscles, in OpenSim's worker process):
gait10dof18musc's 18 Millard muscles (conditional and moving points, a rolling knee) and Hamner's subject 02 made
planar with its 92 Thelen muscles (tests/data/muscles/README.md), at 20 random poses inside the coordinates'
ranges: each muscle's length (``getLength``) and its moment arm about every unlocked coordinate
(``computeMomentArm``) equal OpenSim's to 1e-9 m (measured: 6e-16 m on gait10dof18musc, 2e-15 m on Hamner's)."""

from __future__ import annotations

import dataclasses
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
RAJAGOPAL = DATA / "rajagopal_planar_wraps.osim"


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


def _compare(model: Path, poses: list[dict[str, float]]):
    """casflex's and OpenSim's lengths (k, n_m) and moment arms (k, n_m, n_c) at ``poses``, and the scene."""
    from casflex.peers.opensim_muscles import muscle_geometry

    ref = muscle_geometry(model, poses)
    s = scene_from_osim(model, muscles=True)
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
    return s, out, ref["lengths"], ref["moment_arms"][:, :, order]


@needs_opensim
@pytest.mark.parametrize("model, n_muscles", [(GAIT, 18), (HAMNER, 92)])
def test_lengths_and_moment_arms_equal_opensims_at_random_poses(model, n_muscles):
    poses = _poses(model, 20)
    s, out, L_ref, r_ref = _compare(model, poses)
    assert len(s.muscles) == n_muscles
    assert np.abs(out["lengths"] - L_ref).max() < 1e-9  # the bar; measured 6e-16, 7e-16 m
    assert np.abs(out["moment_arms"] - r_ref).max() < 1e-9  # measured 6e-16, 2e-15 m
    assert np.abs(r_ref).max() > 0.05  # the poses give real moment arms (knee extensors ~0.05 m)
    conditions = [p.condition for m in s.muscles for p in m.path if p.condition]
    on = {lo - 1e-5 <= pose[c] <= hi + 1e-5 for pose in poses for c, lo, hi in conditions}
    assert on == {True, False}  # the poses switch conditional points both on and off the path


def _one_depth(source: Path, dest: Path) -> Path:
    """The model with each wrapping muscle's path points moved along the plane's normal to its cylinder's centre's
    depth (in the ground at the default pose; the bodies turn about the normal only, so at every pose)."""
    import xml.etree.ElementTree as ET

    o = scene_from_osim(source, muscles=True)
    depth = {m.name: m.wraps[0].centre[2] for m in o.muscles if m.wraps}
    tree = ET.parse(source)
    for el in tree.getroot().find("Model/ForceSet/objects"):
        for p in el.findall("GeometryPath/PathPointSet/objects/*") if el.get("name") in depth else ():
            R, pos = o.frames[p.findtext("socket_parent_frame").strip().rsplit("/", 1)[-1]]
            loc = np.array([float(v) for v in p.findtext("location").split()])
            loc[2] = (depth[el.get("name")] - pos[2] - R[2, 0] * loc[0] - R[2, 1] * loc[1]) / R[2, 2]
            p.find("location").text = " ".join(f"{v:.17g}" for v in loc)
    tree.write(dest, encoding="UTF-8", xml_declaration=True)
    return dest


@needs_opensim
def test_wrapped_paths_equal_opensims_where_both_points_lie_at_the_cylinders_depth(tmp_path):
    """Rajagopal's planar leg (tests/data/muscles/README.md): biceps femoris short head over a '+y' cylinder,
    the gastrocnemii and rectus femoris over 'all' ones, its points moved to the cylinders' depth: the wrap is a
    circle in the plane for OpenSim too, and both give one length and moment arm (measured 3e-16 m)."""
    model = _one_depth(RAJAGOPAL, tmp_path / "one_depth.osim")
    poses = _poses(model, 20)
    s, out, L_ref, r_ref = _compare(model, poses)
    assert np.abs(out["lengths"] - L_ref).max() < 1e-9  # the bar
    assert np.abs(out["moment_arms"] - r_ref).max() < 1e-9
    straight = MusclePaths(kinematic_tree(inverse_model(s.scene)),
                           [dataclasses.replace(m, wraps=()) for m in s.muscles])
    tree = straight.tree
    z = np.array([[from_lab(s.scene, c, p[c.name]) if (c := _by_own(s, n)) else 0.0 for n in tree.names]
                  for p in poses])
    wrapped = np.abs(out["lengths"] - straight.evaluate(z)["lengths"]) > 1e-6
    assert wrapped[:, :4].any(axis=0).all() and not wrapped[:, :4].all(axis=0).any()  # on and off the cylinders


def _by_own(s, name: str):
    return next((c for c in s.scene.coordinates if c.scene_coordinate() == name), None)


@needs_opensim
def test_wrapped_paths_off_the_cylinders_plane_differ_from_opensims_by_micrometres():
    """The model's own points (their depths differ by up to 2.6 cm along the cylinder): casflex takes the exact
    shortest path round the cylinder, OpenSim an approximate slide of its tangent points (casflex.muscles.wrap);
    measured: 3.1e-6 m in length, 2.5e-6 m in moment arm over 20 random poses."""
    s, out, L_ref, r_ref = _compare(RAJAGOPAL, _poses(RAJAGOPAL, 20))
    assert np.abs(out["lengths"] - L_ref).max() < 2e-5  # 6x the measured 3.1e-6 m
    assert np.abs(out["moment_arms"] - r_ref).max() < 2e-5
    assert np.abs(out["lengths"] - L_ref)[:, 4].max() < 1e-9  # the soleus, with no wrap: exact


@needs_opensim
@pytest.mark.parametrize("model", [GAIT, HAMNER])
def test_the_compliant_tendons_equilibrium_is_opensims(model):
    """casflex.muscles.compliant's fibre-tendon equilibrium (the fibre's velocity 0, passive forces in) against
    OpenSim 4.6's ``equilibrateMuscles`` with the speeds 0, every muscle at activation 0.3, 3 random poses:
    gait10dof18musc's 18 Millard muscles and Hamner's 92 Thelen muscles (measured: 8e-9 of F_iso, OpenSim's own
    equilibrium tolerance)."""
    from casflex.muscles.compliant import tendon_equilibrium
    from casflex.peers.opensim_muscles import fiber_equilibrium

    poses = _poses(model, 3)
    ref = fiber_equilibrium(model, poses, 0.3)
    s = scene_from_osim(model, muscles=True)
    assert ref["muscles"] == [m.name for m in s.muscles]
    worst, loaded = 0.0, 0
    for i, m in enumerate(s.muscles):
        for k in range(len(poses)):
            T, ln = tendon_equilibrium(m, ref["lengths"][k, i], 0.3, passive=True)
            worst = max(worst, abs(T - ref["tendon_forces"][k, i]) / m.max_isometric_force)
            if ref["tendon_forces"][k, i] > 0.01 * m.max_isometric_force:  # a slack tendon leaves the fibre free
                loaded += 1
                assert abs(ln - ref["norm_fiber_lengths"][k, i]) < 1e-5
    assert worst < 1e-7  # OpenSim solves its equilibrium to ~1e-8 of F_iso
    assert loaded > len(s.muscles)  # most tendons pull
