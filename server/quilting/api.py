"""The public entry points: validate at the edge, pick a backend, run the engine."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from quilting._keywords import option_keywords
from quilting.core.budget import (
    Budget,
    estimate_fill,
    estimate_synthesis,
    estimate_tile,
    estimate_transfer,
    estimate_wang,
)
from quilting.core.errors import InvalidImageError, InvalidParameterError
from quilting.core.exclusion import excluded_pixels, usable_candidates
from quilting.core.fields import CostBackend
from quilting.core.fill import Filled, fill_image, hole_box, hole_of
from quilting.core.kernels import warm_up as warm_kernels
from quilting.core.layout import Layout, apply_layout
from quilting.core.matte import estimate_matte, matte_inputs, matte_quilt
from quilting.core.matting import MatteResult
from quilting.core.options import (
    AlphaOptions,
    ExtendOptions,
    FillOptions,
    MatteOptions,
    QuiltOptions,
    SynthesisOptions,
    TileOptions,
    TransferOptions,
    WangOptions,
    validate_size,
)
from quilting.core.options import (
    DeclaredT as OptionsT,
)
from quilting.core.pixels import PixelFormat, as_channels, to_working
from quilting.core.progress import Progress
from quilting.core.seamless import Tiled
from quilting.core.seamless import make_tileable as tile_image
from quilting.core.seamless_fill import tile_by_filling
from quilting.core.sources import Examples, read_examples
from quilting.core.synthesis import Result, check_block_fits, quilt, synthesis_grid
from quilting.core.transfer import computed_maps, custom_maps, transfer_quilt
from quilting.core.trimap import Extracted
from quilting.core.wang import WangTiles, make_wang_tiles
from quilting.costs.registry import get_backend, resolve_name
from quilting.extract import extract_alpha
from quilting.extract import load as load_matting

__all__ = [
    "Filled",
    "Layout",
    "MatteResult",
    "Result",
    "Tiled",
    "WangTiles",
    "apply_layout",
    "check_inputs",
    "check_matte_inputs",
    "extend",
    "fill",
    "make_tileable",
    "matte",
    "synthesize",
    "transfer",
    "wang_tiles",
    "warm_up",
]


@option_keywords(SynthesisOptions)
def synthesize(
    texture: object,
    size: tuple[int, int],
    options: SynthesisOptions | None = None,
    *,
    progress: Progress | None = None,
    source_mask: NDArray[Any] | Sequence[NDArray[Any] | None] | None = None,
    trimap: object | None = None,
    scribbles: object | None = None,
    max_batch: int | None = None,
    budget: Budget | None = None,
    **overrides: Any,
) -> Result:
    """Synthesize a larger texture from a sample by image quilting.

    Parameters
    ----------
    texture : ndarray, shape (h, w) or (h, w, C), or a list of them
        The sample; C in 1, 3, 4; uint8, uint16 or float (taken as is, finite). A list gives
        several examples of one texture (one dtype and channel count, any sizes, each at
        least the block): candidates come from all of them and the best across them is
        chosen by the same rule (see ``weights`` to prefer some, ``transforms`` for their
        rotations and mirrors); the layout records each block's example.
    size : (int, int)
        Output (height, width), each >= 1. The covering grid of blocks is synthesized and
        cropped to exactly this size (a tileable side is synthesized at exactly its size).
    options : SynthesisOptions, optional
        Every option of the job (default: ``SynthesisOptions()``, the paper's); any of its
        fields given as a keyword (see Other Parameters) replaces the one in it. The options
        are validated once; a value out of range raises
        :class:`~quilting.core.errors.InvalidParameterError` naming the field.
    progress : callable, optional
        ``progress(fraction, stage)`` between wavefront levels; raise from it to stop.
    source_mask : ndarray, shape (h, w) or (h, w, K), or a list of them, optional
        Of the texture's size: black (0 in every channel) pixels are never used. With several
        examples, a list of one mask (or None) per example.
    trimap, scribbles : ndarray, shape (h, w) or (h, w, C), or a list of them, optional
        The texture is an ordinary photo (no alpha) and these say which of it is foreground:
        its alpha and foreground colour are extracted first (:func:`quilting.extract_alpha`
        with ``method=matting``), and the RGBA texture is quilted (``mode='auto'`` then means
        alpha quilting). With several examples, a list of one (or None, for an example that
        already has alpha) per example. The extraction is in ``Result.extracted``.
    max_batch : int, optional
        Most blocks per backend call; never changes the output. Default: the most whose
        temporaries fit the working memory (a quarter of ``budget.memory_bytes``, or 384 MiB).
    budget : Budget, optional
        Memory and time the job may take. Its cost is predicted from the shapes and options
        before any work (see :func:`quilting.core.budget.estimate_synthesis`); a job over
        budget raises :class:`~quilting.core.budget.JobTooLargeError` (code
        ``job_too_large``) saying what would fit. None (the default): no limit. Several
        examples and transforms cost as one texture of their atlas's area; an extraction is
        checked against it first, on its own.

    {option_keywords}

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
    options, given = _resolve(SynthesisOptions, options, overrides, "synthesize")
    out_size = validate_size(size)
    texture, extracted = with_alpha(
        texture, trimap, scribbles, options.matting, progress=progress, budget=budget
    )
    progress = _after_extraction(progress, extracted)
    examples = _examples(texture, options, source_mask)
    view = examples.view
    planned = estimate_synthesis(
        options,
        (view.shape[0], view.shape[1], view.shape[2]),
        out_size,
        backend=_backend_name(given or options.backend),
        itemsize=view.dtype.itemsize,
        max_batch=max_batch,
        budget=budget,
    )
    engine = given or get_backend(options.backend)
    result = quilt(
        view,
        examples.fmt,
        out_size,
        options,
        engine,
        progress=progress,
        max_batch=planned.batch,
        excluded=examples.excluded,
        sources=examples.sources,
        weights=examples.weights,
    )
    return _recorded(result, extracted)


def with_alpha(
    texture: object,
    trimap: object | None,
    scribbles: object | None,
    method: str,
    *,
    progress: Progress | None = None,
    budget: Budget | None = None,
) -> tuple[object, tuple[Extracted | None, ...]]:
    """The texture (or examples) to quilt: as given, or with the alpha extracted from each
    example that comes with a trimap or scribbles, and each example's extraction (None for
    one without; empty when there is none at all).

    Parameters
    ----------
    texture : ndarray or list of ndarray
        One photo or texture, or several examples.
    trimap, scribbles : ndarray or list of (ndarray or None), optional
        One each for one texture; a list of one (or None) per example for several.
    method : str
        The matting method (an :class:`AlphaOptions` ``method``).
    progress : callable, optional
        Told of the extractions as the first :data:`EXTRACT_SHARE` of the job, each its
        equal part of it, so that the job's fractions only grow.
    budget : Budget, optional
        Each extraction is checked against it.
    """
    if trimap is None and scribbles is None:
        return texture, ()
    several = isinstance(texture, (list, tuple))
    examples = list(texture) if several else [texture]  # type: ignore[call-overload]
    trimaps = _per_example("trimap", trimap, len(examples), several)
    strokes = _per_example("scribbles", scribbles, len(examples), several)
    options = AlphaOptions(method=method)  # type: ignore[arg-type]  # validated as the field
    done: list[Extracted | None] = []
    for k, (example, marks, lines) in enumerate(zip(examples, trimaps, strokes, strict=True)):
        if marks is None and lines is None:
            done.append(None)
            continue
        told = _share(progress, EXTRACT_SHARE * k / len(examples), EXTRACT_SHARE / len(examples))
        found = extract_alpha(example, marks, lines, options, progress=told, budget=budget)
        examples[k] = found.image
        done.append(found)
    return (examples if several else examples[0]), tuple(done)


#: The share of a job's progress its alpha extractions take (they come first; the quilting
#: takes the rest): how long each takes depends on the photo, so this is only a split.
EXTRACT_SHARE = 0.5


def _share(progress: Progress | None, start: float, width: float) -> Progress | None:
    """``progress`` told of a part of a job as the span ``[start, start + width]``."""
    if progress is None:
        return None
    told = progress

    def scaled(fraction: float, stage: str) -> None:
        told(start + width * fraction, stage)

    return scaled


def _after_extraction(
    progress: Progress | None, extracted: Sequence[Extracted | None]
) -> Progress | None:
    """``progress`` for the quilting that follows a job's extractions (the rest of its span
    after :data:`EXTRACT_SHARE`), or as it is when nothing was extracted."""
    if not any(found is not None for found in extracted):
        return progress
    return _share(progress, EXTRACT_SHARE, 1 - EXTRACT_SHARE)


def _per_example(name: str, given: object | None, count: int, several: bool) -> list[Any]:
    """One map (or None) per example from what the caller gave."""
    if given is None:
        return [None] * count
    if not several:
        if isinstance(given, (list, tuple)):
            raise InvalidImageError(f"one texture takes one {name} image, not a list")
        return [given]
    if not isinstance(given, (list, tuple)) or len(given) != count:
        raise InvalidImageError(
            f"with {count} examples, {name} is a list of {count} images (None for an example "
            "that already has alpha)"
        )
    return list(given)


def _recorded(result: Result, found: Sequence[Extracted | None]) -> Result:
    """``result`` with the extractions that came before it (their time in its timings)."""
    extracted = tuple(f for f in found if f is not None)
    if not extracted:
        return result
    seconds = sum(found.timings.get("total", 0.0) for found in extracted)
    timings = {**result.timings, "extract": seconds}
    timings["total"] = result.timings.get("total", 0.0) + seconds
    return replace(result, extracted=extracted, timings=timings)


def _examples(texture: object, options: SynthesisOptions, source_mask: object) -> Examples:
    """The job's examples, validated and laid out (:func:`quilting.core.sources.read_examples`)."""
    return read_examples(
        texture,
        block=options.block,
        transforms=options.transforms,
        weights=options.weights,
        exclude_colors=options.exclude_colors,
        source_mask=source_mask,
        walk=options.mode == "walk",
    )


def _resolve(
    kind: type[OptionsT], options: OptionsT | None, overrides: dict[str, Any], caller: str
) -> tuple[OptionsT, CostBackend | None]:
    """The call's options (``options`` with the keyword overrides in, validated once) and the
    backend object when ``backend`` was given as one rather than by name."""
    backend = overrides.get("backend")
    if backend is None or isinstance(backend, str):
        return kind.resolve(options, overrides, caller=caller), None
    named = {**overrides, "backend": backend.name}
    return kind.resolve(options, named, caller=caller), backend


def _backend_name(backend: str | CostBackend) -> str:
    """The concrete backend a job runs on, as the cost model names it."""
    name = resolve_name(backend) if isinstance(backend, str) else backend.name
    return name if name in ("fft", "gl", "reference") else "fft"


@option_keywords(TransferOptions)
def transfer(
    texture: object,
    target: object,
    options: TransferOptions | None = None,
    *,
    source_map: NDArray[Any] | None = None,
    target_map: NDArray[Any] | None = None,
    progress: Progress | None = None,
    source_mask: NDArray[Any] | None = None,
    max_batch: int | None = None,
    budget: Budget | None = None,
    **overrides: Any,
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
    options : TransferOptions, optional
        Every option of the transfer (default: ``TransferOptions()``); any of its fields given
        as a keyword (see Other Parameters) replaces the one in it.
    source_map, target_map : ndarray, shapes (h, w[, K]) and (H, W[, K]), optional
        Your own correspondence maps over the texture and the target (same K, 1..4, and the
        same kind of values: uint8/uint16 scaled to [0, 1], floats as they are). Giving them
        makes the correspondence 'custom' (any other named correspondence is refused).
    progress : callable, optional
        ``progress(fraction, stage)`` between levels, stage ``"pass i/N"``.
    source_mask, max_batch, budget
        As in :func:`synthesize`.

    {option_keywords}

    Returns
    -------
    Result
        ``image`` of shape (H, W) or (H, W, C): the target's size, the texture's channels
        and dtype; ``layout`` with one pass per iteration; ``stats.correspondence_error``
        (of the quilt, before the shading).

    Notes
    -----
    The layout does not record the final shading: ``layout.render`` and
    :func:`apply_layout` give the unshaded quilt (companion maps such as normals are not
    shaded).

    References
    ----------
    .. [1] A. A. Efros and W. T. Freeman, "Image Quilting for Texture Synthesis and Transfer",
           SIGGRAPH 2001, §3 (texture transfer, the
           correspondence map, iterative passes).
    """
    options, given = _resolve(TransferOptions, options, overrides, "transfer")
    if source_map is not None or target_map is not None:
        # Left at its default, the correspondence gives way to the caller's maps.
        default = TransferOptions.__dataclass_fields__["correspondence"].default
        if options.correspondence not in (default, "custom"):
            raise InvalidParameterError(
                "correspondence",
                options.correspondence,
                "'custom' (or leave it out) when source_map and target_map are given",
                "your own maps replace the computed ones",
            )
        options = replace(options, correspondence="custom")
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
        backend=_backend_name(given or options.backend),
        itemsize=view.dtype.itemsize,
        max_batch=max_batch,
        budget=budget,
    )
    if source_map is not None and target_map is not None:  # the 'custom' correspondence
        source, wanted = custom_maps(source_map, target_map, view.shape[:2], target_view.shape[:2])
    else:
        source, wanted = computed_maps(to_working(view), to_working(target_view), options)
    engine = given or get_backend(options.backend)
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


@option_keywords(WangOptions)
def wang_tiles(
    texture: object,
    options: WangOptions | None = None,
    *,
    progress: Progress | None = None,
    max_batch: int | None = None,
    budget: Budget | None = None,
    **overrides: Any,
) -> WangTiles:
    """A complete set of Wang tiles quilted from a texture (Cohen et al. 2003).

    Each edge of a tile carries one of ``colors`` colours; the set has a tile for every
    combination (``colors``^4 tiles), and two tiles whose touching edges share a colour meet
    seamlessly, pixel for pixel. :meth:`WangTiles.arrange` lays out an aperiodic arrangement
    of any size for a seed (a game engine can do the same at run time from the manifest),
    :meth:`WangTiles.render` its image, :meth:`WangTiles.atlas` and
    :meth:`WangTiles.manifest` the set as one image and its edge colours, and
    :meth:`WangTiles.apply` the same tiles of a companion map.

    Parameters
    ----------
    texture : ndarray, shape (h, w) or (h, w, C), or a list of them
        The example(s), as :func:`synthesize` takes them.
    options : WangOptions, optional
        Every option (default ``WangOptions()``); any field given as a keyword replaces it.
    progress : callable, optional
        ``progress(fraction, stage)``: the quilting of the material, then the tiles.
    max_batch : int, optional
        Most blocks per backend call; never changes the output.
    budget : Budget, optional
        Memory and time the job may take (:func:`quilting.core.budget.estimate_wang`).

    {option_keywords}

    Returns
    -------
    WangTiles

    References
    ----------
    .. [1] M. F. Cohen, J. Shade, S. Hiller and O. Deussen, "Wang Tiles for Image and Texture
           Generation", SIGGRAPH 2003, §3.
    """
    options, given = _resolve(WangOptions, options, overrides, "wang_tiles")
    synthesis = options.synthesis()
    examples = _examples(texture, synthesis, None)
    view = examples.view
    planned = estimate_wang(
        options,
        view.shape,
        backend=_backend_name(given or options.backend),
        itemsize=view.dtype.itemsize,
        max_batch=max_batch,
        budget=budget,
    )
    engine = given or get_backend(options.backend)
    return make_wang_tiles(examples, options, engine, progress=progress, max_batch=planned.batch)


@option_keywords(TileOptions)
def make_tileable(
    image: object,
    options: TileOptions | None = None,
    *,
    progress: Progress | None = None,
    budget: Budget | None = None,
    **overrides: Any,
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
    options : TileOptions, optional
        Which axes, how wide the bands the cuts wander in, how the cuts are blended (default:
        ``TileOptions()``: both axes, a quarter of each side, blended); any of its fields
        given as a keyword (see Other Parameters) replaces the one in it. With
        ``blend="none"`` the middle half is kept bit for bit and ``source_rows`` /
        ``source_cols`` say exactly where every pixel came from. ``method="fill"``
        synthesizes the bands across the wraps again instead of cutting
        (:mod:`quilting.core.seamless_fill`).
    progress : callable, optional
        ``method="fill"`` only: ``progress(fraction, "fill")`` after each batch of blocks.
    budget : Budget, optional
        Memory and time the call may take, checked from the image's shape before any work
        (:func:`quilting.core.budget.estimate_tile`: for the cuts memory and time linear in
        the pixels, about 70 bytes a pixel for RGB, the blend's time added; for
        ``method="fill"`` a fill's estimate); over it raises
        :class:`~quilting.core.budget.JobTooLargeError` naming the largest image that fits.
        None (the default): no limit.

    {option_keywords}

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
    options = TileOptions.resolve(options, overrides, caller="make_tileable")
    view, fmt = as_channels(image, "image")
    if budget is not None:
        estimate_tile(
            view.shape,
            itemsize=view.dtype.itemsize,
            budget=budget,
            blend=options.blend,
            method=options.method,
            backend=_backend_name("auto"),
        )
    if options.method == "fill":
        return tile_by_filling(view, fmt, options, get_backend("auto"), progress=progress)
    return tile_image(image, axes=options.axes, band=options.band, blend=options.blend)


@option_keywords(FillOptions)
def fill(
    image: object,
    mask: object,
    options: FillOptions | None = None,
    *,
    texture: object | None = None,
    progress: Progress | None = None,
    max_batch: int | None = None,
    budget: Budget | None = None,
    **overrides: Any,
) -> Filled:
    """Fill the pixels of ``image`` that ``mask`` marks (remove a stain, a logo, a cable) by
    image quilting; every other pixel is returned unchanged, byte for byte.

    The hole is covered by overlapping blocks, placed from its border inward. Each is chosen
    among the blocks of the image that lie wholly outside the hole (or of ``texture``) by its
    error over every known pixel under it, within ``tolerance`` of the best as synthesis
    chooses, and joined to what is known along a minimum cut that never moves a known pixel;
    see :mod:`quilting.core.fill`.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        C in 1, 3, 4; uint8, uint16 or float.
    mask : ndarray, shape (H, W) or (H, W, K)
        The image's size: True, or any colour channel above 0 (white), marks a pixel to fill;
        with K = 2 or 4 a pixel of alpha 0 is kept. An empty mask returns the image as it is.
    options : FillOptions, optional
        Every option of the fill (default: ``FillOptions()``); any of its fields given as a
        keyword (see Other Parameters) replaces the one in it.
    texture : ndarray, shape (h, w) or (h, w, C), optional
        Take the blocks from this texture instead of the image (its channels and dtype must
        be the image's). Needed when the mask covers the whole image.
    progress : callable, optional
        ``progress(fraction, "fill")`` after each batch of blocks; raise from it to stop.
    max_batch : int, optional
        Most blocks per backend call; never changes the output.
    budget : Budget, optional
        Memory and time the fill may take, checked before any work
        (:func:`quilting.core.budget.estimate_fill`); over it raises
        :class:`~quilting.core.budget.JobTooLargeError`. None (the default): no limit.

    {option_keywords}

    Returns
    -------
    Filled
        ``image`` (same shape and dtype), ``filled`` (the hole), where every filled pixel came
        from (``source_rows``, ``source_cols``), and ``apply(companion)`` to fill a companion
        map (normals, roughness) the same way.

    Raises
    ------
    InvalidImageError
        A mask of another size or shape; a mask covering the whole image without a texture.
    InvalidParameterError
        A block larger than the image, or than every part of it outside the hole (the message
        names the largest block that fits).

    References
    ----------
    .. [1] A. A. Efros and W. T. Freeman, "Image Quilting for Texture Synthesis and Transfer",
           SIGGRAPH 2001, §2.2.
    .. [2] V. Kwatra, A. Schoedl, I. Essa, G. Turk and A. Bobick, "Graphcut Textures: Image
           and Video Synthesis Using Graph Cuts", SIGGRAPH 2003, §3.
    """
    options, given = _resolve(FillOptions, options, overrides, "fill")
    view, fmt = as_channels(image, "image")
    hole = hole_of(mask, view.shape[:2])
    source = None
    if texture is not None:
        source, _ = as_channels(texture, "texture")
        if source.shape[2] != view.shape[2] or source.dtype != view.dtype:
            raise InvalidImageError(
                f"the texture ({source.shape[2]} channels, {source.dtype}) must have the "
                f"image's channels and dtype ({view.shape[2]}, {view.dtype})"
            )
    return _filled(view, fmt, hole, options, given, source, None, progress, max_batch, budget)


@option_keywords(ExtendOptions)
def extend(
    image: object,
    options: ExtendOptions | None = None,
    *,
    progress: Progress | None = None,
    max_batch: int | None = None,
    budget: Budget | None = None,
    **overrides: Any,
) -> Filled:
    """Grow ``image`` past its borders (uncrop): a larger canvas with the image placed
    unchanged and the rest synthesized from the image by :func:`fill`.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        C in 1, 3, 4; uint8, uint16 or float.
    options : ExtendOptions, optional
        ``top``, ``bottom``, ``left``, ``right``: pixels added on each side, and the fill's
        options; any of its fields given as a keyword replaces the one in it.
    progress, max_batch, budget
        As for :func:`fill`.

    {option_keywords}

    Returns
    -------
    Filled
        ``image``: shape (H + top + bottom, W + left + right[, C]), the input at
        ``[top:top + H, left:left + W]`` byte for byte; ``filled``: the added pixels;
        ``source_rows`` / ``source_cols``: the input pixel every output pixel came from;
        ``apply(companion)`` extends a companion map of the input's size the same way.
    """
    options, given = _resolve(ExtendOptions, options, overrides, "extend")
    view, fmt = as_channels(image, "image")
    height, width, channels = view.shape
    size = validate_size(
        (height + options.top + options.bottom, width + options.left + options.right)
    )
    placed = np.s_[options.top : options.top + height, options.left : options.left + width]
    canvas = np.zeros((*size, channels), dtype=view.dtype)
    canvas[placed] = view
    hole = np.ones(size, dtype=bool)
    hole[placed] = False
    corner = (options.top, options.left)
    return _filled(canvas, fmt, hole, options, given, view, corner, progress, max_batch, budget)


def _filled(
    view: NDArray[Any],
    fmt: PixelFormat,
    hole: NDArray[np.bool_],
    options: FillOptions,
    given: CostBackend | None,
    texture: NDArray[Any] | None,
    placed: tuple[int, int] | None,
    progress: Progress | None,
    max_batch: int | None,
    budget: Budget | None,
) -> Filled:
    """A fill's or an extension's run: its cost checked against ``budget`` before any work
    (the batch it plans), then the engine (:func:`quilting.core.fill.fill_image`)."""
    planned = estimate_fill(
        options,
        view.shape,
        hole_box(hole),
        texture=None if texture is None else (texture.shape[0], texture.shape[1]),
        backend=_backend_name(given or options.backend),
        itemsize=view.dtype.itemsize,
        max_batch=max_batch,
        budget=budget,
    )
    return fill_image(
        view,
        fmt,
        hole,
        options,
        given or get_backend(options.backend),
        texture=texture,
        placed=placed,
        progress=progress,
        max_batch=planned.batch,
    )


@option_keywords(MatteOptions)
def matte(
    target: object,
    layers: Sequence[object],
    options: MatteOptions | None = None,
    *,
    silhouette: object,
    normals: object | None = None,
    trimap: Sequence[object | None] | None = None,
    scribbles: Sequence[object | None] | None = None,
    progress: Progress | None = None,
    max_batch: int | None = None,
    budget: Budget | None = None,
    **overrides: Any,
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
    normals : ndarray, shape (H, W, 3) or (H, W, 4), optional
        A normal map to use instead of shape from shading: uint8/uint16 as the usual colours
        ``(n + 1) / 2`` (+y up), floats as the components.
    trimap, scribbles : list of (ndarray or None), optional
        One per layer: a layer given as an ordinary photo with a trimap or scribbles has its
        alpha and foreground colour extracted first (:func:`quilting.extract_alpha`, method
        ``matting``), and is then quilted by alpha quilting; None for a layer taken as it is.
        Each layer's extraction is in its ``Result.extracted``.
    options : MatteOptions, optional
        How the surface is read and each layer quilted (default: ``MatteOptions()``); any of
        its fields given as a keyword (see Other Parameters) replaces the one in it. Each
        layer is quilted as by :func:`synthesize` (``mode`` without 'walk'), layer k with a
        seed derived from ``seed`` and k.
    progress : callable, optional
        ``progress(fraction, stage)``, stage ``"layer k/N"`` while quilting, then
        ``"surface"``; raise from it to stop.
    max_batch, budget
        As in :func:`synthesize`.

    {option_keywords}

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
    options, given = _resolve(MatteOptions, options, overrides, "matte")
    if not isinstance(layers, (list, tuple)):
        raise InvalidImageError("layers is a list of textures, bottom first")
    given_layers, extracted = with_alpha(
        list(layers), trimap, scribbles, options.matting, progress=progress, budget=budget
    )
    progress = _after_extraction(progress, extracted)
    inputs = matte_inputs(options, target, cast(list[object], given_layers), silhouette, normals)
    batch = estimate_matte(
        options,
        (inputs.target.shape[0], inputs.target.shape[1]),
        [(view.shape, view.dtype.itemsize) for view, _ in inputs.layers],
        inputs.layer_size,
        backend=_backend_name(given or options.backend),
        max_batch=max_batch,
        budget=budget,
    ).batch
    engine = given or get_backend(options.backend)
    found = matte_quilt(inputs, options, engine, max_batch=batch, progress=progress)
    if not extracted:
        return found
    layers_made = [
        _recorded(layer, [extraction])
        for layer, extraction in zip(found.layers, extracted, strict=True)
    ]
    return replace(found, layers=layers_made)


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
    options: QuiltOptions | WangOptions,
    texture: object,
    source_mask: NDArray[Any] | Sequence[NDArray[Any] | None] | None = None,
    size: tuple[int, int] | None = None,
) -> None:
    """Refuse, before any work, what :func:`synthesize`, :func:`transfer` or
    :func:`wang_tiles` would refuse once running: a block larger than a texture, examples of
    different kinds, weights that are not one per example, exclusions that leave no whole
    block, a tileable side shorter than the block, alpha mode without alpha.

    Parameters
    ----------
    options : SynthesisOptions, TransferOptions or WangOptions
    texture : ndarray, shape (h, w) or (h, w, C), or a list of them
        A list (several examples) for synthesis and Wang tiles only.
    source_mask : ndarray, shape (h, w) or (h, w, K), or a list of them, optional
    size : (int, int), optional
        The output's (height, width).
    """
    if isinstance(options, WangOptions):
        options = options.synthesis()
    if isinstance(options, SynthesisOptions):
        examples = _examples(texture, options, source_mask)
        options.resolved_mode(examples.view.shape[2])  # alpha mode needs an RGBA texture
        if size is not None:
            synthesis_grid(options, validate_size(size))
        if examples.excluded is not None:
            usable_candidates(examples.excluded, options.block)
        return
    if source_mask is not None and not isinstance(source_mask, np.ndarray):
        raise InvalidImageError("a transfer takes one texture and one source_mask image")
    view, _ = as_channels(texture, "texture")
    check_block_fits(options, view.shape[0], view.shape[1])
    options.resolved_mode(view.shape[2])  # alpha mode needs an RGBA texture
    excluded = excluded_pixels(view, options.exclude_colors, source_mask)
    if excluded is not None:
        usable_candidates(excluded, options.block)  # the first, largest block of a transfer


def warm_up() -> None:
    """Load everything a job would otherwise pay for on its first call: every numba kernel
    compiled or read from its cache (a few seconds the first time on a machine, about 0.2 s
    after), and the matting library when the ``matting`` extra is installed (its first
    import compiles its solvers, about 20 s once per installation, under a second after).
    The service's workers and sandbox call it at start."""
    warm_kernels()
    load_matting()
