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

Texture matting (§3) is not built yet, so its row of the issue's benchmark is missing.

Run from the repository root::

    .venv/bin/python benchmarks/bench_alpha.py             # 5 runs per case
    .venv/bin/python benchmarks/bench_alpha.py --repeat 2  # quicker
    .venv/bin/python benchmarks/bench_alpha.py --backend gl  # on a GPU
"""

from __future__ import annotations

import statistics
import time
import tracemalloc
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


def main() -> None:
    args = benchtools.engine_parser(__doc__).parse_args()
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
