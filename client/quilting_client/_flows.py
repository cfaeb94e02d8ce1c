"""The client's workflows as sans-I/O generators, shared by ``Client`` and ``AsyncClient``.

A flow yields *actions* (send a request, sleep, open / read / close an event stream) and is sent
back their outcome; it returns its result through ``StopIteration``. The sync and async clients
are thin drivers that perform the actions with httpx, so the logic (when to poll, how long to
sleep, how to follow events, when to give up) exists once and the two clients cannot drift.

Driver contract, per action:

``Send(request)``
    reply: the ``httpx.Response``, body read; error statuses are raised by the driver.
``Sleep(seconds)``
    reply: None.
``OpenStream(request, limit)``
    reply: None. Error statuses are raised; a time-out while connecting leaves no stream open,
    which the next ``NextEvent`` reports as its end.
``NextEvent()``
    reply: the next :class:`ServerEvent`, or None once the stream ended, broke, was silent
    for longer than the read timeout, or has been open for ``limit`` seconds (heartbeat
    comments alone must not keep a stream alive past its limit).
``CloseStream()``
    reply: None. The driver also closes a stream still open when the flow ends.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Collection, Generator, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import httpx

from quilting_client import _protocol as proto
from quilting_client._protocol import ImageSource, RequestSpec, ServerEvent
from quilting_client.errors import (
    JobCancelledError,
    JobFailedError,
    QuiltingClientError,
    WaitTimeoutError,
)
from quilting_client.models import TERMINAL_STATES, JobStatus, SynthesisResult

#: A progress callback: (fraction done in 0..1, stage name).
ProgressCallback = Callable[[float, str], None]

#: How long ``synthesize`` lets the service hold the POST for the result: most jobs finish
#: within it, which saves a poll and a download round trip.
SUBMIT_HOLD = 10.0
#: The same with a progress callback: short, because nothing is reported while the POST is
#: held; the event stream reports progress after it.
SUBMIT_HOLD_WITH_PROGRESS = 1.0


@dataclass(frozen=True)
class Send:
    """Make a request; the reply is the response."""

    request: RequestSpec


@dataclass(frozen=True)
class Sleep:
    """Wait; the reply is None."""

    seconds: float


@dataclass(frozen=True)
class OpenStream:
    """Open an event stream whose silences may last at most ``limit`` seconds (None: any)."""

    request: RequestSpec
    limit: float | None


@dataclass(frozen=True)
class NextEvent:
    """Read the next event of the open stream; the reply is the event, or None at its end."""


@dataclass(frozen=True)
class CloseStream:
    """Close the open event stream."""


Action = Send | Sleep | OpenStream | NextEvent | CloseStream
Reply = httpx.Response | ServerEvent | None
T = TypeVar("T")
Flow = Generator[Action, Reply, T]


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


# -- building blocks ---------------------------------------------------------------------------


def call(spec: RequestSpec) -> Flow[httpx.Response]:
    """Make a request and return its (successful) response."""
    reply = yield Send(spec)
    assert isinstance(reply, httpx.Response), "driver broke the Send contract"
    return reply


def sleep(seconds: float) -> Flow[None]:
    """Sleep, unless there is nothing to wait for."""
    if seconds > 0:
        yield Sleep(seconds)


def call_job(spec: RequestSpec) -> Flow[JobStatus]:
    """The job status answered to a request."""
    return proto.parse_job((yield from call(spec)))


def fetch_job(job_id: str) -> Flow[JobStatus]:
    """The job's status."""
    return (yield from call_job(proto.job_request(job_id)))


def fetch_bytes(spec: RequestSpec) -> Flow[bytes]:
    """The body of a request (a PNG)."""
    return (yield from call(spec)).content


def fetch_object(spec: RequestSpec) -> Flow[dict[str, Any]]:
    """The JSON object answered to a request."""
    return proto.parse_json_object((yield from call(spec)))


def raise_unless_done(job: JobStatus) -> JobStatus:
    """Return a job that ended well; raise the typed error of one that did not."""
    if job.status == "failed":
        raise JobFailedError(job)
    if job.status == "cancelled":
        raise JobCancelledError(job)
    return job


# -- waiting for a job -------------------------------------------------------------------------


def _poll(job_id: str, deadline: Deadline, poll_interval: float, delay: float) -> Flow[JobStatus]:
    while True:
        yield from sleep(deadline.clip(delay))
        response = yield from call(proto.job_request(job_id))
        job = proto.parse_job(response)
        if job.is_terminal:
            return job
        if deadline.expired():
            raise WaitTimeoutError(job_id, deadline.timeout, job)
        # The poll interval is the floor (no hammering, even on "Retry-After: 0"); the service
        # may ask for longer.
        delay = max(poll_interval, proto.retry_after(response) or 0.0)


