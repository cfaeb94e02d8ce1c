"""The in-process job store's pool of workers: processes by default, or threads.

The engine spends much of its time in small numpy calls that hold the GIL, so threads in one
process use about one core whatever their number; ``worker_mode="process"`` (the default) runs
each worker in a process of its own (:func:`quilting.service.jobs.worker.process_main`), fed
by a pump thread here that turns the worker's messages into store updates. Threads cannot be
memory-limited one by one. A crashed worker process fails its job and is replaced.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import multiprocessing
import queue
import threading
import time
from collections.abc import Iterator
from multiprocessing.connection import Connection
from typing import Any, Protocol

from quilting import warm_up
from quilting.service.jobs.model import Job, Status
from quilting.service.jobs.worker import (
    compute,
    internal_error,
    process_main,
    shutdown_error,
)
from quilting.service.settings import Settings

log = logging.getLogger("quilting.service")

#: How often a pump thread looks at its job's cancel flag while the worker computes.
PUMP_POLL_S = 0.05


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

    def _started(self) -> Iterator[Job]:
        """The jobs this thread runs, each marked started, until the queue's end: one taken
        during shutdown fails, one cancelled while queued is passed over."""
        while (job := self.queue.get()) is not None:
            if self.stopping.is_set():
                self._shut_out(job)
            elif self.store.start(job):
                yield job

    def _report(self, job: Job, fraction: float, stage: str) -> None:
        self.store.update(job, progress=fraction, stage=stage)

    # --- threads ---------------------------------------------------------------------------

    def _work(self) -> None:
        warm_up()  # as a worker process does, before its first job
        for job in self._started():
            spec = job.input
            assert spec is not None
            try:
                status, fields = compute(
                    spec,
                    self.settings.job_timeout_s,
                    functools.partial(self._report, job),
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
            target=process_main, args=(theirs, self.memory_budget), daemon=True
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
            for job in self._started():
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
                    self._report(job, message[1], message[2])
                    continue
                _, status, fields = message
                return Status(status), fields
            if not process.is_alive():
                raise EOFError("worker process exited")
