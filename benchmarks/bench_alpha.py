"""Benchmark of alpha quilting (alpha quilting and texture matting paper, §2.1) against plain
cut quilting of the same texture.

512x512 from ``cloud_rgba.png`` (192x192 RGBA, ``tests/data``), block 32, backend ``fft``
(``--backend`` for another):

* ``cut (rgba)``: the minimum-error cut over all four channels, the baseline;
* ``alpha``: alpha quilting with its defaults (premultiplied error, the alpha-histogram term,
  epsilon 0.02, factored sampling by seam cost, eta 20);
* ``alpha, lambda 0``: without the histogram term;
* ``alpha, eta 0``: the kept candidates drawn uniformly (their seams are still traced).

For each case: the median and minimum wall time over ``--repeat`` timed runs after a warm-up
(the cases take turns, so a slow spell of the noisy machine hits them alike), the median as a
ratio to ``cut (rgba)``'s, the tracemalloc peak of one more call (numpy reports its
allocations), and quality: the Bhattacharyya coefficient between the output's alpha histogram
and the texture's (100 bins; 1 = identical) and the largest verbatim copy.

``--extract`` measures the first step instead, alpha from an ordinary photo
(:func:`quilting.extract_alpha`): photos made by laying the cloud (its alpha and colour,
resized) over a smooth sky gradient (``sky``) and over the grass photo (``grass``, a textured
background), at 256² and 512², each with a trimap drawn from the known alpha (white where it
is over 0.97, black under 0.03, grey between) and with scribbles only (one row in eight of
those white and black pixels: most of the photo unknown, the slowest case). For every method:
the wall and CPU seconds (each case in a fresh interpreter, warmed up on a 32² photo, median
of ``--repeat``), the memory it added (VmHWM over the warmed-up process's), the solver's
iterations and the alpha's mean absolute error against the known one. Then end to end: a
512² alpha quilting from the 192² photo and its trimap (extraction + quilting) against the
same quilting from ``cloud_rgba.png`` itself (the RGBA file), with the output's alpha
histogram against the true alpha's.

Run from the repository root::

    .venv/bin/python benchmarks/bench_alpha.py             # 5 runs per case
    .venv/bin/python benchmarks/bench_alpha.py --repeat 2  # quicker
    .venv/bin/python benchmarks/bench_alpha.py --backend gl  # on a GPU
    .venv/bin/python benchmarks/bench_alpha.py --extract --repeat 1  # alpha from a photo
"""

from __future__ import annotations

import argparse
import functools
import json
import resource
import statistics
import subprocess
import sys
import time
import tracemalloc
from collections.abc import Callable
from importlib import metadata
from pathlib import Path
from typing import Any

import benchtools
import numpy as np
from PIL import Image

import quilting
from quilting.core.alpha import alpha_histogram, bhattacharyya

ROOT = Path(__file__).resolve().parents[1]
CASES: dict[str, dict[str, Any]] = {
    "cut (rgba)": {"mode": "cut"},
    "alpha": {},
    "alpha, lambda 0": {"histogram_weight": 0.0},
    "alpha, eta 0": {"eta": 0.0},
}


def run(texture: np.ndarray, size: int, options: dict[str, Any], backend: str) -> quilting.Result:
    return quilting.synthesize(texture, (size, size), block=32, seed=0, backend=backend, **options)


def scene(side: int, background: str) -> tuple[np.ndarray, np.ndarray]:
    """A photo of the cloud over ``background`` ('sky' or 'grass') at side², uint8 RGB, and
    the known alpha (float64)."""
    cloud = Image.open(ROOT / "tests" / "data" / "cloud_rgba.png")
    layer = np.asarray(cloud.resize((side, side), Image.Resampling.LANCZOS), np.float64) / 255
    alpha, colour = layer[..., 3], layer[..., :3]
    if background == "sky":
        yy, xx = np.mgrid[0:side, 0:side] / (side - 1)
        behind = np.stack([0.25 + 0.2 * xx, 0.45 + 0.2 * yy, 0.85 - 0.1 * yy], -1)
    else:
        grass = Image.open(ROOT / "tests" / "data" / "grass.png").convert("RGB")
        behind = np.asarray(grass.resize((side, side), Image.Resampling.BICUBIC), np.float64)
        behind = behind / 255 * (0.35, 0.6, 0.3)  # green, darker than the cloud
    photo = alpha[..., None] * colour + (1 - alpha[..., None]) * behind
    return np.round(photo * 255).astype(np.uint8), alpha


