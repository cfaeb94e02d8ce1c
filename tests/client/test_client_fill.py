"""``Client.fill`` / ``Client.extend`` (and their ``submit_*``), the same on ``AsyncClient``,
``tile``'s ``method`` and ``seed``, and ``quilting-remote fill`` / ``extend``, against the fake
service: the parts and options sent, the job followed, the companions fetched, the problems
raised as typed errors. The real service is exercised end to end in
tests/service/test_fill_api.py."""

from __future__ import annotations

import inspect
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
    TILED,
    FakeService,
    accepted,
    files_of,
    job_json,
    json_answer,
    multipart,
    options_of,
    png,
    problem,
    sse,
)

from quilting_client import (
    AsyncClient,
    Client,
    JobStatus,
    SynthesisResult,
    ValidationError,
    cli,
)
from quilting_client._options import schemas

MASK = b"\x89PNG\r\n\x1a\nthe mask\r\n--"
SOURCE = b"\xff\xd8\xffa texture as jpeg"


def fill_json(status: str = "queued", operation: str = "fill", **extra: Any) -> dict[str, Any]:
    """A fill job's status as the service writes it: its companions beside."""
    stats = {"blocks": 12, "filled_pixels": 960, "seam_error_mean": 0.01}
    body = {"operation": operation, "stats": stats if status == "done" else None}
    return job_json(status, **{**body, **extra})


def test_fill_posts_the_image_the_mask_and_the_texture(connect: Callable[..., Any]) -> None:
    service = FakeService().on("POST", "/fill", png())
    client = connect(service)
    result = client.fill(TEXTURE, MASK, texture=SOURCE, block=16, seed=3, overlap=None)
    assert result == RESULT and isinstance(result, SynthesisResult)
    assert result.job_id == "j1" and result.companions == {}
    assert service.paths() == ["POST /fill"] and client.sleeps == []
    post = service.requests[0]
    assert post.url.params["wait"] == "10" and "Idempotency-Key" not in post.headers
    assert files_of(post) == [
        ("image", "image", TEXTURE),
        ("mask", "mask", MASK),
        ("texture", "texture", SOURCE),
    ]
    # None is left to the service's default; no companion_kinds field for a fill.
    assert options_of(post) == {"block": 16, "seed": 3}
    assert [name for name, _, _ in multipart(post)] == ["options", "image", "mask", "texture"]


def test_fill_follows_the_job_and_fetches_the_companions(
    connect: Callable[..., Any], tmp_path: Path
) -> None:
    photo, mask, normal = tmp_path / "photo.png", tmp_path / "hole.png", tmp_path / "n.png"
    photo.write_bytes(TEXTURE)
    mask.write_bytes(MASK)
    normal.write_bytes(NORMAL)
    service = (
        FakeService()
        .on("POST", "/fill", json_answer(202, fill_json(companions=["normal"])))
        .on("GET", "/jobs/j1", json_answer(200, fill_json("running")))
        .on("GET", "/jobs/j1", json_answer(200, fill_json("done", companions=["normal"])))
        .on("GET", "/jobs/j1/result", png())
        .on("GET", "/jobs/j1/result/normal", png(NORMAL_OUT, job_id=None))
    )
    client = connect(service)
    result = client.fill(
        photo, mask, companions={"normal": normal}, poll_interval=0.05, idempotency_key="f-1"
    )
    assert result == RESULT and result.companions == {"normal": NORMAL_OUT}
    assert service.paths() == [
        "POST /fill",
        "GET /jobs/j1",
        "GET /jobs/j1",
        "GET /jobs/j1/result",
        "GET /jobs/j1/result/normal",
    ]
    post = service.requests[0]
    assert post.headers["Idempotency-Key"] == "f-1"
    assert files_of(post) == [
        ("image", "photo.png", TEXTURE),
        ("mask", "hole.png", MASK),
        ("companion", "normal.png", NORMAL),
    ]
    assert options_of(post) == {}


def test_fill_with_progress_follows_the_events(connect: Callable[..., Any]) -> None:
    progress = {"progress": 0.5, "stage": "fill", "status": "running"}
    service = (
        FakeService()
        .on("POST", "/fill", accepted())
        .on("GET", "/jobs/j1/events", sse(("progress", progress), ("done", fill_json("done"))))
        .on("GET", "/jobs/j1/result", png())
    )
    calls: list[tuple[float, str]] = []
    result = connect(service).fill(TEXTURE, MASK, progress=lambda f, s: calls.append((f, s)))
    assert result == RESULT
    assert calls[0] == (0.5, "fill")
    assert service.requests[0].url.params["wait"] == "1"


