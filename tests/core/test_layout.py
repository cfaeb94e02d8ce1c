"""``quilting.core.layout``: the block map of a result, checked against oracles of its own.

``Layout.render`` and the engine share ``paste``, so "the layout re-applied equals the image"
cannot catch a paste bug (a block pasted one row early once passed 100 tests that way). Here
the oracle is a plain Python loop over the layout's *JSON document*: for every block of every
pass, in the schedule's order, every pixel its seam gives it (``x >= cut_cols[y]``,
``y >= cut_rows[x]``, and across a torus ``x < cut_right[y]``, ``y < cut_bottom[x]``) is
written with the index of the source pixel it copies. That per-pixel source map must then
explain every pixel of the engine's unblended result and of every unmixed ('hard') render.

Also checked: hand-built layouts whose answer is known by construction (a verbatim copy, a
periodic source on a torus), properties of the blended kinds ('blend', 'normal') where no
exact oracle exists (constants stay constant, the blend is linear, normals stay unit length),
the JSON round trip, and the refusal of malformed documents and of companions that do not fit.
"""

from __future__ import annotations

import functools
import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

import quilting
from quilting.core.errors import InvalidImageError, LayoutError
from quilting.core.grid import Grid
from quilting.core.layout import Layout, LayoutPass
from quilting.core.layout import apply_layout as _apply_layout

Array = NDArray[Any]
Doc = dict[str, Any]

# A noise texture: every pixel (almost surely) unlike the others, so a pixel copied from the
# wrong place shows. 48 x 48, so that a source index y * 48 + x fits a uint16.
SOURCE_SHAPE = (48, 48)


def apply_layout(layout: Layout, companion: object, *, kind: str = "blend") -> Array:
    """:func:`quilting.core.layout.apply_layout`, typed loosely for the arithmetic below."""
    out: Array = _apply_layout(layout, companion, kind=kind)
    return out


@functools.cache
def noise(channels: int = 3, seed: int = 2001) -> Array:
    rng = np.random.default_rng(seed)
    image = rng.integers(0, 256, size=(*SOURCE_SHAPE, channels), dtype=np.uint8)
    image.setflags(write=False)
    return image


def index_map(dtype: Any = np.uint16) -> Array:
    """A companion whose every pixel holds its own flat index in the source (y * W + x)."""
    height, width = SOURCE_SHAPE
    return np.arange(height * width).reshape(height, width).astype(dtype)


def _synthesis(
    size: tuple[int, int], channels: int = 3, **options: Any
) -> Callable[[], tuple[Array, quilting.Result]]:
    """A synthesis case: the noise texture and its result at ``size`` with ``options``."""

    def make() -> tuple[Array, quilting.Result]:
        texture = noise(channels) if channels == 3 else noise(1)[..., 0]
        return texture, quilting.synthesize(texture, size, **options)

    return make


def _transfer(iterations: int, **options: Any) -> Callable[[], tuple[Array, quilting.Result]]:
    """A transfer case: unshaded (the final shading is not part of the layout)."""
    target = np.random.default_rng(5).integers(0, 256, size=(37, 43), dtype=np.uint8)

    def make() -> tuple[Array, quilting.Result]:
        options_ = dict(block=18, min_block=3, shade=1, seed=5, **options)
        return noise(), quilting.transfer(noise(), target, iterations=iterations, **options_)

    return make


# The results, made once each (the suite's time matters). Each is (texture, result).
# The unblended ones' images are made of texture pixels only.
CASES: dict[str, Callable[[], tuple[Array, quilting.Result]]] = {
    "plain": _synthesis((50, 61), block=14, seed=1, blend="none"),
    "overlap-mode": _synthesis((41, 37), block=12, seed=2, blend="none", mode="overlap"),
    "torus": _synthesis((40, 47), block=14, seed=3, blend="none", tileable="both"),
    # A torus of 3 x 3 blocks: the schedule splits levels whose blocks touch across the wrap.
    "torus-small": _synthesis((26, 26), block=12, seed=8, blend="none", tileable="both"),
    "torus-x": _synthesis((33, 45), block=12, seed=4, blend="none", tileable="x"),
    "transfer": _transfer(3, blend="none"),
    "gray": _synthesis((30, 29), channels=1, block=10, seed=6, blend="none"),
    # Blended: the image is not made of texture pixels, but the 'hard' render must be.
    "poisson": _synthesis((50, 61), block=14, seed=1, blend="poisson"),
    "poisson-torus": _synthesis((40, 47), block=14, seed=3, blend="poisson", tileable="both"),
    "poisson-transfer": _transfer(2, blend="poisson"),
    "walk": _synthesis((50, 61), block=14, seed=7, mode="walk", feather=3),
}
UNBLENDED = ["plain", "overlap-mode", "torus", "torus-small", "torus-x", "transfer", "gray"]
CUT = [*UNBLENDED, "poisson", "poisson-torus", "poisson-transfer"]  # all but walk
BLENDED = ["poisson", "poisson-torus", "poisson-transfer", "walk"]
# Output sizes below one block, one pixel wide, one pixel high and a single pixel.
EDGE_SIZES = [(5, 7), (1, 30), (30, 1), (1, 1), (14, 14), (13, 15)]


