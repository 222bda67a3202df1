"""casflex.plotting.series: series names resolve to the trajectory's values with a label and a unit."""

from __future__ import annotations

import numpy as np
import pytest

from casflex.plotting import series


@pytest.mark.parametrize(("name", "kind", "attr", "label", "unit"), [
    ("y5", "q", "q", r"$y_{\mathrm{5}}$", "m"),
    ("theta5", "qd", "qd", r"$\dot{\theta}_{\mathrm{5}}$", "rad/s"),
    ("qdd:x5", "q", "qdd", r"$\ddot{x}_{\mathrm{5}}$", "m/s$^2$"),
])
def test_dof_series(twobar, name, kind, attr, label, unit):
    _, tr = twobar
    values, got_label, got_unit = series._series(tr, name, kind)
    dof = name.rpartition(":")[2]
    np.testing.assert_array_equal(values, getattr(tr, attr)[:, tr.dof_names.index(dof)])
    assert (got_label, got_unit) == (label, unit)


def test_output_and_energy_series(twobar):
    _, tr = twobar
    values, label, unit = series._series(tr, "torsion1.moment")
    np.testing.assert_array_equal(values, tr.output("torsion1.moment"))
    assert (label, unit) == ("torsion1.moment", "N m")
    values, label, unit = series._series(tr, "energy:total")
    np.testing.assert_array_equal(values, tr.energies["total"])
    assert (label, unit) == ("energy: total", "J")


def test_dof_symbol_without_mathtext():
    assert series._dof_symbol("x_a", "qd") == "d/dt x_a"
    assert series._dof_unit("theta_a", "qdd") == "rad/s$^2$"


def test_series_errors(twobar):
    _, tr = twobar
    with pytest.raises(ValueError, match="unknown prefix 'v'"):
        series._series(tr, "v:y5")
    with pytest.raises(ValueError, match="unknown energy 'heat'"):
        series._series(tr, "energy:heat")
    with pytest.raises(ValueError, match="kind: expected one of"):
        series._series(tr, "y5", "qqd")
