"""Properties a scene knows only within an uncertainty (``[[uncertain]]``): a segment's mass or inertia from an
anthropometric table (10-20 %), a beam's E or density to a few percent, a damper, a rest angle.

Each is a Gaussian prior on the property: mean the scene's value and a standard deviation (``sd`` in the
property's unit, or ``relative`` to the value), or a ``range`` [lower, upper] read as its mean and standard
deviation (a uniform's: (upper - lower) / sqrt(12)) and held within it. Identification estimates them beside the
parameters, each with its prior (:mod:`casflex.identification.priors`): as nuisance unknowns, turned into
:class:`~casflex.scene.items.Parameter`\\ s with a ``prior`` by :func:`with_uncertain_estimated`. A standard
deviation of 0 declares the property exact: it stays a constant, as if it were not listed.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from casflex.scene.items import NONNEGATIVE_FIELDS, Parameter, SceneError, _non_negative, _number

__all__ = ["Uncertain", "check_uncertain", "with_uncertain_estimated", "declared_uncertain", "parse"]


@dataclass(frozen=True)
class Uncertain:
    """A scene property ``target`` (``"<element>.<field>"``, as a parameter's) with its uncertainty: exactly
    one of ``sd`` (standard deviation, the property's unit), ``relative`` (standard deviation over the scene's
    value, e.g. 0.1 for 10 %) or ``range`` ([lower, upper], the property's unit)."""

    target: str
    sd: float | None = None
    relative: float | None = None
    range: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        where = f"uncertain {self.target!r}"
        t = self.target
        if not isinstance(t, str) or t.count(".") != 1 or not all(t.partition(".")[::2]):
            raise SceneError.at(where, "target", f"expected '<element>.<field>', e.g. 'bar2.rho', got {t!r}")
        given = [f for f in ("sd", "relative", "range") if getattr(self, f) is not None]
        if len(given) != 1:
            raise SceneError.at(where, None, "give exactly one of sd, relative or range, got "
                                f"{', '.join(given) if given else 'none'}")
        for f in ("sd", "relative"):
            if getattr(self, f) is not None:
                object.__setattr__(self, f, _non_negative(where, f, getattr(self, f)))
        if self.range is not None:
            r = self.range
            if isinstance(r, str) or not isinstance(r, (list, tuple)) or len(r) != 2:
                raise SceneError.at(where, "range", f"expected [lower, upper], got {r!r}")
            lo, hi = (_number(where, f"range[{i}]", v) for i, v in enumerate(r))
            if lo >= hi:
                raise SceneError.at(where, "range", f"lower must be below upper, got [{lo:g}, {hi:g}]")
            object.__setattr__(self, "range", (lo, hi))

    @property
    def name(self) -> str:
        """The name of its nuisance parameter: the target with '_' for '.' (``bar2.rho`` -> ``bar2_rho``)."""
        return self.target.replace(".", "_")

    def prior(self, value: float) -> tuple[float, float]:
        """(mean, standard deviation) of the property whose scene value is ``value``."""
        if self.range is not None:
            lo, hi = self.range
            return 0.5 * (lo + hi), (hi - lo) / math.sqrt(12.0)
        return value, (self.sd if self.sd is not None else abs(value) * float(self.relative))

    def parameter(self, value: float) -> Parameter:
        """Its nuisance parameter (prior, bounds: the range, else the target's defaults)."""
        mean, sd = self.prior(value)
        lo, hi = self.range if self.range is not None else (None, math.inf)
        return Parameter(self.name, self.target, lower=lo, upper=hi, scale=max(abs(mean), sd), prior=(mean, sd))


def parse(text: str) -> Uncertain:
    """The :class:`Uncertain` of ``TARGET=SD``, ``TARGET=P%`` (relative) or ``TARGET=LOWER:UPPER`` (the command
    line's and a study file's form); ValueError in one line otherwise."""
    target, eq, value = (x.strip() for x in str(text).partition("="))
    try:
        if not (eq and target and value):
            raise ValueError
        if ":" in value:
            lo, _, hi = value.partition(":")
            return Uncertain(target, range=(float(lo), float(hi)))
        if value.endswith("%"):
            return Uncertain(target, relative=float(value[:-1]) / 100)
        return Uncertain(target, sd=float(value))
    except SceneError as exc:
        raise ValueError(f"{text!r}: {exc.reason}") from None
    except ValueError:
        raise ValueError(f"expected TARGET=SD, TARGET=PERCENT% or TARGET=LOWER:UPPER, e.g. shank.mass=10%, got "
                         f"{text!r}") from None


def check_uncertain(scene: Any) -> None:
    """SceneError naming the entry: an unknown target, one listed twice or also a parameter, a relative
    uncertainty of a zero value, a scene value outside its range, a range below 0 for a non-negative property."""
    fitted = {p.target: p.name for p in scene.parameters}
    names = {p.name for p in scene.parameters}
    seen: set[str] = set()
    for i, u in enumerate(scene.uncertain):
        where = f"uncertain[{i}] ({u.target})"
        if not isinstance(u, Uncertain):
            raise SceneError(f"uncertain[{i}]: expected an Uncertain, got {type(u).__name__}")
        if u.target in seen:
            raise SceneError(f"{where}.target: listed twice")
        seen.add(u.target)
        if u.target in fitted:
            raise SceneError(f"{where}.target: it is parameter {fitted[u.target]!r}, fitted without a prior; declare "
                             "it one or the other")
        if u.name in names:
            raise SceneError(f"{where}: its estimate's name {u.name!r} is a parameter's; rename that parameter")
        value = scene.property_value(u.target, where=f"{where}.target")
        if u.relative is not None and u.relative > 0 and value == 0:
            raise SceneError(f"{where}.relative: the scene's value is 0; give sd (in the property's unit) instead")
        if u.range is not None:
            lo, hi = u.range
            if not lo <= value <= hi:
                raise SceneError(f"{where}.range: the scene's value {value:g} lies outside [{lo:g}, {hi:g}]")
            if lo < 0 and u.target.partition(".")[2] in NONNEGATIVE_FIELDS:
                raise SceneError(f"{where}.range: {u.target} is never negative, got lower {lo:g}")


def declared_uncertain(scene: Any, uncertain: Any = None) -> Any:
    """The scene with the caller's uncertain properties (``uncertain``: Uncertain entries, each replacing the
    scene's of the same target) added to its own; a ValueError in one line names the offending entry."""
    extra = list(uncertain or ())
    for u in extra:
        if not isinstance(u, Uncertain):
            raise ValueError(f"uncertain: expected casflex.scene.Uncertain entries, got {u!r}")
    given = {u.target for u in extra}
    merged = tuple(u for u in scene.uncertain if u.target not in given) + tuple(extra)
    try:
        return dataclasses.replace(scene, uncertain=merged)
    except SceneError as exc:
        raise ValueError(str(exc)) from None


def with_uncertain_estimated(scene: Any) -> Any:
    """The scene with each uncertain property of non-zero standard deviation appended to its parameters as a
    nuisance parameter with its prior (:meth:`Uncertain.parameter`), and no ``uncertain`` list left."""
    extra = tuple(u.parameter(scene.property_value(u.target)) for u in scene.uncertain
                  if u.prior(scene.property_value(u.target))[1] > 0)
    return dataclasses.replace(scene, parameters=scene.parameters + extra, uncertain=())


def nuisance_names(scene: Any) -> tuple[str, ...]:
    """The names of the nuisance parameters :func:`with_uncertain_estimated` adds (those of sd > 0)."""
    return tuple(u.name for u in scene.uncertain if u.prior(scene.property_value(u.target))[1] > 0)
