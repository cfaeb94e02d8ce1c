"""The actions of the flows and the drivers that perform them (``quilting_client._actions``),
and the requests each public flow of ``quilting_client._flows`` makes.

Covers
------
- :class:`~quilting_client._actions.Steps`: each reply sent back to the action that asked for
  it (and only to it), the result taken from the flow's return, a failed action's
  :class:`QuiltingClientError` thrown in at the yield that asked for it, any other exception
  (``KeyboardInterrupt`` included) left to propagate with the flow closed;
- the building blocks: :func:`~quilting_client._actions.sleep` skipping a sleep of nothing,
  :func:`~quilting_client._actions.call` refusing a reply that breaks the contract, and
  :func:`~quilting_client._actions.start` handing a method's parameters on;
- the two drivers, ``Client._run`` and ``AsyncClient._run``, on a scripted
  ``httpx.MockTransport``: the same actions in the same order, the same replies and the same
  result (or error) for the same flow; sleeps performed with ``time.sleep`` /
  ``asyncio.sleep`` (both replaced); the streams a flow opened closed when it returns, raises,
  is interrupted by a ``BaseException`` or (async) is cancelled, and closed once;
- each public flow of :mod:`quilting_client._flows` on its happy path, driven by hand: the
  requests in order (method, path, ``?wait=``), the multipart parts in order, the ``options``
  JSON, the sleeps between polls, and the result.

Nothing sleeps for real and nothing leaves the process.
"""

from __future__ import annotations

import asyncio
import inspect
import json
from collections.abc import AsyncIterator, Callable, Iterator
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import httpx
import pytest
from client_fakes import (
    BASE,
    CLUSTERS_OUT,
    LAYER_0,
    LAYER_1,
    NORMAL,
    NORMAL_OUT,
    NORMALS_IN,
    RESULT,
    SILHOUETTE,
    TARGET,
    TEXTURE,
    job_json,
)

from quilting_client import AsyncClient, Client
from quilting_client import _actions as actions
from quilting_client import _async as async_module
from quilting_client import _flows as flows
from quilting_client import _protocol as proto
from quilting_client import _sync as sync_module
from quilting_client import _waiting as waiting
from quilting_client._events import ServerEvent
from quilting_client.errors import (
    ConnectionFailedError,
    NotFoundError,
    QuiltingClientError,
    ServerError,
)
from quilting_client.models import JobStatus, SynthesisResult, WangTilesResult

# -- Steps, by hand -----------------------------------------------------------------------------


def spec(path: str) -> proto.RequestSpec:
    return proto.RequestSpec("GET", path)


def test_steps_send_each_reply_to_the_action_that_asked_for_it() -> None:
    received: list[object] = []

    def flow() -> actions.Flow[str]:
        received.append((yield actions.Send(spec("/a"))))
        received.append((yield actions.Sleep(1.0)))
        received.append((yield actions.Send(spec("/b"))))
        return "finished"

    performed: list[actions.Action] = []
    with actions.Steps(flow()) as steps:
        for action in steps:
            performed.append(action)
            if isinstance(action, actions.Send):
                steps.reply = f"reply to {action.request.path}"
            # The Sleep is answered with nothing: the flow must get None, not a stale reply.
    assert performed == [actions.Send(spec("/a")), actions.Sleep(1.0), actions.Send(spec("/b"))]
    assert received == ["reply to /a", None, "reply to /b"]
    assert steps.result == "finished"


def test_steps_throw_an_error_in_at_the_yield_that_failed_and_go_on() -> None:
    seen: list[str] = []

    def flow() -> actions.Flow[list[str]]:
        first = yield actions.Send(spec("/first"))
        seen.append(f"first: {first}")
        try:
            yield actions.Send(spec("/second"))
        except NotFoundError as error:
            seen.append(f"second failed: {error.code}")
        third = yield actions.Send(spec("/third"))
        seen.append(f"third: {third}")
        return seen

    with actions.Steps(flow()) as steps:
        for action in steps:
            assert isinstance(action, actions.Send)
            with steps.catching():
                if action.request.path == "/second":
                    steps.reply = "never sent"
                    raise NotFoundError("gone", code="job_not_found", status=404)
                steps.reply = action.request.path
    # The error replaced the reply of the failed action; the next action got its own reply.
    assert steps.result == ["first: /first", "second failed: job_not_found", "third: /third"]


def test_an_error_the_flow_does_not_handle_comes_out_of_the_loop_unchanged() -> None:
    error = ServerError("boom", code="internal_error", status=500)

    def flow() -> actions.Flow[None]:
        yield actions.Send(spec("/a"))

    with pytest.raises(ServerError) as caught, actions.Steps(flow()) as steps:
        for _ in steps:
            with steps.catching():
                raise error
    assert caught.value is error


