"""One pass of walk-mode synthesis (:class:`quilting.core.walk_pass.WalkPass`), driven directly.

Covers the pass's own work on small random sources: the shapes and dtypes of its canvas and
record; the block positions (whole blocks of the source, each drawn from its own block's
generator, so a larger grid keeps a smaller one's draws; exclusions and weights obeyed); the
walk cuts toward the left and top edges, recomputed by brute force from the documented
resistance (the new block against the neighbour's continuation in the reflected source, the
top cut on the transposed surface) with the seam total and the count of cut pixels they add
up to; what is written, against a naive pixel-by-pixel raster loop (exactly for a hard cut,
to float32 rounding for a feathered one); batch size, seed and progress (monotone over its
span, raising stops the pass); and that no cost backend is ever used. The walk cut itself,
the blend's weights and walk mode end to end are in tests/core/test_walk.py and
tests/core/test_walk_mode.py.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from quilting.core.grid import Grid
from quilting.core.options import SynthesisOptions
from quilting.core.pixels import compared
from quilting.core.progress import Clock
from quilting.core.walk import walk_cuts
from quilting.core.walk_pass import WalkPass


class NoBackend:
    """A cost backend that fails on any use: a walk pass matches nothing."""

    def __getattr__(self, name: str) -> Any:
        raise AssertionError(f"the walk pass used the backend ({name})")


def source(shape: tuple[int, int, int], seed: int = 0) -> NDArray[np.float32]:
    """Working pixels that are multiples of 1/64 in [1/64, 1): every difference, square and
    sum of a few of them is exact in float32, so recomputed resistances are bit for bit the
    pass's; no pixel is 0, so a pixel left unwritten shows."""
    rng = np.random.default_rng(seed)
    return (rng.integers(1, 64, size=shape) / 64).astype(np.float32)


def run(
    image: NDArray[np.float32],
    size: tuple[int, int],
    max_batch: int | None = None,
    progress: Any = None,
    excluded: NDArray[np.bool_] | None = None,
    weights: NDArray[np.float64] | None = None,
    **fields: Any,
) -> WalkPass:
    """A walk pass over the plane grid covering ``size``, executed."""
    options = SynthesisOptions(**{"block": 8, "mode": "walk", "seed": 1, **fields})
    grid = Grid.covering(size[0], size[1], options.block, options.resolved_overlap)
    work = WalkPass(image, grid, options, NoBackend(), Clock(), excluded, weights)
    work.execute(max_batch, progress)
    return work


def ramp(d: int, feather: int) -> float:
    """The documented weight of the new side at signed distance ``d`` from a cut."""
    if feather <= 1:
        return 1.0 if d >= 0 else 0.0
    return min(max((d + 0.5) / feather + 0.5, 0.0), 1.0)


def naive_canvas(image: NDArray[np.float32], work: WalkPass) -> NDArray[np.float64]:
    """What the pass should write, pixel by pixel in raster order of the blocks.

    Each block weighs its pixel ``(y, x)`` by ``a = ramp(x - cut_cols[y])`` (1 in the first
    column) and ``b = ramp(y - cut_rows[x])`` (1 in the first row); over a pixel already
    written it blends ``ab`` new with ``1 - ab`` old, elsewhere the old side is the left,
    upper and upper-left neighbours' continuations in the source mirrored past its edges.
    """
    grid, record = work.grid, work.record
    block, step = grid.block, grid.step
    feather = min(work.options.feather, block)
    pad = 2 * block
    mirror = np.pad(image.astype(np.float64), ((pad, pad), (pad, pad), (0, 0)), mode="reflect")
    canvas = np.zeros((grid.height, grid.width, image.shape[2]))
    written = np.zeros((grid.height, grid.width), dtype=bool)
    pos = record.positions.astype(int)
    for i in range(grid.rows):
        for j in range(grid.cols):
            oy, ox = i * step, j * step
            py, px = pos[i, j]
            for y in range(block):
                for x in range(block):
                    a = ramp(x - int(record.cut_cols[i, j, y]), feather) if j else 1.0
                    b = ramp(y - int(record.cut_rows[i, j, x]), feather) if i else 1.0
                    new = image[py + y, px + x].astype(np.float64)
                    here = (oy + y, ox + x)
                    if written[here]:
                        value = a * b * new + (1 - a * b) * canvas[here]
                    else:
                        value = a * b * new
                        for weight, corner in (
                            ((1 - a) * b, pos[i, j - 1] + (0, step) if j else None),
                            (a * (1 - b), pos[i - 1, j] + (step, 0) if i else None),
                            ((1 - a) * (1 - b), pos[i - 1, j - 1] + step if i and j else None),
                        ):
                            if weight:
                                assert corner is not None
                                ny, nx = corner
                                value = value + weight * mirror[pad + ny + y, pad + nx + x]
                    canvas[here] = value
                    written[here] = True
    assert written.all()
    return canvas


