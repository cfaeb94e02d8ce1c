"""Image files in and out: the only module of quilting that imports Pillow.

:func:`read_image` turns PNG and JPEG files (recognised by their first bytes, never by their
name) into numpy arrays at their native bit depth, and refuses an image whose header declares
more pixels than a limit before a single pixel is decoded. :func:`encode_png` writes 8- or
16-bit PNGs with an optional JSON metadata object, which :func:`read_image_metadata` reads
back. :func:`write_image` picks the format from the file name (PNG, JPEG or WebP) and refuses,
before writing a byte, an image that the format cannot hold (16-bit, float or alpha images are
PNG only), so that no file ever holds one format under another's name.

Pillow decodes 8-bit (and lower) PNGs and all JPEGs. What it cannot do is in
:mod:`quilting.png` (numpy and the standard library): every 16-bit PNG is decoded there,
because Pillow drops the low byte of 16-bit colour samples, and every PNG is written there,
because Pillow cannot write 16-bit colour. This module sniffs the format, applies the pixel
limit, drives Pillow, and reads the PNG chunk structure through :mod:`quilting.png` so that
8-bit files get the same checks as 16-bit ones.

Every failure to read comes out as :class:`~quilting.core.errors.ImageDecodeError` or
:class:`~quilting.core.errors.ImageTooLargeError` with the file named in the message, never as
a raw Pillow, zlib or OS error.
"""

from __future__ import annotations

import io
import os
import re
import struct
import zlib
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import IO, Any, Final

import numpy as np
from PIL import Image, JpegImagePlugin, PngImagePlugin

from quilting.core.errors import (
    ImageDecodeError,
    ImageTooLargeError,
    InvalidParameterError,
    QuiltingError,
)
from quilting.png import (
    PNG_SIGNATURE,
    ImageArray,
    PngHeader,
    assemble_png,
    decode_png16,
    inflate_image_data,
    key_to_rgba,
    metadata_text,
    png_metadata,
    png_samples,
    read_png_header,
    read_png_structure,
)

__all__ = [
    "DEFAULT_MAX_PIXELS",
    "WRITE_FORMATS",
    "ImageHeader",
    "check_writable",
    "encode_image",
    "encode_png",
    "image_format",
    "image_header",
    "output_format",
    "read_image",
    "read_image_metadata",
    "write_image",
]

DEFAULT_MAX_PIXELS: int = 100_000_000
"""Largest image (width * height) :func:`read_image` decodes unless told otherwise."""

_JPEG_SIGNATURE: Final = b"\xff\xd8\xff"

# Signatures of formats people commonly upload by mistake, to say what the file looked like.
_OTHER_SIGNATURES: Final = (
    (b"GIF87a", "GIF"),
    (b"GIF89a", "GIF"),
    (b"BM", "BMP"),
    (b"II*\x00", "TIFF"),
    (b"MM\x00*", "TIFF"),
    (b"\x00\x00\x01\x00", "ICO"),
    (b"8BPS", "PSD"),
)

# What Pillow, zlib and the file system raise on bad input; turned into ImageDecodeError.
_DECODE_FAILURES: Final = (
    OSError,
    SyntaxError,
    ValueError,
    EOFError,
    IndexError,
    KeyError,
    struct.error,
    zlib.error,
    Image.DecompressionBombError,
)

_EXIF_ORIENTATION: Final = 0x0112


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------


def read_image(
    source: str | os.PathLike[str] | bytes, *, max_pixels: int = DEFAULT_MAX_PIXELS
) -> ImageArray:
    """Decode a PNG or JPEG file into an array at its native bit depth.

    The format is recognised from the first bytes (never from a file name). The pixel count
    declared by the header is checked against ``max_pixels`` before any pixel is decoded;
    Pillow's own decompression-bomb limit does not apply, this one does.

    Parameters
    ----------
    source : str, os.PathLike or bytes
        Path of the file, or the file's bytes.
    max_pixels : int, optional
        Largest width * height accepted (default :data:`DEFAULT_MAX_PIXELS`).

    Returns
    -------
    numpy.ndarray
        ``uint8`` for 8-bit (and lower) images, ``uint16`` for 16-bit PNGs, shaped

        - (H, W) for gray (1-bit images come out as 0/255),
        - (H, W, 3) for RGB, palette PNGs without transparency and JPEGs in any colour space,
        - (H, W, 4) for RGBA, gray+alpha (gray copied into R, G and B), palette PNGs with
          transparency and gray or RGB PNGs with a tRNS colour key.

        A JPEG's EXIF orientation is applied, so the array is upright as a viewer shows it.

    Raises
    ------
    ImageDecodeError
        The file cannot be opened, is not a PNG or JPEG, or its data is corrupt or truncated.
    ImageTooLargeError
        The header declares more than ``max_pixels`` pixels.
    InvalidParameterError
        ``max_pixels`` is not a positive integer or ``source`` is not a path or bytes.
    """
    if isinstance(max_pixels, bool) or not isinstance(max_pixels, int | np.integer):
        raise InvalidParameterError("max_pixels", max_pixels, "a positive integer")
    if max_pixels < 1:
        raise InvalidParameterError("max_pixels", max_pixels, "a positive integer")
    with _open_source(source) as (fp, label), _decode_errors(label):
        kind = image_format(fp.read(len(PNG_SIGNATURE)))
        fp.seek(0)
        if kind == "png":
            return _decode_png(fp, label, int(max_pixels))
        if kind == "jpeg":
            return _decode_jpeg(fp, label, int(max_pixels))
        raise ImageDecodeError(_unsupported_message(fp, label))


