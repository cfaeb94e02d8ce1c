"""Form parts, query parameters and answers the submission routes share."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import File, Form, Header, Query, UploadFile

from quilting.service.openapi import problems

CompanionParts = Annotated[
    list[UploadFile] | None,
    File(
        description="Companion maps of the texture's size, quilted with the same layout, named "
        "by their file name's stem. With several textures, each companion's map of every "
        "texture: the part repeated under the same name, once per texture, in their order "
        "(the k-th is of the k-th texture's size)."
    ),
]
#: The ``texture`` part of the routes that take several examples (repeated).
TextureParts = Annotated[
    list[UploadFile],
    File(
        description="The sample texture, PNG or JPEG. Repeat the part for several examples of "
        "one texture (each PNG or JPEG of the same channels and bit depth, any sizes, each at "
        "least the block; at most max_textures): blocks are drawn from all of them, in the "
        "order sent (the order of ``weights`` and of the layout's examples)."
    ),
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
SourceMaskParts = Annotated[
    list[UploadFile] | None,
    File(
        description="Mask of the texture's size: its black pixels are never used. With several "
        "textures, none or one per texture, in their order."
    ),
]
CompanionKindsField = Annotated[
    str | None,
    Form(
        description="JSON object {companion name: kind}: how each companion is rendered. "
        "'blend': blended like the result's pixels (the default); 'hard': never mixed, every "
        "pixel a source pixel (masks, material IDs; not with mode 'walk'); 'normal' (OpenGL, "
        "green up) or 'normal_dx' (DirectX, green down): blended, then renormalized to unit "
        "vectors (normal maps, 3 or 4 channels), their vectors turned with the blocks that "
        "transforms rotates or mirrors. Every name must be an uploaded companion's.",
    ),
]
WaitSeconds = Annotated[float | None, Query(ge=0, description="Seconds to wait for the result.")]
IdempotencyKey = Annotated[str | None, Header(max_length=256)]

SUBMIT_RESPONSES: dict[int | str, dict[str, Any]] = {
    200: {"content": {"image/png": {}}, "description": "The result (job done in time)"},
    202: {"description": "Job accepted; follow Location"},
    **problems(401, 409, 413, 415, 422, 503),
}
