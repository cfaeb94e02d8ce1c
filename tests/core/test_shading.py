"""The surface under a silhouette read from shading (``quilting.core.shading``), piece by piece.

``tests/core/test_matting.py`` checks the whole estimate on rendered spheres (light, normals,
the z floor, the normal-map round trip, coverage). Here each helper is held to its own
promise against an oracle written in the test: closed forms (Lambert's law, a sphere's
normals, a linear ramp's gradient, the trust formula), brute force (a normalized convolution
summed by loops, the nearest point of a circle found by sampling it), and exact recovery of a
light from noiseless synthetic data. Coordinates: x right, y up (= -row), z to the viewer.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from quilting.core.errors import InvalidImageError, InvalidParameterError
from quilting.core.shading import (
    GRADIENT_FLOOR,
    SHADOW,
    Light,
    clamp_z,
    decode_normal_map,
    encode_normal_map,
    estimate_surface,
    fit_light,
    inside_of,
    lit_pixels,
    luminance_gradient,
    masked_blur,
    onto_shading,
    shading_normals,
    silhouette_normals,
    unit,
    unit_direction,
)

AHEAD = np.array([0.0, 0.0, 1.0])


def angles(a: NDArray[Any], b: NDArray[Any]) -> NDArray[np.float64]:
    """Angle in degrees between unit vectors along the last axis."""
    cosine = np.sum(np.asarray(a, np.float64) * np.asarray(b, np.float64), axis=-1)
    degrees: NDArray[np.float64] = np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))
    return degrees


def hemisphere(rng: np.random.Generator, n: int, min_z: float = 0.05) -> NDArray[np.float64]:
    """``n`` random unit vectors with z >= ``min_z`` (rejection sampling, no shading code)."""
    out: list[NDArray[np.float64]] = []
    while sum(len(o) for o in out) < n:
        v = rng.normal(size=(4 * n, 3))
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        out.append(v[v[:, 2] >= min_z])
    return np.concatenate(out)[:n]


def as_image(vectors: NDArray[np.float64], width: int) -> NDArray[np.float32]:
    """(N, 3) vectors as an (N / width, width, 3) float32 image."""
    return vectors.reshape(-1, width, 3).astype(np.float32)


# --------------------------------------------------------------------------------------------
# unit, Light.shading, unit_direction
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_unit_scales_to_length_one_and_keeps_zero(dtype: type) -> None:
    rng = np.random.default_rng(1)
    vectors: NDArray[Any] = rng.normal(size=(7, 5, 3)).astype(dtype)
    vectors[2, 3] = 0.0
    out = unit(vectors)
    assert out.dtype == dtype  # the helper is typed to keep float32 float32
    lengths = np.sqrt(np.sum(vectors.astype(np.float64) ** 2, axis=-1))
    moved = lengths > 0
    np.testing.assert_allclose(
        out[moved], vectors[moved] / lengths[moved][:, None], rtol=1e-6, atol=1e-7
    )
    # The zero vector has no direction: it stays zero rather than becoming NaN.
    np.testing.assert_array_equal(out[2, 3], 0.0)


def test_light_shading_is_lambert_inverted_and_clipped() -> None:
    light = Light(AHEAD.copy(), albedo=0.8, ambient=0.1)
    luma = np.linspace(-0.2, 1.2, 57, dtype=np.float32).reshape(3, 19)
    got = light.shading(luma)
    assert got.dtype == np.float32
    # n . S = (I - a) / rho, and a cosine lies in [0, 1] for a lit Lambertian pixel.
    want = np.clip((luma.astype(np.float64) - 0.1) / 0.8, 0.0, 1.0)
    np.testing.assert_allclose(got, want, atol=1e-6)
    assert got.min() == 0.0 and got.max() == 1.0  # both ends of the range were reached


@pytest.mark.parametrize("given", [(1.0, 2.0, 3.0), (0.0, 0.0, 5.0), (1e-9, 0.0, 0.0)])
def test_unit_direction_normalizes(given: tuple[float, float, float]) -> None:
    got = unit_direction(given)
    assert got.dtype == np.float64
    assert abs(float(np.linalg.norm(got)) - 1.0) < 1e-12
    # Same direction as given: parallel (cross product zero) and not reversed.
    np.testing.assert_allclose(np.cross(got, given), 0.0, atol=1e-12)
    assert float(np.dot(got, given)) > 0


def test_unit_direction_refuses_the_zero_vector() -> None:
    with pytest.raises(InvalidParameterError) as caught:
        unit_direction((0.0, 0.0, 0.0))
    assert caught.value.parameter == "light"
    assert "non-zero" in str(caught.value)


# --------------------------------------------------------------------------------------------
# inside_of, masked_blur
# --------------------------------------------------------------------------------------------


def test_inside_is_covered_at_least_half() -> None:
    cover = np.array([[0.0, 0.49, 0.5, 0.51, 1.0]], dtype=np.float32)
    np.testing.assert_array_equal(inside_of(cover), [[False, False, True, True, True]])


@pytest.mark.parametrize("value", [0.0, 0.49])
def test_inside_refuses_an_empty_silhouette(value: float) -> None:
    with pytest.raises(InvalidImageError, match="silhouette") as caught:
        inside_of(np.full((4, 6), value, dtype=np.float32))
    assert caught.value.parameter == "silhouette"


def gaussian_kernel(sigma: float) -> NDArray[np.float64]:
    """The 2-D kernel of a separable Gaussian truncated at 4 sigma (scipy's default)."""
    radius = int(4.0 * sigma + 0.5)
    offsets = np.arange(-radius, radius + 1)
    g = np.exp(-0.5 * (offsets / sigma) ** 2)
    g /= g.sum()
    kernel: NDArray[np.float64] = np.outer(g, g)
    return kernel


def test_masked_blur_is_a_normalized_convolution() -> None:
    # Brute force, pixel by pixel, away from the image border (where the boundary mode would
    # enter): sum(K v m) / sum(K m) over the window, m the inside mask.
    rng = np.random.default_rng(2)
    sigma = 1.5
    values = rng.random((36, 40)).astype(np.float32)
    inside = rng.random((36, 40)) < 0.6
    got = masked_blur(values, inside, sigma)
    assert got.dtype == np.float32 and got.shape == values.shape
    kernel = gaussian_kernel(sigma)
    radius = kernel.shape[0] // 2
    for row in range(radius, 36 - radius):
        for col in range(radius, 40 - radius):
            window = np.s_[row - radius : row + radius + 1, col - radius : col + radius + 1]
            weight = kernel * inside[window]
            want = float(np.sum(weight * values[window]) / np.sum(weight))
            assert got[row, col] == pytest.approx(want, abs=2e-5), (row, col)


def test_masked_blur_ignores_the_outside() -> None:
    # A constant inside stays that constant inside and a little beyond it, however wild the
    # outside values: the outside never leaks in (the gradients at the outline rely on it).
    inside = np.zeros((30, 30), dtype=bool)
    inside[8:22, 5:25] = True
    values = np.where(inside, 0.3, 50.0).astype(np.float32)
    got = masked_blur(values, inside, 2.0)
    np.testing.assert_allclose(got[inside], 0.3, rtol=1e-5)
    near = np.zeros_like(inside)
    near[6:24, 3:27] = True  # two pixels beyond the inside: extrapolated from it
    np.testing.assert_allclose(got[near], 0.3, rtol=1e-5)


def test_masked_blur_of_vectors_blurs_each_component_alone() -> None:
    rng = np.random.default_rng(3)
    values = rng.random((20, 24, 3)).astype(np.float32)
    inside = rng.random((20, 24)) < 0.7
    got = masked_blur(values, inside, 1.2)
    assert got.shape == values.shape
    for k in range(3):
        np.testing.assert_allclose(
            got[..., k], masked_blur(values[..., k].copy(), inside, 1.2), atol=1e-6
        )


@pytest.mark.parametrize("sigma", [0.0, -1.0])
def test_masked_blur_without_sigma_is_a_copy(sigma: float) -> None:
    values = np.random.default_rng(4).random((5, 7)).astype(np.float32)
    got = masked_blur(values, np.ones((5, 7), bool), sigma)
    np.testing.assert_array_equal(got, values)
    assert got is not values and not np.shares_memory(got, values)


# --------------------------------------------------------------------------------------------
# silhouette_normals
# --------------------------------------------------------------------------------------------


def disc(size: int, centre: tuple[float, float], radius: float) -> NDArray[np.bool_]:
    rows, cols = np.mgrid[0:size, 0:size]
    inside: NDArray[np.bool_] = (rows - centre[0]) ** 2 + (cols - centre[1]) ** 2 < radius**2
    return inside


def sphere_normals(size: int, centre: tuple[float, float], radius: float) -> NDArray[np.float64]:
    """The closed form: a sphere's normal at (x, y) = (col, -row) is ((x, y) - c, z) / R."""
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float64)
    x = (cols - centre[1]) / radius
    y = (centre[0] - rows) / radius
    z = np.sqrt(np.clip(1.0 - x * x - y * y, 0.0, None))
    normals: NDArray[np.float64] = np.stack([x, y, z], axis=-1)
    return normals


