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
exact costs give, on every backend.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

ExactCosts = Callable[[NDArray[np.intp]], NDArray[np.float64]]
"""Exact costs of candidates given by flat index into the field, shape (k,) -> (k,)."""


def kth_smallest(values: NDArray[np.float64], k: int) -> float:
    """The k-th smallest of ``values`` (1-based), ``k`` clipped to the number of values."""
    k = min(k, values.size)
    if k == 1:
        return float(values.min())
    return float(np.partition(values, k - 1)[k - 1])


def acceptable(
    field: NDArray[np.float64],
    bound: float,
    exact: ExactCosts,
    tolerance: float,
    min_candidates: int,
) -> NDArray[np.intp]:
    """Flat indices of every candidate with exact cost ``<= (1 + tolerance) * E_(k)``.

    Parameters
    ----------
    field : ndarray, shape (h, w)
        Approximate costs, ``|field - exact| <= bound``.
    bound : float
        Error bound of ``field`` (0 when it is exact).
    exact : callable
        Exact costs of the candidates at the given flat indices.
    tolerance : float
        Relative tolerance of the rule.
    min_candidates : int
        k: the rule is measured from the k-th best exact cost.

    Returns
    -------
    ndarray of int, shape (m,), m >= min(k, field.size)
        Sorted flat indices into ``field``.
    """
    flat = field.reshape(-1)
    approx_kth = kth_smallest(flat, min_candidates)
    if bound == 0:
        return np.flatnonzero(flat <= (1 + tolerance) * approx_kth)
    # Order statistics move at most `bound` under the noise, so every candidate that can be
    # among the k best lies within 2 * bound of the approximate k-th value.
    contenders = np.flatnonzero(flat <= approx_kth + 2 * bound)
    threshold = (1 + tolerance) * kth_smallest(exact(contenders), min_candidates)
    sure = flat <= threshold - bound
    band = np.flatnonzero((flat > threshold - bound) & (flat <= threshold + bound))
    if band.size:
        sure[band[exact(band) <= threshold]] = True
    return np.flatnonzero(sure)


def pick(candidates: NDArray[np.intp], rng: np.random.Generator) -> int:
    """Draw one of ``candidates`` uniformly with the block's own generator."""
    return int(candidates[rng.integers(candidates.size)])
