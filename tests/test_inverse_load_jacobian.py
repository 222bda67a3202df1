"""The rigid inverse's loads and their exact derivatives (casflex.inverse.load_jacobian), on the Hamner stride with
its plate: the values are rigid_loads', the derivatives its central differences', the bands take them in one call
(no load solved again), and a kinematic tree of another scene is refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from inverse_scenes import pendulum

from casflex.inverse import Bands, Filter, Trial, inverse_model, kinematic_tree, prepare, solve
from casflex.inverse.bands import rigid_load_function
from casflex.inverse.load_jacobian import load_derivatives
from casflex.scene import Uncertain
from casflex.scene.io import loads_scene

LAB = Path(__file__).parent / "data" / "lab"
TRC, GRF = LAB / "hamner_running_stride.trc", LAB / "hamner_running_stride_grf.mot"
TABLE = [Uncertain(f"{b}.{p}", relative=0.15) for b in ("thigh", "shank") for p in ("mass", "inertia")]
NAMES = ("hip.moment", "knee.moment", "ankle.moment", "root.fy", "knee.fx", "ankle.f_along")


@pytest.fixture(scope="module")
def stride():
    inputs = prepare("hamner_leg", Trial(TRC, grf=GRF, plates={"ankle": "ground_"}, root="pelvis"),
                     filter=Filter(10.0), bands=Bands(TABLE))
    res = solve(inputs, bands=Bands(asked=False))
    spec = inputs.band_spec
    d = load_derivatives(spec.tree, res.t, inputs.plates, res.z, res.zd, res.zdd, spec.model.p_nominal, spec.index,
                         kinematics=inputs.tree)
    return inputs, res, d


def test_values_are_the_rigid_inverse_s_with_its_plate(stride):
    _, res, d = stride
    assert sorted(d.value) == sorted(res.loads)
    for name, v in res.loads.items():  # one linear solve a frame either way: round-off
        assert np.abs(d.value[name] - v).max() <= 1e-10 * max(1.0, np.abs(v).max()), name


def test_derivatives_are_the_central_differences_of_the_loads(stride):
    """Along z (step 1e-5: the differences' error ~1e-10 of the derivative's scale), z', z'' (the loads quadratic
    and linear in them: exact but for round-off) and the properties (linear: exact), bound 1e-7 of each
    derivative's largest; the second derivatives along masses and inertias are 0."""
    inputs, res, d = stride
    spec = inputs.band_spec
    p0 = spec.model.p_nominal
    loads = rigid_load_function(spec.tree, res.t, inputs.plates, p0)
    base = [res.z, res.zd, res.zdd]
    for a, h in ((0, 1e-5), (1, 1e-3), (2, 1e-2)):
        for c in range(res.z.shape[1]):
            moved = []
            for sign in (1.0, -1.0):
                args = [x.copy() for x in base]
                args[a][:, c] += sign * h
                moved.append(loads(*args))
            for name in NAMES:
                fd = (moved[0][name] - moved[1][name]) / (2 * h)
                exact = d.motion[name][a, :, c]
                assert np.abs(exact - fd).max() <= 1e-7 * max(1.0, np.abs(d.motion[name][a]).max()), (a, c, name)
    for j, k in enumerate(spec.index):
        dp = np.zeros_like(p0)
        dp[k] = 1e-2 * p0[k]
        up, down = loads(*base, p=p0 + dp), loads(*base, p=p0 - dp)
        for name in NAMES:
            fd = (up[name] - down[name]) / (2 * dp[k])
            assert np.abs(d.props[name][:, j] - fd).max() <= 1e-9 * max(1.0, np.abs(fd).max()), (spec.targets[j], name)
            assert np.abs(d.curvature[name][:, j]).max() == 0.0


def test_bands_solve_no_load_again(stride, monkeypatch):
    """The bands take the loads' derivatives from one mapped function: the rigid loads are solved once, by the
    inverse itself (central differences solved them 2 (3 n_z + n_u) times more)."""
    import casflex.inverse.bands as bands

    inputs, res, _ = stride
    calls = []
    real = bands.rigid_loads
    monkeypatch.setattr(bands, "rigid_loads", lambda *a, **k: calls.append(1) or real(*a, **k))
    again = solve(inputs)
    assert calls == []
    assert again.bands["knee.moment"]["markers"].max() > 0 and again.bands["knee.moment"]["anthropometry"].max() > 0


def test_a_tree_of_another_scene_is_refused(stride):
    inputs, res, _ = stride
    spec = inputs.band_spec
    other = kinematic_tree(inverse_model(loads_scene(pendulum())))  # another scene: other coordinates
    with pytest.raises(ValueError, match=r"kinematics: its coordinates .* are not the tree's"):
        load_derivatives(spec.tree, res.t, inputs.plates, res.z, res.zd, res.zdd, spec.model.p_nominal,
                         kinematics=other)


def test_blocks_of_frames_give_the_whole_record_s(stride, monkeypatch):
    """Blocks of 10 frames (the last padded) against one block of all 44: the same numbers."""
    import casflex.inverse.load_jacobian as lj

    inputs, res, d = stride
    spec = inputs.band_spec
    monkeypatch.setattr(lj, "BLOCK", 10)
    b = load_derivatives(spec.tree, res.t, inputs.plates, res.z, res.zd, res.zdd, spec.model.p_nominal, spec.index,
                         kinematics=inputs.tree)
    for field in ("value", "motion", "props", "curvature"):
        whole, blocks = getattr(d, field), getattr(b, field)
        assert all(np.array_equal(whole[k], blocks[k]) for k in whole), field
