"""The distributed queue's own logic (:mod:`quilting.service.jobs.dramatiq_queue`), in-process.

Covers
------
- the broker a :class:`Dispatch` builds (namespace, heartbeat in milliseconds, no Dramatiq
  middleware, hence no Dramatiq retries or time limit) and the message a job becomes (actor,
  queue, the job id as its only argument, no options);
- the actor :meth:`Dispatch._run` against a fake job store: the time limit and memory budget
  it gives the engine, the attempt it reports progress under, progress throttling, a
  cancelled job, a superseded attempt, a bug in the job, Redis outages waited out with
  backoff, results too large for the memory left (``job_too_large`` naming the budget);
- the same actor run by a real ``dramatiq.Worker`` on a ``StubBroker``;
- :meth:`Dispatch.limit`, :func:`beat`, :func:`run_worker`'s startup line (the job memory
  budget through ``describe_bytes``) and clean leave;
- :class:`RedisQueue`'s submission (message sent then marked, message lost, duplicate) and
  readiness figures against fakes;
- against one real ``redis-server`` (no worker processes): a job whose worker died is run
  again and finished once, a job whose workers keep dying fails with ``job_abandoned``
  after ``max_retries``, a job cancelled while queued is never computed, the message a
  submission leaves in Redis, and the readiness figures.

End-to-end behaviour across worker processes is ``test_distributed.py``'s; the store's Lua
transitions on their own are ``test_redis_jobs.py``'s.
"""

from __future__ import annotations

import asyncio
import json
import logging
import signal
import time
from collections.abc import Callable, Iterator
from types import SimpleNamespace
from typing import Any

import dramatiq
import numpy as np
import pytest
import redis
from cluster import RedisServer, need_redis
from dramatiq.brokers.stub import StubBroker

from quilting.io import encode_png
from quilting.service.jobs import dramatiq_queue as dq
from quilting.service.jobs.job_input import JobInput
from quilting.service.jobs.model import Figures, Job, Status
from quilting.service.jobs.redis_store import RedisJobs, WorkerJobs, sync_client
from quilting.service.memory_limit import describe_bytes
from quilting.service.problems import Problem
from quilting.service.settings import Settings

#: A Redis URL nothing listens on: the in-process tests must never reach it.
NOWHERE = "redis://127.0.0.1:9/0"
BUDGET = 150 << 20

Compute = Callable[..., tuple[Status, dict[str, Any]]]


def _settings(url: str = NOWHERE, **values: Any) -> Settings:
    base: dict[str, Any] = {
        "job_memory_bytes": BUDGET,
        "job_timeout_s": 7.5,
        "heartbeat_timeout_s": 12.0,
        "max_retries": 2,
        "redis_timeout_s": 0.5,
    }
    return Settings(queue=url, **{**base, **values})


def _spec(width: int = 24, height: int = 10) -> JobInput:
    return JobInput(
        texture=encode_png(np.zeros((8, 8), np.uint8)),
        companions={},
        options={},
        width=width,
        height=height,
    )


def _job(job_id: str, width: int = 24, height: int = 10) -> Job:
    return Job(
        id=job_id,
        owner=None,
        width=width,
        height=height,
        companion_names=[],
        input=_spec(width, height),
    )


def _down() -> redis.exceptions.ConnectionError:
    return redis.exceptions.ConnectionError("Redis is down (test)")


