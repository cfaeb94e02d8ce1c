"""The cost model: a job's peak memory and work, predicted from shapes and options alone.

Every large array the engine allocates has a size that follows from the texture's and the
output's shapes, the block, the channels compared and how many blocks go to the backend at
once. This module adds those sizes up, pass by pass, and turns the number of cost-field
evaluations into seconds with coefficients measured on this project's benchmark machine
(``benchmarks/bench_limits.py --calibrate`` refits them; ``QUILTING_SECONDS_SCALE`` scales
them for a faster or slower machine). It also picks the batch (blocks per backend call) that
keeps the per-call temporaries under a working-memory allowance, which is what bounds the
engine's memory whatever the texture.

What cannot be known from shapes is how many candidates the tolerance rule keeps: a texture
whose candidates all cost nearly the same (noise, a flat colour) lists many of them. The
shortlists are counted at :data:`SHORTLIST_FILL` of the field (measured: 17 % on uniform noise,
under 1 % on photographs; at worst 16 bytes a candidate, bounded by the batch), and exact
re-scoring is compiled and keeps one candidate's sums at a time
(:mod:`quilting.core.kernels.exact`), so such a texture costs time, not memory.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, replace

import scipy.fft as sfft

from quilting.core.errors import InvalidParameterError, QuiltingError
from quilting.core.fill_search import COARSE_CANDIDATES, search_scale
from quilting.core.grid import Grid
from quilting.core.options import (
    AlphaOptions,
    FillOptions,
    SynthesisOptions,
    TransferOptions,
    WangOptions,
)
from quilting.core.seamless import BAND_PIXELS
from quilting.core.select import RESCORE_GROUP
from quilting.core.transfer import schedule

#: Bytes a worker takes before any job: the interpreter, numpy, scipy, Pillow and the compiled
#: kernels (numba and LLVM, about 100 MiB of it) loaded (measured VmHWM, 178 MiB).
BASE_BYTES = 180 << 20
#: Per-call working memory when no budget is given: the batch is cut to fit it.
DEFAULT_WORKING_BYTES = 384 << 20
#: Share of a memory budget the per-call temporaries may use; the rest is the job's arrays.
WORKING_SHARE = 0.25
#: Largest batch the engine sends to a backend at once (its default).
MAX_BATCH = 64
#: Requests the FFT backend transforms together on each of its threads.
FFT_CHUNK = 6
#: Safety factor of the bound over the model's sum: measured peaks came within 10 % of it on
#: the benchmark cases (allocator slack, transient copies the model does not itemize).
BOUND_MARGIN = 1.15
#: Fraction of a cost field a shortlist is assumed to hold (see the module docstring).
SHORTLIST_FILL = 0.05
#: Calibrated CPU seconds (``benchmarks/bench_limits.py --fit``) per FFT cost-field unit
#: ((C + 1) N log2 N per block), per candidate pixel-channel summed directly (the reference
#: backend), per block pixel handled by selection, seams and paste, per wavefront level and
#: per output pixel rendered and measured. CPU seconds, not wall: a worker with one core to
#: itself (the service's default, a worker per core) takes about that long.
SECONDS_PER: dict[str, float] = {
    "fft": 4.16e-10,
    "direct": 5.0e-9,
    # Fitted to 0 on the bench cases: the per-block work is inside the fft and level terms.
    "block_pixel": 0.0,
    "level": 3.9e-3,
    "output_pixel": 7.23e-9,
}


class JobTooLargeError(QuiltingError):
    """A job's predicted memory or time is over its budget; the message says what to change."""

    code = "job_too_large"


@dataclass(frozen=True)
class Budget:
    """Limits a job must fit before it starts.

    Attributes
    ----------
    memory_bytes : int, optional
        Largest predicted peak resident memory of the job's process, interpreter included.
    seconds : float, optional
        Largest predicted run time.
    """

    memory_bytes: int | None = None
    seconds: float | None = None

    def __post_init__(self) -> None:
        if self.memory_bytes is not None and self.memory_bytes <= BASE_BYTES:
            raise ValueError(f"memory_bytes must be more than {BASE_BYTES} (the interpreter)")
        if self.seconds is not None and not self.seconds > 0:
            raise ValueError("seconds must be > 0")

    @property
    def working_bytes(self) -> int:
        """What one backend call's temporaries may take under this budget."""
        if self.memory_bytes is None:
            return DEFAULT_WORKING_BYTES
        return max(1 << 20, int((self.memory_bytes - BASE_BYTES) * WORKING_SHARE))


