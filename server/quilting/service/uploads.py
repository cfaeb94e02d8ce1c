"""A job's uploaded images, checked twice and decoded in a worker: never in the API process.

Three steps, each in its own process:

1. :func:`check_headers`, in the API process: what the files' structure says without decoding
   (:func:`quilting.io.image_header`): formats, declared sizes against the pixel limits, chunk
   and segment counts, several examples of one kind (channels and bit depth), companions of
   their texture's size (one map per example), a target within ``max_side``, a
   fill's mask of its image's size and its texture of the image's channels and depth, an
   extension within the output limits. It takes milliseconds, so a bad upload gets its 422 at
   once.
2. :func:`check`, in the sandbox (:mod:`quilting.service.sandbox`): every file decoded as
   strictly as :func:`quilting.io.read_image` decodes, and what needs the pixels checked
   (:func:`quilting.api.check_inputs`, :func:`quilting.api.check_matte_inputs`,
   :func:`quilting.check_fill`, and a fill's cost, which follows its hole); only the output
   size comes back. A submission still gets its 422 before it is queued.
3. :func:`decode`, in the job's worker, when the job starts: the same decoding, under the
   job's time and memory limits, giving the arrays the engine computes from.

Every failure is a :class:`~quilting.service.problems.Problem` naming the form field and the
setting to change.
"""

from __future__ import annotations

import dataclasses

from quilting import Budget, LayoutError, QuiltingError, check_companion_kind
from quilting.api import check_inputs, check_matte_inputs
from quilting.io import ImageHeader
from quilting.options import (
    AlphaOptions,
    FillOptions,
    MatteOptions,
    SynthesisOptions,
    WangOptions,
)
from quilting.service.extract_uploads import (
    check_marks,
    decode_marks,
    extract_headers,
    marks_headers,
    photo_roles,
)
from quilting.service.fill_uploads import FILLS, check_fill_job, decode_fill, fill_headers
from quilting.service.forms import JobOptions
from quilting.service.jobs import JobInput, PixelLimits
from quilting.service.jobs.job_input import EXTRACT
from quilting.service.problems import Problem, from_engine
from quilting.service.upload_images import (
    Decoded,
    Image,
    companion_fits,
    examples_match,
    read_header,
    read_upload,
    target_fits,
)

__all__ = ["Decoded", "check", "check_headers", "decode"]


def _companion_kind_fits(name: str, kind: str, channels: int, mode: object) -> None:
    """422 ``invalid_companion`` for a kind the job could not render the companion as (the
    layout's rules, :func:`quilting.check_companion_kind`), before any work."""
    try:
        check_companion_kind(kind, channels, walk=mode == "walk")
    except LayoutError as exc:
        raise Problem(
            422, "invalid_companion", f"companion {name!r}: {exc}", field="companion_kinds"
        ) from None


def check_headers(spec: JobInput) -> tuple[int, int]:
    """The checks of a job's uploads that need no decoding (the API process); the output's
    (width, height).

    Raises
    ------
    Problem
        422 ``invalid_image``, ``image_too_large`` or ``invalid_companion`` naming the field.
    """
    inputs, sized = spec.limits.input_sized(), spec.limits.output_sized()
    if spec.operation in FILLS:
        return fill_headers(spec)
    if spec.operation == EXTRACT:
        return extract_headers(spec)
    if spec.operation == "matte":
        marks = spec.marks(len(spec.layers))
        roles = photo_roles(len(spec.layers), "layer")
        for data, mark, role in zip(spec.layers, marks, roles, strict=True):
            marks_headers(read_header(data, "layer", *inputs), mark, role, inputs)
    else:
        _example_headers(spec, spec.limits)
    for role in ("silhouette", "normals"):
        data = getattr(spec, role)
        if data is not None:
            read_header(data, role, *sized)
    if spec.target is None:
        return spec.width, spec.height
    target = read_header(spec.target, "target", *sized)
    target_fits(target.width, target.height, spec.limits.max_side)
    return target.width, target.height


