"""Force plates as loads on a segment: force, centre of pressure and free moment, in the model's plane.

A plate's columns follow OpenSim's ground-reaction files: ``<prefix>force_v{x,y,z}`` (N),
``<prefix>force_p{x,y,z}`` (m, the centre of pressure) and ``<prefix>torque_{x,y,z}`` (N m, the free
moment), e.g. prefix ``ground_`` for the first plate and ``1_ground_`` for the second.

In the plane (:class:`casflex.lab.Plane`, model x and y from two lab axes, seen from the normal n =
x cross y) the plate acts by the force F_plane = (F . e_x, F . e_y) and the moment about the lab's
origin M_o = n . (p x F + T), both linear in the data: they, not the centre of pressure (which is
undefined where the force vanishes and wild where it is small), are what is filtered. On the node
``node`` that carries the contacting segment, the equivalent load is F_plane at the node and the
moment M_o - (x_node x F_plane) about it: exact for a rigid segment whatever the point of contact.

What the table does not give is never taken as zero force (:func:`plate_from_table`): a sample that is
not a number is missing; a gap of at most :data:`MAX_PLATE_GAP` samples and :data:`MAX_PLATE_GAP_S`
seconds is filled by a cubic spline through the force and the moment and reported, a longer one refused
in one line; a table that does not cover the trial's window is refused (another trial's file, a clock
offset), and the plate is never evaluated outside its samples (:meth:`Plate.at`).

A plate is checked against the body (:mod:`casflex.lab.plate_checks`): its unfiltered record in
:func:`plate_from_table` (it pushes, carries a stance, holds no single-sample spike; a window it carries no
load in is said), its line of force and its surface against its node's fitted place in :func:`plates_under_feet`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from casflex.lab import LabTable, Plane
from casflex.lab.c3d import MIN_PLATE_FORCE
from casflex.lab.filtering import plate_wrench
from casflex.lab.lowpass import check_cutoff, even_times, lowpass, runs
from casflex.lab.plate_checks import across_plane, check_plate_record, window_load

__all__ = ["Plate", "plate_from_table", "plate_loads", "plates_under_feet", "model_weight", "MAX_PLATE_GAP",
           "MAX_PLATE_GAP_S"]

#: samples: the longest run of missing plate samples filled (the markers' :data:`casflex.lab.filtering.MAX_GAP`).
MAX_PLATE_GAP = 10
#: s: and at most this long: a heel strike's impact peak rises in 20-30 ms, which a spline over a longer
#: gap would not know (at 60 Hz this fills one missing sample, at 1000 Hz ten).
MAX_PLATE_GAP_S = 0.02


@dataclass(frozen=True)
class Plate:
    """One plate acting on ``node``: t (n,) s, force (n, 2) N in the plane, moment (n,) N m about the
    lab's origin (module docstring); ``name``: the columns' prefix; ``notes``: what was done to its samples
    (gaps filled, unloaded samples), a line each; ``floor`` (m): the height of its surface along the model's up in
    the plane, the median height of its centres of pressure where loaded (None: not known), against which the node
    it acts on is checked (:func:`casflex.lab.plate_checks.check_bearing`)."""

    name: str
    node: str
    t: np.ndarray
    force: np.ndarray
    moment: np.ndarray
    notes: tuple[str, ...] = ()
    source: str = ""  # the file and the plate, as messages name them
    floor: float | None = None  # m: its surface's height along the model's up in the plane (None: not known)
    #: m, (n,): its centre of pressure's height along the model's up at t as the table writes it (unfiltered; NaN
    #: where unloaded), checked against the foot's lowest point (None: not known)
    heights: np.ndarray | None = None

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(force (k, 2), moment (k,)) at times t (s), linear between samples. ValueError for a time more than
        half a sample outside the table: the plate's force there is unknown, not zero."""
        t = np.asarray(t, dtype=float)
        half = 0.5 * (self.t[-1] - self.t[0]) / max(self.t.size - 1, 1)
        if t.size and (t.min() < self.t[0] - half or t.max() > self.t[-1] + half):
            bad = t.min() if t.min() < self.t[0] - half else t.max()
            raise ValueError(f"plate {self.name!r}: no samples at t = {bad:g} s (its table covers {self.t[0]:g}.."
                             f"{self.t[-1]:g} s)")
        f = np.column_stack([np.interp(t, self.t, self.force[:, i]) for i in range(2)])
        return f, np.interp(t, self.t, self.moment)


