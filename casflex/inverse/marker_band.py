"""How far the markers' noise moves the loads of a rigid inverse: the markers' band, propagated exactly to
first order.

The chain from the markers to the loads is, frame by frame and then over the trial,

1. the marker fit: z_i = argmin sum w (f(z) - y_i)^2 over the channels seen (:mod:`casflex.inverse.fit`); to first
   order in the noise e_i of the frame's channels, dz_i = G_i e_i with G_i = A^-1 J^T W, A = J^T W J + sum_j W_j
   r_j d2f_j/dz2 (the implicit function theorem on the fit's optimality; J = df/dz, the residuals r and the
   curvatures at the fitted pose, exact by AD), W the markers' weights; a coordinate held at a limit does not move
   (its column left out). Frames whose markers do not decide the pose (gaps) are the spline through the others;
2. the filter, the gap filling and the rates: linear in z, the same for every coordinate: (z, z', z'')_k =
   sum_i (R0, R1, R2)[k, i] z_i, the operators R taken by passing unit impulses through the very functions the
   inverse runs (:func:`casflex.inverse.fit.filtered_rates`, the spline of :func:`casflex.inverse.fit.fit_markers`);
3. the loads: at each frame a function of that frame's (z, z', z''), linearised exactly by AD, every frame in one
   call (:mod:`casflex.inverse.load_jacobian`); other outputs of the frame's coordinates (the muscles') by central
   differences along each coordinate (:func:`load_jacobians`: quadratic in z' and linear in z'', their differences
   exact; along z, errors of 1e-10).

With white noise of standard deviation sigma per axis of every marker (independent between markers, axes and
frames), the variance of a load L at frame k is

    Var L_k = sum_i sum_(a, b) (dL_k/dz^(a))^T R_a[k, i] R_b[k, i] C_i (dL_k/dz^(b)),  C_i = sigma^2 G_i G_i^T.

The filter forgets: R[k, i] falls below 1e-13 of its peak within :func:`memory` frames of k (the filter's slowest
pole), and farther than that from the record's ends and its gaps the filter and the rates are one shift-invariant
operator, R[k, i] = r(k - i): there the sum over i is a convolution of the covariances with r_a r_b (by FFT). The
frames near the ends and the gaps are taken in segments, each with that many frames of margin on both sides: the
cost grows with the frames, not their square. ``sigma`` is declared or, by default, the fit's residuals' (their sum of
squares over the degrees of freedom the fit leaves: unbiased for white noise). What this leaves out: noise that
is not white (soft tissue moving with the muscles, a marker placed off its landmark: correlated over frames, it
passes the filter), and the terms of second order in the noise (relative size: the noise over the segments'
lengths).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from casflex.inverse.fit import FittedMotion, coordinate_bounds, filtered_rates, marker_weights
from casflex.inverse.load_jacobian import dense_outputs
from casflex.inverse.tree import KinematicTree

__all__ = ["fit_covariances", "load_jacobians", "marker_band", "memory", "residual_noise"]

#: The pairs (a, b) of the operators R0, R1, R2 (z, z', z'') whose products enter the variance.
PAIRS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
#: Values of an operator's chunk (frames x impulses) filtered at once: 32 MB.
CHUNK_VALUES = 4_000_000


def _free(tree: KinematicTree, z: np.ndarray) -> np.ndarray:
    """(n, n_z) bool: the coordinates the fit moves in each frame (not held at a limit of their range)."""
    bounds = coordinate_bounds(tree)
    if bounds is None:
        return np.ones(z.shape, dtype=bool)
    return ~((z <= bounds[0]) | (z >= bounds[1]))


def residual_noise(tree: KinematicTree, fit: FittedMotion) -> float:
    """sigma (m): the markers' noise per axis the fit's residuals show, sqrt(sum r^2 / (channels - free
    coordinates)) over the frames the fit decided (unbiased for white noise, equal on every channel)."""
    decided = np.isfinite(fit.rms)
    mis = fit.misfit[decided]
    dof = float((2 * np.isfinite(mis).sum(axis=1) - _free(tree, fit.z[decided]).sum(axis=1)).sum())
    if not dof > 0:
        raise ValueError("marker_noise: the markers seen are no more than the coordinates in every frame, the fit "
                         "leaves no residual to estimate their noise; declare it (marker_noise, m)")
    return float(np.sqrt(np.nansum(mis**2) / dof))


def _fit_terms(tree: KinematicTree):
    """``terms(z, y, w) -> (f, J, H)``: the markers' channels f(z) (2 m), their Jacobian J (2 m, n_z) and the Hessian
    of v . f at fixed v = w (f - y) (n_z, n_z), the fit's weighted residuals (w 0 where a channel is not seen)."""
    import casadi as ca

    m2 = len(tree.model.scene.markers) * 2
    z, y, w, v = ca.SX.sym("z", tree.n), ca.SX.sym("y", m2), ca.SX.sym("w", m2), ca.SX.sym("v", m2)
    f, J = tree.marker_fit(z)
    H = ca.substitute(ca.jacobian(ca.mtimes(J.T, v), z), v, w * (f - y))
    return ca.Function("marker_fit_terms", [z, y, w], [ca.densify(e) for e in (f, J, H)])


