"""A submission's way into the queue: its uploads read and checked from their first bytes,
its input checked from the images' headers here and from their pixels in the sandbox, its
cost predicted, the job queued (or its idempotent twin found), and the answer: the PNG when
the job is done within the wait, else 202 and where to follow it."""

from __future__ import annotations

import dataclasses
from typing import Any

import anyio
from fastapi import UploadFile
from fastapi.responses import JSONResponse, Response

from quilting.io import image_format
from quilting.service import forms
from quilting.service.budgets import predicted
from quilting.service.context import Service
from quilting.service.downloads import attachment, download_name, extracted_headers, job_stem
from quilting.service.forms import COMPANION_NAME, JobOptions, Submission
from quilting.service.jobs import Job, JobInput, Status, new_job_id
from quilting.service.problems import Problem
from quilting.service.settings import Settings
from quilting.service.uploads import check_headers


async def read_upload(upload: UploadFile, field: str, settings: Settings) -> bytes:
    """An upload's bytes: 413 over ``max_file_bytes``, 415 unless PNG or JPEG."""
    if upload.size is not None and upload.size > settings.max_file_bytes:
        raise Problem(
            413,
            "file_too_large",
            f"{field} is {upload.size} bytes; the limit is {settings.max_file_bytes} "
            "(max_file_bytes)",
            field=field,
        )
    data = await upload.read()
    if image_format(data[:8]) is None:
        raise Problem(
            415,
            "unsupported_media_type",
            f"{field} must be a PNG or JPEG image (recognized from its bytes)",
            field=field,
        )
    return data


async def read_optional(upload: UploadFile | None, field: str, settings: Settings) -> bytes | None:
    return None if upload is None else await read_upload(upload, field, settings)


async def read_marks(
    parts: list[UploadFile | str] | None, count: int, field: str, of: str, settings: Settings
) -> list[bytes | None]:
    """The ``trimap`` (or ``scribbles``) parts of a submission, one per photo (``of``: per
    ``"texture"``, per ``"layer"``): none, or exactly ``count``, an empty part (no bytes)
    standing for a photo without one; checked and read. Empty when none has a map.

    Raises
    ------
    Problem
        422 ``invalid_trimap`` naming ``field`` for a count that is not ``count``; as
        :func:`read_upload` for each part with bytes.
    """
    if not parts:
        return []
    if len(parts) != count:
        raise Problem(
            422,
            "invalid_trimap",
            f"{len(parts)} {field} parts for {count} {of} parts: send none, or one per {of}, in "
            f"the {of}s' order (an empty part for a {of} without one)",
            field=field,
        )
    found: list[bytes | None] = []
    for part in parts:
        if isinstance(part, str):  # a field, not a file: sent without a file name
            if part:
                raise Problem(
                    422,
                    "invalid_trimap",
                    f"a {field} part is a PNG file, or empty for a {of} without one",
                    field=field,
                )
            found.append(None)
        else:
            found.append(None if part.size == 0 else await read_upload(part, field, settings))
    return found if any(data is not None for data in found) else []


async def read_companions(parts: list[UploadFile] | None, settings: Settings) -> dict[str, bytes]:
    """Companion uploads by name (their file name's stem), checked and read."""
    return {name: maps[0] for name, maps in (await _companion_maps(parts, 1, settings)).items()}


async def _companion_maps(
    parts: list[UploadFile] | None, per_name: int, settings: Settings
) -> dict[str, list[bytes]]:
    """Companion uploads by name (their file name's stem), each name sent ``per_name`` times
    (once per example, in the examples' order), checked and read."""
    maps: dict[str, list[bytes]] = {}
    for part in parts or []:
        name = (part.filename or "").rsplit("/", 1)[-1].rsplit(".", 1)[0]
        if not COMPANION_NAME.match(name) or len(maps.get(name, ())) >= per_name:
            raise Problem(
                422,
                "invalid_companion",
                "companion file names must be unique stems of [A-Za-z0-9_-]"
                + (f", each sent once per texture ({per_name})" if per_name > 1 else "")
                + f", got {part.filename!r}",
                field="companion",
            )
        maps.setdefault(name, []).append(await read_upload(part, "companion", settings))
    if len(maps) > settings.max_companions:
        raise Problem(
            422,
            "invalid_companion",
            f"at most {settings.max_companions} companions (max_companions)",
            field="companion",
        )
    for name, found in maps.items():
        if len(found) != per_name:
            raise Problem(
                422,
                "invalid_companion",
                f"companion {name!r} was sent {len(found)} time{'s' if len(found) > 1 else ''}; "
                f"with {per_name} textures "
                "each companion is sent once per texture, the k-th part of a name being the "
                "map of the k-th texture",
                field="companion",
            )
    return maps


def count_examples(
    textures: list[UploadFile],
    masks: list[UploadFile] | None,
    options: JobOptions,
    settings: Settings,
) -> None:
    """The checks of a submission of several examples that need only the parts' count, made
    before any is read: at most ``max_textures`` textures (422 ``too_many_textures``), a
    source mask per texture or none (422 ``invalid_source_mask``), a weight per texture or
    none (422 ``invalid_parameter`` naming ``weights``)."""
    if len(textures) > settings.max_textures:
        raise Problem(
            422,
            "too_many_textures",
            f"{len(textures)} textures; at most {settings.max_textures} (max_textures)",
            field="texture",
        )
    if masks and len(masks) != len(textures):
        raise Problem(
            422,
            "invalid_source_mask",
            f"{len(masks)} source_mask parts for {len(textures)} texture parts: send none, or "
            "one per texture, in the textures' order",
            field="source_mask",
        )
    forms.examples_fit(options, len(textures))


