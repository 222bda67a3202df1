"""GIF animation of a motion: the configuration drawing redrawn along a trajectory.

Frames are blitted (only the moving artists are redrawn over a cached background) and mapped
to one fixed palette, then written atomically.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import numpy as np
from matplotlib.animation import PillowWriter
from PIL import Image

from casflex import interrupt
from casflex.model import Model
from casflex.plotting._figure import _new_figure
from casflex.plotting.configuration import _Drawer
from casflex.results import Trajectory, atomic_write_bytes


def animate(model: Model, traj: Trajectory, path: str | os.PathLike[str], *, fps: float = 25,
            duration: float | None = None, dpi: float = 80) -> Path:
    """Write a GIF of the deformed system moving along ``traj``; returns the path.

    Frames are sampled from ``traj`` at equal time intervals (nearest stored time point):
    ``fps`` frames per second of playback, for a playback lasting ``duration`` seconds
    (default: the simulated time span, i.e. real time; a shorter duration plays faster).
    The axis limits are fixed from the whole motion; a label shows the simulated time (s).
    The GIF is written to a temporary file in the target directory and renamed over ``path``.
    """
    if traj.q.shape[1] != model.n_dof:
        raise ValueError(f"traj has {traj.q.shape[1]} dofs, the model {model.n_dof}: not a motion of this model")
    if not (fps > 0 and math.isfinite(fps)):
        raise ValueError(f"fps: must be a positive number, got {fps!r}")
    path = Path(path)
    t = traj.t
    span = float(t[-1] - t[0])
    play = span if duration is None else float(duration)
    if not (play >= 0 and math.isfinite(play)):
        raise ValueError(f"duration: must be a non-negative number of seconds, got {duration!r}")
    n_frames = max(2, int(round(play * fps)) + 1)
    n_frames = min(n_frames, len(t)) if len(t) > 1 else 1
    times = np.linspace(float(t[0]), float(t[-1]), n_frames)
    right = np.clip(np.searchsorted(t, times), 1, max(len(t) - 1, 1)) if len(t) > 1 else np.zeros(1, dtype=int)
    left = np.maximum(right - 1, 0)
    nearest = np.where(np.abs(times - t[left]) <= np.abs(t[right] - times), left, right)
    frames = np.unique(nearest)

    drawer = _Drawer(model)
    (x0, x1), (y0, y1) = drawer.limits(traj.q)
    w, h = x1 - x0, y1 - y0
    width = 6.0
    height = float(np.clip(width * h / max(w, 1e-12), 3.0, 8.0))
    fig = _new_figure((width, height))
    fig.set_dpi(dpi)
    ax = fig.add_subplot()
    art = drawer.draw(ax, traj.q[frames[0]], labels=False)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, alpha=0.25)
    ax.set_title(f"{model.scene.name}", fontsize="medium")
    label = ax.text(0.02, 0.97, "", transform=ax.transAxes, va="top", ha="left", family="monospace",
                    bbox={"boxstyle": "round", "fc": "white", "ec": "0.7", "alpha": 0.9}, zorder=10)
    # lay out once, then drop the engine: every frame has the same geometry
    fig.get_layout_engine().execute(fig)
    fig.set_layout_engine(None)
    moving = sorted([*art.values(), label], key=lambda a: a.get_zorder())  # type: ignore[attr-defined]

    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp.gif")
    os.close(fd)
    try:
        writer = _BlitPillowWriter(moving, fps=fps)
        with writer.saving(fig, tmp, dpi):
            for k in frames:
                drawer.update(art, traj.q[k])
                label.set_text(f"t = {t[k]:6.3f} s")
                writer.grab_frame()
                interrupt.check()  # a Ctrl-C that matplotlib swallowed
        atomic_write_bytes(path, Path(tmp).read_bytes())
    finally:
        Path(tmp).unlink(missing_ok=True)
    return path


class _Palette:
    """Maps RGB frames to the 256 most frequent colours of a reference frame (exactly where a
    colour is in the palette, else to the nearest palette colour); numpy, so exact white stays
    white (Pillow's own palette mapping rounds colours to 6 bits per channel)."""

    def __init__(self, rgb: np.ndarray):
        keys, counts = np.unique(self._keys(rgb), return_counts=True)
        top = np.sort(keys[np.argsort(counts, kind="stable")[::-1][:256]])
        self.keys = top
        self.colors = np.stack([(top >> 16) & 255, (top >> 8) & 255, top & 255], axis=1).astype(np.int32)
        self.flat = self.colors.astype(np.uint8).ravel().tolist() + [0] * (768 - 3 * len(top))

    @staticmethod
    def _keys(rgb: np.ndarray) -> np.ndarray:
        rgb = rgb.astype(np.int32)
        return (rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]

    def index(self, rgb: np.ndarray) -> np.ndarray:
        """(h, w) uint8 palette indices of an (h, w, 3) uint8 frame."""
        keys = self._keys(rgb).ravel()
        pos = np.clip(np.searchsorted(self.keys, keys), 0, len(self.keys) - 1)
        miss = self.keys[pos] != keys
        if miss.any():
            uniq, inv = np.unique(keys[miss], return_inverse=True)
            cols = np.stack([(uniq >> 16) & 255, (uniq >> 8) & 255, uniq & 255], axis=1)
            near = np.empty(len(uniq), dtype=np.intp)
            for i in range(0, len(uniq), 4096):  # bounded memory: 4096 x 256 distances at a time
                c = cols[i:i + 4096]
                near[i:i + 4096] = np.argmin(((c[:, None, :] - self.colors[None, :, :]) ** 2).sum(axis=2), axis=1)
            pos[miss] = near[inv]
        return pos.astype(np.uint8).reshape(rgb.shape[:2])


class _BlitPillowWriter(PillowWriter):
    """PillowWriter that redraws only the moving artists over a cached background.

    The static parts (axes, ticks, grid, labels) are rendered once; every frame restores
    them and draws the moving artists (a full ``savefig`` per frame spends most of its
    time on tick labels). Frames are mapped to the palette of the first frame
    (:class:`_Palette`), so the GIF encoder does not quantize each frame again. The frames
    go to PillowWriter's frame list ``_frames`` (as its own ``grab_frame`` does); if that
    attribute is missing (another matplotlib version) or the figure's dpi differs from the
    writer's, it falls back to PillowWriter's own frame grabbing.
    """

    def __init__(self, moving: list, **kwargs):
        super().__init__(**kwargs)
        self._moving = moving
        self._background = None
        self._palette: _Palette | None = None

    def grab_frame(self, **savefig_kwargs):
        canvas = self.fig.canvas
        frames = getattr(self, "_frames", None)
        if savefig_kwargs or frames is None or self.fig.dpi != self.dpi:
            return super().grab_frame(**savefig_kwargs)
        if self._background is None:
            for a in self._moving:
                a.set_animated(True)
            canvas.draw()
            self._background = canvas.copy_from_bbox(self.fig.bbox)
        canvas.restore_region(self._background)
        renderer = canvas.get_renderer()
        for a in self._moving:
            a.draw(renderer)
        rgb = np.asarray(canvas.buffer_rgba())[..., :3]
        if self._palette is None:
            self._palette = _Palette(rgb)
        idx = self._palette.index(rgb)
        im = Image.frombytes("P", (idx.shape[1], idx.shape[0]), idx.tobytes())
        im.putpalette(self._palette.flat)
        frames.append(im)
