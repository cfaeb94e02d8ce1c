"""Unit tests of :mod:`quilting.service.jobs.pool`: the :class:`Runner` that feeds the in-memory
store's jobs to worker threads or processes.

Covers
------
- thread workers run real jobs to ``done`` with the engine's pixels, relaying each job's
  progress to the store up to the encoding at 1;
- the queue is first in, first out; as many jobs run at once as there are workers, never more;
  hundreds of jobs submitted at once all end ``done``, each computed exactly once, with its own
  result (exact counts);
- a job cancelled while queued is passed over without being computed; one cancelled while
  running stops and ends ``cancelled``, and its worker takes the next job;
- a job past ``job_timeout_s`` fails with ``job_timeout``; one predicted past
  ``job_memory_bytes`` fails with ``job_too_large`` before any work;
- an exception inside a job fails that job alone with a 500 ``internal_error`` problem that
  holds no stack trace (the trace goes to the log), and the worker goes on;
- :meth:`Runner.stop` fails the queued jobs with ``shutdown`` at once and lets the running one
  finish; its worker threads exit;
- one process-mode case (worker processes are slow to start): real jobs relayed through the
  pump, a running job cancelled across the pipe, and no worker process left after ``stop``.

The process-mode shutdown past its grace and the memory cap of a worker process are tested in
``test_hostile.py`` and ``test_hostile_uploads.py``; a killed worker in ``test_workers.py``.
Jobs that must block are a stand-in for :func:`~quilting.service.jobs.worker.compute` waiting
on :mod:`threading` events; nothing waits on a fixed sleep.
"""

from __future__ import annotations

import json
import logging
import threading
from collections import Counter
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest

import quilting
from quilting.io import encode_png, read_image
from quilting.service.jobs import Job, JobInput, Status, new_job_id
from quilting.service.jobs import pool as pool_module
from quilting.service.jobs import results as results_module
from quilting.service.jobs import worker as worker_module
from quilting.service.jobs.memory import Store
from quilting.service.jobs.pool import Runner
from quilting.service.settings import Settings

#: Bound of every wait: generous, it only bounds a failing test on a loaded 2-core machine.
WAIT_S = 60.0

Compute = Callable[..., tuple[Status, dict[str, Any]]]


def _texture() -> np.ndarray:
    rng = np.random.default_rng(7)
    return (rng.random((32, 32, 3)) * 255).astype(np.uint8)


def _input(seed: int, size: int = 32) -> JobInput:
    return JobInput(encode_png(_texture()), {}, {"block": 8, "seed": seed}, size, size)


def _engine(seed: int, size: int = 32) -> np.ndarray:
    return quilting.synthesize(_texture(), (size, size), block=8, seed=seed).image


class Book(Store):
    """The in-memory store, keeping every progress update the runner writes."""

    def __init__(self, settings: Settings) -> None:
        super().__init__(settings)
        self.updates: dict[str, list[tuple[float, str]]] = {}
        self.progressed = threading.Event()  # a job reported progress past 0

    def update(self, job: Job, **changes: Any) -> None:
        super().update(job, **changes)
        if "progress" in changes:
            self.updates.setdefault(job.id, []).append((changes["progress"], changes["stage"]))
            if changes["progress"] > 0:
                self.progressed.set()


class Pool:
    """A started runner over a :class:`Book`, and the gates its blocked jobs wait on."""

    def __init__(self, **settings: Any) -> None:
        values = {"worker_mode": "thread", "workers": 1, "max_queued": 1000, **settings}
        self.store = Book(Settings(results_max_count=1000, **values))
        self.runner = Runner(self.store, self.store.settings)
        self.gates: list[threading.Event] = []
        self.runner.start()

    def submit(self, spec: JobInput) -> Job:
        """Queue a job as :class:`~quilting.service.jobs.memory.LocalQueue` does."""
        job = Job(
            id=new_job_id(),
            owner=None,
            width=spec.width,
            height=spec.height,
            companion_names=list(spec.companions),
            input=spec,
        )
        self.store.add(job)
        self.runner.submit(job)
        return job

    def gate(self) -> threading.Event:
        gate = threading.Event()
        self.gates.append(gate)
        return gate

    def close(self) -> None:
        for gate in self.gates:
            gate.set()
        self.runner.stop(timeout=WAIT_S)


