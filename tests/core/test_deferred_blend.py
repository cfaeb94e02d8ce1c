"""Tests of quilting.core.deferred_blend: blends beside the next level, same bytes."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from textures import texture

import quilting
from quilting.core import deferred_blend, synthesis
from quilting.core.blend import THREADED_VALUES
from quilting.core.deferred_blend import DeferredBlends
from quilting.core.grid import Grid
from quilting.core.progress import Clock

#: A blend large enough to go to the blend thread.
BIG = THREADED_VALUES


class _Recorder:
    """A level's blend that notes each part it ran: its cells, thread and workers."""

    def __init__(
        self, hold: threading.Event | None = None, started: threading.Event | None = None
    ) -> None:
        self.runs: list[tuple[range, str, int | None]] = []
        self.hold, self.started = hold, started

    def __call__(self, part: slice, workers: int | None) -> None:
        if part.start == 0 and self.started is not None:
            self.started.set()
        if part.start == 0 and self.hold is not None:
            assert self.hold.wait(timeout=30)
        self.runs.append((range(part.start, part.stop), threading.current_thread().name, workers))

    def cells(self) -> list[int]:
        """Every cell blended, in the order of the runs."""
        return [cell for done, _, _ in self.runs for cell in done]

    def thread_of(self, first: int) -> str:
        return next(thread for done, thread, _ in self.runs if done.start == first)


def _blend_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith("quilting-blend")]


def test_in_line_blends_run_whole_when_added_with_their_default_threads() -> None:
    clock, seen = Clock(), _Recorder()
    blends = DeferredBlends(clock, deferred=False)
    blends.add(seen, 6, 4 * BIG)
    assert seen.runs == [(range(6), threading.current_thread().name, None)]
    blends.start()
    blends.close()
    assert len(seen.runs) == 1 and clock.spent["blend"] >= 0


def test_handed_parts_wait_for_start_then_run_on_one_other_thread() -> None:
    clock, started = Clock(), threading.Event()
    seen = _Recorder(started=started)
    blends = DeferredBlends(clock, deferred=True)
    blends.add(seen, 3, BIG)
    assert seen.runs == [] and not started.is_set()
    blends.start()
    assert started.wait(timeout=30)  # the thread took it, before any wait()
    blends.wait()
    (cells, thread, workers) = seen.runs[0]
    assert cells == range(3) and thread.startswith("quilting-blend")
    # One thread for its transforms: the other core is the main thread's.
    assert workers == 1
    blends.close()
    assert "blend" in clock.spent and not _blend_threads()


def test_wait_runs_the_parts_not_started_on_the_main_thread_from_the_last() -> None:
    hold, started = threading.Event(), threading.Event()
    seen = _Recorder(hold, started)
    blends = DeferredBlends(Clock(), deferred=True)
    blends.add(seen, 6, 3 * BIG)  # three parts of two cells
    blends.start()
    assert started.wait(timeout=30)
    threading.Timer(0.2, hold.set).start()  # released while wait() joins it
    blends.wait()
    main = threading.current_thread().name
    assert [(cells, thread) for cells, thread, _ in seen.runs[:2]] == [
        (range(4, 6), main),
        (range(2, 4), main),
    ]
    assert seen.thread_of(0).startswith("quilting-blend")
    assert sorted(seen.cells()) == list(range(6))
    # The main thread's parts take one thread each too: the blend thread has the other core.
    assert {workers for _, _, workers in seen.runs} == {1}
    blends.close()


def test_a_blend_too_small_for_a_second_thread_runs_in_line_even_when_deferred() -> None:
    small, big = _Recorder(), _Recorder()
    blends = DeferredBlends(Clock(), deferred=True)
    blends.add(small, 2, BIG - 1)
    assert small.runs == [(range(2), threading.current_thread().name, None)]
    blends.add(big, 2, BIG)
    assert big.runs == []
    empty = _Recorder()
    blends.add(empty, 0, 4 * BIG)  # no cells: nothing to run
    blends.close()
    assert big.cells() == [0, 1] and empty.runs == []


def test_close_runs_the_blends_never_started_in_line_and_stops_the_thread() -> None:
    first, second = _Recorder(), _Recorder()
    blends = DeferredBlends(Clock(), deferred=True)
    blends.add(first, 2, BIG)
    blends.start()
    blends.add(second, 2, BIG)
    blends.close()
    assert first.cells() == [0, 1]
    assert second.runs == [(range(2), threading.current_thread().name, None)]
    assert not _blend_threads()
    blends.close()  # twice is harmless


def test_a_failing_blend_raises_where_it_is_finished() -> None:
    def broken(part: slice, workers: int | None) -> None:
        raise ValueError("broken blend")

    blends = DeferredBlends(Clock(), deferred=True)
    blends.add(broken, 2, BIG)
    blends.start()
    with pytest.raises(ValueError, match="broken blend"):
        blends.wait()
    blends.close()
    assert not _blend_threads()


@pytest.mark.parametrize(
    ("values", "count"),
    [(0, 1), (BIG - 1, 1), (BIG, 1), (2 * BIG, 2), (3 * BIG + 5, 3), (100 * BIG, 4)],
)
def test_a_level_is_cut_into_parts_of_at_least_the_threaded_size(values: int, count: int) -> None:
    assert deferred_blend.parts(values) == count


