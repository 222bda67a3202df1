"""Inverse dynamics' choices as values: one small frozen object per stage, each checking its own fields when it is
made (the one place that says what a bad value is), shared by the Python functions
(:func:`casflex.inverse.inverse_dynamics`, :func:`~casflex.inverse.prepare`, :func:`~casflex.inverse.solve`), the
command line (``casflex inverse`` builds them from its options) and the study file (``casflex study``).

- :class:`Trial`: what the lab recorded and how it meets the scene (markers or coordinates, ground reactions and
  the node each plate acts on, the lab's plane, the root, the window, the markers' weights);
- :class:`Filter`: the zero-lag low-pass of the coordinates and of the plates (kind, cut-offs);
- :class:`Fit`: the marker fit's limits (the longest gap a spline fills, the largest misfit taken);
- :class:`Bands`: each load's band (the anthropometry's uncertain properties, the markers' noise, asked or not);
- :class:`Flexible`: the HHT run of a scene with flexible segments (time step, alpha, compiled C).

A value refused is :class:`OptionRefused` (a ValueError ``"<option>: <reason>"``); the command line and the study
file say it with their own names (:meth:`OptionRefused.said`: ``--cutoff``, ``options.cutoff``). What only the
data or the scene decide (a cut-off against the markers' rate, a plate's node in the scene) is :func:`prepare`'s.
The module is light (no CasADi, no numpy at import): the command line's parser imports it.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["named", "BandError", "Bands", "Filter", "FILTERS", "Fit", "Flexible", "OptionRefused", "Trial"]

#: The coordinates' filters: a 2nd-order Butterworth forward and back (Winter's 4th-order zero-lag), or
#: OpenSim's inverse dynamics tool's (:func:`casflex.lab.lowpass.opensim_lowpass`).
FILTERS = ("butterworth", "opensim")


def named(option: str) -> str:
    """``option`` as a reason mentions it (:class:`OptionRefused`): a placeholder each caller names its own way (no
    path or value holds a NUL)."""
    return f"\x00{option}\x00"


class OptionRefused(ValueError):
    """An option's value refused: ``option`` (its name in the Python API: ``cutoff``, ``t_end``; two joined by
    ", " where only both together are wrong) and ``reason``, in which the other options it mentions are
    :func:`named` (so that :meth:`said` can name them as the caller knows them). ``str()``: the Python API's
    names."""

    def __init__(self, option: str, reason: str) -> None:
        self.option, self.reason = option, reason
        super().__init__(self.said({}))

    def said(self, name: Mapping[str, str] | Callable[[str], str],
             mention: Mapping[str, str] | Callable[[str], str] | None = None) -> str:
        """The message with the option named by ``name`` (a mapping or a function of the API's name; a name a
        mapping lacks as it is) and the others its reason mentions by ``mention`` (default ``name``):
        ``--t-end: must be after --t-start ...`` for the command line, ``subjects[0].trials[1].plates: needs grf``
        for the study file."""
        def of(o: str, how) -> str:
            return how(o) if callable(how) else how.get(o, o)

        reason = re.sub("\x00(\\w+)\x00", lambda m: of(m.group(1), name if mention is None else mention), self.reason)
        return f"{', '.join(of(o, name) for o in self.option.split(', '))}: {reason}"


class BandError(OptionRefused):
    """An option of the bands refused (uncertain, marker_noise, bands): :class:`Bands`, or what only the scene
    decides (:func:`casflex.inverse.bands.band_spec`)."""


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _frequency(option: str, value: Any, words: tuple[Any, ...]) -> None:
    if value in words or (_number(value) and value > 0):
        return
    allowed = " or ".join(["a frequency in Hz > 0", *("none (unfiltered)" if w is None else repr(w) for w in words)])
    raise OptionRefused(option, f"expected {allowed}, got {value!r}")


def _path(value: Any) -> bool:
    return isinstance(value, (str, os.PathLike))


def _prefixes(value: Any) -> bool:
    """A plate's column prefix, or a non-empty list of distinct ones."""
    if isinstance(value, str):
        return bool(value)
    return isinstance(value, (list, tuple)) and bool(value) and len(set(value)) == len(value) and all(
        isinstance(v, str) and v for v in value)


