"""The sandbox pool (:class:`quilting.service.sandbox.Sandbox`) on its own: a call past its
time, one out of memory and one whose process is killed each get a clear 422, never a 500,
and the next call is served by a fresh process; a process killed while idle is replaced
without the next caller noticing; a busy pool answers 503."""

from __future__ import annotations

import asyncio
import os
import signal
import time
from collections.abc import Awaitable, Iterator
from typing import Any, TypeVar

import hostile_inputs
import pytest
from sandbox_runs import run_sandbox as _run
from service_helpers import texture

from quilting.core.options import SynthesisOptions, TileOptions
from quilting.io import read_image
from quilting.service.jobs import JobInput, PixelLimits
from quilting.service.memory_limit import limit_memory
from quilting.service.problems import Problem
from quilting.service.sandbox import Sandbox

T = TypeVar("T")
MiB = 1 << 20
#: Deadlines of the waits below: they only bound a failing test.
WAIT_S = 60.0


def _spec(data: bytes, size: int = 64) -> JobInput:
    return JobInput(data, {}, SynthesisOptions(block=16).to_dict(), size, size)


async def _check(sandbox: Sandbox, data: bytes, **options: Any) -> Any:
    return await sandbox.run(
        "check",
        _spec(data),
        SynthesisOptions(**{"block": 16, **options}),
        doing="reading the uploads",
    )


async def _problem(call: Awaitable[Any]) -> Problem:
    with pytest.raises(Problem) as caught:
        await call
    return caught.value


def _rss(pid: int) -> int:
    with open(f"/proc/{pid}/status") as status:
        line = next(line for line in status if line.startswith("VmRSS:"))
    return int(line.split()[1]) * 1024


@pytest.fixture(scope="module")
def png16() -> Iterator[bytes]:
    yield hostile_inputs.png16_5000()


def test_a_check_answers_the_output_size_and_passes_problems_through() -> None:
    async def body(sandbox: Sandbox) -> None:
        assert await _check(sandbox, texture("gravel")) == (64, 64)
        problem = await _problem(_check(sandbox, texture("gravel"), block=300))
        assert (problem.status, problem.code, problem.extra) == (
            422,
            "invalid_parameter",
            {"field": "block"},
        )
        problem = await _problem(_check(sandbox, texture("gravel")[:3000]))
        assert (problem.code, problem.extra) == ("invalid_image", {"field": "texture"})
        assert "texture" in problem.detail

    _run(Sandbox(1, WAIT_S, 2048 * MiB), body)


def test_a_call_past_its_time_is_killed_and_the_next_call_gets_a_fresh_process(
    png16: bytes,
) -> None:
    async def body(sandbox: Sandbox) -> None:
        assert await _check(sandbox, texture("gravel")) == (64, 64)  # started and warm
        (first,) = sandbox.pids()
        started = time.monotonic()
        # Seconds of decoding on any machine, against a limit of a fraction of one.
        problem = await _problem(_check(sandbox, png16))
        assert time.monotonic() - started < 0.3 + 10
        assert (problem.status, problem.code) == (422, "image_too_costly")
        assert "sandbox_timeout_s" in problem.detail and "0.3 s" in problem.detail
        assert await _check(sandbox, texture("gravel")) == (64, 64)
        assert first not in sandbox.pids()
        assert not os.path.exists(f"/proc/{first}/status")  # killed and reaped

    _run(Sandbox(1, 0.3, 2048 * MiB), body)


def test_a_call_out_of_memory_is_422_and_the_next_call_gets_a_fresh_process() -> None:
    async def body(sandbox: Sandbox) -> None:
        assert await _check(sandbox, texture("gravel")) == (64, 64)
        (first,) = sandbox.pids()
        # Making a 5000x5000 image tileable takes gigabytes: far past a 64 MiB budget.
        problem = await _problem(
            sandbox.run(
                "tile", hostile_inputs.png_5000(), TileOptions(), PixelLimits(), doing="tiling"
            )
        )
        assert (problem.status, problem.code) == (422, "image_too_costly")
        assert "64 MiB" in problem.detail and "job_memory_bytes" in problem.detail
        png = await sandbox.run("tile", texture("wood"), TileOptions(), PixelLimits(), doing="x")
        assert read_image(png).shape == read_image(texture("wood")).shape
        assert first not in sandbox.pids()

    _run(Sandbox(1, WAIT_S, 64 * MiB), body)


def test_a_process_killed_during_a_call_is_422_and_replaced(png16: bytes) -> None:
    async def body(sandbox: Sandbox) -> None:
        assert await _check(sandbox, texture("gravel")) == (64, 64)
        (pid,) = sandbox.pids()
        idle = _rss(pid)
        call = asyncio.ensure_future(_check(sandbox, png16))
        # Wait until the process is decoding (its memory grows by the image's), then kill it.
        deadline = time.monotonic() + WAIT_S
        while _rss(pid) < idle + 50 * MiB:
            assert time.monotonic() < deadline and not call.done(), "the decode never began"
            await asyncio.sleep(0.01)
        os.kill(pid, signal.SIGKILL)
        problem = await _problem(call)
        assert (problem.status, problem.code) == (422, "image_too_costly")
        assert "signal 9" in problem.detail
        assert await _check(sandbox, texture("gravel")) == (64, 64)
        assert pid not in sandbox.pids()

    _run(Sandbox(1, WAIT_S, 2048 * MiB), body)


def test_a_process_killed_while_idle_is_replaced_unnoticed() -> None:
    async def body(sandbox: Sandbox) -> None:
        assert await _check(sandbox, texture("gravel")) == (64, 64)
        (pid,) = sandbox.pids()
        os.kill(pid, signal.SIGKILL)
        # Sent to the dead process first: it never took the call, so a fresh one does.
        assert await _check(sandbox, texture("brick")) == (64, 64)
        assert pid not in sandbox.pids()

    _run(Sandbox(1, WAIT_S, 2048 * MiB), body)


def test_a_pool_busy_past_the_time_limit_answers_503() -> None:
    async def body(sandbox: Sandbox) -> None:
        held = await sandbox._pool().get()  # the only process, taken as a long call would
        try:
            problem = await _problem(_check(sandbox, texture("gravel")))
        finally:
            sandbox._pool().put_nowait(held)
        assert (problem.status, problem.code) == (503, "sandbox_busy")
        assert problem.headers["Retry-After"]
        assert await _check(sandbox, texture("gravel")) == (64, 64)

    _run(Sandbox(1, 0.5, 2048 * MiB), body)


def test_limit_memory_caps_the_data_segment_over_what_is_used() -> None:
    import multiprocessing

    context = multiprocessing.get_context("spawn")
    with context.Pool(1) as pool:
        cap, allocated = pool.apply(_allocate_past, (32 * MiB, 256 * MiB))
    assert cap is not None
    assert allocated == "MemoryError"


def _allocate_past(budget: int, size: int) -> tuple[int | None, str]:
    """In a child: cap the memory at ``budget`` over its use, then allocate ``size``."""
    import numpy as np

    cap = limit_memory(budget)
    try:
        np.ones(size, dtype=np.uint8)
    except MemoryError:
        return cap, "MemoryError"
    return cap, "allocated"
