"""What a client takes away from a job: its files under names that say what they are, and its
progress as an event stream that resumes where a broken connection left it.

Download names (quilting.service.downloads): ``Content-Disposition: attachment`` with a name
made from the upload's file name, the operation, the output's width x height and the seed, on
every kind of result, made safe whatever the client sent, carried with the job through the
in-memory store and through Redis, and the same names on the web page's download links.

Event ids: every event of ``/jobs/{id}/events`` has an increasing ``id:``; ``Last-Event-ID``
skips what the client already has, on any replica of a Redis deployment.
"""

from __future__ import annotations

import itertools
import json
import re
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import unquote

import httpx
import numpy as np
import pytest
from browser import Console, launch_browser, missing, new_context, skip_or_fail, watch
from cluster import RedisServer, WorkerProcess, need_redis
from PIL import Image
from service_helpers import (
    DATA,
    Server,
    assert_png,
    assert_problem,
    job_id_of,
    lit_sphere,
    png_bytes,
    texture,
    wait_for,
)

from quilting.service.downloads import (
    FALLBACK_STEM,
    MAX_STEM_BYTES,
    content_disposition,
    job_stem,
    safe_stem,
    tile_name,
)

if TYPE_CHECKING:
    from playwright.sync_api import Browser, Page

#: A synthesis that takes a fraction of a second: width 96, height 64 (not square: the name
#: must say which is which).
SMALL = {"width": 96, "height": 64, "block": 24, "seed": 7}
#: A synthesis that runs for seconds on this machine: time to read its events mid-way.
LONG = {"width": 2048, "height": 2048, "block": 24, "seed": 11}
#: Generous: a 2-core machine runs the service, its workers (and Chromium) at once.
JOB_S = 120.0
#: The longest wait the service takes (max_wait_s).
WAIT_S = 60.0


# --- helpers --------------------------------------------------------------------------------


def crop(name: str, width: int, height: int) -> bytes:
    """The top-left ``width`` x ``height`` of ``tests/data/<name>.png`` as PNG bytes."""
    with Image.open(DATA / f"{name}.png") as image:
        return png_bytes(np.asarray(image)[:height, :width])


#: ``attachment; filename="<printable ASCII>"`` and, for a name that is not ASCII,
#: ``; filename*=UTF-8''<percent-encoded>``.
DISPOSITION = re.compile(
    r'attachment; filename="(?P<plain>[ -~]+)"'
    r"(?:; filename\*=UTF-8''(?P<exact>[A-Za-z0-9%._~-]+))?"
)


def filename_of(response: httpx.Response) -> str:
    """The download name of ``response`` (RFC 6266): its ``filename*`` (RFC 8187) when it
    has one, else its ``filename``, after checking the header's form."""
    header = response.headers.get("content-disposition")
    assert header, f"{response.url} has no Content-Disposition"
    header.encode("ascii")  # a header line is ASCII: the exact name goes in filename*
    found = DISPOSITION.fullmatch(header)
    assert found, header
    plain = found.group("plain")
    assert '"' not in plain and "\\" not in plain, header
    if found.group("exact") is None:
        return plain
    exact = unquote(found.group("exact"), errors="strict")
    assert exact != plain and not exact.isascii(), header
    return exact


def post_job(
    client: httpx.Client,
    path: str,
    files: list[tuple[str, tuple[str, bytes, str]]],
    options: dict[str, Any],
    wait: float = WAIT_S,
    headers: dict[str, str] | None = None,
) -> httpx.Response:
    """``POST path`` (an operation) with ``files`` and ``options`` as its form."""
    return client.post(
        path,
        params={"wait": wait},
        files=files,
        data={"options": json.dumps(options)},
        headers=headers,
    )


def synthesize(
    client: httpx.Client,
    filename: str,
    options: dict[str, Any],
    *,
    data: bytes | None = None,
    companions: dict[str, bytes] | None = None,
    wait: float = WAIT_S,
    headers: dict[str, str] | None = None,
) -> httpx.Response:
    files = [("texture", (filename, data or texture("brick"), "image/png"))]
    files += [("companion", (n, c, "image/png")) for n, c in (companions or {}).items()]
    return post_job(client, "/synthesize", files, options, wait, headers)


