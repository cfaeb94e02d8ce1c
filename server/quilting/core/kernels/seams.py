"""Compiled seam kernels: the minimum-error boundary cut, block by block.

:func:`surface_cuts` is the dynamic programme behind :func:`quilting.core.seams.
minimum_error_cuts` and :func:`~quilting.core.seams.strip_cuts`: per error surface, the
cost-to-go of each strip, the meeting point of an L-shaped cut, the trace and the sum of the
error along the path. :func:`candidate_seam_costs` is the same cut's cost for many candidate
blocks against one template, for factored sampling (the alpha quilting paper, §2.1.3): it
computes the error on the strips only, straight from the source, instead of gathering whole
blocks.

The arithmetic is the numpy code's that these kernels replaced, operation for operation, so
outputs kept their bytes (``tests/golden_cases.py``): the channel sum of the squared
difference in float32 (three channels in sequence, four in pairs, as numpy's ``einsum`` adds
them), the DP's ``min(min(lower, straight), higher)``, the trace's tie rule (module
docstring of :mod:`quilting.core.seams`), the path sum in stage order, and the edge cost's
mean summed in row-major order. (The numpy code summed that mean pairwise when a batch held
a single block and in sequence otherwise, so its cuts could depend on the batch; here they
never do.) Every function works on one surface at a time, so a block's cut is the same
whatever else is cut with it.

References
----------
Efros, A. A. and Freeman, W. T. "Image Quilting for Texture Synthesis and Transfer",
SIGGRAPH 2001, §2.1 (the minimum-error boundary cut).
"""

from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np
from numpy.typing import NDArray

_INF = np.inf


@nb.njit(cache=True)
def _row_errors(
    source_row: NDArray[np.float32],
    template_row: NDArray[np.float32],
    sx: int,
    start: int,
    stop: int,
    out: NDArray[np.float64],
) -> None:
    """``out[x]`` for x in [start, stop): the squared difference of template pixel x and source
    pixel sx + x of one row, summed over channels in float32 the way numpy's einsum sums them
    (in sequence; four channels in pairs)."""
    channels = template_row.shape[1]
    if channels == 4:
        for x in range(start, stop):
            d0 = template_row[x, 0] - source_row[sx + x, 0]
            d1 = template_row[x, 1] - source_row[sx + x, 1]
            d2 = template_row[x, 2] - source_row[sx + x, 2]
            d3 = template_row[x, 3] - source_row[sx + x, 3]
            out[x] = (d0 * d0 + d1 * d1) + (d2 * d2 + d3 * d3)
        return
    for x in range(start, stop):
        d = template_row[x, 0] - source_row[sx + x, 0]
        total = d * d
        for c in range(1, channels):
            d = template_row[x, c] - source_row[sx + x, c]
            total = total + d * d
        out[x] = total


@nb.njit(cache=True)
def _context_surface(
    err: NDArray[np.float64],
    left: bool,
    top: bool,
    ov: int,
    radius: int,
    weight: float,
    guide: NDArray[np.float64],
    sums: NDArray[np.float64],
    counts: NDArray[np.float64],
) -> None:
    """``guide[y, x] = (err[y, x] + weight * m[y, x]) / (1 + weight)`` on the strips, m the mean
    of ``err`` over the strips' pixels within ``radius`` (a (2r + 1)² window clipped to the
    union of the strips), by summed-area tables of ``err`` and of the union in ``sums`` and
    ``counts``."""
    height, width = err.shape
    # The tables need the union and the windows reaching out of it, no further.
    rows = height if left else min(height, ov + radius)
    cols = width if top else min(width, ov + radius)
    for x in range(cols + 1):
        sums[0, x] = 0.0
        counts[0, x] = 0.0
    for y in range(rows):
        span = cols if top and y < ov else min(ov, cols) if left else 0
        sums[y + 1, 0] = 0.0
        counts[y + 1, 0] = 0.0
        row_sum = 0.0
        row_count = 0.0
        for x in range(cols):
            if x < span:
                row_sum += err[y, x]
                row_count += 1.0
            sums[y + 1, x + 1] = sums[y, x + 1] + row_sum
            counts[y + 1, x + 1] = counts[y, x + 1] + row_count
    for y in range(rows):
        span = cols if top and y < ov else min(ov, cols) if left else 0
        y0 = max(0, y - radius)
        y1 = min(rows, y + radius + 1)
        for x in range(span):
            x0 = max(0, x - radius)
            x1 = min(cols, x + radius + 1)
            total = sums[y1, x1] - sums[y0, x1] - sums[y1, x0] + sums[y0, x0]
            count = counts[y1, x1] - counts[y0, x1] - counts[y1, x0] + counts[y0, x0]
            guide[y, x] = (err[y, x] + weight * (total / count)) / (1.0 + weight)


