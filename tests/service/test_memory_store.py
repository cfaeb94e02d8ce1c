"""The in-process job store, driven directly: no HTTP, no server, no worker.

Covers :class:`quilting.service.jobs.memory.Store` and the thin :class:`LocalQueue` around it,
with the test standing in for the worker (``start``, ``update``, ``finish`` as
:class:`~quilting.service.jobs.pool.Runner` calls them; the runner is never started):

* a job's life, queued -> running -> done / failed / cancelled, and what each state shows;
* the ``max_queued`` cap (503 ``queue_full``) and the room a job leaves as it leaves the queue;
* idempotency keys: a repeat finds the earlier job, another body is 409
  ``idempotency_conflict``, keys are per owner and free again once the results are gone;
* owners: a job is found (404 ``job_not_found`` otherwise) by its owner only;
* cancelling a queued job (final at once, skipped by its worker) and a running one (flagged);
* the result caps (count, bytes), their time-to-live on an injected clock, and the records
  forgotten past ten times the result cap; the duration histogram's bucket edges, as the Redis
  store (``jobs.lua``) counts them;
* versions and waiters (what event streams and ``?wait=`` rest on);
* submissions, repeats, cancels and finishes from many threads at once: nothing lost, nothing
  counted twice.
"""

from __future__ import annotations

import asyncio
import functools
import threading
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

import pytest

from quilting.service.jobs import HISTOGRAM_BUCKETS, Job, Status, memory, new_job_id
from quilting.service.jobs.memory import LocalQueue, Store
from quilting.service.problems import Problem
from quilting.service.settings import Settings

T = TypeVar("T")

#: Threads of the concurrency tests, and what each of them does.
THREADS = 8
PER_THREAD = 40


class Clock:
    """A stand-in for the ``time`` module of :mod:`quilting.service.jobs.memory`."""

    def __init__(self, now: float) -> None:
        self.now = now

    def time(self) -> float:
        return self.now


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> Clock:
    """The store's clock, set by hand (the rest of the process keeps real time)."""
    fake = Clock(1_000_000.0)
    monkeypatch.setattr(memory, "time", fake)
    return fake


@pytest.fixture
def local() -> Iterator[LocalQueue]:
    """A local queue whose runner is never started: the test plays the worker."""
    queue = LocalQueue(Settings(worker_mode="thread", workers=1, max_queued=4))
    yield queue
    asyncio.run(queue.stop(0))


def make_job(
    owner: str | None = None, width: int = 8, height: int = 4, operation: str = "synthesize"
) -> Job:
    return Job(
        id=new_job_id(),
        owner=owner,
        width=width,
        height=height,
        companion_names=["normal"],
        input=None,
        operation=operation,
    )


def problem_of(call: Callable[[], object]) -> Problem:
    """The :class:`Problem` ``call`` raises."""
    with pytest.raises(Problem) as raised:
        call()
    return raised.value


def run_done(store: Store, job: Job, png: bytes = b"png", **changes: Any) -> None:
    """Play a worker that computes ``job`` (already added) to the end."""
    assert store.start(job)
    store.finish(job, Status.DONE, png=png, **changes)


def together(count: int, work: Callable[[int], T]) -> list[T]:
    """``work(0..count-1)``, each in a thread of its own, released at once by a barrier;
    their results in order (an exception in any thread fails the test)."""
    barrier = threading.Barrier(count)
    results: list[Any] = [None] * count
    errors: list[BaseException] = []

    def main(index: int) -> None:
        try:
            barrier.wait(timeout=10)
            results[index] = work(index)
        except BaseException as exc:  # reported below, in the test's thread
            errors.append(exc)

    threads = [threading.Thread(target=main, args=(i,)) for i in range(count)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=30)
        assert not thread.is_alive(), "a thread of the test hung"
    assert errors == [], errors
    return results


# --- a job's life ------------------------------------------------------------------------------


