"""What a force plate under a foot records: it pushes, it carries about the body's weight over a stance, it lies
under its foot. A plate that contradicts it is refused in one line that names the file, the plate and what was
seen, before the loads it would make wrong are computed.

:mod:`casflex.lab.checks` refuses values no lab records (a force of 20 kN, a centre of pressure 100 m away);
the checks here take the body into account: the model's weight W (its total mass x g, N, in the model's plane;
for a model of part of the body, e.g. a pelvis and one leg, a third of the subject's, which makes the checks
that use it lenient, never strict) and, once the pose is known, the node the plate acts on. The vertical is
the model's up, against its gravity. Each limit is far from what a body does, so that a real trial never
meets it (OpenSim's Hamner running trial, whose stance peaks at 2.25 body weights, and its walking2.c3d pass):

- :data:`MAX_PULL` (N), :data:`PULL_SHARE`: a foot pushes on a plate and cannot pull it; a vertical force
  below -100 N and below -0.1 x the record's largest upward force is a sign flipped (the vertical column
  negated; a C3D plate whose corners are numbered in mirrored order, so that its normal points down) or an
  offset not zeroed. Plates that labs leave unzeroed read tens of newtons (walking2.c3d's: -14 and -20 N
  unloaded), their noise some newtons; a record filtered before export rings below zero after a stance by
  at most 3.4 % of its peak (the zero-lag Butterworth's step response; a 2 kN running stance filtered at
  6 Hz: -44 N).
- :data:`MIN_PEAK` (x W): a plate given to a foot whose vertical force never reaches a fifth of the model's
  weight over its whole record carries no stance (a stance peaks at 1-1.3 body weights walking, 2-3 running):
  forces in kN where N are read (the loads would be 1000 times too small), or a plate no foot steps on. A
  record that carries a stance but none inside the trial's window is said, not refused (:func:`window_load`:
  a window may end before the foot reaches the plate; its load there is zero, as computed).
- :data:`SPIKE` (x): a single sample standing above both its neighbours by more than twice the larger of W and
  the record's median loaded force (its stance's typical level) is a corrupted sample: a body's force rises
  over the 20-30 ms of an impact and falls again over a stance, never up by several body weights and back in
  one sample (Hamner's impact peak at 60 Hz stands 3 N above its neighbours). :data:`DROP` (x): a sample
  dropping below both its neighbours by 0.75 times that level (a sample lost, written as 0) likewise: a stance
  unloads over 50-100 ms; the dip between a runner's impact and active peaks is broader than a sample at 60 Hz
  and some half a body weight deep. In the repo's trials no sample stands above or below both its neighbours
  by more than 0.063 times the level.
- :data:`MAX_COP_DISTANCE` (m): the centre of pressure lies under the foot; the line of the plate's force
  passes within a foot's length (0.25-0.30 m) of any point of the foot (the node the plate acts on), plus the
  node's height above the sole and the fitted pose's error: 0.4 m. Farther, over the stance (the median over
  its samples loaded above a quarter of its peak), the plate is under the other foot, or its origin (a C3D
  plate's corners, a centre of pressure in another frame) is wrong. The line is the force's through its centre
  of pressure (the node's distance to it, |M_node| / |F| in the plane): for a force near vertical, the
  distance across the floor, whatever the node's height. Measured (medians): Hamner's stride, the ankle 0.11 m
  (0.00-0.17 over the stance); its whole trial, calcn_r 0.13 m and calcn_l 0.19 m; walking2.c3d's right ankle
  0.12 m; a plate given to the other foot, 0.54 m (walking2) and 0.55 m (Hamner). :data:`FAR_SHARE`: the line
  passing farther than 0.4 m at more than a tenth of the stance's samples is refused too, whatever the median: the
  plate carries another foot at once (a treadmill's single plate under both feet given to one: the Rajagopal
  walk's, 20 % and 37 % of the samples, up to 0.59 and 0.74 m, medians 0.16 and 0.29 m); on the repo's trials the
  line passes at most 0.27 m from the foot's node at any sample (Hamner's whole run; its stride 0.21, the
  Rajagopal walk 0.24, walking2.c3d 0.15).
- :data:`MAX_NODE_HEIGHT` (m): the segment a plate bears on is the foot standing on it, whose node (its joint
  with the shank, a heel, the toes) lies near the floor: the node's height above the plate's surface (the median
  height of its centres of pressure where loaded, :attr:`casflex.inverse.Plate.floor`), median over the stance,
  within 0.25 m. Higher, the plate is given to a thigh or a shank (an ExternalLoads file's ``applied_to_body``
  femur_r): the line-of-force check above passes (the hip stands over the foot), the loads are wrong (Hamner's
  run with its right plate on femur_r: the hip contact force 4.7 body weights for 9.4; on tibia_r the ankle
  moment 5 N m for 185). The node, not the segment's nearest point: a shank reaches down to the ankle, 0.1 m
  above the floor, a thigh's node (the hip) and a shank's (the knee) do not. Measured (medians over each stance):
  calcn 0.008-0.043 m on Hamner's run (whole trial, IK and fitted), the Rajagopal walk and biomechZoo's 12
  children's straight walks (22 plates), the ankle 0.070 m (Hamner's stride) and 0.117 m (walking2.c3d), the
  toes 0.006-0.014 m; a knee 0.48-0.50 m, a hip 0.88 m (Hamner, walking2); a child's knee (some 0.28 of its
  height) from 1 m tall up. Above 0.25 m: 2.1 times the highest foot, half the lowest knee measured. Refused only
  where the node lies as high above the lowest node near the line of force too (the foot under the thigh): a plate
  in a stair's step whose centres of pressure a table writes at the floor's height, or a model without feet
  (a plate under a residual limb, a knee kneeling), is taken.
- :data:`MAX_COP_ABOVE` (m): a centre of pressure lies on the surface the foot stands on (a floor, a ramp, a
  step), never above the foot: over each stance (its samples loaded above a quarter of the record's peak), the
  median height of the centre of pressure as the table writes it above the lowest of the foot's node and its
  markers (heel and toe markers sit 2-6 cm above the sole) within 0.1 m. Higher, the table's vertical column
  holds another coordinate (a Y-up file's py and pz swapped: the sideways position, 0.2 m, read as the height;
  Hamner's stride so: every moment 39 N m off). Measured (medians over each stance): 0.001-0.051 m *below* the
  lowest point on Hamner's run (calcn, toes, ankle; whole trial, stride, IK), walking2.c3d and the Rajagopal walk,
  at most 0.001 m above it at any sample; biomechZoo's 12 children's straight walks (24 stances, the lab's COP
  against the lowest of the foot's heel, toe and ankle markers as recorded) 0.019-0.032 m below; 0.1 m: a foot
  marker calibrated that low still passes the marker fit (its misfit limit). Below the foot is not refused here:
  a plate under a stair's step writes its centres of pressure at its own surface, the floor's, on the force's line
  (the loads right); metres below (mm read as m) the line of force passes metres from the foot
  (:data:`MAX_COP_DISTANCE`).
- :data:`MAX_ACROSS` (x): the planar model drops the force across its plane; in straight gait that force is a
  fraction of the force along the floor (peaks of 0.05-0.1 body weight against 0.2 walking, 0.3-0.5 running). A
  stance (a run of 4 samples and more loaded above 20 N, the record unfiltered) whose force across carries more
  impulse (the integral of its magnitude) than its force along the floor is said (:func:`across_plane`), not
  refused (a cutting or turning step carries more; :mod:`casflex.inverse.heading` refuses a turning trial): the
  fore-aft and sideways columns swapped (a Y-up file's vx and vz: Hamner's stride so, the hip moment 204 N m off)
  or the wrong plane. Measured (each stance): 0.07-0.41 on Hamner's run (whole trial and stride), 0.26 on
  walking2.c3d, 0.37-0.44 on the Rajagopal walk, 0.14-0.55 on biomechZoo's 12 children's straight walks (24
  stances; the plane's x their pelvis's travel); swapped, their inverses, 1.8-14: the limit 1 lies 1.8 times above
  the largest and below the smallest. Their walks with a 90-degree turn (the heading check refuses them): 0.54-3.2,
  15 of 22 stances above 1.
- :data:`MIN_SHEAR` (x W), :data:`MIN_TRAVEL` (m/s): a stance brakes the travelling body (its force along the floor
  against the travel) over its first half and propels it over its second; a whole stance (loaded above 20 N from
  unloaded to unloaded within the trial) that on average propels by more than 0.02 W over its first half and brakes
  by more than 0.02 W over its second, the body (its nodes' mean) travelling faster than 0.3 m/s over it, has its
  force along the floor's sign flipped (a column negated, a plate's own axes). A step starting or stopping a walk
  brakes or propels over both halves, never the other way round. Measured: the Rajagopal walk (1.23 m/s), -0.083 to
  -0.086 W then +0.077 to +0.079 W; walking2.c3d's right leg, -0.33 then +0.33 (W the leg's). Hamner's run is on a
  treadmill (the body travels at 0.04-0.10 m/s): not checked.
"""