def user_maps(alpha: np.ndarray, kind: str) -> np.ndarray:
    """The trimap (kind 'trimap') or scribbles (kind 'scribbles') a user would draw."""
    marks = np.full(alpha.shape, 128, np.uint8)
    if kind == "scribbles":
        rows = (np.arange(alpha.shape[0]) % 8 == 0)[:, None]
        marks[rows & (alpha > 0.97)] = 255
        marks[rows & (alpha < 0.03)] = 0
        return marks
    marks[alpha > 0.97] = 255
    marks[alpha < 0.03] = 0
    return marks


def _vmhwm() -> int:
    """Peak resident bytes of this process so far."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def extract_case(spec: str) -> dict[str, Any]:
    """One extraction case, ``side,background,kind,method,repeat``, in this (fresh) process."""
    side_text, background, kind, method, repeat = spec.split(",")
    warm, warm_alpha = scene(32, "sky")
    quilting.extract_alpha(warm, user_maps(warm_alpha, "trimap"), method=method)
    base = _vmhwm()
    photo, alpha = scene(int(side_text), background)
    marks = user_maps(alpha, kind)
    walls, cpus = [], []
    for _ in range(int(repeat)):
        wall, cpu = time.perf_counter(), time.process_time()
        found = quilting.extract_alpha(photo, marks, method=method)
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return {
        "wall_s": statistics.median(walls),
        "cpu_s": statistics.median(cpus),
        "added_bytes": _vmhwm() - base,
        "iterations": found.iterations,
        "unknown": found.unknown,
        "mae": float(np.abs(found.alpha - alpha).mean()),
    }


def extraction(repeat: int, sides: list[int]) -> list[dict[str, Any]]:
    """Every extraction case, each in a fresh interpreter; printed as a table."""
    rows, found = [], []
    for side in sides:
        for background in ("sky", "grass"):
            for kind in ("trimap", "scribbles"):
                for method in ("cf", "knn", "lkm"):
                    spec = f"{side},{background},{kind},{method},{repeat}"
                    done = subprocess.run(
                        [sys.executable, __file__, "--case", spec],
                        capture_output=True,
                        text=True,
                        check=True,
                    )
                    case = json.loads(done.stdout.strip().splitlines()[-1])
                    predicted = quilting.estimate_extract(
                        quilting.AlphaOptions(method=method), (side, side)
                    )
                    case.update(side=side, background=background, kind=kind, method=method)
                    case["predicted_bytes"] = predicted.peak_bytes - quilting.BASE_BYTES
                    case["predicted_s"] = predicted.seconds
                    found.append(case)
                    rows.append(
                        [
                            f"{side}²",
                            background,
                            kind,
                            method,
                            f"{case['unknown']:.2f}",
                            f"{case['wall_s']:.2f}",
                            f"{case['cpu_s']:.2f}",
                            f"{case['predicted_s']:.1f}",
                            f"{case['added_bytes'] / 2**20:.0f}",
                            f"{case['predicted_bytes'] / 2**20:.0f}",
                            str(case["iterations"]),
                            f"{case['mae']:.4f}",
                        ]
                    )
                    print(benchtools.table(HEADERS, rows[-1:]), flush=True)
    print(benchtools.markdown(HEADERS, rows))
    return found


HEADERS = [
    "photo",
    "background",
    "user map",
    "method",
    "unknown",
    "wall s",
    "cpu s",
    "model s",
    "added MiB",
    "model MiB",
    "iterations",
    "alpha MAE",
]


def end_to_end(size: int, repeat: int, backend: str) -> None:
    """512² alpha quilting from the 192² photo + trimap against from the RGBA file."""
    texture = np.asarray(Image.open(ROOT / "tests" / "data" / "cloud_rgba.png"))
    photo, alpha = scene(192, "sky")
    marks = user_maps(alpha, "trimap")
    truth = alpha_histogram(alpha)
    cases: dict[str, Callable[[], Any]] = {
        "from the RGBA file": lambda: run(texture, size, {}, backend),
    }
    for method in ("lkm", "cf", "knn"):
        cases[f"from photo + trimap ({method})"] = functools.partial(
            quilting.synthesize,
            photo,
            (size, size),
            trimap=marks,
            matting=method,
            block=32,
            seed=0,
            backend=backend,
        )
    times: dict[str, list[float]] = {name: [] for name in cases}
    extracts: dict[str, list[float]] = {name: [] for name in cases}
    results = {name: make() for name, make in cases.items()}  # warm-up
    for _ in range(repeat):
        for name, make in cases.items():
            start = time.perf_counter()
            made = make()
            times[name].append(time.perf_counter() - start)
            if "extract" in made.timings:
                extracts[name].append(made.timings["extract"])
    base = statistics.median(times["from the RGBA file"])
    rows = []
    for name, result in results.items():
        out_alpha = np.asarray(result.image[..., 3], dtype=np.float64) / 255
        extract = statistics.median(extracts[name]) if extracts[name] else None
        rows.append(
            [
                name,
                f"{statistics.median(times[name]):.3f}",
                f"{statistics.median(times[name]) / base:.2f}",
                "-" if extract is None else f"{extract:.3f}",
                f"{float(bhattacharyya(truth, alpha_histogram(out_alpha))):.4f}",
                f"{result.stats.largest_copy:.3f}",
            ]
        )
    headers = ["case", "median s", "x file", "extract s", "alpha rho vs truth", "copy"]
    print(f"{size}x{size} alpha quilting, block 32, seed 0, {backend}, {repeat} runs")
    print(benchtools.markdown(headers, rows))


def main() -> None:
    made = benchtools.engine_parser(__doc__)
    made.add_argument("--extract", action="store_true", help="alpha from a photo instead")
    made.add_argument(
        "--sides", default="256,512", help="photo sides of --extract ('' for none: end to end only)"
    )
    made.add_argument("--case", help=argparse.SUPPRESS)
    args = made.parse_args()
    if args.case:
        print(json.dumps(extract_case(args.case)))
        return
    if args.extract:
        print(benchtools.machine(numpy=np.__version__, pymatting=metadata.version("pymatting")))
        sides = [int(side) for side in args.sides.split(",") if side.strip()]
        if sides:
            extraction(args.repeat, sides)
        end_to_end(args.size, max(args.repeat, 3), args.backend)
        return
    texture = np.asarray(Image.open(ROOT / "tests" / "data" / "cloud_rgba.png"))
    reference = alpha_histogram(texture[..., 3] / 255)
    print(benchtools.machine(numpy=np.__version__, scipy=metadata.version("scipy")))
    print(f"{args.size}x{args.size} from cloud_rgba 192x192 RGBA, block 32, seed 0, {args.backend}")

    times: dict[str, list[float]] = {name: [] for name in CASES}
    for options in CASES.values():
        run(texture, args.size, options, args.backend)  # warm-up
    for _ in range(args.repeat):
        for name, options in CASES.items():
            start = time.perf_counter()
            run(texture, args.size, options, args.backend)
            times[name].append(time.perf_counter() - start)

    rows = []
    base = statistics.median(times["cut (rgba)"])
    for name, options in CASES.items():
        tracemalloc.start()
        result = run(texture, args.size, options, args.backend)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        alpha = np.asarray(result.image[..., 3], dtype=np.float64) / 255
        rho = float(bhattacharyya(reference, alpha_histogram(alpha)))
        median = statistics.median(times[name])
        rows.append(
            [
                name,
                str(len(times[name])),
                f"{median:.3f}",
                f"{min(times[name]):.3f}",
                f"{median / base:.2f}",
                f"{peak / 2**20:.1f}",
                f"{rho:.4f}",
                f"{result.stats.largest_copy:.3f}",
            ]
        )
    headers = ["case", "runs", "median s", "min s", "vs cut", "traced MiB", "alpha rho", "copy"]
    print(benchtools.table(headers, rows))


if __name__ == "__main__":
    main()
