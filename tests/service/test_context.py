"""The service object every route shares (:class:`quilting.service.context.Service`).

Covers
------
- :meth:`Service.build`: the queue, the sandbox (built, nothing spawned), the pixel limits and
  the job and ``/tile`` budgets derived from the settings, the memory budget read once (a
  derived budget does not follow the available memory afterwards); frozen; ``file_cache``;
- the lifecycle the app gives it (:func:`quilting.service.app.create_app`'s lifespan): the
  queue started before the sandbox and stopped after it, the queue given the whole
  ``drain_grace_s`` or what a drain left of it; with the real queue and sandbox, the job
  threads and the sandbox process are there while the app runs and gone after, and stopping
  again changes nothing; the readiness figures reflect the settings.

Readiness fields through a served app, and the drain itself, are in ``test_api.py`` and
``test_drain.py``.
"""

from __future__ import annotations

import asyncio
import dataclasses
import gc
import os
import time
from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from quilting import BASE_BYTES
from quilting.service import settings as settings_module
from quilting.service.app import create_app
from quilting.service.context import Service
from quilting.service.jobs import PixelLimits
from quilting.service.jobs.memory import LocalQueue
from quilting.service.settings import GiB, MiB, Settings

#: Deadlines of the waits below: they only bound a failing test.
WAIT_S = 60.0


@pytest.fixture(autouse=True)
def _unfreeze() -> Iterator[None]:
    """The lifespan freezes the garbage collector's objects (for a server's lifetime)."""
    yield
    gc.unfreeze()


# --- build ---------------------------------------------------------------------------------


def test_build_derives_its_parts_from_the_settings_and_starts_nothing() -> None:
    settings = Settings(
        workers=2,
        worker_mode="thread",
        job_memory_bytes=96 * MiB,
        job_timeout_s=40.0,
        sandbox_workers=3,
        sandbox_timeout_s=7.0,
        max_input_pixels=1000,
        max_output_pixels=500,
        max_side=100,
    )
    service = Service.build(settings)
    assert service.settings is settings
    assert isinstance(service.jobs, LocalQueue) and not service.jobs.busy()
    assert (service.sandbox.timeout_s, service.sandbox.memory_bytes) == (7.0, 96 * MiB)
    assert len(service.sandbox._processes) == 3
    assert service.sandbox.pids() == []
    assert service.limits == PixelLimits(1000, 500, 100)
    assert service.job_budget.memory_bytes == BASE_BYTES + 96 * MiB
    assert service.job_budget.seconds == 40.0
    assert service.tile_budget.memory_bytes == BASE_BYTES + 96 * MiB
    assert service.tile_budget.seconds == 7.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        service.settings = Settings()  # type: ignore[misc]