class FakeState:
    """The worker's job store, in memory: records every call, answers as scripted."""

    def __init__(self, data: bytes, attempt: int = 1) -> None:
        self.claimed: tuple[int, bytes] | None = (attempt, data)
        self.claims: list[tuple[str, str, dict[str, Any]]] = []
        self.claim_failures = 0
        self.progress_answers: list[str] = []
        self.progress_failures = 0
        self.reports: list[tuple[str, int, float, str]] = []
        self.finishes: list[tuple[str, int, Status, dict[str, Any]]] = []
        self.finish_errors: list[BaseException] = []
        self.finish_answer = True
        self.beats: list[str] = []
        self.left: list[str] = []
        self.orphan_ids: list[str] = []

    def claim(
        self, job_id: str, worker: str, abandoned: dict[str, Any]
    ) -> tuple[int, bytes] | None:
        self.claims.append((job_id, worker, abandoned))
        if self.claim_failures:
            self.claim_failures -= 1
            raise _down()
        return self.claimed

    def progress(self, job_id: str, attempt: int, fraction: float, stage: str) -> str:
        if self.progress_failures:
            self.progress_failures -= 1
            raise _down()
        self.reports.append((job_id, attempt, fraction, stage))
        return self.progress_answers.pop(0) if self.progress_answers else "ok"

    def finish(self, job_id: str, pixels: int, status: Status, fields: dict[str, Any]) -> bool:
        if self.finish_errors:
            raise self.finish_errors.pop(0)
        self.finishes.append((job_id, pixels, status, fields))
        return self.finish_answer

    def heartbeat(self, worker: str) -> int:
        self.beats.append(worker)
        return 1

    def orphans(self) -> list[str]:
        found, self.orphan_ids = self.orphan_ids, []
        return found

    def leave(self, worker: str) -> None:
        self.left.append(worker)


class Calls:
    """A stand-in for :func:`~quilting.service.jobs.worker.compute` that records its calls."""

    def __init__(self, body: Compute | None = None) -> None:
        self.calls: list[dict[str, Any]] = []
        self.body = body

    def __call__(
        self,
        spec: JobInput,
        timeout_s: float,
        report: Callable[[float, str], None],
        cancelled: Callable[[], bool],
        memory_bytes: int | None,
        budget_bytes: int | None,
    ) -> tuple[Status, dict[str, Any]]:
        self.calls.append(
            {
                "spec": spec,
                "timeout_s": timeout_s,
                "memory_bytes": memory_bytes,
                "budget_bytes": budget_bytes,
            }
        )
        if self.body is not None:
            return self.body(report, cancelled)
        return Status.DONE, {"png": b"png", "timings": {"total": 0.1}}


def _dispatch(settings: Settings, state: FakeState) -> dq.Dispatch:
    dispatch = dq.Dispatch(settings)
    dispatch.state = state  # type: ignore[assignment]  # the cached property's slot
    return dispatch


@pytest.fixture
def state() -> FakeState:
    return FakeState(_spec().to_bytes())


@pytest.fixture
def quick_pauses(monkeypatch: pytest.MonkeyPatch) -> list[float]:
    """Replace the module's sleeps by a record of them (no waiting on the clock)."""
    pauses: list[float] = []
    fake_time = SimpleNamespace(sleep=pauses.append, monotonic=time.monotonic)
    monkeypatch.setattr(dq, "time", fake_time)
    return pauses


# --- the broker and the message ----------------------------------------------------------


def test_the_broker_is_namespaced_beats_in_milliseconds_and_has_no_middleware() -> None:
    settings = _settings(heartbeat_timeout_s=12.5, redis_timeout_s=0.75)
    dispatch = dq.Dispatch(settings)
    broker = dispatch.broker
    assert broker.namespace == dq.NAMESPACE == "quilting-dramatiq"
    assert broker.heartbeat_timeout == 12_500
    assert broker.maintenance_chance == dq.MAINTENANCE_ALWAYS
    # No Retries, TimeLimit, AgeLimit...: re-runs and the time limit are the job's own.
    assert broker.middleware == []
    assert broker.actor_options == set()
    kwargs = broker.client.connection_pool.connection_kwargs
    assert kwargs["port"] == 9 and kwargs["socket_timeout"] == 0.75
    assert dispatch.budget_bytes == BUDGET and dispatch.memory_bytes is None
    assert len(dispatch.worker_id) == 32
    assert dq.Dispatch(settings).worker_id != dispatch.worker_id


