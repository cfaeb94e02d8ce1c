"""Make an existing image tile seamlessly, keeping its size and its centre.

One pass along x: ``S = np.roll(I, W // 2, axis=1)`` tiles along x by construction (its border
columns ``W - 1`` and ``0`` are the neighbouring columns ``W - 1 - W // 2`` and ``W - W // 2`` of
``I``) but has a seam in its middle, between columns ``W // 2 - 1`` (``I``'s last column) and
``W // 2`` (``I``'s first). The output keeps ``I`` between two minimum-error boundary cuts
(Efros & Freeman 2001, the DP of :func:`quilting.core.seams.strip_cuts`) and ``S``
outside them. Each cut is the cheapest 8-connected top-to-bottom path through the error
``e = sum over channels of (I - S)^2`` (float64, integers scaled to [0, 1]) in its band: the left
cut lies in columns ``1 .. band``, the right one in ``W - 1 - band .. W - 2`` (the same DP on
the mirrored band). Column 0 and column ``W - 1`` are therefore always ``S``, so the wrap joins
``S`` to ``S``, and ``band <= W // 2 - 1`` keeps both cuts clear of ``S``'s middle seam, which is
therefore always covered by ``I``. A y pass is the same on the transposed image.

``axes="both"`` runs the x pass, then the y pass on its result. A single image rolled both
ways cannot do it: its seam is a cross whose arms run out to the borders, and any frame around
a kept centre would cross them. After the x pass the image tiles along x, so its vertical roll
does too, and the second pass only has to keep that: its two cuts are closed, starting and
ending in the same row (the cheaper of the free optimal cut's two end rows, pinned at both
ends), so that no cut crosses the x wrap. The kept centre is still the intersection of the four
half-planes of the cuts. Outside it, the side bands are ``I`` rolled by ``W // 2``; the top and
bottom bands are the x pass's result rolled by ``H // 2``: ``I`` rolled by ``H // 2`` between
copies of the vertical cuts, ``I`` rolled both ways beyond them (the corners). The y wrap thus
crosses the vertical cuts like any other line of the image does.

With ``blend="none"`` every output pixel is an input pixel (pure selection, any dtype,
deterministic); the result records where each came from, so ``companion[t.source_rows,
t.source_cols]`` makes a companion map (normal, roughness...) tileable the same way. With
``blend="poisson"`` (the default) the same selection is then blended across its cuts in the
gradient domain (:mod:`quilting.core.seamless_blend`): a brightness gradient across the
photograph no longer shows as steps along the cuts. The pixels are then no longer copies;
``source_rows``/``source_cols`` still say where each one's texture came from, and
:meth:`Tiled.apply` makes a companion map the same way, blended or not.

References
----------
.. [1] A. A. Efros and W. T. Freeman, "Image Quilting for Texture Synthesis and Transfer",
       SIGGRAPH 2001, §2.1 (the minimum-error boundary cut).
.. [2] P. Perez, M. Gangnet and A. Blake, "Poisson Image Editing", SIGGRAPH 2003, §2-3 (the
       blend of ``blend="poisson"``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, Protocol

import numpy as np
from numpy.typing import NDArray

from quilting.core.errors import InvalidImageError, InvalidParameterError
from quilting.core.layout import COMPANION_KINDS, renormalize
from quilting.core.options import TILE_BLENDS, TileBlend
from quilting.core.pixels import as_channels, from_working, to_working
from quilting.core.seamless_blend import blend_selection
from quilting.core.seams import strip_cuts
from quilting.core.sources import NORMAL_KINDS

__all__ = [
    "BAND_PIXELS",
    "MIN_SIDE",
    "TILE_BLENDS",
    "Axes",
    "TileBlend",
    "Tiled",
    "band_limit",
    "check_tiling",
    "make_tileable",
]

Axes = Literal["both", "x", "y"]

#: Smallest tiled side: two one-pixel bands between the two border pixels.
MIN_SIDE = 4
_AXES = ("both", "x", "y")
_SCALE = {"uint8": 255.0, "uint16": 65535.0}
#: Pixels per band of :func:`_error`: its temporaries are ``16 C`` bytes a pixel of one band.
BAND_PIXELS = 1 << 16


class CompanionReplay(Protocol):
    """How a tileable image made otherwise than by the cuts (``method="fill"``) is made
    again from a companion map: ``replay(companion (H, W, C), normal=...)`` returns the
    companion made tileable and blended as the image was, in its dtype."""

    def __call__(
        self, companion: NDArray[np.generic], *, normal: bool = False
    ) -> NDArray[np.generic]: ...


@dataclass(frozen=True)
class Tiled:
    """An image made tileable, and how.

    Attributes
    ----------
    image : ndarray, shape (H, W, C) (or (H, W) for a 2-D input), the input's dtype
        The tileable image; with ``blend="none"`` every pixel is a copy of an input pixel, with
        ``"poisson"`` that copy plus the blend's smooth correction (alpha excepted).
    kept : ndarray of bool, shape (H, W)
        Pixels whose source is the input's own pixel at their own place (the centre between
        the cuts); with ``blend="poisson"`` their values carry the correction too.
    seam_cols : ndarray of intp, shape (2, H)
        Left and right cut column at each row; ``0`` and ``W - 1`` when x is not tiled.
    seam_rows : ndarray of intp, shape (2, W)
        Top and bottom cut row at each column; ``0`` and ``H - 1`` when y is not tiled.
        ``kept[y, x]`` iff ``seam_cols[0, y] <= x <= seam_cols[1, y]`` and
        ``seam_rows[0, x] <= y <= seam_rows[1, x]``.
    source_rows, source_cols : ndarray of intp, shape (H, W)
        Input pixel that each output pixel is a copy of (before the blend, if any).
    seam_error : float
        Mean over the cut pixels of the squared difference, summed over channels, between the
        two images the cut separates, in working units (integers divided by 255 or 65535).
    axes : {"both", "x", "y"}
        The tiled axes.
    blend : {"none", "poisson"}
        How the cuts were joined (:data:`TILE_BLENDS`).
    replay : CompanionReplay or None
        For an image made tileable by filling (:mod:`quilting.core.seamless_fill`): the fill
        and its blend, done again to a companion. None: the cuts' blend
        (:func:`~quilting.core.seamless_blend.blend_selection`).
    """

    image: NDArray[np.generic]
    kept: NDArray[np.bool_]
    seam_cols: NDArray[np.intp]
    seam_rows: NDArray[np.intp]
    source_rows: NDArray[np.intp]
    source_cols: NDArray[np.intp]
    seam_error: float
    axes: Axes = "both"
    blend: TileBlend = "none"
    replay: CompanionReplay | None = field(default=None, repr=False, compare=False)

    def apply(self, companion: object, kind: str = "blend") -> NDArray[np.generic]:
        """Make a companion map (normal, roughness, height, mask...) tileable the same way.

        Parameters
        ----------
        companion : ndarray, shape (H, W) or (H, W, C)
            The image's size; uint8, uint16 or float, C in 1, 3, 4.
        kind : {'blend', 'hard', 'normal'}
            What the values are (:data:`~quilting.core.layout.COMPANION_KINDS`, as for
            :func:`~quilting.core.layout.apply_layout`): 'blend' is treated like the image,
            its cuts blended when the image's were (from the companion's own gradients);
            'hard' never mixes values (masks, material IDs): the same selection, unblended;
            'normal' like 'blend', then the first three channels (a tangent-space normal,
            each in [0, 1] for [-1, 1]) made unit vectors again where the blend changed them.
            With ``blend="none"`` every kind is the same selection.

        Returns
        -------
        ndarray, the companion's shape and dtype
        """
        if kind not in COMPANION_KINDS:
            raise InvalidParameterError("kind", kind, f"one of {', '.join(COMPANION_KINDS)}")
        view, fmt = as_channels(companion, "companion")
        if view.shape[:2] != self.source_rows.shape:
            height, width = self.source_rows.shape
            raise InvalidImageError(
                f"companion of {view.shape[1]}x{view.shape[0]} pixels does not match the "
                f"tiled image's {width}x{height}: a companion map must have the image's size"
            )
        channels = view.shape[2]
        if kind in NORMAL_KINDS and channels < 3:
            raise InvalidParameterError(
                "kind",
                kind,
                "'blend' or 'hard' for a map of fewer than 3 channels",
                f"a {kind!r} companion needs 3 or 4 channels (x, y, z), got {channels}",
            )
        source = self.source_rows * view.shape[1] + self.source_cols
        if self.blend == "none" or kind == "hard":
            selected = view.reshape(-1, channels)[source].reshape(view.shape)
            return fmt.restore(selected)
        if self.replay is not None:
            return fmt.restore(self.replay(view, normal=kind in NORMAL_KINDS))
        if kind == "blend":
            return fmt.restore(blend_selection(view, source, self.axes))
        # A normal map: blended in working units, so that the unit vectors can be remade
        # before the one rounding back to the map's dtype.
        # float32 in, float32 out: the cast copies nothing.
        canvas = blend_selection(to_working(view), source, self.axes).astype(np.float32, copy=False)
        renormalize(canvas)
        converted = from_working(canvas, view.dtype)
        return fmt.restore(canvas.astype(view.dtype) if converted is None else converted)


def band_limit(side: int) -> int:
    """Widest band for a tiled side: both bands and the middle seam's two columns must fit."""
    return side // 2 - 1


