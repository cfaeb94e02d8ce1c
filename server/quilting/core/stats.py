"""Diagnostics of a result: seam error, repetition of the source, and the seam overlay.

Repetition is measured on the final block ownership: every output pixel comes from one source
pixel at a translation fixed per block. Touching blocks with the same translation are one
verbatim copy of the source; the largest such connected region, as a share of the texture's
area, says how much of the source the output reproduces in one piece.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

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


def ownership(layout: Layout) -> Ownership:
    """Render block indices with the layout's seams (see :class:`Ownership`).

    A plain last pass (see :func:`_plain_cover`: no torus, no walk fill, cuts inside the
    overlap) is rendered cell by cell of its grid (:func:`_grid_owner`), five to seven times
    faster than pasting its blocks one by one (42,025 at 8192²); any other layout is pasted
    through :meth:`Layout.compose`. Both give the same map (tested).
    """
    counts = [p.grid.rows * p.grid.cols for p in layout.passes]
    first = np.cumsum([0, *counts])
    corners, offsets, sizes = [], [], []
    for p, count in zip(layout.passes, counts, strict=True):
        rows, cols = np.divmod(np.arange(count), p.grid.cols)
        origin = p.grid.origins(rows, cols).astype(np.int64)
        corners.append(origin)
        offsets.append(p.positions.reshape(-1, 2).astype(np.int64) - origin)
        sizes.append(np.full(count, p.grid.block, dtype=np.int64))

    # The map is the stage's largest array: 2 bytes a pixel where the block count allows.
    dtype = np.uint16 if first[-1] < np.iinfo(np.uint16).max else np.int32
    fill = np.iinfo(dtype).max if dtype == np.uint16 else -1

    def ids(index: int, p: LayoutPass, rows: Index, cols: Index) -> Blocks:
        block_ids: Blocks = (first[index] + rows * p.grid.cols + cols).astype(dtype)
        return block_ids[:, None, None, None]

    last = layout.passes[-1]
    if _plain_cover(last):
        height, width = layout.output_shape
        owner = _grid_owner(last, int(first[-2]), np.dtype(dtype))[:height, :width]
    else:
        owner = layout.compose(1, dtype, ids, fill=fill, contiguous=False)[..., 0]
    return Ownership(
        owner=owner,
        offsets=np.concatenate(offsets),
        corners=np.concatenate(corners),
        sizes=np.concatenate(sizes),
    )


def _plain_cover(p: LayoutPass) -> bool:
    """Whether :func:`_grid_owner` renders this pass exactly, alone.

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


