"""Workers that run jobs off the event loop: processes by default, or threads.

A job is computed by :func:`compute`: its uploaded files decoded
(:func:`quilting.service.uploads.decode`: the API process keeps them compressed), the engine
with a progress callback that reports progress, stops when the job is cancelled and fails it
past the time limit (the engine checks between wavefront levels), then PNG encoding of the
result and companions. Cost backends are built per job in the worker (a GL context is bound to
the thread that made it). A job that runs out of memory fails with ``job_too_large``.

The engine spends much of its time in small numpy calls that hold the GIL, so threads in one
process use about one core whatever their number; ``worker_mode="process"`` (the default) runs
each worker in a process of its own, fed by a pump thread here that turns the worker's messages
into store updates. Each worker process caps its memory at what it holds once started plus
the job memory budget (``job_memory_bytes``); threads cannot be limited one by one. A crashed
worker process fails its job and is replaced.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import queue
import threading
import time
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import Any, Protocol

from quilting import Budget, CancelledError, JobTooLargeError, QuiltingError, apply_layout, warm_up
from quilting.api import matte, synthesize, transfer
from quilting.backends import get_backend
from quilting.io import encode_png
from quilting.service.budgets import job_budget
from quilting.service.jobs.model import Job, JobInput, Status
from quilting.service.problems import Problem, from_engine
from quilting.service.sandbox import describe_bytes, limit_memory
from quilting.service.settings import Settings
from quilting.service.uploads import Decoded, decode

log = logging.getLogger("quilting.service")

#: How often a pump thread looks at its job's cancel flag while the worker computes.
PUMP_POLL_S = 0.05


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
        to transfer onto its ``target`` or to matte. The files are decoded here, at the start
        of the job and within its time limit.
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
        if spec.operation == "matte":
            return Status.DONE, _matte(spec, images, progress, report, budget)
        if spec.operation == "transfer":
            assert images.target is not None, "a transfer job has a target"
            result = transfer(
                images.texture,
                images.target,
                progress=progress,
                source_mask=images.source_mask,
                budget=budget,
                **spec.options,
            )
        else:
            result = synthesize(
                images.texture,
                (spec.height, spec.width),
                progress=progress,
                source_mask=images.source_mask,
                budget=budget,
                **spec.options,
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
    return Status.DONE, {
        "png": encode_png(result.image, metadata=meta),
        "companions": {
            name: encode_png(
                apply_layout(result.layout, image, kind=spec.kind_of(name)), metadata=meta
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
    spec: JobInput, images: Decoded, progress: Report, report: Report, budget: Budget | None
) -> dict[str, Any]:
    """A matte job's result fields: the image, the normals and patches used, the light."""
    assert images.target is not None and images.silhouette is not None, "a matte job has both"
    result = matte(
        images.target,
        images.layers,
        silhouette=images.silhouette,
        normals=images.normals,
        progress=progress,
        budget=budget,
        **spec.options,
    )
    report(1.0, "encoding")
    meta: dict[str, Any] = {
        "operation": "matte",
        **spec.options,
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
        },
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
    now plus ``memory_bytes`` (:func:`~quilting.service.sandbox.limit_memory`); the budget,
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