@nb.njit(cache=True)
def _cut(
    err: NDArray[np.float64],
    left: bool,
    top: bool,
    overlap: int,
    edge_cost: float,
    context: float,
    radius: int,
    dp_v: NDArray[np.float64],
    dp_h: NDArray[np.float64],
    path_v: NDArray[np.int16],
    path_h: NDArray[np.int16],
    guide: NDArray[np.float64],
    sums: NDArray[np.float64],
    counts: NDArray[np.float64],
) -> float:
    """The cut :func:`quilting.core.seams.minimum_error_cuts` makes through one surface.

    Parameters
    ----------
    err : ndarray, shape (H, W)
        The error; only the strips are read (a view, possibly mirrored). H = W for an
        L-shaped cut; a left strip alone may be any H x W with W >= O.
    left, top, overlap, edge_cost, context
        As ``minimum_error_cuts`` takes them; ``radius`` is the context's
        (:data:`quilting.core.seams.CONTEXT_RADIUS`).
    dp_v, dp_h : ndarray, shape (>= H, >= O + 2), (>= W, >= O + 2)
        Work arrays of the two DPs.
    guide, sums, counts : ndarray, shape (>= H, >= W), (>= H + 1, >= W + 1) twice
        Work arrays of the context (unused when it is 0).
    path_v, path_h : ndarray of int16, shape (H,), (W,)
        Filled with the vertical cut's column at each row and the horizontal cut's row at
        each column (the strips present).

    Returns
    -------
    float
        The cut's cost: ``err`` summed along the paths in stage order, the meeting point once.
    """
    height, width = err.shape
    ov = overlap
    # The edge cost: the mean of err over the union of the strips, summed in row-major
    # order one value after the other.
    scale = 0.0
    guided = edge_cost != 0.0 and ov > 2
    if guided:
        count = 0
        total = 0.0
        for y in range(height):
            row = width if top and y < ov else ov if left else 0
            for x in range(row):
                total += err[y, x]
            count += row
        scale = total / count * edge_cost

    # The paths see the context's surface; the cost is still summed from err.
    if context != 0.0:
        _context_surface(err, left, top, ov, radius, context, guide, sums, counts)
        return _route(
            guide[:height, :width], err, left, top, ov, guided, scale, dp_v, dp_h, path_v, path_h
        )
    return _route(err, err, left, top, ov, guided, scale, dp_v, dp_h, path_v, path_h)


@nb.njit(cache=True)
def _route(
    seen: NDArray[np.float64],
    err: NDArray[np.float64],
    left: bool,
    top: bool,
    ov: int,
    guided: bool,
    scale: float,
    dp_v: NDArray[np.float64],
    dp_h: NDArray[np.float64],
    path_v: NDArray[np.int16],
    path_h: NDArray[np.int16],
) -> float:
    """The DPs over the surface the paths see (``seen``: the error, or the context's surface),
    the start points, the traces into ``path_v``/``path_h``; returns ``err`` summed along them."""
    height, width = err.shape
    if left:
        _cost_to_go(seen, dp_v, height, True, ov, guided and top, guided, scale)
    if top:
        _cost_to_go(seen, dp_h, width, False, ov, guided and left, guided, scale)

    # Start points.
    v_stage = 0
    v_pos = 0
    h_stage = 0
    h_pos = 0
    if left and top:
        lowest = _INF
        for y in range(ov):
            for x in range(ov):
                g = seen[y, x]
                if guided and (x == 0 or x == ov - 1 or y == 0 or y == ov - 1):
                    g = g + scale
                total = dp_v[y, x + 1] + dp_h[x, y + 1] - g
                if total < lowest:
                    lowest = total
                    v_stage = y
                    v_pos = x
        h_stage = v_pos
        h_pos = v_stage
    else:
        dp = dp_v if left else dp_h
        lowest = _INF
        for w in range(ov):
            if dp[0, w + 1] < lowest:
                lowest = dp[0, w + 1]
                v_pos = w
        h_pos = v_pos

    cost = 0.0
    if left:
        cost = _trace(err, dp_v, height, v_stage, v_pos, True, left and top, 0, path_v)
    if top:
        summed = _trace(err, dp_h, width, h_stage, h_pos, False, left and top, 1, path_h)
        cost = cost + summed if left else summed
    return cost


