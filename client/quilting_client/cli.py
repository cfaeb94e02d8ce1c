"""``quilting-remote``: synthesize, transfer, matte, fill, extend, tile and make Wang tiles on
a quilting service from the command line.

``synth`` (from one sample or several examples of one texture), ``transfer``, ``matte``,
``fill`` (the masked pixels of an image synthesized again), ``extend`` (an image grown past its
borders) and ``wang`` (a complete set of Wang tiles: the atlas and its manifest) run as jobs on
the service; ``tile`` (make an image repeat seamlessly) is answered at once.

Errors are printed as one line (``quilting-remote: error: ...``), without a traceback. The
exit status says whose move it is: 2 for what the user can fix (arguments, files, a request the
service rejected with a 4xx), 1 for the service or the network failing.

The service is the one ``--server URL`` (or ``--url``) names, else ``$QUILTING_URL``, else
http://127.0.0.1:8000, where ``quilting serve`` listens by default.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import struct
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, TextIO

from quilting_client import _options
from quilting_client._sync import Client
from quilting_client._uploads import COMPANION_KINDS
from quilting_client._version import __version__
from quilting_client._waiting import ProgressCallback
from quilting_client.errors import (
    ConnectionFailedError,
    JobError,
    QuiltingClientError,
    WaitTimeoutError,
)
from quilting_client.models import SynthesisResult, WangTilesResult

PROG = "quilting-remote"
#: Where the remote commands look for the service when neither --server nor QUILTING_URL says.
DEFAULT_URL = "http://127.0.0.1:8000"

#: The options ``synth`` takes as ``--size WxH`` rather than flags of their own.
SIZE = ("width", "height")
#: The options of ``extend`` that are the client's keywords of their own.
MARGINS = ("top", "bottom", "left", "right")

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

#: What a companion may be called: the service's rule (``quilting synth --with`` has the same).
_COMPANION_NAME = re.compile(r"[A-Za-z0-9_-]{1,64}")

#: Runs one operation on the client: (client, companions, progress) -> the result. A
#: companion is one path, or with several inputs one path per input.
Operation = Callable[[Client, Mapping[str, Any] | None, ProgressCallback | None], SynthesisResult]

#: What the colours of a trimap and the strokes of scribbles say (every --trimap/--scribbles).
TRIMAP_HELP = (
    "a trimap of the photo's size: white where it is surely the texture, black where surely "
    "background, grey where the alpha is to be found"
)
SCRIBBLES_HELP = (
    "scribbles of the photo's size: white (texture) and black (background) strokes, the rest "
    "transparent or grey; drawn over the trimap when both come"
)
#: What happens to a photo given with a trimap or scribbles.
EXTRACTED_HELP = (
    "the input is an ordinary photo (no alpha): the service extracts its alpha and foreground "
    "colour first (--matting) and alpha-quilts the RGBA texture"
)

#: The help of an input that may be several examples of one texture.
INPUTS_HELP = (
    "texture sample (PNG or JPEG); several are several examples of one texture (one channel "
    "count and bit depth, any sizes), blocks taken from all of them"
)


def make_client(server: str, api_key: str | None) -> Client:
    """Build the client the command uses.

    A seam: tests replace it to give the client a fake transport.

    Parameters
    ----------
    server : str
        The service's base URL.
    api_key : str or None
        The API key, if any.

    Returns
    -------
    Client
    """
    return Client(server, api_key)


class UsageError(Exception):
    """A mistake in the command line that argparse cannot see (exit status 2)."""


class ProgressBar:
    """A one-line progress bar on a terminal; silent when the stream is not a terminal.

    Parameters
    ----------
    stream : TextIO
        Where to draw (stderr, so that stdout stays clean for the summary).
    width : int
        Characters of the bar itself.
    """

    def __init__(self, stream: TextIO, width: int = 30) -> None:
        self.stream = stream
        self.width = width
        self.enabled = stream.isatty()
        self.started = time.perf_counter()
        self._open_line = False

    def __call__(self, fraction: float, stage: str) -> None:
        if not self.enabled:
            return
        fraction = min(max(fraction, 0.0), 1.0)
        filled = round(fraction * self.width)
        bar = "#" * filled + "-" * (self.width - filled)
        elapsed = time.perf_counter() - self.started
        self.stream.write(f"\r{stage[:10]:<10} [{bar}] {fraction:6.1%} {elapsed:6.1f}s")
        self._open_line = True
        if fraction >= 1.0:
            self.end()
        self.stream.flush()

    def end(self) -> None:
        """End the bar's line, so that what is printed next starts on its own line."""
        if self._open_line:
            self.stream.write("\n")
            self.stream.flush()
            self._open_line = False


