"""A study's records as typed values: what a subject's calibration and a trial's run give
(:mod:`casflex.study.runner`), made by the workers and read by the table, the figures and the summary
(``casflex study``). On disk each is the JSON of :meth:`to_json` (the record files' format: the sweep writes a
worker's dict, :mod:`casflex.study.sweep`), read back by :meth:`from_json`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

__all__ = ["Calibration", "CycleLoad", "MuscleRecord", "PassiveFit", "TrialRecord"]


@dataclass(frozen=True)
class Calibration:
    """A subject's scene (TOML text), placed on its static trial and scaled to its mass as asked, and the report."""

    scene: str
    report: tuple[str, ...] = ()

    def to_json(self) -> dict:
        return {"scene": self.scene, "report": list(self.report)}

    @classmethod
    def from_json(cls, d: dict) -> Calibration:
        return cls(d["scene"], tuple(d.get("report", ())))


@dataclass(frozen=True)
class CycleLoad:
    """One load over a trial's gait cycles: the ``foot`` whose strikes cut it (None: no foot walks), each cycle's
    [t0, t1] s, whether its stance is wholly on the foot's plate (``clean``; empty where a record does not say),
    its ``value`` and ``band`` (1 SD, None: not asked) on 0-100 % of each cycle (N m or N, per kg where
    normalised)."""

    foot: str | None
    cycles: tuple[tuple[float, float], ...]
    clean: tuple[bool, ...]
    value: tuple[tuple[float, ...], ...]
    band: tuple[tuple[float, ...], ...] | None = None

    def to_json(self) -> dict:
        return {"foot": self.foot, "cycles": [list(c) for c in self.cycles], "clean": list(self.clean),
                "value": [list(v) for v in self.value],
                "band": None if self.band is None else [list(b) for b in self.band]}

    @classmethod
    def from_json(cls, d: dict) -> CycleLoad:
        band = d.get("band")
        return cls(d["foot"], tuple(tuple(c) for c in d["cycles"]), tuple(d.get("clean") or ()),
                   tuple(tuple(v) for v in d["value"]), None if band is None else tuple(tuple(b) for b in band))

    def per(self, mass: float) -> CycleLoad:
        """The values and bands divided by ``mass`` (kg)."""
        return replace(self, value=tuple(tuple(v / mass for v in c) for c in self.value),
                       band=None if self.band is None else tuple(tuple(b / mass for b in c) for c in self.band))


#: A passive fit's estimates, in the record's order (:func:`casflex.inverse.passive.fit_passive`).
_ESTIMATES = ("kt", "ct", "rest_angle", "se", "r2", "n_effective", "passive", "why")


@dataclass(frozen=True)
class PassiveFit:
    """A spring-damper fitted to a hinge's net moment over a ``window`` [t0, t1] s (None: no window to fit) of the
    trial (``phase`` "trial") or of a swing phase ("swing"): its estimates (``kt`` N m/rad, ``ct`` N m s/rad,
    ``rest_angle`` rad, their standard errors ``se``, the share explained ``r2``, the independent samples, the
    verdict ``passive`` and ``why``), or the ``error`` that kept it from being fitted."""

    hinge: str
    phase: str
    window: tuple[float, float] | None
    error: str | None = None
    kt: float | None = None
    ct: float | None = None
    rest_angle: float | None = None
    se: dict[str, float] = field(default_factory=dict)
    r2: float | None = None
    n_effective: float | None = None
    passive: bool | None = None
    why: tuple[str, ...] = ()

    def to_json(self) -> dict:
        head = {"hinge": self.hinge, "phase": self.phase, "window": None if self.window is None else list(self.window)}
        if self.error is not None:
            return head | {"error": self.error}
        return head | {k: list(getattr(self, k)) if k == "why" else getattr(self, k) for k in _ESTIMATES}

    @classmethod
    def from_json(cls, d: dict) -> PassiveFit:
        window = None if d.get("window") is None else tuple(d["window"])
        if "error" in d:
            return cls(d["hinge"], d["phase"], window, error=d["error"])
        return cls(d["hinge"], d["phase"], window, **{k: tuple(d[k]) if k == "why" else d[k] for k in _ESTIMATES})


@dataclass(frozen=True)
class TrialRecord:
    """A trial's run: the ``plates`` (node -> prefix) and the ``plane`` it was run with, the ``report`` and the
    ``warnings``, each load over the gait cycles (``loads``), the window run ``t`` [t0, t1] s and the passive
    fits asked; ``angles``: each joint's angle (deg, the lab's coordinate, filtered) over its moment's cycles;
    ``toe_off``: foot -> each of its cycles' toe-off, % of the cycle (None: not found)."""

    plates: dict[str, str | list[str]] | None
    plane: str
    report: tuple[str, ...]
    warnings: tuple[str, ...]
    loads: dict[str, CycleLoad]
    t: tuple[float, float]
    passive: tuple[PassiveFit, ...] = ()
    angles: dict[str, CycleLoad] = field(default_factory=dict)
    toe_off: dict[str, tuple[float | None, ...]] = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"plates": self.plates, "plane": self.plane, "report": list(self.report),
                "warnings": list(self.warnings), "loads": {k: v.to_json() for k, v in self.loads.items()},
                "t": list(self.t), "passive": [p.to_json() for p in self.passive],
                "angles": {k: v.to_json() for k, v in self.angles.items()},
                "toe_off": {k: list(v) for k, v in self.toe_off.items()}}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> TrialRecord:
        return cls(d["plates"], d["plane"], tuple(d["report"]), tuple(d["warnings"]),
                   {k: CycleLoad.from_json(v) for k, v in d["loads"].items()}, tuple(d["t"]),
                   tuple(PassiveFit.from_json(p) for p in d.get("passive", ())),
                   {k: CycleLoad.from_json(v) for k, v in d.get("angles", {}).items()},
                   {k: tuple(v) for k, v in d.get("toe_off", {}).items()})


@dataclass(frozen=True)
class MuscleRecord:
    """A trial's muscles (:mod:`casflex.study.muscles`): the ``report`` and ``warnings``, each output (a joint's
    reaction component or resultant, a muscle's activation) over the gait cycles (``outputs``, in ``units``: BW,
    BW m or 1) and the subject's ``body_weight`` (N) they are divided by."""

    report: tuple[str, ...]
    warnings: tuple[str, ...]
    outputs: dict[str, CycleLoad]
    units: dict[str, str]
    body_weight: float

    def to_json(self) -> dict:
        return {"report": list(self.report), "warnings": list(self.warnings),
                "outputs": {k: v.to_json() for k, v in self.outputs.items()}, "units": dict(self.units),
                "body_weight": self.body_weight}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> MuscleRecord:
        return cls(tuple(d["report"]), tuple(d["warnings"]), {k: CycleLoad.from_json(v) for k, v in
                                                               d["outputs"].items()}, dict(d["units"]),
                   float(d["body_weight"]))
