"""Muscles on a lab's trial: what the muscles crossing each joint carry, and the force each joint then bears.

The data flow (docs/muscles.md):

1. the model's muscles, read with its .osim (:mod:`casflex.scene.muscles`: pure data);
2. their paths' lengths and moment arms along the lab's coordinates, exact by AD of the length
   (:mod:`casflex.muscles.path`);
3. their force-length-velocity curves, OpenSim's (:mod:`casflex.muscles.curves`);
4. the activations that carry the inverse dynamics' joint moments at least cost (static optimization,
   :mod:`casflex.muscles.static_optimization`);
5. the force and moment each joint bears: the net intersegmental load plus every muscle crossing it
   (:mod:`casflex.muscles.reaction`); a trial end to end: :mod:`casflex.muscles.analysis`;
6. each output's band, one standard deviation, from the muscles' uncertain properties, the anthropometry and the
   markers' noise, and beside it the spread between static optimization's criteria (:mod:`casflex.muscles.bands`).

:func:`muscle_analysis` runs them on a lab trial; :mod:`casflex.muscles.analysis` is the same frame by frame.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from casflex.inverse import Filter, Fit, Trial
    from casflex.muscles.reaction import JointReaction
    from casflex.muscles.result import MuscleResult
    from casflex.muscles.static_optimization import StaticOptimization

__all__ = ["muscle_analysis"]


def muscle_analysis(model, trial: Trial, *, filter: Filter | None = None, fit: Fit | None = None,
                    optimization: StaticOptimization | None = None, reaction: JointReaction | None = None,
                    joints: tuple[str, ...] = (), actuators=None) -> MuscleResult:
    """The muscles of a lab trial: static optimization over its inverse dynamics and the joints' reactions.

    model : path of an OpenSim model (.osim) with Millard2012EquilibriumMuscle, Thelen2003Muscle or
        DeGrooteFregly2016Muscle muscles (read with them: :func:`casflex.scene.from_osim.scene_from_osim`)
    trial, filter, fit : what :func:`casflex.inverse.inverse_dynamics` takes (the markers or coordinates, the
        plates, the filter; :mod:`casflex.inverse.options`)
    optimization : static optimization's choices (exponent, force-length-velocity, bounds;
        :class:`~casflex.muscles.static_optimization.StaticOptimization`)
    reaction : on which body and in which frame the reactions are given, N or body weights
        (:class:`~casflex.muscles.reaction.JointReaction`); ``joints`` the hinges reported (() every one)
    actuators : an OpenSim actuator file (reserves and residuals, e.g. a pipeline's ``*_Reserve_Actuators.xml``),
        added to the model's own actuators as OpenSim's ``replace_force_set`` false does; or a number: a reserve of
        that optimal force (N m, N) on every joint coordinate and the residuals FX, FY, MZ on the root
        (:func:`casflex.muscles.analysis.reserve_actuators`); None: the model's own only

    ValueError in one line naming the file, option, muscle or frame for what cannot be honoured, before the work
    where the inputs can tell.
    """
    from casflex.inverse import prepare, solve
    from casflex.muscles.analysis import TrialMuscles, muscle_result, reserve_actuators, residual_warnings
    from casflex.scene.from_osim import scene_from_osim
    from casflex.scene.osim_actuators import read_actuators

    osim = scene_from_osim(model, muscles=True)
    inputs = prepare(model, trial, filter=filter, fit=fit)
    extra = () if actuators is None else reserve_actuators(osim.scene, inputs.tree.root, actuators) \
        if isinstance(actuators, (int, float)) else read_actuators(actuators)
    acts = read_actuators(model) + extra
    muscles = TrialMuscles(osim, inputs.tree, inputs.t, inputs.plates, acts, optimization=optimization,
                           reaction=reaction, joints=joints, source=str(actuators or model))
    res = solve(inputs)
    out = muscles.solve(res.z, res.zd, res.zdd)
    return muscle_result(muscles, out, res.z, report=(*res.report, *muscles.notes, *_so_lines(out),
                                                      *residual_warnings(muscles, out)))


def _so_lines(out) -> tuple[str, ...]:
    """The report's lines of static optimization (frames it could not satisfy), if any."""
    return tuple(line for line in (out.so.report,) if line)
