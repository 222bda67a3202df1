"""Coordinates given instead of markers: a table of joint angles (OpenSim's IK ``.mot``, or any .mot / .sto
of the scene's coordinates) drives the inverse dynamics directly, with no marker fit.

Columns are matched by the scene's ``[[coordinates]]`` names (``hip_flexion_r``, ``pelvis_tx``: an OpenSim
model read by casflex has them) or by the kinematic tree's own names (``pelvis.x``, ``knee.angle``); a
coordinate the table lacks is refused, naming it. Angles are in degrees where the header says
``inDegrees=yes`` (OpenSim's IK writes so), in radians where it says no; a table that does not say is
refused (a degree read as a radian is 57 times too large). Lengths are in m. Samples must be finite (a gap
is refused, naming the column and time): OpenSim's IK leaves none. Values no body takes (a hinge beyond a
full turn or far past its model's range, every angle within a few degrees under ``inDegrees=yes``, a
position beyond any lab or faster than any body: :func:`casflex.lab.checks.check_coordinates`) are units
the header does not say, refused naming the column.
"""

from __future__ import annotations

import os

import numpy as np

from casflex.inverse.tree import KinematicTree

__all__ = ["coordinates_z", "read_coordinates"]


def read_coordinates(source):
    """The table (:class:`casflex.lab.LabTable`) of a .mot / .sto path, or the table given."""
    from casflex.lab import LabTable, read_sto

    return source if isinstance(source, LabTable) else read_sto(os.fspath(source))


def _column(table, names: list[str], where: str) -> tuple[str, np.ndarray]:
    for name in names:
        if name in table.names:
            return name, table.values[:, table.names.index(name)]
    raise ValueError(f"{where}: no column {' or '.join(repr(n) for n in names)} for the scene's coordinate; the table "
                     f"has {list(table.names)}")


def coordinates_z(scene, tree: KinematicTree, table) -> tuple[np.ndarray, list[str]]:
    """(z (n, tree.n): the tree's coordinates (m, rad) at the table's rows, the report's lines)."""
    from casflex.lab.checks import check_coordinates
    from casflex.scene.coordinates import from_lab

    where = table.source or "coordinates"
    lab = {c.scene_coordinate(): c for c in getattr(scene, "coordinates", ())}
    columns = [_column(table, [lab[own].name, own] if own in lab else [own], where) for own in tree.names]
    length = [lab[own].translational if own in lab else own.endswith((".x", ".y")) for own in tree.names]
    if table.in_degrees is None and not all(length):
        raise ValueError(f"{where}: the header does not say inDegrees=yes or no; the angles' unit is unknown")
    z = np.empty((table.t.size, tree.n))
    checked = []
    for k, (own, (name, v)) in enumerate(zip(tree.names, columns, strict=True)):
        bad = ~np.isfinite(v)
        if bad.any():
            raise ValueError(f"{where}: column {name!r} has no number at t = {table.t[np.argmax(bad)]:g} s")
        v = v if length[k] or not table.in_degrees else np.radians(v)
        kind = "length" if length[k] else ("root angle" if k < 3 else "hinge")
        checked.append((name, v, kind, lab[own].limits if own in lab else None))
        z[:, k] = from_lab(scene, lab[own], v) if own in lab else v
    check_coordinates(where, table.t, checked, table.in_degrees)
    unit = "degrees" if table.in_degrees else "radians"
    return z, [f"coordinates given: {len(columns)} columns of {where} ({unit}), no marker fit"]
