"""Writes the reference motions in this folder: casflex's built-in scenes simulated by another code.

    python tests/data/make_reference_data.py        # needs Exudyn: pip install -e '.[peers]'

For each scene (the built-in twobar and threelink, and twobar_damped.toml here: twobar with dampers
in its joints), Exudyn (:mod:`casflex.peers.exudyn`: ANCF cable elements, generalized-alpha
without damping) simulates 0-4 s with 8 elements per beam and h = 1e-4 s, Newton increments to
1e-10, and every node's x, y, theta and their rates are kept at 1 kHz (``<scene>_exudyn.npz``:
keys t, channels, q, qd, meta). The file's own error is measured against a run with 16
elements per beam and h = 5e-5 s and recorded in ``meta`` (``error_xy``, m, and ``error_theta``, rad:
max over samples and channels). These are the "measurements" the identification tests and
``studies/realdata.py`` fit with casflex's own, different, discretisation. Without arguments it also
writes ``cantilever_damped_exudyn.npz`` (:func:`make_cantilever`), the check of beam damping, and
``twobar_markers_exudyn.npz`` (:func:`make_markers`), the check of markers on beams, and
``forms_exudyn.npz`` (:func:`make_forms`), recordings of other model forms than the scenes', and
``knee_pendulum_exudyn.npz`` (:func:`make_knee_pendulum`), the built-in knee_pendulum's markers written
directly in Exudyn (its translation of casflex scenes takes no rigid bodies).
"""

from __future__ import annotations

import io
import json
import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SCENES = ("twobar", "threelink", str(HERE / "twobar_damped.toml"))
T_END = 4.0


def make(scene_name: str) -> Path:
    import casflex
    from casflex.peers import exudyn
    from casflex.results import atomic_write_bytes

    scene = casflex.load_scene(scene_name)
    scene_name = Path(scene_name).stem
    data = exudyn.simulate(scene, T_END, elements=8, h=1e-4, sample_dt=1e-3)
    # (16 short elements: Newton increments reach 1e-9 only, not 1e-10)
    fine = exudyn.simulate(scene, T_END, elements=16, h=5e-5, sample_dt=1e-3, newton_tol=1e-9)
    error = np.abs(fine.q - data.q).max(axis=0)
    rot = np.array([c.startswith("theta") for c in data.channels])
    meta = {**data.meta, "error_xy": float(error[~rot].max()), "error_theta": float(error[rot].max()),
            "check": "against 16 elements per beam, h = 5e-5 s", "p": scene_name + " nominal"}
    buf = io.BytesIO()
    np.savez_compressed(buf, t=data.t, channels=np.array(data.channels), q=data.q, qd=data.qd,
                        meta=np.array(json.dumps(meta)))
    path = atomic_write_bytes(HERE / f"{scene_name}_exudyn.npz", buf.getvalue())
    print(f"{path.name}: {data.t.size} samples of {len(data.channels)} channels, own error {meta['error_xy']:.2e} m, "
          f"{meta['error_theta']:.2e} rad, {meta['code']}")
    return path


def _positions(toml: str, t_end: float) -> Path:
    """<toml stem>_exudyn.npz: the scene's motion over t_end s at 1 kHz, 8 elements per beam,
    h = 1e-4 s (keys t, channels, q, meta)."""
    import casflex
    from casflex.peers import exudyn
    from casflex.results import atomic_write_bytes

    data = exudyn.simulate(casflex.load_scene(HERE / toml), t_end, elements=8, h=1e-4, sample_dt=1e-3)
    buf = io.BytesIO()
    np.savez_compressed(buf, t=data.t, channels=np.array(data.channels), q=data.q,
                        meta=np.array(json.dumps(data.meta)))
    path = atomic_write_bytes(HERE / f"{Path(toml).stem}_exudyn.npz", buf.getvalue())
    print(f"{path.name}: {data.t.size} samples, {data.meta['code']}")
    return path


def make_cantilever() -> Path:
    """cantilever_damped_exudyn.npz: cantilever_damped.toml over 2 s (Exudyn's Kelvin-Voigt bending
    and axial damping beta EI, beta EA)."""
    return _positions("cantilever_damped.toml", 2.0)


def make_markers() -> Path:
    """twobar_markers_exudyn.npz: twobar_markers.toml (twobar with two markers off its bars' axes) over
    1 s: every node's and marker's x, y (Exudyn's MarkerBodyPosition)."""
    return _positions("twobar_markers.toml", 1.0)


#: Model forms other than the built-in scene's (studies/modelform.py): Exudyn's beam and a factor on every beam's E.
#: "ge": Exudyn's geometrically exact beam, with shear and the section's rotary inertia (casflex's beams without).
FORMS = {"twobar_rotary": ("twobar", "ge", 1.0), "twobar_rotary_stiff": ("twobar", "ge", 10.0),
         "twobar_soft": ("twobar", "ancf", 0.01), "twobar_rigid": ("twobar", "ancf", 1000.0),
         "threelink_rotary": ("threelink", "ge", 1.0)}
