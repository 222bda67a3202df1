"""What no human body in a motion lab produces: the limits that tell corrupted lab data from a measurement.

A lab file can be wrong in ways that look like data: a header whose units lie, a marker that jumps a
metre for one frame, a sample of 1e300, a plate force of ten tonnes. Passed on, each becomes a confident
joint moment of 1e8 N m. The checks here refuse such data in one line that names the file, the marker or
the plate, and the frame, before any fit; each limit is far beyond what a body does, so that a real
measurement never meets it:

- :data:`LAB_EXTENT` (m): no capture volume reaches 100 m from its origin (a large gait lab spans 10-20 m).
- :data:`MAX_MARKER_SPEED` (m/s): a marker moving faster than 50 m/s between two frames. The fastest body
  parts reach about 40 m/s (a pitcher's fingertips at release); a kicking foot 20-25 m/s, a sprinter's
  foot 20 m/s. A mislabelled or corrupted sample makes a jump of the distance between two markers or more
  in one frame: 1 m at 60 Hz is 60 m/s.
- :data:`MAX_PLATE_FORCE` (N): 20 kN is 25 body weights of an 80 kg subject; the hardest landings measured
  reach 10-15. :data:`MAX_FREE_MOMENT` (N m): a foot's free moment about the vertical is 5-10 N m in gait,
  some 50 N m in a pivoting sport: 1 kN m is none. A plate's moment about the lab's origin is bounded by
  both over the capture volume.
- :data:`MAX_MISFIT` (m): a marker 0.1 m from where the fitted model puts it is no soft-tissue artefact
  (1-3 cm): a marker that fell off or was mislabelled, a wrong plane or units, or a scene not scaled to the
  subject (:mod:`casflex.inverse.fit` refuses it, naming the frame and the marker; ``max_misfit`` changes it).
- :data:`STATIC_SPREAD` (m): a static trial's marker farther than 5 cm from its mean position: a subject
  standing still sways by 1-2 cm (:mod:`casflex.inverse.calibrate`).
- :func:`check_scale`: the trial's markers as far apart as the scene's to within a factor
  :data:`SCALE_FACTOR` (3): subjects differ by 20-30 %, units by 10 or 1000.
- :func:`check_coordinates`: joint angles and the root's position given as a table (an IK result). A hinge
  beyond :data:`MAX_ANGLE` (a full turn) or a coordinate :data:`RANGE_MARGIN` past its model's range: degrees
  read as radians; every angle within :data:`TINY_ANGLES` degrees over the trial: radians labelled degrees
  (a joint in motion turns tens of degrees; any human pose in radians lies within +-pi); a position beyond
  :data:`LAB_EXTENT` or moving faster than :data:`MAX_MARKER_SPEED`: millimetres or centimetres read as metres.
- :func:`check_moments`: :data:`MAX_MOMENT_PER_KG` (20 N m/kg) of the body's mass; the largest joint moments
  measured in people are 3-5 N m/kg (the hip and knee in sprinting and in landings): 20 is no body, but a
  unit error in the coordinates or the markers.
- :func:`joint_force_lines`: :data:`MAX_JOINT_FORCE_BW` (30) body weights of a joint's intersegmental force is
  said, not refused: the net force a joint passes on is the ground's push plus the segments' inertia (Hamner's
  run: the ankle's 2.5 body weights; walking2's 1.2; landings 5-15); 30 is the plates' forces in another unit, a
  plate on the wrong body, or markers or coordinates in other units.
- :func:`plate_share_lines`: where the plates are loaded, their vertical force over what the model's motion needs
  of the ground (the plates' plus the root's residual): about 1 for a model of the whole body (Hamner's run 0.99),
  for part of one the subject's weight over the part's (a leg with its pelvis: 2.6 on Hamner's run, 2.8 on
  walking2). Outside :data:`PLATE_SHARE` (0.6-8) it is said: plates in daN (10) or kgf (9.81), lbf read as N
  (0.225), masses in lb read as kg (0.45).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from casflex.lab.tables import LabMarkers, LabTable

__all__ = ["LAB_EXTENT", "MAX_MARKER_SPEED", "MAX_PLATE_FORCE", "MAX_FREE_MOMENT", "MAX_MISFIT", "STATIC_SPREAD",
           "SCALE_FACTOR", "MAX_ANGLE", "RANGE_MARGIN", "TINY_ANGLES", "MAX_MOMENT_PER_KG", "MAX_JOINT_FORCE_BW",
           "PLATE_SHARE",
           "check_markers", "check_plate_values", "check_static", "check_scale", "check_coordinates", "check_moments",
           "joint_force_lines", "plate_share_lines", "median"]

LAB_EXTENT = 100.0
MAX_MARKER_SPEED = 50.0
MAX_PLATE_FORCE = 2.0e4
MAX_FREE_MOMENT = 1.0e3
MAX_MISFIT = 0.1
STATIC_SPREAD = 0.05
SCALE_FACTOR = 3.0
MAX_ANGLE = 2.0 * math.pi
RANGE_MARGIN = math.radians(30.0)
TINY_ANGLES = math.pi
MAX_MOMENT_PER_KG = 20.0
MAX_JOINT_FORCE_BW = 30.0
PLATE_SHARE = (0.6, 8.0)


def check_markers(lab: LabMarkers, labels: Sequence[str], frames: np.ndarray | None = None) -> None:
    """ValueError in one line naming the file, the marker and the frame where a marker among ``labels`` lies
    beyond :data:`LAB_EXTENT` (or is infinite) or moves faster than :data:`MAX_MARKER_SPEED` between two
    frames it is seen in; ``frames`` (bool (n,)): the frames to check (default all)."""
    sel = np.ones(lab.t.size, bool) if frames is None else np.asarray(frames, bool)
    t = lab.t[sel]
    for label in labels:
        xyz = lab.marker(label)[sel]
        with np.errstate(invalid="ignore"):
            far = np.abs(xyz).max(axis=1) > LAB_EXTENT
        far |= np.isinf(xyz).any(axis=1)
        if far.any():
            i = int(np.argmax(far))
            raise ValueError(f"{lab.source}: marker {label!r} at t = {t[i]:g} s lies at {_point(xyz[i])} m, beyond "
                             f"any capture volume ({LAB_EXTENT:g} m): a corrupted sample, or units that are not the "
                             f"header's {lab.units!r}")
        seen = np.flatnonzero(np.isfinite(xyz).all(axis=1))
        if seen.size < 2:
            continue
        step = np.linalg.norm(np.diff(xyz[seen], axis=0), axis=1)
        speed = step / np.diff(t[seen])
        if (speed > MAX_MARKER_SPEED).any():
            k = int(np.argmax(speed > MAX_MARKER_SPEED))
            a, b = seen[k], seen[k + 1]
            raise ValueError(f"{lab.source}: marker {label!r} jumps {step[k]:.3g} m from t = {t[a]:g} to {t[b]:g} s "
                             f"({speed[k]:.3g} m/s; no body moves a marker faster than {MAX_MARKER_SPEED:g} m/s): a "
                             "corrupted or mislabelled sample; delete it (an empty cell is a gap, filled) or fix "
                             "the labels")


def _point(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.3g}" for v in p) + ")"


def check_plate_values(table: LabTable, prefix: str, force: np.ndarray, cop: np.ndarray | None,
                       moment: np.ndarray) -> None:
    """ValueError in one line naming the file, the plate and the time of a force that is infinite or above
    :data:`MAX_PLATE_FORCE`, a centre of pressure ``cop`` (None: the table gives moments about the origin) that
    is infinite or beyond :data:`LAB_EXTENT`, or a ``moment`` (the free moment where ``cop`` is given, else the
    moment about the origin) beyond what such forces and :data:`MAX_FREE_MOMENT` make. Where the force is zero
    the centre of pressure is not checked (it moves nothing; an unloaded plate's is often left at any value:
    metres off in the Rajagopal pipeline's walking trial). Values that are not numbers (NaN) are missing
    samples: the caller's."""
    where = f"{table.source}: plate {prefix!r}"
    with np.errstate(invalid="ignore", over="ignore"):
        size = np.linalg.norm(force, axis=1)
        bad = np.isinf(force).any(axis=1) | (size > MAX_PLATE_FORCE)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"{where} at t = {table.t[i]:g} s: a force of {np.abs(force[i]).max():.3g} N, beyond what a "
                         f"body exerts on a plate ({MAX_PLATE_FORCE:g} N): a corrupted sample or a calibration in "
                         "other units")
    if cop is not None:  # where the force is zero the point carries nothing: exports leave any value there
        with np.errstate(invalid="ignore"):
            bad = (np.isinf(cop).any(axis=1) | (np.abs(cop).max(axis=1) > LAB_EXTENT)) & (size != 0)
        if bad.any():
            i = int(np.argmax(bad))
            raise ValueError(f"{where} at t = {table.t[i]:g} s: its centre of pressure lies at {_point(cop[i])} m, "
                             f"beyond any lab ({LAB_EXTENT:g} m): a corrupted sample or another unit")
    limit = MAX_FREE_MOMENT + (0.0 if cop is not None else LAB_EXTENT * MAX_PLATE_FORCE)
    with np.errstate(invalid="ignore"):
        bad = np.isinf(moment).any(axis=1) | (np.abs(moment).max(axis=1) > limit)
    if bad.any():
        i = int(np.argmax(bad))
        what = "free moment" if cop is not None else "moment about the lab's origin"
        raise ValueError(f"{where} at t = {table.t[i]:g} s: a {what} of {np.abs(moment[i]).max():.3g} N m, beyond "
                         f"what a body exerts on a plate ({limit:g} N m): a corrupted sample")


