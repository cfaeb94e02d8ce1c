"""``POST /synthesize``: a texture of any size from a sample."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, File, Form, Request, UploadFile
from fastapi.responses import Response

from quilting.service import forms
from quilting.service.deps import Owner, ServiceDep, SingleParts, accepting
from quilting.service.routes.parts import (
    SUBMIT_RESPONSES,
    CompanionKindsField,
    CompanionParts,
    IdempotencyKey,
    SourceMaskPart,
    WaitSeconds,
)
from quilting.service.submit import submit, texture_parts

router = APIRouter()


@router.post(
    "/synthesize",
    operation_id="synthesize",
    dependencies=SingleParts,
    summary="Synthesize a texture of any size from a sample",
    responses=SUBMIT_RESPONSES,
)
async def synthesize_endpoint(
    request: Request,
    service: ServiceDep,
    key: Owner,
    texture: Annotated[UploadFile, File(description="The sample texture, PNG or JPEG.")],
    options: Annotated[
        str,
        Form(description="JSON object, schema SynthesizeOptions (width and height required)."),
    ],
    companion: CompanionParts = None,
    companion_kinds: CompanionKindsField = None,
    source_mask: SourceMaskPart = None,
    wait: WaitSeconds = None,
    idempotency_key: IdempotencyKey = None,
) -> Response:
    settings = service.settings
    wait_s = accepting(request, wait)
    width, height, parsed = forms.synthesis_options(options, service.models.synthesize, settings)
    parts = await texture_parts(texture, companion, companion_kinds, source_mask, settings)
    submission = forms.Submission("synthesize", parsed, size=(width, height), **parts)
    return await submit(submission, service, key, idempotency_key, wait_s)
