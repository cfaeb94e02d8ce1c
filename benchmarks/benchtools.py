"""Shared by the benchmark scripts: tables, a description of the machine, a free port, the
argument parser and JSON output every benchmark has, ``quilting serve`` in a subprocess
for the service benchmarks, and where the quality tool texeval is."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import IO, Any, Self

#: The build machines' quality tool, texeval (not part of the project, never imported by the
#: package or the tests): the file ``QUILTING_TEXEVAL`` names, or None. A clone holds no copy
#: and looks nowhere else; on a build machine run the benchmarks with
#: ``QUILTING_TEXEVAL=/path/to/texeval.py`` (or ``--texeval PATH``). The benchmarks
#: that report its figures take it from here and leave its columns out when it is None or
#: absent.
TEXEVAL: Path | None = (
    Path(os.environ["QUILTING_TEXEVAL"]) if os.environ.get("QUILTING_TEXEVAL") else None
)


def free_port() -> int:
    """A TCP port free on the loopback interface right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def table(headers: list[str], rows: list[list[str]], left: int = 1) -> str:
    """Plain-text table: the first ``left`` columns left-aligned, the rest right-aligned."""
    widths = [max(len(row[k]) for row in [headers, *rows]) for k in range(len(headers))]

    def line(row: list[str]) -> str:
        cells = zip(row, widths, strict=True)
        return "  ".join(c.ljust(w) if k < left else c.rjust(w) for k, (c, w) in enumerate(cells))

    rule = "  ".join("-" * w for w in widths)
    return "\n".join([line(headers), rule, *(line(row) for row in rows)])


def markdown(headers: list[str], rows: list[list[str]], left: int = 1) -> str:
    """A markdown table padded to line up as plain text.

    Parameters
    ----------
    headers : list[str]
        Column titles.
    rows : list[list[str]]
        The cells.
    left : int
        The first ``left`` columns are left-aligned, the rest right-aligned.

    Returns
    -------
    str
        The table (:func:`table` with pipes).
    """
    widths = [max(len(row[k]) for row in [headers, *rows]) for k in range(len(headers))]

    def line(row: list[str]) -> str:
        cells = zip(row, widths, strict=True)
        padded = [c.ljust(w) if k < left else c.rjust(w) for k, (c, w) in enumerate(cells)]
        return "| " + " | ".join(padded) + " |"

    rule = ["-" * (w + 2) if k < left else "-" * (w + 1) + ":" for k, w in enumerate(widths)]
    return "\n".join([line(headers), "|" + "|".join(rule) + "|", *(line(row) for row in rows)])


def machine(**versions: str) -> dict[str, object]:
    """Cores, platform, Python, the given library versions and the load average now."""
    return {
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        **versions,
        "loadavg": [round(x, 2) for x in os.getloadavg()],
    }


def source_tree(root: Path) -> str:
    """The commit of the checkout at ``root`` measured, and whether the engine's sources
    (``server/``) differ from it."""

    def git(*args: str) -> str:
        done = subprocess.run(["git", *args], cwd=root, capture_output=True, text=True)
        return done.stdout.strip() if done.returncode == 0 else ""

    commit = git("rev-parse", "--short", "HEAD")
    if not commit:
        return "unknown (not a git checkout)"
    changed = git("status", "--porcelain", "--", "server")
    return commit + (" + uncommitted changes in server/" if changed else "")


def fmt(value: float | None, digits: int = 3) -> str:
    """A table cell: ``value`` with ``digits`` decimals, ``-`` when there is none."""
    return "-" if value is None else f"{value:.{digits}f}"


def percentile(values: list[float], q: float) -> float:
    """The ``q``-th percentile (0..100), linear between closest ranks; NaN when empty."""
    if not values:
        return float("nan")
    ordered = sorted(values)
    rank = (len(ordered) - 1) * q / 100.0
    low = int(rank)
    high = min(low + 1, len(ordered) - 1)
    return ordered[low] + (ordered[high] - ordered[low]) * (rank - low)


def parser(
    doc: str | None, json_help: str = "also write the results as JSON here"
) -> argparse.ArgumentParser:
    """The benchmark's argument parser: its description the docstring's first line, and the
    ``--json PATH`` option every benchmark offers.

    Parameters
    ----------
    doc : str | None
        The benchmark's module docstring.
    json_help : str
        The help of ``--json``.

    Returns
    -------
    argparse.ArgumentParser
        The parser, to which the benchmark adds its own options.
    """
    made = argparse.ArgumentParser(description=doc.splitlines()[0] if doc else None)
    made.add_argument("--json", type=Path, metavar="PATH", help=json_help)
    return made


def engine_parser(doc: str | None) -> argparse.ArgumentParser:
    """The argument parser of a benchmark timing the engine in this process on one output
    size: ``--repeat`` (5 runs), ``--size`` (512) and ``--backend`` (fft)."""
    made = argparse.ArgumentParser(description=doc.splitlines()[0] if doc else None)
    made.add_argument("--repeat", type=int, default=5)
    made.add_argument("--size", type=int, default=512)
    made.add_argument("--backend", default="fft", choices=("fft", "gl", "reference"))
    return made


