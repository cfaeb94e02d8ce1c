"""Unit tests of :mod:`quilting.service.schemas`, the ``options`` models, called directly.

Covers
------
- Every endpoint of :class:`~quilting.service.context.Models` has its options dataclass here,
  and its model has one property per dataclass field (plus ``width`` and ``height`` for
  ``/synthesize``) and no other; an unknown member is refused (``extra="forbid"``).
- Each property has the field's documentation, default (the service's backend for
  ``backend``), choices (:func:`quilting.options.offered_choices`) and ``ge``/``le`` bounds,
  as the published JSON schema shows them; the model's defaults build the dataclass's.
- The settings shape the models: ``max_side`` bounds ``width``/``height``, ``backend`` is the
  default backend, ``max_textures`` the most ``weights``.
- A table of boundary and wrong-typed values generated from each field's metadata (so a new
  option is covered without editing this file): a model accepts a value of a bounded, choice
  or boolean field exactly when the dataclass does; a field the schema only shapes
  (``transforms``, ``weights``, ``light``, ``exclude_colors``) never refuses what the dataclass
  takes; and whatever a model lets through that the engine refuses is still a 422
  ``invalid_parameter`` naming the field once parsed the way the routes parse it.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable
from typing import Any

import pytest
from pydantic import BaseModel, ValidationError

from quilting import QuiltingError
from quilting.backends import BACKEND_NAMES
from quilting.options import (
    AlphaOptions,
    ExtendOptions,
    FillOptions,
    MatteOptions,
    SynthesisOptions,
    TileOptions,
    TransferOptions,
    WangOptions,
    offered_choices,
)
from quilting.service import forms
from quilting.service.context import Models
from quilting.service.problems import Problem
from quilting.service.schemas import options_model
from quilting.service.settings import Settings

#: Not the dataclasses' default backend ("auto"), so that a default taken from the dataclass
#: instead of the settings shows; "fft" also resolves without probing for a GPU.
SETTINGS = Settings(backend="fft")
MODELS = Models.of(SETTINGS)

#: The options dataclass of each endpoint's model.
ENDPOINTS: dict[str, type[Any]] = {
    "synthesize": SynthesisOptions,
    "transfer": TransferOptions,
    "tile": TileOptions,
    "matte": MatteOptions,
    "fill": FillOptions,
    "extend": ExtendOptions,
    "wang_tiles": WangOptions,
    "extract_alpha": AlphaOptions,
}
#: The only model whose output size is part of its options.
SIZED = {"synthesize"}
#: Values a model lets through that its dataclass refuses by a rule outside the field's
#: metadata, so the schema cannot say it (none today: a Wang tile's evenness is its field's
#: ``multiple_of``, published as ``multipleOf``). The route answers 422 for such a value too.
SCHEMA_GAPS: set[tuple[str, str, object]] = set()
#: Fields whose schema gives their shape only; the engine checks the rest.
SHAPED_KINDS = ("transforms", "weights", "direction", "color_ranges")

JUNK: tuple[Any, ...] = (None, True, "x", [], {})


def _model(endpoint: str) -> type[BaseModel]:
    model: type[BaseModel] = getattr(MODELS, endpoint)
    return model


def _base(endpoint: str) -> dict[str, Any]:
    """The members a model requires besides the value under test."""
    return {"width": 8, "height": 8} if endpoint in SIZED else {}


def _pairs(select: Callable[[dataclasses.Field[Any]], bool]) -> list[Any]:
    return [
        pytest.param(endpoint, f, id=f"{endpoint}.{f.name}")
        for endpoint, cls in ENDPOINTS.items()
        for f in dataclasses.fields(cls)
        if select(f)
    ]


def _property(endpoint: str, name: str) -> dict[str, Any]:
    schema: dict[str, Any] = _model(endpoint).model_json_schema()["properties"][name]
    return schema


def _variants(schema: dict[str, Any]) -> list[dict[str, Any]]:
    """A property's schema and the alternatives of an ``anyOf`` (an optional field)."""
    return [schema, *schema.get("anyOf", [])]