def read_image_metadata(source: str | os.PathLike[str] | bytes) -> dict[str, Any]:
    """Return the JSON object that :func:`write_image` stored in a PNG.

    Parameters
    ----------
    source : str, os.PathLike or bytes
        Path of a PNG or JPEG file, or the file's bytes.

    Returns
    -------
    dict
        The object stored under the PNG text key ``"quilting"``; ``{}`` when the PNG has no
        such key or the file is a JPEG.

    Raises
    ------
    ImageDecodeError
        The file cannot be opened, is not a PNG or JPEG, is corrupt, or its ``"quilting"``
        text is not a JSON object.
    """
    with _open_source(source) as (fp, label), _decode_errors(label):
        kind = image_format(fp.read(len(PNG_SIGNATURE)))
        fp.seek(0)
        if kind == "png":
            return png_metadata(fp, label)
        if kind == "jpeg":
            return {}
        raise ImageDecodeError(_unsupported_message(fp, label))


def image_format(head: bytes) -> str | None:
    """``"png"`` or ``"jpeg"`` from a file's first bytes (8 suffice), else ``None``.

    The only formats read here, recognized from the bytes and never from a file name.
    """
    if head.startswith(PNG_SIGNATURE):
        return "png"
    if head.startswith(_JPEG_SIGNATURE):
        return "jpeg"
    return None


@dataclass(frozen=True)
class ImageHeader:
    """What :func:`read_image` would return, known from a file's structure alone.

    Attributes
    ----------
    format : str
        ``"png"`` or ``"jpeg"``.
    width, height : int
        The array's columns and rows (a JPEG's EXIF orientation applied, as :func:`read_image`
        applies it).
    channels : int
        1 (gray), 3 (RGB) or 4 (RGBA), as :func:`read_image` returns the image.
    bit_depth : int
        8 (``uint8``) or 16 (``uint16``: 16-bit PNGs).
    """

    format: str
    width: int
    height: int
    channels: int
    bit_depth: int


def image_header(source: bytes, *, max_pixels: int = DEFAULT_MAX_PIXELS) -> ImageHeader:
    """The size, channels and depth of a PNG or JPEG, and its structure checked, undecoded.

    The checks of :func:`read_image` that need no pixel: the format, the declared pixel count
    against ``max_pixels``, and the file's structure. For a PNG, the header and every chunk
    but the image data (count, lengths, CRCs, PLTE and IDAT order, nothing after IEND); for a
    JPEG, every marker segment and that the entropy-coded data is long enough for the declared
    size. The work is one step per chunk or segment and, for a JPEG, one pass of a regular
    expression over the bytes: milliseconds for any file the service takes. What needs the
    pixels (the image data's CRCs and inflated size, the entropy-coded data itself) only
    :func:`read_image` checks: a file that passes here may still fail there.

    Parameters
    ----------
    source : bytes
        The file's bytes.
    max_pixels : int, optional
        Largest width * height accepted (default :data:`DEFAULT_MAX_PIXELS`).

    Raises
    ------
    ImageDecodeError, ImageTooLargeError
        As :func:`read_image` would, for what is found without decoding.
    """
    label = "<bytes>"
    with _decode_errors(label):
        fp = io.BytesIO(source)
        kind = image_format(source[: len(PNG_SIGNATURE)])
        if kind == "png":
            header = read_png_header(fp, label)
            _check_pixels(header.width, header.height, max_pixels, label)
            structure = read_png_structure(fp, header, label, keep_idat=False, skip_idat=True)
            channels = _PNG_DECODED_CHANNELS[header.color_type]
            keyed = structure.trns is not None and len(structure.trns) >= _TRNS_KEY_BYTES.get(
                header.color_type, 1 << 31
            )
            if (header.color_type == 3 and structure.trns is not None) or keyed:
                channels = 4  # a palette with transparency, or a colour key: RGBA
            depth = 16 if header.bit_depth == 16 else 8
            return ImageHeader("png", header.width, header.height, channels, depth)
        if kind == "jpeg":
            jpeg = _read_jpeg_structure(source, label, headers_only=True)
            _check_pixels(jpeg.width, jpeg.height, max_pixels, label)
            _check_jpeg_data(jpeg, label)
            with JpegImagePlugin.JpegImageFile(fp) as im:  # reads the header segments only
                if im.size != (jpeg.width, jpeg.height):
                    raise ImageDecodeError(
                        f"{label}: corrupt JPEG: its frame header could not be read consistently"
                    )
                channels = 1 if im.mode == "L" else 3
                width, height = im.size
                if _exif_orientation(im) >= 5:  # turned a quarter: rows and columns swap
                    width, height = height, width
            return ImageHeader("jpeg", width, height, channels, 8)
        raise ImageDecodeError(_unsupported_message(fp, label))


