"""Each operation's engine call in a worker, and the fields its finished job stores: the
result as PNG (its metadata holds no job id or time: the same request gives the same bytes),
its companions, its layout (or manifest), timings, backend and figures.

:func:`result_fields` picks the operation from the options' class; the worker
(:mod:`quilting.service.jobs.worker`) decodes the uploads before and maps the engine's errors
after.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from quilting import (
    AlphaOptions,
    Budget,
    Extracted,
    __version__,
    apply_layout,
    extract_alpha,
)
from quilting.api import extend, fill, matte, synthesize, transfer, wang_tiles
from quilting.io import encode_png
from quilting.options import (
    ExtendOptions,
    FillOptions,
    MatteOptions,
    QuiltOptions,
    SynthesisOptions,
    TransferOptions,
    WangOptions,
)
from quilting.service.jobs.job_input import JobInput
from quilting.service.upload_images import Decoded

#: ``report(fraction, stage)``: what a job tells of its progress.
Report = Callable[[float, str], None]


def result_fields(
    spec: JobInput,
    options: QuiltOptions | FillOptions | WangOptions | AlphaOptions,
    images: Decoded,
    progress: Report,
    report: Report,
    budget: Budget | None,
) -> dict[str, Any]:
    """Compute the job and return the fields its store keeps.

    Parameters
    ----------
    spec : JobInput
        The job's input (its size, companions' kinds, operation).
    options : QuiltOptions, FillOptions, WangOptions or AlphaOptions
        The job's options; their class says which engine entry point runs.
    images : Decoded
        The uploads, decoded.
    progress : callable
        ``progress(fraction, stage)`` handed to the engine (it stops a cancelled or late job).
    report : callable
        Told of the encoding once the engine is done.
    budget : Budget or None
        The job's budget, which the engine checks again and sizes its batches to.

    Raises
    ------
    QuiltingError
        The engine's (the worker maps them to the job's error).
    """
    if isinstance(options, AlphaOptions):
        return _extract(spec, options, images, progress, report, budget)
    if isinstance(options, MatteOptions):
        return _matte(spec, options, images, progress, report, budget)
    if isinstance(options, FillOptions):
        return _fill(spec, options, images, progress, report, budget)
    if isinstance(options, WangOptions):
        return _wang(spec, options, images, progress, report, budget)
    assert isinstance(options, SynthesisOptions | TransferOptions), "the operations' classes"
    return _quilt(spec, options, images, progress, report, budget)


def _quilt(
    spec: JobInput,
    options: SynthesisOptions | TransferOptions,
    images: Decoded,
    progress: Report,
    report: Report,
    budget: Budget | None,
) -> dict[str, Any]:
    """A synthesis's or a transfer's result fields: the image, its companions quilted with
    the same layout, the layout, and the figures (with the extractions, if any)."""
    if isinstance(options, TransferOptions):
        assert images.target is not None, "a transfer job has a target"
        result = transfer(
            images.texture,
            images.target,
            options,
            progress=progress,
            source_mask=images.source_mask,
            budget=budget,
        )
    else:
        # Several examples go to the engine as a list (a mask and a companion map per
        # example); one texture as the array it always was.
        result = synthesize(
            images.examples or images.texture,
            (spec.height, spec.width),
            options,
            progress=progress,
            source_mask=images.source_masks or images.source_mask,
            budget=budget,
            **_marks(images, bool(images.examples)),
        )
    report(1.0, "encoding")
    # No job id or time in the metadata: the same request gives the same bytes.
    meta: dict[str, Any] = {**result.layout.meta, "width": spec.width, "height": spec.height}
    stats = result.stats
    figures: dict[str, Any] = {
        "seam_error_mean": stats.seam_error_mean,
        "seam_error_total": stats.seam_error_total,
        "largest_copy": stats.largest_copy,
        "unused": stats.unused,
    }
    if stats.correspondence_error is not None:
        figures["correspondence_error"] = stats.correspondence_error
    if images.trimaps:
        figures["extracted"] = _summaries(images, result.extracted)
    return {
        "png": encode_png(result.image, metadata=meta),
        "companions": {
            name: encode_png(
                apply_layout(
                    result.layout,
                    images.example_companions.get(name) or image,
                    kind=spec.kind_of(name),
                ),
                metadata=meta,
            )
            for name, image in images.companions.items()
        },
        "layout": result.layout.to_json().encode(),
        "timings": dict(result.timings),
        "backend": result.backend,
        "renderer": result.renderer,
        "fallback": result.fallback,
        "stats": figures,
    }


def _matte(
    spec: JobInput,
    options: MatteOptions,
    images: Decoded,
    progress: Report,
    report: Report,
    budget: Budget | None,
) -> dict[str, Any]:
    """A matte job's result fields: the image, the normals and patches used, the light."""
    assert images.target is not None and images.silhouette is not None, "a matte job has both"
    result = matte(
        images.target,
        images.layers,
        options,
        silhouette=images.silhouette,
        normals=images.normals,
        progress=progress,
        budget=budget,
        **_marks(images, True),
    )
    report(1.0, "encoding")
    meta: dict[str, Any] = {
        "operation": "matte",
        **options.to_dict(),
        "light_used": list(result.light),
        "width": spec.width,
        "height": spec.height,
    }
    first = result.layers[0]
    return {
        "png": encode_png(result.image, metadata=meta),
        "companions": {
            "normals": encode_png(result.normal_map(), metadata=meta),
            "clusters": encode_png(result.patch_map(), metadata=meta),
        },
        "layout": None,
        "timings": dict(result.timings),
        "backend": first.backend,
        "renderer": first.renderer,
        "fallback": next((layer.fallback for layer in result.layers if layer.fallback), None),
        "stats": {
            "light": list(result.light),
            "albedo": result.albedo,
            "ambient_fit": result.ambient_fit,
            "clusters": int(result.clusters.max()) + 1,
            "patches": int(result.patches.max()) + 1,
            "layer_size": list(first.image.shape[:2][::-1]),
            **(
                {
                    "extracted": _summaries(
                        images, [e for layer in result.layers for e in layer.extracted]
                    )
                }
                if images.trimaps
                else {}
            ),
        },
    }


