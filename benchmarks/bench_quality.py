"""Quality of synthesis on the test textures: seam error per mode, and repetition of the source.

Prints two tables (means over a few seeds):

1. mean seam error of ``random`` / ``overlap`` / ``cut`` (the paper's Fig. 2 ordering);
2. largest verbatim copy of the source and seam error against ``min_candidates`` (the floor
   of the tolerance rule; 1 is the paper's bare rule).

Run: ``.venv/bin/python benchmarks/bench_quality.py [--size 512] [--seeds 3]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import quilting

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
TEXTURES = ("brick", "gravel", "hubble")


def _mean(values: list[float]) -> float:
    return float(np.mean(values))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--size", type=int, default=512, help="output side (default 512)")
    parser.add_argument("--seeds", type=int, default=3, help="seeds per cell (default 3)")
    args = parser.parse_args()
    seeds = range(1, args.seeds + 1)
    size = (args.size, args.size)
    textures = {name: quilting.read_image(DATA / f"{name}.png") for name in TEXTURES}

    print(f"output {args.size}x{args.size}, block 48, means over {args.seeds} seeds\n")
    print("mean seam error (squared difference per seam pixel, values in [0, 1])")
    print(f"{'texture':<8} {'random':>9} {'overlap':>9} {'cut':>9}  cut/random")
    for name, texture in textures.items():
        row = {
            mode: _mean(
                [
                    quilting.synthesize(texture, size, mode=mode, seed=s).stats.seam_error_mean
                    for s in seeds
                ]
            )
            for mode in ("random", "overlap", "cut")
        }
        print(
            f"{name:<8} {row['random']:9.5f} {row['overlap']:9.5f} {row['cut']:9.5f}"
            f"  {row['cut'] / row['random']:9.3f}"
        )

    print("\nlargest verbatim copy (share of the texture) / mean seam error, by min_candidates")
    ks = (1, 2, 3, 5)
    print(f"{'texture':<8} " + " ".join(f"{'k=' + str(k):>17}" for k in ks))
    for name, texture in textures.items():
        cells = []
        for k in ks:
            stats = [
                quilting.synthesize(texture, size, min_candidates=k, seed=s).stats for s in seeds
            ]
            copy = _mean([st.largest_copy for st in stats])
            seam = _mean([st.seam_error_mean for st in stats])
            cells.append(f"{copy:7.3f} / {seam:7.5f}")
        print(f"{name:<8} " + " ".join(f"{c:>17}" for c in cells))


if __name__ == "__main__":
    main()