def check_tiling(shape: tuple[int, int], axes: str, band: object) -> list[str]:
    """The tiled axes (``"x"``, ``"y"``) of an image of ``shape`` (H, W), after checking that
    each tiled side has :data:`MIN_SIDE` pixels and that an explicit ``band`` fits every one
    (:func:`band_limit`); both methods of :func:`quilting.make_tileable` refuse the same way.

    Raises
    ------
    InvalidImageError
        A tiled side is too short.
    InvalidParameterError
        ``band`` is no integer, or too wide for a tiled side.
    """
    height, width = shape
    sides = {"x": width, "y": height}
    tiled = ["x", "y"] if axes == "both" else [axes]
    for axis in tiled:
        if sides[axis] < MIN_SIDE:
            raise InvalidImageError(
                f"image of {width}x{height} pixels is too small to tile along {axis}: its "
                f"{'width' if axis == 'x' else 'height'} is {sides[axis]}, at least "
                f"{MIN_SIDE} pixels are needed"
            )
    if band is not None:
        limit = min(band_limit(sides[axis]) for axis in tiled)
        if isinstance(band, bool) or not isinstance(band, int | np.integer):
            raise InvalidParameterError("band", band, f"an integer in 1..{limit}")
        if not 1 <= band <= limit:
            raise InvalidParameterError(
                "band",
                band,
                f"1..{limit}",
                "each band plus the rolled image's middle seam must fit in the tiled side "
                f"(band <= side // 2 - 1 for the sides {', '.join(map(str, sides.values()))})",
            )
    return tiled


