"""Moving blocks between the source and the output: gathering and pasting through seam masks."""

from __future__ import annotations

from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from quilting.core.seams import new_block_mask

Pixel = TypeVar("Pixel", bound=np.generic)


def gather(image: NDArray[Pixel], corners: NDArray[np.intp], block: int) -> NDArray[Pixel]:
    """Copy the ``block x block`` squares whose top-left corners are ``corners``.

    Parameters
    ----------
    image : ndarray, shape (H, W, C)
    corners : ndarray of int, shape (n, 2)
        (y, x) of each square; every square lies inside the image.
    block : int

    Returns
    -------
    ndarray, shape (n, block, block, C), same dtype as ``image``
    """
    windows = np.lib.stride_tricks.sliding_window_view(image, (block, block), axis=(0, 1))
    squares = windows[corners[:, 0], corners[:, 1]]  # (n, C, B, B)
    return np.ascontiguousarray(squares.transpose(0, 2, 3, 1))


def paste(
    canvas: NDArray[np.generic],
    blocks: NDArray[np.generic],
    corners: NDArray[np.intp],
    cut_cols: NDArray[np.integer],
    cut_rows: NDArray[np.integer],
) -> None:
    """Write each block into ``canvas`` where its seam says the new block owns the pixel.

    Parameters
    ----------
    canvas : ndarray, shape (H, W, C), modified in place
    blocks : ndarray, shape (n, B, B, C) or broadcastable to it
    corners : ndarray of int, shape (n, 2)
        (y, x) on the canvas of each block's top-left corner.
    cut_cols, cut_rows : ndarray of int, shape (n, B)
        Each block's seam (:func:`quilting.core.seams.new_block_mask`).
    """
    owned = new_block_mask(cut_cols, cut_rows)
    # Below the lowest cut row and right of the rightmost cut column every pixel is new: a plain
    # copy there, masked copies only in the two bands the seams run through (2x faster).
    first_row = cut_rows.max(axis=1).tolist()
    first_col = cut_cols.max(axis=1).tolist()
    block = owned.shape[1]
    for k, (y, x) in enumerate(corners.tolist()):
        r, c = first_row[k], first_col[k]
        region = canvas[y : y + block, x : x + block]
        source = np.broadcast_to(blocks[k], region.shape)
        region[r:, c:] = source[r:, c:]
        if r:
            np.copyto(region[:r], source[:r], where=owned[k, :r, :, None])
        if c:
            np.copyto(region[r:, :c], source[r:, :c], where=owned[k, r:, :c, None])
