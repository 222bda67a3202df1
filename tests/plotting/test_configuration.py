"""casflex.plotting.configuration: drawings of a configuration (new figure or given axes), legend
entries, node positions, and the check of q."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import pendulum
from matplotlib.figure import Figure

import casflex
from casflex import plotting

from .helpers import assert_png, legend_texts


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


def test_plot_configuration_draws_markers_and_bodies_where_they_are():
    # the leg: five markers (on both beams and the foot) and the foot's centre of mass, in a turned state
    model = casflex.assemble(casflex.load_scene("leg"))
    q = model.q0.copy()
    q[model.dof("thetaankle")] += 0.4
    ax = plotting.plot_configuration(model, q).axes[0]
    assert legend_texts(ax) == ["beam", "rigid link", "spring", "torsion spring", "node",
                                "rigid body (centre of mass)", "marker", "clamp"]
    from casflex.model.markers import marker_positions

    markers = next(line for line in ax.lines if line.get_label() == "marker")
    np.testing.assert_allclose(np.column_stack([markers.get_xdata(), markers.get_ydata()]),
                               marker_positions(model, q).reshape(-1, 2))
    foot = model.scene.bodies[0]
    a = model.node_names.index(foot.node)
    r = np.array([foot.com_x - model.q0[3 * a], foot.com_y - model.q0[3 * a + 1]])
    c, s = np.cos(0.4), np.sin(0.4)
    body = next(line for line in ax.lines if line.get_label().startswith("rigid body"))
    np.testing.assert_allclose([body.get_xdata()[0], body.get_ydata()[0]],
                               q[3 * a:3 * a + 2] + np.array([[c, -s], [s, c]]) @ r)


def test_rigid_links_drawn_to_the_joints_they_carry():
    # leg_rigid turned at the hip: the thigh's link runs from the hip to the knee bushing's end on it,
    # which meets the shank's node; the knee's torsion spring is drawn there, not mid-thigh
    model = casflex.assemble(casflex.load_scene("leg_rigid"))
    q = model.q0.copy()
    q[model.dof("thetahip")] += 0.3
    ax = plotting.plot_configuration(model, q).axes[0]
    knee = model.scene.springs[1].point_a
    hip = model.q0[model.dof("xhip"):model.dof("xhip") + 2]
    c, s = np.cos(0.3), np.sin(0.3)
    at_knee = hip + np.array([[c, -s], [s, c]]) @ (np.array(knee) - hip)
    link = next(line for line in ax.lines if line.get_label() == "rigid link")
    pts = np.column_stack([link.get_xdata(), link.get_ydata()])
    assert np.isclose(pts, at_knee, atol=1e-12).all(axis=1).any()  # the thigh's end, turned with the hip
    ring = next(line for line in ax.lines if line.get_label() == "torsion spring")
    rings = np.column_stack([ring.get_xdata(), ring.get_ydata()])
    kn = q[model.dof("xknee_s"):model.dof("xknee_s") + 2]
    np.testing.assert_allclose(rings[1], 0.5 * (at_knee + kn), atol=1e-12)  # the middle of the bushing's ends


def test_ideal_joints_drawn_at_their_points_with_links_to_them():
    # the slider-crank turned by 1 rad at the crank: the crank pin (carried by node a) and the crank's
    # link from o to it; the piston's slider at node b
    model = casflex.assemble(casflex.load_scene("slidercrank"))
    q = model.q0.copy()
    q[model.dof("thetao")] += 1.0
    ax = plotting.plot_configuration(model, q).axes[0]
    hinge = next(line for line in ax.lines if line.get_label() == "hinge")
    np.testing.assert_allclose([hinge.get_xdata()[0], hinge.get_ydata()[0]], q[model.dof("xa"):model.dof("xa") + 2])
    pin = np.array(model.scene.joint_point(model.scene.joints[0]))  # on the crank, turned with node o
    c, s = np.cos(1.0), np.sin(1.0)
    link = next(line for line in ax.lines if line.get_label() == "rigid link")
    pts = np.column_stack([link.get_xdata(), link.get_ydata()])
    assert np.isclose(pts, np.array([[c, -s], [s, c]]) @ pin, atol=1e-12).all(axis=1).any()
    assert any(line.get_label() == "slider" for line in ax.lines)
