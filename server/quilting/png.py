"""PNG container and codec pieces the engine needs beyond Pillow: 16-bit colour decoding,
unfiltering, text chunks, the writer.

Standard library and numpy only; :mod:`quilting.io` is the public image API and the only
module that imports Pillow, and it calls these. Two gaps in Pillow are why this module exists:

- Pillow decodes 16-bit RGB, RGBA and gray+alpha PNGs to 8 bits per channel (it keeps the high
  byte and drops the low one), so every 16-bit PNG is decoded here: zlib, then the per-row
  filters undone in numpy (Adam7 interlacing included).
- Pillow cannot write 16-bit colour PNGs, so every PNG is written here: signature, IHDR, one
  tEXt chunk for the metadata, IDAT (each row filtered None, Sub or Up: :func:`filter_rows`), IEND.

The readers also check the chunk structure and every CRC, and read back the JSON metadata
object the writer stores in a text chunk.

Readers take a binary stream and a ``label`` that names the file in error messages, and raise
:class:`~quilting.core.errors.ImageDecodeError` for what they find wrong. What the stream and
zlib raise themselves (``OSError``, ``zlib.error``, ``UnicodeDecodeError``) is passed through
for the caller to wrap, as :mod:`quilting.io` does. The writer raises
:class:`~quilting.core.errors.InvalidImageError` and
:class:`~quilting.core.errors.InvalidParameterError`.
"""

from __future__ import annotations

import io
import json
import reprlib
import struct
import zlib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import IO, Any, Final

import numpy as np
import numpy.typing as npt

from quilting.core.errors import ImageDecodeError, InvalidImageError, InvalidParameterError

__all__ = [
    "PNG_SIGNATURE",
    "ImageArray",
    "PngHeader",
    "PngImageData",
    "assemble_png",
    "decode_png16",
    "inflate_image_data",
    "iter_png_chunks",
    "key_to_rgba",
    "metadata_text",
    "png_metadata",
    "png_samples",
    "read_png_header",
    "read_png_structure",
]

PNG_SIGNATURE: Final = b"\x89PNG\r\n\x1a\n"
"""The eight bytes every PNG file starts with."""
# Keyword of the text chunk holding the JSON metadata object, written and read back here.
_METADATA_KEY: Final = "quilting"
# Large enough that chunk overhead is nil, small enough for every decoder's buffers.
_IDAT_CHUNK_BYTES: Final = 1 << 20
# A compressed text chunk may not inflate past this: metadata is small, a zlib bomb is not.
_MAX_TEXT_BYTES: Final = 64 << 20
# The specification's limit on chunk lengths, image width and image height (2**31 - 1).
_MAX_PNG_CHUNK: Final = 0x7FFF_FFFF
# Every chunk costs a Python-level step here and in Pillow (about 10-30 us), so millions of
# empty chunks make a small file slow to read. A file may hold this many chunks, plus one per
# _BYTES_PER_EXTRA_CHUNK of its size: libpng writes 8 KiB IDATs, so a legitimately large file
# of small chunks still passes, while a 30 MB file of 2.5 million empty chunks does not.
_MAX_PNG_CHUNKS: Final = 10_000
_BYTES_PER_EXTRA_CHUNK: Final = 4096
# Inflate in pieces of at most this many output bytes: a bounded working set whatever the
# stream claims to hold.
_INFLATE_STEP: Final = 1 << 22

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

ImageArray = npt.NDArray[Any]
"""A decoded image: uint8 or uint16, shaped (H, W), (H, W, 3) or (H, W, 4)."""


@dataclass(frozen=True)
class PngHeader:
    """The fields of an IHDR chunk that decoding needs."""

    width: int
    height: int
    bit_depth: int
    color_type: int
    interlaced: bool


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------


def read_png_header(fp: IO[bytes], label: str) -> PngHeader:
    """Read and validate the IHDR chunk that follows the signature (the first 33 bytes).

    Parameters
    ----------
    fp : IO[bytes]
        Binary stream positioned at the start of the file. The signature bytes are skipped,
        not compared: the caller has already recognised the file by them.
    label : str
        Names the file in error messages.

    Returns
    -------
    PngHeader
        Width, height, bit depth, colour type and interlacing, all checked against what the
        specification allows.

    Raises
    ------
    ImageDecodeError
        The header is truncated, its CRC is wrong or a field is invalid.
    """
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
    return PngHeader(width, height, depth, color_type, interlace == 1)


