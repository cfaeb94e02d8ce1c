"""Unit tests of the service's ASGI middleware, driven directly.

Covers :mod:`quilting.service.middleware`: :class:`BodyLimit` (a body of exactly the limit
passes, one byte more is 413 ``body_too_large`` before the app sees that byte, a
Content-Length over the limit is refused before the app runs, chunked bodies are counted, the
rest of a refused body is drained up to ``drain`` bytes), :class:`RequestTimeout` (408
``request_timeout`` with ``Connection: close`` for a body that stalls, under a fake clock; no
408 once the app has begun its answer; the deadline covers the whole body and nothing past
it), :class:`ResponseHeaders` (``nosniff`` and ``no-store`` on every answer, the problem
answers included, without replacing a route's own policy), the order
:func:`~quilting.service.middleware.add_middleware` stacks them in, and lifespan and websocket
scopes passing through all three untouched.

Each middleware wraps a tiny inner ASGI app and is called with hand-made scope, receive and
send callables under ``asyncio.run`` (no server, no network). The hand-made client behaves
like uvicorn: once its body is sent, ``receive`` waits for a disconnect that never comes, so
every run is bounded by a timeout that fails the test rather than hanging it.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Awaitable, Callable, Iterator, MutableMapping
from contextlib import AbstractContextManager
from typing import Any

import anyio
import pytest
from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse

from quilting.service import middleware
from quilting.service.middleware import BodyLimit, RequestTimeout, ResponseHeaders
from quilting.service.problems import PROBLEM_TYPE
from quilting.service.settings import Settings

Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
App = Callable[[MutableMapping[str, Any], Receive, Send], Awaitable[None]]

#: Longest one call may take before the test fails (every call here takes milliseconds).
BOUND_S = 5.0


# --- a hand-made client -----------------------------------------------------------------------


class Client:
    """The client side of one request: its body in messages, and what it was sent.

    Parameters
    ----------
    *bodies : bytes
        The body, one ``http.request`` message each; the last says ``more_body: False``
        unless ``stall``.
    stall : bool
        Stop after the bodies, mid-upload: the next ``receive`` never returns.
    seconds_per_message : float
        How far each message moves ``clock`` (the time the client takes to send it).
    clock : FakeAnyio, optional
        The fake clock those seconds pass on.
    """

    def __init__(
        self,
        *bodies: bytes,
        stall: bool = False,
        seconds_per_message: float = 0.0,
        clock: FakeAnyio | None = None,
    ) -> None:
        last = len(bodies) - 1
        self.pending: list[Message] = [
            {"type": "http.request", "body": body, "more_body": stall or i < last}
            for i, body in enumerate(bodies)
        ]
        self.handed = 0  # messages handed to the server
        self.waits = 0  # receives that found nothing more to hand and waited
        self.sent: list[Message] = []
        self.seconds_per_message = seconds_per_message
        self.clock = clock

    async def receive(self) -> Message:
        if self.pending:
            self.handed += 1
            if self.clock is not None:
                self.clock.now += self.seconds_per_message
            return self.pending.pop(0)
        self.waits += 1
        await asyncio.Event().wait()  # a body that stops coming, or a disconnect never made
        raise AssertionError("unreachable")

    async def send(self, message: Message) -> None:
        self.sent.append(dict(message))


def http_scope(content_length: bytes | None = None) -> dict[str, Any]:
    """A POST scope, with a Content-Length header when one is given."""
    headers = [(b"content-type", b"application/octet-stream")]
    if content_length is not None:
        headers.append((b"content-length", content_length))
    return {
        "type": "http",
        "asgi": {"version": "3.0"},
        "http_version": "1.1",
        "method": "POST",
        "scheme": "http",
        "path": "/echo",
        "raw_path": b"/echo",
        "root_path": "",
        "query_string": b"",
        "headers": headers,
        "client": ("127.0.0.1", 40000),
        "server": ("127.0.0.1", 8000),
    }


def run(app: App, client: Client, scope: MutableMapping[str, Any] | None = None) -> None:
    """Call ``app`` for one request of ``client``, failing past BOUND_S instead of hanging."""

    async def bounded() -> None:
        await asyncio.wait_for(
            app(http_scope() if scope is None else scope, client.receive, client.send), BOUND_S
        )

    asyncio.run(bounded())


def response(client: Client) -> tuple[int, list[tuple[str, str]], bytes]:
    """The one answer ``client`` got: status, headers (lower-case names), whole body."""
    starts = [m for m in client.sent if m["type"] == "http.response.start"]
    assert len(starts) == 1, client.sent
    assert client.sent[0]["type"] == "http.response.start", client.sent
    bodies = [m for m in client.sent if m["type"] == "http.response.body"]
    assert bodies and not bodies[-1].get("more_body", False), client.sent
    headers = [(k.decode("latin-1").lower(), v.decode("latin-1")) for k, v in starts[0]["headers"]]
    return starts[0]["status"], headers, b"".join(m.get("body", b"") for m in bodies)


def header(headers: list[tuple[str, str]], name: str) -> str:
    """The one value of ``name`` (lower case) among ``headers``."""
    values = [v for k, v in headers if k == name]
    assert len(values) == 1, (name, headers)
    return values[0]


def assert_problem(client: Client, status: int, code: str, detail: str) -> list[tuple[str, str]]:
    """``client`` got exactly one problem+json answer; returns its headers."""
    got, headers, body = response(client)
    assert got == status
    assert header(headers, "content-type") == "application/problem+json"
    assert int(header(headers, "content-length")) == len(body)
    problem = json.loads(body)
    assert problem["type"] == PROBLEM_TYPE + code
    assert problem["status"] == status
    assert problem["code"] == code
    assert problem["detail"] == detail
    return headers


# --- tiny inner apps --------------------------------------------------------------------------


class Reader:
    """An app that reads the whole body, then answers 200 with the bytes it got.

    Told the client left, it asks once more (a parser that keeps reading), then answers 499,
    which must never reach the client. ``answer_first`` sends its response start before
    reading; ``fail`` raises instead of answering the disconnect.
    """

    def __init__(self, *, answer_first: bool = False, fail: bool = False) -> None:
        self.messages: list[Message] = []
        self.answer_first = answer_first
        self.fail = fail
        self.calls = 0

    @property
    def body(self) -> bytes:
        return b"".join(m.get("body", b"") for m in self.messages)

    @property
    def disconnected(self) -> bool:
        return any(m["type"] == "http.disconnect" for m in self.messages)

    async def __call__(self, scope: MutableMapping[str, Any], receive: Receive, send: Send) -> None:
        self.calls += 1
        if self.answer_first:
            headers = [(b"content-type", b"text/plain")]
            await send({"type": "http.response.start", "status": 200, "headers": headers})
        while True:
            message = await receive()
            self.messages.append(message)
            if message["type"] == "http.disconnect":
                self.messages.append(await receive())
                if self.fail:
                    raise RuntimeError("the client left")  # as Starlette's ClientDisconnect
                status = 499
                break
            if not message.get("more_body", False):
                status = 200
                break
        if not self.answer_first:
            headers = [(b"content-type", b"text/plain")]
            await send({"type": "http.response.start", "status": status, "headers": headers})
        await send({"type": "http.response.body", "body": b"got %d" % len(self.body)})


async def never_called(scope: MutableMapping[str, Any], receive: Receive, send: Send) -> None:
    raise AssertionError("the app ran for a request that should have been refused")


# --- BodyLimit --------------------------------------------------------------------------------


@pytest.mark.parametrize("content_length", [None, b"10"], ids=["chunked", "declared"])
def test_a_body_of_exactly_the_limit_reaches_the_app_whole(content_length: bytes | None) -> None:
    app = Reader()
    client = Client(b"abcd", b"efghij")
    run(BodyLimit(app, limit=10), client, http_scope(content_length))
    assert app.body == b"abcdefghij"
    assert not app.disconnected
    assert response(client) == (200, [("content-type", "text/plain")], b"got 10")


def test_one_byte_over_the_limit_is_413_before_the_app_sees_that_byte() -> None:
    app = Reader()
    client = Client(b"a" * 6, b"b" * 5, b"c" * 3, b"")  # 14 bytes, chunked: no Content-Length
    run(BodyLimit(app, limit=10), client)
    # The app had the first 6 bytes; the message that crossed the limit became a disconnect,
    # and so did its next read, without another message taken from the client for it.
    assert app.body == b"a" * 6
    assert [m["type"] for m in app.messages] == ["http.request"] + ["http.disconnect"] * 2
    assert_problem(
        client,
        413,
        "body_too_large",
        "the request body is 11 bytes or more; the limit is 10 (max_body_bytes)",
    )
    assert json.loads(response(client)[2])["title"] == "Payload too large"
    # The rest of the body was read and dropped, so the client is answered, not reset.
    assert client.pending == [] and client.handed == 4 and client.waits == 0


@pytest.mark.parametrize("declared", [b"11", b"1000000000"])
def test_a_content_length_over_the_limit_is_refused_before_the_app_runs(declared: bytes) -> None:
    client = Client(b"x" * 6, b"y" * 5)
    run(BodyLimit(never_called, limit=10), client, http_scope(declared))
    detail = f"the request body is {int(declared)} bytes or more; the limit is 10 (max_body_bytes)"
    assert_problem(client, 413, "body_too_large", detail)
    assert client.pending == [] and client.waits == 0  # drained to its last message


@pytest.mark.parametrize("declared", [None, b"", b"ten", b"-1", b"5"])
def test_a_body_is_counted_whatever_its_content_length_says(declared: bytes | None) -> None:
    app = Reader()
    client = Client(b"a" * 6, b"b" * 6, b"")
    run(BodyLimit(app, limit=10), client, http_scope(declared))
    assert app.body == b"a" * 6
    assert_problem(
        client,
        413,
        "body_too_large",
        "the request body is 12 bytes or more; the limit is 10 (max_body_bytes)",
    )


@pytest.mark.parametrize("bodies", [(b"x" * 11,), (b"a" * 6, b"b" * 6)])
def test_a_body_that_ends_over_the_limit_is_answered_at_once(bodies: tuple[bytes, ...]) -> None:
    # The message that crosses the limit is the body's last (a chunked upload whose final
    # chunk is large): nothing is left to drain, and a read would wait for the client to
    # leave (uvicorn's receive after the body), so the 413 would never be sent.
    app = Reader()
    client = Client(*bodies)
    run(BodyLimit(app, limit=10), client)
    assert response(client)[0] == 413
    assert client.pending == [] and client.waits == 0


def test_many_small_chunks_add_up_to_the_limit() -> None:
    app = Reader()
    client = Client(*[b"z"] * 10)
    run(BodyLimit(app, limit=10), client)
    assert response(client)[0] == 200 and app.body == b"z" * 10

    app = Reader()
    client = Client(*[b"z"] * 11, b"")
    run(BodyLimit(app, limit=10), client)
    assert app.body == b"z" * 10
    assert response(client)[0] == 413


def test_the_drain_of_a_refused_body_stops_after_drain_bytes() -> None:
    client = Client(b"a" * 5, *[b"b" * 4] * 10)  # 45 bytes, over the limit at the first
    run(BodyLimit(Reader(), limit=4, drain=10), client)
    assert response(client)[0] == 413
    assert client.handed == 1 + 3  # the message over the limit, then 12 >= 10 bytes drained
    assert len(client.pending) == 7


def test_an_error_the_app_raises_once_told_the_client_left_still_ends_in_413() -> None:
    client = Client(b"a" * 11, b"")
    run(BodyLimit(Reader(fail=True), limit=10), client)
    assert response(client)[0] == 413


def test_an_error_the_app_raises_under_the_limit_is_not_swallowed() -> None:
    async def app(scope: MutableMapping[str, Any], receive: Receive, send: Send) -> None:
        await receive()
        raise RuntimeError("a bug in the app")

    with pytest.raises(RuntimeError, match="a bug in the app"):
        run(BodyLimit(app, limit=10), Client(b"a" * 10))


# --- RequestTimeout ---------------------------------------------------------------------------


class FakeAnyio:
    """Stands in for the ``anyio`` the middleware uses: a clock and ``fail_after``.

    Time is virtual: ``now`` moves only when a test (or its client) moves it, and a wait that
    blocks - the client has nothing more to send - lasts until the deadline at once. Every
    delay the middleware asks for is kept in ``delays``.
    """

    def __init__(self) -> None:
        self.now = 1000.0
        self.delays: list[float] = []

    def current_time(self) -> float:
        return self.now

    def fail_after(self, delay: float | None) -> AbstractContextManager[Any]:
        assert delay is not None
        self.delays.append(delay)
        # A real scope that is past its deadline: a receive that returns at once gets its
        # message; one that blocks is cancelled and raises TimeoutError.
        return anyio.fail_after(0)


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> Iterator[FakeAnyio]:
    fake = FakeAnyio()
    monkeypatch.setattr(middleware, "anyio", fake)
    yield fake


def test_the_deadline_covers_the_whole_body_not_each_read(clock: FakeAnyio) -> None:
    app = Reader()
    client = Client(b"a", b"b", b"c", b"d", seconds_per_message=10.0, clock=clock)
    run(RequestTimeout(app, seconds=25), client)
    # Each read gets what is left of the one deadline (never less than nothing).
    assert clock.delays == [25.0, 15.0, 5.0, 0.0]
    assert app.body == b"abcd"
    assert response(client) == (200, [("content-type", "text/plain")], b"got 4")


def test_a_stalled_body_is_answered_408_with_connection_close(clock: FakeAnyio) -> None:
    app = Reader()
    client = Client(b"\x89PNG", stall=True)
    run(RequestTimeout(app, seconds=2.5), client)
    # The app is told the client left (twice, without the client being asked again) and its
    # answer to that is not sent: the one answer is the 408.
    assert [m["type"] for m in app.messages] == ["http.request"] + ["http.disconnect"] * 2
    assert client.waits == 1
    headers = assert_problem(
        client,
        408,
        "request_timeout",
        "the request body did not arrive within 2.5 s (request_timeout_s)",
    )
    assert header(headers, "connection") == "close"
    assert json.loads(response(client)[2])["title"] == "Request timeout"


def test_a_stall_after_the_answer_began_sends_nothing_twice(clock: FakeAnyio) -> None:
    app = Reader(answer_first=True)
    client = Client(b"ab", stall=True)
    run(RequestTimeout(app, seconds=30), client)
    assert app.disconnected
    status, _, body = response(client)  # exactly one start, and the app's own body after it
    assert (status, body) == (200, b"got 2")
    assert not any(b"request_timeout" in m.get("body", b"") for m in client.sent)


def test_an_error_the_app_raises_once_timed_out_still_ends_in_408(clock: FakeAnyio) -> None:
    client = Client(stall=True)
    run(RequestTimeout(Reader(fail=True), seconds=30), client)
    assert response(client)[0] == 408


def test_an_error_the_app_raises_in_time_is_not_swallowed(clock: FakeAnyio) -> None:
    async def app(scope: MutableMapping[str, Any], receive: Receive, send: Send) -> None:
        await receive()
        raise RuntimeError("a bug in the app")

    with pytest.raises(RuntimeError, match="a bug in the app"):
        run(RequestTimeout(app, seconds=30), Client(b"x"))


def test_reads_past_the_end_of_the_body_are_not_timed(clock: FakeAnyio) -> None:
    """A streaming answer waits on receive for the client to leave: no deadline there."""
    got: list[Message] = []

    async def app(scope: MutableMapping[str, Any], receive: Receive, send: Send) -> None:
        got.append(await receive())
        await send({"type": "http.response.start", "status": 200, "headers": []})
        clock.now += 3600.0  # an hour of streaming later
        got.append(await receive())
        await send({"type": "http.response.body", "body": b"done"})

    client = Client(b"x")
    client.pending.append({"type": "http.disconnect"})
    run(RequestTimeout(app, seconds=30), client)
    assert got == [
        {"type": "http.request", "body": b"x", "more_body": False},
        {"type": "http.disconnect"},
    ]
    assert clock.delays == [30.0]  # only the body's read was timed
    assert response(client)[0] == 200


def test_a_stalled_body_is_cut_at_the_deadline_on_the_real_clock() -> None:
    client = Client(b"x", stall=True)
    run(RequestTimeout(Reader(), seconds=0.02), client)
    assert response(client)[0] == 408
    assert header(response(client)[1], "connection") == "close"


# --- ResponseHeaders --------------------------------------------------------------------------


async def plain(scope: MutableMapping[str, Any], receive: Receive, send: Send) -> None:
    await send({"type": "http.response.start", "status": 201, "headers": [(b"x-job-id", b"j")]})
    await send({"type": "http.response.body", "body": b"part", "more_body": True})
    await send({"type": "http.response.body", "body": b"-end"})


def test_every_answer_says_nosniff_and_no_store() -> None:
    client = Client(b"")
    run(ResponseHeaders(plain), client)
    status, headers, body = response(client)
    assert (status, body) == (201, b"part-end")
    assert sorted(headers) == [
        ("cache-control", "no-store"),
        ("x-content-type-options", "nosniff"),
        ("x-job-id", "j"),
    ]
    assert [m.get("more_body", False) for m in client.sent[1:]] == [True, False]


def test_a_routes_own_headers_are_kept_not_doubled() -> None:
    async def cached(scope: MutableMapping[str, Any], receive: Receive, send: Send) -> None:
        # ASGI header names are lower case (Starlette's responses write them so).
        own = [(b"cache-control", b"public, max-age=60"), (b"x-content-type-options", b"nosniff")]
        await send({"type": "http.response.start", "status": 200, "headers": own})
        await send({"type": "http.response.body", "body": b""})

    client = Client(b"")
    run(ResponseHeaders(cached), client)
    _, headers, _ = response(client)
    assert header(headers, "cache-control") == "public, max-age=60"
    assert header(headers, "x-content-type-options") == "nosniff"
    assert len(headers) == 2


# --- the stack add_middleware builds ----------------------------------------------------------


@pytest.fixture
def service() -> FastAPI:
    """An app with one route that reads its body, in the service's middleware (limit 10)."""
    app = FastAPI()

    @app.post("/echo")
    async def echo(request: Request) -> JSONResponse:
        return JSONResponse({"bytes": len(await request.body())})

    middleware.add_middleware(app, Settings(max_body_bytes=10, request_timeout_s=4))
    return app


