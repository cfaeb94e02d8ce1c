"""Compiled tolerance rule: a level's shortlists to acceptable sets, around one exact call.

:func:`quilting.core.select.acceptable` decides, for every block of a level, which of its
listed candidates are within ``(1 + tolerance)`` of the k-th best exact cost, from
approximate costs known within a bound. :func:`bracket` does what needs no exact cost (the
k-th listed value, the band of doubt around the threshold, the candidates that must be scored
exactly), the caller scores those in one call, and :func:`settle` draws the line. The
shortlists of a level are concatenated (``values[offsets[b]:offsets[b + 1]]`` is block b's),
so a level is two compiled calls instead of a Python loop over its blocks.

The arithmetic is the numpy code's it replaced: the same k-th values (``np.partition``), the
same float64 expressions for the band and the threshold, the same comparisons.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numpy.typing import NDArray


@nb.njit(cache=True)
def _kth(values: NDArray[np.float64], k: int) -> float:
    """The k-th smallest of ``values`` (1-based), k clipped to their number."""
    k = min(k, values.size)
    if k == 1:
        return float(values.min())
    return float(np.partition(values, k - 1)[k - 1])


@nb.njit(cache=True)
def bracket(
    values: NDArray[np.float64],
    offsets: NDArray[np.intp],
    bounds: NDArray[np.float64],
    scale: float,
    k: int,
) -> tuple[NDArray[np.bool_], NDArray[np.bool_], NDArray[np.bool_], NDArray[np.bool_]]:
    """What the approximate costs decide.

    Parameters
    ----------
    values : ndarray of float64, shape (m,)
        Every block's listed approximate costs, block after block.
    offsets : ndarray of intp, shape (n + 1,)
        Where each block's entries start (and, last, their total).
    bounds : ndarray of float64, shape (n,)
        Each block's error bound.
    scale : float
        ``1 + tolerance``.
    k : int
        ``min_candidates``.

    Returns
    -------
    inside : ndarray of bool, shape (m,)
        Entries under the highest threshold the exact costs could give (the rest are out).
    scored : ndarray of bool, shape (m,)
        The entries to score exactly: in a block with entries in doubt (inside, on either
        side of the threshold by the bound), those in doubt and the contenders.
    contender : ndarray of bool, shape (m,)
        Inside entries that may be among the k best of their block (within two bounds of
        the k-th listed value), whose exact costs give its k-th best.
    undecided : ndarray of bool, shape (n,)
        Blocks with entries in doubt.
    """
    total = values.size
    blocks = offsets.size - 1
    inside = np.zeros(total, dtype=np.bool_)
    scored = np.zeros(total, dtype=np.bool_)  # first the entries in doubt
    contender = np.zeros(total, dtype=np.bool_)
    undecided = np.zeros(blocks, dtype=np.bool_)
    for b in range(blocks):
        start, stop = offsets[b], offsets[b + 1]
        if start == stop:
            continue
        bound = bounds[b]
        kth = _kth(values[start:stop].copy(), k)
        low = scale * (kth - bound) - bound
        high = scale * (kth + bound) + bound
        reach = kth + 2 * bound
        for i in range(start, stop):
            if values[i] <= high:
                inside[i] = True
                if values[i] > low:
                    scored[i] = True
                    undecided[b] = True
                if values[i] <= reach:
                    contender[i] = True
        if undecided[b]:
            for i in range(start, stop):
                scored[i] = scored[i] or contender[i]
    return inside, scored, contender, undecided


@nb.njit(cache=True)
def settle(
    values: NDArray[np.float64],
    offsets: NDArray[np.intp],
    bounds: NDArray[np.float64],
    inside: NDArray[np.bool_],
    contender: NDArray[np.bool_],
    undecided: NDArray[np.bool_],
    exact: NDArray[np.float64],
    scale: float,
    k: int,
) -> NDArray[np.bool_]:
    """Which entries are acceptable, given the exact costs of the scored ones.

    Parameters
    ----------
    values, offsets, bounds, scale, k
        As :func:`bracket` takes them.
    inside, contender, undecided
        What :func:`bracket` returned.
    exact : ndarray of float64, shape (m,)
        The exact cost of every entry of an undecided block that is in doubt or a contender
        (the others are not read).

    Returns
    -------
    ndarray of bool, shape (m,)
        Acceptable entries: inside ones of a decided block; in an undecided block, with
        ``t = scale * E_(k)`` (E_(k) the k-th smallest exact cost of its contenders), those
        whose approximate cost is at most ``t - bound``, and those in ``(t - bound, t + bound]``
        whose exact cost is at most t.
    """
    keep = np.zeros(values.size, dtype=np.bool_)
    for b in range(offsets.size - 1):
        start, stop = offsets[b], offsets[b + 1]
        if not undecided[b]:
            for i in range(start, stop):
                keep[i] = inside[i]
            continue
        count = 0
        for i in range(start, stop):
            if contender[i]:
                count += 1
        best = np.empty(count, dtype=np.float64)
        count = 0
        for i in range(start, stop):
            if contender[i]:
                best[count] = exact[i]
                count += 1
        threshold = scale * _kth(best, k)
        bound = bounds[b]
        for i in range(start, stop):
            if not inside[i]:
                continue
            if values[i] <= threshold - bound:
                keep[i] = True
            elif values[i] <= threshold + bound:
                keep[i] = exact[i] <= threshold
    return keep