def check_static(lab: LabMarkers, labels: Sequence[str]) -> None:
    """ValueError in one line when a marker among ``labels`` of a static trial moves farther than
    :data:`STATIC_SPREAD` from its mean position: a trial of motion given as the static one."""
    worst, which = 0.0, None
    for label in labels:
        xyz = lab.marker(label)
        seen = np.isfinite(xyz).all(axis=1)
        if seen.sum() < 2:
            continue
        d = np.linalg.norm(xyz[seen] - xyz[seen].mean(axis=0), axis=1)
        if d.max() > worst:
            worst, which = float(d.max()), (label, float(lab.t[seen][np.argmax(d)]))
    if worst > STATIC_SPREAD:
        raise ValueError(f"{lab.source}: not a static trial: marker {which[0]!r} lies {1e3 * worst:.0f} mm from its "
                         f"mean position at t = {which[1]:g} s (a subject standing still sways by 1-2 cm; the "
                         f"limit is {1e3 * STATIC_SPREAD:.0f} mm)")


def median(values, *, skip_nan: bool = False) -> float:
    """``np.median`` of the values (flattened; ``skip_nan``: ``np.nanmedian``), the same number to the last bit
    (the middle one, or the two middle ones' sum over 2), NaN for none, without numpy's median's check for NaN, which
    imports numpy.ma: 0.02 s of an inverse command's start."""
    a = np.asarray(values, dtype=float).ravel()
    if skip_nan:
        a = a[~np.isnan(a)]
    elif np.isnan(a).any():
        return math.nan
    if not a.size:
        return math.nan
    s, k = np.sort(a), a.size // 2
    return float(s[k]) if a.size % 2 else float((s[k - 1] + s[k]) / 2)


