"""Job state in Redis, one transition at a time, against a real redis-server.

The properties the distributed queue rests on: a job run twice is finished once and its
results are not overwritten; a second delivery does not take a job from a live worker but does
from a dead one; a job that keeps losing its workers is abandoned; a job cancelled while queued
never runs.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from cluster import RedisServer, need_redis

from quilting.io import encode_png
from quilting.service.jobs import Job, JobInput, Status
from quilting.service.jobs.redis_store import RedisJobs, WorkerJobs, sync_client
from quilting.service.settings import Settings

ABANDONED = {"code": "job_abandoned", "status": 503}


@pytest.fixture
def settings(tmp_path: Path) -> Iterator[Settings]:
    need_redis()
    redis = RedisServer(tmp_path).start()
    try:
        yield Settings(queue=redis.url, max_retries=2, heartbeat_timeout_s=5.0)
    finally:
        redis.stop()


def _job(job_id: str) -> Job:
    spec = JobInput(
        texture=encode_png(np.zeros((8, 8), np.uint8)),
        companions={},
        options={},
        width=16,
        height=8,
    )
    return Job(id=job_id, owner=None, width=16, height=8, companion_names=[], input=spec)


def _add(settings: Settings, job: Job) -> None:
    async def add() -> None:
        jobs = RedisJobs(settings)
        try:
            assert job.input is not None
            assert await jobs.add(job, job.input.to_bytes(), None) == (job.id, True)
        finally:
            await jobs.close()

    asyncio.run(add())


def _read(settings: Settings, job_id: str) -> tuple[Job, dict[str, int], bytes | None]:
    async def read() -> tuple[Job, dict[str, int], bytes | None]:
        jobs = RedisJobs(settings)
        try:
            job = await jobs.get(job_id, None)
            figures = await jobs.figures()
            return job, figures.finished_total, await jobs.output(job, "png")
        finally:
            await jobs.close()

    return asyncio.run(read())


def _fields(png: bytes) -> dict[str, object]:
    return {"png": png, "layout": b"{}", "companions": {}, "timings": {"total": 1.0}}


def test_a_job_run_twice_is_finished_once_with_the_first_results(settings: Settings) -> None:
    state = WorkerJobs(settings, sync_client(settings.queue))
    job = _job("a" * 32)
    _add(settings, job)
    first = state.claim(job.id, "worker-a", ABANDONED)
    assert first is not None and first[0] == 1
    assert JobInput.from_bytes(first[1]).width == 16
    # worker-a sent no heartbeat: a second delivery takes the job over as attempt 2.
    second = state.claim(job.id, "worker-b", ABANDONED)
    assert second is not None and second[0] == 2
    assert state.progress(job.id, 1, 0.5, "level 3") == "stale"  # a stops at its next report
    assert state.progress(job.id, 2, 0.5, "level 3") == "ok"
    pixels = job.width * job.height
    assert state.finish(job.id, pixels, Status.DONE, _fields(b"second")) is True
    # The first attempt finishing late changes nothing: no second result, no second count.
    assert state.finish(job.id, pixels, Status.DONE, _fields(b"first")) is False
    assert state.finish(job.id, pixels, Status.FAILED, {"error": {"code": "x"}}) is False
    record, totals, png = _read(settings, job.id)
    assert record.status is Status.DONE and record.progress == 1.0 and record.has_layout
    assert png == b"second"
    assert totals == {"done": 1, "failed": 0, "cancelled": 0}


def test_a_second_delivery_leaves_a_live_worker_its_job(settings: Settings) -> None:
    state = WorkerJobs(settings, sync_client(settings.queue))
    job = _job("b" * 32)
    _add(settings, job)
    state.heartbeat("worker-a")
    assert state.claim(job.id, "worker-a", ABANDONED) is not None
    state.heartbeat("worker-a")
    assert state.claim(job.id, "worker-b", ABANDONED) is None  # busy on a live worker
    assert state.progress(job.id, 1, 0.25, "level 1") == "ok"  # still worker-a's job
    assert _read(settings, job.id)[0].status is Status.RUNNING


def test_a_job_that_keeps_losing_its_workers_is_abandoned(settings: Settings) -> None:
    state = WorkerJobs(settings, sync_client(settings.queue))
    job = _job("c" * 32)
    _add(settings, job)
    # max_retries=2: three starts, then the fourth delivery fails the job.
    for attempt in (1, 2, 3):
        claimed = state.claim(job.id, f"worker-{attempt}", ABANDONED)
        assert claimed is not None and claimed[0] == attempt
    assert state.claim(job.id, "worker-4", ABANDONED) is None
    record, totals, png = _read(settings, job.id)
    assert record.status is Status.FAILED
    assert record.error == ABANDONED
    assert totals["failed"] == 1 and png is None


def test_a_job_cancelled_while_queued_never_runs(settings: Settings) -> None:
    state = WorkerJobs(settings, sync_client(settings.queue))
    job = _job("d" * 32)
    _add(settings, job)

    async def cancel() -> None:
        jobs = RedisJobs(settings)
        try:
            await jobs.cancel(job)
        finally:
            await jobs.close()

    asyncio.run(cancel())
    assert state.claim(job.id, "worker-a", ABANDONED) is None
    record, totals, _ = _read(settings, job.id)
    assert record.status is Status.CANCELLED and totals["cancelled"] == 1
    # Its input is gone with it: nothing of a final job stays in Redis but its record.
    assert sync_client(settings.queue).exists(f"quilting:input:{job.id}") == 0
    assert json.loads(json.dumps(record.snapshot()))["status"] == "cancelled"


def test_a_job_whose_message_was_never_sent_is_found_once(settings: Settings) -> None:
    state = WorkerJobs(settings, sync_client(settings.queue))
    orphan, sent = _job("e" * 32), _job("f" * 32)
    orphan.created -= 60  # older than the heartbeat timeout
    sent.created -= 60
    young = _job("1" * 32)
    for job in (orphan, sent, young):
        _add(settings, job)

    async def mark() -> None:
        jobs = RedisJobs(settings)
        try:
            await jobs.sent(sent.id)
        finally:
            await jobs.close()

    asyncio.run(mark())
    # Only the old job without a message; and only once, whoever asks next.
    assert state.orphans() == [orphan.id]
    assert state.orphans() == []
