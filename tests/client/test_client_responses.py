"""The service's answers read without I/O (``quilting_client._responses``).

Covers
------
- ``Retry-After`` (delta-seconds, HTTP dates, garbage) read as seconds;
- error responses: :func:`problem_of` (problem+json kept whole, plain text, HTML, empty and
  non-object bodies turned into a short synthetic problem) and :func:`raise_for_problem`
  (statuses below 400 pass, the rest raise the typed error, no decoding error leaking);
- transport failures: :func:`connection_error`, :func:`transport_errors`, :func:`timed_out`;
- successful bodies: JSON objects, job statuses (missing and extra members), PNGs,
  submissions answered with a status or with the result, job ids from ``X-Job-Id`` or
  ``Location``, the ``Quilting-Extracted`` header.
"""

from __future__ import annotations

import json
from datetime import UTC, datetime
from email.utils import format_datetime
from typing import Any

import httpx
import pytest
from client_fakes import BASE, RESULT, job_json

from quilting_client import _responses as responses
from quilting_client._responses import Finished
from quilting_client.errors import (
    ConnectionFailedError,
    NotFoundError,
    QuiltingClientError,
    ServerError,
    ServiceUnavailableError,
    ValidationError,
)
from quilting_client.models import JobStatus

NOW = 1_750_000_000.0


def answer(
    status: int = 200,
    *,
    body: Any = None,
    content: bytes | None = None,
    headers: dict[str, str] | None = None,
    method: str = "GET",
    path: str = "/jobs/j1",
) -> httpx.Response:
    """A response with its request, as a driver hands it over (body read)."""
    request = httpx.Request(method, f"{BASE}{path}")
    if body is not None:
        return httpx.Response(status, json=body, headers=headers, request=request)
    return httpx.Response(status, content=content or b"", headers=headers, request=request)


# -- Retry-After --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "seconds"),
    [
        ("5", 5.0),
        ("0", 0.0),
        ("2.5", 2.5),
        (" 7 ", 7.0),
        ("-3", 0.0),
        ("soon", None),
        ("", None),
        ("inf", None),  # no sleep that overflows or never ends
        ("Infinity", None),
        ("nan", None),
    ],
)
def test_retry_after_in_seconds(value: str, seconds: float | None) -> None:
    assert responses.retry_after(answer(headers={"Retry-After": value})) == seconds


def test_no_retry_after_is_none() -> None:
    assert responses.retry_after(answer()) is None


@pytest.mark.parametrize(("offset", "seconds"), [(120, 120.0), (0, 0.0), (-3600, 0.0)])
def test_retry_after_as_an_http_date_counts_from_now(
    monkeypatch: pytest.MonkeyPatch, offset: int, seconds: float
) -> None:
    monkeypatch.setattr(responses, "time", lambda: NOW)
    date = format_datetime(datetime.fromtimestamp(NOW + offset, UTC), usegmt=True)
    assert responses.retry_after(answer(headers={"Retry-After": date})) == pytest.approx(seconds)


# -- error responses ----------------------------------------------------------------------------


def test_a_problem_document_is_kept_whole() -> None:
    body = {
        "type": "https://quilting.dev/problems/job_too_large",
        "title": "Unprocessable content",
        "status": 422,
        "detail": "the job may need up to 3.6 GiB",
        "code": "job_too_large",
        "budget_bytes": 2231369728,
        "budget_seconds": 300.0,
    }
    assert responses.problem_of(answer(422, body=body)) == body


@pytest.mark.parametrize(
    ("content", "content_type", "detail"),
    [
        (b"upstream worker died\n", "text/plain", "Bad Gateway: upstream worker died"),
        (b"  two\r\n  lines  ", "text/plain", "Bad Gateway: two lines"),
        (b"<html><body>502 Bad Gateway</body></html>", "text/html", "Bad Gateway"),
        (b"  \n<!doctype html><p>x</p>", "text/html", "Bad Gateway"),
        (b"", "text/plain", "Bad Gateway"),
        (b"{}", "application/json", "Bad Gateway: {}"),
        (b"[1, 2]", "application/json", "Bad Gateway: [1, 2]"),
        (b"null", "application/json", "Bad Gateway: null"),
        (b'{"truncated": ', "application/problem+json", 'Bad Gateway: {"truncated":'),
        (b"\xff\xfe\x00binary", "application/octet-stream", "Bad Gateway: "),
    ],
)
def test_a_body_that_is_not_a_problem_gives_a_short_synthetic_one(
    content: bytes, content_type: str, detail: str
) -> None:
    problem = responses.problem_of(
        answer(502, content=content, headers={"Content-Type": content_type})
    )
    assert problem["status"] == 502 and problem["title"] == "Bad Gateway"
    assert problem["detail"].startswith(detail)
    assert "\n" not in problem["detail"] and "<" not in problem["detail"]


