"""``casflex muscles``: the muscles of a lab trial (static optimization) and the force each joint bears (joint
reactions), written as OpenSim's StaticOptimization and JointReaction write them."""

from __future__ import annotations

import argparse
import os
import sys

from casflex.cli._base import OptionError, Outputs, output_path, positive

#: The command's options for static optimization and the reactions, by the field of the value each fills.
FLAGS = {"exponent": "--exponent", "activation_bounds": "--activation-bounds", "on": "--on", "frame": "--in",
         "joints": "--joints", "force_length_velocity": "--no-force-length-velocity", "tendon": "--tendon"}


def _bounds(text: str) -> tuple[float, float]:
    lo, sep, hi = text.partition(":")
    try:
        return float(lo), float(hi)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LOWER:UPPER (e.g. 0.01:1), got {text!r}") from None


def _uncertainty(args: argparse.Namespace):
    """The muscles' declared uncertainty (:class:`~casflex.muscles.options.MuscleUncertainty`) of
    --muscle-uncertainty, or None."""
    from casflex.muscles.options import UNCERTAIN_PROPERTIES, MuscleUncertainty

    given = {}
    for text in args.muscle_uncertainty or []:
        prop, sep, value = text.partition("=")
        prop = prop.strip()
        if not sep or prop not in UNCERTAIN_PROPERTIES:
            raise OptionError(f"--muscle-uncertainty: expected PROPERTY=P% with PROPERTY one of "
                              f"{', '.join(UNCERTAIN_PROPERTIES)}, got {text!r}")
        try:
            v = float(value.strip().removesuffix("%")) / (100.0 if value.strip().endswith("%") else 1.0)
        except ValueError:
            raise OptionError(f"--muscle-uncertainty: {prop}: expected a relative SD (10% or 0.1), got {value!r}") \
                from None
        if prop in given:
            raise OptionError(f"--muscle-uncertainty: {prop} given twice")
        given[prop] = v
    if not given:
        return None
    try:
        return MuscleUncertainty(**given)
    except ValueError as exc:
        raise OptionError(f"--muscle-uncertainty: {exc}") from None


def _options(args: argparse.Namespace):
    """(StaticOptimization, JointReaction, joints) from the command's options, each checked by its value."""
    from casflex.muscles.reaction import JointReaction
    from casflex.muscles.static_optimization import StaticOptimization

    so = {"exponent": args.exponent, "force_length_velocity": not args.no_force_length_velocity,
          "tendon": args.tendon}
    if args.activation_bounds is not None:
        so["activation_bounds"] = args.activation_bounds
    for make, kw in ((StaticOptimization, so), (JointReaction, {"on": args.on, "frame": args.frame,
                                                                 "body_weight": None})):
        try:
            make(**kw)
        except ValueError as exc:
            field, _, reason = str(exc).partition(": ")
            raise OptionError(f"{FLAGS.get(field, field)}: {reason}") from None
    joints = tuple(j.strip() for j in args.joints.split(",")) if args.joints else ()
    if any(not j for j in joints):
        raise OptionError(f"--joints: expected joint names separated by commas, got {args.joints!r}")
    return StaticOptimization(**so), JointReaction(on=args.on, frame=args.frame), joints


