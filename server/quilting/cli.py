"""The ``quilting`` command line: ``synth``, ``transfer``, ``matte``, ``tile``, ``fill``,
``extend``, ``wang``, ``extract-alpha``, ``apply-layout``, ``serve``, ``worker``, ``info``.
Jobs on a running service are the client's own command, ``quilting-remote`` (the
``quilting_client`` distribution).

Errors the user can fix are printed as one line (``quilting: error: ...``) with exit status 2;
no traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import re
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import Field, fields
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from quilting import (
    COMPANION_KINDS,
    AlphaOptions,
    Budget,
    Extracted,
    Filled,
    FillLayout,
    InvalidParameterError,
    Layout,
    QuiltingError,
    Result,
    WangOptions,
    __version__,
    apply_layout,
    extend,
    extract_alpha,
    fill,
    is_fill_layout,
    make_tileable,
    matte,
    synthesize,
    transfer,
    wang_tiles,
)
from quilting.backends import (
    GL_DEVICE_VARIABLE,
    auto_choice,
    available_backends,
)
from quilting.io import check_writable, output_format, read_image, write_image
from quilting.options import (
    Correspondence,
    ExtendOptions,
    FillOptions,
    MatteOptions,
    QuiltOptions,
    SynthesisOptions,
    TileOptions,
    TransferOptions,
    offered_choices,
)

#: What a companion map may be called (the service's rule, so a name works in both places).
COMPANION_NAME = re.compile(r"[A-Za-z0-9_-]{1,64}")

#: Companion maps by name: the file(s) each was read from (comma-separated, one per example,
#: with several), its pixels (a list of them, one per example, with several) and its kind.
Companions = dict[str, tuple[str, Any, str]]
#: How the seams treat a companion's values (apply-layout --kind, --with NAME:KIND=PATH).
COMPANION_KIND_HELP = (
    "'blend' (default) like the output's pixels, 'hard' never mixed (masks, IDs), "
    "'normal' blended and made unit vectors again, 'normal_dx' the same for a normal map "
    "whose green points down (DirectX); a normal map's vectors turn with rotated or mirrored "
    "blocks (--transforms)"
)
OptionsClass = (
    type[QuiltOptions]
    | type[TileOptions]
    | type[FillOptions]
    | type[WangOptions]
    | type[AlphaOptions]
)
"""An options dataclass whose fields document the command-line flags."""


def _option_field(name: str, options: OptionsClass) -> Field[Any]:
    for f in fields(options):
        if f.name == name:
            return f
    raise KeyError(name)


def _colour_range(text: str) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Parse ``LOW:HIGH`` with comma-separated channel values, e.g. ``0,0,0:40,40,40``."""
    parts = text.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        low, high = (tuple(float(v) for v in part.split(",")) for part in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"colour range {text!r} is not LOW:HIGH with comma-separated values, "
            "e.g. 120,120,120:255,255,255"
        ) from None
    return low, high


def _option_doc(name: str, options: OptionsClass) -> str:
    """The documentation of the field ``name`` of ``options``."""
    return str(_option_field(name, options).metadata["doc"])


def _option_help(name: str, options: OptionsClass = SynthesisOptions) -> str:
    """The one-line help of an option, from the documentation of its field in ``options``."""
    return _option_doc(name, options) + f" (default: {_option_default(name, options)})"


def _option_default(name: str, options: OptionsClass) -> Any:
    """The default of an option, from its field in ``options`` (so the two cannot drift)."""
    return _option_field(name, options).default