FORM_NODES = {"twobar": ("3", "5"), "threelink": ("3", "5", "7")}


def make_forms() -> Path:
    """forms_exudyn.npz: for every form of :data:`FORMS`, the positions of the markers' nodes
    (``<form>``: shape (301, 2 n), columns x, y per node of FORM_NODES) over 0-3 s at 100 Hz, 8 elements
    per beam, h = 1e-4 s; ``t`` and per form ``<form>_channels``."""
    import dataclasses

    import casflex
    from casflex.peers import exudyn
    from casflex.results import atomic_write_bytes

    arrays, meta = {}, {}
    for form, (name, beam, e_factor) in FORMS.items():
        scene = casflex.load_scene(name)
        scene = dataclasses.replace(scene, beams=tuple(dataclasses.replace(b, E=b.E * e_factor) for b in scene.beams))
        data = exudyn.simulate(scene, 3.0, elements=8, h=1e-4, sample_dt=1e-2, beam=beam)
        names = [f"{c}{n}" for n in FORM_NODES[name] for c in ("x", "y")]
        arrays["t"] = data.t
        arrays[form] = data.q[:, [data.channels.index(c) for c in names]]
        arrays[f"{form}_channels"] = np.array(names)
        meta[form] = {**data.meta, "scene": name, "beam": beam, "E_factor": e_factor}
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays, meta=np.array(json.dumps(meta)))
    path = atomic_write_bytes(HERE / "forms_exudyn.npz", buf.getvalue())
    print(f"{path.name}: {', '.join(FORMS)}")
    return path


#: The knee pendulum's recording: 0-5 s at a motion-capture rate of 100 Hz, Exudyn's step h (s).
KNEE = {"t_end": 5.0, "sample_dt": 0.01, "h": 1e-4}


def _knee_build(scene, h: float):
    """The built-in knee_pendulum in Exudyn from the scene's numbers: the shank-foot an ObjectRigidBody2D on a
    NodeRigidBody2D at its centre of mass (reference rotation: the scene's shank node's theta), hinged to the
    ground at the knee (RevoluteJoint2D), the knee's spring-damper a CoordinateSpringDamper on the node's
    rotation, gravity LoadMassProportional; SensorMarker on every marker (the thigh's: points of the ground),
    SensorNode on the rotation. Generalized-alpha without damping (spectral radius 1), steps of ``h`` s,
    Newton increments to 1e-10. Returns (system container, mbs, settings, marker sensors by name, rotation
    sensor)."""
    import exudyn as exu
    from exudyn import itemInterface as ii

    nodes = {n.name: n for n in scene.nodes}
    body = next(b for b in scene.bodies if b.name == "shank_foot")
    (knee,), spring = scene.joints, scene.torsion_springs[0]
    thigh, shank = nodes[knee.nodes[0]], nodes[knee.nodes[1]]
    c, s = math.cos(shank.theta), math.sin(shank.theta)

    def local(x: float, y: float) -> list[float]:  # a point of the shank-foot in its body frame (m)
        dx, dy = x - body.com_x, y - body.com_y
        return [c * dx + s * dy, -s * dx + c * dy, 0.0]

    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.AddObject(ii.ObjectGround())
    node = mbs.AddNode(ii.NodeRigidBody2D(referenceCoordinates=[body.com_x, body.com_y, shank.theta]))
    obj = mbs.AddObject(ii.ObjectRigidBody2D(mass=body.mass, inertia=body.inertia, nodeNumber=node))
    mbs.AddLoad(ii.LoadMassProportional(markerNumber=mbs.AddMarker(ii.MarkerBodyMass(bodyNumber=obj)),
                                        loadVector=[*scene.gravity, 0.0]))
    mbs.AddObject(ii.RevoluteJoint2D(markerNumbers=[
        mbs.AddMarker(ii.MarkerBodyPosition(bodyNumber=ground, localPosition=[shank.x, shank.y, 0.0])),
        mbs.AddMarker(ii.MarkerBodyPosition(bodyNumber=obj, localPosition=local(shank.x, shank.y)))]))
    # Exudyn's coordinate is theta - theta0 (the ground's is 0): kt (theta - theta_thigh - rest) is
    # kt (coordinate - offset) with this offset
    offset = spring.rest_angle + thigh.theta - shank.theta
    fixed = mbs.AddMarker(ii.MarkerNodeCoordinate(nodeNumber=mbs.AddNode(ii.NodePointGround()), coordinate=0))
    turn = mbs.AddMarker(ii.MarkerNodeCoordinate(nodeNumber=node, coordinate=2))
    mbs.AddObject(ii.CoordinateSpringDamper(markerNumbers=[fixed, turn], stiffness=spring.kt, damping=spring.ct,
                                            offset=offset))
    sensors = {}
    for mk in scene.markers:
        where = (ii.MarkerBodyPosition(bodyNumber=obj, localPosition=local(mk.x, mk.y)) if mk.on == body.name
                 else ii.MarkerBodyPosition(bodyNumber=ground, localPosition=[mk.x, mk.y, 0.0]))
        sensors[mk.name] = mbs.AddSensor(ii.SensorMarker(markerNumber=mbs.AddMarker(where), storeInternal=True,
                                                         outputVariableType=exu.OutputVariableType.Position))
    rotation = mbs.AddSensor(ii.SensorNode(nodeNumber=node, storeInternal=True,
                                           outputVariableType=exu.OutputVariableType.Coordinates))
    mbs.Assemble()
    ss = exu.SimulationSettings()
    ti = ss.timeIntegration
    ti.numberOfSteps, ti.endTime, ti.verboseMode = int(round(KNEE["t_end"] / h)), KNEE["t_end"], 0
    ti.generalizedAlpha.spectralRadius = 1.0
    ti.newton.residualMode = 1  # tolerance on the Newton increment
    ti.newton.relativeTolerance = ti.newton.absoluteTolerance = 1e-10
    # full Newton at fixed steps: Exudyn's defaults (modified Newton, adaptive steps) stalled on the increment
    # tolerance from about 2.7 s on and shrank steps unseen, so that the samples drifted off their times
    ti.newton.useModifiedNewton, ti.adaptiveStep = False, False
    ss.solution.file.write = False
    ss.solution.sensors.writePeriod = h
    ss.show.computationTime = ss.show.statistics = False
    return SC, mbs, ss, sensors, rotation


