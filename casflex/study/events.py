"""Gait events from a lab trial: the plates' contacts, the foot each plate is under, foot strikes, gait cycles,
and signals normalised to 0..100 % of a cycle. numpy only: no model is assembled.

- Vertical: the model's y, the :class:`casflex.lab.Plane`'s second lab axis ("X,Y" for OpenSim's files, Y up;
  "X,Z" for a C3D lab, Z up); a plate's vertical force fv (N) is its force along it. Horizontal: the lab's
  floor, the plane's x and its normal: the planar model drops the normal, but it sets the left foot apart
  from the right, so distances keep it.
- A contact (:func:`contacts`): fv above ``threshold`` (20 N: below it casflex's C3D plates give no centre of
  pressure), crossings interpolated linearly, shorter than ``min_duration`` dropped; loaded at the record's
  start or end: strike or off None, never a cycle's end.
- A foot (:func:`feet`): a node carrying markers (a body's on it, a beam's on its end farther from the root)
  with none on the nodes beyond it from the root (the scene's first node) along joints and beams: OpenSim's
  calcn_r, calcn_l (the toes carry none), and a wrist's radius, which the height check sets apart. Where the
  toes carry markers the toes are the foot: give ``plates={node: prefix}`` yourself.
- The foot over a contact (:func:`plate_contacts`): each foot's nearest marker's distance across the floor
  from the centre of pressure and its lowest marker's height above it, averaged over the contact weighted by
  fv (the centre of pressure is noise where the force is small); of the feet within ``max_distance`` (0.3 m)
  across and ``max_height`` (0.1 m) above, the nearest. On Hamner's trial the foot on the plate: 0.05 m and
  0.04-0.05 m; the other foot coming down at the end of a stance: 0.17 m and 0.15 m. None: ValueError.
  :func:`assign_plates` refuses a plate stepped on by two feet (over-ground walking on one plate) and two
  plates under one foot: casflex's inverse takes ``plates={node: prefix}``, one node per plate and one plate
  per node; :func:`plate_contacts` gives the foot of each contact.
- Cycles (:func:`gait_cycles`): a foot's strike to its next, from the strikes the lab marked in the file (a C3D's
  events: :func:`marked_strikes`) where the foot has two, else from the plates where it has two plate strikes,
  else from its heel marker (:func:`marker_strikes`), said in the report.
- A clean cycle (:func:`clean_cycles`): its stance wholly on one plate, the plate inverse dynamics applies to the
  foot, as labs take kinetics only from such cycles: a cycle whose stance is off every plate (its strikes from the
  heel marker) or on two plates, or on a plate another foot shares, has loads below the hip without the foot's
  ground reaction (Hamner's right ankle: a peak of -0.78 N m/kg averaged with such a cycle, -1.54 from the clean).
- The feet that walk (:func:`ground_feet`): the feet whose markers come down to the floor (a wrist's never do); a
  foot among them that touches no plate has no kinetic cycle (its leg's loads are not the other foot's).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from casflex.lab.c3d import MIN_PLATE_FORCE
from casflex.lab.filtering import _plate_columns
from casflex.lab.plane import Plane
from casflex.lab.plate_checks import check_plate_record, scene_mass
from casflex.lab.tables import LabMarkers, LabTable, increasing_times

__all__ = ["Contact", "contacts", "vertical_force", "tree_walk", "below", "feet", "plate_contacts", "assign_plates",
           "plates_of", "marked_strikes", "swing_phases", "read_trial", "plate_prefixes", "foot_strikes",
           "marker_strikes", "cycles", "gait_cycles", "clean_cycles", "ground_feet", "normalise"]


def contacts(t, fv, threshold: float = MIN_PLATE_FORCE, min_duration: float = 0.05
             ) -> list[tuple[float | None, float | None]]:
    """A plate's contacts [(strike, off)] (s) from its vertical force ``fv`` (n,) N at the times ``t`` (n,) s:
    where fv > ``threshold`` N, each crossing interpolated linearly between its two samples; an interval
    shorter than ``min_duration`` s (its part in the record) dropped; strike None where the record starts
    loaded, off None where it ends loaded. Samples that are not numbers are left out (the crossings are
    interpolated across them)."""
    t, f = np.asarray(t, dtype=float), np.asarray(fv, dtype=float)
    if t.ndim != 1 or f.shape != t.shape:
        raise ValueError(f"t, fv: expected two (n,) arrays, got {t.shape} and {f.shape}")
    t, f = increasing_times(t[np.isfinite(f)], "t"), f[np.isfinite(f)]
    if t.size < 2:
        return []
    on = f > threshold
    edges = np.flatnonzero(on[1:] != on[:-1])
    at = t[edges] + (threshold - f[edges]) / (f[edges + 1] - f[edges]) * (t[edges + 1] - t[edges])
    ups = [None] * bool(on[0]) + [float(x) for x, i in zip(at, edges, strict=True) if on[i + 1]]
    downs = [float(x) for x, i in zip(at, edges, strict=True) if on[i]] + [None] * bool(on[-1])
    return [(a, b) for a, b in zip(ups, downs, strict=True)
            if (t[-1] if b is None else b) - (t[0] if a is None else a) >= min_duration]


def _plane(plane: Plane | str) -> Plane:
    return Plane.parse(plane) if isinstance(plane, str) else plane


def plate_prefixes(table: LabTable) -> list[str]:
    return [n[:-len("force_vx")] for n in table.names if n.endswith("force_vx")]


def _times(ts) -> str:
    return ", ".join(f"{x:.3f}" for x in ts) or "-"


def _span(a: float | None, b: float | None) -> str:
    return f"{'[start]' if a is None else f'{a:.3f}'}-{'[end]' if b is None else f'{b:.3f}'} s"


def vertical_force(table: LabTable, prefix: str, plane: Plane | str = "X,Y") -> np.ndarray:
    """(n,) N: the plate ``prefix``'s force along the model's y (module docstring)."""
    p, up = _plate_columns(table, prefix), _plane(plane).matrix[1]
    return np.column_stack([table.column(f"{p}force_v{a}") for a in "xyz"]) @ up


def tree_walk(scene) -> tuple[dict[str, str | None], list[str]]:
    """(parent of each node, the nodes in walk order): the scene's nodes breadth first along its joints and beams
    from its first node (then from any node that does not reach), each node's parent the one it was reached from."""
    links = [pair for j in [*scene.joints, *scene.beams] for pair in zip(j.nodes[:-1], j.nodes[1:], strict=True)]
    nbr = {n.name: [b for a, b in links if a == n.name] + [a for a, b in links if b == n.name] for n in scene.nodes}
    parent: dict[str, str | None] = {}
    order: list[str] = []
    for root in (r for r in nbr if r not in parent):
        parent[root] = None
        order.append(root)
        for n in order:  # grows as it is walked
            for m in nbr[n]:
                if m not in parent:
                    parent[m] = n
                    order.append(m)
    return parent, order


