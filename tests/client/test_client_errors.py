"""The client's exception hierarchy (``quilting_client.errors``), built directly.

Covers
------
- :func:`error_from_problem`: every problem ``code`` the service documents (docs/client.md,
  docs/http-service.md and the service's own problems) gives the exception class of its HTTP
  status, with ``status``, ``code``, ``detail``, ``problem`` (and ``field``, ``retry_after``)
  preserved; unknown statuses and codes, missing members and odd member types still give a
  clear error;
- ``str(error)``: one useful line, detail first, then the status and the code;
- :class:`JobFailedError` and :class:`JobCancelledError` built from a job's final status, and
  :class:`WaitTimeoutError`;
- the hierarchy itself: everything is a :class:`QuiltingClientError`, a 503 is a
  :class:`ServerError`, a wait timeout a :class:`TimeoutError`.
"""

from __future__ import annotations

import pickle
from typing import Any

import pytest

import quilting_client
from quilting_client import errors
from quilting_client.errors import (
    AuthenticationError,
    ConflictError,
    ConnectionFailedError,
    GoneError,
    JobCancelledError,
    JobError,
    JobFailedError,
    NotFoundError,
    PayloadTooLargeError,
    QuiltingClientError,
    ServerError,
    ServiceUnavailableError,
    UnsupportedMediaTypeError,
    ValidationError,
    WaitTimeoutError,
    error_from_problem,
)
from quilting_client.models import JobStatus

PROBLEMS = "https://quilting.dev/problems/"

#: (status, code, class) of each problem the service documents or answers with.
DOCUMENTED = [
    (401, "unauthorized", AuthenticationError),
    (404, "job_not_found", NotFoundError),
    (404, "companion_not_found", NotFoundError),
    (404, "no_layout", NotFoundError),
    (404, "no_manifest", NotFoundError),
    (404, "no_seams", NotFoundError),
    (404, "not_found", NotFoundError),
    (409, "idempotency_conflict", ConflictError),
    (409, "job_not_done", ConflictError),
    (409, "job_failed", ConflictError),
    (409, "job_cancelled", ConflictError),
    (409, "job_finished", ConflictError),
    (409, "cancelled", ConflictError),
    (410, "result_expired", GoneError),
    (413, "body_too_large", PayloadTooLargeError),
    (413, "file_too_large", PayloadTooLargeError),
    (415, "unsupported_media_type", UnsupportedMediaTypeError),
    (422, "invalid_parameter", ValidationError),
    (422, "invalid_options", ValidationError),
    (422, "invalid_image", ValidationError),
    (422, "image_too_large", ValidationError),
    (422, "image_too_costly", ValidationError),
    (422, "job_too_large", ValidationError),
    (422, "invalid_companion", ValidationError),
    (422, "invalid_source_mask", ValidationError),
    (422, "invalid_trimap", ValidationError),
    (422, "invalid_layout", ValidationError),
    (422, "too_many_layers", ValidationError),
    (422, "too_many_textures", ValidationError),
    (422, "duplicate_part", ValidationError),
    (422, "missing_field", ValidationError),
    (500, "internal_error", ServerError),
    (503, "queue_full", ServiceUnavailableError),
    (503, "draining", ServiceUnavailableError),
    (503, "sandbox_busy", ServiceUnavailableError),
    (503, "queue_unavailable", ServiceUnavailableError),
    (503, "backend_unavailable", ServiceUnavailableError),
    (503, "matting_unavailable", ServiceUnavailableError),
    (503, "job_abandoned", ServiceUnavailableError),
    (503, "shutdown", ServiceUnavailableError),
    (504, "job_timeout", ServerError),
    # Statuses without a class of their own: the base class, not a guess.
    (400, "bad_request", QuiltingClientError),
    (405, "method_not_allowed", QuiltingClientError),
    (408, "request_timeout", QuiltingClientError),
]


def problem(status: int, code: str, detail: str = "it went wrong", **extra: Any) -> dict[str, Any]:
    """A problem document as the service writes it."""
    return {
        "type": PROBLEMS + code,
        "title": "Some title",
        "status": status,
        "detail": detail,
        "code": code,
        **extra,
    }


