"""Compiled parts of the FFT backend's cost fields: the spectral product and the shortlist.

Between its transforms the FFT backend (:mod:`quilting.costs.fft`) multiplies every channel's
template spectrum by the source's and sums over the channels, and after the inverse transform
adds the candidates' energy and the template's constant, finds the field's threshold and keeps
the candidates under it. Each of those was a pass or two of numpy over arrays of a few MiB a
block; here each is one loop, and both release the GIL so that the backend's threads run them
side by side.

The field's values are those of the numpy code (float32 additions in the same order), so the
error bounds the backend states for them hold unchanged; the spectral product's rounding may
differ from numpy's in the last bit, which the bound of the transforms (an estimate with a
safety factor of 15 over the largest error measured) covers. Nothing here decides a block:
the engine re-scores the candidates near a threshold exactly.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numpy.typing import NDArray


@nb.njit(cache=True, nogil=True)
def spectral_sum(
    spectra: NDArray[np.complex64],
    source_conj: NDArray[np.complex64],
    out: NDArray[np.complex64],
) -> None:
    """``out[k] = conj(sum_c spectra[k, c] * source_conj[c])``.

    Parameters
    ----------
    spectra : ndarray, shape (n, C, H, W), complex64
        The templates' spectra, channel by channel.
    source_conj : ndarray, shape (C, H, W), complex64
        The conjugated spectrum of the source (or of source and guide stacked).
    out : ndarray, shape (n, H, W), complex64
        Filled with the conjugate of the channel sum: the spectrum of the correlation.
    """
    count, channels, height, width = spectra.shape
    for k in range(count):
        for y in range(height):
            for x in range(width):
                out[k, y, x] = spectra[k, 0, y, x] * source_conj[0, y, x]
        for c in range(1, channels):
            for y in range(height):
                for x in range(width):
                    out[k, y, x] += spectra[k, c, y, x] * source_conj[c, y, x]
        for y in range(height):
            for x in range(width):
                out[k, y, x] = out[k, y, x].conjugate()


@nb.njit(cache=True, nogil=True)
def field_shortlist(
    cross: NDArray[np.float32],
    energy: NDArray[np.float32],
    constant: np.float32,
    bound: float,
    scale: float,
    min_candidates: int,
) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """One request's field and the candidates the tolerance rule may need.

    The field is ``(cross + energy) + constant`` in float32, written over ``cross``'s first
    ``W`` columns; the list holds every candidate whose value is at most
    ``scale * (U + bound) + bound``, U the ``min_candidates``-th smallest of the field's row
    minima (the k-th smallest value itself when the field has fewer rows), as
    :func:`quilting.core.select.shortlist_fields` makes it; the comparison is in float64, so
    the list is never short of a candidate by a rounding of the threshold.

    Parameters
    ----------
    cross : ndarray, shape (H, >= W), float32
        The cross term ``-2 sum K S`` of the request at every position (the inverse
        transform's rows, possibly wider than the field).
    energy : ndarray, shape (H, W), float32
        ``sum M S^2`` (plus the transfer terms' energies) at every position.
    constant : float32
        The request's ``sum M T^2`` (plus its transfer constants).
    bound : float
        The field's error bound.
    scale : float
        ``1 + tolerance``.
    min_candidates : int
        k of the tolerance rule.

    Returns
    -------
    index : ndarray of intp, shape (m,)
        Flat indices ``y * W + x`` of the listed candidates, ascending.
    values : ndarray of float64, shape (m,)
        Their field values.
    """
    height, width = energy.shape
    row_min = np.empty(height, dtype=np.float32)
    for y in range(height):
        lowest = np.inf
        for x in range(width):
            value = (cross[y, x] + energy[y, x]) + constant
            cross[y, x] = value
            if value < lowest:
                lowest = value
        row_min[y] = lowest
    k = min(min_candidates, height * width)
    if height >= k:
        kth = float(np.partition(row_min, k - 1)[k - 1])
    else:  # fewer rows than k: the k-th smallest value itself
        flat = np.empty(height * width, dtype=np.float32)
        for y in range(height):
            for x in range(width):
                flat[y * width + x] = cross[y, x]
        kth = float(np.partition(flat, k - 1)[k - 1])
    high = scale * (kth + bound) + bound
    count = 0
    for y in range(height):
        for x in range(width):
            if np.float64(cross[y, x]) <= high:
                count += 1
    index = np.empty(count, dtype=np.intp)
    values = np.empty(count, dtype=np.float64)
    count = 0
    for y in range(height):
        for x in range(width):
            value = np.float64(cross[y, x])
            if value <= high:
                index[count] = y * width + x
                values[count] = value
                count += 1
    return index, values
