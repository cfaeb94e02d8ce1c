"""Service settings: typed, validated, from ``QUILTING_*`` environment variables and flags.

Every limit the service enforces is a field here with a default; the README's settings table is
checked against this list by the tests.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

from quilting import InvalidParameterError

MiB = 1 << 20
GiB = 1 << 30

#: The most and the least a job's memory budget is when job_memory_bytes is 0 (derived): a
#: budget below the floor would refuse every job.
DEFAULT_MEMORY_BUDGET = 2 * GiB
MIN_MEMORY_BUDGET = 64 * MiB

#: URL schemes of a Redis server that ``queue`` accepts.
QUEUE_SCHEMES = ("redis://", "rediss://", "unix://")


def _setting(default: Any, doc: str, **limits: Any) -> Any:
    return field(default=default, metadata={"doc": doc, **limits})


@dataclass(frozen=True, kw_only=True)
class Settings:
    """Everything the service can be configured with (env ``QUILTING_<NAME>``)."""

    host: str = _setting("127.0.0.1", "Address to listen on.")
    port: int = _setting(8000, "TCP port.", ge=0, le=65535)
    workers: int = _setting(
        0, "Compute workers (jobs run at once); 0 = one per CPU core.", ge=0, le=256
    )
    worker_mode: str = _setting(
        "process",
        "process: each worker is a process (uses every core); thread: threads in the service "
        "process (lighter, but the engine holds the GIL: about one core in all).",
        choices=("process", "thread"),
    )
    backend: str = _setting(
        "auto",
        "Default cost backend of jobs: auto (gl on a hardware GPU, else fft), fft, gl "
        "or reference.",
    )
    max_queued: int = _setting(64, "Jobs waiting for a worker before 503 queue_full.", ge=1)
    results_max_count: int = _setting(256, "Finished jobs whose results are kept.", ge=1)
    results_max_bytes: int = _setting(1024 * MiB, "Total bytes of kept results.", ge=1)
    results_ttl_s: float = _setting(3600.0, "Seconds a result is kept (then 410).", ge=1.0)
    job_timeout_s: float = _setting(300.0, "A job running longer fails with job_timeout.", ge=0.1)
    job_memory_bytes: int = _setting(
        0,
        "Memory a job may use beyond what its worker process holds once started (bytes); 0 = "
        "min(2 GiB, available memory / (workers + 1)) when the service starts. A job past it "
        "fails with job_too_large (worker_mode=process: the worker's data segment is capped, "
        "RLIMIT_DATA; thread workers share the service process and are not limited). Also the "
        "budget of each sandbox call (422 image_too_costly past it).",
        ge=0,
    )
    sandbox_workers: int = _setting(
        1,
        "Processes that check uploads' pixels, make /tile images and draw seam overlays, "
        "each under job_memory_bytes and sandbox_timeout_s (the API process decodes nothing).",
        ge=1,
        le=64,
    )
    sandbox_timeout_s: float = _setting(
        20.0,
        "Seconds one sandbox call (checking a submission's images, a /tile, a seam overlay) "
        "may take: past it the process is killed and replaced and the request gets 422 "
        "image_too_costly; also the longest a request waits for a free sandbox process (503 "
        "sandbox_busy).",
        ge=0.1,
    )
    max_body_bytes: int = _setting(64 * MiB, "Largest request body (413 body_too_large).", ge=1)
    max_file_bytes: int = _setting(32 * MiB, "Largest uploaded file (413 file_too_large).", ge=1)
    max_input_pixels: int = _setting(
        25_000_000, "Most pixels an uploaded image may declare (422 image_too_large).", ge=1
    )
    max_output_pixels: int = _setting(
        67_108_864, "Most output pixels, width x height (422 invalid_parameter).", ge=1
    )
    max_side: int = _setting(16384, "Longest output side in pixels.", ge=1, le=65536)
    max_companions: int = _setting(8, "Companion maps per job.", ge=0, le=64)
    max_layers: int = _setting(8, "Texture layers per matte job.", ge=1, le=64)
    default_wait_s: float = _setting(10.0, "Default of the wait query parameter.", ge=0.0)
    max_wait_s: float = _setting(60.0, "Largest accepted wait.", ge=0.0)
    drain_grace_s: float = _setting(30.0, "On SIGTERM, how long running jobs may finish.", ge=0.0)
    api_keys: tuple[str, ...] = _setting(
        (), "Comma-separated API keys; when set, every job endpoint needs one (401)."
    )
    metrics_public: bool = _setting(
        False,
        "Serve /metrics without an API key even when QUILTING_API_KEYS is set (a scraper "
        "without a key); false: /metrics needs a key like the job endpoints.",
    )
    request_timeout_s: float = _setting(
        30.0,
        "Seconds a client has to send its whole request body; a slower one is dropped "
        "(408 request_timeout).",
        ge=0.1,
    )
    cors_origins: tuple[str, ...] = _setting((), "Comma-separated origins allowed by CORS.")
    web_page: bool = _setting(True, "Serve the browser page at / (false: the HTTP API alone).")
    queue: str = _setting(
        "memory",
        "Where jobs live: memory (this process computes them) or a Redis URL "
        "(redis://host:6379/0): jobs, progress and results in Redis, computed by "
        "`quilting worker` processes; any API replica answers for any job.",
    )
    heartbeat_timeout_s: float = _setting(
        60.0,
        "Distributed queue: a worker silent this long is taken for dead and its job is run "
        "again by another worker.",
        ge=1.0,
    )
    redis_timeout_s: float = _setting(
        2.0,
        "Distributed queue: seconds to connect to Redis, and to wait for each answer, before "
        "a request gets 503 queue_unavailable.",
        ge=0.1,
    )
    max_retries: int = _setting(
        3,
        "Distributed queue: how many times a job is run again after its worker died, before "
        "it fails with job_abandoned.",
        ge=0,
        le=100,
    )

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            choices = f.metadata.get("choices")
            if choices is not None and value not in choices:
                raise InvalidParameterError(f.name, value, "one of " + ", ".join(choices))
            lo, hi = f.metadata.get("ge"), f.metadata.get("le")
            if (lo is not None and value < lo) or (hi is not None and value > hi):
                allowed = f"{lo}..{hi}" if hi is not None else f">= {lo}"
                raise InvalidParameterError(f.name, value, allowed)
        if self.max_wait_s < self.default_wait_s:
            raise InvalidParameterError(
                "max_wait_s", self.max_wait_s, f">= default_wait_s ({self.default_wait_s})"
            )
        if self.queue != "memory" and not self.queue.startswith(QUEUE_SCHEMES):
            scheme = self.queue.partition("://")[0]  # never echo a password in the URL
            raise InvalidParameterError(
                "queue", f"{scheme}://...", "memory or a Redis URL (redis://, rediss://, unix://)"
            )
        if any(not key or "," in key for key in self.api_keys):
            raise InvalidParameterError("api_keys", "...", "non-empty keys without commas")

    @property
    def compute_workers(self) -> int:
        """Worker threads actually started."""
        return self.workers or (os.cpu_count() or 1)

    @property
    def memory_budget(self) -> int:
        """The memory budget of a job and of a sandbox call in bytes: ``job_memory_bytes``,
        or when that is 0, min(2 GiB, available memory / (workers + 1)) (the API process and
        every worker get a share; read from ``/proc/meminfo`` when asked, 2 GiB where it
        cannot be read), and at least 64 MiB."""
        if self.job_memory_bytes:
            return self.job_memory_bytes
        available = available_memory()
        if available is None:
            return DEFAULT_MEMORY_BUDGET
        share = available // (self.compute_workers + 1)
        return max(MIN_MEMORY_BUDGET, min(DEFAULT_MEMORY_BUDGET, share))

    @classmethod
    def from_env(cls, environ: Mapping[str, str] | None = None, **overrides: Any) -> Settings:
        """Settings from ``QUILTING_*`` variables, then ``overrides`` (flags) on top.

        A value that does not parse raises :class:`InvalidParameterError` naming the variable.
        """
        environ = os.environ if environ is None else environ
        values: dict[str, Any] = {}
        for f in fields(cls):
            name = "QUILTING_" + f.name.upper()
            if name not in environ:
                continue
            raw = environ[name].strip()
            kind: Any = type(f.default)
            try:
                if kind is tuple:
                    values[f.name] = tuple(p.strip() for p in raw.split(",") if p.strip())
                elif kind is bool:
                    values[f.name] = _boolean(raw)
                else:
                    values[f.name] = kind(raw)
            except ValueError:
                raise InvalidParameterError(name, raw, f"a {kind.__name__}") from None
        values.update({k: v for k, v in overrides.items() if v is not None})
        return replace(cls(), **values)


def available_memory() -> int | None:
    """Bytes of memory the kernel says are available (``MemAvailable``), or None where
    ``/proc/meminfo`` cannot be read (not Linux)."""
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _boolean(raw: str) -> bool:
    word = raw.lower()
    if word not in ("1", "true", "yes", "on", "0", "false", "no", "off"):
        raise ValueError(raw)
    return word in ("1", "true", "yes", "on")


def describe() -> list[tuple[str, str, Any, str]]:
    """``(field, environment variable, default, doc)`` of every setting, for docs and tests."""
    return [
        (f.name, "QUILTING_" + f.name.upper(), f.default, str(f.metadata["doc"]))
        for f in fields(Settings)
    ]
