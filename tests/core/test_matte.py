"""The texture-matting job, :mod:`quilting.core.matte`, driven directly.

Covers
------
- ``matte_inputs`` / ``MatteInputs``: the target, layers, silhouette and normal map checked
  against each other (sizes that disagree, channel counts, empty silhouettes, layers that
  refuse the block or the mode), refused with the project's errors naming the input, and good
  inputs returned with their documented shapes, dtypes and layer size.
- ``estimate_matte``: the layers' memory is the largest layer's plus the target's maps
  (``MATTE_BYTES_PER_PIXEL``), their times add up, the estimate grows with the layer size and
  the layers, and a budget too small raises ``JobTooLargeError`` before any quilting.
- ``matte_quilt``: the image's shape and dtype for gray, RGB and RGBA targets and layers of
  several dtypes; the target kept where the silhouette does not reach; each layer quilted at
  the layer size with its own seed; bytes that depend on the seed only (not the batch); the
  progress callback's stages and fractions, and stopping by raising from it.
- The private helpers: ``_cover``, ``_normal_map``, ``_as_rgba``, ``_restore``,
  ``_layer_options``, ``_layer_progress`` and ``_layer_views``.

tests/core/test_matting.py checks the surface, the compositing arithmetic and the errors as
seen through :func:`quilting.matte`; these tests do not repeat it.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from textures import texture

import quilting
from quilting.core import matte as job
from quilting.core.budget import BOUND_MARGIN, MATTE_BYTES_PER_PIXEL, Budget, JobTooLargeError
from quilting.core.errors import InvalidImageError, InvalidParameterError
from quilting.core.matte import (
    MatteInputs,
    _as_rgba,
    _cover,
    _layer_options,
    _layer_progress,
    _layer_views,
    _normal_map,
    _restore,
    estimate_matte,
    matte_inputs,
    matte_quilt,
)
from quilting.core.options import MatteOptions, SynthesisOptions
from quilting.core.pixels import as_channels, to_working
from quilting.core.synthesis import quilt
from quilting.costs.fft import FFTBackend

SIZE = 48
#: A 24 x 32 white rectangle (rows 12..35, cols 8..39) on black: cover 1 inside, 0 outside.
BOX = np.zeros((SIZE, SIZE), dtype=np.uint8)
BOX[12:36, 8:40] = 255
INSIDE = BOX > 0
BLOCK = 8
OPTIONS = MatteOptions(block=BLOCK, seed=3)


def noise(shape: tuple[int, ...], dtype: Any, seed: int = 0) -> NDArray[Any]:
    """Uniform noise over the whole range of ``dtype`` ([0, 1) for floats)."""
    rng = np.random.default_rng(seed)
    if np.dtype(dtype).kind == "f":
        return rng.random(shape).astype(dtype)
    top = int(np.iinfo(dtype).max)
    return rng.integers(0, top + 1, shape).astype(dtype)


def brick() -> NDArray[Any]:
    """32 x 32 gray brick."""
    return np.ascontiguousarray(texture("brick")[:32, :32])


def wood() -> NDArray[Any]:
    """32 x 32 RGB wood."""
    return np.ascontiguousarray(texture("wood")[:32, :32])


def cloud() -> NDArray[Any]:
    """32 x 32 RGBA cloud."""
    return np.ascontiguousarray(texture("cloud_rgba")[:32, :32])


def run(
    target: NDArray[Any],
    layers: list[NDArray[Any]],
    options: MatteOptions = OPTIONS,
    silhouette: NDArray[Any] = BOX,
    **kwargs: Any,
) -> Any:
    inputs = matte_inputs(options, target, layers, silhouette, None)
    return matte_quilt(inputs, options, FFTBackend(), **kwargs)


# --------------------------------------------------------------------------------------------
# 1. matte_inputs: inputs checked against each other
# --------------------------------------------------------------------------------------------


def test_good_inputs_come_back_as_the_engine_takes_them() -> None:
    target = noise((SIZE, SIZE), np.uint16)
    silhouette = np.zeros((SIZE, SIZE, 3), dtype=np.uint8)
    silhouette[12:36, 8:40] = 255
    silhouette[10, 20] = 64  # a quarter covered: below half, yet part of the extent
    normals = np.zeros((SIZE, SIZE, 3), dtype=np.float32)
    normals[..., 2] = 2.0
    inputs = matte_inputs(OPTIONS, target, [brick(), cloud()], silhouette, normals)
    assert isinstance(inputs, MatteInputs)
    assert inputs.target.shape == (SIZE, SIZE, 1)
    assert inputs.target.dtype == np.uint16
    assert inputs.target_format.two_dimensional
    assert inputs.target_format.channels == 1
    assert [view.shape for view, _ in inputs.layers] == [(32, 32, 1), (32, 32, 4)]
    assert [fmt.channels for _, fmt in inputs.layers] == [1, 4]
    assert inputs.cover.dtype == np.float32
    assert inputs.cover.shape == (SIZE, SIZE)
    expected = np.zeros((SIZE, SIZE), dtype=np.float32)
    expected[12:36, 8:40] = 1.0
    expected[10, 20] = 64 / 255
    np.testing.assert_allclose(inputs.cover, expected, atol=1e-7)
    assert inputs.normals is not None
    assert inputs.normals.shape == (SIZE, SIZE, 3)
    assert inputs.normals.dtype == np.float32
    np.testing.assert_allclose(inputs.normals, np.broadcast_to([0.0, 0.0, 1.0], (SIZE, SIZE, 3)))
    # The extent counts every covered pixel: rows 10..35 (26), cols 8..39 (32).
    assert inputs.layer_size == (26, 32)


def test_without_normals_none_are_given() -> None:
    inputs = matte_inputs(OPTIONS, noise((SIZE, SIZE, 3), np.uint8), [brick()], BOX, None)
    assert inputs.normals is None
    assert inputs.target_format.channels == 3
    assert not inputs.target_format.two_dimensional


@pytest.mark.parametrize(
    ("scale", "block", "expected"),
    [
        (1.0, 8, (24, 32)),
        (2.5, 8, (10, 13)),  # ceil(24 / 2.5), ceil(32 / 2.5)
        (2.5, 12, (12, 13)),  # at least the block
        (4.0, 16, (16, 16)),
    ],
)
def test_layer_size_is_the_extent_over_scale_at_least_the_block(
    scale: float, block: int, expected: tuple[int, int]
) -> None:
    options = MatteOptions(block=block, scale=scale)
    inputs = matte_inputs(options, noise((SIZE, SIZE), np.uint8), [brick()], BOX, None)
    assert inputs.layer_size == expected


def _refusal(change: dict[str, Any]) -> None:
    given: dict[str, Any] = {
        "options": OPTIONS,
        "target": noise((SIZE, SIZE, 3), np.uint8),
        "layers": [brick(), wood()],
        "silhouette": BOX,
        "normals": None,
    }
    given.update(change)
    matte_inputs(
        given["options"], given["target"], given["layers"], given["silhouette"], given["normals"]
    )


@pytest.mark.parametrize(
    ("change", "named", "message"),
    [
        # Sizes are reported width x height: the 48 x 40 silhouette is 40 rows high.
        (
            {"silhouette": BOX[:40]},
            "silhouette",
            "silhouette is 48x40; it must be the target's size, 48x48",
        ),
        ({"silhouette": BOX[:, :30]}, "silhouette", "silhouette is 30x48"),
        ({"silhouette": np.zeros_like(BOX)}, "silhouette", "no pixel at least half white"),
        # 127/255 is just under half: nothing is inside.
        ({"silhouette": np.where(INSIDE, 127, 0).astype(np.uint8)}, "silhouette", "half"),
        (
            {"normals": np.zeros((SIZE, 20, 3), dtype=np.uint8)},
            "normals",
            "normals is 20x48; it must be the target's size, 48x48",
        ),
        ({"normals": np.zeros((SIZE, SIZE), dtype=np.uint8)}, "normals", "normals has 1 channel"),
    ],
    ids=["short-silhouette", "narrow-silhouette", "black", "under-half", "narrow-normals", "gray"],
)
def test_silhouette_and_normals_must_match_the_target(
    change: dict[str, Any], named: str, message: str
) -> None:
    with pytest.raises(InvalidImageError) as raised:
        _refusal(change)
    assert raised.value.parameter == named
    assert message in str(raised.value)


@pytest.mark.parametrize(
    ("change", "error", "words"),
    [
        (
            {"silhouette": np.zeros((SIZE, SIZE, 2), np.uint8)},
            InvalidImageError,
            ["silhouette", "2 channels"],
        ),
        ({"target": [[0, 1], [1, 0]]}, InvalidImageError, ["target", "numpy array"]),
        (
            {"target": np.full((SIZE, SIZE), np.nan, dtype=np.float32)},
            InvalidImageError,
            ["target", "NaN"],
        ),
        (
            {"layers": [brick(), np.zeros((32, 32, 2), np.uint8)]},
            InvalidImageError,
            ["layers[1]", "2 channels"],
        ),
        (
            {"layers": [brick(), np.zeros((32, 6), np.uint8)]},
            InvalidParameterError,
            ["block=8", "3..6", "layers[1]"],
        ),
        (
            {"options": MatteOptions(block=BLOCK, mode="alpha"), "layers": [cloud(), wood()]},
            InvalidParameterError,
            ["mode", "layers[1] has 3 channels"],
        ),
        ({"layers": []}, InvalidParameterError, ["layers", "one or more images"]),
        ({"layers": 7}, InvalidParameterError, ["layers", "one or more images"]),
        ({"layers": brick()}, InvalidParameterError, ["layers", "one or more images"]),
    ],
    ids=[
        "la-silhouette",
        "list",
        "nan",
        "la-layer",
        "narrow-layer",
        "alpha",
        "none",
        "int",
        "array",
    ],
)
def test_bad_inputs_are_refused_by_name(
    change: dict[str, Any], error: type[Exception], words: list[str]
) -> None:
    with pytest.raises(error) as raised:
        _refusal(change)
    for word in words:
        assert word in str(raised.value)


def test_layer_views_keep_order_and_formats() -> None:
    layers = [wood(), brick().astype(np.float32) / 255, cloud()]
    views = _layer_views(layers, OPTIONS)
    assert [view.shape[2] for view, _ in views] == [3, 1, 4]
    assert [fmt.dtype for _, fmt in views] == [np.uint8, np.float32, np.uint8]
    for (view, _), layer in zip(views, layers, strict=True):
        np.testing.assert_array_equal(view.reshape(layer.shape), layer)
    # A tuple is a sequence too.
    assert len(_layer_views(tuple(layers), OPTIONS)) == 3


# --------------------------------------------------------------------------------------------
# 2. estimate_matte
# --------------------------------------------------------------------------------------------

GRAY = ((32, 32), 1)
RGBA = ((32, 32, 4), 1)


def test_target_maps_add_their_bytes_per_pixel() -> None:
    small = estimate_matte(OPTIONS, (64, 64), [GRAY], (32, 32))
    large = estimate_matte(OPTIONS, (128, 96), [GRAY], (32, 32))
    kept = MATTE_BYTES_PER_PIXEL * (128 * 96 - 64 * 64)
    assert large.peak_bytes - small.peak_bytes == kept
    # The bound carries the model's margin on it.
    assert abs((large.bound_bytes - small.bound_bytes) - BOUND_MARGIN * kept) <= 2
    # The target does not change the quilting itself.
    assert large.seconds == small.seconds
    assert large.work == small.work


def test_layers_add_their_times_not_their_memory() -> None:
    one = estimate_matte(OPTIONS, (64, 64), [GRAY], (40, 40))
    two = estimate_matte(OPTIONS, (64, 64), [GRAY, GRAY], (40, 40))
    assert two.seconds == pytest.approx(2 * one.seconds, rel=1e-12)
    assert two.work == pytest.approx(2 * one.work, rel=1e-12)
    assert two.peak_bytes == one.peak_bytes
    assert two.bound_bytes == one.bound_bytes
    # Layers of different shapes: the memory of the largest, the time of all.
    rgba = estimate_matte(OPTIONS, (64, 64), [RGBA], (40, 40))
    both = estimate_matte(OPTIONS, (64, 64), [GRAY, RGBA], (40, 40))
    assert rgba.peak_bytes > one.peak_bytes
    assert both.peak_bytes == max(one.peak_bytes, rgba.peak_bytes)
    assert both.bound_bytes == max(one.bound_bytes, rgba.bound_bytes)
    assert both.seconds == pytest.approx(one.seconds + rgba.seconds, rel=1e-12)
    assert both.batch == min(one.batch, rgba.batch)


def test_estimate_grows_with_the_layer_size_and_channels() -> None:
    base = estimate_matte(OPTIONS, (96, 96), [GRAY], (32, 32))
    larger = estimate_matte(OPTIONS, (96, 96), [GRAY], (96, 96))
    assert larger.seconds > base.seconds
    assert larger.peak_bytes > base.peak_bytes
    assert larger.work > base.work
    rgb = estimate_matte(OPTIONS, (96, 96), [((32, 32, 3), 1)], (32, 32))
    assert rgb.work > base.work
    assert estimate_matte(OPTIONS, (96, 96), [GRAY], (32, 32), max_batch=3).batch == 3


def test_seconds_budget_counts_every_layer() -> None:
    one = estimate_matte(OPTIONS, (64, 64), [GRAY], (48, 48))
    budget = Budget(seconds=1.5 * one.seconds)
    assert estimate_matte(OPTIONS, (64, 64), [GRAY], (48, 48), budget=budget) == one
    # Each layer alone fits; the two, one after the other, do not.
    with pytest.raises(JobTooLargeError, match="fewer or smaller layers"):
        estimate_matte(OPTIONS, (64, 64), [GRAY, GRAY], (48, 48), budget=budget)


def test_memory_budget_is_met_by_each_layer_not_their_sum() -> None:
    one = estimate_matte(OPTIONS, (64, 64), [GRAY], (48, 48))
    budget = Budget(memory_bytes=one.bound_bytes + (1 << 20))
    found = estimate_matte(OPTIONS, (64, 64), [GRAY, GRAY, GRAY], (48, 48), budget=budget)
    assert found.bound_bytes <= one.bound_bytes + (1 << 20)
    assert found.seconds == pytest.approx(3 * one.seconds, rel=1e-12)


def test_matte_over_budget_is_refused_before_any_work(monkeypatch: pytest.MonkeyPatch) -> None:
    import quilting.api as api

    def never(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("the job started")

    monkeypatch.setattr(api, "matte_quilt", never)
    reports: list[tuple[float, str]] = []
    with pytest.raises(JobTooLargeError, match="would take about"):
        quilting.matte(
            noise((SIZE, SIZE, 3), np.uint8),
            [brick(), cloud()],
            silhouette=BOX,
            block=BLOCK,
            backend="fft",
            budget=Budget(seconds=1e-9),
            progress=lambda fraction, stage: reports.append((fraction, stage)),
        )
    assert reports == []


# --------------------------------------------------------------------------------------------
# 3. matte_quilt: the image
# --------------------------------------------------------------------------------------------


def _layer(kind: str, dtype: Any) -> NDArray[Any]:
    source = {"gray": brick, "rgb": wood, "rgba": cloud}[kind]()
    if dtype == np.uint8:
        return source
    if dtype == np.uint16:
        return source.astype(np.uint16) * 257
    return (source / 255).astype(dtype)


@pytest.mark.parametrize(
    ("target_shape", "dtype", "layers", "expected"),
    [
        ((SIZE, SIZE), np.uint8, [("gray", np.uint8)], (SIZE, SIZE)),
        ((SIZE, SIZE), np.uint16, [("rgb", np.uint8)], (SIZE, SIZE, 3)),
        ((SIZE, SIZE, 1), np.float32, [("gray", np.uint16)], (SIZE, SIZE, 1)),
        ((SIZE, SIZE, 1), np.uint8, [("rgba", np.uint8)], (SIZE, SIZE, 3)),
        ((SIZE, SIZE, 3), np.uint16, [("gray", np.float32)], (SIZE, SIZE, 3)),
        ((SIZE, SIZE, 4), np.float32, [("gray", np.uint8), ("rgba", np.uint8)], (SIZE, SIZE, 4)),
        ((SIZE, SIZE, 4), np.uint8, [("rgb", np.uint16)], (SIZE, SIZE, 4)),
    ],
)
def test_image_has_the_target_size_and_dtype_and_keeps_it_outside(
    target_shape: tuple[int, ...],
    dtype: Any,
    layers: list[tuple[str, Any]],
    expected: tuple[int, ...],
) -> None:
    target = noise(target_shape, dtype, seed=len(target_shape))
    result = run(target, [_layer(kind, layer_dtype) for kind, layer_dtype in layers])
    image = result.image
    assert image.shape == expected
    assert image.dtype == target.dtype
    # Where the silhouette covers nothing the target is kept exactly, spread to RGB when a
    # layer brought colour to a gray target; inside, the layers changed it.
    as_3d = image.reshape(SIZE, SIZE, -1)
    kept = np.broadcast_to(target.reshape(SIZE, SIZE, -1), as_3d.shape)
    np.testing.assert_array_equal(as_3d[~INSIDE], kept[~INSIDE])
    assert not np.array_equal(as_3d[INSIDE], kept[INSIDE])


@pytest.mark.parametrize(
    ("target_shape", "dtype", "layers"),
    [
        ((SIZE, SIZE, 3), np.float64, [("rgb", np.uint8)]),
        ((SIZE, SIZE), np.float64, [("rgb", np.uint8)]),
        ((SIZE, SIZE, 4), np.float16, [("gray", np.uint8)]),
    ],
)
def test_float_target_outside_its_silhouette_keeps_its_own_values(
    target_shape: tuple[int, ...], dtype: Any, layers: list[tuple[str, Any]]
) -> None:
    # Values past [0, 1] and float64 digits are the caller's: only laid pixels are computed.
    target = (noise(target_shape, np.float64, seed=5) * 3 - 1).astype(dtype)
    image = run(target, [_layer(kind, layer_dtype) for kind, layer_dtype in layers]).image
    assert image.dtype == target.dtype
    as_3d = image.reshape(SIZE, SIZE, -1)
    kept = np.broadcast_to(target.reshape(SIZE, SIZE, -1), as_3d.shape)
    np.testing.assert_array_equal(as_3d[~INSIDE], kept[~INSIDE])
    # Inside, the laid pixels are computed and rendered in [0, 1].
    assert float(as_3d[INSIDE].min()) >= 0 and float(as_3d[INSIDE].max()) <= 1


def test_result_maps_follow_the_silhouette() -> None:
    silhouette = BOX.copy()
    silhouette[36:38, 8:40] = 64  # a partly covered rim under the box, not read but drawn
    target = noise((SIZE, SIZE, 3), np.uint8, seed=9)
    result = run(target, [wood()], silhouette=silhouette)
    drawn = silhouette > 0
    assert result.normals.shape == (SIZE, SIZE, 3)
    assert result.normals.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(result.normals, axis=-1), 1.0, atol=1e-5)
    np.testing.assert_array_equal(result.normals[~drawn], [[0.0, 0.0, 1.0]] * int((~drawn).sum()))
    for labels in (result.clusters, result.patches):
        assert labels.dtype == np.int32
        np.testing.assert_array_equal(labels >= 0, drawn)
    assert abs(float(np.linalg.norm(result.light)) - 1.0) < 1e-9
    np.testing.assert_array_equal(result.image[~drawn], target[~drawn])
    assert not np.array_equal(result.image[36:38, 8:40], target[36:38, 8:40])
    assert set(result.timings) == {"layers", "surface", "lay", "total"}
    assert all(value >= 0.0 for value in result.timings.values())
    parts = result.timings["layers"] + result.timings["surface"] + result.timings["lay"]
    assert result.timings["total"] == pytest.approx(parts, rel=1e-9, abs=1e-12)


@pytest.fixture(scope="module")
def two_bricks() -> Any:
    """One gray brick given twice as the two layers, seed 3."""
    return run(noise((SIZE, SIZE, 3), np.uint8, seed=4), [brick(), brick()])


def test_each_layer_is_quilted_at_the_layer_size_with_its_own_seed(two_bricks: Any) -> None:
    inputs = matte_inputs(OPTIONS, noise((SIZE, SIZE, 3), np.uint8), [brick(), brick()], BOX, None)
    assert len(two_bricks.layers) == 2
    for index, layer in enumerate(two_bricks.layers):
        assert layer.image.shape == inputs.layer_size == (24, 32)
        assert layer.image.dtype == np.uint8
        view, fmt = inputs.layers[index]
        alone = quilt(view, fmt, inputs.layer_size, _layer_options(OPTIONS, index), FFTBackend())
        assert layer.image.tobytes() == alone.image.tobytes()
    # The same texture twice is not the same layer twice.
    assert not np.array_equal(two_bricks.layers[0].image, two_bricks.layers[1].image)


def test_same_seed_same_bytes_whatever_the_batch(two_bricks: Any) -> None:
    target = noise((SIZE, SIZE, 3), np.uint8, seed=4)
    again = run(target, [brick(), brick()], max_batch=1)
    assert again.image.tobytes() == two_bricks.image.tobytes()
    for first, second in zip(two_bricks.layers, again.layers, strict=True):
        assert first.image.tobytes() == second.image.tobytes()
    assert again.clusters.tobytes() == two_bricks.clusters.tobytes()
    other = run(target, [brick(), brick()], options=MatteOptions(block=BLOCK, seed=4))
    assert not np.array_equal(other.image[INSIDE], two_bricks.image[INSIDE])
    assert not np.array_equal(other.layers[0].image, two_bricks.layers[0].image)
    np.testing.assert_array_equal(other.image[~INSIDE], two_bricks.image[~INSIDE])


# --------------------------------------------------------------------------------------------
# 4. matte_quilt: progress
# --------------------------------------------------------------------------------------------


def test_progress_walks_the_layers_then_the_surface() -> None:
    reports: list[tuple[float, str]] = []
    run(
        noise((SIZE, SIZE), np.uint8),
        [brick(), wood(), cloud()],
        progress=lambda fraction, stage: reports.append((fraction, stage)),
    )
    fractions = [fraction for fraction, _ in reports]
    assert fractions == sorted(fractions)
    assert reports[-1] == (0.9, "surface")
    assert [stage for _, stage in reports].count("surface") == 1
    stages = [stage for _, stage in reports[:-1]]
    assert sorted(set(stages)) == ["layer 1/3", "layer 2/3", "layer 3/3"]
    for k in (1, 2, 3):
        share = [fraction for fraction, stage in reports if stage == f"layer {k}/3"]
        low, high = 0.9 * (k - 1) / 3, 0.9 * k / 3
        assert all(low < fraction <= high + 1e-12 for fraction in share)
        assert share[-1] == pytest.approx(high, abs=1e-12)  # each layer ends its share
    # The stages come in order: all of layer 1, then layer 2, then layer 3.
    assert stages == sorted(stages)


class StopError(Exception):
    """Raised from a progress callback to stop the job."""


@pytest.mark.parametrize("stop_at", ["layer 2/3", "surface"])
def test_raising_from_progress_stops_the_job(stop_at: str, monkeypatch: pytest.MonkeyPatch) -> None:
    quilted: list[int] = []
    surfaces: list[int] = []

    def counted_quilt(*args: Any, **kwargs: Any) -> Any:
        quilted.append(1)
        return quilt(*args, **kwargs)

    def no_surface(*args: Any, **kwargs: Any) -> Any:
        surfaces.append(1)
        raise AssertionError("the surface was read after the stop")

    monkeypatch.setattr(job, "quilt", counted_quilt)
    monkeypatch.setattr(job, "read_surface", no_surface)
    reports: list[str] = []

    def progress(fraction: float, stage: str) -> None:
        reports.append(stage)
        if stage == stop_at:
            raise StopError

    with pytest.raises(StopError):
        run(noise((SIZE, SIZE), np.uint8), [brick(), wood(), cloud()], progress=progress)
    assert reports[-1] == stop_at
    assert reports.count(stop_at) == 1  # nothing reported after the stop
    assert len(quilted) == (2 if stop_at == "layer 2/3" else 3)
    assert surfaces == []


# --------------------------------------------------------------------------------------------
# 5. The private helpers
# --------------------------------------------------------------------------------------------


def test_cover_from_gray_rgb_rgba_and_float_silhouettes() -> None:
    shape = (2, 3)
    gray = np.array([[0, 64, 255], [128, 255, 0]], dtype=np.uint8)
    expected = gray / 255
    for silhouette in (gray, gray[..., None], np.repeat(gray[..., None], 3, axis=2)):
        cover = _cover(silhouette, shape)
        assert cover.dtype == np.float32
        assert cover.shape == shape
        np.testing.assert_allclose(cover, expected, atol=1e-7)
    wide = gray.astype(np.uint16) * 257
    np.testing.assert_allclose(_cover(wide, shape), expected, atol=1e-7)
    # RGBA: colour times alpha (a transparent white covers nothing).
    rgba = np.full((*shape, 4), 255, dtype=np.uint8)
    rgba[..., 3] = gray
    rgba[0, 2, :3] = 0  # opaque black
    cover = _cover(rgba, shape)
    np.testing.assert_allclose(cover, np.where([[1, 1, 0], [1, 1, 1]], expected, 0.0), atol=1e-7)
    # Floats out of range are clipped to [0, 1].
    floats = np.array([[-0.5, 0.25, 3.0], [0.75, 1.0, 0.0]], dtype=np.float32)
    np.testing.assert_allclose(_cover(floats, shape), [[0.0, 0.25, 1.0], [0.75, 1.0, 0.0]])


def test_cover_refuses_a_silhouette_that_marks_nothing_at_half() -> None:
    half = np.full((4, 4), 128, dtype=np.uint8)  # 128/255 > 0.5: inside
    assert _cover(half, (4, 4)).min() > 0.5
    with pytest.raises(InvalidImageError, match="at least half white") as raised:
        _cover(np.full((4, 4), 127, dtype=np.uint8), (4, 4))
    assert raised.value.parameter == "silhouette"
    with pytest.raises(InvalidImageError, match="must be the target's size, 5x4"):
        _cover(half, (4, 5))


def test_normal_map_decodes_integers_and_normalizes_floats() -> None:
    shape = (1, 4)
    encoded = np.array([[[128, 128, 255], [255, 128, 128], [128, 0, 128], [128, 255, 128]]])
    for dtype, top in ((np.uint8, 255), (np.uint16, 65535)):
        scaled = np.rint(encoded / 255 * top).astype(dtype)
        normals = _normal_map(scaled, shape)
        assert normals.dtype == np.float32
        assert normals.shape == (*shape, 3)
        np.testing.assert_allclose(np.linalg.norm(normals, axis=-1), 1.0, atol=1e-6)
        # +z (towards the viewer), +x (right), -y (down), +y (up).
        truth = [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 1.0, 0.0]]
        np.testing.assert_allclose(normals[0], truth, atol=0.01)
    floats = np.array([[[0.0, 0.0, 5.0], [3.0, 0.0, 4.0], [0.0, 0.0, 0.0], [0.0, -2.0, 0.0]]])
    with_alpha = np.concatenate([floats, np.full((*shape, 1), 0.25)], axis=2)
    for given in (floats, with_alpha):
        normals = _normal_map(given.astype(np.float32), shape)
        truth = [[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]
        np.testing.assert_allclose(normals[0], truth, atol=1e-6)


def test_as_rgba_spreads_gray_and_makes_opaque() -> None:
    rng = np.random.default_rng(1)
    gray = rng.random((3, 5, 1)).astype(np.float32)
    rgba = _as_rgba(gray)
    assert rgba.shape == (3, 5, 4)
    assert rgba.dtype == np.float32
    for channel in range(3):
        np.testing.assert_array_equal(rgba[..., channel], gray[..., 0])
    np.testing.assert_array_equal(rgba[..., 3], 1.0)
    rgb = rng.random((3, 5, 3)).astype(np.float32)
    np.testing.assert_array_equal(_as_rgba(rgb)[..., :3], rgb)
    np.testing.assert_array_equal(_as_rgba(rgb)[..., 3], 1.0)
    four = rng.random((3, 5, 4)).astype(np.float32)
    np.testing.assert_array_equal(_as_rgba(four), four)
    assert _as_rgba(four) is not four


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
@pytest.mark.parametrize("shape", [(6, 7), (6, 7, 1), (6, 7, 3), (6, 7, 4)])
def test_restore_round_trips_the_working_rgba(dtype: Any, shape: tuple[int, ...]) -> None:
    image = noise(shape, dtype, seed=2)
    view, fmt = as_channels(image, "target")
    back = _restore(_as_rgba(to_working(view)), fmt, colour=fmt.channels >= 3)
    assert back.dtype == image.dtype
    assert back.shape == image.shape
    np.testing.assert_array_equal(back, image)


def test_restore_colour_alpha_clipping_and_rounding() -> None:
    rgba = np.zeros((1, 3, 4), dtype=np.float32)
    rgba[0, 0] = (1.5, -0.2, 0.5, 0.25)
    rgba[0, 1] = (100.4 / 255, 100.6 / 255, 0.0, 1.0)
    rgba[0, 2] = (0.2, 0.4, 0.6, 1.0)
    _, gray2d = as_channels(np.zeros((1, 3), np.uint8))
    _, rgb = as_channels(np.zeros((1, 3, 3), np.uint16))
    _, with_alpha = as_channels(np.zeros((1, 3, 4), np.uint8))
    # Gray: red is the gray, and a 2-D target comes back 2-D.
    gray = _restore(rgba, gray2d, colour=False)
    np.testing.assert_array_equal(gray, [[255, 100, 51]])
    # A 2-D gray target with colour from a layer comes back RGB.
    assert _restore(rgba, gray2d, colour=True).shape == (1, 3, 3)
    wide = _restore(rgba, rgb, colour=True)
    assert wide.dtype == np.uint16
    np.testing.assert_array_equal(wide[0, 0], [65535, 0, 32768])
    four = _restore(rgba, with_alpha, colour=True)
    assert four.shape == (1, 3, 4)
    np.testing.assert_array_equal(four[0, :2], [[255, 0, 128, 64], [100, 101, 0, 255]])


def test_layer_options_carry_the_quilting_options_and_a_seed_per_layer() -> None:
    options = MatteOptions(
        block=12,
        overlap=3,
        tolerance=0.2,
        mode="overlap",
        error="luminance",
        exclude_colors=[[[250, 0, 0], [255, 10, 10]]],
        histogram_weight=0.1,
        clusters=3,
        scale=2.0,
        seed=5,
    )
    layer = _layer_options(options, 2)
    assert isinstance(layer, SynthesisOptions)
    assert layer.tileable == "both"
    shared = {field.name for field in dataclasses.fields(MatteOptions)}
    for field in dataclasses.fields(SynthesisOptions):
        if field.name in ("seed", "tileable"):
            continue
        if field.name in shared:
            assert getattr(layer, field.name) == getattr(options, field.name), field.name
        else:
            assert getattr(layer, field.name) == getattr(SynthesisOptions(), field.name)
    # Seeds: the same for the same (seed, layer), different across layers and seeds, and
    # not the sum of the two (seed 1's layer 0 is not seed 0's layer 1).
    assert _layer_options(options, 2).seed == layer.seed
    seeds = {
        (seed, index): _layer_options(MatteOptions(seed=seed), index).seed
        for seed in range(4)
        for index in range(4)
    }
    assert len(set(seeds.values())) == len(seeds)
    assert seeds[(1, 0)] != seeds[(0, 1)]


def test_layer_progress_maps_into_the_layer_share() -> None:
    seen: list[tuple[float, str]] = []

    def progress(fraction: float, stage: str) -> str:
        seen.append((fraction, stage))
        return "returned"

    count = 4
    for index in range(count):
        report = _layer_progress(progress, index, count)
        assert report(0.0, "synthesis") == "returned"
        report(0.5, "alpha")
        report(1.0, "synthesis")
    for index in range(count):
        (start, first), (middle, _), (end, _) = seen[3 * index : 3 * index + 3]
        assert first == f"layer {index + 1}/{count}"
        assert start == pytest.approx(0.9 * index / count)
        assert middle == pytest.approx(0.9 * (index + 0.5) / count)
        assert end == pytest.approx(0.9 * (index + 1) / count)
    assert {stage for _, stage in seen} == {f"layer {k}/{count}" for k in range(1, 5)}
    # Contiguous shares: one layer ends where the next begins, the last at 0.9.
    for index in range(count - 1):
        assert seen[3 * index + 2][0] == pytest.approx(seen[3 * index + 3][0])
    assert math.isclose(seen[-1][0], 0.9)

    def failing(fraction: float, stage: str) -> None:
        raise StopError

    with pytest.raises(StopError):
        _layer_progress(failing, 0, 1)(0.5, "synthesis")