def _size(text: str) -> tuple[int, int]:
    """Parse ``WxH`` (or one number for a square) into (height, width)."""
    parts = text.lower().split("x")
    try:
        numbers = [int(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"size {text!r} is not WIDTHxHEIGHT, e.g. 512x512"
        ) from None
    if len(numbers) == 1:
        numbers *= 2
    if len(numbers) != 2:
        raise argparse.ArgumentTypeError(f"size {text!r} is not WIDTHxHEIGHT, e.g. 512x512")
    width, height = numbers
    return height, width


class ProgressBar:
    """A one-line progress bar on a terminal; silent when the stream is not a terminal."""

    def __init__(self, stream: TextIO, width: int = 30) -> None:
        self.stream = stream
        self.width = width
        self.enabled = stream.isatty()
        self.started = time.perf_counter()

    def __call__(self, fraction: float, stage: str) -> None:
        if not self.enabled:
            return
        filled = round(fraction * self.width)
        elapsed = time.perf_counter() - self.started
        bar = "#" * filled + "-" * (self.width - filled)
        self.stream.write(f"\r{stage:<10} [{bar}] {fraction:6.1%} {elapsed:6.1f}s")
        if fraction >= 1.0:
            self.stream.write("\n")
        self.stream.flush()


def _read_companions(
    args: argparse.Namespace,
    texture: Any,
    *,
    specs: Sequence[str] | None = None,
    flag: str = "--with",
    role: str = "texture",
    kinds: bool = True,
) -> Companions:
    """Parse and read every ``--with NAME[:KIND]=PATH``, each checked against the texture's size
    (KIND one of :data:`~quilting.COMPANION_KINDS`, default 'blend').

    Done before the quilting starts, so that a bad map fails at once and nothing is written.
    ``texture`` is one image, or a list of several examples: then PATH is one path per example,
    comma-separated in the examples' order, each map checked against its example's size and
    the companion's pixels are a list of the maps. ``specs`` (default: ``args.companions``)
    and ``flag`` name another flag's maps, ``role`` what ``texture`` is in the messages ('the
    image'), and ``kinds=False`` refuses a KIND (a fill copies its companions' pixels, it never
    blends them).
    """
    companions: Companions = {}
    for spec in args.companions if specs is None else specs:
        label, equals, path = spec.partition("=")
        if not equals or not path:
            raise QuiltingError(f"{flag} {spec!r} is not NAME=PATH, e.g. normal=normal.png")
        name, colon, kind = label.partition(":")
        if colon and not kinds:
            raise QuiltingError(
                f"{flag} {spec!r}: a fill copies each companion's pixels from where the image's "
                "came from, never blended: give NAME=PATH, without :KIND"
            )
        kind = kind or "blend"
        if kind not in COMPANION_KINDS:
            raise QuiltingError(
                f"{flag} {spec!r}: the kind {kind!r} is not one of {', '.join(COMPANION_KINDS)}"
            )
        if not COMPANION_NAME.fullmatch(name):
            raise QuiltingError(
                f"{flag} {spec!r}: the name {name!r} is not 1 to 64 of A-Z a-z 0-9 _ -"
            )
        if name in companions:
            raise QuiltingError(f"{flag}: the companion {name!r} is given twice")
        if isinstance(texture, list):
            companions[name] = (path, _example_maps(flag, spec, name, path, texture), kind)
            continue
        image = _read_map(name, path)
        if image.shape[:2] != texture.shape[:2]:
            raise QuiltingError(
                f"companion {name!r} ('{path}') is {image.shape[1]}x{image.shape[0]} but the "
                f"{role} is {texture.shape[1]}x{texture.shape[0]} (width x height): a "
                f"companion map must have the {role}'s size"
            )
        companions[name] = (path, image, kind)
    return companions


def _read_map(name: str, path: str) -> Any:
    """The companion ``name``'s map read from ``path``; an error names the companion."""
    try:
        return read_image(path)
    except QuiltingError as exc:
        raise QuiltingError(f"companion {name!r}: {exc}") from exc


def _example_maps(flag: str, spec: str, name: str, paths: str, examples: list[Any]) -> list[Any]:
    """The maps of a companion of several examples: ``paths`` comma-separated, one per example
    in order, each of its example's size."""
    parts = paths.split(",")
    if len(parts) != len(examples) or not all(parts):
        raise QuiltingError(
            f"{flag} {spec!r}: with {len(examples)} input images give {len(examples)} "
            f"comma-separated paths, one map per input in the same order "
            f"(NAME=A.png,B.png...), got {len([p for p in parts if p])}"
        )
    maps = []
    for index, (path, example) in enumerate(zip(parts, examples, strict=True)):
        image = _read_map(name, path)
        if image.shape[:2] != example.shape[:2]:
            raise QuiltingError(
                f"companion {name!r} map {index + 1} ('{path}') is "
                f"{image.shape[1]}x{image.shape[0]} but input {index + 1} is "
                f"{example.shape[1]}x{example.shape[0]} (width x height): each map must have "
                "its input's size"
            )
        maps.append(image)
    return maps


def _source_mask(args: argparse.Namespace) -> Any:
    """The ``--source-mask`` image, or None."""
    return None if args.source_mask is None else read_image(args.source_mask)


def _source_masks(args: argparse.Namespace, count: int) -> Any:
    """The repeatable ``--source-mask`` of ``count`` examples: None when not given, the one
    image for one example, else a list of one mask per example (given once per input)."""
    paths = args.source_mask or []
    if not paths:
        return None
    if len(paths) != count:
        raise QuiltingError(
            f"--source-mask is given {len(paths)} time(s) for {count} input images: give it "
            "once per input, in the same order, or not at all"
        )
    masks = [read_image(path) for path in paths]
    return masks[0] if count == 1 else masks


def _extras(args: argparse.Namespace) -> dict[str, Any]:
    """The engine's keyword arguments that are not options: the source mask and the budget."""
    return {"source_mask": _source_mask(args), "budget": _budget(args)}


#: The help of every -o/--output: the format follows the file name (quilting.io.WRITE_FORMATS).
OUTPUT_HELP = (
    "output image; the format follows the extension: .png, .jpg/.jpeg or .webp "
    "(16-bit, float and RGBA images: .png only)"
)


def _check_outputs(
    args: argparse.Namespace, like: Any | None = None, channels: int | None = None
) -> None:
    """Refuse output names whose format cannot hold the result, before any work is done.

    ``like`` is an image with the output's dtype and channels (the texture for synthesis, the
    image for tiling), ``channels`` the output's channels when they are not its own (4: an
    alpha extracted from a photo); without ``like`` only the extensions are checked. The seams
    and normal maps are 8-bit RGB, which every format holds.
    """
    if like is not None:
        own = like.shape[2] if like.ndim == 3 else 1
        check_writable(args.output, like.dtype, own if channels is None else channels)
    else:
        output_format(args.output)
    for extra in ("seams", "normals_out", "clusters_out"):
        path = getattr(args, extra, None)
        if path:
            output_format(path)


#: What the white, black and grey of a trimap say (the help of every --trimap).
TRIMAP_HELP = (
    "white where the photo is surely foreground, black where surely background, grey (any "
    "other value) where the alpha is to be found; of the photo's size"
)
#: What the strokes of a scribbles image say (the help of every --scribbles).
SCRIBBLES_HELP = (
    "white strokes over surely foreground, black over surely background, the rest unknown "
    "(transparent or grey); of the photo's size. With a trimap, drawn over it"
)
#: The photo-and-trimap flags' words of what happens to a photo given with them.
EXTRACTED_HELP = (
    "the input is then an ordinary photo (no alpha): its alpha is extracted first (--matting) "
    "and the RGBA texture is quilted (alpha quilting)"
)


def _read_guide(flag: str, path: str) -> Any:
    """A trimap or scribbles image read from ``path``; an error names the flag."""
    try:
        return read_image(path)
    except QuiltingError as exc:
        raise QuiltingError(f"{flag}: {exc}") from exc


def _check_guide(flag: str, path: str, image: Any, what: str, photo: str, pixels: Any) -> None:
    """A trimap or scribbles image must have its photo's size: the error names both files."""
    if image.shape[:2] != pixels.shape[:2]:
        raise QuiltingError(
            f"{flag} '{path}' is {image.shape[1]}x{image.shape[0]} but {what} ('{photo}') is "
            f"{pixels.shape[1]}x{pixels.shape[0]} (width x height): draw it over the photo, "
            "at the photo's size"
        )


def _input_guides(
    flag: str, paths: Sequence[str] | None, inputs: Sequence[str], images: Sequence[Any]
) -> list[Any] | None:
    """The repeatable ``--trimap``/``--scribbles`` of ``synth``: None when not given, else one
    image (or None, for an empty value) per input, given once per input in the inputs' order
    (the ``--source-mask`` rule), each checked against its input's size."""
    if not paths:
        return None
    count = len(images)
    if len(paths) != count:
        raise QuiltingError(
            f"{flag} is given {len(paths)} time(s) for {count} input images: give it once per "
            "input, in the same order (an empty value, " + flag + "='', for an input without "
            "one), or not at all"
        )
    if not any(paths):
        raise QuiltingError(f"{flag} is empty for every input: give a file for at least one")
    found: list[Any] = []
    for index, (path, photo, pixels) in enumerate(zip(paths, inputs, images, strict=True)):
        if not path:
            found.append(None)
            continue
        image = _read_guide(flag, path)
        what = "the input" if count == 1 else f"input {index + 1}"
        _check_guide(flag, path, image, what, photo, pixels)
        found.append(image)
    return found


def _layer_guides(
    flag: str, specs: Sequence[str], layers: Sequence[str], images: Sequence[Any]
) -> list[Any] | None:
    """The repeatable ``--trimap``/``--scribbles LAYER=FILE`` of ``matte``: None when not
    given, else one image (or None) per ``--layer``, LAYER counting them from 1, bottom first;
    each checked against its layer's size."""
    if not specs:
        return None
    found: list[Any] = [None] * len(layers)
    for spec in specs:
        number, equals, path = spec.partition("=")
        if not equals or not path or not number.strip().isdigit():
            raise QuiltingError(
                f"{flag} {spec!r} is not LAYER=FILE: LAYER is the layer's number, 1 for the "
                f"first --layer (bottom first), e.g. {flag} 2=leaves_{flag[2:]}.png"
            )
        index = int(number) - 1
        if not 0 <= index < len(layers):
            raise QuiltingError(
                f"{flag} {spec!r}: there {'is' if len(layers) == 1 else 'are'} {len(layers)} "
                f"--layer {'image' if len(layers) == 1 else 'images'}: LAYER is 1 to "
                f"{len(layers)}, bottom first"
            )
        if found[index] is not None:
            raise QuiltingError(f"{flag}: layer {index + 1} is given twice")
        image = _read_guide(flag, path)
        _check_guide(flag, path, image, f"layer {index + 1}", layers[index], images[index])
        found[index] = image
    return found


def _engine_guides(given: list[Any] | None, several: bool) -> Any:
    """What the engine takes of the per-input maps: None, the one map, or the list."""
    if given is None or several:
        return given
    return given[0]


def _guided(*given: list[Any] | None) -> list[bool]:
    """For each input (or layer), whether a trimap or scribbles came with it."""
    lists = [g for g in given if g is not None]
    return [any(g[k] is not None for g in lists) for k in range(len(lists[0]))] if lists else []


def _guide_names(paths: Sequence[str | None]) -> list[str | None]:
    """The file names the metadata records of per-input maps (None for an input without)."""
    return [os.path.basename(path) if path else None for path in paths]


def _extraction_record(found: Extracted) -> dict[str, Any]:
    """What an output's metadata records of an extraction: its summary without the seconds
    (the same inputs and options write the same bytes)."""
    return {k: v for k, v in found.summary().items() if k != "seconds"}


def _extraction_words(found: Extracted) -> str:
    """``knn matting, 41.2% of the photo unknown, 84 iterations, foreground ml``."""
    iterations = "iteration" if found.iterations == 1 else "iterations"
    return (
        f"{found.method} matting, {found.unknown:.1%} of the photo unknown, "
        f"{found.iterations} {iterations}, foreground {found.foreground}"
    )


def _print_extracted(found: Extracted, what: str) -> None:
    seconds = found.timings.get("total", 0.0)
    print(f"alpha of {what} extracted in {seconds:.2f}s: {_extraction_words(found)}")


def _read_examples(paths: Sequence[str]) -> tuple[list[Any], Any]:
    """The input images, and what the engine takes: the one image, or the list of several."""
    images = [read_image(path) for path in paths]
    return images, images[0] if len(images) == 1 else images


def _cmd_synth(args: argparse.Namespace) -> int:
    images, texture = _read_examples(args.input)
    trimaps = _input_guides("--trimap", args.trimap, args.input, images)
    scribbles = _input_guides("--scribbles", args.scribbles, args.input, images)
    guided = _guided(trimaps, scribbles)
    # The examples share one dtype and channel count; an extracted alpha makes them RGBA.
    _check_outputs(args, images[0], 4 if any(guided) else None)
    companions = _read_companions(args, texture)
    height, width = args.size
    several = len(images) > 1
    result = synthesize(
        texture,
        (height, width),
        **_field_values(args, SynthesisOptions),
        source_mask=_source_masks(args, len(images)),
        trimap=_engine_guides(trimaps, several),
        scribbles=_engine_guides(scribbles, several),
        budget=_budget(args),
        progress=ProgressBar(sys.stderr),
    )
    source = args.input[0] if len(images) == 1 else list(args.input)
    extra: dict[str, Any] = {}
    if any(guided):
        # One entry per input (None for an input without), in the inputs' order.
        made = iter(result.extracted)
        extracted = [next(made) if g else None for g in guided]
        extra = {
            **({"trimap": _guide_names(args.trimap)} if trimaps else {}),
            **({"scribbles": _guide_names(args.scribbles)} if scribbles else {}),
            "extracted": [None if e is None else _extraction_record(e) for e in extracted],
        }
    written = _write_result(
        args, result, {"operation": "synthesize", "source": source}, companions, extra
    )
    stats = result.stats
    # The statistics are over what the blocks came from: the texture, or the examples' atlas.
    what = "the texture" if result.layout.sources is None else "the examples' atlas"
    print(
        f"wrote {args.output} ({width}x{height}) in {result.timings['total']:.2f}s "
        f"with the {result.backend} backend{_renderer_words(result)}; "
        f"mean seam error {stats.seam_error_mean:.4g}, "
        f"largest verbatim copy {stats.largest_copy:.1%} of {what}, "
        f"{stats.unused:.1%} of {what} unused"
    )
    if any(guided):
        for index, found in zip(
            (k for k, g in enumerate(guided) if g), result.extracted, strict=True
        ):
            named = f"'{args.input[index]}'"
            _print_extracted(found, f"input {index + 1} ({named})" if several else named)
    _print_companions(written, width, height)
    return 0


def _custom_maps(args: argparse.Namespace) -> dict[str, Any]:
    """``source_map`` and ``target_map`` read from their files, or nothing when not given."""
    given = {"source_map": args.source_map, "target_map": args.target_map}
    if not any(given.values()):
        return {}
    if not all(given.values()):
        raise QuiltingError(
            "--source-map and --target-map go together: give both, or neither for a "
            "computed correspondence"
        )
    if args.correspondence is not None:
        raise QuiltingError(
            f"correspondence={args.correspondence!r} with --source-map/--target-map: the maps "
            "replace the computed correspondence, leave --correspondence out"
        )
    return {name: read_image(path) for name, path in given.items()}


def _cmd_transfer(args: argparse.Namespace) -> int:
    texture = read_image(args.texture)
    _check_outputs(args, texture)
    target = read_image(args.target)
    maps = _custom_maps(args)
    companions = _read_companions(args, texture)
    # Maps make the correspondence 'custom'; left out, the options' default applies.
    named = args.correspondence or _option_default("correspondence", TransferOptions)
    correspondence: Correspondence = "custom" if maps else named
    result = transfer(
        texture,
        target,
        **(_field_values(args, TransferOptions) | {"correspondence": correspondence}),
        **_extras(args),
        progress=ProgressBar(sys.stderr),
        **maps,
    )
    files = {"operation": "transfer", "source": args.texture, "target": args.target}
    if maps:
        files |= {"source_map": args.source_map, "target_map": args.target_map}
    written = _write_result(args, result, files, companions)
    height, width = result.image.shape[:2]
    stats = result.stats
    blocks = ", ".join(str(p["block"]) for p in result.layout.meta["passes"])
    count = len(result.layout.meta["passes"])
    print(
        f"wrote {args.output} ({width}x{height}) in {result.timings['total']:.2f}s "
        f"with the {result.backend} backend{_renderer_words(result)}; "
        f"{count} {'pass (block' if count == 1 else 'passes (blocks'} {blocks}), "
        f"correspondence error {stats.correspondence_error:.4g}, "
        f"mean seam error {stats.seam_error_mean:.4g}"
    )
    _print_companions(written, width, height)
    return 0


def _light(text: str) -> tuple[float, float, float]:
    """``X,Y,Z`` as three numbers (the options check z > 0)."""
    try:
        x, y, z = (float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected X,Y,Z (three numbers, y up, z towards the viewer), got {text!r}"
        ) from None
    return x, y, z


def _cmd_matte(args: argparse.Namespace) -> int:
    # The flags of MatteOptions' fields are its options: checked before any file is read.
    options = MatteOptions(**_field_values(args, MatteOptions))
    target = read_image(args.target)
    _check_outputs(args, target)  # the result has the target's dtype, and its alpha if any
    silhouette = read_image(args.silhouette)
    layers = [read_image(path) for path in args.layers]
    trimaps = _layer_guides("--trimap", args.trimap, args.layers, layers)
    scribbles = _layer_guides("--scribbles", args.scribbles, args.layers, layers)
    guided = _guided(trimaps, scribbles)
    normals = None if args.normals is None else read_image(args.normals)
    result = matte(
        target,
        layers,
        options,
        silhouette=silhouette,
        normals=normals,
        trimap=trimaps,
        scribbles=scribbles,
        budget=_budget(args),
        progress=ProgressBar(sys.stderr),
    )
    extracted = [layer.extracted[0] if layer.extracted else None for layer in result.layers]
    extra: dict[str, Any] = {}
    if any(guided):
        extra = {
            **({"trimap": _layer_names(args.trimap, len(layers))} if trimaps else {}),
            **({"scribbles": _layer_names(args.scribbles, len(layers))} if scribbles else {}),
            "extracted": [None if e is None else _extraction_record(e) for e in extracted],
        }
    height, width = result.image.shape[:2]
    metadata: dict[str, Any] = {
        "operation": "matte",
        "target": os.path.basename(args.target),
        "silhouette": os.path.basename(args.silhouette),
        "layers": [os.path.basename(path) for path in args.layers],
        **({"normals": os.path.basename(args.normals)} if args.normals else {}),
        **options.to_dict(),
        **extra,
        "light_used": list(result.light),
        "width": width,
        "height": height,
        "version": __version__,
    }
    write_image(args.output, result.image, metadata=metadata)
    if args.normals_out:
        write_image(args.normals_out, result.normal_map())
    if args.clusters_out:
        write_image(args.clusters_out, result.patch_map())
    x, y, z = result.light
    print(
        f"wrote {args.output} ({width}x{height}) in {result.timings['total']:.2f}s: "
        f"{len(layers)} {'layer' if len(layers) == 1 else 'layers'} on "
        f"{int(result.patches.max()) + 1} patches of {int(result.clusters.max()) + 1} "
        f"clusters, light ({x:.3f}, {y:.3f}, {z:.3f})"
        + (" (given)" if args.light else " (estimated)")
    )
    for index, found in enumerate(extracted):
        if found is not None:
            _print_extracted(found, f"layer {index + 1} ('{args.layers[index]}')")
    return 0


def _layer_names(specs: Sequence[str], count: int) -> list[str | None]:
    """The file names of the ``LAYER=FILE`` maps, one per layer (None for a layer without)."""
    names: list[str | None] = [None] * count
    for spec in specs:
        number, _, path = spec.partition("=")
        names[int(number) - 1] = os.path.basename(path)
    return names


def _cmd_extract_alpha(args: argparse.Namespace) -> int:
    # The flags of AlphaOptions' fields are its options: checked before any file is read.
    options = AlphaOptions(**_field_values(args, AlphaOptions))
    if args.trimap is None and args.scribbles is None:
        raise QuiltingError(
            "extract-alpha needs --trimap TRIMAP.png or --scribbles STROKES.png (or both): "
            "white where the photo is surely foreground, black where surely background"
        )
    photo = read_image(args.photo)
    # The texture is RGBA, the alpha alone gray, both in the photo's bit depth.
    check_writable(args.output, photo.dtype, 4)
    if args.alpha_out:
        check_writable(args.alpha_out, photo.dtype, 1)
    guides = {}
    for flag, path in (("--trimap", args.trimap), ("--scribbles", args.scribbles)):
        if path is not None:
            guides[flag] = image = _read_guide(flag, path)
            _check_guide(flag, path, image, "the photo", args.photo, photo)
    found = extract_alpha(
        photo,
        guides.get("--trimap"),
        guides.get("--scribbles"),
        options,
        budget=_budget(args),
        progress=ProgressBar(sys.stderr),
    )
    height, width = found.image.shape[:2]
    metadata: dict[str, Any] = {
        "operation": "extract-alpha",
        "source": os.path.basename(args.photo),
        **({"trimap": os.path.basename(args.trimap)} if args.trimap else {}),
        **({"scribbles": os.path.basename(args.scribbles)} if args.scribbles else {}),
        **_extraction_record(found),
        "width": width,
        "height": height,
        "version": __version__,
    }
    # Both made before anything is written: the alpha alone is the texture's alpha channel.
    alpha = np.ascontiguousarray(found.image[..., 3])
    write_image(args.output, found.image, metadata=metadata)
    if args.alpha_out:
        write_image(args.alpha_out, alpha, metadata={**metadata, "channel": "alpha"})
    print(
        f"wrote {args.output} ({width}x{height}) in {found.timings.get('total', 0.0):.2f}s: "
        f"{_extraction_words(found)}"
    )
    if args.alpha_out:
        print(f"wrote {args.alpha_out} ({width}x{height}), the alpha alone")
    return 0


def _renderer_words(result: Result) -> str:
    """`` on <renderer>`` when a GPU (or llvmpipe) ran the backend, else nothing."""
    return f" on {result.renderer}" if result.renderer not in (None, "cpu") else ""


def companion_path(output: str | os.PathLike[str], name: str) -> Path:
    """Where the companion ``name`` of ``output`` goes: ``<output stem>_<name>.png`` beside it."""
    path = Path(output)
    return path.with_name(f"{path.stem}_{name}.png")


def _base_names(paths: str | list[str]) -> str | list[str]:
    """The file name of a path, or of each of several (what the metadata records)."""
    if isinstance(paths, str):
        return os.path.basename(paths)
    return [os.path.basename(path) for path in paths]


def _print_companions(written: dict[str, Path], width: int, height: int) -> None:
    for name, path in written.items():
        print(f"wrote {path} ({width}x{height}), companion {name!r}")


def _write_result(
    args: argparse.Namespace,
    result: Result,
    files: Mapping[str, str | list[str]],
    companions: Companions | None = None,
    extra: Mapping[str, Any] | None = None,
) -> dict[str, Path]:
    """Write the output PNG (with metadata), its companions, and the layout and seams if asked.

    ``files`` holds the operation and the input files by role; the files are recorded by
    base name, so the metadata does not depend on where the inputs were. ``extra`` is more
    metadata (an alpha extraction's). Each companion is
    quilted with the result's layout and written as ``<output stem>_<name>.png`` with the same
    metadata plus its name. Returns the companions' paths by name.
    """
    height, width = result.image.shape[:2]
    metadata: dict[str, Any] = {
        "operation": files["operation"],
        **{k: _base_names(v) for k, v in files.items() if k != "operation"},
        **{k: v for k, v in result.layout.meta.items() if k != "operation"},
        **(extra or {}),
        "width": width,
        "height": height,
        "backend_used": result.backend,
        "version": __version__,
    }
    # Quilted before anything is written, so that a failure leaves no partial set.
    quilted = {
        name: apply_layout(result.layout, image, kind=kind)
        for name, (_, image, kind) in (companions or {}).items()
    }
    write_image(args.output, result.image, metadata=metadata)
    written: dict[str, Path] = {}
    for name, image in quilted.items():
        path = companion_path(args.output, name)
        write_image(path, image, metadata={**metadata, "companion": name})
        written[name] = path
    if args.layout:
        result.layout.save(args.layout)
    if args.seams:
        write_image(args.seams, result.seam_overlay())
    if result.fallback:
        print(f"note: {result.fallback}; finished on {result.backend}", file=sys.stderr)
    return written


def _cmd_tile(args: argparse.Namespace) -> int:
    image = read_image(args.input)
    _check_outputs(args, image)
    companions = _read_companions(args, image, role="image")
    options = _field_values(args, TileOptions)
    tiled = make_tileable(image, **options, budget=_budget(args), progress=ProgressBar(sys.stderr))
    metadata = {
        "operation": "tile",
        "source": os.path.basename(args.input),
        **options,
        "version": __version__,
    }
    # Every companion is made before anything is written: a failure leaves no partial set. Each
    # gets the image's treatment for its kind (blended like it, or the pure selection: 'hard').
    mapped = {
        name: tiled.apply(companion, kind=kind) for name, (_, companion, kind) in companions.items()
    }
    write_image(args.output, tiled.image, metadata=metadata)
    height, width = tiled.image.shape[:2]
    print(
        f"wrote {args.output} ({width}x{height}), tileable along {args.axes}; "
        f"{tiled.kept.mean():.1%} of the image kept in place, "
        f"mean seam error {tiled.seam_error:.4g}"
    )
    written = {}
    for name, companion in mapped.items():
        path = companion_path(args.output, name)
        write_image(path, companion, metadata={**metadata, "companion": name})
        written[name] = path
    _print_companions(written, width, height)
    return 0


def _texture_companions(
    args: argparse.Namespace, texture: Any | None, companions: Companions
) -> Companions:
    """The ``--texture-with`` maps of a fill from a texture: one for each ``--with`` map, of the
    same name, the texture's size and the image's companion's channels and dtype."""
    if texture is None:
        if args.texture_companions:
            raise QuiltingError("--texture-with goes with --texture: there is no texture")
        return {}
    of_texture = _read_companions(
        args,
        texture,
        specs=args.texture_companions,
        flag="--texture-with",
        kinds=False,
    )
    if set(of_texture) != set(companions):
        raise QuiltingError(
            "the blocks come from --texture, so each --with NAME=PATH needs the texture's own "
            "map as --texture-with NAME=PATH (and only those): --with gives "
            f"{sorted(companions) or 'none'}, --texture-with {sorted(of_texture) or 'none'}"
        )
    for name, (path, image, _) in of_texture.items():
        ours = companions[name][1]
        if image.shape[2:] != ours.shape[2:] or image.dtype != ours.dtype:
            raise QuiltingError(
                f"--texture-with {name}: '{path}' ({_channels(image)}) must have the channels "
                f"and depth of the image's companion '{companions[name][0]}' ({_channels(ours)})"
            )
    return of_texture


def _channels(image: Any) -> str:
    """``3 channels, uint8``: an image's channels and dtype in words."""
    count = image.shape[2] if image.ndim == 3 else 1
    return f"{count} channel{'s' if count != 1 else ''}, {image.dtype}"


def _write_filled(
    args: argparse.Namespace,
    filled: Filled,
    metadata: dict[str, Any],
    companions: Companions,
    of_texture: Companions | None = None,
) -> dict[str, Path]:
    """Write a fill's or an extension's output PNG (with metadata) and its companions, each
    filled the way the image was (:meth:`quilting.Filled.apply`) before anything is written, so
    that a failure leaves no partial set. Returns the companions' paths by name."""
    height, width = filled.image.shape[:2]
    metadata = {
        **metadata,
        "width": width,
        "height": height,
        "backend_used": filled.backend,
        "version": __version__,
    }
    of_texture = of_texture or {}
    mapped = {
        name: filled.apply(image, of_texture[name][1] if name in of_texture else None)
        for name, (_, image, _) in companions.items()
    }
    write_image(args.output, filled.image, metadata=metadata)
    written: dict[str, Path] = {}
    for name, image in mapped.items():
        path = companion_path(args.output, name)
        write_image(path, image, metadata={**metadata, "companion": name})
        written[name] = path
    if args.layout:
        filled.layout.save(args.layout)
    if args.seams:
        write_image(args.seams, filled.seam_overlay())
    return written


def _cmd_fill(args: argparse.Namespace) -> int:
    # The flags of FillOptions' fields are its options: checked before any file is read.
    options = FillOptions(**_field_values(args, FillOptions))
    image = read_image(args.input)
    _check_outputs(args, image)  # the output has the image's dtype and channels
    mask = read_image(args.mask)
    texture = None if args.texture is None else read_image(args.texture)
    companions = _read_companions(args, image, role="image", kinds=False)
    of_texture = _texture_companions(args, texture, companions)
    filled = fill(
        image,
        mask,
        options,
        texture=texture,
        budget=_budget(args),
        progress=ProgressBar(sys.stderr),
    )
    files = {"source": args.input, "mask": args.mask}
    if args.texture is not None:
        files["texture"] = args.texture
    metadata = {
        "operation": "fill",
        **{role: os.path.basename(path) for role, path in files.items()},
        **options.to_dict(),
    }
    written = _write_filled(args, filled, metadata, companions, of_texture)
    height, width = filled.image.shape[:2]
    holes = int(filled.filled.sum())
    print(
        f"wrote {args.output} ({width}x{height}) in {filled.timings.get('total', 0.0):.2f}s "
        f"with the {filled.backend} backend; filled {holes} pixels "
        f"({holes / (width * height):.1%} of the image) with {filled.blocks} "
        f"{'block' if filled.blocks == 1 else 'blocks'} from the "
        f"{'texture' if filled.from_texture else 'image'}, "
        f"mean seam error {filled.seam_error:.4g}"
    )
    _print_companions(written, width, height)
    return 0


def _cmd_extend(args: argparse.Namespace) -> int:
    # The flags of ExtendOptions' fields are its options: checked before any file is read.
    options = ExtendOptions(**_field_values(args, ExtendOptions))
    image = read_image(args.input)
    _check_outputs(args, image)  # the output has the image's dtype and channels
    companions = _read_companions(args, image, role="image", kinds=False)
    filled = extend(image, options, budget=_budget(args), progress=ProgressBar(sys.stderr))
    metadata = {
        "operation": "extend",
        "source": os.path.basename(args.input),
        **options.to_dict(),
    }
    written = _write_filled(args, filled, metadata, companions)
    height, width = filled.image.shape[:2]
    print(
        f"wrote {args.output} ({width}x{height}) in {filled.timings.get('total', 0.0):.2f}s "
        f"with the {filled.backend} backend; the {image.shape[1]}x{image.shape[0]} input at "
        f"left {options.left}, top {options.top}, {int(filled.filled.sum())} pixels added "
        f"with {filled.blocks} {'block' if filled.blocks == 1 else 'blocks'}, "
        f"mean seam error {filled.seam_error:.4g}"
    )
    _print_companions(written, width, height)
    return 0


def _cmd_apply_layout(args: argparse.Namespace) -> int:
    text = Path(args.layout).read_text(encoding="utf-8")
    maps = [read_image(path) for path in args.map]
    _check_outputs(args, maps[0])
    if is_fill_layout(text):
        if len(maps) != 1:
            raise QuiltingError(
                f"a fill's layout takes one map of the image it filled, got {len(maps)}"
            )
        # A fill's layout copies pixels, never blends: a kind other than the default is moot.
        filled = FillLayout.from_json(text)
        texture = None if args.texture_map is None else read_image(args.texture_map)
        image = filled.apply(maps[0], texture)
        meta = filled.meta
    else:
        if args.texture_map is not None:
            raise QuiltingError("--texture-map goes with a fill's layout (from --texture)")
        layout = Layout.from_json(text)
        if layout.sources is None and len(maps) != 1:
            raise QuiltingError(
                f"this layout was made from one texture: give one map of its size, got {len(maps)}"
            )
        # A layout of several examples takes one map per example (the engine counts them).
        image = apply_layout(layout, maps[0] if len(maps) == 1 else maps, kind=args.kind)
        meta = layout.meta
    write_image(args.output, image, metadata={"operation": "apply-layout", **meta})
    print(f"wrote {args.output} ({image.shape[1]}x{image.shape[0]})")
    return 0


#: Largest side of a ``wang --preview`` image in pixels (a look at the set, not a product).
PREVIEW_MAX_SIDE = 16_384


def _cmd_wang(args: argparse.Namespace) -> int:
    # The flags of WangOptions' fields are its options: checked before any file is read.
    options = WangOptions(**_field_values(args, WangOptions))
    rows, cols = args.preview_size
    if args.preview and max(rows, cols) * options.tile > PREVIEW_MAX_SIDE:
        raise QuiltingError(
            f"--preview-size {cols}x{rows} of {options.tile}-pixel tiles is over "
            f"{PREVIEW_MAX_SIDE} pixels a side: give at most {PREVIEW_MAX_SIDE // options.tile} "
            "tiles a side"
        )
    images, texture = _read_examples(args.input)
    _check_outputs(args, images[0])  # the atlas has the examples' dtype and channels
    if args.preview:
        like = images[0]
        check_writable(args.preview, like.dtype, like.shape[2] if like.ndim == 3 else 1)
    manifest_path = Path(args.manifest or Path(args.output).with_suffix(".json"))
    companions = _read_companions(args, texture)
    tiles = wang_tiles(texture, options, budget=_budget(args), progress=ProgressBar(sys.stderr))

    # Everything is made before anything is written, so that a failure leaves no partial set.
    source = _base_names(args.input[0] if len(images) == 1 else list(args.input))
    atlas = tiles.atlas()
    height, width = atlas.shape[:2]
    metadata: dict[str, Any] = {
        **tiles.meta,
        "source": source,
        "tiles": len(tiles.tiles),
        "width": width,
        "height": height,
        "version": __version__,
    }
    of_companions = {
        name: tiles.apply(maps, kind=kind) for name, (_, maps, kind) in companions.items()
    }
    # (path, image, metadata, companion name or None), written in this order.
    images_out: list[tuple[Path, Any, dict[str, Any], str | None]] = [
        (Path(args.output), atlas, metadata, None)
    ]
    images_out += [
        (companion_path(args.output, name), tiles.atlas(made), metadata, name)
        for name, made in of_companions.items()
    ]
    if args.preview:
        seed = options.seed if args.preview_seed is None else args.preview_seed
        arrangement = tiles.arrange(rows, cols, seed)
        preview = tiles.render(arrangement)
        shown = {
            **metadata,
            "preview": {"columns": cols, "rows": rows, "seed": seed},
            "width": preview.shape[1],
            "height": preview.shape[0],
        }
        images_out.append((Path(args.preview), preview, shown, None))
        images_out += [
            (companion_path(args.preview, name), tiles.render(arrangement, made), shown, name)
            for name, made in of_companions.items()
        ]
    manifest = tiles.manifest() | {
        "image": os.path.basename(args.output),
        "source": source,
        "companions": {name: companion_path(args.output, name).name for name in of_companions},
    }

    for path, image, meta, name in images_out:
        write_image(path, image, metadata=meta if name is None else {**meta, "companion": name})
    manifest_path.write_text(json.dumps(manifest, indent=1) + "\n", encoding="utf-8")
    print(
        f"wrote {args.output} ({width}x{height}) in {tiles.timings['total']:.2f}s: "
        f"{len(tiles.tiles)} tiles of {tiles.tile}x{tiles.tile}, {tiles.colors} colours per "
        f"edge, manifest {manifest_path}"
    )
    for path, image, _, name in images_out[1:]:
        what = f"companion {name!r}" if name else f"an aperiodic arrangement of {cols}x{rows} tiles"
        print(f"wrote {path} ({image.shape[1]}x{image.shape[0]}), {what}")
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    print(f"quilting {__version__} (numpy {np.__version__}, python {sys.version.split()[0]})")
    print("backends:")
    for status in available_backends():
        mark = "yes" if status.available else "no "
        print(f"  {status.name:<10} {mark}  {status.reason}")
        if status.renderer is not None and status.renderer != "cpu":
            print(f"  {'':<10}      renderer: {status.renderer}")
    concrete, why = auto_choice()
    print(f"  auto       -> {concrete}  ({why})")
    return 0


@contextlib.contextmanager
def _needs_extra(extra: str, who: str) -> Iterator[None]:
    """Imports of an optional extra: one missing is a clear error, not a traceback."""
    try:
        yield
    except ImportError as exc:
        raise QuiltingError(f"{who} needs the '{extra}' extra ({exc.name} is missing)") from None


def _cmd_serve(args: argparse.Namespace) -> int:
    with _needs_extra("server", "the service"):
        from quilting.service.server import serve
        from quilting.service.settings import Settings
    serve(Settings.from_env(host=args.host, port=args.port, workers=args.workers, queue=args.queue))
    return 0


def _cmd_worker(args: argparse.Namespace) -> int:
    with _needs_extra("queue", "quilting worker"):
        from quilting.service.jobs.dramatiq_queue import run_worker
        from quilting.service.settings import Settings
    settings = Settings.from_env(queue=args.queue)
    if settings.queue == "memory":
        raise QuiltingError(
            "quilting worker takes jobs from Redis: set QUILTING_QUEUE=redis://HOST:6379/0 "
            "or pass --queue"
        )
    if args.gpu is not None:
        if args.gpu < 0:
            raise QuiltingError(f"--gpu must be a device index >= 0, got {args.gpu}")
        # The gl backend opens this EGL device: one worker process per GPU.
        os.environ[GL_DEVICE_VARIABLE] = str(args.gpu)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    run_worker(settings)
    return 0


def _add_option(
    parser: argparse.ArgumentParser,
    options: OptionsClass,
    name: str,
    **kwargs: Any,
) -> None:
    """Add ``--name`` with its help and default taken from the field ``name`` of ``options``."""
    kwargs.setdefault("default", _option_default(name, options))
    kwargs.setdefault("help", _option_help(name, options))
    flag = "--" + name.replace("_", "-")
    parser.add_argument(flag, **kwargs)


def _add_fields(
    parser: argparse.ArgumentParser,
    options: OptionsClass,
    *,
    skip: Sequence[str] = (),
) -> None:
    """A flag for every field of ``options`` but those in ``skip``, in the fields' order:
    ``--name-with-dashes``, its type, choices and help (with the default) from the field and
    its metadata, so that a new option needs no line here."""
    for f in fields(options):
        if f.name in skip:
            continue
        meta = f.metadata
        kind = meta.get("kind")
        if kind == "color_ranges":
            parser.add_argument(
                "--exclude-color",
                dest=f.name,
                action="append",
                type=_colour_range,
                default=[],
                metavar="LOW:HIGH",
                help="a colour range never to use, e.g. 120,120,120:255,255,255 (repeatable). "
                + _option_doc(f.name, options),
            )
        elif kind == "direction":
            _add_option(
                parser, options, f.name, type=_light, metavar="X,Y,Z",
                help="direction towards the light, e.g. 1,1,2 (write --light=-1,1,2 when x is "
                "negative, so it is not read as a flag). " + _option_doc(f.name, options),
            )  # fmt: skip
        elif kind == "transforms":
            _add_option(
                parser, options, f.name, type=_checked(options, f.name, str),
                metavar="NAME[,NAME...]",
                help="a preset or transforms' names, comma-separated (e.g. --transforms all, "
                "--transforms rot90,flip_x). " + _option_help(f.name, options),
            )  # fmt: skip
        elif kind == "weights":
            _add_option(
                parser, options, f.name, type=_checked(options, f.name, _numbers),
                metavar="W[,W...]",
                help="one number > 0 per input image, comma-separated in the inputs' order, "
                "e.g. --weights 2,1,1. " + _option_help(f.name, options),
            )  # fmt: skip
        elif kind == "bool":
            _add_option(parser, options, f.name, action=argparse.BooleanOptionalAction)
        elif (choices := offered_choices(f)) is not None:
            _add_option(parser, options, f.name, choices=choices)
        else:
            number = int if isinstance(meta.get("ge"), int) else float
            _add_option(parser, options, f.name, type=number, metavar=_METAVARS.get(f.name))


_METAVARS = {"discard": "P"}


def _numbers(text: str) -> tuple[float, ...]:
    """Comma-separated numbers, e.g. ``2,1,1``."""
    try:
        return tuple(float(part) for part in text.split(","))
    except ValueError:
        raise ValueError(f"{text!r} is not comma-separated numbers, e.g. 2,1,1") from None


def _integer(text: str) -> int:
    """A whole number, e.g. ``7``."""
    try:
        return int(text)
    except ValueError:
        raise ValueError(f"{text!r} is not a whole number") from None


def _checked(options: OptionsClass, name: str, parse: Callable[[str], Any]) -> Callable[[str], Any]:
    """The argparse type of the field ``name`` of ``options``: the text parsed by ``parse``,
    then validated, and normalized, by the options class itself (its field's own rule, so the
    flag cannot accept what the options refuse); a bad value is an argparse error naming the
    field and what is allowed."""

    def convert(text: str) -> Any:
        try:
            value = parse(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(f"{name}: {exc}") from None
        try:
            return getattr(options(**{name: value}), name)
        except InvalidParameterError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    convert.__name__ = name
    return convert


def _field_values(args: argparse.Namespace, options: OptionsClass) -> dict[str, Any]:
    """The value of every field of ``options`` from its flag (:func:`_add_fields`)."""
    return {f.name: getattr(args, f.name) for f in fields(options)}


def _add_source_mask(parser: argparse.ArgumentParser, *, several: bool = False) -> None:
    if not several:
        parser.add_argument(
            "--source-mask",
            metavar="MASK.png",
            help="an image of the texture's size whose black pixels are never used",
        )
        return
    parser.add_argument(
        "--source-mask",
        action="append",
        metavar="MASK.png",
        help="an image of the input's size whose black pixels are never used; with several "
        "inputs, give it once per input, in the inputs' order (repeatable)",
    )


def _add_guides(parser: argparse.ArgumentParser, *, layers: bool = False) -> None:
    """``--trimap`` and ``--scribbles``: once per input (``synth``), or ``LAYER=FILE`` for
    the layers that are photos (``matte``)."""
    for flag, metavar, what in (
        ("--trimap", "TRIMAP.png", TRIMAP_HELP),
        ("--scribbles", "STROKES.png", SCRIBBLES_HELP),
    ):
        if layers:
            parser.add_argument(
                flag,
                action="append",
                default=[],
                metavar=f"LAYER={metavar}",
                help=f"the layer numbered LAYER (1 for the first --layer, bottom first) is an "
                f"ordinary photo (no alpha): its alpha is extracted first (--matting), then it "
                f"is alpha-quilted; the map is {what} (repeatable, once per such layer)",
            )
        else:
            parser.add_argument(
                flag,
                action="append",
                metavar=metavar,
                help=f"{EXTRACTED_HELP}; the map is {what}. With several inputs, give it once "
                f"per input, in the inputs' order ({flag}='' for an input without one) "
                "(repeatable)",
            )


#: The help of an input that may be several examples of one texture.
INPUTS_HELP = (
    "texture sample (PNG or JPEG); several are several examples of one texture (one channel "
    "count and bit depth, any sizes), blocks taken from all of them"
)


def _tile_count(text: str) -> tuple[int, int]:
    """``COLSxROWS`` of tiles (or one number for a square) as (rows, cols), each >= 1."""
    try:
        rows, cols = _size(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"{text!r} is not COLSxROWS, e.g. 6x6") from None
    if rows < 1 or cols < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: give at least one tile each way, e.g. 6x6")
    return rows, cols


def _bytes(text: str) -> int:
    """A size such as ``2G``, ``512M``, ``300K`` or plain bytes (binary units)."""
    units = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}
    raw = text.strip().upper().removesuffix("B").removesuffix("I")
    scale = units.get(raw[-1:], 1)
    number = raw[:-1] if raw[-1:] in units else raw
    try:
        value = float(number) * scale
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a size such as 2G, 512M or 1048576, got {text!r}"
        ) from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"a size must be > 0, got {text!r}")
    return int(value)


