"""Hostile and careless clients against a real ``quilting serve``: what must never be a 500, a
hang or a leak.

Deeply nested or huge options JSON, repeated single-file parts, methods a route does not take,
uploads that stall half-way, cancelled queued jobs that would hold their queue slot,
Idempotency-Keys that would be kept for ever, a drain that runs past its grace, a frozen Redis;
and the headers every answer carries (nosniff, Cache-Control) and who may read /metrics.
"""

from __future__ import annotations

import signal
import socket
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import pytest
from cluster import RedisServer, need_redis
from service_helpers import (
    Server,
    assert_png,
    assert_problem,
    job_id_of,
    synth,
    texture,
    wait_expired,
    wait_for,
)

from quilting.service.jobs import Job, JobInput, Status, new_job_id
from quilting.service.jobs.memory import Store
from quilting.service.jobs.pool import Runner
from quilting.service.settings import Settings

SMALL = {"width": 64, "height": 64, "block": 16}
#: Seconds of work on this machine, whatever its speed: a job still running when a test acts.
LONG = {"width": 4096, "height": 4096}
#: Deadlines of the waits below: generous, they only bound a failing test.
WAIT_S = 60
KEY = {"X-API-Key": "k1"}


# --- options JSON ---------------------------------------------------------------------------


def test_options_nested_too_deep_is_422(client: httpx.Client) -> None:
    for options in (
        "[" * 100_000 + "]" * 100_000,
        '{"width": 64, "height": 64, "exclude_colors": ' + "[" * 1000 + "]" * 1000 + "}",
    ):
        body = assert_problem(synth(client, options), 422, "invalid_options", field="options")
        assert "32" in body["detail"], body
    # Brackets inside strings are not nesting: this is an ordinary bad-value answer.
    assert_problem(synth(client, {**SMALL, "backend": "[" * 100}), 422, "invalid_parameter")


def test_options_too_large_is_422(client: httpx.Client) -> None:
    options = '{"width": 64, "height": 64, "backend": "' + "x" * 70_000 + '"}'
    body = assert_problem(synth(client, options), 422, "invalid_options", field="options")
    assert "65536" in body["detail"], body


# --- repeated parts -------------------------------------------------------------------------


def test_a_repeated_single_file_part_is_422(client: httpx.Client) -> None:
    gravel, brick = texture("gravel"), texture("brick")
    files = [
        ("texture", ("a.png", gravel, "image/png")),
        ("texture", ("b.png", brick, "image/png")),
    ]
    # A transfer takes one texture (a synthesis several examples: test_examples_api.py).
    target = [("target", ("t.png", brick, "image/png"))]
    response = client.post("/transfer", files=[*files, *target], data={"options": "{}"})
    body = assert_problem(response, 422, "duplicate_part", field="texture")
    assert "texture" in body["detail"]
    response = client.post(
        "/synthesize",
        files=[*files[:1], *target, *target],
        data={"options": '{"width":64,"height":64}'},
    )
    assert_problem(response, 422, "duplicate_part", field="target")
    options = [("options", '{"width":64,"height":64}'), ("options", '{"width":96,"height":96}')]
    response = client.post("/synthesize", files=[*files[:1], *options])
    assert_problem(response, 422, "duplicate_part", field="options")
    # Companions repeat (one part per map).
    companions = [("companion", (f"{n}.png", gravel, "image/png")) for n in ("normal", "height")]
    response = client.post(
        "/synthesize",
        params={"wait": 30},
        files=[files[0], *companions],
        data={"options": '{"width":64,"height":64,"block":16}'},
    )
    assert_png(response, 64, 64)


# --- 405 ------------------------------------------------------------------------------------


def test_405_names_the_allowed_methods(client: httpx.Client) -> None:
    response = client.put("/jobs/0123")
    assert_problem(response, 405, "method_not_allowed")
    assert set(response.headers["Allow"].split(", ")) == {"DELETE", "GET"}
    response = client.get("/synthesize")
    assert_problem(response, 405, "method_not_allowed")
    assert response.headers["Allow"] == "POST"


# --- headers --------------------------------------------------------------------------------


