"""casflex.scene.osim, casflex.scene.from_osim: a model file that would give a wrong answer, a traceback or a
runaway run is refused in one line naming the file and the element (``casflex: error: model.osim: ...``, exit 2,
nothing written); what the planar scene leaves out that OpenSim's tools keep (a constraint) is said by
``casflex inverse`` and ``casflex import`` on stderr. Each model is the repo's leg with one fault."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from casflex.cli import main
from casflex.scene import osim
from casflex.scene.from_osim import scene_from_osim
from casflex.scene.osim import read_osim

DATA = Path(__file__).parent / "data" / "lab"
LEG, TRC, GRF = (
    DATA / "hamner_subject02_leg.osim",
    DATA / "hamner_running_stride.trc",
    DATA / "hamner_running_stride_grf.mot",
)
TEXT = LEG.read_text()


def _model(tmp_path: Path, text: str, name: str = "model.osim") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _block(text: str, start: str, end: str) -> tuple[int, int]:
    """(begin, end) of the first element that starts with ``start`` and ends with ``end`` (included)."""
    a = text.index(start)
    return a, text.index(end, a) + len(end)


def _duplicated(start: str, end: str, rename: tuple[str, str] | None = None) -> str:
    """The leg with the element ``start``...``end`` repeated after itself (renamed inside by ``rename``)."""
    a, b = _block(TEXT, start, end)
    copy = TEXT[a:b] if rename is None else TEXT[a:b].replace(*rename)
    return TEXT[:b] + "\n" + copy + TEXT[b:]


def _coordinate(name: str, *changes: str) -> str:
    """The leg with coordinate ``name``'s element changed: ``old, new, old, new ...`` replaced."""
    a, b = _block(TEXT, f'<Coordinate name="{name}">', "</Coordinate>")
    block = TEXT[a:b]
    for old, new in zip(changes[::2], changes[1::2], strict=True):
        assert old in block
        block = block.replace(old, new)
    return TEXT[:a] + block + TEXT[b:]


def _inverse(path: Path, *extra: str) -> list[str]:
    """``casflex inverse`` of the model ``path`` on the stride, the right foot on its plate, quiet."""
    return ["inverse", str(path), "--data", str(TRC), "--loads", str(GRF), "--plate", "calcn_r=ground_", "--quiet",
            *extra]


def _run(argv: list[str], capsys) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_a_second_body_of_the_same_name_is_refused_not_taken_for_the_first(tmp_path, capsys):
    # this file (a second 'femur_r' of 40 kg) replaced the thigh: exit 0, a peak hip moment of 182 N m where the
    # model's is 128 (the hostile tester's: 290)
    heavy = (
        '<Body name="femur_r"><mass>40</mass><mass_center>0 -0.1 0</mass_center><inertia>1 1 1 0 0 0</inertia></Body>\n'
    )
    path = _model(tmp_path, TEXT.replace('<Body name="tibia_r">', heavy + '<Body name="tibia_r">', 1))
    out = tmp_path / "id.sto"
    code, _, err = _run(_inverse(path, "--out", str(out)), capsys)
    assert (
        code == 2
        and err
        == f"casflex: error: {path}: BodySet: two bodies named 'femur_r'; give each its own "
        "name (the second would replace the first)\n"
    )
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["model.osim"]


@pytest.mark.parametrize(
    "text, said",
    [
        (
            _duplicated('<CustomJoint name="ankle_r">', "</CustomJoint>", ("ankle_angle_r", "ankle2")),
            "JointSet: two joints named 'ankle_r'",
        ),
        (
            _duplicated('<Coordinate name="mtp_angle_r">', "</Coordinate>"),
            "coordinates: two coordinates named 'mtp_angle_r'",
        ),
        (_duplicated('<Marker name="R.Heel">', "</Marker>"), "MarkerSet: two markers named 'R.Heel'"),
        (
            TEXT.replace(
                "\t\t<MarkerSet",
                "<ForceSet><objects><CoordinateActuator name='a'/><CoordinateActuator name='a'/>"
                "</objects></ForceSet><MarkerSet",
                1,
            ),
            "ForceSet: two force elements named 'a'",
        ),
        (
            TEXT.replace('<Body name="toes_r">', '<Body name="ground">', 1),
            "BodySet: a body named 'ground', the ground's",
        ),
        (TEXT.replace('<Marker name="R.Heel">', '<Marker name="">', 1), "MarkerSet: a marker without a name"),
    ],
    ids=["joint", "coordinate", "marker", "force", "ground", "unnamed"],
)
def test_every_duplicated_name_is_refused_naming_it(tmp_path, text, said):
    path = _model(tmp_path, text)
    with pytest.raises(ValueError, match=f"^{re.escape(f'{path}: {said}')}"):
        read_osim(path)


