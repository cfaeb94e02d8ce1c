"""Trimaps and scribbles read as users make them (quilting.core.trimap)."""

from __future__ import annotations

import numpy as np
import pytest

from quilting.core.errors import InvalidImageError
from quilting.core.pixels import PixelFormat
from quilting.core.trimap import (
    BACKGROUND,
    FOREGROUND,
    MIN_SIDE,
    UNKNOWN,
    InvalidTrimapError,
    photo_pixels,
    rgba,
    user_trimap,
)


def _trimap(shape: tuple[int, int] = (12, 16)) -> np.ndarray:
    marks = np.full(shape, 128, np.uint8)
    marks[:3] = 255
    marks[-3:] = 0
    return marks


def test_a_trimap_reads_white_black_and_grey() -> None:
    marked = user_trimap((12, 16), _trimap())
    assert marked.shape == (12, 16)
    assert (marked[:3] == FOREGROUND).all()
    assert (marked[-3:] == BACKGROUND).all()
    assert (marked[3:-3] == UNKNOWN).all()


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_every_depth_and_layout_reads_the_same(dtype: type) -> None:
    marks = _trimap()
    scale = {np.uint8: 1, np.uint16: 257, np.float32: 1 / 255}[dtype]
    gray = (marks.astype(np.float64) * scale).astype(dtype)
    rgb = np.repeat(gray[..., None], 3, axis=2)
    expected = user_trimap((12, 16), marks)
    assert np.array_equal(user_trimap((12, 16), gray), expected)
    assert np.array_equal(user_trimap((12, 16), rgb), expected)


def test_nearly_white_and_black_count_coloured_strokes_do_not() -> None:
    marks = np.full((10, 10, 3), 128, np.uint8)
    marks[0] = 240  # a soft brush or a JPEG: still white
    marks[1] = 15  # still black
    marks[2] = (255, 0, 0)  # red is no mark
    marked = user_trimap((10, 10), marks)
    assert (marked[0] == FOREGROUND).all() and (marked[1] == BACKGROUND).all()
    assert (marked[2] == UNKNOWN).all()


def test_scribbles_on_a_transparent_layer() -> None:
    strokes = np.zeros((10, 10, 4), np.uint8)  # transparent black: not strokes
    strokes[2, 1:9] = (255, 255, 255, 255)
    strokes[7, 1:9] = (0, 0, 0, 255)
    marked = user_trimap((10, 10), scribbles=strokes)
    assert (marked[2, 1:9] == FOREGROUND).all()
    assert (marked[7, 1:9] == BACKGROUND).all()
    assert (marked == UNKNOWN).sum() == 100 - 16


def test_scribbles_are_drawn_over_a_trimap() -> None:
    strokes = np.zeros((12, 16, 4), np.uint8)
    strokes[5, 2:6] = (0, 0, 0, 255)
    strokes[0, 0] = (0, 0, 0, 255)  # corrects the trimap's white
    marked = user_trimap((12, 16), _trimap(), strokes)
    assert (marked[5, 2:6] == BACKGROUND).all()
    assert marked[0, 0] == BACKGROUND and marked[0, 1] == FOREGROUND


@pytest.mark.parametrize(
    ("trimap", "scribbles", "words"),
    [
        (None, None, "needs a trimap or scribbles"),
        (np.full((12, 16), 255, np.uint8), None, "marks no background"),
        (np.zeros((12, 16), np.uint8), None, "marks no foreground"),
        (np.full((12, 16), 128, np.uint8), None, "marks no foreground"),
        (_trimap((16, 12)), None, "trimap is 12x16 but the photo is 16x12"),
        (None, _trimap((13, 16)), "scribbles is 16x13 but the photo is 16x12"),
    ],
)
def test_what_cannot_guide_a_matte_is_refused(
    trimap: np.ndarray | None, scribbles: np.ndarray | None, words: str
) -> None:
    with pytest.raises(InvalidTrimapError, match=words) as caught:
        user_trimap((12, 16), trimap, scribbles)
    assert caught.value.code == "invalid_trimap"


def test_both_maps_named_when_together_they_lack_background() -> None:
    with pytest.raises(InvalidTrimapError, match="the trimap and scribbles mark no background"):
        user_trimap((4, 4), np.full((4, 4), 255, np.uint8), np.full((4, 4), 200, np.uint8))


def test_a_photo_is_rgb_float64_and_gray_is_repeated() -> None:
    gray = np.arange(100, dtype=np.uint8).reshape(10, 10)
    pixels, fmt = photo_pixels(gray)
    assert pixels.shape == (10, 10, 3) and pixels.dtype == np.float64
    assert np.array_equal(pixels[..., 0], pixels[..., 2])
    assert np.allclose(pixels[..., 1], gray / 255)
    assert fmt.channels == 1


def test_a_photo_with_alpha_or_too_small_is_refused() -> None:
    with pytest.raises(InvalidImageError, match="already has an alpha channel"):
        photo_pixels(np.zeros((10, 10, 4), np.uint8))
    with pytest.raises(InvalidImageError, match=f"at least {MIN_SIDE}x{MIN_SIDE}"):
        photo_pixels(np.zeros((MIN_SIDE - 1, 20, 3), np.uint8))


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_rgba_is_in_the_photos_dtype(dtype: type) -> None:
    colour = np.full((3, 4, 3), 0.5)
    alpha = np.linspace(0, 1, 12).reshape(3, 4)
    out = rgba(colour, alpha, PixelFormat(np.dtype(dtype), 3, False))
    assert out.shape == (3, 4, 4) and out.dtype == dtype
    top = {np.uint8: 255, np.uint16: 65535, np.float32: 1.0}[dtype]
    assert out[0, 0, 3] == 0 and out[-1, -1, 3] == top
