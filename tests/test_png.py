"""``quilting.png``: the project's own PNG writer and 16-bit reader, against independent oracles.

tests/test_io.py checks the public API (``encode_png``, ``read_image``) end to end; this file
checks png.py's functions themselves. The oracles are written here from the PNG specification:
a chunk parser and CRC check over the raw bytes, a byte-by-byte row unfilter (every filter
type, Paeth included), Adam7 as the specification's 8 x 8 pass pattern, and Pillow as a second
decoder and as an encoder of files png.py did not write. Hand-built byte strings give the
damaged files: wrong CRCs and lengths, truncations, absurd sizes, zlib bombs.
"""

from __future__ import annotations

import io
import json
import re
import struct
import tracemalloc
import zlib
from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from PIL import Image, PngImagePlugin

from quilting import png
from quilting.core.errors import ImageDecodeError, InvalidImageError, InvalidParameterError
from quilting.io import read_image

Array = npt.NDArray[Any]
LABEL = "sample.png"
SIGNATURE = b"\x89PNG\r\n\x1a\n"
# Samples per pixel and allowed bit depths of each colour type (PNG specification, table 11.1).
CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
SPEC_DEPTHS = {0: {1, 2, 4, 8, 16}, 2: {8, 16}, 3: {1, 2, 4, 8}, 4: {8, 16}, 6: {8, 16}}
# The Adam7 pass of each pixel, as the specification draws it (section 8.2).
ADAM7_PATTERN = [
    [1, 6, 4, 6, 2, 6, 4, 6],
    [7, 7, 7, 7, 7, 7, 7, 7],
    [5, 6, 5, 6, 5, 6, 5, 6],
    [7, 7, 7, 7, 7, 7, 7, 7],
    [3, 6, 4, 6, 3, 6, 4, 6],
    [7, 7, 7, 7, 7, 7, 7, 7],
    [5, 6, 5, 6, 5, 6, 5, 6],
    [7, 7, 7, 7, 7, 7, 7, 7],
]


# --------------------------------------------------------------------------------------------
# Oracles: a from-the-specification chunk writer, parser, unfilter and decoder
# --------------------------------------------------------------------------------------------


def chunk(ctype: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + ctype + data + struct.pack(">I", zlib.crc32(ctype + data))


def ihdr(width: int, height: int, depth: int, color_type: int, interlace: int = 0) -> bytes:
    return chunk(
        b"IHDR", struct.pack(">IIBBBBB", width, height, depth, color_type, 0, 0, interlace)
    )


def build(
    head: bytes, stream: bytes | list[bytes], before: bytes = b"", after: bytes = b""
) -> bytes:
    """A PNG of the IHDR chunk ``head``, ``before``, the IDAT pieces, ``after`` and IEND."""
    pieces = [stream] if isinstance(stream, bytes) else stream
    idat = b"".join(chunk(b"IDAT", piece) for piece in pieces)
    return SIGNATURE + head + before + idat + after + chunk(b"IEND", b"")


def parse_chunks(data: bytes) -> list[tuple[bytes, bytes]]:
    """Every chunk of a well-formed PNG, each CRC checked; the oracle's view of the file."""
    assert data[:8] == SIGNATURE
    pos, found = 8, []
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        ctype, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + length]
        (crc,) = struct.unpack(">I", data[pos + 8 + length : pos + 12 + length])
        assert crc == zlib.crc32(ctype + body), ctype
        found.append((ctype, body))
        pos += 12 + length
    assert pos == len(data) and found[-1] == (b"IEND", b"")
    return found


def paeth(a: int, b: int, c: int) -> int:
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    if pa <= pb and pa <= pc:
        return a
    return b if pb <= pc else c


def naive_unfilter(scan: bytes, rows: int, row_bytes: int, bpp: int) -> list[bytes]:
    """Undo the row filters byte by byte, as the specification states them (section 9)."""
    out: list[bytes] = []
    prior = bytearray(row_bytes)
    pos = 0
    for _ in range(rows):
        ftype = scan[pos]
        line = bytearray(scan[pos + 1 : pos + 1 + row_bytes])
        pos += 1 + row_bytes
        for i in range(row_bytes):
            a = line[i - bpp] if i >= bpp else 0
            b = prior[i]
            c = prior[i - bpp] if i >= bpp else 0
            predictor = [0, a, b, (a + b) // 2, paeth(a, b, c)][ftype]
            line[i] = (line[i] + predictor) & 0xFF
        out.append(bytes(line))
        prior = line
    return out


def pass_rows(height: int, width: int, interlaced: bool) -> list[list[list[tuple[int, int]]]]:
    """The (sub-)images of an image: for each, its rows of (y, x) pixels in file order."""
    if not interlaced:
        return [[[(y, x) for x in range(width)] for y in range(height)]]
    passes = []
    for number in range(1, 8):
        rows = [
            [(y, x) for x in range(width) if ADAM7_PATTERN[y % 8][x % 8] == number]
            for y in range(height)
        ]
        passes.append([row for row in rows if row])
    return passes


def naive_decode(data: bytes) -> Array:
    """Samples (H, W, channels) of an 8- or 16-bit, non-palette PNG, by the oracles above."""
    chunks = parse_chunks(data)
    assert chunks[0][0] == b"IHDR"
    width, height, depth, color_type, _, _, interlace = struct.unpack(">IIBBBBB", chunks[0][1])
    channels, size = CHANNELS[color_type], depth // 8
    bpp = channels * size
    stream = zlib.decompress(b"".join(body for ctype, body in chunks if ctype == b"IDAT"))
    out = np.zeros((height, width, channels), dtype=np.uint16 if depth == 16 else np.uint8)
    pos = 0
    for rows in pass_rows(height, width, bool(interlace)):
        if not rows:
            continue
        row_bytes = len(rows[0]) * bpp
        for coords, line in zip(
            rows, naive_unfilter(stream[pos:], len(rows), row_bytes, bpp), strict=True
        ):
            for k, (y, x) in enumerate(coords):
                for ch in range(channels):
                    offset = k * bpp + ch * size
                    out[y, x, ch] = int.from_bytes(line[offset : offset + size], "big")
        pos += len(rows) * (1 + row_bytes)
    assert pos == len(stream)
    return out


def filter_types(data: bytes) -> set[int]:
    """The filter type bytes of a non-interlaced PNG's rows."""
    chunks = parse_chunks(data)
    width, height, depth, color_type, *_ = struct.unpack(">IIBBBBB", chunks[0][1])
    stream = zlib.decompress(b"".join(body for ctype, body in chunks if ctype == b"IDAT"))
    row = 1 + width * CHANNELS[color_type] * depth // 8
    return {stream[y * row] for y in range(height)}


# --------------------------------------------------------------------------------------------
# What is tested, called as quilting.io calls it
# --------------------------------------------------------------------------------------------


def encode(image: Array, text: bytes | None = None, level: int = 6) -> bytes:
    samples, color_type, depth = png.png_samples(image)
    return png.assemble_png(samples, color_type, depth, text=text, compress_level=level)


def decode16(data: bytes) -> Array:
    fp = io.BytesIO(data)
    header = png.read_png_header(fp, LABEL)
    return png.decode_png16(fp, header, LABEL)


def pillow(data: bytes) -> Array:
    with Image.open(io.BytesIO(data)) as im:
        return np.asarray(im)


def pillow_png(image: Image.Image, **params: Any) -> bytes:
    buffer = io.BytesIO()
    image.save(buffer, "PNG", **params)
    return buffer.getvalue()


def random_image(rng: np.random.Generator, shape: tuple[int, ...], dtype: Any) -> Array:
    return rng.integers(0, np.iinfo(dtype).max, size=shape, endpoint=True, dtype=dtype)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20010801)


