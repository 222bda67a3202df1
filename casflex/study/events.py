"""Gait events from a lab trial: foot strikes, gait cycles, the clean ones, and signals normalised to 0..100 % of a
cycle, from the plates' contacts and the foot over each (:mod:`casflex.inverse.contacts`, whose names this module
offers too). numpy only: no model is assembled.

- The plates' feet per trial (:func:`plates_of`, :func:`assign_plates`): ``{node: prefix}``, or ``{node:
  [prefixes]}`` for a foot on several plates over the trial; a plate stepped on by two feet in turn has no such
  mapping (ValueError): ``plates="auto"`` (:class:`casflex.inverse.Trial`) applies each of its contacts to its foot
  (:func:`casflex.inverse.contacts.plate_shares`), what a study does where its file names no plates.
- Cycles (:func:`gait_cycles`): a foot's strike to its next, from the strikes the lab marked in the file (a C3D's
  events: :func:`marked_strikes`) where the foot has two, else from the plates where it has two plate strikes (a
  stance straddling two plates strikes once: :func:`foot_strikes`), else from its heel marker
  (:func:`marker_strikes`), said in the report. A cycle between two plate strikes inside which the heel marker
  strikes (:func:`_one_stride`: a stride off the plates) is left out and said; so is one between two marked strikes
  (a strike the lab did not mark).
- A clean cycle (:func:`clean_cycles`): its stance wholly on plates applied to the foot (one, or two it straddles:
  their wrenches are summed), as labs take kinetics only from such cycles: a cycle whose stance is off every plate
  (its strikes from the heel marker), on a plate not applied to the foot, or on a plate another foot shares at the
  time, has loads below the hip without the foot's ground reaction (Hamner's right ankle: a peak of -0.78 N m/kg
  averaged with such a cycle, -1.54 from the clean).
  A stance peaking under half the body's weight (:data:`MIN_STANCE_PEAK`; the model's mass x g: lenient for a
  model of part of the body) is not wholly on its plates (a foot on a plate's edge, its heel or toes on the floor):
  a stance bears the body's weight at least once, 1-1.3 body weights walking, 2-3 running (measured: Hamner's run
  2.25-2.38, the Rajagopal walk 1.09-1.13; walking2.c3d 4.56 times its right leg's model); NaN peaks (contacts made
  by hand) are not checked.
- The feet that walk (:func:`ground_feet`): the feet whose markers come down to the floor (a wrist's never do); a
  foot among them that touches no plate has no kinetic cycle (its leg's loads are not the other foot's).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from casflex.inverse.contacts import (
    AUTO,
    Contact,
    _plane,
    below,
    contacts,
    feet,
    plate_contacts,
    plate_prefixes,
    plate_shares,
    read_trial,
    span_text,
    tree_walk,
    vertical_force,
)
from casflex.lab.c3d import MIN_PLATE_FORCE
from casflex.lab.filtering import _plate_columns
from casflex.lab.plane import Plane
from casflex.lab.tables import LabMarkers, increasing_times

__all__ = ["Contact", "contacts", "vertical_force", "tree_walk", "below", "feet", "plate_contacts", "assign_plates",
           "plates_of", "marked_strikes", "swing_phases", "read_trial", "plate_prefixes", "foot_strikes",
           "marker_strikes", "cycles", "gait_cycles", "clean_cycles", "ground_feet", "normalise", "plate_shares",
           "AUTO"]


def _times(ts) -> str:
    return ", ".join(f"{x:.3f}" for x in ts) or "-"


def assign_plates(scene, markers, grf=None, plane: Plane | str = "X,Y", prefixes=None, **options
                  ) -> tuple[dict[str, str], list[str]]:
    """({node: prefix} for :func:`casflex.inverse.inverse_dynamics`' ``plates``, report lines): each plate
    under the foot over all its contacts (:func:`plate_contacts`, whose ``options`` these are; :func:`plates_of`)."""
    lab, table = read_trial(markers, grf)
    prefixes = [_plate_columns(table, p) for p in prefixes] if prefixes else plate_prefixes(table)
    found = plate_contacts(scene, lab, table, plane, prefixes, **options)
    return plates_of(found, prefixes, options.get("threshold", MIN_PLATE_FORCE))


def plates_of(found: list[Contact], prefixes: list[str], threshold: float = MIN_PLATE_FORCE
              ) -> tuple[dict[str, str | list[str]], list[str]]:
    """({node: prefix, or [prefixes] for a foot on several plates}, report lines) from :func:`plate_contacts`'
    contacts ``found`` of the plates ``prefixes`` (above ``threshold`` N); a plate without contacts is left out and
    said. ValueError in one line for a plate stepped on by two feet: it has no node for the whole trial (module
    docstring)."""
    plates: dict[str, list[str]] = {}
    lines = []
    for p in prefixes:
        mine = [c for c in found if c.plate == p]
        if not mine:
            lines.append(f"plate {p!r}: no contact above {threshold:g} N: left out")
            continue
        by = {c.foot: [span_text(d.strike, d.off) for d in mine if d.foot == c.foot] for c in mine}
        if len(by) > 1:
            raise ValueError(f"plate {p!r} is stepped on by " + " and ".join(f"{n} ({', '.join(s)})" for n, s in
                             by.items()) + ": no one node takes it over the trial; give plates=\"auto\" (each "
                             "contact applied to its foot)")
        node = mine[0].foot
        plates.setdefault(node, []).append(p)
        lines.append(_plate_line(p, node, mine, by[node]))
    return {n: ps[0] if len(ps) == 1 else ps for n, ps in plates.items()}, lines


def _plate_line(p: str, node: str, mine: list[Contact], spans: list[str]) -> str:
    """The report's line of the plate ``p``'s contacts ``mine`` with the foot ``node`` (their ``spans``)."""
    nxt = min((o for c in mine for o in c.others), key=lambda o: o[1], default=None)
    return (f"plate {p!r} -> {node}: {len(mine)} contact(s) {', '.join(spans)}; its markers within "
            f"{max(c.distance for c in mine):.3f} m of the centre of pressure across the floor and "
            f"{max(c.height for c in mine):.3f} m above it" + (
                f"; next: {nxt[0]}, {nxt[1]:.2f} m and {nxt[2]:.2f} m" if nxt else ""))


def contact_lines(found: list[Contact], prefixes: list[str], threshold: float = MIN_PLATE_FORCE) -> list[str]:
    """The report's lines of ``plates="auto"``: for each plate ``prefixes``, each foot and its contacts on it (a
    plate without contacts: left out)."""
    lines = []
    for p in prefixes:
        mine = [c for c in found if c.plate == p]
        if not mine:
            lines.append(f"plate {p!r}: no contact above {threshold:g} N: left out")
        for foot in dict.fromkeys(c.foot for c in mine):
            theirs = [c for c in mine if c.foot == foot]
            lines.append(_plate_line(p, foot, theirs, [span_text(c.strike, c.off) for c in theirs]))
    return lines


def swing_phases(found: list[Contact], scene, lab: LabMarkers, node: str, spans: list[tuple[float, float]]
                 ) -> list[tuple[float, float]]:
    """The swing phases (s) of the foot ``node`` within its gait cycles ``spans``: each foot off (the lab's marked
    "Foot Off" on the foot's side, else its plates' offs) to the cycle's end, the next strike."""
    side = _side(node, feet(scene).get(node, ()))
    offs = [t for cx, lb, t in lab.events if cx == side and lb.lower() == "foot off"] if side else []
    offs = offs or [c.off for c in found if c.foot == node and c.off is not None]
    return [(off, c1) for c0, c1 in spans for off in sorted(offs) if c0 < off < c1]


