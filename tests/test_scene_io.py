"""Reading and writing scenes as TOML: the built-in twobar scene, round trips, and malformed files.

Every malformed scene must be rejected with one SceneError whose message names the offending
field by its path (``springs[0] (spring1).k``), never with a bare TypeError/KeyError.
"""

from __future__ import annotations

import math
from dataclasses import fields, replace
from pathlib import Path

import pytest

import casflex
from casflex.scene import Beam, Load, Parameter, Scene, SceneError, Spring, Support, TorsionSpring
from casflex.scene.io import builtin_scenes, dumps_scene, load_scene, loads_scene, save_scene, scene_from_dict

TWOBAR_PATH = Path(casflex.__file__).parent / "scene" / "builtin" / "twobar.toml"
TWOBAR = TWOBAR_PATH.read_text(encoding="utf-8")


def edit(old: str, new: str, nth: int = 1) -> str:
    """The twobar text with the ``nth`` occurrence of ``old`` replaced by ``new``."""
    start = -1
    for _ in range(nth):
        start = TWOBAR.find(old, start + 1)
        assert start >= 0, f"{old!r} occurs fewer than {nth} times in twobar.toml"
    return TWOBAR[:start] + new + TWOBAR[start + len(old):]


def append(extra: str) -> str:
    """The twobar text with ``extra`` TOML appended."""
    return TWOBAR.rstrip("\n") + "\n\n" + extra.strip("\n") + "\n"


LOAD5 = '[[loads]]\nname = "push"\nnode = "5"\n'
MINI = 'name = "mini"\n\n[[nodes]]\nname = "a"\nx = 0.0\ny = 0.0\n'

