"""The quilting loop (Efros & Freeman 2001, §2.2), driven level by level.

For each wavefront level: read what the output already holds under every block, ask the
backend for one batch of cost fields, pick each block among the acceptable candidates with the
block's own generator, cut every seam of the level in one batch, paste. The output depends on
the options and seed only.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from quilting.core import kernels
from quilting.core.alpha import (
    MAX_SAMPLED,
    HistogramTerm,
    factored_pick,
    histogram_mismatch,
)
from quilting.core.blend import blend_cells
from quilting.core.compose import gather, paste
from quilting.core.deferred_blend import DeferredBlends, may_hand_over
from quilting.core.errors import InvalidParameterError
from quilting.core.exclusion import CandidateField
from quilting.core.fields import CostBackend, CostRequest, ExactScorer, Shortlist
from quilting.core.grid import Grid, Overlap
from quilting.core.layout import Layout, LayoutPass
from quilting.core.options import QuiltOptions, SynthesisOptions
from quilting.core.pixels import PixelFormat, compared, from_working, to_working
from quilting.core.progress import Clock, Progress
from quilting.core.randomness import BlockRandom
from quilting.core.seams import (
    CONTEXT,
    CONTEXT_RADIUS,
    EDGE_COST,
    far_side_cuts,
    straight_cuts,
)
from quilting.core.select import (
    acceptable,
    kept_shortlists,
    relative_costs,
)
from quilting.core.sources import SourceSet
from quilting.core.stats import SynthesisStats, repetition, seam_overlay
from quilting.core.trimap import Extracted
from quilting.core.walk_pass import WalkPass

DEFAULT_BATCH = 64
#: Most candidates whose seams cut mode's factored sampling traces for one block (a uniform
#: subset of those within tolerance when there are more): it bounds the sampling's cost at
#: about a quarter of a 256² texture's cost field per block.
SEAM_SAMPLED = 64


@dataclass(frozen=True)
class Result:
    """What a synthesis returns.

    Attributes
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        The output, same channel count and dtype as the input texture.
    layout : Layout
        Every block's source position and seam; see :func:`quilting.apply_layout`.
    backend : str
        Name of the cost backend that computed the fields (``"none"`` in random mode).
    renderer : str or None
        What ran that backend: ``"cpu"`` or the GL renderer (None in random mode).
    fallback : str or None
        Why ``auto`` left the GPU backend for ``fft`` during this job (None if it did not).
    timings : dict of str to float
        Seconds spent per stage (``costs``, ``select``, ``seams``, ``paste``, ``blend``,
        ``render``, ``stats``) and in all (``total``). The seam blend runs beside the next
        level's selection and paste (:mod:`quilting.core.deferred_blend`), so the stages may
        add up to more than the total.
    stats : SynthesisStats
        Seam error and repetition measures.
    extracted : tuple of Extracted
        The alphas extracted first when the texture came as a photo with a trimap or
        scribbles (one per such example, in order; empty otherwise): each the RGBA texture
        quilted, its alpha, the method and the solver's iterations.
    """

    image: NDArray[np.generic]
    layout: Layout
    backend: str
    timings: dict[str, float]
    stats: SynthesisStats
    renderer: str | None = None
    fallback: str | None = None
    extracted: tuple[Extracted, ...] = ()

    def seam_overlay(
        self, color: tuple[float, float, float] = (1.0, 0.0, 0.0)
    ) -> NDArray[np.uint8]:
        """The image as RGB uint8 (H, W, 3) with the block boundaries drawn in ``color``."""
        return seam_overlay(self.image, self.layout, color)


@dataclass(frozen=True)
class _Weights:
    """Per overlap kind: scale of the overlap mask and weights of the transfer terms."""

    overlap: float = 1.0
    previous: float = 0.0
    guide: float = 0.0


@dataclass(frozen=True)
class Guidance:
    """The texture-transfer terms of one pass (Efros & Freeman 2001, §3).

    The cost of a candidate becomes ``alpha * E_texture + (1 - alpha) * E_map``: E_texture is
    the mean squared difference over the overlap pixels (against the output already there)
    and, from the second pass on, over the whole block (against the previous pass's output);
    E_map is the mean over the block of the squared difference of the correspondence maps,
    summed over the map's K channels and divided by K. Both are per pixel, so alpha means the
    same at every block size.

    Attributes
    ----------
    alpha : float
        In [0, 1].
    source_map : ndarray, shape (h, w, K), float32
        The texture's correspondence map.
    target_map : ndarray, shape (canvas height, canvas width, K), float32
        The target's correspondence map over the pass's whole canvas.
    previous : ndarray, shape (canvas height, canvas width, C), float32, optional
        The previous pass's output over the canvas.
    """

    alpha: float
    source_map: NDArray[np.float32]
    target_map: NDArray[np.float32]
    previous: NDArray[np.float32] | None = None

    def weights(self, mask: NDArray[np.float32], channels: int) -> _Weights:
        """The weights making the cost of a block with overlap ``mask`` per pixel."""
        block = mask.shape[0]
        area = block * block
        texture_terms = float(mask.sum()) * channels + (
            area * channels if self.previous is not None else 0
        )
        texture = self.alpha / texture_terms if texture_terms else 0.0
        return _Weights(
            overlap=texture,
            previous=texture if self.previous is not None else 0.0,
            guide=(1 - self.alpha) / (area * self.target_map.shape[2]),
        )


def check_block_fits(
    options: QuiltOptions, height: int, width: int, image: str = "texture"
) -> None:
    """Refuse a block larger than ``image`` (the texture, or a named layer), naming the
    allowed range."""
    if options.block > min(height, width):
        raise InvalidParameterError(
            "block",
            options.block,
            f"3..{min(height, width)} for a {width}x{height} {image}",
            f"the block is larger than the {image}",
        )


class QuiltPass:
    """One pass of quilting over a grid: choose, cut and paste the blocks level by level.

    ``guidance`` adds the texture-transfer terms; without it this is plain synthesis, where
    the first block is drawn at random. ``excluded`` (h, w) are source pixels no block may
    contain; ``weights`` (one per candidate corner) make some candidates likelier to be drawn
    than others; ``outside`` (h, w) are the source's pixels of no example (an atlas's margins,
    :mod:`quilting.core.sources`), left out of alpha mode's texture histogram.
    """

    def __init__(
        self,
        source: NDArray[np.float32],
        grid: Grid,
        options: QuiltOptions,
        backend: CostBackend,
        clock: Clock,
        pass_index: int = 0,
        guidance: Guidance | None = None,
        excluded: NDArray[np.bool_] | None = None,
        weights: NDArray[np.float64] | None = None,
        outside: NDArray[np.bool_] | None = None,
    ) -> None:
        self.source = source
        self.grid = grid
        self.options = options
        self.backend = backend
        self.clock = clock
        self.pass_index = pass_index
        block = grid.block
        self.field = CandidateField.of(source.shape, block, excluded, weights)
        self.matched = options.mode not in ("random", "walk")
        # The edge cost keeps cut mode's seams off the bands' edges (issue 20); alpha mode
        # keeps the paper's plain cut, its histogram figures measured with it.
        self.edge_cost = EDGE_COST if options.mode == "cut" else 0.0
        # So does the context (the agreement around a cut, not only on it).
        self.context = CONTEXT if options.mode == "cut" else 0.0
        # Cut and alpha modes join along minimum-error cuts (compiled, the error taken on the
        # strips only); the others along straight lines.
        self.minimum_error = options.mode in ("cut", "alpha")
        # Alpha quilting (the alpha quilting and texture matting paper, §2.1): premultiplied
        # colour, the histogram term, its own epsilon and the factored sampling of the
        # candidates by their seams.
        self.alpha = False
        self.tolerance = options.tolerance
        self.eta = 0.0
        self.terms: HistogramTerm | None = None
        # Cut mode's factored sampling (issue 20): relative to the candidates' median seam.
        self.seam_sampling = 0.0
        self.avoid_continuations = (
            isinstance(options, SynthesisOptions) and options.continuation == "avoid"
        )
        if isinstance(options, SynthesisOptions) and options.mode == "cut":
            self.seam_sampling = options.seam_sampling
        if isinstance(options, SynthesisOptions) and options.mode == "alpha":
            self.alpha, self.tolerance, self.eta = True, options.epsilon, options.eta
            mismatch = histogram_mismatch(source[..., 3], block, outside)
            self.terms = HistogramTerm(backend, mismatch, options.histogram_weight)
            self.backend = self.terms
        self.guidance = guidance
        self.match = self._matching(source)
        # One mask array per kind for the whole pass (backends cache per mask), made on first use.
        self.masks: dict[Overlap, NDArray[np.float32]] = {}
        self.weights: dict[Overlap, _Weights] = {}
        self.scorer = ExactScorer(
            self.match, block, None if guidance is None else guidance.source_map
        )
        self.canvas = np.zeros((grid.height, grid.width, source.shape[2]), dtype=np.float32)
        self.record = LayoutPass.empty(grid, blend=options.blend)
        self.seam_total = 0.0
        self.seam_pixels = 0
        # Made by run(): a level's blend runs beside the next level's selection and paste.
        self.blends = DeferredBlends(clock, deferred=False)

    def _matching(self, pixels: NDArray[np.float32]) -> NDArray[np.float32]:
        """``pixels`` (..., C) as the costs see them: as they are, or their luminance (..., 1);
        in alpha mode premultiplied by their alpha (..., 3 or 1)."""
        return compared(pixels, self.options.error, premultiply=self.alpha)

    def execute(
        self,
        max_batch: int | None,
        progress: Progress | None,
        stage: str = "synthesis",
        span: tuple[float, float] = (0.0, 1.0),
    ) -> None:
        """Prepare the backend, place every block, release the backend.

        ``progress(fraction, stage)`` is called after each level, the fraction going from
        ``span[0]`` to ``span[1]`` over this pass.
        """
        if self.matched:
            guide = None if self.guidance is None else self.guidance.source_map
            self.backend.prepare(self.match, self.grid.block, guide)
        try:
            self.run(max(1, max_batch or DEFAULT_BATCH), progress, stage, span)
        finally:
            if self.matched:
                self.backend.close()

    def run(
        self,
        batch: int,
        progress: Progress | None,
        stage: str = "synthesis",
        span: tuple[float, float] = (0.0, 1.0),
    ) -> None:
        """Place every block; ``progress`` is called after each level."""
        groups = self.grid.groups()
        low, high = span
        # Beside selection only where there are cost fields to wait for (and on a torus wide
        # enough, see may_hand_over).
        self.blends = DeferredBlends(self.clock, deferred=self.matched and may_hand_over(self.grid))
        try:
            for done, (group_rows, group_cols) in enumerate(groups, start=1):
                for start in range(0, group_rows.size, batch):
                    self._place(
                        group_rows[start : start + batch], group_cols[start : start + batch]
                    )
                if progress is not None:
                    progress(low + (high - low) * done / len(groups), stage)
        finally:
            self.blends.close()

    def _blend(
        self,
        templates: NDArray[np.float32],
        blocks: NDArray[np.float32],
        owned: NDArray[np.bool_],
        rows: NDArray[np.intp],
        cols: NDArray[np.intp],
    ) -> None:
        """Blend a batch's seams: the blocks a torus cuts on their far sides now (their
        footprints reach the next level's cells, whose templates read them), the others on the
        blend thread (:class:`~quilting.core.deferred_blend.DeferredBlends`: their cells are read
        only by far blocks at least 3 batches later, when their blends are done)."""
        canvas, grid = self.canvas, self.grid
        far = grid.cut_across_wrap(rows, cols)
        if far.any():
            blend_cells(canvas, templates[far], blocks[far], owned[far], grid, rows[far], cols[far])
            templates, blocks, owned = templates[~far], blocks[~far], owned[~far]
            rows, cols = rows[~far], cols[~far]

        def blend(part: slice, workers: int | None) -> None:
            blend_cells(
                canvas, templates[part], blocks[part], owned[part], grid, rows[part], cols[part],
                workers,
            )  # fmt: skip

        self.blends.add(blend, rows.size, rows.size * grid.step**2 * canvas.shape[-1])

    def _kind(self, kind: Overlap) -> tuple[NDArray[np.float32], _Weights]:
        """The cost mask and the transfer weights of blocks of one overlap kind."""
        if kind not in self.masks:
            mask = self.grid.overlap_mask(kind)
            weights = _Weights()
            if self.guidance is not None:
                weights = self.guidance.weights(mask, self.match.shape[2])
                mask = mask * np.float32(weights.overlap)
            self.masks[kind], self.weights[kind] = mask, weights
        return self.masks[kind], self.weights[kind]

    def _place(self, rows: NDArray[np.intp], cols: NDArray[np.intp]) -> None:
        """Choose, cut and paste a batch of independent blocks (all on one level)."""
        tick = time.perf_counter()
        corners = self.grid.origins(rows, cols)
        pairs = list(zip(rows.tolist(), cols.tolist(), strict=True))
        kinds = [Overlap(int(k)) for k in self.grid.overlap_kinds(rows, cols)]
        rngs = [BlockRandom(self.options.seed, self.pass_index, i, j) for i, j in pairs]
        templates = gather(self.canvas, corners, self.grid.block, wrap=self.grid.wrapped)
        self.clock.add("select", tick)
        chosen = self._choose(templates, corners, kinds, rngs, pairs)
        tick = time.perf_counter()
        positions = self.field.corners(chosen)
        blocks = gather(self.source, positions, self.grid.block)
        cut_cols, cut_rows, cut_right, cut_bottom = self._cut(templates, positions, blocks, kinds)
        tick = self.clock.add("seams", tick)
        far = self.grid.wrapped
        owned = paste(
            self.canvas,
            blocks,
            corners,
            cut_cols,
            cut_rows,
            cut_right if far else None,
            cut_bottom if far else None,
        )
        if self.record.blend == "poisson":
            self._blend(templates, blocks, owned, rows, cols)
        record = self.record
        record.positions[rows, cols] = positions
        record.cut_cols[rows, cols] = cut_cols
        record.cut_rows[rows, cols] = cut_rows
        record.cut_right[rows, cols] = cut_right
        record.cut_bottom[rows, cols] = cut_bottom
        self.clock.add("paste", tick)

    def _requests(
        self,
        templates: NDArray[np.float32],
        corners: NDArray[np.intp],
        kinds: list[Overlap],
        scored: list[int],
    ) -> list[CostRequest]:
        """The cost requests of the scored blocks, with the transfer terms when there are any."""
        guidance = self.guidance
        templates = self._matching(templates)
        if guidance is None:
            return [CostRequest(templates[k], self._kind(kinds[k])[0]) for k in scored]
        block = self.grid.block
        guides = gather(guidance.target_map, corners[scored], block)
        previous = (
            None
            if guidance.previous is None
            else self._matching(gather(guidance.previous, corners[scored], block))
        )
        requests = []
        for q, k in enumerate(scored):
            mask, weights = self._kind(kinds[k])
            requests.append(
                CostRequest(
                    templates[k],
                    mask,
                    previous=None if previous is None else previous[q],
                    previous_weight=weights.previous,
                    guide=guides[q] if weights.guide > 0 else None,
                    guide_weight=weights.guide,
                )
            )
        return requests

    def _shortlists(
        self, requests: list[CostRequest], rngs: list[BlockRandom]
    ) -> list[Shortlist]:
        """The backend's shortlists, with the randomly discarded and the excluded candidates
        taken out (:func:`quilting.core.select.kept_shortlists`)."""
        return kept_shortlists(
            self.backend,
            requests,
            rngs,
            self.field,
            self.tolerance,
            self.options.min_candidates,
            self.options.discard,
        )

    def _choose(
        self,
        templates: NDArray[np.float32],
        corners: NDArray[np.intp],
        kinds: list[Overlap],
        rngs: list[BlockRandom],
        cells: list[tuple[int, int]],
    ) -> NDArray[np.intp]:
        """Flat field index of the source block picked for each block of the batch (at grid
        ``cells``)."""
        tick = time.perf_counter()
        chosen = np.empty(len(kinds), dtype=np.intp)
        # With transfer terms every block has something to match, the first one included.
        scored = [
            k
            for k, kind in enumerate(kinds)
            if self.matched and (kind != Overlap.NONE or self.guidance is not None)
        ]
        for k in sorted(set(range(len(kinds))) - set(scored)):
            chosen[k] = self.field.draw(rngs[k])
        if not scored:
            # Started as after cost fields (start() finishes what runs first), so that a blend
            # is never more than two batches behind (what a torus's far blocks rely on).
            self.blends.start()
            self.clock.add("select", tick)
            return chosen
        requests = self._requests(templates, corners, kinds, scored)
        tick = self.clock.add("select", tick)
        # The cost fields want both cores: the last level's blend ends first, and the blends
        # waiting start once the fields are done.
        self.blends.wait()
        shortlists = self._shortlists(requests, [rngs[k] for k in scored])
        self.blends.start()
        tick = self.clock.add("costs", tick)

        def exact(owner: NDArray[np.intp], index: NDArray[np.intp]) -> NDArray[np.float64]:
            ys, xs = np.divmod(index, self.field.width)
            costs = self.scorer.costs_batch(requests, owner, ys, xs)
            if self.terms is not None:
                costs = costs + self.terms.exact_terms(requests, owner, index)
            return costs

        accepted = acceptable(shortlists, exact, self.tolerance, self.options.min_candidates)
        if self.avoid_continuations:
            accepted = [
                self._without_continuations(a, *cells[k])
                for a, k in zip(accepted, scored, strict=True)
            ]
        for q, k in enumerate(scored):
            if self.alpha or self.seam_sampling > 0:
                chosen[k] = self._factored(
                    templates[k], kinds[k], accepted[q], q, exact, rngs[k].generator
                )
            else:
                chosen[k] = self.field.pick(accepted[q], rngs[k])
        self.clock.add("select", tick)
        return chosen

    def _without_continuations(
        self, candidates: NDArray[np.intp], i: int, j: int
    ) -> NDArray[np.intp]:
        """``candidates`` without the blocks that would continue the source of a neighbour of
        block (i, j) placed before it (left, top, top-left, top-right) verbatim
        (``continuation='avoid'``), unless nothing else is acceptable."""
        step, width = self.grid.step, self.field.width
        continuing = []
        # The neighbours placed before it: left, top, top-left and top-right.
        for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1)):
            if i - di >= 0 and 0 <= j - dj < self.grid.cols:
                y, x = self.record.positions[i - di, j - dj].tolist()
                y, x = y + di * step, x + dj * step
                if 0 <= x < width:
                    continuing.append(y * width + x)
        kept = candidates[~np.isin(candidates, continuing)]
        return kept if kept.size else candidates

    def _factored(
        self,
        template: NDArray[np.float32],
        kind: Overlap,
        candidates: NDArray[np.intp],
        owner: int,
        exact: Callable[[NDArray[np.intp], NDArray[np.intp]], NDArray[np.float64]],
        rng: np.random.Generator,
    ) -> int:
        """Factored sampling (the alpha quilting paper, §2.1.3): one of ``candidates`` (flat
        field indices) drawn with probability ``exp(-eta E)``, E the cost of its minimum-error
        seams (its eq. 3-5); in cut mode ``exp(-seam_sampling E / median E)``."""
        if candidates.size == 1 and not self.alpha:  # (alpha mode draws even so: its bytes)
            return int(candidates[0])
        if self.alpha and candidates.size > MAX_SAMPLED:
            costs = exact(np.full(candidates.size, owner, dtype=np.intp), candidates)
            candidates = candidates[np.lexsort((candidates, costs))[:MAX_SAMPLED]]
        elif candidates.size > SEAM_SAMPLED:
            # Where that many are within tolerance they are all about as good a match: a
            # uniform subset of them, drawn without any cost (a flat texture lists the whole
            # field; ranking it exactly would cost more than the rest of the job).
            drawn = rng.choice(candidates.size, SEAM_SAMPLED, replace=False)
            candidates = candidates[np.sort(drawn)]
        seam_costs = kernels.candidate_seam_costs(
            self.match,
            self._matching(template),
            self.field.corners(candidates),
            **self._cut_rule(kind),
        )
        prior = None if self.field.weights is None else self.field.weights[candidates]
        if self.alpha:
            return int(candidates[factored_pick(seam_costs, self.eta, rng, prior)])
        at = factored_pick(relative_costs(seam_costs), self.seam_sampling, rng, prior)
        return int(candidates[at])

    def _cut_rule(self, kind: Overlap) -> dict[str, Any]:
        """How a block of ``kind`` is cut: the keywords of :func:`kernels.block_cuts`."""
        return {
            "left": kind.left,
            "top": kind.top,
            "right": kind.right,
            "bottom": kind.bottom,
            "overlap": self.grid.overlap,
            "wrap_overlap": self.grid.wrap_overlap,
            "edge_cost": self.edge_cost,
            "context": self.context,
            "radius": CONTEXT_RADIUS,
        }

    def _cut(
        self,
        templates: NDArray[np.float32],
        positions: NDArray[np.intp],
        blocks: NDArray[np.float32],
        kinds: list[Overlap],
    ) -> tuple[NDArray[np.int16], NDArray[np.int16], NDArray[np.int16], NDArray[np.int16]]:
        """Seams of the batch, one call per overlap kind; tallies the seam error.

        ``positions`` (n, 2) are the blocks' corners in the source and ``blocks`` their
        pixels. Returns the near cuts (``cut_cols``, ``cut_rows``) and the far ones
        (``cut_right``, ``cut_bottom``, across the wrap of a torus), each of shape (n, B).
        """
        n, block = len(kinds), self.grid.block
        matched = self._matching(templates)
        if not self.minimum_error:
            # Straight cuts: the error only for the seam tally.
            diff = matched - self._matching(blocks)
            errors = np.einsum("nyxc,nyxc->nyx", diff, diff).astype(np.float64)
        cut_cols = np.zeros((n, block), dtype=np.int16)
        cut_rows = np.zeros((n, block), dtype=np.int16)
        cut_right = np.full((n, block), block, dtype=np.int16)
        cut_bottom = np.full((n, block), block, dtype=np.int16)
        kind_of = np.array([int(kind) for kind in kinds])
        for value in sorted(set(kind_of.tolist()) - {0}):
            kind = Overlap(value)
            members = np.flatnonzero(kind_of == value)
            if self.minimum_error:
                cc, rr, right, bottom, cost = kernels.block_cuts(
                    self.match, matched[members], positions[members], **self._cut_rule(kind)
                )
            else:
                cc, rr, right, bottom, cost = self._kind_cuts(errors[members], kind)
            cut_cols[members], cut_rows[members] = cc, rr
            cut_right[members], cut_bottom[members] = right, bottom
            self.seam_total += float(cost.sum())
            if kind.left and kind.top:
                # The L-shaped seam: vertical from the meeting point down, horizontal from
                # it to the right; the meeting point is (cut_rows[0], cut_cols[0]).
                self.seam_pixels += int((2 * block - 1 - rr[:, 0] - cc[:, 0]).sum())
            elif kind.left or kind.top:
                self.seam_pixels += block * members.size
            self.seam_pixels += block * members.size * (int(kind.right) + int(kind.bottom))
        return cut_cols, cut_rows, cut_right, cut_bottom

    def _kind_cuts(
        self, errors: NDArray[np.float64], kind: Overlap
    ) -> tuple[
        NDArray[np.int16], NDArray[np.int16], NDArray[np.int16], NDArray[np.int16], NDArray[Any]
    ]:
        """The straight near and far cuts of blocks of one overlap kind (overlap and random
        modes), from their error surfaces (n, B, B), and each block's total seam cost (n,)."""
        n, block = errors.shape[0], self.grid.block
        cut_cols = np.zeros((n, block), dtype=np.int16)
        cut_rows = np.zeros((n, block), dtype=np.int16)
        cut_right = np.full((n, block), block, dtype=np.int16)
        cut_bottom = np.full((n, block), block, dtype=np.int16)
        cost: NDArray[Any] = np.zeros(n, dtype=np.float64)
        if kind.left or kind.top:
            cut_cols, cut_rows, near = straight_cuts(
                errors, left=kind.left, top=kind.top, overlap=self.grid.overlap
            )
            cost = cost + near
        if kind.right or kind.bottom:
            cut_right, cut_bottom, far = far_side_cuts(
                straight_cuts,
                errors,
                right=kind.right,
                bottom=kind.bottom,
                overlap=self.grid.wrap_overlap,
            )
            cost = cost + far
        return cut_cols, cut_rows, cut_right, cut_bottom, cost


