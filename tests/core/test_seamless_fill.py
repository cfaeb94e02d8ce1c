"""Tests of :mod:`quilting.core.seamless_fill`: making an image tile by re-synthesizing the
band across each wrap (``make_tileable(..., method="fill")``).

Covered: :func:`fill_band` (the default band, an explicit band, the clip to
:func:`~quilting.core.seamless.band_limit`); :func:`tile_by_filling` along x, y and both (shape
and dtype, the kept centre byte for byte and pointing at itself, every pixel the input pixel
its provenance names without a blend, nothing copied from the forgotten band, only the tiled
wraps re-synthesized, the wrap as smooth as the interior afterwards); determinism by seed;
the progress callback; the refusals (a tiled side under ``MIN_SIDE``, a band that leaves no
3x3 block of the image).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from textures import texture

import quilting
from quilting.core.errors import InvalidImageError, InvalidParameterError
from quilting.core.fields import CostBackend
from quilting.core.options import TileOptions
from quilting.core.pixels import as_channels
from quilting.core.seamless import MIN_SIDE, Axes, Tiled, band_limit
from quilting.core.seamless_fill import MIN_BAND, fill_band, tile_by_filling
from quilting.costs.registry import get_backend

Image = NDArray[Any]
AXES: list[Axes] = ["x", "y", "both"]
#: numpy axes (0: rows, 1: columns) whose wrap each ``axes`` makes seamless.
WRAPS: dict[str, list[int]] = {"x": [1], "y": [0], "both": [0, 1]}


# --- helpers ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def backend() -> CostBackend:
    """The backend make_tileable(method="fill") uses (api.py: ``get_backend("auto")``)."""
    return get_backend("auto")


def ramp_image(shape: tuple[int, int, int], seed: int) -> NDArray[np.float32]:
    """A strong ramp left to right and top to bottom plus a little seeded noise, in [0, 1]:
    nearly smooth inside, a jump of almost the ramp's whole height across each of its wraps."""
    height, width, _ = shape
    rng = np.random.default_rng(seed)
    ramp = 0.05 + 0.45 * np.add.outer(np.linspace(0, 1, height), np.linspace(0, 1, width))
    image = ramp[..., None] + 0.02 * rng.standard_normal(shape)
    clipped: NDArray[np.float32] = np.clip(image, 0, 1).astype(np.float32)
    return clipped


def sample(kind: str) -> Image:
    """Small inputs of each format: RGB uint8 (a crop of wood), 2-D gray uint8 (a crop of
    gravel), RGB float32 (the ramp)."""
    if kind == "wood":
        return np.ascontiguousarray(texture("wood")[:64, :80])
    if kind == "gravel":
        return np.ascontiguousarray(texture("gravel")[:72, :64])
    return ramp_image((64, 80, 3), seed=1)


KINDS = ["wood", "gravel", "ramp"]


def tile(
    image: Image,
    backend: CostBackend,
    axes: Axes,
    blend: str = "none",
    band: int | None = None,
    seed: int = 0,
) -> Tiled:
    """``tile_by_filling`` called the way ``quilting.make_tileable(method="fill")`` calls it."""
    view, fmt = as_channels(image, "image")
    options = TileOptions(axes=axes, band=band, blend=blend, method="fill", seed=seed)
    return tile_by_filling(view, fmt, options, backend)


def line_steps(image: Image, axis: int) -> tuple[float, NDArray[np.float64]]:
    """Mean squared step (summed over channels) between neighbouring lines along ``axis``:
    across the wrap (the last line against the first), and for each interior pair of lines."""
    pixels = image.astype(np.float64)
    pixels = pixels[..., None] if pixels.ndim == 2 else pixels
    moved = np.moveaxis(pixels, axis, 0)
    wrap = float(np.square(moved[0] - moved[-1]).sum(axis=-1).mean())
    interior = np.square(np.diff(moved, axis=0)).sum(axis=-1).mean(axis=1)
    return wrap, interior


