"""Fixtures of the service tests: real ``quilting serve`` processes with different settings.

Each server fixture starts ``python -m quilting serve --port P`` with ``QUILTING_*`` variables,
waits for ``/healthz`` and stops the process at the end of the session. When a test fails, the
logs of the servers it used are added to its report.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import pytest
from service_helpers import SECURED_RESULTS_TTL_S, Server

SERVERS_USED = pytest.StashKey[list[Server]]()
LOG_TAIL_LINES = 150


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Iterator[None]:
    outcome = yield
    report = outcome.get_result()
    if not report.failed:
        return
    servers = [v for v in getattr(item, "funcargs", {}).values() if isinstance(v, Server)]
    servers += item.stash.get(SERVERS_USED, [])
    for server in dict.fromkeys(servers):
        tail = "\n".join(server.log().splitlines()[-LOG_TAIL_LINES:])
        report.sections.append((f"server log: {server.name} ({server.url})", tail))


@pytest.fixture(scope="session")
def log_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("service-logs")


def _session_server(name: str, env: dict[str, str], log_dir: Path) -> Iterator[Server]:
    server = Server(name, {"QUILTING_DRAIN_GRACE_S": "5", **env}, log_dir).start()
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture(scope="session")
def server(log_dir: Path) -> Iterator[Server]:
    """Default limits, two compute workers."""
    yield from _session_server("default", {"QUILTING_WORKERS": "2"}, log_dir)


@pytest.fixture(scope="session")
def small_server(log_dir: Path) -> Iterator[Server]:
    """One worker, a queue of 2, small body/file limits, 2 results kept."""
    env = {
        "QUILTING_WORKERS": "1",
        "QUILTING_MAX_QUEUED": "2",
        "QUILTING_MAX_FILE_BYTES": "40000",  # brick.png (30 kB) fits, gravel.png (54 kB) not
        "QUILTING_MAX_BODY_BYTES": "1000000",
        "QUILTING_RESULTS_MAX_COUNT": "2",
    }
    yield from _session_server("small", env, log_dir)


@pytest.fixture(scope="session")
def secured_server(log_dir: Path) -> Iterator[Server]:
    """API keys k1 and k2, CORS for https://app.example, results kept for a few seconds."""
    env = {
        "QUILTING_WORKERS": "2",
        "QUILTING_API_KEYS": "k1,k2",
        "QUILTING_CORS_ORIGINS": "https://app.example",
        "QUILTING_RESULTS_TTL_S": str(SECURED_RESULTS_TTL_S),
    }
    yield from _session_server("secured", env, log_dir)


@pytest.fixture(scope="session")
def timeout_server(log_dir: Path) -> Iterator[Server]:
    """Jobs fail after 0.2 s. The cost model is told the machine is 1000 times faster, so that
    jobs it would refuse as over their time budget are accepted and reach the time limit."""
    env = {
        "QUILTING_WORKERS": "1",
        "QUILTING_JOB_TIMEOUT_S": "0.2",
        "QUILTING_SECONDS_SCALE": "0.001",
    }
    yield from _session_server("timeout", env, log_dir)


@pytest.fixture
def start_server(
    request: pytest.FixtureRequest, log_dir: Path
) -> Iterator[Callable[[str, dict[str, str]], Server]]:
    """A factory of servers owned by one test (stopped after it)."""
    started: list[Server] = []
    request.node.stash[SERVERS_USED] = started

    def start(name: str, env: dict[str, str]) -> Server:
        server = Server(name, env, log_dir)
        started.append(server)
        return server.start()

    yield start
    for server in started:
        server.stop()


@pytest.fixture
def client(server: Server) -> Iterator[httpx.Client]:
    with server.client() as c:
        yield c


@pytest.fixture
def small_client(small_server: Server) -> Iterator[httpx.Client]:
    with small_server.client() as c:
        yield c


@pytest.fixture
def secured_client(secured_server: Server) -> Iterator[httpx.Client]:
    with secured_server.client() as c:
        yield c
