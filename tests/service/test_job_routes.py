"""Unit tests of :mod:`quilting.service.routes.jobs`, the ``/jobs/{id}`` routes, in process.

The app is :func:`quilting.service.app.create_app` driven by Starlette's ``TestClient``
without its lifespan (no ``with``): no worker, no sandbox process, no network. Each test puts
its jobs straight into the app's in-memory :class:`~quilting.service.jobs.memory.Store`
(``add``, ``start``, ``finish``, ``cancel_queued``, ``expire``), in the state it needs, instead
of running the engine.

Covers
------
- ``GET /jobs/{id}``: the status document's members in each state (queued, running, done
  with and without a layout, a Wang tile set, failed, cancelled, expired), ``no-store``.
- ``GET /jobs/{id}/result``, ``/result/{name}``, ``/layout``, ``/manifest``: the exact bytes
  kept, their media types, ``Content-Disposition`` names (the job's stem, the fallback stem,
  a non-ASCII stem as ``filename*``), ``Cache-Control`` from ``results_ttl_s``, the
  ``Quilting-Extracted`` header on the result only; no ETag revalidation (the files never
  change under their URL).
- Refusals: 404 ``job_not_found`` for an unknown id and for another key's job (the same
  body), 404 ``companion_not_found``, ``no_layout``, ``no_manifest``, ``no_seams``, 409
  ``job_not_done`` with ``Retry-After`` while queued or running, 409 ``job_failed`` /
  ``job_cancelled`` without it, 410 ``result_expired`` (expired, or dropped since it was read),
  422 for a bad seam colour.
- ``DELETE /jobs/{id}``: a queued job is cancelled at once and its queue slot freed, a
  running one is flagged and keeps running, a second DELETE is harmless, a finished one is
  409 ``job_finished``.
- ``GET /jobs/{id}/events`` of a finished job: the retry line and one final event carrying the
  status document; 204 once the client has had it.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any
from urllib.parse import quote

import pytest
from fastapi.testclient import TestClient

from quilting.service.app import create_app
from quilting.service.events import END_EVENT_ID
from quilting.service.handlers import PROBLEM_JSON
from quilting.service.jobs import Job, Status, new_job_id
from quilting.service.jobs.memory import Store
from quilting.service.settings import Settings

#: A results time-to-live with a fraction: Cache-Control's max-age is its whole seconds.
TTL_S = 777.9
KEY, OTHER_KEY = "key-one", "key-two"

PNG = b"\x89PNG\r\n\x1a\n" + bytes(range(200))  # the routes never decode it
NORMAL = b"\x89PNG\r\n\x1a\nnormal-map" + bytes(range(50, 90))
LAYOUT = json.dumps({"version": 3, "blocks": [[0, 0, 1, 2]]}).encode()
MANIFEST = json.dumps({"tile": 16, "colors": 2, "tiles": [{"index": 0, "x": 0, "y": 0}]}).encode()


@dataclass
class Jobs:
    """An app that was never started, its client and its job store."""

    client: TestClient
    store: Store
    settings: Settings

    def add(
        self,
        *,
        owner: str | None = None,
        operation: str = "synthesize",
        stem: str = "brick-synth-8x4-seed7",
        companions: tuple[str, ...] = ("normal",),
    ) -> Job:
        """A queued job, as a submission leaves it."""
        job = Job(
            id=new_job_id(),
            owner=owner,
            width=8,
            height=4,
            companion_names=list(companions),
            input=None,
            operation=operation,
            download_stem=stem,
        )
        added, created = self.store.add(job)
        assert created and added is job
        return job

    def running(self, **kwargs: Any) -> Job:
        job = self.add(**kwargs)
        assert self.store.start(job)
        return job

    def done(
        self,
        *,
        layout: bytes | None = LAYOUT,
        stats: dict[str, Any] | None = None,
        **kwargs: Any,
    ) -> Job:
        job = self.running(**kwargs)
        companions = {name: NORMAL for name in job.companion_names}
        self.store.finish(
            job,
            Status.DONE,
            png=PNG,
            companions=companions,
            layout=layout,
            stats=stats or {"blocks": 2},
        )
        return job

    def failed(self, **kwargs: Any) -> Job:
        job = self.running(**kwargs)
        error = {"code": "invalid_parameter", "detail": "block too large"}
        self.store.finish(job, Status.FAILED, error=error)
        return job

    def cancelled(self, **kwargs: Any) -> Job:
        job = self.add(**kwargs)
        self.store.cancel_queued(job)
        # Final now, or the event stream of it would wait for a worker that never comes.
        assert job.status is Status.CANCELLED
        return job

    def expired(self, **kwargs: Any) -> Job:
        job = self.done(**kwargs)
        assert job.finished is not None
        self.store.expire(now=job.finished + TTL_S + 1)
        assert job.expired
        return job


def make_jobs(**settings: Any) -> Jobs:
    built = Settings(results_ttl_s=TTL_S, **settings)
    app = create_app(built)
    # No `with`: the lifespan (workers, sandbox) never starts; the store is all we need.
    client = TestClient(app, raise_server_exceptions=False)
    return Jobs(client, app.state.service.jobs.store, built)


@pytest.fixture(scope="module")
def jobs() -> Iterator[Jobs]:
    made = make_jobs()
    yield made
    made.client.close()


@pytest.fixture(scope="module")
def keyed() -> Iterator[Jobs]:
    made = make_jobs(api_keys=(KEY, OTHER_KEY))
    yield made
    made.client.close()


def assert_problem(response: Any, status: int, code: str) -> dict[str, Any]:
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == PROBLEM_JSON
    body: dict[str, Any] = response.json()
    assert body["status"] == status and body["code"] == code, body
    assert body["type"].endswith("/" + code)
    assert "Traceback" not in response.text
    return body


# --- the status document ----------------------------------------------------------------------


def test_a_queued_job_links_nothing_yet(jobs: Jobs) -> None:
    job = jobs.add()
    response = jobs.client.get(f"/jobs/{job.id}")
    assert response.status_code == 200
    assert response.headers["content-type"] == "application/json"
    assert response.headers["cache-control"] == "no-store"
    status = response.json()
    assert status["id"] == job.id and status["operation"] == "synthesize"
    assert (status["status"], status["stage"], status["progress"]) == ("queued", "queued", 0.0)
    assert status["started"] is None and status["finished"] is None
    assert (status["width"], status["height"]) == (8, 4)
    assert status["companions"] == ["normal"]
    assert (status["result"], status["layout"], status["manifest"]) == (None, None, None)
    assert status["expired"] is False and status["error"] is None


def test_a_running_job_shows_its_progress(jobs: Jobs) -> None:
    job = jobs.running()
    jobs.store.update(job, progress=0.25, stage="quilting")
    status = jobs.client.get(f"/jobs/{job.id}").json()
    assert (status["status"], status["stage"], status["progress"]) == ("running", "quilting", 0.25)
    assert status["started"] is not None and status["finished"] is None
    assert status["result"] is None


def test_a_done_job_links_its_result_and_layout(jobs: Jobs) -> None:
    job = jobs.done()
    status = jobs.client.get(f"/jobs/{job.id}").json()
    assert (status["status"], status["stage"], status["progress"]) == ("done", "done", 1.0)
    assert status["finished"] >= status["started"] >= status["created"]
    assert status["result"] == f"/jobs/{job.id}/result"
    assert status["layout"] == f"/jobs/{job.id}/layout"
    assert status["manifest"] is None  # only a Wang tile set has one
    assert status["stats"] == {"blocks": 2}


def test_a_done_job_without_a_layout_links_none(jobs: Jobs) -> None:
    job = jobs.done(operation="fill", layout=None, stem="camera-fill-8x4-seed3")
    status = jobs.client.get(f"/jobs/{job.id}").json()
    assert status["result"] == f"/jobs/{job.id}/result"
    assert status["layout"] is None and status["manifest"] is None


def test_a_wang_tile_set_links_its_manifest(jobs: Jobs) -> None:
    job = jobs.done(operation="wang_tiles", layout=MANIFEST, companions=())
    status = jobs.client.get(f"/jobs/{job.id}").json()
    assert status["operation"] == "wang_tiles"
    assert status["manifest"] == f"/jobs/{job.id}/manifest"
    assert status["layout"] == f"/jobs/{job.id}/layout"


def test_a_failed_job_gives_its_error(jobs: Jobs) -> None:
    job = jobs.failed()
    status = jobs.client.get(f"/jobs/{job.id}").json()
    assert (status["status"], status["stage"]) == ("failed", "failed")
    assert status["error"] == {"code": "invalid_parameter", "detail": "block too large"}
    assert (status["result"], status["layout"]) == (None, None)


def test_an_expired_job_says_so_and_links_nothing(jobs: Jobs) -> None:
    job = jobs.expired()
    status = jobs.client.get(f"/jobs/{job.id}").json()
    assert status["status"] == "done" and status["expired"] is True
    assert (status["result"], status["layout"], status["manifest"]) == (None, None, None)


# --- the files ----------------------------------------------------------------------------------


def test_the_result_is_the_kept_png_with_its_name_and_cache_policy(jobs: Jobs) -> None:
    job = jobs.done()
    response = jobs.client.get(f"/jobs/{job.id}/result")
    assert response.status_code == 200
    assert response.content == PNG
    assert response.headers["content-type"] == "image/png"
    assert response.headers["content-disposition"] == (
        'attachment; filename="brick-synth-8x4-seed7.png"'
    )
    assert response.headers["cache-control"] == f"private, max-age={int(TTL_S)}, immutable"
    assert "quilting-extracted" not in response.headers


def test_the_result_is_not_revalidated_with_an_etag(jobs: Jobs) -> None:
    # The files never change under their URL (immutable): no ETag, and If-None-Match changes
    # nothing.
    job = jobs.done()
    first = jobs.client.get(f"/jobs/{job.id}/result")
    assert "etag" not in first.headers
    again = jobs.client.get(f"/jobs/{job.id}/result", headers={"If-None-Match": "*"})
    assert again.status_code == 200 and again.content == PNG


def test_a_companion_is_its_own_png_and_name(jobs: Jobs) -> None:
    job = jobs.done(stats={"blocks": 2, "extracted": [{"method": "trimap", "foreground": 0.5}]})
    response = jobs.client.get(f"/jobs/{job.id}/result/normal")
    assert response.status_code == 200
    assert response.content == NORMAL
    assert response.headers["content-type"] == "image/png"
    assert response.headers["content-disposition"] == (
        'attachment; filename="brick-synth-8x4-seed7-normal.png"'
    )
    assert response.headers["cache-control"] == f"private, max-age={int(TTL_S)}, immutable"
    # The extraction summary is the result's, not a companion's.
    assert "quilting-extracted" not in response.headers
    result = jobs.client.get(f"/jobs/{job.id}/result")
    assert json.loads(result.headers["quilting-extracted"]) == job.stats["extracted"]  # type: ignore[index]


def test_the_layout_is_the_kept_json(jobs: Jobs) -> None:
    job = jobs.done()
    response = jobs.client.get(f"/jobs/{job.id}/layout")
    assert response.status_code == 200
    assert response.content == LAYOUT
    assert response.headers["content-type"] == "application/json"
    assert response.headers["content-disposition"] == (
        'attachment; filename="brick-synth-8x4-seed7-layout.json"'
    )
    assert response.headers["cache-control"] == f"private, max-age={int(TTL_S)}, immutable"


def test_a_wang_manifest_is_its_layout_under_another_name(jobs: Jobs) -> None:
    job = jobs.done(operation="wang_tiles", layout=MANIFEST, stem="gravel-wang-32x32-seed0")
    manifest = jobs.client.get(f"/jobs/{job.id}/manifest")
    layout = jobs.client.get(f"/jobs/{job.id}/layout")
    assert manifest.status_code == layout.status_code == 200
    assert manifest.content == layout.content == MANIFEST
    assert manifest.headers["content-type"] == "application/json"
    assert manifest.headers["content-disposition"] == (
        'attachment; filename="gravel-wang-32x32-seed0-manifest.json"'
    )
    assert layout.headers["content-disposition"] == (
        'attachment; filename="gravel-wang-32x32-seed0-layout.json"'
    )
    assert manifest.headers["cache-control"] == f"private, max-age={int(TTL_S)}, immutable"


def test_a_job_without_a_stem_is_named_by_operation_and_size(jobs: Jobs) -> None:
    job = jobs.done(operation="fill", stem="", layout=None)
    response = jobs.client.get(f"/jobs/{job.id}/result/normal")
    assert response.headers["content-disposition"] == (
        'attachment; filename="texture-fill-8x4-normal.png"'
    )


def test_a_non_ascii_stem_is_sent_in_filename_star(jobs: Jobs) -> None:
    stem = "brique-été-synth-8x4-seed1"
    job = jobs.done(stem=stem)
    header = jobs.client.get(f"/jobs/{job.id}/layout").headers["content-disposition"]
    assert header == (
        'attachment; filename="brique-ete-synth-8x4-seed1-layout.json"; '
        "filename*=UTF-8''" + quote(stem + "-layout.json", safe="")
    )


# --- refusals -----------------------------------------------------------------------------------

FILES = ("result", "result/normal", "layout")


@pytest.mark.parametrize("path", ["", "/result", "/result/normal", "/layout", "/manifest"])
def test_an_unknown_job_is_404(jobs: Jobs, path: str) -> None:
    unknown = new_job_id()
    body = assert_problem(jobs.client.get(f"/jobs/{unknown}{path}"), 404, "job_not_found")
    assert body["job_id"] == unknown


@pytest.mark.parametrize("path", ["", "/result", "/layout", "/events"])
def test_another_keys_job_is_the_same_404_as_an_unknown_one(keyed: Jobs, path: str) -> None:
    job = keyed.done(owner=KEY)
    mine = keyed.client.get(f"/jobs/{job.id}{path}", headers={"X-API-Key": KEY})
    assert mine.status_code == 200
    other = keyed.client.get(f"/jobs/{job.id}{path}", headers={"X-API-Key": OTHER_KEY})
    # The same answer as for an id that was never used: nothing tells the job exists.
    keyed.store.jobs.pop(job.id)
    gone = keyed.client.get(f"/jobs/{job.id}{path}", headers={"X-API-Key": OTHER_KEY})
    assert_problem(other, 404, "job_not_found")
    assert other.json() == gone.json()
    assert other.headers == gone.headers


def test_a_job_route_without_a_key_is_401(keyed: Jobs) -> None:
    job = keyed.done(owner=KEY)
    response = keyed.client.get(f"/jobs/{job.id}/result")
    assert_problem(response, 401, "unauthorized")
    assert response.headers["www-authenticate"] == "Bearer"


def test_a_companion_the_job_lacks_is_404(jobs: Jobs) -> None:
    job = jobs.done()
    body = assert_problem(
        jobs.client.get(f"/jobs/{job.id}/result/roughness"), 404, "companion_not_found"
    )
    assert "roughness" in body["detail"]


@pytest.mark.parametrize("state", ["queued", "running"])
@pytest.mark.parametrize("path", [*FILES, "manifest"])
def test_a_file_of_an_unfinished_job_is_409_with_retry_after(
    jobs: Jobs, state: str, path: str
) -> None:
    operation = "wang_tiles" if path == "manifest" else "synthesize"
    job = jobs.add(operation=operation) if state == "queued" else jobs.running(operation=operation)
    response = jobs.client.get(f"/jobs/{job.id}/{path}")
    body = assert_problem(response, 409, "job_not_done")
    assert response.headers["retry-after"] == "1"
    assert state in body["detail"]


@pytest.mark.parametrize(
    ("state", "code"), [("failed", "job_failed"), ("cancelled", "job_cancelled")]
)
@pytest.mark.parametrize("path", FILES)
def test_a_file_of_a_job_without_a_result_is_409_without_retry(
    jobs: Jobs, state: str, code: str, path: str
) -> None:
    job = jobs.failed() if state == "failed" else jobs.cancelled()
    response = jobs.client.get(f"/jobs/{job.id}/{path}")
    assert_problem(response, 409, code)
    assert "retry-after" not in response.headers  # waiting will not help


@pytest.mark.parametrize("path", [*FILES, "seams"])
def test_a_file_of_an_expired_job_is_410(jobs: Jobs, path: str) -> None:
    job = jobs.expired()
    response = jobs.client.get(f"/jobs/{job.id}/{path}")
    assert_problem(response, 410, "result_expired")
    assert "retry-after" not in response.headers


@pytest.mark.parametrize("path", ["result", "result/normal", "layout"])
def test_a_file_dropped_after_the_job_was_read_is_410(jobs: Jobs, path: str) -> None:
    # The job is done and not yet marked expired, but its bytes are gone (evicted between the
    # job's lookup and the file's read): 410, never a 200 without a body.
    job = jobs.done()
    job.png, job.companions, job.layout = None, {}, None
    job.companion_names = ["normal"]
    assert_problem(jobs.client.get(f"/jobs/{job.id}/{path}"), 410, "result_expired")


def test_a_job_without_a_layout_has_no_layout_nor_seams(jobs: Jobs) -> None:
    job = jobs.done(operation="fill", layout=None)
    for path in ("layout", "seams"):
        assert_problem(jobs.client.get(f"/jobs/{job.id}/{path}"), 404, "no_layout")


def test_only_a_wang_tile_set_has_a_manifest(jobs: Jobs) -> None:
    job = jobs.done()
    body = assert_problem(jobs.client.get(f"/jobs/{job.id}/manifest"), 404, "no_manifest")
    assert "synthesize" in body["detail"]


def test_a_wang_tile_set_has_no_seams(jobs: Jobs) -> None:
    job = jobs.done(operation="wang_tiles", layout=MANIFEST, companions=())
    assert_problem(jobs.client.get(f"/jobs/{job.id}/seams"), 404, "no_seams")


@pytest.mark.parametrize("color", ["red", "ff00001", "#ff0000", "gg0000", ""])
def test_a_bad_seam_colour_is_422_naming_it(jobs: Jobs, color: str) -> None:
    job = jobs.done()
    response = jobs.client.get(f"/jobs/{job.id}/seams", params={"color": color})
    body = assert_problem(response, 422, "invalid_parameter")
    assert body["field"] == "color"


# --- cancelling ---------------------------------------------------------------------------------


def test_deleting_a_queued_job_cancels_it_at_once(jobs: Jobs) -> None:
    job = jobs.add()
    queued = jobs.store.queued
    response = jobs.client.delete(f"/jobs/{job.id}")
    assert response.status_code == 202
    assert response.json()["status"] == "cancelled"
    assert response.json()["stage"] == "cancelled"
    assert job.status is Status.CANCELLED and job.cancel.is_set()
    assert jobs.store.queued == queued - 1  # its slot is free now
    again = jobs.client.delete(f"/jobs/{job.id}")
    assert again.status_code == 202 and again.json()["status"] == "cancelled"
    assert jobs.store.queued == queued - 1  # not freed twice
    assert jobs.client.get(f"/jobs/{job.id}").json()["status"] == "cancelled"


def test_deleting_a_running_job_flags_it(jobs: Jobs) -> None:
    job = jobs.running()
    running = jobs.store.running
    response = jobs.client.delete(f"/jobs/{job.id}")
    assert response.status_code == 202
    # The worker stops it at its next step: until then it runs.
    assert response.json()["status"] == "running"
    assert job.cancel.is_set() and job.status is Status.RUNNING
    assert jobs.client.delete(f"/jobs/{job.id}").status_code == 202
    assert jobs.store.running == running


@pytest.mark.parametrize("state", ["done", "failed"])
def test_deleting_a_finished_job_is_409(jobs: Jobs, state: str) -> None:
    job = jobs.done() if state == "done" else jobs.failed()
    body = assert_problem(jobs.client.delete(f"/jobs/{job.id}"), 409, "job_finished")
    assert state in body["detail"]
    assert job.status.value == state and not job.cancel.is_set()


def test_deleting_an_unknown_job_is_404(jobs: Jobs) -> None:
    assert_problem(jobs.client.delete(f"/jobs/{new_job_id()}"), 404, "job_not_found")


# --- events of a finished job -------------------------------------------------------------------


def test_a_finished_jobs_stream_is_its_final_event(jobs: Jobs) -> None:
    job = jobs.cancelled()
    response = jobs.client.get(f"/jobs/{job.id}/events")
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/event-stream")
    assert response.headers["cache-control"] == "no-cache"
    blocks = [b for b in response.text.split("\n\n") if b]
    assert blocks[0].startswith("retry: ")
    assert blocks[1:] == [
        f"id: {END_EVENT_ID}\nevent: cancelled\ndata: {json.dumps(job.snapshot())}"
    ]
    after = jobs.client.get(f"/jobs/{job.id}/events", headers={"Last-Event-ID": str(END_EVENT_ID)})
    assert after.status_code == 204 and after.content == b""
