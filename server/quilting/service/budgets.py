"""A job's predicted cost against the service's budgets, from its uploads' headers alone.

The API process knows each upload's size, channels and depth from its header (see
:func:`quilting.io.image_header`); with the options that is all the cost model needs
(:func:`quilting.estimate_synthesis`, :func:`quilting.estimate_transfer`). A job predicted to
take more memory than ``job_memory_bytes`` beyond a worker's own, or longer than
``job_timeout_s``, is answered 422 ``job_too_large`` before it is queued, with the prediction,
the budget and what would fit. A matte's layers are quilted at the silhouette's extent over
``scale``, known only once its pixels are read: the whole target over ``scale`` bounds it.
"""

from __future__ import annotations

import math

import quilting
from quilting import BASE_BYTES, Budget, Estimate, QuiltingError, estimate_matte
from quilting.api import guide_channels
from quilting.io import image_header
from quilting.options import MatteOptions, QuiltOptions, SynthesisOptions, TransferOptions
from quilting.service.jobs import JobInput
from quilting.service.problems import Problem, from_engine


def job_budget(memory_bytes: int, seconds: float | None) -> Budget:
    """The budget of one job: ``memory_bytes`` beyond what a worker holds once started (the
    cost model counts the interpreter in), and ``seconds`` (None: no time budget)."""
    return Budget(memory_bytes=BASE_BYTES + memory_bytes, seconds=seconds)


def predicted(spec: JobInput, options: QuiltOptions, budget: Budget) -> Estimate:
    """The job's estimate, once checked against ``budget``.

    ``spec`` holds the uploads as they came, already header-checked (their headers parse), and
    the output's size.

    Raises
    ------
    Problem
        422 ``job_too_large`` naming the predicted memory or time, the budget and what to
        change.
    """
    try:
        return _estimate(spec, options, budget)
    except quilting.JobTooLargeError as exc:
        raise _too_large(exc, budget, "job_memory_bytes and job_timeout_s") from None
    except QuiltingError as exc:  # options the shapes refuse (a tileable side under a block)
        raise from_engine(exc) from None


def predicted_tile(data: bytes, budget: Budget, blend: str = "none") -> Estimate:
    """A ``/tile`` call's estimate from its image's header (already checked), against
    ``budget`` (the sandbox's: ``job_memory_bytes`` and ``sandbox_timeout_s``), for the
    options' ``blend``.

    Raises
    ------
    Problem
        422 ``job_too_large`` naming the predicted memory or time, the budget and the largest
        image that fits.
    """
    header = image_header(data, max_pixels=_ANY)
    try:
        return quilting.estimate_tile(
            (header.height, header.width, header.channels),
            itemsize=header.bit_depth // 8,
            budget=budget,
            extra_bytes=len(data),
            blend=blend,
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


def _estimate(spec: JobInput, options: QuiltOptions, budget: Budget) -> Estimate:
    output = (spec.height, spec.width)
    backend = "gl" if options.backend == "gl" else "fft"
    if isinstance(options, MatteOptions):
        return _matte(spec, options, backend, budget)
    header = image_header(spec.texture, max_pixels=_ANY)
    texture = (header.height, header.width, header.channels)
    itemsize = header.bit_depth // 8
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
    for data in spec.layers:
        header = image_header(data, max_pixels=_ANY)
        layers.append(((header.height, header.width, header.channels), header.bit_depth // 8))
    return estimate_matte(
        options, (spec.height, spec.width), layers, size, backend=backend, budget=budget
    )


#: The headers were checked against the pixel limits already: read them here without one.
_ANY = 1 << 62
