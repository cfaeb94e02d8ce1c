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

from quilting.core import kernels


@dataclass(frozen=True)
class CostRequest:
    """One block to score against every candidate position of the source.

    The cost of candidate (y, x), with S its source block:
    ``sum M * (S - T)^2 + previous_weight * sum (S - P)^2 + guide_weight * sum (G_S - G)^2``,
    sums over the block's pixels and channels; G_S is the source's guide (correspondence) map
    given to :meth:`CostBackend.prepare`. Weights carry any per-pixel normalization.

    Attributes
    ----------
    template : ndarray, shape (B, B, C), float32
        The output currently under the block (only pixels where ``mask > 0`` matter).
    mask : ndarray, shape (B, B), float32
        Non-negative weights M of the overlap region.
    previous : ndarray, shape (B, B, C), float32, optional
        The previous pass's output at this block (iterative transfer).
    previous_weight : float
        Weight of the previous-pass term (0 when ``previous`` is None).
    guide : ndarray, shape (B, B, K), float32, optional
        The target's correspondence map at this block (texture transfer).
    guide_weight : float
        Weight of the correspondence term (0 when ``guide`` is None).
    shared_mask : bool
        True (the default) when the same mask array recurs across requests (a grid's few
        overlap kinds): backends may keep what they derive from it for the job. False for a
        mask made for this request alone (a fill's block over known pixels of any shape),
        which backends should use once and not keep.
    """

    template: NDArray[np.float32]
    mask: NDArray[np.float32]
    previous: NDArray[np.float32] | None = None
    previous_weight: float = 0.0
    guide: NDArray[np.float32] | None = None
    guide_weight: float = 0.0
    shared_mask: bool = True

    def __post_init__(self) -> None:
        for name, weight, term in (
            ("previous_weight", self.previous_weight, self.previous),
            ("guide_weight", self.guide_weight, self.guide),
        ):
            if not (weight >= 0 and np.isfinite(weight)):
                raise ValueError(f"{name} must be a finite number >= 0, got {weight!r}")
            if weight > 0 and term is None:
                raise ValueError(f"{name} > 0 needs its term ({name.split('_')[0]})")


@dataclass(frozen=True)
class FieldBatch:
    """Cost fields for a batch of requests.

    Attributes
    ----------
    values : ndarray, shape (n, H - B + 1, W - B + 1), float32 or float64
        ``values[k, y, x]`` approximates the cost of placing source block (y, x) for request k.
    error_bound : ndarray, shape (n,), float64
        ``|values[k] - exact[k]| <= error_bound[k]`` everywhere; 0 for exact backends.
    """

    values: NDArray[np.floating]
    error_bound: NDArray[np.float64]


@dataclass(frozen=True)
class Shortlist:
    """The candidates of one request that may be acceptable, with their approximate costs.

    With E_(k) the k-th smallest approximate cost of the whole field (k = ``min_candidates``)
    and b the error bound, a shortlist holds every candidate whose approximate cost is at most
    ``(1 + tolerance) * (E_(k) + b) + b`` (more is allowed), hence at least min(k, field size)
    entries. That is all :func:`quilting.core.select.acceptable` needs, so a backend can reduce
    its fields where it computed them and hand over only this.

    Attributes
    ----------
    index : ndarray, shape (m,), intp
        Flat field indices (``y * field_width + x``), sorted ascending.
    values : ndarray, shape (m,), float64
        Approximate costs of those candidates.
    bound : float
        ``|values - exact| <= bound`` for every candidate of the field.
    """

    index: NDArray[np.intp]
    values: NDArray[np.float64]
    bound: float


@runtime_checkable
class CostBackend(Protocol):
    """What a cost-field backend provides. One instance serves one job at a time."""

    @property
    def name(self) -> str:
        """The backend's name (``"fft"``, ``"gl"``...)."""

    @property
    def renderer(self) -> str:
        """What computes the fields: ``"cpu"``, or the GL renderer string."""

    def prepare(
        self, source: NDArray[np.float32], block: int, guide: NDArray[np.float32] | None = None
    ) -> None:
        """Take the job's source texture, shape (H, W, C) float32, and the block size.

        ``guide`` is the source's correspondence map, shape (H, W, K), for requests with a
        guide term. Per-job work (spectra, uploads) happens here, once.
        """

    def fields(self, requests: Sequence[CostRequest]) -> FieldBatch:
        """Compute the cost field of every request (one wavefront level, or part of one)."""

    def shortlists(
        self, requests: Sequence[CostRequest], tolerance: float, min_candidates: int
    ) -> list[Shortlist]:
        """The :class:`Shortlist` of every request: what the engine selects from.

        Backends holding dense fields build them with
        :func:`quilting.core.select.shortlist_fields`; a GPU backend reduces on the device.
        """

    def close(self) -> None:
        """Release what ``prepare`` allocated."""


