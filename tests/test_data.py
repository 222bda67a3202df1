"""Measurement sets: central differences, validation of user data."""

from __future__ import annotations

import numpy as np
import pytest

from casflex.data import MeasurementSet, load_measurements, measured_set


def test_central_differences_are_exact_for_a_quadratic():
    t = np.linspace(0.0, 1.0, 101)
    q = np.column_stack([3 * t**2 - t + 2, -0.5 * t**2])
    data = MeasurementSet(t, ("x2", "y2"), q, None, None)
    m = measured_set(data)
    assert m.t.shape == (99,) and m.t[0] == t[1] and m.t[-1] == t[-2]
    np.testing.assert_allclose(m.qd[:, 0], 6 * m.t - 1, atol=1e-11)  # exact for quadratics
    np.testing.assert_allclose(m.qdd, np.tile([6.0, -1.0], (99, 1)), atol=1e-8)


def test_noise_is_seeded():
    t = np.linspace(0.0, 1.0, 11)
    data = MeasurementSet(t, ("x2",), np.zeros((11, 1)), None, None)
    a, b = measured_set(data, noise=1e-3, seed=7), measured_set(data, noise=1e-3, seed=7)
    np.testing.assert_array_equal(a.q, b.q)
    assert 0 < np.abs(a.q).max() < 5e-3


@pytest.mark.parametrize("t, q, channels, match", [
    (np.array([0.0, 0.2, 0.1]), np.zeros((3, 1)), ("x2",), r"data.t: times must increase strictly; t\[2\]"),
    (np.array([0.0, 0.1]), np.array([[0.0], [np.inf]]), ("x2",), "infinite value for channel x2 at t = 0.1"),
    (np.array([0.0, 0.1]), np.zeros((2, 2)), ("x2",), r"data.q: expected shape \(2, 1\)"),
])
def test_bad_data_rejected(t, q, channels, match):
    with pytest.raises(ValueError, match=match):
        MeasurementSet(t, channels, q, None, None)


def test_unknown_channel_and_missing_instant():
    import casflex

    m = casflex.assemble(casflex.load_scene("twobar"))
    data = MeasurementSet(np.array([0.0, 0.1]), ("x9",), np.zeros((2, 1)), None, None)
    with pytest.raises(ValueError, match=r"unknown channels \['x9'\]"):
        data.select(m)
    with pytest.raises(ValueError, match="no sample there"):
        data.index(5.0)
    with pytest.raises(ValueError, match="noise"):
        measured_set(MeasurementSet(np.arange(3.0), ("x2",), np.zeros((3, 1)), None, None), noise=-1.0)


# --------------------------------------------------------------------------------------------
# measurement files: load_measurements / save_measurements


def _sample_set(derivatives: bool = True) -> MeasurementSet:
    t = np.arange(6) * 1e-3
    q = np.column_stack([np.sin(t * 7.0) + 0.1, np.cos(t * 3.0) - 1.7, t**2 / 3])
    return MeasurementSet(t, ("x5", "y5", "theta5"), q, 2 * q if derivatives else None,
                          3 * q if derivatives else None)


@pytest.mark.parametrize("ext", ["npz", "csv"])
@pytest.mark.parametrize("derivatives", [True, False])
def test_file_round_trip_is_exact(ext, derivatives, tmp_path):
    from casflex.data import load_measurements, save_measurements

    data = _sample_set(derivatives)
    path = save_measurements(data, tmp_path / f"m.{ext}")
    back = load_measurements(path)
    assert back.channels == data.channels and back.source == "file" and back.meta["path"] == str(path)
    np.testing.assert_array_equal(back.t, data.t)
    np.testing.assert_array_equal(back.q, data.q)
    if derivatives:
        np.testing.assert_array_equal(back.qd, data.qd)
        np.testing.assert_array_equal(back.qdd, data.qdd)
    else:
        assert back.qd is None and back.qdd is None
    assert not list(tmp_path.glob(".*.tmp"))  # atomic write leaves no temporary file


def test_csv_comments_blank_lines_spaces_and_column_order(tmp_path):
    from casflex.data import load_measurements

    path = tmp_path / "m.csv"
    path.write_text("# measured on the rig, 2024-05-01\n\n t , d:x5, x5 ,dd:x5\n0, 1, 10, 100\n  # pause\n"
                    "0.001,2,20,200\n")
    d = load_measurements(path)
    assert d.channels == ("x5",)
    np.testing.assert_array_equal(d.t, [0.0, 0.001])
    np.testing.assert_array_equal(d.q[:, 0], [10, 20])
    np.testing.assert_array_equal(d.qd[:, 0], [1, 2])
    np.testing.assert_array_equal(d.qdd[:, 0], [100, 200])


