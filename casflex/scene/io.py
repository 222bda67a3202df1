"""Read and write scenes as TOML; find built-in scenes by name.

The format is documented field by field in ``docs/scene-format.md``. Reading checks every
table for unknown or missing fields and wrong types, and reports the field by its path
(``springs[1].k``) before the dataclasses validate the values.
"""

from __future__ import annotations

import math
import os
from dataclasses import MISSING, fields
from pathlib import Path
from typing import Any

from casflex.scene.coordinates import Coordinate
from casflex.scene.markers import Marker
from casflex.scene.scene import (
    Beam,
    Joint,
    Load,
    Node,
    Parameter,
    RigidBody,
    RunSettings,
    Scene,
    SceneError,
    Spring,
    Support,
    TorsionSpring,
)
from casflex.scene.uncertain import Uncertain

__all__ = ["load_scene", "load_osim", "loads_scene", "dumps_scene", "save_scene", "builtin_scenes",
           "builtin_scene_text", "scene_from_dict"]

_BUILTIN_DIR = Path(__file__).parent / "builtin"
_LISTS: dict[str, type] = {
    "nodes": Node,
    "beams": Beam,
    "springs": Spring,
    "torsion_springs": TorsionSpring,
    "bodies": RigidBody,
    "supports": Support,
    "joints": Joint,
    "loads": Load,
    "parameters": Parameter,
    "markers": Marker,
    "coordinates": Coordinate,
    "uncertain": Uncertain,
}
_TOP_KEYS = {"name", "gravity", "run", *_LISTS}


def builtin_scenes() -> list[str]:
    """Names of the scenes shipped with casflex (``casflex/scene/builtin/*.toml``)."""
    return sorted(p.stem for p in _BUILTIN_DIR.glob("*.toml"))


def builtin_scene_text(name: str) -> str:
    """The TOML text of the built-in scene ``name`` as shipped (its comments, sources and units kept): a starting
    point to edit (``casflex scene show NAME > my.toml``). SceneError naming the built-in scenes for another name."""
    if name not in builtin_scenes():
        raise SceneError(f"scene {name!r}: not a built-in scene (built-in: {', '.join(builtin_scenes())})")
    return (_BUILTIN_DIR / f"{name}.toml").read_text(encoding="utf-8")


def load_scene(source: str | os.PathLike[str]) -> Scene:
    """Load a scene from a TOML file, an OpenSim model (``.osim``: :mod:`casflex.scene.from_osim`, its report
    dropped; :func:`casflex.scene.from_osim.scene_from_osim` keeps it), or a built-in scene by name (e.g.
    ``"twobar"``)."""
    text_source = str(source)
    if text_source.lower().endswith(".osim"):
        return load_osim(source)[0]
    if text_source in builtin_scenes():
        path = _BUILTIN_DIR / f"{text_source}.toml"
    else:
        path = Path(source)
        if not path.is_file():
            raise SceneError(f"scene {text_source!r}: no such file, and not a built-in scene "
                             f"(built-in: {builtin_scenes()})")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(f"scene file {path}: cannot be read ({exc})") from None
    return loads_scene(text, source=str(path), base=path.parent)


def load_osim(source: str | os.PathLike[str]) -> tuple[Scene, tuple[str, ...]]:
    """(the planar scene, its warnings: what it leaves out of the model) of the OpenSim model file ``source``
    (:func:`casflex.scene.from_osim.scene_from_osim`), its refusal a SceneError, as :func:`load_scene`'s."""
    from casflex.scene.from_osim import scene_from_osim

    try:
        got = scene_from_osim(source)
    except SceneError:
        raise
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    return got.scene, tuple(got.warnings)


def loads_scene(text: str, *, source: str = "<string>", base: str | os.PathLike[str] | None = None) -> Scene:
    """Parse a scene from TOML text; ``base``: the folder that data files it names are relative to
    (default: the working folder; :mod:`casflex.scene.files`)."""
    import tomllib  # here: its import compiles its patterns (0.01 s), which a command on an OpenSim model never needs

    from casflex.scene.files import resolve_file_inputs

    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{source}: not valid TOML: {exc}") from None
    try:
        return scene_from_dict(resolve_file_inputs(data, Path.cwd() if base is None else Path(base)))
    except SceneError as exc:
        raise SceneError(f"{source}: {exc}") from None