def _covered(t: np.ndarray, ok: np.ndarray, window: tuple[float, float], where: str, written: np.ndarray,
             trial: str) -> slice:
    """The rows of the plate's samples (at the even times t, ``written`` so in the file) to use: the stretch
    between its first and last defined samples (``ok``), which must cover ``window`` (s) to within half a
    sample. ValueError naming the plate otherwise."""
    half = 0.5 * (t[-1] - t[0]) / max(t.size - 1, 1)
    lo, hi = window
    if t[0] > hi or t[-1] < lo:
        raise ValueError(f"{where}: its samples span t = {written[0]:g}..{written[-1]:g} s, the window of {trial} "
                         f"{lo:g}..{hi:g} s: they do not overlap (another trial's file, or a clock offset?)")
    if not ok.any():
        raise ValueError(f"{where}: no sample of its force is a number")
    a, b = int(np.argmax(ok)), int(t.size - np.argmax(ok[::-1]))
    if t[a] - half > lo or t[b - 1] + half < hi:
        raise ValueError(f"{where}: its force is recorded over t = {written[a]:g}..{written[b - 1]:g} s only, not the "
                         f"whole window {lo:g}..{hi:g} s of {trial}; set --t-start/--t-end (t_start, t_end) within it")
    return slice(a, b)