@pytest.mark.parametrize(("status", "code", "cls"), DOCUMENTED)
def test_each_documented_code_maps_to_its_class_with_its_members(
    status: int, code: str, cls: type[QuiltingClientError]
) -> None:
    body = problem(status, code, field="overlap", job_id="j1")
    error = error_from_problem(body, status=status)
    assert type(error) is cls and isinstance(error, QuiltingClientError)
    assert (error.status, error.code, error.detail) == (status, code, "it went wrong")
    assert error.problem == body and error.problem["job_id"] == "j1"
    assert str(error) == f"it went wrong (HTTP {status}, {code})"
    if cls is ValidationError:
        assert isinstance(error, ValidationError) and error.field == "overlap"
    assert isinstance(error, ServerError) is (status >= 500)


@pytest.mark.parametrize(("status", "code", "cls"), DOCUMENTED)
def test_the_problem_s_own_status_is_used_when_none_is_given(
    status: int, code: str, cls: type[QuiltingClientError]
) -> None:
    error = error_from_problem(problem(status, code))
    assert type(error) is cls and error.status == status


def test_the_given_status_wins_over_the_problem_s() -> None:
    error = error_from_problem(problem(422, "invalid_parameter"), status=404)
    assert type(error) is NotFoundError and error.status == 404


@pytest.mark.parametrize("status", [True, "422", 422.0, None])
def test_a_problem_status_that_is_not_an_integer_is_ignored(status: object) -> None:
    error = error_from_problem({"status": status, "code": "invalid_parameter", "detail": "bad"})
    assert type(error) is QuiltingClientError and error.status is None
    assert str(error) == "bad (invalid_parameter)"


@pytest.mark.parametrize(
    ("status", "cls"),
    [(402, QuiltingClientError), (418, QuiltingClientError), (429, QuiltingClientError)]
    + [(s, ServerError) for s in (501, 502, 507, 599)],
)
def test_an_unknown_status_gives_the_base_class_or_a_server_error(
    status: int, cls: type[QuiltingClientError]
) -> None:
    error = error_from_problem(problem(status, "brand_new_code"), status=status)
    assert type(error) is cls and error.code == "brand_new_code"
    assert "brand_new_code" in str(error) and f"HTTP {status}" in str(error)


def test_an_unknown_code_keeps_the_class_of_its_status() -> None:
    error = error_from_problem(problem(422, "invented_later", field="weights"), status=422)
    assert type(error) is ValidationError and error.code == "invented_later"
    assert error.field == "weights"


@pytest.mark.parametrize(
    ("members", "code"),
    [
        ({"type": PROBLEMS + "result_expired"}, "result_expired"),
        ({"type": PROBLEMS + "result_expired/"}, "result_expired"),
        ({"type": "about:blank"}, "http_410"),
        ({"type": 12}, "http_410"),
        ({"code": "", "type": PROBLEMS + "result_expired"}, "result_expired"),
        ({"code": None}, "http_410"),
        ({}, "http_410"),
    ],
)
def test_a_missing_code_comes_from_the_type_or_the_status(
    members: dict[str, Any], code: str
) -> None:
    error = error_from_problem({"detail": "gone", **members}, status=410)
    assert type(error) is GoneError and error.code == code


def test_without_status_nor_code_the_code_is_empty() -> None:
    error = error_from_problem({"detail": "something"})
    assert type(error) is QuiltingClientError and error.code == "" and error.status is None
    assert str(error) == "something"


@pytest.mark.parametrize(
    ("members", "detail"),
    [
        ({"detail": "d", "title": "t"}, "d"),
        ({"title": "Payload too large"}, "Payload too large"),
        ({"detail": "", "title": "t"}, "t"),
        ({"detail": None, "title": None}, ""),
        ({"detail": 42}, "42"),
    ],
)
def test_the_detail_falls_back_on_the_title(members: dict[str, Any], detail: str) -> None:
    error = error_from_problem({"code": "file_too_large", **members}, status=413)
    assert error.detail == detail
    expected = f"{detail} (HTTP 413, file_too_large)" if detail else "HTTP 413, file_too_large"
    assert str(error) == expected


