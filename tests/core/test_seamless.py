"""Tests of make_tileable: seamless wraps, kept centre, cuts (brute force), formats, errors."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy import ndimage

from quilting.core.errors import InvalidImageError, InvalidParameterError
from quilting.core.seamless import Axes, Tiled, band_limit, make_tileable

Image = NDArray[np.generic]
AXES: list[Axes] = ["both", "x", "y"]
#: numpy axis of the wrap that each tiled direction must make seamless.
WRAPS = {"both": [1, 0], "x": [1], "y": [0]}


# --- helpers ----------------------------------------------------------------------------------


def working(image: Image) -> NDArray[np.float64]:
    scale = {"uint8": 255.0, "uint16": 65535.0}.get(image.dtype.name, 1.0)
    return image.astype(np.float64) / scale


def rolled(image: Image, axes: Axes) -> Image:
    """S: the image rolled by half its size along the tiled axes."""
    height, width = image.shape[:2]
    shift = {"both": (height // 2, width // 2), "x": (0, width // 2), "y": (height // 2, 0)}
    return np.roll(image, shift[axes], axis=(0, 1))


def neighbours(array: NDArray[Any], axis: int, wrap: bool) -> tuple[NDArray[Any], NDArray[Any]]:
    """The two sides of every pair of neighbours along ``axis``, that axis moved first.

    ``wrap``: the pairs of the 2x2 tiling's join (last column next to the first, or last row
    next to the first); otherwise every pair of neighbours inside the image.
    """
    moved = np.moveaxis(array, axis, 0)
    return (moved[-1:], moved[:1]) if wrap else (moved[:-1], moved[1:])


def pair_errors(image: Image, axis: int, wrap: bool) -> NDArray[np.float64]:
    """Squared difference (summed over channels) of neighbours along ``axis``."""
    a, b = neighbours(working(image), axis, wrap)
    errors: NDArray[np.float64] = np.square(a - b).sum(axis=-1).ravel()
    return errors


def join_error(image: Image, axes: Axes) -> float:
    """Mean squared difference across the wrap lines of the tiled axes."""
    return float(np.concatenate([pair_errors(image, a, wrap=True) for a in WRAPS[axes]]).mean())


def interior_error(image: Image, axes: Axes) -> float:
    """The same measure over every ordinary pair of neighbours inside the image."""
    return float(np.concatenate([pair_errors(image, a, wrap=False) for a in WRAPS[axes]]).mean())


def natural(t: Tiled, axis: int, wrap: bool) -> NDArray[np.bool_]:
    """Whether each pair of output neighbours along ``axis`` is a pair of input neighbours.

    Sources must be one step apart along the same axis inside the input (not across its own
    wrap), so a natural pair is exactly as smooth as the input is there.
    """
    along, across = (t.source_cols, t.source_rows) if axis == 1 else (t.source_rows, t.source_cols)
    along_a, along_b = neighbours(along, axis, wrap)
    across_a, across_b = neighbours(across, axis, wrap)
    same_line = across_a == across_b
    next_one = along_b == along_a + 1
    result: NDArray[np.bool_] = same_line & next_one
    return result


def seam_pair_error(t: Tiled) -> float:
    """Mean squared difference across the cuts: inner neighbour pairs that are not natural."""
    errors = [pair_errors(t.image, a, wrap=False)[~natural(t, a, False).ravel()] for a in (0, 1)]
    return float(np.concatenate(errors).mean())


def smooth_image(shape: tuple[int, int, int], seed: int) -> NDArray[np.float32]:
    """Blurred noise plus a ramp: smooth inside, a clear jump across its own wraps."""
    rng = np.random.default_rng(seed)
    noise = ndimage.gaussian_filter(rng.random(shape), sigma=(3, 3, 0))
    ramp = np.add.outer(np.linspace(0, 0.5, shape[0]), np.linspace(0, 0.5, shape[1]))
    image: NDArray[np.float32] = (noise + ramp[..., None]).astype(np.float32)
    return image


def paths(length: int, width: int) -> list[tuple[int, ...]]:
    """Every 8-connected sequence of ``length`` positions in ``0 .. width - 1``."""
    return [
        p
        for p in itertools.product(range(width), repeat=length)
        if all(abs(a - b) <= 1 for a, b in itertools.pairwise(p))
    ]


def _channels(image: Image) -> Image:
    return image[..., None] if image.ndim == 2 else image


@pytest.fixture(scope="module", params=["gravel", "brick", "wood"])
def texture(request: pytest.FixtureRequest) -> Image:
    return _channels(request.getfixturevalue(request.param))


@pytest.fixture(scope="module", params=["gravel", "wood"])
def stochastic(request: pytest.FixtureRequest) -> Image:
    """Textures without a dominant straight edge, where one line is like any other."""
    return _channels(request.getfixturevalue(request.param))


# --- formats ----------------------------------------------------------------------------------


@pytest.mark.parametrize("channels", [1, 3, 4])
@pytest.mark.parametrize("dtype", ["uint8", "uint16", "float32"])
def test_same_size_dtype_and_every_pixel_an_input_pixel(channels: int, dtype: str) -> None:
    rng = np.random.default_rng(channels)
    info = np.iinfo(dtype) if dtype != "float32" else None
    top = 1 if info is None else info.max
    image = (rng.random((37, 42, channels)) * top).astype(dtype)
    t = make_tileable(image, blend="none")
    assert t.image.shape == image.shape
    assert t.image.dtype == image.dtype
    np.testing.assert_array_equal(t.image, image[t.source_rows, t.source_cols])
    assert t.kept.shape == t.source_rows.shape == t.source_cols.shape == image.shape[:2]
    again = make_tileable(image, blend="none")
    np.testing.assert_array_equal(again.image, t.image)
    assert again.seam_error == t.seam_error


def test_two_dimensional_gray_keeps_its_shape(gravel: Image) -> None:
    t = make_tileable(gravel[:40, :50], blend="none")
    assert t.image.shape == (40, 50)


# --- seamless ---------------------------------------------------------------------------------


@pytest.mark.parametrize("axes", AXES)
def test_wrap_pairs_are_natural_neighbours(texture: Image, axes: Axes) -> None:
    # The exact form of "the join is as smooth as the image itself": every pair across a tiled
    # wrap is a pair of neighbouring input pixels. In "both" the y wrap shows rows of the first
    # pass's result, where each of its two cuts can step sideways once: two pairs at most.
    t = make_tileable(texture, axes=axes, blend="none")
    for axis in WRAPS[axes]:
        broken = int(np.count_nonzero(~natural(t, axis, wrap=True)))
        assert broken <= (2 if axes == "both" and axis == 0 else 0)


@pytest.mark.parametrize("band", [None, 1, 999])
@pytest.mark.parametrize("axes", AXES)
def test_input_border_never_shows(texture: Image, axes: Axes, band: int | None) -> None:
    # Every pixel is a shifted copy of the input: shift 0 in the kept centre, half the size in
    # the frame. Two neighbours with the same shift whose sources are not neighbours show the
    # input's own border (its last column next to its first): S's middle seam left uncovered,
    # or an untileable wrap. Whatever the band, that never happens, inside or across a tiled
    # wrap; every seam is a cut between two differently shifted copies.
    height, width = texture.shape[:2]
    # 999: the widest band allowed.
    chosen = band if band is None else min(band, band_limit(height), band_limit(width))
    t = make_tileable(texture, axes=axes, band=chosen, blend="none")
    y, x = np.mgrid[:height, :width]
    shift = ((t.source_rows - y) % height) * width + (t.source_cols - x) % width
    for axis in (0, 1):
        pairs = [False, True] if axis in WRAPS[axes] else [False]
        for wrap in pairs:
            a, b = neighbours(shift, axis, wrap)
            exposed = (a == b) & ~natural(t, axis, wrap)
            assert not exposed.any()


@pytest.mark.parametrize("axes", ["x", "y"])
def test_single_axis_border_is_s(texture: Image, axes: Axes) -> None:
    t = make_tileable(texture, axes=axes, blend="none")
    s = rolled(texture, axes)
    axis = WRAPS[axes][0]
    for index in (0, -1):
        np.testing.assert_array_equal(np.take(t.image, index, axis), np.take(s, index, axis))
    assert join_error(t.image, axes) == join_error(s, axes)


def test_both_corners_are_s_and_border_never_kept(texture: Image) -> None:
    t = make_tileable(texture, blend="none")
    s = rolled(texture, "both")
    for y, x in itertools.product((0, -1), repeat=2):
        np.testing.assert_array_equal(t.image[y, x], s[y, x])
    assert not t.kept[[0, -1], :].any()
    assert not t.kept[:, [0, -1]].any()


@pytest.mark.parametrize("axes", AXES)
def test_join_error_as_small_as_the_inside(stochastic: Image, axes: Axes) -> None:
    t = make_tileable(stochastic, axes=axes, blend="none")
    inside = interior_error(stochastic, axes)
    before, after = join_error(stochastic, axes), join_error(t.image, axes)
    # The join is one line of natural neighbours against the image's average: a small factor.
    assert after <= 1.5 * inside
    # Neither texture tiles as it is: an identity function fails both of these.
    assert before >= 2.5 * after
    assert before >= 2.5 * inside


def test_brick_join_is_an_ordinary_line(brick: Image) -> None:
    # Brick's natural line at the wrap (columns 127 | 128) runs along a mortar edge, rougher
    # than 97 % of its lines (and brick nearly tiles along x already), but no rougher than the
    # roughest line of the texture itself.
    image = brick[..., None]
    t = make_tileable(image, blend="none")
    for axis in (0, 1):
        lines = pair_errors(image, axis, wrap=False).reshape(
            np.moveaxis(image, axis, 0)[1:].shape[:2]
        )
        assert pair_errors(t.image, axis, wrap=True).mean() <= lines.mean(axis=1).max()


def test_wrap_seam_no_larger_than_inner_seams(texture: Image) -> None:
    # "The seam error across the wrap boundary (tile it 2x2 and measure the error on the joins)
    # is no larger than the seams inside (same measure)." The joins are natural neighbours, the
    # cuts natural neighbours plus the cut error, so the two agree up to the noise of measuring
    # one line: gravel 0.0149 against 0.0147, brick 0.0090 (a mortar edge) against 0.0081.
    # An identity function is 2.3x (brick) to 8x (wood) over.
    t = make_tileable(texture, blend="none")
    assert join_error(t.image, "both") <= 1.25 * seam_pair_error(t)
    assert join_error(texture, "both") >= 2 * seam_pair_error(t)


@pytest.mark.parametrize("axes", ["x", "y"])
@pytest.mark.parametrize("seed", range(3))
def test_smooth_synthetic_image_tiles(seed: int, axes: Axes) -> None:
    # Single axes only: in "both" the y wrap crosses the first pass's two cuts, and on a smooth
    # ramp those two pairs alone outweigh the rest of the line (test_wrap_pairs_are_natural...).
    image = smooth_image((60, 80, 3), seed)
    t = make_tileable(image, axes=axes, blend="none")
    inside = interior_error(image, axes)
    assert join_error(image, axes) > 10 * inside
    assert join_error(t.image, axes) <= 2 * inside


def test_second_pass_cuts_close_across_the_x_wrap(texture: Image) -> None:
    t = make_tileable(texture, blend="none")
    np.testing.assert_array_equal(t.seam_rows[:, 0], t.seam_rows[:, -1])


# --- centre kept, cuts --------------------------------------------------------------------------


@pytest.mark.parametrize("axes", AXES)
def test_centre_kept(texture: Image, axes: Axes) -> None:
    t = make_tileable(texture, axes=axes, blend="none")
    height, width = texture.shape[:2]
    rows = slice(height // 4, height - height // 4) if axes != "x" else slice(None)
    cols = slice(width // 4, width - width // 4) if axes != "y" else slice(None)
    np.testing.assert_array_equal(t.image[rows, cols], texture[rows, cols])
    assert t.kept[rows, cols].all()
    # Cuts stay within a quarter of each side: at least half of each tiled side is kept, so at
    # least a quarter of the image in "both"; measured there: gravel 0.488, brick 0.552,
    # wood 0.510 (the output is deterministic, so these bounds are not flaky).
    assert t.kept.mean() >= (0.45 if axes == "both" else 0.5)


@pytest.mark.parametrize("axes", AXES)
def test_kept_is_between_the_cuts(texture: Image, axes: Axes) -> None:
    t = make_tileable(texture, axes=axes, blend="none")
    height, width = t.kept.shape
    y, x = np.mgrid[:height, :width]
    between = (t.seam_cols[0][:, None] <= x) & (x <= t.seam_cols[1][:, None])
    between &= (t.seam_rows[0][None, :] <= y) & (y <= t.seam_rows[1][None, :])
    np.testing.assert_array_equal(t.kept, between)
    np.testing.assert_array_equal(t.kept, (t.source_rows == y) & (t.source_cols == x))


@pytest.mark.parametrize("axes", ["x", "y"])
def test_single_axis_moves_pixels_only_along_it(texture: Image, axes: Axes) -> None:
    t = make_tileable(texture, axes=axes, blend="none")
    height, width = t.kept.shape
    y, x = np.mgrid[:height, :width]
    np.testing.assert_array_equal(
        t.source_rows if axes == "x" else t.source_cols, y if axes == "x" else x
    )
    untiled = t.seam_rows if axes == "x" else t.seam_cols
    assert (untiled[0] == 0).all() and (untiled[1] == (height if axes == "x" else width) - 1).all()


@pytest.mark.parametrize("band", [None, 1, 5, 20])
@pytest.mark.parametrize("axes", AXES)
def test_cuts_connected_and_in_their_bands(axes: Axes, band: int | None) -> None:
    image = smooth_image((48, 44, 3), seed=band or 0)
    t = make_tileable(image, axes=axes, band=band, blend="none")
    for cuts, side in ((t.seam_cols, 44), (t.seam_rows, 48)):
        if (cuts is t.seam_cols) == (axes == "y"):
            continue
        width = max(1, side // 4) if band is None else band
        assert ((cuts[0] >= 1) & (cuts[0] <= width)).all()
        assert ((cuts[1] >= side - 1 - width) & (cuts[1] <= side - 2)).all()
        assert (np.abs(np.diff(cuts, axis=1)) <= 1).all()


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize(("height", "width", "band"), [(6, 8, 3), (3, 12, 5)])
def test_cut_is_the_cheapest_path_brute_force(
    seed: int, height: int, width: int, band: int
) -> None:
    # (3, 12, 5): the band is wider than the strip is tall, the zero-padded DP case.
    rng = np.random.default_rng(seed)
    image = rng.integers(0, 256, (height, width, 3), dtype=np.uint8)
    t = make_tileable(image, axes="x", band=band, blend="none")
    error = np.square(working(image) - working(rolled(image, "x"))).sum(axis=2)
    rows = np.arange(height)
    left = error[:, 1 : band + 1]
    right = error[:, width - 2 : width - 2 - band : -1]
    best_left = min(float(left[rows, list(p)].sum()) for p in paths(height, band))
    best_right = min(float(right[rows, list(p)].sum()) for p in paths(height, band))
    cost_left = float(error[rows, t.seam_cols[0]].sum())
    cost_right = float(error[rows, t.seam_cols[1]].sum())
    assert cost_left == pytest.approx(best_left, rel=1e-12, abs=1e-15)
    assert cost_right == pytest.approx(best_right, rel=1e-12, abs=1e-15)
    assert t.seam_error == pytest.approx((cost_left + cost_right) / (2 * height), rel=1e-12)


def test_wide_short_strip_keeps_its_band() -> None:
    # The default band (512 // 4 = 128) is wider than the strip is tall: still fine.
    image = smooth_image((64, 512, 3), seed=4)
    t = make_tileable(image, axes="x", blend="none")
    assert t.seam_cols[0].max() <= 128
    assert natural(t, 1, wrap=True).all()
    assert join_error(t.image, "x") <= 2 * interior_error(image, "x")


# --- bad inputs -------------------------------------------------------------------------------


@pytest.mark.parametrize("band", [0, -1, 20, 100, True, 2.5])
def test_bad_band(band: object) -> None:
    with pytest.raises(InvalidParameterError, match="band") as info:
        make_tileable(np.zeros((40, 60, 3), np.uint8), band=band, blend="none")  # type: ignore[arg-type]
    assert info.value.parameter == "band"


def test_band_limit_is_allowed() -> None:
    # 40 // 2 - 1 = 19: the left band's columns 1..19 end just before the middle seam's
    # columns 19 | 20 ... and the bound is the smaller tiled side's.
    assert band_limit(40) == 19
    image = smooth_image((40, 60, 3), seed=1)
    assert make_tileable(image, band=19, blend="none").kept.any()
    assert make_tileable(image, axes="x", band=29, blend="none").kept.any()
    with pytest.raises(InvalidParameterError, match=r"1\.\.29"):
        make_tileable(image, axes="x", band=30, blend="none")


@pytest.mark.parametrize(
    ("shape", "axes", "word"), [((3, 10, 3), "both", "height"), ((10, 3, 1), "x", "width")]
)
def test_too_small_image(shape: tuple[int, int, int], axes: Axes, word: str) -> None:
    with pytest.raises(InvalidImageError, match=word):
        make_tileable(np.zeros(shape, np.uint8), axes=axes, blend="none")


def test_small_untiled_side_is_fine() -> None:
    t = make_tileable(smooth_image((1, 8, 3), seed=0), axes="x", blend="none")
    assert t.image.shape == (1, 8, 3)


@pytest.mark.parametrize("axes", ["xy", "z", "", None])
def test_bad_axes(axes: object) -> None:
    with pytest.raises(InvalidParameterError, match="axes") as info:
        make_tileable(np.zeros((8, 8, 3), np.uint8), axes=axes, blend="none")  # type: ignore[arg-type]
    assert info.value.parameter == "axes"


def test_public_make_tileable_validates_its_options() -> None:
    import quilting

    image = np.zeros((32, 32, 3), dtype=np.uint8)
    with pytest.raises(InvalidParameterError) as info:
        quilting.make_tileable(image, axes="z", blend="none")  # type: ignore[arg-type]
    assert info.value.parameter == "axes"
    with pytest.raises(InvalidParameterError) as info:
        quilting.make_tileable(image, band=True, blend="none")  # type: ignore[arg-type]
    assert info.value.parameter == "band"
    gray = np.arange(32 * 40, dtype=np.uint16).reshape(32, 40)
    tiled = quilting.make_tileable(gray, axes="y", blend="none")
    assert tiled.image.shape == gray.shape and tiled.image.dtype == np.uint16


@pytest.mark.parametrize("axes", AXES)
def test_the_banded_error_changes_no_output(axes: Axes, monkeypatch: pytest.MonkeyPatch) -> None:
    """The error is gathered a band of rows at a time: any band gives the same bytes as the
    whole image at once (one band)."""
    from quilting.core import seamless

    rng = np.random.default_rng(5)
    image = rng.integers(0, 65536, (61, 87, 3), dtype=np.uint16)
    monkeypatch.setattr(seamless, "BAND_PIXELS", 1 << 30)
    whole = make_tileable(image, axes=axes, blend="none")
    for pixels in (1, 87 * 3 + 5, 1000):
        monkeypatch.setattr(seamless, "BAND_PIXELS", pixels)
        banded = make_tileable(image, axes=axes, blend="none")
        assert banded.seam_error == whole.seam_error
        for name in ("image", "kept", "seam_cols", "seam_rows", "source_rows", "source_cols"):
            assert np.array_equal(getattr(banded, name), getattr(whole, name)), (pixels, name)
