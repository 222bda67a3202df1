"""A static trial calibrates a scene to its subject: segment lengths, then the markers on their segments.

The lab's scaling step (OpenSim's scale tool does the same in 3-D), for the scenes inverse dynamics
takes (:mod:`casflex.inverse.tree`), from a static trial's markers averaged over its frames and
projected on the plane:

1. **Segment scale** (``scale=True``; off by default): each segment (a cluster of the tree) is scaled
   by the median, over the pairs of its markers seen in the trial, of measured distance over the
   scene's distance. That measures a segment's length only where its markers spread along it (joint
   markers at both ends); a cluster of skin markers on the thigh measures the cluster, and the
   projection on the plane shortens what lies out of it (Hamner's static trial: 3-5 %, and the static
   misfit rises from 2.7 to 13 mm). The report compares the fits with and without the scaling;
   about its proximal joint's centre (the root's segment about the root node). Everything fixed in
   it scales (its nodes, bodies' centres of mass, markers, the points of the hinges to its children,
   which carry the distal segments along); a body's inertia scales with the square of the length.
   A segment without two seen markers :data:`MIN_PAIR` apart keeps its size (reported). ``mass`` (kg): the bodies'
   masses scaled together to that total (their inertias with them).
2. **Marker placement**: the static pose is fitted (the tree's coordinates, least squares over the
   markers, :mod:`casflex.inverse.fit`), and every seen marker is moved onto its measured position,
   expressed on its segment and carried back to the scene's configuration. The misfit before and
   after is reported; a marker the trial lacks (lost, or never recorded) stays where it is (reported). A segment
   the trial has none of the markers of is locked for the fit (:mod:`casflex.inverse.locking`), and for it only:
   the scene returned keeps its joints and markers.

The result is a new scene (write it with :func:`casflex.save_scene`) and the report's lines.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from casflex.inverse.tree import KinematicTree, kinematic_tree

__all__ = ["calibrate", "with_mass", "mass_lines", "scene_mass", "MASS_WARN"]


def _rot(th: float) -> np.ndarray:
    c, s = np.cos(th), np.sin(th)
    return np.array([[c, -s], [s, c]])


#: a segment scaled by less than the first or more than the second is said (a warning in the report): subjects differ
#: by 20-30 % from a model; beyond, a marker mislabelled or on the wrong segment is likelier than such a subject
SCALE_WARN = (0.5, 1.5)
#: m: a marker the static trial moves farther than this on its segment is said: skin markers sit within some 1-3 cm
#: of where a model of the subject has them; 5 cm is a marker on the wrong segment, swapped, or the wrong model
MOVE_WARN = 0.05


#: m: a scaled scene that fits the static pose worse than the scene unscaled by more than this is warned of (a tenth of
#: a millimetre: no scaling measured by markers is better than that, and round-off at a perfect fit is far below it)
WORSE_BY = 1e-4

#: m: a pair of markers closer than this in the scene's plane measures their placement, not the segment's size (a
#: few mm of placement is 10 % of it; two markers across a limb, a wrist's two, project within it)
MIN_PAIR = 0.05


def _scales(tree: KinematicTree, y0: np.ndarray, ym: np.ndarray, labels: list[str], source: str) -> dict[int, float]:
    """Per cluster: the median measured over scene distance of its seen markers' pairs at least :data:`MIN_PAIR`
    apart in the scene (1 without such a pair). ValueError naming the segment and its markers when that median
    lies beyond :data:`casflex.lab.checks.SCALE_FACTOR` either way: markers that coincide in the trial (a
    segment scaled to nothing) or lie metres apart are mislabelled or duplicated, no subject's segment."""
    from casflex.lab.checks import SCALE_FACTOR

    cl = np.array([tree.cluster[i] for i in tree.marker_nodes])
    seen = np.isfinite(ym).all(axis=1)
    out = {}
    for c in set(tree.cluster):
        k = np.flatnonzero((cl == c) & seen)
        pairs = [(i, j) for a, i in enumerate(k) for j in k[a + 1:] if np.linalg.norm(y0[i] - y0[j]) >= MIN_PAIR]
        ratios = [np.linalg.norm(ym[i] - ym[j]) / np.linalg.norm(y0[i] - y0[j]) for i, j in pairs]
        out[c] = float(np.median(ratios)) if ratios else 1.0
        if not 1.0 / SCALE_FACTOR < out[c] < SCALE_FACTOR:
            node = tree.model.node_names[tree.entry[c]]
            far = ", ".join(f"{labels[i]}-{labels[j]} {1e3 * np.linalg.norm(ym[i] - ym[j]):.0f} mm (scene "
                            f"{1e3 * np.linalg.norm(y0[i] - y0[j]):.0f})" for i, j in pairs[:4])
            raise ValueError(f"{source}: segment {node!r} would be scaled by {out[c]:.3g}: its markers lie {far} apart "
                             f"in the static trial (the median of {len(pairs)} pairs beyond a factor {SCALE_FACTOR:g} "
                             "of the scene's): markers that coincide or are mislabelled, or a segment held across "
                             "the plane (an arm out to the side: its markers' projections coincide); fix the labels, "
                             "or calibrate without scaling")
    return out


