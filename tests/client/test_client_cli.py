"""``quilting-remote`` (``quilting_client.cli``) against a fake service: files written, options
sent, and every mistake one line with its exit status."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import httpx
import pytest
from client_fakes import (
    BASE,
    CLUSTERS_OUT,
    FAILED,
    LAYER_0,
    LAYER_1,
    NORMAL,
    NORMAL_OUT,
    NORMALS_IN,
    RESULT,
    ROUGH,
    SILHOUETTE,
    TARGET,
    TEXTURE,
    TILED,
    TRANSFERRED,
    FakeService,
    Handler,
    fails,
    files_of,
    json_answer,
    matte_files,
    multipart,
    options_of,
    png,
    problem,
)

from quilting_client import (
    cli,
)


def test_cli_writes_the_result_and_the_companions(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    (tmp_path / "n.png").write_bytes(NORMAL)
    fake_cli.on("POST", "/synthesize", png()).on(
        "GET", "/jobs/j1/result/normal", png(NORMAL_OUT, job_id=None)
    )
    out = tmp_path / "out.png"
    status = cli.main(
        [
            "synth",
            str(tmp_path / "in.png"),
            "-o",
            str(out),
            "--server",
            BASE,
            "--size",
            "64x32",
            "--block",
            "16",
            "--seed",
            "3",
            "--with",
            f"normal={tmp_path / 'n.png'}",
        ]
    )
    assert status == 0
    assert out.read_bytes() == RESULT
    assert (tmp_path / "out_normal.png").read_bytes() == NORMAL_OUT
    post = fake_cli.only("POST", "/synthesize")
    assert options_of(post) == {"width": 64, "height": 32, "block": 16, "seed": 3}
    assert ("companion", "normal.png", NORMAL) in multipart(post)
    captured = capsys.readouterr()
    assert "out.png" in captured.out and captured.err == ""  # stderr is no terminal: no bar


def test_cli_with_name_kind_sends_the_kind(fake_cli: FakeService, tmp_path: Path) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    (tmp_path / "m.png").write_bytes(ROUGH)
    (tmp_path / "n.png").write_bytes(NORMAL)
    fake_cli.on("POST", "/synthesize", png()).on(
        "GET", "/jobs/j1/result/mask", png(b"mask out", job_id=None)
    ).on("GET", "/jobs/j1/result/normal", png(NORMAL_OUT, job_id=None))
    argv = ["synth", str(tmp_path / "in.png"), "-o", str(tmp_path / "out.png"), "--server", BASE]
    argv += ["--size", "64x32", "--with", f"mask:hard={tmp_path / 'm.png'}"]
    assert cli.main([*argv, "--with", f"normal={tmp_path / 'n.png'}"]) == 0
    post = fake_cli.only("POST", "/synthesize")
    fields = {name: body for name, filename, body in multipart(post) if filename is None}
    assert json.loads(fields["companion_kinds"]) == {"mask": "hard"}
    assert ("companion", "mask.png", ROUGH) in multipart(post)
    assert (tmp_path / "out_mask.png").read_bytes() == b"mask out"
    # An unknown kind is a usage error, before anything is sent.
    bad = [*argv[:-1], f"mask:soft={tmp_path / 'm.png'}"]
    assert cli.main(bad) != 0


def test_cli_transfer_writes_the_result_and_sends_only_given_options(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    (tmp_path / "target.png").write_bytes(TARGET)
    (tmp_path / "n.png").write_bytes(NORMAL)
    fake_cli.on("POST", "/transfer", png(TRANSFERRED)).on(
        "GET", "/jobs/j1/result/normal", png(NORMAL_OUT, job_id=None)
    )
    out = tmp_path / "out.png"
    argv = ["transfer", str(tmp_path / "in.png"), str(tmp_path / "target.png"), "-o", str(out)]
    options = ["--block", "16", "--iterations", "2", "--no-remap", "--correspondence", "blurred"]
    extra = ["--alpha", "0.25", "--min-block", "8", "--shade", "1.25"]
    extra += ["--with", f"normal={tmp_path / 'n.png'}"]
    assert cli.main([*argv, "--server", BASE, *options, *extra]) == 0
    assert out.read_bytes() == TRANSFERRED
    assert (tmp_path / "out_normal.png").read_bytes() == NORMAL_OUT
    post = fake_cli.only("POST", "/transfer")
    assert options_of(post) == {
        "block": 16,
        "iterations": 2,
        "remap": False,
        "correspondence": "blurred",
        "alpha": 0.25,
        "min_block": 8,
        "shade": 1.25,
    }
    parts = multipart(post)
    assert ("target", "target.png", TARGET) in parts and ("texture", "in.png", TEXTURE) in parts
    captured = capsys.readouterr()
    # The size is the target's, read from the PNG that came back.
    assert "(48x40, job j1)" in captured.out and captured.err == ""


@pytest.mark.parametrize(
    "args",
    [
        ["transfer", "{in}", "-o", "{out}", "--server", BASE],  # no target
        ["transfer", "{in}", "{missing}", "-o", "{out}", "--server", BASE],
        ["transfer", "{in}", "{in}", "-o", "{out}", "--server", BASE, "--alpha", "half"],
    ],
)
def test_cli_transfer_user_errors_exit_2(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str]
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    paths = {"in": tmp_path / "in.png", "out": tmp_path / "o.png", "missing": tmp_path / "no.png"}
    assert cli.main([a.format(**paths) for a in args]) == 2
    assert "error:" in capsys.readouterr().err
    assert fake_cli.requests == []


def test_cli_transfer_refused_by_the_service_exits_2(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    answer = problem(422, "invalid_parameter", "alpha: must be at most 1", field="alpha")
    fake_cli.on("POST", "/transfer", answer)
    argv = ["transfer", str(tmp_path / "in.png"), str(tmp_path / "in.png"), "-o"]
    assert cli.main([*argv, str(tmp_path / "o.png"), "--server", BASE, "--alpha", "2"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and err.count("\n") == 1
    assert "alpha" in err and not (tmp_path / "o.png").exists()


def test_cli_reads_server_and_key_from_the_environment(
    fake_cli: FakeService, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    monkeypatch.setenv("QUILTING_SERVER", BASE)
    monkeypatch.setenv("QUILTING_API_KEY", "from-env")
    fake_cli.on("POST", "/synthesize", png())
    args = ["synth", str(tmp_path / "in.png"), "-o", str(tmp_path / "o.png"), "--size", "8"]
    assert cli.main(args) == 0
    assert fake_cli.factory_calls == [(BASE, "from-env")]  # type: ignore[attr-defined]
    assert fake_cli.requests[0].headers["Authorization"] == "Bearer from-env"


SYNTH = ("/synthesize", ["synth", "--size", "8x8"])
TILE = ("/tile", ["tile", "--band", "1000"])


@pytest.mark.parametrize(
    ("command", "answer", "expected", "text"),
    [
        (SYNTH, problem(422, "invalid_parameter", "block must be >= 2", field="block"), 2, "block"),
        (SYNTH, problem(401, "unauthorized", "missing API key"), 2, "missing API key"),
        (SYNTH, problem(500, "internal_error", "worker crashed"), 1, "worker crashed"),
        (SYNTH, problem(503, "queue_full", "queue is full"), 1, "queue is full"),
        (SYNTH, fails(httpx.ConnectError("connection refused")), 1, "connection refused"),
        (
            TILE,
            problem(422, "invalid_parameter", "band=1000 is not allowed", field="band"),
            2,
            "band",
        ),
        (TILE, problem(401, "unauthorized", "missing API key"), 2, "missing API key"),
        (TILE, problem(503, "draining", "the service is shutting down"), 1, "shutting down"),
        (TILE, fails(httpx.ConnectError("connection refused")), 1, "connection refused"),
        (TILE, fails(httpx.ReadTimeout("timed out")), 1, "timed out"),
    ],
)
def test_cli_errors_are_one_line_with_exit_status(
    fake_cli: FakeService,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    command: tuple[str, list[str]],
    answer: Handler,
    expected: int,
    text: str,
) -> None:
    """``quilting-remote COMMAND in.png -o out.png`` answered ``answer``: exit status
    ``expected``, one line on stderr saying ``text``, no output file."""
    path, words = command
    (tmp_path / "in.png").write_bytes(TEXTURE)
    fake_cli.on("POST", path, answer)
    out = tmp_path / "out.png"
    args = [words[0], str(tmp_path / "in.png"), "-o", str(out), "--server", BASE, *words[1:]]
    assert cli.main(args) == expected
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and err.count("\n") == 1, err
    assert text in err
    assert not out.exists()


def test_cli_failed_job_exits_1(fake_cli: FakeService, tmp_path: Path) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    engine_failure = {**FAILED, "error": {**FAILED["error"], "status": None}}
    fake_cli.on("POST", "/synthesize", json_answer(202, engine_failure))
    args = [
        "synth",
        str(tmp_path / "in.png"),
        "-o",
        str(tmp_path / "o.png"),
        "--server",
        BASE,
        "--size",
        "8x8",
    ]
    assert cli.main(args) == 1


@pytest.mark.parametrize(
    "args",
    [
        ["synth", "{missing}", "-o", "{out}", "--size", "8x8", "--server", BASE],
        ["synth", "{in}", "-o", "{out}", "--size", "8x8", "--server", BASE, "--with", "normal"],
        ["synth", "{in}", "-o", "{out}", "--size", "eight", "--server", BASE],
        [
            "synth",
            "{in}",
            "-o",
            "{out}",
            "--size",
            "8",
            "--server",
            BASE,
            "--with",
            "a=x",
            "--with",
            "a=y",
        ],
    ],
)
def test_cli_user_errors_exit_2(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str]
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    paths = {"in": tmp_path / "in.png", "out": tmp_path / "o.png", "missing": tmp_path / "no.png"}
    argv = [a.format(**paths) for a in args]
    assert cli.main(argv) == 2
    assert "error:" in capsys.readouterr().err
    assert fake_cli.requests == []


def test_cli_progress_bar_draws_only_on_a_terminal() -> None:
    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    terminal, pipe = Terminal(), io.StringIO()
    for stream in (terminal, pipe):
        bar = cli.ProgressBar(stream)
        bar(0.5, "quilting")
        bar(1.0, "done")
    assert pipe.getvalue() == ""
    drawn = terminal.getvalue()
    assert drawn.count("\r") == 2 and drawn.endswith("\n") and drawn.count("\n") == 1
    assert "50.0%" in drawn and "100.0%" in drawn


@pytest.mark.parametrize("command", ["synth", "transfer"])
@pytest.mark.parametrize(
    ("given", "sent"),
    [
        ([], {}),
        (["--error", "luminance"], {"error": "luminance"}),
        (["--discard", "0.25"], {"discard": 0.25}),
        (["--discard", "0", "--error", "rgb"], {"discard": 0.0, "error": "rgb"}),
    ],
)
def test_cli_sends_error_and_discard_only_when_given(
    fake_cli: FakeService,
    tmp_path: Path,
    command: str,
    given: list[str],
    sent: dict[str, Any],
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    fake_cli.on("POST", "/synthesize", png()).on("POST", "/transfer", png(TRANSFERRED))
    texture, out = str(tmp_path / "in.png"), str(tmp_path / "o.png")
    if command == "synth":
        argv = ["synth", texture, "-o", out, "--size", "64x32", "--block", "16"]
        expected = {"width": 64, "height": 32, "block": 16, **sent}
    else:
        argv = ["transfer", texture, texture, "-o", out, "--block", "16"]
        expected = {"block": 16, **sent}
    assert cli.main([*argv, "--server", BASE, *given]) == 0
    post = fake_cli.only("POST", "/synthesize" if command == "synth" else "/transfer")
    assert options_of(post) == expected


def test_cli_with_companions_sends_each_and_writes_each_beside_the_output(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    (tmp_path / "n.png").write_bytes(NORMAL)
    (tmp_path / "r.jpg").write_bytes(ROUGH)
    fake_cli.on("POST", "/synthesize", png()).on(
        "GET", "/jobs/j1/result/normal", png(NORMAL_OUT, job_id=None)
    ).on("GET", "/jobs/j1/result/rough-2", png(b"quilted rough", job_id=None))
    folder = tmp_path / "out"
    folder.mkdir()
    out = folder / "brick.png"
    argv = ["synth", str(tmp_path / "in.png"), "-o", str(out), "--size", "64x32"]
    extra = ["--with", f"normal={tmp_path / 'n.png'}", "--with", f"rough-2={tmp_path / 'r.jpg'}"]
    assert cli.main([*argv, "--server", BASE, *extra]) == 0
    parts = multipart(fake_cli.only("POST", "/synthesize"))
    companions = [(filename, body) for name, filename, body in parts if name == "companion"]
    assert sorted(companions) == [("normal.png", NORMAL), ("rough-2.png", ROUGH)]
    assert sorted(p.name for p in folder.iterdir()) == [
        "brick.png",
        "brick_normal.png",
        "brick_rough-2.png",
    ]
    assert out.read_bytes() == RESULT
    assert (folder / "brick_normal.png").read_bytes() == NORMAL_OUT
    assert (folder / "brick_rough-2.png").read_bytes() == b"quilted rough"
    [line] = capsys.readouterr().out.splitlines()
    assert "brick_normal.png" in line and "brick_rough-2.png" in line


@pytest.mark.parametrize(
    ("with_args", "fragment"),
    [
        (["normal"], "is not NAME[:KIND]=PATH"),
        (["normal="], "is not NAME[:KIND]=PATH"),
        (["={n}"], "the name '' is not"),
        (["../evil={n}"], "the name '../evil'"),
        (["a b={n}"], "the name 'a b'"),
        ([f"{'n' * 65}={{n}}"], "is not 1 to 64"),
        (["n={n}", "n={n}"], "'n' is given twice"),
        (["n={n}", "m={missing}"], "no.png"),
    ],
)
@pytest.mark.parametrize("command", ["synth", "transfer"])
def test_cli_bad_companions_are_one_line_and_send_nothing(
    fake_cli: FakeService,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    command: str,
    with_args: list[str],
    fragment: str,
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    (tmp_path / "n.png").write_bytes(NORMAL)
    paths = {"n": tmp_path / "n.png", "missing": tmp_path / "no.png"}
    texture, out = str(tmp_path / "in.png"), tmp_path / "o.png"
    if command == "synth":
        argv = ["synth", texture, "-o", str(out), "--size", "8"]
    else:
        argv = ["transfer", texture, texture, "-o", str(out)]
    for spec in with_args:
        argv += ["--with", spec.format(**paths)]
    assert cli.main([*argv, "--server", BASE]) == 2
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and err.count("\n") == 1, err
    assert fragment in err
    assert fake_cli.requests == [] and not out.exists()


@pytest.mark.parametrize("command", ["synth", "transfer"])
def test_cli_companion_of_the_wrong_size_is_refused_by_the_service(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    # Only the service decodes images: it checks the size and answers 422 invalid_companion.
    (tmp_path / "in.png").write_bytes(TEXTURE)
    (tmp_path / "n.png").write_bytes(NORMAL)
    answer = problem(
        422,
        "invalid_companion",
        "companion 'normal' is 32x32; it must be the texture's size, 64x64",
        field="companion",
    )
    fake_cli.on("POST", "/synthesize", answer).on("POST", "/transfer", answer)
    texture, out = str(tmp_path / "in.png"), tmp_path / "o.png"
    if command == "synth":
        argv = ["synth", texture, "-o", str(out), "--size", "8"]
    else:
        argv = ["transfer", texture, texture, "-o", str(out)]
    argv += ["--server", BASE, "--with", f"normal={tmp_path / 'n.png'}"]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and err.count("\n") == 1, err
    assert "32x32" in err and "64x64" in err
    assert len(fake_cli.requests) == 1 and list(tmp_path.glob("o*.png")) == []


def test_cli_tile_writes_the_png_and_sends_the_options(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    fake_cli.on("POST", "/tile", png(TILED, job_id=None))
    out = tmp_path / "out.png"
    argv = ["tile", str(tmp_path / "in.png"), "-o", str(out), "--server", BASE]
    assert cli.main([*argv, "--api-key", "k1", "--axes", "x", "--band", "6"]) == 0
    assert out.read_bytes() == TILED
    post = fake_cli.only("POST", "/tile")
    assert options_of(post) == {"axes": "x", "band": 6}
    assert ("image", "in.png", TEXTURE) in multipart(post)
    assert fake_cli.factory_calls == [(BASE, "k1")]  # type: ignore[attr-defined]
    captured = capsys.readouterr()
    assert captured.out == f"wrote {out} (48x40, tileable along x)\n" and captured.err == ""


@pytest.mark.parametrize(
    ("environment", "flag", "expected"),
    [
        ({}, [], cli.DEFAULT_URL),
        ({"QUILTING_URL": "http://a:1"}, [], "http://a:1"),
        ({"QUILTING_SERVER": "http://b:2"}, [], "http://b:2"),
        ({"QUILTING_URL": "http://a:1", "QUILTING_SERVER": "http://b:2"}, [], "http://a:1"),
        ({"QUILTING_URL": "http://a:1"}, ["--url", "http://c:3"], "http://c:3"),
        ({}, ["--server", "http://c:3"], "http://c:3"),
    ],
)
def test_cli_finds_the_service_from_flag_environment_or_default(
    fake_cli: FakeService,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    environment: dict[str, str],
    flag: list[str],
    expected: str,
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    for name, value in environment.items():
        monkeypatch.setenv(name, value)
    fake_cli.on("POST", "/synthesize", png())
    args = ["synth", str(tmp_path / "in.png"), "-o", str(tmp_path / "o.png"), "--size", "8"]
    assert cli.main([*args, *flag]) == 0
    assert fake_cli.factory_calls == [(expected, None)]  # type: ignore[attr-defined]
    assert cli.DEFAULT_URL == "http://127.0.0.1:8000"  # where `quilting serve` listens


@pytest.mark.parametrize(
    "command",
    [
        ["synth", "{in}", "--size", "8"],
        ["tile", "{in}"],
        ["transfer", "{in}", "{in}"],
    ],
)
@pytest.mark.parametrize("name", ["o.jpg", "o.webp", "o", "o.png.tmp"])
def test_cli_refuses_an_output_that_is_not_png_before_sending(
    fake_cli: FakeService,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    command: list[str],
    name: str,
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    args = [part.replace("{in}", str(tmp_path / "in.png")) for part in command]
    assert cli.main([*args, "-o", str(tmp_path / name), "--server", BASE]) == 2
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and "must end in .png" in err
    assert fake_cli.requests == [] and not (tmp_path / name).exists()


def test_cli_tile_reads_server_and_key_from_the_environment(
    fake_cli: FakeService, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    monkeypatch.setenv("QUILTING_SERVER", BASE)
    monkeypatch.setenv("QUILTING_API_KEY", "from-env")
    fake_cli.on("POST", "/tile", png(TILED, job_id=None))
    assert cli.main(["tile", str(tmp_path / "in.png"), "-o", str(tmp_path / "o.png")]) == 0
    assert fake_cli.factory_calls == [(BASE, "from-env")]  # type: ignore[attr-defined]
    assert options_of(fake_cli.requests[0]) == {"axes": "both"}


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["tile", "{missing}", "-o", "{out}", "--server", BASE], "no.png"),
        (["tile", "{in}", "-o", "{out}", "--server", BASE, "--axes", "z"], "'z' is not one of"),
    ],
)
def test_cli_tile_user_errors_are_one_line_and_send_nothing(
    fake_cli: FakeService,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    args: list[str],
    fragment: str,
) -> None:
    (tmp_path / "in.png").write_bytes(TEXTURE)
    paths = {"in": tmp_path / "in.png", "out": tmp_path / "o.png", "missing": tmp_path / "no.png"}
    assert cli.main([a.format(**paths) for a in args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and err.count("\n") == 1, err
    assert fragment in err
    assert fake_cli.requests == [] and not (tmp_path / "o.png").exists()


def test_cli_matte_writes_the_result_and_the_maps_asked_for(
    fake_cli: FakeService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    paths = matte_files(tmp_path)
    fake_cli.on("POST", "/matte", png(TRANSFERRED)).on(
        "GET", "/jobs/j1/result/normals", png(NORMAL_OUT, job_id=None)
    ).on("GET", "/jobs/j1/result/clusters", png(CLUSTERS_OUT, job_id=None))
    out, normals_out, clusters_out = tmp_path / "o.png", tmp_path / "nm.png", tmp_path / "c.png"
    argv = ["matte", str(paths["target"]), "--silhouette", str(paths["mask"])]
    argv += ["--layer", str(paths["brick"]), "--layer", str(paths["cloud"]), "-o", str(out)]
    argv += ["--server", BASE, "--normals", str(paths["n"]), "--light", "1,1,2"]
    argv += ["--clusters", "8", "--block", "32", "--seed", "0", "--min-z", "0.2"]
    argv += ["--normals-out", str(normals_out), "--clusters-out", str(clusters_out)]
    assert cli.main(argv) == 0
    assert out.read_bytes() == TRANSFERRED
    assert normals_out.read_bytes() == NORMAL_OUT and clusters_out.read_bytes() == CLUSTERS_OUT
    post = fake_cli.only("POST", "/matte")
    assert files_of(post) == [
        ("target", "target.png", TARGET),
        ("silhouette", "mask.png", SILHOUETTE),
        ("layer", "brick.png", LAYER_0),
        ("layer", "cloud.png", LAYER_1),
        ("normals", "n.png", NORMALS_IN),
    ]
    # Only what was given; the light as three numbers.
    assert options_of(post) == {
        "block": 32,
        "seed": 0,
        "clusters": 8,
        "light": [1.0, 1.0, 2.0],
        "min_z": 0.2,
    }
    captured = capsys.readouterr()
    assert captured.out == f"wrote {out}, {normals_out}, {clusters_out} (48x40, job j1)\n"
    assert captured.err == ""


def test_cli_matte_fetches_only_the_maps_asked_for(fake_cli: FakeService, tmp_path: Path) -> None:
    paths = matte_files(tmp_path)
    fake_cli.on("POST", "/matte", png(TRANSFERRED)).on(
        "GET", "/jobs/j1/result/clusters", png(CLUSTERS_OUT, job_id=None)
    )
    out = tmp_path / "o.png"
    argv = ["matte", str(paths["target"]), "--silhouette", str(paths["mask"]), "-o", str(out)]
    argv += ["--layer", str(paths["brick"]), "--server", BASE]
    assert cli.main(argv) == 0
    assert fake_cli.paths() == ["POST /matte"] and options_of(fake_cli.requests[0]) == {}
    assert sorted(p.name for p in tmp_path.glob("o*.png")) == ["o.png"]
    assert cli.main([*argv, "--clusters-out", str(tmp_path / "c.png")]) == 0
    assert fake_cli.paths()[1:] == ["POST /matte", "GET /jobs/j1/result/clusters"]
    assert (tmp_path / "c.png").read_bytes() == CLUSTERS_OUT


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["matte", "{target}", "--layer", "{brick}", "-o", "{out}", "--server", BASE], "silh"),
        (["matte", "{target}", "--silhouette", "{mask}", "-o", "{out}", "--server", BASE], "lay"),
        (
            [
                *["matte", "{target}", "--silhouette", "{mask}", "--layer", "{brick}"],
                *["-o", "{out}", "--server", BASE, "--light", "1,1"],
            ],
            "X,Y,Z",
        ),
        (
            [
                *["matte", "{target}", "--silhouette", "{mask}", "--layer", "{brick}"],
                *["--layer", "{missing}", "-o", "{out}", "--server", BASE],
            ],
            "no.png",
        ),
        (
            [
                *["matte", "{target}", "--silhouette", "{mask}", "--layer", "{brick}"],
                *["--normals", "{missing}", "-o", "{out}", "--server", BASE],
            ],
            "no.png",
        ),
    ],
)
def test_cli_matte_user_errors_exit_2_and_send_nothing(
    fake_cli: FakeService,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    args: list[str],
    fragment: str,
) -> None:
    paths = matte_files(tmp_path)
    paths["out"] = tmp_path / "o.png"
    assert cli.main([a.format(**paths) for a in args]) == 2
    err = capsys.readouterr().err
    assert "error:" in err and fragment in err
    assert fake_cli.requests == [] and not paths["out"].exists()


@pytest.mark.parametrize(
    ("answer", "expected", "text"),
    [
        (
            problem(422, "invalid_parameter", "light=(1, 1, 0) is not allowed", field="light"),
            2,
            "light",
        ),
        (
            problem(422, "invalid_image", "silhouette is 10x10; it must be the target's size"),
            2,
            "10x10",
        ),
        (problem(503, "queue_full", "queue is full"), 1, "queue is full"),
    ],
)
def test_cli_matte_refused_by_the_service_is_one_line(
    fake_cli: FakeService,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    answer: Handler,
    expected: int,
    text: str,
) -> None:
    paths = matte_files(tmp_path)
    fake_cli.on("POST", "/matte", answer)
    out = tmp_path / "o.png"
    argv = ["matte", str(paths["target"]), "--silhouette", str(paths["mask"]), "-o", str(out)]
    argv += ["--layer", str(paths["brick"]), "--server", BASE, "--light", "1,1,0"]
    argv += ["--normals-out", str(tmp_path / "nm.png")]
    assert cli.main(argv) == expected
    err = capsys.readouterr().err
    assert err.startswith("quilting-remote: error: ") and err.count("\n") == 1, err
    assert text in err
    assert not out.exists() and not (tmp_path / "nm.png").exists()
