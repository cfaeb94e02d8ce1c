"""The command line's alpha from an ordinary photo, run the way a user runs it:
``quilting extract-alpha``, and ``synth --trimap/--scribbles`` and ``matte --trimap LAYER=FILE``,
which extract the alpha first and then alpha-quilt the texture."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
import pytest

from quilting import AlphaOptions, extract_alpha, matte, synthesize
from quilting.cli import build_parser, main
from quilting.io import read_image, read_image_metadata, write_image

DATA = Path(__file__).resolve().parent / "data"
#: Small and fast: a 96x96 photo quilted with 16-pixel blocks.
SIDE = 96
BLOCK = ["--block", "16"]


def _usage_error(capsys: pytest.CaptureFixture[str], args: list[str]) -> str:
    """The command line on ``args`` exits with status 2; its stderr, one line, no traceback."""
    with pytest.raises(SystemExit) as info:
        main(args)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("quilting: error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err
    return err


def _photo(depth: type = np.uint8) -> tuple[np.ndarray, np.ndarray]:
    """A photo with no alpha, the white cloud of ``cloud_rgba.png`` (halved to 96x96) over a
    smooth colour gradient, in ``depth``; and the cloud's true alpha in [0, 1]."""
    cloud = read_image(DATA / "cloud_rgba.png")[::2, ::2].astype(np.float64) / 255
    alpha = cloud[..., 3:]
    y, x = np.mgrid[0:SIDE, 0:SIDE] / (SIDE - 1)
    sky = np.stack([0.2 + 0.3 * x, 0.35 + 0.4 * y, 0.6 + 0.3 * x * y], axis=-1)
    top = np.iinfo(depth).max
    photo = np.rint((cloud[..., :3] * alpha + sky * (1 - alpha)) * top).astype(depth)
    return photo, alpha[..., 0]


def _trimap(alpha: np.ndarray) -> np.ndarray:
    """White where the cloud is nearly opaque, black where nearly clear, grey between."""
    trimap = np.full(alpha.shape, 128, dtype=np.uint8)
    trimap[alpha > 0.95] = 255
    trimap[alpha < 0.05] = 0
    return trimap


@pytest.fixture
def files(tmp_path: Path) -> dict[str, Path]:
    """The photo (8 and 16 bits), its trimap, scribbles (RGBA strokes on a clear layer),
    maps that cannot guide a matting, an RGBA texture and a second photo's trimap."""
    photo, alpha = _photo()
    photo16, _ = _photo(np.uint16)
    trimap = _trimap(alpha)
    scribbles = np.zeros((SIDE, SIDE, 4), dtype=np.uint8)  # clear: unknown
    fg = np.argwhere(alpha > 0.95)[:40]  # a few opaque pixels stroked white
    scribbles[fg[:, 0], fg[:, 1]] = (255, 255, 255, 255)
    scribbles[0:4, 0:30] = (0, 0, 0, 255)  # a black stroke over the clear sky
    no_background = np.where(trimap == 0, 128, trimap).astype(np.uint8)
    arrays = {
        "photo": photo,
        "photo16": photo16,
        "trimap": trimap,
        "scribbles": scribbles,
        "small": trimap[:64, :80],
        "nobg": no_background,
        "rgba": read_image(DATA / "cloud_rgba.png")[::2, ::2],
    }
    folder = tmp_path / "in"
    folder.mkdir()
    for name, array in arrays.items():
        write_image(folder / f"{name}.png", array)
    return {name: folder / f"{name}.png" for name in arrays}


def _subcommand(name: str) -> argparse.ArgumentParser:
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return action.choices[name]


# --- extract-alpha ------------------------------------------------------------------------------