def below(scene, node: str) -> set[str]:
    """``node`` and the nodes beyond it from the scene's first node (:func:`tree_walk`): what a joint at ``node``
    carries."""
    parent, _ = tree_walk(scene)
    out = set()
    for n in parent:
        m: str | None = n
        while m is not None and m != node:
            m = parent[m]
        if m == node:
            out.add(n)
    return out


def feet(scene) -> dict[str, tuple[str, ...]]:
    """The scene's feet (module docstring): node -> the lab labels of its markers (``label``, or the name)."""
    parent, order = tree_walk(scene)
    on = {b.name: b.node for b in scene.bodies} | {b.name: max(b.nodes, key=order.index) for b in scene.beams}
    carry: dict[str, list[str]] = {}
    for m in scene.markers:
        carry.setdefault(on[m.on], []).append(m.lab_label)
    beyond = set()
    for n in carry:
        while (n := parent[n]) is not None:
            beyond.add(n)
    return {n: tuple(labels) for n, labels in carry.items() if n not in beyond}


@dataclass(frozen=True)
class Contact:
    """One contact of the plate ``plate`` (its columns' prefix): ``strike``, ``off`` (s, None: the record
    starts or ends during it), the ``foot`` (node) over it, ``distance`` and ``height`` (m: module docstring),
    and ``others``: (node, distance, height) of the other feet, nearest first."""

    plate: str
    strike: float | None
    off: float | None
    foot: str
    distance: float
    height: float
    others: tuple[tuple[str, float, float], ...] = ()


