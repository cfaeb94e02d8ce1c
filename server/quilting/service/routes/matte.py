"""``POST /matte``: textures laid on the surface of an object in an image."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, File, Form, UploadFile
from fastapi.responses import Response

from quilting.options import MatteOptions
from quilting.service import forms
from quilting.service.deps import LayerParts, Submitter
from quilting.service.problems import Problem
from quilting.service.routes.parts import (
    EXTRACTING_RESPONSES,
    LayerScribblesParts,
    LayerTrimapParts,
)
from quilting.service.submit import read_marks, read_optional, read_upload

router = APIRouter()


@router.post(
    "/matte",
    operation_id="matte",
    dependencies=LayerParts,
    summary="Lay textures on the surface of an object in an image (texture matting)",
    description=(
        "A layer that is an ordinary photo (no alpha) sent with a ``trimap`` or "
        "``scribbles`` part has its alpha extracted first (as ``/extract-alpha`` does, "
        "``options.matting``) and is alpha-quilted; the ``Quilting-Extracted`` header of "
        "the result says how."
    ),
    responses=EXTRACTING_RESPONSES,
)
async def matte_endpoint(
    submitting: Submitter,
    target: Annotated[
        UploadFile,
        File(description="The image with the object, PNG or JPEG; the output has its size."),
    ],
    silhouette: Annotated[
        UploadFile,
        File(
            description="The target's size: white (or opaque) where the surface is, black "
            "(or transparent) elsewhere."
        ),
    ],
    layer: Annotated[
        list[UploadFile],
        File(
            description="The textures to lay on the surface, bottom first (repeat the "
            "part); RGBA ones are alpha-quilted."
        ),
    ],
    options: Annotated[
        str,
        Form(description="JSON object, schema MatteOptions (every member optional)."),
    ] = "{}",
    normals: Annotated[
        UploadFile | None,
        File(
            description="A normal map of the target's size ((n + 1) / 2 colours, +y up) "
            "used instead of the one read from the shading."
        ),
    ] = None,
    trimap: LayerTrimapParts = None,
    scribbles: LayerScribblesParts = None,
) -> Response:
    settings = submitting.settings
    values = forms.validate(forms.options_object(options), submitting.models.matte)
    parsed = forms.engine_options(values, MatteOptions)
    if len(layer) > settings.max_layers:
        raise Problem(
            422,
            "too_many_layers",
            f"{len(layer)} layers; at most {settings.max_layers} (max_layers)",
            field="layer",
        )
    layers = [await read_upload(part, "layer", settings) for part in layer]
    trimaps = await read_marks(trimap, len(layers), "trimap", "layer", settings)
    strokes = await read_marks(scribbles, len(layers), "scribbles", "layer", settings)
    submission = forms.Submission(
        "matte",
        parsed,
        texture=layers[0],
        companions={},
        target=await read_upload(target, "target", settings),
        layers=layers,
        silhouette=await read_upload(silhouette, "silhouette", settings),
        normals=await read_optional(normals, "normals", settings),
        texture_name=layer[0].filename,
        target_name=target.filename,
        trimaps=trimaps,
        scribbles=strokes,
    )
    return await submitting.submit(submission)
