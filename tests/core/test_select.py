"""Selection: the acceptable set is exactly the exact rule's, whatever the field's noise."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quilting.core.exclusion import CandidateField
from quilting.core.fields import Shortlist
from quilting.core.randomness import BlockRandom
from quilting.core.select import (
    acceptable,
    candidate_hash,
    first_acceptable,
    relative_costs,
    shortlist_fields,
)


def _accept(fields, bounds, exact, tolerance, k):
    return acceptable(shortlist_fields(fields, bounds, tolerance, k), exact, tolerance, k)


def _rule(exact: np.ndarray, tolerance: float, k: int) -> np.ndarray:
    kth = np.sort(exact.ravel())[min(k, exact.size) - 1]
    return np.flatnonzero(exact.ravel() <= (1 + tolerance) * kth)


@settings(max_examples=150, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    tolerance=st.sampled_from([0.0, 0.05, 0.1, 0.5]),
    k=st.sampled_from([1, 2, 3, 10, 1000]),
    bound=st.sampled_from([0.0, 1e-6, 1e-3, 0.05]),
    ties=st.booleans(),
)
def test_noisy_field_gives_the_exact_set(seed, tolerance, k, bound, ties) -> None:
    rng = np.random.default_rng(seed)
    exact = rng.random((9, 11)) * 2
    if ties:  # many equal values and values sitting right at a threshold
        exact = np.round(exact * 4) / 4
        exact.flat[rng.integers(exact.size)] = (1 + tolerance) * exact.min()
    noisy = exact + rng.uniform(-bound, bound, size=exact.shape)
    calls: list[int] = []

    def rescore(owner: np.ndarray, index: np.ndarray) -> np.ndarray:
        assert np.all(owner == 0)
        calls.append(index.size)
        return exact.ravel()[index]

    got = _accept(noisy[None], np.array([bound]), rescore, tolerance, k)[0]
    assert np.array_equal(got, _rule(exact, tolerance, k))
    assert got.size >= min(k, exact.size)
    if bound == 0:
        assert sum(calls) == 0  # exact fields need no re-scoring


def test_floor_admits_more_than_the_verbatim_continuation() -> None:
    rng = np.random.default_rng(0)
    exact = 1 + rng.random((20, 20))
    exact[3, 4] = 0.0  # the block's own continuation in the source

    def never(owner: np.ndarray, index: np.ndarray) -> np.ndarray:
        raise AssertionError("exact fields need no re-scoring")

    zero = np.zeros(1)
    assert _accept(exact[None], zero, never, 0.1, 1)[0].tolist() == [3 * 20 + 4]
    widened = _accept(exact[None], zero, never, 0.1, 3)[0]
    third = np.sort(exact.ravel())[2]
    assert widened.size >= 3
    assert widened.size == np.count_nonzero(exact <= 1.1 * third)
    assert 3 * 20 + 4 in widened


def test_batch_equals_blocks_one_at_a_time() -> None:
    rng = np.random.default_rng(4)
    exact = rng.random((6, 10, 12))
    bounds = np.array([0.0, 1e-3, 0.02, 0.0, 0.05, 1e-6])
    noisy = exact + rng.uniform(-1, 1, size=exact.shape) * bounds[:, None, None]

    def rescore(owner: np.ndarray, index: np.ndarray) -> np.ndarray:
        return exact.reshape(6, -1)[owner, index]

    together = _accept(noisy, bounds, rescore, 0.1, 3)
    for b in range(6):
        alone = _accept(
            noisy[b : b + 1], bounds[b : b + 1], lambda o, i, b=b: exact[b].ravel()[i], 0.1, 3
        )[0]
        assert np.array_equal(together[b], alone)
        assert np.array_equal(alone, _rule(exact[b], 0.1, 3))


def test_pick_is_uniform_and_seeded() -> None:
    field = CandidateField.of((16, 16), 4)
    candidates = np.array([2, 5, 9, 11])
    draws = [field.pick(candidates, BlockRandom(s, 0, 1, 2)) for s in range(4000)]
    counts = np.array([draws.count(c) for c in candidates])
    assert counts.min() > 850  # 1000 expected each
    assert field.pick(candidates, BlockRandom(7, 0, 1, 2)) == field.pick(
        candidates, BlockRandom(7, 0, 1, 2)
    )


def test_weighted_pick_follows_the_weights() -> None:
    weights = np.zeros(13 * 13)
    weights[[2, 5, 9, 11]] = [4.0, 2.0, 1.0, 1.0]
    field = CandidateField.of((16, 16), 4, weights=weights)
    candidates = np.array([2, 5, 9, 11])
    draws = [field.pick(candidates, BlockRandom(s, 0, 1, 2)) for s in range(8000)]
    counts = np.array([draws.count(c) for c in candidates])
    # 4000, 2000, 1000, 1000 expected; a few standard deviations of slack.
    assert 3700 < counts[0] < 4300 and 1800 < counts[1] < 2200
    assert 850 < counts[2] < 1150 and 850 < counts[3] < 1150


@settings(max_examples=200, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    shape=st.tuples(st.integers(1, 12), st.integers(1, 12)),
    k=st.integers(1, 20),
    ties=st.booleans(),
)
def test_kth_smallest_matches_sorting(seed, shape, k, ties) -> None:
    from quilting.core.select import kth_smallest

    values = np.random.default_rng(seed).random(shape)
    if ties:
        values = np.round(values * 3)
    assert kth_smallest(values, k) == np.sort(values.ravel())[min(k, values.size) - 1]


def test_float32_fields_are_compared_exactly() -> None:
    # A float32 field whose values sit within float32 rounding of the threshold: comparing in
    # float32 would round the threshold onto them and wrongly admit or drop candidates.
    exact = np.array([1.0, 1.0, 1.0, 1.1000000001, 1.1000001, 2.0])
    bound = 1e-9
    field = exact.astype(np.float32).reshape(1, 2, 3)

    def rescore(owner: np.ndarray, index: np.ndarray) -> np.ndarray:
        return exact[index]

    got = _accept(field, np.array([bound]), rescore, 0.1, 3)[0]
    assert np.array_equal(got, _rule(exact.reshape(2, 3), 0.1, 3))


@settings(max_examples=100, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    tolerance=st.sampled_from([0.0, 0.1, 0.5]),
    k=st.sampled_from([1, 3, 10]),
    bound=st.sampled_from([0.0, 1e-3, 0.05]),
    extra=st.floats(0.0, 3.0),
)
def test_any_complete_shortlist_gives_the_exact_set(seed, tolerance, k, bound, extra) -> None:
    # A GPU backend lists everything under a looser threshold than the dense reduction (its
    # k-th value is an upper bound from group minima): any superset must select the same.
    rng = np.random.default_rng(seed)
    exact = rng.random((8, 9)) * 2
    noisy = exact + rng.uniform(-bound, bound, size=exact.shape)
    tight = shortlist_fields(noisy[None], np.array([bound]), tolerance, k)[0]
    limit = tight.values.max() + extra
    loose_index = np.flatnonzero(noisy.ravel() <= limit)
    loose = Shortlist(loose_index, noisy.ravel()[loose_index].astype(np.float64), bound)
    assert loose.index.size >= tight.index.size

    def rescore(owner: np.ndarray, index: np.ndarray) -> np.ndarray:
        return exact.ravel()[index]

    got = acceptable([loose], rescore, tolerance, k)[0]
    assert np.array_equal(got, _rule(exact, tolerance, k))


@settings(max_examples=100, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    tolerance=st.sampled_from([0.0, 0.1, 0.5]),
    k=st.sampled_from([1, 3, 7, 50]),
    bound=st.sampled_from([0.0, 1e-3, 0.05]),
    shape=st.sampled_from([(1, 40), (5, 6), (12, 9)]),
)
def test_dense_shortlists_keep_the_contract(seed, tolerance, k, bound, shape) -> None:
    """Every candidate up to (1 + tol)(E_(k) + b) + b is listed, sorted, with its value;
    the k-th smallest row minimum the reduction uses only ever lists more."""
    rng = np.random.default_rng(seed)
    fields = rng.random((3, *shape)).astype(np.float32)
    bounds = np.full(3, bound)
    for field, listed in zip(fields, shortlist_fields(fields, bounds, tolerance, k), strict=True):
        flat = field.ravel().astype(np.float64)
        kth = np.sort(flat)[min(k, flat.size) - 1]
        required = np.flatnonzero(flat <= (1 + tolerance) * (kth + bound) + bound)
        assert np.isin(required, listed.index).all()
        assert np.all(np.diff(listed.index) > 0)
        assert np.array_equal(listed.values, flat[listed.index])
        assert listed.bound == bound


def test_relative_costs_are_over_the_median() -> None:
    costs = np.array([1.0, 2.0, 4.0, 8.0, 3.0])
    np.testing.assert_array_equal(relative_costs(costs), costs / 3.0)
    # The same weights whatever the texture's contrast.
    np.testing.assert_allclose(relative_costs(costs * 1e-4), relative_costs(costs))


def test_relative_costs_fall_back_to_the_mean_then_to_zero() -> None:
    costs = np.array([0.0, 0.0, 0.0, 2.0])
    np.testing.assert_array_equal(relative_costs(costs), costs / 0.5)
    np.testing.assert_array_equal(relative_costs(np.zeros(3)), np.zeros(3))


@pytest.mark.parametrize("seed", range(30))
@pytest.mark.parametrize("count", [1, 5])
def test_first_acceptable_is_the_accepted_set_in_hash_order(seed: int, count: int) -> None:
    rng = np.random.default_rng(seed)
    size = int(rng.integers(5, 600))
    # Exact costs with many ties (a flat background) or none, and noisy approximations.
    exact_costs = np.round(rng.random(size) * rng.choice([1, 4, 1000]), 0) * rng.random()
    bound = float(rng.choice([0.0, 1e-3, 0.3]))
    noisy = exact_costs + rng.uniform(-bound, bound, size)
    tolerance, k = float(rng.choice([0.0, 0.1, 1.0])), int(rng.integers(1, 6))
    shortlist = shortlist_fields(noisy[None, None, :], np.array([bound]), tolerance, k)[0]
    key = int(rng.integers(0, 2**63))

    def exact(index: np.ndarray) -> np.ndarray:
        return exact_costs[index]

    accepted = acceptable([shortlist], lambda owner, index: exact_costs[index], tolerance, k)[0]
    want = accepted[np.lexsort((accepted, candidate_hash(key, accepted)))][:count]
    got = first_acceptable(shortlist, exact, tolerance, k, key, count)
    assert np.array_equal(got, want)


def test_first_acceptable_scores_one_of_many_ties() -> None:
    # Every candidate of a flat field costs 0: the first in hash order is taken at once.
    size = 50_000
    shortlist = shortlist_fields(np.zeros((1, 1, size)), np.array([1e-6]), 0.1, 3)[0]
    scored: list[int] = []

    def exact(index: np.ndarray) -> np.ndarray:
        scored.append(index.size)
        return np.zeros(index.size)

    first_acceptable(shortlist, exact, 0.1, 3, key=7)
    assert sum(scored) <= 32