@dataclass(frozen=True)
class Trial:
    """One lab trial and how it meets the scene.

    markers : LabMarkers or the path of a .trc or .c3d file: the markers, fitted frame by frame; or, instead,
    coordinates : LabTable or the path of a .mot / .sto file: the scene's coordinates over the trial (e.g.
        OpenSim's IK result; :mod:`casflex.inverse.given`), no marker fit.
    grf : LabTable or the path of a .mot / .sto or .c3d file (the markers' own C3D: its plates), or an OpenSim
        ExternalLoads (or ID setup) .xml, which names the plates' bodies itself.
    plates : node -> the plate's column prefix (``{"ankle": "ground_"}``: :mod:`casflex.inverse.plates`), or
        several (``{"calcn_r": ["ground_", "2_ground_"]}``: a foot on either over the trial, their loads summed); or
        "auto": each plate's contacts applied to the foot over each, by the feet's markers (a foot on plate 1, a
        stride later on plate 3; a plate stepped on by either foot in turn: :mod:`casflex.inverse.contacts`).
        With a C3D trial and no ``grf``, the plates are the markers' file's own.
    plane : the lab axes that become the model's x and y (:class:`casflex.lab.Plane`), e.g. "X,Y"; kept parsed.
    root : the node the data drive (None: the scene's first).
    t_start, t_end : s, the part of the trial used (None: from its start, to its end).
    tasks : the markers' weights: an OpenSim IK task set or setup file, or label -> weight
        (:func:`casflex.inverse.inputs.weighted`); None: the scene's ``[[markers]]`` weights.
    """

    markers: Any = None
    coordinates: Any = None
    grf: Any = None
    plates: Mapping[str, str | Sequence[str]] | str | None = None
    plane: Any = "X,Y"
    root: str | None = None
    t_start: float | None = None
    t_end: float | None = None
    tasks: Any = None

    def __post_init__(self) -> None:
        from casflex.lab import Plane

        if (self.markers is None) == (self.coordinates is None):
            raise OptionRefused("markers, coordinates", "give the trial's markers or its coordinates (one of them)")
        if self.tasks is not None and self.coordinates is not None:
            raise OptionRefused("tasks", f"they weight the marker fit; with {named('coordinates')} given there is none")
        if not isinstance(self.plane, Plane):
            try:
                object.__setattr__(self, "plane", Plane.parse(self.plane))
            except ValueError as exc:
                raise OptionRefused("plane", str(exc).partition(": ")[2]) from None
        self._window()
        self._plates()

    def _window(self) -> None:
        for name in ("t_start", "t_end"):
            value = getattr(self, name)
            if value is not None and not (_number(value) and value >= 0):
                raise OptionRefused(name, f"expected a time in s >= 0, got {value!r}")
        if self.t_start is not None and self.t_end is not None and self.t_end <= self.t_start:
            raise OptionRefused("t_end", f"must be after {named('t_start')} ({self.t_start:g} s), got {self.t_end:g}")

    def _plates(self) -> None:
        if self.plates is None:
            return
        if isinstance(self.plates, str) and self.plates != "auto" or not isinstance(self.plates, (str, Mapping)) \
                or isinstance(self.plates, Mapping) and not all(isinstance(k, str) and k and _prefixes(v)
                                                                for k, v in self.plates.items()):
            raise OptionRefused("plates", "expected node -> the plate's column prefix (or a list of them), or "
                                          f"\"auto\", got {self.plates!r}")
        if self.plates == "auto" and self.coordinates is not None:
            raise OptionRefused("plates", "\"auto\" takes the foot over each plate from the markers; with "
                                          f"{named('coordinates')} given, name each plate's node (node -> prefix)")
        own = _path(self.markers) and os.fspath(self.markers).lower().endswith(".c3d")  # its own plates
        if self.plates and self.grf is None and not own:
            raise OptionRefused("plates", f"needs {named('grf')} (the ground reaction file)")
        if self.plates and _path(self.grf) and os.fspath(self.grf).lower().endswith(".xml"):
            raise OptionRefused("plates", f"{os.fspath(self.grf)} says which body each plate acts on; give "
                                          f"{named('plates')} or that file")

    @property
    def given(self) -> bool:
        """Whether the coordinates are given (no marker fit)."""
        return self.coordinates is not None


@dataclass(frozen=True)
class Filter:
    """The zero-lag low-pass of the coordinates and of the plates.

    cutoff : Hz, the coordinates' cut-off (None: unfiltered), and the plates' unless ``cutoff_plates`` says
        otherwise; filtering kinematics and forces alike keeps impact artefacts out of the moments (Kristianslund
        et al. 2012).
    cutoff_plates : Hz, the plates' own cut-off (None: unfiltered, as OpenSim's ID tool; "same": ``cutoff``).
    kind : "butterworth" (a 2nd-order Butterworth forward and back: Winter's 4th-order zero-lag) or "opensim" (as
        OpenSim's inverse dynamics tool: the record padded by half its length, a 3rd-order Butterworth forward
        and back, :func:`casflex.lab.lowpass.opensim_lowpass`), the coordinates'; both -6 dB at ``cutoff``. The
        plates are filtered by the first in both cases.
    """

    cutoff: float | None = 6.0
    cutoff_plates: float | None | str = "same"
    kind: str = "butterworth"

    def __post_init__(self) -> None:
        _frequency("cutoff", self.cutoff, (None,))
        _frequency("cutoff_plates", self.cutoff_plates, (None, "same"))
        if self.kind not in FILTERS:
            raise OptionRefused("filter", f"one of {', '.join(FILTERS)}, got {self.kind!r}")

    @property
    def plates(self) -> float | None:
        """The plates' cut-off, Hz (None: unfiltered)."""
        return self.cutoff if self.cutoff_plates == "same" else self.cutoff_plates

    def describe(self) -> str:
        """The report's line of the coordinates' filter."""
        if not self.cutoff:
            return "coordinates not filtered"
        how = ("as OpenSim's ID tool (padded by half the record, Butterworth 3rd order forward and back)"
               if self.kind == "opensim" else "Butterworth 4th order zero-lag")
        return f"coordinates filtered: {how} at {self.cutoff:g} Hz"


