"""The public entry points: validate at the edge, pick a backend, run the engine."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from numpy.typing import NDArray

from quilting.core.budget import (
    Budget,
    estimate_synthesis,
    estimate_tile,
    estimate_transfer,
)
from quilting.core.errors import InvalidParameterError
from quilting.core.exclusion import excluded_pixels, usable_candidates
from quilting.core.fields import CostBackend
from quilting.core.layout import Layout, apply_layout
from quilting.core.matte import estimate_matte, matte_inputs, matte_quilt
from quilting.core.matting import MatteResult
from quilting.core.options import (
    Blend,
    Correspondence,
    ErrorKind,
    MatteMode,
    MatteOptions,
    Mode,
    QuiltOptions,
    SynthesisOptions,
    Tileable,
    TileBlend,
    TileOptions,
    TransferMode,
    TransferOptions,
    validate_size,
)
from quilting.core.pixels import as_channels, to_working
from quilting.core.progress import Progress
from quilting.core.seamless import Tiled
from quilting.core.seamless import make_tileable as tile_image
from quilting.core.synthesis import Result, check_block_fits, quilt, synthesis_grid
from quilting.core.transfer import computed_maps, custom_maps, transfer_quilt
from quilting.costs.registry import get_backend, resolve_name

__all__ = [
    "Layout",
    "MatteResult",
    "Result",
    "Tiled",
    "apply_layout",
    "check_inputs",
    "check_matte_inputs",
    "make_tileable",
    "matte",
    "synthesize",
    "transfer",
]


def synthesize(
    texture: object,
    size: tuple[int, int],
    *,
    block: int = 48,
    overlap: int | None = None,
    tolerance: float = 0.1,
    mode: Mode = "auto",
    seed: int = 0,
    backend: str | CostBackend = "auto",
    progress: Progress | None = None,
    min_candidates: int = 3,
    error: ErrorKind = "rgb",
    discard: float = 0.0,
    blend: Blend = "poisson",
    exclude_colors: Sequence[tuple[Sequence[float], Sequence[float]]] = (),
    source_mask: NDArray[Any] | None = None,
    tileable: Tileable | None = None,
    max_run: int = 5,
    feather: int = 4,
    seam_sampling: float = 0.0,
    histogram_weight: float = 0.05,
    epsilon: float = 0.02,
    eta: float = 20.0,
    max_batch: int | None = None,
    budget: Budget | None = None,
) -> Result:
    """Synthesize a larger texture from a sample by image quilting.

    Parameters
    ----------
    texture : ndarray, shape (h, w) or (h, w, C)
        The sample; C in 1, 3, 4; uint8, uint16 or float (taken as is, finite).
    size : (int, int)
        Output (height, width), each >= 1. The covering grid of blocks is synthesized and
        cropped to exactly this size (a tileable side is synthesized at exactly its size).
    block : int
        Block side in pixels, 3..min(h, w).
    overlap : int, optional
        Overlap between neighbouring blocks, < block / 2; default ``max(1, block // 6)``.
    tolerance : float
        Candidates within ``(1 + tolerance) x`` the best overlap error are equally likely.
    mode : {'auto', 'cut', 'overlap', 'random', 'walk', 'alpha'}
        Minimum-error boundary cut, straight matched edges, random blocks, random blocks
        joined along a minimum-resistance walk (the minimum-resistance-cut paper), or alpha
        quilting of an RGBA texture (the alpha quilting and texture matting paper, §2.1).
        ``'auto'``: ``'alpha'`` for an RGBA texture, else ``'cut'``.
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
    error : {'rgb', 'luminance'}
        What the overlap error and the seams compare: every channel, or the luminance.
    discard : float
        Each candidate block is dropped with this probability before the tolerance rule,
        the best one included, breaking repetition loops; decided per seed, block and
        candidate, the same on every backend; 0..0.99.
    blend : {'none', 'poisson'}
        'poisson' (the default): each cut's step is taken off within a few pixels of the cut
        by a screened Poisson solve over the block's cell (the gradients across the cut the
        mean of both sides'); see :mod:`quilting.core.blend`. 'none': the cut as it is, every
        output pixel a texture pixel.
    exclude_colors : sequence of (low, high)
        Colour ranges never to use, in the texture's own values: no block containing a
        pixel with every channel in [low, high] is chosen (the minimum-resistance-cut paper,
        §3.1).
    source_mask : ndarray, shape (h, w) or (h, w, K), optional
        Of the texture's size: black (0 in every channel) pixels are never used.
    tileable : {'both', 'x', 'y'}, optional
        Make the output repeat seamlessly along both axes, left-right or top-bottom: the
        grid wraps on a torus. A tileable side must be at least ``block``.
    max_run : int
        Walk mode: most pixels the walk cut runs straight in one row or column (>= 1).
    feather : int
        Walk mode: width of the blend across the cut in pixels (0 or 1: hard).
    seam_sampling : float
        Cut mode: a block within tolerance is drawn with probability
        ``exp(-seam_sampling E / median(E))``, E the cost of its minimum-error seam [3]_ (the
        median over the candidates). 0 (the default): uniform, the paper's rule [1]_. About 4
        favours the cheapest joins: fewer new patterns along the seams of structured
        textures, more verbatim repetition (see RESULTS.md, "Seam-cost sampling").
    histogram_weight : float
        Alpha mode: lambda per overlap pixel of the alpha-histogram term,
        ``lambda |overlap| (1 - rho)``, rho the Bhattacharyya coefficient with the texture's
        alpha histogram (100 bins).
    epsilon : float
        Alpha mode: candidates within ``(1 + epsilon) x`` the best error are kept (0.02).
    eta : float
        Alpha mode: a kept candidate is drawn with probability ``exp(-eta E)``, E its seam
        cost.
    max_batch : int, optional
        Most blocks per backend call; never changes the output. Default: the most whose
        temporaries fit the working memory (a quarter of ``budget.memory_bytes``, or 384 MiB).
    budget : Budget, optional
        Memory and time the job may take. Its cost is predicted from the shapes and options
        before any work (see :func:`quilting.core.budget.estimate_synthesis`); a job over
        budget raises :class:`~quilting.core.budget.JobTooLargeError` (code
        ``job_too_large``) saying what would fit. None (the default): no limit.

    Returns
    -------
    Result
        ``image`` (size, same channels and dtype as ``texture``), ``layout``, ``backend``,
        ``timings``, ``stats``.

    References
    ----------
    .. [1] A. A. Efros and W. T. Freeman, "Image Quilting for Texture Synthesis and Transfer",
           SIGGRAPH 2001, §2 (random, overlap and cut modes, the
           tolerance rule, overlap = block / 6).
    .. [2] The minimum-resistance-cut paper (random block quilting with a minimum-resistance
           cut line, for flight-simulator terrain), §2-3: ``mode='walk'``, ``exclude_colors``.
    .. [3] The alpha quilting and texture matting paper, §2.1: ``mode='alpha'``; its
           factored sampling (§2.1.3) is ``seam_sampling``'s, made relative.
    .. [4] A course write-up of image quilting ("Graphical Blues", an Advanced Graphics
           course): ``error='luminance'``, ``discard``.
    """
    options = SynthesisOptions(
        block=block,
        overlap=overlap,
        tolerance=tolerance,
        mode=mode,
        seed=seed,
        backend=backend if isinstance(backend, str) else backend.name,
        min_candidates=min_candidates,
        error=error,
        discard=discard,
        blend=blend,
        exclude_colors=exclude_colors,  # type: ignore[arg-type]  # normalized by the options
        tileable=tileable,
        max_run=max_run,
        feather=feather,
        seam_sampling=seam_sampling,
        histogram_weight=histogram_weight,
        epsilon=epsilon,
        eta=eta,
    )
    out_size = validate_size(size)
    view, fmt = as_channels(texture, "texture")
    check_block_fits(options, view.shape[0], view.shape[1])
    planned = estimate_synthesis(
        options,
        (view.shape[0], view.shape[1], view.shape[2]),
        out_size,
        backend=_backend_name(backend),
        itemsize=view.dtype.itemsize,
        max_batch=max_batch,
        budget=budget,
    )
    excluded = excluded_pixels(view, options.exclude_colors, source_mask)
    engine = get_backend(backend) if isinstance(backend, str) else backend
    return quilt(
        view,
        fmt,
        out_size,
        options,
        engine,
        progress=progress,
        max_batch=planned.batch,
        excluded=excluded,
    )


def _backend_name(backend: str | CostBackend) -> str:
    """The concrete backend a job runs on, as the cost model names it."""
    name = resolve_name(backend) if isinstance(backend, str) else backend.name
    return name if name in ("fft", "gl", "reference") else "fft"


def transfer(
    texture: object,
    target: object,
    *,
    block: int = 24,
    overlap: int | None = None,
    alpha: float | None = None,
    iterations: int = 2,
    min_block: int = 16,
    correspondence: Correspondence = "blurred",
    sigma: float = 2.0,
    remap: bool = True,
    shade: float = 1.5,
    source_map: NDArray[Any] | None = None,
    target_map: NDArray[Any] | None = None,
    tolerance: float = 0.1,
    mode: TransferMode = "cut",
    seed: int = 0,
    backend: str | CostBackend = "auto",
    progress: Progress | None = None,
    min_candidates: int = 3,
    error: ErrorKind = "rgb",
    discard: float = 0.0,
    blend: Blend = "poisson",
    exclude_colors: Sequence[tuple[Sequence[float], Sequence[float]]] = (),
    source_mask: NDArray[Any] | None = None,
    max_batch: int | None = None,
    budget: Budget | None = None,
) -> Result:
    """Render ``target`` in the texture of ``texture`` (Efros & Freeman 2001, §3).

    Each block is chosen by ``alpha x`` its overlap error with the blocks already placed
    plus ``(1 - alpha) x`` the difference between the texture's correspondence map under it
    and the target's at its place, both per pixel. With ``iterations`` N > 1 the image is
    synthesized N times, each pass over the previous one with blocks a third smaller (down to
    ``min_block``), also matching the previous pass's output, and alpha going from 0.1 to 0.5
    (the paper goes to 0.9; see :mod:`quilting.core.transfer`). A final shading (``shade``)
    then scales the output's coarse luminance towards the target's.

    Parameters
    ----------
    texture : ndarray, shape (h, w) or (h, w, C)
        The texture to render with; C in 1, 3, 4; uint8, uint16 or float.
    target : ndarray, shape (H, W) or (H, W, C')
        The image to render; any accepted channel count (its luminance is what matters).
    block : int
        Block side of the first pass, 3..min(h, w).
    overlap : int, optional
        Overlap of the first pass, < block / 2; default block // 6. Scaled with the block
        in later passes.
    alpha : float, optional
        Continuity against fidelity, in [0, 1]; default ``0.4 (i - 1) / (N - 1) + 0.1`` at
        pass i (0.5 for a single pass).
    iterations : int
        Number of passes N, 1..8.
    min_block : int
        Smallest block of any pass; the passes stop shrinking there (a smaller first
        ``block`` is kept).
    correspondence : {'blurred', 'luminance', 'orientation', 'custom'}
        The maps compared; 'blurred' (the default) is the Gaussian-blurred luminance. Giving
        ``source_map`` and ``target_map`` makes it 'custom'.
    sigma : float
        Blur of 'blurred' and averaging scale of 'orientation', in pixels.
    remap : bool
        Shift the target's luminance map to the texture's mean first (for 'luminance' and
        'blurred'), so a target brighter or darker than the texture keeps its shapes.
    shade : float
        Largest factor (1..4) by which the final shading brightens or darkens the output so
        that its luminance, coarser than a third of the last block, follows the target's
        map; 1 turns it off. Only for 'luminance' and 'blurred'. The layout does not record
        it: ``layout.render`` and :func:`apply_layout` give the unshaded quilt (companion
        maps such as normals are not shaded).
    source_map, target_map : ndarray, shapes (h, w[, K]) and (H, W[, K]), optional
        Your own correspondence maps over the texture and the target (same K, 1..4, and the
        same kind of values: uint8/uint16 scaled to [0, 1], floats as they are).
    tolerance, mode, seed, min_candidates, error, discard, blend, exclude_colors, source_mask,
    max_batch
        As in :func:`synthesize` (mode is 'cut' or 'overlap').
    backend : str or CostBackend
        ``'auto'``, ``'fft'``, ``'gl'``, ``'reference'``, or a backend instance.
    progress : callable, optional
        ``progress(fraction, stage)`` between levels, stage ``"pass i/N"``.

    Returns
    -------
    Result
        ``image`` of shape (H, W) or (H, W, C): the target's size, the texture's channels
        and dtype; ``layout`` with one pass per iteration; ``stats.correspondence_error``
        (of the quilt, before the shading).

    References
    ----------
    .. [1] A. A. Efros and W. T. Freeman, "Image Quilting for Texture Synthesis and Transfer",
           SIGGRAPH 2001, §3 (texture transfer, the
           correspondence map, iterative passes).
    """
    given = source_map is not None or target_map is not None
    # Left at its default (the signature cannot tell), the correspondence gives way to the maps.
    default = TransferOptions.__dataclass_fields__["correspondence"].default
    if given and correspondence not in (default, "custom"):
        raise InvalidParameterError(
            "correspondence",
            correspondence,
            "'custom' (or leave it out) when source_map and target_map are given",
            "your own maps replace the computed ones",
        )
    if given:
        correspondence = "custom"
    options = TransferOptions(
        block=block,
        overlap=overlap,
        alpha=alpha,
        iterations=iterations,
        min_block=min_block,
        correspondence=correspondence,
        sigma=sigma,
        remap=remap,
        shade=shade,
        tolerance=tolerance,
        mode=mode,
        seed=seed,
        backend=backend if isinstance(backend, str) else backend.name,
        min_candidates=min_candidates,
        error=error,
        discard=discard,
        blend=blend,
        exclude_colors=exclude_colors,  # type: ignore[arg-type]  # normalized by the options
    )
    view, fmt = as_channels(texture, "texture")
    excluded = excluded_pixels(view, options.exclude_colors, source_mask)
    target_view, _ = as_channels(target, "target")
    if options.correspondence == "custom" and (source_map is None or target_map is None):
        raise InvalidParameterError(
            "correspondence",
            "custom",
            "'luminance', 'blurred' or 'orientation' without maps",
            "'custom' needs both source_map and target_map",
        )
    check_block_fits(options, view.shape[0], view.shape[1])
    planned = estimate_transfer(
        options,
        (view.shape[0], view.shape[1], view.shape[2]),
        (target_view.shape[0], target_view.shape[1]),
        guide=guide_channels(options, source_map),
        backend=_backend_name(backend),
        itemsize=view.dtype.itemsize,
        max_batch=max_batch,
        budget=budget,
    )
    if source_map is not None and target_map is not None:  # the 'custom' correspondence
        source, wanted = custom_maps(source_map, target_map, view.shape[:2], target_view.shape[:2])
    else:
        source, wanted = computed_maps(to_working(view), to_working(target_view), options)
    engine = get_backend(backend) if isinstance(backend, str) else backend
    return transfer_quilt(
        view,
        fmt,
        source,
        wanted,
        options,
        engine,
        progress=progress,
        max_batch=planned.batch,
        excluded=excluded,
    )


def guide_channels(options: TransferOptions, custom: object | None = None) -> int:
    """Channels K of a transfer's correspondence maps: 1 for the luminance maps, 2 for
    orientation, the given map's (``custom``, (h, w) or (h, w, K)) for 'custom'."""
    if options.correspondence == "orientation":
        return 2
    shape: tuple[int, ...] = getattr(custom, "shape", ())
    return int(shape[2]) if len(shape) == 3 else 1


def make_tileable(
    image: object,
    *,
    axes: Tileable = "both",
    band: int | None = None,
    blend: TileBlend = "poisson",
    budget: Budget | None = None,
) -> Tiled:
    """Make an existing image repeat seamlessly, at the same size, keeping its centre.

    The image is kept inside four minimum-error cuts near its borders; outside them it is
    replaced by itself rolled by half its size, whose borders are neighbouring pixels of the
    original (see :mod:`quilting.core.seamless`). With ``blend="none"`` every output pixel is
    an input pixel; ``blend="poisson"`` then blends the cuts in the gradient domain (Perez,
    Gangnet & Blake 2003, §2-3), so that a brightness gradient across a photograph does not
    show as steps along them.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        C in 1, 3, 4; uint8, uint16 or float. Each tiled side at least 4 pixels.
    axes : {'both', 'x', 'y'}
        Which wraps must be seamless.
    band : int, optional
        Width of the border bands the cuts may wander in, 1..side // 2 - 1; default a
        quarter of each side, so the middle half is always kept (bit for bit with
        ``blend="none"``; blended, up to the correction's gentle ramp).
    blend : {'none', 'poisson'}
        'poisson' (the default): the
        gradients across the cuts replaced by the mean of both sides' own and the whole image
        solved for them (a plain Poisson equation, periodic along the tiled axes, by FFT and
        DCT): the steps are spread evenly over the period, the texture's detail, the mean
        brightness and an RGBA image's alpha are kept. Integers are rounded and clipped.
        'none': the cuts as they are, bit for bit the selection (``source_rows`` and
        ``source_cols`` then say exactly where every pixel came from).
    budget : Budget, optional
        Memory and time the call may take, checked from the image's shape before any work
        (:func:`quilting.core.budget.estimate_tile`: memory and time linear in the pixels,
        about 70 bytes a pixel for RGB, the blend's time added); over it raises
        :class:`~quilting.core.budget.JobTooLargeError` naming the largest image that fits.
        None (the default): no limit.

    Returns
    -------
    Tiled
        ``image`` (same shape and dtype), ``kept`` (H, W) bool: the pixels still the
        original's at their place, the cuts, ``seam_error``, and ``source_rows`` /
        ``source_cols`` (H, W): where each pixel came from. ``t.apply(companion, kind)``
        makes a companion map of the image's size tile the same way, blended as the image
        was ('blend', 'normal') or as the pure selection ('hard').

    References
    ----------
    .. [1] P. Perez, M. Gangnet and A. Blake, "Poisson Image Editing", SIGGRAPH 2003, §2-3.
    """
    options = TileOptions(axes=axes, band=band, blend=blend)
    if budget is not None:
        view, _ = as_channels(image, "image")
        estimate_tile(view.shape, itemsize=view.dtype.itemsize, budget=budget, blend=options.blend)
    return tile_image(image, axes=options.axes, band=options.band, blend=options.blend)


def matte(
    target: object,
    layers: Sequence[object],
    *,
    silhouette: object,
    light: tuple[float, float, float] | None = None,
    normals: object | None = None,
    clusters: int = 8,
    smoothing: float = 2.0,
    min_z: float = 0.1,
    spatial_weight: float = 1.0,
    scale: float = 1.0,
    ambient: float = 0.0,
    block: int = 48,
    overlap: int | None = None,
    tolerance: float = 0.1,
    mode: MatteMode = "auto",
    seed: int = 0,
    backend: str | CostBackend = "auto",
    progress: Progress | None = None,
    min_candidates: int = 3,
    error: ErrorKind = "rgb",
    discard: float = 0.0,
    blend: Blend = "poisson",
    exclude_colors: Sequence[tuple[Sequence[float], Sequence[float]]] = (),
    histogram_weight: float = 0.05,
    epsilon: float = 0.02,
    eta: float = 20.0,
    max_batch: int | None = None,
    budget: Budget | None = None,
) -> MatteResult:
    """Lay quilted textures on the surface of an object in an image (the alpha quilting and
    texture matting paper, §3).

    The surface under the silhouette is read from the target's shading (or from ``normals``),
    cut into patches by k-means on (nx, ny, nz, x, y), and each layer is quilted (tileable;
    an RGBA layer by alpha quilting) and laid on every patch turned and foreshortened by the
    patch's mean normal, shaded by ``n . S`` with the light estimated by least squares (or
    ``light``), and composited over the target by its alpha, first layer lowest.

    Parameters
    ----------
    target : ndarray, shape (H, W) or (H, W, C)
        The image with the object; C in 1, 3, 4; uint8, uint16 or float. The output has its
        size and dtype.
    layers : sequence of ndarray, each (h, w) or (h, w, C)
        The textures, bottom first: put opaque ones first and transparent (RGBA) ones over
        them, as the seed does. At least one.
    silhouette : ndarray, shape (H, W) or (H, W, C)
        White (or opaque) where the surface is, black (or transparent) elsewhere; grey is
        partial coverage. The surface is read where it is at least half.
    light : (x, y, z), optional
        Direction towards the light (x right, y up, z towards the viewer, z > 0); estimated
        from the target when None.
    normals : ndarray, shape (H, W, 3) or (H, W, 4), optional
        A normal map to use instead of shape from shading: uint8/uint16 as the usual colours
        ``(n + 1) / 2`` (+y up), floats as the components.
    clusters, smoothing, min_z, spatial_weight, scale, ambient
        See :class:`~quilting.core.options.MatteOptions`.
    block, overlap, tolerance, mode, seed, min_candidates, error, discard, blend,
    exclude_colors, histogram_weight, epsilon, eta, max_batch
        How each layer is quilted, as in :func:`synthesize` (``mode`` without 'walk'). Layer
        k is quilted with a seed derived from ``seed`` and k.
    backend : str or CostBackend
        ``'auto'``, ``'fft'``, ``'gl'``, ``'reference'``, or a backend instance.
    progress : callable, optional
        ``progress(fraction, stage)``, stage ``"layer k/N"`` while quilting, then
        ``"surface"``; raise from it to stop.

    Returns
    -------
    MatteResult
        ``image``, the ``normals``, ``clusters`` and ``patches`` used, the ``light``, each
        quilted layer and the timings.

    References
    ----------
    .. [1] The alpha quilting and texture matting paper, §3 (normals from shading under a
           silhouette, k-means patches on (n, x, y), shading by n . S, compositing layers).
    """
    options = MatteOptions(
        block=block,
        overlap=overlap,
        tolerance=tolerance,
        mode=mode,
        seed=seed,
        backend=backend if isinstance(backend, str) else backend.name,
        min_candidates=min_candidates,
        error=error,
        discard=discard,
        blend=blend,
        exclude_colors=exclude_colors,  # type: ignore[arg-type]  # normalized by the options
        histogram_weight=histogram_weight,
        epsilon=epsilon,
        eta=eta,
        clusters=clusters,
        light=light,
        smoothing=smoothing,
        min_z=min_z,
        spatial_weight=spatial_weight,
        scale=scale,
        ambient=ambient,
    )
    inputs = matte_inputs(options, target, layers, silhouette, normals)
    batch = estimate_matte(
        options,
        (inputs.target.shape[0], inputs.target.shape[1]),
        [(view.shape, view.dtype.itemsize) for view, _ in inputs.layers],
        inputs.layer_size,
        backend=_backend_name(backend),
        max_batch=max_batch,
        budget=budget,
    ).batch
    engine = get_backend(backend) if isinstance(backend, str) else backend
    return matte_quilt(inputs, options, engine, max_batch=batch, progress=progress)


def check_matte_inputs(
    options: MatteOptions,
    target: object,
    layers: Sequence[object],
    silhouette: object,
    normals: object | None = None,
) -> tuple[int, int]:
    """Refuse, before any work, what :func:`matte` would refuse: layers that do not fit the
    options, a silhouette or normal map not of the target's size, a silhouette that marks
    nothing.

    Parameters
    ----------
    options : MatteOptions
    target : ndarray, shape (H, W) or (H, W, C)
    layers : sequence of ndarray
    silhouette : ndarray, shape (H, W) or (H, W, C)
    normals : ndarray, shape (H, W, C), optional

    Returns
    -------
    (int, int)
        The (height, width) each layer will be quilted at.
    """
    return matte_inputs(options, target, layers, silhouette, normals).layer_size


def check_inputs(
    options: QuiltOptions,
    texture: object,
    source_mask: NDArray[Any] | None = None,
    size: tuple[int, int] | None = None,
) -> None:
    """Refuse, before any work, what :func:`synthesize` or :func:`transfer` would refuse once
    running: a block larger than the texture, exclusions that leave no whole block, a tileable
    side shorter than the block, alpha mode without alpha.

    Parameters
    ----------
    options : SynthesisOptions or TransferOptions
    texture : ndarray, shape (h, w) or (h, w, C)
    source_mask : ndarray, shape (h, w) or (h, w, K), optional
    size : (int, int), optional
        The output's (height, width).
    """
    view, _ = as_channels(texture, "texture")
    check_block_fits(options, view.shape[0], view.shape[1])
    options.resolved_mode(view.shape[2])  # alpha mode needs an RGBA texture
    if size is not None and isinstance(options, SynthesisOptions):
        synthesis_grid(options, validate_size(size))
    excluded = excluded_pixels(view, options.exclude_colors, source_mask)
    if excluded is not None:
        usable_candidates(excluded, options.block)  # the first, largest block of a transfer
