"""Helpers of the client's live tests: a real ``quilting serve`` process on a loopback port.

The service is started the way a user starts it (``python -m quilting serve --port P`` with
``QUILTING_*`` variables) and reached over HTTP. A module of its own (not the conftest), so
that the tests can import :class:`LiveServer` by a name no other test folder uses.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[2]


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


class LiveServer:
    """One ``quilting serve`` subprocess on a loopback port, its output in a log file.

    Parameters
    ----------
    env : dict
        ``QUILTING_*`` settings; the caller's own ``QUILTING_*`` variables are not passed on.
    log_path : Path
        Where its output goes.
    """

    def __init__(self, env: dict[str, str], log_path: Path) -> None:
        self.settings = dict(env)
        self.port = _free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.log_path = log_path
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self, timeout: float = 30.0) -> LiveServer:
        """Start the process and wait until ``/healthz`` answers."""
        environ = {k: v for k, v in os.environ.items() if not k.startswith("QUILTING_")}
        environ.update(self.settings)
        environ["PYTHONUNBUFFERED"] = "1"
        with open(self.log_path, "wb") as log:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "quilting", "serve", "--port", str(self.port)],
                cwd=ROOT,
                env=environ,
                stdout=log,
                stderr=subprocess.STDOUT,
            )
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"the server exited with {self.proc.returncode}:\n{self.log()}")
            try:
                if httpx.get(self.url + "/healthz", timeout=1.0).status_code == 200:
                    return self
            except httpx.TransportError:
                pass
            time.sleep(0.05)
        self.stop()
        raise RuntimeError(f"the server did not answer /healthz in {timeout} s:\n{self.log()}")

    def log(self) -> str:
        """The server's output so far."""
        try:
            return self.log_path.read_text(errors="replace")
        except OSError:
            return "<no log>"

    def stop(self) -> None:
        """SIGTERM; a second signal if it is still draining; SIGKILL as the last resort."""
        proc = self.proc
        if proc is None or proc.poll() is not None:
            return
        for sig in (signal.SIGTERM, signal.SIGINT):
            proc.send_signal(sig)
            try:
                proc.wait(timeout=5)
                return
            except subprocess.TimeoutExpired:
                continue
        proc.kill()
        proc.wait(timeout=5)
