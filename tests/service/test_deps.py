"""Unit tests of :mod:`quilting.service.deps`, the routes' FastAPI dependencies.

Each dependency is mounted on a tiny FastAPI app (the service's own exception handlers, a
:class:`~quilting.service.context.Service` built from :class:`Settings` but never started)
and driven in-process with Starlette's ``TestClient``; no server, no worker, no network.

Covers
------
- ``owner``: no keys means no owner whatever is sent; ``X-API-Key`` or
  ``Authorization: Bearer`` (any case, blanks stripped; a Bearer key decides over
  ``X-API-Key``, another scheme does not); a missing, wrong, truncated or extended key is 401
  ``unauthorized`` with ``WWW-Authenticate: Bearer`` and a detail that does not echo it.
- ``metrics_reader``: a key needed only with keys and ``metrics_public`` off.
- ``job_of``: a job is found by its owner's key (either header); another key, or an unknown
  id, is the same 404 ``job_not_found`` (never 403); no key at all is 401.
- ``submitting`` / ``Submitter``: ``wait`` absent is ``default_wait_s``, within
  ``0..max_wait_s`` it arrives as given, negative, not a number, NaN, infinite or past the
  maximum is 422 ``invalid_parameter`` naming ``wait``; a draining service is 503
  ``draining`` with ``Retry-After`` before ``wait`` is looked at; an ``Idempotency-Key`` of
  up to 256 characters arrives as sent, a longer one is 422; :class:`Submitting`'s
  properties are the service's and :meth:`Submitting.submit` hands every value to
  :func:`quilting.service.submit.submit` in its place.
- ``parts_once`` (``SingleParts``, ``ExampleParts``, ``LayerParts``): which parts may repeat
  on which routes, as the HTTP docs list them; a repeated single part is 422
  ``duplicate_part`` naming it.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi import Depends, FastAPI, Request
from fastapi.params import Depends as DependsParam
from fastapi.testclient import TestClient
from starlette.responses import Response

from quilting.options import SynthesisOptions
from quilting.service import deps
from quilting.service.context import Service
from quilting.service.forms import Submission
from quilting.service.handlers import PROBLEM_JSON, add_exception_handlers
from quilting.service.jobs import Job, new_job_id
from quilting.service.settings import Settings

KEYS = ("k1-secret", "k2-secret")
K1, K2 = KEYS


def make_app(settings: Settings) -> tuple[FastAPI, Service]:
    """An app with the service's handlers and one route per dependency under test."""
    app = FastAPI()
    add_exception_handlers(app)
    service = Service.build(settings)
    app.state.service = service
    app.state.draining = False

    @app.get("/owner")
    def who(key: deps.Owner) -> dict[str, Any]:
        return {"key": key}

    @app.get("/metrics", dependencies=[Depends(deps.metrics_reader)])
    def metrics() -> dict[str, Any]:
        return {"ok": True}

    @app.get("/jobs/{job_id}")
    def job(found: deps.JobOf) -> dict[str, Any]:
        return {"id": found.id, "owner": found.owner}

    @app.post("/submit")
    def submit(submitting: deps.Submitter, request: Request) -> dict[str, Any]:
        return {
            "key": submitting.key,
            "wait_s": submitting.wait_s,
            "idempotency_key": submitting.idempotency_key,
            "own_service": submitting.service is request.app.state.service,
            "own_settings": submitting.settings is service.settings,
            "own_models": submitting.models is service.models,
        }

    for path, dependencies in (
        ("/single", deps.SingleParts),
        ("/examples", deps.ExampleParts),
        ("/layers", deps.LayerParts),
    ):

        async def parts(request: Request) -> dict[str, Any]:
            return {"names": [name for name, _ in (await request.form()).multi_items()]}

        app.post(path, dependencies=dependencies)(parts)
    return app, service


@pytest.fixture(scope="module")
def open_app() -> Iterator[tuple[TestClient, Service]]:
    app, service = make_app(Settings())
    with TestClient(app) as client:
        yield client, service


@pytest.fixture(scope="module")
def keyed_app() -> Iterator[tuple[TestClient, Service]]:
    app, service = make_app(Settings(api_keys=KEYS))
    with TestClient(app) as client:
        yield client, service


