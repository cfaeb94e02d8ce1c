"""The public entry points: validate at the edge, pick a backend, run the engine."""

from __future__ import annotations

from quilting.core.fields import CostBackend
from quilting.core.layout import Layout, apply_layout
from quilting.core.options import Mode, SynthesisOptions, validate_size
from quilting.core.pixels import as_channels
from quilting.core.synthesis import Progress, Result, quilt
from quilting.costs import get_backend

__all__ = ["Layout", "Result", "apply_layout", "synthesize"]


def synthesize(
    texture: object,
    size: tuple[int, int],
    *,
    block: int = 48,
    overlap: int | None = None,
    tolerance: float = 0.1,
    mode: Mode = "cut",
    seed: int = 0,
    backend: str | CostBackend = "auto",
    progress: Progress | None = None,
    min_candidates: int = 3,
    max_batch: int | None = None,
) -> Result:
    """Synthesize a larger texture from a sample by image quilting.

    Parameters
    ----------
    texture : ndarray, shape (h, w) or (h, w, C)
        The sample; C in 1, 3, 4; uint8, uint16 or float (taken as is, finite).
    size : (int, int)
        Output (height, width), each >= 1. The covering grid of blocks is synthesized and
        cropped to exactly this size.
    block : int
        Block side in pixels, 3..min(h, w).
    overlap : int, optional
        Overlap between neighbouring blocks, < block / 2; default ``max(1, block // 6)``.
    tolerance : float
        Candidates within ``(1 + tolerance) x`` the best overlap error are equally likely.
    mode : {'cut', 'overlap', 'random'}
        Minimum-error boundary cut, straight matched edges, or random blocks.
    seed : int
        The output is a function of the inputs and the seed only.
    backend : str or CostBackend
        ``'auto'``, ``'fft'``, ``'reference'``, or a backend instance.
    progress : callable, optional
        ``progress(fraction, stage)`` between wavefront levels; raise from it to stop.
    min_candidates : int
        Floor of the tolerance rule: at least this many blocks stay acceptable (measured from
        the k-th best cost), so a zero-error continuation does not copy the source; 1 is the
        paper's bare rule.
    max_batch : int, optional
        Most blocks per backend call (memory bound); never changes the output.

    Returns
    -------
    Result
        ``image`` (size, same channels and dtype as ``texture``), ``layout``, ``backend``,
        ``timings``, ``stats``.
    """
    options = SynthesisOptions(
        block=block,
        overlap=overlap,
        tolerance=tolerance,
        mode=mode,
        seed=seed,
        backend=backend if isinstance(backend, str) else backend.name,
        min_candidates=min_candidates,
    )
    out_size = validate_size(size)
    view, fmt = as_channels(texture, "texture")
    engine = get_backend(backend) if isinstance(backend, str) else backend
    return quilt(view, fmt, out_size, options, engine, progress=progress, max_batch=max_batch)