@dataclass
class Tracked:
    """A flow that records how far it got and whether it was closed."""

    events: list[str] = field(default_factory=list)

    def flow(self) -> actions.Flow[str]:
        try:
            self.events.append("started")
            yield actions.Send(spec("/a"))
            self.events.append("after a")
            yield actions.Sleep(5.0)
            self.events.append("after sleep")
            return "done"
        except GeneratorExit:
            self.events.append("closed")
            raise
        except BaseException as error:
            self.events.append(f"thrown {type(error).__name__}")
            raise


@pytest.mark.parametrize("raised", [ValueError("bug"), KeyboardInterrupt(), SystemExit(3)])
def test_steps_close_the_flow_and_let_other_exceptions_through(raised: BaseException) -> None:
    tracked = Tracked()
    flow = tracked.flow()
    with pytest.raises(type(raised)), actions.Steps(flow) as steps:
        for action in steps:
            with steps.catching():
                if isinstance(action, actions.Sleep):
                    raise raised
    # Not thrown into the flow (only QuiltingClientError is): closed where it stood.
    assert tracked.events == ["started", "after a", "closed"]
    assert inspect.getgeneratorstate(flow) == inspect.GEN_CLOSED


def test_steps_close_a_flow_that_the_driver_leaves_half_way() -> None:
    tracked = Tracked()
    flow = tracked.flow()
    with actions.Steps(flow) as steps:
        for _ in steps:
            break
    assert tracked.events == ["started", "closed"]
    assert inspect.getgeneratorstate(flow) == inspect.GEN_CLOSED


# -- the building blocks ------------------------------------------------------------------------


@pytest.mark.parametrize(("seconds", "expected"), [(0.0, []), (-1.0, []), (0.25, [0.25])])
def test_sleep_yields_only_a_sleep_of_something(seconds: float, expected: list[float]) -> None:
    assert list(actions.sleep(seconds)) == [actions.Sleep(s) for s in expected]


def test_call_refuses_a_reply_that_is_not_a_response() -> None:
    flow = actions.call(spec("/readyz"))
    assert next(flow) == actions.Send(spec("/readyz"))
    with pytest.raises(AssertionError, match="driver broke the Send contract"):
        flow.send({"status": "ok"})


def test_start_hands_the_parameters_on_without_self() -> None:
    def operation(job_id: str, *, options: dict[str, object]) -> actions.Flow[tuple[str, Any]]:
        return (job_id, options)
        yield  # pragma: no cover - a generator

    arguments = {"self": object(), "job_id": "j9", "options": {"seed": 1}}
    flow = actions.start(operation, arguments)
    with pytest.raises(StopIteration) as stop:
        next(flow)
    assert stop.value.value == ("j9", {"seed": 1})
    assert "self" in arguments  # the caller's mapping is left alone


# -- the two drivers on a scripted transport ---------------------------------------------------


class Body(httpx.SyncByteStream, httpx.AsyncByteStream):
    """A response body in chunks that records whether (and how often) it was closed."""

    def __init__(self, *chunks: bytes) -> None:
        self.chunks = chunks
        self.closes = 0

    def __iter__(self) -> Iterator[bytes]:
        yield from self.chunks

    async def __aiter__(self) -> AsyncIterator[bytes]:
        for chunk in self.chunks:
            yield chunk

    def close(self) -> None:
        self.closes += 1

    async def aclose(self) -> None:
        self.closes += 1


def sse_body(*events: tuple[str, dict[str, Any]]) -> bytes:
    return b"".join(
        f"event: {name}\ndata: {json.dumps(data)}\n\n".encode() for name, data in events
    )


class Transport:
    """Scripted answers per (method, path), in turn, the last one repeating; records requests
    and the bodies of the event streams it answered with. Serves both clients."""

    def __init__(self, routes: dict[tuple[str, str], list[Callable[[], httpx.Response]]]) -> None:
        self.routes = {key: list(answers) for key, answers in routes.items()}
        self.requests: list[str] = []
        self.bodies: list[Body] = []

    def __call__(self, request: httpx.Request) -> httpx.Response:
        path = request.url.raw_path.decode().split("?", 1)[0]
        self.requests.append(f"{request.method} {request.url.raw_path.decode()}")
        assert len(self.requests) < 200, "runaway flow"
        queue = self.routes[(request.method, path)]
        answer = (queue.pop(0) if len(queue) > 1 else queue[0])()
        if isinstance(answer.stream, Body):
            self.bodies.append(answer.stream)
        return answer


def status_answer(
    state: str, status: int = 200, headers: dict[str, str] | None = None
) -> Callable[[], httpx.Response]:
    return lambda: httpx.Response(status, json=job_json(state), headers=headers)


