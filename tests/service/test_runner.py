"""The worker process's message loop: a cancel that arrives at any moment never kills a worker.

The loop (:func:`quilting.service.jobs.worker.process_main`) runs in a thread here, over a real
``multiprocessing`` pipe, so that each timing of a cancel is forced rather than hoped for:
before the job starts, while it runs, after its last progress report, after it ended, after
it failed, and a cancel of another job.
"""

from __future__ import annotations

import threading
from collections.abc import Generator
from multiprocessing import Pipe
from typing import Any

import numpy as np
import pytest

import quilting
from quilting.io import encode_png
from quilting.service.jobs import JobInput, Status
from quilting.service.jobs.worker import process_main

#: Generous: a 2-core machine under load still answers well inside it.
TIMEOUT_S = 60.0


def _texture() -> np.ndarray:
    rng = np.random.default_rng(3)
    return (rng.random((40, 40)) * 255).astype(np.uint8)


def _spec(size: int = 64, **options: Any) -> JobInput:
    return JobInput(
        texture=encode_png(_texture()),
        companions={},
        options={"block": 16, "seed": 5, **options},
        width=size,
        height=size,
    )


class Worker:
    """The worker loop on one end of a pipe; the test plays the pump on the other."""

    def __init__(self) -> None:
        self.conn, theirs = Pipe()
        self.thread = threading.Thread(target=process_main, args=(theirs,), daemon=True)
        self.thread.start()

    def send(self, message: Any) -> None:
        self.conn.send(message)

    def receive(self) -> Any:
        assert self.conn.poll(TIMEOUT_S), "the worker said nothing"
        return self.conn.recv()

    def end(self) -> tuple[Status, dict[str, Any], int]:
        """Read up to the job's end message: its status, fields and progress reports."""
        reports = 0
        while (message := self.receive())[0] == "progress":
            reports += 1
        kind, status, fields = message
        assert kind == "end"
        return Status(status), fields, reports

    def run(self, job_id: str, spec: JobInput) -> tuple[Status, dict[str, Any], int]:
        self.send(("job", job_id, spec, TIMEOUT_S))
        return self.end()


@pytest.fixture
def worker() -> Generator[Worker, None, None]:
    worker = Worker()
    yield worker
    worker.send(None)
    worker.thread.join(TIMEOUT_S)
    assert not worker.thread.is_alive(), "the worker loop did not stop"


def _expected_png(spec: JobInput) -> np.ndarray:
    return quilting.synthesize(_texture(), (spec.height, spec.width), **spec.options).image


def _assert_done_with_the_engines_pixels(
    result: tuple[Status, dict[str, Any], int], spec: JobInput
) -> None:
    status, fields, _ = result
    assert status == Status.DONE, fields
    np.testing.assert_array_equal(quilting.read_image(fields["png"]), _expected_png(spec))


def test_a_cancel_after_the_last_progress_report_is_dropped(worker: Worker) -> None:
    first = _spec(seed=1)
    status, _, reports = worker.run("a", first)
    assert status == Status.DONE and reports > 0
    # The pump saw the job cancelled only now, after the worker's last check: the cancel
    # waits in the pipe where the next job is expected.
    worker.send(("cancel", "a"))
    second = _spec(seed=2)
    _assert_done_with_the_engines_pixels(worker.run("b", second), second)
    assert worker.thread.is_alive()


def test_several_late_cancels_and_a_failed_job_leave_the_next_job_alone(worker: Worker) -> None:
    failed = worker.run("bad", _spec(block=999))  # larger than the texture: the job fails
    assert failed[0] == Status.FAILED and failed[1]["error"]["code"] != "internal_error"
    for _ in range(3):
        worker.send(("cancel", "bad"))
    spec = _spec(seed=3)
    _assert_done_with_the_engines_pixels(worker.run("next", spec), spec)


def test_a_cancel_sent_with_the_job_stops_it(worker: Worker) -> None:
    # Sent before the worker's first progress check: the job ends cancelled, at once.
    worker.send(("job", "c", _spec(size=2048), TIMEOUT_S))
    worker.send(("cancel", "c"))
    status, fields, _ = worker.end()
    assert status == Status.CANCELLED and fields == {}
    spec = _spec(seed=4)
    _assert_done_with_the_engines_pixels(worker.run("d", spec), spec)


def test_a_cancel_while_running_stops_it_after_a_report(worker: Worker) -> None:
    worker.send(("job", "e", _spec(size=2048), TIMEOUT_S))
    assert worker.receive()[0] == "progress"  # it is running
    worker.send(("cancel", "e"))
    status, _, _ = worker.end()
    assert status == Status.CANCELLED


def test_a_cancel_of_another_job_does_not_stop_this_one(worker: Worker) -> None:
    spec = _spec(seed=6)
    worker.send(("job", "f", spec, TIMEOUT_S))
    worker.send(("cancel", "someone-else"))
    _assert_done_with_the_engines_pixels(worker.end(), spec)