def test_a_job_goes_queued_running_done_and_each_state_shows_what_it_has() -> None:
    store = Store(Settings())
    job = make_job(width=8, height=4)
    assert store.add(job) == (job, True)
    queued = job.snapshot()
    assert (queued["status"], queued["stage"], queued["progress"]) == ("queued", "queued", 0.0)
    assert queued["started"] is None and queued["finished"] is None
    assert queued["result"] is None and queued["layout"] is None
    assert (store.queued, store.running) == (1, 0)

    assert store.start(job)
    running = job.snapshot()
    assert (running["status"], running["stage"]) == ("running", "decoding")
    assert running["started"] is not None and running["result"] is None
    assert (store.queued, store.running) == (0, 1)
    store.update(job, progress=0.5, stage="level 2")
    assert (job.progress, job.stage) == (0.5, "level 2")

    store.finish(
        job, Status.DONE, png=b"12345", layout=b"{}", companions={"normal": b"nn"}, stats={"k": 1}
    )
    done = job.snapshot()
    assert (done["status"], done["stage"], done["progress"]) == ("done", "done", 1.0)
    assert done["result"] == f"/jobs/{job.id}/result"
    assert done["layout"] == f"/jobs/{job.id}/layout"
    assert done["manifest"] is None  # a synthesis's layout is no Wang manifest
    assert done["finished"] is not None and done["finished"] >= done["started"]
    assert done["stats"] == {"k": 1} and done["expired"] is False
    assert job.input is None and job.done.is_set()
    assert (store.queued, store.running) == (0, 0)
    figures = store.figures()
    assert figures.finished_total == {"done": 1, "failed": 0, "cancelled": 0}
    assert figures.counts == {"queued": 0, "running": 0, "done": 1, "failed": 0, "cancelled": 0}
    assert figures.pixels_total == 8 * 4
    assert figures.kept_bytes == len(b"12345") + len(b"{}") + len(b"nn")


def test_a_failed_job_keeps_its_error_and_offers_no_result() -> None:
    store = Store(Settings())
    job = make_job()
    store.add(job)
    store.start(job)
    store.update(job, progress=0.25, stage="level 1")
    error = {"code": "job_timeout", "status": 504}
    store.finish(job, Status.FAILED, error=error)
    snapshot = job.snapshot()
    assert (snapshot["status"], snapshot["stage"]) == ("failed", "failed")
    assert snapshot["error"] == error and snapshot["result"] is None
    assert snapshot["progress"] == 0.25  # as far as it got, not 1
    assert job.done.is_set() and job.input is None
    figures = store.figures()
    assert figures.finished_total == {"done": 0, "failed": 1, "cancelled": 0}
    assert (figures.kept_bytes, figures.pixels_total, figures.running) == (0, 0, 0)


def test_a_finished_wang_tile_set_offers_its_manifest_and_one_without_layout_none() -> None:
    store = Store(Settings())
    wang = make_job(operation="wang_tiles")
    plain = make_job()
    for job in (wang, plain):
        store.add(job)
    run_done(store, wang, layout=b'{"tiles": []}')
    run_done(store, plain)  # no layout
    assert wang.has_layout and wang.snapshot()["manifest"] == f"/jobs/{wang.id}/manifest"
    assert not plain.has_layout
    assert plain.snapshot()["layout"] is None and plain.snapshot()["manifest"] is None


# --- the queue's cap -----------------------------------------------------------------------


def test_the_queue_refuses_past_its_cap_and_has_room_once_a_job_leaves_the_queue() -> None:
    store = Store(Settings(max_queued=2))
    first, second = make_job(), make_job()
    store.add(first)
    store.add(second)
    refused = problem_of(lambda: store.add(make_job()))
    assert (refused.status, refused.code) == (503, "queue_full")
    assert refused.headers.get("Retry-After") == "5"
    assert len(store.jobs) == 2  # the refused job left no record

    # Each way out of the queue frees a slot at once: started, cancelled, failed at shutdown.
    assert store.start(first)
    third = make_job()
    assert store.add(third)[1]
    store.cancel_queued(second)
    fourth = make_job()
    assert store.add(fourth)[1]
    assert store.fail_queued(third, {"code": "shutdown"})
    assert store.add(make_job())[1]
    assert (store.queued, store.running) == (2, 1)
    assert problem_of(lambda: store.add(make_job())).code == "queue_full"
    # A running job does not count against the cap, nor does finishing it change the queue.
    store.finish(first, Status.DONE, png=b"x")
    assert store.queued == 2
    assert problem_of(lambda: store.add(make_job())).code == "queue_full"