@pytest.mark.parametrize("photo", ["photo", "photo16"])
def test_extract_alpha_writes_the_rgba_texture_and_the_alpha(tmp_path, capsys, files, photo):
    out, alpha_out = tmp_path / "tex.png", tmp_path / "alpha.png"
    args = ["extract-alpha", str(files[photo]), "--trimap", str(files["trimap"])]
    assert main([*args, "-o", str(out), "--alpha-out", str(alpha_out), "--method", "cf"]) == 0

    given = read_image(files[photo])
    trimap = read_image(files["trimap"])
    image, alpha = read_image(out), read_image(alpha_out)
    # RGBA and gray of the photo's size and bit depth.
    assert image.shape == (SIDE, SIDE, 4) and image.dtype == given.dtype
    assert alpha.shape == (SIDE, SIDE) and alpha.dtype == given.dtype
    top = np.iinfo(given.dtype).max
    # The alpha is the trimap's where it is white or black, and the same in both files.
    assert np.all(image[..., 3][trimap == 255] == top)
    assert np.all(image[..., 3][trimap == 0] == 0)
    assert np.array_equal(alpha, image[..., 3])
    unknown = trimap == 128
    assert unknown.any() and 0 < alpha[unknown].mean() < top
    # The texture of quilting.extract_alpha for the same inputs.
    expected = extract_alpha(given, trimap, method="cf")
    assert np.array_equal(image, expected.image)

    meta = read_image_metadata(out)
    assert meta["operation"] == "extract-alpha" and meta["source"] == f"{photo}.png"
    assert meta["trimap"] == "trimap.png" and meta["method"] == "cf"
    assert meta["iterations"] == expected.iterations and "seconds" not in meta
    assert meta["unknown"] == pytest.approx(unknown.mean(), abs=1e-4)
    assert meta["width"] == SIDE and meta["height"] == SIDE
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"wrote {out} ({SIDE}x{SIDE}) in ")
    assert f"cf matting, {unknown.mean():.1%} of the photo unknown, " in lines[0]
    assert f"{expected.iterations} iterations, foreground ml" in lines[0]
    assert lines[1] == f"wrote {alpha_out} ({SIDE}x{SIDE}), the alpha alone"


def test_extract_alpha_flags_reach_the_options(tmp_path, files) -> None:
    """--method and --foreground: 'photo' keeps the photo's own colours under the alpha."""
    out = tmp_path / "tex.png"
    args = ["extract-alpha", str(files["photo"]), "--trimap", str(files["trimap"])]
    assert main([*args, "-o", str(out), "--method", "knn", "--foreground", "photo"]) == 0
    photo, image = read_image(files["photo"]), read_image(out)
    assert np.array_equal(image[..., :3], photo)
    expected = extract_alpha(photo, read_image(files["trimap"]), method="knn", foreground="photo")
    assert np.array_equal(image, expected.image)
    meta = read_image_metadata(out)
    assert meta["method"] == "knn" and meta["foreground"] == "photo"


def test_extract_alpha_from_scribbles_and_from_both(tmp_path, files) -> None:
    strokes = read_image(files["scribbles"])
    white = strokes[..., 3] == 255
    white &= strokes[..., 0] == 255
    black = (strokes[..., 3] == 255) & (strokes[..., 0] == 0)
    out = tmp_path / "s.png"
    base = ["extract-alpha", str(files["photo"]), "--method", "cf"]
    assert main([*base, "--scribbles", str(files["scribbles"]), "-o", str(out)]) == 0
    alpha = read_image(out)[..., 3]
    assert np.all(alpha[white] == 255) and np.all(alpha[black] == 0)
    meta = read_image_metadata(out)
    assert meta["scribbles"] == "scribbles.png" and "trimap" not in meta
    # Mostly unknown: only the strokes are known.
    assert meta["unknown"] == pytest.approx(1 - (white | black).mean(), abs=1e-4)

    both = tmp_path / "both.png"
    args = [*base, "--trimap", str(files["trimap"]), "--scribbles", str(files["scribbles"])]
    assert main([*args, "-o", str(both)]) == 0
    trimap = read_image(files["trimap"])
    expected = extract_alpha(read_image(files["photo"]), trimap, strokes, method="cf")
    assert np.array_equal(read_image(both), expected.image)


