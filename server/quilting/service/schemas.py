"""The ``options`` JSON schema of each endpoint, generated from the options dataclasses with
the service's limits: what the routes validate a form's options against, and what the OpenAPI
document publishes (and the web page and the remote client build their forms from)."""

from __future__ import annotations

import typing
from dataclasses import fields
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, create_model

from quilting import AlphaOptions
from quilting.options import (
    FillOptions,
    QuiltOptions,
    SynthesisOptions,
    TileOptions,
    WangOptions,
    offered_choices,
)
from quilting.service.settings import Settings


def options_model(
    settings: Settings,
    options: type[QuiltOptions]
    | type[TileOptions]
    | type[FillOptions]
    | type[WangOptions]
    | type[AlphaOptions] = SynthesisOptions,
    *,
    name: str = "SynthesizeOptions",
    sized: bool = True,
) -> type[BaseModel]:
    """The ``options`` JSON schema of an endpoint, derived from an options dataclass.

    Parameters
    ----------
    settings : Settings
        Limits of the output size and the service's default backend.
    options : type
        An options dataclass (:class:`SynthesisOptions`, :class:`TransferOptions`,
        :class:`MatteOptions`, :class:`TileOptions`, :class:`FillOptions`,
        :class:`ExtendOptions`, :class:`WangOptions`, :class:`~quilting.AlphaOptions`); every
        field becomes a property with its
        documentation, default and limits.
    name : str
        Name of the model (the schema's component name).
    sized : bool
        Whether the output ``width`` and ``height`` are required properties (synthesis);
        a transfer's output has its target's size.

    A field whose type allows more than a user may name (the backend, a string to the core;
    the correspondence, whose 'custom' needs arrays) lists :func:`quilting.options.offered_choices`.
    """
    hints = typing.get_type_hints(options)
    definitions: dict[str, Any] = {}
    if sized:
        definitions["width"] = (
            int,
            Field(ge=1, le=settings.max_side, description="Output width in pixels."),
        )
        definitions["height"] = (
            int,
            Field(ge=1, le=settings.max_side, description="Output height in pixels."),
        )
    for f in fields(options):
        limits = {k: f.metadata[k] for k in ("ge", "le", "multiple_of") if k in f.metadata}
        default = f.default
        if f.name == "backend":
            default = settings.backend
        hint = hints[f.name]
        # Listed choices make the schema a menu (the web page builds its form from it).
        offered = offered_choices(f)
        declared = tuple(c for c in f.metadata.get("choices", ()) if c is not None)
        if offered is not None and offered != declared:
            hint = Literal[offered]
        if f.metadata.get("kind") == "color_ranges":
            # JSON has arrays, not tuples: [[low, high], ...] with colours of 1..4 numbers.
            colour = Annotated[list[float], Field(min_length=1, max_length=4)]
            hint = list[Annotated[list[colour], Field(min_length=2, max_length=2)]]
            default = []
        if f.metadata.get("kind") == "direction":
            hint = Annotated[list[float], Field(min_length=3, max_length=3)] | None
        if f.metadata.get("kind") == "weights":
            # JSON has arrays: one number > 0 per example, at most as many as a job may have
            # (that there is one per texture is checked once the textures are counted).
            weight = Annotated[float, Field(gt=0)]
            hint = Annotated[list[weight], Field(min_length=1, max_length=settings.max_textures)]
            hint = hint | None
        definitions[f.name] = (
            hint,
            Field(default=default, description=str(f.metadata["doc"]), **limits),
        )
    model: type[BaseModel] = create_model(
        name,
        # Strict: JSON true is not the integer 1, and "64" is not a number.
        __config__=ConfigDict(extra="forbid", strict=True),
        **definitions,
    )
    return model