def _example_headers(spec: JobInput, limits: PixelLimits) -> None:
    """:func:`check_headers` of the texture (or the several examples) of a synthesis, a
    transfer or a Wang tile set, their companions and source masks."""
    inputs = limits.input_sized()
    found = [read_header(data, "texture", *inputs) for data in spec.textures]
    # A photo with a trimap or scribbles is quilted as the RGBA texture extracted from it.
    marks, roles = spec.marks(len(found)), photo_roles(len(found), "texture")
    textures = [
        marks_headers(header, mark, role, inputs)
        for header, mark, role in zip(found, marks, roles, strict=True)
    ]
    examples_match([(header.channels, header.bit_depth) for header in textures])
    several = len(textures) > 1
    for name in spec.companions:
        headers = [read_header(data, "companion", *inputs) for data in spec.maps_of(name)]
        for index, (header, texture) in enumerate(zip(headers, textures, strict=True)):
            of = f"texture {index}" if several else "texture"
            companion_fits(name, _size(header), _size(texture), of=of)
        examples_match([(header.channels, header.bit_depth) for header in headers], name)
        _companion_kind_fits(
            name, spec.kind_of(name), headers[0].channels, spec.options.get("mode")
        )
    for data in spec.masks:
        if data is not None:
            read_header(data, "source_mask", *inputs)


def _size(header: ImageHeader) -> tuple[int, int]:
    return header.width, header.height


def decode(spec: JobInput) -> Decoded:
    """Every upload of a job decoded (as strictly as :func:`quilting.io.read_image` does, under
    the input's pixel limits) and the sizes checked against each other.

    Raises
    ------
    Problem
        As :func:`check_headers`, the pixels now decoded.
    """
    limits = spec.limits
    inputs, sized = limits.input_sized(), limits.output_sized()
    target = None
    width, height = spec.width, spec.height
    if spec.target is not None:
        target = read_upload(spec.target, "target", *sized)
        height, width = target.shape[:2]
        target_fits(width, height, limits.max_side)
    if spec.operation in FILLS:
        return decode_fill(spec)
    if spec.operation == EXTRACT:
        photo = read_upload(spec.texture, "photo", *sized)
        trimaps, scribbles = decode_marks([photo], spec.marks(1), ["photo"], sized)
        height, width = photo.shape[:2]
        return Decoded(photo, {}, width, height, trimaps=trimaps, scribbles=scribbles)
    if spec.operation == "matte":
        assert spec.silhouette is not None, "a matte job has a silhouette"
        silhouette = read_upload(spec.silhouette, "silhouette", *sized)
        normals = None if spec.normals is None else read_upload(spec.normals, "normals", *sized)
        layers = [read_upload(data, "layer", *inputs) for data in spec.layers]
        trimaps, scribbles = _marks(spec, layers, "layer", inputs)
        return Decoded(
            layers[0],
            {},
            width,
            height,
            target=target,
            layers=layers,
            silhouette=silhouette,
            normals=normals,
            trimaps=trimaps,
            scribbles=scribbles,
        )
    textures = [read_upload(data, "texture", *inputs) for data in spec.textures]
    trimaps, scribbles = _marks(spec, textures, "texture", inputs)
    # A photo with a trimap or scribbles is quilted as the RGBA texture extracted from it.
    marked = [mark != (None, None) for mark in spec.marks(len(textures))]
    examples_match(
        [_kind(image, extracted) for image, extracted in zip(textures, marked, strict=True)]
    )
    several = len(textures) > 1
    maps: dict[str, list[Image]] = {}
    for name in spec.companions:
        maps[name] = [read_upload(data, "companion", *inputs) for data in spec.maps_of(name)]
        for index, (image, texture) in enumerate(zip(maps[name], textures, strict=True)):
            of = f"texture {index}" if several else "texture"
            companion_fits(name, _shape(image), _shape(texture), of=of)
        examples_match([_kind(image) for image in maps[name]], name)
        channels = _kind(maps[name][0])[0]
        _companion_kind_fits(name, spec.kind_of(name), channels, spec.options.get("mode"))
    masks = [
        None if data is None else read_upload(data, "source_mask", *inputs) for data in spec.masks
    ]
    return Decoded(
        textures[0],
        {name: found[0] for name, found in maps.items()},
        width,
        height,
        target=target,
        source_mask=masks[0],
        examples=textures if several else [],
        source_masks=[m for m in masks if m is not None] if several and spec.source_masks else [],
        example_companions=maps if several else {},
        trimaps=trimaps,
        scribbles=scribbles,
    )