from __future__ import annotations

import numpy as np

from casflex.lab.checks import median

__all__ = [
    "scene_mass",
    "MAX_PULL",
    "PULL_SHARE",
    "MIN_PEAK",
    "SPIKE",
    "DROP",
    "MAX_COP_DISTANCE",
    "FAR_SHARE",
    "MAX_NODE_HEIGHT",
    "check_plate_record",
    "window_load",
    "check_plate_foot",
    "check_bearing",
    "check_shear",
    "MIN_SHEAR",
    "MIN_TRAVEL",
    "check_cop_height",
    "MAX_COP_ABOVE",
    "across_plane",
    "MAX_ACROSS",
]

MAX_PULL = 100.0
PULL_SHARE = 0.1
MIN_PEAK = 0.2
SPIKE = 2.0
DROP = 0.75
MAX_COP_DISTANCE = 0.4
FAR_SHARE = 0.1
MAX_NODE_HEIGHT = 0.25
MIN_SHEAR = 0.02
MIN_TRAVEL = 0.3
MAX_COP_ABOVE = 0.1
MAX_ACROSS = 1.0
#: N: the vertical force below which a plate carries no load (the readers' limit for a centre of pressure)
_LOADED = 20.0


def weight_up(weight: np.ndarray) -> np.ndarray | None:
    """The model's up in its plane (2,), against the weight (N, (2,)); None where it has none."""
    w = np.asarray(weight, dtype=float)
    size = float(np.linalg.norm(w))
    return None if not size > 0 else -w / size


