"""The search of a fill's blocks (:mod:`quilting.core.fill_search`): the scale rule, the
averaged level, and the blocks chosen at full size and coarse to fine, checked against a
brute-force scan of every source position."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from quilting.core.exclusion import CandidateField
from quilting.core.fill_search import (
    COARSE_BLOCK,
    FULL_SEARCH_PIXELS,
    MAX_AUTO_SCALE,
    FillSearch,
    averaged,
    search_scale,
)
from quilting.core.progress import Clock
from quilting.core.randomness import BlockRandom
from quilting.costs.registry import get_backend

BLOCK = 8
TOLERANCE = 0.1
LEAST = 1


def _source(seed: int, size: int = 40, channels: int = 3) -> NDArray[np.float32]:
    """A smooth random image: neighbouring positions cost alike, so that the tolerance rule
    accepts several candidates and the search has something to decide."""
    rng = np.random.default_rng(seed)
    noise = rng.random((size + 4, size + 4, channels), dtype=np.float32)
    smooth = sum(noise[dy : dy + size, dx : dx + size] for dy in range(4) for dx in range(4))
    return np.ascontiguousarray(smooth / np.float32(16.0), dtype=np.float32)


def _brute_costs(
    source: NDArray[np.float32], template: NDArray[np.float32], mask: NDArray[np.bool_]
) -> NDArray[np.float64]:
    """The masked SSD of ``template`` at every top-left corner of ``source``, flat, float64."""
    height, width = source.shape[:2]
    rows, cols = height - BLOCK + 1, width - BLOCK + 1
    costs = np.empty(rows * cols, dtype=np.float64)
    weight = mask[..., None].astype(np.float64)
    for y in range(rows):
        for x in range(cols):
            diff = source[y : y + BLOCK, x : x + BLOCK].astype(np.float64) - template
            costs[y * cols + x] = float((weight * diff * diff).sum())
    return costs


def _search(source: NDArray[np.float32], field: CandidateField, scale: int) -> FillSearch:
    return FillSearch(source, BLOCK, field, get_backend("fft"), Clock(), scale, TOLERANCE, LEAST)


def _choose(
    search: FillSearch, templates: NDArray[np.float32], masks: NDArray[np.bool_], seed: int
) -> NDArray[np.intp]:
    rngs = [BlockRandom(seed, 0, 0, k) for k in range(len(templates))]
    search.prepare()
    try:
        return search.choose(templates, masks, rngs)
    finally:
        search.close()


def _masks(count: int, seed: int) -> NDArray[np.bool_]:
    """L-shaped, strip and scattered masks of known pixels, each with at least one."""
    rng = np.random.default_rng(seed)
    masks = np.zeros((count, BLOCK, BLOCK), dtype=bool)
    for k in range(count):
        kind = k % 3
        if kind == 0:
            masks[k, :3], masks[k, :, :3] = True, True
        elif kind == 1:
            masks[k, :, :2] = True
        else:
            masks[k] = rng.random((BLOCK, BLOCK)) < 0.4
            masks[k, 0, 0] = True
    return masks


def test_search_scale_keeps_a_requested_scale_and_picks_one_by_the_source_and_block() -> None:
    assert search_scale(3, 64, (4096, 4096)) == 3
    small = (int(FULL_SEARCH_PIXELS**0.5), int(FULL_SEARCH_PIXELS**0.5))
    assert small[0] * small[1] <= FULL_SEARCH_PIXELS
    large = (small[0] + 1, small[1] + 1)
    for block in (3, 8, 16, 24, 32, 48, 64, 128):
        assert search_scale(0, block, small) == 1
        expected = max(1, min(MAX_AUTO_SCALE, block // COARSE_BLOCK))
        assert search_scale(0, block, large) == expected
        assert 1 <= search_scale(0, block, large) <= MAX_AUTO_SCALE


@pytest.mark.parametrize("scale", [1, 2, 3, 4])
def test_averaged_is_the_mean_of_each_cell_the_remainder_dropped(scale: int) -> None:
    image = np.random.default_rng(scale).random((13, 11, 2), dtype=np.float32)
    mean = averaged(image, scale)
    rows, cols = 13 // scale, 11 // scale
    assert mean.shape == (rows, cols, 2) and mean.dtype == np.float32
    for y in range(rows):
        for x in range(cols):
            cell = image[y * scale : (y + 1) * scale, x * scale : (x + 1) * scale]
            naive = cell.astype(np.float64).mean(axis=(0, 1)).astype(np.float32)
            np.testing.assert_allclose(mean[y, x], naive, rtol=1e-6)


def test_the_full_size_search_takes_a_block_the_tolerance_rule_accepts() -> None:
    """Every choice is within (1 + tolerance) of the best exact cost, found by brute force."""
    source = _source(1)
    field = CandidateField.of(source.shape, BLOCK)
    rng = np.random.default_rng(2)
    count = 9
    templates = rng.random((count, BLOCK, BLOCK, 3), dtype=np.float32)
    # Some templates close to a source block, so that the best is far below the rest.
    for k in range(0, count, 2):
        y, x = rng.integers(0, source.shape[0] - BLOCK + 1, size=2)
        near = source[y : y + BLOCK, x : x + BLOCK]
        templates[k] = near + rng.normal(0, 0.01, near.shape).astype(np.float32)
    masks = _masks(count, 3)
    chosen = _choose(_search(source, field, 1), templates, masks, seed=5)
    assert chosen.shape == (count,)
    for k in range(count):
        costs = _brute_costs(source, templates[k], masks[k])
        best = np.sort(costs)[LEAST - 1]
        assert costs[chosen[k]] <= (1 + TOLERANCE) * best * (1 + 1e-9) + 1e-9, k


def test_the_choice_is_a_uniform_draw_among_the_accepted_not_always_the_best() -> None:
    """Over many keys, one block with several accepted candidates takes more than one of
    them, and never one the rule refuses."""
    source = _source(4)
    field = CandidateField.of(source.shape, BLOCK)
    # Not a copy of any block (whose cost 0 would be the only one accepted): a flat grey
    # strip, which the smooth source's many grey strips match about as well.
    template = np.full((BLOCK, BLOCK, 3), source.mean(), dtype=np.float32)
    mask = np.zeros((BLOCK, BLOCK), dtype=bool)
    mask[:, :2] = True
    costs = _brute_costs(source, template, mask)
    accepted = set(np.flatnonzero(costs <= (1 + TOLERANCE) * costs.min() + 1e-9).tolist())
    assert len(accepted) > 1, "the test needs a block with several accepted candidates"
    picks: set[int] = set()
    search = _search(source, field, 1)
    for seed in range(24):
        picks.add(int(_choose(search, template[None], mask[None], seed)[0]))
    assert picks <= accepted
    assert len(picks) > 1


def test_an_exact_copy_is_found_at_full_size_and_an_excluded_one_never() -> None:
    source = _source(6)
    template = source[17 : 17 + BLOCK, 5 : 5 + BLOCK].copy()
    mask = np.ones((1, BLOCK, BLOCK), dtype=bool)
    field = CandidateField.of(source.shape, BLOCK)
    at = 17 * field.width + 5
    found = _choose(_search(source, field, 1), template[None], mask, seed=1)
    assert found.tolist() == [at]
    # The copy's pixels excluded: a block holding any of them is never taken.
    excluded = np.zeros(source.shape[:2], dtype=bool)
    excluded[17 + BLOCK // 2, 5 + BLOCK // 2] = True
    field = CandidateField.of(source.shape, BLOCK, excluded)
    assert field.allowed is not None and not field.allowed[at]
    for scale in (1, 2):
        taken = _choose(_search(source, field, scale), template[None], mask, seed=1)
        assert field.allowed[taken].all(), scale


@pytest.mark.parametrize("scale", [2, 4])
def test_coarse_to_fine_finds_an_exact_copy_on_the_coarse_grid(scale: int) -> None:
    """A copy whose corner is a multiple of the scale has averaged cells equal to the
    template's: its coarse cost is 0, so the fine stage scores it and takes it."""
    source = _source(7, size=48)
    field = CandidateField.of(source.shape, BLOCK)
    y, x = 4 * scale, 5 * scale
    template = source[y : y + BLOCK, x : x + BLOCK].copy()
    masks = np.ones((2, BLOCK, BLOCK), dtype=bool)
    masks[1, 3:, 3:] = False  # an L of known pixels, as a fill's border block has
    templates = np.stack([template, template])
    found = _choose(_search(source, field, scale), templates, masks, seed=3)
    assert found.tolist() == [y * field.width + x] * 2


