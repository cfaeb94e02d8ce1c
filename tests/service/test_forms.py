"""The submission's form fields read on their own, without an app: the options schema, the
JSON checks, the engine options, the companion kinds and the idempotency digest."""

from __future__ import annotations

import hashlib
import json

import pytest

from quilting.options import SynthesisOptions, TransferOptions
from quilting.service import forms
from quilting.service.problems import Problem
from quilting.service.schemas import options_model
from quilting.service.settings import Settings

SETTINGS = Settings()
SYNTHESIZE = options_model(SETTINGS)
TRANSFER = options_model(SETTINGS, TransferOptions, name="TransferOptions", sized=False)


def _problem(call: object, *args: object) -> Problem:
    with pytest.raises(Problem) as caught:
        call(*args)  # type: ignore[operator]
    return caught.value


@pytest.mark.parametrize(
    ("text", "depth"),
    [("{}", 1), ("[[[]]]", 3), ('{"a": "[[[[["}', 1), ("not json [", 1), ("", 0), ('"]]"', 0)],
)
def test_json_depth_counts_brackets_outside_strings(text: str, depth: int) -> None:
    assert forms.json_depth(text) == depth


def test_a_deep_or_long_or_broken_options_field_is_refused_with_its_code() -> None:
    deep = "[" * (forms.MAX_OPTIONS_DEPTH + 1) + "]" * (forms.MAX_OPTIONS_DEPTH + 1)
    assert _problem(forms.options_object, deep).code == "invalid_options"
    long = '{"a": "' + "x" * forms.MAX_OPTIONS_CHARS + '"}'
    assert "characters" in _problem(forms.options_object, long).detail
    assert "not JSON" in _problem(forms.options_object, "{").detail
    assert "JSON object" in _problem(forms.options_object, "[1]").detail
    assert forms.options_object('{"block": 32}') == {"block": 32}


def test_synthesis_options_are_validated_once_into_the_engine_s() -> None:
    width, height, options = forms.synthesis_options(
        '{"width": 300, "height": 200, "block": 32, "seed": 4}', SYNTHESIZE, SETTINGS
    )
    assert (width, height) == (300, 200)
    assert options == SynthesisOptions(block=32, seed=4, backend=SETTINGS.backend)


@pytest.mark.parametrize(
    ("text", "code", "field"),
    [
        ('{"height": 10}', "invalid_parameter", "width"),
        ('{"width": 10, "height": 10, "block": "32"}', "invalid_parameter", "block"),
        ('{"width": 10, "height": 10, "colour": 1}', "invalid_options", "colour"),
        ('{"width": 10, "height": 10, "block": 2}', "invalid_parameter", "block"),
        ('{"width": 10, "height": 10, "overlap": 40}', "invalid_parameter", "overlap"),
    ],
)
def test_synthesis_options_refusals_name_the_field(text: str, code: str, field: str) -> None:
    problem = _problem(forms.synthesis_options, text, SYNTHESIZE, SETTINGS)
    assert (problem.status, problem.code, problem.extra.get("field")) == (422, code, field)


def test_an_output_over_the_pixel_limit_is_refused() -> None:
    side = SETTINGS.max_side
    text = f'{{"width": {side}, "height": {side}}}'
    assert side * side > SETTINGS.max_output_pixels
    assert (
        "max_output_pixels" in _problem(forms.synthesis_options, text, SYNTHESIZE, SETTINGS).detail
    )


def test_custom_correspondence_says_why_it_is_not_offered() -> None:
    problem = _problem(forms.transfer_options, '{"correspondence": "custom"}', TRANSFER)
    assert problem.extra.get("field") == "correspondence" and "Python API" in problem.detail
    options = forms.transfer_options('{"correspondence": "blurred"}', TRANSFER)
    assert isinstance(options, TransferOptions) and options.correspondence == "blurred"


def test_companion_kinds() -> None:
    companions = {"normal": b"", "mask": b""}
    assert forms.companion_kinds(None, companions) == {}
    assert forms.companion_kinds('{"normal": "normal", "mask": "hard"}', companions) == {
        "normal": "normal",
        "mask": "hard",
    }
    assert _problem(forms.companion_kinds, '{"other": "hard"}', companions).code == (
        "invalid_companion"
    )
    assert _problem(forms.companion_kinds, '{"mask": "soft"}', companions).code == (
        "invalid_parameter"
    )


def test_the_digest_is_the_request_not_the_file_names() -> None:
    options = SynthesisOptions(seed=1)
    one = forms.Submission("synthesize", options, b"png", {}, size=(8, 8), texture_name="a.png")
    renamed = forms.Submission("synthesize", options, b"png", {}, size=(8, 8), texture_name="b")
    other = forms.Submission("transfer", options, b"png", {}, size=(8, 8))
    bigger = forms.Submission("synthesize", options, b"png", {}, size=(9, 8))
    assert one.digest() == renamed.digest()
    assert len({one.digest(), other.digest(), bigger.digest()}) == 3


def test_the_digest_of_one_texture_is_unchanged_and_several_are_ordered() -> None:
    options = SynthesisOptions(block=12)
    one = forms.Submission("synthesize", options, texture=b"a", companions={}, size=(8, 8))
    document = {
        "operation": "synthesize",
        "size": [8, 8],
        "options": options.to_dict(),
        "files": [["texture", "", hashlib.sha256(b"a").hexdigest()]],
    }
    # One texture digests as it did before several examples existed.
    expected = hashlib.sha256(json.dumps(document, sort_keys=True).encode()).hexdigest()
    assert one.digest() == expected
    several = forms.Submission(
        "synthesize", options, texture=b"a", companions={}, size=(8, 8), examples=[b"a", b"b"]
    )
    swapped = forms.Submission(
        "synthesize", options, texture=b"b", companions={}, size=(8, 8), examples=[b"b", b"a"]
    )
    assert len({one.digest(), several.digest(), swapped.digest()}) == 3


def test_weights_are_a_list_of_numbers_above_zero() -> None:
    model = options_model(Settings())
    values = forms.validate({"width": 8, "height": 8, "weights": [1, 2.5]}, model)
    assert values["weights"] == [1.0, 2.5]
    assert forms.engine_options(
        {k: v for k, v in values.items() if k not in ("width", "height")}, SynthesisOptions
    ).weights == (1.0, 2.5)
    for bad in ([0], [-1], [], "1,2", [True], list(range(1, 10))):
        with pytest.raises(Problem) as caught:
            forms.validate({"width": 8, "height": 8, "weights": bad}, model)
        assert caught.value.extra["field"].split(".")[0] == "weights"