def test_every_answer_says_nosniff_and_how_to_cache(client: httpx.Client) -> None:
    done = synth(client, {**SMALL, "seed": 3})
    job_id = job_id_of(done)
    answers = {
        "submission": done,
        "status": client.get(f"/jobs/{job_id}"),
        "problem": client.get("/jobs/no-such-job"),
        "metrics": client.get("/metrics"),
        "readiness": client.get("/readyz"),
    }
    for name, response in answers.items():
        assert response.headers.get("X-Content-Type-Options") == "nosniff", name
        assert response.headers.get("Cache-Control") == "no-store", (name, response.headers)
    result = client.get(f"/jobs/{job_id}/result")
    assert_png(result, 64, 64)
    for kept in (result, client.get(f"/jobs/{job_id}/layout"), client.get(f"/jobs/{job_id}/seams")):
        assert kept.status_code == 200, kept.text
        assert kept.headers["X-Content-Type-Options"] == "nosniff"
        assert kept.headers["Cache-Control"].startswith("private, max-age="), kept.url
    # A problem under a file's URL is not kept.
    missing = client.get(f"/jobs/{job_id}/result/no_such_companion")
    assert missing.status_code == 404 and missing.headers["Cache-Control"] == "no-store"
    with client.stream("GET", f"/jobs/{job_id}/events") as stream:
        assert stream.headers["Cache-Control"] == "no-cache"
        assert stream.headers["X-Content-Type-Options"] == "nosniff"
    page = client.get("/")
    assert page.headers["Cache-Control"] == "no-cache"
    assert "default-src" in page.headers["Content-Security-Policy"]
    assert page.headers["X-Content-Type-Options"] == "nosniff"


# --- /metrics and API keys ------------------------------------------------------------------


def test_metrics_need_a_key_when_the_service_has_keys(
    secured_client: httpx.Client, start_server: Callable[[str, dict[str, str]], Server]
) -> None:
    assert_problem(secured_client.get("/metrics"), 401, "unauthorized")
    response = secured_client.get("/metrics", headers=KEY)
    assert response.status_code == 200
    assert "quilting_queue_depth" in response.text
    public = start_server(
        "metrics-public",
        {"QUILTING_WORKERS": "1", "QUILTING_API_KEYS": "k1", "QUILTING_METRICS_PUBLIC": "true"},
    )
    with public.client() as other:
        assert other.get("/metrics").status_code == 200
        assert_problem(other.get("/jobs/x"), 401, "unauthorized")  # the jobs stay private


# --- cancelled queued jobs ------------------------------------------------------------------


def test_a_cancelled_queued_job_frees_its_queue_slot(
    start_server: Callable[[str, dict[str, str]], Server],
) -> None:
    server = start_server("slots", {"QUILTING_WORKERS": "1", "QUILTING_MAX_QUEUED": "1"})
    with server.client() as client:
        running = job_id_of(synth(client, {**LONG, "seed": 1}, wait=0))
        wait_for(client, running, ("running",), timeout=WAIT_S)
        queued = job_id_of(synth(client, {**SMALL, "seed": 2}, wait=0))
        assert_problem(synth(client, {**SMALL, "seed": 3}, wait=0), 503, "queue_full")
        assert client.delete(f"/jobs/{queued}").json()["status"] == "cancelled"
        again = job_id_of(synth(client, {**SMALL, "seed": 3}, wait=0))
        for job_id in (again, running):
            client.delete(f"/jobs/{job_id}")
        assert wait_for(client, running, timeout=WAIT_S)["status"] == "cancelled"


# --- Idempotency-Key entries ----------------------------------------------------------------


def test_an_idempotency_key_is_free_again_once_its_result_expired(
    secured_client: httpx.Client,
) -> None:
    headers = {**KEY, "Idempotency-Key": f"expiring-{time.monotonic_ns()}"}
    first = job_id_of(synth(secured_client, {**SMALL, "seed": 7}, headers=headers))
    wait_expired(secured_client, first, headers=KEY, timeout=WAIT_S)
    # Another body under the same key: a new job, not 409 (the first one's result is gone).
    second = synth(secured_client, {**SMALL, "seed": 8}, headers=headers)
    assert job_id_of(second) != first


def _job(store: Store) -> Job:
    return Job(id=new_job_id(), owner=None, width=8, height=8, companion_names=[], input=None)