def band_core(side: int, band: int) -> NDArray[np.bool_]:
    """The lines of a side within ``band // 2`` of its wrap: inside the forgotten band however
    its odd pixel is placed."""
    line = np.arange(side)
    core: NDArray[np.bool_] = (line < band // 2) | (line >= side - band // 2)
    return core


# --- fill_band --------------------------------------------------------------------------------


def test_the_default_band_is_a_sixteenth_of_the_side_at_least_min_band() -> None:
    clipped = unclipped = 0
    for side in range(MIN_SIDE, 1200):
        wanted = max(MIN_BAND, side // 16)
        assert wanted >= MIN_BAND and wanted >= side // 16
        if wanted <= band_limit(side):
            assert fill_band(side, None) == wanted, side
            unclipped += 1
        else:
            assert fill_band(side, None) == band_limit(side), side
            clipped += 1
    # Both regimes were met: small sides clip MIN_BAND, large ones take side // 16.
    assert clipped > 0 and unclipped > 0
    assert fill_band(16 * 4 * MIN_BAND, None) == 4 * MIN_BAND
    assert fill_band(16 * MIN_BAND - 16, None) == MIN_BAND


def test_an_explicit_band_is_kept() -> None:
    for side in range(MIN_SIDE, 300):
        for band in range(1, band_limit(side) + 1):
            assert fill_band(side, band) == band, (side, band)


def test_every_band_is_clipped_to_the_limit_and_at_least_one() -> None:
    for side in range(1, 300):
        limit = band_limit(side)
        for band in [None, *range(1, side + 3), 10**6]:
            width = fill_band(side, band)
            assert 1 <= width <= max(1, limit), (side, band)
            if band is not None and band > limit >= 1:
                assert width == limit, (side, band)


# --- the result -------------------------------------------------------------------------------


@pytest.mark.parametrize("blend", ["none", "poisson"])
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("axes", AXES)
def test_the_kept_centre_is_the_input_at_its_own_place(
    backend: CostBackend, axes: Axes, kind: str, blend: str
) -> None:
    image = sample(kind)
    tiled = tile(image, backend, axes, blend, seed=3)
    height, width = image.shape[:2]
    assert tiled.image.shape == image.shape and tiled.image.dtype == image.dtype
    assert tiled.kept.shape == (height, width) and tiled.kept.dtype == np.bool_
    assert tiled.axes == axes and tiled.blend == blend
    # Something was re-synthesized, and most of the image was not.
    assert 0.3 < tiled.kept.mean() < 1
    # The kept pixels are the input's, byte for byte, even when the fill blends its seams.
    assert np.array_equal(tiled.image[tiled.kept], image[tiled.kept])
    rows, cols = np.indices((height, width))
    assert np.array_equal(tiled.source_rows[tiled.kept], rows[tiled.kept])
    assert np.array_equal(tiled.source_cols[tiled.kept], cols[tiled.kept])
    for source, side in ((tiled.source_rows, height), (tiled.source_cols, width)):
        assert source.shape == (height, width) and source.dtype == np.intp
        assert source.min() >= 0 and source.max() < side


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("axes", AXES)
def test_without_a_blend_every_pixel_is_the_input_pixel_it_names(
    backend: CostBackend, axes: Axes, kind: str
) -> None:
    # Why this holds: with blend="none" the fill pastes its blocks' pixels as they are (copies
    # in float32 working units, which uint8 and float32 survive exactly; see
    # pixels.from_working) and writes the fixed pixels back byte for byte; the half-size roll
    # only moves pixels, and every provenance is taken back through the same roll.
    image = sample(kind)
    tiled = tile(image, backend, axes, "none", seed=5)
    copied = image[tiled.source_rows, tiled.source_cols]
    assert np.array_equal(tiled.image, copied)
    # And some band pixels were actually copied from elsewhere (not just left in place).
    rows, cols = np.indices(image.shape[:2])
    assert ((tiled.source_rows != rows) | (tiled.source_cols != cols)).any()
    # A companion map (here the image itself) is made tileable the same way.
    assert np.array_equal(tiled.apply(image), tiled.image)


@pytest.mark.parametrize("band", [None, 11])
@pytest.mark.parametrize("axes", AXES)
def test_no_pixel_comes_from_the_band_across_the_wrap(
    backend: CostBackend, axes: Axes, band: int | None
) -> None:
    # The band is forgotten: the fill's blocks come from the image outside it, and the pixels
    # outside it point at themselves, so no provenance lies in it (in particular, the old wrap
    # is never copied back).
    image = sample("wood")
    tiled = tile(image, backend, axes, "none", band=band, seed=1)
    height, width = image.shape[:2]
    if axes in ("x", "both"):
        assert not band_core(width, fill_band(width, band))[tiled.source_cols].any()
    if axes in ("y", "both"):
        assert not band_core(height, fill_band(height, band))[tiled.source_rows].any()


def contiguous(mask: NDArray[np.bool_]) -> bool:
    """Whether the True entries of a 1-D mask are one run."""
    where = np.flatnonzero(mask)
    return where.size > 0 and where[-1] - where[0] + 1 == where.size


@pytest.mark.parametrize("band", [None, 11])
@pytest.mark.parametrize("axes", AXES)
def test_only_the_tiled_wraps_are_filled(
    backend: CostBackend, axes: Axes, band: int | None
) -> None:
    image = sample("wood")
    height, width = image.shape[:2]
    tiled = tile(image, backend, axes, "none", band=band, seed=2)
    kept = tiled.kept
    rows_kept, cols_kept = kept.any(axis=1), kept.any(axis=0)
    # The kept part is a rectangle: bands run the whole length of their side.
    assert np.array_equal(kept, np.outer(rows_kept, cols_kept))
    for tiled_axis, lines, side in (("y", rows_kept, height), ("x", cols_kept, width)):
        if axes not in (tiled_axis, "both"):
            # Not tiled along this axis: every line of it is kept, the cut stays at the border.
            assert lines.all()
            continue
        # One band, across the wrap: it holds both border lines and is centred on the wrap
        # (within a pixel); it is at least the band's width (the fill's cuts may also replace
        # a margin on each side of it).
        assert contiguous(lines) and not lines[0] and not lines[-1]
        before, after = int(np.argmax(lines)), int(np.argmax(lines[::-1]))
        assert before + after >= fill_band(side, band)
        assert abs(before - after) <= 1
    # The documented relation between the cuts and the kept mask (Tiled.seam_cols/seam_rows).
    y, x = np.indices(kept.shape)
    inside = (
        (tiled.seam_cols[0][:, None] <= x)
        & (x <= tiled.seam_cols[1][:, None])
        & (tiled.seam_rows[0][None, :] <= y)
        & (y <= tiled.seam_rows[1][None, :])
    )
    assert np.array_equal(kept, inside)
    if axes == "x":
        assert (tiled.seam_rows[0] == 0).all() and (tiled.seam_rows[1] == height - 1).all()
    if axes == "y":
        assert (tiled.seam_cols[0] == 0).all() and (tiled.seam_cols[1] == width - 1).all()


@pytest.mark.parametrize("blend", ["none", "poisson"])
@pytest.mark.parametrize("axes", AXES)
def test_the_wrap_steps_like_the_interior(backend: CostBackend, axes: Axes, blend: str) -> None:
    image = ramp_image((64, 80, 3), seed=4)
    tiled = tile(image, backend, axes, blend, seed=4)
    for axis in WRAPS[axes]:
        wrap_in, interior = line_steps(image, axis)
        wrap_out, _ = line_steps(tiled.image, axis)
        typical = float(np.median(interior))
        # The input does not tile: its wrap jumps by almost the ramp's height (0.45 per
        # channel, squared and summed over 3: about 0.6), where neighbouring lines differ by
        # the noise (2 * 0.02^2 per channel, summed: about 0.0025). Its wrap step is over a
        # hundred times the typical (median) interior step.
        assert wrap_in > 100 * typical
        # Once tiled, the wrap is one more pair of neighbouring lines. Its step is a mean over
        # 64 or 80 pixels of 3 channels, so noise moves it by about 10%; where a cut of the
        # fill crosses the wrap it may be somewhat above the interior's (the ramp must drop
        # back somewhere in the band). Three times the typical step leaves a clear margin
        # over that, and is still 30 times below the input's.
        assert wrap_out < 3 * typical, (axis, wrap_out / typical)


# --- determinism, the public route, progress ------------------------------------------------


def test_the_same_seed_gives_the_same_bytes(backend: CostBackend) -> None:
    image = sample("gravel")
    first = tile(image, backend, "both", "poisson", seed=7)
    again = tile(image, backend, "both", "poisson", seed=7)
    assert first.image.tobytes() == again.image.tobytes()
    assert np.array_equal(first.source_rows, again.source_rows)
    assert np.array_equal(first.source_cols, again.source_cols)
    assert np.array_equal(first.kept, again.kept)
    # The public route is this call.
    public = quilting.make_tileable(image, method="fill", axes="both", blend="poisson", seed=7)
    assert public.image.tobytes() == first.image.tobytes()
    # The seed is used: other seeds draw other blocks.
    others = {tile(image, backend, "both", "poisson", seed=s).image.tobytes() for s in (8, 9)}
    assert others != {first.image.tobytes()}


def test_progress_reaches_the_whole_fill(backend: CostBackend) -> None:
    image = sample("wood")
    view, fmt = as_channels(image, "image")
    calls: list[tuple[float, str]] = []
    options = TileOptions(axes="both", blend="none", method="fill", seed=0)
    tiled = tile_by_filling(view, fmt, options, backend, progress=lambda f, s: calls.append((f, s)))
    fractions = [fraction for fraction, _ in calls]
    assert calls and {stage for _, stage in calls} == {"fill"}
    assert all(0 <= f <= 1 for f in fractions) and fractions == sorted(fractions)
    assert fractions[-1] == 1.0
    # Reporting changes nothing.
    assert np.array_equal(tiled.image, tile(image, backend, "both", "none", seed=0).image)


# --- float images and companions ---------------------------------------------------------------


@pytest.mark.parametrize("dtype", [np.float16, np.float32, np.float64])
def test_float_values_outside_0_1_are_copied_not_clipped(
    backend: CostBackend, dtype: type[np.floating[Any]]
) -> None:
    image = (ramp_image((48, 64, 3), seed=2) * 6 - 2).astype(dtype)
    tiled = tile(image, backend, "both")
    assert tiled.image.dtype == dtype
    assert np.array_equal(tiled.image, image[tiled.source_rows, tiled.source_cols])
    band = tiled.image[~tiled.kept]
    assert band.max() > 1 and band.min() < 0
    blended = tile(image, backend, "both", blend="poisson").image
    assert blended.max() > 1 and blended.min() < 0


@pytest.mark.parametrize("axes", AXES)
@pytest.mark.parametrize("kind", KINDS)
def test_the_image_as_its_own_companion_comes_back_as_the_result(
    backend: CostBackend, kind: str, axes: Axes
) -> None:
    # The fill's own blend is replayed on the companion (not the cuts' blend), so the image
    # comes back byte for byte, blended or not.
    image = sample(kind)
    for blend in ("none", "poisson"):
        tiled = tile(image, backend, axes, blend=blend, seed=4)
        again = tiled.apply(image)
        assert again.dtype == image.dtype and np.array_equal(again, tiled.image)


def test_a_companion_is_blended_by_the_same_linear_operator(backend: CostBackend) -> None:
    image = ramp_image((64, 80, 3), seed=3)
    tiled = tile(image, backend, "both", blend="poisson", seed=2)
    # Halving is exact in float32, so a linear replay gives exactly half the result ...
    half = tiled.apply(image * np.float32(0.5))
    assert np.array_equal(half, tiled.image * np.float32(0.5))
    # ... a companion's kept centre is its own, and 'hard' is the bare selection.
    companion = np.random.default_rng(1).random((64, 80), dtype=np.float32)
    assert np.array_equal(tiled.apply(companion)[tiled.kept], companion[tiled.kept])
    hard = tiled.apply(companion, "hard")
    assert np.array_equal(hard, companion[tiled.source_rows, tiled.source_cols])


def test_a_normal_map_companion_stays_unit_length(backend: CostBackend) -> None:
    image = sample("wood")
    tiled = tile(image, backend, "both", blend="poisson", seed=1)
    rng = np.random.default_rng(5)
    vectors = rng.normal(size=(*image.shape[:2], 3)) + np.array([0, 0, 3.0])
    vectors /= np.linalg.norm(vectors, axis=-1, keepdims=True)
    normals = np.rint((vectors + 1) / 2 * 255).astype(np.uint8)
    out = tiled.apply(normals, "normal")
    length = np.linalg.norm(out.astype(np.float64) / 255 * 2 - 1, axis=-1)
    assert np.abs(length - 1).max() < 0.02
    assert not np.array_equal(out, tiled.apply(normals, "hard"))


# --- refusals ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("shape", "axes", "name"),
    [
        ((32, MIN_SIDE - 1), "x", "width"),
        ((32, MIN_SIDE - 1), "both", "width"),
        ((MIN_SIDE - 1, 32), "y", "height"),
        ((MIN_SIDE - 1, 32), "both", "height"),
    ],
)
def test_a_tiled_side_below_min_side_is_refused(
    backend: CostBackend, shape: tuple[int, int], axes: Axes, name: str
) -> None:
    image = np.random.default_rng(0).integers(0, 256, (*shape, 3), dtype=np.uint8)
    with pytest.raises(InvalidImageError, match=f"its {name} is {MIN_SIDE - 1}") as by_fill:
        tile(image, backend, axes)
    with pytest.raises(InvalidImageError, match=name):
        quilting.make_tileable(image, method="fill", axes=axes)
    # Both methods refuse the same way.
    with pytest.raises(InvalidImageError) as by_cut:
        quilting.make_tileable(image, method="cut", axes=axes)
    assert str(by_cut.value) == str(by_fill.value)


@pytest.mark.parametrize(("axes", "limit"), [("x", 39), ("y", 31), ("both", 31)])
def test_a_band_past_the_limit_is_refused_as_the_cuts_refuse_it(
    backend: CostBackend, axes: Axes, limit: int
) -> None:
    image = np.random.default_rng(0).integers(0, 256, (64, 80, 3), dtype=np.uint8)
    tiled = tile(image, backend, axes, band=limit)  # the widest band is taken as it is
    assert not tiled.kept.all()
    for band in (limit + 1, 2 * limit):
        with pytest.raises(InvalidParameterError, match=f"1..{limit}") as by_fill:
            tile(image, backend, axes, band=band)
        with pytest.raises(InvalidParameterError) as by_cut:
            quilting.make_tileable(image, method="cut", axes=axes, band=band)
        assert str(by_cut.value) == str(by_fill.value)


@pytest.mark.parametrize("height", [1, 2])
def test_an_image_too_thin_for_any_block_is_refused_for_its_size(
    backend: CostBackend, height: int
) -> None:
    # Tiled along x only, the short side is no tiled side: the cuts take it, the fill has no
    # 3x3 block to match and says that the image, not the (default) band, is the problem.
    image = np.random.default_rng(0).integers(0, 256, (height, 64, 3), dtype=np.uint8)
    assert quilting.make_tileable(image, method="cut", axes="x").image.shape == image.shape
    with pytest.raises(InvalidImageError, match=f"image of 64x{height} pixels is too small"):
        tile(image, backend, "x")


@pytest.mark.parametrize(("shape", "axes"), [((48, MIN_SIDE - 1), "y"), ((MIN_SIDE - 1, 48), "x")])
def test_a_short_side_that_is_not_tiled_is_fine(
    backend: CostBackend, shape: tuple[int, int], axes: Axes
) -> None:
    image = np.random.default_rng(0).integers(0, 256, (*shape, 3), dtype=np.uint8)
    tiled = tile(image, backend, axes)
    assert tiled.image.shape == image.shape
    assert np.array_equal(tiled.image, image[tiled.source_rows, tiled.source_cols])


@pytest.mark.parametrize("axes", ["x", "y"])
def test_a_band_that_leaves_no_3x3_block_is_refused(backend: CostBackend, axes: Axes) -> None:
    # The band is centred on the rolled image's middle seam: along a side it covers lines
    # side // 2 - band // 2 .. + band - 1, which leaves `before` lines on one side and `after`
    # on the other. The fill needs a 3x3 block of the image outside the band (the other side
    # is 16 pixels long here), so it refuses exactly when both are under 3 lines.
    rng = np.random.default_rng(0)
    refused = accepted = 0
    for side in range(MIN_SIDE, 13):
        for band in [None, *range(1, band_limit(side) + 1)]:
            shape = (16, side) if axes == "x" else (side, 16)
            image = rng.integers(0, 256, (*shape, 3), dtype=np.uint8)
            width = fill_band(side, band)
            before = side // 2 - width // 2
            after = side - before - width
            if max(before, after) < 3:
                # A band the caller chose is named; the default one is no choice of theirs.
                if band is None:
                    with pytest.raises(InvalidImageError, match="too small to tile by filling"):
                        tile(image, backend, axes, band=band)
                else:
                    with pytest.raises(InvalidParameterError, match="band"):
                        tile(image, backend, axes, band=band)
                refused += 1
            else:
                tiled = tile(image, backend, axes, band=band)
                assert np.array_equal(tiled.image, image[tiled.source_rows, tiled.source_cols])
                accepted += 1
    assert refused > 0 and accepted > 0


def test_a_cross_that_leaves_no_3x3_block_is_refused(backend: CostBackend) -> None:
    # Both axes of a 6x6 image: a 2-pixel band each way leaves four 2x2 corners.
    image = np.random.default_rng(0).integers(0, 256, (6, 6, 3), dtype=np.uint8)
    with pytest.raises(InvalidImageError, match="image of 6x6 pixels is too small"):
        tile(image, backend, "both")
    with pytest.raises(InvalidImageError, match="image of 6x6 pixels is too small"):
        quilting.make_tileable(image, method="fill")
    with pytest.raises(InvalidParameterError, match="band=2"):
        quilting.make_tileable(image, method="fill", band=2)
