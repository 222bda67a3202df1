"""casflex.plotting.animation: the GIF has the expected frames and timing, keeps white exactly,
is written atomically (a failure leaves the old file), and rejects a motion of another model."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import pendulum
from PIL import Image

import casflex
from casflex import plotting

from .helpers import assert_clean


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
