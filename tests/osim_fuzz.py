"""Corrupted copies of the repo's OpenSim models (tests/test_osim_fuzz.py): :func:`corrupt_osim` makes a seeded
copy with one to three of the faults a model file meets: an element deleted or duplicated, a number replaced by
NaN, inf, a huge or negative value or text, two sibling elements' tags swapped or their order, a name changed,
the file cut short. The worker of tests/lab_fuzz.py runs them (``casflex import`` and the reader's Python API).
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

import numpy as np

BAD_NUMBERS = (
    "NaN",
    "nan",
    "inf",
    "-inf",
    "1e300",
    "-1e300",
    "1e12",
    "-1",
    "-0.5",
    "0",
    "abc",
    "",
    "1,5",
    "0x10",
    "-1e-300",
    "3.5.1",
)
_NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")


def _elements(root: ET.Element) -> list[tuple[ET.Element, ET.Element]]:
    """(parent, child) of every element below the model."""
    return [(p, c) for p in root.iter() for c in p]


def _fault(root: ET.Element, rng: np.random.Generator) -> None:
    pairs = _elements(root)
    numeric = [(p, c) for p, c in pairs if c.text and _NUMBER.search(c.text) and not len(c)]
    kind = int(rng.integers(7))
    if kind in (0, 1) and numeric:  # a number replaced
        _, c = numeric[int(rng.integers(len(numeric)))]
        tokens = c.text.split()
        tokens[int(rng.integers(len(tokens)))] = str(rng.choice(BAD_NUMBERS))
        c.text = " ".join(tokens)
    elif kind == 2 and pairs:  # an element deleted
        p, c = pairs[int(rng.integers(len(pairs)))]
        p.remove(c)
    elif kind == 3 and pairs:  # an element duplicated (a body, a joint, a coordinate, a marker, a number ...)
        p, c = pairs[int(rng.integers(len(pairs)))]
        p.insert(list(p).index(c) + 1, _copy(c))
    elif kind == 4:  # two siblings' tags swapped, or their order
        parents = [p for p in root.iter() if len(p) >= 2]
        if parents:
            p = parents[int(rng.integers(len(parents)))]
            i, j = (int(v) for v in rng.choice(len(p), 2, replace=False))
            a, b = p[i], p[j]
            if rng.random() < 0.5:
                a.tag, b.tag = b.tag, a.tag
            else:
                p[i], p[j] = _copy(b), _copy(a)
    elif kind == 5:  # a name changed: to another's, empty or odd
        named = [c for _, c in pairs if c.get("name") is not None]
        if named:
            c = named[int(rng.integers(len(named)))]
            other = named[int(rng.integers(len(named)))].get("name")
            c.set("name", str(rng.choice((other, "", "a b", "x.y", "ground", "/bodyset/pelvis"))))
    elif numeric:  # a whole vector of numbers replaced by one bad value
        _, c = numeric[int(rng.integers(len(numeric)))]
        c.text = " ".join([str(rng.choice(BAD_NUMBERS))] * len(c.text.split()))


def _copy(e: ET.Element) -> ET.Element:
    return ET.fromstring(ET.tostring(e))


def corrupt_osim(text: str, seed: int) -> bytes:
    """A corrupted copy of an .osim file's text (module docstring), as bytes."""
    rng = np.random.default_rng(seed)
    root = ET.fromstring(text)
    for _ in range(int(rng.integers(1, 4))):
        _fault(root, rng)
    raw = b'<?xml version="1.0" encoding="UTF-8" ?>\n' + ET.tostring(root)
    if rng.random() < 0.07:  # cut short
        raw = raw[: int(rng.integers(len(raw)))]
    return raw
