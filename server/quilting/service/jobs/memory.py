"""Jobs in this process: the in-memory job store (caps, expiry, idempotency, per-key
visibility, metrics) and :class:`LocalQueue`, the default queue, whose workers
(:class:`~quilting.service.jobs.pool.Runner`) are this process's.

Thread-safe: the event loop submits and reads, worker threads update. Job state changes bump a
version number that event streams watch.
"""

from __future__ import annotations

import asyncio
import bisect
import contextlib
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

from quilting.backends import backend_renderer
from quilting.service.jobs.model import HISTOGRAM_BUCKETS, Figures, Job, Status
from quilting.service.jobs.pool import Runner
from quilting.service.problems import Problem, idempotency_conflict, job_not_found, queue_full
from quilting.service.settings import Settings


class Store:
    """In-memory jobs with the caps of :class:`Settings` and simple Prometheus counters."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.lock = threading.Lock()
        self.jobs: OrderedDict[str, Job] = OrderedDict()
        self.queued = 0
        self.running = 0
        self.kept: OrderedDict[str, int] = OrderedDict()  # finished job id -> result bytes
        # Final jobs' ids in the order they ended: whose records are forgotten first.
        self.records: OrderedDict[str, None] = OrderedDict()
        self.kept_bytes = 0
        self.idempotency: dict[tuple[str | None, str], tuple[str, str]] = {}
        self.finished_total: dict[str, int] = {s.value: 0 for s in Status if s.final}
        self.seconds_buckets = [0] * (len(HISTOGRAM_BUCKETS) + 1)
        self.seconds_sum = 0.0
        self.pixels_total = 0

    # --- submission and lookup -------------------------------------------------------------

    def add(self, job: Job, idempotency: tuple[str, str] | None = None) -> tuple[Job, bool]:
        """Register a new queued job; returns ``(job, True)``, or the earlier job for a repeated
        idempotency key and body as ``(earlier, False)``.

        Raises
        ------
        Problem
            503 ``queue_full`` when the queue is at its cap; 409 ``idempotency_conflict`` when the
            key was used with another body.
        """
        self.expire()  # a key whose job's results have expired is free again
        with self.lock:
            if idempotency is not None:
                key, digest = idempotency
                seen = self.idempotency.get((job.owner, key))
                if seen is not None and seen[1] in self.jobs:
                    if seen[0] != digest:
                        raise idempotency_conflict()
                    return self.jobs[seen[1]], False
            if self.queued >= self.settings.max_queued:
                raise queue_full(self.queued)
            self.jobs[job.id] = job
            self.queued += 1
            if idempotency is not None:
                job.idempotency_key = (job.owner, idempotency[0])
                self.idempotency[job.idempotency_key] = (idempotency[1], job.id)
            return job, True

    def get(self, job_id: str, owner: str | None) -> Job:
        """The job ``job_id`` if ``owner`` may see it, else 404 ``job_not_found``."""
        self.expire()
        with self.lock:
            job = self.jobs.get(job_id)
        if job is None or job.owner != owner:
            raise job_not_found(job_id)
        return job

    # --- state changes from the workers ----------------------------------------------------

    def update(self, job: Job, **changes: Any) -> None:
        """Change fields of a job and wake its watchers."""
        with self.lock:
            for name, value in changes.items():
                setattr(job, name, value)
            job.version += 1

    def start(self, job: Job) -> bool:
        """Move a queued job to running; False if it was cancelled while queued."""
        with self.lock:
            if job.status is not Status.QUEUED:
                return False  # cancelled while queued: its slot was freed then
            self.queued -= 1
            if job.cancel.is_set():
                self._finalize(job, Status.CANCELLED, stage="cancelled")
                return False
            self.running += 1
            job.status, job.stage, job.started = Status.RUNNING, "decoding", time.time()
            job.version += 1
            return True

    def finish(self, job: Job, status: Status, **changes: Any) -> None:
        """Record a running job's end (results, error...) and apply the result caps; a job
        already final is left as it is (as the Redis store finishes a job run twice once)."""
        with self.lock:
            if job.status.final:
                return
            self.running -= 1
            for name, value in changes.items():
                setattr(job, name, value)
            job.has_layout = job.layout is not None
            self._finalize(job, status, stage=status.value)
            if status is Status.DONE:
                self.pixels_total += job.width * job.height
                self.kept[job.id] = job.result_bytes
                self.kept_bytes += job.result_bytes
                self._evict(lambda: len(self.kept) > self.settings.results_max_count)
                self._evict(lambda: self.kept_bytes > self.settings.results_max_bytes)

    def cancel_queued(self, job: Job) -> None:
        """Flag a job for cancellation; a queued one is final at once (its worker skips it)."""
        job.cancel.set()
        with self.lock:
            if job.status is Status.QUEUED:
                # Its queue slot is free at once (max_queued), not when a worker reaches it.
                self.queued -= 1
                self._finalize(job, Status.CANCELLED, stage="cancelled")

    def fail_queued(self, job: Job, error: dict[str, Any]) -> bool:
        """Fail a job that never started (the service is shutting down); False if it was not
        queued any more."""
        with self.lock:
            if job.status is not Status.QUEUED:
                return False
            self.queued -= 1
            job.error = error
            self._finalize(job, Status.FAILED, stage="failed")
            return True

    def _finalize(self, job: Job, status: Status, stage: str) -> None:
        # Called with the lock held.
        job.status, job.stage = status, stage
        job.finished = time.time()
        job.input = None  # the decoded images are not needed any more
        if status is Status.DONE:
            job.progress = 1.0
        job.version += 1
        self.finished_total[status.value] += 1
        if job.started is not None:
            seconds = job.finished - job.started
            self.seconds_sum += seconds
            self.seconds_buckets[bisect.bisect_left(HISTOGRAM_BUCKETS, seconds)] += 1
        self.records[job.id] = None
        self._forget_old()
        self._wake(job)

    @staticmethod
    def _wake(job: Job) -> None:
        # Called with the lock held: the job is final, wake whoever waits for it.
        job.done.set()
        for wake in job.waiters:
            with contextlib.suppress(RuntimeError):  # the waiter's event loop has closed
                wake()
        job.waiters.clear()

    def on_done(self, job: Job, wake: Callable[[], object]) -> None:
        """Call ``wake()`` (from any thread) once the job is final; at once if it already is."""
        with self.lock:
            if job.done.is_set():
                wake()
            else:
                job.waiters.append(wake)

    def off_done(self, job: Job, wake: Callable[[], object]) -> None:
        """Forget a ``wake`` that :meth:`on_done` registered and that is no longer wanted (its
        wait timed out), so that a client polling a long job with ``?wait=`` leaves none
        behind."""
        with self.lock, contextlib.suppress(ValueError):
            job.waiters.remove(wake)

    # --- caps and expiry -------------------------------------------------------------------

    def _evict(self, too_many: Any) -> None:
        while self.kept and too_many():
            job_id, size = self.kept.popitem(last=False)
            self.kept_bytes -= size
            self._drop_results(self.jobs.get(job_id))

    def _forget_idempotency(self, job: Job) -> None:
        # Called with the lock held: the key may be used again, for a new job. The map may
        # already name a later job under the same key (this one's results had gone): keep it.
        entry = job.idempotency_key
        if entry is not None and self.idempotency.get(entry, ("", ""))[1] == job.id:
            del self.idempotency[entry]

    def _drop_results(self, job: Job | None) -> None:
        if job is not None:
            self._forget_idempotency(job)
            job.png, job.layout, job.companions, job.expired = None, None, {}, True
            job.version += 1

    def expire(self, now: float | None = None) -> None:
        """Drop results older than the time-to-live (their jobs answer 410 afterwards)."""
        now = time.time() if now is None else now
        with self.lock:
            ttl = self.settings.results_ttl_s
            while self.kept:
                job_id = next(iter(self.kept))
                job = self.jobs.get(job_id)
                if job is not None and job.finished is not None and now - job.finished < ttl:
                    break
                self.kept_bytes -= self.kept.pop(job_id)
                self._drop_results(job)

    def _forget_old(self) -> None:
        # Final jobs' records (not results) are kept for 10x the result cap, then forgotten
        # (404), those that ended first first, as the Redis store does: a job still queued or
        # running neither counts nor holds the others back.
        limit = 10 * self.settings.results_max_count + self.settings.max_queued
        while len(self.records) > limit:
            job_id, _ = self.records.popitem(last=False)
            oldest = self.jobs.pop(job_id, None)
            self.kept_bytes -= self.kept.pop(job_id, 0)
            if oldest is not None:
                self._forget_idempotency(oldest)

    # --- figures ---------------------------------------------------------------------------

    def figures(self) -> Figures:
        """The store's counters, copied."""
        with self.lock:
            counts = {s.value: 0 for s in Status}
            for job in self.jobs.values():
                counts[job.status.value] += 1
            return Figures(
                counts=counts,
                finished_total=dict(self.finished_total),
                seconds_buckets=list(self.seconds_buckets),
                seconds_sum=self.seconds_sum,
                pixels_total=self.pixels_total,
                kept_bytes=self.kept_bytes,
                queued=self.queued,
                running=self.running,
            )