def _size(text: str) -> tuple[int, int]:
    """Parse ``WxH`` (or one number for a square) into (width, height)."""
    parts = text.lower().split("x")
    try:
        numbers = [int(p) for p in parts]
    except ValueError:
        numbers = []
    if len(numbers) == 1:
        numbers *= 2
    if len(numbers) != 2 or min(numbers) <= 0:
        raise argparse.ArgumentTypeError(f"size {text!r} is not WIDTHxHEIGHT, e.g. 512x512")
    return numbers[0], numbers[1]


def _companion_kinds(specs: Sequence[str]) -> dict[str, str]:
    """The kinds of the ``--with NAME:KIND=PATH`` arguments by name (those given one; the
    others are 'blend'). :func:`_companions` has checked the arguments."""
    kinds: dict[str, str] = {}
    for spec in specs:
        name, colon, kind = spec.partition("=")[0].partition(":")
        if colon:
            kinds[name] = kind
    return kinds


def _companions(specs: Sequence[str], inputs: int = 1) -> dict[str, str | list[str]]:
    """Parse the ``--with NAME[:KIND]=PATH`` arguments into paths by name, checking each;
    with several ``inputs``, PATH is one path per input, comma-separated in their order.

    The names and files are checked here, before anything is sent; the sizes (a companion has
    the texture's) only the service can check, which answers 422 ``invalid_companion``.
    """
    companions: dict[str, str | list[str]] = {}
    for spec in specs:
        named, equals, path = spec.partition("=")
        if not equals or not path:
            raise UsageError(f"--with {spec!r} is not NAME[:KIND]=PATH, e.g. normal=normal.png")
        name, colon, kind = named.partition(":")
        if colon and kind not in COMPANION_KINDS:
            raise UsageError(
                f"--with {spec!r}: the kind {kind!r} is not one of {', '.join(COMPANION_KINDS)}"
            )
        if not _COMPANION_NAME.fullmatch(name):
            raise UsageError(
                f"--with {spec!r}: the name {name!r} is not 1 to 64 of A-Z a-z 0-9 _ -"
            )
        if name in companions:
            raise UsageError(f"--with: the companion {name!r} is given twice")
        paths = path.split(",") if inputs > 1 else [path]
        if len(paths) != inputs:
            raise UsageError(
                f"--with {spec!r}: with {inputs} input images give {inputs} comma-separated "
                "paths, one map per input in the same order"
            )
        for one in paths:
            if not os.path.isfile(one):
                raise UsageError(f"companion {name!r}: no such file: {one}")
        companions[name] = paths if inputs > 1 else path
    return companions


def _png_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a PNG's IHDR chunk, or None if ``data`` is not a PNG."""
    if len(data) < 24 or not data.startswith(_PNG_SIGNATURE) or data[12:16] != b"IHDR":
        return None
    width, height = struct.unpack(">II", data[16:24])
    return int(width), int(height)