def test_the_problem_is_a_copy_of_the_document() -> None:
    body = problem(422, "job_too_large", budget_bytes=2231369728, budget_seconds=300.0)
    error = error_from_problem(body)
    body["detail"] = "changed"
    body.pop("budget_bytes")
    assert (
        error.problem["detail"] == "it went wrong" and error.problem["budget_bytes"] == 2231369728
    )
    assert error.detail == "it went wrong"


@pytest.mark.parametrize(
    ("field", "expected"), [("overlap", "overlap"), (None, None), (3, "3"), ("", "")]
)
def test_a_validation_error_names_its_field(field: object, expected: str | None) -> None:
    body = problem(422, "invalid_parameter")
    if field is not None:
        body["field"] = field
    error = error_from_problem(body)
    assert isinstance(error, ValidationError) and error.field == expected


@pytest.mark.parametrize(
    ("header", "member", "expected"),
    [
        (7.0, None, 7.0),
        (7.0, 30, 7.0),  # The Retry-After header wins.
        (None, 30, 30.0),
        (None, 2.5, 2.5),
        (None, "30", None),  # Not a number: not a delay.
        (None, None, None),
        (0.0, 30, 0.0),  # "Retry-After: 0" is an answer, not a missing one.
        (None, True, None),  # A bool is no delay (bools are refused as statuses too).
        (None, float("inf"), None),  # Nor is a delay that never ends.
        (None, -4, 0.0),
    ],
)
def test_a_503_carries_when_to_retry(
    header: float | None, member: object, expected: float | None
) -> None:
    body = problem(503, "queue_full")
    if member is not None:
        body["retry_after"] = member
    error = error_from_problem(body, status=503, retry_after=header)
    assert isinstance(error, ServiceUnavailableError) and isinstance(error, ServerError)
    assert error.retry_after == expected


def test_retry_after_is_kept_for_503_only() -> None:
    error = error_from_problem(problem(500, "internal_error"), retry_after=5.0)
    assert type(error) is ServerError and not hasattr(error, "retry_after")


# -- str() --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "text"),
    [
        ({"detail": "d", "status": 422, "code": "c"}, "d (HTTP 422, c)"),
        ({"detail": "d", "code": "c"}, "d (c)"),
        ({"detail": "d", "status": 500}, "d (HTTP 500)"),
        ({"detail": "d"}, "d"),
        ({"status": 502, "code": "http_502"}, "HTTP 502, http_502"),
        ({"code": "c"}, "c"),
        ({}, "unknown error"),
    ],
)
def test_str_is_one_line_detail_first(kwargs: dict[str, Any], text: str) -> None:
    error = QuiltingClientError(**kwargs)
    assert str(error) == text and error.args == (text,)
    assert error.problem == {}


def test_a_client_side_validation_error_reads_well() -> None:
    error = ValidationError(
        "layers: at least one texture is needed", code="missing_field", field="layer"
    )
    assert str(error) == "layers: at least one texture is needed (missing_field)"
    assert error.status is None and error.field == "layer"


# -- errors of a job ----------------------------------------------------------------------------


def job(state: str, error: dict[str, Any] | None = None, job_id: str = "j1") -> JobStatus:
    return JobStatus.from_json({"id": job_id, "status": state, "error": error})


def test_a_failed_job_s_error_carries_its_problem() -> None:
    body = problem(500, "engine_error", "the cost backend crashed", stage="seams")
    final = job("failed", body, "7f3a")
    error = JobFailedError(final)
    assert error.job is final and isinstance(error, JobError)
    assert (error.status, error.code) == (500, "engine_error")
    assert error.detail == "job 7f3a failed: the cost backend crashed"
    assert error.problem == body
    assert str(error) == "job 7f3a failed: the cost backend crashed (HTTP 500, engine_error)"


@pytest.mark.parametrize(
    ("cls", "state", "code", "text"),
    [
        (JobFailedError, "failed", "job_failed", "job j1 failed"),
        (JobCancelledError, "cancelled", "job_cancelled", "job j1 was cancelled"),
    ],
)
def test_a_job_error_without_problem_has_a_default_code(
    cls: type[JobError], state: str, code: str, text: str
) -> None:
    error = cls(job(state))
    assert (error.code, error.status, error.detail, error.problem) == (code, None, text, {})
    assert str(error) == f"{text} ({code})"


