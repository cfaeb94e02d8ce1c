"""Benchmark of the synthesis variants: tileable output and walk mode next to plain cut.

Measures, for each texture (256x256 crops) and each case, quilting a 1024x1024 output (block
48, seed 0, backend ``fft``):

* ``cut``: plain minimum-error boundary cut, the baseline;
* ``tileable both`` and ``tileable x``: the same on a torus (``tileable="both"`` / ``"x"``);
* ``walk``: random blocks joined by the minimum-resistance walk cut (no cost fields);
* ``random``: random blocks, straight edges, the floor of the loop;
* ``make_tileable``: ``quilting.make_tileable`` (both axes) of the 1024x1024 ``cut`` output,
  for reference (an image made tileable after the fact instead of synthesized tileable).

For each case: the median and the minimum of the wall time around the call over ``--repeat``
timed runs (after one untimed warm-up call; the cases of a texture take turns, one run each,
so that a slow spell of a noisy machine hits them alike); the median as a ratio to ``cut``'s
median of the same texture in the same run (only same-run comparisons mean anything on a noisy
machine); the tracemalloc peak of one extra, untimed call (numpy reports its allocations to
tracemalloc; all cases run in this one process, where a peak RSS would mostly show what the
allocator kept from earlier cases); and the quality figures of ``Result.stats``: the mean
seam error and the largest verbatim copy.

One more quality figure, for every row: ``wrap x`` and ``wrap y``, the mean squared
difference (values in [0, 1], summed over channels) between the output's last and first column
(row), divided by the mean squared difference between neighbouring columns (rows) inside it.
About 1 means the wrap looks like any other column boundary (the image tiles along that axis);
a plain output is several times that. It is one line pair against the average of all, so a
wrap that happens to fall on an edge of the texture (a mortar line, a star) reads high.

Textures: ``gravel`` (256x256 gray) and ``hubble`` (256x256 RGB) from ``tests/data``; the
top-left 256x256 of each. ``wood`` is only 136x136 and ``brick`` is gray, so the RGB texture
is hubble.

Run from the repository root::

    .venv/bin/python benchmarks/bench_variants.py              # 1024x1024, 5 runs per case
    .venv/bin/python benchmarks/bench_variants.py --quick      # 512x512, 2 runs: smoke test
    .venv/bin/python benchmarks/bench_variants.py --one walk   # only cut (the baseline) and walk
    .venv/bin/python benchmarks/bench_variants.py --json variants.json
"""

from __future__ import annotations

import statistics
import sys
import time
import tracemalloc
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import benchtools
import numpy as np
import scipy
from benchtools import fmt
from numpy.typing import NDArray

import quilting
from quilting.core.options import Mode, Tileable
from quilting.core.pixels import as_channels, to_working

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
TEXTURES = ("gravel", "hubble")
CROP = 256
SIZE = 1024
QUICK_SIZE = 512
BLOCK = 48
SEED = 0
BACKEND = "fft"
MIB = 1024 * 1024

Image = NDArray[Any]


@dataclass(frozen=True)
class Case:
    name: str
    mode: Mode = "cut"
    tileable: Tileable | None = None
    after: bool = False  # make_tileable of the cut output instead of a synthesis


CASES = {
    case.name: case
    for case in (
        Case("cut"),
        Case("tileable both", tileable="both"),
        Case("tileable x", tileable="x"),
        Case("walk", mode="walk"),
        Case("random", mode="random"),
        Case("make_tileable", after=True),
    )
}
BASELINE = "cut"


@dataclass
class CaseResult:
    case: str
    texture: str
    size: int
    runs: int
    blocks: int | None  # grid rows x cols (None for make_tileable)
    wall_s: float  # median
    min_wall_s: float
    engine_s: float | None  # median of Result.timings["total"]
    traced_mib: float
    seam_error_mean: float | None
    largest_copy: float | None
    wrap_x: float
    wrap_y: float
    stages_s: dict[str, float] = field(default_factory=dict)