@dataclass(frozen=True)
class PassShape:
    """One quilting pass as the cost model sees it.

    Attributes
    ----------
    texture : (int, int)
        Texture (height, width).
    channels : int
        Channels of the texture as given (1..4).
    compared : int
        Channels the costs compare (1 for luminance error, else the texture's).
    guide : int
        Correspondence-map channels of a transfer pass (0 for synthesis).
    grid : Grid
        The pass's blocks.
    matched : bool
        Whether blocks are matched by cost fields (False in random and walk modes).
    backend : str
        ``"fft"``, ``"gl"`` or ``"reference"``.
    """

    texture: tuple[int, int]
    channels: int
    compared: int
    guide: int
    grid: Grid
    matched: bool
    backend: str

    @functools.cached_property
    def fft_cells(self) -> int:
        """Cells of the FFT grid the backend correlates on."""
        height, width = self.texture
        return int(sfft.next_fast_len(height) * sfft.next_fast_len(width, real=True))

    @functools.cached_property
    def field_cells(self) -> int:
        """Candidate positions of the texture."""
        height, width = self.texture
        block = self.grid.block
        return max(1, (height - block + 1) * (width - block + 1))

    @property
    def blocks(self) -> int:
        return self.grid.rows * self.grid.cols

    def request_bytes(self) -> int:
        """Temporaries of one block's cost field while the backend computes it."""
        if not self.matched:
            return 0
        if self.backend == "reference":
            return 8 * self.field_cells * 3
        # Template spectra (complex64, every channel, the half grid), the channel sum's
        # inverse transform and the float32 field: measured at 0.6-0.7 of their sum, as the
        # transforms overwrite their inputs where they can.
        return (4 * (self.compared + self.guide) + 4) * self.fft_cells + 4 * self.field_cells

    def shortlist_bytes(self, fill: float = SHORTLIST_FILL) -> int:
        """What one block's shortlist and its selection keep (index, value, the band's
        copies) when it lists ``fill`` of the field (1: every candidate ties)."""
        if not self.matched:
            return 0
        return int(40 * fill * self.field_cells)

    def batch(self, working_bytes: int, threads: int) -> int:
        """The most blocks per backend call (at most :data:`MAX_BATCH`) whose temporaries fit
        ``working_bytes``; one at the least."""
        if not self.matched:
            return MAX_BATCH
        # Sized for the worst case: every candidate of every block in the batch listed.
        for batch in range(MAX_BATCH, 1, -1):
            if self.in_flight_bytes(batch, threads, fill=1.0) <= working_bytes:
                return batch
        return 1

    def job_bytes(self) -> int:
        """Arrays the pass keeps while it runs: the texture's copies and spectra, the canvas."""
        height, width = self.texture
        texels = height * width
        canvas = self.grid.height * self.grid.width
        total = texels * self.channels * 4  # the float32 working texture
        total += canvas * self.channels * 4  # the output canvas
        if self.guide:
            # The target's map and the previous pass over the canvas; the texture's map.
            total += canvas * (self.guide + self.channels) * 4 + texels * self.guide * 4
        if not self.matched:
            return total
        compared = self.compared + self.guide
        total += texels * compared * 8  # the exact scorer's float64 pixels
        if self.compared != self.channels:
            total += texels * self.compared * 4  # the luminance (or premultiplied) copy
        if self.backend == "reference":
            return total
        cells = self.fft_cells
        total += 4 * compared * cells + 8 * cells * (2 if self.guide else 1)  # spectra
        # Energy fields, one per overlap kind (three, and their weighted sums in a transfer),
        # and what of the float64 transforms making one of them outlives the first levels.
        total += 4 * self.field_cells * (6 if self.guide else 3) + 8 * cells
        return total

    def in_flight_bytes(self, batch: int, threads: int, fill: float = SHORTLIST_FILL) -> int:
        """Temporaries of one backend call of ``batch`` blocks whose shortlists hold
        ``fill`` of the field; with ``fill`` 1 (a flat texture) also the exact re-scoring
        of a group of tied candidates (index and cost arrays; the compiled sums themselves
        keep one block's support at a time)."""
        concurrent = min(batch, threads * FFT_CHUNK)
        flight = self.request_bytes() * concurrent + self.shortlist_bytes(fill) * batch
        if fill >= 1 and self.matched:
            flight += RESCORE_GROUP * 48
        return flight

    def work(self) -> float:
        """Cost-field units of the pass: what the time estimate scales."""
        if not self.matched:
            return 0.0
        if self.backend == "reference":
            return float(self.blocks * self.field_cells * self.grid.block**2 * self.compared)
        cells = self.fft_cells
        return self.blocks * (self.compared + self.guide + 1) * cells * math.log2(max(2, cells))

    def features(self) -> dict[str, float]:
        """What the pass's time is proportional to, by :data:`SECONDS_PER` key."""
        direct = self.backend == "reference"
        return {
            "fft": 0.0 if direct else self.work(),
            "direct": self.work() if direct else 0.0,
            "block_pixel": float(self.blocks * self.grid.block**2),
            "level": float(self.grid.levels),
        }


