"""Soak benchmark of the HTTP service: memory growth and errors over a long, mixed load.

Issue 19's acceptance asks for "a 30-minute soak (bounded, two clients, in-memory mode, in a
benchmark, not a test): memory growth after warm-up < 5 %, 0 errors". This script is that soak:
it runs for ``--minutes`` (default 30) and is far too long for the test suite.

It starts the service the way a user does (``python -m quilting serve --port <free port>``, the
settings as ``QUILTING_*`` environment variables: in-memory queue, worker processes, the
default worker count, results kept bounded by ``QUILTING_RESULTS_MAX_COUNT`` and
``QUILTING_RESULTS_TTL_S``), waits for ``/readyz``, and lets ``--clients`` (default 2)
threads, each with its own ``httpx.Client``, loop over a mix of what users do:

* syntheses of small textures from ``tests/data`` (128² crops to 256², gray, RGB and RGBA
  (alpha mode), tileable, walk and random modes now and then) into 256²..1024² outputs with
  various block sizes and seeds, answered at once (``?wait=60``) or followed by polling
  ``GET /jobs/{id}`` or by the server-sent events of ``GET /jobs/{id}/events`` (then a
  reconnect with ``Last-Event-ID`` that must give 204);
* downloads of the result, the layout, the seams and a quilted companion map
  (``brick.png`` with ``brick_normal.png``);
* transfers of a texture onto ``examples/cat.png`` and camera targets, texture matting of
  ``examples/matte_target.png`` (its normals companion; its layout must be 404) and ``/tile``;
* cancels (``DELETE``) of long jobs, while they run or just after submission; the job must end
  ``cancelled`` (or ``done`` when the cancel came too late) and its result answer 409;
* idempotent resubmits: the same body under the same ``Idempotency-Key`` must return the same
  job, another body under it 409 ``idempotency_conflict``;
* bad requests that must give the right 4xx status and problem ``code`` (bad options, options
  that are not JSON or nest too deep, a file that is not an image, a repeated part, a wait over
  the limit, an unknown job, a wrong method, a bad seam colour...);
* results of jobs that finished ``2 x results_max_count`` jobs ago: 410 ``result_expired``
  (404 once the job's record is forgotten too): retention is bounded.

Every answer is checked (status, problem code, content type, PNG size, job id, final status):
a 5xx, a timeout, a transport error, an unexpected status or body, a job that does not finish
within ``QUILTING_JOB_TIMEOUT_S + 60`` s (lost), a traceback or ERROR line in the server's log
and a non-zero exit of the server after its SIGTERM drain all count as errors.

Every ``--interval`` seconds (default 2) a sampler thread reads ``VmRSS`` (``/proc/<pid>/status``)
of the API process and of every process below it (the worker processes and multiprocessing's
resource tracker, from ``/proc/<pid>/task/*/children``, or from the parent ids in
``/proc/*/stat`` where the kernel has no such files) and times ``GET /healthz``.
After the warm-up (``--warmup-minutes``, default 20 % of the run and at least 2 minutes, at
most 70 % of it), memory growth is ``(median of the last window - median of the first window
after warm-up) / the latter``, each window 10 % of the run's samples (at least 3), for the API
process and for the total of all processes (the workers' own figure is shown, not judged).

Printed: a machine line, the settings, then markdown tables of the run (duration, requests,
errors, throughput), the requests by kind (count, errors, median / p95 / max latency) and the
memory (RSS at warm-up end, at the end, growth, target, result). The exit status is 1 when
there was any error or a growth of 5 % or more, else 0.

The clients share the machine with the server (their CPU time is printed); the workers keep
every core busy for the whole run.

Run from the repository root::

    .venv/bin/python benchmarks/bench_soak.py                  # 30 minutes: the acceptance run
    .venv/bin/python benchmarks/bench_soak.py --minutes 3      # a short check (2 min warm-up)
    .venv/bin/python benchmarks/bench_soak.py --json soak.json # also every sample and request
"""

from __future__ import annotations

import collections
import contextlib
import json
import os
import random
import re
import statistics
import sys
import tempfile
import threading
import time
import uuid
from collections import Counter
from collections.abc import Callable, Collection, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import benchtools
import httpx
import numpy as np

import quilting
from quilting.io import encode_png

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
EXAMPLES = ROOT / "examples"

#: Settings of the server under test (``QUILTING_*``); the rest are the service's defaults.
RESULTS_MAX_COUNT = 16
RESULTS_TTL_S = 120.0
MAX_QUEUED = 64
JOB_TIMEOUT_S = 120.0
MAX_WAIT_S = 60.0

WAIT_S = 60.0  # ?wait= of the requests answered at once
HTTP_TIMEOUT_S = WAIT_S + 30.0
LOST_S = JOB_TIMEOUT_S + 60.0  # a job not final this long after its submission is lost
POLL_S = 0.2
STARTUP_S = 120.0
TARGET_GROWTH = 0.05
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
FINAL = ("done", "failed", "cancelled")

#: What a client does, and how often (relative weights). Every client runs each once first.
WEIGHTS: dict[str, int] = {
    "synth_wait": 24,
    "synth_poll": 14,
    "synth_events": 8,
    "synth_companion": 5,
    "transfer": 10,
    "matte": 3,
    "tile": 8,
    "cancel": 6,
    "idempotent": 6,
    "bad_request": 12,
    "retention": 4,
}


# --- the uploads ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Image:
    """An upload: its file name, bytes and size."""

    name: str
    data: bytes
    width: int
    height: int
    rgba: bool = False


def png_size(data: bytes) -> tuple[int, int] | None:
    """``(width, height)`` from a PNG's IHDR chunk, or None when ``data`` is not a PNG."""
    if len(data) < 24 or not data.startswith(PNG_SIGNATURE) or data[12:16] != b"IHDR":
        return None
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def load(path: Path) -> Image:
    data = path.read_bytes()
    size = png_size(data)
    assert size is not None, f"{path} is not a PNG"
    array = quilting.read_image(data)
    rgba = array.ndim == 3 and array.shape[2] == 4
    return Image(path.name, data, *size, rgba=rgba)


