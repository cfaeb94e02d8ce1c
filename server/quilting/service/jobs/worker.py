"""Computing one job, in a worker thread or a worker process.

A job is computed by :func:`compute`: its uploaded files decoded
(:func:`quilting.service.uploads.decode`: the API process keeps them compressed), the engine
with a progress callback that reports progress, stops when the job is cancelled and fails it
past the time limit (the engine checks between wavefront levels), then PNG encoding of the
result and companions. Cost backends are built per job in the worker (a GL context is bound to
the thread that made it). A job that runs out of memory fails with ``job_too_large``.

A worker process runs :func:`process_main`: it caps its memory at what it holds once started
plus the job memory budget (``job_memory_bytes``), loads the kernels, and computes the jobs it
is sent. The pool that feeds workers and records what they report is
:mod:`quilting.service.jobs.pool`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from multiprocessing.connection import Connection
from typing import Any

from quilting import (
    AlphaOptions,
    Budget,
    CancelledError,
    Extracted,
    JobTooLargeError,
    QuiltingError,
    __version__,
    apply_layout,
    extract_alpha,
    warm_up,
)
from quilting.api import extend, fill, matte, synthesize, transfer, wang_tiles
from quilting.backends import get_backend
from quilting.io import encode_png
from quilting.options import (
    ExtendOptions,
    FillOptions,
    MatteOptions,
    SynthesisOptions,
    TransferOptions,
    WangOptions,
)
from quilting.service.budgets import job_budget
from quilting.service.jobs.model import JobInput, Status
from quilting.service.memory_limit import describe_bytes, limit_memory
from quilting.service.problems import Problem, from_engine
from quilting.service.uploads import Decoded, decode

log = logging.getLogger("quilting.service")


class JobTimeoutError(QuiltingError):
    """A job ran past the service's time limit."""

    code = "job_timeout"


Report = Callable[[float, str], None]


def compute(
    spec: JobInput,
    timeout_s: float,
    report: Report,
    cancelled: Callable[[], bool],
    memory_bytes: int | None = None,
    budget_bytes: int | None = None,
) -> tuple[Status, dict[str, Any]]:
    """Run one job; returns its final status and the fields to store with it.

    Parameters
    ----------
    spec : JobInput
        The uploaded files and engine options; its ``operation`` says whether to synthesize,
        to transfer onto its ``target``, to matte, to fill, to extend or to make a Wang tile
        set. The files are decoded here, at the start of the job and within its time limit.
    timeout_s : float
        Time limit of the job.
    report : callable
        ``report(fraction, stage)`` after each wavefront level.
    cancelled : callable
        True once the job should stop.
    memory_bytes : int, optional
        The memory budget this process was limited to (``job_memory_bytes``), named by the
        ``job_too_large`` problem of a job that runs out of memory; None where nothing limits
        the job (thread workers).
    budget_bytes : int, optional
        The job's memory budget as the cost model counts it (beyond the worker's own memory;
        default ``memory_bytes``): the engine sizes its batches to it, as the API process
        did when it predicted the job's cost.
    """
    budget_bytes = memory_bytes if budget_bytes is None else budget_bytes
    budget = None if budget_bytes is None else job_budget(budget_bytes, None)
    try:
        return _compute(spec, timeout_s, report, cancelled, budget)
    except MemoryError:
        # Raised by numpy (or zlib, Pillow) once the process's data segment is full: this job
        # alone fails, and the frames that held its arrays are gone once this returns.
        return Status.FAILED, {"error": job_too_large(memory_bytes).body()}


def job_too_large(memory_bytes: int | None) -> Problem:
    """422 ``job_too_large``: the job ran out of its memory budget and was stopped."""
    if memory_bytes is None:
        detail = (
            "the job ran out of memory and was stopped (this worker has no per-job limit: "
            "job_memory_bytes caps the worker processes of worker_mode=process)"
        )
    else:
        detail = (
            f"the job needed more than its memory budget of {describe_bytes(memory_bytes)} "
            "(setting job_memory_bytes) and was stopped; a smaller texture or output, or a "
            "larger block, needs less"
        )
    return Problem(422, "job_too_large", detail)


