"""casflex.lab: a real running trial's TRC and ground reactions (OpenSim's Hamner pipeline, excerpts in
tests/data/lab with their source), the lab-to-model plane, and malformed files (one line each)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import casflex
from casflex.lab import Plane, read_sto, read_trc, trial_markers

LAB = Path(__file__).resolve().parent / "data" / "lab"
TRC, GRF = LAB / "hamner_running_excerpt.trc", LAB / "hamner_running_grf_excerpt.mot"


def test_a_real_trc_in_metres_with_its_dropped_marker_as_gaps():
    m = read_trc(TRC)
    assert m.labels[:3] == ("R.ASIS", "L.ASIS", "V.Sacral") and m.xyz.shape == (61, 8, 3)
    assert m.units == "mm" and m.rate == 60.0 and m.t[-1] == pytest.approx(1.0)
    assert m.marker("R.ASIS")[0] == pytest.approx([0.8090094, 1.03451831, -0.06461081], rel=1e-12)  # mm to m
    assert np.isnan(m.marker("L.Bicep")).all()  # written as (0, 0, 0): never recorded
    assert np.isfinite(m.xyz[:, :7]).all()
    # lab Y is up: the pelvis about 1 m high, the heel at the floor at foot strike; on a treadmill the
    # pelvis stays (5 cm along X in the second) while the foot swings along X
    assert 0.9 < np.mean(m.marker("R.ASIS")[:, 1]) < 1.2 and np.min(m.marker("R.Heel")[:, 1]) < 0.1
    assert np.ptp(m.marker("V.Sacral")[:, 0]) < 0.1 < 0.5 < np.ptp(m.marker("R.Heel")[:, 0])


def test_a_real_ground_reaction_table():
    g = read_sto(GRF)
    assert g.names[:3] == ("ground_force_vx", "ground_force_vy", "ground_force_vz") and g.values.shape == (61, 18)
    fy = g.column("ground_force_vy") + g.column("1_ground_force_vy")
    assert 1000.0 < fy.max() < 2500.0  # N: the vertical reaction of a running stance (2-3 body weights)
    assert g.in_degrees is None and g.header["datarows"] == "61"


def test_the_plane_takes_lab_axes_to_the_model_and_says_where_it_is_seen_from():
    assert Plane.parse("X,Y").view == "+Z" and Plane.parse("-Z,Y").view == "+X" and Plane.parse("Z,Y").view == "-X"
    np.testing.assert_array_equal(Plane.parse("-Z,Y").matrix, [[0, 0, -1], [0, 1, 0]])
    for bad in ("X", "X,X", "X,W", "X,Y,Z", "-X,+X"):
        with pytest.raises(ValueError, match="plane: expected two different lab axes"):
            Plane.parse(bad)


def _scene_with_markers(**labels):
    from casflex import Marker, Node, RigidBody, Scene

    return Scene(name="labelled", nodes=(Node("pelvis", 0.8, 1.0),), bodies=(RigidBody("pelvis", "pelvis", 10.0),),
                 markers=tuple(Marker(name, "pelvis", 0.8, 1.0, label=label) for name, label in labels.items()))


def test_the_scene_s_markers_by_their_lab_labels():
    model = casflex.assemble(_scene_with_markers(asis="R.ASIS", sacrum="V.Sacral"))
    data = trial_markers(model, TRC, "X,Y")
    assert data.channels == ("xasis", "yasis", "xsacrum", "ysacrum") and data.meta["view"] == "+Z"
    np.testing.assert_allclose(data.q[:, :2], read_trc(TRC).marker("R.ASIS")[:, :2])
    assert casflex.loads_scene(casflex.dumps_scene(model.scene)) == model.scene  # label round-trips
    with pytest.raises(ValueError, match=r"no marker labelled 'R.Knee'; the trial has \['R.ASIS'"):
        trial_markers(casflex.assemble(_scene_with_markers(knee="R.Knee")), TRC)


def _trc(tmp_path, *, units="mm", labels=("A", "B"), rows=((1, 0.0), (2, 0.01)), ncoords=None):
    k = len(labels)
    lines = ["PathFileType\t4\t(X/Y/Z)\tx.trc", "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits",
             f"100\t100\t{len(rows)}\t{k}\t{units}", "Frame#\tTime\t" + "\t\t\t".join(labels),
             "\t\t" + "\t".join(f"{a}{i + 1}" for i in range(k) for a in "XYZ"), ""]
    for frame, t in rows:
        lines.append("\t".join([str(frame), str(t)] + ["1.5"] * (3 * k if ncoords is None else ncoords)))
    path = tmp_path / "x.trc"
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("kwargs, match", [
    ({"units": ""}, r"header Units '' is missing"),
    ({"units": "in"}, r"header Units 'in' is not a length unit; expected one of \['mm', 'cm', 'm'\]"),
    ({"labels": ("A", "A")}, r"marker labels \['A'\] appear more than once"),
    ({"rows": ((1, 0.0), (2, 0.0))}, r"times must increase: row 2 repeats t = 0 s after 0 s"),
    ({"rows": ((1, 0.02), (2, 0.01))}, r"times must increase: row 2 goes back to t = 0.01 s after 0.02 s"),
    ({"ncoords": 5}, r"row 7 has 5 coordinates for 2 markers \(6 expected\)"),
])
def test_a_malformed_trc_is_one_line_naming_what_is_wrong(tmp_path, kwargs, match):
    with pytest.raises(ValueError, match=match) as err:
        read_trc(_trc(tmp_path, **kwargs))
    assert str(err.value).startswith(str(tmp_path)) and "\n" not in str(err.value)


def test_a_malformed_sto_is_one_line_naming_what_is_wrong(tmp_path):
    path = tmp_path / "f.mot"
    cases = [("time\tfx\n0\t1\n", "no 'endheader' line"),
             ("endheader\ntime\tfx\tfx\n0\t1\t2\n", r"columns \['fx'\] appear more than once"),
             ("endheader\ntime\tfx\n0\t1\t2\n", "row 3 has 3 values for 2 columns"),
             ("endheader\nfx\ttime\n0\t1\n", "should name the columns, 'time' first"),
             ("endheader\ntime\tfx\n0\tx\n", r"row 3: 'x' is not a number")]
    for text, match in cases:
        path.write_text(text)
        with pytest.raises(ValueError, match=match):
            read_sto(path)


def test_the_command_line_refuses_a_bad_plane_before_any_work(tmp_path, capsys):
    from casflex.cli import main

    assert main(["identify", "twobar", "--method", "indirect", "--data", str(TRC), "--plane", "X,W"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--plane" in err[0] and "two different lab axes" in err[0], err