def _knee_run(scene, h: float) -> tuple[np.ndarray, list[str], np.ndarray, np.ndarray]:
    """t (s) every KNEE["sample_dt"], channels x<marker>, y<marker>, their positions (m) and the knee's
    flexion (rad: 0 at full extension, pi/2 hanging; -(theta_shank - theta_thigh)) of Exudyn's run at h."""
    SC, mbs, ss, sensors, rotation = _knee_build(scene, h)
    if not mbs.SolveDynamic(ss):
        raise RuntimeError("Exudyn's dynamic solver failed")
    rows = np.arange(0, int(round(KNEE["t_end"] / h)) + 1, int(round(KNEE["sample_dt"] / h)))
    channels, columns = [], []
    for name, sensor in sensors.items():
        data = np.asarray(mbs.GetSensorStoredData(sensor))[rows]
        channels += [f"x{name}", f"y{name}"]
        columns += [data[:, 1], data[:, 2]]
    turn = np.asarray(mbs.GetSensorStoredData(rotation))[rows]
    if np.abs(turn[:, 0] - rows * h).max() > 1e-9:
        raise RuntimeError("Exudyn's samples are not at their times (steps of another size?)")
    nodes = {n.name: n for n in scene.nodes}
    thigh, shank = (nodes[n] for n in scene.joints[0].nodes)
    flexion = -(shank.theta + turn[:, 3] - thigh.theta)
    return turn[:, 0], channels, np.column_stack(columns), flexion


def _knee_ode(scene, t: np.ndarray) -> np.ndarray:
    """The markers' positions (m) at times t (s) from the pendulum's equation of motion in its one coordinate,
    I_knee theta'' = -m g (the centre of mass's x) - kt (theta - theta_thigh - rest) - ct theta', solved by scipy's
    DOP853 at rtol 1e-12: a third code for the two others (gravity along y, the knee a fixed point)."""
    from scipy.integrate import solve_ivp

    nodes = {n.name: n for n in scene.nodes}
    body = next(b for b in scene.bodies if b.name == "shank_foot")
    (knee,), spring = scene.joints, scene.torsion_springs[0]
    thigh, shank = nodes[knee.nodes[0]], nodes[knee.nodes[1]]
    rx, ry = body.com_x - shank.x, body.com_y - shank.y  # the centre of mass from the knee, initially
    inertia = body.inertia + body.mass * (rx**2 + ry**2)

    def rates(_, z):
        turn, omega = z[0] - shank.theta, z[1]
        moment = body.mass * scene.gravity[1] * (math.cos(turn) * rx - math.sin(turn) * ry)
        moment -= spring.kt * (z[0] - thigh.theta - spring.rest_angle) + spring.ct * omega
        return [omega, moment / inertia]

    theta = solve_ivp(rates, (t[0], t[-1]), [shank.theta, shank.omega], t_eval=t, method="DOP853", rtol=1e-12,
                      atol=1e-13).y[0] - shank.theta
    columns = []
    for mk in scene.markers:
        if mk.on != body.name:
            columns += [np.full(t.size, mk.x), np.full(t.size, mk.y)]
            continue
        dx, dy = mk.x - shank.x, mk.y - shank.y
        c, s = np.cos(theta), np.sin(theta)
        columns += [shank.x + c * dx - s * dy, shank.y + s * dx + c * dy]
    return np.column_stack(columns)