class CountingReader(io.BytesIO):
    """A stream that counts the bytes read from it (seeks are free)."""

    def __init__(self, data: bytes) -> None:
        super().__init__(data)
        self.bytes_read = 0

    def read(self, size: int | None = -1, /) -> bytes:
        data = super().read(size)
        self.bytes_read += len(data)
        return data


# --------------------------------------------------------------------------------------------
# The writer: round trips through independent decoders
# --------------------------------------------------------------------------------------------

SHAPES = [(1, 1), (1, 9), (9, 1), (13, 11)]


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("channels", [None, 1, 3, 4], ids=["HxW", "gray", "rgb", "rgba"])
@pytest.mark.parametrize("hw", SHAPES, ids=[f"{h}x{w}" for h, w in SHAPES])
def test_written_files_decode_to_the_image_by_pillow_and_by_the_specification(
    rng: np.random.Generator, dtype: Any, channels: int | None, hw: tuple[int, int]
) -> None:
    shape = hw if channels is None else (*hw, channels)
    image = random_image(rng, shape, dtype)
    data = encode(image)
    samples = image.reshape(*hw, -1)
    np.testing.assert_array_equal(naive_decode(data), samples)
    seen = pillow(data)
    if samples.shape[2] == 1:
        # Pillow reads 8- and 16-bit gray exactly (modes L and I;16).
        np.testing.assert_array_equal(seen, samples[..., 0])
    elif dtype == np.uint8:
        np.testing.assert_array_equal(seen, samples)
    else:
        # Pillow keeps 16-bit colour's high bytes only: the reason png.py decodes it.
        expected = samples if seen.dtype == np.uint16 else (samples >> 8).astype(np.uint8)
        np.testing.assert_array_equal(seen, expected)
    if dtype == np.uint16:
        got = decode16(data)
        assert got.dtype == np.uint16
        np.testing.assert_array_equal(got, samples[..., 0] if samples.shape[2] == 1 else samples)


@settings(max_examples=25, deadline=None)
@given(
    hnp.arrays(
        dtype=st.sampled_from([np.uint8, np.uint16]),
        shape=st.tuples(st.integers(1, 9), st.integers(1, 9), st.sampled_from([0, 1, 3, 4])).map(
            lambda s: s[:2] if s[2] == 0 else s
        ),
    ),
    st.integers(0, 9),
    st.one_of(st.none(), st.dictionaries(st.text(max_size=5), st.integers() | st.text(max_size=5))),
)
def test_round_trip_property(image: Array, level: int, metadata: dict[str, Any] | None) -> None:
    text = png.metadata_text(metadata)
    data = encode(image, text, level)
    assert data == encode(image, text, level)  # deterministic
    np.testing.assert_array_equal(naive_decode(data), image.reshape(*image.shape[:2], -1))
    assert png.png_metadata(io.BytesIO(data), LABEL) == (metadata or {})
    if image.dtype == np.uint16:
        got = decode16(data)
        np.testing.assert_array_equal(got.reshape(image.shape), image)


def test_the_bytes_depend_on_the_values_only(rng: np.random.Generator) -> None:
    """The same pixels give the same file whatever their memory layout or byte order."""
    image = random_image(rng, (17, 23, 3), np.uint16)
    data = encode(image)
    assert encode(image.copy()) == data
    assert encode(np.asfortranarray(image)) == data
    assert encode(image.astype(">u2")) == data
    wide = random_image(rng, (17, 46, 3), np.uint16)
    wide[:, ::2] = image
    assert encode(wide[:, ::2]) == data
    # Another level is other bytes for the same pixels.
    other = encode(image, level=0)
    assert other != data
    np.testing.assert_array_equal(naive_decode(other), image)


def test_the_file_structure(rng: np.random.Generator) -> None:
    image = random_image(rng, (5, 7, 4), np.uint8)
    text = png.metadata_text({"b": 1, "a": "x"})
    assert text is not None
    chunks = parse_chunks(encode(image, text))  # every CRC checked there
    types = [ctype for ctype, _ in chunks]
    assert types == [b"IHDR", b"tEXt", b"IDAT", b"IEND"]
    assert struct.unpack(">IIBBBBB", chunks[0][1]) == (7, 5, 8, 6, 0, 0, 0)
    assert chunks[1][1] == b"quilting\x00" + text
    assert [ctype for ctype, _ in parse_chunks(encode(image))] == [b"IHDR", b"IDAT", b"IEND"]


