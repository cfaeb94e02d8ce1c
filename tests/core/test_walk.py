"""Tests of the walk cut (minimum-resistance-cut paper): a plain-Python oracle, path rules,
blending, gathering."""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from numpy.typing import NDArray

from quilting.core.errors import InvalidParameterError
from quilting.core.grid import Grid
from quilting.core.walk import (
    WalkCuts,
    covered_pixels,
    ramp,
    reflect_gather,
    regions,
    walk_compose,
    walk_cuts,
)

Pixel = tuple[int, int]

# Tie order of the module: straight on, diagonal to the lower column, the other diagonal,
# sideways to the lower column, sideways to the higher one.
RISING_MOVES = ((-1, 0), (-1, -1), (-1, 1), (0, -1), (0, 1))
FALLING_MOVES = ((1, 0), (1, -1), (1, 1), (0, -1), (0, 1))


# --- the oracle: one block, plain Python ------------------------------------------------------


def _greedy(
    r: NDArray[np.float64],
    start: Pixel,
    moves: tuple[Pixel, ...],
    stop: Callable[[int, int], bool],
    max_run: int,
) -> list[Pixel]:
    size = r.shape[0]
    path = [start]
    row_run = col_run = 1
    while not stop(*path[-1]):
        y, x = path[-1]
        best: tuple[float, int, int, int, int] | None = None
        for dy, dx in moves:
            ny, nx = y + dy, x + dx
            new_row_run = row_run + 1 if dy == 0 else 1
            new_col_run = col_run + 1 if dx == 0 else 1
            if not (0 <= ny < size and 0 <= nx < size) or (ny, nx) in path:
                continue
            if new_row_run > max_run or new_col_run > max_run:
                continue
            value = float(r[ny, nx])
            if best is None or value < best[0]:
                best = (value, ny, nx, new_row_run, new_col_run)
        assert best is not None, "a diagonal step is always allowed"
        _, ny, nx, row_run, col_run = best
        path.append((ny, nx))
    return path


def oracle(
    r: NDArray[np.float64], max_run: int
) -> tuple[list[Pixel], list[Pixel], list[int], float]:
    """Path 1, path 2, cut_cols and cost of one (B, B) surface, straight from the rules."""
    size = r.shape[0]
    rising = _greedy(r, (size - 1, 0), RISING_MOVES, lambda y, x: y == 0, max_run)
    left1 = [min(x for y, x in rising if y == row) for row in range(size)]
    falling = _greedy(r, (0, 0), FALLING_MOVES, lambda y, x: x >= left1[y], max_run)
    ym = falling[-1][0]
    cut = set(falling) | {(y, x) for y, x in rising if y >= ym}
    cut_cols = []
    for row in range(size):
        in_falling = [x for y, x in falling if y == row]
        if row < ym:
            cut_cols.append(min(in_falling))
        elif row > ym:
            cut_cols.append(left1[row])
        else:
            cut_cols.append(min(*in_falling, left1[row]))
    cost = 0.0
    for y, x in sorted(cut):
        cost += float(r[y, x])
    return rising, falling, cut_cols, cost


def path_of(paths: NDArray[np.intp], lengths: NDArray[np.intp], k: int) -> list[Pixel]:
    length = int(lengths[k])
    assert np.all(paths[k, length:] == -1)
    return [(int(y), int(x)) for y, x in paths[k, :length]]


@st.composite
def small_surfaces(draw: st.DrawFn) -> tuple[NDArray[np.float64], int]:
    """Small (n, B, B) surfaces, half of them small integers so that ties abound."""
    size = draw(st.integers(2, 9))
    n = draw(st.integers(1, 4))
    if draw(st.booleans()):
        elements = st.integers(0, 3).map(float)
    else:
        elements = st.floats(0.0, 10.0, allow_nan=False, allow_infinity=False)
    r = draw(hnp.arrays(np.float64, (n, size, size), elements=elements))
    return r, draw(st.integers(1, 4))


