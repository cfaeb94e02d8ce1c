"""Computing one job, in a worker thread or a worker process.

A job is computed by :func:`compute`: its uploaded files decoded
(:func:`quilting.service.uploads.decode`: the API process keeps them compressed), the engine
(each operation's call and result fields: :mod:`quilting.service.jobs.results`) with a
progress callback that reports progress, stops when the job is cancelled and fails it
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
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import Any

from quilting import (
    Budget,
    CancelledError,
    JobTooLargeError,
    QuiltingError,
    warm_up,
)
from quilting.backends import get_backend
from quilting.service.budgets import job_budget
from quilting.service.jobs.job_input import JobInput
from quilting.service.jobs.model import Status
from quilting.service.jobs.results import Report, result_fields
from quilting.service.memory_limit import describe_bytes, limit_memory
from quilting.service.problems import Problem, from_engine
from quilting.service.uploads import decode

log = logging.getLogger("quilting.service")


class JobTimeoutError(QuiltingError):
    """A job ran past the service's time limit."""

    code = "job_timeout"


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
        fields = result_fields(spec, options, images, progress, report, budget)
    except CancelledError:
        return Status.CANCELLED, {}
    except JobTooLargeError as exc:
        # The worker's own budget, where it is smaller than the one the job was accepted under
        # (a Redis worker on a smaller machine than the replica).
        detail = f"{exc.message} (setting job_memory_bytes of the worker)"
        return Status.FAILED, {"error": Problem(422, exc.code, detail).body()}
    except QuiltingError as exc:
        return Status.FAILED, {"error": from_engine(exc).body()}
    return Status.DONE, fields


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