@functools.cache
def case(name: str) -> tuple[Array, quilting.Result]:
    return CASES[name]()


# --------------------------------------------------------------------------------------------
# The oracle: a naive loop over the JSON document
# --------------------------------------------------------------------------------------------


def naive_source_map(doc: Doc) -> NDArray[np.int64]:
    """The flat source index (y * source width + x) each output pixel copies, -1 for none,
    from the layout's JSON document alone, one pixel at a time.

    Each pass starts on a canvas of its grid's size holding what the passes before it made
    (a transfer's later passes are synthesized over the earlier ones). Blocks are pasted by
    wavefront level ``2 i + j``, then by row: on a plane that is raster order (the levels'
    blocks are disjoint); on a torus the grid's schedule splits a level only into groups of
    blocks that do not touch, keeping row order, which a pixel cannot tell apart.
    """
    source_width = int(doc["source_shape"][1])
    out_h, out_w = (int(v) for v in doc["output_shape"])
    previous: NDArray[np.int64] | None = None
    for record in doc["passes"]:
        block, overlap = int(record["block"]), int(record["overlap"])
        rows, cols = int(record["rows"]), int(record["cols"])
        step = block - overlap
        period = record.get("period", [0, 0])
        height = period[0] or rows * step + overlap
        width = period[1] or cols * step + overlap
        no_cut = [[block] * block for _ in range(rows * cols)]
        cut_right = record.get("cut_right", no_cut)
        cut_bottom = record.get("cut_bottom", no_cut)
        canvas = np.full((height, width), -1, dtype=np.int64)
        if previous is not None:
            h = min(height, previous.shape[0], out_h)
            w = min(width, previous.shape[1], out_w)
            canvas[:h, :w] = previous[:h, :w]
        order = sorted((2 * i + j, i, j) for i in range(rows) for j in range(cols))
        for _, i, j in order:
            k = i * cols + j
            sy, sx = record["positions"][k]
            left, top = record["cut_cols"][k], record["cut_rows"][k]
            right, bottom = cut_right[k], cut_bottom[k]
            for y in range(block):
                for x in range(block):
                    if x < left[y] or y < top[x] or x >= right[y] or y >= bottom[x]:
                        continue  # the seam leaves this pixel to the output already there
                    cy, cx = i * step + y, j * step + x
                    if period[0]:
                        cy %= period[0]
                    if period[1]:
                        cx %= period[1]
                    canvas[cy, cx] = (sy + y) * source_width + (sx + x)
        previous = canvas
    assert previous is not None
    return previous[:out_h, :out_w]


def pick(source: Array, where: NDArray[np.int64]) -> Array:
    """``source`` (H, W) or (H, W, C) at the flat indices ``where`` (h, w)."""
    flat = source.reshape(source.shape[0] * source.shape[1], *source.shape[2:])
    return flat[where]


def document(layout: Layout) -> Doc:
    doc: Doc = json.loads(layout.to_json())
    return doc


def test_the_oracle_can_fail() -> None:
    """The naive map of a block pasted one row early (the bug this file is here for) differs
    from the true one, and the check below would see it."""
    texture, result = case("plain")
    doc = document(result.layout)
    good = naive_source_map(doc)
    shifted = json.loads(json.dumps(doc))
    record = shifted["passes"][0]
    k = 1 * record["cols"] + 1  # an inner block
    record["positions"][k][0] += 1  # its pixels one source row off
    bad = naive_source_map(shifted)
    assert (good != bad).sum() > 50
    assert not np.array_equal(pick(texture, bad), result.image)


