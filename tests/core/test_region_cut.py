"""The region cut's kernel: a minimum cut, checked against every cut of small grids."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from quilting.core.kernels.region_cut import FREE, NEW, OLD, region_cuts


def _cost(errors: np.ndarray, owned: np.ndarray) -> np.ndarray:
    """Cut cost of a stack of ownerships (m, s, s): e(p) + e(q) over the separated pairs."""
    across = (owned[:, :, 1:] != owned[:, :, :-1]) * (errors[:, 1:] + errors[:, :-1])
    down = (owned[:, 1:, :] != owned[:, :-1, :]) * (errors[1:, :] + errors[:-1, :])
    return across.sum(axis=(1, 2)) + down.sum(axis=(1, 2))


def _brute_force(errors: np.ndarray, state: np.ndarray) -> float:
    free = np.argwhere(state == FREE)
    combos = np.array(list(itertools.product([False, True], repeat=len(free))), dtype=bool)
    owned = np.broadcast_to(state == NEW, (len(combos), *state.shape)).copy()
    owned[:, free[:, 0], free[:, 1]] = combos.reshape(len(combos), -1)
    return float(_cost(errors, owned).min())


@pytest.mark.parametrize("seed", range(40))
def test_cut_is_minimal_and_keeps_the_ties(seed: int) -> None:
    rng = np.random.default_rng(seed)
    side = 4
    errors = rng.random((side, side)) ** 2
    state = rng.choice([FREE, OLD, NEW], size=(side, side), p=[0.6, 0.2, 0.2]).astype(np.int8)
    owned = region_cuts(errors[None], state[None])[0]
    assert owned[state == NEW].all()
    assert not owned[state == OLD].any()
    assert _cost(errors, owned[None])[0] == pytest.approx(_brute_force(errors, state), abs=1e-12)


def test_cut_follows_the_cheap_valley() -> None:
    # Old on the left column, new on the right: the cut runs down the column of zero error.
    errors = np.ones((6, 6))
    errors[:, 3] = 0.0
    state = np.zeros((6, 6), dtype=np.int8)
    state[:, 0], state[:, 5] = OLD, NEW
    owned = region_cuts(errors[None], state[None])[0]
    # The edges 2-3 and 3-4 both cost 1 (e = 1 + 0): the cut takes one of them in every row.
    assert _cost(errors, owned[None])[0] == pytest.approx(6.0)
    assert (owned[:, :3] == False).all() and owned[:, 4:].all()  # noqa: E712


def test_batch_blocks_are_independent() -> None:
    rng = np.random.default_rng(3)
    errors = rng.random((3, 8, 8))
    state = rng.choice([FREE, OLD, NEW], size=(3, 8, 8), p=[0.8, 0.1, 0.1]).astype(np.int8)
    together = region_cuts(errors, state)
    for k in range(3):
        assert np.array_equal(together[k], region_cuts(errors[k : k + 1], state[k : k + 1])[0])


def test_without_old_pixels_the_block_takes_everything() -> None:
    state = np.full((1, 5, 5), FREE, dtype=np.int8)
    state[0, 2, 2] = NEW
    assert region_cuts(np.ones((1, 5, 5)), state).all()
