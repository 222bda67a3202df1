"""An Agg canvas whose renderer keeps each text it rasterised, to draw it again as a stored coverage image.

matplotlib's Agg renderer lays every text out (libraqm, 0.2-1 ms a string) and rasterises its glyphs (FreeType) at
each draw; a study's gait figures draw the same tick labels, titles and axis labels again and again (165 texts a
figure, the same strings from one figure to the next). :class:`_Renderer` keeps each text's coverage (its alpha, 0-255)
by everything the pixels depend on: the string, the font, the size, the angle, the antialiasing, the dpi, the
position's fraction of a pixel (1/64, FreeType's unit: the glyphs are rendered at the same sub-pixel offset, so the
same pixels up to 8-bit rounding), the text's font features and language, the fonts rcParams name for its families
and the hinting; a text drawn again is one
``draw_text_image`` of its stored coverage in the text's colour. Animated texts (an animation's time label, new each
frame) and mathtext are drawn as matplotlib draws them.

Only where matplotlib lays text out with libraqm (3.11, ``FT2Font._layout``: ``draw_text_image``'s ``y`` the
bitmap's bottom, downwards); elsewhere the canvas is matplotlib's own.
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict

import matplotlib
import numpy as np
from matplotlib import cbook, rcParams
from matplotlib import text as mpl_text
from matplotlib.backends.backend_agg import FigureCanvasAgg, RendererAgg
from matplotlib.font_manager import fontManager, get_font
from matplotlib.ft2font import FT2Font

from casflex.plotting._png import encode

#: texts kept (least recently drawn dropped first): a few kB each, a study's figures draw some 300 different ones
TEXTS_KEPT = 4096
#: the position's fraction of a pixel is part of the key at FreeType's resolution (26.6 fixed point)
_SUBPIXEL = 64

_texts: OrderedDict[tuple, tuple[np.ndarray | None, int, int]] = OrderedDict()
_lock = threading.Lock()  # figures may be drawn in several threads (a dask worker's)
#: texts drawn from the store and rasterised, for tests and measurements
counts = {"kept": 0, "rasterised": 0}

ENABLED = hasattr(FT2Font, "_layout")


def _measured(renderer, s, prop, ismath, dpi):
    return renderer.get_text_width_height_descent(s, prop, ismath)


#: the text's size as matplotlib's text layout measured it (its cache of them), else measured here
_metrics = getattr(mpl_text, "_get_text_metrics_with_cache", _measured)


def _coverage(renderer: RendererAgg, gc, fx: float, fy: float, s: str, prop, angle: float, mtext
              ) -> tuple[np.ndarray | None, int, int]:
    """The text rasterised by matplotlib on a scratch canvas with its pen at (``half + fx``, ``half + fy``):
    (its coverage cropped to its ink, the ink's left and bottom edge from the pen's whole pixel; None: no ink)."""
    w, h, _ = _metrics(renderer, s, prop, False, renderer.dpi)  # the text's layout measured them: kept
    half = int(math.ceil(w + h)) + 4  # any angle: the glyphs lie within w + h of the pen
    scratch = RendererAgg(2 * half, 2 * half, renderer.dpi)
    ink = scratch.new_gc()
    ink.set_foreground("black")
    ink.set_antialiased(gc.get_antialiased())
    RendererAgg.draw_text(scratch, ink, half + fx, half + fy, s, prop, angle, False, mtext)
    ink.restore()
    alpha = np.asarray(scratch.buffer_rgba())[..., 3]
    rows, cols = np.flatnonzero(alpha.any(axis=1)), np.flatnonzero(alpha.any(axis=0))
    if not len(rows):
        return None, 0, 0
    image = np.ascontiguousarray(alpha[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1])
    return image, int(cols[0]) - half, int(rows[-1]) + 1 - half


_heights: dict[tuple, tuple[float, float, float]] = {}


def _font_key(prop) -> tuple:
    """What a text's font is: its properties and the fonts its families name (rcParams' lists: a family
    ``sans-serif`` is the first of them found)."""
    family = tuple(prop.get_family())
    return (family, tuple(tuple(rcParams.get(f"font.{f}", ())) for f in family), prop.get_style(),
            prop.get_variant(), prop.get_weight(), prop.get_stretch(), prop.get_size_in_points(), prop.get_file(),
            prop.get_math_fontfamily())


class _Renderer(RendererAgg):
    """matplotlib's Agg renderer but its texts drawn from the store (module docstring), and each font's line
    metrics kept (:meth:`_get_font_height_metrics`)."""

    def _get_font_height_metrics(self, prop) -> tuple[float, float, float]:
        """(ascent, descent, line gap) in pixels of ``prop``'s font at this renderer's dpi, as matplotlib's
        ``Text._get_layout`` reads them from the font's tables at every layout of every text (a quarter of a
        gait figure's text layout), kept by the font's properties."""
        key = (*_font_key(prop), float(self.dpi))
        found = _heights.get(key)
        if found is None:
            font = get_font(fontManager._find_fonts_by_props(prop))
            for table, gap, ascent, descent in (("OS/2", "sTypoLineGap", "sTypoAscender", "sTypoDescender"),
                                                ("hhea", "lineGap", "ascent", "descent")):
                t = font.get_sfnt_table(table)
                if t is not None:
                    scale = 1 / font.get_sfnt_table("head")["unitsPerEm"] * prop.get_size_in_points() * self.dpi / 72
                    found = (t[ascent] * scale, -t[descent] * scale, t[gap] * scale)
                    break
            else:
                return None, None, None  # matplotlib measures "lp" instead
            _heights[key] = found
        return found

    def draw_text(self, gc, x, y, s, prop, angle, ismath=False, mtext=None):  # noqa: D102 - RendererAgg's
        if ismath or mtext is None or mtext.get_animated() or not s.strip():
            return super().draw_text(gc, x, y, s, prop, angle, ismath, mtext)
        X, Y = math.floor(x), math.floor(y)  # noqa: N806 - the pen's whole pixel
        fx, fy = round((x - X) * _SUBPIXEL) / _SUBPIXEL, round((y - Y) * _SUBPIXEL) / _SUBPIXEL
        if fx >= 1.0 or fy >= 1.0:  # rounded up to the next pixel
            X, fx = (X + 1, 0.0) if fx >= 1.0 else (X, fx)  # noqa: N806
            Y, fy = (Y + 1, 0.0) if fy >= 1.0 else (Y, fy)  # noqa: N806
        key = (s, *_font_key(prop), float(angle), bool(gc.get_antialiased()), fx, fy, float(self.dpi),
               str(mtext.get_fontfeatures()), mtext.get_language(), rcParams["text.hinting"],
               rcParams["text.hinting_factor"])
        with _lock:
            entry = _texts.get(key)
            if entry is not None:
                _texts.move_to_end(key)
        if entry is None:
            entry = _coverage(self, gc, fx, fy, s, prop, angle, mtext)
            counts["rasterised"] += 1
            with _lock:
                _texts[key] = entry
                while len(_texts) > TEXTS_KEPT:
                    _texts.popitem(last=False)
        else:
            counts["kept"] += 1
        image, left, bottom = entry
        if image is not None:
            self._renderer.draw_text_image(image, X + left, Y + bottom, 0, gc)


class Canvas(FigureCanvasAgg):
    """matplotlib's Agg canvas drawing with :class:`_Renderer` (where :data:`ENABLED`), its PNG encoded by
    :func:`casflex.plotting._png.encode` (the same pixels and chunks as matplotlib's, in half the CPU)."""

    def print_png(self, filename_or_obj, *, metadata=None, pil_kwargs=None, dpi=None, facecolor=None,
                  edgecolor=None, orientation=None, bbox_inches_restore=None):  # noqa: D102 - matplotlib's
        # dpi to bbox_inches_restore: print_figure's, applied before (matplotlib's own print_png is not given them)
        meta = {"Software": f"Matplotlib version{matplotlib.__version__}, https://matplotlib.org/", **(metadata or {})}
        meta = {k: v for k, v in meta.items() if v is not None}
        if pil_kwargs or not all(f"{k}{v}".isascii() for k, v in meta.items()):  # Pillow's options, iTXt texts
            return super().print_png(filename_or_obj, metadata=metadata, pil_kwargs=pil_kwargs)
        FigureCanvasAgg.draw(self)
        data = encode(np.asarray(self.buffer_rgba()), self.figure.dpi, meta)
        with cbook.open_file_cm(filename_or_obj, "wb") as fh:
            fh.write(data)

    def get_renderer(self):  # noqa: D102 - FigureCanvasAgg's, but the renderer's class
        if not ENABLED:
            return super().get_renderer()
        w, h = self.get_width_height(physical=True)
        key = w, h, self.figure.dpi
        if self._lastKey != key:
            self.renderer = _Renderer(w, h, self.figure.dpi)
            self._lastKey = key
        return self.renderer


def clear() -> None:
    """Forget every stored text (tests)."""
    with _lock:
        _texts.clear()
