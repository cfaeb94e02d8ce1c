"""The covering grid and the wavefront schedule."""

from __future__ import annotations

import numpy as np
import pytest

from quilting.core.grid import Grid


@pytest.mark.parametrize(
    "height,width,block,overlap",
    [(1, 1, 48, 8), (333, 517, 48, 8), (100, 100, 10, 4), (48, 49, 48, 8)],
)
def test_covering_grid_is_the_smallest_that_covers(height, width, block, overlap) -> None:
    g = Grid.covering(height, width, block, overlap)
    assert g.height >= height and g.width >= width
    if g.rows > 1:
        assert (g.rows - 1) * g.step + overlap < height
    if g.cols > 1:
        assert (g.cols - 1) * g.step + overlap < width


def test_levels_cover_every_block_once_and_respect_dependencies() -> None:
    g = Grid(block=12, overlap=3, rows=6, cols=7)
    level_of = np.full((g.rows, g.cols), -1)
    for level in range(g.levels):
        rows, cols = g.level(level)
        assert np.all(level_of[rows, cols] == -1)
        level_of[rows, cols] = level
        # Blocks of one level never overlap each other (overlap < block / 2).
        corners = g.origins(rows, cols)
        for a in range(len(corners)):
            for b in range(a + 1, len(corners)):
                dy, dx = np.abs(corners[a] - corners[b])
                assert dy >= g.block or dx >= g.block
    assert np.all(level_of >= 0)
    for i in range(g.rows):
        for j in range(g.cols):
            for di, dj in ((0, -1), (-1, -1), (-1, 0), (-1, 1)):
                if 0 <= i + di < g.rows and 0 <= j + dj < g.cols:
                    assert level_of[i + di, j + dj] < level_of[i, j]