def test_a_submission_refused_for_a_full_queue_leaves_its_key_unbound() -> None:
    store = Store(Settings(max_queued=1))
    waiting = make_job()
    store.add(waiting)
    assert problem_of(lambda: store.add(make_job(), ("key", "body-a"))).code == "queue_full"
    assert store.idempotency == {}
    store.cancel_queued(waiting)
    # Not a conflict: the refused submission never used the key.
    job = make_job()
    assert store.add(job, ("key", "body-b")) == (job, True)


# --- idempotency keys ----------------------------------------------------------------------


def test_a_repeated_key_and_body_find_the_earlier_job_even_when_the_queue_is_full() -> None:
    store = Store(Settings(max_queued=1))
    first = make_job(owner="k1")
    assert store.add(first, ("key", "body")) == (first, True)
    again = make_job(owner="k1")
    assert store.add(again, ("key", "body")) == (first, False)
    assert again.id not in store.jobs and store.queued == 1
    # Still the same job once it runs and once it is done.
    store.start(first)
    assert store.add(make_job(owner="k1"), ("key", "body")) == (first, False)
    store.finish(first, Status.DONE, png=b"x")
    assert store.add(make_job(owner="k1"), ("key", "body")) == (first, False)
    assert store.figures().finished_total["done"] == 1 and len(store.jobs) == 1


def test_a_repeated_key_with_another_body_is_a_conflict() -> None:
    store = Store(Settings())
    first = make_job(owner="k1")
    store.add(first, ("key", "body-a"))
    conflict = problem_of(lambda: store.add(make_job(owner="k1"), ("key", "body-b")))
    assert (conflict.status, conflict.code) == (409, "idempotency_conflict")
    assert list(store.jobs) == [first.id] and store.queued == 1
    # The earlier job keeps its key: its own body still finds it.
    assert store.add(make_job(owner="k1"), ("key", "body-a")) == (first, False)


def test_idempotency_keys_are_each_owners_own() -> None:
    store = Store(Settings())
    mine, theirs, anonymous = make_job(owner="k1"), make_job(owner="k2"), make_job(owner=None)
    assert store.add(mine, ("key", "body-a"))[1]
    # The same key under other owners: new jobs, whatever their body.
    assert store.add(theirs, ("key", "body-b"))[1]
    assert store.add(anonymous, ("key", "body-a"))[1]
    assert store.add(make_job(owner="k2"), ("key", "body-b")) == (theirs, False)
    assert store.add(make_job(owner=None), ("key", "body-a")) == (anonymous, False)
    assert store.queued == 3


def test_a_key_is_free_again_once_its_results_expire_and_stays_with_the_later_job(
    clock: Clock,
) -> None:
    store = Store(Settings(results_ttl_s=60.0, results_max_count=1, max_queued=1))
    first = make_job()
    store.add(first, ("key", "body-a"))
    run_done(store, first)
    clock.now += 60.0
    # The results are gone: the key names no job any more, another body is no conflict.
    second = make_job()
    assert store.add(second, ("key", "body-b")) == (second, True)
    assert first.expired and first.id in store.jobs  # its record is still there (410)
    run_done(store, second)
    # Records past 10 x 1 + 1 are forgotten, the first job's first: the key stays the second's.
    for _ in range(10):
        filler = make_job()
        store.add(filler)
        store.cancel_queued(filler)
    assert first.id not in store.jobs and second.id in store.jobs
    assert store.add(make_job(), ("key", "body-b")) == (second, False)


