"""``POST /wang-tiles``: a complete set of Wang tiles quilted from a sample (or several
examples of one), answered with the atlas of its tiles; the manifest that says each tile's
place and edge colours is the job's ``/jobs/{id}/manifest``."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Form
from fastapi.responses import Response

from quilting.service import forms
from quilting.service.deps import ExampleParts, Submitter
from quilting.service.routes.parts import (
    SUBMIT_RESPONSES,
    TextureParts,
)
from quilting.service.submit import count_examples, example_parts

router = APIRouter()


@router.post(
    "/wang-tiles",
    operation_id="wang_tiles",
    dependencies=ExampleParts,
    summary="Make a complete set of Wang tiles from a sample (the atlas PNG)",
    description=(
        "Every edge of a tile carries one of ``colors`` colours and the set has a tile for "
        "every combination (``colors``^4 tiles, Cohen, Shade, Hiller and Deussen 2003): two "
        "tiles whose touching edges share a colour meet seamlessly, so any arrangement that "
        "keeps the edge rule (drawn at random, it is aperiodic) tiles the plane. The answer "
        "is the atlas: every tile in one PNG of ``colors``^2 x ``colors``^2 tiles, tile k at "
        "row k // ``colors``^2, column k % ``colors``^2. ``GET /jobs/{id}/manifest`` (the "
        "job is named by ``X-Job-Id`` and ``Location``, on a 200 as on a 202) gives each "
        "tile's place in the atlas and its north, east, south and west colours."
    ),
    responses=SUBMIT_RESPONSES,
)
async def wang_tiles_endpoint(
    submitting: Submitter,
    texture: TextureParts,
    options: Annotated[
        str,
        Form(description="JSON object, schema WangOptions (every member optional)."),
    ] = "{}",
) -> Response:
    settings = submitting.settings
    parsed = forms.wang_options(options, submitting.models.wang_tiles, settings)
    count_examples(texture, None, parsed, settings)
    parts = await example_parts(texture, None, None, None, settings)
    side = parsed.colors**2 * parsed.tile
    submission = forms.Submission("wang_tiles", parsed, size=(side, side), **parts)
    return await submitting.submit(submission)