def make_knee_pendulum() -> Path:
    """knee_pendulum_exudyn.npz: the built-in knee_pendulum (the clinical pendulum test of the knee) at its
    nominal (true) kt, ct over 0-5 s at 100 Hz, h = 1e-4 s: t (s), channels (x<marker>, y<marker> of its five
    markers), q (m; no noise: the consumer adds it), knee_flexion (rad) and meta (code, settings, the truth,
    the file's own error against h = 5e-5 s: error_xy, m, error_flexion, rad, and against the equation of motion
    (:func:`_knee_ode`): error_ode_xy, m; max over samples and channels)."""
    import exudyn as exu

    import casflex
    from casflex.results import atomic_write_bytes

    scene = casflex.load_scene("knee_pendulum")
    t, channels, q, flexion = _knee_run(scene, KNEE["h"])
    _, _, q_fine, flexion_fine = _knee_run(scene, KNEE["h"] / 2)
    body = next(b for b in scene.bodies if b.name == "shank_foot")
    meta = {"code": f"Exudyn {exu.__version__}", "scene": "knee_pendulum", "h": KNEE["h"],
            "sample_dt": KNEE["sample_dt"], "integrator": "generalized-alpha, spectral radius 1", "newton_tol": 1e-10,
            "model": "ObjectRigidBody2D on NodeRigidBody2D, RevoluteJoint2D to the ground at the knee, "
                     "CoordinateSpringDamper on the rotation, LoadMassProportional",
            "truth": {"kt_knee": scene.torsion_springs[0].kt, "ct_knee": scene.torsion_springs[0].ct,
                      "rest_angle": scene.torsion_springs[0].rest_angle, "mass": body.mass, "inertia": body.inertia,
                      "com": [body.com_x, body.com_y]},
            "units": "t s; q m; knee_flexion rad (0 at full extension, pi/2 hanging); truth SI (inertia kg m^2 "
                     "about the centre of mass, com m in the initial configuration)",
            "error_xy": float(np.abs(q_fine - q).max()), "error_flexion": float(np.abs(flexion_fine - flexion).max()),
            "check": "against h = 5e-5 s", "noise": 0.0,
            "error_ode_xy": float(np.abs(_knee_ode(scene, t) - q).max()),
            "check_ode": "against the equation of motion in the knee angle, scipy DOP853 at rtol 1e-12"}
    buf = io.BytesIO()
    np.savez_compressed(buf, t=t, channels=np.array(channels), q=q, knee_flexion=flexion,
                        meta=np.array(json.dumps(meta)))
    path = atomic_write_bytes(HERE / "knee_pendulum_exudyn.npz", buf.getvalue())
    print(f"{path.name}: {t.size} samples of {len(channels)} channels, own error {meta['error_xy']:.2e} m, "
          f"{meta['error_flexion']:.2e} rad, {meta['error_ode_xy']:.2e} m from the ODE, {meta['code']}")
    return path


def make_knee_trial() -> Path:
    """casflex/scene/builtin/knee_pendulum_trial.csv: the example recording shipped with casflex (read by name,
    ``casflex identify knee_pendulum --method indirect --data knee_pendulum_trial``): knee_pendulum_exudyn.npz's
    five markers at 100 Hz over 5 s with the noise of a motion-capture lab, 1 mm Gaussian per coordinate
    (seed 2026), written at 0.01 mm as a lab's file would be."""
    from casflex.data import MeasurementSet, save_measurements

    with np.load(HERE / "knee_pendulum_exudyn.npz") as z:
        t, channels, q = z["t"], tuple(str(c) for c in z["channels"]), z["q"]
    q = np.round(q + np.random.default_rng(2026).normal(0.0, 1e-3, q.shape), 5)
    path = save_measurements(MeasurementSet(t, channels, q, None, None, source="Exudyn, 1 mm noise"),
                             HERE.parents[1] / "casflex" / "scene" / "builtin" / "knee_pendulum_trial.csv")
    print(f"{path.name}: {t.size} samples of {len(channels)} channels, 1 mm noise")
    return path


if __name__ == "__main__":
    for name in sys.argv[1:] or SCENES:
        make_knee_pendulum() if name == "knee_pendulum" else make(name)
    if not sys.argv[1:]:
        make_cantilever()
        make_markers()
        make_forms()
        make_knee_pendulum()
        make_knee_trial()