def _build(cls: type, where: str, table: Any) -> Any:
    """``cls(**table)``, with errors located as ``<where> (<name>).<field>: <reason>``."""
    if not isinstance(table, dict):
        raise SceneError(f"{where}: expected a table, got {type(table).__name__} {table!r}")
    label = where
    if isinstance(table.get("name"), str) and table["name"]:
        label = f"{where} ({table['name']})"
    elif isinstance(table.get("target"), str) and table["target"]:  # an [[uncertain]] entry: named by its target
        label = f"{where} ({table['target']})"
    known = {f.name: f for f in fields(cls)}
    for key in table:
        if key not in known:
            raise SceneError(f"{label}: unknown field {key!r}; expected some of {list(known)}")
    for name, f in known.items():
        if f.default is MISSING and f.default_factory is MISSING and name not in table:
            raise SceneError(f"{label}: missing required field {name!r}")
    kwargs = dict(table)
    for key in ("nodes", "table", "point", "axis", "shift_x", "shift_y", "range", "prior"):
        if key in kwargs and isinstance(kwargs[key], list):
            kwargs[key] = tuple(tuple(r) if isinstance(r, list) else r for r in kwargs[key])
    for key in ("lower", "upper"):
        if key in kwargs and isinstance(kwargs[key], str) and kwargs[key] in ("inf", "-inf"):
            kwargs[key] = float(kwargs[key])
    for key in kwargs:
        if known[key].type == "str" and not isinstance(kwargs[key], str):  # text fields: name, node, kind, ...
            raise SceneError(f"{label}.{key}: expected a string, got {kwargs[key]!r} ({type(kwargs[key]).__name__})")
    try:
        return cls(**kwargs)
    except SceneError as exc:
        if exc.field is None:
            raise SceneError(f"{label}: {exc.reason}") from None
        raise SceneError(f"{label}.{exc.field}: {exc.reason}") from None


def scene_from_dict(data: dict[str, Any]) -> Scene:
    """Build a :class:`Scene` from the nested dict of a parsed TOML file."""
    if not isinstance(data, dict):
        raise SceneError(f"scene: expected a table, got {type(data).__name__}")
    for key in data:
        if key not in _TOP_KEYS:
            raise SceneError(f"{key}: unknown top-level field {key!r}; expected some of {sorted(_TOP_KEYS)}")
    if "name" not in data:
        raise SceneError("name: missing required top-level field 'name' (the scene's name)")
    if "nodes" not in data:
        raise SceneError("nodes: missing required field 'nodes' (a list of [[nodes]] tables)")
    kwargs: dict[str, Any] = {"name": data["name"]}
    for key, cls in _LISTS.items():
        items = data.get(key, [])
        if not isinstance(items, list):  # e.g. [beams] instead of [[beams]]
            raise SceneError(f"{key}: expected a list of [[{key}]] tables, got {type(items).__name__}")
        kwargs[key] = tuple(_build(cls, f"{key}[{i}]", t) for i, t in enumerate(items))
    if "gravity" in data:
        kwargs["gravity"] = data["gravity"]
    if "run" in data:
        kwargs["run"] = _build(RunSettings, "run", data["run"])
    return Scene(**kwargs)


# -- writing ---------------------------------------------------------------------------------
def _toml_char(c: str) -> str:
    """One character of a TOML basic string, escaped if needed."""
    if c in ('"', "\\"):
        return "\\" + c
    if c < " " or c == "\x7f":
        return f"\\u{ord(c):04x}"
    return c


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return '"' + "".join(_toml_char(c) for c in v) + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} to TOML")


def _table_lines(obj: Any) -> list[str]:
    lines = []
    for f in fields(obj):
        v = getattr(obj, f.name)
        if v is None or (f.default is not MISSING and v == f.default and f.name != "kind"):
            continue
        if isinstance(obj, Parameter) and f.name == "lower" and v == Parameter(obj.name, obj.target).lower:
            continue  # the default bound of this target
        lines.append(f"{f.name} = {_toml_value(v)}")
    return lines


def dumps_scene(scene: Scene) -> str:
    """The scene as TOML text; ``loads_scene(dumps_scene(s)) == s``."""
    out = [f"name = {_toml_value(scene.name)}", f"gravity = {_toml_value(scene.gravity)}", "", "[run]"]
    out += [f"{f.name} = {_toml_value(getattr(scene.run, f.name))}" for f in fields(scene.run)]
    for key in _LISTS:
        for item in getattr(scene, key):
            out += ["", f"[[{key}]]", *_table_lines(item)]
    return "\n".join(out) + "\n"


def save_scene(scene: Scene, path: str | os.PathLike[str]) -> Path:
    """Write the scene to a TOML file atomically (temporary file, then rename)."""
    from casflex.results import atomic_write_text

    return atomic_write_text(Path(path), dumps_scene(scene))
