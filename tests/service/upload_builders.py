"""Small uploads made in the tests, for the unit tests of the service's upload checks
(``test_uploads.py``, ``test_fill_uploads.py``, ``test_extract_uploads.py``): seeded pixels of
any shape and depth, their PNG bytes, a trimap with all three regions, a PNG whose pixels alone
are broken, and a decoder stand-in that fails any check that decodes."""

from __future__ import annotations

from typing import NoReturn

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


def no_decoding(*_args: object, **_kwargs: object) -> NoReturn:
    """Patched over the decoder: a check that should read headers only fails if it decodes."""
    raise AssertionError("a header check decoded pixels")


def corrupt_pixels(data: bytes) -> bytes:
    """``data`` (a PNG) with a byte of its image data flipped: its structure intact, its
    IDAT's CRC wrong (only decoding sees it)."""
    at = data.index(b"IDAT") + 8
    return data[:at] + bytes([data[at] ^ 0xFF]) + data[at + 1 :]
