"""Candidate selection: which source blocks are acceptable for a position, and the pick.

Tolerance policy (Efros & Freeman 2001, §2.2): every candidate whose cost is at most
``(1 + tolerance) * best`` is acceptable, one is drawn uniformly.

The floor: the rule is measured from the ``min_candidates``-th best cost instead of the best,
i.e. the threshold is ``(1 + tolerance) * E_(k)``. When the best cost is ~0 (the block's own
continuation in the source, which always exists next to a block copied earlier) the bare rule
leaves that one candidate and the output becomes a verbatim copy of the source; with the floor
at least k candidates stay acceptable, so continuations are broken with probability
1 - 1/k per block. ``min_candidates = 1`` is the paper's rule exactly. (A floor proportional to
the texture's contrast was tried first; on stochastic textures such as grass the best real
alternative is more than half the contrast away, so no such floor helped without ruining the
seams of structured textures.)

Fields may be approximate within a known bound; candidates whose approximate cost is too close
to a decision to tell are re-scored exactly, so the acceptable set is exactly the one the
exact costs give, on every backend. All blocks of a batch are re-scored in one call.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

ExactCosts = Callable[[NDArray[np.intp], NDArray[np.intp]], NDArray[np.float64]]
"""``exact(block, flat_index)``: exact costs of candidates of the given blocks, (k,) -> (k,)."""


def kth_smallest(values: NDArray[np.floating], k: int) -> float:
    """The k-th smallest of ``values`` (1-based, any shape), ``k`` clipped to its size.

    A full partition of a cost field costs more than the FFT that made it; instead the k-th
    smallest of the row minima bounds the answer from above (k rows each hold a value at most
    that large), and only the values under that bound are partitioned.
    """
    flat = values.reshape(-1)
    k = min(k, flat.size)
    if k == 1:
        return float(flat.min())
    rows = values.reshape(values.shape[0], -1) if values.ndim > 1 else flat[:, None]
    row_min = rows.min(axis=1)
    if row_min.size >= k:
        flat = flat[flat <= np.partition(row_min, k - 1)[k - 1]]
    return float(np.partition(flat, k - 1)[k - 1])


def acceptable(
    fields: NDArray[np.floating],
    bounds: NDArray[np.float64],
    exact: ExactCosts,
    tolerance: float,
    min_candidates: int,
) -> list[NDArray[np.intp]]:
    """For each field, the flat indices of every candidate with exact cost <= (1+tol) E_(k).

    Parameters
    ----------
    fields : ndarray, shape (n, h, w)
        Approximate costs, ``|fields[b] - exact_b| <= bounds[b]``.
    bounds : ndarray, shape (n,)
        Error bounds (0 where a field is exact).
    exact : callable
        Exact costs of candidates, given their block and flat index.
    tolerance : float
        Relative tolerance of the rule.
    min_candidates : int
        k: the rule is measured from the k-th best exact cost.

    Returns
    -------
    list of ndarray of int, each shape (m_b,), m_b >= min(k, h * w)
        Sorted flat indices into each field.
    """
    n = fields.shape[0]
    flats = fields.reshape(n, -1)
    scale = 1 + tolerance
    result: list[NDArray[np.intp]] = []
    # The threshold (1 + tol) E_(k) lies in (1 + tol) [kth - bound, kth + bound] (order
    # statistics move at most `bound` under the noise). Candidates in (lo, hi] may fall on
    # either side of it and are scored exactly, together with every possible member of the
    # k best (within 2 bound of the approximate k-th value) to find E_(k) exactly.
    undecided: dict[int, tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]] = {}
    for b in range(n):
        flat, bound = flats[b], float(bounds[b])
        kth = kth_smallest(fields[b], min_candidates)
        lo, hi = scale * (kth - bound) - bound, scale * (kth + bound) + bound
        # One pass over the field; everything after works on the (small) subset below hi, in
        # float64: a float32 field compared with a Python float compares in float32 (NumPy 2),
        # which could round a threshold past a candidate. (The pass itself can only round hi
        # up, which keeps a superset.)
        below = np.flatnonzero(flat <= hi)
        values = flat[below].astype(np.float64)
        doubt = values > lo
        if not doubt.any():
            # Nothing within reach of the threshold: decided without exact costs.
            result.append(below)
            continue
        contenders = below[values <= kth + 2 * bound]
        result.append(below)  # replaced below
        undecided[b] = (contenders, np.union1d(contenders, below[doubt]), below)
    if not undecided:
        return result
    blocks = list(undecided)
    rescore = [undecided[b][1] for b in blocks]
    sizes = [r.size for r in rescore]
    scored_all = exact(np.repeat(np.array(blocks), sizes), np.concatenate(rescore))
    for b, scored in zip(blocks, np.split(scored_all, np.cumsum(sizes)[:-1]), strict=True):
        contenders, of, below = undecided[b]
        bound = float(bounds[b])
        # `of` is sorted and holds every contender and every candidate in doubt.
        threshold = scale * kth_smallest(scored[np.searchsorted(of, contenders)], min_candidates)
        values = flats[b][below].astype(np.float64)
        keep = values <= threshold - bound
        band = (values > threshold - bound) & (values <= threshold + bound)
        band_index = below[band]
        keep[band] = scored[np.searchsorted(of, band_index)] <= threshold
        result[b] = below[keep]
    return result


def pick(candidates: NDArray[np.intp], rng: np.random.Generator) -> int:
    """Draw one of ``candidates`` uniformly with the block's own generator."""
    return int(candidates[rng.integers(candidates.size)])