@pytest.mark.parametrize(
    ("body", "code", "status", "detail"),
    [
        ({"type": PROBLEMS + "job_timeout", "status": 504}, "job_timeout", 504, ""),
        (
            {"code": "job_too_large", "title": "out of memory"},
            "job_too_large",
            None,
            "out of memory",
        ),
        ({"code": "x", "status": "504"}, "x", None, ""),
        ({"code": "x", "status": True}, "x", None, ""),
        ({"detail": "killed"}, "job_failed", None, "killed"),
    ],
)
def test_a_job_error_reads_what_its_problem_has(
    body: dict[str, Any], code: str, status: int | None, detail: str
) -> None:
    error = JobFailedError(job("failed", body))
    assert (error.code, error.status) == (code, status)
    assert error.detail == (f"job j1 failed: {detail}" if detail else "job j1 failed")


def test_a_cancelled_job_is_not_a_failed_one() -> None:
    error = JobCancelledError(job("cancelled", problem(409, "cancelled", "cancelled by a DELETE")))
    assert not isinstance(error, JobFailedError) and error.code == "cancelled"
    assert str(error) == "job j1 was cancelled: cancelled by a DELETE (HTTP 409, cancelled)"


@pytest.mark.parametrize(
    ("timeout", "text"),
    [
        (2.5, "job j1 did not finish within 2.5 s; it keeps running on the service"),
        (300.0, "job j1 did not finish within 300 s; it keeps running on the service"),
        (None, "job j1 did not finish; it keeps running on the service"),
    ],
)
def test_a_wait_timeout_names_the_job_and_the_timeout(timeout: float | None, text: str) -> None:
    last = job("running")
    error = WaitTimeoutError("j1", timeout, last)
    assert (error.job_id, error.job, error.status, error.code) == ("j1", last, None, "wait_timeout")
    assert str(error) == f"{text} (wait_timeout)"
    assert isinstance(error, TimeoutError) and isinstance(error, QuiltingClientError)
    assert WaitTimeoutError("j1", timeout).job is None


def test_a_wait_timeout_is_caught_as_a_timeout() -> None:
    with pytest.raises(TimeoutError):
        raise WaitTimeoutError("j1", 1.0)


# -- the hierarchy ------------------------------------------------------------------------------


def test_every_exported_error_is_a_quilting_client_error() -> None:
    classes = [getattr(errors, name) for name in errors.__all__ if name != "error_from_problem"]
    assert len(classes) == len(errors.__all__) - 1 == 15
    for cls in classes:
        assert issubclass(cls, QuiltingClientError), cls
        # The package exports them too, so callers need not import a private module.
        assert getattr(quilting_client, cls.__name__) is cls
    assert issubclass(ServiceUnavailableError, ServerError)
    assert issubclass(JobFailedError, JobError) and issubclass(JobCancelledError, JobError)
    assert not issubclass(ConnectionFailedError, ServerError)


# -- crossing a process boundary -----------------------------------------------------------------


@pytest.mark.parametrize(
    "error",
    [
        WaitTimeoutError("j1", 2.5),
        WaitTimeoutError("j2", None, JobStatus("j2", "running")),
        JobFailedError(
            JobStatus("j3", "failed", error={"code": "x", "detail": "d", "status": 422})
        ),
        JobCancelledError(JobStatus("j4", "cancelled")),
        error_from_problem(problem(422, "invalid_parameter", field="block"), status=422),
        error_from_problem(problem(503, "queue_full"), status=503, retry_after=5.0),
    ],
    ids=lambda error: type(error).__name__,
)
def test_every_error_survives_a_pickle(error: QuiltingClientError) -> None:
    # A pipeline's workers (multiprocessing, concurrent.futures) hand errors back pickled.
    again = pickle.loads(pickle.dumps(error))
    assert type(again) is type(error)
    assert str(again) == str(error) and again.__dict__ == error.__dict__
