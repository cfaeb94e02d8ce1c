"""Scaling benchmark of the job queues: jobs/s with 1 and 2 workers, Redis against memory.

Measures the throughput of a batch of synthesis jobs (default 24 jobs, 256x256 from
``--texture``, default options, seeds 1..N) in four configurations on the same machine:

* ``redis``, 1 and 2 workers: ``QUILTING_QUEUE=redis://... python -m quilting serve`` (the API,
  which only enqueues) and 1 or 2 ``python -m quilting worker`` processes, on a
  ``redis-server`` this script starts on a free loopback port (no persistence, data in a
  temporary folder, emptied with ``FLUSHALL`` before each run);
* ``memory``, 1 and 2 workers: the default in-memory queue, ``python -m quilting serve`` with
  ``QUILTING_WORKERS=1`` or ``2`` (worker processes inside the API), the baseline.

Each run starts the processes (inherited ``QUILTING_*`` variables are stripped; only the ones
above are set), waits until ``GET /readyz`` reports the expected number of workers (in Redis
mode that counts workers with a fresh heartbeat), runs ``2 x workers`` untimed warm-up jobs (the
first job of a fresh worker process pays for imports and first-call set-up), then posts the
whole batch at once (``POST /synthesize?wait=0``, concurrently from one ``httpx`` client) and
polls ``GET /jobs/{id}`` until every job is final. The time of a run is from just before the
first request to the latest ``finished`` timestamp of the batch's jobs (the server's clock,
the same machine's, so the poll interval does not count); jobs/s = jobs / that time. Then it
checks every job is ``done`` and that its ``GET /jobs/{id}/result`` is a PNG of the requested
size, and keeps a SHA-256 of the bytes per seed: the same seed must give the same bytes in
every configuration and repeat (a real cross-check that the distributed workers compute the
engine's images; the PNG carries no job id or time).

``--repeats`` rounds (default 3) each run every configuration once, the order rotated from
round to round, so that a slow spell of a noisy machine hits the configurations alike. The
table gives the median over the rounds, jobs/s from it, the ratio to the 1-worker figure of
the same mode and, for Redis, the ratio to memory at the same worker count.

The client, the API, the workers and Redis all share the machine: with 2 cores, 2 workers
compete with the rest for CPU. Compare only figures from the same run. Every process started
is stopped (SIGTERM, then SIGKILL) even on error; on a failure (a job not done, wrong bytes, a
process that exits) the tails of the processes' logs are printed and the exit status is 1.

Run from the repository root (about a minute)::

    .venv/bin/python benchmarks/bench_scale.py                     # 24 jobs, 3 rounds
    .venv/bin/python benchmarks/bench_scale.py --quick             # 8 jobs, 1 round: smoke test
    .venv/bin/python benchmarks/bench_scale.py --jobs 48 --json scale.json
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import io
import json
import os
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from importlib import metadata
from pathlib import Path
from types import FrameType
from typing import Any

import benchtools
import httpx

import quilting
from quilting.core.errors import QuiltingError
from quilting.io import image_format
from quilting.png import read_png_header

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_TEXTURE = ROOT / "tests" / "data" / "brick.png"
REDIS_SERVER = shutil.which("redis-server") or "/usr/bin/redis-server"

#: Seconds to wait for a process to answer after it is started.
STARTUP_S = 60.0
#: Pause between two looks at the jobs of a batch (the measured time does not depend on it).
POLL_S = 0.02
#: Statuses after which a job no longer changes.
FINAL = frozenset({"done", "failed", "cancelled"})
#: The multiplication sign of the table's ratio columns (an escape: ruff flags the character).
TIMES = "\u00d7"


class ServiceError(RuntimeError):
    """The service misbehaved: a job not done, a wrong result, a process that exited."""


# --- processes ------------------------------------------------------------------------------


def clean_env(**settings: str) -> dict[str, str]:
    """This process's environment without ``QUILTING_*`` variables, plus ``settings``.

    Parameters
    ----------
    **settings : str
        Variables to set (``QUILTING_QUEUE=...``, ``QUILTING_WORKERS=...``).

    Returns
    -------
    dict[str, str]
        The environment of a child process.
    """
    # An inherited QUILTING_* (a developer's QUEUE, WORKERS or BACKEND) would change what is
    # measured without showing in the report.
    env = {k: v for k, v in os.environ.items() if not k.startswith("QUILTING_")}
    env.update(settings)
    env["PYTHONUNBUFFERED"] = "1"  # the logs are read while the process runs
    return env


class Proc:
    """One child process, its output in a log file.

    Parameters
    ----------
    name : str
        A label for reports (``api``, ``worker-1``, ``redis``).
    command : list[str]
        The command line.
    env : dict[str, str]
        Its environment.
    log_path : Path
        Where its stdout and stderr go.
    """

    def __init__(self, name: str, command: list[str], env: dict[str, str], log_path: Path) -> None:
        self.name = name
        self.log_path = log_path
        with open(log_path, "wb") as log:
            # A session of its own: a SIGKILL as the last resort reaches the process group,
            # which holds the API's own worker processes in memory mode.
            self.process = subprocess.Popen(
                command,
                cwd=ROOT,
                env=env,
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        self.exit_code: int | None = None

    def log(self, chars: int = 100_000) -> str:
        """The end of the process's output.

        Parameters
        ----------
        chars : int
            At most this many characters, from the end.

        Returns
        -------
        str
            The text, or a placeholder when the log cannot be read.
        """
        try:
            return self.log_path.read_text(errors="replace")[-chars:]
        except OSError:
            return "<no log>"

    def check_alive(self) -> None:
        """Raise :class:`ServiceError` with the log when the process has exited."""
        code = self.process.poll()
        if code is not None:
            raise ServiceError(f"{self.name} exited with code {code}:\n{self.log(3000)}")

    def stop(self, timeout: float = 60.0) -> None:
        """SIGTERM and wait (the service drains), then SIGKILL to the process group.

        Parameters
        ----------
        timeout : float
            Seconds the process may take to exit after SIGTERM.
        """
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(self.process.pid, signal.SIGKILL)
                self.process.wait()
        self.exit_code = self.process.returncode


class Redis:
    """A ``redis-server`` on a free loopback port, without persistence, data in ``folder``.

    Parameters
    ----------
    folder : Path
        Its working directory and log.
    """

    def __init__(self, folder: Path) -> None:
        self.port = benchtools.free_port()
        self.url = f"redis://127.0.0.1:{self.port}/0"
        command = [
            REDIS_SERVER,
            "--port", str(self.port),
            "--bind", "127.0.0.1",
            "--dir", str(folder),
            "--save", "",
            "--appendonly", "no",
        ]  # fmt: skip
        self.proc = Proc("redis", command, clean_env(), folder / "redis.log")
        try:
            deadline = time.monotonic() + STARTUP_S
            while self.command("PING") != b"+PONG":
                self.proc.check_alive()
                if time.monotonic() > deadline:
                    raise ServiceError(f"redis-server did not answer:\n{self.proc.log(3000)}")
                time.sleep(0.05)
        except BaseException:
            self.proc.stop()
            raise

    def command(self, name: str) -> bytes | None:
        """Send one inline command and read the first line of the answer.

        Parameters
        ----------
        name : str
            The command, without arguments (``PING``, ``FLUSHALL``).

        Returns
        -------
        bytes or None
            The answer's first line, or None when the server cannot be reached.
        """
        # A raw socket: this script needs no Redis client of its own.
        try:
            with socket.create_connection(("127.0.0.1", self.port), timeout=5.0) as sock:
                sock.sendall(name.encode() + b"\r\n")
                return sock.recv(256).split(b"\r\n", 1)[0]
        except OSError:
            return None

    def flush(self) -> None:
        """Forget every job, message and worker of the previous run."""
        answer = self.command("FLUSHALL")
        if answer != b"+OK":
            raise ServiceError(f"FLUSHALL answered {answer!r}:\n{self.proc.log(3000)}")


def redis_version() -> str:
    """The installed ``redis-server``'s version, e.g. ``7.0.15``, or ``?``."""
    try:
        text = subprocess.run(
            [REDIS_SERVER, "--version"], capture_output=True, text=True, check=True
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        return "?"
    for word in text.split():
        if word.startswith("v="):
            return word[2:]
    return "?"


# --- one configuration ----------------------------------------------------------------------


@dataclass(frozen=True)
class Config:
    """One configuration: the queue and the number of compute workers."""

    mode: str  # "redis" or "memory"
    workers: int

    @property
    def label(self) -> str:
        """``redis-2``, ``memory-1``, ..."""
        return f"{self.mode}-{self.workers}"


CONFIGS = (Config("redis", 1), Config("redis", 2), Config("memory", 1), Config("memory", 2))


class Deployment:
    """The processes of one configuration: the API, and the workers in Redis mode.

    Parameters
    ----------
    config : Config
        What to start.
    redis : Redis or None
        The Redis server (Redis mode only); flushed before anything starts.
    folder : Path
        Where the logs go.
    """

    def __init__(self, config: Config, redis: Redis | None, folder: Path) -> None:
        self.config = config
        self.procs: list[Proc] = []
        port = benchtools.free_port()
        self.url = f"http://127.0.0.1:{port}"
        serve = [sys.executable, "-m", "quilting", "serve", "--port", str(port)]
        stamp = time.monotonic_ns()
        try:
            if config.mode == "redis":
                assert redis is not None
                redis.flush()
                env = clean_env(QUILTING_QUEUE=redis.url)
                self.procs.append(Proc("api", serve, env, folder / f"api-{stamp}.log"))
                for index in range(1, config.workers + 1):
                    command = [sys.executable, "-m", "quilting", "worker"]
                    log = folder / f"worker{index}-{stamp}.log"
                    self.procs.append(Proc(f"worker-{index}", command, env, log))
            else:
                env = clean_env(QUILTING_WORKERS=str(config.workers))
                self.procs.append(Proc("api", serve, env, folder / f"api-{stamp}.log"))
        except BaseException:
            self.stop()
            raise

    def logs(self, chars: int = 3000) -> str:
        """The ends of every process's log, for a failure report.

        Parameters
        ----------
        chars : int
            At most this many characters of each log.

        Returns
        -------
        str
            One headed section per process.
        """
        return "\n".join(
            f"--- {self.config.label} {p.name} (pid {p.process.pid}, exit "
            f"{p.process.poll()}) ---\n{p.log(chars)}"
            for p in self.procs
        )

    def check_alive(self) -> None:
        """Raise :class:`ServiceError` when any of the processes has exited."""
        for proc in self.procs:
            proc.check_alive()

    def wait_ready(self, client: httpx.Client) -> dict[str, Any]:
        """Wait until ``/readyz`` answers 200 with the expected number of workers.

        Parameters
        ----------
        client : httpx.Client
            A client for the API.

        Returns
        -------
        dict[str, Any]
            The last ``/readyz`` document.
        """
        deadline = time.monotonic() + STARTUP_S
        last: object = None
        while time.monotonic() < deadline:
            self.check_alive()
            with contextlib.suppress(httpx.TransportError, ValueError):
                response = client.get(f"{self.url}/readyz", timeout=5.0)
                last = f"{response.status_code} {response.text[:300]}"
                if response.status_code == 200:
                    document: dict[str, Any] = response.json()
                    # Redis mode: workers whose heartbeat is fresh, so every worker is up.
                    if document.get("workers") == self.config.workers:
                        return document
            time.sleep(0.1)
        raise ServiceError(
            f"{self.config.label}: /readyz did not report {self.config.workers} worker(s) in "
            f"{STARTUP_S:g} s; last answer: {last}"
        )

    def stop(self) -> None:
        """Stop the workers first (they leave the list of live workers), then the API."""
        for proc in reversed(self.procs):
            proc.stop()


@contextlib.contextmanager
def deployed(config: Config, redis: Redis | None, folder: Path) -> Iterator[Deployment]:
    """A running :class:`Deployment`, stopped on the way out whatever happens.

    Parameters
    ----------
    config, redis, folder
        As for :class:`Deployment`.

    Yields
    ------
    Deployment
        The started processes.
    """
    deployment = Deployment(config, redis, folder)
    try:
        yield deployment
    except BaseException:
        # The logs are in the temporary folder, which goes away: show them now.
        print(deployment.logs(), file=sys.stderr, flush=True)
        raise
    finally:
        deployment.stop()


# --- one batch ------------------------------------------------------------------------------


@dataclass
class JobOutcome:
    """One job of a batch, as the service reported it."""

    seed: int
    job_id: str
    status: str
    created: float | None
    started: float | None
    finished: float | None
    engine_s: float | None
    sha256: str | None = None
    error: Any = None


@dataclass
class Run:
    """One batch in one configuration."""

    mode: str
    workers: int
    round: int
    jobs: int
    wall_s: float  # first request -> latest ``finished``
    observed_s: float  # first request -> the poll that saw the last job final
    submit_s: float  # first request -> the last 202 received
    engine_median_s: float  # median Result.timings["total"] of the batch's jobs
    outcomes: list[JobOutcome] = field(default_factory=list)

    @property
    def jobs_per_s(self) -> float:
        """Jobs / wall time."""
        return self.jobs / self.wall_s

    @property
    def idle_per_job_s(self) -> float:
        """Worker time not spent inside a job (started to finished), per job.

        ``(workers x wall - sum of the jobs' started-to-finished) / jobs``: what the queue
        costs per job between jobs (hand-over to a worker, the first job's wait for the
        submissions), plus, with 2 workers, the end of the batch when one worker has nothing
        left to do.
        """
        busy = sum(
            o.finished - o.started
            for o in self.outcomes
            if o.finished is not None and o.started is not None
        )
        return (self.workers * self.wall_s - busy) / self.jobs


def png_size(data: bytes) -> tuple[int, int] | None:
    """Width and height from a PNG's IHDR chunk, or None if ``data`` is not a PNG.

    Parameters
    ----------
    data : bytes
        The file.

    Returns
    -------
    tuple[int, int] or None
        ``(width, height)``.
    """
    if image_format(data[:8]) != "png":
        return None
    try:
        header = read_png_header(io.BytesIO(data), "result")
    except QuiltingError:
        return None
    return header.width, header.height


async def submit(client: httpx.AsyncClient, texture: bytes, name: str, size: int, seed: int) -> str:
    """Post one synthesis job with ``wait=0``; its id from the ``Location`` header.

    Parameters
    ----------
    client : httpx.AsyncClient
        A client with the API as its base URL.
    texture : bytes
        The PNG to upload.
    name : str
        Its file name.
    size : int
        Output width and height.
    seed : int
        The job's seed.

    Returns
    -------
    str
        The job id.
    """
    options = json.dumps({"width": size, "height": size, "seed": seed})
    response = await client.post(
        "/synthesize",
        params={"wait": 0},
        data={"options": options},
        files={"texture": (name, texture, "image/png")},
    )
    location = str(response.headers.get("location", ""))
    if response.status_code != 202 or not location.startswith("/jobs/"):
        raise ServiceError(
            f"seed {seed}: POST /synthesize?wait=0 answered {response.status_code} "
            f"(Location {location!r}): {response.text[:500]}"
        )
    return location.removeprefix("/jobs/")


async def status(client: httpx.AsyncClient, job_id: str) -> dict[str, Any]:
    """``GET /jobs/{id}``.

    Parameters
    ----------
    client : httpx.AsyncClient
        A client with the API as its base URL.
    job_id : str
        The job.

    Returns
    -------
    dict[str, Any]
        The job's status document.
    """
    response = await client.get(f"/jobs/{job_id}")
    if response.status_code != 200:
        raise ServiceError(
            f"GET /jobs/{job_id} answered {response.status_code}: {response.text[:500]}"
        )
    document: dict[str, Any] = response.json()
    return document


async def run_batch(
    url: str,
    texture: bytes,
    name: str,
    size: int,
    seeds: list[int],
    timeout: float,
    deployment: Deployment,
) -> tuple[float, float, float, list[JobOutcome]]:
    """Post one job per seed at once, poll until all are final, check and fetch the results.

    Parameters
    ----------
    url : str
        The API.
    texture : bytes
        The PNG to upload.
    name : str
        Its file name.
    size : int
        Output width and height.
    seeds : list[int]
        One job per seed.
    timeout : float
        Seconds the batch may take before the jobs still pending are reported.
    deployment : Deployment
        Its processes are checked while polling (a dead worker is reported at once).

    Returns
    -------
    tuple[float, float, float, list[JobOutcome]]
        Wall time (first request to latest ``finished``), client-observed time (first request
        to the poll that saw the last job final), submission time (to the last 202), and the
        jobs in seed order.
    """
    limits = httpx.Limits(max_connections=len(seeds) + 4, max_keepalive_connections=len(seeds) + 4)
    async with httpx.AsyncClient(base_url=url, timeout=60.0, limits=limits) as client:
        start = time.time()
        ids = await asyncio.gather(*(submit(client, texture, name, size, s) for s in seeds))
        submitted = time.time()
        documents: dict[str, dict[str, Any]] = {}
        pending = list(ids)
        deadline = time.monotonic() + timeout
        while pending:
            # In submission order, stopping at the first job still running: jobs finish in
            # about the order they were sent (exactly so in memory), so the later ones are
            # seldom done yet, and fewer requests leave the CPU to the workers. The measured
            # time comes from the jobs' own finished times, not from this loop.
            for job_id in list(pending):
                document = await status(client, job_id)
                if document.get("status") not in FINAL:
                    break
                documents[job_id] = document
                pending.remove(job_id)
            if not pending:
                break
            deployment.check_alive()
            if time.monotonic() > deadline:
                stuck = [await status(client, job_id) for job_id in pending]
                summary = "\n".join(
                    f"  {d.get('id')}: status {d.get('status')}, stage {d.get('stage')}, "
                    f"progress {d.get('progress')}, created {d.get('created')}, started "
                    f"{d.get('started')}"
                    for d in stuck
                )
                readyz = await client.get("/readyz")
                raise ServiceError(
                    f"{len(pending)} of {len(seeds)} job(s) not final after {timeout:g} s:\n"
                    f"{summary}\n/readyz: {readyz.status_code} {readyz.text[:500]}"
                )
            await asyncio.sleep(POLL_S)
        observed = time.time()

        outcomes = []
        for seed, job_id in zip(seeds, ids, strict=True):
            d = documents[job_id]
            outcome = JobOutcome(
                seed,
                job_id,
                str(d.get("status")),
                d.get("created"),
                d.get("started"),
                d.get("finished"),
                (d.get("timings") or {}).get("total"),
                error=d.get("error"),
            )
            outcomes.append(outcome)
            if outcome.status != "done":
                continue
            response = await client.get(f"/jobs/{job_id}/result")
            if response.status_code == 200 and png_size(response.content) == (size, size):
                outcome.sha256 = hashlib.sha256(response.content).hexdigest()
            else:
                outcome.error = (
                    f"result: {response.status_code} {response.headers.get('content-type')}, "
                    f"PNG size {png_size(response.content)}, expected {(size, size)}"
                )
    bad = [o for o in outcomes if o.status != "done" or o.sha256 is None]
    if bad:
        raise ServiceError(
            f"{len(bad)} of {len(seeds)} job(s) not done with a {size}x{size} PNG:\n"
            + "\n".join(f"  seed {o.seed} job {o.job_id}: {o.status}, {o.error}" for o in bad)
        )
    missing = [o for o in outcomes if o.finished is None]
    if missing:
        raise ServiceError(f"done jobs without a finished time: {missing}")
    wall = max(float(o.finished) for o in outcomes if o.finished is not None) - start
    return wall, observed - start, submitted - start, outcomes


def measure(
    config: Config,
    redis: Redis | None,
    folder: Path,
    texture: Path,
    size: int,
    seeds: list[int],
    timeout: float,
    round_index: int,
) -> Run:
    """Start one configuration, warm it up, time one batch, stop it.

    Parameters
    ----------
    config : Config
        What to run.
    redis : Redis or None
        The Redis server (Redis mode).
    folder : Path
        Where the logs go.
    texture : Path
        The sample PNG.
    size : int
        Output width and height.
    seeds : list[int]
        One job per seed.
    timeout : float
        Seconds a batch may take.
    round_index : int
        The round, for the record.

    Returns
    -------
    Run
        The timed batch.
    """
    data = texture.read_bytes()
    with deployed(config, redis, folder) as deployment:
        with httpx.Client(timeout=30.0) as client:
            deployment.wait_ready(client)
        # Seeds outside the measured range: the warm-up's results are not cross-checked.
        warm = [1_000_000 + k for k in range(2 * config.workers)]
        asyncio.run(run_batch(deployment.url, data, texture.name, size, warm, timeout, deployment))
        wall, observed, submitted, outcomes = asyncio.run(
            run_batch(deployment.url, data, texture.name, size, seeds, timeout, deployment)
        )
    engine = [o.engine_s for o in outcomes if o.engine_s is not None]
    return Run(
        config.mode,
        config.workers,
        round_index,
        len(seeds),
        wall,
        observed,
        submitted,
        statistics.median(engine) if engine else float("nan"),
        outcomes,
    )


# --- report ---------------------------------------------------------------------------------


def summarize(runs: list[Run]) -> list[dict[str, Any]]:
    """Per configuration: medians over the rounds and the ratios of the table.

    Parameters
    ----------
    runs : list[Run]
        Every timed batch.

    Returns
    -------
    list[dict[str, Any]]
        One row per configuration, in :data:`CONFIGS` order.
    """
    rows: dict[Config, dict[str, Any]] = {}
    for config in CONFIGS:
        mine = [r for r in runs if (r.mode, r.workers) == (config.mode, config.workers)]
        if not mine:
            continue
        wall = statistics.median(r.wall_s for r in mine)
        rows[config] = {
            "mode": config.mode,
            "workers": config.workers,
            "jobs": mine[0].jobs,
            "runs": len(mine),
            "median_s": wall,
            "min_s": min(r.wall_s for r in mine),
            "observed_median_s": statistics.median(r.observed_s for r in mine),
            "submit_median_s": statistics.median(r.submit_s for r in mine),
            "jobs_per_s": mine[0].jobs / wall,
            "engine_median_s": statistics.median(r.engine_median_s for r in mine),
            "idle_per_job_median_s": statistics.median(r.idle_per_job_s for r in mine),
        }
    for config, row in rows.items():
        one = rows.get(Config(config.mode, 1))
        memory = rows.get(Config("memory", config.workers))
        row["vs_1_worker"] = row["jobs_per_s"] / one["jobs_per_s"] if one else None
        row["vs_memory"] = row["jobs_per_s"] / memory["jobs_per_s"] if memory else None
    return list(rows.values())


def ratio(value: float | None) -> str:
    """A ratio as ``1.23x``, or ``-`` when there is none."""
    return "-" if value is None else f"{value:.2f}x"


def report(rows: list[dict[str, Any]]) -> str:
    """The main table and a second one with the times behind it.

    Parameters
    ----------
    rows : list[dict[str, Any]]
        From :func:`summarize`.

    Returns
    -------
    str
        Two markdown tables.
    """
    main = benchtools.markdown(
        [
            "mode",
            "workers",
            "jobs",
            "median s",
            "jobs/s",
            f"{TIMES} 1 worker",
            f"{TIMES} memory (same workers)",
        ],
        [
            [
                r["mode"],
                str(r["workers"]),
                str(r["jobs"]),
                f"{r['median_s']:.3f}",
                f"{r['jobs_per_s']:.2f}",
                ratio(r["vs_1_worker"]),
                ratio(r["vs_memory"]),
            ]
            for r in rows
        ],
    )
    detail = benchtools.markdown(
        [
            "mode",
            "workers",
            "runs",
            "min s",
            "observed s",
            "submit s",
            "engine s/job",
            "workers / engine (jobs/s)",
            "idle ms/job",
        ],
        [
            [
                r["mode"],
                str(r["workers"]),
                str(r["runs"]),
                f"{r['min_s']:.3f}",
                f"{r['observed_median_s']:.3f}",
                f"{r['submit_median_s']:.3f}",
                f"{r['engine_median_s']:.3f}",
                f"{r['workers'] / r['engine_median_s']:.2f}",
                f"{1000 * r['idle_per_job_median_s']:.1f}",
            ]
            for r in rows
        ],
    )
    return f"{main}\n\n{detail}"


def cross_check(runs: list[Run]) -> dict[int, dict[str, list[str]]]:
    """Seeds whose result bytes differ between configurations or rounds.

    Parameters
    ----------
    runs : list[Run]
        Every timed batch.

    Returns
    -------
    dict[int, dict[str, list[str]]]
        For each seed with more than one digest: digest -> the runs (``redis-2#1``) that gave
        it. Empty when every seed gave the same bytes everywhere.
    """
    seen: dict[int, dict[str, list[str]]] = {}
    for run in runs:
        for o in run.outcomes:
            assert o.sha256 is not None
            label = f"{run.mode}-{run.workers}#{run.round}"
            seen.setdefault(o.seed, {}).setdefault(o.sha256, []).append(label)
    return {seed: digests for seed, digests in seen.items() if len(digests) > 1}


def machine() -> dict[str, object]:
    """The machine and the versions that matter here (``benchtools.machine``)."""

    def version(name: str) -> str:
        try:
            return metadata.version(name)
        except metadata.PackageNotFoundError:
            return "?"

    return benchtools.machine(
        quilting=quilting.__version__,
        httpx=httpx.__version__,
        fastapi=version("fastapi"),
        uvicorn=version("uvicorn"),
        dramatiq=version("dramatiq"),
        redis_py=version("redis"),
        redis_server=redis_version(),
    )


# --- main -----------------------------------------------------------------------------------


def on_sigterm(signum: int, frame: FrameType | None) -> None:
    """SIGTERM ends the benchmark like Ctrl-C: through the ``finally`` blocks that stop the
    processes it started."""
    raise SystemExit(128 + signum)


def main(argv: list[str] | None = None) -> int:
    """Run every configuration ``--repeats`` times and print the tables.

    Parameters
    ----------
    argv : list[str] or None
        Command-line arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        0, or 1 when the service misbehaved or the same seed gave different bytes.
    """
    parser = benchtools.parser(__doc__)
    parser.add_argument("--jobs", type=int, default=24, help="jobs per batch (default 24)")
    parser.add_argument("--size", type=int, default=256, help="output side (default 256)")
    parser.add_argument("--repeats", type=int, default=3, help="rounds (default 3)")
    parser.add_argument(
        "--texture",
        type=Path,
        default=DEFAULT_TEXTURE,
        help="sample PNG (default tests/data/brick.png)",
    )
    parser.add_argument(
        "--timeout", type=float, default=300.0, help="seconds a batch may take (default 300)"
    )
    parser.add_argument("--quick", action="store_true", help="8 jobs, 1 round: smoke test")
    args = parser.parse_args(argv)
    jobs, repeats = (8, 1) if args.quick else (max(1, args.jobs), max(1, args.repeats))
    if not args.texture.is_file():
        parser.error(f"no texture at {args.texture}")
    if image_format(args.texture.read_bytes()[:8]) != "png":
        parser.error(f"{args.texture} is not a PNG file")
    if not Path(REDIS_SERVER).exists():
        parser.error(f"redis-server not found ({REDIS_SERVER}); Debian package redis-server")
    signal.signal(signal.SIGTERM, on_sigterm)

    started = time.perf_counter()
    info = machine()
    benchtools.show_machine(info)
    seeds = list(range(1, jobs + 1))
    runs: list[Run] = []
    with tempfile.TemporaryDirectory(prefix="bench_scale-") as tmp:
        folder = Path(tmp)
        redis = Redis(folder)
        try:
            for round_index in range(repeats):
                # Rotated from round to round: no configuration always runs first (or last).
                shift = round_index % len(CONFIGS)
                for config in CONFIGS[shift:] + CONFIGS[:shift]:
                    print(f"round {round_index + 1}/{repeats}: {config.label} ...", file=sys.stderr)
                    server = redis if config.mode == "redis" else None
                    run = measure(
                        config, server, folder, args.texture, args.size, seeds, args.timeout,
                        round_index + 1,
                    )  # fmt: skip
                    print(f"  {run.wall_s:.3f} s, {run.jobs_per_s:.2f} jobs/s", file=sys.stderr)
                    runs.append(run)
        except ServiceError as exc:
            print(f"\nthe service misbehaved: {exc}", file=sys.stderr)
            return 1
        finally:
            redis.proc.stop()

    rows = summarize(runs)
    differing = cross_check(runs)
    print(
        f"\n{jobs} jobs of {args.size}x{args.size} from {args.texture.name} (default options, "
        f"seeds 1..{jobs}) posted at once with wait=0; median of {repeats} round(s), "
        "configurations interleaved; time = first request to the latest job's finished time; "
        f"{TIMES} 1 worker = jobs/s / the same mode's 1-worker jobs/s; {TIMES} memory = jobs/s / "
        "memory's at "
        "the same worker count\n"
    )
    print(report(rows))
    print(
        "\nmin s = fastest round; observed s = first request to the poll that saw the last job "
        "final; submit s = first request to the last 202; engine s/job = median "
        "timings.total of the jobs; workers / engine = the throughput with no overhead at all; "
        "idle ms/job = (workers x time - the jobs' started-to-finished) / jobs, the workers' "
        "time outside jobs"
    )
    if differing:
        print(f"\nSAME SEED, DIFFERENT BYTES for {len(differing)} seed(s):")
        for seed, digests in sorted(differing.items()):
            for digest, labels in digests.items():
                print(f"  seed {seed}: {digest[:16]} from {', '.join(labels)}")
    else:
        print(
            f"\nsame bytes for the same seed in every configuration and round: yes "
            f"({jobs} seeds x {len(runs)} batches)"
        )
    elapsed = benchtools.wall_time(started)
    benchtools.write_json(
        args.json,
        {
            "machine": info,
            "texture": args.texture.name,
            "size": args.size,
            "jobs": jobs,
            "repeats": repeats,
            "summary": rows,
            "same_bytes": not differing,
            "differing": {str(k): v for k, v in differing.items()},
            "runs": [
                {**asdict(r), "jobs_per_s": r.jobs_per_s, "idle_per_job_s": r.idle_per_job_s}
                for r in runs
            ],
            "wall_s": elapsed,
        },
    )
    return 1 if differing else 0


if __name__ == "__main__":
    sys.exit(main())
