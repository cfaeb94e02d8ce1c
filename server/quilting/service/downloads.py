"""Download names of a job's files: made from the upload's file name, the operation, the size
and the seed, so that a saved result says what it is.

The scheme (``W`` x ``H`` is the output's width x height, as the CLI's ``--size WxH`` and the
``width``/``height`` options; ``N`` is the seed):

======================  ==================================================
``POST /synthesize``    ``<texture>-synth-WxH-seedN.png``
``POST /transfer``      ``<texture>-on-<target>-transfer-WxH-seedN.png``
``POST /matte``         ``<first layer>-on-<target>-matte-WxH-seedN.png``
``POST /fill``          ``<image>-fill-WxH-seedN.png``
``POST /extend``        ``<image>-extend-WxH-seedN.png``
``POST /wang-tiles``    ``<texture>-wang-WxH-seedN.png`` (W x H: the atlas)
``POST /extract-alpha`` ``<photo>-alpha-WxH.png`` (no seed: nothing is drawn at random)
``POST /tile``          ``<image>-tile.png``
a companion map         ``<job's name>-<companion>.png``
``/seams``              ``<job's name>-seams.png``
``/layout``             ``<job's name>-layout.json``
``/manifest``           ``<job's name>-manifest.json``
======================  ==================================================

A transfer and a matte name both images: the texture is what the result is made of, the target
what it shows, and either alone would mislead (one texture rendered onto many targets, or one
target in many textures).

``<texture>`` is the stem of the uploaded file's name, made safe: no folders, no quotes, no
control or formatting characters, at most :data:`MAX_STEM_BYTES` bytes of UTF-8; an upload
without a usable name is ``texture``. Responses carry the name in ``Content-Disposition``:
``filename="..."`` in ASCII for old clients and ``filename*=UTF-8''...`` (RFC 6266, RFC 8187)
when the name is not ASCII.
"""

from __future__ import annotations

import json
import re
import unicodedata
from collections.abc import Mapping
from typing import Any
from urllib.parse import quote

#: The stem of an upload without a (usable) file name.
FALLBACK_STEM = "texture"

#: Longest stem of one upload, in bytes of UTF-8: two of them and the suffixes stay under the
#: 255 bytes most file systems allow in a name.
MAX_STEM_BYTES = 64

#: The operation's word in the name.
OPERATION_WORDS = {
    "synthesize": "synth",
    "transfer": "transfer",
    "matte": "matte",
    "fill": "fill",
    "extend": "extend",
    "wang_tiles": "wang",
    "extract_alpha": "alpha",
}

#: Punctuation kept in a stem; any other character that is not a letter or a digit becomes "-".
_KEPT = frozenset("-_.+()")
_DASHES = re.compile(r"-{2,}")
_SPACES = re.compile(r"\s+")
_EDGES = " .-_"
#: How browsers (and httpx) write a quote, CR and LF in a multipart file name (WHATWG HTML,
#: "multipart/form-data encoding algorithm"); read back so that they are dealt with as such.
_FORM_ESCAPES = re.compile(r"%(22|0D|0A)", re.IGNORECASE)
_UNESCAPED = {"22": '"', "0D": "\r", "0A": "\n"}


def safe_stem(filename: str | None) -> str:
    """The stem of an uploaded file's name, safe in a header and as a file name.

    Parameters
    ----------
    filename : str or None
        The name the client sent (``../../etc/pass"wd.png``, ``C:\\photos\\brick.png``...).

    Returns
    -------
    str
        Its last path part without the extension, with letters and digits of any script and
        ``- _ . + ( )`` kept, runs of white space as one space, anything else as ``-``; no
        leading or trailing dots (no hidden files), dashes or spaces; :data:`FALLBACK_STEM`
        when nothing is left.
    """
    name = _FORM_ESCAPES.sub(lambda m: _UNESCAPED[m.group(1).upper()], filename or "")
    name = unicodedata.normalize("NFC", name)
    # Either separator: a browser on Windows may send the full path.
    name = re.split(r"[/\\]", name)[-1]
    dot = name.rfind(".")
    if dot > 0:
        name = name[:dot]
    kept = []
    for char in name:
        if char.isalnum() or char in _KEPT:
            kept.append(char)
        elif char.isspace():
            kept.append(" ")
        else:
            # Quotes, control characters, bidirectional overrides, ...
            kept.append("-")
    stem = _DASHES.sub("-", _SPACES.sub(" ", "".join(kept))).strip(_EDGES)
    encoded = stem.encode()
    if len(encoded) > MAX_STEM_BYTES:
        # Cut on a character boundary, then tidy the new end.
        stem = encoded[:MAX_STEM_BYTES].decode(errors="ignore").rstrip(_EDGES)
    return stem or FALLBACK_STEM


