"""The distributed queue for real: redis-server, several ``quilting serve`` replicas with
``QUILTING_QUEUE=redis://...`` and several ``quilting worker`` processes.

Jobs submitted to any replica finish exactly once with the engine's own images; a worker killed
with SIGKILL mid-job loses nothing (another worker finishes the job); while Redis is down
requests get 503 ``queue_unavailable`` and everything works again once it is back; cancel,
progress, idempotency and the result caps hold across processes.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import json
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cluster import RedisServer, WorkerProcess, need_redis
from service_helpers import (
    DATA,
    FINAL,
    Server,
    assert_png,
    assert_problem,
    assert_status_document,
    job_id_of,
    metric_values,
    parse_sse,
    synth,
    transfer,
    wait_expired,
    wait_for,
    wait_idle,
)

import quilting
from quilting.io import encode_png, read_image
from quilting.service.jobs import Job, JobInput
from quilting.service.jobs.redis_store import RedisJobs
from quilting.service.settings import Settings

#: Short, so that a killed worker's job is taken again within seconds.
HEARTBEAT_S = "3"
#: The module's shared cluster, where no worker dies: long, so that a worker starved of CPU for
#: a few seconds on a busy machine is never taken for dead (its job would run a second time).
SHARED_HEARTBEAT_S = "30"
SMALL = {"width": 96, "height": 96, "block": 24}
#: A job that runs for seconds on this machine: time to kill or cancel it mid-way.
LONG = {"width": 1536, "height": 1536, "block": 24}
#: Long enough to fetch a result right after its job, short enough to wait for its expiry.
RESULTS_TTL_S = 3
#: A drain grace no job of these tests comes near, however slow the machine.
DRAIN_GRACE_S = 600


@dataclass
class Cluster:
    """Redis, API replicas and workers started for a test (or a module)."""

    redis: RedisServer
    log_dir: Path
    apis: list[Server] = field(default_factory=list)
    workers: list[WorkerProcess] = field(default_factory=list)
    heartbeat_s: str = HEARTBEAT_S

    def env(self, **extra: str) -> dict[str, str]:
        return {
            "QUILTING_QUEUE": self.redis.url,
            "QUILTING_HEARTBEAT_TIMEOUT_S": self.heartbeat_s,
            "QUILTING_DRAIN_GRACE_S": "5",
            **extra,
        }

    def api(self, **extra: str) -> Server:
        server = Server(f"api{len(self.apis)}", self.env(**extra), self.log_dir).start()
        self.apis.append(server)
        return server

    def worker(self, **extra: str) -> WorkerProcess:
        worker = WorkerProcess(f"w{len(self.workers)}", self.env(**extra), self.log_dir)
        self.workers.append(worker.start())
        return worker

    def wait_workers(self, count: int, timeout: float = 30.0) -> None:
        """Until the first replica sees ``count`` live workers."""
        with self.apis[0].client() as client:
            deadline = time.monotonic() + timeout
            while True:
                response = client.get("/readyz")
                if response.status_code == 200 and response.json()["workers"] == count:
                    return
                assert time.monotonic() < deadline, response.text
                time.sleep(0.1)

    def attempts(self) -> list[tuple[str, int, str]]:
        """``(job id, attempt, worker name)`` of every job start in every worker's log."""
        return [(job, n, w.name) for w in self.workers for job, n in w.attempts()]

    def logs(self) -> str:
        parts = [f"--- {w.name}\n{w.log()[-3000:]}" for w in self.workers]
        parts += [f"--- {a.name}\n{a.log()[-3000:]}" for a in self.apis]
        return "\n".join([*parts, f"--- redis\n{self.redis.log()}"])

    def stop(self) -> None:
        for process in [*self.workers, *self.apis]:
            process.stop()
        self.redis.stop()


