"""Compiled first draw of a block's random stream, without making its numpy generator.

Every block draws from ``Generator(PCG64(SeedSequence([seed, pass, row, col])))``
(:mod:`quilting.core.randomness`), and most blocks draw once: ``integers(n)``, the pick among
their acceptable candidates. Making the three numpy objects costs about 9 µs a block (a fifth
of the selection stage at 2048²); this kernel computes the same number from the same words in
about 0.3 µs, so the generator is made only for a block that draws anything else.

It does numpy's integer arithmetic step for step (numpy 1.17 and later; the tests compare it
with numpy over seeds of one to four 32-bit words and bounds that exercise the rejection):

1. ``SeedSequence``: the entropy words hashed into a pool of 4 words (``mix_entropy``), and 8
   words generated from the pool (``generate_state(4, uint64)``);
2. ``PCG64``: the 128-bit state and increment seeded from them (``pcg64_set_seed``: state 0,
   one step, the seed added, one step), then one step and the XSL-RR output for each 64-bit
   draw, 128-bit arithmetic on two 64-bit halves;
3. ``Generator.integers(n)`` for ``n - 1 < 2**32 - 1``: Lemire's multiply-and-reject on
   32-bit draws, each 64-bit output giving its low half first and keeping its high half for
   the next draw.

All arithmetic is on ``uint64`` (numba widens ``uint32`` operations to 64 bits), masked to 32
bits where numpy works on ``uint32``.

References
----------
M. E. O'Neill, "PCG: A Family of Simple Fast Space-Efficient Statistically Good Algorithms
for Random Number Generation", Harvey Mudd College HMC-CS-2014-0905, 2014, §6 (the LCG step
and the XSL-RR output).

D. Lemire, "Fast Random Integer Generation in an Interval", ACM Transactions on Modeling and
Computer Simulation 29(1), 2019, §3 (the multiply-and-reject bound).
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numpy.typing import NDArray

_LOW32 = np.uint64(0xFFFFFFFF)
#: SeedSequence's hash constants (numpy/random/bit_generator.pyx).
_INIT_A = np.uint64(0x43B0D7E5)
_MULT_A = np.uint64(0x931E8875)
_INIT_B = np.uint64(0x8B51F9DD)
_MULT_B = np.uint64(0x58F38DED)
_MIX_L = np.uint64(0xCA01F9DD)
_MIX_R = np.uint64(0x4973F715)
#: PCG64's 128-bit multiplier, high and low halves.
_MULT_HIGH = np.uint64(2549297995355413924)
_MULT_LOW = np.uint64(4865540595714422341)
#: Largest ``high - 1`` drawn here: numpy draws ``high - 1 == 2**32 - 1`` and wider ranges
#: another way.
_LARGEST = 0xFFFFFFFE


@nb.njit(cache=True, nogil=True, inline="always")
def _hashmix(value: np.uint64, constant: np.uint64) -> tuple[np.uint64, np.uint64]:
    """SeedSequence's ``hashmix`` of a 32-bit word, and the hash constant after it."""
    value = (value ^ constant) & _LOW32
    constant = (constant * _MULT_A) & _LOW32
    value = (value * constant) & _LOW32
    return value ^ (value >> np.uint64(16)), constant


@nb.njit(cache=True, nogil=True, inline="always")
def _mix(x: np.uint64, y: np.uint64) -> np.uint64:
    """SeedSequence's ``mix`` of two 32-bit words."""
    result = (_MIX_L * x - _MIX_R * y) & _LOW32
    return result ^ (result >> np.uint64(16))


@nb.njit(cache=True, nogil=True, inline="always")
def _product(a: np.uint64, b: np.uint64) -> tuple[np.uint64, np.uint64]:
    """The 128-bit product of two 64-bit words, (high, low)."""
    shift = np.uint64(32)
    a0, a1 = a & _LOW32, a >> shift
    b0, b1 = b & _LOW32, b >> shift
    p00, p01, p10 = a0 * b0, a0 * b1, a1 * b0
    middle = (p00 >> shift) + (p01 & _LOW32) + (p10 & _LOW32)
    low = (p00 & _LOW32) | ((middle & _LOW32) << shift)
    high = a1 * b1 + (p01 >> shift) + (p10 >> shift) + (middle >> shift)
    return high, low


@nb.njit(cache=True, nogil=True, inline="always")
def _add(
    high: np.uint64, low: np.uint64, add_high: np.uint64, add_low: np.uint64
) -> tuple[np.uint64, np.uint64]:
    """``(high, low) + (add_high, add_low)`` modulo 2**128."""
    total = low + add_low
    carry = np.uint64(1) if total < low else np.uint64(0)
    return high + add_high + carry, total


