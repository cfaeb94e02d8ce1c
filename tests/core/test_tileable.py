"""Tileable output (issue 6): the grid wraps on a torus, so the result repeats with no seam.

Checked from the outside on the shared textures (the error across the wrap of a 2x2 tiling is
no larger than inside, the join lines are smooth), the exact output size, the errors, and
from the inside: the torus schedule (masks see every pixel already painted, groups never
touch), the far-side cuts, the layout (version 2, period, exact re-rendering) and that the
result depends on the seed only.
"""

from __future__ import annotations

import functools
import itertools
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from numpy.typing import NDArray
from textures import backends, texture

import quilting
from quilting import InvalidParameterError, Layout, LayoutError, apply_layout
from quilting.api import check_inputs
from quilting.core.exclusion import excluded_pixels
from quilting.core.grid import Grid, _torus_overlap
from quilting.core.seams import far_side_cuts, minimum_error_cuts, new_block_mask, straight_cuts
from quilting.costs.fft import FFTBackend

TEXTURES = ("gravel", "brick", "grass", "wood", "hubble")
WRAPS = [(False, False), (True, False), (False, True), (True, True)]
WRAP_IDS = ["plane", "y", "x", "both"]
STARS = (((120, 120, 120), (255, 255, 255)),)  # hashable: results are cached


# --- helpers --------------------------------------------------------------------------------


@functools.cache
def synth(name: str, size: tuple[int, int], seed: int, **options: Any) -> quilting.Result:
    """One synthesis with block 32, cached: several tests look at the same results."""
    return quilting.synthesize(texture(name), size, block=32, seed=seed, **options)


def owner_map(layout: Layout) -> NDArray[np.int32]:
    """Index (row * cols + col) of the block each output pixel finally comes from."""

    def ids(_: int, p: Any, rows: NDArray[np.intp], cols: NDArray[np.intp]) -> NDArray[np.int32]:
        return (rows * p.grid.cols + cols).astype(np.int32)[:, None, None, None]

    owner: NDArray[np.int32] = layout.compose(1, np.int32, ids, fill=-1)[..., 0]
    return owner


def seam_errors(result: quilting.Result) -> tuple[float, int, float, int]:
    """Squared differences (summed over channels, 8-bit units) of 4-neighbour pixel pairs with
    different owners on the torus (the joins of a 2x2 tiling included).

    Returns the sum and count over *wrap* pairs (owners in the last and first block column for
    horizontal pairs, last and first block row for vertical ones), then over the other pairs.
    """
    image = result.image.astype(np.float64)
    if image.ndim == 2:
        image = image[..., None]
    owner = owner_map(result.layout)
    assert (owner >= 0).all()
    grid = result.layout.passes[0].grid
    block_row, block_col = np.divmod(owner, grid.cols)
    sums = {True: 0.0, False: 0.0}
    counts = {True: 0, False: 0}
    for axis, index, last in ((1, block_col, grid.cols - 1), (0, block_row, grid.rows - 1)):
        other = np.roll(owner, -1, axis=axis)
        other_index = np.roll(index, -1, axis=axis)
        step = ((image - np.roll(image, -1, axis=axis)) ** 2).sum(axis=-1)
        boundary = owner != other
        across = ((index == last) & (other_index == 0)) | ((index == 0) & (other_index == last))
        for wrap in (True, False):
            pairs = boundary & (across if wrap else ~across)
            sums[wrap] += float(step[pairs].sum())
            counts[wrap] += int(pairs.sum())
    return sums[True], counts[True], sums[False], counts[False]


def join_error(image: NDArray[Any]) -> tuple[float, int]:
    """Sum and count of squared differences across the join lines of a 2x2 tiling of the image:
    its last column against its first and its last row against its first."""
    pixels = image.astype(np.float64)
    if pixels.ndim == 2:
        pixels = pixels[..., None]
    columns = ((pixels[:, -1] - pixels[:, 0]) ** 2).sum(axis=-1)
    rows = ((pixels[-1] - pixels[0]) ** 2).sum(axis=-1)
    return float(columns.sum() + rows.sum()), columns.size + rows.size


