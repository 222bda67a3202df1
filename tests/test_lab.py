"""casflex.lab: a real running trial's TRC and ground reactions (OpenSim's Hamner pipeline, excerpts in
tests/data/lab with their source), the lab-to-model plane, and malformed files (one line each)."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import casflex
from casflex.lab import (
    LabTable,
    Plane,
    centre_of_pressure,
    filtered,
    plate_moment_about_origin,
    read_c3d,
    read_sto,
    read_trc,
    trial_markers,
)
from casflex.lab.filtering import zero_lag_minus_3db
from casflex.lab.tables import write_sto

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


def test_a_marker_stands_for_its_label_or_else_its_name():
    sc = _scene_with_markers(asis="R.ASIS", sacrum=None)
    assert [m.lab_label for m in sc.markers] == ["R.ASIS", "sacrum"]


def test_write_sto_is_read_back_by_read_sto(tmp_path):
    t = np.array([0.0, 0.01, 0.02])
    cols = {"knee_angle_r_moment": np.array([1.5, -2.25, 3.0]), "pelvis_tx_force": np.array([10.0, 0.0, -1e-3])}
    path = write_sto(tmp_path / "loads.sto", t, cols, title="a test", units={"knee_angle_r_moment": "N m",
                                                                            "pelvis_tx_force": "N"})
    back = read_sto(path)
    assert back.names == tuple(cols) and back.in_degrees is False
    np.testing.assert_array_equal(back.t, t)
    np.testing.assert_array_equal(back.values, np.column_stack(list(cols.values())))  # %.10g keeps these exactly
    assert "units: time s; knee_angle_r_moment N m; pelvis_tx_force N" in path.read_text().splitlines()


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


def test_header_values_set_apart_by_runs_of_tabs_are_read_as_opensim_reads_them(tmp_path):
    """The Rajagopal pipeline's walking trial writes ``  100.0\t\t  100.0\t\t    238 ...`` under single-tab keys."""
    path = _trc(tmp_path, units="cm")
    lines = path.read_text().splitlines()
    lines[2] = "\t\t".join(f"  {v}" for v in lines[2].split("\t"))
    path.write_text("\n".join(lines) + "\n")
    data = read_trc(path)
    assert data.units == "cm" and data.rate == 100.0
    np.testing.assert_allclose(data.xyz, 0.015)  # 1.5 cm


def test_a_utf8_byte_order_mark_is_read_past(tmp_path):
    """Windows' editors write one before the first line: the TRC and the .mot read as without it."""
    path = tmp_path / "bom.trc"
    path.write_bytes(b"\xef\xbb\xbf" + TRC.read_bytes())
    assert read_trc(path).labels == read_trc(TRC).labels
    mot = tmp_path / "bom.mot"
    mot.write_bytes(b"\xef\xbb\xbf" + GRF.read_bytes())
    assert read_sto(mot).names == read_sto(GRF).names


def test_what_is_no_regular_text_file_is_refused_before_it_is_read(tmp_path):
    """/dev/zero behind a link named .trc, a pipe, a folder: read as text they fill the memory (or block)."""
    import os

    link = tmp_path / "zero.trc"
    link.symlink_to("/dev/zero")
    os.mkfifo(tmp_path / "pipe.mot")
    (tmp_path / "dir.trc").mkdir()
    for path, reader, kind in ((link, read_trc, "a device or a pipe"), (tmp_path / "pipe.mot", read_sto,
                                                                         "a device or a pipe"),
                               (tmp_path / "dir.trc", read_trc, "a directory")):
        with pytest.raises(ValueError, match=rf"^{path}: not a regular file \({kind}\)"):
            reader(path)
    sparse = tmp_path / "sparse.trc"  # 64 MB of zeros and no line end: refused at its first MiB
    with open(sparse, "wb") as f:
        f.truncate(64 << 20)
    with pytest.raises(ValueError, match=r"line 1 is longer than 1,048,576 characters: not a text table"):
        read_trc(sparse)


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


