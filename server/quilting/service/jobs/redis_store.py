"""Job state, progress and results in Redis: the only module that imports redis.

Every state change is one call of ``jobs.lua`` (atomic on the server), with the caps and
expiry of the in-memory :class:`~quilting.service.jobs.Store`: ``max_queued`` queued jobs,
``results_max_count`` / ``results_max_bytes`` / ``results_ttl_s`` for kept results, records of
finished jobs forgotten past ten times the result cap. Any API replica answers for any job.

:class:`RedisJobs` is the API side (asyncio client); :class:`WorkerJobs` the worker side
(blocking client, in a worker thread). A Redis that cannot be reached is a 503
``queue_unavailable`` on the API side and :data:`UNAVAILABLE` (waited out) on the worker side.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import time
from collections.abc import AsyncIterator, Mapping
from importlib import resources
from typing import Any

import redis
import redis.asyncio
from redis.backoff import ExponentialBackoff
from redis.retry import Retry

from quilting.service.jobs.model import HISTOGRAM_BUCKETS, Figures, Job, Status
from quilting.service.problems import Problem, idempotency_conflict, job_not_found, queue_full
from quilting.service.settings import Settings

#: Errors of a Redis that cannot be reached (down, restarting, too slow): transient.
UNAVAILABLE: tuple[type[Exception], ...] = (
    redis.exceptions.ConnectionError,
    redis.exceptions.TimeoutError,
)

#: Prefix of every key this module writes.
PREFIX = "quilting"

#: Seconds to connect, and to wait for an answer, before Redis counts as unreachable (the
#: default of the setting ``redis_timeout_s``).
TIMEOUT_S = 2.0

#: What a request answers while Redis is down.
RETRY_AFTER = {"Retry-After": "5"}


def _script_text() -> str:
    text = resources.files("quilting.service.jobs").joinpath("jobs.lua").read_text()
    return text.replace("__BUCKETS__", ", ".join(repr(b) for b in HISTOGRAM_BUCKETS))


def _connection_options(timeout_s: float) -> dict[str, Any]:
    # A few quick reconnects ride over a blip; a server that stays down fails fast. A server
    # that does not answer (frozen, overloaded) is not asked again: each try would cost the
    # whole timeout, and the request waiting on it would hang for their sum.
    return {
        "socket_connect_timeout": timeout_s,
        "socket_timeout": timeout_s,
        "retry": Retry(
            ExponentialBackoff(cap=0.5, base=0.05),
            2,
            supported_errors=(redis.exceptions.ConnectionError,),
        ),
        "health_check_interval": 15,
    }


def sync_client(url: str, timeout_s: float = TIMEOUT_S) -> redis.Redis:
    """A blocking client of the server at ``url`` (the worker's, and Dramatiq's broker)."""
    return redis.Redis.from_url(url, **_connection_options(timeout_s))


def owner_tag(owner: str | None) -> str:
    """What a job record keeps of its owner's API key: a digest, never the key."""
    return "" if owner is None else hashlib.sha256(owner.encode()).hexdigest()[:32]


def _record_limit(settings: Settings) -> int:
    # As the in-memory store: records outlive their results by ten times the result cap.
    return 10 * settings.results_max_count + settings.max_queued


#: A job record as the client reads it (bytes: the clients do not decode answers).
Record = Mapping[Any, Any]


def _text(fields: Record, name: str) -> str:
    raw: bytes = fields.get(name.encode(), b"")
    return raw.decode()


def _json(fields: Record, name: str) -> Any:
    raw = _text(fields, name)
    return json.loads(raw) if raw else None


def _number(fields: Record, name: str) -> float | None:
    raw = _text(fields, name)
    return float(raw) if raw else None


def job_from_record(fields: Record, owner: str | None) -> Job:
    """A :class:`Job` (without input or results) from its Redis record."""
    return Job(
        id=_text(fields, "id"),
        owner=owner,
        width=int(_text(fields, "width")),
        height=int(_text(fields, "height")),
        companion_names=_json(fields, "companions") or [],
        input=None,
        operation=_text(fields, "operation"),
        download_stem=_text(fields, "download_stem"),
        status=Status(_text(fields, "status")),
        progress=_number(fields, "progress") or 0.0,
        stage=_text(fields, "stage"),
        created=_number(fields, "created") or 0.0,
        started=_number(fields, "started"),
        finished=_number(fields, "finished"),
        timings=_json(fields, "timings") or {},
        backend=_text(fields, "backend") or None,
        renderer=_text(fields, "renderer") or None,
        fallback=_text(fields, "fallback") or None,
        error=_json(fields, "error"),
        stats=_json(fields, "stats"),
        has_layout=_text(fields, "has_layout") == "1",
        expired=_text(fields, "expired") == "1",
    )


