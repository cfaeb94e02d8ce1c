"""SIGTERM drains: readiness and new jobs answer 503 draining at once, the running job finishes
(and its result can be fetched), then the process exits by itself with status 0."""

from __future__ import annotations

import signal
import subprocess
import threading
from collections.abc import Callable

import httpx
from service_helpers import (
    Server,
    assert_png,
    assert_problem,
    job_id_of,
    parse_sse,
    retry_after,
    synth,
    wait_for,
)

#: A drain grace far longer than the job takes, however slow the machine: the job must finish.
DRAIN_GRACE_S = 600
#: Deadlines of the waits below: generous, they only bound a failing test.
WAIT_S = 120
#: The routes that take new jobs.
SUBMISSION_PATHS = (
    "/synthesize",
    "/transfer",
    "/matte",
    "/fill",
    "/extend",
    "/wang-tiles",
    "/extract-alpha",
)


def test_sigterm_drains_then_exits(start_server: Callable[[str, dict[str, str]], Server]) -> None:
    settings = {"QUILTING_WORKERS": "1", "QUILTING_DRAIN_GRACE_S": str(DRAIN_GRACE_S)}
    server = start_server("drain", settings)
    assert server.proc is not None
    with server.client(timeout=WAIT_S) as client:
        job_id = job_id_of(synth(client, {"width": 2048, "height": 2048, "seed": 4}, wait=0))
        wait_for(client, job_id, ("running",))

        # A client following the job's events before the signal keeps its stream to the end.
        events: list[tuple[str, str]] = []
        opened = threading.Event()  # the stream's first line has arrived

        def follow() -> None:
            try:
                with (
                    server.client(timeout=WAIT_S) as other,
                    other.stream("GET", f"/jobs/{job_id}/events") as stream,
                ):
                    lines = []
                    for line in stream.iter_lines():
                        opened.set()
                        lines.append(line)
                    events.extend(parse_sse(lines))
            finally:
                opened.set()

        follower = threading.Thread(target=follow)
        follower.start()
        assert opened.wait(WAIT_S), "the event stream did not open"

        server.signal(signal.SIGTERM)
        assert_problem(client.get("/readyz"), 503, "draining")
        refused = synth(client, {"width": 64, "height": 64}, wait=0)
        assert_problem(refused, 503, "draining")
        retry_after(refused)
        # Every submission route refuses before it reads its form, even an empty one.
        for path in SUBMISSION_PATHS:
            assert_problem(client.post(path, data={"options": "{}"}), 503, "draining")

        # Clients that poll must be able to see the end of the job and fetch its result.
        status = wait_for(client, job_id, timeout=WAIT_S)
        assert status["status"] == "done", status
        assert_png(client.get(f"/jobs/{job_id}/result"), 2048, 2048)

        follower.join(WAIT_S)
        assert [name for name, _ in events][-1:] == ["done"], events

    try:
        code = server.proc.wait(timeout=WAIT_S)
    except subprocess.TimeoutExpired:
        raise AssertionError("the server did not exit after draining") from None
    assert code == 0
    try:
        httpx.get(server.url + "/healthz", timeout=1)
    except httpx.TransportError:
        pass
    else:
        raise AssertionError("the server still answers after exiting")
