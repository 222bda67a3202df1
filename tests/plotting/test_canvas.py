"""casflex.plotting._canvas: texts rasterised once and drawn again from the store give matplotlib's own pixels
(up to 8-bit rounding), a text drawn again is not rasterised again, an animated text is not stored."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from casflex.plotting import _canvas
from casflex.plotting._figure import DPI

pytestmark = pytest.mark.skipif(not _canvas.ENABLED, reason="matplotlib without libraqm's layout: its own canvas")


def _pixels(canvas_class) -> np.ndarray:
    fig = Figure(figsize=(4.1, 3.3))  # not whole pixels at DPI: texts at fractions of a pixel
    canvas_class(fig)
    ax = fig.add_axes((0.173, 0.191, 0.71, 0.63))
    ax.plot([0.0, 1.7], [-3.1, 250.0])
    ax.set_xlabel("gait cycle (%)")
    ax.set_ylabel("N m (extensor +)")  # rotated
    ax.set_title("Hip flexion/extension moment", fontsize="small", color="tab:red", alpha=0.6)
    fig.text(0.31, 0.93, "Wavy text: AVA fi ff", family="serif", style="italic", rotation=17)
    fig.set_dpi(DPI)
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba()).astype(int)


def test_stored_texts_are_matplotlib_s_pixels_and_drawn_again_from_the_store():
    _canvas.clear()
    theirs = _pixels(FigureCanvasAgg)
    before = dict(_canvas.counts)
    first = _pixels(_canvas.Canvas)
    rasterised = _canvas.counts["rasterised"] - before["rasterised"]
    second = _pixels(_canvas.Canvas)
    assert rasterised >= 12  # the tick labels, the axis labels, the title and the rotated text, once each
    assert _canvas.counts["rasterised"] - before["rasterised"] == rasterised  # the second figure: none again
    assert _canvas.counts["kept"] - before["kept"] >= rasterised
    assert (second == first).all()
    differ = np.abs(first - theirs).max(axis=2)
    # the same glyphs at the same sub-pixel offsets: a coverage image blended once where matplotlib blends each
    # glyph's, so a level of 8-bit rounding where two glyphs' boxes overlap, on a few pixels
    assert differ.max() <= 1 and (differ > 0).sum() <= 0.001 * differ.size, ((differ > 0).sum(), differ.max())


def test_an_animated_text_is_drawn_by_matplotlib_not_stored():
    _canvas.clear()
    fig = Figure(figsize=(2.0, 1.0))
    _canvas.Canvas(fig)
    fig.text(0.1, 0.5, "t = 0.125 s", animated=True)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    fig.texts[0].draw(renderer)  # as an animation's blit draws it
    assert not _canvas._texts


def test_a_text_in_a_font_rcparams_name_otherwise_is_rasterised_again():
    # the store's key holds the fonts rcParams name for the text's family: another list, another font's glyphs
    import matplotlib

    def draw() -> np.ndarray:
        fig = Figure(figsize=(2.0, 1.0))
        _canvas.Canvas(fig)
        fig.text(0.1, 0.4, "Hip 120", family="sans-serif", fontsize=14)
        fig.canvas.draw()
        return np.asarray(fig.canvas.buffer_rgba()).copy()

    _canvas.clear()
    first = draw()
    with matplotlib.rc_context({"font.sans-serif": ["DejaVu Sans Mono"]}):
        mono = draw()
    assert len(_canvas._texts) == 2 and not (first == mono).all()