@pytest.fixture
def pools() -> Iterator[Callable[..., Pool]]:
    """Make started pools; each is stopped (its gates opened first) at the end."""
    made: list[Pool] = []

    def make(**settings: Any) -> Pool:
        made.append(Pool(**settings))
        return made[-1]

    yield make
    for pool in made:
        pool.close()


def _finished(job: Job) -> Job:
    assert job.done.wait(WAIT_S), job.snapshot()
    return job


def _seed(spec: JobInput) -> int:
    return int(spec.options["seed"])


def _stand_in(
    monkeypatch: pytest.MonkeyPatch,
    block: Callable[[int], object] = lambda seed: None,
) -> list[int]:
    """Replace the worker's ``compute`` with one that calls ``block(seed)``, then ends the job
    ``done`` with the seed as its PNG; returns the seeds computed, in order."""
    seen: list[int] = []
    lock = threading.Lock()

    def compute(spec: JobInput, *args: Any, **kwargs: Any) -> tuple[Status, dict[str, Any]]:
        seed = _seed(spec)
        with lock:
            seen.append(seed)
        block(seed)
        return Status.DONE, {"png": f"seed {seed}".encode(), "layout": None}

    monkeypatch.setattr(pool_module, "compute", compute)
    return seen


# --- real jobs --------------------------------------------------------------------------------


def test_thread_workers_run_real_jobs_to_done_with_the_engines_pixels(
    pools: Callable[..., Pool],
) -> None:
    pool = pools(workers=2)
    jobs = {seed: pool.submit(_input(seed)) for seed in (1, 2, 3)}
    for seed, job in jobs.items():
        _finished(job)
        assert job.status is Status.DONE and job.error is None, job.snapshot()
        assert (job.progress, job.stage) == (1.0, "done")
        assert job.png is not None and job.has_layout and job.input is None
        np.testing.assert_array_equal(read_image(job.png), _engine(seed))
        updates = pool.store.updates[job.id]
        fractions = [fraction for fraction, _ in updates]
        assert fractions == sorted(fractions) and fractions[0] > 0
        assert updates[-1] == (1.0, "encoding")
    figures = pool.store.figures()
    assert figures.finished_total == {"done": 3, "failed": 0, "cancelled": 0}
    assert (figures.queued, figures.running) == (0, 0)


# --- the queue ------------------------------------------------------------------------------


def test_one_worker_takes_the_jobs_in_the_order_they_came(
    pools: Callable[..., Pool], monkeypatch: pytest.MonkeyPatch
) -> None:
    pool = pools(workers=1)
    first, entered = pool.gate(), threading.Event()

    def block(seed: int) -> None:
        if seed == 0:
            entered.set()
            first.wait(WAIT_S)

    seen = _stand_in(monkeypatch, block)
    jobs = [pool.submit(_input(seed)) for seed in (0, 5, 3, 9, 1, 7)]
    assert entered.wait(WAIT_S)
    assert pool.store.queued == 5  # the first one runs, held at its gate
    first.set()
    for job in jobs:
        assert _finished(job).status is Status.DONE
    assert seen == [0, 5, 3, 9, 1, 7]


def test_as_many_jobs_run_at_once_as_there_are_workers(
    pools: Callable[..., Pool], monkeypatch: pytest.MonkeyPatch
) -> None:
    workers = 3
    pool = pools(workers=workers)
    lock = threading.Lock()
    running, peak = [0], [0]
    threads: set[int] = set()
    # Each job waits for the two others of its round: three must run at once.
    together = threading.Barrier(workers, timeout=WAIT_S)

    def block(seed: int) -> None:
        with lock:
            running[0] += 1
            peak[0] = max(peak[0], running[0])
            threads.add(threading.get_ident())
        together.wait()
        with lock:
            running[0] -= 1

    _stand_in(monkeypatch, block)
    jobs = [pool.submit(_input(seed)) for seed in range(2 * workers)]
    for job in jobs:
        assert _finished(job).status is Status.DONE, job.snapshot()
    assert peak[0] == workers
    assert not together.broken
    # The jobs ran on the pool's threads, and it has one per worker.
    assert len(pool.runner.threads) == workers
    assert threads == {thread.ident for thread in pool.runner.threads}


