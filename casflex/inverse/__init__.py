"""Inverse dynamics from a lab trial: net joint moments, intersegmental forces and root residuals.

The data flow (docs/lab.md, "Inverse dynamics"):

1. the trial's markers, projected on the model's plane (:mod:`casflex.lab`), matched to the scene's
   ``[[markers]]`` by label;
2. per frame, the coordinates of the scene's kinematic tree (root pose and hinge angles) that fit
   them best (:mod:`casflex.inverse.fit`), gaps filled and reported;
3. the coordinates and the force plates filtered by the same zero-lag Butterworth (``cutoff``);
4. the loads that make the scene follow that motion under the plates' forces: exact per frame for
   rigid segments (:mod:`casflex.inverse.rigid`); with flexible ones (beams), the scene driven along
   the motion by HHT, the bones' deflections from its dynamics (:mod:`casflex.inverse.flexible`).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable

import numpy as np

from casflex.filters import even_times, lowpass
from casflex.inverse.fit import coordinate_rates, fit_markers
from casflex.inverse.flexible import driven_loads
from casflex.inverse.plates import Plate, plate_from_table, plate_loads
from casflex.inverse.result import InverseResult
from casflex.inverse.rigid import rigid_loads
from casflex.inverse.tree import KinematicTree, kinematic_tree

__all__ = ["InverseResult", "KinematicTree", "Plate", "inverse_dynamics", "inverse_model", "kinematic_tree"]


def inverse_model(scene, root: str | None = None):
    """The model inverse dynamics drives: the scene without the supports of its root (default: its
    first node), which the root's driver replaces (they would fix what the data moves). A support on
    another node is refused in one line: the data, not the scene, say where the segments go."""
    from casflex.model import assemble
    from casflex.scene import Scene

    if not isinstance(scene, Scene):
        from casflex.scene_io import load_scene

        scene = load_scene(scene)
    root = scene.nodes[0].name if root is None else root
    for s in scene.supports:
        if s.node != root:
            raise ValueError(f"support {s.name!r}: inverse dynamics drives the scene from its root {root!r} only; "
                             "remove the support or make its node the root (--root)")
    return assemble(dataclasses.replace(scene, supports=()))


def _read_markers(path):
    """(markers, plates or None) of a .trc or .c3d file."""
    from casflex.lab import read_c3d, read_trc

    if os.fspath(path).lower().endswith(".c3d"):
        return read_c3d(path)
    return read_trc(path), None


def _trial(markers, grf):
    """(LabMarkers, plates' LabTable or None) from what the caller gave: objects, or .trc/.c3d and
    .mot/.sto/.c3d paths (the markers' own C3D again for its plates)."""
    from casflex.lab import LabMarkers, LabTable, read_sto

    lab, c3d_plates = (markers, None) if isinstance(markers, LabMarkers) else _read_markers(markers)
    if isinstance(grf, LabTable) or grf is None:
        return lab, grf
    if c3d_plates is not None and os.fspath(grf) == os.fspath(markers):
        return lab, c3d_plates
    return lab, _read_markers(grf)[1] if os.fspath(grf).lower().endswith(".c3d") else read_sto(grf)


def _window(t: np.ndarray, t_start: float | None, t_end: float | None) -> np.ndarray:
    lo = t[0] if t_start is None else t_start
    hi = t[-1] if t_end is None else t_end
    keep = (t >= lo - 1e-9) & (t <= hi + 1e-9)
    if keep.sum() < 10:
        raise ValueError(f"t_start, t_end: the window {lo:g}..{hi:g} s holds {int(keep.sum())} frames of the trial "
                         f"({t[0]:g}..{t[-1]:g} s); at least 10 are needed")
    return keep


def inverse_dynamics(scene, markers, *, plane: str = "X,Y", grf=None, plates: dict[str, str] | None = None,
                     cutoff: float | None = 6.0, root: str | None = None,
                     t_start: float | None = None, t_end: float | None = None, max_gap: float = 0.1,
                     dt: float | None = None, alpha: float | None = None, compiled: bool = False,
                     progress: Callable[[int, int], None] | None = None) -> InverseResult:
    """Net joint moments, intersegmental forces and root loads of ``scene`` over a trial.

    Parameters
    ----------
    scene : Scene, scene name or path
        Rigid segments (bodies on nodes) joined by hinges in a tree, ``[[markers]]`` labelled as the trial's.
    markers : LabMarkers or path of a .trc or .c3d file
    plane : str
        The lab axes that become the model's x and y (:class:`casflex.lab.Plane`), e.g. "X,Y".
    grf : LabTable or path of a .mot/.sto or .c3d file (the markers' own C3D: its plates), optional
        Ground reactions; ``plates`` maps each contacting node to its plate's column prefix (e.g.
        ``{"ankle": "ground_"}``: :mod:`casflex.inverse.plates`).
    cutoff : float or None, Hz
        The zero-lag Butterworth's cut-off, for the coordinates and the plates alike (None: unfiltered).
    root : str, optional
        The node the data drive (default: the scene's first node).
    t_start, t_end : float, s, optional
        The part of the trial to use.
    dt, alpha, compiled
        Flexible segments only: the largest HHT time step (s; default the scene's, made to divide the
        frames' interval), HHT's alpha (default the scene's) and whether to run compiled C.
    """
    from casflex.lab import Plane, markers_in_plane

    pl = Plane.parse(plane) if isinstance(plane, str) else plane
    model = inverse_model(scene, root)
    if not model.scene.markers:
        raise ValueError("scene: it has no [[markers]] to fit to the trial")
    plates = dict(plates or {})
    for node in plates:
        if node not in model.node_names:
            raise ValueError(f"plates: no node {node!r} in the scene; nodes are {list(model.node_names)}")
    if plates and grf is None:
        raise ValueError("plates: given without the ground reactions (grf)")
    tree = kinematic_tree(model, root)
    lab, table = _trial(markers, grf)
    ms = markers_in_plane(lab, {m.name: m.label or m.name for m in model.scene.markers}, pl)
    keep = _window(ms.t, t_start, t_end)
    t_frames, y = even_times(ms.t[keep], lab.rate), ms.q[keep]
    fit = fit_markers(tree, t_frames, y, max_gap=max_gap, progress=progress)
    report = list(fit.report)
    zf = lowpass(t_frames, fit.z, cutoff, what="markers")
    report.append(f"coordinates filtered: Butterworth 4th order zero-lag at {cutoff:g} Hz" if cutoff
                  else "coordinates not filtered")
    t, z = t_frames, zf
    zd, zdd = coordinate_rates(t, z)
    plate_list = [plate_from_table(table, prefix, node, pl, cutoff) for node, prefix in plates.items()]
    if plate_list:
        report.append(f"plates {', '.join(f'{p.name!r} on {p.node}' for p in plate_list)}: force and moment about "
                      f"the lab origin filtered {f'at {cutoff:g} Hz' if cutoff else 'not at all'}")
    if model.n_con == model.n_dof - tree.n:  # the coordinates decide every dof: rigid segments
        external = (lambda tt, q: plate_loads(model, plate_list, tt, q)) if plate_list else None
        sol = rigid_loads(tree, t, z, zd, zdd, model.p_nominal, external)
    else:
        run = model.scene.run
        q_fit = np.array(tree.forward.map(t.size)(z.T)).T
        sol = driven_loads(tree, t, z, plate_list, q_fit, dt=run.dt if dt is None else dt,
                           alpha=run.alpha if alpha is None else alpha, compiled=compiled)
        report.append(f"flexible segments: driven by HHT (alpha {run.alpha if alpha is None else alpha:g}), the "
                      f"bones' largest deflection {1e3 * sol['deflection'].max():.2f} mm")
    settings = {"plane": f"{pl.x},{pl.y}", "cutoff_hz": cutoff, "root": tree.root,
                "plates": plates, "moments": [f"{h}.moment" for h in tree.hinges],
                "source": getattr(lab, "source", ""), "scene": model.scene.name}
    loads = {k: v for k, v in sol.items() if k not in ("q", "qd", "qdd", "lam", "deflection")}
    return InverseResult(t, tree.names, z, zd, zdd, model.dof_names, sol["q"], sol["qd"], sol["qdd"], loads,
                         t_frames, fit.rms, report, settings)