def _scaled_scene(tree: KinematicTree, s: dict[int, float]):
    """The scene with every segment scaled about its proximal joint (module docstring, step 1)."""
    sc, idx = tree.model.scene, tree.model.node_names.index
    pos = {n.name: np.array([n.x, n.y]) for n in sc.nodes}
    centre = {tree.cluster[idx(tree.root)]: pos[tree.root]}
    for h in tree.hinges:  # parents first (kinematic_tree's order is a tree walk from the root)
        j = sc.item(h)
        centre[tree.cluster[idx(j.nodes[1])]] = np.array(sc.joint_point(j))
    moved: dict[int, np.ndarray] = {tree.cluster[idx(tree.root)]: np.zeros(2)}  # the centre's displacement

    def new(p, c: int) -> np.ndarray:
        return centre[c] + moved[c] + s[c] * (np.asarray(p, dtype=float) - centre[c])

    for h in _parents_first(tree):
        j = sc.item(h)
        a, b = (tree.cluster[idx(n)] for n in j.nodes)
        moved[b] = new(sc.joint_point(j), a) - centre[b]
    of = lambda node: tree.cluster[idx(node)]  # noqa: E731
    nodes = tuple(dataclasses.replace(n, x=float(new(pos[n.name], of(n.name))[0]),
                                      y=float(new(pos[n.name], of(n.name))[1])) for n in sc.nodes)
    bodies = []
    for b in sc.bodies:
        c, p = of(b.node), pos[b.node]
        com = new((p[0] if b.com_x is None else b.com_x, p[1] if b.com_y is None else b.com_y), c)
        bodies.append(dataclasses.replace(b, inertia=b.inertia * s[c] ** 2,
                                          com_x=float(com[0]), com_y=float(com[1])))
    joints = tuple(_scaled_joint(j, sc, new, s[of(j.nodes[0])], of(j.nodes[0])) for j in sc.joints)
    markers = tuple(dataclasses.replace(m, **dict(zip(("x", "y"), (float(v) for v in new(
        (m.x, m.y), tree.cluster[i])), strict=True))) for m, i in zip(sc.markers, tree.marker_nodes, strict=True))
    return dataclasses.replace(sc, nodes=nodes, bodies=tuple(bodies), joints=joints, markers=markers)


def _scaled_joint(j, sc, new, s: float, c: int):
    """The joint ``j`` with its point carried by its parent segment (cluster ``c``, scaled by ``s`` through ``new``)
    and a coupled hinge's shifts (m, in the parent's frame) times ``s``: OpenSim's ScaleTool multiplies a custom
    joint's translation functions by its parent body's factor (a femur scaled 1.2 left the knee's rolling as it was:
    the shank's markers 5.2 mm from OpenSim 4.6's over the knee's range)."""
    if j.point is not None:
        j = dataclasses.replace(j, point=tuple(float(v) for v in new(sc.joint_point(j), c)))
    if j.coupled:
        j = dataclasses.replace(j, **{f: tuple((a, s * v) for a, v in getattr(j, f)) for f in ("shift_x", "shift_y")
                                      if getattr(j, f) is not None})
    return j


#: a subject's mass more than this factor from the model's total is said: adults weigh 45-150 kg, a generic model
#: 65-80 kg; a factor 2 is a mass in pounds (2.2), ten times off, or a model of part of the body (Hamner's leg, 23 kg)
#: given the whole body's mass, whose segments would then weigh two or three times a subject's
MASS_WARN = 2.0


