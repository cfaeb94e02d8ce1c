"""Form parts, query parameters and answers the submission routes share."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import File, Form, Header, Query, UploadFile

from quilting.service.openapi import problems

CompanionParts = Annotated[
    list[UploadFile] | None,
    File(description="Companion maps of the texture's size, quilted with the same layout."),
]
ImageCompanionParts = Annotated[
    list[UploadFile] | None,
    File(
        description="Companion maps of the image's size (normals, roughness...), named by their "
        "file name's stem, filled the same way: each filled pixel copied from where the image's "
        "came from. Each is a file of the job (GET /jobs/{id}/result/{name})."
    ),
]
SourceMaskPart = Annotated[
    UploadFile | None,
    File(description="Mask of the texture's size: its black pixels are never used."),
]
CompanionKindsField = Annotated[
    str | None,
    Form(
        description="JSON object {companion name: kind}: how each companion is rendered. "
        "'blend': blended like the result's pixels (the default); 'hard': never mixed, every "
        "pixel a source pixel (masks, material IDs; not with mode 'walk'); 'normal': blended, "
        "then renormalized to unit vectors (normal maps, 3 or 4 channels). Every name must be "
        "an uploaded companion's.",
    ),
]
WaitSeconds = Annotated[float | None, Query(ge=0, description="Seconds to wait for the result.")]
IdempotencyKey = Annotated[str | None, Header(max_length=256)]

SUBMIT_RESPONSES: dict[int | str, dict[str, Any]] = {
    200: {"content": {"image/png": {}}, "description": "The result (job done in time)"},
    202: {"description": "Job accepted; follow Location"},
    **problems(401, 409, 413, 415, 422, 503),
}
