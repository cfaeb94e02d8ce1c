"""Image files in and out: the only module of quilting that imports Pillow.

:func:`read_image` turns PNG and JPEG files (recognised by their first bytes, never by their
name) into numpy arrays at their native bit depth, and refuses an image whose header declares
more pixels than a limit before a single pixel is decoded. :func:`encode_png` and
:func:`write_image` write 8- or 16-bit PNGs with an optional JSON metadata object, which
:func:`read_image_metadata` reads back.

Pillow decodes 8-bit (and lower) PNGs and all JPEGs. It cannot do everything this module
needs, so two parts are done here with numpy and the standard library:

- Pillow decodes 16-bit RGB, RGBA and gray+alpha PNGs to 8 bits per channel (it keeps the high
  byte and drops the low one), so every 16-bit PNG is decoded here: zlib, then the per-row
  filters undone in numpy (Adam7 interlacing included).
- Pillow cannot write 16-bit colour PNGs, so every PNG is written here: signature, IHDR, one
  tEXt chunk for the metadata, IDAT (filter type 0 on every row), IEND.

Every failure to read comes out as :class:`~quilting.core.errors.ImageDecodeError` or
:class:`~quilting.core.errors.ImageTooLargeError` with the file named in the message, never as
a raw Pillow, zlib or OS error.
"""

from __future__ import annotations

import io
import json
import os
import reprlib
import struct
import zlib
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import IO, Any, Final

import numpy as np
import numpy.typing as npt
from PIL import Image, JpegImagePlugin, PngImagePlugin

from quilting.core.errors import (
    ImageDecodeError,
    ImageTooLargeError,
    InvalidImageError,
    InvalidParameterError,
    QuiltingError,
)

__all__ = [
    "DEFAULT_MAX_PIXELS",
    "encode_png",
    "read_image",
    "read_image_metadata",
    "write_image",
]

DEFAULT_MAX_PIXELS: int = 100_000_000
"""Largest image (width * height) :func:`read_image` decodes unless told otherwise."""

_PNG_SIGNATURE: Final = b"\x89PNG\r\n\x1a\n"
_JPEG_SIGNATURE: Final = b"\xff\xd8\xff"
_METADATA_KEY: Final = "quilting"
# Large enough that chunk overhead is nil, small enough for every decoder's buffers.
_IDAT_CHUNK_BYTES: Final = 1 << 20
# A compressed text chunk may not inflate past this: metadata is small, a zlib bomb is not.
_MAX_TEXT_BYTES: Final = 64 << 20
_MAX_PNG_CHUNK: Final = 0x7FFF_FFFF

# Bit depths the PNG specification allows for each colour type, and samples per pixel.
_PNG_DEPTHS: Final[dict[int, tuple[int, ...]]] = {
    0: (1, 2, 4, 8, 16),
    2: (8, 16),
    3: (1, 2, 4, 8),
    4: (8, 16),
    6: (8, 16),
}
_PNG_CHANNELS: Final[dict[int, int]] = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}

# (first row, first column, row step, column step) of the seven Adam7 passes.
_ADAM7: Final = (
    (0, 0, 8, 8),
    (0, 4, 8, 8),
    (4, 0, 8, 4),
    (0, 2, 4, 4),
    (2, 0, 4, 2),
    (0, 1, 2, 2),
    (1, 0, 2, 1),
)

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

ImageArray = npt.NDArray[Any]
"""A decoded image: uint8 or uint16, shaped (H, W), (H, W, 3) or (H, W, 4)."""


@dataclass(frozen=True)
class _PngHeader:
    """The fields of an IHDR chunk that decoding needs."""

    width: int
    height: int
    bit_depth: int
    color_type: int
    interlaced: bool


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
        head = fp.read(len(_PNG_SIGNATURE))
        fp.seek(0)
        if head.startswith(_PNG_SIGNATURE):
            return _decode_png(fp, label, int(max_pixels))
        if head.startswith(_JPEG_SIGNATURE):
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
        head = fp.read(len(_PNG_SIGNATURE))
        fp.seek(0)
        if head.startswith(_PNG_SIGNATURE):
            return _png_metadata(fp, label)
        if head.startswith(_JPEG_SIGNATURE):
            return {}
        raise ImageDecodeError(_unsupported_message(fp, label))


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


