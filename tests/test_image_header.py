"""``quilting.io.image_header``: what ``read_image`` would return (size, channels, depth) and
the structural checks that need no decoding, in milliseconds whatever the file."""

from __future__ import annotations

import io
import struct
import time
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from quilting.core.errors import ImageDecodeError, ImageTooLargeError
from quilting.io import encode_png, image_header, read_image

DATA = Path(__file__).resolve().parent / "data"
RGB = np.asarray(Image.open(DATA / "hubble.png").convert("RGB"))[:100]  # 256 x 100


def _saved(image: Image.Image, fmt: str, **params: object) -> bytes:
    buffer = io.BytesIO()
    image.save(buffer, format=fmt, **params)
    return buffer.getvalue()


def _exif(orientation: int) -> bytes:
    exif = Image.Exif()
    exif[0x0112] = orientation
    return exif.tobytes()


CASES = {
    **{path.stem: path.read_bytes() for path in sorted(DATA.glob("*.png"))},
    "rgb16": encode_png(RGB.astype(np.uint16) * 257),
    "gray16": encode_png(RGB[..., 0].astype(np.uint16) * 257),
    "palette+tRNS": _saved(Image.fromarray(RGB).convert("P"), "PNG", transparency=0),
    "gray+tRNS": _saved(Image.fromarray(RGB).convert("L"), "PNG", transparency=3),
    "rgb+tRNS": _saved(Image.fromarray(RGB), "PNG", transparency=(1, 2, 3)),
    "gray+alpha": _saved(Image.fromarray(RGB).convert("LA"), "PNG"),
    "1-bit": _saved(Image.fromarray(RGB).convert("1"), "PNG"),
    "interlaced": _saved(Image.fromarray(RGB), "PNG", interlace=1),
    "jpeg gray": _saved(Image.fromarray(RGB).convert("L"), "JPEG"),
    "jpeg cmyk": _saved(Image.fromarray(RGB).convert("CMYK"), "JPEG"),
    "jpeg progressive": _saved(Image.fromarray(RGB), "JPEG", progressive=True),
    **{
        f"jpeg orientation {o}": _saved(Image.fromarray(RGB), "JPEG", exif=_exif(o))
        for o in range(1, 9)
    },
}


@pytest.mark.parametrize("name", list(CASES))
def test_the_header_says_what_read_image_returns(name: str) -> None:
    data = CASES[name]
    header = image_header(data)
    array = read_image(data)
    channels = 1 if array.ndim == 2 else array.shape[2]
    assert (header.height, header.width, header.channels) == (*array.shape[:2], channels)
    assert header.bit_depth == 8 * array.dtype.itemsize
    assert header.format == ("jpeg" if name.startswith("jpeg") else "png")


def _chunk(kind: bytes, payload: bytes) -> bytes:
    crc = struct.pack(">I", zlib.crc32(kind + payload))
    return struct.pack(">I", len(payload)) + kind + payload + crc


def _claiming(width: int, height: int) -> bytes:
    ihdr = _chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
    idat = _chunk(b"IDAT", zlib.compress(bytes(64)))
    return b"\x89PNG\r\n\x1a\n" + ihdr + idat + _chunk(b"IEND", b"")


def _patched_jpeg(width: int, height: int) -> bytes:
    data = bytearray(CASES["jpeg orientation 1"])  # baseline: frame header SOF0
    at = data.index(b"\xff\xc0")
    data[at + 5 : at + 9] = struct.pack(">HH", height, width)
    return bytes(data)


def test_what_the_header_refuses() -> None:
    with pytest.raises(ImageTooLargeError, match="max_pixels"):
        image_header(_claiming(50_000, 50_000))
    gravel = CASES["gravel"]
    refused = {
        "truncated": gravel[:30_000],
        "junk after IEND": gravel + bytes(1000),
        "chunk flood": _claiming(8, 8)[:33] + _chunk(b"teXt", b"") * 20_000 + _claiming(8, 8)[33:],
        "palette without PLTE": _claiming(8, 8).replace(
            _chunk(b"IHDR", struct.pack(">IIBBBBB", 8, 8, 8, 0, 0, 0, 0)),
            _chunk(b"IHDR", struct.pack(">IIBBBBB", 8, 8, 8, 3, 0, 0, 0)),
        ),
        "JPEG patched to 4999x4999": _patched_jpeg(4999, 4999),
        "not an image": b"GIF89a" + bytes(64),
    }
    for what, data in refused.items():
        with pytest.raises(ImageDecodeError):
            image_header(data)
            pytest.fail(what)


def test_what_needs_the_pixels_is_left_to_read_image() -> None:
    # Declared 5000x5000 over 64 bytes of image data: the header cannot tell; decoding can.
    claiming = _claiming(5000, 5000)
    assert image_header(claiming).width == 5000
    with pytest.raises(ImageDecodeError):
        read_image(claiming)


def test_a_jpeg_of_stuffed_bytes_is_read_in_milliseconds() -> None:
    # 16 MB of entropy-coded 0xFF00 pairs: a walk of the scans takes a search of every byte
    # (about 0.3 s); the header stops at the first scan.
    data = CASES["jpeg progressive"]
    sos = data.index(b"\xff\xda")
    length = int.from_bytes(data[sos + 2 : sos + 4], "big")
    head = data[: sos + 2 + length]
    stuffed = head + b"\xff\x00" * (8 << 20) + b"\xff\xd9"
    started = time.perf_counter()
    header = image_header(stuffed)
    assert time.perf_counter() - started < 0.05
    assert (header.width, header.height) == (256, 100)
