"""``quilting fill``, ``quilting extend`` and ``quilting tile --method fill``, run the way a user
runs them."""

from __future__ import annotations

import argparse
import dataclasses
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from quilting import (
    ExtendOptions,
    FillOptions,
    TileOptions,
    extend,
    fill,
    make_tileable,
    synthesize,
)
from quilting.cli import build_parser, main
from quilting.io import read_image, read_image_metadata, write_image

DATA = Path(__file__).resolve().parent / "data"
GRAVEL = DATA / "gravel.png"  # 256x256 gray
BRICK = DATA / "brick.png"  # 256x256 gray


def _usage_error(capsys: pytest.CaptureFixture[str], args: list[str]) -> str:
    """The command line on ``args`` exits with status 2; its stderr."""
    with pytest.raises(SystemExit) as info:
        main(args)
    assert info.value.code == 2
    return capsys.readouterr().err


def _hole() -> np.ndarray:
    """A 0/255 mask of gravel.png's size: an 80x50 rectangle to fill."""
    mask = np.zeros((256, 256), dtype=np.uint8)
    mask[100:150, 90:170] = 255
    return mask


@pytest.fixture
def mask(tmp_path: Path) -> Path:
    path = tmp_path / "mask.png"
    write_image(path, _hole())
    return path


def _fill(mask: Path, out: Path, *extra: str) -> int:
    return main(["fill", str(GRAVEL), "--mask", str(mask), "-o", str(out), "--block", "24", *extra])


# --- fill ---------------------------------------------------------------------------------------


def test_fill_keeps_every_pixel_outside_the_mask(tmp_path, capsys, mask) -> None:
    out = tmp_path / "out.png"
    assert _fill(mask, out, "--seed", "3") == 0
    gravel, hole, image = read_image(GRAVEL), _hole() > 0, read_image(out)
    assert image.shape == gravel.shape and image.dtype == gravel.dtype
    assert np.array_equal(image[~hole], gravel[~hole])  # byte for byte
    assert not np.array_equal(image[hole], gravel[hole])
    # What the Python API gives for the same inputs.
    assert np.array_equal(image, fill(gravel, _hole(), block=24, seed=3).image)
    meta = read_image_metadata(out)
    assert meta["operation"] == "fill" and meta["source"] == "gravel.png"
    assert meta["mask"] == "mask.png" and meta["seed"] == 3 and meta["block"] == 24
    assert meta["width"] == 256 and meta["backend_used"] in ("fft", "gl", "reference")
    printed = capsys.readouterr().out
    assert f"wrote {out} (256x256)" in printed and "filled 4000 pixels" in printed


def test_fill_layout_replays_with_apply_layout(tmp_path, capsys, mask) -> None:
    out, layout, seams = tmp_path / "out.png", tmp_path / "fill.json", tmp_path / "seams.png"
    args = ("--seed", "2", "--blend", "none", "--layout", str(layout), "--seams", str(seams))
    assert _fill(mask, out, *args) == 0
    # The gravel itself as its own companion, filled by the saved layout, is the output.
    again = tmp_path / "again.png"
    assert main(["apply-layout", str(layout), str(GRAVEL), "-o", str(again)]) == 0
    assert np.array_equal(read_image(again), read_image(out))
    drawn = read_image(seams)
    assert drawn.shape == (256, 256, 3)
    red = (drawn == (255, 0, 0)).all(axis=-1)
    assert red.any() and not red[_hole() == 0][:100].all()
    # A synthesis layout still goes its own way, and --texture-map is a fill layout's alone.
    synthesis = tmp_path / "synth.json"
    synthesize(read_image(GRAVEL), (64, 64), block=24).layout.save(synthesis)
    assert main(["apply-layout", str(synthesis), str(GRAVEL), "-o", str(again)]) == 0
    assert read_image(again).shape == (64, 64)
    with pytest.raises(SystemExit) as stopped:
        main(["apply-layout", str(synthesis), str(GRAVEL), "-o", str(again), "--texture-map",
              str(BRICK)])  # fmt: skip
    assert stopped.value.code == 2
    assert "--texture-map goes with a fill's layout" in capsys.readouterr().err


def test_fill_same_seed_same_bytes(tmp_path, mask) -> None:
    paths = [tmp_path / "a.png", tmp_path / "b.png", tmp_path / "c.png"]
    for path, seed in zip(paths, ["5", "5", "6"], strict=True):
        assert _fill(mask, path, "--seed", seed) == 0
    assert paths[0].read_bytes() == paths[1].read_bytes()
    assert paths[0].read_bytes() != paths[2].read_bytes()


