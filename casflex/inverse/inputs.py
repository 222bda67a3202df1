"""Everything inverse dynamics takes from the user, read and checked before the marker fit.

:func:`prepare` reads the trial (markers, force plates) and decides every refusal that the inputs alone
decide, so that a wrong option or a corrupted file costs a second, not a marker fit over the whole trial
(a minute on 100k frames): the scene's markers and plates, the window, evenly spaced frames (filtered or
not: the rates are differences on an even grid), markers a body can produce (:mod:`casflex.lab.checks`:
no jumps of a metre in a frame, no header whose units lie), the cut-off against both the markers' and the
plates' sampling, each plate's table covering the window, its missing samples (short gaps filled and
reported, long ones refused), each plate against the body (:mod:`casflex.lab.plate_checks`: one node a plate,
no pull, a stance, no one-sample spike), and the memory the run needs. What it changed in the data is in
``warnings`` (also in the report): the result says it, and the command prints it on stderr.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field

import numpy as np

from casflex.inverse.built import inverse_scene, inverse_tree, osim_scene
from casflex.inverse.heading import heading_line
from casflex.inverse.options import Bands, Filter, Fit, Flexible, Trial
from casflex.inverse.plates import Plate, model_weight, plate_from_table
from casflex.inverse.tree import KinematicTree
from casflex.lab.lowpass import check_cutoff, even_times
from casflex.model import Model

__all__ = ["InverseInputs", "prepare", "inverse_model", "read_markers", "weighted"]

#: The fewest frames an inverse takes (the filter's padding and the end differences need them).
MIN_FRAMES = 10
#: s: the widest step between frames (1 Hz): motion capture records at 50-200 Hz, OpenSim's IK writes its frames'
#: times; frames further apart are times in another unit (ms) and would give rates a thousand times too small.
MAX_STEP = 1.0
#: Bytes a frame of the inverse needs per value of its result (:func:`_memory` counts the values), with the
#: copies made while the result is assembled and written: ``casflex inverse hamner_leg --out loads.csv`` on
#: 2e4 and 1e5 frames peaked at 122 and 362 MB (/usr/bin/time -v), 3.0 kB a frame of 136 values, 22.6 bytes
#: a value (the reading of the text included); 32 gives that a 40 % margin.
BYTES_PER_VALUE = 32


@dataclass(frozen=True, kw_only=True)
class InverseInputs:
    """The checked inputs of one inverse run: ``model`` and its ``tree``, the frames ``t`` (n,) s on an even
    grid, the scene's markers ``y`` (n, 2 m) m in the plane (NaN where missing; (n, 0) where the coordinates
    ``z`` (n, n_z) m, rad were given instead: no marker fit), the ``plates``, the ``filter`` and the ``fit``'s
    limits (:mod:`casflex.inverse.options`), ``settings`` (what was asked), ``report`` (what was done to the data,
    a line each) and ``warnings`` (what changed the data)."""

    model: Model
    tree: KinematicTree
    t: np.ndarray
    y: np.ndarray
    labels: tuple[str, ...]
    plates: tuple[Plate, ...]
    filter: Filter
    fit: Fit
    settings: dict
    report: tuple[str, ...] = ()
    warnings: tuple[str, ...] = field(default=())
    z: np.ndarray | None = None  # the tree's coordinates (n, n_z) where they were given instead of markers
    band_spec: object = None  # the bands asked (casflex.inverse.bands.BandSpec), None: none

    @property
    def cutoff(self) -> float | None:
        """The coordinates' cut-off, Hz (None: unfiltered)."""
        return self.filter.cutoff


def inverse_model(scene, root: str | None = None) -> Model:
    """The model inverse dynamics drives: the scene without the supports of its root (default: its
    first node), which the root's driver replaces (they would fix what the data moves). A support on
    another node is refused in one line: the data, not the scene, say where the segments go
    (:func:`casflex.inverse.built.inverse_scene`). A new model each call; :func:`prepare` takes the
    one :func:`casflex.inverse.built.inverse_tree` keeps."""
    from casflex.model import assemble

    return assemble(inverse_scene(scene, root))


def _c3d(markers) -> bool:
    """Whether ``markers`` is the path of a C3D file (whose plates a trial takes where it names no grf)."""
    return isinstance(markers, (str, os.PathLike)) and os.fspath(markers).lower().endswith(".c3d")


