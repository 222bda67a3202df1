"""Inverse dynamics from a lab trial: net joint moments, intersegmental forces and root residuals.

The choices are values (:mod:`casflex.inverse.options`: :class:`Trial`, :class:`Filter`, :class:`Fit`,
:class:`Bands`, :class:`Flexible`), each checking its own fields. The data flow (docs/lab.md, "Inverse dynamics"):

0. the inputs read and checked before any work (:mod:`casflex.inverse.inputs`: corrupted files, markers
   no body produces, plates that do not cover the trial, options that cannot be honoured);
1. the trial's markers, projected on the model's plane (:mod:`casflex.lab`), matched to the scene's
   ``[[markers]]`` by label (or the coordinates given in a table, :mod:`casflex.inverse.given`: steps 1-2
   skipped);
2. per frame, the coordinates of the scene's kinematic tree (root pose and hinge angles) that fit
   them best (:mod:`casflex.inverse.fit`), gaps filled and reported;
3. the coordinates and the force plates filtered by a zero-lag Butterworth (:class:`Filter`), at one cut-off
   (``cutoff``, the default: kinematics and forces filtered alike keep impact artefacts out of the moments,
   Kristianslund et al. 2012) or each at its own (``cutoff_plates``; None: the plates unfiltered, as OpenSim's ID
   tool); the coordinates by Winter's 4th-order filter or, ``kind="opensim"``, by OpenSim's ID tool's; their
   rates by 7-point central differences;
4. each plate's line of force checked to pass near its node over its stance (the fitted pose:
   :func:`casflex.lab.plate_checks.check_plate_foot`); the loads that make the scene follow that motion under
   the plates' forces: exact per frame for
   rigid segments (:mod:`casflex.inverse.rigid`); with flexible ones (beams), the scene driven along
   the motion by HHT, the bones' deflections from its dynamics (:mod:`casflex.inverse.flexible`);
5. where asked (:class:`Bands`: uncertain properties, the markers' noise), each load's band, one standard
   deviation, from the anthropometry's uncertainty and from the markers' noise (:mod:`casflex.inverse.bands`;
   rigid segments).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from casflex.inverse.bands import band_spec, inverse_bands
from casflex.inverse.fit import FittedMotion, filtered_rates, fit_markers
from casflex.inverse.flexible import driven_loads
from casflex.inverse.inputs import InverseInputs, inverse_model, prepare
from casflex.inverse.lab_names import lab_coordinates, lab_loads, lab_name
from casflex.inverse.options import BandError, Bands, Filter, Fit, Flexible, OptionRefused, Trial
from casflex.inverse.plates import Plate, plate_loads, plates_under_feet
from casflex.inverse.result import InverseResult
from casflex.inverse.rigid import rigid_loads
from casflex.inverse.tree import KinematicTree, kinematic_tree

__all__ = ["BandError", "Bands", "Filter", "Fit", "Flexible", "InverseInputs", "InverseResult", "KinematicTree",
           "OptionRefused", "Plate", "Trial", "inverse_dynamics", "inverse_model", "kinematic_tree", "prepare", "solve"]


def inverse_dynamics(scene, trial: Trial, *, filter: Filter | None = None, fit: Fit | None = None,
                     bands: Bands | None = None, flexible: Flexible | None = None,
                     progress: Callable[[int, int], None] | None = None) -> InverseResult:
    """Net joint moments, intersegmental forces and root loads of ``scene`` over a trial.

    Parameters
    ----------
    scene : Scene, scene name or path (a TOML scene or an OpenSim model)
        Rigid segments (bodies on nodes) joined by hinges in a tree, ``[[markers]]`` labelled as the trial's.
    trial : Trial
        The trial's markers (or its coordinates), ground reactions and the node each plate acts on, the lab's
        plane, the root, the window and the markers' weights (:class:`casflex.inverse.options.Trial`).
    filter : Filter, optional
        The coordinates' and the plates' zero-lag low-pass (kind, cut-offs in Hz; default ``Filter()``: 6 Hz).
    fit : Fit, optional
        The marker fit's limits (the longest gap filled, s; the largest misfit taken, m).
    bands : Bands, optional
        Each load's band, one standard deviation (uncertain properties, the markers' noise; asked or not).
    flexible : Flexible, optional
        Flexible segments only: the HHT step (s), alpha and compiled C.
    (None: the object's defaults.)
    progress : callable(done, total), optional
        Called as the marker fit goes frame by frame.

    Every input is read and checked before the marker fit (:func:`prepare`); ValueError in one line naming
    the option, file, marker or plate otherwise.
    """
    inputs = prepare(scene, trial, filter=filter, fit=fit, bands=bands, flexible=flexible)
    return solve(inputs, flexible=flexible, progress=progress)


def _given(inputs: InverseInputs) -> FittedMotion:
    """The coordinates given (no marker fit): no misfit to report."""
    n = inputs.t.size
    return FittedMotion(inputs.t, inputs.z, np.full(n, np.nan), np.zeros(n, dtype=int), [], np.zeros((n, 0)))


def solve(inputs: InverseInputs, *, bands: Bands | None = None, flexible: Flexible | None = None,
          progress: Callable[[int, int], None] | None = None) -> InverseResult:
    """The inverse dynamics of checked inputs (:func:`prepare`): the marker fit, the filter, the rates and the
    loads (module docstring), and their bands; ``bands``, where given, replace what :func:`prepare` was asked
    (checked first); ``flexible`` and ``progress`` as :func:`inverse_dynamics`'s."""
    if bands is not None:
        inputs = dataclasses.replace(inputs, band_spec=band_spec(
            inputs.model, inputs.tree, bands, given=inputs.z is not None,
            n_markers=sum(m.weight > 0 for m in inputs.model.scene.markers)))
    model, tree, t, cutoff = inputs.model, inputs.tree, inputs.t, inputs.cutoff
    fit = _given(inputs) if inputs.z is not None else fit_markers(
        tree, t, inputs.y, max_gap=inputs.fit.max_gap, max_misfit=inputs.fit.misfit, labels=inputs.labels,
        source=inputs.settings["source"], progress=progress)
    report = [*inputs.report, *fit.report]
    warnings = [*inputs.warnings, *(line for line in fit.report if line.startswith("gaps:"))]
    z, zd, zdd = filtered_rates(t, fit.z, cutoff, inputs.filter.kind)
    report.append(inputs.filter.describe())
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
        flexible = flexible or Flexible()
        dt, alpha = flexible.of(model.scene)
        sol = driven_loads(tree, t, z, plates, q_fit, dt=dt, alpha=alpha, compiled=flexible.compiled)
        report.append(f"flexible segments: driven by HHT (alpha {alpha:g}), the "
                      f"bones' largest deflection {1e3 * sol['deflection'].max():.2f} mm")
    loads = {k: v for k, v in sol.items() if k not in ("q", "qd", "qdd", "lam", "deflection")}
    lab = lab_loads(model.scene, loads)
    loads |= lab
    settings = dict(inputs.settings)
    if lab:  # the summary speaks the lab's language
        settings["moments"] = [lab_name(c) for c in model.scene.coordinates
                               if not c.of.startswith(f"{tree.root}.") and lab_name(c) in lab]
    forces = _check_moments(inputs, {name: loads[name] for name in settings["moments"] if name in loads}, loads)
    forces += _plate_share(inputs, plates, loads)
    report += forces
    warnings += forces
    band, parts = {}, {}
    fitted, units = lab_coordinates(model.scene, tree.names, fit.z)  # the IK result, unfiltered
    if inputs.band_spec is not None:
        band, parts, lines, settings["bands"] = inverse_bands(inputs.band_spec, inputs, fit, z, zd, zdd, sorted(loads))
        report += lines
    return InverseResult(t=t, coordinate_names=tree.names, z=z, zd=zd, zdd=zdd, dof_names=model.dof_names, q=sol["q"],
                         qd=sol["qd"], qdd=sol["qdd"], loads=loads, frame_t=t, marker_rms=fit.rms, report=report,
                         settings=settings, warnings=warnings, marker_labels=inputs.labels, marker_misfit=fit.misfit,
                         plates=inputs.plates, bands=band, band_parts=parts, fitted=fitted, fitted_units=units)



def _plate_share(inputs: InverseInputs, plates: list[Plate], loads: dict[str, np.ndarray]) -> list[str]:
    """The line that says the plates push far more or less than the motion needs of the ground
    (:func:`casflex.lab.checks.plate_share_lines`): their forces and the root's residual along the model's up."""
    from casflex.lab.checks import plate_share_lines
    from casflex.lab.plate_checks import weight_up

    up = weight_up(inputs.model.scene.gravity)
    if not plates or "root.fx" not in loads or up is None:
        return []
    pushed = sum(p.at(inputs.t)[0] for p in plates) @ up
    residual = loads["root.fx"] * up[0] + loads["root.fy"] * up[1]
    return plate_share_lines(inputs.settings.get("source") or "inverse dynamics", inputs.t, pushed, pushed + residual)


#: m/s^2: the weight the plates' largest total force is taken for (:func:`_check_moments`)
_G = 9.81


def _check_moments(inputs: InverseInputs, moments: dict[str, np.ndarray], loads: dict[str, np.ndarray]) -> list[str]:
    """ValueError when a joint moment exceeds what a body can carry (:func:`casflex.lab.checks.check_moments`);
    the lines that say a joint's force (``loads``' ``<joint>.fx``, ``.fy``) exceeds what a joint passes on
    (:func:`casflex.lab.checks.joint_force_lines`). The body's mass is the scene's (bodies and beams) or, when
    larger, the plates' largest total force over g (a model of a leg is a third of the subject whose weight the
    plates carry)."""
    from casflex.lab.checks import check_moments, joint_force_lines

    sc = inputs.model.scene
    nodes = {n.name: np.array([n.x, n.y]) for n in sc.nodes}
    mass = sum(b.mass for b in sc.bodies) + sum(
        b.rho * b.A * float(np.linalg.norm(nodes[b.nodes[1]] - nodes[b.nodes[0]])) for b in sc.beams)
    if inputs.plates:
        total = sum(np.linalg.norm(p.at(inputs.t)[0], axis=1) for p in inputs.plates)
        mass = max(mass, float(np.nanmax(total)) / _G)
    if not mass > 0:
        return []
    source = inputs.settings.get("source") or "inverse dynamics"
    check_moments(source, inputs.t, moments, mass)
    joints = [k[:-3] for k in loads if k.endswith(".fx") and k != "root.fx" and f"{k[:-3]}.fy" in loads]
    return joint_force_lines(source, inputs.t, {j: np.hypot(loads[f"{j}.fx"], loads[f"{j}.fy"]) for j in joints}, mass)
