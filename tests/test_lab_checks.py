"""Bad lab data never becomes a confident answer (casflex.lab.checks, casflex.inverse.inputs, the readers).

Each test makes a real-looking bad file from the Hamner stride (tests/data/lab) or the walking2 C3D excerpt
and runs it through ``casflex inverse`` / ``calibrate`` (in process: ``casflex.cli.main``) or the Python API.
What the issue found (each of these gave a wrong answer with exit status 0, or a traceback): plate samples
that are not numbers taken as zero force, plate tables that do not cover the trial, the plate's last frame
dropped, headers whose units lie, markers that jump a kilometre, a cell of 1e300, uneven frames
differentiated as even, a moving trial taken as static, refusals that come after the whole marker fit.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from casflex.cli import main

LAB = Path(__file__).parent / "data" / "lab"
TRC, GRF = LAB / "hamner_running_stride.trc", LAB / "hamner_running_stride_grf.mot"
STATIC = LAB / "hamner_static_excerpt.trc"
BASE = ["inverse", "hamner_leg", "--root", "pelvis", "--quiet"]


def _run(argv: list[str], capsys) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _refused(argv: list[str], capsys, match: str) -> str:
    """The command's one line of refusal (exit 2), which must match ``match``."""
    code, _, err = _run(argv, capsys)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("casflex: error: "), (code, err)
    assert re.search(match, lines[0]), lines[0]
    return lines[0]


def _trc(tmp_path: Path, edit, name: str = "trial.trc") -> Path:
    """A copy of the stride's TRC with ``edit(rows)`` applied to its data rows (lists of cells as text)."""
    lines = TRC.read_text().splitlines()
    rows = [ln.split("\t") for ln in lines[5:] if ln.strip()]
    edit(rows)
    path = tmp_path / name
    path.write_text("\n".join(lines[:5] + ["\t".join(r) for r in rows]) + "\n")
    return path


def _mot(tmp_path: Path, edit, name: str = "grf.mot") -> Path:
    """A copy of the stride's plate table with ``edit(rows)`` applied to its rows (time first, as text)."""
    lines = GRF.read_text().splitlines()
    end = lines.index("endheader") + 2
    rows = [ln.split("\t") for ln in lines[end:] if ln.strip()]
    edit(rows)
    path = tmp_path / name
    path.write_text("\n".join(lines[:end] + ["\t".join(r) for r in rows]) + "\n")
    return path


def _row(rows, t: float) -> list[str]:
    """The row at time t (s): a TRC's rows have their time second (after the frame number), a table's first."""
    return next(r for r in rows if abs(float(r[1] if len(r) > 20 else r[0]) - t) < 1e-3)


def _set(rows, t: float, column: int, value: str) -> None:
    _row(rows, t)[column] = value


PLATE = ["--plate", "ankle=ground_", "--cutoff", "10"]


# -- 1. force plates ------------------------------------------------------------------------------------------

def _loads(res_argv, tmp_path, capsys) -> tuple[dict, str]:
    out = tmp_path / "loads.npz"
    code, _, err = _run([*res_argv, "--out", out], capsys)
    assert code == 0, err
    with np.load(out) as z:
        return dict(zip([str(s) for s in z["load_names"]], z["loads"].T, strict=True)), err


def test_one_plate_sample_not_a_number_at_the_peak_is_filled_and_said(tmp_path, capsys):
    """One NaN at the stance peak (0.517 s, 1455 N) was zero force: the ankle moment moved by 62 N m. Now the
    sample is filled by a spline through its neighbours, said on stderr, and the moments stay within what
    one 60 Hz sample's interpolation can change (the spline misses the true peak by a few %)."""
    good, _ = _loads([*BASE, "--data", TRC, "--loads", GRF, *PLATE], tmp_path, capsys)
    bad_mot = _mot(tmp_path, lambda rows: _set(rows, 0.517, 2, "NaN"))
    bad, err = _loads([*BASE, "--data", TRC, "--loads", bad_mot, *PLATE], tmp_path, capsys)
    assert re.search(r"warning: .*plate 'ground_': 1 sample at t = 0.517 s not a number, filled", err), err
    for joint in ("ankle", "knee", "hip"):
        peak = np.abs(good[f"{joint}.moment"]).max()
        # the missing peak sample rebuilt by a cubic spline: measured 0.9-2.5 % of each joint's peak moment;
        # bound 6 % (62 N m, 34 % of the ankle's peak, before)
        assert np.abs(bad[f"{joint}.moment"] - good[f"{joint}.moment"]).max() < 0.06 * peak, joint


