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
from quilting.core.progress import Clock

#: A blend large enough to go to the blend thread.
BIG = THREADED_VALUES


class _Recorder:
    """Blend parts that note the thread and the workers they ran with."""

    def __init__(self) -> None:
        self.runs: list[tuple[str, str, int | None]] = []

    def blend(
        self,
        name: str,
        hold: threading.Event | None = None,
        started: threading.Event | None = None,
    ) -> deferred_blend.Blend:
        def run(workers: int | None) -> None:
            if started is not None:
                started.set()
            if hold is not None:
                assert hold.wait(timeout=30)
            self.runs.append((name, threading.current_thread().name, workers))

        return run

    def names(self) -> list[str]:
        return [name for name, _, _ in self.runs]

    def thread_of(self, name: str) -> str:
        return next(thread for n, thread, _ in self.runs if n == name)


def _blend_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith("quilting-blend")]


def test_in_line_blends_run_when_added_with_their_default_threads() -> None:
    clock, seen = Clock(), _Recorder()
    blends = DeferredBlends(clock, deferred=False)
    blends.add([seen.blend("a"), seen.blend("b")], BIG)
    main = threading.current_thread().name
    assert seen.runs == [("a", main, None), ("b", main, None)]
    blends.start()
    blends.close()
    assert len(seen.runs) == 2 and clock.spent["blend"] >= 0


def test_handed_parts_wait_for_start_then_run_on_one_other_thread() -> None:
    clock, seen, started = Clock(), _Recorder(), threading.Event()
    blends = DeferredBlends(clock, deferred=True)
    blends.add([seen.blend("a", started=started)], BIG)
    assert seen.runs == [] and not started.is_set()
    blends.start()
    assert started.wait(timeout=30)  # the thread took it, before any wait()
    blends.wait()
    (name, thread, workers) = seen.runs[0]
    assert name == "a" and thread.startswith("quilting-blend")
    # One thread for its transforms: the other core is the main thread's.
    assert workers == 1
    blends.close()
    assert "blend" in clock.spent and not _blend_threads()


def test_wait_runs_the_parts_not_started_on_the_main_thread_from_the_last() -> None:
    seen, hold, started = _Recorder(), threading.Event(), threading.Event()
    blends = DeferredBlends(Clock(), deferred=True)
    blends.add([seen.blend("held", hold, started), seen.blend("b"), seen.blend("c")], BIG)
    blends.start()
    assert started.wait(timeout=30)
    threading.Timer(0.2, hold.set).start()  # released while wait() joins it
    blends.wait()
    main = threading.current_thread().name
    assert [(name, thread) for name, thread, _ in seen.runs[:2]] == [("c", main), ("b", main)]
    assert seen.thread_of("held").startswith("quilting-blend")
    assert sorted(seen.names()) == ["b", "c", "held"]
    # The main thread's parts take one thread each too: the blend thread has the other core.
    assert {workers for _, _, workers in seen.runs} == {1}
    blends.close()


def test_a_blend_too_small_for_a_second_thread_runs_in_line_even_when_deferred() -> None:
    seen = _Recorder()
    blends = DeferredBlends(Clock(), deferred=True)
    blends.add([seen.blend("small")], BIG - 1)
    assert seen.runs == [("small", threading.current_thread().name, None)]
    blends.add([seen.blend("big")], BIG)
    assert len(seen.runs) == 1
    blends.close()
    assert seen.names() == ["small", "big"]


def test_close_runs_the_blends_never_started_in_line_and_stops_the_thread() -> None:
    seen = _Recorder()
    blends = DeferredBlends(Clock(), deferred=True)
    blends.add([seen.blend("a")], BIG)
    blends.start()
    blends.add([seen.blend("b")], BIG)
    blends.close()
    assert sorted(seen.names()) == ["a", "b"]
    assert next(run for run in seen.runs if run[0] == "b")[1:] == (
        threading.current_thread().name,
        None,
    )
    assert not _blend_threads()
    blends.close()  # twice is harmless


def test_a_failing_blend_raises_where_it_is_finished() -> None:
    def broken(workers: int | None) -> None:
        raise ValueError("broken blend")

    blends = DeferredBlends(Clock(), deferred=True)
    blends.add([broken], BIG)
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

    def noted(blend: deferred_blend.Blend, workers: int | None) -> float:
        threads.append(threading.current_thread().name)
        return timed(blend, workers)

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