# --- inputs --------------------------------------------------------------------------------


def find(name: str) -> Path:
    """``tests/data/<name>.png``."""
    path = DATA / f"{name}.png"
    if not path.is_file():
        raise FileNotFoundError(f"{name}.png is not in {DATA}")
    return path


def load(name: str) -> tuple[Image, str]:
    """The top-left ``CROP`` x ``CROP`` of a texture, and its label."""
    image = quilting.read_image(find(name))
    crop = np.ascontiguousarray(image[:CROP, :CROP])
    kind = "gray" if crop.ndim == 2 else {3: "RGB", 4: "RGBA"}.get(crop.shape[2], "?")
    return crop, f"{name} {crop.shape[1]}x{crop.shape[0]} {kind}"


def tile(image: Image) -> Image:
    """``quilting.make_tileable(image, axes="both")``, the image only."""
    out: Image = quilting.make_tileable(image, axes="both").image
    return out


# --- quality -------------------------------------------------------------------------------


def wrap_ratios(image: Image) -> tuple[float, float]:
    """Wrap difference over the mean neighbour difference, along x and along y.

    For each axis: the mean over the seam of the squared difference (summed over channels,
    working units) between the last and the first column (row), divided by the same mean over
    every pair of neighbouring columns (rows) inside the image.
    """
    view, _ = as_channels(image, "image")
    pixels = to_working(view).astype(np.float64)
    ratios = []
    for axis in (1, 0):
        inside = np.square(np.diff(pixels, axis=axis)).sum(axis=2).mean()
        last = np.take(pixels, [-1], axis=axis)
        first = np.take(pixels, [0], axis=axis)
        across = np.square(last - first).sum(axis=2).mean()
        ratios.append(float(across / inside) if inside > 0 else float("nan"))
    return ratios[0], ratios[1]


# --- the cases of one texture ---------------------------------------------------------------


class Runner:
    """One case on one texture: a call, and what its last run returned."""

    def __init__(self, case: Case, texture: Image, size: int) -> None:
        self.case, self.texture, self.size = case, texture, size
        self.plain: Image | None = None  # the cut output, for make_tileable
        self.result: quilting.Result | None = None
        self.image: Image | None = None

    def __call__(self) -> None:
        if self.case.after:
            assert self.plain is not None, "make_tileable runs on the cut case's output"
            self.image = tile(self.plain)
            return
        self.result = quilting.synthesize(
            self.texture,
            (self.size, self.size),
            block=BLOCK,
            mode=self.case.mode,
            tileable=self.case.tileable,
            seed=SEED,
            backend=BACKEND,
        )
        self.image = self.result.image


def run_texture(
    names: list[str], texture: Image, label: str, size: int, repeat: int
) -> list[CaseResult]:
    """Time and measure the cases on one texture.

    The timed runs are interleaved (every case once, ``repeat`` times over), so that a slow
    spell of a noisy machine hits every case alike instead of one of them.
    """
    runners = {name: Runner(CASES[name], texture, size) for name in names}
    for name, runner in runners.items():  # warm-up: imports, first-touch pages, plans
        print(f"{label}: {name} ...", file=sys.stderr, flush=True)
        runner()
        if name == BASELINE:
            for other in runners.values():
                other.plain = runner.image
    wall: dict[str, list[float]] = {name: [] for name in names}
    stages: dict[str, dict[str, list[float]]] = {name: {} for name in names}
    for _ in range(repeat):
        for name, runner in runners.items():
            start = time.perf_counter()
            runner()
            wall[name].append(time.perf_counter() - start)
            if runner.result is not None:
                for stage, seconds in runner.result.timings.items():
                    stages[name].setdefault(stage, []).append(seconds)

    results = []
    for name, runner in runners.items():
        tracemalloc.start()
        runner()
        traced = tracemalloc.get_traced_memory()[1] / MIB
        tracemalloc.stop()
        assert runner.image is not None
        blocks = seam = copy = None
        if runner.result is not None:
            used = runner.result.backend
            if used not in (BACKEND, "none"):
                raise RuntimeError(f"asked for backend {BACKEND!r}, the engine used {used!r}")
            grid = runner.result.layout.passes[0].grid
            blocks = grid.rows * grid.cols
            seam = runner.result.stats.seam_error_mean
            copy = runner.result.stats.largest_copy
        wrap_x, wrap_y = wrap_ratios(runner.image)
        results.append(
            CaseResult(
                case=name,
                texture=label,
                size=size,
                runs=repeat,
                blocks=blocks,
                wall_s=statistics.median(wall[name]),
                min_wall_s=min(wall[name]),
                engine_s=statistics.median(stages[name]["total"]) if stages[name] else None,
                traced_mib=traced,
                seam_error_mean=seam,
                largest_copy=copy,
                wrap_x=wrap_x,
                wrap_y=wrap_y,
                stages_s={s: statistics.median(v) for s, v in stages[name].items()},
            )
        )
    return results


