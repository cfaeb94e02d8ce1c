"""Tests of the boundary cuts: brute force on small surfaces, path validity, masks, batching."""

from __future__ import annotations

import itertools
from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from numpy.typing import NDArray

from quilting.core.errors import InvalidParameterError
from quilting.core.seams import (
    CONTEXT,
    CONTEXT_RADIUS,
    EDGE_COST,
    minimum_error_cuts,
    new_block_mask,
    straight_cuts,
    strip_cuts,
)

KINDS = [(True, False), (False, True), (True, True)]
KIND_IDS = ["left", "top", "L"]
ALL_KINDS = [*KINDS, (False, False)]
ALL_KIND_IDS = [*KIND_IDS, "none"]

Surface = tuple[NDArray[np.float64], int]


# --- strategies -------------------------------------------------------------------------------


@st.composite
def surfaces(
    draw: st.DrawFn, min_b: int = 3, max_b: int = 7, max_o: int = 3, max_n: int = 3
) -> Surface:
    """An (n, B, B) error surface and an overlap; half the time small integers, so many ties."""
    size = draw(st.integers(min_b, max_b))
    overlap = draw(st.integers(1, min(max_o, size)))
    n = draw(st.integers(1, max_n))
    if draw(st.booleans()):
        elements = st.integers(0, 2).map(float)
    else:
        elements = st.floats(0.0, 100.0, allow_nan=False, allow_infinity=False)
    e = draw(hnp.arrays(np.float64, (n, size, size), elements=elements))
    return e, overlap


# --- brute force and reference helpers ------------------------------------------------------


def _paths_down(start_row: int, start_col: int, size: int, overlap: int) -> Iterator[list[int]]:
    """Every 8-connected column sequence for rows start_row..size-1 inside [0, overlap)."""
    for steps in itertools.product((-1, 0, 1), repeat=size - 1 - start_row):
        cols = [start_col]
        for step in steps:
            cols.append(cols[-1] + step)
        if all(0 <= c < overlap for c in cols):
            yield cols


def _min_down(e: NDArray[np.float64], start_row: int, start_col: int, overlap: int) -> float:
    size = e.shape[0]
    return min(
        sum(float(e[start_row + k, c]) for k, c in enumerate(cols))
        for cols in _paths_down(start_row, start_col, size, overlap)
    )


def brute_force(e: NDArray[np.float64], left: bool, top: bool, overlap: int) -> float:
    """Cheapest admissible cut of one (B, B) surface, by enumerating every path."""
    if left and top:
        return min(
            _min_down(e, py, px, overlap) + _min_down(e.T, px, py, overlap) - float(e[py, px])
            for py in range(overlap)
            for px in range(overlap)
        )
    surface = e if left else e.T
    return min(_min_down(surface, 0, c, overlap) for c in range(overlap))


def meeting_point(
    cut_cols: NDArray[np.int16], cut_rows: NDArray[np.int16], overlap: int
) -> tuple[int, int]:
    """The corner point p that the L-shaped fill rule encodes; it is unique when it exists."""
    found = [
        (py, px)
        for py in range(overlap)
        for px in range(overlap)
        if cut_cols[py] == px
        and cut_rows[px] == py
        and np.all(cut_cols[:py] == px)
        and np.all(cut_rows[:px] == py)
    ]
    assert len(found) == 1, f"expected one meeting point, found {found}"
    return found[0]


def path_cost(
    e: NDArray[np.float64],
    cut_cols: NDArray[np.int16],
    cut_rows: NDArray[np.int16],
    left: bool,
    top: bool,
    overlap: int,
) -> float:
    """Sum of e along the path that the cut arrays describe (meeting point once)."""
    size = e.shape[0]
    if left and top:
        py, px = meeting_point(cut_cols, cut_rows, overlap)
        vertical = sum(float(e[y, cut_cols[y]]) for y in range(py, size))
        horizontal = sum(float(e[cut_rows[x], x]) for x in range(px, size))
        return vertical + horizontal - float(e[py, px])
    if left:
        return sum(float(e[y, cut_cols[y]]) for y in range(size))
    if top:
        return sum(float(e[cut_rows[x], x]) for x in range(size))
    return 0.0