def scene_mass(scene) -> float:
    """kg: a scene's total mass, its bodies' and its beams' (rho A L)."""
    mass = sum(b.mass for b in scene.bodies)
    for b in scene.beams:
        a, c = (scene.node(n) for n in b.nodes)
        mass += b.rho * b.A * float(np.hypot(c.x - a.x, c.y - a.y))
    return float(mass)


def check_plate_record(
    where: str,
    t: np.ndarray,
    force3: np.ndarray,
    fv: np.ndarray | None,
    weight: float = 0.0,
    up_hint: str | None = None,
    stance: bool = True,
) -> None:
    """ValueError in one line (``where`` names the file and the plate) for a plate's record at times ``t`` (n,) s
    as written, its force ``force3`` (n, 3) N in the lab and ``fv`` (n,) N its vertical force (None: not known),
    unfiltered, that holds a single-sample spike (:data:`SPIKE`), pulls (:data:`MAX_PULL`) or, with ``stance``,
    carries no stance (:data:`MIN_PEAK`), module docstring; samples that are not numbers are passed over.
    ``weight`` (N): the model's (mass x g; 0: the checks that need it skipped); ``up_hint``: the plate's upward
    normal as its file gives it (a C3D plate's corners, e.g. "-Z"), said where the force pulls."""
    _spike(where, t, force3, weight)
    if fv is None or not np.isfinite(fv).any():
        return
    fv = np.where(np.isfinite(fv), fv, 0.0)
    i, k = int(np.argmin(fv)), int(np.argmax(fv))
    pull = max(MAX_PULL, PULL_SHARE * fv[k])
    if fv[i] < -pull:
        share = 100.0 * np.mean(fv < -pull)
        hint = f"; its corners give it the upward normal {up_hint}: numbered in mirrored order?" if up_hint else ""
        raise ValueError(
            f"{where}: its vertical force pulls the foot down: {fv[i]:.0f} N at t = {t[i]:g} s, below "
            f"-{pull:.0f} N at {share:.0f} % of its samples, its largest upward force {fv[k]:.0f} N "
            f"at t = {t[k]:g} s (a foot pushes on a plate and cannot pull it): a sign flipped (the "
            f"vertical column negated) or an offset not zeroed{hint}"
        )
    if stance and fv[k] < MIN_PEAK * weight:
        raise ValueError(
            f"{where}: its vertical force peaks at {fv[k]:.3g} N (t = {t[k]:g} s) over its whole "
            f"record, {100 * fv[k] / weight:.2g} % of the model's weight ({weight:.0f} N, its mass x g; a stance "
            "peaks at 1-3 times the body's): forces in kN read as N (the loads would be 1000 times too small), "
            "or a plate no foot steps on; convert its forces to N or give the foot's plate"
        )


