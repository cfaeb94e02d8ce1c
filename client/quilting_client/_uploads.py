"""The files a submission uploads, prepared without any I/O but reading them: images read
from paths or bytes and typed, companions' names and kinds checked before anything is sent.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from quilting_client.errors import ValidationError

#: What an image (a texture, a target, a companion map, an image to tile, a matte's silhouette,
#: layer or normal map) may be given as: a path, or the file's bytes.
ImageSource = str | os.PathLike[str] | bytes

#: The first bytes of every PNG file.
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

_NAME = re.compile(r"[A-Za-z0-9_-]{1,64}")
_JPEG_SIGNATURE = b"\xff\xd8\xff"


def read_source(source: ImageSource) -> tuple[bytes, str | None]:
    """The bytes of an image given as a path or as bytes, and the file's name if it has one."""
    if isinstance(source, bytes | bytearray | memoryview):
        return bytes(source), None
    path = Path(os.fspath(source))
    return path.read_bytes(), path.name


def media_type(content: bytes) -> str:
    """The media type of an image's bytes, for its part's ``Content-Type``."""
    # The service sniffs the bytes itself; a matching type only helps proxies and logs.
    if content.startswith(PNG_SIGNATURE):
        return "image/png"
    if content.startswith(_JPEG_SIGNATURE):
        return "image/jpeg"
    return "application/octet-stream"


def part(field: str, source: ImageSource) -> tuple[str, tuple[str, bytes, str]]:
    """One multipart file part; an image given as bytes is named after its field."""
    content, filename = read_source(source)
    return (field, (filename or field, content, media_type(content)))


def check_companion_name(name: object) -> str:
    """``name`` if the service would take it as a companion's name; else raise.

    Raises
    ------
    ValidationError
        A name that is not 1 to 64 of ``A-Z a-z 0-9 _ -`` (checked here to fail before
        uploading).
    """
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise ValidationError(
            f"companion name {name!r} is not 1 to 64 of A-Z a-z 0-9 _ -",
            code="invalid_companion_name",
            field="companion",
        )
    return name


def images_of(value: Iterable[ImageSource], what: str) -> list[ImageSource]:
    """The images of a sequence, refusing a lone image (a path is a sequence of characters)."""
    if isinstance(value, str | bytes | bytearray | memoryview | os.PathLike):
        raise TypeError(f"{what} is a sequence of images: put a single image in a list")
    return list(value)


def one_or_many(value: ImageSource | Sequence[ImageSource], what: str) -> list[ImageSource]:
    """The images of ``value``: one image (a path or bytes), or a sequence of them (several
    examples of one texture, each sent as a part of the same name, in order).

    Raises
    ------
    ValidationError
        An empty sequence (code ``missing_field``, checked here to fail before uploading).
    TypeError
        An open file (a path or bytes is needed, as for every image).
    """
    if isinstance(value, bytearray | memoryview):
        return [bytes(value)]
    if isinstance(value, str | bytes | os.PathLike):
        return [value]
    if hasattr(value, "read"):
        # An open file iterates over its lines: it would go up as a part per line.
        raise TypeError(
            f"{what}: give a path or the file's bytes, not an open file "
            f"({type(value).__name__}); e.g. {what}=f.read()"
        )
    images = list(value)
    if not images:
        raise ValidationError(
            f"{what}: at least one image is needed", code="missing_field", field=what
        )
    return images


def output_names(names: Iterable[str]) -> tuple[str, ...]:
    """The names of companions to download, checked, in order and without repeats.

    Raises
    ------
    TypeError
        ``names`` is one string rather than a collection of names.
    ValidationError
        A name the service could not have given a companion.
    """
    if isinstance(names, str):
        raise TypeError(f"companions is a collection of names: put {names!r} in a tuple")
    return tuple(dict.fromkeys(check_companion_name(name) for name in names))


#: How a companion may be rendered (the service's ``companion_kinds`` values).
COMPANION_KINDS = ("blend", "hard", "normal", "normal_dx")


def check_companion_kinds(
    kinds: Mapping[str, str] | None, companions: Mapping[str, object] | None
) -> dict[str, str]:
    """``kinds`` if every name is one of ``companions`` and every kind one the service takes.

    Raises
    ------
    ValidationError
        Checked here to fail before uploading: code ``invalid_companion`` for an unknown
        name, ``invalid_parameter`` for an unknown kind.
    """
    for name, kind in (kinds or {}).items():
        if name not in (companions or {}):
            raise ValidationError(
                f"companion_kinds names {name!r}, which is not one of the companions sent",
                code="invalid_companion",
                field="companion_kinds",
            )
        if kind not in COMPANION_KINDS:
            raise ValidationError(
                f"companion kind {kind!r} of {name!r} is not one of {', '.join(COMPANION_KINDS)}",
                code="invalid_parameter",
                field="companion_kinds",
            )
    return dict(kinds or {})