def iter_png_chunks(
    fp: IO[bytes], label: str, skip: frozenset[bytes] = frozenset()
) -> Iterator[tuple[bytes, bytes]]:
    """Yield ``(type, data)`` for every chunk up to and including IEND, CRCs checked.

    Parameters
    ----------
    fp : IO[bytes]
        Seekable binary stream of a PNG file; it is first moved to just past the signature.
    label : str
        Names the file in error messages.
    skip : frozenset of bytes, optional
        Chunk types seeked over without reading or checking their data (yielded with empty
        data), for readers that only need the chunks around them.

    Yields
    ------
    tuple of (bytes, bytes)
        The four-letter chunk type and the chunk's data.

    Raises
    ------
    ImageDecodeError
        A chunk header is invalid, a CRC is wrong, the file ends before IEND, holds bytes
        after IEND, or has more chunks than :func:`max_png_chunks` allows for its size (checked
        as each chunk header is read, before its data is looked at).
    """
    size = fp.seek(0, io.SEEK_END)
    limit = max_png_chunks(size)
    fp.seek(len(PNG_SIGNATURE))
    count = 0
    while True:
        count += 1
        if count > limit:
            raise ImageDecodeError(
                f"{label}: corrupt PNG: the file holds more than {limit:,} chunks, more than "
                f"any image of {size:,} bytes needs ({_MAX_PNG_CHUNKS:,}, plus one per "
                f"{_BYTES_PER_EXTRA_CHUNK:,} bytes of file)"
            )
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
        if ctype == b"IEND":
            # Nothing may follow IEND: junk there is never part of the image, and a file is
            # either a PNG or something else hiding behind one.
            extra = size - fp.tell()
            if extra > 0:
                raise ImageDecodeError(
                    f"{label}: corrupt PNG: {extra:,} bytes of data after the IEND chunk "
                    "that ends the image"
                )
            yield ctype, data
            return
        yield ctype, data


def max_png_chunks(size: int) -> int:
    """How many chunks a PNG file of ``size`` bytes may hold.

    :data:`_MAX_PNG_CHUNKS`, plus one for every :data:`_BYTES_PER_EXTRA_CHUNK` bytes of file,
    so that the cost of walking the chunks stays proportional to the file's size with a small
    constant (at most one chunk per 4 KiB beyond the first 10,000).
    """
    return _MAX_PNG_CHUNKS + size // _BYTES_PER_EXTRA_CHUNK


@dataclass(frozen=True)
class PngImageData:
    """What :func:`read_png_structure` found between IHDR and IEND."""

    idat: list[bytes]
    """The IDAT chunks' data in file order (empty unless asked for)."""
    trns: bytes | None
    """The tRNS chunk's data, ``None`` when there is none."""


def read_png_structure(
    fp: IO[bytes], header: PngHeader, label: str, *, keep_idat: bool, skip_idat: bool = False
) -> PngImageData:
    """Walk every chunk of a PNG, CRCs included, and check how they fit together.

    Beyond what :func:`iter_png_chunks` checks (chunk headers, CRCs, the chunk count, nothing
    after IEND), the image data must be one run of consecutive IDAT chunks, and a palette image
    (colour type 3) must have its PLTE chunk before that run. Nothing is decompressed here.
    With ``skip_idat`` the IDAT chunks are seeked over (their CRCs unchecked), so the walk costs
    one step per chunk, whatever the image data's size: the header-only check of
    :func:`quilting.io.image_header`.

    Parameters
    ----------
    fp : IO[bytes]
        Seekable binary stream of the whole PNG file.
    header : PngHeader
        Its header, from :func:`read_png_header`.
    label : str
        Names the file in error messages.
    keep_idat : bool
        Keep the IDAT chunks' data for :func:`inflate_image_data`.
    skip_idat : bool, optional
        Seek over the IDAT chunks' data without reading it (``keep_idat`` must be False).

    Returns
    -------
    PngImageData
        The IDAT data (when ``keep_idat``) and the tRNS chunk.

    Raises
    ------
    ImageDecodeError
        Any of the above is not so.
    """
    idat: list[bytes] = []
    trns: bytes | None = None
    palette = False
    state = "before"  # of the IDAT run: "before", "inside", "after"
    skip = frozenset({b"IDAT"}) if skip_idat and not keep_idat else frozenset()
    for ctype, data in iter_png_chunks(fp, label, skip):
        if ctype == b"IDAT":
            if state == "after":
                raise ImageDecodeError(
                    f"{label}: corrupt PNG: its IDAT chunks are not consecutive (another "
                    "chunk comes between them)"
                )
            if state == "before" and header.color_type == 3 and not palette:
                raise ImageDecodeError(
                    f"{label}: corrupt PNG: a palette image (colour type 3) without a PLTE "
                    "chunk before its image data"
                )
            state = "inside"
            if keep_idat:
                idat.append(data)
            continue
        if state == "inside":
            state = "after"
        if ctype == b"PLTE":
            palette = True
        elif ctype == b"tRNS":
            trns = data
    if state == "before":
        raise ImageDecodeError(f"{label}: corrupt PNG: the file has no image data (no IDAT)")
    return PngImageData(idat, trns)


