"""Joints of a trajectory: which linear springs and torsion springs a joint designation means."""

from __future__ import annotations

import re
from collections.abc import Sequence

from casflex.results import Trajectory


def _joint_catalogue(traj: Trajectory) -> tuple[list[str], list[str]]:
    """Names of the linear springs and of the torsion springs with outputs in ``traj``."""
    outs = set(traj.output_names)
    springs, torsions = [], []
    for name in traj.output_names:
        owner, _, key = name.rpartition(".")
        if key == "force" and {f"{owner}.fx", f"{owner}.fy"} <= outs and owner not in springs:
            springs.append(owner)
        elif key == "moment" and owner not in torsions:
            torsions.append(owner)
    return springs, torsions


def _trailing_number(name: str) -> str | None:
    m = re.search(r"(\d+)$", name)
    return m.group(1) if m else None


def joint_elements(traj: Trajectory, element: str | int | Sequence[str]) -> tuple[list[str], list[str]]:
    """Resolve a joint designation to (linear spring names, torsion spring names).

    ``element`` is a spring or torsion spring name (``"spring1"``), a joint number as in the
    paper (``"1"`` or ``1``: every spring and torsion spring whose name ends in that number,
    e.g. ``spring1`` and ``torsion1``), or a list of such. Raises ValueError naming the
    available joints when nothing matches.
    """
    springs, torsions = _joint_catalogue(traj)
    keys = [element] if isinstance(element, (str, int)) else list(element)
    chosen: list[str] = []
    for key in keys:
        key = str(key)
        if key in springs or key in torsions:
            found = [key]
        else:
            found = [e for e in springs + torsions if _trailing_number(e) == key]
        if not found:
            numbers: dict[str, list[str]] = {}
            for e in springs + torsions:
                n = _trailing_number(e)
                if n is not None:
                    numbers.setdefault(n, []).append(e)
            listing = "; ".join(f"{n!r} ({', '.join(v)})" for n, v in numbers.items()) or "none"
            raise ValueError(
                f"unknown joint element {key!r}. Available joints by number: {listing}; "
                f"or by name: springs {springs}, torsion springs {torsions}"
            )
        chosen += [e for e in found if e not in chosen]
    return [e for e in chosen if e in springs], [e for e in chosen if e in torsions]