def assert_stamped(headers: list[tuple[str, str]]) -> None:
    assert header(headers, "x-content-type-options") == "nosniff"
    assert header(headers, "cache-control") == "no-store"


def test_the_stack_passes_a_body_of_the_limit(service: FastAPI) -> None:
    client = Client(b"0123456789")
    run(service, client)
    status, headers, body = response(client)
    assert (status, json.loads(body)) == (200, {"bytes": 10})
    assert_stamped(headers)


@pytest.mark.parametrize("declared", [None, b"11"], ids=["chunked", "declared"])
def test_the_stacks_413_carries_the_service_headers(
    service: FastAPI, declared: bytes | None
) -> None:
    client = Client(b"0123456789", b"a", b"")
    run(service, client, http_scope(declared))
    detail = "the request body is 11 bytes or more; the limit is 10 (max_body_bytes)"
    assert_stamped(assert_problem(client, 413, "body_too_large", detail))


def test_the_stacks_408_carries_the_service_headers(service: FastAPI, clock: FakeAnyio) -> None:
    client = Client(b"01234", stall=True)
    run(service, client)
    detail = "the request body did not arrive within 4 s (request_timeout_s)"
    headers = assert_problem(client, 408, "request_timeout", detail)
    assert header(headers, "connection") == "close"
    assert_stamped(headers)