def test_extend_sends_the_margins_and_the_fill_s_options(connect: Callable[..., Any]) -> None:
    service = (
        FakeService()
        .on("POST", "/extend", png(job_id="j1"))
        .on("GET", "/jobs/j1/result/height", png(NORMAL_OUT, job_id=None))
    )
    client = connect(service)
    result = client.extend(TEXTURE, top=8, right=24, companions={"height": NORMAL}, blend="none")
    assert result == RESULT and result.companions == {"height": NORMAL_OUT}
    post = service.only("POST", "/extend")
    assert options_of(post) == {"top": 8, "bottom": 0, "left": 0, "right": 24, "blend": "none"}
    assert files_of(post) == [("image", "image", TEXTURE), ("companion", "height.png", NORMAL)]


def test_submit_fill_and_submit_extend_do_not_wait(connect: Callable[..., Any]) -> None:
    service = (
        FakeService()
        .on("POST", "/fill", json_answer(202, fill_json()))
        .on("POST", "/extend", json_answer(202, fill_json(operation="extend", id="j2")))
    )
    client = connect(service)
    job = client.submit_fill(TEXTURE, MASK, seed=4)
    assert isinstance(job, JobStatus) and job.operation == "fill" and job.status == "queued"
    extended = client.submit_extend(TEXTURE, left=16, idempotency_key="e-1")
    assert extended.operation == "extend" and extended.id == "j2"
    fill_post, extend_post = service.requests
    assert fill_post.url.params["wait"] == "0" and extend_post.url.params["wait"] == "0"
    assert options_of(fill_post) == {"seed": 4}
    assert options_of(extend_post) == {"top": 0, "bottom": 0, "left": 16, "right": 0}
    assert extend_post.headers["Idempotency-Key"] == "e-1"


@pytest.mark.parametrize(
    ("code", "field", "detail"),
    [
        ("invalid_image", "mask", "mask is 95x96; it must be the image's size, 96x96"),
        ("invalid_parameter", "block", "block=40 is not allowed (allowed: block=20)"),
        ("job_too_large", None, "the job may need up to 5.4 GiB of memory"),
    ],
)
def test_fill_problems_are_validation_errors(
    connect: Callable[..., Any], code: str, field: str | None, detail: str
) -> None:
    members = {} if field is None else {"field": field}
    service = FakeService().on("POST", "/fill", problem(422, code, detail, **members))
    with pytest.raises(ValidationError) as caught:
        connect(service).fill(TEXTURE, MASK, block=40)
    assert caught.value.code == code and caught.value.status == 422
    assert caught.value.field == field and detail in str(caught.value)
    assert service.paths() == ["POST /fill"]


def test_a_bad_companion_name_is_refused_before_sending(connect: Callable[..., Any]) -> None:
    service = FakeService()
    with pytest.raises(ValidationError) as caught:
        connect(service).fill(TEXTURE, MASK, companions={"no/slash": NORMAL})
    assert caught.value.code == "invalid_companion_name"
    with pytest.raises(ValidationError):
        connect(service).extend(TEXTURE, top=4, companions={"": NORMAL})
    assert service.requests == []


def test_tile_sends_method_and_seed_only_when_given(connect: Callable[..., Any]) -> None:
    service = FakeService().on("POST", "/tile", png(TILED, job_id=None))
    client = connect(service)
    assert client.tile(TEXTURE, method="fill", seed=9, blend="none") == TILED
    assert client.tile(TEXTURE) == TILED
    first, second = service.requests
    assert options_of(first) == {"axes": "both", "blend": "none", "method": "fill", "seed": 9}
    assert options_of(second) == {"axes": "both"}


@pytest.mark.parametrize("name", ["fill", "submit_fill", "extend", "submit_extend"])
def test_both_clients_have_the_same_signature(name: str) -> None:
    sync, both = getattr(Client, name), getattr(AsyncClient, name)
    assert inspect.signature(sync) == inspect.signature(both)
    assert inspect.iscoroutinefunction(both) and not inspect.iscoroutinefunction(sync)


