"""Unit tests of :mod:`quilting.service.extract_uploads`, called directly (no server).

Covers
------
- ``no_marks``, ``photo_fits`` and ``photo_roles``: the problem of an extraction without a
  map, of a photo that already has alpha (its field the role's first word), and how several
  photos are named.
- ``marks_headers``: a photo without marks comes back as it is (alpha or not); with a trimap
  or scribbles, the header of the RGBA texture the extraction makes (4 channels, the photo's
  depth); a map of another size refused naming the map, both sizes and the photo's role; a
  map over the pixel limit refused naming the map and the setting.
- ``extract_headers``: the photo's (width, height); no map, a photo with alpha and a map of
  another size refused; the photo's limit is the tighter of the input and output limits; no
  pixel is decoded (the decoder patched to raise).
- ``decode_marks``: each photo's maps decoded to their exact pixels, None where none was
  sent; a map of another size refused once decoded.
- ``check_marks``: the opaque RGBA stand-in (colours kept, gray repeated, full alpha in the
  photo's dtype); maps marking no foreground or background refused naming the map; a photo
  too small refused naming its part; matting unavailable is a 503.
- ``quilting.service.uploads.decode`` of an extraction: the photo and its maps, its size.
"""

from __future__ import annotations

import numpy as np
import pytest
from upload_builders import no_decoding as _no_decoding
from upload_builders import pixels as _pixels
from upload_builders import png as _png
from upload_builders import trimap as _trimap

import quilting.extract as engine_extract
import quilting.service.upload_images as upload_images
from quilting.io import ImageHeader, encode_png
from quilting.service.extract_uploads import (
    check_marks,
    decode_marks,
    extract_headers,
    marks_headers,
    no_marks,
    photo_fits,
    photo_roles,
)
from quilting.service.jobs import JobInput, PixelLimits
from quilting.service.problems import Problem
from quilting.service.uploads import decode

LIMIT = (25_000_000, "max_input_pixels")


def _header(width: int, height: int, channels: int = 3, depth: int = 8) -> ImageHeader:
    return ImageHeader("png", width, height, channels, depth)


def _extraction(photo: bytes, trimap: bytes | None, scribbles: bytes | None = None) -> JobInput:
    return JobInput(
        texture=photo,
        companions={},
        options={"method": "cf"},
        width=0,
        height=0,
        operation="extract_alpha",
        trimaps=[trimap],
        scribbles=[scribbles],
    )


def test_no_marks_is_an_invalid_trimap_naming_its_field() -> None:
    default, other = no_marks(), no_marks("scribbles")
    assert (default.status, default.code, default.extra) == (
        422,
        "invalid_trimap",
        {"field": "trimap"},
    )
    assert "trimap or scribbles" in default.detail
    assert other.extra == {"field": "scribbles"}


def test_photo_roles_name_one_photo_alone_and_several_by_index() -> None:
    assert photo_roles(1, "texture") == ["texture"]
    assert photo_roles(3, "layer") == ["layer 0", "layer 1", "layer 2"]


@pytest.mark.parametrize(("role", "field"), [("photo", "photo"), ("texture 2", "texture")])
def test_photo_fits_refuses_a_photo_with_alpha_naming_its_part(role: str, field: str) -> None:
    for channels in (1, 3):
        photo_fits(_header(10, 10, channels), role)
    with pytest.raises(Problem) as caught:
        photo_fits(_header(10, 10, 4), role)
    problem = caught.value
    assert (problem.status, problem.code, problem.extra) == (422, "invalid_image", {"field": field})
    assert problem.detail.startswith(f"the {role} already has an alpha channel")


def test_marks_headers_without_marks_returns_the_photo_s_header_even_with_alpha() -> None:
    header = _header(12, 9, 4, 16)
    assert marks_headers(header, (None, None), "texture", LIMIT) is header


@pytest.mark.parametrize(("channels", "depth"), [(1, 8), (3, 8), (3, 16)])
def test_marks_headers_gives_the_rgba_texture_of_the_photo_s_depth(
    channels: int, depth: int
) -> None:
    header = ImageHeader("jpeg", 20, 12, channels, depth)
    made = marks_headers(header, (_png(12, 20, 1), None), "texture", LIMIT)
    assert made == ImageHeader("jpeg", 20, 12, 4, depth)
    assert marks_headers(header, (None, _png(12, 20, 4)), "texture", LIMIT) == made