def synthesis_grid(options: SynthesisOptions, size: tuple[int, int]) -> Grid:
    """The grid of blocks of a synthesis of ``size`` (height, width): a plane, or a torus along
    the tileable axes (refusing a tileable side shorter than the block)."""
    wrap = (options.tileable in ("both", "y"), options.tileable in ("both", "x"))
    return Grid.covering(size[0], size[1], options.block, options.resolved_overlap, wrap)


def quilt(
    view: NDArray[np.generic],
    fmt: PixelFormat,
    size: tuple[int, int],
    options: SynthesisOptions,
    backend: CostBackend,
    *,
    progress: Progress | None = None,
    max_batch: int | None = None,
    excluded: NDArray[np.bool_] | None = None,
    sources: SourceSet | None = None,
    weights: tuple[float, ...] | None = None,
) -> Result:
    """Synthesize a texture of ``size`` from ``view`` by image quilting.

    Parameters
    ----------
    view : ndarray, shape (h, w, C)
        The validated texture in its own dtype (see :func:`quilting.core.pixels.as_channels`).
    fmt : PixelFormat
        How the texture was given, to return the image the same way.
    size : (int, int)
        Output (height, width).
    options : SynthesisOptions
    backend : CostBackend
        Computes the cost fields (unused in ``random`` mode).
    progress : callable, optional
        ``progress(fraction, stage)`` after each level.
    max_batch : int, optional
        Most blocks per backend call; never changes the output.
    excluded : ndarray of bool, shape (h, w), optional
        Texture pixels never to use (see :mod:`quilting.core.exclusion`).
    sources : SourceSet, optional
        ``view`` is the atlas of several or transformed examples
        (:class:`quilting.core.sources.Examples`); the layout records it.
    weights : tuple of float, optional
        With ``sources``: each example's weight in the draws.

    Returns
    -------
    Result
    """
    started = time.perf_counter()
    clock = Clock()
    check_block_fits(options, view.shape[0], view.shape[1])
    source = to_working(view)
    # 'auto' decided by the texture ('alpha' for RGBA) and the sources; the layout records
    # what ran.
    options = replace(
        options,
        mode=options.resolved_mode(source.shape[2]),
        continuation=options.resolved_continuation(1 if sources is None else len(sources.examples)),
    )
    grid = synthesis_grid(options, size)
    drawn = None
    if sources is not None and weights is not None:
        drawn = sources.candidate_weights(grid.block, weights)
    work: QuiltPass | WalkPass = (
        WalkPass(source, grid, options, backend, clock, excluded, drawn)
        if options.mode == "walk"
        else QuiltPass(
            source,
            grid,
            options,
            backend,
            clock,
            excluded=excluded,
            weights=drawn,
            outside=None if sources is None else sources.excluded(),
        )
    )
    work.execute(max_batch, progress)
    layout = Layout(
        source_shape=(source.shape[0], source.shape[1]),
        output_shape=size,
        passes=[work.record],
        meta={"operation": "synthesize", **options.to_dict(), "overlap": grid.overlap},
        sources=sources,
    )
    return finish(view, fmt, layout, work, clock, started)


