"""Compiled per-level hot loops (numba): the only package that imports numba.

Each kernel reproduces the numpy arithmetic it replaced operation for operation, so outputs
kept their bytes; ``cache=True`` keeps the machine code on disk between processes (in the
package's ``__pycache__``, or in ``NUMBA_CACHE_DIR``, which must be writable), and
:func:`warm_up` compiles (or loads) every kernel once, which the service's workers call at
start so that no job pays for a compilation.

numba (with LLVM) costs about 0.3 s and 100 MiB of memory when it loads, so it is loaded on
first use, not by ``import quilting``: the API process and the CLI's light commands never
load it. Call the kernels as attributes of this package (``kernels.block_cuts(...)``), which
loads :mod:`quilting.core.kernels.seams` the first time.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from quilting.core.kernels.blend import add_cells, seam_divergence
    from quilting.core.kernels.compose import paste_pixels
    from quilting.core.kernels.draws import first_integer
    from quilting.core.kernels.exact import masked_costs
    from quilting.core.kernels.fields import field_shortlist, spectral_sum
    from quilting.core.kernels.region_cut import region_cuts
    from quilting.core.kernels.seams import block_cuts, candidate_seam_costs, surface_cuts
    from quilting.core.kernels.select import bracket, settle

__all__ = [
    "add_cells",
    "block_cuts",
    "bracket",
    "candidate_seam_costs",
    "field_shortlist",
    "first_integer",
    "masked_costs",
    "paste_pixels",
    "region_cuts",
    "seam_divergence",
    "settle",
    "spectral_sum",
    "surface_cuts",
    "warm_up",
]

#: Where each kernel lives.
_MODULES = {
    "add_cells": "blend",
    "seam_divergence": "blend",
    "first_integer": "draws",
    "masked_costs": "exact",
    "field_shortlist": "fields",
    "paste_pixels": "compose",
    "region_cuts": "region_cut",
    "spectral_sum": "fields",
    "block_cuts": "seams",
    "candidate_seam_costs": "seams",
    "surface_cuts": "seams",
    "bracket": "select",
    "settle": "select",
}


def __getattr__(name: str) -> Any:
    if name in _MODULES:
        module = importlib.import_module(f"quilting.core.kernels.{_MODULES[name]}")
        value = getattr(module, name)
        globals()[name] = value  # later lookups skip this function
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def warm_up() -> None:
    """Compile or load every kernel for the argument types the engine passes (a few seconds
    the first time on a machine, about 0.2 s from the cache)."""
    import numpy as np

    from quilting.core.kernels import (
        blend,
        compose,
        draws,
        exact,
        fields,
        region_cut,
        seams,
        select,
    )

    match = np.zeros((8, 8, 3), dtype=np.float32)
    templates = np.zeros((1, 6, 6, 3), dtype=np.float32)
    corners = np.zeros((1, 2), dtype=np.intp)
    seams.block_cuts(
        match, templates, corners, left=True, top=True, right=True, bottom=True,
        overlap=2, wrap_overlap=(2, 2), edge_cost=0.1, context=0.5, radius=2,
    )  # fmt: skip
    region_cut.region_cuts(np.zeros((1, 4, 4)), np.zeros((1, 4, 4), dtype=np.int8))
    seams.surface_cuts(
        np.zeros((1, 6, 6)), left=True, top=True, overlap=3, edge_cost=0.1, context=0.5, radius=2
    )
    pixels = np.zeros((64, 3))
    offsets = np.zeros(2, dtype=np.intp)
    one = np.zeros(1, dtype=np.intp)
    exact.masked_costs(pixels, offsets, np.ones(2), np.zeros((1, 2, 3)), one, one)
    cells = np.zeros((1, 4, 4, 3), dtype=np.float32)
    owned = np.zeros((1, 4, 4), dtype=np.bool_)
    blend.seam_divergence(cells, cells, owned, owned, 1.25)
    blend.add_cells(np.zeros((8, 8, 3), dtype=np.float32), cells, np.zeros((1, 2), dtype=np.intp))
    # Pixels of 4-, 2- and 1-byte multiples; blocks are often a read-only view (broadcast),
    # which numba types apart.
    for dtype, channels in ((np.float32, 3), (np.uint16, 3), (np.uint8, 3)):
        painted = np.zeros((1, 4, 4, channels), dtype=dtype)
        for block_pixels in (painted, np.broadcast_to(painted, painted.shape)):
            compose.paste_pixels(
                np.zeros((8, 8, channels), dtype), block_pixels, np.zeros((1, 2), np.intp), owned
            )
    spectra = np.zeros((1, 3, 4, 3), dtype=np.complex64)
    product = np.zeros((1, 4, 3), np.complex64)
    fields.spectral_sum(spectra, np.zeros((3, 4, 3), np.complex64), product)
    listed = np.zeros(3)
    offsets = np.array([0, 3], dtype=np.intp)
    marks = select.bracket(listed, offsets, np.zeros(1), 1.1, 3)
    select.settle(listed, offsets, np.zeros(1), marks[0], marks[2], marks[3], listed, 1.1, 3)
    energy = np.zeros((4, 4), dtype=np.float32)
    fields.field_shortlist(np.zeros((4, 5), np.float32), energy, np.float32(0), 0.0, 1.1, 3)
    draws.first_integer(np.zeros(2, dtype=np.uint32), 0, 0, 3)