def png_answer(content: bytes) -> Callable[[], httpx.Response]:
    return lambda: httpx.Response(200, content=content, headers={"Content-Type": "image/png"})


def stream_answer(*events: tuple[str, dict[str, Any]]) -> Callable[[], httpx.Response]:
    return lambda: httpx.Response(
        200, stream=Body(sse_body(*events)), headers={"Content-Type": "text/event-stream"}
    )


def not_found() -> httpx.Response:
    body = {"status": 404, "code": "result_not_found", "title": "not found", "detail": "no map"}
    return httpx.Response(404, json=body, headers={"Content-Type": "application/problem+json"})


class Clock:
    """The clock of the flows' deadlines and of the readers' limits; sleeping moves it."""

    def __init__(self) -> None:
        self.now = 1000.0

    def monotonic(self) -> float:
        return self.now


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> Clock:
    fake = Clock()
    fake_time = SimpleNamespace(monotonic=fake.monotonic)
    monkeypatch.setattr(waiting, "time", fake_time)
    monkeypatch.setattr("quilting_client._events.time", fake_time)
    return fake


@dataclass
class Run:
    """What a driver did with a flow: its actions and their replies (streams by number),
    the sleeps, the result or the error, and the requests the transport saw."""

    log: list[tuple[Any, ...]]
    outcome: tuple[str, Any]
    requests: list[str]
    sleeps: list[float]


def describe(action: actions.Action, reply: object, streams: list[object]) -> tuple[Any, ...]:
    match action:
        case actions.Send(request):
            assert isinstance(reply, httpx.Response)
            return ("Send", request.method, request.path, dict(request.params), reply.status_code)
        case actions.Sleep(seconds):
            return ("Sleep", seconds, reply)
        case actions.OpenStream(request, limit):
            streams.append(reply)
            return ("OpenStream", request.path, limit, len(streams) - 1)
        case actions.NextEvent(stream):
            return ("NextEvent", streams.index(stream), reply)
        case actions.CloseStream(stream):
            return ("CloseStream", streams.index(stream), reply)
    raise AssertionError(action)


def run_sync(make_flow: Callable[[], actions.Flow[Any]], transport: Transport, clock: Clock) -> Run:
    client = Client(BASE, transport=httpx.MockTransport(transport))
    log: list[tuple[Any, ...]] = []
    streams: list[object] = []
    sleeps: list[float] = []
    perform = client._perform

    def recording(action: actions.Action, stack: Any) -> actions.Reply:
        try:
            reply = perform(action, stack)
        except QuiltingClientError as error:
            log.append(("failed", type(action).__name__, type(error).__name__))
            raise
        log.append(describe(action, reply, streams))
        return reply

    def sleep(seconds: float) -> None:
        sleeps.append(seconds)
        clock.now += seconds

    client._perform = recording  # type: ignore[method-assign, assignment]
    client._sleep = sleep  # type: ignore[method-assign]
    with client:
        try:
            outcome: tuple[str, Any] = ("returned", client._run(make_flow()))
        except QuiltingClientError as error:
            outcome = ("raised", (type(error).__name__, error.code, error.status))
    return Run(log, outcome, transport.requests, sleeps)


def run_async(
    make_flow: Callable[[], actions.Flow[Any]], transport: Transport, clock: Clock
) -> Run:
    client = AsyncClient(BASE, transport=httpx.MockTransport(transport))
    log: list[tuple[Any, ...]] = []
    streams: list[object] = []
    sleeps: list[float] = []
    perform = client._perform

    async def recording(action: actions.Action, stack: Any) -> actions.Reply:
        try:
            reply = await perform(action, stack)
        except QuiltingClientError as error:
            log.append(("failed", type(action).__name__, type(error).__name__))
            raise
        log.append(describe(action, reply, streams))
        return reply

    async def sleep(seconds: float) -> None:
        sleeps.append(seconds)
        clock.now += seconds

    client._perform = recording  # type: ignore[method-assign, assignment]
    client._sleep = sleep  # type: ignore[method-assign]

    async def main() -> tuple[str, Any]:
        async with client:
            try:
                return ("returned", await client._run(make_flow()))
            except QuiltingClientError as error:
                return ("raised", (type(error).__name__, error.code, error.status))

    return Run(log, asyncio.run(main()), transport.requests, sleeps)


PROGRESS_1 = {"progress": 0.4, "stage": "quilting", "status": "running"}
PROGRESS_2 = {"progress": 0.9, "stage": "blending", "status": "running"}