def make_cluster(folder: Path, log_dir: Path, heartbeat_s: str = HEARTBEAT_S) -> Cluster:
    need_redis()
    return Cluster(RedisServer(folder).start(), log_dir, heartbeat_s=heartbeat_s)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory, log_dir: Path) -> Iterator[Cluster]:
    """Two API replicas and two workers on one Redis, shared by the module's tests."""
    group = make_cluster(tmp_path_factory.mktemp("redis"), log_dir, SHARED_HEARTBEAT_S)
    try:
        group.api()
        group.api()
        group.worker()
        group.worker()
        group.wait_workers(2)
        yield group
    finally:
        group.stop()


@pytest.fixture
def own_cluster(tmp_path: Path, log_dir: Path) -> Iterator[Cluster]:
    """An empty cluster (Redis only) for one test; it starts the processes it needs."""
    group = make_cluster(tmp_path, log_dir)
    try:
        yield group
    finally:
        group.stop()


def engine_image(seed: int, options: dict[str, Any], tex: str = "gravel") -> np.ndarray:
    """What ``quilting.synthesize`` makes in this process for the same request."""
    texture = read_image(DATA / f"{tex}.png")
    size = (options["height"], options["width"])
    rest = {k: v for k, v in options.items() if k not in ("width", "height", "seed")}
    return quilting.synthesize(texture, size, seed=seed, **rest).image


def finished(metrics: str) -> dict[str, float]:
    values = metric_values(metrics)
    return {
        status: values.get(f'quilting_jobs_finished_total{{status="{status}"}}', 0.0)
        for status in FINAL
    }


def test_forty_jobs_across_two_replicas_finish_exactly_once(cluster: Cluster) -> None:
    a, b = cluster.apis
    with a.client() as ca, b.client() as cb:
        before = finished(ca.get("/metrics").text)
        pixels_before = metric_values(ca.get("/metrics").text)["quilting_pixels_produced_total"]

        def submit(seed: int) -> tuple[int, str]:
            client = ca if seed % 2 else cb
            response = synth(client, {**SMALL, "seed": seed}, wait=0)
            assert response.status_code == 202, response.text
            return seed, job_id_of(response)

        with concurrent.futures.ThreadPoolExecutor(8) as pool:
            jobs = dict(pool.map(submit, range(40)))
        assert len(set(jobs.values())) == 40
        for seed, job_id in jobs.items():
            # Read from the replica that did not take the job: any replica answers.
            reader = cb if seed % 2 else ca
            status = wait_for(reader, job_id, timeout=120)
            assert status["status"] == "done", (status, cluster.logs())
            assert_status_document(status)
            png = reader.get(f"/jobs/{job_id}/result")
            assert_png(png, 96, 96)
            np.testing.assert_array_equal(read_image(png.content), engine_image(seed, SMALL))
        after_a = finished(ca.get("/metrics").text)
        after_b = finished(cb.get("/metrics").text)
        pixels = metric_values(cb.get("/metrics").text)["quilting_pixels_produced_total"]
    assert pixels - pixels_before == 40 * 96 * 96
    # Counters live in Redis: both replicas see the same 40 jobs done, none failed.
    assert after_a == after_b
    assert after_a["done"] - before["done"] == 40
    assert after_a["failed"] == before["failed"]
    starts = [(job, n) for job, n, _ in cluster.attempts() if job in set(jobs.values())]
    assert sorted(job for job, _ in starts) == sorted(jobs.values()), cluster.logs()
    assert all(n == 1 for _, n in starts)
    # Both workers took jobs: the queue spreads them.
    assert len({w for job, _, w in cluster.attempts() if job in set(jobs.values())}) == 2


