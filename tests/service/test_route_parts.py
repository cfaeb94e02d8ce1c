"""Unit tests of :mod:`quilting.service.routes.parts`, the form parts the submission routes
share, read the way the routes read them.

A tiny FastAPI app declares routes with the module's part types (``TextureParts``,
``CompanionParts``, ``CompanionKindsField``, ``SourceMaskPart``/``SourceMaskParts``,
``TrimapParts``, ``LayerTrimapParts``...) and reads them with the routes' own readers
(:mod:`quilting.service.submit`, :mod:`quilting.service.forms`), driven in-process with
Starlette's ``TestClient``: no server, no pixel decoded (a part is an image by its first
bytes here; its pixels are checked later, elsewhere).

Covers
------
- Good parts arrive exactly: the texture's bytes and file name, companions by their file
  name's stem (a path dropped), their kinds, the source mask, the parsed options; with
  several textures each companion's maps in the textures' order; marks (trimap, scribbles)
  one per photo, an empty part standing for none.
- Refusals, each a problem+json with its status, stable code and ``field``: companion names
  (a dot, a blank, a non-ASCII letter, 65 characters, a repeat, no file name), companion
  kinds (not JSON, not an object, a name no companion has, an unknown kind, not a string),
  a part that is neither PNG nor JPEG (415) or over ``max_file_bytes`` (413), too many
  companions or textures, a source mask, weights or marks not one per texture or layer, a
  mark sent as text, a missing part; the first bad part in the routes' order is the one named.
- The options part of every route: not JSON, not an object, an unknown or misspelt member, a
  wrong type and a value out of range, each 422 with its code and field.
- ``SUBMIT_RESPONSES`` and ``EXTRACTING_RESPONSES``: the statuses these refusals answer are
  declared as problem+json; the extraction header is added without changing the shared 200.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from typing import Annotated, Any

import pytest
from fastapi import FastAPI, File, Form, UploadFile
from fastapi.testclient import TestClient

from quilting.options import SynthesisOptions
from quilting.service import forms, submit
from quilting.service.context import Service
from quilting.service.deps import ExampleParts, LayerParts, SingleParts
from quilting.service.handlers import PROBLEM_JSON, add_exception_handlers
from quilting.service.problems import Problem
from quilting.service.routes import parts
from quilting.service.settings import Settings

#: A PNG by its signature: the routes recognize an image from its first bytes.
PNG = b"\x89PNG\r\n\x1a\n"
JPEG = b"\xff\xd8\xff\xe0"
SETTINGS = Settings(backend="fft", max_file_bytes=64, max_companions=3, max_textures=3)
OPTIONS = json.dumps({"width": 40, "height": 30, "block": 12, "seed": 7})


def png(tag: str) -> bytes:
    return PNG + tag.encode()


def _hex(data: bytes | None) -> str | None:
    return None if data is None else data.hex()


def make_app(settings: Settings) -> FastAPI:
    app = FastAPI()
    add_exception_handlers(app)
    service = Service.build(settings)
    app.state.service = service
    app.state.draining = False

    @app.post("/one", dependencies=SingleParts, responses=parts.SUBMIT_RESPONSES)
    async def one(
        texture: Annotated[UploadFile, File()],
        options: Annotated[str, Form()],
        companion: parts.CompanionParts = None,
        companion_kinds: parts.CompanionKindsField = None,
        source_mask: parts.SourceMaskPart = None,
    ) -> dict[str, Any]:
        width, height, parsed = forms.synthesis_options(
            options, service.models.synthesize, settings
        )
        found = await submit.texture_parts(
            texture, companion, companion_kinds, source_mask, settings
        )
        return {
            "size": [width, height],
            "options": parsed.to_dict(),
            "texture": _hex(found["texture"]),
            "texture_name": found["texture_name"],
            "companions": {n: _hex(d) for n, d in found["companions"].items()},
            "kinds": found["companion_kinds"],
            "source_mask": _hex(found["source_mask"]),
        }

    @app.post("/several", dependencies=ExampleParts, responses=parts.EXTRACTING_RESPONSES)
    async def several(
        texture: parts.TextureParts,
        options: Annotated[str, Form()],
        companion: parts.CompanionParts = None,
        companion_kinds: parts.CompanionKindsField = None,
        source_mask: parts.SourceMaskParts = None,
        trimap: parts.TrimapParts = None,
        scribbles: parts.ScribblesParts = None,
    ) -> dict[str, Any]:
        _, _, parsed = forms.synthesis_options(options, service.models.synthesize, settings)
        submit.count_examples(texture, source_mask, parsed, settings)
        found = await submit.example_parts(
            texture, companion, companion_kinds, source_mask, settings, trimap, scribbles
        )
        return {
            "texture": _hex(found["texture"]),
            "examples": [_hex(d) for d in found.get("examples", [])],
            "companions": {
                n: [_hex(d) for d in maps]
                for n, maps in found.get("example_companions", {}).items()
            },
            "first_companions": {n: _hex(d) for n, d in found["companions"].items()},
            "kinds": found["companion_kinds"],
            "source_masks": [_hex(d) for d in found.get("source_masks", [])],
            "trimaps": [_hex(d) for d in found["trimaps"]],
            "scribbles": [_hex(d) for d in found["scribbles"]],
        }

    @app.post("/layers", dependencies=LayerParts)
    async def layers(
        layer: Annotated[list[UploadFile], File()],
        trimap: parts.LayerTrimapParts = None,
        scribbles: parts.LayerScribblesParts = None,
    ) -> dict[str, Any]:
        count = len(layer)
        marks = {
            name: await submit.read_marks(given, count, name, "layer", settings)
            for name, given in (("trimap", trimap), ("scribbles", scribbles))
        }
        return {name: [_hex(d) for d in found] for name, found in marks.items()}

    return app


@pytest.fixture(scope="module")
def client() -> Iterator[TestClient]:
    with TestClient(make_app(SETTINGS)) as test_client:
        yield test_client


Files = list[tuple[str, tuple[str | None, bytes | str]]]


def one_form(*extra: tuple[str, tuple[str | None, bytes | str]]) -> Files:
    return [("texture", ("brick.png", png("t"))), ("options", (None, OPTIONS)), *extra]


def assert_problem(response: Any, status: int, code: str, field: str) -> dict[str, Any]:
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == PROBLEM_JSON
    body: dict[str, Any] = response.json()
    assert (body["status"], body["code"], body.get("field")) == (status, code, field)
    assert "Traceback" not in response.text
    return body


# --- one texture ---------------------------------------------------------------------------


def test_the_parts_of_one_texture_arrive_exactly(client: TestClient) -> None:
    response = client.post(
        "/one",
        files=one_form(
            ("companion", ("maps/normal.png", png("n"))),
            ("companion", ("rough_2-b.jpg", JPEG + b"r")),
            ("companion_kinds", (None, '{"normal": "normal_dx", "rough_2-b": "hard"}')),
            ("source_mask", ("mask.png", png("m"))),
        ),
    )
    assert response.status_code == 200, response.text
    assert response.json() == {
        "size": [40, 30],
        "options": json.loads(
            json.dumps(SynthesisOptions(block=12, seed=7, backend="fft").to_dict())
        ),
        "texture": png("t").hex(),
        "texture_name": "brick.png",
        "companions": {"normal": png("n").hex(), "rough_2-b": (JPEG + b"r").hex()},
        "kinds": {"normal": "normal_dx", "rough_2-b": "hard"},
        "source_mask": png("m").hex(),
    }


@pytest.mark.parametrize("kinds", [None, "", "  \n", "{}"])
def test_no_companion_kinds_is_none(client: TestClient, kinds: str | None) -> None:
    extra: Files = [("companion", ("n.png", png("n")))]
    if kinds is not None:
        extra.append(("companion_kinds", (None, kinds)))
    response = client.post("/one", files=one_form(*extra))
    assert response.status_code == 200, response.text
    assert response.json()["kinds"] == {} and list(response.json()["companions"]) == ["n"]


def test_a_companion_name_of_64_characters_is_taken(client: TestClient) -> None:
    name = "A" * 32 + "z_-9" * 8
    response = client.post("/one", files=one_form(("companion", (name + ".png", png("c")))))
    assert response.status_code == 200 and list(response.json()["companions"]) == [name]


@pytest.mark.parametrize(
    "names",
    [
        ["normal.map.png"],
        ["bad name.png"],
        ["normé.png"],
        ["x" * 65 + ".png"],
        [".png"],
        ["n.png", "dir/n.png"],
        ["n.png", "n.jpg"],
    ],
    ids=["dot", "blank", "non-ascii", "65-chars", "empty-stem", "same-stem-path", "same-stem"],
)
def test_a_companion_name_the_service_refuses(client: TestClient, names: list[str]) -> None:
    extra = [("companion", (name, png("c"))) for name in names]
    body = assert_problem(
        client.post("/one", files=one_form(*extra)), 422, "invalid_companion", "companion"
    )
    assert repr(names[-1]) in body["detail"] or names[-1] in body["detail"]


def test_a_companion_without_a_file_name_is_422_naming_it(client: TestClient) -> None:
    assert_problem(
        client.post("/one", files=one_form(("companion", (None, "normal")))),
        422,
        "invalid_parameter",
        "companion",
    )


def test_more_companions_than_the_limit_are_refused(client: TestClient) -> None:
    limit = SETTINGS.max_companions
    extra = [("companion", (f"c{i}.png", png(str(i)))) for i in range(limit)]
    assert client.post("/one", files=one_form(*extra)).status_code == 200
    extra.append(("companion", ("last.png", png("x"))))
    body = assert_problem(
        client.post("/one", files=one_form(*extra)), 422, "invalid_companion", "companion"
    )
    assert str(limit) in body["detail"]


@pytest.mark.parametrize(
    ("kinds", "code"),
    [
        ('{"normal": ', "invalid_parameter"),
        ('["normal"]', "invalid_parameter"),
        ('"hard"', "invalid_parameter"),
        ("null", "invalid_parameter"),
        ('{"other": "hard"}', "invalid_companion"),
        ('{"Normal": "hard"}', "invalid_companion"),
        ('{"normal": "soft"}', "invalid_parameter"),
        ('{"normal": "HARD"}', "invalid_parameter"),
        ('{"normal": 1}', "invalid_parameter"),
        ('{"normal": null}', "invalid_parameter"),
        ('{"normal": ["hard"]}', "invalid_parameter"),
    ],
)
def test_companion_kinds_the_service_refuses(client: TestClient, kinds: str, code: str) -> None:
    extra: Files = [("companion", ("normal.png", png("n"))), ("companion_kinds", (None, kinds))]
    assert_problem(client.post("/one", files=one_form(*extra)), 422, code, "companion_kinds")


def test_kinds_without_companions_name_none_uploaded(client: TestClient) -> None:
    body = assert_problem(
        client.post("/one", files=one_form(("companion_kinds", (None, '{"n": "hard"}')))),
        422,
        "invalid_companion",
        "companion_kinds",
    )
    assert "uploaded:" not in body["detail"]
    extra: Files = [
        ("companion", ("a.png", png("a"))),
        ("companion_kinds", (None, '{"n": "hard"}')),
    ]
    body = client.post("/one", files=one_form(*extra)).json()
    assert "uploaded: a" in body["detail"]


@pytest.mark.parametrize(
    ("files", "status", "code", "field"),
    [
        ([("texture", ("t.gif", b"GIF89a..."))], 415, "unsupported_media_type", "texture"),
        ([("texture", ("t.png", b""))], 415, "unsupported_media_type", "texture"),
        ([("companion", ("c.png", b"<svg/>"))], 415, "unsupported_media_type", "companion"),
        ([("source_mask", ("m.png", b"BM..."))], 415, "unsupported_media_type", "source_mask"),
        ([("texture", ("t.png", PNG + b"x" * 57))], 413, "file_too_large", "texture"),
        ([("companion", ("c.png", PNG + b"x" * 57))], 413, "file_too_large", "companion"),
        ([("source_mask", ("m.png", PNG + b"x" * 57))], 413, "file_too_large", "source_mask"),
    ],
)
def test_a_part_that_is_no_image_or_too_large_is_refused(
    client: TestClient, files: Files, status: int, code: str, field: str
) -> None:
    form = dict(one_form())
    form.update(files)
    body = assert_problem(client.post("/one", files=list(form.items())), status, code, field)
    if status == 413:
        assert str(SETTINGS.max_file_bytes) in body["detail"]


def test_a_file_of_exactly_max_file_bytes_is_taken(client: TestClient) -> None:
    data = PNG + b"x" * (SETTINGS.max_file_bytes - len(PNG))
    form = dict(one_form())
    form["texture"] = ("t.png", data)
    response = client.post("/one", files=list(form.items()))
    assert response.status_code == 200 and response.json()["texture"] == data.hex()


def test_the_first_bad_part_in_the_routes_order_is_named(client: TestClient) -> None:
    bad = b"not an image"
    form = [
        ("source_mask", ("m.png", bad)),
        ("companion", ("c.png", bad)),
        ("texture", ("t.png", bad)),
        ("options", (None, OPTIONS)),
    ]
    assert_problem(client.post("/one", files=form), 415, "unsupported_media_type", "texture")
    form[2] = ("texture", ("t.png", png("t")))
    assert_problem(client.post("/one", files=form), 415, "unsupported_media_type", "companion")


@pytest.mark.parametrize("missing", ["texture", "options"])
def test_a_missing_part_is_422_missing_field(client: TestClient, missing: str) -> None:
    form = [part for part in one_form() if part[0] != missing]
    assert_problem(client.post("/one", files=form), 422, "missing_field", missing)


def test_a_texture_sent_as_text_is_422_naming_it(client: TestClient) -> None:
    form = [("texture", (None, "brick.png")), ("options", (None, OPTIONS))]
    assert_problem(client.post("/one", files=form), 422, "invalid_parameter", "texture")


def test_a_repeated_single_part_is_refused_before_anything_is_read(client: TestClient) -> None:
    form = one_form(("texture", ("b.png", b"not an image")))
    assert_problem(client.post("/one", files=form), 422, "duplicate_part", "texture")


# --- several textures ----------------------------------------------------------------------


def test_several_textures_companions_masks_and_marks_arrive_in_order(client: TestClient) -> None:
    form: Files = [
        ("texture", ("a.png", png("A"))),
        ("texture", ("b.png", png("B"))),
        ("options", (None, json.dumps({"width": 8, "height": 8, "weights": [1, 2]}))),
        ("companion", ("normal.png", png("nA"))),
        ("companion", ("normal.png", png("nB"))),
        ("companion_kinds", (None, '{"normal": "normal"}')),
        ("source_mask", ("ma.png", png("mA"))),
        ("source_mask", ("mb.png", png("mB"))),
        ("trimap", (None, "")),
        ("trimap", ("tb.png", png("tB"))),
        ("scribbles", ("sa.png", png("sA"))),
        ("scribbles", ("empty.png", b"")),
    ]
    response = client.post("/several", files=form)
    assert response.status_code == 200, response.text
    assert response.json() == {
        "texture": png("A").hex(),
        "examples": [png("A").hex(), png("B").hex()],
        "companions": {"normal": [png("nA").hex(), png("nB").hex()]},
        "first_companions": {"normal": png("nA").hex()},
        "kinds": {"normal": "normal"},
        "source_masks": [png("mA").hex(), png("mB").hex()],
        "trimaps": [None, png("tB").hex()],
        "scribbles": [png("sA").hex(), None],
    }


def test_one_texture_of_the_several_route_is_a_job_of_one(client: TestClient) -> None:
    form: Files = [
        ("texture", ("a.png", png("A"))),
        ("options", (None, '{"width": 8, "height": 8}')),
        ("trimap", (None, "")),
    ]
    response = client.post("/several", files=form)
    assert response.status_code == 200, response.text
    body = response.json()
    assert body["texture"] == png("A").hex()
    assert (body["examples"], body["companions"], body["trimaps"]) == ([], {}, [])


def _several(count: int, *extra: tuple[str, tuple[str | None, bytes | str]]) -> Files:
    textures: Files = [("texture", (f"t{k}.png", png(f"t{k}"))) for k in range(count)]
    return [*textures, ("options", (None, '{"width": 8, "height": 8}')), *extra]


@pytest.mark.parametrize(
    ("form", "code", "field"),
    [
        (_several(4), "too_many_textures", "texture"),
        (_several(2, ("companion", ("n.png", png("n")))), "invalid_companion", "companion"),
        (
            _several(2, *[("companion", ("n.png", png(str(k)))) for k in range(3)]),
            "invalid_companion",
            "companion",
        ),
        (_several(2, ("source_mask", ("m.png", png("m")))), "invalid_source_mask", "source_mask"),
        (_several(2, ("trimap", ("t.png", png("t")))), "invalid_trimap", "trimap"),
        (
            _several(2, ("scribbles", (None, "")), ("scribbles", (None, "strokes"))),
            "invalid_trimap",
            "scribbles",
        ),
        (
            [
                *_several(2)[:2],
                ("options", (None, '{"width": 8, "height": 8, "weights": [1, 2, 3]}')),
            ],
            "invalid_parameter",
            "weights",
        ),
    ],
    ids=[
        "too-many",
        "companion-once",
        "companion-thrice",
        "one-mask",
        "one-trimap",
        "text-scribbles",
        "three-weights",
    ],
)
def test_several_textures_refusals(client: TestClient, form: Files, code: str, field: str) -> None:
    assert_problem(client.post("/several", files=form), 422, code, field)


# --- marks of layers -----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("marks", "expected"),
    [
        ([], []),
        ([(None, ""), (None, "")], []),
        ([("e.png", b""), ("e.png", b"")], []),
        ([("t.png", png("t")), (None, "")], [png("t").hex(), None]),
        ([(None, ""), ("t.png", png("t"))], [None, png("t").hex()]),
    ],
    ids=["none", "empty-fields", "empty-files", "first", "second"],
)
def test_marks_are_one_per_layer_an_empty_part_for_none(
    client: TestClient, marks: list[tuple[str | None, bytes | str]], expected: list[str | None]
) -> None:
    form: Files = [("layer", ("a.png", png("a"))), ("layer", ("b.png", png("b")))]
    form += [("trimap", mark) for mark in marks]
    response = client.post("/layers", files=form)
    assert response.status_code == 200, response.text
    assert response.json() == {"trimap": expected, "scribbles": []}


@pytest.mark.parametrize(
    "marks",
    [
        [("t.png", png("t"))],
        [(None, ""), (None, ""), (None, "")],
        [("t.png", png("t")), (None, "not a file")],
    ],
    ids=["one-for-two", "three-for-two", "text"],
)
def test_marks_not_one_per_layer_are_refused(
    client: TestClient, marks: list[tuple[str | None, bytes | str]]
) -> None:
    form: Files = [("layer", ("a.png", png("a"))), ("layer", ("b.png", png("b")))]
    form += [("scribbles", mark) for mark in marks]
    body = assert_problem(client.post("/layers", files=form), 422, "invalid_trimap", "scribbles")
    assert "layer" in body["detail"]


def test_a_mark_that_is_no_image_is_415(client: TestClient) -> None:
    form: Files = [("layer", ("a.png", png("a"))), ("trimap", ("t.png", b"GIF89a"))]
    assert_problem(client.post("/layers", files=form), 415, "unsupported_media_type", "trimap")


# --- the options part ----------------------------------------------------------------------

MODELS = Service.build(SETTINGS).models
#: Each route's options parser, with a member the route knows (its first, in range).
PARSERS: dict[str, tuple[Callable[[str], Any], dict[str, Any]]] = {
    "synthesize": (
        lambda t: forms.synthesis_options(t, MODELS.synthesize, SETTINGS),
        {"width": 8, "height": 8},
    ),
    "transfer": (lambda t: forms.transfer_options(t, MODELS.transfer), {}),
    "fill": (lambda t: forms.fill_options(t, MODELS.fill), {}),
    "extend": (lambda t: forms.extend_options(t, MODELS.extend), {}),
    "wang_tiles": (lambda t: forms.wang_options(t, MODELS.wang_tiles, SETTINGS), {}),
    "extract_alpha": (lambda t: forms.alpha_options(t, MODELS.extract_alpha), {}),
}
#: A member of each route's options: a wrong type, and a value out of range, for it.
MEMBERS = {
    "synthesize": ("block", "32", 2),
    "transfer": ("iterations", 2.0, 9),
    "fill": ("search_scale", True, 65),
    "extend": ("top", "1", -1),
    "wang_tiles": ("colors", 3.5, 5),
    "extract_alpha": ("method", 1, "lkmx"),
}


def _refusal(parse: Callable[[str], Any], text: str) -> Problem:
    with pytest.raises(Problem) as caught:
        parse(text)
    return caught.value


@pytest.mark.parametrize("route", PARSERS)
def test_an_options_part_that_is_no_json_object_is_invalid_options(route: str) -> None:
    parse, _ = PARSERS[route]
    for text in ("", "{", "{'block': 3}", "[]", "null", "3", '"{}"', "{}}"):
        problem = _refusal(parse, text)
        assert (problem.status, problem.code, problem.extra["field"]) == (
            422,
            "invalid_options",
            "options",
        ), text


@pytest.mark.parametrize("route", PARSERS)
def test_an_options_part_s_members_are_checked_by_name(route: str) -> None:
    parse, base = PARSERS[route]
    name, wrong_type, out_of_range = MEMBERS[route]
    for extra in ({name + "s": 1}, {name.capitalize(): 1}, {"": 1}):
        problem = _refusal(parse, json.dumps({**base, **extra}))
        assert (problem.status, problem.code) == (422, "invalid_options")
        assert problem.extra["field"] == (next(iter(extra)) or "options")
    for value in (wrong_type, out_of_range, None):
        problem = _refusal(parse, json.dumps({**base, name: value}))
        assert (problem.status, problem.code, problem.extra["field"]) == (
            422,
            "invalid_parameter",
            name,
        ), value
    parsed = parse(json.dumps(base))
    assert parsed is not None


# --- the declared answers ------------------------------------------------------------------


def test_the_declared_answers_are_problems_and_the_extraction_adds_a_header(
    client: TestClient,
) -> None:
    document = client.get("/openapi.json").json()
    one = document["paths"]["/one"]["post"]["responses"]
    several = document["paths"]["/several"]["post"]["responses"]
    for responses in (one, several):
        for status in (401, 409, 413, 415, 422, 503):
            content = responses[str(status)]["content"]
            assert content[PROBLEM_JSON]["schema"] == {"$ref": "#/components/schemas/Problem"}
        assert "image/png" in responses["200"]["content"] and "202" in responses
    assert "Quilting-Extracted" in several["200"]["headers"]
    assert "headers" not in one["200"]
    assert "headers" not in parts.SUBMIT_RESPONSES[200]
    assert parts.EXTRACTING_RESPONSES[200]["content"] == parts.SUBMIT_RESPONSES[200]["content"]


def test_every_status_these_parts_answer_is_declared(client: TestClient) -> None:
    forms_ = [
        one_form(("companion", ("c.png", b"GIF89a"))),
        one_form(("source_mask", ("m.png", PNG + b"x" * 60))),
        one_form(("companion_kinds", (None, "[]"))),
        [("texture", ("t.png", png("t"))), ("options", (None, "{"))],
    ]
    answered = {client.post("/one", files=form).status_code for form in forms_}
    assert answered == {413, 415, 422}
    assert answered <= set(parts.SUBMIT_RESPONSES)