@pytest.mark.parametrize(("column", "value", "match"), [
    (2, "inf", r"plate 'ground_' at t = 0.517 s: a force of inf N, beyond what a body exerts on a plate"),
    (2, "2.5e5", r"plate 'ground_' at t = 0.517 s: a force of 2.5e\+05 N, beyond what a body exerts"),
    (4, "1e4", r"plate 'ground_' at t = 0.517 s: its centre of pressure lies at \(1e\+04, -0.0075, -0.\d+\) m, beyond"),
    (8, "1e300", r"plate 'ground_' at t = 0.517 s: a free moment of 1e\+300 N m, beyond what a body exerts"),
])
def test_a_plate_value_no_body_produces_is_refused_naming_the_time(column, value, match, tmp_path, capsys):
    bad = _mot(tmp_path, lambda rows: _set(rows, 0.517, column, value))
    _refused([*BASE, "--data", TRC, "--loads", bad, *PLATE], capsys, match)


def test_an_unloaded_plate_s_centre_of_pressure_is_not_checked(tmp_path, capsys):
    """Zero force, the point anywhere (the Rajagopal pipeline's walking trial leaves it 346 m off in swing): the
    same loads as with the point left where it was; a force of 1 N there is refused (the point then moves it)."""
    def swing(force: str):
        def edit(rows):
            for r in rows:
                if float(r[2]) == 0.0:  # unloaded in the stride's table: its vertical force exactly zero
                    r[1:4] = ["0", force, "0"]
                    r[4:7] = ["346.1", "0", "96.4"]
        return edit

    assert any(float(r[2]) == 0.0 for r in [ln.split("\t") for ln in GRF.read_text().splitlines()[7:] if ln.strip()])
    good, _ = _loads([*BASE, "--data", TRC, "--loads", GRF, *PLATE], tmp_path, capsys)
    off, _ = _loads([*BASE, "--data", TRC, "--loads", _mot(tmp_path, swing("0")), *PLATE], tmp_path, capsys)
    for name, series in good.items():
        np.testing.assert_array_equal(off[name], series, err_msg=name)  # p x 0 = 0 exactly: no rounding enters
    _refused([*BASE, "--data", TRC, "--loads", _mot(tmp_path, swing("1")), *PLATE], capsys,
             r"its centre of pressure lies at \(346, 0, 96.4\) m, beyond any lab")


def test_a_long_run_of_missing_plate_samples_is_refused(tmp_path, capsys):
    """Six NaN samples in stance (0.1 s at 60 Hz) moved the knee by 241 N m; no spline may fill them."""
    def edit(rows):
        for t in (0.45, 0.467, 0.483, 0.5, 0.517, 0.533):
            _set(rows, t, 2, "NaN")

    bad = _mot(tmp_path, edit)
    _refused([*BASE, "--data", TRC, "--loads", bad, *PLATE], capsys,
             r"grf.mot: plate 'ground_': 6 samples are not numbers from t = 0.45 to 0.533 s, a gap longer than")


def test_a_plate_table_that_does_not_cover_the_trial_is_refused(tmp_path, capsys):
    def shift(rows):
        for r in rows:
            r[0] = f"{float(r[0]) + 5.0:.3f}"

    other = _mot(tmp_path, shift, "other.mot")
    _refused([*BASE, "--data", TRC, "--loads", other, *PLATE], capsys,
             r"other.mot: plate 'ground_': its samples span t = 5.4..6.117 s, the window of "
             r".*hamner_running_stride.trc 0.4..1.11667 s: they do not overlap")
    part = _mot(tmp_path, lambda rows: rows.__delitem__(slice(30, None)), "part.mot")
    _refused([*BASE, "--data", TRC, "--loads", part, *PLATE], capsys,
             r"part.mot: plate 'ground_': its force is recorded over t = 0.4..0.883 s only, not the whole window")
    # a window inside the table is taken
    code, _, err = _run([*BASE, "--data", TRC, "--loads", part, *PLATE, "--t-end", "0.85"], capsys)
    assert code == 0, err