def _median_ratio(seg: np.ndarray, scene_xy: np.ndarray, trial_xy: np.ndarray) -> float:
    """The median, over pairs of markers on one segment and the frames, of trial over scene distance (1: none)."""
    ratios = []
    for s in dict.fromkeys(seg.tolist()):  # a segment's pairs at once (a Python loop over pairs took 0.1 s)
        on = np.flatnonzero(seg == s)
        a, b = (on[k] for k in np.triu_indices(on.size, 1))
        d0 = np.sqrt(((scene_xy[a] - scene_xy[b]) ** 2).sum(axis=1))
        apart = ~(d0 < 1e-3)  # markers 1 mm apart at least
        a, b, d0 = a[apart], b[apart], d0[apart]
        d = np.sqrt(((trial_xy[:, a] - trial_xy[:, b]) ** 2).sum(axis=2))  # (n, pairs)
        ratios.append((d / d0)[np.isfinite(d)])
    every = np.concatenate(ratios) if ratios else np.zeros(0)
    return median(every) if every.size else 1.0


def check_scale(source: str, units: str, scene_xy: np.ndarray, trial_xy: np.ndarray, segment: Sequence[int]) -> None:
    """ValueError in one line when the trial's markers lie :data:`SCALE_FACTOR` times farther apart than the
    scene's, or closer, over the pairs of markers on one segment (median over pairs and frames): units that are
    not the header's, or a scene of another body. ``scene_xy`` (m, 2) the scene's markers in the plane,
    ``trial_xy`` (n, m, 2) the trial's (NaN where missing), ``segment`` (m,) each marker's segment."""
    seg = np.asarray(segment)
    with np.errstate(over="ignore", invalid="ignore"):  # absurd samples are check_markers' to name
        ratio = _median_ratio(seg, scene_xy, trial_xy)
    if not 1.0 / SCALE_FACTOR < ratio < SCALE_FACTOR:
        from casflex.lab.tables import UNITS

        hint = ""
        if units in UNITS and ratio > 0:  # the unit the numbers are in: the header's unit over the ratio
            true = min(UNITS, key=lambda u: abs(np.log10(UNITS[units] / ratio / UNITS[u])))
            if abs(np.log10(UNITS[units] / ratio / UNITS[true])) < 0.3:
                hint = f" (the numbers look like {true})"
        raise ValueError(f"{source}: the trial's markers lie {ratio:.3g} times as far apart as the scene's on the same "
                         f"segments: the header's units {units!r} are wrong{hint}, or the scene is not this subject's")