def scene_mass(scene) -> float:
    """kg: the scene's mass, its rigid bodies' and its beams' (rho A L)."""
    nodes = {n.name: (n.x, n.y) for n in scene.nodes}
    return sum(b.mass for b in scene.bodies) + sum(b.rho * b.A * float(np.hypot(*np.subtract(
        nodes[b.nodes[1]], nodes[b.nodes[0]]))) for b in scene.beams)


def mass_lines(scene, mass: float) -> list[str]:
    """The report's warning (a list of none or one line) where the subject's ``mass`` (kg) is more than
    :data:`MASS_WARN` times the scene's total (:func:`scene_mass`), or less than its inverse."""
    total = scene_mass(scene)
    r = mass / total
    if 1.0 / MASS_WARN <= r <= MASS_WARN:
        return []
    why = (f"a mass in pounds ({mass * 0.45359237:.1f} kg), 10 times off, or a model of part of the body given the "
           "whole body's mass?" if r > 1.0 else "a mass 10 times off, or a subject unlike the model (a child's mass "
           "on an adult's model)?")
    return [f"warning: the subject's mass {mass:g} kg is {r:.3g} times the model's {total:.1f} kg (its bodies' "
            f"masses scaled by it): {why}"]


def with_mass(scene, mass: float):
    """The scene with its masses scaled together to ``mass`` (kg): its bodies' masses and inertias and its beams'
    densities (the segments' sizes as they are; the beams' mass counted: a flexible leg's bones weighed 0.67 kg over
    the subject's mass): a subject weighed but not measured."""
    if not mass > 0:
        raise ValueError(f"mass: must be > 0 kg, got {mass}")
    f = mass / scene_mass(scene)
    return dataclasses.replace(scene, bodies=tuple(dataclasses.replace(b, mass=b.mass * f, inertia=b.inertia * f)
                                                   for b in scene.bodies),
                               beams=tuple(dataclasses.replace(b, rho=b.rho * f) for b in scene.beams))


def _parents_first(tree: KinematicTree) -> list[str]:
    sc, idx = tree.model.scene, tree.model.node_names.index
    done, order, todo = {tree.cluster[idx(tree.root)]}, [], list(tree.hinges)
    while todo:
        h = next(h for h in todo if tree.cluster[idx(sc.item(h).nodes[0])] in done)
        done.add(tree.cluster[idx(sc.item(h).nodes[1])])
        order.append(h)
        todo.remove(h)
    return order


def _undecided_at(tree: KinematicTree, z: np.ndarray, ym: np.ndarray) -> str:
    """The coordinates the seen and weighted markers ``ym`` (m, 2) leave free at the pose ``z``, and the segments
    they move, as a phrase (the null space of the markers' Jacobian there)."""
    from casflex.inverse.fit import _segment_of

    used = np.isfinite(ym).all(axis=1) & np.array([m.weight > 0 for m in tree.model.scene.markers], bool)
    J = np.array(tree.marker_fit(z)[1])[np.repeat(used, 2)]
    s, vt = (np.zeros(0), np.eye(tree.n)) if not J.size else np.linalg.svd(J)[1:]
    null = vt[np.r_[s, np.zeros(tree.n - s.size)] <= 1e-8 * max(s[0] if s.size else 0.0, 1e-300)]
    free = [k for k in range(tree.n) if (np.abs(null[:, k]) > 1e-6).any()]
    lab = {c.scene_coordinate(): c.name for c in tree.model.scene.coordinates}
    segments = dict.fromkeys(tree.model.node_names[tree.entry[_segment_of(tree, k)]] for k in free)
    if not free:  # within the fit's tolerance only: no coordinate stands out
        return "the markers' Jacobian is singular at the static pose"
    return (f"{[lab.get(tree.names[k], tree.names[k]) for k in free]} free, of the segment"
            f"{'s' * (len(segments) > 1)} {', '.join(repr(n) for n in segments)}")


def _scaled(tree, sc, ym: np.ndarray, labels: list[str], source: str, mass: float | None):
    """(the scene scaled segment by segment to the static markers' mean ``ym`` (n_m, 2) m, its report lines)."""
    model = tree.model
    y0 = np.array([[m.x, m.y] for m in sc.markers])
    s = _scales(tree, y0, ym, labels, source)
    sc = _scaled_scene(tree, s)
    lines_mass = [] if mass is None else mass_lines(sc, mass)
    sc = sc if mass is None else with_mass(sc, mass)
    names = {c: next(n for i, n in enumerate(model.node_names) if tree.cluster[i] == c) for c in s}
    lines = ["segments scaled (by the node that carries each): "
             + ", ".join(f"{names[c]} {v:.3f}" for c, v in s.items())]
    lines += [f"warning: segment {names[c]!r} scaled by {v:.3f}, beyond {SCALE_WARN[0]:g}-{SCALE_WARN[1]:g} (its "
              "static markers' distances over the scene's): a marker mislabelled or on another segment?"
              for c, v in s.items() if not SCALE_WARN[0] <= v <= SCALE_WARN[1]]
    return sc, lines + lines_mass