def _read_png_header(fp: IO[bytes], label: str) -> _PngHeader:
    """Read and validate the signature and the IHDR chunk (the first 33 bytes)."""
    head = fp.read(33)
    if len(head) < 33:
        raise ImageDecodeError(f"{label}: truncated PNG: the file ends inside its header")
    length, ctype = struct.unpack(">I4s", head[8:16])
    if ctype != b"IHDR" or length != 13:
        raise ImageDecodeError(f"{label}: corrupt PNG: the first chunk is not a 13-byte IHDR")
    if zlib.crc32(head[12:29]) != int.from_bytes(head[29:33], "big"):
        raise ImageDecodeError(f"{label}: corrupt PNG: checksum mismatch in the IHDR chunk")
    width, height, depth, color_type, compression, filtering, interlace = struct.unpack(
        ">IIBBBBB", head[16:29]
    )
    if not (0 < width <= _MAX_PNG_CHUNK and 0 < height <= _MAX_PNG_CHUNK):
        raise ImageDecodeError(f"{label}: corrupt PNG: invalid size {width}x{height}")
    if depth not in _PNG_DEPTHS.get(color_type, ()):
        raise ImageDecodeError(
            f"{label}: corrupt PNG: colour type {color_type} with bit depth {depth} "
            "is not a valid combination"
        )
    if compression != 0 or filtering != 0 or interlace not in (0, 1):
        raise ImageDecodeError(
            f"{label}: corrupt PNG: unknown compression, filter or interlace method "
            f"({compression}, {filtering}, {interlace})"
        )
    return _PngHeader(width, height, depth, color_type, interlace == 1)


def _iter_png_chunks(
    fp: IO[bytes], label: str, skip: frozenset[bytes] = frozenset()
) -> Iterator[tuple[bytes, bytes]]:
    """Yield ``(type, data)`` for every chunk up to and including IEND, CRCs checked.

    Chunks whose type is in ``skip`` are seeked over and yielded with empty data.
    """
    fp.seek(len(_PNG_SIGNATURE))
    while True:
        head = fp.read(8)
        if len(head) < 8:
            raise ImageDecodeError(f"{label}: truncated PNG: the file ends before its IEND chunk")
        length, ctype = struct.unpack(">I4s", head)
        if length > _MAX_PNG_CHUNK or not ctype.isalpha():
            raise ImageDecodeError(f"{label}: corrupt PNG: invalid chunk header {head!r}")
        if ctype in skip:
            fp.seek(length + 4, io.SEEK_CUR)
            yield ctype, b""
            continue
        data = fp.read(length)
        crc = fp.read(4)
        if len(data) < length or len(crc) < 4:
            raise ImageDecodeError(
                f"{label}: truncated PNG: the file ends inside a chunk of type "
                f"{ctype.decode('ascii')}"
            )
        if zlib.crc32(data, zlib.crc32(ctype)) != int.from_bytes(crc, "big"):
            raise ImageDecodeError(
                f"{label}: corrupt PNG: checksum mismatch in a chunk of type "
                f"{ctype.decode('ascii')}"
            )
        yield ctype, data
        if ctype == b"IEND":
            return


def _decode_png(fp: IO[bytes], label: str, max_pixels: int) -> ImageArray:
    header = _read_png_header(fp, label)
    _check_pixels(header.width, header.height, max_pixels, label)
    fp.seek(0)
    if header.bit_depth == 16:
        return _decode_png16(fp, header, label)
    # Pillow stops reading once the zlib stream ends and never checks IDAT checksums, so a
    # file cut after its image data, or with damaged IDAT bytes that still inflate, would
    # pass. One cheap pass over the chunk structure makes it as strict as the 16-bit path.
    for _ in _iter_png_chunks(fp, label):
        pass
    fp.seek(0)
    return _decode_png_pillow(fp, header, label)