# --- C3D (casflex.lab.c3d, through ezc3d) -----------------------------------------------------------------

C3D = LAB / "walking2_excerpt.c3d"


def test_without_ezc3d_one_line_says_how_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "ezc3d", None)  # import ezc3d then raises ImportError
    with pytest.raises(ModuleNotFoundError, match=r"^read_c3d needs the ezc3d package: pip install 'casflex\[lab\]'$"):
        read_c3d(C3D)


def test_a_real_c3d_in_metres_with_markers_that_leave_the_view():
    pytest.importorskip("ezc3d")
    m, _ = read_c3d(C3D)
    assert m.xyz.shape == (210, 44, 3) and m.labels[:3] == ("RTH1", "RFHD", "RTH3") and m.labels[-1] == "RKJC"
    assert m.units == "mm" and m.rate == 250.0
    # the trial's clock: frames 641-850 of 1249 (1-based), so t from 640 / 250 s
    assert m.t[0] == pytest.approx(2.56) and m.t[-1] == pytest.approx(3.396) and np.allclose(np.diff(m.t), 0.004)
    assert m.marker("RASI")[0] == pytest.approx([0.27832245, 0.42292786, 1.04312146], rel=1e-7)  # mm to m
    # C7 and the 14 joint-centre points leave the cameras' view for the last 13 frames (residual -1)
    gone = [lb for i, lb in enumerate(m.labels) if np.isnan(m.xyz[:, i]).any()]
    assert gone[0] == "C7" and len(gone) == 15 and all(lb.endswith(("FC", "MAL", "JC")) for lb in gone[1:])
    c7 = m.marker("C7")
    assert np.isnan(c7[-13:]).all() and np.isfinite(c7[:-13]).all()
    assert np.isfinite(np.delete(m.xyz, [m.labels.index(lb) for lb in gone], axis=1)).all()
    # lab Z up: the pelvis about 1 m high, a heel at the floor
    assert 0.9 < np.mean(m.marker("RASI")[:, 2]) < 1.1 and np.min(m.marker("RCAL")[:, 2]) < 0.06