def test_a_long_error_text_is_cut_to_a_single_short_line() -> None:
    text = ("word " * 30 + "\n") * 20
    problem = responses.problem_of(answer(500, content=text.encode()))
    excerpt = problem["detail"].removeprefix("Internal Server Error: ")
    assert len(excerpt) == 200 and "\n" not in excerpt and "  " not in excerpt


def test_an_unknown_status_without_reason_still_has_a_title() -> None:
    problem = responses.problem_of(answer(599, content=b"odd"))
    assert problem == {"title": "error", "status": 599, "detail": "error: odd"}


@pytest.mark.parametrize("status", [200, 201, 202, 204, 301, 304, 399])
def test_raise_for_problem_lets_a_non_error_pass(status: int) -> None:
    response = answer(status, content=b"not json")
    assert responses.raise_for_problem(response) is None  # type: ignore[func-returns-value]


@pytest.mark.parametrize(
    ("status", "content", "cls", "code"),
    [
        (400, b"bad", QuiltingClientError, "http_400"),
        (404, b"<h1>Not Found</h1>", NotFoundError, "http_404"),
        (422, b"nope", ValidationError, "http_422"),
        (500, b"Traceback (most recent call last):", ServerError, "http_500"),
        (502, b"{", ServerError, "http_502"),
        (503, b"", ServiceUnavailableError, "http_503"),
    ],
)
def test_a_non_json_error_body_raises_a_typed_error_without_decoding_errors(
    status: int, content: bytes, cls: type[QuiltingClientError], code: str
) -> None:
    with pytest.raises(QuiltingClientError) as caught:
        responses.raise_for_problem(answer(status, content=content))
    error = caught.value
    assert type(error) is cls and (error.status, error.code) == (status, code)
    # The failed JSON decoding is neither raised nor chained onto the error.
    assert error.__cause__ is None and error.__context__ is None
    assert f"HTTP {status}" in str(error) and error.detail


def test_raise_for_problem_passes_the_retry_after_header_on() -> None:
    body = {"status": 503, "code": "draining", "detail": "shutting down", "retry_after": 99}
    response = answer(503, body=body, headers={"Retry-After": "12"})
    with pytest.raises(ServiceUnavailableError) as caught:
        responses.raise_for_problem(response)
    # The header is the service's word on when to come back; the member is the fallback.
    assert caught.value.retry_after == 12.0 and caught.value.code == "draining"


def test_the_response_status_wins_over_the_problem_s() -> None:
    body = {"status": 200, "code": "job_not_found", "detail": "no job 'j9'"}
    with pytest.raises(NotFoundError) as caught:
        responses.raise_for_problem(answer(404, body=body))
    assert caught.value.status == 404 and caught.value.problem == body


# -- transport failures -------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("exc", "reason"),
    [
        (httpx.ConnectError("connection refused"), "connection refused"),
        (httpx.ReadTimeout("timed out"), "timed out"),
        (httpx.RemoteProtocolError(""), "RemoteProtocolError"),
    ],
)
def test_transport_errors_become_connection_failed_errors(
    exc: httpx.TransportError, reason: str
) -> None:
    request = httpx.Request("POST", f"{BASE}/synthesize?wait=10")
    with pytest.raises(ConnectionFailedError) as caught, responses.transport_errors(request):
        raise exc
    error = caught.value
    assert error.__cause__ is exc and error.status is None and error.code == "connection_failed"
    assert str(error).startswith(f"POST {BASE}/synthesize?wait=10: {reason}")
    assert responses.timed_out(error) is isinstance(exc, httpx.TimeoutException)


def test_transport_errors_leave_other_exceptions_alone() -> None:
    request = httpx.Request("GET", f"{BASE}/healthz")
    boom = KeyError("not a transport error")
    with pytest.raises(KeyError) as caught, responses.transport_errors(request):
        raise boom
    assert caught.value is boom


@pytest.mark.parametrize(
    ("error", "expected"),
    [
        (ConnectionFailedError("x", code="connection_failed"), False),  # No cause: not known.
        (QuiltingClientError("x", status=504, code="job_timeout"), False),
    ],
)
def test_timed_out_only_for_a_connection_that_timed_out(
    error: QuiltingClientError, expected: bool
) -> None:
    assert responses.timed_out(error) is expected
    timeout = responses.connection_error(
        httpx.ConnectTimeout("slow"), httpx.Request("GET", f"{BASE}/")
    )
    timeout.__cause__ = httpx.ConnectTimeout("slow")
    assert responses.timed_out(timeout)


# -- successful bodies --------------------------------------------------------------------------


def test_parse_json_object_returns_the_object() -> None:
    body = {"status": "ok", "nested": {"a": [1, 2]}}
    assert responses.parse_json_object(answer(body=body)) == body


@pytest.mark.parametrize(
    ("content", "why"),
    [(b"<html>", "the body is not JSON"), (b"[1, 2]", "not a JSON object"), (b'"ok"', "object")],
)
def test_parse_json_object_refuses_other_bodies_with_invalid_response(
    content: bytes, why: str
) -> None:
    with pytest.raises(QuiltingClientError) as caught:
        responses.parse_json_object(answer(content=content, path="/readyz"))
    error = caught.value
    assert type(error) is QuiltingClientError and error.code == "invalid_response"
    assert error.status == 200 and "GET /readyz" in str(error) and why in str(error)
    # No JSONDecodeError shown in the traceback.
    assert error.__cause__ is None and (error.__context__ is None or error.__suppress_context__)