def test_hundreds_of_jobs_are_each_computed_once_and_none_is_lost(
    pools: Callable[..., Pool], monkeypatch: pytest.MonkeyPatch
) -> None:
    count = 400
    pool = pools(workers=4)
    seen = _stand_in(monkeypatch)
    jobs = [pool.submit(_input(seed)) for seed in range(count)]
    for job in jobs:
        _finished(job)
    assert Counter(seen) == Counter(range(count))  # each exactly once
    for seed, job in enumerate(jobs):
        assert job.status is Status.DONE and job.png == f"seed {seed}".encode()
    figures = pool.store.figures()
    assert figures.finished_total["done"] == count
    assert figures.counts["done"] == count
    assert (figures.queued, figures.running) == (0, 0)


# --- cancellation ---------------------------------------------------------------------------


def test_a_job_cancelled_while_queued_is_never_computed(
    pools: Callable[..., Pool], monkeypatch: pytest.MonkeyPatch
) -> None:
    pool = pools(workers=1)
    first = pool.gate()
    seen = _stand_in(monkeypatch, lambda seed: first.wait(WAIT_S) if seed == 1 else None)
    held, cancelled, last = (pool.submit(_input(seed)) for seed in (1, 2, 3))
    pool.store.cancel_queued(cancelled)
    assert _finished(cancelled).status is Status.CANCELLED  # at once, while the worker is busy
    first.set()
    assert _finished(held).status is Status.DONE
    assert _finished(last).status is Status.DONE
    assert seen == [1, 3]
    assert pool.store.figures().finished_total == {"done": 2, "failed": 0, "cancelled": 1}


def test_a_running_job_cancelled_stops_and_its_worker_takes_the_next(
    pools: Callable[..., Pool],
) -> None:
    pool = pools(workers=1)
    # Seconds of work: it reports progress long before it could end.
    long = pool.submit(_input(1, size=2048))
    assert pool.store.progressed.wait(WAIT_S), long.snapshot()
    assert long.status is Status.RUNNING
    pool.store.cancel_queued(long)
    assert _finished(long).status is Status.CANCELLED
    assert long.stage == "cancelled"
    assert long.png is None and long.error is None and long.progress < 1.0
    after = _finished(pool.submit(_input(2)))
    assert after.status is Status.DONE
    assert after.png is not None
    np.testing.assert_array_equal(read_image(after.png), _engine(2))


# --- failures -------------------------------------------------------------------------------


def test_a_job_past_its_time_limit_fails_job_timeout(pools: Callable[..., Pool]) -> None:
    pool = pools(workers=1, job_timeout_s=0.1)
    job = _finished(pool.submit(_input(1, size=2048)))
    assert job.status is Status.FAILED and job.png is None, job.snapshot()
    assert job.error is not None
    assert (job.error["status"], job.error["code"]) == (504, "job_timeout")
    assert "job_timeout_s" in job.error["detail"]
    assert job.started is not None and job.finished is not None
    assert job.finished - job.started >= 0.1


def test_a_job_past_the_memory_budget_fails_job_too_large_before_any_work(
    pools: Callable[..., Pool],
) -> None:
    pool = pools(workers=1, job_memory_bytes=4096)
    assert pool.runner.memory_budget == 4096
    job = _finished(pool.submit(_input(1, size=64)))
    assert job.status is Status.FAILED, job.snapshot()
    assert job.error is not None
    assert (job.error["status"], job.error["code"]) == (422, "job_too_large")
    assert "job_memory_bytes" in job.error["detail"]
    assert job.id not in pool.store.updates  # no progress: refused before the engine ran


