"""``POST /fill`` and ``POST /extend``: the masked pixels of an image synthesized again from
the rest of it (inpainting), and an image grown past its borders (uncropping)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, File, Form, UploadFile
from fastapi.responses import Response

from quilting.service import forms
from quilting.service.deps import SingleParts, Submitter
from quilting.service.problems import Problem
from quilting.service.routes.parts import (
    SUBMIT_RESPONSES,
    ImageCompanionParts,
)
from quilting.service.submit import read_companions, read_optional, read_upload

router = APIRouter()


@router.post(
    "/fill",
    operation_id="fill",
    dependencies=SingleParts,
    summary="Fill the masked pixels of an image (remove an object, a stain, a logo)",
    description=(
        "The pixels the mask marks are synthesized again by image quilting: blocks of the "
        "image outside the hole (or of the texture) matched on every known pixel under "
        "them, joined along minimum cuts. Every pixel outside the mask is returned as it "
        "came, byte for byte, at the image's bit depth."
    ),
    responses=SUBMIT_RESPONSES,
)
async def fill_endpoint(
    submitting: Submitter,
    image: Annotated[
        UploadFile, File(description="The image to fill, PNG or JPEG; the output has its size.")
    ],
    mask: Annotated[
        UploadFile,
        File(
            description="The image's size, PNG (JPEG's noise would mark pixels): white (any "
            "colour above 0) where to fill, black where to keep; with alpha, a transparent "
            "pixel is kept. An empty mask returns the image as it is."
        ),
    ],
    options: Annotated[
        str,
        Form(description="JSON object, schema FillOptions (every member optional)."),
    ] = "{}",
    texture: Annotated[
        UploadFile | None,
        File(
            description="Take the blocks from this texture instead of the image (the image's "
            "channels and bit depth); needed when the mask covers the whole image."
        ),
    ] = None,
    companion: ImageCompanionParts = None,
) -> Response:
    settings = submitting.settings
    parsed = forms.fill_options(options, submitting.models.fill)
    image_data = await read_upload(image, "image", settings)
    mask_data = await read_upload(mask, "mask", settings)
    source = await read_optional(texture, "texture", settings)
    companions = await read_companions(companion, settings)
    if companions and source is not None:
        raise Problem(
            422,
            "invalid_companion",
            "companions cannot be filled from a texture (the texture's own companions would "
            "be needed, which this endpoint does not take): fill without a texture, or "
            "fill the companions in jobs of their own",
            field="companion",
        )
    submission = forms.Submission(
        "fill",
        parsed,
        texture=image_data,
        companions=companions,
        mask=mask_data,
        source=source,
        texture_name=image.filename,
    )
    return await submitting.submit(submission)


@router.post(
    "/extend",
    operation_id="extend",
    dependencies=SingleParts,
    summary="Grow an image past its borders (uncrop)",
    description=(
        "A larger canvas, the image placed unchanged (byte for byte) ``left`` pixels from "
        "its left and ``top`` from its top, and the added border synthesized from the image "
        "by image quilting, as ``/fill`` fills a hole."
    ),
    responses=SUBMIT_RESPONSES,
)
async def extend_endpoint(
    submitting: Submitter,
    image: Annotated[UploadFile, File(description="The image to extend, PNG or JPEG.")],
    options: Annotated[
        str,
        Form(
            description="JSON object, schema ExtendOptions: top, bottom, left, right (pixels "
            "added on each side) and the fill's options; every member optional."
        ),
    ] = "{}",
    companion: ImageCompanionParts = None,
) -> Response:
    settings = submitting.settings
    parsed = forms.extend_options(options, submitting.models.extend)
    image_data = await read_upload(image, "image", settings)
    companions = await read_companions(companion, settings)
    submission = forms.Submission(
        "extend", parsed, texture=image_data, companions=companions, texture_name=image.filename
    )
    return await submitting.submit(submission)