def test_the_plate_s_last_sample_acts_at_the_last_frame(tmp_path, capsys):
    """The frames' even grid (60 Hz: 0.4 + k / 60) ended 1e-7 s after the plate's (its times rounded to ms,
    regridded by their own slope): the last frame's plate force was zero. Unfiltered, the root's vertical
    residual with and without the plate differs by the plate's vertical force at every frame, the last too
    (175.5 N at the next heel strike, 1.117 s)."""
    with_plate, _ = _loads([*BASE, "--data", TRC, "--loads", GRF, "--plate", "ankle=ground_", "--no-filter"],
                           tmp_path, capsys)
    without, _ = _loads([*BASE, "--data", TRC, "--no-filter"], tmp_path, capsys)
    from casflex.lab import read_sto

    fy = read_sto(GRF).column("ground_force_vy")
    # the root's driver holds the rest: its force changes by minus the plate's; round-off of ~1e3 N sums
    np.testing.assert_allclose(without["root.fy"] - with_plate["root.fy"], fy, rtol=0, atol=1e-9 * 1500)


# -- 2. markers --------------------------------------------------------------------------------------------------

def test_a_header_whose_units_lie_is_refused_before_the_fit(tmp_path, capsys, monkeypatch):
    _no_fit(monkeypatch)
    text = TRC.read_text().splitlines()
    for units, says in (("m", "mm"), ("cm", "mm")):
        lines = list(text)
        lines[2] = lines[2].replace("\tmm\t", f"\t{units}\t")
        path = tmp_path / f"{units}.trc"
        path.write_text("\n".join(lines) + "\n")
        _refused([*BASE, "--data", path], capsys, rf"{units}.trc: the trial's markers lie (1e\+03|10) times as far "
                 rf"apart as the scene's on the same segments: the header's units '{units}' are wrong \(the "
                 rf"numbers look like {says}\)")


def test_a_marker_jumping_for_one_frame_is_refused_naming_it(tmp_path, capsys, monkeypatch):
    _no_fit(monkeypatch)
    for jump, match in ((1000.0, r"marker 'R.ASIS' jumps 1.01 m from t = 0.617 to 0.633 s \(63 m/s; no body"),
                        (1e6, r"marker 'R.ASIS' at t = 0.633 s lies at \(1e\+03, 1.01, -0.0439\) m, beyond any "
                              r"capture volume")):
        path = _trc(tmp_path, lambda rows, j=jump: _set(rows, 0.633, 2, f"{float(_row(rows, 0.633)[2]) + j}"))
        _refused([*BASE, "--data", path], capsys, match)


def test_a_cell_of_1e300_is_refused_not_a_nan_in_every_output(tmp_path, capsys):
    path = _trc(tmp_path, lambda rows: _set(rows, 0.633, 5, "1e300"))
    _refused([*BASE, "--data", path], capsys, r"marker 'L.ASIS' at t = 0.633 s lies at \(1e\+297")
    path = _trc(tmp_path, lambda rows: _set(rows, 0.633, 5, "inf"))
    _refused([*BASE, "--data", path], capsys, r"marker 'L.ASIS' at t = 0.633 s lies at \(inf, ")


def test_junk_in_a_marker_the_scene_does_not_use_is_no_reason_to_refuse(tmp_path, capsys):
    """Labs leave junk in channels nobody uses: only the scene's markers are checked. The stride's TRC with a
    14th marker, 'Junk', at 1e300 and once infinite, is taken."""
    lines = TRC.read_text().splitlines()
    k = len(lines[3].split("\t")[2:]) // 3 + 1  # the new marker's number: 14
    lines[3] += "Junk\t\t\t"
    lines[4] += f"\tX{k}\tY{k}\tZ{k}"
    rows = [ln.split("\t") for ln in lines[5:] if ln.strip()]
    for i, r in enumerate(rows):
        r[2 + 3 * (k - 1):] = ["inf" if i == 20 else "1e300", "0", "0"]
    path = tmp_path / "junk.trc"
    path.write_text("\n".join(lines[:5] + ["\t".join(r) for r in rows]) + "\n")
    from casflex.lab import read_trc

    assert read_trc(path).labels[-1] == "Junk"
    code, _, err = _run([*BASE, "--data", path], capsys)
    assert code == 0, err


