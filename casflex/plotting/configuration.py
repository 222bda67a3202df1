"""Drawings of a model's configuration: beams as Hermite curves, springs as zigzags (axes in m)."""

from __future__ import annotations

import os

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from casflex.model import Model
from casflex.plotting._figure import _fit_column, _new_figure, _save

_BEAM_COLOR = "#1f4e79"
_SPRING_COLOR = "#c0392b"
_TORSION_COLOR = "#8e44ad"
_NODE_COLOR = "black"
_BODY_COLOR = "#e67e22"
_MARKER_COLOR = "#16a085"
_SUPPORT_MARKERS = {"clamp": "s", "pin": "^", "x": ">", "y": "v", "theta": "D"}
_SUPPORT_LABELS = {"clamp": "clamp", "pin": "pin", "x": "x support", "y": "y support", "theta": "rotation support"}
#: Ideal joints at their points: marker, face colour, label
_JOINT_STYLE = {"hinge": ("o", "white", "hinge"), "slider": ("s", "white", "slider"), "weld": ("s", "0.3", "weld")}


class _Drawer:
    """Geometry of a model's drawing: beams as Hermite curves, springs as zigzags, for any q."""

    N_BEAM = 13  # points per beam element curve
    N_COILS = 6

    def __init__(self, model: Model):
        self.model = model
        q0 = np.asarray(model.q0, dtype=float)
        beams = [(a, b) for kind, _, a, b in model.segments if kind == "beam"]
        springs = [(a, b) for kind, _, a, b in model.segments if kind == "spring"]
        self.beam_a = np.array([a for a, _ in beams], dtype=int)
        self.beam_b = np.array([b for _, b in beams], dtype=int)
        self.spring_a = np.array([a for a, _ in springs], dtype=int)
        self.spring_b = np.array([b for _, b in springs], dtype=int)
        xy0 = q0.reshape(-1, 3)
        self.extent = max(float(np.ptp(xy0[:, 0])), float(np.ptp(xy0[:, 1])), model.length_scale, 1e-3)
        d0 = xy0[self.beam_b, :2] - xy0[self.beam_a, :2]
        self.beta0 = np.arctan2(d0[:, 1], d0[:, 0])
        self.th0_a = xy0[self.beam_a, 2]
        self.th0_b = xy0[self.beam_b, 2]
        # spring drawing width: proportional to the spring's initial (or rest) length, bounded
        rest = {s.name: s.rest_length for s in model.scene.springs}
        names = [name for kind, name, _, _ in model.segments if kind == "spring"]
        ls0 = np.linalg.norm(xy0[self.spring_b, :2] - xy0[self.spring_a, :2], axis=1)
        ref = np.array([rest.get(n) or ls0[i] for i, n in enumerate(names)], dtype=float)
        ref = np.where(ref > 0, ref, 0.05 * self.extent)
        self.spring_width = np.clip(0.12 * ref, 0.004 * self.extent, 0.025 * self.extent)
        idx = {n: i for i, n in enumerate(model.node_names)}
        self.torsion_pairs = np.array([(idx[t.nodes[0]], idx[t.nodes[1]]) for t in model.scene.torsion_springs],
                                      dtype=int).reshape(-1, 2)
        # a spring's ends: offsets from their nodes in the initial configuration, turned with the node
        # (points off the nodes, casflex.scene.Spring.point_a/b; zero at a node)
        ends = [model.scene.spring_ends(sp) for sp in model.scene.springs]
        self.end_offsets = np.array([[pt[0] - xy0[idx[n], 0], pt[1] - xy0[idx[n], 1]]
                                     for e, sp in zip(ends, model.scene.springs, strict=True)
                                     for pt, n in zip(e, sp.nodes, strict=True)]).reshape(-1, 2)
        self.end_nodes = np.array([idx[n] for sp in model.scene.springs for n in sp.nodes], dtype=int)
        self.end_th0 = xy0[self.end_nodes, 2]
        # a torsion spring is drawn where a linear spring between the same nodes has its ends (a joint)
        pair_spring = {frozenset(sp.nodes): k for k, sp in enumerate(model.scene.springs)}
        self.torsion_at = np.array([pair_spring.get(frozenset(t.nodes), -1) for t in model.scene.torsion_springs],
                                   dtype=int)
        # rigid links: from a body's node to its centre of mass and to the spring ends fixed off it
        self.link_nodes = np.array([idx[b.node] for b in model.scene.bodies], dtype=int)
        off = np.linalg.norm(self.end_offsets, axis=1) > 1e-12 * self.extent if len(self.end_offsets) else []
        self.link_ends = np.flatnonzero(off)
        self.supports: dict[str, list[int]] = {}
        for s in model.scene.supports:
            self.supports.setdefault(s.kind, []).append(idx[s.node])
        self.n_user = len(model.scene.nodes)
        # ideal joints: drawn at their point seen from node b; the point's offsets from every node of
        # the joint (node a's too) are rigid links where the point is off the node
        self.drawn_joints = [j for j in model.scene.joints if j.kind != "drive"]  # a drive has no place of its own
        self.joint_kinds = [j.kind for j in self.drawn_joints]
        self.joint_ends = [(idx[n], np.subtract(model.scene.joint_point(j), xy0[idx[n], :2]))
                           for j in self.drawn_joints for n in reversed(j.nodes)]  # node b first

    def bodies(self, q: np.ndarray) -> np.ndarray:
        """(k, 2) centres of mass of the rigid bodies."""
        from casflex.model.markers import body_centres

        return body_centres(self.model, q)

    def markers(self, q: np.ndarray) -> np.ndarray:
        """(k, 2) positions of the scene's markers."""
        from casflex.model.markers import marker_positions

        return marker_positions(self.model, q).reshape(-1, 2)

    def beams(self, q: np.ndarray) -> np.ndarray:
        """(k, 2) polyline of all beam elements (Hermite cubics), NaN-separated."""
        if not len(self.beam_a):
            return np.empty((0, 2))
        xy = q.reshape(-1, 3)
        pa, pb = xy[self.beam_a, :2], xy[self.beam_b, :2]
        d = pb - pa
        beta = np.arctan2(d[:, 1], d[:, 0])
        L = np.hypot(d[:, 0], d[:, 1])
        wrap = lambda a: np.arctan2(np.sin(a), np.cos(a))  # noqa: E731
        tha = wrap(xy[self.beam_a, 2] - self.th0_a + self.beta0 - beta)
        thb = wrap(xy[self.beam_b, 2] - self.th0_b + self.beta0 - beta)
        s = np.linspace(0.0, 1.0, self.N_BEAM)
        v = L[:, None] * (tha[:, None] * (s - 2 * s**2 + s**3) + thb[:, None] * (s**3 - s**2))
        e = np.stack([np.cos(beta), np.sin(beta)], axis=1)
        n = np.stack([-e[:, 1], e[:, 0]], axis=1)
        pts = pa[:, None, :] + (s[None, :, None] * d[:, None, :]) + v[:, :, None] * n[:, None, :]
        pts = np.concatenate([pts, np.full((len(L), 1, 2), np.nan)], axis=1)
        return pts.reshape(-1, 2)

    def ends(self, q: np.ndarray) -> np.ndarray:
        """(2 k, 2) the springs' ends, a and b of each in turn: node + R(theta - theta0) offset."""
        xy = q.reshape(-1, 3)
        n = self.end_nodes
        turn = xy[n, 2] - self.end_th0
        c, s = np.cos(turn), np.sin(turn)
        d = self.end_offsets
        return xy[n, :2] + np.column_stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]])

    def joints(self, q: np.ndarray) -> np.ndarray:
        """(k, 2) the joints' points, carried by node b (its end of each joint)."""
        firsts = np.cumsum([0] + [len(j.nodes) for j in self.drawn_joints])[:-1]
        return np.array([self._turned(q, *self.joint_ends[i]) for i in firsts]).reshape(-1, 2)

    def _turned(self, q: np.ndarray, node: int, offset: np.ndarray) -> np.ndarray:
        """node + R(theta - theta0) offset (m)."""
        xy = q.reshape(-1, 3)
        turn = xy[node, 2] - self.model.q0[3 * node + 2]
        c, s = np.cos(turn), np.sin(turn)
        return xy[node, :2] + np.array([c * offset[0] - s * offset[1], s * offset[0] + c * offset[1]])

    def links(self, q: np.ndarray) -> np.ndarray:
        """(k, 2) polyline of the rigid links, NaN-separated: each body's node to its centre of mass,
        and each spring end off its node to that node."""
        xy = q.reshape(-1, 3)
        pieces = [(xy[n, :2], c) for n, c in zip(self.link_nodes, self.bodies(q), strict=True)]
        pieces += [(xy[self.end_nodes[k], :2], p)
                   for k, p in zip(self.link_ends, self.ends(q)[self.link_ends], strict=True)]
        pieces += [(xy[nd, :2], self._turned(q, nd, off)) for nd, off in self.joint_ends
                   if np.hypot(*off) > 1e-12 * self.extent]
        if not pieces:
            return np.empty((0, 2))
        return np.vstack([np.vstack([a, b, [np.nan, np.nan]]) for a, b in pieces])

    def springs(self, q: np.ndarray) -> np.ndarray:
        """(k, 2) polyline of all linear springs (zigzags between their ends), NaN-separated."""
        if not len(self.spring_a):
            return np.empty((0, 2))
        e = self.ends(q)
        pa, pb = e[0::2], e[1::2]
        d = pb - pa
        L = np.hypot(d[:, 0], d[:, 1])
        safe = np.where(L > 0, L, 1.0)
        e = d / safe[:, None]
        n = np.stack([-e[:, 1], e[:, 0]], axis=1)
        m = 2 * self.N_COILS
        s = np.concatenate([[0.0, 0.15], 0.15 + 0.7 * (np.arange(m) + 0.5) / m, [0.85, 1.0]])
        off = np.concatenate([[0.0, 0.0], np.where(np.arange(m) % 2 == 0, 1.0, -1.0), [0.0, 0.0]])
        w = np.where(L > 0, self.spring_width, 0.0)
        side = (w[:, None] * off[None, :])[:, :, None] * n[:, None, :]
        pts = pa[:, None, :] + s[None, :, None] * d[:, None, :] + side
        pts = np.concatenate([pts, np.full((len(L), 1, 2), np.nan)], axis=1)
        return pts.reshape(-1, 2)

    def torsions(self, q: np.ndarray) -> np.ndarray:
        """(k, 2) where the torsion springs are drawn: the middle of the ends of a linear spring
        between the same nodes (a joint's bushing), else the middle of the node pair."""
        xy = q.reshape(-1, 3)[:, :2]
        at = 0.5 * (xy[self.torsion_pairs[:, 0]] + xy[self.torsion_pairs[:, 1]])
        if (self.torsion_at >= 0).any():
            e = self.ends(q)
            joint = self.torsion_at >= 0
            at[joint] = 0.5 * (e[2 * self.torsion_at[joint]] + e[2 * self.torsion_at[joint] + 1])
        return at

    def limits(self, qs: np.ndarray, margin: float = 0.08) -> tuple[tuple[float, float], tuple[float, float]]:
        """Axis limits (m) covering the nodes, bodies, markers and spring ends of all rows of ``qs``
        (n, n_dof)."""
        qs = np.atleast_2d(qs)
        x, y = qs[:, 0::3], qs[:, 1::3]
        if len(self.link_nodes) or len(self.model.scene.markers) or len(self.link_ends):
            rows = qs[np.unique(np.linspace(0, len(qs) - 1, min(len(qs), 200)).astype(int))]
            pts = np.vstack([np.vstack([self.bodies(r), self.markers(r), self.ends(r)]) for r in rows])
            x, y = np.append(x, pts[:, 0]), np.append(y, pts[:, 1])
        pad = margin * self.extent + (float(self.spring_width.max()) if len(self.spring_width) else 0.0)
        return ((float(x.min()) - pad, float(x.max()) + pad), (float(y.min()) - pad, float(y.max()) + pad))

    def draw(self, ax: Axes, q: np.ndarray, *, labels: bool = True) -> dict[str, object]:
        """Draw configuration ``q`` on ``ax``; returns the artists (for animation updates)."""
        xy = q.reshape(-1, 3)
        art: dict[str, object] = {}
        b = self.beams(q)
        art["beams"], = ax.plot(b[:, 0], b[:, 1], color=_BEAM_COLOR, lw=4.5, solid_capstyle="round",
                                label="beam" if len(b) else "_beam", zorder=2)
        lk = self.links(q)
        art["links"], = ax.plot(lk[:, 0], lk[:, 1], color=_BODY_COLOR, lw=3.0, solid_capstyle="round",
                                label="rigid link" if len(lk) else "_link", zorder=2)
        sp = self.springs(q)
        art["springs"], = ax.plot(sp[:, 0], sp[:, 1], color=_SPRING_COLOR, lw=1.1,
                                  label="spring" if len(sp) else "_spring", zorder=3)
        tp = self.torsions(q)
        art["torsions"], = ax.plot(tp[:, 0], tp[:, 1], ls="none", marker="o", ms=11, mfc="none", mew=1.6,
                                   color=_TORSION_COLOR, label="torsion spring" if len(tp) else "_torsion", zorder=4)
        art["nodes"], = ax.plot(xy[:self.n_user, 0], xy[:self.n_user, 1], ls="none", marker="o", ms=5,
                                color=_NODE_COLOR, label="node", zorder=6)
        art["mesh_nodes"], = ax.plot(xy[self.n_user:, 0], xy[self.n_user:, 1], ls="none", marker="o", ms=2.5,
                                     color=_NODE_COLOR, label="_mesh node", zorder=6)
        bp, mp = self.bodies(q), self.markers(q)
        art["bodies"], = ax.plot(bp[:, 0], bp[:, 1], ls="none", marker="D", ms=8, color=_BODY_COLOR,
                                 label="rigid body (centre of mass)" if len(bp) else "_body", zorder=5)
        art["markers"], = ax.plot(mp[:, 0], mp[:, 1], ls="none", marker="x", ms=7, mew=1.8, color=_MARKER_COLOR,
                                  label="marker" if len(mp) else "_marker", zorder=7)
        for kind, nodes in self.supports.items():
            art[f"support:{kind}"], = ax.plot(xy[nodes, 0], xy[nodes, 1], ls="none", marker=_SUPPORT_MARKERS[kind],
                                              ms=12, color="0.45", mec="black", label=_SUPPORT_LABELS[kind], zorder=5)
        jp = self.joints(q)
        for kind, (marker, face, label) in _JOINT_STYLE.items():
            sel = [i for i, k in enumerate(self.joint_kinds) if k == kind]
            if sel:
                art[f"joint:{kind}"], = ax.plot(jp[sel, 0], jp[sel, 1], ls="none", marker=marker, ms=9, mfc=face,
                                                mec="black", mew=1.4, label=label, zorder=8)
        if labels:
            for i, name in enumerate(self.model.node_names[:self.n_user]):
                ax.annotate(name, (xy[i, 0], xy[i, 1]), xytext=(6, 4), textcoords="offset points",
                            fontsize="small", color="0.2", zorder=7)
        return art

    def update(self, art: dict[str, object], q: np.ndarray) -> None:
        xy = q.reshape(-1, 3)
        for key, pts in (("beams", self.beams(q)), ("links", self.links(q)), ("springs", self.springs(q)),
                         ("torsions", self.torsions(q))):
            art[key].set_data(pts[:, 0], pts[:, 1])  # type: ignore[attr-defined]
        art["nodes"].set_data(xy[:self.n_user, 0], xy[:self.n_user, 1])  # type: ignore[attr-defined]
        art["mesh_nodes"].set_data(xy[self.n_user:, 0], xy[self.n_user:, 1])  # type: ignore[attr-defined]
        for key, pts in (("bodies", self.bodies(q)), ("markers", self.markers(q))):
            art[key].set_data(pts[:, 0], pts[:, 1])  # type: ignore[attr-defined]
        for kind, nodes in self.supports.items():
            art[f"support:{kind}"].set_data(xy[nodes, 0], xy[nodes, 1])  # type: ignore[attr-defined]
        jp = self.joints(q)
        for kind in _JOINT_STYLE:
            sel = [i for i, k in enumerate(self.joint_kinds) if k == kind]
            if sel:
                art[f"joint:{kind}"].set_data(jp[sel, 0], jp[sel, 1])  # type: ignore[attr-defined]