# (id, TOML text, regex pinning the field path and the reason)
MALFORMED = [
    # -- missing required fields -------------------------------------------------------------
    ("node-x-missing", edit("x = 0.05\n", ""), r"nodes\[1\] \(2\): missing required field 'x'"),
    ("node-name-missing", edit('name = "3"\n', ""), r"nodes\[2\]: missing required field 'name'"),
    ("beam-E-missing", edit("E = 2.1e11\n", ""), r"beams\[0\] \(bar2\): missing required field 'E'"),
    ("spring-k-missing", edit("k = 400.0\n", ""), r"springs\[1\] \(spring3\): missing required field 'k'"),
    ("scene-name-missing", edit('name = "twobar"\n', ""), r"name: missing required top-level field 'name'"),
    ("nodes-missing", 'name = "empty"\ngravity = [0.0, -9.81]\n', r"nodes: missing required field 'nodes'"),
    ("nodes-empty", 'name = "empty"\nnodes = []\n', r"nodes: a scene needs at least one node"),
    ("parameter-target-missing", edit('target = "spring1.k"\n', ""),
     r"parameters\[0\] \(k1\): missing required field 'target'"),
    # -- geometry -------------------------------------------------------------------------------
    ("beam-zero-length", edit("x = 0.5\ny = -0.8660254037844387", "x = 0.05\ny = -0.08660254037844387"),
     r"beams\[0\] \(bar2\)\.nodes: zero length, nodes '2' and '3' coincide"),
    ("beam-same-node-twice", edit('nodes = ["2", "3"]', 'nodes = ["2", "2"]'),
     r"beams\[0\] \(bar2\)\.nodes: the two nodes must differ"),
    ("beam-one-node", edit('nodes = ["2", "3"]', 'nodes = ["2"]'),
     r"beams\[0\] \(bar2\)\.nodes: expected a list of two node names"),
    ("spring-coincident-nodes", edit("x = 0.05\ny = -0.08660254037844387", "x = 0.0\ny = 0.0"),
     r"springs\[0\] \(spring1\)\.nodes: nodes '1' and '2' coincide"),
    # -- signs of stiffnesses and material data --------------------------------------------------
    ("k-negative", edit("k = 700.0", "k = -5"), r"springs\[0\] \(spring1\)\.k: must be > 0, got -5"),
    ("k-zero", edit("k = 400.0", "k = 0.0"), r"springs\[1\] \(spring3\)\.k: must be > 0, got 0"),
    ("kt-negative", edit("kt = 0.5", "kt = -0.5"), r"torsion_springs\[0\] \(torsion1\)\.kt: must be > 0, got -0.5"),
    ("kt-zero", edit("kt = 0.5", "kt = 0", nth=2), r"torsion_springs\[1\] \(torsion3\)\.kt: must be > 0, got 0"),
    ("E-zero", edit("E = 2.1e11", "E = 0.0"), r"beams\[0\] \(bar2\)\.E: must be > 0, got 0"),
    ("E-negative", edit("E = 2.1e11", "E = -2.1e11", nth=2), r"beams\[1\] \(bar4\)\.E: must be > 0, got -2\.1e\+11"),
    ("A-zero", edit("A = 25e-4", "A = 0.0"), r"beams\[0\] \(bar2\)\.A: must be > 0, got 0"),
    ("A-negative", edit("A = 25e-4", "A = -25e-4"), r"beams\[0\] \(bar2\)\.A: must be > 0, got -0\.0025"),
    ("I-zero", edit("I = 52.1e-8", "I = 0.0"), r"beams\[0\] \(bar2\)\.I: must be > 0, got 0"),
    ("I-negative", edit("I = 52.1e-8", "I = -1e-8", nth=2), r"beams\[1\] \(bar4\)\.I: must be > 0, got -1e-08"),
    ("rho-negative", edit("rho = 7800.0", "rho = -7800.0"), r"beams\[0\] \(bar2\)\.rho: must be >= 0, got -7800"),
    ("rest-length-negative", edit("rest_length = 0.1", "rest_length = -0.1"),
     r"springs\[0\] \(spring1\)\.rest_length: must be >= 0, got -0\.1"),
    ("scale-zero", edit('target = "spring1.k"', 'target = "spring1.k"\nscale = 0.0'),
     r"parameters\[0\] \(k1\)\.scale: must be > 0, got 0"),
    # -- references and names ---------------------------------------------------------------
    ("unknown-node-spring", edit('nodes = ["1", "2"]', 'nodes = ["1", "9"]'),
     r"springs\[0\] \(spring1\)\.nodes\[1\]: unknown node '9'"),
    ("unknown-node-support", edit('node = "1"', 'node = "0"'), r"supports\[0\] \(support1\)\.node: unknown node '0'"),
    ("unknown-node-load", append(LOAD5.replace('"5"', '"6"') + "fy = -1.0"),
     r"loads\[0\] \(push\)\.node: unknown node '6'"),
    ("unknown-table-dampers", append('[[dampers]]\nname = "d1"\nnodes = ["1", "2"]\nc = 3.0'),
     r"dampers: unknown top-level field 'dampers'"),
    ("beams-not-array-of-tables", MINI + '\n[beams]\nname = "b"\n',
     r"beams: expected a list of \[\[beams\]\] tables, got dict"),
    ("nodes-entry-not-table", 'name = "x"\nnodes = [1.0]\n', r"nodes\[0\]: expected a table, got float"),
    ("unknown-field-beam", edit("E = 2.1e11", "Young = 2.1e11", nth=2), r"beams\[1\] \(bar4\): unknown field 'Young'"),
    ("unknown-field-run", edit("t_end = 3.0", "tend = 3.0"), r"run: unknown field 'tend'"),
    ("unknown-field-node", edit("x = 0.5\n", "x = 0.5\nz = 1.0\n"), r"nodes\[2\] \(3\): unknown field 'z'"),
    ("duplicate-node", edit('name = "2"', 'name = "1"'), r"nodes\[1\]\.name: duplicate node '1'"),
    ("duplicate-element-name", edit('name = "spring3"', 'name = "bar2"'),
     r"springs\[1\]\.name: duplicate name 'bar2', already used in beams"),
    ("duplicate-support-load-name", append(LOAD5.replace('"push"', '"support1"') + "fx = 1.0"),
     r"loads\[0\]\.name: duplicate name 'support1', already used in supports"),
    ("reserved-name-gravity", edit('name = "bar4"', 'name = "gravity"'), r"beams\[1\]\.name: 'gravity' is reserved"),
    ("name-with-dot", edit('name = "5"', 'name = "5.1"'),
     r"nodes\[4\] \(5\.1\)\.name: name '5\.1' may not contain '\.'"),
    ("name-with-space", edit('name = "bar2"', 'name = "bar 2"'), r"beams\[0\] \(bar 2\)\.name: .* may not contain"),
    ("name-with-colon", edit('name = "k1"', 'name = "k:1"'), r"parameters\[0\] \(k:1\)\.name: .* may not contain"),
    # -- non-finite values (TOML has nan and inf) ---------------------------------------------------
    ("nan-rho", edit("rho = 7800.0", "rho = nan"), r"beams\[0\] \(bar2\)\.rho: must be finite, got nan"),
    ("nan-node-y", edit("y = -0.9526279441628825", "y = nan"), r"nodes\[3\] \(4\)\.y: must be finite, got nan"),
    ("inf-k", edit("k = 700.0", "k = inf"), r"springs\[0\] \(spring1\)\.k: must be finite, got inf"),
    ("minus-inf-gravity", edit("gravity = [0.0, -9.81]", "gravity = [0.0, -inf]"), r"gravity\[1\]: must be finite"),
    ("inf-t-end", edit("t_end = 3.0", "t_end = inf"), r"run\.t_end: must be finite, got inf"),
    ("nan-lower", edit("lower = 0.0", "lower = nan"), r"parameters\[0\] \(k1\)\.lower: must not be nan"),
    ("nan-load-table", append(LOAD5 + "table = [[0.0, 1.0, 0.0, 0.0], [1.0, nan, 0.0, 0.0]]"),
     r"loads\[0\] \(push\)\.table\[1\]\[1\]: must be finite, got nan"),
    # -- wrong types --------------------------------------------------------------------------------
    ("string-for-number", edit("A = 25e-4", 'A = "25e-4"'),
     r"beams\[0\] \(bar2\)\.A: expected a number, got '25e-4' \(str\)"),
    ("bool-for-number", edit("I = 52.1e-8", "I = true"),
     r"beams\[0\] \(bar2\)\.I: expected a number, got True \(bool\)"),
    ("bool-for-node-x", edit("x = 1.0", "x = false"), r"nodes\[4\] \(5\)\.x: expected a number, got False \(bool\)"),
    ("number-for-name", edit('name = "bar2"', "name = 2"), r"beams\[0\]\.name: expected a string, got 2 \(int\)"),
    ("number-for-scene-name", edit('name = "twobar"', "name = 7"), r"name: expected a non-empty string"),
    ("number-for-node-ref", edit('nodes = ["1", "2"]', "nodes = [1, 2]"),
     r"springs\[0\] \(spring1\)\.nodes\[0\]: expected a non-empty name \(a string\), got 1"),
    ("number-for-support-node", edit('node = "1"', "node = 1"), r"supports\[0\] \(support1\)\.node: expected a string"),
    ("string-for-nodes", edit('nodes = ["2", "3"]', 'nodes = "2-3"'),
     r"beams\[0\] \(bar2\)\.nodes: expected a list of two node names, got '2-3'"),
    ("number-for-rotary-inertia", edit("rho = 7800.0", "rho = 7800.0\nrotary_inertia = 1"),
     r"beams\[0\] \(bar2\)\.rotary_inertia: expected true or false, got 1"),
    ("number-for-unit", edit('unit = "N/m"', "unit = 1"), r"parameters\[0\] \(k1\)\.unit: expected a string"),
    ("string-for-lower", edit("lower = 0.0", 'lower = "zero"'), r"parameters\[0\] \(k1\)\.lower: expected a number"),
    ("run-not-table", TWOBAR[:TWOBAR.index("[run]")] + "run = 3.0\n" + TWOBAR[TWOBAR.index("[[nodes]]"):],
     r"run: expected a table, got float"),
    # -- parameters -------------------------------------------------------------------------------
    ("nominal-below-lower",
     edit('target = "torsion1.kt"\nunit = "N m/rad"\nlower = 0.0', 'target = "torsion1.kt"\nlower = 1.0'),
     r"parameters\[1\] \(kt1\)\.lower: the nominal value 0\.5 of torsion1\.kt is below the lower bound 1"),
    ("nominal-above-upper", edit('target = "spring3.k"', 'target = "spring3.k"\nupper = 300.0'),
     r"parameters\[2\] \(k3\)\.upper: the nominal value 400 of spring3\.k is above the upper bound 300"),
    ("target-unknown-element", edit('target = "spring1.k"', 'target = "spring9.k"'),
     r"parameters\[0\] \(k1\)\.target: unknown element or load 'spring9'"),
    ("target-unknown-property", edit('target = "spring1.k"', 'target = "spring1.kt"'),
     r"parameters\[0\] \(k1\)\.target: 'spring1' has no numeric property 'kt'"),
    ("target-non-numeric-property", edit('target = "spring1.k"', 'target = "bar2.elements"'),
     r"parameters\[0\] \(k1\)\.target: 'bar2' has no numeric property 'elements'"),
    ("target-gravity-z", edit('target = "spring1.k"', 'target = "gravity.z"'),
     r"parameters\[0\] \(k1\)\.target: gravity has components 'x' and 'y', got 'z'"),
    ("target-support", edit('target = "spring1.k"', 'target = "support1.x"'),
     r"parameters\[0\] \(k1\)\.target: 'support1' is a support"),
    ("target-without-dot", edit('target = "spring1.k"', 'target = "spring1"'),
     r"parameters\[0\] \(k1\)\.target: expected '<element>\.<field>'"),
    ("target-two-dots", edit('target = "spring1.k"', 'target = "bar2.1.E"'),
     r"parameters\[0\] \(k1\)\.target: expected '<element>\.<field>'"),
    ("target-tabulated-load", append(LOAD5 + 'table = [[0.0, 1.0, 0.0, 0.0], [1.0, 2.0, 0.0, 0.0]]\n\n'
                                     '[[parameters]]\nname = "f"\ntarget = "push.fx"'),
     r"parameters\[4\] \(f\)\.target: load 'push' is given as a table"),
    ("duplicate-parameter-name", edit('name = "k3"', 'name = "k1"'),
     r"parameters\[2\]\.name: duplicate parameter 'k1'"),
    ("duplicate-parameter-target", edit('target = "spring3.k"', 'target = "spring1.k"'),
     r"parameters\[2\] \(k3\)\.target: 'spring1\.k' is already declared by parameter 'k1'"),
    ("lower-above-upper", edit("lower = 0.0", "lower = 1000.0\nupper = 10.0"),
     r"parameters\[0\] \(k1\)\.lower: must be below upper = 10, got 1000"),
    ("lower-equals-upper", edit("lower = 0.0", "lower = 700.0\nupper = 700.0"),
     r"parameters\[0\] \(k1\)\.lower: must be below upper = 700, got 700"),
    ("lower-inf", edit("lower = 0.0", "lower = inf"),
     r"parameters\[0\] \(k1\)\.lower: must be below upper = inf, got inf"),
    # -- run settings -----------------------------------------------------------------------------
    ("alpha-positive", edit("alpha = 0.0", "alpha = 0.1"), r"run\.alpha: must lie in \[-1/3, 0\], got 0\.1"),
    ("alpha-below-minus-third", edit("alpha = 0.0", "alpha = -0.34"),
     r"run\.alpha: must lie in \[-1/3, 0\], got -0\.34"),
    ("inertia-unknown", edit('inertia = "lagrange"', 'inertia = "newton"'),
     r"run\.inertia: expected one of .* got 'newton'"),
    ("dt-zero", edit("dt = 1e-3", "dt = 0.0"), r"run\.dt: must be > 0, got 0"),
    ("dt-above-t-end", edit("dt = 1e-3", "dt = 5.0"), r"run\.dt: the step 5 s is longer than t_end = 3 s"),
    # -- supports ---------------------------------------------------------------------------------
    ("support-kind-unknown", edit('kind = "clamp"', 'kind = "weld"'),
     r"supports\[0\] \(support1\)\.kind: unknown support kind 'weld'"),
    ("support-kind-number", edit('kind = "clamp"', "kind = 3"), r"supports\[0\] \(support1\)\.kind: expected a string"),
    ("dof-fixed-twice", append('[[supports]]\nname = "roller"\nnode = "1"\nkind = "y"'),
     r"supports\[1\] \(roller\)\.kind: dof y1 is already fixed by support 'support1'"),
    # -- loads --------------------------------------------------------------------------------------
    ("load-times-equal", append(LOAD5 + "table = [[0.0, 1.0, 0.0, 0.0], [0.0, 2.0, 0.0, 0.0]]"),
     r"loads\[0\] \(push\)\.table\[1\]\[0\]: times must increase strictly, got 0 after 0"),
    ("load-times-decreasing",
     append(LOAD5 + "table = [[0.0, 1.0, 0.0, 0.0], [2.0, 2.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]]"),
     r"loads\[0\] \(push\)\.table\[2\]\[0\]: times must increase strictly, got 1 after 2"),
    ("load-constant-and-table", append(LOAD5 + "fy = -3.0\ntable = [[0.0, 1.0, 0.0, 0.0], [1.0, 2.0, 0.0, 0.0]]"),
     r"loads\[0\] \(push\)\.table: give either constant fx/fy/mz or a table, not both"),
    ("load-table-short-row", append(LOAD5 + "table = [[0.0, 1.0, 0.0, 0.0], [1.0, 2.0]]"),
     r"loads\[0\] \(push\)\.table\[1\]: expected a row \[t, fx, fy, mz\]"),
    ("load-table-empty", append(LOAD5 + "table = []"), r"loads\[0\] \(push\)\.table: expected a non-empty list"),
    # -- gravity --------------------------------------------------------------------------------
    ("gravity-three-components", edit("gravity = [0.0, -9.81]", "gravity = [0.0, -9.81, 0.0]"),
     r"gravity: expected \[gx, gy\] in m/s\^2"),
    ("gravity-scalar", edit("gravity = [0.0, -9.81]", "gravity = -9.81"), r"gravity: expected \[gx, gy\] in m/s\^2"),
    ("gravity-string-component", edit("gravity = [0.0, -9.81]", 'gravity = [0.0, "down"]'),
     r"gravity\[1\]: expected a number, got 'down'"),
    # -- meshing ------------------------------------------------------------------------------------
    ("elements-zero", edit("rho = 7800.0", "rho = 7800.0\nelements = 0"),
     r"beams\[0\] \(bar2\)\.elements: expected an integer >= 1, got 0"),
    ("elements-non-integer", edit("rho = 7800.0", "rho = 7800.0\nelements = 2.5", nth=2),
     r"beams\[1\] \(bar4\)\.elements: expected an integer >= 1, got 2\.5"),
    ("elements-bool", edit("rho = 7800.0", "rho = 7800.0\nelements = true"),
     r"beams\[0\] \(bar2\)\.elements: expected an integer >= 1, got True"),
    # -- syntax ---------------------------------------------------------------------------------
    ("invalid-toml", edit("k = 700.0", "k = = 700.0"), r"^<string>: not valid TOML: .*line \d+"),
    ("duplicate-key-toml", edit("k = 700.0", "k = 700.0\nk = 800.0"), r"^<string>: not valid TOML"),
]