# --- owners --------------------------------------------------------------------------------


def test_a_job_is_found_by_its_owner_only() -> None:
    store = Store(Settings())
    mine, anonymous = make_job(owner="k1"), make_job(owner=None)
    store.add(mine)
    store.add(anonymous)
    assert store.get(mine.id, "k1") is mine
    assert store.get(anonymous.id, None) is anonymous
    for job_id, caller in ((mine.id, "k2"), (mine.id, None), (anonymous.id, "k1")):
        problem = problem_of(functools.partial(store.get, job_id, caller))
        # The same answer as for a job that does not exist: nothing tells them apart.
        assert (problem.status, problem.code, problem.extra) == (
            404,
            "job_not_found",
            {"job_id": job_id},
        )
    assert problem_of(lambda: store.get(new_job_id(), "k1")).code == "job_not_found"


def test_another_owner_cannot_reach_a_job_to_cancel_it(local: LocalQueue) -> None:
    async def scenario() -> None:
        job, _ = await local.submit(make_job(owner="k1"), None)
        with pytest.raises(Problem) as raised:
            await local.get(job.id, "k2")  # the route cancels only what get() returns
        assert raised.value.code == "job_not_found"
        assert job.snapshot()["status"] == "queued" and not job.cancel.is_set()
        await local.cancel(await local.get(job.id, "k1"))
        assert job.snapshot()["status"] == "cancelled"

    asyncio.run(scenario())


# --- cancelling ----------------------------------------------------------------------------


def test_a_job_cancelled_while_queued_is_final_at_once_and_never_runs() -> None:
    store = Store(Settings())
    job = make_job()
    store.add(job)
    version = job.version
    store.cancel_queued(job)
    assert (job.status, job.stage) == (Status.CANCELLED, "cancelled")
    assert job.done.is_set() and job.input is None and job.version > version
    assert job.snapshot()["result"] is None and job.started is None
    assert store.queued == 0
    # Its worker reaches it later and passes it over, without counting it out of the queue twice.
    assert store.start(job) is False
    assert (store.queued, store.running) == (0, 0)
    assert job.status is Status.CANCELLED
    figures = store.figures()
    assert figures.finished_total == {"done": 0, "failed": 0, "cancelled": 1}
    assert sum(figures.seconds_buckets) == 0  # it never ran: no duration
    # Cancelling again changes nothing.
    store.cancel_queued(job)
    assert store.queued == 0 and store.figures().finished_total["cancelled"] == 1


def test_a_running_job_is_only_flagged_and_ends_cancelled_when_its_worker_stops() -> None:
    store = Store(Settings())
    job = make_job()
    store.add(job)
    store.start(job)
    store.cancel_queued(job)
    # Still running: the worker stops at its next level.
    assert job.cancel.is_set() and job.status is Status.RUNNING and not job.done.is_set()
    assert (store.queued, store.running) == (0, 1)
    assert store.figures().finished_total["cancelled"] == 0
    store.finish(job, Status.CANCELLED, error={"code": "cancelled", "status": 409})
    assert (job.status, job.stage) == (Status.CANCELLED, "cancelled")
    assert (store.queued, store.running) == (0, 0)
    assert store.figures().finished_total == {"done": 0, "failed": 0, "cancelled": 1}


def test_a_job_not_yet_started_when_cancel_is_flagged_is_cancelled_by_start() -> None:
    """The window between ``cancel.set()`` and the store's lock in ``cancel_queued``."""
    store = Store(Settings())
    job = make_job()
    store.add(job)
    job.cancel.set()  # flagged, the store not told yet
    assert store.start(job) is False
    assert job.status is Status.CANCELLED and job.done.is_set()
    assert (store.queued, store.running) == (0, 0)
    store.cancel_queued(job)  # the rest of that cancel: nothing more happens
    assert store.queued == 0 and store.figures().finished_total["cancelled"] == 1


