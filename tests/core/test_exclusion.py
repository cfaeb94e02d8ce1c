"""Exclusion (minimum-resistance-cut paper, §3.1): no output pixel ever comes from an excluded
part of the texture."""

from __future__ import annotations

import numpy as np
import pytest
from textures import assert_same_as_reference, backends

import quilting
from quilting import InvalidImageError, InvalidParameterError
from quilting.core.exclusion import allowed_candidates, excluded_pixels

STARS = [((120, 120, 120), (255, 255, 255))]


def _blobs(shape: tuple[int, int], seed: int, count: int = 12) -> np.ndarray:
    """A mask image: white (usable) with black discs (never use)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0 : shape[0], 0 : shape[1]]
    mask = np.full(shape, 255, dtype=np.uint8)
    centres_y = rng.integers(0, shape[0], count)
    centres_x = rng.integers(0, shape[1], count)
    for cy, cx, r in zip(centres_y, centres_x, rng.integers(3, 12, count), strict=True):
        mask[(y - cy) ** 2 + (x - cx) ** 2 <= r * r] = 0
    return mask


def _used_excluded(result: quilting.Result, excluded: np.ndarray) -> int:
    """Output pixels that came from excluded texture pixels, traced through the layout."""
    traced = quilting.apply_layout(result.layout, excluded.astype(np.uint8))
    return int(traced.sum())


@pytest.mark.parametrize("mode", ["cut", "overlap", "random"])
def test_excluded_colours_never_reach_the_output(hubble, mode) -> None:
    result = quilting.synthesize(
        hubble, (200, 260), block=32, seed=1, mode=mode, exclude_colors=STARS
    )
    ranges = quilting.SynthesisOptions(exclude_colors=STARS).exclude_colors
    excluded = excluded_pixels(hubble, ranges, None)
    assert excluded is not None and excluded.any()
    assert _used_excluded(result, excluded) == 0
    # Without the exclusion the stars are used: the check can fail.
    plain = quilting.synthesize(hubble, (200, 260), block=32, seed=1, mode=mode)
    assert _used_excluded(plain, excluded) > 0


def test_masked_pixels_never_reach_the_output(gravel) -> None:
    mask = _blobs(gravel.shape, seed=3)
    result = quilting.synthesize(gravel, (300, 300), block=24, seed=2, source_mask=mask)
    assert _used_excluded(result, mask == 0) == 0
    plain = quilting.synthesize(gravel, (300, 300), block=24, seed=2)
    assert _used_excluded(plain, mask == 0) > 0


def test_mask_and_colours_combine(hubble) -> None:
    mask = np.stack([_blobs(hubble.shape[:2], seed=4)] * 3, axis=-1)  # an RGB mask image
    result = quilting.synthesize(
        hubble, (160, 160), block=24, seed=5, source_mask=mask, exclude_colors=STARS
    )
    options = quilting.SynthesisOptions(exclude_colors=STARS)
    excluded = excluded_pixels(hubble, options.exclude_colors, mask)
    assert excluded is not None
    assert excluded.sum() > (mask[..., 0] == 0).sum()
    assert _used_excluded(result, excluded) == 0


def test_heavy_exclusion_still_follows_the_rule(gravel) -> None:
    """With most of the texture excluded, the lists must be asked much deeper."""
    mask = np.zeros(gravel.shape, dtype=np.uint8)
    mask[150:230, 20:120] = 255  # one usable window
    result = quilting.synthesize(gravel, (120, 120), block=20, seed=1, source_mask=mask)
    assert _used_excluded(result, mask == 0) == 0


def test_transfer_respects_exclusions(gravel, camera) -> None:
    mask = _blobs(gravel.shape, seed=6)
    result = quilting.transfer(
        gravel, camera[::2, ::2], block=18, iterations=3, seed=1, source_mask=mask
    )
    assert _used_excluded(result, mask == 0) == 0


@pytest.mark.parametrize("heavy", [False, True])
@pytest.mark.parametrize("with_gl", [False, pytest.param(True, marks=pytest.mark.gl)])
def test_backends_agree(request, hubble, with_gl, heavy) -> None:
    """Light exclusions, and heavy ones, where the lists must be asked to the field's depth."""
    texture = hubble[:60, :60]
    mask = _blobs(texture.shape[:2], seed=8, count=4)
    if heavy:
        mask = np.zeros(texture.shape[:2], dtype=np.uint8)
        mask[35:55, 5:30] = 255  # 11 x 16 usable 10 x 10 blocks of 2601
    images = {
        name: quilting.synthesize(
            texture, (50, 50), block=10, seed=3, backend=backend, source_mask=mask, discard=0.3
        ).image
        for name, backend in backends(request, with_gl).items()
    }
    assert_same_as_reference(images)


def test_no_exclusion_changes_nothing(gravel) -> None:
    a = quilting.synthesize(gravel, (100, 100), block=20, seed=9)
    b = quilting.synthesize(gravel, (100, 100), block=20, seed=9, exclude_colors=[])
    c = quilting.synthesize(
        gravel, (100, 100), block=20, seed=9, source_mask=np.ones(gravel.shape, np.uint8)
    )
    assert a.image.tobytes() == b.image.tobytes() == c.image.tobytes()


def test_allowed_candidates_match_brute_force() -> None:
    rng = np.random.default_rng(0)
    excluded = rng.random((23, 31)) < 0.01
    block = 5
    got = allowed_candidates(excluded, block).reshape(19, 27)
    want = np.array(
        [[not excluded[y : y + block, x : x + block].any() for x in range(27)] for y in range(19)]
    )
    assert np.array_equal(got, want)


def test_nothing_usable_is_a_clear_error(gravel) -> None:
    everything = [((0,), (255,))]
    with pytest.raises(InvalidParameterError, match="every 24x24 block"):
        quilting.synthesize(gravel, (60, 60), block=24, exclude_colors=everything)
    checker = np.zeros(gravel.shape, np.uint8)
    checker[::20, :] = 255  # no 24-row window free of black rows
    checker[:, ::20] = 0
    with pytest.raises(InvalidParameterError, match="exclude_colors/source_mask"):
        quilting.synthesize(gravel, (60, 60), block=24, source_mask=checker)


@pytest.mark.parametrize(
    "ranges",
    [
        "red",
        [((0, 0, 0),)],
        [((10, 0, 0), (5, 255, 255))],
        [((0, 0), (1, 1, 1))],
        [((0, 0, 0, 0, 0), (1, 1, 1, 1, 1))],
        [(("a", 0, 0), (1, 1, 1))],
        [((float("nan"), 0, 0), (1, 1, 1))],
    ],
)
def test_bad_colour_ranges_are_named(hubble, ranges) -> None:
    with pytest.raises(InvalidParameterError) as caught:
        quilting.synthesize(hubble, (50, 50), block=16, exclude_colors=ranges)
    assert caught.value.parameter == "exclude_colors"


def test_colours_must_fit_the_texture(gravel) -> None:
    with pytest.raises(InvalidParameterError, match="1-channel"):
        quilting.synthesize(gravel, (50, 50), exclude_colors=STARS)


def test_mask_of_another_size_is_refused(gravel) -> None:
    with pytest.raises(InvalidImageError, match="source_mask is 10x20"):
        quilting.synthesize(gravel, (50, 50), source_mask=np.ones((20, 10), np.uint8))
