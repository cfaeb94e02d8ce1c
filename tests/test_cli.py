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

from quilting import Layout, apply_layout, matte, synthesize, transfer
from quilting.backends import auto_choice, available_backends
from quilting.cli import main
from quilting.io import read_image, read_image_metadata, write_image

DATA = Path(__file__).resolve().parent / "data"


def _usage_error(capsys: pytest.CaptureFixture[str], args: list[str]) -> str:
    """The command line on ``args`` exits with status 2 (a usage error); its stderr."""
    with pytest.raises(SystemExit) as info:
        main(args)
    assert info.value.code == 2
    return capsys.readouterr().err


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
    err = _usage_error(capsys, [subst.get(a, a) for a in args])
    assert fragment in err and "Traceback" not in err


def test_bad_size_text_is_an_argument_error(capsys) -> None:
    err = _usage_error(capsys, ["synth", str(DATA / "gravel.png"), "-o", "x.png", "--size", "big"])
    assert "WIDTHxHEIGHT" in err


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
    assert meta["backend_used"] == auto_choice()[0] and meta["correspondence"] == "blurred"
    assert (meta["iterations"], meta["min_block"], meta["shade"]) == (2, 16, 1.5)
    [line] = capsys.readouterr().out.splitlines()
    assert line.startswith(f"wrote {out} (48x40)") and "correspondence error" in line
    # Two passes by default; a first block under min_block (16) is kept.
    assert "2 passes (blocks 12, 12)" in line and "mean seam error" in line


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
    # No floor and no shading: the paper's passes, and the layout is the whole image.
    extra += ["--min-block", "3", "--shade", "1"]
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
    err = _usage_error(capsys, [str(DATA / "gravel.png") if a == "{gravel}" else a for a in args])
    assert fragment in err and "Traceback" not in err


# --- companion maps (--with) ----------------------------------------------------------------


@pytest.fixture
def maps(tmp_path: Path) -> dict[str, Path]:
    """A 64x64 gray texture and maps of its size: RGB 8-bit, gray 16-bit; one of another size."""
    gravel, hubble = read_image(DATA / "gravel.png"), read_image(DATA / "hubble.png")
    arrays = {
        "texture": gravel[:64, :64],
        "normal": hubble[:64, :64],
        "height": (read_image(DATA / "brick.png")[:64, :64].astype(np.uint16) * 257),
        "small": gravel[:48, :64],
    }
    for name, array in arrays.items():
        write_image(tmp_path / f"{name}.png", array)
    (tmp_path / "notes.txt").write_text("not an image")
    return {name: tmp_path / f"{name}.png" for name in arrays} | {"text": tmp_path / "notes.txt"}


def _check_companions(
    out: Path, layout_path: Path, given: dict[str, Path], copy_of_texture: str
) -> None:
    """Each ``<out stem>_<name>.png`` is its map quilted with the saved layout, bit depth kept,
    with the output's metadata plus its name; the texture's own copy is the output."""
    layout = Layout.load(layout_path)
    main_meta = read_image_metadata(out)
    for name, path in given.items():
        written = out.with_name(f"{out.stem}_{name}.png")
        image, expected = read_image(written), apply_layout(layout, read_image(path))
        assert image.dtype == expected.dtype and np.array_equal(image, expected), name
        assert read_image_metadata(written) == {**main_meta, "companion": name}
    copy = read_image(out.with_name(f"{out.stem}_{copy_of_texture}.png"))
    assert np.array_equal(copy, read_image(out))


def test_synth_with_companions_quilts_them_with_the_layout(tmp_path, capsys, maps) -> None:
    folder = tmp_path / "out"
    folder.mkdir()
    out, layout = folder / "brick.png", tmp_path / "layout.json"
    given = {"normal": maps["normal"], "height": maps["height"], "copy": maps["texture"]}
    args = ["synth", str(maps["texture"]), "-o", str(out), "--size", "100x80", "--block", "14"]
    args += ["--seed", "3", "--layout", str(layout)]
    args += [a for name, path in given.items() for a in ("--with", f"{name}={path}")]
    assert main(args) == 0
    # Beside the output, in its folder, named after its stem: nothing else written there.
    assert sorted(p.name for p in folder.iterdir()) == [
        "brick.png",
        "brick_copy.png",
        "brick_height.png",
        "brick_normal.png",
    ]
    assert read_image(folder / "brick_height.png").shape == (80, 100)
    assert read_image(folder / "brick_normal.png").shape == (80, 100, 3)
    _check_companions(out, layout, given, "copy")
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 4 and lines[0].startswith(f"wrote {out} (100x80)")
    for name in given:
        assert sum(f"brick_{name}.png" in line and repr(name) in line for line in lines) == 1


