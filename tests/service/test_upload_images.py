"""Unit tests of :mod:`quilting.service.upload_images`, called directly (no server).

Covers
------
- ``read_header``: the format, width, height, channels and bit depth of 8- and 16-bit gray,
  RGB and RGBA PNGs and of gray, RGB and EXIF-turned JPEGs; the pixel limit at its boundary,
  and the 422 problems (``invalid_image``, ``image_too_large``) naming the form field and the
  service setting instead of the engine's ``<bytes>`` and ``max_pixels``.
- ``read_upload``: the exact pixels encoded, in the dtype and shape the header announced; the
  same refusals as the header, and what only decoding can refuse.
- Decompression bombs (a few hundred bytes declaring billions of pixels) refused by both
  before any pixel is inflated or decoded.
- ``check_image_header``: the tighter of the input and output pixel limits, by its name.
- ``companion_fits``, ``examples_match`` and ``target_fits``: their problems name both sizes
  (width x height), the kinds, the index and the field.
- ``Decoded``: its list and dict defaults are not shared between instances.
"""

from __future__ import annotations

import io
import struct
import zlib
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from PIL import Image

import quilting.io as quilting_io
from quilting.io import ImageHeader, encode_png
from quilting.service.jobs import PixelLimits
from quilting.service.problems import Problem
from quilting.service.upload_images import (
    Decoded,
    check_image_header,
    companion_fits,
    examples_match,
    read_header,
    read_upload,
    target_fits,
)

LIMIT = 25_000_000
SETTING = "max_input_pixels"
READERS = [read_header, read_upload]


def _pixels(height: int, width: int, channels: int, dtype: type[np.generic]) -> np.ndarray:
    rng = np.random.default_rng(height * 1000 + width * 10 + channels)
    shape = (height, width) if channels == 1 else (height, width, channels)
    top = 65536 if dtype is np.uint16 else 256
    return rng.integers(0, top, size=shape).astype(dtype)


def _jpeg(image: Image.Image, **params: Any) -> bytes:
    buffer = io.BytesIO()
    image.save(buffer, format="JPEG", quality=95, **params)
    return buffer.getvalue()


def _chunk(kind: bytes, payload: bytes) -> bytes:
    crc = struct.pack(">I", zlib.crc32(kind + payload))
    return struct.pack(">I", len(payload)) + kind + payload + crc


def _png_claiming(width: int, height: int) -> bytes:
    """A well-formed gray PNG header declaring ``width x height`` over 64 bytes of data."""
    ihdr = _chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
    return (
        b"\x89PNG\r\n\x1a\n"
        + ihdr
        + _chunk(b"IDAT", zlib.compress(bytes(64)))
        + _chunk(b"IEND", b"")
    )


def _jpeg_claiming(width: int, height: int) -> bytes:
    """A small real JPEG whose frame header (SOF0) is patched to say ``width x height``."""
    data = bytearray(_jpeg(Image.new("RGB", (16, 16), (90, 30, 200))))
    at = data.index(b"\xff\xc0")
    data[at + 5 : at + 9] = struct.pack(">HH", height, width)
    return bytes(data)


def _refusal(call: Any, *args: Any) -> Problem:
    with pytest.raises(Problem) as caught:
        call(*args)
    return caught.value


PNG_KINDS = [
    (1, np.uint8),
    (3, np.uint8),
    (4, np.uint8),
    (1, np.uint16),
    (3, np.uint16),
    (4, np.uint16),
]


@pytest.mark.parametrize(
    ("channels", "dtype"), PNG_KINDS, ids=[f"{c}ch-{d.__name__}" for c, d in PNG_KINDS]
)
def test_read_header_reads_a_png_exactly_and_read_upload_returns_its_pixels(
    channels: int, dtype: type[np.generic]
) -> None:
    pixels = _pixels(5, 11, channels, dtype)  # not square: width and height cannot swap
    data = encode_png(pixels)
    depth = 16 if dtype is np.uint16 else 8
    assert read_header(data, "texture", LIMIT, SETTING) == ImageHeader(
        "png", 11, 5, channels, depth
    )
    decoded = read_upload(data, "texture", LIMIT, SETTING)
    assert decoded.dtype == dtype and decoded.shape == pixels.shape
    np.testing.assert_array_equal(decoded, pixels)


