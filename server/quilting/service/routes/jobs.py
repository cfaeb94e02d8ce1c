"""``/jobs/{id}``: a job's status, its files (the result, companions, layout, seams, a Wang
tile set's manifest), its progress as events, and cancelling it.

A Wang tile set (``POST /wang-tiles``) keeps its manifest where a synthesis keeps its block
layout: it *is* the layout of its result, the atlas (each tile's place and edge colours), so
``/layout`` and ``/manifest`` serve the same document; it has no seams between blocks to draw
(``/seams`` is 404 ``no_seams``). ``/manifest`` of any other job is 404 ``no_manifest``.
"""

from __future__ import annotations

import re
from typing import Annotated

from fastapi import APIRouter, Header, Query
from fastapi.responses import JSONResponse, Response, StreamingResponse

from quilting.service.context import Service
from quilting.service.deps import JobOf, ServiceDep
from quilting.service.downloads import attachment, download_name, extracted_headers
from quilting.service.events import END_EVENT_ID, job_stream, resume_after
from quilting.service.jobs import Job, Status
from quilting.service.openapi import problems
from quilting.service.problems import Problem

HEX_COLOR = re.compile(r"^[0-9a-fA-F]{6}$")

router = APIRouter()

FILE_PROBLEMS = problems(401, 404, 409, 410, 422)


@router.get(
    "/jobs/{job_id}",
    operation_id="get_job",
    summary="Status of a job",
    responses=problems(401, 404, 422),
)
async def get_job(job: JobOf) -> JSONResponse:
    return JSONResponse(job.snapshot())


def _expired() -> Problem:
    return Problem(410, "result_expired", "the results of this job are no longer kept")


def _finished_result(job: Job) -> None:
    if job.expired:
        raise _expired()
    if not job.status.final:
        raise Problem(
            409, "job_not_done", f"the job is {job.status.value}", headers={"Retry-After": "1"}
        )
    if job.status is not Status.DONE:
        raise Problem(409, f"job_{job.status.value}", f"the job {job.status.value}: no result")


#: The operation whose layout slot holds a manifest rather than a block layout.
WANG = "wang_tiles"


async def _layout(job: Job, service: Service) -> bytes:
    """A finished job's block layout (JSON; a Wang tile set's manifest), refused for a job
    without one."""
    _finished_result(job)
    if not job.has_layout:
        raise Problem(404, "no_layout", _NO_LAYOUT.get(job.operation, _NO_LAYOUT["matte"]))
    return _kept(await service.jobs.layout(job))


#: Why a job of each operation without a block layout has none.
_NO_LAYOUT = {
    "matte": "a matte job has no block layout of its result (each layer is quilted on its "
    "own, then mapped onto the surface)",
}


def _file_headers(job: Job, suffix: str, service: Service) -> dict[str, str]:
    """The headers of a finished job's file: its download name, and how long to keep it."""
    name = download_name(job.operation, job.download_stem, job.width, job.height, suffix)
    return {**attachment(name), "Cache-Control": service.file_cache}


def _kept(data: bytes | None) -> bytes:
    """A finished job's output, or 410 when it expired since the job was read."""
    if data is None:
        raise _expired()
    return data


@router.get(
    "/jobs/{job_id}/result",
    operation_id="get_result",
    summary="The result PNG",
    responses={200: {"content": {"image/png": {}}}, **FILE_PROBLEMS},
)
async def get_result(job: JobOf, service: ServiceDep) -> Response:
    _finished_result(job)
    data = _kept(await service.jobs.result(job))
    headers = {**_file_headers(job, ".png", service), **extracted_headers(job.stats)}
    return Response(data, media_type="image/png", headers=headers)


@router.get(
    "/jobs/{job_id}/result/{name}",
    operation_id="get_companion",
    summary="A quilted companion map",
    responses={200: {"content": {"image/png": {}}}, **FILE_PROBLEMS},
)
async def get_companion(job: JobOf, name: str, service: ServiceDep) -> Response:
    _finished_result(job)
    if name not in job.companion_names:
        raise Problem(404, "companion_not_found", f"job has no companion {name!r}")
    data = _kept(await service.jobs.result(job, name))
    headers = _file_headers(job, f"-{name}.png", service)
    return Response(data, media_type="image/png", headers=headers)