def _compute(
    spec: JobInput,
    timeout_s: float,
    report: Report,
    cancelled: Callable[[], bool],
    budget: Budget | None,
) -> tuple[Status, dict[str, Any]]:
    deadline = time.monotonic() + timeout_s

    def go_on() -> None:
        if cancelled():
            raise CancelledError("the job was cancelled")
        if time.monotonic() > deadline:
            raise JobTimeoutError(
                f"the job ran longer than {timeout_s:g} s (setting job_timeout_s)"
            )

    def progress(fraction: float, stage: str) -> None:
        go_on()
        report(round(fraction, 4), stage)

    try:
        images = decode(spec)
    except Problem as problem:
        return Status.FAILED, {"error": problem.body()}
    try:
        go_on()  # decoding counts against the time limit (it cannot be stopped half-way)
        options = spec.engine_options()
        if isinstance(options, AlphaOptions):
            return Status.DONE, _extract(spec, options, images, progress, report, budget)
        if isinstance(options, MatteOptions):
            return Status.DONE, _matte(spec, options, images, progress, report, budget)
        if isinstance(options, FillOptions):
            return Status.DONE, _fill(spec, options, images, progress, report, budget)
        if isinstance(options, WangOptions):
            return Status.DONE, _wang(spec, options, images, progress, report, budget)
        if isinstance(options, TransferOptions):
            assert images.target is not None, "a transfer job has a target"
            result = transfer(
                images.texture,
                images.target,
                options,
                progress=progress,
                source_mask=images.source_mask,
                budget=budget,
            )
        else:
            assert isinstance(options, SynthesisOptions), "the operations' classes"
            # Several examples go to the engine as a list (a mask and a companion map per
            # example); one texture as the array it always was.
            result = synthesize(
                images.examples or images.texture,
                (spec.height, spec.width),
                options,
                progress=progress,
                source_mask=images.source_masks or images.source_mask,
                budget=budget,
                **_marks(images, bool(images.examples)),
            )
    except CancelledError:
        return Status.CANCELLED, {}
    except JobTooLargeError as exc:
        # The worker's own budget, where it is smaller than the one the job was accepted under
        # (a Redis worker on a smaller machine than the replica).
        detail = f"{exc.message} (setting job_memory_bytes of the worker)"
        return Status.FAILED, {"error": Problem(422, exc.code, detail).body()}
    except QuiltingError as exc:
        return Status.FAILED, {"error": from_engine(exc).body()}
    report(1.0, "encoding")
    # No job id or time in the metadata: the same request gives the same bytes.
    meta: dict[str, Any] = {**result.layout.meta, "width": spec.width, "height": spec.height}
    stats = result.stats
    figures: dict[str, Any] = {
        "seam_error_mean": stats.seam_error_mean,
        "seam_error_total": stats.seam_error_total,
        "largest_copy": stats.largest_copy,
        "unused": stats.unused,
    }
    if stats.correspondence_error is not None:
        figures["correspondence_error"] = stats.correspondence_error
    if images.trimaps:
        figures["extracted"] = _summaries(images, result.extracted)
    return Status.DONE, {
        "png": encode_png(result.image, metadata=meta),
        "companions": {
            name: encode_png(
                apply_layout(
                    result.layout,
                    images.example_companions.get(name) or image,
                    kind=spec.kind_of(name),
                ),
                metadata=meta,
            )
            for name, image in images.companions.items()
        },
        "layout": result.layout.to_json().encode(),
        "timings": dict(result.timings),
        "backend": result.backend,
        "renderer": result.renderer,
        "fallback": result.fallback,
        "stats": figures,
    }


