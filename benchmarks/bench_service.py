"""Load benchmark of the HTTP service: throughput, latency and overhead over the engine.

Starts the real server (``python -m quilting serve``) as a subprocess on a free loopback port
and measures, for 512x512 synthesis jobs (texture ``--texture``, default options, a unique seed
per job, ``POST /synthesize?wait=60`` expecting ``200 image/png``):

* **engine baseline**: the same job run in this process through ``quilting.synthesize``,
  sequentially; the median of ``Result.timings["total"]`` is the engine's own time per job;
* **single-request latency**: the same jobs (same seeds) sent one at a time to the idle server,
  interleaved with the engine runs so both see the same machine; the median client-observed
  latency against the engine median gives the service's overhead,
  ``(latency - engine) / engine``, which the issue's target (<= 15 %) applies to. The job's own
  timestamps (``GET /jobs/{id}``: created, started, finished, timings) split that latency into
  request handling before the job exists (upload, multipart parsing, decoding), queueing,
  engine, the rest of the job (PNG encoding, layout, stats) and the way back (the wait loop's
  wake-up, sending the PNG);
* **under load**: ``--clients`` concurrent clients (default 16) posting jobs back to back for
  ``--seconds`` (default 30): jobs/s, p50/p95/p99 latency, errors by status and code, and the
  theoretical capacity ``workers / engine median`` (workers from ``GET /readyz``) for
  comparison, the engine time the server reports under load, and the CPU the server process
  and the clients used (cores busy on average, from ``/proc`` on Linux).
  Requests still in flight at the deadline are abandoned, not counted (neither as done nor as
  errors); the server finishes their jobs while it drains on SIGTERM.

Client and server share the machine (the clients take some CPU from the workers), as do the
engine baseline and the idle server; compare only figures from the same run.

Run from the repository root (about a minute)::

    .venv/bin/python benchmarks/bench_service.py                  # 16 clients, 30 s
    .venv/bin/python benchmarks/bench_service.py --quick          # 4 clients, 5 s: smoke test
    .venv/bin/python benchmarks/bench_service.py --workers 2 --json service.json
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import os
import statistics
import sys
import tempfile
import time
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import benchtools
import httpx

import quilting
from quilting.io import encode_png

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
TARGET_OVERHEAD = 0.15
WAIT_S = 60.0
STARTUP_S = 60.0


# --- requests -------------------------------------------------------------------------------


@dataclass
class Job:
    """One request's client-side view; the job fields come from ``GET /jobs/{id}``."""

    seed: int
    latency_s: float
    sent: float  # unix time the request started
    received: float  # unix time the response was read
    status: int
    code: str  # "ok", or the problem code / exception name of a failure
    job_id: str | None = None
    created: float | None = None
    started: float | None = None
    finished: float | None = None
    engine_s: float | None = None


def synthesize_request(
    texture: bytes, name: str, size: int, seed: int
) -> tuple[dict[str, str], dict[str, tuple[str, bytes, str]]]:
    """The form fields and files of ``POST /synthesize`` for one job."""
    options = json.dumps({"width": size, "height": size, "seed": seed})
    return {"options": options}, {"texture": (name, texture, "image/png")}


def outcome(response: httpx.Response) -> str:
    """``"ok"`` for the expected 200 PNG, else a short description of what came back."""
    kind = response.headers.get("content-type", "")
    if response.status_code == 200 and kind.startswith("image/png"):
        return "ok"
    code = ""
    with contextlib.suppress(ValueError):
        body = response.json()
        if isinstance(body, dict):
            code = str(body.get("code") or body.get("status") or "")
    return f"{response.status_code} {code or kind}".strip()


def add_job_fields(job: Job, document: dict[str, Any]) -> None:
    job.created = document.get("created")
    job.started = document.get("started")
    job.finished = document.get("finished")
    job.engine_s = (document.get("timings") or {}).get("total")


# --- phase 1: engine and single requests, interleaved ----------------------------------------


@dataclass
class Sequential:
    engine_s: list[float] = field(default_factory=list)
    encode_s: list[float] = field(default_factory=list)  # encode_png of the result, in-process
    decode_s: list[float] = field(default_factory=list)  # read_image of the upload, in-process
    requests: list[Job] = field(default_factory=list)


