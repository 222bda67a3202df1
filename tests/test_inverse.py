"""Inverse dynamics (casflex.inverse): closed forms, Newton's law for the whole system, the lab's
filter against scipy's, the driven (HHT) path against the exact one, and the refusals."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from inverse_scenes import INERTIA, M_BASE, C, M, pendulum

from casflex.inverse import Filter, Trial, inverse_dynamics, inverse_model, kinematic_tree
from casflex.inverse.flexible import driven_loads
from casflex.inverse.plates import Plate, plate_loads
from casflex.inverse.rigid import rigid_loads
from casflex.lab import LabMarkers
from casflex.model.markers import marker_positions
from casflex.scene.io import loads_scene

G = 9.81
A, W = 0.7, 2 * np.pi * 1.3  # the pendulum's swing: A sin(W t), rad


def _tree(extra: str = ""):
    model = inverse_model(loads_scene(pendulum(extra)))
    return model, kinematic_tree(model)


def _swing(t: np.ndarray, moving_root: bool = False):
    """z, z', z'' (k, 4) of the pendulum: analytic, the root still or moving."""
    th, thd, thdd = A * np.sin(W * t), A * W * np.cos(W * t), -A * W * W * np.sin(W * t)
    z = np.zeros((t.size, 4))
    zd, zdd = np.zeros_like(z), np.zeros_like(z)
    z[:, 1] = 1.0
    z[:, 3], zd[:, 3], zdd[:, 3] = th, thd, thdd
    if moving_root:  # x = a sin(3t), y = 1 + b cos(5t), theta = c sin(2t)
        for col, (amp, w, fn) in enumerate(((0.05, 3.0, np.sin), (0.02, 5.0, np.cos), (0.1, 2.0, np.sin))):
            d = np.cos if fn is np.sin else lambda x: -np.sin(x)
            z[:, col] += amp * fn(w * t)
            zd[:, col] = amp * w * d(w * t)
            zdd[:, col] = -amp * w * w * fn(w * t)
    return z, zd, zdd


def test_pendulum_moment_is_the_closed_form():
    model, tree = _tree()
    t = np.linspace(0.0, 1.0, 101)
    sol = rigid_loads(tree, t, *_swing(t), model.p_nominal)
    th, thdd = A * np.sin(W * t), -A * W * W * np.sin(W * t)
    tau = (INERTIA + M * C * C) * thdd + M * G * C * np.sin(th)  # about the pivot, the arm hanging at theta = 0
    # exact per frame: only round-off (1e-12 of the peak, ~10^4 eps)
    assert np.abs(sol["pivot.moment"] - tau).max() < 1e-12 * np.abs(tau).max()
    assert np.abs(sol["root.mz"] - tau).max() < 1e-12 * np.abs(tau).max()  # the base still: it passes it on


def test_root_loads_are_newtons_law_for_the_whole_system():
    model, tree = _tree()
    t = np.linspace(0.0, 1.0, 51)
    z, zd, zdd = _swing(t, moving_root=True)
    F = np.column_stack([30.0 * np.sin(4 * t), 5.0 + 10.0 * t])  # a plate's force on the arm, N
    P = np.column_stack([0.1 + 0.0 * t, 0.4 + 0.1 * t])  # where it acts, m
    plate = Plate("p", "link", t, F, P[:, 0] * F[:, 1] - P[:, 1] * F[:, 0])

    sol = rigid_loads(tree, t, z, zd, zdd, model.p_nominal, lambda tt, q: plate_loads(model, [plate], tt, q))
    # the bodies' centres' accelerations by AD along the coordinates' motion
    from casflex.model.markers import body_centres

    body_centres(model, model.q0)  # builds the Function
    from casflex.model import markers as mk

    zs, zds, zdds = (ca.SX.sym(s, 4) for s in ("z", "zd", "zdd"))
    c = mk._CENTRES[model](tree.forward(zs))
    cd = ca.jtimes(c, zs, zds)
    cdd = ca.jtimes(c, zs, zdds) + ca.jtimes(cd, zs, zds)
    acc = ca.Function("acc", [zs, zds, zdds], [cdd])
    a = np.array([np.array(acc(z[i], zd[i], zdd[i])).reshape(-1, 2) for i in range(t.size)])  # (k, bodies, 2)
    masses = np.array([b.mass for b in model.scene.bodies])
    need = (masses[None, :, None] * a).sum(axis=1) - masses.sum() * np.array([0.0, -G]) - F
    drive = np.column_stack([sol["root.fx"], sol["root.fy"]])
    assert np.abs(drive - need).max() < 1e-10 * np.abs(need).max()  # exact: round-off only


