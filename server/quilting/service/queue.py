"""The job queue the app talks to: one interface, two homes for job state.

:class:`LocalQueue` keeps jobs in this process (:class:`~quilting.service.jobs.Store`) and
computes them in its own workers (:class:`~quilting.service.runner.Runner`); it is the default.
With ``QUILTING_QUEUE=redis://...`` the app gets a
:class:`~quilting.service.distributed.RedisQueue` instead: job state and results live in Redis
and ``quilting worker`` processes, anywhere, compute them. The endpoints cannot tell the two
apart: both answer with :class:`~quilting.service.jobs.Job` records and raise the same
:class:`~quilting.service.problems.Problem` codes.
"""

from __future__ import annotations

import asyncio
import contextlib
from typing import Any, Protocol

from quilting.backends import backend_renderer
from quilting.service.jobs import Figures, Job, Store
from quilting.service.problems import Problem
from quilting.service.runner import Runner
from quilting.service.settings import Settings


class JobQueue(Protocol):
    """Where jobs go once submitted, and where their state and results are read."""

    async def start(self) -> None:
        """Begin taking jobs (the app's startup)."""

    async def stop(self, timeout: float) -> None:
        """Stop; running jobs of a local queue may finish within ``timeout`` seconds."""

    async def submit(self, job: Job, idempotency: tuple[str, str] | None) -> tuple[Job, bool]:
        """Queue ``job``, or find the earlier job of a repeated idempotency key and body.

        Returns ``(job, True)`` for a new job, ``(earlier, False)`` for a repeat. Raises 503
        ``queue_full`` at the queue's cap and 409 ``idempotency_conflict``.
        """

    async def get(self, job_id: str, owner: str | None) -> Job:
        """The job if ``owner`` may see it, else 404 ``job_not_found``."""

    async def refresh(self, job: Job) -> Job:
        """The job's current state."""

    async def result(self, job: Job, name: str | None = None) -> bytes | None:
        """The result PNG (``name`` None), a companion's PNG, or None when not kept."""

    async def layout(self, job: Job) -> bytes | None:
        """The result's layout JSON, or None."""

    async def cancel(self, job: Job) -> Job:
        """Cancel: a queued job is final at once, a running one stops at its next level."""

    async def wait(self, job: Job, seconds: float) -> Job:
        """The job once final, or as it is after ``seconds``."""

    async def figures(self) -> Figures:
        """Counters for ``/metrics``."""

    async def readiness(self) -> dict[str, Any]:
        """Fields of ``/readyz``, ``queue_depth`` among them; raises a 503 :class:`Problem`
        when jobs cannot be computed (backend missing, Redis unreachable)."""

    def busy(self) -> bool:
        """Whether this process still has jobs of its own to finish (graceful drain)."""


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
        self.store.on_done(job, lambda: loop.call_soon_threadsafe(finished.set))
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(finished.wait(), seconds)
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


def make_queue(settings: Settings) -> JobQueue:
    """The queue ``settings.queue`` names: in memory, or Redis with ``quilting worker``."""
    if settings.queue == "memory":
        return LocalQueue(settings)
    from quilting.service.distributed import RedisQueue  # needs the 'queue' extra

    return RedisQueue(settings)
