"""A DeGrooteFregly2016Muscle's default activation bounds against OpenSim 4.6: a DeGroote muscle without its own
``min_control`` has 0 (``DeGrooteFregly2016Muscle().finalizeFromProperties(); getMinControl()``), a Thelen's or a
Millard's 0.01, and OpenSim's StaticOptimization bounds each muscle by its ``getMinControl()`` (StaticOptimization.cpp,
``record``); casflex's default does the same (:meth:`casflex.muscles.analysis.TrialMuscles._muscle_bounds`; it gave
every muscle 0.01 before). Hamner's subject 02 run (tests/data/muscles: the planar model, OpenSim's IK of the run, the
reserve file), 0.2-0.4 s, with soleus_r and tib_post_r turned into DeGrooteFregly2016Muscle (their Thelen curves'
properties dropped: DeGroote's defaults): soleus_r sits at its floor throughout the window (at 0.01 as a Thelen
muscle)."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import numpy as np
import pytest

needs_opensim = pytest.mark.skipif(importlib.util.find_spec("opensim") is None, reason="OpenSim is not installed")

DATA = Path(__file__).parent / "data" / "muscles"
LAB = Path(__file__).parent / "data" / "lab"
DEGROOTE = ("soleus_r", "tib_post_r")
T0, T1 = 0.2, 0.4
THELEN_ONLY = ("FmaxTendonStrain", "FmaxMuscleStrain", "KshapeActive", "KshapePassive", "Af", "Flen")


def _degroote_model(dest: Path) -> Path:
    """Hamner's planar model with :data:`DEGROOTE`'s muscles as DeGrooteFregly2016Muscle (path, max isometric force,
    optimal fibre, tendon slack length, pennation kept)."""
    text = (DATA / "hamner_subject02_planar_muscles.osim").read_text()
    for name in DEGROOTE:
        pattern = re.compile(rf'<Thelen2003Muscle name="{name}">(.*?)</Thelen2003Muscle>', re.S)
        body = pattern.search(text).group(1)
        for tag in THELEN_ONLY:
            body = re.sub(rf"<{tag}>[^<]*</{tag}>", "", body)
        m = pattern.search(text)
        text = f'{text[:m.start()]}<DeGrooteFregly2016Muscle name="{name}">{body}</DeGrooteFregly2016Muscle>' \
            f"{text[m.end():]}"
    dest.write_text(text)
    return dest


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    from casflex.inverse import Filter, prepare, solve
    from casflex.inverse import Trial as InverseTrial
    from casflex.lab.tables import read_sto
    from casflex.muscles.analysis import TrialMuscles
    from casflex.peers.opensim_analyses import Trial, static_optimization
    from casflex.peers.opensim_tools import exact_times, external_loads
    from casflex.scene.from_osim import scene_from_osim
    from casflex.scene.osim_actuators import read_actuators

    tmp = tmp_path_factory.mktemp("hamner_degroote")
    model = _degroote_model(tmp / "degroote.osim")
    coords = DATA / "hamner_run_ik.mot"
    grf = exact_times(LAB / "hamner_running_whole_grf.mot", tmp / "grf.mot", T0, 60.0)
    loads = external_loads(tmp / "loads.xml", grf, {"calcn_r": "ground_", "calcn_l": "1_ground_"})
    reserves = DATA / "hamner_reserve_actuators.xml"
    so = static_optimization(Trial(str(model), str(coords), loads=loads, forces=(str(reserves),), cutoff=10.0,
                                   t_start=T0, t_end=T1), tmp / "so", joints=["hip_r"], on="child", frame="child")
    osim = scene_from_osim(model, muscles=True)
    assert [m.kind for m in osim.muscles if m.name in DEGROOTE] == ["DeGrooteFregly2016Muscle"] * 2
    inputs = prepare(model, InverseTrial(coordinates=coords, grf=loads), filter=Filter(10.0, None, "opensim"))
    res = solve(inputs)
    trial = TrialMuscles(osim, inputs.tree, res.t, res.plates, read_actuators(reserves))
    out = trial.solve(res.z, res.zd, res.zdd)
    act, force = read_sto(so["activation"]), read_sto(so["force"])
    keep = [i for i, t in enumerate(act.t) if not any(abs(t - f) < 1e-6 for f in so["failed"])]
    rows = [int(np.argmin(np.abs(res.t - t))) for t in act.t[keep]]
    assert np.abs(res.t[rows] - act.t[keep]).max() < 1e-6
    names = [m.name for m in osim.muscles]
    return {"names": names, "trial": trial, "out": out, "rows": rows, "keep": keep, "failed": so["failed"],
            "act": np.column_stack([act.column(n) for n in names])[keep],
            "force": np.column_stack([force.column(n) for n in names])[keep]}


@needs_opensim
def test_a_degroote_muscle_s_floor_is_0_in_both(run):
    """soleus_r at its floor: 0 in casflex (its QP to 1e-10) and in OpenSim (within 1e-3: its interior point stops at
    its 1e-4 criterion, inside the bounds), where a Thelen muscle's floor is 0.01 in both; its force and the other
    DeGroote muscle's as OpenSim's (within 2 % of a 50 N peak, RMS over the solved frames)."""
    names, a, theirs = run["names"], run["out"].so.activations[run["rows"]], run["act"]
    assert len(run["keep"]) >= 8, run["failed"]
    i = names.index("soleus_r")
    assert a[:, i].min() == pytest.approx(0.0, abs=1e-8) and 0.0 - 1e-9 <= theirs[:, i].min() < 1e-3
    thelen = [k for k, n in enumerate(names) if n not in DEGROOTE]
    assert a[:, thelen].min() >= 0.01 - 1e-9 and theirs[:, thelen].min() >= 0.01 - 1e-9
    ours, forces = run["out"].so.forces[run["rows"]], run["force"]
    for name in DEGROOTE:
        k = names.index(name)
        rms = np.sqrt(np.mean((ours[:, k] - forces[:, k]) ** 2))
        assert rms < 0.02 * max(np.abs(forces[:, k]).max(), 50.0), (name, rms, np.abs(forces[:, k]).max())
    assert "soleus_r [0, 1]" in " ".join(run["trial"].notes)
