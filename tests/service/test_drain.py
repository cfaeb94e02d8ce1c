"""SIGTERM drains: readiness and new jobs answer 503 draining at once, the running job finishes
(and its result can be fetched), then the process exits by itself with status 0."""

from __future__ import annotations

import signal
import subprocess
import threading
import time
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


def test_sigterm_drains_then_exits(start_server: Callable[[str, dict[str, str]], Server]) -> None:
    server = start_server("drain", {"QUILTING_WORKERS": "1", "QUILTING_DRAIN_GRACE_S": "30"})
    assert server.proc is not None
    with server.client(timeout=30) as client:
        job_id = job_id_of(synth(client, {"width": 2048, "height": 2048, "seed": 4}, wait=0))
        wait_for(client, job_id, ("running",))

        # A client following the job's events before the signal keeps its stream to the end.
        events: list[tuple[str, str]] = []

        def follow() -> None:
            with (
                server.client(timeout=30) as other,
                other.stream("GET", f"/jobs/{job_id}/events") as stream,
            ):
                events.extend(parse_sse(list(stream.iter_lines())))

        follower = threading.Thread(target=follow)
        follower.start()
        time.sleep(0.1)

        server.signal(signal.SIGTERM)
        assert_problem(client.get("/readyz"), 503, "draining")
        refused = synth(client, {"width": 64, "height": 64}, wait=0)
        assert_problem(refused, 503, "draining")
        retry_after(refused)

        # Clients that poll must be able to see the end of the job and fetch its result.
        status = wait_for(client, job_id, timeout=30)
        assert status["status"] == "done", status
        assert_png(client.get(f"/jobs/{job_id}/result"), 2048, 2048)

        follower.join(30)
        assert [name for name, _ in events][-1:] == ["done"], events

    try:
        code = server.proc.wait(timeout=15)
    except subprocess.TimeoutExpired:
        raise AssertionError("the server did not exit after draining") from None
    assert code == 0
    try:
        httpx.get(server.url + "/healthz", timeout=1)
    except httpx.TransportError:
        pass
    else:
        raise AssertionError("the server still answers after exiting")