def test_fill_options_reach_the_engine(tmp_path, mask) -> None:
    out = tmp_path / "out.png"
    extra = ["--overlap", "5", "--blend", "none", "--tolerance", "0.2", "--min-candidates", "2"]
    assert _fill(mask, out, *extra, "--error", "luminance", "--backend", "fft") == 0
    expected = fill(
        read_image(GRAVEL),
        _hole(),
        block=24,
        overlap=5,
        blend="none",
        tolerance=0.2,
        min_candidates=2,
        error="luminance",
        backend="fft",
    )
    assert np.array_equal(read_image(out), expected.image)
    meta = read_image_metadata(out)
    assert meta["overlap"] == 5 and meta["blend"] == "none" and meta["error"] == "luminance"


def test_a_transparent_mask_pixel_is_kept(tmp_path) -> None:
    rgba = np.zeros((256, 256, 4), dtype=np.uint8)
    rgba[..., :3] = _hole()[..., None]
    rgba[..., 3] = 255
    rgba[100:150, 90:130, 3] = 0  # the hole's left half: white but transparent
    path, out = tmp_path / "mask.png", tmp_path / "out.png"
    write_image(path, rgba)
    assert _fill(path, out) == 0
    gravel, image = read_image(GRAVEL), read_image(out)
    assert np.array_equal(image[:, :130], gravel[:, :130])
    assert not np.array_equal(image[100:150, 130:170], gravel[100:150, 130:170])


def test_fill_from_a_texture_covers_the_whole_image(tmp_path, capsys) -> None:
    image, texture = tmp_path / "image.png", tmp_path / "texture.png"
    write_image(image, read_image(GRAVEL)[:64, :80])
    write_image(texture, read_image(BRICK)[:96, :96])
    whole = tmp_path / "whole.png"
    write_image(whole, np.full((64, 80), 255, dtype=np.uint8))
    out = tmp_path / "out.png"
    args = ["fill", str(image), "--mask", str(whole), "--texture", str(texture), "-o", str(out)]
    assert main([*args, "--block", "20", "--seed", "1"]) == 0
    expected = fill(
        read_image(image),
        read_image(whole),
        texture=read_image(texture),
        block=20,
        seed=1,
    )
    assert expected.from_texture and np.array_equal(read_image(out), expected.image)
    assert read_image_metadata(out)["texture"] == "texture.png"
    assert "from the texture" in capsys.readouterr().out


def test_fill_companions_are_filled_the_same_way(tmp_path, capsys, mask) -> None:
    normal = np.ascontiguousarray(read_image(BRICK)[:, ::-1])  # any map of the image's size
    write_image(tmp_path / "normal.png", normal)
    out = tmp_path / "out.png"
    assert _fill(mask, out, "--seed", "2", "--with", f"normal={tmp_path / 'normal.png'}") == 0
    filled = fill(read_image(GRAVEL), _hole(), block=24, seed=2)
    written = read_image(tmp_path / "out_normal.png")
    assert np.array_equal(written, filled.apply(normal))
    hole = _hole() > 0
    assert np.array_equal(written[~hole], normal[~hole])
    assert read_image_metadata(tmp_path / "out_normal.png")["companion"] == "normal"
    assert "out_normal.png" in capsys.readouterr().out


def test_fill_from_a_texture_takes_the_textures_companions(tmp_path) -> None:
    image = read_image(GRAVEL)[:64, :64]
    texture = read_image(BRICK)[:80, :80]
    hole = np.zeros((64, 64), dtype=np.uint8)
    hole[20:44, 16:48] = 255
    ours, theirs = 255 - image, 255 - texture  # companions the fill must keep in step
    files = {"i": image, "t": texture, "m": hole, "ci": ours, "ct": theirs}
    for name, pixels in files.items():
        write_image(tmp_path / f"{name}.png", pixels)
    out = tmp_path / "out.png"
    args = ["fill", str(tmp_path / "i.png"), "--mask", str(tmp_path / "m.png"), "-o", str(out)]
    args += ["--texture", str(tmp_path / "t.png"), "--block", "16", "--blend", "none"]
    args += ["--with", f"c={tmp_path / 'ci.png'}", "--texture-with", f"c={tmp_path / 'ct.png'}"]
    assert main(args) == 0
    filled = fill(image, hole, texture=texture, block=16, blend="none")
    companion = read_image(tmp_path / "out_c.png")
    assert np.array_equal(companion, filled.apply(ours, theirs))
    # blend none: every pixel a source pixel, so the companion is the inverted image.
    assert np.array_equal(companion, 255 - read_image(out))


# --- extend -------------------------------------------------------------------------------------


