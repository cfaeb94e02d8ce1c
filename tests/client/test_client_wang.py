"""``Client.synthesize`` of several examples (the ``texture`` part repeated, a source mask and
a companion map per texture), ``Client.wang_tiles`` / ``submit_wang_tiles`` / ``manifest``, the
same on ``AsyncClient``, and ``quilting-remote synth`` of several inputs and ``wang``, against
the fake service. The real service is exercised end to end in
tests/service/test_client_sources_live.py."""

from __future__ import annotations

import inspect
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from client_fakes import (
    BASE,
    NORMAL,
    NORMAL_OUT,
    RESULT,
    TEXTURE,
    FakeService,
    accepted,
    files_of,
    job_json,
    json_answer,
    options_of,
    png,
    problem,
    sse,
)

from quilting_client import (
    AsyncClient,
    Client,
    JobStatus,
    NotFoundError,
    ValidationError,
    WangTilesResult,
    cli,
)
from quilting_client._options import schemas

SECOND = b"\xff\xd8\xffa second example, as jpeg"
MASK = b"\x89PNG\r\n\x1a\na mask"
ATLAS = b"\x89PNG\r\n\x1a\n" + b"\x00\x00\x00\rIHDR" + bytes.fromhex("0000008000000080") + b"rest"
#: The manifest of a 2-colour set of 32-pixel tiles (its first two tiles listed).
MANIFEST = {
    "format": "quilting.wang",
    "version": 1,
    "tile": 32,
    "colors": 2,
    "columns": 4,
    "rows": 4,
    "edges": ["n", "e", "s", "w"],
    "tiles": [
        {"index": 0, "x": 0, "y": 0, "n": 0, "e": 0, "s": 0, "w": 0},
        {"index": 1, "x": 32, "y": 0, "n": 0, "e": 0, "s": 0, "w": 1},
    ],
    "meta": {"operation": "wang_tiles"},
}


def wang_json(status: str = "queued", **extra: Any) -> dict[str, Any]:
    """A Wang tile set's job status as the service writes it."""
    done = status == "done"
    body = {
        "operation": "wang_tiles",
        "width": 128,
        "height": 128,
        "manifest": "/jobs/j1/manifest" if done else None,
        "layout": "/jobs/j1/layout" if done else None,
        "stats": {"colors": 2, "tile": 32, "tiles": 16} if done else None,
    }
    return job_json(status, **{**body, **extra})


# --- synthesize: several examples --------------------------------------------------------------


def test_synthesize_sends_every_texture_in_order(connect: Callable[..., Any]) -> None:
    service = FakeService().on("POST", "/synthesize", png())
    result = connect(service).synthesize(
        [TEXTURE, SECOND], width=64, height=48, weights=[2, 1], transforms="flips"
    )
    assert result == RESULT and result.job_id == "j1"
    post = service.only("POST", "/synthesize")
    assert files_of(post) == [("texture", "texture", TEXTURE), ("texture", "texture", SECOND)]
    assert options_of(post) == {"width": 64, "height": 48, "weights": [2, 1], "transforms": "flips"}


def test_synthesize_sends_a_mask_and_a_companion_map_per_texture(
    connect: Callable[..., Any], tmp_path: Path
) -> None:
    first, second = tmp_path / "a.png", tmp_path / "b.png"
    first.write_bytes(TEXTURE)
    second.write_bytes(SECOND)
    service = (
        FakeService()
        .on("POST", "/synthesize", png())
        .on("GET", "/jobs/j1/result/normal", png(NORMAL_OUT, job_id=None))
    )
    result = connect(service).synthesize(
        (first, second),
        width=64,
        height=64,
        companions={"normal": [NORMAL, NORMAL + b"2"]},
        companion_kinds={"normal": "normal_dx"},
        source_mask=[MASK, MASK + b"2"],
    )
    assert result.companions == {"normal": NORMAL_OUT}
    post = service.only("POST", "/synthesize")
    assert files_of(post) == [
        ("companion_kinds", None, b'{"normal": "normal_dx"}'),
        ("texture", "a.png", TEXTURE),
        ("texture", "b.png", SECOND),
        ("companion", "normal.png", NORMAL),
        ("companion", "normal.png", NORMAL + b"2"),
        ("source_mask", "source_mask", MASK),
        ("source_mask", "source_mask", MASK + b"2"),
    ]