def single_request(
    client: httpx.Client, url: str, texture: bytes, name: str, size: int, seed: int
) -> Job:
    data, files = synthesize_request(texture, name, size, seed)
    sent, start = time.time(), time.perf_counter()
    response = client.post(f"{url}/synthesize", params={"wait": WAIT_S}, data=data, files=files)
    latency = time.perf_counter() - start
    job = Job(seed, latency, sent, time.time(), response.status_code, outcome(response))
    job.job_id = response.headers.get("x-job-id")
    if job.job_id:
        status = client.get(f"{url}/jobs/{job.job_id}")
        if status.status_code == 200:
            add_job_fields(job, status.json())
    return job


def run_sequential(
    client: httpx.Client, url: str, texture_path: Path, size: int, repeat: int, warmup: int
) -> Sequential:
    """Engine run and server request for the same seeds, alternately, after a warm-up."""
    texture_bytes = texture_path.read_bytes()
    texture = quilting.read_image(texture_path)
    out = Sequential()
    for index in range(warmup + repeat):
        seed = index + 1
        result = quilting.synthesize(texture, (size, size), seed=seed)
        start = time.perf_counter()
        encode_png(result.image, metadata={**result.layout.meta, "width": size, "height": size})
        encoded = time.perf_counter() - start
        start = time.perf_counter()
        quilting.read_image(texture_bytes)
        decoded = time.perf_counter() - start
        job = single_request(client, url, texture_bytes, texture_path.name, size, seed)
        if job.code != "ok":
            raise RuntimeError(f"single request for seed {seed} failed: {job.code}")
        if index >= warmup:
            out.engine_s.append(result.timings["total"])
            out.encode_s.append(encoded)
            out.decode_s.append(decoded)
            out.requests.append(job)
    return out


# --- phase 2: concurrent clients ------------------------------------------------------------


@dataclass
class Load:
    clients: int
    seconds: float  # the measured window
    jobs: list[Job] = field(default_factory=list)  # answered within the window
    abandoned: int = 0  # in flight at the deadline
    server_cpu_s: float | None = None  # CPU time the server process used in the window
    client_cpu_s: float = 0.0  # CPU time this process used in the window


async def client_loop(
    client: httpx.AsyncClient,
    url: str,
    texture: bytes,
    name: str,
    size: int,
    seeds: itertools.count[int],
    deadline: float,
    load: Load,
) -> None:
    while (remaining := deadline - time.monotonic()) > 0:
        seed = next(seeds)
        data, files = synthesize_request(texture, name, size, seed)
        sent, start = time.time(), time.perf_counter()
        try:
            response = await asyncio.wait_for(
                client.post(f"{url}/synthesize", params={"wait": WAIT_S}, data=data, files=files),
                timeout=remaining,
            )
        except TimeoutError:  # cut off by the deadline: neither done nor an error
            load.abandoned += 1
            return
        except httpx.HTTPError as exc:
            latency = time.perf_counter() - start
            load.jobs.append(Job(seed, latency, sent, time.time(), 0, type(exc).__name__))
            continue
        latency = time.perf_counter() - start
        job = Job(seed, latency, sent, time.time(), response.status_code, outcome(response))
        load.jobs.append(job)
        job.job_id = response.headers.get("x-job-id")
        if job.code == "ok" and job.job_id and time.monotonic() < deadline:
            # The job's own timings (engine time under load, queueing): a cheap JSON lookup.
            with contextlib.suppress(httpx.HTTPError):
                status = await client.get(f"{url}/jobs/{job.job_id}")
                if status.status_code == 200:
                    add_job_fields(job, status.json())