def _cuts(
    strips: NDArray[np.float64], closed: bool
) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """Cheapest 8-connected paths down each strip.

    Parameters
    ----------
    strips : ndarray, shape (n, L, O)
        Error along each band, stage (row) first.
    closed : bool
        Force each path to end at the position it starts at.

    Returns
    -------
    positions : ndarray of intp, shape (n, L)
        Column of each path in its strip, ``0 .. O - 1``.
    cost : ndarray of float64, shape (n,)
        Sum of the strip's error along each path.
    """
    n, _, width = strips.shape
    if closed:
        free, _ = _cuts(strips, closed=False)
        # Pinning costs a second DP; trying both end rows of the free cut makes a poor pin,
        # and so a needlessly expensive closed cut, less likely.
        pins = np.stack([free[:, 0], free[:, -1]], axis=1).reshape(-1)
        pinned = np.repeat(strips, 2, axis=0)
        elsewhere = np.arange(width) != pins[:, None]
        pinned[:, 0][elsewhere] = np.inf
        pinned[:, -1][elsewhere] = np.inf
        positions, cost = _cuts(pinned, closed=False)
        best = cost.reshape(n, 2).argmin(axis=1) + 2 * np.arange(n)
        return positions[best], cost[best]
    return strip_cuts(strips)


