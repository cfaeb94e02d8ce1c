"""Uploads built to hurt: decompression bombs, truncations, patched sizes, chunk floods, and
large images that are valid but costly (16-bit 5000x5000, a 5000x5000 /tile).

Each is made in well under a second from a few building blocks (a PNG chunk writer, zlib
streams of zeros, a small JPEG from Pillow), so that tests can send them to a real server.
"""

from __future__ import annotations

import functools
import io
import struct
import zlib

import numpy as np
from PIL import Image
from service_helpers import texture

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def png_chunk(kind: bytes, payload: bytes) -> bytes:
    return (
        struct.pack(">I", len(payload))
        + kind
        + payload
        + struct.pack(">I", zlib.crc32(kind + payload))
    )


def _ihdr(width: int, height: int, depth: int, color_type: int) -> bytes:
    return png_chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, depth, color_type, 0, 0, 0))


def _zero_rows(row_bytes: int, rows: int, extra: int = 0) -> bytes:
    """A zlib stream of ``rows`` rows of filter byte 0 and zero samples, then ``extra`` zeros."""
    packer = zlib.compressobj(9)
    row = bytes(1 + row_bytes)
    parts = [packer.compress(row * 64) for _ in range(rows // 64)]
    parts.append(packer.compress(row * (rows % 64)))
    for _ in range(extra // (1 << 22)):
        parts.append(packer.compress(bytes(1 << 22)))
    parts.append(packer.flush())
    return b"".join(parts)


def png_zeros(width: int, height: int, *, depth: int = 8, color_type: int = 2) -> bytes:
    """A valid, black PNG (tiny on disk, ``width x height`` once decoded)."""
    channels = {0: 1, 2: 3, 4: 2, 6: 4}[color_type]
    data = _zero_rows(width * channels * depth // 8, height)
    idat = [png_chunk(b"IDAT", data[i : i + (1 << 20)]) for i in range(0, len(data), 1 << 20)]
    return (
        PNG_SIGNATURE
        + _ihdr(width, height, depth, color_type)
        + b"".join(idat)
        + png_chunk(b"IEND", b"")
    )


@functools.cache
def png16_5000() -> bytes:
    """16-bit RGBA, 5000x5000: about 200 KB, 200 MB of samples, seconds to decode."""
    return png_zeros(5000, 5000, depth=16, color_type=6)


@functools.cache
def png_5000() -> bytes:
    """8-bit RGB, 5000x5000: about 75 KB; ``/tile`` of it needs gigabytes."""
    return png_zeros(5000, 5000)


def png_claiming(width: int, height: int) -> bytes:
    """A well-formed header declaring ``width x height`` (gray) over a few bytes of data."""
    return (
        PNG_SIGNATURE
        + _ihdr(width, height, 8, 0)
        + png_chunk(b"IDAT", zlib.compress(b"\x00" * 64))
        + png_chunk(b"IEND", b"")
    )


@functools.cache
def png_zlib_bomb() -> bytes:
    """5000x5000 gray whose image data inflates to 256 MB more than the header declares."""
    data = _zero_rows(5000, 5000, extra=256 << 20)
    return (
        PNG_SIGNATURE + _ihdr(5000, 5000, 8, 0) + png_chunk(b"IDAT", data) + png_chunk(b"IEND", b"")
    )


@functools.cache
def png_chunk_flood() -> bytes:
    """2.5 million empty chunks after the header (30 MB)."""
    small = png_claiming(64, 64)
    head, tail = small[:33], small[33:]
    return head + png_chunk(b"teXt", b"") * 2_500_000 + tail


def png_palette_without_plte() -> bytes:
    data = zlib.compress(b"\x00" + bytes(16) * 1)
    return PNG_SIGNATURE + _ihdr(16, 1, 8, 3) + png_chunk(b"IDAT", data) + png_chunk(b"IEND", b"")


@functools.cache
def png_with_junk() -> bytes:
    """A real texture followed by 20 MB of junk after IEND."""
    return texture("gravel") + bytes(20 << 20)


@functools.cache
def jpeg() -> bytes:
    buffer = io.BytesIO()
    Image.open(io.BytesIO(texture("hubble"))).save(buffer, format="JPEG", quality=90)
    return buffer.getvalue()


def jpeg_patched(width: int = 4999, height: int = 4999) -> bytes:
    """A 10 KB-ish JPEG whose frame header (SOF0) says ``width x height``."""
    data = bytearray(jpeg())
    at = data.index(b"\xff\xc0")
    data[at + 5 : at + 9] = struct.pack(">HH", height, width)
    return bytes(data)


def jpeg_truncated() -> bytes:
    data = jpeg()
    return data[: len(data) * 2 // 3]


def rgb_noise(size: int, seed: int = 0) -> bytes:
    """An incompressible RGB PNG of ``size x size``."""
    rng = np.random.default_rng(seed)
    image = Image.fromarray(rng.integers(0, 256, (size, size, 3), dtype=np.uint8))
    buffer = io.BytesIO()
    image.save(buffer, format="PNG")
    return buffer.getvalue()