def cmd_muscles(args: argparse.Namespace, outputs: Outputs) -> int:
    from casflex.cli.inverse import _progress, inverse_options
    from casflex.inverse import prepare, solve
    from casflex.muscles import _so_lines
    from casflex.muscles.analysis import TrialMuscles, muscle_result, reserve_actuators, residual_warnings
    from casflex.muscles.result import file_names
    from casflex.muscles.static_optimization import MAX_EXPONENT
    from casflex.scene.from_osim import scene_from_osim
    from casflex.scene.osim_actuators import read_actuators

    if not args.model.lower().endswith(".osim"):
        raise OptionError(f"model: expected an OpenSim model (.osim) with its muscles, got {args.model!r}")
    chosen = inverse_options(args)
    optimization, reaction, joints = _options(args)
    uncertainty = _uncertainty(args)
    emg_columns = _emg_columns(args)
    criteria = tuple(args.criteria or ())
    if any(not (1.0 <= p <= MAX_EXPONENT) or p == optimization.exponent for p in criteria):
        raise OptionError(f"--criteria: expected exponents >= 1 other than --exponent ({optimization.exponent:g}) "
                          f"and at most {MAX_EXPONENT:g}, got {' '.join(f'{p:g}' for p in criteria)}")
    banded = uncertainty is not None or chosen["bands"].asked or args.uncertain or args.marker_noise is not None
    if banded and optimization.tendon == "compliant":
        raise OptionError("--tendon: 'compliant' takes no bands yet (each perturbed property or frame set would be a "
                          "whole IPOPT solve of the trial, some 10 s each): drop the band options, or use rigid "
                          "tendons for the bands")
    name = args.name or os.path.splitext(os.path.basename(args.data or args.coordinates))[0]
    out = outputs.directory("--out", args.out, file_names(name, bool(banded)))
    plots = None
    if args.plots is not None:
        from casflex.plotting.muscles import FIGURES

        plots = outputs.directory("--plots", args.plots, FIGURES)
    osim = scene_from_osim(args.model, muscles=True)
    if args.actuators and args.reserves is not None:
        raise OptionError("--reserves: --actuators gives the reserves; give one of them")
    acts = read_actuators(args.model) + (read_actuators(args.actuators) if args.actuators else ())
    inputs = prepare(args.model, **chosen)
    emg = None
    if emg_columns:
        from casflex.muscles.emg import emg_envelopes

        emg = emg_envelopes(args.emg, emg_columns, inputs.t, tuple(m.name for m in osim.muscles))
    if args.reserves is not None:
        acts += reserve_actuators(osim.scene, inputs.tree.root, args.reserves)
    trial = TrialMuscles(osim, inputs.tree, inputs.t, inputs.plates, acts, optimization=optimization,
                         reaction=reaction, joints=joints, source=args.actuators or args.model)
    for line in [*osim.warnings, *inputs.warnings, *trial.warnings]:
        print(f"casflex: warning: {line}", file=sys.stderr)
    res = solve(inputs, progress=None if args.quiet else _progress)
    frames = trial.solve(res.z, res.zd, res.zdd)
    residual = residual_warnings(trial, frames)
    for line in residual:
        print(f"casflex: warning: {line}", file=sys.stderr)
    result = muscle_result(trial, frames, res.z, report=(*trial.notes, *_so_lines(frames), *residual),
                           settings={"model": args.model, "trial": args.data or args.coordinates})
    if banded:
        result = _with_bands(result, trial, inputs, res, uncertainty, criteria or (3.0,), args.draws)
    print(result.summary())
    result.save(out, name)
    if plots is not None:
        from casflex.plotting.muscles import save_muscle_figures

        save_muscle_figures(result, plots, emg)
    return 0


def _emg_columns(args: argparse.Namespace) -> dict[str, str]:
    """--emg-column MUSCLE=COLUMN, each checked for its form, with --emg and --plots."""
    pairs = args.emg_column or []
    if not pairs and args.emg is None:
        return {}
    if args.emg is None or not pairs:
        raise OptionError("--emg: give the EMG file (--emg FILE) and the column of each muscle (--emg-column "
                          "MUSCLE=COLUMN, repeated)")
    if args.plots is None:
        raise OptionError("--emg: the envelopes are drawn beside the activations: give --plots DIR")
    out = {}
    for text in pairs:
        muscle, sep, column = (v.strip() for v in text.partition("="))
        if not (sep and muscle and column):
            raise OptionError(f"--emg-column: expected MUSCLE=COLUMN, got {text!r}")
        out[muscle] = column
    return out


def _with_bands(result, trial, inputs, res, uncertainty, criteria, draws):
    """``result`` with its outputs' bands and the criteria's spread (:func:`casflex.muscles.bands.muscle_bands`)."""
    import dataclasses

    from casflex.muscles.bands import muscle_bands
    from casflex.muscles.options import MuscleUncertainty

    mb = muscle_bands(trial, inputs, None, res.z, res.zd, res.zdd, uncertainty=uncertainty or MuscleUncertainty(),
                      criteria=criteria, draws="auto" if draws is None else draws)
    key = next(iter(mb.criteria), None)
    return dataclasses.replace(result, bands={n: b["total"] for n, b in mb.bands.items()},
                               spread={n: d[key] for n, d in mb.spread.items()} if key else {},
                               lines=tuple(mb.summary()), report=(*result.report, *mb.report))


