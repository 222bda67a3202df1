"""Whether a marker trial is straight enough for a planar model: :func:`check_straight` refuses a trial in which the
subject turns (a planar model sees a turn's steps foreshortened and its joints' moments about the wrong axis, without
a word), walks backwards in the plane, or walks straight along a diagonal of it. It compares the heading of the
markers' median horizontal velocity, while the subject moves faster than :data:`WALKING_SPEED`, with the plane's x;
not in a trial whose markers stay within :data:`MIN_TRAVEL` of their place (a treadmill: its runner's pelvis sways
forward and back at up to 0.4 m/s, a velocity of either sign that no heading describes).

Travel and heading are read from the markers of the root segment (:func:`travel_labels`: the pelvis of OpenSim's
models), which moves with the body as a whole: a leg's markers swing forward and back at twice the body's speed
(on a treadmill the median over a pelvis-and-leg set is the swinging leg's, which turned a straight trial into "the
subject turns"). A trial that has none of them is refused naming them (it cannot be fitted either).

Run by :func:`casflex.inverse.prepare` on every marker trial's window (``casflex inverse``, a study's trials); a
study's plane ``"auto"`` reads the travel with the same helpers (:mod:`casflex.study.direction`).
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from casflex.lab import LabMarkers, Plane

__all__ = ["travel_labels", "median_steps", "check_straight", "heading_line", "facing_plane", "MIN_TRAVEL",
           "WALKING_SPEED", "MAX_TURN", "MIN_CORRELATION", "LAB_AXES", "horizontal_axes"]

#: m: less travel than this over a trial is standing (a static trial, a treadmill)
MIN_TRAVEL = 0.5
#: m/s: the heading is judged only while the subject moves at least this fast (slow gait is some 0.5 m/s)
WALKING_SPEED = 0.3
#: degrees: a straight walk's heading sways a few degrees per step (the sample study's: within 12); a turn's is
#: tens of degrees
MAX_TURN = 25.0

def travel_labels(scene, lab: LabMarkers, root: str | None = None) -> list[str]:
    """The lab labels of the scene's markers that define the subject's travel and heading: those on the root
    segment (the bodies at the node ``root``, default the scene's first node) that the trial has; where the root
    carries no marker, every scene marker the trial has. ValueError in one line naming the root's markers where
    the trial has none of them."""
    root = root or scene.nodes[0].name
    on_root = {b.name for b in scene.bodies if b.node == root}
    everyone = [m.lab_label for m in scene.markers]
    mine = [m.lab_label for m in scene.markers if m.on in on_root]
    seen = [lb for lb in (mine or everyone) if lb in lab.labels]
    if mine and not seen:
        raise ValueError(f"{lab.source}: none of the root segment {root}'s markers ({', '.join(mine)}) is in the "
                         f"trial: the subject's travel and heading (and its fit) need them; label them as the model "
                         f"does (the trial has {', '.join(lab.labels[:8])}{', ...' if len(lab.labels) > 8 else ''})")
    return seen


def median_steps(lab: LabMarkers, labels: list[str]) -> np.ndarray:
    """(n - 1, 3) m: each frame-to-frame step of the markers' median displacement (over the markers seen in both
    frames; NaN where fewer than half of them are: a record's ends, where markers enter the cameras' view one by
    one). Steps, not positions: a marker seen late joins without a jump."""
    X = np.stack([lab.marker(lb) for lb in labels], axis=1)  # (n, k, 3)
    d = X[1:] - X[:-1]
    enough = np.isfinite(d).all(axis=2).sum(axis=1) >= max(1, len(labels) // 2)
    out = np.full((lab.t.size - 1, 3), np.nan)
    if enough.any():
        out[enough] = np.nanmedian(d[enough], axis=1)
    return out


def check_straight(lab: LabMarkers, labels: list[str], plane: str) -> str:
    """A report line on the trial's heading against the plane's x; ValueError where the subject turns more than
    :data:`MAX_TURN` or walks backwards in the plane (module docstring)."""
    pl = Plane.parse(plane)
    if lab.t.size < 2 or not labels:
        return "heading not checked: too few frames or markers"
    steps = median_steps(lab, labels)
    x_axis, up = pl.matrix[0], np.cross(*pl.matrix)
    path = np.vstack([np.zeros(3), np.cumsum(np.nan_to_num(steps), axis=0)])
    extent = float(np.hypot(np.ptp(path @ x_axis), np.ptp(path @ up)))
    if extent < MIN_TRAVEL:  # a treadmill's sway or a static trial: velocities of either sign, no heading to judge
        return (f"heading not checked: the subject does not move from its place (within {extent:.2f} m over the "
                f"trial: a static trial or a treadmill)")
    w = max(1, int(round(0.1 * lab.rate)))  # 0.1 s of steps: a stride's sway, not the markers' noise
    if steps.shape[0] < w:
        return "heading not checked: a record shorter than 0.1 s"
    kernel = np.ones(w)
    v = np.column_stack([np.convolve(steps[:, k], kernel, "valid") for k in range(3)]) / (
        lab.t[w:] - lab.t[:-w])[:, None]  # NaN wherever a step in the window is
    forward, side = v @ x_axis, v @ up
    moving = np.hypot(forward, side) >= WALKING_SPEED
    if not moving.any():
        return f"heading not checked: the subject never moves at {WALKING_SPEED:g} m/s or faster"
    heading = np.arctan2(side[moving], forward[moving])
    mean = float(np.arctan2(np.sin(heading).mean(), np.cos(heading).mean()))  # the walk's direction, no wrap at 180
    dev = np.degrees(np.angle(np.exp(1j * (heading - mean))))  # each heading's signed angle from it
    lo, hi = np.degrees(mean) + float(dev.min()), np.degrees(mean) + float(dev.max())  # unwrapped about the mean
    where = f"the heading from {lo:+.0f} to {hi:+.0f} degrees off the plane's x ({pl.x}) while moving"
    turns = "a planar model needs straight walking; give a window in which it walks straight"
    off = max(-lo, hi) > MAX_TURN  # refused whatever follows: only the reason is chosen below
    if off and np.abs(dev).max() > MAX_TURN:
        raise ValueError(f"the subject turns ({where}: {np.abs(dev).max():.0f} degrees from its mean direction, "
                         f"more than {MAX_TURN:g}): {turns}")
    if abs(np.degrees(mean)) > 90.0:
        raise ValueError(f"the subject walks backwards in the plane {plane} ({where}): give the plane along its "
                         f"travel, or plane = \"auto\"")
    if off and np.ptp(dev) < MAX_TURN:  # its headings close together: a diagonal walkway
        raise ValueError(f"the subject walks straight at {np.degrees(mean):+.0f} degrees to the plane's x ({where}, "
                         f"within {np.ptp(dev):.0f} degrees of each other): give the plane along its travel, or "
                         f"plane = \"auto\"")
    if off:
        raise ValueError(f"the subject turns ({where}, more than {MAX_TURN:g}): {turns}")
    return f"straight: {where}"


def heading_line(scene, lab: LabMarkers, plane: str, root: str | None, t_start: float | None,
                 t_end: float | None) -> str:
    """:func:`check_straight`'s report line on the trial's window [t_start, t_end] s (None: its start, its end), read
    from the root segment's markers (:func:`travel_labels`); ValueError in one line where it refuses."""
    labels = travel_labels(scene, lab, root)
    inside = (lab.t >= (-np.inf if t_start is None else t_start)) & (lab.t <= (np.inf if t_end is None else t_end))
    return check_straight(dataclasses.replace(lab, t=lab.t[inside], xyz=lab.xyz[inside]), labels, plane)