def _follow_events(
    job_id: str, deadline: Deadline, poll_interval: float, progress: ProgressCallback
) -> Flow[JobStatus]:
    reported = 0.0
    while True:
        yield OpenStream(proto.events_request(job_id), deadline.remaining())
        while True:
            event = yield NextEvent()
            if not isinstance(event, ServerEvent):
                break
            if event.name == "progress":
                reported = _float(event.data.get("progress"), reported)
                progress(reported, str(event.data.get("stage", "")))
                if deadline.expired():
                    break  # A busy stream must not outlast the deadline: see below.
            elif event.name in TERMINAL_STATES:
                yield CloseStream()
                try:
                    job = JobStatus.from_json(event.data)
                except ValueError:
                    # Trust the status endpoint over a garbled terminal event.
                    job = yield from fetch_job(job_id)
                if job.status == "done" and reported < 1.0:
                    # Progress events are sent only on change: make sure a bar gets to 100 %.
                    progress(1.0, job.stage or "done")
                return job
        yield CloseStream()
        # The stream ended without a terminal event (a restart, a proxy that cuts long
        # responses, silence past the read timeout) or the deadline passed while it ran.
        # The status says whether to go on.
        job = yield from fetch_job(job_id)
        if job.is_terminal:
            return job
        if deadline.expired():
            raise WaitTimeoutError(job_id, deadline.timeout, job)
        yield from sleep(deadline.clip(poll_interval))


def _float(value: object, default: float) -> float:
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    return default


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


def wait(
    job_id: str,
    *,
    progress: ProgressCallback | None,
    timeout: float | None,
    poll_interval: float,
) -> Flow[JobStatus]:
    """The flow of ``Client.wait``: follow a job until it ends or ``timeout`` passes."""
    _check_interval(poll_interval)
    return (
        yield from follow(
            job_id, deadline=Deadline(timeout), progress=progress, poll_interval=poll_interval
        )
    )


def _check_interval(poll_interval: float) -> None:
    if not poll_interval > 0:
        raise ValueError(f"poll_interval must be positive, not {poll_interval!r}")


# -- whole operations --------------------------------------------------------------------------


def submit_job(spec: RequestSpec) -> Flow[JobStatus]:
    """POST a submission without waiting (``spec`` asks for ``wait=0``); the job's status."""
    outcome = proto.parse_submit((yield from call(spec)))
    if isinstance(outcome, JobStatus):
        return outcome
    # Even with wait=0 the answer can be the PNG: an idempotent repeat of a job that finished
    # within its first request's wait. Its status is one request away.
    if outcome.job_id is None:
        raise QuiltingClientError(
            "the service answered with a result but no job id", code="invalid_response"
        )
    return (yield from fetch_job(outcome.job_id))


def submit(
    texture: ImageSource,
    *,
    width: int,
    height: int,
    companions: Mapping[str, ImageSource] | None,
    companion_kinds: Mapping[str, str] | None = None,
    options: Mapping[str, object],
    idempotency_key: str | None,
) -> Flow[JobStatus]:
    """The flow of ``Client.submit``: POST /synthesize without waiting; the job's status."""
    spec = proto.submit_request(
        texture,
        width=width,
        height=height,
        companions=companions,
        companion_kinds=companion_kinds,
        options=options,
        wait=0.0,
        idempotency_key=idempotency_key,
    )
    return (yield from submit_job(spec))


def submit_transfer(
    texture: ImageSource,
    target: ImageSource,
    *,
    companions: Mapping[str, ImageSource] | None,
    companion_kinds: Mapping[str, str] | None = None,
    options: Mapping[str, object],
    idempotency_key: str | None,
) -> Flow[JobStatus]:
    """The flow of ``Client.submit_transfer``: POST /transfer without waiting."""
    spec = proto.transfer_request(
        texture,
        target,
        companions=companions,
        companion_kinds=companion_kinds,
        options=options,
        wait=0.0,
        idempotency_key=idempotency_key,
    )
    return (yield from submit_job(spec))


def submit_matte(
    target: ImageSource,
    silhouette: ImageSource,
    layers: Sequence[ImageSource],
    *,
    normals: ImageSource | None,
    options: Mapping[str, object],
    idempotency_key: str | None,
) -> Flow[JobStatus]:
    """The flow of ``Client.submit_matte``: POST /matte without waiting."""
    spec = proto.matte_request(
        target,
        silhouette,
        layers,
        normals=normals,
        options=options,
        wait=0.0,
        idempotency_key=idempotency_key,
    )
    return (yield from submit_job(spec))


def _hold(progress: ProgressCallback | None, timeout: float | None) -> float:
    """How long to let the service hold the POST for the result."""
    hold = SUBMIT_HOLD if progress is None else SUBMIT_HOLD_WITH_PROGRESS
    if timeout is not None:
        # From the timeout rather than the deadline's remainder, which is already a few
        # microseconds shorter and would print as ?wait=0.499998.
        hold = min(hold, timeout)
    return hold


