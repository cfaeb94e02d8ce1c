"""Compiled pasting: a level's blocks written into the canvas through their seam masks.

The pixels are copied as machine words (4, 2 or 1 bytes, whichever divides a pixel), so three
compiled loops serve every dtype and channel count (float32 working canvases, and the
uint8/uint16/float companions a layout re-renders) and no job compiles anything after
:func:`quilting.core.kernels.warm_up`.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numpy.typing import NDArray


@nb.njit(cache=True, nogil=True)
def _paste(
    canvas: NDArray[np.unsignedinteger],
    blocks: NDArray[np.unsignedinteger],
    corners: NDArray[np.intp],
    owned: NDArray[np.bool_],
    width: int,
    size: int,
) -> None:
    """``canvas`` (H * W * P) and ``blocks`` (n * B * B * P) flat, P words a pixel: each run
    of owned pixels of a block row copied as one slice (two across the wrap)."""
    row_words = width * size
    height = canvas.size // row_words
    count, block = owned.shape[0], owned.shape[1]
    for k in range(count):
        for y in range(block):
            row = (corners[k, 0] + y) % height
            here = (k * block + y) * block
            x = 0
            while x < block:
                if not owned[k, y, x]:
                    x += 1
                    continue
                end = x + 1
                while end < block and owned[k, y, end]:
                    end += 1
                # Pixels x..end-1 of the block row, from canvas column col on, wrapped.
                col = (corners[k, 1] + x) % width
                first = min(end - x, width - col)
                start = row * row_words + col * size
                at = (here + x) * size
                canvas[start : start + first * size] = blocks[at : at + first * size]
                if first < end - x:
                    rest = (end - x - first) * size
                    at += first * size
                    canvas[row * row_words : row * row_words + rest] = blocks[at : at + rest]
                x = end


#: Words the pixels are copied in, by how many bytes divide a pixel: a slice of 4-byte words
#: copies about 4 times as fast as one of bytes.
_WORDS = {4: np.uint32, 2: np.uint16, 1: np.uint8}


def paste_pixels(
    canvas: NDArray[np.generic],
    blocks: NDArray[np.generic],
    corners: NDArray[np.intp],
    owned: NDArray[np.bool_],
) -> None:
    """``canvas[(y + i) % H, (x + j) % W] = blocks[k, i, j]`` where ``owned[k, i, j]``, block
    by block in order (the canvas a torus), in place.

    Parameters
    ----------
    canvas : ndarray, shape (H, W, C), C-contiguous
    blocks : ndarray, shape (n, B, B, C), C-contiguous, the canvas's dtype
    corners : ndarray of int, shape (n, 2)
        (y, x) of each block's top-left corner on the canvas.
    owned : ndarray of bool, shape (n, B, B)
    """
    if not canvas.flags.c_contiguous or blocks.dtype != canvas.dtype:
        raise ValueError("paste_pixels needs a C-contiguous canvas and blocks of its dtype")
    height, width = canvas.shape[:2]
    count = owned.shape[0]
    if count == 0 or canvas.size == 0:
        return
    # Flat words, whole pixels of ``size`` words.
    pixel = canvas.itemsize * (canvas.size // (height * width))
    unit = next(u for u in _WORDS if pixel % u == 0)
    word = _WORDS[unit]
    _paste(
        canvas.reshape(-1).view(np.uint8).view(word),
        np.ascontiguousarray(blocks).reshape(-1).view(np.uint8).view(word),
        np.ascontiguousarray(corners, dtype=np.intp),
        np.ascontiguousarray(owned, dtype=np.bool_),
        width,
        pixel // unit,
    )