def _process_main(conn: Connection, memory_bytes: int | None = None) -> None:
    """Body of a worker process: compute the jobs sent over ``conn``, report back on it.

    With ``memory_bytes``, the process first caps its memory at what it holds after its
    imports plus that budget (:func:`~quilting.service.sandbox.limit_memory`): a job that
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


class JobBook(Protocol):
    """What the workers write of a job's life: the in-memory store
    (:class:`~quilting.service.jobs.memory.Store`) is one."""

    def start(self, job: Job) -> bool:
        """Mark ``job`` running; False if it was cancelled meanwhile."""

    def update(self, job: Job, **changes: Any) -> None:
        """Record progress."""

    def finish(self, job: Job, status: Status, **changes: Any) -> None:
        """Record the end."""

    def fail_queued(self, job: Job, error: dict[str, Any]) -> bool:
        """Fail a job that never started (shutdown); False if it had."""


class Runner:
    """A fixed pool of workers fed by a FIFO queue of jobs."""

    def __init__(self, store: JobBook, settings: Settings) -> None:
        self.store = store
        self.settings = settings
        self.queue: queue.Queue[Job | None] = queue.Queue()
        self.threads: list[threading.Thread] = []
        self.processes = settings.worker_mode == "process"
        self._context = multiprocessing.get_context("spawn")
        # Set by stop(): no job is started and no worker process is spawned any more.
        self.stopping = threading.Event()
        self._alive: dict[int, multiprocessing.process.BaseProcess] = {}
        # Fixed once: a budget derived from the available memory must not change with it.
        self.memory_budget = settings.memory_budget

    def start(self) -> None:
        target = self._pump if self.processes else self._work
        for index in range(self.settings.compute_workers):
            thread = threading.Thread(target=target, name=f"quilting-worker-{index}", daemon=True)
            thread.start()
            self.threads.append(thread)

    def submit(self, job: Job) -> None:
        self.queue.put(job)

    def stop(self, timeout: float | None = None) -> None:
        """Let the workers finish their current job within ``timeout`` seconds, and exit.

        Jobs still queued fail at once with ``shutdown`` (no worker would be left to run them);
        in process mode, a job still running after ``timeout`` fails with ``shutdown`` too and
        its worker process is stopped, not replaced.
        """
        self.stopping.set()
        while True:
            try:
                job = self.queue.get_nowait()
            except queue.Empty:
                break
            if job is not None:
                self._shut_out(job)
        for _ in self.threads:
            self.queue.put(None)
        deadline = None if timeout is None else time.monotonic() + timeout
        for thread in self.threads:
            thread.join(None if deadline is None else max(0.0, deadline - time.monotonic()))
        if not self.processes:
            return  # a thread cannot be stopped; the process exits without it
        overdue = list(self._alive.values())
        for process in overdue:
            if process.is_alive():
                process.terminate()
        for thread in self.threads:
            thread.join(5)
        for process in overdue:
            process.join(5)  # reaped: nothing of the runner outlives stop()

    def _shut_out(self, job: Job) -> None:
        """Fail a job taken off the queue during shutdown, before it started."""
        if self.store.fail_queued(job, shutdown_error()):
            log.warning("job %s failed: the service shut down before it started", job.id)

    # --- threads ---------------------------------------------------------------------------

    def _work(self) -> None:
        warm_up()  # as a worker process does, before its first job
        while (job := self.queue.get()) is not None:
            if self.stopping.is_set():
                self._shut_out(job)
                continue
            if not self.store.start(job):
                continue
            spec = job.input
            assert spec is not None
            try:
                status, fields = compute(
                    spec,
                    self.settings.job_timeout_s,
                    lambda fraction, stage: self.store.update(job, progress=fraction, stage=stage),
                    job.cancel.is_set,
                    budget_bytes=self.settings.memory_budget,
                )
            except Exception:  # a bug must fail the job, never the worker
                log.exception("job %s failed unexpectedly", job.id)
                status, fields = Status.FAILED, internal_error("the job failed unexpectedly")
            self.store.finish(job, status, **fields)

    # --- processes -------------------------------------------------------------------------

    def _spawn(self) -> tuple[multiprocessing.process.BaseProcess, Connection]:
        mine, theirs = self._context.Pipe()
        process = self._context.Process(
            target=_process_main, args=(theirs, self.memory_budget), daemon=True
        )
        process.start()
        theirs.close()
        return process, mine

    def _pump(self) -> None:
        """Feed one worker process and relay what it says about its jobs."""
        slot = threading.get_ident()
        process, conn = self._spawn()
        self._alive[slot] = process
        try:
            while (job := self.queue.get()) is not None:
                if self.stopping.is_set():
                    self._shut_out(job)
                    continue
                if not self.store.start(job):
                    continue
                try:
                    status, fields = self._relay(job, conn, process)
                except (EOFError, OSError):
                    if self.stopping.is_set():
                        # stop() ended the worker past the drain grace: no replacement.
                        log.warning("job %s failed: the service shut down during it", job.id)
                        self.store.finish(job, Status.FAILED, error=shutdown_error())
                        return
                    log.error("worker process %s died during job %s", process.pid, job.id)
                    status, fields = Status.FAILED, internal_error("the worker process died")
                    process, conn = self._spawn()
                    self._alive[slot] = process
                self.store.finish(job, status, **fields)
            with contextlib.suppress(OSError):  # the worker may be gone already
                conn.send(None)
            process.join(5)
        finally:
            if process.is_alive():
                process.terminate()
            self._alive.pop(slot, None)

    def _relay(
        self, job: Job, conn: Connection, process: multiprocessing.process.BaseProcess
    ) -> tuple[Status, dict[str, Any]]:
        conn.send(("job", job.id, job.input, self.settings.job_timeout_s))
        asked_to_cancel = False
        while True:
            # Checked on every pass: progress messages may arrive without a pause.
            if job.cancel.is_set() and not asked_to_cancel:
                conn.send(("cancel", job.id))
                asked_to_cancel = True
            if conn.poll(PUMP_POLL_S):
                message = conn.recv()
                if message[0] == "progress":
                    self.store.update(job, progress=message[1], stage=message[2])
                    continue
                _, status, fields = message
                return Status(status), fields
            if not process.is_alive():
                raise EOFError("worker process exited")
