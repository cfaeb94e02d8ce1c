"""``POST /transfer``: a target image rendered in the texture of a sample."""

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
    "/transfer",
    operation_id="transfer",
    dependencies=SingleParts,
    summary="Render a target image in the texture of a sample (texture transfer)",
    responses=SUBMIT_RESPONSES,
)
async def transfer_endpoint(
    request: Request,
    service: ServiceDep,
    key: Owner,
    texture: Annotated[UploadFile, File(description="The texture to render with, PNG or JPEG.")],
    target: Annotated[
        UploadFile,
        File(description="The image to render, PNG or JPEG; the output has its size."),
    ],
    options: Annotated[
        str,
        Form(description="JSON object, schema TransferOptions (every member optional)."),
    ] = "{}",
    companion: CompanionParts = None,
    companion_kinds: CompanionKindsField = None,
    source_mask: SourceMaskPart = None,
    wait: WaitSeconds = None,
    idempotency_key: IdempotencyKey = None,
) -> Response:
    settings = service.settings
    wait_s = accepting(request, wait)
    parsed = forms.transfer_options(options, service.models.transfer)
    submission = forms.Submission(
        "transfer",
        parsed,
        texture=await read_upload(texture, "texture", settings),
        target=await read_upload(target, "target", settings),
        companions=(companions := await read_companions(companion, settings)),
        source_mask=await read_optional(source_mask, "source_mask", settings),
        texture_name=texture.filename,
        target_name=target.filename,
        companion_kinds=forms.companion_kinds(companion_kinds, companions),
    )
    return await submit(submission, service, key, idempotency_key, wait_s)