def _decode_png_pillow(fp: IO[bytes], header: _PngHeader, label: str) -> ImageArray:
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
            return _key_to_rgba(gray[..., None].repeat(3, axis=2), gray == key, 255)
        if im.mode == "RGB":
            rgb = _pixels(im)
            if transparency is None:
                return rgb
            matches = np.all(rgb == np.asarray(transparency, dtype=np.int64), axis=-1)
            return _key_to_rgba(rgb, matches, 255)
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


def _key_to_rgba(rgb: ImageArray, transparent: npt.NDArray[np.bool_], opaque: int) -> ImageArray:
    """Stack RGB (H, W, 3) with an alpha that is 0 where ``transparent`` and ``opaque`` else."""
    alpha = np.where(transparent, 0, opaque).astype(rgb.dtype)
    return np.concatenate([rgb, alpha[..., None]], axis=2)


def _decode_png16(fp: IO[bytes], header: _PngHeader, label: str) -> ImageArray:
    """Decode a 16-bit PNG (any colour type, interlaced or not) to uint16."""
    channels = _PNG_CHANNELS[header.color_type]
    bpp = 2 * channels
    if header.interlaced:
        passes = [
            (r0, c0, dr, dc, -(-(header.height - r0) // dr), -(-(header.width - c0) // dc))
            for r0, c0, dr, dc in _ADAM7
            if header.height > r0 and header.width > c0
        ]
    else:
        passes = [(0, 0, 1, 1, header.height, header.width)]
    expected = sum(h * (1 + w * bpp) for *_, h, w in passes)

    inflater = zlib.decompressobj()
    inflated = bytearray()
    trns: bytes | None = None
    for ctype, data in _iter_png_chunks(fp, label):
        if ctype == b"IDAT" and len(inflated) < expected:
            # Bounded output: data past what the header announces is never inflated.
            inflated += inflater.decompress(data, expected - len(inflated))
        elif ctype == b"tRNS":
            trns = data
    if len(inflated) < expected:
        raise ImageDecodeError(
            f"{label}: corrupt or truncated PNG: its image data holds {len(inflated):,} of the "
            f"{expected:,} bytes the header announces"
        )

    stream = np.frombuffer(inflated, dtype=np.uint8)
    samples = np.empty((header.height, header.width, bpp), dtype=np.uint8)
    offset = 0
    for r0, c0, dr, dc, h, w in passes:
        size = h * (1 + w * bpp)
        rows = stream[offset : offset + size].reshape(h, 1 + w * bpp)
        samples[r0::dr, c0::dc] = _unfilter(rows, w, bpp, label)
        offset += size
    values = samples.view(">u2").astype(np.uint16)  # (H, W, channels), native byte order

    if header.color_type == 4:
        gray = values[..., :1].repeat(3, axis=2)
        return np.concatenate([gray, values[..., 1:]], axis=2)
    if header.color_type == 0:
        gray = values[..., 0]
        if trns is None or len(trns) < 2:
            return gray
        key = int.from_bytes(trns[:2], "big")
        return _key_to_rgba(values.repeat(3, axis=2), gray == key, 0xFFFF)
    if header.color_type == 2 and trns is not None and len(trns) >= 6:
        key3 = np.frombuffer(trns[:6], dtype=">u2").astype(np.uint16)
        return _key_to_rgba(values, np.all(values == key3, axis=-1), 0xFFFF)
    return values


def _unfilter(rows: npt.NDArray[np.uint8], width: int, bpp: int, label: str) -> ImageArray:
    """Undo the PNG row filters of one (sub-)image.

    Parameters
    ----------
    rows : numpy.ndarray
        (h, 1 + width * bpp) uint8: each row's filter type byte, then its filtered bytes.
    width : int
        Pixels per row.
    bpp : int
        Bytes per pixel (the distance a filter looks back to the left).

    Returns
    -------
    numpy.ndarray
        (h, width, bpp) uint8, the raw sample bytes.
    """
    ftype = rows[:, 0]
    worst = int(ftype.max(initial=0))
    if worst > 4:
        raise ImageDecodeError(f"{label}: corrupt PNG: unknown row filter type {worst}")
    data = rows[:, 1:].reshape(len(rows), width, bpp)
    if worst == 0:
        return data
    if worst <= 2:
        return _unfilter_sub_up(data, ftype)
    return _unfilter_wavefront(data, ftype)


def _unfilter_sub_up(data: npt.NDArray[np.uint8], ftype: npt.NDArray[np.uint8]) -> ImageArray:
    """Undo filters None (0), Sub (1) and Up (2) with whole-array operations.

    Sub is a running sum along each row; a run of Up rows is a running sum down the columns
    that restarts at every row that is not Up. uint8 sums wrap modulo 256 as PNG requires.
    """
    out = data.copy()
    sub = ftype == 1
    out[sub] = np.cumsum(data[sub], axis=1, dtype=np.uint8)
    # out now holds final rows for None/Sub rows and filtered bytes for Up rows.
    total = np.cumsum(out, axis=0, dtype=np.uint8)
    rows = np.arange(len(ftype))
    # For every row, the last row at or above it that is not Up (-1 when there is none).
    start: npt.NDArray[np.intp] = np.maximum.accumulate(np.where(ftype != 2, rows, -1))
    before = np.concatenate([np.zeros_like(total[:1]), total])  # before[i] = sum of rows < i
    base: npt.NDArray[np.uint8] = before[np.maximum(start, 0)]
    return total - base


def _unfilter_wavefront(data: npt.NDArray[np.uint8], ftype: npt.NDArray[np.uint8]) -> ImageArray:
    """Undo any mix of the five filters, one anti-diagonal of pixels at a time.

    Average and Paeth make every pixel depend on its left, upper and upper-left neighbours
    after reconstruction, so no row can be done in one vector operation. The pixels of one
    anti-diagonal (row + column constant) depend only on the two diagonals before it, so
    height + width - 1 vectorised steps do the whole image. In a zero-padded copy flattened to
    (pixels, bpp) a diagonal is a strided slice (step = width), so no index arrays are built.
    """
    h, w, bpp = data.shape
    stride = w + 1  # padded row length: a zero column on the left and a zero row on top
    padded = np.zeros((h + 1, stride, bpp), dtype=np.uint8)
    padded[1:, 1:] = data
    flat = padded.reshape(-1, bpp)
    kinds = ftype.astype(np.int16)[:, None]
    for d in range(h + w - 1):
        r0 = max(0, d - w + 1)
        n = min(h - 1, d) - r0 + 1
        start = (r0 + 1) * stride + (d - r0 + 1)
        diagonal = slice(start, start + (n - 1) * w + 1, w)
        filtered = flat[diagonal].astype(np.int16)
        a = _shifted(flat, diagonal, 1)
        b = _shifted(flat, diagonal, stride)
        c = _shifted(flat, diagonal, stride + 1)
        kind = kinds[r0 : r0 + n]
        pa, pb, pc = np.abs(b - c), np.abs(a - c), np.abs(a + b - 2 * c)
        paeth = np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))
        predicted = np.select(
            [kind == 1, kind == 2, kind == 3, kind == 4], [a, b, (a + b) >> 1, paeth], 0
        )
        flat[diagonal] = (filtered + predicted) & 0xFF
    return padded[1:, 1:]


