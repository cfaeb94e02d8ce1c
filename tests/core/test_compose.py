"""``gather`` and ``paste`` against naive pixel-by-pixel loops.

The engine and ``Layout.render`` share ``paste``, so "a layout re-applied equals the image"
cannot catch a paste bug (a block pasted one row early passed it). These tests write every
pixel by hand instead: the canvas taken as a torus, the seams as their definition states
(DESIGN §6: the tests' oracles are the plain loops).
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from quilting.core.compose import gather, paste

DTYPES = [np.uint8, np.uint16, np.float32]
CHANNELS = [1, 2, 3, 4]


def _image(rng: np.random.Generator, shape: tuple[int, ...], dtype: type) -> NDArray:
    if np.issubdtype(dtype, np.integer):
        return rng.integers(0, np.iinfo(dtype).max, size=shape, endpoint=True).astype(dtype)
    return rng.random(shape, dtype=np.float32).astype(dtype)


def naive_gather(image: NDArray, corners: NDArray, block: int) -> NDArray:
    height, width = image.shape[:2]
    out = np.zeros((len(corners), block, block, image.shape[2]), dtype=image.dtype)
    for k, (y0, x0) in enumerate(corners):
        for y in range(block):
            for x in range(block):
                out[k, y, x] = image[(y0 + y) % height, (x0 + x) % width]
    return out


def naive_paste(
    canvas: NDArray,
    blocks: NDArray,
    corners: NDArray,
    cut_cols: NDArray,
    cut_rows: NDArray,
    cut_right: NDArray | None,
    cut_bottom: NDArray | None,
) -> NDArray:
    """The canvas after pasting, block after block, each pixel the block owns by the seams'
    definition: x >= cut_cols[y], y >= cut_rows[x], x < cut_right[y], y < cut_bottom[x]."""
    out = canvas.copy()
    height, width = out.shape[:2]
    n, block = cut_cols.shape
    for k in range(n):
        for y in range(block):
            for x in range(block):
                if x < cut_cols[k, y] or y < cut_rows[k, x]:
                    continue
                if cut_right is not None and x >= cut_right[k, y]:
                    continue
                if cut_bottom is not None and y >= cut_bottom[k, x]:
                    continue
                out[(corners[k, 0] + y) % height, (corners[k, 1] + x) % width] = blocks[k, y, x]
    return out


@pytest.mark.parametrize("wrap", [False, True])
@pytest.mark.parametrize("channels", [1, 3, 4])
def test_gather_is_the_naive_copy(wrap: bool, channels: int) -> None:
    rng = np.random.default_rng(channels + 10 * wrap)
    image = _image(rng, (23, 31, channels), np.uint16)
    block = 7
    high = (image.shape[0], image.shape[1]) if wrap else (23 - block + 1, 31 - block + 1)
    corners = np.stack(
        [rng.integers(0, high[0], size=12), rng.integers(0, high[1], size=12)], axis=1
    ).astype(np.intp)
    if wrap:
        corners[0] = (22, 30)  # past both edges
    got = gather(image, corners, block, wrap=wrap)
    assert got.shape == (12, block, block, channels) and got.dtype == image.dtype
    assert got.flags.c_contiguous
    np.testing.assert_array_equal(got, naive_gather(image, corners, block))


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("channels", CHANNELS)
@pytest.mark.parametrize("torus", [False, True])
def test_paste_is_the_naive_loop(dtype: type, channels: int, torus: bool) -> None:
    """Random seams, blocks overlapping one another (later ones win where they own), corners
    past the canvas's edges on a torus; every word size of the compiled copy (1, 2, 3, 4, 6,
    8, 12, 16 bytes a pixel)."""
    rng = np.random.default_rng([channels, np.dtype(dtype).itemsize, torus])
    block, n = 9, 14
    height, width = 26, 33
    canvas = _image(rng, (height, width, channels), dtype)
    blocks = _image(rng, (n, block, block, channels), dtype)
    high = (height, width) if torus else (height - block + 1, width - block + 1)
    corners = np.stack(
        [rng.integers(0, high[0], size=n), rng.integers(0, high[1], size=n)], axis=1
    ).astype(np.intp)
    cut_cols = rng.integers(0, 4, size=(n, block))
    cut_rows = rng.integers(0, 4, size=(n, block))
    cut_right = cut_bottom = None
    if torus:
        corners[0] = (height - 3, width - 2)
        cut_right = rng.integers(block - 3, block + 1, size=(n, block))
        cut_bottom = rng.integers(block - 3, block + 1, size=(n, block))
    expected = naive_paste(canvas, blocks, corners, cut_cols, cut_rows, cut_right, cut_bottom)
    owned = paste(canvas, blocks, corners, cut_cols, cut_rows, cut_right, cut_bottom)
    np.testing.assert_array_equal(canvas, expected)
    # The mask returned is the ownership the loop applied.
    idx = np.arange(block)
    mask = (idx[None, None, :] >= cut_cols[:, :, None]) & (
        idx[None, :, None] >= cut_rows[:, None, :]
    )
    if torus:
        assert cut_right is not None and cut_bottom is not None
        mask &= idx[None, None, :] < cut_right[:, :, None]
        mask &= idx[None, :, None] < cut_bottom[:, None, :]
    np.testing.assert_array_equal(owned, mask)


def test_paste_broadcasts_one_colour_and_converts_the_dtype() -> None:
    canvas = np.zeros((10, 10, 3), dtype=np.uint8)
    colour = np.array([[[[1, 2, 3]]]], dtype=np.float64)  # (1, 1, 1, 3), not the canvas's dtype
    corners = np.array([[1, 2], [5, 5]], dtype=np.intp)
    cuts = np.zeros((2, 4), dtype=np.intp)
    paste(canvas, colour, corners, cuts, cuts)
    expected = np.zeros_like(canvas)
    expected[1:5, 2:6] = (1, 2, 3)
    expected[5:9, 5:9] = (1, 2, 3)
    np.testing.assert_array_equal(canvas, expected)


def test_paste_writes_no_row_early_and_no_column_late() -> None:
    """The bug the layout's round trip missed: one block, a known seam, every pixel checked by
    position."""
    canvas = np.zeros((8, 8, 1), dtype=np.uint8)
    block = np.full((1, 4, 4, 1), 9, dtype=np.uint8)
    cut_cols = np.array([[1, 1, 2, 2]])  # row y keeps columns < cut_cols[y]
    cut_rows = np.array([[0, 1, 1, 3]])  # column x keeps rows < cut_rows[x]
    paste(canvas, block, np.array([[3, 2]], dtype=np.intp), cut_cols, cut_rows)
    written = {(int(y), int(x)) for y, x in zip(*np.nonzero(canvas[..., 0]), strict=True)}
    # Worked by hand from the definition (x >= cut_cols[y] and y >= cut_rows[x]), offset by
    # the corner (3, 2).
    assert written == {(4, 3), (4, 4), (5, 4), (6, 4), (6, 5)}
