"""Unit tests of :mod:`quilting.service.problems`, called directly (no server).

Covers
------
- ``from_engine``: every engine error class maps to its documented HTTP status and stable
  ``code`` (``unreadable_image`` answered as ``invalid_image``; an unlisted code as a 422 that
  keeps its own code), and a parameter's name travels as the ``field`` member.
- ``Problem.body``: the RFC 9457 members (``type``, ``title``, ``status``, ``detail``) and the
  project's ``code``, a ``type`` URI ending in the code, a title per status, extra members
  kept; JSON-serialisable, answered as ``application/problem+json`` by the service's
  ``problem_response``, with no traceback or Python repr of the exception chain.
- A problem rebuilt from its parts (as a sandbox process sends it) has the same body.
- The helpers ``queue_full``, ``job_not_found`` and ``idempotency_conflict``.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from urllib.parse import urlparse

import pytest

from quilting import (
    BackendError,
    CancelledError,
    ImageDecodeError,
    ImageTooLargeError,
    InvalidImageError,
    InvalidParameterError,
    InvalidTrimapError,
    JobTooLargeError,
    LayoutError,
    MattingUnavailableError,
    QuiltingError,
)
from quilting.io import read_image
from quilting.service import problems
from quilting.service.handlers import PROBLEM_JSON, problem_response
from quilting.service.jobs.worker import JobTimeoutError
from quilting.service.problems import (
    ENGINE_STATUS,
    PROBLEM_TYPE,
    TITLES,
    Problem,
    from_engine,
    idempotency_conflict,
    job_not_found,
    queue_full,
)

#: Each engine error, the status and code docs/http-service.md and ENGINE_STATUS give it.
ENGINE_CASES: list[tuple[QuiltingError, int, str]] = [
    (InvalidParameterError("block", 2, "3..256"), 422, "invalid_parameter"),
    (InvalidImageError("texture has NaN values"), 422, "invalid_image"),
    (ImageDecodeError("<bytes>: it is not a PNG or JPEG file"), 422, "invalid_image"),
    (ImageTooLargeError("<bytes>: too many pixels (max_pixels)"), 422, "image_too_large"),
    (LayoutError("layout is 3x3 but the map is 4x4"), 422, "invalid_layout"),
    (BackendError("backend 'gl' cannot start"), 503, "backend_unavailable"),
    (MattingUnavailableError("install the matting extra"), 503, "matting_unavailable"),
    (InvalidTrimapError("trimap has no unknown pixel", parameter="trimap"), 422, "invalid_trimap"),
    (CancelledError("cancelled"), 409, "cancelled"),
    (JobTimeoutError("ran past 300 s"), 504, "job_timeout"),
    (JobTooLargeError("predicted 3 GiB, budget 2 GiB"), 422, "job_too_large"),
]

#: What must never appear in a body: a trace, an exception's repr, an object address.
LEAKS = ("Traceback", 'File "', "Error(", "<class", " object at 0x", "__")


def _all_subclasses(cls: type[QuiltingError]) -> list[type[QuiltingError]]:
    found: list[type[QuiltingError]] = []
    for sub in cls.__subclasses__():
        found += [sub, *_all_subclasses(sub)]
    return found


@pytest.mark.parametrize(
    ("error", "status", "code"), ENGINE_CASES, ids=[type(e).__name__ for e, _, _ in ENGINE_CASES]
)
def test_every_engine_error_maps_to_its_documented_status_and_code(
    error: QuiltingError, status: int, code: str
) -> None:
    problem = from_engine(error)
    assert (problem.status, problem.code) == (status, code)
    assert problem.detail == error.message
    assert problem.headers == {}
    body = problem.body()
    assert body["status"] == status and body["code"] == code
    assert body["type"] == PROBLEM_TYPE + code
    assert body["title"] == TITLES[status]


def test_every_engine_error_class_gets_a_titled_status_of_the_table_or_422() -> None:
    # Walks the class tree (after the imports above), so that a new error class is covered.
    classes = _all_subclasses(QuiltingError)
    assert {JobTimeoutError, MattingUnavailableError, InvalidTrimapError} <= set(classes)
    for cls in classes:
        error = QuiltingError.__new__(cls)
        QuiltingError.__init__(error, f"{cls.__name__} raised")
        problem = from_engine(error)
        assert problem.status == ENGINE_STATUS.get(cls.code, 422), cls
        assert problem.status in TITLES, cls
        assert problem.code == ("invalid_image" if cls.code == "unreadable_image" else cls.code)


def test_an_unlisted_engine_code_is_a_422_that_keeps_its_code() -> None:
    class NewEngineError(QuiltingError):
        code = "brand_new_failure"

    cases = [
        (NewEngineError("x went wrong"), "brand_new_failure"),
        (QuiltingError("b"), "quilting_error"),
    ]
    for error, code in cases:
        problem = from_engine(error)
        assert (problem.status, problem.code) == (422, code)
        assert problem.body()["type"] == PROBLEM_TYPE + code
        assert problem.body()["title"] == "Unprocessable content"


def test_a_parameter_error_names_its_field_and_an_image_error_only_when_it_has_one() -> None:
    body = from_engine(InvalidParameterError("overlap", -1, "0..block-1", "negative")).body()
    assert body["field"] == "overlap"
    assert "overlap=-1" in body["detail"] and "0..block-1" in body["detail"]
    assert from_engine(InvalidImageError("3 channels", parameter="silhouette")).extra == {
        "field": "silhouette"
    }
    assert "field" not in from_engine(InvalidImageError("3 channels")).body()
    assert "field" not in from_engine(BackendError("no GL")).body()


def test_the_body_has_the_rfc_9457_members_and_the_projects_code() -> None:
    problem = Problem(413, "file_too_large", "texture is 9 MB; the limit is 8 MB", field="texture")
    body = problem.body()
    assert list(body)[:5] == ["type", "title", "status", "detail", "code"]
    assert body == {
        "type": "https://quilting.dev/problems/file_too_large",
        "title": "Payload too large",
        "status": 413,
        "detail": "texture is 9 MB; the limit is 8 MB",
        "code": "file_too_large",
        "field": "texture",
    }
    uri = urlparse(body["type"])
    assert (uri.scheme, uri.netloc) == ("https", "quilting.dev")  # an absolute URI
    assert isinstance(body["status"], int) and not isinstance(body["status"], bool)
    assert json.loads(json.dumps(body)) == body
    assert str(problem) == problem.detail  # raised, it reads as its detail


def test_every_titled_status_has_its_own_title_and_others_a_generic_one() -> None:
    for status, title in TITLES.items():
        assert Problem(status, "c", "d").body()["title"] == title
    assert len(set(TITLES.values())) == len(TITLES)
    assert Problem(418, "teapot", "d").body()["title"] == "Error"


def test_a_response_is_problem_json_with_the_body_and_headers() -> None:
    problem = queue_full(12)
    response = problem_response(problem)
    assert response.status_code == 503
    assert response.media_type == PROBLEM_JSON == "application/problem+json"
    assert response.headers["content-type"] == "application/problem+json"
    assert response.headers["retry-after"] == "5"
    assert json.loads(bytes(response.body)) == problem.body()


def test_an_engine_error_from_a_failed_decode_leaks_no_trace_or_repr() -> None:
    with pytest.raises(ImageDecodeError) as caught:
        read_image(b"\x89PNG\r\n\x1a\n" + bytes(40))
    errors: list[QuiltingError] = [caught.value]
    try:
        try:
            internals: dict[str, int] = {}
            internals["missing"]  # an internal failure, chained under the engine's error
        except KeyError as internal:
            raise BackendError("the cost backend failed") from internal
    except BackendError as chained:
        errors.append(chained)
    for error in errors:
        text = bytes(problem_response(from_engine(error)).body).decode()
        body = json.loads(text)
        assert set(body) <= {"type", "title", "status", "detail", "code", "field"}
        assert all(isinstance(v, str | int) for v in body.values())
        for leak in LEAKS:
            assert leak not in text, (leak, text)
        assert "KeyError" not in text and "missing" not in text


def test_a_problem_rebuilt_from_its_parts_has_the_same_body() -> None:
    # A sandbox process sends (status, code, detail, headers, extra); the service re-raises.
    for problem in (
        queue_full(3),
        job_not_found("j-1"),
        from_engine(InvalidParameterError("block", 1, "3..256")),
    ):
        again = Problem(
            problem.status, problem.code, problem.detail, headers=problem.headers, **problem.extra
        )
        assert again.body() == problem.body()
        assert again.headers == problem.headers


def test_the_helpers_answer_their_documented_status_code_and_members() -> None:
    full = queue_full(7)
    assert (full.status, full.code, full.headers) == (503, "queue_full", {"Retry-After": "5"})
    assert "7 jobs" in full.detail

    missing = job_not_found("abc123")
    assert (missing.status, missing.code) == (404, "job_not_found")
    assert missing.body()["job_id"] == "abc123" and "'abc123'" in missing.detail
    assert missing.headers == {}

    conflict = idempotency_conflict()
    assert (conflict.status, conflict.code, conflict.extra) == (409, "idempotency_conflict", {})
    assert "Idempotency-Key" in conflict.detail


def test_a_problems_headers_are_its_own() -> None:
    # No shared mutable default: headers added to one problem do not reach another.
    first, second = Problem(400, "a", "x"), Problem(400, "b", "y")
    first.headers["X-Test"] = "1"
    assert second.headers == {} and "X-Test" not in job_not_found("z").headers


def test_every_status_the_service_answers_has_a_title() -> None:
    # The statuses written in the service's sources (problems raised, and Starlette's 404 and
    # 405 that the handlers answer as problems): none falls back to the generic title.
    service = Path(problems.__file__).parent
    written = {
        int(status)
        for path in service.rglob("*.py")
        for status in re.findall(r"Problem\(\s*(\d{3})", path.read_text())
    }
    assert {404, 409, 422, 503} <= written  # the scan reads the sources
    for status in written | {404, 405}:
        assert status in TITLES, status
    assert Problem(405, "method_not_allowed", "d").body()["title"] == "Method not allowed"


@pytest.mark.parametrize("member", ["type", "title"])
def test_an_extra_member_may_not_replace_a_standard_one(member: str) -> None:
    # (status, code and detail are the constructor's own parameters: Python refuses those.)
    with pytest.raises(ValueError, match=member):
        Problem(422, "c", "d", **{member: "x"})
    assert Problem(422, "c", "d", field="block").body()["field"] == "block"
