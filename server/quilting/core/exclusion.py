"""Excluding parts of the texture from block selection (the minimum-resistance-cut paper, §3.1).

A user marks pixels that must never appear in the output: colour ranges (an undesired colour
of the input, a watermark, a background) and/or a mask image of the texture's size where
black means "never use". A candidate block containing any excluded pixel is never chosen.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from quilting.core.errors import InvalidImageError, InvalidParameterError
from quilting.core.randomness import BlockRandom

ColorRange = tuple[tuple[float, ...], tuple[float, ...]]


def color_ranges(value: Any) -> tuple[ColorRange, ...]:
    """Validate ``exclude_colors`` and normalize it to a tuple of (low, high) tuples.

    Parameters
    ----------
    value : sequence of (low, high)
        Each of ``low`` and ``high`` a sequence of 1..4 finite numbers, ``low <= high``
        channel by channel.

    Returns
    -------
    tuple of ((float, ...), (float, ...))
    """
    allowed = "a list of [low, high] colour pairs, each a list of 1..4 numbers, low <= high"
    if isinstance(value, str | bytes) or not isinstance(value, Sequence):
        raise InvalidParameterError("exclude_colors", value, allowed)
    ranges = []
    for pair in value:
        if isinstance(pair, str | bytes) or not isinstance(pair, Sequence) or len(pair) != 2:
            raise InvalidParameterError("exclude_colors", value, allowed)
        bounds = []
        for colour in pair:
            if isinstance(colour, str | bytes) or not isinstance(colour, Sequence):
                raise InvalidParameterError("exclude_colors", value, allowed)
            numbers = tuple(colour)
            if not 1 <= len(numbers) <= 4 or not all(
                isinstance(c, int | float) and not isinstance(c, bool) and np.isfinite(c)
                for c in numbers
            ):
                raise InvalidParameterError("exclude_colors", value, allowed)
            bounds.append(tuple(float(c) for c in numbers))
        low, high = bounds
        if len(low) != len(high) or any(a > b for a, b in zip(low, high, strict=True)):
            raise InvalidParameterError(
                "exclude_colors", value, allowed, "low and high differ in length or low > high"
            )
        ranges.append((low, high))
    return tuple(ranges)


def excluded_pixels(
    texture: NDArray[np.generic],
    ranges: tuple[ColorRange, ...],
    source_mask: NDArray[Any] | None,
) -> NDArray[np.bool_] | None:
    """Which pixels of the texture may never be used.

    Parameters
    ----------
    texture : ndarray, shape (H, W, C)
        The validated texture in its own dtype; colour ranges are in its own values
        (0..255 for 8-bit, 0..65535 for 16-bit, as stored for floats).
    ranges : tuple of (low, high)
        A pixel is excluded when every channel lies in [low, high] of some range. A range has
        C values, or 3 for an RGBA texture (alpha then not compared).
    source_mask : ndarray, shape (H, W) or (H, W, K), optional
        Zero (black in every channel) means excluded.

    Returns
    -------
    ndarray of bool, shape (H, W), or None when nothing is excluded
    """
    height, width, channels = texture.shape
    excluded = np.zeros((height, width), dtype=bool)
    for low, high in ranges:
        if len(low) not in (channels, 3 if channels == 4 else channels):
            raise InvalidParameterError(
                "exclude_colors",
                [list(low), list(high)],
                f"colours of {channels} value(s) for this {channels}-channel texture",
            )
        pixels = texture[..., : len(low)]
        excluded |= np.all((pixels >= np.asarray(low)) & (pixels <= np.asarray(high)), axis=-1)
    if source_mask is not None:
        if not isinstance(source_mask, np.ndarray) or source_mask.ndim not in (2, 3):
            raise InvalidImageError("source_mask must be an image array (H, W) or (H, W, K)")
        if source_mask.shape[:2] != (height, width):
            raise InvalidImageError(
                f"source_mask is {source_mask.shape[1]}x{source_mask.shape[0]}; it must be the "
                f"texture's size, {width}x{height}"
            )
        black = source_mask == 0
        excluded |= black if black.ndim == 2 else black.all(axis=-1)
    return excluded if ranges or source_mask is not None else None


def allowed_candidates(excluded: NDArray[np.bool_], block: int) -> NDArray[np.bool_]:
    """Which candidate blocks contain no excluded pixel.

    Parameters
    ----------
    excluded : ndarray of bool, shape (H, W)
    block : int

    Returns
    -------
    ndarray of bool, shape ((H - B + 1) * (W - B + 1),)
        Flat, indexed like the cost fields (``y * field_width + x``).
    """
    # Box sums of the excluded count over every B x B window, from the summed-area table.
    summed = np.cumsum(np.cumsum(excluded, axis=0, dtype=np.int64), axis=1)
    table = np.pad(summed, ((1, 0), (1, 0)))
    b = block
    counts = table[b:, b:] - table[:-b, b:] - table[b:, :-b] + table[:-b, :-b]
    allowed: NDArray[np.bool_] = (counts == 0).ravel()
    return allowed


def usable_candidates(excluded: NDArray[np.bool_], block: int) -> NDArray[np.bool_]:
    """:func:`allowed_candidates`, refusing exclusions that leave no block at all."""
    allowed = allowed_candidates(excluded, block)
    if not allowed.any():
        raise InvalidParameterError(
            "exclude_colors/source_mask",
            f"{int(excluded.sum())} of {excluded.size} pixels excluded",
            f"exclusions leaving at least one {block}x{block} block of the texture",
            f"every {block}x{block} block of the texture contains an excluded pixel",
        )
    return allowed


@dataclass(frozen=True)
class CandidateField:
    """The source blocks a pass may use: every top-left corner, and those an exclusion leaves.

    Attributes
    ----------
    width : int
        Field width ``W - B + 1``: a flat index ``i`` is the corner ``divmod(i, width)``.
    size : int
        Number of candidate corners.
    allowed : ndarray of bool, shape (size,), or None
        Which candidates are free of excluded pixels; None when nothing is excluded.
    index : ndarray of intp, shape (m,)
        Flat indices of the allowed candidates (all of them when nothing is excluded).
    weights : ndarray of float64, shape (size,), or None
        How likely each candidate is to be drawn relative to the others (several examples
        with ``weights``, :mod:`quilting.core.sources`); None: all alike.
    """

    width: int
    size: int
    allowed: NDArray[np.bool_] | None
    index: NDArray[np.intp]
    weights: NDArray[np.float64] | None = None

    @classmethod
    def of(
        cls,
        shape: tuple[int, ...],
        block: int,
        excluded: NDArray[np.bool_] | None = None,
        weights: NDArray[np.float64] | None = None,
    ) -> CandidateField:
        """The field of a source of ``shape`` (H, W, ...) for blocks of side ``block``;
        raises like :func:`usable_candidates` when an exclusion leaves nothing."""
        width = shape[1] - block + 1
        size = (shape[0] - block + 1) * width
        allowed = None if excluded is None else usable_candidates(excluded, block)
        index = np.arange(size, dtype=np.intp) if allowed is None else np.flatnonzero(allowed)
        return cls(width=width, size=size, allowed=allowed, index=index, weights=weights)

    def draw(self, rng: BlockRandom) -> int:
        """A candidate drawn among the allowed ones (uniformly, or by their weights)."""
        return self.pick(self.index, rng)

    def pick(self, candidates: NDArray[np.intp], rng: BlockRandom) -> int:
        """One of ``candidates`` (flat indices) from the block's own stream: uniformly,
        or with probability proportional to their weights (one draw either way)."""
        if self.weights is None:
            return int(candidates[rng.integers(candidates.size)])
        cumulative = np.cumsum(self.weights[candidates])
        drawn = rng.random() * cumulative[-1]
        at = min(int(np.searchsorted(cumulative, drawn, side="right")), candidates.size - 1)
        return int(candidates[at])

    def corners(self, flat: NDArray[np.integer]) -> NDArray[np.intp]:
        """Source (y, x) of flat candidate indices, shape (..., 2)."""
        return np.stack(np.divmod(np.asarray(flat, dtype=np.intp), self.width), axis=-1)