def assert_valid_path(path: NDArray[np.int16], overlap: int) -> None:
    assert np.all(path >= 0)
    assert np.all(path < overlap)
    assert np.all(np.abs(np.diff(path.astype(np.int64))) <= 1)


def naive_mask(cut_cols: NDArray[np.int16], cut_rows: NDArray[np.int16]) -> NDArray[np.bool_]:
    n, size = cut_cols.shape
    mask = np.zeros((n, size, size), dtype=bool)
    for k in range(n):
        for y in range(size):
            for x in range(size):
                mask[k, y, x] = x >= cut_cols[k, y] and y >= cut_rows[k, x]
    return mask


# --- minimum_error_cuts ---------------------------------------------------------------------


@pytest.mark.parametrize(("left", "top"), KINDS, ids=KIND_IDS)
@settings(max_examples=60, deadline=None)
@given(surface=surfaces())
def test_cost_is_brute_force_minimum(left: bool, top: bool, surface: Surface) -> None:
    e, overlap = surface
    _, _, cost = minimum_error_cuts(e, left=left, top=top, overlap=overlap)
    for k in range(e.shape[0]):
        assert cost[k] == pytest.approx(brute_force(e[k], left, top, overlap), rel=1e-9, abs=1e-9)


@pytest.mark.parametrize(("left", "top"), KINDS, ids=KIND_IDS)
@pytest.mark.parametrize("overlap", [1, 2, 3])
def test_brute_force_on_a_fixed_batch(left: bool, top: bool, overlap: int) -> None:
    # Many small integer surfaces in one call: dense in near-ties, so that a meeting point
    # counted twice or a wrong tie rule changes some cost (hypothesis may miss such cases).
    e = np.random.default_rng(overlap).integers(0, 6, size=(150, 5, 5)).astype(np.float64)
    _, _, cost = minimum_error_cuts(e, left=left, top=top, overlap=overlap)
    expected = [brute_force(e[k], left, top, overlap) for k in range(e.shape[0])]
    assert cost.tolist() == expected


@pytest.mark.parametrize(("left", "top"), KINDS, ids=KIND_IDS)
@settings(max_examples=40, deadline=None)
@given(surface=surfaces(min_b=1, max_b=12, max_o=12, max_n=4))
def test_paths_are_valid_and_cost_is_their_sum(left: bool, top: bool, surface: Surface) -> None:
    e, overlap = surface
    n, size, _ = e.shape
    cut_cols, cut_rows, cost = minimum_error_cuts(e, left=left, top=top, overlap=overlap)
    assert cut_cols.shape == cut_rows.shape == (n, size)
    assert cut_cols.dtype == cut_rows.dtype == np.int16
    assert cost.shape == (n,)
    assert cost.dtype == np.float64
    for k in range(n):
        if left:
            assert_valid_path(cut_cols[k], overlap)
        else:
            assert np.all(cut_cols[k] == 0)
        if top:
            assert_valid_path(cut_rows[k], overlap)
        else:
            assert np.all(cut_rows[k] == 0)
        expected = path_cost(e[k], cut_cols[k], cut_rows[k], left, top, overlap)
        assert cost[k] == pytest.approx(expected, rel=1e-9, abs=1e-9)


def _cost_to_go_reference(e: NDArray[np.float64], overlap: int) -> list[list[float]]:
    """Cheapest cost from each pixel of the left strip down to the last row: scalar DP."""
    size = e.shape[0]
    E = [[0.0] * overlap for _ in range(size)]
    for y in range(size - 1, -1, -1):
        for x in range(overlap):
            below = [E[y + 1][c] for c in (x - 1, x, x + 1) if y + 1 < size and 0 <= c < overlap]
            E[y][x] = float(e[y, x]) + (min(below) if below else 0.0)
    return E


