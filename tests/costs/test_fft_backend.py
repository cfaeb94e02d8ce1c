"""Unit tests of the FFT cost backend (``quilting.costs.fft``) against brute-force numpy.

Covers
------
- Dense fields equal ``sum M (S - T)^2`` computed directly (float64 sliding windows) at every
  valid position, for shared and one-off masks, 1 and 3 channels, sources whose sides are
  primes or powers of two and blocks as large as the source, within a float32 tolerance
  derived from the magnitudes of the inputs (and within the backend's own error bound).
- Exactness promises: fields do not depend on the thread count, on how a batch is split into
  calls or ordered (same bytes, as the class docstring says "Results do not depend on it"),
  and shortlist values are the dense field's float32 values.
- Shortlists hold the true minimum and every candidate of the documented tolerance band.
- ``prepare`` with another source, block or guide replaces what was prepared before;
  ``close`` releases the job and the thread pool, a closed backend refuses work until it is
  prepared again.
- The private helpers: ``_map``'s chunking, ``_Terms``' decomposition of a field, ``_Map``'s
  norms and spectra, ``_stacked`` and ``_linear_fit`` on hand-made inputs.

Agreement with the reference backend, thread safety of the energy cache and the transfer terms
are checked in ``test_conformance.py`` and ``test_one_off_masks.py`` and not repeated here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pytest
import scipy.fft as sfft
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import NDArray

from quilting.core.fields import CostRequest, FieldBatch
from quilting.costs import fft
from quilting.costs.fft import FFTBackend

#: Unit round-off of float32 (2^-24).
EPS32 = float(np.finfo(np.float32).eps) / 2


# --------------------------------------------------------------------------------------------
# Brute force and request builders
# --------------------------------------------------------------------------------------------


def brute_fields(
    source: NDArray[np.float32], requests: Sequence[CostRequest]
) -> NDArray[np.float64]:
    """``sum M (S - T)^2`` at every valid position, in float64, by direct summation."""
    block = requests[0].mask.shape[0]
    windows = sliding_window_view(source.astype(np.float64), (block, block), axis=(0, 1))
    # windows: (H - B + 1, W - B + 1, C, B, B)
    out = []
    for request in requests:
        template = request.template.astype(np.float64).transpose(2, 0, 1)  # (C, B, B)
        mask = request.mask.astype(np.float64)
        out.append(np.einsum("yxcij,ij->yx", (windows - template) ** 2, mask))
    return np.stack(out)


def brute_energy(source: NDArray[np.float32], mask: NDArray[np.float32]) -> NDArray[np.float64]:
    """``sum M S^2`` at every valid position, float64."""
    block = mask.shape[0]
    windows = sliding_window_view(source.astype(np.float64), (block, block), axis=(0, 1))
    energy: NDArray[np.float64] = np.einsum("yxcij,ij->yx", windows**2, mask.astype(np.float64))
    return energy


def tolerance(source: NDArray[np.float32], request: CostRequest) -> float:
    """A float32 error allowance for one request's field, from the magnitudes involved.

    The backend computes ``E = sum M S^2 - 2 corr(M T, S) + sum M T^2``. The correlation (and,
    for a one-off mask, ``corr(M, S^2)`` too) is a float32 FFT over the whole source: by
    Cauchy-Schwarz every output is at most ``|K| |X|`` (Frobenius norms of kernel and map), and
    the round-off of a length-N float32 FFT grows like ``eps * log2(N)`` of that. The other
    terms are float32 numbers at most ``top`` (the largest energy plus the constant), each
    rounded by half an ulp, plus the two float32 additions. A factor 8 on each covers the
    constants of the estimate; the result stays below ~1e-3 of the costs' spread here
    (checked, with margin, by the tests that use it) and measured errors stay below 2 % of
    it, so a wrong term anywhere (a missed mask weight, channel or position) is far outside.
    """
    s = source.astype(np.float64)
    squares = (s**2).sum(axis=2)
    m = request.mask.astype(np.float64)
    mt = m[..., None] * request.template.astype(np.float64)
    kernel = math.hypot(2 * float(np.linalg.norm(mt)), float(np.linalg.norm(m)))
    image = math.hypot(float(np.linalg.norm(s)), float(np.linalg.norm(squares)))
    log_n = math.log2(source.shape[0] * source.shape[1]) + 1
    constant = float((m[..., None] * request.template.astype(np.float64) ** 2).sum())
    top = float(brute_energy(source, request.mask).max()) + constant
    return 8 * EPS32 * (log_n * kernel * image + 4 * top)


def overlap_masks(block: int, overlap: int) -> list[NDArray[np.float32]]:
    """The grid's three overlap kinds (left strip, top strip, both) and a weighted mask."""
    left = np.zeros((block, block), np.float32)
    left[:, :overlap] = 1
    top = np.zeros((block, block), np.float32)
    top[:overlap] = 1
    both = np.maximum(left, top)
    weighted = np.zeros((block, block), np.float32)
    weighted[:, :overlap] = np.linspace(0.75, 0.25, overlap, dtype=np.float32)
    return [left, top, both, weighted]


