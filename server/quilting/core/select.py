"""Candidate selection: which source blocks are acceptable for a position, and the pick.

Tolerance policy (Efros & Freeman 2001, §2.2): every candidate whose cost is at most
``(1 + tolerance) * best`` is acceptable, one is drawn uniformly, or, with factored sampling,
by the cost of its seam (:func:`relative_costs`; the draw is ``alpha.factored_pick``).

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

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from quilting.core import kernels
from quilting.core.exclusion import CandidateField
from quilting.core.fields import CostBackend, CostRequest, FieldBatch, Shortlist
from quilting.core.randomness import BlockRandom

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


def shortlist_fields(
    fields: NDArray[np.floating],
    bounds: NDArray[np.float64],
    tolerance: float,
    min_candidates: int,
) -> list[Shortlist]:
    """Reduce dense fields to the candidates :func:`acceptable` may need.

    Parameters
    ----------
    fields : ndarray, shape (n, h, w)
        Approximate costs, ``|fields[b] - exact_b| <= bounds[b]``.
    bounds : ndarray, shape (n,)
        Error bounds (0 where a field is exact).
    tolerance, min_candidates : float, int
        The rule, as in :func:`acceptable`.

    Returns
    -------
    list of Shortlist, length n
        Every candidate with approximate cost <= ``(1 + tol) (U + bound) + bound``, with U the
        k-th smallest of the field's row minima: an upper bound on E_(k) (k rows each hold a
        value at most U), so a superset of what :class:`Shortlist` asks for. Taking the bound
        instead of E_(k) itself saves a partition of the field per request; the exact E_(k)
        is found on the (short) list by :func:`acceptable`.
    """
    n = fields.shape[0]
    flats = fields.reshape(n, -1)
    row_minima = fields.min(axis=2)  # (n, h): one pass over every field
    rows = row_minima.shape[1]
    result: list[Shortlist] = []
    for b in range(n):
        bound = float(bounds[b])
        if rows >= min_candidates:
            kth = float(np.partition(row_minima[b], min_candidates - 1)[min_candidates - 1])
        else:  # fewer rows than k: the bound does not exist
            kth = kth_smallest(fields[b], min_candidates)
        hi = (1 + tolerance) * (kth + bound) + bound
        # One pass over the field; the rest works on the (small) subset below hi, in float64:
        # a float32 field compared with a Python float compares in float32 (NumPy 2), which
        # could round a threshold past a candidate. (The pass itself can only round hi up,
        # which keeps a superset.)
        index = np.flatnonzero(flats[b] <= hi)
        result.append(Shortlist(index, flats[b][index].astype(np.float64), bound))
    return result


class DenseShortlists:
    """Mixin for backends that compute whole fields: shortlists by :func:`shortlist_fields`."""

    def fields(self, requests: Sequence[CostRequest]) -> FieldBatch:
        raise NotImplementedError

    def shortlists(
        self, requests: Sequence[CostRequest], tolerance: float, min_candidates: int
    ) -> list[Shortlist]:
        """The :class:`Shortlist` of every request, from its dense field."""
        batch = self.fields(requests)
        return shortlist_fields(batch.values, batch.error_bound, tolerance, min_candidates)


def acceptable(
    shortlists: Sequence[Shortlist],
    exact: ExactCosts,
    tolerance: float,
    min_candidates: int,
) -> list[NDArray[np.intp]]:
    """For each shortlist, the flat indices of every candidate with exact cost <= (1+tol) E_(k).

    Parameters
    ----------
    shortlists : sequence of Shortlist, length n
        Per block, the candidates that may be acceptable (see :class:`Shortlist`).
    exact : callable
        Exact costs of candidates, given their block and flat index.
    tolerance : float
        Relative tolerance of the rule.
    min_candidates : int
        k: the rule is measured from the k-th best exact cost.

    Returns
    -------
    list of ndarray of int, each shape (m_b,), m_b >= min(k, field size)
        Sorted flat indices into each field.

    Notes
    -----
    The threshold (1 + tol) E_(k) lies in (1 + tol) [kth - bound, kth + bound] (order
    statistics move at most ``bound`` under the noise). Candidates in that band may fall on
    either side of it and are scored exactly, together with every possible member of the k
    best (within 2 bound of the approximate k-th value) to find E_(k) exactly. A shortlist
    holds every candidate up to the band's top, so the k best of the field are the k best of
    the list. The per-block work is compiled (:mod:`quilting.core.kernels.select`); the
    exact costs of the whole level are asked in one call (a few, for very long lists). Each
    cost is the same number whatever call it is asked in.
    """
    scale = 1 + tolerance
    result: list[NDArray[np.intp]] = []
    # Blocks a group at a time, each group's lists at most RESCORE_GROUP long (or one block):
    # a level of blocks whose candidates all tie (a flat texture lists every one of them)
    # keeps its working arrays a few MiB.
    start = 0
    while start < len(shortlists):
        stop, count = start + 1, shortlists[start].index.size
        while stop < len(shortlists) and count + shortlists[stop].index.size <= RESCORE_GROUP:
            count += shortlists[stop].index.size
            stop += 1
        group = shortlists[start:stop]
        result.extend(_acceptable_group(group, exact, start, scale, min_candidates))
        start = stop
    return result


def _acceptable_group(
    shortlists: Sequence[Shortlist], exact: ExactCosts, first: int, scale: float, k: int
) -> list[NDArray[np.intp]]:
    """:func:`acceptable` of consecutive blocks, the first being block ``first`` of the
    level; their exact costs in one call."""
    n = len(shortlists)
    sizes = np.array([listed.index.size for listed in shortlists], dtype=np.intp)
    offsets = np.zeros(n + 1, dtype=np.intp)
    np.cumsum(sizes, out=offsets[1:])
    index = np.concatenate([listed.index for listed in shortlists]).astype(np.intp, copy=False)
    values = np.concatenate([listed.values for listed in shortlists]).astype(np.float64)
    bounds = np.array([listed.bound for listed in shortlists], dtype=np.float64)
    inside, scored, contender, undecided = kernels.bracket(values, offsets, bounds, scale, k)
    scores = np.zeros(values.size, dtype=np.float64)
    if undecided.any():
        chosen = np.flatnonzero(scored)
        owner = np.searchsorted(offsets, chosen, side="right") - 1
        scores[chosen] = exact(owner + first, index[chosen])
    keep = kernels.settle(values, offsets, bounds, inside, contender, undecided, scores, scale, k)
    return [index[offsets[b] : offsets[b + 1]][keep[offsets[b] : offsets[b + 1]]] for b in range(n)]


#: Most candidates re-scored in one call: a level of blocks whose candidates all tie (a flat
#: texture lists every one of them) is scored a part at a time, so the call's index and cost
#: arrays stay a few MiB instead of batch x field.
RESCORE_GROUP = 1 << 18


def relative_costs(costs: NDArray[np.float64]) -> NDArray[np.float64]:
    """``costs`` (m,) over their median, the scale-free seam cost of cut mode's factored
    sampling: ``exp(-s E / median E)`` weighs candidates the same way on a faint texture as on
    a contrasted one. Where more than half the candidates join without error (median 0) the
    mean is the scale; where all do, every cost is 0 (a uniform draw)."""
    scale = float(np.median(costs))
    if scale <= 0:
        scale = float(costs.mean())
    if scale <= 0:
        return np.zeros_like(costs)
    scaled: NDArray[np.float64] = costs / scale
    return scaled


def survivors(key: int, index: NDArray[np.intp], discard: float) -> NDArray[np.bool_]:
    """Which candidates survive random discarding, each with probability 1 - p.

    A candidate's fate is a hash of the block's ``key`` and its flat index, so it is the
    same whichever backend listed it and whatever else was listed with it.

    Parameters
    ----------
    key : int
        The block's discarding key, 0..2**64 - 1 (drawn from its generator).
    index : ndarray of int, shape (m,)
        Flat candidate indices.
    discard : float
        Probability p of dropping a candidate.

    Returns
    -------
    ndarray of bool, shape (m,)
    """
    uniform = (candidate_hash(key, index) >> np.uint64(11)).astype(np.float64) * 2.0**-53
    kept: NDArray[np.bool_] = uniform >= discard
    return kept


def candidate_hash(key: int, index: NDArray[np.intp]) -> NDArray[np.uint64]:
    """A 64-bit hash of a block's ``key`` and each flat candidate index: splitmix64 of
    ``key + index``, well mixed, vectorized, the same on every platform."""
    with np.errstate(over="ignore"):
        x = np.uint64(key) + index.astype(np.uint64)
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        x ^= x >> np.uint64(31)
    return x


#: Candidates :func:`first_acceptable` scores one by one, in hash order, before it falls back
#: to the whole band (:func:`acceptable`), and how many it scores per call.
SCAN_LIMIT, SCAN_CHUNK = 256, 32


def first_acceptable(
    shortlist: Shortlist,
    exact: Callable[[NDArray[np.intp]], NDArray[np.float64]],
    tolerance: float,
    min_candidates: int,
    key: int,
    count: int = 1,
) -> NDArray[np.intp]:
    """The first ``count`` candidates the tolerance rule accepts, in the order of
    :func:`candidate_hash` keyed by ``key`` (all of them when it accepts fewer).

    The same candidates as taking :func:`acceptable`'s set and sorting it by the hash, so the
    same on every backend, and a uniform draw from the set when ``count`` is 1. It is found
    without scoring the whole set where the rule is clear: a candidate whose exact cost is at
    most ``(1 + tol) max(0, U_k - b)`` is accepted whatever ``E_(k)`` is, and one above
    ``(1 + tol)(U_k + b)`` is refused (``U_k`` the list's k-th approximate cost, within the
    bound b of ``E_(k)``). Candidates are scored in hash order until ``count`` are accepted;
    the first that falls between, or :data:`SCAN_LIMIT` scored, hands the decision to
    :func:`acceptable`. Where thousands of candidates tie (a flat background) the first one
    scored is usually taken, where :func:`acceptable` would score every one of them.

    Parameters
    ----------
    shortlist : Shortlist
        One block's list (see :class:`Shortlist`).
    exact : callable
        Exact costs of flat candidate indices of this block, (m,) -> (m,).
    tolerance, min_candidates
        The rule's.
    key : int
        The block's key, 0..2**64 - 1 (drawn from its generator).
    count : int
        How many candidates to return.

    Returns
    -------
    ndarray of int, shape (<= count,)
        Flat indices, in hash order.
    """
    values, bound = shortlist.values, shortlist.bound
    k = min(min_candidates, values.size)
    kth = float(np.partition(values, k - 1)[k - 1])
    scale = 1 + tolerance
    sure, never = scale * max(0.0, kth - bound), scale * (kth + bound)
    listed = values <= never + bound
    maybe, approximate = shortlist.index[listed], values[listed]
    hashes = candidate_hash(key, maybe)
    if maybe.size > SCAN_LIMIT:  # only the first SCAN_LIMIT in hash order can be scored
        first = np.argpartition(hashes, SCAN_LIMIT - 1)[:SCAN_LIMIT]
        maybe, approximate, hashes = maybe[first], approximate[first], hashes[first]
    ranked = np.lexsort((maybe, hashes))
    order, approximate = maybe[ranked], approximate[ranked]
    taken: list[int] = []
    for start in range(0, min(order.size, SCAN_LIMIT), SCAN_CHUNK):
        chunk = order[start : start + SCAN_CHUNK]
        # A list without error (bound 0) holds the exact costs already.
        costs = approximate[start : start + SCAN_CHUNK] if bound == 0 else exact(chunk)
        for candidate, cost in zip(chunk.tolist(), costs.tolist(), strict=True):
            if cost <= sure:
                taken.append(candidate)
                if len(taken) == count:
                    return np.array(taken, dtype=np.intp)
            elif cost <= never:  # on the rule's edge: only E_(k) itself can tell
                return _hash_ordered(shortlist, exact, tolerance, min_candidates, key, count)
    if order.size < SCAN_LIMIT:
        return np.array(taken, dtype=np.intp)  # every candidate that may pass was decided
    return _hash_ordered(shortlist, exact, tolerance, min_candidates, key, count)


def _hash_ordered(
    shortlist: Shortlist,
    exact: Callable[[NDArray[np.intp]], NDArray[np.float64]],
    tolerance: float,
    min_candidates: int,
    key: int,
    count: int,
) -> NDArray[np.intp]:
    """:func:`acceptable`'s set of one list, the first ``count`` of it in hash order."""

    def scored(owner: NDArray[np.intp], index: NDArray[np.intp]) -> NDArray[np.float64]:
        return exact(index)

    accepted = acceptable([shortlist], scored, tolerance, min_candidates)[0]
    ordered: NDArray[np.intp] = accepted[np.lexsort((accepted, candidate_hash(key, accepted)))]
    return ordered[:count]