def _matte(
    spec: JobInput,
    options: MatteOptions,
    images: Decoded,
    progress: Report,
    report: Report,
    budget: Budget | None,
) -> dict[str, Any]:
    """A matte job's result fields: the image, the normals and patches used, the light."""
    assert images.target is not None and images.silhouette is not None, "a matte job has both"
    result = matte(
        images.target,
        images.layers,
        options,
        silhouette=images.silhouette,
        normals=images.normals,
        progress=progress,
        budget=budget,
        **_marks(images, True),
    )
    report(1.0, "encoding")
    meta: dict[str, Any] = {
        "operation": "matte",
        **options.to_dict(),
        "light_used": list(result.light),
        "width": spec.width,
        "height": spec.height,
    }
    first = result.layers[0]
    return {
        "png": encode_png(result.image, metadata=meta),
        "companions": {
            "normals": encode_png(result.normal_map(), metadata=meta),
            "clusters": encode_png(result.patch_map(), metadata=meta),
        },
        "layout": None,
        "timings": dict(result.timings),
        "backend": first.backend,
        "renderer": first.renderer,
        "fallback": next((layer.fallback for layer in result.layers if layer.fallback), None),
        "stats": {
            "light": list(result.light),
            "albedo": result.albedo,
            "ambient_fit": result.ambient_fit,
            "clusters": int(result.clusters.max()) + 1,
            "patches": int(result.patches.max()) + 1,
            "layer_size": list(first.image.shape[:2][::-1]),
            **(
                {
                    "extracted": _summaries(
                        images, [e for layer in result.layers for e in layer.extracted]
                    )
                }
                if images.trimaps
                else {}
            ),
        },
    }


def _fill(
    spec: JobInput,
    options: FillOptions,
    images: Decoded,
    progress: Report,
    report: Report,
    budget: Budget | None,
) -> dict[str, Any]:
    """A fill's or an extension's result fields: the image, its companions filled the same
    way (copied from where the image's filled pixels came from), and its layout (every block
    placed, where from and the pixels it took: :class:`quilting.FillLayout`)."""
    if isinstance(options, ExtendOptions):
        result = extend(images.texture, options, progress=progress, budget=budget)
    else:
        assert images.mask is not None, "a fill job has a mask"
        result = fill(
            images.texture,
            images.mask,
            options,
            texture=images.source,
            progress=progress,
            budget=budget,
        )
    report(1.0, "encoding")
    meta = _meta(spec, options)
    return {
        "png": encode_png(result.image, metadata=meta),
        "companions": {
            name: encode_png(result.apply(image), metadata=meta)
            for name, image in images.companions.items()
        },
        "layout": result.layout.to_json().encode(),
        "timings": dict(result.timings),
        "backend": result.backend,
        "renderer": None,
        "fallback": None,
        "stats": {
            "seam_error_mean": result.seam_error,
            "blocks": result.blocks,
            "filled_pixels": int(result.filled.sum()),
        },
    }


def _wang(
    spec: JobInput,
    options: WangOptions,
    images: Decoded,
    progress: Report,
    report: Report,
    budget: Budget | None,
) -> dict[str, Any]:
    """A Wang tile set's result fields: the atlas of its tiles (the result), and its manifest
    (each tile's place in the atlas and edge colours) where a synthesis keeps its layout."""
    tiles = wang_tiles(images.examples or images.texture, options, progress=progress, budget=budget)
    report(1.0, "encoding")
    # No job id or time in the metadata: the same request gives the same bytes.
    meta: dict[str, Any] = {**tiles.meta, "width": spec.width, "height": spec.height}
    return {
        "png": encode_png(tiles.atlas(), metadata=meta),
        "companions": {},
        "layout": tiles.to_json().encode(),
        "timings": dict(tiles.timings),
        "backend": tiles.backend,
        "renderer": tiles.renderer,
        "fallback": tiles.fallback,
        "stats": {
            "colors": tiles.colors,
            "tile": tiles.tile,
            "tiles": len(tiles.edges),
            "atlas": [spec.width, spec.height],
        },
    }


def _meta(spec: JobInput, options: FillOptions | AlphaOptions) -> dict[str, Any]:
    """The PNG metadata of a job's result: its operation, options, size and the version. No
    job id or time: the same request gives the same bytes."""
    return {
        "operation": spec.operation,
        **options.to_dict(),
        "width": spec.width,
        "height": spec.height,
        "version": __version__,
    }


def _marks(images: Decoded, several: bool) -> dict[str, Any]:
    """The ``trimap`` and ``scribbles`` keywords of a job's engine call: none for a job that
    extracts no alpha, one list per kind (one map or None per photo) when ``several``, else
    the one photo's maps."""
    if not images.trimaps:
        return {}
    if several:
        return {"trimap": list(images.trimaps), "scribbles": list(images.scribbles)}
    return {"trimap": images.trimaps[0], "scribbles": images.scribbles[0]}