def job_named(response: httpx.Response, stem: str) -> str:
    """The job of an answer whose PNG is named ``<stem>.png``."""
    assert filename_of(response) == f"{stem}.png"
    return job_id_of(response)


# --- the names, as functions ----------------------------------------------------------------


@pytest.mark.parametrize(
    ("sent", "stem"),
    [
        ("brick.png", "brick"),
        ("brick.v2.final.png", "brick.v2.final"),
        ('../../etc/pass"wd.png', "pass-wd"),
        ("C:\\Users\\me\\My Textures\\red  brick.jpeg", "red brick"),
        ("evil\r\nSet-Cookie: x=1.png", "evil Set-Cookie- x-1"),
        ("a\x00b\x1bc.png", "a-b-c"),
        ("\u202egnp.exe.png", "gnp.exe"),  # a right-to-left override is not kept
        ("Ziegel-\u00e4 \u7816.png", "Ziegel-\u00e4 \u7816"),
        ("e\u0301t\u00e9.png", "\u00e9t\u00e9"),  # composed (NFC)
        ("..", FALLBACK_STEM),
        ("...png", FALLBACK_STEM),
        (".hidden.png", "hidden"),
        ("", FALLBACK_STEM),
        (None, FALLBACK_STEM),
        ('"";:*?.png', FALLBACK_STEM),
        ("pass%22wd%0D%0Ax.png", "pass-wd x"),  # a browser's escapes of a quote, CR, LF
    ],
)
def test_safe_stem(sent: str | None, stem: str) -> None:
    assert safe_stem(sent) == stem