@settings(max_examples=40, deadline=None)
@given(surface=surfaces(min_b=1, max_b=12, max_o=12, max_n=3))
def test_l_cut_meets_at_least_total_in_corner(surface: Surface) -> None:
    e, overlap = surface
    cut_cols, cut_rows, cost = minimum_error_cuts(e, left=True, top=True, overlap=overlap)
    for k in range(e.shape[0]):
        Ev = _cost_to_go_reference(e[k], overlap)
        Eh = _cost_to_go_reference(e[k].T, overlap)  # Eh[x][y]
        totals = {
            (y, x): Ev[y][x] + Eh[x][y] - float(e[k, y, x])
            for y in range(overlap)
            for x in range(overlap)
        }
        py, px = meeting_point(cut_cols[k], cut_rows[k], overlap)
        # The cut is the cheapest through its meeting point, and that point is a least one.
        assert cost[k] == pytest.approx(totals[(py, px)], rel=1e-9, abs=1e-9)
        assert cost[k] == pytest.approx(min(totals.values()), rel=1e-9, abs=1e-9)


def test_follows_a_zero_valley() -> None:
    size, overlap = 9, 4
    e = np.ones((1, size, size))
    vertical = [0, 1, 2, 3, 3, 2, 2, 1, 1]
    for y, x in enumerate(vertical):
        e[0, y, x] = 0.0
    cut_cols, cut_rows, cost = minimum_error_cuts(e, left=True, top=False, overlap=overlap)
    assert cut_cols[0].tolist() == vertical
    assert np.all(cut_rows == 0)
    assert cost[0] == 0.0


def test_l_cut_follows_an_l_shaped_valley() -> None:
    size, overlap = 10, 4
    e = np.full((1, size, size), 5.0)
    py, px = 2, 1
    vertical = [px, px, 1, 2, 3, 3, 2, 1, 0, 0]  # used from row py down
    horizontal = [py, py, 2, 3, 2, 1, 0, 0, 1, 2]  # used from column px right
    for y in range(py, size):
        e[0, y, vertical[y]] = 0.0
    for x in range(px, size):
        e[0, horizontal[x], x] = 0.0
    cut_cols, cut_rows, cost = minimum_error_cuts(e, left=True, top=True, overlap=overlap)
    assert cut_cols[0].tolist() == vertical
    assert cut_rows[0].tolist() == horizontal
    assert meeting_point(cut_cols[0], cut_rows[0], overlap) == (py, px)
    assert cost[0] == 0.0


def test_ties_on_a_flat_surface() -> None:
    overlap = 3
    e = np.zeros((2, 6, 6))
    e[1] = 3.0
    for left, top in KINDS:
        cut_cols, cut_rows, _ = minimum_error_cuts(e, left=left, top=top, overlap=overlap)
        # All zero: every cut costs 0; the first start and the first corner point win.
        assert np.all(cut_cols[0] == 0)
        assert np.all(cut_rows[0] == 0)
        assert np.all(new_block_mask(cut_cols[:1], cut_rows[:1]))
        if left and top:
            # Constant > 0: the far corner point gives the shortest paths, which go straight.
            assert np.all(cut_cols[1] == overlap - 1)
            assert np.all(cut_rows[1] == overlap - 1)
        else:
            assert np.all(cut_cols[1] == 0)
            assert np.all(cut_rows[1] == 0)


def test_ties_prefer_going_straight() -> None:
    e = np.zeros((1, 7, 7))
    e[0, 0, 0] = 1.0  # only the first row's cost decides where the path starts
    cut_cols, _, cost = minimum_error_cuts(e, left=True, top=False, overlap=3)
    assert cut_cols[0].tolist() == [1] * 7
    assert cost[0] == 0.0
    _, cut_rows, _ = minimum_error_cuts(e.transpose(0, 2, 1), left=False, top=True, overlap=3)
    assert cut_rows[0].tolist() == [1] * 7


