"""What inverse dynamics builds from the scene alone, built once: the model it drives (the scene without its root's
supports), the model's kinematic tree and the tree's CasADi Functions (``forward``, ``marker_fit``, and what other
modules build of them).

Built from a scene, they cost about 0.1 s of a study's 0.3 s trial on Hamner's 1 s run (the functions' symbolic
build; the model's assembly more in a new process), the same for every trial of a subject. So:

- in a process, they are kept by the scene's content and the root (:func:`inverse_tree`): the scene is a frozen
  dataclass compared field by field, so two subjects whose scenes differ in one mass or one length never share a
  model, and the runs of one subject (a study worker's trials, their calibrated scene read again each time)
  share one; a tree shared so keeps what other modules build from it (:meth:`KinematicTree.built
  <casflex.inverse.tree.KinematicTree.built>`: the marker fit mapped over frames, the rigid inverse's frame);
- across processes, the model and the :data:`FUNCTIONS` are kept in ``$CASFLEX_CACHE``
  (:func:`casflex.codegen.store_built`; ``casflex cache`` counts them, ``--clear`` removes them) under a key of the
  scene's content (its ``repr``: every field, the floats to the last bit), the root, the source of the modules that
  build them (:data:`SOURCES`: a changed line of casflex's model or elements is a new entry) and casflex's, CasADi's,
  numpy's and Python's versions, the machine and its C library (:func:`casflex.codegen.built_key`). Loading the
  entry (0.02 s) replaces the model's assembly and the functions' build (0.13-0.15 s in a new process); a damaged
  entry is built again and replaced. An OpenSim model's planar scene is kept so too, by its file's bytes
  (:func:`osim_scene`).

The Functions loaded are CasADi's own serialisation of those built: the same operations on the same constants, the
same numbers to the last bit (tests/test_inverse_built.py).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import os
import stat
from pathlib import Path

from casflex.inverse.tree import KinematicTree, kinematic_tree

__all__ = ["inverse_scene", "inverse_tree", "osim_scene", "SOURCES"]

_PACKAGE = Path(__file__).resolve().parents[1]
#: The code that builds what :func:`inverse_tree` keeps (folders: every module in them), relative to casflex/: its
#: bytes are part of the cache key.
SOURCES = ("model", "elements", "scene", "inverse/tree.py", "inverse/built.py")
#: The tree's Functions kept on disk with the model (``marker_fit`` where the scene has markers): those that load
#: faster than they build (Hamner's planar model: forward 1.6 ms against 44, marker_fit 6.4 against 36; rates 6.3
#: against 4.1 ms and the maps over frames, 31 ms against 1.4 at 64 frames, are built).
FUNCTIONS = ("forward", "marker_fit")


def inverse_scene(scene, root: str | None = None):
    """The scene inverse dynamics drives: ``scene`` (a Scene, or a scene name or path, loaded) without the supports of
    its root (default: its first node), which the root's driver replaces (they would fix what the data moves). A
    support on another node is refused in one line: the data, not the scene, say where the segments go."""
    from casflex.scene import Scene

    if not isinstance(scene, Scene):
        from casflex.scene.io import load_scene

        scene = load_scene(scene)
    root = scene.nodes[0].name if root is None else root
    for s in scene.supports:
        if s.node != root:
            raise ValueError(f"support {s.name!r}: inverse dynamics drives the scene from its root {root!r} only; "
                             "remove the support or make its node the root (--root)")
    return dataclasses.replace(scene, supports=()) if scene.supports else scene


def inverse_tree(scene, root: str | None = None) -> KinematicTree:
    """The kinematic tree (:func:`casflex.inverse.tree.kinematic_tree`) of the model of :func:`inverse_scene`
    ``(scene, root)``, its Functions built, kept in this process and on disk (module docstring). ValueError in one
    line where the scene cannot be driven so (a support off the root, a tree the hinges do not make)."""
    scene = inverse_scene(scene, root)
    root = scene.nodes[0].name if root is None else root
    try:
        hash(scene)
    except TypeError:  # a scene holding an unhashable value: its own tree
        return _tree(scene, root)
    return _kept(scene, root)


@functools.lru_cache(maxsize=16)
def _kept(scene, root: str) -> KinematicTree:
    return _tree(scene, root)


def _tree(scene, root: str) -> KinematicTree:
    """The tree of ``scene`` (its root's supports off) from the disk cache, else built and stored there."""
    from casflex.codegen import built_key, load_built, store_built

    code = _source_digest()
    key = built_key(repr(scene), root, code or "", _version())
    entry = load_built("inverse", key) if code else None
    if _whole(entry) and entry["model"].scene == scene:  # the scene compared too: a key's collision builds anew
        tree = kinematic_tree(entry["model"], root)
        for name in FUNCTIONS:
            if name in entry:  # the cached properties, as KinematicTree would build them
                tree.__dict__[name] = entry[name]
        return tree
    from casflex.model import assemble

    tree = kinematic_tree(assemble(scene), root)
    entry = {"model": tree.model, "forward": tree.forward}
    if scene.markers:
        entry["marker_fit"] = tree.marker_fit
    if code:
        store_built("inverse", key, entry)
    return tree


def osim_scene(path: str | os.PathLike[str]) -> tuple[object, tuple[str, ...]]:
    """(the planar scene, its warnings) of the OpenSim model file ``path``
    (:func:`casflex.scene.from_osim.scene_from_osim`: what the scene leaves out of the model), kept on disk by the
    file's bytes and the path as given (which the warnings name; module docstring): the next run of the same file
    loads them (1 ms) instead of reading the model (0.04 s) and importing its reader (0.04 s). A file changed while
    it was read is not kept."""
    from casflex.codegen import built_key, load_built, store_built

    source = os.fspath(path)
    digest, code = _file_digest(source), _source_digest()
    key = built_key(source, digest or "", code or "", _version())
    entry = load_built("osim", key) if digest and code else None
    if _scene_entry(entry):
        return entry
    from casflex.scene.from_osim import scene_from_osim

    made = scene_from_osim(source)
    out = (made.scene, tuple(made.warnings))
    if digest and code and _file_digest(source) == digest:
        store_built("osim", key, out)
    return out


#: bytes: a model file larger than this is read each time, not kept (a whole-body model with its muscles is a few
#: MiB; hashing a huge one would only delay the reader's refusal)
MAX_KEPT_FILE = 64 * 2**20


def _file_digest(path: str) -> str | None:
    """SHA-256 of the file's bytes, read in pieces; None (nothing kept) where it cannot be read, is no regular file
    (a pipe would block) or is larger than :data:`MAX_KEPT_FILE`: the reader then reads it, as without the cache."""
    h = hashlib.sha256()
    try:
        st = os.stat(path)
        if not stat.S_ISREG(st.st_mode) or st.st_size > MAX_KEPT_FILE:
            return None
        with open(path, "rb") as fh:
            while block := fh.read(1 << 20):
                h.update(block)
    except OSError:
        return None
    return h.hexdigest()


def _scene_entry(entry: object) -> bool:
    from casflex.scene import Scene

    return (isinstance(entry, tuple) and len(entry) == 2 and isinstance(entry[0], Scene)
            and isinstance(entry[1], tuple) and all(isinstance(w, str) for w in entry[1]))


def _whole(entry: object) -> bool:
    """Whether a loaded entry has what :func:`_tree` stores (an entry of another shape: built again)."""
    import casadi as ca

    from casflex.model import Model

    return (isinstance(entry, dict) and isinstance(entry.get("model"), Model)
            and isinstance(entry.get("forward"), ca.Function)
            and (not entry["model"].scene.markers or isinstance(entry.get("marker_fit"), ca.Function)))


def _version() -> str:
    from casflex import __version__

    return __version__


@functools.lru_cache(maxsize=1)
def _source_digest() -> str | None:
    """SHA-256 of the :data:`SOURCES`' bytes (each file's name with them): 1 ms, once per process; None where they
    cannot be read (an installation without its sources: nothing is then kept on disk, the code being unknown)."""
    h = hashlib.sha256()
    try:
        for part in SOURCES:
            path = _PACKAGE / part
            files = [path] if path.suffix == ".py" else sorted(
                Path(e.path) for e in os.scandir(path) if e.name.endswith(".py"))
            if not files:
                return None
            for f in files:
                h.update(f"{f.relative_to(_PACKAGE).as_posix()}\n".encode())
                h.update(f.read_bytes())
    except OSError:
        return None
    return h.hexdigest()
