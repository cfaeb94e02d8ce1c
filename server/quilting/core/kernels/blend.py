"""Compiled parts of the seam blend (:mod:`quilting.core.blend`): the divergence of the
gradient change asked for across the cuts, and the corrections added to the canvas.

Both do the numpy code's float32 arithmetic they replaced in the same order, so the blend
keeps its bytes: per seam edge ``1.25 (wanted - pasted)`` with ``wanted`` the mean of both
sides' differences (or the block's own), added at the edge's first pixel and subtracted at
its second, the edges across rows before those across columns and, along each, the
additions before the subtractions; the cells' corrections added pixel by pixel in block
order (what ``np.add.at`` does where footprints overlap).

References
----------
Pérez, P., Gangnet, M. and Blake, A. "Poisson Image Editing", SIGGRAPH 2003, §2-3.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numpy.typing import NDArray


@nb.njit(cache=True, nogil=True, inline="always")
def _edge_change(
    old: NDArray[np.float32],
    new: NDArray[np.float32],
    k: int,
    py: int,
    px: int,
    qy: int,
    qx: int,
    c: int,
    both: bool,
    first_owned: bool,
    overshoot: np.float32,
) -> np.float32:
    """The gradient change on the seam edge from pixel p to pixel q of cell k, channel c;
    ``both``: blocks placed before covered p and q, ``first_owned``: the block owns p."""
    d_new = new[k, qy, qx, c] - new[k, py, px, c]
    wanted = np.float32(0.5) * (d_new + (old[k, qy, qx, c] - old[k, py, px, c])) if both else d_new
    if first_owned:
        pasted = old[k, qy, qx, c] - new[k, py, px, c]
    else:
        pasted = new[k, qy, qx, c] - old[k, py, px, c]
    return overshoot * (wanted - pasted)  # type: ignore[no-any-return]


@nb.njit(cache=True, nogil=True)
def _divergence(
    old: NDArray[np.float32],
    new: NDArray[np.float32],
    owned: NDArray[np.bool_],
    covered: NDArray[np.bool_],
    overshoot: np.float32,
    out: NDArray[np.float32],
) -> None:
    count, side, _, channels = old.shape
    for k in range(count):
        for y in range(side):
            for x in range(side):
                here = owned[k, y, x]
                down = y + 1 < side and owned[k, y + 1, x] != here
                up = y > 0 and owned[k, y - 1, x] != here
                right = x + 1 < side and owned[k, y, x + 1] != here
                left = x > 0 and owned[k, y, x - 1] != here
                if not (down or up or right or left):
                    continue
                # What an edge's change needs besides the pixels, read once for the channels
                # (inlined and unswitched, this pass is 2-3x faster than asking per channel):
                # both ends covered, and whether the block owns the edge's first pixel (this
                # one on the edges leaving it, the neighbour, so not this one, entering it).
                mine = covered[k, y, x]
                both_down = down and mine and covered[k, y + 1, x]
                both_up = up and mine and covered[k, y - 1, x]
                both_right = right and mine and covered[k, y, x + 1]
                both_left = left and mine and covered[k, y, x - 1]
                for c in range(channels):
                    total = np.float32(0.0)
                    if down:
                        total = total + _edge_change(
                            old, new, k, y, x, y + 1, x, c, both_down, here, overshoot
                        )
                    if up:
                        total = total - _edge_change(
                            old, new, k, y - 1, x, y, x, c, both_up, not here, overshoot
                        )
                    if right:
                        total = total + _edge_change(
                            old, new, k, y, x, y, x + 1, c, both_right, here, overshoot
                        )
                    if left:
                        total = total - _edge_change(
                            old, new, k, y, x - 1, y, x, c, both_left, not here, overshoot
                        )
                    out[k, y, x, c] = total


def seam_divergence(
    old: NDArray[np.float32],
    new: NDArray[np.float32],
    owned: NDArray[np.bool_],
    covered: NDArray[np.bool_],
    overshoot: float,
) -> NDArray[np.float32]:
    """:func:`quilting.core.blend.seam_divergence`, compiled.

    Parameters
    ----------
    old, new : ndarray of float32, shape (n, s, s, C)
    owned, covered : ndarray of bool, shape (n, s, s)
    overshoot : float
        The factor on the change (:data:`quilting.core.blend.OVERSHOOT`).

    Returns
    -------
    ndarray of float32, shape (n, s, s, C)
    """
    out = np.zeros(old.shape, dtype=np.float32)
    _divergence(
        np.ascontiguousarray(old, dtype=np.float32),
        np.ascontiguousarray(new, dtype=np.float32),
        np.ascontiguousarray(owned, dtype=np.bool_),
        np.ascontiguousarray(covered, dtype=np.bool_),
        np.float32(overshoot),
        out,
    )
    return out


@nb.njit(cache=True, nogil=True)
def _add_cells(
    canvas: NDArray[np.float32], cells: NDArray[np.float32], origins: NDArray[np.intp]
) -> None:
    height, width, channels = canvas.shape
    count, side = cells.shape[0], cells.shape[1]
    for k in range(count):
        for y in range(side):
            row = (origins[k, 0] + y) % height
            for x in range(side):
                col = (origins[k, 1] + x) % width
                for c in range(channels):
                    canvas[row, col, c] = canvas[row, col, c] + cells[k, y, x, c]


def add_cells(
    canvas: NDArray[np.float32], cells: NDArray[np.float32], origins: NDArray[np.intp]
) -> None:
    """``canvas[(oy + y) % H, (ox + x) % W] += cells[k, y, x]`` for every cell k in order
    (the canvas a torus), in place.

    Parameters
    ----------
    canvas : ndarray of float32, shape (H, W, C), C-contiguous
    cells : ndarray of float32, shape (n, s, s, C)
    origins : ndarray of int, shape (n, 2)
    """
    _add_cells(
        canvas,
        np.ascontiguousarray(cells, dtype=np.float32),
        np.ascontiguousarray(origins, dtype=np.intp),
    )