@pytest.mark.parametrize(("left", "top"), ALL_KINDS, ids=ALL_KIND_IDS)
@pytest.mark.parametrize("cut", [minimum_error_cuts, straight_cuts])
def test_batch_equals_one_block_at_a_time(left: bool, top: bool, cut: object) -> None:
    assert callable(cut)
    rng = np.random.default_rng(7)
    size, overlap = 48, 8
    e = rng.random((20, size, size)) * 3.0
    # A few integer surfaces so that ties are exercised too.
    e[::4] = np.floor(e[::4])
    batch = cut(e, left=left, top=top, overlap=overlap)
    for k in range(e.shape[0]):
        alone = cut(e[k : k + 1], left=left, top=top, overlap=overlap)
        for got, want in zip(batch, alone, strict=True):
            assert np.array_equal(got[k : k + 1], want)


@pytest.mark.parametrize("cut", [minimum_error_cuts, straight_cuts])
def test_no_overlap_is_all_new_and_free(cut: object) -> None:
    assert callable(cut)
    e = np.random.default_rng(1).random((3, 6, 6))
    cut_cols, cut_rows, cost = cut(e, left=False, top=False, overlap=2)
    assert np.all(cut_cols == 0)
    assert np.all(cut_rows == 0)
    assert np.all(cost == 0.0)
    assert np.all(new_block_mask(cut_cols, cut_rows))


@pytest.mark.parametrize(("left", "top"), ALL_KINDS, ids=ALL_KIND_IDS)
@pytest.mark.parametrize("cut", [minimum_error_cuts, straight_cuts])
def test_empty_batch(left: bool, top: bool, cut: object) -> None:
    assert callable(cut)
    cut_cols, cut_rows, cost = cut(np.zeros((0, 8, 8)), left=left, top=top, overlap=2)
    assert cut_cols.shape == cut_rows.shape == (0, 8)
    assert cost.shape == (0,)
    assert new_block_mask(cut_cols, cut_rows).shape == (0, 8, 8)


@pytest.mark.parametrize("cut", [minimum_error_cuts, straight_cuts])
@pytest.mark.parametrize("overlap", [0, -1, 9])
def test_overlap_out_of_range_is_refused(cut: object, overlap: int) -> None:
    assert callable(cut)
    with pytest.raises(InvalidParameterError, match="overlap"):
        cut(np.zeros((1, 8, 8)), left=True, top=True, overlap=overlap)


@pytest.mark.parametrize("shape", [(8, 8), (1, 8, 7), (1, 2, 8, 8), (1, 0, 0)])
def test_bad_surface_shape_is_refused(shape: tuple[int, ...]) -> None:
    with pytest.raises(InvalidParameterError):
        minimum_error_cuts(np.zeros(shape), left=True, top=False, overlap=2)


# --- straight_cuts --------------------------------------------------------------------------


@pytest.mark.parametrize(("left", "top"), KINDS, ids=KIND_IDS)
@settings(max_examples=30, deadline=None)
@given(surface=surfaces(min_b=1, max_b=10, max_o=10))
def test_straight_cuts_against_direct_computation(left: bool, top: bool, surface: Surface) -> None:
    e, overlap = surface
    n, size, _ = e.shape
    c = overlap // 2
    cut_cols, cut_rows, cost = straight_cuts(e, left=left, top=top, overlap=overlap)
    assert cut_cols.dtype == cut_rows.dtype == np.int16
    assert np.all(cut_cols == (c if left else 0))
    assert np.all(cut_rows == (c if top else 0))
    for k in range(n):
        if left and top:
            assert meeting_point(cut_cols[k], cut_rows[k], overlap) == (c, c)
            pixels = {(y, c) for y in range(c, size)} | {(c, x) for x in range(c, size)}
        elif left:
            pixels = {(y, c) for y in range(size)}
        else:
            pixels = {(c, x) for x in range(size)}
        expected = sum(float(e[k, y, x]) for y, x in pixels)
        assert cost[k] == pytest.approx(expected, rel=1e-9, abs=1e-9)
        assert cost[k] == pytest.approx(
            path_cost(e[k], cut_cols[k], cut_rows[k], left, top, overlap), rel=1e-9, abs=1e-9
        )