def test_a_long_stem_is_cut_on_a_character_boundary() -> None:
    stem = safe_stem("\u7816" * 100 + ".png")  # three bytes of UTF-8 each
    assert stem == "\u7816" * (MAX_STEM_BYTES // 3)
    assert len(safe_stem("x" * 500 + ".png").encode()) == MAX_STEM_BYTES


def test_job_stems_name_operation_size_and_seed() -> None:
    assert job_stem("synthesize", "brick.png", None, 1024, 768, 7) == "brick-synth-1024x768-seed7"
    assert (
        job_stem("transfer", "brick.png", "photos/camera.jpg", 640, 480, 0)
        == "brick-on-camera-transfer-640x480-seed0"
    )
    assert (
        job_stem("matte", "cloth.png", "vase.png", 300, 200, 5)
        == "cloth-on-vase-matte-300x200-seed5"
    )
    assert job_stem("synthesize", None, "ignored.png", 8, 9, 1) == "texture-synth-8x9-seed1"
    assert tile_name("wall.jpeg") == "wall-tile.png"


def test_content_disposition_forms() -> None:
    assert content_disposition("brick-tile.png") == 'attachment; filename="brick-tile.png"'
    header = content_disposition("Ziegel-\u00e4 \u7816-tile.png")
    assert header == (
        'attachment; filename="Ziegel-a _-tile.png"; '
        "filename*=UTF-8''Ziegel-%C3%A4%20%E7%A0%96-tile.png"
    )


# --- the names over HTTP, in-memory store ---------------------------------------------------


def test_a_synthesis_and_all_its_files_are_named(client: httpx.Client) -> None:
    normal = png_bytes(255 - np.asarray(Image.open(DATA / "brick.png")))
    response = synthesize(client, "brick.png", SMALL, companions={"normal.png": normal})
    assert_png(response, 96, 64)
    stem = "brick-synth-96x64-seed7"
    # Answered at once: the PNG itself carries the name.
    job_id = job_named(response, stem)
    named = {
        f"/jobs/{job_id}/result": f"{stem}.png",
        f"/jobs/{job_id}/result/normal": f"{stem}-normal.png",
        f"/jobs/{job_id}/layout": f"{stem}-layout.json",
        f"/jobs/{job_id}/seams": f"{stem}-seams.png",
        f"/jobs/{job_id}/seams?color=00ff00": f"{stem}-seams.png",
    }
    for path, name in named.items():
        got = client.get(path)
        assert got.status_code == 200, (path, got.text[:200])
        assert filename_of(got) == name, path
    layout = client.get(f"/jobs/{job_id}/layout")
    assert layout.headers["content-type"] == "application/json"
    json.loads(layout.content)  # the body is untouched JSON


def test_a_job_answered_later_has_the_same_names(client: httpx.Client) -> None:
    response = synthesize(client, "gravel.png", {**SMALL, "seed": 3}, wait=0)
    job_id = job_id_of(response)
    if response.status_code == 202:
        assert "content-disposition" not in response.headers  # a status document, no file
    assert wait_for(client, job_id, timeout=JOB_S)["status"] == "done"
    result = client.get(f"/jobs/{job_id}/result")
    assert filename_of(result) == "gravel-synth-96x64-seed3.png"


def test_a_transfer_names_texture_target_and_the_targets_size(client: httpx.Client) -> None:
    files = [
        ("texture", ("gravel.png", texture("gravel"), "image/png")),
        ("target", ("camera shot.png", crop("target_camera", 80, 48), "image/png")),
    ]
    response = post_job(client, "/transfer", files, {"block": 16, "seed": 4})
    assert_png(response, 80, 48)
    stem = "gravel-on-camera shot-transfer-80x48-seed4"
    job_id = job_named(response, stem)
    assert filename_of(client.get(f"/jobs/{job_id}/layout")) == f"{stem}-layout.json"
    assert filename_of(client.get(f"/jobs/{job_id}/seams")) == f"{stem}-seams.png"


def test_a_matte_names_its_first_layer_target_and_companions(client: httpx.Client) -> None:
    target, silhouette = (png_bytes(image) for image in lit_sphere(112, 96))
    files = [
        ("target", ("vase.png", target, "image/png")),
        ("silhouette", ("vase-mask.png", silhouette, "image/png")),
        ("layer", ("cloth.png", texture("brick"), "image/png")),
        ("layer", ("cloud.png", texture("cloud_rgba"), "image/png")),
    ]
    options = {"block": 32, "seed": 5, "clusters": 6, "backend": "fft"}
    response = post_job(client, "/matte", files, options)
    assert_png(response, 112, 96)
    stem = "cloth-on-vase-matte-112x96-seed5"
    job_id = job_named(response, stem)
    for name in ("normals", "clusters"):
        assert filename_of(client.get(f"/jobs/{job_id}/result/{name}")) == f"{stem}-{name}.png"


def test_a_tiled_image_is_named_after_it(client: httpx.Client) -> None:
    files = [("image", ("wood planks.png", texture("wood"), "image/png"))]
    response = client.post("/tile", files=files)
    assert_png(response, 136, 136)
    assert filename_of(response) == "wood planks-tile.png"


@pytest.mark.parametrize(
    ("sent", "name"),
    [
        ('../../etc/pass"wd.png', "pass-wd-synth-96x64-seed7.png"),
        ("..\\..\\boot.ini", "boot-synth-96x64-seed7.png"),
        ("x\r\nSet-Cookie: a=b.png", "x Set-Cookie- a-b-synth-96x64-seed7.png"),
        ('"";:*?.png', "texture-synth-96x64-seed7.png"),
        ("Ziegel-\u00e4 \u7816.png", "Ziegel-\u00e4 \u7816-synth-96x64-seed7.png"),
        ("\u7816" * 200 + ".png", "\u7816" * 21 + "-synth-96x64-seed7.png"),
    ],
    ids=["path-and-quote", "windows-path", "header-injection", "no-name", "non-ascii", "long"],
)
def test_hostile_or_odd_file_names_are_made_safe(
    client: httpx.Client, sent: str, name: str
) -> None:
    response = synthesize(client, sent, SMALL)
    assert response.status_code == 200, response.text[:300]
    assert filename_of(response) == name
    header = response.headers["content-disposition"]
    assert "\r" not in header and "\n" not in header
    assert "set-cookie" not in response.headers
    # The exact name is in filename* only when it is not ASCII; the plain one is ASCII.
    assert ("filename*=" in header) == (not name.isascii())


def test_an_upload_without_a_file_name_is_a_problem(client: httpx.Client) -> None:
    # A multipart part without a file name is a form field, not a file: 422, never a 500.
    response = synthesize(client, "", SMALL)
    assert_problem(response, 422, "invalid_parameter", field="texture")


def test_the_plain_name_is_the_exact_one_in_ascii(client: httpx.Client) -> None:
    response = synthesize(client, "Caf\u00e9 \u7816.png", SMALL)
    header = response.headers["content-disposition"]
    assert header.startswith('attachment; filename="Cafe _-synth-96x64-seed7.png"; '), header
    assert filename_of(response) == "Caf\u00e9 \u7816-synth-96x64-seed7.png"


def test_idempotent_retries_keep_the_first_name(client: httpx.Client) -> None:
    key = {"Idempotency-Key": f"names-{time.monotonic_ns()}"}
    first = synthesize(client, "first.png", {**SMALL, "seed": 21}, headers=key)
    again = synthesize(client, "renamed.png", {**SMALL, "seed": 21}, headers=key)
    # The same files and options are the same request, whatever they are called.
    assert job_id_of(first) == job_id_of(again)
    assert filename_of(again) == filename_of(first) == "first-synth-96x64-seed21.png"


# --- event ids ------------------------------------------------------------------------------


@dataclass
class Event:
    id: int
    name: str
    data: dict[str, Any]


@dataclass
class Stream:
    status: int
    retry: int | None
    events: list[Event]


def read_stream(
    client: httpx.Client,
    job_id: str,
    last_event_id: int | str | None = None,
    *,
    stop_after: Any = None,
) -> Stream:
    """The events of ``/jobs/{id}/events`` (all, or until ``stop_after(event)`` is true)."""
    headers = {} if last_event_id is None else {"Last-Event-ID": str(last_event_id)}
    events: list[Event] = []
    retry = None
    with client.stream("GET", f"/jobs/{job_id}/events", headers=headers, timeout=JOB_S) as response:
        if response.status_code != 200:
            response.read()
            return Stream(response.status_code, None, [])
        assert response.headers["content-type"].startswith("text/event-stream")
        fields: dict[str, list[str]] = {}
        for line in response.iter_lines():
            if line:
                name, _, value = line.partition(":")
                fields.setdefault(name, []).append(value.removeprefix(" "))
                continue
            if "retry" in fields:
                retry = int(fields["retry"][-1])
            if "data" in fields:
                assert "id" in fields, f"an event without an id: {fields}"
                event = Event(
                    int(fields["id"][-1]),
                    fields.get("event", ["message"])[-1],
                    json.loads("\n".join(fields["data"])),
                )
                events.append(event)
                if stop_after is not None and stop_after(event):
                    break
            fields = {}
    return Stream(200, retry, events)


def assert_increasing(events: list[Event]) -> None:
    ids = [e.id for e in events]
    assert all(a < b for a, b in itertools.pairwise(ids)), ids


def finished_job_with_events(client: httpx.Client) -> tuple[str, Stream]:
    """A job followed from its start to its end: (id, its whole stream)."""
    job_id = job_id_of(synthesize(client, "gravel.png", {**LONG, "width": 1024}, wait=0))
    stream = read_stream(client, job_id)
    assert stream.status == 200
    assert stream.events[-1].name == "done", [e.name for e in stream.events]
    return job_id, stream


def test_every_event_has_an_increasing_id_and_the_stream_a_retry(client: httpx.Client) -> None:
    _, stream = finished_job_with_events(client)
    assert stream.retry is not None and 0 < stream.retry <= 10_000
    progress, end = stream.events[:-1], stream.events[-1]
    assert progress and all(e.name == "progress" for e in progress)
    assert_increasing(stream.events)
    assert all(e.id >= 0 for e in stream.events)
    assert end.data["status"] == "done"


def test_reconnecting_after_the_end_gets_just_the_end(client: httpx.Client) -> None:
    job_id, stream = finished_job_with_events(client)
    end = stream.events[-1]
    for seen in stream.events[:-1]:
        # A client cut off after any progress event gets exactly the end, with the same id.
        again = read_stream(client, job_id, seen.id)
        assert [(e.name, e.id) for e in again.events] == [("done", end.id)]
        assert again.events[0].id > seen.id
        assert again.events[0].data == end.data
    # A client that had the end gets nothing, and 204 tells an EventSource to stop retrying.
    response = client.get(f"/jobs/{job_id}/events", headers={"Last-Event-ID": str(end.id)})
    assert response.status_code == 204 and response.content == b""
    # Without Last-Event-ID the stream starts over: the end, same id.
    fresh = read_stream(client, job_id)
    assert [(e.name, e.id) for e in fresh.events] == [("done", end.id)]


def test_resuming_a_running_job_skips_what_was_seen(client: httpx.Client) -> None:
    job_id = job_id_of(synthesize(client, "gravel.png", LONG, wait=0))
    try:

        def running(event: Event) -> bool:
            return event.data.get("status") == "running" and event.data["progress"] > 0

        first = read_stream(client, job_id, stop_after=running)
        assert first.events and running(first.events[-1]), [e.data for e in first.events]
        seen = first.events[-1]
        resumed = read_stream(
            client, job_id, seen.id, stop_after=lambda e: e.data.get("progress", 0) > 0.05
        )
        assert resumed.events, "nothing after the event the client had"
        assert all(e.id > seen.id for e in resumed.events), (seen.id, resumed.events)
        assert_increasing(first.events + resumed.events)
        fractions = [
            e.data["progress"] for e in first.events + resumed.events if e.name == "progress"
        ]
        assert fractions == sorted(fractions)
        # Not the same event again: the job had moved on (or ended) by the next one.
        assert (resumed.events[0].data.get("progress"), resumed.events[0].data.get("stage")) != (
            seen.data["progress"],
            seen.data["stage"],
        )
    finally:
        client.delete(f"/jobs/{job_id}")
    end = read_stream(client, job_id, seen.id)
    assert end.events[-1].name in ("cancelled", "done")
    assert all(e.id > seen.id for e in end.events)


@pytest.mark.parametrize("value", ["abc", "-1", "1.5", "1" * 25, "0x10"])
def test_a_bad_last_event_id_is_a_problem(client: httpx.Client, value: str) -> None:
    job_id = job_id_of(synthesize(client, "brick.png", SMALL))
    response = client.get(f"/jobs/{job_id}/events", headers={"Last-Event-ID": value})
    assert_problem(response, 422, "invalid_parameter", field="Last-Event-ID")


# --- through Redis --------------------------------------------------------------------------


@dataclass
class RedisDeployment:
    redis: RedisServer
    apis: list[Server]
    worker: WorkerProcess


@pytest.fixture(scope="module")
def redis_deployment(
    tmp_path_factory: pytest.TempPathFactory, log_dir: Path
) -> Iterator[RedisDeployment]:
    """Redis, two API replicas and one worker."""
    need_redis()
    redis = RedisServer(tmp_path_factory.mktemp("redis-names")).start()
    env = {"QUILTING_QUEUE": redis.url, "QUILTING_DRAIN_GRACE_S": "5"}
    apis: list[Server] = []
    worker: WorkerProcess | None = None
    try:
        apis = [Server(f"redis-api{n}", env, log_dir).start() for n in range(2)]
        worker = WorkerProcess("names", env, log_dir).start()
        yield RedisDeployment(redis, apis, worker)
    finally:
        if worker is not None:
            worker.stop()
        for api in apis:
            api.stop()
        redis.stop()


def test_names_are_kept_with_the_job_in_redis(redis_deployment: RedisDeployment) -> None:
    a, b = redis_deployment.apis
    with a.client() as ca, b.client() as cb:
        response = synthesize(ca, "Ziegel-\u00e4.png", SMALL, wait=0)
        job_id = job_id_of(response)
        assert wait_for(cb, job_id, timeout=JOB_S)["status"] == "done"
        stem = "Ziegel-\u00e4-synth-96x64-seed7"
        # Read from the other replica: the name came through the job's record in Redis.
        assert filename_of(cb.get(f"/jobs/{job_id}/result")) == f"{stem}.png"
        assert filename_of(cb.get(f"/jobs/{job_id}/layout")) == f"{stem}-layout.json"
        assert filename_of(ca.get(f"/jobs/{job_id}/seams")) == f"{stem}-seams.png"


def test_events_resume_on_another_replica(redis_deployment: RedisDeployment) -> None:
    a, b = redis_deployment.apis
    with a.client() as ca, b.client() as cb:
        job_id = job_id_of(synthesize(ca, "gravel.png", {**LONG, "width": 1024}, wait=0))
        first = read_stream(ca, job_id, stop_after=lambda e: e.data.get("progress", 0) > 0)
        seen = first.events[-1]
        # The connection broke; the client comes back through the other replica.
        rest = read_stream(cb, job_id, seen.id)
        assert rest.events[-1].name == "done", [e.name for e in rest.events]
        assert all(e.id > seen.id for e in rest.events)
        assert_increasing(first.events + rest.events)
        fractions = [e.data["progress"] for e in first.events + rest.events if e.name == "progress"]
        assert fractions == sorted(fractions)
        # And one that had everything gets 204 from either.
        for client in (ca, cb):
            done = client.get(
                f"/jobs/{job_id}/events", headers={"Last-Event-ID": str(rest.events[-1].id)}
            )
            assert done.status_code == 204


# --- the web page's download links ----------------------------------------------------------


@pytest.fixture(scope="module")
def chromium() -> Iterator[Browser]:
    reason = missing()
    if reason is not None:
        skip_or_fail(reason)
    yield from launch_browser()


def page_of(chromium: Browser, server: Server) -> tuple[Page, Console]:
    page = new_context(chromium).new_page()
    console = watch(page)
    page.goto(server.url + "/")
    page.locator("#opt-block").wait_for(state="attached", timeout=30_000)
    return page, console


def set_option(page: Page, name: str, value: object) -> None:
    field = page.locator(f"#opt-{name}")
    if not field.is_visible():
        page.locator(f"details:has(#opt-{name}) > summary").click()
    field.fill(str(value))


def run_and_wait_downloads(page: Page) -> None:
    page.locator("#run").click()
    page.locator("#downloads").wait_for(state="visible", timeout=JOB_S * 1000)


@pytest.mark.browser
def test_the_pages_download_links_use_the_services_names(
    chromium: Browser, server: Server, client: httpx.Client
) -> None:
    page, console = page_of(chromium, server)
    try:
        page.set_input_files(
            "#texture",
            {"name": "Kies \u00e4.png", "mimeType": "image/png", "buffer": texture("gravel")},
        )
        normal = png_bytes(255 - np.asarray(Image.open(DATA / "gravel.png")))
        page.set_input_files(
            "#companions", {"name": "normal.png", "mimeType": "image/png", "buffer": normal}
        )
        for name, value in {"width": 120, "height": 80, "block": 32, "seed": 9}.items():
            set_option(page, name, value)
        run_and_wait_downloads(page)
        job_id = (page.locator("#job-id").text_content() or "").strip()
        assert re.fullmatch(r"[0-9a-f]{32}", job_id), job_id
        stem = "Kies \u00e4-synth-120x80-seed9"
        served = {
            "#download-png": filename_of(client.get(f"/jobs/{job_id}/result")),
            "#download-layout": filename_of(client.get(f"/jobs/{job_id}/layout")),
            "a.download-companion": filename_of(client.get(f"/jobs/{job_id}/result/normal")),
        }
        assert served == {
            "#download-png": f"{stem}.png",
            "#download-layout": f"{stem}-layout.json",
            "a.download-companion": f"{stem}-normal.png",
        }
        for selector, name in served.items():
            assert page.locator(selector).get_attribute("download") == name, selector
        # What the browser saves the file as.
        with page.expect_download(timeout=30_000) as info:
            page.locator("#download-png").click()
        assert info.value.suggested_filename == f"{stem}.png"

        page.get_by_role("radio", name="Make tileable", exact=True).check()
        page.set_input_files(
            "#texture", {"name": "wood.png", "mimeType": "image/png", "buffer": texture("wood")}
        )
        page.evaluate("() => { document.querySelector('#downloads').hidden = true; }")
        run_and_wait_downloads(page)
        page.wait_for_function(
            "() => document.querySelector('#download-png').download === 'wood-tile.png'",
            timeout=30_000,
        )
        console.assert_clean()
    finally:
        page.context.close()