@pytest.mark.parametrize(
    ("image", "size", "channels"),
    [
        (Image.new("L", (24, 16), 77), (24, 16), 1),
        (Image.new("RGB", (24, 16), (200, 40, 10)), (24, 16), 3),
        (Image.new("CMYK", (24, 16), (10, 20, 30, 0)), (24, 16), 3),
    ],
    ids=["gray", "rgb", "cmyk"],
)
def test_read_header_reads_a_jpeg_and_read_upload_agrees(
    image: Image.Image, size: tuple[int, int], channels: int
) -> None:
    data = _jpeg(image)
    header = read_header(data, "texture", LIMIT, SETTING)
    assert header == ImageHeader("jpeg", *size, channels, 8)
    decoded = read_upload(data, "texture", LIMIT, SETTING)
    expected = (size[1], size[0]) if channels == 1 else (size[1], size[0], 3)
    assert decoded.dtype == np.uint8 and decoded.shape == expected
    if image.mode in ("L", "RGB"):  # a flat colour survives JPEG within a step or two
        reference = np.asarray(image).astype(np.int16)
        assert np.abs(decoded.astype(np.int16) - reference).max() <= 2


def test_a_jpeg_turned_a_quarter_by_exif_has_its_sides_swapped_in_header_and_pixels() -> None:
    exif = Image.Exif()
    exif[0x0112] = 6  # rotate 90 degrees clockwise to show
    data = _jpeg(Image.new("RGB", (24, 16), (0, 128, 255)), exif=exif.tobytes())
    header = read_header(data, "texture", LIMIT, SETTING)
    assert (header.width, header.height) == (16, 24)
    assert read_upload(data, "texture", LIMIT, SETTING).shape == (24, 16, 3)