@nb.njit(cache=True)
def _cost_to_go(
    err: NDArray[np.float64],
    dp: NDArray[np.float64],
    stages: int,
    vertical: bool,
    ov: int,
    cross_edges: bool,
    guided: bool,
    scale: float,
) -> None:
    """The DP of one strip into ``dp[:stages, :O + 2]``: stage t, position w is
    ``err[t, w]`` (vertical) or ``err[w, t]``, plus ``scale`` on the strip's first and last
    positions and, with ``cross_edges``, on the other strip's edge lines (stages 0 and
    O - 1); positions 0 and O + 1 are the +inf padding."""
    for t in range(stages):
        dp[t, 0] = _INF
        dp[t, ov + 1] = _INF
    for t in range(stages - 1, -1, -1):
        edge_stage = guided and cross_edges and (t == 0 or t == ov - 1)
        for w in range(ov):
            g = err[t, w] if vertical else err[w, t]
            if edge_stage or (guided and (w == 0 or w == ov - 1)):
                g = g + scale
            if t < stages - 1:
                # np.minimum's order, on values that are never NaN (ties: the same value).
                a = dp[t + 1, w]
                b = dp[t + 1, w + 1]
                best = b if b < a else a
                c = dp[t + 1, w + 2]
                best = c if c < best else best
                g = g + best
            dp[t, w + 1] = g


@nb.njit(cache=True)
def _trace(
    err: NDArray[np.float64],
    dp: NDArray[np.float64],
    stages: int,
    start_stage: int,
    start_pos: int,
    vertical: bool,
    corner: bool,
    skip: int,
    path: NDArray[np.int16],
) -> float:
    """Follow ``dp`` downhill from the start point into ``path`` and sum ``err`` along it in
    stage order. Before its start stage a path stays at the start position (the corner fill
    rule of an L-shaped cut), and those stages (plus ``skip``) are fill, not summed. Ties:
    straight on if it is among the cheapest, else the lower position, else the higher."""
    first = start_stage + skip if corner else 0
    pos = start_pos
    total = 0.0
    for t in range(stages):
        if t > 0 and t > start_stage:
            lower = dp[t, pos]
            straight = dp[t, pos + 1]
            higher = dp[t, pos + 2]
            if straight > lower or straight > higher:
                pos += 1 if lower > higher else -1
        path[t] = pos
        if t >= first:
            total += err[t, pos] if vertical else err[pos, t]
    return total