def test_companion_kinds_reach_apply_layout(tmp_path, maps) -> None:
    """With blended seams, --with NAME:KIND=PATH and apply-layout --kind give what
    quilting.apply_layout gives for that kind, and 'hard' differs from 'blend'."""
    out, layout = tmp_path / "b.png", tmp_path / "b.json"
    args = ["synth", str(maps["texture"]), "-o", str(out), "--size", "90x70", "--block", "14"]
    args += ["--seed", "3", "--layout", str(layout), "--blend", "poisson"]
    args += ["--with", f"ids:hard={maps['height']}", "--with", f"n:normal={maps['normal']}"]
    args += ["--with", f"soft={maps['height']}"]
    assert main(args) == 0
    saved = Layout.load(layout)
    for name, source, kind in (
        ("ids", "height", "hard"),
        ("n", "normal", "normal"),
        ("soft", "height", "blend"),
    ):
        expected = apply_layout(saved, read_image(maps[source]), kind=kind)
        assert np.array_equal(read_image(tmp_path / f"b_{name}.png"), expected), name
    assert not np.array_equal(
        read_image(tmp_path / "b_ids.png"), read_image(tmp_path / "b_soft.png")
    )
    again = tmp_path / "again.png"
    assert (
        main(["apply-layout", str(layout), str(maps["height"]), "-o", str(again), "--kind", "hard"])
        == 0
    )
    assert np.array_equal(read_image(again), read_image(tmp_path / "b_ids.png"))


def test_transfer_with_companions_quilts_them_with_every_pass(
    tmp_path, capsys, small_target
) -> None:
    # gravel.png (256x256, gray) is the texture of _transfer: the maps have its size.
    out, layout = tmp_path / "t.png", tmp_path / "t.json"
    given = {
        "normal": DATA / "hubble.png",
        "rough": DATA / "brick.png",
        "self": DATA / "gravel.png",
    }
    # Unshaded: the companion that is the texture itself is then the output exactly.
    extra = ["--iterations", "2", "--seed", "4", "--layout", str(layout), "--shade", "1"]
    extra += [a for name, path in given.items() for a in ("--with", f"{name}={path}")]
    assert _transfer(small_target, out, *extra) == 0
    assert read_image(out.with_name("t_normal.png")).shape == (40, 48, 3)
    _check_companions(out, layout, given, "self")
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 4 and "t_rough.png" in lines[2]


def _must_not_run(*args: object, **kwargs: object) -> None:
    raise AssertionError("the quilting ran although a companion map was bad")


@pytest.mark.parametrize(
    "with_args,fragment",
    [
        (["normal"], "is not NAME=PATH"),
        (["normal="], "is not NAME=PATH"),
        (["=x.png"], "the name '' is not"),
        (["no rmal={normal}"], "the name 'no rmal'"),
        (["../evil={normal}"], "the name '../evil'"),
        ([f"{'n' * 65}={{normal}}"], "is not 1 to 64"),
        (["n={normal}", "n={height}"], "'n' is given twice"),
        (["n={normal}", "m={missing}"], "missing.png"),
        (["n={text}"], "companion 'n'"),
        (["n={normal}", "s={small}"], "is 64x48 but the texture is 64x64"),
        (["n:soft={normal}"], "the kind 'soft' is not one of blend, hard, normal"),
    ],
)
@pytest.mark.parametrize("command", ["synth", "transfer"])
def test_bad_companions_fail_before_quilting_and_write_nothing(
    tmp_path, capsys, monkeypatch, maps, command, with_args, fragment
) -> None:
    monkeypatch.setattr("quilting.cli.synthesize", _must_not_run)
    monkeypatch.setattr("quilting.cli.transfer", _must_not_run)
    folder = tmp_path / "out"
    folder.mkdir()
    subst = {k: str(v) for k, v in maps.items()} | {"missing": str(tmp_path / "missing.png")}
    if command == "synth":
        args = ["synth", str(maps["texture"]), "-o", str(folder / "o.png"), "--size", "80x80"]
    else:  # the target has another size than the texture: the maps must have the texture's
        args = ["transfer", str(maps["texture"]), str(maps["small"]), "-o", str(folder / "o.png")]
    for spec in with_args:
        args += ["--with", spec.format(**subst)]
    err = _usage_error(capsys, [*args, "--block", "12", "--layout", str(folder / "l.json")])
    assert err.startswith("quilting: error: ") and err.count("\n") == 1, err
    assert fragment in err and "Traceback" not in err
    assert list(folder.iterdir()) == []


