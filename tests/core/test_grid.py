"""The covering grid and the wavefront schedule."""

from __future__ import annotations

import numpy as np
import pytest

from quilting.core.grid import Grid, Overlap


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


# --------------------------------------------------------------------------------------------
# The vectorised overlap kinds and covered pixels against the per-block ones
# --------------------------------------------------------------------------------------------


def _grids() -> list[Grid]:
    """Plane grids and tori wrapped along both axes or one, from one block to many, with
    widened torus overlaps and wrap overlaps from 1 to the step."""
    grids = []
    for height, width, block, overlap in [
        (48, 48, 48, 8),
        (96, 200, 48, 8),
        (333, 517, 32, 5),
        (200, 130, 32, 5),
        (100, 100, 10, 4),
        (64, 25, 12, 3),
        (37, 12, 12, 2),
    ]:
        for wrap in [(False, False), (True, True), (True, False), (False, True)]:
            grids.append(Grid.covering(height, width, block, overlap, wrap))
    grids += [
        Grid(block=12, overlap=3, rows=1, cols=1, period=(11, 0)),
        Grid(block=12, overlap=3, rows=1, cols=3, period=(11, 28)),
        Grid(block=12, overlap=3, rows=2, cols=1, period=(20, 0)),
        Grid(block=6, overlap=0, rows=3, cols=4),
    ]
    return grids


def _reference_kind(grid: Grid, row: int, col: int) -> Overlap:
    """The per-block loop the vectorised version replaced: each neighbour placed before."""
    order = grid.placed
    kind = Overlap.NONE
    sides = (
        (Overlap.LEFT, row, col - 1, grid.period[1]),
        (Overlap.RIGHT, row, col + 1, grid.period[1]),
        (Overlap.TOP, row - 1, col, grid.period[0]),
        (Overlap.BOTTOM, row + 1, col, grid.period[0]),
    )
    for side, i, j, wraps in sides:
        if not wraps and not (0 <= i < grid.rows and 0 <= j < grid.cols):
            continue
        i, j = i % grid.rows, j % grid.cols
        if (i, j) != (row, col) and order[i, j] < order[row, col]:
            kind |= side
    return kind


def _reference_covered(grid: Grid, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """The per-block version it replaced: each block's overlap mask, one by one."""
    return np.stack(
        [
            grid.overlap_mask(_reference_kind(grid, i, j)) > 0
            for i, j in zip(rows, cols, strict=True)
        ]
    )


@pytest.mark.parametrize("grid", _grids(), ids=str)
def test_vectorised_overlap_kinds_and_covered_equal_the_per_block_ones(grid: Grid) -> None:
    rows, cols = np.divmod(np.arange(grid.rows * grid.cols), grid.cols)
    kinds = grid.overlap_kinds(rows, cols)
    assert kinds.dtype == np.uint8
    assert kinds.tolist() == [
        int(_reference_kind(grid, i, j)) for i, j in zip(rows, cols, strict=True)
    ]
    assert [grid.overlap_kind(i, j) for i, j in zip(rows, cols, strict=True)] == [
        _reference_kind(grid, i, j) for i, j in zip(rows, cols, strict=True)
    ]
    np.testing.assert_array_equal(grid.covered(rows, cols), _reference_covered(grid, rows, cols))
    columns, lines = grid.overlap_strips(rows, cols)
    assert columns.shape == (rows.size, 1, grid.block) and lines.shape == (rows.size, grid.block, 1)
    # In any order and any subset, a group of the schedule too.
    for group_rows, group_cols in grid.groups()[:5]:
        if not group_rows.size:
            continue  # a level of a one-column plane may be empty
        np.testing.assert_array_equal(
            grid.covered(group_rows[::-1], group_cols[::-1]),
            _reference_covered(grid, group_rows[::-1], group_cols[::-1]),
        )
    assert grid.covered(rows[:0], cols[:0]).shape == (0, grid.block, grid.block)


def test_placed_is_the_group_of_each_block_read_only() -> None:
    grid = Grid.covering(96, 200, 48, 8, (True, True))
    placed = grid.placed
    for index, (rows, cols) in enumerate(grid.groups()):
        assert (placed[rows, cols] == index).all()
    with pytest.raises(ValueError):
        placed[0, 0] = 1


@pytest.mark.parametrize("wrap", [(False, False), (True, False), (False, True), (True, True)])
def test_only_the_last_row_and_column_of_a_torus_are_cut_across_the_wrap(wrap) -> None:
    grid = Grid.covering(200, 240, 48, 8, wrap)
    rows, cols = (a.reshape(-1) for a in np.indices((grid.rows, grid.cols), dtype=np.intp))
    far = grid.cut_across_wrap(rows, cols)
    expected = (wrap[0] & (rows == grid.rows - 1)) | (wrap[1] & (cols == grid.cols - 1))
    assert far.tolist() == expected.tolist()
