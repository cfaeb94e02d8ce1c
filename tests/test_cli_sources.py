"""The command line with several examples, transforms and weights, and Wang tile sets, run the
way a user runs it: ``synth`` of several inputs, ``apply-layout`` of several maps, ``wang``."""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from quilting import Layout, WangOptions, apply_layout, synthesize, wang_tiles
from quilting.cli import build_parser, main
from quilting.io import read_image, read_image_metadata, write_image

DATA = Path(__file__).resolve().parent / "data"
#: Small and fast: every run here quilts a few dozen 12-pixel blocks.
BLOCK = ["--block", "12"]
WANG = ["--tile", "32", "--block", "12"]


def _usage_error(capsys: pytest.CaptureFixture[str], args: list[str]) -> str:
    """The command line on ``args`` exits with status 2 (a usage error); its stderr."""
    with pytest.raises(SystemExit) as info:
        main(args)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


@pytest.fixture
def files(tmp_path: Path) -> dict[str, Path]:
    """Two examples of one texture (gray, 64x64 and 64 high by 80 wide), an RGB normal-like
    map of each example's size, masks of each size, and a one-map texture."""
    gravel, hubble = read_image(DATA / "gravel.png"), read_image(DATA / "hubble.png")
    mask_a = np.full((64, 64), 255, dtype=np.uint8)
    mask_a[:, :20] = 0  # the left third of example a is never used
    mask_b = np.full((64, 80), 255, dtype=np.uint8)
    mask_b[40:] = 0
    arrays = {
        "a": gravel[:64, :64],
        "b": gravel[100:164, 120:200],
        "na": hubble[:64, :64],
        "nb": hubble[100:164, 120:200],
        "ma": mask_a,
        "mb": mask_b,
        "rgb": hubble[:64, 64:128],  # another kind of image: RGB, not gray
    }
    folder = tmp_path / "in"
    folder.mkdir()
    for name, array in arrays.items():
        write_image(folder / f"{name}.png", array)
    return {name: folder / f"{name}.png" for name in arrays}


def _read(*paths: Path) -> list[np.ndarray]:
    return [read_image(path) for path in paths]


def _synth(files: dict[str, Path], out: Path, *extra: str, inputs: str = "ab") -> int:
    args = ["synth", *(str(files[name]) for name in inputs), "-o", str(out)]
    return main([*args, "--size", "70x50", *BLOCK, "--seed", "3", *extra])


# --- synth of several inputs ---------------------------------------------------------------


def test_synth_of_two_inputs_is_the_python_result(tmp_path, capsys, files) -> None:
    out, layout = tmp_path / "out.png", tmp_path / "out.json"
    assert _synth(files, out, "--layout", str(layout)) == 0
    image = read_image(out)
    expected = synthesize(_read(files["a"], files["b"]), (50, 70), block=12, seed=3)
    assert image.shape == (50, 70) and image.dtype == np.uint8
    assert image.tobytes() == expected.image.tobytes()
    meta = read_image_metadata(out)
    assert meta["source"] == ["a.png", "b.png"] and meta["width"] == 70
    saved = json.loads(layout.read_text())
    assert saved["version"] == 3 and len(saved["sources"]["examples"]) == 2
    line = capsys.readouterr().out.splitlines()[0]
    assert line.startswith(f"wrote {out} (70x50)") and "examples' atlas" in line


def test_one_input_is_what_it_always_was(tmp_path, files) -> None:
    """One input: the one image goes to the engine (not a list of one), the source is a name,
    the layout is the plain version 2."""
    out, layout = tmp_path / "out.png", tmp_path / "out.json"
    assert _synth(files, out, "--layout", str(layout), inputs="a") == 0
    expected = synthesize(read_image(files["a"]), (50, 70), block=12, seed=3)
    assert read_image(out).tobytes() == expected.image.tobytes()
    assert read_image_metadata(out)["source"] == "a.png"
    assert json.loads(layout.read_text())["version"] == 2