def test_enough_distinct_malformed_cases():
    ids = [case[0] for case in MALFORMED]
    assert len(ids) == len(set(ids)) >= 24
    assert len({case[1] for case in MALFORMED}) == len(MALFORMED)


@pytest.mark.parametrize(("text", "match"), [pytest.param(t, m, id=i) for i, t, m in MALFORMED])
def test_malformed_scene_is_rejected_with_the_field_named(text, match):
    with pytest.raises(SceneError, match=match) as info:
        loads_scene(text)
    message = str(info.value)
    assert message.startswith("<string>: ")  # the source is named
    assert "\n" not in message.strip()  # one message, one line


def test_malformed_messages_do_not_repeat_the_location():
    for _, text, _ in MALFORMED:
        with pytest.raises(SceneError) as info:
            loads_scene(text)
        message = str(info.value)
        assert "run: run." not in message and "[].name" not in message, message
        assert "spring 'spring1'" not in message, message  # relabelled as springs[i] (name)


def test_error_is_a_value_error():
    with pytest.raises(ValueError, match=r"springs\[0\] \(spring1\)\.k"):
        loads_scene(edit("k = 700.0", "k = -5"))


# -- files ---------------------------------------------------------------------------------------
def test_invalid_toml_file_names_the_file(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text(edit("[run]", "[run"), encoding="utf-8")
    with pytest.raises(SceneError, match=rf"^{path}: not valid TOML"):
        load_scene(path)


def test_malformed_file_names_the_file_and_the_field(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(edit("kt = 0.5", "kt = -1.0"), encoding="utf-8")
    with pytest.raises(SceneError, match=rf"^{path}: torsion_springs\[0\] \(torsion1\)\.kt: must be > 0"):
        load_scene(str(path))


def test_file_not_found(tmp_path):
    missing = tmp_path / "nope.toml"
    with pytest.raises(SceneError, match=r"nope\.toml': no such file, and not a built-in scene \(built-in: .*'twobar'"):
        load_scene(missing)
    with pytest.raises(SceneError, match=r"'twobarr': no such file"):
        load_scene("twobarr")


def test_directory_is_not_a_scene(tmp_path):
    with pytest.raises(SceneError, match="no such file"):
        load_scene(tmp_path)


def test_undecodable_file(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes(b'name = "caf\xe9"\n')
    with pytest.raises(SceneError, match=rf"{path}: cannot be read"):
        load_scene(path)


def test_scene_from_dict_rejects_non_table():
    with pytest.raises(SceneError, match=r"scene: expected a table, got list"):
        scene_from_dict([])  # type: ignore[arg-type]


# -- the built-in twobar scene ------------------------------------------------------------------------
def test_builtin_scenes_lists_twobar():
    assert "twobar" in builtin_scenes()
    assert load_scene("twobar") == load_scene(TWOBAR_PATH) == loads_scene(TWOBAR)


def test_twobar_has_the_numbers_of_shared_scenes_twobar_md():
    s = load_scene("twobar")
    assert s.name == "twobar"
    assert s.gravity == (0.0, -9.81)
    e = (math.sin(math.pi / 6), -math.cos(math.pi / 6))
    assert [n.name for n in s.nodes] == ["1", "2", "3", "4", "5"]
    for n, dist in zip(s.nodes, (0.0, 0.1, 1.0, 1.1, 2.0), strict=True):
        # the file's digits against this machine's libm sin and cos (within an ulp, not the same bits on every
        # machine) times <= 2 m: a few ulps of 2 m (1e-15); 1e-12 m is 1e3 x that
        assert (n.x, n.y) == pytest.approx((dist * e[0], dist * e[1]), abs=1e-12)
        assert (n.theta, n.vx, n.vy, n.omega) == (0.0, 0.0, 0.0, 0.0)  # at rest

    assert [(sp.name, sp.nodes, sp.k, sp.rest_length) for sp in s.springs] == [
        ("spring1", ("1", "2"), 700.0, 0.1), ("spring3", ("3", "4"), 400.0, 0.1)]
    assert [(t.name, t.nodes, t.kt, t.rest_angle) for t in s.torsion_springs] == [
        ("torsion1", ("1", "2"), 0.5, 0.0), ("torsion3", ("3", "4"), 0.5, 0.0)]
    assert [(b.name, b.nodes) for b in s.beams] == [("bar2", ("2", "3")), ("bar4", ("4", "5"))]
    for b in s.beams:
        assert (b.E, b.A, b.I, b.rho, b.elements, b.rotary_inertia) == (2.1e11, 25e-4, 52.1e-8, 7800.0, 1, False)
        length = s.distance(*b.nodes)
        assert length == pytest.approx(0.9, rel=1e-14)
        assert b.rho * b.A * length == pytest.approx(17.55, rel=1e-12)  # bar mass
    for sp in s.springs:  # all springs start at rest length
        assert s.distance(*sp.nodes) == pytest.approx(sp.rest_length, rel=1e-14)

    assert [(su.name, su.node, su.kind, su.dofs) for su in s.supports] == [
        ("support1", "1", "clamp", ("x", "y", "theta"))]
    assert s.loads == ()
    assert [p.name for p in s.parameters] == ["k1", "kt1", "k3", "kt3"]
    assert [p.target for p in s.parameters] == ["spring1.k", "torsion1.kt", "spring3.k", "torsion3.kt"]
    assert [s.property_value(p.target) for p in s.parameters] == [700.0, 0.5, 400.0, 0.5]
    assert [p.unit for p in s.parameters] == ["N/m", "N m/rad", "N/m", "N m/rad"]
    assert all(p.lower == 0.0 and p.upper == math.inf and p.scale is None for p in s.parameters)
    assert (s.run.t_end, s.run.dt, s.run.alpha, s.run.inertia) == (3.0, 1e-3, 0.0, "lagrange")


# -- round trips ----------------------------------------------------------------------------------
EVERYTHING = """
name = "everything"
gravity = [0.5, -9.81]

[run]
t_end = 2.0
dt = 0.005
alpha = -0.1
inertia = "seed"

[[nodes]]
name = "a"
x = 0.0
y = 0.0

[[nodes]]
name = "b"
x = 1.0
y = 0.0
theta = 0.1
vx = 0.2
vy = -0.3
omega = 0.4

[[nodes]]
name = "c"
x = 2.0
y = 0.5

[[nodes]]
name = "d"
x = 2.0
y = 0.5

[[nodes]]
name = "e"
x = 3.0
y = 0.5

[[beams]]
name = "ab"
nodes = ["a", "b"]
E = 7e10
A = 1e-4
I = 8.3e-10
rho = 2700
elements = 4
rotary_inertia = true

[[beams]]
name = "de"
nodes = ["d", "e"]
E = 2.1e11
A = 25e-4
I = 52.1e-8
rho = 0

[[springs]]
name = "bc"
nodes = ["b", "c"]
k = 1500.0

[[springs]]
name = "cd"
nodes = ["c", "d"]
k = 2e4
rest_length = 0.0

[[torsion_springs]]
name = "tbc"
nodes = ["b", "c"]
kt = 3.0

[[torsion_springs]]
name = "tcd"
nodes = ["c", "d"]
kt = 4.0
rest_angle = 0.2

[[supports]]
name = "pin_a"
node = "a"
kind = "pin"

[[supports]]
name = "rot_a"
node = "a"
kind = "theta"

[[supports]]
name = "slide_e"
node = "e"
kind = "x"

[[loads]]
name = "const_b"
node = "b"
fx = 1.0
fy = -2.0
mz = 0.3

[[loads]]
name = "ramp_e"
node = "e"
table = [[0.0, 0.0, 0.0, 0.0], [0.5, 0.0, -10.0, 0.0], [1.5, 5.0, -10.0, 1.0]]

[[parameters]]
name = "k_bc"
target = "bc.k"
unit = "N/m"
lower = 0.0
upper = inf

[[parameters]]
name = "E_ab"
target = "ab.E"
unit = "Pa"
lower = 1e9
upper = 1e12
scale = 7e10

[[parameters]]
name = "L_bc"
target = "bc.rest_length"
unit = "m"

[[parameters]]
name = "g_y"
target = "gravity.y"
unit = "m/s^2"
lower = -inf
upper = 0.0

[[parameters]]
name = "fx_b"
target = "const_b.fx"
unit = "N"

[[parameters]]
name = "rest_tbc"
target = "tbc.rest_angle"
"""


def test_everything_scene_loads_as_written():
    s = loads_scene(EVERYTHING)
    assert s.run.inertia == "seed" and s.run.alpha == -0.1
    assert s.node("b").omega == 0.4
    ab = s.item("ab")
    assert isinstance(ab, Beam) and ab.elements == 4 and ab.rotary_inertia is True
    assert s.item("de").rho == 0.0
    assert s.item("bc").rest_length is None and s.item("tbc").rest_angle is None
    assert [su.kind for su in s.supports] == ["pin", "theta", "x"]
    ramp = s.item("ramp_e")
    assert isinstance(ramp, Load) and ramp.table[2] == (1.5, 5.0, -10.0, 1.0)
    assert s.item("const_b").rows() == ((0.0, 1.0, -2.0, 0.3),)
    assert s.parameter("k_bc").upper == math.inf and s.parameter("g_y").lower == -math.inf
    assert s.parameter("L_bc").lower == 0.0  # default bound of a rest length
    assert s.property_value("bc.rest_length") == pytest.approx(math.hypot(1.0, 0.5))  # default: initial distance
    assert s.property_value("tbc.rest_angle") == pytest.approx(-0.1)  # default: initial relative rotation
    assert s.property_value("gravity.y") == -9.81 and s.property_value("const_b.fx") == 1.0


@pytest.mark.parametrize("source", ["twobar", EVERYTHING], ids=["twobar", "everything"])
def test_dumps_loads_round_trip(source):
    scene = load_scene(source) if source == "twobar" else loads_scene(source)
    text = dumps_scene(scene)
    again = loads_scene(text)
    assert again == scene
    assert dumps_scene(again) == text  # stable
    for f in fields(Scene):  # field by field, so a failure says which table differs
        assert getattr(again, f.name) == getattr(scene, f.name), f.name


def test_dumps_omits_default_bounds_and_fields():
    text = dumps_scene(loads_scene(EVERYTHING))
    g_y = text.split('name = "g_y"')[1].split("[[")[0]
    assert "upper = 0.0" in g_y and "lower" not in g_y  # -inf is the default bound
    assert "upper = 1000000000000.0" in text and "upper = inf" not in text
    assert "rest_length" not in text.split('name = "bc"')[1].split("[[")[0]  # default stays implicit
    assert 'kind = "pin"' in text


def test_round_trip_of_python_built_scene_with_awkward_strings():
    base = load_scene("twobar")
    par = replace(base.parameters[0], unit='N/m "per metre"\\ \t\u00e9')
    scene = replace(base, name="two bar: ünïcode", parameters=(par, *base.parameters[1:]))
    assert loads_scene(dumps_scene(scene)) == scene


def test_round_trip_after_with_values():
    scene = load_scene("twobar").with_values(k1=650.0, kt3=0.45)
    assert loads_scene(dumps_scene(scene)) == scene


def test_save_scene_round_trip(tmp_path):
    scene = loads_scene(EVERYTHING)
    path = tmp_path / "sub" / "everything.toml"
    path.parent.mkdir()
    save_scene(scene, path)
    assert path.read_text(encoding="utf-8") == dumps_scene(scene)
    assert load_scene(path) == scene
    assert sorted(p.name for p in path.parent.iterdir()) == ["everything.toml"]  # no temporary left


# -- minimal scenes and defaults ----------------------------------------------------------------------
def test_minimal_scene_defaults():
    s = loads_scene(MINI)
    assert s.gravity == (0.0, -9.81)
    assert (s.run.t_end, s.run.dt, s.run.alpha, s.run.inertia) == (3.0, 1e-3, -0.05, "lagrange")
    assert s.beams == s.springs == s.torsion_springs == s.supports == s.loads == s.parameters == ()
    assert loads_scene(dumps_scene(s)) == s


def test_twobar_types_after_loading():
    s = load_scene("twobar")
    assert all(isinstance(x, Spring) for x in s.springs)
    assert all(isinstance(x, TorsionSpring) for x in s.torsion_springs)
    assert all(isinstance(x, Support) for x in s.supports)
    assert all(isinstance(x, Parameter) for x in s.parameters)
    assert isinstance(s.nodes, tuple) and isinstance(s.beams[0].nodes, tuple)
    assert all(isinstance(v, float) for n in s.nodes for v in (n.x, n.y, n.theta))


def test_examples_in_docs_scene_format_load():
    doc = Path(__file__).resolve().parents[1] / "docs" / "scene-format.md"
    if not doc.is_file():
        pytest.skip("docs/scene-format.md not present")
    text = doc.read_text(encoding="utf-8")
    blocks = [b.split("```")[0] for b in text.split("```toml\n")[1:]]
    assert len(blocks) >= 2
    assert loads_scene(blocks[0], source="docs example 1") == load_scene("twobar")
    cantilever = loads_scene(blocks[1], source="docs example 2")
    assert cantilever.beams[0].elements == 4 and len(cantilever.loads[0].table) == 4
    for block in blocks:  # every documented field is a real one
        assert loads_scene(dumps_scene(loads_scene(block))) == loads_scene(block)


def test_an_osim_model_s_scene_and_warnings_come_from_one_reader_with_load_scene_s_errors(tmp_path):
    """scene.io.load_osim: what load_scene and a study's calibrations (casflex.study.runner._osim) read from an .osim
    file, the reader's ValueError given as load_scene's SceneError."""
    from casflex.scene.from_osim import scene_from_osim
    from casflex.scene.io import load_osim
    from casflex.scene.items import SceneError
    from casflex.study.runner import _osim

    leg = Path(__file__).parent / "data" / "lab" / "hamner_subject02_leg.osim"
    made = scene_from_osim(leg)
    scene, warnings = load_osim(leg)
    text = dumps_scene(made.scene)  # the scene's text (its items compare by identity where they hold functions)
    assert dumps_scene(scene) == dumps_scene(load_scene(leg)) == text and warnings == tuple(made.warnings)
    cached = _osim(str(leg), "digest")
    assert dumps_scene(cached[0]) == text and cached[1] == warnings
    bad = tmp_path / "bad.osim"
    bad.write_text("<OpenSimDocument Version='30000'><Model name='m'/></OpenSimDocument>")
    for read in (load_osim, load_scene, lambda p: _osim(str(p), None)):
        with pytest.raises(SceneError, match=r"format 30000; casflex reads format 4.x"):
            read(bad)