@pytest.mark.parametrize("clamped", ["true", "false"])
def test_a_reversed_range_is_refused_naming_the_coordinate(tmp_path, clamped):
    # read before as no clamp at all: the knee's hyperextension limit dropped without a word
    text = _coordinate(
        "knee_angle_r",
        "<range>-2.0943950999999998 0.17453293</range>",
        "<range>0.17453293 -2.0943950999999998</range>",
        "<clamped>true",
        f"<clamped>{clamped}",
    )
    path = _model(tmp_path, text)
    with pytest.raises(
        ValueError,
        match=re.escape(
            f"{path}: joint 'knee_r' coordinate 'knee_angle_r'.range: its upper "
            "end -2.0944 is below its lower end 0.174533"
        ),
    ):
        scene_from_osim(path)


def test_a_clamped_coordinate_without_range_is_refused_an_unclamped_one_is_free(tmp_path, capsys):
    text = _coordinate("knee_angle_r", "<range>-2.0943950999999998 0.17453293</range>", "")
    path = _model(tmp_path, text)
    code, _, err = _run(["import", str(path), "--out", str(tmp_path / "leg.toml")], capsys)
    assert code == 2 and err == (
        f"casflex: error: {path}: joint 'knee_r' coordinate 'knee_angle_r': clamped, but it "
        "has no <range>: give its range (lower upper, rad or m) or set "
        "<clamped>false</clamped>\n"
    )
    free = _model(
        tmp_path,
        _coordinate(
            "knee_angle_r", "<range>-2.0943950999999998 0.17453293</range>", "", "<clamped>true", "<clamped>false"
        ),
        "free.osim",
    )
    knee = {c.name: c for c in scene_from_osim(free).scene.coordinates}["knee_angle_r"]
    assert knee.limits is None


@pytest.mark.parametrize(
    "old, new, said",
    [
        (
            "<y> -0.0032 0.00179",
            "<y> NaN 0.00179",
            "joint 'knee_r' translation1 SimmSpline.y: expected one or more numbers, got 'NaN 0.00179",
        ),
        ("<x> -2.0944 -1.74533", "<x> -2.0944 inf", "joint 'knee_r' translation1 SimmSpline.x: expected one or more"),
        (
            "<mass>3.2505228525130199</mass>",
            "<mass>1e300</mass>",
            "body 'tibia_r'.mass: '1e300' holds a number beyond 1e+09",
        ),
        (
            "<inertia>0.054408400000000003 0.0055056100000000002 0.055164100000000001 0 0 0</inertia>",
            "<inertia>-0.5 0.0055056100000000002 0.055164100000000001 0 0 0</inertia>",
            "body 'tibia_r'.inertia: -0.5 0.00550561 0.0551641 0 0 0 is no body's inertia",
        ),
        (  # read first-wins without a word before
            "<mass>3.2505228525130199</mass>",
            "<mass>3.2505228525130199</mass><mass>32.5</mass>",
            "body 'tibia_r'.mass: given 2 times; give it once",
        ),
    ],
    ids=["spline-nan", "spline-inf", "huge-mass", "negative-inertia", "mass-twice"],
)
def test_a_number_no_model_has_is_refused_naming_the_element(tmp_path, old, new, said):
    assert old in TEXT
    path = _model(tmp_path, TEXT.replace(old, new, 1))
    with pytest.raises(ValueError, match=f"^{re.escape(f'{path}: {said}')}"):
        scene_from_osim(path)


