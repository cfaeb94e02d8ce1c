"""A job: its status and progress, its results once finished, its snapshot as the API shows
it, and the counters behind ``/metrics``. Its input, the uploads as they came, is
:class:`~quilting.service.jobs.job_input.JobInput`.
"""

from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from quilting.service.jobs.job_input import JobInput

#: Upper bounds (seconds) of the job duration histogram.
HISTOGRAM_BUCKETS = (0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0)


class Status(StrEnum):
    """Where a job is in its life."""

    QUEUED = "queued"
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"
    CANCELLED = "cancelled"

    @property
    def final(self) -> bool:
        return self in (Status.DONE, Status.FAILED, Status.CANCELLED)


@dataclass(frozen=True)
class Figures:
    """The counters behind ``/metrics`` and ``/readyz``, from either job store."""

    counts: dict[str, int]
    finished_total: dict[str, int]
    seconds_buckets: list[int]
    seconds_sum: float
    pixels_total: int
    kept_bytes: int
    queued: int
    running: int


@dataclass(eq=False)
class Job:
    """One job (a synthesis, a transfer, a matte, a fill, an extension, a Wang tile set or an
    alpha extraction) and, once finished, its results (a Wang tile set's ``layout`` is its
    manifest: where each tile lies in the atlas, its ``png``, and the colours of its edges)."""

    id: str
    owner: str | None
    width: int
    height: int
    companion_names: list[str]
    input: JobInput | None
    operation: str = "synthesize"
    #: Start of the download names of the job's files (from the uploads' file names, the
    #: operation, the size and the seed: :func:`quilting.service.downloads.job_stem`).
    download_stem: str = ""
    #: (owner, Idempotency-Key) the job was submitted with, if any: its entry in the store's
    #: map goes when the job's results or record do.
    idempotency_key: tuple[str | None, str] | None = None
    status: Status = Status.QUEUED
    progress: float = 0.0
    stage: str = "queued"
    created: float = field(default_factory=time.time)
    started: float | None = None
    finished: float | None = None
    timings: dict[str, float] = field(default_factory=dict)
    backend: str | None = None
    renderer: str | None = None
    fallback: str | None = None
    error: dict[str, Any] | None = None
    stats: dict[str, Any] | None = None
    png: bytes | None = None
    companions: dict[str, bytes] = field(default_factory=dict)
    layout: bytes | None = None
    has_layout: bool = False
    expired: bool = False
    version: int = 0
    cancel: threading.Event = field(default_factory=threading.Event)
    done: threading.Event = field(default_factory=threading.Event)
    waiters: list[Callable[[], object]] = field(default_factory=list)

    @property
    def result_bytes(self) -> int:
        return (
            len(self.png or b"") + len(self.layout or b"") + sum(map(len, self.companions.values()))
        )

    def snapshot(self) -> dict[str, Any]:
        """The job status document (``GET /jobs/{id}``)."""
        base = f"/jobs/{self.id}"
        ready = self.status is Status.DONE and not self.expired
        return {
            "id": self.id,
            "operation": self.operation,
            "status": self.status.value,
            "progress": self.progress,
            "stage": self.stage,
            "created": self.created,
            "started": self.started,
            "finished": self.finished,
            "timings": dict(self.timings),
            "backend": self.backend,
            "renderer": self.renderer,
            "fallback": self.fallback,
            "error": self.error,
            "stats": self.stats,
            "width": self.width,
            "height": self.height,
            "result": base + "/result" if ready else None,
            "layout": base + "/layout" if ready and self.has_layout else None,
            "manifest": base + "/manifest"
            if ready and self.has_layout and self.operation == "wang_tiles"
            else None,
            "companions": list(self.companion_names),
            "expired": self.expired,
        }


def new_job_id() -> str:
    """A random, URL-safe job id."""
    return uuid.uuid4().hex