def test_a_marker_off_by_15_cm_in_one_frame_is_refused_after_the_fit_naming_it(tmp_path, capsys):
    """Too slow for the jump check at 60 Hz (9 m/s), too far for soft tissue: the fit's misfit names it."""
    path = _trc(tmp_path, lambda rows: _set(rows, 0.633, 2, f"{float(_row(rows, 0.633)[2]) + 150}"))
    _refused([*BASE, "--data", path], capsys, r"at t = 0.633333 s marker 'R.ASIS' lies 1\d\d mm from where the best "
             r"pose of the scene puts it \(max_misfit 100 mm\)")
    code, _, err = _run([*BASE, "--data", path, "--max-misfit", "0.2"], capsys)
    assert code == 0, err


def test_uneven_frames_are_refused_unfiltered_too(tmp_path, capsys, monkeypatch):
    _no_fit(monkeypatch)
    path = _trc(tmp_path, lambda rows: _set(rows, 0.633, 1, "0.639"))
    for extra in (["--no-filter"], ["--cutoff", "6"]):
        _refused([*BASE, "--data", path, *extra], capsys, r"trial.trc: frames must be evenly spaced .*: t = 0.639 s "
                 r"follows 0.617 s, the frames are 0.01[67] s apart elsewhere")


def test_a_trial_whose_markers_are_all_missing_is_one_line(tmp_path, capsys):
    def empty(rows):
        for r in rows:
            r[2:] = [""] * (len(r) - 2)

    _refused([*BASE, "--data", _trc(tmp_path, empty)], capsys, r"none of the scene's markers \['R.ASIS'")


@pytest.mark.parametrize(("rate", "match"), [("0", r"header DataRate '0' must be a rate > 0"),
                                              ("sixty", r"header DataRate 'sixty' is not a number")])
def test_a_bad_data_rate_is_one_line_naming_it(rate, match, tmp_path, capsys):
    lines = TRC.read_text().splitlines()
    lines[2] = rate + lines[2][2:]
    path = tmp_path / "rate.trc"
    path.write_text("\n".join(lines) + "\n")
    _refused([*BASE, "--data", path], capsys, f"rate.trc: {match}")


def test_a_moving_trial_is_not_taken_as_the_static_one(tmp_path, capsys):
    out = tmp_path / "subject.toml"
    _refused(["calibrate", "hamner_leg", "--static", TRC, "--root", "pelvis", "--out", out], capsys,
             r"hamner_running_stride.trc: not a static trial: marker '.*' lies \d+ mm from its mean position")
    code, _, err = _run(["calibrate", "hamner_leg", "--static", STATIC, "--root", "pelvis", "--out", out], capsys)
    assert code == 0 and out.is_file(), err


@pytest.mark.parametrize(("word", "degrees"), [("yes", True), ("true", True), ("True", True), ("no", False),
                                                ("false", False)])
def test_in_degrees_as_yes_or_true(word, degrees, tmp_path):
    from casflex.lab import read_sto

    path = tmp_path / "ik.mot"
    path.write_text(f"inDegrees={word}\nendheader\ntime\tknee\n0\t10\n0.01\t20\n")
    assert read_sto(path).in_degrees is degrees
    path.write_text("inDegrees=maybe\nendheader\ntime\tknee\n0\t10\n")
    with pytest.raises(ValueError, match=r"ik.mot: header inDegrees='maybe'; expected yes or no"):
        read_sto(path)


# -- 3. tracebacks that are one line now --------------------------------------------------------------------

def test_hinges_that_close_a_loop_are_refused():
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    from inverse_scenes import pendulum

    from casflex.inverse import inverse_model, kinematic_tree
    from casflex.scene.io import loads_scene

    twice = '[[joints]]\nname = "pivot2"\nkind = "hinge"\nnodes = ["base", "link"]\npoint = [0.0, 0.9]\n'
    with pytest.raises(ValueError, match=r"joint 'pivot2': closes a loop"):
        kinematic_tree(inverse_model(loads_scene(pendulum(twice))))


def test_a_csv_input_with_a_header_and_blank_rows_is_one_line(tmp_path):
    from casflex.scene.io import load_scene
    from casflex.scene.items import SceneError

    scene = tmp_path / "s.toml"
    scene.write_text(_csv_scene())
    (tmp_path / "load.csv").write_text("t,fx\n\n \n")
    with pytest.raises(SceneError, match=r"load.csv' has no data rows under its header"):
        load_scene(scene)
    (tmp_path / "load.csv").write_text("t,fx\n0,1\n0.1,nan\n")
    with pytest.raises(SceneError, match=r"loads\[0\].table.fx: column 'fx' is not a number at t = 0.1 s"):
        load_scene(scene)
    (tmp_path / "load.csv").write_bytes(b"t,fx\n0,\xff\n")
    with pytest.raises(SceneError, match=r"load.csv' is not a UTF-8 text file \(byte 7\)"):
        load_scene(scene)
    (tmp_path / "load.csv").write_text("t,fx\n0,1\n0,2\n")
    with pytest.raises(SceneError, match=r"times must increase: row 2 repeats t = 0 s"):
        load_scene(scene)