def test_silhouette_of_a_disc_is_a_sphere() -> None:
    inside = disc(80, (39.5, 39.5), 30.0)
    got = silhouette_normals(inside)
    assert got.shape == (80, 80, 3) and got.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(got, axis=-1), 1.0, atol=1e-5)
    np.testing.assert_array_equal(got[~inside], np.broadcast_to(AHEAD, got[~inside].shape))
    truth = sphere_normals(80, (39.5, 39.5), 30.0)
    # Away from the rim (where the discrete distance and gradient are coarsest) the inflated
    # disc is the sphere to a few degrees; the pixel grid's distance transform has ridges
    # along the axes, so only a small tail strays further.
    core = disc(80, (39.5, 39.5), 24.0)
    err = angles(got[core], truth[core])
    assert np.median(err) < 3.0 and np.percentile(err, 90) < 8.0 and err.max() < 15.0
    # Orientation: the right half faces right (+x), the top half faces up (+y).
    assert (got[core & (truth[..., 0] > 0.2)][:, 0] > 0).all()
    assert (got[core & (truth[..., 1] > 0.2)][:, 1] > 0).all()


def test_each_part_of_the_silhouette_has_its_own_radius() -> None:
    # A big and a small disc: were the radius global, the small one would come out flattened.
    small_centre, small_r = (20.0, 20.0), 10.0
    big_centre, big_r = (60.0, 60.0), 25.0
    inside = disc(96, small_centre, small_r) | disc(96, big_centre, big_r)
    got = silhouette_normals(inside)
    for centre, r in ((small_centre, small_r), (big_centre, big_r)):
        core = disc(96, centre, 0.75 * r)
        truth = sphere_normals(96, centre, r)
        assert np.median(angles(got[core], truth[core])) < 4.0, r


