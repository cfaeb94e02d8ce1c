"""Helpers of the service tests: a real ``quilting serve`` process, requests, checks.

The server is started the way a user starts it (``python -m quilting serve --port P`` with
``QUILTING_*`` variables) and talked to over loopback HTTP with httpx.
"""

from __future__ import annotations

import io
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
PROBLEM_JSON = "application/problem+json"
FINAL = ("done", "failed", "cancelled")
#: The results TTL of the ``secured`` server: long enough for a test to fetch a result right
#: after its job, even on a busy machine; short enough for a test to wait for its expiry.
SECURED_RESULTS_TTL_S = 3
STATUS_FIELDS = {
    "id",
    "operation",
    "status",
    "progress",
    "stage",
    "created",
    "started",
    "finished",
    "timings",
    "backend",
    "renderer",
    "fallback",
    "error",
    "result",
    "companions",
    "layout",
    "manifest",
    "stats",
    "width",
    "height",
}


def texture(name: str) -> bytes:
    """The bytes of ``tests/data/<name>.png``."""
    return (DATA / f"{name}.png").read_bytes()


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def spawn_quilting(
    command: list[str], settings: dict[str, str], log_path: Path
) -> subprocess.Popen[bytes]:
    """``python -m quilting <command>`` from the checkout's root, its output unbuffered into
    ``log_path``; of the ``QUILTING_*`` variables it sees only ``settings`` (not this
    process's, so that a developer's own settings do not leak into a test)."""
    environ = {k: v for k, v in os.environ.items() if not k.startswith("QUILTING_")}
    environ.update(settings)
    environ["PYTHONUNBUFFERED"] = "1"
    with open(log_path, "wb") as log:
        return subprocess.Popen(
            [sys.executable, "-m", "quilting", *command],
            cwd=ROOT,
            env=environ,
            stdout=log,
            stderr=subprocess.STDOUT,
        )


