"""The command line, run the way a user runs it."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from quilting.cli import main
from quilting.costs.base import auto_choice, available_backends
from quilting.io import read_image, read_image_metadata

DATA = Path(__file__).resolve().parent / "data"


def test_synth_writes_the_requested_size_layout_and_seams(tmp_path, capsys) -> None:
    out, layout, seams = tmp_path / "out.png", tmp_path / "layout.json", tmp_path / "seams.png"
    status = main(
        [
            "synth",
            str(DATA / "gravel.png"),
            "-o",
            str(out),
            "--size",
            "517x333",
            "--block",
            "32",
            "--seed",
            "4",
            "--layout",
            str(layout),
            "--seams",
            str(seams),
        ]
    )
    assert status == 0
    image = read_image(out)
    assert image.shape == (333, 517) and image.dtype == np.uint8
    meta = read_image_metadata(out)
    assert meta["seed"] == 4 and meta["block"] == 32 and meta["width"] == 517
    assert json.loads(layout.read_text())["output_shape"] == [333, 517]
    assert read_image(seams).shape == (333, 517, 3)
    assert "wrote" in capsys.readouterr().out


def test_same_seed_same_file_bytes(tmp_path) -> None:
    paths = [tmp_path / "a.png", tmp_path / "b.png"]
    for path in paths:
        main(["synth", str(DATA / "wood.png"), "-o", str(path), "--size", "200x150", "--seed", "2"])
    assert paths[0].read_bytes() == paths[1].read_bytes()


def test_apply_layout_reproduces_the_output(tmp_path) -> None:
    out, layout, again = tmp_path / "out.png", tmp_path / "l.json", tmp_path / "again.png"
    main(
        [
            "synth",
            str(DATA / "hubble.png"),
            "-o",
            str(out),
            "--size",
            "300x200",
            "--layout",
            str(layout),
        ]
    )
    assert main(["apply-layout", str(layout), str(DATA / "hubble.png"), "-o", str(again)]) == 0
    assert np.array_equal(read_image(again), read_image(out))


def test_info_lists_the_backends(capsys) -> None:
    assert main(["info"]) == 0
    text = capsys.readouterr().out
    assert "fft" in text and "reference" in text and "gl" in text
    concrete, why = auto_choice()
    assert f"auto       -> {concrete}  ({why})" in text
    gl = next(s for s in available_backends() if s.name == "gl")
    if gl.renderer is not None:  # the renderer is named, and why auto does (not) use it
        assert f"renderer: {gl.renderer}" in text


@pytest.mark.gl
def test_synth_names_the_gl_renderer(tmp_path, capsys) -> None:
    gl = next(s for s in available_backends() if s.name == "gl")
    if not gl.available:
        pytest.skip(gl.reason)
    out = tmp_path / "out.png"
    args = ["synth", str(DATA / "gravel.png"), "-o", str(out), "--size", "64x64"]
    assert main([*args, "--block", "24", "--backend", "gl"]) == 0
    assert f"with the gl backend on {gl.renderer}" in capsys.readouterr().out


@pytest.mark.parametrize(
    "args,fragment",
    [
        (["synth", "missing.png", "-o", "x.png", "--size", "10x10"], "missing.png"),
        (["synth", "{notpng}", "-o", "x.png", "--size", "10x10"], "PNG"),
        (["synth", "{gravel}", "-o", "x.png", "--size", "10x10", "--block", "999"], "block=999"),
        (["synth", "{gravel}", "-o", "x.png", "--size", "0x10"], "size"),
        (["synth", "{gravel}", "-o", "x.png", "--size", "10x10", "--overlap", "30"], "overlap=30"),
        (["apply-layout", "{notpng}", "{gravel}", "-o", "x.png"], "layout"),
    ],
)
def test_errors_are_one_line_and_exit_2(tmp_path, capsys, args, fragment) -> None:
    text_file = tmp_path / "notes.txt"
    text_file.write_text("not an image")
    subst = {"{notpng}": str(text_file), "{gravel}": str(DATA / "gravel.png")}
    with pytest.raises(SystemExit) as info:
        main([subst.get(a, a) for a in args])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert fragment in err and "Traceback" not in err


def test_bad_size_text_is_an_argument_error(capsys) -> None:
    with pytest.raises(SystemExit) as info:
        main(["synth", str(DATA / "gravel.png"), "-o", "x.png", "--size", "big"])
    assert info.value.code == 2
    assert "WIDTHxHEIGHT" in capsys.readouterr().err


def test_installed_command_runs(tmp_path) -> None:
    # The console script as a user starts it (falls back to `python -m quilting`).
    exe = shutil.which("quilting", path=os.path.dirname(sys.executable))
    command = [exe] if exe else [sys.executable, "-m", "quilting"]
    out = tmp_path / "out.png"
    done = subprocess.run(
        [*command, "synth", str(DATA / "brick.png"), "-o", str(out), "--size", "96x64"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert read_image(out).shape == (64, 96)
    bad = subprocess.run(
        [*command, "synth", str(tmp_path / "nope.png"), "-o", str(out), "--size", "9"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert bad.returncode == 2 and "nope.png" in bad.stderr and "Traceback" not in bad.stderr


class _Terminal:
    """A stream that says it is a terminal and records what is written."""

    def __init__(self, tty: bool) -> None:
        self.tty = tty
        self.text = ""

    def isatty(self) -> bool:
        return self.tty

    def write(self, text: str) -> None:
        self.text += text

    def flush(self) -> None:
        pass


def test_progress_bar_draws_on_a_terminal_only() -> None:
    from quilting.cli import ProgressBar

    terminal, pipe = _Terminal(True), _Terminal(False)
    for stream in (terminal, pipe):
        bar = ProgressBar(stream)  # type: ignore[arg-type]
        for fraction in (0.25, 0.5, 1.0):
            bar(fraction, "synthesis")
    assert pipe.text == ""
    assert terminal.text.count("\r") == 3 and "100.0%" in terminal.text
    assert terminal.text.endswith("\n")