@pytest.mark.parametrize("shape", [(1, 1), (3, 17), (12, 12)])
def test_a_silhouette_without_outline_faces_the_viewer(shape: tuple[int, int]) -> None:
    got = silhouette_normals(np.ones(shape, dtype=bool))
    np.testing.assert_array_equal(got, np.broadcast_to(AHEAD, (*shape, 3)))


def test_silhouette_running_off_the_image_goes_on() -> None:
    # A band across the whole width: its outline is only top and bottom, so the surface is a
    # horizontal cylinder: no x tilt anywhere, y tilt pointing away from the band's middle.
    inside = np.zeros((21, 30), dtype=bool)
    inside[5:16] = True
    got = silhouette_normals(inside)
    np.testing.assert_allclose(got[inside][:, 0], 0.0, atol=1e-6)
    assert (got[5:9, :, 1] > 0.1).all()  # upper rows face up
    assert (got[12:16, :, 1] < -0.1).all()  # lower rows face down


# --------------------------------------------------------------------------------------------
# luminance_gradient, lit_pixels
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("sigma", [0.0, 2.0])
def test_gradient_of_a_ramp(sigma: float) -> None:
    # I = 0.01 col - 0.02 row: dI/dx = 0.01 and, with y = -row, dI/dy = +0.02. A linear
    # ramp is its own normalized blur away from the border.
    rows, cols = np.mgrid[0:40, 0:50].astype(np.float32)
    luma = (0.3 + 0.01 * cols - 0.02 * rows).astype(np.float32)
    inside = np.ones((40, 50), dtype=bool)
    smooth, gradient = luminance_gradient(luma, inside, sigma)
    assert gradient.shape == (40, 50, 2) and gradient.dtype == np.float32
    core = np.s_[10:30, 10:40]
    np.testing.assert_allclose(smooth[core], luma[core], atol=1e-5)
    np.testing.assert_allclose(gradient[core][..., 0], 0.01, atol=1e-5)
    np.testing.assert_allclose(gradient[core][..., 1], 0.02, atol=1e-5)


