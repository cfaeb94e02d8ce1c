"""Pixels at the engine's edge: validation, the working format and back, luminance."""

from __future__ import annotations

import numpy as np
import pytest

from quilting.core.errors import InvalidImageError
from quilting.core.pixels import (
    MAX_FLOAT_MAGNITUDE,
    as_channels,
    check_float_range,
    compared,
    from_working,
    luminance,
    rendered,
    to_working,
)


@pytest.mark.parametrize(
    ("shape", "channels", "flat"),
    [((5, 7), 1, True), ((5, 7, 1), 1, False), ((5, 7, 3), 3, False), ((5, 7, 4), 4, False)],
)
def test_as_channels_views_every_accepted_shape(
    shape: tuple[int, ...], channels: int, flat: bool
) -> None:
    image = np.arange(np.prod(shape), dtype=np.uint16).reshape(shape)
    view, fmt = as_channels(image)
    assert view.shape == (5, 7, channels) and np.shares_memory(view, image)
    assert (fmt.channels, fmt.two_dimensional, fmt.dtype) == (channels, flat, np.uint16)
    assert fmt.restore(view).shape == shape


@pytest.mark.parametrize(
    ("image", "words"),
    [
        ([[1, 2]], "numpy array"),
        (np.zeros((4,), np.uint8), "expected (H, W)"),
        (np.zeros((4, 4, 2), np.uint8), "2 channels"),
        (np.zeros((4, 4), np.int32), "dtype int32"),
        (np.zeros((0, 4), np.uint8), "empty"),
        (np.array([[0.5, np.nan]], np.float32), "1 NaN or infinite"),
        (np.array([[0.5, -np.inf, np.nan, 1e30]], np.float64), "2 NaN or infinite"),
        (np.array([[0.5, -3e6]], np.float64), "magnitude up to 3e+06"),
        (np.array([[2e7, 0.5]], np.float32), "magnitude up to 2e+07"),
    ],
)
def test_as_channels_refuses_with_the_reason(image: object, words: str) -> None:
    with pytest.raises(InvalidImageError) as caught:
        as_channels(image, "texture")
    assert words in str(caught.value)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_float_range_ends_at_the_largest_magnitude_both_signs(dtype: type) -> None:
    top = dtype(MAX_FLOAT_MAGNITUDE)
    check_float_range(np.array([[top, -top, 0.0]], dtype), "texture")
    for sign in (1, -1):
        over = np.nextafter(top, dtype(np.inf)) * sign
        with pytest.raises(InvalidImageError, match="within ±1e\\+06"):
            check_float_range(np.array([[0.0, over]], dtype), "texture")


def test_float_range_passes_integers_float16_and_empty_arrays() -> None:
    check_float_range(np.full((2, 2), 65535, np.uint16), "texture")
    check_float_range(np.full((2, 2), np.finfo(np.float16).max, np.float16), "texture")
    check_float_range(np.zeros((0, 3), np.float64), "texture")
    with pytest.raises(InvalidImageError, match="target contains 1 NaN"):
        check_float_range(np.array([np.nan], np.float16), "target")


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_integers_round_trip_bit_for_bit(dtype: type) -> None:
    top = np.iinfo(dtype).max
    image = np.random.default_rng(1).integers(0, top, (16, 9, 3), endpoint=True).astype(dtype)
    work = to_working(image)
    assert work.dtype == np.float32 and work.min() >= 0 and work.max() <= 1
    back = from_working(work.copy(), np.dtype(dtype))
    assert back is not None and back.dtype == dtype
    np.testing.assert_array_equal(back, image)


def test_from_working_clips_an_overshoot_and_keeps_float32() -> None:
    canvas = np.array([[[-0.2], [0.5], [1.3]]], dtype=np.float32)
    np.testing.assert_array_equal(
        from_working(canvas.copy(), np.dtype(np.uint8))[..., 0],  # type: ignore[index]
        [[0, 128, 255]],
    )
    same = from_working(canvas.copy(), np.dtype(np.float32))
    np.testing.assert_array_equal(same, canvas)  # floats are kept as computed
    assert from_working(canvas.copy(), np.dtype(np.float64)) is None  # re-rendered instead


def test_rendered_rounds_to_the_nearest_step() -> None:
    image = np.array([[[0.0], [0.4 / 255], [0.6 / 255], [2.0]]], dtype=np.float32)
    np.testing.assert_array_equal(rendered(image, np.dtype(np.uint8))[0, :, 0], [0, 0, 1, 255])
    assert rendered(image, np.dtype(np.float64)).dtype == np.float64


def test_luminance_is_rec601_and_gray_is_its_own() -> None:
    rgb = np.array([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]], dtype=np.float32)
    np.testing.assert_allclose(luminance(rgb)[0], [0.299, 0.587, 0.114], rtol=1e-6)
    rgba = np.concatenate([rgb, np.zeros((1, 3, 1), np.float32)], axis=-1)
    np.testing.assert_array_equal(luminance(rgba), luminance(rgb))  # alpha ignored
    gray = np.full((2, 2, 1), 0.25, np.float32)
    np.testing.assert_array_equal(luminance(gray), gray[..., 0])


def test_compared_by_error_kind_and_premultiplied() -> None:
    rgba = np.array([[[0.2, 0.4, 0.6, 0.5]]], dtype=np.float32)
    np.testing.assert_array_equal(compared(rgba[..., :3], "rgb"), rgba[..., :3])
    assert compared(rgba[..., :3], "luminance").shape == (1, 1, 1)
    np.testing.assert_allclose(compared(rgba, "rgb", premultiply=True), [[[0.1, 0.2, 0.3]]])
    np.testing.assert_allclose(
        compared(rgba, "luminance", premultiply=True)[..., 0],
        luminance(rgba[..., :3]) * 0.5,
    )