@dataclass(frozen=True)
class Estimate:
    """A job's predicted cost.

    Attributes
    ----------
    peak_bytes : int
        Predicted peak resident memory of the process running the job, interpreter included,
        for a texture like the photographs of the benchmarks.
    bound_bytes : int
        The same when every candidate ties (a flat or noise texture: every shortlist holds
        the whole field): what a budget is checked against.
    seconds : float
        Predicted run time on the calibrated machine (times ``QUILTING_SECONDS_SCALE``).
    work : float
        Cost-field units (what ``seconds`` is proportional to).
    batch : int
        Blocks per backend call the engine uses (the largest that fits the working memory).
    """

    peak_bytes: int
    bound_bytes: int
    seconds: float
    work: float
    batch: int

    def over(self, budget: Budget) -> list[str]:
        """What of ``budget`` this estimate exceeds, in words (empty if it fits)."""
        found = []
        if budget.memory_bytes is not None and self.bound_bytes > budget.memory_bytes:
            found.append(
                f"may need up to {_size(self.bound_bytes)} of memory, over the budget of "
                f"{_size(budget.memory_bytes)}"
            )
        if budget.seconds is not None and self.seconds > budget.seconds:
            found.append(
                f"would take about {self.seconds:.0f} s, over the budget of {budget.seconds:g} s"
            )
        return found


def seconds_scale() -> float:
    """``QUILTING_SECONDS_SCALE``: how much slower than the calibrated machine this one is."""
    raw = os.environ.get("QUILTING_SECONDS_SCALE", "").strip()
    try:
        value = float(raw) if raw else 1.0
    except ValueError:
        return 1.0
    return value if value > 0 and math.isfinite(value) else 1.0


def time_features(passes: list[PassShape], output: tuple[int, int]) -> dict[str, float]:
    """The job's :meth:`PassShape.features` summed over its passes, and its output pixels."""
    total = dict.fromkeys(SECONDS_PER, 0.0)
    for shape in passes:
        for key, value in shape.features().items():
            total[key] += value
    total["output_pixel"] = float(output[0] * output[1])
    return total


def estimate(
    passes: list[PassShape],
    output: tuple[int, int],
    channels: int,
    itemsize: int,
    *,
    working_bytes: int = DEFAULT_WORKING_BYTES,
    max_batch: int | None = None,
    threads: int | None = None,
    extra_bytes: int = 0,
) -> Estimate:
    """Predicted peak memory and time of a job made of ``passes`` (run one after another).

    Parameters
    ----------
    passes : list of PassShape
    output : (int, int)
        Output (height, width).
    channels, itemsize : int
        Channels and bytes per sample of the output image.
    working_bytes : int
        What one backend call's temporaries may take; sets the batch unless ``max_batch``.
    max_batch : int, optional
        The caller's batch (then used as given).
    threads : int, optional
        FFT threads (default ``min(2, cores)`` as the backend).
    extra_bytes : int
        Arrays the caller keeps beside the passes (a matte's target and maps...).
    """
    threads = threads or min(2, os.cpu_count() or 1)
    if max_batch is not None:
        batch = max(1, max_batch)
    else:
        batch = min((p.batch(working_bytes, threads) for p in passes), default=MAX_BATCH)
    pixels = output[0] * output[1]
    # The last pass's canvas (counted in its job bytes) lives on while the image is rendered
    # in the input's dtype and measured (the statistics' streamed ownership rows and run
    # tables: under a byte a pixel, measured at 8192²).
    finish = int(pixels * (channels * itemsize + 0.8))
    ending = (passes[-1].job_bytes() if passes else 0) + finish
    peak = max(
        max((p.job_bytes() + p.in_flight_bytes(batch, threads) for p in passes), default=0),
        ending,
    )
    bound = max(
        max(
            (p.job_bytes() + p.in_flight_bytes(batch, threads, fill=1.0) for p in passes),
            default=0,
        ),
        ending,
    )
    seconds = seconds_scale() * sum(
        SECONDS_PER[key] * value for key, value in time_features(passes, output).items()
    )
    return Estimate(
        peak_bytes=int(BASE_BYTES + peak + extra_bytes),
        bound_bytes=int(BASE_BYTES + BOUND_MARGIN * (bound + extra_bytes)),
        seconds=seconds,
        work=sum(p.work() for p in passes),
        batch=batch,
    )


def check(found: Estimate, budget: Budget | None, advice: str) -> None:
    """Raise :class:`JobTooLargeError` if ``found`` exceeds ``budget``.

    ``advice`` is what the caller suggests changing ("use a texture of at most ...").
    """
    if budget is None:
        return
    over = found.over(budget)
    if over:
        raise JobTooLargeError(f"the job {' and '.join(over)}: {advice}")