def _placed(sc, model, tree, z: np.ndarray, ym: np.ndarray, report: list[str]):
    """(the scene's markers moved on their segments to where the static pose ``z`` puts the trial's mean ``ym``,
    each marker's move (m), the far moves' descriptions); a marker the trial never saw stays (said in ``report``)."""
    q = np.array(tree.forward(z)).ravel()
    markers, moved, far = [], [], []
    for k, (m, i) in enumerate(zip(sc.markers, tree.marker_nodes, strict=True)):
        if not np.isfinite(ym[k]).all() or m.fixed:
            markers.append(m)
            report.append(f"marker {m.name!r} ({m.lab_label}): " + ("fixed in the model, left where it was (as "
                          "OpenSim's marker placer leaves it)" if m.fixed else "not in the static trial, left where "
                          "it was"))
            continue
        x_fit, th_fit = q[3 * i:3 * i + 2], q[3 * i + 2]
        x0, th0 = model.q0[3 * i:3 * i + 2], model.q0[3 * i + 2]
        p = x0 + _rot(th0 - th_fit) @ (ym[k] - x_fit)
        moved.append(float(np.hypot(p[0] - m.x, p[1] - m.y)))
        far += [f"{m.name!r} ({m.lab_label}) {1e3 * moved[-1]:.0f} mm"] * (moved[-1] > MOVE_WARN)
        markers.append(dataclasses.replace(m, x=float(p[0]), y=float(p[1])))
    return markers, moved, far


def _static_mean(lab, sc, pl) -> np.ndarray:
    """The static trial's mean (n_m, 2) m in the plane ``pl`` of the scene ``sc``'s markers (NaN: never seen; every
    label in ``lab``)."""
    from casflex.lab import markers_in_plane

    ms = markers_in_plane(lab, {m.name: m.lab_label for m in sc.markers}, pl)
    with warnings.catch_warnings():  # a marker never seen: its mean NaN, said below
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(ms.q, axis=0).reshape(-1, 2)


def _warnings(before: float, held: list[str], far: list[str], unscaled: float | None = None, near: str = ""
              ) -> list[str]:
    """The report's warnings of labels that differ from the scene's by case only ``near``, of a scaling that fits the
    static pose worse (misfit ``before``, m) than the scene unscaled (``unscaled``; None: not scaled), of the static
    pose held at a limit ``held`` and of the markers moved far ``far``: a study's summary and the command's stderr
    show warnings, not the report's other lines."""
    out = [f"warning: the static trial's labels {near} differ from the scene's by case or spaces only: those markers "
           "are left where they were (labels are matched exactly): fix the labels"] * bool(near)
    if unscaled is not None and before > unscaled + WORSE_BY:
        out.append(f"warning: the scaled segments fit the static pose worse than the scene's ({1e3 * before:.1f} mm "
                   f"RMS, {1e3 * unscaled:.1f} mm unscaled): their markers' pairs do not measure the segments' lengths "
                   "(skin clusters, or segments across the plane): calibrate without scaling")
    if held:  # the markers would be placed on a pose the subject was not in: said, as OpenSim's marker placer does it
        out.append(f"warning: the static pose holds {', '.join(held)} at a limit of its range (the model's clamped "
                   f"range; the subject stood beyond it): the markers are placed on the pose held there, the static "
                   f"misfit {1e3 * before:.1f} mm before: widen the range, or the model is not of this subject")
    if far:
        out.append(f"warning: markers moved more than {1e3 * MOVE_WARN:.0f} mm on their segments: {', '.join(far)}: "
                   "a marker on another segment, labels swapped, or a model not of this subject?")
    return out


def _near_labels(wanted, recorded) -> str:
    """The trial's labels ``recorded`` that differ from the scene's absent ones ``wanted`` by case or spaces only, as
    a phrase ("" where none): labels are matched exactly, and such a marker would be left where it was."""
    folded = {r.strip().casefold(): r for r in recorded}
    near = [(w, folded[w.strip().casefold()]) for w in wanted if w.strip().casefold() in folded]
    return ", ".join(f"{r!r} for {w!r}" for w, r in near)