def random_surface(seed: int, n: int, size: int, ties: bool) -> NDArray[np.float64]:
    rng = np.random.default_rng(seed)
    if ties:
        return rng.integers(0, 3, size=(n, size, size)).astype(np.float64)
    return rng.random((n, size, size))


# --- walk_cuts --------------------------------------------------------------------------------


@settings(max_examples=300, deadline=None)
@given(surface=small_surfaces())
def test_walk_cuts_equal_the_oracle(surface: tuple[NDArray[np.float64], int]) -> None:
    r, max_run = surface
    cuts = walk_cuts(r, max_run=max_run)
    for k in range(r.shape[0]):
        rising, falling, cut_cols, cost = oracle(r[k], max_run)
        assert path_of(cuts.rising, cuts.rising_length, k) == rising
        assert path_of(cuts.falling, cuts.falling_length, k) == falling
        assert cuts.cut_cols[k].tolist() == cut_cols
        assert cuts.cost[k] == cost


def _max_run(values: list[int]) -> int:
    best = run = 1
    for prev, cur in itertools.pairwise(values):
        run = run + 1 if cur == prev else 1
        best = max(best, run)
    return best


def _assert_path(path: list[Pixel], size: int, max_run: int, direction: int) -> None:
    assert len(set(path)) == len(path), "a pixel repeats"
    assert all(0 <= y < size and 0 <= x < size for y, x in path)
    for (y0, x0), (y1, x1) in itertools.pairwise(path):
        assert max(abs(y1 - y0), abs(x1 - x0)) == 1, "not an 8-connected step"
        assert (y1 - y0) * direction >= 0, "the path turned back"
    assert _max_run([y for y, _ in path]) <= max_run
    assert _max_run([x for _, x in path]) <= max_run


def _connected(pixels: set[Pixel]) -> bool:
    start = next(iter(pixels))
    seen, todo = {start}, [start]
    while todo:
        y, x = todo.pop()
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                q = (y + dy, x + dx)
                if q in pixels and q not in seen:
                    seen.add(q)
                    todo.append(q)
    return seen == pixels


def _assert_cuts(r: NDArray[np.float64], cuts: WalkCuts, max_run: int) -> None:
    n, size, _ = r.shape
    assert cuts.cut_cols.dtype == np.int16 and cuts.cut_cols.shape == (n, size)
    for k in range(n):
        rising = path_of(cuts.rising, cuts.rising_length, k)
        falling = path_of(cuts.falling, cuts.falling_length, k)
        _assert_path(rising, size, max_run, direction=-1)
        _assert_path(falling, size, max_run, direction=1)
        assert rising[0] == (size - 1, 0)
        assert rising[-1][0] == 0 and all(y > 0 for y, _ in rising[:-1])
        left1 = [min((x for y, x in rising if y == row), default=size) for row in range(size)]
        assert max(left1) < size, "path 1 misses a row"
        assert falling[0] == (0, 0)
        met = [x >= left1[y] for y, x in falling]
        assert met[-1] and not any(met[:-1])
        ym = falling[-1][0]
        cut = set(falling) | {(y, x) for y, x in rising if y >= ym}
        assert (0, 0) in cut and (size - 1, 0) in cut and _connected(cut)
        cols = cuts.cut_cols[k]
        assert cols[0] == 0 and cols[-1] == 0
        assert all(0 <= c < size for c in cols)
        # cut_cols is the leftmost cut pixel of every row: the old side holds no cut pixel.
        assert cols.tolist() == [min(x for y, x in cut if y == row) for row in range(size)]
        assert cuts.cost[k] == pytest.approx(sum(float(r[k][p]) for p in cut), rel=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    size=st.integers(2, 48),
    n=st.integers(1, 4),
    max_run=st.integers(1, 6),
    ties=st.booleans(),
)
def test_paths_follow_the_rules(seed: int, size: int, n: int, max_run: int, ties: bool) -> None:
    r = random_surface(seed, n, size, ties)
    _assert_cuts(r, walk_cuts(r, max_run=max_run), max_run)