def test_transfer_with_companion_layout_and_seams_from_another_replica(
    cluster: Cluster,
) -> None:
    a, b = cluster.apis
    # A companion map of the texture's size: the gravel inverted.
    inverted = 255 - read_image(DATA / "gravel.png")
    companion = encode_png(inverted)
    options = {"seed": 5, "block": 24}
    with a.client() as ca, b.client() as cb:
        response = transfer(ca, options, tex="gravel", target="hubble", wait=0,
                            companions={"height.png": companion})  # fmt: skip
        job_id = job_id_of(response)
        status = wait_for(cb, job_id, timeout=120)
        assert status["status"] == "done", status
        assert status["companions"] == ["height"]
        assert status["layout"] == f"/jobs/{job_id}/layout"
        result = cb.get(f"/jobs/{job_id}/result")
        width, height = status["width"], status["height"]
        assert_png(result, width, height)
        assert_png(cb.get(f"/jobs/{job_id}/result/height"), width, height)
        layout = quilting.Layout.from_json(cb.get(f"/jobs/{job_id}/layout").content)
        # The companion is the map quilted with the result's layout, pixel for pixel.
        expected = quilting.apply_layout(layout, inverted)
        got = read_image(cb.get(f"/jobs/{job_id}/result/height").content)
        np.testing.assert_array_equal(got, expected)
        assert_png(ca.get(f"/jobs/{job_id}/seams"), width, height)
        assert_problem(ca.get(f"/jobs/{job_id}/result/nope"), 404, "companion_not_found")


def test_companion_kinds_travel_through_the_redis_queue(cluster: Cluster) -> None:
    """A 'hard' mask submitted to one replica, run by a Redis worker, read from the other,
    keeps only the mask's values; the same mask blended (the default) does not."""
    from service_helpers import synth_request

    a, b = cluster.apis
    gravel = read_image(DATA / "gravel.png")
    gray = gravel[..., :3].mean(axis=2) if gravel.ndim == 3 else gravel
    mask = encode_png(np.where(gray > np.median(gray), 255, 0).astype(np.uint8))
    values = {}
    with a.client() as ca, b.client() as cb:
        for kind in ("hard", "blend"):
            request = synth_request(
                {"width": 160, "height": 120, "seed": 2}, companions={"mask.png": mask}
            )
            request["data"]["companion_kinds"] = json.dumps({"mask": kind})
            job_id = job_id_of(ca.post("/synthesize", params={"wait": 0}, **request))
            status = wait_for(cb, job_id, timeout=120)
            assert status["status"] == "done", status
            got = read_image(cb.get(f"/jobs/{job_id}/result/mask").content)
            values[kind] = set(np.unique(got).tolist())
    assert values["hard"] <= {0, 255}
    assert not values["blend"] <= {0, 255}


def test_progress_events_from_another_replica(cluster: Cluster) -> None:
    a, b = cluster.apis
    with a.client() as ca, b.client() as cb:
        job_id = job_id_of(synth(ca, {**LONG, "width": 768, "height": 768, "seed": 2}, wait=0))
        with cb.stream("GET", f"/jobs/{job_id}/events", timeout=120) as stream:
            assert stream.status_code == 200
            events = parse_sse(list(stream.iter_lines()))
    kinds = [kind for kind, _ in events]
    assert kinds[-1] == "done", events
    progress = [json.loads(data)["progress"] for kind, data in events if kind == "progress"]
    assert len(progress) >= 2, events  # progress written by the worker, read by replica b
    assert progress == sorted(progress)
    assert json.loads(events[-1][1])["status"] == "done"


def test_cancel_across_processes(cluster: Cluster) -> None:
    a, b = cluster.apis
    with a.client() as ca, b.client() as cb:
        wait_idle(ca, timeout=120)
        # Two long jobs keep both workers busy; the third waits in the queue.
        running = [job_id_of(synth(ca, {**LONG, "seed": s}, wait=0)) for s in (11, 12)]
        for job_id in running:
            wait_for(cb, job_id, ("running",), timeout=60)
        queued = job_id_of(synth(ca, {**LONG, "seed": 13}, wait=0))
        assert cb.get(f"/jobs/{queued}").json()["status"] == "queued"
        # A queued job cancelled through the other replica is final at once.
        response = cb.delete(f"/jobs/{queued}")
        assert response.status_code == 202
        assert response.json()["status"] == "cancelled"
        # A running job stops at its worker's next progress report.
        for job_id in running:
            assert cb.delete(f"/jobs/{job_id}").status_code == 202
        for job_id in [*running, queued]:
            status = wait_for(ca, job_id, timeout=60)
            assert status["status"] == "cancelled", status
            assert_problem(ca.get(f"/jobs/{job_id}/result"), 409, "job_cancelled")
        # The cancelled queued job never reached a worker; the workers take new jobs.
        assert queued not in {job for job, _, _ in cluster.attempts()}
        after = synth(cb, {**SMALL, "seed": 99}, wait=60)
        assert_png(after, 96, 96)