def test_pipeline_from_exact_markers_is_second_order():
    """Markers of a known motion, unfiltered: the loads' error is the central differences' (h^2/12 f'''')."""
    model, tree = _tree()
    h = 0.01
    t = np.arange(0.0, 1.0 + h / 2, h)
    z, _, _ = _swing(t)
    q = np.array(tree.forward.map(t.size)(z.T)).T
    y = marker_positions(model, q).reshape(t.size, -1, 2)
    lab = LabMarkers(t, ("BASE.1", "BASE.2", "ARM.1", "ARM.2"), np.concatenate([y, np.zeros_like(y[..., :1])], 2),
                     100.0, "m", "synthetic")
    res = inverse_dynamics(loads_scene(pendulum()), Trial(lab), filter=Filter(cutoff=None))
    assert res.marker_rms.max() < 1e-9  # the markers fit exactly
    th, thdd = A * np.sin(W * t), -A * W * W * np.sin(W * t)
    tau = (INERTIA + M * C * C) * thdd + M * G * C * np.sin(th)
    err = np.abs(res.load("pivot.moment") - tau)
    inner = (INERTIA + M * C * C) * h**2 / 12 * A * W**4  # the central second difference's truncation error
    ends = (INERTIA + M * C * C) * 11 / 12 * h**2 * A * W**4 * 1.2  # the one-sided one's (11/12 h^2 f''''), +20 %
    assert err[1:-1].max() < 1.05 * inner  # to the truncation error's next term (h^4)
    assert err[[0, -1]].max() < ends


def test_plate_under_the_centre_of_mass_leaves_no_joint_moment():
    model, tree = _tree()
    t = np.linspace(0.0, 0.5, 11)
    z = np.zeros((t.size, 4))
    z[:, 1] = 1.0
    for dx, want in ((0.0, 0.0), (0.05, M * G * 0.05)):  # the arm's weight carried at x = dx
        F = np.tile([0.0, M * G], (t.size, 1))
        plate = Plate("p", "link", t, F, np.full(t.size, dx * M * G))
        sol = rigid_loads(tree, t, z, 0 * z, 0 * z, model.p_nominal,
                          lambda tt, q, pl=plate: plate_loads(model, [pl], tt, q))
        # the plate's moment about the pivot, dx M g, is what the joint holds back: -dx M g on the arm
        assert np.allclose(sol["pivot.moment"], -want, atol=1e-12)
        assert np.allclose(sol["root.fy"], M_BASE * G, atol=1e-12)


def test_driven_run_converges_to_the_exact_rigid_inverse():
    """The flexible inverse's path (drive joints, HHT) on rigid segments against the exact solve, with
    the same kinematics (the supports' splines)."""
    from scipy.interpolate import make_interp_spline

    model, tree = _tree()
    t = np.arange(0.0, 0.6 + 1e-9, 0.01)
    z, _, _ = _swing(t, moving_root=True)
    s = make_interp_spline(t, z, k=5, axis=0)  # the supports' quintic
    s = lambda x, d=0, sp=s: sp(x, d)  # noqa: E731
    exact = rigid_loads(tree, t, s(t), s(t, 1), s(t, 2), model.p_nominal)
    run = driven_loads(tree, t, z, [], exact["q"], dt=2.5e-4, alpha=-0.1)
    late = t > 0.2  # past the start's O(dt) transient of index-3 multipliers
    for k in ("pivot.moment", "root.fx", "root.fy", "root.mz"):
        # measured 2e-6 of the peak at dt = h / 40 (HHT's error; 7e-4 of it at h / 20): bound 5x that
        assert np.abs(run[k] - exact[k])[late].max() < 1e-5 * np.abs(exact[k]).max() + 1e-9, k
    assert run["deflection"].max() < 1e-9  # rigid: nothing deflects


