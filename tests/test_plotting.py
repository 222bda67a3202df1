"""casflex.plotting: every figure and the animation are written (atomically, valid PNG/GIF),
carry the expected lines, labels and units, and bad names fail with helpful messages."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import pendulum
from matplotlib.figure import Figure
from PIL import Image

import casflex
from casflex import plotting
from casflex.simulate import simulate

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def twobar():
    model = casflex.assemble(casflex.load_scene("twobar"))
    return model, simulate(model, 0.2, dt=1e-3)


@pytest.fixture(scope="module")
def twobar_soft(twobar):
    model, _ = twobar
    return simulate(model, 0.2, dt=1e-3, p={"k1": 500.0, "kt1": 0.3})


def assert_png(path: Path) -> None:
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC and len(data) > 1000, path


def assert_clean(directory: Path) -> None:
    """No temporary files left behind by the atomic writes."""
    leftovers = [p.name for p in directory.rglob("*") if p.name.startswith(".") or ".tmp" in p.name]
    assert not leftovers, leftovers


def legend_texts(ax) -> list[str]:
    leg = ax.get_legend()
    return [t.get_text() for t in leg.get_texts()] if leg else []


# -- time histories ---------------------------------------------------------------------------

@pytest.mark.parametrize(("kind", "units"), [("q", ("m", "m", "rad")), ("qd", ("m/s", "m/s", "rad/s")),
                                             ("qdd", ("m/s$^2$", "m/s$^2$", "rad/s$^2$"))])
def test_plot_node(twobar, tmp_path, kind, units):
    _, tr = twobar
    path = tmp_path / f"node5_{kind}.png"
    fig = plotting.plot_node(tr, "5", kind=kind, path=path)
    assert isinstance(fig, Figure)
    assert_png(path)
    assert_clean(tmp_path)
    axes = fig.axes
    assert len(axes) == 3
    for ax, unit, d in zip(axes, units, ("x", "y", "theta"), strict=True):
        assert len(ax.lines) == 1
        assert ax.get_ylabel().endswith(f"({unit})")
        np.testing.assert_array_equal(ax.lines[0].get_ydata(), getattr(tr, kind)[:, tr.dof_names.index(f"{d}5")])
    assert axes[-1].get_xlabel() == "time t (s)"
    assert "node 5" in fig.get_suptitle()


def test_plot_node_errors(twobar):
    _, tr = twobar
    with pytest.raises(ValueError, match=r"unknown node '9'; nodes are \['1', '2', '3', '4', '5'\]"):
        plotting.plot_node(tr, "9")
    with pytest.raises(ValueError, match="kind: expected one of"):
        plotting.plot_node(tr, "5", kind="v")


def test_plot_energies(twobar, tmp_path):
    _, tr = twobar
    path = tmp_path / "energies.png"
    fig = plotting.plot_energies(tr, path)
    assert_png(path)
    top, bottom = fig.axes
    assert len(top.lines) == 4 and len(bottom.lines) == 1  # no external loads: no work line
    assert legend_texts(top) == ["kinetic", "elastic (springs, beams)", "gravity potential", "total"]
    assert legend_texts(bottom) == ["removed by numerical damping"]
    assert top.get_ylabel() == bottom.get_ylabel() == "energy (J)"
    np.testing.assert_array_equal(top.lines[3].get_ydata(), tr.energies["total"])


def test_plot_energies_with_loads(tmp_path):
    tr = simulate(pendulum(2, load=(1.0, 0.0, 0.0)), 0.05, dt=1e-3)
    fig = plotting.plot_energies(tr, tmp_path / "e.png")
    assert len(fig.axes[1].lines) == 2
    assert "work of external loads" in legend_texts(fig.axes[1])


@pytest.mark.parametrize("element", ["1", 1])
def test_plot_joint_forces_by_number(twobar, tmp_path, element):
    _, tr = twobar
    path = tmp_path / "joint1.png"
    fig = plotting.plot_joint_forces(tr, element, path=path)
    assert_png(path)
    forces, moment = fig.axes
    assert len(forces.lines) == 3 and len(moment.lines) == 1
    assert forces.get_ylabel() == "force (N)" and moment.get_ylabel() == "moment (N m)"
    np.testing.assert_array_equal(forces.lines[0].get_ydata(), tr.output("spring1.force"))
    np.testing.assert_array_equal(forces.lines[1].get_ydata(), tr.output("spring1.fx"))
    np.testing.assert_array_equal(forces.lines[2].get_ydata(), tr.output("spring1.fy"))
    np.testing.assert_array_equal(moment.lines[0].get_ydata(), tr.output("torsion1.moment"))
    assert "joint 1" in fig.get_suptitle()


def test_plot_joint_forces_by_name(twobar):
    _, tr = twobar
    fig = plotting.plot_joint_forces(tr, "spring3")
    assert len(fig.axes) == 1 and len(fig.axes[0].lines) == 3
    fig = plotting.plot_joint_forces(tr, "torsion3")
    assert len(fig.axes) == 1 and len(fig.axes[0].lines) == 1
    assert fig.axes[0].get_ylabel() == "moment (N m)"
    fig = plotting.plot_joint_forces(tr, ["spring1", "torsion3"])
    assert [len(ax.lines) for ax in fig.axes] == [3, 1]


def test_plot_joint_forces_unknown(twobar):
    _, tr = twobar
    with pytest.raises(ValueError) as exc:
        plotting.plot_joint_forces(tr, "7")
    msg = str(exc.value)
    assert "unknown joint element '7'" in msg
    assert "'1' (spring1, torsion1)" in msg and "'3' (spring3, torsion3)" in msg
    with pytest.raises(ValueError, match="springs \\['spring1', 'spring3'\\]"):
        plotting.plot_joint_forces(tr, "bar2")


def test_plot_comparison(twobar, twobar_soft, tmp_path):
    _, tr = twobar
    runs = {"nominal": tr, "k1 = 500 N/m": twobar_soft}
    path = tmp_path / "cmp.png"
    names = ["y5", "qd:y5", "qdd:theta5", "spring1.force", "torsion1.moment", "energy:total"]
    fig = plotting.plot_comparison(runs, names, path=path)
    assert_png(path)
    assert len(fig.axes) == len(names)
    assert all(len(ax.lines) == 2 for ax in fig.axes)
    assert legend_texts(fig.axes[0]) == list(runs)
    units = ["(m)", "(m/s)", "(rad/s$^2$)", "(N)", "(N m)", "(J)"]
    for ax, unit in zip(fig.axes, units, strict=True):
        assert ax.get_ylabel().endswith(unit), ax.get_ylabel()
    np.testing.assert_array_equal(fig.axes[1].lines[1].get_ydata(), twobar_soft.qd[:, tr.dof_names.index("y5")])
    # kind applies to plain dof names
    fig = plotting.plot_comparison(runs, ["x5", "y5", "theta5"], kind="qdd")
    assert [ax.get_ylabel()[-9:] for ax in fig.axes] == ["(m/s$^2$)", "(m/s$^2$)", "ad/s$^2$)"]


def test_plot_comparison_errors(twobar):
    _, tr = twobar
    with pytest.raises(ValueError, match="unknown series 'z5'.*spring1.force"):
        plotting.plot_comparison({"a": tr}, ["z5"])
    with pytest.raises(ValueError, match="unknown dof 'y9'"):
        plotting.plot_comparison({"a": tr}, ["qd:y9"])
    with pytest.raises(ValueError, match="at least one"):
        plotting.plot_comparison({}, ["y5"])


# -- drawings and animation -------------------------------------------------------------------

def test_plot_configuration(twobar, tmp_path):
    model, tr = twobar
    path = tmp_path / "config.png"
    fig = plotting.plot_configuration(model, tr.q[-1], path=path)
    assert_png(path)
    ax = fig.axes[0]
    assert ax.get_aspect() == 1.0
    assert ax.get_xlabel() == "x (m)" and ax.get_ylabel() == "y (m)"
    assert legend_texts(ax) == ["beam", "spring", "torsion spring", "node", "clamp"]
    nodes = next(line for line in ax.lines if line.get_label() == "node")
    np.testing.assert_allclose(nodes.get_xdata(), tr.q[-1, 0::3])
    # into a given axes
    fig2 = Figure()
    ax2 = fig2.add_subplot()
    assert plotting.plot_configuration(model, None, ax2, legend=False) is fig2
    assert ax2.get_legend() is None and len(ax2.lines) == len(ax.lines)
    with pytest.raises(ValueError, match="q: expected 15 values"):
        plotting.plot_configuration(model, np.zeros(3))


def test_plot_configuration_mesh_and_pin(tmp_path):
    model = casflex.assemble(pendulum(4))
    fig = plotting.plot_configuration(model, path=tmp_path / "p.png")
    ax = fig.axes[0]
    assert legend_texts(ax) == ["beam", "node", "pin"]
    mesh = next(line for line in ax.lines if line.get_label() == "_mesh node")
    assert len(mesh.get_xdata()) == 3


def test_animate(twobar, tmp_path):
    model, tr = twobar
    path = tmp_path / "anim.gif"
    assert plotting.animate(model, tr, path, fps=25) == path
    assert path.read_bytes()[:6] in (b"GIF89a", b"GIF87a")
    with Image.open(path) as im:
        assert im.n_frames == 6  # 0.2 s at 25 frames/s, both ends
        assert im.info["duration"] == 40
        im.seek(0)
        first = np.asarray(im.convert("RGB"))
        im.seek(5)
        last = np.asarray(im.convert("RGB"))
    assert (first != last).any()  # the system moves
    assert (first == 255).all(axis=2).mean() > 0.5  # white background kept exactly
    assert_clean(tmp_path)
    # duration: playback length (slow motion here)
    plotting.animate(model, tr, path, fps=10, duration=1.0)
    with Image.open(path) as im:
        assert im.n_frames == 11
    assert_clean(tmp_path)


def test_animate_failure_leaves_old_file(twobar, tmp_path, monkeypatch):
    model, tr = twobar
    path = tmp_path / "anim.gif"
    path.write_bytes(b"old")
    calls = []

    def broken(self, art, q):
        calls.append(1)
        if len(calls) > 2:
            raise RuntimeError("boom")

    monkeypatch.setattr(plotting._Drawer, "update", broken)
    with pytest.raises(RuntimeError, match="boom"):
        plotting.animate(model, tr, path)
    assert path.read_bytes() == b"old"
    assert_clean(tmp_path)


def test_animate_checks_model(twobar, tmp_path):
    _, tr = twobar
    with pytest.raises(ValueError, match="not a motion of this model"):
        plotting.animate(casflex.assemble(pendulum(2)), tr, tmp_path / "a.gif")
    assert not list(tmp_path.iterdir())


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
    tr = simulate(model, 0.05, dt=1e-3)
    paths = plotting.save_standard_figures(model, tr, tmp_path, animation=False)
    assert [p.name for p in paths] == ["nodeend_q.png", "nodeend_qd.png", "nodeend_qdd.png",
                                       "configuration.png", "energies.png"]


def test_no_pyplot_state():
    """The module never imports pyplot (no global figure registry, no backend switch)."""
    code = (
        "import sys, casflex\n"
        "from casflex import plotting\n"
        "from casflex.simulate import simulate\n"
        "m = casflex.assemble(casflex.load_scene('twobar'))\n"
        "tr = simulate(m, 0.02, dt=1e-3)\n"
        "plotting.plot_node(tr); plotting.plot_energies(tr); plotting.plot_configuration(m, tr.q[-1])\n"
        "assert 'matplotlib.pyplot' not in sys.modules, 'pyplot imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)
