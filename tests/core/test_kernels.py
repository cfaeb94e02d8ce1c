"""The compiled kernels: the same numbers as numpy's sums, and as the cuts of whole error
surfaces (the DP itself is checked against brute force in test_seams.py)."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from quilting.core.kernels import candidate_seam_costs
from quilting.core.seams import CONTEXT, CONTEXT_RADIUS, far_side_cuts, minimum_error_cuts


def surface_costs(
    match: np.ndarray,
    template: np.ndarray,
    corners: np.ndarray,
    left: bool,
    top: bool,
    right: bool,
    bottom: bool,
    overlap: int,
    wrap: tuple[int, int],
    edge_cost: float,
    context: float = 0.0,
) -> np.ndarray:
    """The long way: gather whole blocks, their error surfaces by einsum, then the cuts of
    :func:`minimum_error_cuts` and :func:`far_side_cuts` on them."""
    size = template.shape[0]
    blocks = np.stack([match[y : y + size, x : x + size] for y, x in corners])
    diff = template[None] - blocks
    errors = np.einsum("nyxc,nyxc->nyx", diff, diff).astype(np.float64)
    cutter = functools.partial(minimum_error_cuts, edge_cost=edge_cost, context=context)
    cost = np.zeros(len(corners))
    if left or top:
        cost = cost + cutter(errors, left=left, top=top, overlap=overlap)[2]
    if right or bottom:
        cost = cost + far_side_cuts(cutter, errors, right=right, bottom=bottom, overlap=wrap)[2]
    return cost


KINDS = [
    (True, False, False, False),
    (False, True, False, False),
    (True, True, False, False),
    (True, True, True, False),
    (True, True, False, True),
    (False, True, True, True),
    (True, False, False, True),
]


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("channels", [1, 2, 3, 4])
@pytest.mark.parametrize(("edge_cost", "context"), [(0.0, 0.0), (0.1, 0.0), (0.1, CONTEXT)])
def test_candidate_costs_are_the_cuts_of_whole_surfaces(
    kind: tuple[bool, bool, bool, bool], channels: int, edge_cost: float, context: float
) -> None:
    rng = np.random.default_rng(channels * 100 + int(edge_cost * 10) + int(context * 1000))
    # Quantized values: ties in the DP are common, as with 8-bit textures.
    match = (rng.integers(0, 6, (40, 44, channels)) / 5).astype(np.float32)
    for size, overlap in [(12, 2), (12, 3), (16, 5), (9, 4)]:
        template = (rng.integers(0, 6, (size, size, channels)) / 5).astype(np.float32)
        ys = rng.integers(0, 40 - size + 1, 30)
        xs = rng.integers(0, 44 - size + 1, 30)
        corners = np.stack([ys, xs], axis=1).astype(np.intp)
        wrap = (overlap - 1 if overlap > 1 else 1, overlap)
        got = candidate_seam_costs(
            match,
            template,
            corners,
            left=kind[0],
            top=kind[1],
            right=kind[2],
            bottom=kind[3],
            overlap=overlap,
            wrap_overlap=wrap,
            edge_cost=edge_cost,
            context=context,
            radius=CONTEXT_RADIUS,
        )
        want = surface_costs(match, template, corners, *kind, overlap, wrap, edge_cost, context)
        np.testing.assert_array_equal(got, want)


def test_candidate_costs_are_the_cuts_of_whole_surfaces_on_a_texture(
    gravel: np.ndarray, hubble: np.ndarray
) -> None:
    rng = np.random.default_rng(5)
    for image in (gravel[..., None], hubble):
        match = (image / 255.0).astype(np.float32)
        size, overlap = 48, 8
        template = match[100 : 100 + size, 37 : 37 + size] + np.float32(0.01)
        corners = rng.integers(0, match.shape[0] - size + 1, (200, 2)).astype(np.intp)
        for edge_cost, context in ((0.0, 0.0), (0.1, 0.0), (0.1, CONTEXT)):
            got = candidate_seam_costs(
                match,
                template,
                corners,
                left=True,
                top=True,
                overlap=overlap,
                edge_cost=edge_cost,
                context=context,
                radius=CONTEXT_RADIUS,
            )
            want = surface_costs(
                match,
                template,
                corners,
                True,
                True,
                False,
                False,
                overlap,
                (0, 0),
                edge_cost,
                context,
            )
            np.testing.assert_array_equal(got, want)


def test_no_candidates_gives_no_costs() -> None:
    match = np.zeros((10, 10, 3), dtype=np.float32)
    got = candidate_seam_costs(
        match, match[:6, :6], np.zeros((0, 2), dtype=np.intp), left=True, top=False, overlap=2
    )
    assert got.shape == (0,)


@pytest.mark.parametrize("count", [1, 7, 8, 9, 64, 127, 128, 129, 255, 256, 300, 1000, 4097])
def test_pairwise_sum_is_numpys(count: int) -> None:
    from quilting.core.kernels.exact import pairwise_sum

    rng = np.random.default_rng(count)
    values = rng.random(count) * 10.0 ** rng.integers(-3, 4, count)
    assert pairwise_sum(values, count) == values.sum()


@pytest.mark.parametrize("channels", [1, 3, 4])
def test_masked_costs_are_numpys_sums(channels: int) -> None:
    from quilting.core.kernels import masked_costs

    rng = np.random.default_rng(channels)
    pixels = rng.random((50 * 50, channels))
    ys, xs = np.nonzero(rng.random((12, 12)) < 0.4)
    offsets = (ys * 50 + xs).astype(np.intp)
    weights = rng.random(offsets.size)
    targets = rng.random((3, offsets.size, channels))
    which = rng.integers(0, 3, 200).astype(np.intp)
    corners = (rng.integers(0, 38, 200) * 50 + rng.integers(0, 38, 200)).astype(np.intp)
    diff = pixels[corners[:, None] + offsets] - targets[which]
    want = ((diff * diff).sum(axis=-1) * weights).sum(axis=-1)
    got = masked_costs(pixels, offsets, weights, targets, which, corners)
    np.testing.assert_array_equal(got, want)
    # Weights 1: the plain sums of squares (the transfer terms).
    plain = masked_costs(pixels, offsets, np.ones(offsets.size), targets, which, corners)
    np.testing.assert_array_equal(plain, (diff * diff).sum(axis=-1).sum(axis=-1))


def test_add_cells_is_add_at_on_a_torus() -> None:
    from quilting.core.kernels import add_cells

    rng = np.random.default_rng(3)
    canvas = rng.random((30, 26, 3), dtype=np.float32)
    cells = rng.random((5, 12, 12, 3), dtype=np.float32)
    origins = np.array([[0, 0], [20, 20], [25, 3], [5, 18], [5, 18]], dtype=np.intp)
    want = canvas.copy()
    ys = ((origins[:, :1] + np.arange(12)) % 30)[:, :, None]
    xs = ((origins[:, 1:] + np.arange(12)) % 26)[:, None, :]
    np.add.at(want, (ys, xs), cells)
    add_cells(canvas, cells, origins)
    np.testing.assert_array_equal(canvas, want)


def test_seam_divergence_sums_to_zero_and_vanishes_without_seams() -> None:
    from quilting.core.kernels import seam_divergence

    rng = np.random.default_rng(4)
    old = rng.random((3, 10, 10, 3), dtype=np.float32)
    new = rng.random((3, 10, 10, 3), dtype=np.float32)
    covered = np.ones((3, 10, 10), dtype=bool)
    owned = np.zeros((3, 10, 10), dtype=bool)
    owned[:, :, 4:] = True
    found = seam_divergence(old, new, owned, covered, 1.25)
    # Each edge adds at one end what it takes at the other.
    np.testing.assert_allclose(found.sum(axis=(1, 2)), 0.0, atol=1e-5)
    assert found[:, :, [3, 4]].any() and not found[:, :, [0, 1, 2, 5, 6, 7, 8, 9]].any()
    assert not seam_divergence(old, new, np.ones_like(owned), covered, 1.25).any()


def test_warm_up_compiles_every_signature_a_job_uses(
    gravel: np.ndarray, hubble: np.ndarray
) -> None:
    # A service worker calls warm_up() before its first job: a job must then find every
    # kernel compiled for the types it passes, or it pays for a compilation.
    import numba

    import quilting
    from quilting.core.kernels import blend, compose, draws, exact, fields, seams, select

    quilting.warm_up()
    dispatchers = [
        value
        for module in (blend, compose, draws, exact, fields, seams, select)
        for value in vars(module).values()
        if isinstance(value, numba.core.registry.CPUDispatcher)
    ]
    before = {d: len(d.signatures) for d in dispatchers}
    cloud = np.zeros((64, 64, 4), dtype=np.uint8)
    cloud[..., :3] = hubble[:64, :64]
    cloud[..., 3] = gravel[:64, :64]
    quilting.synthesize(gravel[:96, :96], (100, 90), block=24, seed=1)
    tiled = quilting.synthesize(hubble[:96, :96], (100, 90), block=24, seed=1, tileable="both")
    heights = (gravel[:96, :96].astype(np.uint16) * 257)[..., None]
    quilting.apply_layout(tiled.layout, heights)
    quilting.apply_layout(tiled.layout, heights, kind="hard")
    quilting.synthesize(cloud, (80, 80), block=20, seed=1)
    quilting.transfer(hubble[:96, :96], gravel[:80, :80], block=16, iterations=2, seed=1)
    quilting.make_tileable(hubble[:96, :96])
    after = {d: len(d.signatures) for d in dispatchers}
    assert after == before, {d.py_func.__name__: (before[d], after[d]) for d in dispatchers}


def test_field_shortlist_lists_every_candidate_under_the_threshold() -> None:
    from quilting.core.kernels import field_shortlist

    rng = np.random.default_rng(6)
    for height, width, k in [(30, 40, 3), (2, 50, 5), (17, 1, 1), (1, 1, 3)]:
        cross = (rng.random((height, width + 7)) * 4 - 2).astype(np.float32)
        energy = rng.random((height, width)).astype(np.float32) * 3
        constant, bound, scale = np.float32(1.5), 1e-3, 1.1
        field = (cross[:, :width] + energy) + constant  # float32, in this order
        # The k-th smallest of the row minima (of every value when there are fewer rows).
        pool = field.min(axis=1) if height >= k else field.reshape(-1)
        kth = float(np.sort(pool)[min(k, pool.size) - 1])
        high = scale * (kth + bound) + bound
        want = np.flatnonzero(field.reshape(-1).astype(np.float64) <= high)
        index, values = field_shortlist(cross, energy, constant, bound, scale, k)
        np.testing.assert_array_equal(index, want)
        np.testing.assert_array_equal(values, field.reshape(-1)[want].astype(np.float64))
        np.testing.assert_array_equal(cross[:, :width], field)  # written in place
        assert index.size >= min(k, height * width)


def test_spectral_sum_is_the_conjugate_of_the_channel_sum() -> None:
    from quilting.core.kernels import spectral_sum

    rng = np.random.default_rng(7)
    for channels in (1, 3, 4):
        spectra = (rng.random((5, channels, 8, 6)) + 1j * rng.random((5, channels, 8, 6))).astype(
            np.complex64
        )
        source = (rng.random((channels, 8, 6)) + 1j * rng.random((channels, 8, 6))).astype(
            np.complex64
        )
        out = np.empty((5, 8, 6), dtype=np.complex64)
        spectral_sum(spectra, source, out)
        want = np.conj((spectra.astype(np.complex128) * source[None]).sum(axis=1))
        np.testing.assert_allclose(out, want, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32, np.float64, np.bool_])
def test_paste_pixels_writes_the_owned_pixels_in_block_order_on_a_torus(dtype: type) -> None:
    from quilting.core.kernels import paste_pixels

    rng = np.random.default_rng(8)
    canvas = (rng.random((20, 17, 3)) * 200).astype(dtype)
    blocks = (rng.random((4, 9, 9, 3)) * 200).astype(dtype)
    owned = rng.random((4, 9, 9)) < 0.6
    # Overlapping footprints (a later block wins) and some past the edges (wrapped).
    corners = np.array([[0, 0], [4, 5], [15, 12], [4, 5]], dtype=np.intp)
    want = canvas.copy()
    for k, (y, x) in enumerate(corners):
        for i in range(9):
            for j in range(9):
                if owned[k, i, j]:
                    want[(y + i) % 20, (x + j) % 17] = blocks[k, i, j]
    paste_pixels(canvas, blocks, corners, owned)
    np.testing.assert_array_equal(canvas, want)


#: Seeds of one to four 32-bit words (numpy splits them so), passes of one and two words.
SEEDS = [0, 1, 12345, 2**32 - 1, 2**32, 2**64 + 3, 2**100 + 9]
#: Bounds where the rejection never, sometimes and often redraws (2**32 mod high is 0, small
#: and near high), from 1 to the kernel's largest.
BOUNDS = [1, 2, 3, 7, 1000, 2**16, 2**31 - 1, 2**31 + 1, 3 * 2**30 + 5, 2**32 - 1]


@pytest.mark.parametrize("high", BOUNDS)
def test_first_integer_is_numpys_first_draw(high: int) -> None:
    from quilting.core.kernels import first_integer
    from quilting.core.randomness import _prefix

    places = np.random.default_rng(high).integers(0, 5000, size=(12, 2))
    for seed in SEEDS:
        for pass_index in (0, 2, 2**32 + 1):
            for row, col in places.tolist():
                words = [seed, pass_index, row, col]
                expected = np.random.Generator(np.random.PCG64(np.random.SeedSequence(words)))
                drawn = first_integer(_prefix(seed, pass_index), row, col, high)
                assert drawn == int(expected.integers(high)), words


def test_first_integer_declines_what_numpy_draws_another_way() -> None:
    from quilting.core.kernels import first_integer
    from quilting.core.randomness import _prefix

    prefix = _prefix(1, 0)
    assert first_integer(prefix, 3, 4, 2**32) is None  # numpy: a whole 32-bit draw
    assert first_integer(prefix, 3, 4, 2**40) is None  # numpy: 64-bit draws
    assert first_integer(prefix, 3, 4, 0) is None  # numpy refuses it
    assert first_integer(prefix, 2**32, 4, 5) is None  # a row of two words
    assert first_integer(prefix, 3, 2**32, 5) is None
