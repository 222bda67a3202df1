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

from tests.hamner_so import DATA, both_static_optimizations

needs_opensim = pytest.mark.skipif(importlib.util.find_spec("opensim") is None, reason="OpenSim is not installed")

DEGROOTE = ("soleus_r", "tib_post_r")
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
    from casflex.scene.from_osim import scene_from_osim

    tmp = tmp_path_factory.mktemp("hamner_degroote")
    model = _degroote_model(tmp / "degroote.osim")
    assert [m.kind for m in scene_from_osim(model, muscles=True).muscles if m.name in DEGROOTE] == \
        ["DeGrooteFregly2016Muscle"] * 2
    return both_static_optimizations(model, tmp, (("hip_r", "femur_r"),))


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
