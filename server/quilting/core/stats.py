"""Diagnostics of a result: seam error, repetition of the source, and the seam overlay.

Repetition is measured on the final block ownership: every output pixel comes from one source
pixel at a translation fixed per block. Neighbouring blocks with the same translation are one
verbatim copy of the source; the largest such connected region, as a share of the texture's
area, says how much of the source the output reproduces in one piece.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from quilting.core.compose import paste
from quilting.core.layout import Layout, owned_mask


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
    """

    seam_error_total: float
    seam_error_mean: float
    seam_pixels: int
    largest_copy: float
    unused: float


def owner_map(layout: Layout) -> tuple[NDArray[np.int32], NDArray[np.int64]]:
    """Which block each output pixel finally comes from.

    Returns
    -------
    owner : ndarray of int32, shape (out_h, out_w)
        Global block index (passes concatenated, row-major within a pass).
    offsets : ndarray of int64, shape (blocks, 2)
        Source position minus output position of each block's pixels.
    """
    ids: list[NDArray[np.int64]] = []
    offsets: list[NDArray[np.int64]] = []
    height, width = layout.output_shape
    canvas: NDArray[np.int32] | None = None
    first = 0
    for p in layout.passes:
        g = p.grid
        count = g.rows * g.cols
        ids.append(np.arange(first, first + count))
        rows, cols = np.divmod(np.arange(count), g.cols)
        origin = g.origins(rows, cols)
        offsets.append(p.positions.reshape(-1, 2).astype(np.int64) - origin)
        new = np.full((g.height, g.width, 1), -1, dtype=np.int32)
        if canvas is not None:
            h, w = min(g.height, height), min(g.width, width)
            new[:h, :w, 0] = canvas[:h, :w]
        for level in range(g.levels):
            r, c = g.level(level)
            owned = owned_mask(p.cut_cols[r, c], p.cut_rows[r, c])
            block_ids = (first + r * g.cols + c).astype(np.int32)[:, None, None, None]
            paste(new, block_ids, g.origins(r, c), owned)
        canvas = new[..., 0]
        first += count
    assert canvas is not None
    return np.ascontiguousarray(canvas[:height, :width]), np.concatenate(offsets)


def repetition(layout: Layout) -> tuple[float, float]:
    """Largest verbatim copy and unused share of the source (see :class:`SynthesisStats`)."""
    owner, offsets = owner_map(layout)
    blocks = offsets.shape[0]
    src_h, src_w = layout.source_shape
    # Translation of every block as one integer, so equal translations compare equal.
    key = offsets[:, 0] * (2 * (owner.shape[1] + src_w) + 1) + offsets[:, 1]
    edges = []
    for a, b in ((owner[:, :-1], owner[:, 1:]), (owner[:-1, :], owner[1:, :])):
        touching = (a != b) & (key[a] == key[b])
        edges.append(np.stack([a[touching], b[touching]], axis=1))
    pairs = np.unique(np.concatenate(edges), axis=0)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(blocks, blocks))
    _, component = connected_components(graph, directed=False)
    pixels = np.bincount(owner.ravel(), minlength=blocks)
    largest = int(np.bincount(component, weights=pixels).max())
    yy, xx = np.indices(owner.shape, sparse=True)
    used = np.zeros((src_h, src_w), dtype=bool)
    used[yy + offsets[owner, 0], xx + offsets[owner, 1]] = True
    return largest / (src_h * src_w), 1.0 - float(used.mean())


def seam_overlay(
    image: NDArray[np.generic], layout: Layout, color: tuple[float, float, float] = (1.0, 0.0, 0.0)
) -> NDArray[np.uint8]:
    """The output with the boundaries between blocks drawn over it.

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
    owner, _ = owner_map(layout)
    view = image[..., None] if image.ndim == 2 else image
    rgb = view[..., :3] if view.shape[2] >= 3 else np.repeat(view[..., :1], 3, axis=2)
    scale = {np.dtype(np.uint8): 1.0, np.dtype(np.uint16): 1 / 257}.get(rgb.dtype, 255.0)
    out = np.clip(np.rint(rgb.astype(np.float64) * scale), 0, 255).astype(np.uint8)
    seam = np.zeros(owner.shape, dtype=bool)
    seam[:, :-1] |= owner[:, :-1] != owner[:, 1:]
    seam[:-1, :] |= owner[:-1, :] != owner[1:, :]
    out[seam] = np.rint(np.asarray(color) * 255).astype(np.uint8)
    return out