def _add_connection(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-o", "--output", required=True, help="output PNG (a .png name)")
    parser.add_argument(
        "--server",
        "--url",
        dest="server",
        help=f"base URL of the service (default: $QUILTING_URL, else {DEFAULT_URL})",
    )
    parser.add_argument("--api-key", help="API key (default: $QUILTING_API_KEY)")


def _add_companions_and_timeout(
    parser: argparse.ArgumentParser, along: str | None = None, several: bool = False
) -> None:
    """``--with`` and ``--timeout``; ``along`` (a fill's or an extension's) says how the
    companions follow the image, whose size they have, and they take no KIND; ``several``
    (synth's): one map per input image, comma-separated."""
    if along is None:
        metavar = "NAME[:KIND]=PATH[,PATH...]" if several else "NAME[:KIND]=PATH"
        what = (
            "a companion map of the texture's size to quilt along (repeatable; NAME is 1 to "
            "64 of A-Z a-z 0-9 _ -; KIND is blend (the default), hard (masks, IDs: never "
            "mixed), normal or normal_dx (OpenGL's or DirectX's normal maps: renormalized to "
            "unit vectors, turned with rotated blocks))"
            + (
                "; with several inputs, PATH is one map per input, comma-separated in the "
                "inputs' order, each of its input's size"
                if several
                else ""
            )
        )
    else:
        metavar = "NAME=PATH"
        what = (
            f"a companion map of the image's size, {along} (repeatable; NAME is 1 to 64 of "
            "A-Z a-z 0-9 _ -)"
        )
    parser.add_argument(
        "--with",
        dest="companions",
        action="append",
        default=[],
        metavar=metavar,
        help=f"{what}; written as <OUT stem>_<NAME>.png beside the output",
    )
    parser.add_argument(
        "--timeout", type=float, help="seconds to wait for the job (default: no limit)"
    )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``quilting-remote``.

    Returns
    -------
    argparse.ArgumentParser
    """
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Synthesize, transfer, matte, fill, extend and tile textures on a quilting "
        "HTTP service.",
    )
    parser.add_argument("--version", action="version", version=f"quilting-client {__version__}")
    commands = parser.add_subparsers(dest="command", required=True)

    synth = commands.add_parser(
        "synth", help="synthesize a larger texture from a sample (or several of one texture)"
    )
    synth.add_argument("input", nargs="+", help=INPUTS_HELP)
    _add_connection(synth)
    synth.add_argument(
        "--size", type=_size, required=True, help="output WIDTHxHEIGHT, e.g. 512x512"
    )
    synth.add_argument(
        "--source-mask",
        dest="source_masks",
        action="append",
        default=[],
        metavar="MASK",
        help="an image of the input's size whose black pixels are never used; with several "
        "inputs, give it once per input, in the inputs' order (repeatable)",
    )
    _add_marks(synth)
    _options.add_option_flags(synth, "synthesize", skip=SIZE)
    _add_companions_and_timeout(synth, several=True)
    synth.set_defaults(run=_cmd_synth)

    transfer = commands.add_parser(
        "transfer", help="render a target image in the texture of a sample (texture transfer)"
    )
    transfer.add_argument("texture", help="texture to render with (PNG or JPEG)")
    transfer.add_argument("target", help="image to render (PNG or JPEG); the output has its size")
    _add_connection(transfer)
    _options.add_option_flags(transfer, "transfer")
    _add_companions_and_timeout(transfer)
    transfer.set_defaults(run=_cmd_transfer)

    matte = commands.add_parser(
        "matte", help="lay textures on the surface of an object in an image (texture matting)"
    )
    matte.add_argument(
        "target", help="image with the object (PNG or JPEG); the output has its size"
    )
    matte.add_argument(
        "--silhouette",
        required=True,
        metavar="MASK",
        help="the target's size: white (or opaque) where the surface is, black elsewhere",
    )
    matte.add_argument(
        "--layer",
        dest="layers",
        action="append",
        required=True,
        metavar="TEXTURE",
        help="a texture to lay on the surface (repeatable, bottom first: opaque ones first, "
        "then RGBA ones, which are alpha-quilted)",
    )
    _add_connection(matte)
    matte.add_argument(
        "--normals",
        metavar="MAP",
        help="a normal map of the target's size ((n + 1) / 2 colours, +y up) to use instead of "
        "the one read from the shading",
    )
    _add_marks(matte, layers=True)
    _options.add_option_flags(matte, "matte")
    matte.add_argument(
        "--normals-out", metavar="OUT", help="also write the normals used, as a normal map"
    )
    matte.add_argument(
        "--clusters-out",
        metavar="OUT",
        help="also write the patches (connected parts of the clusters) in distinct colours",
    )
    matte.add_argument(
        "--timeout", type=float, help="seconds to wait for the job (default: no limit)"
    )
    matte.set_defaults(run=_cmd_matte)

    fill = commands.add_parser(
        "fill", help="fill the masked pixels of an image (remove an object, a stain, a logo)"
    )
    fill.add_argument("input", help="image to fill (PNG or JPEG); the output has its size")
    fill.add_argument(
        "--mask",
        required=True,
        metavar="MASK",
        help="the image's size: white (any colour above 0) where to fill, black where to keep; "
        "with alpha, transparent pixels are kept (a PNG: JPEG's noise marks pixels)",
    )
    fill.add_argument(
        "--texture",
        metavar="TEXTURE",
        help="take the blocks from this texture (the image's channels and bit depth) instead "
        "of the image; needed when the mask covers all of it",
    )
    _add_connection(fill)
    _options.add_option_flags(fill, "fill")
    _add_companions_and_timeout(fill, along="filled the same way")
    fill.set_defaults(run=_cmd_fill)

    extend = commands.add_parser(
        "extend", help="grow an image past its borders (uncrop): --top, --bottom, --left, --right"
    )
    extend.add_argument("input", help="image to extend (PNG or JPEG); kept unchanged in the output")
    _add_connection(extend)
    _options.add_option_flags(extend, "extend")
    _add_companions_and_timeout(extend, along="extended the same way")
    extend.set_defaults(run=_cmd_extend)

    extract = commands.add_parser(
        "extract-alpha",
        help="make an RGBA texture from an ordinary photo and a trimap or scribbles (matting)",
    )
    extract.add_argument("input", help="the photo (PNG or JPEG, gray or RGB: no alpha)")
    extract.add_argument(
        "--trimap", metavar="TRIMAP.png", help=TRIMAP_HELP + " (this, --scribbles, or both)"
    )
    extract.add_argument("--scribbles", metavar="STROKES.png", help=SCRIBBLES_HELP)
    _add_connection(extract)
    _options.add_option_flags(extract, "extract_alpha")
    extract.add_argument(
        "--timeout", type=float, help="seconds to wait for the job (default: no limit)"
    )
    extract.set_defaults(run=_cmd_extract)

    wang = commands.add_parser(
        "wang", help="make a set of Wang tiles (an atlas and its manifest) for aperiodic tiling"
    )
    wang.add_argument("input", nargs="+", help=INPUTS_HELP)
    _add_connection(wang)
    wang.add_argument(
        "--manifest",
        metavar="TILES.json",
        help="where to write the manifest: the tile size, the colours and, for every tile, its "
        "place in the atlas and its edge colours n, e, s, w (default: the atlas's name with "
        ".json)",
    )
    _options.add_option_flags(wang, "wang_tiles")
    wang.add_argument(
        "--timeout", type=float, help="seconds to wait for the job (default: no limit)"
    )
    wang.set_defaults(run=_cmd_wang)

    tile = commands.add_parser(
        "tile", help="make an existing image repeat seamlessly (same size, centre kept)"
    )
    tile.add_argument("input", help="image to make tileable (PNG or JPEG)")
    _add_connection(tile)
    _options.add_option_flags(tile, "tile")
    tile.add_argument(
        "--timeout",
        type=float,
        help="seconds allowed for each step of the request (default: the client's, 60)",
    )
    tile.set_defaults(run=_cmd_tile)
    return parser


def _add_marks(parser: argparse.ArgumentParser, *, layers: bool = False) -> None:
    """``--trimap`` and ``--scribbles``: once per input (``synth``), or ``LAYER=FILE`` for
    the layers that are photos (``matte``), as ``quilting synth`` and ``quilting matte``
    take them."""
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
                default=[],
                metavar=metavar,
                help=f"{EXTRACTED_HELP}; the map is {what}. With several inputs, give it once "
                f"per input, in the inputs' order ({flag}='' for an input without one) "
                "(repeatable)",
            )


def _input_marks(flag: str, paths: Sequence[str], inputs: int) -> str | list[str | None] | None:
    """What the client takes of ``synth``'s ``--trimap`` (``--scribbles``): None when not
    given, the one path for one input, else one path (or None, for '') per input."""
    if not paths:
        return None
    if len(paths) != inputs:
        raise UsageError(
            f"{flag} is given {len(paths)} time(s) for {inputs} input image(s): give it once "
            f"per input, in the same order ({flag}='' for an input without one), or not at all"
        )
    if not any(paths):
        raise UsageError(f"{flag} is empty for every input: give a file for at least one")
    return paths[0] if inputs == 1 else [path or None for path in paths]


def _layer_marks(flag: str, specs: Sequence[str], layers: int) -> list[str | None] | None:
    """What the client takes of ``matte``'s ``--trimap LAYER=FILE``: None when not given,
    else one path (or None) per layer, LAYER counting them from 1, bottom first."""
    if not specs:
        return None
    found: list[str | None] = [None] * layers
    for spec in specs:
        number, equals, path = spec.partition("=")
        if not equals or not path or not number.strip().isdigit():
            raise UsageError(
                f"{flag} {spec!r} is not LAYER=FILE: LAYER is the layer's number, 1 for the "
                f"first --layer (bottom first), e.g. {flag} 2=leaves_{flag[2:]}.png"
            )
        index = int(number) - 1
        if not 0 <= index < layers:
            raise UsageError(
                f"{flag} {spec!r}: there {'is' if layers == 1 else 'are'} {layers} --layer "
                f"{'image' if layers == 1 else 'images'}: LAYER is 1 to {layers}, bottom first"
            )
        if found[index] is not None:
            raise UsageError(f"{flag}: layer {index + 1} is given twice")
        found[index] = path
    return found


def _extracted_line(result: SynthesisResult) -> str:
    """How the service found each alpha it extracted, one clause per photo ('' for none)."""
    said = [
        f"{entry.get('method')}, {100 * float(entry.get('unknown') or 0):.0f} % unknown, "
        f"{entry.get('iterations')} iterations"
        for entry in result.extracted
        if entry is not None
    ]
    return f"; alpha extracted ({'; '.join(said)})" if said else ""


def _inputs(paths: Sequence[str]) -> str | list[str]:
    """What the client takes: the one path, or the list of several."""
    return paths[0] if len(paths) == 1 else list(paths)


def _cmd_synth(args: argparse.Namespace, bar: ProgressBar) -> int:
    width, height = args.size
    options = _given(args, "synthesize", skip=SIZE)
    masks = args.source_masks
    if masks and len(masks) != len(args.input):
        raise UsageError(
            f"--source-mask is given {len(masks)} time(s) for {len(args.input)} input "
            "image(s): give it once per input, in the same order, or not at all"
        )
    trimap = _input_marks("--trimap", args.trimap, len(args.input))
    scribbles = _input_marks("--scribbles", args.scribbles, len(args.input))

    def run(
        client: Client, companions: Mapping[str, Any] | None, progress: ProgressCallback | None
    ) -> SynthesisResult:
        return client.synthesize(
            _inputs(args.input),
            width=width,
            height=height,
            companions=companions,
            companion_kinds=_companion_kinds(args.companions),
            source_mask=_inputs(masks) if masks else None,
            trimap=trimap,
            scribbles=scribbles,
            progress=progress,
            timeout=args.timeout,
            **options,
        )

    return _deliver(args, bar, run, size=(width, height), inputs=len(args.input))


def _cmd_wang(args: argparse.Namespace, bar: ProgressBar) -> int:
    options = _given(args, "wang_tiles")
    output = _png_path(args.output)
    manifest_path = Path(args.manifest) if args.manifest else output.with_suffix(".json")
    server, api_key = _connection(args)
    with make_client(server, api_key) as client:
        tiles: WangTilesResult = client.wang_tiles(
            _inputs(args.input),
            progress=bar if bar.enabled else None,
            timeout=args.timeout,
            **options,
        )
    bar.end()
    # Written only once both have arrived, so that a failure leaves no partial set.
    output.write_bytes(tiles.atlas)
    manifest_path.write_text(json.dumps(tiles.manifest, indent=1) + "\n", encoding="utf-8")
    size = _png_size(tiles.atlas)
    described = f"{size[0]}x{size[1]}, " if size else ""
    count = len(tiles.tiles)
    print(f"wrote {output} ({described}{count} tiles), {manifest_path} (job {tiles.job_id})")
    return 0


def _cmd_transfer(args: argparse.Namespace, bar: ProgressBar) -> int:
    options = _given(args, "transfer")

    def run(
        client: Client, companions: Mapping[str, Any] | None, progress: ProgressCallback | None
    ) -> SynthesisResult:
        return client.transfer(
            args.texture,
            args.target,
            companions=companions,
            companion_kinds=_companion_kinds(args.companions),
            progress=progress,
            timeout=args.timeout,
            **options,
        )

    # The output has the target's size, which the PNG that comes back says.
    return _deliver(args, bar, run)


def _cmd_matte(args: argparse.Namespace, bar: ProgressBar) -> int:
    options = _given(args, "matte")
    # Only the maps asked for are downloaded, each to its own file (as `quilting matte`).
    outputs = {
        name: path
        for name, path in (("normals", args.normals_out), ("clusters", args.clusters_out))
        if path
    }
    trimap = _layer_marks("--trimap", args.trimap, len(args.layers))
    scribbles = _layer_marks("--scribbles", args.scribbles, len(args.layers))

    def run(
        client: Client, companions: Mapping[str, Any] | None, progress: ProgressCallback | None
    ) -> SynthesisResult:
        # No --with: a matte's companions are made by the service, not sent along.
        return client.matte(
            args.target,
            args.silhouette,
            args.layers,
            normals=args.normals,
            trimap=trimap,
            scribbles=scribbles,
            companions=tuple(outputs),
            progress=progress,
            timeout=args.timeout,
            **options,
        )

    # The output has the target's size, which the PNG that comes back says.
    return _deliver(args, bar, run, outputs=outputs)


def _cmd_extract(args: argparse.Namespace, bar: ProgressBar) -> int:
    options = _given(args, "extract_alpha")
    if args.trimap is None and args.scribbles is None:
        raise UsageError(
            "extract-alpha needs --trimap TRIMAP.png or --scribbles STROKES.png (or both): "
            "they say which parts of the photo are the texture and which are background"
        )

    def run(
        client: Client, companions: Mapping[str, Any] | None, progress: ProgressCallback | None
    ) -> SynthesisResult:
        return client.extract_alpha(
            args.input,
            args.trimap,
            args.scribbles,
            progress=progress,
            timeout=args.timeout,
            **options,
        )

    # The output has the photo's size, which the PNG that comes back says.
    return _deliver(args, bar, run, outputs={})


def _no_kinds(args: argparse.Namespace) -> None:
    """A fill's and an extension's companions are copied as the image's pixels are: no KIND."""
    for spec in args.companions:
        named = spec.partition("=")[0]
        if ":" in named:
            raise UsageError(
                f"--with {spec!r}: {args.command} copies companions' pixels as the image's; "
                "give NAME=PATH, without a KIND"
            )


def _cmd_fill(args: argparse.Namespace, bar: ProgressBar) -> int:
    options = _given(args, "fill")
    _no_kinds(args)

    def run(
        client: Client, companions: Mapping[str, Any] | None, progress: ProgressCallback | None
    ) -> SynthesisResult:
        return client.fill(
            args.input,
            args.mask,
            texture=args.texture,
            companions=companions,
            progress=progress,
            timeout=args.timeout,
            **options,
        )

    # The output has the image's size, which the PNG that comes back says.
    return _deliver(args, bar, run)


def _cmd_extend(args: argparse.Namespace, bar: ProgressBar) -> int:
    options = _given(args, "extend", skip=MARGINS)
    margins: dict[str, int] = {side: getattr(args, side) or 0 for side in MARGINS}
    if not any(margins.values()):
        raise UsageError("extend: give at least one of --top, --bottom, --left, --right")
    _no_kinds(args)

    def run(
        client: Client, companions: Mapping[str, Any] | None, progress: ProgressCallback | None
    ) -> SynthesisResult:
        return client.extend(
            args.input,
            top=margins["top"],
            bottom=margins["bottom"],
            left=margins["left"],
            right=margins["right"],
            companions=companions,
            progress=progress,
            timeout=args.timeout,
            **options,
        )

    # The output's size (the image's and the margins') is what the PNG that comes back says.
    return _deliver(args, bar, run)


def _cmd_tile(args: argparse.Namespace, bar: ProgressBar) -> int:
    # The values are the service's to check: a bad one is its one-line 422.
    options = _given(args, "tile")
    output = _png_path(args.output)
    server, api_key = _connection(args)
    with make_client(server, api_key) as client:
        image = client.tile(args.input, timeout=args.timeout, **options)
    output.write_bytes(image)
    size = _png_size(image)
    described = f"{size[0]}x{size[1]}, " if size else ""
    print(f"wrote {output} ({described}tileable along {options.get('axes', 'both')})")
    return 0


def _given(args: argparse.Namespace, operation: str, skip: Sequence[str] = ()) -> dict[str, Any]:
    """The options given on the command line; a value outside its choices is the user's
    one-line mistake, and nothing is sent."""
    try:
        return _options.given(args, operation, skip)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def _png_path(name: str) -> Path:
    """``name`` as a path, once sure it ends in .png: the service answers PNG files, and this
    client (httpx alone, no image library) writes them as they come, so any other name would
    hold PNG bytes under a wrong extension."""
    path = Path(name)
    if path.suffix.lower() != ".png":
        raise UsageError(
            f"{name!r}: the service answers PNG, so the output's name must end in .png"
        )
    return path


def _connection(args: argparse.Namespace) -> tuple[str, str | None]:
    """The service's URL and the API key, from the arguments or else the environment."""
    # QUILTING_SERVER is the variable's older name, still read.
    server = (
        args.server
        or os.environ.get("QUILTING_URL")
        or os.environ.get("QUILTING_SERVER")
        or DEFAULT_URL
    )
    api_key = args.api_key or os.environ.get("QUILTING_API_KEY") or None
    return server, api_key


def _deliver(
    args: argparse.Namespace,
    bar: ProgressBar,
    operation: Operation,
    size: tuple[int, int] | None = None,
    outputs: Mapping[str, str] | None = None,
    inputs: int = 1,
) -> int:
    """Connect, run ``operation``, write the result and its companions, print a summary.

    ``size`` is the (width, height) asked for, if any; else the result PNG's is reported.
    ``outputs`` maps the companions the service makes (a matte's) to the files to write them
    to; None sends those of ``--with`` (one map per input of ``inputs``) and writes each as
    ``<OUT stem>_<NAME>.png``.
    """
    output = _png_path(args.output)
    server, api_key = _connection(args)
    if outputs is None:
        companions = _companions(args.companions, inputs)
        targets = {name: output.with_name(f"{output.stem}_{name}.png") for name in companions}
    else:
        companions, targets = {}, {name: _png_path(path) for name, path in outputs.items()}
    with make_client(server, api_key) as client:
        # Without a terminal to draw on, no callback: the client then polls, which lets
        # the service hold the first answer longer and usually saves round trips.
        result = operation(client, companions or None, bar if bar.enabled else None)
    bar.end()
    # Written only once everything has arrived, so that a failure leaves no partial set.
    output.write_bytes(result)
    for name, target in targets.items():
        target.write_bytes(result.companions[name])
    extra = "".join(f", {target}" for target in targets.values())
    size = size or _png_size(result)
    described = f"{size[0]}x{size[1]}, " if size else ""
    print(f"wrote {output}{extra} ({described}job {result.job_id}{_extracted_line(result)})")
    return 0


def _exit_status(exc: QuiltingClientError) -> int:
    """2 when the user can fix it, 1 when the service or the network failed."""
    if isinstance(exc, ConnectionFailedError | WaitTimeoutError):
        return 1
    if exc.status is None:
        # A job's engine failure without a status is the service's; a local check is the user's.
        return 1 if isinstance(exc, JobError) else 2
    return 2 if 400 <= exc.status < 500 else 1


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``quilting-remote``.

    Parameters
    ----------
    argv : sequence of str or None
        The arguments after ``quilting-remote``; None reads ``sys.argv``.

    Returns
    -------
    int
        The exit status: 0 on success, 2 for errors the user can fix, 1 for service or
        connection failures, 130 when interrupted.
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        # argparse has printed its message; return its status rather than exit the caller.
        return exc.code if isinstance(exc.code, int) else 2
    bar = ProgressBar(sys.stderr)
    message: str
    try:
        return int(args.run(args, bar))
    except QuiltingClientError as exc:
        # Before OSError: WaitTimeoutError is a TimeoutError, hence an OSError.
        status, message = _exit_status(exc), str(exc)
    except UsageError as exc:
        status, message = 2, str(exc)
    except OSError as exc:
        # A file that cannot be read or written.
        where = f": {exc.filename}" if exc.filename else ""
        status, message = 2, f"{exc.strerror or exc}{where}"
    except KeyboardInterrupt:
        status, message = 130, "interrupted (a submitted job keeps running on the service)"
    bar.end()
    print(f"{PROG}: error: {message}", file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
