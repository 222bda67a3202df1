"""casflex.study.direction: the plane of a trial from the subject's travel or facing.

Synthetic trials (deterministic): a planar "subject" of four markers (heel, toe, hip front, hip back) whose
scene-x positions are known, walking or standing in a lab with Z up, along a chosen direction."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from casflex.inverse.heading import facing_plane
from casflex.lab import LabMarkers
from casflex.study.direction import walking_plane

#: scene x, y (m) of the markers: the toe and the pelvis's front ahead of the heel and its back
SCENE = {"HEE": (-0.05, 0.05), "TOE": (0.15, 0.03), "ASI": (0.12, 0.95), "SACR": (-0.08, 0.97)}
LABELS = list(SCENE)


def _scene():
    return SimpleNamespace(markers=[SimpleNamespace(name=n, label=None, lab_label=n, x=x, y=y)
                                    for n, (x, y) in SCENE.items()])


def _trial(heading_deg, speed: float = 1.2, duration: float = 2.0, rate: float = 100.0, facing=None,
           turn_deg: float = 0.0) -> LabMarkers:
    """Markers walking at ``speed`` along the heading (degrees from lab +X toward +Y, Z up), turning by
    ``turn_deg`` over the trial; the body faces its direction of travel (or ``facing`` when standing)."""
    t = np.arange(0.0, duration, 1.0 / rate)
    head = np.radians(heading_deg + turn_deg * t / duration)
    face = head if facing is None else np.full_like(t, np.radians(facing))
    step = speed / rate * np.column_stack([np.cos(head), np.sin(head)])
    centre = np.vstack([np.zeros(2), np.cumsum(step, axis=0)[:-1]])
    xyz = np.empty((t.size, len(SCENE), 3))
    for k, (x, y) in enumerate(SCENE.values()):
        xyz[:, k, 0] = centre[:, 0] + x * np.cos(face)
        xyz[:, k, 1] = centre[:, 1] + x * np.sin(face)
        xyz[:, k, 2] = y
    return LabMarkers(t, tuple(LABELS), xyz, rate, "m", "synthetic")


@pytest.mark.parametrize(("heading", "plane"), [(0, "X,Z"), (180, "-X,Z"), (90, "Y,Z"), (-90, "-Y,Z")])
def test_the_plane_follows_the_travel(heading, plane):
    got, line = walking_plane(_trial(heading), LABELS, "Z")
    assert got == plane and "2.39 m" in line  # 199 steps of 12 mm (1.2 m/s at 100 Hz for 2 s)


@pytest.mark.parametrize(("facing", "plane"), [(0, "X,Z"), (180, "-X,Z"), (90, "Y,Z"), (-90, "-Y,Z")])
def test_a_standing_subject_s_plane_is_the_one_it_faces(facing, plane):
    still = _trial(0.0, speed=0.0, facing=facing)
    assert walking_plane(still, LABELS, "Z") is None
    assert facing_plane(_scene(), still, "Z")[0] == plane


def test_a_marker_entering_the_view_late_does_not_fake_a_travel():
    lab = _trial(0.0, speed=0.0)
    lab.xyz[:100, 0] = np.nan  # the heel seen from 1 s on, 3 m away from the others' start: no step joins it
    lab.xyz[100:, 0, 0] += 3.0
    assert walking_plane(lab, LABELS, "Z") is None


def test_a_facing_the_markers_cannot_tell_is_refused():
    lab = _trial(0.0, speed=0.0)
    lab.xyz[:, :, :2] = 0.0  # every marker on one vertical line: no horizontal direction
    lab.xyz[:, :, 0] += np.arange(len(SCENE)) * 1e-9
    with pytest.raises(ValueError, match="cannot tell"):
        facing_plane(_scene(), lab, "Z")


def _hamner_legs(drop=()):
    """(hamner_leg's scene, Hamner's treadmill running trial cut to that scene's pelvis and right-leg markers, less
    ``drop``): a leg-only marker set, on a treadmill (the pelvis stays within some 0.1 m over the trial)."""
    import dataclasses
    from pathlib import Path

    from casflex import load_scene
    from casflex.lab import read_trc

    scene = load_scene("hamner_leg")
    lab = read_trc(Path(__file__).resolve().parent / "data" / "lab" / "hamner_running_whole.trc")
    keep = [i for i, lb in enumerate(lab.labels) if lb in {m.lab_label for m in scene.markers} - set(drop)]
    return scene, dataclasses.replace(lab, labels=tuple(lab.labels[i] for i in keep), xyz=lab.xyz[:, keep])


@pytest.mark.parametrize("plane", ["X,Y", "auto"])
def test_a_treadmill_trial_with_a_leg_only_marker_set_is_straight(plane):
    # the heading from the pelvis's markers: the median over the pelvis and one leg's 13 markers was the swinging
    # leg's, refused as "the subject turns (the heading from -163 to +16 degrees ...)" where casflex inverse runs
    from casflex.inverse.heading import heading_line
    from casflex.study.runner import _trial_plane

    scene, lab = _hamner_legs()
    got, _ = _trial_plane(scene, lab, plane, "Y")
    line = heading_line(scene, lab, got, None, None, None)
    assert got == "X,Y" and line.startswith(("straight", "heading not checked: the subject does not")), line


def test_a_trial_without_the_pelvis_markers_says_which_are_missing():
    # it said "the subject walks backwards in the plane X,Y (the heading from -180 to +174 degrees ...)"
    from casflex.study.runner import _trial_plane

    scene, lab = _hamner_legs(drop=("R.ASIS", "L.ASIS", "V.Sacral"))
    with pytest.raises(ValueError, match=r"none of the root segment pelvis's markers \(R\.ASIS, L\.ASIS, V\.Sacral\)"):
        _trial_plane(scene, lab, "X,Y", "Y")