def _shifted(flat: npt.NDArray[np.uint8], diagonal: slice, back: int) -> npt.NDArray[np.int16]:
    """The pixels ``back`` places before those of ``diagonal`` in ``flat``, as int16."""
    return flat[diagonal.start - back : diagonal.stop - back : diagonal.step].astype(np.int16)


def _png_metadata(fp: IO[bytes], label: str) -> dict[str, Any]:
    _read_png_header(fp, label)
    key = _METADATA_KEY.encode("latin-1")
    for ctype, data in _iter_png_chunks(fp, label, skip=frozenset({b"IDAT"})):
        if ctype not in (b"tEXt", b"zTXt", b"iTXt"):
            continue
        keyword, _, body = data.partition(b"\x00")
        if keyword != key:
            continue
        text = _text_chunk_value(ctype, body, label)
        try:
            value = json.loads(text)
        except ValueError as exc:
            raise ImageDecodeError(
                f"{label}: the '{_METADATA_KEY}' metadata is not valid JSON ({exc})"
            ) from exc
        if not isinstance(value, dict):
            raise ImageDecodeError(
                f"{label}: the '{_METADATA_KEY}' metadata is a JSON "
                f"{type(value).__name__}, not an object"
            )
        return value
    return {}


def _text_chunk_value(ctype: bytes, body: bytes, label: str) -> str:
    """The text of a tEXt, zTXt or iTXt chunk, given what follows its keyword's NUL."""
    if ctype == b"tEXt":
        return body.decode("latin-1")
    if ctype == b"zTXt":
        if not body:
            raise ImageDecodeError(f"{label}: corrupt PNG: empty zTXt chunk")
        return _inflate_text(body[1:], label).decode("latin-1")
    if len(body) < 2:
        raise ImageDecodeError(f"{label}: corrupt PNG: short iTXt chunk")
    compressed = body[0] == 1
    _language, _, rest = body[2:].partition(b"\x00")
    _translated, _, text = rest.partition(b"\x00")
    return (_inflate_text(text, label) if compressed else text).decode("utf-8")