def _unreadable() -> dict[str, bytes]:
    png = encode_png(_pixels(8, 8, 3, np.uint8))
    jpeg = _jpeg(Image.new("RGB", (32, 32), (1, 2, 3)))
    bad_crc = bytearray(png)
    bad_crc[29] ^= 0xFF  # inside IHDR's CRC
    return {
        "empty": b"",
        "text": b"hello, this is not an image at all",
        "gif": b"GIF89a" + bytes(64),
        "png signature only": png[:8],
        "truncated png": png[: len(png) // 2],
        "png with a bad crc": bytes(bad_crc),
        "jpeg signature only": jpeg[:3],
        "truncated jpeg": jpeg[: len(jpeg) // 2],
    }


@pytest.mark.parametrize("what", list(_unreadable()))
@pytest.mark.parametrize("reader", READERS, ids=lambda f: f.__name__)
def test_unreadable_bytes_are_invalid_image_naming_the_field(reader: Any, what: str) -> None:
    problem = _refusal(reader, _unreadable()[what], "source_mask", LIMIT, SETTING)
    assert (problem.status, problem.code, problem.extra) == (
        422,
        "invalid_image",
        {"field": "source_mask"},
    )
    assert problem.detail.startswith("source_mask: ")
    assert "<bytes>" not in problem.detail and "Traceback" not in problem.detail
    assert problem.body()["type"].endswith("/invalid_image")


@pytest.mark.parametrize("reader", READERS, ids=lambda f: f.__name__)
def test_the_pixel_limit_takes_exactly_its_count_and_refuses_one_more(reader: Any) -> None:
    data = encode_png(_pixels(5, 7, 3, np.uint8))  # 35 pixels
    reader(data, "companion", 35, "max_input_pixels")  # exactly the limit: accepted
    problem = _refusal(reader, data, "companion", 34, "max_output_pixels")
    assert (problem.status, problem.code, problem.extra) == (
        422,
        "image_too_large",
        {"field": "companion"},
    )
    assert problem.detail.startswith("companion: ")
    assert "declares 7x5 pixels" in problem.detail and "limit of 34 pixels" in problem.detail
    assert "(max_output_pixels)" in problem.detail  # the setting, not the engine's argument
    assert "max_pixels" not in problem.detail and "<bytes>" not in problem.detail


@pytest.mark.parametrize(
    "data",
    [_png_claiming(60_000, 60_000), _jpeg_claiming(65_000, 65_000)],
    ids=["png", "jpeg"],
)
@pytest.mark.parametrize("reader", READERS, ids=lambda f: f.__name__)
def test_a_bomb_is_refused_before_any_pixel_is_decoded(
    reader: Any, data: bytes, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert len(data) < 2000  # a tiny file declaring billions of pixels

    def no_decoding(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("pixels were decoded before the limit was checked")

    for name in ("inflate_image_data", "decode_png16", "_decode_png_pillow", "_check_jpeg_data"):
        monkeypatch.setattr(quilting_io, name, no_decoding)
    for plugin in ("PngImagePlugin", "JpegImagePlugin"):
        fake = SimpleNamespace(PngImageFile=no_decoding, JpegImageFile=no_decoding)
        monkeypatch.setattr(quilting_io, plugin, fake)
    problem = _refusal(reader, data, "texture", LIMIT, SETTING)
    assert (problem.status, problem.code, problem.extra["field"]) == (
        422,
        "image_too_large",
        "texture",
    )
    assert problem.detail.endswith("the limit of 25,000,000 pixels (max_input_pixels)")


def test_a_header_within_the_limit_over_too_little_data_fails_when_decoded() -> None:
    # 5000x5000 declared over 64 bytes of image data: only decoding can tell.
    data = _png_claiming(5000, 5000)
    assert read_header(data, "target", LIMIT, SETTING) == ImageHeader("png", 5000, 5000, 1, 8)
    problem = _refusal(read_upload, data, "target", LIMIT, SETTING)
    assert (problem.status, problem.code, problem.extra) == (
        422,
        "invalid_image",
        {"field": "target"},
    )


def test_check_image_header_applies_the_tighter_limit_and_names_its_setting() -> None:
    data = encode_png(_pixels(6, 10, 1, np.uint8))  # 60 pixels
    output_tighter = PixelLimits(max_input_pixels=100, max_output_pixels=50, max_side=64)
    problem = _refusal(check_image_header, data, "image", output_tighter)
    assert (problem.code, problem.extra) == ("image_too_large", {"field": "image"})
    assert "(max_output_pixels)" in problem.detail

    input_tighter = PixelLimits(max_input_pixels=50, max_output_pixels=100, max_side=64)
    problem = _refusal(check_image_header, data, "image", input_tighter)
    assert "(max_input_pixels)" in problem.detail

    roomy = PixelLimits(max_input_pixels=60, max_output_pixels=60, max_side=64)
    assert check_image_header(data, "image", roomy) == ImageHeader("png", 10, 6, 1, 8)


@pytest.mark.parametrize("of", ["texture", "image"])
def test_a_companion_of_another_size_is_refused_naming_both_sizes(of: str) -> None:
    companion_fits("normals", (9, 4), (9, 4), of)  # the same size: no problem raised
    problem = _refusal(companion_fits, "normals", (4, 9), (9, 4), of)
    assert (problem.status, problem.code, problem.extra) == (
        422,
        "invalid_companion",
        {"field": "companion"},
    )
    # width x height, each in its place: the companion's first, the texture's second
    assert "'normals' is 4x9" in problem.detail
    assert problem.detail.endswith(f"the {of}'s size, 9x4")


def test_examples_of_one_kind_match_and_another_kind_is_refused_naming_its_index() -> None:
    examples_match([(3, 8), (3, 8), (3, 8)])  # no problem raised
    examples_match([(1, 16)])  # no problem raised

    problem = _refusal(examples_match, [(3, 8), (3, 8), (4, 16)])
    assert (problem.status, problem.code, problem.extra) == (
        422,
        "invalid_image",
        {"field": "texture"},
    )
    assert "texture 2 has 4 channels at 16 bits" in problem.detail
    assert "texture 0 has 3 at 8" in problem.detail

    problem = _refusal(examples_match, [(1, 8), (3, 8)], "normals")
    assert (problem.code, problem.extra) == ("invalid_companion", {"field": "companion"})
    assert "companion 'normals''s map of texture 1 has 3 channels at 8 bits" in problem.detail


def test_a_target_may_be_as_long_as_the_longest_side_and_no_longer() -> None:
    target_fits(4096, 100, 4096)  # no problem raised
    target_fits(100, 4096, 4096)  # no problem raised
    for width, height in ((4097, 10), (10, 4097)):
        problem = _refusal(target_fits, width, height, 4096)
        assert (problem.status, problem.code, problem.extra) == (
            422,
            "image_too_large",
            {"field": "target"},
        )
        assert f"target is {width}x{height}" in problem.detail
        assert "4096 pixels (max_side)" in problem.detail


def test_decoded_defaults_are_not_shared_between_jobs() -> None:
    texture = np.zeros((4, 4), np.uint8)
    first = Decoded(texture, {}, 4, 4)
    second = Decoded(texture, {}, 4, 4)
    first.layers.append(texture)
    first.examples.append(texture)
    first.example_companions["normals"] = [texture]
    first.trimaps.append(None)
    assert second.layers == [] and second.examples == [] and second.trimaps == []
    assert second.example_companions == {} and second.source_masks == []
    assert (second.target, second.mask, second.source) == (None, None, None)