def fit_covariances(tree: KinematicTree, fit: FittedMotion, y: np.ndarray, sigma: float) -> np.ndarray:
    """C (n, n_z, n_z): the covariance of each frame's fitted coordinates (m, rad) under white noise of ``sigma``
    m per axis on the markers y (n, 2 m) (NaN where missing): sigma^2 G G^T, G = dz/dy = A^-1 J^T W the fit's exact
    derivative (A = J^T W J + sum_j W_j r_j d2f_j/dz2, the residuals r's curvature term included: without it the
    band was 9e-4 off the brute force's at 2 mm of noise on a 0.3 m segment, with it 4e-6), over the channels seen
    and the coordinates not held at a limit; 0 where the fit did not decide the pose (a gap)."""
    n, nz = fit.z.shape
    decided = np.isfinite(fit.rms)
    w = marker_weights(tree)
    W = np.where(np.isfinite(y) & decided[:, None], 1.0 if w is None else w**2, 0.0)  # (n, 2 m)
    terms = tree.built(("marker_fit_terms",), lambda: _fit_terms(tree))
    _, J, H = dense_outputs(terms.map(n), [fit.z.T, np.nan_to_num(y).T, W.T])  # one call, every frame
    J = J.reshape(y.shape[1], n, nz).transpose(1, 0, 2)
    H = H.reshape(nz, n, nz).transpose(1, 0, 2)
    free = _free(tree, fit.z) & decided[:, None]
    both = free[:, :, None] & free[:, None, :]
    Jf = np.where(free[:, None, :], J, 0.0)
    B = Jf.transpose(0, 2, 1) * W[:, None, :]  # J^T W (n, n_z, 2 m)
    A = B @ Jf + np.where(both, H, 0.0) + np.eye(nz)[None] * (~free)[:, :, None]  # a held coordinate: nothing moves it
    G = np.linalg.solve(A, B)
    return sigma**2 * G @ G.transpose(0, 2, 1)


