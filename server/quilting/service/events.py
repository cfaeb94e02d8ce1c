"""A job's progress as server-sent events: the ids (positions in the job's life, the same on
every replica, so a client that reconnects elsewhere resumes where it was), the
``Last-Event-ID`` header read back, and the stream itself."""

from __future__ import annotations

import asyncio
import json
import re
from collections.abc import AsyncIterator

from quilting.service.jobs import Job, Status
from quilting.service.jobs.queue import JobQueue
from quilting.service.problems import Problem

#: Seconds between two looks at a job that is not finished.
POLL_S = 0.04

#: How long an EventSource waits before it reconnects to a broken event stream (the ``retry:``
#: line), in milliseconds.
SSE_RETRY_MS = 1000

#: Event ids are positions in a job's life, the same on every replica (a reconnecting client
#: may reach another one): ``(phase * 10001 + progress in 1/10000) * 1000``, phase 0 queued and
#: 1 running, plus up to 999 changes that one stream saw at the same progress.
_PROGRESS_STEPS = 10_000
_CHANGES_PER_STEP = 1000
#: The id of the final event (done, failed, cancelled): above every progress event's.
END_EVENT_ID = 2 * (_PROGRESS_STEPS + 1) * _CHANGES_PER_STEP
_EVENT_ID = re.compile(r"^[0-9]{1,19}$")


def event_position(status: Status, progress: float) -> int:
    """The event id of a job that is ``status`` (queued or running) at ``progress``.

    It grows as the job moves on (the engine's progress never goes back within one run), so
    an event's id tells any replica what a client that got it has seen.
    """
    phase = 0 if status is Status.QUEUED else 1
    steps = min(max(round(progress * _PROGRESS_STEPS), 0), _PROGRESS_STEPS)
    return (phase * (_PROGRESS_STEPS + 1) + steps) * _CHANGES_PER_STEP


def resume_after(header: str | None) -> int:
    """The ``Last-Event-ID`` request header as a number; -1 when absent (nothing seen yet).

    Raises
    ------
    Problem
        422 ``invalid_parameter`` for a value that is not an id this service sent.
    """
    if header is None or not header.strip():
        return -1
    if not _EVENT_ID.match(header.strip()):
        raise Problem(
            422,
            "invalid_parameter",
            "Last-Event-ID must be the id of an event of this stream (a whole number)",
            field="Last-Event-ID",
        )
    return int(header.strip())


async def job_stream(jobs: JobQueue, job: Job, after: int) -> AsyncIterator[str]:
    """The events of ``job`` after the id ``after``: progress while it runs, then its final
    status, then the end of the stream."""
    yield f"retry: {SSE_RETRY_MS}\n\n"
    last = after
    seen: tuple[float, str, Status] | None = None
    current = job
    while True:
        status = current.status
        if status.final:
            event_id = max(END_EVENT_ID, last + 1)
            data = json.dumps(current.snapshot())
            yield f"id: {event_id}\nevent: {status.value}\ndata: {data}\n\n"
            return
        now = (current.progress, current.stage, status)
        if now != seen:
            first_look, seen = seen is None, now
            event_id = event_position(status, now[0])
            if event_id <= last and not first_look:
                # A change this stream saw at a position it already used (a new stage at the
                # same progress, or a job run again from 0): the next id.
                event_id = last + 1
            # Ids below the end event's stay below it, so that an id at or past it always
            # means "had the end"; on a first look, a position at or before Last-Event-ID is
            # what the client has already seen.
            if last < event_id < END_EVENT_ID:
                last = event_id
                body = {"progress": now[0], "stage": now[1], "status": status.value}
                yield f"id: {event_id}\nevent: progress\ndata: {json.dumps(body)}\n\n"
        await asyncio.sleep(POLL_S)
        current = await jobs.refresh(current)