def synthesize_with_progress(calls: list[tuple[float, str]]) -> Callable[[], actions.Flow[Any]]:
    arguments = {
        "texture": TEXTURE,
        "width": 64,
        "height": 32,
        "companions": {"normal": NORMAL},
        "companion_kinds": None,
        "source_mask": None,
        "trimap": None,
        "scribbles": None,
        "progress": lambda fraction, stage: calls.append((fraction, stage)),
        "poll_interval": 0.5,
        "timeout": 30.0,
        "idempotency_key": "k1",
        "options": {"block": 16},
    }
    return lambda: flows.synthesize(**arguments)


def events_routes() -> dict[tuple[str, str], list[Callable[[], httpx.Response]]]:
    """A job followed by its events: the first stream ends early, the second has the end."""
    return {
        ("POST", "/synthesize"): [status_answer("queued", 202, headers={"Retry-After": "1"})],
        ("GET", "/jobs/j1/events"): [
            stream_answer(("progress", PROGRESS_1)),
            stream_answer(("progress", PROGRESS_2), ("done", job_json("done"))),
        ],
        ("GET", "/jobs/j1"): [status_answer("running")],
        ("GET", "/jobs/j1/result"): [png_answer(RESULT)],
        ("GET", "/jobs/j1/result/normal"): [png_answer(NORMAL_OUT)],
    }


def test_both_drivers_follow_a_job_s_events_with_the_same_actions(clock: Clock) -> None:
    runs, calls = [], []
    for runner in (run_sync, run_async):
        clock.now = 1000.0
        progress: list[tuple[float, str]] = []
        transport = Transport(events_routes())
        runs.append(runner(synthesize_with_progress(progress), transport, clock))
        calls.append(progress)
        assert [body.closes for body in transport.bodies] == [1, 1]
    sync, async_ = runs
    assert sync.log == async_.log
    assert sync.requests == async_.requests
    assert sync.sleeps == async_.sleeps == [0.5]
    assert sync.outcome == async_.outcome
    assert calls[0] == calls[1] == [(0.4, "quilting"), (0.9, "blending"), (1.0, "done")]
    # Not merely the same: the sequence a follower of events must have.
    assert [entry[0] for entry in sync.log] == [
        "Send",  # POST /synthesize: 202
        "OpenStream",
        "NextEvent",  # progress 0.4
        "NextEvent",  # the end of the stream, without a terminal event
        "CloseStream",
        "Send",  # GET /jobs/j1: still running
        "Sleep",
        "OpenStream",
        "NextEvent",  # progress 0.9
        "NextEvent",  # done
        "CloseStream",
        "Send",  # the result
        "Send",  # the companion
    ]
    assert sync.log[2] == ("NextEvent", 0, ServerEvent("progress", PROGRESS_1))
    assert sync.log[3] == ("NextEvent", 0, None)
    assert sync.log[9] == ("NextEvent", 1, ServerEvent("done", job_json("done")))
    assert sync.log[0][3] == {"wait": "1"}  # held 1 s with a progress callback
    kind, result = sync.outcome
    assert kind == "returned" and isinstance(result, SynthesisResult)
    assert bytes(result) == RESULT and result.companions == {"normal": NORMAL_OUT}


def wait_flow() -> actions.Flow[JobStatus]:
    return flows.wait("j1", progress=None, timeout=10.0, poll_interval=0.5)


def test_both_drivers_poll_with_the_same_sleeps_and_requests(clock: Clock) -> None:
    runs = []
    for runner in (run_sync, run_async):
        clock.now = 1000.0
        answers = [
            status_answer("running", headers={"Retry-After": "2"}),
            status_answer("running"),
            status_answer("done"),
        ]
        runs.append(runner(wait_flow, Transport({("GET", "/jobs/j1"): answers}), clock))
    sync, async_ = runs
    assert sync.log == async_.log and sync.outcome == async_.outcome
    assert sync.requests == async_.requests == ["GET /jobs/j1"] * 3
    # Asked at once, then after the Retry-After, then after the poll interval.
    assert sync.sleeps == async_.sleeps == [2.0, 0.5]
    assert sync.outcome[0] == "returned" and sync.outcome[1].status == "done"


def test_both_drivers_raise_the_same_error_after_the_same_actions(clock: Clock) -> None:
    runs = []
    for runner in (run_sync, run_async):
        clock.now = 1000.0
        routes = events_routes()
        routes[("GET", "/jobs/j1/result/normal")] = [not_found]
        runs.append(runner(synthesize_with_progress([]), Transport(routes), clock))
    sync, async_ = runs
    assert sync.log == async_.log
    assert sync.outcome == async_.outcome == ("raised", ("NotFoundError", "result_not_found", 404))
    assert sync.log[-1] == ("failed", "Send", "NotFoundError")