def test_idempotency_key_across_replicas(cluster: Cluster) -> None:
    a, b = cluster.apis
    key = {"Idempotency-Key": f"farm-{time.time_ns()}"}
    with a.client() as ca, b.client() as cb:
        first = synth(ca, {**SMALL, "seed": 21}, wait=0, headers=key)
        again = synth(cb, {**SMALL, "seed": 21}, wait=0, headers=key)
        assert job_id_of(first) == job_id_of(again)
        other = synth(cb, {**SMALL, "seed": 22}, wait=0, headers=key)
        assert_problem(other, 409, "idempotency_conflict")
        assert wait_for(ca, job_id_of(first), timeout=60)["status"] == "done"
    assert [job for job, _, _ in cluster.attempts()].count(job_id_of(first)) == 1


def test_python_client_works_against_the_redis_queue(cluster: Cluster) -> None:
    quilting_client = pytest.importorskip("quilting_client")
    texture = (DATA / "gravel.png").read_bytes()
    with quilting_client.Client(cluster.apis[1].url) as client:
        png = client.synthesize(texture, width=96, height=96, block=24, seed=8)
    np.testing.assert_array_equal(read_image(png), engine_image(8, SMALL))


def test_worker_killed_mid_job_is_finished_by_the_other(own_cluster: Cluster) -> None:
    api = own_cluster.api()
    first = own_cluster.worker()
    second = own_cluster.worker()
    own_cluster.wait_workers(2)
    options = {**LONG, "seed": 31}
    with api.client() as client:
        job_id = job_id_of(synth(client, options, wait=0))
        wait_for(client, job_id, ("running",), timeout=60)
        # Let it get under way, then kill whichever worker runs it.
        deadline = time.monotonic() + 30
        while client.get(f"/jobs/{job_id}").json()["progress"] < 0.05:
            assert time.monotonic() < deadline
            time.sleep(0.05)
        runner = next(w for w in (first, second) if (job_id, 1) in w.attempts())
        other = second if runner is first else first
        runner.kill()
        # Meanwhile more jobs arrive: none may be lost either.
        more = [job_id_of(synth(client, {**SMALL, "seed": s}, wait=0)) for s in (41, 42, 43)]
        status = wait_for(client, job_id, timeout=120)
        assert status["status"] == "done", (status, own_cluster.logs())
        png = client.get(f"/jobs/{job_id}/result")
        assert_png(png, LONG["width"], LONG["height"])
        np.testing.assert_array_equal(read_image(png.content), engine_image(31, options))
        for seed, other_id in zip((41, 42, 43), more, strict=True):
            assert wait_for(client, other_id, timeout=120)["status"] == "done"
            got = read_image(client.get(f"/jobs/{other_id}/result").content)
            np.testing.assert_array_equal(got, engine_image(seed, SMALL))
        counts = finished(client.get("/metrics").text)
    # The killed worker's attempt never finished; the other worker's second attempt did.
    assert (job_id, 2) in other.attempts(), own_cluster.logs()
    assert counts == {"done": 4.0, "failed": 0.0, "cancelled": 0.0}