# --- --error and --discard ------------------------------------------------------------------


def _pixels(path: Path) -> bytes:
    return read_image(path).tobytes()


def test_error_and_discard_reach_the_engine(tmp_path) -> None:
    # An RGB texture: luminance compares something else than the three channels.
    texture_path = tmp_path / "hubble.png"
    texture = read_image(DATA / "hubble.png")[64:128, 64:128]
    write_image(texture_path, texture)
    base = ["synth", str(texture_path), "--size", "96x96", "--block", "14", "--seed", "7"]
    runs = {
        "default": [],
        "luminance": ["--error", "luminance"],
        "discard": ["--discard", "0.5"],
    }
    paths: dict[str, list[Path]] = {}
    for name, extra in runs.items():
        paths[name] = [tmp_path / f"{name}{i}.png" for i in range(2)]
        for path in paths[name]:
            assert main([*base, "-o", str(path), *extra]) == 0
        assert paths[name][0].read_bytes() == paths[name][1].read_bytes()  # same seed
    default = _pixels(paths["default"][0])
    assert _pixels(paths["luminance"][0]) != default
    assert _pixels(paths["discard"][0]) != default
    assert _pixels(paths["luminance"][0]) != _pixels(paths["discard"][0])
    for name, options in {
        "luminance": {"error": "luminance"},
        "discard": {"discard": 0.5},
        "default": {},
    }.items():
        local = synthesize(texture, (96, 96), block=14, seed=7, **options)  # type: ignore[arg-type]
        assert np.array_equal(read_image(paths[name][0]), local.image), name
    meta = read_image_metadata(paths["luminance"][0])
    assert (meta["error"], meta["discard"]) == ("luminance", 0.0)
    meta = read_image_metadata(paths["discard"][0])
    assert (meta["error"], meta["discard"]) == ("rgb", 0.5)


def test_transfer_error_and_discard_reach_the_engine(tmp_path, small_target) -> None:
    wood = read_image(DATA / "wood.png")  # RGB, like the target
    outs = [tmp_path / "default.png", tmp_path / "both.png"]
    args = ["transfer", str(DATA / "wood.png"), str(small_target), "--block", "12", "--seed", "2"]
    assert main([*args, "-o", str(outs[0])]) == 0
    assert main([*args, "-o", str(outs[1]), "--error", "luminance", "--discard", "0.3"]) == 0
    assert _pixels(outs[0]) != _pixels(outs[1])
    local = transfer(
        wood, read_image(small_target), block=12, seed=2, error="luminance", discard=0.3
    )
    assert np.array_equal(read_image(outs[1]), local.image)
    meta = read_image_metadata(outs[1])
    assert (meta["error"], meta["discard"]) == ("luminance", 0.3)


@pytest.mark.parametrize(
    "extra,fragment",
    [
        (["--error", "lab"], "invalid choice: 'lab'"),
        (["--discard", "1"], "discard=1"),
        (["--discard", "-0.1"], "discard=-0.1"),
        (["--discard", "some"], "invalid float value"),
    ],
)
def test_bad_error_and_discard_exit_2(tmp_path, capsys, extra, fragment) -> None:
    out = tmp_path / "o.png"
    err = _usage_error(
        capsys, ["synth", str(DATA / "gravel.png"), "-o", str(out), "--size", "32", *extra]
    )
    assert fragment in err and not out.exists()


def test_exclusions_reach_the_engine(tmp_path, capsys) -> None:
    """--exclude-color and --source-mask: no output pixel traced back through the layout comes
    from an excluded pixel, and the output equals the Python API's."""
    hubble = read_image(DATA / "hubble.png")
    mask = np.full(hubble.shape[:2], 255, dtype=np.uint8)
    mask[30:120, 40:160] = 0
    write_image(tmp_path / "mask.png", mask)
    out, layout = tmp_path / "out.png", tmp_path / "out.json"
    args = ["synth", str(DATA / "hubble.png"), "-o", str(out), "--size", "150x120"]
    args += ["--block", "24", "--seed", "2", "--layout", str(layout)]
    args += ["--exclude-color", "120,120,120:255,255,255"]
    args += ["--source-mask", str(tmp_path / "mask.png")]
    assert main(args) == 0
    stars = np.all(hubble >= 120, axis=-1)
    excluded = (stars | (mask == 0)).astype(np.uint8)
    assert apply_layout(Layout.load(layout), excluded).sum() == 0
    expected = synthesize(
        hubble,
        (120, 150),
        block=24,
        seed=2,
        exclude_colors=[((120, 120, 120), (255, 255, 255))],
        source_mask=mask,
    )
    assert np.array_equal(read_image(out), expected.image)