# --- results: caps and expiry --------------------------------------------------------------


def test_results_expire_after_their_time_to_live(clock: Clock) -> None:
    store = Store(Settings(results_ttl_s=100.0))
    early, late = make_job(owner="k1"), make_job(owner="k1")
    for job in (early, late):
        store.add(job)
    run_done(store, early, png=b"early")
    clock.now += 40.0
    run_done(store, late, png=b"late!")
    clock.now += 59.0  # early is 99 s old
    assert store.get(early.id, "k1").png == b"early" and not early.expired
    clock.now += 1.0  # 100 s: gone (as in Redis, finished at or before now - ttl)
    found = store.get(early.id, "k1")  # the record is still found (410, not 404)
    assert found is early and early.expired and early.png is None
    assert early.snapshot()["result"] is None and early.snapshot()["expired"] is True
    assert not late.expired and late.png == b"late!"
    assert store.figures().kept_bytes == len(b"late!")
    clock.now += 40.0
    store.expire()
    assert late.expired and store.figures().kept_bytes == 0 and store.kept == {}


def test_the_local_queue_serves_results_until_they_expire(local: LocalQueue, clock: Clock) -> None:
    store = local.store
    job, _ = asyncio.run(local.submit(make_job(), None))
    run_done(store, job, png=b"png", layout=b"[]", companions={"normal": b"nrm"})

    async def outputs() -> tuple[bytes | None, ...]:
        found = await local.get(job.id, None)
        return (
            await local.result(found),
            await local.result(found, "normal"),
            await local.layout(found),
        )

    assert asyncio.run(outputs()) == (b"png", b"nrm", b"[]")
    clock.now += local.settings.results_ttl_s
    assert asyncio.run(outputs()) == (None, None, None)
    assert job.expired and job.status is Status.DONE


def test_the_result_count_cap_evicts_the_oldest_results_first() -> None:
    store = Store(Settings(results_max_count=2, max_queued=8))
    jobs = [make_job() for _ in range(3)]
    for job in jobs:
        store.add(job, (f"key-{job.id}", "body"))
    for job in jobs:
        run_done(store, job, png=job.id.encode())
    oldest, *kept = jobs
    assert oldest.expired and oldest.png is None and oldest.status is Status.DONE
    assert [job.expired for job in kept] == [False, False]
    assert list(store.kept) == [job.id for job in kept]
    assert store.figures().kept_bytes == sum(len(job.id) for job in kept)
    # The evicted job's key is free; the others' still find their jobs.
    assert store.add(make_job(), (f"key-{oldest.id}", "other"))[1]
    assert store.add(make_job(), (f"key-{kept[0].id}", "body")) == (kept[0], False)


def test_the_result_bytes_cap_evicts_until_the_rest_fit() -> None:
    store = Store(Settings(results_max_bytes=10, max_queued=8))
    small, medium, big = make_job(), make_job(), make_job()
    for job in (small, medium, big):
        store.add(job)
    run_done(store, small, png=b"s" * 4)
    run_done(store, medium, png=b"m" * 5)
    assert store.figures().kept_bytes == 9 and not small.expired
    run_done(store, big, png=b"b" * 11)  # more than the cap on its own
    assert small.expired and medium.expired and big.expired
    assert store.figures().kept_bytes == 0 and store.kept == {}


def test_records_of_final_jobs_are_forgotten_past_ten_times_the_result_cap() -> None:
    store = Store(Settings(results_max_count=1, max_queued=2))
    limit = 10 * 1 + 2
    jobs = []
    for n in range(limit + 3):
        job = make_job()
        store.add(job, (f"key-{n}", "body"))
        store.cancel_queued(job)
        jobs.append(job)
    assert len(store.jobs) == limit
    assert list(store.jobs) == [job.id for job in jobs[-limit:]]  # the oldest went first
    forgotten = jobs[0]
    assert problem_of(lambda: store.get(forgotten.id, None)).code == "job_not_found"
    # Its key went with it: the same key with another body is a new job.
    assert store.add(make_job(), ("key-0", "other"))[1]
    assert store.add(make_job(), (f"key-{limit + 2}", "body")) == (jobs[-1], False)
    # Queued jobs take no final record's place (as in the Redis store): still `limit` of them.
    assert store.figures().counts["cancelled"] == limit


