"""The repetition measure on layouts whose answer is known by construction."""

from __future__ import annotations

import numpy as np
import pytest

from quilting.core import stats
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


# --------------------------------------------------------------------------------------------
# The banded computation against the whole-image one it replaced
# --------------------------------------------------------------------------------------------


def _reference_repetition(layout: Layout) -> tuple[float, float, set[tuple[int, int]]]:
    """Whole-output version: every pixel's source coordinates at once (the oracle); also the
    set of block pairs found to continue a copy."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    own, source = _reference_sources(layout)
    owner = own.owner
    blocks = own.offsets.shape[0]
    src_h, src_w = layout.source_shape
    period = layout.passes[-1].grid.period

    pairs = []
    for axis in (0, 1):
        step = np.zeros(2, dtype=np.int64)
        step[axis] = 1
        if period[axis]:
            after, after_source = np.roll(owner, -1, axis), np.roll(source, -1, axis)
            here, here_source = owner, source
        else:
            cut, nxt = [slice(None)] * 2, [slice(None)] * 2
            cut[axis], nxt[axis] = slice(None, -1), slice(1, None)
            here, after = owner[tuple(cut)], owner[tuple(nxt)]
            here_source, after_source = source[tuple(cut)], source[tuple(nxt)]
        boundary = here != after
        same = np.all(after_source[boundary] - here_source[boundary] == step, axis=1)
        pairs.append(np.stack([here[boundary][same], after[boundary][same]], axis=1))
    edges = np.concatenate(pairs)
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(blocks, blocks))
    _, component = connected_components(graph, directed=False)
    pixels = np.bincount(owner.ravel(), minlength=blocks)
    used = np.zeros((src_h, src_w), dtype=bool)
    used[source[..., 0], source[..., 1]] = True
    largest = float(np.bincount(component, weights=pixels).max())
    found = {(int(a), int(b)) for a, b in edges}
    return largest / (src_h * src_w), 1.0 - float(used.mean()), found


def _reference_sources(layout: Layout) -> tuple[stats.Ownership, np.ndarray]:
    """The ownership, and every output pixel's source (y, x), shape (H, W, 2): wrapped and
    folded back pixel by pixel."""
    own = ownership(layout)
    owner = own.owner
    periods = np.concatenate(
        [np.tile(np.asarray(p.grid.period), (p.grid.rows * p.grid.cols, 1)) for p in layout.passes]
    )
    height, width = owner.shape
    source = np.empty((height, width, 2), dtype=np.int64)
    lines = (np.arange(height)[:, None], np.arange(width)[None, :])
    for axis, size in enumerate(layout.source_shape):
        corner = own.corners[:, axis][owner]
        coordinate = lines[axis] + own.offsets[:, axis][owner]
        coordinate = coordinate + np.where(lines[axis] < corner, periods[:, axis][owner], 0)
        fold = max(2 * (size - 1), 1)
        coordinate %= fold
        source[..., axis] = np.minimum(coordinate, fold - coordinate)
    return own, source


def _results() -> list[tuple[str, Layout]]:
    import quilting

    rng = np.random.default_rng(11)
    # A texture with repeats in it, so that verbatim copies across block boundaries happen.
    tile = (rng.random((24, 24, 3)) * 255).astype(np.uint8)
    texture = np.tile(tile, (3, 3, 1))
    cases = [
        ("cut", {}),
        ("bare rule", {"min_candidates": 1, "tolerance": 0.0}),
        ("tileable both", {"tileable": "both"}),
        ("tileable x", {"tileable": "x"}),
        ("tileable y", {"tileable": "y"}),
        ("walk", {"mode": "walk"}),
        ("random", {"mode": "random"}),
    ]
    found = [
        (name, quilting.synthesize(texture, (83, 97), block=18, seed=3, **kw).layout)
        for name, kw in cases
    ]
    target = (rng.random((70, 60)) * 255).astype(np.uint8)
    found.append(("transfer", quilting.transfer(texture, target, block=15, iterations=2).layout))
    return found


@pytest.mark.parametrize("band_pixels", [1, 97, 500, 1 << 20])
def test_banded_repetition_equals_the_whole_image_computation(
    monkeypatch: pytest.MonkeyPatch, band_pixels: int
) -> None:
    monkeypatch.setattr(stats, "BAND_PIXELS", band_pixels)  # 1: a band of one row
    largest_seen = 0.0
    for name, layout in _results():
        got = repetition(layout)
        largest, unused, want_pairs = _reference_repetition(layout)
        assert got == (largest, unused), name
        pairs = {(int(a), int(b)) for a, b in stats.copy_pairs(layout)[1]}
        assert pairs == want_pairs, name
        largest_seen = max(largest_seen, got[0])
    assert largest_seen > 0.05  # some case has copies spanning blocks: edges were followed


# --------------------------------------------------------------------------------------------
# The cell-by-cell ownership of plain grids against pasting block by block
# --------------------------------------------------------------------------------------------


def _pasted_owner(layout: Layout) -> np.ndarray:
    """The ownership map as :meth:`Layout.compose` pastes it, block by block (the oracle)."""
    first = np.cumsum([0] + [p.grid.rows * p.grid.cols for p in layout.passes])

    def ids(index: int, p: LayoutPass, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        return (first[index] + rows * p.grid.cols + cols).astype(np.uint16)[:, None, None, None]

    return layout.compose(1, np.uint16, ids, fill=np.iinfo(np.uint16).max)[..., 0]


def _random_plain_layout(rng: np.random.Generator, passes: int = 1) -> Layout:
    """A plain layout with arbitrary cuts inside the overlap (not only DP paths), overlaps
    from 0 to block / 2, cropped outputs, and blocks that often continue their neighbour's
    translation (so that copies span blocks); earlier passes under the last one."""
    block = int(rng.integers(1, 21))
    overlap = int(rng.integers(0, block // 2 + 1))
    grid = Grid(
        block=block, overlap=overlap, rows=int(rng.integers(1, 6)), cols=int(rng.integers(1, 6))
    )
    out = (
        int(rng.integers(max(1, grid.height - grid.step + 1), grid.height + 1)),
        int(rng.integers(max(1, grid.width - grid.step + 1), grid.width + 1)),
    )
    source = (grid.height + 4, grid.width + 3)
    records = []
    for index in range(passes):
        g = grid if index == passes - 1 else Grid(block + 2, overlap, grid.rows, grid.cols)
        record = LayoutPass.empty(g)
        record.cut_cols[:] = rng.integers(0, g.overlap + 1, record.cut_cols.shape)
        record.cut_rows[:] = rng.integers(0, g.overlap + 1, record.cut_rows.shape)
        record.cut_cols[:, 0] = 0
        record.cut_rows[0] = 0
        # Verbatim (its own output position) or shifted by one of three steps: neighbours
        # continue each other's translation half of the time.
        rows, cols = np.divmod(np.arange(g.rows * g.cols), g.cols)
        origins = g.origins(rows, cols).reshape(g.rows, g.cols, 2)
        shift = rng.integers(0, 4, size=(g.rows, g.cols, 1)) * (
            rng.random((g.rows, g.cols, 1)) < 0.5
        )
        record.positions[:] = np.minimum(origins + shift, np.array(source) - g.block)
        records.append(record)
    return Layout(source_shape=source, output_shape=out, passes=records)


@pytest.mark.parametrize("seed", range(6))
def test_plain_ownership_equals_pasting_block_by_block(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(60):
        layout = _random_plain_layout(rng, passes=1 + int(rng.integers(0, 2)))
        assert stats._plain_cover(layout.passes[-1])
        np.testing.assert_array_equal(ownership(layout).owner, _pasted_owner(layout))


def test_the_engine_layouts_take_the_plain_path_where_they_can() -> None:
    plain = {name: stats._plain_cover(layout.passes[-1]) for name, layout in _results()}
    assert plain == {
        "cut": True,
        "bare rule": True,
        "tileable both": False,
        "tileable x": False,
        "tileable y": False,
        "walk": False,
        "random": True,
        "transfer": True,
    }
    for name, layout in _results():
        np.testing.assert_array_equal(ownership(layout).owner, _pasted_owner(layout), name)


def test_cuts_past_the_overlap_are_pasted() -> None:
    grid = Grid(block=10, overlap=3, rows=2, cols=2)
    record = LayoutPass.empty(grid)
    record.cut_cols[0, 1, :] = 5  # wider than the overlap: not a plain pass
    layout = Layout(source_shape=(30, 30), output_shape=(17, 17), passes=[record])
    assert not stats._plain_cover(record)
    np.testing.assert_array_equal(ownership(layout).owner, _pasted_owner(layout))


@pytest.mark.parametrize("band_pixels", [1, 37, 1 << 18])
def test_plain_repetition_equals_the_whole_image_computation(
    monkeypatch: pytest.MonkeyPatch, band_pixels: int
) -> None:
    monkeypatch.setattr(stats, "BAND_PIXELS", band_pixels)
    rng = np.random.default_rng(5)
    spanning = 0
    for _ in range(40):
        layout = _random_plain_layout(rng, passes=1 + int(rng.integers(0, 2)))
        largest, unused, want_pairs = _reference_repetition(layout)
        assert repetition(layout) == (largest, unused)
        pairs = {(int(a), int(b)) for a, b in stats.copy_pairs(layout)[1]}
        assert pairs == want_pairs
        spanning += bool(pairs)
    assert spanning > 10  # copies across blocks were found and followed


# --------------------------------------------------------------------------------------------
# The cell-by-cell ownership of tori and walk passes against pasting block by block
# --------------------------------------------------------------------------------------------


def _random_cell_layout(
    rng: np.random.Generator, walk: bool, passes: int = 1, holes: bool = True
) -> Layout:
    """A torus (both axes, one, or none) or walk layout with arbitrary cuts anywhere in the
    block (past the overlap, far cuts that leave pixels to no block), overlaps from 0 to block
    / 2 (sometimes past it: the pasted fallback), and positions that often continue their
    neighbour's translation, near the source's edge so that walk continuations fold back.
    ``holes=False``: the first column and row cut nothing and far cuts are rare, so that
    (nearly always) every pixel has a block."""
    block = int(rng.integers(2, 17))
    overlap = int(rng.integers(0, block // 2 + 1))
    if rng.random() < 0.1:
        overlap = int(rng.integers(block // 2, block))  # 2 O > B: pasted block by block
    wrap = (False, False) if walk else (bool(rng.random() < 0.6), bool(rng.random() < 0.6))
    size = (int(rng.integers(block, 5 * block)), int(rng.integers(block, 5 * block)))
    grid = Grid.covering(*size, block, overlap, wrap)
    out = (
        (
            size[0]
            if wrap[0]
            else int(rng.integers(max(1, grid.height - grid.step + 1), grid.height + 1))
        ),
        (
            size[1]
            if wrap[1]
            else int(rng.integers(max(1, grid.width - grid.step + 1), grid.width + 1))
        ),
    )
    # Sometimes larger than the output, so that the unused share tells which pixels show.
    extra = int(rng.integers(0, 5)) if rng.random() < 0.5 else int(rng.integers(0, 3 * block))
    source = (grid.height + extra, grid.width + int(rng.integers(0, 5)))
    records = []
    for index in range(passes):
        g = grid
        if index < passes - 1:  # an earlier pass, plain, under the last one
            g = Grid(block + 1, min(overlap, (block + 1) // 2), grid.rows, grid.cols)
            source = (max(source[0], g.height), max(source[1], g.width))
        record = LayoutPass.empty(
            g, feather=int(rng.integers(0, 4)) if walk and index == passes - 1 else None
        )
        shape = record.cut_cols.shape
        wide = rng.random() < 0.5
        top = g.block + 1 if wide else g.overlap + 1
        record.cut_cols[:] = rng.integers(0, top, shape)
        record.cut_rows[:] = rng.integers(0, top, shape)
        if not holes:
            record.cut_cols[:, 0] = 0
            record.cut_rows[0] = 0
        if g.wrapped and index == passes - 1:
            far = 0.3 if holes else 0.01
            cut = rng.integers(0, g.block + 1, shape)
            record.cut_right[:] = np.where(rng.random(shape) < far, cut, g.block)
            record.cut_bottom[:] = np.where(rng.random(shape) < far, cut, g.block)
        rows, cols = np.divmod(np.arange(g.rows * g.cols), g.cols)
        origins = g.origins(rows, cols).reshape(g.rows, g.cols, 2) % np.maximum(
            np.array(source) - g.block + 1, 1
        )
        shift = rng.integers(0, 4, size=(g.rows, g.cols, 1)) * (
            rng.random((g.rows, g.cols, 1)) < 0.5
        )
        record.positions[:] = np.minimum(origins + shift, np.array(source) - g.block)
        # Some anywhere, the source's far edge too: a walk continuation there folds back.
        anywhere = rng.random((g.rows, g.cols)) < 0.3
        record.positions[anywhere] = rng.integers(
            0, np.array(source) - g.block + 1, (int(anywhere.sum()), 2)
        )
        records.append(record)
    return Layout(source_shape=source, output_shape=out, passes=records)


@pytest.mark.parametrize("walk", [False, True], ids=["torus", "walk"])
@pytest.mark.parametrize("seed", range(5))
def test_cell_ownership_equals_pasting_block_by_block(walk: bool, seed: int) -> None:
    rng = np.random.default_rng(100 * seed + walk)
    kinds = set()
    for _ in range(60):
        layout = _random_cell_layout(rng, walk, passes=1 + int(rng.integers(0, 2)))
        last = layout.passes[-1]
        assert not stats._plain_cover(last) or not (walk or last.grid.wrapped)
        kinds.add((stats._cell_cover(last), last.grid.period[0] > 0, last.grid.period[1] > 0))
        np.testing.assert_array_equal(ownership(layout).owner, _pasted_owner(layout))
    if not walk:  # every kind of torus met, and the fallback
        assert {(True, True, True), (True, True, False), (True, False, True)} <= kinds
    assert any(not cover for cover, *_ in kinds)


@pytest.mark.parametrize("walk", [False, True], ids=["torus", "walk"])
def test_cell_repetition_equals_the_whole_image_computation(walk: bool) -> None:
    rng = np.random.default_rng(7 + walk)
    spanning = tested = 0
    for _ in range(80):
        layout = _random_cell_layout(rng, walk, 1 + int(rng.integers(0, 2)), holes=False)
        owner = _pasted_owner(layout)
        np.testing.assert_array_equal(ownership(layout).owner, owner)
        if (owner == np.iinfo(np.uint16).max).any():
            continue  # pixels of no block (random far cuts): no repetition to measure
        tested += 1
        largest, unused, want_pairs = _reference_repetition(layout)
        assert repetition(layout) == (largest, unused)
        _, _, used, _ = stats.copy_pairs(layout)
        pairs = {(int(a), int(b)) for a, b in stats.copy_pairs(layout)[1]}
        assert pairs == want_pairs
        source = _reference_sources(layout)[1]
        want_used = np.zeros(layout.source_shape, dtype=bool)
        want_used[source[..., 0], source[..., 1]] = True
        np.testing.assert_array_equal(used, want_used)
        spanning += bool(pairs)
    assert tested > 30 and spanning > 10


def test_a_pass_of_holes_shows_the_pass_below() -> None:
    # Far cuts of 0 on a torus: the last column's blocks write nothing across the wrap, and
    # where nothing of the last pass is, the pass below shows.
    below = LayoutPass.empty(Grid(block=14, overlap=4, rows=4, cols=4))
    grid = Grid.covering(40, 40, 12, 3, (True, True))
    record = LayoutPass.empty(grid)
    record.cut_right[:] = 0
    record.cut_bottom[:, :, :5] = 0
    layout = Layout(source_shape=(60, 60), output_shape=(40, 40), passes=[below, record])
    assert stats._cell_cover(record)
    owner = ownership(layout).owner
    np.testing.assert_array_equal(owner, _pasted_owner(layout))
    assert (owner < 16).any()  # some pixels of the pass below