def read_markers(path, *, plates: bool = False):
    """(markers, plates or None) of a .trc or .c3d file (a C3D's plates read only when ``plates``)."""
    from casflex.lab import read_c3d, read_trc

    if os.fspath(path).lower().endswith(".c3d"):
        return read_c3d(path, plates=plates)
    return read_trc(path), None


def _trial(markers, grf, need_plates: bool):
    """(LabMarkers or None, plates' LabTable or None) from what the caller gave: objects, or .trc/.c3d and
    .mot/.sto/.c3d paths (the markers' own C3D again for its plates); markers None where coordinates are
    given. ValueError when plates are needed and the file has none."""
    from casflex.lab import LabMarkers, LabTable, read_sto

    same = grf is not None and markers is not None and not isinstance(grf, LabTable) and not isinstance(
        markers, LabMarkers) and os.fspath(grf) == os.fspath(markers)
    lab, table = (markers, None) if markers is None or isinstance(markers, LabMarkers) else read_markers(
        markers, plates=same)
    if isinstance(grf, LabTable):
        table = grf
    elif grf is not None and not same:
        table = read_markers(grf, plates=True)[1] if os.fspath(grf).lower().endswith(".c3d") else read_sto(grf)
    if need_plates and table is None:
        raise ValueError(f"{grf}: the file has no force plates")
    return lab, table


def _external_loads(grf, plates) -> tuple[object, dict | str]:
    """(the ground reactions' file or table, plates node -> prefix): an OpenSim ExternalLoads (or ID setup)
    file given as ``grf`` names both (:func:`casflex.lab.setups.read_external_loads`; its bodies are the
    nodes of a model read from .osim). A plate whose identifiers are not ``<prefix>force_v`` ... (e.g.
    ``ground_force_r_v``, ``ground_force_r_p``, ``ground_torque_r_``) has its columns copied under the prefix
    ``<body>_`` (``<body>_<k>_`` for a body's k-th plate: several on one body are summed, as OpenSim sums them)."""
    from casflex.lab import LabTable, read_sto

    if grf is None or isinstance(grf, LabTable) or not os.fspath(grf).lower().endswith(".xml"):
        return grf, plates if isinstance(plates, str) else dict(plates or {})
    from casflex.lab.setups import read_external_loads
    from casflex.scene.items import node_name

    ext = read_external_loads(grf)  # plates given with it: refused by Trial
    prefixes = {body: [ext.prefix(ident) for ident in idents] for body, idents in ext.plates.items()}
    if any(None in ps for ps in prefixes.values()):
        table = read_sto(ext.datafile)
        names, columns = list(table.names), [table.values]
        for body, idents in ext.plates.items():
            for k, (ident, p) in enumerate(zip(idents, prefixes[body], strict=True)):
                if p is not None:
                    continue
                prefixes[body][k] = alias = f"{node_name(body)}_{k + 1}_" if len(idents) > 1 else f"{node_name(body)}_"
                for stem, new in zip(ident, ("force_v", "force_p", "torque_"), strict=True):
                    for axis in "xyz" if stem else ():
                        columns.append(table.column(f"{stem}{axis}")[:, None])
                        names.append(f"{alias}{new}{axis}")
        source = dataclasses.replace(table, names=tuple(names), values=np.hstack(columns))
    else:
        source = ext.datafile
    return source, {node_name(body): ps[0] if len(ps) == 1 else ps for body, ps in prefixes.items()}