def test_an_axis_of_length_zero_or_of_no_coordinate_of_the_joint_is_refused(tmp_path):
    a, b = _block(TEXT, '<CustomJoint name="knee_r">', "</CustomJoint>")
    knee = TEXT[a:b]
    axis = knee.index("<axis>0 0 1</axis>")
    path = _model(tmp_path, TEXT[:a] + knee[:axis] + "<axis>0 0 0</axis>" + knee[axis + 18 :] + TEXT[b:])
    with pytest.raises(ValueError, match=re.escape(f"{path}: joint 'knee_r' rotation1.axis: 0 0 0 has no direction")):
        scene_from_osim(path)
    other = _model(
        tmp_path,
        TEXT[:a]
        + knee.replace("<coordinates>knee_angle_r</coordinates>", "<coordinates>hip_flexion_r</coordinates>", 1)
        + TEXT[b:],
        "o.osim",
    )
    with pytest.raises(
        ValueError,
        match=re.escape(
            f"{other}: joint 'knee_r' rotation1.coordinates: 'hip_flexion_r' is "
            "no coordinate of the joint (its coordinates: ['knee_angle_r'])"
        ),
    ):
        scene_from_osim(other)


def test_a_model_whose_bodies_are_all_massless_is_refused(tmp_path, capsys):
    path = _model(tmp_path, re.sub(r"<mass>[^<]*</mass>", "<mass>0</mass>", TEXT))
    code, _, err = _run(["inverse", str(path), "--data", str(TRC), "--quiet"], capsys)
    assert code == 2 and err == (
        f"casflex: error: {path}: BodySet: no body of the tree has a mass > 0 (6 bodies); a "
        "scene of massless nodes has no dynamics: give the bodies their masses\n"
    )


def test_a_jointed_scene_without_masses_assembles():
    # its mass matrix has no nonzeros: the assembly's gathers had no list to start from (IndexError)
    from casflex.model import assemble
    from casflex.scene import Joint, Node, Scene, Support

    scene = Scene(
        "bare",
        (Node("a", 0, 0, 0), Node("b", 1, 0, 0)),
        joints=(Joint("h", "hinge", ("a", "b")),),
        supports=(Support("fix", "a"),),
    )
    model = assemble(scene)
    M = np.array(model.mass(model.q0, np.zeros(0))).reshape(6, 6)  # no parameters
    assert not M.any()


def test_a_model_of_more_bodies_than_a_body_has_is_refused_before_it_is_read(tmp_path):
    # the hostile tester's 1000-body model ran a 4 GB process out of memory after a minute
    n = osim.MAX_BODIES + 1
    bodies = "".join(f'<Body name="b{i}"><mass>1</mass></Body>' for i in range(n))
    path = _model(
        tmp_path,
        f'<OpenSimDocument Version="40000"><Model name="big"><BodySet><objects>{bodies}</objects>'
        "</BodySet></Model></OpenSimDocument>",
    )
    with pytest.raises(
        ValueError, match=re.escape(f"{path}: BodySet: {n} bodies; casflex reads models of up to {osim.MAX_BODIES}")
    ):
        read_osim(path)


# -- constraints ---------------------------------------------------------------------------------------------------
def _constrained(tmp_path: Path, xml: str, name: str = "model.osim") -> Path:
    return _model(
        tmp_path,
        TEXT.replace(
            "\t\t<MarkerSet",
            f'<ConstraintSet name="constraintset"><objects>{xml}</objects></ConstraintSet>\n\t\t<MarkerSet',
            1,
        ),
        name,
    )


def _coupler(dependent: str, independent: str, enforced: str = "true") -> str:
    return (
        f'<CoordinateCouplerConstraint name="cc"><isEnforced>{enforced}</isEnforced><coupled_coordinates_function>'
        "<LinearFunction><coefficients>1 0</coefficients></LinearFunction></coupled_coordinates_function>"
        f"<independent_coordinate_names>{independent}</independent_coordinate_names>"
        f"<dependent_coordinate_name>{dependent}</dependent_coordinate_name></CoordinateCouplerConstraint>"
    )


