"""Tests of quilting.io: PNG/JPEG decoding with limits, PNG encoding, metadata.

Pillow is used here only to build fixtures (JPEG, GIF, BMP, palette PNGs...) and as an
independent decoder to check that what we write is a valid PNG. 16-bit PNGs with every row
filter and Adam7 interlacing are built by the small encoder below, written from the PNG
specification independently of the decoder under test.
"""

from __future__ import annotations

import io
import re
import struct
import tracemalloc
import warnings
import zlib
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from PIL import Image, ImageOps

from quilting.core.errors import (
    ImageDecodeError,
    ImageTooLargeError,
    InvalidImageError,
    InvalidParameterError,
    QuiltingError,
)
from quilting.io import (
    DEFAULT_MAX_PIXELS,
    encode_png,
    read_image,
    read_image_metadata,
    write_image,
)

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# Adam7 passes as the PNG specification lists them: (x0, y0, dx, dy).
ADAM7 = [
    (0, 0, 8, 8),
    (4, 0, 8, 8),
    (0, 4, 4, 8),
    (2, 0, 4, 4),
    (0, 2, 2, 4),
    (1, 0, 2, 2),
    (0, 1, 1, 2),
]

Array = npt.NDArray[Any]


# --------------------------------------------------------------------------------------------
# Helpers: a from-the-spec PNG writer with every filter type, and Pillow fixtures
# --------------------------------------------------------------------------------------------


