"""Unit tests of :class:`quilting.costs.fallback.FallbackBackend` with real backends.

Covers
------
- The documented order: the primary is made at once and used while it works; the secondary
  is made only when the primary raises :class:`BackendError`, once, and used for good.
- A primary failing at ``prepare`` or at its first ``shortlists``: the switch happens once,
  the failed primary is closed, and the results are byte for byte those of the secondary
  backend (``fft``) prepared with the same job on its own; ``close`` then closes the secondary.
- Errors that are not a ``BackendError`` at ``prepare`` are not a reason to switch.
- Every backend failing (at start, at ``prepare``, at the replayed ``prepare``): the
  ``BackendError`` raised is the secondary's, and ``fallback`` keeps the primary's failure,
  so both backends' failures are reported.

The scripted-fake cases (argument passing, mid-job ``fields`` switch, one fallback only, no
replay after ``close``) live in ``test_registry.py`` and are not repeated here.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Generic, TypeVar

import numpy as np
import pytest
from numpy.typing import NDArray

from quilting.core.errors import BackendError
from quilting.core.fields import CostBackend, CostRequest, FieldBatch, Shortlist
from quilting.costs.fallback import FallbackBackend
from quilting.costs.fft import FFTBackend
from quilting.costs.reference import ReferenceBackend

B = TypeVar("B", bound=CostBackend)


class Factory(Generic[B]):
    """A backend factory that counts the backends it makes and keeps them."""

    def __init__(self, make: Callable[[], B]) -> None:
        self.make = make
        self.made: list[B] = []

    def __call__(self) -> B:
        backend = self.make()
        self.made.append(backend)
        return backend


class BrokenReference(ReferenceBackend):
    """The reference backend as a 'GPU' that fails on one method (or at start)."""

    name = "gpu"
    renderer = "Fake GPU"

    def __init__(self, fail_on: str, error: type[Exception] = BackendError) -> None:
        super().__init__()
        self.fail_on = fail_on
        self.error = error
        self.closed = 0
        if fail_on == "start":
            raise error("no context (test)")

    def _maybe_fail(self, what: str) -> None:
        if self.fail_on == what:
            raise self.error(f"{what} failed (test)")

    def prepare(
        self, source: NDArray[np.float32], block: int, guide: NDArray[np.float32] | None = None
    ) -> None:
        self._maybe_fail("prepare")
        super().prepare(source, block, guide)

    def fields(self, requests: Sequence[CostRequest]) -> FieldBatch:
        self._maybe_fail("fields")
        return super().fields(requests)

    def shortlists(
        self, requests: Sequence[CostRequest], tolerance: float, min_candidates: int
    ) -> list[Shortlist]:
        self._maybe_fail("shortlists")
        return super().shortlists(requests, tolerance, min_candidates)

    def close(self) -> None:
        self.closed += 1
        super().close()


class BrokenFFT(FFTBackend):
    """The fft backend failing at ``prepare`` (a secondary that cannot run either)."""

    def prepare(
        self, source: NDArray[np.float32], block: int, guide: NDArray[np.float32] | None = None
    ) -> None:
        raise BackendError("fft ran out of memory (test)")


def job(seed: int) -> tuple[NDArray[np.float32], int, list[CostRequest]]:
    """A small source, block and a batch of requests (shared and one-off masks)."""
    rng = np.random.default_rng(seed)
    source = rng.random((21, 24, 3), dtype=np.float32)
    block = 6
    left = np.zeros((block, block), np.float32)
    left[:, :2] = 1
    requests = [CostRequest(rng.random((block, block, 3), dtype=np.float32), left)]
    requests += [
        CostRequest(
            rng.random((block, block, 3), dtype=np.float32),
            (rng.random((block, block)) < 0.5).astype(np.float32),
            shared_mask=False,
        )
        for _ in range(3)
    ]
    return source, block, requests


def fft_alone(
    source: NDArray[np.float32], block: int, requests: Sequence[CostRequest]
) -> tuple[FieldBatch, list[Shortlist]]:
    backend = FFTBackend(threads=1)
    backend.prepare(source, block)
    try:
        return backend.fields(requests), backend.shortlists(requests, 0.1, 3)
    finally:
        backend.close()


def assert_same_shortlists(got: list[Shortlist], want: list[Shortlist]) -> None:
    assert len(got) == len(want)
    for a, b in zip(got, want, strict=True):
        assert np.array_equal(a.index, b.index)
        assert np.array_equal(a.values, b.values)
        assert a.bound == b.bound


def test_a_working_primary_is_used_and_the_secondary_never_made() -> None:
    source, block, requests = job(1)
    primary = Factory(lambda: BrokenReference(fail_on="nothing"))
    secondary = Factory(lambda: FFTBackend(threads=1))
    backend = FallbackBackend(primary, secondary)
    assert len(primary.made) == 1 and secondary.made == []
    backend.prepare(source, block)
    got = backend.fields(requests)
    backend.shortlists(requests, 0.1, 3)
    assert (backend.name, backend.renderer, backend.fallback) == ("gpu", "Fake GPU", None)
    assert secondary.made == []
    # The reference's exact fields, not fft's approximate ones: it was the primary that ran.
    reference = ReferenceBackend()
    reference.prepare(source, block)
    assert np.array_equal(got.values, reference.fields(requests).values)
    backend.close()
    assert primary.made[0].closed == 1


def test_a_failure_at_prepare_switches_once_to_the_secondary_s_own_results() -> None:
    source, block, requests = job(2)
    primary = Factory(lambda: BrokenReference(fail_on="prepare"))
    secondary = Factory(lambda: FFTBackend(threads=1))
    backend = FallbackBackend(primary, secondary)
    backend.prepare(source, block)
    assert backend.fallback == "gpu failed: prepare failed (test)"
    assert (backend.name, backend.renderer) == ("fft", "cpu")
    assert primary.made[0].closed == 1
    fields = [backend.fields(requests) for _ in range(2)]
    lists = backend.shortlists(requests, 0.1, 3)
    assert len(primary.made) == 1 and len(secondary.made) == 1
    want_fields, want_lists = fft_alone(source, block, requests)
    for got in fields:
        assert np.array_equal(got.values, want_fields.values)
        assert np.array_equal(got.error_bound, want_fields.error_bound)
    assert_same_shortlists(lists, want_lists)
    # close reaches the backend in use: the secondary forgets the job.
    backend.close()
    with pytest.raises(RuntimeError, match="prepare"):
        secondary.made[0].fields(requests)
    assert primary.made[0].closed == 1


def test_a_failure_at_the_first_shortlists_is_answered_by_the_secondary() -> None:
    source, block, requests = job(3)
    primary = Factory(lambda: BrokenReference(fail_on="shortlists"))
    secondary = Factory(lambda: FFTBackend(threads=1))
    backend = FallbackBackend(primary, secondary)
    backend.prepare(source, block)
    assert secondary.made == []
    lists = backend.shortlists(requests, 0.1, 3)
    assert backend.fallback == "gpu failed: shortlists failed (test)"
    want_fields, want_lists = fft_alone(source, block, requests)
    assert_same_shortlists(lists, want_lists)
    assert np.array_equal(backend.fields(requests).values, want_fields.values)
    assert len(secondary.made) == 1
    backend.close()


def test_a_primary_that_cannot_start_leaves_the_job_to_the_secondary() -> None:
    source, block, requests = job(4)
    secondary = Factory(lambda: FFTBackend(threads=1))
    backend = FallbackBackend(lambda: BrokenReference(fail_on="start"), secondary)
    assert backend.fallback == "the GPU backend failed to start: no context (test)"
    backend.prepare(source, block)
    want_fields, _ = fft_alone(source, block, requests)
    assert np.array_equal(backend.fields(requests).values, want_fields.values)
    assert len(secondary.made) == 1
    backend.close()


def test_other_errors_at_prepare_are_not_a_fallback() -> None:
    source, block, _ = job(5)
    secondary = Factory(lambda: FFTBackend(threads=1))
    backend = FallbackBackend(lambda: BrokenReference("prepare", error=ValueError), secondary)
    with pytest.raises(ValueError, match="prepare failed"):
        backend.prepare(source, block)
    assert backend.fallback is None and backend.name == "gpu" and secondary.made == []


def test_every_backend_failing_at_prepare_raises_the_secondary_s_error() -> None:
    source, block, _ = job(6)
    secondary = Factory(BrokenFFT)
    backend = FallbackBackend(lambda: BrokenReference(fail_on="prepare"), secondary)
    with pytest.raises(BackendError, match="fft ran out of memory") as caught:
        backend.prepare(source, block)
    # Both failures are on record: the primary's in `fallback` (and as the error's context).
    assert backend.fallback == "gpu failed: prepare failed (test)"
    assert isinstance(caught.value.__context__, BackendError)
    assert caught.value.__context__.message == "prepare failed (test)"
    assert len(secondary.made) == 1  # no third try, no second secondary


def test_every_backend_failing_after_a_failed_start_raises_the_secondary_s_error() -> None:
    source, block, _ = job(7)
    secondary = Factory(BrokenFFT)
    backend = FallbackBackend(lambda: BrokenReference(fail_on="start"), secondary)
    with pytest.raises(BackendError, match="fft ran out of memory"):
        backend.prepare(source, block)
    assert backend.fallback == "the GPU backend failed to start: no context (test)"
    assert len(secondary.made) == 1


def test_no_backend_able_to_start_raises_the_secondary_s_error() -> None:
    def cannot_start() -> CostBackend:
        raise BackendError("no CPU backend either (test)")

    with pytest.raises(BackendError, match="no CPU backend either") as caught:
        FallbackBackend(lambda: BrokenReference(fail_on="start"), cannot_start)
    assert isinstance(caught.value.__context__, BackendError)
    assert caught.value.__context__.message == "no context (test)"


def test_a_secondary_that_cannot_take_the_job_over_fails_every_later_call_alike() -> None:
    # The primary fails mid-job and the secondary's replayed prepare fails too: that error,
    # and the same one on every later call, not a RuntimeError of a secondary left
    # unprepared.
    source, block, requests = job(6)
    backend = FallbackBackend(
        Factory(lambda: BrokenReference(fail_on="fields")), Factory(lambda: BrokenFFT(threads=1))
    )
    backend.prepare(source, block)
    with pytest.raises(BackendError, match="fft ran out of memory") as first:
        backend.fields(requests)
    for call in (
        lambda: backend.fields(requests),
        lambda: backend.shortlists(requests, 0.1, 3),
    ):
        with pytest.raises(BackendError) as again:
            call()
        assert again.value is first.value
