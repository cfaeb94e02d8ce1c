"""A job's uploaded images, checked twice and decoded in a worker: never in the API process.

Three steps, each in its own process:

1. :func:`check_headers`, in the API process: what the files' structure says without decoding
   (:func:`quilting.io.image_header`): formats, declared sizes against the pixel limits, chunk
   and segment counts, companions of the texture's size, a target within ``max_side``. It
   takes milliseconds, so a bad upload gets its 422 at once.
2. :func:`check`, in the sandbox (:mod:`quilting.service.sandbox`): every file decoded as
   strictly as :func:`quilting.io.read_image` decodes, and what needs the pixels checked
   (:func:`quilting.api.check_inputs`, :func:`quilting.api.check_matte_inputs`); only the
   output size comes back. A submission still gets its 422 before it is queued.
3. :func:`decode`, in the job's worker, when the job starts: the same decoding, under the
   job's time and memory limits, giving the arrays the engine computes from.

Every failure is a :class:`~quilting.service.problems.Problem` naming the form field and the
setting to change.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from quilting import (
    ImageDecodeError,
    ImageTooLargeError,
    LayoutError,
    QuiltingError,
    check_companion_kind,
)
from quilting.api import check_inputs, check_matte_inputs
from quilting.io import ImageHeader, image_header, read_image
from quilting.options import MatteOptions, QuiltOptions
from quilting.service.jobs import JobInput, PixelLimits
from quilting.service.problems import Problem, from_engine

Image = NDArray[np.generic]


@dataclass
class Decoded:
    """A job's images, decoded (:func:`decode`); the rest of the job is its :class:`JobInput`.

    Attributes
    ----------
    texture : ndarray
        The sample texture (a matte job's first layer).
    companions : dict of str to ndarray
        Companion maps, of the texture's size.
    target, source_mask, silhouette, normals : ndarray or None
        As the input has them.
    layers : list of ndarray
        A matte job's textures, bottom first.
    width, height : int
        The output's size (a transfer's and a matte's is its target's).
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


def _header(data: bytes, role: str, max_pixels: int, setting: str) -> ImageHeader:
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


def _companion_fits(name: str, size: tuple[int, int], texture: tuple[int, int]) -> None:
    """422 ``invalid_companion`` unless the companion's (width, height) is the texture's."""
    if size != texture:
        raise Problem(
            422,
            "invalid_companion",
            f"companion {name!r} is {size[0]}x{size[1]}; it must be the texture's size, "
            f"{texture[0]}x{texture[1]}",
            field="companion",
        )


def _companion_kind_fits(name: str, kind: str, channels: int, mode: object) -> None:
    """422 ``invalid_companion`` for a kind the job could not render the companion as (the
    layout's rules, :func:`quilting.check_companion_kind`), before any work."""
    try:
        check_companion_kind(kind, channels, walk=mode == "walk")
    except LayoutError as exc:
        raise Problem(
            422, "invalid_companion", f"companion {name!r}: {exc}", field="companion_kinds"
        ) from None


def _target_fits(width: int, height: int, max_side: int) -> None:
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
    return _header(data, role, *limits.output_sized())


def check_headers(spec: JobInput) -> tuple[int, int]:
    """The checks of a job's uploads that need no decoding (the API process); the output's
    (width, height).

    Raises
    ------
    Problem
        422 ``invalid_image``, ``image_too_large`` or ``invalid_companion`` naming the field.
    """
    inputs, sized = spec.limits.input_sized(), spec.limits.output_sized()
    if spec.operation == "matte":
        for data in spec.layers:
            _header(data, "layer", *inputs)
    else:
        texture = _header(spec.texture, "texture", *inputs)
        for name, data in spec.companions.items():
            header = _header(data, "companion", *inputs)
            _companion_fits(name, (header.width, header.height), (texture.width, texture.height))
            _companion_kind_fits(
                name, spec.kind_of(name), header.channels, spec.options.get("mode")
            )
        if spec.source_mask is not None:
            _header(spec.source_mask, "source_mask", *inputs)
    for role in ("silhouette", "normals"):
        data = getattr(spec, role)
        if data is not None:
            _header(data, role, *sized)
    if spec.target is None:
        return spec.width, spec.height
    target = _header(spec.target, "target", *sized)
    _target_fits(target.width, target.height, spec.limits.max_side)
    return target.width, target.height


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
        _target_fits(width, height, limits.max_side)
    if spec.operation == "matte":
        assert spec.silhouette is not None, "a matte job has a silhouette"
        silhouette = read_upload(spec.silhouette, "silhouette", *sized)
        normals = None if spec.normals is None else read_upload(spec.normals, "normals", *sized)
        layers = [read_upload(data, "layer", *inputs) for data in spec.layers]
        return Decoded(
            layers[0],
            {},
            width,
            height,
            target=target,
            layers=layers,
            silhouette=silhouette,
            normals=normals,
        )
    texture = read_upload(spec.texture, "texture", *inputs)
    companions = {
        name: read_upload(data, "companion", *inputs) for name, data in spec.companions.items()
    }
    for name, image in companions.items():
        _companion_fits(
            name, (image.shape[1], image.shape[0]), (texture.shape[1], texture.shape[0])
        )
        channels = image.shape[2] if image.ndim == 3 else 1
        _companion_kind_fits(name, spec.kind_of(name), channels, spec.options.get("mode"))
    mask = (
        None if spec.source_mask is None else read_upload(spec.source_mask, "source_mask", *inputs)
    )
    return Decoded(texture, companions, width, height, target=target, source_mask=mask)


def check(spec: JobInput, options: QuiltOptions) -> tuple[int, int]:
    """Decode a job's uploads and refuse what the engine would refuse once running (the
    sandbox); the output's (width, height). The arrays are dropped: the worker decodes again.

    Raises
    ------
    Problem
        As :func:`decode`, and the engine's own refusals (``invalid_parameter``...) and, for a
        matte job, 422 ``invalid_parameter`` when a layer would be quilted at more than
        ``max_output_pixels``.
    """
    images = decode(spec)
    try:
        if isinstance(options, MatteOptions):
            assert images.target is not None and images.silhouette is not None
            layer_height, layer_width = check_matte_inputs(
                options, images.target, images.layers, images.silhouette, images.normals
            )
        else:
            check_inputs(options, images.texture, images.source_mask, (images.height, images.width))
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