def test_redis_down_gives_503_and_the_service_recovers(own_cluster: Cluster) -> None:
    api = own_cluster.api()
    own_cluster.worker()
    own_cluster.wait_workers(1)
    with api.client() as client:
        done = job_id_of(synth(client, {**SMALL, "seed": 51}, wait=60))
        own_cluster.redis.stop()
        for response in (
            synth(client, {**SMALL, "seed": 52}, wait=0),
            client.get(f"/jobs/{done}"),
            client.get("/readyz"),
        ):
            body = assert_problem(response, 503, "queue_unavailable")
            assert "Redis" in body["detail"]
            assert int(response.headers["Retry-After"]) > 0
        assert client.get("/healthz").status_code == 200  # the process itself is alive
        own_cluster.redis.start()
        # The API reconnects; the worker reconnects and takes new jobs; the old job is kept.
        deadline = time.monotonic() + 30
        while client.get("/readyz").status_code != 200:
            assert time.monotonic() < deadline, own_cluster.logs()
            time.sleep(0.2)
        assert client.get(f"/jobs/{done}").json()["status"] == "done"
        assert_png(client.get(f"/jobs/{done}/result"), 96, 96)
        response = synth(client, {**SMALL, "seed": 53}, wait=60)
        assert_png(response, 96, 96)
        np.testing.assert_array_equal(read_image(response.content), engine_image(53, SMALL))


def test_caps_hold_across_processes(own_cluster: Cluster) -> None:
    # No worker yet: jobs stay queued and the queue cap is shared by both replicas.
    a = own_cluster.api(QUILTING_MAX_QUEUED="2", QUILTING_RESULTS_MAX_COUNT="1")
    b = own_cluster.api(QUILTING_MAX_QUEUED="2", QUILTING_RESULTS_MAX_COUNT="1")
    with a.client() as ca, b.client() as cb:
        first = job_id_of(synth(ca, {**SMALL, "seed": 61}, wait=0))
        second = job_id_of(synth(cb, {**SMALL, "seed": 62}, wait=0))
        assert_problem(synth(cb, {**SMALL, "seed": 63}, wait=0), 503, "queue_full")
        assert_problem(ca.get("/readyz"), 503, "queue_full")
        own_cluster.worker(QUILTING_MAX_QUEUED="2", QUILTING_RESULTS_MAX_COUNT="1")
        for job_id in (first, second):
            assert wait_for(ca, job_id, timeout=60)["status"] == "done"
        # One result is kept: the older one has expired (410), the newer one is there.
        statuses = {job_id: cb.get(f"/jobs/{job_id}").json() for job_id in (first, second)}
        kept = [j for j, s in statuses.items() if not s["expired"]]
        gone = [j for j, s in statuses.items() if s["expired"]]
        assert len(kept) == 1 and len(gone) == 1, statuses
        assert_png(ca.get(f"/jobs/{kept[0]}/result"), 96, 96)
        assert_problem(ca.get(f"/jobs/{gone[0]}/result"), 410, "result_expired")
        # Jobs are private to their API key's owner across replicas too: unknown ids are 404.
        assert_problem(cb.get("/jobs/0123456789abcdef0123456789abcdef"), 404, "job_not_found")


def test_results_expire_after_their_ttl(own_cluster: Cluster) -> None:
    ttl = RESULTS_TTL_S
    api = own_cluster.api(QUILTING_RESULTS_TTL_S=str(ttl))
    own_cluster.worker(QUILTING_RESULTS_TTL_S=str(ttl))
    with api.client() as client:
        submitted = time.monotonic()
        job_id = job_id_of(synth(client, {**SMALL, "seed": 71}, wait=60))
        assert_png(client.get(f"/jobs/{job_id}/result"), 96, 96)
        # Gone once the TTL has passed (polled: no guess at how long that takes), not before.
        wait_expired(client, job_id)
        assert time.monotonic() - submitted >= ttl
        assert_problem(client.get(f"/jobs/{job_id}/result"), 410, "result_expired")
        assert client.get(f"/jobs/{job_id}").json()["expired"] is True
        values = metric_values(client.get("/metrics").text)
        assert values["quilting_results_bytes"] == 0


