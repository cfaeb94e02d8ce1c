"""How the service is started (:mod:`quilting.service.server`), without serving anything.

Covers
------
- ``quilting serve``'s flags and ``QUILTING_*`` variables reaching uvicorn: the
  :class:`uvicorn.Config` that :func:`~quilting.service.server.serve` builds (host, port, log
  level, graceful-shutdown time, one uvicorn process, the header-timed HTTP protocol at
  ``request_timeout_s``), the app built from those settings and the SIGTERM/SIGINT handlers
  installed (``DrainingServer.serve`` and ``signal.signal`` are replaced by recorders);
- bad settings: exit status 2 and one line naming the setting, no traceback, nothing built;
- :class:`~quilting.service.server.DrainingServer` on a fake clock and a fake job queue: the
  first signal drains (readiness flag, deadline), the server exits once idle for
  :data:`~quilting.service.server.LINGER_S` or past ``drain_grace_s``, a second signal stops
  at once;
- :func:`~quilting.service.server.header_timed` on a fake transport: a connection whose
  request headers stall is closed, one whose request is being answered is not, and a
  kept-alive connection with no next request is closed after the answer.

``tests/service/test_drain.py`` checks a real drain end to end (``SIGTERM`` to a server);
``tests/service/test_settings.py`` a bad variable through a ``quilting serve`` subprocess.
"""

from __future__ import annotations

import asyncio
import os
import signal
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import pytest
import uvicorn
from uvicorn.protocols.http.h11_impl import H11Protocol
from uvicorn.server import ServerState

from quilting import cli
from quilting.service import server as server_module
from quilting.service.server import LINGER_S, DrainingServer, header_timed
from quilting.service.settings import Settings

#: Deadlines of the waits below: they only bound a failing test.
WAIT_S = 30.0


@pytest.fixture
def clean_env(monkeypatch: pytest.MonkeyPatch) -> pytest.MonkeyPatch:
    """No ``QUILTING_*`` variable of the machine running the tests leaks into the settings."""
    for name in list(os.environ):
        if name.startswith("QUILTING_"):
            monkeypatch.delenv(name)
    return monkeypatch


# --- serve: settings to uvicorn ------------------------------------------------------------


def test_serve_turns_flags_and_variables_into_the_uvicorn_config(
    clean_env: pytest.MonkeyPatch,
) -> None:
    served: list[DrainingServer] = []
    handlers: dict[int, Any] = {}
    timeouts: list[float] = []

    async def record_serve(self: DrainingServer, sockets: Any = None) -> None:
        served.append(self)
        # The handlers in force while it would serve (asyncio.run's own SIGINT handler not).
        handlers.update({sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGINT)})

    def record_header_timed(seconds: float) -> type[H11Protocol]:
        timeouts.append(seconds)
        protocol: type[H11Protocol] = header_timed(seconds)
        return protocol

    clean_env.setenv("QUILTING_REQUEST_TIMEOUT_S", "12.5")
    clean_env.setenv("QUILTING_DRAIN_GRACE_S", "7")
    clean_env.setenv("QUILTING_WORKER_MODE", "thread")
    clean_env.setenv("QUILTING_PORT", "1234")  # the flag wins
    clean_env.setattr(DrainingServer, "serve", record_serve)
    clean_env.setattr(server_module, "header_timed", record_header_timed)

    argv = ["serve", "--host", "0.0.0.0", "--port", "9123", "--workers", "3"]
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGINT)}
    try:
        assert cli.main(argv) == 0
    finally:
        for sig, handler in before.items():
            signal.signal(sig, handler)

    (server,) = served
    config = server.config
    assert (config.host, config.port) == ("0.0.0.0", 9123)
    assert config.log_level == "info"
    assert config.timeout_graceful_shutdown == 5
    # --workers are compute workers: one uvicorn process owns the in-memory job queue.
    assert config.workers == 1
    assert timeouts == [12.5]
    assert isinstance(config.http, type) and issubclass(config.http, H11Protocol)
    assert config.app is server.app
    settings = server.settings
    app: Any = server.app
    assert app.state.service.settings is settings
    assert (settings.workers, settings.compute_workers, settings.worker_mode) == (3, 3, "thread")
    assert settings.drain_grace_s == 7.0
    assert app.state.draining is False and server.draining_since is None
    assert app.state.service.sandbox.pids() == []  # nothing started without serving
    assert handlers == {signal.SIGTERM: server.handle_exit, signal.SIGINT: server.handle_exit}


