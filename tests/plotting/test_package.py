"""casflex.plotting (the package): the standard set of figures, the names it re-exports, and its
import-time behaviour (matplotlib only when plotting is imported, never pyplot)."""

from __future__ import annotations

import subprocess
import sys

import pytest
from conftest import pendulum
from PIL import Image

import casflex
from casflex import plotting
from casflex.simulate import Stepping, simulate

from .helpers import assert_clean, assert_png


def test_save_standard_figures(twobar, tmp_path):
    model, tr = twobar
    out = tmp_path / "plots"
    paths = plotting.save_standard_figures(model, tr, out)
    names = [p.name for p in paths]
    assert names == ["node5_q.png", "node5_qd.png", "node5_qdd.png", "configuration.png", "energies.png",
                     "joint1.png", "joint3.png", "animation.gif"]
    assert sorted(p.name for p in out.iterdir()) == sorted(names)
    for p in paths[:-1]:
        assert_png(p)
    with Image.open(paths[-1]) as im:
        assert im.n_frames > 1
    assert_clean(out)


def test_save_standard_figures_other_scene(tmp_path):
    model = casflex.assemble(pendulum(2))
    tr = simulate(model, 0.05, stepping=Stepping(dt=1e-3))
    paths = plotting.save_standard_figures(model, tr, tmp_path, animation=False)
    assert [p.name for p in paths] == ["nodeend_q.png", "nodeend_qd.png", "nodeend_qdd.png",
                                       "configuration.png", "energies.png"]


def test_no_pyplot_state():
    """The module never imports pyplot (no global figure registry, no backend switch)."""
    code = (
        "import sys, casflex\n"
        "from casflex import plotting\n"
        "from casflex.simulate import Stepping, simulate\n"
        "m = casflex.assemble(casflex.load_scene('twobar'))\n"
        "tr = simulate(m, 0.02, stepping=Stepping(dt=1e-3))\n"
        "plotting.plot_node(tr); plotting.plot_energies(tr); plotting.plot_configuration(m, tr.q[-1])\n"
        "assert 'matplotlib.pyplot' not in sys.modules, 'pyplot imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


@pytest.mark.parametrize(("name", "module"), [
    ("plot_node", "time_series"), ("plot_energies", "time_series"), ("plot_joint_forces", "time_series"),
    ("plot_comparison", "time_series"), ("plot_configuration", "configuration"), ("animate", "animation"),
    ("joint_elements", "joints"), ("KINDS", "series"), ("DPI", "_figure"), ("_Drawer", "configuration"),
])
def test_reexports(name, module):
    """Every name the single-module ``casflex.plotting`` offered is still there, as the submodule's object."""
    sub = __import__(f"casflex.plotting.{module}", fromlist=[name])
    assert getattr(plotting, name) is getattr(sub, name)


def test_all_is_importable():
    assert plotting.__all__ == ["plot_node", "plot_energies", "plot_joint_forces", "plot_comparison",
                                "plot_configuration", "animate", "save_standard_figures", "joint_elements", "KINDS"]
    for name in plotting.__all__:
        assert hasattr(plotting, name), name


def test_casflex_does_not_import_plotting():
    """``import casflex`` (and the CLI module) stay free of matplotlib; plotting loads it on import."""
    code = (
        "import sys, casflex, casflex.cli\n"
        "assert not any(m.startswith(('matplotlib', 'casflex.plotting')) for m in sys.modules), 'eager import'\n"
        "import casflex.plotting\n"
        "assert 'matplotlib' in sys.modules\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)
