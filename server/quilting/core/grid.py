"""Block positions on the output, the overlap regions and the schedule, on a plane or a torus.

Block (i, j) sits at (i * step, j * step) with step = block - overlap. On a plane it overlaps
its left, upper-left, upper and upper-right neighbours, so every block of level ``2 i + j``
depends only on lower levels and the blocks of one level are independent (and disjoint while
overlap < block / 2). Running levels in order reproduces raster order bit for bit.

A tileable output wraps the grid on a torus along one or both axes: the canvas is exactly the
requested size (the period), and the last column (row) of blocks runs past the edge onto the
first, overlapping it by the *wrap overlap* ``count * step + overlap - period``, between the
overlap and ``step`` pixels (the overlap is widened by a pixel or two for sizes that would
otherwise wrap over a narrower strip). Those blocks match and are cut against the first column
(row) too, so the output repeats with no seam. The same levels are kept; where a small torus
would put two touching blocks on one level, the level is split in two (see :meth:`Grid.groups`).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntFlag
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from quilting.core.errors import InvalidParameterError

Group = tuple[NDArray[np.intp], NDArray[np.intp]]


class Overlap(IntFlag):
    """Which sides of a block overlap blocks already in place."""

    NONE = 0
    LEFT = 1
    TOP = 2
    BOTH = 3  # the L-shaped overlap
    RIGHT = 4  # only across the wrap of a torus
    BOTTOM = 8

    @property
    def left(self) -> bool:
        return bool(self & Overlap.LEFT)

    @property
    def top(self) -> bool:
        return bool(self & Overlap.TOP)

    @property
    def right(self) -> bool:
        return bool(self & Overlap.RIGHT)

    @property
    def bottom(self) -> bool:
        return bool(self & Overlap.BOTTOM)


def _wrapped_count(size: int, block: int, step: int, overlap: int, axis: str) -> int:
    """Blocks along a wrapped axis of ``size`` pixels: the wrap overlap lands in 1..step."""
    if size < block:
        raise InvalidParameterError(
            "size",
            size,
            f">= {block} (the block) along a tileable axis",
            f"a tileable {axis} must hold at least two overlapping blocks",
        )
    return -(-(size - overlap + 1) // step)


@dataclass(frozen=True)
class Grid:
    """The grid of blocks covering an output of a given size.

    Attributes
    ----------
    block, overlap : int
    rows, cols : int
    period : (int, int)
        Canvas (height, width) of the axes that wrap; 0 for an axis that does not.
    """

    block: int
    overlap: int
    rows: int
    cols: int
    period: tuple[int, int] = (0, 0)

    @classmethod
    def covering(
        cls,
        height: int,
        width: int,
        block: int,
        overlap: int,
        wrap: tuple[bool, bool] = (False, False),
    ) -> Grid:
        """Smallest grid covering ``height x width``; ``wrap`` (y, x) makes those axes a torus.

        A plane axis gets a canvas of ``count * step + overlap`` pixels, cropped afterwards; a
        wrapped axis gets a canvas of exactly its size. On a torus the overlap may be widened
        (see :func:`_torus_overlap`).
        """
        if wrap[0] or wrap[1]:
            overlap = _torus_overlap((height, width), wrap, block, overlap)
        step = block - overlap
        rows = max(1, -(-(height - overlap) // step))
        cols = max(1, -(-(width - overlap) // step))
        if wrap[0]:
            rows = _wrapped_count(height, block, step, overlap, "height")
        if wrap[1]:
            cols = _wrapped_count(width, block, step, overlap, "width")
        period = (height if wrap[0] else 0, width if wrap[1] else 0)
        return cls(block=block, overlap=overlap, rows=rows, cols=cols, period=period)

    @property
    def step(self) -> int:
        return self.block - self.overlap

    @property
    def wrapped(self) -> bool:
        return bool(self.period[0] or self.period[1])

    @property
    def height(self) -> int:
        """Canvas height in pixels (at least the requested output height)."""
        return self.period[0] or self.rows * self.step + self.overlap

    @property
    def width(self) -> int:
        return self.period[1] or self.cols * self.step + self.overlap

    @property
    def wrap_overlap(self) -> tuple[int, int]:
        """Overlap (y, x) of the last row (column) with the first across the wrap; 0 if none."""
        return (
            self.rows * self.step + self.overlap - self.period[0] if self.period[0] else 0,
            self.cols * self.step + self.overlap - self.period[1] if self.period[1] else 0,
        )

    @property
    def levels(self) -> int:
        """Number of wavefront levels, ``2 (rows - 1) + cols``."""
        return 2 * (self.rows - 1) + self.cols

    def level(self, index: int) -> Group:
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

    def groups(self) -> list[Group]:
        """The schedule: groups of independent blocks, placed group after group.

        On a plane these are the levels. On a torus a level of a small grid may hold blocks
        that touch across the wrap; such a level is split, greedily in row order, into groups
        of blocks that do not touch.
        """
        return list(self._groups)

    @cached_property
    def _groups(self) -> tuple[Group, ...]:
        result: list[Group] = []
        for index in range(self.levels):
            rows, cols = self.level(index)
            if not self.wrapped:
                result.append((rows, cols))
                continue
            pending = list(zip(rows.tolist(), cols.tolist(), strict=True))
            while pending:
                taken: list[tuple[int, int]] = []
                for cell in pending:
                    if not any(self._touch(cell, other) for other in taken):
                        taken.append(cell)
                pending = [cell for cell in pending if cell not in taken]
                result.append(
                    (
                        np.array([c[0] for c in taken], dtype=np.intp),
                        np.array([c[1] for c in taken], dtype=np.intp),
                    )
                )
        return tuple(result)

    def _touch(self, a: tuple[int, int], b: tuple[int, int]) -> bool:
        """Whether the footprints of two blocks share a pixel (neighbours, across a wrap too)."""
        return _near(a[0], b[0], self.rows, bool(self.period[0])) and _near(
            a[1], b[1], self.cols, bool(self.period[1])
        )

    @cached_property
    def _order(self) -> NDArray[np.intp]:
        """Index of the group each block is placed in, shape (rows, cols)."""
        order = np.empty((self.rows, self.cols), dtype=np.intp)
        for index, (rows, cols) in enumerate(self._groups):
            order[rows, cols] = index
        return order

    @property
    def placed(self) -> NDArray[np.intp]:
        """Index of the group (:meth:`groups`) each block is placed in, shape (rows, cols),
        read-only."""
        view = self._order.view()
        view.flags.writeable = False
        return view

    def origins(self, rows: NDArray[np.intp], cols: NDArray[np.intp]) -> NDArray[np.intp]:
        """Top-left canvas corner of each block, shape (n, 2) as (y, x)."""
        return np.stack([rows * self.step, cols * self.step], axis=-1)

    def overlap_kind(self, row: int, col: int) -> Overlap:
        """Which sides of block (row, col) overlap blocks placed before it (one block of
        :meth:`overlap_kinds`)."""
        kinds = self.overlap_kinds(np.array([row], dtype=np.intp), np.array([col], dtype=np.intp))
        return Overlap(int(kinds[0]))

    def overlap_kinds(self, rows: NDArray[np.intp], cols: NDArray[np.intp]) -> NDArray[np.uint8]:
        """:meth:`overlap_kind` of many blocks at once.

        Parameters
        ----------
        rows, cols : ndarray of int, shape (n,)
            The blocks.

        Returns
        -------
        ndarray of uint8, shape (n,)
            The :class:`Overlap` flags of each block.
        """
        kinds: NDArray[np.uint8] = self._kinds[
            np.asarray(rows, dtype=np.intp), np.asarray(cols, dtype=np.intp)
        ]
        return kinds

    def cut_across_wrap(self, rows: NDArray[np.intp], cols: NDArray[np.intp]) -> NDArray[np.bool_]:
        """Which blocks a torus cuts on their far sides too (right or bottom, against the
        first column or row across the wrap), shape (n,): the last column's and row's."""
        far: NDArray[np.bool_] = (
            self.overlap_kinds(rows, cols) & np.uint8(Overlap.RIGHT | Overlap.BOTTOM)
        ) > 0
        return far

    @cached_property
    def _kinds(self) -> NDArray[np.uint8]:
        """:meth:`overlap_kinds` of every block, shape (rows, cols) (asked once a level)."""
        rows, cols = (a.reshape(-1) for a in np.indices((self.rows, self.cols), dtype=np.intp))
        order = self._order
        mine = order[rows, cols]
        kinds = np.zeros(rows.shape, dtype=np.uint8)
        sides = (
            (Overlap.LEFT, 0, -1, self.period[1]),
            (Overlap.RIGHT, 0, 1, self.period[1]),
            (Overlap.TOP, -1, 0, self.period[0]),
            (Overlap.BOTTOM, 1, 0, self.period[0]),
        )
        for side, di, dj, wraps in sides:
            i, j = rows + di, cols + dj
            there = (
                np.ones(rows.shape, dtype=bool)
                if wraps
                else (i >= 0) & (i < self.rows) & (j >= 0) & (j < self.cols)
            )
            i, j = i % self.rows, j % self.cols
            # A one-block axis wraps onto the block itself, which is not placed before itself.
            there &= (i != rows) | (j != cols)
            kinds[there & (order[i, j] < mine)] |= np.uint8(side)
        return kinds.reshape(self.rows, self.cols)

    def covered(self, rows: NDArray[np.intp], cols: NDArray[np.intp]) -> NDArray[np.bool_]:
        """Footprint pixels of each block that blocks placed before it wrote: the nonzero
        weights of :meth:`overlap_mask` for each block's :meth:`overlap_kind`.

        Parameters
        ----------
        rows, cols : ndarray of int, shape (n,)
            The blocks.

        Returns
        -------
        ndarray of bool, shape (n, block, block)
        """
        columns, lines = self.overlap_strips(rows, cols)
        covered: NDArray[np.bool_] = columns | lines
        return covered

    def overlap_strips(
        self, rows: NDArray[np.intp], cols: NDArray[np.intp]
    ) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
        """:meth:`covered` as the union of its columns and its rows.

        Parameters
        ----------
        rows, cols : ndarray of int, shape (n,)
            The blocks.

        Returns
        -------
        columns : ndarray of bool, shape (n, 1, block)
            The columns of each block's footprint covered from the left or right.
        lines : ndarray of bool, shape (n, block, 1)
            Its rows covered from above or below; ``columns | lines`` is :meth:`covered`.
        """
        kinds = self.overlap_kinds(rows, cols)[:, None, None]
        wrap_y, wrap_x = self.wrap_overlap
        # The same slices as overlap_mask's.
        near, far_x, far_y = (np.zeros(self.block, dtype=bool) for _ in range(3))
        near[: self.overlap] = True
        far_x[self.block - wrap_x :] = True
        far_y[self.block - wrap_y :] = True

        def has(side: Overlap) -> NDArray[np.bool_]:
            return (kinds & np.uint8(side)) > 0

        columns = (has(Overlap.LEFT) & near) | (has(Overlap.RIGHT) & far_x)
        lines = (has(Overlap.TOP) & near[:, None]) | (has(Overlap.BOTTOM) & far_y[:, None])
        return columns, lines

    def overlap_mask(self, kind: Overlap) -> NDArray[np.float32]:
        """Weights M of the overlap region of a block of this kind, shape (block, block)."""
        mask = np.zeros((self.block, self.block), dtype=np.float32)
        wrap_y, wrap_x = self.wrap_overlap
        if kind.left:
            mask[:, : self.overlap] = 1
        if kind.top:
            mask[: self.overlap, :] = 1
        if kind.right:
            mask[:, self.block - wrap_x :] = 1
        if kind.bottom:
            mask[self.block - wrap_y :, :] = 1
        return mask


def _torus_overlap(size: tuple[int, int], wrap: tuple[bool, bool], block: int, overlap: int) -> int:
    """The overlap of a torus grid: the least one from ``overlap`` up whose wrap overlap is at
    least the overlap itself along every wrapped axis.

    With step s, a side of N pixels wraps over ``s - N mod s + overlap`` pixels (``overlap``
    when s divides N), which is narrower than the other strips when ``0 < N mod s < overlap``:
    a seam cut through one or two pixels shows. Widening the overlap by a pixel or two almost
    always avoids that (the few sizes of tiny blocks where no overlap below block / 2 does keep
    the narrow wrap).
    """
    for candidate in range(overlap, (block - 1) // 2 + 1):
        step = block - candidate
        if all(
            not 0 < side % step < candidate for side, wraps in zip(size, wrap, strict=True) if wraps
        ):
            return candidate
    return overlap


def _near(a: int, b: int, count: int, wraps: bool) -> bool:
    """Whether blocks a and b of one axis overlap: neighbours, or first and last on a torus."""
    distance = abs(a - b)
    if wraps:
        distance = min(distance, count - distance)
    return distance <= 1
