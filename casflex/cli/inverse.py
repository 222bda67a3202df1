"""``casflex inverse``: net joint moments, intersegmental forces and root loads from a lab trial."""

from __future__ import annotations

import argparse
import sys

from casflex.cli._base import OptionError, Outputs, need_extra, non_negative, output_path, positive, uncertain_option


def _filter_kind(text: str) -> str:
    """--filter's value, one of :data:`casflex.inverse.options.FILTERS`, checked as argparse checks choices (the
    same message). Not argparse's ``choices``: the help expands them, and importing them loads the package
    casflex.inverse (numpy, CasADi: 0.3 s), which ``casflex inverse --help`` does not need (its usage line names
    them by :data:`FILTER_METAVAR`)."""
    from casflex.inverse.options import FILTERS

    if text not in FILTERS:
        raise argparse.ArgumentTypeError(f"invalid choice: {text!r} (choose from {', '.join(map(repr, FILTERS))})")
    return text


#: FILTERS as argparse writes choices in the usage line (tests/test_cli_startup.py holds them equal).
FILTER_METAVAR = "{butterworth,opensim}"


def _plate(text: str) -> tuple[str, str]:
    if text.strip() == "auto":  # each plate's contacts to the foot over each (casflex.inverse.contacts)
        return "auto", ""
    node, sep, prefix = text.partition("=")
    if not sep or not node.strip() or not prefix.strip():
        raise argparse.ArgumentTypeError(f"expected NODE=PREFIX (e.g. ankle=ground_) or auto, got {text!r}")
    return node.strip(), prefix.strip()


def _passive(text: str) -> tuple[str, float | None, float | None]:
    hinge, *window = text.split(":")
    if not hinge or len(window) not in (0, 2):
        raise argparse.ArgumentTypeError(f"expected HINGE or HINGE:T0:T1 (a window in s), got {text!r}")
    try:
        t0, t1 = (float(w) for w in window) if window else (None, None)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected HINGE:T0:T1 with times in s, got {text!r}") from None
    if t0 is not None and not t1 > t0:
        raise argparse.ArgumentTypeError(f"the window's end must follow its start, got {text!r}")
    return hinge, t0, t1


def _cutoff_or_none(text: str) -> float | None | str:
    if text.strip().lower() in ("none", "same"):
        return None if text.strip().lower() == "none" else "same"
    try:
        v = float(text)
    except ValueError:
        v = float("nan")
    if not (v > 0 and v < float("inf")):
        raise argparse.ArgumentTypeError(f"expected a frequency in Hz (> 0), 'none' or 'same', got {text!r}")
    return v


_UNSET = object()  # --cutoff-plates not given (its values include None: 'none')


