"""Fixtures of the client tests: a real ``quilting serve`` process for the live tests.

The unit tests in ``test_client.py`` use an in-process fake of the service and need none of
this. The live tests talk to the service the way a user does (see :mod:`live_helpers`); the
server's log is added to the report of a test that fails.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from live_helpers import LiveServer

LOG_TAIL_LINES = 150


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Iterator[None]:
    outcome = yield
    report = outcome.get_result()
    if not report.failed:
        return
    for value in getattr(item, "funcargs", {}).values():
        if isinstance(value, LiveServer):
            tail = "\n".join(value.log().splitlines()[-LOG_TAIL_LINES:])
            report.sections.append((f"server log ({value.url})", tail))


@pytest.fixture(scope="session")
def live_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """A service with default limits and two compute workers, for the whole session."""
    log_path = tmp_path_factory.mktemp("client-live") / "server.log"
    env = {"QUILTING_WORKERS": "2", "QUILTING_DRAIN_GRACE_S": "5"}
    server = LiveServer(env, log_path).start()
    try:
        yield server
    finally:
        server.stop()