def test_api_keys_keep_jobs_private_across_replicas(own_cluster: Cluster) -> None:
    a = own_cluster.api(QUILTING_API_KEYS="k1,k2")
    b = own_cluster.api(QUILTING_API_KEYS="k1,k2")
    own_cluster.worker()
    one, two = {"X-API-Key": "k1"}, {"X-API-Key": "k2"}
    with a.client() as ca, b.client() as cb:
        job_id = job_id_of(synth(ca, {**SMALL, "seed": 81}, wait=60, headers=one))
        assert cb.get(f"/jobs/{job_id}", headers=one).json()["status"] == "done"
        assert_problem(cb.get(f"/jobs/{job_id}", headers=two), 404, "job_not_found")
        assert_problem(cb.delete(f"/jobs/{job_id}", headers=two), 404, "job_not_found")


def test_worker_refuses_to_start_without_a_redis_queue() -> None:
    env = {"PATH": "/usr/bin:/bin"}
    run = subprocess.run
    done = run([sys.executable, "-m", "quilting", "worker"], env=env, capture_output=True,
               text=True, timeout=60)  # fmt: skip
    assert done.returncode == 2
    assert "QUILTING_QUEUE=redis://" in done.stderr
    bad = run([sys.executable, "-m", "quilting", "worker", "--queue", "http://x"], env=env,
              capture_output=True, text=True, timeout=60)  # fmt: skip
    assert bad.returncode == 2
    assert "queue" in bad.stderr and "redis://" in bad.stderr


def test_a_job_whose_replica_died_before_queueing_it_is_run(own_cluster: Cluster) -> None:
    # What a replica killed between writing a job and sending its message leaves behind.
    settings = Settings(queue=own_cluster.redis.url, heartbeat_timeout_s=float(HEARTBEAT_S))
    texture = (DATA / "gravel.png").read_bytes()
    spec = JobInput(texture=texture, companions={}, options={"block": 24, "seed": 91},
                    width=96, height=96)  # fmt: skip
    job = Job(id="9" * 32, owner=None, width=96, height=96, companion_names=[], input=spec)
    job.created -= 2 * settings.heartbeat_timeout_s

    async def write() -> None:
        jobs = RedisJobs(settings)
        try:
            await jobs.add(job, spec.to_bytes(), None)
        finally:
            await jobs.close()

    asyncio.run(write())
    api = own_cluster.api()
    own_cluster.worker()
    with api.client() as client:
        status = wait_for(client, job.id, timeout=60)
        assert status["status"] == "done", own_cluster.logs()
        got = read_image(client.get(f"/jobs/{job.id}/result").content)
    np.testing.assert_array_equal(got, engine_image(91, SMALL))
    assert "was never queued" in own_cluster.workers[0].log()


def test_a_worker_stopped_with_sigterm_finishes_its_job_first(own_cluster: Cluster) -> None:
    api = own_cluster.api()
    # A drain grace far longer than the job takes on any machine: the worker must wait for the
    # job however slow the machine is, and a worker that leaves without it still fails the test.
    worker = own_cluster.worker(QUILTING_DRAIN_GRACE_S=str(DRAIN_GRACE_S))
    own_cluster.wait_workers(1)
    with api.client() as client:
        job_id = job_id_of(synth(client, {**LONG, "seed": 101}, wait=0))
        wait_for(client, job_id, ("running",), timeout=60)
        # The job is under way in this worker (its attempt is in the log) when the signal comes.
        deadline = time.monotonic() + 60
        while (job_id, 1) not in worker.attempts():
            assert time.monotonic() < deadline, worker.log()
            time.sleep(0.05)
        assert worker.proc is not None
        signalled = time.time()
        worker.proc.send_signal(signal.SIGTERM)
        try:
            code = worker.proc.wait(timeout=DRAIN_GRACE_S / 2)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"the worker did not exit: {worker.log()}") from None
        assert code == 0, worker.log()
        assert "stopping (grace" in worker.log(), worker.log()
        # The job was finished by the worker that was stopping, once, after the signal.
        status = client.get(f"/jobs/{job_id}").json()
        assert status["status"] == "done", (status, worker.log())
        assert status["finished"] > signalled, (status, signalled)
        assert_png(client.get(f"/jobs/{job_id}/result"), LONG["width"], LONG["height"])
        assert worker.attempts() == [(job_id, 1)]
        assert client.get("/readyz").json()["workers"] == 0


