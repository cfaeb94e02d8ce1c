"""The flows of the clients' public methods, as sans-I/O generators.

Each public method of :class:`~quilting_client.Client` and :class:`~quilting_client.AsyncClient`
runs the flow of the same name here: the requests are built by :mod:`quilting_client._protocol`,
the answers read by :mod:`quilting_client._responses`, and a job is waited for by
:mod:`quilting_client._waiting`. The drivers only perform the actions
(:mod:`quilting_client._actions`), so both clients do exactly the same.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from quilting_client import _protocol as proto
from quilting_client import _responses as responses
from quilting_client._actions import Flow, call, fetch_bytes, fetch_job, fetch_object
from quilting_client._protocol import RequestSpec
from quilting_client._uploads import ImageSource, output_names
from quilting_client._waiting import (
    Deadline,
    ProgressCallback,
    check_interval,
    follow,
    raise_unless_done,
)
from quilting_client.errors import QuiltingClientError
from quilting_client.models import JobStatus, SynthesisResult, WangTilesResult

#: How long ``synthesize`` lets the service hold the POST for the result: most jobs finish
#: within it, which saves a poll and a download round trip.
SUBMIT_HOLD = 10.0
#: The same with a progress callback: short, because nothing is reported while the POST is
#: held; the event stream reports progress after it.
SUBMIT_HOLD_WITH_PROGRESS = 1.0


def wait(
    job_id: str,
    *,
    progress: ProgressCallback | None,
    timeout: float | None,
    poll_interval: float,
) -> Flow[JobStatus]:
    """The flow of ``Client.wait``: follow a job until it ends or ``timeout`` passes."""
    check_interval(poll_interval)
    return (
        yield from follow(
            job_id, deadline=Deadline(timeout), progress=progress, poll_interval=poll_interval
        )
    )


# -- whole operations --------------------------------------------------------------------------
#
# The flows of the public methods that submit work take the methods' own arguments, handed on
# by _actions.start (``**options`` as ``options``). The arguments about waiting (progress,
# poll_interval, timeout) are used here; the rest go on as they are to the request's builder in
# _protocol, whose signature checks them, so that they are not spelled out here once more.


def submit_job(spec: RequestSpec) -> Flow[JobStatus]:
    """POST a submission without waiting (``spec`` asks for ``wait=0``); the job's status."""
    outcome = responses.parse_submit((yield from call(spec)))
    if isinstance(outcome, JobStatus):
        return outcome
    # Even with wait=0 the answer can be the PNG: an idempotent repeat of a job that finished
    # within its first request's wait. Its status is one request away.
    if outcome.job_id is None:
        raise QuiltingClientError(
            "the service answered with a result but no job id", code="invalid_response"
        )
    return (yield from fetch_job(outcome.job_id))


def submit(**arguments: Any) -> Flow[JobStatus]:
    """The flow of ``Client.submit``: POST /synthesize without waiting; the job's status."""
    return (yield from submit_job(proto.submit_request(**arguments, wait=0.0)))


def submit_transfer(**arguments: Any) -> Flow[JobStatus]:
    """The flow of ``Client.submit_transfer``: POST /transfer without waiting."""
    return (yield from submit_job(proto.transfer_request(**arguments, wait=0.0)))


def submit_matte(**arguments: Any) -> Flow[JobStatus]:
    """The flow of ``Client.submit_matte``: POST /matte without waiting."""
    return (yield from submit_job(proto.matte_request(**arguments, wait=0.0)))


def submit_fill(**arguments: Any) -> Flow[JobStatus]:
    """The flow of ``Client.submit_fill``: POST /fill without waiting."""
    return (yield from submit_job(proto.fill_request(**arguments, wait=0.0)))


def submit_extend(**arguments: Any) -> Flow[JobStatus]:
    """The flow of ``Client.submit_extend``: POST /extend without waiting."""
    return (yield from submit_job(proto.extend_request(**arguments, wait=0.0)))


def submit_extract_alpha(**arguments: Any) -> Flow[JobStatus]:
    """The flow of ``Client.submit_extract_alpha``: POST /extract-alpha without waiting."""
    return (yield from submit_job(proto.extract_request(**arguments, wait=0.0)))


def submit_wang_tiles(**arguments: Any) -> Flow[JobStatus]:
    """The flow of ``Client.submit_wang_tiles``: POST /wang-tiles without waiting."""
    return (yield from submit_job(proto.wang_request(**arguments, wait=0.0)))


def _hold(progress: ProgressCallback | None, timeout: float | None) -> float:
    """How long to let the service hold the POST for the result."""
    hold = SUBMIT_HOLD if progress is None else SUBMIT_HOLD_WITH_PROGRESS
    if timeout is not None:
        # From the timeout rather than the deadline's remainder, which is already a few
        # microseconds shorter and would print as ?wait=0.499998.
        hold = min(hold, timeout)
    return hold


