"""Worker processes: a crashed worker fails only its job and is replaced; thread mode works."""

from __future__ import annotations

import os
import signal
from collections.abc import Callable
from pathlib import Path

from service_helpers import Server, job_id_of, synth, wait_for


def _children(pid: int) -> list[int]:
    """Live worker processes of the server ``pid`` (not multiprocessing's resource tracker)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmdline = (entry / "cmdline").read_bytes()
        except OSError:
            continue
        # State and parent pid are the first two fields after the parenthesised command name.
        state, parent = stat.rsplit(")", 1)[1].split()[:2]
        if int(parent) == pid and state != "Z" and b"spawn_main" in cmdline:
            found.append(int(entry.name))
    return found


def test_a_killed_worker_fails_its_job_and_is_replaced(
    start_server: Callable[[str, dict[str, str]], Server],
) -> None:
    server = start_server("crash", {"QUILTING_WORKERS": "1"})
    assert server.proc is not None
    with server.client() as client:
        job = job_id_of(synth(client, {"width": 3000, "height": 3000}, wait=0))
        wait_for(client, job, ("running",))
        workers = _children(server.proc.pid)
        assert workers, "no worker process found"
        for pid in workers:
            os.kill(pid, signal.SIGKILL)
        status = wait_for(client, job)
        assert status["status"] == "failed"
        assert status["error"]["code"] == "internal_error"
        assert "worker process died" in status["error"]["detail"]
        # The service goes on with a new worker.
        again = synth(client, {"width": 200, "height": 100, "seed": 1})
        assert again.status_code == 200 and again.headers["content-type"] == "image/png"
        assert set(_children(server.proc.pid)).isdisjoint(workers)


def test_thread_mode_runs_jobs(start_server: Callable[[str, dict[str, str]], Server]) -> None:
    server = start_server(
        "threads",
        {
            "QUILTING_WORKER_MODE": "thread",
            "QUILTING_WORKERS": "2",
            "QUILTING_SANDBOX_WORKERS": "1",
        },
    )
    assert server.proc is not None
    with server.client() as client:
        response = synth(client, {"width": 300, "height": 200, "seed": 4})
        assert response.status_code == 200
        # No worker processes in thread mode: the one child is the sandbox's (which checked
        # the upload).
        assert len(_children(server.proc.pid)) == 1
        job = job_id_of(synth(client, {"width": 3000, "height": 3000}, wait=0))
        wait_for(client, job, ("running",))
        assert client.delete(f"/jobs/{job}").status_code == 202
        assert wait_for(client, job)["status"] == "cancelled"


def test_results_over_the_byte_cap_are_evicted_oldest_first(
    start_server: Callable[[str, dict[str, str]], Server],
) -> None:
    # Each 512x512 gravel result is ~190 kB of PNG + layout: a 300 kB cap keeps only the newest.
    server = start_server("bytes", {"QUILTING_RESULTS_MAX_BYTES": "300000"})
    with server.client() as client:
        first = job_id_of(synth(client, {"width": 512, "height": 512, "seed": 1}))
        assert client.get(f"/jobs/{first}/result").status_code == 200
        second = job_id_of(synth(client, {"width": 512, "height": 512, "seed": 2}))
        gone = client.get(f"/jobs/{first}/result")
        assert gone.status_code == 410 and gone.json()["code"] == "result_expired"
        assert client.get(f"/jobs/{first}").json()["expired"] is True
        assert client.get(f"/jobs/{second}/result").status_code == 200
        metrics = client.get("/metrics").text
        kept = next(
            line for line in metrics.splitlines() if line.startswith("quilting_results_bytes")
        )
        assert 0 < float(kept.split()[1]) <= 300000
