"""The shared test textures (tests/data, licences in its README), read once, read-only.

Read through ``quilting.read_image``: the tests that use these check engine behaviour, not
decoding (tests/test_io.py tests io.py against Pillow directly).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

import quilting
from quilting.costs.fft import FFTBackend
from quilting.costs.reference import ReferenceBackend

DATA = Path(__file__).resolve().parent.parent / "data"


@functools.cache
def texture(name: str) -> NDArray[Any]:
    """``tests/data/<name>.png`` as the engine reads it; shared, so made read-only."""
    image: NDArray[Any] = quilting.read_image(DATA / f"{name}.png")
    image.setflags(write=False)
    return image


def backends(request: pytest.FixtureRequest, with_gl: bool) -> dict[str, Any]:
    """The cost backends the agreement tests compare, by name: fft and reference, and gl
    (from the ``gl`` fixture, which skips or fails without OpenGL) with ``with_gl``."""
    found: dict[str, Any] = {"fft": FFTBackend(), "reference": ReferenceBackend()}
    if with_gl:
        found["gl"] = request.getfixturevalue("gl").GLBackend()
    return found


def assert_same_as_reference(images: dict[str, NDArray[Any]]) -> None:
    """Every backend's image (by name) is the reference backend's, pixel for pixel."""
    reference = images.pop("reference")
    for name, image in images.items():
        assert np.array_equal(image, reference), name
