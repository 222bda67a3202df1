"""PNG files of casflex's figures, encoded without Pillow's adaptive row filters.

matplotlib writes a PNG through Pillow, which tries each of PNG's five filters on every row of the image and keeps
the one that compresses best: a study's gait figure (1080 x 2016 RGBA pixels, mostly white) took 75-100 ms of CPU
to encode at zlib level 1. Its rows unfiltered (filter 0) deflate as well (the same runs of white and of each line's
colour: 369 against 380 kB) in 40 ms. The same pixels (a test decodes both) and the chunks matplotlib writes
beside them: the size, the resolution (pHYs, as Pillow writes the dpi) and the ``Software`` text.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

#: zlib's level: 1, not Pillow's 6, the same pixels in a file about 5 % larger, encoded in half the time
COMPRESS_LEVEL = 1


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def encode(rgba: np.ndarray, dpi: float, metadata: dict[str, str]) -> bytes:
    """The PNG of ``rgba`` (height, width, 4) uint8, rows top to bottom, at ``dpi`` (dots per inch), with
    ``metadata``'s texts (tEXt chunks, latin-1)."""
    height, width, _ = rgba.shape
    rows = np.empty((height, 4 * width + 1), np.uint8)
    rows[:, 0] = 0  # each row's filter: none
    rows[:, 1:] = rgba.reshape(height, 4 * width)
    per_metre = int(dpi / 0.0254 + 0.5)  # Pillow's rounding of the dpi
    texts = b"".join(_chunk(b"tEXt", k.encode("latin-1") + b"\0" + v.encode("latin-1"))
                     for k, v in metadata.items())
    return b"".join((b"\x89PNG\r\n\x1a\n",
                     _chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0)),  # 8-bit RGBA
                     _chunk(b"pHYs", struct.pack(">IIB", per_metre, per_metre, 1)), texts,
                     _chunk(b"IDAT", zlib.compress(rows, COMPRESS_LEVEL)), _chunk(b"IEND", b"")))