def test_the_idempotency_map_does_not_outgrow_the_jobs() -> None:
    store = Store(Settings(results_max_count=2, max_queued=4, results_ttl_s=5.0))
    for n in range(200):
        job = _job(store)
        store.add(job, (f"key-{n}", "digest"))
        assert store.start(job)
        store.finish(job, Status.DONE, png=b"x" * 10)
    assert len(store.jobs) <= 10 * 2 + 4
    # Only jobs whose results are still kept hold their key.
    assert len(store.idempotency) == len(store.kept) == 2
    assert {job_id for _, job_id in store.idempotency.values()} == set(store.kept)
    store.expire(now=time.time() + 10)
    assert store.idempotency == {}


# --- drain past its grace -------------------------------------------------------------------


def test_jobs_left_after_the_drain_grace_fail_with_shutdown() -> None:
    """The runner itself: queued jobs and the one running past the grace fail ``shutdown``,
    and no worker process is started again."""
    import multiprocessing

    store = Store(Settings(workers=1, max_queued=8))
    runner = Runner(store, store.settings)
    runner.start()
    gravel = texture("gravel")
    jobs = []
    for seed in range(3):
        job = _job(store)
        job.input = JobInput(gravel, {}, {"seed": seed}, 4096, 4096)
        store.add(job)
        runner.submit(job)
        jobs.append(job)
    deadline = time.monotonic() + WAIT_S
    while jobs[0].status is not Status.RUNNING or jobs[0].progress == 0:
        assert time.monotonic() < deadline, jobs[0].snapshot()
        time.sleep(0.02)
    runner.stop(timeout=0.5)
    for job in jobs:
        assert job.status is Status.FAILED, job.snapshot()
        assert job.error is not None and job.error["code"] == "shutdown", job.error
    assert store.queued == 0 and store.running == 0
    assert multiprocessing.active_children() == []


def test_a_drain_past_its_grace_fails_the_rest_and_exits_cleanly(
    start_server: Callable[[str, dict[str, str]], Server],
) -> None:
    server = start_server("grace", {"QUILTING_WORKERS": "1", "QUILTING_DRAIN_GRACE_S": "1"})
    assert server.proc is not None
    with server.client() as client:
        running = job_id_of(synth(client, {**LONG, "seed": 1}, wait=0))
        wait_for(client, running, ("running",), timeout=WAIT_S)
        queued = [job_id_of(synth(client, {**LONG, "seed": s}, wait=0)) for s in (2, 3, 4)]
        for job_id in queued:
            assert client.get(f"/jobs/{job_id}").json()["status"] == "queued"
    server.signal(signal.SIGTERM)
    try:
        code = server.proc.wait(timeout=WAIT_S)
    except subprocess.TimeoutExpired:
        raise AssertionError(f"the server did not exit:\n{server.log()}") from None
    log = server.log()
    assert code == 0, log
    for word in ("Traceback", "EOFError", "BrokenPipe", "died during job"):
        assert word not in log, log
    for job_id in queued:
        assert f"job {job_id} failed: the service shut down" in log, log


# --- stalled uploads ------------------------------------------------------------------------


def _assert_dropped(sock: socket.socket, timeout_s: float, held: str) -> None:
    """The server closes ``sock`` (EOF or a reset) within its request timeout and 10 s; the
    socket's own 30 s timeout reads as ``held``."""
    started = time.monotonic()
    try:
        assert sock.recv(65536) == b""
    except TimeoutError:
        raise AssertionError(held) from None
    except ConnectionResetError:
        pass
    assert time.monotonic() - started < timeout_s + 10


def test_a_stalled_upload_is_dropped_after_the_request_timeout(
    start_server: Callable[[str, dict[str, str]], Server],
) -> None:
    timeout_s = 1.5
    server = start_server(
        "stall", {"QUILTING_WORKERS": "1", "QUILTING_REQUEST_TIMEOUT_S": str(timeout_s)}
    )
    head = (
        "POST /synthesize HTTP/1.1\r\n"
        f"Host: 127.0.0.1:{server.port}\r\n"
        "Content-Type: multipart/form-data; boundary=xyz\r\n"
        "Content-Length: 100000\r\n\r\n"
    ).encode()
    part = b'--xyz\r\nContent-Disposition: form-data; name="texture"; filename="t.png"\r\n\r\n'
    with socket.create_connection(("127.0.0.1", server.port), timeout=30) as sock:
        sock.sendall(head + part + b"\x89PNG" + b"\0" * 1000)  # then nothing more
        started = time.monotonic()
        # The service answers others meanwhile.
        assert httpx.get(server.url + "/healthz", timeout=5).status_code == 200
        answer = b""
        try:
            while chunk := sock.recv(65536):
                answer += chunk
        except TimeoutError:
            raise AssertionError("the stalled upload was still held open after 30 s") from None
        except ConnectionResetError:
            pass
        elapsed = time.monotonic() - started
    assert elapsed < timeout_s + 10, elapsed
    assert answer == b"" or answer.startswith(b"HTTP/1.1 408"), answer[:200]
    if answer:
        assert b"request_timeout" in answer and b"application/problem+json" in answer
    assert "Traceback" not in server.log(), server.log()

    # Headers that never end: the connection is closed too.
    with socket.create_connection(("127.0.0.1", server.port), timeout=30) as sock:
        sock.sendall(b"POST /synthesize HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-")
        _assert_dropped(sock, timeout_s, "half-sent headers were still held open after 30 s")