def _size(count: float) -> str:
    for unit, scale in (("GiB", 1 << 30), ("MiB", 1 << 20)):
        if count >= scale:
            return f"{count / scale:.1f} {unit}"
    return f"{count / 1024:.0f} KiB"


def synthesis_passes(
    texture: tuple[int, int, int], size: tuple[int, int], options: SynthesisOptions, backend: str
) -> list[PassShape]:
    """The one pass of a synthesis of ``size`` (height, width) from a texture (h, w, C).

    ``backend`` is the concrete backend (``fft``, ``gl``, ``reference``).
    """
    height, width, channels = texture
    mode = options.resolved_mode(channels)
    wrap = (options.tileable in ("both", "y"), options.tileable in ("both", "x"))
    grid = Grid.covering(size[0], size[1], options.block, options.resolved_overlap, wrap)
    colour = 3 if channels >= 3 else 1
    compared = 1 if options.error == "luminance" else (colour if mode == "alpha" else channels)
    # Alpha quilting adds the histogram term's field to every request: count it as a channel.
    extra = 1 if mode == "alpha" else 0
    return [
        PassShape(
            texture=(height, width),
            channels=channels,
            compared=compared + extra,
            guide=0,
            grid=grid,
            matched=mode not in ("random", "walk"),
            backend=backend,
        )
    ]


def transfer_passes(
    texture: tuple[int, int, int],
    target: tuple[int, int],
    options: TransferOptions,
    backend: str,
    guide: int,
) -> list[PassShape]:
    """The passes of a transfer onto a target of (height, width), ``guide`` map channels."""
    height, width, channels = texture
    compared = 1 if options.error == "luminance" else channels
    return [
        PassShape(
            texture=(height, width),
            channels=channels,
            compared=compared,
            guide=guide,
            grid=Grid.covering(target[0], target[1], plan.block, plan.overlap),
            matched=True,
            backend=backend,
        )
        for plan in schedule(options)
    ]


def fits(found: Estimate, budget: Budget) -> bool:
    """Whether ``found`` is within ``budget``."""
    return not found.over(budget)


def _last_true(holds: Callable[[int], bool], low: int, high: int) -> int:
    """The largest n in [low, high] for which ``holds(n)``, where it holds for every n below
    one where it does, or ``low - 1`` if it holds for none (a bisection)."""
    if not holds(low):
        return low - 1
    while low < high:
        middle = (low + high + 1) // 2
        if holds(middle):
            low = middle
        else:
            high = middle - 1
    return low


def _first_true(holds: Callable[[int], bool], low: int, high: int) -> int:
    """The smallest n in [low, high] for which ``holds(n)``, where it holds for every n above
    one where it does, or ``high + 1`` if it holds for none (a bisection)."""
    if not holds(high):
        return high + 1
    while low < high:
        middle = (low + high) // 2
        if holds(middle):
            high = middle
        else:
            low = middle + 1
    return low


def largest_fitting(make: Callable[[int], Estimate], low: int, high: int, budget: Budget) -> int:
    """The largest n in [low, high] whose ``make(n)`` fits ``budget`` (costs grow with n), or
    ``low - 1`` if none does."""
    return _last_true(lambda n: fits(make(n), budget), low, high)


def smallest_fitting(make: Callable[[int], Estimate], low: int, high: int, budget: Budget) -> int:
    """The smallest n in [low, high] whose ``make(n)`` fits ``budget`` (costs shrink as n
    grows), or ``high + 1`` if none does."""
    return _first_true(lambda n: fits(make(n), budget), low, high)


def _is_job(make: Callable[[int], Estimate], n: int) -> bool:
    """Whether ``make(n)`` describes a job at all: a changed size or block may not be one (a
    tileable side under the block, a block past a side), which the estimate refuses."""
    try:
        make(n)
    except InvalidParameterError:
        return False
    return True


def first_job(make: Callable[[int], Estimate], low: int, high: int) -> int:
    """The smallest n in [low, high] for which ``make(n)`` is a job, where every larger n is
    one too (sizes), or ``high + 1`` if none is."""
    return _first_true(lambda n: _is_job(make, n), low, high)


def last_job(make: Callable[[int], Estimate], low: int, high: int) -> int:
    """The largest n in [low, high] for which ``make(n)`` is a job, where every smaller n is
    one too (blocks), or ``low - 1`` if none is."""
    return _last_true(lambda n: _is_job(make, n), low, high)