def load_jacobians(loads: Callable[[np.ndarray, np.ndarray, np.ndarray], dict[str, np.ndarray]],
                   z: np.ndarray, zd: np.ndarray, zdd: np.ndarray, names: list[str], step: float = 1e-5
                   ) -> np.ndarray:
    """D (3, n, n_loads, n_z): the derivatives of the loads ``names`` (N, N m) at each frame along z, z', z''
    (n, n_z) each, by central differences of ``loads(z, zd, zdd) -> {name: (n,)}`` (every frame moved at once:
    a frame's loads depend on its own coordinates only). Steps: ``step`` along z (m, rad; 1e-5: error ~1e-10
    relative for the loads), 1e-3 of the coordinate's scale along z' and z'' (the loads are quadratic and linear
    in them: exact). Any per-frame function of (z, z', z'') will do (the muscles': :mod:`casflex.muscles.bands`)."""
    n, nz = z.shape
    D = np.zeros((3, n, len(names), nz))
    base = (z, zd, zdd)
    for a in range(3):
        for c in range(nz):
            h = step if a == 0 else 1e-3 * max(1.0, float(np.sqrt(np.mean(base[a][:, c] ** 2))))
            moved = []
            for sign in (1.0, -1.0):
                args = [x.copy() for x in base]
                args[a][:, c] += sign * h
                out = loads(*args)
                moved.append(np.column_stack([out[k] for k in names]))
            D[a, :, :, c] = (moved[0] - moved[1]) / (2.0 * h)
    return D


def memory(t: np.ndarray, cutoff: float | None, how: str) -> int:
    """Frames after which an impulse's effect on the filtered coordinates and their rates is below 1e-13 of its
    peak: the filter's slowest pole's decay (both filters run forward and back), plus 40 frames for the rates'
    stencils, the filter's padding and the gaps' spline."""
    if cutoff is None:
        return 40
    from casflex.lab.lowpass import _butterworth3, butterworth2

    fs = 1.0 / float(t[1] - t[0])
    a = _butterworth3(cutoff, fs)[1] if how == "opensim" else butterworth2(cutoff, fs)[1]
    rho = float(np.max(np.abs(np.roots(a))))
    return int(np.ceil(np.log(1e-13) / np.log(rho))) + 40


def _operators(t: np.ndarray, good: np.ndarray, cols: np.ndarray, rows: slice, cutoff, how: str):
    """(R0, R1, R2) (rows, cols): the filtered coordinates, their rates and accelerations at frames ``rows`` of the
    record t (s,) from unit impulses at frames ``cols`` (decided ones), the frames not ``good`` filled by the
    spline through the others first (as the fit fills gaps)."""
    X = np.zeros((t.size, cols.size))
    X[cols, np.arange(cols.size)] = 1.0
    if not good.all():
        from scipy.interpolate import CubicSpline

        X[~good] = CubicSpline(t[good], X[good], axis=0)(t[~good])
    return tuple(r[rows] for r in filtered_rates(t, X, cutoff, how))