def job_stem(
    operation: str,
    texture_name: str | None,
    target_name: str | None,
    width: int,
    height: int,
    seed: int | None,
) -> str:
    """The common start of every download name of a job (see the module's table).

    Parameters
    ----------
    operation : str
        ``"synthesize"``, ``"transfer"``, ``"matte"``, ``"fill"``, ``"extend"``,
        ``"wang_tiles"`` or ``"extract_alpha"``.
    texture_name, target_name : str or None
        The uploads' file names (a matte's first layer is its texture, a fill's and an
        extension's image is); the target's is used by a transfer and a matte only.
    width, height : int
        The output's size.
    seed : int or None
        The job's seed; None for a job without one (an alpha extraction).
    """
    word = OPERATION_WORDS.get(operation, operation)
    made_of = safe_stem(texture_name)
    if operation in ("transfer", "matte"):
        made_of += "-on-" + safe_stem(target_name)
    stem = f"{made_of}-{word}-{width}x{height}"
    return stem if seed is None else f"{stem}-seed{seed}"


def fallback_stem(operation: str, width: int, height: int) -> str:
    """The stem of a job recorded without one (by an older version): no names, no seed."""
    return f"{FALLBACK_STEM}-{OPERATION_WORDS.get(operation, operation)}-{width}x{height}"


def tile_name(image_name: str | None) -> str:
    """The download name of a ``POST /tile`` result."""
    return f"{safe_stem(image_name)}-tile.png"


def _ascii(filename: str) -> str:
    # Accents dropped (é -> e), other scripts as "_": only for clients without filename*.
    decomposed = unicodedata.normalize("NFKD", filename)
    plain = "".join(c for c in decomposed if not unicodedata.combining(c))
    return re.sub(r"_{2,}", "_", "".join(c if c.isascii() else "_" for c in plain))


def content_disposition(filename: str) -> str:
    """The ``Content-Disposition`` of a download named ``filename`` (a name made here).

    ``filename`` has no quotes, backslashes or control characters (:func:`safe_stem`), so the
    quoted form needs no escapes; ``filename*`` carries the exact name when it is not ASCII.
    """
    fallback = _ascii(filename)
    header = f'attachment; filename="{fallback}"'
    if fallback != filename:
        header += "; filename*=UTF-8''" + quote(filename, safe="")
    return header


def download_name(operation: str, stem: str | None, width: int, height: int, suffix: str) -> str:
    """The file name of one of a job's downloads: its stem (or the fallback made of its
    operation and size), then ``suffix``."""
    return (stem or fallback_stem(operation, width, height)) + suffix


def attachment(filename: str) -> dict[str, str]:
    """The header that makes ``filename`` the name a download is saved under."""
    return {"Content-Disposition": content_disposition(filename)}


#: The header of a result made from photos whose alpha was extracted first: the extractions'
#: summaries (the job's ``stats["extracted"]``) as compact JSON.
EXTRACTED_HEADER = "Quilting-Extracted"


def extracted_headers(stats: Mapping[str, Any] | None) -> dict[str, str]:
    """``{EXTRACTED_HEADER: ...}`` for the result of a job that extracted an alpha (its
    ``stats``), else empty.

    The value is an array of one entry per photo (an extraction's one, a synthesis's
    textures, a matte's layers), null for one without a trimap or scribbles, each
    :meth:`quilting.Extracted.summary` ({method, foreground, unknown, iterations, seconds}).
    """
    found = (stats or {}).get("extracted")
    if not found:
        return {}
    return {EXTRACTED_HEADER: json.dumps(found, separators=(",", ":"))}