# --------------------------------------------------------------------------------------------
# Real results against the oracle
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", UNBLENDED)
def test_every_unblended_pixel_is_the_texture_pixel_the_layout_names(name: str) -> None:
    texture, result = case(name)
    where = naive_source_map(document(result.layout))
    assert where.shape == result.image.shape[:2] == tuple(result.layout.output_shape)
    assert (where >= 0).all(), "a pixel that no block of the layout covers"
    np.testing.assert_array_equal(pick(texture, where), result.image)


@pytest.mark.parametrize("name", CUT)
@pytest.mark.parametrize("dtype", [np.uint16, np.float32, np.float64])
def test_a_hard_render_is_the_oracles_selection(name: str, dtype: Any) -> None:
    """An index map quilted 'hard' names, pixel for pixel, the source pixel the oracle names:
    blended layouts included (the blocks and cuts, unmixed), in every dtype."""
    _, result = case(name)
    where = naive_source_map(document(result.layout))
    got = apply_layout(result.layout, index_map(dtype), kind="hard")
    assert got.dtype == dtype and got.shape == where.shape
    np.testing.assert_array_equal(got.astype(np.int64), where)


@pytest.mark.parametrize("name", UNBLENDED)
@pytest.mark.parametrize("kind", ["blend", "hard", "normal"])
def test_without_a_blend_every_kind_is_the_oracles_selection(name: str, kind: str) -> None:
    """Unblended, every kind copies pixels: a 4-channel float64 map of arbitrary (not unit)
    vectors comes back as the oracle's selection, 'normal' leaving the vectors as they are."""
    texture, result = case(name)
    rng = np.random.default_rng(11)
    companion = rng.random((*SOURCE_SHAPE, 4))
    where = naive_source_map(document(result.layout))
    got = apply_layout(result.layout, companion, kind=kind)
    assert got.dtype == np.float64
    np.testing.assert_array_equal(got, pick(companion, where))
    # The texture itself, through render, is the result (the oracle said so above).
    view = texture if texture.ndim == 3 else texture[..., None]
    if kind != "normal" or view.shape[2] >= 3:
        np.testing.assert_array_equal(
            result.layout.render(view, kind).reshape(result.image.shape), result.image
        )


@pytest.mark.parametrize("size", EDGE_SIZES)
def test_edge_sizes(size: tuple[int, int]) -> None:
    """Outputs smaller than one block, one pixel wide or high: the grid still covers them and
    every pixel is the texture pixel the layout names."""
    texture = noise()
    result = quilting.synthesize(texture, size, block=14, seed=9, blend="none")
    assert result.image.shape == (*size, 3)
    assert tuple(result.layout.output_shape) == size
    grid = result.layout.passes[0].grid
    assert grid.height >= size[0] and grid.width >= size[1]
    where = naive_source_map(document(result.layout))
    assert where.shape == size and (where >= 0).all()
    np.testing.assert_array_equal(pick(texture, where), result.image)
    np.testing.assert_array_equal(
        apply_layout(result.layout, index_map(), kind="hard").astype(np.int64), where
    )
    again = Layout.from_json(result.layout.to_json())
    np.testing.assert_array_equal(apply_layout(again, texture), result.image)


def test_tileable_layouts_record_the_torus_and_wrap() -> None:
    """A torus layout's output is its period, the far-side cuts are recorded, and its pixels
    repeat: the oracle's source map, computed modulo the period, covers every pixel."""
    _, result = case("torus")
    doc = document(result.layout)
    (record,) = doc["passes"]
    assert record["period"] == [40, 47] == list(result.layout.output_shape)
    assert "cut_right" in record and "cut_bottom" in record
    # Blocks of the last column and row really run past the edge onto the first.
    step = record["block"] - record["overlap"]
    assert (record["cols"] - 1) * step + record["block"] > 47
    assert (record["rows"] - 1) * step + record["block"] > 40
    assert (np.asarray(record["cut_right"]) < record["block"]).any()
    assert (np.asarray(record["cut_bottom"]) < record["block"]).any()
    assert doc["version"] == 2


