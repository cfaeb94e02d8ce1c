"""``POST /transfer``: a target image rendered in the texture of a sample."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, File, Form, UploadFile
from fastapi.responses import Response

from quilting.service import forms
from quilting.service.deps import SingleParts, Submitter
from quilting.service.routes.parts import (
    SUBMIT_RESPONSES,
    CompanionKindsField,
    CompanionParts,
    SourceMaskPart,
)
from quilting.service.submit import texture_parts

router = APIRouter()


@router.post(
    "/transfer",
    operation_id="transfer",
    dependencies=SingleParts,
    summary="Render a target image in the texture of a sample (texture transfer)",
    responses=SUBMIT_RESPONSES,
)
async def transfer_endpoint(
    submitting: Submitter,
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
) -> Response:
    parsed = forms.transfer_options(options, submitting.models.transfer)
    parts = await texture_parts(
        texture, companion, companion_kinds, source_mask, submitting.settings, target=target
    )
    submission = forms.Submission("transfer", parsed, **parts)
    return await submitting.submit(submission)