@pytest.mark.parametrize(("extra", "message"), [
    ('[[joints]]\nname = "s"\nkind = "slider"\nnodes = ["base", "extra"]\n', "sliders are not in inverse"),
    ('[[springs]]\nname = "s"\nnodes = ["base", "extra"]\nk = 10.0\n', "spring 's'"),
    ('[[joints]]\nname = "s"\nkind = "hinge"\nnodes = ["extra", "base"]\n', "run away from the root"),
    ('[[joints]]\nname = "s"\nkind = "hinge"\nnodes = ["extra"]\n', "joint to the ground"),
    ('[[joints]]\nname = "h"\nkind = "hinge"\nnodes = ["link", "extra"]\n[[supports]]\nname = "s"\nnode = "extra"\n',
     "support 's': inverse dynamics drives the scene from its root 'base' only"),
])
def test_scenes_inverse_dynamics_refuses(extra, message):
    node = '[[nodes]]\nname = "extra"\nx = 0.5\ny = 1.0\n[[bodies]]\nname = "e"\nnode = "extra"\nmass = 1.0\n'
    with pytest.raises(ValueError, match=message):
        _tree(node + extra)


def test_missing_label_and_short_window_are_one_line():
    model, tree = _tree()
    t = np.arange(0, 0.3, 0.01)
    xyz = np.zeros((t.size, 2, 3))
    lab = LabMarkers(t, ("BASE.1", "OTHER"), xyz, 100.0, "m", "trial.trc")
    # a marker the trial lacks is left out (as OpenSim's IK), and where too few remain, the segment is named
    with pytest.raises(ValueError, match=r"trial.trc: the markers do not decide \['base.x', .*segment 'base' has the "
                                         r"markers \['BASE.1'\] to place it \(\['BASE.2'\] not in the trial\)"):
        inverse_dynamics(loads_scene(pendulum()), Trial(lab))
    with pytest.raises(ValueError, match="plates: no node 'foot'"):
        inverse_dynamics(loads_scene(pendulum()), Trial(lab, grf="x.mot", plates={"foot": "ground_"}))


def test_c3d_plate_is_the_same_load_from_its_moment_or_its_centre_of_pressure():
    """A C3D's plate (its moment about the lab origin at every sample) against the same plate from its
    centre of pressure and free moment where both exist (the vertical force over 200 N)."""
    pytest.importorskip("ezc3d")
    from pathlib import Path

    from casflex.inverse.plates import plate_from_table
    from casflex.lab import LabTable, Plane, read_c3d

    _, table = read_c3d(Path(__file__).parent / "data" / "lab" / "walking2_excerpt.c3d")
    plane = Plane.parse("X,Z")  # the file's lab: Z up
    via_moment = plate_from_table(table, "ground_", "foot", plane, None)
    keep = [i for i, n in enumerate(table.names) if "moment_" not in n]
    cop_only = LabTable(table.t, tuple(table.names[i] for i in keep), table.values[:, keep], source="c3d")
    loaded = table.column("ground_force_vz") > 200.0
    rows = np.flatnonzero(loaded)
    sub = LabTable(table.t[rows], cop_only.names, cop_only.values[rows], source="c3d")
    via_cop = plate_from_table(sub, "ground_", "foot", plane, None)
    assert np.allclose(via_cop.force, via_moment.force[rows], rtol=0, atol=1e-9)
    # the same numbers through p x F + T: round-off of moments of ~1e3 N m
    assert np.abs(via_cop.moment - via_moment.moment[rows]).max() < 1e-9 * np.abs(via_moment.moment).max()


