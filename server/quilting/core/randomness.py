"""Per-block random generators.

Each block draws from its own generator derived from (seed, pass, row, col), so the output
depends on the seed alone, never on the schedule, the batch size, the thread count or the
backend.
"""

from __future__ import annotations

import numpy as np


def block_rng(seed: int, pass_index: int, row: int, col: int) -> np.random.Generator:
    """The generator of block (row, col) in pass ``pass_index`` of a job seeded ``seed``."""
    return np.random.Generator(
        np.random.PCG64(np.random.SeedSequence([seed, pass_index, row, col]))
    )
