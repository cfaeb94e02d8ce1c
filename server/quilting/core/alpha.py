"""Alpha quilting (the alpha quilting and texture matting paper, §2.1): the terms that make
quilting respect a texture's alpha.

* The overlap error compares premultiplied colour, ``sum ||a_i F_i - a'_i P_i||^2`` (eq. 1's
  first term; :func:`quilting.core.pixels.compared` with ``premultiply``): colour under zero
  alpha counts for nothing.
* A candidate block whose alpha histogram differs from the texture's pays
  ``lambda (1 - rho(h_texture, h_block))`` (eq. 1's second term, eq. 2), rho the Bhattacharyya
  coefficient over 100 bins. It keeps the error's preference for nearly transparent blocks
  (whose premultiplied colour is small) from emptying the output.
* Among the candidates within ``(1 + epsilon) g_min``, one is drawn with probability
  ``exp(-eta E)``, E its minimum-error seam's cost on the foreground error (eq. 3-5).

Here ``lambda`` is given per overlap pixel (the term is ``lambda |Omega| (1 - rho)``), so one
value suits every block size; the paper leaves its scale open.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from quilting.core.fields import CostBackend, CostRequest, FieldBatch, Shortlist
from quilting.core.select import shortlist_fields

#: Bins of the alpha histograms (the paper's 100).
BINS = 100
#: Most candidates whose seams are traced for the factored sampling of one block: the lowest
#: errors (ties by position). With epsilon = 0.02 far fewer are usual.
MAX_SAMPLED = 256


def has_alpha(channels: int) -> bool:
    """Whether pixels of ``channels`` channels carry alpha (RGBA: the fourth)."""
    return channels == 4


def alpha_bins(alpha: NDArray[np.floating]) -> NDArray[np.intp]:
    """The histogram bin (0..BINS-1) of each alpha value in [0, 1]."""
    scaled = np.floor(np.clip(alpha, 0.0, 1.0) * BINS).astype(np.intp)
    bins: NDArray[np.intp] = np.minimum(scaled, BINS - 1)
    return bins


def alpha_histogram(alpha: NDArray[np.floating]) -> NDArray[np.float64]:
    """Normalized histogram (BINS,) of alpha values in [0, 1] (any shape)."""
    counts = np.bincount(alpha_bins(alpha).ravel(), minlength=BINS).astype(np.float64)
    histogram: NDArray[np.float64] = counts / max(1.0, counts.sum())
    return histogram


def bhattacharyya(p: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Bhattacharyya coefficient ``sum sqrt(p q)`` of histograms over the last axis, in [0, 1]."""
    coefficient: NDArray[np.float64] = np.sqrt(p * q).sum(axis=-1)
    return coefficient


def histogram_mismatch(
    alpha: NDArray[np.floating], block: int, outside: NDArray[np.bool_] | None = None
) -> NDArray[np.float64]:
    """``1 - rho(h_texture, h_block)`` for every candidate block of a texture's alpha.

    Parameters
    ----------
    alpha : ndarray, shape (h, w)
        The texture's alpha in [0, 1].
    block : int
        Side of the candidate blocks.
    outside : ndarray of bool, shape (h, w), optional
        Pixels of no texture (the margins of an atlas of several examples), left out of the
        texture's histogram.

    Returns
    -------
    ndarray, shape (h - block + 1, w - block + 1)
        Indexed like the cost fields (the candidate's top-left corner).
    """
    h, w = alpha.shape
    texture = alpha_histogram(alpha if outside is None else alpha[~outside])
    bins = alpha_bins(alpha)
    fh, fw = h - block + 1, w - block + 1
    rho = np.zeros((fh, fw), dtype=np.float64)
    area = float(block * block)
    # One box sum per occupied bin (at most BINS; a loop over bins, not pixels): the count of
    # the bin in every window from a summed-area table (one buffer; its zero border stays).
    table = np.zeros((h + 1, w + 1), dtype=np.int64)
    for b in np.flatnonzero(texture):
        np.cumsum(np.cumsum(bins == b, axis=0), axis=1, out=table[1:, 1:])
        counts = table[block:, block:] - table[:fh, block:] - table[block:, :fw] + table[:fh, :fw]
        rho += np.sqrt(texture[b] * counts / area)
    mismatch: NDArray[np.float64] = np.clip(1.0 - rho, 0.0, 1.0)
    return mismatch


@dataclass
class HistogramTerm:
    """A cost backend with the histogram term added: ``g = SSD + lambda |Omega| (1 - rho)``.

    The term is exact (computed once on the CPU) and added to the backend's dense fields, so
    the shortlists and the exact re-scoring see the same ``g`` on every backend.
    """

    backend: CostBackend
    mismatch: NDArray[np.float64]  # (fh, fw), see histogram_mismatch
    weight: float  # lambda, per overlap pixel

    @property
    def name(self) -> str:
        return self.backend.name

    @property
    def renderer(self) -> str:
        return self.backend.renderer

    def prepare(
        self,
        source: NDArray[np.float32],
        block: int,
        guide: NDArray[np.float32] | None = None,
    ) -> None:
        self.backend.prepare(source, block, guide)

    def close(self) -> None:
        self.backend.close()

    def scale(self, request: CostRequest) -> float:
        """``lambda |Omega|`` of a request (its mask's weight)."""
        return self.weight * float(request.mask.sum())

    def fields(self, requests: Sequence[CostRequest]) -> FieldBatch:
        batch = self.backend.fields(requests)
        values = batch.values.astype(np.float64)
        for b, request in enumerate(requests):
            values[b] += self.scale(request) * self.mismatch
        return FieldBatch(values, batch.error_bound)

    def shortlists(
        self, requests: Sequence[CostRequest], tolerance: float, min_candidates: int
    ) -> list[Shortlist]:
        batch = self.fields(requests)
        return shortlist_fields(batch.values, batch.error_bound, tolerance, min_candidates)

    def exact_terms(
        self, requests: Sequence[CostRequest], owner: NDArray[np.intp], index: NDArray[np.intp]
    ) -> NDArray[np.float64]:
        """The term for candidates ``index`` (flat field indices) of requests ``owner``."""
        scales = np.array([self.scale(r) for r in requests])
        terms: NDArray[np.float64] = scales[owner] * self.mismatch.ravel()[index]
        return terms


def factored_pick(
    seam_costs: NDArray[np.float64],
    eta: float,
    rng: np.random.Generator,
    prior: NDArray[np.float64] | None = None,
) -> int:
    """Draw a candidate with probability proportional to ``exp(-eta E)`` (eq. 5).

    Parameters
    ----------
    seam_costs : ndarray, shape (m,)
        E of each candidate: its minimum-error seam's cumulative error.
    eta : float
        Sharpness: 0 draws uniformly; larger favours the cheapest seams.
    rng : numpy.random.Generator
        The block's generator (one draw).
    prior : ndarray, shape (m,), optional
        Weights multiplying each candidate's probability (its example's ``weights``).

    Returns
    -------
    int
        Position of the drawn candidate in ``seam_costs``.
    """
    # Shifted by the minimum: the same distribution, without underflow to all zeros.
    weights = np.exp(-eta * (seam_costs - seam_costs.min()))
    if prior is not None:
        weights = weights * prior
    cumulative = np.cumsum(weights)
    drawn = rng.random() * cumulative[-1]
    return int(min(np.searchsorted(cumulative, drawn, side="right"), seam_costs.size - 1))