def test_forward_simulation_under_the_inverse_moments_retraces_the_motion():
    """Inverse, then forward: the pendulum on its moving base, driven by the moment the rigid inverse found
    (a load of ``mz`` on the arm ``against`` the base), follows the analytic swing it was computed from."""
    import dataclasses

    from casflex.scene import Load, Support
    from casflex.simulate import Start, Stepping, simulate

    model, tree = _tree()
    t = np.arange(0.0, 1.0 + 1e-9, 1e-3)
    z, zd, zdd = _swing(t, moving_root=True)
    sol = rigid_loads(tree, t, z, zd, zdd, model.p_nominal)
    sc = model.scene
    base = sc.node("base")
    every = slice(None, None, 10)  # the base's path: a spline through 100 Hz rows
    path = tuple((float(a), float(b - base.x), float(c - base.y), float(d - base.theta))
                 for a, b, c, d in zip(t[every], z[every, 0], z[every, 1], z[every, 2], strict=True))
    moment = tuple((float(a), 0.0, 0.0, float(m)) for a, m in zip(t, sol["pivot.moment"], strict=True))
    driven = dataclasses.replace(sc, supports=(Support("ground", "base", "clamp", path),),
                                 loads=(Load("muscle", "link", table=moment, against="base"),))
    q0, qd0 = sol["q"][0], sol["qd"][0]
    tr = simulate(driven, 1.0, stepping=Stepping(dt=1e-3, alpha=-0.05), start=Start(q0=q0, qd0=qd0))
    angle = tr.output("pivot.angle")
    # HHT's O(dt^2) and the table's linear interpolation, accumulated over 1 s of an undamped swing:
    # measured 2.8e-5 rad; bound 7x that (3e-4 of the swing's 0.7 rad)
    assert np.abs(angle - A * np.sin(W * tr.t)).max() < 2e-4


def test_one_rule_for_a_load_s_unit():
    from casflex.inverse.lab_names import load_unit
    from casflex.study.runner import unit_of

    forces = ("pelvis_tx_force", "knee.fx", "root.fy", "knee.f_along", "knee.f_across", "slide.force")
    moments = ("knee_angle_r_moment", "knee.moment", "root.mz")
    assert [load_unit(n) for n in forces] == ["N"] * len(forces)
    assert [load_unit(n) for n in moments] == ["N m"] * len(moments)
    assert [unit_of(n, per_kg=True) for n in ("pelvis_tx_force", "knee.moment")] == ["N/kg", "N m/kg"]


def _reference_lm(f, z, y, w, lo, hi, max_iter=50):
    """The marker fit's Levenberg-Marquardt as written before it was made fast (a CasADi call and its DM
    conversions per evaluation, np.clip, the damping as a diagonal matrix added): the numbers to keep."""
    seen = np.isfinite(y) & (w > 0)
    sw = w[seen]
    z, lam = np.clip(z, lo, hi), 1e-3
    ym, J = (np.array(v) for v in f(z))
    r, J = sw * (ym.ravel()[seen] - y[seen]), sw[:, None] * J[seen]
    for _ in range(max_iter):
        A, g = J.T @ J, J.T @ r
        free = ~(((z <= lo) & (g > 0)) | ((z >= hi) & (g < 0)))
        step = np.zeros_like(z)
        Af = A[np.ix_(free, free)]
        step[free] = np.linalg.solve(Af + lam * np.diag(np.diag(Af) + 1e-12), -g[free])
        step = np.clip(z + step, lo, hi) - z
        if np.max(np.abs(step)) < 1e-10:
            break
        ym2, J2 = (np.array(v) for v in f(z + step))
        r2 = sw * (ym2.ravel()[seen] - y[seen])
        if r2 @ r2 <= r @ r:
            z, r, J, lam = z + step, r2, sw[:, None] * J2[seen], max(lam / 10, 1e-12)
        else:
            lam *= 10
            if lam > 1e8:
                break
    return z, r / sw


