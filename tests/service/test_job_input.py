"""A job's input is its uploaded files as they came, and crosses processes as bytes (the
distributed queue): the round trip is exact, the bytes are JSON and the files only, never a
pickle, and the worker decodes the files under the limits they were accepted with."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from service_helpers import texture

from quilting.io import encode_png
from quilting.service.jobs import JobInput, PixelLimits
from quilting.service.problems import Problem
from quilting.service.uploads import check_headers, decode


def _png(shape: tuple[int, ...], dtype: type[np.generic], seed: int) -> bytes:
    rng = np.random.default_rng(seed)
    high = 65535 if dtype is np.uint16 else 255
    return encode_png(rng.integers(0, high + 1, size=shape).astype(dtype))


def _assert_same(a: JobInput, b: JobInput) -> None:
    for name in (
        "options",
        "width",
        "height",
        "operation",
        "texture",
        "target",
        "source_mask",
        "silhouette",
        "normals",
        "layers",
        "limits",
    ):
        assert getattr(b, name) == getattr(a, name), name
    assert list(b.companions.items()) == list(a.companions.items())  # order names the outputs
    assert b.outputs == a.outputs


def test_synthesis_input_round_trip_keeps_files_companions_options_and_limits() -> None:
    spec = JobInput(
        texture=_png((40, 30, 3), np.uint8, 1),
        companions={"zeta": _png((40, 30), np.uint16, 2), "alpha": _png((40, 30, 4), np.uint8, 3)},
        options={"block": 24, "seed": 7, "tileable": "both", "backend": "fft", "exclude": None},
        width=100,
        height=80,
        source_mask=_png((40, 30), np.uint8, 4),
        limits=PixelLimits(max_input_pixels=5000, max_output_pixels=9000, max_side=100),
    )
    _assert_same(spec, JobInput.from_bytes(spec.to_bytes()))
    assert spec.nbytes == sum(
        len(data) for data in (spec.texture, spec.source_mask or b"", *spec.companions.values())
    )


def test_transfer_and_matte_inputs_round_trip() -> None:
    transfer = JobInput(
        texture=_png((32, 32), np.uint8, 5),
        companions={},
        options={"alpha": 0.3, "iterations": 2, "correspondence": "luminance"},
        width=50,
        height=60,
        target=_png((60, 50, 3), np.uint16, 6),
        operation="transfer",
    )
    _assert_same(transfer, JobInput.from_bytes(transfer.to_bytes()))
    layers = [_png((24, 24, 3), np.uint8, 7), _png((20, 20, 4), np.uint8, 8)]
    matte = JobInput(
        texture=layers[0],
        companions={},
        options={"light": [1.0, -0.5, 2.0], "clusters": 4, "scale": 1.5},
        width=64,
        height=48,
        target=_png((48, 64, 3), np.uint8, 9),
        operation="matte",
        layers=layers,
        silhouette=_png((48, 64), np.uint8, 10),
        normals=_png((48, 64, 3), np.uint8, 11),
    )
    back = JobInput.from_bytes(matte.to_bytes())
    _assert_same(matte, back)
    assert back.outputs == ["normals", "clusters"]
    assert matte.nbytes == sum(map(len, (*layers, matte.target, matte.silhouette, matte.normals)))


def test_the_bytes_hold_no_pickle_and_anything_else_is_refused() -> None:
    spec = JobInput(texture=texture("gravel"), companions={}, options={}, width=8, height=8)
    data = spec.to_bytes()
    assert pickle.PROTO not in data[:64]  # a JSON header, then the PNG
    for bad in (
        pickle.dumps(spec),
        data[:-1],  # cut short
        data + b"x",  # bytes after the files
        data.replace(b'"texture"', b'"payload"', 1),  # an unknown file
        b"",
    ):
        with pytest.raises(ValueError):
            JobInput.from_bytes(bad)


def test_the_worker_decodes_under_the_limits_the_job_carries() -> None:
    gravel = texture("gravel")  # 256 x 256
    spec = JobInput(gravel, {}, {}, 64, 64, limits=PixelLimits(max_input_pixels=256 * 256))
    assert decode(spec).texture.shape == (256, 256)
    small = JobInput(gravel, {}, {}, 64, 64, limits=PixelLimits(max_input_pixels=256 * 255))
    for step in (check_headers, decode):
        with pytest.raises(Problem) as caught:
            step(small)
        assert caught.value.code == "image_too_large"
        assert "max_input_pixels" in caught.value.detail


def test_several_examples_round_trip_with_their_masks_and_companion_maps() -> None:
    examples = [_png((40, 30, 3), np.uint8, 12), _png((28, 36, 3), np.uint8, 13)]
    masks = [_png((40, 30), np.uint8, 14), _png((28, 36), np.uint8, 15)]
    normals = [_png((40, 30, 3), np.uint8, 16), _png((28, 36, 3), np.uint8, 17)]
    spec = JobInput(
        texture=examples[0],
        companions={"normal": normals[0]},
        options={"block": 12, "weights": [1.0, 2.0], "transforms": "flips"},
        width=64,
        height=48,
        source_mask=masks[0],
        examples=examples,
        source_masks=masks,
        example_companions={"normal": normals},
        companion_kinds={"normal": "normal_dx"},
    )
    back = JobInput.from_bytes(spec.to_bytes())
    _assert_same(spec, back)
    assert back.examples == examples and back.source_masks == masks
    assert back.example_companions == {"normal": normals}
    assert back.textures == examples and back.masks == masks
    assert back.maps_of("normal") == normals and back.outputs == ["normal"]
    # Each file is held once (the first of each list is the job's texture, mask, companion).
    assert spec.nbytes == sum(map(len, (*examples, *masks, *normals)))
    # The worker decodes them all, as lists.
    images = decode(back)
    assert [image.shape for image in images.examples] == [(40, 30, 3), (28, 36, 3)]
    assert [image.shape for image in images.source_masks] == [(40, 30), (28, 36)]
    assert [image.shape for image in images.example_companions["normal"]] == [
        (40, 30, 3),
        (28, 36, 3),
    ]


def test_one_texture_s_input_has_no_example_lists() -> None:
    spec = JobInput(texture=texture("gravel"), companions={}, options={}, width=8, height=8)
    back = JobInput.from_bytes(spec.to_bytes())
    assert back.examples == [] and back.source_masks == [] and back.example_companions == {}
    assert back.textures == [spec.texture] and back.masks == [None]
    images = decode(back)
    assert images.examples == [] and images.source_masks == []
    # An input pickled before several examples (a worker of an older build) reads back.
    state = dict(spec.__dict__)
    for name in ("examples", "source_masks", "example_companions"):
        del state[name]
    old = JobInput.__new__(JobInput)
    old.__setstate__(state)
    assert old.textures == [spec.texture] and old.example_companions == {}


def test_a_wang_tile_set_s_input_round_trips() -> None:
    spec = JobInput(
        texture=texture("gravel"),
        companions={},
        options={"colors": 2, "tile": 32, "block": 12},
        width=128,
        height=128,
        operation="wang_tiles",
    )
    back = JobInput.from_bytes(spec.to_bytes())
    _assert_same(spec, back)
    options = back.engine_options()
    assert type(options).__name__ == "WangOptions" and options.tile == 32
    assert back.outputs == []


def test_trimaps_and_scribbles_round_trip_with_their_gaps() -> None:
    """One map (or none) per photo: the gaps stay in place, each map is held once, the worker
    decodes them per photo; an input written before extraction reads back with none."""
    photos = [_png((40, 30, 3), np.uint8, 21), _png((28, 36, 3), np.uint8, 22)]
    trimap = _png((28, 36), np.uint8, 23)
    strokes = _png((40, 30, 4), np.uint8, 24)
    spec = JobInput(
        texture=photos[0],
        companions={},
        options={"block": 12, "matting": "knn"},
        width=64,
        height=48,
        examples=photos,
        trimaps=[None, trimap],
        scribbles=[strokes, None],
    )
    back = JobInput.from_bytes(spec.to_bytes())
    _assert_same(spec, back)
    assert back.trimaps == [None, trimap] and back.scribbles == [strokes, None]
    assert back.marks(2) == [(None, strokes), (trimap, None)] and back.extracting
    assert spec.nbytes == sum(map(len, (*photos, trimap, strokes)))
    images = decode(back)
    assert images.trimaps[0] is None and images.trimaps[1].shape == (28, 36)
    assert images.scribbles[0].shape == (40, 30, 4) and images.scribbles[1] is None
    plain = JobInput(texture=photos[0], companions={}, options={}, width=8, height=8)
    again = JobInput.from_bytes(plain.to_bytes())
    assert again.trimaps == [] and again.marks(1) == [(None, None)] and not again.extracting
    state = dict(plain.__dict__)
    del state["trimaps"], state["scribbles"]
    old = JobInput.__new__(JobInput)
    old.__setstate__(state)
    assert old.trimaps == [] and not old.extracting


def test_an_extraction_s_input_round_trips_and_checks_its_headers() -> None:
    photo, trimap = _png((40, 30, 3), np.uint8, 31), _png((40, 30), np.uint8, 32)
    spec = JobInput(
        texture=photo,
        companions={},
        options={"method": "cf"},
        width=0,
        height=0,
        operation="extract_alpha",
        trimaps=[trimap],
        scribbles=[None],
    )
    back = JobInput.from_bytes(spec.to_bytes())
    assert back.trimaps == [trimap] and back.scribbles == [None]
    assert type(back.engine_options()).__name__ == "AlphaOptions"
    assert check_headers(back) == (30, 40)
    wrong = JobInput(**{**spec.__dict__, "trimaps": [_png((20, 30), np.uint8, 33)]})
    with pytest.raises(Problem) as caught:
        check_headers(wrong)
    assert caught.value.code == "invalid_trimap" and caught.value.extra["field"] == "trimap"