def test_a_large_image_spans_bands_and_idat_chunks(rng: np.random.Generator) -> None:
    """Over 1 MiB of rows: filtered in bands (each band's first row filtered Up against the
    last row of the band before) and written as IDAT chunks of at most 1 MiB."""
    noise = random_image(rng, (700, 520, 3), np.uint8)  # 1.09 MB of rows, incompressible
    data = encode(noise, level=0)
    idat = [body for ctype, body in parse_chunks(data) if ctype == b"IDAT"]
    assert len(idat) >= 2 and all(len(body) <= 1 << 20 for body in idat)
    np.testing.assert_array_equal(pillow(data), noise)
    # Every row the same: Up (filter 2) wins on every row but the first, band edges included;
    # a band filtered against zeros instead of the row above would decode wrong.
    stripes = np.tile(random_image(rng, (1, 260, 3), np.uint16), (700, 1, 1))
    data = encode(stripes, level=1)
    chunks = parse_chunks(data)
    stream = zlib.decompress(b"".join(body for ctype, body in chunks if ctype == b"IDAT"))
    row = 1 + 260 * 6
    assert [stream[y * row] for y in range(700)] == [1 if stream[0] == 1 else 0] + [2] * 699
    np.testing.assert_array_equal(decode16(data), stripes)
    np.testing.assert_array_equal(pillow(data), (stripes >> 8).astype(np.uint8))


def test_rows_use_only_the_filters_the_writer_promises(rng: np.random.Generator) -> None:
    """None, Sub or Up (the writer leaves Average and Paeth out), on a smooth image where
    Sub and Up both win somewhere."""
    y, x = np.mgrid[0:40, 0:50]
    smooth = np.stack([y * 5, x * 4, (x + y) * 2], axis=-1).astype(np.uint8)
    smooth[::7] = random_image(rng, (6, 50, 3), np.uint8)
    used = filter_types(encode(smooth))
    assert used <= {0, 1, 2} and {1, 2} <= used


# --------------------------------------------------------------------------------------------
# filter_rows: libpng's heuristic, by hand
# --------------------------------------------------------------------------------------------


def naive_choice(raw: Array, bpp: int, above: Array | None) -> list[int]:
    """Per row: the filter of None, Sub, Up whose bytes, taken as signed, sum smallest in
    absolute value (the first on a tie)."""
    choices = []
    for y in range(raw.shape[0]):
        row = [int(v) for v in raw[y]]
        if y:
            prior = [int(v) for v in raw[y - 1]]
        elif above is not None:
            prior = [int(v) for v in above]
        else:
            prior = [0] * len(row)
        sub = [(row[i] - (row[i - bpp] if i >= bpp else 0)) % 256 for i in range(len(row))]
        up = [(row[i] - prior[i]) % 256 for i in range(len(row))]
        scores = [
            sum(abs(v - 256 if v > 127 else v) for v in candidate) for candidate in (row, sub, up)
        ]
        choices.append(scores.index(min(scores)))
    return choices


