"""Compiled pasting: a level's blocks written into the canvas through their seam masks.

The pixels are copied as bytes, so one compiled loop serves every dtype and channel count
(float32 working canvases, and the uint8/uint16/float companions a layout re-renders) and no
job compiles anything after :func:`quilting.core.kernels.warm_up`.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numpy.typing import NDArray


@nb.njit(cache=True, nogil=True)
def _paste(
    canvas: NDArray[np.uint8],
    blocks: NDArray[np.uint8],
    corners: NDArray[np.intp],
    owned: NDArray[np.bool_],
) -> None:
    height, width, size = canvas.shape
    count, block = owned.shape[0], owned.shape[1]
    for k in range(count):
        for y in range(block):
            row = (corners[k, 0] + y) % height
            for x in range(block):
                if owned[k, y, x]:
                    col = (corners[k, 1] + x) % width
                    for b in range(size):
                        canvas[row, col, b] = blocks[k, y, x, b]


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
    count, block = owned.shape[:2]
    if count == 0 or canvas.size == 0:
        return
    # Whole pixels as runs of bytes: (H, W, C * itemsize).
    _paste(
        canvas.reshape(height, width, -1).view(np.uint8),
        np.ascontiguousarray(blocks).reshape(count, block, block, -1).view(np.uint8),
        np.ascontiguousarray(corners, dtype=np.intp),
        np.ascontiguousarray(owned, dtype=np.bool_),
    )