@nb.njit(cache=True)
def _block_cuts(
    match: NDArray[np.float32],
    templates: NDArray[np.float32],
    template_of: NDArray[np.intp],
    corners: NDArray[np.intp],
    left: bool,
    top: bool,
    right: bool,
    bottom: bool,
    overlap: int,
    right_overlap: int,
    bottom_overlap: int,
    edge_cost: float,
    context: float,
    radius: int,
    cut_cols: NDArray[np.int16],
    cut_rows: NDArray[np.int16],
    cut_right: NDArray[np.int16],
    cut_bottom: NDArray[np.int16],
    costs: NDArray[np.float64],
) -> None:
    """Block k (source corner ``corners[k]``) against ``templates[template_of[k]]``: its cuts
    into row k of the four cut arrays and its cost (near cuts plus far cuts) into costs[k]."""
    size = templates.shape[1]
    count = corners.shape[0]
    err = np.zeros((size, size), dtype=np.float64)
    widest = max(overlap, right_overlap, bottom_overlap)
    dp_v = np.empty((size, widest + 2), dtype=np.float64)
    dp_h = np.empty((size, widest + 2), dtype=np.float64)
    path = np.empty(size, dtype=np.int16)
    guide = np.empty((size, size), dtype=np.float64)
    sums = np.empty((size + 1, size + 1), dtype=np.float64)
    counts = np.empty((size + 1, size + 1), dtype=np.float64)
    for k in range(count):
        sy = corners[k, 0]
        sx = corners[k, 1]
        template = templates[template_of[k]]
        # Only the strips: rows of the top and bottom strips whole, the side strips' columns
        # on the other rows (a pixel in two strips is computed twice, to the same value).
        for y in range(size):
            source_row = match[sy + y]
            template_row = template[y]
            if (top and y < overlap) or (bottom and y >= size - bottom_overlap):
                _row_errors(source_row, template_row, sx, 0, size, err[y])
                continue
            if left:
                _row_errors(source_row, template_row, sx, 0, overlap, err[y])
            if right:
                _row_errors(source_row, template_row, sx, size - right_overlap, size, err[y])
        cost = 0.0
        if left or top:
            cost = _cut(
                err, left, top, overlap, edge_cost, context, radius, dp_v, dp_h,
                cut_cols[k], cut_rows[k], guide, sums, counts,
            )  # fmt: skip
        if right or bottom:
            # The far strips mirrored into near ones; the mirrored path p is size - p.
            far = 0.0
            if right:
                far += _cut(
                    err[:, ::-1], True, False, right_overlap, edge_cost, context, radius,
                    dp_v, dp_h, path, path, guide, sums, counts,
                )  # fmt: skip
                for y in range(size):
                    cut_right[k, y] = size - path[y]
            if bottom:
                far += _cut(
                    err[::-1, :], False, True, bottom_overlap, edge_cost, context, radius,
                    dp_v, dp_h, path, path, guide, sums, counts,
                )  # fmt: skip
                for x in range(size):
                    cut_bottom[k, x] = size - path[x]
            cost = cost + far
        costs[k] = cost


def block_cuts(
    match: NDArray[np.float32],
    templates: NDArray[np.float32],
    corners: NDArray[np.intp],
    *,
    left: bool,
    top: bool,
    right: bool = False,
    bottom: bool = False,
    overlap: int,
    wrap_overlap: tuple[int, int] = (0, 0),
    edge_cost: float = 0.0,
    context: float = 0.0,
    radius: int = 0,
) -> tuple[
    NDArray[np.int16], NDArray[np.int16], NDArray[np.int16], NDArray[np.int16], NDArray[np.float64]
]:
    """The minimum-error cuts of blocks of one overlap kind, their error taken on the strips
    straight from the source.

    Parameters
    ----------
    match : ndarray, shape (H, W, C), float32
        The source as the costs compare it.
    templates : ndarray, shape (n, B, B, C) or (1, B, B, C), float32
        What the output holds under each block, compared the same way (one template for
        every block: candidates of one block).
    corners : ndarray of int, shape (n, 2)
        (y, x) of each block's top-left corner in ``match``.
    left, top, right, bottom : bool
        The blocks' overlaps (right and bottom: across the wrap of a torus).
    overlap : int
        Width of the near strips.
    wrap_overlap : (int, int)
        Height of the bottom strip and width of the right strip.
    edge_cost, context : float
        As :func:`quilting.core.seams.minimum_error_cuts` takes them.
    radius : int
        The context's window radius (:data:`quilting.core.seams.CONTEXT_RADIUS`).

    Returns
    -------
    cut_cols, cut_rows : ndarray of int16, shape (n, B)
        The near cuts, as :func:`quilting.core.seams.minimum_error_cuts` gives them.
    cut_right, cut_bottom : ndarray of int16, shape (n, B)
        The far cuts, as :func:`quilting.core.seams.far_side_cuts` gives them (B: none).
    cost : ndarray of float64, shape (n,)
        Near plus far cost of each block.
    """
    count, size = corners.shape[0], templates.shape[1]
    # Block k against templates[template_of[k]]: each its own here; every candidate against
    # the one template in candidate_seam_costs.
    if templates.shape[0] == count:
        template_of = np.arange(count, dtype=np.intp)
    elif templates.shape[0] == 1:
        template_of = np.zeros(count, dtype=np.intp)
    else:
        raise ValueError(f"{templates.shape[0]} templates for {count} blocks (1 or n)")
    cut_cols = np.zeros((count, size), dtype=np.int16)
    cut_rows = np.zeros((count, size), dtype=np.int16)
    cut_right = np.full((count, size), size, dtype=np.int16)
    cut_bottom = np.full((count, size), size, dtype=np.int16)
    costs = np.zeros(count, dtype=np.float64)
    _block_cuts(
        np.ascontiguousarray(match, dtype=np.float32),
        np.ascontiguousarray(templates, dtype=np.float32),
        template_of,
        np.ascontiguousarray(corners, dtype=np.intp),
        bool(left),
        bool(top),
        bool(right),
        bool(bottom),
        int(overlap),
        int(wrap_overlap[1]),
        int(wrap_overlap[0]),
        float(edge_cost),
        float(context),
        int(radius),
        cut_cols,
        cut_rows,
        cut_right,
        cut_bottom,
        costs,
    )
    return cut_cols, cut_rows, cut_right, cut_bottom, costs