class Server:
    """One ``quilting serve`` subprocess on a loopback port, its output in a log file."""

    def __init__(self, name: str, env: dict[str, str], log_dir: Path) -> None:
        self.name = name
        self.settings = dict(env)
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.log_path = log_dir / f"server-{name}-{self.port}.log"
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self, timeout: float = 60.0) -> Server:
        self.proc = spawn_quilting(
            ["serve", "--port", str(self.port)], self.settings, self.log_path
        )
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(
                    f"server {self.name} exited with {self.proc.returncode}:\n{self.log()}"
                )
            try:
                if httpx.get(self.url + "/healthz", timeout=1.0).status_code == 200:
                    return self
            except httpx.TransportError:
                pass
            time.sleep(0.05)
        self.stop()
        raise RuntimeError(
            f"server {self.name} did not answer /healthz in {timeout} s:\n{self.log()}"
        )

    def log(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")
        except OSError:
            return "<no log>"

    def signal(self, sig: int) -> None:
        assert self.proc is not None
        self.proc.send_signal(sig)

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

    def client(self, **kwargs: Any) -> httpx.Client:
        return httpx.Client(base_url=self.url, timeout=kwargs.pop("timeout", 60.0), **kwargs)

    def async_client(self, **kwargs: Any) -> httpx.AsyncClient:
        return httpx.AsyncClient(base_url=self.url, timeout=kwargs.pop("timeout", 60.0), **kwargs)


# --- requests -------------------------------------------------------------------------------


def synth_request(
    options: dict[str, Any] | str,
    *,
    tex: str | bytes = "gravel",
    companions: dict[str, bytes] | list[tuple[str, bytes]] | None = None,
) -> dict[str, Any]:
    """``files`` and ``data`` of a ``POST /synthesize`` multipart request."""
    data = tex if isinstance(tex, bytes) else texture(tex)
    files: list[tuple[str, tuple[str, bytes, str]]] = [
        ("texture", ("texture.png", data, "image/png"))
    ]
    items = companions.items() if isinstance(companions, dict) else (companions or [])
    for filename, content in items:
        files.append(("companion", (filename, content, "image/png")))
    text = options if isinstance(options, str) else json.dumps(options)
    return {"files": files, "data": {"options": text}}


def synth(
    client: httpx.Client,
    options: dict[str, Any] | str,
    *,
    wait: float | None = 30,
    tex: str | bytes = "gravel",
    companions: dict[str, bytes] | list[tuple[str, bytes]] | None = None,
    headers: dict[str, str] | None = None,
) -> httpx.Response:
    request = synth_request(options, tex=tex, companions=companions)
    return _post(client, "/synthesize", wait, headers, request)


def _post(
    client: httpx.Client,
    path: str,
    wait: float | None,
    headers: dict[str, str] | None,
    request: dict[str, Any],
) -> httpx.Response:
    """``POST path`` with ``?wait=`` unless ``wait`` is None; ``request``: files and data."""
    params = {} if wait is None else {"wait": wait}
    return client.post(path, params=params, headers=headers, **request)


def transfer_request(
    options: dict[str, Any] | str | None,
    *,
    tex: str | bytes = "gravel",
    target: str | bytes | None = "hubble",
    companions: dict[str, bytes] | list[tuple[str, bytes]] | None = None,
) -> dict[str, Any]:
    """``files`` and ``data`` of a ``POST /transfer`` multipart request.

    ``target`` None leaves the target part out; ``options`` None leaves the options field out.
    """
    request = synth_request(options or {}, tex=tex, companions=companions)
    if target is not None:
        data = target if isinstance(target, bytes) else texture(target)
        request["files"].insert(1, ("target", ("target.png", data, "image/png")))
    if options is None:
        request["data"] = {}
    return request


def transfer(
    client: httpx.Client,
    options: dict[str, Any] | str | None,
    *,
    wait: float | None = 30,
    tex: str | bytes = "gravel",
    target: str | bytes | None = "hubble",
    companions: dict[str, bytes] | list[tuple[str, bytes]] | None = None,
    headers: dict[str, str] | None = None,
) -> httpx.Response:
    request = transfer_request(options, tex=tex, target=target, companions=companions)
    return _post(client, "/transfer", wait, headers, request)


def tile(
    client: httpx.Client, image: bytes, options: dict[str, Any] | str | None = None
) -> httpx.Response:
    """``POST /tile`` of ``image``, with ``options`` (a dict, or the field's raw text) unless
    None."""
    data = (
        {}
        if options is None
        else {"options": options if isinstance(options, str) else json.dumps(options)}
    )
    return client.post("/tile", files={"image": ("in.png", image, "image/png")}, data=data)


def job_id_of(response: httpx.Response) -> str:
    """The job id of an accepted ``POST /synthesize`` or ``/transfer`` (checking its headers)."""
    assert response.status_code in (200, 202), response.text
    job_id = response.headers["X-Job-Id"]
    assert job_id
    assert response.headers["Location"] == f"/jobs/{job_id}"
    if response.status_code == 202:
        assert response.json()["id"] == job_id
    return job_id


def wait_for(
    client: httpx.Client,
    job_id: str,
    statuses: tuple[str, ...] = FINAL,
    timeout: float = 60.0,
    headers: dict[str, str] | None = None,
    poll: float = 0.02,
) -> dict[str, Any]:
    """Poll ``GET /jobs/{id}`` until its status is one of ``statuses``; the status JSON."""
    deadline = time.monotonic() + timeout
    while True:
        response = client.get(f"/jobs/{job_id}", headers=headers)
        assert response.status_code == 200, response.text
        status = response.json()
        if status["status"] in statuses:
            return status
        assert status["status"] not in FINAL, f"job ended {status['status']}: {status}"
        assert time.monotonic() < deadline, f"job still {status['status']} after {timeout} s"
        time.sleep(poll)


def wait_expired(
    client: httpx.Client,
    job_id: str,
    timeout: float = 60.0,
    headers: dict[str, str] | None = None,
    poll: float = 0.1,
) -> None:
    """Poll ``GET /jobs/{id}/result`` until it answers 410 ``result_expired`` (a result's TTL
    has passed); until then it must still be the PNG."""
    deadline = time.monotonic() + timeout
    while True:
        response = client.get(f"/jobs/{job_id}/result", headers=headers)
        if response.status_code == 410:
            assert_problem(response, 410, "result_expired")
            return
        assert response.status_code == 200, response.text
        assert time.monotonic() < deadline, f"the result of {job_id} still kept after {timeout} s"
        time.sleep(poll)


def wait_idle(
    client: httpx.Client, timeout: float = 60.0, headers: dict[str, str] | None = None
) -> None:
    """Wait until the server has no queued or running job."""
    deadline = time.monotonic() + timeout
    while True:
        response = client.get("/readyz", headers=headers)
        if response.status_code == 200:
            body = response.json()
            if body["queue_depth"] == 0 and body["running"] == 0:
                return
        assert time.monotonic() < deadline, f"server still busy: {response.text}"
        time.sleep(0.05)


# --- checks ---------------------------------------------------------------------------------


def png_bytes(image: np.ndarray) -> bytes:
    """``image`` (uint8, gray or colour) encoded as PNG with Pillow."""
    buffer = io.BytesIO()
    Image.fromarray(image).save(buffer, format="PNG")
    return buffer.getvalue()


def lit_sphere(width: int, height: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The matting tests' target, ``width`` x ``height`` (square by default): a Lambertian
    sphere (radius 0.4 of the shorter side) lit from (1, 1, 2), shaded 0 to 0.8 (gray uint8),
    and its silhouette (uint8, 0 or 255)."""
    height = width if height is None else height
    x, y = np.meshgrid(np.arange(width) - (width - 1) / 2, (height - 1) / 2 - np.arange(height))
    radius = min(width, height) * 0.4
    inside = x**2 + y**2 < radius**2
    z = np.sqrt(np.clip(radius**2 - x**2 - y**2, 0, None))
    normals = np.stack([x, y, z], axis=-1) / radius
    light = np.array([1.0, 1.0, 2.0]) / np.sqrt(6.0)
    shade = np.where(inside, np.clip(normals @ light, 0, 1) * 0.8, 0.0)
    return np.rint(shade * 255).astype(np.uint8), (inside * 255).astype(np.uint8)


def png_image(data: bytes) -> Image.Image:
    """Decode PNG bytes (checking the signature) with Pillow."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n", data[:32]
    image = Image.open(io.BytesIO(data))
    assert image.format == "PNG"
    image.load()
    return image


def assert_png(response: httpx.Response, width: int, height: int) -> Image.Image:
    assert response.status_code == 200, response.text[:500]
    assert response.headers["content-type"] == "image/png"
    image = png_image(response.content)
    assert image.size == (width, height)
    return image


def assert_problem(
    response: httpx.Response, status: int, code: str | tuple[str, ...], field: str | None = None
) -> dict[str, Any]:
    """``response`` is an RFC 9457 problem with ``status`` and ``code`` (and ``field``)."""
    assert response.status_code == status, (response.status_code, response.text[:500])
    assert response.headers["content-type"].split(";")[0] == PROBLEM_JSON, response.headers
    body = response.json()
    codes = (code,) if isinstance(code, str) else code
    assert body["code"] in codes, body
    assert body["status"] == status
    assert body["type"] == "https://quilting.dev/problems/" + body["code"]
    assert isinstance(body["title"], str) and body["title"]
    assert isinstance(body["detail"], str) and body["detail"]
    if field is not None:
        assert body.get("field") == field, body
    return body


def assert_status_document(status: dict[str, Any]) -> None:
    """The job status JSON has the contract's members with the contract's types."""
    missing = STATUS_FIELDS - set(status)
    assert not missing, f"status lacks {missing}: {status}"
    assert status["status"] in ("queued", "running", *FINAL)
    assert status["operation"] in (
        "synthesize",
        "transfer",
        "matte",
        "fill",
        "extend",
        "wang_tiles",
    )
    assert 0.0 <= status["progress"] <= 1.0
    assert isinstance(status["stage"], str)
    assert isinstance(status["created"], float)
    assert isinstance(status["timings"], dict)
    assert isinstance(status["companions"], list)
    assert isinstance(status["width"], int) and isinstance(status["height"], int)
    base = f"/jobs/{status['id']}"
    if status["status"] == "done" and not status.get("expired"):
        assert status["result"] == base + "/result"
        # A matte job's layers are quilted apart: its result has no one layout.
        layout = None if status["operation"] == "matte" else base + "/layout"
        assert status["layout"] == layout
        # A Wang tile set's manifest (its layout, by another name); no other job has one.
        wang = status["operation"] == "wang_tiles"
        assert status["manifest"] == (base + "/manifest" if wang else None)
        assert status["progress"] == 1.0
        assert status["started"] is not None and status["finished"] is not None
        assert status["created"] <= status["started"] <= status["finished"]
    else:
        assert status["result"] is None
        assert status["layout"] is None
        assert status["manifest"] is None


def retry_after(response: httpx.Response) -> int:
    value = response.headers.get("Retry-After")
    assert value is not None, f"no Retry-After: {response.headers}"
    seconds = int(value)
    assert seconds >= 0
    return seconds


def parse_sse(lines: list[str]) -> list[tuple[str, str]]:
    """``(event, data)`` pairs of a text/event-stream body given as lines."""
    events: list[tuple[str, str]] = []
    event, data = "message", []
    for line in [*lines, ""]:
        if not line:
            if data:
                events.append((event, "\n".join(data)))
            event, data = "message", []
        elif line.startswith("event:"):
            event = line[6:].strip()
        elif line.startswith("data:"):
            data.append(line[5:].lstrip())
    return events


def metric_values(text: str) -> dict[str, float]:
    """Sample name (with labels) -> value of a Prometheus text exposition."""
    values: dict[str, float] = {}
    for line in text.splitlines():
        if not line or line.startswith("#"):
            continue
        name, _, value = line.rpartition(" ")
        values[name] = float(value)
    return values