def test_a_real_c3d_s_force_plates_as_opensim_s_ground_reaction_columns():
    pytest.importorskip("ezc3d")
    m, g = read_c3d(C3D)
    kinds = ("force_v", "force_p", "torque_", "moment_")
    assert g.names == tuple(f"{p}{k}{a}" for p in ("ground_", "1_ground_") for k in kinds for a in "xyz")
    assert g.values.shape == (1680, 24) and g.header["rate"] == 2000.0 and g.header["up"] == "+Z"
    assert g.t[0] == m.t[0] and np.allclose(np.diff(g.t), 0.0005)  # 8 analog samples a frame
    corners = {"ground_": ((0.6646, 1.1726), (0.3793, 0.8429)), "1_ground_": ((0.0, 0.6096), (0.0, 1.2192))}
    for p, (xs, ys) in corners.items():
        F, P, T, M = (np.column_stack([g.column(f"{p}{k}{a}") for a in "xyz"]) for k in kinds)
        # walking: each plate's vertical reaction peaks at about a body weight (750-950 N); an unloaded plate
        # reads its offset (-14 and -20 N in this file: not zeroed)
        assert 700.0 < F[:, 2].max() < 1000.0 and -30.0 < F[:, 2].min() < 0.0
        assert np.array_equal(np.isnan(P[:, 0]), F[:, 2] < 20.0) and np.array_equal(np.isnan(T[:, 2]), F[:, 2] < 20.0)
        on = F[:, 2] > 200.0  # the centre of pressure on the plate, its free moment vertical
        assert (xs[0] < P[on, 0]).all() and (P[on, 0] < xs[1]).all() and (ys[0] < P[on, 1]).all()
        assert (P[on, 1] < ys[1]).all() and np.allclose(P[on, 2], 0.0) and np.allclose(T[on, :2], 0.0, atol=1e-9)
        ok = np.isfinite(P[:, 0])  # the moment about the origin is p x F + T where p is defined
        np.testing.assert_allclose(M[ok], np.cross(P[ok], F[ok]) + T[ok], atol=1e-9 * np.abs(M).max())
    # at each plate's peak, its centre of pressure lies under the foot on it (right on plate 1, left on 2)
    for p, foot in (("ground_", "R"), ("1_ground_", "L")):
        k = int(np.argmax(g.column(f"{p}force_vz")))
        mid = (m.marker(f"{foot}CAL") + m.marker(f"{foot}MT1"))[k // 8, :2] / 2
        assert np.hypot(*(np.array([g.column(f"{p}force_px")[k], g.column(f"{p}force_py")[k]]) - mid)) < 0.15
    assert read_c3d(C3D, plates=False)[1] is None


def _type_5_plates(tmp_path):
    raw = bytearray(C3D.read_bytes())
    i = raw.index(b"TYPE\n\x00\x02\x01\x02")  # FORCE_PLATFORM:TYPE: int16, one dimension of 2
    raw[i + 9:i + 13] = b"\x05\x00\x05\x00"
    path = tmp_path / "type5.c3d"
    path.write_bytes(bytes(raw))
    return path


def test_a_corrupted_or_unsupported_c3d_is_one_line_naming_the_file(tmp_path):
    pytest.importorskip("ezc3d")
    raw = C3D.read_bytes()
    cases = [(raw[:len(raw) // 2], r"truncated: its header announces 210 frames, the file holds 101"),
             (raw[:3000], r"truncated in its parameter section"),
             (raw[:100], r"not a C3D file: 100 bytes, shorter than a C3D header \(512\)"),
             (TRC.read_bytes(), r"not a C3D file \(its second byte is not the C3D key 0x50\)")]
    path = tmp_path / "bad.c3d"
    for data, match in cases:
        path.write_bytes(data)
        with pytest.raises(ValueError, match=match) as err:
            read_c3d(path)
        assert str(err.value).startswith(str(path)) and "\n" not in str(err.value)
    for first, last in ((641, 600), (900, 850)):  # the header's frames (words 4 and 5) out of order
        bad = bytearray(raw)
        bad[6:10] = first.to_bytes(2, "little") + last.to_bytes(2, "little")
        path.write_bytes(bytes(bad))
        with pytest.raises(ValueError, match=rf"corrupted header: its first frame \(word 4\) is {first} and its "
                                             rf"last \(word 5\) {last}: the last cannot precede the first"):
            read_c3d(path)
    for where, match in ((tmp_path / "none.c3d", "no such file"), (tmp_path, "not a file")):
        with pytest.raises(ValueError, match=f"{match}$"):
            read_c3d(where)
    five = _type_5_plates(tmp_path)
    with pytest.raises(ValueError, match=r"type5.c3d: ezc3d cannot read its force plates: Type 5 is not supported"
                                         r".*; read_c3d\(\.\.\., plates=False\) reads the markers alone$"):
        read_c3d(five)
    assert read_c3d(five, plates=False)[0].xyz.shape == (210, 44, 3)


# --- filtering (casflex.lab.filtering) -----------------------------------------------------------------------

def _gain(f: float, fc: float, fs: float) -> float:
    """The zero-lag filter's gain: the 2nd-order digital Butterworth's |H|, squared by the double pass."""
    return 1.0 / (1.0 + (np.tan(np.pi * f / fs) / np.tan(np.pi * fc / fs)) ** 4)


def test_filtfilt_of_sines_keeps_the_4th_order_butterworth_gain():
    fs, fc = 100.0, 6.0
    t = np.round(np.arange(500) / fs, 3)
    freqs = (1.0, 3.0, 4.8, 6.0, 9.0)
    table = LabTable(t, tuple(f"s{f:g}" for f in freqs), np.column_stack([np.sin(2 * np.pi * f * t) for f in freqs]))
    out, report = filtered(table, fc)
    mid = slice(100, 400)  # away from the ends' transients
    for j, f in enumerate(freqs):
        amp = np.max(np.abs(out.values[mid, j]))
        assert amp == pytest.approx(_gain(f, fc, fs), rel=2e-3, abs=2e-3), f
    # the cut-off is each pass's (-6 dB zero-lag); -3 dB at 0.80 of it, said in the report
    f3 = zero_lag_minus_3db(fc, fs)
    assert _gain(f3, fc, fs) == pytest.approx(2 ** -0.5) and 4.8 < f3 < 4.9
    assert report.splitlines()[0] == ("zero-lag Butterworth low-pass, order 4 (2nd order forward and backward), "
                                      "cut-off 6 Hz per pass, not corrected for the double pass (-3 dB at 4.83 Hz), "
                                      "100 Hz sampling; 5 of 5 columns filtered")
    np.testing.assert_array_equal(table.values[:, 0], np.sin(2 * np.pi * t))  # the input is left alone


def test_filtering_refuses_in_one_line_what_it_cannot_do():
    t = np.arange(50) / 100.0
    table = LabTable(t, ("a",), np.ones((50, 1)), source="tbl")
    jitter = t.copy()
    jitter[20] += 0.002
    cases = [(lambda: filtered(table, 50.0), r"cutoff: must lie between 0 and the Nyquist frequency 50 Hz, got 50"),
             (lambda: filtered(table, 6.0, order=2), r"order: only 4"),
             (lambda: filtered(table, 6.0, names=["b"]), r"tbl: no column 'b'; there are \['a'\]"),
             (lambda: filtered(replace(table, t=jitter), 6.0), r"tbl: filtering needs evenly spaced samples: "
                                                                r"t = 0.202 s is 0.002 s off the grid of 0.01 s steps"),
             (lambda: filtered(replace(table, t=t[:5], values=table.values[:5]), 1.0), "at least 10 samples, got 5")]
    for call, match in cases:
        with pytest.raises(ValueError, match=match) as err:
            call()
        assert "\n" not in str(err.value)


def test_marker_gaps_are_filled_up_to_max_gap_refused_beyond_and_ends_left_missing():
    m = read_trc(TRC)  # 60 Hz; L.Bicep never recorded
    out, report = filtered(m, 6.0)
    assert np.isnan(out.marker("L.Bicep")).all() and np.isfinite(out.xyz[:, :7]).all()
    assert "L.Bicep: no samples, left missing" in report.splitlines()
    assert np.abs(out.marker("V.Sacral") - m.marker("V.Sacral")).max() < 0.005  # m: the pelvis barely moves at 6 Hz
    xyz = m.xyz.copy()
    xyz[20:25, m.labels.index("R.Heel")] = np.nan  # a 5-frame gap (t = 0.333 to 0.4 s)
    gap, report = filtered(replace(m, xyz=xyz), 6.0)
    assert "R.Heel: 5 samples filled by a cubic spline (t = 0.333 to 0.4 s)" in report.splitlines()
    assert np.abs(gap.marker("R.Heel") - out.marker("R.Heel")).max() < 0.01  # m, against the unbroken marker's
    xyz[10:25, m.labels.index("R.Heel")] = np.nan
    with pytest.raises(ValueError, match=r"hamner_running_excerpt.trc: R.Heel: a gap of 15 samples \(t = 0.167 to "
                                         r"0.4 s\) is longer than max_gap = 10 samples"):
        filtered(replace(m, xyz=xyz), 6.0)
    assert np.isfinite(filtered(replace(m, xyz=xyz), 6.0, max_gap=15)[0].marker("R.Heel")).all()


def test_c3d_markers_leaving_the_view_are_filtered_up_to_where_they_leave():
    pytest.importorskip("ezc3d")
    m, _ = read_c3d(C3D)
    out, report = filtered(m, 6.0, names=["C7", "RCAL"])
    assert ("C7: missing at the ends (0 + 13 samples), left missing; filtered from t = 2.56 to 3.344 s"
            in report.splitlines())
    assert np.isnan(out.marker("C7")[-13:]).all() and np.isfinite(out.marker("C7")[:-13]).all()
    # m: C7 moves forward at 1.3 m/s; 6 Hz smooths its sway by a few millimetres, 12 mm at the stretch's end
    assert np.abs(out.marker("C7")[:-13] - m.marker("C7")[:-13]).max() < 0.015
    assert np.abs(out.marker("C7")[25:-38] - m.marker("C7")[25:-38]).max() < 0.004
    np.testing.assert_array_equal(out.marker("RTH1"), m.marker("RTH1"))  # not asked for: as read


def _wrench_table(g: LabTable, prefix: str) -> LabTable:
    F, M = plate_moment_about_origin(g, prefix)
    return LabTable(g.t, ("fx", "fy", "fz", "mx", "my", "mz"), np.hstack([F, M]), source=g.source)


def test_a_plate_filtered_through_its_force_and_moment_about_the_origin():
    g = read_sto(GRF)  # Y up, the belts' surface at y = -7.5 mm, 60 Hz
    for p in ("ground_", "1_ground_"):
        F, M = plate_moment_about_origin(g, p)
        P0, T0 = (np.column_stack([g.column(f"{p}{k}{a}") for a in "xyz"]) for k in ("force_p", "torque_"))
        P, T = centre_of_pressure(F, M, -0.0075, up="Y")
        # unfiltered, exact back where the file's free moment is vertical, as a free moment at p must be
        vertical = (F[:, 1] > 20.0) & (T0[:, 0] == 0) & (T0[:, 2] == 0)
        assert vertical.sum() > 10
        np.testing.assert_allclose(P[vertical], P0[vertical], atol=1e-12)
        np.testing.assert_allclose(T[vertical], T0[vertical], atol=1e-12)
        assert np.isnan(P[F[:, 1] < 20.0]).all()
        # filtered at 25 Hz (of 30 Hz Nyquist): within 2.5 cm where Fy > 50 N, 1 cm where Fy > 100 N (the
        # first and last samples of a stance rise or fall by 500 N in one 60 Hz step)
        w, _ = filtered(_wrench_table(g, p), 25.0)
        Pf, _ = centre_of_pressure(w.values[:, :3], w.values[:, 3:], -0.0075)
        for over, tol in ((50.0, 0.025), (100.0, 0.01)):
            on = F[:, 1] > over
            assert np.abs(Pf[on] - P0[on]).max() < tol, (p, over)


def test_a_c3d_plate_filtered_through_its_force_and_moment():
    pytest.importorskip("ezc3d")
    _, g = read_c3d(C3D)
    for p in ("ground_", "1_ground_"):
        cols = [f"{p}{k}{a}" for k in ("force_v", "moment_") for a in "xyz"]
        out, report = filtered(g, 50.0, names=cols)
        assert "2000 Hz sampling; 6 of 24 columns filtered" in report
        F, M = plate_moment_about_origin(out, p)
        P, _ = centre_of_pressure(F, M, 0.0, up=g.header["up"])
        P0, Fz = np.column_stack([g.column(f"{p}force_p{a}") for a in "xyz"]), g.column(f"{p}force_vz")
        for over, tol in ((50.0, 0.03), (200.0, 0.01)):  # m; the raw CoP's own noise: ~0.2 N m / Fz
            on = Fz > over
            assert np.abs(P[on] - P0[on]).max() < tol, (p, over)


def test_plate_helpers_refuse_in_one_line():
    g = read_sto(GRF)
    with pytest.raises(ValueError, match=r"no plate '2_' \(columns 2_force_vx ...\); the plates there are "
                                         r"\['1_ground_', 'ground_'\]"):
        plate_moment_about_origin(g, "2_")
    assert plate_moment_about_origin(g, "1_")[0].shape == (61, 3)  # "1_" stands for "1_ground_"
    values = g.values.copy()
    values[30, g.names.index("ground_force_px")] = np.nan
    with pytest.raises(ValueError, match=r"plate 'ground_' has a force but no centre of pressure at t = 0.5 s"):
        plate_moment_about_origin(replace(g, values=values), "ground_")
    with pytest.raises(ValueError, match=r"up: expected a lab axis such as 'Y', '\+Z' or '-Z', got 'W'"):
        centre_of_pressure(np.zeros((2, 3)), np.zeros((2, 3)), up="W")


def test_a_c3d_trial_gives_the_scenes_markers():
    pytest.importorskip("ezc3d")
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    from inverse_scenes import pendulum

    from casflex.lab import read_c3d, trial_markers
    from casflex.model import assemble
    from casflex.scene.io import loads_scene

    path = Path(__file__).parent / "data" / "lab" / "walking2_excerpt.c3d"
    lab, _ = read_c3d(path, plates=False)
    labels = lab.labels[:4]
    text = pendulum()
    for old, new in zip(("BASE.1", "BASE.2", "ARM.1", "ARM.2"), labels, strict=True):
        text = text.replace(f'"{old}"', f'"{new}"')
    data = trial_markers(assemble(loads_scene(text)), path, "X,Z")
    assert np.allclose(data.q[:, 0], lab.xyz[:, 0, 0], equal_nan=True)  # x of the first marker: the lab's X, m
    assert np.allclose(data.q[:, 1], lab.xyz[:, 0, 2], equal_nan=True)  # y: the lab's Z (up in this file)


def test_a_trial_file_s_span_is_read_from_its_header_and_its_ends():
    # casflex study checks windows and cut-offs before any work from these: the same times and rates as the
    # whole files' readers (C3D without ezc3d: its header's frames and rate)
    from casflex.lab import read_c3d
    from casflex.lab.c3d import c3d_span
    from casflex.lab.tables import sto_span, trc_span

    lab = Path(__file__).resolve().parent / "data" / "lab"
    trc, whole = trc_span(lab / "hamner_running_whole.trc"), read_trc(lab / "hamner_running_whole.trc")
    assert (trc.t0, trc.t1, trc.rate, trc.names) == (whole.t[0], whole.t[-1], whole.rate, whole.labels)
    mot, table = sto_span(lab / "hamner_running_whole_grf.mot"), read_sto(lab / "hamner_running_whole_grf.mot")
    assert (mot.t0, mot.t1, mot.names) == (table.t[0], table.t[-1], table.names)
    assert mot.rate == pytest.approx(60.0, rel=1e-3)  # times rounded to ms: 0.2, 0.217, 0.233 ...
    pytest.importorskip("ezc3d")
    (c3d, analog), (markers, plates) = c3d_span(lab / "walking2_excerpt.c3d"), read_c3d(lab / "walking2_excerpt.c3d")
    assert (c3d.t0, c3d.rate) == (markers.t[0], markers.rate)
    assert analog == 2000.0 and 1.0 / (plates.t[1] - plates.t[0]) == pytest.approx(analog, rel=1e-9)
    assert c3d.t1 == pytest.approx(markers.t[-1], abs=1e-12)  # (last - 1) / rate, computed the same way
    assert c3d.names == tuple(plates.names)  # its plates' columns, from FORCE_PLATFORM:USED (2 plates)


def test_a_table_larger_than_the_memory_can_read_is_refused_before_it_is_read(monkeypatch):
    # a regular file as large as the memory was read until the memory ran out: its size is checked first
    import casflex.results
    from casflex.lab.tables import READ_FACTOR

    path = Path(__file__).resolve().parent / "data" / "lab" / "hamner_running_stride.trc"
    size = path.stat().st_size
    monkeypatch.setattr(casflex.results, "memory_available", lambda: READ_FACTOR * size - 1)
    with pytest.raises(ValueError, match=rf"{path}: 19.7 KiB: reading it needs about 78.7 KiB of memory and "
                                         r"78.7 KiB are available"):
        read_trc(path)
    monkeypatch.setattr(casflex.results, "memory_available", lambda: READ_FACTOR * size)
    assert read_trc(path).t.size > 0


def test_write_trc_round_trips_read_trc_with_opensim_s_header(tmp_path):
    from casflex.lab import read_c3d, read_trc, write_trc

    m = read_c3d(LAB / "walking2_excerpt.c3d")[0]  # 44 markers, some missing in places, from t = 2.56 s
    assert np.isnan(m.xyz).any()
    back = read_trc(write_trc(tmp_path / "walk.trc", m))
    assert back.labels == m.labels and (back.rate, back.units) == (250.0, "mm")
    np.testing.assert_allclose(back.t, m.t, rtol=0, atol=1e-12)
    assert (np.isnan(back.xyz) == np.isnan(m.xyz)).all()  # a missing sample stays missing (NaN)
    np.testing.assert_allclose(back.xyz, m.xyz, rtol=0, atol=1e-9)  # 10 significant digits of mm
    head = (tmp_path / "walk.trc").read_text().splitlines()[:5]
    assert head[0].split("\t")[:3] == ["PathFileType", "4", "(X/Y/Z)"]  # what OpenSim's TRC reader checks
    assert dict(zip(head[1].split("\t"), head[2].split("\t"), strict=True))["NumMarkers"] == "44"
    assert head[3].split("\t")[:3] == ["Frame#", "Time", "RTH1"] and head[4].split("\t")[2:5] == ["X1", "Y1", "Z1"]
    in_m = read_trc(write_trc(tmp_path / "walk_m.trc", m, units="m"))
    np.testing.assert_allclose(in_m.xyz, m.xyz, rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match="units: 'inch' is not a length unit"):
        write_trc(tmp_path / "x.trc", m, units="inch")


def test_c3d_events_stored_as_one_list_of_minute_second_pairs_are_read(tmp_path):
    # BTKData's Plug-in Gait walks hold EVENT:TIMES as one list (ezc3d reads it flat): their events were dropped,
    # and the gait cycles taken from the heel markers without a word
    ezc3d = pytest.importorskip("ezc3d")
    from casflex.lab import read_c3d

    c = ezc3d.c3d(str(LAB / "walking2_excerpt.c3d"))
    c.add_parameter("EVENT", "USED", [2])
    c.add_parameter("EVENT", "CONTEXTS", ["Right", "Left"])
    c.add_parameter("EVENT", "LABELS", ["Foot Strike", "Foot Off"])
    c.add_parameter("EVENT", "TIMES", [0.0, 3.1, 0.0, 2.7])  # (minutes, seconds) pairs
    c.write(str(tmp_path / "events.c3d"))
    events = read_c3d(tmp_path / "events.c3d", plates=False)[0].events
    assert [(cx, lb) for cx, lb, _ in events] == [("Left", "Foot Off"), ("Right", "Foot Strike")]  # by time
    np.testing.assert_allclose([e[2] for e in events], [2.7, 3.1], atol=1e-6)  # float32 in the file


@pytest.mark.skipif(__import__("importlib").util.find_spec("opensim") is None, reason="OpenSim is not installed")
def test_write_trc_is_read_by_opensim(tmp_path):
    # a missing marker at a row's end written as empty cells made OpenSim's reader refuse the row ("Unexpected
    # number of columns"); OpenSim runs in its own process (it cannot share one with CasADi)
    import json
    import subprocess

    from casflex.lab import read_c3d, write_trc

    m = read_c3d(LAB / "walking2_excerpt.c3d")[0]
    assert np.isnan(m.xyz[203, -1]).all()  # the last marker missing in that frame
    write_trc(tmp_path / "walk.trc", m)
    code = ("import json, sys, opensim as o; t = o.TimeSeriesTableVec3(sys.argv[1]); r = t.getRowAtIndex(0); "
            "print(json.dumps([t.getNumRows(), list(t.getColumnLabels()), t.getIndependentColumn()[0], "
            "[r[0][k] for k in range(3)], t.getTableMetaDataAsString('Units')]))")
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path / "walk.trc")], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-500:]
    n, labels, t0, first, units = json.loads(out.stdout)
    assert (n, labels, units) == (m.t.size, list(m.labels), "mm")
    assert abs(t0 - m.t[0]) < 1e-9 and np.allclose(first, 1e3 * m.xyz[0, 0], atol=1e-6)
