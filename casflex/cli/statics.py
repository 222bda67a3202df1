"""``casflex static`` and ``casflex modes``: equilibrium, its stability, equilibrium paths and
small vibrations.

Stability warnings of the library (:class:`~casflex.statics.StabilityWarning`) are printed as
one line ``casflex: warning: ...`` on stderr; an unstable but converged equilibrium still exits 0.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import warnings
from collections.abc import Iterator

import numpy as np

from casflex.cli._base import OptionError, Outputs, integer, load_model, output_path, positive

#: How the command line spells the statics options (error messages name these, not Python's).
NAMES = {"steps": "--steps", "max_iter": "--max-iter", "tol": "--tol", "min_increment": "--min-increment",
         "seek": "--seek", "to_factor": "--to-factor", "max_points": "--max-points", "arc_length": "--arc-length"}
#: The statics options, their argparse destinations and defaults (None: the library's default).
_STATIC_OPTIONS = ("steps", "max_iter", "tol", "min_increment", "seek")
_PATH_OPTIONS = ("to_factor", "max_points", "arc_length", "monitor")


def _write_npz(path, **arrays) -> None:
    from casflex.results import atomic_write_bytes

    buf = io.BytesIO()
    np.savez(buf, **arrays)
    atomic_write_bytes(path, buf.getvalue())


def _fraction(text: str) -> float:
    """Option type: a number in (0, 1] (a share of the full load)."""
    v = positive("a share of the full load")(text)
    if v > 1.0:
        raise argparse.ArgumentTypeError(f"must be a share of the full load in (0, 1], got {text}")
    return v


@contextlib.contextmanager
def _warnings_as_lines(hint: str = "") -> Iterator[None]:
    """Print the library's stability warnings as one line each on stderr (``hint`` appended)."""
    from casflex.statics import StabilityWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", StabilityWarning)
        try:
            yield
        finally:
            for w in caught:
                if issubclass(w.category, StabilityWarning):
                    print(f"casflex: warning: {w.message}{hint}", file=sys.stderr)
                else:
                    warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)


def _settings(args: argparse.Namespace) -> dict:
    """The statics options given on the command line (the others keep the library's defaults)."""
    return {k: getattr(args, k) for k in _STATIC_OPTIONS if getattr(args, k, None) is not None}


def _check_combinations(args: argparse.Namespace, given: tuple[str, ...], needs: str) -> None:
    for k in given:
        if getattr(args, k, None) is not None:
            raise OptionError(f"{NAMES.get(k, '--' + k.replace('_', '-'))}: only with {needs}")


def _print_equilibrium(model, res) -> None:
    print(f"static equilibrium of {model.scene.name}: {res.iterations} iterations over "
          f"{len(res.load_factors)} load increment(s){f', {res.cuts} cut' if res.cuts else ''}")
    print(f"  {res.stability.describe()}")
    for left in res.left:
        print(f"  passed an unstable equilibrium at load factor {left.load_factor:.6g} (smallest tangent eigenvalue "
              f"{left.min_eigenvalue:.3g} of the largest) and left it along its unstable mode")
    for k, name in enumerate(model.node_names[:len(model.scene.nodes)]):
        print(f"  node {name:<6s} x = {res.q[3 * k]:11.6f} m  y = {res.q[3 * k + 1]:11.6f} m  "
              f"theta = {res.q[3 * k + 2]:10.6f} rad")
    for name, lam in zip(model.constraint_names, res.lam, strict=True):
        print(f"  reaction {name:<18s} {-lam:12.4f}")


def _monitor(model, args: argparse.Namespace) -> int | None:
    if args.monitor is None:
        return None
    try:
        return model.dof(args.monitor)
    except KeyError:
        raise OptionError(f"--monitor: unknown dof {args.monitor!r}; dofs are {list(model.dof_names)}") from None


