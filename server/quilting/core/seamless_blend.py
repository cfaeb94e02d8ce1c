"""Gradient-domain blending of the cuts :func:`quilting.core.seamless.make_tileable` leaves.

``make_tileable`` keeps the image inside four minimum-error cuts and fills outside them with
the image rolled by half its size: every output pixel ``O[p]`` is an input pixel
``I[s(p)]``. Across most edges of the output (a pixel and its right or lower neighbour, the
wrap included along a tiled axis) the two pixels are neighbours in the input too, and the
output's gradient there is the input's own. Across a *cut edge* they are not (their sources
are two different places of ``I``); a brightness gradient across the photograph then shows as a
step along the cut, since the rolled part comes from the other side of the picture.

The blend (Perez, Gangnet & Blake 2003) asks for a guidance field ``v`` equal to the output's
own gradients everywhere except on the cut edges, where it is the mean of the two sides'
gradients in the input: the edge ``p -> q`` (``q = p + e``) gets ``I[s(p) + e] - I[s(p)]``
from ``p``'s side and ``I[s(q)] - I[s(q) - e]`` from ``q``'s, each side counted where its
source pixel has that neighbour inside the input (one always does along ``make_tileable``'s
cuts; an edge with neither would keep its gradient). The output is ``O + c``, the
correction ``c`` the least-squares fit of ``grad(c)`` to ``d = v - grad(O)``, non-zero on the
cut edges only: ``laplacian(c) = div(d)``. A plain Poisson problem, not a screened one: a
brightness gradient across the photo cannot be periodic, so the step must be spread over the
whole period (the correction is a gentle ramp between the cuts, under ``step / side`` a
pixel), not merely softened near the cut.

Along a tiled axis the output is periodic, so that axis is solved on the circle: the discrete
Fourier transform diagonalizes its Laplacian, eigenvalues ``2 cos(2 pi k / N) - 2``. Along an
axis that does not tile (y for ``axes="x"``) the output has two free ends (no edge joins its
last row to its first), the Neumann problem, diagonalized by the type-II discrete cosine
transform, eigenvalues ``2 cos(pi k / N) - 2``. The zero frequency (the constant, the one
null vector of either) is set to 0: the correction has zero mean, so the image's mean
brightness is kept. Each channel is solved in float32 by ``scipy.fft`` (one worker), one
channel at a time, so that the blend's temporaries are a few float32 planes; the sources of
the cut edges, a few per row and column, are gathered sparsely.

Alpha is not blended: it is a coverage or cutout mask, not lighting. The correction reaches
every pixel of the image (it is a ramp between the cuts), so blending alpha would turn a clean
0/255 cutout into values a step or two off everywhere, and the cuts, chosen on every channel's
error, already join alpha where it matches. An RGBA image's alpha is therefore exactly
``blend="none"``'s.

References
----------
.. [1] P. Perez, M. Gangnet and A. Blake, "Poisson Image Editing", SIGGRAPH 2003, §2 (the
       guidance field and the Poisson equation ``laplacian(f) = div(v)``) and §3 (seamless
       cloning with a mixture of gradients; here the mean of both sides' source gradients).
.. [2] A. A. Efros and W. T. Freeman, "Image Quilting for Texture Synthesis and Transfer",
       SIGGRAPH 2001, §2.1 (the minimum-error boundary cuts whose steps this removes).
"""

from __future__ import annotations

import numpy as np
import scipy.fft as sfft
from numpy.typing import NDArray

from quilting.core.options import TileBlend

__all__ = [
    "BLEND_ROWS_PIXELS",
    "TileBlend",
    "blend_selection",
    "blended_channels",
    "cut_edges",
    "divergence",
    "periodic_axes",
    "poisson_correction",
]

#: Pixels per band of :func:`cut_edges`' comparisons (their temporaries are a few bytes a pixel).
BLEND_ROWS_PIXELS = 1 << 16
_SCALE = {"uint8": 255.0, "uint16": 65535.0}
_AXES_PERIODIC = {"both": (True, True), "x": (False, True), "y": (True, False)}


def periodic_axes(axes: str) -> tuple[bool, bool]:
    """Whether the output of ``make_tileable(axes=axes)`` is periodic along (y, x)."""
    return _AXES_PERIODIC[axes]


def blended_channels(channels: int) -> int:
    """How many leading channels are blended: all of them but an RGBA image's alpha."""
    return 3 if channels == 4 else channels


