"""Pixel arrays at the edge of the engine: validation and conversion to the working format.

Inside the engine an image is float32 (H, W, C) in [0, 1] (floats are taken as they are).
Accepted at the edge: (H, W) or (H, W, C) with C in 1, 3, 4; uint8, uint16 or float.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from quilting.core.errors import InvalidImageError

ACCEPTED_DTYPES = ("uint8", "uint16", "float16", "float32", "float64")
ACCEPTED_CHANNELS = (1, 3, 4)
#: Largest magnitude of a float pixel (HDR values included). Costs and seams are float32 sums
#: of squared differences over a block, in alpha mode of colour times alpha (float32 overflows
#: past 3.4e38). At 1e6 a 4096² block of such products stays below 1e33; measured, alpha mode
#: failed at 3e8 with a 128² block and every mode at 1e9.
MAX_FLOAT_MAGNITUDE = 1e6
#: Rec. 601 luma weights of R, G, B.
LUMA = np.array([0.299, 0.587, 0.114], dtype=np.float32)


@dataclass(frozen=True)
class PixelFormat:
    """How an input image was given, so the output can be returned the same way."""

    dtype: np.dtype[np.generic]
    channels: int
    two_dimensional: bool

    def restore(self, image: NDArray[np.generic]) -> NDArray[np.generic]:
        """Give a (H, W, C) array of this format back its original shape (drop C for 2-D)."""
        return image[..., 0] if self.two_dimensional else image


def as_channels(image: object, name: str = "texture") -> tuple[NDArray[np.generic], PixelFormat]:
    """Validate an image and view it as (H, W, C) in its own dtype.

    Parameters
    ----------
    image : array_like
        (H, W) or (H, W, C) with C in 1, 3, 4; uint8, uint16 or float, finite.
    name : str
        What the image is, for error messages (``"texture"``, ``"companion"``...).

    Returns
    -------
    view : ndarray, shape (H, W, C)
        The same data, channel axis always present.
    fmt : PixelFormat
        Its dtype, channel count and whether it was 2-D.
    """
    if not isinstance(image, np.ndarray):
        raise InvalidImageError(f"{name} must be a numpy array, got {type(image).__name__}")
    if image.ndim not in (2, 3):
        raise InvalidImageError(
            f"{name} has shape {image.shape}: expected (H, W) or (H, W, C) with C in 1, 3, 4"
        )
    if image.dtype.name not in ACCEPTED_DTYPES:
        raise InvalidImageError(
            f"{name} has dtype {image.dtype}: expected one of {', '.join(ACCEPTED_DTYPES)}"
        )
    view = image[..., None] if image.ndim == 2 else image
    height, width, channels = view.shape
    if channels not in ACCEPTED_CHANNELS:
        raise InvalidImageError(
            f"{name} has {channels} channels (shape {image.shape}): expected 1 (gray), "
            "3 (RGB) or 4 (RGBA)"
        )
    if height < 1 or width < 1:
        raise InvalidImageError(f"{name} is empty (shape {image.shape})")
    check_float_range(image, name)
    fmt = PixelFormat(dtype=image.dtype, channels=channels, two_dimensional=image.ndim == 2)
    return view, fmt


def to_working(view: NDArray[np.generic]) -> NDArray[np.float32]:
    """Convert a validated (H, W, C) array to contiguous float32, integers scaled to [0, 1]."""
    if view.dtype == np.uint8:
        return np.ascontiguousarray(view, dtype=np.float32) / np.float32(255)
    if view.dtype == np.uint16:
        return np.ascontiguousarray(view, dtype=np.float32) / np.float32(65535)
    return np.ascontiguousarray(view, dtype=np.float32)


def from_working(
    canvas: NDArray[np.float32], dtype: np.dtype[np.generic]
) -> NDArray[np.generic] | None:
    """Convert a working-format image back to ``dtype`` when that is exact, else ``None``.

    Pixels in the canvas are copies of source pixels, so for uint8, uint16 and float32 sources
    scaling back and rounding returns the source values bit for bit (the float32 error of
    ``v / 255 * 255`` is far below half a step). Other dtypes must be re-rendered from the
    source. Integers are clipped to their range first (a blended seam may overshoot it);
    floats are kept as computed. The canvas is scaled in place: it is not needed afterwards,
    and fresh temporaries of this size cost more in page faults than the arithmetic.

    Parameters
    ----------
    canvas : ndarray, shape (H, W, C), float32, overwritten
    dtype : numpy dtype of the source

    Returns
    -------
    ndarray, shape (H, W, C), or None
    """
    if dtype == np.uint8 or dtype == np.uint16:
        # Copies are in [0, 1] already; a blended seam (core.blend) may overshoot a little,
        # and a float past the integer range would wrap around in the cast.
        np.clip(canvas, np.float32(0), np.float32(1), out=canvas)
        np.multiply(canvas, np.float32(255 if dtype == np.uint8 else 65535), out=canvas)
        np.rint(canvas, out=canvas)
        converted: NDArray[np.generic] = canvas.astype(dtype)
        return converted
    if dtype == np.float32:
        return np.ascontiguousarray(canvas)
    return None


def rendered(image: NDArray[np.float32], dtype: np.dtype[np.generic]) -> NDArray[np.generic]:
    """Pixels the engine computed (not copied), clipped to [0, 1], in ``dtype``.

    Unlike :func:`from_working` this rounds: integers to the nearest step, floats of any
    width by a cast.

    Parameters
    ----------
    image : ndarray, shape (H, W, C), float32
    dtype : numpy dtype of the output (uint8, uint16 or a float)

    Returns
    -------
    ndarray, shape (H, W, C)
    """
    clipped = np.clip(image, 0.0, 1.0)
    if dtype.kind == "u":
        top = float(np.iinfo(dtype).max)  # type: ignore[type-var]
        clipped = np.rint(clipped * top)
    converted: NDArray[np.generic] = clipped.astype(dtype)
    return converted


def luminance(image: NDArray[np.float32]) -> NDArray[np.float32]:
    """Luminance of working pixels.

    Parameters
    ----------
    image : ndarray, shape (..., C), float32, C in 1, 3, 4
        Gray is taken as is; RGB(A) by Rec. 601 weights (alpha ignored).

    Returns
    -------
    ndarray, shape (...), float32
        Computed pixel by pixel in a fixed order, so a pixel copied elsewhere has the same
        luminance there.
    """
    if image.shape[-1] == 1:
        return np.ascontiguousarray(image[..., 0])
    luma: NDArray[np.float32] = (
        image[..., 0] * LUMA[0] + image[..., 1] * LUMA[1] + image[..., 2] * LUMA[2]
    )
    return luma


def check_float_range(image: NDArray[np.generic], name: str) -> None:
    """Refuse a float array with NaN, infinite values or magnitudes over
    :data:`MAX_FLOAT_MAGNITUDE` (integer arrays pass: their range is bounded).

    Raises
    ------
    InvalidImageError
        Naming ``name`` and how many values are not finite, or the largest magnitude.
    """
    if image.dtype.kind != "f" or not image.size:
        return
    # Two reductions that propagate NaN, and no temporary the size of the image.
    peak = max(-float(np.min(image)), float(np.max(image)))
    if peak <= MAX_FLOAT_MAGNITUDE:
        return
    bad = int(np.count_nonzero(~np.isfinite(image)))
    if bad:
        raise InvalidImageError(f"{name} contains {bad} NaN or infinite values")
    raise InvalidImageError(
        f"{name} has values of magnitude up to {peak:.3g}: float pixels must lie within "
        f"±{MAX_FLOAT_MAGNITUDE:.0e} (the costs are float32 sums of their squares)"
    )


def compared(
    image: NDArray[np.float32], error: str, *, premultiply: bool = False
) -> NDArray[np.float32]:
    """What costs and seams compare of working pixels (..., C): the pixels themselves, or with
    ``error == "luminance"`` their luminance (..., 1) (a gray image is its own luminance).

    With ``premultiply`` (alpha quilting, the alpha quilting paper's eq. 1 and 3;
    RGBA only) the colour or its
    luminance times alpha, (..., 3) or (..., 1): colour under zero alpha counts for nothing.
    """
    if premultiply:
        colour = compared(image[..., :3], error)
        return np.ascontiguousarray(colour * image[..., 3:4])
    if error != "luminance" or image.shape[-1] == 1:
        return image
    return luminance(image)[..., None]
