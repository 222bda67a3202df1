"""casflex.plotting._png: casflex's figures' PNG encoded without Pillow's adaptive row filters (issue 49: half the
CPU of a study's gait figure's encoding): the pixels, resolution and texts of matplotlib's PNG through Pillow."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from casflex.plotting._figure import _new_figure


def _figure(facecolor: str):
    fig = _new_figure((3.1, 2.3), layout=None)
    fig.set_facecolor(facecolor)  # "none": a transparent background, alpha in the pixels
    ax = fig.add_subplot()
    ax.fill_between([0.0, 1.0], [0.0, 1.0], [0.5, 2.0], alpha=0.3)
    ax.plot([0.0, 1.0], [2.0, -1.0])
    ax.set_title("Knee flexion/extension moment")
    return fig


def _png(fig, **kwargs) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", **kwargs)
    return buf.getvalue()


@pytest.mark.parametrize("facecolor", ["white", "none"])
@pytest.mark.parametrize("metadata", [None, {"Title": "s02: knee", "Software": None}])
def test_casflex_s_png_is_pillow_s_pixels_resolution_and_texts(facecolor, metadata):
    fig = _figure(facecolor)
    ours = _png(fig, dpi=97, metadata=metadata)
    pillow = _png(fig, dpi=97, metadata=metadata, pil_kwargs={"compress_level": 1})  # Pillow's options: Pillow's
    assert ours != pillow
    mine, theirs = Image.open(io.BytesIO(ours)), Image.open(io.BytesIO(pillow))
    assert mine.mode == theirs.mode == "RGBA" and mine.info == theirs.info
    assert np.array_equal(np.asarray(mine), np.asarray(theirs))
    assert mine.info["dpi"] == pytest.approx((97, 97), abs=0.01)  # pHYs: pixels per metre, rounded
    if facecolor == "none":
        assert np.asarray(mine)[..., 3].min() == 0


def test_a_text_outside_latin_1_is_written_by_pillow():
    # Pillow writes such a text as an iTXt chunk (UTF-8): left to it
    fig = _figure("white")
    png = _png(fig, metadata={"Title": "Ωmega"})
    assert Image.open(io.BytesIO(png)).info["Title"] == "Ωmega"