def _csv_scene() -> str:
    return """name = "mass"
[[nodes]]
name = "a"
x = 0.0
y = 0.0
[[bodies]]
name = "m"
node = "a"
mass = 1.0
[[loads]]
name = "push"
node = "a"
table = {file = "load.csv", fx = "fx"}
"""


def test_c3d_plates_that_are_not_there_or_not_sampled_are_one_line(tmp_path, capsys):
    pytest.importorskip("ezc3d")
    import struct

    from casflex.lab import read_c3d

    raw = bytearray((LAB / "walking2_excerpt.c3d").read_bytes())
    rates = [m.start() for m in re.finditer(rb"RATE", raw[:6656])]
    analog = next(i for i in rates if struct.unpack("<f", raw[i + 8:i + 12])[0] == 2000.0)
    raw[analog + 8:analog + 12] = struct.pack("<f", 0.0)
    path = tmp_path / "rate0.c3d"
    path.write_bytes(bytes(raw))
    with pytest.raises(ValueError, match=r"rate0.c3d: ANALOG:RATE is 0 Hz and the plates have 0 samples"):
        read_c3d(path)
    assert read_c3d(path, plates=False)[0].xyz.shape == (210, 44, 3)
    # a C3D with no plates given as the plates of a TRC trial
    fp = raw.index(b"FORCE_PLATFORM", 0, 6656)  # its group id, negative before the name: its parameters carry -id
    used = raw.index(bytes([4, 256 - raw[fp - 1]]) + b"USED", 0, 6656) + 2
    none = bytearray((LAB / "walking2_excerpt.c3d").read_bytes())
    none[used + 8:used + 10] = b"\x00\x00"  # FORCE_PLATFORM:USED = 0
    path = tmp_path / "noplates.c3d"
    path.write_bytes(bytes(none))
    _refused([*BASE, "--data", TRC, "--loads", path, *PLATE], capsys, r"noplates.c3d: the file has no force plates")


# -- 5. refusals before the marker fit ---------------------------------------------------------------------------

def _no_fit(monkeypatch) -> None:
    """Make the marker fit fail loudly: a refusal that comes after it shows as this error, not the refusal."""
    import casflex.inverse as inv

    def fit(*args, **kwargs):
        raise AssertionError("the marker fit ran")

    monkeypatch.setattr(inv, "fit_markers", fit)


@pytest.mark.parametrize(("extra", "match"), [
    (["--loads", GRF, "--plate", "ankle=ground2_"], r"no plate 'ground2_'"),
    (["--loads", GRF, "--plate", "ankle=ground_", "--cutoff", "40"], r"cutoff: must lie between 0 and the Nyquist"),
    (["--loads", GRF, "--plate", "ankle=ground_", "--cutoff", "1e-9"],
     r"cutoff: 1e-09 Hz is a period over twice the markers' span of 0.716667 s"),
    (["--passive", "knee:0.1:0.5"], r"--passive: the window 0.1..0.5 s of 'knee' is not inside the trial's 0.4.."),
])
def test_what_the_inputs_decide_is_refused_before_the_marker_fit(extra, match, capsys, monkeypatch):
    _no_fit(monkeypatch)
    _refused([*BASE, "--data", TRC, *extra], capsys, match)


def test_a_trial_too_long_for_the_memory_is_refused_before_the_fit(capsys, monkeypatch):
    import casflex.results

    _no_fit(monkeypatch)
    monkeypatch.setattr(casflex.results, "memory_available", lambda: 100_000)  # the stride's 20 kB read, not its fit
    _refused([*BASE, "--data", TRC], capsys, r"t_start, t_end: 44 frames of \d+ values each need about .* of memory "
             r"and 97.7 KiB are available; take a shorter window")


# -- 6. messages that name what is wrong ------------------------------------------------------------------------

