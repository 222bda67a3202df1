"""The package's shape (docs/architecture.md): the folders on their floors, every import running down, no
import circles, a handful of modules under casflex/, a light ``import casflex`` offering the verbs.

The graph is read from the source (every ``import`` and ``from ... import``, at module level or inside a
function: a lazy import is still a dependency), one node per file; ``from casflex.pkg import name`` is an
edge to the package's ``__init__.py``, or to the submodule ``casflex/pkg/name.py`` where that exists;
``from casflex import name`` an edge to the module that ``casflex/__init__.py`` loads the name from.
"""

from __future__ import annotations

import ast
import functools
import subprocess
import sys
from pathlib import Path

import pytest

import casflex

PACKAGE = Path(__file__).resolve().parents[1] / "casflex"

#: The floors, from the ground up, as docs/architecture.md draws them: a folder (or a module directly under
#: casflex/) imports only from its own folder and from folders on floors below its own.
FLOORS = (
    ("results", "interrupt"),  # shared by all: records and atomic files, signals
    ("codegen",),  # shared by all: compiled code and its cache (written by results' atomic write)
    ("data",),  # measurement sets: pure data
    ("lab",),
    ("elements", "scene"),
    ("model",),
    ("integrators",),
    ("peers",),
    ("simulate", "statics"),
    ("inverse", "identification"),
    ("muscles",),
    ("study", "plotting"),
    ("cli",),
    ("_entry",),
    ("__main__",),
)


def _face(name: str) -> str:
    """The module ``from casflex import name`` loads ``name`` from (casflex/__init__.py's lazy names)."""
    if name in casflex._PACKAGES:
        return f"casflex.{name}"
    if name in casflex._ALIASES:
        return casflex._ALIASES[name][0]
    return casflex._EXPORTS.get(name, "casflex")


def _module(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _graph() -> dict[str, set[str]]:
    """module -> the modules it imports (a fresh copy: tests may add to it)."""
    return {m: set(t) for m, t in _read_graph().items()}


@functools.cache
def _read_graph() -> dict[str, set[str]]:
    files = {_module(p): p for p in PACKAGE.rglob("*.py")}
    graph: dict[str, set[str]] = {m: set() for m in files}
    for mod, path in files.items():
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    base = ".".join(package.split(".")[:len(package.split(".")) - node.level + 1] + [base]).strip(".")
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in files else _face(a.name) if base == "casflex"
                           else base for a in node.names]
            else:
                continue
            graph[mod] |= {t for t in targets if t in files and t != mod}
    return graph


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_graph_sees_the_imports():
    g = _graph()
    assert "casflex.model.model" in g["casflex.model"]  # the package's face
    assert "casflex.lab.tables" in g["casflex.scene.files"]  # a lazy import inside a function
    assert "casflex.scene" in g["casflex.simulate.run"]


def _floor_of(module: str) -> tuple[str, int]:
    """(the folder or module directly under casflex/, its floor) of a module; the package's face is no floor's."""
    part = module.split(".")[1] if "." in module else ""
    return part, next((i for i, names in enumerate(FLOORS) if part in names), -1)


def _arrows_up(graph: dict[str, set[str]]) -> list[str]:
    """Every import from a folder to one on its own floor or above (``a -> b``)."""
    out = []
    for a, targets in graph.items():
        pa, fa = _floor_of(a)
        for b in targets:
            pb, fb = _floor_of(b)
            if pa != pb and b != "casflex" and fb >= fa:
                out.append(f"{a} -> {b}")
    return sorted(out)


def test_every_folder_stands_on_a_floor():
    parts = {_floor_of(m)[0] for m in _graph()} - {""}
    assert sorted(p for p in parts if _floor_of(f"casflex.{p}")[1] < 0) == []
    assert sorted(n for names in FLOORS for n in names if n not in parts) == []


def test_every_import_runs_down_the_floors():
    assert _arrows_up(_graph()) == []


def test_an_import_running_back_up_is_found():
    g = _graph()
    g["casflex.lab.plane"] = g["casflex.lab.plane"] | {"casflex.model"}  # the lab below the model
    g["casflex.simulate.run"] = g["casflex.simulate.run"] | {"casflex.statics"}  # a floor's neighbour
    assert _arrows_up(g) == ["casflex.lab.plane -> casflex.model", "casflex.simulate.run -> casflex.statics"]


def test_the_face_s_names_are_edges_to_their_modules():
    g = _graph()
    assert "casflex.scene" in g["casflex.study.runner"]  # from casflex import load_scene
    assert "casflex" in g["casflex.cli"]  # from casflex import __version__: the face itself


def test_import_casflex_is_light_and_offers_the_verbs():
    code = ("import sys, casflex; heavy = sorted(m for m in ('casadi', 'numpy', 'casflex.model') if m in sys.modules)\n"
            "import casflex.identification, casflex.inverse, casflex.simulate, casflex.study.study_file\n"
            "assert casflex.simulate is sys.modules['casflex.simulate'] and callable(casflex.simulate)\n"
            "assert casflex.study is sys.modules['casflex.study'] and callable(casflex.study)\n"
            "assert casflex.identify is casflex.identification.identify_indirect\n"
            "assert casflex.inverse_dynamics is casflex.inverse.inverse_dynamics\n"
            "assert casflex.load_study is casflex.study.study_file.load_study\n"
            "print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=PACKAGE.parent)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_the_verb_simulate_runs_a_scene():
    model = casflex.assemble(casflex.load_scene("twobar"))
    tr = casflex.simulate(model, 0.005, stepping=casflex.Stepping(dt=1e-3))
    assert tr.t.shape == (6,) and tr.success


def test_the_verb_study_reads_the_study_file_first(tmp_path):
    with pytest.raises(ValueError, match="no such study file"):
        casflex.study(tmp_path / "missing.toml", tmp_path / "records")


def test_no_import_circles():
    assert _circles(_graph()) == []


def test_the_circle_finder_finds_a_circle():
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_a_handful_of_modules_directly_under_casflex():
    loose = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert len(loose) <= 8, loose
