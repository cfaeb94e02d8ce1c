"""Filling a hole in an image by image quilting with known pixels anywhere (inpainting).

The hole is covered by a grid of blocks that overlap by ``overlap`` pixels. A block is
matched against every pixel under it that is known, from the image or filled before: the cost
field ``E = sum M (S - T)^2`` with M the block's known pixels, an arbitrary mask (one cost
request per block, ``shared_mask=False``; see :mod:`quilting.costs.fft` for the masked energy
by FFT). Candidates are the blocks of the image that contain no hole pixel (or every block of
a given texture); the tolerance rule and the exact re-scoring are synthesis's, so every
backend chooses the same blocks. The block is joined to what is known along a minimum cut of
its footprint (:mod:`quilting.core.kernels.region_cut`): the image's known pixels and the old
output on the block's rim stay, the pixels nobody has written yet take the block, the cut
decides the rest. The seam is then blended as synthesis blends its cells, never changing a
known pixel.

Fill order: onion peel by blocks. Each round takes the blocks still to place whose footprint
holds a known pixel (the hole's outermost ring), best-constrained first (most known pixels,
then row-major), packed into batches of blocks whose footprints do not overlap, each batch one
backend call; a batch's blocks see everything earlier batches wrote. A block then always has
known pixels on the side facing the hole's border, which is what the match needs; ordering by
the count of known pixels (not by an image-structure term, as Criminisi et al.'s priority
does) keeps the order a pure function of the hole's shape, so the same seed gives the same
bytes whatever the batch size or backend, and the rounds keep batches large.

References
----------
.. [1] A. A. Efros and W. T. Freeman, "Image Quilting for Texture Synthesis and Transfer",
       SIGGRAPH 2001, §2.2 (blocks matched on their overlap with what is there, the tolerance
       rule; here the overlap is every known pixel under the block).
.. [2] V. Kwatra, A. Schoedl, I. Essa, G. Turk and A. Bobick, "Graphcut Textures: Image and
       Video Synthesis Using Graph Cuts", SIGGRAPH 2003, §3 (the seam of an arbitrary overlap
       as a minimum cut, old pixels on the patch's border kept).
.. [3] A. Criminisi, P. Perez and K. Toyama, "Region Filling and Object Removal by
       Exemplar-Based Image Inpainting", IEEE TIP 13(9), 2004, §3 (filling from the hole's
       border inward, blocks with more known pixels first).
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from quilting.core import kernels
from quilting.core.blend import cell_corrections
from quilting.core.compose import gather
from quilting.core.errors import InvalidImageError, InvalidParameterError
from quilting.core.exclusion import CandidateField, allowed_candidates
from quilting.core.fields import CostBackend
from quilting.core.fill_layout import FillLayout
from quilting.core.fill_search import FillSearch, search_scale
from quilting.core.layout import renormalize
from quilting.core.options import FillOptions
from quilting.core.pixels import PixelFormat, compared, from_working, to_working
from quilting.core.progress import Clock, Progress
from quilting.core.randomness import BlockRandom
from quilting.core.stats import draw_seams

#: Pixel states of the region cut (:mod:`quilting.core.kernels.region_cut`).
_FREE, _OLD, _NEW = 0, 1, 2
#: Blocks per backend call when the caller gives no limit.
DEFAULT_BATCH = 64


@dataclass(frozen=True)
class Filled:
    """What a fill returns.

    Attributes
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        The image with the hole filled, same shape and dtype as the input; every pixel
        outside the hole is the input's, byte for byte.
    filled : ndarray of bool, shape (H, W)
        The pixels that were synthesized (the hole).
    layout : FillLayout
        Every block placed, where it came from and the pixels it took: what :meth:`apply`
        replays, and what the service and ``quilting apply-layout`` save as JSON. The
        provenance, the source and the count of blocks below are read from it.
    backend : str
        The cost backend that computed the fields.
    timings : dict of str to float
        Seconds per stage (``costs``, ``select``, ``seams``, ``paste``) and in all (``total``).
    seam_error : float
        Mean squared difference across the cuts, per cut edge (0 without cuts).
    rounds : ndarray of int16, shape (H, W), or None
        The fill order: the onion-peel round (0 first) whose block last wrote each pixel; -1
        where no block wrote (None for an empty mask).
    replay : FillReplay or None
        The fill done again to a companion map, blended as the image was (None for an empty
        mask and when the blocks came from a texture or an extension's input).
    """

    image: NDArray[np.generic]
    filled: NDArray[np.bool_]
    layout: FillLayout
    backend: str
    timings: dict[str, float] = field(default_factory=dict)
    seam_error: float = 0.0
    rounds: NDArray[np.int16] | None = None
    replay: FillReplay | None = field(default=None, repr=False, compare=False)

    @functools.cached_property
    def _provenance(self) -> tuple[NDArray[np.int32], NDArray[np.int32]]:
        return self.layout.provenance()

    @property
    def source_rows(self) -> NDArray[np.int32]:
        """(H, W): the source row each pixel of the hard selection (before any blend) came
        from: in the image itself (a known pixel points at itself), in the input of an
        extension, or in the texture (a known pixel then holds -1)."""
        return self._provenance[0]

    @property
    def source_cols(self) -> NDArray[np.int32]:
        """(H, W): the source column, as :attr:`source_rows`."""
        return self._provenance[1]

    @property
    def from_texture(self) -> bool:
        """Whether the blocks came from a given texture rather than from the image."""
        return self.layout.source == "texture"

    @property
    def placed(self) -> tuple[int, int] | None:
        """For :func:`quilting.extend`: where the input's top-left corner lies in ``image``."""
        return self.layout.placed

    @property
    def blocks(self) -> int:
        """Blocks placed."""
        return int(self.layout.corners.shape[0])

    def apply(
        self, companion: NDArray[np.generic], texture_companion: NDArray[np.generic] | None = None
    ) -> NDArray[np.generic]:
        """A companion map (normals, roughness...) filled the way the image was: see
        :meth:`quilting.core.fill_layout.FillLayout.apply` (the image's companion, of its size
        for a fill, of the input's for an extension; the texture's too when the blocks came
        from a texture)."""
        return self.layout.apply(companion, texture_companion)

    def seam_overlay(
        self, color: tuple[float, float, float] = (1.0, 0.0, 0.0)
    ) -> NDArray[np.uint8]:
        """The image as RGB uint8 (H, W, 3) with the fill's seams drawn in ``color``."""
        return draw_seams(self.image, self.layout.seam_mask(), color)


def origins(side: int, block: int, overlap: int) -> NDArray[np.intp]:
    """Block origins along one side: evenly spread from 0 to ``side - block``, neighbours at
    most ``block - overlap`` apart (so they overlap by at least ``overlap``)."""
    if side <= block:
        return np.zeros(1, dtype=np.intp)
    count = -(-(side - block) // (block - overlap)) + 1
    return np.rint(np.linspace(0, side - block, count)).astype(np.intp)


def largest_block(known: NDArray[np.bool_], below: int) -> int:
    """The largest block side under ``below`` that fits somewhere in ``known`` pixels, or 0."""
    low, high = 0, below - 1
    while low < high:  # fitting is monotone: a block that fits holds every smaller one
        mid = (low + high + 1) // 2
        if mid <= min(known.shape) and allowed_candidates(~known, mid).any():
            low = mid
        else:
            high = mid - 1
    return low


def _window_counts(
    flags: NDArray[np.bool_], corners: NDArray[np.intp], block: int
) -> NDArray[np.int64]:
    """How many set pixels each ``block x block`` window at ``corners`` (n, 2) holds."""
    windows = np.lib.stride_tricks.sliding_window_view(flags, (block, block))
    counts: NDArray[np.int64] = windows[corners[:, 0], corners[:, 1]].sum(
        axis=(1, 2), dtype=np.int64
    )
    return counts


def _independent(
    order: list[int], cells: NDArray[np.intp], corners: NDArray[np.intp], block: int
) -> list[list[int]]:
    """``order`` packed greedily into batches whose footprints do not overlap (a block goes
    into the first batch none of whose blocks it overlaps), each batch in ``order``'s order."""
    batches: list[list[int]] = []
    placed: dict[tuple[int, int], tuple[int, int]] = {}  # grid cell -> (block, batch)
    for k in order:
        i, j = int(cells[k, 0]), int(cells[k, 1])
        taken = set()
        # Neighbours are over block / 2 apart, so footprints overlap within two grid steps.
        for di in range(-2, 3):
            for dj in range(-2, 3):
                other = placed.get((i + di, j + dj))
                if other is not None and bool(
                    (np.abs(corners[other[0]] - corners[k]) < block).all()
                ):
                    taken.add(other[1])
        slot = next((b for b in range(len(batches)) if b not in taken), len(batches))
        if slot == len(batches):
            batches.append([])
        batches[slot].append(k)
        placed[(i, j)] = (k, slot)
    return batches


def check_fill(
    shape: tuple[int, int],
    hole: NDArray[np.bool_],
    options: FillOptions,
    texture_shape: tuple[int, int] | None,
) -> None:
    """Refuse a fill that cannot run, before any work: a block larger than the image or the
    texture, a hole covering everything without a texture, no block outside the hole."""
    height, width = shape
    block = options.block
    if options.search_scale and block // options.search_scale < 3:
        raise InvalidParameterError(
            "search_scale",
            options.search_scale,
            f"0 (automatic) or 1..{block // 3} for block={block}",
            "the coarse block (block / search_scale) must be at least 3 pixels",
        )
    if block > min(height, width):
        raise InvalidParameterError(
            "block", block, f"3..{min(height, width)} for a {width}x{height} image",
            "the block is larger than the image",
        )  # fmt: skip
    if texture_shape is not None:
        if block > min(texture_shape):
            raise InvalidParameterError(
                "block", block, f"3..{min(texture_shape)} for a "
                f"{texture_shape[1]}x{texture_shape[0]} texture",
                "the block is larger than the texture",
            )  # fmt: skip
        return
    if hole.all():
        raise InvalidImageError(
            "the mask covers the whole image: there is nothing to fill it from; give a texture"
        )
    if not allowed_candidates(hole, block).any():
        fits = largest_block(~hole, block)
        advice = (
            f"block={fits} (the largest that fits), or give a texture"
            if fits >= 3
            else "a smaller hole, or give a texture"
        )
        raise InvalidParameterError(
            "block",
            block,
            advice,
            f"no {block}x{block} block of the image lies wholly outside the hole",
        )


class FillPass:
    """One fill: the blocks over the hole placed round by round, batch by batch."""

    def __init__(
        self,
        image: NDArray[np.float32],
        hole: NDArray[np.bool_],
        options: FillOptions,
        backend: CostBackend,
        clock: Clock,
        texture: NDArray[np.float32] | None = None,
        fixed: NDArray[np.bool_] | None = None,
    ) -> None:
        self.options = options
        self.backend = backend
        self.clock = clock
        self.block = block = options.block
        self.hole = hole
        # The pixels no cut may take: every known pixel, unless the caller frees a margin.
        self.known = ~hole if fixed is None else fixed & ~hole
        self.source = image if texture is None else texture
        self.from_texture = texture is not None
        self.match = compared(self.source, options.error)
        self.field = CandidateField.of(self.source.shape, block, hole if texture is None else None)
        scale = search_scale(options.search_scale, block, self.source.shape[:2])
        self.search = FillSearch(
            self.match, block, self.field, backend, clock, scale, options.tolerance,
            options.min_candidates,
        )  # fmt: skip
        self.canvas = np.where(hole[..., None], np.float32(0), image)
        self.covered = ~hole
        height, width = hole.shape
        ys = origins(height, block, options.resolved_overlap)
        xs = origins(width, block, options.resolved_overlap)
        cells = np.stack(np.meshgrid(np.arange(ys.size), np.arange(xs.size), indexing="ij"), -1)
        cells = cells.reshape(-1, 2)
        corners = np.stack([ys[cells[:, 0]], xs[cells[:, 1]]], axis=-1)
        over_hole = _window_counts(hole, corners, block) > 0
        self.cells, self.corners = cells[over_hole], corners[over_hole]
        self.rounds = np.full(hole.shape, -1, dtype=np.int16)
        self.round = 0
        # The layout's blocks, in the order they are placed.
        self.placed: list[tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]] = []
        self.seam_total = 0.0
        self.seam_edges = 0

    def run(self, max_batch: int, progress: Progress | None) -> None:
        """Place every block, calling ``progress(fraction, "fill")`` after each batch."""
        if self.corners.shape[0] == 0:
            return
        self.search.prepare()
        try:
            self._rounds(max_batch, progress)
        finally:
            self.search.close()

    def _rounds(self, max_batch: int, progress: Progress | None) -> None:
        remaining = np.ones(self.corners.shape[0], dtype=bool)
        total = int(self.hole.sum())
        while remaining.any():
            left = np.flatnonzero(remaining)
            counts = _window_counts(self.covered, self.corners[left], self.block)
            frontier = left[counts > 0]
            if frontier.size == 0:
                # Nothing known anywhere (a texture fills the whole image): start at the first
                # block, drawn at random as synthesis's first block is.
                frontier, counts = left[:1], np.zeros(1, dtype=np.int64)
            else:
                counts = counts[counts > 0]
            order = sorted(
                range(frontier.size),
                key=lambda q: (-int(counts[q]), int(self.cells[frontier[q], 0]),
                               int(self.cells[frontier[q], 1])),
            )  # fmt: skip
            picked = [int(frontier[q]) for q in order]
            for batch in _independent(picked, self.cells, self.corners, self.block):
                for start in range(0, len(batch), max_batch):
                    self._place(np.array(batch[start : start + max_batch], dtype=np.intp))
                remaining[batch] = False
                if progress is not None:
                    done = total - int((~self.covered).sum())
                    progress(done / total if total else 1.0, "fill")
            self.round += 1

    def _place(self, members: NDArray[np.intp]) -> None:
        """Choose, cut, paste and blend a batch of blocks whose footprints do not overlap."""
        tick = time.perf_counter()
        block = self.block
        corners = self.corners[members]
        cells = self.cells[members]
        rngs = [BlockRandom(self.options.seed, 0, int(i), int(j)) for i, j in cells]
        old = gather(self.canvas, corners, block)
        covered = gather(self.covered[..., None], corners, block)[..., 0]
        known = gather(self.known[..., None], corners, block)[..., 0]
        match_old = compared(old, self.options.error)
        chosen = np.empty(members.size, dtype=np.intp)
        scored = [k for k in range(members.size) if covered[k].any()]
        for k in sorted(set(range(members.size)) - set(scored)):
            chosen[k] = self.field.draw(rngs[k])
        tick = self.clock.add("select", tick)
        if scored:  # the search books its own time, as costs and select
            chosen[scored] = self.search.choose(
                match_old[scored], covered[scored], [rngs[k] for k in scored]
            )
            tick = time.perf_counter()
        positions = self.field.corners(chosen)
        blocks = gather(self.source, positions, block)
        owned = self._cut(match_old, compared(blocks, self.options.error), covered, known,
                          corners)  # fmt: skip
        tick = self.clock.add("seams", tick)
        paste_batch(self.canvas, self.covered, corners, old, blocks, owned, covered, known,
                    self.options.blend,
                    (self.rounds, min(self.round, np.iinfo(np.int16).max)))  # fmt: skip
        self.placed.append((corners, positions, owned))
        self.clock.add("paste", tick)

    def replay(self, layout: FillLayout) -> FillReplay | None:
        """How to fill and blend a companion map the way this fill did the image (None when
        the blocks came from another image: a texture or an extension's input)."""
        if self.from_texture:
            return None
        batches = tuple(len(corners) for corners, _, _ in self.placed)
        return FillReplay(layout, self.hole, self.known, batches, self.options.blend)

    def layout(self, shape: tuple[int, int], placed: tuple[int, int] | None) -> FillLayout:
        """The blocks placed, as a :class:`FillLayout`; ``placed``: an extension's input's
        corner (the blocks came from that input, not from a texture)."""
        block = self.block
        corners = [c for c, _, _ in self.placed]
        positions = [p for _, p, _ in self.placed]
        owned = [o for _, _, o in self.placed]
        return FillLayout(
            shape=shape,
            source_shape=(self.source.shape[0], self.source.shape[1]),
            source="texture" if self.from_texture and placed is None else "image",
            placed=placed,
            block=block,
            corners=np.concatenate(corners) if corners else np.zeros((0, 2), np.intp),
            positions=np.concatenate(positions) if positions else np.zeros((0, 2), np.intp),
            owned=np.concatenate(owned) if owned else np.zeros((0, block, block), bool),
            meta={"operation": "fill", **self.options.to_dict()},
        )

    def _cut(
        self,
        old: NDArray[np.float32],
        new: NDArray[np.float32],
        covered: NDArray[np.bool_],
        known: NDArray[np.bool_],
        corners: NDArray[np.intp],
    ) -> NDArray[np.bool_]:
        """Where each block takes the pixel: a minimum cut between the pixels that must stay
        (known, or on the rim where the old output goes on outside the block) and those
        nobody has written (which must take the block)."""
        block = self.block
        height, width = self.hole.shape
        errors = (((old - new) ** 2).sum(axis=-1) * covered).astype(np.float64)
        state = np.where(covered, _FREE, _NEW).astype(np.int8)
        rim = np.zeros((corners.shape[0], block, block), dtype=bool)
        rim[corners[:, 0] > 0, 0, :] = True
        rim[corners[:, 0] + block < height, -1, :] = True
        rim[corners[:, 1] > 0, :, 0] = True
        rim[corners[:, 1] + block < width, :, -1] = True
        state[known | (rim & covered)] = _OLD
        owned: NDArray[np.bool_] = kernels.region_cuts(errors, state)
        # The seam's cost: the squared difference on both pixels of every edge it cuts.
        across = (owned[:, :, 1:] != owned[:, :, :-1]) & covered[:, :, 1:] & covered[:, :, :-1]
        down = (owned[:, 1:, :] != owned[:, :-1, :]) & covered[:, 1:, :] & covered[:, :-1, :]
        self.seam_total += (
            float(
                ((errors[:, :, 1:] + errors[:, :, :-1]) * across).sum()
                + ((errors[:, 1:, :] + errors[:, :-1, :]) * down).sum()
            )
            / 2
        )
        self.seam_edges += int(across.sum() + down.sum())
        return owned


def fill_image(
    view: NDArray[np.generic],
    fmt: PixelFormat,
    hole: NDArray[np.bool_],
    options: FillOptions,
    backend: CostBackend,
    *,
    texture: NDArray[np.generic] | None = None,
    placed: tuple[int, int] | None = None,
    fixed: NDArray[np.bool_] | None = None,
    progress: Progress | None = None,
    max_batch: int | None = None,
) -> Filled:
    """Fill the ``hole`` of a validated image (the engine behind :func:`quilting.fill`).

    Parameters
    ----------
    view : ndarray, shape (H, W, C)
        The image, in its own dtype (see :func:`quilting.core.pixels.as_channels`).
    fmt : PixelFormat
        How it was given.
    hole : ndarray of bool, shape (H, W)
        The pixels to synthesize.
    options : FillOptions
    backend : CostBackend
    texture : ndarray, shape (h, w, C), optional
        Where blocks come from instead of the image (same channels and dtype).
    placed : (int, int), optional
        An extension: ``texture`` is the input, placed with its top-left corner here in
        ``view``; the provenance and the layout then point into it as into the image.
    fixed : ndarray of bool, shape (H, W), optional
        The known pixels that must stay (default: all of them). Known pixels left out are
        matched like the others but the cuts may replace them: a margin around a hole whose
        outline is no edge of the image (the bands of :mod:`quilting.core.seamless_fill`).
    progress : callable, optional
        ``progress(fraction, "fill")`` after each batch; raise from it to stop.
    max_batch : int, optional
        Most blocks per backend call; never changes the output.

    Returns
    -------
    Filled
    """
    started = time.perf_counter()
    clock = Clock()
    if not hole.any():  # nothing to fill: the image as it is
        return Filled(
            image=fmt.restore(view.copy()),
            filled=hole.copy(),
            layout=FillLayout.empty(hole.shape, options),
            backend=backend.name,
            timings={"total": time.perf_counter() - started},
        )
    check_fill(hole.shape, hole, options, None if texture is None else texture.shape[:2])
    work = FillPass(
        to_working(view),
        hole,
        options,
        backend,
        clock,
        None if texture is None else to_working(texture),
        fixed,
    )
    work.run(max(1, max_batch or DEFAULT_BATCH), progress)
    tick = time.perf_counter()
    layout = work.layout(hole.shape, placed)
    out = _output(work.canvas, view, texture, layout, options.blend, work.known)
    clock.add("render", tick)
    clock.spent["total"] = time.perf_counter() - started
    return Filled(
        image=fmt.restore(out),
        filled=hole.copy(),
        rounds=work.rounds,
        layout=layout,
        backend=backend.name,
        timings=clock.spent,
        seam_error=work.seam_total / work.seam_edges if work.seam_edges else 0.0,
        replay=work.replay(layout),
    )


def paste_batch(
    canvas: NDArray[np.float32],
    covered: NDArray[np.bool_],
    corners: NDArray[np.intp],
    old: NDArray[np.float32],
    blocks: NDArray[np.float32],
    owned: NDArray[np.bool_],
    old_covered: NDArray[np.bool_],
    known: NDArray[np.bool_],
    blend: str,
    rounds: tuple[NDArray[np.int16], int] | None = None,
) -> None:
    """Paste a batch of blocks whose footprints do not overlap, each cell blended across its
    cut when ``blend="poisson"``; the fill and its replay on a companion share it.

    Parameters
    ----------
    canvas : ndarray of float32, shape (H, W, C), updated
    covered : ndarray of bool, shape (H, W), updated
        The pixels some block or the image wrote; every footprint becomes covered.
    corners : ndarray of intp, shape (n, 2)
        Each block's (y, x) in the canvas.
    old, blocks : ndarray of float32, shape (n, B, B, C)
        The canvas under each footprint before the batch, and the blocks' pixels.
    owned : ndarray of bool, shape (n, B, B)
        Where the cuts give the block the pixel.
    old_covered, known : ndarray of bool, shape (n, B, B)
        ``covered`` under each footprint before the batch, and the pixels no blend may change.
    blend : {"none", "poisson"}
    rounds : (ndarray of int16, shape (H, W), int), optional
        The fill's order map, updated, and the round to write where a block takes a pixel.
    """
    pasted = np.where(owned[..., None], blocks, old)
    if blend == "poisson":
        corrections = cell_corrections(old, blocks, owned, old_covered)
        corrections[known] = 0  # fixed pixels never change
        pasted += corrections
    block = owned.shape[1]
    for k, (y, x) in enumerate(corners.tolist()):
        window = np.s_[y : y + block, x : x + block]
        canvas[window] = pasted[k]
        covered[window] = True
        if rounds is not None:
            rounds[0][window][owned[k]] = rounds[1]


@dataclass(frozen=True)
class FillReplay:
    """A fill from the image itself, to be done again to a companion map of its size: the
    same blocks, cuts and batches, each batch's cells blended from the companion's own values
    as the image's were (:func:`paste_batch`), so a companion equal to the image comes back
    equal to the fill's output, byte for byte.

    Attributes
    ----------
    layout : FillLayout
        The blocks, in order; their sources lie in the image.
    hole : ndarray of bool, shape (H, W)
    known : ndarray of bool, shape (H, W)
        The pixels no cut or blend changed.
    batches : tuple of int
        How many blocks each paste took, in order.
    blend : {"none", "poisson"}
    """

    layout: FillLayout
    hole: NDArray[np.bool_]
    known: NDArray[np.bool_]
    batches: tuple[int, ...]
    blend: str

    def render(
        self, companion: NDArray[np.generic], *, normal: bool = False
    ) -> NDArray[np.generic]:
        """Fill ``companion`` (H, W, C), the image's size, in its own dtype; ``normal``: make
        the first three channels unit vectors again (a tangent-space normal map) before the
        one rounding. The known pixels are returned byte for byte."""
        working = to_working(companion)
        canvas = np.where(self.hole[..., None], np.float32(0), working)
        covered = ~self.hole
        block, start = self.layout.block, 0
        for count in self.batches:
            corners = self.layout.corners[start : start + count]
            positions = self.layout.positions[start : start + count]
            owned = self.layout.owned[start : start + count]
            start += count
            paste_batch(
                canvas,
                covered,
                corners,
                gather(canvas, corners, block),
                gather(working, positions, block),
                owned,
                gather(covered[..., None], corners, block)[..., 0],
                gather(self.known[..., None], corners, block)[..., 0],
                self.blend,
            )
        if normal:
            renormalize(canvas)
        return _output(canvas, companion, None, self.layout, self.blend, self.known)


def _output(
    canvas: NDArray[np.float32],
    view: NDArray[np.generic],
    texture: NDArray[np.generic] | None,
    layout: FillLayout,
    blend: str,
    known: NDArray[np.bool_],
) -> NDArray[np.generic]:
    """The filled canvas (H, W, C) in ``view``'s dtype (the canvas is overwritten), the
    ``known`` pixels (H, W) byte for byte whatever the working format's round trip."""
    converted = from_working(canvas, view.dtype)
    if converted is None:
        converted = _float_output(canvas, view, texture, layout, blend)
    converted[known] = view[known]
    return converted


def _float_output(
    canvas: NDArray[np.float32],
    view: NDArray[np.generic],
    texture: NDArray[np.generic] | None,
    layout: FillLayout,
    blend: str,
) -> NDArray[np.generic]:
    """The fill in a float dtype the working float32 cannot return exactly (float16, float64).

    Unblended, every filled pixel is a copy of a source pixel, taken from the source in its
    own dtype; blended, the canvas is cast as it was computed. Neither is clipped to [0, 1]:
    a float image may hold any finite values, and synthesis keeps them too.

    Parameters
    ----------
    canvas : ndarray, shape (H, W, C), float32
    view : ndarray, shape (H, W, C)
        The image being filled.
    texture : ndarray, shape (h, w, C), optional
        Where the blocks came from instead (a texture, or an extension's input).
    layout : FillLayout
    blend : {"none", "poisson"}

    Returns
    -------
    ndarray, shape (H, W, C), ``view``'s dtype
    """
    if blend != "none":
        cast: NDArray[np.generic] = canvas.astype(view.dtype)
        return cast
    source = view if texture is None else texture
    rows, cols = layout.provenance()
    taken = rows >= 0
    out = view.copy()
    out[taken] = source[rows[taken], cols[taken]]
    return out


def hole_of(mask: object, shape: tuple[int, int]) -> NDArray[np.bool_]:
    """The pixels a fill mask asks to synthesize.

    Parameters
    ----------
    mask : ndarray, shape (H, W) or (H, W, K)
        Of the image's size. bool: True fills. Numbers: a pixel is filled where any colour
        channel is above 0 (white or any colour: fill; black: keep); with K = 2 or 4 the last
        channel is alpha, and a pixel of alpha 0 is kept whatever its colour.
    shape : (int, int)
        The image's (H, W).

    Returns
    -------
    ndarray of bool, shape (H, W)
    """
    if not isinstance(mask, np.ndarray):
        raise InvalidImageError(f"mask must be a numpy array, got {type(mask).__name__}")
    if mask.ndim not in (2, 3) or (mask.ndim == 3 and mask.shape[2] not in (1, 2, 3, 4)):
        raise InvalidImageError(
            f"mask has shape {mask.shape}: expected (H, W) or (H, W, K) with K in 1..4"
        )
    if mask.shape[:2] != shape:
        raise InvalidImageError(
            f"mask is {mask.shape[1]}x{mask.shape[0]}; it must be the image's size, "
            f"{shape[1]}x{shape[0]}"
        )
    if mask.dtype.kind not in "buif":
        raise InvalidImageError(f"mask has dtype {mask.dtype}: expected bool or numbers")
    if mask.dtype.kind == "f" and not bool(np.isfinite(mask).all()):
        raise InvalidImageError("mask contains NaN or infinite values")
    planes = mask[..., None] if mask.ndim == 2 else mask
    alpha = planes.shape[2] in (2, 4)
    colour = planes[..., :-1] if alpha else planes
    hole: NDArray[np.bool_] = np.asarray((colour > 0).any(axis=-1))
    if alpha:
        hole &= planes[..., -1] > 0
    return hole


def hole_box(hole: NDArray[np.bool_]) -> tuple[int, int]:
    """(height, width) of the hole's bounding box; (0, 0) for an empty hole."""
    rows, cols = np.flatnonzero(hole.any(axis=1)), np.flatnonzero(hole.any(axis=0))
    if rows.size == 0:
        return 0, 0
    return int(rows[-1] - rows[0] + 1), int(cols[-1] - cols[0] + 1)