def test_the_documented_plane_with_a_minus_sign_is_taken(capsys):
    """``--plane -Z,Y`` (docs/lab.md) was taken by the parser for an option: "expected one argument"."""
    code, _, err = _run([*BASE, "--data", TRC, "--plane", "-Z,Y"], capsys)
    # seen from +X the stride's markers do not sit where the scene has them: refused, but by casflex, for that
    assert code == 2 and "expected one argument" not in err and "--plane" not in err, err


def test_coordinate_checks_tell_units_from_motion():
    """check_coordinates on a 60 Hz stride-like motion: the real one passes; each unit error is named."""
    from casflex.lab.checks import check_coordinates

    t = np.arange(44) / 60.0
    knee = np.radians(-20 - 40 * (1 - np.cos(2 * np.pi * t / t[-1])))  # to -100 degrees in swing
    x = 0.8 + 0.02 * np.sin(2 * np.pi * t)
    good = [("pelvis_tx", x, "length", None), ("knee_angle_r", knee, "hinge", (-2.094, 0.175))]
    check_coordinates("ik.mot", t, good, True)
    cases = [
        # centimetres read as metres, 80 m from the origin: within a lab, but 250 m/s between two frames
        ([("pelvis_tx", 100 * x + np.sin(60 * t), "length", None)], True, r"^ik.mot: column 'pelvis_tx' moves "),
        # the knee 40 degrees past its range's end: another model's sign convention
        ([("knee_angle_r", -knee, "hinge", (-2.094, 0.175))], True,
         r"column 'knee_angle_r' reaches 99.89 degrees at t = 0.35 s, more than 30 degrees beyond the model's range "
         r"-120..10.03 degrees"),
        ([("knee_angle_r", knee, "hinge", None)], True, None),  # without a range, -100 degrees is fine
        ([("knee_angle_r", np.radians(knee), "hinge", None)], True, r"within 1.74 degrees over the trial"),
        ([("knee_angle_r", np.radians(knee), "hinge", None)], False, None),  # radians said: tiny is theirs to say
    ]
    for columns, degrees, match in cases:
        if match is None:
            check_coordinates("ik.mot", t, columns, degrees)
            continue
        with pytest.raises(ValueError, match=match):
            check_coordinates("ik.mot", t, columns, degrees)


def test_a_joint_moment_beyond_20_n_m_per_kg_is_refused():
    from casflex.lab.checks import check_moments

    t = np.arange(5) * 0.01
    check_moments("trial.trc", t, {"knee.moment": np.full(5, 1599.0)}, 80.0)  # 19.99 N m/kg: no human, still taken
    with pytest.raises(ValueError, match=r"^trial.trc: knee.moment reaches -1601 N m at t = 0.02 s, 20 N m per kg of a "
                                         r"body of 80 kg; no human joint carries 20 N m/kg"):
        check_moments("trial.trc", t, {"knee.moment": np.array([0, 1, -1601, 3, 4.0])}, 80.0)
    with pytest.raises(ValueError, match=r"^trial.trc: knee.moment is not a number at t = 0.03 s$"):
        check_moments("trial.trc", t, {"knee.moment": np.array([0, 1, 2, np.nan, 4.0])}, 80.0)



def test_a_joint_force_beyond_30_body_weights_is_said_not_refused():
    from casflex.lab.checks import joint_force_lines

    t = np.arange(5) * 0.01
    w = 9.81 * 80.0
    assert joint_force_lines("trial.trc", t, {"knee": np.full(5, 29.99 * w)}, 80.0) == []  # no human, still quiet
    lines = joint_force_lines("trial.trc", t, {"hip": np.zeros(5), "knee": np.array([0, 1, 30.5 * w, 3, np.nan])}, 80.0)
    assert lines == ["trial.trc: the force at knee reaches 2.394e+04 N at t = 0.02 s, 30.5 body weights of a body of "
                     "80 kg; no human joint passes on 30 (the ground's push and the segments' inertia: 1-3 walking and "
                     "running, 5-15 landing): the plates' forces in another unit or on the wrong body, or the "
                     "markers' or coordinates' units wrong"]