def discard_depth(min_candidates: int, discard: float) -> int:
    """How deep a shortlist to ask for (its ``min_candidates``) so that, very likely, at least
    ``min_candidates`` of its best entries survive discarding with probability ``discard``."""
    expected = min_candidates / (1 - discard)
    return math.ceil(expected + 4 * math.sqrt(expected) + 4)


def enough_survive(
    listed: Shortlist, kept: NDArray[np.bool_], depth: int, k: int, field_size: int
) -> bool:
    """Whether the survivors of ``listed`` (a shortlist made with ``min_candidates=depth``)
    hold every survivor the tolerance rule with ``k`` can accept.

    The list holds every candidate up to (1 + tol)(E_(depth) + b) + b. If k survivors are
    among its ``depth`` best, the k-th best survivor costs at most E_(depth), so the list
    holds every survivor the rule can accept. A list of a field no larger than ``depth`` is
    the whole field.
    """
    if field_size <= depth:
        return True
    best = np.argpartition(listed.values, depth - 1)[:depth]
    return int(kept[best].sum()) >= k


def kept_shortlists(
    backend: CostBackend,
    requests: Sequence[CostRequest],
    rngs: Sequence[BlockRandom],
    field: CandidateField,
    tolerance: float,
    min_candidates: int,
    discard: float,
) -> list[Shortlist]:
    """The backend's shortlists of ``requests``, without the candidates ``field`` excludes
    and those randomly discarded.

    Discarding drops candidates from the whole field before the tolerance rule, so the best
    match itself may go and a loop of blocks that keep following each other breaks. The lists
    are asked deep enough that k survivors are among their best entries (then they hold every
    survivor the rule can accept); a block unlucky even so asks again, twice as deep.

    Parameters
    ----------
    backend : CostBackend
        Prepared with the source ``field`` describes.
    requests : sequence of CostRequest, length n
    rngs : sequence of BlockRandom, length n
        Each block's own random stream (a discard draws its key from it).
    field : CandidateField
        The candidates, and which of them an exclusion (or a fill's hole) leaves.
    tolerance, min_candidates, discard
        The options of the same names.

    Returns
    -------
    list of Shortlist, length n
    """
    k = min_candidates
    allowed, candidates = field.allowed, field.size
    if discard == 0 and allowed is None:
        return backend.shortlists(requests, tolerance, k)
    # Excluded candidates are dropped like discarded ones, for sure instead of by chance.
    share = 1.0 if allowed is None else field.index.size / candidates
    dropped = min(1 - (1 - discard) * share, 0.999)
    depth = min(discard_depth(k, dropped), candidates)
    listed = backend.shortlists(requests, tolerance, depth)
    result = []
    for request, rng, shortlist in zip(requests, rngs, listed, strict=True):
        key = int(rng.generator.integers(0, 2**64, dtype=np.uint64)) if discard > 0 else 0

        def kept_of(index: NDArray[np.intp], key: int = key) -> NDArray[np.bool_]:
            kept = np.ones(index.size, dtype=bool) if allowed is None else allowed[index]
            return kept & survivors(key, index, discard) if discard > 0 else kept

        deeper = depth
        kept = kept_of(shortlist.index)
        while not enough_survive(shortlist, kept, deeper, k, candidates):
            deeper = min(2 * deeper, candidates)
            shortlist = backend.shortlists([request], tolerance, deeper)[0]
            kept = kept_of(shortlist.index)
        if not kept.any():
            # Every candidate was discarded: the rule runs over all those allowed (the list is
            # then the whole field, and some are allowed).
            kept = np.ones(shortlist.index.size, dtype=bool)
            if allowed is not None:
                kept = allowed[shortlist.index]
        result.append(Shortlist(shortlist.index[kept], shortlist.values[kept], shortlist.bound))
    return result