def boundary_values(f: dataclasses.Field[Any]) -> list[Any]:
    """Values at and past a field's limits, and of the wrong JSON types, from its metadata."""
    meta = f.metadata
    values: list[Any] = list(JUNK)
    if "choices" in meta:
        offered = offered_choices(f) or ()
        values += [*meta["choices"], *(c.upper() for c in offered), "", 0]
    elif meta.get("kind") == "bool":
        values += [False, 1, 0, "true"]
    elif "ge" in meta:
        lo, hi = meta["ge"], meta.get("le")
        if isinstance(lo, float):
            values += [lo, math.nextafter(lo, -math.inf), str(lo)]
            values += [math.nan, math.inf, -math.inf]
            if lo == int(lo):
                values.append(int(lo))  # an integer where a number is due
            if hi is not None:
                values += [hi, math.nextafter(hi, math.inf)]
        else:
            values += [lo, lo - 1, lo + 1, float(lo), lo + 0.5, str(lo)]
            if hi is not None:
                values += [hi, hi + 1, hi + 2**64]
            else:  # past what the other fields allow (an overlap of half the block...)
                values.append(2**64)
    elif meta.get("kind") == "transforms":
        values += ["none", "flips", "rotations", "all", "bogus", "", "flips,none", 1]
        values.remove([])  # a list of names is the Python API's, not offered over HTTP
    elif meta.get("kind") == "weights":
        values += [[1], [0], [-1], [0.5, 2], [math.nan], [math.inf], [True], "1", ["1"]]
        values += [[1] * SETTINGS.max_textures]
    elif meta.get("kind") == "direction":
        values += [[0, 0, 1], [0.5, -2, 3], [0, 0, 0], [0, 0, -1], [1, 2], [1, 2, 3, 4]]
        values += [[math.nan, 0, 1], [True, 0, 1], ["1", 0, 1]]
    elif meta.get("kind") == "color_ranges":
        values += [[[[0], [1]]], [[[0, 0, 0], [255, 255, 255]]], [[[0, 0, 0, 0], [1, 1, 1, 1]]]]
        values += [[[[0], [1], [2]]], [[[], [1]]], [[[0] * 5, [1] * 5]], [[[0, 0, 0], [1]]]]
        values += [[[[2], [1]]], [[[math.nan], [1]]], [[["a"], [1]]], [[[True], [1]]]]
    return values


def _model_takes(endpoint: str, name: str, value: Any) -> bool:
    try:
        _model(endpoint).model_validate({**_base(endpoint), name: value})
    except ValidationError:
        return False
    return True


def _dataclass_takes(cls: type[Any], name: str, value: Any) -> bool:
    try:
        cls(**{name: value})
    except QuiltingError:
        return False
    return True


# --- the properties ------------------------------------------------------------------------


def test_every_endpoint_model_has_its_dataclass_here() -> None:
    assert {f.name for f in dataclasses.fields(Models)} == set(ENDPOINTS)


@pytest.mark.parametrize("endpoint", ENDPOINTS)
def test_a_model_has_one_property_per_field_and_no_other(endpoint: str) -> None:
    names = {f.name for f in dataclasses.fields(ENDPOINTS[endpoint])}
    sized = {"width", "height"} if endpoint in SIZED else set()
    assert set(_model(endpoint).model_fields) == names | sized
    schema = _model(endpoint).model_json_schema()
    assert schema["additionalProperties"] is False
    assert set(schema.get("required", [])) == sized


@pytest.mark.parametrize("endpoint", ENDPOINTS)
def test_an_unknown_or_misspelt_member_is_refused(endpoint: str) -> None:
    first = dataclasses.fields(ENDPOINTS[endpoint])[0].name
    for extra in (first + "s", first.upper(), "colour"):
        with pytest.raises(Problem) as caught:
            forms.validate({**_base(endpoint), extra: 1}, _model(endpoint))
        assert (caught.value.status, caught.value.code) == (422, "invalid_options")
        assert caught.value.extra["field"] == extra


