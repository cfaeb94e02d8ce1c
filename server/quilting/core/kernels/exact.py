"""Compiled exact costs: the float64 sums of :class:`quilting.core.fields.ExactScorer`.

A candidate's exact cost decides whether it is acceptable, so it must be the same number as
the numpy code it replaced gave, to the last bit: per support pixel the squared differences
summed over channels in sequence, times the mask's weight, and those summed over the support
by numpy's pairwise summation (runs of up to 128 values added eight ways and combined as a
tree, longer runs halved). A transfer term is the same sum over the whole block with weights
1 (a product by 1 is exact). ``tests/core/test_kernels.py`` checks it against numpy.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numpy.typing import NDArray

#: numpy's pairwise summation: runs of at most this many are added eight ways.
_PW_BLOCK = 128


@nb.njit(cache=True)
def _pairwise_run(values: NDArray[np.float64], start: int, count: int) -> float:
    """numpy's sum of ``values[start:start + count]``, ``count <= _PW_BLOCK``."""
    if count < 8:
        total = 0.0
        for i in range(count):
            total += values[start + i]
        return total
    r0 = values[start]
    r1 = values[start + 1]
    r2 = values[start + 2]
    r3 = values[start + 3]
    r4 = values[start + 4]
    r5 = values[start + 5]
    r6 = values[start + 6]
    r7 = values[start + 7]
    i = 8
    end = count - count % 8
    while i < end:
        r0 += values[start + i]
        r1 += values[start + i + 1]
        r2 += values[start + i + 2]
        r3 += values[start + i + 3]
        r4 += values[start + i + 4]
        r5 += values[start + i + 5]
        r6 += values[start + i + 6]
        r7 += values[start + i + 7]
        i += 8
    total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < count:
        total += values[start + i]
        i += 1
    return float(total)


@nb.njit(cache=True)
def pairwise_sum(values: NDArray[np.float64], count: int) -> float:
    """``values[:count].sum()`` exactly as numpy adds a contiguous float64 run.

    numpy halves a run longer than :data:`_PW_BLOCK` (the first half rounded down to a
    multiple of 8) and adds the halves' sums; this walks the same tree with an explicit
    stack, since numba's on-disk cache does not take recursive functions.
    """
    if count <= _PW_BLOCK:
        return _pairwise_run(values, 0, count)
    starts = np.empty(64, dtype=np.int64)
    counts = np.empty(64, dtype=np.int64)
    states = np.empty(64, dtype=np.int64)  # 0: not split, 1: left half pushed, 2: both
    sums = np.empty(64, dtype=np.float64)
    frames = 1
    depth = 0
    starts[0] = 0
    counts[0] = count
    states[0] = 0
    while frames > 0:
        top = frames - 1
        start = starts[top]
        length = counts[top]
        if length <= _PW_BLOCK:
            sums[depth] = _pairwise_run(values, start, length)
            depth += 1
            frames -= 1
            continue
        half = length // 2
        half -= half % 8
        if states[top] == 0:
            states[top] = 1
            starts[frames] = start
            counts[frames] = half
            states[frames] = 0
            frames += 1
        elif states[top] == 1:
            states[top] = 2
            starts[frames] = start + half
            counts[frames] = length - half
            states[frames] = 0
            frames += 1
        else:
            depth -= 1
            sums[depth - 1] = sums[depth - 1] + sums[depth]
            frames -= 1
    return float(sums[0])


@nb.njit(cache=True)
def _masked(
    pixels: NDArray[np.float64],
    offsets: NDArray[np.intp],
    weights: NDArray[np.float64],
    targets: NDArray[np.float64],
    which: NDArray[np.intp],
    corners: NDArray[np.intp],
    out: NDArray[np.float64],
) -> None:
    support = offsets.shape[0]
    channels = pixels.shape[1]
    terms = np.empty(support, dtype=np.float64)
    for k in range(corners.shape[0]):
        target = targets[which[k]]
        corner = corners[k]
        for p in range(support):
            pixel = pixels[corner + offsets[p]]
            d = pixel[0] - target[p, 0]
            squared = d * d
            for c in range(1, channels):
                d = pixel[c] - target[p, c]
                squared = squared + d * d
            terms[p] = squared * weights[p]
        out[k] = pairwise_sum(terms, support)


def masked_costs(
    pixels: NDArray[np.float64],
    offsets: NDArray[np.intp],
    weights: NDArray[np.float64],
    targets: NDArray[np.float64],
    which: NDArray[np.intp],
    corners: NDArray[np.intp],
) -> NDArray[np.float64]:
    """``sum_p w_p sum_c (S[corner + o_p, c] - T[p, c])^2`` of each candidate.

    Parameters
    ----------
    pixels : ndarray, shape (H W, C), float64
        The source, flattened to pixel rows.
    offsets, weights : ndarray, shape (P,)
        The mask's support: flat offsets of its pixels from a block's corner, their weights.
    targets : ndarray, shape (m, P, C), float64
        Each request's template at the support.
    which, corners : ndarray of int, shape (k,)
        Each candidate's request (index into ``targets``) and flat corner in ``pixels``.

    Returns
    -------
    ndarray, shape (k,), float64
    """
    out = np.empty(corners.shape[0], dtype=np.float64)
    # Contiguous arguments of fixed types: one compiled signature, the one warm_up loads.
    _masked(
        np.ascontiguousarray(pixels, dtype=np.float64),
        np.ascontiguousarray(offsets, dtype=np.intp),
        np.ascontiguousarray(weights, dtype=np.float64),
        np.ascontiguousarray(targets, dtype=np.float64),
        np.ascontiguousarray(which, dtype=np.intp),
        np.ascontiguousarray(corners, dtype=np.intp),
        out,
    )
    return out
