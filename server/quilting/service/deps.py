"""The routes' dependencies: the app's shared :class:`~quilting.service.context.Service`, the
caller's API key, the job a path names, one value per form part, the checks of a service
that is shutting down, and what every submission route needs beside its own parts
(:class:`Submitting`)."""

from __future__ import annotations

import hmac
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, Header, Query, Request
from fastapi.responses import Response

from quilting.service.context import Models, Service
from quilting.service.forms import EXAMPLE_PARTS, MARK_PARTS, REPEATABLE_PARTS, Submission
from quilting.service.jobs import Job
from quilting.service.problems import Problem
from quilting.service.settings import Settings
from quilting.service.submit import submit


def service(request: Request) -> Service:
    """The app's shared parts."""
    found: Service = request.app.state.service
    return found


ServiceDep = Annotated[Service, Depends(service)]


def owner(
    request: Request,
    authorization: Annotated[str | None, Header()] = None,
    x_api_key: Annotated[str | None, Header()] = None,
) -> str | None:
    """The API key of the caller (None when the service has no keys); 401 without a valid
    one."""
    keys = service(request).settings.api_keys
    if not keys:
        return None
    key = x_api_key
    if authorization and authorization.lower().startswith("bearer "):
        key = authorization[7:].strip()
    # Constant-time comparison against every key: no timing hint of how much matched.
    matches = [hmac.compare_digest((key or "").encode(), k.encode()) for k in keys]
    if not any(matches):
        raise Problem(
            401,
            "unauthorized",
            "a valid API key is required (Authorization: Bearer KEY or X-API-Key)",
            headers={"WWW-Authenticate": "Bearer"},
        )
    return key


Owner = Annotated[str | None, Depends(owner)]


def metrics_reader(
    request: Request,
    authorization: Annotated[str | None, Header()] = None,
    x_api_key: Annotated[str | None, Header()] = None,
) -> None:
    """401 unless the caller has a key, when the service has keys and metrics_public is off:
    the figures tell outsiders how busy the service is and what it has made."""
    if not service(request).settings.metrics_public:
        owner(request, authorization, x_api_key)


def parts_once(repeatable: frozenset[str]) -> Callable[[Request], Awaitable[None]]:
    """The dependency that answers 422 ``duplicate_part`` for a part sent twice that is one
    value (a second ``target`` would otherwise silently replace the first), the parts in
    ``repeatable`` excepted."""

    async def single_parts(request: Request) -> None:
        seen: set[str] = set()
        for name, _ in (await request.form()).multi_items():
            if name in seen and name not in repeatable:
                raise Problem(
                    422,
                    "duplicate_part",
                    f"the part {name!r} was sent more than once; only "
                    + ", ".join(sorted(repeatable))
                    + " may repeat here",
                    field=name,
                )
            seen.add(name)

    return single_parts


SingleParts = [Depends(parts_once(REPEATABLE_PARTS))]
#: Of the routes that take several examples: ``texture`` and ``source_mask`` (``trimap`` and
#: ``scribbles``) repeat too.
ExampleParts = [Depends(parts_once(REPEATABLE_PARTS | EXAMPLE_PARTS))]
#: Of ``/matte``: ``trimap`` and ``scribbles`` repeat too, one per layer.
LayerParts = [Depends(parts_once(REPEATABLE_PARTS | MARK_PARTS))]


async def job_of(request: Request, job_id: str, key: Owner) -> Job:
    """The job ``job_id`` names, if the caller may see it (404 otherwise)."""
    return await service(request).jobs.get(job_id, key)


JobOf = Annotated[Job, Depends(job_of)]


def refuse_while_draining(request: Request) -> None:
    """503 ``draining`` once shutdown has begun: no new work is taken."""
    if request.app.state.draining:
        raise Problem(
            503, "draining", "the service is shutting down", headers={"Retry-After": "10"}
        )


def accepting(request: Request, wait: float | None) -> float:
    """The seconds to hold a submission, once the service is known to take new jobs."""
    refuse_while_draining(request)
    settings = service(request).settings
    wait_s = settings.default_wait_s if wait is None else wait
    if wait_s > settings.max_wait_s:
        raise Problem(
            422, "invalid_parameter", f"wait must be 0..{settings.max_wait_s:g}", field="wait"
        )
    return wait_s


WaitSeconds = Annotated[float | None, Query(ge=0, description="Seconds to wait for the result.")]
IdempotencyKey = Annotated[str | None, Header(max_length=256)]


@dataclass(frozen=True)
class Submitting:
    """What a submission route needs beside its own parts, once the service is known to take
    new jobs: the service, the caller's key, the seconds to hold the answer and the
    ``Idempotency-Key``.

    Attributes
    ----------
    service : Service
        The app's shared parts.
    key : str or None
        The caller's API key (None when the service has no keys).
    wait_s : float
        Seconds to hold the submission for its result (``wait``, or the default).
    idempotency_key : str or None
        The ``Idempotency-Key`` header.
    """

    service: Service
    key: str | None
    wait_s: float
    idempotency_key: str | None

    @property
    def settings(self) -> Settings:
        """The service's settings."""
        return self.service.settings

    @property
    def models(self) -> Models:
        """The options' schema models, each route's options checked against its own."""
        return self.service.models

    async def submit(self, submission: Submission) -> Response:
        """Check, queue (or find the idempotent twin), wait and answer
        (:func:`quilting.service.submit.submit`)."""
        return await submit(submission, self.service, self.key, self.idempotency_key, self.wait_s)


def submitting(
    request: Request,
    service: ServiceDep,
    key: Owner,
    wait: WaitSeconds = None,
    idempotency_key: IdempotencyKey = None,
) -> Submitting:
    """The :class:`Submitting` of a submission: 401 without a valid key, 503 ``draining``
    once shutdown has begun, 422 for a ``wait`` over ``max_wait_s``."""
    return Submitting(service, key, accepting(request, wait), idempotency_key)


Submitter = Annotated[Submitting, Depends(submitting)]
