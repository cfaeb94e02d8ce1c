"""Gradient-domain blending of the seams a block's cuts leave in its cell.

A cut joins two images whose brightness or colour may differ by a step. The blend keeps every
gradient of the pasted result except those that cross the cut, which it replaces by the mean
of the two sides' own gradients there, and finds the correction ``c`` that makes it so with
the least squared change of gradients plus a small penalty on ``c`` itself: a screened Poisson
problem ``laplacian(c) - SCREEN c = div(d)``, ``d`` the gradient change asked for on the
seam's edges (zero elsewhere). The screening keeps the correction within a few pixels of the
cut: a plain Poisson correction spreads a step as a ramp across the whole block, shifting the
brightness of patches that then look like no part of the texture. It is solved on each block's
cell, the ``step x step`` square at the block's corner (the block's left and top overlap
strips and its core), with ``c = 0`` on the ring around the cell, so the pixels around it keep
their values. On a torus the blocks of the last row and column are also cut on their far
sides, into the first row and column (the seams across the wrap); they are solved on their
whole ``block x block`` footprint instead, so that those seams are blended too.

Cells of one wavefront level are disjoint (a block's right and bottom strips, which it shares
with blocks of the same level, lie outside its cell; so are the footprints of a level), so the
blocks of a level are blended at once and in any batches with the same result. The square with
zero boundary is diagonalized by the type-I discrete sine transform (scipy.fft), a solve of
``O(s^2 log s)`` per cell.

References
----------
.. [1] P. Perez, M. Gangnet and A. Blake, "Poisson Image Editing", SIGGRAPH 2003, §2-3 (the
       guidance field and the Dirichlet problem on a region; here with a screening term, the
       least squares weighing the correction's size as well as its gradients).
.. [2] A. A. Efros and W. T. Freeman, "Image Quilting for Texture Synthesis and Transfer",
       SIGGRAPH 2001, §2.1 (the minimum error boundary cut whose seams this blends).
"""

from __future__ import annotations

import functools
import os

import numpy as np
import scipy.fft as sfft
from numpy.typing import NDArray

from quilting.core import kernels
from quilting.core.grid import Grid

#: Weight of the screening term: the blend minimises the squared change of gradients from the
#: guidance plus SCREEN times the squared correction, so a step is spread over about
#: ``1 / sqrt(SCREEN)`` pixels each side of the cut (here about 1.4) instead of across the whole
#: cell. A correction spread across the cell shifts the brightness of whole patches, which then
#: match no patch of the texture (the blend's coherence figure rose from 0.68 to 0.74 with
#: SCREEN = 0); chosen by benchmarks/bench_quality.py, see RESULTS.md.
SCREEN = 0.5
#: How much more than the seam's gradient change the blend asks for. Screening leaves part of
#: a step standing: across a long straight cut the correction's jump is ``2 / (3 + SCREEN - r)``
#: of the step, ``r + 1 / r = 2 + SCREEN`` (two thirds at SCREEN = 0.5), and asking 1.5 times
#: the change would remove it. Asking 1.25 times, half way, lowered the coherence figure from
#: 0.663 to 0.644 with the seam figure about the same (0.677 to 0.684); the full 1.5 lowered
#: coherence no further and raised the seam figure to 0.710 (over-correction where cuts bend).
OVERSHOOT = 1.25
#: Threads of the cells' transforms: each transform is computed whole by one thread, so the
#: result does not depend on it (1.7x faster with 2 on 2 cores for 30 RGB cells at block 48).
WORKERS = min(2, os.cpu_count() or 1)
#: Fewest values (cells x side^2 x channels) whose transforms are worth a second thread:
#: below it the threads' start costs more than they save (12 gray cells of side 40: even).
THREADED_VALUES = 1 << 15


@functools.cache
def _denominators(side: int, screen: float) -> NDArray[np.float32]:
    """Eigenvalues of the screened Dirichlet Laplacian ``laplacian - screen`` on a
    ``side x side`` square, shape (side, side) (all negative), in the order of
    :func:`scipy.fft.dstn` type I coefficients."""
    k = np.arange(1, side + 1)
    line = 2.0 * np.cos(np.pi * k / (side + 1)) - 2.0
    return (line[:, None] + line[None, :] - screen).astype(np.float32)