def test_lit_pixels_are_inside_and_above_the_shadow_fraction() -> None:
    inside = np.zeros((10, 10), dtype=bool)
    inside[1:9, 1:9] = True
    luma = np.ones((10, 10), dtype=np.float32)  # the outside is bright, and still not lit
    luma[3, 3] = SHADOW * 0.5  # in shadow: below 5 % of the brightest
    luma[4, 4] = SHADOW * 1.5  # dim but lit
    luma[5, 5] = 0.0
    lit = lit_pixels(luma, inside)
    want = inside.copy()
    want[3, 3] = want[5, 5] = False
    np.testing.assert_array_equal(lit, want)


def test_lit_pixels_ignore_a_few_hot_pixels() -> None:
    # The brightest is the 99th percentile: a handful of hot pixels must not push every
    # ordinary pixel into the shadow.
    luma = np.full((20, 20), 0.5, dtype=np.float32)
    luma[0, :3] = 1000.0  # 3 pixels of 400: under 1 %
    lit = lit_pixels(luma, np.ones((20, 20), dtype=bool))
    assert lit.all()


# --------------------------------------------------------------------------------------------
# fit_light
# --------------------------------------------------------------------------------------------


def lambert(
    normals: NDArray[np.float64], s: NDArray[np.float64], rho: float, ambient: float
) -> NDArray[np.float64]:
    shaded: NDArray[np.float64] = rho * np.clip(normals @ s, 0.0, None) + ambient
    return shaded


@pytest.mark.parametrize(
    ("light", "rho", "ambient"), [((1.0, 1.0, 2.0), 0.8, 0.0), ((-1.0, 0.5, 1.5), 0.6, 0.15)]
)
def test_fit_light_recovers_a_noiseless_light(
    light: tuple[float, float, float], rho: float, ambient: float
) -> None:
    rng = np.random.default_rng(5)
    s = np.asarray(light) / np.linalg.norm(light)
    n = hemisphere(rng, 600)
    n = n[n @ s > 0.05][:400]  # every pixel lit: the model I = rho n.S + a holds exactly
    luma = lambert(n, s, rho, ambient).reshape(20, 20).astype(np.float32)
    normals = as_image(n, 20)
    where = np.ones((20, 20), dtype=bool)
    fitted = fit_light(luma, normals, where)
    assert angles(fitted.direction, s) < 0.05
    assert abs(float(np.linalg.norm(fitted.direction)) - 1.0) < 1e-9
    assert fitted.albedo == pytest.approx(rho, abs=1e-4)
    assert fitted.ambient == pytest.approx(ambient, abs=1e-4)
    # Given the direction, the same rho and a come back.
    known = fit_light(luma, normals, where, direction=s)
    np.testing.assert_array_equal(known.direction, s)
    assert known.albedo == pytest.approx(rho, abs=1e-4)
    assert known.ambient == pytest.approx(ambient, abs=1e-4)