def png_data_size(header: PngHeader) -> int:
    """Bytes the image data inflates to: every (sub-)image row's filter byte and samples."""
    bits = header.bit_depth * _PNG_CHANNELS[header.color_type]
    return sum(h * (1 + (w * bits + 7) // 8) for *_, h, w in _passes(header))


def _passes(header: PngHeader) -> list[tuple[int, int, int, int, int, int]]:
    """(first row, first column, row step, column step, rows, columns) of each (sub-)image
    that has pixels: the seven Adam7 passes, or the whole image when not interlaced."""
    if not header.interlaced:
        return [(0, 0, 1, 1, header.height, header.width)]
    return [
        (r0, c0, dr, dc, -(-(header.height - r0) // dr), -(-(header.width - c0) // dc))
        for r0, c0, dr, dc in _ADAM7
        if header.height > r0 and header.width > c0
    ]


def inflate_image_data(
    idat: list[bytes], header: PngHeader, label: str, *, keep: bool = True
) -> bytearray:
    """Inflate the IDAT data, refusing anything but exactly what the header announces.

    The header fixes the decompressed size (:func:`png_data_size`: every row's filter byte
    and samples, per Adam7 pass when interlaced). The stream is inflated with a
    ``max_length`` bound, so that nothing past that size plus one byte is ever produced: a
    zlib bomb costs no more than a well-formed file of the same dimensions.

    Parameters
    ----------
    idat : list of bytes
        The IDAT chunks' data, in file order.
    header : PngHeader
        The file's header.
    label : str
        Names the file in error messages.
    keep : bool, optional
        Return the inflated bytes (default); with False they are counted and dropped, so a
        check costs working memory of one step, not of the image.

    Returns
    -------
    bytearray
        The inflated image data (empty when ``keep`` is False).

    Raises
    ------
    ImageDecodeError
        The data inflates to fewer or more bytes than announced, the zlib stream is not
        complete (it stops before its end and checksum), or bytes follow the stream's end.
        ``zlib.error`` from damaged compressed data is left for the caller to wrap.
    """
    expected = png_data_size(header)
    inflater = zlib.decompressobj()
    out = bytearray()
    produced = 0
    for data in idat:
        if inflater.eof:
            if data:
                raise _after_stream(label)
            continue
        pending = data
        while pending and not inflater.eof:
            # One byte past the announced size is enough to know that the stream is too long
            # (and max_length is never 0, which would mean no bound at all).
            piece = inflater.decompress(pending, min(_INFLATE_STEP, expected + 1 - produced))
            produced += len(piece)
            if produced > expected:
                raise ImageDecodeError(
                    f"{label}: corrupt PNG: its image data inflates to more than the "
                    f"{expected:,} bytes the header announces"
                )
            if keep:
                out += piece
            pending = inflater.unconsumed_tail
        if inflater.unused_data:
            raise _after_stream(label)
    if produced < expected:
        raise ImageDecodeError(
            f"{label}: corrupt or truncated PNG: its image data holds {produced:,} of the "
            f"{expected:,} bytes the header announces"
        )
    if not inflater.eof:
        raise ImageDecodeError(
            f"{label}: corrupt or truncated PNG: its compressed image data stops before the "
            "end of the zlib stream (its checksum is missing)"
        )
    return out


def _after_stream(label: str) -> ImageDecodeError:
    return ImageDecodeError(
        f"{label}: corrupt PNG: its IDAT chunks hold data after the end of the compressed "
        "image stream"
    )


def key_to_rgba(rgb: ImageArray, transparent: npt.NDArray[np.bool_], opaque: int) -> ImageArray:
    """Stack RGB with an alpha that is 0 where ``transparent`` and ``opaque`` elsewhere.

    Parameters
    ----------
    rgb : numpy.ndarray
        (H, W, 3) uint8 or uint16.
    transparent : numpy.ndarray
        (H, W) bool: the pixels that match a tRNS colour key.
    opaque : int
        Alpha of the other pixels: 255 for uint8, 0xFFFF for uint16.

    Returns
    -------
    numpy.ndarray
        (H, W, 4), the dtype of ``rgb``.
    """
    alpha = np.where(transparent, 0, opaque).astype(rgb.dtype)
    return np.concatenate([rgb, alpha[..., None]], axis=2)


def decode_png16(fp: IO[bytes], header: PngHeader, label: str) -> ImageArray:
    """Decode a 16-bit PNG (any colour type, interlaced or not) to uint16.

    Parameters
    ----------
    fp : IO[bytes]
        Seekable binary stream of the whole PNG file.
    header : PngHeader
        Its header, from :func:`read_png_header`, with ``bit_depth`` 16; the caller has
        already checked the pixel count against its limit.
    label : str
        Names the file in error messages.

    Returns
    -------
    numpy.ndarray
        uint16, shaped (H, W) for gray, (H, W, 3) for RGB, and (H, W, 4) for RGBA, gray+alpha
        (gray copied into R, G and B) and gray or RGB with a tRNS colour key.

    Raises
    ------
    ImageDecodeError
        The chunks are corrupt or truncated (see :func:`read_png_structure`), the image data
        does not inflate to exactly the size the header announces (see
        :func:`inflate_image_data`) or a row filter type is unknown. ``zlib.error`` from
        damaged compressed data is left for the caller to wrap.
    """
    bpp = 2 * _PNG_CHANNELS[header.color_type]
    passes = _passes(header)
    # The whole chunk structure is checked before a byte is inflated; then the data must
    # inflate to exactly what the header announces, never more.
    structure = read_png_structure(fp, header, label, keep_idat=True)
    inflated = inflate_image_data(structure.idat, header, label)
    trns = structure.trns

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
        return key_to_rgba(values.repeat(3, axis=2), gray == key, 0xFFFF)
    if header.color_type == 2 and trns is not None and len(trns) >= 6:
        key3 = np.frombuffer(trns[:6], dtype=">u2").astype(np.uint16)
        return key_to_rgba(values, np.all(values == key3, axis=-1), 0xFFFF)
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


def png_metadata(fp: IO[bytes], label: str) -> dict[str, Any]:
    """Return the JSON object stored under the text key ``"quilting"``, ``{}`` when absent.

    tEXt, zTXt and iTXt chunks are all looked at; the image data is seeked over unread.

    Parameters
    ----------
    fp : IO[bytes]
        Seekable binary stream positioned at the start of a PNG file.
    label : str
        Names the file in error messages.

    Returns
    -------
    dict
        The first ``"quilting"`` text chunk's JSON object.

    Raises
    ------
    ImageDecodeError
        The header or chunks are corrupt, a compressed text inflates past 64 MiB, or the text
        is not a JSON object. ``zlib.error`` and ``UnicodeDecodeError`` from a damaged text
        chunk are left for the caller to wrap.
    """
    read_png_header(fp, label)
    key = _METADATA_KEY.encode("latin-1")
    for ctype, data in iter_png_chunks(fp, label, skip=frozenset({b"IDAT"})):
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


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------


_ACCEPTED_SHAPES: Final = "(H, W), (H, W, 1), (H, W, 3) or (H, W, 4)"
_ACCEPTED_DTYPES: Final = "uint8, uint16, float32 or float64"


def png_samples(image: ImageArray) -> tuple[ImageArray, int, int]:
    """Validate an image for writing and turn it into PNG samples.

    Parameters
    ----------
    image : numpy.ndarray
        (H, W), (H, W, 1), (H, W, 3) or (H, W, 4); uint8, uint16, float32 or float64 (floats
        finite, clipped to [0, 1] and scaled to 16 bits as ``round(x * 65535)``).

    Returns
    -------
    samples : numpy.ndarray
        (H, W, C) C-contiguous, uint8 or big-endian ``>u2``.
    color_type : int
        0 (gray), 2 (RGB) or 6 (RGBA).
    depth : int
        8 or 16 bits per sample.

    Raises
    ------
    InvalidImageError
        Wrong type, dimension count, channel count or dtype, no pixels, a side past the PNG
        limit, or NaN/inf values.
    """
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


def metadata_text(metadata: Mapping[str, Any] | None) -> bytes | None:
    """Serialise the metadata object for the ``"quilting"`` tEXt chunk.

    Parameters
    ----------
    metadata : Mapping[str, Any] or None
        JSON-serialisable object.

    Returns
    -------
    bytes or None
        ASCII ``json.dumps(metadata, sort_keys=True)``; ``None`` when ``metadata`` is None.

    Raises
    ------
    InvalidParameterError
        ``metadata`` is not a mapping, or holds values JSON cannot represent (non-finite
        numbers included).
    """
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


def assemble_png(
    samples: ImageArray,
    color_type: int,
    depth: int,
    *,
    text: bytes | None,
    compress_level: int,
) -> bytes:
    """Build a complete PNG file from samples that :func:`png_samples` has validated.

    Parameters
    ----------
    samples : numpy.ndarray
        (H, W, C) C-contiguous samples, ``uint8`` for depth 8 or big-endian ``>u2`` for depth
        16, C matching ``color_type``.
    color_type : int
        PNG colour type: 0 (gray), 2 (RGB) or 6 (RGBA).
    depth : int
        Bits per sample, 8 or 16.
    text : bytes or None
        Latin-1 text (from :func:`metadata_text`) stored in a tEXt chunk under the key
        ``"quilting"``; ``None`` writes no text chunk.
    compress_level : int
        zlib level 0..9, already validated.

    Returns
    -------
    bytes
        Signature, IHDR, the optional tEXt, IDAT chunks of at most 1 MiB each, IEND. Rows are
        filtered with :func:`filter_rows`.
    """
    height, width = samples.shape[:2]
    raw = samples.reshape(height, -1).view(np.uint8)
    # A band of rows at a time: filtering holds about 17 bytes per image byte, which for a
    # whole 8192² RGB image would be 3.4 GB. The deflate stream is the same bytes however its
    # input is split.
    bpp = samples[0, 0].nbytes
    band = max(1, _FILTER_BAND_BYTES // max(1, raw.shape[1]))
    ihdr = struct.pack(">IIBBBBB", width, height, depth, color_type, 0, 0, 0)
    out = bytearray(PNG_SIGNATURE + _png_chunk(b"IHDR", ihdr))
    if text is not None:
        out += _png_chunk(b"tEXt", _METADATA_KEY.encode("latin-1") + b"\x00" + text)
    packer = zlib.compressobj(int(compress_level))
    pending = bytearray()
    starts = range(0, height, band)
    for start in [*starts, height]:
        if start < height:
            above = raw[start - 1] if start else None
            pending += packer.compress(filter_rows(raw[start : start + band], bpp, above).data)
        else:
            pending += packer.flush()
        # Full IDAT chunks go out as they fill, so the file is built once, not joined.
        while len(pending) >= _IDAT_CHUNK_BYTES or (start == height and pending):
            out += _png_chunk(b"IDAT", bytes(pending[:_IDAT_CHUNK_BYTES]))
            del pending[:_IDAT_CHUNK_BYTES]
    out += _png_chunk(b"IEND", b"")
    return bytes(out)


#: Image bytes filtered at once by :func:`assemble_png`.
_FILTER_BAND_BYTES = 1 << 20


def filter_rows(
    raw: npt.NDArray[np.uint8], bpp: int, above: npt.NDArray[np.uint8] | None = None
) -> npt.NDArray[np.uint8]:
    """PNG scanlines: each row filtered with None, Sub or Up, whichever suits it best.

    The choice is libpng's heuristic: the smallest sum of the filtered bytes taken as signed.
    Average and Paeth are left out: they compress a little better but cannot be undone with
    running sums, which keeps every file written here fast to read back (16-bit ones included).

    Parameters
    ----------
    raw : ndarray of uint8, shape (H, row bytes)
        The image bytes, row by row.
    bpp : int
        Bytes per pixel (the Sub filter's distance).
    above : ndarray of uint8, shape (row bytes,), optional
        The row above the first (the Up filter's reference), when ``raw`` is a band of a
        larger image; None for an image's first row (zeros above it).

    Returns
    -------
    ndarray of uint8, shape (H, 1 + row bytes)
        Filter type byte, then the filtered row.
    """
    height = raw.shape[0]
    sub = raw.copy()
    sub[:, bpp:] -= raw[:, :-bpp]  # uint8 arithmetic wraps modulo 256, as PNG wants
    up = raw.copy()
    up[1:] -= raw[:-1]
    if above is not None:
        up[0] -= above
    candidates = np.stack([raw, sub, up])  # (3, H, row bytes), indexed by filter type
    score = np.abs(candidates.view(np.int8).astype(np.int16)).sum(axis=2, dtype=np.int64)
    choice = score.argmin(axis=0)  # (H,)
    rows = np.empty((height, 1 + raw.shape[1]), dtype=np.uint8)
    rows[:, 0] = choice
    rows[:, 1:] = candidates[choice, np.arange(height)]
    return rows


def _png_chunk(ctype: bytes, data: bytes) -> bytes:
    """One chunk: length, type, data and the CRC over type and data."""
    crc = zlib.crc32(data, zlib.crc32(ctype))
    return struct.pack(">I", len(data)) + ctype + data + struct.pack(">I", crc)