def _stances(found: list[Contact], node: str) -> list[tuple[float | None, float | None, list[Contact]]]:
    """The stances of the foot ``node``: its contacts ``found`` merged where they overlap in time (a stance
    straddling two plates), (strike, off, contacts) in time order; None: at the record's start or end."""
    lo = lambda c: -np.inf if c.strike is None else c.strike  # noqa: E731
    out: list[list] = []
    for c in sorted((c for c in found if c.foot == node), key=lo):
        if out and (out[-1][1] is None or lo(c) < out[-1][1]):  # it starts before the stance so far ends
            out[-1][1] = None if c.off is None else max(out[-1][1], c.off)
            out[-1][2].append(c)
        else:
            out.append([c.strike, c.off, [c]])
    return [(a, b, cs) for a, b, cs in out]


def foot_strikes(found: list[Contact]) -> dict[str, list[float]]:
    """node -> its plate strikes (s, increasing) from :func:`plate_contacts`' contacts: each stance's first
    (:func:`_stances`: a stance straddling two plates strikes once; one loaded at the record's start gives none)."""
    return {n: [a for a, _, _ in _stances(found, n) if a is not None] for n in dict.fromkeys(c.foot for c in found)}


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
        if label and not how.startswith(label):  # a strike off the plates or not marked between two: two strides
            out[node], dropped = _one_stride(out[node], marker_strikes(lab.t, lab.marker(label) @ up, lift))
            why = "a stride off the plates" if s is plate else "a strike not marked"
            said += "".join(f"; {a:.3f}-{b:.3f} s left out: {label} strikes at {m:.3f} s inside it ({why})"
                            for a, b, m in dropped)
        lines.append(f"{node}: {len(out[node])} cycle(s) from {how} strikes at {_times(s)} s{said}")
    return out, lines


