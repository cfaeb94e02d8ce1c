"""The options dataclasses: every field declared once with its documentation and limits, the
limits enforced at construction, the values round-tripping through ``to_dict``."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest

from quilting.core.errors import InvalidParameterError
from quilting.core.options import (
    MAX_SIDE,
    MatteOptions,
    SynthesisOptions,
    TileOptions,
    TransferOptions,
    validate_size,
)

CLASSES = [SynthesisOptions, TransferOptions, MatteOptions, TileOptions]
NUMERIC = [
    (cls, f)
    for cls in CLASSES
    for f in dataclasses.fields(cls)
    if "ge" in f.metadata and f.metadata.get("kind") is None
]


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_every_field_is_documented(cls: type) -> None:
    for f in dataclasses.fields(cls):
        doc = f.metadata.get("doc", "")
        assert len(doc) > 20, f"{cls.__name__}.{f.name} has no documentation"


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_defaults_round_trip_through_to_dict(cls: type) -> None:
    options = cls()
    values = options.to_dict()
    assert set(values) == {f.name for f in dataclasses.fields(cls)}
    assert cls(**values) == options


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_options_are_frozen_and_keyword_only(cls: type) -> None:
    options = cls()
    name = dataclasses.fields(cls)[0].name
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(options, name, getattr(options, name))
    with pytest.raises(TypeError):
        cls(getattr(options, name))


@pytest.mark.parametrize(
    ("cls", "field"), NUMERIC, ids=[f"{c.__name__}.{f.name}" for c, f in NUMERIC]
)
def test_numeric_limits_are_enforced_and_named(cls: type, field: dataclasses.Field[Any]) -> None:
    low, high = field.metadata["ge"], field.metadata.get("le")
    # Fields whose valid range depends on others (overlap < block / 2) are tried at values
    # the others allow.
    others: dict[str, Any] = {"block": 48} if field.name == "overlap" else {}
    below = low - (0.5 if isinstance(low, float) else 1)
    with pytest.raises(InvalidParameterError) as caught:
        cls(**others, **{field.name: below})
    assert caught.value.parameter == field.name
    if high is not None and field.name != "block":
        with pytest.raises(InvalidParameterError) as caught:
            cls(**others, **{field.name: high + (0.5 if isinstance(high, float) else 1)})
        assert caught.value.parameter == field.name
    if field.name not in ("overlap", "block"):
        assert getattr(cls(**{field.name: low}), field.name) == low


@pytest.mark.parametrize("value", ["3", True, float("nan"), None, [1]])
def test_a_number_must_be_a_number(value: object) -> None:
    with pytest.raises(InvalidParameterError) as caught:
        SynthesisOptions(tolerance=value)  # type: ignore[arg-type]
    assert caught.value.parameter == "tolerance"


def test_an_integer_field_refuses_a_float() -> None:
    with pytest.raises(InvalidParameterError, match="an integer"):
        SynthesisOptions(block=32.0)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("cls", "field"),
    [(c, f) for c in CLASSES for f in dataclasses.fields(c) if "choices" in f.metadata],
    ids=lambda x: getattr(x, "__name__", getattr(x, "name", "")),
)
def test_choices_are_enforced(cls: type, field: dataclasses.Field[Any]) -> None:
    for choice in field.metadata["choices"]:
        if choice == "custom":  # transfer's correspondence by maps, given with them
            continue
        assert getattr(cls(**{field.name: choice}), field.name) == choice
    with pytest.raises(InvalidParameterError) as caught:
        cls(**{field.name: "no-such-choice"})
    assert caught.value.parameter == field.name
    assert "one of" in str(caught.value)


@pytest.mark.parametrize("size", [(1, 1), (MAX_SIDE, 7), (300, 200)])
def test_validate_size_accepts(size: tuple[int, int]) -> None:
    assert validate_size(size) == size


@pytest.mark.parametrize(
    "size", [(0, 5), (5, -1), (MAX_SIDE + 1, 5), (5.0, 5), (True, 5), (5,), (1, 2, 3), "55", None]
)
def test_validate_size_refuses(size: object) -> None:
    with pytest.raises(InvalidParameterError) as caught:
        validate_size(size)
    assert caught.value.parameter == "size"


@pytest.mark.parametrize("cls", [SynthesisOptions, TransferOptions, MatteOptions, TileOptions])
def test_resolve_puts_overrides_into_the_object_and_validates(cls: type) -> None:
    base = cls.resolve(None, {}, caller="f")
    assert base == cls()
    name = "seed" if "seed" in {f.name for f in dataclasses.fields(cls)} else "band"
    changed = cls.resolve(base, {name: 7}, caller="f")
    assert getattr(changed, name) == 7 and getattr(base, name) != 7
    assert cls.resolve(changed, None) is changed  # nothing to put in: the same object
    with pytest.raises(InvalidParameterError):
        cls.resolve(base, {name: -1})


def test_resolve_refuses_an_unknown_name_and_another_class() -> None:
    with pytest.raises(TypeError, match=r"f\(\) got an unexpected keyword argument 'tolerence'"):
        SynthesisOptions.resolve(None, {"tolerence": 0.2}, caller="f")
    with pytest.raises(TypeError, match="did you mean 'tolerance'"):
        SynthesisOptions.resolve(None, {"tolerence": 0.2})
    with pytest.raises(TypeError, match="must be a SynthesisOptions, not TileOptions"):
        SynthesisOptions.resolve(TileOptions(), {})  # type: ignore[arg-type]
