"""Gradient-domain blending of the seams a block's cuts leave in its cell.

A cut joins two images whose brightness or colour may differ by a step. The blend keeps every
gradient of the pasted result except those that cross the cut, which it replaces by the mean
of the two sides' own gradients there, and finds the correction ``c`` of least squared change
of gradients that makes it so: a Poisson problem ``laplacian(c) = div(d)``, ``d`` the
gradient change asked for on the seam's edges (zero elsewhere). It is solved on each block's
cell, the ``step x step`` square at the block's corner (the block's left and top overlap
strips and its core), with ``c = 0`` on the ring around the cell, so the pixels around it keep
their values and a step is spread as a gentle ramp across the cell instead of a line.

Cells of one wavefront level are disjoint (a block's right and bottom strips, which it shares
with blocks of the same level, lie outside its cell), so the blocks of a level are blended at
once and in any batches with the same result. The square with zero boundary is diagonalized
by the type-I discrete sine transform (scipy.fft), a solve of ``O(s^2 log s)`` per cell.

References
----------
.. [1] P. Perez, M. Gangnet and A. Blake, "Poisson Image Editing", SIGGRAPH 2003, §2-3 (the
       guidance field and the Dirichlet problem on a region).
.. [2] A. A. Efros and W. T. Freeman, "Image Quilting for Texture Synthesis and Transfer",
       SIGGRAPH 2001, §2.1 (the minimum error boundary cut whose seams this blends).
"""

from __future__ import annotations

import functools

import numpy as np
import scipy.fft as sfft
from numpy.typing import NDArray

from quilting.core.grid import Grid


@functools.cache
def _eigenvalues(side: int) -> NDArray[np.float32]:
    """Eigenvalues of the Dirichlet Laplacian on a ``side x side`` square, shape (side, side)
    (all negative), in the order of :func:`scipy.fft.dstn` type I coefficients."""
    k = np.arange(1, side + 1)
    line = 2.0 * np.cos(np.pi * k / (side + 1)) - 2.0
    return (line[:, None] + line[None, :]).astype(np.float32)


def seam_gradients(
    old: NDArray[np.float32],
    new: NDArray[np.float32],
    owned: NDArray[np.bool_],
    covered: NDArray[np.bool_],
    axis: int,
) -> NDArray[np.float32]:
    """The gradient change the blend asks for on each edge along ``axis``.

    Parameters
    ----------
    old, new : ndarray of float32, shape (n, s, s, C)
        The canvas before the block was pasted, and the block.
    owned : ndarray of bool, shape (n, s, s)
        Where the block's cuts give it the pixel.
    covered : ndarray of bool, shape (n, s, s)
        Where ``old`` holds pixels of blocks placed before (elsewhere it is not an image).
    axis : {1, 2}
        1: edges between a pixel and the one below; 2: the one to its right.

    Returns
    -------
    ndarray of float32, shape (n, s - 1, s, C) or (n, s, s - 1, C)
        Zero except on the seam's edges (the two pixels on different sides of the cut):
        there, the mean of both images' differences where both cover the edge, else the
        block's own difference, minus the pasted result's difference.
    """

    def diff(values: NDArray[np.generic]) -> NDArray[np.float32]:
        upper = np.delete(values, 0, axis=axis)
        lower = np.delete(values, -1, axis=axis)
        return (upper - lower).astype(np.float32)

    def ends(values: NDArray[np.bool_]) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
        return np.delete(values, -1, axis=axis), np.delete(values, 0, axis=axis)

    here, there = ends(owned)
    seam = here != there
    first, second = ends(covered)
    both = (first & second)[..., None]
    d_new = diff(new)
    wanted = np.where(both, np.float32(0.5) * (d_new + diff(old)), d_new)
    pasted = np.where(owned[..., None], new, old)
    change: NDArray[np.float32] = np.where(seam[..., None], wanted - diff(pasted), 0).astype(
        np.float32
    )
    return change


def cell_corrections(
    old: NDArray[np.float32],
    new: NDArray[np.float32],
    owned: NDArray[np.bool_],
    covered: NDArray[np.bool_],
) -> NDArray[np.float32]:
    """What to add to each pasted cell so that its seams carry no step.

    Parameters
    ----------
    old, new : ndarray of float32, shape (n, s, s, C)
        The cell before the paste (the blocks placed before) and the block's pixels there.
    owned : ndarray of bool, shape (n, s, s)
        Where the block's cuts give it the pixel.
    covered : ndarray of bool, shape (n, s, s)
        Where blocks placed before wrote ``old``.

    Returns
    -------
    ndarray of float32, shape (n, s, s, C)
        ``c`` with ``laplacian(c) = div(d)`` inside the cell and ``c = 0`` around it, ``d``
        from :func:`seam_gradients`: the least-squares change of the pasted cell's gradients
        into the guidance field. Zero where no cut crosses the cell.
    """
    n, side, _, channels = old.shape
    divergence = np.zeros((n, side, side, channels), dtype=np.float32)
    if not n or side < 2:
        return divergence
    rows = seam_gradients(old, new, owned, covered, 1)
    cols = seam_gradients(old, new, owned, covered, 2)
    if not (rows.any() or cols.any()):
        return divergence
    # div(d) at p: d on the edge leaving p minus d on the edge entering it, both axes.
    divergence[:, :-1] += rows
    divergence[:, 1:] -= rows
    divergence[:, :, :-1] += cols
    divergence[:, :, 1:] -= cols
    spectrum = sfft.dstn(divergence, type=1, axes=(1, 2), norm="ortho")
    spectrum /= _eigenvalues(side)[None, :, :, None]
    correction: NDArray[np.float32] = sfft.idstn(
        spectrum, type=1, axes=(1, 2), norm="ortho"
    ).astype(np.float32)
    return correction


def blend_cells(
    canvas: NDArray[np.float32],
    old: NDArray[np.float32],
    blocks: NDArray[np.float32],
    owned: NDArray[np.bool_],
    grid: Grid,
    rows: NDArray[np.intp],
    cols: NDArray[np.intp],
) -> None:
    """Blend the seams of blocks just pasted on one level, in their cells.

    Parameters
    ----------
    canvas : ndarray of float32, shape (H, W, C), modified in place
        The canvas after the paste (working pixels).
    old : ndarray of float32, shape (n, B, B, C)
        The blocks' footprints before the paste.
    blocks : ndarray of float32, shape (n, B, B, C)
        The pasted blocks.
    owned : ndarray of bool, shape (n, B, B)
        Where each block's cuts gave it the pixel (what :func:`quilting.core.compose.paste`
        returns).
    grid : Grid
    rows, cols : ndarray of int, shape (n,)
        The blocks' grid cells, all on one level.
    """
    side = grid.step
    cell = np.s_[:, :side, :side]
    corrections = cell_corrections(
        old[cell], blocks[cell], owned[cell], grid.covered(rows, cols)[cell]
    )
    height, width = canvas.shape[:2]
    # The cells of a level are disjoint, so one fancy-indexed add writes them all; the modulo
    # takes the last cells of a torus past the edge onto the first (a cell is narrower than
    # the period, so no pixel twice).
    origins = grid.origins(rows, cols)
    offsets = np.arange(side)
    ys = ((origins[:, :1] + offsets) % height)[:, :, None]
    xs = ((origins[:, 1:] + offsets) % width)[:, None, :]
    canvas[ys, xs] += corrections