# --- report --------------------------------------------------------------------------------


def report(results: list[CaseResult]) -> str:
    """A markdown table, one row per texture and case."""
    base = {r.texture: r.wall_s for r in results if r.case == BASELINE}
    headers = ["texture", "case", "blocks", "median s", "min s", "vs cut", "traced MiB"]
    headers += ["seam error", "largest copy", "wrap x", "wrap y"]
    rows = [
        [
            r.texture,
            r.case,
            "-" if r.blocks is None else str(r.blocks),
            fmt(r.wall_s),
            fmt(r.min_wall_s),
            f"{r.wall_s / base[r.texture]:.2f}" if r.texture in base else "-",
            fmt(r.traced_mib, 1),
            fmt(r.seam_error_mean, 5),
            fmt(r.largest_copy),
            fmt(r.wrap_x, 2),
            fmt(r.wrap_y, 2),
        ]
        for r in results
    ]
    return benchtools.markdown(headers, rows, left=2)


def main(argv: list[str] | None = None) -> int:
    parser = benchtools.parser(__doc__)
    parser.add_argument("--repeat", type=int, default=5, help="timed runs per case (default 5)")
    parser.add_argument("--quick", action="store_true", help="2 runs, 512x512 output")
    parser.add_argument("--one", choices=sorted(CASES), help="only this case (and cut)")
    args = parser.parse_args(argv)
    repeat = 2 if args.quick else max(1, args.repeat)
    size = QUICK_SIZE if args.quick else SIZE
    names = list(CASES) if args.one is None else list(dict.fromkeys([BASELINE, args.one]))

    started = time.perf_counter()
    info = benchtools.machine(numpy=np.__version__, scipy=scipy.__version__)
    benchtools.show_machine(info)
    results = []
    for name in TEXTURES:
        texture, label = load(name)
        results += run_texture(names, texture, label, size, repeat)

    print(
        f"\nvariants: {size}x{size} from 256x256 crops, block {BLOCK}, seed {SEED}, backend "
        f"{BACKEND}; wall seconds around the call, median and min of {repeat} timed run(s) "
        "after one warm-up, the cases interleaved; vs cut = median / cut's median (same "
        "texture, same run); traced = "
        "tracemalloc peak of one extra call (numpy's arrays included); seam error = "
        "Result.stats.seam_error_mean; "
        "largest copy = Result.stats.largest_copy (share of the texture's area); wrap x/y = "
        "squared difference across the wrap / mean between neighbouring columns/rows (about 1: "
        f"tiles); make_tileable = quilting.make_tileable(axes='both') of the {size}x{size} cut "
        "output\n"
    )
    print(report(results))
    elapsed = benchtools.wall_time(started)
    benchtools.write_json(
        args.json,
        {
            "machine": info,
            "size": size,
            "repeat": repeat,
            "block": BLOCK,
            "backend": BACKEND,
            "cases": [asdict(r) for r in results],
            "wall_s": elapsed,
        },
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