def test_the_inverse_says_a_joint_force_beyond_the_limit_on_stderr_and_in_its_report(tmp_path, capsys, monkeypatch):
    """The limit lowered to 0.5 body weights: the stride's ankle passes on 0.99 (its body's mass the plate's peak
    over g, 146 kg at 6 Hz, the leg's 23 kg being less), said with its time, the run done; at 30 nothing of the repo's
    trials comes near (peaks 0.84-0.99: Hamner's run, walking2, the Rajagopal walk, biomechZoo's children)."""
    import casflex.lab.checks as checks

    code, _, err = _run([*BASE, "--data", TRC, "--loads", GRF, "--plate", "ankle=ground_"], capsys)
    assert code == 0 and "body weights" not in err
    monkeypatch.setattr(checks, "MAX_JOINT_FORCE_BW", 0.5)
    code, out, err = _run([*BASE, "--data", TRC, "--loads", GRF, "--plate", "ankle=ground_", "--out",
                           tmp_path / "loads.csv"], capsys)
    said = [ln for ln in err.splitlines() if "the force at ankle reaches" in ln]
    assert code == 0 and len(said) == 1 and said[0].startswith("casflex: warning: ")
    assert re.search(r"the force at ankle reaches 14\d\d N at t = 0.5\d* s, 0.9\d+ body weights of a body of "
                     r"1[45]\d kg", said[0]), said[0]
    assert (tmp_path / "loads.csv").exists()
    from casflex.inverse import Trial, inverse_dynamics

    res = inverse_dynamics("hamner_leg", Trial(str(TRC), grf=str(GRF), plates={"ankle": "ground_"}, root="pelvis"))
    said = [ln for ln in res.report if "the force at" in ln]
    assert [ln for ln in res.warnings if "the force at" in ln] == said
    assert [ln.split(": ")[1].split(" reaches")[0] for ln in said] == ["the force at hip", "the force at knee",
                                                                        "the force at ankle"]  # 0.84-0.99 BW each

# -- 7. markers that decide no pose, static trials that scale a segment to nothing -----------------------------

FOOT = ("R.Heel", "R.Midfoot.Sup", "R.Midfoot.Lat", "R.Toe.Tip")


def _columns(path: Path, labels) -> list[int]:
    """The cells (x, y, z) of the markers ``labels`` in a TRC's rows."""
    names = [c for c in path.read_text().splitlines()[3].split("\t")[2:] if c]
    return [2 + 3 * names.index(lb) + a for lb in labels for a in range(3)]


def test_a_segment_whose_markers_are_all_at_the_origin_is_named_before_the_fit(tmp_path, capsys, monkeypatch):
    """The foot's markers written as (0, 0, 0) (a dropped marker) in every frame: an IndexError in the fit."""
    cols = _columns(TRC, FOOT)

    def drop(rows):
        for r in rows:
            for c in cols:
                r[c] = "0"

    _no_fit(monkeypatch)
    _refused([*BASE, "--data", _trc(tmp_path, drop)], capsys,
             r"trial.trc: the markers do not decide \['ankle.angle'\] in any frame: segment 'ankle' has no marker to "
             r"place it \(\['R.Heel', 'R.Midfoot.Sup', 'R.Midfoot.Lat', 'R.Toe.Tip'\] never seen in the window\); a "
             r"hinged segment needs a marker off its joint, the root's two")


def test_weights_that_leave_a_segment_undecided_are_named():
    from casflex.inverse import Trial, inverse_dynamics

    with pytest.raises(ValueError, match=r"do not decide \['knee.angle', 'ankle.angle'\] in any frame: segment 'knee' "
                                         r"has no marker to place it; segment 'ankle' has no marker"):
        inverse_dynamics("hamner_leg", Trial(TRC, root="pelvis", tasks={lb: 1.0 for lb in (
            "R.ASIS", "L.ASIS", "V.Sacral", "R.Thigh.Upper", "R.Thigh.Front", "R.Thigh.Rear")}))
    with pytest.raises(ValueError, match=r"segment 'pelvis' has no marker to place it; .* segment 'ankle' has the "
                                         r"markers \['R.Heel'\] to place it"):
        inverse_dynamics("hamner_leg", Trial(TRC, root="pelvis", tasks={"R.Heel": 1.0}))
    import dataclasses

    from casflex.scene.io import load_scene

    sc = load_scene("hamner_leg")  # the scene's own weights: the foot's 0
    sc = dataclasses.replace(sc, markers=tuple(dataclasses.replace(m, weight=0.0) if m.label in FOOT else m
                                               for m in sc.markers))
    with pytest.raises(ValueError, match=r"segment 'ankle' has no marker to place it \(\['R.Heel', 'R.Midfoot.Sup', "
                                         r"'R.Midfoot.Lat', 'R.Toe.Tip'\] of weight 0\)"):
        inverse_dynamics(sc, Trial(TRC, root="pelvis"))


