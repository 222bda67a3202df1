"""Which way a subject walks or faces, for a study whose plane is ``"auto"`` (the lab's vertical axis given).

A lab's walkway does not fix the direction: children walk it both ways, and stand facing either end in a static
trial. Each trial's plane is then the sagittal one of that trial, seen from the subject's right as the study's
scenes are (OpenSim's convention: x forward, y up):

- a trial in which the subject travels (the markers' median displacement over the horizontal >=
  :data:`MIN_TRAVEL`): x along that displacement's larger horizontal lab axis, with its sign
  (:func:`walking_plane`);
- a static trial (before the scene is calibrated to the subject): of the four horizontal directions, the one
  along which the markers lie as the scene's lie along its x (:func:`casflex.inverse.heading.facing_plane`: the
  calibration checks a given plane with it);
- a trial in which the subject stays (a treadmill; the scene calibrated): the direction in whose plane the scene
  fits the trial's frames best (:func:`fitted_plane`).

Whether a trial is straight enough for a planar model and whose markers tell the subject's travel are
:mod:`casflex.inverse.heading`'s (:func:`~casflex.inverse.heading.check_straight`, which every marker trial's inverse
dynamics runs, and :func:`~casflex.inverse.heading.travel_labels`, which the study's plane uses).
"""

from __future__ import annotations

import numpy as np

from casflex.inverse.heading import LAB_AXES, MIN_TRAVEL, horizontal_axes, median_steps
from casflex.lab import LabMarkers, Plane

__all__ = ["walking_plane", "fitted_plane"]


def walking_plane(lab: LabMarkers, labels: list[str], vertical: str) -> tuple[str, str] | None:
    """(plane, report line): the plane whose x is the subject's travel over the trial (module docstring); None
    where it travels less than :data:`MIN_TRAVEL`."""
    if lab.t.size < 2 or not labels:
        return None
    d = np.nansum(median_steps(lab, labels), axis=0)
    h = horizontal_axes(vertical)
    if np.hypot(*d[h]) < MIN_TRAVEL:
        return None
    k = h[int(np.argmax(np.abs(d[h])))]
    plane = f"{'-' if d[k] < 0 else ''}{LAB_AXES[k]},{vertical}"
    return plane, f"plane {plane}: the subject travels {np.hypot(*d[h]):.2f} m along {'-' if d[k] < 0 else '+'}" \
                  f"{LAB_AXES[k]}"


def fitted_plane(scene, lab: LabMarkers, vertical: str, root: str | None = None, frames: int = 5) -> tuple[str, str]:
    """(plane, report line): of the four horizontal directions, the one in whose plane the scene (calibrated to the
    subject) fits ``frames`` frames of the trial best (their summed misfit; frames spread over those with half the
    markers seen): a running or walking trial on a treadmill, whose mean is no pose the scene's x can be read from."""
    from casflex.inverse.built import inverse_tree
    from casflex.inverse.fit import fit_pose

    tree = inverse_tree(scene, root)  # built once for the subject's trials (casflex.inverse.built)
    labels = {m.name: m.lab_label for m in tree.model.scene.markers if m.lab_label in lab.labels}
    seen = np.flatnonzero(np.isfinite(np.stack([lab.marker(lb) for lb in labels.values()], axis=1)).all(axis=2)
                          .sum(axis=1) >= max(1, len(labels) // 2))
    if not seen.size:
        raise ValueError(f"{lab.source}: no frame with half the scene's markers seen: give the plane")
    pick = seen[np.linspace(0, seen.size - 1, min(frames, seen.size)).round().astype(int)]
    nan = np.full((pick.size, 3), np.nan)
    X = np.stack([lab.marker(m.lab_label)[pick] if m.lab_label in lab.labels else nan
                  for m in tree.model.scene.markers], axis=1)  # (frames, the scene's markers, 3), NaN: not in it
    misfit = {}
    for k in horizontal_axes(vertical):
        for sign in ("", "-"):
            plane = f"{sign}{LAB_AXES[k]},{vertical}"
            y = (X @ Plane.parse(plane).matrix.T).reshape(pick.size, -1)
            misfit[plane] = float(sum(fit_pose(tree, yi)[1] for yi in y))
    best = min(misfit, key=misfit.get)
    others = ", ".join(f"{p} {1e3 * v / pick.size:.0f}" for p, v in misfit.items() if p != best)
    return best, f"plane {best}: the subject faces {best.split(',')[0]} (the scene's misfit over {pick.size} frames " \
                 f"{1e3 * misfit[best] / pick.size:.0f} mm; {others} mm in the others)"