def test_both_drivers_throw_a_failed_action_into_the_flow(clock: Clock) -> None:
    def flow() -> actions.Flow[str]:
        try:
            yield from actions.fetch_object(proto.ready_request())
        except NotFoundError as error:
            job = yield from actions.fetch_job("j1")
            return f"handled {error.code}, then {job.status}"
        return "not thrown"

    runs = []
    for runner in (run_sync, run_async):
        routes = {("GET", "/readyz"): [not_found], ("GET", "/jobs/j1"): [status_answer("done")]}
        runs.append(runner(flow, Transport(routes), clock))
    assert runs[0].outcome == runs[1].outcome == ("returned", "handled result_not_found, then done")
    assert runs[0].requests == runs[1].requests == ["GET /readyz", "GET /jobs/j1"]


def test_the_drivers_sleep_with_time_sleep_and_asyncio_sleep(
    monkeypatch: pytest.MonkeyPatch, clock: Clock
) -> None:
    slept: dict[str, list[float]] = {"sync": [], "async": []}

    def time_sleep(seconds: float) -> None:
        slept["sync"].append(seconds)
        clock.now += seconds

    async def asyncio_sleep(seconds: float) -> None:
        slept["async"].append(seconds)
        clock.now += seconds

    monkeypatch.setattr(sync_module, "time", SimpleNamespace(sleep=time_sleep))
    monkeypatch.setattr(async_module, "asyncio", SimpleNamespace(sleep=asyncio_sleep))

    def routes() -> dict[tuple[str, str], list[Callable[[], httpx.Response]]]:
        answers = [status_answer("running", headers={"Retry-After": "3"}), status_answer("done")]
        return {("GET", "/jobs/j1"): answers}

    with Client(BASE, transport=httpx.MockTransport(Transport(routes()))) as client:
        assert client.wait("j1", timeout=10.0, poll_interval=0.5).status == "done"

    async def main() -> JobStatus:
        async with AsyncClient(BASE, transport=httpx.MockTransport(Transport(routes()))) as aio:
            return await aio.wait("j1", timeout=10.0, poll_interval=0.5)

    assert asyncio.run(main()).status == "done"
    assert slept == {"sync": [3.0], "async": [3.0]}


# -- the drivers close the streams a flow leaves open -------------------------------------------


class Interrupt(BaseException):
    """Like KeyboardInterrupt: not an Exception, not an error of the client."""


@dataclass
class StreamFlow:
    """A flow that opens an event stream, reads an event, then ends as told: returns, raises,
    sleeps (to be interrupted there), or closes the stream first."""

    transport: Transport
    ending: str
    trail: list[str] = field(default_factory=list)

    def __call__(self) -> actions.Flow[str]:
        try:
            stream = yield actions.OpenStream(proto.events_request("j1"), None)
            event = yield actions.NextEvent(stream)
            assert isinstance(event, ServerEvent)
            self.trail.append(f"read {event.name}")
            body = self.transport.bodies[-1]
            if self.ending == "close":
                yield actions.CloseStream(stream)
                self.trail.append(f"closed by the flow: {body.closes}")
            elif self.ending == "raise":
                raise LookupError("the flow failed")
            elif self.ending == "sleep":
                yield actions.Sleep(1.0)
            # Still open as the flow ends (unless it closed it).
            self.trail.append(f"closes at the end: {body.closes}")
            return "returned"
        except GeneratorExit:
            self.trail.append("flow closed")
            raise


def stream_transport() -> Transport:
    routes = {("GET", "/jobs/j1/events"): [stream_answer(("progress", PROGRESS_1))]}
    return Transport(routes)


