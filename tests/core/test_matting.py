"""Texture matting (alpha quilting and texture matting paper, §3): normals and light read from
one image, k-means patches, layers laid on the surface, shaded and composited "over" the target.

The surfaces are rendered here with numpy (a Lambertian sphere under a known light), so every
check compares with a known truth. Coordinates: x right, y up (= -row), z towards the viewer.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy import ndimage
from textures import texture

import quilting
from quilting.core.matting import (
    cluster_surface,
    lay_layers,
    plane_maps,
    read_surface,
    split_patches,
)
from quilting.core.shading import (
    clamp_z,
    coverage,
    decode_normal_map,
    encode_normal_map,
    estimate_surface,
    silhouette_normals,
)

EIGHT = np.ones((3, 3), dtype=bool)
ALBEDO = 0.8


def render_sphere(
    light: tuple[float, float, float],
    *,
    size: int = 256,
    radius: float = 100.0,
    noise: float = 0.0,
    seed: int = 0,
) -> tuple[NDArray[np.float32], NDArray[np.bool_], NDArray[np.float32], NDArray[np.float64]]:
    """A Lambertian sphere, ``I = 0.8 max(n . S, 0)``, black outside.

    Returns the luminance, the disc, the true normals ((0, 0, 1) outside) and the unit light.
    """
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float64)
    centre = (size - 1) / 2.0
    x = (cols - centre) / radius
    y = (centre - rows) / radius  # y up
    r2 = x * x + y * y
    inside = r2 < 1.0
    z = np.sqrt(np.clip(1.0 - r2, 0.0, None))
    normals = np.stack([x, y, z], axis=-1)
    normals[~inside] = (0.0, 0.0, 1.0)
    s = np.asarray(light, dtype=np.float64)
    s = s / np.linalg.norm(s)
    luma = ALBEDO * np.clip(normals @ s, 0.0, None)
    if noise:
        luma = luma + np.random.default_rng(seed).normal(0.0, noise, luma.shape)
        luma = np.clip(luma, 0.0, 1.0)
    luma[~inside] = 0.0
    return luma.astype(np.float32), inside, normals.astype(np.float32), s


def angles(a: NDArray[Any], b: NDArray[Any]) -> NDArray[np.float64]:
    """Angle in degrees between unit vectors along the last axis."""
    cosine = np.sum(np.asarray(a, np.float64) * np.asarray(b, np.float64), axis=-1)
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def as_uint8(luma: NDArray[np.float32]) -> NDArray[np.uint8]:
    return np.rint(np.clip(luma, 0.0, 1.0) * 255).astype(np.uint8)


def mask_image(mask: NDArray[np.bool_]) -> NDArray[np.uint8]:
    return mask.astype(np.uint8) * 255


GRAY_LAYER = np.full((64, 64), 128, dtype=np.uint8)

#: (light, noise): straight ahead, oblique, from the left, and oblique with noise.
SPHERES = [
    ((0.0, 0.0, 1.0), 0.0),
    ((1.0, 1.0, 2.0), 0.0),
    ((-1.0, 0.5, 1.5), 0.0),
    ((1.0, 1.0, 2.0), 0.02),
    ((-1.0, 0.5, 1.5), 0.02),
]


# --------------------------------------------------------------------------------------------
# 1. Shape and light from shading on a rendered sphere
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("light", "noise"), SPHERES)
def test_estimate_surface_recovers_sphere_light_and_normals(
    light: tuple[float, float, float], noise: float
) -> None:
    luma, inside, truth, s = render_sphere(light, noise=noise, seed=7)
    normals, fitted = estimate_surface(luma, inside, sigma=2.0, min_z=0.1)
    assert angles(fitted.direction, s) < 5.0
    assert np.median(angles(normals[inside], truth[inside])) < 15.0
    # The fit's albedo and ambient are the rendered ones (rho = 0.8, no ambient).
    assert abs(fitted.albedo - ALBEDO) < 0.05
    assert fitted.ambient < 0.05
    # Outside the silhouette the normal is the viewer's direction.
    assert (normals[~inside] == (0.0, 0.0, 1.0)).all()


@pytest.mark.parametrize(("light", "noise"), SPHERES[1:4])
def test_matte_recovers_sphere_light_and_normals(
    light: tuple[float, float, float], noise: float
) -> None:
    luma, inside, truth, s = render_sphere(light, noise=noise, seed=3)
    result = quilting.matte(
        as_uint8(luma), [GRAY_LAYER], silhouette=mask_image(inside), block=16, scale=4.0
    )
    assert angles(np.array(result.light), s) < 5.0
    assert abs(np.linalg.norm(result.light) - 1.0) < 1e-9
    assert np.median(angles(result.normals[inside], truth[inside])) < 15.0
    assert abs(result.albedo - ALBEDO) < 0.05


# --------------------------------------------------------------------------------------------
# 2. A given light and a given normal map are used as they are
# --------------------------------------------------------------------------------------------


def test_given_light_is_used_as_is() -> None:
    # Rendered under one light, told another: the told one is the result's light.
    luma, inside, _, _ = render_sphere((-1.0, 0.5, 1.5), size=128, radius=50)
    given = (1.0, 2.0, 3.0)
    unit = np.array(given) / np.linalg.norm(given)
    result = quilting.matte(
        as_uint8(luma), [GRAY_LAYER], silhouette=mask_image(inside), light=given, block=16
    )
    np.testing.assert_allclose(result.light, unit, atol=1e-12)
    _, fitted = estimate_surface(luma, inside, sigma=2.0, min_z=0.1, light=unit)
    np.testing.assert_array_equal(fitted.direction, unit)


def test_given_uint8_normal_map_is_used() -> None:
    # The image is flat gray, so shape from shading alone would say nothing of the sphere's
    # tilt under the square silhouette; the map says it all.
    _, _, truth, _ = render_sphere((0.0, 0.0, 1.0), size=128, radius=50)
    window = np.zeros((128, 128), dtype=bool)
    window[34:94, 34:94] = True
    target = np.full((128, 128), 150, dtype=np.uint8)
    result = quilting.matte(
        target,
        [GRAY_LAYER],
        silhouette=mask_image(window),
        normals=encode_normal_map(truth),
        block=16,
    )
    err = angles(result.normals[window], truth[window])
    assert err.max() < 2.0
    # ... where the silhouette's prior is far from it (so the map was not just agreed with).
    prior = silhouette_normals(window)
    assert np.median(angles(prior[window], truth[window])) > 10.0
    np.testing.assert_array_equal(result.normals[~window][:, 2], 1.0)


def test_given_uint8_normal_map_on_sphere_within_clamp() -> None:
    luma, inside, truth, _ = render_sphere((1.0, 1.0, 2.0), size=128, radius=50)
    result = quilting.matte(
        as_uint8(luma),
        [GRAY_LAYER],
        silhouette=mask_image(inside),
        normals=encode_normal_map(truth),
        block=16,
    )
    upright = inside & (truth[..., 2] >= 0.1)
    assert angles(result.normals[upright], truth[upright]).max() < 2.0


def test_given_float_normals_are_used() -> None:
    # A tilted plane, given as float components of length 2 (normalized on the way in),
    # under a sphere's shading: the plane wins everywhere inside.
    luma, inside, _, _ = render_sphere((1.0, 1.0, 2.0), size=128, radius=50)
    plane = np.array([0.3, -0.2, 0.9])
    plane /= np.linalg.norm(plane)
    given = np.broadcast_to(2.0 * plane, (128, 128, 3)).astype(np.float32)
    result = quilting.matte(
        as_uint8(luma), [GRAY_LAYER], silhouette=mask_image(inside), normals=given, block=16
    )
    assert angles(result.normals[inside], plane).max() < 0.01
    estimated = quilting.matte(
        as_uint8(luma), [GRAY_LAYER], silhouette=mask_image(inside), block=16
    )
    assert np.median(angles(estimated.normals[inside], plane)) > 10.0


# --------------------------------------------------------------------------------------------
# 3. Shading matters: a sphere seen through a square window
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("light", [(1.0, 1.0, 2.0), (-1.0, 0.5, 1.5)])
def test_shading_beats_the_silhouette_prior_through_a_window(
    light: tuple[float, float, float],
) -> None:
    luma, disc, truth, s = render_sphere(light)
    window = np.zeros_like(disc)
    window[68:188, 68:188] = True  # 120 px square, corners inside the radius-100 disc
    assert (disc | ~window).all()
    luma = np.where(window, luma, 0.0).astype(np.float32)
    normals, _ = estimate_surface(luma, window, sigma=2.0, min_z=0.1, light=s)
    estimate = float(np.median(angles(normals[window], truth[window])))
    prior = float(np.median(angles(silhouette_normals(window)[window], truth[window])))
    assert estimate < 15.0
    assert estimate < prior - 5.0


# --------------------------------------------------------------------------------------------
# 4. The z floor
# --------------------------------------------------------------------------------------------


def assert_floored_units(normals: NDArray[np.float32], min_z: float) -> None:
    assert normals[..., 2].min() >= min_z - 1e-6
    np.testing.assert_allclose(np.linalg.norm(normals, axis=-1), 1.0, atol=1e-5)


@pytest.mark.parametrize("min_z", [0.1, 0.3])
def test_estimated_normals_are_floored_unit_vectors(min_z: float) -> None:
    luma, inside, _, _ = render_sphere((-1.0, 0.5, 1.5), size=128, radius=50)
    normals, _ = estimate_surface(luma, inside, sigma=2.0, min_z=min_z)
    assert_floored_units(normals, min_z)
    if min_z == 0.3:  # the sphere's rim is steeper than that: the floor was hit
        assert np.isclose(normals[inside][:, 2], min_z, atol=1e-6).any()


@pytest.mark.parametrize("min_z", [0.1, 0.3])
def test_given_normals_are_floored_unit_vectors(min_z: float) -> None:
    luma, inside, truth, _ = render_sphere((1.0, 1.0, 2.0), size=128, radius=50)
    for given in (encode_normal_map(truth), truth):
        result = quilting.matte(
            as_uint8(luma),
            [GRAY_LAYER],
            silhouette=mask_image(inside),
            normals=given,
            min_z=min_z,
            block=16,
        )
        assert_floored_units(result.normals, min_z)
        # (Clear of the floor by more than the 8-bit map's rounding.)
        low = inside & (truth[..., 2] < min_z - 0.02)
        assert low.any()
        np.testing.assert_allclose(result.normals[low][:, 2], min_z, atol=1e-6)
        # Raised, the tilt keeps its direction.
        tilt = truth[low][:, :2] / np.linalg.norm(truth[low][:, :2], axis=1, keepdims=True)
        kept = result.normals[low][:, :2] / np.sqrt(1.0 - min_z**2)
        np.testing.assert_allclose(kept, tilt, atol=0.02)


# --------------------------------------------------------------------------------------------
# 5. Clusters and patches
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1])
def test_sphere_clusters_are_numbered_and_spatially_coherent(seed: int) -> None:
    luma, inside, _, _ = render_sphere((1.0, 1.0, 2.0))
    result = quilting.matte(
        as_uint8(luma),
        [GRAY_LAYER],
        silhouette=mask_image(inside),
        clusters=8,
        seed=seed,
        block=16,
        scale=4.0,
    )
    clusters = result.clusters
    assert clusters.dtype == np.int32
    np.testing.assert_array_equal(clusters == -1, ~inside)
    count = int(clusters.max()) + 1
    assert 2 <= count <= 8
    np.testing.assert_array_equal(np.unique(clusters[inside]), np.arange(count))
    for cluster in range(count):
        parts, _ = ndimage.label(clusters == cluster, structure=EIGHT)
        sizes = np.bincount(parts.ravel())[1:]
        assert sizes.max() >= 0.9 * sizes.sum(), f"cluster {cluster} is scattered"
    patches = result.patches
    np.testing.assert_array_equal(patches == -1, ~inside)
    total = int(patches.max()) + 1
    np.testing.assert_array_equal(np.unique(patches[inside]), np.arange(total))
    for patch in range(total):
        here = patches == patch
        assert ndimage.label(here, structure=EIGHT)[1] == 1
        assert np.unique(clusters[here]).size == 1  # a patch lies in one cluster


def corrugated_normals(size: int) -> NDArray[np.float32]:
    """Normals of a washboard surface: the tilt swings left and right every ~38 columns."""
    cols = np.arange(size, dtype=np.float64)[None, :].repeat(size, axis=0)
    tilt = 0.6 * np.sin(cols / 6.0)
    normals = np.stack([tilt, np.zeros_like(tilt), np.ones_like(tilt)], axis=-1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    return normals.astype(np.float32)


def test_spatial_weight_makes_clusters_compact() -> None:
    # On a washboard the same tilt comes back on every ridge: by normal alone a cluster takes
    # every ridge of its tilt (many patches); weighted by position it takes one region.
    normals = corrugated_normals(128)
    inside = np.zeros((128, 128), dtype=bool)
    inside[16:112, 16:112] = True

    def clustered(weight: float) -> tuple[int, int, float]:
        labels = cluster_surface(normals, inside, 8, weight, np.random.default_rng(0))
        patches = split_patches(labels, normals, 0.1)
        spread = []
        for cluster in range(int(labels.max()) + 1):
            rows, cols = np.nonzero(labels == cluster)
            spread.append(np.sqrt(rows.var() + cols.var()))
        return int(labels.max()) + 1, int(patches.patches.max()) + 1, float(np.mean(spread))

    loose_clusters, loose_patches, loose_spread = clustered(0.0)
    tight_clusters, tight_patches, tight_spread = clustered(20.0)
    assert loose_patches > 2 * loose_clusters
    assert tight_patches == tight_clusters  # every cluster in one piece
    assert tight_spread < 0.6 * loose_spread


# --------------------------------------------------------------------------------------------
# 6. Compositing: order, alpha, coverage, the target's format
# --------------------------------------------------------------------------------------------

SIZE = 128
SQUARE = np.zeros((SIZE, SIZE), dtype=bool)
SQUARE[32:96, 32:96] = True
RED = np.zeros((64, 64, 3), dtype=np.uint8)
RED[..., 0] = 255
BLUE_HALF = np.zeros((64, 64, 4), dtype=np.uint8)
BLUE_HALF[..., 2] = 255
BLUE_HALF[..., 3] = 128
A = 128 / 255
FACING = np.broadcast_to(np.array([0.0, 0.0, 1.0], np.float32), (SIZE, SIZE, 3)).copy()


def flat_matte(target: NDArray[Any], layers: list[NDArray[Any]], **kwargs: Any) -> Any:
    """Matte with every normal facing the viewer and the light ahead: the shading is 1."""
    options: dict[str, Any] = {
        "silhouette": mask_image(SQUARE),
        "normals": FACING,
        "light": (0.0, 0.0, 1.0),
        "block": 16,
    }
    options.update(kwargs)
    return quilting.matte(target, layers, **options)


@pytest.fixture(scope="module")
def noisy_target() -> NDArray[np.uint8]:
    # Noise, so that "unchanged outside" is tested on every value.
    return np.random.default_rng(5).integers(0, 256, (SIZE, SIZE, 3), dtype=np.uint8)


def test_second_layer_lies_over_the_first(noisy_target: NDArray[np.uint8]) -> None:
    result = flat_matte(noisy_target, [RED, BLUE_HALF])
    inside = result.image[SQUARE].astype(np.float64)
    expected = A * np.array([0.0, 0.0, 255.0]) + (1 - A) * np.array([255.0, 0.0, 0.0])
    assert np.abs(inside - expected).max() <= 2.0
    assert result.image.dtype == np.uint8
    assert result.image.shape == noisy_target.shape
    np.testing.assert_array_equal(result.image[~SQUARE], noisy_target[~SQUARE])


def test_opaque_top_layer_hides_the_one_below(noisy_target: NDArray[np.uint8]) -> None:
    result = flat_matte(noisy_target, [BLUE_HALF, RED])
    assert np.abs(result.image[SQUARE].astype(int) - [255, 0, 0]).max() <= 1
    np.testing.assert_array_equal(result.image[~SQUARE], noisy_target[~SQUARE])


def test_one_transparent_layer_over_the_target(noisy_target: NDArray[np.uint8]) -> None:
    result = flat_matte(noisy_target, [BLUE_HALF])
    expected = A * np.array([0.0, 0.0, 255.0]) + (1 - A) * noisy_target[SQUARE]
    assert np.abs(result.image[SQUARE] - expected).max() <= 1.0
    np.testing.assert_array_equal(result.image[~SQUARE], noisy_target[~SQUARE])


def test_partial_silhouette_scales_the_layer_alpha(noisy_target: NDArray[np.uint8]) -> None:
    # 200 (inside, > half) and 64 (a quarter: an outline pixel that is not read, but drawn).
    silhouette = np.zeros((SIZE, SIZE), dtype=np.uint8)
    silhouette[32:96, 32:96] = 200
    silhouette[24:32, 32:96] = 64
    result = flat_matte(noisy_target, [RED], silhouette=silhouette)
    for value in (200, 64):
        where = silhouette == value
        cover = value / 255
        expected = cover * np.array([255.0, 0.0, 0.0]) + (1 - cover) * noisy_target[where]
        assert np.abs(result.image[where] - expected).max() <= 1.0, value
    outside = silhouette == 0
    np.testing.assert_array_equal(result.image[outside], noisy_target[outside])


def test_shading_is_lambert_with_ambient(noisy_target: NDArray[np.uint8]) -> None:
    light = (0.6, 0.0, 0.8)  # n . S = 0.8 for the normals facing the viewer
    for ambient, shade in ((0.0, 0.8), (0.5, 0.9)):
        result = flat_matte(noisy_target, [RED], light=light, ambient=ambient)
        assert np.abs(result.image[SQUARE].astype(int) - [255 * shade, 0, 0]).max() <= 1


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_target_alpha_size_and_dtype_are_kept(dtype: type) -> None:
    rng = np.random.default_rng(11)
    if dtype == np.float32:
        top = 1.0
        target = rng.random((SIZE, SIZE, 4)).astype(np.float32)
    else:
        top = float(np.iinfo(dtype).max)
        target = rng.integers(0, int(top) + 1, (SIZE, SIZE, 4)).astype(dtype)
    result = flat_matte(target, [BLUE_HALF])
    assert result.image.dtype == target.dtype
    assert result.image.shape == target.shape
    np.testing.assert_array_equal(result.image[~SQUARE], target[~SQUARE])
    # "Over": alpha = a + alpha_target (1 - a); colour premultiplied.
    t_alpha = target[SQUARE][:, 3].astype(np.float64) / top
    alpha = A + t_alpha * (1 - A)
    np.testing.assert_allclose(result.image[SQUARE][:, 3] / top, alpha, atol=1.5 / 255)
    blue = (A + target[SQUARE][:, 2] / top * t_alpha * (1 - A)) / alpha
    np.testing.assert_allclose(result.image[SQUARE][:, 2] / top, blue, atol=1.5 / 255)
    opaque = flat_matte(target, [RED, BLUE_HALF])
    np.testing.assert_allclose(opaque.image[SQUARE][:, 3] / top, 1.0, atol=1e-6)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_gray_target_and_layer_stay_gray(dtype: type) -> None:
    rng = np.random.default_rng(2)
    top = int(np.iinfo(dtype).max)
    target = rng.integers(0, top + 1, (SIZE, SIZE)).astype(dtype)
    result = flat_matte(target, [np.full((64, 64), 200, np.uint8)])
    assert result.image.shape == target.shape
    assert result.image.dtype == target.dtype
    np.testing.assert_array_equal(result.image[~SQUARE], target[~SQUARE])
    assert np.abs(result.image[SQUARE] / top - 200 / 255).max() <= 1.0 / 255
    # A colour layer on a gray target gives colour.
    coloured = flat_matte(target, [RED])
    assert coloured.image.shape == (SIZE, SIZE, 3)
    np.testing.assert_array_equal(coloured.image[~SQUARE][:, 0], target[~SQUARE])


def test_gray_float_target_unchanged_outside() -> None:
    target = np.random.default_rng(0).random((SIZE, SIZE)).astype(np.float32)
    result = flat_matte(target, [np.full((64, 64), 200, np.uint8)])
    np.testing.assert_array_equal(result.image[~SQUARE], target[~SQUARE])


def test_lay_layers_with_facing_normals_reads_the_layer_in_place() -> None:
    # Facing the viewer, every patch's map is the identity around its own anchor, so all
    # patches read the layer at (row, col) / scale: the layer lies unbroken across patches.
    rng = np.random.default_rng(4)
    cover = SQUARE.astype(np.float32)
    surface = read_surface(
        rng.random((SIZE, SIZE)).astype(np.float32),
        cover,
        normals=FACING.copy(),
        light=np.array([0.0, 0.0, 1.0]),
        clusters=4,
        spatial_weight=1.0,
        smoothing=2.0,
        min_z=0.1,
        rng=np.random.default_rng(0),
    )
    np.testing.assert_array_equal(surface.light.direction, [0.0, 0.0, 1.0])
    assert int(surface.patches.patches.max()) >= 1  # more than one patch to line up
    layer = np.ones((40, 40, 4), dtype=np.float32)
    layer[..., :3] = rng.random((40, 40, 3))
    target = np.zeros((SIZE, SIZE, 4), dtype=np.float32)
    out = lay_layers(target, [layer], surface, scale=1.0, ambient=0.0)
    rows, cols = np.nonzero(SQUARE)
    np.testing.assert_allclose(out[rows, cols], layer[rows % 40, cols % 40], atol=1e-5)
    np.testing.assert_array_equal(out[~SQUARE], target[~SQUARE])


# --------------------------------------------------------------------------------------------
# 7. Determinism
# --------------------------------------------------------------------------------------------


def test_same_seed_same_bytes_other_seed_other_image() -> None:
    luma, inside, _, _ = render_sphere((1.0, 1.0, 2.0), size=128, radius=50)
    layers = [texture("brick")[:96, :96], texture("cloud_rgba")[:96, :96]]
    options: dict[str, Any] = {"silhouette": mask_image(inside), "block": 16, "scale": 1.5}
    first = quilting.matte(as_uint8(luma), layers, seed=3, **options)
    again = quilting.matte(as_uint8(luma), layers, seed=3, **options)
    other = quilting.matte(as_uint8(luma), layers, seed=4, **options)
    assert first.image.tobytes() == again.image.tobytes()
    assert first.normals.tobytes() == again.normals.tobytes()
    assert first.clusters.tobytes() == again.clusters.tobytes()
    assert first.light == again.light
    assert not np.array_equal(first.image, other.image)
    assert not np.array_equal(first.image[inside], other.image[inside])


# --------------------------------------------------------------------------------------------
# 8. Bad input
# --------------------------------------------------------------------------------------------

SMALL = 64
SMALL_SQUARE = np.zeros((SMALL, SMALL), dtype=np.uint8)
SMALL_SQUARE[16:48, 16:48] = 255
SMALL_LAYER = np.full((32, 32, 3), 100, dtype=np.uint8)


@pytest.mark.parametrize(
    ("change", "error", "named"),
    [
        ({"layers": []}, quilting.InvalidParameterError, "layers"),
        ({"silhouette": SMALL_SQUARE[:32]}, quilting.InvalidImageError, "silhouette"),
        (
            {"silhouette": np.zeros_like(SMALL_SQUARE)},
            quilting.InvalidImageError,
            "silhouette",
        ),
        (
            {"normals": np.zeros((32, SMALL, 3), dtype=np.uint8)},
            quilting.InvalidImageError,
            "normals",
        ),
        ({"light": (1.0, 0.0, 0.0)}, quilting.InvalidParameterError, "light"),
        ({"light": (0.0, 0.5, -1.0)}, quilting.InvalidParameterError, "light"),
        ({"mode": "walk"}, quilting.InvalidParameterError, "mode"),
        ({"mode": "alpha"}, quilting.InvalidParameterError, "alpha"),
        ({"block": 40}, quilting.InvalidParameterError, "block"),
    ],
)
def test_bad_input_is_refused_by_name(change: dict[str, Any], error: type, named: str) -> None:
    options: dict[str, Any] = {
        "layers": [SMALL_LAYER],
        "silhouette": SMALL_SQUARE,
        "block": 16,
    }
    options.update(change)
    layers = options.pop("layers")
    target = np.full((SMALL, SMALL), 128, dtype=np.uint8)
    with pytest.raises(error, match=named):
        quilting.matte(target, layers, **options)


# --------------------------------------------------------------------------------------------
# 9. The plane map of a patch
# --------------------------------------------------------------------------------------------


def test_plane_map_of_a_facing_patch_is_the_identity() -> None:
    np.testing.assert_allclose(plane_maps(np.array([[0.0, 0.0, 1.0]]))[0], np.eye(2), atol=1e-12)


@pytest.mark.parametrize(
    "normal", [(0.6, 0.0, 0.8), (0.0, -0.5, 0.7), (0.3, -0.5, 0.6), (-0.9, 0.3, 0.15)]
)
def test_plane_map_undoes_foreshortening_along_the_tilt(
    normal: tuple[float, float, float],
) -> None:
    m = np.asarray(normal) / np.linalg.norm(normal)
    mapping = plane_maps(m[None])[0]
    _, values, right = np.linalg.svd(mapping)
    np.testing.assert_allclose(values, [1.0 / m[2], 1.0], rtol=1e-9)
    tilt = m[:2] / np.linalg.norm(m[:2])
    assert abs(abs(right[0] @ tilt) - 1.0) < 1e-9  # stretched along the tilt
    across = np.array([-tilt[1], tilt[0]])
    np.testing.assert_allclose(np.linalg.norm(mapping @ across), 1.0, rtol=1e-9)
    assert np.linalg.det(mapping) > 0  # turned and stretched, never mirrored


# --------------------------------------------------------------------------------------------
# 10. clamp_z, coverage, the normal-map encoding
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("min_z", [0.1, 0.3])
def test_clamp_z(min_z: float) -> None:
    rng = np.random.default_rng(6)
    normals = rng.normal(size=(500, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    out = clamp_z(normals.astype(np.float32), min_z)
    assert out.dtype == np.float32
    assert_floored_units(out, min_z)
    high = normals[:, 2] >= min_z
    np.testing.assert_allclose(out[high], normals[high], atol=1e-6)
    low = ~high
    assert low.sum() > 100
    np.testing.assert_allclose(out[low][:, 2], min_z, atol=1e-6)
    direction = normals[low][:, :2] / np.linalg.norm(normals[low][:, :2], axis=1, keepdims=True)
    np.testing.assert_allclose(out[low][:, :2] / np.sqrt(1 - min_z**2), direction, atol=1e-5)


def test_coverage() -> None:
    gray = np.array([[[1.0], [0.0], [0.5]]], dtype=np.float32)
    np.testing.assert_allclose(coverage(gray), [[1.0, 0.0, 0.5]])
    rgb = np.repeat(gray, 3, axis=2)
    np.testing.assert_allclose(coverage(rgb), [[1.0, 0.0, 0.5]])
    rgba = np.ones((1, 4, 4), dtype=np.float32)
    rgba[0, :, 3] = [1.0, 0.0, 0.5, 0.25]
    rgba[0, 3, :3] = 0.0  # black, so uncovered whatever its alpha
    np.testing.assert_allclose(coverage(rgba), [[1.0, 0.0, 0.5, 0.0]])
    assert coverage(rgba).dtype == np.float32


def test_normal_map_round_trip() -> None:
    rng = np.random.default_rng(8)
    normals = rng.normal(size=(40, 40, 3))
    normals[..., 2] = np.abs(normals[..., 2])
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    encoded = encode_normal_map(normals.astype(np.float32))
    assert encoded.dtype == np.uint8
    # The usual colours: (0, 0, 1) is (128, 128, 255), +y up is green up.
    np.testing.assert_array_equal(encode_normal_map(np.array([[0.0, 0.0, 1.0]])), [[128, 128, 255]])
    np.testing.assert_array_equal(encode_normal_map(np.array([[0.0, 1.0, 0.0]])), [[128, 255, 128]])
    decoded = decode_normal_map(encoded.astype(np.float32) / 255, integer=True)
    assert np.abs(decoded - normals).max() <= 1 / 127
    np.testing.assert_allclose(np.linalg.norm(decoded, axis=-1), 1.0, atol=1e-5)


@pytest.mark.gl
def test_gl_gives_the_same_bytes(gl: Any) -> None:
    """The layers quilted by the GL backend give the fft backend's image, byte for byte."""
    target, inside, _, _ = render_sphere((1.0, 1.0, 2.0), size=96, radius=38.0)
    image = np.rint(target * 255).astype(np.uint8)
    mask = (inside * 255).astype(np.uint8)
    layers = [texture("brick"), texture("cloud_rgba")]
    fft = quilting.matte(image, layers, silhouette=mask, block=24, seed=2, backend="fft")
    on_gl = quilting.matte(image, layers, silhouette=mask, block=24, seed=2, backend=gl.GLBackend())
    assert on_gl.layers[0].backend == "gl"
    assert np.array_equal(on_gl.image, fft.image)
