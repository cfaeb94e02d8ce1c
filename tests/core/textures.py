"""The shared test textures (tests/data, licences in its README), read once, read-only.

Read through ``quilting.read_image``: the tests that use these check engine behaviour, not
decoding (tests/test_io.py tests io.py against Pillow directly).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

from numpy.typing import NDArray

import quilting

DATA = Path(__file__).resolve().parent.parent / "data"


@functools.cache
def texture(name: str) -> NDArray[Any]:
    """``tests/data/<name>.png`` as the engine reads it; shared, so made read-only."""
    image: NDArray[Any] = quilting.read_image(DATA / f"{name}.png")
    image.setflags(write=False)
    return image