def test_transfer_layouts_record_every_pass() -> None:
    _, result = case("transfer")
    doc = document(result.layout)
    assert [p["block"] for p in doc["passes"]] == [18, 12, 8]
    assert doc["meta"]["operation"] == "transfer"
    # The later passes matter: the first pass alone explains fewer pixels.
    first_only = dict(doc, passes=doc["passes"][:1])
    full = naive_source_map(doc)
    assert (naive_source_map(first_only) != full).mean() > 0.5


# --------------------------------------------------------------------------------------------
# Hand-built layouts whose answer is known without any loop
# --------------------------------------------------------------------------------------------


def _random_cuts(rng: np.random.Generator, grid: Grid, record: LayoutPass) -> None:
    """Arbitrary cuts anywhere in each block's overlap strips, on the sides where a block
    placed before it lies (a first row or column cut on its open side would leave pixels
    that no block paints)."""
    shape = (grid.rows, grid.cols, grid.block)
    wrap_y, wrap_x = grid.wrap_overlap
    record.cut_cols[:, 1:] = rng.integers(0, grid.overlap + 1, size=shape)[:, 1:]
    record.cut_rows[1:] = rng.integers(0, grid.overlap + 1, size=shape)[1:]
    if wrap_x:  # the last column meets the first across the wrap
        record.cut_right[:, -1] = rng.integers(grid.block - wrap_x, grid.block + 1, size=shape)[
            :, -1
        ]
    if wrap_y:
        record.cut_bottom[-1] = rng.integers(grid.block - wrap_y, grid.block + 1, size=shape)[-1]


@pytest.mark.parametrize("seed", range(3))
def test_a_verbatim_layout_is_a_crop_of_the_source_whatever_its_seams(seed: int) -> None:
    """Each block copied from where it sits: whichever block owns a pixel, it is the source's
    pixel there, so the render is a crop of the source (every kind, any seams)."""
    rng = np.random.default_rng(seed)
    grid = Grid(block=9, overlap=3, rows=4, cols=5)
    record = LayoutPass.empty(grid)
    i, j = np.indices((grid.rows, grid.cols))
    record.positions[..., 0] = i * grid.step
    record.positions[..., 1] = j * grid.step
    _random_cuts(rng, grid, record)
    out = (grid.height - 2, grid.width - 1)
    layout = Layout(source_shape=(30, 40), output_shape=out, passes=[record])
    source = rng.random((30, 40, 3)).astype(np.float32)
    for kind in ("blend", "hard", "normal"):
        np.testing.assert_array_equal(layout.render(source, kind), source[: out[0], : out[1]])
    # The same document through JSON: still valid, still the crop.
    again = Layout.from_json(layout.to_json())
    np.testing.assert_array_equal(
        apply_layout(again, source[..., 0]), source[: out[0], : out[1], 0]
    )
    y, x = np.indices(out)
    np.testing.assert_array_equal(naive_source_map(document(layout)), y * 40 + x)


@pytest.mark.parametrize("wrap", [(True, True), (True, False), (False, True)])
def test_a_periodic_source_on_a_torus_renders_its_period(wrap: tuple[bool, bool]) -> None:
    """A source tiled from a ``period`` image: a block copied from where it sits modulo the
    period shows the period image there, however it wraps and however it is cut."""
    rng = np.random.default_rng(sum(wrap))
    period = (23, 29)
    grid = Grid.covering(*period, block=10, overlap=2, wrap=wrap)
    assert grid.wrapped
    record = LayoutPass.empty(grid)
    i, j = np.indices((grid.rows, grid.cols))
    # Where the block sits, modulo the period along a wrapped axis (the source holds two).
    record.positions[..., 0] = (i * grid.step) % (period[0] if wrap[0] else 10**6)
    record.positions[..., 1] = (j * grid.step) % (period[1] if wrap[1] else 10**6)
    _random_cuts(rng, grid, record)
    base = rng.integers(0, 65536, size=(*period, 1), dtype=np.uint16)
    source = np.tile(base, (2, 2, 1))  # positions + block stay inside it
    out = (grid.height, grid.width)
    layout = Layout(source_shape=source.shape[:2], output_shape=out, passes=[record])
    expected = np.tile(base, (2, 2, 1))[: out[0], : out[1]]
    np.testing.assert_array_equal(layout.render(source, "hard"), expected)
    again = Layout.from_json(layout.to_json())
    np.testing.assert_array_equal(apply_layout(again, source[..., 0]), expected[..., 0])