def make_requests(
    rng: np.random.Generator,
    source: NDArray[np.float32],
    block: int,
    count: int,
    shared: bool,
) -> list[CostRequest]:
    """``count`` requests; shared ones cycle through a few mask arrays, one-off ones each get a
    mask of their own (random support and weights). The first template is a piece of the
    source itself, so its field has an exact zero: the worst case for cancellation."""
    height, width, channels = source.shape
    masks = overlap_masks(block, max(1, block // 4))
    requests = []
    for k in range(count):
        if k == 0:
            y = int(rng.integers(0, height - block + 1))
            x = int(rng.integers(0, width - block + 1))
            template = source[y : y + block, x : x + block].copy()
        else:
            template = rng.random((block, block, channels), dtype=np.float32)
        if shared:
            mask = masks[k % len(masks)]
        else:
            support = rng.random((block, block)) < rng.uniform(0.2, 0.9)
            mask = (support * rng.uniform(0.5, 2.0, (block, block))).astype(np.float32)
        requests.append(CostRequest(template, mask, shared_mask=shared))
    return requests


def prepared(source: NDArray[np.float32], block: int, threads: int = 1) -> FFTBackend:
    backend = FFTBackend(threads=threads)
    backend.prepare(source, block)
    return backend


# Sources whose sides are primes, powers of two, and blocks at the source's size limit.
SHAPES = [
    pytest.param((31, 37), 8, id="primes-31x37-b8"),
    pytest.param((53, 29), 29, id="primes-53x29-b29-width-limit"),
    pytest.param((32, 64), 16, id="pow2-32x64-b16"),
    pytest.param((64, 32), 32, id="pow2-64x32-b32-width-limit"),
    pytest.param((16, 16), 16, id="pow2-16x16-b16-single-position"),
    pytest.param((23, 41), 23, id="primes-23x41-b23-height-limit"),
]


# --------------------------------------------------------------------------------------------
# Fields against brute force
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("shared", [True, False], ids=["shared", "one-off"])
@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("shape,block", SHAPES)
def test_fields_equal_brute_force(
    shape: tuple[int, int], block: int, channels: int, shared: bool
) -> None:
    rng = np.random.default_rng([*shape, block, channels, int(shared)])
    source = rng.random((*shape, channels), dtype=np.float32)
    requests = make_requests(rng, source, block, 5, shared)
    backend = prepared(source, block)
    try:
        got = backend.fields(requests)
    finally:
        backend.close()
    want = brute_fields(source, requests)
    field_shape = (shape[0] - block + 1, shape[1] - block + 1)
    assert got.values.shape == (len(requests), *field_shape)
    assert got.error_bound.shape == (len(requests),)
    for k, request in enumerate(requests):
        error = float(np.abs(got.values[k].astype(np.float64) - want[k]).max())
        allowed = tolerance(source, request)
        assert error <= allowed, (k, error, allowed)
        assert error <= got.error_bound[k], (k, error, got.error_bound[k])
        if want[k].size > 1:  # the allowance must be small enough to mean something
            assert allowed < 1e-2 * (want[k].max() - want[k].min())
    # The piece of the source: its own position costs (about) nothing.
    assert float(got.values[0].min()) <= tolerance(source, requests[0])


def test_mask_weights_channels_and_positions_all_count() -> None:
    # Hand-made: a constant template against a source that is 1 in one pixel only. The cost at
    # (y, x) is sum M (S - t)^2; the single bright pixel raises it by M[py - y, px - x] * (1 -
    # 2t) in one channel, exactly where the block covers it.
    source = np.zeros((9, 11, 3), np.float32)
    source[5, 6, 2] = 1.0
    block, t = 4, 0.25
    mask = (np.arange(1, block * block + 1).reshape(block, block) / 8).astype(np.float32)
    template = np.full((block, block, 3), t, np.float32)
    want = np.full((6, 8), 3 * t**2 * float(mask.sum()))
    for y in range(6):
        for x in range(8):
            if 0 <= 5 - y < block and 0 <= 6 - x < block:
                want[y, x] += mask[5 - y, 6 - x] * (1 - 2 * t)
    for shared in (True, False):
        backend = prepared(source, block)
        got = backend.fields([CostRequest(template, mask, shared_mask=shared)])
        backend.close()
        np.testing.assert_allclose(got.values[0], want, rtol=0, atol=1e-5)


# --------------------------------------------------------------------------------------------
# Exactness: threads, chunks, order
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("shared", [True, False], ids=["shared", "one-off"])
def test_fields_do_not_depend_on_threads_chunks_or_order(shared: bool) -> None:
    # FFTBackend's docstring: "Results do not depend on it" (the thread count), and each
    # thread count cuts a batch into other chunks: the same bytes whatever the split.
    rng = np.random.default_rng(17 + shared)
    source = rng.random((41, 47, 3), dtype=np.float32)
    requests = make_requests(rng, source, 9, 17, shared)
    base = prepared(source, 9, threads=1)
    want = base.fields(requests)
    runs: dict[str, FieldBatch] = {}
    for threads in (2, 3, 4):
        backend = prepared(source, 9, threads=threads)
        runs[f"threads={threads}"] = backend.fields(requests)
        backend.close()
    runs["one call per request"] = FieldBatch(
        np.concatenate([base.fields([r]).values for r in requests]),
        np.concatenate([base.fields([r]).error_bound for r in requests]),
    )
    runs["uneven calls"] = FieldBatch(
        np.concatenate([base.fields(requests[a:b]).values for a, b in ((0, 7), (7, 8), (8, 17))]),
        np.concatenate(
            [base.fields(requests[a:b]).error_bound for a, b in ((0, 7), (7, 8), (8, 17))]
        ),
    )
    order = rng.permutation(len(requests))
    shuffled = base.fields([requests[k] for k in order])
    inverse = np.argsort(order)
    runs["shuffled"] = FieldBatch(shuffled.values[inverse], shuffled.error_bound[inverse])
    base.close()
    for how, got in runs.items():
        assert got.values.dtype == want.values.dtype, how
        assert np.array_equal(got.values, want.values), how
        assert np.array_equal(got.error_bound, want.error_bound), how


def test_a_batch_of_both_mask_kinds_is_each_request_s_own_terms() -> None:
    # A chunk took the one-off path only when all of it was one-off: in a mixed batch the
    # thread count (which cuts the chunks) changed a request's bytes, and one-off masks had
    # their energy fields kept.
    rng = np.random.default_rng(23)
    source = rng.random((40, 44, 3), dtype=np.float32)
    shared = make_requests(rng, source, 10, 3, shared=True)
    alone = make_requests(rng, source, 10, 6, shared=False)
    mixed = [shared[0], *alone, *shared[1:]]
    base = prepared(source, 10, threads=1)
    want = FieldBatch(
        np.concatenate([base.fields([r]).values for r in mixed]),
        np.concatenate([base.fields([r]).error_bound for r in mixed]),
    )
    kept = len(base._energy)
    assert kept == len({id(r.mask) for r in shared})  # the shared masks' energies only
    for threads in (1, 2, 3, 4):
        backend = prepared(source, 10, threads=threads)
        got = backend.fields(mixed)
        assert np.array_equal(got.values, want.values), threads
        assert np.array_equal(got.error_bound, want.error_bound), threads
        assert len(backend._energy) == kept, threads
        backend.close()
    base.close()


def test_an_empty_batch_is_empty() -> None:
    source = np.random.default_rng(2).random((20, 24, 3), dtype=np.float32)
    backend = prepared(source, 6, threads=2)
    batch = backend.fields([])
    assert batch.values.shape == (0, 15, 19) and batch.error_bound.shape == (0,)
    assert backend.shortlists([], 0.1, 4) == []
    backend.close()


@pytest.mark.parametrize("shared", [True, False], ids=["shared", "one-off"])
def test_shortlists_do_not_depend_on_threads_and_match_the_fields(shared: bool) -> None:
    rng = np.random.default_rng(5 + shared)
    source = rng.random((37, 32, 3), dtype=np.float32)
    requests = make_requests(rng, source, 8, 13, shared)
    lists = []
    for threads in (1, 3):
        backend = prepared(source, 8, threads=threads)
        lists.append(backend.shortlists(requests, 0.2, 4))
        dense = backend.fields(requests)
        backend.close()
        # The shortlist's values are the dense field's float32 values, not recomputed ones.
        for k, shortlist in enumerate(lists[-1]):
            flat = dense.values[k].ravel()
            assert np.array_equal(shortlist.values, flat[shortlist.index].astype(np.float64))
            assert shortlist.bound == dense.error_bound[k]
    for one, three in zip(*lists, strict=True):
        assert np.array_equal(one.index, three.index)
        assert np.array_equal(one.values, three.values)
        assert one.bound == three.bound


# --------------------------------------------------------------------------------------------
# Shortlists against brute force
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("tol,k", [(0.0, 1), (0.1, 4), (0.5, 3)])
@pytest.mark.parametrize("shared", [True, False], ids=["shared", "one-off"])
@pytest.mark.parametrize(
    "shape,block",
    [
        pytest.param((29, 31), 7, id="primes"),
        pytest.param((20, 33), 20, id="one-row-field"),
        pytest.param((12, 12), 12, id="single-position"),
    ],
)
def test_shortlists_hold_the_minimum_and_the_tolerance_band(
    shape: tuple[int, int], block: int, shared: bool, tol: float, k: int
) -> None:
    rng = np.random.default_rng(int(tol * 10) + k + 100 * block)
    source = rng.random((*shape, 3), dtype=np.float32)
    # Templates near source pieces: fields with a clear minimum and a crowd of near ties.
    requests = make_requests(rng, source, block, 5, shared)
    backend = prepared(source, block)
    try:
        lists = backend.shortlists(requests, tol, k)
        approx = backend.fields(requests)
    finally:
        backend.close()
    exact = brute_fields(source, requests)
    assert len(lists) == len(requests)
    for n, shortlist in enumerate(lists):
        flat = exact[n].ravel()
        index = shortlist.index
        assert index.dtype == np.intp and shortlist.values.dtype == np.float64
        assert np.all(np.diff(index) > 0)  # ascending, no repeats
        assert index.size >= min(k, flat.size)
        assert int(np.argmin(flat)) in index
        # Every candidate whose exact cost is within the band of the k-th smallest exact cost:
        # its approximate cost is within the documented threshold (1 + t)(E_(k) + b) + b.
        kth_exact = float(np.partition(flat, min(k, flat.size) - 1)[min(k, flat.size) - 1])
        band = np.flatnonzero(flat <= (1 + tol) * kth_exact)
        assert np.isin(band, index).all(), (n, np.setdiff1d(band, index))
        # The documented rule itself, on the backend's own approximate values.
        values = approx.values[n].ravel().astype(np.float64)
        bound = float(shortlist.bound)
        kth = float(np.partition(values, min(k, values.size) - 1)[min(k, values.size) - 1])
        rule = np.flatnonzero(values <= (1 + tol) * (kth + bound) + bound)
        assert np.isin(rule, index).all()
        # The listed values are within the bound of the exact costs.
        assert np.all(np.abs(shortlist.values - flat[index]) <= bound)


# --------------------------------------------------------------------------------------------
# prepare / close
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("shared", [True, False], ids=["shared", "one-off"])
def test_prepare_with_another_source_forgets_the_first(shared: bool) -> None:
    rng = np.random.default_rng(23 + shared)
    first = rng.random((30, 34, 3), dtype=np.float32)
    second = rng.random((30, 34, 3), dtype=np.float32) ** 2  # other values, same shape
    requests = make_requests(rng, first, 8, 6, shared)
    backend = FFTBackend(threads=2)
    backend.prepare(first, 8)
    on_first = backend.fields(requests)  # fills the caches (energies, joint spectra)
    backend.prepare(second, 8)
    on_second = backend.fields(requests)
    fresh = prepared(second, 8, threads=2)
    want = fresh.fields(requests)
    fresh.close()
    backend.close()
    assert np.array_equal(on_second.values, want.values)
    assert np.array_equal(on_second.error_bound, want.error_bound)
    exact = brute_fields(second, requests)
    for k, request in enumerate(requests):
        assert np.abs(on_second.values[k] - exact[k]).max() <= tolerance(second, request)
    assert not np.allclose(on_first.values, on_second.values)


def test_prepare_with_another_shape_block_or_guide_replaces_the_job() -> None:
    rng = np.random.default_rng(29)
    big = rng.random((40, 45, 3), dtype=np.float32)
    small = rng.random((19, 23, 3), dtype=np.float32)
    guide_map = rng.random((40, 45, 1), dtype=np.float32)
    backend = FFTBackend(threads=1)
    backend.prepare(big, 10, guide_map)
    guided = CostRequest(
        rng.random((10, 10, 3), dtype=np.float32),
        overlap_masks(10, 3)[0],
        guide=rng.random((10, 10, 1), dtype=np.float32),
        guide_weight=0.5,
    )
    backend.fields([guided])
    # Another source, another block, no guide: the field's shape follows, the old guide is gone.
    backend.prepare(small, 6)
    requests = make_requests(rng, small, 6, 4, True)
    got = backend.fields(requests)
    assert got.values.shape == (4, 14, 18)
    exact = brute_fields(small, requests)
    for k, request in enumerate(requests):
        assert np.abs(got.values[k] - exact[k]).max() <= tolerance(small, request)
    with pytest.raises(ValueError, match="guide"):
        backend.fields([guided])
    backend.close()


def test_close_releases_the_job_and_the_pool() -> None:
    rng = np.random.default_rng(31)
    source = rng.random((26, 30, 3), dtype=np.float32)
    requests = make_requests(rng, source, 7, 8, True) + make_requests(rng, source, 7, 8, False)
    backend = FFTBackend(threads=2)
    backend.prepare(source, 7)
    before = backend.fields(requests)
    pool = backend._pool
    assert pool is not None
    backend.close()
    assert backend._spectrum is None
    assert backend._maps == {} and backend._energy == {}
    assert backend._joint is None and backend._with_energy is None and backend._fold is None
    assert backend._pool is None
    with pytest.raises(RuntimeError):  # the pool was shut down: it takes no more work
        pool.submit(int)
    with pytest.raises(RuntimeError, match="prepare"):
        backend.fields(requests)
    with pytest.raises(RuntimeError, match="prepare"):
        backend.shortlists(requests, 0.1, 3)
    # Prepared again, it works as before, on a new pool.
    backend.prepare(source, 7)
    assert backend._pool is not None and backend._pool is not pool
    after = backend.fields(requests)
    backend.close()
    assert np.array_equal(after.values, before.values)


def test_unprepared_backend_refuses_work() -> None:
    backend = FFTBackend(threads=1)
    request = CostRequest(np.zeros((4, 4, 1), np.float32), np.ones((4, 4), np.float32))
    with pytest.raises(RuntimeError, match="prepare"):
        backend.fields([request])


# --------------------------------------------------------------------------------------------
# Private helpers
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("threads", [1, 2, 3, 4])
def test_map_cuts_batches_into_even_ordered_chunks(threads: int) -> None:
    # _map's comment: chunks at most _CHUNK long, as many as a multiple of the threads, of
    # equal length to within one, results in order.
    backend = prepared(np.zeros((8, 8, 1), np.float32), 4, threads=threads)
    mask = np.ones((4, 4), np.float32)
    pool = [CostRequest(np.full((4, 4, 1), k, np.float32), mask) for k in range(30)]

    def chunk(part: Sequence[CostRequest]) -> list[CostRequest]:
        return list(part)

    try:
        for n in range(1, 31):
            parts = backend._map(chunk, pool[:n])
            sizes = [len(p) for p in parts]
            assert [x for p in parts for x in p] == pool[:n], n
            assert max(sizes) <= fft._CHUNK, (n, sizes)
            assert max(sizes) - min(sizes) <= 1, (n, sizes)
            assert min(sizes) >= 1, (n, sizes)
            if n >= threads:
                assert len(parts) % threads == 0, (n, sizes)
        # The module's own example: 17 requests on 2 threads run in 4 chunks of 4 or 5.
        if threads == 2:
            assert sorted(len(p) for p in backend._map(chunk, pool[:17])) == [4, 4, 4, 5]
    finally:
        backend.close()


@pytest.mark.parametrize("shared", [True, False], ids=["shared", "one-off"])
def test_terms_add_up_to_the_field(shared: bool) -> None:
    # _Terms: field[k] = (cross[k][:, :W] + energies[k]) + constants[k] in float32.
    rng = np.random.default_rng(37 + shared)
    source = rng.random((25, 28, 3), dtype=np.float32)
    block = 6
    requests = make_requests(rng, source, block, 8, shared)
    backend = prepared(source, block)
    terms = backend._terms(requests)
    dense = backend.fields(requests)
    backend.close()
    height, width = 25 - block + 1, 28 - block + 1
    assert terms.cross.dtype == np.float32 and terms.cross.shape[:2] == (8, height)
    rebuilt = np.stack(
        [
            (terms.cross[k][:, :width] + terms.energies[k]) + terms.constants[k]
            for k in range(len(requests))
        ]
    )
    assert np.array_equal(rebuilt, dense.values)
    assert np.array_equal(terms.bounds, dense.error_bound)
    for k, request in enumerate(requests):
        constant = float((request.mask[..., None] * request.template.astype(np.float64) ** 2).sum())
        assert terms.constants[k] == np.float32(constant)
        if shared:
            # sum M S^2, computed in float64 and stored in float32: half an ulp of the largest.
            want = brute_energy(source, request.mask)
            assert np.abs(terms.energies[k] - want).max() <= 2 * EPS32 * want.max()
        else:  # the energy rides in the cross term's transforms
            assert not terms.energies[k].any()
    if shared:
        # Requests of one mask share one energy field (one array, not copies).
        for j, other in enumerate(requests):
            same = np.array_equal(other.mask, requests[0].mask)
            assert (terms.energies[j] is terms.energies[0]) == same


def test_maps_hold_the_norms_and_spectra_of_the_source() -> None:
    source = np.zeros((5, 7, 2), np.float32)
    source[1, 2] = [3.0, 4.0]  # squares sum to 25
    source[4, 6] = [0.0, 1.0]
    backend = prepared(source, 3)
    nh, nw = backend._fft_shape
    assert nh >= 5 and nw >= 7  # circular correlation is exact only on a grid this large
    assert backend._field_shape == (3, 5)
    source_map = backend._maps["source"]
    assert set(backend._maps) == {"source"}
    assert source_map.norm == pytest.approx(math.sqrt(26.0))
    assert source_map.energy_norm == pytest.approx(math.sqrt(25.0**2 + 1.0))
    assert source_map.spectrum_conj.dtype == np.complex64
    assert source_map.spectrum_conj.shape == (2, nh, nw // 2 + 1)
    want = np.conj(sfft.rfft2(source.transpose(2, 0, 1).astype(np.float64), s=(nh, nw)))
    np.testing.assert_allclose(source_map.spectrum_conj, want, atol=1e-5)
    backend.close()


def test_stacked_stacks_and_sums_in_float64() -> None:
    # 4097^2 = 16785409 is odd and above 2^24: a float32 sum could not hold it.
    big = np.full((2, 2, 2), 4097.0, np.float32)
    small = np.arange(8, dtype=np.float32).reshape(2, 2, 2)
    ones = np.ones((2, 2), np.float32)
    partial = np.array([[0.5, 0.0], [2.0, 0.0]], np.float32)
    requests = [CostRequest(big, ones), CostRequest(small, partial), CostRequest(big, partial)]
    masks, templates, constants = fft._stacked(requests)
    assert masks.shape == (3, 2, 2) and masks.dtype == np.float32
    assert templates.shape == (3, 2, 2, 2) and templates.dtype == np.float32
    assert constants.shape == (3,) and constants.dtype == np.float64
    assert np.array_equal(masks, np.stack([ones, partial, partial]))
    assert np.array_equal(templates, np.stack([big, small, big]))
    # small: pixel (0, 0) holds 0, 1 (weight 0.5); pixel (1, 0) holds 4, 5 (weight 2).
    assert constants.tolist() == [8 * 4097**2, 0.5 * (0 + 1) + 2 * (16 + 25), 5 * 4097**2]


def test_linear_fit_finds_an_exact_combination() -> None:
    source = np.array(
        [[[1, 0, 2], [0, 1, 1]], [[3, 2, 0], [1, 1, 1]], [[0, 4, 1], [2, 0, 5]]], np.float32
    )  # (3, 2, 3): six pixels, three independent channels
    mix = np.array([[0.25, 0.5, 2.0], [1.0, 0.0, -1.0]])  # (K, C)
    guide = (source.astype(np.float64) @ mix.T).astype(np.float32)  # exact in float32
    fold, residual = fft._linear_fit(source, guide)
    assert fold is not None
    assert fold.shape == (2, 3) and fold.dtype == np.float64
    np.testing.assert_allclose(fold, mix, atol=1e-12)
    want = np.abs(source.reshape(-1, 3).astype(np.float64) @ fold.T - guide.reshape(-1, 2)).max()
    assert residual == pytest.approx(want, abs=1e-15)
    assert residual < 1e-12


def test_linear_fit_refuses_what_is_not_a_combination() -> None:
    source = np.array([[[1, 2], [3, 1]], [[2, 2], [0, 1]]], np.float32)
    product = (source[..., :1] * source[..., 1:]).astype(np.float32)  # c0 * c1: not linear
    assert fft._linear_fit(source, product) == (None, 0.0)
    # A linear guide moved by 1e-3 somewhere: far more than rounding.
    guide = source[..., :1] + source[..., 1:]
    guide[1, 0, 0] += np.float32(1e-3)
    assert fft._linear_fit(source, guide) == (None, 0.0)


def test_linear_fit_tolerates_rounding_only() -> None:
    # One channel of ones; the guide is 1 everywhere but one pixel, raised by d. The fit is
    # the mean, so the largest residual is about d: accepted up to a few float32 ulps
    # (8 unit round-offs of the guide's scale), refused beyond.
    source = np.ones((10, 10, 1), np.float32)
    for ulps, accepted in ((1, True), (16, False)):
        guide = np.ones((10, 10, 1), np.float32)
        guide[3, 7, 0] = np.float32(1 + ulps * 2 * EPS32)  # 2 EPS32 is one ulp at 1
        fold, residual = fft._linear_fit(source, guide)
        assert (fold is not None) is accepted, ulps
        if accepted:
            assert fold is not None
            assert fold[0, 0] == pytest.approx(1 + ulps * 2 * EPS32 / 100, abs=1e-12)
            assert residual == pytest.approx(ulps * 2 * EPS32 * 0.99, rel=1e-6)
        else:
            assert residual == 0.0
    # An all-zero guide is the zero combination.
    fold, residual = fft._linear_fit(source, np.zeros((10, 10, 2), np.float32))
    assert fold is not None and not fold.any() and fold.shape == (2, 1) and residual == 0.0