def _marks(
    spec: JobInput, images: list[Image], role: str, limit: tuple[int, str]
) -> tuple[list[Image | None], list[Image | None]]:
    """The photos' trimaps and scribbles decoded, one (or None) per image; empty lists for
    a job that extracts no alpha."""
    if not spec.extracting:
        return [], []
    marks = spec.marks(len(images))
    return decode_marks(images, marks, photo_roles(len(images), role), limit)


def _stand_ins(images: Decoded) -> Decoded:
    """``images`` with each photo that has a trimap or scribbles checked
    (:func:`quilting.check_extract`) and replaced by a stand-in of the RGBA texture it would
    make (:func:`~quilting.service.extract_uploads.check_marks`), for the checks of
    the rest of the job."""
    photos = images.layers or images.examples or [images.texture]
    role = "layer" if images.layers else "texture"
    roles = photo_roles(len(photos), role)
    made = [
        image if (trimap is None and strokes is None) else check_marks(image, trimap, strokes, name)
        for image, trimap, strokes, name in zip(
            photos, images.trimaps, images.scribbles, roles, strict=True
        )
    ]
    if images.layers:
        return dataclasses.replace(images, texture=made[0], layers=made)
    if images.examples:
        return dataclasses.replace(images, texture=made[0], examples=made)
    return dataclasses.replace(images, texture=made[0])


def _shape(image: Image) -> tuple[int, int]:
    return image.shape[1], image.shape[0]


def _kind(image: Image, extracted: bool = False) -> tuple[int, int]:
    """(channels, bits per sample) of a decoded image; of the RGBA texture extracted from it
    when ``extracted``."""
    channels = 4 if extracted else (image.shape[2] if image.ndim == 3 else 1)
    return channels, image.dtype.itemsize * 8


def check(spec: JobInput, options: JobOptions, budget: Budget | None = None) -> tuple[int, int]:
    """Decode a job's uploads and refuse what the engine would refuse once running (the
    sandbox); the output's (width, height). The arrays are dropped: the worker decodes again.

    ``budget`` is the job's: a fill's cost, which needs its hole, is predicted here against
    it (None: not checked).

    Raises
    ------
    Problem
        As :func:`decode`, and the engine's own refusals (``invalid_parameter``...) and, for a
        matte job, 422 ``invalid_parameter`` when a layer would be quilted at more than
        ``max_output_pixels``; for a fill, as :func:`check_fill_job`.
    """
    images = decode(spec)
    if isinstance(options, AlphaOptions):
        assert images.trimaps, "an extraction job has a trimap or scribbles"
        photo, trimap, strokes = images.texture, images.trimaps[0], images.scribbles[0]
        check_marks(photo, trimap, strokes, "photo")
        return images.width, images.height
    if spec.extracting:
        assert isinstance(options, SynthesisOptions | MatteOptions), "what takes photos"
        images = _stand_ins(images)
    if isinstance(options, FillOptions):
        if budget is None:
            budget = Budget()
        check_fill_job(spec, options, images, budget)
        return images.width, images.height
    try:
        if isinstance(options, MatteOptions):
            assert images.target is not None and images.silhouette is not None
            layer_height, layer_width = check_matte_inputs(
                options, images.target, images.layers, images.silhouette, images.normals
            )
        elif isinstance(options, WangOptions):
            # Its material: a tile high, two colours' diamonds of a tile each wide.
            material = (options.tile, 2 * options.colors * options.tile)
            check_inputs(options, images.examples or images.texture, None, material)
        else:
            check_inputs(
                options,
                images.examples or images.texture,
                images.source_masks or images.source_mask,
                (images.height, images.width),
            )
    except QuiltingError as exc:
        raise from_engine(exc) from None
    if isinstance(options, MatteOptions) and (
        layer_height * layer_width > spec.limits.max_output_pixels
    ):
        raise Problem(
            422,
            "invalid_parameter",
            f"each layer would be quilted at {layer_width}x{layer_height} (the silhouette's "
            f"extent over scale={options.scale:g}), more than {spec.limits.max_output_pixels} "
            "pixels (max_output_pixels): raise scale",
            field="scale",
        )
    return images.width, images.height