def crop(path: Path, side: int, name: str) -> Image:
    """A ``side`` x ``side`` crop of the middle of an image, as a PNG."""
    array = quilting.read_image(path)
    top, left = (array.shape[0] - side) // 2, (array.shape[1] - side) // 2
    data = encode_png(np.ascontiguousarray(array[top : top + side, left : left + side]))
    return Image(name, data, side, side)


@dataclass(frozen=True)
class Media:
    """Everything the clients upload, read once."""

    textures: list[Image]
    transfer_textures: list[Image]
    targets: list[Image]
    tiles: list[Image]
    brick: Image
    brick_normal: Image
    hubble: Image
    matte_target: Image
    silhouette: Image
    cloud: Image

    @classmethod
    def read(cls) -> Media:
        brick, gravel, grass = (
            load(DATA / "brick.png"),
            load(DATA / "gravel.png"),
            load(DATA / "grass.png"),
        )
        hubble, wood, cloud = (
            load(DATA / "hubble.png"),
            load(DATA / "wood.png"),
            load(DATA / "cloud_rgba.png"),
        )
        hubble128 = crop(DATA / "hubble.png", 128, "hubble128.png")
        gravel128 = crop(DATA / "gravel.png", 128, "gravel128.png")
        return cls(
            textures=[brick, gravel, grass, hubble, wood, cloud, hubble128, gravel128],
            transfer_textures=[gravel, brick, wood, grass, hubble128],
            targets=[
                load(EXAMPLES / "cat.png"),
                load(DATA / "target_camera.png"),
                load(EXAMPLES / "camera.png"),
            ],
            tiles=[grass, gravel, wood, hubble, brick],
            brick=load(EXAMPLES / "brick.png"),
            brick_normal=load(EXAMPLES / "brick_normal.png"),
            hubble=hubble,
            matte_target=load(EXAMPLES / "matte_target.png"),
            silhouette=load(EXAMPLES / "matte_silhouette.png"),
            cloud=load(EXAMPLES / "cloud_rgba.png"),
        )


def part(image: Image) -> tuple[str, bytes, str]:
    return image.name, image.data, "image/png"


# --- the server under test ------------------------------------------------------------------


def server_environment() -> dict[str, str]:
    """This process's environment without its ``QUILTING_*`` variables, plus the soak's."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("QUILTING_")}
    env.update(
        QUILTING_QUEUE="memory",
        QUILTING_WORKER_MODE="process",
        QUILTING_RESULTS_MAX_COUNT=str(RESULTS_MAX_COUNT),
        QUILTING_RESULTS_TTL_S=str(RESULTS_TTL_S),
        QUILTING_MAX_QUEUED=str(MAX_QUEUED),
        QUILTING_JOB_TIMEOUT_S=str(JOB_TIMEOUT_S),
        QUILTING_MAX_WAIT_S=str(MAX_WAIT_S),
    )
    return env


def log_problems(text: str) -> list[str]:
    """Lines of the server's log that show something went wrong: tracebacks, uvicorn's ERROR
    lines, and the service's own warnings (printed bare: ``quilting serve`` configures no
    handler for them), such as a worker process that died or a job that failed unexpectedly."""
    signs = (" died ", "failed unexpectedly", "shut down", "Exception in ")
    found: list[str] = []
    in_traceback = False
    for line in text.splitlines():
        if in_traceback:
            if line[:1].isspace():
                continue
            in_traceback = False
            found[-1] += ": " + line  # the exception that ended the traceback
            continue
        if line.startswith("Traceback"):
            in_traceback = True
            found.append("Traceback")
        elif line.startswith(("ERROR", "CRITICAL")) or any(s in line for s in signs):
            found.append(line)
    return found


def grouped(lines: list[str]) -> Counter[str]:
    """Lines counted with their job ids (32 hex digits) blanked, so one cause is one line."""
    return Counter(re.sub(r"\b[0-9a-f]{32}\b", "<id>", line) for line in lines)


# --- memory ---------------------------------------------------------------------------------


def rss_bytes(pid: int) -> int | None:
    """``VmRSS`` of a process in bytes, None once it is gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _children_files_work() -> bool:
    me = os.getpid()
    return Path(f"/proc/{me}/task/{me}/children").exists()


CHILDREN_FILES = _children_files_work()


