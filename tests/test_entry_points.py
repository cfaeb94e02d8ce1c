"""The public entry points (quilting.api) take an options object, and its fields as generated
keywords (quilting._keywords)."""

from __future__ import annotations

import dataclasses
import inspect
from typing import Any

import numpy as np
import pytest

import quilting
from quilting.backends import get_backend

OPTIONS = [
    (quilting.synthesize, quilting.SynthesisOptions),
    (quilting.transfer, quilting.TransferOptions),
    (quilting.matte, quilting.MatteOptions),
    (quilting.make_tileable, quilting.TileOptions),
]


def _texture(seed: int = 3, side: int = 40) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (side, side, 3), dtype=np.uint8)


@pytest.mark.parametrize(("func", "kind"), OPTIONS, ids=lambda x: getattr(x, "__name__", ""))
def test_every_field_is_a_keyword_with_its_default(func: Any, kind: type) -> None:
    params = inspect.signature(func).parameters
    for f in dataclasses.fields(kind):
        assert f.name in params, f"{func.__name__} lacks the keyword {f.name}"
        assert params[f.name].kind is inspect.Parameter.KEYWORD_ONLY
        assert params[f.name].default == f.default
    assert "options" in params


@pytest.mark.parametrize(("func", "kind"), OPTIONS, ids=lambda x: getattr(x, "__name__", ""))
def test_every_field_is_documented_once_from_its_metadata(func: Any, kind: type) -> None:
    doc = func.__doc__
    assert "{option_keywords}" not in doc
    assert "Other Parameters" in doc
    for f in dataclasses.fields(kind):
        assert doc.count(f"\n    {f.name} : ") == 1, f.name
        # The field's own words, as the docs and the CLI show them (first few, wrapped).
        first = " ".join(f.metadata["doc"].split()[:4])
        assert first in " ".join(doc.split()), f.name


def test_options_object_and_keywords_give_the_same_bytes() -> None:
    texture = _texture()
    options = quilting.SynthesisOptions(block=12, seed=5, blend="none")
    by_object = quilting.synthesize(texture, (50, 60), options)
    by_keywords = quilting.synthesize(texture, (50, 60), block=12, seed=5, blend="none")
    assert by_object.image.tobytes() == by_keywords.image.tobytes()
    assert by_object.image.shape == (50, 60, 3)


def test_a_keyword_overrides_the_options_object() -> None:
    texture = _texture()
    options = quilting.SynthesisOptions(block=12, seed=5, blend="none")
    overridden = quilting.synthesize(texture, (50, 60), options, seed=6)
    direct = quilting.synthesize(texture, (50, 60), block=12, seed=6, blend="none")
    assert overridden.image.tobytes() == direct.image.tobytes()
    assert overridden.layout.meta["seed"] == 6


def test_a_misspelt_keyword_is_refused_with_the_closest_field() -> None:
    with pytest.raises(TypeError, match=r"synthesize\(\).*'blok'.*did you mean 'block'"):
        quilting.synthesize(_texture(), (50, 60), blok=12)


def test_options_of_another_operation_are_refused() -> None:
    with pytest.raises(TypeError, match="TransferOptions, not SynthesisOptions"):
        quilting.transfer(_texture(), _texture(4), quilting.SynthesisOptions(block=12))


def test_an_override_out_of_range_names_the_field() -> None:
    with pytest.raises(quilting.InvalidParameterError) as caught:
        quilting.synthesize(_texture(), (50, 60), quilting.SynthesisOptions(), tolerance=-1.0)
    assert caught.value.parameter == "tolerance"


def test_a_backend_object_is_used_and_recorded_by_name() -> None:
    engine = get_backend("reference")
    result = quilting.synthesize(_texture(side=24), (30, 30), block=9, backend=engine)
    assert result.backend == "reference"


def test_transfer_maps_make_the_default_correspondence_custom() -> None:
    texture, target = _texture(), _texture(5)
    gray = np.random.default_rng(1).random((40, 40)).astype(np.float32)
    result = quilting.transfer(
        texture, target, block=12, iterations=1, source_map=gray, target_map=gray
    )
    assert result.layout.meta["correspondence"] == "custom"
    with pytest.raises(quilting.InvalidParameterError, match="correspondence"):
        quilting.transfer(
            texture,
            target,
            quilting.TransferOptions(correspondence="orientation"),
            source_map=gray,
            target_map=gray,
        )


def test_make_tileable_takes_its_options_object() -> None:
    image = _texture(side=32)
    by_object = quilting.make_tileable(image, quilting.TileOptions(axes="x", blend="none"))
    by_keywords = quilting.make_tileable(image, axes="x", blend="none")
    assert by_object.image.tobytes() == by_keywords.image.tobytes()
    # Left-right seamless: the last column continues into the first as the middle does.
    assert np.array_equal(by_object.image[:, 8:24], image[:, 8:24])
