"""Small uploads made in the tests, for the unit tests of the service's upload checks
(``test_uploads.py``, ``test_fill_uploads.py``, ``test_extract_uploads.py``): seeded pixels of
any shape and depth, their PNG bytes, and a trimap with all three regions."""

from __future__ import annotations

import numpy as np

from quilting.io import encode_png


def pixels(
    height: int, width: int, channels: int, dtype: type[np.generic], seed: int
) -> np.ndarray:
    """Seeded random pixels, (H, W) for one channel else (H, W, C), over ``dtype``'s range."""
    rng = np.random.default_rng(seed)
    shape = (height, width) if channels == 1 else (height, width, channels)
    top = 65536 if dtype is np.uint16 else 256
    return rng.integers(0, top, size=shape).astype(dtype)


def png(height: int, width: int, channels: int = 3, dtype: type[np.generic] = np.uint8) -> bytes:
    """The PNG of :func:`pixels`, seeded by its shape (two calls alike give the same bytes)."""
    return encode_png(pixels(height, width, channels, dtype, height * 100 + width + channels))


def trimap(height: int, width: int) -> np.ndarray:
    """Black left half (background), white right quarter (foreground), grey between."""
    marks = np.full((height, width), 128, dtype=np.uint8)
    marks[:, : width // 2] = 0
    marks[:, 3 * width // 4 :] = 255
    return marks
