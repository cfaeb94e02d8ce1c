"""The uploads of an alpha extraction: photos (an ``/extract-alpha`` photo, a synthesis's
textures, a matte's layers) sent with a trimap or scribbles, their alpha extracted first by
:func:`quilting.extract_alpha` in the job's worker.

:mod:`quilting.service.uploads` calls these at the same three steps as every job's: the maps
checked from their headers (a photo without alpha, each map of its photo's size), decoded, and
checked in the sandbox by :func:`quilting.check_extract` (a map marking no foreground or no
background), the photo then standing in for the RGBA texture the extraction makes when the
rest of the job is checked.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from quilting import InvalidImageError, InvalidTrimapError, QuiltingError, check_extract
from quilting.io import ImageHeader
from quilting.service.jobs import JobInput
from quilting.service.problems import Problem, from_engine
from quilting.service.upload_images import Image, read_header, read_upload

#: A photo's trimap and scribbles (either may be None).
Marks = tuple[bytes | None, bytes | None]


def no_marks(field: str = "trimap") -> Problem:
    """422 ``invalid_trimap``: an extraction without a trimap or scribbles."""
    return Problem(
        422,
        "invalid_trimap",
        "extracting alpha needs a trimap or scribbles (a trimap or scribbles part)",
        field=field,
    )


def photo_fits(header: ImageHeader, role: str) -> None:
    """422 ``invalid_image`` naming ``role`` for a photo that has an alpha channel already:
    there is nothing to extract."""
    if header.channels == 4:
        raise Problem(
            422,
            "invalid_image",
            f"the {role} already has an alpha channel: send it without a trimap or scribbles "
            "(it is quilted as it is), or send its RGB to extract an alpha from them",
            field=role.split()[0],
        )


def _map_fits(size: tuple[int, int], photo: tuple[int, int], field: str, role: str) -> None:
    """422 ``invalid_trimap`` naming ``field`` unless a map's (width, height) is its photo's."""
    if size != photo:
        raise Problem(
            422,
            "invalid_trimap",
            f"{field} is {size[0]}x{size[1]} but the {role} is {photo[0]}x{photo[1]}: draw it "
            f"over the {role}, at its size",
            field=field,
        )


def marks_headers(
    header: ImageHeader, marks: Marks, role: str, limit: tuple[int, str]
) -> ImageHeader:
    """The header checks of one photo's trimap and scribbles (the API process): the photo
    without alpha, each map a PNG or JPEG of its size within ``limit`` (pixels, setting).
    Returns the header of the RGBA texture the extraction makes of the photo (4 channels,
    the photo's depth), or ``header`` itself for a photo without marks.

    Raises
    ------
    Problem
        422 ``invalid_image`` naming the photo's part or the map's, ``image_too_large``,
        ``invalid_trimap`` for a map of another size.
    """
    if marks == (None, None):
        return header
    photo_fits(header, role)
    for field, data in zip(("trimap", "scribbles"), marks, strict=True):
        if data is not None:
            found = read_header(data, field, *limit)
            _map_fits((found.width, found.height), (header.width, header.height), field, role)
    return ImageHeader(header.format, header.width, header.height, 4, header.bit_depth)


def decode_marks(
    images: Sequence[Image], marks: Sequence[Marks], roles: Sequence[str], limit: tuple[int, str]
) -> tuple[list[Image | None], list[Image | None]]:
    """Each photo's trimap and scribbles decoded (None where there is none), of its size.

    Raises
    ------
    Problem
        As :func:`marks_headers`, the pixels now decoded.
    """
    trimaps: list[Image | None] = []
    scribbles: list[Image | None] = []
    for image, (trimap, strokes), role in zip(images, marks, roles, strict=True):
        size = (image.shape[1], image.shape[0])
        for field, data, found in (("trimap", trimap, trimaps), ("scribbles", strokes, scribbles)):
            if data is None:
                found.append(None)
                continue
            decoded = read_upload(data, field, *limit)
            _map_fits((decoded.shape[1], decoded.shape[0]), size, field, role)
            found.append(decoded)
    return trimaps, scribbles


def check_marks(photo: Image, trimap: Image | None, scribbles: Image | None, role: str) -> Image:
    """What :func:`quilting.check_extract` refuses of a photo and its maps (the sandbox); a
    stand-in of the RGBA texture the extraction would make (the photo's colours, opaque, in
    its dtype), for the checks of the rest of the job. The extraction itself is the worker's.

    Raises
    ------
    Problem
        422 ``invalid_trimap`` naming the map (none marking foreground or background),
        ``invalid_image`` naming the photo (already with alpha, too small); 503
        ``matting_unavailable``.
    """
    field = "trimap" if trimap is not None else "scribbles"
    try:
        check_extract(photo, trimap, scribbles)
    except InvalidTrimapError as exc:
        raise Problem(422, "invalid_trimap", exc.message, field=field) from None
    except InvalidImageError as exc:
        detail = f"{role}: {exc.message}"
        raise Problem(422, "invalid_image", detail, field=role.split()[0]) from None
    except QuiltingError as exc:  # matting_unavailable: 503, as the engine's code maps
        raise from_engine(exc) from None
    return _opaque(photo)


def _opaque(photo: Image) -> Image:
    """The photo as an opaque RGBA image of its dtype (gray repeated)."""
    colour = photo if photo.ndim == 3 else photo[..., None]
    if colour.shape[2] == 1:
        colour = np.repeat(colour, 3, axis=2)
    full = (1 << (8 * photo.dtype.itemsize)) - 1 if photo.dtype.kind == "u" else 1
    opaque = np.full((*photo.shape[:2], 1), full, dtype=photo.dtype)
    return np.concatenate([colour[..., :3], opaque], axis=2)


def extract_headers(spec: JobInput) -> tuple[int, int]:
    """:func:`~quilting.service.uploads.check_headers` of an alpha extraction: the photo (its
    size is the output's), without alpha, and its trimap and scribbles of its size."""
    limit = spec.limits.output_sized()
    photo = read_header(spec.texture, "photo", *limit)
    marks = spec.marks(1)[0]
    if marks == (None, None):
        raise no_marks()
    marks_headers(photo, marks, "photo", limit)
    return photo.width, photo.height


def photo_roles(count: int, role: str) -> list[str]:
    """How each of ``count`` photos is named in problems: ``"texture"`` alone, else
    ``"texture 0"``, ``"texture 1"``..."""
    return [role] if count == 1 else [f"{role} {k}" for k in range(count)]
