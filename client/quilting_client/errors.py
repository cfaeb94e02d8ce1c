"""Typed exceptions of the quilting client, built from the service's problem+json bodies.

Every error the client raises on purpose derives from :class:`QuiltingClientError`, which carries
the HTTP status (or None when no response was involved), the stable problem ``code``, the
human-readable ``detail`` and the whole ``problem`` document. The subclass is chosen from the
HTTP status, so callers can catch what they can handle (``ServiceUnavailableError`` to retry later,
``ValidationError`` to fix an option) and let the rest propagate.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, TypedDict, Unpack

if TYPE_CHECKING:
    from quilting_client.models import JobStatus

__all__ = [
    "AuthenticationError",
    "ConflictError",
    "ConnectionFailedError",
    "GoneError",
    "JobCancelledError",
    "JobError",
    "JobFailedError",
    "NotFoundError",
    "PayloadTooLargeError",
    "QuiltingClientError",
    "ServerError",
    "ServiceUnavailableError",
    "UnsupportedMediaTypeError",
    "ValidationError",
    "WaitTimeoutError",
    "error_from_problem",
]


class QuiltingClientError(Exception):
    """Base class of every error raised by the quilting client.

    Parameters
    ----------
    detail : str
        Human-readable explanation of this occurrence.
    status : int or None
        HTTP status of the response, or None when the error did not come from a response.
    code : str
        Stable machine-readable problem code (e.g. ``"invalid_parameter"``).
    problem : Mapping or None
        The whole problem document, extra members included.

    Attributes
    ----------
    status : int or None
    code : str
    detail : str
    problem : dict
    """

    def __init__(
        self,
        detail: str = "",
        *,
        status: int | None = None,
        code: str = "",
        problem: Mapping[str, Any] | None = None,
    ) -> None:
        self.status = status
        self.code = code
        self.detail = detail
        self.problem: dict[str, Any] = dict(problem) if problem else {}
        super().__init__(self._describe())

    def _describe(self) -> str:
        # One line that reads well after "error: " in a terminal: the detail first, then the
        # status and code that a bug report or a log search needs.
        tags = [t for t in (f"HTTP {self.status}" if self.status else "", self.code) if t]
        if not self.detail:
            return ", ".join(tags) or "unknown error"
        return f"{self.detail} ({', '.join(tags)})" if tags else self.detail


class Common(TypedDict, total=False):
    """The keywords of :class:`QuiltingClientError`, which its subclasses pass on as they are.

    A subclass that adds a keyword of its own (:class:`ValidationError`,
    :class:`ServiceUnavailableError`) takes these as ``**common``, typed, rather than
    repeating them.
    """

    status: int | None
    code: str
    problem: Mapping[str, Any] | None


class AuthenticationError(QuiltingClientError):
    """The API key is missing or wrong (HTTP 401, code ``unauthorized``)."""


class NotFoundError(QuiltingClientError):
    """Unknown job or companion, or a job created with another key (HTTP 404)."""


class ConflictError(QuiltingClientError):
    """The request conflicts with the job's state or an idempotency key (HTTP 409).

    Codes: ``idempotency_conflict``, ``job_not_done``, ``job_failed``, ``job_cancelled``,
    ``job_finished``.
    """


class GoneError(QuiltingClientError):
    """The job's results were evicted (HTTP 410, code ``result_expired``)."""


class PayloadTooLargeError(QuiltingClientError):
    """The request body or one file is too large (HTTP 413)."""


class UnsupportedMediaTypeError(QuiltingClientError):
    """An uploaded file is neither PNG nor JPEG (HTTP 415)."""


class ValidationError(QuiltingClientError):
    """An option or an image was rejected (HTTP 422), or a client-side check failed.

    Parameters
    ----------
    detail, status, code, problem
        See :class:`QuiltingClientError`.
    field : str or None
        The option at fault, when the service names one (code ``invalid_parameter``).
    """

    def __init__(
        self, detail: str = "", *, field: str | None = None, **common: Unpack[Common]
    ) -> None:
        self.field = field
        super().__init__(detail, **common)


class ServerError(QuiltingClientError):
    """The service failed (HTTP 5xx other than 503)."""


class ServiceUnavailableError(ServerError):
    """The service is draining or its queue is full (HTTP 503); try again later.

    Parameters
    ----------
    detail, status, code, problem
        See :class:`QuiltingClientError`.
    retry_after : float or None
        Seconds the service asked to wait before retrying (``Retry-After``), if it said.
    """

    def __init__(
        self, detail: str = "", *, retry_after: float | None = None, **common: Unpack[Common]
    ) -> None:
        self.retry_after = retry_after
        super().__init__(detail, **common)


class ConnectionFailedError(QuiltingClientError):
    """The service could not be reached or the connection broke (an httpx transport error)."""


