"""The quilting loop (Efros & Freeman 2001, §2.2), driven level by level.

For each wavefront level: read what the output already holds under every block, ask the
backend for one batch of cost fields, pick each block among the acceptable candidates with the
block's own generator, cut every seam of the level in one batch, paste. The output depends on
the options and seed only.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from quilting.core.compose import gather, paste
from quilting.core.errors import InvalidParameterError
from quilting.core.fields import CostBackend, CostRequest, ExactScorer
from quilting.core.grid import Grid, Overlap
from quilting.core.layout import Layout, LayoutPass
from quilting.core.options import SynthesisOptions
from quilting.core.pixels import PixelFormat, to_working
from quilting.core.randomness import block_rng
from quilting.core.seams import minimum_error_cuts, straight_cuts
from quilting.core.select import acceptable, pick
from quilting.core.stats import SynthesisStats, repetition, seam_overlay

Progress = Callable[[float, str], object]
"""``progress(fraction, stage)``, called between levels; raising from it stops the job."""

DEFAULT_BATCH = 64


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
        Name of the cost backend that computed the fields.
    timings : dict of str to float
        Seconds spent per stage (``costs``, ``select``, ``seams``, ``paste``, ``render``,
        ``stats``) and in all (``total``).
    stats : SynthesisStats
        Seam error and repetition measures.
    """

    image: NDArray[np.generic]
    layout: Layout
    backend: str
    timings: dict[str, float] = field(default_factory=dict)
    stats: SynthesisStats | None = None

    def seam_overlay(
        self, color: tuple[float, float, float] = (1.0, 0.0, 0.0)
    ) -> NDArray[np.uint8]:
        """The image as RGB uint8 (H, W, 3) with the block boundaries drawn in ``color``."""
        return seam_overlay(self.image, self.layout, color)


@dataclass
class _Clock:
    spent: dict[str, float] = field(default_factory=dict)

    def add(self, stage: str, since: float) -> float:
        now = time.perf_counter()
        self.spent[stage] = self.spent.get(stage, 0.0) + now - since
        return now


def check_block_fits(options: SynthesisOptions, height: int, width: int) -> None:
    """Refuse a block larger than the texture, naming the allowed range."""
    if options.block > min(height, width):
        raise InvalidParameterError(
            "block",
            options.block,
            f"3..{min(height, width)} for a {width}x{height} texture",
            "the block is larger than the texture",
        )


def quilt(
    view: NDArray[np.generic],
    fmt: PixelFormat,
    size: tuple[int, int],
    options: SynthesisOptions,
    backend: CostBackend,
    *,
    progress: Progress | None = None,
    max_batch: int | None = None,
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

    Returns
    -------
    Result
    """
    started = time.perf_counter()
    clock = _Clock()
    check_block_fits(options, view.shape[0], view.shape[1])
    source = to_working(view)
    src_h, src_w, channels = source.shape
    block, overlap = options.block, options.resolved_overlap
    grid = Grid.covering(size[0], size[1], block, overlap)
    batch = max(1, max_batch or DEFAULT_BATCH)
    field_w = src_w - block + 1
    candidates = (src_h - block + 1) * field_w
    matched = options.mode != "random"
    cutter = minimum_error_cuts if options.mode == "cut" else straight_cuts

    masks = {kind: grid.overlap_mask(kind) for kind in Overlap}

    canvas = np.zeros((grid.height, grid.width, channels), dtype=np.float32)
    record = LayoutPass.empty(grid)
    scorer = ExactScorer(source, block)
    if matched:
        backend.prepare(source, block)
    seam_total, seam_pixels = 0.0, 0
    tick = time.perf_counter()
    for level in range(grid.levels):
        level_rows, level_cols = grid.level(level)
        for start in range(0, level_rows.size, batch):
            rows = level_rows[start : start + batch]
            cols = level_cols[start : start + batch]
            corners = grid.origins(rows, cols)
            kinds = [
                Grid.overlap_kind(i, j) for i, j in zip(rows.tolist(), cols.tolist(), strict=True)
            ]
            rngs = [
                block_rng(options.seed, 0, i, j)
                for i, j in zip(rows.tolist(), cols.tolist(), strict=True)
            ]
            templates = gather(canvas, corners, block)
            chosen = np.empty(rows.size, dtype=np.intp)
            scored = [k for k, kind in enumerate(kinds) if matched and kind is not Overlap.NONE]
            for k in set(range(rows.size)) - set(scored):
                chosen[k] = rngs[k].integers(candidates)
            tick = clock.add("select", tick)
            if scored:
                requests = [CostRequest(templates[k], masks[kinds[k]]) for k in scored]
                fields = backend.fields(requests)
                tick = clock.add("costs", tick)

                def exact(
                    owner: NDArray[np.intp],
                    index: NDArray[np.intp],
                    requests: list[CostRequest] = requests,
                ) -> NDArray[np.float64]:
                    ys, xs = np.divmod(index, field_w)
                    return scorer.costs_batch(requests, owner, ys, xs)

                accepted = acceptable(
                    fields.values,
                    fields.error_bound,
                    exact,
                    options.tolerance,
                    options.min_candidates,
                )
                for q, k in enumerate(scored):
                    chosen[k] = pick(accepted[q], rngs[k])
                tick = clock.add("select", tick)
            positions = np.stack(np.divmod(chosen, field_w), axis=-1)
            blocks = gather(source, positions, block)
            diff = templates - blocks
            errors = np.einsum("nyxc,nyxc->nyx", diff, diff).astype(np.float64)
            cut_cols = np.zeros((rows.size, block), dtype=np.int16)
            cut_rows = np.zeros((rows.size, block), dtype=np.int16)
            kind_of = np.array([int(kind) for kind in kinds])
            for kind in (Overlap.LEFT, Overlap.TOP, Overlap.BOTH):
                members = np.flatnonzero(kind_of == kind)
                if members.size:
                    cc, rr, cost = cutter(
                        errors[members], left=kind.left, top=kind.top, overlap=overlap
                    )
                    cut_cols[members], cut_rows[members] = cc, rr
                    seam_total += float(cost.sum())
                    if kind is Overlap.BOTH:
                        seam_pixels += int((2 * block - 1 - rr[:, 0] - cc[:, 0]).sum())
                    else:
                        seam_pixels += block * members.size
            tick = clock.add("seams", tick)
            paste(canvas, blocks, corners, cut_cols, cut_rows)
            record.positions[rows, cols] = positions
            record.cut_cols[rows, cols] = cut_cols
            record.cut_rows[rows, cols] = cut_rows
            tick = clock.add("paste", tick)
        if progress is not None:
            progress((level + 1) / grid.levels, "synthesis")
        tick = time.perf_counter()
    if matched:
        backend.close()

    layout = Layout(
        source_shape=(src_h, src_w),
        output_shape=size,
        passes=[record],
        meta={"operation": "synthesize", **options.to_dict(), "overlap": overlap},
    )
    image = fmt.restore(layout.render(view))
    tick = clock.add("render", tick)
    largest_copy, unused = repetition(layout)
    stats = SynthesisStats(
        seam_error_total=seam_total,
        seam_error_mean=seam_total / seam_pixels if seam_pixels else 0.0,
        seam_pixels=seam_pixels,
        largest_copy=largest_copy,
        unused=unused,
    )
    clock.add("stats", tick)
    clock.spent["total"] = time.perf_counter() - started
    return Result(
        image=image, layout=layout, backend=backend.name, timings=clock.spent, stats=stats
    )