def _setup_unapplied(grf, filter: Filter | None, t: np.ndarray) -> list[str]:
    """The lines that say what an inverse dynamics setup given as ``grf`` (or an inverse kinematics setup given as
    the tasks, ``filter`` None) asks and is not done: its coordinates' cut-off other than ``filter``'s, its time
    range other than the trial's frames ``t`` (s) by more than a frame (casflex takes the plates or the tasks from
    it; the filter and the window are the options': --cutoff, --t-start, --t-end)."""
    from casflex.lab.setups import tool_settings

    if grf is None or not isinstance(grf, str | os.PathLike) or not os.fspath(grf).lower().endswith(".xml"):
        return []
    setup = tool_settings(grf)
    lines = []
    if filter is not None and "cutoff" in setup and setup["cutoff"] != filter.cutoff:
        want = f"{setup['cutoff']:g} Hz" if setup["cutoff"] else "-1 (unfiltered)"
        how = f"--cutoff {setup['cutoff']:g}" if setup["cutoff"] else "--no-filter"
        have = f"at {filter.cutoff:g} Hz" if filter.cutoff else "not at all"
        lines.append(f"{os.fspath(grf)}: its lowpass_cutoff_frequency_for_coordinates {want} is not applied: the "
                     f"coordinates are filtered {have} ({how}, with --match opensim for OpenSim's filter, does as the "
                     "setup says)")
    if "time_range" in setup:
        (t0, t1), step = setup["time_range"], float(t[1] - t[0]) if t.size > 1 else 0.0
        if max(t0, float(t[0])) - float(t[0]) > step or float(t[-1]) - min(t1, float(t[-1])) > step:
            lines.append(f"{os.fspath(grf)}: its time_range {t0:g}-{t1:g} s is not applied: the loads cover "
                         f"{float(t[0]):g}-{float(t[-1]):g} s (--t-start {t0:g} --t-end {t1:g} does as the setup says)")
    return lines


def _from_markers(model: Model, tree: KinematicTree, lab, plane, t_start, t_end):
    """(t, the scene markers' channels y (n, 2 m), their labels, the rate, warnings) of a marker trial."""
    if not model.scene.markers:
        raise ValueError("scene: it has no [[markers]] to fit to the trial")
    keep = _window(lab.t, t_start, t_end, lab.source)
    lab, absent = _with_absent(model, lab)
    ms, labels = _scene_markers(model, tree, lab, plane, keep, absent)
    t = _even_frames(ms.t[keep], lab.rate, lab.source)
    unseen = [lb for lb, xy in zip(labels, np.moveaxis(ms.q[keep].reshape(t.size, -1, 2), 1, 0), strict=True)
              if not np.isfinite(xy).all(axis=1).any() and lb not in absent]
    notes = [f"{lab.source}: the scene's markers {list(absent)} are not in the trial: left out of the fit (as "
             "OpenSim's IK leaves out a marker the trial lacks)"] if absent else []
    notes += [f"{lab.source}: markers {unseen} are not seen in the window; the pose is fitted without them"] \
        if unseen else []
    return t, ms.q[keep], labels, lab.rate, notes


def _with_absent(model: Model, lab) -> tuple[object, tuple[str, ...]]:
    """(the trial's markers with a column of NaN for each scene marker it lacks entirely, those labels):
    such a marker is left out of the fit as one never seen, where the others decide the pose (else
    :func:`casflex.inverse.fit.check_decided` refuses, naming the segment)."""
    absent = tuple(dict.fromkeys(m.lab_label for m in model.scene.markers if m.lab_label not in lab.labels))
    if not absent:
        return lab, ()
    xyz = np.concatenate([lab.xyz, np.full((lab.t.size, len(absent), 3), np.nan)], axis=1)
    return dataclasses.replace(lab, labels=tuple(lab.labels) + absent, xyz=xyz), absent


def _from_coordinates(model: Model, tree: KinematicTree, coordinates, t_start, t_end):
    """(t, the tree's coordinates z (n, n_z), the report's lines, the source) of a coordinates table."""
    from casflex.inverse.given import coordinates_z, read_coordinates

    table = read_coordinates(coordinates)
    keep = _window(table.t, t_start, t_end, table.source)
    z, report = coordinates_z(model.scene, tree, table)
    # a .mot says no rate, and OpenSim's IK writes the frames' times rounded to the ms: the slope of 44 such
    # times is 2e-5 off 1/60 s; a whole number of Hz that puts every frame within a tenth of a step is the rate
    rate = float(table.header.get("DataRate") or round(1.0 / np.polyfit(np.arange(keep.sum()), table.t[keep], 1)[0]))
    return _even_frames(table.t[keep], rate, table.source), z[keep], report, table.source