def _weld(a: str, b: str) -> str:
    return (
        f'<WeldConstraint name="w"><isEnforced>true</isEnforced><socket_frame1>{a}</socket_frame1>'
        f"<socket_frame2>{b}</socket_frame2></WeldConstraint>"
    )


def test_a_constraint_the_planar_scene_would_break_is_refused(tmp_path):
    path = _constrained(tmp_path, _coupler("knee_angle_r", "hip_flexion_r"))
    with pytest.raises(
        ValueError,
        match=re.escape(
            f"{path}: ConstraintSet: CoordinateCouplerConstraint 'cc' makes "
            "'knee_angle_r' follow ['hip_flexion_r'], and the planar scene moves "
            "'knee_angle_r' on its own"
        ),
    ):
        scene_from_osim(path)
    loop = _constrained(tmp_path, _weld("/bodyset/tibia_r", "/ground"), "loop.osim")
    with pytest.raises(
        ValueError,
        match=re.escape(
            f"{loop}: ConstraintSet: WeldConstraint 'w' closes a loop between "
            "'tibia_r' and 'ground', which the planar scene moves relative to "
            "each other (joints ['ground_pelvis', 'hip_r', 'knee_r'])"
        ),
    ):
        scene_from_osim(loop)
    unknown = _constrained(tmp_path, _coupler("patella_angle", "knee_angle_r"), "unknown.osim")
    with pytest.raises(ValueError, match="CoordinateCouplerConstraint 'cc': 'patella_angle' is no coordinate of the"):
        scene_from_osim(unknown)
    nowhere = _constrained(tmp_path, _weld("/bodyset/tibia_r", "/bodyset/patella_r"), "nowhere.osim")
    with pytest.raises(ValueError, match="its sockets name no two bodies of the model"):
        scene_from_osim(nowhere)


def test_a_constraint_the_scene_leaves_out_is_said_by_inverse_and_import(tmp_path, capsys):
    # before: `casflex inverse` on the model said nothing of it (only import's report listed it as ignored)
    path = _constrained(
        tmp_path, _coupler("subtalar_angle_r", "ankle_angle_r") + _weld("/bodyset/calcn_r", "/bodyset/toes_r")
    )
    said = [
        f"{path}: constraint CoordinateCouplerConstraint 'cc' ignored: 'subtalar_angle_r' is locked in the model, "
        "where OpenSim's tools move it with ['ankle_angle_r']",
        f"{path}: constraint WeldConstraint 'w' ignored: the planar scene holds 'calcn_r' and 'toes_r' fixed "
        "relative to each other already",
    ]
    assert list(scene_from_osim(path).warnings) == said
    code, _, err = _run(_inverse(path, "--t-end", "0.6", "--out", str(tmp_path / "id.sto")), capsys)
    assert code == 0 and [f"casflex: warning: {s}" for s in said] == [
        ln for ln in err.splitlines() if "constraint" in ln
    ]
    code, out, err = _run(["import", str(path), "--out", str(tmp_path / "leg.toml")], capsys)
    assert code == 0 and err.splitlines() == [f"casflex: warning: {s}" for s in said] and said[0] in out
    off = _constrained(tmp_path, _coupler("knee_angle_r", "hip_flexion_r", enforced="false"), "off.osim")
    made = scene_from_osim(off)
    assert (
        not made.warnings
        and "constraint CoordinateCouplerConstraint 'cc': not enforced in the model; ignored" in made.report
    )