def test_matte_job_through_redis_is_the_python_result(cluster: Cluster) -> None:
    from test_matte_api import OPTIONS, SIZE, _expected, _matte  # the matte tests' request

    a, b = cluster.apis
    expected = _expected()
    with a.client() as ca, b.client() as cb:
        job_id = job_id_of(_matte(ca, OPTIONS, wait=0))
        status = wait_for(cb, job_id, timeout=120)
        assert status["status"] == "done", status
        assert status["companions"] == ["normals", "clusters"] and status["layout"] is None
        image = assert_png(cb.get(f"/jobs/{job_id}/result"), SIZE, SIZE)
        np.testing.assert_array_equal(np.asarray(image), expected.image)
        normals = assert_png(cb.get(f"/jobs/{job_id}/result/normals"), SIZE, SIZE)
        np.testing.assert_array_equal(np.asarray(normals), expected.normal_map())
        assert np.allclose(status["stats"]["light"], expected.light)
        assert_problem(ca.get(f"/jobs/{job_id}/layout"), 404, "no_layout")


def test_a_redis_worker_caps_a_job_at_its_memory_budget_and_takes_the_next(
    own_cluster: Cluster,
) -> None:
    """``quilting worker`` limits its memory as a service worker process does: a job past the
    budget fails with job_too_large naming it, and the same worker does the next job. (The
    replica here allows more than the worker, as one on a larger machine would, so that the
    job reaches the worker instead of being refused from its headers.)"""
    api = own_cluster.api(QUILTING_JOB_MEMORY_BYTES=str(8 << 30))
    worker = own_cluster.worker(QUILTING_JOB_MEMORY_BYTES=str(150 << 20))
    own_cluster.wait_workers(1)
    assert "memory budget of a job: 150 MiB" in worker.log(), worker.log()
    assert worker.proc is not None
    # The cap: the worker's data segment as it was once started, plus the budget.
    limits = Path(f"/proc/{worker.proc.pid}/limits").read_text()
    (soft,) = [line.split()[3] for line in limits.splitlines() if line.startswith("Max data")]
    status_text = Path(f"/proc/{worker.proc.pid}/status").read_text()
    (data_kib,) = [int(line.split()[1]) for line in status_text.splitlines() if "VmData" in line]
    assert soft != "unlimited" and 150 << 20 < int(soft) <= data_kib * 1024 + (150 << 20), soft
    with api.client() as client:
        # An 8192x8192 output alone is 256 MiB of float32: the worker's cost model refuses it
        # before any work (or, were the model to miss, the cap stops it).
        big = job_id_of(synth(client, {"width": 8192, "height": 8192}, wait=0))
        status = wait_for(client, big, timeout=120)
        assert status["status"] == "failed", (status, own_cluster.logs())
        error = status["error"]
        assert error["code"] == "job_too_large" and error["status"] == 422, error
        assert "job_memory_bytes" in error["detail"], error
        small = job_id_of(synth(client, {**SMALL, "seed": 5}, wait=0))
        assert wait_for(client, small, timeout=120)["status"] == "done", own_cluster.logs()
        got = read_image(client.get(f"/jobs/{small}/result").content)
        np.testing.assert_array_equal(got, engine_image(5, SMALL))
    assert [n for _, n, _ in own_cluster.attempts()] == [1, 1]  # no job ran twice
    assert "Traceback" not in worker.log(), worker.log()
