"""The contract between the client's flows and its two drivers, without any I/O.

A flow is a generator: it yields *actions* (send a request, sleep, open / read / close an event
stream) and is sent back their outcome; it returns its result through ``StopIteration``. The
sync and async clients are thin drivers that perform the actions with httpx and step through a
flow with :class:`Steps`, so the logic (what to send, when to poll, how long to sleep, how to
follow events, when to give up) exists once, in :mod:`quilting_client._flows` and
:mod:`quilting_client._waiting`, and the two clients cannot drift. This module also holds the
smallest flows, one request each, that the others are made of.

Driver contract, per action:

``Send(request)``
    reply: the ``httpx.Response``, body read.
``Sleep(seconds)``
    reply: None.
``OpenStream(request, limit)``
    reply: the open stream, a handle of the driver's own that the flow only hands back.
``NextEvent(stream)``
    reply: the next :class:`~quilting_client._events.ServerEvent`, or None once the stream
    ended, broke, was silent for longer than the read timeout, or has been open for ``limit``
    seconds (see :class:`~quilting_client._events.EventReader`).
``CloseStream(stream)``
    reply: None. The driver also closes the streams still open when the flow ends.

An action that fails raises a :class:`~quilting_client.errors.QuiltingClientError` (an error
status mapped by :func:`~quilting_client._responses.raise_for_problem`, or a transport
failure): the driver throws it into the flow, which may handle it.
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import httpx

from quilting_client import _protocol as proto
from quilting_client import _responses as responses
from quilting_client._protocol import RequestSpec
from quilting_client.errors import QuiltingClientError
from quilting_client.models import JobStatus


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
    """Open an event stream followed for at most ``limit`` seconds (None: as long as it lasts);
    the reply is the stream."""

    request: RequestSpec
    limit: float | None


@dataclass(frozen=True)
class _OnStream:
    """An action on an event stream that :class:`OpenStream` opened."""

    stream: object


class NextEvent(_OnStream):
    """Read the next event of an open stream; the reply is the event, or None at its end."""


class CloseStream(_OnStream):
    """Close an open event stream."""


Action = Send | Sleep | OpenStream | NextEvent | CloseStream
#: What a driver answers an action with: a response, a stream, an event, or None. The flows
#: check the type of what they expect.
Reply = object
T = TypeVar("T")
Flow = Generator[Action, Reply, T]


class Steps(Generic[T]):
    """A flow as a driver runs it: its actions one at a time, each answered in turn.

    A driver performs each action inside :meth:`catching` and sets :attr:`reply`; when the
    action raises a :class:`QuiltingClientError` instead, the error is thrown into the flow,
    which may handle it. Leaving the ``with`` block closes the flow::

        with Steps(flow) as steps:
            for action in steps:
                with steps.catching():
                    steps.reply = perform(action)
        return steps.result

    Parameters
    ----------
    flow : Flow
        The flow to run, not started yet.

    Attributes
    ----------
    reply : Reply
        The outcome of the action just performed, sent to the flow at the next step.
    result : T
        What the flow returned, once the iteration is over.
    """

    def __init__(self, flow: Flow[T]) -> None:
        self._flow = flow
        self._error: QuiltingClientError | None = None
        self.reply: Reply = None
        self.result: T

    def __enter__(self) -> Steps[T]:
        return self

    def __exit__(self, *exc_info: object) -> None:
        # A flow abandoned half-way (the caller interrupted, a task was cancelled) is closed
        # now rather than by the garbage collector.
        self._flow.close()

    def __iter__(self) -> Iterator[Action]:
        try:
            action = next(self._flow)
            while True:
                yield action
                reply, error = self.reply, self._error
                self.reply, self._error = None, None
                action = self._flow.send(reply) if error is None else self._flow.throw(error)
        except StopIteration as stop:
            self.result = stop.value

    @contextmanager
    def catching(self) -> Iterator[None]:
        """Keep the :class:`QuiltingClientError` the block raises for the flow to handle."""
        try:
            yield
        except QuiltingClientError as error:
            self._error = error


def start(operation: Callable[..., Flow[T]], arguments: Mapping[str, Any]) -> Flow[T]:
    """The flow ``operation`` with the arguments a public method of a client was given.

    The methods of both clients name their parameters as the flows they run do, and hand them
    on as their ``locals()``, taken first thing so that it holds only the parameters: ``self``
    (dropped here) and ``options`` (the ``**options`` keywords, as one mapping) included. Each
    argument is thus written once, in the method's signature, rather than once more in each
    client's call.
    """
    return operation(**{name: value for name, value in arguments.items() if name != "self"})


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
    return responses.parse_job((yield from call(spec)))


def fetch_job(job_id: str) -> Flow[JobStatus]:
    """The job's status."""
    return (yield from call_job(proto.job_request(job_id)))


def fetch_bytes(spec: RequestSpec) -> Flow[bytes]:
    """The body of a request (a PNG)."""
    return (yield from call(spec)).content


def fetch_object(spec: RequestSpec) -> Flow[dict[str, Any]]:
    """The JSON object answered to a request."""
    return responses.parse_json_object((yield from call(spec)))