def test_one_texture_is_sent_as_before(connect: Callable[..., Any]) -> None:
    service = FakeService().on("POST", "/synthesize", png())
    connect(service).synthesize(TEXTURE, width=32, height=32, source_mask=MASK)
    post = service.only("POST", "/synthesize")
    assert files_of(post) == [("texture", "texture", TEXTURE), ("source_mask", "source_mask", MASK)]


@pytest.mark.parametrize(
    ("arguments", "code"),
    [
        ({"texture": []}, "missing_field"),
        ({"texture": [TEXTURE, SECOND], "source_mask": MASK}, "invalid_source_mask"),
        ({"texture": [TEXTURE], "source_mask": [MASK, MASK]}, "invalid_source_mask"),
        ({"texture": [TEXTURE, SECOND], "companions": {"n": NORMAL}}, "invalid_companion"),
        ({"texture": TEXTURE, "companions": {"n": [NORMAL, NORMAL]}}, "invalid_companion"),
    ],
)
def test_examples_that_do_not_match_are_refused_before_sending(
    connect: Callable[..., Any], arguments: dict[str, Any], code: str
) -> None:
    service = FakeService()
    with pytest.raises(ValidationError) as caught:
        connect(service).synthesize(width=32, height=32, **arguments)
    assert caught.value.code == code
    assert service.requests == []


def test_a_weights_problem_names_the_field(connect: Callable[..., Any]) -> None:
    detail = "weights: 1 given for 2 textures; one number > 0 per texture part, in their order"
    service = FakeService().on(
        "POST", "/synthesize", problem(422, "invalid_parameter", detail, field="weights")
    )
    with pytest.raises(ValidationError) as caught:
        connect(service).synthesize([TEXTURE, SECOND], width=32, height=32, weights=[1])
    assert caught.value.field == "weights" and caught.value.status == 422


# --- wang_tiles --------------------------------------------------------------------------------


def test_wang_tiles_answered_at_once_fetches_the_manifest(connect: Callable[..., Any]) -> None:
    service = (
        FakeService()
        .on("POST", "/wang-tiles", png(ATLAS))
        .on("GET", "/jobs/j1/manifest", json_answer(200, MANIFEST))
    )
    client = connect(service)
    tiles = client.wang_tiles(TEXTURE, colors=2, tile=32, block=12, seed=None)
    assert isinstance(tiles, WangTilesResult)
    assert tiles == ATLAS and tiles.atlas == ATLAS and type(tiles.atlas) is bytes
    assert tiles.manifest == MANIFEST and tiles.job_id == "j1"
    assert [t["index"] for t in tiles.tiles] == [0, 1]
    assert service.paths() == ["POST /wang-tiles", "GET /jobs/j1/manifest"]
    post = service.requests[0]
    assert post.url.params["wait"] == "10"
    assert files_of(post) == [("texture", "texture", TEXTURE)]
    assert options_of(post) == {"colors": 2, "tile": 32, "block": 12}


def test_wang_tiles_of_several_follows_the_job(connect: Callable[..., Any]) -> None:
    service = (
        FakeService()
        .on("POST", "/wang-tiles", json_answer(202, wang_json(), {"Location": "/jobs/j1"}))
        .on("GET", "/jobs/j1", json_answer(200, wang_json("running")))
        .on("GET", "/jobs/j1", json_answer(200, wang_json("done")))
        .on("GET", "/jobs/j1/result", png(ATLAS))
        .on("GET", "/jobs/j1/manifest", json_answer(200, MANIFEST))
    )
    tiles = connect(service).wang_tiles(
        [TEXTURE, SECOND], weights=[1, 3], poll_interval=0.05, idempotency_key="w-1"
    )
    assert tiles.atlas == ATLAS and tiles.manifest == MANIFEST
    assert service.paths() == [
        "POST /wang-tiles",
        "GET /jobs/j1",
        "GET /jobs/j1",
        "GET /jobs/j1/result",
        "GET /jobs/j1/manifest",
    ]
    post = service.requests[0]
    assert post.headers["Idempotency-Key"] == "w-1"
    assert files_of(post) == [("texture", "texture", TEXTURE), ("texture", "texture", SECOND)]
    assert options_of(post) == {"weights": [1, 3]}