@pytest.mark.parametrize(("endpoint", "f"), _pairs(lambda f: True))
def test_a_property_has_the_field_s_doc_and_default(
    endpoint: str, f: dataclasses.Field[Any]
) -> None:
    info = _model(endpoint).model_fields[f.name]
    assert info.description == f.metadata["doc"]
    if f.name == "backend":
        expected: Any = SETTINGS.backend
    elif f.metadata.get("kind") == "color_ranges":
        assert f.default == ()
        expected = []  # JSON has arrays, not tuples
    else:
        expected = f.default
    assert info.default == expected
    assert type(info.default) is type(expected)
    assert _property(endpoint, f.name)["default"] == expected


@pytest.mark.parametrize("endpoint", ENDPOINTS)
def test_a_model_s_defaults_build_the_dataclass_s_defaults(endpoint: str) -> None:
    cls = ENDPOINTS[endpoint]
    values = _model(endpoint).model_validate(_base(endpoint)).model_dump()
    for name in _base(endpoint):
        values.pop(name)
    names = {f.name for f in dataclasses.fields(cls)}
    expected = cls(backend=SETTINGS.backend) if "backend" in names else cls()
    assert cls(**values) == expected


@pytest.mark.parametrize(("endpoint", "f"), _pairs(lambda f: offered_choices(f) is not None))
def test_a_property_s_choices_are_those_offered(endpoint: str, f: dataclasses.Field[Any]) -> None:
    offered = offered_choices(f)
    assert offered is not None
    enums = [v["enum"] for v in _variants(_property(endpoint, f.name)) if "enum" in v]
    assert enums == [list(offered)]
    for choice in offered:
        assert _model_takes(endpoint, f.name, choice)
    # None is a value only where the dataclass declares it one.
    assert _model_takes(endpoint, f.name, None) == (None in f.metadata.get("choices", ()))
    # Declared but not offered ('custom' correspondence): refused by the schema.
    for hidden in set(f.metadata.get("choices", ())) - set(offered) - {None}:
        assert not _model_takes(endpoint, f.name, hidden)


@pytest.mark.parametrize(("endpoint", "f"), _pairs(lambda f: "ge" in f.metadata))
def test_a_property_s_bounds_are_the_field_s(endpoint: str, f: dataclasses.Field[Any]) -> None:
    bounded = [v for v in _variants(_property(endpoint, f.name)) if "minimum" in v]
    assert len(bounded) == 1
    assert bounded[0]["minimum"] == f.metadata["ge"]
    assert bounded[0].get("maximum") == f.metadata.get("le")
    kind = "number" if isinstance(f.metadata["ge"], float) else "integer"
    assert bounded[0]["type"] == kind
    assert _model_takes(endpoint, f.name, None) == bool(f.metadata.get("optional"))


def test_the_settings_shape_the_models() -> None:
    settings = Settings(backend="reference", max_side=512, max_textures=3)
    sized = options_model(settings)
    schema = sized.model_json_schema()["properties"]
    for side in ("width", "height"):
        assert (schema[side]["minimum"], schema[side]["maximum"]) == (1, settings.max_side)
    assert sized.model_fields["backend"].default == "reference"
    values = sized.model_validate({"width": 512, "height": 1, "weights": [1, 2, 3]}).model_dump()
    assert (values["width"], values["height"], values["weights"]) == (512, 1, [1.0, 2.0, 3.0])
    for refused in ({"width": 513, "height": 1}, {"width": 1, "height": 0}, {"height": 1}):
        with pytest.raises(ValidationError):
            sized.model_validate(refused)
    with pytest.raises(ValidationError):
        sized.model_validate({"width": 8, "height": 8, "weights": [1, 1, 1, 1]})
    unsized = options_model(settings, TransferOptions, name="TransferOptions", sized=False)
    assert "width" not in unsized.model_fields and unsized.__name__ == "TransferOptions"
    with pytest.raises(ValidationError):
        unsized.model_validate({"width": 8})


def test_the_backend_is_one_of_the_registry_s_names() -> None:
    for endpoint, cls in ENDPOINTS.items():
        if "backend" not in {f.name for f in dataclasses.fields(cls)}:
            continue
        for name in BACKEND_NAMES:
            assert _model_takes(endpoint, "backend", name)
        for other in ("quantum", "FFT", "", None, 1):
            assert not _model_takes(endpoint, "backend", other)