def footprint(grid: Grid, row: int, col: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Canvas rows and columns under block (row, col), wrapped along the torus axes."""
    ys = row * grid.step + np.arange(grid.block)
    xs = col * grid.step + np.arange(grid.block)
    if grid.period[0]:
        ys %= grid.period[0]
    if grid.period[1]:
        xs %= grid.period[1]
    assert ys.max() < grid.height and xs.max() < grid.width
    return ys, xs


def torus_grids() -> list[Grid]:
    """Grids of 2..7 x 2..7 blocks, every wrap combination, wrap strips from 1 pixel (the narrow
    fallback) through the overlap to the step."""
    block, overlap = 12, 3
    step = block - overlap
    grids = []
    for rows, cols in itertools.product(range(2, 8), range(2, 8)):
        for wrap in WRAPS:
            for strip in (1, overlap, step):
                period = (
                    rows * step + overlap - strip if wrap[0] else 0,
                    cols * step + overlap - strip if wrap[1] else 0,
                )
                grids.append(Grid(block, overlap, rows, cols, period))
    return grids


def covering_grids() -> list[Grid]:
    """Grids that :meth:`Grid.covering` makes for many sizes, including widened overlaps."""
    grids = []
    for block, overlap in ((8, 1), (12, 2), (16, 5)):
        for height, width in itertools.product(range(block, 6 * block, 7), repeat=2):
            for wrap in WRAPS[1:]:
                grids.append(Grid.covering(height, width, block, overlap, wrap))
    return grids


# --- the seam across the wrap ---------------------------------------------------------------


@pytest.mark.parametrize("blend", ["none", "poisson"])
@pytest.mark.parametrize("name", TEXTURES)
def test_wrap_seams_are_no_worse_than_inner_seams(name: str, blend: str) -> None:
    """Blended, the wrap blocks are blended over their whole footprint, far-side cuts
    included: within 10 % of the inner seams (grass 1.05; over their cells only, the wrap
    seams kept their steps: 1.1 to 1.9 times the inner seams' on gravel, grass, wood, hubble)."""
    wrap_sum = inner_sum = 0.0
    wrap_count = inner_count = 0
    for size in ((256, 256), (300, 260)):
        for seed in range(4):
            a, b, c, d = seam_errors(synth(name, size, seed, tileable="both", blend=blend))
            wrap_sum, wrap_count = wrap_sum + a, wrap_count + b
            inner_sum, inner_count = inner_sum + c, inner_count + d
    assert wrap_count > 0 and inner_count > 0
    wrap_mean, inner_mean = wrap_sum / wrap_count, inner_sum / inner_count
    assert wrap_mean <= (1.0 if blend == "none" else 1.1) * inner_mean, (
        name,
        wrap_mean,
        inner_mean,
    )


def test_a_plane_result_has_a_visible_wrap_seam() -> None:
    """The measure can fail: without tileable, the 2x2 joins are far worse than the seams."""
    wrap_sum, wrap_count, inner_sum, inner_count = seam_errors(synth("gravel", (256, 256), 0))
    assert wrap_sum / wrap_count > 1.5 * inner_sum / inner_count


@pytest.mark.parametrize("name", TEXTURES)
def test_the_join_lines_of_a_tiling_are_smooth(name: str) -> None:
    tiled = plain = 0.0
    for seed in range(4):
        tiled += join_error(synth(name, (256, 256), seed, tileable="both").image)[0]
        plain += join_error(synth(name, (256, 256), seed).image)[0]
    assert tiled < 0.5 * plain, (name, tiled, plain)


@pytest.mark.parametrize("mode", ["overlap", "random"])
def test_other_modes_tile_and_re_render(mode: str) -> None:
    tiled = plain = 0.0
    for name, seed in itertools.product(("gravel", "wood", "brick"), range(3)):
        result = synth(name, (130, 150), seed, tileable="both", mode=mode)
        tiled += join_error(result.image)[0]
        plain += join_error(synth(name, (130, 150), seed, mode=mode).image)[0]
        layout = Layout.from_json(result.layout.to_json())
        assert np.array_equal(apply_layout(layout, texture(name)), result.image)
    assert tiled < 0.5 * plain, (mode, tiled, plain)


@pytest.mark.parametrize(("tileable", "axis"), [("x", 1), ("y", 0)])
def test_one_axis_tiles_and_the_other_does_not(tileable: str, axis: int) -> None:
    joins = {}
    for which in ("tiled", "plain"):
        for seed in range(3):
            options = {"tileable": tileable} if which == "tiled" else {}
            image = synth("gravel", (120, 140), seed, **options).image.astype(np.float64)
            # The join along the tiled axis, and the one along the other axis.
            along = np.take(image, -1, axis=axis) - np.take(image, 0, axis=axis)
            across = np.take(image, -1, axis=1 - axis) - np.take(image, 0, axis=1 - axis)
            joins[which, "along"] = joins.get((which, "along"), 0.0) + float((along**2).mean())
            joins[which, "across"] = joins.get((which, "across"), 0.0) + float((across**2).mean())
    assert joins["tiled", "along"] < 0.5 * joins["plain", "along"], joins
    # The other axis is a plane: its join is as bad as in a plain result.
    assert joins["tiled", "across"] > 0.5 * joins["plain", "across"], joins


# --- size and errors ------------------------------------------------------------------------


def _widened_size(block: int, overlap: int) -> int:
    """A side where the torus grid must widen the overlap (found with _torus_overlap)."""
    for side in range(block, 10 * block):
        if _torus_overlap((side, side), (True, True), block, overlap) > overlap:
            return side
    raise AssertionError("no size widens the overlap")


@pytest.mark.parametrize(
    ("size", "tileable"),
    [
        ((101, 77), "both"),
        ((32, 33), "both"),
        ((64, 99), "x"),
        ((99, 64), "y"),
        ((10, 70), "x"),  # the plane axis may be shorter than the block
        ((70, 7), "y"),
    ],
)
def test_output_has_exactly_the_requested_size(size: tuple[int, int], tileable: str) -> None:
    result = synth("wood", size, 1, tileable=tileable)
    assert result.image.shape == (*size, 3)
    assert result.image.dtype == np.uint8
    assert result.layout.output_shape == size
    grid = result.layout.passes[0].grid
    wraps = (tileable in ("both", "y"), tileable in ("both", "x"))
    assert grid.period == tuple(s if w else 0 for s, w in zip(size, wraps, strict=True))
    if wraps[0]:
        assert grid.height == size[0]
    if wraps[1]:
        assert grid.width == size[1]


@pytest.mark.parametrize("tileable", ["both", "x", "y"])
def test_sizes_that_widen_the_overlap(tileable: str) -> None:
    block, overlap = 32, max(1, 32 // 6)
    side = _widened_size(block, overlap)
    size = {"both": (side, side), "x": (50, side), "y": (side, 50)}[tileable]
    wraps = (tileable in ("both", "y"), tileable in ("both", "x"))
    expected = _torus_overlap(size, wraps, block, overlap)
    assert expected > overlap
    result = synth("gravel", size, 2, tileable=tileable)
    assert result.image.shape == size
    grid = result.layout.passes[0].grid
    assert grid.overlap == expected
    for wrapped, strip in zip(wraps, grid.wrap_overlap, strict=True):
        if wrapped:
            assert grid.overlap <= strip <= grid.step
        else:
            assert strip == 0
    assert result.layout.meta["overlap"] == grid.overlap
    assert np.array_equal(apply_layout(result.layout, texture("gravel")), result.image)
    # The plain grid of the same size, for contrast, would wrap over a narrower strip.
    plain = Grid.covering(*size, block, overlap)
    for wrapped, count, length in zip(wraps, (plain.rows, plain.cols), size, strict=True):
        if wrapped:
            assert 0 < length % (block - overlap) < overlap, (count, length)


@pytest.mark.parametrize(
    ("size", "tileable"),
    [((31, 64), "both"), ((64, 31), "both"), ((64, 20), "x"), ((20, 64), "y"), ((1, 1), "both")],
)
def test_a_tileable_side_shorter_than_the_block_is_refused(
    size: tuple[int, int], tileable: str
) -> None:
    with pytest.raises(InvalidParameterError) as caught:
        quilting.synthesize(texture("gravel"), size, block=32, tileable=tileable)
    assert caught.value.parameter == "size"


def test_submission_check_refuses_a_short_tileable_side() -> None:
    gravel = texture("gravel")
    options = quilting.SynthesisOptions(block=32, tileable="x")
    check_inputs(options, gravel, size=(20, 64))  # the plane axis may be short
    with pytest.raises(InvalidParameterError) as caught:
        check_inputs(options, gravel, size=(64, 20))
    assert caught.value.parameter == "size"


def test_tileable_walk_is_refused() -> None:
    with pytest.raises(InvalidParameterError) as caught:
        quilting.synthesize(texture("gravel"), (64, 64), block=32, tileable="both", mode="walk")
    assert caught.value.parameter == "tileable"


def test_an_unknown_tileable_value_is_refused() -> None:
    with pytest.raises(InvalidParameterError) as caught:
        quilting.synthesize(texture("gravel"), (64, 64), block=32, tileable="z")  # type: ignore[arg-type]
    assert caught.value.parameter == "tileable"


# --- the grid on a torus --------------------------------------------------------------------


def _check_schedule(grid: Grid) -> None:
    """Groups cover every block once, never touch, and every block's overlap mask is exactly the
    part of its footprint that earlier groups painted."""
    seen = np.zeros((grid.rows, grid.cols), dtype=int)
    painted = np.zeros((grid.height, grid.width), dtype=bool)
    for rows, cols in grid.groups():
        assert rows.size > 0
        seen[rows, cols] += 1
        layer = np.zeros(painted.shape, dtype=int)
        for i, j in zip(rows.tolist(), cols.tolist(), strict=True):
            ys, xs = footprint(grid, i, j)
            mask = grid.overlap_mask(grid.overlap_kind(i, j)) > 0
            old = painted[ys[:, None], xs[None, :]]
            assert np.array_equal(old, mask), (grid, i, j, grid.overlap_kind(i, j))
            layer[ys[:, None], xs[None, :]] += 1
        assert layer.max() == 1, (grid, rows, cols)  # one group's footprints are disjoint
        painted |= layer > 0
    assert (seen == 1).all(), grid
    assert painted.all(), grid


@pytest.mark.parametrize("wrap", WRAPS, ids=WRAP_IDS)
def test_schedule_on_small_tori(wrap: tuple[bool, bool]) -> None:
    grids = [g for g in torus_grids() if (bool(g.period[0]), bool(g.period[1])) == wrap]
    assert len(grids) >= 36
    for grid in grids:
        _check_schedule(grid)


def test_schedule_of_covering_grids() -> None:
    checked = 0
    for grid in covering_grids():
        if grid.rows <= 7 and grid.cols <= 7:
            _check_schedule(grid)
            checked += 1
    assert checked > 100


def test_wrap_overlap_of_covering_grids() -> None:
    widened = 0
    for block, overlap in ((8, 1), (12, 2), (16, 2), (24, 4), (32, 5), (48, 8)):
        for size in range(block, 6 * block):
            for wrap in WRAPS[1:]:
                dims = (size, size + 3)
                grid = Grid.covering(*dims, block, overlap, wrap)
                for axis in (0, 1):
                    if not wrap[axis]:
                        assert grid.period[axis] == 0 and grid.wrap_overlap[axis] == 0
                        continue
                    assert grid.period[axis] == dims[axis]
                    assert 1 <= grid.wrap_overlap[axis] <= grid.step
                # The least overlap from the requested one whose wrap strips are all at least
                # that wide, found by brute force.
                fits = [
                    o
                    for o in range(overlap, (block - 1) // 2 + 1)
                    if all(
                        not w or (-(-(s - o + 1) // (block - o))) * (block - o) + o - s >= o
                        for s, w in zip(dims, wrap, strict=True)
                    )
                ]
                assert grid.overlap == (fits[0] if fits else overlap), (block, dims, wrap)
                if grid.overlap > overlap:
                    widened += 1
                    for axis in (0, 1):
                        if wrap[axis]:
                            assert grid.overlap <= grid.wrap_overlap[axis] <= grid.step
    assert widened > 50


def test_torus_footprints_fill_the_period_exactly() -> None:
    """The blocks of a wrapped axis cover the whole period and run past it by the wrap strip."""
    for grid in torus_grids():
        for axis, count in ((0, grid.rows), (1, grid.cols)):
            if grid.period[axis]:
                end = (count - 1) * grid.step + grid.block
                assert end - grid.period[axis] == grid.wrap_overlap[axis]


# --- far-side cuts --------------------------------------------------------------------------


@st.composite
def surfaces(draw: st.DrawFn) -> tuple[NDArray[np.float64], int]:
    size = draw(st.integers(2, 8))
    overlap = draw(st.integers(1, size))
    n = draw(st.integers(1, 3))
    if draw(st.booleans()):
        elements = st.integers(0, 2).map(float)
    else:
        elements = st.floats(0.0, 100.0, allow_nan=False, allow_infinity=False)
    return draw(hnp.arrays(np.float64, (n, size, size), elements=elements)), overlap


def _cheapest_path(e: NDArray[np.float64], columns: range) -> float:
    """Least sum of e over 8-connected paths with one pixel per row inside ``columns``."""
    best = e[0, columns.start : columns.stop].copy()
    for y in range(1, e.shape[0]):
        padded = np.concatenate([[np.inf], best, [np.inf]])
        best = e[y, columns.start : columns.stop] + np.minimum(
            np.minimum(padded[:-2], padded[1:-1]), padded[2:]
        )
    return float(best.min())


@settings(max_examples=80, deadline=None)
@given(surface=surfaces())
def test_far_side_cuts_mirror_the_near_ones(surface: tuple[NDArray[np.float64], int]) -> None:
    e, overlap = surface
    n, size = e.shape[:2]
    right, _, right_cost = far_side_cuts(
        minimum_error_cuts, e, right=True, bottom=False, overlap=(size, overlap)
    )
    _, bottom, bottom_cost = far_side_cuts(
        minimum_error_cuts, e, right=False, bottom=True, overlap=(overlap, size)
    )
    both_right, both_bottom, both_cost = far_side_cuts(
        minimum_error_cuts, e, right=True, bottom=True, overlap=(overlap, overlap)
    )
    left, _, left_cost = minimum_error_cuts(e[:, :, ::-1], left=True, top=False, overlap=overlap)
    _, top, top_cost = minimum_error_cuts(e[:, ::-1, :], left=False, top=True, overlap=overlap)
    assert np.array_equal(right, size - left)
    assert np.array_equal(bottom, size - top)
    assert np.array_equal(both_right, right) and np.array_equal(both_bottom, bottom)
    assert np.allclose(right_cost, left_cost) and np.allclose(bottom_cost, top_cost)
    assert np.allclose(both_cost, right_cost + bottom_cost)
    for k in range(n):
        # The path pixels are the last column (row) the new block owns: inside the far strip,
        # 8-connected, their sum is the cost and it is the cheapest such path.
        xs = right[k].astype(np.int64) - 1
        ys = bottom[k].astype(np.int64) - 1
        for path in (xs, ys):
            assert ((path >= size - overlap) & (path < size)).all()
            assert (np.abs(np.diff(path)) <= 1).all()
        strip = range(size - overlap, size)
        assert np.isclose(right_cost[k], e[k, np.arange(size), xs].sum())
        assert np.isclose(bottom_cost[k], e[k, ys, np.arange(size)].sum())
        assert np.isclose(right_cost[k], _cheapest_path(e[k], strip))
        assert np.isclose(bottom_cost[k], _cheapest_path(e[k].T, strip))


def test_far_side_cuts_without_a_side_cut_nothing() -> None:
    e = np.random.default_rng(0).random((2, 6, 6))
    right, bottom, cost = far_side_cuts(
        minimum_error_cuts, e, right=False, bottom=False, overlap=(2, 2)
    )
    assert (right == 6).all() and (bottom == 6).all() and (cost == 0).all()
    right, bottom, _ = far_side_cuts(straight_cuts, e, right=True, bottom=True, overlap=(4, 3))
    assert (right == 6 - 3 // 2).all() and (bottom == 6 - 4 // 2).all()


@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_mask_with_four_cuts_is_the_intersection(data: st.DataObject) -> None:
    size = data.draw(st.integers(1, 8))
    n = data.draw(st.integers(1, 3))
    cuts = [
        data.draw(hnp.arrays(np.int16, (n, size), elements=st.integers(0, size))) for _ in range(4)
    ]
    cut_cols, cut_rows, cut_right, cut_bottom = cuts
    zeros = np.zeros((n, size), dtype=np.int16)
    full = np.full((n, size), size, dtype=np.int16)
    got = new_block_mask(cut_cols, cut_rows, cut_right, cut_bottom)
    near = new_block_mask(cut_cols, cut_rows)
    far_right = new_block_mask(zeros, zeros, cut_right, None)
    far_bottom = new_block_mask(zeros, zeros, None, cut_bottom)
    assert np.array_equal(got, near & far_right & far_bottom)
    assert np.array_equal(new_block_mask(cut_cols, cut_rows, full, full), near)
    y, x = np.indices((size, size))
    for k in range(n):
        naive = (
            (x >= cut_cols[k][:, None])
            & (y >= cut_rows[k][None, :])
            & (x < cut_right[k][:, None])
            & (y < cut_bottom[k][None, :])
        )
        assert np.array_equal(got[k], naive)


# --- the layout -----------------------------------------------------------------------------


def test_layout_json_re_renders_a_tileable_result(tmp_path: Path) -> None:
    hubble = texture("hubble")
    result = synth("hubble", (101, 130), 3, tileable="both")
    data = json.loads(result.layout.to_json())
    assert data["version"] == 2
    (pass_data,) = data["passes"]
    assert pass_data["period"] == [101, 130]
    assert "cut_right" in pass_data and "cut_bottom" in pass_data
    # The far cuts are really used: some block is cut against the first column / row.
    assert (np.asarray(pass_data["cut_right"]) < 32).any()
    assert (np.asarray(pass_data["cut_bottom"]) < 32).any()
    path = tmp_path / "layout.json"
    result.layout.save(path)
    for layout in (Layout.from_json(result.layout.to_json()), Layout.load(path)):
        assert layout.passes[0].grid == result.layout.passes[0].grid
        assert np.array_equal(apply_layout(layout, hubble), result.image)
        # A companion in another dtype and channel count, encoding the source position.
        yy, xx = np.indices(hubble.shape[:2])
        companion = (yy * 256 + xx).astype(np.uint16)
        quilted = apply_layout(layout, companion, kind="hard")
        assert quilted.shape == (101, 130) and quilted.dtype == np.uint16
        src_y, src_x = np.divmod(quilted.astype(np.int64), 256)
        assert np.array_equal(hubble[src_y, src_x], apply_layout(layout, hubble, kind="hard"))
        # A gray companion of one channel follows the same seams.
        assert np.array_equal(apply_layout(layout, hubble[..., 1]), result.image[..., 1])


@pytest.mark.parametrize("tileable", ["x", "y"])
def test_layout_of_one_wrapped_axis(tileable: str) -> None:
    result = synth("wood", (70, 90), 4, tileable=tileable)
    data = json.loads(result.layout.to_json())
    period = data["passes"][0]["period"]
    assert period == ([0, 90] if tileable == "x" else [70, 0])
    layout = Layout.from_json(result.layout.to_json())
    assert np.array_equal(apply_layout(layout, texture("wood")), result.image)


def test_a_plane_layout_has_no_torus_and_version_1_still_loads() -> None:
    result = synth("brick", (90, 110), 5)
    data = json.loads(result.layout.to_json())
    assert data["version"] == 2
    assert "period" not in data["passes"][0]
    data["version"] = 1
    old = Layout.from_json(json.dumps(data))
    assert old.passes[0].grid.period == (0, 0)
    assert np.array_equal(apply_layout(old, texture("brick")), result.image)


def test_a_corrupted_torus_is_refused() -> None:
    result = synth("gravel", (100, 120), 6, tileable="both")
    grid = result.layout.passes[0].grid
    data = json.loads(result.layout.to_json())
    plane_width = grid.cols * grid.step + grid.overlap  # a wrap strip of 0 pixels
    for period in (
        [100, plane_width],
        [100, plane_width - grid.step - 1],  # a strip wider than the step
        [grid.rows * grid.step + grid.overlap + 5, 120],  # a negative strip
    ):
        broken = json.loads(json.dumps(data))
        broken["passes"][0]["period"] = period
        with pytest.raises(LayoutError):
            Layout.from_json(json.dumps(broken))
    # The untouched document loads (the check above can pass only by refusing).
    assert Layout.from_json(json.dumps(data)).passes[0].grid == grid


# --- reproducibility ------------------------------------------------------------------------


def test_same_seed_same_bytes_and_the_batch_does_not_matter() -> None:
    gravel = texture("gravel")
    kwargs: dict[str, Any] = {"block": 24, "tileable": "both"}
    base = quilting.synthesize(gravel, (110, 97), seed=7, **kwargs)
    again = quilting.synthesize(gravel, (110, 97), seed=7, **kwargs)
    one = quilting.synthesize(gravel, (110, 97), seed=7, max_batch=1, **kwargs)
    three = quilting.synthesize(
        gravel, (110, 97), seed=7, max_batch=3, backend=FFTBackend(threads=2), **kwargs
    )
    other = quilting.synthesize(gravel, (110, 97), seed=8, **kwargs)
    assert base.image.tobytes() == again.image.tobytes() == one.image.tobytes()
    assert base.image.tobytes() == three.image.tobytes()
    assert base.layout.to_json() == one.layout.to_json()
    assert base.image.tobytes() != other.image.tobytes()


@pytest.mark.parametrize("tileable", ["both", "x", "y"])
@pytest.mark.parametrize("with_gl", [False, pytest.param(True, marks=pytest.mark.gl)])
def test_backends_agree_on_a_tileable_result(
    request: pytest.FixtureRequest, with_gl: bool, tileable: str
) -> None:
    crop = np.ascontiguousarray(texture("hubble")[:48, :48])
    results = {
        name: quilting.synthesize(crop, (64, 72), block=16, seed=2, tileable=tileable, backend=b)
        for name, b in backends(request, with_gl).items()
    }
    reference = results.pop("reference")
    assert reference.backend == "reference"
    for name, result in results.items():
        assert result.backend == name
        assert result.image.tobytes() == reference.image.tobytes(), name
        passes = json.loads(result.layout.to_json())["passes"]
        assert passes == json.loads(reference.layout.to_json())["passes"], name


# --- statistics ---------------------------------------------------------------------------


def _traced_unused(result: quilting.Result, source: NDArray[Any]) -> float:
    """Share of texture pixels that no output pixel comes from, traced with a position map."""
    yy, xx = np.indices(source.shape[:2])
    positions = (yy * 256 + xx).astype(np.uint16)
    where = apply_layout(result.layout, positions, kind="hard").astype(np.int64)
    used = np.zeros(source.shape[:2], dtype=bool)
    used[where // 256, where % 256] = True
    return 1.0 - float(used.mean())


@pytest.mark.parametrize("tileable", [None, "both", "x"])
def test_unused_share_counts_the_pixels_across_the_wrap(tileable: str | None) -> None:
    """stats.unused is the share of the texture appearing nowhere in the output; on a torus the
    last column's blocks show pixels past the canvas edge, at the left."""
    wood = texture("wood")
    for seed in range(2):
        result = synth("wood", (150, 170), seed, tileable=tileable)
        assert result.stats.unused == pytest.approx(_traced_unused(result, wood), abs=1e-9)


# --- exclusion ------------------------------------------------------------------------------


def test_tileable_respects_excluded_colours() -> None:
    hubble = texture("hubble")
    ranges = quilting.SynthesisOptions(exclude_colors=STARS).exclude_colors
    excluded = excluded_pixels(hubble, ranges, None)
    assert excluded is not None and excluded.any()
    marks = excluded.astype(np.uint8)
    result = synth("hubble", (150, 170), 1, tileable="both", exclude_colors=STARS)
    assert int(apply_layout(result.layout, marks).sum()) == 0
    # Without the exclusion the stars are used: the check can fail.
    plain = synth("hubble", (150, 170), 1, tileable="both")
    assert int(apply_layout(plain.layout, marks).sum()) > 0