def find_mask(known: Sequence[NDArray[np.float32]], mask: NDArray[np.float32]) -> int | None:
    """Index of ``mask`` among ``known`` masks, or None.

    A job uses a handful of mask arrays (left, top, L) over and over: look them up by identity
    first, by value second.
    """
    for k, candidate in enumerate(known):
        if candidate is mask:
            return k
    for k, candidate in enumerate(known):
        if candidate.shape == mask.shape and np.array_equal(candidate, mask):
            return k
    return None


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
    guide : ndarray, shape (H, W, K), float32, optional
        The source's correspondence map, for requests with a guide term.
    """

    def __init__(
        self, source: NDArray[np.float32], block: int, guide: NDArray[np.float32] | None = None
    ) -> None:
        _, width, channels = source.shape
        self.width = width
        self.block = block
        # Flat (pixel, channel) rows: one `take` per call is much cheaper than 2-D fancy indexing.
        self.pixels = np.ascontiguousarray(source, dtype=np.float64).reshape(-1, channels)
        self.guide_pixels = (
            None
            if guide is None
            else np.ascontiguousarray(guide, dtype=np.float64).reshape(-1, guide.shape[2])
        )
        self._masks: list[NDArray[np.float32]] = []
        self._supports: list[_Support] = []  # of self._masks[k]
        self._block_support = self._support(np.ones((block, block), dtype=np.float32))

    def _support(self, mask: NDArray[np.float32], keep: bool = True) -> _Support:
        slot = find_mask(self._masks, mask) if keep else None
        if slot is not None:
            return self._supports[slot]
        py, px = np.nonzero(mask)
        support = _Support(
            rows=py, cols=px, offsets=py * self.width + px, weights=mask[py, px].astype(np.float64)
        )
        if not keep:  # a one-off mask: looked up by value it would only slow every lookup
            return support
        self._masks.append(mask)
        self._supports.append(support)
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
        return self.costs_batch([request], np.zeros(ys.size, dtype=np.intp), ys, xs)

    def costs_batch(
        self,
        requests: Sequence[CostRequest],
        owner: NDArray[np.intp],
        ys: NDArray[np.intp],
        xs: NDArray[np.intp],
    ) -> NDArray[np.float64]:
        """Exact costs of candidates of several requests at once.

        Candidate k belongs to ``requests[owner[k]]``. Each cost is computed by the same
        sequence of operations whatever else is in the batch, so it is the same number in
        every batch.

        Parameters
        ----------
        requests : sequence of CostRequest
        owner, ys, xs : ndarray of int, shape (k,)

        Returns
        -------
        ndarray, shape (k,), float64
        """
        costs = np.empty(owner.size, dtype=np.float64)
        # Requests sharing a mask share a pixel support: score each such group in one go.
        groups: dict[int, list[int]] = {}
        supports: dict[int, _Support] = {}
        for index, request in enumerate(requests):
            support = self._support(request.mask, request.shared_mask)
            groups.setdefault(id(support), []).append(index)
            supports[id(support)] = support
        for key, members in groups.items():
            support = supports[key]
            chosen = (
                np.flatnonzero(np.isin(owner, members))
                if len(groups) > 1
                else np.arange(owner.size)
            )
            if chosen.size == 0:
                continue
            templates = np.stack([requests[m].template for m in members])
            targets = templates[:, support.rows, support.cols].astype(np.float64)  # (m, P, C)
            slot = np.zeros(len(requests), dtype=np.intp)
            slot[members] = np.arange(len(members))
            corners = ys[chosen] * self.width + xs[chosen]
            costs[chosen] = kernels.masked_costs(
                self.pixels, support.offsets, support.weights, targets, slot[owner[chosen]], corners
            )
        # Transfer terms cover the whole block: one gather per term over every request having it.
        for term in ("previous", "guide"):
            members = [
                n
                for n, r in enumerate(requests)
                if getattr(r, term) is not None and getattr(r, f"{term}_weight") > 0
            ]
            if not members:
                continue
            pixels = self.pixels if term == "previous" else self.guide_pixels
            if pixels is None:
                raise ValueError("a request has a guide term but the source has no guide map")
            chosen = np.flatnonzero(np.isin(owner, members))
            slot = np.zeros(len(requests), dtype=np.intp)
            slot[members] = np.arange(len(members))
            weights = np.array([getattr(requests[n], f"{term}_weight") for n in members])
            support = self._block_support
            wanted = np.stack([getattr(requests[n], term) for n in members])[
                :, support.rows, support.cols
            ].astype(np.float64)  # (m, B*B, K)
            corners = ys[chosen] * self.width + xs[chosen]
            which = slot[owner[chosen]]
            # The block's support weighs every pixel 1: the plain sums of squares.
            squared = kernels.masked_costs(
                pixels, support.offsets, support.weights, wanted, which, corners
            )
            costs[chosen] += weights[which] * squared
        return costs


@dataclass(frozen=True)
class _Support:
    """The non-zero pixels of a mask: coordinates, flat offsets into the source, weights."""

    rows: NDArray[np.intp]
    cols: NDArray[np.intp]
    offsets: NDArray[np.intp]
    weights: NDArray[np.float64]
