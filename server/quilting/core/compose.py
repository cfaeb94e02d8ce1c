"""Moving blocks between the source and the output: gathering and pasting through seam masks.

On a torus canvas (tileable output) a block may run past the right or bottom edge; its pixels
there are those of the first columns (rows), reached by wrapped indices.
"""

from __future__ import annotations

from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from quilting.core import kernels
from quilting.core.seams import new_block_mask

Pixel = TypeVar("Pixel", bound=np.generic)


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
    canvas : ndarray, shape (H, W, C), C-contiguous, modified in place
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
    n, block = owned.shape[:2]
    pixels = np.broadcast_to(blocks, (n, block, block, canvas.shape[2])).astype(
        canvas.dtype, copy=False
    )
    kernels.paste_pixels(canvas, pixels, corners, owned)
    return owned