def _window(t: np.ndarray, t_start: float | None, t_end: float | None, source: str) -> np.ndarray:
    lo = t[0] if t_start is None else t_start
    hi = t[-1] if t_end is None else t_end
    keep = (t >= lo - 1e-9) & (t <= hi + 1e-9)
    if keep.sum() < MIN_FRAMES:
        raise ValueError(f"t_start, t_end: the window {lo:g}..{hi:g} s holds {int(keep.sum())} frames of the trial "
                         f"{source} ({t[0]:g}..{t[-1]:g} s); at least {MIN_FRAMES} are needed")
    return keep


def _even_frames(t: np.ndarray, rate: float, source: str) -> np.ndarray:
    """The frames' times on their even grid (:func:`casflex.lab.lowpass.even_times`); ValueError when they are
    not evenly spaced: the rates are differences on an even grid, filtered or not."""
    grid = even_times(t, rate if np.isfinite(rate) else None)
    h = np.diff(grid)
    if np.median(h) > MAX_STEP:  # no lab records motion that slowly: times in ms read as s (a 1000 s trial)
        raise ValueError(f"{source}: the frames are {np.median(h):.4g} s apart ({1.0 / np.median(h):.3g} Hz; the "
                         f"trial runs {t[-1] - t[0]:.4g} s): times in ms, not s? give the times in seconds")
    if np.ptp(h) > 1e-6 * h.mean():
        step = np.median(h)
        dev = np.abs(h - step)
        k = int(np.argmax(dev > 0.1 * step) if (dev > 0.1 * step).any() else np.argmax(dev)) + 1
        raise ValueError(f"{source}: frames must be evenly spaced (the velocities and accelerations are differences "
                         f"on an even grid): t = {t[k]:g} s follows {t[k - 1]:g} s, the frames are {step:.3g} s apart "
                         "elsewhere; resample the trial")
    return grid


def _scene_markers(model: Model, tree: KinematicTree, lab, plane, keep_frames, absent: tuple[str, ...] = ()):
    """(scene markers' channels in the plane (a MeasurementSet), their lab labels), checked first
    (:mod:`casflex.lab.checks`): seen in the window, as far apart as the scene's, no sample no body makes."""
    from casflex.inverse.fit import check_decided
    from casflex.lab import markers_in_plane
    from casflex.lab.checks import check_markers, check_scale

    names = {m.name: m.lab_label for m in model.scene.markers}
    labels = tuple(names.values())
    with np.errstate(invalid="ignore", over="ignore"):  # absurd samples are check_markers' to name
        xy = np.stack([lab.marker(lb)[keep_frames] for lb in labels], axis=1) @ plane.matrix.T
    if not np.isfinite(xy).all(axis=2).any():
        raise ValueError(f"{lab.source}: none of the scene's markers {list(labels)} is seen in the window")
    scene_xy = np.array([[m.x, m.y] for m in model.scene.markers])
    check_scale(lab.source, lab.units, scene_xy, xy, [tree.cluster[i] for i in tree.marker_nodes])
    check_markers(lab, labels, keep_frames)
    check_decided(tree, xy.reshape(xy.shape[0], -1), labels, lab.source, absent)
    return markers_in_plane(lab, names, plane), labels


def _memory(model: Model, tree: KinematicTree, t: np.ndarray, n_markers: int, dt: float | None) -> None:
    """ValueError when the run's result would not fit in the memory available (the bound of
    :data:`BYTES_PER_VALUE`); with flexible segments, also the HHT steps' (``dt`` s, default the scene's:
    :func:`casflex.simulate.check_memory`)."""
    from casflex.results import format_bytes, memory_available

    n = t.size
    if model.n_con != model.n_dof - tree.n and n > 1:
        from casflex.simulate import check_memory  # here: the simulator's import (0.05 s) only where it would run

        h = float(t[1] - t[0])
        sub = max(1, int(np.ceil(h / (model.scene.run.dt if dt is None else dt) - 1e-9)))
        check_memory(model, (n - 1) * sub, h / sub, names=("t_start, t_end", "dt"))
    values = 3 * n_markers + 4 * tree.n + 4 * model.n_dof + model.n_con + len(model.output_names) + 4
    need, avail = BYTES_PER_VALUE * n * values, memory_available()
    if avail is not None and need > avail:
        raise ValueError(f"t_start, t_end: {n:,} frames of {values} values each need about {format_bytes(need)} of "
                         f"memory and {format_bytes(avail)} are available; take a shorter window")


