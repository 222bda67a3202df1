"""The Scene dataclasses built from Python: validation, defaults, queries and with_values."""

from __future__ import annotations

import math
from dataclasses import FrozenInstanceError, fields, replace

import pytest

from casflex.scene import (
    SUPPORT_DOFS,
    Beam,
    Load,
    Node,
    Parameter,
    RunSettings,
    Scene,
    SceneError,
    Spring,
    Support,
    TorsionSpring,
)
from casflex.scene.io import load_scene


@pytest.fixture(scope="module")
def twobar() -> Scene:
    return load_scene("twobar")


def small(**overrides) -> Scene:
    """Two nodes joined by a spring and a torsion spring, node a clamped."""
    kw = dict(
        name="small",
        nodes=(Node("a", 0.0, 0.0), Node("b", 3.0, 4.0, theta=0.25)),
        springs=(Spring("s", ("a", "b"), 100.0),),
        torsion_springs=(TorsionSpring("t", ("a", "b"), 2.0),),
        supports=(Support("fix", "a"),),
    )
    kw.update(overrides)
    return Scene(**kw)


# -- SceneError ------------------------------------------------------------------------------------
def test_scene_error_carries_field_and_reason():
    with pytest.raises(SceneError, match=r"^spring 'spring1'\.k: must be > 0, got -5$") as info:
        Spring("spring1", ("1", "2"), -5)
    assert isinstance(info.value, ValueError)
    assert info.value.field == "k" and info.value.reason == "must be > 0, got -5"


def test_scene_error_at():
    e = SceneError.at("beam 'b'", "E", "must be > 0, got 0")
    assert str(e) == "beam 'b'.E: must be > 0, got 0" and e.field == "E"
    assert str(SceneError.at("", "gravity[0]", "bad")) == "gravity[0]: bad"
    assert str(SceneError.at("load 'l'", None, "bad")) == "load 'l': bad"
    assert SceneError("plain").reason == "plain" and SceneError("plain").field is None


# -- malformed scenes built in Python (no bare TypeError/KeyError) ----------------------------------
MALFORMED = [
    ("node-empty-name", lambda: Node("", 0.0, 0.0), r"node ''\.name: expected a non-empty name"),
    ("node-number-name", lambda: Node(3, 0.0, 0.0), r"node 3\.name: expected a non-empty name \(a string\), got 3"),
    ("node-string-x", lambda: Node("a", "0", 0.0), r"node 'a'\.x: expected a number, got '0' \(str\)"),
    ("node-nan-omega", lambda: Node("a", 0.0, 0.0, omega=math.nan), r"node 'a'\.omega: must be finite"),
    ("beam-none-E", lambda: Beam("b", ("a", "c"), None, 1.0, 1.0, 1.0), r"beam 'b'\.E: expected a number, got None"),
    ("beam-negative-rho", lambda: Beam("b", ("a", "c"), 1.0, 1.0, 1.0, -1.0), r"beam 'b'\.rho: must be >= 0"),
    ("beam-float-elements", lambda: Beam("b", ("a", "c"), 1.0, 1.0, 1.0, 1.0, elements=2.0),
     r"beam 'b'\.elements: expected an integer >= 1, got 2\.0"),
    ("beam-three-nodes", lambda: Beam("b", ("a", "c", "d"), 1.0, 1.0, 1.0, 1.0),
     r"beam 'b'\.nodes: expected a list of two node names"),
    ("spring-node-none", lambda: Spring("s", ("a", None), 1.0), r"spring 's'\.nodes\[1\]: expected a non-empty name"),
    ("torsion-inf-rest", lambda: TorsionSpring("t", ("a", "b"), 1.0, rest_angle=math.inf),
     r"torsion spring 't'\.rest_angle: must be finite"),
    ("support-kind-list", lambda: Support("s", "a", kind=["x"]), r"support 's'\.kind: unknown support kind \['x'\]"),
    ("support-kind-case", lambda: Support("s", "a", kind="Clamp"), r"support 's'\.kind: unknown support kind 'Clamp'"),
    ("load-table-number", lambda: Load("l", "a", table=5), r"load 'l'\.table: expected a non-empty list"),
    ("load-table-string-row", lambda: Load("l", "a", table=("abcd",)), r"load 'l'\.table\[0\]: expected a row"),
    ("load-mz-and-table", lambda: Load("l", "a", mz=1.0, table=((0.0, 0.0, 0.0, 0.0),)),
     r"load 'l'\.table: give either constant fx/fy/mz or a table, not both \(also given: \['mz'\]\)"),
    ("parameter-target-number", lambda: Parameter("p", 5), r"parameter 'p'\.target: expected '<element>\.<field>'"),
    ("parameter-target-empty-field", lambda: Parameter("p", "spring1."), r"parameter 'p'\.target: expected"),
    ("parameter-bool-upper", lambda: Parameter("p", "s.k", upper=True), r"parameter 'p'\.upper: expected a number"),
    ("parameter-unit-none", lambda: Parameter("p", "s.k", unit=None), r"parameter 'p'\.unit: expected a string"),
    ("parameter-negative-scale", lambda: Parameter("p", "s.k", scale=-1.0), r"parameter 'p'\.scale: must be > 0"),
    ("run-inertia-list", lambda: RunSettings(inertia=["seed"]), r"run\.inertia: expected one of"),
    ("run-alpha-string", lambda: RunSettings(alpha="-0.1"), r"run\.alpha: expected a number"),
    ("scene-empty-name", lambda: small(name=" "), r"^name: expected a non-empty string"),
    ("scene-nodes-string", lambda: small(nodes="ab"), r"^nodes: expected a list, got str"),
    ("scene-node-as-dict", lambda: small(nodes=({"name": "a", "x": 0.0, "y": 0.0},)),
     r"nodes\[0\]: expected a Node, got dict"),
    ("scene-spring-in-beams", lambda: small(beams=(Spring("x", ("a", "b"), 1.0),)),
     r"beams\[0\]: expected a Beam, got Spring"),
    ("scene-gravity-string", lambda: small(gravity="xy"), r"^gravity: expected \[gx, gy\]"),
    ("scene-run-dict", lambda: small(run={"t_end": 1.0}), r"^run: expected RunSettings, got dict"),
    ("scene-unknown-torsion-node", lambda: small(torsion_springs=(TorsionSpring("t", ("a", "z"), 1.0),)),
     r"torsion_springs\[0\] \(t\)\.nodes\[1\]: unknown node 'z'; known nodes: \['a', 'b'\]"),
    ("scene-pin-after-clamp", lambda: small(supports=(Support("fix", "a"), Support("pin", "a", "pin"))),
     r"supports\[1\] \(pin\)\.kind: dof xa is already fixed by support 'fix'"),
    ("scene-parameter-bound", lambda: small(parameters=(Parameter("k", "s.k", upper=50.0),)),
     r"parameters\[0\] \(k\)\.upper: the nominal value 100 of s\.k is above the upper bound 50"),
]