# -- what the marker fit cannot decide -----------------------------------------------------------------------------
def test_a_hinge_no_marker_moves_with_is_refused_before_the_fit(tmp_path):
    # a segment without markers beyond the toes: before, the fit decided no frame and ended in an IndexError
    from casflex.inverse import Trial, prepare

    extra = (
        '<PinJoint name="tip"><socket_parent_frame>p</socket_parent_frame><socket_child_frame>c'
        "</socket_child_frame><coordinates><Coordinate name='tip_angle'><range>-1 1</range></Coordinate>"
        "</coordinates><frames><PhysicalOffsetFrame name='p'><socket_parent>/bodyset/toes_r</socket_parent>"
        "<translation>0.05 0 0</translation><orientation>0 0 0</orientation></PhysicalOffsetFrame>"
        "<PhysicalOffsetFrame name='c'><socket_parent>/bodyset/tip</socket_parent><translation>0 0 0"
        "</translation><orientation>0 0 0</orientation></PhysicalOffsetFrame></frames></PinJoint>"
    )
    text = TEXT.replace('<Body name="toes_r">', '<Body name="tip"><mass>0.1</mass></Body><Body name="toes_r">', 1)
    a = text.index("</objects>", text.index("<JointSet"))
    path = _model(tmp_path, text[:a] + extra + text[a:])
    with pytest.raises(
        ValueError,
        match=re.escape(
            f"{TRC}: the markers do not decide ['tip_angle'] in any frame: segment 'tip' has no marker to place it"
        ),
    ):
        prepare(path, Trial(TRC, grf=GRF, plates={"calcn_r": "ground_"}))


def test_a_trial_whose_markers_decide_no_frame_is_refused_in_one_line():
    from casflex.inverse.fit import _fill

    t = np.linspace(0, 1, 11)
    with pytest.raises(ValueError, match="the markers do not decide the coordinates in any frame"):
        _fill(t, np.full((11, 3), np.nan), 0.1, [])


def test_a_joint_whose_child_is_the_ground_is_refused(tmp_path):
    # it closed a loop from the toes to the ground, read before as a massless node welded to the toes (exit 0)
    fix = (
        '<WeldJoint name="fix"><socket_parent_frame>p</socket_parent_frame><socket_child_frame>c</socket_child_frame>'
        "<frames><PhysicalOffsetFrame name='p'><socket_parent>/bodyset/toes_r</socket_parent>{0}</PhysicalOffsetFrame>"
        "<PhysicalOffsetFrame name='c'><socket_parent>/ground</socket_parent>{0}</PhysicalOffsetFrame></frames>"
        "</WeldJoint>"
    ).format("<translation>0 0 0</translation><orientation>0 0 0</orientation>")
    a = TEXT.index("</objects>", TEXT.index("<JointSet"))
    path = _model(tmp_path, TEXT[:a] + fix + TEXT[a:])
    with pytest.raises(ValueError, match=re.escape(f"{path}: joint 'fix': its child frame is on the ground")):
        scene_from_osim(path)


def test_a_spatial_transform_s_axes_are_taken_by_their_names(tmp_path):
    # a duplicated TransformAxis was applied twice (a constant offset doubled, exit 0), and the file's order of the
    # axes taken as the rotations' order where OpenSim's is rotation1, 2, 3 whatever the file's
    a, b = _block(TEXT, '<CustomJoint name="knee_r">', "</CustomJoint>")
    knee = TEXT[a:b]
    t2 = _block(knee, '<TransformAxis name="translation2">', "</TransformAxis>")
    twice = _model(tmp_path, TEXT[:a] + knee[: t2[1]] + knee[t2[0] : t2[1]] + knee[t2[1] :] + TEXT[b:], "twice.osim")
    with pytest.raises(
        ValueError, match=re.escape(f"{twice}: joint 'knee_r' SpatialTransform: two TransformAxis elem")
    ):
        scene_from_osim(twice)
    odd = _model(tmp_path, TEXT[:a] + knee.replace('"rotation1"', '"rotation4"') + TEXT[b:], "odd.osim")
    with pytest.raises(ValueError, match="a TransformAxis named 'rotation4'; OpenSim's are rotation1, rotation2"):
        scene_from_osim(odd)
    # the hip adducted 0.3 rad by default: its flexion axis is then tilted only where adduction comes second
    text = _coordinate("hip_adduction_r", "<default_value>0</default_value>", "<default_value>0.3</default_value>")
    a, b = _block(text, '<CustomJoint name="hip_r">', "</CustomJoint>")
    hip = text[a:b]
    r1, r2 = (_block(hip, f'<TransformAxis name="rotation{k}">', "</TransformAxis>") for k in (1, 2))
    swapped = hip[: r1[0]] + hip[r2[0] : r2[1]] + hip[r1[1] : r2[0]] + hip[r1[0] : r1[1]] + hip[r2[1] :]
    as_is, moved = _model(tmp_path, text, "hip.osim"), _model(tmp_path, text[:a] + swapped + text[b:], "moved.osim")
    made, want = scene_from_osim(moved), scene_from_osim(as_is)
    assert made.scene == want.scene and [ln.replace(str(moved), "") for ln in made.report] == [
        ln.replace(str(as_is), "") for ln in want.report
    ]