@pytest.mark.parametrize("field", ["trimap", "scribbles"])
def test_marks_headers_refuses_a_map_of_another_size_naming_map_sizes_and_role(
    field: str,
) -> None:
    wrong = _png(12, 21, 1)
    marks = (wrong, None) if field == "trimap" else (_png(12, 20, 1), wrong)
    with pytest.raises(Problem) as caught:
        marks_headers(_header(20, 12), marks, "layer 1", LIMIT)
    problem = caught.value
    assert (problem.status, problem.code, problem.extra) == (
        422,
        "invalid_trimap",
        {"field": field},
    )
    assert problem.detail.startswith(f"{field} is 21x12 but the layer 1 is 20x12")


def test_marks_headers_refuses_a_map_over_the_limit_naming_the_map_and_setting() -> None:
    with pytest.raises(Problem) as caught:
        marks_headers(_header(20, 12), (None, _png(12, 20, 1)), "photo", (239, "max_side_x"))
    problem = caught.value
    assert (problem.code, problem.extra) == ("image_too_large", {"field": "scribbles"})
    assert "scribbles" in problem.detail and "(max_side_x)" in problem.detail
    assert "<bytes>" not in problem.detail
    # One pixel more is all it takes: 240 pixels pass.
    marks_headers(_header(20, 12), (None, _png(12, 20, 1)), "photo", (240, "max_side_x"))


def test_marks_headers_refuses_an_undecodable_map_naming_it() -> None:
    with pytest.raises(Problem) as caught:
        marks_headers(_header(20, 12), (b"GIF89a not an image", None), "photo", LIMIT)
    assert (caught.value.code, caught.value.extra) == ("invalid_image", {"field": "trimap"})