# --- new_block_mask -------------------------------------------------------------------------


@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_mask_matches_naive_rule_on_arbitrary_cuts(data: st.DataObject) -> None:
    size = data.draw(st.integers(1, 8))
    n = data.draw(st.integers(0, 3))
    cuts = hnp.arrays(np.int16, (n, size), elements=st.integers(0, size))
    cut_cols = data.draw(cuts)
    cut_rows = data.draw(cuts)
    mask = new_block_mask(cut_cols, cut_rows)
    assert mask.dtype == np.bool_
    assert np.array_equal(mask, naive_mask(cut_cols, cut_rows))


@pytest.mark.parametrize(("left", "top"), KINDS, ids=KIND_IDS)
@settings(max_examples=30, deadline=None)
@given(surface=surfaces(min_b=2, max_b=10, max_o=5))
def test_mask_of_real_cuts(left: bool, top: bool, surface: Surface) -> None:
    e, overlap = surface
    n, size, _ = e.shape
    cut_cols, cut_rows, _ = minimum_error_cuts(e, left=left, top=top, overlap=overlap)
    mask = new_block_mask(cut_cols, cut_rows)
    assert np.array_equal(mask, naive_mask(cut_cols, cut_rows))

    in_strips = np.zeros((size, size), dtype=bool)
    if left:
        in_strips[:, :overlap] = True
    if top:
        in_strips[:overlap, :] = True
    assert np.all(mask[:, ~in_strips]), "pixels outside the overlap must be new"

    xs = np.arange(size)
    for k in range(n):
        if left and not top:
            assert np.array_equal(mask[k], xs[None, :] >= cut_cols[k][:, None])
        elif top and not left:
            assert np.array_equal(mask[k], xs[:, None] >= cut_rows[k][None, :])
        else:
            py, px = meeting_point(cut_cols[k], cut_rows[k], overlap)
            assert not mask[k, :py, :px].any(), "the region above-left of p must stay old"
            # Left of p's column only the vertical path decides (the fill rule puts the
            # horizontal one at row py there), above p's row only the horizontal path does.
            left_part = xs[None, :px] >= cut_cols[k, py:, None]
            assert np.array_equal(mask[k, py:, :px], left_part)
            top_part = xs[:py, None] >= cut_rows[k, None, px:]
            assert np.array_equal(mask[k, :py, px:], top_part)
            # Nothing left of the vertical path or above the horizontal path is new.
            for y in range(py, size):
                assert not mask[k, y, : cut_cols[k, y]].any()
            for x in range(px, size):
                assert not mask[k, : cut_rows[k, x], x].any()


@st.composite
def strips(draw: st.DrawFn) -> NDArray[np.float64]:
    """(n, L, O) strips of any proportions; half the time small integers, so many ties."""
    n, length, width = draw(st.integers(1, 3)), draw(st.integers(1, 7)), draw(st.integers(1, 5))
    if draw(st.booleans()):
        elements = st.integers(0, 2).map(float)
    else:
        elements = st.floats(0.0, 100.0, allow_nan=False, allow_infinity=False)
    return draw(hnp.arrays(np.float64, (n, length, width), elements=elements))