def _check_q(model: Model, q: np.ndarray | None) -> np.ndarray:
    q = np.asarray(model.q0 if q is None else q, dtype=float).reshape(-1)
    if q.shape != (model.n_dof,):
        raise ValueError(f"q: expected {model.n_dof} values ({', '.join(model.dof_names[:3])}, ...), got {q.shape}")
    return q


def plot_configuration(model: Model, q: np.ndarray | None = None, ax: Axes | None = None, *,
                       labels: bool = True, legend: bool = True, title: str | None = None,
                       path: str | os.PathLike[str] | None = None) -> Figure:
    """Draw the system in configuration ``q`` (n_dof,), default the initial one ``model.q0``.

    Beams are thick lines (each element a cubic Hermite curve through its end rotations, so
    bending shows at true scale), linear springs zigzags between their ends, torsion springs rings
    (at the ends of a linear spring between the same nodes, else the middle of their node pair),
    rigid bodies diamonds at their centres of mass joined to their node (with the spring ends fixed
    off a node: rigid links), markers crosses, nodes dots (user nodes labelled), supports grey
    markers (square clamp, triangle pin), ideal joints at their points (open circle hinge, open
    square slider, grey square weld; rigid links from their nodes where the point is off them).
    Axes in m with equal aspect. Draws into ``ax`` if given, else a new figure; returns the figure.
    """
    q = _check_q(model, q)
    own = ax is None
    if ax is None:
        fig = _new_figure((6.0, 6.0), layout=None)  # laid out by hand below (the constrained layout's cost)
        ax = fig.add_subplot()
    else:
        fig = ax.figure
        fig = getattr(fig, "figure", None) or fig  # the root figure when ax is in a SubFigure
    drawer = _Drawer(model)
    drawer.draw(ax, q, labels=labels)
    (x0, x1), (y0, y1) = drawer.limits(q[None, :])
    ax.update_datalim([(x0, y0), (x1, y1)])
    ax.margins(0.0)
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, alpha=0.25)
    if legend:
        ax.legend(loc="best", fontsize="small")
    ax.set_title(title if title is not None else f"{model.scene.name}: configuration")
    if own:
        _fit_column(fig, [ax])
    _save(fig, path)
    return fig