@router.get(
    "/jobs/{job_id}/layout",
    operation_id="get_layout",
    summary="The block layout (JSON); a Wang tile set's is its manifest",
    responses=FILE_PROBLEMS,
)
async def get_layout(job: JobOf, service: ServiceDep) -> Response:
    data = await _layout(job, service)
    headers = _file_headers(job, "-layout.json", service)
    return Response(data, media_type="application/json", headers=headers)


@router.get(
    "/jobs/{job_id}/manifest",
    operation_id="get_manifest",
    summary="A Wang tile set's manifest (JSON): each tile's place in the atlas and edge colours",
    description=(
        "The ``quilting.wang`` document of a ``POST /wang-tiles`` job: ``tile`` (the side in "
        "pixels), ``colors``, ``rows`` and ``columns`` of the atlas, ``edges`` "
        '(``["n", "e", "s", "w"]``), and ``tiles``: for each its ``index``, its top-left '
        "``x`` and ``y`` in the atlas and the colour of each edge (``n``, ``e``, ``s``, "
        "``w``); two tiles may touch where their touching edges' colours agree. ``meta`` "
        "holds the options that made the set. Any other job: 404 ``no_manifest``."
    ),
    responses=FILE_PROBLEMS,
)
async def get_manifest(job: JobOf, service: ServiceDep) -> Response:
    if job.operation != WANG:
        raise Problem(
            404,
            "no_manifest",
            f"a {job.operation} job has no Wang tile manifest (only POST /wang-tiles makes one)",
        )
    data = await _layout(job, service)
    headers = _file_headers(job, "-manifest.json", service)
    return Response(data, media_type="application/json", headers=headers)


@router.get(
    "/jobs/{job_id}/seams",
    operation_id="get_seams",
    summary="The seams between blocks, as a transparent PNG to lay over the result",
    responses={200: {"content": {"image/png": {}}}, **problems(401, 404, 409, 410, 422, 503)},
)
async def get_seams(
    job: JobOf,
    service: ServiceDep,
    color: Annotated[str, Query(description="Seam colour as six hex digits (RRGGBB).")] = "ff0000",
) -> Response:
    if not HEX_COLOR.match(color):
        raise Problem(
            422, "invalid_parameter", "color must be six hex digits (RRGGBB)", field="color"
        )
    layout = await _layout(job, service)
    if job.operation == WANG:
        raise Problem(
            404,
            "no_seams",
            "a Wang tile set has no seams between blocks to draw (its layout is the manifest "
            "of its tiles)",
        )
    png = await service.sandbox.run("seams", layout, color, doing="drawing the seams")
    headers = _file_headers(job, "-seams.png", service)
    return Response(png, media_type="image/png", headers=headers)


@router.get(
    "/jobs/{job_id}/events",
    operation_id="job_events",
    summary="Progress as server-sent events",
    description=(
        "A `progress` event whenever the job's progress or stage changes, then one event "
        "named after its final status (`done`, `failed`, `cancelled`) with the status "
        "document, and the stream ends. Every event has an `id:`, increasing over the "
        "job's life; a client that reconnects with `Last-Event-ID` gets only what came "
        "after it (and 204 No Content once it has had the final event)."
    ),
    responses={
        200: {"content": {"text/event-stream": {}}},
        204: {"description": "The final event was already sent (Last-Event-ID)"},
        **problems(401, 404, 422),
    },
)
async def job_events(
    job: JobOf,
    service: ServiceDep,
    last_event_id: Annotated[
        str | None,
        Header(description="The id of the last event received: resume after it."),
    ] = None,
) -> Response:
    after = resume_after(last_event_id)
    if job.status.final and after >= END_EVENT_ID:
        # The client has the end: 204 also tells an EventSource not to reconnect.
        return Response(status_code=204)
    return StreamingResponse(
        job_stream(service.jobs, job, after),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-cache"},
    )


@router.delete(
    "/jobs/{job_id}",
    operation_id="cancel_job",
    summary="Cancel a job",
    status_code=202,
    responses=problems(401, 404, 409, 422),
)
async def cancel_job(job: JobOf, service: ServiceDep) -> JSONResponse:
    if job.status in (Status.DONE, Status.FAILED):
        raise Problem(409, "job_finished", f"the job is already {job.status.value}")
    job = await service.jobs.cancel(job)
    return JSONResponse(job.snapshot(), status_code=202)