def read_trial(markers, grf, plates: bool = True, required: bool = True) -> tuple[LabMarkers, LabTable | None]:
    """(markers, plates) from objects or files (.trc / .c3d; .mot / .sto / .c3d; grf None: the markers' C3D);
    ``plates`` False: the markers alone; ``required`` False: None where there are no plates, else ValueError."""
    from casflex.lab import read_c3d, read_sto, read_trc

    if not isinstance(markers, LabMarkers):
        path = os.fspath(markers)
        same = plates and path.lower().endswith(".c3d") and (grf is None or (
            not isinstance(grf, LabTable) and os.fspath(grf) == path))
        markers, table = read_c3d(path, plates=same) if path.lower().endswith(".c3d") else (read_trc(path), None)
        grf = table if same else grf
    if plates and grf is not None and not isinstance(grf, LabTable):
        grf = read_c3d(grf)[1] if os.fspath(grf).lower().endswith(".c3d") else read_sto(grf)
    if plates and grf is None and required:
        raise ValueError("grf: no force plates (give a .mot / .sto or .c3d file with plates, or a LabTable)")
    return markers, grf if plates else None


def _foot_distance(lab: LabMarkers, labels, t, P, w, axes) -> tuple[float, float]:
    """(distance, height) m of the foot with the markers ``labels`` from the centres of pressure P (k, 3) m
    at the times t (k,) s, means weighted by w (k,) N; inf where its markers are missing throughout."""
    X = np.empty((t.size, len(labels), 3))  # the markers at the plate's times
    for j, lb in enumerate(labels):
        X[:, j] = np.column_stack([np.interp(t, lab.t, c) for c in lab.marker(lb).T])
    d = X - P[:, None, :]
    across, up = np.linalg.norm(d @ axes[:2].T, axis=2), d @ axes[2]
    across, up = (np.where(np.isfinite(v), v, np.inf).min(axis=1) for v in (across, up))
    ok = np.isfinite(across)
    if not ok.any():
        return np.inf, np.inf
    return float(np.average(across[ok], weights=w[ok])), float(np.average(up[ok], weights=w[ok]))


def plate_contacts(scene, markers, grf=None, plane: Plane | str = "X,Y", prefixes=None, *,
                   threshold: float = MIN_PLATE_FORCE, min_duration: float = 0.05, max_distance: float = 0.3,
                   max_height: float = 0.1) -> list[Contact]:
    """Every contact of the plates ``prefixes`` (default: all the table's, ``<prefix>force_vx`` ...) with the
    foot over it (module docstring), in plate order then time. ``markers``: a LabMarkers or a .trc / .c3d
    file; ``grf``: a LabTable or a .mot / .sto / .c3d file (None: the markers' C3D). ValueError in one line:
    a scene without feet in the trial, a plate unknown, no foot over a contact, a plate whose vertical force pulls
    or holds a one-sample spike (:func:`casflex.lab.plate_checks.check_plate_record`)."""
    lab, table = read_trial(markers, grf)
    pl = _plane(plane)
    axes = np.vstack([pl.matrix[0], np.cross(*pl.matrix), pl.matrix[1]])  # the floor's two axes, then up
    cands = {n: [lb for lb in labels if lb in lab.labels] for n, labels in feet(scene).items()}
    cands = {n: labels for n, labels in cands.items() if labels}
    if not cands:
        raise ValueError(f"{lab.source}: no marker of the scene's feet {sorted(feet(scene))} is in the trial")
    found = []
    weight = scene_mass(scene) * float(np.hypot(*scene.gravity))
    for prefix in prefixes or plate_prefixes(table):
        p = _plate_columns(table, prefix)
        fv = vertical_force(table, p, pl)
        force = np.column_stack([table.column(f"{p}force_v{a}") for a in "xyz"])
        # a plate that pulls or spikes would have its stances missed or cut: refused, whether a foot is found on it
        check_plate_record(f"{table.source}: plate {p!r}", table.t, force, fv, weight, stance=False)
        P = np.column_stack([table.column(f"{p}force_p{a}") for a in "xyz"])
        for a, b in contacts(table.t, fv, threshold, min_duration):
            lo, hi = (table.t[0] if a is None else a), (table.t[-1] if b is None else b)
            rows = (table.t >= lo) & (table.t <= hi) & (fv > threshold) & np.isfinite(P).all(axis=1)
            rows &= (table.t >= lab.t[0]) & (table.t <= lab.t[-1])
            if not rows.any():
                raise ValueError(f"plate {p!r}, contact {_span(a, b)}: no centre of pressure within the markers' "
                                 f"times {lab.t[0]:g}..{lab.t[-1]:g} s")
            score = sorted(((n, *_foot_distance(lab, labels, table.t[rows], P[rows], fv[rows], axes))
                            for n, labels in cands.items()), key=lambda s: s[1])
            near = [s for s in score if s[1] <= max_distance and s[2] <= max_height]
            if not near:
                raise ValueError(f"plate {p!r}, contact {_span(a, b)}: no foot within {max_distance:g} m across the "
                                 f"floor of its centre of pressure and {max_height:g} m above it (nearest: "
                                 f"{score[0][0]}, {score[0][1]:.2f} m and {score[0][2]:.2f} m); plane {pl.x},{pl.y}")
            found.append(Contact(p, a, b, near[0][0], near[0][1], near[0][2],
                                 tuple(s for s in score if s is not near[0])))
    return found


