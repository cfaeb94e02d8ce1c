"""Texture matting (the alpha quilting and texture matting paper, §3): layers of texture laid
on a surface seen in an image.

The surface's pixels are grouped by k-means on (nx, ny, nz, x, y); each connected part of a
cluster is one patch. A patch takes its texture from the layer as if the texture lay on the
plane of the patch's mean normal, seen from the front: the texture's axes are the image's x
axis and its perpendicular turned into that plane, so the texture is rotated with the plane
and foreshortened by n_z along the tilt. Each pixel's colour is then shaded by its own normal,
``ambient + (1 - ambient) max(n · S, 0)``, and the layers are laid over the target in order,
by their alpha times the silhouette's coverage.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from scipy.cluster.vq import kmeans2

from quilting.core.shading import (
    Light,
    clamp_z,
    encode_normal_map,
    estimate_surface,
    fit_light,
    inside_of,
    lit_pixels,
    masked_blur,
    unit,
)
from quilting.core.synthesis import Result

#: At most this many pixels fit the k-means centres; every pixel is then assigned to one.
FIT_SAMPLE = 20_000
#: Pixels assigned per step (bounds the (pixels, k) distance matrix).
ASSIGN_CHUNK = 65_536


@dataclass(frozen=True)
class Patches:
    """The surface cut into patches.

    Attributes
    ----------
    clusters : ndarray, shape (H, W), int32
        k-means cluster of each pixel, -1 outside the silhouette.
    patches : ndarray, shape (H, W), int32
        Patch of each pixel (a connected part of one cluster), -1 outside.
    normals : ndarray, shape (P, 3), float64
        Each patch's mean normal, unit length, z at least the floor.
    anchors : ndarray, shape (P, 2), float64
        Each patch's centroid as (row, col): where its texture lines up with the layer's.
    """

    clusters: NDArray[np.int32]
    patches: NDArray[np.int32]
    normals: NDArray[np.float64]
    anchors: NDArray[np.float64]


def cluster_surface(
    normals: NDArray[np.float32],
    inside: NDArray[np.bool_],
    clusters: int,
    spatial_weight: float,
    rng: np.random.Generator,
) -> NDArray[np.int32]:
    """k-means of the inside pixels on (nx, ny, nz, x, y).

    Parameters
    ----------
    normals : ndarray, shape (H, W, 3)
    inside : ndarray, shape (H, W), bool
    clusters : int
        k; fewer when there are fewer distinct pixels.
    spatial_weight : float
        Positions are scaled to 0..spatial_weight over the silhouette's longer side.
    rng : numpy Generator
        Draws the fitting sample and the k-means++ start.

    Returns
    -------
    ndarray, shape (H, W), int32
        Cluster per pixel, numbered 0..k'-1 with none empty, -1 outside.
    """
    rows, cols = np.nonzero(inside)
    extent = max(int(np.ptp(rows)), int(np.ptp(cols)), 1)
    features = np.empty((rows.size, 5), dtype=np.float64)
    features[:, :3] = normals[rows, cols]
    features[:, 3] = cols * (spatial_weight / extent)
    features[:, 4] = rows * (spatial_weight / extent)
    k = min(clusters, rows.size)
    sample = features
    if rows.size > FIT_SAMPLE:
        sample = features[np.sort(rng.choice(rows.size, FIT_SAMPLE, replace=False))]
    with warnings.catch_warnings():
        # An empty cluster is dropped below; scipy's warning about it says nothing more.
        warnings.simplefilter("ignore", UserWarning)
        centres, _ = kmeans2(sample, k, iter=10, minit="++", seed=rng)
    assigned = np.empty(rows.size, dtype=np.int64)
    # |f - c|^2 = |f|^2 - 2 f.c + |c|^2; |f|^2 is the same for every centre, so it drops out
    # and a chunk needs one (chunk, k) matrix.
    reach = (centres**2).sum(axis=1)
    for start in range(0, rows.size, ASSIGN_CHUNK):
        chunk = features[start : start + ASSIGN_CHUNK]
        assigned[start : start + ASSIGN_CHUNK] = (reach - 2.0 * chunk @ centres.T).argmin(axis=1)
    _, dense = np.unique(assigned, return_inverse=True)
    labels = np.full(inside.shape, -1, dtype=np.int32)
    labels[rows, cols] = dense.astype(np.int32)
    return labels


def split_patches(
    clusters: NDArray[np.int32], normals: NDArray[np.float32], min_z: float
) -> Patches:
    """Cut each cluster into its connected parts (8-connected), with their normals and anchors.

    Parameters
    ----------
    clusters : ndarray, shape (H, W), int32
        From :func:`cluster_surface`.
    normals : ndarray, shape (H, W, 3)
    min_z : float
        Floor of the mean normals' z.

    Returns
    -------
    Patches
    """
    patches = np.full(clusters.shape, -1, dtype=np.int32)
    count = 0
    eight = np.ones((3, 3), dtype=bool)
    for cluster in range(int(clusters.max()) + 1):
        parts, found = ndimage.label(clusters == cluster, structure=eight)
        where = parts > 0
        patches[where] = parts[where] - 1 + count
        count += found
    inside = patches >= 0
    index = patches[inside]
    weights = np.bincount(index, minlength=count).astype(np.float64)
    covered = normals[inside].astype(np.float64)
    sums = np.stack(
        [np.bincount(index, covered[:, axis], minlength=count) for axis in range(3)], axis=1
    ).astype(np.float64)
    mean = clamp_z(unit(sums), min_z)
    rows, cols = np.nonzero(inside)
    anchors = np.stack(
        [np.bincount(index, rows, minlength=count), np.bincount(index, cols, minlength=count)],
        axis=1,
    ) / weights[:, None].clip(1.0)
    return Patches(clusters, patches, mean, anchors)


def plane_maps(normals: NDArray[np.float64]) -> NDArray[np.float64]:
    """Per patch, the linear map from an image offset (dx, dy) to texture coordinates (u, v).

    The offset is lifted onto the plane through the patch with normal m,
    ``P = (dx, dy, -(m_x dx + m_y dy) / m_z)``, and read in the plane's basis
    ``e1 = normalize(x - (x · m) m)``, ``e2 = m cross e1``: lengths along the tilt grow by
    ``1 / m_z`` (the foreshortening undone) and the texture turns with the plane.

    Parameters
    ----------
    normals : ndarray, shape (P, 3)
        Unit normals with z > 0.

    Returns
    -------
    ndarray, shape (P, 2, 2)
        ``[u, v] = maps[p] @ [dx, dy]`` (y up, v up).
    """
    m = normals
    e1 = np.stack([1.0 - m[:, 0] ** 2, -m[:, 0] * m[:, 1], -m[:, 0] * m[:, 2]], axis=1)
    e1 = unit(e1)
    e2 = np.cross(m, e1)
    # dP/d(dx) = (1, 0, -m_x / m_z) and dP/d(dy) = (0, 1, -m_y / m_z).
    lift = np.zeros((m.shape[0], 3, 2))
    lift[:, 0, 0] = 1.0
    lift[:, 1, 1] = 1.0
    lift[:, 2, 0] = -m[:, 0] / m[:, 2]
    lift[:, 2, 1] = -m[:, 1] / m[:, 2]
    basis = np.stack([e1, e2], axis=1)  # (P, 2, 3)
    maps: NDArray[np.float64] = basis @ lift
    return maps


def texture_coordinates(patches: Patches, scale: float) -> NDArray[np.float64]:
    """Where each inside pixel reads its layers, as (row, col) in layer pixels.

    Parameters
    ----------
    patches : Patches
    scale : float
        Target pixels per texture pixel on a surface facing the viewer.

    Returns
    -------
    ndarray, shape (2, N), float64
        Layer (row, col) of the N inside pixels in ``np.nonzero(patches.patches >= 0)``
        order; the layers are tileable, so any value wraps.
    """
    rows, cols = np.nonzero(patches.patches >= 0)
    index = patches.patches[rows, cols]
    anchor = patches.anchors[index]
    dx = cols - anchor[:, 1]
    dy = anchor[:, 0] - rows  # y up
    maps = plane_maps(patches.normals)[index]
    u = maps[:, 0, 0] * dx + maps[:, 0, 1] * dy
    v = maps[:, 1, 0] * dx + maps[:, 1, 1] * dy
    # The anchor keeps each patch's texture at its own place (neighbours line up near it).
    return np.stack([anchor[:, 0] - v, anchor[:, 1] + u]) / scale


def sample_layer(
    layer: NDArray[np.float32], coordinates: NDArray[np.float64]
) -> NDArray[np.float32]:
    """Bilinear samples of a tileable layer, premultiplied by its alpha.

    Parameters
    ----------
    layer : ndarray, shape (h, w, 4), float32
        RGBA in [0, 1], straight (not premultiplied) colour.
    coordinates : ndarray, shape (2, N)
        (row, col) per sample; wraps around the layer.

    Returns
    -------
    ndarray, shape (N, 4), float32
        Premultiplied RGB and alpha, so colour under clear pixels does not bleed in.
    """
    premultiplied = layer.copy()
    premultiplied[..., :3] *= layer[..., 3:4]
    samples = np.empty((coordinates.shape[1], 4), dtype=np.float32)
    for channel in range(4):
        samples[:, channel] = ndimage.map_coordinates(
            premultiplied[..., channel], coordinates, order=1, mode="grid-wrap"
        )
    return samples


def lambert(
    normals: NDArray[np.float32], light: NDArray[np.float64], ambient: float
) -> NDArray[np.float32]:
    """Shading ``ambient + (1 - ambient) max(n · S, 0)`` per normal.

    Parameters
    ----------
    normals : ndarray, shape (..., 3)
    light : ndarray, shape (3,)
        Unit direction towards the light.

    Returns
    -------
    ndarray, shape (...), float32
    """
    facing = np.clip(normals @ light.astype(np.float32), 0.0, 1.0)
    shade: NDArray[np.float32] = (ambient + (1.0 - ambient) * facing).astype(np.float32)
    return shade


def composite(
    base: NDArray[np.float32],
    layers: list[NDArray[np.float32]],
    where: tuple[NDArray[np.intp], NDArray[np.intp]],
    cover: NDArray[np.float32],
    shade: NDArray[np.float32],
) -> NDArray[np.float32]:
    """Lay premultiplied layer samples over ``base``, first layer lowest ("over" operator).

    Parameters
    ----------
    base : ndarray, shape (H, W, 4), float32
        The target as RGBA (straight colour).
    layers : list of ndarray, each shape (N, 4)
        Premultiplied samples at the pixels ``where``, bottom layer first.
    where : (rows, cols), each shape (N,)
    cover : ndarray, shape (N,)
        The silhouette's coverage there (scales each layer's alpha).
    shade : ndarray, shape (N,)
        Shading of the layers' colour there.

    Returns
    -------
    ndarray, shape (H, W, 4), float32
        Straight RGBA: outside ``where`` the base unchanged.
    """
    out = base.copy()
    colour = base[where][:, :3] * base[where][:, 3:4]
    alpha = base[where][:, 3].copy()
    for samples in layers:
        a = samples[:, 3] * cover
        colour = samples[:, :3] * (cover * shade)[:, None] + colour * (1.0 - a)[:, None]
        alpha = a + alpha * (1.0 - a)
    out[where[0], where[1], :3] = np.where(
        alpha[:, None] > 1e-6, colour / np.maximum(alpha, 1e-6)[:, None], 0.0
    )
    out[where[0], where[1], 3] = alpha
    return out


@dataclass(frozen=True)
class Surface:
    """The surface under the silhouette, as the layers are laid on it.

    Attributes
    ----------
    cover : ndarray, shape (H, W), float32
        Silhouette coverage in [0, 1].
    normals : ndarray, shape (H, W, 3), float32
        Unit normals (estimated or given), z at least the floor; (0, 0, 1) outside.
    light : Light
        Direction towards the light, with the fit's albedo and ambient.
    patches : Patches
        Clusters and patches, extended to partly covered pixels at the outline.
    """

    cover: NDArray[np.float32]
    normals: NDArray[np.float32]
    light: Light
    patches: Patches


def layer_size(cover: NDArray[np.float32], scale: float, block: int) -> tuple[int, int]:
    """The (height, width) each layer is quilted at: the covered bounding box over ``scale``,
    at least ``block`` (a tileable side's minimum)."""
    rows, cols = np.nonzero(cover > 0)
    height = int(np.ptp(rows)) + 1 if rows.size else 1
    width = int(np.ptp(cols)) + 1 if cols.size else 1
    return (
        max(int(np.ceil(height / scale)), block),
        max(int(np.ceil(width / scale)), block),
    )


def read_surface(
    luma: NDArray[np.float32],
    cover: NDArray[np.float32],
    *,
    normals: NDArray[np.float32] | None,
    light: NDArray[np.float64] | None,
    clusters: int,
    spatial_weight: float,
    smoothing: float,
    min_z: float,
    rng: np.random.Generator,
) -> Surface:
    """Normals, light and patches of the surface under ``cover``.

    Parameters
    ----------
    luma : ndarray, shape (H, W), float32
        The target's luminance.
    cover : ndarray, shape (H, W), float32
        Silhouette coverage; the surface is read where it is at least 0.5.
    normals : ndarray, shape (H, W, 3), optional
        Given unit normals: used instead of shape from shading (z still floored).
    light : ndarray, shape (3,), optional
        Given unit direction towards the light.
    clusters, spatial_weight, smoothing, min_z
        As in :class:`~quilting.core.options.MatteOptions`.
    rng : numpy Generator
        For k-means.
    """
    inside = inside_of(cover)
    if normals is None:
        normals, fitted = estimate_surface(luma, inside, sigma=smoothing, min_z=min_z, light=light)
    else:
        normals = clamp_z(normals, min_z)
        normals[~inside] = (0.0, 0.0, 1.0)
        smooth = masked_blur(luma, inside, smoothing)
        fitted = fit_light(smooth, normals, lit_pixels(smooth, inside), light)
    labels = cluster_surface(normals, inside, clusters, spatial_weight, rng)
    rim = (cover > 0) & ~inside
    if rim.any():
        # Partly covered outline pixels take the nearest inside pixel's cluster and normal.
        _, (near_r, near_c) = ndimage.distance_transform_edt(~inside, return_indices=True)
        rows, cols = np.nonzero(rim)
        source = (near_r[rows, cols], near_c[rows, cols])
        normals = normals.copy()
        normals[rows, cols] = normals[source]
        labels[rows, cols] = labels[source]
    patches = split_patches(labels, normals, min_z)
    return Surface(cover, normals, fitted, patches)


def lay_layers(
    target: NDArray[np.float32],
    layers: list[NDArray[np.float32]],
    surface: Surface,
    *,
    scale: float,
    ambient: float,
) -> NDArray[np.float32]:
    """The target with the quilted layers laid on its surface, first layer lowest.

    Parameters
    ----------
    target : ndarray, shape (H, W, 4), float32
        Straight RGBA.
    layers : list of ndarray, each shape (h, w, 4), float32
        Tileable RGBA layers (opaque ones with alpha 1).
    surface : Surface
    scale : float
        Target pixels per layer pixel.
    ambient : float
        Shading floor.

    Returns
    -------
    ndarray, shape (H, W, 4), float32
    """
    rows, cols = np.nonzero(surface.patches.patches >= 0)
    where = (rows, cols)
    coordinates = texture_coordinates(surface.patches, scale)
    shade = lambert(surface.normals[where], surface.light.direction, ambient)
    samples = [sample_layer(layer, coordinates) for layer in layers]
    return composite(target, samples, where, surface.cover[where], shade)


@dataclass
class MatteResult:
    """What texture matting returns.

    Attributes
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        The target with the layers laid on its surface: the target's size and dtype; RGB if
        the target or a layer has colour, gray otherwise, with alpha if the target has it.
        Where no layer is laid (outside the silhouette) the target's own values, as given.
    normals : ndarray, shape (H, W, 3), float32
        The surface normals used (x right, y up, z towards the viewer); (0, 0, 1) outside.
    clusters : ndarray, shape (H, W), int32
        The k-means cluster of each pixel, -1 outside the silhouette.
    patches : ndarray, shape (H, W), int32
        The patch (connected part of a cluster) of each pixel, -1 outside.
    light : tuple of float
        Unit direction towards the light (estimated, or the given one normalized).
    albedo, ambient_fit : float
        rho and a of the least-squares fit ``I = rho (n · S) + a`` over the lit pixels.
    layers : list of Result
        Each layer as quilted (tileable, the layer size), bottom first.
    timings : dict of str to float
        Seconds per stage: ``layers``, ``surface``, ``lay`` and ``total``.
    """

    image: NDArray[np.generic]
    normals: NDArray[np.float32]
    clusters: NDArray[np.int32]
    patches: NDArray[np.int32]
    light: tuple[float, float, float]
    albedo: float
    ambient_fit: float
    layers: list[Result]
    timings: dict[str, float]

    def normal_map(self) -> NDArray[np.uint8]:
        """The normals used as the usual 8-bit normal map, (H, W, 3) ``(n + 1) / 2``, +y up."""
        return encode_normal_map(self.normals)

    def patch_map(self) -> NDArray[np.uint8]:
        """The patches in distinct colours, (H, W, 3) uint8, black outside."""
        return cluster_colours(self.patches)


def cluster_colours(labels: NDArray[np.int32]) -> NDArray[np.uint8]:
    """Labels as distinct colours for looking at: black outside (-1).

    Parameters
    ----------
    labels : ndarray, shape (H, W), int
        Cluster or patch numbers, -1 outside.

    Returns
    -------
    ndarray, shape (H, W, 3), uint8
        Label k gets the hue ``k x golden angle``, so neighbouring numbers differ clearly.
    """
    count = int(labels.max()) + 1 if labels.size else 0
    hue = (np.arange(max(count, 1)) * 0.618033988749895) % 1.0
    # HSV with full saturation and value 0.9, as RGB.
    sector = hue[:, None] * 6.0 - np.array([0.0, 4.0, 2.0])
    rgb = 0.9 * (1.0 - 0.75 * np.clip(np.abs((sector % 6.0) - 3.0) - 1.0, 0.0, 1.0))
    palette = np.vstack([np.rint(rgb * 255).astype(np.uint8), np.zeros((1, 3), np.uint8)])
    image: NDArray[np.uint8] = palette[np.where(labels >= 0, labels, count if count else 1)]
    return image