def test_a_job_becomes_a_message_carrying_only_its_id() -> None:
    dispatch = dq.Dispatch(_settings())
    assert dispatch.run.actor_name == dq.RUN_ACTOR == "quilting_run_job"
    assert dispatch.run.queue_name == dq.QUEUE_NAME == "quilting"
    assert dispatch.broker.get_actor(dq.RUN_ACTOR) is dispatch.run
    message = dispatch.run.message("abc123")
    assert message.actor_name == dq.RUN_ACTOR
    assert message.queue_name == dq.QUEUE_NAME
    assert message.args == ("abc123",) and message.kwargs == {}
    # No max_retries, time_limit...: Dramatiq neither retries nor times out a job.
    assert message.options == {}
    decoded = json.loads(message.encode())
    assert decoded["args"] == ["abc123"] and decoded["options"] == {}


# --- the actor against a fake store ------------------------------------------------------


def test_the_actor_gives_the_engine_the_time_limit_and_budgets(
    monkeypatch: pytest.MonkeyPatch, state: FakeState
) -> None:
    compute = Calls()
    monkeypatch.setattr(dq, "compute", compute)
    monkeypatch.setattr(dq, "cap_memory", lambda budget: budget)
    dispatch = _dispatch(_settings(job_timeout_s=7.5), state)
    dispatch._run("job-1")
    assert compute.calls[-1]["timeout_s"] == 7.5
    # Before limit(): nothing caps the process, the engine still sizes batches to the budget.
    assert compute.calls[-1]["memory_bytes"] is None
    assert compute.calls[-1]["budget_bytes"] == BUDGET
    dispatch.limit()
    dispatch._run("job-1")
    assert compute.calls[-1]["memory_bytes"] == BUDGET
    assert compute.calls[-1]["budget_bytes"] == BUDGET
    spec = compute.calls[-1]["spec"]
    assert (spec.width, spec.height) == (24, 10)
    # Claimed with this worker's id and the abandoned document; finished with the pixels.
    assert state.claims == [("job-1", dispatch.worker_id, dq.ABANDONED)] * 2
    assert dq.ABANDONED["code"] == "job_abandoned" and dq.ABANDONED["status"] == 503
    assert state.finishes[-1] == (
        "job-1",
        240,
        Status.DONE,
        {"png": b"png", "timings": {"total": 0.1}},
    )


def test_limit_caps_the_process_at_the_job_budget(monkeypatch: pytest.MonkeyPatch) -> None:
    asked: list[int | None] = []

    def cap(budget: int | None) -> int | None:
        asked.append(budget)
        return None  # the cap could not be set

    monkeypatch.setattr(dq, "cap_memory", cap)
    dispatch = dq.Dispatch(_settings(job_memory_bytes=300 << 20))
    dispatch.limit()
    assert asked == [300 << 20] and dispatch.memory_bytes is None
    monkeypatch.setattr(dq, "cap_memory", lambda budget: budget)
    dispatch.limit()
    assert dispatch.memory_bytes == 300 << 20


def test_a_job_not_to_run_is_neither_computed_nor_finished(
    monkeypatch: pytest.MonkeyPatch, state: FakeState
) -> None:
    compute = Calls()
    monkeypatch.setattr(dq, "compute", compute)
    state.claimed = None  # final, cancelled while queued, gone, busy or abandoned
    _dispatch(_settings(), state)._run("job-2")
    assert len(state.claims) == 1
    assert compute.calls == [] and state.finishes == [] and state.reports == []