def test_the_options_are_the_service_s_schemas() -> None:
    fill_options, extend_options = schemas()["fill"], schemas()["extend"]
    assert {"block", "overlap", "blend", "seed", "backend"} <= set(fill_options)
    assert set(extend_options) == set(fill_options) | {"top", "bottom", "left", "right"}
    assert {"method", "seed"} <= set(schemas()["tile"])
    doc = Client.extend.__doc__ or ""
    assert "\ntop : int" in doc and "Other Parameters" in doc


# --- quilting-remote ---------------------------------------------------------------------------


def _inputs(tmp_path: Path) -> dict[str, Path]:
    paths = {}
    for name, content in [("in", TEXTURE), ("mask", MASK), ("tex", SOURCE), ("n", NORMAL)]:
        paths[name] = tmp_path / f"{name}.png"
        paths[name].write_bytes(content)
    return paths


def test_cli_fill_sends_the_parts_and_the_flags(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    paths = _inputs(tmp_path)
    fake_cli.on("POST", "/fill", png()).on(
        "GET", "/jobs/j1/result/normal", png(NORMAL_OUT, job_id=None)
    )
    out = tmp_path / "out.png"
    argv = ["fill", str(paths["in"]), "--mask", str(paths["mask"]), "-o", str(out)]
    argv += ["--server", BASE, "--block", "16", "--blend", "none", "--seed", "7"]
    argv += ["--with", f"normal={paths['n']}"]
    assert cli.main(argv) == 0, capsys.readouterr().err
    assert out.read_bytes() == RESULT
    assert (tmp_path / "out_normal.png").read_bytes() == NORMAL_OUT
    post = fake_cli.only("POST", "/fill")
    assert options_of(post) == {"block": 16, "blend": "none", "seed": 7}
    assert files_of(post) == [
        ("image", "in.png", TEXTURE),
        ("mask", "mask.png", MASK),
        ("companion", "normal.png", NORMAL),
    ]
    assert capsys.readouterr().out.startswith(f"wrote {out}, {tmp_path / 'out_normal.png'} (")


def test_cli_fill_with_a_texture(fake_cli: FakeService, tmp_path: Path) -> None:
    paths = _inputs(tmp_path)
    fake_cli.on("POST", "/fill", png())
    argv = ["fill", str(paths["in"]), "--mask", str(paths["mask"]), "--texture", str(paths["tex"])]
    assert cli.main([*argv, "-o", str(tmp_path / "o.png"), "--server", BASE]) == 0
    post = fake_cli.only("POST", "/fill")
    assert ("texture", "tex.png", SOURCE) in files_of(post)


def test_cli_extend_sends_the_margins(fake_cli: FakeService, tmp_path: Path) -> None:
    paths = _inputs(tmp_path)
    fake_cli.on("POST", "/extend", png())
    out = tmp_path / "wide.png"
    argv = ["extend", str(paths["in"]), "-o", str(out), "--server", BASE]
    assert cli.main([*argv, "--left", "32", "--right", "32", "--block", "24"]) == 0
    assert out.read_bytes() == RESULT
    post = fake_cli.only("POST", "/extend")
    assert options_of(post) == {"top": 0, "bottom": 0, "left": 32, "right": 32, "block": 24}


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["extend", "{in}", "-o", "{out}"], "at least one of --top"),
        (["fill", "{in}", "--mask", "{mask}", "-o", "{out}", "--with", "n:hard={n}"], "KIND"),
        (["fill", "{in}", "--mask", "{mask}", "-o", "{out}", "--blend", "feather"], "--blend"),
        (["fill", "{in}", "-o", "{out}"], "--mask"),
    ],
)
def test_cli_fill_and_extend_mistakes_are_one_line(
    fake_cli: FakeService,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    argv: list[str],
    message: str,
) -> None:
    paths = {name: str(path) for name, path in _inputs(tmp_path).items()}
    paths["out"] = str(tmp_path / "o.png")
    assert cli.main([arg.format(**paths) for arg in argv]) == 2
    err = capsys.readouterr().err
    assert message in err, err
    assert fake_cli.requests == []


def test_cli_fill_a_refused_request_is_one_line(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    paths = _inputs(tmp_path)
    detail = "mask is 95x96; it must be the image's size, 96x96"
    fake_cli.on("POST", "/fill", problem(422, "invalid_image", detail, field="mask"))
    argv = ["fill", str(paths["in"]), "--mask", str(paths["mask"]), "-o", str(tmp_path / "o.png")]
    assert cli.main([*argv, "--server", BASE]) == 2
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and err.count("\n") == 1, err
    assert "95x96" in err and "96x96" in err
    assert not (tmp_path / "o.png").exists()
