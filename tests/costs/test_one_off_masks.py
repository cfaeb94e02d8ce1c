"""Requests whose masks are their own (a fill's): fields equal to the direct sums, nothing kept."""

from __future__ import annotations

import numpy as np
import pytest

from quilting.core.fields import CostRequest, ExactScorer
from quilting.core.select import acceptable
from quilting.costs.fft import FFTBackend
from quilting.costs.reference import ReferenceBackend


@pytest.fixture(params=["fft", pytest.param("gl", marks=pytest.mark.gl)])
def backend_cls(request: pytest.FixtureRequest) -> type:
    if request.param == "gl":
        return request.getfixturevalue("gl").GLBackend
    return FFTBackend


def _one_off(rng: np.random.Generator, count: int, block: int, channels: int) -> list[CostRequest]:
    """Random templates under random masks of any shape, each mask made for its request."""
    return [
        CostRequest(
            rng.random((block, block, channels), dtype=np.float32),
            (rng.random((block, block)) < rng.uniform(0.1, 0.9)).astype(np.float32),
            shared_mask=False,
        )
        for _ in range(count)
    ]


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("shape,block", [((40, 37), 12), ((64, 70), 16)])
def test_masked_fields_equal_the_direct_sums(backend_cls, channels, shape, block) -> None:
    rng = np.random.default_rng(channels * 100 + block)
    source = rng.random((*shape, channels), dtype=np.float32)
    requests = _one_off(rng, 5, block, channels)
    fast, ref = backend_cls(), ReferenceBackend()
    fast.prepare(source, block)
    ref.prepare(source, block)
    try:
        got, want = fast.fields(requests), ref.fields(requests)
    finally:
        fast.close()
    # The reference is the direct sum sum M (S - T)^2; check one position by hand too.
    y, x = 3, 5
    window = source[y : y + block, x : x + block].astype(np.float64)
    direct = (requests[0].mask[..., None] * (window - requests[0].template) ** 2).sum()
    assert want.values[0, y, x] == pytest.approx(direct, rel=1e-12)
    error = np.abs(got.values - want.values).max(axis=(1, 2))
    assert np.all(error <= got.error_bound)
    spread = want.values.max(axis=(1, 2)) - want.values.min(axis=(1, 2))
    assert np.all(got.error_bound < 1e-2 * spread)


def test_shortlists_choose_what_the_reference_chooses(backend_cls) -> None:
    rng = np.random.default_rng(11)
    block = 10
    source = rng.random((48, 52, 3), dtype=np.float32)
    requests = _one_off(rng, 6, block, 3)
    scorer = ExactScorer(source, block)

    def exact(owner: np.ndarray, index: np.ndarray) -> np.ndarray:
        ys, xs = np.divmod(index, 52 - block + 1)
        return scorer.costs_batch(requests, owner, ys, xs)

    chosen = []
    for backend in (backend_cls(), ReferenceBackend()):
        backend.prepare(source, block)
        try:
            lists = backend.shortlists(requests, 0.1, 3)
        finally:
            backend.close()
        chosen.append(acceptable(lists, exact, 0.1, 3))
    for fast, ref in zip(*chosen, strict=True):
        assert np.array_equal(fast, ref)


def test_fft_keeps_no_energy_per_one_off_mask() -> None:
    rng = np.random.default_rng(2)
    backend = FFTBackend(threads=1)
    backend.prepare(rng.random((40, 40, 3), dtype=np.float32), 8)
    backend.fields(_one_off(rng, 12, 8, 3))
    assert backend._energy == {}  # a shared mask would have cached a float64 field
    backend.close()


def test_exact_scorer_keeps_no_one_off_mask() -> None:
    rng = np.random.default_rng(4)
    scorer = ExactScorer(rng.random((30, 30, 3), dtype=np.float32), 6)
    requests = _one_off(rng, 4, 6, 3)
    scorer.costs_batch(requests, np.arange(4), np.zeros(4, np.intp), np.zeros(4, np.intp))
    assert len(scorer._masks) == 1  # only the whole block's support, made at construction


@pytest.mark.gl
def test_gl_mask_table_does_not_grow_with_one_off_masks(gl) -> None:
    rng = np.random.default_rng(6)
    backend = gl.GLBackend()
    backend.prepare(rng.random((40, 40, 3), dtype=np.float32), 8)
    try:
        for _ in range(3):
            backend.fields(_one_off(rng, 4, 8, 3))
        assert len(backend._masks.arrays) == 0
    finally:
        backend.close()
