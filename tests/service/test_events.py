"""Event ids and the event stream of a job, without an app (a fake queue feeds the job's
states)."""

from __future__ import annotations

import asyncio
import dataclasses
import json

import pytest

from quilting.service import events
from quilting.service.jobs import Job, Status
from quilting.service.problems import Problem


def test_positions_grow_with_the_job_and_stay_below_the_end() -> None:
    positions = [
        events.event_position(Status.QUEUED, 0.0),
        events.event_position(Status.QUEUED, 0.5),
        events.event_position(Status.RUNNING, 0.0),
        events.event_position(Status.RUNNING, 0.3),
        events.event_position(Status.RUNNING, 1.0),
    ]
    assert positions == sorted(positions) and len(set(positions)) == len(positions)
    assert positions[-1] < events.END_EVENT_ID


@pytest.mark.parametrize(("header", "after"), [(None, -1), ("  ", -1), ("42", 42), (" 7 ", 7)])
def test_resume_after(header: str | None, after: int) -> None:
    assert events.resume_after(header) == after


@pytest.mark.parametrize("header", ["-1", "abc", "1" * 20])
def test_resume_after_refuses_what_was_never_sent(header: str) -> None:
    with pytest.raises(Problem) as caught:
        events.resume_after(header)
    assert caught.value.extra.get("field") == "Last-Event-ID"


class _Steps:
    """A queue whose job moves through given states, one per refresh."""

    def __init__(self, states: list[Job]) -> None:
        self.states = states

    async def refresh(self, job: Job) -> Job:
        return self.states.pop(0)


def _collect(job: Job, later: list[Job], after: int = -1) -> list[str]:
    async def run() -> list[str]:
        queue = _Steps(later)
        return [e async for e in events.job_stream(queue, job, after)]  # type: ignore[arg-type]

    return asyncio.run(run())


def test_the_stream_sends_progress_then_the_end(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(events, "POLL_S", 0.0)
    job = Job(id="j", owner=None, width=8, height=8, companion_names=[], input=None)
    running = dataclasses.replace(job, status=Status.RUNNING, progress=0.5, stage="cut")
    done = dataclasses.replace(running, status=Status.DONE, progress=1.0)
    sent = _collect(job, [running, running, done])
    assert sent[0].startswith("retry: ")
    names = [
        line.split(": ", 1)[1]
        for e in sent[1:]
        for line in e.split("\n")
        if line.startswith("event:")
    ]
    assert names == ["progress", "progress", "done"]  # the repeat of `running` is not resent
    ids = [int(e.split("\n")[0].removeprefix("id: ")) for e in sent[1:]]
    assert ids == sorted(ids) and ids[-1] == events.END_EVENT_ID
    assert json.loads(sent[-1].split("data: ", 1)[1])["status"] == "done"
    # A client that had the first progress event gets only what came after it.
    resumed = _collect(job, [running, done], after=ids[0])
    assert [int(e.split("\n")[0].removeprefix("id: ")) for e in resumed[1:]] == ids[1:]
