"""The OpenAPI document: problem answers declared on each route, and the schemas FastAPI
cannot see (the ``options`` form field is JSON text, its schema one of the generated models;
the problem body) published as components."""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI

from quilting.service.context import Models
from quilting.service.handlers import PROBLEM_JSON

PROBLEM_SCHEMA: dict[str, Any] = {
    "type": "object",
    "required": ["type", "title", "status", "detail", "code"],
    "properties": {
        "type": {"type": "string"},
        "title": {"type": "string"},
        "status": {"type": "integer"},
        "detail": {"type": "string"},
        "code": {"type": "string"},
        "field": {"type": "string"},
        "job_id": {"type": "string"},
    },
}


def problems(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` entries: these statuses answer ``application/problem+json``."""
    ref = {"$ref": "#/components/schemas/Problem"}
    return {
        status: {"description": "Problem", "content": {PROBLEM_JSON: {"schema": ref}}}
        for status in statuses
    }


def publish_components(app: FastAPI, models: Models) -> None:
    """Make ``app.openapi()`` add the options models and the problem body as components."""
    original = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            schema = original()
            components = schema.setdefault("components", {}).setdefault("schemas", {})
            components["SynthesizeOptions"] = models.synthesize.model_json_schema()
            components["TransferOptions"] = models.transfer.model_json_schema()
            components["TileOptions"] = models.tile.model_json_schema()
            components["MatteOptions"] = models.matte.model_json_schema()
            components["FillOptions"] = models.fill.model_json_schema()
            components["ExtendOptions"] = models.extend.model_json_schema()
            components["WangOptions"] = models.wang_tiles.model_json_schema()
            components["AlphaOptions"] = models.extract_alpha.model_json_schema()
            components["Problem"] = PROBLEM_SCHEMA
            app.openapi_schema = schema
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