def assign_plates(scene, markers, grf=None, plane: Plane | str = "X,Y", prefixes=None, **options
                  ) -> tuple[dict[str, str], list[str]]:
    """({node: prefix} for :func:`casflex.inverse.inverse_dynamics`' ``plates``, report lines): each plate
    under the foot over all its contacts (:func:`plate_contacts`, whose ``options`` these are; :func:`plates_of`)."""
    lab, table = read_trial(markers, grf)
    prefixes = [_plate_columns(table, p) for p in prefixes] if prefixes else plate_prefixes(table)
    found = plate_contacts(scene, lab, table, plane, prefixes, **options)
    return plates_of(found, prefixes, options.get("threshold", MIN_PLATE_FORCE))


def plates_of(found: list[Contact], prefixes: list[str], threshold: float = MIN_PLATE_FORCE
              ) -> tuple[dict[str, str], list[str]]:
    """({node: prefix}, report lines) from :func:`plate_contacts`' contacts ``found`` of the plates ``prefixes``
    (above ``threshold`` N); a plate without contacts is left out and said. ValueError in one line for a plate
    stepped on by two feet and for two plates under one foot (module docstring)."""
    plates: dict[str, str] = {}
    lines = []
    for p in prefixes:
        mine = [c for c in found if c.plate == p]
        if not mine:
            lines.append(f"plate {p!r}: no contact above {threshold:g} N: left out")
            continue
        by = {c.foot: [_span(d.strike, d.off) for d in mine if d.foot == c.foot] for c in mine}
        if len(by) > 1:
            raise ValueError(f"plate {p!r} is stepped on by " + " and ".join(f"{n} ({', '.join(s)})" for n, s in
                             by.items()) + ": casflex's inverse takes one node per plate; cut the trial "
                             "(t_start, t_end) to one foot's contacts, or take plate_contacts' feet per contact")
        node = mine[0].foot
        if node in plates:
            raise ValueError(f"plates {plates[node]!r} and {p!r} are both under {node}: casflex's inverse takes one "
                             "plate per node; cut the trial (t_start, t_end) to one of them")
        plates[node] = p
        nxt = min((o for c in mine for o in c.others), key=lambda o: o[1], default=None)
        lines.append(f"plate {p!r} -> {node}: {len(mine)} contact(s) {', '.join(by[node])}; its markers within "
                     f"{max(c.distance for c in mine):.3f} m of the centre of pressure across the floor and "
                     f"{max(c.height for c in mine):.3f} m above it" + (
                         f"; next: {nxt[0]}, {nxt[1]:.2f} m and {nxt[2]:.2f} m" if nxt else ""))
    return plates, lines


def swing_phases(found: list[Contact], scene, lab: LabMarkers, node: str, spans: list[tuple[float, float]]
                 ) -> list[tuple[float, float]]:
    """The swing phases (s) of the foot ``node`` within its gait cycles ``spans``: each foot off (the lab's marked
    "Foot Off" on the foot's side, else its plates' offs) to the cycle's end, the next strike."""
    side = _side(node, feet(scene).get(node, ()))
    offs = [t for cx, lb, t in lab.events if cx == side and lb.lower() == "foot off"] if side else []
    offs = offs or [c.off for c in found if c.foot == node and c.off is not None]
    return [(off, c1) for c0, c1 in spans for off in sorted(offs) if c0 < off < c1]


def foot_strikes(found: list[Contact]) -> dict[str, list[float]]:
    """node -> its plate strikes (s, increasing) from :func:`plate_contacts`' contacts (those loaded at the
    record's start give none)."""
    feet_ = dict.fromkeys(c.foot for c in found)
    return {n: sorted(c.strike for c in found if c.foot == n and c.strike is not None) for n in feet_}