def chunk(ctype: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + ctype + data + struct.pack(">I", zlib.crc32(ctype + data))


def filter_rows(x: npt.NDArray[np.uint8], ftypes: npt.NDArray[np.integer[Any]]) -> bytes:
    """Filter (h, w, bpp) sample bytes with the given per-row filter types (PNG spec 9.2)."""
    h, w, bpp = x.shape
    xi = x.astype(np.int32)
    a = np.zeros_like(xi)
    a[:, 1:] = xi[:, :-1]
    b = np.zeros_like(xi)
    b[1:] = xi[:-1]
    c = np.zeros_like(xi)
    c[1:, 1:] = xi[:-1, :-1]
    p = a + b - c
    pa, pb, pc = np.abs(p - a), np.abs(p - b), np.abs(p - c)
    paeth = np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))
    predictors = np.stack([np.zeros_like(xi), a, b, (a + b) // 2, paeth])
    pred = predictors[np.asarray(ftypes), np.arange(h)]
    filtered = ((xi - pred) % 256).astype(np.uint8).reshape(h, w * bpp)
    return np.concatenate([np.asarray(ftypes, np.uint8)[:, None], filtered], axis=1).tobytes()


def png16_bytes(values: npt.NDArray[np.uint16]) -> npt.NDArray[np.uint8]:
    """(H, W, C) uint16 -> (H, W, 2C) big-endian sample bytes."""
    h, w, ch = values.shape
    return values.astype(">u2").view(np.uint8).reshape(h, w, 2 * ch)


def craft_png(
    samples: npt.NDArray[np.uint8],
    depth: int,
    color_type: int,
    *,
    rng: np.random.Generator,
    filters: tuple[int, ...] = (0, 1, 2, 3, 4),
    interlace: bool = False,
    extra: tuple[tuple[bytes, bytes], ...] = (),
) -> bytes:
    """A PNG of (H, W, bpp) sample bytes, rows filtered with types drawn from ``filters``."""
    h, w, _ = samples.shape
    if interlace:
        parts = []
        for x0, y0, dx, dy in ADAM7:
            sub = samples[y0::dy, x0::dx]
            if sub.shape[0] and sub.shape[1]:
                parts.append(filter_rows(sub, rng.choice(filters, size=sub.shape[0])))
        scanlines = b"".join(parts)
    else:
        scanlines = filter_rows(samples, rng.choice(filters, size=h))
    ihdr = struct.pack(">IIBBBBB", w, h, depth, color_type, 0, 0, int(interlace))
    compressed = zlib.compress(scanlines)
    return (
        PNG_SIGNATURE
        + chunk(b"IHDR", ihdr)
        + b"".join(chunk(t, d) for t, d in extra)
        + chunk(b"IDAT", compressed[: len(compressed) // 2])  # split: IDATs concatenate
        + chunk(b"IDAT", compressed[len(compressed) // 2 :])
        + chunk(b"IEND", b"")
    )


def header_only_png(width: int, height: int, depth: int = 8, color_type: int = 0) -> bytes:
    """A PNG whose IHDR declares width x height but whose IDAT holds a single row."""
    ihdr = struct.pack(">IIBBBBB", width, height, depth, color_type, 0, 0, 0)
    return (
        PNG_SIGNATURE
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(b"\x00" * 64))
        + chunk(b"IEND", b"")
    )


def pil_bytes(im: Image.Image, fmt: str, **params: Any) -> bytes:
    buf = io.BytesIO()
    im.save(buf, fmt, **params)
    return buf.getvalue()


def random_image(rng: np.random.Generator, shape: tuple[int, ...], dtype: Any) -> Array:
    return rng.integers(0, np.iinfo(dtype).max, size=shape, endpoint=True, dtype=dtype)


def jpeg_with_orientation(array: npt.NDArray[np.uint8], orientation: int | None) -> bytes:
    im = Image.fromarray(array)
    if orientation is None:
        return pil_bytes(im, "JPEG", quality=95)
    exif = Image.Exif()
    exif[0x0112] = orientation
    return pil_bytes(im, "JPEG", quality=95, exif=exif.tobytes())


def gradient_rgb(h: int, w: int) -> npt.NDArray[np.uint8]:
    """A smooth, asymmetric picture: JPEG keeps it close, and any flip or turn shows."""
    rows, cols = np.mgrid[0:h, 0:w]
    return np.stack(
        [rows * 255 // max(h - 1, 1), cols * 255 // max(w - 1, 1), (rows + 2 * cols) % 256],
        axis=2,
    ).astype(np.uint8)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20010801)


# --------------------------------------------------------------------------------------------
# Round trips through encode_png / write_image
# --------------------------------------------------------------------------------------------

SHAPES = [(7, 13), (13, 7), (1, 1), (1, 17), (17, 1), (64, 33)]


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("channels", [None, 3, 4])
@pytest.mark.parametrize("hw", SHAPES)
def test_round_trip_is_exact(
    rng: np.random.Generator, dtype: Any, channels: int | None, hw: tuple[int, int]
) -> None:
    shape = hw if channels is None else (*hw, channels)
    image = random_image(rng, shape, dtype)
    decoded = read_image(encode_png(image))
    assert decoded.dtype == dtype
    assert decoded.shape == shape
    np.testing.assert_array_equal(decoded, image)


@settings(max_examples=60, deadline=None)
@given(
    hnp.arrays(
        dtype=st.sampled_from([np.uint8, np.uint16]),
        shape=st.tuples(st.integers(1, 20), st.integers(1, 20), st.sampled_from([0, 3, 4])).map(
            lambda s: s[:2] if s[2] == 0 else s
        ),
    ),
    st.integers(0, 9),
)
def test_round_trip_property(image: Array, level: int) -> None:
    decoded = read_image(encode_png(image, compress_level=level))
    assert decoded.dtype == image.dtype
    np.testing.assert_array_equal(decoded, image)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_single_channel_reads_back_as_two_dimensional(rng: np.random.Generator, dtype: Any) -> None:
    image = random_image(rng, (7, 13, 1), dtype)
    decoded = read_image(encode_png(image))
    assert decoded.shape == (7, 13)
    np.testing.assert_array_equal(decoded, image[..., 0])


def test_big_endian_uint16_input_is_accepted(rng: np.random.Generator) -> None:
    image = random_image(rng, (5, 6, 3), np.uint16)
    decoded = read_image(encode_png(image.astype(">u2")))
    np.testing.assert_array_equal(decoded, image)


def test_non_contiguous_input_round_trips(rng: np.random.Generator) -> None:
    image = random_image(rng, (20, 30, 4), np.uint8)[::2, ::3, :]
    np.testing.assert_array_equal(read_image(encode_png(image)), image)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_float_is_clipped_and_written_as_16_bit(dtype: Any) -> None:
    values = np.array([[-1.0, 0.0, 0.25, 0.5, 0.75, 1.0, 3.0, 1e-5, 1.0 - 1e-6]], dtype=dtype)
    # 0.25 * 65535 = 16383.75 -> 16384; 0.5 -> 32767.5 -> 32768 (ties to even);
    # 0.75 -> 49151.25 -> 49151; 1e-5 -> 0.655 -> 1; 1 - 1e-6 -> 65534.93 -> 65535.
    expected = np.array([[0, 0, 16384, 32768, 49151, 65535, 65535, 1, 65535]], dtype=np.uint16)
    decoded = read_image(encode_png(values))
    assert decoded.dtype == np.uint16
    np.testing.assert_array_equal(decoded, expected)


def test_float_rgba_keeps_alpha_and_channels() -> None:
    image = np.zeros((2, 3, 4), dtype=np.float32)
    image[..., 0] = 1.0
    image[..., 3] = 0.5
    decoded = read_image(encode_png(image))
    assert decoded.shape == (2, 3, 4)
    assert decoded.dtype == np.uint16
    np.testing.assert_array_equal(decoded[..., 0], 65535)
    np.testing.assert_array_equal(decoded[..., 1:3], 0)
    np.testing.assert_array_equal(decoded[..., 3], 32768)


@pytest.mark.parametrize(
    ("image", "needle"),
    [
        (np.zeros((4, 4), dtype=bool), "bool"),
        (np.zeros((4, 4), dtype=np.int32), "int32"),
        (np.zeros((4, 4), dtype=np.float16), "float16"),
        (np.zeros((4, 4), dtype=np.uint32), "uint32"),
        (np.zeros((4, 4), dtype=np.complex64), "complex64"),
        (np.zeros(16, dtype=np.uint8), "(16,)"),
        (np.zeros((2, 4, 4, 3), dtype=np.uint8), "(2, 4, 4, 3)"),
        (np.zeros((4, 4, 2), dtype=np.uint8), "(4, 4, 2)"),
        (np.zeros((4, 4, 5), dtype=np.uint8), "(4, 4, 5)"),
        (np.zeros((0, 4, 3), dtype=np.uint8), "(0, 4, 3)"),
        (np.full((2, 2), np.nan, dtype=np.float32), "NaN"),
        (np.array([[0.0, np.inf]]), "infinite"),
        (np.array([[0.0, -np.inf]], dtype=np.float32), "infinite"),
    ],
)
def test_invalid_images_are_refused_with_a_clear_message(image: Array, needle: str) -> None:
    with pytest.raises(InvalidImageError) as info:
        encode_png(image)
    message = str(info.value)
    assert needle in message
    # ... and says what would have been accepted.
    assert any(s in message for s in ("uint8, uint16", "(H, W, 3)", "finite", "at least 1"))


def test_non_array_image_is_refused() -> None:
    with pytest.raises(InvalidImageError, match="numpy array"):
        encode_png([[0, 1], [2, 3]])  # type: ignore[arg-type]


@pytest.mark.parametrize("level", [-1, 10, 2.5, True])
def test_bad_compress_level_is_refused(level: Any) -> None:
    with pytest.raises(InvalidParameterError, match="compress_level"):
        encode_png(np.zeros((2, 2), np.uint8), compress_level=level)


def test_written_png_structure() -> None:
    data = encode_png(np.zeros((3, 5, 3), np.uint16), metadata={"b": 1, "a": [1, 2]})
    assert data.startswith(PNG_SIGNATURE)
    width, height, depth, color_type, _, _, interlace = struct.unpack(">IIBBBBB", data[16:29])
    assert (width, height, depth, color_type, interlace) == (5, 3, 16, 2, 0)
    assert b'tEXtquilting\x00{"a": [1, 2], "b": 1}' in data  # sorted keys, tEXt chunk
    assert data.endswith(chunk(b"IEND", b""))


@pytest.mark.parametrize(
    ("shape", "dtype"),
    [((9, 11), np.uint8), ((9, 11, 3), np.uint8), ((9, 11, 4), np.uint8), ((9, 11), np.uint16)],
)
def test_pillow_decodes_what_we_write(
    rng: np.random.Generator, shape: tuple[int, ...], dtype: Any
) -> None:
    image = random_image(rng, shape, dtype)
    with Image.open(io.BytesIO(encode_png(image))) as im:
        np.testing.assert_array_equal(np.asarray(im), image)


@pytest.mark.parametrize("channels", [3, 4])
def test_pillow_truncates_16_bit_colour_which_is_why_we_decode_it(
    rng: np.random.Generator, channels: int
) -> None:
    image = random_image(rng, (9, 11, channels), np.uint16)
    data = encode_png(image)
    with Image.open(io.BytesIO(data)) as im:
        pillow = np.asarray(im)
    # Pillow agrees with us on the high byte (so the file is valid) and drops the low byte.
    assert pillow.dtype == np.uint8
    np.testing.assert_array_equal(pillow, (image >> 8).astype(np.uint8))
    np.testing.assert_array_equal(read_image(data), image)


# --------------------------------------------------------------------------------------------
# Metadata
# --------------------------------------------------------------------------------------------


def test_metadata_round_trip(tmp_path: Path, rng: np.random.Generator) -> None:
    metadata = {
        "seed": 42,
        "block": [48, 48],
        "options": {"overlap": 8, "tolerance": 0.1, "tileable": True, "backend": None},
        "note": "caf\u00e9 \u2603",
    }
    image = random_image(rng, (6, 7, 3), np.uint16)
    path = tmp_path / "out.png"
    write_image(path, image, metadata=metadata)
    assert read_image_metadata(path) == metadata
    assert read_image_metadata(str(path)) == metadata
    assert read_image_metadata(path.read_bytes()) == metadata
    np.testing.assert_array_equal(read_image(path), image)


def test_metadata_absent_is_empty(rng: np.random.Generator) -> None:
    assert read_image_metadata(encode_png(random_image(rng, (3, 3), np.uint8))) == {}
    assert read_image_metadata(jpeg_with_orientation(gradient_rgb(8, 8), None)) == {}
    assert read_image_metadata(encode_png(np.zeros((2, 2), np.uint8), metadata={})) == {}


@pytest.mark.parametrize("ctype", [b"zTXt", b"iTXt-compressed", b"iTXt"])
def test_metadata_from_other_text_chunks(rng: np.random.Generator, ctype: bytes) -> None:
    text = b'{"from": "elsewhere", "n": 3}'
    if ctype == b"zTXt":
        extra = (b"zTXt", b"quilting\x00\x00" + zlib.compress(text))
    elif ctype == b"iTXt":
        extra = (b"iTXt", b"quilting\x00\x00\x00en\x00\x00" + text)
    else:
        extra = (b"iTXt", b"quilting\x00\x01\x00\x00\x00" + zlib.compress(text))
    other = (b"tEXt", b"Comment\x00hello")
    data = craft_png(
        np.zeros((2, 2, 1), np.uint8), 8, 0, rng=rng, filters=(0,), extra=(other, extra)
    )
    assert read_image_metadata(data) == {"from": "elsewhere", "n": 3}


@pytest.mark.parametrize("text", [b"not json", b"[1, 2]"])
def test_bad_metadata_text_is_a_decode_error(rng: np.random.Generator, text: bytes) -> None:
    data = craft_png(
        np.zeros((2, 2, 1), np.uint8),
        8,
        0,
        rng=rng,
        filters=(0,),
        extra=((b"tEXt", b"quilting\x00" + text),),
    )
    with pytest.raises(ImageDecodeError, match="quilting"):
        read_image_metadata(data)


@pytest.mark.parametrize(
    "metadata", [{"a": np.zeros(2)}, {"a": float("nan")}, {"a": object()}, [("a", 1)]]
)
def test_unserialisable_metadata_is_refused(metadata: Any) -> None:
    with pytest.raises(InvalidParameterError, match="metadata"):
        encode_png(np.zeros((2, 2), np.uint8), metadata=metadata)


def test_metadata_of_non_image_is_a_decode_error() -> None:
    with pytest.raises(ImageDecodeError, match="only PNG and JPEG"):
        read_image_metadata(b"GIF89a" + b"\x00" * 20)


# --------------------------------------------------------------------------------------------
# Writing errors
# --------------------------------------------------------------------------------------------


def test_write_failure_names_the_path(tmp_path: Path) -> None:
    path = tmp_path / "no" / "such" / "dir" / "out.png"
    with pytest.raises(QuiltingError) as info:
        write_image(path, np.zeros((2, 2), np.uint8))
    assert str(path) in str(info.value)
    assert not isinstance(info.value, ImageDecodeError)


def test_write_image_validates_before_touching_the_file(tmp_path: Path) -> None:
    path = tmp_path / "out.png"
    with pytest.raises(InvalidImageError):
        write_image(path, np.zeros((2, 2), bool))
    assert not path.exists()


# --------------------------------------------------------------------------------------------
# 16-bit PNGs from other writers: every filter, interlacing, tRNS, gray+alpha
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("color_type", "channels"), [(0, 1), (2, 3), (4, 2), (6, 4)])
@pytest.mark.parametrize("filters", [(0, 1, 2, 3, 4), (0, 1, 2), (2,), (1,), (3,), (4,), (0,)])
@pytest.mark.parametrize("interlace", [False, True])
@pytest.mark.parametrize("hw", [(13, 7), (1, 9), (9, 1), (20, 31)])
def test_16_bit_png_with_any_filter_decodes_exactly(
    rng: np.random.Generator,
    color_type: int,
    channels: int,
    filters: tuple[int, ...],
    interlace: bool,
    hw: tuple[int, int],
) -> None:
    values = random_image(rng, (*hw, channels), np.uint16)
    data = craft_png(
        png16_bytes(values), 16, color_type, rng=rng, filters=filters, interlace=interlace
    )
    decoded = read_image(data)
    assert decoded.dtype == np.uint16
    if color_type == 0:
        expected = values[..., 0]
    elif color_type == 4:
        expected = np.concatenate([values[..., :1].repeat(3, axis=2), values[..., 1:]], axis=2)
    else:
        expected = values
    np.testing.assert_array_equal(decoded, expected)


def test_16_bit_smooth_image_with_paeth_rows(rng: np.random.Generator) -> None:
    # Smooth data makes Paeth pick all three neighbours; random data mostly picks one.
    rows, cols = np.mgrid[0:40, 0:50]
    values = np.stack([rows * 1000 + cols * 7, cols * 1300, (rows * cols) % 65536, rows * 5], 2)
    values = values.astype(np.uint16)
    data = craft_png(png16_bytes(values), 16, 6, rng=rng, filters=(3, 4))
    np.testing.assert_array_equal(read_image(data), values)


def test_16_bit_gray_written_by_pillow_matches_pillow(rng: np.random.Generator) -> None:
    image = random_image(rng, (33, 47), np.uint16)
    image[:10] = np.arange(47, dtype=np.uint16) * 1000  # smooth part: Pillow's filters vary
    data = pil_bytes(Image.fromarray(image), "PNG")
    with Image.open(io.BytesIO(data)) as im:
        assert im.mode == "I;16"
        np.testing.assert_array_equal(np.asarray(im), image)
    np.testing.assert_array_equal(read_image(data), image)


def test_16_bit_high_bytes_agree_with_pillow_on_any_filter(rng: np.random.Generator) -> None:
    values = random_image(rng, (25, 19, 3), np.uint16)
    data = craft_png(png16_bytes(values), 16, 2, rng=rng, interlace=True)
    with Image.open(io.BytesIO(data)) as im:
        pillow = np.asarray(im)
    decoded = read_image(data)
    np.testing.assert_array_equal((decoded >> 8).astype(np.uint8), pillow)


def test_16_bit_transparency_key_makes_rgba(rng: np.random.Generator) -> None:
    gray = np.array([[[100], [4000]], [[4000], [65535]]], dtype=np.uint16)
    data = craft_png(png16_bytes(gray), 16, 0, rng=rng, extra=((b"tRNS", struct.pack(">H", 4000)),))
    decoded = read_image(data)
    assert decoded.shape == (2, 2, 4)
    np.testing.assert_array_equal(decoded[..., 0], gray[..., 0])
    np.testing.assert_array_equal(decoded[..., 3], [[65535, 0], [0, 65535]])

    rgb = np.array([[[1, 2, 3], [1, 2, 4]]], dtype=np.uint16)
    data = craft_png(
        png16_bytes(rgb), 16, 2, rng=rng, extra=((b"tRNS", struct.pack(">HHH", 1, 2, 3)),)
    )
    decoded = read_image(data)
    np.testing.assert_array_equal(decoded[..., :3], rgb)
    np.testing.assert_array_equal(decoded[..., 3], [[0, 65535]])


def test_16_bit_with_trailing_data_after_the_image_is_refused(rng: np.random.Generator) -> None:
    # Image data that inflates past the rows the header announces is corrupt (it used to be
    # read, the excess ignored); see "Strict decoding" below for the other cases.
    values = random_image(rng, (4, 5, 1), np.uint16)
    scanlines = filter_rows(png16_bytes(values), np.zeros(4, int))
    ihdr = struct.pack(">IIBBBBB", 5, 4, 16, 0, 0, 0, 0)
    data = (
        PNG_SIGNATURE
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(scanlines + b"\x00" * 100))
        + chunk(b"IEND", b"")
    )
    with pytest.raises(ImageDecodeError, match="inflates to more than the 44 bytes"):
        read_image(data)


# --------------------------------------------------------------------------------------------
# 8-bit and lower PNGs in every colour type
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("interlace", [False, True])
def test_8_bit_crafted_with_all_filters(rng: np.random.Generator, interlace: bool) -> None:
    values = random_image(rng, (15, 22, 3), np.uint8)
    data = craft_png(values, 8, 2, rng=rng, interlace=interlace)
    np.testing.assert_array_equal(read_image(data), values)


def test_gray_alpha_png_becomes_rgba() -> None:
    la = np.array([[[10, 200], [30, 0]], [[255, 255], [0, 7]]], dtype=np.uint8)
    decoded = read_image(pil_bytes(Image.fromarray(la, "LA"), "PNG"))
    assert decoded.shape == (2, 2, 4)
    assert decoded.dtype == np.uint8
    for channel in range(3):
        np.testing.assert_array_equal(decoded[..., channel], la[..., 0])
    np.testing.assert_array_equal(decoded[..., 3], la[..., 1])


def palette_image(transparency: Any = None) -> tuple[bytes, Array]:
    palette = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [9, 8, 7]], dtype=np.uint8)
    indices = np.array([[0, 1, 2, 3], [3, 2, 1, 0], [1, 1, 3, 3]], dtype=np.uint8)
    im = Image.fromarray(indices, "P")
    im.putpalette(palette.ravel().tolist())
    params = {} if transparency is None else {"transparency": transparency}
    return pil_bytes(im, "PNG", **params), palette[indices]


def test_palette_png_becomes_rgb() -> None:
    data, rgb = palette_image()
    decoded = read_image(data)
    assert decoded.shape == (3, 4, 3)
    np.testing.assert_array_equal(decoded, rgb)


def test_palette_png_with_transparency_becomes_rgba() -> None:
    data, rgb = palette_image(transparency=bytes([255, 0, 128, 255]))
    decoded = read_image(data)
    assert decoded.shape == (3, 4, 4)
    np.testing.assert_array_equal(decoded[..., :3], rgb)
    alpha = np.array([255, 0, 128, 255], dtype=np.uint8)
    indices = np.array([[0, 1, 2, 3], [3, 2, 1, 0], [1, 1, 3, 3]])
    np.testing.assert_array_equal(decoded[..., 3], alpha[indices])


def test_one_bit_png_becomes_0_255_gray() -> None:
    bits = np.array([[0, 1, 1, 0, 1, 0, 0, 1, 1]], dtype=bool).repeat(3, axis=0)
    decoded = read_image(pil_bytes(Image.fromarray(bits), "PNG"))
    assert decoded.dtype == np.uint8
    assert decoded.shape == (3, 9)
    np.testing.assert_array_equal(decoded, bits * 255)


def test_two_bit_gray_with_transparency_key(rng: np.random.Generator) -> None:
    levels = np.array([[0, 1, 2, 3, 2]], dtype=np.uint8)  # 2-bit samples
    packed = np.packbits(np.unpackbits(levels[..., None], axis=-1)[..., 6:].reshape(1, -1), 1)
    scanlines = b"\x00" + packed.tobytes()
    ihdr = struct.pack(">IIBBBBB", 5, 1, 2, 0, 0, 0, 0)
    data = (
        PNG_SIGNATURE
        + chunk(b"IHDR", ihdr)
        + chunk(b"tRNS", struct.pack(">H", 2))
        + chunk(b"IDAT", zlib.compress(scanlines))
        + chunk(b"IEND", b"")
    )
    decoded = read_image(data)
    assert decoded.shape == (1, 5, 4)
    np.testing.assert_array_equal(decoded[..., 0], levels * 85)
    np.testing.assert_array_equal(decoded[..., 3], [[255, 255, 0, 255, 0]])


def test_rgb_with_transparency_key_becomes_rgba() -> None:
    rgb = np.array([[[1, 2, 3], [4, 5, 6], [1, 2, 3]]], dtype=np.uint8)
    decoded = read_image(pil_bytes(Image.fromarray(rgb), "PNG", transparency=(1, 2, 3)))
    np.testing.assert_array_equal(decoded[..., :3], rgb)
    np.testing.assert_array_equal(decoded[..., 3], [[0, 255, 0]])


# --------------------------------------------------------------------------------------------
# JPEG
# --------------------------------------------------------------------------------------------


def test_jpeg_decodes_to_uint8_rgb() -> None:
    rgb = gradient_rgb(21, 34)
    decoded = read_image(jpeg_with_orientation(rgb, None))
    assert decoded.dtype == np.uint8
    assert decoded.shape == (21, 34, 3)
    assert np.abs(decoded.astype(int) - rgb).mean() < 4


def test_gray_jpeg_decodes_to_two_dimensions() -> None:
    gray = gradient_rgb(12, 18)[..., 1]
    decoded = read_image(pil_bytes(Image.fromarray(gray), "JPEG", quality=95))
    assert decoded.shape == (12, 18)
    assert decoded.dtype == np.uint8


def test_cmyk_jpeg_decodes_to_rgb() -> None:
    data = pil_bytes(Image.fromarray(gradient_rgb(10, 14)).convert("CMYK"), "JPEG")
    decoded = read_image(data)
    assert decoded.shape == (10, 14, 3)
    assert decoded.dtype == np.uint8


def test_jpeg_exif_orientation_6_is_turned_upright() -> None:
    rgb = gradient_rgb(24, 40)
    decoded = read_image(jpeg_with_orientation(rgb, 6))
    assert decoded.shape == (40, 24, 3)
    # Orientation 6: the stored picture must turn 90 degrees clockwise to be upright.
    upright = np.rot90(rgb, k=-1)
    assert np.abs(decoded.astype(int) - upright).mean() < 4


@pytest.mark.parametrize("orientation", range(1, 9))
def test_jpeg_orientation_matches_pillow_exif_transpose(orientation: int) -> None:
    data = jpeg_with_orientation(gradient_rgb(24, 40), orientation)
    with Image.open(io.BytesIO(data)) as im:
        expected = np.asarray(ImageOps.exif_transpose(im))
    decoded = read_image(data)
    assert decoded.shape == expected.shape
    assert decoded.shape[:2] == ((40, 24) if orientation >= 5 else (24, 40))
    np.testing.assert_array_equal(decoded, expected)


# --------------------------------------------------------------------------------------------
# Limits
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("depth", [8, 16])
def test_huge_declared_png_is_refused_before_decoding(depth: int) -> None:
    data = header_only_png(100_000, 100_000, depth=depth)
    assert len(data) < 200
    tracemalloc.start()
    try:
        with pytest.raises(ImageTooLargeError) as info:
            read_image(data)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 1_000_000
    message = str(info.value)
    assert "100000x100000" in message
    assert f"{DEFAULT_MAX_PIXELS:,}" in message


def test_huge_declared_png_file_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "bomb.png"
    path.write_bytes(header_only_png(100_000, 100_000))
    with pytest.raises(ImageTooLargeError, match=re.escape("bomb.png")):
        read_image(path)


def patched_jpeg(width: int, height: int) -> bytes:
    data = bytearray(pil_bytes(Image.fromarray(gradient_rgb(8, 8)[..., 0]), "JPEG"))
    sof = data.index(b"\xff\xc0")
    data[sof + 5 : sof + 9] = struct.pack(">HH", height, width)
    return bytes(data)


def test_huge_declared_jpeg_is_refused_before_decoding() -> None:
    with pytest.raises(ImageTooLargeError, match="60000x50000"):
        read_image(patched_jpeg(60_000, 50_000))


@pytest.mark.parametrize(
    "make",
    [
        lambda: encode_png(np.zeros((12, 10), np.uint8)),
        lambda: encode_png(np.zeros((12, 10, 3), np.uint16)),
        lambda: jpeg_with_orientation(gradient_rgb(12, 10), 6),
    ],
    ids=["png8", "png16", "jpeg"],
)
def test_max_pixels_boundary(make: Any) -> None:
    data = make()
    assert read_image(data, max_pixels=120).shape[:2] in ((12, 10), (10, 12))
    with pytest.raises(ImageTooLargeError, match="119"):
        read_image(data, max_pixels=119)


@pytest.mark.parametrize("bad", [0, -5, 1.5, "100", True, None])
def test_bad_max_pixels_is_refused(bad: Any) -> None:
    with pytest.raises(InvalidParameterError, match="max_pixels"):
        read_image(encode_png(np.zeros((2, 2), np.uint8)), max_pixels=bad)


@pytest.mark.parametrize(
    ("width", "height", "max_pixels"),
    [(10_000, 9_000, DEFAULT_MAX_PIXELS), (13_400, 13_360, 180_000_000)],
    ids=["above-pillow-warning", "above-pillow-error"],
)
def test_our_limit_applies_not_pillows(width: int, height: int, max_pixels: int) -> None:
    # Pillow's Image.open warns above 89.5 M pixels and refuses above 178.96 M (twice that):
    # neither may leak. The sizes are just past those thresholds to keep memory down.
    row = b"\x00" * (width + 1)
    compressor = zlib.compressobj()
    idat = b"".join(compressor.compress(row * 1000) for _ in range(height // 1000))
    idat += compressor.compress(row * (height % 1000)) + compressor.flush()
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    data = PNG_SIGNATURE + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        decoded = read_image(data, max_pixels=max_pixels)
    assert decoded.shape == (height, width)
    assert not decoded.any()


def test_jpeg_above_pillow_limit_is_decoded_when_our_limit_allows_it() -> None:
    # 179.6 M pixels declared: Image.open would raise DecompressionBombError. A complete file
    # (minimal_jpeg, in "Strict decoding" below: 0.7 MB of one-bit codes) rather than a
    # patched header, which is now refused as too short for its size.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        decoded = read_image(minimal_jpeg(13_400, 13_400), max_pixels=180_000_000)
    assert decoded.shape == (13_400, 13_400)
    assert decoded[::97, ::89].min() == decoded[::97, ::89].max() == 128


# --------------------------------------------------------------------------------------------
# Refused formats and broken files
# --------------------------------------------------------------------------------------------


def other_format(kind: str) -> bytes:
    if kind == "text":
        return b"width,height\n3,4\n"
    if kind == "empty":
        return b""
    im = Image.fromarray(gradient_rgb(6, 6))
    return pil_bytes(im, {"gif": "GIF", "bmp": "BMP", "webp": "WEBP", "tiff": "TIFF"}[kind])


@pytest.mark.parametrize("kind", ["text", "gif", "bmp", "webp", "tiff", "empty"])
def test_other_formats_are_refused(tmp_path: Path, kind: str) -> None:
    data = other_format(kind)
    with pytest.raises(ImageDecodeError, match="only PNG and JPEG"):
        read_image(data)
    # Sniffed from the bytes, never the name: a GIF called .png is still refused.
    path = tmp_path / "picture.png"
    path.write_bytes(data)
    with pytest.raises(ImageDecodeError) as info:
        read_image(path)
    assert str(path) in str(info.value)
    assert "PNG" in str(info.value)
    assert "JPEG" in str(info.value)


@pytest.mark.parametrize(("kind", "name"), [("gif", "GIF"), ("bmp", "BMP"), ("webp", "WebP")])
def test_refusal_says_what_the_file_looks_like(kind: str, name: str) -> None:
    with pytest.raises(ImageDecodeError, match=name):
        read_image(other_format(kind))


def test_png_named_gif_is_read(tmp_path: Path, rng: np.random.Generator) -> None:
    image = random_image(rng, (3, 4, 3), np.uint8)
    path = tmp_path / "picture.gif"
    path.write_bytes(encode_png(image))
    np.testing.assert_array_equal(read_image(path), image)


def test_sources_may_be_str_pathlike_bytes_bytearray(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    image = random_image(rng, (3, 4), np.uint8)
    data = encode_png(image)
    path = tmp_path / "a.png"
    path.write_bytes(data)
    for source in (path, str(path), data, bytearray(data), memoryview(data)):
        np.testing.assert_array_equal(read_image(source), image)  # type: ignore[arg-type]


def test_wrong_source_type_is_refused() -> None:
    with pytest.raises(InvalidParameterError, match="source"):
        read_image(42)  # type: ignore[arg-type]


def test_missing_file_names_the_path(tmp_path: Path) -> None:
    path = tmp_path / "nowhere" / "missing.png"
    with pytest.raises(ImageDecodeError) as info:
        read_image(path)
    assert str(path) in str(info.value)
    with pytest.raises(ImageDecodeError, match=re.escape("missing.png")):
        read_image_metadata(path)


def test_directory_is_a_decode_error(tmp_path: Path) -> None:
    with pytest.raises(ImageDecodeError, match=str(tmp_path)):
        read_image(tmp_path)


def sample_files() -> dict[str, bytes]:
    rng = np.random.default_rng(7)
    return {
        "png8": encode_png(random_image(rng, (20, 30, 3), np.uint8)),
        "png16": encode_png(random_image(rng, (20, 30, 4), np.uint16)),
        "png16-paeth": craft_png(
            png16_bytes(random_image(rng, (20, 30, 3), np.uint16)), 16, 2, rng=rng
        ),
        "png8-pillow": pil_bytes(Image.fromarray(gradient_rgb(20, 30)), "PNG"),
        "jpeg": jpeg_with_orientation(gradient_rgb(20, 30), None),
    }


SAMPLES = sample_files()


@pytest.mark.parametrize("name", sorted(SAMPLES))
@pytest.mark.parametrize("keep", [0.2, 0.5, 0.9])
def test_truncated_files_are_decode_errors(tmp_path: Path, name: str, keep: float) -> None:
    data = SAMPLES[name]
    truncated = data[: int(len(data) * keep)]
    with pytest.raises(ImageDecodeError):
        read_image(truncated)
    path = tmp_path / f"{name}.bin"
    path.write_bytes(truncated)
    with pytest.raises(ImageDecodeError, match=f"{name}.bin"):
        read_image(path)


@pytest.mark.parametrize("name", ["png8", "png16"])
def test_png_cut_before_iend_or_inside_header_is_a_decode_error(name: str) -> None:
    data = SAMPLES[name]
    for cut in (10, 20, 32, len(data) - 12, len(data) - 1):
        with pytest.raises(ImageDecodeError):
            read_image(data[:cut])


@pytest.mark.parametrize("name", ["png8", "png16"])
def test_png_checksum_mismatch_is_a_decode_error(name: str) -> None:
    data = bytearray(SAMPLES[name])
    data[20] ^= 0x01  # inside IHDR: its CRC no longer matches
    with pytest.raises(ImageDecodeError, match="checksum"):
        read_image(bytes(data))


@settings(max_examples=150, deadline=None)
@given(
    st.sampled_from(sorted(SAMPLES)),
    st.lists(st.tuples(st.integers(0, 10**6), st.integers(1, 255)), min_size=1, max_size=4),
    st.one_of(st.none(), st.integers(0, 10**6)),
)
def test_damaged_files_never_leak_foreign_exceptions(
    name: str, flips: list[tuple[int, int]], cut: int | None
) -> None:
    data = bytearray(SAMPLES[name])
    for position, mask in flips:
        data[position % len(data)] ^= mask
    if cut is not None:
        data = data[: cut % len(data)]
    try:
        decoded = read_image(bytes(data), max_pixels=1_000_000)
    except QuiltingError:
        return
    assert decoded.dtype in (np.uint8, np.uint16)
    assert decoded.ndim in (2, 3)


# --------------------------------------------------------------------------------------------
# The test textures (tests/data, and the cat of examples/, licences in tests/data/README.md)
# --------------------------------------------------------------------------------------------

TEXTURE_SHAPES = {
    "brick.png": (256, 256),
    "grass.png": (256, 256),
    "gravel.png": (256, 256),
    "hubble.png": (256, 256, 3),
    "wood.png": (136, 136, 3),
    "cloud_rgba.png": (192, 192, 4),
    "target_camera.png": (256, 256),
}
#: Inside the repository but outside tests/data, as paths relative to its root.
OTHER_SHAPES = {
    "examples/cat.png": (300, 451, 3),
}
TEXTURE_PATHS = [(DATA / name, shape) for name, shape in sorted(TEXTURE_SHAPES.items())] + [
    (ROOT / name, shape) for name, shape in sorted(OTHER_SHAPES.items())
]


@pytest.mark.parametrize(
    ("path", "shape"), TEXTURE_PATHS, ids=[path.name for path, _ in TEXTURE_PATHS]
)
def test_test_textures_decode_to_listed_shapes(path: Path, shape: tuple[int, ...]) -> None:
    decoded = read_image(path)
    assert decoded.dtype == np.uint8
    assert decoded.shape == shape
    with Image.open(path) as im:
        np.testing.assert_array_equal(decoded, np.asarray(im))
    # And they survive our writer unchanged.
    np.testing.assert_array_equal(read_image(encode_png(decoded)), decoded)


# --------------------------------------------------------------------------------------------
# Output formats chosen by the file name
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "signature"),
    [
        ("out.png", PNG_SIGNATURE),
        ("out.PNG", PNG_SIGNATURE),
        ("out.jpg", b"\xff\xd8\xff"),
        ("out.jpeg", b"\xff\xd8\xff"),
        ("out.JPG", b"\xff\xd8\xff"),
        ("out.webp", b"RIFF"),
    ],
)
@pytest.mark.parametrize("channels", [1, 3])
def test_write_image_writes_the_format_its_name_asks_for(
    tmp_path: Path, name: str, signature: bytes, channels: int
) -> None:
    rng = np.random.default_rng(5)
    # A smooth image, so that a lossy format at quality 95 stays close to it.
    ramp = np.linspace(0, 255, 48)[None, :, None] * np.ones((40, 1, channels))
    image = np.clip(ramp + rng.normal(0, 2, ramp.shape), 0, 255).astype(np.uint8)
    image = image[..., 0] if channels == 1 else image
    path = tmp_path / name
    write_image(path, image)
    data = path.read_bytes()
    assert data.startswith(signature)
    with Image.open(path) as im:
        assert im.format == {"png": "PNG", "jpg": "JPEG", "jpeg": "JPEG", "webp": "WEBP"}[
            name.rsplit(".", 1)[1].lower()
        ]
        back = np.asarray(im.convert("L" if channels == 1 else "RGB"))
    assert back.shape == image.shape
    if signature == PNG_SIGNATURE:
        np.testing.assert_array_equal(back, image)
    else:
        assert np.abs(back.astype(int) - image.astype(int)).mean() < 3


@pytest.mark.parametrize(
    ("name", "image", "fragment"),
    [
        ("out.gif", np.zeros((4, 4), np.uint8), "'.gif' names no format"),
        ("out", np.zeros((4, 4), np.uint8), "no extension"),
        ("out.png.bak", np.zeros((4, 4), np.uint8), "'.bak' names no format"),
        ("out.jpg", np.zeros((4, 4), np.uint16), "16-bit image"),
        ("out.webp", np.zeros((4, 4, 3), np.uint16), "16-bit image"),
        ("out.jpg", np.zeros((4, 4, 3), np.float32), "float32 image"),
        ("out.jpg", np.zeros((4, 4, 4), np.uint8), "alpha channel"),
        ("out.webp", np.zeros((4, 4, 4), np.uint8), "alpha channel"),
    ],
)
def test_write_image_refuses_what_the_name_cannot_hold_before_writing(
    tmp_path: Path, name: str, image: Array, fragment: str
) -> None:
    path = tmp_path / name
    with pytest.raises(InvalidParameterError) as info:
        write_image(path, image)
    message = str(info.value)
    assert fragment in message and str(path) in message
    assert ".png" in message  # what would work
    assert not path.exists()


def test_16_bit_and_alpha_images_still_go_to_png(tmp_path: Path) -> None:
    rng = np.random.default_rng(6)
    for image in (random_image(rng, (5, 6, 4), np.uint8), random_image(rng, (5, 6), np.uint16)):
        path = tmp_path / "out.png"
        write_image(path, image)
        np.testing.assert_array_equal(read_image(path), image)


# --------------------------------------------------------------------------------------------
# Strict decoding: no small file decodes to far more than it holds
# --------------------------------------------------------------------------------------------


def jpeg_segment(marker: int, body: bytes) -> bytes:
    return bytes([0xFF, marker]) + struct.pack(">H", len(body) + 2) + body


def minimal_jpeg(
    width: int, height: int, *, progressive: bool = False, data_bytes: int | None = None
) -> bytes:
    """A complete gray JPEG coded with one-bit Huffman codes, as small as a JPEG can be.

    Both tables hold a single symbol with the code ``0``: DC difference 0 and, sequential,
    end-of-block. Every block costs exactly 2 bits (sequential) or 1 bit (a progressive file
    with only its DC scan), so the entropy-coded data is all zero bytes and sits exactly on
    the lower bound the decoder checks. The image is flat grey (128). ``data_bytes`` overrides
    the amount of coded data.
    """
    blocks = -(-width // 8) * -(-height // 8)
    needed = -(-blocks * (1 if progressive else 2) // 8)
    one_code = bytes([1] + [0] * 15) + b"\x00"  # BITS: one code of length 1; HUFFVAL: 0
    sof = 0xC2 if progressive else 0xC0
    return (
        b"\xff\xd8"
        + jpeg_segment(0xDB, b"\x00" + b"\x01" * 64)
        + jpeg_segment(sof, struct.pack(">BHHB", 8, height, width, 1) + b"\x01\x11\x00")
        + jpeg_segment(0xC4, b"\x00" + one_code + (b"" if progressive else b"\x10" + one_code))
        + jpeg_segment(
            0xDA, b"\x01\x01\x00" + (b"\x00\x00\x00" if progressive else b"\x00\x3f\x00")
        )
        + b"\x00" * (needed if data_bytes is None else data_bytes)
        + b"\xff\xd9"
    )


@pytest.mark.parametrize("progressive", [False, True], ids=["sequential", "progressive"])
def test_jpeg_exactly_at_the_size_bound_is_read_and_one_byte_less_is_refused(
    progressive: bool,
) -> None:
    # 64x64: 64 blocks, 16 bytes sequential and 8 progressive, all of them needed.
    full = minimal_jpeg(64, 64, progressive=progressive)
    decoded = read_image(full)
    assert decoded.shape == (64, 64)
    assert (decoded == 128).all()
    short = minimal_jpeg(64, 64, progressive=progressive, data_bytes=15 if not progressive else 7)
    with pytest.raises(ImageDecodeError, match=r"64x64 pixels \(64 blocks of 8x8\)"):
        read_image(short)


def test_jpeg_patched_to_a_larger_size_is_refused(tmp_path: Path, rng: np.random.Generator) -> None:
    # A 10 KB photo-like JPEG whose frame header claims 4999x4999: libjpeg would fill the
    # missing 25 M pixels with grey.
    image = np.clip(gradient_rgb(100, 100) + rng.integers(-30, 30, (100, 100, 3)), 0, 255)
    data = bytearray(pil_bytes(Image.fromarray(image.astype(np.uint8)), "JPEG", quality=90))
    assert 5_000 < len(data) < 20_000
    sof = data.index(b"\xff\xc0")
    data[sof + 5 : sof + 9] = struct.pack(">HH", 4999, 4999)
    path = tmp_path / "patched.jpg"
    path.write_bytes(data)
    with pytest.raises(ImageDecodeError) as info:
        read_image(path)
    message = str(info.value)
    assert "patched.jpg" in message
    assert "4999x4999" in message
    assert "truncated or corrupt JPEG" in message
    assert f"holds only {len(data) - 2 - sof:,}" not in message  # counts scan bytes only


def _flat(shape: tuple[int, ...], value: int = 90) -> Image.Image:
    return Image.fromarray(np.full(shape, value, np.uint8))


REAL_JPEGS: dict[str, Any] = {
    "baseline": lambda: pil_bytes(Image.fromarray(gradient_rgb(40, 60)), "JPEG"),
    "progressive": lambda: pil_bytes(
        Image.fromarray(gradient_rgb(40, 60)), "JPEG", progressive=True
    ),
    "optimize": lambda: pil_bytes(Image.fromarray(gradient_rgb(40, 60)), "JPEG", optimize=True),
    "444": lambda: pil_bytes(Image.fromarray(gradient_rgb(40, 60)), "JPEG", subsampling=0),
    "420": lambda: pil_bytes(Image.fromarray(gradient_rgb(41, 63)), "JPEG", subsampling=2),
    "gray": lambda: pil_bytes(Image.fromarray(gradient_rgb(40, 60)[..., 0]), "JPEG"),
    "cmyk": lambda: pil_bytes(Image.fromarray(gradient_rgb(40, 60)).convert("CMYK"), "JPEG"),
    "exif": lambda: jpeg_with_orientation(gradient_rgb(40, 60), 3),
    "1x1": lambda: pil_bytes(_flat((1, 1, 3)), "JPEG"),
    "8x8": lambda: pil_bytes(_flat((8, 8)), "JPEG"),
    "1x1-progressive": lambda: pil_bytes(_flat((1, 1)), "JPEG", progressive=True),
    # Flat images are the ones closest to the size bound: every block is one DC code and EOB.
    "flat-2000": lambda: pil_bytes(_flat((2000, 2000, 3)), "JPEG"),
    "flat-2000-gray-optimize": lambda: pil_bytes(_flat((2000, 2000)), "JPEG", optimize=True),
    "flat-2000-optimize-444": lambda: pil_bytes(
        _flat((2000, 2000, 3)), "JPEG", optimize=True, subsampling=0
    ),
    "flat-2000-progressive": lambda: pil_bytes(_flat((2000, 2000, 3)), "JPEG", progressive=True),
    "flat-2000-gray-progressive-optimize": lambda: pil_bytes(
        _flat((2000, 2000)), "JPEG", progressive=True, optimize=True
    ),
    "flat-2000-quality-1": lambda: pil_bytes(_flat((2000, 2000)), "JPEG", quality=1),
}


@pytest.mark.parametrize("name", sorted(REAL_JPEGS))
def test_real_jpegs_still_decode_as_pillow_does(name: str) -> None:
    data = REAL_JPEGS[name]()
    with Image.open(io.BytesIO(data)) as im:
        expected = np.asarray(ImageOps.exif_transpose(im).convert("L" if im.mode == "L" else "RGB"))
    np.testing.assert_array_equal(read_image(data), expected)


@pytest.mark.parametrize(
    ("path", "shape"), TEXTURE_PATHS, ids=[path.name for path, _ in TEXTURE_PATHS]
)
@pytest.mark.parametrize("progressive", [False, True], ids=["baseline", "progressive"])
def test_repository_images_saved_as_jpeg_decode(
    path: Path, shape: tuple[int, ...], progressive: bool
) -> None:
    with Image.open(path) as im:
        rgb = im.convert("L" if im.mode == "L" else "RGB")
    data = pil_bytes(rgb, "JPEG", quality=85, progressive=progressive)
    decoded = read_image(data)
    assert decoded.shape == shape[:2] + ((3,) if rgb.mode == "RGB" else ())
    with Image.open(io.BytesIO(data)) as im:
        np.testing.assert_array_equal(decoded, np.asarray(im))


def jpeg_parts(data: bytes) -> list[tuple[int, bytes]]:
    """(marker, whole segment bytes) up to SOS; the rest (scans and EOI) as marker 0."""
    parts, pos = [], 2
    while data[pos + 1] != 0xDA:
        length = int.from_bytes(data[pos + 2 : pos + 4], "big")
        parts.append((data[pos + 1], data[pos : pos + 2 + length]))
        pos += 2 + length
    parts.append((0, data[pos:]))
    return parts


def jpeg_without(data: bytes, marker: int) -> bytes:
    return b"\xff\xd8" + b"".join(seg for m, seg in jpeg_parts(data) if m != marker)


BASE_JPEG = pil_bytes(Image.fromarray(gradient_rgb(24, 32)), "JPEG")


@pytest.mark.parametrize(
    ("make", "needle"),
    [
        (lambda d: d[:-2], "ends inside its image data, before the end-of-image (EOI)"),
        (lambda d: d[:-20], "truncated JPEG: the file ends inside its image data"),
        (lambda d: jpeg_without(d, 0xC0), "image data (SOS) before the frame header (SOF)"),
        (
            lambda d: b"\xff\xd8" + b"".join(s for m, s in jpeg_parts(d) if m) + b"\xff\xd9",
            "no image data (no SOS scan before EOI)",
        ),
        (
            lambda d: d[:2] + jpeg_segment(0xFE, b"x") * 1001 + d[2:],
            "more than 1,000 marker segments",
        ),
        (lambda d: d.replace(b"\xff\xc0", b"\xff\xc9", 1), "arithmetic-coded JPEGs (SOF9)"),
        (lambda d: d.replace(b"\xff\xc0", b"\xff\xc3", 1), "lossless JPEGs (SOF3)"),
        (
            lambda d: d.replace(
                b"\xff\xc0",
                jpeg_parts(d)[[m for m, _ in jpeg_parts(d)].index(0xC0)][1] + b"\xff\xc0",
                1,
            ),
            "more than one frame header",
        ),
    ],
    ids=[
        "no-eoi",
        "cut-in-scan",
        "no-sof",
        "no-sos",
        "segments",
        "arithmetic",
        "lossless",
        "two-sof",
    ],
)
def test_broken_jpeg_structure_is_refused(make: Any, needle: str) -> None:
    with pytest.raises(ImageDecodeError, match=re.escape(needle)) as info:
        read_image(make(BASE_JPEG))
    assert str(info.value).startswith("<bytes>: ")


def test_jpeg_with_too_many_scans_is_refused() -> None:
    # A progressive file whose last AC scan is repeated: each copy costs a few bytes and makes
    # libjpeg visit every block once more.
    data = pil_bytes(_flat((64, 64)), "JPEG", progressive=True)
    last_sos = data.rindex(b"\xff\xda")
    scan = data[last_sos:-2]
    many = data[:last_sos] + scan * 101 + b"\xff\xd9"
    with pytest.raises(ImageDecodeError, match="more than 100 scans"):
        read_image(many)
    np.testing.assert_array_equal(
        read_image(data[:last_sos] + scan * 3 + b"\xff\xd9"), read_image(data)
    )


def test_data_after_jpeg_eoi_is_accepted_and_ignored() -> None:
    # Gain maps (Ultra HDR, Apple), MPF previews and motion-photo videos live after EOI.
    appended = BASE_JPEG + pil_bytes(Image.fromarray(gradient_rgb(8, 8)), "JPEG") + b"\x00" * 1000
    np.testing.assert_array_equal(read_image(appended), read_image(BASE_JPEG))


def png_of(
    ihdr: tuple[int, int, int, int],
    idat: bytes | list[bytes],
    *,
    before: bytes = b"",
    after: bytes = b"",
) -> bytes:
    width, height, depth, color_type = ihdr
    head = struct.pack(">IIBBBBB", width, height, depth, color_type, 0, 0, 0)
    pieces = [idat] if isinstance(idat, bytes) else idat
    return (
        PNG_SIGNATURE
        + chunk(b"IHDR", head)
        + before
        + b"".join(chunk(b"IDAT", piece) for piece in pieces)
        + chunk(b"IEND", b"")
        + after
    )


@pytest.mark.parametrize("depth", [8, 16])
@pytest.mark.parametrize(
    ("stream", "needle"),
    [
        # 3 rows announced, 2 in the stream (Pillow leaves the third black).
        (lambda row: zlib.compress(row * 2), "holds 2/3 of the bytes"),
        (lambda row: zlib.compress(row * 3 + b"\x00"), "inflates to more than"),
        (lambda row: zlib.compress(row * 3)[:-4], "before the end of the zlib stream"),
        (lambda row: zlib.compress(row * 3) + b"junk", "after the end of the compressed"),
    ],
    ids=["short", "long", "no-checksum", "after-stream"],
)
def test_png_image_data_must_inflate_to_exactly_the_declared_rows(
    depth: int, stream: Any, needle: str
) -> None:
    row = b"\x00" + bytes(range(5 * depth // 8))
    data = png_of((5, 3, depth, 0), stream(row))
    if needle == "holds 2/3 of the bytes":
        needle = f"holds {2 * len(row):,} of the {3 * len(row):,} bytes"
    with pytest.raises(ImageDecodeError, match=re.escape(needle)):
        read_image(data)
    read_image(png_of((5, 3, depth, 0), zlib.compress(row * 3)))  # the exact one is fine


@pytest.mark.parametrize("depth", [8, 16])
def test_png_zlib_bomb_is_never_inflated_past_the_declared_size(depth: int) -> None:
    # 64x64 announced (4 or 8 KB of rows); the stream inflates to 256 MB of zeros.
    compressor = zlib.compressobj(9)
    piece = b"\x00" * (1 << 20)
    bomb = b"".join(compressor.compress(piece) for _ in range(256)) + compressor.flush()
    assert len(bomb) < 300_000
    data = png_of((64, 64, depth, 0), bomb)
    tracemalloc.start()
    try:
        with pytest.raises(ImageDecodeError, match="inflates to more than"):
            read_image(data)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 8 * len(bomb) + 1_000_000


def test_png_with_too_many_chunks_is_refused() -> None:
    # 20,000 private ancillary chunks (240 KB): the walk stops at the limit, before any
    # image data is touched.
    junk = chunk(b"prVt", b"") * 20_000
    data = png_of((4, 1, 8, 0), zlib.compress(b"\x00" * 5), before=junk)
    with pytest.raises(ImageDecodeError, match=r"more than 10,0\d\d chunks"):
        read_image(data)
    with pytest.raises(ImageDecodeError, match="chunks"):
        read_image_metadata(data)


def test_large_png_of_many_small_idat_chunks_is_read(rng: np.random.Generator) -> None:
    # 11,000 IDAT chunks of about 400 bytes in a 4.4 MB file: within the allowance of one
    # chunk per 4 KiB beyond the first 10,000 (libpng writes 8 KiB chunks).
    image = random_image(rng, (2100, 2100), np.uint8)
    stream = zlib.compress(filter_rows(image[..., None], np.zeros(2100, int)), 1)
    step = -(-len(stream) // 11_000)
    pieces = [stream[i : i + step] for i in range(0, len(stream), step)]
    assert len(pieces) > 10_900
    np.testing.assert_array_equal(read_image(png_of((2100, 2100, 8, 0), pieces)), image)


def test_palette_png_without_plte_is_refused() -> None:
    data = png_of((4, 1, 8, 3), zlib.compress(b"\x00\x00\x01\x02\x03"))
    with pytest.raises(ImageDecodeError, match=r"palette image \(colour type 3\) without a PLTE"):
        read_image(data)
    plte = chunk(b"PLTE", bytes(range(12)))
    assert read_image(
        png_of((4, 1, 8, 3), zlib.compress(b"\x00\x00\x01\x02\x03"), before=plte)
    ).shape == (1, 4, 3)


@pytest.mark.parametrize("depth", [8, 16])
@pytest.mark.parametrize("extra", [1, 20 << 20])
def test_bytes_after_png_iend_are_refused(depth: int, extra: int) -> None:
    data = encode_png(np.zeros((3, 4), np.uint8 if depth == 8 else np.uint16))
    with pytest.raises(ImageDecodeError, match=f"{extra:,} bytes of data after the IEND"):
        read_image(data + b"\x00" * extra)


@pytest.mark.parametrize(
    ("pieces", "needle"),
    [
        ([], "no image data (no IDAT)"),
        (None, "IDAT chunks are not consecutive"),
    ],
    ids=["no-idat", "split-idat"],
)
def test_png_idat_run_must_exist_and_be_consecutive(pieces: Any, needle: str) -> None:
    stream = zlib.compress(b"\x00" * 5)
    if pieces is None:
        data = (
            PNG_SIGNATURE
            + chunk(b"IHDR", struct.pack(">IIBBBBB", 4, 1, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", stream[:5])
            + chunk(b"tEXt", b"a\x00b")
            + chunk(b"IDAT", stream[5:])
            + chunk(b"IEND", b"")
        )
    else:
        data = png_of((4, 1, 8, 0), pieces)
    with pytest.raises(ImageDecodeError, match=re.escape(needle)):
        read_image(data)
