"""The service's answers, interpreted without any I/O: documents parsed, errors mapped.

A driver hands every response here: error statuses become the typed errors of
:mod:`quilting_client.errors` (:func:`raise_for_problem`), transport failures become
:class:`~quilting_client.errors.ConnectionFailedError` (:func:`transport_errors`), and successful
bodies become job statuses, PNGs and JSON objects. The sync and async clients share all of it.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from email.utils import parsedate_to_datetime
from time import time
from typing import Any

import httpx

from quilting_client._uploads import PNG_SIGNATURE
from quilting_client.errors import ConnectionFailedError, QuiltingClientError, error_from_problem
from quilting_client.models import JobStatus


@dataclass(frozen=True)
class Finished:
    """A ``POST /synthesize``, ``/transfer`` or ``/matte`` answered with the result PNG itself
    (HTTP 200).

    Attributes
    ----------
    image : bytes
        The result PNG.
    job_id : str or None
        From ``X-Job-Id`` (or ``Location``).
    extracted : list of (dict or None)
        From ``Quilting-Extracted`` (:func:`extracted_of`).
    """

    image: bytes
    job_id: str | None
    extracted: list[dict[str, Any] | None] = field(default_factory=list)


def retry_after(response: httpx.Response) -> float | None:
    """The ``Retry-After`` header in seconds (delta-seconds or an HTTP date), or None."""
    value = response.headers.get("Retry-After")
    if value is None:
        return None
    try:
        seconds = float(value)
    except ValueError:
        pass
    else:
        # "inf" and "nan" parse as floats but are no delta-seconds: a sleep would overflow
        # or never end.
        return max(0.0, seconds) if math.isfinite(seconds) else None
    try:
        return max(0.0, parsedate_to_datetime(value).timestamp() - time())
    except (TypeError, ValueError):
        return None


def problem_of(response: httpx.Response) -> dict[str, Any]:
    """The problem document of an error response; a synthetic one if the body is not JSON."""
    try:
        body = response.json()
    except ValueError:
        body = None
    if isinstance(body, dict) and body:
        return body
    # A proxy or a crashed worker may answer in plain text or HTML: keep the status and a
    # short, single-line excerpt so that the error still says something useful.
    reason = response.reason_phrase or "error"
    text = " ".join(response.text.split())[:200]
    detail = f"{reason}: {text}" if text and not text.startswith("<") else reason
    return {"title": reason, "status": response.status_code, "detail": detail}


def raise_for_problem(response: httpx.Response) -> None:
    """Raise the typed error of an error response (status >= 400); return otherwise.

    The body must have been read.
    """
    if response.status_code < 400:
        return
    raise error_from_problem(
        problem_of(response), status=response.status_code, retry_after=retry_after(response)
    )


def connection_error(exc: httpx.TransportError, request: httpx.Request) -> ConnectionFailedError:
    """The client error for an httpx transport failure (refused, reset, timed out...)."""
    kind = type(exc).__name__
    reason = str(exc) or kind
    return ConnectionFailedError(
        f"{request.method} {request.url}: {reason}", code="connection_failed"
    )


@contextmanager
def transport_errors(request: httpx.Request) -> Iterator[None]:
    """Raise :func:`connection_error` for an httpx transport failure inside the block.

    A plain context manager, so that the blocking and the asyncio driver wrap their sends
    alike (an ``await`` inside a ``with`` block is fine).
    """
    try:
        yield
    except httpx.TransportError as exc:
        raise connection_error(exc, request) from exc


def timed_out(error: QuiltingClientError) -> bool:
    """Whether ``error`` is a connection that timed out (rather than one refused or reset)."""
    return isinstance(error, ConnectionFailedError) and isinstance(
        error.__cause__, httpx.TimeoutException
    )


def _invalid_response(response: httpx.Response, why: str) -> QuiltingClientError:
    return QuiltingClientError(
        f"unexpected response to {response.request.method} {response.request.url.path}: {why}",
        status=response.status_code,
        code="invalid_response",
    )


def parse_json_object(response: httpx.Response) -> dict[str, Any]:
    """The JSON object of a successful response."""
    try:
        body = response.json()
    except ValueError:
        raise _invalid_response(response, "the body is not JSON") from None
    if not isinstance(body, dict):
        raise _invalid_response(response, "the body is not a JSON object")
    return body


def parse_job(response: httpx.Response) -> JobStatus:
    """The job status in a successful response."""
    try:
        return JobStatus.from_json(parse_json_object(response))
    except ValueError as exc:
        raise _invalid_response(response, str(exc)) from None


def job_id_of(response: httpx.Response) -> str | None:
    """The job id a response names in ``X-Job-Id``, or else in ``Location: /jobs/<id>``."""
    job_id: str | None = response.headers.get("X-Job-Id")
    if job_id:
        return job_id
    location = response.headers.get("Location", "")
    if "/jobs/" in location:
        return location.rsplit("/jobs/", 1)[1].split("/", 1)[0] or None
    return None


def parse_png(response: httpx.Response) -> bytes:
    """The PNG of a successful response that must be one (``POST /tile``)."""
    if not response.content.startswith(PNG_SIGNATURE):
        raise _invalid_response(response, "the body is not a PNG")
    return response.content


def parse_submit(response: httpx.Response) -> Finished | JobStatus:
    """Interpret the answer to a submission: the result itself, or the job's status."""
    media_type = response.headers.get("Content-Type", "").split(";")[0].strip().lower()
    if response.status_code == 202 or media_type.endswith("json"):
        return parse_job(response)
    return Finished(
        image=response.content, job_id=job_id_of(response), extracted=extracted_of(response)
    )


#: The header of a result made from photos whose alpha the service extracted first.
EXTRACTED_HEADER = "Quilting-Extracted"


def extracted_of(response: httpx.Response) -> list[dict[str, Any] | None]:
    """The ``Quilting-Extracted`` header of a result: one entry per photo (a synthesis's
    textures, a matte's layers, an extraction's photo), None for one without a trimap or
    scribbles, each ``{method, foreground, unknown, iterations, seconds}``; empty when no
    alpha was extracted (or the header is not such an array)."""
    value = response.headers.get(EXTRACTED_HEADER)
    if not value:
        return []
    try:
        found = json.loads(value)
    except ValueError:
        return []
    if not isinstance(found, list):
        return []
    return [dict(entry) if isinstance(entry, dict) else None for entry in found]