def _one_node_a_plate(table, pairs: list[tuple[str, str]]) -> None:
    """ValueError naming a plate given to two nodes (``pairs``: (node, prefix) over the whole trial): its load would
    be counted twice."""
    from casflex.lab.filtering import _plate_columns

    seen: dict[str, str] = {}
    for node, prefix in pairs:
        p = _plate_columns(table, prefix)
        if p in seen:
            raise ValueError(f"plates: {table.source}: plate {p!r} is given to both {seen[p]!r} and {node!r}: its "
                             "load would be counted twice; give each plate to the one foot that stands on it, or "
                             "plates=\"auto\" (each contact to the foot over it)")
        seen[p] = node


def _unapplied(model: Model, lab, table, pairs: list[tuple[str, str]], plane, window: tuple[float, float]
               ) -> list[str]:
    """Warnings (lines starting "plate '") for the table's plates that ``pairs`` (node, prefix) apply to no node
    but that a foot of the scene stands on inside the ``window`` (s) by the trial's markers ``lab``
    (:func:`casflex.inverse.contacts.plate_contacts`; a plate under no foot of the scene, e.g. a leg model's other
    foot's, says nothing): its load is left out of that foot's ground reaction (a stance straddling it and a plate
    that is applied)."""
    from casflex.inverse.contacts import plate_contacts, plate_prefixes, span_text
    from casflex.lab.filtering import _plate_columns

    if lab is None:
        return []
    given = {_plate_columns(table, p) for _, p in pairs}
    lines = []
    for p in (p for p in plate_prefixes(table) if p not in given):
        try:
            found = plate_contacts(model.scene, lab, table, plane, [p])
        except ValueError:  # no foot of the scene over it, or a record plate_contacts refuses: not this check's
            continue
        on = [c for c in found if (c.strike is None or c.strike <= window[1]) and (c.off is None or c.off >= window[0])]
        if on:
            span = span_text(on[0].strike, on[0].off)
            lines.append(f"plate {p!r} ({table.source}): {on[0].foot} stands on it {span} "
                         f"inside the window, but it is applied to no node: its load ({on[0].peak:.0f} N) is left out "
                         f"of {on[0].foot}'s ground reaction; apply it (--plate {on[0].foot}={p}, a node may take two "
                         "plates) or --plate auto")
    return lines


def _shares(model: Model, lab, table, plates, plane, window: tuple[float, float], reach: float = 0.0
            ) -> tuple[list[tuple[str, str, tuple | None]], dict, list[str]]:
    """([(prefix, node, spans or None: all its samples)], the settings' plates, report lines): the trial's
    ``plates`` resolved. A mapping node -> prefix (or prefixes): each plate on its node over the whole trial (a
    plate given to two nodes refused); "auto" (the trial's markers ``lab`` given): each plate's contacts to the foot
    over each (:func:`casflex.inverse.contacts.plate_shares`), a foot's share of a plate kept where one of its
    contacts on it falls in the ``window`` (s) widened by ``reach`` (s) on each side: the plates' filter spreads a
    stance's load that far (two periods of its cut-off: Hamner's run cut to 0.7-1.05 s, the right stance ending at
    0.665 s, gave the ankle moment 14.8 N m off at 0.7 s with the share left out)."""
    from casflex.inverse.contacts import AUTO, plate_contacts, plate_prefixes, plate_shares

    if not (isinstance(plates, str) and plates == AUTO):
        pairs = [(node, p) for node, v in plates.items() for p in ([v] if isinstance(v, str) else v)]
        _one_node_a_plate(table, pairs)
        return [(p, node, None) for node, p in pairs], plates, _unapplied(model, lab, table, pairs, plane, window)
    found = plate_contacts(model.scene, lab, table, plane, plate_prefixes(table))
    lo, hi = window[0] - reach, window[1] + reach
    inside = {(c.plate, c.foot) for c in found
              if (c.strike is None or c.strike <= hi) and (c.off is None or c.off >= lo)}
    out, lines, said = [], [], {}
    for (p, node), spans in plate_shares(found).items():
        theirs = [c for c in found if c.plate == p and c.foot == node]
        when = ", ".join(f"{'start' if c.strike is None else f'{c.strike:.3f}'}-"
                         f"{'end' if c.off is None else f'{c.off:.3f}'} s" for c in theirs)
        if (p, node) in inside:
            out.append((p, node, spans))
            said.setdefault(node, []).append(p)
        lines.append(f"plate {p!r} -> {node} (plates=\"auto\"): contact(s) {when}"
                     + ("" if (p, node) in inside else ", none in the window: left out"))
    lines += [f"plate {p!r}: no contact above 20 N: left out" for p in plate_prefixes(table)
              if p not in {c.plate for c in found}]
    return out, {n: ps[0] if len(ps) == 1 else ps for n, ps in said.items()}, lines


