"""Which foot is on a force plate when: a plate's contacts (its vertical force above a threshold), the scene's feet,
the foot over each contact by its markers, and each plate's samples shared out among the feet it carries in turn
(:func:`plate_shares`), so that a node's ground reaction may come from different plates over a trial (a foot on
plate 1, a stride later on plate 3) and from two plates at once (a stance straddling them: their wrenches summed).
numpy only: no model is assembled.

- Vertical: the model's y, the :class:`casflex.lab.Plane`'s second lab axis ("X,Y" for OpenSim's files, Y up;
  "X,Z" for a C3D lab, Z up); a plate's vertical force fv (N) is its force along it. Horizontal: the lab's
  floor, the plane's x and its normal: the planar model drops the normal, but it sets the left foot apart
  from the right, so distances keep it.
- A contact (:func:`contacts`): fv above ``threshold`` (20 N: below it casflex's C3D plates give no centre of
  pressure), crossings interpolated linearly, shorter than ``min_duration`` dropped; loaded at the record's
  start or end: strike or off None, never a cycle's end. In :func:`plate_contacts` (:func:`_plate_spans`) a shorter
  one above 100 N (beyond a noise's level) is kept at the record's start or end (a stance the record cuts: its load
  goes to its own foot, not the plate's next) and refused elsewhere (a foot grazing the plate: its load would go to a
  foot in swing); a plate whose unloaded reading reaches the threshold (noise, an offset: its contacts' times would
  chatter) is refused (:func:`_unloaded`).
- A foot (:func:`feet`): a node carrying markers (a body's on it, a beam's on its end farther from the root)
  with none on the nodes beyond it from the root (the scene's first node) along joints and beams: OpenSim's
  calcn_r, calcn_l (the toes carry none), and a wrist's radius, which the height check sets apart. Where the
  toes carry markers the toes are the foot: give ``plates={node: prefix}`` yourself.
- The foot over a contact (:func:`plate_contacts`): each foot's nearest marker's distance across the floor
  from the centre of pressure and its lowest marker's height above it, averaged over the contact weighted by
  fv (the centre of pressure is noise where the force is small); of the feet within ``max_distance`` (0.3 m)
  across and ``max_height`` (0.1 m) above, the nearest. On Hamner's trial the foot on the plate: 0.05 m and
  0.04-0.05 m; the other foot coming down at the end of a stance: 0.17 m and 0.15 m. None: ValueError. A contact
  whose centre of pressure, loaded, lies farther than :data:`MAX_COP_FROM_FOOT` from its foot's markers and nearer
  another foot's (:func:`_one_foot`) carries both feet at once (a treadmill's single plate, a double support on one
  plate): ValueError, as no nearest foot can take their load together.
- A plate's samples shared among its feet (:func:`plate_shares`): each sample goes to the foot of the contact
  nearest in time (inside a contact, its foot; between two contacts of different feet, the boundary halfway
  between the first's off and the second's strike, where the plate carries no load): the shares partition the
  plate's samples, so that their loads, filtered (a linear filter), sum to the whole plate's exactly.
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

__all__ = ["Contact", "contacts", "vertical_force", "tree_walk", "below", "feet", "plate_contacts", "read_trial",
           "plate_prefixes", "plate_shares", "AUTO"]

#: ``plates="auto"`` (:class:`casflex.inverse.Trial`): each plate's contacts applied to the foot over each
AUTO = "auto"


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


def span_text(a: float | None, b: float | None) -> str:
    return f"{'[start]' if a is None else f'{a:.3f}'}-{'[end]' if b is None else f'{b:.3f}'} s"


def vertical_force(table: LabTable, prefix: str, plane: Plane | str = "X,Y") -> np.ndarray:
    """(n,) N: the plate ``prefix``'s force along the model's y (module docstring)."""
    p, up = _plate_columns(table, prefix), _plane(plane).matrix[1]
    with np.errstate(invalid="ignore"):  # a sample that is not a number stays one (contacts() leaves it out)
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
    ``others``: (node, distance, height) of the other feet, nearest first, and ``peak`` (N): its largest vertical
    force (NaN: not known)."""

    plate: str
    strike: float | None
    off: float | None
    foot: str
    distance: float
    height: float
    others: tuple[tuple[str, float, float], ...] = ()
    peak: float = float("nan")


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


def _foot_samples(lab: LabMarkers, labels, t, P, axes) -> tuple[np.ndarray, np.ndarray]:
    """(across, up) (k,) m: the distance across the floor of the foot's (markers ``labels``) nearest marker from the
    centres of pressure P (k, 3) m at the times t (k,) s, and its lowest marker's height above them; inf where its
    markers are missing."""
    X = np.empty((t.size, len(labels), 3))  # the markers at the plate's times
    for j, lb in enumerate(labels):
        X[:, j] = np.column_stack([np.interp(t, lab.t, c) for c in lab.marker(lb).T])
    d = X - P[:, None, :]
    across, up = np.linalg.norm(d @ axes[:2].T, axis=2), d @ axes[2]
    return tuple(np.where(np.isfinite(v), v, np.inf).min(axis=1) for v in (across, up))