def _grid_owner(p: LayoutPass, first: int, dtype: np.dtype[Any]) -> NDArray[np.integer[Any]]:
    """The global block index of every pixel of a plain pass's canvas, cell by cell.

    Parameters
    ----------
    p : LayoutPass
        A pass that :func:`_plain_cover` accepts.
    first : int
        Global index of its block (0, 0).
    dtype : numpy dtype
        Of the map (uint16 or int32).

    Returns
    -------
    ndarray of ``dtype``, shape (grid height, grid width)
        A view of a slightly larger array (rows contiguous): the same map as
        :meth:`Layout.compose` pastes block by block.

    Notes
    -----
    With block B, overlap O, step s = B - O and C columns, canvas row ``O + i s + a``
    (a in [0, s)) lies in block row i alone for a < s - O (its core) and in rows i and i + 1
    beyond (the overlap strip); columns the same. So a pixel is in one block's core, a strip
    of two blocks or a corner of four, and its owner is the last of those, in paste order
    (level 2 i + j), whose seam mask (:func:`quilting.core.seams.new_block_mask`) holds it.
    Cells of one kind form a regular 4-d view of the canvas, so each kind is a few broadcast
    comparisons of cut arrays instead of one masked paste a block. Every cell is written as
    the index of its upper-left block plus 0, 1 (the block to its right), C (below) or C + 1:
    indices are row-major, and modular (uint16) arithmetic gives the blocks beyond the grid
    indices too, which only cells outside the canvas keep. Blocks beyond the grid get cuts of
    B: they hold nothing.
    """
    g = p.grid
    B, overlap, s = g.block, g.overlap, g.step
    n = s - overlap  # the core's side
    R, C = g.rows, g.cols
    big = np.empty(((R + 1) * s, (C + 1) * s), dtype=dtype)
    view = big.reshape(R + 1, s, C + 1, s)  # [I, a, J, b]: block row I - 1, column J - 1
    # Padded by one block on every side: block (i, j) is entry [i + 1, j + 1].
    rows, cols = np.divmod(np.arange((R + 2) * (C + 2)), C + 2)
    ids = (first + (rows - 1) * C + cols - 1).reshape(R + 2, C + 2).astype(dtype)
    cut_cols = np.full((R + 2, C + 2, B), B, dtype=np.int16)
    cut_rows = np.full((R + 2, C + 2, B), B, dtype=np.int16)
    cut_cols[1:-1, 1:-1] = p.cut_cols
    cut_rows[1:-1, 1:-1] = p.cut_rows
    u = np.arange(overlap)  # column inside an overlap strip
    v = u[:, None, None]  # row inside an overlap strip, broadcast over (J, u)
    down, both = dtype.type(C), dtype.type(C + 1)
    # Block rows a chunk: the temporaries below are a few bytes per pixel of the chunk.
    chunk = max(1, 4 * BAND_PIXELS // ((C + 1) * s * s))
    for lo in range(0, R + 1, chunk):
        hi = min(lo + chunk, R + 1)
        here, below = slice(lo, hi), slice(lo + 1, hi + 1)
        core = max(lo, 1)  # view row 0 holds only the first row's upper overlap
        # Cores: the block itself.
        view[core:hi, :n, 1:, :n] = ids[core:hi, None, 1:-1, None]
        # Strip between (i, j - 1) and (i, j) beside the cores: (i, j) holds u >= its cut.
        # (Arithmetic, not copyto(where=): twice as fast on these rows of O pixels.)
        cut = cut_cols[core:hi, 1:, overlap:s].transpose(0, 2, 1)[..., None]
        np.add(ids[core:hi, None, :-1, None], u >= cut, out=view[core:hi, :n, :, n:])
        # Strip between (i - 1, j) and (i, j) below the cores: (i, j) holds v >= its cut.
        cut = cut_rows[below, 1:-1, overlap:s][:, None]
        np.add(ids[here, None, 1:-1, None], (v >= cut) * down, out=view[here, n:, 1:, :n])
        # Corners of (i - 1, j - 1), (i - 1, j), (i, j - 1), (i, j), pasted in that order: the
        # last whose mask holds the pixel owns it (local y = s + v or v, x = s + u or u).
        last = (u >= cut_cols[below, 1:, :overlap].transpose(0, 2, 1)[..., None]) & (
            v >= cut_rows[below, 1:, :overlap][:, None]
        )
        lower_left = v >= cut_rows[below, :-1, s:][:, None]
        upper_right = u >= cut_cols[here, 1:, s:].transpose(0, 2, 1)[..., None]
        delta = np.where(last, both, np.where(lower_left, down, upper_right.astype(dtype)))
        np.add(ids[here, None, :-1, None], delta, out=view[here, n:, :, n:])
    return big[s - overlap :, s - overlap :]


#: Output pixels per band of rows in :func:`copy_pairs` (and per chunk in :func:`_grid_owner`):
#: its temporaries are a few bytes per pixel of one band, never of the whole output.
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
    own : Ownership
    periods : ndarray of int64, shape (blocks, 2)
        Each block's torus period (0: that axis does not wrap).
    shape : (int, int)
        The source's (height, width).
    wraps : (bool, bool)
        Whether some block wraps along y, x.
    plain : bool
        No block wraps and every pixel lies in its own block's footprint inside the source
        (no walk pass): a pixel's source is its position plus its block's translation, and
        two touching pixels continue one copy exactly when their blocks' translations are
        equal. Every synthesis that is neither tileable nor walk is plain.
    """

    own: Ownership
    periods: NDArray[np.int64]
    shape: tuple[int, int]
    wraps: tuple[bool, bool]
    plain: bool

    @classmethod
    def of(cls, layout: Layout, own: Ownership) -> _Sources:
        periods = np.concatenate(
            [
                np.tile(np.asarray(p.grid.period, dtype=np.int64), (p.grid.rows * p.grid.cols, 1))
                for p in layout.passes
            ]
        )
        wraps = (bool(periods[:, 0].any()), bool(periods[:, 1].any()))
        inside = all(
            p.feather is None
            and int(p.positions.min(initial=0)) >= 0
            and int(p.positions[..., 0].max(initial=0)) <= layout.source_shape[0] - p.grid.block
            and int(p.positions[..., 1].max(initial=0)) <= layout.source_shape[1] - p.grid.block
            for p in layout.passes
        )
        return cls(own, periods, layout.source_shape, wraps, inside and not any(wraps))

    def along(
        self, axis: int, coordinate: NDArray[np.int64], block: NDArray[np.integer[Any]]
    ) -> tuple[NDArray[np.int64], NDArray[np.bool_] | None]:
        """Source coordinate along ``axis`` of the pixels at ``coordinate`` owned by ``block``
        (same shapes), and where it was folded back into the texture (None: nowhere)."""
        source = coordinate + self.own.offsets[block, axis]
        # Most layouts need neither the wrap (no torus along this axis) nor the fold (no walk
        # continuation past the edge); skipping them changes no value.
        if self.wraps[axis]:
            before = coordinate < self.own.corners[block, axis]
            source += np.where(before, self.periods[block, axis], 0)
        size = self.shape[axis]
        if not source.size or (source.min() >= 0 and source.max() < size):
            return source, None
        folded = (source < 0) | (source >= size)
        fold = max(2 * (size - 1), 1)
        source %= fold
        return np.minimum(source, fold - source), folded

    def continues(self, here: _Pixels, after: _Pixels, axis: int) -> NDArray[np.bool_]:
        """Whether each pixel ``after`` shows the source pixel one step along ``axis`` from
        the one pixel ``here`` shows: one verbatim copy across them."""
        same = np.ones(here[0].shape, dtype=bool)
        for a, (start, end) in enumerate(((here[0], after[0]), (here[1], after[1]))):
            step = self.along(a, end, after[2])[0] - self.along(a, start, here[2])[0]
            same &= step == (1 if a == axis else 0)
        return same


#: Pixels as (y, x, block), three arrays of one shape.
_Pixels = tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.integer[Any]]]


def repetition(layout: Layout) -> tuple[float, float]:
    """Largest verbatim copy and unused share of the source (see :class:`SynthesisStats`).

    Exact, from the block-ownership map (2 bytes a pixel, the stage's only output-sized
    array), read band of rows by band of rows (:func:`copy_pairs`).
    """
    own, pairs, used, pixels = copy_pairs(layout)
    blocks = own.offsets.shape[0]
    src_h, src_w = layout.source_shape
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(blocks, blocks))
    _, component = connected_components(graph, directed=False)
    largest = float(np.bincount(component, weights=pixels).max())
    return largest / (src_h * src_w), 1.0 - float(used.mean())


def copy_pairs(
    layout: Layout,
) -> tuple[Ownership, NDArray[np.int64], NDArray[np.bool_], NDArray[np.int64]]:
    """The block ownership, the touching block pairs that continue one verbatim copy, and
    the source pixels used.

    Returns
    -------
    own : Ownership
    pairs : ndarray of int64, shape (n, 2)
        Global block indices (``here``, ``after``): a pixel of ``here`` and its right or lower
        neighbour in ``after`` (across the wrap on a torus) whose source pixels are neighbours
        the same way; each pair once, sorted.
    used : ndarray of bool, shape (source height, source width)
        The source pixels that appear somewhere in the output.
    pixels : ndarray of int64, shape (blocks,)
        How many output pixels each block owns.

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
    own = ownership(layout)
    owner = own.owner
    height, width = owner.shape
    blocks = own.offsets.shape[0]
    src_h, src_w = layout.source_shape
    sources = _Sources.of(layout, own)
    period = layout.passes[-1].grid.period
    offsets = own.offsets
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

    band = max(1, BAND_PIXELS // max(width, 1))
    changes = np.empty((min(band, height), width), dtype=bool)
    for top in range(0, height, band):
        bottom = min(top + band, height)
        rows = bottom - top
        # The band and the row below it, contiguous: flat indices address both.
        lines = np.ascontiguousarray(owner[top : min(bottom + 1, height)])
        flat = lines.reshape(-1)
        # Runs: a run starts at each row's first pixel and wherever the owner changes.
        starts_map = changes[:rows]
        starts_map[:, 0] = True
        np.not_equal(lines[:rows, 1:], lines[:rows, :-1], out=starts_map[:, 1:])
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
                ys = top + np.flatnonzero(lines[:rows, -1] != lines[:rows, 0])
                keep(
                    (ys, np.full(ys.size, width - 1, dtype=np.int64), owner[ys, -1]),
                    (ys, np.zeros(ys.size, dtype=np.int64), owner[ys, 0]),
                    1,
                )
            _mark_runs(sources, used, segments, run_y, run_x, lengths, run_block)
        # Down: each row of the band with the next (the first again across a torus's wrap).
        downs = changes[: lines.shape[0] - 1]
        np.not_equal(lines[:-1], lines[1:], out=downs)
        below = np.flatnonzero(downs)
        if sources.plain:
            keep_plain(flat[below], flat[below + width])
        else:
            ys, xs = _rows_cols(below, width, top)
            keep((ys, xs, flat[below]), (ys + 1, xs, flat[below + width]), 0)
            if bottom == height and period[0]:
                xs = np.flatnonzero(owner[-1] != owner[0])
                keep(
                    (np.full(xs.size, height - 1, dtype=np.int64), xs, owner[-1, xs]),
                    (np.zeros(xs.size, dtype=np.int64), xs, owner[0, xs]),
                    0,
                )
    covered = np.cumsum(segments.reshape(src_h, src_w + 1), axis=1)[:, :src_w] > 0
    used |= covered
    keys = np.unique(np.concatenate(found)) if found else np.zeros(0, dtype=np.int64)
    pairs = np.stack(np.divmod(keys, blocks), axis=1).astype(np.int64)
    return own, pairs, used, np.rint(pixels).astype(np.int64)


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
        corner = sources.own.corners[block, 1]
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
    view = image[..., None] if image.ndim == 2 else image
    rgb = view[..., :3] if view.shape[2] >= 3 else np.repeat(view[..., :1], 3, axis=2)
    scale = {np.dtype(np.uint8): 1.0, np.dtype(np.uint16): 1 / 257}.get(rgb.dtype, 255.0)
    out = np.clip(np.rint(rgb.astype(np.float64) * scale), 0, 255).astype(np.uint8)
    out[seam_mask(layout)] = np.rint(np.asarray(color) * 255).astype(np.uint8)
    return out