@pytest.mark.parametrize(("build", "match"), [pytest.param(b, m, id=i) for i, b, m in MALFORMED])
def test_malformed_python_scene_is_rejected_with_the_field_named(build, match):
    with pytest.raises(SceneError, match=match):
        build()


# -- defaults and normalisation ----------------------------------------------------------------------
def test_defaults():
    n = Node("a", 1, 2)
    assert (n.theta, n.vx, n.vy, n.omega) == (0.0, 0.0, 0.0, 0.0)
    assert isinstance(n.x, float) and isinstance(n.y, float)
    b = Beam("b", ["a", "c"], 1, 2, 3, 4)
    assert b.nodes == ("a", "c") and (b.elements, b.rotary_inertia) == (1, False)
    assert Spring("s", ("a", "b"), 1.0).rest_length is None
    assert TorsionSpring("t", ("a", "b"), 1.0).rest_angle is None
    assert Support("s", "a").kind == "clamp"
    p = Parameter("p", "s.k")
    assert (p.unit, p.lower, p.upper, p.scale) == ("", 0.0, math.inf, None)  # a stiffness is >= 0
    assert Parameter("g", "gravity.y").lower == Parameter("a", "t.rest_angle").lower == -math.inf
    assert Parameter("e", "b.E", lower=-1.0).lower == -1.0  # given bounds are kept
    r = RunSettings()
    assert (r.t_end, r.dt, r.alpha, r.inertia) == (3.0, 1e-3, -0.05, "lagrange")
    assert small().gravity == (0.0, -9.81)


def test_lists_and_ints_are_normalised_so_equal_scenes_compare_equal():
    a = small()
    b = small(nodes=[Node("a", 0, 0), Node("b", 3, 4, theta=0.25)], springs=[Spring("s", ["a", "b"], 100)])
    assert a == b
    rows = ((0.0, 1.0, 2.0, 3.0), (1.0, 1.0, 2.0, 3.0))
    assert Load("l", "a", table=[[0, 1, 2, 3], [1, 1, 2, 3]]) == Load("l", "a", table=rows)


def test_scene_is_frozen(twobar):
    with pytest.raises(FrozenInstanceError):
        twobar.name = "other"
    with pytest.raises(FrozenInstanceError):
        twobar.springs[0].k = 1.0


def test_support_dofs():
    assert SUPPORT_DOFS == {
        "clamp": ("x", "y", "theta"), "pin": ("x", "y"), "x": ("x",), "y": ("y",), "theta": ("theta",)}
    for kind, dofs in SUPPORT_DOFS.items():
        assert Support("s", "a", kind).dofs == dofs


def test_several_supports_on_one_node_with_distinct_dofs():
    s = small(supports=(Support("p", "a", "pin"), Support("r", "a", "theta")))
    assert [x.dofs for x in s.supports] == [("x", "y"), ("theta",)]