def _worst(t: np.ndarray, v: np.ndarray, bad: np.ndarray) -> tuple[float, float]:
    """(time s, value) of the largest magnitude among the samples ``bad``."""
    i = int(np.argmax(np.where(bad, np.abs(v), -np.inf)))
    return float(t[i]), float(v[i])


def _check_angle(source: str, t: np.ndarray, name: str, v: np.ndarray, hinge: bool,
                 limits: tuple[float, float] | None, unit: str) -> None:
    """One angle column v (rad): a hinge within :data:`MAX_ANGLE`, any angle within its ``limits`` (rad) and
    :data:`RANGE_MARGIN`; ``unit``: what the header says the table's angles are."""
    said = f"the header says inDegrees={'yes' if unit == 'degrees' else 'no'}"
    if hinge and (np.abs(v) > MAX_ANGLE).any():
        at, x = _worst(t, v, np.abs(v) > MAX_ANGLE)
        raise ValueError(f"{source}: column {name!r} reaches {x:.4g} rad ({math.degrees(x):.4g} degrees) at t = "
                         f"{at:g} s: no joint turns beyond a full turn; {said}: are the angles in the other unit?")
    if limits is not None:
        lo, hi = limits[0] - RANGE_MARGIN, limits[1] + RANGE_MARGIN
        out = (v < lo) | (v > hi)
        if out.any():
            at, x = _worst(t, v, out)
            raise ValueError(f"{source}: column {name!r} reaches {math.degrees(x):.4g} degrees at t = {at:g} s, more "
                             f"than {math.degrees(RANGE_MARGIN):g} degrees beyond the model's range "
                             f"{math.degrees(limits[0]):.4g}..{math.degrees(limits[1]):.4g} degrees; {said}: angles "
                             "in the other unit, or another model's coordinates")


def _check_length(source: str, t: np.ndarray, name: str, v: np.ndarray) -> None:
    """One position column v (m): within :data:`LAB_EXTENT`, no faster than :data:`MAX_MARKER_SPEED`."""
    far = np.abs(v) > LAB_EXTENT
    if far.any():
        at, x = _worst(t, v, far)
        raise ValueError(f"{source}: column {name!r} is {x:.4g} m at t = {at:g} s, beyond any lab ({LAB_EXTENT:g} m): "
                         "positions are in m; millimetres read as metres?")
    if v.size > 1:
        speed = np.abs(np.diff(v)) / np.diff(t)
        if (speed > MAX_MARKER_SPEED).any():
            k = int(np.argmax(speed))
            raise ValueError(f"{source}: column {name!r} moves {speed[k]:.4g} m/s from t = {t[k]:g} to {t[k + 1]:g} s "
                             f"(no body moves faster than {MAX_MARKER_SPEED:g} m/s): positions are in m; millimetres "
                             "or centimetres read as metres?")


def check_coordinates(source: str, t: np.ndarray, columns: Sequence[tuple], in_degrees: bool | None) -> None:
    """ValueError in one line naming the file, the column and the time of coordinates no body takes (module
    docstring). ``columns``: (name, values (n,) in m or rad, kind, limits (lower, upper) in m or rad or None),
    kind one of "length", "root angle", "hinge"; ``in_degrees``: what the table's header said."""
    unit = "degrees" if in_degrees else "radians"
    for name, v, kind, limits in columns:
        if kind == "length":
            _check_length(source, t, name, v)
        else:
            _check_angle(source, t, name, v, kind == "hinge", limits, unit)
    angles = [(name, np.degrees(np.abs(v)).max()) for name, v, kind, _ in columns if kind != "length" and v.size]
    if in_degrees and any(kind == "hinge" for _, _, kind, _ in columns) and angles:
        name, top = max(angles, key=lambda a: a[1])
        if top < TINY_ANGLES:
            raise ValueError(f"{source}: header inDegrees=yes, yet every angle stays within {top:.3g} degrees over the "
                             f"trial ({name} the largest): radians labelled degrees look so (a joint in motion turns "
                             "tens of degrees); give the header inDegrees=no if they are radians")