# --------------------------------------------------------------------------------------------
# Blended kinds: properties where no exact oracle exists
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", BLENDED)
@pytest.mark.parametrize("kind", ["blend", "normal", "hard"])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_a_constant_companion_stays_constant(name: str, kind: str, dtype: Any) -> None:
    """Blending a constant map mixes equal values: the constant, exactly in integers."""
    _, result = case(name)
    value = {np.uint8: 200, np.uint16: 40000, np.float32: 0.625}[dtype]
    if kind == "normal":
        # A unit normal stored as (n + 1) / 2, plus a fourth channel.
        stored = np.array([(0.6 + 1) / 2, (0.0 + 1) / 2, (0.8 + 1) / 2, 1.0])
        scale = 1.0 if dtype == np.float32 else np.iinfo(dtype).max
        pixel = (stored * scale).astype(dtype)
        companion = np.broadcast_to(pixel, (*SOURCE_SHAPE, 4)).copy()
    else:
        companion = np.full(SOURCE_SHAPE, value, dtype=dtype)
    if kind == "hard" and name == "walk":
        with pytest.raises(LayoutError, match="walk"):
            apply_layout(result.layout, companion, kind=kind)
        return
    got = apply_layout(result.layout, companion, kind=kind)
    assert got.dtype == dtype and got.shape[:2] == tuple(result.layout.output_shape)
    assert got.shape[2:] == companion.shape[2:]
    reference = np.broadcast_to(companion[0, 0], got.shape)
    if dtype == np.float32:
        np.testing.assert_allclose(got, reference, atol=2e-6)
    else:
        # A normal renormalized in float32 may land one integer step off after rounding.
        np.testing.assert_allclose(got, reference, atol=1 if kind == "normal" else 0)


@pytest.mark.parametrize("name", BLENDED)
def test_the_blend_is_linear_and_per_channel(name: str) -> None:
    """The seams' blend (Poisson correction, walk feathering) mixes values linearly, channel
    by channel: in float32 (no clipping, no rounding) render(a X + b Y + c) is
    a render(X) + b render(Y) + c, and a channel rendered alone is that channel of the whole."""
    _, result = case(name)
    rng = np.random.default_rng(12)
    x = rng.random((*SOURCE_SHAPE, 3), dtype=np.float32)
    y = rng.random((*SOURCE_SHAPE, 3), dtype=np.float32)
    layout = result.layout
    rx, ry = apply_layout(layout, x), apply_layout(layout, y)
    mixed = apply_layout(layout, np.float32(0.5) * x - np.float32(2) * y + np.float32(0.25))
    np.testing.assert_allclose(mixed, 0.5 * rx - 2 * ry + 0.25, atol=5e-5)
    for channel in range(3):
        alone = apply_layout(layout, np.ascontiguousarray(x[..., channel]))
        assert alone.ndim == 2
        np.testing.assert_allclose(alone, rx[..., channel], atol=1e-6)
    # And the blend really mixes: it is not the unmixed rendering of the same blocks and cuts.
    assert np.abs(rx - unmixed(layout, x)).max() > 0.01


def unmixed(layout: Layout, companion: Array) -> Array:
    """The same blocks and cuts without mixing: 'hard', or for walk mode (which has no 'hard'
    rendering) the same walk with no feather."""
    if layout.passes[0].feather is None:
        return apply_layout(layout, companion, kind="hard")
    doc = document(layout)
    doc["passes"][0]["feather"] = 0
    return apply_layout(Layout.from_json(json.dumps(doc)), companion)