def test_a_job_still_running_holds_no_record_back() -> None:
    # The records forgotten are the final ones that ended first, whatever is still running:
    # the oldest job running does not keep every later record alive.
    store = Store(Settings(results_max_count=1, max_queued=1))
    limit = 10 * 1 + 1
    first = make_job()
    store.add(first)
    assert store.start(first)
    later = []
    for _ in range(30):
        job = make_job()
        store.add(job)
        run_done(store, job)
        later.append(job)
    assert len(store.jobs) == limit + 1 and first.id in store.jobs
    assert list(store.records) == [job.id for job in later[-limit:]]
    store.finish(first, Status.FAILED, error={"code": "x"})
    assert len(store.jobs) == limit and list(store.records)[-1] == first.id


# --- figures -------------------------------------------------------------------------------


def test_durations_fall_in_the_histogram_buckets_as_redis_counts_them(clock: Clock) -> None:
    store = Store(Settings(max_queued=8))
    clock.now = 0.0  # durations below are exact differences from 0
    last = HISTOGRAM_BUCKETS[-1]
    durations = [0.0, HISTOGRAM_BUCKETS[0], 0.06, last, last + 1.0]
    for seconds in durations:
        job = make_job()
        store.add(job)
        clock.now = 0.0
        store.start(job)
        clock.now = seconds
        store.finish(job, Status.DONE, png=b"x")
    never_ran = make_job()
    store.add(never_ran)
    store.cancel_queued(never_ran)
    figures = store.figures()
    expected = [0] * (len(HISTOGRAM_BUCKETS) + 1)
    # A duration equal to a bound is in that bound's bucket (le=), past the last one overflows.
    for bucket in (0, 0, 1, len(HISTOGRAM_BUCKETS) - 1, len(HISTOGRAM_BUCKETS)):
        expected[bucket] += 1
    assert figures.seconds_buckets == expected
    assert figures.seconds_sum == pytest.approx(sum(durations))
    assert figures.finished_total == {"done": 5, "failed": 0, "cancelled": 1}


# --- versions and waiters ------------------------------------------------------------------


def test_every_change_of_a_job_raises_its_version_and_progress_reads_in_order() -> None:
    store = Store(Settings(results_max_count=1, max_queued=4))
    job = make_job()
    store.add(job)
    seen = [(job.version, job.status, job.progress, job.stage)]

    def look() -> None:
        seen.append((job.version, job.status, job.progress, job.stage))

    store.start(job)
    look()
    for level, fraction in enumerate((0.25, 0.5, 0.75), start=1):
        store.update(job, progress=fraction, stage=f"level {level}")
        look()
    store.finish(job, Status.DONE, png=b"x")
    look()
    other = make_job()
    store.add(other)
    run_done(store, other)  # evicts the job's results (cap 1): a change too
    look()
    versions = [version for version, *_ in seen]
    assert versions == sorted(set(versions)), versions  # strictly increasing
    assert [(status, progress, stage) for _, status, progress, stage in seen] == [
        (Status.QUEUED, 0.0, "queued"),
        (Status.RUNNING, 0.0, "decoding"),
        (Status.RUNNING, 0.25, "level 1"),
        (Status.RUNNING, 0.5, "level 2"),
        (Status.RUNNING, 0.75, "level 3"),
        (Status.DONE, 1.0, "done"),
        (Status.DONE, 1.0, "done"),
    ]
    assert job.expired


