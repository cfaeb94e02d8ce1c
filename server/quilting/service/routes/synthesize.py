"""``POST /synthesize``: a texture of any size from a sample (or several examples of one)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Form
from fastapi.responses import Response

from quilting.service import forms
from quilting.service.deps import ExampleParts, Submitter
from quilting.service.routes.parts import (
    EXTRACTING_RESPONSES,
    CompanionKindsField,
    CompanionParts,
    ScribblesParts,
    SourceMaskParts,
    TextureParts,
    TrimapParts,
)
from quilting.service.submit import count_examples, example_parts

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
        "records each block's example and transform. A texture that is an ordinary photo "
        "(no alpha) sent with a ``trimap`` or ``scribbles`` part has its alpha extracted "
        "first (as ``/extract-alpha`` does, ``options.matting``) and is alpha-quilted; the "
        "``Quilting-Extracted`` header of the result says how."
    ),
    responses=EXTRACTING_RESPONSES,
)
async def synthesize_endpoint(
    submitting: Submitter,
    texture: TextureParts,
    options: Annotated[
        str,
        Form(description="JSON object, schema SynthesizeOptions (width and height required)."),
    ],
    companion: CompanionParts = None,
    companion_kinds: CompanionKindsField = None,
    source_mask: SourceMaskParts = None,
    trimap: TrimapParts = None,
    scribbles: ScribblesParts = None,
) -> Response:
    settings = submitting.settings
    width, height, parsed = forms.synthesis_options(options, submitting.models.synthesize, settings)
    count_examples(texture, source_mask, parsed, settings)
    parts = await example_parts(
        texture, companion, companion_kinds, source_mask, settings, trimap, scribbles
    )
    submission = forms.Submission("synthesize", parsed, size=(width, height), **parts)
    return await submitting.submit(submission)