def _foot_distance(across: np.ndarray, up: np.ndarray, w: np.ndarray) -> tuple[float, float]:
    """(distance, height) m of a foot from :func:`_foot_samples`' (across, up), means weighted by w (k,) N; inf
    where its markers are missing throughout."""
    ok = np.isfinite(across)
    if not ok.any():
        return np.inf, np.inf
    return float(np.average(across[ok], weights=w[ok])), float(np.average(up[ok], weights=w[ok]))


#: m: a centre of pressure lies within a foot's outline, near its markers (heel, toe, the metatarsals'): measured
#: over each contact's samples loaded above a quarter of its peak, at most 0.064-0.070 m from the nearest of the
#: foot's on Hamner's run and 0.11 m on the Rajagopal walk; with the other foot on the plate too (the right stance
#: and the left's first 0.1 s on one plate) 0.25 m, and a treadmill's single plate 0.48 m (the centre of pressure
#: between the feet, nearer the other over 41 % of the load).
MAX_COP_FROM_FOOT = 0.2


def _one_foot(p: str, a, b, foot: str, each: dict, t: np.ndarray, fv: np.ndarray, max_height: float) -> None:
    """ValueError in one line where the plate ``p``'s (the file and the plate, as said) contact (a, b) s given to
    ``foot`` carries another foot at once: a sample loaded above a quarter of the contact's peak (and 20 N) whose
    centre of pressure lies more than :data:`MAX_COP_FROM_FOOT` across the floor from ``foot``'s nearest marker
    (where one is seen) and nearer another foot's, that foot within ``max_height`` m above it (``each``: node ->
    :func:`_foot_samples`' (across, up) at the times t (k,) s, vertical force fv (k,) N). Its load is the two feet's
    together, which no nearest foot may share out."""
    across = each[foot][0]
    big = fv > max(MIN_PLATE_FORCE, 0.25 * float(fv.max()))
    for n, (o_across, o_up) in each.items():
        both = big & np.isfinite(across) & (across > MAX_COP_FROM_FOOT) & (o_across < across) & (o_up <= max_height)
        if n != foot and both.any():
            i = int(np.argmax(np.where(both, across, -np.inf)))
            share = 100.0 * fv[np.isfinite(across) & (o_across < across)].sum() / fv.sum()
            raise ValueError(
                f"{p}, contact {span_text(a, b)}: its centre of pressure lies {across[i]:.2f} m across the floor "
                f"from {foot}'s nearest marker at t = {t[i]:.3f} s ({fv[i]:.0f} N; a foot's within "
                f"{MAX_COP_FROM_FOOT:g} m), nearer {n}'s ({o_across[i]:.2f} m; over {share:.0f} % of the contact's "
                f"load): both feet on the plate at once (a treadmill's single plate, or a double support on one "
                "plate): its load is theirs together and cannot go to one foot; give each foot its own plate"
            )


def _unloaded(p: str, t: np.ndarray, fv: np.ndarray, threshold: float, min_duration: float) -> None:
    """ValueError in one line where the plate ``p``'s (the file and the plate, as said) unloaded reading (its vertical
    force fv (n,) N at times t (n,) s under :data:`casflex.lab.plate_checks.MAX_PULL` and ``min_duration`` s from any
    sample above it: away from a stance's edges), median plus three robust standard deviations (1.4826 x the median
    absolute deviation), reaches ``threshold`` N: noise or an offset around the level a contact starts at makes its
    strikes and offs chatter (Hamner's run with its right plate reading 20 +- 5 N unloaded: a strike 56 ms early, a
    55 ms contact after a stance). At least 20 such samples, else not checked (a plate loaded throughout)."""
    from casflex.lab.plate_checks import MAX_PULL

    high = t[fv > MAX_PULL]
    far = fv <= MAX_PULL
    if high.size:
        k = np.clip(np.searchsorted(high, t), 1, high.size - 1) if high.size > 1 else np.zeros(t.size, dtype=int)
        near = np.minimum(np.abs(t - high[k]), np.abs(t - high[np.maximum(k - 1, 0)]))
        far &= near > min_duration
    if far.sum() < 20:
        return
    level = float(np.median(fv[far]))
    spread = 1.4826 * float(np.median(np.abs(fv[far] - level)))
    if level + 3.0 * spread >= threshold:
        i = int(np.flatnonzero(far)[np.argmax(fv[far])])
        raise ValueError(f"{p}: unloaded it reads {level:.1f} +- {spread:.1f} N (median and robust standard "
                         f"deviation of its {int(far.sum())} samples under {MAX_PULL:g} N away from its stances; up to "
                         f"{fv[i]:.0f} N at t = {t[i]:.3f} s): within reach of the {threshold:g} N a contact starts "
                         "at, its strikes and offs would chatter; zero the plate (subtract its unloaded reading) or "
                         "filter its noise")