def _spike(where: str, t: np.ndarray, force3: np.ndarray, weight: float) -> None:
    """ValueError for a sample whose force stands above both its neighbours' by :data:`SPIKE` times the larger of
    the weight (N) and the record's median loaded force, or below them by :data:`DROP` times it (module
    docstring)."""
    with np.errstate(invalid="ignore"):
        f = np.linalg.norm(force3, axis=1)
        if f.size < 3:
            return
        loaded = f[f > _LOADED]
        level = max(weight, median(loaded) if loaded.size else 0.0)
        if not level > 0:
            return
        above = f[1:-1] - np.maximum(f[:-2], f[2:])
        below = np.minimum(f[:-2], f[2:]) - f[1:-1]
    rel = np.maximum(above / SPIKE, below / DROP) / level  # 1 at the limit
    rel = np.where(np.isfinite(rel), rel, -np.inf)
    k = int(np.argmax(rel))
    if rel[k] > 1.0:
        i = k + 1
        up = above[k] / SPIKE >= below[k] / DROP
        jump, way = (above[k], "above") if up else (below[k], "below")
        raise ValueError(
            f"{where}: a single sample of {f[i]:.4g} N at t = {t[i]:g} s stands {jump:.4g} N {way} "
            f"both its neighbours' ({f[i - 1]:.4g} and {f[i + 1]:.4g} N, {t[i + 1] - t[i]:.3g} s "
            f"apart), {jump / level:.3g} times the stance's level ({level:.0f} N; the limit "
            f"{SPIKE if up else DROP:g}): no foot {'loads and unloads' if up else 'unloads and reloads'} a plate "
            "so in one sample; a corrupted sample: delete it (an empty cell is a gap, filled by a spline)"
        )


def window_load(
    where: str, t: np.ndarray, force: np.ndarray, weight: np.ndarray | None, window: tuple[float, float]
) -> str | None:
    """A line saying that the plate (its force (n, 2) N in the plane at times t (n,) s) carries no load
    (its vertical force under 20 N) inside ``window`` (s), else None: its load there is zero, as computed
    (module docstring)."""
    up = weight_up(weight) if weight is not None else None
    if up is None:
        return None
    inside = (t >= window[0] - 1e-9) & (t <= window[1] + 1e-9)
    fv = force[inside] @ up
    if fv.size and fv.max() < _LOADED:
        return (
            f"{where}: no load in the window {window[0]:g}..{window[1]:g} s (its vertical force at most "
            f"{fv.max():.3g} N): no foot steps on it there; it adds nothing"
        )
    return None