def _summaries(images: Decoded, extracted: Sequence[Extracted]) -> list[dict[str, Any] | None]:
    """One entry per photo of the job (``stats["extracted"]``, the ``Quilting-Extracted``
    header): its extraction's summary, None for a photo without a trimap or scribbles. The
    engine lists only the extractions made, in the photos' order."""
    made = iter(extracted)
    return [
        None if (trimap is None and strokes is None) else next(made).summary()
        for trimap, strokes in zip(images.trimaps, images.scribbles, strict=True)
    ]


def _extract(
    spec: JobInput,
    options: AlphaOptions,
    images: Decoded,
    progress: Report,
    report: Report,
    budget: Budget | None,
) -> dict[str, Any]:
    """An alpha extraction's result fields: the RGBA texture, and its summary in the stats."""
    found = extract_alpha(
        images.texture,
        images.trimaps[0],
        images.scribbles[0],
        options,
        progress=progress,
        budget=budget,
    )
    report(1.0, "encoding")
    meta = _meta(spec, options)
    return {
        "png": encode_png(found.image, metadata=meta),
        "companions": {},
        "layout": None,
        "timings": dict(found.timings),
        "backend": None,
        "renderer": None,
        "fallback": None,
        "stats": {"extracted": [found.summary()]},
    }


def shutdown_error() -> dict[str, Any]:
    """The error document of a job the service stopped before it finished (drain grace over)."""
    return Problem(
        503,
        "shutdown",
        "the service shut down before the job finished (drain_grace_s ran out); submit it again",
    ).body()


def internal_error(detail: str) -> dict[str, Any]:
    """The fields of a job failed by a bug (500 ``internal_error``), never by its input."""
    return {"error": Problem(500, "internal_error", detail).body()}


def cap_memory(memory_bytes: int | None) -> int | None:
    """Load what every job needs, then cap this worker process's memory at what it holds
    now plus ``memory_bytes`` (:func:`~quilting.service.memory_limit.limit_memory`); the budget,
    or None where nothing could be limited (a job that runs out then says so) or no budget
    was given (nothing is capped).

    Loaded before the cap is measured, so that no job pays for them: the engine (imported
    with this module), the FFT backend (with scipy.fft), which jobs build, and the compiled
    kernels (:func:`quilting.warm_up`).
    """
    get_backend("fft")
    warm_up()
    if memory_bytes is None:
        return None
    return memory_bytes if limit_memory(memory_bytes) is not None else None


def process_main(conn: Connection, memory_bytes: int | None = None) -> None:
    """Body of a worker process: compute the jobs sent over ``conn``, report back on it.

    With ``memory_bytes``, the process first caps its memory at what it holds after its
    imports plus that budget (:func:`~quilting.service.memory_limit.limit_memory`): a job that
    needs more fails with ``job_too_large`` and the process takes the next job.

    The pump sends ``("job", job id, input, time limit)``, ``("cancel", job id)`` and, to
    stop, ``None``. A cancel can reach the process after its job's last progress check (the
    pump sends it as soon as the job is cancelled, without knowing whether the job is about
    to end), so one may be waiting when the next job is expected: a cancel met there is for
    a job that is over, and is dropped.
    """
    memory_bytes = cap_memory(memory_bytes)
    while True:
        message = conn.recv()
        if message is None:
            return
        if message[0] != "job":  # a late cancel of a finished job
            continue
        _, job_id, spec, timeout_s = message
        stop = False

        def cancelled(job_id: str = job_id) -> bool:
            nonlocal stop
            while conn.poll():  # control messages: ("cancel", job id)
                kind, target = conn.recv()
                stop = stop or (kind == "cancel" and target == job_id)
            return stop

        def report(fraction: float, stage: str) -> None:
            conn.send(("progress", fraction, stage))

        try:
            status, fields = compute(spec, timeout_s, report, cancelled, memory_bytes)
        except Exception:  # a bug must fail the job, never the worker
            log.exception("job %s failed unexpectedly", job_id)
            status, fields = Status.FAILED, internal_error("the job failed unexpectedly")
        try:
            conn.send(("end", status, fields))
        except MemoryError:  # the results did not fit in what the budget left
            del fields
            conn.send(("end", Status.FAILED, {"error": job_too_large(memory_bytes).body()}))