def drive(ending: str, mode: str) -> StreamFlow:
    """Run a :class:`StreamFlow` under the sync or async driver, exceptions propagating."""
    transport = stream_transport()
    flow = StreamFlow(transport, ending)
    if mode == "sync":
        with Client(BASE, transport=httpx.MockTransport(transport)) as client:
            assert client._run(flow()) == "returned"
        return flow

    async def main() -> None:
        async with AsyncClient(BASE, transport=httpx.MockTransport(transport)) as aio:
            assert await aio._run(flow()) == "returned"

    asyncio.run(main())
    return flow


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_a_stream_left_open_is_closed_when_the_flow_returns(mode: str) -> None:
    flow = drive("return", mode)
    assert flow.trail == ["read progress", "closes at the end: 0"]
    assert [body.closes for body in flow.transport.bodies] == [1]


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_a_stream_the_flow_closes_is_closed_once(mode: str) -> None:
    flow = drive("close", mode)
    assert flow.trail == ["read progress", "closed by the flow: 1", "closes at the end: 1"]
    assert [body.closes for body in flow.transport.bodies] == [1]


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_a_stream_is_closed_when_the_flow_raises(mode: str) -> None:
    transport = stream_transport()
    flow = StreamFlow(transport, "raise")

    def run() -> None:
        if mode == "sync":
            with Client(BASE, transport=httpx.MockTransport(transport)) as client:
                client._run(flow())
        else:

            async def main() -> None:
                async with AsyncClient(BASE, transport=httpx.MockTransport(transport)) as aio:
                    await aio._run(flow())

            asyncio.run(main())

    with pytest.raises(LookupError, match="the flow failed"):
        run()
    assert flow.trail == ["read progress"]
    assert [body.closes for body in transport.bodies] == [1]


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_an_interrupt_closes_the_streams_and_the_flow(mode: str) -> None:
    transport = stream_transport()
    flow = StreamFlow(transport, "sleep")
    generator = flow()  # held here, so that only the driver can have closed it

    def interrupt_sync(seconds: float) -> None:
        assert [body.closes for body in transport.bodies] == [0]  # open while it sleeps
        raise KeyboardInterrupt

    async def interrupt_async(seconds: float) -> None:
        assert [body.closes for body in transport.bodies] == [0]
        raise Interrupt

    if mode == "sync":
        with (
            pytest.raises(KeyboardInterrupt),
            Client(BASE, transport=httpx.MockTransport(transport)) as client,
        ):
            client._sleep = interrupt_sync  # type: ignore[method-assign]
            client._run(generator)
    else:

        async def main() -> None:
            async with AsyncClient(BASE, transport=httpx.MockTransport(transport)) as aio:
                aio._sleep = interrupt_async  # type: ignore[method-assign]
                await aio._run(generator)

        with pytest.raises(Interrupt):
            asyncio.run(main())
    assert flow.trail == ["read progress", "flow closed"]
    assert inspect.getgeneratorstate(generator) == inspect.GEN_CLOSED
    assert [body.closes for body in transport.bodies] == [1]


def test_a_cancelled_async_run_closes_its_streams_and_its_flow() -> None:
    transport = stream_transport()
    flow = StreamFlow(transport, "sleep")
    generator = flow()  # held here, so that only the driver can have closed it

    async def main() -> None:
        sleeping = asyncio.Event()

        async def sleep_for_ever(seconds: float) -> None:
            sleeping.set()
            await asyncio.Event().wait()

        async with AsyncClient(BASE, transport=httpx.MockTransport(transport)) as aio:
            aio._sleep = sleep_for_ever  # type: ignore[method-assign]
            task = asyncio.create_task(aio._run(generator))
            await sleeping.wait()
            assert [body.closes for body in transport.bodies] == [0]
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task

    asyncio.run(main())
    assert flow.trail == ["read progress", "flow closed"]
    assert inspect.getgeneratorstate(generator) == inspect.GEN_CLOSED
    assert [body.closes for body in transport.bodies] == [1]


def test_a_stream_that_fails_to_open_is_thrown_into_the_flow_and_its_answer_closed() -> None:
    problem = Body(b'{"status": 404, "code": "job_not_found", "detail": "no job j1"}')

    def answer() -> httpx.Response:
        headers = {"Content-Type": "application/problem+json"}
        return httpx.Response(404, stream=problem, headers=headers)

    def flow() -> actions.Flow[str]:
        try:
            yield actions.OpenStream(proto.events_request("j1"), 5.0)
        except NotFoundError as error:
            return f"caught {error.code}"
        return "opened"

    transport = Transport({("GET", "/jobs/j1/events"): [answer]})
    with Client(BASE, transport=httpx.MockTransport(transport)) as client:
        assert client._run(flow()) == "caught job_not_found"
    assert problem.closes == 1


def test_a_transport_failure_is_thrown_in_as_connection_failed() -> None:
    def refuse(request: httpx.Request) -> httpx.Response:
        raise httpx.ConnectError("refused", request=request)

    def flow() -> actions.Flow[str]:
        try:
            yield from actions.call(proto.health_request())
        except ConnectionFailedError as error:
            return error.code or ""
        return "answered"

    with Client(BASE, transport=httpx.MockTransport(refuse)) as client:
        assert client._run(flow()) == "connection_failed"

    async def main() -> str:
        async with AsyncClient(BASE, transport=httpx.MockTransport(refuse)) as aio:
            return await aio._run(flow())

    assert asyncio.run(main()) == "connection_failed"


# -- each public flow on its happy path, driven by hand -----------------------------------------

PHOTO = b"\x89PNG\r\n\x1a\nphoto"
TRIMAP = b"\x89PNG\r\n\x1a\ntrimap"
IMAGE = b"\x89PNG\r\n\x1a\nimage to fill"
MASK = b"\x89PNG\r\n\x1a\nmask"
ATLAS = b"\x89PNG\r\n\x1a\natlas"
MANIFEST = {"tiles": 8, "colors": 2}


def answer(status: int, path: str, **kwargs: Any) -> httpx.Response:
    return httpx.Response(status, request=httpx.Request("GET", BASE + path), **kwargs)