def test_coarse_to_fine_chooses_among_the_positions_it_scored_exactly() -> None:
    """Coarse to fine takes a block the tolerance rule accepts among the fine positions of
    the coarse cells it kept: never worse than (1 + tolerance) times the best of those, and
    never worse than a brute-force best over the whole source scaled by a loose margin
    (the coarse stage may miss the global best, not land far from it on a smooth image)."""
    source = _source(8, size=48)
    field = CandidateField.of(source.shape, BLOCK)
    rng = np.random.default_rng(9)
    count = 6
    templates = np.empty((count, BLOCK, BLOCK, 3), dtype=np.float32)
    for k in range(count):
        y, x = rng.integers(0, source.shape[0] - BLOCK + 1, size=2)
        near = source[y : y + BLOCK, x : x + BLOCK]
        templates[k] = near + rng.normal(0, 0.02, near.shape).astype(np.float32)
    masks = _masks(count, 10)
    search = _search(source, field, 2)
    first = _choose(search, templates, masks, seed=11)
    again = _choose(search, templates, masks, seed=11)
    np.testing.assert_array_equal(first, again)
    for k in range(count):
        costs = _brute_costs(source, templates[k], masks[k])
        assert 0 <= first[k] < field.size
        # The noise's own cost (0.02² a known value) bounds what a good pick costs.
        floor = 0.02**2 * 3 * masks[k].sum()
        assert costs[first[k]] <= (1 + TOLERANCE) * max(costs.min(), floor) * 4, k
