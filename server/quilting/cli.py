"""The ``quilting`` command line: ``synth``, ``apply-layout``, ``info``.

Errors the user can fix are printed as one line (``quilting: error: ...``) with exit status 2;
no traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import fields
from typing import Any, TextIO

import numpy as np

from quilting import __version__
from quilting.api import synthesize
from quilting.core.errors import QuiltingError
from quilting.core.layout import Layout, apply_layout
from quilting.core.options import MODES, SynthesisOptions
from quilting.costs.base import BACKEND_NAMES, auto_choice, available_backends
from quilting.io import read_image, write_image


def _option_help(name: str) -> str:
    """The one-line help of an option, from the documentation in SynthesisOptions."""
    for f in fields(SynthesisOptions):
        if f.name == name:
            return str(f.metadata["doc"]) + f" (default: {f.default})"
    raise KeyError(name)


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


def _cmd_synth(args: argparse.Namespace) -> int:
    texture = read_image(args.input)
    height, width = args.size
    result = synthesize(
        texture,
        (height, width),
        block=args.block,
        overlap=args.overlap,
        tolerance=args.tolerance,
        mode=args.mode,
        seed=args.seed,
        backend=args.backend,
        min_candidates=args.min_candidates,
        progress=ProgressBar(sys.stderr),
    )
    metadata: dict[str, Any] = {
        "operation": "synthesize",
        "source": os.path.basename(args.input),
        **{k: v for k, v in result.layout.meta.items() if k != "operation"},
        "width": width,
        "height": height,
        "backend_used": result.backend,
        "version": __version__,
    }
    write_image(args.output, result.image, metadata=metadata)
    if args.layout:
        result.layout.save(args.layout)
    if args.seams:
        write_image(args.seams, result.seam_overlay())
    stats = result.stats
    if result.fallback:
        print(f"note: {result.fallback}; finished on {result.backend}", file=sys.stderr)
    on = f" on {result.renderer}" if result.renderer not in (None, "cpu") else ""
    print(
        f"wrote {args.output} ({width}x{height}) in {result.timings['total']:.2f}s "
        f"with the {result.backend} backend{on}; mean seam error {stats.seam_error_mean:.4g}, "
        f"largest verbatim copy {stats.largest_copy:.1%} of the texture, "
        f"{stats.unused:.1%} of the texture unused"
    )
    return 0


def _cmd_apply_layout(args: argparse.Namespace) -> int:
    layout = Layout.load(args.layout)
    image = apply_layout(layout, read_image(args.map))
    write_image(args.output, image, metadata={"operation": "apply-layout", **layout.meta})
    print(f"wrote {args.output} ({image.shape[1]}x{image.shape[0]})")
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


def _cmd_serve(args: argparse.Namespace) -> int:
    try:
        from quilting.service.server import serve
        from quilting.service.settings import Settings
    except ImportError as exc:  # the server extra is not installed
        raise QuiltingError(
            f"the service needs the 'server' extra ({exc.name} is missing)"
        ) from None
    serve(Settings.from_env(host=args.host, port=args.port, workers=args.workers))
    return 0


def _cmd_remote(args: argparse.Namespace) -> int:
    try:
        from quilting_client.cli import main as remote_main
    except ImportError:
        raise QuiltingError("the remote commands need the client: pip install ./client") from None
    return int(remote_main(args.rest))


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``quilting`` command."""
    parser = argparse.ArgumentParser(
        prog="quilting", description="Texture synthesis by image quilting (Efros & Freeman 2001)."
    )
    parser.add_argument("--version", action="version", version=f"quilting {__version__}")
    commands = parser.add_subparsers(dest="command", required=True)

    synth = commands.add_parser("synth", help="synthesize a larger texture from a sample")
    synth.add_argument("input", help="texture sample (PNG or JPEG)")
    synth.add_argument("-o", "--output", required=True, help="output PNG")
    synth.add_argument(
        "--size", type=_size, required=True, help="output WIDTHxHEIGHT, e.g. 512x512"
    )
    synth.add_argument("--block", type=int, default=48, help=_option_help("block"))
    synth.add_argument("--overlap", type=int, default=None, help=_option_help("overlap"))
    synth.add_argument("--tolerance", type=float, default=0.1, help=_option_help("tolerance"))
    synth.add_argument("--mode", choices=MODES, default="cut", help=_option_help("mode"))
    synth.add_argument("--seed", type=int, default=0, help=_option_help("seed"))
    synth.add_argument(
        "--backend", choices=BACKEND_NAMES, default="auto", help=_option_help("backend")
    )
    synth.add_argument("--min-candidates", type=int, default=3, help=_option_help("min_candidates"))
    synth.add_argument("--layout", metavar="OUT.json", help="also write the block layout as JSON")
    synth.add_argument(
        "--seams", metavar="OUT.png", help="also write the seams drawn over the output"
    )
    synth.set_defaults(run=_cmd_synth)

    apply = commands.add_parser(
        "apply-layout", help="quilt a companion map (normal, roughness...) with a saved layout"
    )
    apply.add_argument("layout", help="layout JSON written by synth --layout")
    apply.add_argument("map", help="map of the same size as the original texture (PNG or JPEG)")
    apply.add_argument("-o", "--output", required=True, help="output PNG")
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
    serve.set_defaults(run=_cmd_serve)

    remote = commands.add_parser(
        "remote", help="use a running service: quilting remote synth IN -o OUT --server URL ..."
    )
    remote.add_argument("rest", nargs=argparse.REMAINDER, help="arguments of the remote command")
    remote.set_defaults(run=_cmd_remote)

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