def test_fit_light_refits_without_the_attached_shadow() -> None:
    # Half the normals face away from the light: they show only the ambient term. Fitted as
    # n . S they would drag the light; the refits leave them out and find it again.
    rng = np.random.default_rng(6)
    s = np.array([1.0, 0.0, 0.6]) / np.linalg.norm([1.0, 0.0, 0.6])
    n = hemisphere(rng, 900)
    luma = lambert(n, s, 0.7, 0.1).reshape(30, 30).astype(np.float32)
    assert (n @ s <= 0).sum() > 100  # the case is what it claims to be
    fitted = fit_light(luma, as_image(n, 30), np.ones((30, 30), dtype=bool))
    assert angles(fitted.direction, s) < 1.0
    assert fitted.albedo == pytest.approx(0.7, abs=0.02)
    assert fitted.ambient == pytest.approx(0.1, abs=0.02)


def test_fit_light_never_returns_a_negative_ambient() -> None:
    # Rendered with a negative offset the free fit would find a < 0; the promise is a >= 0,
    # refitted through the origin: then b is the least-squares solution of n b = I.
    rng = np.random.default_rng(7)
    s = np.array([0.3, -0.4, 0.8]) / np.linalg.norm([0.3, -0.4, 0.8])
    n = hemisphere(rng, 600)
    n = n[n @ s > 0.3][:256]
    luma = (0.9 * (n @ s) - 0.2).reshape(16, 16).astype(np.float32)
    where = np.ones((16, 16), dtype=bool)
    fitted = fit_light(luma, as_image(n, 16), where)
    assert fitted.ambient == 0.0
    # Oracle: the normal equations of min |n b - I|^2, solved in the test.
    n32 = as_image(n, 16).reshape(-1, 3).astype(np.float64)
    values = luma.reshape(-1).astype(np.float64)
    b = np.linalg.solve(n32.T @ n32, n32.T @ values)
    np.testing.assert_allclose(fitted.direction, b / np.linalg.norm(b), atol=1e-6)
    assert fitted.albedo == pytest.approx(float(np.linalg.norm(b)), rel=1e-6)
    # With the direction given: rho = (shade . I) / (shade . shade), the 1-D least squares.
    known = fit_light(luma, as_image(n, 16), where, direction=s)
    shade = n32 @ s
    assert known.ambient == 0.0
    assert known.albedo == pytest.approx(float(shade @ values / (shade @ shade)), rel=1e-6)


def test_flat_luminance_has_no_light_to_fit() -> None:
    # A constant image is all ambient: no direction is better than another, so the light is
    # taken straight ahead with the constant as its ambient term.
    n = hemisphere(np.random.default_rng(8), 144)
    luma = np.full((12, 12), 0.4, dtype=np.float32)
    fitted = fit_light(luma, as_image(n, 12), np.ones((12, 12), dtype=bool))
    np.testing.assert_array_equal(fitted.direction, AHEAD)
    assert fitted.albedo == 1.0
    assert fitted.ambient == pytest.approx(0.4, abs=1e-5)


@pytest.mark.parametrize("count", [0, 1, 3])
def test_fit_light_on_too_few_pixels(count: int) -> None:
    # Four unknowns need four pixels; with fewer the light is straight ahead (or the given one).
    luma = np.full((4, 4), 0.5, dtype=np.float32)
    normals = as_image(hemisphere(np.random.default_rng(9), 16), 4)
    where = np.zeros((4, 4), dtype=bool)
    where.reshape(-1)[:count] = True
    fitted = fit_light(luma, normals, where)
    np.testing.assert_array_equal(fitted.direction, AHEAD)
    assert (fitted.albedo, fitted.ambient) == (1.0, 0.0)
    given = np.array([0.6, 0.0, 0.8])
    assert fit_light(luma, normals, where, direction=given).direction is given