def test_wang_tiles_with_progress_follows_the_events(connect: Callable[..., Any]) -> None:
    progress = {"progress": 0.45, "stage": "material", "status": "running"}
    service = (
        FakeService()
        .on("POST", "/wang-tiles", accepted())
        .on("GET", "/jobs/j1/events", sse(("progress", progress), ("done", wang_json("done"))))
        .on("GET", "/jobs/j1/result", png(ATLAS))
        .on("GET", "/jobs/j1/manifest", json_answer(200, MANIFEST))
    )
    calls: list[tuple[float, str]] = []
    tiles = connect(service).wang_tiles(TEXTURE, progress=lambda f, s: calls.append((f, s)))
    assert tiles.manifest == MANIFEST
    assert calls[0] == (0.45, "material")


def test_wang_tiles_problems_are_validation_errors(connect: Callable[..., Any]) -> None:
    detail = "tile=33 is not allowed: a tile is two diamond halves"
    service = FakeService().on(
        "POST", "/wang-tiles", problem(422, "invalid_parameter", detail, field="tile")
    )
    with pytest.raises(ValidationError) as caught:
        connect(service).wang_tiles(TEXTURE, tile=33)
    assert caught.value.field == "tile" and detail in str(caught.value)
    assert service.paths() == ["POST /wang-tiles"]


def test_submit_wang_tiles_and_manifest(connect: Callable[..., Any]) -> None:
    service = (
        FakeService()
        .on("POST", "/wang-tiles", json_answer(202, wang_json()))
        .on("GET", "/jobs/j1", json_answer(200, wang_json("done")))
        .on("GET", "/jobs/j1/manifest", json_answer(200, MANIFEST))
        .on("GET", "/jobs/j2/manifest", problem(404, "no_manifest", "a synthesize job has none"))
    )
    client = connect(service)
    job = client.submit_wang_tiles([TEXTURE, SECOND], colors=3)
    assert isinstance(job, JobStatus) and job.operation == "wang_tiles"
    assert job.status == "queued" and job.manifest is None
    assert service.requests[0].url.params["wait"] == "0"
    assert options_of(service.requests[0]) == {"colors": 3}
    done = client.status("j1")
    assert done.manifest == "/jobs/j1/manifest"
    assert client.manifest("j1") == MANIFEST
    with pytest.raises(NotFoundError) as caught:
        client.manifest("j2")
    assert caught.value.code == "no_manifest"


def test_an_atlas_without_a_job_id_is_an_invalid_response(connect: Callable[..., Any]) -> None:
    service = FakeService().on("POST", "/wang-tiles", png(ATLAS, job_id=None))
    with pytest.raises(Exception) as caught:
        connect(service).wang_tiles(TEXTURE)
    assert getattr(caught.value, "code", None) == "invalid_response"


@pytest.mark.parametrize("name", ["wang_tiles", "submit_wang_tiles", "manifest"])
def test_both_clients_have_the_same_signature(name: str) -> None:
    sync, both = getattr(Client, name), getattr(AsyncClient, name)
    assert inspect.signature(sync) == inspect.signature(both)
    assert inspect.iscoroutinefunction(both) and not inspect.iscoroutinefunction(sync)


def test_the_wang_options_are_the_service_s_schema() -> None:
    assert {"colors", "tile", "block", "transforms", "weights", "seed"} <= set(
        schemas()["wang_tiles"]
    )
    doc = Client.wang_tiles.__doc__ or ""
    assert "\ncolors : int" in doc and "WangTilesResult" in doc
    assert "source_mask" in (Client.synthesize.__doc__ or "")


# --- quilting-remote ---------------------------------------------------------------------------


def _files(tmp_path: Path, **contents: bytes) -> dict[str, str]:
    paths = {}
    for name, content in contents.items():
        path = tmp_path / f"{name}.png"
        path.write_bytes(content)
        paths[name] = str(path)
    return paths