@pytest.mark.parametrize("max_run", [1, 2, 5, 100])
def test_flat_and_structured_surfaces(max_run: int) -> None:
    size = 24
    yy, xx = np.mgrid[:size, :size].astype(np.float64)
    r = np.stack([np.zeros((size, size)), xx, yy, -xx + 30, (xx - yy) ** 2, np.sin(xx * yy) + 1])
    _assert_cuts(r, walk_cuts(r, max_run=max_run), max_run)


def test_batch_does_not_change_a_block() -> None:
    r = random_surface(7, 9, 20, ties=True) + random_surface(8, 9, 20, ties=False) * 1e-3
    batch = walk_cuts(r, max_run=3)
    for k in range(r.shape[0]):
        one = walk_cuts(r[k : k + 1], max_run=3)
        assert np.array_equal(one.cut_cols[0], batch.cut_cols[k])
        assert one.cost[0] == batch.cost[k]
        assert path_of(one.rising, one.rising_length, 0) == path_of(
            batch.rising, batch.rising_length, k
        )
        assert path_of(one.falling, one.falling_length, 0) == path_of(
            batch.falling, batch.falling_length, k
        )


def _corridor(size: int) -> list[Pixel]:
    """A zig-zag path up from the bottom-left corner (runs of 2) whose steps are unambiguous."""
    pattern = [(-1, 0), (-1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (-1, -1)]
    path = [(size - 1, 0)]
    step = 0
    while path[-1][0] > 0:
        dy, dx = pattern[step % len(pattern)]
        path.append((path[-1][0] + dy, path[-1][1] + dx))
        step += 1
    return path


@pytest.mark.parametrize("max_run", [2, 3, 6])
@pytest.mark.parametrize("size", [2, 9, 48])
def test_path_1_follows_a_zero_resistance_corridor(size: int, max_run: int) -> None:
    corridor = _corridor(size)
    # The fixture itself: from each corridor pixel the next one is the only corridor pixel
    # among the five moves, so the walk has no choice but to follow it.
    for i, (y, x) in enumerate(corridor[:-1]):
        ahead = [(y + dy, x + dx) for dy, dx in RISING_MOVES]
        assert [q for q in ahead if q in corridor[i + 1 :]] == [corridor[i + 1]]
    r = 1.0 + np.random.default_rng(size).random((3, size, size))
    for y, x in corridor:
        r[:, y, x] = 0.0
    cuts = walk_cuts(r, max_run=max_run)
    for k in range(3):
        assert path_of(cuts.rising, cuts.rising_length, k) == corridor


def test_path_2_is_one_pixel_when_path_1_reaches_the_corner() -> None:
    r = np.ones((1, 6, 6))
    r[0, :, 0] = 0.5
    cuts = walk_cuts(r, max_run=6)
    assert path_of(cuts.rising, cuts.rising_length, 0) == [(y, 0) for y in range(5, -1, -1)]
    assert path_of(cuts.falling, cuts.falling_length, 0) == [(0, 0)]
    assert cuts.cut_cols.tolist() == [[0] * 6]
    assert cuts.cost[0] == 3.0


def test_max_run_one_walks_diagonals() -> None:
    cuts = walk_cuts(np.zeros((1, 5, 5)), max_run=1)
    # Ties go to the up-left diagonal, which is outside in column 0: zig-zag 0, 1, 0, 1, 0.
    assert path_of(cuts.rising, cuts.rising_length, 0) == [(4, 0), (3, 1), (2, 0), (1, 1), (0, 0)]


def test_empty_batch() -> None:
    cuts = walk_cuts(np.zeros((0, 5, 5)), max_run=2)
    assert cuts.cut_cols.shape == (0, 5) and cuts.cost.shape == (0,)
    assert cuts.rising_length.shape == (0,) and cuts.falling.shape[0] == 0


@pytest.mark.parametrize(
    ("r", "max_run", "name"),
    [
        (np.zeros((5, 5)), 2, "r"),
        (np.zeros((1, 5, 4)), 2, "r"),
        (np.zeros((1, 1, 1)), 2, "r"),
        (np.full((1, 3, 3), np.nan), 2, "r"),
        (np.full((1, 3, 3), np.inf), 2, "r"),
        (np.zeros((1, 3, 3)), 0, "max_run"),
        (np.zeros((1, 3, 3)), True, "max_run"),
        (np.zeros((1, 3, 3)), 1.5, "max_run"),
    ],
)
def test_walk_cuts_rejects_bad_input(r: NDArray[np.float64], max_run: int, name: str) -> None:
    with pytest.raises(InvalidParameterError) as info:
        walk_cuts(r, max_run=max_run)
    assert info.value.parameter == name


# --- ramp -------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("feather", "at_minus_one", "at_zero"),
    [(0, 0.0, 1.0), (1, 0.0, 1.0), (2, 0.25, 0.75), (4, 0.375, 0.625)],
)
def test_ramp_values(feather: int, at_minus_one: float, at_zero: float) -> None:
    w = ramp(np.array([-1, 0]), feather)
    assert w.dtype == np.float32
    assert w.tolist() == [at_minus_one, at_zero]