@pytest.mark.parametrize(
    ("flags", "options"),
    [
        (["--transforms", "all"], {"transforms": "all"}),
        (["--transforms", "rot90,flip_x"], {"transforms": "rot90,flip_x"}),
        (["--weights", "1,6"], {"weights": (1.0, 6.0)}),
        (["--transforms", "flips", "--weights", "5,1"], {"transforms": "flips", "weights": (5, 1)}),
    ],
)
def test_transforms_and_weights_reach_the_engine(tmp_path, files, flags, options) -> None:
    plain, out = tmp_path / "plain.png", tmp_path / "out.png"
    assert _synth(files, plain) == 0
    assert _synth(files, out, *flags) == 0
    expected = synthesize(_read(files["a"], files["b"]), (50, 70), block=12, seed=3, **options)
    assert read_image(out).tobytes() == expected.image.tobytes()
    assert read_image(out).tobytes() != read_image(plain).tobytes()
    meta = read_image_metadata(out)
    stored = {"rot90,flip_x": "identity,rot90,flip_x"}  # the options' canonical form
    transforms = options.get("transforms", "none")
    assert meta["transforms"] == stored.get(transforms, transforms)
    assert meta["weights"] == (None if "weights" not in options else list(options["weights"]))


def test_transforms_of_one_input_keep_the_layout_and_its_maps(tmp_path, files) -> None:
    """--transforms on one input: a layout of sources (version 3) that apply-layout takes with
    the one map, normal vectors turned as the engine turns them."""
    out, layout, again = tmp_path / "o.png", tmp_path / "o.json", tmp_path / "again.png"
    extra = ["--transforms", "all", "--layout", str(layout)]
    assert _synth(files, out, *extra, "--with", f"n:normal={files['na']}", inputs="a") == 0
    assert json.loads(layout.read_text())["version"] == 3
    args = ["apply-layout", str(layout), str(files["na"]), "-o", str(again), "--kind", "normal"]
    assert main(args) == 0
    expected = apply_layout(Layout.load(layout), read_image(files["na"]), kind="normal")
    assert np.array_equal(read_image(again), expected)
    assert np.array_equal(read_image(again), read_image(tmp_path / "o_n.png"))


def test_source_masks_once_per_input(tmp_path, files) -> None:
    out = tmp_path / "out.png"
    masks = ["--source-mask", str(files["ma"]), "--source-mask", str(files["mb"])]
    assert _synth(files, out, *masks) == 0
    expected = synthesize(
        _read(files["a"], files["b"]),
        (50, 70),
        block=12,
        seed=3,
        source_mask=_read(files["ma"], files["mb"]),
    )
    assert read_image(out).tobytes() == expected.image.tobytes()
    assert _synth(files, tmp_path / "plain.png") == 0
    assert read_image(out).tobytes() != read_image(tmp_path / "plain.png").tobytes()


def test_companions_of_two_inputs_and_apply_layout_of_two_maps(tmp_path, capsys, files) -> None:
    """--with NAME:KIND=A,B quilts one map per input; apply-layout with the layout and the two
    maps gives the same, and with the two examples themselves gives the output."""
    out, layout = tmp_path / "out.png", tmp_path / "out.json"
    maps = f"{files['na']},{files['nb']}"
    extra = ["--transforms", "rotations", "--layout", str(layout), "--with", f"n:normal={maps}"]
    assert _synth(files, out, *extra, "--with", f"copy={files['a']},{files['b']}") == 0
    companion = read_image(tmp_path / "out_n.png")
    assert companion.shape == (50, 70, 3)
    expected = apply_layout(Layout.load(layout), _read(files["na"], files["nb"]), kind="normal")
    assert np.array_equal(companion, expected)
    assert np.array_equal(read_image(tmp_path / "out_copy.png"), read_image(out))
    assert read_image_metadata(tmp_path / "out_n.png")["companion"] == "n"
    capsys.readouterr()

    again, same = tmp_path / "again.png", tmp_path / "same.png"
    apply = ["apply-layout", str(layout), str(files["na"]), str(files["nb"]), "-o", str(again)]
    assert main([*apply, "--kind", "normal"]) == 0
    assert np.array_equal(read_image(again), companion)
    assert (
        main(["apply-layout", str(layout), str(files["a"]), str(files["b"]), "-o", str(same)]) == 0
    )
    assert np.array_equal(read_image(same), read_image(out))
    assert capsys.readouterr().out.splitlines()[-1] == f"wrote {same} (70x50)"