def seam_divergence(
    old: NDArray[np.float32],
    new: NDArray[np.float32],
    owned: NDArray[np.bool_],
    covered: NDArray[np.bool_],
) -> NDArray[np.float32]:
    """The divergence of the gradient change the blend asks for, ``div(d)``.

    On an edge between two pixels on different sides of the cut (a *seam edge*), the guidance
    gradient is the mean of both images' differences where both cover the edge, else the
    block's own difference; ``d`` is that minus the pasted result's difference there. Off the
    seam ``d`` is zero: every other gradient of the pasted cell is kept. On the seam it is
    :data:`OVERSHOOT` times that change, which the screened solve only partly makes.

    Parameters
    ----------
    old, new : ndarray of float32, shape (n, s, s, C)
        The canvas before the block was pasted, and the block.
    owned : ndarray of bool, shape (n, s, s)
        Where the block's cuts give it the pixel.
    covered : ndarray of bool, shape (n, s, s)
        Where ``old`` holds pixels of blocks placed before (elsewhere it is not an image).

    Returns
    -------
    ndarray of float32, shape (n, s, s, C)
        At each pixel, ``d`` on the edges leaving it (to the pixel below and the one to the
        right) minus ``d`` on the edges entering it.
    """
    return kernels.seam_divergence(old, new, owned, covered, OVERSHOOT)


def cell_corrections(
    old: NDArray[np.float32],
    new: NDArray[np.float32],
    owned: NDArray[np.bool_],
    covered: NDArray[np.bool_],
    screen: float | None = None,
    workers: int | None = None,
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
    screen : float, optional
        Weight of the squared correction in the least squares; default :data:`SCREEN`. 0:
        plain Poisson, the step spread across the whole cell.
    workers : int, optional
        Threads of the transforms (default :data:`WORKERS` for a batch of at least
        :data:`THREADED_VALUES` values); the result does not depend on it.

    Returns
    -------
    ndarray of float32, shape (n, s, s, C)
        ``c`` with ``laplacian(c) - screen c = div(d)`` inside the cell and ``c = 0`` around
        it, ``d`` the gradient change of :func:`seam_divergence` (:data:`OVERSHOOT` times the
        change to the guidance): the correction of least ``|grad(c) - d|^2 + screen |c|^2``.
        Zero where no cut crosses the cell.
    """
    n, side, _, channels = old.shape
    if not n or side < 2:
        return np.zeros((n, side, side, channels), dtype=np.float32)
    divergence = seam_divergence(old, new, owned, covered)
    if not divergence.any():
        return divergence
    if workers is None:
        workers = WORKERS if divergence.size >= THREADED_VALUES else 1
    # Each transform writes over its input (the arrays are this call's own): the same
    # arithmetic without two new arrays the size of the batch (7 % of the solve at block 48).
    spectrum = sfft.dstn(
        divergence, type=1, axes=(1, 2), norm="ortho", workers=workers, overwrite_x=True
    )
    weight = SCREEN if screen is None else float(screen)
    spectrum /= _denominators(side, weight)[None, :, :, None]
    correction: NDArray[np.float32] = sfft.idstn(
        spectrum, type=1, axes=(1, 2), norm="ortho", workers=workers, overwrite_x=True
    ).astype(np.float32, copy=False)
    return correction


def blend_cells(
    canvas: NDArray[np.float32],
    old: NDArray[np.float32],
    blocks: NDArray[np.float32],
    owned: NDArray[np.bool_],
    grid: Grid,
    rows: NDArray[np.intp],
    cols: NDArray[np.intp],
    workers: int | None = None,
) -> None:
    """Blend the seams of blocks just pasted on one level, in their cells (in their whole
    footprints for the blocks a torus cuts on their far sides too).

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
    workers : int, optional
        Threads of the transforms (see :func:`cell_corrections`); the result does not
        depend on it.
    """
    side = grid.step
    covered = grid.covered(rows, cols)
    # On a torus the last row's and column's blocks are cut on their far sides too, into the
    # first ones (the wrap seams), outside their cells: those blocks are blended over their
    # whole footprint, so that the wrap seams are as smooth as the others.
    far = grid.cut_across_wrap(rows, cols)
    for chosen, size in ((~far, side), (far, grid.block)):
        if not chosen.any():
            continue
        part = np.s_[chosen, :size, :size]
        corrections = cell_corrections(
            old[part], blocks[part], owned[part], covered[part], workers=workers
        )
        # The modulo takes the last cells of a torus past the edge onto the first; pixel by
        # pixel in block order, so that a pixel two footprints reach gets both corrections.
        kernels.add_cells(canvas, corrections, grid.origins(rows[chosen], cols[chosen]))