@settings(max_examples=200, deadline=None)
@given(strips())
def test_strip_cuts_are_the_left_cut_of_the_padded_square(e: NDArray[np.float64]) -> None:
    """Zero rows below a strip add no cost or constraint: the square DP on the padded surface
    is the same cut, ties included; and its cost is the brute-force minimum."""
    n, length, width = e.shape
    positions, cost = strip_cuts(e)
    size = max(length, width)
    square = np.zeros((n, size, size))
    square[:, :length, :width] = e
    cols, _, square_cost = minimum_error_cuts(square, left=True, top=False, overlap=width)
    assert np.array_equal(positions, cols[:, :length])
    assert np.array_equal(cost, square_cost)
    for k in range(n):
        path = positions[k]
        assert np.all(np.abs(np.diff(path)) <= 1) and path.min() >= 0 and path.max() < width
        assert cost[k] == pytest.approx(float(e[k, np.arange(length), path].sum()))
        best = min(
            sum(float(e[k, row, c]) for row, c in enumerate(cols))
            for start in range(width)
            for cols in _paths_down(0, start, length, width)
        )
        assert cost[k] == pytest.approx(best)


def test_strip_cuts_refuse_an_empty_strip() -> None:
    with pytest.raises(InvalidParameterError):
        strip_cuts(np.zeros((1, 0, 3)))


# --- the edge cost: seams off the bands' edges ---------------------------------------------


def _edge_surface(
    edge: float, size: int = 12, overlap: int = 5, rows: bool = True
) -> NDArray[np.float64]:
    """An error surface of ones, a little noise, and its first and last strip columns at
    ``edge`` (and the top strip's first and last rows, if ``rows``)."""
    rng = np.random.default_rng(4)
    e = 1.0 + 0.01 * rng.random((1, size, size))
    for index in (0, overlap - 1):
        e[0, :, index] = edge
        if rows:
            e[0, index, :] = edge
    return e


def _plain_error(
    e: NDArray[np.float64],
    cut_cols: NDArray[np.int16],
    cut_rows: NDArray[np.int16],
    left: bool,
    top: bool,
) -> float:
    """Sum of ``e`` over the pixels of the cut paths (overlap 5; the L-shaped paths from
    their meeting point on, that point once)."""
    pixels: set[tuple[int, int]] = set()
    size = e.shape[1]
    py = px = 0
    if left and top:
        py, px = meeting_point(cut_cols[0], cut_rows[0], 5)
    if left:
        pixels |= {(y, int(cut_cols[0, y])) for y in range(py, size)}
    if top:
        pixels |= {(int(cut_rows[0, x]), x) for x in range(px, size)}
    return float(sum(e[0, y, x] for y, x in pixels))


@pytest.mark.parametrize(("left", "top"), [(True, False), (False, True), (True, True)])
def test_the_edge_cost_keeps_a_cut_off_the_bands_edges(left: bool, top: bool) -> None:
    """Edges 5 % cheaper than the inside: the plain cut runs along them, the engine's edge cost
    (10 % of the strips' mean error) takes it inside; ``cost`` is the plain error of the path
    taken, in both."""
    overlap = 5
    e = _edge_surface(0.95, overlap=overlap)
    plain = minimum_error_cuts(e, left=left, top=top, overlap=overlap)
    moved = minimum_error_cuts(e, left=left, top=top, overlap=overlap, edge_cost=EDGE_COST)
    for cuts, along in ((plain, True), (moved, False)):
        cut_cols, cut_rows, cost = cuts
        on_edge = []
        if left:
            on_edge.append(np.isin(cut_cols[0, overlap:], (0, overlap - 1)))
        if top:
            on_edge.append(np.isin(cut_rows[0, overlap:], (0, overlap - 1)))
        edge_share = float(np.concatenate(on_edge).mean())
        assert edge_share == (1.0 if along else 0.0), (along, edge_share)
        assert cost[0] == pytest.approx(_plain_error(e, cut_cols, cut_rows, left, top))
    assert moved[2][0] > plain[2][0]  # the moved path crosses more error


def test_a_straight_edge_in_the_texture_still_carries_the_cut() -> None:
    """Where the error along a band's edge is far lower than inside (the texture has a straight
    edge there), the cut keeps to it with the edge cost as without."""
    overlap = 5
    e = _edge_surface(0.5, overlap=overlap, rows=False)
    plain = minimum_error_cuts(e, left=True, top=False, overlap=overlap)
    moved = minimum_error_cuts(e, left=True, top=False, overlap=overlap, edge_cost=EDGE_COST)
    assert np.array_equal(plain[0], moved[0]) and plain[2][0] == moved[2][0]
    assert set(plain[0][0].tolist()) <= {0, overlap - 1}


