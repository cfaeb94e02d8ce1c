"""Compiled minimum cuts over an arbitrary overlap region (a fill's blocks).

A block placed over a hole overlaps known pixels on any side and in any shape, so its seam is
no path through a strip but a minimum s-t cut of the block's pixel grid: pixels that must keep
the old output (the image's known pixels, and those on the block's rim where the old output
continues outside it) are tied to the source, pixels nobody has written yet are tied to the
sink, and the edge between 4-neighbours ``p, q`` costs ``e(p) + e(q)``, ``e`` the squared
difference of old and new there. The maximum flow is found by Dinic's blocking flows on the
implicit grid graph; the pixels still reachable from the source in the residual graph keep the
old output, every other pixel takes the new block.

References
----------
.. [1] V. Kwatra, A. Schoedl, I. Essa, G. Turk and A. Bobick, "Graphcut Textures: Image and
       Video Synthesis Using Graph Cuts", SIGGRAPH 2003, §3 (the patch seam as a minimum cut,
       the matching cost ``|A(s) - B(s)| + |A(t) - B(t)|`` of adjacent pixels, old pixels on
       the patch's border tied to the old side).
.. [2] E. A. Dinic, "Algorithm for solution of a problem of maximum flow in networks with
       power estimation", Soviet Math. Doklady 11, 1970 (level graphs and blocking flows).
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numpy.typing import NDArray

#: Pixel states of :func:`region_cuts`.
FREE, OLD, NEW = 0, 1, 2


@nb.njit(cache=True, nogil=True)
def _neighbour(p: int, d: int, side: int) -> int:
    """The pixel ``d`` (0 right, 1 down, 2 left, 3 up) of pixel ``p``, or -1 past the edge."""
    y, x = p // side, p % side
    if d == 0:
        return p + 1 if x + 1 < side else -1
    if d == 1:
        return p + side if y + 1 < side else -1
    if d == 2:
        return p - 1 if x > 0 else -1
    return p - side if y > 0 else -1


@nb.njit(cache=True, nogil=True)
def _levels(
    residual: NDArray[np.float64],
    state: NDArray[np.int8],
    side: int,
    level: NDArray[np.int32],
    queue: NDArray[np.int32],
) -> bool:
    """Breadth-first levels from every OLD pixel through arcs with residual capacity; True
    when a NEW pixel is reached. NEW pixels are not expanded (the sink is one step past
    them)."""
    size = side * side
    head = tail = 0
    for p in range(size):
        level[p] = -1
        if state[p] == OLD:
            level[p] = 0
            queue[tail] = p
            tail += 1
    reached = False
    while head < tail:
        p = queue[head]
        head += 1
        if state[p] == NEW:
            reached = True
            continue
        for d in range(4):
            q = _neighbour(p, d, side)
            if q >= 0 and level[q] < 0 and residual[p, d] > 0.0:
                level[q] = level[p] + 1
                queue[tail] = q
                tail += 1
    return reached


@nb.njit(cache=True, nogil=True)
def _blocking_flow(
    residual: NDArray[np.float64],
    state: NDArray[np.int8],
    side: int,
    level: NDArray[np.int32],
    arc: NDArray[np.int8],
    path: NDArray[np.int32],
    turns: NDArray[np.int8],
) -> None:
    """Saturate the level graph: augmenting paths OLD -> NEW along arcs one level up, each
    node's next arc remembered so that a dead arc is never tried twice in a phase."""
    size = side * side
    for p in range(size):
        arc[p] = 0
    for start in range(size):
        if state[start] != OLD or level[start] != 0:
            continue
        depth = 0
        path[0] = start
        while depth >= 0:
            p = path[depth]
            if state[p] == NEW:
                # Augment by the path's bottleneck; the arc at the minimum saturates exactly.
                bottleneck = np.inf
                for k in range(depth):
                    r = residual[path[k], turns[k]]
                    if r < bottleneck:
                        bottleneck = r
                for k in range(depth):
                    u, d = path[k], turns[k]
                    residual[u, d] -= bottleneck
                    residual[_neighbour(u, d, side), (d + 2) % 4] += bottleneck
                depth = 0
                continue
            advanced = False
            while arc[p] < 4:
                d = arc[p]
                q = _neighbour(p, d, side)
                if q >= 0 and residual[p, d] > 0.0 and level[q] == level[p] + 1:
                    turns[depth] = d
                    depth += 1
                    path[depth] = q
                    advanced = True
                    break
                arc[p] += 1
            if not advanced:
                level[p] = -1  # a dead end for the rest of this phase
                depth -= 1
                if depth >= 0:
                    arc[path[depth]] += 1


@nb.njit(cache=True, nogil=True)
def _cut_one(errors: NDArray[np.float64], state: NDArray[np.int8]) -> NDArray[np.bool_]:
    side = errors.shape[0]
    size = side * side
    flat_errors = errors.ravel()
    flat_state = state.ravel()
    residual = np.zeros((size, 4), dtype=np.float64)
    for p in range(size):
        for d in range(4):
            q = _neighbour(p, d, side)
            if q >= 0:
                residual[p, d] = flat_errors[p] + flat_errors[q]
    level = np.empty(size, dtype=np.int32)
    queue = np.empty(size, dtype=np.int32)
    arc = np.empty(size, dtype=np.int8)
    path = np.empty(size + 1, dtype=np.int32)
    turns = np.empty(size + 1, dtype=np.int8)
    while _levels(residual, flat_state, side, level, queue):
        _blocking_flow(residual, flat_state, side, level, arc, path, turns)
    # The old side: what the source still reaches (NEW pixels never are, once the flow is
    # maximal); every other pixel is the new block's.
    _levels(residual, flat_state, side, level, queue)
    owned = np.empty(size, dtype=np.bool_)
    for p in range(size):
        owned[p] = level[p] < 0
    return owned.reshape(side, side)


@nb.njit(cache=True, nogil=True)
def region_cuts(errors: NDArray[np.float64], state: NDArray[np.int8]) -> NDArray[np.bool_]:
    """Minimum cuts of a batch of blocks between pixels tied to the old output and to the new.

    Parameters
    ----------
    errors : ndarray of float64, shape (n, B, B)
        ``e(p)``: squared difference of the old output and the new block at each pixel (0
        where there is no old output).
    state : ndarray of int8, shape (n, B, B)
        :data:`OLD` (must keep the old output), :data:`NEW` (must take the block) or
        :data:`FREE` (the cut decides).

    Returns
    -------
    ndarray of bool, shape (n, B, B)
        Where the block takes the pixel: every NEW pixel, no OLD pixel, and the FREE pixels
        on the block's side of a cut of least total ``e(p) + e(q)`` over the 4-neighbour
        pairs it separates.
    """
    count, side = errors.shape[0], errors.shape[1]
    owned = np.empty((count, side, side), dtype=np.bool_)
    for k in range(count):
        owned[k] = _cut_one(errors[k], state[k])
    return owned