def test_on_done_wakes_once_when_the_job_ends_or_at_once_if_it_has() -> None:
    store = Store(Settings())
    job = make_job()
    store.add(job)
    woken: list[str] = []
    store.on_done(job, lambda: woken.append("early"))
    store.start(job)
    store.update(job, progress=0.5)
    assert woken == []
    store.finish(job, Status.FAILED, error={"code": "x"})
    assert woken == ["early"] and job.waiters == []
    store.on_done(job, lambda: woken.append("late"))
    assert woken == ["early", "late"] and job.waiters == []


def test_wait_returns_as_soon_as_a_worker_thread_finishes_the_job(
    local: LocalQueue, monkeypatch: pytest.MonkeyPatch
) -> None:
    async def scenario() -> Job:
        job, _ = await local.submit(make_job(), None)
        local.store.start(job)
        registered = threading.Event()
        real = local.store.on_done

        def on_done(watched: Job, wake: Callable[[], object]) -> None:
            real(watched, wake)
            registered.set()

        monkeypatch.setattr(local.store, "on_done", on_done)

        def worker() -> None:
            assert registered.wait(10)  # the waiter is registered: finish now
            local.store.finish(job, Status.DONE, png=b"x")

        thread = threading.Thread(target=worker)
        thread.start()
        # A long limit: returning at all before it means the worker woke the waiter.
        found = await asyncio.wait_for(local.wait(job, 60.0), 10.0)
        thread.join(10)
        return found

    job = asyncio.run(scenario())
    assert job.status is Status.DONE


def test_wait_on_an_unfinished_job_returns_it_unfinished_after_its_limit(
    local: LocalQueue,
) -> None:
    async def scenario() -> Job:
        job, _ = await local.submit(make_job(), None)
        for _ in range(5):  # a client polling a long job with ?wait=
            await local.wait(job, 0.001)
        return job

    job = asyncio.run(scenario())
    assert job.status is Status.QUEUED and not job.done.is_set()
    assert job.waiters == []  # each timed-out wait took its wake-up back


def test_a_job_finished_twice_is_finished_once() -> None:
    store = Store(Settings())
    job = make_job()
    store.add(job)
    assert store.start(job)
    before = store.figures().counts
    store.finish(job, Status.DONE, png=b"png")
    store.finish(job, Status.FAILED, error={"code": "late"})
    assert job.status is Status.DONE and job.error is None
    assert store.running == 0 and store.figures().counts["done"] == 1
    assert store.figures().counts.get("failed", 0) == before.get("failed", 0)


# --- the local queue and its runner --------------------------------------------------------


def test_the_local_queue_hands_each_new_job_to_its_runner_once_in_order(
    local: LocalQueue,
) -> None:
    async def scenario() -> list[Job]:
        jobs = []
        for n in range(3):
            job, created = await local.submit(make_job(), (f"key-{n}", "body"))
            assert created
            jobs.append(job)
        repeat, created = await local.submit(make_job(), ("key-1", "body"))
        assert (repeat, created) == (jobs[1], False)
        return jobs

    jobs = asyncio.run(scenario())
    handed = [local.runner.queue.get_nowait() for _ in range(local.runner.queue.qsize())]
    assert handed == jobs
    assert local.busy()


def test_stopping_the_local_queue_fails_the_queued_jobs_with_shutdown(local: LocalQueue) -> None:
    async def scenario() -> tuple[Job, Job]:
        waiting, _ = await local.submit(make_job(), None)
        cancelled, _ = await local.submit(make_job(), None)
        await local.cancel(cancelled)
        assert local.busy()
        await local.stop(0)
        return waiting, cancelled

    waiting, cancelled = asyncio.run(scenario())
    assert waiting.status is Status.FAILED and waiting.done.is_set()
    assert waiting.error is not None and waiting.error["code"] == "shutdown"
    assert waiting.error["status"] == 503
    assert cancelled.status is Status.CANCELLED and cancelled.error is None
    assert not local.busy()
    assert local.store.figures().finished_total == {"done": 0, "failed": 1, "cancelled": 1}


# --- many threads at once ------------------------------------------------------------------