def check_plate_foot(
    where: str,
    node: str,
    t: np.ndarray,
    force: np.ndarray,
    moment: np.ndarray,
    node_xy: np.ndarray,
    weight: np.ndarray | None,
    floor: float | None = None,
    nodes: dict[str, np.ndarray] | None = None,
) -> None:
    """ValueError in one line when the line of a plate's force passes farther than :data:`MAX_COP_DISTANCE`
    from the node it acts on over its stance, or (``floor`` given: the plate's surface's height along the model's
    up, m) when that node lies higher than :data:`MAX_NODE_HEIGHT` above the surface (:func:`check_bearing`):
    force (k, 2) N and moment about the lab's origin (k,) N m in the plane, the node's position ``node_xy``
    (k, 2) m, at times t (k,) s; the stance: the samples whose vertical force exceeds a quarter of its peak and
    20 N (module docstring). ``nodes``: every node's positions (k, 2) m, to name the foot in the refusal."""
    up = weight_up(weight) if weight is not None else None
    if up is None:
        return
    fv = force @ up
    stance = fv > max(_LOADED, 0.25 * float(fv.max(initial=0.0)))
    if not stance.any():
        return
    F, x = force[stance], node_xy[stance]
    d = _line_distance(x, F, moment[stance])
    mid = median(d)
    if mid > MAX_COP_DISTANCE:
        ts = t[stance]
        raise ValueError(
            f"{where}: its force passes {mid:.2f} m from {node!r} over its stance (median of "
            f"{int(stance.sum())} samples at t = {ts[0]:g}..{ts[-1]:g} s; {d.min():.2f}..{d.max():.2f} "
            f"m): a centre of pressure lies under its foot, within a foot's length of it (the limit "
            f"is {MAX_COP_DISTANCE:g} m); the plate is under another foot, or its origin is wrong"
        )
    far = d > MAX_COP_DISTANCE
    if far.mean() > FAR_SHARE:
        i = int(np.argmax(d))
        raise ValueError(
            f"{where}: its force passes more than {MAX_COP_DISTANCE:g} m from {node!r} at {100 * far.mean():.0f} % of "
            f"its stance's {int(stance.sum())} samples (up to {d[i]:.2f} m at t = {t[stance][i]:g} s; median "
            f"{mid:.2f} m): a foot's centre of pressure lies within a foot's length of it throughout; the plate "
            "carries another foot, at once (a treadmill's single plate, both feet on it) or in turn (give each foot "
            "its own plate, or --plate auto)"
        )
    if floor is not None:
        others = {k: v[stance] for k, v in (nodes or {}).items()}
        check_bearing(where, node, t[stance], F, moment[stance], x, up, floor, others)


def _line_distance(xy: np.ndarray, force: np.ndarray, moment: np.ndarray) -> np.ndarray:
    """m, (k,): how far the line of force (force (k, 2) N, moment about the origin (k,) N m) passes from the points
    ``xy`` (k, 2) m: the moment about each point over the force."""
    return np.abs(moment - (xy[:, 0] * force[:, 1] - xy[:, 1] * force[:, 0])) / np.linalg.norm(force, axis=1)


def _cop(force: np.ndarray, moment: np.ndarray, up: np.ndarray, floor: float) -> np.ndarray:
    """m, (k, 2): where the line of force (force (k, 2) N, moment about the origin (k,) N m, its vertical force
    positive) meets the surface at the height ``floor`` (m) along ``up`` (2,): the centre of pressure."""
    across = np.array([up[1], -up[0]])  # the floor's direction: across x up = 1
    s = (moment - floor * (up[0] * force[:, 1] - up[1] * force[:, 0])) / (force @ up)
    return s[:, None] * across + floor * up


def _above_the_body(node_xy: np.ndarray, force: np.ndarray, moment: np.ndarray, up: np.ndarray,
                    nodes: dict[str, np.ndarray]) -> float:
    """m: how high the node (positions (k, 2) m) lies above the lowest of ``nodes`` whose median distance to the
    line of force (force (k, 2) N, moment about the origin (k,) N m) is within :data:`MAX_COP_DISTANCE`, medians
    over the samples: the foot under a thigh, whatever the surface's height a table gives (a plate in a stair's
    step whose centres of pressure are written at the floor's). Where the body has nothing lower (a model without
    feet), 0."""
    low = median(node_xy @ up)
    for xy in nodes.values():
        if median(_line_distance(xy, force, moment)) <= MAX_COP_DISTANCE:
            low = min(low, median(xy @ up))
    return median(node_xy @ up) - low


