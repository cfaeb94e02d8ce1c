"""The seam blends of a quilting pass, run beside the placement of the next level.

A level's blend (:func:`quilting.core.blend.blend_cells`) writes only the cells of that level's
blocks, and on a plane no later level reads them (a torus is below): a block's template is its
footprint, its own cell and the cells right of and below it, whose levels come after its own.
So the blend of level ``L - 1`` may run on a thread of its own while level ``L`` is selected,
cut and pasted, with the same bytes as a blend run in line (each pixel is written by one side
only, and each blend's arithmetic is that of the in-line call).

The cost fields keep both cores busy on their own (the FFT backend's threads), so a blend is
started only once a level's fields are done and finished before the next level's are asked for:
it fills the time in which selection, the cuts and the paste leave the second core idle. Where
it outlasts that time, the main thread helps: a level's blend comes in parts over disjoint
cells (:func:`parts`), and before the next fields the main thread runs those the blend thread
has not reached. A blend too small for its transforms to take a second thread
(:data:`quilting.core.blend.THREADED_VALUES`) stays in line: its handover would cost about what
it saves.

On a torus the blocks of the last row and column are cut on their far sides too and blended
over their whole footprint, which reaches the next level's cells and, across the wrap, the
first row's and column's: the pass blends those in line (:meth:`QuiltPass._blend
<quilting.core.synthesis.QuiltPass._blend>`), and hands over the others only when every
wrapped axis has at least :data:`TORUS_CELLS` cells (:func:`may_hand_over`).

Tried and measured no faster (2048² RGB 1.14 s either way): handing every blend at once to a
thread of the lowest priority (``nice`` 19) so that it could also take the moments the cost
fields leave a core idle. There are hardly any: the blend's seconds doubled, spent waiting.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor

from quilting.core.blend import THREADED_VALUES
from quilting.core.grid import Grid
from quilting.core.progress import Clock

#: A level's blend: ``blend(part, workers)`` blends the level's cells in the slice ``part``,
#: its transforms on ``workers`` threads. Its parts cover disjoint cells and may run in any
#: order.
Blend = Callable[[slice, int | None], None]
#: Most parts a level's blend is cut into.
PARTS = 4
#: Fewest cells along each wrapped axis of a torus whose blends may be handed over: a blend
#: handed over is at most two batches behind, and a far block reads the wrapped cells of
#: levels ``cells - 2`` before its own, so ``cells - 2 >= 3``.
TORUS_CELLS = 5


def parts(values: int) -> int:
    """How many parts to cut a level's blend of ``values`` values into: enough that the main
    thread can take some when it must wait for the blend thread, none below
    :data:`THREADED_VALUES` values (each part costs a call's overhead)."""
    return min(PARTS, max(1, values // max(1, THREADED_VALUES)))


def may_hand_over(grid: Grid) -> bool:
    """Whether a pass over ``grid`` may blend beside the next level: a plane always, a torus
    with at least :data:`TORUS_CELLS` cells along each wrapped axis."""
    counts = (grid.rows, grid.cols)
    return all(
        not period or count >= TORUS_CELLS
        for period, count in zip(grid.period, counts, strict=True)
    )


class DeferredBlends:
    """Blends waiting for the next level's cost fields, and those running.

    Parameters
    ----------
    clock : Clock
        The pass's clock: each blend's seconds are added to its ``"blend"`` stage (on a
        thread of their own these seconds overlap other stages').
    deferred : bool
        False runs every blend in line as it is added (no cost fields to overlap with, or a
        torus too small).
    """

    def __init__(self, clock: Clock, deferred: bool) -> None:
        self._clock = clock
        self._waiting: list[tuple[Blend, slice]] = []
        self._running: list[tuple[Future[float], Blend, slice]] = []
        self._pool = (
            ThreadPoolExecutor(1, thread_name_prefix="quilting-blend") if deferred else None
        )

    def add(self, blend: Blend, cells: int, values: int) -> None:
        """A level's blend of ``cells`` cells and ``values`` values (cells x side^2 x
        channels): run now in one call, or cut into :func:`parts` kept for :meth:`start`."""
        if not cells:
            return
        if self._pool is None or values < THREADED_VALUES:
            self._count(_timed(blend, slice(0, cells), None))
            return
        count = parts(values)
        edges = [cells * k // count for k in range(count + 1)]
        self._waiting += [(blend, slice(a, b)) for a, b in itertools.pairwise(edges) if b > a]

    def start(self) -> None:
        """The cost fields are done: finish what runs, then hand the waiting parts to the
        blend thread, in order (their transforms on that one thread, leaving the other core
        to the main one)."""
        self.wait()
        if self._pool is None or not self._waiting:
            return
        waiting, self._waiting = self._waiting, []
        pool = self._pool
        self._running = [
            (pool.submit(_timed, blend, part, 1), blend, part) for blend, part in waiting
        ]

    def wait(self) -> None:
        """Finish the handed parts before the next cost fields, which want both cores: the
        main thread runs those the blend thread has not started, from the last, and joins the
        rest; re-raises what a part raised."""
        running, self._running = self._running, []
        for future, blend, part in reversed(running):
            if future.cancel():
                self._count(_timed(blend, part, 1))
        for future, _, _ in running:
            if not future.cancelled():
                self._count(future.result())

    def _count(self, seconds: float) -> None:
        """Add a part's seconds to the clock (from the main thread only)."""
        self._clock.spent["blend"] = self._clock.spent.get("blend", 0.0) + seconds

    def close(self) -> None:
        """Finish the handed parts, run the waiting ones in line and stop the thread: the
        canvas is whole after it. Safe to call twice, and while an exception unwinds."""
        try:
            self.wait()
            waiting, self._waiting = self._waiting, []
            for blend, part in waiting:
                self._count(_timed(blend, part, None))
        finally:
            if self._pool is not None:
                self._pool.shutdown(wait=True, cancel_futures=True)
                self._pool = None


def _timed(blend: Blend, part: slice, workers: int | None) -> float:
    """Run one part of a blend; its seconds."""
    start = time.perf_counter()
    blend(part, workers)
    return time.perf_counter() - start
