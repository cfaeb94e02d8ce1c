"""The options the client takes (``quilting_client._options`` and the option documents the
request builders of ``quilting_client._protocol`` write), without a service.

Covers the shape of the client's copy of the service's schema (``options.json``: every
documented operation, each option typed and described, no defaults), the flag
``add_option_flags`` makes for every option of every operation (its type, its choices, its
help), ``given`` (only what was given, None left out, a value outside the choices refused
naming the flag), the parsers of list-shaped values (``numbers``, ``colour_range``,
``direction``), and every option of the schema reaching the request's ``options`` field as it
was given. That the schema is the service's own is checked in
tests/service/test_client_options.py.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable, Iterator, Mapping
from functools import cache
from typing import Any

import pytest
from client_fakes import NORMAL, TEXTURE

from quilting_client import _options as options
from quilting_client import _protocol as proto

#: The operations the module documents (extract_alpha came later; it is there too).
DOCUMENTED = {"synthesize", "transfer", "matte", "tile", "fill", "extend", "wang_tiles"}
JSON_TYPES = {"integer", "number", "boolean", "string", "array", "null", "object"}


def _all_options() -> list[tuple[str, str]]:
    return [(op, name) for op, schema in options.schemas().items() for name in schema]


def _with_choices() -> list[tuple[str, str]]:
    return [(op, name) for op, name in _all_options() if _choices(op, name)]


def _schema(operation: str, name: str) -> dict[str, Any]:
    schema: dict[str, Any] = options.schemas()[operation][name]
    return schema


def _kinds(schema: Mapping[str, Any]) -> set[str]:
    """The types of an option as the schema says (written here, not taken from the module)."""
    found = {schema["type"]} if "type" in schema else set()
    for part in schema.get("anyOf", ()):
        found |= _kinds(part)
    return found - {"null"}


def _choices(operation: str, name: str) -> list[str]:
    schema = _schema(operation, name)
    parts = [schema, *schema.get("anyOf", ())]
    return [str(value) for part in parts for value in part.get("enum", ())]


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


@cache
def _parser(operation: str) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=operation, exit_on_error=False)
    options.add_option_flags(parser, operation)
    return parser


def _walk(node: object) -> Iterator[Mapping[str, Any]]:
    if isinstance(node, Mapping):
        yield node
        for value in node.values():
            yield from _walk(value)
    elif isinstance(node, list):
        for value in node:
            yield from _walk(value)


def _sample(operation: str, name: str) -> tuple[list[str], object]:
    """A command line giving option ``name`` of ``operation`` and the value it stands for."""
    kinds = _kinds(_schema(operation, name))
    choices = _choices(operation, name)
    flag = _flag(name)
    if name == "light":
        return [f"{flag}=-1,1,2"], [-1.0, 1.0, 2.0]
    if name == "exclude_colors":
        argv = ["--exclude-color", "0,0,0:9,9,9", "--exclude-color", "200:255"]
        return argv, [[[0.0, 0.0, 0.0], [9.0, 9.0, 9.0]], [[200.0], [255.0]]]
    if "array" in kinds:
        return [flag, "2,1,0.5"], [2.0, 1.0, 0.5]
    if "boolean" in kinds:
        return [flag], True
    if choices:
        return [flag, choices[-1]], choices[-1]
    if "integer" in kinds:
        return [flag, "7"], 7
    if "number" in kinds:
        return [flag, "0.25"], 0.25
    return [flag, "rot90,flip_x"], "rot90,flip_x"


def _json_sample(operation: str, name: str) -> object:
    """A JSON value of option ``name`` as a caller of the client would give it."""
    _, value = _sample(operation, name)
    return value


# -- the schema ------------------------------------------------------------------------------


def test_the_schema_has_every_documented_operation() -> None:
    assert set(options.schemas()) >= DOCUMENTED
    for operation, schema in options.schemas().items():
        assert schema, f"{operation} has no options"


@pytest.mark.parametrize(("operation", "name"), _all_options())
def test_every_option_is_typed_and_described(operation: str, name: str) -> None:
    schema = _schema(operation, name)
    assert isinstance(schema.get("description"), str) and schema["description"].strip()
    kinds = _kinds(schema)
    assert kinds and kinds <= JSON_TYPES, kinds
    for value in (v for part in _walk(schema) for v in part.get("enum", ())):
        assert isinstance(value, str)


def test_the_schema_has_no_defaults() -> None:
    # An option left out is left to the service, whose defaults are the deployment's.
    found = [part for part in _walk(options.schemas()) if "default" in part]
    assert found == []


@pytest.mark.parametrize("operation", sorted(DOCUMENTED))
def test_option_names_are_the_schema_s_in_order(operation: str) -> None:
    names = list(options.schemas()[operation])
    assert options.option_names(operation) == names
    skip = names[::2]
    assert options.option_names(operation, skip=skip) == names[1::2]
    assert options.option_names(operation, skip=("not_an_option",)) == names


# -- the flags -------------------------------------------------------------------------------


@pytest.mark.parametrize(("operation", "name"), _all_options())
def test_every_option_has_a_flag_that_converts_its_value(operation: str, name: str) -> None:
    argv, expected = _sample(operation, name)
    args = _parser(operation).parse_args(argv)
    value = getattr(args, name)
    assert value == expected
    assert type(value) is type(expected)
    if isinstance(value, list) and value and not isinstance(value[0], list):
        assert all(type(item) is float for item in value)
    # Only that option is sent.
    assert options.given(args, operation) == {name: expected}


@pytest.mark.parametrize("operation", sorted(options.schemas()))
def test_nothing_given_sends_nothing(operation: str) -> None:
    args = _parser(operation).parse_args([])
    for name in options.option_names(operation):
        assert getattr(args, name) is None, name
    assert options.given(args, operation) == {}


@pytest.mark.parametrize(("operation", "name"), _all_options())
def test_every_flag_s_help_is_the_schema_s_description(operation: str, name: str) -> None:
    dest = {action.dest: action for action in _parser(operation)._actions}
    action = dest[name]
    assert action.help is not None
    assert " ".join(_schema(operation, name)["description"].split()) in " ".join(
        action.help.split()
    )
    choices = _choices(operation, name)
    if choices and name not in ("light", "exclude_colors"):
        assert action.metavar == "{" + ",".join(choices) + "}"


@pytest.mark.parametrize(("operation", "name"), _with_choices())
def test_every_choice_is_taken(operation: str, name: str) -> None:
    for choice in _choices(operation, name):
        args = _parser(operation).parse_args([_flag(name), choice])
        assert options.given(args, operation) == {name: choice}


@pytest.mark.parametrize(("operation", "name"), _with_choices())
def test_a_value_outside_the_choices_is_refused_naming_the_flag(operation: str, name: str) -> None:
    choices = _choices(operation, name)
    for wrong in ("bogus", choices[0].upper(), choices[0] + " ", ""):
        if wrong in choices:
            continue
        args = _parser(operation).parse_args([f"{_flag(name)}={wrong}"])
        with pytest.raises(ValueError) as caught:
            options.given(args, operation)
        text = str(caught.value)
        assert text.startswith(f"{_flag(name)} {wrong!r} is not one of ")
        assert text.endswith(", ".join(choices))


@pytest.mark.parametrize(
    ("operation", "name"),
    [(op, name) for op, name in _all_options() if _kinds(_schema(op, name)) == {"integer"}],
)
def test_an_integer_option_refuses_a_fraction(operation: str, name: str) -> None:
    with pytest.raises(argparse.ArgumentError, match=_flag(name)):
        _parser(operation).parse_args([_flag(name), "1.5"])


@pytest.mark.parametrize(
    ("operation", "name"),
    [(op, name) for op, name in _all_options() if _kinds(_schema(op, name)) == {"number"}],
)
def test_a_number_option_takes_an_integer_as_a_float_and_refuses_words(
    operation: str, name: str
) -> None:
    args = _parser(operation).parse_args([_flag(name), "2"])
    assert getattr(args, name) == 2.0 and type(getattr(args, name)) is float
    with pytest.raises(argparse.ArgumentError, match=_flag(name)):
        _parser(operation).parse_args([_flag(name), "much"])


def test_a_misspelt_flag_is_refused_naming_it(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        _parser("synthesize").parse_args(["--blok", "20"])
    assert "--blok" in capsys.readouterr().err


def test_skipped_options_get_no_flag_and_are_not_sent() -> None:
    parser = argparse.ArgumentParser(exit_on_error=False)
    options.add_option_flags(parser, "synthesize", skip=("width", "height"))
    dests = {action.dest for action in parser._actions}
    assert "width" not in dests and "height" not in dests and "block" in dests
    args = argparse.Namespace(width=64, height=32, block=20)
    assert options.given(args, "synthesize", skip=("width", "height")) == {"block": 20}


def test_given_reads_only_the_operation_s_options() -> None:
    args = argparse.Namespace(
        server="http://x", output="o.png", blok=3, block=None, seed=0, remap=False, colors=4
    )
    # seed=0 is given (only None is left out); remap and colors are not synthesis options.
    assert options.given(args, "synthesize") == {"seed": 0}
    assert options.given(args, "transfer") == {"seed": 0, "remap": False}
    assert options.given(args, "wang_tiles") == {"seed": 0, "colors": 4}


def test_a_list_value_is_not_checked_against_choices() -> None:
    # exclude_colors has no choices; a list-valued option never is compared as text.
    args = argparse.Namespace(exclude_colors=[[[1.0], [2.0]]], error="rgb")
    assert options.given(args, "synthesize") == {"exclude_colors": [[[1.0], [2.0]]], "error": "rgb"}


# -- list-shaped values ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "expected"),
    [("2,1,1", [2.0, 1.0, 1.0]), ("3", [3.0]), ("-1.5,1e2", [-1.5, 100.0])],
)
def test_numbers_are_separated_by_commas(text: str, expected: list[float]) -> None:
    assert options.numbers(text) == expected


@pytest.mark.parametrize("text", ["", "1,,2", "1;2", "a", "1, x"])
def test_numbers_refuse_anything_else_quoting_it(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError) as caught:
        options.numbers(text)
    assert repr(text) in str(caught.value)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("120,120,120:255,255,255", [[120.0, 120.0, 120.0], [255.0, 255.0, 255.0]]),
        ("0:10", [[0.0], [10.0]]),
        ("0,0,0,0:1,1,1,1", [[0.0] * 4, [1.0] * 4]),
    ],
)
def test_a_colour_range_is_low_colon_high(text: str, expected: list[list[float]]) -> None:
    assert options.colour_range(text) == expected


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("1,2,3", "is not LOW:HIGH"),
        ("", "is not LOW:HIGH"),
        ("a:1", "colour 'a'"),
        ("1:2:3", "colour '2:3'"),
        (":1", "colour ''"),
    ],
)
def test_a_colour_range_refuses_other_text(text: str, fragment: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match=fragment):
        options.colour_range(text)


def test_a_direction_is_three_numbers() -> None:
    assert options.direction("1,-1,2") == [1.0, -1.0, 2.0]
    for text in ("1,1", "1,1,2,3", "1"):
        with pytest.raises(argparse.ArgumentTypeError, match="X,Y,Z"):
            options.direction(text)
    with pytest.raises(argparse.ArgumentTypeError, match="light 'x,1,2'"):
        options.direction("x,1,2")


def test_a_flag_of_a_bad_list_is_refused_by_the_parser() -> None:
    for argv in (["--light", "1,1"], ["--exclude-color", "1,2"], ["--weights", "1,a"]):
        operation = "matte" if argv[0] == "--light" else "synthesize"
        with pytest.raises(argparse.ArgumentError, match=argv[0]):
            _parser(operation).parse_args(argv)


# -- the options a request sends --------------------------------------------------------------


#: A request of each operation with the given options (sizes and margins are keywords).
BUILDERS: dict[str, Callable[[Mapping[str, object]], proto.RequestSpec]] = {
    "synthesize": lambda o: proto.submit_request(
        TEXTURE, width=64, height=32, companions=None, options=o, wait=0, idempotency_key=None
    ),
    "transfer": lambda o: proto.transfer_request(
        TEXTURE, NORMAL, companions=None, options=o, wait=0, idempotency_key=None
    ),
    "matte": lambda o: proto.matte_request(
        TEXTURE, NORMAL, [TEXTURE], normals=None, options=o, wait=0, idempotency_key=None
    ),
    "fill": lambda o: proto.fill_request(
        TEXTURE, NORMAL, texture=None, companions=None, options=o, wait=0, idempotency_key=None
    ),
    "extend": lambda o: proto.extend_request(
        TEXTURE,
        top=1,
        bottom=2,
        left=3,
        right=4,
        companions=None,
        options=o,
        wait=0,
        idempotency_key=None,
    ),
    "wang_tiles": lambda o: proto.wang_request(TEXTURE, options=o, wait=0, idempotency_key=None),
    "extract_alpha": lambda o: proto.extract_request(
        TEXTURE, trimap=NORMAL, scribbles=None, options=o, wait=0, idempotency_key=None
    ),
}
KEYWORDS = {
    "synthesize": {"width": 64, "height": 32},
    "extend": {"top": 1, "bottom": 2, "left": 3, "right": 4},
}


def _sent(spec: proto.RequestSpec) -> dict[str, Any]:
    document: dict[str, Any] = json.loads(spec.data["options"])
    return document


def test_every_operation_with_options_has_a_builder_here() -> None:
    assert set(BUILDERS) | {"tile"} == set(options.schemas())


@pytest.mark.parametrize("operation", sorted(BUILDERS))
def test_every_option_of_the_schema_is_sent_as_given(operation: str) -> None:
    keywords = KEYWORDS.get(operation, {})
    given = {
        name: _json_sample(operation, name)
        for name in options.schemas()[operation]
        if name not in keywords
    }
    assert _sent(BUILDERS[operation](given)) == {**keywords, **given}


@pytest.mark.parametrize("operation", sorted(BUILDERS))
def test_none_options_are_left_to_the_service(operation: str) -> None:
    keywords = KEYWORDS.get(operation, {})
    nothing = {name: None for name in options.schemas()[operation] if name not in keywords}
    assert _sent(BUILDERS[operation](nothing)) == keywords
    # Falsy values that are not None are sent.
    falsy = {"seed": 0, "tolerance": 0.0, "remap": False}
    wanted = {k: v for k, v in falsy.items() if k in options.schemas()[operation]}
    assert _sent(BUILDERS[operation]({**nothing, **wanted})) == {**keywords, **wanted}


def test_an_unknown_option_is_passed_on_for_the_service_to_refuse() -> None:
    # The client documents that the service refuses an unknown name: it is not dropped.
    assert _sent(BUILDERS["synthesize"]({"blok": 20}))["blok"] == 20


def test_the_tile_request_takes_exactly_the_tile_options() -> None:
    names = list(options.schemas()["tile"])
    given: dict[str, Any] = {name: _json_sample("tile", name) for name in names}
    spec = proto.tile_request(TEXTURE, **given)
    assert _sent(spec) == given
    bare = proto.tile_request(TEXTURE, axes="both", band=None)
    assert _sent(bare) == {"axes": "both"}