def test_cli_synth_of_several_inputs(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    paths = _files(tmp_path, a=TEXTURE, b=SECOND, ma=MASK, mb=MASK + b"2", na=NORMAL, nb=NORMAL)
    fake_cli.on("POST", "/synthesize", png()).on(
        "GET", "/jobs/j1/result/normal", png(NORMAL_OUT, job_id=None)
    )
    out = tmp_path / "out.png"
    argv = ["synth", paths["a"], paths["b"], "-o", str(out), "--server", BASE, "--size", "64x48"]
    argv += ["--weights", "2,1", "--transforms", "rotations"]
    argv += ["--source-mask", paths["ma"], "--source-mask", paths["mb"]]
    argv += ["--with", f"normal:normal_dx={paths['na']},{paths['nb']}"]
    assert cli.main(argv) == 0, capsys.readouterr().err
    assert out.read_bytes() == RESULT
    assert (tmp_path / "out_normal.png").read_bytes() == NORMAL_OUT
    post = fake_cli.only("POST", "/synthesize")
    assert options_of(post) == {
        "width": 64,
        "height": 48,
        "weights": [2.0, 1.0],
        "transforms": "rotations",
    }
    assert [(field, name) for field, name, _ in files_of(post)] == [
        ("companion_kinds", None),
        ("texture", "a.png"),
        ("texture", "b.png"),
        ("companion", "normal.png"),
        ("companion", "normal.png"),
        ("source_mask", "ma.png"),
        ("source_mask", "mb.png"),
    ]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--source-mask", "{ma}"], "--source-mask is given 1 time(s) for 2 input"),
        (["--with", "normal={na}"], "give 2 comma-separated paths"),
        (["--weights", "2,x"], "--weights"),
    ],
)
def test_cli_synth_of_several_inputs_mistakes(
    fake_cli: FakeService,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    extra: list[str],
    message: str,
) -> None:
    paths = _files(tmp_path, a=TEXTURE, b=SECOND, ma=MASK, na=NORMAL)
    argv = ["synth", paths["a"], paths["b"], "-o", str(tmp_path / "o.png"), "--size", "32"]
    assert cli.main([*argv, *[arg.format(**paths) for arg in extra]]) == 2
    assert message in capsys.readouterr().err
    assert fake_cli.requests == []


def test_cli_wang_writes_the_atlas_and_the_manifest(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    paths = _files(tmp_path, a=TEXTURE, b=SECOND)
    fake_cli.on("POST", "/wang-tiles", png(ATLAS)).on(
        "GET", "/jobs/j1/manifest", json_answer(200, MANIFEST)
    )
    out = tmp_path / "tiles.png"
    argv = ["wang", paths["a"], paths["b"], "-o", str(out), "--server", BASE]
    argv += ["--colors", "2", "--tile", "32", "--weights", "1,2"]
    assert cli.main(argv) == 0, capsys.readouterr().err
    assert out.read_bytes() == ATLAS
    assert json.loads((tmp_path / "tiles.json").read_text()) == MANIFEST
    post = fake_cli.only("POST", "/wang-tiles")
    assert options_of(post) == {"colors": 2, "tile": 32, "weights": [1.0, 2.0]}
    assert [name for _, name, _ in files_of(post)] == ["a.png", "b.png"]
    said = capsys.readouterr().out
    assert said.startswith(f"wrote {out} (128x128, 2 tiles), {tmp_path / 'tiles.json'}"), said


def test_cli_wang_manifest_path_and_refusals(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    paths = _files(tmp_path, a=TEXTURE)
    fake_cli.on("POST", "/wang-tiles", png(ATLAS)).on(
        "GET", "/jobs/j1/manifest", json_answer(200, MANIFEST)
    )
    manifest = tmp_path / "set" / "edges.json"
    manifest.parent.mkdir()
    argv = ["wang", paths["a"], "-o", str(tmp_path / "t.png"), "--manifest", str(manifest)]
    assert cli.main([*argv, "--server", BASE]) == 0
    assert json.loads(manifest.read_text())["tile"] == 32
    # The output must be a PNG name; the service's 422 is one line.
    assert cli.main(["wang", paths["a"], "-o", str(tmp_path / "t.jpg")]) == 2
    assert ".png" in capsys.readouterr().err
    fake_cli.routes.clear()
    fake_cli.on(
        "POST",
        "/wang-tiles",
        problem(422, "invalid_parameter", "colors: at most 4", field="colors"),
    )
    argv = ["wang", paths["a"], "-o", str(tmp_path / "u.png"), "--server", BASE, "--colors", "9"]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and "colors" in err
    assert not (tmp_path / "u.png").exists()
