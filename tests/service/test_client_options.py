"""The remote client takes every option the service takes: its copy of the options schemas
is the service's ``/openapi.json``, and its command line has a flag for each option."""

from __future__ import annotations

import argparse
import importlib.util
import json
from pathlib import Path
from typing import Any

import pytest

from quilting.service.app import create_app
from quilting.service.settings import Settings
from quilting_client import _options
from quilting_client.cli import build_parser

ROOT = Path(__file__).resolve().parents[2]
COMMANDS = {
    "synthesize": "synth",
    "transfer": "transfer",
    "matte": "matte",
    "tile": "tile",
    "fill": "fill",
    "extend": "extend",
    "wang_tiles": "wang",
}


def _generator() -> Any:
    spec = importlib.util.spec_from_file_location("generate", ROOT / "docs" / "generate.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


#: The component of each operation's options in the OpenAPI document (the generator's table).
COMPONENTS: dict[str, str] = _generator().OPERATIONS


def _subparser(command: str) -> argparse.ArgumentParser:
    for action in build_parser()._actions:
        if isinstance(action, argparse._SubParsersAction):
            found: argparse.ArgumentParser = action.choices[command]
            return found
    raise AssertionError("no subcommands")


def test_the_client_s_schemas_are_the_service_s() -> None:
    committed = (ROOT / "client" / "quilting_client" / "options.json").read_text()
    assert committed == _generator().client_options()


@pytest.mark.parametrize("operation", sorted(COMMANDS))
def test_every_option_of_the_service_has_a_flag(operation: str) -> None:
    published = create_app(Settings()).openapi()["components"]["schemas"][COMPONENTS[operation]]
    wanted = set(published["properties"])
    assert wanted == set(_options.schemas()[operation])
    dests = {action.dest for action in _subparser(COMMANDS[operation])._actions}
    if operation == "synthesize":
        wanted -= {"width", "height"}
        assert "size" in dests
    assert wanted <= dests, sorted(wanted - dests)


def test_flags_given_are_sent_and_only_those() -> None:
    argv = [
        "synth", "in.png", "-o", "o.png", "--size", "64x32", "--block", "20", "--feather", "3",
        "--tileable", "x", "--exclude-color", "0,0,0:0.1,0.1,0.1", "--eta", "5",
    ]  # fmt: skip
    args = build_parser().parse_args(argv)
    sent = _options.given(args, "synthesize", skip=("width", "height"))
    assert sent == {
        "block": 20,
        "feather": 3,
        "tileable": "x",
        "exclude_colors": [[[0.0, 0.0, 0.0], [0.1, 0.1, 0.1]]],
        "eta": 5.0,
    }
    json.dumps(sent)  # what the client puts in the options form field


def test_a_value_outside_the_choices_is_refused_before_sending() -> None:
    args = build_parser().parse_args(["transfer", "t.png", "g.png", "-o", "o.png", "--mode", "x"])
    with pytest.raises(ValueError, match="--mode 'x' is not one of overlap, cut"):
        _options.given(args, "transfer")


def test_booleans_take_both_spellings() -> None:
    base = ["transfer", "t.png", "g.png", "-o", "o.png"]
    assert _options.given(build_parser().parse_args([*base, "--no-remap"]), "transfer") == {
        "remap": False
    }
    assert _options.given(build_parser().parse_args([*base, "--remap"]), "transfer") == {
        "remap": True
    }
