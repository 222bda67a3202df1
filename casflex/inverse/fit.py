"""The coordinates of a trial: a marker fit per frame, gaps, zero-lag filtering and rates.

Per frame, the coordinates z of the kinematic tree (:mod:`casflex.inverse.tree`) that bring the
scene's markers nearest the measured ones (least squares over the markers seen in that frame;
Levenberg-Marquardt on exact Jacobians, each frame started at the one before, the first one at
every segment's pose by a rigid (Kabsch) fit of its own markers; every frame's iterations run together,
:mod:`casflex.inverse.frames`). A frame whose markers do not
decide every coordinate is a gap; gaps up to ``max_gap`` s are filled by a cubic spline through the
frames around them and reported, longer ones refused in one line.

Then the lab's filter: a 2nd-order Butterworth low-pass run forward and backward
(``scipy.signal.filtfilt``'s algorithm: 4th order, no lag) at ``cutoff`` Hz on every coordinate,
and z', z'' by second-order central differences of the filtered frames. By default the same filter
serves the force plates (:mod:`casflex.inverse.plates`), so that the moments are not made of
kinematics and forces filtered differently (Kristianslund et al. 2012, J Biomech 45:666);
``cutoff_plates`` gives them their own. Markers are weighted as the scene's ``weight`` says (an
OpenSim IK task file sets them: the fit minimises the sum of weight x squared distance); coordinates with
``limits`` (an OpenSim model's clamped ones) are kept within them, as OpenSim's IK keeps them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from casflex import interrupt
from casflex.inverse.tree import KinematicTree
from casflex.lab.checks import median

try:  # np.linalg.solve's own kernel: its wrapper (an errstate each call) costs as much as the 14 x 14 solve
    from numpy.linalg._umath_linalg import solve1 as _solve1
except ImportError:  # pragma: no cover (another numpy's layout)
    _solve1 = None

__all__ = ["FittedMotion", "check_decided", "coordinate_rates", "filtered_rates", "fit_markers", "fit_pose",
           "undecided"]


@dataclass(frozen=True)
class FittedMotion:
    """t (n,) s; z (n, n_z) the fitted coordinates (m, rad), NaN in gaps filled later; rms (n,) m: the
    markers' root-mean-square misfit per frame; seen (n,) markers used per frame; misfit (n, m) m: each
    marker's distance from where the fitted pose puts it (NaN where it is missing or the frame a gap);
    report: lines, the last one saying what was filled where frames were gaps."""

    t: np.ndarray
    z: np.ndarray
    rms: np.ndarray
    seen: np.ndarray
    report: list[str] = field(default_factory=list)
    misfit: np.ndarray | None = None


def _kabsch_start(tree: KinematicTree, y: np.ndarray, y0: np.ndarray) -> np.ndarray:
    """z of every segment's rigid fit to its own seen markers (a start for the first frame)."""
    m, idx = tree.model, tree.model.node_names.index
    cl = np.array([tree.cluster[i] for i in tree.marker_nodes])
    meas, ref = y.reshape(-1, 2), y0.reshape(-1, 2)
    turn = {}
    for c in set(cl.tolist()):
        sel = (cl == c) & np.isfinite(meas).all(axis=1)
        if sel.sum() < 2:
            continue
        a, b = ref[sel] - ref[sel].mean(0), meas[sel] - meas[sel].mean(0)
        phi = float(np.arctan2((a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum(), (a * b).sum()))
        turn[c] = (phi, ref[sel].mean(0), meas[sel].mean(0))
    r = idx(tree.root)
    z = np.zeros(tree.n)
    z[:3] = m.q0[3 * r:3 * r + 3]
    if tree.cluster[r] in turn:
        phi, c0, c1 = turn[tree.cluster[r]]
        R = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
        z[:2] = c1 + R @ (m.q0[3 * r:3 * r + 2] - c0)
        z[2] += phi
    for k, h in enumerate(tree.hinges):
        a, b = (tree.cluster[idx(n)] for n in m.scene.item(h).nodes)
        if a in turn and b in turn:
            z[3 + k] = turn[b][0] - turn[a][0]
    return z


class _MarkerFit:
    """``marker_fit`` evaluated into numpy arrays it owns: ``(y (2 m,), J (2 m, n_z))`` of z (n_z,), the
    same numbers as ``np.array(f(z))`` (the same expressions), without a CasADi call's and its DM conversions'
    0.2 ms each time (CasADi's function buffer: the marker fit makes some 2600 calls on a 151-frame trial). The
    arrays are overwritten by the next call: copy what is kept. ``tree``: the tree whose ``marker_fit`` ``f`` is,
    which keeps the dense Function for the next fit of its scene."""

    def __init__(self, f: ca.Function, tree: KinematicTree | None = None) -> None:
        if tree is not None and tree.marker_fit is not f:
            raise ValueError("_MarkerFit: f is not the tree's marker_fit")
        self._f = _dense_fit(f) if tree is None else tree.built(("marker_fit_dense",), lambda: _dense_fit(f))
        self._buf, self._eval = self._f.buffer()
        n, rows = f.size1_in(0), f.size1_out(0)
        self._z, self.y, self._jt = np.zeros(n), np.zeros(rows), np.zeros((n, rows))
        for k, a in enumerate((self._z,)):
            self._buf.set_arg(k, memoryview(a))
        for k, a in enumerate((self.y, self._jt)):  # J column-major: its transpose row-major
            self._buf.set_res(k, memoryview(a))

    def __call__(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self._z[:] = z
        self._eval()
        return self.y, self._jt.T


def _dense_fit(f: ca.Function) -> ca.Function:
    """``marker_fit_dense(z) -> (y, J)``: ``f``'s expressions with dense outputs (:class:`_MarkerFit`)."""
    z = ca.SX.sym("z", f.size1_in(0))
    y, J = f(z)
    return ca.Function("marker_fit_dense", [z], [ca.densify(y), ca.densify(J)])


def _solve_frame(f: ca.Function | _MarkerFit, z: np.ndarray, y: np.ndarray, max_iter: int = 50,
                 w: np.ndarray | None = None, bounds: tuple[np.ndarray, np.ndarray] | None = None
                 ) -> tuple[np.ndarray, float, bool]:
    """Levenberg-Marquardt from z on the seen entries of y: (z, rms misfit (m), decided)."""
    z, r, decided = _levenberg_marquardt(f, z, y, max_iter, w, bounds)
    return z, float(np.sqrt(np.mean(r.reshape(-1, 2) ** 2, axis=0).sum())) if r.size else np.nan, decided


def _levenberg_marquardt(f: ca.Function | _MarkerFit, z: np.ndarray, y: np.ndarray, max_iter: int,
                         w: np.ndarray | None = None, bounds: tuple[np.ndarray, np.ndarray] | None = None
                         ) -> tuple[np.ndarray, np.ndarray, bool]:
    """(z, the residuals (m, unweighted) of the seen entries of y, decided) from the start z, minimising the
    weighted sum of squares: ``w`` (2 m,) the square roots of the markers' weights per channel (entries of
    weight 0 are left out, as unseen ones); ``bounds`` (lower, upper) (n_z,) the coordinates' limits (-inf,
    inf: none). Within bounds the steps are projected on them, and a coordinate at a bound that the descent
    pushes outward is held there for the step (an active set: the fit's KKT point, as OpenSim's IK's)."""
    f = _MarkerFit(f) if isinstance(f, ca.Function) else f
    seen = np.isfinite(y) if w is None else np.isfinite(y) & (w > 0)
    sw = np.ones(int(seen.sum())) if w is None else w[seen]
    lo, hi = bounds if bounds is not None else (np.full(z.size, -np.inf), np.full(z.size, np.inf))
    z = np.clip(z, lo, hi)
    every = bool(seen.all())  # every channel seen: no row selection (the same numbers, no copies)
    ys, sw_col = (y if every else y[seen]), sw[:, None]
    ym, J = f(z)
    r = sw * ((ym if every else ym[seen]) - ys)
    J = np.multiply(sw_col, J if every else J[seen], order="C")  # C-ordered as J[seen] is: BLAS's sums alike
    with np.errstate(invalid="ignore"):  # for _solve's kernel: the loop's numbers are finite
        return _iterate(f, z, r, J, seen, every, ys, sw, lo, hi, max_iter)


def _iterate(f, z, r, J, seen, every, ys, sw, lo, hi, max_iter) -> tuple[np.ndarray, np.ndarray, bool]:
    """The iterations of :func:`_levenberg_marquardt` from z with residuals r and Jacobian J (weighted)."""
    lam, sw_col = 1e-3, sw[:, None]
    for _ in range(max_iter):
        A, g = J.T @ J, J.T @ r
        free = ~(((z <= lo) & (g > 0)) | ((z >= hi) & (g < 0)))
        step = _damped_step(A, g, free, lam)
        step = np.minimum(np.maximum(z + step, lo), hi) - z  # np.clip's numbers at a fifth of its cost
        if abs(step).max() < 1e-10:  # converged: 0.1 nm, 1e-10 rad
            break
        ym2, J2 = f(z + step)
        r2 = sw * ((ym2 if every else ym2[seen]) - ys)
        if r2 @ r2 <= r @ r:
            z, r, J, lam = z + step, r2, np.multiply(sw_col, J2 if every else J2[seen], order="C"), max(lam / 10, 1e-12)
        else:
            lam *= 10
            if lam > 1e8:
                break
    s = np.linalg.svd(J, compute_uv=False) if J.size else np.zeros(1)
    decided = J.shape[0] >= J.shape[1] and s[-1] > 1e-8 * max(s[0], 1e-300)
    return z, r / sw, bool(decided)


def _damped_step(A: np.ndarray, g: np.ndarray, free: np.ndarray, lam: float) -> np.ndarray:
    """The Levenberg-Marquardt step (n_z,) of the normal equations A, g on the ``free`` coordinates (0 on the
    others): (A_ff + lam (diag A_ff + 1e-12)) s_f = -g_f, the damping added to A's diagonal in place of a
    diagonal matrix added whole (the same numbers; the marker fit solves some 2600 of these per trial)."""
    every = free.all()
    M = A.copy() if every else A[np.ix_(free, free)]
    d = M.ravel()[::M.shape[0] + 1]  # a view of the diagonal
    d += lam * (d + 1e-12)
    if every:
        return _solve(M, -g)
    step = np.zeros_like(g)
    step[free] = _solve(M, -g[free])
    return step


def _solve(M: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.linalg.solve(M, b)``, the same LAPACK call and numbers, through its kernel; a singular M (NaN from the
    kernel) goes to np.linalg.solve, which raises as it always did."""
    if _solve1 is not None:
        x = _solve1(M, b)  # its caller ignores the invalid-value flag a singular M raises (an errstate per frame)
        if np.isfinite(x).all():
            return x
    return np.linalg.solve(M, b)


def fit_pose(tree: KinematicTree, y: np.ndarray, start: np.ndarray | None = None) -> tuple[np.ndarray, float, bool]:
    """One frame's fit: (z, the markers' RMS misfit (m), whether they decide every coordinate) for the
    markers y (2 m,) (NaN where missing), from ``start`` or each segment's rigid fit of its own markers."""
    f = tree.marker_fit
    if start is None:
        start = _kabsch_start(tree, y, np.array(f(tree.coordinates(tree.model.q0))[0]).ravel())
    return _solve_frame(_MarkerFit(f, tree), start, y, w=marker_weights(tree), bounds=coordinate_bounds(tree))


def undecided(tree: KinematicTree, used: np.ndarray) -> list[int]:
    """The tree's coordinates (indices) that the markers ``used`` (bool (m,): seen and weighted) cannot decide in
    any pose: the null space of their Jacobian at two generic poses (random turns of 0.3 rad about the initial
    one, away from a straight knee's singularity), empty when they decide every coordinate."""
    rows = np.repeat(np.asarray(used, bool), 2)
    z0 = tree.coordinates(tree.model.q0)
    rng = np.random.default_rng(0)
    free = set(range(tree.n))
    for _ in range(2):
        J = np.array(tree.marker_fit(z0 + rng.normal(0.0, 0.3, z0.size))[1])[rows]
        s, vt = (np.zeros(0), np.eye(tree.n)) if not J.size else np.linalg.svd(J)[1:]
        null = vt[np.r_[s, np.zeros(tree.n - s.size)] <= 1e-8 * max(s[0] if s.size else 0.0, 1e-300)]
        free &= {k for k in range(tree.n) if (np.abs(null[:, k]) > 1e-6).any()}
    return sorted(free)


def _segment_of(tree: KinematicTree, k: int) -> int:
    """The cluster coordinate k moves: the root's for its pose, a hinge's child's for its angle."""
    idx = tree.model.node_names.index
    node = tree.root if k < 3 else tree.model.scene.item(tree.hinges[k - 3]).nodes[1]
    return tree.cluster[idx(node)]


def check_decided(tree: KinematicTree, y: np.ndarray, labels: tuple[str, ...] | None = None,
                  source: str = "data", absent: tuple[str, ...] = ()) -> None:
    """ValueError in one line, before the fit, when the markers y (n, 2 m) (NaN where missing) seen in the
    window and weighted cannot decide the pose in any frame: it names the coordinates, their segments and those
    segments' markers (``labels``: the trial's names; ``absent``: those the trial lacks entirely), and what their
    markers lack."""
    sc = tree.model.scene
    names = labels or tuple(m.name for m in sc.markers)
    seen = np.isfinite(y).reshape(y.shape[0], -1, 2).all(axis=2).any(axis=0)
    weighted = np.array([m.weight > 0 for m in sc.markers], bool)
    free = undecided(tree, seen & weighted)
    if not free:
        return
    lab = {c.scene_coordinate(): c.name for c in sc.coordinates}
    idx = tree.model.node_names.index
    parts = []
    for c in dict.fromkeys(_segment_of(tree, k) for k in free):
        on = [i for i, n in enumerate(tree.marker_nodes) if tree.cluster[n] == c]
        used = [names[i] for i in on if seen[i] and weighted[i]]
        unseen = [names[i] for i in on if not seen[i] and names[i] not in absent]
        lacked = [names[i] for i in on if not seen[i] and names[i] in absent]
        zero = [names[i] for i in on if seen[i] and not weighted[i]]
        node = tree.model.node_names[tree.entry[c]]
        nodes = [n for i, n in enumerate(tree.model.node_names) if tree.cluster[i] == c]
        bodiless = not any(tree.cluster[idx(b.node)] == c for b in sc.bodies) and not any(
            tree.cluster[idx(b.nodes[0])] == c for b in sc.beams)
        parts.append(f"segment {node!r} has " + (f"the markers {used}" if used else "no marker") + " to place it"
                     + (f" ({unseen} never seen in the window)" if unseen else "")
                     + (f" ({lacked} not in the trial)" if lacked else "")
                     + (f" ({zero} of weight 0)" if zero else "")
                     + (f" (nodes {nodes} and no body: an OpenSim model's massless bodies are nodes, their markers "
                        "left out)" if bodiless and not on else ""))
    coords = [lab.get(tree.names[k], tree.names[k]) for k in free]
    raise ValueError(f"{source}: the markers do not decide {coords} in any frame: {'; '.join(parts)}; a hinged "
                     "segment needs a marker off its joint, the root's two: record them, weight them (--tasks), or "
                     "take the segment out of the scene")


def coordinate_bounds(tree: KinematicTree) -> tuple[np.ndarray, np.ndarray] | None:
    """(lower, upper) (n_z,) of the tree's coordinates: the scene's ``[[coordinates]]`` limits (an OpenSim model's
    clamped ranges), -inf and inf elsewhere; None when no coordinate has limits."""
    from casflex.scene.coordinates import scene_limits

    scene = tree.model.scene
    limited = {c.scene_coordinate(): scene_limits(scene, c) for c in scene.coordinates if c.limits is not None}
    if not limited:
        return None
    lo, hi = (np.array([limited.get(n, (-np.inf, np.inf))[k] for n in tree.names]) for k in (0, 1))
    return lo, hi


def marker_weights(tree: KinematicTree) -> np.ndarray | None:
    """(2 m,) the square roots of the scene markers' weights, per channel (x, y); None when all are 1."""
    w = np.array([m.weight for m in tree.model.scene.markers], dtype=float)
    return None if (w == 1.0).all() else np.repeat(np.sqrt(w), 2)


def fit_markers(tree: KinematicTree, t: np.ndarray, y: np.ndarray, *, max_gap: float = 0.1,
                max_misfit: float | None = None, labels: tuple[str, ...] | None = None, source: str = "data",
                progress=None) -> FittedMotion:
    """The coordinates of the markers y (n, 2 m) at times t (n,) (module docstring); y's columns are
    the scene markers' x, y in scene order (:func:`casflex.model.markers.marker_channels`), NaN where missing.
    ``max_misfit`` (m): a marker farther than that from the fitted pose is refused in one line naming the
    frame and the marker (``labels``, the trial's names for the scene's markers; ``source``, the trial):
    :data:`casflex.lab.checks.MAX_MISFIT`."""
    f = _MarkerFit(tree.marker_fit, tree)
    y0 = f(tree.coordinates(tree.model.q0))[0].copy()
    n, m = t.size, y.shape[1] // 2
    rms, seen = np.full(n, np.nan), np.isfinite(y).reshape(n, -1, 2).all(2).sum(1)
    misfit = np.full((n, m), np.nan)
    w, bounds = marker_weights(tree), coordinate_bounds(tree)
    used = np.ones(m, dtype=bool) if w is None else w[::2] > 0
    Z, R, ok = _fit_frames(tree, f, y, y0, w, bounds, progress)
    Z[~ok] = np.nan
    pairs = R[ok].reshape(-1, m, 2)
    rms[ok] = np.sqrt(np.nanmean(pairs**2, axis=1).sum(axis=1))
    misfit[ok] = np.where(used, np.hypot(pairs[..., 0], pairs[..., 1]), np.nan)
    if max_misfit is not None:  # the first frame with a marker too far is named, as the fit meets it
        for i in np.flatnonzero(ok & (np.nan_to_num(misfit, nan=0.0) > max_misfit).any(axis=1)):
            _check_misfit(misfit[i], t[i], max_misfit, labels, source, at_limits(Z[i], bounds, tree))
    report = [f"marker fit: {n} frames, misfit RMS median {1e3 * median(rms, skip_nan=True):.1f} mm, "
              f"max {1e3 * np.nanmax(rms):.1f} mm"] if np.isfinite(rms).any() else []
    report += _by_marker(misfit, labels, tree) + _at_limits(Z, bounds, tree)
    Z = _fill(t, Z, max_gap, report, source)
    return FittedMotion(t, Z, rms, seen, report, misfit)


#: m, rad: the first pass's stop (each frame near its own pose: a start for the frame after it), and how near the
#: second pass must end to it for that start to be the frame-by-frame fit's (else the frames from there are fitted
#: one by one, each from the one before)
_PREDICT, _AGREE = 1e-4, 1e-3
#: frames fitted at once: the stacked Jacobians of a block stay small (2 m x n_z x 8 bytes a frame)
_BLOCK = 1024


def _fit_frames(tree: KinematicTree, f: _MarkerFit, y: np.ndarray, y0: np.ndarray, w: np.ndarray | None,
                bounds: tuple[np.ndarray, np.ndarray] | None, progress) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Z (n, n_z), residuals (n, 2 m) (NaN where unused), decided (n,)) of the frames y (n, 2 m), each frame's
    fit started at the frame before it (the last one decided), the first at its segments' rigid fits: on all frames
    at once (:mod:`casflex.inverse.frames`), a first pass from each frame's rigid fits giving each frame the pose
    of the one before it."""
    from casflex.inverse.frames import MappedFit, kabsch_starts, levenberg_marquardt

    n = y.shape[0]
    lo, hi = bounds if bounds is not None else (np.full(tree.n, -np.inf), np.full(tree.n, np.inf))
    fm = MappedFit(tree.marker_fit, tree)

    def blocks(starts, tol, report=None):
        parts = [levenberg_marquardt(fm, starts[s:s + _BLOCK], y[s:s + _BLOCK], w, lo, hi, tol=tol,
                                     progress=None if report is None else lambda d, _, s=s: report(s + d, n))
                 for s in range(0, n, _BLOCK)]
        return tuple(np.concatenate([p[k] for p in parts]) for k in range(3))

    def tick(done: int, total: int) -> None:
        if progress is not None:
            progress(done, total)
        interrupt.check()  # a Ctrl-C that a CasADi call swallowed

    Z1, _, ok1 = blocks(kabsch_starts(tree, y, y0), _PREDICT)
    interrupt.check()
    before = _last_before(ok1)
    starts = Z1[np.maximum(before, 0)]
    for i in np.flatnonzero(before < 0):  # no frame decided before it: its segments' rigid fits
        starts[i] = _kabsch_start(tree, y[i], y0)
    Z, R, ok = blocks(starts, 1e-10, tick)
    used = before[(before >= 0)]
    apart = np.zeros(n, dtype=bool)
    apart[before >= 0] = np.abs(Z1[used] - Z[used]).max(axis=1) > _AGREE
    wrong = np.flatnonzero((_last_before(ok) != before) | apart)
    if wrong.size:  # a start not the frame-by-frame fit's: from there, frame by frame
        _one_by_one(tree, f, y, y0, w, bounds, Z, R, ok, int(wrong[0]))
    return Z, R, ok


def _last_before(ok: np.ndarray) -> np.ndarray:
    """(n,) the index of the last frame before each that is ``ok``, -1 where none is."""
    idx = np.where(ok, np.arange(ok.size), -1)
    return np.r_[-1, np.maximum.accumulate(idx)[:-1]]


def _one_by_one(tree, f, y, y0, w, bounds, Z, R, ok, first: int) -> None:
    """Fit the frames from ``first`` on, each from the last one decided before it, into Z, R, ok (in place)."""
    back = _last_before(ok)[first]
    z_prev = Z[back] if back >= 0 else None
    for i in range(first, y.shape[0]):
        start = _kabsch_start(tree, y[i], y0) if z_prev is None else z_prev
        z, r, ok[i] = _levenberg_marquardt(f, start, y[i], 50, w, bounds)
        seen = np.isfinite(y[i]) if w is None else np.isfinite(y[i]) & (w > 0)
        Z[i], R[i] = z, np.nan
        R[i, seen] = r
        if ok[i]:
            z_prev = z
        interrupt.check()


def _at_limit(Z: np.ndarray, bounds: tuple[np.ndarray, np.ndarray] | None, tree: KinematicTree) -> dict[str, int]:
    """{lab name: frames} of the coordinates that the poses Z (n, n_z) or z (n_z,) hold at a limit (the fit
    projects on the limits: equal there, not near)."""
    if bounds is None:
        return {}
    at = np.atleast_2d((Z <= bounds[0]) | (Z >= bounds[1]))
    lab = {c.scene_coordinate(): c.name for c in tree.model.scene.coordinates}
    return {lab.get(n, n): int(at[:, k].sum()) for k, n in enumerate(tree.names) if at[:, k].any()}


def at_limits(z: np.ndarray, bounds: tuple[np.ndarray, np.ndarray] | None, tree: KinematicTree) -> list[str]:
    """The lab names of the coordinates at a limit in the pose z."""
    return list(_at_limit(z, bounds, tree))


def _at_limits(Z: np.ndarray, bounds: tuple[np.ndarray, np.ndarray] | None, tree: KinematicTree) -> list[str]:
    """One line naming the coordinates the fit held at a limit, and in how many frames."""
    held = [f"{name} in {k}" for name, k in _at_limit(Z, bounds, tree).items()]
    return [f"held at a limit of its range (frames): {', '.join(held)}"] if held else []


def _by_marker(misfit: np.ndarray, labels, tree: KinematicTree) -> list[str]:
    """One report line: each marker's misfit RMS and largest (mm) over the frames, and its weight."""
    if not np.isfinite(misfit).any():
        return []
    names = labels or tuple(m.name for m in tree.model.scene.markers)
    parts = []
    for k, mk in enumerate(tree.model.scene.markers):
        col = misfit[:, k][np.isfinite(misfit[:, k])]
        if col.size:
            parts.append(f"{names[k]} {1e3 * np.sqrt(np.mean(col**2)):.1f}/{1e3 * col.max():.1f}"
                         + (f" (w {mk.weight:g})" if mk.weight != 1.0 else ""))
    return ["markers' misfit RMS/largest, mm: " + ", ".join(parts)]


def _check_misfit(misfit: np.ndarray, t: float, limit: float | None, labels, source: str, held: list[str]) -> None:
    """ValueError naming the frame and the marker when a marker lies farther than ``limit`` (m) from the pose;
    ``held``: the coordinates at a limit in that frame (named first: a range too narrow for the trial)."""
    if limit is None or not (misfit > limit).any():
        return
    k = int(np.nanargmax(misfit))
    name = labels[k] if labels is not None else f"#{k}"
    why = (f"{', '.join(held)} held at a limit of its range (the model's clamped range: widen it, or unclamp it), "
           if held else "")
    raise ValueError(f"{source}: at t = {t:g} s marker {name!r} lies {1e3 * misfit[k]:.0f} mm from where the best pose "
                     f"of the scene puts it (max_misfit {1e3 * limit:g} mm): {why}a marker lost or mislabelled, the "
                     "wrong plane or units, a scene not calibrated to this subject (casflex calibrate), or motion out "
                     "of the plane the scene cannot follow (a running trunk's twist: raise --max-misfit, in a study "
                     "options.max_misfit)")


def _fill(t: np.ndarray, Z: np.ndarray, max_gap: float, report: list[str], source: str = "data") -> np.ndarray:
    """Z with its gaps (frames whose markers did not decide the coordinates) filled by a cubic spline."""
    bad = ~np.isfinite(Z).all(axis=1)
    if not bad.any():
        return Z
    from scipy.interpolate import CubicSpline  # here: its import alone costs 0.5 s
    if bad.all():  # check_decided passed: each frame sees too few of the markers at once
        raise ValueError(f"{source}: the markers do not decide the coordinates in any frame: no frame sees enough of "
                         "them at once (each marker is seen in some frames, never together); fill the markers' gaps")
    if bad[0] or bad[-1]:
        k = np.flatnonzero(~bad)
        where = "start" if bad[0] else "end"
        raise ValueError(f"{source}: the markers do not decide the coordinates at the trial's {where}"
                         f" (t = {t[0] if bad[0] else t[-1]:g} s); trim the trial to "
                         f"{t[k[0]]:g}..{t[k[-1]]:g} s (--t-start, --t-end) or fill the markers' gaps")
    edges = np.flatnonzero(np.diff(bad.astype(int)))
    for s, e in zip(edges[::2], edges[1::2], strict=True):
        span = t[e + 1] - t[s]
        if span > max_gap:
            raise ValueError(f"{source}: the markers do not decide the coordinates from t = {t[s + 1]:g} to "
                             f"{t[e]:g} s, a gap longer than {max_gap:g} s; fill the markers' gaps first")
    runs = ", ".join(f"{t[s + 1]:g}..{t[e]:g} s" for s, e in zip(edges[::2], edges[1::2], strict=True))
    report.append(f"gaps: {int(bad.sum())} frames whose markers do not decide the pose ({runs}), the coordinates "
                  "filled by a cubic spline")
    good = ~bad
    return np.where(bad[:, None], CubicSpline(t[good], Z[good], axis=0)(t), Z)


def coordinate_rates(t: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(z', z''), each (n, k), of the evenly spaced frames z (n, k) at t (n,): 6th-order central differences
    (7 points), 4th- and 2nd-order ones nearer the ends, one-sided 2nd-order ones at the ends. Central
    differences of 2nd order, the textbook's (Winter 2009, ch. 3), are themselves a low-pass: at 60 Hz they
    take 9 % off the acceleration of a 10 Hz component, 2.3 % off a 5 Hz one; the 7-point ones 0.2 % and
    0.01 % (tests/test_filters.py)."""
    h = float(t[1] - t[0])
    z = np.asarray(z, dtype=float)
    n = z.shape[0]
    zd = np.gradient(z, h, axis=0, edge_order=2)
    zdd = np.empty_like(z)
    zdd[1:-1] = (z[2:] - 2.0 * z[1:-1] + z[:-2]) / h**2
    zdd[0] = (2.0 * z[0] - 5.0 * z[1] + 4.0 * z[2] - z[3]) / h**2
    zdd[-1] = (2.0 * z[-1] - 5.0 * z[-2] + 4.0 * z[-3] - z[-4]) / h**2
    for m, d1, d2 in ((2, _D1_5, _D2_5), (3, _D1_7, _D2_7)):  # the wider stencils where they fit
        if n > 2 * m:
            window = np.stack([z[j:n - 2 * m + j] for j in range(2 * m + 1)])
            zd[m:n - m] = np.tensordot(d1, window, axes=1) / h
            zdd[m:n - m] = np.tensordot(d2, window, axes=1) / h**2
    return zd, zdd


def filtered_rates(t: np.ndarray, z: np.ndarray, cutoff: float | None, how: str):
    """(z, z', z'') (n, k) each: the coordinates z (n, k) at the evenly spaced t (n,) s filtered at ``cutoff`` Hz
    (None: not filtered; ``how``: "butterworth" or "opensim") and their rates (:func:`coordinate_rates`); OpenSim's
    filter pads the record, and the rates are taken on the padded record. Linear in z."""
    from casflex.lab.lowpass import lowpass, opensim_lowpass

    if cutoff is None or how != "opensim":
        z = lowpass(t, z, cutoff, what="markers")
        return (z, *coordinate_rates(t, z))
    tp, zp, keep = opensim_lowpass(t, z, cutoff)
    zd, zdd = coordinate_rates(tp, zp)
    return zp[keep], zd[keep], zdd[keep]


_D1_5, _D2_5 = np.array([1.0, -8.0, 0.0, 8.0, -1.0]) / 12.0, np.array([-1.0, 16.0, -30.0, 16.0, -1.0]) / 12.0
_D1_7 = np.array([-1.0, 9.0, -45.0, 0.0, 45.0, -9.0, 1.0]) / 60.0
_D2_7 = np.array([2.0, -27.0, 270.0, -490.0, 270.0, -27.0, 2.0]) / 180.0