def _progress(done: int, total: int) -> None:
    from casflex.interrupt import progress

    if done == total or done % max(total // 20, 1) == 0:
        progress(f"casflex: marker fit {done}/{total} frames", done, total)


#: The command's options by the names of the option values they build (:mod:`casflex.inverse.options`): how a value
#: refused is said (:meth:`~casflex.inverse.options.OptionRefused.said`).
FLAGS = {"markers": "--data", "coordinates": "--coordinates", "grf": "--loads", "plates": "--plate", "plane": "--plane",
         "root": "--root", "t_start": "--t-start", "t_end": "--t-end", "tasks": "--tasks", "cutoff": "--cutoff",
         "cutoff_plates": "--cutoff-plates", "filter": "--filter", "max_misfit": "--max-misfit",
         "uncertain": "--uncertain", "marker_noise": "--marker-noise", "bands": "--bands"}


def inverse_options(args: argparse.Namespace) -> dict:
    """The option values of :func:`casflex.inverse.inverse_dynamics` (``trial``, ``filter``, ``fit``, ``bands``)
    from the command's options, each checked by its object: OptionError naming the option. Shared by the commands
    that take what ``casflex inverse`` takes (:func:`add_trial_options`)."""
    for flag, value in (("--data", args.data), ("--loads", args.loads)):
        if value and value.lower().endswith(".c3d"):
            need_extra("ezc3d", f"{flag} {value!r} (a C3D file)")
    given = args.plate or []
    plates: dict | str = {}
    for node, prefix in given:
        if node == "auto" and not prefix:
            if len(given) > 1:
                raise OptionError("--plate: auto (each contact to the foot over it) takes every plate: give it alone")
            plates = "auto"
        elif node in plates:
            plates[node] = [*([plates[node]] if isinstance(plates[node], str) else plates[node]), prefix]
        else:
            plates[node] = prefix
    external = bool(args.loads) and args.loads.lower().endswith(".xml")  # OpenSim's ExternalLoads: it says
    if args.loads and not plates and not external:  # the library would take the plates as none: a command asks
        raise OptionError("--loads: say which node each plate acts on with --plate NODE=PREFIX (e.g. ankle=ground_), "
                          "or --plate auto (each contact to the foot over it), or give OpenSim's ExternalLoads file")
    how, plates_hz = _matched(args)
    from casflex.inverse import Bands, Filter, Fit, OptionRefused, Trial  # here: the options' own checks first

    try:
        return {"trial": Trial(args.data, args.coordinates, grf=args.loads, plates=plates, plane=args.plane,
                               root=args.root, t_start=args.t_start, t_end=args.t_end, tasks=args.tasks),
                "filter": Filter(None, None, how) if args.no_filter else Filter(args.cutoff, plates_hz, how),
                "fit": Fit(max_misfit=args.max_misfit),
                "bands": Bands(args.uncertain, args.marker_noise, args.bands)}
    except OptionRefused as exc:
        raise OptionError(exc.said(FLAGS)) from None


#: ``--match``'s presets: the options each sets, (--filter, --cutoff-plates), as the peer's tools run.
MATCH = {"opensim": ("opensim", None)}
_DEFAULT_FILTER, _DEFAULT_PLATES = "butterworth", "same"


def _matched(args: argparse.Namespace) -> tuple[str, float | None | str]:
    """(--filter, --cutoff-plates) as given, else as --match's preset sets them, else the defaults; an option
    given against the preset is refused (one line naming both)."""
    given_filter, given_plates = getattr(args, "filter", None), getattr(args, "cutoff_plates", _UNSET)
    if getattr(args, "match", None) is None:
        return given_filter or _DEFAULT_FILTER, _DEFAULT_PLATES if given_plates is _UNSET else given_plates
    how, plates_hz = MATCH[args.match]
    if given_filter is not None and given_filter != how:
        raise OptionError(f"--filter: {given_filter} contradicts --match {args.match} (its filter is {how}); give "
                          "one or the other")
    if given_plates is not _UNSET and given_plates != plates_hz:
        raise OptionError(f"--cutoff-plates: {given_plates} contradicts --match {args.match} (the plates "
                          f"{'unfiltered' if plates_hz is None else f'at {plates_hz} Hz'}); give one or the other")
    return how, plates_hz


def cmd_inverse(args: argparse.Namespace, outputs: Outputs) -> int:
    chosen = inverse_options(args)
    outs = [(outputs.file("--out", path, (".npz", ".csv", ".sto", ".mot"), "inverse dynamics"), path)
            for path in args.out or []]  # each checked and reserved before any work
    plots = None
    if args.plots is not None:
        from casflex.plotting.inverse import FIGURES

        plots = outputs.directory("--plots", args.plots, FIGURES if args.data is not None else FIGURES[:1])
    from casflex.inverse import BandError, prepare, solve  # after the options' checks: numpy, CasADi

    try:
        inputs = prepare(args.scene, **chosen)
    except BandError as exc:
        raise OptionError(exc.said(FLAGS)) from None
    _check_passive(args.passive or [], inputs)
    for line in inputs.warnings:
        print(f"casflex: warning: {line}", file=sys.stderr)
    res = solve(inputs, progress=None if args.quiet else _progress)
    for line in res.warnings[len(inputs.warnings):]:
        print(f"casflex: warning: {line}", file=sys.stderr)
    if not args.quiet:
        print(res.summary())
    for hinge, t0, t1 in args.passive or []:  # asked for, and written nowhere else: printed under --quiet too
        from casflex.inverse.passive import fit_passive

        print(fit_passive(res, hinge, t0, t1).summary())
    for staged, path in outs:
        res.save(staged, fmt=path.rsplit(".", 1)[-1].lower())
    if plots is not None:
        from casflex.plotting.inverse import save_inverse_figures

        save_inverse_figures(res, plots)
    return 0


def _check_passive(passive: list, inputs) -> None:
    """--passive: each hinge in the scene, each window inside the trial's, before the marker fit."""
    hinges = inputs.tree.hinges
    t0, t1 = float(inputs.t[0]), float(inputs.t[-1])
    for hinge, a, b in passive:
        if hinge not in hinges:
            raise OptionError(f"--passive: no hinge {hinge!r} in the scene; its hinges are {sorted(hinges)}")
        if a is not None and (a < t0 - 1e-9 or b > t1 + 1e-9):
            raise OptionError(f"--passive: the window {a:g}..{b:g} s of {hinge!r} is not inside the trial's "
                              f"{t0:g}..{t1:g} s")


def cmd_calibrate(args: argparse.Namespace, outputs: Outputs) -> int:
    from casflex.inverse.calibrate import calibrate
    from casflex.lab import Plane
    from casflex.scene.io import dumps_scene

    Plane.parse(args.plane, option="--plane")
    if args.static.lower().endswith(".c3d"):
        need_extra("ezc3d", f"--static {args.static!r} (a C3D file)")
    if args.mass is not None and not args.scale:
        raise OptionError("--mass: scales the bodies with the segments; give --scale too")
    out = outputs.file("--out", args.out, (".toml",), "calibrated scene")
    scene, report = calibrate(args.scene, args.static, args.plane, root=args.root, scale=args.scale, mass=args.mass)
    print("\n".join(ln for ln in report if not ln.startswith("warning: ")))
    for line in (ln for ln in report if ln.startswith("warning: ")):
        print(f"casflex: {line}", file=sys.stderr)
    out.write_text(dumps_scene(scene))
    return 0


def add_trial_options(s: argparse.ArgumentParser) -> None:
    """The options that build :func:`inverse_options`' values (a trial, its filter, the fit's limit, the bands):
    ``casflex inverse``'s, for every command that takes what it takes."""
    s.add_argument("--data", metavar="TRIAL", help="the trial's markers (.trc or .c3d)")
    s.add_argument("--coordinates", metavar="MOT", help="instead of --data: the trial's coordinates (.mot/.sto, "
                                                        "e.g. OpenSim's IK result; columns named as the model's "
                                                        "coordinates, degrees where the header says inDegrees=yes)")
    s.add_argument("--plane", default="X,Y", help="the lab axes that become the model's x and y (default X,Y)")
    s.add_argument("--loads", metavar="GRF", help="ground reactions (OpenSim .mot/.sto, or a .c3d's plates: the "
                                                  "trial's own C3D file again for its plates), or OpenSim's "
                                                  "ExternalLoads .xml (or ID setup) naming the file and the bodies")
    s.add_argument("--plate", action="append", type=_plate, metavar="NODE=PREFIX",
                   help="a plate's columns (PREFIXforce_vx ...) act on NODE's segment; repeat per plate (a node "
                        "given twice: both plates act on it); 'auto': each plate's contacts act on the foot over "
                        "each, by the feet's markers (a .c3d trial without --loads: its own plates)")
    s.add_argument("--cutoff", type=positive("a frequency in Hz"), default=6.0,
                   help="zero-lag Butterworth cut-off for the kinematics and the plates alike, Hz (default 6)")
    s.add_argument("--cutoff-plates", type=_cutoff_or_none, default=_UNSET, metavar="HZ|none",
                   help="the plates' own cut-off, Hz, 'none' (unfiltered, as OpenSim's ID tool) or 'same' (the "
                        "default: --cutoff's)")
    s.add_argument("--filter", type=_filter_kind, metavar=FILTER_METAVAR, default=None,
                   help="the coordinates' filter: butterworth (2nd order forward and back: 4th-order zero-lag, the "
                        "default) or opensim (as OpenSim's ID tool: the record padded by half its length, 3rd "
                        "order forward and back); both -6 dB at --cutoff")
    s.add_argument("--match", choices=sorted(MATCH), default=None,
                   help="filter as a peer's tools do, as a lab runs them: opensim = OpenSim's IK then its ID tool "
                        "(--filter opensim --cutoff-plates none: the coordinates filtered at --cutoff, 6 Hz by "
                        "default as OpenSim's example ID setups say, the plates as measured)")
    s.add_argument("--no-filter", action="store_true", help="use the data unfiltered")
    s.add_argument("--tasks", metavar="XML", help="marker weights: an OpenSim IK task set or IK setup file (markers "
                                                  "with no task are left out); default the scene's weights")
    s.add_argument("--root", metavar="NODE", help="the node the data drive (default: the scene's first)")
    s.add_argument("--t-start", type=non_negative("a time in s"), help="use the trial from this time, s")
    s.add_argument("--t-end", type=positive("a time in s"), help="use the trial up to this time, s")
    s.add_argument("--max-misfit", type=positive("a distance in m"), metavar="M",
                   help="refuse a marker farther than this from the fitted pose, m (default 0.1: no soft-tissue "
                        "artefact is that large; at most 1)")
    s.add_argument("--uncertain", type=uncertain_option, action="append", metavar="TARGET=SD|P%|LO:HI",
                   help="a property known only within an uncertainty (a segment's mass or inertia from an "
                        "anthropometric table: shank.mass=10%%, shank.inertia=0.04:0.06), added to the scene's "
                        "[[uncertain]]: each load gets its band (1 SD) from them and from the markers' noise; "
                        "repeatable")
    s.add_argument("--marker-noise", type=non_negative("a distance in m"), metavar="M",
                   help="the markers' noise per axis (SD, m; 0: exact) whose band the loads get (default: the fit's "
                        "residuals'); asks for the bands")
    s.add_argument("--bands", action=argparse.BooleanOptionalAction, default=None,
                   help="the loads' bands (1 SD) from the uncertain properties and the markers' noise (default: when "
                        "a property is uncertain or --marker-noise is given); written as <load>_sd columns")


def add_parsers(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("inverse", help="net joint moments and intersegmental forces from a lab trial")
    s.add_argument("scene", help="built-in scene name (hamner_leg), a TOML file (segments on hinges, labelled "
                                 "markers) or an OpenSim model (.osim)")
    add_trial_options(s)
    s.add_argument("--passive", action="append", type=_passive, metavar="HINGE[:T0:T1]",
                   help="fit a torsion spring-damper to HINGE's net moment (over T0..T1 s) and say how much of it "
                        "it explains; repeat per hinge")
    s.add_argument("--out", type=output_path, action="append", metavar="FILE",
                   help="write the result to FILE.npz (everything), FILE.csv (a table: the filtered coordinates and "
                        "the loads), FILE.sto (OpenSim's table of the loads, the lab's names) or FILE.mot (the joint "
                        "angles as OpenSim's IK writes them: the marker fit, unfiltered, in degrees); repeat for "
                        "several files (docs/lab.md)")
    s.add_argument("--plots", type=output_path, metavar="DIR", help="write figures into this directory")
    s.add_argument("--quiet", action="store_true", help="print nothing but warnings and errors (stderr), and "
                                                        "the --passive fits asked")
    s.set_defaults(func=cmd_inverse)

    s = sub.add_parser("calibrate", help="place a scene's markers (and scale its segments) from a static trial")
    s.add_argument("scene", help="built-in scene name (hamner_leg) or a TOML file: segments on hinges, labelled "
                                 "markers")
    s.add_argument("--static", required=True, metavar="STATIC", help="the static trial's markers (.trc or .c3d)")
    s.add_argument("--out", type=output_path, required=True, metavar="SUBJECT.toml",
                   help="write the calibrated scene here")
    s.add_argument("--plane", default="X,Y", help="the lab axes that become the model's x and y (default X,Y)")
    s.add_argument("--root", metavar="NODE", help="the tree's root node (default: the scene's first)")
    s.add_argument("--scale", action="store_true",
                   help="scale each segment by its markers' distances first (needs markers along the segment)")
    s.add_argument("--mass", type=positive("a mass in kg"), help="with --scale: the bodies' total mass, kg")
    s.add_argument("--quiet", action="store_true", help="no progress messages")
    s.set_defaults(func=cmd_calibrate)