def _fill(
    spec: JobInput,
    options: FillOptions,
    images: Decoded,
    progress: Report,
    report: Report,
    budget: Budget | None,
) -> dict[str, Any]:
    """A fill's or an extension's result fields: the image, its companions filled the same
    way (copied from where the image's filled pixels came from), and its layout (every block
    placed, where from and the pixels it took: :class:`quilting.FillLayout`)."""
    if isinstance(options, ExtendOptions):
        result = extend(images.texture, options, progress=progress, budget=budget)
    else:
        assert images.mask is not None, "a fill job has a mask"
        result = fill(
            images.texture,
            images.mask,
            options,
            texture=images.source,
            progress=progress,
            budget=budget,
        )
    report(1.0, "encoding")
    meta = _meta(spec, options)
    return {
        "png": encode_png(result.image, metadata=meta),
        "companions": {
            name: encode_png(result.apply(image), metadata=meta)
            for name, image in images.companions.items()
        },
        "layout": result.layout.to_json().encode(),
        "timings": dict(result.timings),
        "backend": result.backend,
        "renderer": None,
        "fallback": None,
        "stats": {
            "seam_error_mean": result.seam_error,
            "blocks": result.blocks,
            "filled_pixels": int(result.filled.sum()),
        },
    }


def _wang(
    spec: JobInput,
    options: WangOptions,
    images: Decoded,
    progress: Report,
    report: Report,
    budget: Budget | None,
) -> dict[str, Any]:
    """A Wang tile set's result fields: the atlas of its tiles (the result), and its manifest
    (each tile's place in the atlas and edge colours) where a synthesis keeps its layout."""
    tiles = wang_tiles(images.examples or images.texture, options, progress=progress, budget=budget)
    report(1.0, "encoding")
    # No job id or time in the metadata: the same request gives the same bytes.
    meta: dict[str, Any] = {**tiles.meta, "width": spec.width, "height": spec.height}
    return {
        "png": encode_png(tiles.atlas(), metadata=meta),
        "companions": {},
        "layout": tiles.to_json().encode(),
        "timings": dict(tiles.timings),
        "backend": tiles.backend,
        "renderer": tiles.renderer,
        "fallback": tiles.fallback,
        "stats": {
            "colors": tiles.colors,
            "tile": tiles.tile,
            "tiles": len(tiles.edges),
            "atlas": [spec.width, spec.height],
        },
    }


def _meta(spec: JobInput, options: FillOptions | AlphaOptions) -> dict[str, Any]:
    """The PNG metadata of a job's result: its operation, options, size and the version. No
    job id or time: the same request gives the same bytes."""
    return {
        "operation": spec.operation,
        **options.to_dict(),
        "width": spec.width,
        "height": spec.height,
        "version": __version__,
    }


def _marks(images: Decoded, several: bool) -> dict[str, Any]:
    """The ``trimap`` and ``scribbles`` keywords of a job's engine call: none for a job that
    extracts no alpha, one list per kind (one map or None per photo) when ``several``, else
    the one photo's maps."""
    if not images.trimaps:
        return {}
    if several:
        return {"trimap": list(images.trimaps), "scribbles": list(images.scribbles)}
    return {"trimap": images.trimaps[0], "scribbles": images.scribbles[0]}


def _summaries(images: Decoded, extracted: Sequence[Extracted]) -> list[dict[str, Any] | None]:
    """One entry per photo of the job (``stats["extracted"]``, the ``Quilting-Extracted``
    header): its extraction's summary, None for a photo without a trimap or scribbles. The
    engine lists only the extractions made, in the photos' order."""
    made = iter(extracted)
    return [
        None if (trimap is None and strokes is None) else next(made).summary()
        for trimap, strokes in zip(images.trimaps, images.scribbles, strict=True)
    ]


def _extract(
    spec: JobInput,
    options: AlphaOptions,
    images: Decoded,
    progress: Report,
    report: Report,
    budget: Budget | None,
) -> dict[str, Any]:
    """An alpha extraction's result fields: the RGBA texture, and its summary in the stats."""
    found = extract_alpha(
        images.texture,
        images.trimaps[0],
        images.scribbles[0],
        options,
        progress=progress,
        budget=budget,
    )
    report(1.0, "encoding")
    meta = _meta(spec, options)
    return {
        "png": encode_png(found.image, metadata=meta),
        "companions": {},
        "layout": None,
        "timings": dict(found.timings),
        "backend": None,
        "renderer": None,
        "fallback": None,
        "stats": {"extracted": [found.summary()]},
    }
