"""The loads in the lab's language: along each of the scene's ``[[coordinates]]``
(:mod:`casflex.scene.coordinates`), named as OpenSim's inverse dynamics names them: ``<coordinate>_moment``
(N m) for a rotation, ``<coordinate>_force`` (N) for a translation, signed as the coordinate; and the one rule
for any load's unit (:func:`load_unit`)."""

from __future__ import annotations

import numpy as np

__all__ = ["lab_coordinates", "lab_loads", "lab_name", "load_unit"]

_ROOT = {"x": "root.fx", "y": "root.fy", "theta": "root.mz"}
#: The endings of a force's name (N); every other load is a moment (N m).
_FORCES = ("_force", ".fx", ".fy", ".f_along", ".f_across", ".force")


def lab_name(coordinate) -> str:
    """``<name>_force`` or ``<name>_moment`` of a :class:`~casflex.scene.coordinates.Coordinate`."""
    return f"{coordinate.name}_{'force' if coordinate.translational else 'moment'}"


def lab_loads(scene, loads: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The generalised force along each lab coordinate (k,) from the scene's loads (``<hinge>.moment``,
    ``root.fx|fy|mz``): the one the coordinate's driver applies, times the coordinate's sign."""
    out = {}
    for c in getattr(scene, "coordinates", ()):
        node, _, dof = c.of.rpartition(".")
        key = _ROOT[dof] if node and dof in _ROOT else f"{c.of}.moment"
        if key in loads:
            out[lab_name(c)] = c.sign * loads[key]
    return out


def load_unit(name: str) -> str:
    """The unit of a load called ``name``: N for a force (``<coordinate>_force``, ``<hinge>.fx`` ..., ``root.fx``),
    else N m."""
    return "N" if name.endswith(_FORCES) else "N m"


def lab_coordinates(scene, names, z: np.ndarray) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """The tree's coordinates ``names`` (``pelvis.x``, ``knee.angle``) with values z (k, n_z) as the lab's
    (:func:`casflex.scene.coordinates.to_lab`: their names and values where the scene has ``[[coordinates]]``, else
    the tree's), and their units (m, rad)."""
    from casflex.scene.coordinates import to_lab

    lab = {c.scene_coordinate(): c for c in getattr(scene, "coordinates", ())}
    values, units = {}, {}
    for k, own in enumerate(names):
        c = lab.get(own)
        name = c.name if c is not None else own
        values[name] = to_lab(scene, c, z[:, k]) if c is not None else z[:, k]
        units[name] = c.unit if c is not None else ("m" if own.endswith((".x", ".y")) else "rad")
    return values, units