def _check_facing(scene, lab, pl) -> None:
    """ValueError in one line where the static trial's subject faces another horizontal direction than the plane
    ``pl``'s x (:func:`casflex.inverse.heading.facing_plane`, where it can tell): the plane would see it mirrored
    (facing -x: its knees bent forward) or from the front, and the markers would be placed on that."""
    from casflex.inverse.heading import facing_plane

    if pl.y.startswith("-") or len(lab.t) == 0:
        return
    try:
        with np.errstate(all="ignore"):  # markers on one vertical line (no x spread): no facing, ValueError below
            best, line = facing_plane(scene, lab, pl.y.lstrip("+"))
    except ValueError:  # too few markers, or no direction stands out: the fit's misfit and moves say the rest
        return
    if best.split(",")[0].lstrip("+") != pl.x.lstrip("+"):
        raise ValueError(f"{lab.source}: the subject faces {best.split(',')[0]} in the static trial, not the plane's "
                         f"x {pl.x} ({line.split('(', 1)[1].rstrip(')')}): give the plane {best}")


#: a static trial's markers whose heights in the scene correlate with a lab axis at least this well stand along it
#: (Hamner's static: 1.00 with Y; 0.31 with X, -0.51 with Z: a leg's markers lie forward and to the side)
ALONG = 0.8


def _vertical_lines(scene, lab, pl) -> list[str]:
    """The report's warning (none or one line) where the subject of the static trial stands along a lab axis other
    than the plane's y: the plane sees it lying or from above (a plane whose y is not the lab's vertical), and its
    pose is fitted so (a subject lying in the plane, rarely recorded as a static trial, is the other reason)."""
    labels = [m.lab_label for m in scene.markers if m.lab_label in lab.labels]
    with warnings.catch_warnings():  # a marker never seen: its mean NaN, left out
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.array([np.nanmean(lab.marker(lb), axis=0) for lb in labels]).reshape(-1, 3)
    y = np.array([m.y for m in scene.markers if m.lab_label in lab.labels])
    ok = np.isfinite(mean).all(axis=1)
    if ok.sum() < 3 or np.ptp(y[ok]) == 0.0:
        return []
    with np.errstate(all="ignore"):
        c = np.nan_to_num([np.corrcoef(y[ok], mean[ok, k])[0, 1] for k in range(3)])
    k = int(np.argmax(np.abs(c)))
    mine = float(pl.matrix[1] @ c)  # the plane's y's correlation (signed)
    axis = ('-' if c[k] < 0 else '') + 'XYZ'[k]
    if abs(c[k]) < ALONG or axis == pl.y.lstrip("+"):
        return []
    return [f"warning: the subject stands along {axis} in the static trial (the markers' heights' correlation "
            f"{abs(c[k]):.2f}), not along the plane's y {pl.y} ({mine:+.2f}): a plane whose y is not the lab's "
            "vertical? (the pose is fitted lying or seen from above)"]


