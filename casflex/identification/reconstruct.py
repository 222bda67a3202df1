"""Nodes' dofs from a recording of markers, for the direct methods (Eqs. 11-14), which write the
equations of motion in the nodes' kinematics.

At each sample the configuration is the constrained kinematic fit through the recorded channels
(:func:`.initial_state.kinematic_fits`): the recorded dofs as recorded, the markers nearest their
records (least squares, the elastic energy at the nominal parameters weighing the motions the
markers do not fix, :func:`.initial_state._kinematic_fit`). The direct methods then
proceed as with nodes' channels (positions only: smoothing gives the rates).

The fit fills in what the channels do not fix from the model's own springs, at nominal values: it
would hand the parameters back to the methods that identify them. So the channels must fix every
*slow* mode (below the samples' Nyquist frequency, :func:`.initial_state.slow_modes`) of the model
at its initial configuration; the fast ones (a bar's stretching and bending) take their
quasi-static values, as in an estimated initial state. A bar carrying one marker and no recorded
node can turn about it: too few markers, refused before any fit. For the same reason a beam
property cannot be a parameter here: the fit would set the beams' deformation between the
markers by their nominal properties (a strip's E from two markers came out 3e-4 to 5e-4 of its
value).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from casflex.data import MeasurementSet
from casflex.identification.initial_state import kinematic_fits, slow_modes
from casflex.identification.measurement import free_dofs
from casflex.model import Model
from casflex.model.markers import channel_index, marker_channels, marker_states

__all__ = ["dofs_from_markers"]

#: Smallest singular value of the recorded channels' response to the slow modes (unit-norm modes,
#: in length scales) for the modes to count as determined. On twobar at 100 Hz the channels'
#: smallest values are 0.087 (its two markers and nodes 3, 5) against 4e-9 (a bar with one marker).
DETERMINED = 1e-6


def _check_determined(model: Model, data: MeasurementSet, names: list[str], method: str) -> None:
    """ValueError when the channels ``names`` leave a slow mode of the model free (module docstring)."""
    free = free_dofs(model)
    cut = float(np.pi / np.median(np.diff(data.t))) if data.t.size > 1 else np.inf
    B = slow_modes(model, model.q0, model.p_nominal, cut)
    J = marker_states(model, model.q0, model.qd0)[2][0]
    rows = np.vstack([np.eye(model.n_dof), J])[[channel_index(model, c) for c in names]][:, free]
    unit = np.where(model.is_rotation[free], 1.0, model.length_scale)  # rad, length scales
    rot = np.array([c in model.dof_names and bool(model.is_rotation[model.dof(c)]) for c in names])
    A = (rows / np.where(rot, 1.0, model.length_scale)[:, None]) @ (B / np.linalg.norm(B / unit[:, None], axis=0))
    sv = np.linalg.svd(A, compute_uv=False) if A.size else np.zeros(0)
    seen = int((sv > DETERMINED).sum())
    if seen < B.shape[1]:
        raise ValueError(f"data: the channels {names} determine {seen} of the model's {B.shape[1]} slow modes (below "
                         f"the samples' Nyquist frequency, {cut / (2 * np.pi):g} Hz), too few markers for {method}, "
                         "which needs every node's motion (a body with one marker turns about it); record more "
                         "markers or nodes, or use the indirect method, which compares markers directly")


def dofs_from_markers(model: Model, data: MeasurementSet, method: str, rotations: bool = True
                      ) -> tuple[MeasurementSet, dict[str, Any] | None]:
    """``data`` as nodes' dofs when it holds markers' channels (module docstring), and the report
    for a result's ``extra["from_markers"]`` (None: no marker channel, ``data`` unchanged).

    The dofs (every dof, or the translations only with ``rotations=False``) are positions (m, rad)
    at the samples that have every channel; their rates are left to smoothing. ``method`` names the
    caller in the error of too few markers.
    """
    data.select(model)  # unknown channel names raise here
    markers = [c for c in data.channels if c in marker_channels(model)]
    if not markers:
        return data, None
    beams = {b.name for b in model.scene.beams}
    on_beams = [par.name for par in model.parameters if par.target.split(".")[0] in beams]
    if on_beams:
        raise ValueError(f"data: markers' channels {markers} and beam properties as parameters {on_beams}: {method} "
                         "would take the beams' deformation between the markers from the kinematic fit, which sets it "
                         "by their nominal properties; use the indirect method, which compares markers directly")
    names = list(data.channels)
    _check_determined(model, data, names, method)
    t, Q = kinematic_fits(model, data, names)
    keep = [i for i in range(model.n_dof) if rotations or not model.is_rotation[i]]
    out = MeasurementSet(t, tuple(model.dof_names[i] for i in keep), Q[:, keep], None, None,
                         source=data.source, meta=data.meta)
    report = {"markers": markers, "channels": names, "samples": int(t.size),
              "dropped_samples": int(data.t.size - t.size),
              "note": "nodes' dofs from the kinematic fit through the recorded channels at each sample (markers "
                      "by least squares, the elastic energy at the nominal parameters weighing what they do not "
                      "fix); the standard errors ignore the fit's uncertainty"}
    return out, report