def _inflate_text(data: bytes, label: str) -> bytes:
    inflater = zlib.decompressobj()
    text = inflater.decompress(data, _MAX_TEXT_BYTES)
    if inflater.unconsumed_tail:
        raise ImageDecodeError(
            f"{label}: a compressed PNG text chunk inflates past {_MAX_TEXT_BYTES:,} bytes"
        )
    return text


# --- JPEG -------------------------------------------------------------------------------------


def _decode_jpeg(fp: IO[bytes], label: str, max_pixels: int) -> ImageArray:
    """Decode a JPEG to uint8 gray or RGB, upright according to its EXIF orientation.

    The plugin class is used directly (not ``Image.open``) so that Pillow's global
    decompression-bomb check does not pre-empt ``max_pixels``; constructing it reads the
    header only.
    """
    with JpegImagePlugin.JpegImageFile(fp) as im:
        width, height = im.size
        _check_pixels(width, height, max_pixels, label)
        orientation = _exif_orientation(im)
        array = _pixels(im if im.mode in ("L", "RGB") else im.convert("RGB"))
    return _orient(array, orientation)


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
        A complete PNG file. Every row uses filter type 0, so it reads back without any
        per-pixel reconstruction.

    Raises
    ------
    InvalidImageError
        Wrong type, dimension count, channel count or dtype, no pixels, or NaN/inf values.
    InvalidParameterError
        ``metadata`` is not a JSON-serialisable mapping or ``compress_level`` is not 0..9.
    """
    samples, color_type, depth = _png_samples(image)
    if isinstance(compress_level, bool) or not isinstance(compress_level, int | np.integer):
        raise InvalidParameterError("compress_level", compress_level, "an integer 0..9")
    if not 0 <= compress_level <= 9:
        raise InvalidParameterError("compress_level", compress_level, "an integer 0..9")
    text = _metadata_text(metadata)

    height, width = samples.shape[:2]
    row_bytes = samples[0].nbytes
    rows = np.zeros((height, 1 + row_bytes), dtype=np.uint8)  # column 0: filter type 0
    rows[:, 1:] = samples.reshape(height, -1).view(np.uint8)
    compressed = zlib.compress(rows.data, int(compress_level))

    ihdr = struct.pack(">IIBBBBB", width, height, depth, color_type, 0, 0, 0)
    parts = [_PNG_SIGNATURE, _png_chunk(b"IHDR", ihdr)]
    if text is not None:
        parts.append(_png_chunk(b"tEXt", _METADATA_KEY.encode("latin-1") + b"\x00" + text))
    parts.extend(
        _png_chunk(b"IDAT", compressed[i : i + _IDAT_CHUNK_BYTES])
        for i in range(0, len(compressed), _IDAT_CHUNK_BYTES)
    )
    parts.append(_png_chunk(b"IEND", b""))
    return b"".join(parts)


def write_image(
    path: str | os.PathLike[str],
    image: ImageArray,
    *,
    metadata: Mapping[str, Any] | None = None,
) -> None:
    """Write an image array to ``path`` as PNG (whatever the file name's extension).

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
        As :func:`encode_png`.
    QuiltingError
        The file cannot be written; the message names it and says why.
    """
    data = encode_png(image, metadata=metadata)
    try:
        with open(path, "wb") as fp:
            fp.write(data)
    except OSError as exc:
        raise QuiltingError(f"cannot write '{os.fspath(path)!s}': {exc.strerror or exc}") from exc


_ACCEPTED_SHAPES: Final = "(H, W), (H, W, 1), (H, W, 3) or (H, W, 4)"
_ACCEPTED_DTYPES: Final = "uint8, uint16, float32 or float64"


def _png_samples(image: ImageArray) -> tuple[ImageArray, int, int]:
    """Validate ``image``; return (H, W, C) big-endian samples, PNG colour type and depth."""
    if not isinstance(image, np.ndarray):
        raise InvalidImageError(
            f"image must be a numpy array of shape {_ACCEPTED_SHAPES}, got {type(image).__name__}"
        )
    shape = image.shape  # as given, for messages
    if image.ndim == 2:
        image = image[:, :, None]
    elif image.ndim != 3 or image.shape[2] not in (1, 3, 4):
        raise InvalidImageError(
            f"image of shape {image.shape} is not accepted: expected {_ACCEPTED_SHAPES}"
        )
    if image.shape[0] == 0 or image.shape[1] == 0:
        raise InvalidImageError(
            f"image of shape {shape} has no pixels: height and width must be at least 1"
        )
    if max(image.shape[:2]) > _MAX_PNG_CHUNK:
        raise InvalidImageError(f"image of shape {shape} is too large for PNG")
    dtype = image.dtype
    if dtype.kind == "u" and dtype.itemsize == 1:
        samples: ImageArray = np.ascontiguousarray(image, dtype=np.uint8)
        depth = 8
    elif dtype.kind == "u" and dtype.itemsize == 2:
        samples = np.ascontiguousarray(image, dtype=">u2")
        depth = 16
    elif dtype.kind == "f" and dtype.itemsize in (4, 8):
        if not np.isfinite(image).all():
            raise InvalidImageError(
                f"image ({dtype}, shape {shape}) contains NaN or infinite values; "
                "float images must be finite (they are clipped to [0, 1])"
            )
        scaled = np.rint(np.clip(image.astype(np.float64), 0.0, 1.0) * 65535.0)
        samples = np.ascontiguousarray(scaled, dtype=">u2")
        depth = 16
    else:
        raise InvalidImageError(
            f"image dtype {dtype} (shape {shape}) is not accepted: expected {_ACCEPTED_DTYPES}"
        )
    color_type = {1: 0, 3: 2, 4: 6}[image.shape[2]]
    return samples, color_type, depth


def _metadata_text(metadata: Mapping[str, Any] | None) -> bytes | None:
    if metadata is None:
        return None
    if not isinstance(metadata, Mapping):
        raise InvalidParameterError(
            "metadata", reprlib.repr(metadata), "a mapping of JSON-serialisable values or None"
        )
    try:
        # ensure_ascii keeps the text Latin-1 clean, as a tEXt chunk requires.
        text = json.dumps(dict(metadata), sort_keys=True, allow_nan=False, ensure_ascii=True)
    except (TypeError, ValueError) as exc:
        raise InvalidParameterError(
            "metadata",
            reprlib.repr(metadata),
            "a mapping of JSON-serialisable values (finite numbers, str keys)",
            reason=str(exc),
        ) from exc
    return text.encode("ascii")


def _png_chunk(ctype: bytes, data: bytes) -> bytes:
    crc = zlib.crc32(data, zlib.crc32(ctype))
    return struct.pack(">I", len(data)) + ctype + data + struct.pack(">I", crc)
