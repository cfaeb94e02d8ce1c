"""``Client.extract_alpha`` (and ``submit_extract_alpha``), the ``trimap`` and ``scribbles`` of
``synthesize`` and ``matte``, the same on ``AsyncClient``, and ``quilting-remote
extract-alpha`` / ``synth --trimap`` / ``matte --trimap LAYER=FILE``, against the fake
service: the parts sent (an empty one for a photo without a map), the summary read from the
``Quilting-Extracted`` header on either path, the mistakes refused before anything is sent.
The real service is exercised end to end in tests/service/test_client_extract_live.py."""

from __future__ import annotations

import inspect
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import pytest
from client_fakes import (
    BASE,
    RESULT,
    TEXTURE,
    FakeService,
    files_of,
    job_json,
    json_answer,
    options_of,
    problem,
)

from quilting_client import AsyncClient, Client, JobStatus, ValidationError, cli
from quilting_client._options import schemas

PHOTO = b"\x89PNG\r\n\x1a\na photo of smoke"
TRIMAP = b"\x89PNG\r\n\x1a\nits trimap"
STROKES = b"\x89PNG\r\n\x1a\nits scribbles"
SUMMARY = {"method": "lkm", "foreground": "ml", "unknown": 0.42, "iterations": 77, "seconds": 1.5}


def extracted_png(entries: list[Any], job_id: str = "j1") -> Callable[..., httpx.Response]:
    """A 200 PNG answer carrying the extraction summaries, as the service sends them."""
    headers = {
        "Content-Type": "image/png",
        "X-Job-Id": job_id,
        "Location": f"/jobs/{job_id}",
        "Quilting-Extracted": json.dumps(entries, separators=(",", ":")),
    }
    return lambda request: httpx.Response(200, content=RESULT, headers=headers)


def test_extract_alpha_posts_the_photo_and_its_maps(connect: Callable[..., Any]) -> None:
    service = FakeService().on("POST", "/extract-alpha", extracted_png([SUMMARY]))
    client = connect(service)
    result = client.extract_alpha(PHOTO, TRIMAP, STROKES, method="cf", foreground=None)
    assert result == RESULT and result.job_id == "j1"
    assert result.extracted == [SUMMARY]
    post = service.only("POST", "/extract-alpha")
    assert files_of(post) == [
        ("photo", "photo", PHOTO),
        ("trimap", "trimap", TRIMAP),
        ("scribbles", "scribbles", STROKES),
    ]
    assert options_of(post) == {"method": "cf"}


def test_a_followed_extraction_reads_the_summary_from_the_result(
    connect: Callable[..., Any],
) -> None:
    """202, then the job's status, then its result: the header of the result's GET counts."""
    done = job_json("done", operation="extract_alpha", stats={"extracted": [SUMMARY]})
    service = (
        FakeService()
        .on("POST", "/extract-alpha", json_answer(202, job_json("queued")))
        .on("GET", "/jobs/j1", json_answer(200, done))
        .on("GET", "/jobs/j1/result", extracted_png([SUMMARY]))
    )
    client = connect(service)
    result = client.extract_alpha(PHOTO, scribbles=STROKES, poll_interval=0.05)
    assert result == RESULT and result.extracted == [SUMMARY]
    assert service.paths() == ["POST /extract-alpha", "GET /jobs/j1", "GET /jobs/j1/result"]
    assert [name for name, _, _ in files_of(service.requests[0])] == ["photo", "scribbles"]


def test_submit_extract_alpha_does_not_wait(connect: Callable[..., Any]) -> None:
    service = FakeService().on("POST", "/extract-alpha", json_answer(202, job_json("queued")))
    status = connect(service).submit_extract_alpha(PHOTO, TRIMAP, idempotency_key="x-1")
    assert isinstance(status, JobStatus) and status.id == "j1"
    post = service.only("POST", "/extract-alpha")
    assert post.url.params["wait"] == "0" and post.headers["Idempotency-Key"] == "x-1"


def test_no_map_is_refused_before_anything_is_sent(connect: Callable[..., Any]) -> None:
    service = FakeService()
    client = connect(service)
    with pytest.raises(ValidationError) as caught:
        client.extract_alpha(PHOTO)
    assert caught.value.code == "invalid_trimap" and caught.value.field == "trimap"
    assert service.requests == []