def test_a_derived_memory_budget_is_read_once_and_kept(monkeypatch: pytest.MonkeyPatch) -> None:
    # Every read of the available memory finds less: parts built from separate reads differ.
    available = iter(range(6 * GiB, 0, -GiB // 4))  # shares of 1.5 GiB, then less
    monkeypatch.setattr(settings_module, "available_memory", lambda: next(available))
    settings = Settings(workers=3, worker_mode="thread")  # job_memory_bytes=0: derived
    service = Service.build(settings)
    memory = service.sandbox.memory_bytes
    assert settings_module.MIN_MEMORY_BUDGET <= memory <= settings_module.DEFAULT_MEMORY_BUDGET
    assert service.job_budget.memory_bytes == BASE_BYTES + memory
    assert service.tile_budget.memory_bytes == BASE_BYTES + memory
    # Memory available later changes nothing of a built service.
    monkeypatch.setattr(settings_module, "available_memory", lambda: 256 * MiB)
    assert settings.memory_budget == settings_module.MIN_MEMORY_BUDGET
    assert service.sandbox.memory_bytes == memory
    assert service.job_budget.memory_bytes == BASE_BYTES + memory


@pytest.mark.parametrize(("ttl", "max_age"), [(3600.0, 3600), (90.9, 90)])
def test_file_cache_is_private_immutable_for_the_results_lifetime(ttl: float, max_age: int) -> None:
    service = Service.build(Settings(results_ttl_s=ttl, worker_mode="thread", workers=1))
    assert service.file_cache == f"private, max-age={max_age}, immutable"


# --- lifecycle -----------------------------------------------------------------------------


class _Recorder:
    """Stand-in queue and sandbox that write what is done to them into one list."""

    def __init__(self, events: list[tuple[Any, ...]], name: str) -> None:
        self.events = events
        self.name = name

    async def start(self) -> None:
        self.events.append((self.name, "start"))

    async def close(self) -> None:
        self.events.append((self.name, "close"))

    async def stop(self, timeout: float) -> None:
        self.events.append((self.name, "stop", timeout))


def _recorded_app(grace: float) -> tuple[Any, list[tuple[Any, ...]]]:
    app = create_app(Settings(drain_grace_s=grace, worker_mode="thread", workers=1))
    events: list[tuple[Any, ...]] = []
    app.state.service = dataclasses.replace(
        app.state.service,
        jobs=_Recorder(events, "jobs"),
        sandbox=_Recorder(events, "sandbox"),
    )
    return app, events


@pytest.mark.parametrize("drain", [None, 100.0, -5.0])
def test_the_queue_starts_first_stops_last_with_what_is_left_of_the_grace(
    drain: float | None,
) -> None:
    app, events = _recorded_app(grace=30.0)

    async def main() -> None:
        async with app.router.lifespan_context(app):
            assert events == [("jobs", "start"), ("sandbox", "start")]
            if drain is not None:  # as DrainingServer.handle_exit sets it
                app.state.drain_deadline = time.monotonic() + drain

    asyncio.run(main())
    assert events[2] == ("sandbox", "close")
    name, action, timeout = events[3]
    assert (name, action, len(events)) == ("jobs", "stop", 4)
    if drain is None:
        assert timeout == 30.0  # the whole grace
    elif drain > 0:
        assert drain - WAIT_S < timeout <= drain  # what is left of the drain's, not 30 s more
    else:
        assert timeout == 0.0  # the drain's grace is spent


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def test_a_real_lifecycle_starts_and_stops_everything_and_stopping_again_is_harmless() -> None:
    settings = Settings(
        workers=2, worker_mode="thread", sandbox_workers=1, backend="fft", drain_grace_s=5.0
    )
    app = create_app(settings)
    service: Service = app.state.service
    assert isinstance(service.jobs, LocalQueue)
    runner = service.jobs.runner

    async def main() -> list[int]:
        async with app.router.lifespan_context(app):
            assert [t.is_alive() for t in runner.threads] == [True, True]
            pids = service.sandbox.pids()
            assert len(pids) == 1 and pids[0] != os.getpid()
            figures = await service.jobs.readiness()
            assert (figures["queue"], figures["backend"], figures["workers"]) == (
                "memory",
                "fft",
                2,
            )
            assert (figures["queue_depth"], figures["running"]) == (0, 0)
            transport = httpx.ASGITransport(app=app)
            async with httpx.AsyncClient(transport=transport, base_url="http://t") as client:
                ready = await client.get("/readyz")
            assert ready.status_code == 200, ready.text
            assert {k: ready.json()[k] for k in figures} == figures
        assert not any(t.is_alive() for t in runner.threads)
        assert service.sandbox.pids() == [] and not _alive(pids[0])
        # Stopped twice (a second shutdown path): nothing raised, nothing restarted.
        await service.sandbox.close()
        await asyncio.wait_for(service.jobs.stop(timeout=1.0), WAIT_S)
        assert service.sandbox.pids() == []
        assert not any(t.is_alive() for t in runner.threads)
        return pids

    asyncio.run(main())
