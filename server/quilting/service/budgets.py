"""A job's predicted cost against the service's budgets, from its uploads' headers alone.

The API process knows each upload's size, channels and depth from its header (see
:func:`quilting.io.image_header`); with the options that is all the cost model needs
(:func:`quilting.estimate_synthesis`, :func:`quilting.estimate_transfer`,
:func:`quilting.estimate_fill`). A job predicted to take more memory than ``job_memory_bytes``
beyond a worker's own, or longer than ``job_timeout_s``, is answered 422 ``job_too_large``
before it is queued, with the prediction, the budget and what would fit. A matte's layers are
quilted at the silhouette's extent over ``scale``, known only once its pixels are read: the
whole target over ``scale`` bounds it. A fill's cost follows its hole's extent, known only once
its mask is decoded: the sandbox predicts it then (:func:`predicted_fill`, called by
:func:`quilting.service.uploads.check`), still before the job is queued; an extension's hole
is known from the image's header and the margins. A job of several examples, or of their
rotations and mirrors (``transforms``), quilts from their atlas, whose shape the examples'
sizes give (:func:`quilting.options.examples_shape`); a Wang tile set costs the quilting of its
material and its tiles (:func:`quilting.estimate_wang`).
"""

from __future__ import annotations

import math

import quilting
from quilting import BASE_BYTES, Budget, Estimate, QuiltingError, estimate_extract, estimate_matte
from quilting.api import guide_channels
from quilting.io import ImageHeader, image_header
from quilting.options import (
    AlphaOptions,
    ExtendOptions,
    FillOptions,
    MatteOptions,
    QuiltOptions,
    SynthesisOptions,
    TransferOptions,
    WangOptions,
    examples_shape,
)
from quilting.service.forms import JobOptions
from quilting.service.jobs import JobInput
from quilting.service.problems import Problem, from_engine


def job_budget(memory_bytes: int, seconds: float | None) -> Budget:
    """The budget of one job: ``memory_bytes`` beyond what a worker holds once started (the
    cost model counts the interpreter in), and ``seconds`` (None: no time budget)."""
    return Budget(memory_bytes=BASE_BYTES + memory_bytes, seconds=seconds)


def predicted(spec: JobInput, options: JobOptions, budget: Budget) -> Estimate | None:
    """The job's estimate, once checked against ``budget``; None for a fill, whose cost
    needs its hole (:func:`predicted_fill`, once the mask is decoded). A job that extracts
    alpha from photos first has each extraction checked against ``budget`` too (they run one
    after another, before the quilting); its quilting is costed on RGBA textures.

    ``spec`` holds the uploads as they came, already header-checked (their headers parse), and
    the output's size.

    Raises
    ------
    Problem
        422 ``job_too_large`` naming the predicted memory or time, the budget and what to
        change.
    """
    try:
        if isinstance(options, AlphaOptions):
            return estimate_extract(options, (spec.height, spec.width), budget=budget)
        if spec.extracting:
            _extractions(spec, options, budget)
        return _estimate(spec, options, budget)
    except quilting.JobTooLargeError as exc:
        raise _too_large(exc, budget, "job_memory_bytes and job_timeout_s") from None
    except QuiltingError as exc:  # options the shapes refuse (a tileable side under a block)
        raise from_engine(exc) from None


def predicted_fill(
    options: FillOptions,
    image: tuple[int, int, int],
    hole: tuple[int, int],
    budget: Budget,
    *,
    texture: tuple[int, int] | None = None,
    itemsize: int = 1,
    extra_bytes: int = 0,
) -> Estimate:
    """A fill's (or an extension's) estimate, against ``budget``.

    Parameters
    ----------
    options : FillOptions
    image : (int, int, int)
        The shape of the image filled: (height, width, channels); an extension's canvas.
    hole : (int, int)
        The (height, width) of the hole's bounding box (:func:`quilting.hole_box`).
    budget : Budget
    texture : (int, int), optional
        The (height, width) of the texture the blocks come from, when not the image.
    itemsize : int
        Bytes per sample of the image (1 or 2).
    extra_bytes : int
        Bytes held beside the fill (the uploads).

    Raises
    ------
    Problem
        422 ``job_too_large`` naming the predicted memory or time, the budget and what to
        change.
    """
    try:
        return quilting.estimate_fill(
            options,
            image,
            hole,
            texture=texture,
            backend=_backend(options),
            itemsize=itemsize,
            budget=budget,
            extra_bytes=extra_bytes,
        )
    except quilting.JobTooLargeError as exc:
        raise _too_large(exc, budget, "job_memory_bytes and job_timeout_s") from None


def extension_hole(height: int, width: int, options: ExtendOptions) -> tuple[int, int]:
    """The bounding box (height, width) of what an extension of a ``height`` x ``width`` image
    synthesizes, from its margins alone (what :func:`quilting.hole_box` gives of its hole)."""

    def extent(before: int, after: int, side: int, across: bool) -> int:
        # A margin across the other axis reaches every line of this one.
        if across or (before and after):
            return before + side + after
        return before or after

    rows = extent(options.top, options.bottom, height, bool(options.left or options.right))
    cols = extent(options.left, options.right, width, bool(options.top or options.bottom))
    if not (rows and cols):
        return 0, 0
    return rows, cols