def _print_path(model, path, monitor: int | None) -> int:
    """The table of (load factor, monitored dof, stability), critical points marked; returns the dof shown."""
    if monitor is None:  # the translation that moves most along the path
        rng = np.ptp(path.q, axis=0)
        rng[np.asarray(model.is_rotation)] = -1.0
        monitor = int(np.argmax(rng))
    name = model.dof_names[monitor]
    unit = "rad" if model.is_rotation[monitor] else "m"
    print(f"equilibrium path of {model.scene.name}: {path.message}; {path.iterations} iterations")
    print(f"  {'point':>5s} {'load factor':>14s} {name + ' (' + unit + ')':>16s}  stability")
    crit = {}
    for c in path.critical:
        crit.setdefault(c.after, []).append(c)
    for i, s in enumerate(path.load_factors):
        state = "stable" if path.stable[i] else (f"UNSTABLE ({path.negative[i]})" if path.negative[i] else "neutral")
        print(f"  {i:5d} {s:14.6g} {path.q[i, monitor]:16.8g}  {state}")
        for c in crit.get(i, []):
            print(f"  {'':5s} {c.load_factor:14.6g} {c.q[monitor]:16.8g}  <- {c.kind} point")
    return monitor


def cmd_static(args: argparse.Namespace, outputs: Outputs) -> int:
    from casflex.statics import equilibrium, equilibrium_path

    if args.path is None:
        _check_combinations(args, _PATH_OPTIONS, "--path")
    out = outputs.file("--out", args.out, (".npz",), "path" if args.path else "equilibrium") if args.out else None
    model = load_model(args.scene)
    names = np.array(model.dof_names), np.array(model.constraint_names)
    if args.path is not None:
        monitor = _monitor(model, args)
        kw = {k: getattr(args, k) for k in ("to_factor", "max_points", "arc_length") if getattr(args, k) is not None}
        with _warnings_as_lines():
            path = equilibrium_path(model, names=NAMES, **kw, **_settings(args))
        shown = _print_path(model, path, monitor)
        if out is not None:
            c = path.critical
            _write_npz(out, load_factors=path.load_factors, q=path.q, lam=path.lam, arc_length=path.arc_length,
                       stable=path.stable, negative=path.negative, min_eigenvalue=path.min_eigenvalue,
                       critical_kind=np.array([x.kind for x in c], dtype=str),
                       critical_load_factor=np.array([x.load_factor for x in c]),
                       critical_q=np.array([x.q for x in c]).reshape(len(c), model.n_dof),
                       monitor=np.array(model.dof_names[shown]), dof_names=names[0], constraint_names=names[1])
        return 0
    with _warnings_as_lines():
        res = equilibrium(model, names=NAMES, **_settings(args))
    _print_equilibrium(model, res)
    if out is not None:
        _write_npz(out, q=res.q, lam=res.lam, dof_names=names[0], constraint_names=names[1],
                   load_factors=np.array(res.load_factors), stable=np.array(res.stable),
                   min_eigenvalue=np.array(res.stability.min_eigenvalue), critical_mode=res.stability.mode)
    return 0


