"""The minimum-resistance walk cut and the four-block blend of the random-quilting variant.

After the minimum-resistance-cut paper (random block quilting with a minimum-resistance cut line,
for flight-simulator terrain), sections 2 and 3: instead of a dynamic programme, the cut toward a
block's left edge is traced greedily. Path 1 climbs from the bottom-left corner to the top row,
always stepping to the neighbour (left, up-left, up, up-right, right) of least resistance; path 2
descends from the top-left corner the same way (left, down-left, down, down-right, right) until it
reaches or crosses path 1. Path 2 plus the part of path 1 below the meeting point is the cut; the
old side is the lens between the left edge and the cut. The top-edge cut is the same walk on
transposed surfaces. No more than ``max_run`` consecutive path pixels may share a row or a column,
which keeps the cut from running along straight lines and bounds how far it strays from the edge.

The cut uses the representation of :mod:`quilting.core.seams`: ``cut_cols[y]`` is the first
column the new block owns in row ``y``. :func:`walk_compose` then blends across the cut with a
linear ramp and, where nothing is written yet, mixes the four blocks of the paper's corner
(the new block and the continuations of its left, upper and upper-left neighbours).
:func:`reflect_gather` reads those continuations from the source extended by its reflection.

Tie order (fixed, the same for every block whatever its batch): straight on first (up for path
1, down for path 2), then the diagonal toward the lower column, the other diagonal, the
sideways step to the lower column, the sideways step to the higher one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from quilting.core.compose import gather
from quilting.core.errors import InvalidParameterError
from quilting.core.grid import Grid

__all__ = [
    "WalkCuts",
    "continuation_corners",
    "covered_pixels",
    "fill_blocks",
    "ramp",
    "reflect_gather",
    "regions",
    "walk_compose",
    "walk_cuts",
]

Pixel = TypeVar("Pixel", bound=np.generic)

# Candidate steps (dy, dx) in tie order: argmin keeps the first of equal costs.
_RISING = np.array([(-1, 0), (-1, -1), (-1, 1), (0, -1), (0, 1)], dtype=np.intp)
_FALLING = np.array([(1, 0), (1, -1), (1, 1), (0, -1), (0, 1)], dtype=np.intp)


@dataclass(frozen=True, eq=False)
class WalkCuts:
    """Walk cuts of a batch of ``n`` blocks of size ``B`` toward their left edges.

    Attributes
    ----------
    cut_cols : ndarray of int16, shape (n, B)
        The new block owns pixel ``(y, x)`` iff ``x >= cut_cols[y]``; rows 0 and B - 1 are 0.
    rising, falling : ndarray of intp, shape (n, L1, 2) and (n, L2, 2)
        Pixels ``(y, x)`` of path 1 and path 2 (ending with the meeting pixel) in walk order,
        padded with -1; L1, L2 are the longest paths of the batch.
    rising_length, falling_length : ndarray of intp, shape (n,)
        Number of pixels of each path.
    cost : ndarray of float64, shape (n,)
        Sum of the resistance over the cut pixels (path 2 and the rows >= the meeting row of
        path 1, each pixel once), added in row-major order.
    pixels : ndarray of intp, shape (n,)
        How many pixels ``cost`` sums (the cut's length in pixels).
    """

    cut_cols: NDArray[np.int16]
    rising: NDArray[np.intp]
    rising_length: NDArray[np.intp]
    falling: NDArray[np.intp]
    falling_length: NDArray[np.intp]
    cost: NDArray[np.float64]
    pixels: NDArray[np.intp]


def _check_int(name: str, value: object, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
        raise InvalidParameterError(name, value, f"an integer >= {low}")
    return int(value)


def _walk(
    r: NDArray[np.float64],
    start: tuple[int, int],
    moves: NDArray[np.intp],
    goal: NDArray[np.intp],
    max_run: int,
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
    """Greedy walks of all blocks at once, each stopping on the first pixel with ``x >= goal[y]``.

    Returns the paths (n, L, 2) padded with -1, their lengths (n,) and the visited pixels
    (n, B, B). A path never revisits a pixel, so a row holds at most ``min(max_run, B)``
    consecutive pixels and, as the walks are monotone in y, a path has at most
    ``B * min(max_run, B)`` pixels: that bounds the loop.

    If no step were allowed the walk would go straight on (up / down), which is inside the
    block while the walk runs (path 1 stops in row 0, path 2 by row B - 1 since
    ``goal[B - 1] = 0``). It cannot happen: a diagonal step always enters a row the path has
    not been in and resets both runs, and one of the two diagonals is inside as ``B >= 2``.
    """
    n, size, _ = r.shape
    flat = r.reshape(-1)
    visited = np.zeros(n * size * size, dtype=bool)
    block = np.arange(n, dtype=np.intp)
    base = block * (size * size)
    y = np.full(n, start[0], dtype=np.intp)
    x = np.full(n, start[1], dtype=np.intp)
    row_run = np.ones(n, dtype=np.intp)
    col_run = np.ones(n, dtype=np.intp)
    length = np.ones(n, dtype=np.intp)
    visited[base + y * size + x] = True
    active = x < goal[block, y]
    trail_y, trail_x = [y], [x]
    dy, dx = moves[:, 0], moves[:, 1]
    for _ in range(size * min(max_run, size) - 1):
        if not active.any():
            break
        cy, cx = y[:, None] + dy, x[:, None] + dx  # (n, 5)
        inside = (cy >= 0) & (cy < size) & (cx >= 0) & (cx < size)
        pixel = base[:, None] + np.clip(cy, 0, size - 1) * size + np.clip(cx, 0, size - 1)
        runs_y = np.where(dy == 0, row_run[:, None] + 1, 1)
        runs_x = np.where(dx == 0, col_run[:, None] + 1, 1)
        allowed = inside & ~visited[pixel] & (runs_y <= max_run) & (runs_x <= max_run)
        choice = np.where(allowed, flat[pixel], np.inf).argmin(axis=1)
        choice[~allowed.any(axis=1)] = 0  # the unreachable fallback: straight on
        y = np.where(active, cy[block, choice], y)
        x = np.where(active, cx[block, choice], x)
        row_run = np.where(active, runs_y[block, choice], row_run)
        col_run = np.where(active, runs_x[block, choice], col_run)
        visited[pixel[block, choice][active]] = True
        length += active
        trail_y.append(y)
        trail_x.append(x)
        active &= x < goal[block, y]
    path = np.stack([np.stack(trail_y, axis=1), np.stack(trail_x, axis=1)], axis=2)
    path[np.arange(path.shape[1]) >= length[:, None]] = -1
    return path, length, visited.reshape(n, size, size)


def walk_cuts(r: NDArray[np.float64], *, max_run: int) -> WalkCuts:
    """Minimum-resistance walk cuts toward the left edge of a batch of blocks.

    Parameters
    ----------
    r : ndarray, shape (n, B, B), B >= 2
        Finite resistance of each pixel (the colour difference between the new block and the
        old side's content there).
    max_run : int
        Most consecutive path pixels allowed in one row or one column, >= 1.

    Returns
    -------
    WalkCuts
        ``cut_cols[y]`` is the leftmost cut pixel of row ``y``: path 2's for rows above the
        meeting row ``ym``, path 1's below it, the lesser of both in row ``ym``. Path 2 stops
        on its first pixel ``(y, x)`` with ``x >= left1[y]`` (path 1's leftmost column in row
        ``y``), which also catches diagonal crossings that share no pixel. Ties: see the module
        docstring; a block's result does not depend on the rest of its batch.
    """
    arr = np.ascontiguousarray(r, dtype=np.float64)
    if arr.ndim != 3 or arr.shape[1] != arr.shape[2] or arr.shape[1] < 2:
        raise InvalidParameterError(
            "r", f"array of shape {arr.shape}", "a float array of shape (n, B, B), B >= 2"
        )
    if not np.isfinite(arr).all():
        raise InvalidParameterError("r", "an array with NaN or inf", "finite values")
    max_run = _check_int("max_run", max_run, 1)
    n, size, _ = arr.shape
    rows = np.arange(size, dtype=np.intp)

    # Path 1 stops on reaching row 0, whatever the column.
    top_row = np.where(rows == 0, 0, size).astype(np.intp)
    rising, rising_length, on1 = _walk(
        arr, (size - 1, 0), _RISING, np.broadcast_to(top_row, (n, size)), max_run
    )
    left1 = on1.argmax(axis=2)  # path 1 covers every row
    falling, falling_length, on2 = _walk(arr, (0, 0), _FALLING, left1, max_run)
    first2 = on2.argmax(axis=2)  # meaningful in rows <= ym, where path 2 has pixels

    ym = falling[np.arange(n), falling_length - 1, 0][:, None]
    cut = np.where(rows < ym, first2, np.where(rows > ym, left1, np.minimum(first2, left1)))
    on_cut = on2 | (on1 & (rows >= ym)[:, :, None])
    # cumsum adds strictly in row-major order: the cost is the same whatever the batch.
    masked = np.where(on_cut, arr, 0.0).reshape(n, size * size)
    cost = np.cumsum(masked, axis=1)[:, -1]
    return WalkCuts(
        cut_cols=cut.astype(np.int16),
        rising=rising,
        rising_length=rising_length,
        falling=falling,
        falling_length=falling_length,
        cost=cost.astype(np.float64),
        pixels=np.count_nonzero(on_cut.reshape(n, size * size), axis=1).astype(np.intp),
    )


def ramp(distance: NDArray[np.integer] | NDArray[np.floating], feather: int) -> NDArray[np.float32]:
    """Weight of the new side at signed distance ``d = x - cut_cols[y]`` from a cut.

    Parameters
    ----------
    distance : ndarray of any shape
        ``d >= 0`` is the new side.
    feather : int
        Width of the blend in pixels, >= 0; 0 and 1 give a hard cut.

    Returns
    -------
    ndarray of float32, same shape
        ``1`` where ``d >= 0`` else ``0`` for feather <= 1; otherwise
        ``clip((d + 0.5) / feather + 0.5, 0, 1)``, a linear blend centred between the last old
        and the first new pixel, so that ``ramp(d) + ramp(-1 - d) == 1`` up to rounding.
    """
    feather = _check_int("feather", feather, 0)
    d = np.asarray(distance, dtype=np.float32)
    if feather <= 1:
        return (d >= 0).astype(np.float32)
    w = (d + np.float32(0.5)) / np.float32(feather) + np.float32(0.5)
    weight: NDArray[np.float32] = np.clip(w, np.float32(0), np.float32(1))
    return weight


def walk_compose(
    old: NDArray[np.float32],
    covered: NDArray[np.bool_],
    new: NDArray[np.floating],
    left: NDArray[np.float32] | None,
    top: NDArray[np.float32] | None,
    diagonal: NDArray[np.float32] | None,
    cut_cols: NDArray[np.integer],
    cut_rows: NDArray[np.integer],
    has_left: NDArray[np.bool_],
    has_top: NDArray[np.bool_],
    feather: int,
) -> NDArray[np.float32]:
    """Blend each new block with what lies under and beside it across its walk cuts.

    Parameters
    ----------
    old : ndarray of float32, shape (n, B, B, C)
        Output already under each block.
    covered : ndarray of bool, shape (n, B, B)
        Which pixels of ``old`` were written.
    new : ndarray, shape (n, B, B, C)
        The new blocks.
    left, top, diagonal : ndarray of float32, shape (n, B, B, C), or None
        Continuations (in the source) of the left, upper and upper-left neighbours; None when
        no block of the batch has that neighbour. Rows of blocks without the neighbour get
        weight 0 and must merely be finite. ``diagonal`` is required when some block has both
        a left and a top neighbour (the grid then always has the upper-left one).
    cut_cols, cut_rows : ndarray of int, shape (n, B)
        Cut toward the left edge (by row) and toward the top edge (by column).
    has_left, has_top : ndarray of bool, shape (n,)
    feather : int
        Ramp width (:func:`ramp`).

    Returns
    -------
    ndarray of float32, shape (n, B, B, C)
        With ``a = ramp(x - cut_cols[y])`` (1 without a left neighbour) and
        ``b = ramp(y - cut_rows[x])`` (1 without a top one): ``ab·new + (1 - ab)·old`` where
        covered, else ``ab·new + (1-a)b·left + a(1-b)·top + (1-a)(1-b)·diagonal``, evaluated
        in that fixed order in float32 so the same inputs give the same bytes.
    """
    old32 = np.asarray(old, dtype=np.float32)
    new32 = np.asarray(new, dtype=np.float32)
    if old32.ndim != 4 or new32.shape != old32.shape or old32.shape[1] != old32.shape[2]:
        raise InvalidParameterError(
            "old/new", f"shapes {old32.shape} and {new32.shape}", "equal shapes (n, B, B, C)"
        )
    n, size = old32.shape[:2]
    shapes = {
        "covered": (np.shape(covered), (n, size, size)),
        "cut_cols": (np.shape(cut_cols), (n, size)),
        "cut_rows": (np.shape(cut_rows), (n, size)),
        "has_left": (np.shape(has_left), (n,)),
        "has_top": (np.shape(has_top), (n,)),
    }
    for name, (got, want) in shapes.items():
        if got != want:
            raise InvalidParameterError(name, f"array of shape {got}", f"shape {want}")
    hl, ht = np.asarray(has_left, dtype=bool), np.asarray(has_top, dtype=bool)
    needed = {"left": hl.any(), "top": ht.any(), "diagonal": (hl & ht).any()}
    given = {"left": left, "top": top, "diagonal": diagonal}
    for name, arr in given.items():
        if arr is None and needed[name]:
            raise InvalidParameterError(
                name,
                None,
                f"an array of shape {old32.shape}",
                "some block of the batch has this neighbour",
            )
        if arr is not None and np.shape(arr) != old32.shape:
            raise InvalidParameterError(
                name, f"array of shape {np.shape(arr)}", f"shape {old32.shape}"
            )

    idx = np.arange(size)
    a = ramp(idx[None, None, :] - np.asarray(cut_cols, dtype=np.intp)[:, :, None], feather)
    b = ramp(idx[None, :, None] - np.asarray(cut_rows, dtype=np.intp)[:, None, :], feather)
    one = np.float32(1)
    a[~hl] = one
    b[~ht] = one
    w_new = (a * b)[..., None]
    not_a, not_b = (one - a)[..., None], (one - b)[..., None]
    a4, b4 = a[..., None], b[..., None]

    fresh = w_new * new32
    # A missing continuation would add exactly +0 (its weight is 0), so it is skipped.
    for arr, weight in ((left, not_a * b4), (top, a4 * not_b), (diagonal, not_a * not_b)):
        if arr is not None:
            fresh = fresh + weight * np.asarray(arr, dtype=np.float32)
    under = w_new * new32 + (one - w_new) * old32
    out: NDArray[np.float32] = np.where(np.asarray(covered, dtype=bool)[..., None], under, fresh)
    return out


def reflect_gather(image: NDArray[Pixel], corners: NDArray[np.intp], block: int) -> NDArray[Pixel]:
    """The ``block x block`` squares at ``corners`` of ``image`` extended by its reflection.

    Parameters
    ----------
    image : ndarray, shape (H, W, C)
    corners : ndarray of int, shape (n, 2)
        (y, x) of each square's top-left corner; squares may run past any edge.
    block : int
        Side of the squares, >= 1.

    Returns
    -------
    ndarray, shape (n, block, block, C), same dtype as ``image``
        Indices past an edge are mirrored without repeating the edge pixel (``H + k`` reads
        ``H - 2 - k``, ``-k`` reads ``k``), folded again as often as needed: the same pixels
        as ``np.pad(image, ..., mode="reflect")``.
    """
    block = _check_int("block", block, 1)
    img = np.asarray(image)
    pos = np.asarray(corners)
    if img.ndim != 3 or 0 in img.shape[:2]:
        raise InvalidParameterError("image", f"array of shape {img.shape}", "shape (H, W, C)")
    if pos.ndim != 2 or pos.shape[1] != 2 or not np.issubdtype(pos.dtype, np.integer):
        raise InvalidParameterError(
            "corners", f"array of shape {pos.shape}", "an integer array of shape (n, 2)"
        )

    def fold(start: NDArray[np.intp], size: int) -> NDArray[np.intp]:
        # Reflection without edge repeat is periodic with period 2 (size - 1).
        period = max(2 * (size - 1), 1)
        k = (start[:, None] + np.arange(block, dtype=np.intp)) % period
        folded: NDArray[np.intp] = np.minimum(k, period - k)
        return folded

    ys = fold(pos[:, 0].astype(np.intp), img.shape[0])
    xs = fold(pos[:, 1].astype(np.intp), img.shape[1])
    out: NDArray[Pixel] = np.ascontiguousarray(img[ys[:, :, None], xs[:, None, :]])
    return out


def continuation_corners(
    positions: NDArray[np.integer], rows: NDArray[np.intp], cols: NDArray[np.intp], step: int
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]:
    """Where the continuations of each block's left, upper and upper-left neighbours start.

    The continuation of a neighbour over the block is the source just right of (below, or
    right of and below) the neighbour's own block: its recorded position shifted by one step.
    A block without that neighbour gets its own position (finite pixels, weight 0).

    Parameters
    ----------
    positions : ndarray of int, shape (rows, cols, 2)
        Source (y, x) of every block of the grid.
    rows, cols : ndarray of int, shape (n,)
        The blocks.
    step : int
        The grid's step.

    Returns
    -------
    left, top, diagonal : ndarray of intp, shape (n, 2)
        Source corners, possibly past the source's edges (read by :func:`reflect_gather`).
    """
    pos = np.asarray(positions, dtype=np.intp)
    up, back = np.maximum(rows - 1, 0), np.maximum(cols - 1, 0)
    has_left, has_top = (cols > 0)[:, None], (rows > 0)[:, None]
    own = pos[rows, cols]
    left = np.where(has_left, pos[rows, back] + (0, step), own)
    top = np.where(has_top, pos[up, cols] + (step, 0), own)
    diagonal = np.where(has_left & has_top, pos[up, back] + (step, step), own)
    return left, top, diagonal


def covered_pixels(grid: Grid, rows: NDArray[np.intp], cols: NDArray[np.intp]) -> NDArray[np.bool_]:
    """Which footprint pixels of each block the blocks placed before it wrote, (n, B, B).

    The nonzero weights of each block's overlap mask (:meth:`Grid.covered`), for all blocks
    at once.
    """
    return grid.covered(rows, cols)


def fill_blocks(
    source: NDArray[np.float32],
    canvas: NDArray[np.float32],
    grid: Grid,
    positions: NDArray[np.integer],
    rows: NDArray[np.intp],
    cols: NDArray[np.intp],
    cut_cols: NDArray[np.integer],
    cut_rows: NDArray[np.integer],
    feather: int,
) -> NDArray[np.float32]:
    """What a group of walk-mode blocks writes over its whole footprint.

    The new block where its cuts give it the pixel, blended over ``feather`` pixels with the
    old side: the output already there where a block was written before, else the
    continuations of the left, upper and upper-left neighbours (the paper's four-block corner).

    Parameters
    ----------
    source : ndarray of float32, shape (h, w, C)
    canvas : ndarray of float32, shape (H, W, C)
        The output so far.
    grid : Grid
        A plane grid.
    positions : ndarray of int, shape (rows, cols, 2)
        Source (y, x) of every block; those of the group and of its neighbours are read.
    rows, cols : ndarray of int, shape (n,)
        The group (one wavefront level).
    cut_cols, cut_rows : ndarray of int, shape (n, B)
        The group's walk cuts toward the left and top edges.
    feather : int

    Returns
    -------
    ndarray of float32, shape (n, B, B, C)
    """
    block = grid.block
    own = np.asarray(positions, dtype=np.intp)[rows, cols]
    left, top, diagonal = continuation_corners(positions, rows, cols, grid.step)
    has_left, has_top = cols > 0, rows > 0
    covered = covered_pixels(grid, rows, cols)
    return walk_compose(
        gather(canvas, grid.origins(rows, cols), block),
        covered,
        gather(source, own, block),
        reflect_gather(source, left, block) if has_left.any() else None,
        reflect_gather(source, top, block) if has_top.any() else None,
        reflect_gather(source, diagonal, block) if (has_left & has_top).any() else None,
        cut_cols,
        cut_rows,
        has_left,
        has_top,
        min(feather, block),
    )


def regions(
    grid: Grid,
    rows: NDArray[np.intp],
    cols: NDArray[np.intp],
    cut_cols: NDArray[np.integer],
    cut_rows: NDArray[np.integer],
) -> NDArray[np.int8]:
    """Which block each footprint pixel of a group mostly shows, for ownership statistics.

    Returns
    -------
    ndarray of int8, shape (n, B, B)
        0: the new block; 1, 2, 3: the continuation of the left, upper, upper-left
        neighbour; -1: the output already there (old side over a written pixel).
    """
    by_row, by_col = np.asarray(cut_cols), np.asarray(cut_rows)
    # In the cuts' own dtype (int16 in layouts, at least that): comparisons at a quarter of
    # intp's bytes.
    idx = np.arange(grid.block).astype(np.result_type(by_row, by_col, np.int16))
    # The old side of each cut; a block of the first column (row) has none: a cut of 0.
    by_row = np.where((np.asarray(cols) != 0)[:, None], by_row, 0).astype(idx.dtype)
    by_col = np.where((np.asarray(rows) != 0)[:, None], by_col, 0).astype(idx.dtype)
    old_x = idx[None, None, :] < by_row[:, :, None]
    old_y = idx[None, :, None] < by_col[:, None, :]
    label = old_x.view(np.int8) | (old_y.view(np.int8) << 1)
    np.copyto(label, np.int8(-1), where=covered_pixels(grid, rows, cols) & (old_x | old_y))
    return label
