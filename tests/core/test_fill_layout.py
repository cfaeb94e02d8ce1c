"""A fill's layout: saved and read back, replayed into the same selection, malformed refused."""

from __future__ import annotations

import json

import numpy as np
import pytest

import quilting
from quilting import InvalidImageError, LayoutError
from quilting.core.fill_layout import FillLayout, is_fill_layout


def _hole(shape: tuple[int, int]) -> np.ndarray:
    mask = np.zeros(shape, dtype=bool)
    mask[shape[0] // 3 : shape[0] // 2, shape[1] // 4 : shape[1] // 2] = True
    return mask


def test_the_layout_replays_the_fill(hubble) -> None:
    filled = quilting.fill(hubble, _hole(hubble.shape[:2]), block=20, blend="none", seed=2)
    layout = FillLayout.from_json(filled.layout.to_json())
    assert layout.corners.shape[0] == filled.blocks
    rows, cols = layout.provenance()
    assert np.array_equal(rows, filled.source_rows) and np.array_equal(cols, filled.source_cols)
    # The image's own companion, filled by the saved layout, is the (unblended) result.
    assert np.array_equal(layout.apply(hubble), filled.image)
    # A one-channel companion comes back with one channel, filled the same way.
    gray = hubble[..., 0]
    assert np.array_equal(layout.apply(gray), filled.image[..., 0])


def test_the_seams_lie_in_the_hole_and_around_it(gravel) -> None:
    mask = _hole(gravel.shape)
    seams = quilting.fill(gravel, mask, block=16, seed=1).layout.seam_mask()
    assert seams.any()
    near = np.zeros_like(mask)
    ys, xs = np.nonzero(mask)
    near[max(0, ys.min() - 1) : ys.max() + 2, max(0, xs.min() - 1) : xs.max() + 2] = True
    assert not (seams & ~near).any()


def test_a_texture_fill_needs_the_texture_companion(gravel, brick) -> None:
    everything = np.ones((64, 64), dtype=bool)
    filled = quilting.fill(gravel[:64, :64], everything, texture=brick, block=16, blend="none")
    layout = filled.layout
    assert layout.source == "texture" and layout.source_shape == brick.shape[:2]
    with pytest.raises(InvalidImageError, match="texture's companion"):
        layout.apply(gravel[:64, :64])
    assert np.array_equal(layout.apply(gravel[:64, :64], brick), filled.image)


def test_an_extension_layout_takes_the_input_companion(wood) -> None:
    grown = quilting.extend(wood, top=16, right=24, block=16, blend="none", seed=3)
    layout = FillLayout.from_json(grown.layout.to_json())
    assert layout.placed == (16, 0) and layout.shape == grown.image.shape[:2]
    assert np.array_equal(layout.apply(wood), grown.image)
    with pytest.raises(InvalidImageError, match="136x136"):
        layout.apply(grown.image)


def test_the_kind_tells_the_layouts_apart(gravel) -> None:
    fill_json = quilting.fill(gravel, _hole(gravel.shape), block=16).layout.to_json()
    synth_json = quilting.synthesize(gravel, (64, 64), block=16).layout.to_json()
    assert is_fill_layout(fill_json) and is_fill_layout(fill_json.encode())
    assert not is_fill_layout(synth_json)


@pytest.mark.parametrize(
    "change",
    [
        lambda d: d.update(kind="synthesis"),
        lambda d: d.update(owned="not base64!"),
        lambda d: d.update(corners=[-5, 0] * (len(d["corners"]) // 2)),
        lambda d: d.update(positions=d["positions"][:-2]),
        lambda d: d.update(source="elsewhere"),
        lambda d: d.pop("block"),
    ],
    ids=["kind", "owned", "outside", "count", "source", "missing"],
)
def test_a_malformed_layout_says_what_is_wrong(gravel, change) -> None:
    data = json.loads(quilting.fill(gravel, _hole(gravel.shape), block=16).layout.to_json())
    change(data)
    with pytest.raises(LayoutError, match="fill layout"):
        FillLayout.from_json(json.dumps(data))


def test_save_and_load(tmp_path, gravel) -> None:
    layout = quilting.fill(gravel, _hole(gravel.shape), block=16, seed=4).layout
    layout.save(tmp_path / "fill.json")
    again = FillLayout.load(tmp_path / "fill.json")
    assert np.array_equal(again.owned, layout.owned) and again.meta == layout.meta
