"""Initial positions and velocities that satisfy the ideal joints' constraints (Eq. 1, second line).

A scene's own initial configuration closes every joint by construction (a joint's point is fixed
in both nodes' frames where the scene has it); a state given by the caller (an estimated or
measured one, or node velocities that ignore the joints) may not. Both are projected onto the
constraints, the supports' dofs left alone:

- positions: Gauss-Newton on Phi_J(q) = 0, each update the least change of the free dofs in their
  own scale (translations divided by the scene's length scale, rotations in radians);
- velocities: the least change in kinetic energy, qd+ = qd - M^-1 B^T (B M^-1 B^T)^-1 B qd on the
  free dofs: the velocities an impulse through the joints gives (what a stiff bushing's snap tends
  to), with a 1e-9 regularisation in the dofs' own scale for dofs without mass.

A projection that cannot close the joints raises ValueError naming the joint row.
"""

from __future__ import annotations

import logging

import numpy as np

from casflex.model.model import Model

__all__ = ["project_positions", "project_velocities"]

log = logging.getLogger("casflex")
#: Joint rows are closed to this fraction of their scale (m for lengths, rad for angles): round-off.
CLOSED = 1e-12


def _rows(model: Model, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Phi_J (n_mu,), B_J (n_mu, n), the rows' scales (n_mu,)) at q."""
    phi, B, _ = model.joint_rows(q, np.zeros(len(model.joint_row_names)))
    return np.array(phi).ravel(), np.array(B), model.joint_scales


def _free_and_weights(model: Model) -> tuple[np.ndarray, np.ndarray]:
    fixed = {c.dof for c in model.constraints}
    free = np.array([i for i in range(model.n_dof) if i not in fixed], dtype=int)
    ell = np.where(model.is_rotation, 1.0, model.length_scale)
    return free, ell[free]


def _step(B: np.ndarray, free: np.ndarray, ell: np.ndarray, r: np.ndarray, W: np.ndarray | None = None) -> np.ndarray:
    """The least change dx of the free dofs with B[:, free] dx = -r: in the metric W (n_free square),
    or in the dofs' own scale ell."""
    if W is None:
        W = np.diag(1.0 / ell**2)
    Bf = B[:, free]
    WiBt = np.linalg.solve(W, Bf.T)
    return WiBt @ np.linalg.lstsq(Bf @ WiBt, -r, rcond=None)[0]


def project_positions(model: Model, q: np.ndarray, *, what: str = "q0", max_iter: int = 30,
                      report: bool = True) -> np.ndarray:
    """q with the joints closed (a copy; q itself when already closed to round-off); ``report``: say so
    on the casflex log (INFO) when it moved."""
    if not model.joint_row_names:
        return q
    phi, B, scale = _rows(model, q)
    if np.all(np.abs(phi) <= CLOSED * scale):
        return q
    free, ell = _free_and_weights(model)
    out = q.copy()
    for _ in range(max_iter):
        out[free] += _step(B, free, ell, phi)
        phi, B, _ = _rows(model, out)
        if np.all(np.abs(phi) <= CLOSED * scale):
            if report:
                log.info("%s: moved onto the joints' constraints (largest change %.3g)", what, np.abs(out - q).max())
            return out
    j = int(np.argmax(np.abs(phi) / scale))
    raise ValueError(f"{what}: the joints cannot be closed: {model.joint_row_names[j]} stays {phi[j]:.3g} off "
                     f"after {max_iter} projections (are the joint's nodes and point where the scene has them?)")


def project_velocities(model: Model, q: np.ndarray, qd: np.ndarray, p: np.ndarray | None = None, *,
                       what: str = "qd0") -> np.ndarray:
    """qd with B_J(q) qd = 0 (a copy; qd itself when it already holds to round-off), the least change
    in kinetic energy at parameters p (default nominal)."""
    if not model.joint_row_names:
        return qd
    _, B, scale = _rows(model, q)
    v = B @ qd
    ell_all = np.where(model.is_rotation, 1.0, model.length_scale)
    tiny = CLOSED * max(np.abs(qd / ell_all).max(initial=0.0), 1.0)
    if np.all(np.abs(v) / scale <= tiny):
        return qd
    free, ell = _free_and_weights(model)
    M = np.array(model.mass(q, model.p_nominal if p is None else p))[np.ix_(free, free)]
    W = 0.5 * (M + M.T) + 1e-9 * max(np.trace(M * ell[:, None] ** 2) / len(free), 1e-300) * np.diag(1.0 / ell**2)
    out = qd.copy()
    out[free] += _step(B, free, ell, v, W)
    rest = np.abs(B @ out) / scale
    if rest.max() > 1e3 * tiny:  # the joints' rows are dependent and inconsistent with the supports
        j = int(np.argmax(rest))
        raise ValueError(f"{what}: the velocities cannot satisfy the joints: {model.joint_row_names[j]} keeps "
                         f"{(B @ out)[j]:.3g} (do the supports hold a dof that the joint must move?)")
    log.info("%s: projected onto the joints' constraints (largest change %.3g)", what, np.abs(out - qd).max())
    return out