def test_concurrent_submissions_and_workers_lose_no_job_and_count_each_once() -> None:
    total = THREADS * PER_THREAD
    store = Store(Settings(max_queued=total, results_max_count=total))

    def submit(index: int) -> list[Job]:
        jobs = [make_job(owner=f"k{index}") for _ in range(PER_THREAD)]
        for job in jobs:
            assert store.add(job) == (job, True)
        return jobs

    submitted = [job for jobs in together(THREADS, submit) for job in jobs]
    assert len({job.id for job in submitted}) == total
    assert set(store.jobs) == {job.id for job in submitted}
    assert (store.queued, store.running) == (total, 0)

    # As many workers finish them, each taking every THREADS-th job.
    def work(index: int) -> int:
        mine = submitted[index::THREADS]
        for job in mine:
            assert store.start(job)
            store.update(job, progress=0.5, stage="level 1")
            store.finish(job, Status.DONE, png=job.id.encode())
        return len(mine)

    assert sum(together(THREADS, work)) == total
    figures = store.figures()
    assert (figures.queued, figures.running) == (0, 0)
    assert figures.finished_total == {"done": total, "failed": 0, "cancelled": 0}
    assert figures.counts["done"] == total
    assert figures.kept_bytes == sum(len(job.id) for job in submitted)
    assert figures.pixels_total == total * 8 * 4
    assert all(job.png == job.id.encode() for job in submitted)
    for job in submitted:
        assert store.get(job.id, job.owner) is job


def test_concurrent_submissions_at_the_cap_admit_exactly_the_cap() -> None:
    cap = 13
    store = Store(Settings(max_queued=cap))

    def submit(_: int) -> tuple[int, int]:
        admitted = refused = 0
        for _ in range(PER_THREAD):
            try:
                store.add(make_job())
                admitted += 1
            except Problem as problem:
                assert problem.code == "queue_full"
                refused += 1
        return admitted, refused

    results = together(THREADS, submit)
    assert sum(admitted for admitted, _ in results) == cap
    assert sum(refused for _, refused in results) == THREADS * PER_THREAD - cap
    assert store.queued == cap and len(store.jobs) == cap


def test_concurrent_repeats_of_one_key_make_one_job() -> None:
    store = Store(Settings(max_queued=THREADS))

    def submit(_: int) -> list[tuple[str, bool]]:
        answers = []
        for _ in range(PER_THREAD):
            job, created = store.add(make_job(owner="k1"), ("same-key", "body"))
            answers.append((job.id, created))
        return answers

    answers = [answer for part in together(THREADS, submit) for answer in part]
    assert len(answers) == THREADS * PER_THREAD
    assert len({job_id for job_id, _ in answers}) == 1
    assert sum(created for _, created in answers) == 1
    assert len(store.jobs) == 1 and store.queued == 1


def test_a_cancel_racing_the_start_leaves_every_job_counted_once() -> None:
    rounds = 200
    store = Store(Settings(max_queued=rounds))
    jobs = [make_job() for _ in range(rounds)]
    for job in jobs:
        store.add(job)
    started = [False] * rounds

    def race(index: int) -> None:
        for n, job in enumerate(jobs):
            if index == 0:
                started[n] = store.start(job)
            else:
                store.cancel_queued(job)

    together(2, race)
    ran = [job for job, yes in zip(jobs, started, strict=True) if yes]
    skipped = [job for job, yes in zip(jobs, started, strict=True) if not yes]
    assert all(job.status is Status.RUNNING and job.cancel.is_set() for job in ran)
    assert all(job.status is Status.CANCELLED and job.done.is_set() for job in skipped)
    figures = store.figures()
    assert (figures.queued, figures.running) == (0, len(ran))
    assert figures.finished_total["cancelled"] == len(skipped)
    for job in ran:  # their workers see the flag and stop
        store.finish(job, Status.CANCELLED)
    figures = store.figures()
    assert (figures.queued, figures.running) == (0, 0)
    assert figures.finished_total["cancelled"] == rounds
