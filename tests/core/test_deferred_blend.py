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
    """Blends that note the thread and the workers they ran with."""

    def __init__(self) -> None:
        self.runs: list[tuple[str, str, int | None]] = []

    def blend(self, name: str) -> deferred_blend.Blend:
        def run(workers: int | None) -> None:
            self.runs.append((name, threading.current_thread().name, workers))

        return run


def test_in_line_blends_run_when_added_with_their_default_threads() -> None:
    clock, seen = Clock(), _Recorder()
    blends = DeferredBlends(clock, deferred=False)
    blends.add(seen.blend("a"), BIG)
    assert seen.runs == [("a", threading.current_thread().name, None)]
    blends.start()
    blends.close()
    assert len(seen.runs) == 1 and clock.spent["blend"] >= 0


def test_deferred_blends_wait_for_start_then_run_in_order_on_one_other_thread() -> None:
    clock, seen = Clock(), _Recorder()
    blends = DeferredBlends(clock, deferred=True)
    blends.add(seen.blend("a"), BIG)
    blends.add(seen.blend("b"), BIG)
    assert seen.runs == []
    blends.start()
    blends.wait()
    assert [name for name, _, _ in seen.runs] == ["a", "b"]
    threads = {thread for _, thread, _ in seen.runs}
    assert len(threads) == 1 and threading.current_thread().name not in threads
    # On the blend thread the transforms get one thread: the other core is the main one's.
    assert {workers for _, _, workers in seen.runs} == {1}
    blends.close()
    assert "blend" in clock.spent


def test_a_blend_too_small_for_a_second_thread_runs_in_line_even_when_deferred() -> None:
    seen = _Recorder()
    blends = DeferredBlends(Clock(), deferred=True)
    blends.add(seen.blend("small"), BIG - 1)
    assert seen.runs == [("small", threading.current_thread().name, None)]
    blends.add(seen.blend("big"), BIG)
    assert len(seen.runs) == 1
    blends.close()
    assert [name for name, _, _ in seen.runs] == ["small", "big"]


def test_close_runs_the_blends_never_started_in_line_and_stops_the_thread() -> None:
    seen = _Recorder()
    blends = DeferredBlends(Clock(), deferred=True)
    blends.add(seen.blend("a"), BIG)
    blends.start()
    blends.add(seen.blend("b"), BIG)
    blends.close()
    assert [name for name, _, _ in seen.runs] == ["a", "b"]
    assert seen.runs[1][1:] == (threading.current_thread().name, None)
    assert not [t for t in threading.enumerate() if t.name.startswith("quilting-blend")]
    blends.close()  # twice is harmless


def test_a_failing_blend_raises_where_it_is_joined() -> None:
    def broken(workers: int | None) -> None:
        raise ValueError("broken blend")

    blends = DeferredBlends(Clock(), deferred=True)
    blends.add(broken, BIG)
    blends.start()
    with pytest.raises(ValueError, match="broken blend"):
        blends.wait()
    blends.close()


def _sample(channels: int) -> np.ndarray:
    """A 96 x 96 crop of a test texture with that many channels."""
    name = {1: "gravel", 3: "hubble", 4: "cloud_rgba"}[channels]
    image = texture(name)
    if channels == 1 and image.ndim == 3:
        image = image[..., 0]
    return np.ascontiguousarray(image[:96, :96])


def _every_blend_deferred(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Send even the smallest blend to the blend thread; the threads blends ran on."""
    threads: list[str] = []
    run_all = deferred_blend._run_all

    def noted(blends: list[deferred_blend.Blend], workers: int | None = 1) -> float:
        threads.append(threading.current_thread().name)
        return run_all(blends, workers)

    monkeypatch.setattr(deferred_blend, "THREADED_VALUES", 0)
    monkeypatch.setattr(deferred_blend, "_run_all", noted)
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
