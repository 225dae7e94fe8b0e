"""PNG files of 8-bit RGB images, written a band of rows at a time without Pillow: the bytes Pillow writes.

Why not Pillow: it copies the whole image into its own pixels (4 bytes each) before encoding, and importing
it adds about 3 MB of libraries; for a 1280 x 960 render the two were a fifth of the command's peak memory.
Here each band of rows is filtered and handed to zlib as it comes, so what writing adds is a band and
zlib's state.

The file is the one Pillow (7 to 11) writes for an RGB image with no metadata, byte for byte where Pillow
deflates with the zlib library that Python's zlib module uses (Pillow's Linux wheels use the system's, as
Python does; tests compare the files there, and the pixels elsewhere, where a Pillow built on another
deflate, such as zlib-ng, gives other bytes for the same filtered rows): the signature, an IHDR chunk (8 bits, colour type 2, no interlace), the compressed rows in IDAT
chunks of max(65536, 4 x width) bytes each (the last one shorter: Pillow's encoder fills a buffer of that
size per chunk), and IEND.  Each row gets the filter whose output bytes, read as signed, have the smallest
sum of magnitudes, trying none, up, sub and Paeth in that order and keeping the first on a tie (Pillow's
choice, the heuristic from libpng; Pillow leaves "average" to its optimize option).  The filtered rows go
through zlib's deflate with a 15-bit window, memory level 9 and the Z_FILTERED strategy, as Pillow's do.
"""
from __future__ import annotations

import struct
import zlib
from typing import BinaryIO, Iterable

import numpy as np

SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: Pillow's smallest encoder buffer (ImageFile.MAXBLOCK); each IDAT chunk but the last is one buffer full.
MIN_IDAT_BYTES = 65536
CHANNELS = 3  # RGB, one byte each: also the filters' distance to "the pixel on the left"
#: PNG's filter type bytes, in the order they are tried.
NONE, SUB, UP, PAETH = 0, 1, 2, 4
TRIED = np.array([NONE, UP, SUB, PAETH], dtype=np.uint8)
#: Bytes of rows filtered at a time (at least one row): the filters' temporaries are about 12 times this.
FILTER_BYTES = 1 << 15


def write_chunk(handle: BinaryIO, kind: bytes, data: bytes) -> None:
    handle.write(struct.pack(">I", len(data)) + kind)
    handle.write(data)
    handle.write(struct.pack(">I", zlib.crc32(data, zlib.crc32(kind))))


def idat_bytes(width: int) -> int:
    """The size of every IDAT chunk but the last, for an image ``width`` pixels wide."""
    return max(MIN_IDAT_BYTES, 4 * width)


def filter_rows(rows: np.ndarray, above: np.ndarray) -> np.ndarray:
    """Rows of bytes (n, row bytes) as they go to zlib: each prefixed by its filter type and filtered.
    ``above``: the row before the first (zeros above the image's first row)."""
    count, size = rows.shape
    up = np.empty_like(rows)
    up[0], up[1:] = above, rows[:-1]
    left = np.zeros_like(rows)
    left[:, CHANNELS:] = rows[:, :-CHANNELS]
    up_left = np.zeros_like(rows)
    up_left[:, CHANNELS:] = up[:, :-CHANNELS]
    # Paeth's predictor: of left, up and up-left, the nearest to left + up - up-left (ties in that order).
    up_step = up.astype(np.int16) - up_left
    left_step = left.astype(np.int16) - up_left
    to_left, to_up, to_up_left = np.abs(up_step), np.abs(left_step), np.abs(up_step + left_step)
    predictor = np.where((to_left <= to_up) & (to_left <= to_up_left), left,
                         np.where(to_up <= to_up_left, up, up_left))
    candidates = np.empty((4, count, size), dtype=np.uint8)  # in TRIED's order; uint8 arithmetic wraps mod 256
    candidates[0] = rows
    np.subtract(rows, up, out=candidates[1])
    np.subtract(rows, left, out=candidates[2])
    np.subtract(rows, predictor, out=candidates[3])
    # A byte's cost is its magnitude as a signed byte: abs of int8 gives it, -128 staying -128 (128 unsigned).
    cost = np.abs(candidates.view(np.int8)).view(np.uint8).sum(axis=2, dtype=np.int64)
    best = np.argmin(cost, axis=0)  # (the first of equal costs, as Pillow keeps)
    out = np.empty((count, size + 1), dtype=np.uint8)
    out[:, 0] = TRIED[best]
    out[:, 1:] = candidates[best, np.arange(count)]
    return out


class PngWriter:
    """A PNG file being written: the header now, rows as they come (:meth:`add_rows`, top first), the end
    with :meth:`finish`.  ``level``: zlib's compression level, 1 to 9 (Pillow's compress_level; its default,
    -1, is zlib's 6).  (Level 0 is left out: zlib's stored blocks follow how the input was cut, so they would
    not be Pillow's.)"""

    def __init__(self, handle: BinaryIO, width: int, height: int, level: int = 6):
        if not 1 <= level <= 9:
            raise ValueError(f"PNG compression level must be 1 to 9, not {level}")
        self.handle, self.width, self.height = handle, int(width), int(height)
        handle.write(SIGNATURE)
        write_chunk(handle, b"IHDR", struct.pack(">IIBBBBB", self.width, self.height, 8, 2, 0, 0, 0))
        self.compressor = zlib.compressobj(level, zlib.DEFLATED, 15, 9, zlib.Z_FILTERED)
        self.chunk = idat_bytes(self.width)
        self.pending = bytearray()  # compressed bytes not yet in a chunk: less than one chunk between calls
        self.above = np.zeros(self.width * CHANNELS, dtype=np.uint8)
        self.rows_written = 0

    def add_rows(self, band: np.ndarray) -> None:
        """The next rows: uint8 (rows, width, 3).  The band may be reused or released afterwards."""
        band = np.asarray(band, dtype=np.uint8).reshape(len(band), self.width * CHANNELS)
        step = max(1, FILTER_BYTES // band.shape[1])
        for top in range(0, len(band), step):
            rows = band[top:top + step]
            self.pending += self.compressor.compress(filter_rows(rows, self.above))
            self.above = rows[-1].copy()
        self.rows_written += len(band)
        self._write_full_chunks()

    def finish(self) -> None:
        """The last IDAT chunk (shorter than the others, unless it is full) and IEND."""
        if self.rows_written != self.height:
            raise ValueError(f"PNG of {self.height} rows given {self.rows_written}")
        self.pending += self.compressor.flush()
        self._write_full_chunks()
        if self.pending:
            write_chunk(self.handle, b"IDAT", bytes(self.pending))
        write_chunk(self.handle, b"IEND", b"")

    def _write_full_chunks(self) -> None:
        while len(self.pending) >= self.chunk:
            write_chunk(self.handle, b"IDAT", bytes(self.pending[:self.chunk]))
            del self.pending[:self.chunk]


def write_png(handle: BinaryIO, width: int, height: int, bands: Iterable[np.ndarray], level: int = 6) -> None:
    """Write a PNG of ``bands``: uint8 arrays (rows, width, 3), top row first, ``height`` rows in all."""
    writer = PngWriter(handle, width, height, level)
    for band in bands:
        writer.add_rows(band)
    writer.finish()