def _add_budget(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--memory-budget",
        type=_bytes,
        metavar="SIZE",
        help="refuse, before any work, a job whose predicted peak memory is over SIZE "
        "(e.g. 2G; the job's own process, interpreter included); off by default",
    )
    parser.add_argument(
        "--time-budget",
        type=float,
        metavar="SECONDS",
        help="refuse, before any work, a job predicted to take longer; off by default",
    )


def _budget(args: argparse.Namespace) -> Budget | None:
    """The ``--memory-budget``/``--time-budget`` flags as a Budget, or None for neither."""
    if args.memory_budget is None and args.time_budget is None:
        return None
    try:
        return Budget(memory_bytes=args.memory_budget, seconds=args.time_budget)
    except ValueError as exc:
        raise QuiltingError(f"--memory-budget/--time-budget: {exc}") from None


#: What --with says of a command that takes several input images.
SEVERAL_MAPS_HELP = (
    "; with several inputs, PATH is one map per input, comma-separated in the inputs' order "
    "(NAME=A_normal.png,B_normal.png), each of its input's size"
)


def _add_output_files(parser: argparse.ArgumentParser, *, several: bool = False) -> None:
    parser.add_argument(
        "--with",
        dest="companions",
        action="append",
        default=[],
        metavar="NAME[:KIND]=PATH[,PATH...]" if several else "NAME[:KIND]=PATH",
        help="a companion map of the texture's size (normal, roughness, height...) to quilt "
        "with the output's layout; written as <OUT stem>_<NAME>.png beside the output "
        "(repeatable; NAME is 1 to 64 of A-Z a-z 0-9 _ -; KIND, when the seams are blended: "
        + COMPANION_KIND_HELP
        + (SEVERAL_MAPS_HELP if several else "")
        + ")",
    )
    parser.add_argument("--layout", metavar="OUT.json", help="also write the block layout as JSON")
    parser.add_argument(
        "--seams", metavar="OUT.png", help="also write the seams drawn over the output"
    )