@dataclass
class HandDriver:
    """Answers the Sends of a flow per (method, path), in turn; records every action."""

    answers: dict[tuple[str, str], list[httpx.Response]]
    log: list[actions.Action] = field(default_factory=list)

    def run(self, flow: actions.Flow[Any]) -> Any:
        with actions.Steps(flow) as steps:
            for action in steps:
                self.log.append(action)
                assert len(self.log) < 100, "runaway flow"
                if isinstance(action, actions.Send):
                    queue = self.answers[(action.request.method, action.request.path)]
                    steps.reply = queue.pop(0)
                else:
                    assert isinstance(action, actions.Sleep), action
        return steps.result

    def requests(self) -> list[str]:
        return [
            f"{a.request.method} {a.request.path}" if isinstance(a, actions.Send) else f"sleep {a}"
            for a in self.log
        ]


def arguments_of(method: Callable[..., Any], /, *args: Any, **kwargs: Any) -> dict[str, Any]:
    """The ``locals()`` a method of the Client hands to ``actions.start``."""
    bound = inspect.signature(method).bind(None, *args, **kwargs)
    bound.apply_defaults()
    return dict(bound.arguments)


@dataclass(frozen=True)
class Case:
    """A public operation: how to call it, what it must post."""

    name: str
    args: tuple[Any, ...]
    kwargs: dict[str, Any]
    path: str
    parts: list[tuple[str, str, bytes]]
    options: dict[str, Any]
    downloads: tuple[str, ...] = ()


CASES = [
    Case(
        "synthesize",
        (TEXTURE,),
        {"width": 64, "height": 32, "companions": {"normal": NORMAL}, "block": 16, "seed": None},
        "/synthesize",
        [("texture", "texture", TEXTURE), ("companion", "normal.png", NORMAL)],
        {"width": 64, "height": 32, "block": 16},
        ("normal",),
    ),
    Case(
        "transfer",
        (TEXTURE, TARGET),
        {"companions": {"normal": NORMAL}, "overlap": 4},
        "/transfer",
        [
            ("texture", "texture", TEXTURE),
            ("target", "target", TARGET),
            ("companion", "normal.png", NORMAL),
        ],
        {"overlap": 4},
        ("normal",),
    ),
    Case(
        "matte",
        (TARGET, SILHOUETTE, [LAYER_0, LAYER_1]),
        {"normals": NORMALS_IN, "companions": ["clusters"], "seed": 5},
        "/matte",
        [
            ("target", "target", TARGET),
            ("silhouette", "silhouette", SILHOUETTE),
            ("layer", "layer", LAYER_0),
            ("layer", "layer", LAYER_1),
            ("normals", "normals", NORMALS_IN),
        ],
        {"seed": 5},
        ("clusters",),
    ),
    Case(
        "fill",
        (IMAGE, MASK),
        {"texture": TEXTURE, "companions": {"normal": NORMAL}, "block": 12, "error": None},
        "/fill",
        [
            ("image", "image", IMAGE),
            ("mask", "mask", MASK),
            ("texture", "texture", TEXTURE),
            ("companion", "normal.png", NORMAL),
        ],
        {"block": 12},
        ("normal",),
    ),
    Case(
        "extend",
        (IMAGE,),
        {"top": 8, "right": 4, "companions": {"normal": NORMAL}, "seed": 2},
        "/extend",
        [("image", "image", IMAGE), ("companion", "normal.png", NORMAL)],
        {"top": 8, "bottom": 0, "left": 0, "right": 4, "seed": 2},
        ("normal",),
    ),
    Case(
        "extract_alpha",
        (PHOTO, TRIMAP),
        {"method": "closed_form"},
        "/extract-alpha",
        [("photo", "photo", PHOTO), ("trimap", "trimap", TRIMAP)],
        {"method": "closed_form"},
    ),
    Case(
        "wang_tiles",
        (TEXTURE,),
        {"colors": 2, "tile": 32, "block": None},
        "/wang-tiles",
        [("texture", "texture", TEXTURE)],
        {"colors": 2, "tile": 32},
    ),
]


def check_post(action: actions.Action, case: Case, wait: str) -> None:
    assert isinstance(action, actions.Send)
    request = action.request
    assert (request.method, request.path, dict(request.params)) == (
        "POST",
        case.path,
        {"wait": wait},
    )
    parts = [(name, filename, content) for name, (filename, content, _) in request.files]
    assert parts == case.parts
    assert json.loads(request.data["options"]) == case.options
    assert request.hold == float(wait)


