"""The built-in knee_pendulum (the clinical pendulum test of the knee) against Exudyn's recording of it, and
the knee's passive stiffness and damping identified from that recording's markers.

The recording (tests/data/knee_pendulum_exudyn.npz, :func:`make_reference_data.make_knee_pendulum`) is the
scene written directly in Exudyn: the shank-foot an ObjectRigidBody2D on a RevoluteJoint2D, the knee a
CoordinateSpringDamper on its rotation, generalized-alpha without damping at h = 1e-4 s. Its meta records
its own error against h = 5e-5 s, 3.3e-7 m, and its distance from the equation of motion in the knee angle
(I_knee theta'' = -m g d cos theta - kt (theta - rest) - ct theta', scipy's DOP853 at rtol 1e-12), 4.4e-7 m.
Five markers at 100 Hz over 5 s, without noise: the tests add 1 mm.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import casflex
from casflex.cli import main
from casflex.data import add_position_noise, load_measurements
from casflex.identification import identify_indirect
from casflex.simulate import Stepping, simulate

RECORDING = Path(__file__).resolve().parent / "data" / "knee_pendulum_exudyn.npz"
NOISE = 1e-3  # m: a motion-capture lab's marker noise


@pytest.fixture(scope="module")
def model():
    return casflex.assemble(casflex.load_scene("knee_pendulum"))


@pytest.fixture(scope="module")
def exudyn() -> dict:
    """The recording's arrays: t (s), channels, q (m), knee_flexion (rad) and meta (a dict)."""
    with np.load(RECORDING) as z:
        return {"t": z["t"], "channels": [str(c) for c in z["channels"]], "q": z["q"],
                "knee_flexion": z["knee_flexion"], "meta": json.loads(str(z["meta"]))}


def _casflex(model, channels: list[str], dt: float) -> tuple[np.ndarray, np.ndarray]:
    """casflex's markers (m) and knee flexion (rad, -knee_pin.angle) over 5 s at steps of dt (s), at 100 Hz."""
    tr = simulate(model, 5.0, stepping=Stepping(dt=dt))
    every = int(round(0.01 / dt))
    q = np.column_stack([tr.channel(c) for c in channels])[::every]
    return q, -tr.outputs[::every, tr.output_names.index("knee_pin.angle")]


def test_the_recording_is_the_scenes_motion_at_a_labs_rate(model, exudyn):
    scene, meta = model.scene, exudyn["meta"]
    body = next(b for b in scene.bodies if b.name == "shank_foot")
    truth = {"kt_knee": 2.0, "ct_knee": 0.15, "mass": body.mass, "inertia": body.inertia,
             "com": [body.com_x, body.com_y], "rest_angle": scene.torsion_springs[0].rest_angle}
    assert meta["truth"] == truth and list(model.p_nominal) == [2.0, 0.15]
    np.testing.assert_allclose(exudyn["t"], np.arange(501) * 0.01, atol=1e-12)
    assert exudyn["channels"] == [f"{c}{m.name}" for m in scene.markers for c in "xy"]
    assert meta["error_xy"] < 1e-6 and meta["error_ode_xy"] < 1e-6  # measured 3.3e-7 and 4.4e-7 m
    assert meta["noise"] == 0.0 and RECORDING.stat().st_size < 200_000  # 31 kB
    # the file as the command line and load_measurements read it: markers only, the knee angle aside
    assert load_measurements(RECORDING).channels == tuple(exudyn["channels"])