def test_extract_alpha_has_a_flag_for_every_option_field() -> None:
    dests = {action.dest for action in _subcommand("extract-alpha")._actions}
    names = {f.name for f in dataclasses.fields(AlphaOptions)}
    assert names <= dests, sorted(names - dests)
    assert {"memory_budget", "time_budget", "alpha_out", "trimap", "scribbles"} <= dests


@pytest.mark.parametrize(
    ("photo", "extra", "out", "fragment"),
    [
        ("photo", ["--trimap", "{small}"], "o.png", "is 80x64 but the photo"),
        ("photo", ["--trimap", "{nobg}"], "o.png", "marks no background"),
        ("rgba", ["--trimap", "{trimap}"], "o.png", "already has an alpha channel"),
        ("missing", ["--trimap", "{trimap}"], "o.png", "missing.png"),
        ("photo", ["--trimap", "{tmp}/none.png"], "o.png", "--trimap: "),
        ("photo", [], "o.png", "needs --trimap"),
        ("photo", ["--trimap", "{trimap}"], "o.jpg", "alpha channel"),
        ("photo", ["--trimap", "{trimap}", "--alpha-out", "{tmp}/a.gif"], "o.png", "'.gif'"),
    ],
)
def test_extract_alpha_errors_are_one_line_and_write_nothing(
    tmp_path, capsys, files, photo, extra, out, fragment
) -> None:
    folder = tmp_path / "out"
    folder.mkdir()
    subst = {f"{{{name}}}": str(path) for name, path in files.items()} | {"{tmp}": str(folder)}
    given = str(files[photo]) if photo in files else str(tmp_path / f"{photo}.png")
    args = [a.replace("{tmp}", str(folder)) for a in (subst.get(a, a) for a in extra)]
    err = _usage_error(capsys, ["extract-alpha", given, *args, "-o", str(folder / out)])
    assert fragment in err, err
    assert list(folder.iterdir()) == []


def test_bad_method_is_an_argument_error(capsys, files) -> None:
    args = ["extract-alpha", str(files["photo"]), "--trimap", str(files["trimap"])]
    with pytest.raises(SystemExit) as info:
        main([*args, "-o", "o.png", "--method", "magic"])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "--method" in err and "'cf'" in err and "Traceback" not in err


def test_extract_alpha_budget_refuses_before_any_work(tmp_path, capsys, files) -> None:
    out = tmp_path / "o.png"
    args = ["extract-alpha", str(files["photo"]), "--trimap", str(files["trimap"])]
    err = _usage_error(capsys, [*args, "-o", str(out), "--time-budget", "1e-9"])
    assert "over the budget of 1e-09 s" in err
    assert not out.exists()


# --- synth --trimap / --scribbles ----------------------------------------------------------------


def test_synth_of_a_photo_and_trimap_alpha_quilts_the_extracted_texture(
    tmp_path, capsys, files
) -> None:
    outs = [tmp_path / "a.png", tmp_path / "b.png"]
    flags = ["--size", "80x64", *BLOCK, "--seed", "5", "--matting", "cf", "--blend", "none"]
    for out in outs:
        args = ["synth", str(files["photo"]), "--trimap", str(files["trimap"]), "-o", str(out)]
        assert main([*args, *flags]) == 0
    assert outs[0].read_bytes() == outs[1].read_bytes()  # same seed, same bytes

    image = read_image(outs[0])
    assert image.shape == (64, 80, 4) and image.dtype == np.uint8
    photo, trimap = read_image(files["photo"]), read_image(files["trimap"])
    expected = synthesize(
        photo, (64, 80), trimap=trimap, block=16, seed=5, matting="cf", blend="none"
    )
    assert np.array_equal(image, expected.image)
    # Cut, not blended: every output pixel, alpha included, is one of the extracted texture's.
    texture = expected.extracted[0].image.reshape(-1, 4)
    assert set(map(tuple, image.reshape(-1, 4))) <= set(map(tuple, texture))

    meta = read_image_metadata(outs[0])
    assert meta["trimap"] == ["trimap.png"] and meta["matting"] == "cf"
    (record,) = meta["extracted"]
    assert record == {k: v for k, v in expected.extracted[0].summary().items() if k != "seconds"}
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"wrote {outs[0]} (80x64) in ")
    assert lines[1].startswith(f"alpha of '{files['photo']}' extracted in ")
    assert f"cf matting, {np.mean(trimap == 128):.1%} of the photo unknown" in lines[1]
    assert f"{expected.extracted[0].iterations} iterations" in lines[1]