def marker_strikes(t, height, lift: float = 0.1) -> list[float]:
    """Foot strikes (s) from a heel marker's height (n,) m along the vertical at the times t (n,) s: the
    heel's lowest point (its velocity, central differences, crossing zero upward, interpolated linearly)
    first after each swing that lifted it more than ``lift`` m above its lowest height in the record; a
    minimum at the record's start is no strike. Samples that are not numbers are left out. On Hamner's
    running trial (60 Hz) -4 to +21 ms from the plates' 20 N crossings (tests/test_study_events.py)."""
    t, h = np.asarray(t, dtype=float), np.asarray(height, dtype=float)
    t, h = increasing_times(t[np.isfinite(h)], "t"), h[np.isfinite(h)]
    if t.size < 3:
        return []
    v, floor = np.gradient(h, t), h.min()
    out, lifted = [], False
    for i in range(t.size - 1):
        lifted |= bool(h[i] > floor + lift)
        if lifted and v[i] < 0 <= v[i + 1]:
            out.append(float(t[i] - v[i] * (t[i + 1] - t[i]) / (v[i + 1] - v[i])))
            lifted = False
    return out


def _side(node: str, labels: tuple[str, ...]) -> str | None:
    """"Left", "Right" or None: the side of the foot ``node`` by its name (calcn_l, r_foot, LeftFoot) or else by
    its markers' labels (Plug-in Gait's LHEE, LTOE: every one starting with L or R)."""
    n = node.lower()
    for side, short in (("Left", "l"), ("Right", "r")):
        if n.endswith("_" + short) or n.startswith(short + "_") or side.lower() in n:
            return side
    first = {lb[:1].upper() for lb in labels}
    return {"L": "Left", "R": "Right"}.get(first.pop()) if len(first) == 1 else None


def marked_strikes(lab: LabMarkers, scene) -> dict[str, list[float]]:
    """node -> the foot strikes the lab marked in the file (``lab.events``: "Foot Strike" in the foot's side's
    context) for each foot of the scene whose side :func:`_side` tells; empty where the file marks none."""
    strikes = {side: [t for cx, lb, t in lab.events if cx == side and lb.lower() == "foot strike"]
               for side in ("Left", "Right")}
    return {node: strikes[side] for node, labels in feet(scene).items() if (side := _side(node, labels))}


def cycles(strike_times, max_duration: float | None = None) -> list[tuple[float, float]]:
    """Gait cycles [(t0, t1)] (s) of one foot: each strike to its next (``strike_times`` in any order); a
    cycle longer than ``max_duration`` s (a strike missed between, e.g. off the plates) left out."""
    s = sorted({float(x) for x in strike_times})
    return [(a, b) for a, b in zip(s[:-1], s[1:], strict=True) if max_duration is None or b - a <= max_duration]


def gait_cycles(found: list[Contact], scene, markers, plane: Plane | str = "X,Y", heel: dict[str, str] | None = None,
                max_duration: float | None = None, lift: float = 0.1
                ) -> tuple[dict[str, list[tuple[float, float]]], list[str]]:
    """({node: cycles}, report lines) for the feet of :func:`plate_contacts`' contacts ``found``: from the foot
    strikes the lab marked in the file (:func:`marked_strikes`) where a foot has two, else the plates' where it
    has two, else its heel marker's (``heel[node]``, default the foot's first marker labelled like heel (hee:
    Plug-in Gait's RHEE) or cal) by :func:`marker_strikes`; ``markers`` a LabMarkers or a file."""
    lab = read_trial(markers, None, plates=False)[0]
    up = _plane(plane).matrix[1]
    marked = marked_strikes(lab, scene)
    out, lines = {}, []
    for node, plate in foot_strikes(found).items():
        label = (heel or {}).get(node) or next((lb for lb in feet(scene).get(node, ()) if lb in lab.labels and (
            "hee" in lb.lower() or "cal" in lb.lower())), None)
        if len(marked.get(node, [])) >= 2:
            s, how = marked[node], "the marked events'"
        elif len(plate) >= 2:
            s, how = plate, "the plates'"
        else:
            s = marker_strikes(lab.t, lab.marker(label) @ up, lift) if label else []
            how = f"{label}'s" if label else "no heel marker's (heel=)"
        out[node] = cycles(s, max_duration)
        said = "" if s is plate else f" ({len(plate)} plate strike(s): {_times(plate)} s)"
        lines.append(f"{node}: {len(out[node])} cycle(s) from {how} strikes at {_times(s)} s{said}")
    return out, lines