@pytest.mark.parametrize("case", CASES, ids=[case.name for case in CASES])
def test_each_submit_flow_posts_once_without_waiting(case: Case) -> None:
    name = f"submit_{case.name}" if case.name != "synthesize" else "submit"
    kwargs = {
        k: v for k, v in case.kwargs.items() if not (k == "companions" and case.name == "matte")
    }
    arguments = arguments_of(getattr(Client, name), *case.args, idempotency_key="key-1", **kwargs)
    driver = HandDriver({("POST", case.path): [answer(202, case.path, json=job_json("queued"))]})
    job = driver.run(actions.start(getattr(flows, name), arguments))
    [post] = driver.log
    check_post(post, case, "0")
    assert isinstance(post, actions.Send) and post.request.headers == {"Idempotency-Key": "key-1"}
    assert isinstance(job, JobStatus) and (job.id, job.status) == ("j1", "queued")


@pytest.mark.parametrize("case", CASES, ids=[case.name for case in CASES])
def test_each_run_flow_posts_polls_and_downloads_in_order(case: Case) -> None:
    downloads = {
        ("GET", f"/jobs/j1/result/{name}"): [
            answer(200, "/", content=CLUSTERS_OUT if name == "clusters" else NORMAL_OUT)
        ]
        for name in case.downloads
    }
    result_png = ATLAS if case.name == "wang_tiles" else RESULT
    driver = HandDriver(
        {
            ("POST", case.path): [answer(202, case.path, json=job_json("queued"))],
            ("GET", "/jobs/j1"): [
                answer(200, "/jobs/j1", json=job_json("running")),
                answer(200, "/jobs/j1", json=job_json("done")),
            ],
            ("GET", "/jobs/j1/result"): [
                answer(200, "/", content=result_png, headers={"Content-Type": "image/png"})
            ],
            ("GET", "/jobs/j1/manifest"): [answer(200, "/", json=MANIFEST)],
            **downloads,
        }
    )
    arguments = arguments_of(
        getattr(Client, case.name), *case.args, poll_interval=0.75, **case.kwargs
    )
    result = driver.run(actions.start(getattr(flows, case.name), arguments))
    check_post(driver.log[0], case, "10")  # held 10 s without a progress callback
    expected = [
        f"POST {case.path}",
        "sleep Sleep(seconds=0.75)",  # no Retry-After: the poll interval
        "GET /jobs/j1",
        "sleep Sleep(seconds=0.75)",
        "GET /jobs/j1",
        "GET /jobs/j1/result",
        *(f"GET /jobs/j1/result/{name}" for name in case.downloads),
    ]
    if case.name == "wang_tiles":
        expected.append("GET /jobs/j1/manifest")
    assert driver.requests() == expected
    if case.name == "wang_tiles":
        assert isinstance(result, WangTilesResult)
        assert (bytes(result), result.manifest, result.job_id) == (ATLAS, MANIFEST, "j1")
    else:
        assert isinstance(result, SynthesisResult)
        assert (bytes(result), result.job_id) == (RESULT, "j1")
        assert set(result.companions) == set(case.downloads)


@pytest.mark.parametrize("timeout", [None, 4.0])
def test_the_wait_flow_polls_the_job_until_it_ends(clock: Clock, timeout: float | None) -> None:
    driver = HandDriver(
        {
            ("GET", "/jobs/j1"): [
                answer(200, "/jobs/j1", json=job_json("queued")),
                answer(200, "/jobs/j1", json=job_json("done")),
            ]
        }
    )
    job = driver.run(flows.wait("j1", progress=None, timeout=timeout, poll_interval=0.3))
    assert driver.requests() == ["GET /jobs/j1", "sleep Sleep(seconds=0.3)", "GET /jobs/j1"]
    assert isinstance(job, JobStatus) and job.status == "done"


@pytest.mark.parametrize(
    ("body", "healthy"), [({"status": "ok"}, True), ({"status": "down"}, False)]
)
def test_the_health_flow_reads_the_status_of_healthz(body: dict[str, str], healthy: bool) -> None:
    driver = HandDriver({("GET", "/healthz"): [answer(200, "/healthz", json=body)]})
    assert driver.run(flows.health()) is healthy
    assert driver.requests() == ["GET /healthz"]


def test_a_result_answered_at_once_skips_the_polling(clock: Clock) -> None:
    calls: list[tuple[float, str]] = []
    png = answer(
        200, "/synthesize", content=RESULT, headers={"Content-Type": "image/png", "X-Job-Id": "j7"}
    )
    driver = HandDriver({("POST", "/synthesize"): [png]})
    arguments = arguments_of(
        Client.synthesize, TEXTURE, width=8, height=8, progress=lambda f, s: calls.append((f, s))
    )
    result = driver.run(actions.start(flows.synthesize, arguments))
    assert driver.requests() == ["POST /synthesize"]
    assert isinstance(result, SynthesisResult) and (bytes(result), result.job_id) == (RESULT, "j7")
    assert calls == [(1.0, "done")]