def candidate_seam_costs(
    match: NDArray[np.float32],
    template: NDArray[np.float32],
    corners: NDArray[np.intp],
    **cut: Any,
) -> NDArray[np.float64]:
    """The minimum-error seam cost of each candidate block against one template.

    Parameters
    ----------
    match : ndarray, shape (H, W, C), float32
        The source as the costs compare it.
    template : ndarray, shape (B, B, C), float32
        What the output holds under the block, compared the same way.
    corners : ndarray of int, shape (m, 2)
        (y, x) of each candidate's top-left corner in ``match``.
    **cut
        The block's overlaps and how it is cut (``left``, ``top``, ``right``, ``bottom``,
        ``overlap``, ``wrap_overlap``, ``edge_cost``, ``context``, ``radius``), as
        :func:`block_cuts` takes them.

    Returns
    -------
    ndarray of float64, shape (m,)
        What ``minimum_error_cuts`` (plus ``far_side_cuts``) returns as the cost of the
        candidate's cuts, bit for bit.
    """
    return block_cuts(match, np.asarray(template)[None], corners, **cut)[4]


@nb.njit(cache=True)
def _surface_cuts(
    err: NDArray[np.float64],
    left: bool,
    top: bool,
    overlap: int,
    edge_cost: float,
    context: float,
    radius: int,
    cut_cols: NDArray[np.int16],
    cut_rows: NDArray[np.int16],
    cost: NDArray[np.float64],
) -> None:
    count, height, width = err.shape
    dp_v = np.empty((height, overlap + 2), dtype=np.float64)
    dp_h = np.empty((width, overlap + 2), dtype=np.float64)
    guide = np.empty((height, width), dtype=np.float64)
    sums = np.empty((height + 1, width + 1), dtype=np.float64)
    counts = np.empty((height + 1, width + 1), dtype=np.float64)
    for k in range(count):
        cost[k] = _cut(
            err[k], left, top, overlap, edge_cost, context, radius, dp_v, dp_h,
            cut_cols[k], cut_rows[k], guide, sums, counts,
        )  # fmt: skip


def surface_cuts(
    err: NDArray[np.float64],
    *,
    left: bool,
    top: bool,
    overlap: int,
    edge_cost: float = 0.0,
    context: float = 0.0,
    radius: int = 0,
) -> tuple[NDArray[np.int16], NDArray[np.int16], NDArray[np.float64]]:
    """The minimum-error cuts of a batch of error surfaces.

    Parameters
    ----------
    err : ndarray, shape (n, H, W), float64
        Error surfaces (H = W for an L-shaped cut; only the strips are read).
    left, top : bool
        The strips to cut through (at least one).
    overlap : int
        Their width O, ``1 <= O <= min(H, W)``.
    edge_cost, context : float
        See :func:`quilting.core.seams.minimum_error_cuts`.
    radius : int
        The context's window radius.

    Returns
    -------
    cut_cols : ndarray of int16, shape (n, H)
        The vertical cut's column at each row (0 without ``left``).
    cut_rows : ndarray of int16, shape (n, W)
        The horizontal cut's row at each column (0 without ``top``).
    cost : ndarray of float64, shape (n,)
    """
    count, height, width = err.shape
    cut_cols = np.zeros((count, height), dtype=np.int16)
    cut_rows = np.zeros((count, width), dtype=np.int16)
    cost = np.zeros(count, dtype=np.float64)
    _surface_cuts(
        np.ascontiguousarray(err, dtype=np.float64),
        bool(left),
        bool(top),
        int(overlap),
        float(edge_cost),
        float(context),
        int(radius),
        cut_cols,
        cut_rows,
        cost,
    )
    return cut_cols, cut_rows, cost
