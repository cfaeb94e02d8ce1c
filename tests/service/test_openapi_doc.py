"""Unit tests of :mod:`quilting.service.openapi` (the OpenAPI document's problem answers and
published components) and :mod:`quilting.service.apidocs` (the offline API docs pages and
their bundles), in process.

The app is :func:`quilting.service.app.create_app` driven by Starlette's ``TestClient``
without its lifespan: no worker, no sandbox, no network.

Covers
------
- :func:`~quilting.service.openapi.problems`: every 4xx/5xx answer an operation declares is
  ``application/problem+json`` whose schema is the published ``Problem`` component (FastAPI's
  own 422 of an operation that declares no problems aside), and the
  component is :data:`~quilting.service.openapi.PROBLEM_SCHEMA`; every ``$ref`` of the
  document resolves; operation ids are unique; the options models are published.
- The problems the job routes answer (found by driving them) are each declared for their
  operation, and each answer carries the ``Problem`` schema's required members.
- The document is built once: the same bytes on every request, the same object from
  ``app.openapi()``, and the same bytes from two apps built with the same settings.
- :mod:`~quilting.service.apidocs`: every bundle of ``ASSETS`` is served with its documented
  media type, ``no-cache`` and an ETag of its bytes; a list of ETags in ``If-None-Match``
  holding its own is a 304 without a body; the pages name no other host (no ``http://`` or
  ``https://`` at all) and, behind a proxy's ``root_path``, name their files under it.
"""

from __future__ import annotations

import hashlib
import re
from collections import Counter
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from quilting.service import apidocs
from quilting.service.app import create_app
from quilting.service.handlers import PROBLEM_JSON
from quilting.service.jobs import Job, Status, new_job_id
from quilting.service.openapi import PROBLEM_SCHEMA, problems
from quilting.service.settings import Settings

PROBLEM_REF = "#/components/schemas/Problem"
METHODS = ("get", "put", "post", "delete", "patch", "head", "options")
KEY = "doc-key"


@pytest.fixture(scope="module")
def app() -> FastAPI:
    return create_app(Settings(api_keys=(KEY,)))


@pytest.fixture(scope="module")
def client(app: FastAPI) -> Iterator[TestClient]:
    # No `with`: the lifespan (workers, sandbox) never starts.
    with_client = TestClient(app, raise_server_exceptions=False)
    yield with_client
    with_client.close()


@pytest.fixture(scope="module")
def document(client: TestClient) -> dict[str, Any]:
    response = client.get("/openapi.json")
    assert response.status_code == 200
    found: dict[str, Any] = response.json()
    return found


def operations(document: dict[str, Any]) -> Iterator[tuple[str, str, dict[str, Any]]]:
    """``(method, path, operation)`` of every operation of the document."""
    for path, item in document["paths"].items():
        for method in METHODS:
            if method in item:
                yield method, path, item[method]


def operation_of(document: dict[str, Any], operation_id: str) -> dict[str, Any]:
    for _, _, operation in operations(document):
        if operation["operationId"] == operation_id:
            return operation
    raise AssertionError(f"no operation {operation_id}")


def refs(node: Any) -> Iterator[str]:
    if isinstance(node, dict):
        for key, value in node.items():
            if key == "$ref" and isinstance(value, str):
                yield value
            else:
                yield from refs(value)
    elif isinstance(node, list):
        for value in node:
            yield from refs(value)


# --- the document -------------------------------------------------------------------------------


def test_problems_declares_problem_json_for_each_status() -> None:
    declared = problems(404, 409)
    assert set(declared) == {404, 409}
    for entry in declared.values():
        assert entry["content"] == {PROBLEM_JSON: {"schema": {"$ref": PROBLEM_REF}}}


def test_every_declared_error_answer_is_a_problem(document: dict[str, Any]) -> None:
    checked = 0
    for method, path, operation in operations(document):
        for status, answer in operation["responses"].items():
            if int(status) < 400:
                continue
            # No FastAPI HTTPValidationError left: every 422 the app sends is a problem.
            assert set(answer["content"]) == {PROBLEM_JSON}, (method, path, status)
            assert answer["content"][PROBLEM_JSON]["schema"] == {"$ref": PROBLEM_REF}
            checked += 1
    assert checked > 50
    assert "HTTPValidationError" not in document["components"]["schemas"]


def test_cancelling_declares_what_it_answers(document: dict[str, Any]) -> None:
    # DELETE /jobs/{id} answers 401, 404 and 409 problems (test_job_routes.py): declared.
    answers = document["paths"]["/jobs/{job_id}"]["delete"]["responses"]
    assert {"202", "401", "404", "409", "422"} <= set(answers)


def test_the_problem_component_is_the_problem_schema(document: dict[str, Any]) -> None:
    schemas = document["components"]["schemas"]
    assert schemas["Problem"] == PROBLEM_SCHEMA
    assert set(PROBLEM_SCHEMA["required"]) == {"type", "title", "status", "detail", "code"}
    for name in (
        "SynthesizeOptions",
        "TransferOptions",
        "TileOptions",
        "MatteOptions",
        "FillOptions",
        "ExtendOptions",
        "WangOptions",
        "AlphaOptions",
    ):
        assert schemas[name]["type"] == "object", name


def test_every_reference_resolves(document: dict[str, Any]) -> None:
    found = set(refs(document))
    assert PROBLEM_REF in found
    for ref in found:
        assert ref.startswith("#/"), ref
        node: Any = document
        for part in ref[2:].split("/"):
            assert part in node, ref
            node = node[part]


def test_operation_ids_are_unique(document: dict[str, Any]) -> None:
    ids = Counter(operation["operationId"] for _, _, operation in operations(document))
    assert len(ids) > 15
    assert [name for name, count in ids.items() if count > 1] == []