def test_extend_places_the_input_unchanged_at_top_left(tmp_path, capsys) -> None:
    out = tmp_path / "out.png"
    sides = ["--top", "10", "--bottom", "7", "--left", "30", "--right", "5"]
    assert main(["extend", str(BRICK), "-o", str(out), "--block", "24", *sides]) == 0
    brick, image = read_image(BRICK), read_image(out)
    assert image.shape == (256 + 10 + 7, 256 + 30 + 5) and image.dtype == brick.dtype
    assert np.array_equal(image[10 : 10 + 256, 30 : 30 + 256], brick)
    expected = extend(brick, block=24, top=10, bottom=7, left=30, right=5)
    assert np.array_equal(image, expected.image)
    meta = read_image_metadata(out)
    assert meta["operation"] == "extend" and (meta["top"], meta["left"]) == (10, 30)
    assert (meta["width"], meta["height"]) == (291, 273)
    assert f"wrote {out} (291x273)" in capsys.readouterr().out


def test_extend_same_seed_same_bytes(tmp_path) -> None:
    paths = [tmp_path / "a.png", tmp_path / "b.png"]
    for path in paths:
        args = ["extend", str(GRAVEL), "-o", str(path), "--block", "24", "--right", "40"]
        assert main([*args, "--seed", "9"]) == 0
    assert paths[0].read_bytes() == paths[1].read_bytes()


def test_extend_companion_is_the_inputs_extended(tmp_path, capsys) -> None:
    height = np.ascontiguousarray(read_image(GRAVEL)[::-1])  # a map of the input's size
    write_image(tmp_path / "height.png", height)
    out = tmp_path / "out.png"
    args = ["extend", str(BRICK), "-o", str(out), "--block", "24", "--top", "20", "--left", "12"]
    assert main([*args, "--with", f"height={tmp_path / 'height.png'}"]) == 0
    written = read_image(tmp_path / "out_height.png")
    assert written.shape == (276, 268)
    assert np.array_equal(written[20:, 12:], height)
    expected = extend(read_image(BRICK), block=24, top=20, left=12)
    assert np.array_equal(written, expected.apply(height))
    assert "out_height.png" in capsys.readouterr().out


# --- tile --method fill -------------------------------------------------------------------------


def test_tile_method_fill_keeps_the_size_and_tiles(tmp_path, capsys) -> None:
    out = tmp_path / "tiled.png"
    assert main(["tile", str(BRICK), "-o", str(out), "--method", "fill", "--seed", "4"]) == 0
    brick, image = read_image(BRICK), read_image(out)
    assert image.shape == brick.shape and image.dtype == brick.dtype
    assert np.array_equal(image, make_tileable(brick, method="fill", seed=4).image)
    assert not np.array_equal(image, make_tileable(brick).image)  # not the cut method
    meta = read_image_metadata(out)
    assert meta["method"] == "fill" and meta["seed"] == 4
    assert "tileable along both" in capsys.readouterr().out


def test_tile_method_fill_same_seed_same_bytes(tmp_path) -> None:
    paths = [tmp_path / "a.png", tmp_path / "b.png"]
    for path in paths:
        assert main(["tile", str(BRICK), "-o", str(path), "--method", "fill", "--seed", "8"]) == 0
    assert paths[0].read_bytes() == paths[1].read_bytes()


# --- errors -------------------------------------------------------------------------------------


@pytest.fixture
def masks(tmp_path: Path) -> dict[str, str]:
    """Masks for gravel.png: the wrong size, covering everything, keeping a 40-wide strip."""
    found = {}
    small = _hole()[:100]
    whole = np.full((256, 256), 255, dtype=np.uint8)
    strip = whole.copy()
    strip[:, :40] = 0
    for name, pixels in {"small": small, "whole": whole, "strip": strip, "hole": _hole()}.items():
        write_image(tmp_path / f"{name}.png", pixels)
        found["{" + name + "}"] = str(tmp_path / f"{name}.png")
    found["{gravel}"] = str(GRAVEL)
    found["{brick}"] = str(BRICK)
    found["{rgb}"] = str(DATA / "hubble.png")
    return found