# --------------------------------------------------------------------------------------------
# shading_normals, onto_shading
# --------------------------------------------------------------------------------------------


def test_shading_normals_satisfy_the_shading_and_face_against_the_gradient() -> None:
    rng = np.random.default_rng(10)
    s = np.array([0.5, 0.3, 0.8]) / np.linalg.norm([0.5, 0.3, 0.8])
    light = Light(s, albedo=0.9, ambient=0.05)
    smooth = rng.uniform(0.0, 1.0, (30, 30)).astype(np.float32)
    gradient = rng.normal(size=(30, 30, 2)).astype(np.float32)
    normals, _ = shading_normals(smooth, gradient, light)
    assert normals.shape == (30, 30, 3) and normals.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(normals, axis=-1), 1.0, atol=1e-5)
    i = np.clip((smooth.astype(np.float64) - 0.05) / 0.9, 0.0, 1.0)
    u = -gradient / np.linalg.norm(gradient, axis=-1, keepdims=True)
    c = u @ s[:2]
    # Where the formula holds without its guards (1 - c^2 not floored, i strictly inside):
    exact = (np.abs(c) < 0.95) & (i > 0.01) & (i < 0.99)
    assert exact.sum() > 400
    n = normals[exact].astype(np.float64)
    np.testing.assert_allclose(n @ s, i[exact], atol=1e-5)  # n . S = (I - a) / rho
    # n_xy - (n_z / S_z) S_xy points along u: Pentland's local sphere, convex.
    projection = n[:, :2] - (n[:, 2:] / s[2]) * s[:2]
    direction = projection / np.linalg.norm(projection, axis=1, keepdims=True)
    np.testing.assert_allclose(direction, u[exact], atol=1e-4)


def test_with_the_light_ahead_the_rule_is_textureshop() -> None:
    # S = (0, 0, 1), no ambient, rho 1: n_z = I and the tilt points against the gradient.
    rng = np.random.default_rng(11)
    smooth = rng.uniform(0.1, 0.95, (16, 16)).astype(np.float32)
    gradient = rng.normal(size=(16, 16, 2)).astype(np.float32)
    normals, _ = shading_normals(smooth, gradient, Light(AHEAD.copy(), 1.0, 0.0))
    np.testing.assert_allclose(normals[..., 2], smooth, atol=1e-5)
    tilt = normals[..., :2] / np.linalg.norm(normals[..., :2], axis=-1, keepdims=True)
    against = -gradient / np.linalg.norm(gradient, axis=-1, keepdims=True)
    np.testing.assert_allclose(tilt, against, atol=1e-5)


def test_trust_grows_with_the_gradient_and_is_nil_in_shadow() -> None:
    rng = np.random.default_rng(12)
    smooth = rng.uniform(0.2, 1.0, (20, 20)).astype(np.float32)
    smooth[:3] = SHADOW * 0.5  # three rows in shadow
    gradient = rng.normal(size=(20, 20, 2)).astype(np.float32)
    gradient[5, 5] = 0.0  # no gradient: no evidence at all
    _, trust = shading_normals(smooth, gradient, Light(AHEAD.copy(), 1.0, 0.0))
    assert trust.dtype == np.float32
    # Closed form: m / (m + GRADIENT_FLOOR * median of the non-zero magnitudes).
    m = np.sqrt(np.sum(gradient.astype(np.float64) ** 2, axis=-1))
    typical = float(np.median(m[m > 0]))
    want = m / (m + GRADIENT_FLOOR * typical)
    want[:3] = 0.0
    np.testing.assert_allclose(trust, want, atol=1e-6)
    assert trust[5, 5] == 0.0
    assert trust.min() >= 0.0 and trust.max() < 1.0


