"""Benchmark of make_tileable's blend: ``blend="none"`` against ``blend="poisson"``.

For each image, both blends of ``quilting.make_tileable`` (axes "both", the default band):

* ``time``: the median wall time of ``--repeat`` calls (after one untimed warm-up; the two
  blends take turns, one call each, so that a slow spell of a noisy machine hits them alike),
  and ``x none``, poisson's median as a ratio to none's of the same image in the same run;
* ``cut step``: the mean absolute difference across the *cut edges* (output neighbours whose
  sources are not input neighbours: where the cuts join the kept centre to the rolled image)
  divided by the mean absolute difference across every other pair of neighbours of the output
  (colour channels, alpha left out). About 1: the cuts look like any other line of the image;
  a brightness gradient across a photo makes it several times that without the blend;
* ``wrap step``: the same numerator taken across the two joins of the output tiled 2x2 (last
  column next to the first, last row next to the first), over the same denominator;
* ``mean shift``: how far the blend moved the image's mean (8-bit steps; none: 0 by definition).

Images: the textures of ``tests/data`` (but ``target_camera``, which is ``camera``); the
photographs of ``examples/`` (``camera``, ``cat``); and the two photographs given an artificial
brightness gradient (multiplied by a ramp from 0.45 at the top-left corner to 1.25 at the
bottom-right, as a photo lit from one side), once more for ``cat`` at 4x its size (1804x1200)
for a time at a realistic size.

Run from the repository root::

    .venv/bin/python benchmarks/bench_tile_blend.py             # 5 calls per case
    .venv/bin/python benchmarks/bench_tile_blend.py --repeat 2  # quicker
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import benchtools
import numpy as np
import scipy
from numpy.typing import NDArray
from PIL import Image as PILImage

import quilting
from quilting.core.options import TileBlend
from quilting.core.seamless import Tiled
from quilting.core.seamless_blend import cut_edges, periodic_axes

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
EXAMPLES = ROOT / "examples"
#: ``target_camera`` is left out: it is ``examples/camera.png``, measured with the photographs.
TEXTURES = ("brick", "grass", "gravel", "hubble", "wood", "cloud_rgba")
PHOTOS = ("camera", "cat")
BLENDS: tuple[TileBlend, ...] = ("none", "poisson")

Image = NDArray[Any]


def load(path: Path) -> Image:
    image: Image = np.asarray(PILImage.open(path))
    return image


def lit(image: Image) -> Image:
    """``image`` (uint8) under a brightness ramp from 0.45 (top left) to 1.25 (bottom right)."""
    height, width = image.shape[:2]
    y, x = np.mgrid[0:height, 0:width]
    gain = 0.45 + 0.8 * (x / (width - 1) + y / (height - 1)) / 2
    gain = gain[..., None] if image.ndim == 3 else gain
    out: Image = np.clip(np.rint(image * gain), 0, 255).astype(np.uint8)
    return out


def cases() -> list[tuple[str, Image]]:
    found = [(name, load(DATA / f"{name}.png")) for name in TEXTURES]
    for name in PHOTOS:
        photo = load(EXAMPLES / f"{name}.png")
        found += [(name, photo), (f"{name} + gradient", lit(photo))]
    cat = PILImage.open(EXAMPLES / "cat.png")
    big = np.asarray(cat.resize((cat.width * 4, cat.height * 4), PILImage.Resampling.BICUBIC))
    found.append(("cat 4x + gradient", lit(big)))
    return found


def colour(image: Image) -> NDArray[np.float64]:
    """The colour channels as float64 (H, W, C): alpha left out, gray given a channel axis."""
    values = image.astype(np.float64)
    values = values[..., None] if values.ndim == 2 else values
    return values[..., :3]


def figures(t: Tiled) -> tuple[float, float]:
    """(cut step, wrap step) of a result, as described in the module docstring."""
    out = colour(t.image)
    flat = out.reshape(-1, out.shape[2])
    width = out.shape[1]
    source = (t.source_rows * width + t.source_cols).astype(np.intp)
    periodic = periodic_axes(t.axes)
    cut_sum, cut_n, other_sum, other_n = 0.0, 0, 0.0, 0
    for axis in (0, 1):
        p, q = cut_edges(source, axis, periodic[axis])
        cut = np.abs(flat[q] - flat[p]).mean(axis=1)
        inner = np.abs(np.diff(out, axis=axis)).mean(axis=2)
        # The cut edges that are inner edges (not across the wrap) leave the denominator.
        last = out.shape[axis] - 1
        at = np.divmod(p, width)[axis]
        inner_cut = cut[at < last]
        cut_sum, cut_n = cut_sum + cut.sum(), cut_n + cut.size
        other_sum += inner.sum() - inner_cut.sum()
        other_n += inner.size - inner_cut.size
    elsewhere = other_sum / other_n
    tiled = np.tile(out, (2, 2, 1))
    height = out.shape[0]
    joins = np.concatenate(
        [
            np.abs(tiled[:, width] - tiled[:, width - 1]).mean(axis=-1).ravel(),
            np.abs(tiled[height] - tiled[height - 1]).mean(axis=-1).ravel(),
        ]
    )
    return cut_sum / max(cut_n, 1) / elsewhere, float(joins.mean()) / elsewhere


def run(repeat: int) -> list[list[str]]:
    rows: list[list[str]] = []
    for name, image in cases():
        height, width = image.shape[:2]
        channels = 1 if image.ndim == 2 else image.shape[2]
        times: dict[str, list[float]] = {blend: [] for blend in BLENDS}
        results: dict[str, Tiled] = {}
        for blend in BLENDS:
            results[blend] = quilting.make_tileable(image, blend=blend)  # warm-up
        for _ in range(repeat):
            for blend in BLENDS:
                start = time.perf_counter()
                quilting.make_tileable(image, blend=blend)
                times[blend].append(time.perf_counter() - start)
        base = statistics.median(times["none"])
        mean_none = float(colour(results["none"].image).mean())
        for blend in BLENDS:
            median = statistics.median(times[blend])
            cut, wrap = figures(results[blend])
            shift = float(colour(results[blend].image).mean()) - mean_none
            rows.append(
                [
                    name,
                    f"{width}x{height}x{channels}",
                    blend,
                    f"{median * 1000:.1f}",
                    f"{median / base:.2f}",
                    f"{cut:.2f}",
                    f"{wrap:.2f}",
                    f"{shift:+.2f}",
                ]
            )
        print(f"  {name}: done", file=sys.stderr)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5, help="timed calls per case (default 5)")
    args = parser.parse_args(argv)
    rows = run(max(1, args.repeat))
    headers = [
        "image",
        "size",
        "blend",
        "time ms",
        "x none",
        "cut step",
        "wrap step",
        "mean shift",
    ]
    info = benchtools.machine(numpy=np.__version__, scipy=scipy.__version__)
    print(
        f"machine: {info['cpu_count']} CPUs, {info['platform']}, Python {info['python']}, "
        f"numpy {info['numpy']}, scipy {info['scipy']}, load {info['loadavg']}; "
        f"source {benchtools.source_tree(ROOT)}; median of {max(1, args.repeat)} calls"
    )
    print()
    print(benchtools.markdown(headers, rows, left=3))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