def test_synth_of_two_inputs_takes_one_trimap_per_input(tmp_path, capsys, files) -> None:
    """An empty --trimap= stands for an input without one (here, one already RGBA)."""
    out = tmp_path / "o.png"
    args = ["synth", str(files["photo"]), str(files["rgba"]), "-o", str(out)]
    args += ["--trimap", str(files["trimap"]), "--trimap=", "--matting", "cf"]
    assert main([*args, "--size", "64x64", *BLOCK, "--seed", "2"]) == 0
    photo, trimap, rgba = (read_image(files[n]) for n in ("photo", "trimap", "rgba"))
    expected = synthesize(
        [photo, rgba], (64, 64), trimap=[trimap, None], block=16, seed=2, matting="cf"
    )
    assert np.array_equal(read_image(out), expected.image)
    meta = read_image_metadata(out)
    assert meta["trimap"] == ["trimap.png", None]
    assert meta["extracted"][1] is None and meta["extracted"][0]["method"] == "cf"
    printed = capsys.readouterr().out
    assert f"alpha of input 1 ('{files['photo']}') extracted in " in printed
    assert "input 2" not in printed


def test_synth_scribbles_reach_the_engine(tmp_path, files) -> None:
    out = tmp_path / "o.png"
    args = ["synth", str(files["photo"]), "--scribbles", str(files["scribbles"])]
    assert main([*args, "-o", str(out), "--size", "48x48", *BLOCK, "--matting", "cf"]) == 0
    photo, strokes = read_image(files["photo"]), read_image(files["scribbles"])
    expected = synthesize(photo, (48, 48), scribbles=strokes, block=16, matting="cf")
    assert np.array_equal(read_image(out), expected.image)
    assert read_image_metadata(out)["scribbles"] == ["scribbles.png"]


@pytest.mark.parametrize(
    ("inputs", "extra", "fragment"),
    [
        (["photo"], ["--trimap", "{small}"], "--trimap '"),
        (["photo"], ["--trimap", "{nobg}"], "marks no background"),
        (["photo"], ["--trimap", "{trimap}", "--trimap", "{trimap}"], "given 2 time(s) for 1"),
        (["photo", "photo"], ["--trimap", "{trimap}"], "once per input"),
        (["photo", "photo"], ["--trimap=", "--trimap="], "empty for every input"),
        (["photo", "photo"], ["--trimap", "{trimap}", "--trimap", "{small}"], "input 2"),
        (["rgba"], ["--trimap", "{trimap}"], "already has an alpha channel"),
        (["photo"], ["--scribbles", "{tmp}/none.png"], "--scribbles: "),
    ],
)
def test_synth_trimap_errors_are_one_line_and_write_nothing(
    tmp_path, capsys, files, inputs, extra, fragment
) -> None:
    folder = tmp_path / "out"
    folder.mkdir()
    subst = {f"{{{name}}}": str(path) for name, path in files.items()}
    args = [subst.get(a, a).replace("{tmp}", str(folder)) for a in extra]
    given = [str(files[name]) for name in inputs]
    err = _usage_error(
        capsys, ["synth", *given, *args, "-o", str(folder / "o.png"), "--size", "48x48", *BLOCK]
    )
    assert fragment in err, err
    assert list(folder.iterdir()) == []