def finish(
    view: NDArray[np.generic],
    fmt: PixelFormat,
    layout: Layout,
    work: QuiltPass | WalkPass,
    clock: Clock,
    started: float,
    **extra_stats: float,
) -> Result:
    """The :class:`Result` of a job whose last pass is ``work``: the image in the input's
    format, the stats (seams of that last pass) and the timings."""
    size = layout.output_shape
    tick = time.perf_counter()
    converted = from_working(work.canvas[: size[0], : size[1]], fmt.dtype)
    image = fmt.restore(layout.render(view) if converted is None else converted)
    tick = clock.add("render", tick)
    largest_copy, unused = repetition(layout)
    stats = SynthesisStats(
        seam_error_total=work.seam_total,
        seam_error_mean=work.seam_total / work.seam_pixels if work.seam_pixels else 0.0,
        seam_pixels=work.seam_pixels,
        largest_copy=largest_copy,
        unused=unused,
        **extra_stats,
    )
    clock.add("stats", tick)
    clock.spent["total"] = time.perf_counter() - started
    backend = work.backend
    # Random mode computes no cost fields.
    return Result(
        image=image,
        layout=layout,
        backend=backend.name if work.matched else "none",
        timings=clock.spent,
        stats=stats,
        renderer=backend.renderer if work.matched else None,
        fallback=getattr(backend, "fallback", None) if work.matched else None,
    )
