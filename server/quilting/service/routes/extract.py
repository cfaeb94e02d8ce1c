"""``POST /extract-alpha``: an RGBA texture from an ordinary photo and a trimap or scribbles
(the first step of alpha quilting), nothing quilted."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, File, Form, UploadFile
from fastapi.responses import Response

from quilting.service import forms
from quilting.service.deps import SingleParts, Submitter
from quilting.service.extract_uploads import no_marks
from quilting.service.jobs.job_input import EXTRACT
from quilting.service.routes.parts import (
    EXTRACTING_RESPONSES,
    SCRIBBLES,
    TRIMAP,
)
from quilting.service.submit import read_optional, read_upload

router = APIRouter()


@router.post(
    "/extract-alpha",
    operation_id="extract_alpha",
    dependencies=SingleParts,
    summary="Extract the alpha and foreground colour of an ordinary photo (ice, smoke, leaves)",
    description=(
        "The photo's alpha is found where the trimap (or the scribbles) leaves it unknown, by "
        "a natural-image matting solver (options.method), and its foreground colour is "
        "estimated under it (options.foreground), so that the background showing through "
        "semi-transparent pixels does not stay in the texture. The result is the RGBA "
        "texture, the photo's size and bit depth, ready for ``mode=alpha`` of "
        "``/synthesize`` or a ``/matte`` layer (which can also take the photo and its "
        "trimap directly). A trimap or scribbles part is needed."
    ),
    responses=EXTRACTING_RESPONSES,
)
async def extract_alpha_endpoint(
    submitting: Submitter,
    photo: Annotated[
        UploadFile,
        File(description="The photo, PNG or JPEG, gray or RGB (no alpha channel)."),
    ],
    trimap: Annotated[UploadFile | None, File(description=TRIMAP)] = None,
    scribbles: Annotated[UploadFile | None, File(description=SCRIBBLES)] = None,
    options: Annotated[
        str,
        Form(description="JSON object, schema AlphaOptions (every member optional)."),
    ] = "{}",
) -> Response:
    settings = submitting.settings
    parsed = forms.alpha_options(options, submitting.models.extract_alpha)
    photo_data = await read_upload(photo, "photo", settings)
    trimap_data = await read_optional(trimap, "trimap", settings)
    scribbles_data = await read_optional(scribbles, "scribbles", settings)
    if trimap_data is None and scribbles_data is None:
        raise no_marks()
    submission = forms.Submission(
        EXTRACT,
        parsed,
        texture=photo_data,
        companions={},
        trimaps=[trimap_data],
        scribbles=[scribbles_data],
        texture_name=photo.filename,
    )
    return await submitting.submit(submission)