@nb.njit(cache=True, nogil=True, inline="always")
def _step(
    high: np.uint64, low: np.uint64, inc_high: np.uint64, inc_low: np.uint64
) -> tuple[np.uint64, np.uint64]:
    """PCG64's LCG step: ``state * multiplier + increment`` modulo 2**128."""
    product_high, product_low = _product(low, _MULT_LOW)
    product_high = product_high + low * _MULT_HIGH + high * _MULT_LOW
    return _add(product_high, product_low, inc_high, inc_low)


@nb.njit(cache=True, nogil=True, inline="always")
def _output(high: np.uint64, low: np.uint64) -> np.uint64:
    """PCG64's XSL-RR output of a state: its halves xor-ed, rotated right by its top 6 bits."""
    folded = high ^ low
    turn = high >> np.uint64(58)
    return (folded >> turn) | (folded << ((np.uint64(64) - turn) & np.uint64(63)))


@nb.njit(cache=True, nogil=True)
def _first_integer(prefix: NDArray[np.uint32], row: int, col: int, high: int) -> int:
    # SeedSequence([..., row, col]): the entropy is the prefix's words, then row's and col's
    # (one word each below 2**32). The prefix holds at least the seed's and the pass's words,
    # so the entropy fills the pool of 4 (numpy pads a shorter one with zeros).
    size = prefix.size + 2
    entropy = np.empty(size, dtype=np.uint64)
    for i in range(prefix.size):
        entropy[i] = np.uint64(prefix[i])
    entropy[size - 2] = np.uint64(row)
    entropy[size - 1] = np.uint64(col)
    pool = np.zeros(4, dtype=np.uint64)
    constant = _INIT_A
    for i in range(4):
        pool[i], constant = _hashmix(entropy[i], constant)
    for source in range(4):
        for target in range(4):
            if source != target:
                hashed, constant = _hashmix(pool[source], constant)
                pool[target] = _mix(pool[target], hashed)
    for source in range(4, size):
        for target in range(4):
            hashed, constant = _hashmix(entropy[source], constant)
            pool[target] = _mix(pool[target], hashed)
    # generate_state(4, uint64): 8 words, little-endian pairs.
    words = np.empty(8, dtype=np.uint64)
    constant = _INIT_B
    for i in range(8):
        word = pool[i % 4] ^ constant
        constant = (constant * _MULT_B) & _LOW32
        word = (word * constant) & _LOW32
        words[i] = word ^ (word >> np.uint64(16))
    seed_high = words[0] | (words[1] << np.uint64(32))
    seed_low = words[2] | (words[3] << np.uint64(32))
    sequence_high = words[4] | (words[5] << np.uint64(32))
    sequence_low = words[6] | (words[7] << np.uint64(32))
    # pcg64_set_seed: increment = sequence << 1 | 1; state 0, step, add the seed, step.
    inc_high = (sequence_high << np.uint64(1)) | (sequence_low >> np.uint64(63))
    inc_low = (sequence_low << np.uint64(1)) | np.uint64(1)
    state_high, state_low = _step(np.uint64(0), np.uint64(0), inc_high, inc_low)
    state_high, state_low = _add(state_high, state_low, seed_high, seed_low)
    state_high, state_low = _step(state_high, state_low, inc_high, inc_low)
    # integers(high): Lemire's rejection on 32-bit draws, low half of each output first.
    bound = np.uint64(high)
    state_high, state_low = _step(state_high, state_low, inc_high, inc_low)
    drawn = _output(state_high, state_low)
    kept = drawn >> np.uint64(32)
    buffered = True
    scaled = (drawn & _LOW32) * bound
    leftover = scaled & _LOW32
    if leftover < bound:
        threshold = (_LOW32 - (bound - np.uint64(1))) % bound
        while leftover < threshold:
            if buffered:
                word = kept
                buffered = False
            else:
                state_high, state_low = _step(state_high, state_low, inc_high, inc_low)
                drawn = _output(state_high, state_low)
                word, kept, buffered = drawn & _LOW32, drawn >> np.uint64(32), True
            scaled = word * bound
            leftover = scaled & _LOW32
    return int(scaled >> np.uint64(32))


def first_integer(prefix: NDArray[np.uint32], row: int, col: int, high: int) -> int | None:
    """``Generator(PCG64(SeedSequence([*prefix words, row, col]))).integers(high)``, the
    generator's first draw; None where numpy draws it another way (``high - 1`` of 2**32 - 1
    or more; ``high <= 0``, which numpy refuses) or ``row`` or ``col`` is 2**32 or more.

    Parameters
    ----------
    prefix : ndarray of uint32, shape (m,), m >= 2
        The entropy words before ``row`` and ``col`` (numpy's split of the seed and the pass
        into 32-bit words, least significant first, one word for 0).
    row, col : int
        Non-negative.
    high : int

    Returns
    -------
    int or None
        The first draw, in ``[0, high)``.
    """
    if not 0 < high <= _LARGEST + 1 or row >> 32 or col >> 32 or prefix.size < 2:
        return None
    return int(_first_integer(prefix, row, col, high))