@pytest.mark.parametrize(
    ("argv", "env", "named", "hidden"),
    [
        (["serve", "--port", "70000"], {}, "port", None),
        (["serve", "--workers", "-1"], {}, "workers", None),
        (["serve"], {"QUILTING_SANDBOX_TIMEOUT_S": "soon"}, "QUILTING_SANDBOX_TIMEOUT_S", None),
        (["serve", "--queue", "ftp://user:hunter2@host/0"], {}, "queue", "hunter2"),
    ],
)
def test_bad_settings_exit_2_with_one_line_before_anything_is_built(
    clean_env: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    argv: list[str],
    env: dict[str, str],
    named: str,
    hidden: str | None,
) -> None:
    def never(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("the service was built from refused settings")

    for name, value in env.items():
        clean_env.setenv(name, value)
    clean_env.setattr(server_module, "create_app", never)
    clean_env.setattr(uvicorn, "Config", never)
    with pytest.raises(SystemExit) as caught:
        cli.main(argv)
    assert caught.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("quilting: error: ") and err.count("\n") == 1, err
    assert named in err and "Traceback" not in err
    if hidden is not None:
        assert hidden not in err


# --- DrainingServer: signals and the drain -------------------------------------------------


class _Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def monotonic(self) -> float:
        return self.now


def _draining_server(
    monkeypatch: pytest.MonkeyPatch, grace: float
) -> tuple[DrainingServer, _Clock, SimpleNamespace]:
    """A DrainingServer over a stand-in app whose job queue's ``busy()`` the test sets."""
    clock = _Clock()
    monkeypatch.setattr(server_module, "time", clock)
    jobs = SimpleNamespace(busy_now=False)
    jobs.busy = lambda: jobs.busy_now
    state = SimpleNamespace(service=SimpleNamespace(jobs=jobs), draining=False, drain_deadline=None)
    app: Any = SimpleNamespace(state=state)
    server = DrainingServer(uvicorn.Config(app), app, Settings(drain_grace_s=grace))
    return server, clock, jobs


def _tick(server: DrainingServer) -> bool:
    # Counter 1: uvicorn's once-a-second header refresh (which needs a loaded config) skipped.
    exits: bool = asyncio.run(server.on_tick(1))
    return exits


def test_the_first_signal_drains_and_the_server_exits_once_idle_for_the_linger(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    server, clock, jobs = _draining_server(monkeypatch, grace=30.0)
    # Not draining: idle ticks never stop the server.
    assert _tick(server) is False

    jobs.busy_now = True
    server.handle_exit(signal.SIGTERM, None)
    assert server.app.state.draining is True
    assert server.app.state.drain_deadline == clock.now + 30.0
    assert not server.should_exit and not server.force_exit
    assert _tick(server) is False

    clock.now += 10.0
    jobs.busy_now = False  # the last job ended
    assert _tick(server) is False
    clock.now += LINGER_S / 2
    assert _tick(server) is False
    jobs.busy_now = True  # a job still queued started: the linger starts again when it ends
    assert _tick(server) is False
    jobs.busy_now = False
    clock.now += LINGER_S / 2
    assert _tick(server) is False
    clock.now += LINGER_S
    assert _tick(server) is True
    assert server.should_exit and not server.force_exit


def test_a_drain_ends_at_its_grace_even_with_jobs_running(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    server, clock, jobs = _draining_server(monkeypatch, grace=5.0)
    jobs.busy_now = True
    server.handle_exit(signal.SIGINT, None)
    clock.now += 5.0
    assert _tick(server) is False  # at the grace, not past it
    clock.now += 0.01
    assert _tick(server) is True


def test_a_second_signal_stops_at_once(monkeypatch: pytest.MonkeyPatch) -> None:
    server, clock, jobs = _draining_server(monkeypatch, grace=600.0)
    jobs.busy_now = True
    server.handle_exit(signal.SIGTERM, None)
    deadline = server.app.state.drain_deadline
    assert not server.should_exit
    clock.now += 1.0
    server.handle_exit(signal.SIGTERM, None)
    assert server.should_exit
    assert server.app.state.drain_deadline == deadline  # the drain is not restarted
    assert _tick(server) is True
    server.handle_exit(signal.SIGINT, None)  # a third, Ctrl-C: uvicorn's forced exit
    assert server.force_exit


# --- header_timed: a connection's headers on a timer ---------------------------------------


class _Transport(asyncio.Transport):
    """What a protocol needs of a socket's transport: writes kept, a close recorded."""

    def __init__(self) -> None:
        super().__init__()
        self.closed = asyncio.Event()
        self.written = b""

    def get_extra_info(self, name: str, default: Any = None) -> Any:
        return default

    def is_closing(self) -> bool:
        return self.closed.is_set()

    def close(self) -> None:
        self.closed.set()

    def write(self, data: bytes | bytearray | memoryview) -> None:
        self.written += bytes(data)

    def pause_reading(self) -> None:
        pass

    def resume_reading(self) -> None:
        pass


def _connect(
    seconds: float, app: Callable[..., Any]
) -> tuple[H11Protocol, _Transport, asyncio.AbstractEventLoop]:
    """A header-timed protocol on a fake connection (keep-alive far longer than the test)."""
    config = uvicorn.Config(
        app, timeout_keep_alive=3600, log_level="warning", lifespan="off", interface="asgi3"
    )
    loop = asyncio.get_running_loop()
    protocol = header_timed(seconds)(config, ServerState(), {}, loop)
    transport = _Transport()
    protocol.connection_made(transport)
    return protocol, transport, loop


async def _answer_when(release: asyncio.Event, scope: Any, receive: Any, send: Any) -> None:
    await release.wait()
    await send({"type": "http.response.start", "status": 204, "headers": []})
    await send({"type": "http.response.body", "body": b""})


def test_a_connection_whose_headers_stall_is_closed() -> None:
    async def main() -> None:
        release = asyncio.Event()
        protocol, transport, loop = _connect(0.2, lambda *a: _answer_when(release, *a))
        timer = protocol._header_timer  # type: ignore[attr-defined]
        assert timer is not None and 0 < timer.when() - loop.time() <= 0.2
        protocol.data_received(b"GET /healthz HTTP/1.1\r\nHost: x\r\n")  # then nothing
        await asyncio.wait_for(transport.closed.wait(), WAIT_S)
        assert transport.written == b""  # dropped, not answered
        protocol.connection_lost(None)

    asyncio.run(main())


def test_a_request_in_progress_is_not_cut_and_keep_alive_is_timed_after_the_answer() -> None:
    async def main() -> None:
        release = asyncio.Event()
        protocol, transport, _ = _connect(0.2, lambda *a: _answer_when(release, *a))
        protocol.data_received(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")
        # The timer of the first request's headers fires while the app works: no close.
        deadline = asyncio.get_running_loop().time() + WAIT_S
        while protocol._header_timer is not None:  # type: ignore[attr-defined]
            assert asyncio.get_running_loop().time() < deadline, "the header timer never fired"
            await asyncio.sleep(0.01)
        assert not transport.is_closing()
        release.set()
        # Answered; no next request on the kept-alive connection: closed on the header timer
        # (uvicorn's own keep-alive would wait an hour).
        await asyncio.wait_for(transport.closed.wait(), WAIT_S)
        assert transport.written.startswith(b"HTTP/1.1 204")
        protocol.connection_lost(None)

    asyncio.run(main())