@pytest.mark.parametrize(
    "extra,fragment",
    [
        (["--exclude-color", "1,2"], "LOW:HIGH"),
        (["--exclude-color", "9:1"], "low > high"),
        (["--exclude-color", "0,0,0:9,9,9"], "1-channel"),  # RGB colours, gray texture
        (["--source-mask", "missing.png"], "missing.png"),
    ],
)
def test_bad_exclusions_exit_2(tmp_path, capsys, extra, fragment) -> None:
    args = ["synth", str(DATA / "gravel.png"), "-o", str(tmp_path / "o.png"), "--size", "40x40"]
    err = _usage_error(capsys, [*args, *extra])
    assert fragment in err
    assert not (tmp_path / "o.png").exists()


def test_tileable_and_walk_reach_the_engine(tmp_path) -> None:
    gravel = read_image(DATA / "gravel.png")
    cases = [
        (["--tileable", "x", "--block", "24"], {"tileable": "x", "block": 24}),
        (
            ["--mode", "walk", "--max-run", "3", "--feather", "0"],
            {"mode": "walk", "max_run": 3, "feather": 0},
        ),
    ]
    for flags, kwargs in cases:
        out = tmp_path / "out.png"
        assert (
            main(
                [
                    "synth",
                    str(DATA / "gravel.png"),
                    "-o",
                    str(out),
                    "--size",
                    "90x70",
                    "--seed",
                    "3",
                    *flags,
                ]
            )
            == 0
        )
        expected = synthesize(gravel, (70, 90), seed=3, **kwargs)  # type: ignore[arg-type]
        assert np.array_equal(read_image(out), expected.image), flags
        meta = read_image_metadata(out)
        assert all(meta[key] == value for key, value in kwargs.items()), meta


def test_tile_writes_a_tileable_image_and_its_companions(tmp_path, capsys) -> None:
    out = tmp_path / "tiled.png"
    brick = read_image(DATA / "brick.png")
    normal = np.ascontiguousarray(brick[:, ::-1])  # any map of the image's size
    write_image(tmp_path / "normal.png", normal)
    status = main(
        [
            "tile",
            str(DATA / "brick.png"),
            "-o",
            str(out),
            "--axes",
            "both",
            "--band",
            "30",
            "--with",
            f"normal={tmp_path / 'normal.png'}",
        ]
    )
    assert status == 0
    from quilting import make_tileable

    tiled = make_tileable(brick, axes="both", band=30)
    assert np.array_equal(read_image(out), tiled.image)
    mapped = read_image(tmp_path / "tiled_normal.png")
    # Blended by default, like the image ('blend' kind).
    assert np.array_equal(mapped, tiled.apply(normal))
    assert read_image_metadata(out)["operation"] == "tile"
    printed = capsys.readouterr().out
    assert "tileable along both" in printed and "tiled_normal.png" in printed


