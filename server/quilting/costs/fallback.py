"""The GPU with a safety net: ``auto`` on a GPU machine runs ``gl`` and, if the GPU fails,
finishes the job on ``fft``.

Both backends choose the same blocks (exact re-scoring), so switching in the middle of a job
changes nothing in the output; the result says which backend finished it and why it switched.
A backend asked for by name never goes through here: there a failure is an error.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from quilting.core.errors import BackendError
from quilting.core.fields import CostBackend, CostRequest, FieldBatch, Shortlist

T = TypeVar("T")


class FallbackBackend:
    """``primary`` until it raises :class:`BackendError`, then ``secondary`` for good.

    Parameters
    ----------
    primary, secondary : callable returning CostBackend
        Factories; the secondary is made only when needed.
    """

    def __init__(
        self, primary: Callable[[], CostBackend], secondary: Callable[[], CostBackend]
    ) -> None:
        self._secondary_factory = secondary
        self.fallback: str | None = None
        self._job: tuple[NDArray[np.float32], int, NDArray[np.float32] | None] | None = None
        # The secondary's own failure to take the job over: every later call repeats it.
        self._broken: BackendError | None = None
        try:
            self._active: CostBackend = primary()
        except BackendError as exc:
            self.fallback = f"the GPU backend failed to start: {exc.message}"
            self._active = secondary()

    @property
    def name(self) -> str:
        return self._active.name

    @property
    def renderer(self) -> str:
        return self._active.renderer

    def _switch(self, exc: BackendError) -> None:
        """Leave the failed backend for the secondary, for good, and give it the job."""
        if self.fallback is not None:
            raise exc  # already on the secondary: nothing left to fall back to
        failed = self._active
        self.fallback = f"{failed.name} failed: {exc.message}"
        with contextlib.suppress(BackendError):
            failed.close()
        self._active = self._secondary_factory()
        if self._job is not None:
            try:
                self._active.prepare(*self._job)
            except BackendError as broken:
                self._broken = broken  # not a secondary left unprepared for the next call
                raise

    def _attempt(self, call: Callable[[CostBackend], T]) -> T:
        """``call(active)``; on a BackendError switch to the secondary and retry."""
        if self._broken is not None:
            raise self._broken
        try:
            return call(self._active)
        except BackendError as exc:
            self._switch(exc)
            return call(self._active)

    def prepare(
        self, source: NDArray[np.float32], block: int, guide: NDArray[np.float32] | None = None
    ) -> None:
        self._job = (source, block, guide)
        self._broken = None
        try:
            self._active.prepare(source, block, guide)
        except BackendError as exc:
            self._switch(exc)  # which prepares the secondary with this job

    def fields(self, requests: Sequence[CostRequest]) -> FieldBatch:
        return self._attempt(lambda backend: backend.fields(requests))

    def shortlists(
        self, requests: Sequence[CostRequest], tolerance: float, min_candidates: int
    ) -> list[Shortlist]:
        return self._attempt(lambda b: b.shortlists(requests, tolerance, min_candidates))

    def close(self) -> None:
        self._job = None
        self._active.close()
