"""Budgets in the service: a job predicted over its memory or time is refused before it is
queued (422 job_too_large with the prediction, the budget and what fits), within a second and
from the uploads' headers alone; what fits runs."""

from __future__ import annotations

import io
import time
from collections.abc import Callable

import httpx
from PIL import Image
from service_helpers import DATA, Server, assert_png, assert_problem, synth, tile, transfer


def _png(width: int, height: int, mode: str = "RGB") -> bytes:
    """A flat image: a few kB of PNG however many pixels it declares."""
    buffer = io.BytesIO()
    Image.new(mode, (width, height), 90).save(buffer, format="PNG")
    return buffer.getvalue()


def _memory_server(
    start_server: Callable[[str, dict[str, str]], Server], name: str, budget: int
) -> Server:
    """One worker, jobs capped at ``budget`` bytes."""
    return start_server(name, {"QUILTING_WORKERS": "1", "QUILTING_JOB_MEMORY_BYTES": str(budget)})


def _advised(detail: str, lead: str) -> tuple[int, int]:
    """The width x height a problem's detail advises, after ``lead``."""
    advice = detail.split(lead)[1].split(",")[0].split(" ")[0]
    width, height = (int(n) for n in advice.rstrip(")").split("x"))
    return width, height


def test_a_huge_texture_is_refused_at_once_naming_the_budget(client: httpx.Client) -> None:
    huge = _png(4900, 4900)
    assert client.get("/healthz").status_code == 200
    started = time.monotonic()
    response = synth(client, {"width": 1024, "height": 1024}, tex=huge)
    elapsed = time.monotonic() - started
    body = assert_problem(response, 422, "job_too_large")
    assert elapsed < 1.0, elapsed
    assert "memory" in body["detail"] and "job_memory_bytes" in body["detail"]
    assert "a texture of at most" in body["detail"], body["detail"]
    assert body["budget_bytes"] > 0 and body["budget_seconds"] > 0
    assert client.get("/healthz").status_code == 200


def test_memory_budget_follows_the_setting(
    start_server: Callable[[str, dict[str, str]], Server],
) -> None:
    server = _memory_server(start_server, "budget-memory", 125 << 20)
    with server.client() as client:
        buffer = io.BytesIO()
        Image.open(DATA / "gravel.png").convert("RGB").resize((512, 512)).save(buffer, "PNG")
        texture = buffer.getvalue()
        over = synth(client, {"width": 4096, "height": 4096, "block": 48}, tex=texture)
        body = assert_problem(over, 422, "job_too_large")
        assert body["budget_bytes"] > 125 << 20, body  # the interpreter counted in
        # A tileable output too: the advice only weighs outputs that hold a block per side.
        tiled = {"width": 4096, "height": 4096, "block": 48, "tileable": "both"}
        refused = assert_problem(synth(client, tiled, tex=texture), 422, "job_too_large")
        assert "an output of at most" in refused["detail"], refused
        # The advice is what fits: an output of at most that size is accepted, and well within
        # it the job is made in a worker whose memory is capped at the budget.
        width, height = _advised(body["detail"], "an output of at most ")
        accepted = synth(client, {"width": width, "height": height}, tex=texture, wait=0)
        assert accepted.status_code == 202, accepted.text
        client.delete(f"/jobs/{accepted.json()['id']}")
        side = width * 3 // 4
        done = synth(client, {"width": side, "height": side}, tex=texture, wait=60)
        assert_png(done, side, side)


def test_time_budget_follows_the_job_timeout(
    start_server: Callable[[str, dict[str, str]], Server],
) -> None:
    server = start_server("budget-time", {"QUILTING_WORKERS": "1", "QUILTING_JOB_TIMEOUT_S": "1"})
    with server.client() as client:
        over = synth(client, {"width": 8192, "height": 8192, "block": 16})
        body = assert_problem(over, 422, "job_too_large")
        assert "would take about" in body["detail"] and "budget of 1 s" in body["detail"]
        assert "block >=" in body["detail"] or "an output of at most" in body["detail"]
        refused = transfer(client, {"iterations": 8, "block": 8}, target=_png(4096, 4096))
        assert_problem(refused, 422, "job_too_large")


def test_a_tile_over_the_sandbox_budget_is_refused_at_once_naming_what_fits(
    start_server: Callable[[str, dict[str, str]], Server],
) -> None:
    server = _memory_server(start_server, "budget-tile", 200 << 20)
    with server.client() as client:
        started = time.monotonic()
        response = tile(client, _png(3000, 2000))  # about 400 MB to tile: twice the budget
        elapsed = time.monotonic() - started
        body = assert_problem(response, 422, "job_too_large")
        assert elapsed < 1.0, elapsed
        assert "memory" in body["detail"] and "job_memory_bytes" in body["detail"], body
        assert body["budget_bytes"] > 200 << 20 and body["budget_seconds"] > 0, body
        width, height = _advised(body["detail"], "an image of at most ")
        assert width < 3000 and height < 2000
        # What the advice names is tiled, in a sandbox process capped at the budget.
        tiled = tile(client, _png(width, height))
        assert_png(tiled, width, height)
        assert client.get("/healthz").status_code == 200
