"""The matting job: its inputs checked against each other, its predicted cost, each layer
quilted and laid on the surface read from the target.

:func:`quilting.matte` builds the options and picks the backend; everything after that is
here, beside the surface and compositing steps of :mod:`quilting.core.matting`.

References
----------
The alpha quilting and texture matting paper, §3 (normals from shading under a silhouette,
k-means patches on (n, x, y), shading by n . S, compositing layers).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from quilting.core.budget import (
    MATTE_BYTES_PER_PIXEL,
    Budget,
    Estimate,
    estimate_synthesis,
    layers_in_turn,
)
from quilting.core.errors import InvalidImageError, InvalidParameterError
from quilting.core.exclusion import excluded_pixels
from quilting.core.fields import CostBackend
from quilting.core.matting import MatteResult, lay_layers, layer_size, read_surface
from quilting.core.options import MatteOptions, SynthesisOptions
from quilting.core.pixels import PixelFormat, as_channels, luminance, rendered, to_working
from quilting.core.progress import Progress
from quilting.core.shading import coverage, decode_normal_map, inside_of, unit_direction
from quilting.core.synthesis import Result, check_block_fits, quilt


def matte_quilt(
    inputs: MatteInputs,
    options: MatteOptions,
    engine: CostBackend,
    *,
    max_batch: int | None = None,
    progress: Progress | None = None,
) -> MatteResult:
    """Quilt every layer, read the surface, lay the layers on it.

    Parameters
    ----------
    inputs : MatteInputs
        From :func:`matte_inputs`.
    options : MatteOptions
    engine : CostBackend
    max_batch : int, optional
        Most blocks in one backend call (from :func:`estimate_matte`).
    progress : callable, optional
        ``progress(fraction, stage)``, stage ``"layer k/N"`` while quilting, then
        ``"surface"``.
    """
    started = time.perf_counter()
    views, size = inputs.layers, inputs.layer_size
    quilted: list[Result] = []
    for index, (view, fmt) in enumerate(views):
        layer_progress = None
        if progress is not None:
            layer_progress = _layer_progress(progress, index, len(views))
        quilted.append(
            quilt(
                view,
                fmt,
                size,
                _layer_options(options, index),
                engine,
                progress=layer_progress,
                max_batch=max_batch,
                excluded=excluded_pixels(view, options.exclude_colors, None),
            )
        )
    layered = time.perf_counter()
    if progress is not None:
        progress(0.9, "surface")
    work = to_working(inputs.target)
    surface = read_surface(
        luminance(work),
        inputs.cover,
        normals=inputs.normals,
        light=None if options.light is None else unit_direction(options.light),
        clusters=options.clusters,
        spatial_weight=options.spatial_weight,
        smoothing=options.smoothing,
        min_z=options.min_z,
        rng=np.random.default_rng(np.random.SeedSequence([options.seed, MATTE_STREAM])),
    )
    read = time.perf_counter()
    rgba = lay_layers(
        _as_rgba(work),
        [_as_rgba(to_working(result.image.reshape(*size, -1))) for result in quilted],
        surface,
        scale=options.scale,
        ambient=options.ambient,
    )
    colour = inputs.target.shape[2] >= 3 or any(view.shape[2] >= 3 for view, _ in views)
    image = _restore(rgba, inputs.target_format, colour)
    _keep_target(image, inputs.target, surface.patches.patches < 0)
    done = time.perf_counter()
    direction = surface.light.direction
    return MatteResult(
        image=image,
        normals=surface.normals,
        clusters=surface.patches.clusters,
        patches=surface.patches.patches,
        light=(float(direction[0]), float(direction[1]), float(direction[2])),
        albedo=surface.light.albedo,
        ambient_fit=surface.light.ambient,
        layers=quilted,
        timings={
            "layers": layered - started,
            "surface": read - layered,
            "lay": done - read,
            "total": done - started,
        },
    )


def estimate_matte(
    options: MatteOptions,
    target: tuple[int, int],
    layers: Sequence[tuple[tuple[int, ...], int]],
    layer_size: tuple[int, int],
    *,
    backend: str = "fft",
    max_batch: int | None = None,
    budget: Budget | None = None,
) -> Estimate:
    """A matte's predicted cost, checked against ``budget``.

    Parameters
    ----------
    options : MatteOptions
    target : (int, int)
        The target's (height, width).
    layers : sequence of (shape, itemsize)
        Each layer's array shape, (h, w) or (h, w, C), and bytes per sample.
    layer_size : (int, int)
        The size the layers are quilted at (the silhouette's extent over ``scale``).

    The layers are quilted one after another: each must fit the memory budget beside the
    target's maps (:data:`~quilting.core.budget.MATTE_BYTES_PER_PIXEL`), and their times add up.
    """
    kept = MATTE_BYTES_PER_PIXEL * target[0] * target[1]
    memory = None if budget is None else Budget(memory_bytes=budget.memory_bytes)
    found = [
        estimate_synthesis(
            _layer_options(options, index),
            shape,
            layer_size,
            backend=backend,
            itemsize=itemsize,
            max_batch=max_batch,
            budget=memory,
            extra_bytes=kept,
        )
        for index, (shape, itemsize) in enumerate(layers)
    ]
    return layers_in_turn(found, budget)


@dataclass(frozen=True)
class MatteInputs:
    """A matting's inputs once checked against each other, as the engine takes them."""

    target: NDArray[Any]
    target_format: PixelFormat
    layers: list[tuple[NDArray[Any], PixelFormat]]
    cover: NDArray[np.float32]
    normals: NDArray[np.float32] | None
    layer_size: tuple[int, int]


def matte_inputs(
    options: MatteOptions,
    target: object,
    layers: Sequence[object],
    silhouette: object,
    normals: object | None,
) -> MatteInputs:
    target_view, target_format = as_channels(target, "target")
    views = _layer_views(layers, options)
    cover = _cover(silhouette, target_view.shape[:2])
    given = None if normals is None else _normal_map(normals, target_view.shape[:2])
    size = layer_size(cover, options.scale, options.block)
    return MatteInputs(target_view, target_format, views, cover, given, size)


#: Stream of the matting job's own draws (k-means), apart from the layers' seeds.
MATTE_STREAM = 0x6D617474


def _layer_views(
    layers: Sequence[object], options: MatteOptions
) -> list[tuple[NDArray[Any], PixelFormat]]:
    """Each layer validated, with a block that fits and a mode its channels allow."""
    if not isinstance(layers, Sequence):
        raise InvalidParameterError("layers", layers, "a list of one or more images")
    if isinstance(layers, np.ndarray) or len(layers) == 0:
        raise InvalidParameterError(
            "layers", "an array" if len(layers) else "[]", "a list of one or more images"
        )
    views = []
    for index, layer in enumerate(layers):
        name = f"layers[{index}]"
        view, fmt = as_channels(layer, name)
        check_block_fits(options, view.shape[0], view.shape[1], name)
        options.resolved_mode(view.shape[2], name)
        views.append((view, fmt))
    return views


def _layer_options(options: MatteOptions, index: int) -> SynthesisOptions:
    """The synthesis options of layer ``index``: tileable both ways, its own seed."""
    values = {k: v for k, v in options.to_dict().items() if k in _SYNTHESIS_FIELDS}
    values["seed"] = int(
        np.random.SeedSequence([options.seed, index]).generate_state(1, np.uint64)[0]
    )
    values["tileable"] = "both"
    return SynthesisOptions(**values)


_SYNTHESIS_FIELDS = frozenset(SynthesisOptions.__dataclass_fields__)


def _layer_progress(progress: Progress, index: int, count: int) -> Progress:
    def report(fraction: float, stage: str) -> object:
        return progress(0.9 * (index + fraction) / count, f"layer {index + 1}/{count}")

    return report


def _cover(silhouette: object, shape: tuple[int, ...]) -> NDArray[np.float32]:
    view, _ = as_channels(silhouette, "silhouette")
    if view.shape[:2] != shape:
        raise InvalidImageError(
            f"silhouette is {view.shape[1]}x{view.shape[0]}; it must be the target's size, "
            f"{shape[1]}x{shape[0]}",
            parameter="silhouette",
        )
    cover = coverage(to_working(view))
    inside_of(cover)  # refuses a silhouette that marks nothing
    return cover


def _normal_map(normals: object, shape: tuple[int, ...]) -> NDArray[np.float32]:
    view, _ = as_channels(normals, "normals")
    if view.shape[:2] != shape:
        raise InvalidImageError(
            f"normals is {view.shape[1]}x{view.shape[0]}; it must be the target's size, "
            f"{shape[1]}x{shape[0]}",
            parameter="normals",
        )
    return decode_normal_map(to_working(view), integer=view.dtype.kind == "u")


def _as_rgba(image: NDArray[np.float32]) -> NDArray[np.float32]:
    """Working pixels as straight RGBA (gray spread to RGB, opaque without alpha)."""
    rgba = np.ones((*image.shape[:2], 4), dtype=np.float32)
    if image.shape[2] >= 3:
        rgba[..., : image.shape[2]] = image
    else:
        rgba[..., :3] = image[..., :1]
    return rgba


def _keep_target(image: NDArray[Any], target: NDArray[Any], outside: NDArray[np.bool_]) -> None:
    """Put the target's own values back where no layer is laid (``outside``, (H, W)).

    The working copy's float32 round trip and the clip to [0, 1] are for the pixels the
    matting computes; a float target's values outside that range, or its float64 digits, are
    the caller's and stay as given. ``image`` is :func:`_restore`'s output, in the target's
    dtype; a gray target under coloured layers gives its gray to each colour channel.
    """
    planes = image if image.ndim == 3 else image[..., None]
    kept = target if planes.shape[2] == target.shape[2] else np.repeat(target[..., :1], 3, axis=2)
    planes[outside] = kept[outside]


def _restore(rgba: NDArray[np.float32], fmt: PixelFormat, colour: bool) -> NDArray[Any]:
    """RGBA working pixels in the target's dtype: RGB if ``colour`` else gray, alpha kept
    only if the target had it."""
    channels = [0, 1, 2] if colour else [0]
    if fmt.channels == 4:
        channels.append(3)
    # Without colour anywhere every pixel has r = g = b, so red is the gray itself.
    image = rendered(rgba[..., channels], fmt.dtype)
    return image[..., 0] if fmt.two_dimensional and image.shape[2] == 1 else image