# --- shapes, draws ---------------------------------------------------------------------------


@pytest.mark.parametrize("channels", [1, 3, 4])
@pytest.mark.parametrize("size", [(8, 8), (23, 31), (40, 9)])
def test_canvas_and_record_shapes(channels: int, size: tuple[int, int]) -> None:
    work = run(source((30, 26, channels)), size, feather=3)
    grid = work.grid
    assert grid.height >= size[0] and grid.width >= size[1]
    assert work.canvas.shape == (grid.height, grid.width, channels)
    assert work.canvas.dtype == np.float32
    record = work.record
    assert record.grid == grid and record.feather == 3 and record.blend == "none"
    assert record.positions.shape == (grid.rows, grid.cols, 2)
    for cuts in (record.cut_cols, record.cut_rows, record.cut_right, record.cut_bottom):
        assert cuts.shape == (grid.rows, grid.cols, grid.block) and cuts.dtype == np.int16
    assert (record.cut_right == grid.block).all() and (record.cut_bottom == grid.block).all()
    # Every canvas pixel is written (the source has no 0), with a value in the source's range.
    assert work.canvas.min() >= 1 / 64 and work.canvas.max() < 1
    assert work.matched is False


def test_positions_are_whole_blocks_drawn_by_each_blocks_own_generator() -> None:
    image = source((29, 33, 3))
    small = run(image, (30, 30), seed=5).record.positions
    large = run(image, (70, 90), seed=5).record.positions
    block = 8
    assert large.min() >= 0
    assert large[..., 0].max() <= 29 - block and large[..., 1].max() <= 33 - block
    rows, cols = small.shape[:2]
    assert large.shape[0] > rows and large.shape[1] > cols
    assert np.array_equal(large[:rows, :cols], small)
    other = run(image, (70, 90), seed=6).record.positions
    assert not np.array_equal(other, large)
    # Drawn uniformly: distinct corners nearly everywhere over the 22 x 26 possible ones.
    assert len({tuple(p) for p in large.reshape(-1, 2).tolist()}) > 0.8 * large[..., 0].size


