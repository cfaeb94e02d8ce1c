"""The repetition measure on layouts whose answer is known by construction."""

from __future__ import annotations

import numpy as np

from quilting.core.grid import Grid
from quilting.core.layout import Layout, LayoutPass
from quilting.core.stats import ownership, repetition


def _layout(
    positions: np.ndarray, grid: Grid, source: tuple[int, int], out: tuple[int, int]
) -> Layout:
    record = LayoutPass.empty(grid)
    record.positions[:] = positions
    return Layout(source_shape=source, output_shape=out, passes=[record])


def test_verbatim_layout_is_one_whole_copy() -> None:
    # Every block placed at its own output position: the output is the texture itself.
    grid = Grid.covering(64, 64, 16, 4)
    rows, cols = np.divmod(np.arange(grid.rows * grid.cols), grid.cols)
    positions = grid.origins(rows, cols).reshape(grid.rows, grid.cols, 2)
    layout = _layout(positions, grid, (grid.height, grid.width), (64, 64))
    largest, unused = repetition(layout)
    assert largest == 64 * 64 / (grid.height * grid.width)
    source_rows, source_cols = grid.height, grid.width
    used_share = 64 * 64 / (source_rows * source_cols)
    assert np.isclose(unused, 1 - used_share)


def test_two_separate_copies_are_not_merged() -> None:
    # Left half verbatim, right half verbatim from another place: two copies, not one.
    grid = Grid(block=10, overlap=2, rows=1, cols=4)
    positions = np.array([[[0, 0], [0, 8], [20, 0], [20, 8]]])
    layout = _layout(positions, grid, (40, 40), (10, 34))
    own = ownership(layout)
    assert set(np.unique(own.owner).tolist()) == {0, 1, 2, 3}
    largest, unused = repetition(layout)
    left_pixels = np.count_nonzero(own.owner <= 1)
    right_pixels = np.count_nonzero(own.owner >= 2)
    assert largest == max(left_pixels, right_pixels) / (40 * 40)
    assert np.isclose(unused, 1 - (10 * 18 + 10 * 16) / (40 * 40))


def test_random_layout_has_small_copies() -> None:
    grid = Grid(block=12, overlap=2, rows=5, cols=5)
    rng = np.random.default_rng(0)
    positions = rng.integers(0, 100 - 12, size=(5, 5, 2))
    largest, _ = repetition(_layout(positions, grid, (100, 100), (52, 52)))
    assert largest <= 12 * 12 / (100 * 100)