def test_onto_shading_turns_lit_normals_to_the_nearest_solution() -> None:
    rng = np.random.default_rng(13)
    s = np.array([-0.4, 0.5, 0.77]) / np.linalg.norm([-0.4, 0.5, 0.77])
    light = Light(s, albedo=0.8, ambient=0.1)
    normals = as_image(hemisphere(rng, 64), 8)
    smooth = rng.uniform(0.15, 0.85, (8, 8)).astype(np.float32)
    lit = rng.random((8, 8)) < 0.7
    got = onto_shading(normals, smooth, light, lit)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got[~lit], normals[~lit])  # the shadow keeps its normals
    i = np.clip((smooth.astype(np.float64) - 0.1) / 0.8, 0.0, 1.0)
    np.testing.assert_allclose(np.linalg.norm(got[lit], axis=-1), 1.0, atol=1e-5)
    np.testing.assert_allclose(got[lit].astype(np.float64) @ s, i[lit], atol=1e-5)
    # Brute force "nearest": sample the whole circle of unit vectors with n . S = i and check
    # that none is nearer to the original normal than the result.
    e1 = np.cross(s, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(s, e1)
    theta = np.linspace(0.0, 2 * np.pi, 3600, endpoint=False)
    for row, col in zip(*np.nonzero(lit), strict=True):
        k = i[row, col]
        circle = k * s + np.sqrt(1 - k * k) * (
            np.cos(theta)[:, None] * e1 + np.sin(theta)[:, None] * e2
        )
        best = np.linalg.norm(circle - normals[row, col], axis=1).min()
        mine = np.linalg.norm(got[row, col] - normals[row, col])
        assert mine <= best + 1e-4, (row, col)


# --------------------------------------------------------------------------------------------
# clamp_z (float64), estimate_surface's promises on any input
# --------------------------------------------------------------------------------------------


def test_clamp_z_keeps_float64_and_leaves_upright_normals() -> None:
    normals = hemisphere(np.random.default_rng(14), 200, min_z=-1.0)
    out = clamp_z(normals, 0.25)
    assert out.dtype == np.float64
    assert out[:, 2].min() >= 0.25 - 1e-12
    upright = normals[:, 2] >= 0.25
    np.testing.assert_allclose(out[upright], normals[upright], atol=1e-12)
    np.testing.assert_allclose(clamp_z(out, 0.25), out, atol=1e-12)  # idempotent


@pytest.mark.parametrize("min_z", [0.1, 0.4])
def test_estimate_surface_on_noise_keeps_its_promises(min_z: float) -> None:
    # Whatever the luminance says, the normals are unit vectors with z >= min_z inside,
    # (0, 0, 1) outside, and the light is a unit vector in front of the surface.
    rng = np.random.default_rng(15)
    inside = disc(48, (23.5, 23.5), 18.0)
    luma = np.where(inside, rng.random((48, 48)), 0.0).astype(np.float32)
    normals, light = estimate_surface(luma, inside, sigma=1.5, min_z=min_z)
    assert normals.shape == (48, 48, 3) and normals.dtype == np.float32
    assert np.isfinite(normals).all()
    np.testing.assert_allclose(np.linalg.norm(normals[inside], axis=-1), 1.0, atol=1e-5)
    assert normals[inside][:, 2].min() >= min_z - 1e-6
    np.testing.assert_array_equal(normals[~inside], np.broadcast_to(AHEAD, normals[~inside].shape))
    assert abs(float(np.linalg.norm(light.direction)) - 1.0) < 1e-9
    assert light.direction[2] >= min_z - 1e-9
    assert light.albedo > 0 and light.ambient >= 0


def test_a_grazing_light_is_floored_to_min_z() -> None:
    # A sphere lit almost from the side: a free fit could put the light behind the surface;
    # the estimate keeps it at z >= min_z like every normal.
    size, radius = 64, 26.0
    inside = disc(size, (31.5, 31.5), radius)
    truth = sphere_normals(size, (31.5, 31.5), radius)
    s = np.array([1.0, 0.0, 0.02]) / np.linalg.norm([1.0, 0.0, 0.02])
    luma = np.where(inside, 0.8 * np.clip(truth @ s, 0.0, None), 0.0).astype(np.float32)
    _, light = estimate_surface(luma, inside, sigma=1.5, min_z=0.3)
    assert light.direction[2] >= 0.3 - 1e-9
    assert light.direction[0] > 0.5  # still from the right


@pytest.mark.parametrize("pixels", [1, 2, 3])
def test_a_tiny_silhouette_is_estimated_without_error(pixels: int) -> None:
    # Fewer than four inside pixels: no light can be fitted, the light is straight ahead.
    inside = np.zeros((5, 5), dtype=bool)
    inside[2, 1 : 1 + pixels] = True
    luma = np.where(inside, 0.6, 0.0).astype(np.float32)
    normals, light = estimate_surface(luma, inside, sigma=1.0, min_z=0.1)
    np.testing.assert_array_equal(light.direction, AHEAD)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=-1), 1.0, atol=1e-5)
    assert normals[..., 2].min() >= 0.1 - 1e-6