def test_a_casflex_trajectory_file_is_accepted(tmp_path):
    import casflex
    from casflex.data import load_measurements
    from casflex.simulate import Stepping, simulate

    model = casflex.assemble(casflex.load_scene("twobar"))
    tr = simulate(model, 0.003, stepping=Stepping(dt=1e-3))
    d = load_measurements(tr.save(tmp_path / "run.npz"))
    assert d.channels == tuple(model.dof_names)
    np.testing.assert_array_equal(d.qdd, tr.qdd)
    assert (d.select(model) == np.arange(model.n_dof)).all()


def test_unknown_channel_of_a_file_is_caught_by_select(tmp_path):
    import casflex
    from casflex.data import load_measurements

    path = tmp_path / "m.csv"
    path.write_text("t,x5,x9\n0,1,2\n")
    with pytest.raises(ValueError, match=r"unknown channels \['x9'\]"):
        load_measurements(path).select(casflex.assemble(casflex.load_scene("twobar")))


_CSV_CASES = {
    "empty file": ("", "empty file"),
    "only comments": ("# nothing\n", "empty file"),
    "no data rows": ("t,x5\n# no rows\n", r"no data rows after the header \(line 1\)"),
    "missing t": ("time,x5\n0,1\n", r"line 1: the header's first column must be 't'.*got 'time'"),
    "no channels": ("t\n0\n", "no channel columns after 't'"),
    "empty column name": ("t,x5,\n0,1,2\n", "header column 3 has an empty name"),
    "duplicate channel": ("t,x5,y5,x5\n0,1,2,3\n", r"duplicate column 'x5' \(columns 2 and 4\)"),
    "duplicate t": ("t,x5,t\n0,1,2\n", "duplicate column 't'"),
    "velocity without position": ("t,x5,d:y5\n0,1,2\n", "velocity column 'd:y5' has no position column 'y5'"),
    "acceleration without position": ("t,x5,dd:x7\n0,1,2\n",
                                      "acceleration column 'dd:x7' has no position column 'x7'"),
    "partial velocities": ("t,x5,y5,d:x5\n0,1,2,3\n", r"velocity columns must cover every channel.*\['d:y5'\]"),
    "prefix alone": ("t,x5,d:\n0,1,2\n", "column 3 'd:' names no channel"),
    "non-numeric cell": ("t,x5,y5\n0,1,2\n0.001,1,abc\n", r"line 3 \(data row 2\), column 'y5': 'abc' is not a number"),
    "empty time cell": ("t,x5\n0,1\n,2\n", r"line 3 \(data row 2\), column 't': empty cell"),
    "short row": ("t,x5,y5\n0,1,2\n0.001,1\n", r"line 3 \(data row 2\): expected 3 cells as in the header, got 2"),
    "long row": ("# c\nt,x5\n0,1,2\n", r"line 3 \(data row 1\): expected 2 cells"),
    "inf position": ("t,x5,y5\n0,1,2\n0.001,1,inf\n", "data.q: infinite value for channel y5 at t = 0.001 s"),
    "inf velocity": ("t,x5,d:x5\n0,1,2\n0.001,1,inf\n", "data.qd: infinite value for channel x5 at t = 0.001 s"),
    "nan time": ("t,x5\n0,1\nnan,2\n", "t: non-finite time nan at sample 1"),
    "times repeat": ("t,x5\n0,1\n0.001,2\n0.001,3\n", r"times must increase strictly; t\[2\] = 0.001 follows 0.001"),
    "times decrease": ("t,x5\n0.002,1\n0.001,2\n", r"t\[1\] = 0.001 follows 0.002"),
}


@pytest.mark.parametrize("content, match", list(_CSV_CASES.values()), ids=list(_CSV_CASES))
def test_malformed_csv_is_rejected_with_one_line(content, match, tmp_path):
    from casflex.data import load_measurements

    path = tmp_path / "bad.csv"
    path.write_text(content)
    with pytest.raises(ValueError, match=match) as exc:
        load_measurements(path)
    assert str(exc.value).startswith(f"{path}: ") and "\n" not in str(exc.value)