def _one_stride(spans: list[tuple[float, float]], heel: list[float]
                ) -> tuple[list[tuple[float, float]], list[tuple[float, float, float]]]:
    """(the cycles ``spans`` (s) that hold one stride, [(t0, t1, the heel's strike inside)] those that hold two): a
    cycle between two plate strikes inside which the heel marker strikes (:func:`marker_strikes`: -4 to +21 ms from
    the plates' on Hamner's run) farther than a quarter of the cycle from both its ends is two strides, the one
    between them struck off every plate; normalised as one cycle it would be a wrong curve."""
    keep, dropped = [], []
    for a, b in spans:
        inner = [m for m in heel if a + 0.25 * (b - a) < m < b - 0.25 * (b - a)]
        (dropped.append((a, b, inner[0])) if inner else keep.append((a, b)))
    return keep, dropped


#: x W: a stance wholly on plates peaks above half the body's weight (module docstring)
MIN_STANCE_PEAK = 0.5


def clean_cycles(found: list[Contact], node: str, spans: list[tuple[float, float]],
                 plate: str | Sequence[str] | None, slack: float = 0.05, weight: float = 0.0
                 ) -> list[tuple[bool, str]]:
    """(clean, why) for each gait cycle (t0, t1) s in ``spans`` of the foot ``node`` (module docstring). ``plate``:
    what inverse dynamics applies to the foot: a plate's prefix or several (over the whole trial), None (none), or
    :data:`AUTO` (each contact to the foot over it). Clean where a stance of the foot (its contacts ``found``,
    :func:`plate_contacts`, merged where they overlap: :func:`_stances`) strikes within ``slack`` s of t0 (the heel
    marker's strikes are -4 to +21 ms from the plates' on Hamner's trial) and comes off before t1, every contact
    of it on a plate applied to the foot, and no other foot on those plates (or on a plate applied to this foot)
    during it, and (``weight`` N, the body's; 0: not checked) its contacts' peaks summed above
    :data:`MIN_STANCE_PEAK` x ``weight``; ``why`` says what is wrong, or the stance's span and plates."""
    auto = isinstance(plate, str) and plate == AUTO
    applied = set() if plate is None or auto else {plate} if isinstance(plate, str) else set(plate)
    stances = _stances(found, node)
    return [_clean(found, node, stances, t0, t1, auto, applied, slack, weight) for t0, t1 in spans]


def _clean(found, node, stances, t0, t1, auto, applied, slack, weight=0.0) -> tuple[bool, str]:
    """:func:`clean_cycles` of one cycle (t0, t1) s."""
    def on(cs) -> str:
        return " and ".join(repr(p) for p in dict.fromkeys(c.plate for c in cs))

    if not auto and not applied:
        return False, "no plate is applied to it (the study file's plates)"
    which = "a plate" if auto else f"its plate {on([Contact(p, None, None, node, 0, 0) for p in sorted(applied)])}"
    st = next((s for s in stances if s[0] is not None and abs(s[0] - t0) <= slack), None)
    if st is None:
        near = [s for s in stances if (-np.inf if s[0] is None else s[0]) < (t0 + t1) / 2  # in its stance
                and (np.inf if s[1] is None else s[1]) > t0]
        said = f" (its contact {span_text(near[0][0], near[0][1])} on {on(near[0][2])})" if near else \
            " (the foot off every plate)"
        return False, f"no strike on {which} within {slack:g} s of {t0:.3f} s{said}"
    strike, off, cs = st
    if off is None or off > t1:
        return False, f"its stance on {on(cs)} from {strike:.3f} s does not end within the cycle"
    for c in cs:
        if not auto and c.plate not in applied:
            return False, (f"{node} on {c.plate!r} {span_text(c.strike, c.off)} during its stance "
                           f"{span_text(strike, off)}: not applied to it")
    plates = {c.plate for c in cs} | applied
    also = [c for c in found if c.foot != node and c.plate in plates
            and (c.strike is None or c.strike < off) and (c.off is None or c.off > strike)]
    if also:
        c = also[0]
        return False, f"{c.foot} on {c.plate!r} {span_text(c.strike, c.off)} during its stance on {on(cs)} " \
                      f"{span_text(strike, off)}"
    peak = sum(c.peak for c in cs)  # of a stance straddling plates, at least its peak
    if weight > 0 and peak < MIN_STANCE_PEAK * weight:
        return False, (f"its stance on {on(cs)} {span_text(strike, off)} peaks at {peak:.0f} N, {peak / weight:.2f} of "
                       f"the body's weight (a stance wholly on plates, above {MIN_STANCE_PEAK:g}): the foot partly off "
                       "the plate (on its edge)")
    return True, f"stance on {on(cs)} {span_text(strike, off)}"


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