def show_machine(info: dict[str, object]) -> None:
    """Print the machine line (``machine: cpu_count=16, ...``) first, before the long runs."""
    print("machine: " + ", ".join(f"{k}={v}" for k, v in info.items()), flush=True)


def service_machine(**versions: str) -> dict[str, object]:
    """:func:`machine` with the versions of the service's stack (quilting, numpy, FastAPI,
    uvicorn), for the benchmarks that measure ``quilting serve``."""
    # Imported here: the engine-only benchmarks run without the service extra installed.
    import fastapi
    import numpy
    import uvicorn

    import quilting

    return machine(
        quilting=quilting.__version__,
        numpy=numpy.__version__,
        fastapi=fastapi.__version__,
        uvicorn=uvicorn.__version__,
        **versions,
    )


def wall_time(started: float) -> float:
    """Print and return the seconds since ``started`` (a ``time.perf_counter()``)."""
    elapsed = time.perf_counter() - started
    print(f"\nbenchmark wall time: {elapsed:.0f} s")
    return elapsed


def write_json(path: Path | None, payload: object, indent: int = 2) -> None:
    """Write ``payload`` as JSON to ``path`` (the ``--json`` option), nothing when it is None."""
    if path is not None:
        path.write_text(json.dumps(payload, indent=indent) + "\n")


class ServeProcess:
    """``python -m quilting serve`` on a free loopback port in a subprocess, its output in
    ``log``; as a context manager it prints the end of that log when the block fails, and
    stops the server on the way out whatever happens.

    Parameters
    ----------
    log : IO[bytes]
        A file open for reading and writing (a temporary file): the server's stdout and
        stderr.
    workers : int | None
        ``--workers``; None for the server's own default.
    env : Mapping[str, str] | None
        The server's environment; None for this process's.
    cwd : Path | None
        Its working directory; None for this process's.
    stop_s : float
        Seconds :meth:`stop` waits after SIGTERM when leaving the ``with`` block.
    """

    def __init__(
        self,
        log: IO[bytes],
        workers: int | None = None,
        env: Mapping[str, str] | None = None,
        cwd: Path | None = None,
        stop_s: float = 60.0,
    ) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.command = [sys.executable, "-m", "quilting", "serve", "--port", str(self.port)]
        if workers is not None:
            self.command += ["--workers", str(workers)]
        self.log = log
        self.stop_s = stop_s
        self.process = subprocess.Popen(
            self.command, stdout=log, stderr=subprocess.STDOUT, env=env, cwd=cwd
        )
        self.exit_code: int | None = None

    def log_text(self) -> str:
        """All the server has printed so far."""
        self.log.seek(0)
        return self.log.read().decode(errors="replace")

    def log_tail(self, chars: int = 3000) -> str:
        """The end of :meth:`log_text`."""
        return self.log_text()[-chars:]

    def wait_for(self, path: str, startup_s: float, interval_s: float = 0.1) -> Any:
        """Ask ``path`` until it answers 200 (the server is up), its answer.

        Parameters
        ----------
        path : str
            ``/healthz`` or ``/readyz``.
        startup_s : float
            Seconds the server may take to start.
        interval_s : float
            Seconds between two questions.

        Returns
        -------
        httpx.Response
            The first 200 answer.

        Raises
        ------
        RuntimeError
            The server exited (with the end of its log), or did not answer in time.
        """
        # Imported here: the engine-only benchmarks run without the service extra installed.
        import httpx

        deadline = time.monotonic() + startup_s
        with httpx.Client(timeout=5.0) as client:
            while time.monotonic() < deadline:
                if self.process.poll() is not None:
                    raise RuntimeError(f"the server exited at start:\n{self.log_tail()}")
                with contextlib.suppress(httpx.TransportError):
                    response = client.get(f"{self.url}{path}")
                    if response.status_code == 200:
                        return response
                time.sleep(interval_s)
        raise RuntimeError(f"the server did not answer {path} in {startup_s:g} s")

    def stop(self, timeout: float = 60.0, again_s: float | None = 10.0) -> None:
        """SIGTERM (the server drains its queue) and wait; a second SIGTERM (uvicorn's forced
        exit) and ``again_s`` more seconds unless that is None; then SIGKILL."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                if again_s is not None:
                    self.process.send_signal(signal.SIGTERM)
                    with contextlib.suppress(subprocess.TimeoutExpired):
                        self.process.wait(again_s)
                if self.process.poll() is None:
                    self.process.kill()
                    self.process.wait()
        self.exit_code = self.process.returncode

    def __enter__(self) -> Self:
        return self

    def __exit__(self, kind: type[BaseException] | None, *rest: object) -> None:
        try:
            if kind is not None:
                print(self.log_tail(), file=sys.stderr)
        finally:
            self.stop(self.stop_s)
