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

from quilting import Layout, apply_layout, transfer
from quilting.cli import main
from quilting.costs.base import auto_choice, available_backends
from quilting.io import read_image, read_image_metadata, write_image

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


# --- transfer -------------------------------------------------------------------------------


@pytest.fixture
def small_target(tmp_path: Path) -> Path:
    """A 48x40 RGB crop of hubble.png (the gravel texture is gray: channels must follow it)."""
    path = tmp_path / "target.png"
    write_image(path, read_image(DATA / "hubble.png")[100:140, 60:108])
    return path


def _transfer(target: Path, out: Path, *extra: str) -> int:
    args = ["transfer", str(DATA / "gravel.png"), str(target), "-o", str(out), "--block", "12"]
    return main([*args, *extra])


def test_transfer_writes_the_targets_size_with_the_textures_channels(
    tmp_path, capsys, small_target
) -> None:
    out = tmp_path / "out.png"
    assert _transfer(small_target, out, "--seed", "5") == 0
    image = read_image(out)
    assert image.shape == (40, 48) and image.dtype == np.uint8  # gravel.png is gray
    meta = read_image_metadata(out)
    assert meta["operation"] == "transfer" and meta["seed"] == 5 and meta["block"] == 12
    assert (meta["source"], meta["target"]) == ("gravel.png", "target.png")
    assert (meta["width"], meta["height"]) == (48, 40)
    assert meta["backend_used"] == auto_choice()[0] and meta["correspondence"] == "luminance"
    [line] = capsys.readouterr().out.splitlines()
    assert line.startswith(f"wrote {out} (48x40)") and "correspondence error" in line
    assert "1 pass (block 12)" in line and "mean seam error" in line


def test_transfer_colour_texture_onto_gray_target(tmp_path) -> None:
    gray_target = tmp_path / "gray.png"
    write_image(gray_target, read_image(DATA / "brick.png")[:40, :48])
    out = tmp_path / "out.png"
    args = ["transfer", str(DATA / "wood.png"), str(gray_target), "-o", str(out)]
    assert main([*args, "--block", "12"]) == 0
    assert read_image(out).shape == (40, 48, 3)  # wood.png is RGB


def test_transfer_same_seed_same_bytes(tmp_path, small_target) -> None:
    paths = [tmp_path / "a.png", tmp_path / "b.png", tmp_path / "c.png"]
    for path, seed in zip(paths, ("2", "2", "3"), strict=True):
        assert _transfer(small_target, path, "--seed", seed, "--correspondence", "blurred") == 0
    assert paths[0].read_bytes() == paths[1].read_bytes()
    assert read_image(paths[0]).tobytes() != read_image(paths[2]).tobytes()  # seed is used


def test_transfer_iterations_and_layout_rerender(tmp_path, capsys, small_target) -> None:
    out, layout_path, seams = tmp_path / "o.png", tmp_path / "l.json", tmp_path / "s.png"
    extra = ["--iterations", "2", "--layout", str(layout_path), "--seams", str(seams)]
    assert _transfer(small_target, out, *extra) == 0
    assert "2 passes (blocks 12, 8)" in capsys.readouterr().out
    layout = Layout.load(layout_path)
    assert layout.meta["operation"] == "transfer" and len(layout.passes) == 2
    assert [p["block"] for p in layout.meta["passes"]] == [12, 8]
    image = read_image(out)
    texture = read_image(DATA / "gravel.png")
    # The saved layout quilts the texture into exactly the output, every pass included.
    assert np.array_equal(layout.render(texture[:, :, None])[:, :, 0], image)
    assert np.array_equal(apply_layout(layout, texture), image)
    assert read_image(seams).shape == (40, 48, 3)


def test_transfer_options_reach_the_engine(tmp_path, small_target) -> None:
    out = tmp_path / "out.png"
    extra = ["--alpha", "0.3", "--no-remap", "--mode", "overlap", "--sigma", "1.5"]
    assert _transfer(small_target, out, *extra, "--correspondence", "orientation") == 0
    meta = read_image_metadata(out)
    assert (meta["alpha"], meta["remap"], meta["mode"], meta["sigma"]) == (
        0.3,
        False,
        "overlap",
        1.5,
    )
    assert meta["correspondence"] == "orientation"
    local = transfer(
        read_image(DATA / "gravel.png"),
        read_image(small_target),
        block=12,
        alpha=0.3,
        remap=False,
        mode="overlap",
        sigma=1.5,
        correspondence="orientation",
    )
    assert np.array_equal(read_image(out), local.image)


def test_transfer_with_custom_maps(tmp_path, small_target) -> None:
    # Maps of the texture's and the target's size, read from files: the result is the
    # Python API's with the same arrays, and the metadata says the correspondence was custom.
    source_map, target_map = tmp_path / "sm.png", tmp_path / "tm.png"
    write_image(source_map, read_image(DATA / "gravel.png"))
    write_image(target_map, read_image(DATA / "brick.png")[:40, :48])
    out = tmp_path / "out.png"
    extra = ["--source-map", str(source_map), "--target-map", str(target_map)]
    assert _transfer(small_target, out, *extra) == 0
    meta = read_image_metadata(out)
    assert meta["correspondence"] == "custom"
    assert (meta["source_map"], meta["target_map"]) == ("sm.png", "tm.png")
    local = transfer(
        read_image(DATA / "gravel.png"),
        read_image(small_target),
        block=12,
        source_map=read_image(source_map),
        target_map=read_image(target_map),
    )
    assert np.array_equal(read_image(out), local.image)


@pytest.mark.parametrize(
    "extra,fragment",
    [
        (["--block", "999"], "block=999"),
        (["--alpha", "2"], "alpha=2"),
        (["--iterations", "0"], "iterations=0"),
        (["--overlap", "6"], "overlap=6"),
        (["--source-map", "{gravel}"], "--target-map"),
        (["--source-map", "{gravel}", "--target-map", "{gravel}"], "target_map"),
        (
            ["--source-map", "{gravel}", "--target-map", "{target}", "--correspondence", "blurred"],
            "correspondence='blurred'",
        ),
    ],
)
def test_transfer_errors_are_one_line_and_exit_2(
    tmp_path, capsys, small_target, extra, fragment
) -> None:
    subst = {"{gravel}": str(DATA / "gravel.png"), "{target}": str(small_target)}
    with pytest.raises(SystemExit) as info:
        _transfer(small_target, tmp_path / "x.png", *[subst.get(a, a) for a in extra])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("quilting: error: ") and err.count("\n") == 1, err
    assert fragment in err and "Traceback" not in err
    assert not (tmp_path / "x.png").exists()


@pytest.mark.parametrize(
    "args,fragment",
    [
        (["transfer", "{gravel}", "missing.png", "-o", "x.png"], "missing.png"),
        (
            ["transfer", "{gravel}", "{gravel}", "-o", "x.png", "--correspondence", "custom"],
            "custom",
        ),
        (["transfer", "{gravel}", "{gravel}", "-o", "x.png", "--mode", "random"], "random"),
    ],
)
def test_transfer_argument_errors_exit_2(capsys, args, fragment) -> None:
    with pytest.raises(SystemExit) as info:
        main([str(DATA / "gravel.png") if a == "{gravel}" else a for a in args])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert fragment in err and "Traceback" not in err
