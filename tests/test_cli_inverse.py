"""``casflex inverse`` on the Hamner stride: files written, options refused in one line before any work."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from casflex.cli import main

LAB = Path(__file__).parent / "data" / "lab"
TRC, GRF = str(LAB / "hamner_running_stride.trc"), str(LAB / "hamner_running_stride_grf.mot")
BASE = ["inverse", "hamner_leg", "--data", TRC, "--root", "pelvis", "--quiet"]
LOUD = [a for a in BASE if a != "--quiet"]  # the summary on stdout (--quiet prints nothing but warnings and errors)


def _run(argv: list[str], capsys) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_writes_the_loads_as_csv_npz_and_figures(tmp_path, capsys):
    csv, npz, figs = tmp_path / "loads.csv", tmp_path / "loads.npz", tmp_path / "figs"
    for out in (csv, npz):
        code, text, err = _run([*LOUD, "--loads", GRF, "--plate", "ankle=ground_", "--cutoff", "10", "--out", str(out),
                                "--passive", "knee:0.7:1.05"]
                               + (["--plots", str(figs)] if out == csv else []), capsys)
        assert code == 0, err
        assert "hip.moment" in text and "plates 'ground_' on ankle" in text
        # the knee in swing over 0.35 s: a smooth muscle moment, 87 % 'explained' by a spring over 4 independent
        # samples with huge errors: the verdict says it does not decide a passive joint
        assert "passive knee over t = 0.7" in text and "not a passive joint" in text
    header = csv.read_text().splitlines()[0].split(",")
    assert header[0] == "t [s]" and "pelvis.x [m]" in header and "knee.angle [rad]" in header
    assert "knee.moment [N m]" in header and "root.fy [N]" in header
    table = np.loadtxt(csv, delimiter=",", skiprows=1)
    with np.load(npz) as z:
        names = [str(s) for s in z["load_names"]]
        k = names.index("knee.moment")
        assert np.allclose(table[:, header.index("knee.moment [N m]")], z["loads"][:, k], rtol=1e-9)
        assert z["q"].shape == (table.shape[0], 12)
    assert sorted(p.name for p in figs.iterdir()) == ["inverse_loads.png", "marker_fit.png"]


@pytest.mark.parametrize(("extra", "match"), [
    (["--plate", "ankle"], "--plate: expected NODE=PREFIX"),
    (["--plate", "ankle=ground_"], "--plate: needs --loads"),
    (["--loads", GRF], "--loads: say which node"),
    (["--loads", GRF, "--plate", "heel=ground_"], "plates: no node 'heel'"),
    (["--loads", GRF, "--plate", "ankle=2_ground_"],
     r"no plate '2_ground_' \(columns 2_ground_force_vx .*the plates there are \['ground_'\]"),
    (["--plane", "X,X"], "--plane: expected two different lab axes"),
    (["--cutoff", "0"], "--cutoff: must be a frequency in Hz > 0"),
    (["--filter", "spline"], "--filter: invalid choice: 'spline'"),
    (["--cutoff", "40"], "cutoff: must lie between 0 and the Nyquist frequency 30 Hz"),
    (["--t-start", "0.5", "--t-end", "0.45"], "--t-end: must be after --t-start"),
    (["--t-start", "0.9", "--t-end", "0.95"], "t_start, t_end: the window"),
    (["--root", "hip"], "support|root|run away"),
    (["--passive", "elbow"], "--passive: no hinge 'elbow'"),
    (["--passive", "knee:0.7"], "--passive: expected HINGE or HINGE:T0:T1"),
    (["--passive", "knee:0.9:0.7"], "the window's end must follow its start"),
    (["--uncertain", "shank.mass"], "--uncertain: expected TARGET=SD, TARGET=PERCENT% or TARGET=LOWER:UPPER"),
    (["--uncertain", "shank.mass=-1"], r"--uncertain: 'shank.mass=-1': must be >= 0"),
    (["--uncertain", "nobody.mass=10%"], r"--uncertain: .*unknown element or load 'nobody'"),
    (["--uncertain", "knee.kt=1"], r"--uncertain: .*'knee' is a joint"),
    (["--uncertain", "shank.inertia=0.06:0.08"], r"--uncertain: .*the scene's value 0.0551641 lies outside"),
    (["--marker-noise", "-1"], "--marker-noise: must be a distance in m >= 0"),
    (["--no-bands", "--uncertain", "shank.mass=10%"], r"--bands: not asked \(False\), yet uncertain"),
])
def test_bad_options_exit_2_with_one_line_and_write_nothing(extra, match, tmp_path, capsys):
    out = tmp_path / "x.csv"
    code, text, err = _run([*BASE, "--out", str(out), *extra], capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("casflex: error:")
    import re

    assert re.search(match, lines[0]), lines[0]
    assert list(tmp_path.iterdir()) == []


def test_a_label_the_trial_lacks_is_left_out_and_said_and_a_segment_with_none_locked(tmp_path, capsys):
    # before: refused ("no marker labelled 'R.Heel'"); OpenSim's IK leaves such a marker out
    trc = tmp_path / "t.trc"
    trc.write_text(Path(TRC).read_text().replace("R.Heel", "R.Heal"))
    code, _, err = _run(["inverse", "hamner_leg", "--data", str(trc), "--root", "pelvis", "--out",
                         str(tmp_path / "loads.npz")], capsys)
    assert code == 0, err
    assert f"casflex: warning: {trc}: the scene's markers ['R.Heel'] are not in the trial: left out of the fit (as " \
           "OpenSim's IK leaves out a marker the trial lacks)" in err.splitlines()
    text = Path(TRC).read_text()
    for label in ("R.Heel", "R.Midfoot.Sup", "R.Midfoot.Lat", "R.Toe.Tip"):  # the foot's every marker
        text = text.replace(label, label.replace(".", "_"))
    trc.write_text(text)
    code, _, err = _run(["inverse", "hamner_leg", "--data", str(trc), "--root", "pelvis", "--quiet"], capsys)
    # a segment the trial records none of the markers of is locked where it hangs, and said (a lower-body marker set
    # on a whole-body model: tests/test_marker_sets.py)
    assert code == 0 and err.count("\n") == 1
    assert "segment 'ankle': " in err and "has none of its markers ['R.Heel', 'R.Midfoot.Sup', 'R.Midfoot.Lat', " \
           "'R.Toe.Tip']: its joint 'ankle' locked at the model's default pose" in err


def test_uncertain_properties_give_each_load_its_band(tmp_path, capsys):
    out = tmp_path / "loads.sto"
    code, text, err = _run([*LOUD, "--uncertain", "shank.mass=10%", "--uncertain", "thigh.inertia=0.12:0.16",
                            "--marker-noise", "0.002", "--out", str(out)], capsys)
    assert code == 0, err
    assert "anthropometry from shank.mass (sd 0.325), thigh.inertia (sd 0.0115)" in text
    assert "markers' noise 2.00 mm per axis (declared" in text
    peak = text.split("bands at each moment's peak")[1].splitlines()
    assert [line.split()[0] for line in peak[1:4]] == ["hip.moment", "knee.moment", "ankle.moment"]
    names = out.read_text().split("endheader\n")[1].splitlines()[0].split("\t")
    assert {"knee.moment_sd", "knee.moment_sd_anthropometry", "knee.moment_sd_markers"} <= set(names)


@pytest.mark.parametrize(("argv", "match"), [
    (["inverse", "hamner_leg_flexible", "--data", TRC, "--root", "pelvis", "--uncertain", "pelvis.mass=10%"],
     r"--bands: for rigid segments only: the beams \['thigh_bone_1'"),
    (["inverse", "hamner_leg", "--coordinates", "ik.mot", "--marker-noise", "0.001"],
     "--marker-noise: the coordinates were given"),
])
def test_bands_the_inverse_cannot_give_are_refused_before_any_work(argv, match, tmp_path, capsys):
    code, _, err = _run([*argv, "--quiet", "--out", str(tmp_path / "x.csv")], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    import re

    assert re.search(match, err), err
    assert list(tmp_path.iterdir()) == []


def test_a_figure_s_place_taken_by_a_folder_is_refused_before_the_fit(tmp_path, capsys, monkeypatch):
    """--plots figs where figs/marker_fit.png is a folder: found only when the figures were moved into place, after
    the whole marker fit (33 s on 20k frames)."""
    import casflex.inverse as inv

    monkeypatch.setattr(inv, "fit_markers", lambda *a, **k: pytest.fail("the marker fit ran"))
    figs = tmp_path / "figs"
    (figs / "marker_fit.png").mkdir(parents=True)
    code, _, err = _run([*BASE, "--plots", str(figs)], capsys)
    assert code == 2 and err.strip() == (f"casflex: error: --plots: '{figs / 'marker_fit.png'}' is a directory; the "
                                         "figure 'marker_fit.png' would go there: give another directory")
    assert [p.name for p in figs.iterdir()] == ["marker_fit.png"]


def test_several_outputs_in_one_run_the_ik_mot_read_back_gives_the_same_loads(tmp_path, capsys):
    """--out repeated writes every file (it kept only the last); the .mot is OpenSim's IK result (the fit,
    unfiltered, degrees), which --coordinates reads back: the same filter on the same coordinates, the same loads."""
    outs = {fmt: tmp_path / f"run.{fmt}" for fmt in ("npz", "csv", "sto", "mot")}
    code, text, err = _run([*BASE, "--loads", GRF, "--plate", "ankle=ground_",
                            *(a for p in outs.values() for a in ("--out", str(p)))], capsys)
    assert code == 0, err
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in outs.values())
    head, _, body = outs["mot"].read_text().partition("endheader\n")
    assert head.splitlines()[0].startswith("Coordinates") and "inDegrees=yes" in head.splitlines()
    assert body.splitlines()[0].split("\t") == ["time", "pelvis.x", "pelvis.y", "pelvis.theta", "hip.angle",
                                                "knee.angle", "ankle.angle"]
    with np.load(outs["npz"]) as z:
        from casflex.inverse.result import NPZ_KEYS  # docs/lab.md's table of the keys

        assert set(z.files) == {k for k in NPZ_KEYS if not k.startswith(("sd_", "band_"))}  # no bands asked
        fitted, names = z["fitted"], [str(s) for s in z["fitted_names"]]
        assert [str(u) for u in z["fitted_units"]] == ["m", "m", "rad", "rad", "rad", "rad"]
        first = z["loads"]
        # the .mot holds the fit, unfiltered: not the filtered z (they differ by the 6 Hz filter's smoothing)
        assert np.abs(fitted - z["z"]).max() > 1e-3
    mot = np.loadtxt(outs["mot"], skiprows=len(head.splitlines()) + 2)  # the header, endheader, the names
    assert np.allclose(np.radians(mot[:, 4:]), fitted[:, 3:], atol=1e-9)  # %.10g of degrees
    again = tmp_path / "again.npz"
    code, _, err = _run(["inverse", "hamner_leg", "--coordinates", str(outs["mot"]), "--loads", GRF, "--plate",
                         "ankle=ground_", "--root", "pelvis", "--quiet", "--out", str(again)], capsys)
    assert code == 0, err
    with np.load(again) as z:
        # 10 significant digits in the .mot: loads of up to ~1000 N agree to well under 1e-3 N
        assert np.allclose(z["loads"], first, atol=1e-3) and names == [str(s) for s in z["fitted_names"]]


def test_quiet_prints_nothing_and_the_csv_header_names_each_column_once_with_its_unit(tmp_path, capsys):
    csv = tmp_path / "loads.csv"
    code, text, err = _run([*BASE, "--loads", GRF, "--plate", "ankle=ground_", "--out", str(csv)], capsys)
    assert code == 0 and text == "" and err == ""
    header = csv.read_text().splitlines()[0].split(",")
    assert len(header) == len(set(h.split(" [")[0] for h in header))  # hip.angle was there twice
    assert all(h.endswith(("[s]", "[m]", "[rad]", "[N]", "[N m]")) for h in header), header
    assert header.count("knee.angle [rad]") == 1 and "knee.moment [N m]" in header and "root.mz [N m]" in header


def test_progress_lines_end_with_a_newline_where_stderr_is_no_terminal(tmp_path, capsys):
    code, _, err = _run(LOUD, capsys)  # capsys's stderr is no terminal, as a log file
    assert code == 0
    fit = [line for line in err.splitlines() if "marker fit" in line and "frames" in line]
    assert "\r" not in err and fit[-1] == "casflex: marker fit 44/44 frames" and 2 <= len(fit) <= 5, fit


def test_match_opensim_filters_as_opensim_s_id_tool_and_refuses_an_option_against_it(tmp_path, capsys):
    """--match opensim: OpenSim's IK then its ID tool as a lab runs them (the README's first .osim command): the
    coordinates filtered as the ID tool does at --cutoff, the plates unfiltered."""
    base = [*BASE, "--loads", GRF, "--plate", "ankle=ground_"]
    runs = {"match": ["--match", "opensim"], "spelled": ["--filter", "opensim", "--cutoff-plates", "none"], "own": []}
    loads = {}
    for tag, extra in runs.items():
        code, _, err = _run([*base, *extra, "--out", str(tmp_path / f"{tag}.npz")], capsys)
        assert code == 0, err
        with np.load(tmp_path / f"{tag}.npz") as z:
            loads[tag] = z["loads"]
            settings = __import__("json").loads(str(z["meta"]))["settings"]
        if tag == "match":
            assert settings["filter"] == "opensim" and settings["cutoff_plates_hz"] is None, settings
    assert np.array_equal(loads["match"], loads["spelled"])
    assert np.abs(loads["match"] - loads["own"]).max() > 1.0  # N m: the filters differ (36 N m at the ankle)
    for extra, said in ((["--filter", "butterworth"], "--filter: butterworth contradicts --match opensim"),
                        (["--cutoff-plates", "same"], "--cutoff-plates: same contradicts --match opensim")):
        code, _, err = _run([*base, "--match", "opensim", *extra, "--out", str(tmp_path / "x.csv")], capsys)
        assert code == 2 and err.startswith(f"casflex: error: {said}") and len(err.splitlines()) == 1, err
    assert not (tmp_path / "x.csv").exists()


def _npz_loads(path) -> dict[str, np.ndarray]:
    with np.load(path) as z:
        return dict(zip((str(s) for s in z["load_names"]), z["loads"].T, strict=True))


def test_plate_auto_applies_each_plate_s_contacts_to_the_foot_over_each(tmp_path, capsys):
    # the whole body on Hamner's run: --plate auto finds what Pipelines/Hamner/External_Loads.xml says
    whole = ["inverse", str(LAB / "hamner_subject02_planar.osim"), "--data", str(LAB / "hamner_running_whole.trc"),
             "--loads", str(LAB / "hamner_running_whole_grf.mot"), "--tasks", str(LAB / "hamner_tasks_ik.xml")]
    code, text, err = _run([*whole, "--plate", "auto", "--out", str(tmp_path / "auto.npz")], capsys)
    assert code == 0, err
    assert "plate 'ground_' -> calcn_r (plates=\"auto\"): contact(s) 0.390-0.665 s, 1.101-end s" in text
    code, _, err = _run([*whole, "--plate", "calcn_r=ground_", "--plate", "calcn_l=1_ground_", "--out",
                         str(tmp_path / "named.npz")], capsys)
    assert code == 0, err
    auto, named = _npz_loads(tmp_path / "auto.npz"), _npz_loads(tmp_path / "named.npz")
    assert auto.keys() == named.keys() and all(np.array_equal(auto[k], named[k]) for k in auto)
    code, _, err = _run([*whole, "--plate", "auto", "--plate", "calcn_r=ground_"], capsys)
    assert code == 2 and err.strip() == "casflex: error: --plate: auto (each contact to the foot over it) takes " \
                                        "every plate: give it alone"


def _scaled_plates(src: Path, factor: float, dest: Path) -> Path:
    """``src`` (.mot) with its forces and torques times ``factor`` (a plate's units mistaken)."""
    lines = src.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader") + 1
    names = lines[k].split()
    scaled = [str(float(v) * factor) if ("force_v" in n or "torque" in n) else v
              for row in lines[k + 1:] for n, v in zip(names, row.split(), strict=True)]
    rows = [scaled[i:i + len(names)] for i in range(0, len(scaled), len(names))]
    dest.write_text("\n".join([*lines[:k + 1], *("\t".join(r) for r in rows)]) + "\n")
    return dest


@pytest.mark.parametrize("factor", [10.0, 1 / 4.448])
def test_plates_in_another_unit_are_said_naming_their_share_of_the_motion_s_needs(factor, tmp_path, capsys):
    # before: daN plates gave the ankle 1951 N m and lbf read as N 42 N m (193 with the plates' N), exit 0 and no
    # word (the moments' check takes the plates' peak for the body's weight); the unscaled trial's share is 0.994
    whole = ["inverse", str(LAB / "hamner_subject02_planar.osim"), "--data", str(LAB / "hamner_running_whole.trc"),
             "--tasks", str(LAB / "hamner_tasks_ik.xml"), "--plate", "auto", "--quiet"]
    code, _, err = _run([*whole, "--loads", str(LAB / "hamner_running_whole_grf.mot")], capsys)
    assert code == 0 and "push" not in err, err
    grf = _scaled_plates(LAB / "hamner_running_whole_grf.mot", factor, tmp_path / "grf.mot")
    code, _, err = _run([*whole, "--loads", str(grf)], capsys)
    said = re.search(r"they push ([0-9.]+) times what the model's motion needs of the ground", err)
    # the motion's needs do not change with the plates' unit: the share scales by the factor exactly; 0.5 %: the
    # printed 3 digits (0.25 %) and the unscaled share's own 3 digits
    assert code == 0 and said and float(said[1]) == pytest.approx(0.994 * factor, rel=5e-3), err


def test_a_c3d_trial_s_plates_are_its_own_without_loads(tmp_path, capsys):
    # before: "--plate: needs --loads" (the same .c3d named again)
    from tests.lab_scenes import C3D, PLANE, walking2_leg

    scene = tmp_path / "leg.toml"
    scene.write_text(walking2_leg())
    base = ["inverse", str(scene), "--data", str(C3D), "--plane", PLANE, "--root", "pelvis", "--plate", "ankle=ground_"]
    for name, extra in (("own", []), ("again", ["--loads", str(C3D)])):
        code, _, err = _run([*base, *extra, "--out", str(tmp_path / f"{name}.npz")], capsys)
        assert code == 0, err
    own, again = _npz_loads(tmp_path / "own.npz"), _npz_loads(tmp_path / "again.npz")
    assert np.array_equal(own["knee.moment"], again["knee.moment"])