def test_tile_blend_poisson_reaches_the_engine_and_its_companions(tmp_path, capsys) -> None:
    out = tmp_path / "tiled.png"
    brick = read_image(DATA / "brick.png")
    rows, cols = np.mgrid[0:256, 0:256]
    # A brightness ramp (what the blend is for) and a mask: blended vs only rearranged.
    height = np.clip(rows + cols, 0, 255).astype(np.uint8) // 2
    mask = ((rows // 16 + cols // 16) % 2 * 255).astype(np.uint8)
    write_image(tmp_path / "height.png", height)
    write_image(tmp_path / "mask.png", mask)
    args = ["tile", str(DATA / "brick.png"), "-o", str(out)]  # --blend poisson, the default
    args += ["--with", f"height={tmp_path / 'height.png'}"]
    args += ["--with", f"mask:hard={tmp_path / 'mask.png'}"]
    assert main(args) == 0
    from quilting import make_tileable

    tiled = make_tileable(brick, blend="poisson")
    assert np.array_equal(read_image(out), tiled.image)
    assert not np.array_equal(tiled.image, make_tileable(brick, blend="none").image)
    assert read_image_metadata(out)["blend"] == "poisson"
    assert np.array_equal(read_image(tmp_path / "tiled_height.png"), tiled.apply(height))
    assert not np.array_equal(tiled.apply(height), height[tiled.source_rows, tiled.source_cols])
    assert np.array_equal(
        read_image(tmp_path / "tiled_mask.png"), mask[tiled.source_rows, tiled.source_cols]
    )
    capsys.readouterr()


def test_tile_help_lists_blend(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["tile", "--help"])
    printed = capsys.readouterr().out
    assert "--blend {none,poisson}" in printed and "poisson" in printed


@pytest.mark.parametrize(
    ("extra", "fragment"),
    [
        (["--band", "0"], "band=0"),
        (["--band", "400"], "band=400"),
        (["--axes", "z"], "invalid choice"),
        (["--blend", "feather"], "invalid choice"),
    ],
)
def test_bad_tile_options_exit_2(tmp_path, capsys, extra, fragment) -> None:
    err = _usage_error(
        capsys, ["tile", str(DATA / "brick.png"), "-o", str(tmp_path / "t.png"), *extra]
    )
    assert fragment in err and "Traceback" not in err
    assert not (tmp_path / "t.png").exists()


@pytest.mark.parametrize(
    ("extra", "fragment"),
    [
        (["--size", "30x90", "--tileable", "x", "--block", "40"], "tileable width"),
        (["--size", "90x90", "--tileable", "both", "--mode", "walk"], "tileable"),
        (["--size", "90x90", "--mode", "walk", "--max-run", "0"], "max_run=0"),
    ],
)
def test_bad_tileable_and_walk_exit_2(tmp_path, capsys, extra, fragment) -> None:
    err = _usage_error(
        capsys, ["synth", str(DATA / "gravel.png"), "-o", str(tmp_path / "o.png"), *extra]
    )
    assert fragment in err and "Traceback" not in err


def test_matte_writes_the_python_result_normals_and_clusters(
    tmp_path, capsys, sphere_files
) -> None:
    """quilting matte: the image of quilting.matte for the same inputs, plus the normals and
    patches it was asked for, and a summary naming the estimated light."""
    target_path, mask_path, target, mask = sphere_files
    out, normals, clusters = tmp_path / "o.png", tmp_path / "n.png", tmp_path / "c.png"
    args = ["matte", str(target_path), "--silhouette", str(mask_path), "-o", str(out)]
    args += ["--layer", str(DATA / "brick.png"), "--layer", str(DATA / "cloud_rgba.png")]
    args += ["--block", "24", "--seed", "3", "--clusters", "5", "--ambient", "0.2"]
    args += ["--normals-out", str(normals), "--clusters-out", str(clusters)]
    assert main(args) == 0
    layers = [read_image(DATA / "brick.png"), read_image(DATA / "cloud_rgba.png")]
    expected = matte(target, layers, silhouette=mask, block=24, seed=3, clusters=5, ambient=0.2)
    assert np.array_equal(read_image(out), expected.image)
    assert read_image(normals).shape == (96, 96, 3)
    assert read_image(clusters).shape == (96, 96, 3)
    meta = read_image_metadata(out)
    assert meta["operation"] == "matte" and meta["layers"] == ["brick.png", "cloud_rgba.png"]
    assert meta["clusters"] == 5 and meta["ambient"] == 0.2
    printed = capsys.readouterr().out
    assert "2 layers" in printed and "(estimated)" in printed


def test_matte_given_light_and_normals(tmp_path, capsys, sphere_files) -> None:
    target_path, mask_path, target, mask = sphere_files
    flat = np.zeros((96, 96, 3), dtype=np.uint8) + np.array([128, 128, 255], dtype=np.uint8)
    write_image(tmp_path / "flat.png", flat)
    out = tmp_path / "o.png"
    args = ["matte", str(target_path), "--silhouette", str(mask_path), "-o", str(out)]
    args += ["--layer", str(DATA / "brick.png"), "--light=-1,0,2", "--block", "24"]
    args += ["--normals", str(tmp_path / "flat.png")]
    assert main(args) == 0
    expected = matte(
        target,
        [read_image(DATA / "brick.png")],
        silhouette=mask,
        light=(-1, 0, 2),
        normals=flat,
        block=24,
    )
    assert np.array_equal(read_image(out), expected.image)
    assert "(-0.447, 0.000, 0.894) (given)" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("extra", "fragment"),
    [
        (["--light", "1,1,-1"], "light"),
        (["--light", "1,1"], "--light"),
        (["--mode", "walk"], "--mode"),
        (["--clusters", "0"], "clusters"),
        (["--layer", str(DATA / "wood.png"), "--mode", "alpha"], "mode"),
    ],
)
def test_bad_matte_arguments_exit_2(tmp_path, capsys, sphere_files, extra, fragment) -> None:
    target_path, mask_path, _, _ = sphere_files
    args = ["matte", str(target_path), "--silhouette", str(mask_path)]
    args += ["-o", str(tmp_path / "o.png"), "--layer", str(DATA / "brick.png"), *extra]
    err = _usage_error(capsys, args)
    assert fragment in err
    assert not (tmp_path / "o.png").exists()


# --- output formats -------------------------------------------------------------------------


@pytest.mark.parametrize(("name", "fmt"), [("out.jpg", "JPEG"), ("out.webp", "WEBP")])
def test_synth_writes_the_format_of_the_output_name(tmp_path, name, fmt) -> None:
    from PIL import Image

    out = tmp_path / name
    args = ["synth", str(DATA / "hubble.png"), "-o", str(out), "--size", "96x80", "--block", "32"]
    assert main(args) == 0
    with Image.open(out) as im:
        assert im.format == fmt and im.size == (96, 80) and im.mode == "RGB"
    # The pixels are the PNG's, up to the lossy format's small error.
    png = tmp_path / "out.png"
    assert main([*args[:3], str(png), *args[4:]]) == 0
    with Image.open(out) as im:  # read_image takes PNG and JPEG only
        lossy = np.asarray(im.convert("RGB")).astype(int)
    error = np.abs(lossy - read_image(png).astype(int)).mean()
    assert error < 6


@pytest.mark.parametrize(
    ("texture", "out", "fragment"),
    [
        ("cloud_rgba.png", "o.jpg", "alpha channel"),
        ("gravel.png", "o.tiff", "'.tiff' names no format"),
        ("gravel16", "o.webp", "16-bit image"),
    ],
)
def test_synth_refuses_an_output_name_before_quilting(
    tmp_path, capsys, monkeypatch, texture, out, fragment
) -> None:
    monkeypatch.setattr("quilting.cli.synthesize", _must_not_run)
    if texture == "gravel16":
        path = tmp_path / "gravel16.png"
        write_image(path, read_image(DATA / "gravel.png").astype(np.uint16) * 257)
    else:
        path = DATA / texture
    folder = tmp_path / "out"
    folder.mkdir()
    err = _usage_error(
        capsys, ["synth", str(path), "-o", str(folder / out), "--size", "64x64", "--block", "16"]
    )
    assert err.startswith("quilting: error: ") and fragment in err and ".png" in err
    assert list(folder.iterdir()) == []


def test_seams_overlay_name_is_checked_before_quilting(tmp_path, capsys, monkeypatch) -> None:
    monkeypatch.setattr("quilting.cli.synthesize", _must_not_run)
    args = ["synth", str(DATA / "gravel.png"), "-o", str(tmp_path / "o.png"), "--size", "64x64"]
    with pytest.raises(SystemExit):
        main([*args, "--seams", str(tmp_path / "seams.bmp")])
    assert "'.bmp' names no format" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["synth", "tile"])
def test_a_memory_budget_refuses_the_job_before_any_output(tmp_path, capsys, command) -> None:
    out = tmp_path / "out.png"
    sized = ["--size", "4096x4096"] if command == "synth" else []
    err = _usage_error(
        capsys,
        [command, str(DATA / "brick.png"), "-o", str(out), *sized, "--memory-budget", "181M"],
    )
    assert "181.0 MiB" in err and "memory" in err and "Traceback" not in err, err
    assert not out.exists()


@pytest.mark.parametrize(
    ("command", "options"),
    [
        ("synth", "SynthesisOptions"),
        ("transfer", "TransferOptions"),
        ("matte", "MatteOptions"),
        ("tile", "TileOptions"),
    ],
)
def test_every_option_field_has_a_flag(command: str, options: str) -> None:
    """The flags are made from the options' fields: a field added is a flag added."""
    import argparse
    import dataclasses

    import quilting.options
    from quilting.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[
        command
    ]
    dests = {action.dest for action in sub._actions}
    names = {f.name for f in dataclasses.fields(getattr(quilting.options, options))}
    assert names <= dests, sorted(names - dests)
