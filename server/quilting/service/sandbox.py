"""The sandbox: a few processes that do the API's pixel work, each under a memory and a time
limit, so that no upload can make the API process decode, allocate or wait without bound.

The API process parses and routes; what is proportional to pixels runs in these processes
(what they do is :mod:`quilting.service.sandbox_process`):

- ``check``: a submission's uploads decoded and checked against each other and the options
  (:func:`quilting.service.uploads.check`), so that a bad upload still gets its 422 before it
  is queued; only the output size comes back. The job's worker decodes the files again when
  the job starts (:func:`quilting.service.uploads.decode`): decoding twice costs the time of
  one decode per job, and it is the price of a queued job that costs the API process no more
  than its compressed upload;
- ``tile``: ``POST /tile`` (decode, :func:`quilting.make_tileable`, encode); PNG bytes back;
- ``seams``: the seam overlay of ``GET /jobs/{id}/seams``; PNG bytes back.

This module is the API process's side: :class:`Sandbox` owns ``sandbox_workers`` spawned
processes. Each caps its data segment (RLIMIT_DATA, see
:func:`quilting.service.memory_limit.limit_memory`) at what it holds after its imports plus
``job_memory_bytes``, and each call has ``sandbox_timeout_s``. A call past its time gets its
process killed and replaced; one that runs out of memory (MemoryError) or kills its process
is answered likewise, and the next call gets a fresh process. All three are 422
``image_too_costly``, naming the limit and its setting, never a 500. A request that finds
every process busy for ``sandbox_timeout_s`` gets 503 ``sandbox_busy``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import multiprocessing
import threading
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from typing import Any

import anyio

from quilting.service.memory_limit import describe_bytes
from quilting.service.problems import Problem
from quilting.service.sandbox_process import sandbox_main

__all__ = ["START_TIMEOUT_S", "Sandbox"]

log = logging.getLogger("quilting.service")

#: How long a new process may take to import and say it is ready (seconds).
START_TIMEOUT_S = 60.0


class _ProcessDiedError(Exception):
    """The sandbox process ended during a call (``started``: after it took the call)."""

    def __init__(self, started: bool, exitcode: int | None) -> None:
        super().__init__(exitcode)
        self.started = started
        self.exitcode = exitcode


class _Process:
    """One sandbox process and its pipe, replaced when it dies, overruns or runs out of memory.

    Used by one caller at a time (the pool hands it out), from a worker thread.
    """

    def __init__(self, context: Any, budget: int) -> None:
        self.context = context
        self.budget = budget
        self.process: BaseProcess | None = None
        self.conn: Connection | None = None
        self.ready = False

    def spawn(self) -> None:
        """Start a fresh process (it imports and limits itself; :meth:`call` waits for it)."""
        mine, theirs = self.context.Pipe()
        process = self.context.Process(
            target=sandbox_main, args=(theirs, self.budget), daemon=True, name="quilting-sandbox"
        )
        process.start()
        theirs.close()
        self.process, self.conn, self.ready = process, mine, False

    def discard(self) -> None:
        """Kill the process (whatever it is doing) and reap it."""
        process, conn = self.process, self.conn
        self.process, self.conn, self.ready = None, None, False
        if conn is not None:
            conn.close()
        if process is not None:
            if process.is_alive():
                process.kill()
            process.join(5)

    def stop(self) -> None:
        """Ask the process to exit; kill it if it does not at once."""
        if self.conn is not None:
            with contextlib.suppress(OSError):
                self.conn.send(None)
        if self.process is not None:
            self.process.join(2)
        self.discard()

    def _connection(self) -> Connection:
        """The pipe of a live, ready process (spawned and waited for if need be)."""
        if self.process is None or not self.process.is_alive():
            self.discard()
            self.spawn()
        assert self.conn is not None and self.process is not None
        if not self.ready:
            try:
                if not self.conn.poll(START_TIMEOUT_S):
                    raise EOFError(f"not ready in {START_TIMEOUT_S:g} s")
                kind, _ = self.conn.recv()
            except (EOFError, OSError) as exc:
                self.discard()
                raise RuntimeError(f"a sandbox process did not start ({exc})") from None
            assert kind == "ready"
            self.ready = True
        return self.conn

    def call(self, task: str, args: tuple[Any, ...], timeout_s: float) -> tuple[Any, ...]:
        """Run ``task`` in the process; its answer (see :mod:`quilting.service.sandbox_process`), or
        ``("timeout",)`` after ``timeout_s`` (the process is then killed).

        Raises
        ------
        _ProcessDiedError
            The process ended before answering.
        """
        conn = self._connection()
        started = False
        try:
            conn.send(("call", task, args))
            if not conn.poll(START_TIMEOUT_S):
                raise EOFError("no acknowledgement")
            kind = conn.recv()[0]
            assert kind == "started"
            started = True
            if not conn.poll(timeout_s):
                self.discard()
                self.spawn()  # the next call finds it started (or starting)
                return ("timeout",)
            answer: tuple[Any, ...] = conn.recv()
        except (EOFError, OSError):
            process = self.process
            exitcode = None
            if process is not None:
                process.join(5)
                exitcode = process.exitcode
            self.discard()
            raise _ProcessDiedError(started, exitcode) from None
        if answer[0] == "memory":
            self.discard()  # it exits by itself: a fresh one for the next call
            self.spawn()
        return answer


class Sandbox:
    """A pool of sandbox processes for the app's pixel work (see the module's docstring).

    Parameters
    ----------
    processes : int
        How many calls run at once (``sandbox_workers``).
    timeout_s : float
        Time limit of one call (``sandbox_timeout_s``); also how long a call waits for a free
        process.
    memory_bytes : int
        Memory budget of one call on top of a process's own (``job_memory_bytes``).
    """

    def __init__(self, processes: int, timeout_s: float, memory_bytes: int) -> None:
        self.timeout_s = timeout_s
        self.memory_bytes = memory_bytes
        context = multiprocessing.get_context("spawn")
        self._processes = [_Process(context, memory_bytes) for _ in range(processes)]
        self._idle: asyncio.Queue[_Process] | None = None
        self._lock = threading.Lock()

    def _pool(self) -> asyncio.Queue[_Process]:
        if self._idle is None:
            self._idle = asyncio.Queue()
            for process in self._processes:
                self._idle.put_nowait(process)
        return self._idle

    async def start(self) -> None:
        """Spawn the processes now, so that the first requests do not wait for their imports
        (they start in the background; a call waits for its process to be ready)."""
        self._pool()
        await anyio.to_thread.run_sync(self._spawn_all)

    def _spawn_all(self) -> None:
        with self._lock:
            for process in self._processes:
                if process.process is None:
                    process.spawn()

    async def close(self) -> None:
        """Stop every process (the app's shutdown)."""
        await anyio.to_thread.run_sync(self._stop_all)

    def _stop_all(self) -> None:
        with self._lock:
            for process in self._processes:
                process.stop()

    def pids(self) -> list[int]:
        """Process ids of the live sandbox processes (tests, metrics)."""
        return [
            p.process.pid
            for p in self._processes
            if p.process is not None and p.process.pid is not None and p.process.is_alive()
        ]

    async def run(self, task: str, *args: Any, doing: str) -> Any:
        """Run ``task(*args)`` in a sandbox process and return its value.

        Parameters
        ----------
        task : str
            A name of :data:`quilting.service.sandbox_process.TASKS`.
        *args
            Its arguments (pickled to the process: keep them to bytes and small objects).
        doing : str
            What the call does, for the problem's detail ("reading the uploads").

        Raises
        ------
        Problem
            The task's own problem (its 422s); 422 ``image_too_costly`` past the time or
            memory limit or when the process died; 503 ``sandbox_busy`` when no process was
            free within the time limit; 500 ``internal_error`` for a bug.
        """
        pool = self._pool()
        try:
            process = await asyncio.wait_for(pool.get(), self.timeout_s)
        except TimeoutError:
            raise Problem(
                503,
                "sandbox_busy",
                f"every sandbox process stayed busy for {self.timeout_s:g} s "
                "(sandbox_workers, sandbox_timeout_s); retry later",
                headers={"Retry-After": "5"},
            ) from None
        try:
            answer = await anyio.to_thread.run_sync(self._call, process, task, args)
        finally:
            pool.put_nowait(process)
        return self._value(answer, doing)

    def _call(self, process: _Process, task: str, args: tuple[Any, ...]) -> tuple[Any, ...]:
        # A process that died while idle (killed from outside) never took the call: the call
        # is sent again to a fresh process once; one that died after taking it is the call's.
        for attempt in range(2):
            try:
                return process.call(task, args, self.timeout_s)
            except _ProcessDiedError as died:
                if died.started or attempt:
                    return ("died", died.exitcode)
                log.warning("a sandbox process had died (exit code %s): replaced", died.exitcode)
        raise AssertionError("unreachable")

    def _value(self, answer: tuple[Any, ...], doing: str) -> Any:
        kind = answer[0]
        if kind == "ok":
            return answer[1]
        if kind == "problem":
            _, status, code, detail, headers, extra = answer
            raise Problem(status, code, detail, headers=headers, **extra)
        if kind == "timeout":
            raise Problem(
                422,
                "image_too_costly",
                f"{doing} took longer than {self.timeout_s:g} s (sandbox_timeout_s) and was "
                "stopped; send a smaller image",
            )
        budget = describe_bytes(self.memory_bytes)
        if kind == "memory":
            raise Problem(
                422,
                "image_too_costly",
                f"{doing} needed more than {budget} of memory (job_memory_bytes) and was "
                "stopped; send a smaller image",
            )
        if kind == "died":
            exitcode = answer[1]
            how = f"signal {-exitcode}" if exitcode is not None and exitcode < 0 else exitcode
            raise Problem(
                422,
                "image_too_costly",
                f"the process {doing} ended ({how}), as one that runs out of its {budget} "
                "(job_memory_bytes) does; send a smaller image",
            )
        log.error("a sandbox call failed unexpectedly:\n%s", answer[1])
        raise Problem(500, "internal_error", "unexpected server error")
