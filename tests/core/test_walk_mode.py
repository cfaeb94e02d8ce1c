"""Walk mode end to end (minimum-resistance-cut paper, §2-3): random blocks joined by the walk cut.

Sizes, channels and dtypes are kept; the result depends on the seed only and re-renders
exactly from its layout; block positions are drawn without matching; the recorded cuts, the
feathered blend, the options that steer the cut, exclusions, and the seams against the
random-placement mode, measured on the image.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from textures import texture

import quilting
from quilting import Layout, apply_layout
from quilting.core.exclusion import excluded_pixels
from quilting.core.stats import ownership

STARS = [((120, 120, 120), (255, 255, 255))]


def noise(shape: tuple[int, ...], seed: int = 0) -> NDArray[np.uint8]:
    """Random 8-bit pixels: two pixels almost never share a colour."""
    return np.random.default_rng(seed).integers(0, 256, size=shape, dtype=np.uint8)


def walk(image: NDArray[Any], size: tuple[int, int], **options: Any) -> quilting.Result:
    options = {"block": 20, "seed": 1, **options}
    return quilting.synthesize(image, size, mode="walk", **options)


def reflected(image: NDArray[Any], pad: int) -> NDArray[Any]:
    """The image extended by its mirror image (edge pixel not repeated) on every side."""
    view = image if image.ndim == 3 else image[..., None]
    return np.pad(view, ((pad, pad), (pad, pad), (0, 0)), mode="reflect")


def boundary_error(result: quilting.Result) -> float:
    """Mean squared step (8-bit units, summed over channels) between 4-neighbour output pixels
    that come from different blocks."""
    owner = ownership(result.layout).owner
    image = result.image.astype(np.float64)
    if image.ndim == 2:
        image = image[..., None]
    steps = []
    for axis in (0, 1):
        a = [slice(None), slice(None)]
        b = [slice(None), slice(None)]
        a[axis], b[axis] = slice(None, -1), slice(1, None)
        across = owner[tuple(a)] != owner[tuple(b)]
        step = ((image[tuple(a)] - image[tuple(b)]) ** 2).sum(axis=-1)
        steps.append(step[across])
    return float(np.concatenate(steps).mean())


# --- shape, dtype, determinism --------------------------------------------------------------


def _source(kind: str) -> NDArray[Any]:
    if kind == "gray":
        return texture("gravel")
    if kind == "gray2d-from-rgb":
        return np.ascontiguousarray(texture("hubble")[..., 0])
    if kind == "rgb":
        return texture("wood")
    if kind == "rgba":
        return texture("cloud_rgba")
    if kind == "uint16":
        return texture("gravel").astype(np.uint16) * 257
    return noise((50, 60, 1))  # an explicit single channel


@pytest.mark.parametrize("kind", ["gray", "gray2d-from-rgb", "rgb", "rgba", "uint16", "one"])
def test_size_dtype_and_channels_are_kept(kind: str) -> None:
    source = _source(kind)
    channels = {"gray": (), "gray2d-from-rgb": (), "rgb": (3,), "rgba": (4,), "uint16": ()}
    assert source.shape[2:] == channels.get(kind, (1,))
    for size in ((77, 101), (20, 20), (5, 7)):
        result = walk(source, size)
        assert result.image.shape == (*size, *source.shape[2:])
        assert result.image.dtype == source.dtype
        assert result.layout.output_shape == size
        assert np.array_equal(apply_layout(result.layout, source), result.image)


def test_same_seed_same_bytes_different_seed_different() -> None:
    wood = texture("wood")
    a = walk(wood, (90, 110), seed=5)
    b = walk(wood, (90, 110), seed=5)
    c = walk(wood, (90, 110), seed=6)
    one = walk(wood, (90, 110), seed=5, max_batch=1)
    assert a.image.tobytes() == b.image.tobytes() == one.image.tobytes()
    assert a.layout.to_json() == b.layout.to_json()
    assert a.image.tobytes() != c.image.tobytes()
    assert not np.array_equal(a.layout.passes[0].positions, c.layout.passes[0].positions)


def test_walk_needs_no_backend_and_reports_its_seams() -> None:
    result = walk(texture("gravel"), (100, 100))
    assert result.backend == "none"
    assert result.renderer is None
    stats = result.stats
    assert stats.seam_pixels > 0
    for value in (stats.seam_error_total, stats.seam_error_mean, stats.largest_copy, stats.unused):
        assert np.isfinite(value)
    assert stats.seam_error_total > 0
    assert stats.largest_copy >= 0 and 0 <= stats.unused <= 1


# --- layouts --------------------------------------------------------------------------------


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
@pytest.mark.parametrize("feather", [0, 4])
def test_layout_json_re_renders_exactly(dtype: Any, feather: int, tmp_path: Path) -> None:
    wood = texture("wood")
    if dtype == np.uint16:
        source = wood.astype(np.uint16) * 257 + 3
    elif dtype == np.float32:
        source = (wood.astype(np.float32) + 0.25) / 256
    else:
        source = wood
    result = walk(source, (83, 97), feather=feather)
    data = json.loads(result.layout.to_json())
    assert data["version"] == 2
    assert data["passes"][0]["fill"] == "walk"
    assert data["passes"][0]["feather"] == feather
    path = tmp_path / "layout.json"
    result.layout.save(path)
    for layout in (Layout.from_json(result.layout.to_json()), Layout.load(path)):
        assert layout.passes[0].feather == feather
        rendered = apply_layout(layout, source)
        assert rendered.dtype == source.dtype
        assert rendered.tobytes() == result.image.tobytes()


def test_apply_layout_on_companions() -> None:
    wood = texture("wood")
    result = walk(wood, (83, 97), feather=4)
    layout = Layout.from_json(result.layout.to_json())
    # One channel as a gray companion follows the same blend, byte for byte.
    for channel in range(3):
        gray = np.ascontiguousarray(wood[..., channel])
        assert np.array_equal(apply_layout(layout, gray), result.image[..., channel])
    # A blend of a constant map is that constant: the weights sum to one.
    flat = np.full(wood.shape[:2], 200, dtype=np.uint8)
    assert (apply_layout(layout, flat) == 200).all()
    # The same texture in 16 bits gives the same picture, to 8-bit precision.
    deep = apply_layout(layout, wood.astype(np.uint16) * 257)
    assert deep.dtype == np.uint16 and deep.shape == result.image.shape
    assert np.abs(deep.astype(np.int64) / 257 - result.image).max() <= 1
    with pytest.raises(quilting.LayoutError):
        apply_layout(layout, np.zeros((10, 10), dtype=np.uint8))


def test_hard_walk_pixels_come_from_the_block_or_a_continuation() -> None:
    """With feather 0, every output pixel is the new block's source pixel or the source pixel
    of a neighbour's continuation (the source mirrored past its edges), of one of the blocks
    covering it; with a feather, blends appear that are neither."""
    source = noise((70, 64, 3))
    block = 20
    mirror = reflected(source, 2 * block)

    def strays(feather: int) -> float:
        result = walk(source, (95, 103), block=block, seed=4, feather=feather)
        p = result.layout.passes[0]
        g = p.grid
        image = result.image
        height, width = image.shape[:2]
        matched = np.zeros((height, width), dtype=bool)
        for i in range(g.rows):
            for j in range(g.cols):
                y0, x0 = i * g.step, j * g.step
                h, w = min(block, height - y0), min(block, width - x0)
                if h <= 0 or w <= 0:
                    continue
                here = image[y0 : y0 + h, x0 : x0 + w]
                starts = [tuple(p.positions[i, j])]
                if j > 0:
                    starts.append(tuple(p.positions[i, j - 1] + (0, g.step)))
                if i > 0:
                    starts.append(tuple(p.positions[i - 1, j] + (g.step, 0)))
                if i > 0 and j > 0:
                    starts.append(tuple(p.positions[i - 1, j - 1] + (g.step, g.step)))
                for sy, sx in starts:
                    sy, sx = sy + 2 * block, sx + 2 * block
                    candidate = mirror[sy : sy + h, sx : sx + w]
                    matched[y0 : y0 + h, x0 : x0 + w] |= (candidate == here).all(axis=-1)
        return float(1 - matched.mean())

    assert strays(0) == 0
    assert strays(4) > 0.01  # the check can fail: blended pixels are no source pixel


def test_hard_walk_companion_traces_the_source() -> None:
    """With feather 0 a position map quilted with the layout says where each pixel came from."""
    source = texture("wood")
    result = walk(source, (90, 100), feather=0, seed=6)
    yy, xx = np.indices(source.shape[:2])
    where = apply_layout(result.layout, (yy * 256 + xx).astype(np.uint16))
    src_y, src_x = np.divmod(where.astype(np.int64), 256)
    assert np.array_equal(source[src_y, src_x], result.image)
    # It is the block the ownership map names (the one the pixel mostly shows), translated by
    # that block's offset, mirrored where a continuation runs past the texture's edge.
    owner = ownership(result.layout)
    offsets = owner.offsets[owner.owner]
    yy, xx = np.indices(result.image.shape[:2])
    for got, own, length in (
        (src_y, yy + offsets[..., 0], source.shape[0]),
        (src_x, xx + offsets[..., 1], source.shape[1]),
    ):
        assert own.min() >= 0
        assert (own >= length).any()  # this seed's continuations run past both edges
        assert np.array_equal(got, np.where(own >= length, 2 * (length - 1) - own, own))
    # Some pixels are continuations: their owner is not the last block placed over them.
    g = result.layout.passes[0].grid
    last_row = np.minimum(yy // g.step, g.rows - 1)
    last_col = np.minimum(xx // g.step, g.cols - 1)
    assert (owner.owner != last_row * g.cols + last_col).mean() > 0.05


def test_unused_share_matches_the_traced_pixels() -> None:
    """stats.unused is the share of the texture appearing nowhere in the output: with feather 0
    every output pixel is one source pixel, traced with a position map."""
    wood = texture("wood")
    yy, xx = np.indices(wood.shape[:2])
    positions = (yy * 256 + xx).astype(np.uint16)
    for mode in ("random", "walk"):
        result = quilting.synthesize(
            wood, (90, 100), block=20, seed=0, mode=mode, feather=0, blend="none"
        )
        where = apply_layout(result.layout, positions).astype(np.int64)
        used = np.zeros(wood.shape[:2], dtype=bool)
        used[where // 256, where % 256] = True
        assert result.stats.unused == pytest.approx(1.0 - used.mean(), abs=1e-9), mode


# --- positions and cuts ---------------------------------------------------------------------


def test_positions_are_drawn_without_looking_at_the_texture() -> None:
    a = walk(noise((90, 80), 1), (150, 160), seed=3).layout.passes[0]
    b = walk(noise((90, 80), 2), (150, 160), seed=3).layout.passes[0]
    gravel = walk(texture("gravel")[:90, :80], (150, 160), seed=3).layout.passes[0]
    assert np.array_equal(a.positions, b.positions)
    assert np.array_equal(a.positions, gravel.positions)
    # ... but the cuts follow the content.
    assert not np.array_equal(a.cut_cols, gravel.cut_cols)


def test_positions_cover_the_texture_uniformly() -> None:
    result = walk(texture("gravel"), (400, 400), block=16, seed=9)
    positions = result.layout.passes[0].positions.reshape(-1, 2)
    field = 256 - 16 + 1
    assert positions.min() >= 0 and positions.max() < field
    assert len(positions) >= 600
    # Each quarter of the field along each axis holds about a quarter of the blocks.
    for axis in (0, 1):
        counts = np.bincount(positions[:, axis] * 4 // field, minlength=4)
        assert (counts > 0.15 * len(positions)).all(), counts
    # Nearly all positions are distinct (a matching method would repeat its favourites).
    distinct = len({tuple(p) for p in positions.tolist()})
    assert distinct > 0.95 * len(positions)


def test_cuts_are_zero_without_a_neighbour() -> None:
    p = walk(texture("wood"), (110, 120), seed=2).layout.passes[0]
    assert (p.cut_cols[:, 0] == 0).all()
    assert (p.cut_rows[0, :] == 0).all()
    # Blocks with a neighbour are really cut, inside the block.
    assert (p.cut_cols[:, 1:] > 0).any() and (p.cut_rows[1:, :] > 0).any()
    assert p.cut_cols.max() < p.grid.block and p.cut_rows.max() < p.grid.block
    assert (p.cut_right == p.grid.block).all() and (p.cut_bottom == p.grid.block).all()


def test_feather_changes_the_blend_not_the_cuts() -> None:
    wood = texture("wood")
    hard = walk(wood, (90, 100), feather=0)
    soft = walk(wood, (90, 100), feather=4)
    wide = walk(wood, (90, 100), feather=8)
    assert hard.image.tobytes() != soft.image.tobytes() != wide.image.tobytes()
    for other in (soft, wide):
        assert np.array_equal(hard.layout.passes[0].positions, other.layout.passes[0].positions)
        assert np.array_equal(hard.layout.passes[0].cut_cols, other.layout.passes[0].cut_cols)
        assert np.array_equal(hard.layout.passes[0].cut_rows, other.layout.passes[0].cut_rows)
    # feather 1 is a hard cut too.
    assert walk(wood, (90, 100), feather=1).image.tobytes() == hard.image.tobytes()


def test_max_run_changes_the_cuts() -> None:
    wood = texture("wood")
    passes = {run: walk(wood, (90, 100), max_run=run).layout.passes[0] for run in (1, 5, 20)}
    assert np.array_equal(passes[1].positions, passes[5].positions)
    assert not np.array_equal(passes[1].cut_cols, passes[5].cut_cols)
    assert not np.array_equal(passes[5].cut_cols, passes[20].cut_cols)


def test_luminance_error_changes_the_cuts_on_colour() -> None:
    wood = texture("wood")
    rgb = walk(wood, (90, 100)).layout.passes[0]
    luma = walk(wood, (90, 100), error="luminance").layout.passes[0]
    assert np.array_equal(rgb.positions, luma.positions)
    assert not np.array_equal(rgb.cut_cols, luma.cut_cols)
    # On a gray texture the luminance is the texture: nothing changes.
    gravel = np.ascontiguousarray(texture("gravel")[:100, :100])
    assert (
        walk(gravel, (80, 80)).image.tobytes()
        == walk(gravel, (80, 80), error="luminance").image.tobytes()
    )


# --- exclusion ------------------------------------------------------------------------------


def _covers(result: quilting.Result, excluded: NDArray[np.bool_]) -> int:
    """Blocks whose source square holds an excluded pixel."""
    p = result.layout.passes[0]
    block = p.grid.block
    return sum(
        bool(excluded[y : y + block, x : x + block].any())
        for y, x in p.positions.reshape(-1, 2).tolist()
    )


def test_excluded_colours_are_never_drawn() -> None:
    hubble = texture("hubble")
    ranges = quilting.SynthesisOptions(exclude_colors=STARS).exclude_colors
    excluded = excluded_pixels(hubble, ranges, None)
    assert excluded is not None and excluded.any()
    result = walk(hubble, (160, 180), exclude_colors=STARS)
    assert _covers(result, excluded) == 0
    plain = walk(hubble, (160, 180))
    assert _covers(plain, excluded) > 0  # the check can fail


def test_masked_pixels_are_never_drawn() -> None:
    gravel = texture("gravel")
    mask = np.full(gravel.shape, 255, dtype=np.uint8)
    mask[60:200, 40:90] = 0
    mask[10:30, 150:250] = 0
    result = walk(gravel, (160, 180), source_mask=mask, seed=3)
    assert _covers(result, mask == 0) == 0
    plain = walk(gravel, (160, 180), seed=3)
    assert _covers(plain, mask == 0) > 0


# --- quality --------------------------------------------------------------------------------


def test_walk_seams_beat_random_placement() -> None:
    gravel = texture("gravel")
    for seed in (1, 2):
        random = quilting.synthesize(
            gravel, (200, 200), block=32, mode="random", seed=seed, blend="none"
        )
        soft = walk(gravel, (200, 200), block=32, seed=seed)
        hard = walk(gravel, (200, 200), block=32, seed=seed, feather=0)
        # Same blocks: only the joins differ.
        assert np.array_equal(random.layout.passes[0].positions, soft.layout.passes[0].positions)
        assert boundary_error(soft) < boundary_error(random)
        assert boundary_error(hard) < boundary_error(random)
        assert soft.stats.seam_error_mean < random.stats.seam_error_mean


@pytest.mark.parametrize("size", [(90, 20), (20, 90), (20, 20)])
def test_one_row_or_one_column_of_blocks(size: tuple[int, int]) -> None:
    # A one-column grid has empty wavefront levels (odd 2 i + j); they place nothing.
    result = walk(noise((40, 40, 3)), size)
    assert result.image.shape == (*size, 3)
    np.testing.assert_array_equal(result.layout.render(noise((40, 40, 3))), result.image)
    assert 0 < result.stats.largest_copy <= 1
