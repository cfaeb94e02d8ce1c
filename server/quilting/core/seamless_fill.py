"""Make an existing image tile by filling the band across each wrap (``method="fill"``).

The image rolled by half its size along a tiled axis tiles along it by construction (its
border pixels are neighbours in the image) but has a seam in its middle, where the image's
last column meets its first. Instead of hiding that seam inside minimum-error cuts of the
image against its rolled copy (:mod:`quilting.core.seamless`), this method forgets a band
``band`` pixels wide across it and synthesizes the band again by :func:`quilting.core.fill`
from the rest of the image, blocks matched on the known pixels of both sides; rolled back, the
re-synthesized bands lie across the wraps. With both axes the band is a cross, filled in one
go. This is how Embark's texture-synthesis makes an image tile (its inpainting across the
wrap), built on quilting's blocks and minimum cuts.

References
----------
.. [1] A. A. Efros and W. T. Freeman, "Image Quilting for Texture Synthesis and Transfer",
       SIGGRAPH 2001, §2.2.
.. [2] V. Kwatra, A. Schoedl, I. Essa, G. Turk and A. Bobick, "Graphcut Textures: Image and
       Video Synthesis Using Graph Cuts", SIGGRAPH 2003, §3.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import binary_dilation

from quilting.core.errors import InvalidImageError, InvalidParameterError
from quilting.core.fields import CostBackend
from quilting.core.fill import FillReplay, fill_image, largest_block
from quilting.core.options import FillOptions, TileOptions
from quilting.core.pixels import PixelFormat
from quilting.core.progress import Progress
from quilting.core.seamless import MIN_SIDE, Tiled, band_limit, check_tiling

#: Narrowest default band, in pixels.
MIN_BAND = 8


def fill_band(side: int, band: int | None) -> int:
    """The band's width on a side: ``band``, or a sixteenth of the side (at least
    :data:`MIN_BAND`), at most :func:`~quilting.core.seamless.band_limit`."""
    width = band if band is not None else max(MIN_BAND, side // 16)
    return max(1, min(width, band_limit(side)))


@dataclass(frozen=True)
class WrapReplay:
    """A fill of the rolled image, done again to a companion map: the companion rolled as the
    image was, filled by :meth:`FillReplay.render`, and rolled back."""

    fill: FillReplay
    shift: tuple[int, int]

    def __call__(
        self, companion: NDArray[np.generic], *, normal: bool = False
    ) -> NDArray[np.generic]:
        rolled = np.roll(companion, self.shift, axis=(0, 1))
        filled = self.fill.render(rolled, normal=normal)
        return np.roll(filled, (-self.shift[0], -self.shift[1]), axis=(0, 1))


def tile_by_filling(
    view: NDArray[np.generic],
    fmt: PixelFormat,
    options: TileOptions,
    backend: CostBackend,
    *,
    progress: Progress | None = None,
) -> Tiled:
    """Make ``view`` (H, W, C) tile along ``options.axes`` by re-synthesizing the bands across
    the wraps.

    Returns
    -------
    Tiled
        ``kept``: the pixels outside the bands (at their own place); ``seam_cols`` and
        ``seam_rows``: the bands' inner edges; ``source_rows`` / ``source_cols``: the image pixel
        each output pixel's selection came from; ``seam_error``: the fill's cuts'.
    """
    height, width = view.shape[:2]
    tiled_axes = check_tiling((height, width), options.axes, options.band)
    tile_x, tile_y = "x" in tiled_axes, "y" in tiled_axes
    shift = (height // 2 if tile_y else 0, width // 2 if tile_x else 0)
    rolled = np.roll(view, shift, axis=(0, 1))
    hole = np.zeros((height, width), dtype=bool)
    bands = (fill_band(height, options.band), fill_band(width, options.band))
    if tile_x:
        hole[:, shift[1] - bands[1] // 2 : shift[1] - bands[1] // 2 + bands[1]] = True
    if tile_y:
        hole[shift[0] - bands[0] // 2 : shift[0] - bands[0] // 2 + bands[0], :] = True
    block = min(FillOptions().block, largest_block(~hole, FillOptions().block + 1))
    if block < 3:
        if options.band is None:
            raise InvalidImageError(
                f"image of {width}x{height} pixels is too small to tile by filling: no 3x3 "
                "block of it is left outside the bands across the wraps (method='cut' needs "
                f"only {MIN_SIDE} pixels along a tiled side)"
            )
        raise InvalidParameterError(
            "band", options.band, "a narrower band", "no 3x3 block of the image is left outside it"
        )
    fill = FillOptions(block=block, seed=options.seed, blend=options.blend)
    # The band's straight edges are no edges of the image: the cuts may wander past them by
    # the blocks' overlap, so that no seam runs straight along a band.
    margin = fill.resolved_overlap
    free = binary_dilation(hole, np.ones((2 * margin + 1, 2 * margin + 1), dtype=bool))
    filled = fill_image(rolled, fmt, hole, fill, backend, fixed=~free, progress=progress)
    # Rolled back, and every provenance taken back to the image's own coordinates.
    unroll = (-shift[0], -shift[1])
    rows = np.roll((filled.source_rows - shift[0]) % height, unroll, axis=(0, 1))
    cols = np.roll((filled.source_cols - shift[1]) % width, unroll, axis=(0, 1))
    kept = np.roll(~free, unroll, axis=(0, 1))
    image = np.roll(filled.image.reshape(view.shape), unroll, axis=(0, 1))
    # The kept centre is a rectangle: its first and last rows and columns.
    rows_kept, cols_kept = np.flatnonzero(kept.any(axis=1)), np.flatnonzero(kept.any(axis=0))
    inner = ((rows_kept[0], rows_kept[-1]), (cols_kept[0], cols_kept[-1]))
    return Tiled(
        image=fmt.restore(image),
        kept=kept,
        seam_cols=np.array([[inner[1][0]] * height, [inner[1][1]] * height], dtype=np.intp),
        seam_rows=np.array([[inner[0][0]] * width, [inner[0][1]] * width], dtype=np.intp),
        source_rows=rows.astype(np.intp),
        source_cols=cols.astype(np.intp),
        seam_error=filled.seam_error,
        axes=options.axes,
        blend=options.blend,
        replay=None if filled.replay is None else WrapReplay(filled.replay, shift),
    )