@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        (["--mask", "{small}"], ["mask is 256x100", "image's size, 256x256"]),
        (["--mask", "{hole}", "--block", "300"], ["block=300", "3..256"]),
        (["--mask", "{strip}", "--block", "64"], ["block=64", "block=40 (the largest that fits)"]),
        (["--mask", "{whole}"], ["covers the whole image", "texture"]),
        (["--mask", "{hole}", "--texture", "{rgb}"], ["texture (3 channels", "image's channels"]),
        (["--mask", "{hole}", "--overlap", "16"], ["overlap=16", "less than half the block"]),
        (["--mask", "{hole}", "--block", "2"], ["block=2"]),
        (["--mask", "missing.png"], ["missing.png"]),
        (["--mask", "{hole}", "--with", "n={small}"], ["'n'", "is 256x100 but the image"]),
        (["--mask", "{hole}", "--with", "n:hard={brick}"], ["without :KIND"]),
        (["--mask", "{hole}", "--texture-with", "n={brick}"], ["--texture-with goes with"]),
        (
            ["--mask", "{hole}", "--texture", "{brick}", "--with", "n={brick}"],
            ["--texture-with NAME=PATH", "--texture-with none"],
        ),
        (["--mask", "{hole}", "--memory-budget", "1M"], ["memory"]),
    ],
)
def test_fill_errors_are_one_line_exit_2_and_write_nothing(
    tmp_path, capsys, masks, args, fragments
) -> None:
    out = tmp_path / "out.png"
    for key, path in masks.items():  # also inside NAME={file}
        args = [a.replace(key, path) for a in args]
    err = _usage_error(capsys, ["fill", str(GRAVEL), "-o", str(out), *args])
    assert err.startswith("quilting: error: ") and err.count("\n") == 1, err
    assert all(fragment in err for fragment in fragments), err
    assert "Traceback" not in err
    assert not out.exists() and not (tmp_path / "out_n.png").exists()


def test_fill_without_a_mask_is_an_argument_error(tmp_path, capsys) -> None:
    out = tmp_path / "out.png"
    err = _usage_error(capsys, ["fill", str(GRAVEL), "-o", str(out)])
    assert "the following arguments are required: --mask" in err and "Traceback" not in err
    assert not out.exists()


@pytest.mark.parametrize(
    ("extra", "fragment"),
    [
        (["--top", "-1"], "top=-1"),
        (["--right", "70000"], "right=70000"),
        (["--right", "40", "--block", "300"], "block=300"),
        (["--right", "40", "--blend", "feather"], "invalid choice"),
        (["--right", "40", "--with", "n=missing.png"], "missing.png"),
    ],
)
def test_extend_errors_exit_2_and_write_nothing(tmp_path, capsys, extra, fragment) -> None:
    out = tmp_path / "out.png"
    err = _usage_error(capsys, ["extend", str(GRAVEL), "-o", str(out), *extra])
    assert fragment in err and "Traceback" not in err, err
    assert not out.exists()


def test_tile_method_must_be_cut_or_fill(tmp_path, capsys) -> None:
    err = _usage_error(capsys, ["tile", str(BRICK), "-o", str(tmp_path / "t.png"), "--method", "x"])
    assert "invalid choice" in err and "'cut'" in err and "'fill'" in err


# --- the parser ---------------------------------------------------------------------------------


def _subcommand(command: str) -> argparse.ArgumentParser:
    parser = build_parser()
    actions = (a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return next(actions).choices[command]


@pytest.mark.parametrize(
    ("command", "options"),
    [("fill", FillOptions), ("extend", ExtendOptions), ("tile", TileOptions)],
)
def test_every_option_field_has_a_flag_with_its_default(command: str, options: type) -> None:
    """The flags are made from the options' fields: a field added is a flag added."""
    sub = _subcommand(command)
    by_dest = {action.dest: action for action in sub._actions}
    for field in dataclasses.fields(options):
        assert field.name in by_dest, field.name
        action = by_dest[field.name]
        assert action.default == field.default, field.name
        assert "--" + field.name.replace("_", "-") in action.option_strings


def test_help_lists_the_commands(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["--help"])
    printed = capsys.readouterr().out
    assert "fill" in printed and "extend" in printed


def test_installed_command_fills_and_fails_cleanly(tmp_path, mask) -> None:
    # The console script as a user starts it (falls back to `python -m quilting`).
    exe = shutil.which("quilting", path=os.path.dirname(sys.executable))
    command = [exe] if exe else [sys.executable, "-m", "quilting"]
    out = tmp_path / "out.png"
    args = ["fill", str(GRAVEL), "--mask", str(mask), "-o", str(out), "--block", "24"]
    done = subprocess.run([*command, *args], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    hole = _hole() > 0
    assert np.array_equal(read_image(out)[~hole], read_image(GRAVEL)[~hole])
    out.unlink()
    bad = subprocess.run(
        [*command, "fill", str(GRAVEL), "--mask", str(mask), "-o", str(out), "--block", "999"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert bad.returncode == 2 and "block=999" in bad.stderr, bad.stderr
    assert "Traceback" not in bad.stderr and not out.exists()