def run_job(
    build: Callable[..., RequestSpec],
    downloads: Iterable[str] | None,
    *,
    progress: ProgressCallback | None,
    poll_interval: float,
    timeout: float | None,
    **request: Any,
) -> Flow[SynthesisResult]:
    """Submit a synthesis, a transfer, a matte, a fill or an extension, wait, download the
    result and companions.

    Parameters
    ----------
    build : callable
        The request's builder (:func:`~quilting_client._protocol.submit_request`...), called
        with ``request`` and the ``wait`` chosen here.
    downloads : iterable of str or None
        The companions to download beside the result (a mapping's keys: those sent along).
    progress, poll_interval, timeout
        As for ``Client.synthesize``.
    **request
        The rest of the arguments of ``build``.
    """
    check_interval(poll_interval)
    deadline = Deadline(timeout)
    response = yield from call(build(**request, wait=_hold(progress, timeout)))
    outcome = responses.parse_submit(response)
    if isinstance(outcome, JobStatus):
        job = outcome
        if not job.is_terminal:
            job = yield from follow(
                job.id,
                deadline=deadline,
                progress=progress,
                poll_interval=poll_interval,
                delay=max(poll_interval, responses.retry_after(response) or 0.0),
            )
        raise_unless_done(job)
        answer = yield from call(proto.result_request(job.id))
        image, extracted = answer.content, responses.extracted_of(answer)
        job_id: str | None = job.id
    else:
        image, job_id, extracted = outcome.image, outcome.job_id, outcome.extracted
        if progress is not None:
            progress(1.0, "done")
    maps: dict[str, bytes] = {}
    for name in downloads or ():
        if job_id is None:
            raise QuiltingClientError(
                "the service answered with a result but no job id to fetch companions from",
                code="invalid_response",
            )
        maps[name] = yield from fetch_bytes(proto.result_request(job_id, name))
    return SynthesisResult(image, job_id=job_id, companions=maps, extracted=extracted)


def synthesize(**arguments: Any) -> Flow[SynthesisResult]:
    """The flow of ``Client.synthesize``: submit, wait, download result and companions."""
    return (yield from run_job(proto.submit_request, arguments["companions"], **arguments))


def transfer(**arguments: Any) -> Flow[SynthesisResult]:
    """The flow of ``Client.transfer``: submit to /transfer, wait, download the results."""
    return (yield from run_job(proto.transfer_request, arguments["companions"], **arguments))


def matte(*, companions: Iterable[str], **arguments: Any) -> Flow[SynthesisResult]:
    """The flow of ``Client.matte``: submit to /matte, wait, download the result and the
    companions asked for (``normals``, ``clusters``).

    The names are checked before anything is sent, so that a mistake uploads nothing.
    """
    check_interval(arguments["poll_interval"])  # First, as in the other operations.
    names = output_names(companions)
    return (yield from run_job(proto.matte_request, names, **arguments))


def fill(**arguments: Any) -> Flow[SynthesisResult]:
    """The flow of ``Client.fill``: submit to /fill, wait, download the result and the
    companions filled along."""
    return (yield from run_job(proto.fill_request, arguments["companions"], **arguments))


def extend(**arguments: Any) -> Flow[SynthesisResult]:
    """The flow of ``Client.extend``: submit to /extend, wait, download the result and the
    companions extended along."""
    return (yield from run_job(proto.extend_request, arguments["companions"], **arguments))


def extract_alpha(**arguments: Any) -> Flow[SynthesisResult]:
    """The flow of ``Client.extract_alpha``: submit to /extract-alpha, wait, download the
    RGBA texture (its summary in the result's ``extracted``)."""
    return (yield from run_job(proto.extract_request, None, **arguments))


def wang_tiles(**arguments: Any) -> Flow[WangTilesResult]:
    """The flow of ``Client.wang_tiles``: submit to /wang-tiles, wait, download the atlas,
    then the manifest of the job (``X-Job-Id`` names it on a 200 as on a 202, as the
    companions of a synthesis answered at once are found)."""
    atlas = yield from run_job(proto.wang_request, None, **arguments)
    if atlas.job_id is None:
        raise QuiltingClientError(
            "the service answered with an atlas but no job id to fetch its manifest from",
            code="invalid_response",
        )
    manifest = yield from fetch_object(proto.manifest_request(atlas.job_id))
    return WangTilesResult(bytes(atlas), manifest=manifest, job_id=atlas.job_id)


def tile(
    image: ImageSource,
    *,
    axes: str,
    band: int | None,
    timeout: float | None,
    blend: str | None = None,
    method: str | None = None,
    seed: int | None = None,
) -> Flow[bytes]:
    """The flow of ``Client.tile``: one ``POST /tile``, answered with the PNG itself.

    No job is created, so there is nothing to follow: the service answers when the image is
    tiled. Like a submission, a 503 (``draining``) is raised at once as
    :class:`~quilting_client.errors.ServiceUnavailableError` with its ``retry_after``, not
    retried.
    """
    if timeout is not None and not timeout > 0:
        raise ValueError(f"timeout must be positive, not {timeout!r}")
    spec = proto.tile_request(
        image, axes=axes, band=band, blend=blend, method=method, seed=seed, timeout=timeout
    )
    return responses.parse_png((yield from call(spec)))


def health() -> Flow[bool]:
    """The flow of ``Client.health``: whether ``GET /healthz`` says ``ok``; False for any
    error, the service being unreachable included."""
    try:
        body = yield from fetch_object(proto.health_request())
    except QuiltingClientError:
        return False
    return body.get("status") == "ok"