def test_load_rows():
    assert Load("l", "a", fx=1.0, fy=2.0, mz=3.0).rows() == ((0.0, 1.0, 2.0, 3.0),)
    table = ((0.0, 0.0, 0.0, 0.0), (1.0, 5.0, 0.0, 0.0))
    assert Load("l", "a", table=table).rows() == table
    assert Load("l", "a", fx=0.0, table=table).table == table  # explicit zero constants are no conflict


def test_zero_length_spring_and_coincident_torsion_spring_are_allowed():
    nodes = (Node("a", 0.0, 0.0), Node("b", 0.0, 0.0))
    s = Scene("joint", nodes, springs=(Spring("s", ("a", "b"), 1e4, rest_length=0.0),),
              torsion_springs=(TorsionSpring("t", ("a", "b"), 1.0),), supports=(Support("fix", "a"),))
    assert s.distance("a", "b") == 0.0 and s.property_value("s.rest_length") == 0.0


# -- queries --------------------------------------------------------------------------------------
def test_property_value_defaults_to_the_initial_configuration():
    s = small()
    assert s.property_value("s.rest_length") == pytest.approx(5.0)  # rest_length: initial distance
    assert s.property_value("t.rest_angle") == pytest.approx(0.25)  # rest_angle: theta_b - theta_a
    assert s.property_value("s.k") == 100.0 and s.property_value("t.kt") == 2.0
    assert s.property_value("gravity.x") == 0.0 and s.property_value("gravity.y") == -9.81
    explicit = small(springs=(Spring("s", ("a", "b"), 100.0, rest_length=4.5),))
    assert explicit.property_value("s.rest_length") == 4.5


def test_property_value_errors():
    s = small()
    with pytest.raises(SceneError, match=r"target: unknown element or load 'q' in 'q\.k'"):
        s.property_value("q.k")
    with pytest.raises(SceneError, match=r"where: 's' has no numeric property 'E'; expected one of \['k', "):
        s.property_value("s.E", where="where")


def test_queries(twobar):
    assert twobar.node("3").x == 0.5
    assert twobar.item("bar4").nodes == ("4", "5") and twobar.item("support1").kind == "clamp"
    assert twobar.parameter("kt3").target == "torsion3.kt"
    assert twobar.length_scale == pytest.approx(2.0)
    with pytest.raises(SceneError, match="unknown node '9'"):
        twobar.node("9")
    with pytest.raises(SceneError, match="unknown element or load 'bar3'"):
        twobar.item("bar3")
    with pytest.raises(SceneError, match=r"unknown parameter 'k2'; declared: \['k1', 'kt1', 'k3', 'kt3'\]"):
        twobar.parameter("k2")


def test_length_scale_has_a_floor():
    assert Scene("dot", (Node("a", 1.0, 1.0),)).length_scale == 1e-3


# -- with_values ----------------------------------------------------------------------------------
def test_with_values_changes_only_that_property(twobar):
    changed = twobar.with_values(k1=800)
    assert changed.springs[0].k == 800.0 and isinstance(changed.springs[0].k, float)
    assert twobar.springs[0].k == 700.0  # the original is untouched
    assert changed.springs[0] == replace(twobar.springs[0], k=800.0)
    assert changed.springs[1] == twobar.springs[1]
    for f in fields(Scene):
        if f.name != "springs":
            assert getattr(changed, f.name) == getattr(twobar, f.name), f.name
    assert [changed.property_value(p.target) for p in changed.parameters] == [800.0, 0.5, 400.0, 0.5]
    assert changed != twobar and changed.with_values(k1=700.0) == twobar


def test_with_values_several_and_gravity_and_loads():
    s = small(loads=(Load("push", "b", fx=1.0),),
              parameters=(Parameter("k", "s.k", lower=0.0), Parameter("gy", "gravity.y"),
                          Parameter("f", "push.fx"), Parameter("L", "s.rest_length")))
    t = s.with_values(k=120.0, gy=-1.62, f=-3.0, L=4.0)
    assert t.springs[0].k == 120.0 and t.gravity == (0.0, -1.62) and t.loads[0].fx == -3.0
    assert t.springs[0].rest_length == 4.0 and s.springs[0].rest_length is None
    assert t.torsion_springs == s.torsion_springs and t.nodes == s.nodes


def test_with_values_rejects_bad_values(twobar):
    with pytest.raises(SceneError, match=r"with_values\(k1=-1\.0\): spring 'spring1'\.k: must be > 0, got -1"):
        twobar.with_values(k1=-1.0)
    with pytest.raises(SceneError, match=r"with_values\(kt1=nan\): torsion spring 'torsion1'\.kt: must be finite"):
        twobar.with_values(kt1=math.nan)
    bounded = replace(twobar, parameters=(replace(twobar.parameters[0], upper=1000.0), *twobar.parameters[1:]))
    with pytest.raises(SceneError, match=r"parameters\[0\] \(k1\)\.upper: the nominal value 1500 .* bound 1000"):
        bounded.with_values(k1=1500.0)
    with pytest.raises(SceneError, match="unknown parameter 'E'"):
        twobar.with_values(E=1.0)