def add_parsers(sub: argparse._SubParsersAction) -> None:
    from casflex.cli.inverse import add_trial_options

    s = sub.add_parser("muscles", help="muscle forces (static optimization) and joint reactions from a lab trial")
    s.add_argument("model", help="an OpenSim model (.osim) with its muscles (Millard2012EquilibriumMuscle, "
                                 "Thelen2003Muscle, DeGrooteFregly2016Muscle)")
    add_trial_options(s)
    s.add_argument("--actuators", metavar="XML", help="reserve and residual actuators (an OpenSim ForceSet file, e.g. "
                                                      "the pipeline's *_Reserve_Actuators.xml), added to the model's")
    s.add_argument("--reserves", type=positive("an optimal force in N m"), metavar="N",
                   help="instead of --actuators: a reserve of this optimal force on every joint coordinate and the "
                        "residuals FX, FY, MZ on the root")
    s.add_argument("--exponent", type=float, default=2.0, metavar="P",
                   help="static optimization minimises the sum of activation^P (OpenSim's activation_exponent; "
                        "default 2)")
    s.add_argument("--no-force-length-velocity", action="store_true",
                   help="a muscle's force per activation is its maximum isometric force (OpenSim's "
                        "use_muscle_physiology false)")
    s.add_argument("--tendon", choices=("rigid", "compliant"), default="rigid",
                   help="rigid: each tendon at its slack length (OpenSim's static optimization); compliant: each "
                        "muscle's fibre and tendon in static equilibrium, the fibre's length solved with the "
                        "activations (docs/muscles.md)")
    s.add_argument("--activation-bounds", type=_bounds, metavar="LO:HI",
                   help="the activations' bounds of the muscles whose model gives no min_control / max_control of "
                        "their own (a muscle's own win, as in OpenSim's static optimization); default: each kind's "
                        "OpenSim default (0.01:1 for Millard and Thelen, 0:1 for DeGrooteFregly2016Muscle)")
    s.add_argument("--joints", metavar="J1,J2", help="the joints whose reactions are written (default: every hinge)")
    s.add_argument("--on", choices=("child", "parent"), default="child",
                   help="the reaction on the joint's child (default) or parent body, as OpenSim's apply_on_bodies")
    s.add_argument("--in", dest="frame", choices=("child", "parent", "ground"), default="ground",
                   help="the frame the reactions are expressed in (default ground, as OpenSim's express_in_frame)")
    s.add_argument("--muscle-uncertainty", action="append", metavar="PROPERTY=P%",
                   help="every muscle's max_isometric_force, optimal_fiber_length or tendon_slack_length known within "
                        "P%% (1 SD, independent between muscles); repeat per property: the outputs' bands (written as "
                        "<name>_..._sd.sto), with the anthropometry's and the markers' (--uncertain, --marker-noise)")
    s.add_argument("--criteria", action="append", type=float, metavar="P",
                   help="with bands: the outputs also with static optimization's exponent P, their spread said "
                        "beside the bands (default 3); repeatable")
    s.add_argument("--draws", type=int, metavar="N",
                   help="the muscles' part of the bands by a Monte Carlo of N draws (default: 100 where a fibre or "
                        "tendon length is uncertain, the outputs being far from linear in them; 0: first order)")
    s.add_argument("--name", help="the files' prefix (default: the trial file's name)")
    s.add_argument("--out", type=output_path, required=True, metavar="DIR",
                   help="write <name>_StaticOptimization_activation.sto, _force.sto and "
                        "<name>_JointReaction_ReactionLoads.sto into this directory")
    s.add_argument("--plots", type=output_path, metavar="DIR", help="write figures into this directory")
    s.add_argument("--emg", metavar="FILE", help="a .c3d (its analog channels) or .mot / .sto of the trial's raw EMG: "
                   "each muscle's envelope drawn "
                   "beside its activation (--plots; band-pass 20-400 Hz, rectified, low-pass 6 Hz, over its peak)")
    s.add_argument("--emg-column", action="append", metavar="MUSCLE=COLUMN",
                   help="the --emg file's column (a C3D's analog label) of a muscle (repeat for each muscle)")
    s.add_argument("--quiet", action="store_true", help="no progress messages")
    s.set_defaults(func=cmd_muscles)
