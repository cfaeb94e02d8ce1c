"""The distributed queue: jobs through Redis with Dramatiq (the only module that imports it).

``QUILTING_QUEUE=redis://...`` gives the app a :class:`RedisQueue`: a submission writes the
job's record and input to Redis (:mod:`quilting.service.jobs.redis_store`), then sends a Dramatiq
message carrying only the job id. ``quilting worker`` runs :func:`run_worker`: one Dramatiq
worker thread per process (it owns the GL context, which is bound to its thread; one process
per GPU), taking one message at a time.

Delivery is at least once. A message is acknowledged only after the job's end is written; the
results are written under the job id by one atomic call that only the first attempt to finish
gets through, so a job run twice is still finished once, with one set of results.

Transient failures are retried, with a limit:

- a worker that dies (SIGKILL, OOM, power) stops its heartbeat; after ``heartbeat_timeout_s``
  another worker takes its message again and runs the job, at most ``max_retries`` times, then
  the job fails with ``job_abandoned``;
- a worker that loses Redis waits for it (with backoff) to claim or finish its job, and drops
  progress reports meanwhile: without Redis no job can move, and giving up would lose the
  result.

Failures of the job itself (bad input, time limit, a bug) are final at once: running them again
would give the same answer.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import signal
import threading
import time
import uuid
from collections.abc import Callable
from typing import Any, TypeVar

import dramatiq
from dramatiq.brokers.redis import RedisBroker

from quilting.service.jobs.job_input import JobInput
from quilting.service.jobs.model import Figures, Job, Status
from quilting.service.jobs.redis_store import (
    UNAVAILABLE,
    RedisJobs,
    WorkerJobs,
    sync_client,
    unavailable,
)
from quilting.service.jobs.worker import cap_memory, compute, internal_error, job_too_large
from quilting.service.memory_limit import describe_bytes
from quilting.service.problems import Problem
from quilting.service.settings import Settings

log = logging.getLogger("quilting.worker")

T = TypeVar("T")

#: The Dramatiq queue, actor and key namespace (shared by every replica and worker).
QUEUE_NAME = "quilting"
RUN_ACTOR = "quilting_run_job"
NAMESPACE = "quilting-dramatiq"

#: Every broker command looks for dead workers' messages: cheap while none are dead.
MAINTENANCE_ALWAYS = 1_000_000

#: How often a job's progress goes to Redis (and its cancel flag is read), at most.
PROGRESS_EVERY_S = 0.05

#: Pauses of a worker waiting for Redis to come back, in seconds.
FIRST_PAUSE_S = 0.25
LONGEST_PAUSE_S = 5.0

#: The longest an idle worker waits between looks at the queue, in milliseconds. Also the
#: longest a worker waits after a job before fetching the next: with one message at a time,
#: Dramatiq's consumer only sleeps while its job runs (at 250 ms, that gap was 40 ms a job).
IDLE_POLL_MS = 50

#: A job whose workers kept dying.
ABANDONED = Problem(
    503,
    "job_abandoned",
    "the job's worker stopped (died or was cut off) as many times as the service runs a job "
    "again (setting max_retries); it is not run again",
).body()


class Superseded(Exception):  # noqa: N818 - a signal, not an error
    """Another attempt owns the job now: stop without writing anything."""


class Dispatch:
    """The broker and the job actor, built for one set of settings."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.worker_id = uuid.uuid4().hex
        self.stopping = threading.Event()
        # The job budget the engine sizes its batches to, and the cap of this process once
        # :meth:`limit` has set it (None: nothing limits a job, which is then not named).
        self.budget_bytes = settings.memory_budget
        self.memory_bytes: int | None = None
        # No retry middleware: a message whose actor raised is dead-lettered. The actor raises
        # only for a bug of its own; re-runs after transient failures are the job's (above).
        self.broker = RedisBroker(  # type: ignore[no-untyped-call]  # untyped in Dramatiq
            client=sync_client(settings.queue, settings.redis_timeout_s),
            namespace=NAMESPACE,
            heartbeat_timeout=int(settings.heartbeat_timeout_s * 1000),
            maintenance_chance=MAINTENANCE_ALWAYS,
            middleware=[],
        )
        self.run = dramatiq.actor(broker=self.broker, actor_name=RUN_ACTOR, queue_name=QUEUE_NAME)(
            self._run
        )

    @functools.cached_property
    def state(self) -> WorkerJobs:
        """The worker's side of the job store (an API replica only sends messages)."""
        return WorkerJobs(self.settings, self.broker.client)

    def limit(self) -> None:
        """Cap this process's memory at what it holds now plus the job budget
        (``job_memory_bytes``), as a service worker process does: a job that needs more
        fails with ``job_too_large`` and the worker takes the next one (what every job
        loads is loaded first: :func:`~quilting.service.jobs.worker.cap_memory`)."""
        self.memory_bytes = cap_memory(self.budget_bytes)

    def _patiently(self, step: Callable[[], T]) -> T:
        """``step()``, tried again while Redis cannot be reached (until the worker stops)."""
        pause = FIRST_PAUSE_S
        while True:
            try:
                return step()
            except UNAVAILABLE as exc:
                if self.stopping.is_set():
                    raise
                log.warning("Redis cannot be reached (%s); trying again in %.2f s", exc, pause)
                time.sleep(pause)
                pause = min(pause * 2, LONGEST_PAUSE_S)

    def _run(self, job_id: str) -> None:
        """The actor: compute one job and write its end (in the worker thread)."""
        claimed = self._patiently(lambda: self.state.claim(job_id, self.worker_id, ABANDONED))
        if claimed is None:
            return  # final, cancelled while queued, gone, busy elsewhere or abandoned
        attempt, data = claimed
        log.info("job %s: attempt %d on worker %s", job_id, attempt, self.worker_id)
        last = 0.0
        stop = False

        def report(fraction: float, stage: str) -> None:
            nonlocal last, stop
            now = time.monotonic()
            if now - last < PROGRESS_EVERY_S and fraction < 1.0:
                return
            last = now
            try:
                answer = self.state.progress(job_id, attempt, fraction, stage)
            except UNAVAILABLE:
                return  # progress is not worth waiting for; the job goes on
            if answer == "stale":
                raise Superseded(job_id)
            stop = answer == "cancel"

        pixels = 0  # of the output, for /metrics; known once the input is read
        try:
            spec = JobInput.from_bytes(data)
            pixels = spec.width * spec.height
            status, fields = compute(
                spec,
                self.settings.job_timeout_s,
                report,
                lambda: stop,
                self.memory_bytes,
                self.budget_bytes,
            )
        except Superseded:
            log.warning("job %s: attempt %d superseded by a later one", job_id, attempt)
            return
        except Exception:  # a bug must fail the job, never the worker
            log.exception("job %s failed unexpectedly", job_id)
            status, fields = Status.FAILED, internal_error("the job failed unexpectedly")
        try:
            finished = self._patiently(lambda: self.state.finish(job_id, pixels, status, fields))
        except MemoryError:  # writing the results took more than the budget left
            del fields
            failed = {"error": job_too_large(self.memory_bytes).body()}
            finished = self._patiently(
                lambda: self.state.finish(job_id, pixels, Status.FAILED, failed)
            )
        if not finished:
            log.info("job %s: already finished by another attempt", job_id)


