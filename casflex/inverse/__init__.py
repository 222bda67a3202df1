"""Inverse dynamics from a lab trial: net joint moments, intersegmental forces and root residuals.

The data flow (docs/lab.md, "Inverse dynamics"):

0. the inputs read and checked before any work (:mod:`casflex.inverse.inputs`: corrupted files, markers
   no body produces, plates that do not cover the trial, options that cannot be honoured);
1. the trial's markers, projected on the model's plane (:mod:`casflex.lab`), matched to the scene's
   ``[[markers]]`` by label (or the coordinates given in a table, :mod:`casflex.inverse.given`: steps 1-2
   skipped);
2. per frame, the coordinates of the scene's kinematic tree (root pose and hinge angles) that fit
   them best (:mod:`casflex.inverse.fit`), gaps filled and reported;
3. the coordinates and the force plates filtered by a zero-lag Butterworth, at one cut-off (``cutoff``, the
   default: kinematics and forces filtered alike keep impact artefacts out of the moments, Kristianslund et
   al. 2012) or each at its own (``cutoff_plates``; None: the plates unfiltered, as OpenSim's ID tool); the
   coordinates by Winter's 4th-order filter or, ``filter="opensim"``, by OpenSim's ID tool's; their rates
   by 7-point central differences;
4. each plate's line of force checked to pass near its node over its stance (the fitted pose:
   :func:`casflex.lab.plate_checks.check_plate_foot`); the loads that make the scene follow that motion under
   the plates' forces: exact per frame for
   rigid segments (:mod:`casflex.inverse.rigid`); with flexible ones (beams), the scene driven along
   the motion by HHT, the bones' deflections from its dynamics (:mod:`casflex.inverse.flexible`);
5. where asked (uncertain properties, ``marker_noise``, ``bands``), each load's band, one standard deviation, from the
   anthropometry's uncertainty and from the markers' noise (:mod:`casflex.inverse.bands`; rigid segments).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from casflex.inverse.bands import band_spec, inverse_bands
from casflex.inverse.fit import FittedMotion, filtered_rates, fit_markers
from casflex.inverse.flexible import driven_loads
from casflex.inverse.inputs import InverseInputs, inverse_model, prepare
from casflex.inverse.lab_names import lab_loads, lab_name
from casflex.inverse.plates import Plate, plate_loads, plates_under_feet
from casflex.inverse.result import InverseResult
from casflex.inverse.rigid import rigid_loads
from casflex.inverse.tree import KinematicTree, kinematic_tree

__all__ = ["InverseInputs", "InverseResult", "KinematicTree", "Plate", "inverse_dynamics", "inverse_model",
           "kinematic_tree", "prepare", "solve"]


def inverse_dynamics(scene, markers=None, *, coordinates=None, plane: str = "X,Y", grf=None,
                     plates: dict[str, str] | None = None, cutoff: float | None = 6.0, root: str | None = None,
                     t_start: float | None = None, t_end: float | None = None, max_gap: float = 0.1,
                     max_misfit: float | None = None, dt: float | None = None, alpha: float | None = None,
                     tasks=None, cutoff_plates: float | None | str = "same", filter: str = "butterworth",
                     compiled: bool = False, progress: Callable[[int, int], None] | None = None, uncertain=None,
                     marker_noise: float | None = None, bands: bool | None = None) -> InverseResult:
    """Net joint moments, intersegmental forces and root loads of ``scene`` over a trial.

    Parameters
    ----------
    scene : Scene, scene name or path
        Rigid segments (bodies on nodes) joined by hinges in a tree, ``[[markers]]`` labelled as the trial's.
    markers : LabMarkers or path of a .trc or .c3d file
        The trial's markers, fitted frame by frame; or, instead:
    coordinates : LabTable or path of a .mot / .sto file
        The scene's coordinates over the trial (e.g. OpenSim's IK result), no marker fit
        (:mod:`casflex.inverse.given`: the columns named by the scene's ``[[coordinates]]``, degrees where the
        header says ``inDegrees=yes``).
    plane : str
        The lab axes that become the model's x and y (:class:`casflex.lab.Plane`), e.g. "X,Y".
    grf : LabTable or path of a .mot/.sto or .c3d file (the markers' own C3D: its plates), optional
        Ground reactions; ``plates`` maps each contacting node to its plate's column prefix (e.g.
        ``{"ankle": "ground_"}``: :mod:`casflex.inverse.plates`).
    cutoff : float or None, Hz
        The zero-lag Butterworth's cut-off for the coordinates (None: unfiltered), and for the plates unless
        ``cutoff_plates`` says otherwise.
    cutoff_plates : float, None or "same", Hz
        The plates' own cut-off (None: unfiltered; "same": ``cutoff``).
    filter : "butterworth" or "opensim"
        The coordinates' filter: a 2nd-order Butterworth run forward and back (4th order, zero lag; the
        default), or the one OpenSim's inverse dynamics tool applies (the record padded by half its length,
        a 3rd-order Butterworth forward and back: :func:`casflex.lab.lowpass.opensim_lowpass`), to get that
        tool's answer. Both are -6 dB at ``cutoff``. The plates are filtered by the first in both cases.
    tasks : path or dict, optional
        Marker weights: an OpenSim IK task set or setup file, or label -> weight (:func:`weighted`); default
        the scene's ``[[markers]]`` weights.
    root : str, optional
        The node the data drive (default: the scene's first node).
    t_start, t_end : float, s, optional
        The part of the trial to use.
    max_gap : float, s
        The longest stretch of frames whose markers do not decide the pose that a spline fills.
    max_misfit : float, m, optional
        A marker farther than this from the fitted pose is refused (default
        :data:`casflex.lab.checks.MAX_MISFIT`, 0.1 m).
    dt, alpha, compiled
        Flexible segments only: the largest HHT time step (s; default the scene's, made to divide the
        frames' interval), HHT's alpha (default the scene's) and whether to run compiled C.
    uncertain : list of casflex.scene.Uncertain, optional
        Properties known within an uncertainty (a segment's ``mass`` or ``inertia`` from an anthropometric table),
        added to the scene's ``[[uncertain]]`` (replacing those of the same target): each load's band from them,
        ``res.bands`` (:mod:`casflex.inverse.bands`). Rigid segments only.
    marker_noise : float, m, optional
        The markers' noise per axis (standard deviation) whose band the loads get (default: the fit's residuals').
    bands : bool, optional
        None: bands when an uncertain property or ``marker_noise`` is declared; True: always (the markers' part
        alone when nothing is uncertain); False: never.

    Every input is read and checked before the marker fit (:func:`prepare`); ValueError in one line naming
    the option, file, marker or plate otherwise.
    """
    inputs = prepare(scene, markers, plane=plane, grf=grf, plates=plates, cutoff=cutoff, root=root,
                     t_start=t_start, t_end=t_end, max_gap=max_gap, max_misfit=max_misfit, dt=dt, tasks=tasks,
                     cutoff_plates=cutoff_plates, filter=filter, coordinates=coordinates, uncertain=uncertain,
                     marker_noise=marker_noise, bands=bands)
    return solve(inputs, dt=dt, alpha=alpha, compiled=compiled, progress=progress)


def _given(inputs: InverseInputs) -> FittedMotion:
    """The coordinates given (no marker fit): no misfit to report."""
    n = inputs.t.size
    return FittedMotion(inputs.t, inputs.z, np.full(n, np.nan), np.zeros(n, dtype=int), [], np.zeros((n, 0)))


def solve(inputs: InverseInputs, *, dt: float | None = None, alpha: float | None = None, compiled: bool = False,
          progress: Callable[[int, int], None] | None = None, uncertain=None, marker_noise: float | None = None,
          bands: bool | None = None) -> InverseResult:
    """The inverse dynamics of checked inputs (:func:`prepare`): the marker fit, the filter, the rates and the
    loads (module docstring), and their bands; options as :func:`inverse_dynamics`'s (``uncertain``,
    ``marker_noise`` and ``bands``, where given, replace what :func:`prepare` was asked, checked first)."""
    if uncertain is not None or marker_noise is not None or bands is not None:
        inputs = dataclasses.replace(inputs, band_spec=band_spec(
            inputs.model, inputs.tree, uncertain=uncertain, marker_noise=marker_noise, bands=bands,
            given=inputs.z is not None, n_markers=sum(m.weight > 0 for m in inputs.model.scene.markers)))
    model, tree, t, cutoff = inputs.model, inputs.tree, inputs.t, inputs.cutoff
    fit = _given(inputs) if inputs.z is not None else fit_markers(
        tree, t, inputs.y, max_gap=inputs.max_gap, max_misfit=inputs.max_misfit, labels=inputs.labels,
        source=inputs.settings["source"], progress=progress)
    report = [*inputs.report, *fit.report]
    warnings = [*inputs.warnings, *(line for line in fit.report if line.startswith("gaps:"))]
    z, zd, zdd = filtered_rates(t, fit.z, cutoff, inputs.settings.get("filter", "butterworth"))
    report.append(("coordinates filtered: " + ("as OpenSim's ID tool (padded by half the record, Butterworth 3rd "
                                              "order forward and back)" if inputs.settings.get("filter") == "opensim"
                                              else "Butterworth 4th order zero-lag") + f" at {cutoff:g} Hz")
                  if cutoff else "coordinates not filtered")
    plates = list(inputs.plates)
    q_fit = np.array(tree.forward.map(t.size)(z.T)).T if plates or model.n_con != model.n_dof - tree.n else None
    if plates:
        plates_under_feet(model, plates, t, q_fit)
        fc = inputs.settings.get("cutoff_plates_hz", cutoff)
        report.append(f"plates {', '.join(f'{p.name!r} on {p.node}' for p in plates)}: force and moment about "
                      f"the lab origin filtered {f'at {fc:g} Hz' if fc else 'not at all'}")
    if model.n_con == model.n_dof - tree.n:  # the coordinates decide every dof: rigid segments
        external = (lambda tt, q: plate_loads(model, plates, tt, q)) if plates else None
        sol = rigid_loads(tree, t, z, zd, zdd, model.p_nominal, external)
    else:
        run = model.scene.run
        sol = driven_loads(tree, t, z, plates, q_fit, dt=run.dt if dt is None else dt,
                           alpha=run.alpha if alpha is None else alpha, compiled=compiled)
        report.append(f"flexible segments: driven by HHT (alpha {run.alpha if alpha is None else alpha:g}), the "
                      f"bones' largest deflection {1e3 * sol['deflection'].max():.2f} mm")
    loads = {k: v for k, v in sol.items() if k not in ("q", "qd", "qdd", "lam", "deflection")}
    lab = lab_loads(model.scene, loads)
    loads |= lab
    settings = dict(inputs.settings)
    if lab:  # the summary speaks the lab's language
        settings["moments"] = [lab_name(c) for c in model.scene.coordinates
                               if not c.of.startswith(f"{tree.root}.") and lab_name(c) in lab]
    _check_moments(inputs, {name: loads[name] for name in settings["moments"] if name in loads})
    band, parts = {}, {}
    if inputs.band_spec is not None:
        band, parts, lines, settings["bands"] = inverse_bands(inputs.band_spec, inputs, fit, z, zd, zdd, sorted(loads))
        report += lines
    return InverseResult(t, tree.names, z, zd, zdd, model.dof_names, sol["q"], sol["qd"], sol["qdd"], loads,
                         t, fit.rms, report, settings, warnings, inputs.labels, fit.misfit, inputs.plates, band, parts)


#: m/s^2: the weight the plates' largest total force is taken for (:func:`_check_moments`)
_G = 9.81


def _check_moments(inputs: InverseInputs, moments: dict[str, np.ndarray]) -> None:
    """ValueError when a joint moment exceeds what a body can carry (:func:`casflex.lab.checks.check_moments`):
    the body's mass is the scene's (bodies and beams) or, when larger, the plates' largest total force over g (a
    model of a leg is a third of the subject whose weight the plates carry)."""
    from casflex.lab.checks import check_moments

    sc = inputs.model.scene
    nodes = {n.name: np.array([n.x, n.y]) for n in sc.nodes}
    mass = sum(b.mass for b in sc.bodies) + sum(
        b.rho * b.A * float(np.linalg.norm(nodes[b.nodes[1]] - nodes[b.nodes[0]])) for b in sc.beams)
    if inputs.plates:
        total = sum(np.linalg.norm(p.at(inputs.t)[0], axis=1) for p in inputs.plates)
        mass = max(mass, float(np.nanmax(total)) / _G)
    if mass > 0:
        check_moments(inputs.settings.get("source") or "inverse dynamics", inputs.t, moments, mass)
