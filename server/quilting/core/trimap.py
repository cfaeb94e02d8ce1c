"""What the user says of a photo's alpha: trimaps and scribbles read into one map of known
foreground, known background and unknown pixels, and what an extraction gives back.

A trimap is white where the photo is foreground, black where it is background and grey where
the alpha is to be found; scribbles are a few white and black strokes over the photo, the rest
unknown (painted on a transparent layer, or on a mid-grey one). Both read into the same
``(h, w)`` map of 1, 0 and 0.5 that the matting solvers take; the solving itself is
:mod:`quilting.extract`'s (the one module that imports the matting library).

References
----------
.. [1] The alpha quilting and texture matting paper, §2: the user gives the information the
       matte is derived from "in a form such as scribbles or trimaps", and the foreground
       texture and matte come from closed-form matting.
.. [2] A. Levin, D. Lischinski and Y. Weiss, "A Closed-Form Solution to Natural Image
       Matting", IEEE TPAMI 30(2), 2008, §2-3 (scribbles as constraints, the matting
       Laplacian) and §7 (the foreground colour recovered once the alpha is known).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from quilting.core.errors import InvalidImageError
from quilting.core.pixels import PixelFormat, as_channels, rendered, to_working

#: A map pixel at least this bright (luminance, in [0, 1]) is known foreground; at most
#: ``1 - LIGHT`` known background. Not exactly 1 and 0, so that a trimap saved as a JPEG or
#: drawn with a soft brush still reads as drawn.
LIGHT = 0.9
#: Where a scribbles image has alpha, pixels under this opacity are not strokes.
OPAQUE = 0.5
#: Smallest side of a photo to extract from: the solvers' windows and neighbourhoods need it.
MIN_SIDE = 8
#: The map's values.
FOREGROUND, BACKGROUND, UNKNOWN = 1.0, 0.0, 0.5


class InvalidTrimapError(InvalidImageError):
    """A trimap or scribbles image that cannot guide the matting: of another size than the
    photo, or marking no foreground or no background."""

    code = "invalid_trimap"


def _marks(image: object, name: str) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Which pixels of a user's map are marked foreground and which background."""
    view, fmt = as_channels(image, name)
    pixels = to_working(view)
    colour = pixels[..., :3] if fmt.channels >= 3 else pixels[..., :1]
    # Mean of the colour channels, not Rec. 601 luminance: a pure white or black stroke reads
    # the same either way, and a coloured stroke is neither (it is not a mark).
    level = colour.mean(axis=2)
    spread = colour.max(axis=2) - colour.min(axis=2)
    grey = spread <= 1 - LIGHT
    drawn = pixels[..., 3] >= OPAQUE if fmt.channels == 4 else np.ones(level.shape, bool)
    foreground = drawn & grey & (level >= LIGHT)
    background = drawn & grey & (level <= 1 - LIGHT)
    return foreground, background


def user_trimap(
    shape: tuple[int, int], trimap: object | None = None, scribbles: object | None = None
) -> NDArray[np.float64]:
    """The map the solvers take, from a trimap, scribbles or both.

    Parameters
    ----------
    shape : (int, int)
        The photo's (height, width); both maps must have it.
    trimap : ndarray, shape (h, w) or (h, w, C), optional
        White (at least 0.9 of full scale in every colour channel) is foreground, black (at
        most 0.1) background, anything else (grey, colours) unknown. uint8, uint16 or float;
        with alpha, transparent pixels (alpha under half) are unknown.
    scribbles : ndarray, shape (h, w) or (h, w, C), optional
        Strokes read by the same rule (white foreground, black background, the rest unknown),
        usually on a transparent or mid-grey layer. Given with a trimap, the strokes are drawn
        over it.

    Returns
    -------
    ndarray, shape (h, w), float64
        1 (foreground), 0 (background) or 0.5 (unknown) per pixel.

    Raises
    ------
    InvalidTrimapError
        Neither map given, a map of another size than the photo, or together they mark no
        foreground or no background (the solvers need both: the alpha is only defined
        between them).
    """
    if trimap is None and scribbles is None:
        raise InvalidTrimapError("extracting alpha needs a trimap or scribbles")
    marked = np.full(shape, UNKNOWN)
    for name, image in (("trimap", trimap), ("scribbles", scribbles)):
        if image is None:
            continue
        foreground, background = _marks(image, name)
        if foreground.shape != tuple(shape):
            raise InvalidTrimapError(
                f"{name} is {foreground.shape[1]}x{foreground.shape[0]} but the photo is "
                f"{shape[1]}x{shape[0]}: draw it over the photo, at the photo's size"
            )
        marked[foreground] = FOREGROUND
        marked[background] = BACKGROUND
    given = [n for n, i in (("trimap", trimap), ("scribbles", scribbles)) if i is not None]
    said = f"the {' and '.join(given)} " + ("mark" if len(given) > 1 else "marks")
    if not (marked == FOREGROUND).any():
        raise InvalidTrimapError(
            f"{said} no foreground: paint white (or nearly: at least "
            f"{LIGHT:.0%} of full scale) over some of what is to be kept"
        )
    if not (marked == BACKGROUND).any():
        raise InvalidTrimapError(
            f"{said} no background: paint black (or nearly: at most "
            f"{1 - LIGHT:.0%} of full scale) over some of what is to be left out"
        )
    return marked