def test_casflex_simulates_exudyns_markers(model, exudyn):
    # Measured (max over 10 channels, 501 samples): casflex at the scene's dt = 1 ms is 0.0190 mm from Exudyn,
    # at 0.5 ms 0.0044 mm; the two casflex runs differ by 0.0146 mm, so casflex's own error at 1 ms is about
    # 4/3 x 0.0146 = 0.0194 mm (second order), all of the difference (Exudyn's own: 3.3e-4 mm). Tolerance
    # 0.03 mm: the measured 0.019 mm with a margin of 1.5. Knee flexion: 3.9e-5 rad at 1 ms, 9.0e-6 at 0.5 ms.
    q1, flexion1 = _casflex(model, exudyn["channels"], 1e-3)
    q2, flexion2 = _casflex(model, exudyn["channels"], 5e-4)
    err1, err2 = (float(np.abs(q - exudyn["q"]).max()) for q in (q1, q2))
    assert err1 < 3e-5, err1
    assert err2 < err1 / 3, (err1, err2)  # converging to Exudyn's motion at second order (measured ratio 4.3)
    assert np.abs(flexion1 - exudyn["knee_flexion"]).max() < 6e-5
    assert np.abs(flexion2 - exudyn["knee_flexion"]).max() < 1.5e-5
    # the motion: released at full extension, through the hanging position (pi/2) to 2.97 rad at 0.87 Hz
    assert exudyn["knee_flexion"][0] == 0.0 and exudyn["knee_flexion"].max() > 2.9


def _within_three_se(parameters: dict, std_errors: dict) -> None:
    for name, truth in (("kt_knee", 2.0), ("ct_knee", 0.15)):
        value, se = parameters[name], std_errors[name]
        assert abs(value - truth) <= 3 * se, (name, value, se)
        assert abs(value / truth - 1) < 1e-3, (name, value)  # measured within 0.05 %


def test_command_line_identifies_the_knee_from_the_recording(tmp_path, capsys):
    # what a user runs: the file with 1 mm of noise, from half the nominal values; the scene's initial state
    # (the recording starts at rest at full extension). Measured: kt 2.00005 +- 0.00025, ct 0.14998 +- 3.3e-5
    out = tmp_path / "knee.json"
    code = main(["identify", "knee_pendulum", "--method", "indirect", "--data", str(RECORDING), "--noise",
                 str(NOISE), "--seed", "0", "--start", "0.5", "--quiet", "--out", str(out)])
    assert code == 0, capsys.readouterr()
    res = json.loads(out.read_text())
    assert res["success"], res["message"]
    _within_three_se(res["parameters"], res["std_errors"])
    for name, channel in res["extra"]["experiments"]["data"]["residuals"].items():  # the residuals are the noise
        assert channel["rms"] == pytest.approx(NOISE, rel=0.1), name


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_identifies_the_knee_from_noisy_markers(model, seed):
    # the Python API on the same file, exact mass and inertia. Measured (seeds 1, 2, 3): kt 1.99988, 2.00028,
    # 1.99984 (SE 0.00025, z -0.50, 1.14, -0.65); ct 0.15002, 0.14997, 0.15006 (SE 3.5e-5, z 0.54, -0.80, 1.91)
    data = add_position_noise(load_measurements(RECORDING), NOISE, seed)
    r = identify_indirect(model, data, start={"kt_knee": 1.0, "ct_knee": 0.3})
    assert r.success, r.message
    _within_three_se(r.parameters, r.std_errors)


def test_the_example_trial_is_shipped_and_read_by_name(tmp_path, exudyn, capsys):
    # the recording with a lab's 1 mm of noise, shipped in the package (casflex/scene/builtin/knee_pendulum_trial.csv)
    from casflex.data import builtin_recordings

    assert "knee_pendulum_trial" in builtin_recordings()
    trial = load_measurements("knee_pendulum_trial")
    assert list(trial.channels) == exudyn["channels"]
    noise = trial.q - exudyn["q"]
    # 5010 draws of 1 mm, rounded to 0.01 mm: their sd within 4 % (3.5 sampling sds), their mean within 0.1 mm
    assert abs(noise.std() / 1e-3 - 1) < 0.04 and abs(noise.mean()) < 1e-4
    out = tmp_path / "r.json"
    assert main(["identify", "knee_pendulum", "--method", "indirect", "--data", "knee_pendulum_trial", "--quiet",
                 "--uncertain", "shank_foot.mass=10%", "--uncertain", "shank_foot.inertia=20%",
                 "--out", str(out)]) == 0
    res = json.loads(out.read_text())
    for name, truth in (("kt_knee", 2.0), ("ct_knee", 0.15)):
        assert abs(res["parameters"][name] - truth) <= 3 * res["std_errors"][name]