def _osim_scene(scene) -> tuple[object, list[str]]:
    """(the scene, warnings): an OpenSim model file read with what it holds that the scene leaves out (its
    constraints: :func:`casflex.scene.from_osim.scene_from_osim`); anything else as given."""
    from casflex.scene import Scene

    if isinstance(scene, Scene) or not os.fspath(scene).lower().endswith(".osim"):
        return scene, []
    made, warnings = osim_scene(scene)  # read once: the next run of the same file takes it from the cache
    return made, list(warnings)


def weighted(scene, tasks) -> tuple[object, list[str]]:
    """(the scene with its markers weighted by ``tasks``, warnings): an OpenSim IK task set or setup file
    (:func:`casflex.lab.setups.read_tasks`) or a dict label -> weight. As OpenSim's IK, a scene marker with no
    task (or weight 0) is left out, and the trial need not have it; a task naming no scene marker, or a
    coordinate task, is said."""
    from casflex.lab.setups import MarkerTasks, read_tasks
    from casflex.scene import Scene
    from casflex.scene.io import load_scene

    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    t = tasks if isinstance(tasks, MarkerTasks) else (
        MarkerTasks("tasks", {str(k): float(v) for k, v in tasks.items()}) if isinstance(tasks, dict)
        else read_tasks(tasks))
    label = {m.name: m.lab_label for m in scene.markers}
    markers = tuple(dataclasses.replace(m, weight=t.weights[label[m.name]]) for m in scene.markers
                    if t.weights.get(label[m.name], 0.0) > 0)  # as OpenSim's IK: the trial need not have the others
    notes = []
    left = [label[m.name] for m in scene.markers if t.weights.get(label[m.name], 0.0) <= 0]
    if left:
        notes.append(f"{t.source}: the scene's markers {left} have no task or a weight of 0: left out")
    if not markers:
        raise ValueError(f"{t.source}: no task weights any of the scene's markers {list(label.values())}")
    unknown = sorted(set(t.weights) - set(label.values()))
    if unknown:
        notes.append(f"{t.source}: tasks of markers the scene does not have, ignored: {unknown}")
    if t.coordinate_tasks:
        notes.append(f"{t.source}: coordinate tasks {list(t.coordinate_tasks)} are not taken (markers only)")
    return dataclasses.replace(scene, markers=markers), notes


def _marker_set(scene, lab):
    """(the scene with the segments the trial's marker set leaves out locked, the trial with the scene's markers of
    weight 0 it lacks as never seen, the lines saying what was locked): a whole-body model on lower-body markers
    (:func:`casflex.inverse.locking.lock_unmarked`); the joint centres a built-in model carries with weight 0 for its
    calibration (:mod:`casflex.lab.marker_sets`) are not the marker fit's, and a trial need not have them."""
    from casflex.inverse.locking import lock_unmarked

    scene, lines = lock_unmarked(scene, lab.labels, lab.source)
    absent = tuple(dict.fromkeys(m.lab_label for m in scene.markers if m.weight == 0 and m.lab_label not in lab.labels))
    if absent:
        lab = dataclasses.replace(lab, labels=lab.labels + absent, xyz=np.concatenate(
            [lab.xyz, np.full((lab.t.size, len(absent), 3), np.nan)], axis=1))
    return scene, lab, lines


