"""A casflex scene simulated by Exudyn: an independent code for cross-checks and reference data.

``pip install exudyn`` (the ``peers`` extra). :func:`build` turns a :class:`~casflex.scene.Scene`
into an Exudyn model; :func:`simulate` runs it and returns the motion of the scene's nodes as a
:class:`~casflex.data.MeasurementSet`, the form in which measured data reach identification.

The translation, element by element (the same continuum, another discretisation and integrator):

- beam: ``ObjectANCFCable2D`` elements (Euler-Bernoulli, cubic Hermite position field, consistent
  mass, no rotary inertia; damping beta: Kelvin-Voigt bending and axial damping beta EI, beta EA,
  the continuum of stiffness-proportional damping) on ``NodePoint2DSlope1`` nodes (x, y and the slope vector dr/ds). An
  Euler-Bernoulli beam's nodal rotation is the angle of its slope: theta = theta_0 + (angle of the
  slope now - angle of the slope at t = 0);
- node that is no beam end (a joint node, e.g. twobar's node 1): a slope node, which must be clamped
  (it carries no mass);
- linear spring: ``ObjectConnectorSpringDamper`` between node positions (k, rest length, damper c along
  the spring, as casflex's);
- torsion spring: ``ObjectConnectorTorsionalSpringDamper`` between node frames (kt, damper ct; its offset is the
  rest angle plus the initial angle between the two nodes' slopes, e.g. 90 degrees at a right-angled
  joint, since a slope node's frame is its beam's direction);
- supports: ``CoordinateConstraint``s (Lagrange multipliers, as in casflex); a clamp fixes x, y and
  the slope component across the beam, which needs a beam along x or y (or a joint node, whose
  whole slope is fixed);
- gravity: ``LoadMassProportional`` on every element; constant nodal loads: ``LoadForceVector`` and
  ``LoadTorqueVector``;
- marker on a beam: ``MarkerBodyPosition`` on the ANCF element that holds it, at its distance along
  the element and across the beam (Exudyn's local y, to the left of the beam's direction, as
  casflex's), recorded by ``SensorMarker`` (positions and velocities; channels x<marker>, y<marker>);
- time integration: implicit generalized-alpha without numerical damping (spectral radius 1: the
  trapezoidal rule, as HHT alpha = 0), Newton on the increment to ``newton_tol``.

``beam="ge"`` builds the beams of ``ObjectBeamGeometricallyExact2D`` elements instead (on ``NodeRigidBody2D``
nodes: x, y, theta), a Timoshenko beam with the section's rotary inertia rho I and shear stiffness
kappa G A (kappa = 5/6, G = E / (2 (1 + 0.3))): the continuum of casflex's beam with ``rotary_inertia = true``
up to shear (studies/bench_exudyn.py compares the two). Its nodal rotation is Exudyn's theta; it takes no
beam damping.

What casflex has and this translation does not (:class:`NotImplementedError` naming it): load
tables, follower loads, moving supports, rigid bodies (and markers on them), rotary inertia, a node
where two beams meet, a clamp on a beam end at an angle, a damper on a zero-length spring (casflex
damps its relative velocity, Exudyn along an undefined direction).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from casflex.data import MeasurementSet
from casflex.scene import Scene

__all__ = ["build", "simulate", "ExudynModel"]


def _exudyn():
    try:
        import exudyn
    except ImportError:
        raise ImportError("Exudyn is not installed: pip install exudyn (or casflex's extra 'peers')") from None
    return exudyn


@dataclass
class ExudynModel:
    """An Exudyn system of a scene: ``mbs`` and ``settings`` to solve, and per scene node its
    Exudyn node and reference slope (``nodes``: name -> (node number, (sx, sy)))."""

    system_container: Any
    mbs: Any
    settings: Any
    nodes: dict[str, tuple[int, tuple[float, float]]]
    sensors: dict[str, dict[str, int]]
    h: float
    t_end: float


def _check_supported(scene: Scene, beam: str) -> None:
    if beam not in ("ancf", "ge"):
        raise ValueError(f"beam: {beam!r} is not an Exudyn beam of this translation (ancf, ge)")
    if any(sp.motion is not None for sp in scene.supports):
        raise NotImplementedError("moving supports (motion) are not translated to Exudyn")
    if any(ld.follower for ld in scene.loads):
        raise NotImplementedError("follower loads are not translated to Exudyn")
    if any(len(ld.rows()) > 1 for ld in scene.loads):
        raise NotImplementedError("load tables are not translated to Exudyn (constant loads only)")
    if scene.bodies:
        raise NotImplementedError("rigid bodies are not translated to Exudyn (nor markers on them)")
    if beam == "ancf" and any(b.rotary_inertia for b in scene.beams):
        raise NotImplementedError("rotary inertia: Exudyn's ANCF cable element has none (beam='ge' has)")
    if beam == "ge" and any(b.beta for b in scene.beams):
        raise NotImplementedError("beam damping (beta) on the geometrically exact beam is not translated")
    for sp in scene.springs:
        if sp.point_a is not None or sp.point_b is not None:
            raise NotImplementedError(f"spring {sp.name!r}: ends at points off the nodes are not translated")
        if sp.c and (scene.distance(*sp.nodes) if sp.rest_length is None else sp.rest_length) == 0.0:
            raise NotImplementedError(f"spring {sp.name!r}: a damper on a zero-length spring is not translated")
    ends = [n for b in scene.beams for n in b.nodes]
    shared = sorted({n for n in ends if ends.count(n) > 1})
    if shared:
        raise NotImplementedError(f"nodes {shared}: two beams meet there (a rigid joint between ANCF elements is "
                                  "not translated)")


def build(scene: Scene, *, elements: int, h: float, t_end: float, newton_tol: float = 1e-10, beam: str = "ancf",
          record: tuple[str, ...] | None = None) -> ExudynModel:
    """The Exudyn model of ``scene``: every beam meshed into ``elements`` elements of the Exudyn beam
    ``beam`` ("ancf" or "ge", see the module's docstring), steps of ``h`` s to ``t_end`` s, Newton increments
    to ``newton_tol``; sensors (Coordinates and their rates) of the scene nodes ``record`` (default: every node)
    and of the markers, recording every step."""
    _check_supported(scene, beam)  # before the import: what is not translated is said with or without Exudyn
    exu = _exudyn()
    from exudyn import itemInterface as ii

    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.AddObject(ii.ObjectGround())
    gx, gy = scene.gravity
    nodes: dict[str, tuple[int, tuple[float, float]]] = {}
    objects: dict[str, tuple[Any, float, float, float, list[int]]] = {}  # beam: (node a, L, ex, ey, elements)
    state = {n.name: n for n in scene.nodes}

    def velocity(node, s: float, other, slope: tuple[float, float]) -> list[float]:
        """Initial coordinate rates, interpolated between two scene nodes as casflex's meshing does."""
        vx = (1 - s) * node.vx + s * other.vx
        vy = (1 - s) * node.vy + s * other.vy
        om = (1 - s) * node.omega + s * other.omega
        return [vx, vy, -om * slope[1], om * slope[0]]

    for b in scene.beams:
        na, nb = (state[k] for k in b.nodes)
        L = math.hypot(nb.x - na.x, nb.y - na.y)
        ex, ey = (nb.x - na.x) / L, (nb.y - na.y) / L
        chain = []
        for k in range(elements + 1):
            s = k / elements
            xy, v = [na.x + s * (nb.x - na.x), na.y + s * (nb.y - na.y)], velocity(na, s, nb, (ex, ey))
            chain.append(mbs.AddNode(ii.NodePoint2DSlope1(referenceCoordinates=[*xy, ex, ey], initialVelocities=v)
                                     if beam == "ancf" else ii.NodeRigidBody2D(
                referenceCoordinates=[*xy, math.atan2(ey, ex)],
                initialVelocities=[*v[:2], (1 - s) * na.omega + s * nb.omega])))
        nodes[na.name], nodes[nb.name] = (chain[0], (ex, ey)), (chain[-1], (ex, ey))
        objects[b.name] = (na, L, ex, ey, [])
        for k in range(elements):
            common = {"nodeNumbers": [chain[k], chain[k + 1]], "length": L / elements, "massPerLength": b.rho * b.A,
                      "bendingStiffness": b.E * b.I, "axialStiffness": b.E * b.A}
            obj = mbs.AddObject(ii.ObjectANCFCable2D(**common, bendingDamping=b.beta * b.E * b.I,
                                                     axialDamping=b.beta * b.E * b.A) if beam == "ancf" else
                                ii.ObjectBeamGeometricallyExact2D(**common, crossSectionInertia=b.rho * b.I,
                                                                  shearStiffness=5 / 6 * b.E / 2.6 * b.A,
                                                                  includeReferenceRotations=True))
            objects[b.name][4].append(obj)
            mark = mbs.AddMarker(ii.MarkerBodyMass(bodyNumber=obj))
            mbs.AddLoad(ii.LoadMassProportional(markerNumber=mark, loadVector=[gx, gy, 0.0]))

    supports = {s.node: s for s in scene.supports}
    for el in (*scene.springs, *scene.torsion_springs):  # joint nodes: clamped slope nodes
        for name, other in (el.nodes, el.nodes[::-1]):
            if name in nodes:
                continue
            if name not in supports or supports[name].kind != "clamp":
                raise NotImplementedError(f"node {name!r}: a node that is no beam end must be clamped (it has no mass)")
            slope = nodes[other][1] if other in nodes else (1.0, 0.0)
            nodes[name] = (mbs.AddNode(ii.NodePoint2DSlope1(referenceCoordinates=[state[name].x, state[name].y, *slope])
                                       if beam == "ancf" else ii.NodeRigidBody2D(
                referenceCoordinates=[state[name].x, state[name].y, math.atan2(slope[1], slope[0])])), slope)

    def fix(node: int, coordinate: int) -> None:
        mn = mbs.AddMarker(ii.MarkerNodeCoordinate(nodeNumber=node, coordinate=coordinate))
        mg = mbs.AddMarker(ii.MarkerNodeCoordinate(nodeNumber=mbs.AddNode(ii.NodePointGround()), coordinate=0))
        mbs.AddObject(ii.CoordinateConstraint(markerNumbers=[mg, mn], offset=0.0))

    beam_ends = {n for b in scene.beams for n in b.nodes}
    for s in scene.supports:
        node, (sx, sy) = nodes[s.node]
        coords = [c for d, c in (("x", 0), ("y", 1)) if d in s.dofs]
        if "theta" in s.dofs and beam == "ge":  # a rigid-body node: its rotation is a coordinate
            coords.append(2)
        elif "theta" in s.dofs:
            if s.node not in beam_ends:
                coords += [2, 3]
            elif abs(sx) < 1e-14 or abs(sy) < 1e-14:
                coords.append(3 if abs(sy) < 1e-14 else 2)  # the slope component across the beam
            else:
                raise NotImplementedError(f"support {s.name!r}: a clamped beam end at an angle is not translated")
        for c in coords:
            fix(node, c)

    for sp in scene.springs:
        a, b = sp.nodes
        rest = scene.distance(a, b) if sp.rest_length is None else sp.rest_length
        mbs.AddObject(ii.ObjectConnectorSpringDamper(
            markerNumbers=[mbs.AddMarker(ii.MarkerNodePosition(nodeNumber=nodes[n][0])) for n in (a, b)],
            referenceLength=rest, stiffness=sp.k, damping=sp.c))
    for ts in scene.torsion_springs:
        a, b = ts.nodes
        rest = state[b].theta - state[a].theta if ts.rest_angle is None else ts.rest_angle
        # Exudyn's angle is that of node b's frame relative to node a's, the frames of slope (and of ge)
        # nodes being the beam directions: psi = psi_0 + theta - theta_0, so kt (theta_b - theta_a - rest) is
        # kt (psi_b - psi_a - offset) with this offset
        psi = {n: math.atan2(nodes[n][1][1], nodes[n][1][0]) for n in (a, b)}
        offset = rest + (psi[b] - psi[a]) - (state[b].theta - state[a].theta)
        mbs.AddObject(ii.ObjectConnectorTorsionalSpringDamper(
            markerNumbers=[mbs.AddMarker(ii.MarkerNodeRigid(nodeNumber=nodes[n][0])) for n in (a, b)],
            stiffness=ts.kt, damping=ts.ct, offset=offset))
    for ld in scene.loads:
        node = nodes[ld.node][0]
        if ld.fx or ld.fy:
            mbs.AddLoad(ii.LoadForceVector(markerNumber=mbs.AddMarker(ii.MarkerNodePosition(nodeNumber=node)),
                                           loadVector=[ld.fx, ld.fy, 0.0]))
        if ld.mz:
            mbs.AddLoad(ii.LoadTorqueVector(markerNumber=mbs.AddMarker(ii.MarkerNodeRigid(nodeNumber=node)),
                                            loadVector=[0.0, 0.0, ld.mz]))
    del ground

    out = exu.OutputVariableType
    sensors = {name: {kind: mbs.AddSensor(ii.SensorNode(nodeNumber=node, storeInternal=True, writeToFile=False,
                                                        outputVariableType=getattr(out, kind)))
                      for kind in ("Coordinates", "Coordinates_t", "Coordinates_tt")}
               for name, (node, _) in nodes.items() if record is None or name in record}
    for mk in scene.markers:  # on a beam (bodies are refused): the element's point at (along, across)
        na, L, ex, ey, objs = objects[mk.on]
        along = (mk.x - na.x) * ex + (mk.y - na.y) * ey
        k = min(int(along / L * elements), elements - 1)
        local = [along - k * L / elements, -(mk.x - na.x) * ey + (mk.y - na.y) * ex, 0.0]
        number = mbs.AddMarker(ii.MarkerBodyPosition(bodyNumber=objs[k], localPosition=local))
        sensors[f"marker {mk.name}"] = {kind: mbs.AddSensor(ii.SensorMarker(
            markerNumber=number, storeInternal=True, writeToFile=False, outputVariableType=getattr(out, kind)))
            for kind in ("Position", "Velocity")}
    mbs.Assemble()

    ss = exu.SimulationSettings()
    ti = ss.timeIntegration
    ti.numberOfSteps = int(round(t_end / h))
    ti.endTime = t_end
    ti.verboseMode = 0
    ti.generalizedAlpha.spectralRadius = 1.0
    ti.newton.residualMode = 1  # tolerance on the Newton increment
    ti.newton.relativeTolerance = ti.newton.absoluteTolerance = newton_tol
    ss.solution.file.write = False
    ss.solution.sensors.writePeriod = h
    ss.show.computationTime = False
    ss.show.statistics = False
    return ExudynModel(SC, mbs, ss, nodes, sensors, h, t_end)


def simulate(scene: Scene, t_end: float, *, elements: int = 8, h: float = 1e-4, sample_dt: float = 1e-3,
             newton_tol: float = 1e-10, beam: str = "ancf") -> MeasurementSet:
    """Exudyn's motion of ``scene`` from t = 0 to ``t_end`` s, sampled every ``sample_dt`` s.

    Parameters
    ----------
    scene : Scene
        Its current property values are simulated (e.g. ``scene.with_values(k1=800)``).
    elements : int
        Elements per beam.
    beam : str
        "ancf" (Euler-Bernoulli, no rotary inertia) or "ge" (geometrically exact, with shear and rotary
        inertia); see the module's docstring.
    h, sample_dt : float, s
        Integration step and sample spacing (a whole number of steps).

    Returns
    -------
    MeasurementSet
        Channels ``x<node>``, ``y<node>``, ``theta<node>`` of every scene node (casflex's dof names);
        q (m, rad), qd (m/s, rad/s), qdd (m/s^2, rad/s^2), shape (n_samples, 3 n_nodes);
        ``meta`` records the code, version and settings.
    """
    exu = _exudyn()
    every = int(round(sample_dt / h))
    if every < 1 or abs(every * h - sample_dt) > 1e-9 * sample_dt:
        raise ValueError(f"sample_dt: {sample_dt:g} s is not a whole number of steps h = {h:g} s")
    m = build(scene, elements=elements, h=h, t_end=t_end, newton_tol=newton_tol, beam=beam)
    if not m.mbs.SolveDynamic(m.settings):
        raise RuntimeError("Exudyn's dynamic solver failed")
    n = int(round(t_end / h))
    rows = np.arange(0, n + 1, every)
    channels, cols = [], {"q": [], "qd": [], "qdd": []}
    t = None
    for node in scene.nodes:
        number, (sx0, sy0) = m.nodes[node.name]
        ref = np.array(m.mbs.GetNodeParameter(number, "referenceCoordinates"), dtype=float)
        c, c_t, c_tt = (np.asarray(m.mbs.GetSensorStoredData(m.sensors[node.name][k]))[rows]
                        for k in ("Coordinates", "Coordinates_t", "Coordinates_tt"))
        t = c[:, 0]
        if beam == "ge":  # a rigid-body node: x, y and its rotation psi, psi(0) the beam's direction
            x, y, psi = (ref[None, :] + c[:, 1:4]).T
            (vx, vy, omega), (ax, ay, alpha) = c_t[:, 1:4].T, c_tt[:, 1:4].T
            theta = node.theta + psi - ref[2]
        else:
            x, y, sx, sy = (ref[None, :] + c[:, 1:5]).T
            vx, vy, sxd, syd = c_t[:, 1:5].T
            ax, ay, sxdd, sydd = c_tt[:, 1:5].T
            s2 = sx**2 + sy**2
            cross_d = sx * syd - sy * sxd
            theta = node.theta + np.unwrap(np.arctan2(sy, sx)) - math.atan2(sy0, sx0)
            omega = cross_d / s2
            # d/dt (s x s' / |s|^2)
            alpha = (sx * sydd - sy * sxdd) / s2 - 2 * cross_d * (sx * sxd + sy * syd) / s2**2
        channels += [f"x{node.name}", f"y{node.name}", f"theta{node.name}"]
        cols["q"] += [x, y, theta]
        cols["qd"] += [vx, vy, omega]
        cols["qdd"] += [ax, ay, alpha]
    for mk in scene.markers:  # positions and velocities; Exudyn reports no marker accelerations (NaN)
        c, c_t = (np.asarray(m.mbs.GetSensorStoredData(m.sensors[f"marker {mk.name}"][k]))[rows]
                  for k in ("Position", "Velocity"))
        channels += [f"x{mk.name}", f"y{mk.name}"]
        cols["q"] += [c[:, 1], c[:, 2]]
        cols["qd"] += [c_t[:, 1], c_t[:, 2]]
        cols["qdd"] += [np.full(c.shape[0], np.nan)] * 2
    return MeasurementSet(t, tuple(channels), *(np.column_stack(cols[k]) for k in ("q", "qd", "qdd")),
                          source="exudyn",
                          meta={"code": f"Exudyn {exu.__version__}", "beam": beam, "elements": elements, "h": h,
                                "integrator": "generalized-alpha, spectral radius 1", "newton_tol": newton_tol,
                                "scene": scene.name})