def check_bearing(
    where: str,
    node: str,
    t: np.ndarray,
    force: np.ndarray,
    moment: np.ndarray,
    node_xy: np.ndarray,
    up: np.ndarray,
    floor: float,
    nodes: dict[str, np.ndarray],
) -> None:
    """ValueError in one line when the node a plate acts on lies higher than :data:`MAX_NODE_HEIGHT` above the
    plate's surface (at ``floor`` m along ``up`` (2,)) over its stance (the median over its samples at times t (k,)
    s; force (k, 2) N, moment about the origin (k,) N m, the node's positions (k, 2) m) and as high above the
    lowest node of ``nodes`` near the line of force (:func:`_above_the_body`: a surface whose height the table
    gives wrong refuses nothing): the plate given to a thigh or a shank, not to the foot on it. The refusal names
    the nodes of ``nodes`` (name -> (k, 2) m) that could bear it: those within :data:`MAX_NODE_HEIGHT` of the
    surface and :data:`MAX_COP_DISTANCE` of the centre of pressure, the nearest first (module docstring)."""
    high = node_xy @ up - floor
    mid = median(high)
    if not mid > MAX_NODE_HEIGHT or not _above_the_body(node_xy, force, moment, up, nodes) > MAX_NODE_HEIGHT:
        return
    cop = _cop(force, moment, up, floor)
    near = []
    for name, xy in nodes.items():
        h, d = median(xy @ up - floor), median(np.linalg.norm(xy - cop, axis=1))
        if h <= MAX_NODE_HEIGHT and d <= MAX_COP_DISTANCE:
            near.append((d, name, h))
    feet = ", ".join(f"{n!r} ({h:.2f} m high)" for _, n, h in sorted(near)[:3])
    raise ValueError(
        f"{where}: it is applied to {node!r}, whose node lies {mid:.2f} m above the plate's surface over its stance "
        f"(median of {t.size} samples at t = {t[0]:g}..{t[-1]:g} s; {high.min():.2f}..{high.max():.2f} m): a plate "
        f"bears on the foot standing on it, whose node lies within {MAX_NODE_HEIGHT:g} m of the floor (an ankle "
        f"0.05-0.12 m, a heel or the toes 0-0.05 m; a knee lies 0.4-0.55 m high, a hip 0.8-1 m); apply it to the "
        "foot (--plate NODE=PREFIX, an ExternalLoads file's applied_to_body)"
        + (f": the nodes near its centre of pressure are {feet}" if feet else "")
    )


def _shear_halves(force: np.ndarray, up: np.ndarray) -> list[tuple[int, int, float, float]]:
    """[(start, stop, its first half's and its second half's mean force (N) along the floor's direction (up
    turned clockwise: the plane's x for y up))] of each whole stance (a run of vertical force above 20 N that the
    samples neither start nor end in) of a plate's force (k, 2) N in the plane, the model's up ``up`` (2,)."""
    from casflex.lab.lowpass import runs

    along = force @ np.array([up[1], -up[0]])
    out = []
    for s, e in runs(force @ up > _LOADED):
        if s > 0 and e < force.shape[0] and e - s >= 4:
            m = (s + e) // 2
            out.append((s, e, float(along[s:m].mean()), float(along[m:e].mean())))
    return out


def check_shear(where: str, t: np.ndarray, force: np.ndarray, weight: np.ndarray | None, body_x: np.ndarray) -> None:
    """ValueError in one line for a plate whose force along the floor (force (k, 2) N in the plane at times t (k,) s)
    propels the body in the first half of a whole stance and brakes it in the second, each by more than
    :data:`MIN_SHEAR` x W on average, while the body (``body_x`` (k,) m: its nodes' mean position along the floor)
    travels faster than :data:`MIN_TRAVEL` m/s over it (module docstring): a stance brakes, then propels."""
    up = weight_up(weight) if weight is not None else None
    if up is None:
        return
    W = float(np.linalg.norm(weight))
    for s, e, first, second in _shear_halves(force, up):
        v = (body_x[e - 1] - body_x[s]) / (t[e - 1] - t[s])
        a, b = (first, second) if v > 0 else (-first, -second)
        if abs(v) > MIN_TRAVEL and a > MIN_SHEAR * W and b < -MIN_SHEAR * W:
            raise ValueError(
                f"{where}: over its stance at t = {t[s]:g}..{t[e - 1]:g} s its force along the floor pushes the body "
                f"on ({a:.0f} N on average over its first half) then holds it back ({b:.0f} N over its second), the "
                f"body travelling at {abs(v):.2f} m/s: a stance brakes the body, then propels it (beyond "
                f"{MIN_SHEAR:g} x its weight, {MIN_SHEAR * W:.0f} N); the horizontal force's sign is flipped (a "
                "column negated, a plate's own axes)"
            )


