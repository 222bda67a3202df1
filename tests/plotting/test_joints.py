"""casflex.plotting.joints: joint designations (name, number, list) resolve to the springs and
torsion springs with outputs in the trajectory; unknown ones list what is available."""

from __future__ import annotations

import pytest

from casflex.plotting import joints


@pytest.mark.parametrize(("element", "expected"), [
    ("1", (["spring1"], ["torsion1"])),
    (3, (["spring3"], ["torsion3"])),
    ("spring3", (["spring3"], [])),
    ("torsion1", ([], ["torsion1"])),
    (["torsion3", "1", "spring1"], (["spring1"], ["torsion3", "torsion1"])),
])
def test_joint_elements(twobar, element, expected):
    _, tr = twobar
    assert joints.joint_elements(tr, element) == expected


def test_joint_elements_unknown(twobar):
    _, tr = twobar
    with pytest.raises(ValueError, match=r"unknown joint element '2'.*'1' \(spring1, torsion1\)"):
        joints.joint_elements(tr, ["1", "2"])


def test_trailing_number():
    assert joints._trailing_number("spring12") == "12"
    assert joints._trailing_number("spring") is None