# Channels of each PNG colour type as read_image returns them (gray+alpha becomes RGBA), and
# the tRNS bytes that make a gray (0) or RGB (2) image's colour key, which makes it RGBA.
_PNG_DECODED_CHANNELS: Final = {0: 1, 2: 3, 3: 3, 4: 4, 6: 4}
_TRNS_KEY_BYTES: Final = {0: 2, 2: 6}


@contextmanager
def _open_source(source: str | os.PathLike[str] | bytes) -> Iterator[tuple[IO[bytes], str]]:
    """Yield a seekable binary stream over ``source`` and the label that names it in errors."""
    if isinstance(source, bytes | bytearray | memoryview):
        yield io.BytesIO(source), "<bytes>"
        return
    if not isinstance(source, str | os.PathLike):
        raise InvalidParameterError(
            "source", type(source).__name__, "a path (str or os.PathLike) or the file's bytes"
        )
    label = f"'{os.fspath(source)!s}'"
    try:
        fp: IO[bytes] = open(source, "rb")  # noqa: SIM115 - closed by the with below
    except OSError as exc:
        raise ImageDecodeError(f"{label}: cannot open the file ({exc.strerror or exc})") from exc
    with fp:
        if not fp.seekable():
            # Pipes and sockets: sniffing and header checks need to seek back.
            try:
                data = fp.read()
            except OSError as exc:
                raise ImageDecodeError(
                    f"{label}: cannot read the file ({exc.strerror or exc})"
                ) from exc
            yield io.BytesIO(data), label
        else:
            yield fp, label


@contextmanager
def _decode_errors(label: str) -> Iterator[None]:
    """Turn what Pillow, zlib and the OS raise on bad data into ImageDecodeError."""
    try:
        yield
    except QuiltingError:
        raise
    except _DECODE_FAILURES as exc:
        reason = str(exc) or type(exc).__name__
        raise ImageDecodeError(f"{label}: corrupt or truncated image data ({reason})") from exc


def _unsupported_message(fp: IO[bytes], label: str) -> str:
    head = fp.read(12)
    if not head:
        what = "the file is empty"
    elif head[:4] == b"RIFF" and head[8:12] == b"WEBP":
        what = "it looks like a WebP image"
    else:
        kind = next((name for sig, name in _OTHER_SIGNATURES if head.startswith(sig)), None)
        what = f"it looks like a {kind} image" if kind else "it is not a PNG or JPEG file"
    return f"{label}: {what}; only PNG and JPEG images are accepted"


def _check_pixels(width: int, height: int, max_pixels: int, label: str) -> None:
    if width * height > max_pixels:
        raise ImageTooLargeError(
            f"{label}: the image declares {width}x{height} pixels (width x height, "
            f"{width * height:,} in all), more than the limit of {max_pixels:,} pixels "
            "(max_pixels)"
        )


# --- PNG --------------------------------------------------------------------------------------


def _decode_png(fp: IO[bytes], label: str, max_pixels: int) -> ImageArray:
    header = read_png_header(fp, label)
    _check_pixels(header.width, header.height, max_pixels, label)
    fp.seek(0)
    if header.bit_depth == 16:
        return decode_png16(fp, header, label)
    # Pillow never checks IDAT checksums, and it takes a zlib stream that ends early as a
    # finished image (the missing rows stay zero), so a few hundred bytes could declare and
    # "decode" 100 M pixels. One pass over the chunk structure and one bounded inflate that
    # counts the bytes (and keeps none) make it exactly as strict as the 16-bit path, before
    # Pillow allocates the image. This second inflate is the price of that: about a third of
    # Pillow's own decode time.
    structure = read_png_structure(fp, header, label, keep_idat=True)
    inflate_image_data(structure.idat, header, label, keep=False)
    del structure
    fp.seek(0)
    return _decode_png_pillow(fp, header, label)


