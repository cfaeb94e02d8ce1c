"""The parts of a submission as the service reads them, before any pixel: the JSON form
fields checked and parsed against the options' schema (:mod:`quilting.service.schemas`), the
engine's options made from them, the companion kinds, and the :class:`Submission` an
Idempotency-Key is bound to.

Pure functions of their arguments (the settings and schema models passed in), each raising a
:class:`~quilting.service.problems.Problem` with the status and code a client gets; the
routes call them, and they are tested on their own.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from pydantic import BaseModel, ValidationError

from quilting import COMPANION_KINDS, AlphaOptions, QuiltingError
from quilting.backends import resolve_name
from quilting.options import (
    NAMED_CORRESPONDENCES,
    ExtendOptions,
    FillOptions,
    QuiltOptions,
    SynthesisOptions,
    TransferOptions,
    WangOptions,
)
from quilting.service.jobs.job_files import JobFiles
from quilting.service.problems import Problem, from_engine
from quilting.service.settings import Settings

COMPANION_NAME = re.compile(r"^[A-Za-z0-9_-]{1,64}$")

#: The options object a job carries: a synthesis's, a transfer's or a matte's
#: (:class:`QuiltOptions`), a fill's or an extension's (:class:`FillOptions`), a Wang tile
#: set's (:class:`WangOptions`), or an alpha extraction's (:class:`~quilting.AlphaOptions`).
JobOptions = QuiltOptions | FillOptions | WangOptions | AlphaOptions

OptionsT = TypeVar("OptionsT", bound=JobOptions)

#: Limits of the options form field, checked before it is parsed: json.loads and the schema
#: validation recurse, so a deeply nested value would exhaust Python's stack (no option
#: nests more than a few levels).
MAX_OPTIONS_CHARS = 64 * 1024
MAX_OPTIONS_DEPTH = 32
#: A JSON string (escapes included, closing quote optional) or one bracket.
_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"?')
#: Steps of the nesting depth: +1 for an opening bracket, -1 for a closing one, 0 otherwise.
_DEPTH_STEP = np.zeros(256, dtype=np.int64)
_DEPTH_STEP[[ord("["), ord("{")]] = 1
_DEPTH_STEP[[ord("]"), ord("}")]] = -1

#: Parts of a submission that may be sent more than once; any other part is one value.
REPEATABLE_PARTS = frozenset({"companion", "layer"})
#: The parts that say which of a photo is foreground, its alpha to be extracted first: one (or
#: an empty part, for none) per example of ``/synthesize``, per layer of ``/matte``.
MARK_PARTS = frozenset({"trimap", "scribbles"})
#: Parts that may also repeat where a job takes several examples (``/synthesize``,
#: ``/wang-tiles``): one texture per example, and a source mask (a trimap, scribbles) per
#: texture.
EXAMPLE_PARTS = frozenset({"texture", "source_mask"}) | MARK_PARTS


@dataclass
class Submission(JobFiles):
    """A job's submission (``POST /synthesize``, ``/transfer``, ``/matte``, ``/fill``,
    ``/extend``, ``/wang-tiles`` or ``/extract-alpha``) once read, before its images are
    decoded. The files besides the texture and its companions are the
    :class:`~quilting.service.jobs.job_files.JobFiles` fields (keywords), which the job's
    input takes as they are.

    Attributes
    ----------
    operation : str
        ``"synthesize"``, ``"transfer"``, ``"matte"``, ``"fill"``, ``"extend"``,
        ``"wang_tiles"`` or ``"extract_alpha"``.
    options : QuiltOptions, FillOptions, WangOptions or AlphaOptions
        The validated engine options of the operation (a :class:`TransferOptions` for a
        transfer, an :class:`ExtendOptions` for an extension...).
    texture : bytes
        The uploaded texture (the first of several examples); a fill's or an extension's
        image (the ``image`` part); an alpha extraction's photo.
    companions : dict of str to bytes
        Companion maps by name.
    size : (int, int) or None
        Output (width, height) of a synthesis; None for a transfer (the target's size).
    texture_name, target_name : str or None
        The file names the client gave the texture (a matte's first layer) and the target:
        the start of the download names. Not part of :meth:`digest`: the same files under
        other names are the same request, with the same result.
    """

    operation: str
    options: JobOptions
    texture: bytes
    companions: dict[str, bytes]
    size: tuple[int, int] | None = None
    texture_name: str | None = None
    target_name: str | None = None

    def digest(self) -> str:
        """What an Idempotency-Key is bound to: the operation, options and every file.

        The operation is part of it, so that a synthesis and a transfer never count as the
        same request, and so is the target, so that another target is another request.
        """
        files: list[tuple[str, str, bytes]] = [("texture", "", self.texture)]
        if self.target is not None:
            files.append(("target", "", self.target))
        if self.source_mask is not None:
            files.append(("source_mask", "", self.source_mask))
        files += [("layer", str(index), data) for index, data in enumerate(self.layers)]
        for role, data in (
            ("silhouette", self.silhouette),
            ("normals", self.normals),
            ("mask", self.mask),
            ("source", self.source),
        ):
            if data is not None:
                files.append((role, "", data))
        files += [("companion", name, data) for name, data in sorted(self.companions.items())]
        # Only with several examples: a request of one texture digests as it always has.
        files += [("example", str(k), data) for k, data in enumerate(self.examples)]
        files += [("example_mask", str(k), data) for k, data in enumerate(self.source_masks)]
        for name, maps in sorted(self.example_companions.items()):
            files += [("example_companion", f"{k}/{name}", data) for k, data in enumerate(maps)]
        # Only with an extraction: a request without one digests as it always has.
        for role, marks in (("trimap", self.trimaps), ("scribbles", self.scribbles)):
            files += [(role, str(k), data) for k, data in enumerate(marks) if data is not None]
        document = {
            "operation": self.operation,
            "size": self.size,
            "options": self.options.to_dict(),
            "files": [[role, name, hashlib.sha256(data).hexdigest()] for role, name, data in files],
        }
        # Only kinds other than the default: a request that names none (or only 'blend') is the
        # same request as before kinds existed, so its Idempotency-Key digest is unchanged.
        kinds = {n: k for n, k in sorted(self.companion_kinds.items()) if k != "blend"}
        if kinds:
            document["companion_kinds"] = kinds
        return hashlib.sha256(json.dumps(document, sort_keys=True).encode()).hexdigest()


def json_depth(text: str) -> int:
    """How deep arrays and objects nest in the JSON ``text``, without recursion.

    Brackets inside strings do not count; the text need not be valid JSON (a parser that
    reads it afterwards says what else is wrong).
    """
    # At C speed, on the event loop: a Python loop over 200,000 brackets held it 0.4 s. The
    # strings go first (brackets inside them are not nesting), then every character is a step.
    # Bytes past ASCII are never brackets (UTF-8 continuation and lead bytes are >= 0x80).
    outside = _JSON_STRING.sub("", text).encode("utf-8", "surrogatepass")
    if not outside:
        return 0
    steps = _DEPTH_STEP[np.frombuffer(outside, dtype=np.uint8)]
    return max(0, int(np.cumsum(steps).max()))


def json_object(text: str, field: str, code: str, what: str) -> dict[str, Any]:
    """A form field holding a JSON object; ``code`` for every refusal (422), ``what``
    the shape the message asks for. Its length and depth are checked before it is parsed:
    a deep nesting would exhaust the parser's recursion."""
    depth = json_depth(text)
    if depth > MAX_OPTIONS_DEPTH:
        raise Problem(
            422,
            code,
            f"{field} nests arrays and objects {depth} levels deep; at most {MAX_OPTIONS_DEPTH}",
            field=field,
        )
    if len(text) > MAX_OPTIONS_CHARS:
        raise Problem(
            422,
            code,
            f"{field} is {len(text)} characters; at most {MAX_OPTIONS_CHARS}",
            field=field,
        )
    try:
        raw = json.loads(text)
    except ValueError as exc:
        raise Problem(422, code, f"{field} is not JSON: {exc}", field=field) from None
    if not isinstance(raw, dict):
        raise Problem(422, code, f"{field} must be a JSON object{what}", field=field)
    return raw


def options_object(text: str) -> dict[str, Any]:
    """The options form field as a JSON object."""
    return json_object(text, "options", "invalid_options", "")


def validate(raw: dict[str, Any], model: type[BaseModel]) -> dict[str, Any]:
    """The options checked against the endpoint's schema, as plain values."""
    try:
        values: dict[str, Any] = model.model_validate(raw).model_dump()
    except ValidationError as exc:
        first = exc.errors()[0]
        field = ".".join(str(p) for p in first["loc"]) or "options"
        code = "invalid_options" if first["type"] == "extra_forbidden" else "invalid_parameter"
        raise Problem(422, code, f"{field}: {first['msg']}", field=field) from None
    return values


def engine_options(values: dict[str, Any], options: type[OptionsT]) -> OptionsT:
    """The engine's options from schema-checked values (the engine checks the rest)."""
    try:
        resolve_name(values["backend"])
        return options(**values)
    except QuiltingError as exc:
        raise from_engine(exc) from None


def synthesis_options(
    text: str, model: type[BaseModel], settings: Settings
) -> tuple[int, int, SynthesisOptions]:
    """Output width, height and the engine options, validated against ``model`` (the
    ``SynthesizeOptions`` schema) and the output limit, from the options JSON."""
    values = validate(options_object(text), model)
    if values["width"] * values["height"] > settings.max_output_pixels:
        raise Problem(
            422,
            "invalid_parameter",
            f"output {values['width']}x{values['height']} is more than "
            f"{settings.max_output_pixels} pixels (max_output_pixels)",
            field="width",
        )
    width, height = values.pop("width"), values.pop("height")
    return width, height, engine_options(values, SynthesisOptions)


def wang_options(text: str, model: type[BaseModel], settings: Settings) -> WangOptions:
    """The Wang tile set's options, validated against ``model`` (the ``WangOptions`` schema)
    and the output limits (the atlas, ``colors``^2 tiles a side), from the options JSON."""
    options = engine_options(validate(options_object(text), model), WangOptions)
    side = options.colors**2 * options.tile
    if side > settings.max_side or side * side > settings.max_output_pixels:
        largest = min(settings.max_side, math.isqrt(settings.max_output_pixels))
        raise Problem(
            422,
            "invalid_parameter",
            f"the atlas of {options.colors**4} tiles of {options.tile} pixels would be "
            f"{side}x{side}; its side may be {largest} pixels (max_side, max_output_pixels): "
            f"at most tile={largest // options.colors**2 // 2 * 2} with colors={options.colors}",
            field="tile",
        )
    return options


def examples_fit(options: JobOptions, count: int) -> None:
    """422 ``invalid_parameter`` naming ``weights`` unless the options give one weight per
    texture (or none): checked once the textures are counted, before any is read."""
    weights = getattr(options, "weights", None)
    if weights is not None and len(weights) != count:
        raise Problem(
            422,
            "invalid_parameter",
            f"weights: {len(weights)} given for {count} texture{'s' if count > 1 else ''}; "
            "one number > 0 per texture part, in their order",
            field="weights",
        )


def transfer_options(text: str, model: type[BaseModel]) -> TransferOptions:
    """The transfer options, validated against ``model`` (the ``TransferOptions`` schema),
    from the options JSON."""
    raw = options_object(text)
    if raw.get("correspondence") == "custom":
        # The schema would refuse it too; this says why and what to do instead.
        raise Problem(
            422,
            "invalid_parameter",
            "correspondence: 'custom' needs correspondence maps given as arrays, which only "
            "the Python API (quilting.transfer) takes; the service offers "
            + ", ".join(repr(c) for c in NAMED_CORRESPONDENCES),
            field="correspondence",
        )
    return engine_options(validate(raw, model), TransferOptions)


def fill_options(text: str, model: type[BaseModel]) -> FillOptions:
    """The fill options, validated against ``model`` (the ``FillOptions`` schema), from the
    options JSON."""
    return engine_options(validate(options_object(text), model), FillOptions)


def extend_options(text: str, model: type[BaseModel]) -> ExtendOptions:
    """The extension's options (the pixels added on each side and the fill's), validated
    against ``model`` (the ``ExtendOptions`` schema), from the options JSON. The size of the
    extended image is checked against the output limits once the image's header is read
    (:func:`quilting.service.uploads.check_headers`)."""
    return engine_options(validate(options_object(text), model), ExtendOptions)


def alpha_options(text: str, model: type[BaseModel]) -> AlphaOptions:
    """The alpha extraction's options, validated against ``model`` (the ``AlphaOptions``
    schema), from the options JSON."""
    try:
        return AlphaOptions(**validate(options_object(text), model))
    except QuiltingError as exc:
        raise from_engine(exc) from None


def companion_kinds(text: str | None, companions: Mapping[str, bytes]) -> dict[str, str]:
    """The ``companion_kinds`` form field: {name: kind} of uploaded companions.

    Raises
    ------
    Problem
        422 ``invalid_parameter`` for a field that is not a JSON object of strings or names
        an unknown kind; 422 ``invalid_companion`` for a name no companion has.
    """
    if text is None or not text.strip():
        return {}
    raw = json_object(text, "companion_kinds", "invalid_parameter", " {companion name: kind}")
    allowed = ", ".join(repr(k) for k in COMPANION_KINDS)
    for name, kind in raw.items():
        if name not in companions:
            raise Problem(
                422,
                "invalid_companion",
                f"companion_kinds names {name!r}, which is not an uploaded companion"
                + (f" (uploaded: {', '.join(sorted(companions))})" if companions else ""),
                field="companion_kinds",
            )
        if kind not in COMPANION_KINDS:
            raise Problem(
                422,
                "invalid_parameter",
                f"companion_kinds: {name!r} has kind {kind!r}; one of {allowed}",
                field="companion_kinds",
            )
    return {str(name): str(kind) for name, kind in raw.items()}
