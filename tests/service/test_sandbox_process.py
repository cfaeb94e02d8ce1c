"""The sandbox process (:mod:`quilting.service.sandbox_process`) driven over its own pipe, and
the pool's answers to its deaths (:class:`quilting.service.sandbox.Sandbox`).

Covers
------
- the protocol of :func:`~quilting.service.sandbox_process.sandbox_main` spoken by hand:
  ``("ready", cap)``, then ``("started",)`` and one answer per call; a ``tile`` answered with
  exactly the bytes :func:`~quilting.service.sandbox_process.tile_png` gives in this process;
  a task's :class:`~quilting.service.problems.Problem` as the ``("problem", ...)`` tuple; an
  unknown task or wrong arguments as ``("error", traceback)`` with the process still serving;
  ``("memory",)`` past the budget, after which the process exits by itself (and this
  process's own limits are untouched); ``None`` stops it; SIGINT is ignored; its niceness;
- the pool with test tasks added to its processes (a call that sleeps, one that exits): a call
  past ``sandbox_timeout_s`` and a process killed (``os.kill``) or crashing during a call are
  each answered with the documented 422 ``image_too_costly``, and every such process is reaped
  (no zombie is left) and replaced.

What ``tests/service/test_sandbox.py`` checks through real decodes (the 503 of a busy pool,
a process killed while idle, the memory cap itself) is not repeated.
"""

from __future__ import annotations

import asyncio
import io
import multiprocessing
import os
import resource
import signal
import time
from collections.abc import Awaitable, Callable, Iterator
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from pathlib import Path
from types import SimpleNamespace
from typing import Any, TypeVar

import hostile_inputs
import numpy as np
import pytest
from PIL import Image
from sandbox_runs import run_sandbox as _run
from service_helpers import texture

from quilting.io import read_image
from quilting.options import TileOptions
from quilting.service import sandbox as sandbox_module
from quilting.service import sandbox_process
from quilting.service.jobs import PixelLimits
from quilting.service.problems import Problem
from quilting.service.sandbox import Sandbox
from quilting.service.sandbox_process import NICENESS, sandbox_main, tile_png

T = TypeVar("T")
MiB = 1 << 20
#: Deadlines of the waits below: they only bound a failing test.
WAIT_S = 60.0
#: A budget far under what tiling a 5000x5000 image takes, far over a 64x64 one's.
SMALL_BUDGET = 64 * MiB
SPAWN = multiprocessing.get_context("spawn")


# --- helpers -------------------------------------------------------------------------------


def _small_png() -> bytes:
    """A 64x64 RGB crop of the wood texture: tiled in a fraction of a second."""
    image = read_image(texture("wood"))[:64, :64]
    out = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image)).save(out, format="PNG")
    return out.getvalue()


def _recv(conn: Connection) -> Any:
    """The next message from the process, or a failure after :data:`WAIT_S`."""
    assert conn.poll(WAIT_S), "the sandbox process did not answer"
    return conn.recv()


def _reaped(pid: int) -> bool:
    """Whether ``pid`` is no child of this process any more (exited and waited for)."""
    try:
        os.waitpid(pid, os.WNOHANG)
    except ChildProcessError:
        return True
    return False


@pytest.fixture
def raw_process() -> Iterator[Callable[[int], tuple[BaseProcess, Connection, Any]]]:
    """Start :func:`sandbox_main` with a budget; yields ``(process, conn, ready message)``.
    Every process started is killed and reaped at the end, whatever the test did."""
    started: list[BaseProcess] = []

    def start(budget: int) -> tuple[BaseProcess, Connection, Any]:
        mine, theirs = SPAWN.Pipe()
        process = SPAWN.Process(target=sandbox_main, args=(theirs, budget), daemon=True)
        process.start()
        theirs.close()
        started.append(process)
        return process, mine, _recv(mine)

    yield start
    for process in started:
        if process.is_alive():
            process.kill()
        process.join(WAIT_S)


# --- the protocol, by hand -----------------------------------------------------------------