@pytest.mark.parametrize("name", BLENDED)
def test_normals_come_back_unit_length_with_their_fourth_channel_blended(name: str) -> None:
    _, result = case(name)
    rng = np.random.default_rng(13)
    vectors = rng.normal(size=(*SOURCE_SHAPE, 3))
    vectors[..., 2] = np.abs(vectors[..., 2]) + 0.3
    vectors /= np.linalg.norm(vectors, axis=-1, keepdims=True)
    extra = rng.random((*SOURCE_SHAPE, 1))
    normals = np.concatenate([(vectors + 1) / 2, extra], axis=-1).astype(np.float32)
    got = apply_layout(result.layout, normals, kind="normal")
    blended = apply_layout(result.layout, normals, kind="blend")
    lengths = np.linalg.norm(got[..., :3].astype(np.float64) * 2 - 1, axis=-1)
    np.testing.assert_allclose(lengths, 1, atol=1e-5)
    # Blending alone shortened some of them (the check could fail).
    plain_lengths = np.linalg.norm(blended[..., :3].astype(np.float64) * 2 - 1, axis=-1)
    assert plain_lengths.min() < 0.99
    # Renormalizing keeps each vector's direction and leaves the fourth channel to the blend.
    direction = blended[..., :3].astype(np.float64) * 2 - 1
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    np.testing.assert_allclose(got[..., :3] * 2 - 1, direction, atol=1e-5)
    np.testing.assert_array_equal(got[..., 3], blended[..., 3])


# --------------------------------------------------------------------------------------------
# JSON: save, load, round trip
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(CASES))
def test_json_round_trip_is_identical(name: str, tmp_path: Path) -> None:
    texture, result = case(name)
    layout = result.layout
    text = layout.to_json()
    path = tmp_path / "layout.json"
    layout.save(path)
    assert path.read_text(encoding="utf-8") == text
    for again in (Layout.from_json(text), Layout.from_json(text.encode()), Layout.load(path)):
        assert again.to_json() == text
        assert again.source_shape == tuple(layout.source_shape)
        assert again.output_shape == tuple(layout.output_shape)
        # JSON has no tuples: the meta comes back as JSON would give it.
        assert again.meta == json.loads(json.dumps(layout.meta))
        assert len(again.passes) == len(layout.passes)
        for mine, theirs in zip(again.passes, layout.passes, strict=True):
            assert mine.grid == theirs.grid
            assert (mine.feather, mine.blend) == (theirs.feather, theirs.blend)
            for field in ("positions", "cut_cols", "cut_rows", "cut_right", "cut_bottom"):
                a, b = getattr(mine, field), getattr(theirs, field)
                assert a.dtype == b.dtype and a.shape == b.shape, field
                np.testing.assert_array_equal(a, b, err_msg=field)
        kinds = ["blend", "normal"] if name == "walk" else ["blend", "hard", "normal"]
        rng = np.random.default_rng(14)
        companion = rng.integers(0, 65536, size=(*SOURCE_SHAPE, 3), dtype=np.uint16)
        for kind in kinds:
            assert (
                apply_layout(again, companion, kind=kind).tobytes()
                == apply_layout(layout, companion, kind=kind).tobytes()
            )
        assert apply_layout(again, texture).tobytes() == result.image.tobytes()


