"""Drawings of a model's configuration: beams as Hermite curves, springs as zigzags (axes in m)."""

from __future__ import annotations

import os

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from casflex.model import Model
from casflex.plotting._figure import _new_figure, _save

_BEAM_COLOR = "#1f4e79"
_SPRING_COLOR = "#c0392b"
_TORSION_COLOR = "#8e44ad"
_NODE_COLOR = "black"
_BODY_COLOR = "#e67e22"
_MARKER_COLOR = "#16a085"
_SUPPORT_MARKERS = {"clamp": "s", "pin": "^", "x": ">", "y": "v", "theta": "D"}
_SUPPORT_LABELS = {"clamp": "clamp", "pin": "pin", "x": "x support", "y": "y support", "theta": "rotation support"}


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
        self.supports: dict[str, list[int]] = {}
        for s in model.scene.supports:
            self.supports.setdefault(s.kind, []).append(idx[s.node])
        self.n_user = len(model.scene.nodes)

    def bodies(self, q: np.ndarray) -> np.ndarray:
        """(k, 2) centres of mass of the rigid bodies."""
        from casflex.markers import body_centres

        return body_centres(self.model, q)

    def markers(self, q: np.ndarray) -> np.ndarray:
        """(k, 2) positions of the scene's markers."""
        from casflex.markers import marker_positions

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

    def springs(self, q: np.ndarray) -> np.ndarray:
        """(k, 2) polyline of all linear springs (zigzags), NaN-separated."""
        if not len(self.spring_a):
            return np.empty((0, 2))
        xy = q.reshape(-1, 3)
        pa, pb = xy[self.spring_a, :2], xy[self.spring_b, :2]
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
        """(k, 2) midpoints of the torsion springs' node pairs."""
        xy = q.reshape(-1, 3)[:, :2]
        return 0.5 * (xy[self.torsion_pairs[:, 0]] + xy[self.torsion_pairs[:, 1]])

    def limits(self, qs: np.ndarray, margin: float = 0.08) -> tuple[tuple[float, float], tuple[float, float]]:
        """Axis limits (m) covering the node positions of all rows of ``qs`` (n, n_dof)."""
        qs = np.atleast_2d(qs)
        x, y = qs[:, 0::3], qs[:, 1::3]
        pad = margin * self.extent + (float(self.spring_width.max()) if len(self.spring_width) else 0.0)
        return ((float(x.min()) - pad, float(x.max()) + pad), (float(y.min()) - pad, float(y.max()) + pad))

    def draw(self, ax: Axes, q: np.ndarray, *, labels: bool = True) -> dict[str, object]:
        """Draw configuration ``q`` on ``ax``; returns the artists (for animation updates)."""
        xy = q.reshape(-1, 3)
        art: dict[str, object] = {}
        b = self.beams(q)
        art["beams"], = ax.plot(b[:, 0], b[:, 1], color=_BEAM_COLOR, lw=4.5, solid_capstyle="round",
                                label="beam" if len(b) else "_beam", zorder=2)
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
        if labels:
            for i, name in enumerate(self.model.node_names[:self.n_user]):
                ax.annotate(name, (xy[i, 0], xy[i, 1]), xytext=(6, 4), textcoords="offset points",
                            fontsize="small", color="0.2", zorder=7)
        return art

    def update(self, art: dict[str, object], q: np.ndarray) -> None:
        xy = q.reshape(-1, 3)
        for key, pts in (("beams", self.beams(q)), ("springs", self.springs(q)), ("torsions", self.torsions(q))):
            art[key].set_data(pts[:, 0], pts[:, 1])  # type: ignore[attr-defined]
        art["nodes"].set_data(xy[:self.n_user, 0], xy[:self.n_user, 1])  # type: ignore[attr-defined]
        art["mesh_nodes"].set_data(xy[self.n_user:, 0], xy[self.n_user:, 1])  # type: ignore[attr-defined]
        for key, pts in (("bodies", self.bodies(q)), ("markers", self.markers(q))):
            art[key].set_data(pts[:, 0], pts[:, 1])  # type: ignore[attr-defined]
        for kind, nodes in self.supports.items():
            art[f"support:{kind}"].set_data(xy[nodes, 0], xy[nodes, 1])  # type: ignore[attr-defined]


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
    bending shows at true scale), linear springs zigzags, torsion springs rings at the middle
    of their node pair, nodes dots (user nodes labelled), supports grey markers (square clamp,
    triangle pin). Axes in m with equal aspect. Draws into ``ax`` if given, else a new figure;
    returns the figure.
    """
    q = _check_q(model, q)
    if ax is None:
        fig = _new_figure((6.0, 6.0))
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
    _save(fig, path)
    return fig