def test_a_frame_s_orientation_or_translation_left_out_is_opensim_s_default(tmp_path):
    # OpenSim reads a PhysicalOffsetFrame without <orientation> (or <translation>) as 0 0 0; it was refused
    from casflex.scene import dumps_scene

    bare = re.sub(r"\s*<orientation>0 0 0</orientation>", "", TEXT)
    assert bare.count("<orientation>") < TEXT.count("<orientation>")
    assert dumps_scene(scene_from_osim(_model(tmp_path, bare)).scene) == dumps_scene(scene_from_osim(LEG).scene)


def test_an_element_named_as_opensim_names_a_base_class_s_property_is_read(tmp_path, capsys):
    # <HuntCrossleyForce::ContactParametersSet> (OpenSim writes it so: its ToyLanding, WalkerModel, SoccerKick, Jumper
    # and BouncingBlock models) is no XML name: such a model OpenSim loads was refused as "not an OpenSim model (XML:
    # not well-formed (invalid token))", whatever else it held; now read, the force listed as ignored
    force = ('<ForceSet name="forceset"><objects><HuntCrossleyForce name="contact">'
             '<HuntCrossleyForce::ContactParametersSet name="contact_parameters"><objects>'
             '<HuntCrossleyForce::ContactParameters><geometry>a b</geometry><stiffness>1e8</stiffness>'
             '</HuntCrossleyForce::ContactParameters></objects></HuntCrossleyForce::ContactParametersSet>'
             '</HuntCrossleyForce></objects></ForceSet>\n')
    at = TEXT.index("<MarkerSet")
    path = _model(tmp_path, TEXT[:at] + force + TEXT[at:])
    made = scene_from_osim(path)
    assert [m.label for m in made.scene.markers] == [m.label for m in scene_from_osim(LEG).scene.markers]
    assert "ignored: 1 ForceSet HuntCrossleyForce" in made.report
    broken = _model(tmp_path, TEXT[:at] + force.replace("</ForceSet>", "") + TEXT[at:], "broken.osim")
    code, _, err = _run(["import", str(broken), "--out", str(tmp_path / "x.toml")], capsys)
    assert code == 2 and "broken.osim: not an OpenSim model (XML: mismatched tag" in err  # the file's own fault


def test_a_marker_on_a_body_the_model_lacks_is_refused_naming_it(tmp_path, capsys):
    # R.ASIS on /bodyset/humerus_r in a model of the leg: OpenSim refuses the model (its socket finds no frame);
    # casflex inverse and calibrate left the marker out of the fit without a word, exit 0 (import alone said it)
    text = TEXT.replace("<socket_parent_frame>/bodyset/pelvis</socket_parent_frame>",
                        "<socket_parent_frame>/bodyset/humerus_r</socket_parent_frame>", 1)
    path = _model(tmp_path, text)
    code, _, err = _run([*_inverse(path), "--out", str(tmp_path / "x.csv")], capsys)
    assert code == 2 and err.strip().endswith("MarkerSet: marker 'R.ASIS' is on '/bodyset/humerus_r', a body the "
                                              "model does not have: fix its socket_parent_frame (OpenSim refuses "
                                              "such a model)")
    assert not (tmp_path / "x.csv").exists()
    ground = _model(tmp_path, TEXT.replace("<socket_parent_frame>/bodyset/pelvis</socket_parent_frame>",
                                           "<socket_parent_frame>/ground</socket_parent_frame>", 1), "ground.osim")
    # on the ground: it moves with no coordinate, a fit gains nothing from it (it was said to be 'massless')
    assert "marker 'R.ASIS': on 'ground', the ground: it moves with no coordinate; left out" in scene_from_osim(
        ground).report