class RedisQueue:
    """The app's :class:`~quilting.service.jobs.queue.JobQueue` on Redis: jobs for any worker."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.jobs = RedisJobs(settings)
        self.dispatch = Dispatch(settings)

    async def start(self) -> None:
        pass  # connections are made on first use: the API starts even while Redis is down

    async def stop(self, timeout: float) -> None:
        await self.jobs.close()
        self.dispatch.broker.close()

    async def submit(self, job: Job, idempotency: tuple[str, str] | None) -> tuple[Job, bool]:
        assert job.input is not None, "a new job carries its input"
        data = await asyncio.to_thread(job.input.to_bytes)
        job_id, created = await self.jobs.add(job, data, idempotency)
        if not created:
            return await self.jobs.get(job_id, job.owner), False
        try:
            # The broker's client blocks: off the event loop.
            await asyncio.to_thread(self.dispatch.run.send, job.id)
        except UNAVAILABLE as exc:
            # No message, so no worker would ever see the job: take it back if Redis lets us.
            with contextlib.suppress(Problem):
                await self.jobs.drop(job.id)
            raise unavailable(exc) from None
        # Had this replica died before this line, a worker would send the message again.
        with contextlib.suppress(Problem):
            await self.jobs.sent(job.id)
        job.input = None
        return job, True

    async def get(self, job_id: str, owner: str | None) -> Job:
        return await self.jobs.get(job_id, owner)

    async def refresh(self, job: Job) -> Job:
        return await self.jobs.get(job.id, job.owner)

    async def result(self, job: Job, name: str | None = None) -> bytes | None:
        return await self.jobs.output(job, "png" if name is None else f"c:{name}")

    async def layout(self, job: Job) -> bytes | None:
        return await self.jobs.output(job, "layout")

    async def cancel(self, job: Job) -> Job:
        await self.jobs.cancel(job)
        return await self.refresh(job)

    async def wait(self, job: Job, seconds: float) -> Job:
        # Polling Redis, quickly at first: a worker in another process finishes the job.
        deadline = time.monotonic() + seconds
        pause = 0.01
        while not job.status.final:
            left = deadline - time.monotonic()
            if left <= 0:
                break
            await asyncio.sleep(min(pause, left))
            pause = min(pause * 1.5, 0.25)
            job = await self.refresh(job)
        return job

    async def figures(self) -> Figures:
        return await self.jobs.figures()

    async def readiness(self) -> dict[str, Any]:
        figures = await self.jobs.figures()  # 503 queue_unavailable while Redis is down
        return {
            "queue": "redis",
            "backend": self.settings.backend,
            "queue_depth": figures.queued,
            "running": figures.running,
            "workers": await self.jobs.workers(),
        }

    def busy(self) -> bool:
        return False  # jobs belong to the shared queue, not to this replica


def run_worker(settings: Settings) -> None:
    """Run one worker until SIGTERM or SIGINT: one thread computing one job at a time.

    On the first signal the worker takes no new message and lets its job finish within
    ``drain_grace_s``; a job still running then is taken again by another worker once this
    one's heartbeat has stopped for ``heartbeat_timeout_s``.
    """
    dispatch = Dispatch(settings)
    worker = dramatiq.Worker(dispatch.broker, worker_threads=1, worker_timeout=IDLE_POLL_MS)
    # One message at a time: a busy worker never holds a second job another could run.
    worker.queue_prefetch = 1

    def on_signal(signum: int, frame: object) -> None:
        dispatch.stopping.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    every = settings.heartbeat_timeout_s / 6
    beat(dispatch)  # before the first message: a claim checks that its worker is alive
    dispatch.limit()
    worker.start()
    log.info(
        "worker %s taking jobs from queue %r (memory budget of a job: %s)",
        dispatch.worker_id,
        QUEUE_NAME,
        "not limited" if dispatch.memory_bytes is None else describe_bytes(dispatch.memory_bytes),
    )
    while not dispatch.stopping.wait(every):
        beat(dispatch)
    log.info("worker %s stopping (grace %.0f s)", dispatch.worker_id, settings.drain_grace_s)
    worker.stop(timeout=int(settings.drain_grace_s * 1000))
    with contextlib.suppress(*UNAVAILABLE):
        dispatch.state.leave(dispatch.worker_id)
    dispatch.broker.close()


def beat(dispatch: Dispatch) -> None:
    """Say this worker is alive, to the job store and to Dramatiq; queue orphaned jobs."""
    try:
        dispatch.state.heartbeat(dispatch.worker_id)
        # Dramatiq's own heartbeat: its consumer says nothing while its one job runs.
        dispatch.broker.do_qsize(QUEUE_NAME)
        for job_id in dispatch.state.orphans():
            log.warning("job %s was never queued (its replica died?): queueing it", job_id)
            dispatch.run.send(job_id)
    except UNAVAILABLE as exc:
        log.warning("Redis cannot be reached: %s", exc)