def assert_problem(response: Any, status: int, code: str, field: str | None = None) -> Any:
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == PROBLEM_JSON
    body = response.json()
    assert (body["status"], body["code"]) == (status, code)
    assert body.get("field") == field
    assert "Traceback" not in response.text
    return body


def add_job(service: Service, owner: str | None) -> str:
    job = Job(id=new_job_id(), owner=owner, width=8, height=8, companion_names=[], input=None)
    asyncio.run(service.jobs.submit(job, None))  # queued only: the queue is never started
    job_id: str = job.id
    return job_id


# --- the API key ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "headers",
    [{}, {"X-API-Key": "anything"}, {"Authorization": "Bearer anything"}],
    ids=["none", "x-api-key", "bearer"],
)
def test_without_keys_there_is_no_owner(
    open_app: tuple[TestClient, Service], headers: dict[str, str]
) -> None:
    client, _ = open_app
    response = client.get("/owner", headers=headers)
    assert response.status_code == 200 and response.json() == {"key": None}


@pytest.mark.parametrize(
    ("headers", "key"),
    [
        ({"X-API-Key": K1}, K1),
        ({"Authorization": f"Bearer {K2}"}, K2),
        ({"Authorization": f"bearer {K2}"}, K2),
        ({"Authorization": f"BEARER   {K1}  "}, K1),
        ({"Authorization": f"Bearer {K2}", "X-API-Key": "wrong"}, K2),
        ({"Authorization": f"Basic {K2}", "X-API-Key": K1}, K1),
    ],
    ids=["x-api-key", "bearer", "lower-case", "blanks", "bearer-decides", "other-scheme"],
)
def test_a_valid_key_is_the_owner(
    keyed_app: tuple[TestClient, Service], headers: dict[str, str], key: str
) -> None:
    client, _ = keyed_app
    response = client.get("/owner", headers=headers)
    assert response.status_code == 200 and response.json() == {"key": key}


@pytest.mark.parametrize(
    "headers",
    [
        {},
        {"X-API-Key": ""},
        {"X-API-Key": "k3-secret"},
        {"X-API-Key": K1[:-1]},
        {"X-API-Key": K1 + "x"},
        {"X-API-Key": K1.upper()},
        {"Authorization": "Bearer "},
        {"Authorization": K1},
        {"Authorization": f"Bearer {K1},{K2}"},
        {"Authorization": "Bearer wrong-key", "X-API-Key": K1},
    ],
    ids=[
        "none",
        "empty",
        "unknown",
        "truncated",
        "extended",
        "other-case",
        "empty-bearer",
        "no-scheme",
        "two-keys",
        "wrong-bearer-right-x-api-key",
    ],
)
def test_a_missing_or_wrong_key_is_401(
    keyed_app: tuple[TestClient, Service], headers: dict[str, str]
) -> None:
    client, _ = keyed_app
    for response in (
        client.get("/owner", headers=headers),
        client.post("/submit", headers=headers),
    ):
        body = assert_problem(response, 401, "unauthorized")
        assert response.headers["WWW-Authenticate"] == "Bearer"
        sent = " ".join(headers.values())
        for secret in (*KEYS, "k3-secret", "wrong-key"):
            if secret in sent:
                assert secret not in response.text, "the detail echoes a key"
        assert "Bearer" in body["detail"] and "X-API-Key" in body["detail"]


@pytest.mark.parametrize(
    ("settings", "headers", "status"),
    [
        (Settings(), {}, 200),
        (Settings(api_keys=KEYS), {}, 401),
        (Settings(api_keys=KEYS), {"X-API-Key": "nope"}, 401),
        (Settings(api_keys=KEYS), {"X-API-Key": K2}, 200),
        (Settings(api_keys=KEYS, metrics_public=True), {}, 200),
        (Settings(api_keys=KEYS, metrics_public=True), {"X-API-Key": "nope"}, 200),
    ],
    ids=["no-keys", "keys", "wrong-key", "key", "public", "public-wrong-key"],
)
def test_metrics_need_a_key_only_with_keys_and_not_public(
    settings: Settings, headers: dict[str, str], status: int
) -> None:
    app, _ = make_app(settings)
    with TestClient(app) as client:
        response = client.get("/metrics", headers=headers)
    if status == 200:
        assert response.status_code == 200 and response.json() == {"ok": True}
    else:
        assert_problem(response, 401, "unauthorized")


