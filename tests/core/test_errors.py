"""Every bad input gets a clear error naming the parameter and what is allowed."""

from __future__ import annotations

import numpy as np
import pytest

import quilting
from quilting import InvalidImageError, InvalidParameterError, synthesize

TEX = np.random.default_rng(0).integers(0, 256, (64, 80, 3), dtype=np.uint8)


@pytest.mark.parametrize(
    "kwargs,parameter,fragment",
    [
        ({"block": 65}, "block", "3..64"),
        ({"block": 2}, "block", "3"),
        ({"block": 48, "overlap": 24}, "overlap", "1..23"),
        ({"block": 12, "overlap": 0}, "overlap", ">= 1"),
        ({"tolerance": -0.1}, "tolerance", "0.0..10.0"),
        ({"tolerance": float("nan")}, "tolerance", "finite"),
        ({"mode": "quilt"}, "mode", "'random', 'overlap', 'cut'"),
        ({"seed": -1}, "seed", "0.."),
        ({"backend": "cuda"}, "backend", "'auto', 'fft', 'gl', 'reference'"),
        ({"block": 12.5}, "block", "integer"),
    ],
)
def test_parameter_errors_name_the_parameter_and_range(kwargs, parameter, fragment) -> None:
    with pytest.raises(InvalidParameterError) as info:
        synthesize(TEX, (100, 100), **kwargs)
    assert info.value.parameter == parameter
    assert parameter in str(info.value) and fragment in str(info.value)
    assert info.value.code == "invalid_parameter"


@pytest.mark.parametrize("size", [(0, 10), (10, 0), (-5, 5), (10,), "big", (10.5, 10), (70000, 10)])
def test_size_errors(size) -> None:
    with pytest.raises(InvalidParameterError, match="size"):
        synthesize(TEX, size)


@pytest.mark.parametrize(
    "texture,fragment",
    [
        (np.zeros((10, 10, 3, 1), np.uint8), "shape"),
        (np.zeros((10,), np.uint8), "shape"),
        (np.zeros((20, 20, 2), np.uint8), "2 channels"),
        (np.zeros((20, 20), bool), "dtype"),
        (np.zeros((20, 20), np.int64), "dtype"),
        (np.zeros((0, 20), np.uint8), "empty"),
        ([[0, 1], [1, 0]], "numpy array"),
    ],
)
def test_image_shape_and_dtype_errors(texture, fragment) -> None:
    with pytest.raises(InvalidImageError, match=fragment):
        synthesize(texture, (10, 10), block=3)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_and_inf_pixels_are_refused(bad) -> None:
    texture = np.random.default_rng(0).random((30, 30)).astype(np.float32)
    texture[4, 7] = bad
    with pytest.raises(InvalidImageError, match="NaN or infinite"):
        synthesize(texture, (50, 50), block=12)


def test_all_errors_share_the_base_class() -> None:
    for exc in (InvalidParameterError("x", 1, "2"), InvalidImageError("x")):
        assert isinstance(exc, quilting.QuiltingError)
