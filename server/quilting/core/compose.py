"""Moving blocks between the source and the output: gathering and pasting through seam masks.

On a torus canvas (tileable output) a block may run past the right or bottom edge; its pixels
there are those of the first columns (rows), reached by wrapped indices.
"""

from __future__ import annotations

from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from quilting.core.seams import new_block_mask

Pixel = TypeVar("Pixel", bound=np.generic)


def _wrapped(start: int, block: int, size: int) -> NDArray[np.intp]:
    return (start + np.arange(block, dtype=np.intp)) % size


def gather(
    image: NDArray[Pixel], corners: NDArray[np.intp], block: int, wrap: bool = False
) -> NDArray[Pixel]:
    """Copy the ``block x block`` squares whose top-left corners are ``corners``.

    Parameters
    ----------
    image : ndarray, shape (H, W, C)
    corners : ndarray of int, shape (n, 2)
        (y, x) of each square; every square lies inside the image, unless ``wrap``.
    block : int
    wrap : bool
        Take the image as a torus: a square running past the bottom or right edge continues
        at the top or left.

    Returns
    -------
    ndarray, shape (n, block, block, C), same dtype as ``image``
    """
    height, width = image.shape[:2]
    if (
        wrap
        and corners.size
        and (int(corners[:, 0].max()) + block > height or int(corners[:, 1].max()) + block > width)
    ):
        ys = (corners[:, :1] + np.arange(block)) % height  # (n, B)
        xs = (corners[:, 1:] + np.arange(block)) % width
        return np.ascontiguousarray(image[ys[:, :, None], xs[:, None, :]])
    windows = np.lib.stride_tricks.sliding_window_view(image, (block, block), axis=(0, 1))
    squares = windows[corners[:, 0], corners[:, 1]]  # (n, C, B, B)
    return np.ascontiguousarray(squares.transpose(0, 2, 3, 1))


def paste(
    canvas: NDArray[np.generic],
    blocks: NDArray[np.generic],
    corners: NDArray[np.intp],
    cut_cols: NDArray[np.integer],
    cut_rows: NDArray[np.integer],
    cut_right: NDArray[np.integer] | None = None,
    cut_bottom: NDArray[np.integer] | None = None,
) -> NDArray[np.bool_]:
    """Write each block into ``canvas`` where its seam says the new block owns the pixel;
    returns that mask, shape (n, B, B).

    Parameters
    ----------
    canvas : ndarray, shape (H, W, C), modified in place
        Taken as a torus where a block runs past its bottom or right edge.
    blocks : ndarray, shape (n, B, B, C) or broadcastable to it
    corners : ndarray of int, shape (n, 2)
        (y, x) on the canvas of each block's top-left corner.
    cut_cols, cut_rows : ndarray of int, shape (n, B)
        Each block's seam (:func:`quilting.core.seams.new_block_mask`).
    cut_right, cut_bottom : ndarray of int, shape (n, B), optional
        Seams against blocks on the right and below, across the wrap of a torus.
    """
    owned = new_block_mask(cut_cols, cut_rows, cut_right, cut_bottom)
    n = owned.shape[0]
    far = np.zeros(n, dtype=bool)  # blocks with a cut on the right or below
    for cut in (cut_right, cut_bottom):
        if cut is not None:
            far |= (np.asarray(cut) < owned.shape[1]).any(axis=1)
    # Below the lowest cut row and right of the rightmost cut column every pixel is new: a plain
    # copy there, masked copies only in the two bands the seams run through (2x faster).
    first_row = cut_rows.max(axis=1).tolist()
    first_col = cut_cols.max(axis=1).tolist()
    block = owned.shape[1]
    height, width = canvas.shape[:2]
    for k, (y, x) in enumerate(corners.tolist()):
        source = np.broadcast_to(blocks[k], (block, block, canvas.shape[2]))
        if far[k] or y + block > height or x + block > width:
            ys = _wrapped(y, block, height)[:, None]
            xs = _wrapped(x, block, width)[None, :]
            canvas[ys, xs] = np.where(owned[k, :, :, None], source, canvas[ys, xs])
            continue
        r, c = first_row[k], first_col[k]
        region = canvas[y : y + block, x : x + block]
        region[r:, c:] = source[r:, c:]
        if r:
            np.copyto(region[:r], source[:r], where=owned[k, :r, :, None])
        if c:
            np.copyto(region[r:, :c], source[r:, :c], where=owned[k, r:, :c, None])
    return owned