def _segment(t, decided, C, D, core: tuple[int, int], margin: int, cutoff, how: str) -> np.ndarray:
    """The loads' variances (frames of ``core``, n_loads) from the sub-record around it (``margin`` frames each
    side, widened to decided frames at its ends)."""
    n, nz = C.shape[:2]
    c0, c1 = core
    a, b = max(0, c0 - margin), min(n, c1 + margin)
    while not decided[a]:
        a -= 1
    while not decided[b - 1]:
        b += 1
    good = decided[a:b]
    cols = np.flatnonzero(good)
    width = max(16, CHUNK_VALUES // (b - a))
    Q = np.zeros((len(PAIRS), c1 - c0, nz * nz))
    for s in range(0, cols.size, width):
        chunk = cols[s:s + width]
        R = _operators(t[a:b], good, chunk, slice(c0 - a, c1 - a), cutoff, how)
        Cf = C[a + chunk].reshape(chunk.size, nz * nz)
        for p, (i, j) in enumerate(PAIRS):
            Q[p] += (R[i] * R[j]) @ Cf
    return _variance(D[:, c0:c1], Q)


def _interior(decided: np.ndarray, margin: int) -> np.ndarray:
    """(n,) bool: the frames more than ``margin`` frames from both ends of the record and from every frame the fit
    did not decide: there the filter and the rates are the same operator whatever the frame (shift-invariant)."""
    n = decided.size
    near = np.zeros(n + 1, dtype=int)  # a difference array: +1 where a window of 2 margin + 1 frames starts
    for g in np.flatnonzero(~decided):
        near[max(0, g - margin)] += 1
        near[min(n, g + margin + 1)] -= 1
    inner = np.cumsum(near[:n]) == 0
    inner[:margin] = inner[max(margin, n - margin):] = False
    return inner


def _shift_invariant(t: np.ndarray, C: np.ndarray, margin: int, cutoff, how: str) -> np.ndarray:
    """Q (len(PAIRS), n, n_z^2): sum_i R_a[k, i] R_b[k, i] C_i for every frame k as if R were the interior's
    operator, R_a[k, i] = r_a(k - i): a convolution of C with r_a r_b, by FFT. The kernels r_a are the response to
    one impulse in the middle of a record of 4 ``margin`` + 1 frames at the trial's rate (the same functions the
    inverse runs); exact (to round-off) at the frames :func:`_interior` gives."""
    n, nz = C.shape[:2]
    L = 4 * margin + 1
    tt = t[0] + (t[1] - t[0]) * np.arange(L)
    X = np.zeros((L, 1))
    X[2 * margin, 0] = 1.0
    r = [v[margin:3 * margin + 1, 0] for v in filtered_rates(tt, X, cutoff, how)]  # offsets -margin..margin
    size = 1 << int(np.ceil(np.log2(n + 2 * margin)))
    spectrum = np.fft.rfft(C.reshape(n, nz * nz), size, axis=0)
    Q = np.empty((len(PAIRS), n, nz * nz))
    for p, (i, j) in enumerate(PAIRS):
        full = np.fft.irfft(spectrum * np.fft.rfft(r[i] * r[j], size)[:, None], size, axis=0)
        Q[p] = full[margin:margin + n]
    return Q


def _variance(D: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """The loads' variances (k, n_loads) from their derivatives D (3, k, n_loads, n_z) and Q (len(PAIRS), k,
    n_z^2) (the module docstring's sum)."""
    nz = D.shape[3]
    var = np.zeros(D.shape[1:3])
    for p, (i, j) in enumerate(PAIRS):
        var += (1.0 if i == j else 2.0) * np.einsum("klc,kcd,kld->kl", D[i], Q[p].reshape(-1, nz, nz), D[j])
    return var


def marker_band(t: np.ndarray, decided: np.ndarray, C: np.ndarray, D: np.ndarray, cutoff: float | None, how: str,
                *, core: int | None = None) -> np.ndarray:
    """(n, n_loads): the loads' standard deviations (N, N m) from the fit's covariances C (n, n_z, n_z) and the
    loads' derivatives D (3, n, n_loads, n_z) (:func:`load_jacobians`), through the filter (``cutoff`` Hz, None:
    none; ``how``) and the rates (module docstring), over the frames t (n,) s, ``decided`` (n,) where the fit
    decided the pose. Frames farther than :func:`memory` from the ends and the gaps see the filter's interior
    operator: a convolution (:func:`_shift_invariant`); the others are taken in segments of ``core`` frames
    (default 4 x :func:`memory`, at least 512) with :func:`memory` frames of margin: the same to 1e-13 as the whole
    record at once."""
    n = t.size
    margin = memory(t, cutoff, how)
    core = max(4 * margin, 512) if core is None else int(core)
    inner = _interior(decided, margin)
    var = np.zeros((n, D.shape[2]))
    if inner.any():
        var[inner] = _variance(D[:, inner], _shift_invariant(t, C, margin, cutoff, how)[:, inner])
    edges = np.flatnonzero(np.diff(np.r_[0, (~inner).astype(int), 0]))  # the runs of frames not inner
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        for c0 in range(a, b, core):
            var[c0:min(b, c0 + core)] = _segment(t, decided, C, D, (c0, min(b, c0 + core)), margin, cutoff, how)
    return np.sqrt(np.maximum(var, 0.0))
