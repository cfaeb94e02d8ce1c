"""Texture transfer (Efros & Freeman 2001, §3): correspondence maps and the pass schedule.

A target image is rendered in the texture of another. Each block is chosen for its fit with
the blocks already placed (continuity) and for how well the texture's correspondence map
under it matches the target's at that place (fidelity), weighted by alpha. Iterative
transfer runs N passes, each over the previous one, with blocks a third smaller every pass
(down to a smallest block) and alpha rising from 0.1: the first pass lays out where
everything goes, the later ones make the pieces fit (and also match what the previous pass
put under the block). A final shading (:func:`shade_towards`) then scales the output's
luminance, at scales coarser than the blocks' detail, towards the target's.

The paper's schedule raises alpha to 0.9 in the last pass. Measured on its kind of example
(gravel onto the 256² cameraman, wood onto a cat; ``benchmarks/bench_quality.py --transfer``)
that last pass copies the previous one and gives back little fidelity: the defaults stop at
0.5, compare blurred luminance (the grain of a texture such as gravel then does not count
against it, so smooth blocks are not preferred and the output stays as crisp as a plain
synthesis), and stop shrinking the blocks at 16 px (11 px blocks showed as a lattice in flat
bright areas and cost the most).

Correspondence maps are (H, W, K) float32 arrays. Luminance and blurred luminance have K = 1.
Orientation has K = 2: the gradient orientation theta (an axis, defined modulo pi) is stored
as ``c * (cos 2 theta, sin 2 theta) / sqrt 2`` with c the coherence in [0, 1], so that the
squared distance between two pixels' maps, averaged over K, is ``sin^2`` of the angle between
their orientations (for fully coherent pixels): angles wrap around, 1 degree and 179 degrees
are 2 degrees apart, and flat regions (c ~ 0) carry no direction.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from quilting.core.errors import InvalidImageError, InvalidParameterError
from quilting.core.fields import CostBackend
from quilting.core.grid import Grid
from quilting.core.layout import Layout
from quilting.core.options import TransferOptions
from quilting.core.pixels import (
    PixelFormat,
    check_float_range,
    luminance,
    rendered,
    to_working,
)
from quilting.core.progress import Clock, Progress
from quilting.core.synthesis import (
    Guidance,
    QuiltPass,
    Result,
    check_block_fits,
    finish,
)

#: Gradient energy (per pixel, intensities in [0, 1]) below which an orientation fades out: a
#: gradient of 0.01 per pixel has coherence-weighted strength 1/2.
ORIENTATION_FLOOR = 1e-4
#: What a custom correspondence map may be made of.
MAP_DTYPES = ("uint8", "uint16", "float16", "float32", "float64")
#: Most channels of a correspondence map (what every backend, the GPU's included, takes).
MAX_MAP_CHANNELS = 4
#: Alpha of a single pass when none is given.
SINGLE_PASS_ALPHA = 0.5
#: Alpha of the first and of the last pass of an iterative transfer when none is given
#: (Efros & Freeman 2001, §3 go from 0.1 to 0.9; see the module docstring for why 0.5).
FIRST_ALPHA = 0.1
LAST_ALPHA = 0.5
#: Gaussian sigma of the shading, as a share of the last pass's block: the shading changes
#: brightness at scales coarser than this and leaves the texture's finer detail alone.
SHADE_SCALE = 1 / 3
#: Luminance below which the shading's ratio is taken at this value (no division by ~0).
SHADE_FLOOR = 0.02


def blurred_luminance(image: NDArray[np.float32], sigma: float) -> NDArray[np.float32]:
    """Gaussian-blurred luminance (edges reflected), shape (H, W), float32."""
    blurred: NDArray[np.float32] = ndimage.gaussian_filter(
        luminance(image), sigma, mode="reflect"
    ).astype(np.float32)
    return blurred


def _structure_tensor(
    image: NDArray[np.float32], sigma: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Gaussian-averaged ``(gx^2, gx gy, gy^2)`` of the luminance, each (H, W)."""
    luma = luminance(image).astype(np.float64)
    # Sobel / 8: the derivative per pixel of a linear ramp, exactly.
    gx = ndimage.sobel(luma, axis=1, mode="reflect") / 8
    gy = ndimage.sobel(luma, axis=0, mode="reflect") / 8
    products = (gx * gx, gx * gy, gy * gy)
    smooth = [ndimage.gaussian_filter(g, sigma, mode="reflect") for g in products]
    return smooth[0], smooth[1], smooth[2]


