"""``POST /tile``: an existing image made to repeat seamlessly, answered at once (the work
runs in the sandbox under its time and memory limit)."""

from __future__ import annotations

from typing import Annotated

import anyio
from fastapi import APIRouter, File, Form, Request, UploadFile
from fastapi.responses import Response

from quilting import QuiltingError
from quilting.options import TileOptions
from quilting.service import forms
from quilting.service.budgets import predicted_tile
from quilting.service.deps import Owner, ServiceDep, SingleParts, refuse_while_draining
from quilting.service.downloads import attachment, tile_name
from quilting.service.openapi import problems
from quilting.service.problems import from_engine
from quilting.service.submit import read_upload
from quilting.service.upload_images import check_image_header

router = APIRouter()


@router.post(
    "/tile",
    operation_id="tile",
    dependencies=SingleParts,
    summary="Make an existing image repeat seamlessly (same size, centre kept)",
    responses={
        200: {"content": {"image/png": {}}, "description": "The tileable image"},
        **problems(401, 413, 415, 422, 503),
    },
)
async def tile_endpoint(
    request: Request,
    service: ServiceDep,
    key: Owner,
    image: Annotated[UploadFile, File(description="The image to make tileable, PNG or JPEG.")],
    options: Annotated[
        str,
        Form(description="JSON object, schema TileOptions (every member optional)."),
    ] = "{}",
) -> Response:
    refuse_while_draining(request)
    values = forms.validate(forms.options_object(options), service.models.tile)
    try:
        parsed = TileOptions(**values)
    except QuiltingError as exc:
        raise from_engine(exc) from None
    data = await read_upload(image, "image", service.settings)
    limits = service.limits
    # The header first (milliseconds, here): a bomb or a broken file is refused at once.
    await anyio.to_thread.run_sync(check_image_header, data, "image", limits)
    # ... and its cost: an image the sandbox could not tile in its budget is refused here.
    await anyio.to_thread.run_sync(
        predicted_tile, data, service.tile_budget, parsed.blend, parsed.method
    )
    png = await service.sandbox.run("tile", data, parsed, limits, doing="making the image tileable")
    return Response(png, media_type="image/png", headers=attachment(tile_name(image.filename)))