def test_apply_layout_with_the_wrong_number_of_maps_exits_2(tmp_path, capsys, files) -> None:
    two, one = tmp_path / "two.json", tmp_path / "one.json"
    assert _synth(files, tmp_path / "two.png", "--layout", str(two)) == 0
    assert _synth(files, tmp_path / "one.png", "--layout", str(one), inputs="a") == 0
    out = tmp_path / "never.png"
    err = _usage_error(capsys, ["apply-layout", str(two), str(files["na"]), "-o", str(out)])
    assert "2 example(s); got 1 companion map(s)" in err
    three = [str(files[n]) for n in ("na", "nb", "na")]
    err = _usage_error(capsys, ["apply-layout", str(two), *three, "-o", str(out)])
    assert "got 3 companion map(s)" in err
    err = _usage_error(capsys, ["apply-layout", str(two), *three[1::-1], "-o", str(out)])
    assert "companion map 0 is 80x64" in err and "example 0 was 64x64" in err
    err = _usage_error(capsys, ["apply-layout", str(one), *three[:2], "-o", str(out)])
    assert "made from one texture" in err and "got 2" in err
    assert not out.exists()


def _must_not_run(*args: object, **kwargs: object) -> None:
    raise AssertionError("the engine ran although the command was refused")


@pytest.mark.parametrize(
    ("extra", "fragment"),
    [
        (["--weights", "1,2,3"], "weights=[1.0, 2.0, 3.0] is not allowed"),
        (["--weights", "2"], "2 number(s), one per example"),
        (["--source-mask", "{ma}"], "--source-mask is given 1 time(s) for 2 input images"),
        (["--with", "n={na}"], "with 2 input images give 2 comma-separated paths"),
        (["--with", "n={na},{nb},{na}"], "got 3"),
        (["--with", "n={na},"], "got 1"),
        (["--with", "n={nb},{na}"], "companion 'n' map 1 ('"),
        (["--with", "n={na},{missing}"], "missing.png"),
        (["--with", "n:bumpy={na},{nb}"], "the kind 'bumpy' is not one of"),
    ],
)
def test_bad_sources_fail_before_quilting_and_write_nothing(
    tmp_path, capsys, monkeypatch, files, extra, fragment
) -> None:
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    subst = {k: str(v) for k, v in files.items()} | {"missing": str(tmp_path / "missing.png")}
    extra = [a.format(**subst) for a in extra]
    if extra[0] != "--weights":  # the engine counts the weights, before any work
        monkeypatch.setattr("quilting.cli.synthesize", _must_not_run)
    args = ["synth", str(files["a"]), str(files["b"]), "-o", str(out_dir / "o.png")]
    err = _usage_error(capsys, [*args, "--size", "70x50", *BLOCK, *extra])
    assert err.startswith("quilting: error: ") and err.count("\n") == 1, err
    assert fragment in err
    assert list(out_dir.iterdir()) == []


@pytest.mark.parametrize(
    ("extra", "fragment"),
    [
        (["--weights", "2,x"], "argument --weights: weights: '2,x' is not comma-separated"),
        (["--weights", "1,0"], "weights=(1.0, 0.0) is not allowed: 0.0 is not a number > 0"),
        (["--weights", "1,nan"], "is not a number > 0"),
        (["--weights", ""], "argument --weights"),
        (
            ["--transforms", "spin"],
            "transforms='spin' is not allowed: 'spin' is neither a transform nor a preset",
        ),
        (["--transforms", "rot90,bogus"], "'bogus' is neither a transform nor a preset"),
    ],
)
def test_bad_transforms_and_weights_are_argument_errors(capsys, files, extra, fragment) -> None:
    args = ["synth", str(files["a"]), str(files["b"]), "-o", "never.png", "--size", "70x50"]
    err = _usage_error(capsys, [*args, *extra])
    assert fragment in err, err


def test_examples_of_different_kinds_exit_2(tmp_path, capsys, files) -> None:
    out = tmp_path / "o.png"
    args = ["synth", str(files["a"]), str(files["rgb"]), "-o", str(out), "--size", "70x50"]
    err = _usage_error(capsys, [*args, *BLOCK])
    assert "examples must be of one kind" in err and not out.exists()