# --- the table of boundary values ----------------------------------------------------------


def _exact(f: dataclasses.Field[Any]) -> bool:
    """A field the schema checks as fully as the dataclass: bounds, choices or a switch."""
    meta = f.metadata
    return f.name != "backend" and ("ge" in meta or "choices" in meta or meta.get("kind") == "bool")


@pytest.mark.parametrize(("endpoint", "f"), _pairs(_exact))
def test_a_model_takes_exactly_what_the_dataclass_takes(
    endpoint: str, f: dataclasses.Field[Any]
) -> None:
    """Values the dataclass refuses by another field's value (an overlap past half the
    block) are left to the 422 test below: one field's schema cannot know them."""
    cls = ENDPOINTS[endpoint]
    offered = offered_choices(f)
    hidden = set(f.metadata.get("choices", ())) - set(offered or ()) - {None}
    differ = [
        value
        for value in boundary_values(f)
        if value != 2**64
        and not any(gap == (endpoint, f.name, value) for gap in SCHEMA_GAPS)
        and not (isinstance(value, str) and value in hidden)
        and _model_takes(endpoint, f.name, value) != _dataclass_takes(cls, f.name, value)
    ]
    assert differ == []


@pytest.mark.parametrize(
    ("endpoint", "f"), _pairs(lambda f: f.metadata.get("kind") in SHAPED_KINDS)
)
def test_a_shaped_field_never_refuses_what_the_dataclass_takes(
    endpoint: str, f: dataclasses.Field[Any]
) -> None:
    cls = ENDPOINTS[endpoint]
    values = boundary_values(f)
    taken = [v for v in values if _dataclass_takes(cls, f.name, v)]
    assert taken, "the table has values the dataclass takes"
    assert [v for v in taken if not _model_takes(endpoint, f.name, v)] == []
    # and refuses every value of another JSON shape, before the engine sees it
    other: tuple[Any, ...] = (True, {}, "x" if f.metadata["kind"] != "transforms" else 1)
    for value in other:
        assert not _model_takes(endpoint, f.name, value)


def _parse_synthesis(text: str) -> Any:
    return forms.synthesis_options(text, MODELS.synthesize, SETTINGS)[2]


#: How each route turns its options text into the engine's options (the tile route checks
#: its options itself, outside :mod:`quilting.service.forms`).
PARSERS: dict[str, Callable[[str], Any]] = {
    "synthesize": _parse_synthesis,
    "transfer": lambda text: forms.transfer_options(text, MODELS.transfer),
    "matte": lambda text: forms.engine_options(
        forms.validate(forms.options_object(text), MODELS.matte), MatteOptions
    ),
    "fill": lambda text: forms.fill_options(text, MODELS.fill),
    "extend": lambda text: forms.extend_options(text, MODELS.extend),
    "wang_tiles": lambda text: forms.wang_options(text, MODELS.wang_tiles, SETTINGS),
    "extract_alpha": lambda text: forms.alpha_options(text, MODELS.extract_alpha),
}


@pytest.mark.parametrize(
    ("endpoint", "f"), [p for p in _pairs(lambda f: True) if p.values[0] in PARSERS]
)
def test_a_parsed_value_is_the_dataclass_s_or_a_422_naming_its_field(
    endpoint: str, f: dataclasses.Field[Any]
) -> None:
    cls = ENDPOINTS[endpoint]
    backend = {"backend": SETTINGS.backend} if "backend" in cls.__dataclass_fields__ else {}
    for value in boundary_values(f):
        text = json.dumps({**_base(endpoint), f.name: value})  # NaN and Infinity as Python's
        try:
            parsed = PARSERS[endpoint](text)
        except Problem as problem:
            assert (problem.status, problem.code) == (422, "invalid_parameter"), value
            assert problem.extra["field"].split(".")[0] == f.name, value
            continue
        assert parsed == cls(**{**backend, f.name: value}), value
