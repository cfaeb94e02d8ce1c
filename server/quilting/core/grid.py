"""Block positions on the output and the wavefront schedule.

Block (i, j) sits at (i * step, j * step) with step = block - overlap. It overlaps its left,
upper-left, upper and upper-right neighbours, so every block of level ``2 i + j`` depends only
on lower levels and the blocks of one level are independent (and disjoint while
overlap < block / 2). Running levels in order reproduces raster order bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numpy.typing import NDArray


class Overlap(IntEnum):
    """Which already-synthesized neighbours a block overlaps."""

    NONE = 0
    LEFT = 1
    TOP = 2
    BOTH = 3  # the L-shaped overlap

    @property
    def left(self) -> bool:
        return bool(self & Overlap.LEFT)

    @property
    def top(self) -> bool:
        return bool(self & Overlap.TOP)


@dataclass(frozen=True)
class Grid:
    """The covering grid of blocks for an output of a given size."""

    block: int
    overlap: int
    rows: int
    cols: int

    @classmethod
    def covering(cls, height: int, width: int, block: int, overlap: int) -> Grid:
        """Smallest grid whose canvas (``rows * step + overlap``) covers ``height x width``."""
        step = block - overlap
        rows = max(1, -(-(height - overlap) // step))
        cols = max(1, -(-(width - overlap) // step))
        return cls(block=block, overlap=overlap, rows=rows, cols=cols)

    @property
    def step(self) -> int:
        return self.block - self.overlap

    @property
    def height(self) -> int:
        """Canvas height in pixels (at least the requested output height)."""
        return self.rows * self.step + self.overlap

    @property
    def width(self) -> int:
        return self.cols * self.step + self.overlap

    @property
    def levels(self) -> int:
        """Number of wavefront levels, ``2 (rows - 1) + cols``."""
        return 2 * (self.rows - 1) + self.cols

    def level(self, index: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Rows and columns of the blocks on wavefront level ``index`` (= 2 i + j).

        Returns
        -------
        rows, cols : ndarray of int, shape (n,)
            Ordered by row.
        """
        i = np.arange(self.rows)
        j = index - 2 * i
        keep = (j >= 0) & (j < self.cols)
        return i[keep], j[keep]

    def origins(self, rows: NDArray[np.intp], cols: NDArray[np.intp]) -> NDArray[np.intp]:
        """Top-left canvas corner of each block, shape (n, 2) as (y, x)."""
        return np.stack([rows * self.step, cols * self.step], axis=-1)

    @staticmethod
    def overlap_kind(row: int, col: int) -> Overlap:
        """Which overlap strips block (row, col) has."""
        return Overlap((Overlap.LEFT if col > 0 else 0) | (Overlap.TOP if row > 0 else 0))

    def overlap_mask(self, kind: Overlap) -> NDArray[np.float32]:
        """Weights M of the overlap region of a block of this kind, shape (block, block)."""
        mask = np.zeros((self.block, self.block), dtype=np.float32)
        if kind.left:
            mask[:, : self.overlap] = 1
        if kind.top:
            mask[: self.overlap, :] = 1
        return mask
