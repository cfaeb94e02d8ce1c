"""The surface under a silhouette, read from one image: normals and the light (the alpha quilting
and texture matting paper, §3).

Coordinates: x to the right, y up, z towards the viewer (the usual normal-map convention), so
a pixel at (row, col) sits at (x, y) = (col, -row).

The shape comes from shading. The luminance is smoothed inside the silhouette and its gradient
taken. A Lambertian surface that is locally spherical (Pentland's local model) has
``grad I ∝ S_xy - n_xy S_z / n_z``: the projection ``n_xy - (n_z / S_z) S_xy`` points against
the gradient. Together with the shading constraint ``n · S = (I - a) / rho`` this fixes the
normal at each pixel (:func:`shading_normals`; with the light straight ahead it reduces to
Textureshop's rule, the tilt against the gradient and ``n_z = I``).

Where the shading says little (attached shadow, flat luminance) the estimate leans on a prior
from the silhouette alone: its outline is an occluding contour, where normals lie in the image
plane, and the inside is inflated as the sphere whose outline passes there
(:func:`silhouette_normals`). The two are mixed by how strong the gradient is, smoothed, and
each lit normal turned to the nearest one that satisfies the shading exactly
(:func:`onto_shading`). The light is the least-squares fit of
``I = rho (n · S) + a`` over the lit pixels (:func:`fit_light`); light and normals are
estimated in turn, starting from the prior. Normals with z below ``min_z`` are raised to it and
renormalized, as the seed says.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from quilting.core.errors import InvalidImageError, InvalidParameterError

FloatT = TypeVar("FloatT", np.float32, np.float64)

#: Rounds of (light from normals, normals from light) after the silhouette's prior.
ROUNDS = 2
#: Refits of the light without the pixels the previous fit put in attached shadow.
SHADOW_REFITS = 2
#: Pixels darker than this fraction of the brightest are taken as shadow, not as n · S.
SHADOW = 0.05
#: A gradient this many times the typical one counts half as evidence of the tilt: the local
#: spherical model misreads anisotropic curvature, so the silhouette's prior keeps a say.
GRADIENT_FLOOR = 2.0


@dataclass(frozen=True)
class Light:
    """A distant light fitted to (or assumed for) a Lambertian image.

    Attributes
    ----------
    direction : ndarray, shape (3,)
        Unit vector towards the light (x right, y up, z towards the viewer).
    albedo : float
        rho in ``I = rho (n · S) + ambient``.
    ambient : float
        The constant term of that fit (light every point gets).
    """

    direction: NDArray[np.float64]
    albedo: float
    ambient: float

    def shading(self, luma: NDArray[np.float32]) -> NDArray[np.float32]:
        """What ``luma`` says of n · S under this light: ``(I - a) / rho`` in [0, 1]."""
        shade: NDArray[np.float32] = np.clip((luma - self.ambient) / self.albedo, 0.0, 1.0).astype(
            np.float32
        )
        return shade


def unit(vectors: NDArray[FloatT]) -> NDArray[FloatT]:
    """``vectors`` (..., K) scaled to unit length along the last axis (zero stays zero)."""
    length = np.linalg.norm(vectors, axis=-1, keepdims=True)
    scaled: NDArray[FloatT] = vectors / np.maximum(length, 1e-12).astype(vectors.dtype)
    return scaled


def coverage(silhouette: NDArray[np.float32]) -> NDArray[np.float32]:
    """How much of each pixel the silhouette covers, in [0, 1].

    Parameters
    ----------
    silhouette : ndarray, shape (H, W, C), float32 in [0, 1], C in 1, 3, 4
        White (or opaque white) inside, black (or transparent) outside; grey is partial.

    Returns
    -------
    ndarray, shape (H, W), float32
    """
    colour = silhouette[..., :3] if silhouette.shape[2] >= 3 else silhouette[..., :1]
    cover = colour.mean(axis=2)
    if silhouette.shape[2] == 4:
        cover = cover * silhouette[..., 3]
    result: NDArray[np.float32] = np.clip(cover, 0.0, 1.0).astype(np.float32)
    return result


def inside_of(cover: NDArray[np.float32]) -> NDArray[np.bool_]:
    """The pixels the surface is estimated over: covered at least half; refuses an empty one."""
    inside: NDArray[np.bool_] = cover >= 0.5
    if not inside.any():
        raise InvalidImageError(
            "silhouette has no pixel at least half white: it must mark the surface in white "
            "(or opaque) on black (or transparent)",
            parameter="silhouette",
        )
    return inside


def masked_blur(
    values: NDArray[np.float32], inside: NDArray[np.bool_], sigma: float
) -> NDArray[np.float32]:
    """Gaussian blur of ``values`` using only the inside pixels (normalized convolution).

    Parameters
    ----------
    values : ndarray, shape (H, W) or (H, W, K)
    inside : ndarray, shape (H, W), bool
    sigma : float
        In pixels; 0 returns ``values`` unchanged.

    Returns
    -------
    ndarray, the shape of ``values``
        Defined a few sigma beyond the inside too (extrapolated from it), so that gradients
        at the outline do not see the outside.
    """
    if sigma <= 0:
        return values.astype(np.float32, copy=True)
    weight = inside.astype(np.float32)
    spread = (sigma, sigma) + (0,) * (values.ndim - 2)
    mask = weight if values.ndim == 2 else weight[..., None]
    total = ndimage.gaussian_filter(values * mask, spread, mode="nearest")
    norm = ndimage.gaussian_filter(mask, spread, mode="nearest")
    blurred: NDArray[np.float32] = np.where(
        norm > 1e-4, total / np.maximum(norm, 1e-4), values
    ).astype(np.float32)
    return blurred


def silhouette_normals(inside: NDArray[np.bool_]) -> NDArray[np.float32]:
    """Normals of the silhouette inflated as spheres: the prior where shading says little.

    Each connected part of radius R (its largest distance to the outline) gets the height
    ``h = sqrt(2 R d - d^2)``, d the distance to the outline: exactly a sphere for a disc,
    a rounded ridge along the medial axis otherwise. Where the silhouette runs off the image
    the surface is taken to go on.

    Parameters
    ----------
    inside : ndarray, shape (H, W), bool

    Returns
    -------
    ndarray, shape (H, W, 3), float32
        Unit normals; (0, 0, 1) outside and where the silhouette has no outline.
    """
    normals = np.zeros((*inside.shape, 3), dtype=np.float32)
    normals[..., 2] = 1.0
    if inside.all():
        return normals
    distance = ndimage.distance_transform_edt(inside)
    parts, count = ndimage.label(inside)
    radius = np.zeros(count + 1)
    radius[1:] = ndimage.maximum(distance, parts, np.arange(1, count + 1))
    r = radius[parts]
    height = np.sqrt(np.clip(2.0 * r * distance - distance**2, 0.0, None))
    d_row, d_col = np.gradient(height)
    # n ∝ (-dh/dx, -dh/dy, 1) with x = col and y = -row.
    raw = np.stack([-d_col, d_row, np.ones_like(height)], axis=-1)
    normals[inside] = unit(raw)[inside]
    return normals


def luminance_gradient(
    luma: NDArray[np.float32], inside: NDArray[np.bool_], sigma: float
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """The luminance smoothed inside the silhouette and its gradient in (x, y).

    Returns
    -------
    smooth : ndarray, shape (H, W), float32
    gradient : ndarray, shape (H, W, 2), float32
        dI/dx and dI/dy per pixel (y up).
    """
    smooth = masked_blur(luma, inside, sigma)
    d_row, d_col = np.gradient(smooth)
    gradient: NDArray[np.float32] = np.stack([d_col, -d_row], axis=-1).astype(np.float32)
    return smooth, gradient


def lit_pixels(luma: NDArray[np.float32], inside: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Inside pixels bright enough to be shaded by the light rather than in its shadow."""
    values = luma[inside]
    peak = float(np.percentile(values, 99)) if values.size else 0.0
    lit: NDArray[np.bool_] = inside & (luma > SHADOW * peak)
    return lit