def test_the_service_s_refusal_is_a_typed_error(connect: Callable[..., Any]) -> None:
    detail = "trimap is 32x64 but the photo is 64x64: draw it over the photo, at its size"
    service = FakeService().on(
        "POST", "/extract-alpha", problem(422, "invalid_trimap", detail, field="trimap")
    )
    with pytest.raises(ValidationError) as caught:
        connect(service).extract_alpha(PHOTO, TRIMAP)
    assert caught.value.code == "invalid_trimap" and caught.value.field == "trimap"
    assert "32x64" in str(caught.value)


def test_synthesize_sends_one_map_per_texture_an_empty_part_for_none(
    connect: Callable[..., Any],
) -> None:
    service = FakeService().on("POST", "/synthesize", extracted_png([SUMMARY, None]))
    client = connect(service)
    result = client.synthesize(
        [PHOTO, TEXTURE], width=64, height=32, trimap=[TRIMAP, None], matting="knn"
    )
    assert result.extracted == [SUMMARY, None]
    post = service.only("POST", "/synthesize")
    assert files_of(post) == [
        ("texture", "texture", PHOTO),
        ("texture", "texture", TEXTURE),
        ("trimap", "trimap", TRIMAP),
        ("trimap", "none.png", b""),
    ]
    assert options_of(post) == {"width": 64, "height": 32, "matting": "knn"}


def test_one_texture_takes_one_map_and_a_result_without_header_has_none(
    connect: Callable[..., Any],
) -> None:
    service = (
        FakeService()
        .on("POST", "/synthesize", extracted_png([SUMMARY]))
        .on("POST", "/synthesize", lambda request: httpx.Response(
            200, content=RESULT, headers={"Content-Type": "image/png", "X-Job-Id": "j2"}
        ))
    )  # fmt: skip
    client = connect(service)
    assert client.synthesize(PHOTO, width=8, height=8, scribbles=STROKES).extracted == [SUMMARY]
    assert client.synthesize(TEXTURE, width=8, height=8).extracted == []
    first, second = service.requests
    assert ("scribbles", "scribbles", STROKES) in files_of(first)
    assert [name for name, _, _ in files_of(second)] == ["texture"]


def test_a_wrong_count_of_maps_is_refused_before_sending(connect: Callable[..., Any]) -> None:
    service = FakeService()
    client = connect(service)
    with pytest.raises(ValidationError) as caught:
        client.synthesize([PHOTO, TEXTURE], width=8, height=8, trimap=[TRIMAP])
    assert caught.value.code == "invalid_trimap" and caught.value.field == "trimap"
    with pytest.raises(ValidationError):
        client.matte(TEXTURE, TEXTURE, [TEXTURE, PHOTO], scribbles=[STROKES])
    with pytest.raises(TypeError):
        client.matte(TEXTURE, TEXTURE, [TEXTURE, PHOTO], trimap=TRIMAP)
    assert service.requests == []


def test_matte_sends_one_map_per_layer(connect: Callable[..., Any]) -> None:
    service = FakeService().on("POST", "/matte", extracted_png([None, SUMMARY]))
    client = connect(service)
    result = client.matte(TEXTURE, TEXTURE, [TEXTURE, PHOTO], trimap=[None, TRIMAP])
    assert result.extracted == [None, SUMMARY]
    names = [(name, filename) for name, filename, _ in files_of(service.only("POST", "/matte"))]
    assert names[-2:] == [("trimap", "none.png"), ("trimap", "trimap")]


@pytest.mark.parametrize("name", ["extract_alpha", "submit_extract_alpha"])
def test_both_clients_have_the_same_signature(name: str) -> None:
    sync, both = getattr(Client, name), getattr(AsyncClient, name)
    assert inspect.signature(sync) == inspect.signature(both)
    assert inspect.iscoroutinefunction(both) and not inspect.iscoroutinefunction(sync)


def test_the_options_and_docs_come_from_the_service_s_schema() -> None:
    assert set(schemas()["extract_alpha"]) == {"method", "foreground"}
    assert "matting" in schemas()["synthesize"] and "matting" in schemas()["matte"]
    doc = Client.extract_alpha.__doc__ or ""
    assert "\nmethod : " in doc and "invalid_trimap" in doc
    assert "trimap, scribbles" in (Client.synthesize.__doc__ or "")


# --- quilting-remote ---------------------------------------------------------------------------


