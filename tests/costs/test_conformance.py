"""Every backend against the reference: fields equal within the declared bound."""

from __future__ import annotations

import numpy as np
import pytest

from quilting.core.fields import CostRequest, ExactScorer
from quilting.core.grid import Grid, Overlap
from quilting.costs.fft import FFTBackend
from quilting.costs.reference import ReferenceBackend


@pytest.fixture(params=["fft", pytest.param("gl", marks=pytest.mark.gl)])
def backend_cls(request: pytest.FixtureRequest) -> type:
    """Each fast backend's class; ``gl`` goes through the ``gl`` fixture (skips without a
    context, fails in CI)."""
    if request.param == "gl":
        return request.getfixturevalue("gl").GLBackend
    return FFTBackend


def _requests(rng: np.random.Generator, block: int, channels: int) -> list[CostRequest]:
    grid = Grid(block=block, overlap=max(1, block // 5), rows=2, cols=2)
    masks = [grid.overlap_mask(kind) for kind in (Overlap.LEFT, Overlap.TOP, Overlap.BOTH)]
    masks.append((rng.random((block, block)) < 0.3).astype(np.float32) * rng.random())
    return [
        CostRequest(rng.random((block, block, channels), dtype=np.float32), mask) for mask in masks
    ]


@pytest.mark.parametrize("channels", [1, 3, 4])
@pytest.mark.parametrize("shape,block", [((40, 37), 12), ((64, 64), 16), ((31, 50), 7)])
def test_fields_equal_reference(backend_cls, channels, shape, block) -> None:
    rng = np.random.default_rng(channels * 1000 + block)
    source = rng.random((*shape, channels), dtype=np.float32)
    requests = _requests(rng, block, channels)
    fast, ref = backend_cls(), ReferenceBackend()
    fast.prepare(source, block)
    ref.prepare(source, block)
    got, want = fast.fields(requests), ref.fields(requests)
    assert got.values.shape == want.values.shape == (4, shape[0] - block + 1, shape[1] - block + 1)
    assert np.all(want.error_bound == 0)
    error = np.abs(got.values - want.values).max(axis=(1, 2))
    assert np.all(error <= got.error_bound)
    # The bound must be tight enough to be useful: far below the spread of the costs.
    spread = want.values.max(axis=(1, 2)) - want.values.min(axis=(1, 2))
    assert np.all(got.error_bound < 1e-2 * spread)


def test_fields_on_real_texture(backend_cls, hubble) -> None:
    source = hubble.astype(np.float32) / 255
    block = 48
    rng = np.random.default_rng(5)
    grid = Grid(block=block, overlap=8, rows=2, cols=2)
    requests = []
    for kind in (Overlap.LEFT, Overlap.TOP, Overlap.BOTH):
        y, x = rng.integers(0, 256 - block, size=2)
        # A real template: a piece of the texture itself, so the minimum is ~0.
        requests.append(
            CostRequest(source[y : y + block, x : x + block].copy(), grid.overlap_mask(kind))
        )
    fast, ref = backend_cls(), ReferenceBackend()
    fast.prepare(source, block)
    ref.prepare(source, block)
    got, want = fast.fields(requests), ref.fields(requests)
    assert np.all(np.abs(got.values - want.values).max(axis=(1, 2)) <= got.error_bound)
    assert np.all(want.values.min(axis=(1, 2)) == 0.0)


def test_fft_does_not_depend_on_threads() -> None:
    rng = np.random.default_rng(3)
    source = rng.random((50, 60, 3), dtype=np.float32)
    requests = _requests(rng, 10, 3) * 3
    outs = []
    for threads in (1, 2, 3):
        backend = FFTBackend(threads=threads)
        backend.prepare(source, 10)
        outs.append(backend.fields(requests))
        backend.close()
    # pocketfft groups transforms for SIMD, so the last bits depend on how a batch is split;
    # the fields agree within their bound, and exact re-scoring makes the choices identical.
    for out in outs[1:]:
        assert np.all(np.abs(out.values - outs[0].values).max(axis=(1, 2)) <= out.error_bound)


def test_exact_scorer_matches_naive_sum() -> None:
    rng = np.random.default_rng(11)
    source = rng.random((20, 25, 3), dtype=np.float32)
    template = rng.random((6, 6, 3), dtype=np.float32)
    mask = (rng.random((6, 6)) < 0.5).astype(np.float32) * 2
    scorer = ExactScorer(source, 6)
    ys, xs = np.divmod(np.arange(15 * 20), 20)
    got = scorer.costs(CostRequest(template, mask), ys, xs)
    for k, (y, x) in enumerate(zip(ys, xs, strict=True)):
        patch = source[y : y + 6, x : x + 6].astype(np.float64)
        want = float(np.sum(mask[..., None] * (patch - template) ** 2))
        assert got[k] == pytest.approx(want, rel=1e-12, abs=1e-12)


def test_reference_scores_positions_the_same_in_any_chunk() -> None:
    # The oracle and the re-scoring of shortlists share ExactScorer; a candidate's exact cost
    # must not depend on which other candidates were scored with it.
    rng = np.random.default_rng(2)
    source = rng.random((30, 30, 3), dtype=np.float32)
    request = _requests(rng, 8, 3)[2]
    scorer = ExactScorer(source, 8)
    ys, xs = np.divmod(np.arange(23 * 23), 23)
    everything = scorer.costs(request, ys, xs)
    pick = rng.choice(ys.size, size=17, replace=False)
    assert np.array_equal(scorer.costs(request, ys[pick], xs[pick]), everything[pick])
    assert np.array_equal(scorer.costs(request, ys[pick[:1]], xs[pick[:1]]), everything[pick[:1]])


def test_new_masks_from_many_threads_at_once() -> None:
    # Worker threads meet a new mask together: the per-mask energy cache must not hand out a
    # half-written entry (this raced once: the energy was visible before its error bound).
    rng = np.random.default_rng(8)
    source = rng.random((40, 40, 3), dtype=np.float32)
    for trial in range(20):
        masks = [(rng.random((8, 8)) < 0.5).astype(np.float32) for _ in range(6)]
        requests = [CostRequest(rng.random((8, 8, 3), dtype=np.float32), m) for m in masks * 4]
        backend = FFTBackend(threads=4)
        backend.prepare(source, 8)
        ref = ReferenceBackend()
        ref.prepare(source, 8)
        got, want = backend.fields(requests), ref.fields(requests)
        backend.close()
        assert np.all(np.abs(got.values - want.values).max(axis=(1, 2)) <= got.error_bound), trial


def _transfer_requests(
    rng: np.random.Generator, block: int, channels: int, guide_channels: int
) -> list[CostRequest]:
    """Requests with every combination of the transfer terms (previous pass, guide map)."""
    base = _requests(rng, block, channels)
    out = []
    for k, request in enumerate(base):
        previous = rng.random((block, block, channels), dtype=np.float32)
        guide = rng.random((block, block, guide_channels), dtype=np.float32)
        with_previous, with_guide = k % 2 == 0, k < 2
        out.append(
            CostRequest(
                request.template,
                request.mask,
                previous=previous if with_previous else None,
                previous_weight=0.3 if with_previous else 0.0,
                guide=guide if with_guide else None,
                guide_weight=0.7 if with_guide else 0.0,
            )
        )
    return out


@pytest.mark.parametrize(
    "channels,guide_channels,linear",
    [(1, 1, False), (3, 1, False), (4, 3, False), (1, 1, True), (3, 1, True), (4, 2, True)],
)
def test_transfer_terms_equal_reference(backend_cls, channels, guide_channels, linear) -> None:
    """Random guide maps, and guide maps that are combinations of the source's channels (as
    luminance is), which the fft backend folds into the source correlation."""
    rng = np.random.default_rng(20 + channels + 10 * linear)
    shape, block = (45, 38), 11
    source = rng.random((*shape, channels), dtype=np.float32)
    if linear:
        mix = rng.random((channels, guide_channels)).astype(np.float32)
        guide_map = source @ mix  # float32 products: a fold within rounding, not exactly
    else:
        guide_map = rng.random((*shape, guide_channels), dtype=np.float32)
    requests = _transfer_requests(rng, block, channels, guide_channels)
    fast, ref = backend_cls(), ReferenceBackend()
    fast.prepare(source, block, guide_map)
    ref.prepare(source, block, guide_map)
    got, want = fast.fields(requests), ref.fields(requests)
    error = np.abs(got.values - want.values).max(axis=(1, 2))
    assert np.all(error <= got.error_bound)
    spread = want.values.max(axis=(1, 2)) - want.values.min(axis=(1, 2))
    assert np.all(got.error_bound < 1e-2 * spread)


def test_exact_scorer_transfer_terms_match_the_formula() -> None:
    rng = np.random.default_rng(31)
    source = rng.random((18, 21, 3), dtype=np.float32)
    guide_map = rng.random((18, 21, 2), dtype=np.float32)
    block = 5
    template = rng.random((block, block, 3), dtype=np.float32)
    previous = rng.random((block, block, 3), dtype=np.float32)
    guide = rng.random((block, block, 2), dtype=np.float32)
    mask = (rng.random((block, block)) < 0.4).astype(np.float32)
    request = CostRequest(template, mask, previous, 0.25, guide, 1.5)
    scorer = ExactScorer(source, block, guide_map)
    ys, xs = np.divmod(np.arange(14 * 17), 17)
    got = scorer.costs(request, ys, xs)
    for k, (y, x) in enumerate(zip(ys, xs, strict=True)):
        s = source[y : y + block, x : x + block].astype(np.float64)
        g = guide_map[y : y + block, x : x + block].astype(np.float64)
        want = (
            np.sum(mask[..., None] * (s - template) ** 2)
            + 0.25 * np.sum((s - previous) ** 2)
            + 1.5 * np.sum((g - guide) ** 2)
        )
        assert got[k] == pytest.approx(want, rel=1e-12, abs=1e-12)


def test_requests_without_transfer_terms_score_as_before() -> None:
    # Zero weights must not change a single bit of the synthesis costs.
    rng = np.random.default_rng(4)
    source = rng.random((30, 30, 3), dtype=np.float32)
    plain = _requests(rng, 8, 3)
    zero = [
        CostRequest(r.template, r.mask, previous=r.template, previous_weight=0.0) for r in plain
    ]
    scorer = ExactScorer(source, 8)
    ys, xs = np.divmod(np.arange(23 * 23), 23)
    for a, b in zip(plain, zero, strict=True):
        assert np.array_equal(scorer.costs(a, ys, xs), scorer.costs(b, ys, xs))
    backend = FFTBackend(threads=1)
    backend.prepare(source, 8)
    assert np.array_equal(backend.fields(plain).values, backend.fields(zero).values)


def test_weights_need_their_terms() -> None:
    template = np.zeros((4, 4, 1), np.float32)
    mask = np.ones((4, 4), np.float32)
    with pytest.raises(ValueError, match="previous_weight"):
        CostRequest(template, mask, previous_weight=1.0)
    with pytest.raises(ValueError, match="guide_weight"):
        CostRequest(template, mask, guide=template, guide_weight=-1.0)


def test_fft_folds_only_source_linear_guides() -> None:
    rng = np.random.default_rng(41)
    source = rng.random((30, 30, 3), dtype=np.float32)
    backend = FFTBackend(threads=1)
    backend.prepare(source, 8, source @ np.array([[0.299], [0.587], [0.114]], np.float32))
    assert backend._fold is not None
    assert backend._fold.ravel() == pytest.approx([0.299, 0.587, 0.114], abs=1e-6)
    backend.prepare(source, 8, rng.random((30, 30, 1), dtype=np.float32))
    assert backend._fold is None
    backend.close()