def fit_light(
    luma: NDArray[np.float32],
    normals: NDArray[np.float32],
    where: NDArray[np.bool_],
    direction: NDArray[np.float64] | None = None,
) -> Light:
    """Least-squares fit of ``I = rho (n · S) + a`` over ``where``.

    Parameters
    ----------
    luma : ndarray, shape (H, W)
    normals : ndarray, shape (H, W, 3)
    where : ndarray, shape (H, W), bool
        The lit pixels (a shadowed one would ask for n · S < 0).
    direction : ndarray, shape (3,), optional
        A known light: only rho and a are fitted.

    Returns
    -------
    Light
        With ``a >= 0`` (refitted without it when the free fit made it negative), and the
        light straight ahead when the image has no shading to fit.
    """
    n = normals[where].astype(np.float64)
    values = luma[where].astype(np.float64)
    if n.shape[0] < 4:
        return Light(direction if direction is not None else _AHEAD.copy(), 1.0, 0.0)
    if direction is not None:
        shade = n @ direction
        design = np.stack([shade, np.ones_like(shade)], axis=1)
        (albedo, ambient), *_ = np.linalg.lstsq(design, values, rcond=None)
        if ambient < 0:
            albedo, ambient = float(shade @ values) / max(float(shade @ shade), 1e-12), 0.0
        return Light(direction, max(float(albedo), 1e-6), float(ambient))
    fitted = _free_fit(n, values)
    # Pixels the fit puts in attached shadow (n . S <= 0) show only the ambient light: fitted
    # as n . S they would drag the light towards them. Refit without them.
    for _ in range(SHADOW_REFITS):
        facing = n @ fitted.direction > 0.0
        if facing.all() or facing.sum() < 4:
            break
        fitted = _free_fit(n[facing], values[facing])
    return fitted


