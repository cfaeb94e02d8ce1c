"""Per-block random streams: :class:`BlockRandom` draws what the block's numpy generator draws,
whether its first draw is compiled or not."""

from __future__ import annotations

import numpy as np
import pytest

from quilting.core.randomness import BlockRandom, block_rng

PLACES = [(0, 0, 0, 0), (1, 0, 3, 4), (7, 2, 49, 50), (2**40 + 5, 1, 0, 9), (3, 0, 2**32, 1)]


@pytest.mark.parametrize("key", PLACES)
@pytest.mark.parametrize("high", [1, 2, 40, 2**31 + 1, 2**32, 2**40])
def test_draws_are_the_generators(key: tuple[int, int, int, int], high: int) -> None:
    expected = block_rng(*key)
    stream = BlockRandom(*key)
    # The first integer (compiled where it can be), then the generator past it.
    assert stream.integers(high) == int(expected.integers(high))
    assert stream.integers(high) == int(expected.integers(high))
    assert stream.random() == float(expected.random())
    assert stream.generator.integers(0, 2**64, dtype=np.uint64) == expected.integers(
        0, 2**64, dtype=np.uint64
    )


@pytest.mark.parametrize("key", PLACES)
def test_a_stream_that_starts_elsewhere_is_the_generators(key: tuple[int, int, int, int]) -> None:
    expected = block_rng(*key)
    stream = BlockRandom(*key)
    assert stream.random() == float(expected.random())
    assert stream.integers(97) == int(expected.integers(97))
    other = BlockRandom(*key)
    assert other.generator.integers(0, 2**64, size=2, dtype=np.uint64).tolist() == (
        block_rng(*key).integers(0, 2**64, size=2, dtype=np.uint64).tolist()
    )


def test_streams_differ_by_block_and_pass() -> None:
    draws = {
        BlockRandom(5, p, r, c).integers(2**31) for p in (0, 1) for r in range(4) for c in range(4)
    }
    assert len(draws) == 32


def test_bad_draws_fail_as_numpys() -> None:
    with pytest.raises(ValueError, match="high <= 0"):
        BlockRandom(1, 0, 2, 3).integers(0)
    with pytest.raises(ValueError):
        np.random.SeedSequence([-1, 0, 2, 3])
    with pytest.raises(ValueError, match="non-negative"):
        BlockRandom(-1, 0, 2, 3).integers(5)