@settings(max_examples=30, deadline=None)
@given(
    st.integers(1, 8).flatmap(
        lambda bpp: st.tuples(
            st.just(bpp),
            hnp.arrays(
                np.uint8, st.tuples(st.integers(1, 6), st.integers(1, 5).map(lambda w: w * bpp))
            ),
            st.booleans(),
        )
    )
)
def test_filter_rows_is_the_heuristic_and_undoes(case: tuple[int, Array, bool]) -> None:
    bpp, raw, smooth = case
    if smooth:  # runs and ramps, where Sub and Up win
        raw = np.cumsum(raw // 64, axis=1, dtype=np.uint8)
    rows = png.filter_rows(raw, bpp)
    assert rows.shape == (raw.shape[0], 1 + raw.shape[1]) and rows.dtype == np.uint8
    assert rows[:, 0].tolist() == naive_choice(raw, bpp, None)
    undone = naive_unfilter(rows.tobytes(), raw.shape[0], raw.shape[1], bpp)
    assert b"".join(undone) == raw.tobytes()
    # A band of rows below the first, filtered against the row above it, is the same rows.
    if raw.shape[0] > 1:
        band = png.filter_rows(raw[1:], bpp, above=raw[0])
        np.testing.assert_array_equal(band, rows[1:])
        assert band[:, 0].tolist() == naive_choice(raw[1:], bpp, raw[0])


# --------------------------------------------------------------------------------------------
# The 16-bit decoder on files png.py did not write
# --------------------------------------------------------------------------------------------


def random_filtered_png(
    rng: np.random.Generator,
    height: int,
    width: int,
    color_type: int,
    *,
    interlaced: bool,
    extra: bytes = b"",
) -> bytes:
    """A 16-bit PNG of random filtered bytes, every row a random one of the five filters:
    any bytes are a valid filtered image, so the decoder meets every sum and wrap-around."""
    bpp = 2 * CHANNELS[color_type]
    scan = bytearray()
    for rows in pass_rows(height, width, interlaced):
        for coords in rows:
            scan.append(int(rng.integers(0, 5)))
            scan += rng.integers(0, 256, size=len(coords) * bpp, dtype=np.uint8).tobytes()
    head = ihdr(width, height, 16, color_type, int(interlaced))
    stream = zlib.compress(bytes(scan))
    return build(head, [stream[: len(stream) // 3], stream[len(stream) // 3 :]], before=extra)


@pytest.mark.parametrize("color_type", [0, 2, 4, 6])
@pytest.mark.parametrize("interlaced", [False, True], ids=["plain", "adam7"])
@pytest.mark.parametrize("hw", [(1, 1), (3, 5), (9, 10)], ids=["1x1", "3x5", "9x10"])
def test_decode_png16_is_the_specification(
    color_type: int, interlaced: bool, hw: tuple[int, int]
) -> None:
    rng = np.random.default_rng([color_type, int(interlaced), *hw])
    data = random_filtered_png(rng, *hw, color_type, interlaced=interlaced)
    samples = naive_decode(data)
    got = decode16(data)
    assert got.dtype == np.uint16
    if color_type == 0:
        expected = samples[..., 0]
    elif color_type == 4:  # gray and alpha: gray copied into R, G and B
        expected = samples[..., [0, 0, 0, 1]]
    else:
        expected = samples
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("color_type", [0, 2])
def test_a_16_bit_colour_key_makes_exactly_its_pixels_transparent(color_type: int) -> None:
    rng = np.random.default_rng(color_type)
    channels = CHANNELS[color_type]
    values = rng.integers(0, 4, size=(6, 7, channels)).astype(np.uint16) * 21845  # few colours
    key = values[2, 3].copy()
    raw = values.astype(">u2").tobytes()
    scan = b"".join(
        b"\x00" + raw[y * 7 * 2 * channels : (y + 1) * 7 * 2 * channels] for y in range(6)
    )
    trns = chunk(b"tRNS", key.astype(">u2").tobytes())
    data = build(ihdr(7, 6, 16, color_type), zlib.compress(scan), before=trns)
    got = decode16(data)
    assert got.shape == (6, 7, 4)
    for y in range(6):
        for x in range(7):
            colour = [int(v) for v in values[y, x]] * (3 if channels == 1 else 1)
            alpha = 0 if (values[y, x] == key).all() else 65535
            assert got[y, x].tolist() == [*colour, alpha]
    # A tRNS too short for the colour type names no key.
    short = chunk(b"tRNS", key.astype(">u2").tobytes()[:-1])
    plain = decode16(build(ihdr(7, 6, 16, color_type), zlib.compress(scan), before=short))
    np.testing.assert_array_equal(plain, values[..., 0] if channels == 1 else values)


def test_pillow_written_16_bit_gray_decodes_exactly() -> None:
    """Pillow chooses its own filters (Average and Paeth among them on a smooth image) and
    writes a tRNS key when asked: png.py decodes both as Pillow does."""
    y, x = np.mgrid[0:40, 0:50]
    smooth = ((y * 1000 + x * 777 + (x * y) % 97) % 65536).astype(np.uint16)
    data = pillow_png(Image.fromarray(smooth))
    assert filter_types(data) & {3, 4}, "Pillow no longer uses Average or Paeth here"
    np.testing.assert_array_equal(decode16(data), smooth)
    np.testing.assert_array_equal(decode16(data), pillow(data))
    key = int(smooth[3, 4])
    keyed = decode16(pillow_png(Image.fromarray(smooth), transparency=key))
    np.testing.assert_array_equal(keyed[..., :3], np.repeat(smooth[..., None], 3, axis=2))
    np.testing.assert_array_equal(keyed[..., 3] == 0, smooth == key)


def test_an_unknown_row_filter_is_refused() -> None:
    scan = b"\x00" + b"\x01\x02" * 3 + b"\x05" + b"\x01\x02" * 3
    with pytest.raises(ImageDecodeError, match="unknown row filter type 5"):
        decode16(build(ihdr(3, 2, 16, 0), zlib.compress(scan)))


@pytest.mark.parametrize(
    ("mode", "params"),
    [("L", {}), ("RGB", {}), ("RGBA", {}), ("LA", {}), ("P", {"transparency": 1}), ("1", {})],
)
def test_pillow_written_files_pass_the_structure_checks(mode: str, params: dict[str, Any]) -> None:
    """The header, the chunk walk and the inflated size of files Pillow wrote agree with the
    oracle's parse and with zlib."""
    rng = np.random.default_rng(3)
    image = Image.fromarray(random_image(rng, (11, 13, 3), np.uint8)).convert(mode)
    data = pillow_png(image, **params)
    chunks = parse_chunks(data)
    fields = struct.unpack(">IIBBBBB", chunks[0][1])
    fp = io.BytesIO(data)
    header = png.read_png_header(fp, LABEL)
    assert (header.width, header.height, header.bit_depth, header.color_type) == fields[:4]
    assert header.interlaced is bool(fields[6])
    assert (header.width, header.height) == (13, 11)
    structure = png.read_png_structure(fp, header, LABEL, keep_idat=True)
    assert structure.idat == [body for ctype, body in chunks if ctype == b"IDAT"]
    assert structure.trns == next((body for ctype, body in chunks if ctype == b"tRNS"), None)
    inflated = png.inflate_image_data(structure.idat, header, LABEL)
    assert bytes(inflated) == zlib.decompress(b"".join(structure.idat))


# --------------------------------------------------------------------------------------------
# Sizes: what the header announces
# --------------------------------------------------------------------------------------------


def test_png_data_size_counts_every_sub_image_row() -> None:
    """Filter byte plus samples, bits rounded up to bytes per row, for every (sub-)image row
    of the specification's Adam7 pattern; every colour type and depth, sizes 1..9."""
    for color_type, depths in SPEC_DEPTHS.items():
        for depth in sorted(depths):
            bits = depth * CHANNELS[color_type]
            for height in range(1, 10):
                for width in range(1, 10):
                    for interlaced in (False, True):
                        header = png.PngHeader(width, height, depth, color_type, interlaced)
                        expected = sum(
                            len(rows) * (1 + (len(rows[0]) * bits + 7) // 8)
                            for rows in pass_rows(height, width, interlaced)
                            if rows
                        )
                        assert png.png_data_size(header) == expected, header


# --------------------------------------------------------------------------------------------
# The header
# --------------------------------------------------------------------------------------------


def header_of(head: bytes, signature: bytes = SIGNATURE) -> png.PngHeader:
    return png.read_png_header(io.BytesIO(signature + head), LABEL)


def test_exactly_the_specifications_depths_are_accepted() -> None:
    for color_type in range(8):
        for depth in range(18):
            data = ihdr(3, 2, depth, color_type)
            if depth in SPEC_DEPTHS.get(color_type, set()):
                assert header_of(data) == png.PngHeader(3, 2, depth, color_type, False)
            else:
                with pytest.raises(ImageDecodeError, match="not a valid combination"):
                    header_of(data)


@pytest.mark.parametrize(
    ("fields", "needle"),
    [
        ((0, 5, 8, 0, 0, 0, 0), "invalid size 0x5"),
        ((5, 0, 8, 0, 0, 0, 0), "invalid size 5x0"),
        ((1 << 31, 5, 8, 0, 0, 0, 0), f"invalid size {1 << 31}x5"),
        ((5, 0xFFFFFFFF, 8, 0, 0, 0, 0), "invalid size"),
        ((5, 5, 8, 0, 1, 0, 0), "unknown compression, filter or interlace method (1, 0, 0)"),
        ((5, 5, 8, 0, 0, 1, 0), "(0, 1, 0)"),
        ((5, 5, 8, 0, 0, 0, 2), "(0, 0, 2)"),
    ],
)
def test_an_impossible_header_is_refused(fields: tuple[int, ...], needle: str) -> None:
    with pytest.raises(ImageDecodeError, match=re.escape(needle)) as info:
        header_of(chunk(b"IHDR", struct.pack(">IIBBBBB", *fields)))
    assert LABEL in str(info.value)


def test_the_largest_side_the_specification_allows_is_accepted() -> None:
    top = (1 << 31) - 1
    assert header_of(ihdr(top, top, 16, 6)) == png.PngHeader(top, top, 16, 6, False)


def test_a_broken_header_chunk_is_refused() -> None:
    good = ihdr(4, 3, 8, 2)
    for cut in range(len(good)):
        with pytest.raises(ImageDecodeError, match="ends inside its header"):
            header_of(good[:cut])
    flipped = bytearray(good)
    flipped[12] ^= 0x10  # inside the width: the CRC no longer matches
    with pytest.raises(ImageDecodeError, match="checksum mismatch in the IHDR"):
        header_of(bytes(flipped))
    with pytest.raises(ImageDecodeError, match="not a 13-byte IHDR"):
        header_of(chunk(b"IHDx", good[8:21]))
    with pytest.raises(ImageDecodeError, match="not a 13-byte IHDR"):
        header_of(chunk(b"IHDR", good[8:21] + b"\x00") + b"\x00" * 4)


def test_the_signature_is_the_callers_to_check() -> None:
    """read_png_header skips the eight signature bytes unread, as documented (quilting.io
    recognises the file by them first), and quilting.io refuses a file without them."""
    head = ihdr(4, 3, 8, 2)
    assert header_of(head, signature=b"GIF89a\x00\x00") == png.PngHeader(4, 3, 8, 2, False)
    data = encode(np.zeros((3, 4, 3), np.uint8))
    assert header_of(data[8:]) == png.PngHeader(4, 3, 8, 2, False)
    for broken in (b"\x89PNG\r\n\x1a\x00", b"\x88PNG\r\n\x1a\n", b"\x00" * 8):
        with pytest.raises(ImageDecodeError):
            read_image(broken + data[8:])


# --------------------------------------------------------------------------------------------
# The chunk walk: CRCs, lengths, truncations, limits
# --------------------------------------------------------------------------------------------


def small_file(depth: int = 8) -> bytes:
    rng = np.random.default_rng(depth)
    image = random_image(rng, (4, 5, 3), np.uint8 if depth == 8 else np.uint16)
    text = png.metadata_text({"k": 1})
    return encode(image, text)


def walk(data: bytes, skip: frozenset[bytes] = frozenset()) -> list[tuple[bytes, bytes]]:
    fp = io.BytesIO(data)
    png.read_png_header(fp, LABEL)
    return list(png.iter_png_chunks(fp, LABEL, skip))


def offsets(data: bytes) -> list[tuple[bytes, int, int]]:
    """(type, offset of the chunk's length field, data length) of every chunk."""
    pos, found = 8, []
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        found.append((data[pos + 4 : pos + 8], pos, length))
        pos += 12 + length
    return found


def test_the_walk_yields_every_chunk() -> None:
    data = small_file()
    assert walk(data) == parse_chunks(data)
    # Skipped types come back empty, the others as they are.
    skipped = walk(data, frozenset({b"IDAT"}))
    assert skipped == [(t, b"" if t == b"IDAT" else d) for t, d in parse_chunks(data)]


@pytest.mark.parametrize("ctype", [b"tEXt", b"IDAT", b"IEND"])
def test_a_checksum_mismatch_names_the_chunk(ctype: bytes) -> None:
    data = bytearray(small_file())
    (_, at, length) = next(entry for entry in offsets(bytes(data)) if entry[0] == ctype)
    data[at + 8 + length] ^= 0x01  # the CRC's first byte
    with pytest.raises(
        ImageDecodeError, match=f"checksum mismatch in a chunk of type {ctype.decode()}"
    ):
        walk(bytes(data))
    if ctype == b"IDAT":  # a skipped chunk's CRC is not read, as documented
        assert [t for t, _ in walk(bytes(data), frozenset({b"IDAT"}))][-1] == b"IEND"


@pytest.mark.parametrize(
    ("patch", "needle"),
    [
        (lambda length: length + 1, "checksum mismatch"),  # reads one byte of the CRC as data
        (lambda length: length + 10_000, "ends inside a chunk of type tEXt"),
        (lambda length: 0x8000_0000, "invalid chunk header"),
        (lambda length: 0xFFFF_FFFF, "invalid chunk header"),
    ],
    ids=["one more", "past the end", "2**31", "2**32-1"],
)
def test_a_wrong_length_is_refused(patch: Callable[[int], int], needle: str) -> None:
    data = bytearray(small_file())
    (_, at, length) = next(entry for entry in offsets(bytes(data)) if entry[0] == b"tEXt")
    data[at : at + 4] = struct.pack(">I", patch(length))
    with pytest.raises(ImageDecodeError, match=re.escape(needle)):
        walk(bytes(data))


@pytest.mark.parametrize("ctype", [b"tE7t", b"tE t", b"\x00\x00\x00\x00"])
def test_a_chunk_type_of_other_than_letters_is_refused(ctype: bytes) -> None:
    data = bytearray(small_file())
    (_, at, _) = next(entry for entry in offsets(bytes(data)) if entry[0] == b"tEXt")
    data[at + 4 : at + 8] = ctype
    with pytest.raises(ImageDecodeError, match="invalid chunk header"):
        walk(bytes(data))


@pytest.mark.parametrize("depth", [8, 16])
def test_every_truncation_is_a_decode_error(depth: int) -> None:
    """Each prefix of a complete file, through header, chunk walk and inflation (and the
    16-bit decoder): ImageDecodeError, never another exception, never an image."""
    data = small_file(depth)
    for cut in range(len(data)):
        fp = io.BytesIO(data[:cut])
        with pytest.raises(ImageDecodeError, match=r"truncated|ends"):
            header = png.read_png_header(fp, LABEL)
            if depth == 16:
                png.decode_png16(fp, header, LABEL)
            else:
                structure = png.read_png_structure(fp, header, LABEL, keep_idat=True)
                png.inflate_image_data(structure.idat, header, LABEL)
    assert decode16(small_file(16)).shape == (4, 5, 3)  # the whole file is fine


@pytest.mark.parametrize("extra", [b"\x00", b"IEND", chunk(b"IEND", b"")])
def test_anything_after_iend_is_refused(extra: bytes) -> None:
    with pytest.raises(ImageDecodeError, match=f"{len(extra):,} bytes of data after the IEND"):
        walk(small_file() + extra)


def test_a_missing_iend_is_refused() -> None:
    data = small_file()
    with pytest.raises(ImageDecodeError, match="ends before its IEND"):
        walk(data[:-12])


def test_max_png_chunks_is_ten_thousand_plus_one_per_4_kib() -> None:
    for size, expected in [(0, 10_000), (4095, 10_000), (4096, 10_001), (10 << 20, 12_560)]:
        assert png.max_png_chunks(size) == expected


def test_the_chunk_limit_is_exact() -> None:
    """A file of exactly as many chunks as its size allows is read; one chunk more is not."""
    stream = zlib.compress(b"\x00" * 5)

    def made(count: int) -> bytes:  # IHDR, count empty private chunks, IDAT, IEND
        return build(ihdr(4, 1, 8, 0), stream, before=chunk(b"prVt", b"") * count)

    base = len(made(0))  # each private chunk adds 12 bytes
    count = max(n for n in range(20_000) if n + 3 <= png.max_png_chunks(base + 12 * n))
    assert count > 9_000
    assert len(walk(made(count))) == count + 3
    limit = png.max_png_chunks(base + 12 * (count + 1))
    assert count + 4 == limit + 1  # one over, not the size's allowance growing with it
    with pytest.raises(ImageDecodeError, match=f"more than {limit:,} chunks"):
        walk(made(count + 1))


def test_a_declared_giant_chunk_costs_nothing() -> None:
    """A chunk claiming 2**31 - 1 bytes in a file of a few hundred: refused as truncated,
    without a buffer of the size it claims."""
    data = bytearray(small_file())
    (_, at, _) = next(entry for entry in offsets(bytes(data)) if entry[0] == b"tEXt")
    data[at : at + 4] = struct.pack(">I", (1 << 31) - 1)
    tracemalloc.start()
    try:
        with pytest.raises(ImageDecodeError, match="ends inside a chunk of type tEXt"):
            walk(bytes(data))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 1 << 20


# --------------------------------------------------------------------------------------------
# The chunk structure and the image data
# --------------------------------------------------------------------------------------------


def structure(data: bytes, **kwargs: bool) -> png.PngImageData:
    fp = io.BytesIO(data)
    header = png.read_png_header(fp, LABEL)
    return png.read_png_structure(fp, header, LABEL, **kwargs)


def test_read_png_structure_keeps_what_it_is_asked_for() -> None:
    stream = zlib.compress(b"\x00" * 7 * 2)
    pieces = [stream[:4], stream[4:9], stream[9:]]
    trns = chunk(b"tRNS", b"\x00\x07")
    data = build(ihdr(3, 2, 16, 0), pieces, before=trns)
    assert structure(data, keep_idat=True) == png.PngImageData(pieces, b"\x00\x07")
    assert structure(data, keep_idat=False) == png.PngImageData([], b"\x00\x07")
    assert structure(data, keep_idat=False, skip_idat=True).trns == b"\x00\x07"
    # Seeking over the IDATs reads none of their bytes.
    big = encode(random_image(np.random.default_rng(0), (300, 300, 3), np.uint8))
    fp = CountingReader(big)
    header = png.read_png_header(fp, LABEL)
    png.read_png_structure(fp, header, LABEL, keep_idat=False, skip_idat=True)
    assert fp.bytes_read < 200 < len(big) // 1000


@pytest.mark.parametrize(
    ("data", "needle"),
    [
        (SIGNATURE + ihdr(3, 1, 8, 0) + chunk(b"IEND", b""), "no image data (no IDAT)"),
        (
            build(
                ihdr(3, 1, 8, 0), zlib.compress(b"\x00" * 4)[:6], after=chunk(b"tEXt", b"a\x00b")
            )[:-12]
            + chunk(b"IDAT", zlib.compress(b"\x00" * 4)[6:])
            + chunk(b"IEND", b""),
            "IDAT chunks are not consecutive",
        ),
        (build(ihdr(3, 1, 8, 3), zlib.compress(b"\x00" * 4)), "without a PLTE chunk before"),
        (
            build(ihdr(3, 1, 8, 3), zlib.compress(b"\x00" * 4), after=chunk(b"PLTE", b"\x00" * 3)),
            "without a PLTE chunk before",
        ),
    ],
    ids=["no IDAT", "IDAT split", "no PLTE", "PLTE after IDAT"],
)
def test_an_impossible_chunk_order_is_refused(data: bytes, needle: str) -> None:
    with pytest.raises(ImageDecodeError, match=re.escape(needle)):
        structure(data, keep_idat=True)


def test_a_palette_before_the_image_data_is_fine() -> None:
    data = build(ihdr(3, 1, 8, 3), zlib.compress(b"\x00" * 4), before=chunk(b"PLTE", b"\x00" * 3))
    assert len(structure(data, keep_idat=True).idat) == 1


def inflate(pieces: list[bytes], header: png.PngHeader, keep: bool = True) -> bytearray:
    return png.inflate_image_data(pieces, header, LABEL, keep=keep)


ROWS = png.PngHeader(5, 3, 16, 0, False)  # 3 rows of 1 + 10 bytes
ROW = b"\x00" + bytes(range(10))


def test_inflate_returns_exactly_the_announced_bytes() -> None:
    stream = zlib.compress(ROW * 3)
    assert inflate([stream], ROWS) == ROW * 3
    # Split anywhere, even a byte a chunk, with empty chunks between and after.
    pieces = [stream[i : i + 1] for i in range(len(stream))]
    assert inflate([b"", *pieces, b"", b""], ROWS) == ROW * 3
    # keep=False checks the same and keeps nothing.
    assert inflate(pieces, ROWS, keep=False) == bytearray()


@pytest.mark.parametrize("keep", [True, False])
@pytest.mark.parametrize(
    ("pieces", "needle"),
    [
        ([zlib.compress(ROW * 2)], f"holds {2 * len(ROW):,} of the {3 * len(ROW):,} bytes"),
        ([], f"holds 0 of the {3 * len(ROW):,} bytes"),
        ([zlib.compress(ROW * 3 + b"\x00")], f"inflates to more than the {3 * len(ROW):,} bytes"),
        ([zlib.compress(ROW * 3)[:-4]], "stops before the end of the zlib stream"),
        ([zlib.compress(ROW * 3) + b"\x00"], "after the end of the compressed image stream"),
        ([zlib.compress(ROW * 3), b"\x00"], "after the end of the compressed image stream"),
    ],
    ids=["short", "empty", "long", "no checksum", "junk after", "junk in a later chunk"],
)
def test_inflate_refuses_anything_else(pieces: list[bytes], needle: str, keep: bool) -> None:
    with pytest.raises(ImageDecodeError, match=re.escape(needle)) as info:
        inflate(pieces, ROWS, keep)
    assert LABEL in str(info.value)


def test_an_absurd_declared_size_is_refused_without_its_memory() -> None:
    """A header of (2**31 - 1)^2 RGBA 16-bit pixels (about 3.7e19 bytes) over a stream of a
    few bytes: the stream runs out, and no buffer of the announced size is made."""
    top = (1 << 31) - 1
    stream = zlib.compress(b"\x00" * 100)
    data = build(ihdr(top, top, 16, 6), stream)
    announced = top * (1 + top * 8)
    tracemalloc.start()
    try:
        with pytest.raises(ImageDecodeError, match=re.escape(f"holds 100 of the {announced:,}")):
            decode16(data)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 1 << 20


def test_a_zlib_bomb_is_stopped_at_the_announced_size() -> None:
    """32 MiB of zeros in about 32 KB, under a header announcing 64 x 64 gray 16-bit:
    refused after inflating at most the announced size plus a byte."""
    header = png.PngHeader(64, 64, 16, 0, False)
    packer = zlib.compressobj(9)
    bomb = b"".join(packer.compress(bytes(1 << 20)) for _ in range(32)) + packer.flush()
    assert len(bomb) < 64_000
    for keep in (True, False):
        tracemalloc.start()
        try:
            with pytest.raises(ImageDecodeError, match="inflates to more than"):
                inflate([bomb], header, keep)
            _, peak = tracemalloc.get_traced_memory()
        finally:
            tracemalloc.stop()
        assert peak < 2 << 20


# --------------------------------------------------------------------------------------------
# Samples and metadata text
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("shape", "dtype", "color_type", "depth"),
    [
        ((3, 4), np.uint8, 0, 8),
        ((3, 4, 1), np.uint16, 0, 16),
        ((3, 4, 3), np.uint8, 2, 8),
        ((3, 4, 4), np.uint16, 6, 16),
        ((3, 4, 3), np.float32, 2, 16),
        ((3, 4), np.float64, 0, 16),
    ],
)
def test_png_samples_makes_contiguous_big_endian_samples(
    shape: tuple[int, ...], dtype: Any, color_type: int, depth: int
) -> None:
    rng = np.random.default_rng(1)
    if np.dtype(dtype).kind == "f":
        image = (rng.random(shape) * 1.4 - 0.2).astype(dtype)  # some outside [0, 1]
        values = [
            round(min(max(float(v), 0.0), 1.0) * 65535) for v in image.astype(np.float64).ravel()
        ]
    else:
        image = random_image(rng, shape, dtype)
        values = [int(v) for v in image.ravel()]
    view = np.asfortranarray(image)  # not C-contiguous
    assert not view.flags.c_contiguous
    samples, got_type, got_depth = png.png_samples(view)
    assert (got_type, got_depth) == (color_type, depth)
    assert samples.shape == (3, 4, CHANNELS[color_type]) and samples.flags.c_contiguous
    assert samples.dtype == (np.dtype(np.uint8) if depth == 8 else np.dtype(">u2"))
    assert [int(v) for v in samples.ravel()] == values


def test_png_samples_refuses_a_side_past_the_png_limit_without_copying() -> None:
    wide = np.broadcast_to(np.zeros((1, 1), np.uint8), (1, 1 << 31))  # no memory behind it
    with pytest.raises(InvalidImageError, match="too large for PNG"):
        png.png_samples(wide)


@pytest.mark.parametrize(
    ("image", "needle"),
    [
        ([[1, 2]], "numpy array"),
        (np.zeros((2, 2, 2), np.uint8), "(2, 2, 2)"),
        (np.zeros((0, 3), np.uint8), "no pixels"),
        (np.zeros((2, 2), np.int16), "int16"),
        (np.array([[np.nan]], np.float32), "NaN"),
    ],
)
def test_png_samples_refuses_what_png_cannot_hold(image: Any, needle: str) -> None:
    with pytest.raises(InvalidImageError, match=re.escape(needle)):
        png.png_samples(image)


def test_metadata_text_is_sorted_ascii_json() -> None:
    metadata = {"b": [1, 2.5], "a": {"z": None, "y": True}, "é": "snow ☃"}
    text = png.metadata_text(metadata)
    assert text is not None
    text.decode("ascii")  # the non-ASCII escaped: a tEXt chunk is Latin-1
    assert json.loads(text) == metadata
    assert text == json.dumps(metadata, sort_keys=True).encode("ascii")
    assert png.metadata_text(None) is None
    assert png.metadata_text({}) == b"{}"


@pytest.mark.parametrize(
    "metadata",
    [[("a", 1)], "text", {"a": float("nan")}, {"a": float("inf")}, {"a": object()}, {1: 2, "b": 3}],
)
def test_metadata_text_refuses_what_json_cannot_hold(metadata: Any) -> None:
    with pytest.raises(InvalidParameterError, match="metadata"):
        png.metadata_text(metadata)


def test_written_metadata_is_visible_to_pillow_and_read_back() -> None:
    metadata = {"seed": 7, "options": {"block": 32, "blend": "poisson"}, "note": "café"}
    text = png.metadata_text(metadata)
    data = encode(np.zeros((2, 3, 3), np.uint16), text)
    with Image.open(io.BytesIO(data)) as im:
        assert isinstance(im, PngImagePlugin.PngImageFile)
        assert json.loads(im.text["quilting"]) == metadata
    assert png.png_metadata(io.BytesIO(data), LABEL) == metadata
    assert png.png_metadata(io.BytesIO(encode(np.zeros((2, 3), np.uint8))), LABEL) == {}


@pytest.mark.parametrize("how", ["tEXt", "zTXt", "iTXt", "iTXt compressed"])
def test_pillow_written_metadata_is_read(how: str) -> None:
    info = PngImagePlugin.PngInfo()
    info.add_text("other", '{"not": "this"}')
    text = (
        '{"from": "pillow", "snow": "\u2603"}' if how.startswith("iTXt") else '{"from": "pillow"}'
    )
    if how == "tEXt":
        info.add_text("quilting", text)
    elif how == "zTXt":
        info.add_text("quilting", text, zip=True)
    else:
        info.add_itxt("quilting", text, lang="en", tkey="q", zip=how.endswith("compressed"))
    data = pillow_png(Image.new("RGB", (3, 2)), pnginfo=info)
    wanted = how.split()[0].encode()
    assert wanted in [ctype for ctype, _ in parse_chunks(data)]
    assert png.png_metadata(io.BytesIO(data), LABEL) == json.loads(text)


def with_text(*texts: tuple[bytes, bytes], after: tuple[tuple[bytes, bytes], ...] = ()) -> bytes:
    return build(
        ihdr(2, 1, 8, 0),
        zlib.compress(b"\x00\x00\x00"),
        before=b"".join(chunk(t, d) for t, d in texts),
        after=b"".join(chunk(t, d) for t, d in after),
    )


def test_the_first_quilting_text_counts_wherever_it_is() -> None:
    first = (b"tEXt", b'quilting\x00{"n": 1}')
    second = (b"tEXt", b'quilting\x00{"n": 2}')
    assert png.png_metadata(io.BytesIO(with_text(first, second)), LABEL) == {"n": 1}
    # After the image data too; the keyword must match exactly.
    late = with_text((b"tEXt", b'quiltingX\x00{"n": 0}'), after=(second,))
    assert png.png_metadata(io.BytesIO(late), LABEL) == {"n": 2}


@pytest.mark.parametrize(
    ("entry", "needle"),
    [
        ((b"tEXt", b"quilting\x00not json"), "'quilting' metadata is not valid JSON"),
        ((b"tEXt", b"quilting\x00[1, 2]"), "is a JSON list, not an object"),
        ((b"tEXt", b'quilting\x00"a"'), "is a JSON str, not an object"),
        ((b"zTXt", b"quilting\x00"), "empty zTXt chunk"),
        ((b"iTXt", b"quilting\x00\x00"), "short iTXt chunk"),
    ],
    ids=["not json", "a list", "a string", "empty zTXt", "short iTXt"],
)
def test_a_bad_metadata_text_is_a_decode_error(entry: tuple[bytes, bytes], needle: str) -> None:
    with pytest.raises(ImageDecodeError, match=re.escape(needle)) as info:
        png.png_metadata(io.BytesIO(with_text(entry)), LABEL)
    assert LABEL in str(info.value)


def test_a_compressed_text_bomb_is_refused() -> None:
    """A zTXt inflating past 64 MiB is refused (metadata is small), without inflating all of
    it: 128 MiB of zeros in about 130 KB."""
    packer = zlib.compressobj(1)
    piece = bytes(1 << 22)
    bomb = b"".join(packer.compress(piece) for _ in range(32)) + packer.flush()
    data = with_text((b"zTXt", b"quilting\x00\x00" + bomb))
    tracemalloc.start()
    try:
        with pytest.raises(ImageDecodeError, match="inflates past 67,108,864 bytes"):
            png.png_metadata(io.BytesIO(data), LABEL)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # Inflating to the 64 MiB allowed peaks at twice that while zlib joins its output; all
    # 128 MiB of the stream would peak at 256 MiB.
    assert peak < 3 * (64 << 20)


def test_png_metadata_reads_no_image_data() -> None:
    """The IDAT chunks are seeked over: a 1 MB image without metadata, walked to its end,
    costs a few dozen bytes of reading, and a damaged IDAT does not matter to it."""
    image = random_image(np.random.default_rng(4), (600, 600, 3), np.uint8)
    data = bytearray(encode(image, level=0))
    assert len(offsets(bytes(data))) == 4  # IHDR, two IDATs, IEND
    fp = CountingReader(bytes(data))
    assert png.png_metadata(fp, LABEL) == {}
    assert fp.bytes_read < 200 and len(data) > 1 << 20
    (_, at, length) = next(entry for entry in offsets(bytes(data)) if entry[0] == b"IDAT")
    data[at + 8 + length // 2] ^= 0xFF
    assert png.png_metadata(io.BytesIO(bytes(data)), LABEL) == {}
    with pytest.raises(ImageDecodeError, match="checksum mismatch in a chunk of type IDAT"):
        walk(bytes(data))  # the damage is there to be found


def test_key_to_rgba() -> None:
    rng = np.random.default_rng(5)
    for dtype, opaque in ((np.uint8, 255), (np.uint16, 65535)):
        rgb = random_image(rng, (3, 4, 3), dtype)
        transparent = rng.random((3, 4)) < 0.5
        got = png.key_to_rgba(rgb, transparent, opaque)
        assert got.dtype == dtype and got.shape == (3, 4, 4)
        for y in range(3):
            for x in range(4):
                alpha = 0 if transparent[y, x] else opaque
                assert got[y, x].tolist() == [*rgb[y, x].tolist(), alpha]