def unavailable(exc: BaseException) -> Problem:
    """503 ``queue_unavailable``: what a request gets while Redis cannot be reached."""
    return Problem(
        503,
        "queue_unavailable",
        f"the job queue (Redis) cannot be reached: {exc}; retry later",
        headers=RETRY_AFTER,
    )


@contextlib.asynccontextmanager
async def answering() -> AsyncIterator[None]:
    """Turn an unreachable Redis into 503 ``queue_unavailable`` for the caller."""
    try:
        yield
    except UNAVAILABLE as exc:
        raise unavailable(exc) from None


class RedisJobs:
    """The API side: submit, read, cancel, count (asyncio)."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.client: redis.asyncio.Redis = redis.asyncio.Redis.from_url(
            settings.queue, **_connection_options(settings.redis_timeout_s)
        )
        self.script = self.client.register_script(_script_text())

    async def close(self) -> None:
        await self.client.aclose()

    async def _call(self, *args: Any) -> Any:
        async with answering():
            return await self.script(keys=[PREFIX], args=list(args))

    async def add(
        self, job: Job, data: bytes, idempotency: tuple[str, str] | None
    ) -> tuple[str, bool]:
        """Record a queued job with its input; ``(id, created)`` as :meth:`Store.add`."""
        idem, digest = "", ""
        if idempotency is not None:
            key, digest = idempotency
            idem = (
                f"{PREFIX}:idem:{owner_tag(job.owner)}:{hashlib.sha256(key.encode()).hexdigest()}"
            )
        fields = {
            "id": job.id,
            "owner": owner_tag(job.owner),
            "operation": job.operation,
            "download_stem": job.download_stem,
            "width": job.width,
            "height": job.height,
            "companions": json.dumps(job.companion_names),
            "progress": 0.0,
            "stage": "queued",
            "created": job.created,
            "attempt": 0,
            "cancel": 0,
            "has_layout": 0,
            "expired": 0,
        }
        pairs = [part for item in fields.items() for part in item]
        answer = await self._call(
            "add", job.id, time.time(), self.settings.max_queued, idem, digest, data, *pairs
        )
        kind = answer[0].decode()
        if kind == "conflict":
            raise idempotency_conflict()
        if kind == "full":
            raise queue_full(int(answer[1]))
        if kind == "existing":
            return answer[1].decode(), False
        return job.id, True

    async def sent(self, job_id: str) -> None:
        """Note that the job's message is in the queue (else a worker sends it again)."""
        await self._call("sent", job_id)

    async def drop(self, job_id: str) -> None:
        """Take back a queued job that no worker can have seen (its message was not sent)."""
        await self._call("drop", job_id)

    async def get(self, job_id: str, owner: str | None) -> Job:
        """The job if ``owner`` may see it, else 404 ``job_not_found``."""
        async with answering():
            await self.expire()
            fields = await self.client.hgetall(f"{PREFIX}:job:{job_id}")
        if not fields or _text(fields, "owner") != owner_tag(owner):
            raise job_not_found(job_id)
        return job_from_record(fields, owner)

    async def output(self, job: Job, name: str) -> bytes | None:
        """One kept output (``png``, ``layout`` or ``c:NAME``), or None."""
        async with answering():
            data = await self.client.hget(f"{PREFIX}:out:{job.id}", name)
        return data if isinstance(data, bytes) else None

    async def cancel(self, job: Job) -> None:
        await self._call("cancel", job.id, time.time(), _record_limit(self.settings))

    async def expire(self) -> None:
        """Drop results older than ``results_ttl_s``."""
        await self._call("expire", time.time() - self.settings.results_ttl_s)

    async def figures(self) -> Figures:
        """The counters of ``/metrics``, shared by every replica."""
        async with answering(), self.client.pipeline(transaction=False) as pipe:
            pipe.hgetall(f"{PREFIX}:stats")
            pipe.scard(f"{PREFIX}:queued")
            pipe.scard(f"{PREFIX}:running")
            stats, queued, running = await pipe.execute()
        values = {key.decode(): value.decode() for key, value in stats.items()}

        def count(name: str) -> int:
            return int(values.get(name, "0"))

        return Figures(
            counts={s.value: count(f"known:{s.value}") for s in Status},
            finished_total={s.value: count(f"total:{s.value}") for s in Status if s.final},
            seconds_buckets=[count(f"bucket:{i}") for i in range(len(HISTOGRAM_BUCKETS) + 1)],
            seconds_sum=float(values.get("seconds_sum", "0")),
            pixels_total=count("pixels_total"),
            kept_bytes=count("kept_bytes"),
            queued=int(queued),
            running=int(running),
        )

    async def workers(self) -> int:
        """Workers that sent a heartbeat within ``heartbeat_timeout_s``."""
        async with answering():
            since = time.time() - self.settings.heartbeat_timeout_s
            alive: int = await self.client.zcount(f"{PREFIX}:workers", since, "+inf")
        return alive