def test_markers_never_seen_together_are_one_line_not_an_index_error():
    """Each marker is seen in some frames (so together they would decide the pose) but no frame sees enough."""
    from casflex.inverse import Trial, kinematic_tree, prepare
    from casflex.inverse.fit import fit_markers

    inputs = prepare("hamner_leg", Trial(str(TRC), root="pelvis"))
    y = inputs.y.copy().reshape(inputs.t.size, -1, 2)
    foot = [inputs.labels.index(lb) for lb in FOOT]
    rest = [k for k in range(y.shape[1]) if k not in foot]
    y[0::2, foot], y[1::2, rest] = np.nan, np.nan
    tree = kinematic_tree(inputs.model, "pelvis")
    with pytest.raises(ValueError, match=r"^data: the markers do not decide the coordinates in any frame: no frame "
                                         r"sees enough of them at once"):
        fit_markers(tree, inputs.t, y.reshape(inputs.t.size, -1), source="data")


@pytest.mark.parametrize("spread", [0.0, 2.0])  # mm between the shank's three markers in the static trial
def test_a_static_trial_whose_segment_markers_coincide_does_not_scale_it_to_nothing(spread, tmp_path, capsys):
    """The shank's three markers at one point (or within 4 mm): scaled by 0 (a traceback-free refusal only by luck:
    the pose went undecided) or by 0.048 with exit 0 and a shank of 2 cm."""
    lines = STATIC.read_text().splitlines()
    cols = _columns(STATIC, ("R.Shank.Upper", "R.Shank.Front", "R.Shank.Rear"))
    for i, line in enumerate(lines[5:], start=5):
        cells = line.split("\t")
        if len(cells) > 20:
            for k, c in enumerate(cols[3:]):
                cells[c] = f"{float(cells[cols[k % 3]]) + spread * (k // 3 + 1) * (k % 3 == k // 3):.5f}"
            lines[i] = "\t".join(cells)
    path = tmp_path / "static.trc"
    path.write_text("\n".join(lines) + "\n")
    _refused(["calibrate", "hamner_leg", "--static", path, "--scale", "--out", tmp_path / "s.toml"], capsys,
             r"static.trc: segment 'knee' would be scaled by 0(.0477)?: its markers lie R.Shank.Upper-R.Shank.Front "
             r"[02] mm \(scene 83\), .* markers that coincide or are mislabelled, or a segment held across the plane")
    assert not (tmp_path / "s.toml").exists()


def test_a_model_with_massless_feet_names_the_foot_its_markers_left(tmp_path):
    """OpenSim's talus, calcaneus and toes of mass 0: nodes only, their markers left out by the import; the ankle's
    angle then had no marker (an IndexError in the fit)."""
    import re as regex

    from casflex.inverse import Trial, inverse_dynamics

    text = (LAB / "hamner_subject02_leg.osim").read_text()
    for body in ("talus_r", "calcn_r", "toes_r"):
        text = regex.sub(rf'(<Body name="{body}">\s*<mass>)[^<]*', r"\g<1>0", text)
    osim = tmp_path / "massless.osim"
    osim.write_text(text)
    with pytest.raises(ValueError, match=r"do not decide \['ankle_angle_r'\] in any frame: segment 'talus_r' has no "
                                         r"marker to place it \(nodes \['talus_r', 'calcn_r', 'toes_r'\] and no body"):
        inverse_dynamics(osim, Trial(TRC))


def test_the_plates_share_of_the_motion_s_needs_is_said_only_outside_its_bounds():
    from casflex.lab.checks import PLATE_SHARE, plate_share_lines

    t = np.linspace(0.0, 1.0, 101)
    needed = 700.0 * np.clip(np.sin(2 * np.pi * t), 0.0, None) + 5.0  # a stance, then flight
    assert plate_share_lines("trial.trc", t, 1.0 * needed, needed) == []  # a whole body
    assert plate_share_lines("trial.trc", t, 2.7 * needed, needed) == []  # a leg with its pelvis
    for share in (0.9 * PLATE_SHARE[0], 1.1 * PLATE_SHARE[1]):
        (line,) = plate_share_lines("trial.trc", t, share * needed, needed)
        assert line.startswith("trial.trc: where the plates are loaded (") and f"push {share:.3g} times" in line
    edge = np.where(t < 0.02, 30.0, 0.0)  # two loaded frames: too few to tell a share
    assert plate_share_lines("trial.trc", t, edge, needed) == []