def advice(
    budget: Budget,
    texture: tuple[int, int],
    output: tuple[int, int],
    block: int,
    make: Callable[[tuple[int, int], tuple[int, int], int], Estimate],
) -> str:
    """What to change so that a job fits: a smaller texture, a smaller output, a larger block.

    ``make(texture, output, block)`` estimates the job with those changed; each suggestion
    keeps the other two as they are and the aspect ratios.
    """

    def scaled(shape: tuple[int, int], side: int) -> tuple[int, int]:
        longest = max(shape)
        return (max(1, shape[0] * side // longest), max(1, shape[1] * side // longest))

    def of_texture(side: int) -> Estimate:
        return make(scaled(texture, side), output, block)

    def of_output(side: int) -> Estimate:
        return make(texture, scaled(output, side), block)

    def of_block(side: int) -> Estimate:
        return make(texture, output, side)

    # Each search runs over the sizes that still make a job: a tileable output, say, holds
    # at least a block along its tiled axes.
    ideas = []
    smallest = first_job(of_texture, max(block, 3), max(texture))
    side = largest_fitting(of_texture, smallest, max(texture), budget)
    if side >= smallest and side < max(texture):
        height, width = scaled(texture, side)
        ideas.append(f"a texture of at most {width}x{height}")
    smallest = first_job(of_output, 1, max(output))
    side = largest_fitting(of_output, smallest, max(output), budget)
    if smallest <= side < max(output):
        height, width = scaled(output, side)
        ideas.append(f"an output of at most {width}x{height}")
    largest_block = last_job(of_block, block, min(texture))
    found = smallest_fitting(of_block, block, largest_block, budget)
    if block < found <= largest_block:
        ideas.append(f"block >= {found}")
    if not ideas:
        return "raise the budget: no smaller texture, output or larger block fits it"
    return "use " + ", or ".join(ideas)


def _planned(
    make: Callable[[tuple[int, int], tuple[int, int], int], Estimate],
    texture: tuple[int, int],
    out: tuple[int, int],
    block: int,
    budget: Budget | None,
) -> Estimate:
    """``make``'s estimate of the job as asked; over ``budget``, a
    :class:`JobTooLargeError` with :func:`advice` on what would fit."""
    found = make(texture, out, block)
    if budget is not None and not fits(found, budget):
        check(found, budget, advice(budget, texture, out, block, make))
    return found


def estimate_synthesis(
    options: SynthesisOptions,
    texture: tuple[int, ...],
    size: tuple[int, int],
    *,
    backend: str = "fft",
    itemsize: int = 1,
    max_batch: int | None = None,
    budget: Budget | None = None,
    layers: int = 1,
    extra_bytes: int = 0,
) -> Estimate:
    """The cost of quilting ``size`` (height, width) from a texture of shape (h, w) or
    (h, w, C) (an array's ``shape``).

    With ``budget``, a job over it raises :class:`JobTooLargeError` saying what would fit.
    ``layers`` counts textures of this shape quilted one after another (a matte's layers):
    their times add up, their memory does not. ``extra_bytes``: arrays the caller keeps.
    """
    working = DEFAULT_WORKING_BYTES if budget is None else budget.working_bytes
    channels = _channels(texture)

    def make(shape: tuple[int, int], out: tuple[int, int], block: int) -> Estimate:
        changed = options if block == options.block else replace(options, block=block)
        passes = synthesis_passes((*shape, channels), out, changed, backend)
        found = estimate(
            passes,
            out,
            channels,
            itemsize,
            working_bytes=working,
            max_batch=max_batch,
            extra_bytes=extra_bytes,
        )
        return replace(found, seconds=found.seconds * layers, work=found.work * layers)

    return _planned(make, (texture[0], texture[1]), size, options.block, budget)


def estimate_transfer(
    options: TransferOptions,
    texture: tuple[int, ...],
    target: tuple[int, int],
    *,
    guide: int = 1,
    backend: str = "fft",
    itemsize: int = 1,
    max_batch: int | None = None,
    budget: Budget | None = None,
) -> Estimate:
    """The cost of a transfer of a texture, shape (h, w) or (h, w, C), onto a target of
    (height, width), with ``guide`` correspondence-map channels. ``budget`` as in
    :func:`estimate_synthesis`."""
    working = DEFAULT_WORKING_BYTES if budget is None else budget.working_bytes
    channels = _channels(texture)

    def make(shape: tuple[int, int], out: tuple[int, int], block: int) -> Estimate:
        changed = options if block == options.block else replace(options, block=block)
        passes = transfer_passes((*shape, channels), out, changed, backend, guide)
        # The target's working copy and both maps live through every pass.
        kept = out[0] * out[1] * 4 * (channels + 2 * guide)
        return estimate(
            passes,
            out,
            channels,
            itemsize,
            working_bytes=working,
            max_batch=max_batch,
            extra_bytes=kept,
        )

    return _planned(make, (texture[0], texture[1]), target, options.block, budget)


#: Bytes a matte keeps per target pixel beside its layers (the working target, cover, normals
#: and the k-means features).
MATTE_BYTES_PER_PIXEL = 64


#: CPU seconds per term (pixel x channel) of the exact scores of a fill's fine search stage:
#: 1.4 ns measured (compiled masked sums, 1024² RGB, block 32 at scale 4), rounded up.
EXACT_SECONDS_PER_TERM = 1.5e-9


def estimate_fill(
    options: FillOptions,
    image: tuple[int, ...],
    hole: tuple[int, int],
    *,
    texture: tuple[int, int] | None = None,
    backend: str = "fft",
    itemsize: int = 1,
    max_batch: int | None = None,
    budget: Budget | None = None,
    extra_bytes: int = 0,
) -> Estimate:
    """The cost of filling a hole whose bounding box is ``hole`` (height, width) in an image
    of shape (H, W) or (H, W, C), from the image itself or from a ``texture`` (h, w).

    The backend's work is costed as one synthesis pass over the hole's bounding box (at least
    as many blocks as the fill places) at the search's scale
    (:func:`quilting.core.fill_search.search_scale`): the source and the block divided by it,
    the masked energy one more correlated channel. Beside it: the full-size source, its exact
    scorer's float64 copy, the image's canvas, its maps (known, covered, provenance, rounds),
    and the fine stage's exact scores. With ``budget``, a job over it raises
    :class:`JobTooLargeError` saying so.
    """
    working = DEFAULT_WORKING_BYTES if budget is None else budget.working_bytes
    found = _fill_cost(
        options, image, hole, texture, backend, itemsize, max_batch, working, extra_bytes
    )
    check(
        found,
        budget,
        "fill a smaller hole, give a smaller image or texture, or raise the block size",
    )
    return found


def _fill_cost(
    options: FillOptions,
    image: tuple[int, ...],
    hole: tuple[int, int],
    texture: tuple[int, int] | None,
    backend: str,
    itemsize: int,
    max_batch: int | None,
    working: int,
    extra_bytes: int,
) -> Estimate:
    """:func:`estimate_fill`'s estimate, planned within ``working`` bytes, checked against
    nothing."""
    channels = _channels(image)
    height, width = image[0], image[1]
    source = texture if texture is not None else (height, width)
    compared = 1 if options.error == "luminance" else channels
    scale = search_scale(options.search_scale, options.block, source)
    block, overlap = options.block // scale, max(1, options.resolved_overlap // scale)
    grid = Grid.covering(
        max(hole[0], options.block) // scale + 1, max(hole[1], options.block) // scale + 1,
        block, min(overlap, (block - 1) // 2) if block > 2 else 1,
    )  # fmt: skip
    shape = PassShape(
        texture=(source[0] // scale, source[1] // scale),
        channels=channels,
        compared=compared + 1,
        guide=0,
        grid=grid,
        matched=True,
        backend=backend,
    )
    # The image's canvas, its known and covered maps, the provenance and round maps; the
    # source's working copy and its candidates (allowed flags and their flat indices); at a
    # coarse scale also the source's exact scorer's float64 copy (the pass counts it else).
    held = height * width * (4 * channels + 2 + 8 + 2)
    held += source[0] * source[1] * (4 * channels + 9)
    if scale > 1:
        held += source[0] * source[1] * 8 * compared
    found = estimate(
        [shape],
        (height, width),
        channels,
        itemsize,
        working_bytes=working,
        max_batch=max_batch,
        extra_bytes=extra_bytes + held,
    )
    if scale > 1:
        terms = grid.rows * grid.cols * COARSE_CANDIDATES * scale**2 * options.block**2 * compared
        seconds = found.seconds + seconds_scale() * EXACT_SECONDS_PER_TERM * terms
        found = replace(found, seconds=seconds)
    return found


def layers_in_turn(found: list[Estimate], budget: Budget | None) -> Estimate:
    """The cost of layers quilted one after another (a matte's): the memory of the largest,
    the time of all; checked against ``budget``."""
    total = Estimate(
        peak_bytes=max(f.peak_bytes for f in found),
        bound_bytes=max(f.bound_bytes for f in found),
        seconds=sum(f.seconds for f in found),
        work=sum(f.work for f in found),
        batch=min(f.batch for f in found),
    )
    check(total, budget, "use fewer or smaller layers, a larger scale or a larger block")
    return total


def _channels(shape: tuple[int, ...]) -> int:
    """Channels of an image of ``shape`` (h, w) or (h, w, C)."""
    if len(shape) not in (2, 3):
        raise ValueError(f"an image shape is (h, w) or (h, w, C), got {shape}")
    return shape[2] if len(shape) == 3 else 1


#: Bytes :func:`quilting.make_tileable` holds per pixel whatever the channels (the source map,
#: its roll, the error, the next map and the cut mask: int64/float64 each), and per channel
#: (the float64 working copy of the pixels), measured at 2000² and 5000² (gray, RGB, RGBA;
#: 8 and 16 bits): the model's sum came within 10 % of the peaks, the image itself counted
#: once more in its own dtype.
TILE_BYTES_PER_PIXEL = 44
TILE_BYTES_PER_CHANNEL = 8
#: CPU seconds of a ``/tile`` call (decode, make tileable, encode) per pixel, per channel and
#: per channel of a 16-bit (or float) image beyond 8-bit's, fitted to the ``/tile`` cases of
#: ``benchmarks/bench_limits.py`` (a photograph at 2000²-5000², gray, RGB, RGBA 16-bit).
TILE_SECONDS_PER: dict[str, float] = {"pixel": 1.39e-7, "channel": 1.65e-7, "wide_channel": 2.5e-8}
#: Bytes a pixel that ``blend="poisson"`` holds at its peak, whatever the channels: the source
#: map (int64) and one channel's float32 / complex64 planes (the divergence, its transforms and
#: the correction), measured with tracemalloc at 1500² (19-22 bytes beyond the map); besides,
#: per channel, the image, the output and the gathered channel (3 C itemsize, generous). The
#: blend runs after the cut search has freed its float64 copy, so a job's peak is the larger of
#: the two: the cut search's for 8- and 16-bit images, the blend's only for wide float ones.
TILE_BLEND_BYTES_PER_PIXEL = 30
#: CPU seconds of ``blend="poisson"`` per pixel and blended channel (every channel but an RGBA
#: image's alpha): 24-38 ns measured at 1500² (the FFTs, the DCT and the gathers), rounded up.
TILE_BLEND_SECONDS_PER_CHANNEL = 4.5e-8


def estimate_tile(
    shape: tuple[int, ...],
    *,
    itemsize: int = 1,
    budget: Budget | None = None,
    extra_bytes: int = 0,
    blend: str = "none",
    method: str = "cut",
    backend: str = "fft",
) -> Estimate:
    """The cost of making an image of ``shape`` (h, w) or (h, w, C) tileable
    (:func:`quilting.make_tileable`), with ``itemsize`` bytes per sample.

    ``method="fill"`` (the bands across the wraps synthesized again on ``backend``) is costed
    as :func:`estimate_fill` of the whole image with :class:`FillOptions`' defaults (with both
    axes tiled the bands' bounding box is the image); the rest of this paragraph is the cuts'.

    Memory and time are linear in the pixels: the cuts are found in bands a quarter of each
    side wide, but the source map and the working copy are whole-image. With ``budget``, an
    image over it raises :class:`JobTooLargeError` naming the largest image of the same aspect
    that fits. ``extra_bytes``: what the caller keeps beside (an upload's encoded bytes).
    ``blend``: the option of that name; "poisson" adds its solve's time and, where its planes
    outgrow the cut search's (wide float images), its memory. ``batch`` is 1 and ``work`` the
    pixel count: no backend is called.
    """
    channels = _channels(shape)
    blended = (3 if channels == 4 else channels) if blend == "poisson" else 0
    working = DEFAULT_WORKING_BYTES if budget is None else budget.working_bytes

    def make(height: int, width: int) -> Estimate:
        if method == "fill":
            return _fill_cost(
                FillOptions(),
                (height, width, channels),
                (height, width),
                None,
                backend,
                itemsize,
                None,
                working,
                extra_bytes,
            )
        pixels = height * width
        per_pixel = TILE_BYTES_PER_PIXEL + TILE_BYTES_PER_CHANNEL * channels + channels * itemsize
        if blended:
            per_pixel = max(per_pixel, TILE_BLEND_BYTES_PER_PIXEL + 3 * channels * itemsize)
        wide = channels if itemsize > 1 else 0
        seconds = (
            seconds_scale()
            * pixels
            * (
                TILE_SECONDS_PER["pixel"]
                + TILE_SECONDS_PER["channel"] * channels
                + TILE_SECONDS_PER["wide_channel"] * wide
                + TILE_BLEND_SECONDS_PER_CHANNEL * blended
            )
        )
        # and one band of the error's gathers (two float64 copies of its pixels).
        band = 2 * TILE_BYTES_PER_CHANNEL * channels * min(pixels, BAND_PIXELS)
        held = pixels * per_pixel + band + extra_bytes
        return Estimate(
            peak_bytes=int(BASE_BYTES + held),
            bound_bytes=int(BASE_BYTES + BOUND_MARGIN * held),
            seconds=seconds,
            work=float(pixels),
            batch=1,
        )

    height, width = shape[0], shape[1]
    found = make(height, width)
    if budget is not None and not fits(found, budget):
        longest = max(height, width)

        def side(s: int) -> Estimate:
            return make(max(1, height * s // longest), max(1, width * s // longest))

        smallest = first_job(side, 1, longest)
        largest = largest_fitting(side, smallest, longest, budget)
        if largest >= smallest:
            idea = (
                f"use an image of at most {max(1, width * largest // longest)}x"
                f"{max(1, height * largest // longest)}"
            )
        else:
            idea = "raise the budget: no image fits it"
        check(found, budget, idea)
    return found


def estimate_wang(
    options: WangOptions,
    texture: tuple[int, ...],
    *,
    backend: str = "fft",
    itemsize: int = 1,
    max_batch: int | None = None,
    budget: Budget | None = None,
) -> Estimate:
    """The cost of a Wang tile set (:mod:`quilting.core.wang`) from examples whose atlas has
    shape (h, w) or (h, w, C): the quilting of its material (``tile`` x ``2 colors tile``)
    with the tiles beside it (each in working floats and in the output's dtype, and its
    labels), the cuts' error planes and the material kept for companions.

    With ``budget``, a job over it raises :class:`JobTooLargeError` saying what would fit.
    """
    channels = _channels(texture)
    t, count = options.tile, options.colors**4
    tiles = count * t * t * (channels * (4 + itemsize) + 1)
    quarters = 4 * options.colors**2 * (t // 2) ** 2 * (8 + 1 + 1 + 8 * 6)
    found = estimate_synthesis(
        options.synthesis(),
        texture,
        (t, 2 * options.colors * t),
        backend=backend,
        itemsize=itemsize,
        max_batch=max_batch,
        extra_bytes=tiles + quarters,
    )
    check(found, budget, "use fewer colours, smaller tiles or a smaller texture")
    return found


#: Bytes an alpha extraction holds per photo pixel at its peak, by method, every pixel unknown
#: (a photo with only scribbles: the worst case), measured as the process's VmHWM over the
#: warmed-up interpreter at 256² and 512² (``benchmarks/bench_alpha.py``, extraction rows),
#: rounded up: the matting Laplacian (cf: 3x3 windows, 25 non-zeros a pixel; knn: the
#: neighbour graph of 30 a pixel and its k-d tree; lkm: none, it applies the Laplacian by box
#: filters), the preconditioner (cf: an incomplete Cholesky factor of at most
#: ``quilting.extract.ICHOL_FILL`` non-zeros an unknown pixel) and the conjugate-gradient
#: vectors.
EXTRACT_BYTES_PER_PIXEL: dict[str, int] = {"cf": 1700, "knn": 4000, "lkm": 600}
#: CPU seconds per pixel of an extraction when most of the photo is unknown (the
#: conjugate-gradient iterations grow with the unknown region: cf 1100-3700 of them at
#: 256²-512² when its incomplete Cholesky factor cannot be used, knn 90-230, lkm 90-640),
#: the largest measured at 512² as above (cf 104 s, knn 12.5 s, lkm 70 s of CPU on the
#: benchmark's photos on the loaded 2-core machine; 105-140 s on a high-frequency alpha
#: under load), rounded up; a trimap with a narrow unknown band takes a small fraction of it
#: (cf: 3 iterations).
EXTRACT_SECONDS_PER_PIXEL: dict[str, float] = {"cf": 4e-4, "knn": 6e-5, "lkm": 4e-4}


def estimate_extract(
    options: AlphaOptions, shape: tuple[int, int], *, budget: Budget | None = None
) -> Estimate:
    """The cost of extracting an alpha from a photo of (h, w) (:func:`quilting.extract_alpha`),
    counted as if every pixel were unknown (only the trimap, decoded later, says how many are).

    With ``budget``, a job over it raises :class:`JobTooLargeError` saying what would fit.
    """
    pixels = shape[0] * shape[1]
    per_pixel = EXTRACT_BYTES_PER_PIXEL[options.method]
    # The photo, the map, the alpha, the foreground and the RGBA (float64 and the output's).
    images = pixels * (3 * 8 + 8 + 8 + 3 * 8 + 4 * 4)
    peak = int(BASE_BYTES + pixels * per_pixel + images)
    found = Estimate(
        peak_bytes=peak,
        bound_bytes=int(BOUND_MARGIN * peak),
        seconds=seconds_scale() * EXTRACT_SECONDS_PER_PIXEL[options.method] * pixels,
        work=float(pixels),
        batch=1,
    )
    check(found, budget, "use a smaller photo (or crop it to the texture), or another method")
    return found