# --- the job a path names ------------------------------------------------------------------


def test_a_job_is_its_owner_s_whichever_header_carries_the_key(
    keyed_app: tuple[TestClient, Service],
) -> None:
    client, service = keyed_app
    job_id = add_job(service, K1)
    for headers in ({"X-API-Key": K1}, {"Authorization": f"Bearer {K1}"}):
        response = client.get(f"/jobs/{job_id}", headers=headers)
        assert response.status_code == 200 and response.json() == {"id": job_id, "owner": K1}


def test_another_key_s_job_is_404_exactly_as_an_unknown_one(
    keyed_app: tuple[TestClient, Service],
) -> None:
    client, service = keyed_app
    job_id = add_job(service, K1)
    other = assert_problem(
        client.get(f"/jobs/{job_id}", headers={"X-API-Key": K2}), 404, "job_not_found"
    )
    unknown_id = new_job_id()
    unknown = assert_problem(
        client.get(f"/jobs/{unknown_id}", headers={"X-API-Key": K2}), 404, "job_not_found"
    )
    assert other["job_id"] == job_id
    # Nothing tells the other key that the job exists.
    assert {**other, "detail": "", "job_id": ""} == {**unknown, "detail": "", "job_id": ""}
    assert other["detail"].replace(job_id, "ID") == unknown["detail"].replace(unknown_id, "ID")


def test_a_job_without_a_key_is_401_not_404(keyed_app: tuple[TestClient, Service]) -> None:
    client, service = keyed_app
    job_id = add_job(service, K1)
    assert_problem(client.get(f"/jobs/{job_id}"), 401, "unauthorized")
    assert_problem(client.get(f"/jobs/{new_job_id()}"), 401, "unauthorized")


def test_without_keys_every_job_is_visible(open_app: tuple[TestClient, Service]) -> None:
    client, service = open_app
    job_id = add_job(service, None)
    response = client.get(f"/jobs/{job_id}", headers={"X-API-Key": "ignored"})
    assert response.status_code == 200 and response.json() == {"id": job_id, "owner": None}
    assert_problem(client.get("/jobs/not-a-job"), 404, "job_not_found")


# --- wait, draining and the Idempotency-Key -------------------------------------------------


@pytest.mark.parametrize(
    ("query", "wait_s"),
    [("", 3.0), ("?wait=0", 0.0), ("?wait=2.5", 2.5), ("?wait=7", 7.0), ("?wait=7.0", 7.0)],
)
def test_wait_arrives_as_given_or_the_default(query: str, wait_s: float) -> None:
    app, _ = make_app(Settings(default_wait_s=3, max_wait_s=7))
    with TestClient(app) as client:
        response = client.post("/submit" + query)
    assert response.status_code == 200
    assert response.json()["wait_s"] == wait_s


@pytest.mark.parametrize("wait", ["-1", "-0.001", "soon", "", "nan", "inf", "-inf", "7.001", "1e9"])
def test_a_wait_out_of_range_or_not_a_number_is_422_naming_wait(wait: str) -> None:
    app, _ = make_app(Settings(default_wait_s=3, max_wait_s=7))
    with TestClient(app) as client:
        response = client.post("/submit", params={"wait": wait})
    body = assert_problem(response, 422, "invalid_parameter", field="wait")
    assert "Traceback" not in body["detail"]


def test_a_wait_over_the_maximum_names_the_range() -> None:
    app, _ = make_app(Settings(default_wait_s=3, max_wait_s=7))
    with TestClient(app) as client:
        body = assert_problem(client.post("/submit?wait=8"), 422, "invalid_parameter", field="wait")
    assert "0..7" in body["detail"]


def test_a_draining_service_takes_nothing_whatever_the_wait() -> None:
    app, _ = make_app(Settings(default_wait_s=3, max_wait_s=7))
    app.state.draining = True
    with TestClient(app) as client:
        for query in ("", "?wait=0", "?wait=100"):
            response = client.post("/submit" + query)
            assert_problem(response, 503, "draining")
            assert response.headers["Retry-After"] == "10"
        # Only submissions: the other dependencies still answer.
        assert client.get("/owner").status_code == 200