def test_an_exception_inside_a_job_fails_it_alone_without_a_stack_trace(
    pools: Callable[..., Pool],
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
) -> None:
    real = results_module.result_fields

    def result_fields(spec: JobInput, *args: Any) -> dict[str, Any]:
        if _seed(spec) == 13:
            raise RuntimeError("secret-detail at /srv/quilting/private.py")
        return real(spec, *args)

    # The name the worker calls the engine by, inside compute().
    monkeypatch.setattr(worker_module, "result_fields", result_fields)
    pool = pools(workers=1)
    with caplog.at_level(logging.ERROR, logger="quilting.service"):
        bad = _finished(pool.submit(_input(13)))
        good = _finished(pool.submit(_input(4)))
    assert bad.status is Status.FAILED and bad.png is None
    assert bad.error is not None
    assert (bad.error["status"], bad.error["code"]) == (500, "internal_error")
    assert bad.error["detail"] == "the job failed unexpectedly"
    text = json.dumps(bad.error)
    for leak in ("Traceback", "RuntimeError", "secret-detail", "private.py"):
        assert leak not in text, text
    # The trace is the log's.
    assert any(record.exc_info and bad.id in record.getMessage() for record in caplog.records)
    assert good.status is Status.DONE and good.png is not None
    np.testing.assert_array_equal(read_image(good.png), _engine(4))


# --- shutdown -------------------------------------------------------------------------------


def test_stop_fails_the_queued_jobs_and_lets_the_running_one_finish(
    pools: Callable[..., Pool], monkeypatch: pytest.MonkeyPatch
) -> None:
    pool = pools(workers=1)
    gate, entered = pool.gate(), threading.Event()

    def block(seed: int) -> None:
        if seed == 1:
            entered.set()
            gate.wait(WAIT_S)

    seen = _stand_in(monkeypatch, block)
    running = pool.submit(_input(1))
    queued = [pool.submit(_input(seed)) for seed in (2, 3, 4)]
    assert entered.wait(WAIT_S)
    stopper = threading.Thread(target=pool.runner.stop)  # no timeout: waits for the job
    stopper.start()
    for job in queued:
        _finished(job)
        assert job.status is Status.FAILED and job.error is not None, job.snapshot()
        assert (job.error["status"], job.error["code"]) == (503, "shutdown")
    assert running.status is Status.RUNNING and stopper.is_alive()
    gate.set()
    stopper.join(WAIT_S)
    assert not stopper.is_alive()
    assert _finished(running).status is Status.DONE
    assert seen == [1]
    assert not any(thread.is_alive() for thread in pool.runner.threads)
    figures = pool.store.figures()
    assert figures.finished_total == {"done": 1, "failed": 3, "cancelled": 0}
    assert (figures.queued, figures.running) == (0, 0)


def test_stop_past_its_timeout_returns_and_a_thread_job_still_ends(
    pools: Callable[..., Pool], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A thread cannot be stopped: stop() returns after its timeout, the job finishes later."""
    pool = pools(workers=1)
    gate, entered = pool.gate(), threading.Event()

    def block(seed: int) -> None:
        entered.set()
        gate.wait(WAIT_S)

    _stand_in(monkeypatch, block)
    running = pool.submit(_input(1))
    assert entered.wait(WAIT_S)
    pool.runner.stop(timeout=0.05)
    assert pool.runner.stopping.is_set()
    assert running.status is Status.RUNNING
    gate.set()
    assert _finished(running).status is Status.DONE


# --- worker processes -----------------------------------------------------------------------


def test_worker_processes_relay_progress_and_cancels_and_are_gone_after_stop(
    pools: Callable[..., Pool],
) -> None:
    """The one process-mode case (a worker process takes a second or more to start)."""
    pool = pools(workers=1, worker_mode="process")
    long = pool.submit(_input(1, size=2048))
    assert pool.store.progressed.wait(WAIT_S), long.snapshot()
    pool.store.cancel_queued(long)  # the pump sends the cancel down the pipe
    assert _finished(long).status is Status.CANCELLED, long.snapshot()
    job = _finished(pool.submit(_input(5)))
    assert job.status is Status.DONE, job.snapshot()
    assert job.png is not None
    np.testing.assert_array_equal(read_image(job.png), _engine(5))
    assert pool.store.updates[job.id][-1] == (1.0, "encoding")
    processes = list(pool.runner._alive.values())
    assert len(processes) == 1 and processes[0].is_alive()
    pool.runner.stop(timeout=WAIT_S)
    assert not processes[0].is_alive()
    assert pool.runner._alive == {}
