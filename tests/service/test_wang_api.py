"""Wang tile sets over ``POST /wang-tiles``: the answer is the atlas of the set (the Python
API's, pixel for pixel), the manifest is ``GET /jobs/{id}/manifest`` (reached from a 200 as
from a 202, through ``X-Job-Id``), the job contract holds (wait, idempotency), the cost of a
set (and of a synthesis of several examples or transforms) is predicted before any work, and
every bad input is a 4xx problem with its code, never a 500."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import httpx
import numpy as np
import pytest
from service_helpers import (
    Server,
    assert_png,
    assert_problem,
    assert_status_document,
    job_id_of,
    texture,
    wait_for,
)

import quilting
from quilting.io import encode_png
from quilting.options import SynthesisOptions, WangOptions, examples_shape

GRAVEL = quilting.read_image(texture("gravel"))
FIRST = np.ascontiguousarray(GRAVEL[:64, :64])
SECOND = np.ascontiguousarray(GRAVEL[100:148, 90:146])
OPTIONS = {"colors": 2, "tile": 32, "block": 12, "seed": 3, "backend": "fft"}
#: A synthesis from gravel.png that fits a job time budget of 5 s, but not with transforms.
SYNTH = {"width": 512, "height": 512, "block": 12}


def _part(image: np.ndarray | bytes, filename: str = "gravel.png") -> tuple[str, Any]:
    data = image if isinstance(image, bytes) else encode_png(image)
    return ("texture", (filename, data, "image/png"))


def _wang(
    client: httpx.Client,
    files: list[tuple[str, Any]],
    options: dict[str, Any] | str | None = None,
    *,
    wait: float = 60,
    headers: dict[str, str] | None = None,
) -> httpx.Response:
    text = options if isinstance(options, str) else json.dumps({**OPTIONS, **(options or {})})
    return client.post(
        "/wang-tiles",
        params={"wait": wait},
        files=files,
        data={"options": text},
        headers=headers,
    )


def _check_manifest(manifest: dict[str, Any], colors: int, tile: int) -> None:
    """The manifest lists the complete set: colors^4 tiles, each once, laid out row by row
    in the atlas, with its four edge colours."""
    side = colors**2
    assert manifest["format"] == "quilting.wang" and manifest["version"] == 1
    assert (manifest["tile"], manifest["colors"]) == (tile, colors)
    assert (manifest["rows"], manifest["columns"]) == (side, side)
    assert manifest["edges"] == ["n", "e", "s", "w"]
    tiles = manifest["tiles"]
    assert len(tiles) == colors**4
    seen = set()
    for k, entry in enumerate(tiles):
        assert entry["index"] == k
        assert (entry["x"], entry["y"]) == ((k % side) * tile, (k // side) * tile)
        edges = tuple(entry[name] for name in ("n", "e", "s", "w"))
        assert all(0 <= c < colors for c in edges), entry
        seen.add(edges)
    assert len(seen) == colors**4  # every combination once: a complete set


def test_wang_tiles_answers_the_atlas_and_the_job_has_the_manifest(client: httpx.Client) -> None:
    response = _wang(client, [_part(FIRST)])
    side = 2**2 * 32
    assert_png(response, side, side)
    assert 'filename="gravel-wang-128x128-seed3.png"' in response.headers["Content-Disposition"]
    # The atlas is the Python API's, pixel for pixel.
    local = quilting.wang_tiles(FIRST, **OPTIONS)
    assert np.array_equal(quilting.read_image(response.content), local.atlas())

    # A 200 names its job as a 202 does: the manifest is one GET away.
    job_id = job_id_of(response)
    manifest = client.get(f"/jobs/{job_id}/manifest")
    assert manifest.status_code == 200
    assert manifest.headers["content-type"] == "application/json"
    assert "gravel-wang-128x128-seed3-manifest.json" in manifest.headers["Content-Disposition"]
    document = manifest.json()
    _check_manifest(document, 2, 32)
    assert document == json.loads(local.to_json())
    # The layout of a set is its manifest (the atlas's layout); it has no seams to draw.
    assert client.get(f"/jobs/{job_id}/layout").json() == document
    assert_problem(client.get(f"/jobs/{job_id}/seams"), 404, "no_seams")

    status = client.get(f"/jobs/{job_id}").json()
    assert status["operation"] == "wang_tiles" and status["status"] == "done"
    assert (status["width"], status["height"]) == (side, side)
    assert status["manifest"] == f"/jobs/{job_id}/manifest"
    assert status["layout"] == f"/jobs/{job_id}/layout"
    assert status["stats"]["tiles"] == 16 and status["companions"] == []
    assert client.get(f"/jobs/{job_id}/result").content == response.content


def test_wang_tiles_of_several_textures_and_three_colours(client: httpx.Client) -> None:
    options = {"colors": 3, "weights": [2, 1], "transforms": "rotations"}
    response = _wang(client, [_part(FIRST, "a.png"), _part(SECOND, "b.png")], options)
    assert_png(response, 9 * 32, 9 * 32)
    local = quilting.wang_tiles([FIRST, SECOND], **{**OPTIONS, **options})
    assert np.array_equal(quilting.read_image(response.content), local.atlas())
    manifest = client.get(f"/jobs/{job_id_of(response)}/manifest").json()
    _check_manifest(manifest, 3, 32)
    assert manifest["meta"]["weights"] == [2.0, 1.0]


def test_wang_tiles_asynchronously_and_idempotently(client: httpx.Client) -> None:
    headers = {"Idempotency-Key": "wang-1"}
    accepted = _wang(client, [_part(FIRST)], {"seed": 11}, wait=0, headers=headers)
    assert accepted.status_code in (200, 202), accepted.text
    job_id = job_id_of(accepted)
    status = wait_for(client, job_id)
    assert status["status"] == "done", status
    assert_status_document(status)
    atlas = client.get(status["result"])
    assert_png(atlas, 128, 128)
    _check_manifest(client.get(status["manifest"]).json(), 2, 32)
    # The same key and body: the same job, answered with its atlas.
    again = _wang(client, [_part(FIRST)], {"seed": 11}, headers=headers)
    assert job_id_of(again) == job_id and again.content == atlas.content
    # The same key, other options: a conflict.
    other = _wang(client, [_part(FIRST)], {"seed": 12}, headers=headers)
    assert_problem(other, 409, "idempotency_conflict")
    # Events end with done, as any job's.
    events = client.get(f"/jobs/{job_id}/events")
    assert "event: done" in events.text


def test_manifest_of_another_job_is_404(client: httpx.Client) -> None:
    response = client.post(
        "/synthesize",
        params={"wait": 60},
        files=[_part(FIRST)],
        data={"options": json.dumps({"width": 48, "height": 40, "block": 12})},
    )
    job_id = job_id_of(response)
    body = assert_problem(client.get(f"/jobs/{job_id}/manifest"), 404, "no_manifest")
    assert "synthesize" in body["detail"]
    assert_problem(client.get("/jobs/0123456789abcdef/manifest"), 404, "job_not_found")


#: Bad submissions: (options, files maker, status, code, field).
BAD: list[tuple[str, dict[str, Any] | str, Callable[[], list[Any]], int, str, str | None]] = [
    ("nine colours", {"colors": 9}, lambda: [_part(FIRST)], 422, "invalid_parameter", "colors"),
    ("one colour", {"colors": 1}, lambda: [_part(FIRST)], 422, "invalid_parameter", "colors"),
    ("an odd tile", {"tile": 33}, lambda: [_part(FIRST)], 422, "invalid_parameter", "tile"),
    ("a tiny tile", {"tile": 8}, lambda: [_part(FIRST)], 422, "invalid_parameter", "tile"),
    (
        "an atlas past the output limits",
        {"colors": 4, "tile": 4096},
        lambda: [_part(FIRST)],
        422,
        "invalid_parameter",
        "tile",
    ),
    ("no texture", {}, lambda: [], 422, "missing_field", "texture"),
    (
        "a texture that is no image",
        {},
        lambda: [_part(b"GIF89a not a png")],
        415,
        "unsupported_media_type",
        "texture",
    ),
    (
        "a texture that is a broken PNG",
        {},
        lambda: [_part(encode_png(FIRST)[:100])],
        422,
        "invalid_image",
        "texture",
    ),
    (
        "too many textures",
        {},
        lambda: [_part(FIRST)] * 9,
        422,
        "too_many_textures",
        "texture",
    ),
    (
        "a weight per texture missing",
        {"weights": [1]},
        lambda: [_part(FIRST), _part(SECOND)],
        422,
        "invalid_parameter",
        "weights",
    ),
    (
        "a weight of 0",
        {"weights": [0]},
        lambda: [_part(FIRST)],
        422,
        "invalid_parameter",
        "weights.0",  # the schema's own error names the item, as for every option
    ),
    (
        "an unknown transform",
        {"transforms": "spin"},
        lambda: [_part(FIRST)],
        422,
        "invalid_parameter",
        "transforms",
    ),
    ("an unknown option", {"size": 3}, lambda: [_part(FIRST)], 422, "invalid_options", "size"),
    ("options not JSON", "{colors: 2", lambda: [_part(FIRST)], 422, "invalid_options", "options"),
    (
        "a block larger than the texture",
        {"block": 80},
        lambda: [_part(FIRST)],
        422,
        "invalid_parameter",
        "block",
    ),
    (
        "examples of different kinds",
        {},
        lambda: [_part(FIRST), _part(quilting.read_image(texture("hubble"))[:64, :64])],
        422,
        "invalid_image",
        "texture",
    ),
    (
        "an unknown backend",
        {"backend": "gpu"},
        lambda: [_part(FIRST)],
        422,
        "invalid_parameter",
        "backend",
    ),
]


@pytest.mark.parametrize(
    ("options", "files", "status", "code", "field"),
    [case[1:] for case in BAD],
    ids=[case[0] for case in BAD],
)
def test_bad_inputs_are_problems(
    client: httpx.Client,
    options: dict[str, Any] | str,
    files: Callable[[], list[Any]],
    status: int,
    code: str,
    field: str | None,
) -> None:
    parts = files()
    if parts:
        response = _wang(client, parts, options)
    else:  # no file part at all: the options alone
        response = client.post("/wang-tiles", data={"options": json.dumps(options)})
    assert_problem(response, status, code, field)


def test_the_cost_of_an_atlas_is_predicted_before_work(
    start_server: Callable[[str, dict[str, str]], Server],
) -> None:
    """With a job time budget of 5 s, a set or a synthesis whose examples' atlas would take
    longer is refused 422 job_too_large at once; a small one runs."""
    budget = quilting.Budget(seconds=5.0)
    texture_shape = (*GRAVEL.shape[:2], 1)
    big_wang = WangOptions(colors=4, tile=256, block=12)
    small_wang = WangOptions(**OPTIONS)
    assert quilting.estimate_wang(big_wang, texture_shape).over(budget)
    assert not quilting.estimate_wang(small_wang, (64, 64, 1)).over(budget)
    plain, turned = SynthesisOptions(block=12), SynthesisOptions(block=12, transforms="all")
    atlas = (*examples_shape([GRAVEL.shape[:2]], turned), 1)
    assert not quilting.estimate_synthesis(plain, texture_shape, (512, 512)).over(budget)
    assert quilting.estimate_synthesis(turned, atlas, (512, 512)).over(budget)
    eight = (*examples_shape([GRAVEL.shape[:2]] * 8, plain), 1)
    assert quilting.estimate_synthesis(plain, eight, (512, 512)).over(budget)

    server = start_server("budget", {"QUILTING_WORKERS": "1", "QUILTING_JOB_TIMEOUT_S": "5"})
    with server.client() as client:
        refused = _wang(client, [_part(GRAVEL)], {"colors": 4, "tile": 256})
        body = assert_problem(refused, 422, "job_too_large")
        assert body["budget_seconds"] == 5.0
        assert_png(_wang(client, [_part(FIRST)]), 128, 128)
        # Transforms multiply the material: the same synthesis with all eight is refused.
        synth = client.post(
            "/synthesize",
            params={"wait": 0},
            files=[_part(GRAVEL)],
            data={"options": json.dumps({**SYNTH, "transforms": "all"})},
        )
        assert_problem(synth, 422, "job_too_large")
        # ... as several examples are: eight copies of it.
        several = client.post(
            "/synthesize",
            params={"wait": 0},
            files=[_part(GRAVEL)] * 8,
            data={"options": json.dumps(SYNTH)},
        )
        assert_problem(several, 422, "job_too_large")
        assert client.get("/readyz").json()["queue_depth"] == 0