@pytest.mark.parametrize("feather", [0, 1, 2, 3, 4, 7, 16])
def test_ramp_is_monotone_and_symmetric(feather: int) -> None:
    d = np.arange(-40, 40)
    w = ramp(d, feather)
    assert np.all(np.diff(w) >= 0)
    assert w[0] == 0.0 and w[-1] == 1.0
    np.testing.assert_allclose(w + ramp(-1 - d, feather), 1.0, atol=1e-6)
    # The blend is centred between two pixels: an odd width has its ends exactly at 0 and 1.
    assert np.count_nonzero((w > 0) & (w < 1)) == 2 * (feather // 2)


def test_ramp_rejects_negative_feather() -> None:
    with pytest.raises(InvalidParameterError):
        ramp(np.zeros(3, dtype=np.intp), -1)


# --- walk_compose -----------------------------------------------------------------------------


Inputs = dict[str, NDArray[Any]]


def compose_inputs(seed: int, n: int = 6, size: int = 10, channels: int = 3) -> Inputs:
    rng = np.random.default_rng(seed)
    shape = (n, size, size, channels)
    names = ("old", "new", "left", "top", "diagonal")
    return {
        **{name: rng.random(shape, dtype=np.float32) for name in names},
        "covered": rng.random((n, size, size)) < 0.5,
        "cut_cols": rng.integers(0, size, (n, size)),
        "cut_rows": rng.integers(0, size, (n, size)),
        # Every combination of neighbours appears.
        "has_left": np.arange(n) % 2 == 0,
        "has_top": np.arange(n) % 4 < 2,
    }


def compose(inputs: Inputs, feather: int) -> NDArray[np.float32]:
    return walk_compose(
        inputs["old"],
        inputs["covered"],
        inputs["new"],
        inputs.get("left"),
        inputs.get("top"),
        inputs.get("diagonal"),
        inputs["cut_cols"],
        inputs["cut_rows"],
        inputs["has_left"],
        inputs["has_top"],
        feather,
    )


@pytest.mark.parametrize("feather", [0, 1])
@pytest.mark.parametrize("seed", range(5))
def test_hard_compose_picks_one_source_per_pixel(seed: int, feather: int) -> None:
    inputs = compose_inputs(seed)
    out = compose(inputs, feather)
    n, size = inputs["cut_cols"].shape
    for k in range(n):
        for y in range(size):
            for x in range(size):
                a = x >= inputs["cut_cols"][k, y] or not inputs["has_left"][k]
                b = y >= inputs["cut_rows"][k, x] or not inputs["has_top"][k]
                if a and b:
                    source = "new"
                elif inputs["covered"][k, y, x]:
                    source = "old"
                else:
                    source = {(False, True): "left", (True, False): "top"}.get((a, b), "diagonal")
                assert np.array_equal(out[k, y, x], inputs[source][k, y, x]), (k, y, x, source)


@pytest.mark.parametrize("feather", [0, 2, 3, 8])
def test_compose_weights_sum_to_one(feather: int) -> None:
    inputs = compose_inputs(1)
    for name in ("old", "new", "left", "top", "diagonal"):
        inputs[name] = np.ones_like(inputs[name])
    out = compose(inputs, feather)
    assert out.dtype == np.float32
    np.testing.assert_allclose(out, 1.0, atol=1e-6)


def test_compose_blends_between_the_sources() -> None:
    inputs = compose_inputs(2)
    out = compose(inputs, 4)
    sources = np.stack([inputs[s] for s in ("old", "new", "left", "top", "diagonal")])
    assert np.all(out >= sources.min(axis=0) - 1e-6)
    assert np.all(out <= sources.max(axis=0) + 1e-6)
    # Some pixels are true mixtures, not copies of one source.
    assert not np.all(np.any(out[None] == sources, axis=0))


def test_block_without_neighbours_is_the_new_block() -> None:
    inputs = compose_inputs(3)
    n = inputs["new"].shape[0]
    inputs["has_left"] = np.zeros(n, dtype=bool)
    inputs["has_top"] = np.zeros(n, dtype=bool)
    for name in ("left", "top", "diagonal"):
        del inputs[name]
    out = compose(inputs, 5)
    assert np.array_equal(out, inputs["new"])


def test_compose_is_deterministic_and_batch_independent() -> None:
    inputs = compose_inputs(4)
    first = compose(inputs, 3)
    assert first.tobytes() == compose(inputs, 3).tobytes()
    for k in range(first.shape[0]):
        single = {name: value[k : k + 1] for name, value in inputs.items()}
        assert compose(single, 3).tobytes() == first[k : k + 1].tobytes()


def test_compose_requires_present_neighbours() -> None:
    inputs = compose_inputs(5)
    del inputs["diagonal"]
    with pytest.raises(InvalidParameterError) as info:
        compose(inputs, 2)
    assert info.value.parameter == "diagonal"
    inputs = compose_inputs(5)
    inputs["cut_cols"] = inputs["cut_cols"][:, :-1]
    with pytest.raises(InvalidParameterError) as info:
        compose(inputs, 2)
    assert info.value.parameter == "cut_cols"


# --- reflect_gather ---------------------------------------------------------------------------


@settings(max_examples=100, deadline=None)
@given(
    height=st.integers(1, 6),
    width=st.integers(1, 6),
    block=st.integers(1, 9),
    data=st.data(),
)
def test_reflect_gather_equals_reflect_padding(
    height: int, width: int, block: int, data: st.DataObject
) -> None:
    image = np.arange(height * width * 2, dtype=np.uint16).reshape(height, width, 2)
    span = st.integers(-(height + block), height + block)
    corners = np.array(
        data.draw(st.lists(st.tuples(span, st.integers(-(width + block), width + block)))),
        dtype=np.intp,
    ).reshape(-1, 2)
    pad = 2 * (max(height, width) + block)
    padded = np.pad(image, ((pad, pad), (pad, pad), (0, 0)), mode="reflect")
    out = reflect_gather(image, corners, block)
    assert out.dtype == image.dtype and out.shape == (len(corners), block, block, 2)
    for k, (y, x) in enumerate(corners):
        assert np.array_equal(out[k], padded[pad + y : pad + y + block, pad + x : pad + x + block])


def test_reflect_gather_inside_is_slicing() -> None:
    image = np.random.default_rng(0).random((12, 15, 3), dtype=np.float32)
    corners = np.array([[0, 0], [4, 7], [7, 10]], dtype=np.intp)
    out = reflect_gather(image, corners, 5)
    assert out.dtype == np.float32
    for k, (y, x) in enumerate(corners):
        assert np.array_equal(out[k], image[y : y + 5, x : x + 5])


def test_reflect_gather_mirrors_without_repeating_the_edge() -> None:
    image = np.arange(4, dtype=np.uint8).reshape(1, 4, 1)
    out = reflect_gather(image, np.array([[0, 2]], dtype=np.intp), 4)
    assert out[0, 0, :, 0].tolist() == [2, 3, 2, 1]


@pytest.mark.parametrize(
    ("image", "corners", "block", "name"),
    [
        (np.zeros((4, 4)), np.zeros((1, 2), dtype=np.intp), 2, "image"),
        (np.zeros((4, 4, 1)), np.zeros((1, 3), dtype=np.intp), 2, "corners"),
        (np.zeros((4, 4, 1)), np.zeros((1, 2)), 2, "corners"),
        (np.zeros((4, 4, 1)), np.zeros((1, 2), dtype=np.intp), 0, "block"),
    ],
)
def test_reflect_gather_rejects_bad_input(
    image: NDArray[np.float64], corners: NDArray[np.intp], block: int, name: str
) -> None:
    with pytest.raises(InvalidParameterError) as info:
        reflect_gather(image, corners, block)
    assert info.value.parameter == name


# --- regions and covered pixels against the per-block versions they replaced ----------------


def _reference_regions(
    grid: Grid,
    rows: NDArray[np.intp],
    cols: NDArray[np.intp],
    cut_cols: NDArray[Any],
    cut_rows: NDArray[Any],
) -> NDArray[np.int8]:
    """The earlier implementation: nested wheres, and each block's overlap mask one by one."""
    size = grid.block
    idx = np.arange(size)
    new_x = (idx[None, None, :] >= np.asarray(cut_cols)[:, :, None]) | (cols == 0)[:, None, None]
    new_y = (idx[None, :, None] >= np.asarray(cut_rows)[:, None, :]) | (rows == 0)[:, None, None]
    label = np.where(new_y, np.where(new_x, 0, 1), np.where(new_x, 2, 3)).astype(np.int8)
    label[_reference_covered(grid, rows, cols) & (label != 0)] = -1
    return label


def _reference_covered(
    grid: Grid, rows: NDArray[np.intp], cols: NDArray[np.intp]
) -> NDArray[np.bool_]:
    """The earlier covered_pixels: each block's overlap mask, one by one."""
    return np.stack(
        [grid.overlap_mask(grid.overlap_kind(i, j)) > 0 for i, j in zip(rows, cols, strict=True)]
    )


@pytest.mark.parametrize(
    "grid",
    [
        Grid.covering(333, 517, 32, 5),
        Grid.covering(200, 130, 20, 4, (True, True)),
        Grid.covering(200, 130, 20, 4, (True, False)),
        Grid.covering(200, 130, 20, 4, (False, True)),
        Grid(block=9, overlap=0, rows=3, cols=2),
    ],
    ids=str,
)
@pytest.mark.parametrize("dtype", [np.int16, np.intp])
def test_regions_and_covered_pixels_equal_the_per_block_ones(grid: Grid, dtype: type) -> None:
    rng = np.random.default_rng(grid.rows * 31 + grid.cols)
    rows, cols = np.divmod(np.arange(grid.rows * grid.cols), grid.cols)
    # Cuts anywhere in the block, past the overlap and to its far edge too.
    cut_cols = rng.integers(0, grid.block + 1, (rows.size, grid.block)).astype(dtype)
    cut_rows = rng.integers(0, grid.block + 1, (rows.size, grid.block)).astype(dtype)
    np.testing.assert_array_equal(
        regions(grid, rows, cols, cut_cols, cut_rows),
        _reference_regions(grid, rows, cols, cut_cols, cut_rows),
    )
    for group_rows, group_cols in grid.groups():
        if not group_rows.size:
            continue
        at = group_rows * grid.cols + group_cols
        got = regions(grid, group_rows, group_cols, cut_cols[at], cut_rows[at])
        want = _reference_regions(grid, group_rows, group_cols, cut_cols[at], cut_rows[at])
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(
            covered_pixels(grid, group_rows, group_cols),
            _reference_covered(grid, group_rows, group_cols),
        )
