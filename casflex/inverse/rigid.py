"""Inverse dynamics of rigid segments: the loads that make the scene follow its coordinates.

With the coordinates z(t) (:mod:`casflex.inverse.tree`) every dof's motion is known: q = forward(z),
q' = J z', q'' = J z'' + (dJ/dz z') z'. The scene is then held on that motion by constraints and
their multipliers (Eq. 1): the joints' own rows (a hinge's two, a weld's three), the root's three
rows (its x, y and theta held where z has them) and one drive row per hinge, psi = theta_b - theta_a
- (theta_b0 - theta_a0) held at its angle. When these rows are as many as the dofs (rigid segments:
bodies on nodes, welds and hinges), Eq. 1 at each frame,

    B^T lambda = f_ext + g + f_plates - M q'' - h - f_int,

is a square linear system for the multipliers, solved exactly, frame by frame: no integration, no
time step. The loads (outputs, named like simulate's):

- ``<hinge>.moment`` (N m): the net joint moment, -lambda of the drive row: the moment segment a
  exerts on segment b about the hinge (counter-clockwise positive; b gets it, a the opposite). A
  torsion spring across the hinge is counted separately (its ``<torsion>.moment``): the drive moment
  is what the spring leaves to the muscles.
- ``<hinge>.fx``, ``.fy`` (N, global), ``.f_along``, ``.f_across``: the intersegmental force a exerts on b.
- ``root.fx``, ``root.fy`` (N), ``root.mz`` (N m): the loads the root's driver applies to the
  root node to make it follow the data: the residual forces and moment of the lab's inverse dynamics
  when the root is a free body (how far the measured forces and kinematics disagree), the rest of
  the body's action when the scene is a part of it (a leg from its pelvis).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from casflex.codegen import BufferedCall
from casflex.inverse.tree import KinematicTree

__all__ = ["driver_rows", "rigid_loads"]


def driver_rows(tree: KinematicTree) -> np.ndarray:
    """(3 + hinges, n_dof): the root's rows and the drive rows (constant: the drives are linear in q)."""
    m, idx = tree.model, tree.model.node_names.index
    D = np.zeros((tree.n, m.n_dof))
    r = 3 * idx(tree.root)
    D[0, r], D[1, r + 1], D[2, r + 2] = 1.0, 1.0, 1.0
    for k, h in enumerate(tree.hinges):
        a, b = m.scene.item(h).nodes
        D[3 + k, 3 * idx(b) + 2], D[3 + k, 3 * idx(a) + 2] = 1.0, -1.0
    return D


def _frame_function(tree: KinematicTree) -> ca.Function:
    """``frame(z, zd, zdd, t, p) -> (q, qd, qdd, r, B)``: the motion of z, the residual of Eq. 1 without
    the constraints' forces (M q'' + h + f_int - f_ext - g) and the joints' B at q."""
    m = tree.model
    z, zd, zdd = (ca.MX.sym(s, tree.n) for s in ("z", "zd", "zdd"))
    t, p = ca.MX.sym("t"), ca.MX.sym("p", m.n_p)
    q, qd, qdd = tree.rates(z, zd, zdd)
    r, _ = m.equilibrium(q, qd, qdd, ca.MX.zeros(m.n_con), t, p)
    B = m.constraint(q)[1]
    return ca.Function("inverse_frame", [z, zd, zdd, t, p], [q, qd, qdd, r, B],
                       ["z", "zd", "zdd", "t", "p"], ["q", "qd", "qdd", "r", "B"])


#: Frames solved at once: the per-frame matrices of a block stay small (1e6 frames at once took 6 GB).
BLOCK = 4096
#: The frame Function is evaluated mapped over chunks of these many frames (a block's frames by the largest that
#: fit, then the smaller): each chunk's Function is built once per tree (:meth:`KinematicTree.built`), whatever the
#: trials' lengths (a map over a trial's own length, densified, took 6 ms to build at 61 frames and 62 at 512).
SIZES = (512, 64, 8, 1)


