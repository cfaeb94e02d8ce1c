"""Diagnostics of a result: seam error, repetition of the source, and the seam overlay.

Repetition is measured on the final block ownership: every output pixel comes from one source
pixel at a translation fixed per block. Touching blocks with the same translation are one
verbatim copy of the source; the largest such connected region, as a share of the texture's
area, says how much of the source the output reproduces in one piece.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from quilting.core.grid import Grid
from quilting.core.layout import Blocks, Index, Layout, LayoutPass


@dataclass(frozen=True)
class SynthesisStats:
    """Quality figures of one result.

    Attributes
    ----------
    seam_error_total : float
        Sum over every seam pixel of the squared difference (summed over channels, values in
        [0, 1]) between the two blocks that meet there.
    seam_error_mean : float
        ``seam_error_total`` per seam pixel.
    seam_pixels : int
        Number of seam pixels.
    largest_copy : float
        Largest connected region of the output copied verbatim from one place in the source,
        as a share of the texture's area (1.0: the output contains a whole copy of the texture).
    unused : float
        Share of the texture's pixels that appear nowhere in the output.
    correspondence_error : float or None
        Texture transfer only: mean over the output's pixels of the squared difference
        between the correspondence map the output carries (the texture's map quilted with the
        result's layout) and the target's, per map channel. None for synthesis.

    For a multi-pass transfer the seam figures are those of the last pass, the one seen.
    """

    seam_error_total: float
    seam_error_mean: float
    seam_pixels: int
    largest_copy: float
    unused: float
    correspondence_error: float | None = None


@dataclass(frozen=True)
class Ownership:
    """Which block each output pixel finally comes from.

    Attributes
    ----------
    owner : ndarray of uint16 or int32, shape (out_h, out_w)
        Global block index (passes concatenated, row-major within a pass): uint16 while the
        indices fit (up to 65,534 blocks; 8192² from block 48 has 42,025), else int32. Rows
        are contiguous; the map may be a view of a slightly larger canvas.
    offsets : ndarray of int64, shape (blocks, 2)
        Source position minus output position of each block's pixels.
    corners : ndarray of int64, shape (blocks, 2)
        Output position of each block's top-left corner.
    sizes : ndarray of int64, shape (blocks,)
        Side of each block.
    """

    owner: NDArray[np.integer[Any]]
    offsets: NDArray[np.int64]
    corners: NDArray[np.int64]
    sizes: NDArray[np.int64]


@dataclass(frozen=True)
class _Blocks:
    """Every block of a layout, passes concatenated (row-major within a pass).

    Attributes
    ----------
    first : ndarray of int64, shape (passes + 1,)
        Global index of each pass's block (0, 0), and the block count last.
    offsets, corners, sizes
        As in :class:`Ownership`.
    periods : ndarray of int64, shape (blocks, 2)
        Each block's torus period (0: that axis does not wrap).
    dtype : numpy dtype
        Of the ownership map: uint16 while the indices fit (up to 65,534 blocks; 8192² from
        block 48 has 42,025), else int32.
    """

    first: NDArray[np.int64]
    offsets: NDArray[np.int64]
    corners: NDArray[np.int64]
    sizes: NDArray[np.int64]
    periods: NDArray[np.int64]
    dtype: np.dtype[Any]

    @classmethod
    def of(cls, layout: Layout) -> _Blocks:
        counts = [p.grid.rows * p.grid.cols for p in layout.passes]
        first = np.cumsum([0, *counts])
        corners, offsets, sizes, periods = [], [], [], []
        for p, count in zip(layout.passes, counts, strict=True):
            rows, cols = np.divmod(np.arange(count), p.grid.cols)
            origin = p.grid.origins(rows, cols).astype(np.int64)
            corners.append(origin)
            offsets.append(p.positions.reshape(-1, 2).astype(np.int64) - origin)
            sizes.append(np.full(count, p.grid.block, dtype=np.int64))
            periods.append(np.tile(np.asarray(p.grid.period, dtype=np.int64), (count, 1)))
        # The map is the stage's largest array: 2 bytes a pixel where the block count allows.
        dtype = np.dtype(np.uint16 if first[-1] < np.iinfo(np.uint16).max else np.int32)
        return cls(
            first=first,
            offsets=np.concatenate(offsets),
            corners=np.concatenate(corners),
            sizes=np.concatenate(sizes),
            periods=np.concatenate(periods),
            dtype=dtype,
        )

    @property
    def count(self) -> int:
        return int(self.first[-1])


def ownership(layout: Layout) -> Ownership:
    """Render block indices with the layout's seams (see :class:`Ownership`).

    A plain last pass (see :func:`_plain_cover`: no torus, no walk fill, cuts inside the
    overlap) is rendered cell by cell of its grid (:func:`_plain_rows`), five to seven times
    faster than pasting its blocks one by one (42,025 at 8192²); a torus or walk pass cell by
    cell of its grid unrolled into a plane (:func:`_cell_pass`), three to six times faster;
    any other is pasted through :meth:`Layout.compose`. All give the same map (tested).
    """
    blocks = _Blocks.of(layout)
    last = layout.passes[-1]
    height, width = layout.output_shape
    if _plain_cover(last):
        g = last.grid
        big = np.empty(((g.rows + 1) * g.step, (g.cols + 1) * g.step), dtype=blocks.dtype)
        view = big.reshape(g.rows + 1, g.step, g.cols + 1, g.step)
        chunk = _chunk_rows(g)
        for lo in range(0, g.rows + 1, chunk):
            hi = min(lo + chunk, g.rows + 1)
            _plain_rows(last, int(blocks.first[-2]), view[lo:hi], lo, hi)
        owner = big[g.step - g.overlap :, g.step - g.overlap :][:height, :width]
    else:
        owner = _general(layout.passes, layout.output_shape, blocks)
    return Ownership(
        owner=owner, offsets=blocks.offsets, corners=blocks.corners, sizes=blocks.sizes
    )


def _pasted(layout: Layout, blocks: _Blocks) -> NDArray[np.integer[Any]]:
    """The ownership map pasted block by block through :meth:`Layout.compose`, a view of its
    canvas (rows contiguous)."""
    fill = _fill(blocks.dtype)

    def ids(index: int, p: LayoutPass, rows: Index, cols: Index) -> Blocks:
        block_ids: Blocks = (blocks.first[index] + rows * p.grid.cols + cols).astype(blocks.dtype)
        return block_ids[:, None, None, None]

    owner: NDArray[np.integer[Any]] = layout.compose(
        1, blocks.dtype, ids, fill=fill, contiguous=False
    )[..., 0]
    return owner


def _general(
    passes: list[LayoutPass], shape: tuple[int, int], blocks: _Blocks
) -> NDArray[np.integer[Any]]:
    """The ownership map of layouts :func:`_plain_cover` does not take, output-sized (a view,
    rows contiguous).

    A last pass that :func:`_cell_cover` accepts is rendered by :func:`_cell_pass`, the passes
    before it only if some pixel is left to them; any other layout is pasted through
    :meth:`Layout.compose` (:func:`_pasted`).
    """
    last = passes[-1]
    if not _cell_cover(last):
        return _pasted(Layout((0, 0), shape, passes), blocks)
    fill = _fill(blocks.dtype)
    owner = _cell_pass(last, int(blocks.first[len(passes) - 1]), blocks.dtype)
    owner = owner[: shape[0], : shape[1]]
    if len(passes) == 1:
        return owner
    hole = owner == fill
    if hole.any():
        # Layout.compose pastes a pass over the map of the passes before it, where that map
        # reaches (the fill beyond).
        found = _general(passes[:-1], shape, blocks)
        below = np.full(owner.shape, fill, dtype=blocks.dtype)
        h, w = min(found.shape[0], owner.shape[0]), min(found.shape[1], owner.shape[1])
        below[:h, :w] = found[:h, :w]
        owner = np.where(hole, below, owner)
    return owner


def _fill(dtype: np.dtype[Any]) -> int:
    """The map's value where no block is: above every index."""
    return int(np.iinfo(dtype).max) if dtype == np.uint16 else -1


def _cell_cover(p: LayoutPass) -> bool:
    """Whether :func:`_cell_pass` renders this pass exactly.

    It does when every pixel of the pass's grid, with a torus unrolled into a plane, lies in at
    most two blocks' footprints along each axis (overlap <= block / 2), a block's footprint
    wraps onto itself nowhere (a wrapped axis at least a block long), and a walk pass lies on
    a plane (as the engine and :meth:`LayoutPass.from_json` make them). Every tileable and walk
    synthesis is.
    """
    g = p.grid
    return (
        2 * g.overlap <= g.block
        and all(period >= g.block for period in g.period if period)
        and (p.feather is None or not g.wrapped)
    )


def _cell_pass(p: LayoutPass, first: int, dtype: np.dtype[Any]) -> NDArray[np.integer[Any]]:
    """One pass's ownership map, cell by cell of its grid unrolled into a plane.

    Parameters
    ----------
    p : LayoutPass
        A pass that :func:`_cell_cover` accepts, with block B, overlap O, step s = B - O, R
        rows and C columns.
    first : int
        Global index of its block (0, 0).
    dtype : numpy dtype
        Of the map (see :class:`_Blocks`).

    Returns
    -------
    ndarray of dtype, shape (grid height, grid width)
        A view (rows contiguous): the index of the block each pixel shows, :func:`_fill`
        where the pass writes nothing.

    Notes
    -----
    Unrolled, block (i, j) covers the plane's pixels [i s, i s + B) x [j s, j s + B), which
    run past a wrapped axis's period P by its wrap overlap w <= s. Blocks that share a pixel
    of that plane are neighbours, placed in row-major order (levels 2 i + j), so
    it is drawn as the last of them that writes the pixel. A pixel of the
    torus at x < w is plane pixels x and P + x: it shows the one of their two owners placed
    later (:meth:`Grid.groups`), which is the last writer of all the blocks over it.

    The plane is drawn as in :func:`_plain_rows`, on a 4-d view of cells. Cell (I, a, J, b)
    lies in block (I - 1, J - 1) at (O + a, O + b), in its interior; for b >= s - O also in
    (I - 1, J) at (O + a, b - (s - O)), that block's left strip; for a >= s - O in (I, J - 1)
    at (a - (s - O), O + b), its top strip; for both in (I, J), at the top strip's first O
    columns. Placed in that order, the last that writes the pixel owns it. A block writes its
    whole interior bar the few pixels its cuts reach (:func:`_interior_exceptions`): a
    broadcast of the indices, then those pixels; the strips are evaluated pixel by pixel
    (:func:`_written`) and copied over where they write (:func:`_strips`).
    """
    g = p.grid
    s, n = g.step, g.step - g.overlap
    fill = _fill(dtype)
    big = np.empty(((g.rows + 1) * s, (g.cols + 1) * s), dtype=dtype)
    view = big.reshape(g.rows + 1, s, g.cols + 1, s)
    cuts = _Cuts.of(p, first, dtype)
    # Interiors: cell (I, J) shows block (I - 1, J - 1)'s, bar the pixels its cuts reach.
    ids = np.full((g.rows + 1, g.cols + 1), fill, dtype=dtype)
    ids[1:, 1:] = cuts.ids.reshape(g.rows, g.cols)
    view[...] = ids[:, None, :, None]
    chunk = _chunk_rows(g)
    for lo in range(0, g.rows, chunk):
        _strips(p, cuts, view, range(lo, min(lo + chunk, g.rows)), fill)
    plane = big[n:, n:]  # (R s + O, C s + O): the grid's canvas, or its torus unrolled
    if not g.wrapped:
        return plane
    # The order each block is placed in; the fill (no writer) before all.
    order = np.append(g.placed.reshape(-1), -1)

    def rank(ids: NDArray[np.integer[Any]]) -> NDArray[np.intp]:
        local = ids.astype(np.int64) - first
        local[ids == fill] = -1
        ranks: NDArray[np.intp] = order[local]
        return ranks

    wrap_y, wrap_x = g.wrap_overlap
    if g.period[1]:
        near, far = plane[:, :wrap_x], plane[:, g.period[1] : g.period[1] + wrap_x]
        later = rank(far) > rank(near)
        near[later] = far[later]
        plane = plane[:, : g.period[1]]
    if g.period[0]:
        near, far = plane[:wrap_y], plane[g.period[0] : g.period[0] + wrap_y]
        later = rank(far) > rank(near)
        near[later] = far[later]
        plane = plane[: g.period[0]]
    return plane


def _strips(
    p: LayoutPass, cuts: _Cuts, view: NDArray[np.integer[Any]], rows: range, fill: int
) -> None:
    """Write what some block rows of a pass change over the interiors' indices in the cells
    (see :func:`_cell_pass`): their interiors' exceptions, their left strips, their top strips.

    Parameters
    ----------
    p : LayoutPass
        A pass that :func:`_cell_cover` accepts (B, O, s, R, C as there).
    cuts : _Cuts
        Of every block of the pass.
    view : ndarray of uint16 or int32, shape (R + 1, s, C + 1, s), updated
        The cells: ``view[I, a, J, b]`` is plane pixel ``(I s + a - (s - O), J s + b - (s - O))``.
    rows : range
        The block rows, in order over calls: cell row I holds block row I - 1's interior and
        left strips and block row I's top strips, so these come after the rows before them.
    fill : int
        Where no block writes.
    """
    g = p.grid
    B, overlap = g.block, g.overlap
    n, C = g.step - overlap, g.cols
    part = cuts.rows_of(rows, C)
    # Interiors: block (i, j)'s in cell (i + 1, j + 1).
    k, y, x, value = _interior_exceptions(p, part, fill)
    view[k // C + rows.start + 1, y - overlap, k % C + 1, x - overlap] = value
    # Left strips: block (i, j) over the columns b >= s - O of cell (i + 1, j).
    value, writes = _window(p, part, slice(overlap, B), slice(0, overlap))
    np.copyto(
        view[rows.start + 1 : rows.stop + 1, :, :C, n:],
        _cell_order(value, len(rows), C),
        where=_cell_order(writes, len(rows), C),
    )
    # Top strips: block (i, j) over the rows a >= s - O of cell (i, j + 1), then over their
    # columns b >= s - O of cell (i, j).
    value, writes = _window(p, part, slice(0, overlap), slice(0, B))
    value, writes = (
        _cell_order(a, len(rows), C) for a in (np.broadcast_to(value, writes.shape), writes)
    )
    cells = slice(rows.start, rows.stop)
    for xs, target in (
        (slice(overlap, B), view[cells, n:, 1:, :]),
        (slice(0, overlap), view[cells, n:, :C, n:]),
    ):
        np.copyto(target, value[..., xs], where=writes[..., xs])


def _cell_order(a: NDArray[Any], rows: int, cols: int) -> NDArray[Any]:
    """Per-block windows (rows * cols, y, x), or broadcastable ones, in the order of a view
    of cells: (rows, y, cols, x)."""
    return a.reshape(rows, cols, *a.shape[1:]).transpose(0, 2, 1, 3)


def _ids(first: int, rows: range, cols: int, dtype: np.dtype[Any]) -> NDArray[np.integer[Any]]:
    """Global index of every block of some rows of a pass, row-major."""
    return (first + np.arange(rows.start * cols, rows.stop * cols)).astype(dtype)


class _Cuts(NamedTuple):
    """What decides the pixels some blocks of a pass write (all rows of the grid).

    Attributes
    ----------
    ids : ndarray, shape (m,)
        The blocks' global indices, in the map's dtype.
    cols, rows, right, bottom : ndarray of int16, shape (m, B)
        Each block's ``cut_cols``, ``cut_rows``, ``cut_right``, ``cut_bottom``; for a walk pass
        the first column's ``cut_cols`` and the first row's ``cut_rows`` are 0 (no old side).
    lines, columns : ndarray of bool, shape (m, B)
        The rows and the columns of each footprint that blocks placed before it covered
        (:meth:`Grid.overlap_strips`).
    """

    ids: NDArray[np.integer[Any]]
    cols: NDArray[np.integer[Any]]
    rows: NDArray[np.integer[Any]]
    right: NDArray[np.integer[Any]]
    bottom: NDArray[np.integer[Any]]
    lines: NDArray[np.bool_]
    columns: NDArray[np.bool_]

    @classmethod
    def of(cls, p: LayoutPass, first: int, dtype: np.dtype[Any]) -> _Cuts:
        """Of every block of a pass, row-major."""
        g = p.grid
        i, j = np.divmod(np.arange(g.rows * g.cols), g.cols)
        columns, lines = g.overlap_strips(i, j)
        by_row, by_col = p.cut_cols.reshape(-1, g.block), p.cut_rows.reshape(-1, g.block)
        if p.feather is not None:
            by_row = np.where((j == 0)[:, None], 0, by_row).astype(by_row.dtype)
            by_col = np.where((i == 0)[:, None], 0, by_col).astype(by_col.dtype)
        return cls(
            ids=_ids(first, range(g.rows), g.cols, dtype),
            cols=by_row,
            rows=by_col,
            right=p.cut_right.reshape(-1, g.block),
            bottom=p.cut_bottom.reshape(-1, g.block),
            lines=lines[:, :, 0],
            columns=columns[:, 0],
        )

    def rows_of(self, rows: range, cols: int) -> _Cuts:
        """The blocks of some rows of a grid ``cols`` wide."""
        part = slice(rows.start * cols, rows.stop * cols)
        return _Cuts(
            ids=self.ids[part],
            cols=self.cols[part],
            rows=self.rows[part],
            right=self.right[part],
            bottom=self.bottom[part],
            lines=self.lines[part],
            columns=self.columns[part],
        )


def _written(
    p: LayoutPass,
    cuts: _Cuts,
    ids: NDArray[np.integer[Any]],
    y: NDArray[np.integer[Any]],
    x: NDArray[np.integer[Any]],
    at_row: Callable[[NDArray[Any]], NDArray[Any]],
    at_col: Callable[[NDArray[Any]], NDArray[Any]],
) -> tuple[NDArray[np.integer[Any]], NDArray[np.bool_]]:
    """What blocks write at pixels of their footprints, as :meth:`Layout.compose` pastes.

    Parameters
    ----------
    p : LayoutPass
    cuts : _Cuts
        Of the blocks.
    ids : ndarray
        Each pixel's block's global index.
    y, x : ndarray of int
        Each pixel's row and column in the footprint.
    at_row, at_col : callable
        ``at_row(a)`` is a per-row array ``a`` of ``cuts`` (m, B) at each pixel's block and
        row, ``at_col(a)`` a per-column one at its column; ids, y, x and these broadcast
        together.

    Returns
    -------
    value : ndarray of the ids' dtype
        The index written.
    writes : ndarray of bool
        Where the block writes at all; both broadcast to the pixels' shape.

    Notes
    -----
    A pasted block writes its own index where its seam mask holds the pixel
    (:func:`quilting.core.seams.new_block_mask`: x >= cut_cols[y], y >= cut_rows[x] and, on
    a torus, x < cut_right[y], y < cut_bottom[x]). A walk block writes its own index, or its
    left, upper or upper-left neighbour's where it shows that one's continuation (left of
    cut_cols[y], above cut_rows[x], both), and nothing where that side was covered before
    it (:func:`quilting.core.walk.regions`).
    """
    if p.feather is None:
        owned = x >= at_row(cuts.cols)
        owned &= y >= at_col(cuts.rows)
        if p.grid.wrapped:
            owned &= x < at_row(cuts.right)
            owned &= y < at_col(cuts.bottom)
        return ids, owned
    old_x = x < at_row(cuts.cols)
    old_y = y < at_col(cuts.rows)
    # Row-major indices: the left, upper and upper-left neighbours of block k are k - 1,
    # k - C and k - C - 1.
    value = ids - old_x
    value -= old_y * ids.dtype.type(p.grid.cols)
    keeps = (old_x | old_y) & (at_col(cuts.columns) | at_row(cuts.lines))
    return value, ~keeps


def _window(
    p: LayoutPass, cuts: _Cuts, ys: slice, xs: slice
) -> tuple[NDArray[np.integer[Any]], NDArray[np.bool_]]:
    """:func:`_written` on the window [ys, xs] of every footprint of ``cuts``: shape (m, rows,
    columns) or broadcastable to it, possibly a transposed view. The slices step by 1."""
    # In the cuts' own dtype (int16): comparisons at a quarter of intp's bytes.
    idx = np.arange(p.grid.block).astype(cuts.cols.dtype)
    ids = cuts.ids[:, None, None]
    if ys.stop - ys.start <= xs.stop - xs.start:
        return _written(
            p,
            cuts,
            ids,
            idx[ys][:, None],
            idx[xs][None, :],
            lambda a: a[:, ys, None],
            lambda a: a[:, None, xs],
        )
    # A tall window is evaluated column by column, its longer side innermost (four times
    # faster than rows of a few pixels), and handed back transposed.
    value, writes = _written(
        p,
        cuts,
        ids,
        idx[ys][None, :],
        idx[xs][:, None],
        lambda a: a[:, None, ys],
        lambda a: a[:, xs, None],
    )
    return value.transpose(0, 2, 1), writes.transpose(0, 2, 1)


def _interior_exceptions(
    p: LayoutPass, cuts: _Cuts, fill: int
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp], NDArray[np.integer[Any]]]:
    """The pixels of blocks' interiors (y, x >= O) where a block may not write its own index,
    and what it writes there (:func:`_written`).

    Only a cut decides that: inside the interior, the pixels of row y before ``cut_cols[y]``
    and from ``cut_right[y]`` on, of column x before ``cut_rows[x]`` and from
    ``cut_bottom[x]`` on. They are few (the engine's cuts stay in the overlap, bar the walk's
    strays and a torus's far side), so they are listed as spans and evaluated one by one.

    Parameters
    ----------
    p : LayoutPass
    cuts : _Cuts
        Of m blocks.
    fill : int
        Where a block writes nothing.

    Returns
    -------
    k, y, x : ndarray of intp, shape (e,)
        Each pixel as its block's position in ``cuts`` and its place in the footprint; a
        pixel may be listed more than once (with the same value).
    value : ndarray, shape (e,)
        What the block writes there.
    """
    B, overlap = p.grid.block, p.grid.overlap
    found = []
    for cut, before, along_row in (
        (cuts.cols, True, True),
        (cuts.rows, True, False),
        (cuts.right, False, True),
        (cuts.bottom, False, False),
    ):
        if not before and (p.feather is not None or not p.grid.wrapped):
            continue  # far cuts cut only a pasted torus
        bound = cut[:, overlap:].astype(np.intp)  # rows (columns) O.. of each block
        line = np.flatnonzero(bound > overlap if before else bound < B)
        bound = bound.reshape(-1)[line]
        start, stop = (overlap, np.minimum(bound, B)) if before else (np.maximum(bound, overlap), B)
        span, position = _spans(
            np.broadcast_to(start, line.shape), np.broadcast_to(stop, line.shape)
        )
        k, other = np.divmod(line[span], B - overlap)
        other += overlap
        found.append((k, other, position) if along_row else (k, position, other))
    k, y, x = (np.concatenate(parts) for parts in zip(*found, strict=True))
    value, writes = _written(p, cuts, cuts.ids[k], y, x, lambda a: a[k, y], lambda a: a[k, x])
    return k, y, x, np.where(writes, value, value.dtype.type(fill))


def _spans(starts: NDArray[np.intp], stops: NDArray[np.intp]) -> tuple[NDArray[np.intp], ...]:
    """Every integer of each span [start, stop): the span's position and the integer."""
    count = np.maximum(stops - starts, 0)
    span = np.repeat(np.arange(count.size), count)
    position = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    return span, position + starts[span]


def _plain_cover(p: LayoutPass) -> bool:
    """Whether :func:`_plain_rows` renders this pass exactly, alone.

    It does when every pixel of the pass's canvas lies in at most two blocks' footprints along
    each axis (overlap <= block / 2), the pass pastes (no walk fill) on a plane (no torus), its
    seams stay inside the overlap strips (cuts <= overlap) and the first row and column cut
    nothing, so that the pass owns every pixel and earlier passes show nowhere. The engine's
    passes in modes cut, overlap, random and alpha, and transfer's, are; tileable and walk
    layouts are not.
    """
    g = p.grid
    cuts = (p.cut_cols, p.cut_rows)
    return (
        p.feather is None
        and not g.wrapped
        and 2 * g.overlap <= g.block
        and all(int(c.min()) >= 0 and int(c.max()) <= g.overlap for c in cuts)
        and not p.cut_cols[:, 0].any()
        and not p.cut_rows[0].any()
    )


def _chunk_rows(g: Grid) -> int:
    """Block rows :func:`_plain_rows` renders at once: about four bands' worth of pixels."""
    return max(1, 4 * BAND_PIXELS // ((g.cols + 1) * g.step * g.step))


def _plain_rows(
    p: LayoutPass, first: int, view: NDArray[np.integer[Any]], lo: int, hi: int
) -> None:
    """Render rows of a plain pass's ownership map, cell by cell.

    Parameters
    ----------
    p : LayoutPass
        A pass that :func:`_plain_cover` accepts, with block B, overlap O, step s = B - O, R
        rows and C columns.
    first : int
        Global index of its block (0, 0).
    view : ndarray of uint16 or int32, shape (hi - lo, s, C + 1, s), written
        ``view[I - lo, a, J, b]`` is canvas pixel ``(I s + a - (s - O), J s + b - (s - O))``:
        the rows of an array of shape ((R + 1) s, (C + 1) s) whose view from (s - O, s - O)
        on is the canvas. Its first s - O rows and columns are left unwritten.
    lo, hi : int
        The block rows [lo, hi) of that array, out of R + 1 (row I holds block row I - 1's
        core and the overlap strip below it).

    Notes
    -----
    Canvas row ``O + i s + a`` (a in [0, s)) lies in block row i alone for a < s - O (its
    core) and in rows i and i + 1 beyond (the overlap strip); columns the same. So a pixel is
    in one block's core, a strip of two blocks or a corner of four, and its owner is the last
    of those, in paste order (level 2 i + j), whose seam mask
    (:func:`quilting.core.seams.new_block_mask`) holds it: the same map as
    :meth:`Layout.compose` pastes block by block. Cells of one kind form a regular 4-d view,
    so each kind is a few broadcast comparisons of cut arrays instead of one masked paste a
    block. Every cell is written as the index of its upper-left block plus 0, 1 (the block to
    its right), C (below) or C + 1: indices are row-major, and modular (uint16) arithmetic
    gives the blocks beyond the grid indices too, which only cells outside the canvas keep.
    Blocks beyond the grid get cuts of B: they hold nothing.
    """
    g = p.grid
    B, overlap, s = g.block, g.overlap, g.step
    n = s - overlap  # the core's side
    R, C = g.rows, g.cols
    dtype = view.dtype
    # Entry [k] of these arrays is block row lo + k - 1 (view row lo + k holds its core),
    # padded by a column on each side: block (lo + k - 1, j) is entry [k, j + 1].
    rows = np.arange(lo, hi + 1)[:, None]
    ids = (first + (rows - 1) * C + np.arange(-1, C + 1)).astype(dtype)
    cut_cols = np.full((hi - lo + 1, C + 2, B), B, dtype=np.int16)
    cut_rows = np.full((hi - lo + 1, C + 2, B), B, dtype=np.int16)
    inside = slice(max(lo - 1, 0), min(hi, R))  # the grid's rows among lo - 1 .. hi - 1
    at = slice(inside.start - lo + 1, inside.stop - lo + 1)
    cut_cols[at, 1:-1] = p.cut_cols[inside]
    cut_rows[at, 1:-1] = p.cut_rows[inside]
    here, below = slice(0, hi - lo), slice(1, hi - lo + 1)  # view row lo + k: entries k, k + 1
    u = np.arange(overlap)  # column inside an overlap strip
    v = u[:, None, None]  # row inside an overlap strip, broadcast over (J, u)
    down, both = dtype.type(C), dtype.type(C + 1)
    core = 1 if lo == 0 else 0  # view row 0 holds only the first row's upper overlap
    mine = slice(core, hi - lo)  # the view's rows that have a core
    # Cores: the block itself.
    view[mine, :n, 1:, :n] = ids[mine, None, 1:-1, None]
    # Strip between (i, j - 1) and (i, j) beside the cores: (i, j) holds u >= its cut.
    # (Arithmetic, not copyto(where=): twice as fast on these rows of O pixels.)
    cut = cut_cols[mine, 1:, overlap:s].transpose(0, 2, 1)[..., None]
    np.add(ids[mine, None, :-1, None], u >= cut, out=view[mine, :n, :, n:])
    # Strip between (i - 1, j) and (i, j) below the cores: (i, j) holds v >= its cut.
    cut = cut_rows[below, 1:-1, overlap:s][:, None]
    np.add(ids[here, None, 1:-1, None], (v >= cut) * down, out=view[:, n:, 1:, :n])
    # Corners of (i - 1, j - 1), (i - 1, j), (i, j - 1), (i, j), pasted in that order: the
    # last whose mask holds the pixel owns it (local y = s + v or v, x = s + u or u).
    last = (u >= cut_cols[below, 1:, :overlap].transpose(0, 2, 1)[..., None]) & (
        v >= cut_rows[below, 1:, :overlap][:, None]
    )
    lower_left = v >= cut_rows[below, :-1, s:][:, None]
    upper_right = u >= cut_cols[here, 1:, s:].transpose(0, 2, 1)[..., None]
    delta = np.where(last, both, np.where(lower_left, down, upper_right.astype(dtype)))
    np.add(ids[here, None, :-1, None], delta, out=view[:, n:, :, n:])


def _owner_bands(layout: Layout, blocks: _Blocks) -> Iterator[tuple[int, NDArray[np.integer[Any]]]]:
    """The ownership map band of rows by band of rows, each (top row, contiguous band).

    A plain layout's bands are rendered one after the other (:func:`_plain_rows`), so the
    whole map never exists; any other's map is rendered whole (:func:`_general`) and cut."""
    height, width = layout.output_shape
    last = layout.passes[-1]
    if _plain_cover(last):
        g = last.grid
        s, lead = g.step, g.step - g.overlap  # lead: rows and columns above/left the canvas
        chunk = _chunk_rows(g)
        for lo in range(0, g.rows + 1, chunk):
            hi = min(lo + chunk, g.rows + 1)
            rows = np.empty(((hi - lo) * s, (g.cols + 1) * s), dtype=blocks.dtype)
            _plain_rows(last, int(blocks.first[-2]), rows.reshape(hi - lo, s, -1, s), lo, hi)
            start, stop = max(lo * s, lead), min(hi * s, lead + height)
            if stop > start:
                band = rows[start - lo * s : stop - lo * s, lead : lead + width]
                yield start - lead, np.ascontiguousarray(band)
        return
    owner = _general(layout.passes, layout.output_shape, blocks)
    step = max(1, BAND_PIXELS // max(width, 1))
    for top in range(0, height, step):
        yield top, np.ascontiguousarray(owner[top : top + step])


#: Output pixels per band of rows in :func:`copy_pairs` (a plain layout's bands are about
#: four of these): its temporaries are a few bytes per pixel of one band, never of the whole
#: output.
BAND_PIXELS = 1 << 18


@dataclass(frozen=True)
class _Sources:
    """Where in the source each output pixel comes from, for any pixels given with their block.

    A pixel's block gives the translation; on a torus a pixel that lies before its block's
    corner is the part that ran past the edge and wrapped, one period further on. A walk
    continuation past the texture's edge reads the texture mirrored, so the coordinate is
    folded back the same way.

    Attributes
    ----------
    blocks : _Blocks
    shape : (int, int)
        The source's (height, width).
    wraps : (bool, bool)
        Whether some block wraps along y, x.
    plain : bool
        No block wraps and every pixel lies in its own block's footprint inside the source
        (no walk pass): a pixel's source is its position plus its block's translation, and
        two touching pixels continue one copy exactly when their blocks' translations are
        equal. Every synthesis that is neither tileable nor walk is plain.
    inside : bool
        Every pixel lies in its own block's footprint inside the source, across a torus's
        wrap too (no walk pass): no coordinate needs folding back.
    offsets, corners : (ndarray, ndarray) of int64, shape (blocks,) each
        The blocks' translations and corners along y and x, each axis contiguous.
    periods : (ndarray or int, ndarray or int)
        The blocks' periods along y and x (see :class:`_Blocks`), or the one period of every
        block.
    """

    blocks: _Blocks
    shape: tuple[int, int]
    wraps: tuple[bool, bool]
    plain: bool
    inside: bool
    offsets: tuple[NDArray[np.int64], NDArray[np.int64]]
    corners: tuple[NDArray[np.int64], NDArray[np.int64]]
    periods: tuple[NDArray[np.int64] | int, NDArray[np.int64] | int]

    @classmethod
    def of(cls, layout: Layout, blocks: _Blocks) -> _Sources:
        wraps = (bool(blocks.periods[:, 0].any()), bool(blocks.periods[:, 1].any()))
        inside = all(
            p.feather is None
            and int(p.positions.min(initial=0)) >= 0
            and int(p.positions[..., 0].max(initial=0)) <= layout.source_shape[0] - p.grid.block
            and int(p.positions[..., 1].max(initial=0)) <= layout.source_shape[1] - p.grid.block
            for p in layout.passes
        )

        def axes(table: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
            return np.ascontiguousarray(table[:, 0]), np.ascontiguousarray(table[:, 1])

        def period(axis: int) -> NDArray[np.int64] | int:
            column = blocks.periods[:, axis]
            uniform = column.size and (column == column[0]).all()
            return int(column[0]) if uniform else np.ascontiguousarray(column)

        return cls(
            blocks,
            layout.source_shape,
            wraps,
            inside and not any(wraps),
            inside,
            axes(blocks.offsets),
            axes(blocks.corners),
            (period(0), period(1)),
        )

    def along(
        self, axis: int, coordinate: NDArray[np.int64], block: NDArray[np.integer[Any]]
    ) -> tuple[NDArray[np.int64], NDArray[np.bool_] | None]:
        """Source coordinate along ``axis`` of the pixels at ``coordinate`` owned by ``block``
        (same shapes), and where it was folded back into the texture (None: nowhere)."""
        source = coordinate + self.offsets[axis][block]
        # Most layouts need neither the wrap (no torus along this axis) nor the fold (no walk
        # continuation past the edge); skipping them changes no value.
        if self.wraps[axis]:
            before = coordinate < self.corners[axis][block]
            period = self.periods[axis]
            source += (
                before * period if isinstance(period, int) else np.where(before, period[block], 0)
            )
        size = self.shape[axis]
        if self.inside or not source.size or (source.min() >= 0 and source.max() < size):
            return source, None
        folded = (source < 0) | (source >= size)
        fold = max(2 * (size - 1), 1)
        # Folding leaves coordinates inside the texture as they are: fold only the others.
        at = np.flatnonzero(folded)
        bent = source[at] % fold
        source[at] = np.minimum(bent, fold - bent)
        return source, folded

    def continues(self, here: _Pixels, after: _Pixels, axis: int) -> NDArray[np.bool_]:
        """Whether each pixel ``after`` shows the source pixel one step along ``axis`` from
        the one pixel ``here`` shows: one verbatim copy across them."""
        step = self.along(0, after[0], after[2])[0] - self.along(0, here[0], here[2])[0]
        same = step == (1 if axis == 0 else 0)
        # Most pairs of blocks do not continue each other: the x step only where y's holds.
        kept = np.flatnonzero(same)
        x_here, x_after = here[1][kept], after[1][kept]
        step = self.along(1, x_after, after[2][kept])[0] - self.along(1, x_here, here[2][kept])[0]
        same[kept] = step == (1 if axis == 1 else 0)
        continued: NDArray[np.bool_] = same
        return continued


#: Pixels as (y, x, block), three arrays of one shape.
_Pixels = tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.integer[Any]]]


class Copies(NamedTuple):
    """What :func:`copy_pairs` finds.

    Attributes
    ----------
    blocks : int
        Number of blocks (all passes).
    pairs : ndarray of int64, shape (n, 2)
        Global block indices (``here``, ``after``): a pixel of ``here`` and its right or lower
        neighbour in ``after`` (across the wrap on a torus) whose source pixels are neighbours
        the same way; each pair once, sorted.
    used : ndarray of bool, shape (source height, source width)
        The source pixels that appear somewhere in the output.
    pixels : ndarray of int64, shape (blocks,)
        How many output pixels each block owns.
    """

    blocks: int
    pairs: NDArray[np.int64]
    used: NDArray[np.bool_]
    pixels: NDArray[np.int64]


def repetition(layout: Layout) -> tuple[float, float]:
    """Largest verbatim copy and unused share of the source (see :class:`SynthesisStats`).

    Exact, and streamed: the block-ownership map is read band of rows by band of rows
    (:func:`copy_pairs`); a plain layout's is rendered band by band too, never whole.
    """
    blocks, pairs, used, pixels = copy_pairs(layout)
    src_h, src_w = layout.source_shape
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(blocks, blocks))
    _, component = connected_components(graph, directed=False)
    largest = float(np.bincount(component, weights=pixels).max())
    return largest / (src_h * src_w), 1.0 - float(used.mean())


def copy_pairs(layout: Layout) -> Copies:
    """The touching block pairs that continue one verbatim copy, the source pixels used and
    the pixels each block owns (see :class:`Copies`).

    Notes
    -----
    Each row of the ownership map is read as runs of one block (about 1.3 runs a block a
    row). Source coordinates are computed only where they decide something: at the first
    pixel of a run and the pixel left of it (a copy continues across them when the source
    pixels are neighbours too), at the pixels whose lower neighbour has another owner, and
    at both ends of each run. A run maps to one segment of a source row (its block's
    translation) unless a torus wrap or a mirror fold bends it inside; segments mark ``used``
    through a difference array, the few bent runs pixel by pixel. So the stage makes two
    comparisons a pixel and otherwise works per run, and for a plain layout (see
    :class:`_Sources`) compares translations instead of computing coordinates.
    """
    table = _Blocks.of(layout)
    height, width = layout.output_shape
    blocks = table.count
    src_h, src_w = layout.source_shape
    sources = _Sources.of(layout, table)
    period = layout.passes[-1].grid.period
    offsets = table.offsets
    # Plain layouts: one number per translation, and where its segments start in the
    # difference array below.
    translation = offsets[:, 0] * (1 << 32) + offsets[:, 1]
    segment_shift = offsets[:, 0] * (src_w + 1) + offsets[:, 1]
    used = np.zeros((src_h, src_w), dtype=bool)
    # Segments [start, end) of source rows: +1 at each start, -1 at each end, summed along
    # the row > 0 where some segment covers the pixel.
    segments = np.zeros(src_h * (src_w + 1), dtype=np.int64)
    pixels = np.zeros(blocks, dtype=np.float64)
    found: list[NDArray[np.int64]] = []

    def keep(here: _Pixels, after: _Pixels, axis: int) -> None:
        same = sources.continues(here, after, axis)
        found.append(here[2][same].astype(np.int64) * blocks + after[2][same])

    def keep_plain(here: NDArray[np.integer[Any]], after: NDArray[np.integer[Any]]) -> None:
        same = translation[here] == translation[after]
        found.append(here[same].astype(np.int64) * blocks + after[same])

    def down(
        top: int,
        upper: NDArray[np.integer[Any]],
        lower: NDArray[np.integer[Any]],
        wrap: bool = False,
    ) -> None:
        """Pairs across rows ``upper`` (from row ``top`` on) and ``lower``, the rows below
        them (``wrap``: the first row, below the last across a torus's wrap)."""
        below = np.flatnonzero(upper != lower)
        here, after = upper.reshape(-1)[below], lower.reshape(-1)[below]
        if sources.plain:
            keep_plain(here, after)
            return
        ys, xs = _rows_cols(below, width, top)
        keep((ys, xs, here), (np.zeros_like(ys) if wrap else ys + 1, xs, after), 0)

    first_row: NDArray[np.integer[Any]] | None = None
    previous: NDArray[np.integer[Any]] | None = None  # the last row of the band before
    for top, lines in _owner_bands(layout, table):
        rows = lines.shape[0]
        flat = lines.reshape(-1)
        # Runs: a run starts at each row's first pixel and wherever the owner changes.
        starts_map = np.empty((rows, width), dtype=bool)
        starts_map[:, 0] = True
        np.not_equal(lines[:, 1:], lines[:, :-1], out=starts_map[:, 1:])
        starts = np.flatnonzero(starts_map)
        run_block = flat[starts]
        lengths = np.diff(starts, append=rows * width)
        pixels += np.bincount(run_block, weights=lengths, minlength=blocks)
        run_y = starts // width
        run_x = starts - run_y * width
        run_y += top
        # Across a run's start: the pixel left of it, in another block.
        inner = starts[run_x > 0]
        if sources.plain:
            keep_plain(flat[inner - 1], flat[inner])
            first = run_y * (src_w + 1) + run_x + segment_shift[run_block]
            segments += np.bincount(first, minlength=segments.size)
            segments -= np.bincount(first + lengths, minlength=segments.size)
        else:
            ys, xs = _rows_cols(inner, width, top)
            keep((ys, xs - 1, flat[inner - 1]), (ys, xs, flat[inner]), 1)
            if period[1]:  # across the wrap: the last column before the first
                ys = np.flatnonzero(lines[:, -1] != lines[:, 0])
                keep(
                    (ys + top, np.full(ys.size, width - 1, dtype=np.int64), lines[ys, -1]),
                    (ys + top, np.zeros(ys.size, dtype=np.int64), lines[ys, 0]),
                    1,
                )
            _mark_runs(sources, used, segments, run_y, run_x, lengths, run_block)
        # Down: from the band before into this one, then within this one.
        if previous is not None:
            down(top - 1, previous[None], lines[:1])
        down(top, lines[:-1], lines[1:])
        previous = lines[-1].copy()
        if first_row is None:
            first_row = lines[0].copy()
    if period[0] and previous is not None and first_row is not None:
        down(height - 1, previous[None], first_row[None], wrap=True)
    covered = np.cumsum(segments.reshape(src_h, src_w + 1), axis=1)[:, :src_w] > 0
    used |= covered
    keys = np.unique(np.concatenate(found)) if found else np.zeros(0, dtype=np.int64)
    pairs = np.stack(np.divmod(keys, blocks), axis=1).astype(np.int64)
    return Copies(blocks, pairs, used, np.rint(pixels).astype(np.int64))


def _rows_cols(
    index: NDArray[np.intp], width: int, top: int
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Output (y, x) of flat indices into rows ``top...`` of a map ``width`` wide."""
    ys, xs = np.divmod(index.astype(np.int64), width)
    return ys + top, xs


def _mark_runs(
    sources: _Sources,
    used: NDArray[np.bool_],
    segments: NDArray[np.int64],
    ys: NDArray[np.int64],
    xs: NDArray[np.int64],
    lengths: NDArray[np.int64],
    block: NDArray[np.integer[Any]],
) -> None:
    """Mark the source pixels runs of output pixels show.

    Parameters
    ----------
    sources : _Sources
    used : ndarray of bool, shape (source height, source width), updated in place
        Set pixel by pixel for the runs a wrap or a fold bends.
    segments : ndarray of int64, shape (source height * (source width + 1),), updated
        The difference array of the straight runs' source segments (see :func:`copy_pairs`).
    ys, xs, lengths, block : ndarray, shape (runs,)
        Output row, first column, length and block of each run (one block, one row).
    """
    src_w = sources.shape[1]
    sy, _ = sources.along(0, ys, block)  # one row: its fold or wrap is the same all along
    ends = xs + lengths - 1
    sx, folded = sources.along(1, xs, block)
    end_x, end_folded = sources.along(1, ends, block)
    # Straight: the source column is the output column plus one constant along the run.
    straight = end_x - sx == lengths - 1
    if folded is not None:
        straight &= ~folded
    if end_folded is not None:
        straight &= ~end_folded
    if sources.wraps[1]:
        corner = sources.blocks.corners[block, 1]
        straight &= (xs < corner) == (ends < corner)
    row = sy * (src_w + 1)
    segments += np.bincount((row + sx)[straight], minlength=segments.size)
    segments -= np.bincount((row + sx + lengths)[straight], minlength=segments.size)
    if straight.all():
        return
    bent = ~straight
    count = lengths[bent]
    step = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    pixel_x = np.repeat(xs[bent], count) + step
    pixel_block = np.repeat(block[bent], count)
    pixel_y, _ = sources.along(0, np.repeat(ys[bent], count), pixel_block)
    pixel_sx, _ = sources.along(1, pixel_x, pixel_block)
    used[pixel_y, pixel_sx] = True


def seam_mask(layout: Layout) -> NDArray[np.bool_]:
    """Where the output changes from one block to another: the seams of its layout.

    Parameters
    ----------
    layout : Layout
        The layout of a result.

    Returns
    -------
    ndarray of bool, shape (H, W)
        True on every pixel whose right or lower neighbour belongs to another block (the last
        pass's blocks, over the blocks of earlier passes they leave showing).
    """
    owner = ownership(layout).owner
    seam = np.zeros(owner.shape, dtype=bool)
    seam[:, :-1] |= owner[:, :-1] != owner[:, 1:]
    seam[:-1, :] |= owner[:-1, :] != owner[1:, :]
    return seam


def seam_overlay(
    image: NDArray[np.generic], layout: Layout, color: tuple[float, float, float] = (1.0, 0.0, 0.0)
) -> NDArray[np.uint8]:
    """The output with the boundaries between blocks (:func:`seam_mask`) drawn over it.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        The result image (any accepted dtype).
    layout : Layout
        Its layout.
    color : (r, g, b) in [0, 1]
        Colour of the seam pixels.

    Returns
    -------
    ndarray of uint8, shape (H, W, 3)
    """
    return draw_seams(image, seam_mask(layout), color)


def draw_seams(
    image: NDArray[np.generic],
    seams: NDArray[np.bool_],
    color: tuple[float, float, float] = (1.0, 0.0, 0.0),
) -> NDArray[np.uint8]:
    """``image`` as RGB uint8, shape (H, W, 3), with the pixels of ``seams`` (H, W) painted
    ``color`` ((r, g, b) in [0, 1]): a synthesis's seams or a fill's
    (:meth:`quilting.core.fill_layout.FillLayout.seam_mask`)."""
    view = image[..., None] if image.ndim == 2 else image
    rgb = view[..., :3] if view.shape[2] >= 3 else np.repeat(view[..., :1], 3, axis=2)
    scale = {np.dtype(np.uint8): 1.0, np.dtype(np.uint16): 1 / 257}.get(rgb.dtype, 255.0)
    out = np.clip(np.rint(rgb.astype(np.float64) * scale), 0, 255).astype(np.uint8)
    out[seams] = np.rint(np.asarray(color) * 255).astype(np.uint8)
    return out
