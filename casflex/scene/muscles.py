"""Muscles of a scene, pure data: each muscle's properties as its OpenSim model gives them and its path.

A planar scene made of an OpenSim model (:mod:`casflex.scene.from_osim`) carries the model's muscles: what
:mod:`casflex.muscles` needs to compute their lengths, moment arms (exact, by AD of the path's length) and
forces. Numbers only here; the CasADi geometry is :mod:`casflex.muscles.path`'s, the force-length-velocity
curves :mod:`casflex.muscles.curves`'.

Frames. Each path point sits on a body of the OpenSim model, at ``location`` (m) in that body's frame. The
body's frame in the ground at the scene's initial configuration (the model's default pose) is ``frame``:
the rotation R (3 x 3, row-major) and the origin p (m), so that the point is at ``p + R @ location`` in the
ground there. The scene moves the body with its node (``node``): a rotation about the plane's normal and a
translation in the plane, so the point's out-of-plane coordinate z (m, the ground's z) stays what it was
in the default pose and the path's length is measured in 3D, as OpenSim measures it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from casflex.scene.functions import Function

__all__ = ["MUSCLE_KINDS", "QUADRANTS", "Muscle", "PathPoint", "Wrap"]

#: The muscle models casflex computes, by their OpenSim class names.
MUSCLE_KINDS = ("Millard2012EquilibriumMuscle", "Thelen2003Muscle", "DeGrooteFregly2016Muscle")

#: OpenSim's quadrant names of a wrap object (WrapObject::setupQuadrant) -> (axis 0-2, sign; 0 for all quadrants).
QUADRANTS = {**{q: (0, -1) for q in ("-x", "-X")}, **{q: (0, 1) for q in ("x", "+x", "X", "+X")},
             **{q: (1, -1) for q in ("-y", "-Y")}, **{q: (1, 1) for q in ("y", "+y", "Y", "+Y")},
             **{q: (2, -1) for q in ("-z", "-Z")}, **{q: (2, 1) for q in ("z", "+z", "Z", "+Z")},
             **{q: (0, 0) for q in ("all", "ALL", "All", "Unassigned")}}


@dataclass(frozen=True)
class PathPoint:
    """A point of a muscle's path (OpenSim's PathPoint, ConditionalPathPoint or MovingPathPoint).

    name : the OpenSim point's name
    node : the scene node whose motion the point's body follows
    location : (x, y, z) m in the body's frame (a MovingPathPoint's: its value at the default pose)
    frame : the body's frame in the ground at the default pose: R (9 numbers, row-major), then p (3 numbers, m)
    condition : (coordinate, lower, upper): a ConditionalPathPoint, on the path only while the scene's lab
        coordinate (``[[coordinates]]`` name) is within [lower, upper] (rad or m); None: always on the path
    moving : ((axis, coordinate, function), ...): a MovingPathPoint's location component ``axis`` (0, 1, 2: x, y,
        z in the body's frame) as ``function`` of the lab coordinate ``coordinate``; the components not listed
        are ``location``'s
    """

    name: str
    node: str
    location: tuple[float, float, float]
    frame: tuple[float, ...]
    condition: tuple[str, float, float] | None = None
    moving: tuple[tuple[int, str, Function], ...] = ()


@dataclass(frozen=True)
class Wrap:
    """A wrap object a muscle's path may wrap over, kept where the wrapping stays in the plane: a cylinder whose
    axis is the plane's normal wraps as a circle of ``radius`` (m) (:mod:`casflex.muscles.wrap`), on ``node``.

    centre : the cylinder's centre (x, y, z in the ground at the default pose, m)
    frame : the cylinder's frame in the ground at the default pose: R (9 numbers, row-major; its columns the
        cylinder's x, y and z axes, z the plane's normal or its opposite), then p (3 numbers, m: ``centre``)
    quadrant : OpenSim's (e.g. "+x", "-y", "all"), in the cylinder's own axes (OpenSim's meaning)
    points : the range of the path's points (1-based, inclusive, as OpenSim's PathWrap ``range`` but counted in
        the scene's ``Muscle.path``; (-1, -1) the whole path) between which it applies
    length : the cylinder's length along its axis (m): a segment whose two points both lie beyond its ends does not
        wrap (OpenSim's test on the tangent points, at the points' depths)
    """

    name: str
    node: str
    radius: float
    centre: tuple[float, float, float]
    frame: tuple[float, ...]
    quadrant: str = "all"
    points: tuple[int, int] = (-1, -1)
    length: float = math.inf


@dataclass(frozen=True)
class Muscle:
    """A muscle of the model (its ForceSet's), with its OpenSim class ``kind`` (:data:`MUSCLE_KINDS`).

    max_isometric_force : N
    optimal_fiber_length : m
    tendon_slack_length : m
    pennation_angle_at_optimal : rad
    max_contraction_velocity : optimal fibre lengths per second
    properties : the model's other numbers for this muscle, as (XML tag, value) pairs, e.g. Millard's curves'
        ``ActiveForceLengthCurve.min_norm_active_fiber_length`` or Thelen's ``FmaxTendonStrain``; a tag the file
        does not give is absent (its OpenSim default applies: :mod:`casflex.muscles.curves`)
    path : the path's points from origin to insertion
    wraps : the wraps the path may wrap over
    """

    name: str
    kind: str
    max_isometric_force: float
    optimal_fiber_length: float
    tendon_slack_length: float
    pennation_angle_at_optimal: float
    max_contraction_velocity: float
    path: tuple[PathPoint, ...]
    properties: tuple[tuple[str, float], ...] = ()
    wraps: tuple[Wrap, ...] = ()

    def property(self, tag: str, default: float) -> float:
        """The model's value of ``tag`` (e.g. ``FmaxTendonStrain``), or ``default`` (OpenSim's) where absent."""
        return next((v for k, v in self.properties if k == tag), default)
