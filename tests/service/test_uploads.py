"""Unit tests of :mod:`quilting.service.uploads`, called directly (no server).

Covers
------
- ``check_headers`` of a synthesis, a transfer and a matte: the output's size (the job's, or
  its target's); a target longer than ``max_side`` or over the tighter pixel limit, a
  companion of another size (of one texture or of any of several examples), examples or a
  companion's maps of mixed kinds, a companion kind the layout cannot render, an
  undecodable source mask, silhouette or layer, and a layer's trimap of another size, each
  refused with its status, code, field and the sizes or kinds; all of it without decoding a
  pixel (the decoder patched to raise); a photo sent with a trimap counted as the RGBA
  texture it becomes.
- ``decode``: the exact pixels and dtypes of the texture, companions, target and source
  mask; several examples with their masks and companion maps (and none of those lists for
  one texture); the same refusals as the headers once decoded; a file whose structure passes
  the header check but whose pixels are corrupt refused naming its part.
- ``check``: a synthesis whose block is larger than its texture (the engine's refusal, with
  its field); a synthesis from a photo with a trimap checked as the RGBA texture it makes,
  and its maps checked by the matting rules.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from upload_builders import corrupt_pixels as _corrupt_pixels
from upload_builders import no_decoding as _no_decoding
from upload_builders import pixels as _pixels
from upload_builders import png as _png
from upload_builders import trimap as _trimap

import quilting.service.upload_images as upload_images
from quilting.io import encode_png
from quilting.options import SynthesisOptions
from quilting.service.jobs import JobInput, PixelLimits
from quilting.service.problems import Problem
from quilting.service.uploads import check, check_headers, decode


def _synthesis(texture: bytes, **files: Any) -> JobInput:
    return JobInput(
        texture=texture,
        companions=files.pop("companions", {}),
        options=files.pop("options", {}),
        width=files.pop("width", 64),
        height=files.pop("height", 48),
        operation=files.pop("operation", "synthesize"),
        **files,
    )


def _examples(*textures: bytes, **files: Any) -> JobInput:
    return _synthesis(textures[0], examples=list(textures), **files)


def _matte(layers: list[bytes], **files: Any) -> JobInput:
    return _synthesis(
        layers[0],
        operation="matte",
        layers=layers,
        target=files.pop("target", _png(30, 40)),
        silhouette=files.pop("silhouette", _png(30, 40, 1)),
        **files,
    )


def _refused(spec: JobInput) -> list[Problem]:
    """The problems of ``check_headers`` and of ``decode`` of ``spec``: each must refuse."""
    found = []
    for step in (check_headers, decode):
        with pytest.raises(Problem) as caught:
            step(spec)
        found.append(caught.value)
    return found


def test_check_headers_gives_the_job_s_size_or_its_target_s() -> None:
    assert check_headers(_synthesis(_png(20, 30), width=64, height=48)) == (64, 48)
    transfer = _synthesis(_png(20, 30), operation="transfer", target=_png(33, 71))
    assert check_headers(transfer) == (71, 33)
    decoded = decode(transfer)
    assert (decoded.width, decoded.height) == (71, 33)


def test_check_headers_decodes_no_pixel(monkeypatch: pytest.MonkeyPatch) -> None:
    spec = _examples(
        _png(20, 30),
        _png(24, 18),
        companions={"height": _png(20, 30, 1, np.uint16)},
        example_companions={"height": [_png(20, 30, 1, np.uint16), _png(24, 18, 1, np.uint16)]},
        source_masks=[_png(20, 30, 1), _png(24, 18, 1)],
        source_mask=_png(20, 30, 1),
        target=_png(40, 50),
        operation="transfer",
    )
    monkeypatch.setattr(upload_images, "read_image", _no_decoding)
    assert check_headers(spec) == (50, 40)
    matte = _matte(
        [_png(20, 30), _png(16, 16)],
        normals=_png(30, 40),
        trimaps=[encode_png(_trimap(20, 30)), None],
        scribbles=[None, None],
    )
    assert check_headers(matte) == (40, 30)
    with pytest.raises(AssertionError, match="decoded pixels"):
        decode(spec)  # and the patch does catch a decoding


def test_a_target_longer_than_max_side_is_refused_naming_its_size() -> None:
    limits = PixelLimits(max_side=40)
    assert check_headers(_synthesis(_png(10, 10), target=_png(12, 40), limits=limits)) == (40, 12)
    for problem in _refused(_synthesis(_png(10, 10), target=_png(12, 41), limits=limits)):
        assert (problem.status, problem.code) == (422, "image_too_large")
        assert problem.extra == {"field": "target"}
        assert problem.detail.startswith("target is 41x12;")
        assert "40 pixels (max_side)" in problem.detail


def test_a_target_is_held_to_the_tighter_pixel_limit_by_its_name() -> None:
    limits = PixelLimits(max_input_pixels=10_000, max_output_pixels=299)
    spec = _synthesis(_png(10, 10), target=_png(10, 30), limits=limits)
    for problem in _refused(spec):
        assert (problem.code, problem.extra) == ("image_too_large", {"field": "target"})
        assert "(max_output_pixels)" in problem.detail
    spec.limits = PixelLimits(max_input_pixels=10_000, max_output_pixels=300)
    assert check_headers(spec) == (30, 10)


def test_a_companion_of_another_size_is_refused_naming_both_sizes() -> None:
    spec = _synthesis(_png(20, 30), companions={"normal": _png(20, 29)})
    for problem in _refused(spec):
        assert (problem.code, problem.extra) == ("invalid_companion", {"field": "companion"})
        assert problem.detail == "companion 'normal' is 29x20; it must be the texture's size, 30x20"


def test_a_companion_map_of_another_example_s_size_names_that_example() -> None:
    spec = _examples(
        _png(20, 30),
        _png(24, 18),
        companions={"h": _png(20, 30, 1)},
        example_companions={"h": [_png(20, 30, 1), _png(18, 24, 1)]},
    )
    for problem in _refused(spec):
        assert problem.code == "invalid_companion"
        assert problem.detail == "companion 'h' is 24x18; it must be the texture 1's size, 18x24"


@pytest.mark.parametrize(
    ("second", "kind"),
    [((4, np.uint8), "4 channels at 8 bits"), ((3, np.uint16), "3 channels at 16 bits")],
)
def test_examples_of_mixed_kinds_are_refused(
    second: tuple[int, type[np.generic]], kind: str
) -> None:
    spec = _examples(_png(20, 30), _png(20, 30), _png(16, 16, *second))
    for problem in _refused(spec):
        assert (problem.code, problem.extra) == ("invalid_image", {"field": "texture"})
        assert problem.detail.startswith(f"texture 2 has {kind}, but texture 0 has 3 at 8")


def test_a_companion_s_maps_of_mixed_kinds_are_refused_naming_it() -> None:
    spec = _examples(
        _png(20, 30),
        _png(16, 16),
        companions={"rough": _png(20, 30, 1)},
        example_companions={"rough": [_png(20, 30, 1), _png(16, 16, 1, np.uint16)]},
    )
    for problem in _refused(spec):
        assert (problem.code, problem.extra) == ("invalid_companion", {"field": "companion"})
        assert "companion 'rough''s map of texture 1 has 1 channels at 16 bits" in problem.detail


@pytest.mark.parametrize(
    ("kind", "channels", "mode", "said"),
    [
        ("normal", 1, "cut", "needs 3 or 4 channels"),
        ("hard", 3, "walk", "walk-mode"),
        ("sharp", 3, "cut", "unknown companion kind"),
    ],
)
def test_a_companion_kind_the_layout_cannot_render_is_refused(
    kind: str, channels: int, mode: str, said: str
) -> None:
    spec = _synthesis(
        _png(20, 30),
        companions={"n": _png(20, 30, channels)},
        companion_kinds={"n": kind},
        options={"mode": mode},
    )
    for problem in _refused(spec):
        assert (problem.code, problem.extra) == ("invalid_companion", {"field": "companion_kinds"})
        assert problem.detail.startswith("companion 'n': ") and said in problem.detail


def test_companion_kinds_the_layout_renders_are_taken() -> None:
    for kind, channels, mode in (("normal", 3, "cut"), ("hard", 1, "cut"), ("blend", 1, "walk")):
        spec = _synthesis(
            _png(20, 30),
            companions={"n": _png(20, 30, channels)},
            companion_kinds={"n": kind},
            options={"mode": mode},
        )
        assert check_headers(spec) == (64, 48)
        assert decode(spec).companions["n"].shape[:2] == (20, 30)


@pytest.mark.parametrize("part", ["source_mask", "silhouette", "layer", "normals"])
def test_an_undecodable_part_is_refused_naming_it(part: str) -> None:
    junk = b"GIF89a this is no png"
    if part == "source_mask":
        spec = _synthesis(_png(20, 30), source_mask=junk)
    elif part == "layer":
        spec = _matte([_png(20, 30), junk])
    else:
        spec = _matte([_png(20, 30)], **{part: junk})
    for problem in _refused(spec):
        assert (problem.status, problem.code, problem.extra) == (
            422,
            "invalid_image",
            {"field": part},
        )


def test_a_layer_s_trimap_of_another_size_names_the_layer() -> None:
    spec = _matte(
        [_png(20, 30), _png(16, 16)],
        trimaps=[None, encode_png(_trimap(16, 17))],
        scribbles=[None, None],
    )
    for problem in _refused(spec):
        assert (problem.code, problem.extra) == ("invalid_trimap", {"field": "trimap"})
        assert problem.detail.startswith("trimap is 17x16 but the layer 1 is 16x16")


def test_a_layer_with_alpha_and_a_trimap_is_refused_naming_the_layer() -> None:
    spec = _matte(
        [_png(20, 30), _png(16, 16, 4)],
        trimaps=[None, encode_png(_trimap(16, 16))],
        scribbles=[None, None],
    )
    with pytest.raises(Problem) as caught:
        check_headers(spec)
    assert (caught.value.code, caught.value.extra) == ("invalid_image", {"field": "layer"})
    assert caught.value.detail.startswith("the layer 1 already has an alpha channel")


def test_a_photo_with_a_trimap_counts_as_the_rgba_texture_it_becomes() -> None:
    rgba, rgb = _png(20, 30, 4), _png(16, 16, 3)
    marked = _examples(rgba, rgb, trimaps=[None, encode_png(_trimap(16, 16))], scribbles=[])
    assert check_headers(marked) == (64, 48)
    decoded = decode(marked)
    assert [example.shape for example in decoded.examples] == [(20, 30, 4), (16, 16, 3)]
    assert decoded.trimaps[0] is None and decoded.trimaps[1] is not None
    assert decoded.scribbles == [None, None]
    unmarked = _examples(rgba, rgb)
    for problem in _refused(unmarked):
        assert problem.code == "invalid_image"
        assert "texture 1 has 3 channels at 8 bits, but texture 0 has 4 at 8" in problem.detail


def test_decode_gives_the_exact_pixels_of_one_texture_s_job() -> None:
    texture = _pixels(20, 30, 3, np.uint16, 1)
    height = _pixels(20, 30, 1, np.uint8, 2)
    target = _pixels(33, 71, 3, np.uint8, 3)
    mask = _pixels(20, 30, 1, np.uint8, 4)
    spec = _synthesis(
        encode_png(texture),
        companions={"height": encode_png(height)},
        target=encode_png(target),
        source_mask=encode_png(mask),
        operation="transfer",
    )
    decoded = decode(spec)
    assert decoded.texture.dtype == np.uint16 and np.array_equal(decoded.texture, texture)
    assert np.array_equal(decoded.companions["height"], height)
    assert decoded.target is not None and np.array_equal(decoded.target, target)
    assert decoded.source_mask is not None and np.array_equal(decoded.source_mask, mask)
    assert (decoded.width, decoded.height) == (71, 33)
    assert decoded.examples == [] and decoded.source_masks == []
    assert decoded.example_companions == {} and decoded.trimaps == [] and decoded.scribbles == []


def test_decode_gives_every_example_its_mask_and_companion_maps_in_order() -> None:
    examples = [_pixels(20, 30, 3, np.uint8, 5), _pixels(24, 18, 3, np.uint8, 6)]
    masks = [_pixels(20, 30, 1, np.uint8, 7), _pixels(24, 18, 1, np.uint8, 8)]
    maps = [_pixels(20, 30, 1, np.uint16, 9), _pixels(24, 18, 1, np.uint16, 10)]
    spec = _examples(
        *(encode_png(e) for e in examples),
        companions={"h": encode_png(maps[0])},
        example_companions={"h": [encode_png(m) for m in maps]},
        source_mask=encode_png(masks[0]),
        source_masks=[encode_png(m) for m in masks],
    )
    decoded = decode(spec)
    assert np.array_equal(decoded.texture, examples[0])
    assert len(decoded.examples) == 2 and len(decoded.source_masks) == 2
    for got, want in zip(decoded.examples, examples, strict=True):
        assert np.array_equal(got, want)
    for got, want in zip(decoded.source_masks, masks, strict=True):
        assert np.array_equal(got, want)
    assert list(decoded.example_companions) == ["h"]
    for got, want in zip(decoded.example_companions["h"], maps, strict=True):
        assert got.dtype == np.uint16 and np.array_equal(got, want)
    assert np.array_equal(decoded.companions["h"], maps[0])
    assert decoded.source_mask is not None and np.array_equal(decoded.source_mask, masks[0])


def test_several_examples_with_one_source_mask_keep_it_as_the_first_s() -> None:
    mask = _pixels(20, 30, 1, np.uint8, 11)
    spec = _examples(_png(20, 30), _png(16, 16), source_mask=encode_png(mask))
    decoded = decode(spec)
    assert decoded.source_mask is not None and np.array_equal(decoded.source_mask, mask)
    assert decoded.source_masks == []


@pytest.mark.parametrize("part", ["texture", "companion", "target", "source_mask"])
def test_decode_refuses_corrupt_pixels_the_headers_let_through(part: str) -> None:
    files = {
        "texture": _png(20, 30),
        "companion": _png(20, 30, 1),
        "target": _png(25, 25),
        "source_mask": _png(20, 30, 1),
    }
    files[part] = _corrupt_pixels(files[part])
    spec = _synthesis(
        files["texture"],
        companions={"c": files["companion"]},
        target=files["target"],
        source_mask=files["source_mask"],
        operation="transfer",
    )
    assert check_headers(spec) == (25, 25)
    with pytest.raises(Problem) as caught:
        decode(spec)
    assert (caught.value.code, caught.value.extra) == ("invalid_image", {"field": part})


def test_check_refuses_a_block_larger_than_the_texture_naming_the_field() -> None:
    spec = _synthesis(_png(20, 30), width=40, height=40)
    assert check(spec, SynthesisOptions(block=16)) == (40, 40)
    with pytest.raises(Problem) as caught:
        check(spec, SynthesisOptions(block=24))
    problem = caught.value
    assert (problem.status, problem.code, problem.extra) == (
        422,
        "invalid_parameter",
        {"field": "block"},
    )


def test_check_of_a_synthesis_from_a_photo_checks_its_trimap() -> None:
    photo = _png(24, 24)
    good = _synthesis(photo, width=40, height=40, trimaps=[encode_png(_trimap(24, 24))])
    # Alpha mode needs an RGBA texture: the photo with a trimap stands in for one.
    assert check(good, SynthesisOptions(block=12, mode="alpha")) == (40, 40)
    with pytest.raises(Problem) as caught:
        check(_synthesis(photo, width=40, height=40), SynthesisOptions(block=12, mode="alpha"))
    assert (caught.value.code, caught.value.extra) == ("invalid_parameter", {"field": "mode"})
    blank = np.zeros((24, 24), dtype=np.uint8)
    bad = _synthesis(photo, width=40, height=40, trimaps=[encode_png(blank)])
    with pytest.raises(Problem) as caught:
        check(bad, SynthesisOptions(block=12))
    assert (caught.value.code, caught.value.extra) == ("invalid_trimap", {"field": "trimap"})
    assert "no foreground" in caught.value.detail
