"""The job queue the app talks to: one interface, two homes for job state.

:class:`~quilting.service.jobs.memory.LocalQueue` keeps jobs in this process and computes
them in its own workers (:class:`~quilting.service.jobs.pool.Runner`); it is the default.
With ``QUILTING_QUEUE=redis://...`` the app gets a
:class:`~quilting.service.jobs.dramatiq_queue.RedisQueue` instead: job state and results live
in Redis and ``quilting worker`` processes, anywhere, compute them. The endpoints cannot tell
the two apart: both answer with :class:`~quilting.service.jobs.model.Job` records and raise
the same :class:`~quilting.service.problems.Problem` codes.
"""

from __future__ import annotations

from typing import Any, Protocol

from quilting.service.jobs.model import Figures, Job
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


def make_queue(settings: Settings) -> JobQueue:
    """The queue ``settings.queue`` names: in memory, or Redis with ``quilting worker``."""
    if settings.queue == "memory":
        from quilting.service.jobs.memory import LocalQueue

        return LocalQueue(settings)
    from quilting.service.jobs.dramatiq_queue import RedisQueue  # needs the 'queue' extra

    return RedisQueue(settings)
