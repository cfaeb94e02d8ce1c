"""Which source block a fill's block takes: the search over every candidate, at full size or
coarse to fine.

At full size (``scale`` 1) the backend computes each block's masked cost field over the whole
source and the tolerance rule picks among the exact costs, as synthesis does. A fill's source
is the image itself, often a large photograph, so that is one full-size correlation per block
(57 ms at 1024² RGB on the build machine). Coarse to fine (``scale`` s > 1) runs the same
search on the source and the block averaged over s x s cells (a correlation s² times smaller)
to keep :data:`COARSE_CANDIDATES` of the best coarse positions by exact coarse cost, then
scores exactly, at full size, every allowed fine position those cells hold, and applies the
tolerance rule among them. Both stages are exact where they decide, so every backend still
chooses the same blocks; the coarse stage can only miss a block whose averaged cells match
worse than those of :data:`COARSE_CANDIDATES` others. Among the candidates the rule accepts,
the block takes the first in an order hashed from its own generator (a uniform draw, found
without scoring every tied candidate of a flat background; see
:func:`quilting.core.select.first_acceptable`).

References
----------
.. [1] A. A. Efros and W. T. Freeman, "Image Quilting for Texture Synthesis and Transfer",
       SIGGRAPH 2001, §2.2 (the tolerance rule).
.. [2] L.-Y. Wei and M. Levoy, "Fast Texture Synthesis using Tree-structured Vector
       Quantization", SIGGRAPH 2000, §3.2 (searching a coarser level of a pyramid first).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from quilting.core.exclusion import CandidateField
from quilting.core.fields import CostBackend, CostRequest, ExactScorer, Shortlist
from quilting.core.progress import Clock
from quilting.core.randomness import BlockRandom
from quilting.core.select import first_acceptable, kept_shortlists

#: The coarse block's side the automatic scale aims at: the block divided by the scale. At
#: 1024² RGB with a 20 % hole and block 32, scales 1, 2, 4 and 8 took 14.7, 3.0, 1.5 and 1.9 s
#: and left seams of 0.00159, 0.00138, 0.00124 and 0.00122 (mean squared step per cut edge):
#: the coarse search loses nothing there, as the tolerance rule's draw among many near-equal
#: full-size candidates is no better than among a few hundred good ones.
COARSE_BLOCK = 8
#: Largest automatic scale: above it the fine stage (scale² positions per coarse one) costs
#: more than the coarse correlation saves (block 64: 1.0 s at scale 4, 1.7 s at 8).
MAX_AUTO_SCALE = 4
#: Coarse positions kept per block (each holds scale² fine positions).
COARSE_CANDIDATES = 16
#: Sources of at most this many pixels are searched at full size by the automatic scale: their
#: correlations are cheap, and the full search is exact.
FULL_SEARCH_PIXELS = 1 << 18


def search_scale(requested: int, block: int, source: tuple[int, int]) -> int:
    """The scale a fill searches at: ``requested``, or for 0 (automatic) 1 on sources of at
    most :data:`FULL_SEARCH_PIXELS` pixels and ``block // COARSE_BLOCK`` (1 to
    :data:`MAX_AUTO_SCALE`) above."""
    if requested:
        return requested
    if source[0] * source[1] <= FULL_SEARCH_PIXELS:
        return 1
    return max(1, min(MAX_AUTO_SCALE, block // COARSE_BLOCK))


def averaged(image: NDArray[np.float32], scale: int) -> NDArray[np.float32]:
    """``image`` (H, W, C) averaged over ``scale x scale`` cells: (H // s, W // s, C)."""
    height, width, channels = image.shape
    rows, cols = height // scale, width // scale
    cells = image[: rows * scale, : cols * scale].reshape(rows, scale, cols, scale, channels)
    mean: NDArray[np.float32] = cells.mean(axis=(1, 3), dtype=np.float64).astype(np.float32)
    return mean


class FillSearch:
    """The search of one fill's blocks.

    Parameters
    ----------
    match : ndarray, shape (H, W, C), float32
        The source as the costs compare it.
    block : int
    field : CandidateField
        The source's candidates at full size, and which the hole leaves.
    backend : CostBackend
    clock : Clock
    scale : int
        1: full-size search; s > 1: coarse to fine, the coarse level averaged over s x s.
    tolerance, min_candidates
        The tolerance rule's.
    """

    def __init__(
        self,
        match: NDArray[np.float32],
        block: int,
        field: CandidateField,
        backend: CostBackend,
        clock: Clock,
        scale: int,
        tolerance: float,
        min_candidates: int,
    ) -> None:
        self.block, self.field, self.backend, self.clock = block, field, backend, clock
        self.scale, self.tolerance, self.least = scale, tolerance, min_candidates
        self.match = match
        self.scorer = ExactScorer(match, block)
        self.coarse_match = match if scale == 1 else averaged(match, scale)
        self.coarse_block = block // scale
        self.coarse_field = field if scale == 1 else self._coarse_field()
        self.coarse_scorer = (
            self.scorer if scale == 1 else ExactScorer(self.coarse_match, self.coarse_block)
        )

    def _coarse_field(self) -> CandidateField:
        """The coarse positions holding at least one allowed fine position."""
        s, b = self.scale, self.coarse_block
        rows = self.coarse_match.shape[0] - b + 1
        cols = self.coarse_match.shape[1] - b + 1
        fine_rows, fine_cols = self.field.size // self.field.width, self.field.width
        fine = np.zeros((rows * s, cols * s), dtype=bool)
        allowed = (
            np.ones(self.field.size, dtype=bool)
            if self.field.allowed is None
            else self.field.allowed
        )
        # Every fine position y lies in the coarse cell y // s, which is a coarse position.
        fine[:fine_rows, :fine_cols] = allowed.reshape(fine_rows, fine_cols)
        coarse = fine.reshape(rows, s, cols, s).any(axis=(1, 3)).ravel()
        return CandidateField(
            width=cols, size=rows * cols, allowed=coarse, index=np.flatnonzero(coarse)
        )

    def prepare(self) -> None:
        self.backend.prepare(self.coarse_match, self.coarse_block)

    def close(self) -> None:
        self.backend.close()

    def choose(
        self,
        templates: NDArray[np.float32],
        masks: NDArray[np.bool_],
        rngs: Sequence[BlockRandom],
    ) -> NDArray[np.intp]:
        """Flat full-size field index of the source block each block takes: a uniform draw
        among those the tolerance rule accepts (:func:`quilting.core.select.first_acceptable`,
        the first of them in an order hashed from the block's generator).

        Parameters
        ----------
        templates : ndarray, shape (n, B, B, C), float32
            What the output holds under each block (as the costs compare it).
        masks : ndarray of bool, shape (n, B, B)
            The known pixels under each block; each has at least one.
        rngs : sequence of BlockRandom, length n
        """
        n = len(rngs)
        # Two keys a block: the coarse stage's order and the pick's.
        keys = [rng.generator.integers(0, 2**64, size=2, dtype=np.uint64).tolist() for rng in rngs]
        requests = [
            CostRequest(templates[k], masks[k].astype(np.float32), shared_mask=False)
            for k in range(n)
        ]

        if self.scale == 1:
            tick = time.perf_counter()
            shortlists = kept_shortlists(
                self.backend, requests, rngs, self.field, self.tolerance, self.least, 0.0
            )
            self.clock.add("costs", tick)
        else:
            coarse = self._coarse(templates, masks, rngs, [key[0] for key in keys])
            shortlists = self._fine_lists(requests, coarse)
        tick = time.perf_counter()
        chosen = np.array(
            [
                first_acceptable(
                    shortlists[q],
                    _one_block(self.scorer, self.field, requests[q]),
                    self.tolerance,
                    self.least,
                    keys[q][1],
                )[0]
                for q in range(n)
            ],
            dtype=np.intp,
        )
        self.clock.add("select", tick)
        return chosen

    def _coarse(
        self,
        templates: NDArray[np.float32],
        masks: NDArray[np.bool_],
        rngs: Sequence[BlockRandom],
        keys: Sequence[int],
    ) -> list[NDArray[np.intp]]:
        """Per block, :data:`COARSE_CANDIDATES` of the best coarse positions: the best, ties
        at the last place taken in the order of the block's key."""
        s, b = self.scale, self.coarse_block
        n, channels = templates.shape[0], templates.shape[3]
        used = np.s_[:, : b * s, : b * s]
        weights = masks[used].astype(np.float32).reshape(n, b, s, b, s)
        known = weights.sum(axis=(2, 4))  # (n, b, b): known pixels per cell
        sums = (templates[used] * masks[used][..., None]).reshape(n, b, s, b, s, channels)
        cells = sums.sum(axis=(2, 4)) / np.maximum(known, 1)[..., None]
        coarse = [
            CostRequest(
                np.ascontiguousarray(cells[k], dtype=np.float32),
                (known[k] / (s * s)).astype(np.float32),
                shared_mask=False,
            )
            for k in range(n)
        ]
        tick = time.perf_counter()
        keep = COARSE_CANDIDATES
        shortlists = kept_shortlists(self.backend, coarse, rngs, self.coarse_field, 0.0, keep, 0.0)
        tick = self.clock.add("costs", tick)

        best = [
            np.sort(
                first_acceptable(
                    shortlists[q],
                    _one_block(self.coarse_scorer, self.coarse_field, coarse[q]),
                    0.0,
                    keep,
                    keys[q],
                    keep,
                )
            )
            for q in range(n)
        ]
        self.clock.add("select", tick)
        return best

    def _fine_lists(
        self, requests: list[CostRequest], coarse: list[NDArray[np.intp]]
    ) -> list[Shortlist]:
        """Every allowed fine position in the kept coarse cells, scored exactly at full size."""
        tick = time.perf_counter()
        s = self.scale
        fine_rows, fine_cols = self.field.size // self.field.width, self.field.width
        offsets = np.arange(s)
        owners, indices = [], []
        for q, cells in enumerate(coarse):
            ys, xs = np.divmod(cells, self.coarse_field.width)
            fy = (ys[:, None, None] * s + offsets[None, :, None]).repeat(s, axis=2)
            fx = (xs[:, None, None] * s + offsets[None, None, :]).repeat(s, axis=1)
            inside = (fy < fine_rows) & (fx < fine_cols)
            flat = np.unique(fy[inside] * fine_cols + fx[inside])
            if self.field.allowed is not None:
                flat = flat[self.field.allowed[flat]]
            owners.append(np.full(flat.size, q, dtype=np.intp))
            indices.append(flat)
        owner, index = np.concatenate(owners), np.concatenate(indices)
        ys, xs = np.divmod(index, fine_cols)
        costs = self.scorer.costs_batch(requests, owner, ys, xs)
        lists = []
        start = 0
        for flat in indices:
            stop = start + flat.size
            lists.append(Shortlist(flat, costs[start:stop], 0.0))
            start = stop
        self.clock.add("select", tick)
        return lists


def _one_block(
    scorer: ExactScorer, field: CandidateField, request: CostRequest
) -> Callable[[NDArray[np.intp]], NDArray[np.float64]]:
    """Exact costs of one block's candidates (flat indices of ``field``), scored with that
    block's support alone (a batch's other one-off masks are not looked at)."""

    def exact(index: NDArray[np.intp]) -> NDArray[np.float64]:
        ys, xs = np.divmod(index, field.width)
        return scorer.costs_batch([request], np.zeros(index.size, dtype=np.intp), ys, xs)

    return exact