def cmd_modes(args: argparse.Namespace, outputs: Outputs) -> int:
    from casflex.statics import equilibrium, modes

    if args.about != "equilibrium":
        _check_combinations(args, _STATIC_OPTIONS, "--about equilibrium")
    out = outputs.file("--out", args.out, (".npz",), "modes") if args.out else None
    model = load_model(args.scene)
    free = model.n_dof - len({c.dof for c in model.constraints}) - len(model.joint_row_names)
    count = min(6, free) if args.count is None else args.count
    if count > free:
        raise OptionError(f"--count: {model.scene.name} has {free} free motions, so at most {free} modes; "
                          f"got {count}")
    q = None
    if args.about == "equilibrium":
        with _warnings_as_lines():
            st = equilibrium(model, names=NAMES, **_settings(args))
        q = st.q
        print(f"static equilibrium of {model.scene.name}: {st.iterations} iterations; {st.stability.describe()}")
    where = "the static equilibrium" if q is not None else "the initial configuration"
    with _warnings_as_lines("" if q is not None else " (--about equilibrium)"):
        res = modes(model, q=q, count=count)
    print(f"natural frequencies of {model.scene.name} linearised about {where}:")
    growth = np.abs(np.sqrt(res.omega2.astype(complex)).imag)
    for k, (f, g) in enumerate(zip(res.freq_hz, growth, strict=True), 1):
        print(f"  mode {k:3d}: {f:14.6f} Hz" + (f"  flutter: grows at {g:.6g} 1/s" if g > 0 and res.flutter else ""))
    if out is not None:
        _write_npz(out, freq_hz=res.freq_hz, shapes=res.shapes, dof_names=np.array(model.dof_names),
                   equilibrium=np.array(res.equilibrium), omega2=res.omega2)
    return 0


def _add_static_options(s: argparse.ArgumentParser, when: str = "") -> None:
    g = s.add_argument_group("statics options" + when)
    g.add_argument("--steps", type=integer(1, "a number of load steps"),
                   help="first load increment 1/STEPS of the load, adaptive from there (default 1)")
    g.add_argument("--max-iter", dest="max_iter", type=integer(1, "a number of iterations"),
                   help="Newton iterations per load increment (default 100)")
    g.add_argument("--tol", type=positive("a tolerance"),
                   help="scaled residual tolerance, in structure lengths (default 1e-10)")
    g.add_argument("--min-increment", dest="min_increment", type=_fraction,
                   help="smallest load increment before giving up, a share of the load (default 1e-3)")
    g.add_argument("--seek", choices=("stable", "nearest"),
                   help="stable: a stable equilibrium, leaving unstable ones (default); nearest: plain Newton, "
                        "may return an unstable equilibrium (with a warning)")


def add_parsers(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("static", help="static equilibrium under gravity and loads, its stability, equilibrium paths")
    s.add_argument("scene", help="built-in scene name (twobar) or a TOML file")
    _add_static_options(s)
    g = s.add_argument_group("path following (with --path)")
    g.add_argument("--path", choices=("arc-length",),
                   help="trace the equilibrium path from the unloaded structure by arc-length continuation "
                        "(through limit points), instead of solving at full load")
    g.add_argument("--to-factor", dest="to_factor", type=positive("a load factor"),
                   help="end the path at this load factor (default 1)")
    g.add_argument("--max-points", dest="max_points", type=integer(2, "a number of points"),
                   help="largest number of path points (default 200)")
    g.add_argument("--arc-length", dest="arc_length", type=positive("an arc length in structure lengths"),
                   help="first arc length (scaled, structure lengths); steps grow to 4x it (default: the load "
                        "factor rises by 1/20 of --to-factor in the first step)")
    g.add_argument("--monitor", metavar="DOF", help="dof shown in the path table (default the translation that "
                                                    "moves most)")
    s.add_argument("--out", type=output_path, metavar="FILE.npz",
                   help="write q, lam, dof_names, stability (with --path: the whole path) to this .npz file")
    s.set_defaults(func=cmd_static)

    s = sub.add_parser("modes", help="natural frequencies and mode shapes")
    s.add_argument("scene", help="built-in scene name (twobar) or a TOML file")
    s.add_argument("--count", type=integer(1, "a number of modes"),
                   help="number of modes (default 6, or as many as the scene's free motions)")
    s.add_argument("--about", choices=("initial", "equilibrium"), default="initial",
                   help="linearise about the initial configuration (default) or the static equilibrium")
    _add_static_options(s, " (with --about equilibrium)")
    s.add_argument("--out", type=output_path, metavar="FILE.npz",
                   help="write freq_hz, shapes, dof_names to this .npz file")
    s.set_defaults(func=cmd_modes)