def children(pid: int) -> list[int]:
    """Direct children of ``pid``: from ``/proc/<pid>/task/*/children`` where the kernel has
    them, else from the parent id in every ``/proc/<n>/stat``."""
    if CHILDREN_FILES:
        found: list[int] = []
        with contextlib.suppress(OSError):
            for task in Path(f"/proc/{pid}/task").iterdir():
                with contextlib.suppress(OSError):
                    found += [int(c) for c in (task / "children").read_text().split()]
        return found
    found = []
    with os.scandir("/proc") as entries:
        for entry in entries:
            if not entry.name.isdigit():
                continue
            try:
                stat = Path(f"/proc/{entry.name}/stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(entry.name))
    return found


def descendants(root: int) -> list[int]:
    out: list[int] = []
    todo = [root]
    while todo:
        kids = children(todo.pop())
        out += kids
        todo += kids
    return out


def is_helper(pid: int) -> bool:
    """multiprocessing's resource tracker (not a worker)."""
    try:
        return b"resource_tracker" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return False


@dataclass
class Sample:
    t: float  # seconds since the load began
    api: int  # bytes
    workers: int  # bytes, all worker processes
    helpers: int  # bytes, the resource tracker
    worker_pids: list[int]

    @property
    def total(self) -> int:
        return self.api + self.workers + self.helpers


def sample(api_pid: int, t: float) -> Sample | None:
    api = rss_bytes(api_pid)
    if api is None:
        return None
    workers = helpers = 0
    pids = []
    for pid in descendants(api_pid):
        rss = rss_bytes(pid)
        if rss is None:
            continue
        if is_helper(pid):
            helpers += rss
        else:
            workers += rss
            pids.append(pid)
    return Sample(t, api, workers, helpers, sorted(pids))


# --- bookkeeping ----------------------------------------------------------------------------


@dataclass
class Kind:
    requests: int = 0
    errors: int = 0
    seconds: list[float] = field(default_factory=list)


class Recorder:
    """Requests by kind, errors, job outcomes; shared by the client threads."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.kinds: dict[str, Kind] = collections.defaultdict(Kind)
        self.errors: list[str] = []
        self.jobs: Counter[str] = Counter()  # final statuses seen
        self.actions: Counter[str] = Counter()
        self.cases: Counter[str] = Counter()  # bad requests by case
        self.notes: Counter[str] = Counter()  # cancels too late and the like

    def add(self, kind: str, seconds: float, error: str | None = None) -> None:
        with self.lock:
            entry = self.kinds[kind]
            entry.requests += 1
            entry.seconds.append(seconds)
            if error is not None:
                entry.errors += 1
                self.errors.append(f"{kind}: {error}")

    def fail(self, kind: str, error: str) -> None:
        """An error found in an answer already counted (its body, a lost job...)."""
        with self.lock:
            self.kinds[kind].errors += 1
            self.errors.append(f"{kind}: {error}")

    def count(self, counter: str, key: str) -> None:
        with self.lock:
            getattr(self, counter)[key] += 1

    @property
    def error_count(self) -> int:
        with self.lock:
            return sum(k.errors for k in self.kinds.values())


class Ledger:
    """Order of the jobs submitted and finished (all clients): which results must be gone."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.submitted = 0
        self.done_count = 0
        self.index: collections.OrderedDict[str, int] = collections.OrderedDict()
        self.done: collections.deque[tuple[str, int, int]] = collections.deque(maxlen=2000)
        self.seen_done: set[str] = set()

    def submit(self, job_id: str) -> bool:
        """Count a job; False when it was known already (an idempotent repeat)."""
        with self.lock:
            if job_id in self.index:
                return False
            self.submitted += 1
            self.index[job_id] = self.submitted
            while len(self.index) > 5000:
                self.index.popitem(last=False)
            return True

    def finished(self, job_id: str) -> None:
        with self.lock:
            if job_id in self.seen_done or job_id not in self.index:
                return
            self.seen_done.add(job_id)
            self.done_count += 1
            self.done.append((job_id, self.index[job_id], self.done_count))

    def evicted(self, rng: random.Random) -> tuple[str, int] | None:
        """A done job whose result was pushed out by ``results_max_count`` later ones (with a
        margin for the clients' order), and how many jobs were submitted since it."""
        with self.lock:
            gone = [
                (job_id, submitted)
                for job_id, submitted, done in self.done
                if self.done_count - done >= 2 * RESULTS_MAX_COUNT + 4
            ]
            if not gone:
                return None
            job_id, submitted = rng.choice(gone)
            return job_id, self.submitted - submitted


def problem_code(response: httpx.Response) -> str | None:
    if not response.headers.get("content-type", "").startswith("application/problem+json"):
        return None
    with contextlib.suppress(ValueError):
        body = response.json()
        if isinstance(body, dict):
            return str(body.get("code"))
    return None


# --- a client -------------------------------------------------------------------------------


JOB = "GET /jobs/{id}"
BAD = "bad request (4xx expected)"


class SoakClient:
    """One user of the service: a loop of actions until the deadline, every answer checked."""

    def __init__(
        self,
        index: int,
        url: str,
        media: Media,
        recorder: Recorder,
        ledger: Ledger,
        seed: int,
    ) -> None:
        self.index = index
        self.url = url
        self.media = media
        self.recorder = recorder
        self.ledger = ledger
        self.rng = random.Random(seed * 1000 + index)
        self.http = httpx.Client(base_url=url, timeout=HTTP_TIMEOUT_S)
        self.last_done: str | None = None  # a done job of this client (seams, DELETE checks)
        self.cpu_s = 0.0

    # --- requests ----------------------------------------------------------------------

    def call(
        self,
        kind: str,
        method: str,
        path: str,
        expect: Collection[int],
        *,
        code: str | Collection[str] | None = None,
        **kwargs: Any,
    ) -> httpx.Response | None:
        """One request; None (and an error recorded) unless its status is in ``expect`` and,
        for a problem, its code is ``code`` (or one of them)."""
        start = time.perf_counter()
        try:
            response = self.http.request(method, path, **kwargs)
        except httpx.TimeoutException as exc:
            self.recorder.add(kind, time.perf_counter() - start, f"timeout ({exc!r}) {path}")
            return None
        except httpx.HTTPError as exc:
            self.recorder.add(kind, time.perf_counter() - start, f"{exc!r} {path}")
            return None
        elapsed = time.perf_counter() - start
        got = problem_code(response)
        error = None
        if response.status_code not in expect:
            error = (
                f"{method} {path}: {response.status_code} {got or response.text[:200]!r} "
                f"(expected {sorted(expect)})"
            )
        elif code is not None and response.status_code >= 400:
            wanted = {code} if isinstance(code, str) else set(code)
            if got not in wanted:
                error = f"{method} {path}: {response.status_code} code {got!r}, expected {wanted}"
        self.recorder.add(kind, elapsed, error)
        return None if error else response

    def check(self, kind: str, ok: bool, error: str) -> bool:
        if not ok:
            self.recorder.fail(kind, error)
        return ok

    def check_png(self, kind: str, response: httpx.Response, size: tuple[int, int]) -> bool:
        kind_ok = response.headers.get("content-type", "").startswith("image/png")
        got = png_size(response.content)
        return self.check(
            kind,
            kind_ok and got == size,
            f"expected a {size[0]}x{size[1]} PNG, got {response.headers.get('content-type')} "
            f"of size {got}",
        )

    def submit(
        self,
        path: str,
        options: dict[str, Any] | str,
        files: list[tuple[str, tuple[str, bytes, str]]],
        wait: float,
        headers: dict[str, str] | None = None,
        kind: str | None = None,
    ) -> tuple[httpx.Response, str] | None:
        """POST a job: the answer (200 with the PNG or 202) and the job's id."""
        kind = kind or f"POST {path}"
        text = options if isinstance(options, str) else json.dumps(options)
        response = self.call(
            kind,
            "POST",
            path,
            (200, 202),
            params={"wait": wait},
            data={"options": text},
            files=files,
            headers=headers,
        )
        if response is None:
            return None
        job_id = response.headers.get("x-job-id", "")
        if not self.check(kind, bool(job_id), "no X-Job-Id header"):
            return None
        location = response.headers.get("location")
        if not self.check(kind, location == f"/jobs/{job_id}", f"Location {location!r}"):
            return None
        self.ledger.submit(job_id)
        return response, job_id

    def follow(self, job_id: str, submitted: float) -> dict[str, Any] | None:
        """Poll the job until it is final; None (an error) when it is lost."""
        while True:
            response = self.call(JOB, "GET", f"/jobs/{job_id}", (200,))
            if response is None:
                return None
            document: dict[str, Any] = response.json()
            if document.get("status") in FINAL:
                return document
            if time.monotonic() - submitted > LOST_S:
                self.recorder.fail(
                    JOB, f"lost job {job_id}: still {document.get('status')} after {LOST_S:g} s"
                )
                return None
            time.sleep(POLL_S)

    def outcome(self, kind: str, job_id: str, document: dict[str, Any], wanted: str) -> bool:
        status = document.get("status", "?")
        self.recorder.count("jobs", status)
        if status == "done":
            self.ledger.finished(job_id)
            self.last_done = job_id
        return self.check(
            kind, status == wanted, f"job {job_id} ended {status}: {document.get('error')}"
        )

    def job_result(
        self,
        path: str,
        options: dict[str, Any],
        files: list[tuple[str, tuple[str, bytes, str]]],
        size: tuple[int, int],
        wait: float,
    ) -> str | None:
        """Submit, follow unless answered at once, check the PNG; the id of the done job."""
        kind = f"POST {path}"
        submitted = time.monotonic()
        answer = self.submit(path, options, files, wait)
        if answer is None:
            return None
        response, job_id = answer
        if response.status_code == 200:
            self.recorder.count("jobs", "done")
            self.ledger.finished(job_id)
            self.last_done = job_id
            return job_id if self.check_png(kind, response, size) else None
        document = self.follow(job_id, submitted)
        if document is None or not self.outcome(kind, job_id, document, "done"):
            return None
        self.check(JOB, document.get("result") == f"/jobs/{job_id}/result", "no result link")
        result = self.call("GET /jobs/{id}/result", "GET", f"/jobs/{job_id}/result", (200,))
        if result is None or not self.check_png("GET /jobs/{id}/result", result, size):
            return None
        return job_id

    # --- the mix -----------------------------------------------------------------------

    def synth_options(self, texture: Image, big: bool = True) -> dict[str, Any]:
        rng = self.rng
        sides = [256, 320, 384, 512, 640, 768, 1024] if big else [256, 320, 384, 512]
        if texture.rgba:
            sides = [256, 320, 384, 512]
        width, height = rng.choice(sides), rng.choice(sides)
        side = min(texture.width, texture.height)
        blocks = [b for b in (24, 32, 40, 48, 64) if b <= side]
        if width * height > 512 * 512:
            blocks = [b for b in blocks if b >= 40] or blocks[-1:]
        options: dict[str, Any] = {
            "width": width,
            "height": height,
            "block": rng.choice(blocks),
            "seed": rng.randrange(2**32),
        }
        if not texture.rgba:
            variant = rng.random()
            if variant < 0.10:
                options["tileable"] = rng.choice(["both", "x", "y"])
            elif variant < 0.15:
                options["mode"] = "walk"
            elif variant < 0.20:
                options["mode"] = rng.choice(["random", "overlap"])
            elif variant < 0.25:
                options["error"] = "luminance"
        return options

    def act_synth_wait(self) -> None:
        texture = self.rng.choice(self.media.textures)
        options = self.synth_options(texture)
        size = (options["width"], options["height"])
        self.job_result("/synthesize", options, [("texture", part(texture))], size, WAIT_S)

    def act_synth_poll(self) -> None:
        texture = self.rng.choice(self.media.textures)
        options = self.synth_options(texture)
        size = (options["width"], options["height"])
        job_id = self.job_result("/synthesize", options, [("texture", part(texture))], size, 0)
        if job_id is None:
            return
        layout = self.call("GET /jobs/{id}/layout", "GET", f"/jobs/{job_id}/layout", (200,))
        if layout is not None:
            try:
                ok = isinstance(json.loads(layout.content), dict)
            except ValueError:
                ok = False
            self.check("GET /jobs/{id}/layout", ok, "the layout is not a JSON object")
        if self.rng.random() < 0.5:
            seams = self.call("GET /jobs/{id}/seams", "GET", f"/jobs/{job_id}/seams", (200,))
            if seams is not None:
                self.check_png("GET /jobs/{id}/seams", seams, size)

    def act_synth_events(self) -> None:
        texture = self.rng.choice(self.media.textures)
        options = self.synth_options(texture)
        size = (options["width"], options["height"])
        answer = self.submit("/synthesize", options, [("texture", part(texture))], 0)
        if answer is None:
            return
        _, job_id = answer
        kind = "GET /jobs/{id}/events"
        events = self.events(job_id)
        if events is None:
            return
        ids = [event_id for event_id, _, _ in events]
        self.check(kind, ids == sorted(set(ids)), f"event ids not increasing: {ids}")
        if not self.check(kind, bool(events), "no event"):
            return
        last_id, name, data = events[-1]
        try:
            document = json.loads(data)
        except ValueError:
            document = {}
        if not self.check(kind, name in FINAL, f"the stream ended with {name!r}"):
            return
        if not self.outcome(kind, job_id, document, "done"):
            return
        self.call(
            kind,
            "GET",
            f"/jobs/{job_id}/events",
            (204,),
            headers={"Last-Event-ID": str(last_id)},
        )
        result = self.call("GET /jobs/{id}/result", "GET", f"/jobs/{job_id}/result", (200,))
        if result is not None:
            self.check_png("GET /jobs/{id}/result", result, size)

    def events(self, job_id: str) -> list[tuple[int, str, str]] | None:
        """The server-sent events of a job until the stream ends: (id, event, data)."""
        kind = "GET /jobs/{id}/events"
        events: list[tuple[int, str, str]] = []
        start = time.perf_counter()
        try:
            with self.http.stream("GET", f"/jobs/{job_id}/events") as response:
                if response.status_code != 200:
                    response.read()
                    self.recorder.add(
                        kind, time.perf_counter() - start, f"{response.status_code} (expected 200)"
                    )
                    return None
                current: dict[str, str] = {}
                for line in response.iter_lines():
                    if not line:
                        if "event" in current:
                            event_id = int(current.get("id", "-1"))
                            events.append((event_id, current["event"], current.get("data", "")))
                        current = {}
                        continue
                    name, _, value = line.partition(":")
                    current[name] = value[1:] if value.startswith(" ") else value
        except (httpx.HTTPError, ValueError) as exc:
            self.recorder.add(kind, time.perf_counter() - start, f"{exc!r}")
            return None
        self.recorder.add(kind, time.perf_counter() - start)
        return events

    def act_synth_companion(self) -> None:
        brick, normal = self.media.brick, self.media.brick_normal
        options = self.synth_options(brick, big=False)
        size = (options["width"], options["height"])
        files = [("texture", part(brick)), ("companion", part(normal))]
        job_id = self.job_result("/synthesize", options, files, size, WAIT_S)
        if job_id is None:
            return
        name = normal.name.rsplit(".", 1)[0]
        kind = "GET /jobs/{id}/result/{name}"
        response = self.call(kind, "GET", f"/jobs/{job_id}/result/{name}", (200,))
        if response is not None:
            self.check_png(kind, response, size)

    def act_transfer(self) -> None:
        rng = self.rng
        texture = rng.choice(self.media.transfer_textures)
        target = rng.choice(self.media.targets)
        options: dict[str, Any] = {"iterations": rng.choice([1, 1, 2]), "seed": rng.randrange(999)}
        if rng.random() < 0.5:
            options["block"] = rng.choice([16, 24, 32])
        files = [("texture", part(texture)), ("target", part(target))]
        wait = WAIT_S if rng.random() < 0.6 else 0
        job_id = self.job_result("/transfer", options, files, (target.width, target.height), wait)
        if job_id is not None and rng.random() < 0.3:
            self.call("GET /jobs/{id}/layout", "GET", f"/jobs/{job_id}/layout", (200,))

    def act_matte(self) -> None:
        media, rng = self.media, self.rng
        layers = [media.brick] if rng.random() < 0.5 else [media.brick, media.cloud]
        files = [("target", part(media.matte_target)), ("silhouette", part(media.silhouette))]
        files += [("layer", part(layer)) for layer in layers]
        options = {"clusters": 8, "light": [-1, 1, 2], "seed": rng.randrange(999)}
        size = (media.matte_target.width, media.matte_target.height)
        job_id = self.job_result("/matte", options, files, size, WAIT_S)
        if job_id is None:
            return
        kind = "GET /jobs/{id}/result/{name}"
        response = self.call(kind, "GET", f"/jobs/{job_id}/result/normals", (200,))
        if response is not None:
            self.check_png(kind, response, size)
        self.call(BAD, "GET", f"/jobs/{job_id}/layout", (404,), code="no_layout")
        self.recorder.count("cases", "matte_layout")

    def act_tile(self) -> None:
        image = self.rng.choice(self.media.tiles)
        options = json.dumps({"axes": self.rng.choice(["both", "x", "y"])})
        response = self.call(
            "POST /tile",
            "POST",
            "/tile",
            (200,),
            data={"options": options},
            files=[("image", part(image))],
        )
        if response is not None:
            self.check_png("POST /tile", response, (image.width, image.height))

    def act_cancel(self) -> None:
        """A long job cancelled while it runs (or at once): it must end cancelled, or done
        when the cancel came too late, and the next jobs must not suffer."""
        options = {"width": 1024, "height": 1024, "block": 24, "seed": self.rng.randrange(999)}
        submitted = time.monotonic()
        answer = self.submit("/synthesize", options, [("texture", part(self.media.hubble))], 0)
        if answer is None:
            return
        _, job_id = answer
        if self.rng.random() < 0.7:  # wait until the engine is at work
            while time.monotonic() - submitted < 30:
                response = self.call(JOB, "GET", f"/jobs/{job_id}", (200,))
                if response is None:
                    return
                document = response.json()
                if document["status"] != "queued" and document["progress"] > 0:
                    break
                time.sleep(0.1)
        kind = "DELETE /jobs/{id}"
        response = self.call(kind, "DELETE", f"/jobs/{job_id}", (202, 409), code="job_finished")
        if response is None:
            return
        final = self.follow(job_id, submitted)
        if final is None:
            return
        status = final["status"]
        if response.status_code == 409 or status == "done":
            self.recorder.count("notes", "cancel too late (job done)")
            self.outcome(kind, job_id, final, "done")
            return
        self.outcome(kind, job_id, final, "cancelled")
        self.recorder.count("notes", "cancelled")
        self.call(BAD, "GET", f"/jobs/{job_id}/result", (409,), code="job_cancelled")
        self.recorder.count("cases", "result_of_cancelled")

    def act_idempotent(self) -> None:
        texture = self.rng.choice(self.media.textures)
        options = self.synth_options(texture, big=False)
        size = (options["width"], options["height"])
        key = {"Idempotency-Key": f"soak-{self.index}-{uuid.uuid4().hex}"}
        files = [("texture", part(texture))]
        submitted = time.monotonic()
        first = self.submit("/synthesize", options, files, 0, headers=key)
        if first is None:
            return
        _, job_id = first
        kind = "POST /synthesize (same Idempotency-Key)"
        again = self.submit("/synthesize", options, files, WAIT_S, headers=key, kind=kind)
        if again is None:
            return
        response, same = again
        if not self.check(kind, same == job_id, f"another job {same} for the key of {job_id}"):
            return
        if response.status_code == 200:
            self.recorder.count("jobs", "done")
            self.ledger.finished(job_id)
            self.check_png(kind, response, size)
        else:
            document = self.follow(job_id, submitted)
            if document is None or not self.outcome(kind, job_id, document, "done"):
                return
        other = {**options, "seed": options["seed"] + 1}
        self.call(
            BAD,
            "POST",
            "/synthesize",
            (409,),
            code="idempotency_conflict",
            params={"wait": 0},
            data={"options": json.dumps(other)},
            files=files,
            headers=key,
        )
        self.recorder.count("cases", "idempotency_conflict")

    def act_retention(self) -> None:
        """The result of a job many jobs ago is gone (410; 404 once its record is too)."""
        found = self.ledger.evicted(self.rng)
        kind = "GET /jobs/{id}/result (expired)"
        if found is None:
            self.recorder.count("notes", "retention check skipped (too early)")
            return
        job_id, since = found
        if since < 4 * RESULTS_MAX_COUNT:  # the job's record is certainly still kept
            status = self.call(JOB, "GET", f"/jobs/{job_id}", (200,))
            if status is not None:
                document = status.json()
                self.check(
                    JOB,
                    document.get("expired") is True and document.get("result") is None,
                    f"job {job_id}, {since} jobs ago: expired={document.get('expired')}",
                )
            self.call(kind, "GET", f"/jobs/{job_id}/result", (410,), code="result_expired")
        else:
            codes = ("result_expired", "job_not_found")
            self.call(kind, "GET", f"/jobs/{job_id}/result", (404, 410), code=codes)

    # --- bad requests -------------------------------------------------------------------

    def bad_cases(self) -> dict[str, Callable[[], object]]:
        texture = self.rng.choice(self.media.textures)
        files = [("texture", part(texture))]
        small = {"width": 256, "height": 256, "seed": 1}

        def synth(options: str, code: str, status: int = 422, **kwargs: Any) -> None:
            self.call(
                BAD,
                "POST",
                "/synthesize",
                (status,),
                code=code,
                data={"options": options},
                files=kwargs.pop("files", files),
                params=kwargs.pop("params", {"wait": 0}),
            )

        deep = '{"width": 256, "height": 256, "exclude_colors": ' + "[" * 40 + "]" * 40 + "}"
        cases: dict[str, Callable[[], object]] = {
            "overlap_too_large": lambda: synth(
                json.dumps({**small, "block": 48, "overlap": 30}), "invalid_parameter"
            ),
            "options_not_json": lambda: synth('{"width": 256, "height"', "invalid_options"),
            "options_not_object": lambda: synth("[256, 256]", "invalid_options"),
            "options_too_deep": lambda: synth(deep, "invalid_options"),
            "unknown_option": lambda: synth(json.dumps({**small, "colour": 1}), "invalid_options"),
            "width_zero": lambda: synth(json.dumps({**small, "width": 0}), "invalid_parameter"),
            "wait_too_long": lambda: synth(
                json.dumps(small), "invalid_parameter", params={"wait": 10 * MAX_WAIT_S}
            ),
            "not_an_image": lambda: synth(
                json.dumps(small),
                "unsupported_media_type",
                status=415,
                files=[("texture", ("notes.png", b"not an image at all", "image/png"))],
            ),
            "duplicate_texture": lambda: synth(
                json.dumps(small), "duplicate_part", files=[*files, *files]
            ),
            "unknown_job": lambda: self.call(
                BAD, "GET", f"/jobs/{uuid.uuid4().hex}", (404,), code="job_not_found"
            ),
            "wrong_method": self.bad_method,
            "transfer_custom": lambda: self.call(
                BAD,
                "POST",
                "/transfer",
                (422,),
                code="invalid_parameter",
                data={"options": json.dumps({"correspondence": "custom"})},
                files=[*files, ("target", part(self.media.targets[1]))],
            ),
            "tile_bad_axes": lambda: self.call(
                BAD,
                "POST",
                "/tile",
                (422,),
                code="invalid_parameter",
                data={"options": json.dumps({"axes": "z"})},
                files=[("image", part(texture))],
            ),
        }
        if self.last_done is not None:
            done = self.last_done
            cases["seams_bad_color"] = lambda: self.call(
                BAD,
                "GET",
                f"/jobs/{done}/seams",
                (422,),
                code="invalid_parameter",
                params={"color": "red"},
            )
            cases["cancel_done_job"] = lambda: self.call(
                BAD, "DELETE", f"/jobs/{done}", (409,), code="job_finished"
            )
        return cases

    def bad_method(self) -> None:
        response = self.call(BAD, "PUT", "/synthesize", (405,), code="method_not_allowed")
        if response is not None:
            allow = response.headers.get("allow", "")
            self.check(BAD, "POST" in allow, f"405 with Allow {allow!r}")

    def act_bad_request(self) -> None:
        cases = self.bad_cases()
        name = self.rng.choice(sorted(cases))
        self.recorder.count("cases", name)
        cases[name]()

    # --- the loop ----------------------------------------------------------------------

    def actions(self) -> Iterator[str]:
        first = list(WEIGHTS)
        self.rng.shuffle(first)
        yield from first
        names, weights = list(WEIGHTS), list(WEIGHTS.values())
        while True:
            yield self.rng.choices(names, weights)[0]

    def run(self, deadline: float) -> None:
        cpu = time.thread_time()
        try:
            for name in self.actions():
                if time.monotonic() >= deadline:
                    break
                self.recorder.count("actions", name)
                try:
                    getattr(self, f"act_{name}")()
                except Exception as exc:  # a surprise in an answer is an error, not a crash
                    self.recorder.fail(f"action {name}", repr(exc))
        finally:
            self.cpu_s = time.thread_time() - cpu
            self.http.close()


# --- the sampler ----------------------------------------------------------------------------


class Sampler(threading.Thread):
    """RSS of the API process and its children, and ``/healthz``, every ``interval`` s."""

    def __init__(
        self, api_pid: int, url: str, interval: float, start: float, recorder: Recorder
    ) -> None:
        super().__init__(name="soak-sampler", daemon=True)
        self.api_pid = api_pid
        self.url = url
        self.interval = interval
        self.start_time = start
        self.recorder = recorder
        self.samples: list[Sample] = []
        self.stopping = threading.Event()

    def run(self) -> None:
        with httpx.Client(base_url=self.url, timeout=10.0) as client:
            next_at = time.monotonic()
            while not self.stopping.is_set():
                now = time.monotonic()
                taken = sample(self.api_pid, now - self.start_time)
                if taken is None:
                    self.recorder.fail("memory sampler", "the API process is gone")
                    return
                self.samples.append(taken)
                start = time.perf_counter()
                try:
                    response = client.get("/healthz")
                    error = None if response.status_code == 200 else str(response.status_code)
                except httpx.HTTPError as exc:
                    error = repr(exc)
                self.recorder.add("GET /healthz", time.perf_counter() - start, error)
                next_at += self.interval
                self.stopping.wait(max(0.0, next_at - time.monotonic()))


# --- report ---------------------------------------------------------------------------------


@dataclass
class Growth:
    start: float  # median bytes of the first window after warm-up
    end: float  # median bytes of the last window
    peak: int

    @property
    def growth(self) -> float:
        return (self.end - self.start) / self.start


def windows(samples: list[Sample], warmup_s: float) -> tuple[list[Sample], list[Sample]]:
    """The first window after the warm-up and the last window, each 10 % of the samples."""
    after = [s for s in samples if s.t >= warmup_s]
    n = max(3, round(0.1 * len(samples)))
    n = min(n, len(after) // 2)
    if n < 1:
        return [], []
    return after[:n], after[-n:]


def growth(samples: list[Sample], warmup_s: float, value: Callable[[Sample], int]) -> Growth | None:
    first, last = windows(samples, warmup_s)
    if not first:
        return None
    return Growth(
        statistics.median(value(s) for s in first),
        statistics.median(value(s) for s in last),
        max(value(s) for s in samples),
    )


def mib(value: float) -> str:
    return f"{value / 2**20:.1f}"


def report(
    recorder: Recorder,
    samples: list[Sample],
    warmup_s: float,
    duration_s: float,
    clients: list[SoakClient],
    workers: int,
    server_cpu_s: float | None,
    log_lines: list[str],
    exit_code: int | None,
) -> tuple[str, dict[str, Any]]:
    kinds = dict(sorted(recorder.kinds.items()))
    requests = sum(k.requests for k in kinds.values())
    errors = sum(k.errors for k in kinds.values()) + len(log_lines) + (exit_code != 0)
    finished = sum(recorder.jobs.values())
    healthz = kinds.get("GET /healthz", Kind()).seconds
    client_cpu = sum(c.cpu_s for c in clients)
    run = benchtools.markdown(
        [
            "duration min",
            "clients",
            "workers",
            "actions",
            "requests",
            "errors",
            "requests/s",
            "jobs done",
            "jobs cancelled",
            "jobs/s",
            "healthz p99 ms",
            "server CPU cores",
            "client CPU cores",
        ],
        [
            [
                f"{duration_s / 60:.1f}",
                str(len(clients)),
                str(workers),
                str(sum(recorder.actions.values())),
                str(requests),
                str(errors),
                f"{requests / duration_s:.2f}",
                str(recorder.jobs["done"]),
                str(recorder.jobs["cancelled"]),
                f"{finished / duration_s:.2f}",
                f"{1000 * benchtools.percentile(healthz, 99):.1f}",
                "?" if server_cpu_s is None else f"{server_cpu_s / duration_s:.2f}",
                f"{client_cpu / duration_s:.2f}",
            ]
        ],
        left=0,
    )
    rows = [
        [
            name,
            str(k.requests),
            str(k.errors),
            f"{1000 * statistics.median(k.seconds):.1f}" if k.seconds else "-",
            f"{1000 * benchtools.percentile(k.seconds, 95):.1f}" if k.seconds else "-",
            f"{1000 * max(k.seconds):.1f}" if k.seconds else "-",
        ]
        for name, k in kinds.items()
    ]
    rows.append(["all", str(requests), str(sum(k.errors for k in kinds.values())), "", "", ""])
    by_kind = benchtools.markdown(
        ["requests by kind", "count", "errors", "median ms", "p95 ms", "max ms"], rows
    )
    memory: dict[str, Any] = {}
    memory_rows = []
    judged = {"API process": True, "workers": False, "total": True}
    values: dict[str, Callable[[Sample], int]] = {
        "API process": lambda s: s.api,
        "workers": lambda s: s.workers,
        "total": lambda s: s.total,
    }
    passed = True
    first, _ = windows(samples, warmup_s)
    for name, value in values.items():
        found = growth(samples, warmup_s, value)
        if found is None:
            passed = False
            memory_rows.append([name, "-", "-", "-", "-", "-", "too few samples"])
            continue
        ok = found.growth < TARGET_GROWTH
        if judged[name]:
            passed = passed and ok
        memory[name] = {**asdict(found), "growth": found.growth}
        memory_rows.append(
            [
                name,
                mib(found.start),
                mib(found.end),
                f"{100 * found.growth:+.2f} %",
                mib(found.peak),
                f"< {100 * TARGET_GROWTH:.0f} %" if judged[name] else "-",
                ("PASS" if ok else "MISS") if judged[name] else "-",
            ]
        )
    table = benchtools.markdown(
        [
            "RSS",
            "warm-up end MiB",
            "end MiB",
            "growth",
            "max MiB",
            "target",
            "result",
        ],
        memory_rows,
    )
    pids = sorted({pid for s in samples for pid in s.worker_pids})
    distinct = grouped(recorder.errors)
    error_text = "none"
    if errors:
        shown = [f"- {n} x {text}" for text, n in distinct.most_common(20)]
        shown += [f"- {n} x server log: {t}" for t, n in grouped(log_lines).most_common(20)]
        if exit_code != 0:
            shown.append(f"- the server exited with code {exit_code}")
        client_errors = sum(k.errors for k in kinds.values())
        error_text = (
            f"{errors} ({client_errors} in answers, {len(log_lines)} server log lines, "
            f"server exit code {exit_code})\n" + "\n".join(shown)
        )
    window_s = (first[-1].t - first[0].t) if first else 0.0
    cases = ", ".join(f"{k} {n}" for k, n in sorted(recorder.cases.items())) or "none"
    notes = ", ".join(f"{k}: {n}" for k, n in sorted(recorder.notes.items())) or "none"
    text = (
        f"{run}\n\n{by_kind}\n\n"
        f"memory: warm-up {warmup_s / 60:.1f} min; medians of windows of {len(first)} samples "
        f"(about {window_s:.0f} s) right after the warm-up and at the end; "
        f"{len(samples)} samples; worker pids seen: {len(pids)}\n\n{table}\n\n"
        f"actions: {', '.join(f'{k} {n}' for k, n in sorted(recorder.actions.items()))}\n"
        f"bad requests by case: {cases}\n"
        f"notes: {notes}\n"
        f"errors: {error_text}\n"
        f"result: {'PASS' if passed and not errors else 'FAIL'}"
    )
    summary = {
        "duration_s": duration_s,
        "warmup_s": warmup_s,
        "clients": len(clients),
        "workers": workers,
        "requests": requests,
        "errors": errors,
        "error_messages": recorder.errors[:500],
        "server_log_problems": log_lines[:100],
        "server_exit_code": exit_code,
        "jobs": dict(recorder.jobs),
        "actions": dict(recorder.actions),
        "bad_request_cases": dict(recorder.cases),
        "notes": dict(recorder.notes),
        "memory": memory,
        "worker_pids_seen": len(pids),
        "memory_pass": passed,
        "pass": passed and not errors,
        "kinds": {
            name: {"requests": k.requests, "errors": k.errors, "seconds": k.seconds}
            for name, k in kinds.items()
        },
    }
    return text, summary


def process_cpu_s(pid: int) -> float | None:
    """User + system CPU seconds of a process and its waited-for children so far."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return sum(int(f) for f in fields[11:15]) / os.sysconf("SC_CLK_TCK")


def tree_cpu_s(pid: int) -> float | None:
    """CPU seconds of a process and of the processes below it now."""
    own = process_cpu_s(pid)
    if own is None:
        return None
    return own + sum(process_cpu_s(child) or 0.0 for child in descendants(pid))


# --- main -----------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    parser = benchtools.parser(__doc__, json_help="also write the results and samples here")
    parser.add_argument("--minutes", type=float, default=30.0, help="length of the load (30)")
    parser.add_argument(
        "--warmup-minutes",
        type=float,
        default=None,
        help="warm-up before memory is compared (20 %% of the run, at least 2 min)",
    )
    parser.add_argument("--clients", type=int, default=2, help="concurrent clients (2)")
    parser.add_argument(
        "--workers", type=int, default=None, help="server workers (default: its own)"
    )
    parser.add_argument("--interval", type=float, default=2.0, help="seconds between samples")
    parser.add_argument("--seed", type=int, default=0, help="seed of the clients' choices")
    args = parser.parse_args(argv)
    duration_s = 60.0 * args.minutes
    if args.warmup_minutes is None:
        warmup_s = min(max(0.2 * duration_s, 120.0), 0.7 * duration_s)
    else:
        warmup_s = 60.0 * args.warmup_minutes

    info = benchtools.service_machine(httpx=httpx.__version__)
    benchtools.show_machine(info)
    media = Media.read()
    recorder, ledger = Recorder(), Ledger()
    with tempfile.TemporaryFile() as log:
        server = benchtools.ServeProcess(
            log, args.workers, env=server_environment(), cwd=ROOT, stop_s=90.0
        )
        with server:
            ready = server.wait_for("/readyz", STARTUP_S, interval_s=0.2).json()
            workers = int(ready["workers"])
            print(
                f"server: python -m quilting serve --port {server.port}; "
                f"queue={ready['queue']}, backend={ready['backend']}, worker_mode=process, "
                f"{workers} workers, results_max_count={RESULTS_MAX_COUNT}, "
                f"results_ttl_s={RESULTS_TTL_S:g}, job_timeout_s={JOB_TIMEOUT_S:g}; "
                f"{args.clients} clients for {args.minutes:g} min, warm-up "
                f"{warmup_s / 60:.1f} min, a sample every {args.interval:g} s",
                flush=True,
            )
            start = time.monotonic()
            deadline = start + duration_s
            cpu_before = tree_cpu_s(server.process.pid)
            sampler = Sampler(server.process.pid, server.url, args.interval, start, recorder)
            clients = [
                SoakClient(k, server.url, media, recorder, ledger, args.seed)
                for k in range(args.clients)
            ]
            threads = [
                threading.Thread(target=c.run, args=(deadline,), name=f"soak-client-{k}")
                for k, c in enumerate(clients)
            ]
            sampler.start()
            for thread in threads:
                thread.start()
            progress_at = start + 60.0
            while any(t.is_alive() for t in threads):
                if time.monotonic() >= deadline and not sampler.stopping.is_set():
                    sampler.stopping.set()
                if time.monotonic() >= progress_at:
                    progress_at += 60.0
                    last = sampler.samples[-1] if sampler.samples else None
                    rss = f"API {mib(last.api)} MiB, total {mib(last.total)} MiB" if last else ""
                    print(
                        f"  {(time.monotonic() - start) / 60:.0f} min: "
                        f"{sum(k.requests for k in recorder.kinds.values())} requests, "
                        f"{recorder.error_count} errors; {rss}",
                        file=sys.stderr,
                        flush=True,
                    )
                time.sleep(0.5)
            sampler.stopping.set()
            sampler.join()
            cpu_after = tree_cpu_s(server.process.pid)
            elapsed_s = time.monotonic() - start  # the clients end their last action
        log_lines = log_problems(server.log_text())
    server_cpu = None if cpu_before is None or cpu_after is None else cpu_after - cpu_before
    text, summary = report(
        recorder,
        sampler.samples,
        warmup_s,
        elapsed_s,
        clients,
        workers,
        server_cpu,
        log_lines,
        server.exit_code,
    )
    print(text)
    if args.json:
        summary["machine"] = info
        summary["samples"] = [asdict(s) for s in sampler.samples]
        args.json.write_text(json.dumps(summary, indent=1) + "\n")
    return 0 if summary["pass"] else 1


if __name__ == "__main__":
    sys.exit(main())