def test_progress_goes_under_the_attempt_and_is_throttled(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    state = FakeState(_spec().to_bytes(), attempt=3)

    def body(
        report: Callable[[float, str], None], cancelled: Callable[[], bool]
    ) -> tuple[Status, dict[str, Any]]:
        for i in range(1, 50):  # far quicker than one report per PROGRESS_EVERY_S
            report(i / 100, "synthesis")
        report(1.0, "encoding")  # the end always goes through
        return Status.DONE, {"png": b"p"}

    monkeypatch.setattr(dq, "compute", Calls(body))
    monkeypatch.setattr(dq, "PROGRESS_EVERY_S", 3600.0)
    _dispatch(_settings(), state)._run("job-3")
    assert state.reports == [("job-3", 3, 0.01, "synthesis"), ("job-3", 3, 1.0, "encoding")]
    assert [f[2] for f in state.finishes] == [Status.DONE]


def test_a_cancel_seen_in_progress_stops_the_engine(
    monkeypatch: pytest.MonkeyPatch, state: FakeState
) -> None:
    seen: list[bool] = []

    def body(
        report: Callable[[float, str], None], cancelled: Callable[[], bool]
    ) -> tuple[Status, dict[str, Any]]:
        seen.append(cancelled())
        report(0.5, "synthesis")
        seen.append(cancelled())
        return Status.CANCELLED, {}

    monkeypatch.setattr(dq, "compute", Calls(body))
    state.progress_answers = ["cancel"]
    _dispatch(_settings(), state)._run("job-4")
    assert seen == [False, True]
    assert [(f[0], f[2], f[3]) for f in state.finishes] == [("job-4", Status.CANCELLED, {})]


def test_a_superseded_attempt_stops_without_writing(
    monkeypatch: pytest.MonkeyPatch, state: FakeState
) -> None:
    after: list[str] = []

    def body(
        report: Callable[[float, str], None], cancelled: Callable[[], bool]
    ) -> tuple[Status, dict[str, Any]]:
        report(0.2, "synthesis")
        after.append("went on")  # never: the report raises
        return Status.DONE, {"png": b"p"}

    monkeypatch.setattr(dq, "compute", Calls(body))
    state.progress_answers = ["stale"]
    _dispatch(_settings(), state)._run("job-5")
    assert after == [] and state.finishes == []
    assert len(state.reports) == 1


def test_a_bug_in_the_job_fails_it_with_internal_error(
    monkeypatch: pytest.MonkeyPatch, state: FakeState
) -> None:
    def body(
        report: Callable[[float, str], None], cancelled: Callable[[], bool]
    ) -> tuple[Status, dict[str, Any]]:
        raise KeyError("a bug")

    monkeypatch.setattr(dq, "compute", Calls(body))
    _dispatch(_settings(), state)._run("job-6")  # the actor itself does not raise
    ((job_id, pixels, status, fields),) = state.finishes
    assert (job_id, pixels, status) == ("job-6", 240, Status.FAILED)
    assert fields["error"]["code"] == "internal_error" and fields["error"]["status"] == 500


def test_an_unreadable_input_fails_the_job_and_not_the_worker(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    compute = Calls()
    monkeypatch.setattr(dq, "compute", compute)
    state = FakeState(b"not a job input")
    _dispatch(_settings(), state)._run("job-7")
    assert compute.calls == []
    ((_, pixels, status, fields),) = state.finishes
    assert pixels == 0 and status is Status.FAILED
    assert fields["error"]["code"] == "internal_error"


def test_lost_progress_reports_are_dropped_and_the_job_goes_on(
    monkeypatch: pytest.MonkeyPatch, state: FakeState
) -> None:
    def body(
        report: Callable[[float, str], None], cancelled: Callable[[], bool]
    ) -> tuple[Status, dict[str, Any]]:
        report(0.5, "synthesis")  # Redis down: dropped, not waited for
        report(1.0, "encoding")
        return Status.DONE, {"png": b"p"}

    monkeypatch.setattr(dq, "compute", Calls(body))
    state.progress_failures = 1
    _dispatch(_settings(), state)._run("job-8")
    assert state.reports == [("job-8", 1, 1.0, "encoding")]
    assert [f[2] for f in state.finishes] == [Status.DONE]


def test_a_worker_waits_for_redis_with_backoff_to_claim(
    monkeypatch: pytest.MonkeyPatch, state: FakeState, quick_pauses: list[float]
) -> None:
    monkeypatch.setattr(dq, "compute", Calls())
    state.claim_failures = 7
    _dispatch(_settings(), state)._run("job-9")
    assert quick_pauses == [0.25, 0.5, 1.0, 2.0, 4.0, 5.0, 5.0]
    assert len(state.claims) == 8 and len(state.finishes) == 1


def test_a_stopping_worker_gives_up_waiting_for_redis(
    monkeypatch: pytest.MonkeyPatch, state: FakeState, quick_pauses: list[float]
) -> None:
    compute = Calls()
    monkeypatch.setattr(dq, "compute", compute)
    state.claim_failures = 3
    dispatch = _dispatch(_settings(), state)
    dispatch.stopping.set()
    with pytest.raises(redis.exceptions.ConnectionError):
        dispatch._run("job-10")
    assert quick_pauses == [] and compute.calls == [] and len(state.claims) == 1


def test_a_worker_waits_for_redis_to_write_the_end(
    monkeypatch: pytest.MonkeyPatch, state: FakeState, quick_pauses: list[float]
) -> None:
    monkeypatch.setattr(dq, "compute", Calls())
    state.finish_errors = [_down(), redis.exceptions.TimeoutError("slow")]
    _dispatch(_settings(), state)._run("job-11")
    assert quick_pauses == [0.25, 0.5]
    assert [(f[0], f[2]) for f in state.finishes] == [("job-11", Status.DONE)]


@pytest.mark.parametrize(
    ("capped", "named"), [(BUDGET, describe_bytes(BUDGET)), (None, "no per-job limit")]
)
def test_results_too_large_to_write_fail_the_job_too_large(
    monkeypatch: pytest.MonkeyPatch, state: FakeState, capped: int | None, named: str
) -> None:
    monkeypatch.setattr(dq, "compute", Calls())
    monkeypatch.setattr(dq, "cap_memory", lambda budget: capped)
    state.finish_errors = [MemoryError()]
    dispatch = _dispatch(_settings(), state)
    dispatch.limit()
    dispatch._run("job-12")
    ((job_id, pixels, status, fields),) = state.finishes
    assert (job_id, pixels, status) == ("job-12", 240, Status.FAILED)
    assert set(fields) == {"error"}  # no results
    error = fields["error"]
    assert error["code"] == "job_too_large" and error["status"] == 422
    assert named in error["detail"]
    if capped is not None:
        assert "150 MiB" in error["detail"]


# --- through a dramatiq worker -----------------------------------------------------------


class Stub(StubBroker):  # type: ignore[misc]
    """A StubBroker with what Dispatch asks of a RedisBroker: a client, its own heartbeat."""

    client = None

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(middleware=kwargs["middleware"])
        self.sizes: list[str] = []

    def do_qsize(self, queue_name: str) -> int:
        self.sizes.append(queue_name)
        return 0


@pytest.fixture
def stub_dispatch(monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[dq.Dispatch, FakeState]]:
    """A Dispatch on a StubBroker (its RedisBroker replaced), with a fake store."""
    built: list[dict[str, Any]] = []

    def broker(**kwargs: Any) -> Stub:
        built.append(kwargs)
        return Stub(**kwargs)

    monkeypatch.setattr(dq, "RedisBroker", broker)
    state = FakeState(_spec().to_bytes())
    monkeypatch.setattr(dq, "WorkerJobs", lambda settings, client: state)
    dispatch = dq.Dispatch(_settings())
    assert built[0]["middleware"] == [] and built[0]["namespace"] == dq.NAMESPACE
    yield dispatch, state
    dispatch.broker.close()


def test_a_dramatiq_worker_runs_each_message_once(
    monkeypatch: pytest.MonkeyPatch, stub_dispatch: tuple[dq.Dispatch, FakeState]
) -> None:
    dispatch, state = stub_dispatch
    calls = 0

    def body(
        report: Callable[[float, str], None], cancelled: Callable[[], bool]
    ) -> tuple[Status, dict[str, Any]]:
        nonlocal calls
        calls += 1
        if calls == 2:
            raise RuntimeError("a bug")  # must not dead-letter the message
        return Status.DONE, {"png": b"p"}

    monkeypatch.setattr(dq, "compute", Calls(body))
    worker = dramatiq.Worker(dispatch.broker, worker_threads=1, worker_timeout=dq.IDLE_POLL_MS)
    worker.start()
    try:
        for job_id in ("a", "b", "c"):
            dispatch.run.send(job_id)
        dispatch.broker.join(dq.QUEUE_NAME, timeout=10_000, fail_fast=True)
        worker.join()
    finally:
        worker.stop()
    assert dispatch.broker.dead_letters == []
    assert [c[0] for c in state.claims] == ["a", "b", "c"]
    assert [(f[0], f[2]) for f in state.finishes] == [
        ("a", Status.DONE),
        ("b", Status.FAILED),
        ("c", Status.DONE),
    ]


def test_beat_says_alive_to_both_and_queues_orphans_once(
    stub_dispatch: tuple[dq.Dispatch, FakeState],
) -> None:
    dispatch, state = stub_dispatch
    state.orphan_ids = ["o1", "o2"]
    dq.beat(dispatch)
    dq.beat(dispatch)
    assert state.beats == [dispatch.worker_id] * 2
    assert dispatch.broker.sizes == [dq.QUEUE_NAME] * 2  # type: ignore[attr-defined]
    queued = dispatch.broker.queues[dq.QUEUE_NAME]
    messages = [dramatiq.Message.decode(queued.get_nowait()) for _ in range(queued.qsize())]
    assert [m.args for m in messages] == [("o1",), ("o2",)]
    assert {m.actor_name for m in messages} == {dq.RUN_ACTOR}


def test_beat_rides_over_an_unreachable_redis(
    stub_dispatch: tuple[dq.Dispatch, FakeState],
) -> None:
    dispatch, state = stub_dispatch

    def down(worker: str) -> int:
        raise _down()

    state.heartbeat = down  # type: ignore[method-assign]
    dq.beat(dispatch)  # logged, not raised
    assert dispatch.broker.queues[dq.QUEUE_NAME].qsize() == 0


@pytest.mark.parametrize(("capped", "said"), [(BUDGET, "150 MiB"), (None, "not limited")])
def test_run_worker_names_its_budget_and_leaves_on_sigterm(
    monkeypatch: pytest.MonkeyPatch,
    stub_dispatch: tuple[dq.Dispatch, FakeState],
    caplog: pytest.LogCaptureFixture,
    capped: int | None,
    said: str,
) -> None:
    _, state = stub_dispatch
    monkeypatch.setattr(dq, "cap_memory", lambda budget: capped)
    workers: list[dramatiq.Worker] = []

    class Spy(dramatiq.Worker):  # type: ignore[misc]
        def start(self) -> None:
            workers.append(self)
            super().start()

    monkeypatch.setattr(dq.dramatiq, "Worker", Spy)
    beat_once = state.heartbeat

    def heartbeat(worker: str) -> int:
        # The first beat comes after the handlers are set: stop the worker as a user would.
        signal.raise_signal(signal.SIGTERM)
        return beat_once(worker)

    state.heartbeat = heartbeat  # type: ignore[method-assign]
    handlers = signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)
    try:
        with caplog.at_level(logging.INFO, logger="quilting.worker"):
            dq.run_worker(_settings(drain_grace_s=1.0))
    finally:
        signal.signal(signal.SIGTERM, handlers[0])
        signal.signal(signal.SIGINT, handlers[1])
    ((worker_id,),) = {tuple(state.beats)}
    assert state.left == [worker_id]
    (worker,) = workers
    assert worker.queue_prefetch == 1 and worker.worker_timeout == dq.IDLE_POLL_MS
    assert worker.workers and not any(t.is_alive() for t in worker.workers)  # stopped
    started = [r.getMessage() for r in caplog.records if "taking jobs" in r.getMessage()]
    assert started == [
        f"worker {worker_id} taking jobs from queue 'quilting' (memory budget of a job: {said})"
    ]


# --- the API side against fakes ----------------------------------------------------------


class FakeJobs:
    """The API side of the store, in memory."""

    def __init__(self, created: bool = True) -> None:
        self.created = created
        self.calls: list[tuple[str, str]] = []
        self.records: dict[str, Job] = {}

    async def add(
        self, job: Job, data: bytes, idempotency: tuple[str, str] | None
    ) -> tuple[str, bool]:
        self.calls.append(("add", job.id))
        assert JobInput.from_bytes(data).width == job.width
        if not self.created:
            return "earlier", False
        self.records[job.id] = job
        return job.id, True

    async def get(self, job_id: str, owner: str | None) -> Job:
        self.calls.append(("get", job_id))
        return Job(id=job_id, owner=owner, width=1, height=1, companion_names=[], input=None)

    async def sent(self, job_id: str) -> None:
        self.calls.append(("sent", job_id))

    async def drop(self, job_id: str) -> None:
        self.calls.append(("drop", job_id))

    async def figures(self) -> Figures:
        return Figures({}, {}, [], 0.0, 0, 0, queued=4, running=2)

    async def workers(self) -> int:
        return 3


def _queue(settings: Settings, jobs: FakeJobs) -> tuple[dq.RedisQueue, list[str]]:
    queue = dq.RedisQueue(settings)
    queue.jobs = jobs  # type: ignore[assignment]
    sent: list[str] = []
    queue.dispatch.broker.enqueue = (  # type: ignore[method-assign]
        lambda message, delay=None: sent.append(message.args[0]) or message
    )
    return queue, sent


def test_a_submission_is_recorded_then_sent_then_marked_sent() -> None:
    jobs = FakeJobs()
    queue, sent = _queue(_settings(), jobs)
    job = _job("j1")
    got, created = asyncio.run(queue.submit(job, None))
    assert created and got is job and job.input is None  # the input lives in Redis now
    assert sent == ["j1"]
    assert jobs.calls == [("add", "j1"), ("sent", "j1")]


def test_a_submission_whose_message_is_lost_is_taken_back() -> None:
    jobs = FakeJobs()
    queue, _ = _queue(_settings(), jobs)

    def lost(message: dramatiq.Message, delay: int | None = None) -> None:
        raise _down()

    queue.dispatch.broker.enqueue = lost  # type: ignore[method-assign]
    with pytest.raises(Problem) as caught:
        asyncio.run(queue.submit(_job("j2"), None))
    assert caught.value.status == 503 and caught.value.code == "queue_unavailable"
    assert jobs.calls == [("add", "j2"), ("drop", "j2")]


def test_a_duplicate_submission_sends_nothing() -> None:
    jobs = FakeJobs(created=False)
    queue, sent = _queue(_settings(), jobs)
    got, created = asyncio.run(queue.submit(_job("j3"), ("key", "digest")))
    assert not created and got.id == "earlier"
    assert sent == [] and jobs.calls == [("add", "j3"), ("get", "earlier")]


def test_readiness_reports_the_shared_queue() -> None:
    queue, _ = _queue(_settings(backend="fft"), FakeJobs())
    assert asyncio.run(queue.readiness()) == {
        "queue": "redis",
        "backend": "fft",
        "queue_depth": 4,
        "running": 2,
        "workers": 3,
    }
    assert queue.busy() is False


# --- against a real redis-server (no worker processes) -----------------------------------


@pytest.fixture(scope="module")
def redis_url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    need_redis()
    server = RedisServer(tmp_path_factory.mktemp("redis")).start()
    try:
        yield server.url
    finally:
        server.stop()


@pytest.fixture
def live(redis_url: str) -> Iterator[str]:
    client = sync_client(redis_url)
    client.flushall()
    client.close()
    yield redis_url


def _add(queue: dq.RedisQueue, job: Job) -> None:
    async def add() -> None:
        assert job.input is not None
        assert await queue.jobs.add(job, job.input.to_bytes(), None) == (job.id, True)

    asyncio.run(add())


def _read(settings: Settings, job_id: str) -> tuple[Job, Figures]:
    async def read() -> tuple[Job, Figures]:
        jobs = RedisJobs(settings)
        try:
            return await jobs.get(job_id, None), await jobs.figures()
        finally:
            await jobs.close()

    return asyncio.run(read())


def _dead_claim(settings: Settings, job_id: str) -> int:
    """A worker claims the job, then dies (never beats, never finishes): its attempt."""
    client = sync_client(settings.queue)
    try:
        claimed = WorkerJobs(settings, client).claim(job_id, "dead" * 8, dq.ABANDONED)
    finally:
        client.close()
    assert claimed is not None
    return claimed[0]


def test_a_job_whose_worker_died_is_run_again_and_counted_once(
    monkeypatch: pytest.MonkeyPatch, live: str
) -> None:
    settings = _settings(live, max_retries=2)
    compute = Calls()
    monkeypatch.setattr(dq, "compute", compute)
    queue = dq.RedisQueue(settings)
    _add(queue, _job("d1"))
    assert _dead_claim(settings, "d1") == 1
    dispatch = dq.Dispatch(settings)
    dispatch._run("d1")  # the message, taken again once the first worker's heartbeat stopped
    dispatch._run("d1")  # and delivered once more: the job is final, nothing runs
    assert len(compute.calls) == 1
    job, figures = _read(settings, "d1")
    assert job.status is Status.DONE and job.error is None
    assert figures.finished_total["done"] == 1 and sum(figures.finished_total.values()) == 1
    assert (figures.queued, figures.running) == (0, 0)
    dispatch.broker.close()


def test_a_job_whose_workers_keep_dying_is_abandoned_after_max_retries(
    monkeypatch: pytest.MonkeyPatch, live: str
) -> None:
    settings = _settings(live, max_retries=1)
    compute = Calls()
    monkeypatch.setattr(dq, "compute", compute)
    queue = dq.RedisQueue(settings)
    _add(queue, _job("d2"))
    assert [_dead_claim(settings, "d2") for _ in range(2)] == [1, 2]  # the run and 1 retry
    dispatch = dq.Dispatch(settings)
    dispatch._run("d2")
    assert compute.calls == []
    job, figures = _read(settings, "d2")
    assert job.status is Status.FAILED
    assert job.error == dq.ABANDONED
    assert "max_retries" in dq.ABANDONED["detail"]
    assert figures.finished_total == {"done": 0, "failed": 1, "cancelled": 0}
    dispatch.broker.close()


def test_a_message_for_a_job_cancelled_meanwhile_is_not_computed(
    monkeypatch: pytest.MonkeyPatch, live: str
) -> None:
    settings = _settings(live)
    compute = Calls()
    monkeypatch.setattr(dq, "compute", compute)
    queue = dq.RedisQueue(settings)
    job = _job("c1")
    _add(queue, job)

    async def cancel() -> Job:
        jobs = RedisJobs(settings)
        try:
            await jobs.cancel(job)
            return await jobs.get(job.id, None)
        finally:
            await jobs.close()

    assert asyncio.run(cancel()).status is Status.CANCELLED
    dispatch = dq.Dispatch(settings)
    dispatch._run("c1")
    assert compute.calls == []
    after, figures = _read(settings, "c1")
    assert after.status is Status.CANCELLED and after.started is None
    assert figures.finished_total == {"done": 0, "failed": 0, "cancelled": 1}
    dispatch.broker.close()


def test_a_submission_leaves_one_message_and_readiness_counts_it(live: str) -> None:
    settings = _settings(live, backend="fft")

    async def scenario() -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
        queue = dq.RedisQueue(settings)
        try:
            empty = await queue.readiness()
            job, created = await queue.submit(_job("s1"), None)
            assert created and job.status is Status.QUEUED
            queued = await queue.readiness()
            dispatch = dq.Dispatch(settings)
            await asyncio.to_thread(dq.beat, dispatch)
            claimed = await asyncio.to_thread(
                dispatch.state.claim, "s1", dispatch.worker_id, dq.ABANDONED
            )
            assert claimed is not None and claimed[0] == 1
            running = await queue.readiness()
            dispatch.broker.close()
            return empty, queued, running
        finally:
            await queue.stop(1.0)

    empty, queued, running = asyncio.run(scenario())
    base = {"queue": "redis", "backend": "fft"}
    assert empty == {**base, "queue_depth": 0, "running": 0, "workers": 0}
    assert queued == {**base, "queue_depth": 1, "running": 0, "workers": 0}
    assert running == {**base, "queue_depth": 0, "running": 1, "workers": 1}
    client = sync_client(live)
    try:
        raw = client.hvals(f"{dq.NAMESPACE}:{dq.QUEUE_NAME}.msgs")
    finally:
        client.close()
    (message,) = [json.loads(m) for m in raw]
    assert message["actor_name"] == dq.RUN_ACTOR and message["queue_name"] == dq.QUEUE_NAME
    assert message["args"] == ["s1"] and message["kwargs"] == {}
    assert set(message["options"]) <= {"redis_message_id"}