_T, _Q = np.arange(3) * 1e-3, np.zeros((3, 2))
_CH = np.array(["x5", "y5"])
_NPZ_CASES = {
    "missing t": ({"channels": _CH, "q": _Q}, r"missing key 't' \(keys present: \['channels', 'q'\]\)"),
    "missing q": ({"t": _T, "channels": _CH}, "missing key 'q'"),
    "missing channels": ({"t": _T, "q": _Q}, "missing key 'channels'"),
    "empty t": ({"t": np.zeros(0), "channels": _CH, "q": np.zeros((0, 2))}, r"no samples \(t is empty\)"),
    "no channels": ({"t": _T, "channels": np.array([], dtype=str), "q": np.zeros((3, 0))}, "no channels"),
    "2-d t": ({"t": np.zeros((3, 1)), "channels": _CH, "q": _Q}, r"key 't': expected a 1-d array.*\(3, 1\)"),
    "q shape": ({"t": _T, "channels": _CH, "q": np.zeros((3, 3))},
                r"key 'q': expected shape \(len\(t\), len\(channels\)\) = \(3, 2\), got \(3, 3\)"),
    "qdd shape": ({"t": _T, "channels": _CH, "q": _Q, "qdd": np.zeros((2, 2))}, r"key 'qdd': expected shape"),
    "q not numbers": ({"t": _T, "channels": _CH, "q": np.full((3, 2), "a")}, "key 'q': expected numbers, got dtype"),
    "channels not strings": ({"t": _T, "channels": np.array([1, 2]), "q": _Q},
                             "key 'channels': expected a 1-d array of strings"),
    "empty channel name": ({"t": _T, "channels": np.array(["x5", " "]), "q": _Q}, "channel 1 has an empty name"),
    "duplicate channel": ({"t": _T, "channels": np.array(["x5", "x5"]), "q": _Q},
                          "duplicate channel name 'x5'"),
    "object array": ({"t": _T, "channels": _CH, "q": np.array([[1, None]] * 3, dtype=object)},
                     "key 'q': holds Python objects"),
    "inf": ({"t": _T, "channels": _CH, "q": np.array([[0, 0], [0, 0], [0, np.inf]])},
            "data.q: infinite value for channel y5 at t = 0.002 s"),
    "nan time": ({"t": np.array([0, np.nan, 1]), "channels": _CH, "q": _Q}, "non-finite time nan at sample 1"),
    "times decrease": ({"t": np.array([0.0, 2e-3, 1e-3]), "channels": _CH, "q": _Q},
                       r"times must increase strictly; t\[2\] = 0.001 follows 0.002"),
}


@pytest.mark.parametrize("arrays, match", list(_NPZ_CASES.values()), ids=list(_NPZ_CASES))
def test_malformed_npz_is_rejected_with_one_line(arrays, match, tmp_path):
    from casflex.data import load_measurements

    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    with pytest.raises(ValueError, match=match) as exc:
        load_measurements(path)
    assert str(exc.value).startswith(f"{path}: ") and "\n" not in str(exc.value)


def test_bad_paths(tmp_path):
    from casflex.data import load_measurements, save_measurements

    with pytest.raises(ValueError, match=r"nosuch.csv: no such file"):
        load_measurements(tmp_path / "nosuch.csv")
    with pytest.raises(ValueError, match=r"m.txt: unknown extension '.txt'; measurement files are .npz or .csv"):
        load_measurements(tmp_path / "m.txt")
    with pytest.raises(ValueError, match=r"unknown extension '\(none\)'"):
        save_measurements(_sample_set(), tmp_path / "m")
    (tmp_path / "dir.csv").mkdir()
    with pytest.raises(ValueError, match="dir.csv: not a regular file"):
        load_measurements(tmp_path / "dir.csv")
    (tmp_path / "text.npz").write_text("t,x5\n0,1\n")
    with pytest.raises(ValueError, match="text.npz: not a readable .npz file"):
        load_measurements(tmp_path / "text.npz")
    (tmp_path / "bin.csv").write_bytes(b"t,x5\n\xff\xfe\n")
    with pytest.raises(ValueError, match="bin.csv: not a UTF-8 text file"):
        load_measurements(tmp_path / "bin.csv")


def test_duplicate_channels_rejected_in_memory_too():
    with pytest.raises(ValueError, match="data.channels: duplicate channel name 'x2'"):
        MeasurementSet(np.arange(2.0), ("x2", "x2"), np.zeros((2, 2)), None, None)


def test_position_noise_is_seeded_and_keeps_derivatives():
    from casflex.data import add_position_noise

    data = _sample_set()
    a, b = add_position_noise(data, 1e-3, seed=4), add_position_noise(data, 1e-3, seed=4)
    np.testing.assert_array_equal(a.q, b.q)
    assert 0 < np.abs(a.q - data.q).max() < 5e-3 and a.meta["noise"] == 1e-3 and a.meta["seed"] == 4
    np.testing.assert_array_equal(a.qd, data.qd)
    with pytest.raises(ValueError, match="noise"):
        add_position_noise(data, float("nan"))


def test_missing_samples_are_nan(tmp_path):
    # a hidden marker: an empty cell or nan in a position column is a missing sample, kept as NaN
    path = tmp_path / "gaps.csv"
    path.write_text("t,x5,y5\n0,1,2\n0.001,,2.5\n0.002,nan,3\n")
    d = load_measurements(path)
    assert np.isnan(d.q[1, 0]) and np.isnan(d.q[2, 0]) and d.q[1, 1] == 2.5

