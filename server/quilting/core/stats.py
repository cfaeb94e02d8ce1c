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
    """Render block indices with the layout's seams (see :class:`Ownership`)."""
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

    owner = layout.compose(1, dtype, ids, fill=fill, contiguous=False)[..., 0]
    return Ownership(
        owner=owner,
        offsets=np.concatenate(offsets),
        corners=np.concatenate(corners),
        sizes=np.concatenate(sizes),
    )


#: Output pixels per band of rows in :func:`repetition`: its temporaries are a few bytes per
#: pixel of one band instead of tens of bytes per pixel of the whole output.
BAND_PIXELS = 1 << 18


def _source_rows(
    layout: Layout,
    own: Ownership,
    periods: NDArray[np.int32],
    owner: NDArray[np.integer[Any]],
    rows: NDArray[np.int32],
) -> NDArray[np.int32]:
    """Source (y, x) of every output pixel of ``rows``, shape (len(rows), out_w, 2).

    ``owner`` is ``own.owner[rows]``. A pixel's block gives the translation; on a torus a
    pixel that lies before its block's corner is the part that ran past the edge and wrapped,
    one period further on. A walk continuation past the texture's edge reads the texture
    mirrored, so the coordinate is folded back the same way.
    """
    width = owner.shape[1]
    source = np.empty((rows.size, width, 2), dtype=np.int32)
    lines = (rows[:, None], np.arange(width, dtype=np.int32)[None, :])
    for axis, size in enumerate(layout.source_shape):
        coordinate = lines[axis] + own.offsets[:, axis].astype(np.int32)[owner]
        # The wrap and the fold cost three passes over the band; most layouts need neither
        # (no torus along this axis; no walk continuation past the texture's edge), and
        # skipping them changes no value: a coordinate inside the texture folds to itself.
        if periods[:, axis].any():
            corner = own.corners[:, axis].astype(np.int32)[owner]
            coordinate += np.where(lines[axis] < corner, periods[:, axis][owner], 0)
        if coordinate.size and (coordinate.min() < 0 or coordinate.max() >= size):
            fold = max(2 * (size - 1), 1)
            coordinate %= fold
            coordinate = np.minimum(coordinate, fold - coordinate)
        source[..., axis] = coordinate
    return source


def _copy_edges(
    here: NDArray[np.integer[Any]],
    after: NDArray[np.integer[Any]],
    here_source: NDArray[np.int32],
    after_source: NDArray[np.int32],
    axis: int,
) -> NDArray[np.integer[Any]]:
    """Pairs of blocks that touch along ``axis`` where their source pixels touch the same way
    (one verbatim copy), each pair once, shape (n, 2); the arrays are pixelwise neighbours.

    Once per pair rather than per pixel: a boundary of two continuing blocks is tens of pixels
    long, and the graph of all of them would be the stage's largest temporary."""
    boundary = here != after
    step = np.zeros(2, dtype=np.int32)
    step[axis] = 1
    same = np.all(after_source[boundary] - here_source[boundary] == step, axis=1)
    found = np.stack([here[boundary][same], after[boundary][same]], axis=1).astype(np.int64)
    return np.unique(found, axis=0)


def repetition(layout: Layout) -> tuple[float, float]:
    """Largest verbatim copy and unused share of the source (see :class:`SynthesisStats`).

    Exact, and computed band of rows by band of rows: only the block-ownership map is
    whole-output sized (4 bytes a pixel); the source coordinates, boundaries and their
    temporaries exist for one band (and the row after it) at a time.
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
    """
    own = ownership(layout)
    owner = own.owner
    src_h, src_w = layout.source_shape
    height, width = owner.shape
    periods = np.concatenate(
        [
            np.tile(np.asarray(p.grid.period, dtype=np.int32), (p.grid.rows * p.grid.cols, 1))
            for p in layout.passes
        ]
    )
    period = layout.passes[-1].grid.period
    used = np.zeros((src_h, src_w), dtype=bool)
    pixels = np.zeros(own.offsets.shape[0], dtype=np.int64)
    edges: list[NDArray[np.integer[Any]]] = []
    band = max(1, BAND_PIXELS // max(width, 1))
    for top in range(0, height, band):
        bottom = min(top + band, height)
        # Rows of the band, and the row below its last one (the first row again on a torus);
        # a view of the ownership map except for that wrapped row.
        rows = np.arange(top, bottom + 1, dtype=np.int32)
        if bottom < height:
            band_owner = owner[top : bottom + 1]
        elif period[0]:
            band_owner = np.concatenate([owner[top:bottom], owner[:1]])
            rows[-1] = 0
        else:
            band_owner, rows = owner[top:bottom], rows[:-1]
        source = _source_rows(layout, own, periods, band_owner, rows)
        mine, mine_source = band_owner[: bottom - top], source[: bottom - top]
        used[mine_source[..., 0], mine_source[..., 1]] = True
        pixels += np.bincount(mine.ravel(), minlength=pixels.size)
        # Two touching pixels of different blocks are one verbatim copy when their source
        # pixels touch the same way; across the wrap of a torus too. Down: each row of the
        # band (and the one after it, when there is one) with the next.
        edges.append(
            _copy_edges(band_owner[:-1], band_owner[1:], source[:-1], source[1:], 0)
        )
        edges.append(
            _copy_edges(mine[:, :-1], mine[:, 1:], mine_source[:, :-1], mine_source[:, 1:], 1)
        )
        if period[1]:
            edges.append(
                _copy_edges(
                    mine[:, -1:], mine[:, :1], mine_source[:, -1:], mine_source[:, :1], 1
                )
            )
    return own, np.unique(np.concatenate(edges), axis=0), used, pixels


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
