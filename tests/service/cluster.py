"""Helpers of the distributed-queue tests: a real ``redis-server``, ``quilting worker`` processes.

Redis is Debian's ``redis-server`` on a free loopback port, with its append-only file in a
temporary folder so that a stopped server comes back with its data. Workers are started the
way a user starts them (``python -m quilting worker`` with ``QUILTING_*`` variables); each
prints its id when it starts, so a test can tell which process runs which job.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path

import pytest
from service_helpers import free_port, spawn_quilting

REDIS_SERVER = shutil.which("redis-server") or "/usr/bin/redis-server"
WORKER_ID = re.compile(r"worker ([0-9a-f]{32}) taking jobs")


def terminate(proc: subprocess.Popen[bytes] | None, grace_s: float) -> None:
    """SIGTERM, then SIGKILL if the process is still there after ``grace_s``."""
    if proc is None or proc.poll() is not None:
        return
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=grace_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=5)


def need_redis() -> None:
    """Skip without ``redis-server``, except in CI (QUILTING_REQUIRE_REDIS=1): there, fail."""
    if os.path.exists(REDIS_SERVER):
        return
    message = "redis-server is not installed (Debian package redis-server)"
    if os.environ.get("QUILTING_REQUIRE_REDIS") == "1":
        pytest.fail(message)
    pytest.skip(message)


class RedisServer:
    """One ``redis-server`` on a loopback port, data (AOF) kept in ``folder`` across restarts."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.port = free_port()
        self.url = f"redis://127.0.0.1:{self.port}/0"
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self, timeout: float = 20.0) -> RedisServer:
        command = [
            REDIS_SERVER,
            "--port", str(self.port),
            "--bind", "127.0.0.1",
            "--dir", str(self.folder),
            "--save", "",
            "--appendonly", "yes",
            "--appendfsync", "always",
        ]  # fmt: skip
        log = open(self.folder / "redis.log", "ab")  # noqa: SIM115 - the process keeps it
        self.proc = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)
        log.close()
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"redis-server exited: {self.log()}")
            if self.ping():
                return self
            time.sleep(0.05)
        raise RuntimeError(f"redis-server did not answer in {timeout} s: {self.log()}")

    def ping(self) -> bool:
        try:
            with socket.create_connection(("127.0.0.1", self.port), timeout=0.5) as sock:
                sock.sendall(b"PING\r\n")
                return sock.recv(64).startswith(b"+PONG")
        except OSError:
            return False

    def log(self) -> str:
        path = self.folder / "redis.log"
        return path.read_text(errors="replace")[-4000:] if path.exists() else "<no log>"

    def stop(self) -> None:
        terminate(self.proc, 10)


class WorkerProcess:
    """One ``python -m quilting worker`` subprocess, its output in a log file."""

    def __init__(self, name: str, env: dict[str, str], log_dir: Path) -> None:
        self.name = name
        self.settings = dict(env)
        self.log_path = log_dir / f"worker-{name}-{time.monotonic_ns()}.log"
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self, timeout: float = 30.0) -> WorkerProcess:
        self.proc = spawn_quilting(["worker"], self.settings, self.log_path)
        deadline = time.monotonic() + timeout
        while self.worker_id is None:
            if self.proc.poll() is not None:
                raise RuntimeError(f"worker {self.name} exited: {self.log()}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"worker {self.name} did not start: {self.log()}")
            time.sleep(0.05)
        return self

    @property
    def worker_id(self) -> str | None:
        found = WORKER_ID.search(self.log())
        return found.group(1) if found else None

    def log(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")
        except OSError:
            return "<no log>"

    def attempts(self) -> list[tuple[str, int]]:
        """``(job id, attempt)`` of every job this worker started."""
        found = re.findall(r"job ([0-9a-f]{32}): attempt (\d+) on worker", self.log())
        return [(job, int(attempt)) for job, attempt in found]

    def kill(self) -> None:
        assert self.proc is not None
        self.proc.kill()
        self.proc.wait(timeout=10)

    def stop(self) -> None:
        # A worker lets its job finish first (drain grace): give it the time.
        terminate(self.proc, 15)