def test_a_kept_alive_connection_that_stalls_in_its_next_headers_is_closed(
    start_server: Callable[[str, dict[str, str]], Server],
) -> None:
    """The header timer is armed again after each answer: a client that got one answer on a
    kept-alive connection, then sends half of its next request's headers, is dropped too."""
    timeout_s = 1.5
    server = start_server(
        "keepalive", {"QUILTING_WORKERS": "1", "QUILTING_REQUEST_TIMEOUT_S": str(timeout_s)}
    )
    with socket.create_connection(("127.0.0.1", server.port), timeout=30) as sock:
        sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
        answer = b""
        while not answer.endswith(b'{"status":"ok"}'):
            chunk = sock.recv(65536)
            assert chunk, answer
            answer += chunk
        assert answer.startswith(b"HTTP/1.1 200")
        # The next request on the same connection: half its headers, then nothing.
        sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Half")
        _assert_dropped(sock, timeout_s, "the stalled second request was still held after 30 s")

    # A request that has begun is not cut by the timer its connection armed before it (the
    # synthesis takes seconds here; the timer would have fired during it).
    with server.client() as client:
        assert client.get("/healthz").status_code == 200
        assert_png(synth(client, {"width": 1024, "height": 1024, "seed": 1}, wait=60), 1024, 1024)
        assert client.get("/healthz").status_code == 200


# --- Redis ----------------------------------------------------------------------------------


@pytest.fixture
def redis_server(tmp_path: Path) -> Iterator[RedisServer]:
    need_redis()
    server = RedisServer(tmp_path).start()
    try:
        yield server
    finally:
        if server.proc is not None and server.proc.poll() is None:
            server.proc.send_signal(signal.SIGCONT)
        server.stop()


def test_redis_frozen_answers_503_quickly_then_recovers(
    redis_server: RedisServer, start_server: Callable[[str, dict[str, str]], Server]
) -> None:
    env = {"QUILTING_QUEUE": redis_server.url, "QUILTING_MAX_QUEUED": "1"}
    api = start_server("redis-api", env)
    assert redis_server.proc is not None
    with api.client() as client:
        # No worker: jobs stay queued. A cancelled queued job frees its slot here too.
        first = job_id_of(synth(client, {**SMALL, "seed": 1}, wait=0))
        assert_problem(synth(client, {**SMALL, "seed": 2}, wait=0), 503, "queue_full")
        client.delete(f"/jobs/{first}")
        job_id = job_id_of(synth(client, {**SMALL, "seed": 2}, wait=0))

        redis_server.proc.send_signal(signal.SIGSTOP)
        try:
            healthy: list[int] = []
            probe = threading.Thread(
                target=lambda: healthy.append(httpx.get(api.url + "/healthz").status_code)
            )
            started = time.monotonic()
            probe.start()
            response = client.get(f"/jobs/{job_id}")
            elapsed = time.monotonic() - started
            probe.join(WAIT_S)
            assert_problem(response, 503, "queue_unavailable")
            assert elapsed < 5.0, f"a frozen Redis held the request {elapsed:.1f} s"
            assert healthy == [200]
        finally:
            redis_server.proc.send_signal(signal.SIGCONT)
        deadline = time.monotonic() + WAIT_S
        while (response := client.get(f"/jobs/{job_id}")).status_code != 200:
            assert time.monotonic() < deadline, response.text
            time.sleep(0.1)
        assert response.json()["status"] == "queued"