async def example_parts(
    textures: list[UploadFile],
    companion: list[UploadFile] | None,
    companion_kinds: str | None,
    source_masks: list[UploadFile] | None,
    settings: Settings,
    trimap: list[UploadFile | str] | None = None,
    scribbles: list[UploadFile | str] | None = None,
) -> dict[str, Any]:
    """The :class:`Submission` fields of a job of one or several examples (a synthesis, a
    Wang tile set): the textures, their companions (each name once per texture, in their
    order) and kinds, their source masks (none, or one per texture), and their trimaps and
    scribbles (likewise, an empty part for none), read and checked in that order. One
    texture gives exactly the fields of a job of one texture."""
    data = [await read_upload(part, "texture", settings) for part in textures]
    maps = await _companion_maps(companion, len(data), settings)
    masks = [await read_upload(part, "source_mask", settings) for part in source_masks or []]
    companions = {name: found[0] for name, found in maps.items()}
    parts: dict[str, Any] = {
        "texture": data[0],
        "texture_name": textures[0].filename,
        "companions": companions,
        "source_mask": masks[0] if masks else None,
        "companion_kinds": forms.companion_kinds(companion_kinds, companions),
        "trimaps": await read_marks(trimap, len(data), "trimap", "texture", settings),
        "scribbles": await read_marks(scribbles, len(data), "scribbles", "texture", settings),
    }
    if len(data) > 1:
        parts.update(examples=data, source_masks=masks, example_companions=maps)
    return parts


async def texture_parts(
    texture: UploadFile,
    companion: list[UploadFile] | None,
    companion_kinds: str | None,
    source_mask: UploadFile | None,
    settings: Settings,
    target: UploadFile | None = None,
) -> dict[str, Any]:
    """The :class:`Submission` fields of a synthesis or a transfer: the texture (and the
    target), its companions and their kinds, and the source mask, read and checked in that
    order (the first bad part is the one refused)."""
    parts: dict[str, Any] = {
        "texture": await read_upload(texture, "texture", settings),
        "texture_name": texture.filename,
    }
    if target is not None:
        parts["target"] = await read_upload(target, "target", settings)
        parts["target_name"] = target.filename
    parts["companions"] = companions = await read_companions(companion, settings)
    parts["source_mask"] = await read_optional(source_mask, "source_mask", settings)
    parts["companion_kinds"] = forms.companion_kinds(companion_kinds, companions)
    return parts


async def checked_input(submission: Submission, service: Service) -> JobInput:
    """The job's input: the uploads as they came, checked from their headers here and from
    their pixels in the sandbox, with the output's size."""
    size = submission.size or (0, 0)  # a transfer's and a matte's: its target's; a fill's,
    # an extension's and an extraction's: from their image's header; a Wang tile set's: its
    # atlas's
    spec = JobInput(
        submission.texture,
        dict(submission.companions),
        submission.options.to_dict(),
        size[0],
        size[1],
        operation=submission.operation,
        limits=service.limits,
        **submission.job_files(),
    )
    # Milliseconds, the 422s of most bad uploads; in a thread all the same, so that the
    # chunk walk of a large file never holds the event loop for more than a GIL switch.
    width, height = await anyio.to_thread.run_sync(check_headers, spec)
    spec = dataclasses.replace(spec, width=width, height=height)
    # The cost model needs the shapes only: a job over budget never reaches a process (but a
    # fill, whose cost follows its hole: the sandbox predicts it from the decoded mask).
    await anyio.to_thread.run_sync(predicted, spec, submission.options, service.job_budget)
    width, height = await service.sandbox.run(
        "check", spec, submission.options, service.job_budget, doing="reading the uploads"
    )
    return dataclasses.replace(spec, width=width, height=height)


async def submit(
    submission: Submission,
    service: Service,
    key: str | None,
    idempotency_key: str | None,
    wait_s: float,
) -> Response:
    """Check, queue (or find the idempotent twin), wait up to ``wait_s`` and answer."""
    jobs = service.jobs
    digest = submission.digest()
    spec = await checked_input(submission, service)
    stem = job_stem(
        submission.operation,
        submission.texture_name,
        submission.target_name,
        spec.width,
        spec.height,
        getattr(submission.options, "seed", None),  # an extraction has none
    )
    job = Job(
        id=new_job_id(),
        owner=key,
        width=spec.width,
        height=spec.height,
        companion_names=spec.outputs,
        input=spec,
        operation=submission.operation,
        download_stem=stem,
    )
    job, _ = await jobs.submit(job, (idempotency_key, digest) if idempotency_key else None)
    if wait_s > 0:
        job = await jobs.wait(job, wait_s)
    location = {"Location": f"/jobs/{job.id}", "X-Job-Id": job.id}
    if job.status is Status.DONE and (png := await jobs.result(job)) is not None:
        name = download_name(job.operation, job.download_stem, job.width, job.height, ".png")
        headers = {**location, **attachment(name), **extracted_headers(job.stats)}
        return Response(png, media_type="image/png", headers=headers)
    return JSONResponse(job.snapshot(), status_code=202, headers={**location, "Retry-After": "1"})
