"""Form parts, query parameters and answers the submission routes share."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import File, Form, UploadFile

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
#: What a trimap and scribbles are, said once for every route that takes them.
_MARKS = (
    "white where the photo is surely foreground (kept, alpha 1), black where surely "
    "background (left out, alpha 0)"
)
TRIMAP = (
    "A trimap of the photo's size, PNG: " + _MARKS + ", grey (or any other colour) where the "
    "alpha is to be found."
)
SCRIBBLES = (
    "Scribbles of the photo's size, PNG: a few white (foreground) and black (background) "
    "strokes, the rest unknown (transparent, or grey); drawn over the trimap when both come."
)
#: The ``trimap`` and ``scribbles`` parts of ``/synthesize``: one per texture.
TrimapParts = Annotated[
    list[UploadFile | str] | None,
    File(
        description=TRIMAP + " The texture is then an ordinary photo (no alpha): its alpha and "
        "foreground colour are extracted first (options.matting) and the RGBA texture "
        "is alpha-quilted. With several textures, none or one per texture, in their order "
        "(an empty part for a texture without one)."
    ),
]
ScribblesParts = Annotated[
    list[UploadFile | str] | None,
    File(
        description=SCRIBBLES + " Instead of (or with) a trimap, as ``trimap`` says: none or "
        "one per texture, in their order (an empty part for a texture without one)."
    ),
]
#: The ``trimap`` and ``scribbles`` parts of ``/matte``: one per layer.
LayerTrimapParts = Annotated[
    list[UploadFile | str] | None,
    File(
        description=TRIMAP + " The layer is then an ordinary photo (no alpha): its alpha and "
        "foreground colour are extracted first (options.matting) and it is alpha-quilted. "
        "None, or one per ``layer`` part in the layers' order, an empty part (no bytes) for a "
        "layer taken as it is."
    ),
]
LayerScribblesParts = Annotated[
    list[UploadFile | str] | None,
    File(
        description=SCRIBBLES + " Instead of (or with) a trimap, as ``trimap`` says: none, or "
        "one per ``layer`` part in the layers' order, an empty part for a layer without."
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

SUBMIT_RESPONSES: dict[int | str, dict[str, Any]] = {
    200: {"content": {"image/png": {}}, "description": "The result (job done in time)"},
    202: {"description": "Job accepted; follow Location"},
    **problems(401, 409, 413, 415, 422, 503),
}
#: The answers of a submission that may extract an alpha first: its result carries the
#: extraction's summary in a header (:data:`quilting.service.submit.EXTRACTED_HEADER`).
EXTRACTING_RESPONSES: dict[int | str, dict[str, Any]] = {
    **SUBMIT_RESPONSES,
    200: {
        **SUBMIT_RESPONSES[200],
        "headers": {
            "Quilting-Extracted": {
                "description": "Sent when an alpha was extracted from a photo first (a "
                "trimap or scribbles came): the extraction's summary as compact JSON, an "
                "array of one entry per photo (texture, layer), null for one without, each "
                "{method, foreground, unknown, iterations, seconds}.",
                "schema": {"type": "string"},
            }
        },
    },
}