@pytest.mark.parametrize("key", ["k", "x" * 256, "a-b_c.d:e/f=g", "with space"])
def test_an_idempotency_key_arrives_as_sent(open_app: tuple[TestClient, Service], key: str) -> None:
    client, _ = open_app
    response = client.post("/submit", headers={"Idempotency-Key": key})
    assert response.status_code == 200
    assert response.json()["idempotency_key"] == key
    assert client.post("/submit").json()["idempotency_key"] is None


def test_an_idempotency_key_over_256_characters_is_422(
    open_app: tuple[TestClient, Service],
) -> None:
    client, _ = open_app
    response = client.post("/submit", headers={"Idempotency-Key": "x" * 257})
    assert response.status_code == 422
    body = response.json()
    assert body["code"] == "invalid_parameter"
    assert body["field"] == "idempotency-key"  # the header, as a query parameter is named
    assert "256" in body["detail"]


def test_submitting_carries_the_service_its_key_and_values(
    keyed_app: tuple[TestClient, Service],
) -> None:
    client, _ = keyed_app
    headers = {"Authorization": f"Bearer {K2}", "Idempotency-Key": "once"}
    response = client.post("/submit?wait=1.5", headers=headers)
    assert response.status_code == 200
    assert response.json() == {
        "key": K2,
        "wait_s": 1.5,
        "idempotency_key": "once",
        "own_service": True,
        "own_settings": True,
        "own_models": True,
    }


def test_submit_hands_every_value_to_the_submission_in_its_place(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    service = Service.build(Settings())
    calls: list[tuple[Any, ...]] = []
    answer = Response(b"done")

    async def fake_submit(*args: Any) -> Response:
        calls.append(args)
        return answer

    monkeypatch.setattr(deps, "submit", fake_submit)
    submission = Submission("synthesize", SynthesisOptions(), b"png", {}, size=(8, 8))
    submitting = deps.Submitting(service, "the-key", 4.5, "the-idempotency-key")
    assert asyncio.run(submitting.submit(submission)) is answer
    assert calls == [(submission, service, "the-key", "the-idempotency-key", 4.5)]


# --- parts sent once -----------------------------------------------------------------------

#: Which parts may repeat on a route of each kind (docs/http-service.md): ``companion`` and
#: ``layer`` everywhere; ``texture``, ``source_mask``, ``trimap``, ``scribbles`` on the routes
#: of several examples; ``trimap`` and ``scribbles`` on /matte.
REPEATING = {
    "/single": {"companion", "layer"},
    "/examples": {"companion", "layer", "texture", "source_mask", "trimap", "scribbles"},
    "/layers": {"companion", "layer", "trimap", "scribbles"},
}
PARTS = (
    "companion",
    "layer",
    "texture",
    "source_mask",
    "trimap",
    "scribbles",
    "target",
    "options",
    "companion_kinds",
    "image",
    "mask",
)


@pytest.mark.parametrize("path", REPEATING)
@pytest.mark.parametrize("part", PARTS)
def test_only_the_documented_parts_repeat(
    open_app: tuple[TestClient, Service], path: str, part: str
) -> None:
    client, _ = open_app
    files = [
        ("options", (None, "{}")),
        (part, ("a.png", b"one")),
        ("other", (None, "x")),
        (part, ("b.png", b"two")),
    ]
    if part == "options":
        files = files[1:]
    response = client.post(path, files=files)
    if part in REPEATING[path]:
        assert response.status_code == 200, response.text
        assert response.json()["names"].count(part) == 2
    else:
        body = assert_problem(response, 422, "duplicate_part", field=part)
        assert repr(part) in body["detail"]
        for allowed in REPEATING[path]:
            assert allowed in body["detail"]


def test_every_part_once_passes_every_route(open_app: tuple[TestClient, Service]) -> None:
    client, _ = open_app
    files = [(part, (None, "x")) for part in PARTS]
    for path in REPEATING:
        response = client.post(path, files=files)
        assert response.status_code == 200 and response.json()["names"] == list(PARTS)


def test_the_route_dependencies_are_single_dependencies() -> None:
    for dependencies in (deps.SingleParts, deps.ExampleParts, deps.LayerParts):
        assert len(dependencies) == 1 and isinstance(dependencies[0], DependsParam)
