"""Hostile uploads against ``quilting serve``: the API process's peak memory and /healthz latency.

Starts the real server as a user would (``python -m quilting serve --port P --workers 1``, the
other settings at their defaults unless given) and sends it a battery of uploads built to hurt:

* decompression bombs: a PNG declaring 50000x50000, one declaring 5000x5000 over 64 bytes of
  data, one whose image data inflates to 256 MB more than it declares;
* broken files: a truncated PNG and JPEG, a palette PNG without PLTE, 20 MB of junk after IEND,
  a PNG of 2.5 million chunks (30 MB), a JPEG whose size field is patched to 4999x4999;
* the same as a companion, a transfer target and a ``/tile`` image;
* valid but costly: a 16-bit RGBA 5000x5000 PNG to ``/synthesize`` and ``/tile``, an 8-bit
  5000x5000 PNG to ``/tile``, four 5000x5000 jobs queued behind a busy worker;
* options nested 100,000 deep and 70 KB long;
* slow clients: uploads that stop half-way and requests whose headers never end (on a new and
  on a kept-alive connection), all held open at once.

Throughout, a process of its own asks ``/healthz`` back to back (in this one, the battery's own
work and garbage collections would stall it) and a thread samples the API process's VmRSS;
the table gives each input's answer and time, then the API process's peak (VmHWM, the
kernel's own figure) and the /healthz latencies (median, p95, max) against the targets of
issue 19 (<= 300 MB, < 100 ms).

Run from the repository root (about a minute, plus ``QUILTING_REQUEST_TIMEOUT_S`` for the slow
clients)::

    .venv/bin/python benchmarks/bench_hostile.py
    .venv/bin/python benchmarks/bench_hostile.py --request-timeout 5 --json hostile.json
"""

from __future__ import annotations

import io
import json
import os
import selectors
import socket
import statistics
import struct
import subprocess
import sys
import tempfile
import threading
import time
import zlib
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import IO, Any

import benchtools
import httpx
from PIL import Image

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
MiB = 1 << 20
STARTUP_S = 60.0
TARGET_RSS = 300 * MiB
TARGET_HEALTHZ_S = 0.1
SMALL = {"width": 64, "height": 64, "block": 16}
SIGNATURE = b"\x89PNG\r\n\x1a\n"


# --- inputs -----------------------------------------------------------------------------------


def chunk(kind: bytes, payload: bytes) -> bytes:
    crc = struct.pack(">I", zlib.crc32(kind + payload))
    return struct.pack(">I", len(payload)) + kind + payload + crc


def ihdr(width: int, height: int, depth: int, color_type: int) -> bytes:
    return chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, depth, color_type, 0, 0, 0))