def rigid_loads(tree: KinematicTree, t: np.ndarray, z: np.ndarray, zd: np.ndarray, zdd: np.ndarray,
                p: np.ndarray, external=None) -> dict[str, np.ndarray]:
    """The inverse dynamics of rigid segments at the frames t (k,) with coordinates z, z', z'' (k, n_z)
    (module docstring), in blocks of :data:`BLOCK` frames. ``external(t, q) -> (k, n_dof)``: further
    generalised forces (force plates). Returns q, qd, qdd (k, n_dof), lam (k, rows) and the loads by name (k,)."""
    m = tree.model
    if m.n_con != m.n_dof - tree.n:
        raise ValueError(f"the scene has {m.n_dof} dofs and {m.n_con} joint rows: with the {tree.n} coordinates they "
                         "do not decide its motion; flexible segments need the flexible inverse")
    calls: dict[int, BufferedCall] = {}  # this call's buffers of the tree's chunk Functions
    parts = [_block(tree, calls, t[s:s + BLOCK], z[s:s + BLOCK], zd[s:s + BLOCK], zdd[s:s + BLOCK], p, external)
             for s in range(0, t.size, BLOCK)]
    q, qd, qdd, lam = (np.concatenate([pt[i] for pt in parts]) for i in range(4))
    out = loads_by_name(tree, q, qd, lam, p)
    return {"q": q, "qd": qd, "qdd": qdd, "lam": lam, **out}


def _chunk(tree: KinematicTree, calls: dict[int, BufferedCall], size: int) -> BufferedCall:
    """The frame Function mapped over ``size`` frames, densified, on numpy memory (its buffer ``calls``')."""
    if size not in calls:
        frame = tree.built(("inverse_frame",), lambda: _frame_function(tree))
        calls[size] = BufferedCall(tree.built(("inverse_frame", size), lambda: _dense(frame.map(size))))
    return calls[size]


def _block(tree: KinematicTree, calls: dict[int, BufferedCall], t, z, zd, zdd, p, external):
    """(q, qd, qdd, lam) of the frames t (k,) by the frame Function mapped over chunks of :data:`SIZES` frames."""
    m, k = tree.model, t.size
    # a matrix (rows, size) of the mapped Function is column-major: a C-ordered (size, rows) array, frame by frame
    args = [np.ascontiguousarray(a, dtype=float) for a in (z, zd, zdd, t, np.tile(p, (k, 1)))]
    q, qd, qdd, r = (np.empty((k, m.n_dof)) for _ in range(4))
    Bt = np.empty((k, m.n_dof, m.n_con))  # B (n_con, size n_dof) column-major: each frame's B transposed
    s = 0
    for size in SIZES:
        while k - s >= size:
            _chunk(tree, calls, size)([a[s:s + size] for a in args], [o[s:s + size] for o in (q, qd, qdd, r, Bt)])
            s += size
    B = Bt.transpose(0, 2, 1)
    if external is not None:
        r = r - external(t, q)
    A = np.concatenate([B, np.broadcast_to(driver_rows(tree), (k, tree.n, m.n_dof))], axis=1)
    cond = np.linalg.cond(A)
    if not np.all(cond < 1e12):
        i = int(np.argmax(~(cond < 1e12)))
        raise ValueError(f"the coordinates do not decide the scene's motion at t = {t[i]:g} s (singular joints)")
    lam = np.linalg.solve(A.transpose(0, 2, 1), -r[:, :, None])[:, :, 0]
    return q, qd, qdd, lam


def _dense(f: ca.Function) -> ca.Function:
    """``f`` with dense outputs, to be called on numpy memory (:class:`~casflex.codegen.BufferedCall`: no DM
    conversions, which took as long as the frames' work)."""
    ins = [ca.MX.sym(f.name_in(i), f.sparsity_in(i)) for i in range(f.n_in())]
    return ca.Function(f"{f.name()}_dense", ins, [ca.densify(o) for o in f.call(ins)])


def loads_by_name(tree: KinematicTree, q: np.ndarray, qd: np.ndarray, lam: np.ndarray,
                  p: np.ndarray) -> dict[str, np.ndarray]:
    """The outputs of the joints and elements (as simulate names them) and the drivers' loads, (k,) each,
    from the multipliers lam (k, joints' rows + n_z): the model's rows first, then the drivers'."""
    m = tree.model
    k = q.shape[0]
    y = np.array(m.outputs.map(k)(q.T, qd.T, lam[:, :m.n_con].T, np.tile(p[:, None], (1, k)))).T
    out = {name: y[:, i] for i, name in enumerate(m.output_names)}
    drv = -lam[:, m.n_con:]
    for c, what in enumerate(("fx", "fy", "mz")):
        out[f"root.{what}"] = drv[:, c]
    for j, h in enumerate(tree.hinges):
        out[f"{h}.moment"] = drv[:, 3 + j]
    return out