def test_the_fast_marker_fit_gives_the_numbers_of_the_plain_one():
    """The marker fit's buffered evaluations and in-place damping (issue 49) against the plain algorithm, on the
    planar Hamner subject 02 run with its task weights: bit-equal coordinates and residuals, free and with a
    coordinate held at a limit below its free optimum (the active set's path). Equal, not close: the same
    arithmetic."""
    from pathlib import Path

    from casflex.inverse.fit import _kabsch_start, _levenberg_marquardt, _MarkerFit, coordinate_bounds, marker_weights
    from casflex.inverse.inputs import weighted
    from casflex.lab import read_trc
    from casflex.scene.from_osim import scene_from_osim

    data = Path(__file__).parent / "data" / "lab"
    scene = weighted(scene_from_osim(data / "hamner_subject02_planar.osim").scene, data / "hamner_tasks_ik.xml")[0]
    tree = kinematic_tree(inverse_model(scene))
    f, w = tree.marker_fit, marker_weights(tree)
    lo, hi = coordinate_bounds(tree) or (np.full(tree.n, -np.inf), np.full(tree.n, np.inf))
    z = np.random.default_rng(0).normal(size=tree.n)
    assert all(np.array_equal(np.array(a).reshape(b.shape), b) for a, b in zip(f(z), _MarkerFit(f)(z), strict=True))
    trc = read_trc(data / "hamner_running_whole.trc")
    y0 = _MarkerFit(f)(tree.coordinates(tree.model.q0))[0].copy()
    for i in (0, 25, 50):
        y = np.concatenate([trc.marker(m.label)[i, :2] for m in tree.model.scene.markers])
        start = _kabsch_start(tree, y, y0)
        z_free, r_free = _reference_lm(f, start, y, w, lo, hi)
        k = 3 + i % (tree.n - 3)  # a hinge given a limit below its free optimum: held there
        hi2 = hi.copy()
        hi2[k] = z_free[k] - 0.05
        for bounds in ((lo, hi), (lo, hi2)):
            want, got = _reference_lm(f, start, y, w, *bounds), _levenberg_marquardt(_MarkerFit(f), start, y, 50, w,
                                                                                      bounds)
            assert np.array_equal(want[0], got[0]) and np.array_equal(want[1], got[1]), (i, bounds[1])
        assert got[0][k] == hi2[k]  # the held path was taken


def test_the_loads_are_each_frame_s_whatever_the_chunks_and_blocks(monkeypatch):
    """The frames are evaluated in chunks of fixed sizes (each chunk's Function built once per tree, whatever the
    trial's length) and blocks: every frame's numbers are its own, to the last bit."""
    from casflex.inverse import rigid

    model, tree = _tree()
    t = np.linspace(0.0, 1.0, 613)  # 512 + 64 + 4 x 8 + 5 x 1
    motion = _swing(t, moving_root=True)
    whole = rigid_loads(tree, t, *motion, model.p_nominal)
    monkeypatch.setattr(rigid, "BLOCK", 100)  # blocks of 64 + 4 x 8 + 4 x 1, the last 13 frames
    blocks = rigid_loads(tree, t, *motion, model.p_nominal)
    for i in (0, 17, 511, 512, 575, 600, 612):  # chunks of 1 frame: each frame alone
        one = rigid_loads(tree, t[i:i + 1], *(m[i:i + 1] for m in motion), model.p_nominal)
        for k in whole:
            assert np.array_equal(one[k][0], whole[k][i]) and np.array_equal(one[k][0], blocks[k][i]), (k, i)
    built = {key for key in tree._built if key[0] == "inverse_frame"}
    assert built == {("inverse_frame",), *(("inverse_frame", s) for s in rigid.SIZES)}  # not one per length
