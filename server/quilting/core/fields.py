"""The cost-field interface every backend implements, and the exact scorer they all agree with.

A cost field gives, for one block being placed, the error of every candidate block of the
source: ``E[y, x] = sum M * (S[y:y+B, x:x+B] - T)^2`` over pixels and channels, where T is the
output already under the block and M the overlap weights. ``quilting.costs`` implements
:class:`CostBackend`; the engine asks for one batch of fields per wavefront level.

Fast backends are approximate (float32 FFT round-off). Each returns with its field a bound on
its error, and the engine re-scores candidates near the decision thresholds with
:class:`ExactScorer`, so every backend chooses exactly the blocks ``reference`` chooses.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class CostRequest:
    """One block to score against every candidate position of the source.

    Attributes
    ----------
    template : ndarray, shape (B, B, C), float32
        The output currently under the block (only pixels where ``mask > 0`` matter).
    mask : ndarray, shape (B, B), float32
        Non-negative weights M of the overlap region.
    """

    template: NDArray[np.float32]
    mask: NDArray[np.float32]


@dataclass(frozen=True)
class FieldBatch:
    """Cost fields for a batch of requests.

    Attributes
    ----------
    values : ndarray, shape (n, H - B + 1, W - B + 1), float64
        ``values[k, y, x]`` approximates the cost of placing source block (y, x) for request k.
    error_bound : ndarray, shape (n,), float64
        ``|values[k] - exact[k]| <= error_bound[k]`` everywhere; 0 for exact backends.
    """

    values: NDArray[np.float64]
    error_bound: NDArray[np.float64]


@runtime_checkable
class CostBackend(Protocol):
    """What a cost-field backend provides. One instance serves one job at a time."""

    name: str

    def prepare(self, source: NDArray[np.float32], block: int) -> None:
        """Take the job's source texture, shape (H, W, C) float32, and the block size.

        Per-job work (spectra, uploads) happens here, once.
        """

    def fields(self, requests: Sequence[CostRequest]) -> FieldBatch:
        """Compute the cost field of every request (one wavefront level, or part of one)."""

    def close(self) -> None:
        """Release what ``prepare`` allocated."""


class ExactScorer:
    """Direct float64 sums of the cost at chosen candidate positions.

    The reference backend scores every position through this same code, so a candidate's exact
    cost is the same number whichever backend proposed it.

    Parameters
    ----------
    source : ndarray, shape (H, W, C), float32
        The source texture.
    block : int
        Block size B.
    """

    def __init__(self, source: NDArray[np.float32], block: int) -> None:
        self.source = np.ascontiguousarray(source, dtype=np.float64)
        self.block = block
        self._supports: dict[bytes, tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]]
        self._supports = {}

    def _support(
        self, mask: NDArray[np.float32]
    ) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
        # Masks repeat (left, top, L): cache their non-zero pixel lists.
        key = mask.tobytes()
        support = self._supports.get(key)
        if support is None:
            py, px = np.nonzero(mask)
            support = (py, px, mask[py, px].astype(np.float64))
            self._supports[key] = support
        return support

    def costs(
        self, request: CostRequest, ys: NDArray[np.intp], xs: NDArray[np.intp]
    ) -> NDArray[np.float64]:
        """Exact cost of the candidates whose top-left corners are ``(ys[k], xs[k])``.

        Parameters
        ----------
        request : CostRequest
        ys, xs : ndarray of int, shape (k,)

        Returns
        -------
        ndarray, shape (k,), float64
        """
        py, px, weights = self._support(request.mask)
        target = request.template[py, px].astype(np.float64)  # (P, C)
        patches = self.source[ys[:, None] + py, xs[:, None] + px]  # (k, P, C)
        diff = patches - target
        return ((diff * diff).sum(axis=-1) * weights).sum(axis=-1)