def cut_edges(
    source: NDArray[np.intp], axis: int, periodic: bool
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """The output's edges along ``axis`` whose two pixels are not neighbours in the input.

    Parameters
    ----------
    source : ndarray of intp, shape (H, W)
        Flat input index (``row * W + col``) of each output pixel.
    axis : int
        0: the edges from each pixel to the one below; 1: to the one on its right.
    periodic : bool
        Whether the output wraps along ``axis`` (then the last row or column's edges join it to
        the first).

    Returns
    -------
    p, q : ndarray of intp, shape (n,)
        Flat output indices of each cut edge's two pixels, ``q`` the one below or to the right
        of ``p`` (across the wrap: ``p`` in the last row or column, ``q`` in the first).

    An edge is natural when ``q``'s source is ``p``'s source's neighbour in the same direction
    (``+ W`` along y, ``+ 1`` along x without leaving the row). Compared a band of rows at a
    time: whole-image comparisons would take several bytes a pixel.
    """
    height, width = source.shape
    step = width if axis == 0 else 1
    last = height if periodic or axis == 1 else height - 1  # rows whose edges exist
    rows = max(1, BLEND_ROWS_PIXELS // max(width, 1))
    found_p: list[NDArray[np.intp]] = []
    found_q: list[NDArray[np.intp]] = []
    for top in range(0, last, rows):
        bottom = min(top + rows, last)
        here = source[top:bottom]
        if axis == 0:
            below = np.arange(top + 1, bottom + 1) % height
            # The input's pixel below (``+ W``); past the input's last row no index matches.
            natural = source[below] == here + step
            ys, xs = np.nonzero(~natural)
            p = (ys + top) * width + xs
            # Across the y wrap the pixel below is in row 0: ``p + W - H W``.
            q = p + np.where(below[ys] == 0, width - height * width, width)
        else:
            there = np.roll(here, -1, axis=1) if periodic else here[:, 1:]
            here = here if periodic else here[:, :-1]
            # ``+ 1`` is the next row's first pixel when the source is in the input's last column.
            natural = (there == here + 1) & (here % width != width - 1)
            ys, xs = np.nonzero(~natural)
            p = (ys + top) * width + xs
            q = p + np.where(xs == width - 1, 1 - width, 1)
        found_p.append(p.astype(np.intp))
        found_q.append(q.astype(np.intp))
    if not found_p:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty
    return np.concatenate(found_p), np.concatenate(found_q)


def divergence(
    pixels: NDArray[np.generic],
    source: NDArray[np.intp],
    edges: list[tuple[int, NDArray[np.intp], NDArray[np.intp]]],
    channel: int,
) -> NDArray[np.float32]:
    """``div(d)`` of one channel: the gradient change the blend asks for on the cut edges.

    Parameters
    ----------
    pixels : ndarray, shape (H * W, C), the input's dtype
        The input image, flat.
    source : ndarray of intp, shape (H, W)
        Flat input index of each output pixel.
    edges : list of (axis, p, q)
        The cut edges along each axis (:func:`cut_edges`).
    channel : int
        The channel.

    Returns
    -------
    ndarray of float32, shape (H, W)
        At each pixel, ``d`` on the edges leaving it (to the right, below) minus ``d`` on the
        edges entering it, in working units (integers divided by 255 or 65535).
    """
    height, width = source.shape
    flat = source.reshape(-1)
    scale = _SCALE.get(pixels.dtype.name, 1.0)
    rhs = np.zeros(height * width, dtype=np.float32)
    for axis, p, q in edges:
        if not p.size:
            continue
        step = width if axis == 0 else 1
        sp, sq = flat[p], flat[q]
        # Each side's own gradient, where its source pixel has the neighbour in the input.
        if axis == 0:
            has_p, has_q = sp // width < height - 1, sq // width > 0
        else:
            has_p, has_q = sp % width < width - 1, sq % width > 0

        def value(index: NDArray[np.intp]) -> NDArray[np.float64]:
            values: NDArray[np.float64] = pixels[index, channel].astype(np.float64) / scale
            return values

        at_p, at_q = value(sp), value(sq)
        side_p = np.where(has_p, value(np.where(has_p, sp + step, sp)) - at_p, 0.0)
        side_q = np.where(has_q, at_q - value(np.where(has_q, sq - step, sq)), 0.0)
        count = has_p.astype(np.float64) + has_q
        pasted = at_q - at_p
        guidance = np.where(count > 0, (side_p + side_q) / np.maximum(count, 1), pasted)
        change = (guidance - pasted).astype(np.float32)
        # Along one axis each pixel is the p of one edge and the q of one: plain fancy-indexed
        # adds are exact (no index twice in one of them).
        rhs[p] += change
        rhs[q] -= change
    return rhs.reshape(height, width)


def _eigenvalues(size: int, periodic: bool, count: int) -> NDArray[np.float64]:
    """The first ``count`` eigenvalues of the 1-D Laplacian on ``size`` points, in the order of
    the transform's coefficients: periodic (DFT) or free ends (Neumann, type-II DCT)."""
    k = np.arange(count, dtype=np.float64)
    angle = (2.0 * np.pi if periodic else np.pi) * k / size
    values: NDArray[np.float64] = 2.0 * np.cos(angle) - 2.0
    return values


def poisson_correction(
    rhs: list[NDArray[np.float32]], periodic: tuple[bool, bool]
) -> NDArray[np.float32]:
    """The zero-mean ``c`` with ``laplacian(c) = rhs`` on the output's grid.

    Parameters
    ----------
    rhs : list holding one ndarray of float32, shape (H, W)
        The divergence; the list is emptied, so that the array is freed once transformed.
    periodic : (bool, bool)
        Whether the grid wraps along y and along x; at least one does.

    Returns
    -------
    ndarray of float32, shape (H, W)
        The correction, mean 0. The 5-point Laplacian with wrapped neighbours along a
        periodic axis, and without the missing neighbour at a free end (Neumann).
    """
    plane = rhs.pop()
    height, width = plane.shape
    # The Fourier axis (real to half-complex) is a periodic one; the other is Fourier as well
    # when it wraps, else cosine (the real DCT runs first, on the real plane).
    fourier = 1 if periodic[1] else 0
    other = 1 - fourier
    if not periodic[other]:
        plane = sfft.dct(plane, type=2, axis=other, overwrite_x=True, workers=1)
    spectrum = sfft.rfft(plane, axis=fourier, workers=1)
    del plane
    if periodic[other]:
        spectrum = sfft.fft(spectrum, axis=other, overwrite_x=True, workers=1)
    sizes = (height, width)
    along = [
        _eigenvalues(sizes[a], periodic[a], spectrum.shape[a]).astype(np.float32) for a in (0, 1)
    ]
    spectrum[0, 0] = 0  # the constant: zero mean
    rows = max(1, BLEND_ROWS_PIXELS // max(spectrum.shape[1], 1))
    for top in range(0, spectrum.shape[0], rows):
        denominator = along[0][top : top + rows, None] + along[1][None, :]
        if top == 0:
            denominator[0, 0] = 1.0  # its numerator is 0 already
        spectrum[top : top + rows] /= denominator
    if periodic[other]:
        spectrum = sfft.ifft(spectrum, axis=other, overwrite_x=True, workers=1)
    plane = sfft.irfft(spectrum, n=sizes[fourier], axis=fourier, workers=1)
    del spectrum
    if not periodic[other]:
        plane = sfft.idct(plane, type=2, axis=other, overwrite_x=True, workers=1)
    result: NDArray[np.float32] = plane.astype(np.float32, copy=False)
    return result


def blend_selection(
    image: NDArray[np.generic], source: NDArray[np.intp], axes: str
) -> NDArray[np.generic]:
    """``image`` rearranged by ``source``, with the steps across its cuts blended away.

    Parameters
    ----------
    image : ndarray, shape (H, W, C)
        The input; uint8, uint16 or float.
    source : ndarray of intp, shape (H, W)
        Flat input index of each output pixel (what ``make_tileable`` chose).
    axes : {"both", "x", "y"}
        The tiled axes: the output is periodic along them, free at the ends of the other.

    Returns
    -------
    ndarray, shape (H, W, C), the input's dtype
        ``image[source]`` plus the correction, per blended channel (every channel but an
        RGBA image's alpha, which stays ``image[source]``); integers rounded and clipped to
        their range, floats as computed (not clipped).
    """
    height, width, channels = image.shape
    pixels = image.reshape(-1, channels)
    flat = source.reshape(-1)
    periodic = periodic_axes(axes)
    out = np.empty(image.shape, dtype=image.dtype)
    edges = [(axis, *cut_edges(source, axis, periodic[axis])) for axis in (0, 1)]
    integer = image.dtype.kind in "ui"
    scale = _SCALE.get(image.dtype.name, 1.0)
    for channel in range(channels):
        gathered = pixels[flat, channel].reshape(height, width)
        if channel >= blended_channels(channels) or not any(p.size for _, p, _ in edges):
            out[..., channel] = gathered
            continue
        correction = poisson_correction([divergence(pixels, source, edges, channel)], periodic)
        if integer:
            correction *= np.float32(scale)
            correction += gathered
            np.rint(correction, out=correction)
            np.clip(correction, 0, scale, out=correction)
            out[..., channel] = correction
        else:
            work = np.promote_types(image.dtype, np.float32)
            out[..., channel] = gathered.astype(work) + correction
    return out