class LocalQueue:
    """Jobs in this process's memory, computed by this process's workers."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.store = Store(settings)
        self.runner = Runner(self.store, settings)

    async def start(self) -> None:
        self.runner.start()

    async def stop(self, timeout: float) -> None:
        await asyncio.to_thread(self.runner.stop, timeout)

    async def submit(self, job: Job, idempotency: tuple[str, str] | None) -> tuple[Job, bool]:
        job, created = self.store.add(job, idempotency)
        if created:
            self.runner.submit(job)
        return job, created

    async def get(self, job_id: str, owner: str | None) -> Job:
        return self.store.get(job_id, owner)

    async def refresh(self, job: Job) -> Job:
        return job  # the workers update this very object

    async def result(self, job: Job, name: str | None = None) -> bytes | None:
        return job.png if name is None else job.companions.get(name)

    async def layout(self, job: Job) -> bytes | None:
        return job.layout

    async def cancel(self, job: Job) -> Job:
        self.store.cancel_queued(job)
        return job

    async def wait(self, job: Job, seconds: float) -> Job:
        # Woken by the worker that finishes the job: no polling.
        loop = asyncio.get_running_loop()
        finished = asyncio.Event()

        def wake() -> None:
            loop.call_soon_threadsafe(finished.set)

        self.store.on_done(job, wake)
        try:
            await asyncio.wait_for(finished.wait(), seconds)
        except TimeoutError:
            self.store.off_done(job, wake)
        return job

    async def figures(self) -> Figures:
        return self.store.figures()

    async def readiness(self) -> dict[str, Any]:
        # Off the event loop: the first call may create the GL context (a fraction of a second).
        backend, renderer, why = await asyncio.to_thread(backend_renderer, self.settings.backend)
        if renderer is None:
            raise Problem(503, "backend_unavailable", f"the {backend} backend cannot run: {why}")
        return {
            "queue": "memory",
            "backend": backend,
            "renderer": renderer,
            "backend_reason": why,
            "queue_depth": self.store.queued,
            "running": self.store.running,
            "workers": self.settings.compute_workers,
        }

    def busy(self) -> bool:
        return bool(self.store.queued or self.store.running)