# --- the context: the error around a path's pixels ---------------------------------------------


def _context_reference(
    e: NDArray[np.float64], left: bool, top: bool, overlap: int, weight: float
) -> NDArray[np.float64]:
    """What the paths see with a context, written out pixel by pixel: on the strips,
    ``(e + w * mean of e over the strip pixels within CONTEXT_RADIUS) / (1 + w)``."""
    size = e.shape[0]
    strips = np.zeros((size, size), dtype=bool)
    if left:
        strips[:, :overlap] = True
    if top:
        strips[:overlap, :] = True
    seen = e.copy()
    r = CONTEXT_RADIUS
    for y, x in zip(*np.nonzero(strips), strict=True):
        window = strips[max(0, y - r) : y + r + 1, max(0, x - r) : x + r + 1]
        values = e[max(0, y - r) : y + r + 1, max(0, x - r) : x + r + 1][window]
        seen[y, x] = (e[y, x] + weight * values.mean()) / (1 + weight)
    return seen


@pytest.mark.parametrize(("left", "top"), KINDS, ids=KIND_IDS)
@settings(max_examples=40, deadline=None)
@given(surface=surfaces(max_b=6, max_o=3), weight=st.sampled_from([CONTEXT, 2.0]))
def test_with_a_context_the_path_is_the_cheapest_on_the_context_surface(
    left: bool, top: bool, surface: Surface, weight: float
) -> None:
    """The cut is a cheapest path by brute force over the surface the context describes (the
    edge cost added to it), and its cost is the plain error along it."""
    e, overlap = surface
    cut_cols, cut_rows, cost = minimum_error_cuts(
        e, left=left, top=top, overlap=overlap, context=weight
    )
    for k in range(e.shape[0]):
        seen = _context_reference(e[k], left, top, overlap, weight)
        taken = path_cost(seen, cut_cols[k], cut_rows[k], left, top, overlap)
        assert taken == pytest.approx(brute_force(seen, left, top, overlap), rel=1e-9, abs=1e-9)
        plain = path_cost(e[k], cut_cols[k], cut_rows[k], left, top, overlap)
        assert cost[k] == pytest.approx(plain, rel=1e-12, abs=1e-12)


def test_a_context_takes_the_cut_where_the_sides_agree_around_it() -> None:
    """A column of pixels that agree by chance inside a band of disagreement, and a column
    of slightly worse pixels inside a band of agreement: the plain cut threads the first,
    the cut with the engine's context the second."""
    size, overlap = 16, 8
    e = np.full((1, size, size), 1.0)
    e[0, :, 0:3] = 1.0
    e[0, :, 1] = 0.0  # agrees on the path only, its neighbours disagree
    e[0, :, 4:8] = 0.05  # agrees all around
    e[0, :, 5] = 0.1
    plain = minimum_error_cuts(e, left=True, top=False, overlap=overlap)
    held = minimum_error_cuts(e, left=True, top=False, overlap=overlap, context=CONTEXT)
    assert np.all(plain[0][0] == 1)
    assert set(held[0][0].tolist()) <= {4, 5, 6, 7} and 5 not in held[0][0][2:-2].tolist()
    assert held[2][0] > plain[2][0]  # the plain error it crosses is larger


def test_no_context_is_the_plain_cut() -> None:
    e = np.random.default_rng(9).random((20, 10, 10))
    for left, top in KINDS:
        plain = minimum_error_cuts(e, left=left, top=top, overlap=4)
        zero = minimum_error_cuts(e, left=left, top=top, overlap=4, context=0.0)
        for a, b in zip(plain, zero, strict=True):
            assert np.array_equal(a, b)