def prepare(scene, trial: Trial, *, filter: Filter | None = None, fit: Fit | None = None, bands: Bands | None = None,
            flexible: Flexible | None = None) -> InverseInputs:
    """The inputs of :func:`casflex.inverse.inverse_dynamics` (its parameters; None: the object's defaults), read and
    checked (module docstring); the bands asked (:func:`casflex.inverse.bands.band_spec`) checked before the trial
    is read. ValueError in one line naming the option, file, marker or plate otherwise."""
    from casflex.inverse.bands import band_spec
    from casflex.scene import Scene
    from casflex.scene.io import load_scene

    filter, fit, bands, flexible = filter or Filter(), fit or Fit(), bands or Bands(), flexible or Flexible()

    pl = trial.plane
    scene, task_notes = _osim_scene(scene)
    if trial.tasks is not None:
        scene, notes = weighted(scene, trial.tasks)
        task_notes += notes
    grf, plates = _external_loads(trial.grf, trial.plates)
    if grf is None and plates and _c3d(trial.markers):  # a C3D trial's plates: its own
        grf = trial.markers
    scene = scene if isinstance(scene, Scene) else load_scene(scene)
    for node in plates if not isinstance(plates, str) else ():
        if node not in (names := [n.name for n in scene.nodes]):
            raise ValueError(f"plates: no node {node!r} in the scene; nodes are {names}")
    tree = inverse_tree(scene, trial.root)
    model = tree.model
    spec = band_spec(model, tree, bands, given=trial.given, n_markers=sum(m.weight > 0 for m in scene.markers))
    lab, table = _trial(trial.markers, grf, bool(plates))  # the bands checked before: a bad band costs no reading
    if lab is not None and not trial.given:
        scene, lab, locked = _marker_set(scene, lab)
        task_notes += locked
        if locked:  # a segment the trial records no marker of, locked: the model and the bands' spec again
            tree = inverse_tree(scene, trial.root)
            model = tree.model
            spec = band_spec(model, tree, bands, given=trial.given,
                             n_markers=sum(m.weight > 0 for m in scene.markers))
    if not trial.given:
        t, y, labels, rate, notes = _from_markers(model, tree, lab, pl, trial.t_start, trial.t_end)  # units checked
        heading = heading_line(scene, lab, f"{pl.x},{pl.y}", tree.root, trial.t_start, trial.t_end)  # before the fit
        z, report, source = None, [heading], lab.source
    else:
        t, z, report, source = _from_coordinates(model, tree, trial.coordinates, trial.t_start, trial.t_end)
        y, labels, rate, notes = np.zeros((t.size, 0)), (), 1.0 / float(t[1] - t[0]), []
    cutoff = filter.cutoff
    check_cutoff(cutoff, t, "markers" if z is None else "coordinates")
    warnings = [*task_notes, *notes, *_setup_unapplied(trial.grf, filter, t), *_setup_unapplied(trial.tasks, None, t)]
    plate_list = []
    fc = filter.plates
    window = (float(t[0]), float(t[-1]))
    reach = 2.0 / fc if fc else 0.0  # s: how far the plates' filter spreads a load (two periods of its cut-off)
    shares, plates, share_report = _shares(model, lab, table, plates, pl, window, reach) if plates else \
        ([], plates, [])
    unapplied = [ln for ln in share_report if "applied to no node" in ln]  # a warning (in the report too, once)
    share_report, warnings = [ln for ln in share_report if ln not in unapplied], warnings + unapplied
    for prefix, node, spans in shares:
        plate = plate_from_table(table, prefix, node, pl, fc, window=window, rate=rate, trial=source,
                                 weight=model_weight(model), spans=spans)
        plate_list.append(plate)
        warnings += [n for n in plate.notes if n not in warnings]  # a plate shared by two feet: said once
    _memory(model, tree, t, len(labels), flexible.dt)
    settings = {"plane": f"{pl.x},{pl.y}", "cutoff_hz": cutoff, "filter": filter.kind,
                "cutoff_plates_hz": fc, "root": tree.root, "plates": plates,
                "moments": [f"{h}.moment" for h in tree.hinges], "weights": {lb: m.weight for lb, m in zip(
                    labels, model.scene.markers, strict=False)}, "source": source or "",
                "scene": model.scene.name, "max_misfit_m": fit.misfit, "given": z is not None}
    return InverseInputs(model=model, tree=tree, t=t, y=y, labels=labels, plates=tuple(plate_list), filter=filter,
                         fit=fit, settings=settings, report=tuple(report + share_report + warnings),
                         warnings=tuple(warnings), z=z,
                         band_spec=spec)
