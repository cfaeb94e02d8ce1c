"""Unit tests of :mod:`quilting.service.fill_uploads`, called directly (no server).

Covers
------
- ``mask_fits``, ``texture_matches`` and ``extension_fits``: their 422 problems name the
  field, both sizes (or kinds) and the setting; ``extension_fits`` names the larger margin of
  the longer axis, at the boundary of ``max_side`` and ``max_output_pixels``.
- ``fill_headers``: a fill's size is its image's, an extension's its image's grown by the
  margins; a fill's image is limited as an output, an extension's as an input; a mask, a
  companion of another size and a texture of other channels or depth refused; no pixel
  decoded (the decoder patched to raise).
- ``decode_fill``: the image, mask, texture and companions decoded to their exact pixels and
  dtypes, the output size the input's; a mask or a companion of another size refused, and a
  file whose header passes but whose pixels are corrupt refused naming its part.
- ``check_fill_job``: a mask covering everything without a texture (field ``mask``), a block
  larger than the image or texture, a hole leaving no block outside it (naming the largest
  that fits), an empty hole accepted whatever the block, an extension's block against its
  image, and the cost against a budget (``job_too_large``).
- ``quilting.service.uploads``: ``check_headers``, ``decode`` and ``check`` hand fills and
  extensions to these.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from upload_builders import corrupt_pixels as _corrupt_pixels
from upload_builders import no_decoding as _no_decoding
from upload_builders import pixels as _pixels
from upload_builders import png as _png

import quilting.service.upload_images as upload_images
from quilting import Budget
from quilting.core.budget import BASE_BYTES
from quilting.io import ImageHeader, encode_png
from quilting.options import ExtendOptions, FillOptions
from quilting.service.fill_uploads import (
    FILLS,
    check_fill_job,
    decode_fill,
    extension_fits,
    fill_headers,
    mask_fits,
    texture_matches,
)
from quilting.service.jobs import JobInput, PixelLimits
from quilting.service.problems import Problem
from quilting.service.uploads import check, check_headers, decode


def _mask(height: int, width: int, box: tuple[int, int, int, int] | None = None) -> np.ndarray:
    """Black (keep) with white (fill) over ``box`` = (top, left, bottom, right)."""
    mask = np.zeros((height, width), dtype=np.uint8)
    if box is not None:
        top, left, bottom, right = box
        mask[top:bottom, left:right] = 255
    return mask


def _fill(image: bytes, mask: bytes | None, **files: Any) -> JobInput:
    return JobInput(
        texture=image,
        companions=files.pop("companions", {}),
        options={},
        width=files.pop("width", 0),
        height=files.pop("height", 0),
        operation="fill",
        mask=mask,
        **files,
    )


def _extend(image: bytes, limits: PixelLimits | None = None, **margins: int) -> JobInput:
    options = {"top": 0, "bottom": 0, "left": 0, "right": 0, **margins}
    return JobInput(
        texture=image,
        companions={},
        options=options,
        width=0,
        height=0,
        operation="extend",
        limits=limits or PixelLimits(),
    )


def test_fills_are_the_fill_and_the_extension() -> None:
    assert set(FILLS) == {"fill", "extend"}


def test_mask_fits_names_both_sizes() -> None:
    mask_fits((30, 20), (30, 20))
    with pytest.raises(Problem) as caught:
        mask_fits((20, 30), (30, 20))
    problem = caught.value
    assert (problem.status, problem.code, problem.extra) == (
        422,
        "invalid_image",
        {"field": "mask"},
    )
    assert problem.detail == "mask is 20x30; it must be the image's size, 30x20"


@pytest.mark.parametrize(("channels", "depth"), [(4, 8), (3, 16), (1, 8)])
def test_texture_matches_refuses_other_channels_or_depth(channels: int, depth: int) -> None:
    image = ImageHeader("png", 30, 20, 3, 8)
    texture_matches(ImageHeader("jpeg", 5, 9, 3, 8), image)  # the size does not matter
    with pytest.raises(Problem) as caught:
        texture_matches(ImageHeader("png", 30, 20, channels, depth), image)
    problem = caught.value
    assert (problem.code, problem.extra) == ("invalid_image", {"field": "texture"})
    assert f"({channels} channels, {depth}-bit)" in problem.detail
    assert "(3, 8-bit)" in problem.detail


def test_extension_fits_max_side_names_the_larger_margin_of_the_longer_axis() -> None:
    limits = PixelLimits(max_input_pixels=10_000, max_output_pixels=10_000, max_side=100)
    extension_fits(100, 90, {"left": 40, "right": 10}, limits)  # at the limit
    with pytest.raises(Problem) as caught:
        extension_fits(101, 90, {"left": 10, "right": 40, "top": 80}, limits)
    problem = caught.value
    assert (problem.code, problem.extra) == ("invalid_parameter", {"field": "right"})
    assert "101x90" in problem.detail and "100 pixels (max_side)" in problem.detail
    with pytest.raises(Problem) as caught:
        extension_fits(40, 101, {"left": 50, "top": 3, "bottom": 7}, limits)
    assert caught.value.extra == {"field": "bottom"}


def test_extension_fits_refuses_more_than_max_output_pixels() -> None:
    limits = PixelLimits(max_input_pixels=10_000, max_output_pixels=5000, max_side=100)
    extension_fits(100, 50, {"right": 20}, limits)  # 5000 pixels: at the limit
    with pytest.raises(Problem) as caught:
        extension_fits(100, 51, {"right": 20}, limits)
    problem = caught.value
    assert (problem.code, problem.extra) == ("invalid_parameter", {"field": "right"})
    assert "100x51, more than 5000 pixels (max_output_pixels)" in problem.detail


def test_an_extension_over_a_limit_names_a_margin_the_caller_gave() -> None:
    # A 1000x10 image grown by `top` alone: its long axis (x) was not grown, so neither
    # `left` nor `right` is the problem.
    limits = PixelLimits(max_input_pixels=10**6, max_output_pixels=100_000, max_side=1000)
    with pytest.raises(Problem) as caught:
        extension_fits(1000, 110, {"top": 100, "bottom": 0, "left": 0, "right": 0}, limits)
    assert caught.value.extra == {"field": "top"}
    with pytest.raises(Problem) as caught:
        extension_fits(1001, 10, {"bottom": 1}, limits)  # too long a side, as the input is
    assert caught.value.extra == {"field": "bottom"}


def test_fill_headers_of_a_fill_is_its_image_s_size_without_decoding(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(upload_images, "read_image", _no_decoding)
    spec = _fill(
        _png(20, 30),
        encode_png(_mask(20, 30, (5, 5, 10, 10))),
        companions={"height": _png(20, 30, 1, np.uint16)},
        source=_png(50, 60),
    )
    assert fill_headers(spec) == (30, 20)
    assert check_headers(spec) == (30, 20)


def test_fill_headers_of_an_extension_is_its_grown_size() -> None:
    assert fill_headers(_extend(_png(20, 30), top=3, bottom=4, left=5, right=6)) == (41, 27)
    limits = PixelLimits(max_input_pixels=10_000, max_output_pixels=10_000, max_side=40)
    with pytest.raises(Problem) as caught:
        check_headers(_extend(_png(20, 30), limits, top=3, bottom=4, left=5, right=6))
    assert (caught.value.code, caught.value.extra) == ("invalid_parameter", {"field": "right"})
    assert "41x27" in caught.value.detail


def test_a_fill_s_image_is_limited_as_an_output_an_extension_s_as_an_input() -> None:
    limits = PixelLimits(max_input_pixels=1000, max_output_pixels=599, max_side=1000)
    image = _png(20, 30)  # 600 pixels
    spec = _fill(image, encode_png(_mask(20, 30)), limits=limits)
    with pytest.raises(Problem) as caught:
        fill_headers(spec)
    assert (caught.value.code, caught.value.extra) == ("image_too_large", {"field": "image"})
    assert "(max_output_pixels)" in caught.value.detail
    with pytest.raises(Problem) as caught:
        decode_fill(spec)
    assert (caught.value.code, caught.value.extra) == ("image_too_large", {"field": "image"})
    # An extension's image is an input: decoded under max_input_pixels; only the extended
    # output is held to max_output_pixels, as a parameter problem naming a margin.
    extension = _extend(image, limits)
    assert decode_fill(extension).texture.shape == (20, 30, 3)
    with pytest.raises(Problem) as caught:
        fill_headers(extension)
    assert caught.value.code == "invalid_parameter"
    assert "30x20, more than 599 pixels (max_output_pixels)" in caught.value.detail


def test_fill_headers_refuses_a_mask_of_another_size() -> None:
    with pytest.raises(Problem) as caught:
        fill_headers(_fill(_png(20, 30), encode_png(_mask(30, 20))))
    assert (caught.value.code, caught.value.extra) == ("invalid_image", {"field": "mask"})
    assert caught.value.detail == "mask is 20x30; it must be the image's size, 30x20"


def test_fill_headers_refuses_a_companion_of_another_size() -> None:
    spec = _fill(_png(20, 30), None, companions={"depth": _png(20, 31, 1)})
    with pytest.raises(Problem) as caught:
        fill_headers(spec)
    problem = caught.value
    assert (problem.code, problem.extra) == ("invalid_companion", {"field": "companion"})
    assert problem.detail == "companion 'depth' is 31x20; it must be the image's size, 30x20"


def test_fill_headers_refuses_a_texture_of_other_channels_or_depth() -> None:
    for source in (_png(40, 40, 4), _png(40, 40, 3, np.uint16)):
        spec = _fill(_png(20, 30), encode_png(_mask(20, 30)), source=source)
        with pytest.raises(Problem) as caught:
            fill_headers(spec)
        assert (caught.value.code, caught.value.extra) == ("invalid_image", {"field": "texture"})


def test_fill_headers_refuses_an_undecodable_mask_naming_it() -> None:
    with pytest.raises(Problem) as caught:
        fill_headers(_fill(_png(20, 30), b"\x89PNG\r\n\x1a\n cut short"))
    assert (caught.value.code, caught.value.extra) == ("invalid_image", {"field": "mask"})


def test_decode_fill_gives_the_exact_pixels_of_every_part() -> None:
    image = _pixels(20, 30, 3, np.uint16, 1)
    mask = _mask(20, 30, (2, 3, 9, 12))
    source = _pixels(25, 26, 3, np.uint16, 2)
    depth = _pixels(20, 30, 1, np.uint8, 3)
    spec = _fill(
        encode_png(image),
        encode_png(mask),
        companions={"depth": encode_png(depth)},
        source=encode_png(source),
        width=30,
        height=20,
    )
    decoded = decode(spec)
    assert (decoded.width, decoded.height) == (30, 20)
    assert decoded.texture.dtype == np.uint16 and np.array_equal(decoded.texture, image)
    assert decoded.mask is not None and np.array_equal(decoded.mask, mask)
    assert decoded.source is not None and np.array_equal(decoded.source, source)
    assert list(decoded.companions) == ["depth"]
    assert np.array_equal(decoded.companions["depth"], depth)
    assert decoded.target is None and decoded.examples == [] and decoded.trimaps == []


def test_decode_fill_refuses_a_mask_or_companion_of_another_size() -> None:
    with pytest.raises(Problem) as caught:
        decode_fill(_fill(_png(20, 30), encode_png(_mask(21, 30))))
    assert (caught.value.code, caught.value.extra) == ("invalid_image", {"field": "mask"})
    assert "mask is 30x21" in caught.value.detail
    spec = _fill(_png(20, 30), None, companions={"z": _png(19, 30)})
    with pytest.raises(Problem) as caught:
        decode_fill(spec)
    assert (caught.value.code, caught.value.extra) == ("invalid_companion", {"field": "companion"})


@pytest.mark.parametrize("part", ["image", "mask", "texture", "companion"])
def test_decoding_refuses_corrupt_pixels_the_headers_let_through(part: str) -> None:
    files: dict[str, bytes] = {
        "image": _png(20, 30),
        "mask": encode_png(_mask(20, 30, (0, 0, 5, 5))),
        "texture": _png(24, 24),
        "companion": _png(20, 30, 1),
    }
    files[part] = _corrupt_pixels(files[part])
    spec = _fill(
        files["image"], files["mask"], source=files["texture"], companions={"c": files["companion"]}
    )
    assert fill_headers(spec) == (30, 20)
    with pytest.raises(Problem) as caught:
        decode_fill(spec)
    assert (caught.value.code, caught.value.extra) == ("invalid_image", {"field": part})


def _job(image: np.ndarray, mask: np.ndarray, source: np.ndarray | None = None) -> JobInput:
    return _fill(
        encode_png(image),
        encode_png(mask),
        source=None if source is None else encode_png(source),
        width=image.shape[1],
        height=image.shape[0],
    )


def test_check_fill_job_refuses_a_mask_covering_everything_without_a_texture() -> None:
    image = _pixels(40, 40, 3, np.uint8, 4)
    whole = _mask(40, 40, (0, 0, 40, 40))
    spec = _job(image, whole)
    with pytest.raises(Problem) as caught:
        check_fill_job(spec, FillOptions(block=8), decode(spec), Budget())
    assert (caught.value.code, caught.value.extra) == ("invalid_image", {"field": "mask"})
    assert "covers the whole image" in caught.value.detail
    spec = _job(image, whole, _pixels(30, 30, 3, np.uint8, 5))
    check_fill_job(spec, FillOptions(block=8), decode(spec), Budget())


def test_check_fill_job_refuses_a_block_larger_than_the_image_or_texture() -> None:
    image = _pixels(20, 30, 3, np.uint8, 6)
    spec = _job(image, _mask(20, 30, (5, 5, 10, 10)))
    with pytest.raises(Problem) as caught:
        check_fill_job(spec, FillOptions(block=21), decode(spec), Budget())
    assert (caught.value.code, caught.value.extra) == ("invalid_parameter", {"field": "block"})
    assert "30x20 image" in caught.value.detail
    spec = _job(image, _mask(20, 30, (5, 5, 10, 10)), _pixels(16, 40, 3, np.uint8, 7))
    with pytest.raises(Problem) as caught:
        check_fill_job(spec, FillOptions(block=17), decode(spec), Budget())
    assert caught.value.extra == {"field": "block"}
    assert "40x16 texture" in caught.value.detail
    check_fill_job(spec, FillOptions(block=16), decode(spec), Budget())


def test_check_fill_job_names_the_largest_block_that_fits_outside_the_hole() -> None:
    image = _pixels(40, 40, 3, np.uint8, 8)
    # Everything but a 12-pixel band on the left is to be filled.
    spec = _job(image, _mask(40, 40, (0, 12, 40, 40)))
    with pytest.raises(Problem) as caught:
        check_fill_job(spec, FillOptions(block=16), decode(spec), Budget())
    problem = caught.value
    assert (problem.code, problem.extra) == ("invalid_parameter", {"field": "block"})
    assert "block=12 (the largest that fits)" in problem.detail
    check_fill_job(spec, FillOptions(block=12), decode(spec), Budget())


def test_check_fill_job_takes_an_empty_hole_whatever_the_block() -> None:
    spec = _job(_pixels(20, 30, 3, np.uint8, 9), _mask(20, 30))
    check_fill_job(spec, FillOptions(block=64), decode(spec), Budget())


def test_check_fill_job_of_an_extension_checks_the_block_against_its_image() -> None:
    spec = _extend(_png(20, 30), top=8)
    spec.width, spec.height = fill_headers(spec)
    with pytest.raises(Problem) as caught:
        check_fill_job(spec, ExtendOptions(block=21, top=8), decode(spec), Budget())
    assert (caught.value.code, caught.value.extra) == ("invalid_parameter", {"field": "block"})
    check_fill_job(spec, ExtendOptions(block=20, top=8), decode(spec), Budget())


def test_check_fill_job_refuses_a_fill_over_its_budget() -> None:
    spec = _job(_pixels(40, 40, 3, np.uint8, 10), _mask(40, 40, (10, 10, 30, 30)))
    images = decode(spec)
    check_fill_job(spec, FillOptions(block=8), images, Budget())
    with pytest.raises(Problem) as caught:
        check_fill_job(spec, FillOptions(block=8), images, Budget(memory_bytes=BASE_BYTES + 1))
    assert (caught.value.status, caught.value.code) == (422, "job_too_large")


def test_check_of_a_fill_decodes_and_checks_it_whole() -> None:
    image = _pixels(24, 32, 3, np.uint8, 11)
    spec = _job(image, _mask(24, 32, (8, 8, 16, 16)))
    assert check(spec, FillOptions(block=8)) == (32, 24)
    with pytest.raises(Problem) as caught:
        check(spec, FillOptions(block=25))
    assert caught.value.extra == {"field": "block"}
    with pytest.raises(Problem) as caught:
        check(spec, FillOptions(block=8), Budget(memory_bytes=BASE_BYTES + 1))
    assert caught.value.code == "job_too_large"