def test_extract_headers_gives_the_photo_s_size_without_decoding(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(upload_images, "read_image", _no_decoding)
    spec = _extraction(_png(14, 23), encode_png(_trimap(14, 23)), _png(14, 23, 4))
    assert extract_headers(spec) == (23, 14)


def test_extract_headers_refuses_a_photo_without_marks_or_with_alpha() -> None:
    with pytest.raises(Problem) as caught:
        extract_headers(_extraction(_png(14, 23), None, None))
    assert (caught.value.code, caught.value.extra) == ("invalid_trimap", {"field": "trimap"})
    with pytest.raises(Problem) as caught:
        extract_headers(_extraction(_png(14, 23, 4), encode_png(_trimap(14, 23))))
    assert (caught.value.code, caught.value.extra) == ("invalid_image", {"field": "photo"})
    assert "the photo already has an alpha channel" in caught.value.detail


def test_extract_headers_refuses_a_trimap_of_another_size() -> None:
    with pytest.raises(Problem) as caught:
        extract_headers(_extraction(_png(14, 23), encode_png(_trimap(23, 14))))
    assert (caught.value.code, caught.value.extra) == ("invalid_trimap", {"field": "trimap"})
    assert "trimap is 14x23 but the photo is 23x14" in caught.value.detail


def test_extract_headers_limits_the_photo_as_an_output() -> None:
    spec = _extraction(_png(10, 10), encode_png(_trimap(10, 10)))
    # The photo's size is the output's: the tighter limit applies, by its name.
    spec.limits = PixelLimits(max_input_pixels=1000, max_output_pixels=99)
    with pytest.raises(Problem) as caught:
        extract_headers(spec)
    assert (caught.value.code, caught.value.extra) == ("image_too_large", {"field": "photo"})
    assert "max_output_pixels" in caught.value.detail
    spec.limits = PixelLimits(max_input_pixels=99, max_output_pixels=1000)
    with pytest.raises(Problem) as caught:
        extract_headers(spec)
    assert "max_input_pixels" in caught.value.detail
    spec.limits = PixelLimits(max_input_pixels=100, max_output_pixels=100)
    assert extract_headers(spec) == (10, 10)


def test_decode_marks_gives_each_photo_s_exact_maps_and_none_where_absent() -> None:
    photos = [_pixels(10, 12, 3, np.uint8, 1), _pixels(8, 9, 3, np.uint8, 2)]
    trimap = _trimap(10, 12)
    strokes = _pixels(8, 9, 4, np.uint16, 3)
    marks = [(encode_png(trimap), None), (None, encode_png(strokes))]
    trimaps, scribbles = decode_marks(photos, marks, ["texture 0", "texture 1"], LIMIT)
    assert len(trimaps) == len(scribbles) == 2
    assert trimaps[1] is None and scribbles[0] is None
    assert trimaps[0] is not None and scribbles[1] is not None
    assert trimaps[0].dtype == np.uint8 and np.array_equal(trimaps[0], trimap)
    assert scribbles[1].dtype == np.uint16 and np.array_equal(scribbles[1], strokes)


def test_decode_marks_refuses_a_decoded_map_of_another_size() -> None:
    photos = [_pixels(10, 12, 3, np.uint8, 1), _pixels(8, 9, 3, np.uint8, 2)]
    marks = [(None, None), (None, encode_png(_trimap(9, 8)))]
    with pytest.raises(Problem) as caught:
        decode_marks(photos, marks, ["layer 0", "layer 1"], LIMIT)
    assert (caught.value.code, caught.value.extra) == ("invalid_trimap", {"field": "scribbles"})
    assert caught.value.detail.startswith("scribbles is 8x9 but the layer 1 is 9x8")


def test_check_marks_gives_an_opaque_rgba_stand_in_of_the_photo_s_dtype() -> None:
    rgb = _pixels(16, 20, 3, np.uint8, 4)
    made = check_marks(rgb, _trimap(16, 20), None, "photo")
    assert made.shape == (16, 20, 4) and made.dtype == np.uint8
    assert np.array_equal(made[..., :3], rgb) and (made[..., 3] == 255).all()
    gray = _pixels(16, 20, 1, np.uint16, 5)
    made = check_marks(gray, None, _trimap(16, 20), "texture 1")
    assert made.shape == (16, 20, 4) and made.dtype == np.uint16
    for channel in range(3):
        assert np.array_equal(made[..., channel], gray)
    assert (made[..., 3] == 65535).all()


@pytest.mark.parametrize("field", ["trimap", "scribbles"])
def test_check_marks_refuses_maps_marking_no_foreground_naming_the_map(field: str) -> None:
    photo = _pixels(16, 20, 3, np.uint8, 6)
    background = np.zeros((16, 20), dtype=np.uint8)
    trimap, scribbles = (background, None) if field == "trimap" else (None, background)
    with pytest.raises(Problem) as caught:
        check_marks(photo, trimap, scribbles, "photo")
    problem = caught.value
    assert (problem.status, problem.code, problem.extra) == (
        422,
        "invalid_trimap",
        {"field": field},
    )
    assert "no foreground" in problem.detail


def test_check_marks_refuses_a_photo_too_small_naming_its_part() -> None:
    photo = _pixels(7, 20, 3, np.uint8, 7)
    trimap = _trimap(7, 20)
    with pytest.raises(Problem) as caught:
        check_marks(photo, trimap, None, "layer 2")
    problem = caught.value
    assert (problem.code, problem.extra) == ("invalid_image", {"field": "layer"})
    assert problem.detail.startswith("layer 2: ")


def test_check_marks_without_matting_is_a_503(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(engine_extract, "available", lambda: False)
    with pytest.raises(Problem) as caught:
        check_marks(_pixels(16, 20, 3, np.uint8, 8), _trimap(16, 20), None, "photo")
    assert (caught.value.status, caught.value.code) == (503, "matting_unavailable")


def test_decode_of_an_extraction_gives_the_photo_its_maps_and_its_size() -> None:
    photo = _pixels(14, 23, 3, np.uint16, 9)
    trimap = _trimap(14, 23)
    decoded = decode(_extraction(encode_png(photo), encode_png(trimap)))
    assert (decoded.width, decoded.height) == (23, 14)
    assert decoded.texture.dtype == np.uint16 and np.array_equal(decoded.texture, photo)
    assert len(decoded.trimaps) == 1 and decoded.trimaps[0] is not None
    assert np.array_equal(decoded.trimaps[0], trimap)
    assert decoded.scribbles == [None]
    assert decoded.companions == {} and decoded.examples == []
