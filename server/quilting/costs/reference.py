"""The reference backend: every candidate scored by direct sums. Slow, obviously right.

It scores through :class:`quilting.core.fields.ExactScorer`, the same code that re-scores the
shortlists of the fast backends, so its fields are the exact costs the others must agree with.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from quilting.core.fields import CostRequest, ExactScorer, FieldBatch
from quilting.core.select import DenseShortlists

#: Candidates scored per numpy call (bounds the temporary memory).
CHUNK = 4096


class ReferenceBackend(DenseShortlists):
    """Exact cost fields by direct summation over every candidate position."""

    name = "reference"
    renderer = "cpu"

    def __init__(self) -> None:
        self._scorer: ExactScorer | None = None
        self._shape = (0, 0)

    def prepare(
        self, source: NDArray[np.float32], block: int, guide: NDArray[np.float32] | None = None
    ) -> None:
        self._scorer = ExactScorer(source, block, guide)
        self._shape = (source.shape[0] - block + 1, source.shape[1] - block + 1)

    def fields(self, requests: Sequence[CostRequest]) -> FieldBatch:
        if self._scorer is None:
            raise RuntimeError("prepare() must be called before fields()")
        height, width = self._shape
        ys, xs = np.divmod(np.arange(height * width), width)
        values = np.empty((len(requests), height * width), dtype=np.float64)
        for k, request in enumerate(requests):
            for start in range(0, ys.size, CHUNK):
                stop = start + CHUNK
                values[k, start:stop] = self._scorer.costs(request, ys[start:stop], xs[start:stop])
        return FieldBatch(values.reshape(-1, height, width), np.zeros(len(requests)))

    def close(self) -> None:
        self._scorer = None