def test_help_lists_the_presets_and_the_syntax(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["synth", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for word in ("'flips'", "'rotations'", "'all'", "rot90", "transverse", "--weights 2,1,1"):
        assert word in text, word
    assert "NAME[:KIND]=PATH[,PATH...]" in text and "comma-separated in the inputs' order" in text


# --- wang ----------------------------------------------------------------------------------


@pytest.mark.parametrize("colors", [2, 3])
def test_wang_writes_the_atlas_manifest_and_preview(tmp_path, capsys, files, colors) -> None:
    atlas, preview = tmp_path / "tiles.png", tmp_path / "look.png"
    args = ["wang", str(files["a"]), str(files["b"]), "-o", str(atlas), *WANG]
    args += ["--colors", str(colors), "--seed", "2", "--preview", str(preview)]
    assert main(args) == 0
    tiles = wang_tiles(_read(files["a"], files["b"]), tile=32, block=12, colors=colors, seed=2)
    image = read_image(atlas)
    assert image.shape == (colors**2 * 32, colors**2 * 32)
    assert np.array_equal(image, tiles.atlas())

    manifest = json.loads((tmp_path / "tiles.json").read_text())  # beside it, named after it
    assert manifest["tile"] == 32 and manifest["colors"] == colors
    assert manifest["image"] == "tiles.png" and manifest["source"] == ["a.png", "b.png"]
    assert len(manifest["tiles"]) == colors**4
    for k, entry in enumerate(manifest["tiles"]):
        edges = [entry[side] for side in ("n", "e", "s", "w")]
        assert edges == tiles.edges[k].tolist() and all(0 <= c < colors for c in edges)
        x, y = entry["x"], entry["y"]
        assert np.array_equal(image[y : y + 32, x : x + 32], tiles.tiles[k])
    # Every combination of edge colours once: the complete set.
    assert len({tuple(t[s] for s in "nesw") for t in manifest["tiles"]}) == colors**4

    shown = read_image(preview)
    assert shown.shape == (6 * 32, 6 * 32)
    assert np.array_equal(shown, tiles.render(tiles.arrange(6, 6, 2)))
    meta = read_image_metadata(atlas)
    assert meta["operation"] == "wang_tiles" and meta["colors"] == colors
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"wrote {atlas} ({colors**2 * 32}x{colors**2 * 32}) in ")
    assert f"{colors**4} tiles of 32x32, {colors} colours per edge" in lines[0]
    assert lines[1].startswith(f"wrote {preview} (192x192)") and len(lines) == 2


def test_wang_options_manifest_path_and_preview_flags(tmp_path, files) -> None:
    atlas, manifest, preview = tmp_path / "a.png", tmp_path / "set.json", tmp_path / "p.png"
    args = ["wang", str(files["b"]), "-o", str(atlas), *WANG, "--transforms", "all"]
    args += ["--manifest", str(manifest), "--preview", str(preview)]
    args += ["--preview-size", "3x2", "--preview-seed", "9", "--blend", "none"]
    assert main(args) == 0
    tiles = wang_tiles(read_image(files["b"]), tile=32, block=12, transforms="all", blend="none")
    assert np.array_equal(read_image(atlas), tiles.atlas())
    assert json.loads(manifest.read_text())["meta"]["transforms"] == "all"
    assert not (tmp_path / "a.json").exists()
    shown = read_image(preview)
    assert shown.shape == (2 * 32, 3 * 32)
    assert np.array_equal(shown, tiles.render(tiles.arrange(2, 3, 9)))


def test_wang_weights_reach_the_engine(tmp_path, files) -> None:
    atlas = tmp_path / "w.png"
    args = ["wang", str(files["a"]), str(files["b"]), "-o", str(atlas), *WANG]
    assert main([*args, "--weights", "1,9"]) == 0
    tiles = wang_tiles(_read(files["a"], files["b"]), tile=32, block=12, weights=(1, 9))
    plain = wang_tiles(_read(files["a"], files["b"]), tile=32, block=12)
    assert np.array_equal(read_image(atlas), tiles.atlas())
    assert not np.array_equal(tiles.atlas(), plain.atlas())


def test_wang_companions_are_atlases_of_the_same_tiles(tmp_path, capsys, files) -> None:
    atlas, preview = tmp_path / "set.png", tmp_path / "look.png"
    maps = f"{files['na']},{files['nb']}"
    args = ["wang", str(files["a"]), str(files["b"]), "-o", str(atlas), *WANG]
    args += ["--with", f"n:normal={maps}", "--with", f"self={files['a']},{files['b']}"]
    assert main([*args, "--preview", str(preview)]) == 0
    tiles = wang_tiles(_read(files["a"], files["b"]), tile=32, block=12)
    normal = tiles.apply(_read(files["na"], files["nb"]), kind="normal")
    written = read_image(tmp_path / "set_n.png")
    assert written.shape == (128, 128, 3) and np.array_equal(written, tiles.atlas(normal))
    # The examples themselves as a companion give the atlas again.
    assert np.array_equal(read_image(tmp_path / "set_self.png"), read_image(atlas))
    assert read_image_metadata(tmp_path / "set_n.png")["companion"] == "n"
    manifest = json.loads((tmp_path / "set.json").read_text())
    assert manifest["companions"] == {"n": "set_n.png", "self": "set_self.png"}
    arranged = tiles.arrange(6, 6, 0)
    assert np.array_equal(read_image(tmp_path / "look_n.png"), tiles.render(arranged, normal))
    out = capsys.readouterr().out
    assert f"wrote {tmp_path / 'set_n.png'} (128x128), companion 'n'" in out


def test_wang_companion_of_one_input(tmp_path, files) -> None:
    atlas = tmp_path / "one.png"
    args = ["wang", str(files["a"]), "-o", str(atlas), *WANG, "--with", f"h:hard={files['na']}"]
    assert main(args) == 0
    tiles = wang_tiles(read_image(files["a"]), tile=32, block=12)
    expected = tiles.atlas(tiles.apply(read_image(files["na"]), kind="hard"))
    assert np.array_equal(read_image(tmp_path / "one_h.png"), expected)


@pytest.mark.parametrize(
    ("extra", "fragment"),
    [
        (["--tile", "31"], "tile=31 is not allowed"),
        (["--tile", "8"], "tile=8 is not allowed"),
        (["--colors", "5"], "colors=5 is not allowed (allowed: 2..4)"),
        (["--colors", "two"], "argument --colors"),
        (["--block", "99"], "block=99"),
        (["--weights", "1,2,3"], "weights=[1.0, 2.0, 3.0] is not allowed"),
        (["--weights=-1,2"], "weights=(-1.0, 2.0) is not allowed"),
        (["--transforms", "sideways"], "'sideways' is neither a transform nor a preset"),
        (["--preview", "{p}", "--preview-size", "0x2"], "at least one tile each way"),
        (["--preview", "{p}", "--preview-size", "big"], "'big' is not COLSxROWS"),
        (["--preview", "{p}", "--preview-size", "600x2"], "--preview-size 600x2"),
        (["--preview-seed", "-1"], "argument --preview-seed: seed=-1 is not allowed"),
        (["--preview-seed", "x"], "'x' is not a whole number"),
        (["--preview", "{d}/p.gif"], "'.gif' names no format"),
        (["--with", "n={na}"], "with 2 input images give 2 comma-separated paths"),
        (["--with", "n={nb},{na}"], "companion 'n' map 1"),
        (["--memory-budget", "1K"], "memory"),
    ],
)
def test_wang_errors_are_clear_and_write_nothing(tmp_path, capsys, files, extra, fragment) -> None:
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    subst = {k: str(v) for k, v in files.items()} | {"p": str(out_dir / "p.png"), "d": str(out_dir)}
    args = ["wang", str(files["a"]), str(files["b"]), "-o", str(out_dir / "set.png"), *WANG]
    err = _usage_error(capsys, [*args, *(a.format(**subst) for a in extra)])
    assert fragment in err, err
    assert list(out_dir.iterdir()) == []


def test_wang_output_format_is_checked_first(tmp_path, capsys, monkeypatch, files) -> None:
    monkeypatch.setattr("quilting.cli.wang_tiles", _must_not_run)
    err = _usage_error(capsys, ["wang", str(files["a"]), "-o", str(tmp_path / "s.bmp"), *WANG])
    assert "'.bmp' names no format" in err


def test_wang_has_a_flag_for_every_option_field() -> None:
    """The flags are made from WangOptions' fields: a field added is a flag added."""
    parser = build_parser()
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    dests = {action.dest for action in commands.choices["wang"]._actions}
    names = {f.name for f in dataclasses.fields(WangOptions)}
    assert names <= dests, sorted(names - dests)
