"""Boundary cuts between a new block and the output already in place.

This is the minimum-error boundary cut of Efros & Freeman (2001, section 2.1): a dynamic
programme over the overlap error surface finds the cheapest 8-connected path through the left
strip (vertical) and/or the top strip (horizontal); for an L-shaped overlap the two paths meet
at the point of the top-left O x O corner where their total cost is least. The straight cuts of
the paper's "random" and "overlap" variants (Fig. 2a/2b) share the same representation.

A cut is stored per block as two int16 arrays, ``cut_cols`` (indexed by row) and ``cut_rows``
(indexed by column); the new block owns pixel ``(y, x)`` iff ``x >= cut_cols[y]`` and
``y >= cut_rows[x]`` (see :func:`new_block_mask`). For an L-shaped overlap with meeting point
``(py, px)``, ``cut_cols[y] = px`` for ``y < py`` and ``cut_rows[x] = py`` for ``x < px``, so
the region above and left of the meeting point keeps the old output.

Every function works on a batch of ``n`` blocks of one kind at once (one wavefront level); the
dynamic programme runs compiled, block by block (:mod:`quilting.core.kernels.seams`).

Tie-breaking is deterministic and independent of the batch: the start of a path is the lowest
index among equal costs (leftmost column, topmost row); at each step a path goes straight on if
that is among the cheapest continuations, else to the lower index (left, up), else the higher;
the meeting point is the first minimum of the corner in row-major order (smallest ``py``, then
smallest ``px``). Costs are summed sequentially along each path, so a block's cost is bit-for-bit
the same whatever the batch it is cut in.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from quilting.core import kernels
from quilting.core.errors import InvalidParameterError

__all__ = [
    "CONTEXT",
    "CONTEXT_RADIUS",
    "EDGE_COST",
    "far_side_cuts",
    "minimum_error_cuts",
    "new_block_mask",
    "straight_cuts",
    "strip_cuts",
]

Cuts = tuple[NDArray[np.int16], NDArray[np.int16], NDArray[np.float64]]
#: The engine's ``edge_cost`` of :func:`minimum_error_cuts` (cut mode). Without it 7.5 % of the
#: seams' length (median over 18 textures, 512² outputs, block/6 overlaps; up to 15 %) ran
#: straight along a band's edge for 5 pixels or more, where wider overlaps (1/3 of the block)
#: only got it to 4.8 %. With 0.1 it is 1.5 % and the seam and coherence figures stay as they
#: were (blended: seam_grad 0.684 -> 0.679, coh_p95 0.644 -> 0.650); 0.2 gave 1.1 % and 0.5
#: 0.8 %, but cuts pushed off the edge cross worse error (seam_grad 0.716, 0.710): see
#: benchmarks/bench_quality.py, 'edge run', and RESULTS.md.
EDGE_COST = 0.1
#: The engine's ``context`` of :func:`minimum_error_cuts` (cut mode): the weight of the error
#: around a path's pixels beside the error on them. An 8 x 8 patch across a cut looks like the
#: texture when the two sides agree over the patch, not only on the cut's pixels; a path that
#: threads through pixels that happen to agree between two stones leaves a half stone beside it.
#: Weighing in the mean error of the (2 CONTEXT_RADIUS + 1)² window around each pixel (within
#: the strips) steers the cut through regions where the sides agree. Measured on 18 textures,
#: 512² outputs, 3 seeds, the issue's rule block (benchmarks/bench_quality.py, RESULTS.md):
#: coherence (coh_p95) 0.648 -> 0.631, seam_grad 0.672 -> 0.667; the window alone (no pixel
#: term) reached 0.628 but let single pixels of a path differ more (seam_grad 0.77), and
#: weights 0.25 or 1 and windows of 3, 7 or 9 pixels measured worse.
CONTEXT = 0.5
#: Radius of the context's window: 5 x 5 pixels, about the reach of a texture patch each side
#: of the cut within an overlap of block / 6.
CONTEXT_RADIUS = 2
Cutter = Callable[..., Cuts]
"""``cutter(e, *, left, top, overlap)``: :func:`minimum_error_cuts` or :func:`straight_cuts`."""


def _check(e: ArrayLike, overlap: int) -> NDArray[np.float64]:
    """Validate the error surface and the overlap; return ``e`` as float64 (n, B, B)."""
    # C order so that path pixels can be gathered from the flat array.
    arr = np.ascontiguousarray(e, dtype=np.float64)
    if arr.ndim != 3 or arr.shape[1] != arr.shape[2] or arr.shape[1] == 0:
        raise InvalidParameterError(
            "e", f"array of shape {arr.shape}", "a float array of shape (n, B, B), B >= 1"
        )
    size = arr.shape[1]
    if isinstance(overlap, bool) or not isinstance(overlap, int | np.integer):
        raise InvalidParameterError("overlap", overlap, "an integer")
    if not 1 <= overlap <= size:
        raise InvalidParameterError("overlap", overlap, f"1..{size} (the block size)")
    return arr


def _empty_cuts(n: int, size: int) -> Cuts:
    return (
        np.zeros((n, size), dtype=np.int16),
        np.zeros((n, size), dtype=np.int16),
        np.zeros(n, dtype=np.float64),
    )


def _stage_sums(values: NDArray[np.float64]) -> NDArray[np.float64]:
    """Column sums of an (L, m) array, added strictly in stage order.

    ``ndarray.sum`` may pick a different (pairwise, blocked) order depending on m and the
    memory layout, which would make a block's cost depend on its batch; cumsum is sequential.
    """
    if values.shape[0] == 0:
        return np.zeros(values.shape[1], dtype=np.float64)
    sums: NDArray[np.float64] = np.cumsum(values, axis=0)[-1]
    return sums


def minimum_error_cuts(
    e: NDArray[np.float64],
    *,
    left: bool,
    top: bool,
    overlap: int,
    edge_cost: float = 0.0,
    context: float = 0.0,
) -> Cuts:
    """Minimum-error boundary cuts of a batch of blocks of the same overlap kind.

    Parameters
    ----------
    e : ndarray, shape (n, B, B)
        Per-pixel squared difference (summed over channels) between the output already in
        place and each new block. Only the overlap strips are read: ``e[:, :, :overlap]`` when
        ``left`` and ``e[:, :overlap, :]`` when ``top``.
    left, top : bool
        Which overlaps the blocks have; both give the L-shaped cut, neither the empty cut.
    overlap : int
        Overlap width O, ``1 <= O <= B``.
    edge_cost : float
        Extra cost the paths see on the strips' first and last columns (rows), as a multiple
        of each block's mean ``e`` over its strips: a cut then runs along a band's edge only
        where the error there is that much lower than inside (the texture has a straight
        edge there), instead of wherever the band is too narrow to wander (:data:`EDGE_COST`;
        0: the plain minimum-error cut). Only the choice of path sees it, not ``cost``.
    context : float
        Weight w of each pixel's neighbourhood: the paths see ``(e + w m) / (1 + w)`` on the
        strips, ``m`` the mean of ``e`` over the strips' pixels within
        :data:`CONTEXT_RADIUS` of the pixel (Chebyshev distance), so that a cut passes where
        the two sides agree around it, not only on it (:data:`CONTEXT`; 0: the plain error).
        The edge cost is added to that surface; ``cost`` is still the plain error's.

    Returns
    -------
    cut_cols : ndarray of int16, shape (n, B)
        Column of the vertical cut at each row (all 0 without a left overlap).
    cut_rows : ndarray of int16, shape (n, B)
        Row of the horizontal cut at each column (all 0 without a top overlap).
    cost : ndarray of float64, shape (n,)
        Sum of ``e`` over the path pixels, the meeting point counted once; 0 without overlap.

    Notes
    -----
    Left only: ``cut_cols`` is the cheapest path with one pixel per row, moving at most one
    column between rows, inside ``[0, O)``; top only: the same for ``cut_rows`` through the top
    strip. L-shaped: with ``Ev`` (``Eh``) the cheapest cost from a pixel down (right) to the
    border, the meeting point ``p`` in the O x O corner minimises ``Ev[p] + Eh[p] - e[p]``;
    both paths are traced from ``p`` and filled with ``p``'s column (row) before it.
    Ties: see the module docstring.
    """
    err = _check(e, overlap)
    n, size, _ = err.shape
    if n == 0 or not (left or top):
        return _empty_cuts(n, size)
    return kernels.surface_cuts(
        err,
        left=left,
        top=top,
        overlap=overlap,
        edge_cost=edge_cost,
        context=context,
        radius=CONTEXT_RADIUS,
    )


def strip_cuts(strips: ArrayLike) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """Cheapest 8-connected top-to-bottom paths through strips of any length and width.

    The DP of :func:`minimum_error_cuts` for a left strip, without the square block around
    it (a band along a whole image side, say). Ties as in the module docstring.

    Parameters
    ----------
    strips : ndarray, shape (n, L, O)
        Error of each strip, row by row.

    Returns
    -------
    positions : ndarray of intp, shape (n, L)
        Column of each path in its strip at each row, ``0 .. O - 1``.
    cost : ndarray of float64, shape (n,)
        Sum of the error along each path.
    """
    err = np.ascontiguousarray(strips, dtype=np.float64)
    if err.ndim != 3 or 0 in err.shape:
        raise InvalidParameterError(
            "strips", f"array of shape {err.shape}", "a float array of shape (n, L, O), L, O >= 1"
        )
    width = err.shape[2]
    cut_cols, _, cost = kernels.surface_cuts(err, left=True, top=False, overlap=width)
    return cut_cols.astype(np.intp), cost


def straight_cuts(e: NDArray[np.float64], *, left: bool, top: bool, overlap: int) -> Cuts:
    """Straight cuts in the middle of the overlap, for the "overlap" and "random" modes.

    Parameters
    ----------
    e : ndarray, shape (n, B, B)
        Error surface as for :func:`minimum_error_cuts`; only used for the cost.
    left, top : bool
        Which overlaps the blocks have.
    overlap : int
        Overlap width O, ``1 <= O <= B``; the line lies at column/row ``c = O // 2``.

    Returns
    -------
    cut_cols, cut_rows : ndarray of int16, shape (n, B)
        ``c`` everywhere for each overlap present (in the L case the vertical line at column
        ``c`` for rows ``>= c`` and the horizontal one at row ``c`` for columns ``>= c`` meet at
        ``(c, c)``, and the corner fill rule gives ``c`` before it too), 0 otherwise.
    cost : ndarray of float64, shape (n,)
        Sum of ``e`` over the line pixels, the meeting point counted once.
    """
    err = _check(e, overlap)
    n, size, _ = err.shape
    cut_cols, cut_rows, cost = _empty_cuts(n, size)
    c = overlap // 2
    if left and top:
        cut_cols[:] = c
        cut_rows[:] = c
        cost = _stage_sums(err[:, c:, c].T) + _stage_sums(err[:, c, c + 1 :].T)
    elif left:
        cut_cols[:] = c
        cost = _stage_sums(err[:, :, c].T)
    elif top:
        cut_rows[:] = c
        cost = _stage_sums(err[:, c, :].T)
    return cut_cols, cut_rows, cost


def new_block_mask(
    cut_cols: NDArray[np.integer],
    cut_rows: NDArray[np.integer],
    cut_right: NDArray[np.integer] | None = None,
    cut_bottom: NDArray[np.integer] | None = None,
) -> NDArray[np.bool_]:
    """Pixels of each block's footprint that the new block owns.

    Parameters
    ----------
    cut_cols, cut_rows : ndarray of int, shape (n, B)
        Cuts as returned by :func:`minimum_error_cuts` or :func:`straight_cuts`.
    cut_right, cut_bottom : ndarray of int, shape (n, B), optional
        The cuts against blocks on the right and below (across the wrap of a torus): the new
        block owns columns ``< cut_right[y]`` of row y and rows ``< cut_bottom[x]`` of column
        x; B (or None) means no cut.

    Returns
    -------
    ndarray of bool, shape (n, B, B)
        ``mask[k, y, x]`` is true iff ``x >= cut_cols[k, y]`` and ``y >= cut_rows[k, x]``
        (and ``x < cut_right[k, y]``, ``y < cut_bottom[k, x]``); false pixels keep the old
        output.
    """
    cols = np.asarray(cut_cols)
    rows = np.asarray(cut_rows)
    if cols.ndim != 2 or cols.shape != rows.shape:
        raise InvalidParameterError(
            "cut_cols/cut_rows",
            f"shapes {cols.shape} and {rows.shape}",
            "two arrays of the same shape (n, B)",
        )
    idx = np.arange(cols.shape[1])
    owned = idx[None, None, :] >= cols[:, :, None]
    owned &= idx[None, :, None] >= rows[:, None, :]
    if cut_right is not None:
        owned &= idx[None, None, :] < np.asarray(cut_right)[:, :, None]
    if cut_bottom is not None:
        owned &= idx[None, :, None] < np.asarray(cut_bottom)[:, None, :]
    return owned


def far_side_cuts(
    cutter: Cutter, e: NDArray[np.float64], *, right: bool, bottom: bool, overlap: tuple[int, int]
) -> tuple[NDArray[np.int16], NDArray[np.int16], NDArray[np.float64]]:
    """Cuts against blocks on the right and/or below, for the wrap of a torus.

    The surface is mirrored so that the far strip becomes a near one, cut by ``cutter``
    (:func:`minimum_error_cuts` or :func:`straight_cuts`) and mirrored back. The right and
    bottom cuts are independent paths over the whole height and width of their strips; where
    they and the near cuts cross, a pixel stays old if any cut gives it to the old side.

    Parameters
    ----------
    cutter : callable
    e : ndarray, shape (n, B, B)
        Error surfaces as for :func:`minimum_error_cuts`.
    right, bottom : bool
        Which far strips to cut.
    overlap : (int, int)
        Height of the bottom strip and width of the right strip.

    Returns
    -------
    cut_right, cut_bottom : ndarray of int16, shape (n, B)
        The new block owns ``x < cut_right[y]`` and ``y < cut_bottom[x]``; B where not cut.
    cost : ndarray of float64, shape (n,)
        Sum of ``e`` along both paths.
    """
    err = np.asarray(e, dtype=np.float64)
    n, size = err.shape[0], err.shape[1]
    cut_right = np.full((n, size), size, dtype=np.int16)
    cut_bottom = np.full((n, size), size, dtype=np.int16)
    cost = np.zeros(n, dtype=np.float64)
    if right:
        cc, _, c = cutter(err[:, :, ::-1], left=True, top=False, overlap=overlap[1])
        cut_right = (size - cc).astype(np.int16)
        cost += c
    if bottom:
        _, rr, c = cutter(err[:, ::-1, :], left=False, top=True, overlap=overlap[0])
        cut_bottom = (size - rr).astype(np.int16)
        cost += c
    return cut_right, cut_bottom, cost
