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
from quilting.service.submit import read_companions, read_optional, read_upload, submit

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
    submission = forms.Submission(
        "synthesize",
        parsed,
        texture=await read_upload(texture, "texture", settings),
        companions=(companions := await read_companions(companion, settings)),
        source_mask=await read_optional(source_mask, "source_mask", settings),
        size=(width, height),
        texture_name=texture.filename,
        companion_kinds=forms.companion_kinds(companion_kinds, companions),
    )
    return await submit(submission, service, key, idempotency_key, wait_s)