@pytest.mark.parametrize(
    ("height", "width", "wrap", "allowed"),
    [
        (100, 100, (False, False), True),  # a plane: always
        (300, 150, (True, False), True),  # 8 rows wrapped, 4 columns on a plane
        (300, 150, (False, True), False),  # 4 columns wrapped
        (200, 200, (True, True), True),  # 5 x 5
        (160, 200, (True, True), False),  # 4 rows
    ],
)
def test_a_torus_hands_blends_over_only_with_enough_cells_per_wrapped_axis(
    height: int, width: int, wrap: tuple[bool, bool], allowed: bool
) -> None:
    grid = Grid.covering(height, width, 48, 8, wrap)
    assert deferred_blend.may_hand_over(grid) is allowed


def _sample(channels: int) -> np.ndarray:
    """A 96 x 96 crop of a test texture with that many channels."""
    name = {1: "gravel", 3: "hubble", 4: "cloud_rgba"}[channels]
    image = texture(name)
    if channels == 1 and image.ndim == 3:
        image = image[..., 0]
    return np.ascontiguousarray(image[:96, :96])


def _every_blend_deferred(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Hand even the smallest blend over, in 4 parts; the threads the parts ran on."""
    threads: list[str] = []
    timed = deferred_blend._timed

    def noted(blend: deferred_blend.Blend, part: slice, workers: int | None) -> float:
        threads.append(threading.current_thread().name)
        return timed(blend, part, workers)

    monkeypatch.setattr(deferred_blend, "THREADED_VALUES", 0)
    monkeypatch.setattr(deferred_blend, "_timed", noted)
    return threads


def _in_line(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make every pass blend in line, as before the blends were deferred."""

    class InLine(DeferredBlends):
        def __init__(self, clock: Clock, deferred: bool) -> None:
            super().__init__(clock, deferred=False)

    monkeypatch.setattr(synthesis, "DeferredBlends", InLine)


@pytest.mark.parametrize(
    ("channels", "size", "options"),
    [
        (3, (300, 340), {}),
        (1, (260, 300), {"block": 24, "max_batch": 3}),
        (3, (240, 240), {"seam_sampling": 1.0, "continuation": "avoid"}),
        (4, (200, 230), {"mode": "alpha"}),
        # A torus: its far blocks blended in line, the others beside.
        (3, (240, 260), {"tileable": "both"}),
        (1, (200, 180), {"block": 24, "tileable": "x", "max_batch": 2}),
        (3, (210, 200), {"block": 32, "tileable": "y"}),
    ],
)
def test_deferred_blends_give_the_bytes_of_in_line_ones(
    monkeypatch: pytest.MonkeyPatch,
    channels: int,
    size: tuple[int, int],
    options: dict[str, object],
) -> None:
    sample = _sample(channels)
    threads = _every_blend_deferred(monkeypatch)
    deferred = quilting.synthesize(sample, size, seed=5, **options)
    assert deferred.timings["blend"] > 0
    assert any(name.startswith("quilting-blend") for name in threads)
    _in_line(monkeypatch)
    in_line = quilting.synthesize(sample, size, seed=5, **options)
    assert deferred.image.tobytes() == in_line.image.tobytes()
    assert deferred.layout.to_json() == in_line.layout.to_json()


def test_a_torus_of_fewer_than_5_cells_a_side_blends_in_line(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Its far blocks would read cells whose blends may still wait: nothing is handed over."""
    sample = _sample(3)
    threads = _every_blend_deferred(monkeypatch)
    result = quilting.synthesize(sample, (160, 300), seed=2, tileable="both")
    assert result.layout.passes[0].grid.rows < 5 <= result.layout.passes[0].grid.cols
    assert not any(name.startswith("quilting-blend") for name in threads)
    _in_line(monkeypatch)
    in_line = quilting.synthesize(sample, (160, 300), seed=2, tileable="both")
    assert result.image.tobytes() == in_line.image.tobytes()


def test_a_transfer_with_deferred_blends_gives_the_bytes_of_in_line_ones(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    sample, target = _sample(3)[:80, :80], texture("target_camera")[:120, :120]
    threads = _every_blend_deferred(monkeypatch)
    deferred = quilting.transfer(sample, target, seed=4, iterations=2)
    assert any(name.startswith("quilting-blend") for name in threads)
    _in_line(monkeypatch)
    in_line = quilting.transfer(sample, target, seed=4, iterations=2)
    assert deferred.image.tobytes() == in_line.image.tobytes()


def test_a_job_cancelled_mid_pass_leaves_no_blend_thread() -> None:
    sample = _sample(3)
    calls = []

    def progress(fraction: float, stage: str) -> None:
        calls.append(fraction)
        if len(calls) == 3:
            raise KeyboardInterrupt  # what a cancelled job's callback raises, in effect

    with pytest.raises(KeyboardInterrupt):
        quilting.synthesize(sample, (400, 400), seed=1, progress=progress)
    assert not [t for t in threading.enumerate() if t.name.startswith("quilting-blend")]
