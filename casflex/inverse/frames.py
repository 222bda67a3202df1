"""The marker fit on every frame at once (:func:`casflex.inverse.fit.fit_markers`): its Levenberg-Marquardt with
each frame's iterations in step with the others', as arrays over the frames still iterating: one mapped CasADi
evaluation of their markers and Jacobians into numpy memory, their normal equations solved together
(``np.linalg.solve`` on a stack), no Python per frame and no conversion. The iterations are the frame-by-frame
fit's (:func:`casflex.inverse.fit._levenberg_marquardt`: its damping, active set at the limits, acceptance and
stop), their sums taken in another order: the same minimum, to the fit's tolerance.

Frame-by-frame, each frame starts at the one before; here the frames start together, from each segment's rigid
(Kabsch) fit of its own markers (:func:`kabsch_starts`), and a second pass starts each frame at the first pass's
pose of the frame before (:func:`casflex.inverse.fit.fit_markers` checks that the two passes agree).
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as ca
import numpy as np

from casflex.codegen import BufferedCall
from casflex.inverse.tree import KinematicTree

__all__ = ["MappedFit", "kabsch_starts", "levenberg_marquardt"]


class MappedFit:
    """``tree.marker_fit`` on k frames at once: ``(Y (k, 2 m), J (k, 2 m, n_z))`` of Z (k, n_z), each frame's the
    numbers of ``marker_fit(z)`` (the same Function mapped), in chunks of the sizes :attr:`SIZES` (each mapped
    Function built when first needed). ``tree``: the tree whose ``marker_fit`` ``f`` is, which keeps the mapped
    Functions for the next fit of its scene (:meth:`casflex.inverse.tree.KinematicTree.built`)."""

    SIZES = (512, 64, 8, 1)

    def __init__(self, f: ca.Function, tree: KinematicTree | None = None) -> None:
        if tree is not None and tree.marker_fit is not f:
            raise ValueError("MappedFit: f is not the tree's marker_fit")
        self._f, self._tree, self._calls = f, tree, {}
        self.n, self.rows = f.size1_in(0), f.size1_out(0)

    def _mapped(self, size: int) -> ca.Function:
        z = ca.MX.sym("z", self.n, size)
        y, J = self._f.map(size)(z)  # (2 m, size) and (2 m, n_z size): column-major, frame after frame
        return ca.Function(f"marker_fit_{size}", [z], [ca.densify(y), ca.densify(J)])

    def _call(self, size: int) -> BufferedCall:
        if size not in self._calls:
            f = self._mapped(size) if self._tree is None else self._tree.built(("marker_fit", size),
                                                                               lambda: self._mapped(size))
            self._calls[size] = BufferedCall(f)
        return self._calls[size]

    def __call__(self, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        k = Z.shape[0]
        Z = np.ascontiguousarray(Z, dtype=float)
        Y, Jt = np.empty((k, self.rows)), np.empty((k, self.n, self.rows))  # Jt: each frame's J transposed
        s = 0
        for size in self.SIZES:
            while k - s >= size:
                self._call(size)([Z[s:s + size]], [Y[s:s + size], Jt[s:s + size]])
                s += size
        return Y, Jt.transpose(0, 2, 1)


def kabsch_starts(tree: KinematicTree, Y: np.ndarray, y0: np.ndarray) -> np.ndarray:
    """Z (F, n_z): each frame's every segment turned and carried as the rigid fit of its own seen markers (at least
    two) says, the root's pose and the hinges' angles from those turns (0 where a segment has fewer markers): the
    start :func:`casflex.inverse.fit._kabsch_start` makes of one frame, for the frames Y (F, 2 m) at once."""
    m, idx = tree.model, tree.model.node_names.index
    cl = np.array([tree.cluster[i] for i in tree.marker_nodes])
    F = Y.shape[0]
    meas, ref = Y.reshape(F, -1, 2), y0.reshape(-1, 2)
    seen = np.isfinite(meas).all(axis=2)
    turn = {}
    for c in set(cl.tolist()):
        sel = (cl == c)[None, :] & seen  # (F, markers)
        count = sel.sum(axis=1)
        wgt = sel / np.maximum(count, 1)[:, None]
        c0 = wgt @ ref  # (F, 2): the reference markers' centre
        c1 = np.einsum("fk,fkd->fd", wgt, np.where(sel[:, :, None], meas, 0.0))
        a, b = ref[None] - c0[:, None], np.where(sel[:, :, None], meas, 0.0) - c1[:, None]
        cross = ((a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]) * sel).sum(axis=1)
        phi = np.arctan2(cross, ((a * b).sum(axis=2) * sel).sum(axis=1))
        turn[c] = (np.where(count >= 2, phi, 0.0), c0, c1, count >= 2)
    r = idx(tree.root)
    Z = np.zeros((F, tree.n))
    Z[:, :3] = m.q0[3 * r:3 * r + 3]
    if tree.cluster[r] in turn:
        phi, c0, c1, has = turn[tree.cluster[r]]
        d = m.q0[3 * r:3 * r + 2][None] - c0
        moved = c1 + np.stack([np.cos(phi) * d[:, 0] - np.sin(phi) * d[:, 1],
                               np.sin(phi) * d[:, 0] + np.cos(phi) * d[:, 1]], axis=1)
        Z[:, :2] = np.where(has[:, None], moved, Z[:, :2])
        Z[:, 2] += phi
    for k, h in enumerate(tree.hinges):
        a, b = (tree.cluster[idx(n)] for n in m.scene.item(h).nodes)
        if a in turn and b in turn:
            Z[:, 3 + k] = np.where(turn[a][3] & turn[b][3], turn[b][0] - turn[a][0], 0.0)
    return Z


def _normal(J: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The normal equations' A = J^T J (k, n_z, n_z) and g = J^T r (k, n_z) of k frames' weighted J and r."""
    Jt = J.transpose(0, 2, 1)
    return Jt @ J, (Jt @ R[:, :, None])[:, :, 0]


