"""``POST /synthesize``: a texture of any size from a sample (or several examples of one)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Form, Request
from fastapi.responses import Response

from quilting.service import forms
from quilting.service.deps import ExampleParts, Owner, ServiceDep, accepting
from quilting.service.routes.parts import (
    SUBMIT_RESPONSES,
    CompanionKindsField,
    CompanionParts,
    IdempotencyKey,
    SourceMaskParts,
    TextureParts,
    WaitSeconds,
)
from quilting.service.submit import count_examples, example_parts, submit

router = APIRouter()


@router.post(
    "/synthesize",
    operation_id="synthesize",
    dependencies=ExampleParts,
    summary="Synthesize a texture of any size from a sample",
    description=(
        "The ``texture`` part may repeat: several examples of one texture, quilted together "
        "(the best block across all of them is chosen; ``weights`` prefers some, "
        "``transforms`` adds their rotations and mirrors). The layout (``/jobs/{id}/layout``) "
        "records each block's example and transform."
    ),
    responses=SUBMIT_RESPONSES,
)
async def synthesize_endpoint(
    request: Request,
    service: ServiceDep,
    key: Owner,
    texture: TextureParts,
    options: Annotated[
        str,
        Form(description="JSON object, schema SynthesizeOptions (width and height required)."),
    ],
    companion: CompanionParts = None,
    companion_kinds: CompanionKindsField = None,
    source_mask: SourceMaskParts = None,
    wait: WaitSeconds = None,
    idempotency_key: IdempotencyKey = None,
) -> Response:
    settings = service.settings
    wait_s = accepting(request, wait)
    width, height, parsed = forms.synthesis_options(options, service.models.synthesize, settings)
    count_examples(texture, source_mask, parsed, settings)
    parts = await example_parts(texture, companion, companion_kinds, source_mask, settings)
    submission = forms.Submission("synthesize", parsed, size=(width, height), **parts)
    return await submit(submission, service, key, idempotency_key, wait_s)
