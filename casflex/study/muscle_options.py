"""A study file's ``[options.muscles]`` as a value (:mod:`casflex.study.muscles` says what each key does):
checked when read by :func:`casflex.study.study_file.load_study`, each refusal a ValueError ``"<field>: <reason>"``
that the study file says as ``options.muscles.<field>``."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from casflex.muscles.options import UNCERTAIN_PROPERTIES, MuscleUncertainty

__all__ = ["KEYS", "MuscleOptions", "muscle_options"]

#: the keys of ``[options.muscles]``
KEYS = {"exponent", "force_length_velocity", "activation_bounds", "actuators", "reserves", "joints", "on", "frame",
        "uncertainty", "criteria"}


@dataclass(frozen=True)
class MuscleOptions:
    """``[options.muscles]``, checked: static optimization's ``exponent``, ``force_length_velocity`` and
    ``activation_bounds`` (None: each muscle kind's OpenSim default, a DeGrooteFregly2016Muscle's 0, 1, the
    others' 0.01, 1); the ``actuators`` file (resolved path) or ``reserves`` (N m); the reported ``joints``
    (() every hinge), the reactions' ``on`` and ``frame``; the muscles' ``uncertainty`` and the ``criteria``
    (exponents) for the bands."""

    exponent: float = 2.0
    force_length_velocity: bool = True
    activation_bounds: tuple[float, float] | None = None  # None: each muscle kind's OpenSim default
    actuators: str | None = None
    reserves: float | None = None
    joints: tuple[str, ...] = ()
    on: str = "child"
    frame: str = "ground"
    uncertainty: MuscleUncertainty = MuscleUncertainty()
    criteria: tuple[float, ...] = (3.0,)

    def optimization(self):
        """Static optimization's choices (:class:`~casflex.muscles.static_optimization.StaticOptimization`); a
        frame no activation satisfies is reported, the trial kept."""
        from casflex.muscles.static_optimization import StaticOptimization

        return StaticOptimization(exponent=self.exponent, force_length_velocity=self.force_length_velocity,
                                  activation_bounds=self.activation_bounds, infeasible="report")


def _number(where: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ValueError(f"{where}: expected a number, got {v!r}")
    return float(v)


def _uncertainty(table: Any) -> MuscleUncertainty:
    """``{property = "P%" or a fraction}`` as :class:`MuscleUncertainty`."""
    if not isinstance(table, dict):
        raise ValueError(f"uncertainty: expected a table PROPERTY = \"P%\" with PROPERTY among "
                         f"{list(UNCERTAIN_PROPERTIES)}, got {table!r}")
    given = {}
    for prop, v in table.items():
        if prop not in UNCERTAIN_PROPERTIES:
            raise ValueError(f"uncertainty.{prop}: unknown property; expected some of {list(UNCERTAIN_PROPERTIES)}")
        text = v.strip() if isinstance(v, str) else None
        try:
            given[prop] = float(text.removesuffix("%")) / (100.0 if text.endswith("%") else 1.0) if text is not None \
                else _number(f"uncertainty.{prop}", v)
        except ValueError:
            raise ValueError(f"uncertainty.{prop}: expected a relative SD (\"10%\" or 0.1), got {v!r}") from None
    try:
        return MuscleUncertainty(**given)
    except ValueError as exc:
        raise ValueError(f"uncertainty.{exc}") from None


def muscle_options(t: dict, actuators: str | None) -> MuscleOptions:
    """The table ``t`` (its keys among :data:`KEYS`, checked by the caller) with its ``actuators`` file resolved
    (or None), checked: ValueError ``"<field>: <reason>"``."""
    from casflex.muscles.reaction import JointReaction

    kw: dict[str, Any] = {"actuators": actuators}
    if "exponent" in t:
        kw["exponent"] = _number("exponent", t["exponent"])
    if "force_length_velocity" in t:
        if not isinstance(t["force_length_velocity"], bool):
            raise ValueError(f"force_length_velocity: expected true or false, got {t['force_length_velocity']!r}")
        kw["force_length_velocity"] = t["force_length_velocity"]
    if "activation_bounds" in t:
        b = t["activation_bounds"]
        if not isinstance(b, list) or len(b) != 2:
            raise ValueError(f"activation_bounds: expected [lower, upper], got {b!r}")
        kw["activation_bounds"] = tuple(_number("activation_bounds", v) for v in b)
    if "actuators" in t and "reserves" in t:
        raise ValueError("reserves: actuators gives the reserves; give one of them")
    if "reserves" in t:
        kw["reserves"] = _number("reserves", t["reserves"])
        if not kw["reserves"] > 0:
            raise ValueError(f"reserves: expected an optimal force > 0 (N m), got {t['reserves']!r}")
    joints = t.get("joints", [])
    if not isinstance(joints, list) or not joints or not all(isinstance(j, str) and j.strip() for j in joints):
        raise ValueError(f"joints: expected a list of joint names (leave the key out for every hinge), got {joints!r}")
    twice = [j for i, j in enumerate(joints) if j in joints[:i]]
    if twice:
        raise ValueError(f"joints: {twice[0]!r} given twice; give each joint once")
    kw["joints"] = tuple(joints)
    kw |= {k: t[k] for k in ("on", "frame") if k in t}
    if "uncertainty" in t:
        kw["uncertainty"] = _uncertainty(t["uncertainty"])
    crit = t.get("criteria", [2.0 if kw.get("exponent") == 3.0 else 3.0])  # the two criteria, p = 2 and 3
    if not isinstance(crit, list):
        raise ValueError(f"criteria: expected a list of exponents, got {crit!r}")
    kw["criteria"] = tuple(_number("criteria", p) for p in crit)
    opts = MuscleOptions(**kw)
    from casflex.muscles.static_optimization import MAX_EXPONENT  # here: it loads CasADi

    if any(not 1.0 <= p <= MAX_EXPONENT or p == opts.exponent for p in opts.criteria):
        raise ValueError(f"criteria: expected exponents >= 1 other than exponent ({opts.exponent:g}) and at most "
                         f"{MAX_EXPONENT:g}, got {list(opts.criteria)}")
    opts.optimization()  # each checks its fields: "<field>: <reason>"
    JointReaction(on=opts.on, frame=opts.frame)
    return opts
