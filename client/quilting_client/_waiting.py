"""Waiting for a job, without any I/O: polling its status or following its event stream.

The flows here decide when to poll, how long to sleep (the poll interval, the service's
``Retry-After``, the caller's deadline), how to follow a job's server-sent events and report
progress, and when to give up; both clients run them through :mod:`quilting_client._actions`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping

from quilting_client import _protocol as proto
from quilting_client import _responses as responses
from quilting_client._actions import (
    CloseStream,
    Flow,
    NextEvent,
    OpenStream,
    call,
    fetch_job,
    sleep,
)
from quilting_client._events import ServerEvent
from quilting_client._protocol import RequestSpec
from quilting_client.errors import (
    JobCancelledError,
    JobFailedError,
    QuiltingClientError,
    WaitTimeoutError,
)
from quilting_client.models import TERMINAL_STATES, JobStatus

#: A progress callback: (fraction done in 0..1, stage name).
ProgressCallback = Callable[[float, str], None]


class Deadline:
    """A point in time after which waiting stops; ``timeout=None`` never comes.

    Parameters
    ----------
    timeout : float or None
        Seconds from now.
    """

    def __init__(self, timeout: float | None) -> None:
        self.timeout = timeout
        self._end = None if timeout is None else time.monotonic() + timeout

    def remaining(self) -> float | None:
        """Seconds left (never negative), or None without a deadline."""
        return None if self._end is None else max(0.0, self._end - time.monotonic())

    def expired(self) -> bool:
        """Whether the deadline has passed."""
        return self._end is not None and time.monotonic() >= self._end

    def clip(self, seconds: float) -> float:
        """``seconds``, shortened so as not to go past the deadline."""
        remaining = self.remaining()
        return seconds if remaining is None else min(seconds, remaining)


def check_interval(poll_interval: float) -> None:
    """Refuse a poll interval that is not positive (it would poll without a pause).

    Raises
    ------
    ValueError
        ``poll_interval`` is zero or negative.
    """
    if not poll_interval > 0:
        raise ValueError(f"poll_interval must be positive, not {poll_interval!r}")


def raise_unless_done(job: JobStatus) -> JobStatus:
    """Return a job that ended well; raise the typed error of one that did not."""
    if job.status == "failed":
        raise JobFailedError(job)
    if job.status == "cancelled":
        raise JobCancelledError(job)
    return job


def _poll(job_id: str, deadline: Deadline, poll_interval: float, delay: float) -> Flow[JobStatus]:
    """Poll the job's status until it ends; its final status."""
    while True:
        yield from sleep(deadline.clip(delay))
        response = yield from call(proto.job_request(job_id))
        job = responses.parse_job(response)
        if job.is_terminal:
            return job
        if deadline.expired():
            raise WaitTimeoutError(job_id, deadline.timeout, job)
        # The poll interval is the floor (no hammering, even on "Retry-After: 0"); the service
        # may ask for longer.
        delay = max(poll_interval, responses.retry_after(response) or 0.0)


class _Reporter:
    """Hands progress events on to a progress callback."""

    def __init__(self, progress: ProgressCallback) -> None:
        self._progress = progress
        self._reported = 0.0

    def event(self, data: Mapping[str, object]) -> None:
        """Report a ``progress`` event."""
        value = data.get("progress")
        if isinstance(value, int | float) and not isinstance(value, bool):
            self._reported = float(value)
        self._progress(self._reported, str(data.get("stage", "")))

    def ended(self, job: JobStatus) -> None:
        """Report the terminal event of a job."""
        if job.status == "done" and self._reported < 1.0:
            # Progress events are sent only on change: make sure a bar gets to 100 %.
            self._progress(1.0, job.stage or "done")


def _open_stream(spec: RequestSpec, limit: float | None) -> Flow[object]:
    """Open an event stream; None if the service did not answer within ``limit`` seconds."""
    try:
        return (yield OpenStream(spec, limit))
    except QuiltingClientError as error:
        # No answer within the silence allowed: report no stream, so that the caller checks
        # the job and the deadline, as for a stream that went silent.
        if limit is None or not responses.timed_out(error):
            raise
        return None


def _read_events(job_id: str, deadline: Deadline, reporter: _Reporter) -> Flow[JobStatus | None]:
    """Follow the job's event stream once: the job's terminal status, or None when the stream
    ended first (or went silent, or the deadline passed)."""
    stream = yield from _open_stream(proto.events_request(job_id), deadline.remaining())
    terminal: ServerEvent | None = None
    while stream is not None and terminal is None:
        event = yield NextEvent(stream)
        if not isinstance(event, ServerEvent):
            break
        if event.name in TERMINAL_STATES:
            terminal = event
        elif event.name == "progress":
            reporter.event(event.data)
            if deadline.expired():
                break  # A busy stream must not outlast the deadline.
    if stream is not None:
        yield CloseStream(stream)
    if terminal is None:
        return None
    try:
        return JobStatus.from_json(terminal.data)
    except ValueError:
        # Trust the status endpoint over a garbled terminal event.
        return (yield from fetch_job(job_id))


def _follow_events(
    job_id: str, deadline: Deadline, poll_interval: float, progress: ProgressCallback
) -> Flow[JobStatus]:
    """Follow the job's event stream, reconnecting while it runs; its final status."""
    reporter = _Reporter(progress)
    while True:
        job = yield from _read_events(job_id, deadline, reporter)
        if job is not None:
            reporter.ended(job)
            return job
        # The stream ended without a terminal event (a restart, a proxy that cuts long
        # responses, silence past the read timeout) or the deadline passed while it ran.
        # The status says whether to go on.
        job = yield from fetch_job(job_id)
        if job.is_terminal:
            reporter.ended(job)  # a bar gets to 100 % whichever way the end was learnt
            return job
        if deadline.expired():
            raise WaitTimeoutError(job_id, deadline.timeout, job)
        yield from sleep(deadline.clip(poll_interval))


def follow(
    job_id: str,
    *,
    deadline: Deadline,
    progress: ProgressCallback | None,
    poll_interval: float,
    delay: float = 0.0,
) -> Flow[JobStatus]:
    """Wait for a job to end: by its event stream with a progress callback, else by polling.

    Parameters
    ----------
    job_id : str
        The job.
    deadline : Deadline
        When to give up (raising :class:`WaitTimeoutError`; the job is not cancelled).
    progress : callable or None
        Called with (fraction, stage) on each progress event.
    poll_interval : float
        Seconds between polls (at least), and between reconnections of a broken stream.
    delay : float
        Seconds to wait before the first poll (the submission's ``Retry-After``).

    Returns
    -------
    JobStatus
        The final status of a job that is ``done``.

    Raises
    ------
    JobFailedError, JobCancelledError
        The job ended without a result.
    WaitTimeoutError
        The deadline passed first.
    """
    if progress is None:
        job = yield from _poll(job_id, deadline, poll_interval, delay)
    else:
        job = yield from _follow_events(job_id, deadline, poll_interval, progress)
    return raise_unless_done(job)