def _decode_png_pillow(fp: IO[bytes], header: PngHeader, label: str) -> ImageArray:
    """Decode a PNG of at most 8 bits per sample with Pillow.

    The plugin class is used directly rather than ``Image.open`` so that Pillow's global
    decompression-bomb check (a warning above 89 M pixels, an error above 179 M) stays out of
    the way: the caller has already applied ``max_pixels``.
    """
    with PngImagePlugin.PngImageFile(fp) as im:
        im.load()
        transparency = im.info.get("transparency")
        if im.mode == "P":
            return _pixels(im.convert("RGB" if transparency is None else "RGBA"))
        if im.mode == "RGBA":
            return _pixels(im)
        if im.mode == "LA":
            return _pixels(im.convert("RGBA"))
        if im.mode in ("1", "L"):
            gray = _pixels(im.convert("L") if im.mode == "1" else im)
            if transparency is None:
                return gray
            # A low-depth key is stored unscaled (0..2**depth - 1); Pillow leaves it that way
            # while scaling the pixels to 0..255. Mask and scale it as libpng does.
            top = (1 << header.bit_depth) - 1
            key = (int(transparency) & top) * (255 // top)
            return key_to_rgba(gray[..., None].repeat(3, axis=2), gray == key, 255)
        if im.mode == "RGB":
            rgb = _pixels(im)
            if transparency is None:
                return rgb
            matches = np.all(rgb == np.asarray(transparency, dtype=np.int64), axis=-1)
            return key_to_rgba(rgb, matches, 255)
        raise ImageDecodeError(f"{label}: unsupported PNG pixel mode {im.mode!r}")


def _pixels(im: Image.Image) -> ImageArray:
    """A writable numpy copy of ``im``'s pixels; ``im`` is closed.

    Pillow hands numpy a bytes copy of its pixel store; freeing the store before copying that
    into a writable array keeps the peak near three times the image (inside ``tobytes``)
    rather than four or five.
    """
    view = np.asarray(im)
    im.close()
    return view.copy()


# --- JPEG -------------------------------------------------------------------------------------


def _decode_jpeg(fp: IO[bytes], label: str, max_pixels: int) -> ImageArray:
    """Decode a JPEG to uint8 gray or RGB, upright according to its EXIF orientation.

    The marker structure is checked first (:func:`_read_jpeg_structure`), then the declared
    pixel count, then that the file holds enough entropy-coded data to fill the declared size
    (:func:`_check_jpeg_data`), and only then does Pillow decode. The plugin class is used
    directly (not ``Image.open``) so that Pillow's global decompression-bomb check does not
    pre-empt ``max_pixels``; constructing it reads the header only.
    """
    structure = _read_jpeg_structure(fp.read(), label)
    _check_pixels(structure.width, structure.height, max_pixels, label)
    _check_jpeg_data(structure, label)
    fp.seek(0)
    with JpegImagePlugin.JpegImageFile(fp) as im:
        width, height = im.size
        if (width, height) != (structure.width, structure.height):
            # Pillow and this parser must agree on what they read, or the checks are moot.
            raise ImageDecodeError(
                f"{label}: corrupt JPEG: its frame header could not be read consistently"
            )
        orientation = _exif_orientation(im)
        array = _pixels(im if im.mode in ("L", "RGB") else im.convert("RGB"))
    return _orient(array, orientation)


# Markers (the byte after 0xFF). SOF0 baseline, SOF1 extended sequential, SOF2 progressive:
# the Huffman-coded DCT frames that libjpeg decodes and browsers show.
_SOF_HUFFMAN: Final = frozenset({0xC0, 0xC1, 0xC2})
_SOF_PROGRESSIVE: Final = 0xC2
# The other frame types: lossless (3), hierarchical (5-7) and arithmetic-coded (9-11, 13-15).
_SOF_OTHER: Final = {
    0xC3: "lossless",
    0xC5: "hierarchical",
    0xC6: "hierarchical progressive",
    0xC7: "hierarchical lossless",
    0xC9: "arithmetic-coded",
    0xCA: "arithmetic-coded progressive",
    0xCB: "arithmetic-coded lossless",
    0xCD: "arithmetic-coded hierarchical",
    0xCE: "arithmetic-coded hierarchical progressive",
    0xCF: "arithmetic-coded hierarchical lossless",
}
_SOS: Final = 0xDA
_EOI: Final = 0xD9
# Markers without a length field: TEM and RST0-7 (the latter belong inside scans).
_STANDALONE: Final = frozenset({0x01, *range(0xD0, 0xD8)})
# A real JPEG has a few dozen segments (APPn, DQT, DHT, SOF, SOS...); the most seen in camera
# files, with an ICC profile or XMP split over many APPn segments, stay well below this.
_MAX_JPEG_SEGMENTS: Final = 1000
# Every scan makes libjpeg visit every block of its components, even a scan of a few bytes
# (one end-of-band run covers 32,767 blocks), so scans multiply decode work without adding
# to the file. libjpeg writes 10 scans for a progressive colour image and 6 for gray; mozjpeg
# and jpegtran scripts use a few dozen at most.
_MAX_JPEG_SCANS: Final = 100
# The end of a scan's entropy-coded data: 0xFF followed by anything but a stuffed zero, an
# RSTn marker (which stays inside the scan) or another 0xFF (fill before a marker).
_END_OF_SCAN: Final = re.compile(rb"\xff[^\x00\xd0-\xd7\xff]")


@dataclass(frozen=True)
class _JpegStructure:
    """What :func:`_read_jpeg_structure` found: the frame and the entropy-coded data size."""

    width: int
    height: int
    progressive: bool
    blocks: int
    """8x8 blocks of all components together (each component at its own sampling)."""
    scan_bytes: int
    """Bytes of entropy-coded data in all scans (stuffed bytes and RSTn markers included)."""


def _read_jpeg_structure(data: bytes, label: str, *, headers_only: bool = False) -> _JpegStructure:
    """Walk a JPEG's markers from SOI to EOI in pure Python, without decoding anything.

    With ``headers_only`` the walk stops at the first scan (SOS): every byte after it counts
    as entropy-coded data (an upper bound, so :func:`_check_jpeg_data` still refuses only
    files too short for their size), and nothing after it is checked. That costs one step per
    header segment, where skipping the scans costs a search of every byte (half a second for
    32 MB of stuffed ``0xFF00`` bytes): the header-only check of :func:`image_header`.

    Segments are skipped by their length fields; the entropy-coded data after each SOS is
    skipped to the next marker that is not a stuffed ``0xFF00`` or an RSTn (a regular
    expression search, so the cost is a scan of the bytes at C speed). The work is
    proportional to the header sizes plus one pass over the data.

    Refused: a marker where one must be, a segment running past the end, more than
    :data:`_MAX_JPEG_SEGMENTS` segments or :data:`_MAX_JPEG_SCANS` scans, no frame header
    (SOF) or more than one, a frame type other than Huffman-coded baseline, extended
    sequential or progressive (lossless, hierarchical and arithmetic-coded JPEGs: libjpeg's
    own support for them is partial, no browser shows them, and the size check of
    :func:`_check_jpeg_data` is not sound for arithmetic coding, which can spend less than a
    bit on a block), a scan before the frame header, no scan, and a file that ends before EOI.

    Data after EOI is accepted and never read: phones put whole second images there (Ultra
    HDR and Apple gain maps, MPF previews) or a video (motion photos), and neither Pillow nor
    libjpeg looks past EOI, so it costs no decoding; the request body limit bounds its size.
    """
    size = len(data)
    pos = 2  # after SOI, which image_format has recognised
    segments = 0
    scans = 0
    scan_bytes = 0
    frame: tuple[int, int, bool, int] | None = None
    while True:
        if pos >= size:
            raise ImageDecodeError(
                f"{label}: truncated JPEG: the file ends before its end-of-image (EOI) marker"
            )
        if data[pos] != 0xFF:
            raise ImageDecodeError(
                f"{label}: corrupt JPEG: a marker was expected at byte {pos:,} and is not there"
            )
        while pos < size and data[pos] == 0xFF:  # a marker may be preceded by fill bytes
            pos += 1
        if pos >= size:
            continue  # reported as truncated above
        marker = data[pos]
        pos += 1
        if marker == _EOI:
            break
        if marker in _STANDALONE:
            continue
        segments += 1
        if segments > _MAX_JPEG_SEGMENTS:
            raise ImageDecodeError(
                f"{label}: corrupt JPEG: more than {_MAX_JPEG_SEGMENTS:,} marker segments"
            )
        if marker in (0x00, 0xD8):
            raise ImageDecodeError(
                f"{label}: corrupt JPEG: unexpected marker 0xFF{marker:02X} at byte {pos - 2:,}"
            )
        length = int.from_bytes(data[pos : pos + 2], "big")
        if pos + max(length, 2) > size:
            raise ImageDecodeError(
                f"{label}: truncated JPEG: the file ends inside a marker segment (0xFF{marker:02X})"
            )
        if length < 2:
            raise ImageDecodeError(
                f"{label}: corrupt JPEG: a marker segment (0xFF{marker:02X}) has an invalid "
                f"length {length}"
            )
        body = data[pos + 2 : pos + length]
        pos += length
        if marker in _SOF_OTHER:
            raise ImageDecodeError(
                f"{label}: {_SOF_OTHER[marker]} JPEGs (SOF{marker - 0xC0}) are not supported; "
                "save the image as a baseline or progressive JPEG, or as PNG"
            )
        if marker in _SOF_HUFFMAN:
            if frame is not None:
                raise ImageDecodeError(f"{label}: corrupt JPEG: more than one frame header (SOF)")
            frame = _jpeg_frame(body, marker == _SOF_PROGRESSIVE, label)
        elif marker == _SOS:
            if frame is None:
                raise ImageDecodeError(
                    f"{label}: corrupt JPEG: image data (SOS) before the frame header (SOF)"
                )
            if headers_only:
                scans, scan_bytes = 1, size - pos
                break
            scans += 1
            if scans > _MAX_JPEG_SCANS:
                raise ImageDecodeError(
                    f"{label}: corrupt JPEG: more than {_MAX_JPEG_SCANS} scans (progressive "
                    "passes); no encoder needs that many"
                )
            end = _END_OF_SCAN.search(data, pos)
            if end is None:
                raise ImageDecodeError(
                    f"{label}: truncated JPEG: the file ends inside its image data, before "
                    "the end-of-image (EOI) marker"
                )
            scan_bytes += end.start() - pos
            pos = end.start()
    if frame is None:
        raise ImageDecodeError(f"{label}: corrupt JPEG: no frame header (SOF) before its end")
    if scans == 0:
        raise ImageDecodeError(
            f"{label}: corrupt JPEG: the file has no image data (no SOS scan before EOI)"
        )
    width, height, progressive, blocks = frame
    return _JpegStructure(width, height, progressive, blocks, scan_bytes)


def _jpeg_frame(body: bytes, progressive: bool, label: str) -> tuple[int, int, bool, int]:
    """Width, height, progressive and the 8x8 block count from an SOF segment's body."""
    if len(body) < 6:
        raise ImageDecodeError(f"{label}: corrupt JPEG: short frame header (SOF)")
    height, width, count = struct.unpack(">HHB", body[1:6])
    if len(body) < 6 + 3 * count or not 1 <= count <= 4:
        raise ImageDecodeError(
            f"{label}: corrupt JPEG: the frame header declares {count} colour components "
            "(1 to 4 are supported)"
        )
    if width == 0 or height == 0:
        # Height 0 means "given later by a DNL marker", which libjpeg does not support.
        raise ImageDecodeError(f"{label}: corrupt JPEG: invalid size {width}x{height}")
    sampling = [(body[7 + 3 * i] >> 4, body[7 + 3 * i] & 0x0F) for i in range(count)]
    if any(not (1 <= h <= 4 and 1 <= v <= 4) for h, v in sampling):
        raise ImageDecodeError(f"{label}: corrupt JPEG: invalid sampling factors {sampling}")
    h_max = max(h for h, _ in sampling)
    v_max = max(v for _, v in sampling)
    blocks = 0
    for h, v in sampling:
        # A component's size is the image's scaled by its sampling (rounded up); a scan codes
        # at least every block that covers it (interleaved scans code MCU padding on top).
        component_width = -(-width * h // h_max)
        component_height = -(-height * v // v_max)
        blocks += -(-component_width // 8) * -(-component_height // 8)
    return width, height, progressive, blocks


def _check_jpeg_data(structure: _JpegStructure, label: str) -> None:
    """Refuse a JPEG whose entropy-coded data is too short to fill its declared size.

    libjpeg fills what a truncated or patched file lacks with grey (a warning Pillow ignores),
    so a 10 KB file whose frame header claims 4999x4999 would decode to 25 M pixels. A lower
    bound on the coded size of a complete image rules that out without decoding anything:

    - sequential (SOF0, SOF1): every 8x8 block of every component is coded once, as a DC
      difference (a Huffman code of at least 1 bit) and then either an end-of-block code or
      the code of a coefficient (at least 1 bit more): at least 2 bits a block;
    - progressive (SOF2): every component's DC coefficients come first, in a DC scan that
      spends a Huffman code (at least 1 bit) on every block: at least 1 bit a block.

    The coded bytes counted include stuffed zero bytes, RSTn markers and padding, which only
    makes the count larger, so no complete file is refused. The bound is tight: a flat image
    coded with one-bit codes sits right on it. It does not catch every damaged file (one that
    lost a few rows still passes), only ones that would decode to far more than they hold.
    """
    bits = 1 if structure.progressive else 2
    needed = -(-structure.blocks * bits // 8)
    if structure.scan_bytes < needed:
        raise ImageDecodeError(
            f"{label}: truncated or corrupt JPEG: it declares {structure.width}x"
            f"{structure.height} pixels ({structure.blocks:,} blocks of 8x8), which take at "
            f"least {needed:,} bytes of image data, but it holds only {structure.scan_bytes:,}"
        )


def _exif_orientation(im: Image.Image) -> int:
    """The EXIF orientation tag (1..8), or 1 when it is absent or unreadable."""
    try:
        value = im.getexif().get(_EXIF_ORIENTATION, 1)
    except (*_DECODE_FAILURES, TypeError):
        # Broken EXIF is metadata damage, not image damage: show the pixels as stored.
        return 1
    return value if isinstance(value, int) and 1 <= value <= 8 else 1


def _orient(array: ImageArray, orientation: int) -> ImageArray:
    """Apply an EXIF orientation to an (H, W) or (H, W, C) array (same result as Pillow's
    ``ImageOps.exif_transpose``)."""
    match orientation:
        case 2:  # mirrored left-right
            array = array[:, ::-1]
        case 3:  # rotated 180
            array = array[::-1, ::-1]
        case 4:  # mirrored top-bottom
            array = array[::-1]
        case 5:  # transposed
            array = array.swapaxes(0, 1)
        case 6:  # stored rotated 90 counter-clockwise: turn 90 clockwise
            array = array.swapaxes(0, 1)[:, ::-1]
        case 7:  # transversed
            array = array.swapaxes(0, 1)[::-1, ::-1]
        case 8:  # stored rotated 90 clockwise: turn 90 counter-clockwise
            array = array.swapaxes(0, 1)[::-1]
        case _:
            return array
    return np.ascontiguousarray(array)


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------


def encode_png(
    image: ImageArray,
    *,
    metadata: Mapping[str, Any] | None = None,
    compress_level: int = 6,
) -> bytes:
    """Encode an image array as PNG bytes, keeping its bit depth and alpha.

    Parameters
    ----------
    image : numpy.ndarray
        (H, W) or (H, W, 1) gray, (H, W, 3) RGB or (H, W, 4) RGBA, H and W at least 1.
        ``uint8`` is written as an 8-bit PNG and ``uint16`` as a 16-bit PNG. ``float32`` and
        ``float64`` must be finite; they are clipped to [0, 1] and written as 16-bit samples
        ``round(x * 65535)`` (computed in float64, ties to even).
    metadata : Mapping[str, Any], optional
        JSON-serialisable object, stored as ``json.dumps(metadata, sort_keys=True)`` in a tEXt
        chunk with the key ``"quilting"`` (see :func:`read_image_metadata`).
    compress_level : int, optional
        zlib level 0 (none, fastest) .. 9 (smallest); default 6.

    Returns
    -------
    bytes
        A complete PNG file. Each row is filtered None, Sub or Up (whichever suits it,
        :func:`quilting.png.filter_rows`), which read back with running sums only.

    Raises
    ------
    InvalidImageError
        Wrong type, dimension count, channel count or dtype, no pixels, or NaN/inf values.
    InvalidParameterError
        ``metadata`` is not a JSON-serialisable mapping or ``compress_level`` is not 0..9.
    """
    samples, color_type, depth = png_samples(image)
    if isinstance(compress_level, bool) or not isinstance(compress_level, int | np.integer):
        raise InvalidParameterError("compress_level", compress_level, "an integer 0..9")
    if not 0 <= compress_level <= 9:
        raise InvalidParameterError("compress_level", compress_level, "an integer 0..9")
    text = metadata_text(metadata)
    return assemble_png(samples, color_type, depth, text=text, compress_level=int(compress_level))


#: The formats :func:`write_image` writes, by file-name extension (lower case).
WRITE_FORMATS: Final[Mapping[str, str]] = {
    ".png": "png",
    ".jpg": "jpeg",
    ".jpeg": "jpeg",
    ".webp": "webp",
}
#: Quality of the lossy formats: high enough that quilting seams are not hidden by artefacts.
LOSSY_QUALITY: Final = 95
_PILLOW_FORMATS: Final = {"jpeg": "JPEG", "webp": "WEBP"}
_FORMAT_NAMES: Final = {"png": "PNG", "jpeg": "JPEG", "webp": "WebP"}


def output_format(path: str | os.PathLike[str]) -> str:
    """The format a file name asks for: ``'png'``, ``'jpeg'`` or ``'webp'``.

    Parameters
    ----------
    path : str or os.PathLike
        A file name; only its extension is read (case does not matter).

    Raises
    ------
    InvalidParameterError
        The extension is none of ``.png``, ``.jpg``, ``.jpeg``, ``.webp``; the message names
        the file and the formats.
    """
    suffix = os.path.splitext(os.fspath(path))[1].lower()
    found = WRITE_FORMATS.get(suffix)
    if found is None:
        raise InvalidParameterError(
            "output",
            os.fspath(path),
            "a file name ending in " + ", ".join(WRITE_FORMATS),
            f"the extension {suffix!r} names no format quilting writes"
            if suffix
            else "the file name has no extension to choose the format by",
        )
    return found


def check_writable(path: str | os.PathLike[str], dtype: np.dtype[Any], channels: int) -> str:
    """The format of ``path``, once sure that an image of ``dtype`` and ``channels`` fits it.

    Lets a caller refuse an output name before any work (the command line checks it before
    synthesis), with the same rule :func:`write_image` applies.

    Parameters
    ----------
    path : str or os.PathLike
        The output file name.
    dtype : numpy.dtype
        The image's dtype: uint8 fits every format; uint16 and floats need PNG's 16 bits.
    channels : int
        1 (gray), 3 (RGB) or 4 (RGBA): alpha needs PNG (JPEG has none, and WebP's lossy
        alpha would not keep the values quilting computed).

    Returns
    -------
    str
        ``'png'``, ``'jpeg'`` or ``'webp'``.

    Raises
    ------
    InvalidParameterError
        Unknown extension, or an image the format cannot hold; the message says to use .png.
    """
    fmt = output_format(path)
    if fmt == "png":
        return fmt
    name = _FORMAT_NAMES[fmt]
    problem = ""
    if np.dtype(dtype) != np.uint8:
        kind = "16-bit" if np.dtype(dtype) == np.uint16 else f"{np.dtype(dtype)}"
        problem = f"a {kind} image needs more than the 8 bits {name} holds"
    elif channels == 4:
        problem = f"the image has an alpha channel, which quilting keeps in PNG only, not {name}"
    if problem:
        raise InvalidParameterError(
            "output", os.fspath(path), "a .png file name for this image", problem
        )
    return fmt


def encode_image(
    image: ImageArray,
    fmt: str,
    *,
    metadata: Mapping[str, Any] | None = None,
) -> bytes:
    """Encode an image array in ``fmt`` (``'png'``, ``'jpeg'`` or ``'webp'``).

    Parameters
    ----------
    image : numpy.ndarray
        (H, W), (H, W, 1), (H, W, 3) or (H, W, 4), as for :func:`encode_png`. JPEG and WebP
        take uint8 gray or RGB only (see :func:`check_writable`).
    fmt : str
        A value of :data:`WRITE_FORMATS`. The lossy formats are written at quality
        :data:`LOSSY_QUALITY`.
    metadata : Mapping[str, Any], optional
        Stored in a PNG only (JPEG and WebP files carry none).

    Returns
    -------
    bytes
        The complete file.
    """
    if fmt == "png":
        return encode_png(image, metadata=metadata)
    samples, _, depth = png_samples(image)
    if depth != 8 or samples.shape[2] == 4:
        raise InvalidParameterError(
            "format", fmt, "'png' for 16-bit, float or RGBA images", "8-bit gray or RGB only"
        )
    metadata_text(metadata)  # the same check of metadata as PNG, though it is not stored
    pixels = samples[:, :, 0] if samples.shape[2] == 1 else samples
    buffer = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(pixels)).save(
        buffer, format=_PILLOW_FORMATS[fmt], quality=LOSSY_QUALITY
    )
    return buffer.getvalue()


def write_image(
    path: str | os.PathLike[str],
    image: ImageArray,
    *,
    metadata: Mapping[str, Any] | None = None,
) -> None:
    """Write an image array to ``path`` in the format its extension names.

    ``.png`` writes PNG (8 or 16 bits, alpha and metadata kept), ``.jpg``/``.jpeg`` JPEG and
    ``.webp`` WebP (8-bit gray or RGB, quality :data:`LOSSY_QUALITY`, no metadata). Any other
    extension, or an image the format cannot hold, is refused before the file is touched.

    Parameters
    ----------
    path : str or os.PathLike
        Destination file; replaced if it exists.
    image : numpy.ndarray
        (H, W), (H, W, 1), (H, W, 3) or (H, W, 4); uint8, uint16, float32 or float64, as for
        :func:`encode_png`.
    metadata : Mapping[str, Any], optional
        JSON object stored in the file (see :func:`encode_png`).

    Raises
    ------
    InvalidImageError, InvalidParameterError
        As :func:`encode_png`; also an unknown extension, or a 16-bit, float or RGBA image
        given a JPEG or WebP name (see :func:`check_writable`).
    QuiltingError
        The file cannot be written; the message names it and says why.
    """
    if isinstance(image, np.ndarray):
        fmt = check_writable(path, image.dtype, image.shape[2] if image.ndim == 3 else 1)
    else:  # encode_image says what is wrong with it
        fmt = output_format(path)
    data = encode_image(image, fmt, metadata=metadata)
    try:
        with open(path, "wb") as fp:
            fp.write(data)
    except OSError as exc:
        raise QuiltingError(f"cannot write '{os.fspath(path)!s}': {exc.strerror or exc}") from exc