#: The largest ``max_misfit`` taken, m: beyond it the check would pass anything (a value in mm, 150 for 0.15 m).
MAX_MISFIT_LIMIT = 1.0


@dataclass(frozen=True)
class Fit:
    """The marker fit's limits: ``max_gap`` s, the longest stretch of frames whose markers do not decide the pose
    that a spline fills; ``max_misfit`` m, a marker farther than this from the fitted pose is refused (None:
    :data:`casflex.lab.checks.MAX_MISFIT`, 0.1 m: no soft-tissue artefact is that large)."""

    max_gap: float = 0.1
    max_misfit: float | None = None

    def __post_init__(self) -> None:
        if not (_number(self.max_gap) and self.max_gap >= 0):
            raise OptionRefused("max_gap", f"must be a time >= 0 s, got {self.max_gap!r}")
        if self.max_misfit is not None and not (_number(self.max_misfit) and self.max_misfit > 0):
            raise OptionRefused("max_misfit", f"must be a distance > 0 m, got {self.max_misfit!r}")
        if self.max_misfit is not None and self.max_misfit > MAX_MISFIT_LIMIT:
            raise OptionRefused("max_misfit", f"must be at most {MAX_MISFIT_LIMIT:g} m (a marker farther than that "
                                f"is no marker of the subject: the limit is in m, not mm), got {self.max_misfit!r}")

    @property
    def misfit(self) -> float:
        """The largest misfit taken, m (the default where None)."""
        from casflex.lab.checks import MAX_MISFIT

        return MAX_MISFIT if self.max_misfit is None else float(self.max_misfit)


@dataclass(frozen=True)
class Bands:
    """Each load's band, one standard deviation (:mod:`casflex.inverse.bands`; rigid segments).

    uncertain : :class:`casflex.scene.Uncertain` properties (a segment's ``mass`` or ``inertia`` from an
        anthropometric table) added to the scene's ``[[uncertain]]`` (replacing those of the same target).
    marker_noise : m, the markers' noise per axis (standard deviation; 0: exact); None: the fit's residuals'.
    asked : None: bands when an uncertain property or ``marker_noise`` is declared; True: always (the markers'
        part alone when nothing is uncertain); False: never (then neither may be given).
    """

    uncertain: Sequence[Any] | None = None
    marker_noise: float | None = None
    asked: bool | None = None

    def __post_init__(self) -> None:
        if self.asked not in (None, True, False):
            raise BandError("bands", f"expected True, False or None (when declared), got {self.asked!r}")
        if self.asked is False and (self.uncertain or self.marker_noise is not None):
            raise BandError("bands", "not asked (False), yet uncertain or marker_noise is given: they ask for bands")
        if self.marker_noise is not None and not (_number(self.marker_noise) and self.marker_noise >= 0):
            raise BandError("marker_noise", f"must be a distance >= 0 m (0: the markers exact), got "
                                            f"{self.marker_noise!r}")


@dataclass(frozen=True)
class Flexible:
    """The HHT run of a scene with flexible segments (beams; :mod:`casflex.inverse.flexible`): ``dt`` s, the largest
    time step (None: the scene's; made to divide the frames' interval), ``alpha`` HHT's (-1/3 to 0; None: the
    scene's) and ``compiled``: run generated and compiled C."""

    dt: float | None = None
    alpha: float | None = None
    compiled: bool = False

    def __post_init__(self) -> None:
        if self.dt is not None and not (_number(self.dt) and self.dt > 0):
            raise OptionRefused("dt", f"must be a positive number of seconds, got {self.dt!r}")
        if self.alpha is not None and not (_number(self.alpha) and -1.0 / 3.0 - 1e-12 <= self.alpha <= 0.0):
            raise OptionRefused("alpha", f"HHT alpha must lie in [-1/3, 0] (0: no numerical damping), got "
                                         f"{self.alpha!r}")
        if not isinstance(self.compiled, bool):
            raise OptionRefused("compiled", f"expected True or False, got {self.compiled!r}")

    def of(self, scene: Any) -> tuple[float, float]:
        """(dt, alpha): these, or the scene's run settings where None."""
        return (scene.run.dt if self.dt is None else self.dt, scene.run.alpha if self.alpha is None else self.alpha)