def process_cpu_s(pid: int) -> float | None:
    """User + system CPU seconds of a process so far (Linux ``/proc``; None elsewhere)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


async def run_load(
    url: str, texture_path: Path, size: int, clients: int, seconds: float, server_pid: int
) -> Load:
    texture = texture_path.read_bytes()
    seeds = itertools.count(1_000_000)
    limits = httpx.Limits(max_connections=clients + 4, max_keepalive_connections=clients + 4)
    load = Load(clients, seconds)
    async with httpx.AsyncClient(timeout=WAIT_S + 30.0, limits=limits) as client:
        server_cpu, client_cpu = process_cpu_s(server_pid), time.process_time()
        start = time.monotonic()
        deadline = start + seconds
        await asyncio.gather(
            *(
                client_loop(client, url, texture, texture_path.name, size, seeds, deadline, load)
                for _ in range(clients)
            )
        )
        load.seconds = min(time.monotonic(), deadline) - start
        load.client_cpu_s = time.process_time() - client_cpu
        server_cpu_end = process_cpu_s(server_pid)
        if server_cpu is not None and server_cpu_end is not None:
            load.server_cpu_s = server_cpu_end - server_cpu
    return load


# --- report ---------------------------------------------------------------------------------


def median(values: list[float]) -> float:
    return statistics.median(values) if values else float("nan")


def breakdown(jobs: list[Job]) -> dict[str, float]:
    """Medians (seconds) of where a request's time went, from the job's own timestamps."""
    timed = [
        j
        for j in jobs
        if j.created is not None
        and j.started is not None
        and j.finished is not None
        and j.engine_s is not None
    ]

    def med(part: Any) -> float:
        return median([part(j) for j in timed])

    return {
        "jobs": float(len(timed)),
        "latency": med(lambda j: j.latency_s),
        "before_job": med(lambda j: j.created - j.sent),  # upload, parsing, decoding
        "queued": med(lambda j: j.started - j.created),
        "engine": med(lambda j: j.engine_s),
        "after_engine": med(lambda j: j.finished - j.started - j.engine_s),  # PNG, layout, stats
        "back": med(lambda j: j.received - j.finished),  # wait-loop wake-up, response
    }


def summarize(
    sequential: Sequential, load: Load, workers: int, size: int, texture: str
) -> dict[str, Any]:
    engine = median(sequential.engine_s)
    single = median([j.latency_s for j in sequential.requests])
    overhead = (single - engine) / engine
    done = [j for j in load.jobs if j.code == "ok"]
    latencies = [j.latency_s for j in done]
    errors = Counter(j.code for j in load.jobs if j.code != "ok")
    outside = [j.latency_s - j.engine_s for j in sequential.requests if j.engine_s is not None]
    return {
        "texture": texture,
        "size": size,
        "workers": workers,
        "clients": load.clients,
        "duration_s": load.seconds,
        "jobs_done": len(done),
        "errors": sum(errors.values()),
        "errors_by_code": dict(errors),
        "abandoned_at_deadline": load.abandoned,
        "server_cpu_cores": None if load.server_cpu_s is None else load.server_cpu_s / load.seconds,
        "client_cpu_cores": load.client_cpu_s / load.seconds,
        "jobs_per_s": len(done) / load.seconds,
        "p50_s": benchtools.percentile(latencies, 50),
        "p95_s": benchtools.percentile(latencies, 95),
        "p99_s": benchtools.percentile(latencies, 99),
        "capacity_jobs_per_s": workers / engine,
        "engine_median_s": engine,
        "engine_runs": len(sequential.engine_s),
        "single_latency_median_s": single,
        "overhead": overhead,
        "target_overhead": TARGET_OVERHEAD,
        "pass": overhead <= TARGET_OVERHEAD,
        "single_breakdown_s": breakdown(sequential.requests),
        "load_breakdown_s": breakdown(done),
        "outside_engine_median_s": median(outside),
        "outside_engine_share": median(
            [(j.latency_s - j.engine_s) / j.engine_s for j in sequential.requests if j.engine_s]
        ),
        "encode_png_median_s": median(sequential.encode_s),
        "decode_median_s": median(sequential.decode_s),
    }


def cores(value: float | None) -> str:
    return "?" if value is None else f"{value:.2f}"


def report(s: dict[str, Any]) -> str:
    main = benchtools.table(
        [
            "clients",
            "duration s",
            "jobs done",
            "errors",
            "jobs/s",
            "capacity jobs/s",
            "p50 s",
            "p95 s",
            "p99 s",
            "engine median s",
            "single-request s",
            "overhead",
            "target",
            "result",
        ],
        [
            [
                str(s["clients"]),
                f"{s['duration_s']:.1f}",
                str(s["jobs_done"]),
                str(s["errors"]),
                f"{s['jobs_per_s']:.2f}",
                f"{s['capacity_jobs_per_s']:.2f}",
                f"{s['p50_s']:.3f}",
                f"{s['p95_s']:.3f}",
                f"{s['p99_s']:.3f}",
                f"{s['engine_median_s']:.3f}",
                f"{s['single_latency_median_s']:.3f}",
                f"{100 * s['overhead']:+.1f} %",
                f"<= {100 * s['target_overhead']:.0f} %",
                "PASS" if s["pass"] else "MISS",
            ]
        ],
        left=0,
    )
    parts = ("latency", "before_job", "queued", "engine", "after_engine", "back")
    rows = []
    for label, key in (
        ("single request", "single_breakdown_s"),
        ("under load", "load_breakdown_s"),
    ):
        b = s[key]
        rows.append([label, str(int(b["jobs"])), *(f"{1000 * b[p]:.1f}" for p in parts)])
    split = benchtools.table(["phase", "jobs", *parts], rows, left=1)
    errors = ", ".join(f"{code}: {n}" for code, n in s["errors_by_code"].items()) or "none"
    return (
        f"{s['size']}x{s['size']} jobs from {s['texture']}, {s['workers']} server worker(s); "
        f"engine and single-request figures are medians of {s['engine_runs']} sequential runs "
        f"(same seeds); capacity = workers / engine median\n\n{main}\n\n"
        f"errors: {errors}; requests in flight at the deadline (not counted): "
        f"{s['abandoned_at_deadline']}\n"
        f"CPU under load (cores busy on average): server {cores(s['server_cpu_cores'])}, "
        f"benchmark clients {cores(s['client_cpu_cores'])}, of {os.cpu_count()}\n\n"
        "where a request's time goes (medians, ms; from the job's created/started/finished and "
        "timings.total):\nbefore_job = upload, parsing, decoding; after_engine = PNG encoding, "
        "layout, stats; back = wait-loop wake-up, sending the PNG\n\n"
        f"{split}\n\n"
        f"single request, latency minus the server's own engine time (same job): median "
        f"{1000 * s['outside_engine_median_s']:.1f} ms = "
        f"{100 * s['outside_engine_share']:+.1f} % of it\n"
        f"in-process reference: encode_png of the result {1000 * s['encode_png_median_s']:.1f} ms, "
        f"read_image of the upload {1000 * s['decode_median_s']:.1f} ms"
    )


# --- main -----------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    parser = benchtools.parser(__doc__)
    parser.add_argument("--seconds", type=float, default=30.0, help="load duration (default 30)")
    parser.add_argument("--clients", type=int, default=16, help="concurrent clients (default 16)")
    parser.add_argument("--size", type=int, default=512, help="output side (default 512)")
    parser.add_argument(
        "--texture", type=Path, default=DATA / "gravel.png", help="sample (default gravel.png)"
    )
    parser.add_argument(
        "--repeat", type=int, default=20, help="sequential engine / single-request runs (20)"
    )
    parser.add_argument(
        "--workers", type=int, default=None, help="server worker threads (default: its own)"
    )
    parser.add_argument("--quick", action="store_true", help="5 s with 4 clients: smoke test")
    args = parser.parse_args(argv)
    if args.quick:
        args.seconds, args.clients = 5.0, 4
    repeat = max(1, args.repeat)

    info = benchtools.service_machine(httpx=httpx.__version__)
    benchtools.show_machine(info)
    with tempfile.TemporaryFile() as log, benchtools.ServeProcess(log, args.workers) as server:
        workers = int(server.wait_for("/readyz", STARTUP_S).json()["workers"])
        with httpx.Client(timeout=WAIT_S + 30.0) as client:
            print(f"engine + single requests ({repeat} runs) ...", file=sys.stderr, flush=True)
            sequential = run_sequential(
                client, server.url, args.texture, args.size, repeat, warmup=2
            )
        print(f"load: {args.clients} clients for {args.seconds:g} s ...", file=sys.stderr)
        load = asyncio.run(
            run_load(
                server.url, args.texture, args.size, args.clients, args.seconds, server.process.pid
            )
        )
    summary = summarize(sequential, load, workers, args.size, args.texture.name)
    summary["server_exit_code"] = server.exit_code
    print(report(summary))
    if server.exit_code != 0:
        print(f"note: the server exited with code {server.exit_code}")
    benchtools.write_json(
        args.json,
        {
            "machine": info,
            "summary": summary,
            "engine_s": sequential.engine_s,
            "single_requests": [asdict(j) for j in sequential.requests],
            "load_requests": [asdict(j) for j in load.jobs],
        },
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