#: a facing needs the markers to lie along it as the scene's do at least this well (biomechZoo's sample study's
#: statics on a Plug-in Gait model: 0.78-0.91 facing, 0.02-0.07 across)
MIN_CORRELATION = 0.3

#: the lab's axes, by their index in a marker's coordinates
LAB_AXES = "XYZ"


def horizontal_axes(vertical: str) -> list[int]:
    """The indices of the lab's two horizontal axes, ``vertical`` ("Y", "+Z", ...) the up one."""
    return [k for k in range(3) if LAB_AXES[k] != vertical.lstrip("+-").upper()]


def facing_plane(scene, lab: LabMarkers, vertical: str) -> tuple[str, str]:
    """(plane, report line): of the four horizontal directions, the one along which the trial's markers (their
    mean over its frames) lie as the scene's lie along its x (the largest slope of their lab coordinate on the
    scene's x: the subject's toes ahead of its heels, its pelvis's front ahead of its back, whatever its size;
    refused where their correlation is below :data:`MIN_CORRELATION`; module docstring)."""
    markers = [m for m in scene.markers if m.lab_label in lab.labels]
    x0 = np.array([m.x for m in markers])
    with warnings.catch_warnings():  # a marker never seen: its mean NaN, left out below
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.array([np.nanmean(lab.marker(m.lab_label), axis=0) for m in markers]).reshape(-1, 3)
    seen = np.isfinite(mean).all(axis=1)
    if seen.sum() < 3:
        raise ValueError(f"{lab.source}: fewer than 3 of the scene's markers seen: cannot tell which way the "
                         f"subject faces; give the plane")
    r, slope = {}, {}
    x = x0[seen] - x0[seen].mean()
    for k in horizontal_axes(vertical):
        lab_k = mean[seen, k] - mean[seen, k].mean()
        b = float(x @ lab_k / (x @ x))  # the lab axis's metres per metre of the scene's x: a subject's size
        with np.errstate(all="ignore"):  # a lab axis the markers do not spread along: no correlation (0)
            c = float(np.nan_to_num(np.corrcoef(x, lab_k)[0, 1]))
        for sign, axis in ((1.0, f"{LAB_AXES[k]},{vertical}"), (-1.0, f"-{LAB_AXES[k]},{vertical}")):
            r[axis], slope[axis] = sign * c, sign * b
    best = max(slope, key=slope.get)
    if r[best] < MIN_CORRELATION:
        raise ValueError(f"{lab.source}: cannot tell which way the subject faces (the markers' correlation with the "
                         f"scene's x at most {r[best]:+.2f} along {best}): give the plane")
    others = ", ".join(f"{p} {v:+.2f}" for p, v in r.items() if p != best)
    return best, f"plane {best}: the subject faces {best.split(',')[0]} (the markers' correlation with the " \
                 f"scene's x {r[best]:+.2f}, {slope[best]:.2f} m per m; {others} in the others)"
