"""Synthesis by the random-quilting variant of the minimum-resistance-cut paper: random blocks
joined by walk cuts.

Every block is drawn at random (no matching, so no cost backend). Its cut toward the left
edge is the minimum-resistance walk over the difference between the block and the left
neighbour's continuation in the source, the cut toward the top edge the same walk against the
upper neighbour's continuation; the old side is filled from those continuations, the corner
from all four blocks, and the pixels near the cuts blended (:mod:`quilting.core.walk`).

The cuts depend only on where the blocks come from, and every position is random, so all the
cuts are traced before anything is written, in large vectorized batches; writing then goes
level by level, since a block blends with what its neighbours wrote.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from quilting.core.compose import gather
from quilting.core.exclusion import CandidateField
from quilting.core.grid import Grid
from quilting.core.layout import LayoutPass
from quilting.core.options import SynthesisOptions
from quilting.core.pixels import compared
from quilting.core.randomness import BlockRandom
from quilting.core.walk import continuation_corners, reflect_gather, walk_cuts

if TYPE_CHECKING:
    from quilting.core.fields import CostBackend
    from quilting.core.progress import Clock, Progress

#: Blocks whose cuts are traced in one vectorized batch (memory: a few arrays of B x B x C).
CUT_BATCH = 256


class WalkPass:
    """One pass of walk-mode synthesis over a plane grid (see the module docstring).

    Has the attributes :func:`quilting.core.synthesis.finish` reads: ``canvas``, ``record``,
    ``seam_total``, ``seam_pixels``, ``backend`` and ``matched`` (False).
    """

    matched = False

    def __init__(
        self,
        source: NDArray[np.float32],
        grid: Grid,
        options: SynthesisOptions,
        backend: CostBackend,
        clock: Clock,
        excluded: NDArray[np.bool_] | None = None,
        weights: NDArray[np.float64] | None = None,
    ) -> None:
        self.source = source
        self.grid = grid
        self.options = options
        self.backend = backend
        self.clock = clock
        self.field = CandidateField.of(source.shape, grid.block, excluded, weights)
        # The walk's resistance: the colour difference, or the luminance difference.
        self.match = compared(source, options.error)
        self.canvas = np.zeros((grid.height, grid.width, source.shape[2]), dtype=np.float32)
        self.record = LayoutPass.empty(grid, feather=options.feather)
        self.seam_total = 0.0
        self.seam_pixels = 0

    def execute(
        self,
        max_batch: int | None,
        progress: Progress | None,
        stage: str = "synthesis",
        span: tuple[float, float] = (0.0, 1.0),
    ) -> None:
        """Draw every block, trace every cut, then write level by level.

        ``progress(fraction, stage)`` is called after each batch of cuts (the first half of
        ``span``) and after each level (the second half).
        """
        low, high = span
        middle = (low + high) / 2
        tick = time.perf_counter()
        self._draw()
        tick = self.clock.add("select", tick)
        grid = self.grid
        rows, cols = np.divmod(np.arange(grid.rows * grid.cols, dtype=np.intp), grid.cols)
        batch = max(1, min(max_batch or CUT_BATCH, CUT_BATCH))
        for start in range(0, rows.size, batch):
            part = slice(start, start + batch)
            self._cut(rows[part], cols[part])
            if progress is not None:
                progress(low + (middle - low) * min(start + batch, rows.size) / rows.size, stage)
        tick = self.clock.add("seams", tick)

        def written(count: int, groups: int) -> None:
            if progress is not None:
                progress(middle + (high - middle) * count / groups, stage)

        self.record.fill_walk(self.source, self.canvas, written)
        self.clock.add("paste", tick)

    def _draw(self) -> None:
        """Each block's source position, drawn with the block's own generator."""
        grid, seed = self.grid, self.options.seed
        chosen = np.array(
            [
                self.field.draw(BlockRandom(seed, 0, i, j))
                for i in range(grid.rows)
                for j in range(grid.cols)
            ],
            dtype=np.intp,
        )
        self.record.positions[:] = self.field.corners(chosen).reshape(grid.rows, grid.cols, 2)

    def _cut(self, rows: NDArray[np.intp], cols: NDArray[np.intp]) -> None:
        """Trace the walk cuts of a batch of blocks toward their left and top edges."""
        grid, record = self.grid, self.record
        block, max_run = grid.block, self.options.max_run
        new = gather(self.match, record.positions[rows, cols].astype(np.intp), block)
        left, top, _ = continuation_corners(record.positions, rows, cols, grid.step)
        for has, corners, target in (
            (cols > 0, left, record.cut_cols),
            (rows > 0, top, record.cut_rows),
        ):
            members = np.flatnonzero(has)
            if not members.size:
                continue
            diff = new[members] - reflect_gather(self.match, corners[members], block)
            resistance = np.einsum("nyxc,nyxc->nyx", diff, diff).astype(np.float64)
            if target is record.cut_rows:  # the top edge's cut is the left edge's, transposed
                resistance = np.ascontiguousarray(resistance.transpose(0, 2, 1))
            cuts = walk_cuts(resistance, max_run=max_run)
            target[rows[members], cols[members]] = cuts.cut_cols
            self.seam_total += float(cuts.cost.sum())
            self.seam_pixels += int(cuts.pixels.sum())
