"""casflex.peers.exudyn's geometrically exact beam: the same motion as casflex's beam with rotary inertia."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import casflex
from casflex.simulate import Stepping, simulate


def _meshed(scene, elements: int, rotary: bool):
    return dataclasses.replace(scene, beams=tuple(dataclasses.replace(b, elements=elements, rotary_inertia=rotary)
                                                  for b in scene.beams))


def test_ge_beam_moves_as_casflex_beam_with_rotary_inertia():
    pytest.importorskip("exudyn")
    from casflex.peers.exudyn import simulate as exudyn_simulate

    scene = casflex.load_scene("twobar")
    ms = exudyn_simulate(scene, 0.2, elements=8, h=1e-4, sample_dt=1e-3, beam="ge")
    rows = np.round(ms.t / 1e-4).astype(int)
    cols = [ms.channels.index(c) for c in ("x3", "y3", "x5", "y5")]

    def gap(rotary: bool) -> float:
        tr = simulate(casflex.assemble(_meshed(scene, 4, rotary)), 0.2, stepping=Stepping(dt=1e-4))
        return float(np.abs(ms.q[:, cols] - tr.q[rows][:, [tr.dof_names.index(c) for c in ("x3", "y3", "x5", "y5")]])
                     .max())

    # measured 3e-8 m (the shear the casflex beam lacks, two meshes); without rotary inertia 3.3e-5 m
    assert gap(True) < 1e-6
    assert gap(False) > 1e-5


def test_exudyn_translation_names_an_unknown_beam_and_ancf_without_rotary_inertia():
    from casflex.peers.exudyn import build

    scene = casflex.load_scene("twobar")
    with pytest.raises(ValueError, match="beam: 'timoshenko'"):
        build(scene, elements=1, h=1e-3, t_end=0.1, beam="timoshenko")
    with pytest.raises(NotImplementedError, match="rotary inertia"):
        build(_meshed(scene, 1, True), elements=1, h=1e-3, t_end=0.1)


def _body_and_strip_exudyn(elements: int, h: float, t_end: float, *, mass, inertia, lb, strip):
    """Exudyn's model of ``test_a_strip_hinged_to_a_rigid_body_moves_as_in_exudyn``: a RigidBody2D pinned to the
    ground by a RevoluteJoint2D, an ANCF strip hinged to its tip by another. (t, tip position, joint force)."""
    import exudyn as exu
    from exudyn import itemInterface as ii

    E, A, I, rho, lf = strip  # noqa: E741
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.AddObject(ii.ObjectGround())
    body = mbs.AddObject(ii.ObjectRigidBody2D(mass=mass, inertia=inertia, nodeNumber=mbs.AddNode(
        ii.NodeRigidBody2D(referenceCoordinates=[lb / 2, 0, 0]))))

    def at(obj, x):
        return mbs.AddMarker(ii.MarkerBodyPosition(bodyNumber=obj, localPosition=[x, 0, 0]))

    def weigh(obj):
        mbs.AddLoad(ii.LoadMassProportional(markerNumber=mbs.AddMarker(ii.MarkerBodyMass(bodyNumber=obj)),
                                            loadVector=[0, -9.81, 0]))

    weigh(body)
    mbs.AddObject(ii.ObjectJointRevolute2D(markerNumbers=[at(ground, 0.0), at(body, -lb / 2)]))
    chain = [mbs.AddNode(ii.NodePoint2DSlope1(referenceCoordinates=[lb + k * lf / elements, 0, 1, 0]))
             for k in range(elements + 1)]
    for k in range(elements):
        weigh(mbs.AddObject(ii.ObjectANCFCable2D(nodeNumbers=[chain[k], chain[k + 1]], length=lf / elements,
                                                 massPerLength=rho * A, bendingStiffness=E * I, axialStiffness=E * A)))
    hinge = mbs.AddObject(ii.ObjectJointRevolute2D(markerNumbers=[
        at(body, lb / 2), mbs.AddMarker(ii.MarkerNodePosition(nodeNumber=chain[0]))]))
    out = exu.OutputVariableType
    s_tip = mbs.AddSensor(ii.SensorNode(nodeNumber=chain[-1], storeInternal=True, writeToFile=False,
                                        outputVariableType=out.Coordinates))
    s_force = mbs.AddSensor(ii.SensorObject(objectNumber=hinge, storeInternal=True, writeToFile=False,
                                            outputVariableType=out.Force))
    mbs.Assemble()
    ss = exu.SimulationSettings()
    ti = ss.timeIntegration
    ti.numberOfSteps, ti.endTime, ti.verboseMode = int(round(t_end / h)), t_end, 0
    ti.generalizedAlpha.spectralRadius = 1.0  # the trapezoidal rule, as HHT at alpha = 0
    ti.newton.residualMode = 1
    ti.newton.relativeTolerance = ti.newton.absoluteTolerance = 1e-10
    ss.solution.file.write = False
    ss.solution.sensors.writePeriod = h
    exu.SolveDynamic(mbs, ss)
    tip, force = mbs.GetSensorStoredData(s_tip), mbs.GetSensorStoredData(s_force)
    return tip[:, 0], tip[:, 1:3] + [lb + lf, 0.0], force[:, 1:3]


def test_a_strip_hinged_to_a_rigid_body_moves_as_in_exudyn():
    """A rigid link (2 kg, 0.4 m) pinned to the ground and a steel strip (0.8 m) hinged to its tip, released
    horizontal: casflex's hinges against Exudyn's RevoluteJoint2D, 1 s at dt = 1e-4, both undamped. The
    strip's tip and the hinge's force (filtered over 5 ms: both codes' undamped axial modes ring at their
    own mesh's frequencies) agree as the meshes are refined."""
    pytest.importorskip("exudyn")
    from scipy.ndimage import uniform_filter1d

    from casflex import Beam, Joint, Node, RigidBody, Scene

    mass, inertia, lb, h, t_end = 2.0, 0.02, 0.4, 1e-4, 1.0
    strip = (2.1e11, 1e-4, 2e-10, 7800.0, 0.8)
    gap, force = {}, {}
    for elements in (8, 16):
        scene = Scene(name="body_and_strip", nodes=(Node("o", 0, 0), Node("p", lb, 0), Node("e", lb + strip[4], 0)),
                      beams=(Beam("strip", ("p", "e"), *strip[:4], elements=elements),),
                      bodies=(RigidBody("link", "o", mass, inertia, com_x=lb / 2, com_y=0.0),),
                      joints=(Joint("pin", "hinge", ("o",)), Joint("h", "hinge", ("o", "p"))))
        model = casflex.assemble(scene)
        tr = simulate(model, t_end, stepping=Stepping(dt=h, alpha=0.0, compiled=True))
        t, tip, f_exu = _body_and_strip_exudyn(elements, h, t_end, mass=mass, inertia=inertia, lb=lb, strip=strip)
        k = np.round(t / h).astype(int)
        gap[elements] = np.abs(tr.q[k][:, [model.dof("xe"), model.dof("ye")]] - tip).max()
        f = np.column_stack([tr.output("h.fx"), tr.output("h.fy")])[k]  # on the strip from the link
        # Exudyn's joint force acts on its first marker (the link): the opposite
        force[elements] = np.abs(uniform_filter1d(f, 50, axis=0) + uniform_filter1d(f_exu, 50, axis=0)).max()
    # both codes converge to the same continuum at order 2 in the mesh: measured 2.2e-5 and 5.4e-6 m (tip
    # range 1.8 m); the force 0.045 and 0.0044 N of up to 44 N
    assert 3.0 < gap[8] / gap[16] < 5.5 and gap[16] < 1e-5, gap
    assert force[16] < 0.02, force
