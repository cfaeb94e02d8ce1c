"""The cost-field interface of the core (``quilting.core.fields``).

What is checked: :class:`CostRequest`'s validation of its weights and terms; the
:class:`CostBackend` protocol as ``isinstance`` sees it; :func:`find_mask` (identity first,
then value); and :class:`ExactScorer` against a brute-force float64 sum written here, over
masks with zero and fractional weights, every channel count, the field's last row and
column, batches mixing masks, owners and transfer terms, and a guide term without a guide
map. ``tests/costs/test_conformance.py`` already holds the single-request sums and chunk
independence; this file adds the batch and edge cases.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from fractions import Fraction
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from quilting.core.fields import (
    CostBackend,
    CostRequest,
    ExactScorer,
    FieldBatch,
    Shortlist,
    find_mask,
)
from quilting.costs.fft import FFTBackend
from quilting.costs.reference import ReferenceBackend

Array = NDArray[np.float32]


def brute_cost(
    source: Array,
    request: CostRequest,
    y: int,
    x: int,
    guide_map: Array | None = None,
) -> float:
    """The documented cost of candidate (y, x), by plain Python loops in float64."""
    block = request.mask.shape[0]
    total = 0.0
    for r in range(block):
        for c in range(block):
            s = source[y + r, x + c].astype(np.float64)
            weight = float(request.mask[r, c])
            total += weight * float(np.sum((s - request.template[r, c].astype(np.float64)) ** 2))
            if request.previous is not None and request.previous_weight > 0:
                p = request.previous[r, c].astype(np.float64)
                total += request.previous_weight * float(np.sum((s - p) ** 2))
            if request.guide is not None and request.guide_weight > 0:
                assert guide_map is not None
                g = guide_map[y + r, x + c].astype(np.float64)
                wanted = request.guide[r, c].astype(np.float64)
                total += request.guide_weight * float(np.sum((g - wanted) ** 2))
    return total


def every_position(height: int, width: int, block: int) -> tuple[NDArray[np.intp], ...]:
    ys, xs = np.divmod(np.arange((height - block + 1) * (width - block + 1)), width - block + 1)
    return ys.astype(np.intp), xs.astype(np.intp)


# --------------------------------------------------------------------------------------------
# CostRequest
# --------------------------------------------------------------------------------------------

TEMPLATE = np.zeros((4, 4, 3), dtype=np.float32)
MASK = np.ones((4, 4), dtype=np.float32)


@pytest.mark.parametrize("weight", [-1.0, -1e-12, math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("term", ["previous", "guide"])
def test_request_refuses_a_weight_that_is_not_finite_non_negative(term: str, weight: float) -> None:
    # The term is present, so only the weight can be the fault; the message names it.
    with pytest.raises(ValueError, match=f"{term}_weight must be a finite number >= 0"):
        terms: dict[str, Any] = {term: TEMPLATE, f"{term}_weight": weight}
        CostRequest(TEMPLATE, MASK, **terms)


@pytest.mark.parametrize("term", ["previous", "guide"])
def test_request_refuses_a_weight_without_its_term(term: str) -> None:
    with pytest.raises(ValueError, match=f"{term}_weight > 0 needs its term \\({term}\\)"):
        weight: dict[str, Any] = {f"{term}_weight": 0.5}
        CostRequest(TEMPLATE, MASK, **weight)


def test_request_accepts_terms_without_weight_and_zero_weights_without_terms() -> None:
    # A term with weight 0 is simply unused; weight 0 without a term is the default.
    CostRequest(TEMPLATE, MASK, previous=TEMPLATE, previous_weight=0.0)
    CostRequest(TEMPLATE, MASK, guide=TEMPLATE, guide_weight=0.0)
    CostRequest(TEMPLATE, MASK, previous_weight=0.0, guide_weight=0.0)
    request = CostRequest(TEMPLATE, MASK, TEMPLATE, 2.0, TEMPLATE, 3.0)
    assert (request.previous_weight, request.guide_weight) == (2.0, 3.0)


def test_requests_and_batches_are_frozen() -> None:
    request = CostRequest(TEMPLATE, MASK)
    with pytest.raises(AttributeError):
        request.previous_weight = 1.0  # type: ignore[misc]
    batch = FieldBatch(np.zeros((1, 2, 2)), np.zeros(1))
    with pytest.raises(AttributeError):
        batch.values = np.ones((1, 2, 2))  # type: ignore[misc]
    shortlist = Shortlist(np.arange(2, dtype=np.intp), np.zeros(2), 0.0)
    with pytest.raises(AttributeError):
        shortlist.bound = 1.0  # type: ignore[misc]


# --------------------------------------------------------------------------------------------
# CostBackend: the protocol as isinstance sees it
# --------------------------------------------------------------------------------------------


class _Incomplete:
    """Has a name and fields, but neither prepare, shortlists nor close."""

    name = "incomplete"
    renderer = "cpu"

    def fields(self, requests: Sequence[CostRequest]) -> FieldBatch:
        raise NotImplementedError


def test_the_cpu_backends_are_cost_backends() -> None:
    assert isinstance(FFTBackend(threads=1), CostBackend)
    assert isinstance(ReferenceBackend(), CostBackend)
    assert not isinstance(_Incomplete(), CostBackend)
    assert not isinstance(object(), CostBackend)


# --------------------------------------------------------------------------------------------
# find_mask
# --------------------------------------------------------------------------------------------


def test_find_mask_prefers_identity_then_value() -> None:
    left = np.zeros((4, 4), dtype=np.float32)
    left[:, :2] = 1.0
    top = left.T.copy()
    twin = left.copy()  # equal values, another array
    known = [left, top, twin]
    assert find_mask(known, top) == 1
    # The identical array wins over an equal one earlier in the list.
    assert find_mask(known, twin) == 2
    # A fresh array equal in value finds the first equal one.
    assert find_mask(known, left.copy()) == 0


def test_find_mask_misses() -> None:
    mask = np.ones((4, 4), dtype=np.float32)
    assert find_mask([], mask) is None
    assert find_mask([np.ones((5, 5), dtype=np.float32)], mask) is None  # other shape
    other = mask.copy()
    other[3, 3] = 0.5
    assert find_mask([other], mask) is None
    # Same values laid out differently: a (2, 8) array of ones is not a (4, 4) mask.
    assert find_mask([np.ones((2, 8), dtype=np.float32)], mask) is None


# --------------------------------------------------------------------------------------------
# ExactScorer
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("channels", [1, 3, 4])
def test_exact_costs_match_the_brute_force_sum(channels: int) -> None:
    rng = np.random.default_rng(channels)
    height, width, block = 13, 16, 5
    source = rng.random((height, width, channels), dtype=np.float32)
    template = rng.random((block, block, channels), dtype=np.float32)
    # Zero, fractional and larger-than-one weights all count as written.
    mask = rng.choice(np.array([0.0, 0.25, 1.0, 2.5], dtype=np.float32), (block, block))
    request = CostRequest(template, mask)
    ys, xs = every_position(height, width, block)
    got = ExactScorer(source, block).costs(request, ys, xs)
    assert got.dtype == np.float64 and got.shape == ys.shape
    want = [brute_cost(source, request, int(y), int(x)) for y, x in zip(ys, xs, strict=True)]
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    # The field's last row and column are real candidates (the block touches the border).
    assert ys.max() == height - block and xs.max() == width - block


def test_exact_costs_are_float64_sums() -> None:
    # Squares of 4096 + k / 1024 summed 16 at a time: every term and partial sum is exact in
    # float64 (48 significant bits at most), while float32 keeps only 24 and would drop the
    # small parts. The oracle is exact rational arithmetic.
    block = 4
    steps = np.arange(36).reshape(6, 6)
    source = (4096.0 + steps * 2.0**-10).astype(np.float32)[..., None]
    assert np.array_equal(source[..., 0].astype(np.float64), 4096.0 + steps * 2.0**-10)
    request = CostRequest(
        np.zeros((block, block, 1), np.float32), np.ones((block, block), dtype=np.float32)
    )
    ys, xs = every_position(6, 6, block)
    got = ExactScorer(source, block).costs(request, ys, xs)
    for k, (y, x) in enumerate(zip(ys, xs, strict=True)):
        window = steps[y : y + block, x : x + block].ravel()
        exact = sum(Fraction(4096 * 1024 + int(n), 1024) ** 2 for n in window)
        assert got[k] == pytest.approx(float(exact), rel=1e-14, abs=0.0)


def test_a_mask_of_zeros_costs_nothing() -> None:
    rng = np.random.default_rng(5)
    source = rng.random((10, 10, 3), dtype=np.float32)
    request = CostRequest(rng.random((4, 4, 3), dtype=np.float32), np.zeros((4, 4), np.float32))
    ys, xs = every_position(10, 10, 4)
    np.testing.assert_array_equal(ExactScorer(source, 4).costs(request, ys, xs), 0.0)


def test_a_batch_of_mixed_requests_matches_the_brute_force_sum() -> None:
    # Several masks (some shared by identity, one equal by value only), transfer terms on
    # some requests only, and candidates interleaved between owners.
    rng = np.random.default_rng(6)
    height, width, block, channels = 14, 15, 4, 3
    source = rng.random((height, width, channels), dtype=np.float32)
    guide_map = rng.random((height, width, 2), dtype=np.float32)
    left = np.zeros((block, block), np.float32)
    left[:, :2] = 1.0
    top = np.zeros((block, block), np.float32)
    top[:2] = 0.5
    corner = np.maximum(left, top)

    def block_of(k: int) -> Array:
        return rng.random((block, block, k), dtype=np.float32)

    requests = [
        CostRequest(block_of(3), left),
        CostRequest(block_of(3), top, block_of(3), 0.3),
        CostRequest(block_of(3), left, guide=block_of(2), guide_weight=1.7),
        CostRequest(block_of(3), corner.copy(), block_of(3), 0.5, block_of(2), 0.25),
        CostRequest(block_of(3), corner),
    ]
    count = 60
    owner = rng.integers(0, len(requests), count).astype(np.intp)
    ys = rng.integers(0, height - block + 1, count).astype(np.intp)
    xs = rng.integers(0, width - block + 1, count).astype(np.intp)
    scorer = ExactScorer(source, block, guide_map)
    got = scorer.costs_batch(requests, owner, ys, xs)
    want = [
        brute_cost(source, requests[o], int(y), int(x), guide_map)
        for o, y, x in zip(owner, ys, xs, strict=True)
    ]
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    # The promise: a candidate's cost is the same number in any batch, e.g. scored alone.
    for k in range(count):
        alone = scorer.costs(requests[owner[k]], ys[k : k + 1], xs[k : k + 1])
        assert alone[0] == got[k], k


def test_an_empty_batch_and_a_request_without_candidates() -> None:
    rng = np.random.default_rng(7)
    source = rng.random((9, 9, 1), dtype=np.float32)
    scorer = ExactScorer(source, 3)
    requests = [
        CostRequest(rng.random((3, 3, 1), dtype=np.float32), np.ones((3, 3), np.float32)),
        CostRequest(rng.random((3, 3, 1), dtype=np.float32), np.eye(3, dtype=np.float32)),
    ]
    none = np.zeros(0, dtype=np.intp)
    assert scorer.costs_batch(requests, none, none, none).shape == (0,)
    # Only the second request has candidates; the first (another mask) is skipped.
    owner = np.ones(3, dtype=np.intp)
    ys = np.array([0, 3, 6], dtype=np.intp)
    xs = np.array([6, 0, 2], dtype=np.intp)
    got = scorer.costs_batch(requests, owner, ys, xs)
    want = [brute_cost(source, requests[1], int(y), int(x)) for y, x in zip(ys, xs, strict=True)]
    np.testing.assert_allclose(got, want, rtol=1e-12)


def test_a_guide_term_needs_the_source_guide_map() -> None:
    rng = np.random.default_rng(8)
    source = rng.random((8, 8, 3), dtype=np.float32)
    request = CostRequest(
        rng.random((3, 3, 3), dtype=np.float32),
        np.ones((3, 3), np.float32),
        guide=rng.random((3, 3, 1), dtype=np.float32),
        guide_weight=1.0,
    )
    one = np.zeros(1, dtype=np.intp)
    with pytest.raises(ValueError, match="no guide map"):
        ExactScorer(source, 3).costs(request, one, one)
    # A guide given with weight 0 is not a guide term: no map needed, the plain cost returned.
    unused = CostRequest(request.template, request.mask, guide=request.guide, guide_weight=0.0)
    got = ExactScorer(source, 3).costs(unused, one, one)
    assert got[0] == pytest.approx(brute_cost(source, unused, 0, 0), rel=1e-12)