def calibrate(scene, static, plane: str = "X,Y", *, root: str | None = None, scale: bool = False,
              mass: float | None = None):
    """(the calibrated scene, report lines) from the static trial ``static`` (LabMarkers or a .trc/.c3d
    path), module docstring. A segment the static trial has none of the markers of is locked for the static fit
    only (:func:`casflex.inverse.locking.lock_unmarked`): the scene returned keeps its joints and its markers (where
    they were; scaled, it keeps its size), for the trials that record them."""
    from casflex.inverse.fit import at_limits, check_decided, coordinate_bounds, fit_pose
    from casflex.inverse.inputs import inverse_model, read_markers
    from casflex.inverse.locking import lock_unmarked
    from casflex.lab import LabMarkers, Plane
    from casflex.lab.checks import check_markers, check_scale, check_static
    from casflex.lab.marker_sets import JOINT_CENTRES, joint_centres
    from casflex.scene import Scene, load_scene

    if mass is not None and not mass > 0:
        raise ValueError(f"mass: must be > 0 kg, got {mass}")
    pl = Plane.parse(plane) if isinstance(plane, str) else plane
    lab = static if isinstance(static, LabMarkers) else read_markers(static)[0]
    scene = scene if isinstance(scene, Scene) else load_scene(scene)
    lab, early = joint_centres(lab, [m.lab_label for m in scene.markers])
    centres = {m.name for m in scene.markers if m.weight == 0 and m.lab_label in JOINT_CENTRES}
    full = inverse_model(dataclasses.replace(scene, markers=tuple(  # the joint centres place the segments (weight 1)
        dataclasses.replace(m, weight=1.0) if m.name in centres else m for m in scene.markers)), root).scene
    recorded, where = lab.labels, f"the static trial {lab.source}"
    _check_facing(full, lab, pl)
    early += _vertical_lines(full, lab, pl)
    scene, locked = lock_unmarked(full, recorded, where)
    early += locked
    model = inverse_model(scene, root)
    tree = kinematic_tree(model, root)
    sc = model.scene
    labels = {m.name: m.lab_label for m in sc.markers}
    absent = tuple(dict.fromkeys(m.lab_label for m in full.markers if m.lab_label not in lab.labels))
    if absent:  # a marker the static trial never recorded: like one it lost, left where it is (reported below)
        lab = dataclasses.replace(lab, labels=lab.labels + absent, xyz=np.concatenate(
            [lab.xyz, np.full((lab.t.size, len(absent), 3), np.nan)], axis=1))
    check_markers(lab, tuple(labels.values()))
    check_static(lab, tuple(labels.values()))
    ym = _static_mean(lab, sc, pl)
    near = _near_labels(absent, recorded)
    if not np.isfinite(ym).any():
        raise ValueError(f"{lab.source}: none of the scene's markers {list(labels.values())} is seen in the trial"
                         + f" (it has {near}: labels are matched exactly)" * bool(near))
    check_scale(lab.source, lab.units, np.array([[m.x, m.y] for m in sc.markers]), ym[None],
                [tree.cluster[i] for i in tree.marker_nodes])
    report = [*early, f"static trial: {lab.t.size} frames averaged, {int(np.isfinite(ym).all(1).sum())} of "
                       f"{len(sc.markers)} markers seen"]
    check_decided(tree, ym.ravel()[None], tuple(labels.values()), lab.source)
    unscaled = fit_pose(tree, ym.ravel())[1]
    if scale:  # on the whole tree: a segment locked for the fit has no marker seen, and keeps its size
        full, lines = _scaled(kinematic_tree(inverse_model(full, root), root), full, _static_mean(lab, full, pl),
                              [m.lab_label for m in full.markers], lab.source, mass)
        report += lines
        sc = lock_unmarked(full, recorded, where)[0]
    elif mass is not None:
        raise ValueError("mass: scales the bodies with the segments (scale=True)")
    model = inverse_model(sc, root)
    tree = kinematic_tree(model, root)
    z, before, decided = fit_pose(tree, ym.ravel())
    if not decided:
        raise ValueError(f"static trial: its markers do not decide the pose: {_undecided_at(tree, z, ym)} (a segment "
                         "with fewer than two seen markers and no other way to place it): record them, or take the "
                         "segment out of the scene")
    held = at_limits(z, coordinate_bounds(tree), tree)
    markers, moved, far = _placed(sc, model, tree, z, ym, report)
    y_after = np.array(kinematic_tree(inverse_model(dataclasses.replace(sc, markers=tuple(markers)), root), root)
                       .marker_fit(z)[0]).reshape(-1, 2)
    ok = np.isfinite(ym).all(axis=1)
    after = float(np.sqrt(np.mean(np.sum((y_after[ok] - ym[ok]) ** 2, axis=1))))
    placed = {m.name: m for m in markers}
    out = dataclasses.replace(full, markers=tuple(  # the marker fit's weights again
        dataclasses.replace(m, weight=0.0) if m.name in centres else m
        for m in (placed.get(m.name, m) for m in full.markers)))
    if scale:
        report.append(f"the static pose's misfit with the scene's markers: {1e3 * unscaled:.1f} mm unscaled, "
                      f"{1e3 * before:.1f} mm scaled")
    report.append(f"markers placed: moved by {1e3 * np.median(moved):.1f} mm (median), {1e3 * max(moved):.1f} mm "
                  f"(most); static misfit RMS {1e3 * before:.1f} mm before, {1e3 * after:.2g} mm after" if moved else
                  f"markers placed: none (each seen one fixed); static misfit RMS {1e3 * before:.1f} mm")
    return out, report + _warnings(before, held, far, unscaled if scale else None, near)
