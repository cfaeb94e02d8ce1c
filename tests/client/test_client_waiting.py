"""Waiting for a job (``quilting_client._waiting``), driven by hand without any I/O.

Covers
------
- :class:`Deadline` and :func:`check_interval` on a fake monotonic clock;
- :func:`raise_unless_done`: the final status of a job that ended well, the typed error of one
  that did not;
- polling (:func:`follow` without a progress callback): the first delay, the poll interval as
  a floor under ``Retry-After``, sleeps clipped to the deadline, :class:`WaitTimeoutError` at
  the deadline naming the job, terminal statuses ending the wait;
- following the event stream (:func:`follow` with a progress callback): fractions handed on in
  order and completed to 1.0, a raising callback stopping the wait, terminal events, garbled
  events, streams that end early, go silent or stay busy past the deadline.

The flows are generators of actions (:mod:`quilting_client._actions`); the :class:`Driver`
below answers them from a script and advances a fake clock on ``Sleep`` (nothing sleeps).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import httpx
import pytest
from client_fakes import BASE, FAILED, FakeClock, job_json

from quilting_client import _actions as actions
from quilting_client import _flows as flows
from quilting_client import _protocol as proto
from quilting_client import _waiting as waiting
from quilting_client._events import ServerEvent
from quilting_client._waiting import Deadline, follow
from quilting_client.errors import (
    ConnectionFailedError,
    JobCancelledError,
    JobFailedError,
    NotFoundError,
    QuiltingClientError,
    WaitTimeoutError,
)
from quilting_client.models import JobStatus

START = 1000.0


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> FakeClock:
    """The clock of ``_waiting`` (its deadlines), replaced by a fake one."""
    fake = FakeClock(START)
    monkeypatch.setattr(waiting, "time", SimpleNamespace(monotonic=fake.monotonic))
    return fake


def status(state: str, job_id: str = "j1", retry_after: str | None = None) -> httpx.Response:
    """A ``GET /jobs/{id}`` answer."""
    headers = {"Retry-After": retry_after} if retry_after is not None else {}
    request = httpx.Request("GET", f"{BASE}/jobs/{job_id}")
    return httpx.Response(200, json=job_json(state, job_id), headers=headers, request=request)


def progress_event(fraction: object, stage: str = "quilting") -> ServerEvent:
    return ServerEvent("progress", {"progress": fraction, "stage": stage, "status": "running"})


def terminal_event(state: str, **extra: Any) -> ServerEvent:
    data = FAILED if state == "failed" else job_json(state, **extra)
    return ServerEvent(state, data)


@dataclass
class FakeStream:
    """An open event stream: its events, then None; each read may take some (fake) time."""

    events: list[ServerEvent]
    seconds_per_event: float = 0.0
    closed: bool = False
    read: int = 0


#: A stream script entry: the events of one connection, or the error opening it raises.
StreamScript = list[ServerEvent] | FakeStream | QuiltingClientError


@dataclass
class Driver:
    """Performs a flow's actions from a script, on a fake clock, recording what it did.

    ``statuses`` answer the ``Send``s in turn (the last one repeats); ``streams`` answer the
    ``OpenStream``s in turn. A ``Sleep`` advances the clock by its seconds.
    """

    clock: FakeClock
    statuses: Sequence[httpx.Response] = ()
    streams: Sequence[StreamScript] = ()
    log: list[tuple[float, actions.Action]] = field(default_factory=list)
    opened: list[FakeStream] = field(default_factory=list)
    _sent: int = 0

    def run(self, flow: actions.Flow[Any]) -> Any:
        with actions.Steps(flow) as steps:
            for action in steps:
                self.log.append((self.clock.now, action))
                with steps.catching():
                    steps.reply = self.perform(action)
        return steps.result

    def perform(self, action: actions.Action) -> object:
        match action:
            case actions.Sleep(seconds):
                assert seconds > 0, "a flow must not yield a sleep of nothing"
                self.clock.now += seconds
            case actions.Send(spec):
                assert spec == proto.job_request("j1"), spec
                answer = self.statuses[min(self._sent, len(self.statuses) - 1)]
                self._sent += 1
                assert len(self.log) < 1000, "runaway flow"
                return answer
            case actions.OpenStream(spec, _):
                assert spec == proto.events_request("j1"), spec
                script = self.streams[len(self.opened)]
                if isinstance(script, QuiltingClientError):
                    self.opened.append(FakeStream([], closed=True))
                    raise script
                stream = script if isinstance(script, FakeStream) else FakeStream(list(script))
                self.opened.append(stream)
                return stream
            case actions.NextEvent(stream):
                assert isinstance(stream, FakeStream) and not stream.closed
                if stream.read >= len(stream.events):
                    return None
                stream.read += 1
                self.clock.now += stream.seconds_per_event
                return stream.events[stream.read - 1]
            case actions.CloseStream(stream):
                assert isinstance(stream, FakeStream)
                stream.closed = True
        return None

    @property
    def sleeps(self) -> list[float]:
        return [a.seconds for _, a in self.log if isinstance(a, actions.Sleep)]

    def kinds(self) -> list[str]:
        return [type(a).__name__ for _, a in self.log]

    def times_of(self, kind: type) -> list[float]:
        return [t - START for t, a in self.log if isinstance(a, kind)]

    def limits(self) -> list[float | None]:
        return [a.limit for _, a in self.log if isinstance(a, actions.OpenStream)]


class Recorder:
    """A progress callback that records its calls."""

    def __init__(self) -> None:
        self.calls: list[tuple[float, str]] = []

    def __call__(self, fraction: float, stage: str) -> None:
        self.calls.append((fraction, stage))


# -- Deadline, check_interval, raise_unless_done ------------------------------------------------


def test_deadline_counts_down_on_the_clock_and_clips_sleeps(clock: FakeClock) -> None:
    deadline = Deadline(5.0)
    assert deadline.remaining() == 5.0 and not deadline.expired()
    assert deadline.clip(2.0) == 2.0 and deadline.clip(9.0) == 5.0
    clock.now += 3.5
    assert deadline.remaining() == pytest.approx(1.5) and not deadline.expired()
    assert deadline.clip(2.0) == pytest.approx(1.5)
    clock.now += 1.5
    assert deadline.expired() and deadline.remaining() == 0.0
    clock.now += 100.0
    # Never negative once past: a sleep clipped to it is a sleep of nothing.
    assert deadline.remaining() == 0.0 and deadline.clip(1.0) == 0.0


def test_a_deadline_without_timeout_never_comes(clock: FakeClock) -> None:
    deadline = Deadline(None)
    clock.now += 1e9
    assert deadline.remaining() is None and not deadline.expired()
    assert deadline.clip(42.0) == 42.0 and deadline.timeout is None


@pytest.mark.parametrize("interval", [0.0, -0.25, -1e9, math.nan])
def test_check_interval_refuses_an_interval_that_is_not_positive(interval: float) -> None:
    with pytest.raises(ValueError, match="poll_interval must be positive"):
        waiting.check_interval(interval)


@pytest.mark.parametrize("interval", [1e-6, 0.25, 60.0])
def test_a_positive_interval_is_accepted_and_the_wait_polls_at_once(
    clock: FakeClock, interval: float
) -> None:
    waiting.check_interval(interval)
    flow = flows.wait("j1", progress=None, timeout=None, poll_interval=interval)
    assert next(flow) == actions.Send(proto.job_request("j1"))
    flow.close()


def test_wait_flow_checks_the_interval_before_any_request() -> None:
    flow = flows.wait("j1", progress=None, timeout=None, poll_interval=0.0)
    with pytest.raises(ValueError, match="poll_interval"):
        next(flow)


def test_raise_unless_done_returns_a_done_job_as_it_is() -> None:
    job = JobStatus.from_json(job_json("done"))
    assert waiting.raise_unless_done(job) is job


@pytest.mark.parametrize(
    ("state", "error", "code"),
    [("failed", JobFailedError, "engine_error"), ("cancelled", JobCancelledError, "job_cancelled")],
)
def test_raise_unless_done_raises_the_typed_error_of_a_job_without_result(
    state: str, error: type[QuiltingClientError], code: str
) -> None:
    job = JobStatus.from_json(FAILED if state == "failed" else job_json(state))
    with pytest.raises(error) as caught:
        waiting.raise_unless_done(job)
    assert caught.value.job is job  # type: ignore[attr-defined]
    assert caught.value.code == code and "j1" in str(caught.value)


# -- polling ------------------------------------------------------------------------------------


def test_polling_waits_the_delay_first_then_the_poll_interval(clock: FakeClock) -> None:
    driver = Driver(clock, [status("queued"), status("running"), status("done")])
    job = driver.run(
        follow("j1", deadline=Deadline(None), progress=None, poll_interval=0.5, delay=2)
    )
    assert job.status == "done" and job.id == "j1"
    assert driver.kinds() == ["Sleep", "Send", "Sleep", "Send", "Sleep", "Send"]
    assert driver.sleeps == [2.0, 0.5, 0.5]
    # Nothing is asked for once the job has ended.
    assert driver.times_of(actions.Send) == [2.0, 2.5, 3.0]


def test_polling_without_delay_asks_at_once(clock: FakeClock) -> None:
    driver = Driver(clock, [status("done")])
    job = driver.run(follow("j1", deadline=Deadline(None), progress=None, poll_interval=0.5))
    assert job.status == "done" and driver.kinds() == ["Send"]


@pytest.mark.parametrize(
    ("retry_after", "interval", "expected"),
    [
        ("0", 0.5, 0.5),  # The interval is a floor: "Retry-After: 0" does not hammer.
        ("3", 0.5, 3.0),  # The service may ask for longer.
        ("1.5", 2.0, 2.0),
        ("soon", 0.5, 0.5),  # Neither seconds nor an HTTP date: ignored.
        ("Thu, 01 Jan 1970 00:00:00 GMT", 0.5, 0.5),  # A date in the past.
    ],
)
def test_poll_interval_is_a_floor_under_retry_after(
    clock: FakeClock, retry_after: str, interval: float, expected: float
) -> None:
    driver = Driver(clock, [status("running", retry_after=retry_after), status("done")])
    driver.run(follow("j1", deadline=Deadline(None), progress=None, poll_interval=interval))
    assert driver.sleeps == [expected]


def test_polling_without_deadline_keeps_the_interval_and_never_times_out(
    clock: FakeClock,
) -> None:
    driver = Driver(clock, [status("running")] * 200 + [status("done")])
    job = driver.run(follow("j1", deadline=Deadline(None), progress=None, poll_interval=30.0))
    assert job.status == "done"
    assert driver.sleeps == [30.0] * 200 and clock.now - START == pytest.approx(6000.0)


@pytest.mark.parametrize(
    ("timeout", "interval", "delay", "retry_after"),
    [
        (1.0, 0.4, 0.0, None),
        (1.0, 0.25, 0.0, None),
        (2.0, 0.3, 5.0, None),  # A submission's Retry-After longer than the whole timeout.
        (5.0, 0.5, 0.0, "3600"),  # The service asks for an hour.
        (0.0, 0.5, 1.0, None),
    ],
)
def test_polling_times_out_at_the_deadline_naming_the_job(
    clock: FakeClock, timeout: float, interval: float, delay: float, retry_after: str | None
) -> None:
    driver = Driver(clock, [status("running", retry_after=retry_after)])
    deadline = Deadline(timeout)
    flow = follow("j1", deadline=deadline, progress=None, poll_interval=interval, delay=delay)
    with pytest.raises(WaitTimeoutError) as caught:
        driver.run(flow)
    error = caught.value
    # Raised at the deadline by the fake clock: not before, and not a sleep later.
    assert clock.now - START == pytest.approx(timeout)
    # No sleep is longer than what the schedule asks, none passes the deadline.
    waited = 0.0
    for seconds in driver.sleeps:
        ask = max(interval, float(retry_after or 0)) if waited or not delay else delay
        assert 0 < seconds <= ask + 1e-9
        waited += seconds
        assert waited <= timeout + 1e-9
    # The last poll is at the deadline, so the error carries the freshest status.
    assert driver.times_of(actions.Send)[-1] == pytest.approx(timeout)
    assert error.job_id == "j1" and error.job is not None and error.job.status == "running"
    assert error.code == "wait_timeout" and error.status is None
    assert isinstance(error, TimeoutError)
    assert "j1" in str(error) and f"{timeout:g} s" in str(error)


def test_a_job_that_ends_at_the_deadline_is_not_a_timeout(clock: FakeClock) -> None:
    driver = Driver(clock, [status("running"), status("done")])
    deadline = Deadline(1.0)
    job = driver.run(follow("j1", deadline=deadline, progress=None, poll_interval=1.0))
    assert deadline.expired() and job.status == "done"


@pytest.mark.parametrize(
    ("state", "error"), [("failed", JobFailedError), ("cancelled", JobCancelledError)]
)
def test_polling_a_job_that_ends_without_result_raises_its_error(
    clock: FakeClock, state: str, error: type[QuiltingClientError]
) -> None:
    ended = status(state)
    if state == "failed":
        request = httpx.Request("GET", f"{BASE}/jobs/j1")
        ended = httpx.Response(200, json=FAILED, request=request)
    driver = Driver(clock, [status("running"), ended, status("done")])
    with pytest.raises(error) as caught:
        driver.run(follow("j1", deadline=Deadline(60.0), progress=None, poll_interval=0.5))
    assert caught.value.job.status == state  # type: ignore[attr-defined]
    # The wait ended on the terminal status: no poll after it.
    assert driver.kinds().count("Send") == 2


def test_polling_a_garbled_status_raises_invalid_response(clock: FakeClock) -> None:
    request = httpx.Request("GET", f"{BASE}/jobs/j1")
    garbled = httpx.Response(200, json={"state": "done"}, request=request)
    driver = Driver(clock, [garbled])
    with pytest.raises(QuiltingClientError) as caught:
        driver.run(follow("j1", deadline=Deadline(None), progress=None, poll_interval=0.5))
    assert caught.value.code == "invalid_response" and "/jobs/j1" in str(caught.value)


# -- following the event stream -----------------------------------------------------------------


def test_progress_is_handed_on_in_order_and_completed_to_one(clock: FakeClock) -> None:
    events = [progress_event(0.1, "queued"), progress_event(0.4), progress_event(0.9, "seams")]
    driver = Driver(clock, streams=[[*events, terminal_event("done", stage="finished")]])
    progress = Recorder()
    job = driver.run(follow("j1", deadline=Deadline(None), progress=progress, poll_interval=0.5))
    assert job.status == "done"
    assert progress.calls == [(0.1, "queued"), (0.4, "quilting"), (0.9, "seams"), (1.0, "finished")]
    fractions = [f for f, _ in progress.calls]
    assert fractions == sorted(fractions) and all(0.0 <= f <= 1.0 for f in fractions)
    # One stream, closed once the terminal event came; no polling, no sleeping.
    assert driver.kinds() == ["OpenStream"] + ["NextEvent"] * 4 + ["CloseStream"]
    assert driver.opened[0].closed and driver.limits() == [None]


def test_a_progress_already_at_one_is_not_reported_twice(clock: FakeClock) -> None:
    driver = Driver(clock, streams=[[progress_event(1.0, "writing"), terminal_event("done")]])
    progress = Recorder()
    driver.run(follow("j1", deadline=Deadline(None), progress=progress, poll_interval=0.5))
    assert progress.calls == [(1.0, "writing")]


def test_a_progress_event_without_a_number_repeats_the_last_fraction(clock: FakeClock) -> None:
    events = [
        progress_event(0.25),
        ServerEvent("progress", {"stage": "seams"}),
        progress_event(True, "flag"),  # A bool is not a fraction.
        progress_event("0.9", "text"),
        ServerEvent("progress", {"progress": 0.5}),
        ServerEvent("heartbeat", {"progress": 0.99}),  # Not a progress event: ignored.
        terminal_event("done"),
    ]
    driver = Driver(clock, streams=[events])
    progress = Recorder()
    driver.run(follow("j1", deadline=Deadline(None), progress=progress, poll_interval=0.5))
    assert progress.calls == [
        (0.25, "quilting"),
        (0.25, "seams"),
        (0.25, "flag"),
        (0.25, "text"),
        (0.5, ""),
        (1.0, "done"),
    ]


def test_raising_from_the_progress_callback_stops_the_wait(clock: FakeClock) -> None:
    class StopWaitingError(Exception):
        pass

    def progress(fraction: float, stage: str) -> None:
        if fraction >= 0.5:
            raise StopWaitingError(stage)

    events = [progress_event(0.2), progress_event(0.5, "seams"), progress_event(0.8)]
    driver = Driver(clock, [status("running")], streams=[[*events, terminal_event("done")]])
    with pytest.raises(StopWaitingError, match="seams"):
        driver.run(follow("j1", deadline=Deadline(None), progress=progress, poll_interval=0.5))
    # Nothing read, polled or slept after the callback raised.
    assert driver.kinds() == ["OpenStream", "NextEvent", "NextEvent"]
    assert driver.opened[0].read == 2


@pytest.mark.parametrize(
    ("state", "error"), [("failed", JobFailedError), ("cancelled", JobCancelledError)]
)
def test_a_terminal_event_without_result_raises_without_completing_progress(
    clock: FakeClock, state: str, error: type[QuiltingClientError]
) -> None:
    driver = Driver(clock, streams=[[progress_event(0.3), terminal_event(state)]])
    progress = Recorder()
    with pytest.raises(error) as caught:
        driver.run(follow("j1", deadline=Deadline(None), progress=progress, poll_interval=0.5))
    assert progress.calls == [(0.3, "quilting")]
    assert caught.value.job.status == state  # type: ignore[attr-defined]
    assert driver.opened[0].closed and "Send" not in driver.kinds()


def test_a_garbled_terminal_event_is_checked_against_the_status(clock: FakeClock) -> None:
    garbled = ServerEvent("done", {"data": "not a job"})
    driver = Driver(clock, [status("done")], streams=[[garbled]])
    progress = Recorder()
    job = driver.run(follow("j1", deadline=Deadline(None), progress=progress, poll_interval=0.5))
    assert job.status == "done" and progress.calls == [(1.0, "done")]
    assert driver.kinds() == ["OpenStream", "NextEvent", "CloseStream", "Send"]


def test_a_stream_that_ends_early_is_reopened_after_the_poll_interval(clock: FakeClock) -> None:
    driver = Driver(
        clock,
        [status("running")],
        streams=[[progress_event(0.3)], [], [progress_event(0.6), terminal_event("done")]],
    )
    progress = Recorder()
    job = driver.run(follow("j1", deadline=Deadline(10.0), progress=progress, poll_interval=2.0))
    assert job.status == "done"
    assert progress.calls == [(0.3, "quilting"), (0.6, "quilting"), (1.0, "done")]
    # Each broken stream is closed, the status asked, and the reconnection waits the interval.
    assert driver.sleeps == [2.0, 2.0] and all(s.closed for s in driver.opened)
    assert driver.times_of(actions.OpenStream) == [0.0, 2.0, 4.0]
    # Each stream is followed for at most what is left of the deadline.
    assert driver.limits() == pytest.approx([10.0, 8.0, 6.0])


def test_a_stream_that_ends_on_a_finished_job_returns_its_status(clock: FakeClock) -> None:
    driver = Driver(clock, [status("done")], streams=[[progress_event(0.5)]])
    job = driver.run(follow("j1", deadline=Deadline(None), progress=Recorder(), poll_interval=1))
    assert job.status == "done" and driver.sleeps == []


def test_events_that_keep_ending_time_out_at_the_deadline(clock: FakeClock) -> None:
    driver = Driver(clock, [status("running")], streams=[[]] * 50)
    with pytest.raises(WaitTimeoutError) as caught:
        driver.run(follow("j1", deadline=Deadline(1.0), progress=Recorder(), poll_interval=0.3))
    assert clock.now - START == pytest.approx(1.0)
    # The reconnection sleeps are clipped to the deadline: 0.3, 0.3, 0.3, then 0.1.
    assert driver.sleeps == pytest.approx([0.3, 0.3, 0.3, 0.1])
    assert caught.value.job_id == "j1" and caught.value.job is not None


def test_a_busy_stream_is_left_at_the_deadline(clock: FakeClock) -> None:
    # Progress every 0.3 s for an hour: the flow must leave it once the deadline passed.
    busy = FakeStream([progress_event(0.01 * (i % 100)) for i in range(12000)], 0.3)
    driver = Driver(clock, [status("running")], streams=[busy])
    progress = Recorder()
    with pytest.raises(WaitTimeoutError):
        driver.run(follow("j1", deadline=Deadline(1.0), progress=progress, poll_interval=0.5))
    assert 1.0 <= clock.now - START < 1.0 + 0.3 + 1e-9
    assert busy.read == 4 and busy.closed and len(progress.calls) == 4
    assert driver.kinds()[-2:] == ["CloseStream", "Send"]


def timed_out_error() -> ConnectionFailedError:
    error = ConnectionFailedError("GET /jobs/j1/events: read timed out", code="connection_failed")
    error.__cause__ = httpx.ReadTimeout("read timed out")
    return error


def test_a_stream_that_does_not_answer_in_time_is_taken_for_silence(clock: FakeClock) -> None:
    driver = Driver(clock, [status("running"), status("done")], streams=[timed_out_error(), []])
    job = driver.run(follow("j1", deadline=Deadline(30.0), progress=Recorder(), poll_interval=1))
    assert job.status == "done"
    assert driver.kinds() == [
        "OpenStream",
        "Send",
        "Sleep",
        "OpenStream",
        "NextEvent",
        "CloseStream",
        "Send",
    ]


def refused() -> ConnectionFailedError:
    error = ConnectionFailedError("GET /jobs/j1/events: refused", code="connection_failed")
    error.__cause__ = httpx.ConnectError("refused")
    return error


@pytest.mark.parametrize(
    ("error", "timeout"),
    [
        (NotFoundError("no job 'j1'", status=404, code="job_not_found"), 30.0),
        (refused(), 30.0),
        # Without a deadline the stream has no read limit: a timeout is a real failure.
        (timed_out_error(), None),
    ],
    ids=["not-found", "refused", "timeout-without-deadline"],
)
def test_other_failures_to_open_the_stream_propagate(
    clock: FakeClock, error: QuiltingClientError, timeout: float | None
) -> None:
    driver = Driver(clock, [status("done")], streams=[error])
    with pytest.raises(type(error)) as caught:
        driver.run(follow("j1", deadline=Deadline(timeout), progress=Recorder(), poll_interval=1))
    assert caught.value is error and driver.kinds() == ["OpenStream"]