def test_a_process_answers_calls_in_order_and_exits_after_running_out_of_memory(
    raw_process: Callable[[int], tuple[BaseProcess, Connection, Any]],
) -> None:
    limits_before = resource.getrlimit(resource.RLIMIT_DATA)
    png = _small_png()
    options = TileOptions(seed=7)
    expected = tile_png(png, options, PixelLimits())

    process, conn, ready = raw_process(SMALL_BUDGET)
    kind, cap = ready
    assert kind == "ready"
    assert isinstance(cap, int) and cap > SMALL_BUDGET  # what it holds, plus the budget

    # A good call: acknowledged, then exactly the bytes of the same call in this process.
    conn.send(("call", "tile", (png, options, PixelLimits())))
    assert _recv(conn) == ("started",)
    assert _recv(conn) == ("ok", expected)

    # A task's own problem crosses as its fields.
    conn.send(("call", "tile", (png[:100], options, PixelLimits())))
    assert _recv(conn) == ("started",)
    answer = _recv(conn)
    assert answer[:3] == ("problem", 422, "invalid_image"), answer
    detail, headers, extra = answer[3:]
    assert isinstance(detail, str) and detail
    assert isinstance(headers, dict) and extra == {"field": "image"}

    # A name that is no task, and a task given the wrong arguments: a bug's traceback, and
    # the process goes on serving.
    conn.send(("call", "no-such-task", ()))
    assert _recv(conn) == ("started",)
    kind, trace = _recv(conn)
    assert kind == "error" and "KeyError" in trace and "no-such-task" in trace
    conn.send(("call", "tile", (png,)))
    assert _recv(conn) == ("started",)
    kind, trace = _recv(conn)
    assert kind == "error" and "TypeError" in trace
    # A message of another shape than the protocol's: a bug answered, not the process ended.
    conn.send(("call", "tile"))
    assert _recv(conn) == ("started",)
    kind, trace = _recv(conn)
    assert kind == "error" and "ValueError" in trace
    conn.send(("call", "tile", (png, options, PixelLimits())))
    assert _recv(conn)[0] == "started"
    assert _recv(conn) == ("ok", expected)

    # Past the budget: ("memory",), then the process ends by itself, cleanly.
    conn.send(("call", "tile", (hostile_inputs.png_5000(), TileOptions(), PixelLimits())))
    assert _recv(conn) == ("started",)
    assert _recv(conn) == ("memory",)
    process.join(WAIT_S)
    assert process.exitcode == 0
    assert _reaped(process.pid or -1)
    # The cap was the child's own: this process's limit is as it was.
    assert resource.getrlimit(resource.RLIMIT_DATA) == limits_before


def test_the_pool_names_the_budget_of_a_memory_answer() -> None:
    sandbox = Sandbox(1, 5.0, SMALL_BUDGET)  # no process is started by building it
    with pytest.raises(Problem) as caught:
        sandbox._value(("memory",), "tiling the image")
    problem = caught.value
    assert (problem.status, problem.code) == (422, "image_too_costly")
    assert "tiling the image" in problem.detail
    assert "64 MiB" in problem.detail and "job_memory_bytes" in problem.detail
    assert sandbox.pids() == []


def test_a_process_ignores_sigint_runs_niced_and_stops_when_asked(
    raw_process: Callable[[int], tuple[BaseProcess, Connection, Any]],
) -> None:
    process, conn, ready = raw_process(256 * MiB)
    assert ready[0] == "ready"
    pid = process.pid
    assert pid is not None
    mine = os.getpriority(os.PRIO_PROCESS, 0)
    assert os.getpriority(os.PRIO_PROCESS, pid) == min(mine + NICENESS, 19)

    # Ctrl-C in a terminal reaches the process group: the sandbox leaves it to the service.
    os.kill(pid, signal.SIGINT)
    conn.send(("call", "seams", (b"not a layout", "ff0000")))
    assert _recv(conn) == ("started",)
    assert _recv(conn)[0] == "error"  # answered: still alive after the SIGINT
    assert process.is_alive()

    conn.send(None)
    process.join(WAIT_S)
    assert process.exitcode == 0
    assert _reaped(pid)


# --- the pool, with test tasks in its processes --------------------------------------------


def _sleep_task(marker: str, seconds: float) -> str:
    """In a sandbox process: say it has begun (a file), then take ``seconds``."""
    Path(marker).touch()
    time.sleep(seconds)
    return "slept"


def _main_with_test_tasks(conn: Connection, budget: int) -> None:
    """:func:`sandbox_main`, in a process that also takes ``sleep`` and ``exit``."""
    sandbox_process.TASKS["sleep"] = _sleep_task
    sandbox_process.TASKS["exit"] = os._exit
    sandbox_main(conn, budget)