def zero_rows(row_bytes: int, rows: int, extra: int = 0) -> bytes:
    """zlib of ``rows`` rows of filter byte 0 and zero samples, then ``extra`` zero bytes."""
    packer = zlib.compressobj(9)
    row = bytes(1 + row_bytes)
    parts = [packer.compress(row * 64) for _ in range(rows // 64)]
    parts.append(packer.compress(row * (rows % 64)))
    parts += [packer.compress(bytes(1 << 22)) for _ in range(extra >> 22)]
    parts.append(packer.flush())
    return b"".join(parts)


def png(width: int, height: int, depth: int, color_type: int, data: bytes) -> bytes:
    idat = b"".join(chunk(b"IDAT", data[i : i + MiB]) for i in range(0, len(data), MiB))
    return SIGNATURE + ihdr(width, height, depth, color_type) + idat + chunk(b"IEND", b"")


def black(width: int, height: int, depth: int = 8, color_type: int = 2) -> bytes:
    """A valid black PNG: a few hundred KB at most, ``width x height`` once decoded."""
    channels = {0: 1, 2: 3, 6: 4}[color_type]
    return png(width, height, depth, color_type, zero_rows(width * channels * depth // 8, height))


def claiming(width: int, height: int) -> bytes:
    return png(width, height, 8, 0, zlib.compress(bytes(64)))


def jpeg_of(name: str) -> bytes:
    buffer = io.BytesIO()
    Image.open(DATA / f"{name}.png").convert("RGB").save(buffer, format="JPEG", quality=90)
    return buffer.getvalue()


def patched_jpeg(width: int, height: int) -> bytes:
    data = bytearray(jpeg_of("hubble"))
    at = data.index(b"\xff\xc0")
    data[at + 5 : at + 9] = struct.pack(">HH", height, width)
    return bytes(data)


@dataclass
class Input:
    """One hostile request: what it is, where it goes, its files and options."""

    name: str
    endpoint: str
    files: list[tuple[str, tuple[str, bytes, str]]]
    options: str
    params: dict[str, str]

    @property
    def size(self) -> int:
        return sum(len(part[1][1]) for part in self.files) + len(self.options)


def battery() -> list[Input]:
    gravel = (DATA / "gravel.png").read_bytes()
    small = json.dumps(SMALL)

    def synth(name: str, data: bytes, **companions: bytes) -> Input:
        files = [("texture", ("texture.png", data, "image/png"))]
        files += [("companion", (f"{n}.png", d, "image/png")) for n, d in companions.items()]
        return Input(name, "/synthesize", files, small, {"wait": "30"})

    def tile(name: str, data: bytes) -> Input:
        return Input(name, "/tile", [("image", ("image.png", data, "image/png"))], "{}", {})

    bomb = claiming(50_000, 50_000)
    flood = claiming(64, 64)
    flood = flood[:33] + chunk(b"teXt", b"") * 2_500_000 + flood[33:]
    palette = png(16, 1, 8, 3, zlib.compress(bytes(17)))
    inputs = [
        synth("PNG declaring 50000x50000", bomb),
        synth("PNG declaring 5000x5000 over 64 bytes", claiming(5000, 5000)),
        synth(
            "PNG inflating 256 MB past its size",
            png(5000, 5000, 8, 0, zero_rows(5000, 5000, 256 * MiB)),
        ),
        synth("truncated PNG", gravel[:30_000]),
        synth("PNG of 2.5 million chunks (30 MB)", flood),
        synth("palette PNG without PLTE", palette),
        synth("20 MB after IEND", gravel + bytes(20 * MiB)),
        synth("JPEG patched to 4999x4999", patched_jpeg(4999, 4999)),
        synth("truncated JPEG", jpeg_of("hubble")[:10_000]),
        synth("companion declaring 50000x50000", gravel, normal=bomb),
        Input(
            "transfer target declaring 50000x50000",
            "/transfer",
            [
                ("texture", ("texture.png", gravel, "image/png")),
                ("target", ("target.png", bomb, "image/png")),
            ],
            "{}",
            {"wait": "30"},
        ),
        tile("/tile of a PNG declaring 50000x50000", bomb),
        Input(
            "16-bit RGBA 5000x5000",
            "/synthesize",
            [("texture", ("big16.png", black(5000, 5000, 16, 6), "image/png"))],
            json.dumps({"width": 256, "height": 256}),
            {"wait": "0"},
        ),
        tile("/tile of 8-bit RGB 5000x5000", black(5000, 5000)),
        tile("/tile of 16-bit RGBA 5000x5000", black(5000, 5000, 16, 6)),
        Input(
            "options nested 100,000 deep",
            "/synthesize",
            [("texture", ("t.png", gravel, "image/png"))],
            "[" * 100_000 + "]" * 100_000,
            {},
        ),
        Input(
            "options of 70 KB",
            "/synthesize",
            [("texture", ("t.png", gravel, "image/png"))],
            json.dumps({**SMALL, "backend": "x" * 70_000}),
            {},
        ),
    ]
    return inputs


# --- the server and what watches it -----------------------------------------------------------


class Server(benchtools.ServeProcess):
    """``python -m quilting serve --workers 1`` without this process's ``QUILTING_*``
    settings (``env`` instead), and its memory and scheduling figures from ``/proc``."""

    def __init__(self, env: dict[str, str], log: IO[bytes]) -> None:
        environ = {k: v for k, v in os.environ.items() if not k.startswith("QUILTING_")}
        super().__init__(log, workers=1, env={**environ, **env})

    def status(self, field: str) -> int:
        """A kB line of the server's /proc status (VmRSS, VmHWM), in bytes."""
        with open(f"/proc/{self.process.pid}/status") as status:
            line = next(line for line in status if line.startswith(field + ":"))
        return int(line.split()[1]) * 1024

    def schedstat(self) -> tuple[float, float]:
        """Seconds the server process has run on a CPU, and waited runnable for one."""
        with open(f"/proc/{self.process.pid}/schedstat") as stat:
            running, waiting, _ = stat.read().split()
        return int(running) / 1e9, int(waiting) / 1e9


#: The /healthz prober, a process of its own: in this one, the battery's own work (building
#: 30 MB bodies, a full garbage collection of 120 ms) would stall it and be counted as the
#: server's latency. It says "ready" after its first answer, asks back to back (10 ms apart)
#: until its stdin closes, then prints the (asked, seconds, ok) triples as JSON.
PROBE = r"""
import gc, json, sys, threading, time
import httpx
gc.collect(); gc.freeze()
url, found, done = sys.argv[1], [], threading.Event()
threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
with httpx.Client(base_url=url, timeout=10) as client:
    while not done.is_set():
        asked, started = time.monotonic(), time.perf_counter()
        try:
            ok = client.get("/healthz").status_code == 200
        except httpx.HTTPError:
            ok = False
        found.append((asked, time.perf_counter() - started, ok))
        if len(found) == 1:
            print("ready", flush=True)
        done.wait(0.01)
print(json.dumps(found))
"""


class Watch:
    """A process asking /healthz back to back (:data:`PROBE`), and a thread sampling the
    server's VmRSS."""

    def __init__(self, server: Server) -> None:
        self.server = server
        self.latencies: list[float] = []
        self.times: list[float] = []  # when each /healthz was asked (time.monotonic)
        self.failures = 0
        self.peak_rss = 0
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._sample, daemon=True)
        self.prober: subprocess.Popen[str] | None = None

    def slowest(self, start: float, end: float) -> float:
        """The slowest /healthz asked between ``start`` and ``end`` (0 when none was)."""
        during = [
            lat for t, lat in zip(self.times, self.latencies, strict=True) if start <= t <= end
        ]
        return max(during, default=0.0)

    def _sample(self) -> None:
        while not self.stop.wait(0.005):
            self.peak_rss = max(self.peak_rss, self.server.status("VmRSS"))

    def __enter__(self) -> Watch:
        self.prober = subprocess.Popen(
            [sys.executable, "-c", PROBE, self.server.url],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.prober.stdout is not None
        # Its interpreter takes a moment to start: the battery waits for its first answer.
        assert self.prober.stdout.readline().strip() == "ready"
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.thread.join(30)
        assert self.prober is not None
        out, _ = self.prober.communicate("", timeout=60)
        for asked, seconds, ok in json.loads(out):
            self.times.append(asked)
            self.latencies.append(seconds)
            self.failures += not ok


# --- sending ----------------------------------------------------------------------------------


@dataclass
class Answer:
    name: str
    endpoint: str
    upload_bytes: int
    status: int
    code: str
    seconds: float
    rss_after: int
    started: float = 0.0  # time.monotonic() when it was sent
    healthz_max_s: float = 0.0  # the slowest /healthz asked meanwhile


def send(client: httpx.Client, server: Server, item: Input) -> Answer:
    started = time.monotonic()
    response = client.post(
        item.endpoint, params=item.params, files=item.files, data={"options": item.options}
    )
    seconds = time.monotonic() - started
    code = "png" if response.status_code == 200 else str(response.json().get("code", "?"))
    if response.status_code == 202:  # a job: follow it to its end (cancelled meanwhile)
        job_id = response.headers["X-Job-Id"]
        client.delete(f"/jobs/{job_id}")
        deadline = time.monotonic() + 300
        while (status := client.get(f"/jobs/{job_id}").json())["status"] not in (
            "done",
            "failed",
            "cancelled",
        ):
            if time.monotonic() > deadline:
                break
            time.sleep(0.1)
        error = status.get("error") or {}
        code = f"job {status['status']}" + (f" {error['code']}" if error else "")
    return Answer(
        item.name,
        item.endpoint,
        item.size,
        response.status_code,
        code,
        seconds,
        server.status("VmRSS"),
        started,
    )


def queued_jobs(client: httpx.Client, server: Server, count: int = 4) -> Answer:
    """``count`` 5000x5000 jobs queued behind a busy worker: what each costs the API process."""
    busy = client.post(
        "/synthesize",
        params={"wait": "0"},
        files={"texture": ("gravel.png", (DATA / "gravel.png").read_bytes(), "image/png")},
        data={"options": json.dumps({"width": 4096, "height": 4096})},
    )
    busy_id = busy.headers["X-Job-Id"]
    big = black(5000, 5000)
    ids = []
    started = time.monotonic()
    before = server.status("VmRSS")
    for seed in range(count):
        response = client.post(
            "/synthesize",
            params={"wait": "0"},
            files={"texture": ("big.png", big, "image/png")},
            data={"options": json.dumps({**SMALL, "seed": seed})},
        )
        ids.append(response.headers.get("X-Job-Id"))
    grown = server.status("VmRSS") - before
    seconds = time.monotonic() - started
    statuses = [client.get(f"/jobs/{job_id}").json()["status"] for job_id in ids if job_id]
    for job_id in [busy_id, *ids]:
        if job_id:
            client.delete(f"/jobs/{job_id}")
    return Answer(
        f"{count} jobs of 5000x5000 queued (API grew {grown / MiB:+.1f} MiB)",
        "/synthesize",
        count * len(big),
        202,
        ", ".join(sorted(set(statuses))),
        seconds,
        server.status("VmRSS"),
        started,
    )


class SlowClients:
    """``count`` connections of each slow kind, held open: an upload that stops half-way, a
    request whose headers never end, and a kept-alive connection whose second request's headers
    never end. A thread waits on all of them and notes when the server closes each."""

    HEAD = (
        b"POST /synthesize HTTP/1.1\r\nHost: x\r\n"
        b"Content-Type: multipart/form-data; boundary=b\r\nContent-Length: 100000\r\n\r\n"
        b'--b\r\nContent-Disposition: form-data; name="texture"; filename="t.png"\r\n\r\n'
        + SIGNATURE
        + bytes(1000)
    )

    def __init__(self, server: Server, count: int) -> None:
        self.socks: list[socket.socket] = []
        for _ in range(count):
            body = socket.create_connection(("127.0.0.1", server.port))
            body.sendall(self.HEAD)
            headers = socket.create_connection(("127.0.0.1", server.port))
            headers.sendall(b"POST /synthesize HTTP/1.1\r\nHost: x\r\nContent-")
            kept = socket.create_connection(("127.0.0.1", server.port))
            kept.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")
            kept.recv(65536)  # its answer; the next request's headers never end
            kept.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\nX-")
            self.socks += [body, headers, kept]
        self.opened = time.monotonic()
        self.closed_after: list[float] = []
        self.thread = threading.Thread(target=self._wait, daemon=True)
        self.thread.start()

    def _wait(self, limit_s: float = 300.0) -> None:
        with selectors.DefaultSelector() as selector:
            for sock in self.socks:
                sock.setblocking(False)
                selector.register(sock, selectors.EVENT_READ)
            while selector.get_map() and time.monotonic() - self.opened < limit_s:
                for key, _ in selector.select(timeout=1.0):
                    conn = key.fileobj
                    assert isinstance(conn, socket.socket)
                    try:
                        data = conn.recv(65536)
                    except (BlockingIOError, InterruptedError):
                        continue
                    except ConnectionResetError:
                        data = b""
                    if not data:  # closed by the server (after its 408, if any)
                        self.closed_after.append(time.monotonic() - self.opened)
                        selector.unregister(conn)
                        conn.close()

    def result(self) -> dict[str, Any]:
        """Wait until the server has closed them all (or 300 s); when it did."""
        self.thread.join()
        for sock in self.socks:
            sock.close()
        closed = sorted(self.closed_after)
        return {
            "connections": len(self.socks),
            "held_after_300_s": len(self.socks) - len(closed),
            "first_closed_s": closed[0] if closed else float("nan"),
            "last_closed_s": closed[-1] if closed else float("nan"),
        }


# --- report -----------------------------------------------------------------------------------


def size(count: int) -> str:
    """A byte count for the table: ``68 B``, ``54 kB``, ``30.0 MB``."""
    if count < 10_000:
        return f"{count} B"
    if count < 10_000_000:
        return f"{count / 1000:.0f} kB"
    return f"{count / 1e6:.1f} MB"


def report(answers: list[Answer], summary: dict[str, Any]) -> str:
    rows = [
        [
            a.name,
            a.endpoint,
            size(a.upload_bytes),
            str(a.status),
            a.code,
            f"{a.seconds:.2f}",
            f"{a.rss_after / MiB:.0f}",
            f"{1000 * a.healthz_max_s:.0f}",
        ]
        for a in answers
    ]
    table = benchtools.markdown(
        [
            "input",
            "endpoint",
            "upload",
            "status",
            "code",
            "seconds",
            "API RSS after, MiB",
            "slowest /healthz meanwhile, ms",
        ],
        rows,
        left=2,
    )
    s = summary
    verdict = benchtools.markdown(
        ["figure", "measured", "target", "result"],
        [
            [
                "API process peak RSS (VmHWM)",
                f"{s['api_peak_bytes'] / MiB:.0f} MiB",
                f"<= {TARGET_RSS / MiB:.0f} MiB",
                "PASS" if s["api_peak_bytes"] <= TARGET_RSS else "MISS",
            ],
            [
                "/healthz median",
                f"{1000 * s['healthz_median_s']:.1f} ms",
                f"< {1000 * TARGET_HEALTHZ_S:.0f} ms",
                "PASS" if s["healthz_median_s"] < TARGET_HEALTHZ_S else "MISS",
            ],
            [
                "/healthz p95",
                f"{1000 * s['healthz_p95_s']:.1f} ms",
                f"< {1000 * TARGET_HEALTHZ_S:.0f} ms",
                "PASS" if s["healthz_p95_s"] < TARGET_HEALTHZ_S else "MISS",
            ],
            [
                "/healthz max",
                f"{1000 * s['healthz_max_s']:.1f} ms",
                f"< {1000 * TARGET_HEALTHZ_S:.0f} ms",
                "PASS" if s["healthz_max_s"] < TARGET_HEALTHZ_S else "MISS",
            ],
        ],
    )
    slow = s["slow_clients"]
    return (
        f"{table}\n\n{verdict}\n\n"
        f"API process at start {s['api_start_bytes'] / MiB:.0f} MiB; /healthz asked "
        f"{s['healthz_count']} times during the battery, {s['healthz_failures']} failed; "
        f"slow clients: the server closed {slow['connections'] - slow['held_after_300_s']} of "
        f"{slow['connections']} held-open connections {slow['first_closed_s']:.1f} to "
        f"{slow['last_closed_s']:.1f} s after they stalled (request_timeout_s "
        f"{s['request_timeout_s']:g} s); {slow['held_after_300_s']} still held after 300 s\n"
        f"the API process ran {s['api_cpu_s']:.1f} s on a CPU and waited "
        f"{s['api_runnable_wait_s']:.1f} s runnable for one (the machine's load average after: "
        f"{', '.join(map(str, s['loadavg_after']))}, on {os.cpu_count()} cores)"
    )


def main(argv: list[str] | None = None) -> int:
    parser = benchtools.parser(__doc__)
    parser.add_argument(
        "--request-timeout",
        type=float,
        default=None,
        help="QUILTING_REQUEST_TIMEOUT_S of the server (default: its own, 30 s)",
    )
    parser.add_argument(
        "--slow", type=int, default=20, help="slow connections of each kind (default 20)"
    )
    parser.add_argument("--log", type=Path, help="keep the server's output in this file")
    args = parser.parse_args(argv)
    env = {}
    if args.request_timeout is not None:
        env["QUILTING_REQUEST_TIMEOUT_S"] = str(args.request_timeout)
    timeout_s = args.request_timeout or 30.0

    info = benchtools.service_machine()
    benchtools.show_machine(info)
    print("building the inputs ...", file=sys.stderr, flush=True)
    inputs = battery()
    with (
        open(args.log, "w+b") if args.log else tempfile.TemporaryFile() as log,
        Server(env, log) as server,
    ):
        server.wait_for("/healthz", STARTUP_S)
        with httpx.Client(base_url=server.url, timeout=300) as client:
            warm = client.post(
                "/synthesize",
                params={"wait": "30"},
                files={"texture": ("g.png", (DATA / "gravel.png").read_bytes(), "image/png")},
                data={"options": json.dumps(SMALL)},
            )
            assert warm.status_code == 200, warm.text
            start_rss = server.status("VmRSS")
            start_sched = server.schedstat()
            with Watch(server) as watch:
                slow_clients = SlowClients(server, args.slow)
                answers = []
                for item in inputs:
                    print(f"  {item.name} ...", file=sys.stderr, flush=True)
                    answers.append(send(client, server, item))
                answers.append(queued_jobs(client, server))
                slow = slow_clients.result()
                ordinary = Input(
                    "an ordinary job afterwards",
                    "/synthesize",
                    [("texture", ("g.png", (DATA / "gravel.png").read_bytes(), "image/png"))],
                    json.dumps({**SMALL, "seed": 1}),
                    {"wait": "60"},
                )
                answers.append(send(client, server, ordinary))
        peak = max(watch.peak_rss, server.status("VmHWM"))
        end_sched = server.schedstat()
    for answer in answers:
        answer.healthz_max_s = watch.slowest(answer.started, answer.started + answer.seconds)
    latencies = sorted(watch.latencies)
    summary = {
        "api_start_bytes": start_rss,
        "api_peak_bytes": peak,
        "healthz_count": len(latencies),
        "healthz_failures": watch.failures,
        "healthz_median_s": statistics.median(latencies),
        "healthz_p95_s": latencies[int(0.95 * (len(latencies) - 1))],
        "healthz_max_s": latencies[-1],
        "slow_clients": slow,
        "request_timeout_s": timeout_s,
        "api_cpu_s": end_sched[0] - start_sched[0],
        "api_runnable_wait_s": end_sched[1] - start_sched[1],
        "loadavg_after": [round(x, 2) for x in os.getloadavg()],
    }
    print(report(answers, summary))
    # Every /healthz slower than 20 ms, when it was asked: to find what it waited behind.
    slow_probes = [
        [round(t, 3), round(lat, 4)]
        for t, lat in zip(watch.times, watch.latencies, strict=True)
        if lat > 0.02
    ]
    benchtools.write_json(
        args.json,
        {
            "machine": info,
            "summary": summary,
            "answers": [asdict(a) for a in answers],
            "slow_healthz": slow_probes,
        },
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