def test_the_document_is_the_same_bytes_every_time(app: FastAPI, client: TestClient) -> None:
    first = client.get("/openapi.json")
    second = client.get("/openapi.json")
    assert first.content == second.content
    assert app.openapi() is app.openapi()
    # Another app with the same settings publishes the very same document.
    other = TestClient(create_app(Settings(api_keys=(KEY,))))
    assert other.get("/openapi.json").content == first.content
    other.close()


# --- the job routes' answers against the document ----------------------------------------------


def _job(app: FastAPI, status: Status, operation: str = "synthesize") -> Job:
    store = app.state.service.jobs.store
    job = Job(new_job_id(), KEY, 8, 8, ["normal"], None, operation=operation)
    store.add(job)
    if status is not Status.QUEUED:
        store.start(job)
    if status is Status.DONE:
        store.finish(job, Status.DONE, png=b"png", companions={"normal": b"n"}, layout=None)
    return job


def test_each_problem_a_job_route_answers_is_documented(
    app: FastAPI, client: TestClient, document: dict[str, Any]
) -> None:
    store = app.state.service.jobs.store
    expired = _job(app, Status.DONE)
    store.expire(now=expired.finished + store.settings.results_ttl_s + 1)  # type: ignore[operator]
    # Made after the expiry, which drops every result kept by then.
    queued, done = _job(app, Status.QUEUED), _job(app, Status.DONE)
    auth = {"X-API-Key": KEY}
    cases = [
        ("get_job", f"/jobs/{new_job_id()}", auth, 404),
        ("get_job", f"/jobs/{done.id}", {}, 401),
        ("get_result", f"/jobs/{queued.id}/result", auth, 409),
        ("get_result", f"/jobs/{expired.id}/result", auth, 410),
        ("get_result", f"/jobs/{new_job_id()}/result", auth, 404),
        ("get_companion", f"/jobs/{done.id}/result/nope", auth, 404),
        ("get_companion", f"/jobs/{queued.id}/result/normal", auth, 409),
        ("get_layout", f"/jobs/{done.id}/layout", auth, 404),
        ("get_layout", f"/jobs/{expired.id}/layout", auth, 410),
        ("get_manifest", f"/jobs/{done.id}/manifest", auth, 404),
        ("get_seams", f"/jobs/{done.id}/seams?color=nope", auth, 422),
        ("get_seams", f"/jobs/{queued.id}/seams", auth, 409),
        ("job_events", f"/jobs/{done.id}/events", {**auth, "Last-Event-ID": "x"}, 422),
    ]
    for operation_id, url, headers, status in cases:
        response = client.get(url, headers=headers)
        assert response.status_code == status, (url, response.text)
        assert response.headers["content-type"] == PROBLEM_JSON
        body = response.json()
        assert set(PROBLEM_SCHEMA["required"]) <= set(body), body
        assert set(body) <= set(PROBLEM_SCHEMA["properties"]), body
        declared = operation_of(document, operation_id)["responses"]
        assert str(status) in declared, (operation_id, status)
        assert declared[str(status)]["content"] == {PROBLEM_JSON: {"schema": {"$ref": PROBLEM_REF}}}


# --- the docs pages and their bundles -----------------------------------------------------------


@pytest.mark.parametrize("name", sorted(apidocs.ASSETS))
def test_each_bundle_has_its_media_type_and_an_etag_of_its_bytes(
    client: TestClient, name: str
) -> None:
    response = client.get(f"{apidocs.STATIC_PATH}/{name}")
    assert response.status_code == 200
    assert response.headers["content-type"] == apidocs.ASSETS[name]
    assert response.headers["cache-control"] == "no-cache"
    assert response.headers["x-content-type-options"] == "nosniff"
    assert response.content
    digest = hashlib.sha256(response.content).hexdigest()
    assert response.headers["etag"] == f'"{digest[:32]}"'


def test_a_list_of_etags_holding_the_bundles_is_a_304(client: TestClient) -> None:
    url = f"{apidocs.STATIC_PATH}/redoc.standalone.js"
    etag = client.get(url).headers["etag"]
    again = client.get(url, headers={"If-None-Match": f'"0000", {etag}, W/"1111"'})
    assert again.status_code == 304
    assert again.content == b""
    assert again.headers["etag"] == etag
    assert again.headers["cache-control"] == "no-cache"


@pytest.mark.parametrize("path", ["/docs", "/redoc"])
def test_the_pages_name_no_other_host(client: TestClient, path: str) -> None:
    response = client.get(path)
    assert response.status_code == 200
    assert response.headers["content-type"] == "text/html; charset=utf-8"
    assert response.headers["cache-control"] == "no-cache"
    assert re.search(r"https?://|//[a-z0-9.-]+\.[a-z]{2,}/", response.text, re.I) is None
    assert "fonts.googleapis" not in response.text


@pytest.mark.parametrize(
    ("path", "assets"),
    [
        ("/docs", ["swagger-ui-bundle.js", "swagger-ui.css", "favicon.png"]),
        ("/redoc", ["redoc.standalone.js", "favicon.png"]),
    ],
)
def test_behind_a_proxy_the_pages_name_their_files_under_its_prefix(
    app: FastAPI, path: str, assets: list[str]
) -> None:
    proxied = TestClient(app, root_path="/quilt")
    html = proxied.get(path).text
    proxied.close()
    assert "/quilt/openapi.json" in html
    for name in assets:
        assert f'"/quilt{apidocs.STATIC_PATH}/{name}"' in html, name
    assert f'"{apidocs.STATIC_PATH}/' not in html  # none without the prefix
