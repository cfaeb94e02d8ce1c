"""One uploaded image: its header and its pixels read under the pixel limits, and the checks
of one part's size against another's, each failure a 422 problem naming the form field.

The steps that use them, and when each runs, are :mod:`quilting.service.uploads`'s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from quilting import ImageDecodeError, ImageTooLargeError, QuiltingError
from quilting.io import ImageHeader, image_header, read_image
from quilting.service.jobs import PixelLimits
from quilting.service.problems import Problem

Image = NDArray[np.generic]


@dataclass
class Decoded:
    """A job's images, decoded (:func:`quilting.service.uploads.decode`); the rest of the job
    is its :class:`JobInput`.

    Attributes
    ----------
    texture : ndarray
        The sample texture (a matte job's first layer; a fill's or an extension's image).
    companions : dict of str to ndarray
        Companion maps, of the texture's size.
    target, source_mask, silhouette, normals, mask, source : ndarray or None
        As the input has them.
    layers : list of ndarray
        A matte job's textures, bottom first.
    width, height : int
        The output's size (a transfer's and a matte's is its target's).
    examples : list of ndarray
        Every texture of a job of several examples, in order (``texture`` is the first);
        empty for one texture.
    source_masks : list of ndarray
        With several examples sent with source masks, one per example; else empty.
    example_companions : dict of str to list of ndarray
        With several examples, each companion's map of every example; else empty.
    trimaps, scribbles : list of (ndarray or None)
        Of a job that extracts an alpha first: each photo's (an extraction's one, a
        synthesis's textures, a matte's layers, in order), None for one without; else empty.
    """

    texture: Image
    companions: dict[str, Image]
    width: int
    height: int
    target: Image | None = None
    source_mask: Image | None = None
    layers: list[Image] = field(default_factory=list)
    silhouette: Image | None = None
    normals: Image | None = None
    mask: Image | None = None
    source: Image | None = None
    examples: list[Image] = field(default_factory=list)
    source_masks: list[Image] = field(default_factory=list)
    example_companions: dict[str, list[Image]] = field(default_factory=dict)
    trimaps: list[Image | None] = field(default_factory=list)
    scribbles: list[Image | None] = field(default_factory=list)


def image_problem(error: QuiltingError, role: str, setting: str) -> Problem:
    """The problem of an upload that cannot be decoded or is too large, naming the part.

    The engine names bytes ``<bytes>`` and its pixel limit ``max_pixels``; here they are
    the form field and the service setting that the caller can act on.
    """
    detail = error.message.replace("<bytes>", role, 1)
    if isinstance(error, ImageTooLargeError):
        detail = detail.replace("(max_pixels)", f"({setting})")
        return Problem(422, "image_too_large", detail, field=role)
    return Problem(422, "invalid_image", detail, field=role)


def read_header(data: bytes, role: str, max_pixels: int, setting: str) -> ImageHeader:
    try:
        return image_header(data, max_pixels=max_pixels)
    except (ImageTooLargeError, ImageDecodeError) as exc:
        raise image_problem(exc, role, setting) from None


def read_upload(data: bytes, role: str, max_pixels: int, setting: str) -> Image:
    """One upload decoded by :func:`quilting.io.read_image`; a failure is its 422 problem."""
    try:
        return read_image(data, max_pixels=max_pixels)
    except (ImageTooLargeError, ImageDecodeError) as exc:
        raise image_problem(exc, role, setting) from None


def companion_fits(
    name: str, size: tuple[int, int], texture: tuple[int, int], of: str = "texture"
) -> None:
    """422 ``invalid_companion`` unless the companion's (width, height) is the texture's (or
    the image's, ``of``, for a fill or an extension)."""
    if size != texture:
        raise Problem(
            422,
            "invalid_companion",
            f"companion {name!r} is {size[0]}x{size[1]}; it must be the {of}'s size, "
            f"{texture[0]}x{texture[1]}",
            field="companion",
        )


def examples_match(kinds: list[tuple[int, int]], role: str = "texture") -> None:
    """422 unless every example has the first's (channels, bit depth): several examples are
    quilted from one atlas (``invalid_image`` naming ``texture``), and a companion's maps of
    them are laid into one (``invalid_companion``, ``role`` the companion's name)."""
    first = kinds[0]
    for index, kind in enumerate(kinds[1:], 1):
        if kind != first:
            what = "texture" if role == "texture" else f"companion {role!r}'s map of texture"
            raise Problem(
                422,
                "invalid_image" if role == "texture" else "invalid_companion",
                f"{what} {index} has {kind[0]} channels at {kind[1]} bits, but {what} 0 has "
                f"{first[0]} at {first[1]}: the examples must be of one kind",
                field="texture" if role == "texture" else "companion",
            )


def target_fits(width: int, height: int, max_side: int) -> None:
    """422 ``image_too_large`` for a target longer than the longest output side."""
    if max(height, width) > max_side:
        raise Problem(
            422,
            "image_too_large",
            f"target is {width}x{height}; the output has its size and its longest side may "
            f"be {max_side} pixels (max_side)",
            field="target",
        )


def check_image_header(data: bytes, role: str, limits: PixelLimits) -> ImageHeader:
    """The header check of an upload whose size is the output's (the image of ``/tile``).

    Raises
    ------
    Problem
        422 ``invalid_image`` or ``image_too_large`` naming ``role``.
    """
    return read_header(data, role, *limits.output_sized())
