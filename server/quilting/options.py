"""The options of every job, with the choices their fields allow, as the upper layers see
them.

Each option is one field of a frozen dataclass (:class:`SynthesisOptions`,
:class:`TransferOptions`, :class:`MatteOptions`, :class:`TileOptions`, :class:`FillOptions`,
:class:`ExtendOptions`, :class:`WangOptions`; the fields they share in :class:`QuiltOptions`);
its ``metadata`` carries its documentation and limits, from which the command line, the HTTP
schema and the docs' tables are generated. The service and the command line take them from
here, never from :mod:`quilting.core.options`.

:func:`offered_choices` is what a user may ask for by name in a field with choices, the one
rule the command line and the HTTP schema both follow. :func:`examples_shape` is the shape of
the texture a job of several examples (or of rotated and mirrored ones) quilts from, which the
cost model takes, known from the examples' sizes alone.
"""

from collections.abc import Sequence
from dataclasses import Field
from typing import Any

from quilting.backends import BACKEND_NAMES
from quilting.core.options import (
    BLENDS,
    CORRESPONDENCES,
    ERRORS,
    FILL_BLENDS,
    MATTE_MODES,
    MATTING_METHODS,
    MODES,
    TILE_BLENDS,
    TILE_METHODS,
    TILEABLE,
    TRANSFER_MODES,
    AlphaOptions,
    Correspondence,
    ExtendOptions,
    FillOptions,
    MatteOptions,
    QuiltOptions,
    SynthesisOptions,
    TileOptions,
    TransferOptions,
    WangOptions,
)
from quilting.core.sources import SourceSet

#: The correspondences a user names: 'custom' is what correspondence maps given as arrays
#: make (the Python API, or the command line's --source-map/--target-map), not a name to ask for.
NAMED_CORRESPONDENCES: tuple[str, ...] = tuple(c for c in CORRESPONDENCES if c != "custom")


def offered_choices(field: "Field[Any]") -> tuple[str, ...] | None:
    """The values a user may give an options field by name, or None for a field without
    choices: the backend registry's names for ``backend`` (the core cannot list them), the
    named correspondences for ``correspondence``, else the field's declared choices (None, the
    absence of a value, left out)."""
    if field.name == "backend":
        return BACKEND_NAMES
    if field.name == "correspondence":
        return NAMED_CORRESPONDENCES
    declared = field.metadata.get("choices")
    if declared is None:
        return None
    return tuple(c for c in declared if c is not None)


def examples_shape(
    sizes: Sequence[tuple[int, int]], options: SynthesisOptions | WangOptions
) -> tuple[int, int]:
    """(height, width) of the texture a job quilts from, given its examples' sizes alone: the
    one example itself, or the atlas of every example under every transform of
    ``options.transforms`` (:class:`quilting.core.sources.SourceSet`), the shape that
    :func:`quilting.estimate_synthesis` and :func:`quilting.estimate_wang` cost.

    Parameters
    ----------
    sizes : sequence of (int, int)
        (height, width) of each example, in order; at least one.
    options : SynthesisOptions or WangOptions
        Their ``transforms`` and ``block`` (and ``mode``: walk mode's placements keep a
        block of margin).
    """
    walk = getattr(options, "mode", None) == "walk"
    examples = [(int(h), int(w)) for h, w in sizes]
    plan = SourceSet.for_job(examples, options.transforms, options.block, walk=walk)
    return examples[0] if plan.trivial else plan.shape


__all__ = [
    "BLENDS",
    "CORRESPONDENCES",
    "ERRORS",
    "FILL_BLENDS",
    "MATTE_MODES",
    "MATTING_METHODS",
    "MODES",
    "NAMED_CORRESPONDENCES",
    "TILEABLE",
    "TILE_BLENDS",
    "TILE_METHODS",
    "TRANSFER_MODES",
    "AlphaOptions",
    "Correspondence",
    "ExtendOptions",
    "FillOptions",
    "MatteOptions",
    "QuiltOptions",
    "SynthesisOptions",
    "TileOptions",
    "TransferOptions",
    "WangOptions",
    "examples_shape",
    "offered_choices",
]
