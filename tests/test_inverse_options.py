"""Inverse dynamics' choices as values (casflex.inverse.options): each refuses a bad value where it is made, naming
its field, and each caller says the refusal in its own names; the result is a frozen value made with named
fields."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from casflex.inverse import Bands, Filter, Fit, Flexible, InverseResult, OptionRefused, Trial
from casflex.inverse.options import BandError


@pytest.mark.parametrize(("make", "said"), [
    (lambda: Trial(), "markers, coordinates: give the trial's markers or its coordinates"),
    (lambda: Trial("t.trc", coordinates="ik.mot"), "markers, coordinates: give"),
    (lambda: Trial(coordinates="ik.mot", tasks="ik.xml"), "tasks: they weight the marker fit; with coordinates"),
    (lambda: Trial("t.trc", plane="X,X"), "plane: expected two different lab axes"),
    (lambda: Trial("t.trc", t_start=0.5, t_end=0.45), r"t_end: must be after t_start \(0.5 s\), got 0.45"),
    (lambda: Trial("t.trc", t_start=-1.0), "t_start: expected a time in s >= 0, got -1.0"),
    (lambda: Trial("t.trc", t_end=math.nan), "t_end: expected a time in s >= 0, got nan"),
    (lambda: Trial("t.trc", plates={"ankle": "ground_"}), r"plates: needs grf \(the ground reaction file\)"),
    (lambda: Trial("t.trc", grf="loads.xml", plates={"ankle": "ground_"}), "plates: loads.xml says which body"),
    (lambda: Trial("t.trc", grf="g.mot", plates={"ankle": ""}), "plates: expected node -> the plate's column"),
    (lambda: Filter(cutoff=0.0), r"cutoff: expected a frequency in Hz > 0 or none \(unfiltered\), got 0.0"),
    (lambda: Filter(cutoff="same"), "cutoff: expected a frequency in Hz > 0 or none"),
    (lambda: Filter(cutoff_plates=-3.0), "cutoff_plates: expected a frequency in Hz > 0 or none .* or 'same'"),
    (lambda: Filter(kind="spline"), "filter: one of butterworth, opensim, got 'spline'"),
    (lambda: Fit(max_misfit=0.0), "max_misfit: must be a distance > 0 m, got 0.0"),
    (lambda: Fit(max_misfit=150), r"max_misfit: must be at most 1 m .*in m, not mm\), got 150"),
    (lambda: Fit(max_gap=-0.1), "max_gap: must be a time >= 0 s"),
    (lambda: Bands(marker_noise=-1.0), "marker_noise: must be a distance >= 0 m"),
    (lambda: Bands(marker_noise=0.001, asked=False), r"bands: not asked \(False\), yet uncertain or marker_noise"),
    (lambda: Bands(asked="yes"), "bands: expected True, False or None"),
    (lambda: Flexible(dt=0.0), "dt: must be a positive number of seconds"),
    (lambda: Flexible(alpha=0.2), r"alpha: HHT alpha must lie in \[-1/3, 0\]"),
    (lambda: Flexible(compiled=1), "compiled: expected True or False"),
])
def test_each_value_refuses_a_bad_field_naming_it(make, said):
    with pytest.raises(OptionRefused, match=said) as err:
        make()
    assert "\n" not in str(err.value)


def test_the_values_take_what_they_did():
    trial = Trial("t.trc", grf="g.mot", plates={"ankle": "ground_"}, plane="-Z,Y", t_start=0.0, t_end=1.0)
    assert (trial.plane.x, trial.plane.y) == ("-Z", "Y") and not trial.given
    assert Trial(coordinates="ik.mot").given
    assert Filter().plates == 6.0 and Filter(10, None).plates is None and Filter(None).plates is None
    assert Filter().describe() == "coordinates filtered: Butterworth 4th order zero-lag at 6 Hz"
    assert Filter(None).describe() == "coordinates not filtered"
    assert Fit().misfit == 0.1 and Fit(max_misfit=0.03).misfit == 0.03
    with pytest.raises(dataclasses.FrozenInstanceError):
        trial.root = "pelvis"


def test_a_refusal_is_said_in_the_caller_s_names():
    """The command line names its flags, the study file its fields; the mentioned option too."""
    from casflex.cli.inverse import FLAGS

    with pytest.raises(OptionRefused) as err:
        Trial("t.trc", t_start=0.5, t_end=0.45)
    assert err.value.said(FLAGS) == "--t-end: must be after --t-start (0.5 s), got 0.45"
    assert err.value.said(lambda o: f"subjects[0].trials[1].{o}", {"t_start": "the window's start"}) == \
        "subjects[0].trials[1].t_end: must be after the window's start (0.5 s), got 0.45"
    with pytest.raises(OptionRefused) as err:
        Trial("/tmp/plates/loads.xml", grf="/tmp/plates/loads.xml", plates={"ankle": "ground_"})
    # a path that holds an option's name is left as it is
    assert err.value.said(FLAGS) == ("--plate: /tmp/plates/loads.xml says which body each plate acts on; give "
                                     "--plate or that file")
    with pytest.raises(BandError) as err:
        Bands(marker_noise=-1.0)
    assert err.value.said(FLAGS).startswith("--marker-noise: must be a distance >= 0 m")


def test_the_result_is_frozen_and_made_with_named_fields():
    t = np.linspace(0.0, 1.0, 3)
    z = np.zeros((3, 1))
    fields = dict(t=t, coordinate_names=("a",), z=z, zd=z, zdd=z, dof_names=("x1",), q=z, qd=z, qdd=z,
                  loads={"root.fx": t}, frame_t=t, marker_rms=t)
    res = InverseResult(**fields)
    assert res.load("root.fx") is t and res.report == [] and res.bands == {}
    with pytest.raises(TypeError):
        InverseResult(*fields.values())  # no positional construction
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.loads = {}
