"""The rigid inverse's loads and their exact derivatives at every frame, from one CasADi function mapped over the
frames: what the bands (:mod:`casflex.inverse.bands`, :mod:`casflex.inverse.marker_band`) propagate.

At a frame the loads are y = outputs(q, q', lambda, p) and the drivers' -lambda, lambda solving Eq. 1 of
:mod:`casflex.inverse.rigid`, A(q)^T lambda = -(r(z, z', z'', t, p) - f_plates(t, q)), A the joints' rows and the
drivers'. The plates' generalised forces are linear in q (:func:`casflex.inverse.plates.plate_loads`: the force at
the node's x, y rows and the moment about the node, M_o - (x F_y - y F_x), at its theta row), so they enter as
their value at q = 0 and that linear term. The frame's function is built in SX (the model's functions expanded,
the small linear system solved symbolically) and differentiated by AD along z, z', z'' and the uncertain
properties; the second derivative along each property measures how far the loads are from linear in it. One
call of the function mapped over the frames gives them all: no finite differences, no call a frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from casflex.inverse.lab_names import lab_loads
from casflex.inverse.plates import plate_loads
from casflex.inverse.rigid import BLOCK, driver_rows
from casflex.inverse.tree import KinematicTree

__all__ = ["LoadDerivatives", "dense_outputs", "load_derivatives"]


@dataclass(frozen=True)
class LoadDerivatives:
    """The loads (N, N m) at k frames by name (the rigid inverse's and the lab's, as
    :func:`casflex.inverse.bands.rigid_load_function` gives them): ``value`` {name: (k,)}, ``motion`` {name:
    (3, k, n_z)} their derivatives along z, z', z'' (per m or rad, and per their rates), ``props`` {name: (k, n_u)}
    along the uncertain properties (per the property's unit) and ``curvature`` {name: (k, n_u)} their second
    derivatives along each."""

    value: dict[str, np.ndarray]
    motion: dict[str, np.ndarray]
    props: dict[str, np.ndarray]
    curvature: dict[str, np.ndarray]

    def jacobians(self, names: list[str]) -> np.ndarray:
        """D (3, k, n_loads, n_z): the derivatives of the loads ``names`` along z, z', z'' (the layout of
        :func:`casflex.inverse.marker_band.load_jacobians`)."""
        return np.stack([self.motion[n] for n in names], axis=2)


def _frame_loads(tree: KinematicTree, index: np.ndarray, rates: ca.Function) -> tuple[ca.Function, list[str]]:
    """``frame(z, zd, zdd, t, p, e0) -> (y, dy/d(z, zd, zdd), dy/dp_u, d2y/dp_u^2 (columns))`` at one frame, e0
    the plates' generalised forces at q = 0, and the names of y's rows (the model's outputs, then the root's and
    the hinges' drivers); ``rates`` the tree's (z, z', z'') -> (q, q', q'')."""
    m = tree.model
    n, nd, nc = tree.n, m.n_dof, m.n_con
    z, zd, zdd = (ca.SX.sym(s, n) for s in ("z", "zd", "zdd"))
    t, p, e0 = ca.SX.sym("t"), ca.SX.sym("p", m.n_p), ca.SX.sym("e0", nd)
    q, qd, qdd = rates(z, zd, zdd)
    r = m.equilibrium(q, qd, qdd, ca.SX.zeros(nc), t, p)[0]  # Eq. 1 without the constraints' forces
    B = m.constraint(q)[1]
    moment = ca.SX.zeros(nd)  # the plates' moments about the nodes as they move: M_o - (x F_y - y F_x)
    for i in range(0, nd, 3):
        moment[i + 2] = -(q[i] * e0[i + 1] - q[i + 1] * e0[i])
    A = ca.vertcat(B, ca.SX(driver_rows(tree))) if nc else ca.SX(driver_rows(tree))
    lam = ca.solve(A.T, -(r - e0 - moment))
    y = ca.vertcat(m.outputs.expand()(q, qd, lam[:nc], p), -lam[nc:])
    names = [*m.output_names, "root.fx", "root.fy", "root.mz", *(f"{h}.moment" for h in tree.hinges)]
    motion = ca.jacobian(y, ca.vertcat(z, zd, zdd))
    pu = [p[int(j)] for j in index]
    props = ca.jacobian(y, ca.vertcat(*pu)) if pu else ca.SX.zeros(y.numel(), 0)
    curv = ca.horzcat(*(ca.jacobian(props[:, c], pu[c]) for c in range(len(pu)))) if pu else ca.SX.zeros(y.numel(), 0)
    f = ca.Function("frame_load_derivatives", [z, zd, zdd, t, p, e0], [ca.densify(v) for v in (y, motion, props, curv)])
    return f, names


def dense_outputs(f: ca.Function, args: list[np.ndarray]) -> list[np.ndarray]:
    """The dense outputs of ``f`` at the dense inputs ``args`` (each as f takes it), through the function's buffer:
    no DM in between (converting the outputs to numpy took three times the evaluation)."""
    buf, run = f.buffer()
    ins = [np.ascontiguousarray(np.asarray(a, dtype=float).T) for a in args]  # C order (cols, rows) = column-major
    outs = [np.zeros((f.size2_out(i), f.size1_out(i))) for i in range(f.n_out())]
    for i, a in enumerate(ins):
        buf.set_arg(i, memoryview(a))
    for i, o in enumerate(outs):
        buf.set_res(i, memoryview(o))
    run()
    return [o.T for o in outs]


def load_derivatives(tree: KinematicTree, t: np.ndarray, plates, z: np.ndarray, zd: np.ndarray, zdd: np.ndarray,
                     p: np.ndarray, index: np.ndarray | None = None, *,
                     kinematics: KinematicTree | None = None) -> LoadDerivatives:
    """The loads at the frames t (k,) s, coordinates z, z', z'' (k, n_z) each, properties p of ``tree.model``,
    with the ``plates`` applied, and their exact derivatives (module docstring) along the coordinates and along
    the properties p[index]. ``kinematics``: a tree of the same scene's geometry whose rates are built already
    (the inverse's, whose model lacks the uncertain parameters; the properties move no node): its coordinates
    and dofs must be ``tree``'s."""
    m, k = tree.model, t.size
    index = np.zeros(0, dtype=int) if index is None else np.asarray(index, dtype=int)
    kin = tree if kinematics is None else kinematics
    if kin is not tree and (kin.names != tree.names or kin.model.dof_names != m.dof_names):
        raise ValueError(f"kinematics: its coordinates {kin.names} and dofs are not the tree's {tree.names}")
    rates = kin.rates
    built_with, f, names = tree.built(("frame_loads", tuple(index.tolist()), id(rates)),
                                      lambda: (rates, *_frame_loads(tree, index, rates)))
    if built_with is not rates:  # another tree's rates that had this one's id: built for these
        f, names = _frame_loads(tree, index, rates)
    e0 = plate_loads(m, list(plates), t, np.zeros((k, m.n_dof))) if plates else np.zeros((k, m.n_dof))
    nl, nu, n = len(names), len(index), tree.n
    size = min(BLOCK, k)
    fm, pk = f.map(size), np.tile(np.asarray(p, float)[:, None], (1, size))
    blocks = []
    for s in range(0, k, size):  # blocks of frames: the mapped function's outputs stay small
        rows = np.minimum(np.arange(s, s + size), k - 1)  # the last block padded with its last frame
        y, motion, props, curv = dense_outputs(fm, [z[rows].T, zd[rows].T, zdd[rows].T, t[rows][None, :], pk,
                                                e0[rows].T])
        keep = min(size, k - s)
        blocks.append((y[:, :keep], motion.reshape(nl, size, 3, n)[:, :keep],
                       props.reshape(nl, size, nu)[:, :keep], curv.reshape(nl, size, nu)[:, :keep]))
    y, motion, props, curv = (np.concatenate([b[i] for b in blocks], axis=1) for i in range(4))
    motion = motion.transpose(0, 2, 1, 3)  # (n_l, 3, k, n_z)
    if plates:  # the plates' linear form against plate_loads itself, at the fitted configurations
        q = np.array(kin.forward.map(k)(z.T)).T
        e = plate_loads(m, list(plates), t, q)
        lin = e0.copy()
        lin[:, 2::3] -= q[:, 0::3] * e0[:, 1::3] - q[:, 1::3] * e0[:, 0::3]
        if not np.allclose(e, lin, rtol=1e-12, atol=1e-9 * max(1.0, float(np.abs(e).max()))):
            raise RuntimeError("casflex: the plates' loads are not linear in the configuration as the bands take "
                               "them (casflex.inverse.load_jacobian); report this")
    out = []
    for arr in (y, motion, props, curv):  # each load's rows first
        by = {nm: arr[i] for i, nm in enumerate(names)}
        out.append(by | lab_loads(m.scene, by))
    return LoadDerivatives(*out)
