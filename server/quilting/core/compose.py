"""Moving blocks between the source and the output: gathering and pasting through seam masks."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def gather(image: NDArray[np.generic], corners: NDArray[np.intp], block: int) -> NDArray[np.generic]:
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
    owned: NDArray[np.bool_],
) -> None:
    """Write each block into ``canvas`` where its seam mask says the new block owns the pixel.

    Parameters
    ----------
    canvas : ndarray, shape (H, W, C), modified in place
    blocks : ndarray, shape (n, B, B, C) or broadcastable to it
    corners : ndarray of int, shape (n, 2)
        (y, x) on the canvas of each block's top-left corner.
    owned : ndarray of bool, shape (n, B, B)
        True where the new block replaces what the canvas holds.
    """
    block = owned.shape[1]
    for k, (y, x) in enumerate(corners.tolist()):
        np.copyto(canvas[y : y + block, x : x + block], blocks[k], where=owned[k, :, :, None])