def _free_fit(n: NDArray[np.float64], values: NDArray[np.float64]) -> Light:
    """Least squares of ``values = b . n + a`` with b = rho S free."""
    design = np.concatenate([n, np.ones((n.shape[0], 1))], axis=1)
    solution, *_ = np.linalg.lstsq(design, values, rcond=None)
    b, ambient = solution[:3], float(solution[3])
    if ambient < 0:
        b, *_ = np.linalg.lstsq(n, values, rcond=None)
        ambient = 0.0
    albedo = float(np.linalg.norm(b))
    if albedo < 1e-9:
        return Light(_AHEAD.copy(), 1.0, ambient)
    return Light((b / albedo).astype(np.float64), albedo, ambient)


_AHEAD = np.array([0.0, 0.0, 1.0])


def shading_normals(
    smooth: NDArray[np.float32], gradient: NDArray[np.float32], light: Light
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Normals from shading under a locally spherical surface, with how far to trust each.

    With ``i = (I - a) / rho`` and ``u`` the unit vector against the gradient, the normal is
    ``(a' S_xy + t u, a' S_z)`` with ``c = u · S_xy``, ``t = sqrt((1 - i^2) / (1 - c^2))`` and
    ``a' = i - t c``: the one unit vector with ``n · S = i`` whose ``n_xy - (n_z / S_z) S_xy``
    points along ``u`` (convex surfaces).

    Parameters
    ----------
    smooth : ndarray, shape (H, W)
        Smoothed luminance.
    gradient : ndarray, shape (H, W, 2)
        Its (x, y) gradient.
    light : Light

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit vectors (z may still be below the floor).
    trust : ndarray, shape (H, W), float32
        In [0, 1]: grows with the gradient's size (a faint gradient's direction is noise),
        0 in shadow (``i`` near 0 says only that n · S <= 0).
    """
    s = light.direction
    shade = light.shading(smooth)
    magnitude = np.linalg.norm(gradient, axis=-1)
    u = -gradient / np.maximum(magnitude, 1e-12)[..., None]
    c = u[..., 0] * s[0] + u[..., 1] * s[1]
    t = np.sqrt((1.0 - shade**2) / np.maximum(1.0 - c**2, 1e-3))
    along = shade - t * c
    normals = np.empty((*smooth.shape, 3), dtype=np.float32)
    normals[..., 0] = along * s[0] + t * u[..., 0]
    normals[..., 1] = along * s[1] + t * u[..., 1]
    normals[..., 2] = along * s[2]
    normals = unit(normals)
    moving = magnitude[magnitude > 0]
    typical = float(np.median(moving)) if moving.size else 1.0
    floor = GRADIENT_FLOOR * typical
    trust = (magnitude / (magnitude + floor + 1e-12)).astype(np.float32)
    trust[shade <= SHADOW] = 0.0
    return normals, trust


def onto_shading(
    normals: NDArray[np.float32],
    smooth: NDArray[np.float32],
    light: Light,
    lit: NDArray[np.bool_],
) -> NDArray[np.float32]:
    """Turn each lit normal to the nearest one with ``n · S = (I - a) / rho``."""
    s = light.direction.astype(np.float32)
    shade = light.shading(smooth)
    across = normals - (normals @ s)[..., None] * s
    turned = shade[..., None] * s + np.sqrt(1.0 - shade**2)[..., None] * unit(across)
    out: NDArray[np.float32] = np.where(lit[..., None], turned, normals).astype(np.float32)
    return out


def clamp_z(normals: NDArray[FloatT], min_z: float) -> NDArray[FloatT]:
    """Raise every normal's z to at least ``min_z`` and renormalize (the matting paper, §3.1).

    Parameters
    ----------
    normals : ndarray, shape (..., 3), float32 or float64

    Returns
    -------
    ndarray, shape (..., 3), the same dtype
        Unit vectors with z >= min_z.
    """
    out = normals.copy()
    low = out[..., 2] < min_z
    if low.any():
        # Keep the tilt's direction and set z exactly: (xy scaled, min_z) is then unit length.
        out[low, :2] = unit(out[low, :2]) * np.sqrt(1.0 - min_z**2)
        out[low, 2] = min_z
    return unit(out)


def estimate_surface(
    luma: NDArray[np.float32],
    inside: NDArray[np.bool_],
    *,
    sigma: float,
    min_z: float,
    light: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float32], Light]:
    """Normals and light of the surface under ``inside``, from the luminance alone.

    Parameters
    ----------
    luma : ndarray, shape (H, W), float32
    inside : ndarray, shape (H, W), bool
    sigma : float
        Smoothing of the luminance and of the normals, in pixels.
    min_z : float
        Floor of the normals' z.
    light : ndarray, shape (3,), optional
        A known unit direction towards the light; estimated otherwise.

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals inside, (0, 0, 1) outside.
    light : Light
    """
    prior = silhouette_normals(inside)
    smooth, gradient = luminance_gradient(luma, inside, sigma)
    lit = lit_pixels(smooth, inside)
    normals = prior
    fitted = fit_light(smooth, normals, lit, light)
    for _ in range(ROUNDS):
        shaded, trust = shading_normals(smooth, gradient, fitted)
        mixed = trust[..., None] * shaded + (1.0 - trust[..., None]) * prior
        mixed = masked_blur(mixed, inside, sigma)
        mixed = onto_shading(mixed, smooth, fitted, lit)
        normals = clamp_z(mixed, min_z)
        normals[~inside] = (0.0, 0.0, 1.0)
        fitted = fit_light(smooth, normals, lit, light)
    if light is None and fitted.direction[2] < min_z:
        # A fit that puts the light behind the surface cannot be shaded from: same floor.
        fitted = fit_light(smooth, normals, lit, clamp_z(fitted.direction, min_z))
    return normals, fitted


def unit_direction(value: tuple[float, float, float]) -> NDArray[np.float64]:
    """A given light direction as a unit vector (refusing the zero vector)."""
    vector = np.asarray(value, dtype=np.float64)
    length = float(np.linalg.norm(vector))
    if length < 1e-12:
        raise InvalidParameterError("light", value, "a non-zero [x, y, z] with z > 0")
    result: NDArray[np.float64] = vector / length
    return result


def decode_normal_map(image: NDArray[np.float32], integer: bool) -> NDArray[np.float32]:
    """A normal map given by the caller, as unit vectors.

    Parameters
    ----------
    image : ndarray, shape (H, W, C), float32, C in 3, 4 (alpha ignored)
        Working values of the map.
    integer : bool
        Whether it came as uint8/uint16: then encoded as ``(n + 1) / 2`` (the usual
        normal-map colours, +y up); floats are taken as the components themselves.

    Returns
    -------
    ndarray, shape (H, W, 3), float32
    """
    if image.shape[2] < 3:
        raise InvalidImageError(
            f"normals has {image.shape[2]} channel: a normal map needs 3 (RGB = x, y, z)",
            parameter="normals",
        )
    vectors = image[..., :3] * 2.0 - 1.0 if integer else image[..., :3].copy()
    # A zero vector points nowhere: taken as facing the viewer.
    blank = np.linalg.norm(vectors, axis=-1, keepdims=True) <= 1e-6
    decoded: NDArray[np.float32] = np.where(
        blank, np.array([0.0, 0.0, 1.0], dtype=np.float32), unit(vectors)
    ).astype(np.float32)
    return decoded


def encode_normal_map(normals: NDArray[np.float32]) -> NDArray[np.uint8]:
    """Normals as the usual 8-bit normal-map colours ``(n + 1) / 2`` (+y up).

    Parameters
    ----------
    normals : ndarray, shape (H, W, 3)

    Returns
    -------
    ndarray, shape (H, W, 3), uint8
    """
    encoded: NDArray[np.uint8] = np.rint((normals + 1.0) * 127.5).clip(0, 255).astype(np.uint8)
    return encoded
