"""Per-block random streams.

Each block draws from its own generator derived from (seed, pass, row, col), so the output
depends on the seed alone, never on the schedule, the batch size, the thread count or the
backend. Most blocks draw one integer, the pick among their acceptable candidates:
:class:`BlockRandom` computes that first draw with a compiled kernel
(:mod:`quilting.core.kernels.draws`) and makes the numpy generator only for a block that draws
anything else, the same numbers either way.
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import NDArray

from quilting.core import kernels


def block_rng(seed: int, pass_index: int, row: int, col: int) -> np.random.Generator:
    """The generator of block (row, col) in pass ``pass_index`` of a job seeded ``seed``."""
    return np.random.Generator(
        np.random.PCG64(np.random.SeedSequence([seed, pass_index, row, col]))
    )


class BlockRandom:
    """The random stream of block (row, col) in pass ``pass_index``: the draws of
    :func:`block_rng`'s generator, which is made only when a draw needs it.

    Parameters
    ----------
    seed, pass_index, row, col : int
        Non-negative.
    """

    __slots__ = ("_first", "_generator", "_key")

    def __init__(self, seed: int, pass_index: int, row: int, col: int) -> None:
        self._key = (seed, pass_index, row, col)
        self._generator: np.random.Generator | None = None
        self._first = 0  # the bound of a first draw made without the generator, else 0

    @property
    def generator(self) -> np.random.Generator:
        """The block's numpy generator, past the draws already made."""
        if self._generator is None:
            self._generator = block_rng(*self._key)
            if self._first:
                self._generator.integers(self._first)  # replays the compiled first draw
        return self._generator

    def integers(self, high: int) -> int:
        """``generator.integers(high)``: an integer in ``[0, high)``."""
        if self._generator is None and not self._first:
            seed, pass_index, row, col = self._key
            drawn = kernels.first_integer(_prefix(seed, pass_index), row, col, high)
            if drawn is not None:
                self._first = high
                return drawn
        return int(self.generator.integers(high))

    def random(self) -> float:
        """``generator.random()``: a float in ``[0, 1)``."""
        return float(self.generator.random())


@functools.lru_cache(maxsize=16)
def _prefix(seed: int, pass_index: int) -> NDArray[np.uint32]:
    """The entropy words of ``SeedSequence([seed, pass_index, ...])`` before the row's: each
    number split into 32-bit words, least significant first (numpy's rule; 0 is one word)."""
    words: list[int] = []
    for number in (seed, pass_index):
        if number < 0:
            raise ValueError("expected non-negative integer")  # numpy's words for it
        words.append(number & 0xFFFFFFFF)
        number >>= 32
        while number:
            words.append(number & 0xFFFFFFFF)
            number >>= 32
    return np.array(words, dtype=np.uint32)