def test_parse_job_keeps_extra_members_and_defaults_missing_ones() -> None:
    job = responses.parse_job(answer(body={"id": "j1", "status": "running", "gpu": "h100"}))
    assert (job.id, job.status, job.progress, job.stage, job.error) == (
        "j1",
        "running",
        0,
        "",
        None,
    )
    assert job.raw["gpu"] == "h100" and not job.is_terminal
    full = responses.parse_job(answer(body=job_json("done", progress=1, timings={"total": 2})))
    assert full == JobStatus.from_json(job_json("done", progress=1, timings={"total": 2}))
    assert full.progress == 1.0 and full.timings == {"total": 2.0}


@pytest.mark.parametrize(
    "body",
    [{"status": "done"}, {"id": "j1"}, {"id": 7, "status": "done"}, {"id": "j1", "status": None}],
)
def test_parse_job_refuses_a_status_without_id_or_state(body: dict[str, Any]) -> None:
    with pytest.raises(QuiltingClientError) as caught:
        responses.parse_job(answer(body=body))
    assert caught.value.code == "invalid_response" and "/jobs/j1" in str(caught.value)
    assert "'id'" in str(caught.value) and not isinstance(caught.value, KeyError)


def test_parse_png_returns_a_png_and_refuses_anything_else() -> None:
    assert responses.parse_png(answer(content=RESULT)) == RESULT
    for content in (b"", b"GIF89a", b'{"status": "done"}', RESULT[:7]):
        with pytest.raises(QuiltingClientError, match="not a PNG") as caught:
            responses.parse_png(answer(content=content, method="POST", path="/tile"))
        assert caught.value.code == "invalid_response" and "POST /tile" in str(caught.value)


@pytest.mark.parametrize(
    ("headers", "job_id"),
    [
        ({"X-Job-Id": "abc", "Location": "/jobs/zzz"}, "abc"),
        ({"Location": "/jobs/abc"}, "abc"),
        ({"Location": "/jobs/abc/result"}, "abc"),
        ({"Location": f"{BASE}/jobs/abc"}, "abc"),
        ({"Location": "/jobs/"}, None),
        ({"Location": "/elsewhere"}, None),
        ({"X-Job-Id": ""}, None),
        ({}, None),
    ],
)
def test_job_id_of_reads_x_job_id_then_location(
    headers: dict[str, str], job_id: str | None
) -> None:
    assert responses.job_id_of(answer(headers=headers)) == job_id


@pytest.mark.parametrize(
    ("status", "content_type"),
    [
        (202, "application/json"),
        (200, "application/json; charset=utf-8"),
        (200, "APPLICATION/JSON"),
    ],
)
def test_a_submission_answered_with_a_status_gives_the_status(
    status: int, content_type: str
) -> None:
    response = answer(
        status,
        content=json.dumps(job_json("queued", "j7")).encode(),
        headers={"Content-Type": content_type, "Location": "/jobs/j7"},
        method="POST",
        path="/synthesize",
    )
    outcome = responses.parse_submit(response)
    assert isinstance(outcome, JobStatus) and (outcome.id, outcome.status) == ("j7", "queued")


def test_a_submission_answered_with_the_result_gives_it_with_its_job_id() -> None:
    extracted = [{"method": "lkm", "unknown": 0.42}, None]
    headers = {
        "Content-Type": "image/png",
        "X-Job-Id": "j7",
        "Quilting-Extracted": json.dumps(extracted),
    }
    outcome = responses.parse_submit(answer(content=RESULT, headers=headers, method="POST"))
    assert outcome == Finished(image=RESULT, job_id="j7", extracted=extracted)
    bare = responses.parse_submit(answer(content=RESULT, method="POST"))
    assert bare == Finished(image=RESULT, job_id=None, extracted=[])


def test_a_202_that_is_not_a_status_is_an_invalid_response() -> None:
    response = answer(202, content=RESULT, headers={"Content-Type": "image/png"}, method="POST")
    with pytest.raises(QuiltingClientError) as caught:
        responses.parse_submit(response)
    assert caught.value.code == "invalid_response" and caught.value.status == 202


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        (None, []),
        ("", []),
        ("not json", []),
        ('{"method": "lkm"}', []),
        ("[]", []),
        (
            '[{"method": "lkm", "seconds": 0.5}, null, 3, "x"]',
            [{"method": "lkm", "seconds": 0.5}, None, None, None],
        ),
    ],
)
def test_extracted_of_reads_one_entry_per_photo(value: str | None, expected: list[Any]) -> None:
    headers = {} if value is None else {responses.EXTRACTED_HEADER: value}
    assert responses.extracted_of(answer(content=RESULT, headers=headers)) == expected