class JobError(QuiltingClientError):
    """The job ended without a result; ``code`` and ``detail`` come from the job's ``error``.

    Parameters
    ----------
    job : JobStatus
        The job's final status.

    Attributes
    ----------
    job : JobStatus
    """

    default_code = "job_error"
    verb = "ended without a result"

    def __init__(self, job: JobStatus) -> None:
        self.job = job
        problem = dict(job.error or {})
        detail = str(problem.get("detail") or problem.get("title") or "")
        code = problem.get("code") or _code_from_type(problem.get("type")) or self.default_code
        super().__init__(
            f"job {job.id} {self.verb}: {detail}" if detail else f"job {job.id} {self.verb}",
            # The problem's status is the one the service would have answered with had the
            # error happened during the request; the CLI uses it to tell user from server faults.
            status=_as_int(problem.get("status")),
            code=str(code),
            problem=problem,
        )

    def __reduce__(self) -> tuple[Any, ...]:
        # Rebuilt from the job, as constructed: the error crosses process boundaries
        # (multiprocessing, concurrent.futures), where a pickle made from ``args`` alone
        # would call __init__ with the message.
        return (type(self), (self.job,), self.__dict__)


class JobFailedError(JobError):
    """The job ended ``failed`` (the engine reported an error)."""

    default_code = "job_failed"
    verb = "failed"


class JobCancelledError(JobError):
    """The job ended ``cancelled`` (by a ``DELETE``, possibly from another client)."""

    default_code = "job_cancelled"
    verb = "was cancelled"


class WaitTimeoutError(QuiltingClientError, TimeoutError):
    """The job did not finish within the caller's timeout. The job itself was NOT cancelled.

    Parameters
    ----------
    job_id : str
        The job that is still running on the service.
    timeout : float or None
        The timeout that ran out, in seconds.
    job : JobStatus or None
        The last status seen, if any.
    """

    def __init__(self, job_id: str, timeout: float | None, job: JobStatus | None = None) -> None:
        self.job_id = job_id
        self.timeout = timeout
        self.job = job
        super().__init__(
            f"job {job_id} did not finish within {timeout:g} s; it keeps running on the service"
            if timeout is not None
            else f"job {job_id} did not finish; it keeps running on the service",
            code="wait_timeout",
        )

    def __reduce__(self) -> tuple[Any, ...]:
        # As JobError's: rebuilt from what it was made of, so that it survives a pickle.
        return (type(self), (self.job_id, self.timeout, self.job), self.__dict__)


# The status decides the class; codes refine within a class and are left to the caller.
_BY_STATUS: dict[int, type[QuiltingClientError]] = {
    401: AuthenticationError,
    404: NotFoundError,
    409: ConflictError,
    410: GoneError,
    413: PayloadTooLargeError,
    415: UnsupportedMediaTypeError,
    422: ValidationError,
    503: ServiceUnavailableError,
}


def _as_int(value: object) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def _code_from_type(value: object) -> str:
    # The problem type URI ends in the code (".../problems/<code>"): a fallback for a problem
    # whose "code" member is missing.
    if not isinstance(value, str) or "/" not in value:
        return ""
    return value.rstrip("/").rsplit("/", 1)[-1]


def error_from_problem(
    problem: Mapping[str, Any],
    *,
    status: int | None = None,
    retry_after: float | None = None,
) -> QuiltingClientError:
    """Build the typed error for a problem document.

    Parameters
    ----------
    problem : Mapping
        The problem+json body (or a synthetic one for a non-JSON error body).
    status : int or None
        The HTTP status; defaults to the problem's ``status`` member.
    retry_after : float or None
        The ``Retry-After`` header in seconds, for 503 answers.

    Returns
    -------
    QuiltingClientError
        An instance of the subclass that matches the status.
    """
    if status is None:
        status = _as_int(problem.get("status"))
    code = str(problem.get("code") or _code_from_type(problem.get("type")) or "")
    if not code and status is not None:
        code = f"http_{status}"
    detail = str(problem.get("detail") or problem.get("title") or "")
    cls = _BY_STATUS.get(status or 0)
    if cls is None:
        cls = ServerError if status is not None and status >= 500 else QuiltingClientError
    if cls is ValidationError:
        field = problem.get("field")
        return ValidationError(
            detail,
            status=status,
            code=code,
            problem=problem,
            field=str(field) if field is not None else None,
        )
    if cls is ServiceUnavailableError:
        member = problem.get("retry_after")
        if (
            retry_after is None
            and isinstance(member, int | float)
            and not isinstance(member, bool)
            and math.isfinite(member)
        ):
            retry_after = max(0.0, float(member))
        return ServiceUnavailableError(
            detail, status=status, code=code, problem=problem, retry_after=retry_after
        )
    return cls(detail, status=status, code=code, problem=problem)