def predicted_tile(
    data: bytes, budget: Budget, blend: str = "none", method: str = "cut"
) -> Estimate:
    """A ``/tile`` call's estimate from its image's header (already checked), against
    ``budget`` (the sandbox's: ``job_memory_bytes`` and ``sandbox_timeout_s``), for the
    options' ``blend`` and ``method`` (as :func:`quilting.make_tileable` costs them).

    Raises
    ------
    Problem
        422 ``job_too_large`` naming the predicted memory or time, the budget and the largest
        image that fits.
    """
    header = image_header(data, max_pixels=_ANY)
    shape = (header.height, header.width, header.channels)
    try:
        return quilting.estimate_tile(
            shape,
            itemsize=header.bit_depth // 8,
            budget=budget,
            extra_bytes=len(data),
            blend=blend,
            method=method,
        )
    except quilting.JobTooLargeError as exc:
        raise _too_large(exc, budget, "job_memory_bytes and sandbox_timeout_s") from None


def _too_large(exc: QuiltingError, budget: Budget, settings: str) -> Problem:
    return Problem(
        422,
        "job_too_large",
        f"{exc.message} (settings {settings})",
        budget_bytes=budget.memory_bytes,
        budget_seconds=budget.seconds,
    )


def _backend(options: QuiltOptions | FillOptions | WangOptions) -> str:
    """The backend the cost model counts a job's on (``auto`` runs ``fft`` on a machine
    without a GPU, and the model costs the GPU's as the slower)."""
    return "gl" if options.backend == "gl" else "fft"


def _extractions(spec: JobInput, options: JobOptions, budget: Budget) -> None:
    """Each extraction of a job that extracts alpha from its photos, against ``budget``."""
    assert isinstance(options, SynthesisOptions | MatteOptions), "what takes photos"
    method = AlphaOptions(method=options.matting)
    photos = spec.layers if spec.operation == "matte" else spec.textures
    for data, marks in zip(photos, spec.marks(len(photos)), strict=True):
        if marks != (None, None):
            estimate_extract(method, _hw(image_header(data, max_pixels=_ANY)), budget=budget)


def _channels(spec: JobInput, header: ImageHeader, index: int = 0) -> int:
    """The channels the job quilts of its ``index``-th photo: 4 when its alpha is extracted
    first, else its header's."""
    photos = spec.layers if spec.operation == "matte" else spec.textures
    if spec.marks(len(photos))[index] != (None, None):
        return 4
    return header.channels


def _estimate(spec: JobInput, options: JobOptions, budget: Budget) -> Estimate | None:
    assert not isinstance(options, AlphaOptions), "costed by estimate_extract"
    output = (spec.height, spec.width)
    backend = _backend(options)
    if isinstance(options, MatteOptions):
        return _matte(spec, options, backend, budget)
    header = image_header(spec.texture, max_pixels=_ANY)
    channels = _channels(spec, header)
    texture = (header.height, header.width, channels)
    itemsize = header.bit_depth // 8
    if isinstance(options, ExtendOptions):
        return predicted_fill(
            options,
            (*output, header.channels),
            extension_hole(header.height, header.width, options),
            budget,
            texture=(header.height, header.width),
            itemsize=itemsize,
            extra_bytes=spec.nbytes,
        )
    if isinstance(options, FillOptions):
        return None  # its hole is known once the sandbox has decoded the mask
    if isinstance(options, WangOptions | SynthesisOptions):
        # The examples' atlas (the one texture itself when there is no other, untransformed).
        sizes = [(header.height, header.width)]
        sizes += [_hw(image_header(data, max_pixels=_ANY)) for data in spec.textures[1:]]
        texture = (*examples_shape(sizes, options), channels)
    if isinstance(options, WangOptions):
        return quilting.estimate_wang(
            options, texture, backend=backend, itemsize=itemsize, budget=budget
        )
    if isinstance(options, TransferOptions):
        return quilting.estimate_transfer(
            options,
            texture,
            output,
            guide=guide_channels(options),
            backend=backend,
            itemsize=itemsize,
            budget=budget,
        )
    assert isinstance(options, SynthesisOptions)
    return quilting.estimate_synthesis(
        options, texture, output, backend=backend, itemsize=itemsize, budget=budget
    )


def _matte(spec: JobInput, options: MatteOptions, backend: str, budget: Budget) -> Estimate:
    """Each layer quilted at most at the target's size over ``scale``."""
    size = (
        max(options.block, math.ceil(spec.height / options.scale)),
        max(options.block, math.ceil(spec.width / options.scale)),
    )
    layers = []
    for index, data in enumerate(spec.layers):
        header = image_header(data, max_pixels=_ANY)
        shape = (header.height, header.width, _channels(spec, header, index))
        layers.append((shape, header.bit_depth // 8))
    return estimate_matte(
        options, (spec.height, spec.width), layers, size, backend=backend, budget=budget
    )


def _hw(header: ImageHeader) -> tuple[int, int]:
    return header.height, header.width


#: The headers were checked against the pixel limits already: read them here without one.
_ANY = 1 << 62