def test_the_drain_of_a_refused_body_is_timed_too(service: FastAPI, clock: FakeAnyio) -> None:
    """A client over the limit that then stalls is let go (408), not held while drained."""
    client = Client(b"0123456789", b"ab", stall=True)
    run(service, client)
    headers = assert_problem(
        client,
        408,
        "request_timeout",
        "the request body did not arrive within 4 s (request_timeout_s)",
    )
    assert_stamped(headers)


# --- other scopes -----------------------------------------------------------------------------


MIDDLEWARES: list[tuple[str, Callable[[App], App]]] = [
    ("body_limit", lambda app: BodyLimit(app, limit=1)),
    ("request_timeout", lambda app: RequestTimeout(app, seconds=0.1)),
    ("response_headers", ResponseHeaders),
]


@pytest.mark.parametrize("scope_type", ["lifespan", "websocket"])
@pytest.mark.parametrize("wrap", [w for _, w in MIDDLEWARES], ids=[n for n, _ in MIDDLEWARES])
def test_other_scopes_pass_through_untouched(
    wrap: Callable[[App], App], scope_type: str, clock: FakeAnyio
) -> None:
    seen: list[tuple[MutableMapping[str, Any], Receive, Send]] = []
    start = {"type": "http.response.start", "status": 200, "headers": []}

    async def inner(scope: MutableMapping[str, Any], receive: Receive, send: Send) -> None:
        seen.append((scope, receive, send))
        await send(start)  # would be stamped, were this an http scope

    client = Client(b"far more than one byte")
    scope = {
        "type": scope_type,
        "asgi": {"version": "3.0"},
        "headers": [(b"content-length", b"99")],
    }
    run(wrap(inner), client, scope)
    assert len(seen) == 1
    assert seen[0][0] is scope
    assert seen[0][1] == client.receive and seen[0][2] == client.send
    assert client.sent == [{"type": "http.response.start", "status": 200, "headers": []}]
    assert clock.delays == []