def _steps(A: np.ndarray, g: np.ndarray, Z: np.ndarray, lam: np.ndarray, lo: np.ndarray, hi: np.ndarray
           ) -> np.ndarray:
    """The damped steps (k, n_z) of k frames' normal equations A (a copy: damped in place), g
    (:func:`casflex.inverse.fit._damped_step`'s, each frame's held coordinates' rows and columns replaced by the
    identity, their right-hand side by 0: a step of 0 there), projected on the limits."""
    held = ((Z <= lo) & (g > 0)) | ((Z >= hi) & (g < 0))
    diag = np.arange(Z.shape[1])
    d = A[:, diag, diag]
    A[:, diag, diag] = d + lam[:, None] * (d + 1e-12)
    if held.any():
        A = np.where(held[:, :, None] | held[:, None, :], 0.0, A)
        A[:, diag, diag] = np.where(held, 1.0, A[:, diag, diag])
        g = np.where(held, 0.0, g)
    step = np.linalg.solve(A, -g[:, :, None])[:, :, 0]
    return np.minimum(np.maximum(Z + step, lo), hi) - Z


def levenberg_marquardt(f: MappedFit, Z: np.ndarray, Y: np.ndarray, w: np.ndarray | None, lo: np.ndarray,
                        hi: np.ndarray, *, max_iter: int = 50, tol: float = 1e-10,
                        progress: Callable[[int, int], None] | None = None
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Z (F, n_z), the residuals (F, 2 m) (m, unweighted; NaN where a channel is unseen or of weight 0), decided
    (F,)) of the frames Y (F, 2 m) from the starts Z, as :func:`casflex.inverse.fit._levenberg_marquardt` fits
    each (``w``: the square roots of the weights per channel, or None; ``lo``, ``hi`` (n_z,) the limits), a frame
    converged where its step is below ``tol`` (m, rad). ``progress(done, F)`` as frames converge."""
    F = Z.shape[0]
    seen = np.isfinite(Y) if w is None else np.isfinite(Y) & (w > 0)
    SW = np.where(seen, 1.0 if w is None else w, 0.0)  # an unseen channel's row weighs nothing
    Yz = np.where(seen, Y, 0.0)
    Z = np.minimum(np.maximum(Z, lo), hi)
    ym, J = f(Z)
    R = SW * (ym - Yz)
    A, g = _normal(SW[:, :, None] * J, R)  # each frame's, kept until it takes a step
    lam, active, done = np.full(F, 1e-3), np.ones(F, dtype=bool), 0
    for _ in range(max_iter):
        idx = np.flatnonzero(active)
        step = _steps(A[idx], g[idx], Z[idx], lam[idx], lo, hi)
        moving = np.abs(step).max(axis=1) >= tol
        active[idx[~moving]] = False
        idx, step = idx[moving], step[moving]
        if idx.size:
            trial = Z[idx] + step
            ym2, J2 = f(trial)
            R2 = SW[idx] * (ym2 - Yz[idx])
            better = np.einsum("ij,ij->i", R2, R2) <= np.einsum("ij,ij->i", R[idx], R[idx])
            ok = idx[better]
            Z[ok], R[ok] = trial[better], R2[better]
            A[ok], g[ok] = _normal(SW[ok][:, :, None] * J2[better], R2[better])
            lam[ok] = np.maximum(lam[ok] / 10, 1e-12)
            worse = idx[~better]
            lam[worse] *= 10
            active[worse[lam[worse] > 1e8]] = False
        if progress is not None and (now := F - int(active.sum())) > done:
            done = now
            progress(done, F)
        if not active.any():
            break
    if progress is not None and done < F:  # the frames still moving at max_iter stop there, as frame by frame
        progress(F, F)
    J = SW[:, :, None] * f(Z)[1]  # at the poses reached (one evaluation more than keeping each frame's)
    s = np.linalg.svd(J, compute_uv=False)  # the rows of unseen channels are 0: the seen rows' singular values
    decided = (seen.sum(axis=1) >= Z.shape[1]) & (s[:, -1] > 1e-8 * np.maximum(s[:, 0], 1e-300))
    return Z, np.where(seen, R / np.where(seen, SW, 1.0), np.nan), decided