def test_exclusions_and_weights_steer_the_draws() -> None:
    image = source((30, 30, 3))
    block = 8
    excluded = np.zeros((30, 30), dtype=bool)
    excluded[:, 10:] = True  # only corners with x + 8 <= 10: x in 0..2
    left = run(image, (60, 60), excluded=excluded).record.positions
    assert left[..., 1].max() <= 2
    field = 30 - block + 1
    weights = np.zeros(field * field)
    weights[np.arange(field * field) // field >= 20] = 1.0  # only corners with y >= 20
    low = run(image, (60, 60), weights=weights).record.positions
    assert low[..., 0].min() >= 20
    plain = run(image, (60, 60)).record.positions
    assert plain[..., 1].max() > 2 and plain[..., 0].min() < 20  # the checks can fail


# --- cuts ------------------------------------------------------------------------------------


@pytest.mark.parametrize("overlap", [None, 3])
@pytest.mark.parametrize("error", ["rgb", "luminance"])
@pytest.mark.parametrize("max_run", [1, 2, 5])
def test_cuts_equal_a_brute_force_recomputation(
    error: str, max_run: int, overlap: int | None
) -> None:
    image = source((27, 25, 3), seed=2)
    work = run(image, (44, 50), error=error, max_run=max_run, seed=3, overlap=overlap)
    grid, record = work.grid, work.record
    block, step = grid.block, grid.step
    match = compared(image, error).astype(np.float64)
    pad = 2 * block
    mirror = np.pad(match, ((pad, pad), (pad, pad), (0, 0)), mode="reflect")
    pos = record.positions.astype(int)
    total, pixels = 0.0, 0
    for i in range(grid.rows):
        for j in range(grid.cols):
            py, px = pos[i, j]
            new = match[py : py + block, px : px + block]
            for has, (ny, nx), cuts, transpose in (
                (j > 0, pos[i, j - 1] + (0, step), record.cut_cols, False),
                (i > 0, pos[i - 1, j] + (step, 0), record.cut_rows, True),
            ):
                if not has:
                    assert (cuts[i, j] == 0).all()  # no neighbour: nothing cut
                    continue
                old = mirror[pad + ny : pad + ny + block, pad + nx : pad + nx + block]
                resistance = ((new - old) ** 2).sum(axis=-1)
                if transpose:
                    resistance = resistance.T
                cut = walk_cuts(resistance[None], max_run=max_run)
                assert np.array_equal(cuts[i, j], cut.cut_cols[0]), (i, j, transpose)
                total += float(cut.cost[0])
                # The pixels the cost sums: path 2 whole, path 1 from the meeting row down,
                # each pixel once.
                falling = {tuple(p) for p in cut.falling[0, : cut.falling_length[0]].tolist()}
                meeting = cut.falling[0, cut.falling_length[0] - 1, 0]
                rising = cut.rising[0, : cut.rising_length[0]].tolist()
                pixels += len(falling | {tuple(p) for p in rising if p[0] >= meeting})
    assert total > 0
    # Exact pixels add up exactly (up to the order of the sum); luminance is float32.
    assert work.seam_total == pytest.approx(total, rel=1e-12 if error == "rgb" else 1e-6)
    assert work.seam_pixels == pixels > 0


def test_the_top_cut_is_the_left_cut_of_the_transposed_problem() -> None:
    """Transposing the source and the output transposes the cuts of blocks whose
    positions (transposed) coincide: the left cut of one is the top cut of the other."""
    image = source((26, 26, 3), seed=4)
    work = run(image, (40, 40), seed=2)
    record = work.record
    # A pass over the transposed source whose positions are the transposed ones.
    options = work.options
    grid = work.grid
    flipped = WalkPass(
        np.ascontiguousarray(image.transpose(1, 0, 2)),
        grid,
        options,
        NoBackend(),
        Clock(),
    )
    flipped.record.positions[:] = record.positions.transpose(1, 0, 2)[..., ::-1]
    rows, cols = np.divmod(np.arange(grid.rows * grid.cols), grid.cols)
    flipped._cut(rows, cols)
    assert np.array_equal(flipped.record.cut_cols, record.cut_rows.transpose(1, 0, 2))
    assert np.array_equal(flipped.record.cut_rows, record.cut_cols.transpose(1, 0, 2))
    assert (record.cut_rows[1:] > 0).any() and (record.cut_cols[:, 1:] > 0).any()


# --- what is written -------------------------------------------------------------------------


@pytest.mark.parametrize("overlap", [None, 3])
@pytest.mark.parametrize("feather", [0, 1])
@pytest.mark.parametrize("channels", [1, 3])
def test_hard_pass_writes_what_a_naive_loop_writes(
    feather: int, channels: int, overlap: int | None
) -> None:
    image = source((26, 30, channels), seed=5)
    work = run(image, (37, 45), feather=feather, seed=7, overlap=overlap)
    expected = naive_canvas(image, work)
    assert np.array_equal(work.canvas, expected.astype(np.float32))
    # Hard: each pixel is a source pixel (all values are multiples of 1/64).
    assert np.array_equal(work.canvas * 64, np.round(work.canvas * 64))


@pytest.mark.parametrize("overlap", [None, 3])
@pytest.mark.parametrize("feather", [2, 3, 5, 100])
def test_feathered_pass_writes_what_a_naive_loop_writes(feather: int, overlap: int | None) -> None:
    image = source((26, 30, 3), seed=6)
    work = run(image, (37, 45), feather=feather, seed=8, overlap=overlap)
    expected = naive_canvas(image, work)
    np.testing.assert_allclose(work.canvas, expected, rtol=0, atol=2e-6)
    # The check can fail: blended pixels are no source pixel.
    assert not np.array_equal(work.canvas * 64, np.round(work.canvas * 64))


# --- batches, seeds, progress, backend -------------------------------------------------------


def test_batch_size_never_changes_the_pass() -> None:
    image = source((24, 24, 3), seed=9)
    passes = [run(image, (50, 47), max_batch=b) for b in (None, 1, 3, 10**6)]
    first = passes[0]
    for other in passes[1:]:
        assert other.canvas.tobytes() == first.canvas.tobytes()
        for name in ("positions", "cut_cols", "cut_rows"):
            assert np.array_equal(getattr(other.record, name), getattr(first.record, name))
        assert other.seam_total == pytest.approx(first.seam_total, rel=1e-12)
        assert other.seam_pixels == first.seam_pixels


def test_same_seed_same_bytes_other_seed_differs() -> None:
    image = source((24, 24, 3), seed=10)
    a = run(image, (40, 40), seed=11)
    b = run(image, (40, 40), seed=11)
    c = run(image, (40, 40), seed=12)
    assert a.canvas.tobytes() == b.canvas.tobytes()
    assert np.array_equal(a.record.cut_cols, b.record.cut_cols)
    assert a.seam_total == b.seam_total
    assert a.canvas.tobytes() != c.canvas.tobytes()
    assert not np.array_equal(a.record.positions, c.record.positions)


@pytest.mark.parametrize("max_batch", [None, 1, 4])
@pytest.mark.parametrize("span", [(0.0, 1.0), (0.2, 0.7)])
def test_progress_rises_over_its_span(max_batch: int | None, span: tuple[float, float]) -> None:
    image = source((24, 24, 3), seed=13)
    options = SynthesisOptions(block=8, mode="walk", seed=1)
    grid = Grid.covering(40, 50, 8, options.resolved_overlap)
    calls: list[tuple[float, str]] = []
    work = WalkPass(image, grid, options, NoBackend(), Clock())
    work.execute(max_batch, lambda f, s: calls.append((f, s)), stage="layer 1/2", span=span)
    low, high = span
    fractions = [f for f, _ in calls]
    assert {s for _, s in calls} == {"layer 1/2"}
    assert all(b >= a for a, b in itertools.pairwise(fractions))
    assert low <= fractions[0] and fractions[-1] == pytest.approx(high, abs=1e-12)
    assert all(low <= f <= high + 1e-12 for f in fractions)
    # One call per batch of cuts, reaching the middle, then one per wavefront group.
    blocks = grid.rows * grid.cols
    batches = -(-blocks // (max_batch or blocks))
    assert len(calls) == batches + len(grid.groups())
    assert fractions[batches - 1] == pytest.approx((low + high) / 2, abs=1e-12)
    if span == (0.0, 1.0):
        assert fractions[-1] == 1.0


class StopError(Exception):
    """Raised from a progress callback."""


@pytest.mark.parametrize("at", [1, 2, "first write", "last write"])
def test_raising_from_progress_stops_the_pass(at: int | str) -> None:
    image = source((24, 24, 3), seed=14)
    options = SynthesisOptions(block=8, mode="walk", seed=1)
    grid = Grid.covering(40, 40, 8, options.resolved_overlap)
    blocks = grid.rows * grid.cols  # batches of one block: one call each, then the writes
    writes = {"first write": blocks + 1, "last write": blocks + len(grid.groups())}
    stop_at = at if isinstance(at, int) else writes[at]
    calls: list[float] = []

    def progress(fraction: float, stage: str) -> None:
        calls.append(fraction)
        if len(calls) == stop_at:
            raise StopError

    work = WalkPass(image, grid, options, NoBackend(), Clock())
    with pytest.raises(StopError):
        work.execute(1, progress)
    assert len(calls) == stop_at  # nothing ran on after the raise
    complete = run(image, (40, 40), seed=1)
    written = np.count_nonzero(work.canvas.any(axis=-1))
    if stop_at <= blocks:
        # Stopped while cutting: the later blocks are not cut, nothing is written.
        assert written == 0
        assert not np.array_equal(work.record.cut_cols, complete.record.cut_cols)
    elif at == "first write":
        assert written == grid.block**2  # the first block only
    else:
        # The last group was written too: the pass is complete, only the return is lost.
        assert work.canvas.tobytes() == complete.canvas.tobytes()


def test_the_clock_records_the_pass_stages() -> None:
    clock = Clock()
    options = SynthesisOptions(block=8, mode="walk")
    grid = Grid.covering(30, 30, 8, options.resolved_overlap)
    WalkPass(source((20, 20, 3)), grid, options, NoBackend(), clock).execute(None, None)
    assert set(clock.spent) == {"select", "seams", "paste"}
    assert all(t >= 0 for t in clock.spent.values())