def test_json_document_describes_the_arrays() -> None:
    """The document's fields, read with json alone, are the layout's arrays row-major."""
    _, result = case("poisson-torus")
    doc = document(result.layout)
    assert doc["format"] == "quilting.layout"
    assert doc["source_shape"] == list(SOURCE_SHAPE)
    (record,) = doc["passes"]
    (layout_pass,) = result.layout.passes
    grid = layout_pass.grid
    assert (record["block"], record["overlap"], record["rows"], record["cols"]) == (
        grid.block,
        grid.overlap,
        grid.rows,
        grid.cols,
    )
    assert record["blend"] == "poisson"
    assert len(record["positions"]) == grid.rows * grid.cols
    for k, (y, x) in enumerate(record["positions"]):
        assert [y, x] == layout_pass.positions[k // grid.cols, k % grid.cols].tolist()
    assert record["cut_cols"][5] == layout_pass.cut_cols[5 // grid.cols, 5 % grid.cols].tolist()


# --------------------------------------------------------------------------------------------
# Malformed documents and companions that do not fit
# --------------------------------------------------------------------------------------------


def _mutated(change: Callable[[Doc], object]) -> str:
    doc = document(case("plain")[1].layout)
    change(doc)
    return json.dumps(doc)


def _pass(doc: Doc) -> Doc:
    record: Doc = doc["passes"][0]
    return record


MALFORMED: list[tuple[str, Callable[[Doc], object] | str | bytes, str]] = [
    ("not json", "{not json", "not valid JSON"),
    ("not utf-8", b"\xff\xfe\x00", "not valid JSON"),
    ("a list", "[1, 2]", "not a quilting layout"),
    ("other format", lambda d: d.update(format="other"), "not a quilting layout"),
    ("version 4", lambda d: d.update(version=4), "unsupported layout version 4"),
    ("version 3 without sources", lambda d: d.update(version=3), "sources are malformed"),
    ("no version", lambda d: d.pop("version"), "unsupported layout version None"),
    ("no passes key", lambda d: d.pop("passes"), "missing or has a malformed field"),
    ("no source shape", lambda d: d.pop("source_shape"), "missing or has a malformed field"),
    ("short output shape", lambda d: d.update(output_shape=[3]), "malformed field"),
    ("no passes", lambda d: d.update(passes=[]), "no passes"),
    ("pass without block", lambda d: _pass(d).pop("block"), "malformed field"),
    ("block 0", lambda d: _pass(d).update(block=0), "impossible grid"),
    ("overlap = block", lambda d: _pass(d).update(overlap=_pass(d)["block"]), "impossible grid"),
    ("negative overlap", lambda d: _pass(d).update(overlap=-1), "impossible grid"),
    ("no rows", lambda d: _pass(d).update(rows=0), "impossible grid"),
    ("positions short", lambda d: _pass(d)["positions"].pop(), "do not match the grid"),
    ("cuts short", lambda d: _pass(d)["cut_rows"][0].pop(), "do not match the grid"),
    ("negative position", lambda d: _pass(d)["positions"][0].__setitem__(1, -1), "negative"),
    ("negative cut", lambda d: _pass(d)["cut_cols"][3].__setitem__(0, -2), "negative"),
    ("cut past block", lambda d: _pass(d)["cut_rows"][3].__setitem__(0, 15), "exceed the block"),
    (
        "position outside source",
        lambda d: _pass(d)["positions"][2].__setitem__(0, SOURCE_SHAPE[0] - 13),
        "outside its source",
    ),
    ("output past grid", lambda d: d.update(output_shape=[50, 200]), "larger than its grid"),
    ("unknown fill", lambda d: _pass(d).update(fill="spray"), "unknown fill 'spray'"),
    ("negative feather", lambda d: _pass(d).update(fill="walk", feather=-1), "impossible walk"),
    ("unknown blend", lambda d: _pass(d).update(blend="smudge"), "unknown blend 'smudge'"),
    (
        "walk and poisson",
        lambda d: _pass(d).update(fill="walk", feather=2, blend="poisson"),
        "unknown blend",
    ),
    ("torus of 0 overlap", lambda d: _pass(d).update(period=[50, 10_000]), "impossible torus"),
]


@pytest.mark.parametrize(
    ("change", "needle"), [m[1:] for m in MALFORMED], ids=[m[0] for m in MALFORMED]
)
def test_a_malformed_document_is_a_layout_error_naming_the_problem(
    change: Callable[[Doc], object] | str | bytes, needle: str
) -> None:
    text = change if isinstance(change, str | bytes) else _mutated(change)
    with pytest.raises(LayoutError, match=re.escape(needle)):
        Layout.from_json(text)


def test_the_untouched_document_and_its_version_1_load() -> None:
    """The refusals above are the mutations': the document they start from loads, as a plane
    document of version 1 too."""
    text = _mutated(lambda d: None)
    assert json.loads(Layout.from_json(text).to_json()) == json.loads(text)
    old = Layout.from_json(_mutated(lambda d: d.update(version=1)))
    assert old.passes[0].grid.period == (0, 0)


# Malformed values of the right JSON shape but the wrong type or range. ``from_json`` promises
# LayoutError for "a malformed one"; these raised ValueError, OverflowError or AttributeError
# when this file was written (reported, not fixed here).
FOREIGN: list[tuple[str, Callable[[Doc], object]]] = [
    ("block not a number", lambda d: _pass(d).update(block="abc")),
    ("block infinite", lambda d: _pass(d).update(block=float("inf"))),
    ("position past int32", lambda d: _pass(d)["positions"][0].__setitem__(0, 2**40)),
    ("cut past int16", lambda d: _pass(d)["cut_cols"][0].__setitem__(0, 40_000)),
    ("source shape not a number", lambda d: d.update(source_shape=["a", 48])),
    ("feather not a number", lambda d: _pass(d).update(fill="walk", feather="x")),
    ("period not numbers", lambda d: _pass(d).update(period="ab")),
    ("passes an object", lambda d: d.update(passes={"a": 1})),
]


@pytest.mark.parametrize("change", [m[1] for m in FOREIGN], ids=[m[0] for m in FOREIGN])
def test_a_malformed_value_is_a_layout_error_not_a_foreign_one(
    change: Callable[[Doc], object],
) -> None:
    text = _mutated(change)
    with pytest.raises(LayoutError):
        Layout.from_json(text)


@pytest.mark.parametrize("shape", [[-5, 10], [10, -1], [0, 10]])
def test_an_output_shape_of_no_pixels_is_refused(shape: list[int]) -> None:
    """A result has at least one pixel a side (synthesize refuses less); a document saying
    otherwise is malformed. Accepted, a negative height crops from the end: the render
    silently comes back with grid height - 5 rows."""
    text = _mutated(lambda d: d.update(output_shape=shape))
    with pytest.raises(LayoutError, match="output"):
        Layout.from_json(text)


def test_a_walk_fill_is_one_pass_only() -> None:
    """Walk mode is a single pass of synthesis (``Layout._walk_canvas`` unpacks exactly one);
    a document with a walk pass among others must be refused when read, not fail with a
    ValueError when rendered."""
    doc = document(case("walk")[1].layout)
    doc["passes"].append(json.loads(json.dumps(doc["passes"][0])))
    text = json.dumps(doc)
    try:
        layout = Layout.from_json(text)
    except LayoutError:
        return
    layout.render(noise())  # accepted: it must render then


def test_loading_a_missing_file_names_it(tmp_path: Path) -> None:
    path = tmp_path / "nowhere" / "layout.json"
    with pytest.raises(LayoutError, match=re.escape(str(path))):
        Layout.load(path)


def test_loading_a_corrupt_file_is_a_layout_error(tmp_path: Path) -> None:
    path = tmp_path / "layout.json"
    text = case("plain")[1].layout.to_json()
    path.write_text(text[: len(text) // 2], encoding="utf-8")  # cut short
    with pytest.raises(LayoutError, match="not valid JSON"):
        Layout.load(path)


def test_a_companion_of_another_size_is_refused_naming_both_sizes() -> None:
    layout = case("plain")[1].layout
    with pytest.raises(LayoutError) as info:
        apply_layout(layout, np.zeros((20, 30, 3), np.uint8))
    message = str(info.value)
    assert "30x20" in message and "48x48" in message
    # Transposed is another size too (48 x 47 against 47 x 48).
    with pytest.raises(LayoutError, match="47x48"):
        apply_layout(layout, np.zeros((48, 47), np.uint8))


@pytest.mark.parametrize(
    ("companion", "error", "needle"),
    [
        (np.zeros((*SOURCE_SHAPE, 2), np.uint8), InvalidImageError, "2 channels"),
        (np.zeros((*SOURCE_SHAPE, 5), np.uint8), InvalidImageError, "5 channels"),
        (np.zeros(SOURCE_SHAPE, np.int32), InvalidImageError, "int32"),
        (np.full(SOURCE_SHAPE, np.nan, np.float32), InvalidImageError, "NaN"),
        ([[0, 1], [2, 3]], InvalidImageError, "numpy array"),
    ],
    ids=["2 channels", "5 channels", "int32", "nan", "a list"],
)
def test_a_companion_the_engine_cannot_take_is_refused(
    companion: object, error: type[Exception], needle: str
) -> None:
    with pytest.raises(error, match=re.escape(needle)):
        apply_layout(case("plain")[1].layout, companion)


@pytest.mark.parametrize("channels", [1, 2])
def test_a_normal_companion_needs_three_channels(channels: int) -> None:
    layout = case("poisson")[1].layout
    companion = np.zeros((*SOURCE_SHAPE, channels), np.uint8)
    error = LayoutError if channels == 1 else InvalidImageError
    with pytest.raises(error, match="channels"):
        apply_layout(layout, companion, kind="normal")


@pytest.mark.parametrize("kind", ["soft", "", "Hard", "normals"])
def test_an_unknown_kind_is_refused_listing_the_kinds(kind: str) -> None:
    with pytest.raises(LayoutError) as info:
        apply_layout(case("plain")[1].layout, noise(), kind=kind)
    message = str(info.value)
    assert repr(kind) in message
    assert all(known in message for known in ("blend", "hard", "normal"))