def _paths(tmp_path: Path) -> dict[str, Path]:
    paths = {}
    for name, content in [("smoke", PHOTO), ("tri", TRIMAP), ("lines", STROKES), ("t", TEXTURE)]:
        paths[name] = tmp_path / f"{name}.png"
        paths[name].write_bytes(content)
    return paths


def test_cli_extract_alpha_writes_the_texture_and_says_how(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    paths = _paths(tmp_path)
    fake_cli.on("POST", "/extract-alpha", extracted_png([SUMMARY]))
    out = tmp_path / "smoke_rgba.png"
    argv = ["extract-alpha", str(paths["smoke"]), "--trimap", str(paths["tri"])]
    argv += ["--method", "knn", "-o", str(out), "--server", BASE]
    assert cli.main(argv) == 0, capsys.readouterr().err
    assert out.read_bytes() == RESULT
    post = fake_cli.only("POST", "/extract-alpha")
    assert files_of(post) == [("photo", "smoke.png", PHOTO), ("trimap", "tri.png", TRIMAP)]
    assert options_of(post) == {"method": "knn"}
    said = capsys.readouterr().out
    assert said.startswith(f"wrote {out} (") and "alpha extracted (lkm, 42 % unknown" in said


def test_cli_extract_alpha_needs_a_map(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    paths = _paths(tmp_path)
    argv = ["extract-alpha", str(paths["smoke"]), "-o", str(tmp_path / "o.png"), "--server", BASE]
    assert cli.main(argv) == 2
    assert "--trimap" in capsys.readouterr().err and fake_cli.requests == []


def test_cli_synth_and_matte_send_the_maps(fake_cli: FakeService, tmp_path: Path) -> None:
    paths = _paths(tmp_path)
    fake_cli.on("POST", "/synthesize", extracted_png([SUMMARY, None]))
    fake_cli.on("POST", "/matte", extracted_png([None, SUMMARY]))
    argv = ["synth", str(paths["smoke"]), str(paths["t"]), "--size", "32x32"]
    argv += ["--trimap", str(paths["tri"]), "--trimap=", "--matting", "cf"]
    assert cli.main([*argv, "-o", str(tmp_path / "s.png"), "--server", BASE]) == 0
    synth = fake_cli.only("POST", "/synthesize")
    assert [(n, f) for n, f, _ in files_of(synth)][-2:] == [
        ("trimap", "tri.png"),
        ("trimap", "none.png"),
    ]
    assert options_of(synth)["matting"] == "cf"
    argv = ["matte", str(paths["t"]), "--silhouette", str(paths["t"])]
    argv += ["--layer", str(paths["t"]), "--layer", str(paths["smoke"])]
    argv += ["--scribbles", f"2={paths['lines']}"]
    assert cli.main([*argv, "-o", str(tmp_path / "m.png"), "--server", BASE]) == 0
    matte = fake_cli.only("POST", "/matte")
    assert [(n, f) for n, f, _ in files_of(matte)][-2:] == [
        ("scribbles", "none.png"),
        ("scribbles", "lines.png"),
    ]


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--trimap", "x.png"], "once per input"),  # one --trimap for two inputs
        (["--trimap=", "--trimap="], "empty for every input"),
    ],
)
def test_cli_synth_refuses_maps_that_are_not_one_per_input(
    fake_cli: FakeService,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    extra: list[str],
    words: str,
) -> None:
    paths = _paths(tmp_path)
    argv = ["synth", str(paths["smoke"]), str(paths["t"]), "--size", "32x32", *extra]
    assert cli.main([*argv, "-o", str(tmp_path / "s.png"), "--server", BASE]) == 2
    assert words in capsys.readouterr().err and fake_cli.requests == []


@pytest.mark.parametrize("spec", ["3=a.png", "x.png", "0=a.png"])
def test_cli_matte_refuses_a_bad_layer_number(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str], spec: str
) -> None:
    paths = _paths(tmp_path)
    argv = ["matte", str(paths["t"]), "--silhouette", str(paths["t"])]
    argv += ["--layer", str(paths["t"]), "--layer", str(paths["smoke"]), "--trimap", spec]
    assert cli.main([*argv, "-o", str(tmp_path / "m.png"), "--server", BASE]) == 2
    assert "LAYER" in capsys.readouterr().err and fake_cli.requests == []
