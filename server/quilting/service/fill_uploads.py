"""The uploads of a fill (``POST /fill``) and an extension (``POST /extend``): their image,
mask and texture checked from their headers, decoded, and checked against what
:func:`quilting.fill` and :func:`quilting.extend` refuse, the cost included.

:mod:`quilting.service.uploads` calls these for the operations in :data:`FILLS`, at the same
three steps as every job's.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from quilting import Budget, InvalidImageError, QuiltingError, check_fill, hole_box, hole_of
from quilting.io import ImageHeader
from quilting.options import ExtendOptions, FillOptions
from quilting.service.budgets import extension_hole, predicted_fill
from quilting.service.jobs import JobInput, PixelLimits
from quilting.service.problems import Problem, from_engine
from quilting.service.upload_images import Decoded, companion_fits, read_header, read_upload

#: The operations whose ``texture`` is an image to fill or extend (the ``image`` part), its
#: companions of its size.
FILLS = ("fill", "extend")


def mask_fits(size: tuple[int, int], image: tuple[int, int]) -> None:
    """422 ``invalid_image`` unless a fill's mask's (width, height) is its image's."""
    if size != image:
        raise Problem(
            422,
            "invalid_image",
            f"mask is {size[0]}x{size[1]}; it must be the image's size, {image[0]}x{image[1]}",
            field="mask",
        )


def texture_matches(texture: ImageHeader, image: ImageHeader) -> None:
    """422 ``invalid_image`` unless a fill's texture has its image's channels and depth (the
    blocks are pasted into the image as they are)."""
    if (texture.channels, texture.bit_depth) != (image.channels, image.bit_depth):
        raise Problem(
            422,
            "invalid_image",
            f"the texture ({texture.channels} channels, {texture.bit_depth}-bit) must have the "
            f"image's channels and bit depth ({image.channels}, {image.bit_depth}-bit)",
            field="texture",
        )


def extension_fits(width: int, height: int, options: dict[str, Any], limits: PixelLimits) -> None:
    """422 ``invalid_parameter`` for an extension larger than the output limits, naming a
    margin the caller gave: too long a side, the larger margin of that axis (of all four
    when that axis was not grown); too many pixels, the largest margin."""
    margins = {side: int(options.get(side, 0)) for side in ("left", "right", "top", "bottom")}

    def largest(sides: tuple[str, ...]) -> str:
        return max(sides, key=margins.__getitem__)

    axis = ("left", "right") if width >= height else ("top", "bottom")
    if max(width, height) > limits.max_side:
        raise Problem(
            422,
            "invalid_parameter",
            f"the extended image would be {width}x{height}; its longest side may be "
            f"{limits.max_side} pixels (max_side)",
            field=largest(axis) if any(margins[side] for side in axis) else largest(tuple(margins)),
        )
    if width * height > limits.max_output_pixels:
        raise Problem(
            422,
            "invalid_parameter",
            f"the extended image would be {width}x{height}, more than "
            f"{limits.max_output_pixels} pixels (max_output_pixels)",
            field=largest(tuple(margins)),
        )


def fill_headers(spec: JobInput) -> tuple[int, int]:
    """:func:`check_headers` of a fill or an extension: the image (a fill's has the output's
    size, an extension's is an input), its companions of its size, a fill's mask of its size
    and texture of its channels and depth, an extension's size within the output limits."""
    limits = spec.limits
    filling = spec.operation == "fill"
    image = read_header(
        spec.texture, "image", *(limits.output_sized() if filling else limits.input_sized())
    )
    size = (image.width, image.height)
    for name, data in spec.companions.items():
        header = read_header(data, "companion", *limits.input_sized())
        companion_fits(name, (header.width, header.height), size, of="image")
    if spec.mask is not None:
        mask = read_header(spec.mask, "mask", *limits.output_sized())
        mask_fits((mask.width, mask.height), size)
    if spec.source is not None:
        texture_matches(read_header(spec.source, "texture", *limits.input_sized()), image)
    if filling:
        return size
    options = spec.options
    width = image.width + int(options["left"]) + int(options["right"])
    height = image.height + int(options["top"]) + int(options["bottom"])
    extension_fits(width, height, options, limits)
    return width, height


def decode_fill(spec: JobInput) -> Decoded:
    """:func:`decode` of a fill or an extension."""
    limits = spec.limits
    filling = spec.operation == "fill"
    image = read_upload(
        spec.texture, "image", *(limits.output_sized() if filling else limits.input_sized())
    )
    size = (image.shape[1], image.shape[0])
    companions = {
        name: read_upload(data, "companion", *limits.input_sized())
        for name, data in spec.companions.items()
    }
    for name, companion in companions.items():
        companion_fits(name, (companion.shape[1], companion.shape[0]), size, of="image")
    mask = None
    if spec.mask is not None:
        mask = read_upload(spec.mask, "mask", *limits.output_sized())
        mask_fits((mask.shape[1], mask.shape[0]), size)
    source = None
    if spec.source is not None:
        source = read_upload(spec.source, "texture", *limits.input_sized())
    return Decoded(image, companions, spec.width, spec.height, mask=mask, source=source)


def check_fill_job(spec: JobInput, options: FillOptions, images: Decoded, budget: Budget) -> None:
    """What :func:`quilting.fill` (or :func:`quilting.extend`) would refuse before any work,
    its cost against ``budget`` included: it follows the hole's extent, which the mask gives.

    Raises
    ------
    Problem
        422 ``invalid_image`` (field ``mask``) for a mask covering the whole image without a
        texture; ``invalid_parameter`` (field ``block``) for a block that fits nowhere, naming
        the largest that does; ``job_too_large``.
    """
    image = images.texture
    height, width = image.shape[:2]
    channels = image.shape[2] if image.ndim == 3 else 1
    source: tuple[int, int] | None
    try:
        if isinstance(options, ExtendOptions):
            shape = (spec.height, spec.width)
            box = extension_hole(height, width, options)
            # The blocks come from the image: check_fill looks at the sizes alone (this hole
            # is never read, nor its pages touched).
            hole = np.zeros(shape, dtype=bool)
            source = (height, width)
        else:
            assert images.mask is not None, "a fill job has a mask"
            shape = (height, width)
            hole = hole_of(images.mask, shape)
            box = hole_box(hole)
            source = None if images.source is None else images.source.shape[:2]
        if box != (0, 0):  # an empty hole is the image as it is, whatever the options
            check_fill(shape, hole, options, source)
    except InvalidImageError as exc:  # the mask: it covers everything and there is no texture
        raise Problem(422, "invalid_image", exc.message, field="mask") from None
    except QuiltingError as exc:
        raise from_engine(exc) from None
    predicted_fill(
        options,
        (*shape, channels),
        box,
        budget,
        texture=source,
        itemsize=image.dtype.itemsize,
        extra_bytes=spec.nbytes,
    )