def _plate_spans(p: str, t: np.ndarray, fv: np.ndarray, threshold: float, min_duration: float
                 ) -> list[tuple[float | None, float | None]]:
    """The contacts of the plate ``p`` (the file and the plate, as said; vertical force fv (n,) N at times t (n,) s,
    above ``threshold``; module docstring) in time order. One shorter than ``min_duration`` s is dropped where it
    never exceeds :data:`casflex.lab.plate_checks.MAX_PULL` (100 N: a noise's level); above it, it is kept at the
    record's start or end (a stance the record cuts: its load goes to its own foot, not to the plate's next) and
    refused in one line elsewhere (a foot grazing the plate, too loaded for noise: its load would go to a foot in
    swing). A plate whose unloaded reading reaches the threshold is refused (:func:`_unloaded`) where it carries a
    stance (above 100 N): an unused plate's offset changes no contact of a foot."""
    from casflex.lab.plate_checks import MAX_PULL

    ok = np.isfinite(fv)
    t, fv = t[ok], fv[ok]
    if fv.max(initial=-np.inf) > MAX_PULL:  # a plate no foot steps on (an offset, noise) is left as it was
        _unloaded(p, t, fv, threshold, min_duration)
    out = []
    for a, b in contacts(t, fv, threshold, 0.0):
        lo, hi = (t[0] if a is None else a), (t[-1] if b is None else b)
        peak = float(fv[(t >= lo) & (t <= hi)].max(initial=-np.inf))
        if hi - lo >= min_duration or (a is None or b is None) and peak > MAX_PULL:
            out.append((a, b))
        elif peak > MAX_PULL:
            raise ValueError(f"{p}: a contact of {1e3 * (b - a):.0f} ms at t = {span_text(a, b)} peaking at "
                             f"{peak:.0f} N, shorter than a stance ({min_duration:g} s) and above noise "
                             f"({MAX_PULL:g} N): a foot grazing the plate, whose load would go to another foot; cut "
                             "it from the record (set its force to 0) or give each plate its node")
    return out


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
        where = f"{table.source}: plate {p!r}" if table.source else f"plate {p!r}"
        check_plate_record(where, table.t, force, fv, weight, stance=False)
        P = np.column_stack([table.column(f"{p}force_p{a}") for a in "xyz"])
        for a, b in _plate_spans(where, table.t, fv, threshold, min_duration):
            lo, hi = (table.t[0] if a is None else a), (table.t[-1] if b is None else b)
            rows = (table.t >= lo) & (table.t <= hi) & (fv > threshold) & np.isfinite(P).all(axis=1)
            rows &= (table.t >= lab.t[0]) & (table.t <= lab.t[-1])
            if not rows.any():
                raise ValueError(f"{where}, contact {span_text(a, b)}: no centre of pressure within the markers' "
                                 f"times {lab.t[0]:g}..{lab.t[-1]:g} s")
            each = {n: _foot_samples(lab, labels, table.t[rows], P[rows], axes) for n, labels in cands.items()}
            score = sorted(((n, *_foot_distance(*each[n], fv[rows])) for n in cands), key=lambda s: s[1])
            near = [s for s in score if s[1] <= max_distance and s[2] <= max_height]
            if not near:
                raise ValueError(f"{where}, contact {span_text(a, b)}: no foot within {max_distance:g} m across the "
                                 f"floor of its centre of pressure and {max_height:g} m above it (nearest: "
                                 f"{score[0][0]}, {score[0][1]:.2f} m and {score[0][2]:.2f} m); plane {pl.x},{pl.y}"
                                 " (a foot the scene does not model, e.g. a leg's other foot: name each plate's node, "
                                 "plates={node: prefix})")
            _one_foot(where, a, b, near[0][0], each, table.t[rows], fv[rows], max_height)
            found.append(Contact(p, a, b, near[0][0], near[0][1], near[0][2],
                                 tuple(s for s in score if s is not near[0]), float(fv[rows].max())))
    return found




def plate_shares(found: list[Contact]) -> dict[tuple[str, str], tuple[tuple[float | None, float | None], ...]]:
    """(plate, foot) -> the time spans (s; None: open to the record's start or end) of the plate's samples that go
    to that foot, from :func:`plate_contacts`' contacts ``found`` (module docstring): the spans of a plate's feet
    partition its record; a plate without contacts has none."""
    out: dict[tuple[str, str], list[list[float | None]]] = {}
    for plate in dict.fromkeys(c.plate for c in found):
        mine = sorted((c for c in found if c.plate == plate), key=lambda c: -np.inf if c.strike is None else c.strike)
        lo: float | None = None
        for k, c in enumerate(mine):
            nxt = mine[k + 1] if k + 1 < len(mine) else None
            if nxt is not None and nxt.foot == c.foot:
                continue  # the same foot again: its share runs on
            hi = None if nxt is None else 0.5 * (c.off + nxt.strike)  # halfway across the unloaded gap
            out.setdefault((plate, c.foot), []).append([lo, hi])
            lo = hi
    return {k: tuple((a, b) for a, b in v) for k, v in out.items()}
