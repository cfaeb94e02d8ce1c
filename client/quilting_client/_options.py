"""The options each operation of the service takes, as command-line flags.

``options.json`` (beside this module) is the service's own schema of each operation's options,
written from its ``/openapi.json`` by ``docs/generate.py`` and kept in step by a test: names,
types, choices and descriptions, no defaults (an option left out is left to the service, whose
defaults are the deployment's). Every option becomes ``--name-with-dashes``; values are checked
by the service, which answers a bad one with a 422 naming it.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Collection, Mapping
from functools import cache
from importlib import resources
from typing import Any

#: Letters of a flag's metavar for the options whose values have a shape of their own.
_METAVARS = {
    "discard": "P",
    "exclude_colors": "LOW:HIGH",
    "light": "X,Y,Z",
    "weights": "W[,W...]",
}


@cache
def schemas() -> dict[str, dict[str, dict[str, Any]]]:
    """Per operation (``synthesize``, ``transfer``, ``matte``, ``tile``, ``fill``,
    ``extend``, ``wang_tiles``), each option's schema, in the service's order."""
    text = resources.files("quilting_client").joinpath("options.json").read_text("utf-8")
    loaded: dict[str, dict[str, dict[str, Any]]] = json.loads(text)
    return loaded


def option_names(operation: str, skip: Collection[str] = ()) -> list[str]:
    """The options of ``operation`` a command sends (those in ``skip`` have flags of their
    own, such as ``--size`` for width and height)."""
    return [name for name in schemas()[operation] if name not in skip]


def add_option_flags(
    parser: argparse.ArgumentParser, operation: str, skip: Collection[str] = ()
) -> None:
    """Add a flag for every option of ``operation`` but those in ``skip``."""
    for name in option_names(operation, skip):
        schema = schemas()[operation][name]
        flag = "--" + name.replace("_", "-")
        kinds = _kinds(schema)
        help_text = str(schema.get("description", ""))
        if name == "exclude_colors":
            parser.add_argument(
                "--exclude-color",
                dest=name,
                action="append",
                type=colour_range,
                metavar=_METAVARS[name],
                help="a colour range never to use, e.g. 120,120,120:255,255,255 "
                f"(repeatable). {help_text}",
            )
        elif name == "light":
            parser.add_argument(
                flag, type=direction, metavar=_METAVARS[name],
                help=f"{help_text} With a negative x write --light=-1,1,2.",
            )  # fmt: skip
        elif "array" in kinds:  # a list of numbers (weights): comma-separated
            parser.add_argument(
                flag, type=numbers, metavar=_METAVARS.get(name, "N[,N...]"),
                help=f"{help_text} Comma-separated, e.g. 2,1,1.",
            )  # fmt: skip
        elif "boolean" in kinds:
            parser.add_argument(flag, action=argparse.BooleanOptionalAction, help=help_text)
        else:
            choices = _choices(schema)
            metavar = _METAVARS.get(name) or ("{" + ",".join(choices) + "}" if choices else None)
            convert = int if "integer" in kinds else float if "number" in kinds else str
            parser.add_argument(flag, type=convert, metavar=metavar, help=help_text)


def given(args: argparse.Namespace, operation: str, skip: Collection[str] = ()) -> dict[str, Any]:
    """The options of ``operation`` given on the command line (the others left out).

    Raises
    ------
    ValueError
        For a value outside an option's choices, naming the flag and the choices: the client
        sends nothing the service would refuse for that.
    """
    found = {
        name: value
        for name in option_names(operation, skip)
        if (value := getattr(args, name, None)) is not None
    }
    for name, value in found.items():
        choices = _choices(schemas()[operation][name])
        if choices and not isinstance(value, list) and str(value) not in choices:
            flag = "--" + name.replace("_", "-")
            raise ValueError(f"{flag} {value!r} is not one of {', '.join(choices)}")
    return found


def _kinds(schema: Mapping[str, Any]) -> set[str]:
    """The JSON types a value may have (``anyOf`` unfolded, null left out)."""
    found = {str(schema["type"])} if "type" in schema else set()
    for part in schema.get("anyOf", ()):
        found |= _kinds(part)
    found.discard("null")
    return found


def _choices(schema: Mapping[str, Any]) -> list[str]:
    values = list(schema.get("enum", ()))
    for part in schema.get("anyOf", ()):
        values += _choices(part)
    return [str(v) for v in values]


def _numbers(text: str, what: str) -> list[float]:
    try:
        return [float(part) for part in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{what} {text!r} is not numbers separated by commas"
        ) from None


def numbers(text: str) -> list[float]:
    """Numbers separated by commas (``2,1,1``)."""
    return _numbers(text, "list")


def colour_range(text: str) -> list[list[float]]:
    """``LOW:HIGH``, each a colour of 1 to 4 numbers (``120,120,120:255,255,255``)."""
    low, colon, high = text.partition(":")
    if not colon:
        raise argparse.ArgumentTypeError(
            f"colour range {text!r} is not LOW:HIGH, e.g. 120,120,120:255,255,255"
        )
    return [_numbers(low, "colour"), _numbers(high, "colour")]


def direction(text: str) -> list[float]:
    """``X,Y,Z``: three numbers (the service checks z > 0)."""
    numbers = _numbers(text, "light")
    if len(numbers) != 3:
        raise argparse.ArgumentTypeError(
            f"light {text!r} is not X,Y,Z (three numbers, y up, z towards the viewer), e.g. 1,1,2"
        )
    return numbers