def orientation_angle(
    image: NDArray[np.float32], sigma: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Local gradient orientation and its coherence, from the structure tensor.

    Averaging gradients as doubled angles (the tensor) treats a gradient and its opposite as
    the same orientation, so opposite edges reinforce instead of cancelling.

    Parameters
    ----------
    image : ndarray, shape (H, W, C), float32
    sigma : float
        Gaussian scale of the averaging, in pixels.

    Returns
    -------
    angle : ndarray, shape (H, W), float64
        Orientation of the dominant gradient in [0, pi), measured from the +x axis (columns)
        towards +y (rows, downwards).
    coherence : ndarray, shape (H, W), float64
        ``(l1 - l2) / (l1 + l2 + floor)`` of the tensor's eigenvalues, in [0, 1): 1 on a
        clean straight gradient, 0 where the image is flat or isotropic.
    """
    jxx, jxy, jyy = _structure_tensor(image, sigma)
    angle = 0.5 * np.arctan2(2 * jxy, jxx - jyy)
    coherence = np.hypot(jxx - jyy, 2 * jxy) / (jxx + jyy + ORIENTATION_FLOOR)
    return np.mod(angle, np.pi), coherence


def orientation_map(image: NDArray[np.float32], sigma: float) -> NDArray[np.float32]:
    """The orientation correspondence map (see the module docstring), shape (H, W, 2)."""
    jxx, jxy, jyy = _structure_tensor(image, sigma)
    # c (cos 2t, sin 2t) = (jxx - jyy, 2 jxy) / (trace + floor): no trigonometry needed.
    scale = 1 / ((jxx + jyy + ORIENTATION_FLOOR) * np.sqrt(2))
    return np.stack([(jxx - jyy) * scale, 2 * jxy * scale], axis=-1).astype(np.float32)


def correspondence_map(image: NDArray[np.float32], kind: str, sigma: float) -> NDArray[np.float32]:
    """The correspondence map of a working image.

    Parameters
    ----------
    image : ndarray, shape (H, W, C), float32
    kind : {'luminance', 'blurred', 'orientation'}
    sigma : float
        Scale of 'blurred' and 'orientation'.

    Returns
    -------
    ndarray, shape (H, W, K), float32
        K = 2 for 'orientation', else 1.
    """
    if kind == "luminance":
        return luminance(image)[..., None]
    if kind == "blurred":
        return blurred_luminance(image, sigma)[..., None]
    if kind == "orientation":
        return orientation_map(image, sigma)
    raise InvalidParameterError(
        "correspondence", kind, "'luminance', 'blurred', 'orientation', or maps given"
    )


def remap_to(target: NDArray[np.float32], source: NDArray[np.float32]) -> NDArray[np.float32]:
    """``target`` shifted per channel so that its mean is ``source``'s.

    Only the mean moves. Scaling the spread to the texture's as well (Hertzmann et al.'s
    luminance remapping) was tried: a grainy texture such as gravel has a large pixel spread
    but blocks of nearly equal mean, so the target lost the contrast its shapes are drawn with.

    Parameters
    ----------
    target : ndarray, shape (H, W, K), float32
    source : ndarray, shape (h, w, K), float32

    Returns
    -------
    ndarray, shape (H, W, K), float32
    """
    shift = source.mean(axis=(0, 1), dtype=np.float64) - target.mean(axis=(0, 1), dtype=np.float64)
    remapped: NDArray[np.float32] = (target + shift).astype(np.float32)
    return remapped


def shade_towards(
    canvas: NDArray[np.float32], wanted: NDArray[np.float32], factor: float, sigma: float
) -> None:
    """Scale ``canvas``'s colour so that its coarse luminance follows ``wanted``, in place.

    Each pixel's colour channels (not alpha) are multiplied by
    ``G(wanted) / G(luminance(canvas))``, both Gaussian-blurred by ``sigma`` (edges
    reflected) and floored at :data:`SHADE_FLOOR`, the ratio clipped to
    ``[1 / factor, factor]``; the result is clipped to [0, 1]. The ratio is smooth at the scale
    ``sigma``, so the texture's finer detail (grain, edges of pebbles) is kept, only
    brightened or darkened: quilting places the texture's features where the target's shapes
    are; the shading makes up the brightness the texture's blocks do not reach (a gravel has
    no block as bright as a sky). The clip keeps it a correction: with ``factor`` 1.5 a
    region loses at most a third of its brightness or gains at most a half.

    Parameters
    ----------
    canvas : ndarray, shape (H, W, C), float32, C in 1, 3, 4; overwritten
        The output in working format.
    wanted : ndarray, shape (H, W, 1), float32
        The target's luminance (or blurred luminance) map, remapped as the passes saw it.
    factor : float
        Largest brightening (and 1 / smallest darkening), >= 1.
    sigma : float
        Gaussian sigma in pixels of the scales the shading changes.
    """
    colours = 3 if canvas.shape[2] >= 3 else 1
    floor = np.float32(SHADE_FLOOR)
    # float32 planes, in place: the shading's extra memory is a few (H, W) planes, less than
    # a pass's own temporaries at the same size (core/budget.py counts those).
    have = ndimage.gaussian_filter(luminance(canvas), sigma, mode="reflect")
    gain = ndimage.gaussian_filter(
        np.ascontiguousarray(wanted[..., 0], dtype=np.float32), sigma, mode="reflect"
    )
    np.maximum(gain, floor, out=gain)
    np.maximum(have, floor, out=have)
    np.divide(gain, have, out=gain)
    del have
    np.clip(gain, np.float32(1 / factor), np.float32(factor), out=gain)
    for channel in range(colours):
        plane = canvas[..., channel]
        np.multiply(plane, gain, out=plane)
        np.clip(plane, np.float32(0), np.float32(1), out=plane)


def computed_maps(
    texture: NDArray[np.float32], target: NDArray[np.float32], options: TransferOptions
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """The correspondence maps ``options`` asks for, of a working texture and target.

    Parameters
    ----------
    texture : ndarray, shape (h, w, C), float32
    target : ndarray, shape (H, W, C'), float32
    options : TransferOptions
        ``correspondence`` (not 'custom'), ``sigma`` and ``remap``.

    Returns
    -------
    source, wanted : ndarray, shapes (h, w, K) and (H, W, K), float32
    """
    source = correspondence_map(texture, options.correspondence, options.sigma)
    wanted = correspondence_map(target, options.correspondence, options.sigma)
    if options.remap and options.correspondence in ("luminance", "blurred"):
        wanted = remap_to(wanted, source)
    return source, wanted


def custom_maps(
    source_map: NDArray[np.generic],
    target_map: NDArray[np.generic],
    texture_shape: tuple[int, int],
    target_shape: tuple[int, int],
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Validate maps given by the caller and bring them to the working format.

    Parameters
    ----------
    source_map : ndarray, shape (h, w) or (h, w, K)
        Over the texture; uint8/uint16 are scaled to [0, 1], floats taken as they are.
    target_map : ndarray, shape (H, W) or (H, W, K)
        Over the target, the same K and dtype kind.
    texture_shape, target_shape : (int, int)
        (height, width) the maps must have.

    Returns
    -------
    source, target : ndarray, shapes (h, w, K) and (H, W, K), float32
    """
    maps = []
    for name, array, shape in (
        ("source_map", source_map, texture_shape),
        ("target_map", target_map, target_shape),
    ):
        if not isinstance(array, np.ndarray) or array.ndim not in (2, 3):
            raise InvalidImageError(f"{name} must be an array of shape (H, W) or (H, W, K)")
        if array.dtype.name not in MAP_DTYPES:
            raise InvalidImageError(
                f"{name} has dtype {array.dtype}: expected one of {', '.join(MAP_DTYPES)}"
            )
        view = array[..., None] if array.ndim == 2 else array
        if view.shape[:2] != shape:
            raise InvalidImageError(
                f"{name} is {view.shape[1]}x{view.shape[0]} (width x height); it must match "
                f"its image, {shape[1]}x{shape[0]}"
            )
        if not 1 <= view.shape[2] <= MAX_MAP_CHANNELS:
            raise InvalidImageError(
                f"{name} has {view.shape[2]} channels: expected 1..{MAX_MAP_CHANNELS}"
            )
        check_float_range(view, name)
        maps.append(view)
    if maps[0].shape[2] != maps[1].shape[2]:
        raise InvalidImageError(
            f"source_map has {maps[0].shape[2]} channels and target_map {maps[1].shape[2]}: "
            "they must match"
        )
    if (maps[0].dtype.kind == "f") != (maps[1].dtype.kind == "f") or (
        maps[0].dtype.kind != "f" and maps[0].dtype != maps[1].dtype
    ):
        raise InvalidImageError(
            f"source_map ({maps[0].dtype}) and target_map ({maps[1].dtype}) must have the same "
            "kind of values to be compared"
        )
    scaled = []
    for view in maps:
        if view.dtype in (np.uint8, np.uint16):
            scaled.append(to_working(view))
        else:
            scaled.append(np.ascontiguousarray(view, dtype=np.float32))
    return scaled[0], scaled[1]


@dataclass(frozen=True)
class PassPlan:
    """Block, overlap and alpha of one transfer pass."""

    block: int
    overlap: int
    alpha: float


def schedule(options: TransferOptions) -> list[PassPlan]:
    """The passes of an (iterative) transfer, after Efros & Freeman 2001, §3.

    Pass i of N (1-based) uses blocks ``round(block * (2/3)^(i-1))``, the paper's reduction by
    a third, but never below ``min(block, min_block)``; an overlap scaled the same way
    (``block_i // 6`` when not given; always < block_i / 2); and
    ``alpha_i = FIRST_ALPHA + (LAST_ALPHA - FIRST_ALPHA) (i - 1) / (N - 1)``, 0.1 to 0.5 (the
    paper's formula with 0.5 in place of its 0.9, see the module docstring), unless
    ``options.alpha`` is given (then every pass uses it). A single pass uses
    :data:`SINGLE_PASS_ALPHA`.

    Returns
    -------
    list of PassPlan, length ``options.iterations``
    """
    count = options.iterations
    floor = min(options.block, options.min_block)
    plans = []
    for i in range(1, count + 1):
        block = max(floor, round(options.block * (2 / 3) ** (i - 1)))
        if options.overlap is None:
            overlap = max(1, block // 6)
        else:
            overlap = max(1, round(options.overlap * block / options.block))
        overlap = min(overlap, (block - 1) // 2)
        if options.alpha is not None:
            alpha = options.alpha
        elif count == 1:
            alpha = SINGLE_PASS_ALPHA
        else:
            alpha = FIRST_ALPHA + (LAST_ALPHA - FIRST_ALPHA) * (i - 1) / (count - 1)
        plans.append(PassPlan(block=block, overlap=overlap, alpha=alpha))
    return plans


def _over_canvas(image: NDArray[np.float32], grid: Grid) -> NDArray[np.float32]:
    """``image`` (H, W, K) cropped or mirrored out to the grid's canvas size."""
    height, width = grid.height, grid.width
    image = image[:height, :width]
    pad = ((0, height - image.shape[0]), (0, width - image.shape[1]), (0, 0))
    if not any(p[1] for p in pad):
        return np.ascontiguousarray(image)
    # Blocks reaching past the target's edge see its mirror image there: a natural
    # continuation to match, and the part past the edge is cropped from the output anyway.
    return np.pad(image, pad, mode="symmetric")


def transfer_quilt(
    view: NDArray[np.generic],
    fmt: PixelFormat,
    source_map: NDArray[np.float32],
    target_map: NDArray[np.float32],
    options: TransferOptions,
    backend: CostBackend,
    *,
    progress: Progress | None = None,
    max_batch: int | None = None,
    excluded: NDArray[np.bool_] | None = None,
) -> Result:
    """Render a target, given by its correspondence map, in the texture ``view``.

    Parameters
    ----------
    view : ndarray, shape (h, w, C)
        The validated texture in its own dtype.
    fmt : PixelFormat
        How the texture was given, to return the image the same way.
    source_map : ndarray, shape (h, w, K), float32
        The texture's correspondence map.
    target_map : ndarray, shape (H, W, K), float32
        The target's correspondence map; the output is H x W.
    options : TransferOptions
    backend : CostBackend
    progress : callable, optional
        ``progress(fraction, stage)`` after each level; stage is ``"pass i/N"``.
    max_batch : int, optional
        Most blocks per backend call; never changes the output.
    excluded : ndarray of bool, shape (h, w), optional
        Texture pixels never to use (see :mod:`quilting.core.exclusion`).

    Returns
    -------
    Result
        ``stats.correspondence_error`` is set; ``layout`` holds every pass.
    """
    started = time.perf_counter()
    clock = Clock()
    plans = schedule(options)
    check_block_fits(options, view.shape[0], view.shape[1])
    source = to_working(view)
    size = (target_map.shape[0], target_map.shape[1])
    grids = [Grid.covering(size[0], size[1], p.block, p.overlap) for p in plans]
    # Progress in proportion to the blocks placed.
    counts = np.cumsum([0] + [g.rows * g.cols for g in grids], dtype=np.float64)
    spans = counts / counts[-1]
    previous: NDArray[np.float32] | None = None
    records = []
    work: QuiltPass | None = None
    for index, (plan, grid) in enumerate(zip(plans, grids, strict=True)):
        guidance = Guidance(
            alpha=plan.alpha,
            source_map=source_map,
            target_map=_over_canvas(target_map, grid),
            previous=None if previous is None else _over_canvas(previous, grid),
        )
        work = QuiltPass(source, grid, options, backend, clock, index, guidance, excluded)
        work.execute(
            max_batch,
            progress,
            f"pass {index + 1}/{len(plans)}",
            (float(spans[index]), float(spans[index + 1])),
        )
        records.append(work.record)
        previous = work.canvas[: size[0], : size[1]]
    assert work is not None
    shaded = (
        options.shade > 1
        and options.correspondence in ("luminance", "blurred")
        and target_map.shape[2] == 1
    )
    if shaded:
        tick = time.perf_counter()
        shade_towards(
            work.canvas[: size[0], : size[1]],
            target_map,
            options.shade,
            SHADE_SCALE * plans[-1].block,
        )
        clock.add("shade", tick)
    layout = Layout(
        source_shape=(source.shape[0], source.shape[1]),
        output_shape=size,
        passes=records,
        meta={
            "operation": "transfer",
            **options.to_dict(),
            "passes": [{"block": p.block, "overlap": p.overlap, "alpha": p.alpha} for p in plans],
        },
    )
    tick = time.perf_counter()
    carried = layout.render(source_map)
    difference = (carried.astype(np.float64) - target_map) ** 2
    error = float(difference.mean())
    clock.add("stats", tick)
    result = finish(view, fmt, layout, work, clock, started, correspondence_error=error)
    if shaded and fmt.dtype not in (np.uint8, np.uint16, np.float32):
        # finish re-rendered these from the layout, which does not record the shading.
        image = fmt.restore(rendered(work.canvas[: size[0], : size[1]], fmt.dtype))
        result = dataclasses.replace(result, image=image)
    return result
