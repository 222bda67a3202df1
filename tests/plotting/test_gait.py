"""A study's figures as gait reports show them (issue 48, item 8): joint names as titles, angles and moments, left
and right overlaid with their bands (mean +- 1 SD) and toe-offs, the clinical signs, a normative band from a file.
The data: one trial run of Hamner's subject 02 running (tests/data/lab: one right stride on its plate), as the study
runs it (:func:`casflex.study.runner.trial_run`)."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from casflex.cli import main
from casflex.plotting.gait import gait_figure, joint_title, read_normative, sign_factor, split_side

from .helpers import assert_png

LAB = Path(__file__).resolve().parents[1] / "data" / "lab"
PERCENT = np.linspace(0.0, 100.0, 101)


@pytest.fixture(scope="module")
def record():
    from casflex import load_scene
    from casflex.scene import dumps_scene
    from casflex.study.records import Calibration, TrialRecord
    from casflex.study.runner import trial_run
    from casflex.study.study_file import Trial, TrialOptions

    scene = dumps_scene(load_scene(str(LAB / "hamner_subject02_planar.osim")))
    rec = trial_run(scene=scene, trial=Trial("run", str(LAB / "hamner_running_whole.trc"),
                                             str(LAB / "hamner_running_whole_grf.mot")),
                    options=TrialOptions(tasks=str(LAB / "hamner_tasks_ik.xml")), uncertain=())
    return {"subjects": {"s02": Calibration(scene)}, "trials": {("s02", "run"): TrialRecord.from_json(rec)}}


@pytest.mark.parametrize("name, key, side, title", [
    ("hip_flexion_r_moment", "hip_flexion_moment", "right", "Hip flexion/extension"),
    ("knee_angle_l", "knee_angle", "left", "Knee flexion/extension"),
    ("knee_l.moment", "knee.moment", "left", "Knee"),
    ("r_ankle.angle", "ankle.angle", "right", "Ankle"),
    ("ankle.moment", "ankle.moment", None, "Ankle"),
    ("lumbar_extension_moment", "lumbar_extension_moment", None, "Lumbar flexion/extension"),
])
def test_a_curve_s_side_and_its_joint_s_title(name, key, side, title):
    assert split_side(name) == (key, side) and joint_title(key) == title


def test_the_record_holds_each_joint_s_angle_over_its_moment_s_cycles_and_the_toe_off(record):
    rec = record["trials"][("s02", "run")]
    knee, moment = rec.angles["knee_angle_r"], rec.loads["knee_angle_r_moment"]
    assert (knee.foot, knee.cycles, knee.clean) == (moment.foot, moment.cycles, moment.clean) == (
        "calcn_r", moment.cycles, (True,))
    v = np.array(knee.value[0])
    # OpenSim's knee_angle_r, degrees: extension +, a running knee flexed 17 to 106 degrees over the stride
    assert -110 < v.min() < -95 and -20 < v.max() < -10
    toe_off, = rec.toe_off["calcn_r"]
    assert 33 < toe_off < 43  # running: stance some 35-40 % of the stride (the plate's foot off at 20 N)
    assert rec.toe_off["calcn_l"] == () and rec.angles["knee_angle_l"].value == ()  # the left has no cycle here


def test_the_clinical_signs_make_stance_s_extensor_and_plantarflexor_moments_positive(record):
    rec = record["trials"][("s02", "run")]
    for name, stance in (("hip_flexion_r_moment", slice(0, 15)), ("knee_angle_r_moment", slice(10, 30)),
                         ("ankle_angle_r_moment", slice(15, 35)), ("knee_angle_r", slice(0, 101))):
        factor, positive = sign_factor(name, clinical=True)
        v = factor * np.array(rec.loads.get(name, rec.angles.get(name)).value[0])[stance]
        # early stance's hip extensor, mid-stance's knee extensor and push-off's plantarflexor moments (N m), the
        # knee's flexion (deg): positive, as gait reports draw them
        assert v[np.argmax(np.abs(v))] > 50, (name, positive)
    assert sign_factor("knee_angle_r_moment", clinical=False) == (1.0, "the model's sign")
    assert sign_factor("lumbar_extension_moment", clinical=True) == (1.0, "the model's sign")
    assert sign_factor("hip_flexion_r_moment", clinical=True, coordinate_sign=-1.0) == (1.0, "extensor")


def _norms(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "norms.csv"
    path.write_text(text)
    return path


def test_the_figure_overlays_the_sides_bands_toe_offs_and_the_normative_band(record, tmp_path):
    rec = record["trials"][("s02", "run")]
    right = {n: np.array(rec.loads.get(n, rec.angles.get(n)).value) for n in
             ("hip_flexion_r", "hip_flexion_r_moment", "knee_angle_r", "knee_angle_r_moment")}
    curves = right | {n.replace("_r", "_l"): np.vstack([c, c + 5.0]) for n, c in right.items()}  # a left, 2 cycles
    toe_off = {n: [38.7] if "_r" in n else [60.0, 62.0] for n in curves}
    norms = read_normative(_norms(tmp_path, "# made up\nload,percent,mean,sd,unit\nhip_flexion_moment,0,10,5,N m\n"
                                            "hip_flexion_moment,100,20,5,N m\n"), {"angle": "deg", "moment": "N m"})
    fig = gait_figure(PERCENT, curves, toe_off, "s02", tmp_path / "s02.png",
                      units={n: "N m" if n.endswith("moment") else "deg" for n in curves}, clinical=True,
                      normative=norms)
    assert_png(tmp_path / "s02.png")
    axes = {ax.get_title(): ax for ax in fig.axes if ax.get_visible()}
    assert sorted(axes) == ["Hip flexion/extension angle", "Hip flexion/extension moment",
                            "Knee flexion/extension angle", "Knee flexion/extension moment"]
    hip = axes["Hip flexion/extension moment"]
    assert [t.get_text() for t in fig.legends[0].get_texts()] == [
        "Left: mean +- 1 SD (2 cycles)", "Left toe-off (61 %)", "Right: mean +- 1 SD (1 cycle)",
        "Right toe-off (39 %)", "normative mean +- 1 SD"]  # one legend for the figure, the panels' labels once
    assert hip.get_ylabel() == "N m (extensor +)" and axes["Knee flexion/extension angle"].get_ylabel() == \
        "deg (flexion +)"
    lines = {ln.get_label(): ln for ln in hip.get_lines()}
    # the right's mean line, drawn in the clinical sign: OpenSim's hip moment turned
    assert np.allclose(lines["Right: mean +- 1 SD (1 cycle)"].get_ydata(), -right["hip_flexion_r_moment"][0])
    assert lines["Right toe-off (39 %)"].get_xdata()[0] == pytest.approx(38.7)
    knee = axes["Knee flexion/extension moment"].get_legend_handles_labels()[1]
    assert "normative mean +- 1 SD" not in knee and "normative mean +- 1 SD" in hip.get_legend_handles_labels()[1]


@pytest.mark.parametrize("text, said", [
    ("load,percent,mean\nknee_angle,0,1\n", "line 1: the header has no column sd, unit"),
    ("load,percent,mean,sd,unit\nknee_angle,0,1,2,deg\nknee_angle,120,1,2,deg\n",
     "line 3: percent: must lie in 0..100"),
    ("load,percent,mean,sd,unit\nknee_angle,0,1,-2,deg\n", "line 2: sd: must be >= 0"),
    ("load,percent,mean,sd,unit\nknee_angle,0,one,2,deg\n", "line 2: mean: expected a number, got 'one'"),
    ("load,percent,mean,sd,unit\nknee_angle_moment,0,1,2,N m\n",
     "line 2: unit: the figures draw 'knee_angle_moment' (a moment) in N m/kg, the file says 'N m'"),
    ("load,percent,mean,sd,unit\nknee_angle_r,0,1,2,deg\n", "line 2: load: 'knee_angle_r' names a side"),
    ("load,percent,mean,sd,unit\nknee_angle,50,1,2,deg\nknee_angle,40,1,2,deg\n",
     "line 3: percent: 'knee_angle' needs two or more points with increasing percents"),
])
def test_a_bad_normative_file_is_refused_naming_the_line_and_field(text, said, tmp_path):
    path = _norms(tmp_path, text)
    with pytest.raises(ValueError) as err:
        read_normative(path, {"angle": "deg", "moment": "N m/kg"})
    assert str(err.value).startswith(f"{path}: ") and said in str(err.value), str(err.value)


def test_study_refuses_a_bad_normative_file_in_one_line_before_any_work(tmp_path, capsys):
    for f in ("hamner_subject02_planar.osim", "hamner_running_whole.trc", "hamner_running_whole_grf.mot"):
        shutil.copy(LAB / f, tmp_path / f)
    study = tmp_path / "study.toml"
    study.write_text('name = "s"\n[options]\nplane = "X,Y"\nnormalise = "mass"\n\n[[subjects]]\nname = "s02"\n'
                     'model = "hamner_subject02_planar.osim"\nmass = 80.0\n\n[[subjects.trials]]\nname = "run"\n'
                     'markers = "hamner_running_whole.trc"\ngrf = "hamner_running_whole_grf.mot"\n')
    norms = _norms(tmp_path, "load,percent,mean,sd,unit\nknee_angle_moment,0,1,2,N m\nknee_angle_moment,100,1,2,N m\n")
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(["study", str(study), "--out", str(tmp_path / "res"), "--normative", str(norms)]) == 2
    err = capsys.readouterr().err
    assert err == (f"casflex: error: --normative: {norms}: line 2: unit: the figures draw 'knee_angle_moment' (a "
                   "moment) in N m/kg, the file says 'N m'; give the band in N m/kg\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_the_study_s_figures_and_a_normative_band_no_curve_takes(record, tmp_path):
    from casflex.cli.study import _draw_figures, _figure_plans

    norms = read_normative(_norms(tmp_path, "load,percent,mean,sd,unit\nknee_angle,0,1,2,deg\nknee_angle,100,1,2,deg\n"
                                            "hip_rotation,0,1,2,deg\nhip_rotation,100,1,2,deg\n"))
    plans, notes = _figure_plans(record, "running", False, False, True, norms)
    _draw_figures(plans, tmp_path, {})
    written = list(plans)
    assert written == ["s02.png", "group.png"]
    for name in written:
        assert_png(tmp_path / name)
    assert len(notes) == 1 and notes[0].startswith("--normative: no curve 'hip_rotation' in the figures (theirs: ")
    from casflex.cli.study import _kept

    kept = _kept(record, False, "angles")  # an arm, cut on the right foot's cycles: no toe-off of its own side
    assert [o for _, o in kept["knee_angle_r"]["s02"]] == [pytest.approx(38.69, abs=0.01)]
    assert [o for _, o in kept["arm_flex_l"]["s02"]] == [None] == [o for _, o in kept["lumbar_extension"]["s02"]]


def _other(plan: dict, rows: int, shift: float, title: str) -> dict:
    """``plan`` with other curves (``rows`` cycles each, scaled and shifted), toe-offs and title: the same panels."""
    rng = np.random.default_rng(rows)
    curves = {n: np.vstack([2.0 * c[0] + shift + rng.normal(0.0, 3.0, c.shape[1]) for _ in range(rows)])
              for n, c in plan["curves"].items()}
    return plan | {"curves": curves, "title": title,
                   "toe_off": {n: [None if v is None else v + shift / 10 for v in vs] * rows
                               for n, vs in plan["toe_off"].items()}}


def test_a_figure_drawn_over_the_previous_one_is_the_same_png_as_drawn_anew(record):
    # GaitFigures draws a subject's figure over the previous one of the same panels (its axes, ticks and texts
    # kept): the bytes of a new figure's, whatever was drawn before; another shape is drawn anew
    from casflex.cli.study import _figure_plans
    from casflex.plotting._figure import render
    from casflex.plotting.gait import _REUSABLE, GaitFigures

    plan = _figure_plans(record, "run")[0]["s02.png"]
    second, third = _other(plan, 3, 40.0, "run: s03"), _other(plan, 7, -25.0, "run: s04")
    fewer = plan | {"curves": {n: c for n, c in plan["curves"].items() if "knee" not in n}}
    figures = GaitFigures()
    pngs, drawn_on = [], []
    for p in (plan, second, third, fewer, plan):
        pngs.append(figures.png(**p))
        drawn_on.append(figures._last.fig)
    fresh = [render(gait_figure(path=None, **p)) for p in (plan, second, third, fewer, plan)]
    assert pngs == fresh
    assert len(set(pngs)) == 4  # each figure its own (the first and last the same plan)
    same = [a is b for a, b in zip(drawn_on, drawn_on[1:], strict=False)]
    # the second and third subjects drawn over the first's figure; without the knee another figure, and another
    # again with it (one figure kept: the last)
    assert same == ([True, True, False, False] if _REUSABLE else [False] * 4)
    assert len(drawn_on[3].axes) == 10


def test_the_gait_cycle_s_numbers_are_under_each_column_s_lowest_panel(record, tmp_path):
    rec = record["trials"][("s02", "run")]
    curves = {n: np.array(rec.loads.get(n, rec.angles.get(n)).value) for n in
              ("hip_flexion_r", "hip_flexion_r_moment", "knee_angle_r", "ankle_angle_r", "ankle_angle_r_moment")}
    fig = gait_figure(PERCENT, curves, {}, "s02", None, units={n: "N m" if "moment" in n else "deg" for n in curves})
    fig.canvas.draw()
    shown = {ax.get_title(): [t.get_text() for t in ax.get_xticklabels() if t.get_visible() and t.get_text()]
             for ax in fig.axes if ax.get_visible()}
    numbers = ["0", "20", "40", "60", "80", "100"]
    assert shown == {"Hip flexion/extension angle": [], "Hip flexion/extension moment": [],
                     "Knee flexion/extension angle": [], "Ankle dorsi/plantarflexion angle": numbers,
                     "Ankle dorsi/plantarflexion moment": numbers}
    # the knee has no moment here: the hip's moment's panel is its column's lowest but one
    assert {ax.get_title(): ax.get_xlabel() for ax in fig.axes if ax.get_visible() and ax.get_xlabel()} == {
        "Ankle dorsi/plantarflexion angle": "gait cycle (%)", "Ankle dorsi/plantarflexion moment": "gait cycle (%)"}


def test_the_gait_figure_s_axes_draw_matplotlib_s_pixels(record, monkeypatch):
    # casflex's axes (their ticks found once a draw, grid lines and marks drawn as one line each): the PNG of
    # matplotlib's own axes, for a figure drawn anew and one drawn over another
    from matplotlib.axes import Axes

    from casflex.cli.study import _figure_plans
    from casflex.plotting import _axes
    from casflex.plotting._figure import render
    from casflex.plotting.gait import GaitFigures

    plan = _figure_plans(record, "run", clinical=True)[0]["s02.png"]
    plans = [plan, _other(plan, 3, 40.0, "run: s03")]
    ours = [GaitFigures().png(**plans[0]), GaitFigures().png(**plans[1])]
    figures = GaitFigures()
    ours += [figures.png(**p) for p in plans]
    monkeypatch.setattr(_axes, "Axes", Axes)
    theirs = [render(gait_figure(path=None, **p)) for p in plans]
    assert type(figures._last.fig.axes[0]) is not Axes  # the figure drawn over was casflex's
    assert ours == theirs + theirs


def test_each_thread_draws_over_its_own_figures():
    # a study draws its figures in its command's thread and a dask worker's threads: one GaitFigures each
    import threading

    from casflex.plotting.gait import GaitFigures

    mine = GaitFigures.of_thread()
    other = []
    worker = threading.Thread(target=lambda: other.extend([GaitFigures.of_thread(), GaitFigures.of_thread()]))
    worker.start()
    worker.join()
    assert GaitFigures.of_thread() is mine and other[0] is other[1] and other[0] is not mine


def test_each_subject_s_scene_is_read_once_for_the_clinical_signs(record, monkeypatch):
    # each subject's figure plan asks for every subject's coordinates' signs (30 ms a whole-body scene's reading):
    # read once a scene in the process, the same plan after
    from casflex.cli import study
    from casflex.scene import io

    study._scene_signs.cache_clear()
    read = []
    monkeypatch.setattr(io, "loads_scene", lambda text, f=io.loads_scene: read.append(1) or f(text))
    plans = [study._figure_plans(record, "run", clinical=True)[0]["s02.png"] for _ in range(3)]
    assert len(read) == 1 and plans[0]["coordinate_signs"] and plans[2]["coordinate_signs"] == \
        plans[0]["coordinate_signs"]


if __name__ == "__main__":  # pragma: no cover
    sys.exit(pytest.main([__file__]))


def test_the_study_s_figure_is_the_same_pixels_as_matplotlib_s_own_placement_and_png(record):
    # draw_figure gives each panel's title its height and encodes the PNG itself (casflex.plotting._png, cheaper):
    # the pixels must be those of matplotlib placing the titles itself (measuring the tick labels) through Pillow
    import io

    from PIL import Image

    from casflex.cli.study import _figure_plans, draw_figure
    from casflex.plotting._figure import DPI

    plan = _figure_plans(record, "run")[0]["s02.png"]
    png = draw_figure(plan)
    fig = gait_figure(path=None, **plan)
    for ax in fig.axes:
        ax._autotitlepos = True  # matplotlib's own placement, as a title set without its height has it
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, pil_kwargs={"compress_level": 6})  # Pillow's options: Pillow's PNG
    mine, theirs = (np.asarray(Image.open(io.BytesIO(b)).convert("RGBA")) for b in (png, buf.getvalue()))
    assert png != buf.getvalue()  # another encoding ...
    assert mine.shape == theirs.shape and (mine == theirs).all()  # ... of the same pixels
