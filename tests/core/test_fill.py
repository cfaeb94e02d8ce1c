"""quilting.fill, quilting.extend and make_tileable(method='fill'): known pixels kept byte for
byte, seams that never take one, the same bytes for the same seed on every backend, and clear
errors for masks that cannot be filled."""

from __future__ import annotations

import numpy as np
import pytest

import quilting
from quilting import FillOptions, InvalidImageError, InvalidParameterError, JobTooLargeError
from quilting.core.fill import hole_of, largest_block, origins


def _square_hole(shape: tuple[int, int], top: int, left: int, side: int) -> np.ndarray:
    mask = np.zeros(shape, dtype=bool)
    mask[top : top + side, left : left + side] = True
    return mask


def _blob(shape: tuple[int, int], seed: int) -> np.ndarray:
    """An irregular hole: a few overlapping discs."""
    rng = np.random.default_rng(seed)
    ys, xs = np.indices(shape)
    mask = np.zeros(shape, dtype=bool)
    for _ in range(4):
        cy, cx = (
            rng.integers(shape[0] // 3, 2 * shape[0] // 3),
            rng.integers(shape[1] // 3, 2 * shape[1] // 3),
        )
        mask |= (ys - cy) ** 2 + (xs - cx) ** 2 < rng.integers(8, 20) ** 2
    return mask


@pytest.mark.parametrize("blend", ["none", "poisson"])
@pytest.mark.parametrize("fixture", ["gravel", "hubble", "wood"])
def test_known_pixels_are_kept_byte_for_byte(request, fixture, blend) -> None:
    image = request.getfixturevalue(fixture)
    mask = _blob(image.shape[:2], 1)
    result = quilting.fill(image, mask, block=16, seed=3, blend=blend)
    assert result.image.shape == image.shape and result.image.dtype == image.dtype
    assert np.array_equal(result.image[~mask], image[~mask])
    assert np.array_equal(result.filled, mask)
    assert result.blocks > 0
    # Something was synthesized where the hole was (the hole's own pixels are never a source).
    assert not np.array_equal(result.image[mask], image[mask])


@pytest.mark.parametrize("dtype", [np.uint16, np.float32])
def test_other_dtypes_keep_their_pixels(gravel, dtype) -> None:
    scale = 257 if dtype == np.uint16 else 1 / 255
    image = (gravel.astype(np.float64) * scale).astype(dtype)
    mask = _square_hole(image.shape, 100, 90, 40)
    result = quilting.fill(image, mask, block=16, seed=1)
    assert result.image.dtype == dtype
    assert np.array_equal(result.image[~mask], image[~mask])


@pytest.mark.parametrize("dtype", [np.float16, np.float32, np.float64])
def test_float_pixels_outside_0_1_are_copied_not_clipped(gravel, dtype) -> None:
    # A float image may hold any finite values (HDR, a height map in metres): the filled
    # pixels are copies of source pixels in the image's own dtype, not clipped to [0, 1].
    image = (gravel.astype(np.float64) / 255 * 6 - 2).astype(dtype)
    mask = _square_hole(image.shape, 100, 90, 40)
    result = quilting.fill(image, mask, block=16, seed=1, blend="none")
    assert result.image.dtype == dtype
    rows, cols = result.source_rows, result.source_cols
    assert np.array_equal(result.image, image[rows, cols])
    assert result.image[mask].max() > 1 and result.image[mask].min() < 0
    blended = quilting.fill(image, mask, block=16, seed=1)
    assert blended.image[mask].max() > 1 and blended.image[mask].min() < 0


@pytest.mark.parametrize("blend", ["none", "poisson"])
def test_the_replay_fills_a_companion_as_the_image_was_filled(hubble, blend) -> None:
    mask = _blob(hubble.shape[:2], 2)
    result = quilting.fill(hubble, mask, block=20, seed=5, blend=blend)
    assert result.replay is not None
    # The image itself, filled again, is the result byte for byte, blend included ...
    assert np.array_equal(result.replay.render(hubble), result.image)
    # ... and the blend is the same linear operator on a companion: half the image (float32,
    # where halving is exact) comes back as half the result.
    working = hubble.astype(np.float32) / 255
    again = quilting.fill(working, mask, block=20, seed=5, blend=blend)
    assert again.replay is not None
    half = again.replay.render(working * np.float32(0.5))
    assert np.array_equal(half, again.image * np.float32(0.5))


def test_no_replay_when_the_blocks_came_from_elsewhere(gravel, brick) -> None:
    mask = _square_hole(gravel.shape[:2], 20, 20, 30)
    assert quilting.fill(gravel, mask, texture=brick, block=16).replay is None
    assert quilting.extend(gravel, left=16, block=16).replay is None


def test_unblended_fill_is_a_selection_that_never_moves_a_known_pixel(hubble) -> None:
    mask = _blob(hubble.shape[:2], 2)
    result = quilting.fill(hubble, mask, block=20, seed=5, blend="none")
    rows, cols = result.source_rows, result.source_cols
    # Every pixel is a copy of the source pixel its provenance names ...
    assert np.array_equal(result.image, hubble[rows, cols])
    # ... a known pixel of itself (no cut took it), a filled one of a pixel outside the hole.
    ys, xs = np.indices(mask.shape)
    assert np.array_equal(rows[~mask], ys[~mask]) and np.array_equal(cols[~mask], xs[~mask])
    assert not mask[rows[mask], cols[mask]].any()
    # The companion of the image itself, filled the same way, is the result.
    assert np.array_equal(result.apply(hubble), result.image)


def test_same_seed_same_bytes_on_every_batch_and_backend(wood) -> None:
    mask = _blob(wood.shape[:2], 3)
    first = quilting.fill(wood, mask, block=16, seed=9, backend="fft")
    assert np.array_equal(quilting.fill(wood, mask, block=16, seed=9).image, first.image)
    again = quilting.fill(wood, mask, block=16, seed=9, backend="reference", max_batch=1)
    assert np.array_equal(again.image, first.image)
    other = quilting.fill(wood, mask, block=16, seed=10)
    assert not np.array_equal(other.image, first.image)


@pytest.mark.gl
def test_gl_fills_the_same_bytes(gl, wood) -> None:
    mask = _blob(wood.shape[:2], 4)
    want = quilting.fill(wood, mask, block=16, seed=2, backend="fft")
    got = quilting.fill(wood, mask, block=16, seed=2, backend="gl")
    assert np.array_equal(got.image, want.image)


def test_coarse_search_chooses_the_same_on_every_backend(hubble) -> None:
    mask = _square_hole(hubble.shape[:2], 60, 80, 70)
    fast = quilting.fill(hubble, mask, block=24, seed=4, search_scale=3)
    slow = quilting.fill(hubble, mask, block=24, seed=4, search_scale=3, backend="reference")
    assert np.array_equal(fast.image, slow.image)
    assert np.array_equal(fast.image[~mask], hubble[~mask])


def test_search_scale_must_leave_a_coarse_block(gravel) -> None:
    with pytest.raises(InvalidParameterError, match="search_scale"):
        quilting.fill(gravel, _square_hole(gravel.shape, 10, 10, 20), block=16, search_scale=8)


@pytest.mark.parametrize(
    "mask",
    [
        lambda shape: _blob(shape, 5).astype(np.uint8) * 255,
        lambda shape: np.repeat((_blob(shape, 5) * 255).astype(np.uint8)[..., None], 3, axis=2),
    ],
    ids=["gray", "rgb"],
)
def test_mask_images_fill_where_white(gravel, mask) -> None:
    given = mask(gravel.shape)
    want = quilting.fill(gravel, _blob(gravel.shape, 5), block=16, seed=1)
    assert np.array_equal(quilting.fill(gravel, given, block=16, seed=1).image, want.image)


def test_alpha_zero_keeps_a_pixel() -> None:
    mask = np.zeros((4, 5, 4), dtype=np.uint8)
    mask[..., :3] = 255
    mask[1, 2, 3] = mask[3, 4, 3] = 255
    assert np.array_equal(np.argwhere(hole_of(mask, (4, 5))), [[1, 2], [3, 4]])


def test_empty_mask_returns_the_image(hubble) -> None:
    result = quilting.fill(hubble, np.zeros(hubble.shape[:2], dtype=bool), block=500)
    assert np.array_equal(result.image, hubble) and result.blocks == 0


def test_mask_of_another_size_is_refused(gravel) -> None:
    with pytest.raises(InvalidImageError, match=r"mask is 200x256; it must be the image's size"):
        quilting.fill(gravel, np.ones((256, 200), dtype=bool))


def test_mask_covering_everything_needs_a_texture(gravel, brick) -> None:
    everything = np.ones(gravel.shape, dtype=bool)
    with pytest.raises(InvalidImageError, match=r"covers the whole image.*give a texture"):
        quilting.fill(gravel, everything)
    result = quilting.fill(
        gravel[:96, :96], everything[:96, :96], texture=brick, block=24, blend="none"
    )
    assert result.from_texture and result.image.shape == (96, 96)
    # Every pixel came from the texture.
    assert np.array_equal(result.image, brick[result.source_rows, result.source_cols])


def test_texture_must_match_the_image(hubble, gravel) -> None:
    with pytest.raises(InvalidImageError, match="channels and dtype"):
        quilting.fill(hubble, _blob(hubble.shape[:2], 1), texture=gravel)


def test_a_hole_leaving_no_block_names_the_block_that_fits(gravel) -> None:
    # Known: a frame 20 pixels wide around a hole; no 32 x 32 block lies wholly outside it.
    mask = np.ones(gravel.shape, dtype=bool)
    mask[:20], mask[-20:], mask[:, :20], mask[:, -20:] = False, False, False, False
    fits = largest_block(~mask, 32)
    assert fits == 20
    with pytest.raises(InvalidParameterError, match="block=20 \\(the largest that fits\\)"):
        quilting.fill(gravel, mask, block=32)
    result = quilting.fill(gravel, mask, block=fits)
    assert np.array_equal(result.image[~mask], gravel[~mask])


def test_block_larger_than_the_image_is_refused(wood) -> None:
    with pytest.raises(InvalidParameterError, match="larger than the image"):
        quilting.fill(wood, _blob(wood.shape[:2], 1), block=140)


def test_misspelt_option_names_the_field(wood) -> None:
    with pytest.raises(TypeError, match="did you mean 'block'"):
        quilting.fill(wood, _blob(wood.shape[:2], 1), blok=16)


def test_progress_rises_to_one_and_can_stop_the_fill(gravel) -> None:
    seen: list[float] = []
    quilting.fill(gravel, _blob(gravel.shape, 6), block=16, progress=lambda f, _: seen.append(f))
    assert seen == sorted(seen) and seen[-1] == 1.0 and len(seen) > 2

    class StopError(Exception):
        pass

    def stop(fraction: float, stage: str) -> None:
        raise StopError

    with pytest.raises(StopError):
        quilting.fill(gravel, _blob(gravel.shape, 6), block=16, progress=stop)


def test_a_fill_over_budget_is_refused_before_any_work(gravel) -> None:
    with pytest.raises(JobTooLargeError, match="fill a smaller hole"):
        quilting.fill(
            gravel,
            _blob(gravel.shape, 1),
            block=16,
            budget=quilting.Budget(memory_bytes=quilting.BASE_BYTES + 1000),
        )


def test_origins_cover_the_side_with_the_overlap() -> None:
    for side, block, overlap in [(100, 32, 8), (33, 32, 8), (32, 32, 8), (257, 16, 4)]:
        starts = origins(side, block, overlap)
        assert starts[0] == 0 and starts[-1] == max(0, side - block)
        assert np.all(np.diff(starts) <= block - overlap) and np.all(np.diff(starts) > 0)


def test_extend_places_the_image_and_fills_around_it(wood) -> None:
    result = quilting.extend(wood, top=10, bottom=20, left=30, right=5, block=16, seed=1)
    assert result.image.shape == (136 + 30, 136 + 35, 3)
    assert np.array_equal(result.image[10:146, 30:166], wood)
    assert result.filled.sum() == result.image.shape[0] * result.image.shape[1] - 136 * 136
    # A companion of the input's size is extended the same way (here the input itself).
    unblended = quilting.extend(wood, top=10, left=7, block=16, blend="none")
    assert np.array_equal(unblended.apply(wood), unblended.image)
    with pytest.raises(InvalidImageError, match="136x136"):
        unblended.apply(wood[:50])


def test_extend_by_nothing_is_the_image(wood) -> None:
    assert np.array_equal(quilting.extend(wood).image, wood)


def test_options_validate_once() -> None:
    with pytest.raises(InvalidParameterError, match="overlap"):
        FillOptions(block=16, overlap=8)
    with pytest.raises(InvalidParameterError, match="top"):
        quilting.ExtendOptions(top=-1)
    assert FillOptions(block=32).resolved_overlap == 8


def _wrap_step(image: np.ndarray, axis: int) -> float:
    """Mean squared step across the wrap along ``axis``, over that of the interior."""
    pixels = image.astype(np.float64)
    wrap = np.diff(
        np.concatenate([np.take(pixels, [-1], axis), np.take(pixels, [0], axis)], axis), axis=axis
    )
    inner = np.diff(pixels, axis=axis)
    return float((wrap**2).mean() / (inner**2).mean())


@pytest.mark.parametrize("blend", ["none", "poisson"])
def test_tileable_by_fill_joins_across_the_wrap(gravel, blend) -> None:
    tiled = quilting.make_tileable(gravel, method="fill", blend=blend, seed=2)
    assert tiled.image.shape == gravel.shape and tiled.image.dtype == gravel.dtype
    # The centre outside the bands is the input's, byte for byte.
    assert np.array_equal(tiled.image[tiled.kept], gravel[tiled.kept])
    assert tiled.kept.mean() > 0.7
    # The wrap steps like any other pair of neighbouring lines; the input's did not.
    for axis in (0, 1):
        assert _wrap_step(gravel, axis) > 1.5
        assert _wrap_step(tiled.image, axis) < 1.3


def test_tileable_by_fill_along_one_axis(wood) -> None:
    tiled = quilting.make_tileable(wood, method="fill", axes="x")
    assert tiled.kept[:, wood.shape[1] // 2].all()  # rows are never re-synthesized
    assert tiled.kept.all(axis=0).sum() > 100


def test_the_estimate_grows_with_the_hole_and_the_image() -> None:
    options = FillOptions()
    small = quilting.estimate_fill(options, (1024, 1024, 3), (100, 100))
    large = quilting.estimate_fill(options, (1024, 1024, 3), (600, 600))
    bigger = quilting.estimate_fill(options, (2048, 2048, 3), (600, 600))
    assert small.seconds < large.seconds < bigger.seconds
    assert small.peak_bytes <= large.peak_bytes < bigger.peak_bytes
    assert large.peak_bytes < large.bound_bytes