def check_cop_height(where: str, node: str, t: np.ndarray, fv: np.ndarray, cop: np.ndarray, low: np.ndarray) -> None:
    """ValueError in one line for a stance (a run of samples whose vertical force ``fv`` (k,) N exceeds a quarter of
    its record's peak and 20 N, at times t (k,) s) over which the plate's centre of pressure (its height ``cop``
    (k,) m along the model's up as the table writes it; NaN: passed over) lies, median, more than
    :data:`MAX_COP_ABOVE` above the lowest point ``low`` (k,) m of the foot ``node`` bears on (its node and its
    markers): a centre of pressure lies on the surface the foot stands on (module docstring)."""
    from casflex.lab.lowpass import runs

    stance = fv > max(_LOADED, 0.25 * float(fv.max(initial=0.0)))
    for s, e in runs(stance):
        h = (cop - low)[s:e]
        h = h[np.isfinite(h)]
        if h.size and median(h) > MAX_COP_ABOVE:
            raise ValueError(
                f"{where}: its centre of pressure lies {median(h):.2f} m above the lowest point of {node!r} (its "
                f"node and its markers) over its stance at t = {t[s]:g}..{t[e - 1]:g} s (median of {h.size} "
                f"samples; {h.min():.2f}..{h.max():.2f} m): a centre of pressure lies on the surface the foot stands "
                f"on, at most {MAX_COP_ABOVE:g} m above its lowest marker; its coordinates' columns swapped (the "
                "vertical's holding the sideways position: a Y-up file read as Z-up?) or the wrong plane"
            )


def across_plane(where: str, t: np.ndarray, force3: np.ndarray, E: np.ndarray, up: np.ndarray) -> str | None:
    """A line (a warning) for the first stance (a run of at least 4 samples of vertical force above 20 N) of a
    plate's record (force ``force3`` (n, 3) N in the lab at times t (n,) s, unfiltered) over which its force across
    the model's plane (lab axes ``E`` (2, 3)) carries more than :data:`MAX_ACROSS` times the impulse of its force
    along the floor (the integrals of their magnitudes, N s; ``up`` (2,): the model's up in the plane), else None
    (module docstring): in straight gait the force across is a fraction of the fore-aft one; more, the columns are
    swapped or the plane is wrong (a cutting or turning step aside)."""
    from casflex.lab.lowpass import runs

    normal = np.cross(E[0], E[1])
    along = np.array([up[1], -up[0]]) @ E
    with np.errstate(invalid="ignore"):
        fv = force3 @ (up @ E)
        loaded = fv > _LOADED
    for s, e in runs(loaded):
        if e - s < 4:
            continue
        ts = t[s:e]
        across, fore = (_impulse(ts, np.abs(force3[s:e] @ d)) for d in (normal, along))
        if across > MAX_ACROSS * fore:
            return (f"{where}: over its stance at t = {ts[0]:g}..{ts[-1]:g} s its force across the model's plane "
                    f"carries {across:.3g} N s, more than its force along the floor ({fore:.3g} N s; in straight gait "
                    f"the force across carries 0.07-0.55 of it, the limit {MAX_ACROSS:g}): the planar model drops that "
                    "force; its columns swapped (the fore-aft and the sideways force: a Y-up file's vx and vz), or the "
                    "wrong plane?")
    return None


def _impulse(t: np.ndarray, f: np.ndarray) -> float:
    """N s: the trapezoidal integral of the force f (k,) N over the times t (k,) s."""
    return float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(t)))