class _TestTasksContext:
    """A spawn context whose sandbox processes run :func:`_main_with_test_tasks`."""

    def __init__(self) -> None:
        self.processes: list[BaseProcess] = []

    @property
    def pids(self) -> list[int]:
        """Process ids of every sandbox process spawned so far, oldest first."""
        return [p.pid for p in self.processes if p.pid is not None]

    def Pipe(self) -> tuple[Connection, Connection]:  # noqa: N802 (multiprocessing's name)
        return SPAWN.Pipe()

    def Process(self, *, target: Any, args: Any, **kwargs: Any) -> BaseProcess:  # noqa: N802
        assert target is sandbox_main
        process = SPAWN.Process(target=_main_with_test_tasks, args=args, **kwargs)
        self.processes.append(process)
        return process


@pytest.fixture
def test_tasks(monkeypatch: pytest.MonkeyPatch) -> _TestTasksContext:
    """Sandboxes built in this test spawn processes that also take the test tasks."""
    context = _TestTasksContext()
    monkeypatch.setattr(
        sandbox_module, "multiprocessing", SimpleNamespace(get_context=lambda _: context)
    )
    return context


async def _problem(call: Awaitable[Any]) -> Problem:
    with pytest.raises(Problem) as caught:
        await call
    return caught.value


async def _until(condition: Callable[[], bool], call: asyncio.Future[Any]) -> None:
    deadline = time.monotonic() + WAIT_S
    while not condition():
        assert not call.done(), call
        assert time.monotonic() < deadline, "the call never began"
        await asyncio.sleep(0.01)


def test_a_call_past_its_time_limit_is_killed_reaped_and_answered(
    test_tasks: _TestTasksContext, tmp_path: Path
) -> None:
    marker = tmp_path / "began"

    async def body(sandbox: Sandbox) -> None:
        problem = await _problem(
            sandbox.run("sleep", str(marker), WAIT_S, doing="sleeping on the image")
        )
        assert (problem.status, problem.code) == (422, "image_too_costly")
        assert "sleeping on the image" in problem.detail
        assert "0.5 s" in problem.detail and "sandbox_timeout_s" in problem.detail
        assert marker.exists()  # it had begun: the limit stopped it
        first = test_tasks.pids[0]
        assert _reaped(first)
        assert first not in sandbox.pids()

    _run(Sandbox(1, 0.5, 256 * MiB), body)
    assert len(test_tasks.pids) == 2  # replaced once, at the timeout
    assert all(_reaped(pid) for pid in test_tasks.pids)  # the replacement too, at close


def test_a_process_killed_or_crashing_during_a_call_is_answered_reaped_and_replaced(
    test_tasks: _TestTasksContext, tmp_path: Path
) -> None:
    marker = tmp_path / "began"
    png = _small_png()

    async def body(sandbox: Sandbox) -> None:
        call = asyncio.ensure_future(
            sandbox.run("sleep", str(marker), WAIT_S, doing="sleeping on the image")
        )
        await _until(marker.exists, call)
        killed = test_tasks.pids[-1]
        os.kill(killed, signal.SIGKILL)
        problem = await _problem(call)
        assert (problem.status, problem.code) == (422, "image_too_costly")
        assert "sleeping on the image" in problem.detail and "signal 9" in problem.detail
        assert "job_memory_bytes" in problem.detail
        assert _reaped(killed)

        # A process that ends itself during a call: its exit status, never a retry.
        problem = await _problem(sandbox.run("exit", 3, doing="exiting"))
        assert (problem.status, problem.code) == (422, "image_too_costly")
        assert "(3)" in problem.detail
        crashed = test_tasks.pids[-1]
        assert crashed != killed and _reaped(crashed)

        # The next call gets a fresh process, which answers as one in this process would.
        tiled = await sandbox.run("tile", png, TileOptions(seed=3), PixelLimits(), doing="t")
        assert tiled == tile_png(png, TileOptions(seed=3), PixelLimits())
        assert sandbox.pids() == [test_tasks.pids[-1]]

    _run(Sandbox(1, WAIT_S, 256 * MiB), body)
    assert len(test_tasks.pids) == 3  # one per death, none spawned again for a retry
    assert all(_reaped(pid) for pid in test_tasks.pids)