def clean_cycles(found: list[Contact], node: str, spans: list[tuple[float, float]], plate: str | None,
                 slack: float = 0.05) -> list[tuple[bool, str]]:
    """(clean, why) for each gait cycle (t0, t1) s in ``spans`` of the foot ``node`` (module docstring): clean where
    one of its contacts ``found`` (:func:`plate_contacts`) on ``plate`` (the plate inverse dynamics applies to the
    foot; None: none) strikes within ``slack`` s of t0 (the heel marker's strikes are -4 to +21 ms from the plates'
    on Hamner's trial) and comes off before t1, and no other contact (of this foot on another plate, or of another
    foot on this plate) overlaps its stance; ``why`` says what is wrong, or the stance's span."""
    out = []
    for t0, t1 in spans:
        mine = [c for c in found if c.foot == node and c.strike is not None and abs(c.strike - t0) <= slack]
        stance = next((c for c in mine if c.plate == plate), None)
        if plate is None:
            out.append((False, "no plate is applied to it (the study file's plates)"))
            continue
        if stance is None:
            on = ", ".join(f"{c.plate!r}" for c in mine)
            near = [c for c in found if c.foot == node and (c.strike or -np.inf) < (t0 + t1) / 2  # in its stance
                    and (c.off or np.inf) > t0]
            said = (f" (on {on}, not applied to it)" if on else f" (its contact {_span(near[0].strike, near[0].off)} "
                    f"on {near[0].plate!r})" if near else " (the foot off every plate)")
            out.append((False, f"no strike on its plate {plate!r} within {slack:g} s of {t0:.3f} s{said}"))
            continue
        if stance.off is None or stance.off > t1:
            out.append((False, f"its stance on {plate!r} from {stance.strike:.3f} s does not end within the cycle"))
            continue
        also = [c for c in found if c is not stance and (c.foot == node) != (c.plate == plate)
                and (c.strike is None or c.strike < stance.off) and (c.off is None or c.off > stance.strike)]
        if also:
            c = also[0]
            out.append((False, f"{c.foot} on {c.plate!r} {_span(c.strike, c.off)} during its stance on {plate!r} "
                               f"{_span(stance.strike, stance.off)}"))
            continue
        out.append((True, f"stance on {plate!r} {_span(stance.strike, stance.off)}"))
    return out


def ground_feet(scene, lab: LabMarkers, plane: Plane | str = "X,Y", max_height: float = 0.15) -> list[str]:
    """The scene's feet (:func:`feet`) that walk: whose lowest marker in the trial ``lab`` comes within
    ``max_height`` m (vertical: the plane's y) of the trial's lowest marker (the floor's level, near enough: heel
    and toe markers sit some 0.02-0.05 m above it), in :func:`feet`'s order; a wrist's stay 0.7 m up."""
    up = _plane(plane).matrix[1]
    low = {}
    for node, labels in feet(scene).items():
        h = [lab.marker(lb) @ up for lb in labels if lb in lab.labels]
        h = np.concatenate(h) if h else np.array([])
        low[node] = float(np.nanmin(h)) if np.isfinite(h).any() else np.inf
    floor = min(low.values(), default=np.inf)
    return [n for n, v in low.items() if v <= floor + max_height]


def normalise(t, y, t0: float, t1: float, n: int = 101) -> np.ndarray:
    """(n, ...) the signal y (len(t), ...) at 0, 100/(n-1), ..., 100 % of the cycle [t0, t1] (s), linear
    between its samples t (s, increasing). ValueError where [t0, t1] is not within t."""
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    if t.ndim != 1 or t.size < 2 or y.shape[:1] != t.shape or n < 2:
        raise ValueError(f"t, y, n: expected t (k,), y (k, ...), k >= 2, n >= 2, got {t.shape}, {y.shape}, {n}")
    t = increasing_times(t, "t")
    slack = 1e-9 * max(1.0, abs(t[0]), abs(t[-1]))
    if not (t[0] - slack <= t0 < t1 <= t[-1] + slack):
        raise ValueError(f"cycle {t0:g}..{t1:g} s: not within the signal's times {t[0]:g}..{t[-1]:g} s")
    grid = np.linspace(t0, t1, n)
    i = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, t.size - 2)
    w = np.clip((grid - t[i]) / (t[i + 1] - t[i]), 0.0, 1.0).reshape((n,) + (1,) * (y.ndim - 1))
    return (1.0 - w) * y[i] + w * y[i + 1]