def run_job(
    spec: RequestSpec,
    *,
    deadline: Deadline,
    companions: Collection[str] | None,
    progress: ProgressCallback | None,
    poll_interval: float,
) -> Flow[SynthesisResult]:
    """Submit ``spec`` (a synthesis, a transfer or a matte), wait, download the result and the
    companions named in ``companions`` (a mapping's keys: those sent along)."""
    response = yield from call(spec)
    outcome = proto.parse_submit(response)
    if isinstance(outcome, JobStatus):
        job = outcome
        if not job.is_terminal:
            job = yield from follow(
                job.id,
                deadline=deadline,
                progress=progress,
                poll_interval=poll_interval,
                delay=max(poll_interval, proto.retry_after(response) or 0.0),
            )
        raise_unless_done(job)
        image = yield from fetch_bytes(proto.result_request(job.id))
        job_id: str | None = job.id
    else:
        image, job_id = outcome.image, outcome.job_id
        if progress is not None:
            progress(1.0, "done")
    maps: dict[str, bytes] = {}
    for name in companions or {}:
        if job_id is None:
            raise QuiltingClientError(
                "the service answered with a result but no job id to fetch companions from",
                code="invalid_response",
            )
        maps[name] = yield from fetch_bytes(proto.result_request(job_id, name))
    return SynthesisResult(image, job_id=job_id, companions=maps)


def synthesize(
    texture: ImageSource,
    *,
    width: int,
    height: int,
    companions: Mapping[str, ImageSource] | None,
    companion_kinds: Mapping[str, str] | None = None,
    options: Mapping[str, object],
    progress: ProgressCallback | None,
    poll_interval: float,
    timeout: float | None,
    idempotency_key: str | None,
) -> Flow[SynthesisResult]:
    """The flow of ``Client.synthesize``: submit, wait, download result and companions."""
    _check_interval(poll_interval)
    deadline = Deadline(timeout)
    spec = proto.submit_request(
        texture,
        width=width,
        height=height,
        companions=companions,
        companion_kinds=companion_kinds,
        options=options,
        wait=_hold(progress, timeout),
        idempotency_key=idempotency_key,
    )
    return (
        yield from run_job(
            spec,
            deadline=deadline,
            companions=companions,
            progress=progress,
            poll_interval=poll_interval,
        )
    )


def transfer(
    texture: ImageSource,
    target: ImageSource,
    *,
    companions: Mapping[str, ImageSource] | None,
    companion_kinds: Mapping[str, str] | None = None,
    options: Mapping[str, object],
    progress: ProgressCallback | None,
    poll_interval: float,
    timeout: float | None,
    idempotency_key: str | None,
) -> Flow[SynthesisResult]:
    """The flow of ``Client.transfer``: submit to /transfer, wait, download the results."""
    _check_interval(poll_interval)
    deadline = Deadline(timeout)
    spec = proto.transfer_request(
        texture,
        target,
        companions=companions,
        companion_kinds=companion_kinds,
        options=options,
        wait=_hold(progress, timeout),
        idempotency_key=idempotency_key,
    )
    return (
        yield from run_job(
            spec,
            deadline=deadline,
            companions=companions,
            progress=progress,
            poll_interval=poll_interval,
        )
    )


def matte(
    target: ImageSource,
    silhouette: ImageSource,
    layers: Sequence[ImageSource],
    *,
    normals: ImageSource | None,
    companions: Iterable[str],
    options: Mapping[str, object],
    progress: ProgressCallback | None,
    poll_interval: float,
    timeout: float | None,
    idempotency_key: str | None,
) -> Flow[SynthesisResult]:
    """The flow of ``Client.matte``: submit to /matte, wait, download the result and the
    companions asked for (``normals``, ``clusters``).

    The names are checked and the request built before anything is sent, so that a mistake
    uploads nothing.
    """
    _check_interval(poll_interval)
    deadline = Deadline(timeout)
    names = proto.output_names(companions)
    spec = proto.matte_request(
        target,
        silhouette,
        layers,
        normals=normals,
        options=options,
        wait=_hold(progress, timeout),
        idempotency_key=idempotency_key,
    )
    return (
        yield from run_job(
            spec,
            deadline=deadline,
            companions=names,
            progress=progress,
            poll_interval=poll_interval,
        )
    )


def tile(
    image: ImageSource,
    *,
    axes: str,
    band: int | None,
    timeout: float | None,
    blend: str | None = None,
) -> Flow[bytes]:
    """The flow of ``Client.tile``: one ``POST /tile``, answered with the PNG itself.

    No job is created, so there is nothing to follow: the service answers when the image is
    tiled. Like a submission, a 503 (``draining``) is raised at once as
    :class:`~quilting_client.errors.ServiceUnavailableError` with its ``retry_after``, not
    retried.
    """
    if timeout is not None and not timeout > 0:
        raise ValueError(f"timeout must be positive, not {timeout!r}")
    spec = proto.tile_request(image, axes=axes, band=band, blend=blend, timeout=timeout)
    return proto.parse_png((yield from call(spec)))
