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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from casflex.filters import even_times, lowpass
from casflex.lab import LabTable, Plane, plate_moment_about_origin

__all__ = ["Plate", "plate_from_table", "plate_loads"]


@dataclass(frozen=True)
class Plate:
    """One plate acting on ``node``: t (n,) s, force (n, 2) N in the plane, moment (n,) N m about the
    lab's origin (module docstring); ``name``: the columns' prefix."""

    name: str
    node: str
    t: np.ndarray
    force: np.ndarray
    moment: np.ndarray

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(force (k, 2), moment (k,)) at times t (s), linear between samples, zero outside the table."""
        f = np.column_stack([np.interp(t, self.t, self.force[:, i], left=0.0, right=0.0) for i in range(2)])
        return f, np.interp(t, self.t, self.moment, left=0.0, right=0.0)


def plate_from_table(table: LabTable, prefix: str, node: str, plane: Plane, cutoff: float | None) -> Plate:
    """The plate ``prefix`` of ``table`` on ``node``, in ``plane``, filtered at ``cutoff`` Hz (None: as
    recorded). The moment about the lab's origin from the table's ``<prefix>moment_{x,y,z}`` where it has
    them (C3D plates, :func:`casflex.lab.read_c3d`), else p x F + T. Rows without force (NaN) are no
    contact: zero force and moment. A force without a centre of pressure is refused in one line."""
    F, M3 = plate_moment_about_origin(table, prefix)
    off = ~np.isfinite(F).all(axis=1) | ~np.isfinite(M3).all(axis=1)  # no force recorded: no contact
    F, M3 = np.where(off[:, None], 0.0, F), np.where(off[:, None], 0.0, M3)
    E = plane.matrix
    n = np.cross(E[0], E[1])
    force, moment = F @ E.T, M3 @ n
    both = lowpass(table.t, np.column_stack([force, moment]), cutoff, what=f"plate {prefix!r}")
    return Plate(prefix, node, even_times(table.t), both[:, :2], both[:, 2])


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