class WorkerJobs:
    """The worker side: claim a job, report progress, write its end (blocking client).

    Every method raises one of :data:`UNAVAILABLE` when Redis cannot be reached.
    """

    def __init__(self, settings: Settings, client: redis.Redis) -> None:
        self.settings = settings
        self.client = client
        self.script = client.register_script(_script_text())

    def _call(self, *args: Any) -> Any:
        return self.script(keys=[PREFIX], args=list(args))

    def claim(
        self, job_id: str, worker: str, abandoned: dict[str, Any]
    ) -> tuple[int, bytes] | None:
        """Start (or take over) a job: ``(attempt, input)``, or None when it is not to run.

        None when the job is final, cancelled while queued, gone, running on a worker that is
        alive (a second delivery), or has been started more than ``max_retries + 1`` times (it
        then fails with the ``abandoned`` error document).
        """
        now = time.time()
        answer = self._call(
            "claim",
            job_id,
            now,
            worker,
            self.settings.max_retries + 1,
            _record_limit(self.settings),
            json.dumps(abandoned),
            now - self.settings.heartbeat_timeout_s,
        )
        if answer[0] != b"run" or answer[2] is None:
            return None
        return int(answer[1]), bytes(answer[2])

    def progress(self, job_id: str, attempt: int, fraction: float, stage: str) -> str:
        """Record progress; ``"ok"``, ``"cancel"`` (stop) or ``"stale"`` (not ours any more)."""
        answer: bytes = self._call("progress", job_id, attempt, fraction, stage)
        return answer.decode()

    def finish(self, job_id: str, pixels: int, status: Status, fields: dict[str, Any]) -> bool:
        """Write a job's end and results under its id; False if another attempt already did.

        ``pixels`` is the output's width x height (``/metrics``); ``fields`` are those of
        :func:`quilting.service.jobs.worker.compute`.
        """
        record: dict[str, Any] = {
            "timings": json.dumps(fields.get("timings", {})),
            "backend": fields.get("backend") or "",
            "renderer": fields.get("renderer") or "",
            "fallback": fields.get("fallback") or "",
            "error": json.dumps(fields["error"]) if fields.get("error") else "",
            "stats": json.dumps(fields["stats"]) if fields.get("stats") else "",
            "has_layout": int(fields.get("layout") is not None),
        }
        outputs: list[Any] = []
        if status is Status.DONE:
            outputs += ["png", fields["png"]]
            if fields.get("layout") is not None:
                outputs += ["layout", fields["layout"]]
            for name, data in fields.get("companions", {}).items():
                outputs += [f"c:{name}", data]
        settings = self.settings
        answer: bytes = self._call(
            "finish",
            job_id,
            time.time(),
            status.value,
            _record_limit(settings),
            settings.results_max_count,
            settings.results_max_bytes,
            int(settings.results_ttl_s * 1000),
            pixels,
            len(record),
            *[part for item in record.items() for part in item],
            *outputs,
        )
        return answer == b"finished"

    def heartbeat(self, worker: str) -> int:
        """Say this worker is alive and expire old results; returns the workers alive."""
        now = time.time()
        self._call("expire", now - self.settings.results_ttl_s)
        alive: int = self._call("heartbeat", worker, now, now - self.settings.heartbeat_timeout_s)
        return alive

    def orphans(self) -> list[str]:
        """Queued jobs older than ``heartbeat_timeout_s`` whose message was never sent.

        Each is returned once (it is marked sent): the caller sends its message.
        """
        before = time.time() - self.settings.heartbeat_timeout_s
        return [job_id.decode() for job_id in self._call("orphans", before)]

    def leave(self, worker: str) -> None:
        """Take this worker off the list of the living (a clean shutdown)."""
        self._call("leave", worker)
