"""HTTP problems (RFC 9457 ``application/problem+json``) with stable codes.

Engine errors map onto statuses here, in one table; the app turns a :class:`Problem` into a
response. Nothing in this module knows about FastAPI.
"""

from __future__ import annotations

from typing import Any

from quilting import QuiltingError

PROBLEM_TYPE = "https://quilting.dev/problems/"

#: Status of each engine error code (anything else a job raises is a 422 unless listed).
ENGINE_STATUS = {
    "invalid_parameter": 422,
    "invalid_image": 422,
    "unreadable_image": 422,
    "image_too_large": 422,
    "invalid_layout": 422,
    "backend_unavailable": 503,
    "matting_unavailable": 503,
    "invalid_trimap": 422,
    "cancelled": 409,
    "job_timeout": 504,
}

TITLES = {
    400: "Bad request",
    401: "Unauthorized",
    404: "Not found",
    405: "Method not allowed",
    408: "Request timeout",
    409: "Conflict",
    410: "Gone",
    413: "Payload too large",
    415: "Unsupported media type",
    422: "Unprocessable content",
    500: "Internal error",
    503: "Service unavailable",
    504: "Timed out",
}


#: The members every problem has, which no extra member may replace.
_MEMBERS = frozenset({"type", "title", "status", "detail", "code"})


class Problem(Exception):  # noqa: N818 - an HTTP problem document, raised
    """An error answered as problem+json.

    Parameters
    ----------
    status : int
        HTTP status.
    code : str
        Stable machine-readable code.
    detail : str
        What went wrong, for a person.
    headers : dict, optional
        Extra response headers (``Retry-After``...).
    **extra
        More members of the problem object (``field``, ``job_id``...).
    """

    def __init__(
        self,
        status: int,
        code: str,
        detail: str,
        headers: dict[str, str] | None = None,
        **extra: Any,
    ) -> None:
        super().__init__(detail)
        self.status = status
        self.code = code
        self.detail = detail
        self.headers = headers or {}
        reserved = _MEMBERS.intersection(extra)
        if reserved:  # a caller's mistake: the RFC 9457 members are the problem's own
            raise ValueError(f"a problem's extra members may not replace {sorted(reserved)}")
        self.extra = extra

    def body(self) -> dict[str, Any]:
        """The problem object."""
        return {
            "type": PROBLEM_TYPE + self.code,
            "title": TITLES.get(self.status, "Error"),
            "status": self.status,
            "detail": self.detail,
            "code": self.code,
            **self.extra,
        }


def queue_full(depth: int) -> Problem:
    """503 ``queue_full``: ``depth`` jobs wait, the most the service queues (either store)."""
    return Problem(
        503,
        "queue_full",
        f"{depth} jobs are waiting, the most this service queues; retry later",
        headers={"Retry-After": "5"},
    )


def job_not_found(job_id: str) -> Problem:
    """404 ``job_not_found``: no such job, or not the caller's (either store)."""
    return Problem(404, "job_not_found", f"no job {job_id!r}", job_id=job_id)


def idempotency_conflict() -> Problem:
    """409 ``idempotency_conflict``: a repeated Idempotency-Key with another body."""
    return Problem(
        409,
        "idempotency_conflict",
        "this Idempotency-Key was used with a different request body",
    )


def from_engine(error: QuiltingError) -> Problem:
    """The problem for an engine error (parameter errors name their field)."""
    code = "invalid_image" if error.code == "unreadable_image" else error.code
    extra: dict[str, Any] = {}
    parameter = getattr(error, "parameter", None)
    if parameter is not None:
        extra["field"] = parameter
    return Problem(ENGINE_STATUS.get(error.code, 422), code, error.message, **extra)