def _fill(t: np.ndarray, F: np.ndarray, M: np.ndarray, where: str, written: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """F (n, 3), M (n, 3) at the even times t (n,) with their interior gaps (NaN rows) filled by a cubic spline
    through the samples around them (module docstring); ValueError naming the plate and the gap's times (as
    ``written`` in the file) for a longer gap."""
    missing = ~np.isfinite(F).all(axis=1)
    notes: list[str] = []
    if not missing.any():
        return F, M, notes
    from scipy.interpolate import CubicSpline  # here: its import alone costs 0.5 s

    gaps, h = runs(missing), (t[-1] - t[0]) / (t.size - 1)
    for s, e in gaps:
        if e - s > MAX_PLATE_GAP or (e - s) * h > MAX_PLATE_GAP_S * (1 + 1e-6):
            raise ValueError(f"{where}: {e - s} samples are not numbers from t = {written[s]:g} to "
                             f"{written[e - 1]:g} s, a gap longer than a spline may fill (at most {MAX_PLATE_GAP} "
                             f"samples and {1e3 * MAX_PLATE_GAP_S:g} ms); fill or cut it in the file")
    wrench = np.hstack([F, M])
    ok = ~missing
    wrench[missing] = CubicSpline(t[ok], wrench[ok], axis=0)(t[missing])
    for s, e in gaps:
        f = np.linalg.norm(wrench[s:e, :3], axis=1).max()
        when = f"1 sample at t = {written[s]:g} s" if e - s == 1 else \
            f"{e - s} samples at t = {written[s]:g}..{written[e - 1]:g} s"
        notes.append(f"{where}: {when} not a number, filled by a cubic spline (a force up to {f:.0f} N there)")
    return wrench[:, :3], wrench[:, 3:], notes


def plate_from_table(table: LabTable, prefix: str, node: str, plane: Plane, cutoff: float | None, *,
                     window: tuple[float, float] | None = None, rate: float | None = None, trial: str = "the trial",
                     weight: np.ndarray | None = None,
                     spans: tuple[tuple[float | None, float | None], ...] | None = None) -> Plate:
    """The plate ``prefix`` of ``table`` on ``node``, in ``plane``, filtered at ``cutoff`` Hz (None: as
    recorded). The moment about the lab's origin from the table's ``<prefix>moment_{x,y,z}`` where it has
    them (C3D plates, :func:`casflex.lab.read_c3d`), else p x F + T (:func:`casflex.lab.filtering.plate_wrench`:
    forces and centres of pressure no body produces refused). ``window`` (s): the trial's times, which the
    table must cover. ``rate`` (Hz): the samples' rate where the table's times round it (a .mot at the markers'
    rate, its times written to the ms: their own slope is off by some 1e-4 and the samples would be taken
    between the frames); the table's header ``rate`` (C3D) otherwise. Missing samples as the module docstring
    says; the plate's ``notes`` say what was done. ``weight`` (N, (2,)): the model's mass x gravity in the plane:
    its record, unfiltered, is checked against the body (:func:`casflex.lab.plate_checks.check_plate_record`: it
    pushes, carries a stance, holds no single-sample spike) and a window it carries no load in is said. ``spans``
    (s, None: open): ``node`` takes the plate's samples in these spans [start, end) only, the others taken as no
    load before filtering (the foot's share of a plate that carries two feet in turn,
    :func:`casflex.inverse.contacts.plate_shares`: the shares' loads sum to the whole plate's); None: every sample."""
    from casflex.lab.filtering import _plate_columns

    where = f"{table.source}: plate {_plate_columns(table, prefix)!r}"
    F, M3, unloaded = plate_wrench(table, prefix)
    hint = rate if rate is not None and np.isfinite(rate) else table.header.get("rate")
    t = even_times(table.t, float(hint) if hint else None)
    ok = np.isfinite(F).all(axis=1)
    rows = _covered(t, ok, window, where, table.t, trial) if window is not None else slice(None)
    t, F, M3, unloaded, written = t[rows], F[rows], M3[rows], unloaded[rows], table.t[rows]
    if window is None and not np.isfinite(F[[0, -1]]).all():
        raise ValueError(f"{where}: its first or last sample is not a number")
    F, M3, notes = _fill(t, F, M3, where, written)
    whole = F  # the record is checked whole (below), a foot's share of it applied
    if spans is not None:
        mine = np.zeros(t.size, dtype=bool)
        for a, b in spans:
            mine |= (written >= (-np.inf if a is None else a)) & (written < (np.inf if b is None else b))
        F, M3 = np.where(mine[:, None], F, 0.0), np.where(mine[:, None], M3, 0.0)
    if unloaded.any():
        notes.append(f"{where}: {int(unloaded.sum())} samples of a force under {MIN_PLATE_FORCE:g} N without a "
                     "centre of pressure, taken as no load")
    E = plane.matrix
    n = np.cross(E[0], E[1])
    force, moment = F @ E.T, M3 @ n
    if weight is not None and np.linalg.norm(weight) > 0:  # the vertical: against the model's gravity
        fv, W = (whole @ E.T) @ (-np.asarray(weight) / np.linalg.norm(weight)), float(np.linalg.norm(weight))
    else:
        fv, W = None, 0.0
    check_plate_record(where, written, whole, fv, W, _normal(table, prefix, E, weight))
    floor, heights = _floor(table, prefix, rows, E, fv, weight)
    if fv is not None:
        across = across_plane(where, written, whole, E, -np.asarray(weight) / W)
        notes += [across] if across else []
    empty = window_load(where, t, force, weight, window) if window is not None else None
    notes += [empty] if empty else []
    check_cutoff(cutoff, t, f"{where}'s samples")
    both = lowpass(t, np.column_stack([force, moment]), cutoff, what=where)
    return Plate(prefix, node, t, both[:, :2], both[:, 2], tuple(notes), where, floor, heights)


def _floor(table: LabTable, prefix: str, rows: slice, E: np.ndarray, fv: np.ndarray | None,
           weight: np.ndarray | None) -> tuple[float | None, np.ndarray | None]:
    """(m: the height of the plate's surface along the model's up in the plane (lab axes ``E`` (2, 3)): the median
    height of its centres of pressure (the table's ``<prefix>force_p{x,y,z}``, unfiltered) where its vertical
    force ``fv`` (N, the table's ``rows``) exceeds 20 N; m, (n,): those heights, NaN elsewhere); (None, None) where
    the table or the weight gives none."""
    from casflex.lab.checks import median
    from casflex.lab.filtering import _plate_columns
    from casflex.lab.plate_checks import weight_up

    p = _plate_columns(table, prefix)
    up = weight_up(weight) if weight is not None else None
    if fv is None or up is None or f"{p}force_px" not in table.names:
        return None, None
    P = np.column_stack([table.column(f"{p}force_p{a}")[rows] for a in "xyz"]).astype(float)
    with np.errstate(invalid="ignore"):
        h = (P @ E.T) @ up
        on = np.isfinite(h) & (fv > MIN_PLATE_FORCE)
    return (median(h[on]), np.where(on, h, np.nan)) if on.any() else (None, None)


def _normal(table: LabTable, prefix: str, E: np.ndarray, weight: np.ndarray | None) -> str | None:
    """A C3D plate's upward normal as its corners give it (the table's header ``up``, one a plate) where it points
    down, against the model's gravity (lab axes ``E`` (2, 3) of the plane); else None."""
    from casflex.lab.filtering import _plate_columns

    ups = str(table.header.get("up", "")).split(",")
    if weight is None or "plates" not in table.header or not ups[0]:
        return None
    p = _plate_columns(table, prefix)
    i = 0 if p == "ground_" else int(p.split("_")[0]) if p.split("_")[0].isdigit() else -1
    if not 0 <= i < len(ups) and len(ups) != 1:
        return None
    axis = ups[i if len(ups) > 1 else 0].strip()
    u = np.zeros(3)
    u["XYZ".index(axis[-1])] = -1.0 if axis.startswith("-") else 1.0
    return axis if float(u @ E.T @ np.asarray(weight, dtype=float)) > 0 else None


def plate_loads(model, plates: list[Plate], t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The plates' generalised forces (k, n_dof) at times t (k,) with the configurations q (k, n_dof):
    each plate's force at its node's x, y rows and its moment about the node at its theta row."""
    f = np.zeros((t.size, model.n_dof))
    for pl in plates:
        i = 3 * model.node_names.index(pl.node)
        F, Mo = pl.at(t)
        f[:, i] += F[:, 0]
        f[:, i + 1] += F[:, 1]
        f[:, i + 2] += Mo - (q[:, i] * F[:, 1] - q[:, i + 1] * F[:, 0])
    return f


def model_weight(model) -> np.ndarray:
    """N, (2,): the model's weight in its plane, its total mass (bodies and beams) times its gravity."""
    from casflex.lab.plate_checks import scene_mass

    return scene_mass(model.scene) * np.asarray(model.scene.gravity, dtype=float)


def plates_under_feet(model, plates: list[Plate], t: np.ndarray, q: np.ndarray) -> None:
    """ValueError in one line for a plate whose force passes farther from its node than a centre of pressure
    under the foot can, or whose node lies higher above the plate than a foot's
    (:func:`casflex.lab.plate_checks.check_plate_foot`) over its stance, or whose force along the floor propels the
    body first and brakes it after (:func:`casflex.lab.plate_checks.check_shear`: its sign flipped), with the fitted
    configurations q (k, n_dof) at times t (k,) s: the plate under another foot, its origin wrong, or given to a
    thigh or a shank (the refusal names the nodes near its centre of pressure)."""
    from casflex.lab.plate_checks import check_cop_height, check_plate_foot, check_shear, weight_up

    weight = model_weight(model)
    nodes = {n: q[:, 3 * k:3 * k + 2] for k, n in enumerate(model.node_names)}
    up = weight_up(weight)
    body_x = np.mean([xy @ [up[1], -up[0]] for xy in nodes.values()], axis=0) if up is not None else None
    for pl in plates:
        F, Mo = pl.at(t)
        where = pl.source or f"plate {pl.name!r}"
        check_plate_foot(where, pl.node, t, F, Mo, nodes[pl.node], weight, pl.floor, nodes)
        if pl.heights is not None and up is not None:
            cop = np.interp(t, pl.t, pl.heights)  # NaN beside the unloaded samples: passed over
            check_cop_height(where, pl.node, t, F @ up, cop, _foot_low(model, pl.node, q, up))
        check_shear(where, t, F, weight, body_x)


def _foot_low(model, node: str, q: np.ndarray, up: np.ndarray) -> np.ndarray:
    """m, (k,): the height along ``up`` (2,) of the lowest of ``node`` and the markers on the rigid bodies fixed
    to it (a foot's heel and toe markers) at the configurations q (k, n_dof)."""
    i = model.node_names.index(node)
    low = q[:, 3 * i:3 * i + 2] @ up
    on = {b.name for b in model.scene.bodies if b.node == node}
    phi = q[:, 3 * i + 2] - model.q0[3 * i + 2]
    c, s = np.cos(phi), np.sin(phi)
    for m in model.scene.markers:
        if m.on in on:
            rx, ry = m.x - model.q0[3 * i], m.y - model.q0[3 * i + 1]
            xy = np.column_stack([q[:, 3 * i] + c * rx - s * ry, q[:, 3 * i + 1] + s * rx + c * ry])
            low = np.minimum(low, xy @ up)
    return low