def test_synth_with_a_trimap_refuses_a_jpeg_output_before_the_work(
    tmp_path, capsys, monkeypatch, files
) -> None:
    """The extracted texture is RGBA: its output must be a PNG, checked before anything runs."""

    def must_not_run(*args: object, **kwargs: object) -> None:
        raise AssertionError("the synthesis ran although the output name was bad")

    monkeypatch.setattr("quilting.cli.synthesize", must_not_run)
    out = tmp_path / "o.jpg"
    args = ["synth", str(files["photo"]), "--trimap", str(files["trimap"]), "-o", str(out)]
    err = _usage_error(capsys, [*args, "--size", "48x48"])
    assert "alpha channel" in err and ".png" in err
    assert not out.exists()


def test_synth_and_matte_have_the_trimap_flags() -> None:
    for command in ("synth", "matte"):
        dests = {action.dest for action in _subcommand(command)._actions}
        assert {"trimap", "scribbles", "matting"} <= dests, command


# --- matte --trimap LAYER=FILE ------------------------------------------------------------------


def test_matte_extracts_the_alpha_of_a_photo_layer(tmp_path, capsys, files, sphere_files) -> None:
    target_path, mask_path, target, mask = sphere_files
    out = tmp_path / "o.png"
    args = ["matte", str(target_path), "--silhouette", str(mask_path), "-o", str(out)]
    args += ["--layer", str(DATA / "brick.png"), "--layer", str(files["photo"])]
    args += ["--trimap", f"2={files['trimap']}", "--matting", "cf"]
    assert main([*args, "--block", "24", "--seed", "3", "--clusters", "4"]) == 0

    layers = [read_image(DATA / "brick.png"), read_image(files["photo"])]
    trimap = read_image(files["trimap"])
    expected = matte(
        target,
        layers,
        silhouette=mask,
        trimap=[None, trimap],
        block=24,
        seed=3,
        clusters=4,
        matting="cf",
    )
    image = read_image(out)
    # The target's size and depth, RGB since the layers have colour.
    assert image.shape == (SIDE, SIDE, 3) and image.dtype == np.uint8
    outside = mask == 0
    assert np.array_equal(image[outside], np.repeat(target[outside][:, None], 3, axis=1))
    assert np.array_equal(image, expected.image)
    found = expected.layers[1].extracted[0]
    assert expected.layers[0].extracted == ()
    meta = read_image_metadata(out)
    assert meta["trimap"] == [None, "trimap.png"] and "scribbles" not in meta
    assert meta["extracted"][0] is None
    assert meta["extracted"][1] == {k: v for k, v in found.summary().items() if k != "seconds"}
    lines = capsys.readouterr().out.splitlines()
    assert lines[-1].startswith(f"alpha of layer 2 ('{files['photo']}') extracted in ")
    assert f"{found.iterations} iterations" in lines[-1]


@pytest.mark.parametrize(
    ("extra", "fragment"),
    [
        (["--trimap", "{trimap}"], "is not LAYER=FILE"),
        (["--trimap", "3={trimap}"], "LAYER is 1 to 2"),
        (["--trimap", "0={trimap}"], "LAYER is 1 to 2"),
        (["--trimap", "2={trimap}", "--trimap", "2={trimap}"], "layer 2 is given twice"),
        (["--scribbles", "2={small}"], "but layer 2"),
        (["--trimap", "2={nobg}"], "marks no background"),
        (["--trimap", "2={tmp}/none.png"], "--trimap: "),
    ],
)
def test_bad_matte_trimaps_exit_2(tmp_path, capsys, files, sphere_files, extra, fragment) -> None:
    target_path, mask_path, _, _ = sphere_files
    folder = tmp_path / "out"
    folder.mkdir()
    args = ["matte", str(target_path), "--silhouette", str(mask_path)]
    args += ["-o", str(folder / "o.png"), "--layer", str(DATA / "brick.png")]
    args += ["--layer", str(files["photo"]), "--block", "24"]
    subst = {f"{{{name}}}": str(path) for name, path in files.items()} | {"{tmp}": str(folder)}
    for text in extra:
        for key, value in subst.items():
            text = text.replace(key, value)
        args.append(text)
    err = _usage_error(capsys, args)
    assert fragment in err, err
    assert list(folder.iterdir()) == []