# --------------------------------------------------------------------------------------------
# decode_normal_map, encode_normal_map
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("channels", [1, 2])
def test_a_normal_map_needs_three_channels(channels: int) -> None:
    with pytest.raises(InvalidImageError, match="3") as caught:
        decode_normal_map(np.zeros((4, 4, channels), dtype=np.float32), integer=True)
    assert caught.value.parameter == "normals"


def test_integer_maps_decode_the_usual_colours() -> None:
    # (n + 1) / 2 per component: flat blue is facing the viewer, red is +x, green is +y (up).
    image = np.array(
        [[[0.5, 0.5, 1.0], [1.0, 0.5, 0.5], [0.5, 1.0, 0.5], [0.0, 0.5, 0.5]]], dtype=np.float32
    )
    got = decode_normal_map(image, integer=True)
    assert got.dtype == np.float32
    want = [[[0, 0, 1], [1, 0, 0], [0, 1, 0], [-1, 0, 0]]]
    np.testing.assert_allclose(got, want, atol=1e-6)


def test_float_maps_are_the_components_normalized() -> None:
    rng = np.random.default_rng(16)
    vectors = rng.normal(size=(6, 7, 3)).astype(np.float32) * 3.0
    got = decode_normal_map(vectors, integer=False)
    lengths = np.sqrt(np.sum(vectors.astype(np.float64) ** 2, axis=-1, keepdims=True))
    np.testing.assert_allclose(got, vectors / lengths, atol=1e-6)


@pytest.mark.parametrize("integer", [True, False])
def test_zero_vectors_face_the_viewer_and_alpha_is_ignored(integer: bool) -> None:
    rng = np.random.default_rng(17)
    zero = 0.5 if integer else 0.0  # what encodes the zero vector in each convention
    image = rng.random((5, 5, 4)).astype(np.float32)
    image[1, 2, :3] = zero
    got = decode_normal_map(image, integer)
    np.testing.assert_array_equal(got[1, 2], AHEAD)
    np.testing.assert_allclose(np.linalg.norm(got, axis=-1), 1.0, atol=1e-5)
    # The alpha channel says nothing of the normal: another alpha, the same normals.
    other = image.copy()
    other[..., 3] = rng.random((5, 5))
    np.testing.assert_array_equal(decode_normal_map(other, integer), got)
    np.testing.assert_array_equal(decode_normal_map(image[..., :3].copy(), integer), got)


def test_encode_clips_out_of_range_components() -> None:
    got = encode_normal_map(np.array([[[1.5, -1.5, 0.0]]], dtype=np.float32))
    assert got.dtype == np.uint8
    np.testing.assert_array_equal(got, [[[255, 0, 128]]])