def photo_pixels(photo: object) -> tuple[NDArray[np.float64], PixelFormat]:
    """A photo as the solvers take it: (h, w, 3) float64 in [0, 1] (gray repeated).

    Raises
    ------
    InvalidImageError
        Not an image, smaller than ``MIN_SIDE`` on a side, or one that already has an alpha
        channel (nothing to extract: quilt it as it is).
    """
    view, fmt = as_channels(photo, "photo")
    if fmt.channels == 4:
        raise InvalidImageError(
            "the photo already has an alpha channel: quilt it as it is (mode='alpha'), or "
            "give its RGB to extract an alpha from a trimap"
        )
    if min(view.shape[0], view.shape[1]) < MIN_SIDE:
        raise InvalidImageError(
            f"the photo is {view.shape[1]}x{view.shape[0]}: extracting alpha needs at least "
            f"{MIN_SIDE}x{MIN_SIDE} pixels"
        )
    pixels = to_working(view).astype(np.float64)
    if fmt.channels == 1:
        pixels = np.repeat(pixels, 3, axis=2)
    return pixels, fmt


def rgba(
    foreground: NDArray[np.floating[Any]], alpha: NDArray[np.floating[Any]], fmt: PixelFormat
) -> NDArray[np.generic]:
    """The extracted texture in the photo's dtype: (h, w, 4), the foreground colour and alpha.

    Parameters
    ----------
    foreground : ndarray, shape (h, w, 3), float
    alpha : ndarray, shape (h, w), float
    fmt : PixelFormat
        The photo's (its dtype; a gray photo's foreground is grey in all three channels).
    """
    stacked = np.concatenate([foreground, alpha[..., None]], axis=2).astype(np.float32)
    return rendered(stacked, fmt.dtype)


@dataclass(frozen=True)
class Extracted:
    """An alpha extracted from a photo and a trimap or scribbles.

    Attributes
    ----------
    image : ndarray, shape (h, w, 4)
        The RGBA texture, in the photo's dtype: the estimated foreground colour (the colour
        the photo's pixels would have without the background showing through) and the alpha.
        What ``mode='alpha'`` quilts.
    alpha : ndarray, shape (h, w), float32
        The alpha in [0, 1]: exactly 1 and 0 where the trimap or scribbles say so.
    trimap : ndarray, shape (h, w), float32
        The map the solver took: 1 foreground, 0 background, 0.5 unknown.
    method : str
        The matting method (``"knn"``, ``"cf"`` or ``"lkm"``).
    foreground : str
        How the colour was found (``"ml"`` or ``"photo"``).
    iterations : int
        Conjugate-gradient iterations the solver took.
    timings : dict of str to float
        Seconds spent finding the ``alpha``, the ``foreground`` colour, and in all (``total``).
    """

    image: NDArray[np.generic]
    alpha: NDArray[np.float32]
    trimap: NDArray[np.float32]
    method: str
    foreground: str
    iterations: int
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def unknown(self) -> float:
        """Share of the photo's pixels whose alpha was solved for (the trimap's grey)."""
        return float(np.mean(self.trimap == UNKNOWN))

    def summary(self) -> dict[str, Any]:
        """What a result records of the extraction (JSON-able; no arrays)."""
        return {
            "method": self.method,
            "foreground": self.foreground,
            "unknown": round(self.unknown, 4),
            "iterations": self.iterations,
            "seconds": round(self.timings.get("total", 0.0), 3),
        }