def _error(pixels: NDArray[np.float64], source: NDArray[np.intp], axis: int) -> NDArray[np.float64]:
    """Squared difference, summed over channels, between the image and itself rolled by half
    its size along ``axis``.

    Parameters
    ----------
    pixels : ndarray of float64, shape (h * w, C)
        The input's pixels, in working units.
    source : ndarray of intp, shape (h, w)
        Flat input index of each pixel of the image so far.
    axis : int
        0 (y) or 1 (x).

    Returns
    -------
    ndarray of float64, shape (h, w)

    Gathered a band of rows at a time: the image so far and its roll in float64 would be
    ``16 C`` bytes a pixel (a 5000x5000 RGB image: 3 GB), the band's are a few MiB. Every value
    is the same as the whole-image expression's.
    """
    rolled = np.roll(source, source.shape[axis] // 2, axis=axis)
    error = np.empty(source.shape, dtype=np.float64)
    rows = max(1, BAND_PIXELS // max(source.shape[1], 1))
    for top in range(0, source.shape[0], rows):
        band = pixels[source[top : top + rows]]
        band -= pixels[rolled[top : top + rows]]
        np.square(band, out=band)
        band.sum(axis=2, out=error[top : top + rows])
    return error


def _x_pass(
    error: NDArray[np.float64], source: NDArray[np.intp], band: int, closed: bool
) -> tuple[NDArray[np.intp], NDArray[np.intp], float]:
    """One pass along x.

    Parameters
    ----------
    error : ndarray of float64, shape (h, w)
        :func:`_error` of the image so far along x.
    source : ndarray of intp, shape (h, w)
        Flat input index of each of its pixels.
    band : int
        Band width.
    closed : bool
        Whether the cuts must end in the row they start in.

    Returns
    -------
    source : ndarray of intp, shape (h, w)
        The new source map.
    cut : ndarray of intp, shape (2, h)
        Left and right cut column at each row.
    cost : float
        Error summed along both cuts.
    """
    width = source.shape[1]
    # The right band mirrored, so that the one DP (leftmost band column = outermost) serves both.
    strips = np.stack([error[:, 1 : band + 1], error[:, width - 2 : width - 2 - band : -1]])
    positions, cost = _cuts(strips, closed)
    cut = np.stack([1 + positions[0], width - 2 - positions[1]])
    column = np.arange(width)
    inside = (column >= cut[0][:, None]) & (column <= cut[1][:, None])
    return np.where(inside, source, np.roll(source, width // 2, axis=1)), cut, float(cost.sum())


def make_tileable(
    view: object,
    *,
    axes: Axes = "both",
    band: int | None = None,
    blend: TileBlend = "poisson",
) -> Tiled:
    """Make an image tile seamlessly along x, y or both, same size, centre kept.

    Parameters
    ----------
    view : ndarray, shape (H, W, C) or (H, W)
        uint8, uint16 or float, C in 1, 3, 4. Every tiled side needs at least ``MIN_SIDE``
        pixels.
    axes : {"both", "x", "y"}
        Which wraps must be seamless ("x": the last column joins the first).
    band : int, optional
        Width of each band the cuts may wander in, ``1 .. band_limit(side)`` for every tiled
        side (``side // 2 - 1``). Default ``max(1, W // 4)`` along x and ``max(1, H // 4)``
        along y, so the middle half is always kept. A band wider than the other side (a wide,
        short strip tiled along x) is fine.
    blend : {"none", "poisson"}
        "none": the selection as the cuts leave it, every pixel an input pixel. "poisson": the
        selection then blended across its cuts in the gradient domain
        (:func:`quilting.core.seamless_blend.blend_selection`: the guidance field the
        output's own gradients except on the cut edges, the mean of both sides' input
        gradients there; a plain Poisson solve, periodic along the tiled axes); the image's
        mean and an RGBA image's alpha are kept. The cuts are the same either way.

    Returns
    -------
    Tiled
        The image, the kept mask, the cuts and where every pixel came from.

    References
    ----------
    .. [1] P. Perez, M. Gangnet and A. Blake, "Poisson Image Editing", SIGGRAPH 2003, §2-3.
    """
    if axes not in _AXES:
        raise InvalidParameterError("axes", axes, "one of 'both', 'x', 'y'")
    if blend not in TILE_BLENDS:
        raise InvalidParameterError("blend", blend, f"one of {', '.join(map(repr, TILE_BLENDS))}")
    image, fmt = as_channels(view, "image")
    height, width, channels = image.shape
    sides = {"x": width, "y": height}
    tiled = check_tiling((height, width), axes, band)

    pixels = image.reshape(-1, channels).astype(np.float64)
    pixels /= _SCALE.get(image.dtype.name, 1.0)
    source = np.arange(height * width, dtype=np.intp).reshape(height, width)
    seam_cols = np.array([[0], [width - 1]]).repeat(height, axis=1)
    seam_rows = np.array([[0], [height - 1]]).repeat(width, axis=1)
    total, count = 0.0, 0
    for index, axis in enumerate(tiled):
        side = sides[axis]
        chosen = max(1, side // 4) if band is None else int(band)
        # The second pass must keep the first one's wrap: its cuts close on themselves.
        closed = index == 1
        # The error is gathered in the source map's own order (a transposed gather reads all
        # over memory), and the y pass is the x pass on its transpose.
        if axis == "x":
            source, seam_cols, cost = _x_pass(_error(pixels, source, 1), source, chosen, closed)
        else:
            error = _error(pixels, source, 0)
            transposed, seam_rows, cost = _x_pass(error.T, source.T, chosen, closed)
            source = transposed.T
        total += cost
        count += 2 * (height * width // side)
    del pixels  # the largest array (8 C bytes a pixel): gone before the outputs are made

    if blend == "poisson":
        # After the float64 copy is gone: the blend's planes (one channel at a time) then
        # stay under the cut search's peak.
        out = blend_selection(image, source, axes)
    else:
        out = image.reshape(-1, channels)[source].reshape(image.shape)
    rows, cols = np.divmod(source, width)
    here = np.arange(height * width).reshape(height, width)
    return Tiled(
        image=fmt.restore(out),
        kept=source == here,
        seam_cols=seam_cols.astype(np.intp),
        seam_rows=seam_rows.astype(np.intp),
        source_rows=rows,
        source_cols=cols,
        seam_error=total / count,
        axes=axes,
        blend=blend,
    )