def _add_fill_companions(parser: argparse.ArgumentParser, role: str) -> None:
    parser.add_argument(
        "--with",
        dest="companions",
        action="append",
        default=[],
        metavar="NAME=PATH",
        help=f"a companion map of the {role}'s size (normal, roughness, height...) filled the "
        "same way: each new pixel copied from where the output's came from, never blended; "
        "written as <OUT stem>_<NAME>.png beside the output (repeatable; NAME is 1 to 64 of "
        "A-Z a-z 0-9 _ -)",
    )
    parser.add_argument(
        "--layout",
        metavar="OUT.json",
        help="also write the fill's layout as JSON (every block, where it came from and the "
        "pixels it took), for quilting apply-layout",
    )
    parser.add_argument(
        "--seams", metavar="OUT.png", help="also write the seams drawn over the output"
    )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``quilting`` command."""
    parser = argparse.ArgumentParser(
        prog="quilting", description="Texture synthesis by image quilting (Efros & Freeman 2001)."
    )
    parser.add_argument("--version", action="version", version=f"quilting {__version__}")
    commands = parser.add_subparsers(dest="command", required=True)

    synth = commands.add_parser(
        "synth", help="synthesize a larger texture from a sample (or several of one texture)"
    )
    synth.add_argument("input", nargs="+", help=INPUTS_HELP)
    synth.add_argument("-o", "--output", required=True, help=OUTPUT_HELP)
    synth.add_argument(
        "--size", type=_size, required=True, help="output WIDTHxHEIGHT, e.g. 512x512"
    )
    _add_fields(synth, SynthesisOptions)
    _add_budget(synth)
    _add_source_mask(synth, several=True)
    _add_guides(synth)
    _add_output_files(synth, several=True)
    synth.set_defaults(run=_cmd_synth)

    transfer_cmd = commands.add_parser(
        "transfer", help="render a target image in the texture of a sample (texture transfer)"
    )
    transfer_cmd.add_argument("texture", help="texture to render with (PNG or JPEG)")
    transfer_cmd.add_argument("target", help="image to render; the output has its size")
    transfer_cmd.add_argument("-o", "--output", required=True, help=OUTPUT_HELP)
    _add_fields(transfer_cmd, TransferOptions)
    _add_budget(transfer_cmd)
    # No default: left out, it is the options' default, or 'custom' with maps.
    transfer_cmd.set_defaults(correspondence=None)
    _add_source_mask(transfer_cmd)
    transfer_cmd.add_argument(
        "--source-map",
        metavar="MAP.png",
        help="your own correspondence map of the texture (its size); with --target-map it "
        "replaces the computed one",
    )
    transfer_cmd.add_argument(
        "--target-map",
        metavar="MAP.png",
        help="your own correspondence map of the target (its size, the source map's channels)",
    )
    _add_output_files(transfer_cmd)
    transfer_cmd.set_defaults(run=_cmd_transfer)

    matte_cmd = commands.add_parser(
        "matte",
        help="lay textures on the surface of an object in an image (texture matting)",
    )
    matte_cmd.add_argument("target", help="image with the object; the output has its size")
    matte_cmd.add_argument(
        "--silhouette",
        required=True,
        metavar="MASK.png",
        help="the target's size: white (or opaque) where the surface is, black elsewhere",
    )
    matte_cmd.add_argument(
        "--layer",
        dest="layers",
        action="append",
        required=True,
        metavar="TEXTURE.png",
        help="a texture to lay on the surface (repeatable, bottom first: opaque ones first, "
        "then RGBA ones, which are alpha-quilted)",
    )
    matte_cmd.add_argument("-o", "--output", required=True, help=OUTPUT_HELP)
    matte_cmd.add_argument(
        "--normals",
        metavar="MAP.png",
        help="a normal map of the target's size ((n + 1) / 2 colours, +y up) to use instead "
        "of the one read from the shading",
    )
    _add_fields(matte_cmd, MatteOptions)
    _add_budget(matte_cmd)
    matte_cmd.set_defaults(source_mask=None)
    _add_guides(matte_cmd, layers=True)
    matte_cmd.add_argument(
        "--normals-out", metavar="OUT.png", help="also write the normals used, as a normal map"
    )
    matte_cmd.add_argument(
        "--clusters-out",
        metavar="OUT.png",
        help="also write the patches (connected parts of the clusters) in distinct colours",
    )
    matte_cmd.set_defaults(run=_cmd_matte)

    tile = commands.add_parser(
        "tile", help="make an existing image repeat seamlessly (same size, centre kept)"
    )
    tile.add_argument("input", help="image to make tileable (PNG or JPEG)")
    tile.add_argument("-o", "--output", required=True, help=OUTPUT_HELP)
    _add_fields(tile, TileOptions)
    tile.add_argument(
        "--with",
        dest="companions",
        action="append",
        default=[],
        metavar="NAME[:KIND]=PATH",
        help="a companion map of the image's size to rearrange the same way; written as "
        "<OUT stem>_<NAME>.png beside the output (repeatable; NAME is 1 to 64 of A-Z a-z 0-9 "
        "_ -; KIND, when --blend is poisson: " + COMPANION_KIND_HELP + ")",
    )
    _add_budget(tile)
    tile.set_defaults(run=_cmd_tile)

    fill_cmd = commands.add_parser(
        "fill",
        help="fill the masked pixels of an image (remove a stain, a logo) from the rest of it",
    )
    fill_cmd.add_argument("input", help="image with a hole to fill (PNG or JPEG)")
    fill_cmd.add_argument(
        "--mask",
        required=True,
        metavar="MASK.png",
        help="the image's size: white (any colour channel above 0) where to fill, black where "
        "to keep; a pixel of alpha 0 is kept. Every other pixel is written unchanged",
    )
    fill_cmd.add_argument("-o", "--output", required=True, help=OUTPUT_HELP)
    fill_cmd.add_argument(
        "--texture",
        metavar="TEXTURE.png",
        help="take the blocks from this texture (the image's channels and depth) instead of "
        "from the image outside the mask; needed when the mask covers the whole image",
    )
    _add_fields(fill_cmd, FillOptions)
    _add_budget(fill_cmd)
    _add_fill_companions(fill_cmd, "image")
    fill_cmd.add_argument(
        "--texture-with",
        dest="texture_companions",
        action="append",
        default=[],
        metavar="NAME=PATH",
        help="with --texture: the texture's own map for each --with NAME (its size, the "
        "companion's channels), where the filled companion pixels are copied from (repeatable)",
    )
    fill_cmd.set_defaults(run=_cmd_fill)

    extend_cmd = commands.add_parser(
        "extend",
        help="grow an image past its borders (uncrop), the image kept unchanged inside",
    )
    extend_cmd.add_argument("input", help="image to extend (PNG or JPEG)")
    extend_cmd.add_argument("-o", "--output", required=True, help=OUTPUT_HELP)
    _add_fields(extend_cmd, ExtendOptions)
    _add_budget(extend_cmd)
    _add_fill_companions(extend_cmd, "input")
    extend_cmd.set_defaults(run=_cmd_extend)

    wang = commands.add_parser(
        "wang",
        help="quilt a set of Wang tiles (an atlas and its manifest) for aperiodic tiling",
    )
    wang.add_argument("input", nargs="+", help=INPUTS_HELP)
    wang.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="ATLAS",
        help="the atlas: every tile in one image, colors^2 by colors^2 tiles, tile k at row "
        "k // colors^2, column k %% colors^2; " + OUTPUT_HELP,
    )
    wang.add_argument(
        "--manifest",
        metavar="TILES.json",
        help="where to write the manifest: the tile size, the colours and, for every tile, "
        "its place in the atlas and its edge colours n, e, s, w (default: the atlas's name "
        "with .json)",
    )
    wang.add_argument(
        "--preview",
        metavar="OUT.png",
        help="also write an image of an aperiodic arrangement of the tiles (and of each "
        "companion's, as <OUT stem>_<NAME>.png)",
    )
    wang.add_argument(
        "--preview-size",
        type=_tile_count,
        default=(6, 6),
        metavar="COLSxROWS",
        help="tiles across and down the preview (default: 6x6)",
    )
    wang.add_argument(
        "--preview-seed",
        type=_checked(WangOptions, "seed", _integer),
        metavar="N",
        help="seed of the preview's arrangement (default: --seed)",
    )
    _add_fields(wang, WangOptions)
    _add_budget(wang)
    wang.add_argument(
        "--with",
        dest="companions",
        action="append",
        default=[],
        metavar="NAME[:KIND]=PATH[,PATH...]",
        help="a companion map of the input's size (normal, roughness, height...) cut into the "
        "same tiles; its atlas is written as <ATLAS stem>_<NAME>.png beside the atlas "
        "(repeatable; NAME is 1 to 64 of A-Z a-z 0-9 _ -; KIND: " + COMPANION_KIND_HELP
        + SEVERAL_MAPS_HELP + ")",
    )  # fmt: skip
    wang.set_defaults(run=_cmd_wang)

    extract = commands.add_parser(
        "extract-alpha",
        help="make an RGBA texture from an ordinary photo and a trimap or scribbles (matting)",
    )
    extract.add_argument(
        "photo", help="photo to take the texture from (PNG or JPEG; gray or RGB, no alpha)"
    )
    extract.add_argument(
        "--trimap", metavar="TRIMAP.png", help=TRIMAP_HELP + " (this, --scribbles, or both)"
    )
    extract.add_argument("--scribbles", metavar="STROKES.png", help=SCRIBBLES_HELP)
    extract.add_argument(
        "-o",
        "--output",
        required=True,
        help="the RGBA texture: the foreground's colour and the alpha, in the photo's bit "
        "depth (.png: it has alpha)",
    )
    extract.add_argument(
        "--alpha-out",
        metavar="OUT.png",
        help="also write the alpha alone, as a gray image in the photo's bit depth",
    )
    _add_fields(extract, AlphaOptions)
    _add_budget(extract)
    extract.set_defaults(run=_cmd_extract_alpha)

    apply = commands.add_parser(
        "apply-layout", help="quilt a companion map (normal, roughness...) with a saved layout"
    )
    apply.add_argument("layout", help="layout JSON written by synth, fill or extend --layout")
    apply.add_argument(
        "map",
        nargs="+",
        help="map of the same size as the original texture (a fill's: the image; an "
        "extension's: the input) (PNG or JPEG); for a layout made from several inputs, one "
        "map per input, in the same order",
    )
    apply.add_argument(
        "--texture-map",
        metavar="PATH",
        help="a fill from --texture: the texture's own map, where the new pixels come from",
    )
    apply.add_argument("-o", "--output", required=True, help=OUTPUT_HELP)
    apply.add_argument(
        "--kind",
        choices=COMPANION_KINDS,
        default="blend",
        help=COMPANION_KIND_HELP,
    )
    apply.set_defaults(run=_cmd_apply_layout)

    serve = commands.add_parser(
        "serve", help="run the HTTP service (settings from QUILTING_* variables and these flags)"
    )
    serve.add_argument("--host", default=None, help="address to listen on (default 127.0.0.1)")
    serve.add_argument("--port", type=int, default=None, help="TCP port (default 8000)")
    serve.add_argument(
        "--workers",
        type=int,
        default=None,
        help="compute workers, jobs run at once (default: one per core)",
    )
    serve.add_argument(
        "--queue",
        default=None,
        help="memory (default) or a Redis URL: jobs go to `quilting worker` processes",
    )
    serve.set_defaults(run=_cmd_serve)

    worker = commands.add_parser(
        "worker",
        help="compute the jobs of a Redis queue, one at a time (run one per GPU or per core)",
    )
    worker.add_argument(
        "--queue", default=None, help="Redis URL (default: the QUILTING_QUEUE variable)"
    )
    worker.add_argument(
        "--gpu",
        type=int,
        default=None,
        help=f"EGL device index of this worker's GPU (sets {GL_DEVICE_VARIABLE})",
    )
    worker.set_defaults(run=_cmd_worker)

    info = commands.add_parser("info", help="version and available backends")
    info.set_defaults(run=_cmd_info)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.run(args))
    except QuiltingError as exc:
        parser.exit(2, f"quilting: error: {exc}\n")
    except KeyboardInterrupt:
        parser.exit(130, "quilting: interrupted\n")


if __name__ == "__main__":
    sys.exit(main())
