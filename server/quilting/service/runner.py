"""Worker threads that run jobs off the event loop.

Each worker takes queued jobs in order and runs the engine with a progress callback that
reports progress, stops the job when it is cancelled and fails it past the time limit (the
engine checks between wavefront levels). Cost backends are built per job on the worker's own
thread (a GL context is bound to the thread that made it).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from typing import Any

from quilting.api import synthesize
from quilting.core.errors import CancelledError, QuiltingError
from quilting.core.layout import apply_layout
from quilting.io import encode_png
from quilting.service.jobs import Job, Status, Store
from quilting.service.problems import Problem, from_engine
from quilting.service.settings import Settings

log = logging.getLogger("quilting.service")


class JobTimeoutError(QuiltingError):
    """A job ran past the service's time limit."""

    code = "job_timeout"


class Runner:
    """A fixed pool of worker threads fed by a FIFO queue."""

    def __init__(self, store: Store, settings: Settings) -> None:
        self.store = store
        self.settings = settings
        self.queue: queue.Queue[Job | None] = queue.Queue()
        self.threads: list[threading.Thread] = []

    def start(self) -> None:
        for index in range(self.settings.compute_workers):
            thread = threading.Thread(
                target=self._work, name=f"quilting-worker-{index}", daemon=True
            )
            thread.start()
            self.threads.append(thread)

    def submit(self, job: Job) -> None:
        self.queue.put(job)

    def stop(self, timeout: float | None = None) -> None:
        """Let the workers finish their current job and exit."""
        for _ in self.threads:
            self.queue.put(None)
        for thread in self.threads:
            thread.join(timeout)

    def _work(self) -> None:
        while True:
            job = self.queue.get()
            if job is None:
                return
            if not self.store.start(job):
                continue
            try:
                self._run(job)
            except Exception:  # a bug must fail the job, never the worker
                log.exception("job %s failed unexpectedly", job.id)
                problem = Problem(500, "internal_error", "the job failed unexpectedly")
                self.store.finish(job, Status.FAILED, error=problem.body())

    def _run(self, job: Job) -> None:
        spec = job.input
        assert spec is not None
        deadline = time.monotonic() + self.settings.job_timeout_s

        def progress(fraction: float, stage: str) -> None:
            if job.cancel.is_set():
                raise CancelledError("the job was cancelled")
            if time.monotonic() > deadline:
                raise JobTimeoutError(
                    f"the job ran longer than {self.settings.job_timeout_s:g} s "
                    "(setting job_timeout_s)"
                )
            self.store.update(job, progress=round(fraction, 4), stage=stage)

        try:
            result = synthesize(
                spec.texture,
                (spec.height, spec.width),
                progress=progress,
                **spec.options,
            )
        except CancelledError:
            self.store.finish(job, Status.CANCELLED)
            return
        except QuiltingError as exc:
            self.store.finish(job, Status.FAILED, error=from_engine(exc).body())
            return
        self.store.update(job, stage="encoding")
        # No job id or time in the metadata: the same request gives the same bytes.
        meta: dict[str, Any] = {**result.layout.meta, "width": spec.width, "height": spec.height}
        png = encode_png(result.image, metadata=meta)
        companions = {
            name: encode_png(apply_layout(result.layout, image), metadata=meta)
            for name, image in spec.companions.items()
        }
        stats = result.stats
        self.store.finish(
            job,
            Status.DONE,
            png=png,
            companions=companions,
            layout=result.layout.to_json().encode(),
            timings=dict(result.timings),
            backend=result.backend,
            stats={
                "seam_error_mean": stats.seam_error_mean,
                "seam_error_total": stats.seam_error_total,
                "largest_copy": stats.largest_copy,
                "unused": stats.unused,
            },
        )