def check_moments(source: str, t: np.ndarray, moments: dict[str, np.ndarray], mass: float) -> None:
    """ValueError in one line naming the moment, the time and its size per kg when a joint moment (N m) of
    ``moments`` exceeds :data:`MAX_MOMENT_PER_KG` times ``mass`` (kg: the body's, e.g. the model's or the weight
    the plates carry, whichever is larger); ``source``: the trial."""
    limit = MAX_MOMENT_PER_KG * mass
    for name, m in moments.items():
        with np.errstate(invalid="ignore"):
            bad = ~(np.abs(m) <= limit)
        if np.isnan(m).any():
            raise ValueError(f"{source}: {name} is not a number at t = {t[int(np.argmax(np.isnan(m)))]:g} s")
        if bad.any():
            at, x = _worst(t, m, bad)
            raise ValueError(f"{source}: {name} reaches {x:.4g} N m at t = {at:g} s, {abs(x) / mass:.3g} N m per kg of "
                             f"a body of {mass:.3g} kg; no human joint carries {MAX_MOMENT_PER_KG:g} N m/kg (3-5 in "
                             "sprinting and landing): the coordinates' or the markers' units are wrong, or the scene "
                             "is not this trial's")


def joint_force_lines(source: str, t: np.ndarray, forces: dict[str, np.ndarray], mass: float) -> list[str]:
    """The lines that say a joint's intersegmental force (``forces``: joint -> its magnitude (k,) N at times t (k,)
    s) exceeds :data:`MAX_JOINT_FORCE_BW` times the weight of ``mass`` (kg x 9.81; the body's, as
    :func:`check_moments` takes it), naming the joint, the peak and its time; ``source``: the trial."""
    weight = 9.81 * mass
    lines = []
    for name, f in forces.items():
        with np.errstate(invalid="ignore"):
            k = int(np.nanargmax(f)) if np.isfinite(f).any() else -1
        if k >= 0 and f[k] > MAX_JOINT_FORCE_BW * weight:
            lines.append(f"{source}: the force at {name} reaches {f[k]:.4g} N at t = {t[k]:g} s, {f[k] / weight:.3g} "
                         f"body weights of a body of {mass:.3g} kg; no human joint passes on {MAX_JOINT_FORCE_BW:g} "
                         "(the ground's push and the segments' inertia: 1-3 walking and running, 5-15 landing): the "
                         "plates' forces in another unit or on the wrong body, or the markers' or coordinates' "
                         "units wrong")
    return lines


def plate_share_lines(source: str, t: np.ndarray, plates: np.ndarray, needed: np.ndarray) -> list[str]:
    """The line that says the plates push far more or far less than the model's motion needs of the ground.

    ``plates`` (k,) N: the plates' summed force along the model's up at times t (k,) s; ``needed`` (k,) N: the
    upward external force the model's motion needs (the plates' plus the root's residual along up). Their ratio,
    the median over the frames where the plates carry more than a quarter of their peak (and 20 N: the contacts'
    edges divide small numbers), is the plates' share of the motion's needs: a whole body's 1, part of one more
    (it stands on the plates with the rest of the subject). Outside :data:`PLATE_SHARE` the plates' units or the
    model's masses are off (module docstring); said, not refused: a model of a shank and foot, or a seat or a
    rail the plates do not measure, give such shares in earnest. ``source``: the trial."""
    peak = float(np.nanmax(plates, initial=0.0))
    loaded = np.isfinite(plates) & np.isfinite(needed) & (plates > max(20.0, 0.25 * peak))
    if loaded.sum() < 3:
        return []
    with np.errstate(divide="ignore", invalid="ignore"):
        share = float(np.median(plates[loaded] / needed[loaded]))
    lo, hi = PLATE_SHARE
    if lo <= share <= hi:
        return []
    what = (f"the plates' forces in another unit (daN: 10, kgf: 9.81) or the model's masses too small (for part "
            f"of a body: the subject weighs {share:.3g} times it)" if share > hi else
            "the plates' forces in another unit (lbf read as N: 0.225), the model's masses too large (lb read as "
            "kg: 0.45), the feet off the plates, or a support the plates do not measure (a seat, a rail)")
    return [f"{source}: where the plates are loaded ({loaded.sum()} frames, t = {t[loaded][0]:g}..{t[loaded][-1]:g} "
            f"s) they push {share:.3g} times what the model's motion needs of the ground (the median; a whole "
            f"body's plates about 1, a leg's with its pelvis 4-6): {what}; the loads are the motion's under those "
            "forces"]
