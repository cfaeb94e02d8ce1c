"""Benchmark of ``quilting.synthesize``: speed and peak memory against the issue's targets.

Measures, for each case (output size x texture, block 48, mode ``cut``, backend ``auto``):

* the median over ``--repeat`` runs of the engine time (``Result.timings["total"]``), of the
  wall time around the call and of every stage (costs, select, seams, paste, render, stats);
* the peak memory of one call: the peak RSS increase of a fresh process over its baseline after
  imports and loading the texture (``ru_maxrss``), and the tracemalloc peak of one extra,
  untimed call (numpy reports its allocations to tracemalloc);
* baselines from the same run, since only same-run comparisons mean anything on a noisy
  machine: ``mode="random"`` (no cost fields: the floor of the loop) and a naive FFT quilter
  defined here (per block, full-size float64 FFTs of source and masked template, no caching,
  no batching, no pruning, paper's tolerance rule, straight-edge paste).

Each case runs in its own subprocess (this script with the hidden ``--one CASE``), so the
memory figures are not polluted by earlier cases. Targets (from the issue, 2-core machine):
512x512 in <= 0.2 s, 2048x2048 in <= 2.0 s and <= 300 MiB; a time target is checked against
the wall median, the memory target against the peak RSS increase.

Run from the repository root::

    .venv/bin/python benchmarks/bench_synthesis.py               # all cases, 5 runs each
    .venv/bin/python benchmarks/bench_synthesis.py --quick       # 512 cases, 1 run: smoke test
    .venv/bin/python benchmarks/bench_synthesis.py --repeat 9 --json bench.json
    .venv/bin/python benchmarks/bench_synthesis.py --full-baseline   # naive baseline at 2048 too
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time
import tracemalloc
from dataclasses import asdict, dataclass
from pathlib import Path

import benchtools
import numpy as np
import scipy
import scipy.fft as sfft
from numpy.typing import NDArray

import quilting

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
BLOCK = 48
STAGES = ("costs", "select", "seams", "paste", "render", "stats")
MIB = 1024 * 1024


@dataclass(frozen=True)
class Case:
    name: str
    texture: str
    crop: int | None  # side of the top-left crop of the texture, or None for all of it
    size: int
    target_s: float | None = None
    target_mib: float | None = None

    def load(self) -> NDArray[np.generic]:
        image = quilting.read_image(DATA / f"{self.texture}.png")
        return image if self.crop is None else np.ascontiguousarray(image[: self.crop, : self.crop])


CASES = {
    case.name: case
    for case in (
        Case("512-gravel", "gravel", None, 512, target_s=0.2),
        Case("512-hubble", "hubble", None, 512, target_s=0.2),
        Case("2048-gravel", "gravel", None, 2048, target_s=2.0, target_mib=300.0),
        Case("2048-hubble", "hubble", None, 2048, target_s=2.0, target_mib=300.0),
        Case("1024-gravel128", "gravel", 128, 1024),
        Case("1024-hubble128", "hubble", 128, 1024),
    )
}


@dataclass
class CaseResult:
    case: str
    texture: str
    channels: int
    size: int
    blocks: int
    engine_s: float  # medians over the timed runs
    wall_s: float
    min_wall_s: float
    stages_s: dict[str, float]
    peak_rss_mib: float
    tracemalloc_mib: float
    random_s: float  # engine median of mode="random"
    naive_s: float | None  # wall median of the naive baseline, None when skipped
    seam_error_mean: float
    largest_copy: float
    unused: float


# --- the naive baseline ------------------------------------------------------------------


def naive_costs(
    source: NDArray[np.float64], template: NDArray[np.float64], mask: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Masked SSD of ``template`` at every block position of ``source``, by full-size FFTs.

    ``E = sum M S^2 - 2 sum (M T) S + sum M T^2``; every transform is recomputed per call.
    """
    h, w, channels = source.shape
    block = mask.shape[0]
    shape = (h, w)
    mask_spectrum = np.conj(sfft.rfft2(mask, s=shape))
    cost = sfft.irfft2(mask_spectrum * sfft.rfft2((source**2).sum(axis=2)), s=shape)
    for c in range(channels):
        kernel = np.conj(sfft.rfft2(mask * template[..., c], s=shape))
        cost -= 2 * sfft.irfft2(kernel * sfft.rfft2(source[..., c]), s=shape)
    cost += float((mask[..., None] * template**2).sum())
    field: NDArray[np.float64] = np.maximum(cost[: h - block + 1, : w - block + 1], 0.0)
    return field


def naive_quilt(
    texture: NDArray[np.generic], size: int, block: int, tolerance: float = 0.1, seed: int = 0
) -> NDArray[np.float64]:
    """Raster-scan quilting, one block at a time, straight edges: the straightforward way."""
    source = texture.astype(np.float64).reshape(texture.shape[0], texture.shape[1], -1)
    source /= {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(texture.dtype, 1.0)
    rng = np.random.default_rng(seed)
    overlap = max(1, block // 6)
    step = block - overlap
    n = max(1, -(-(size - overlap) // step))
    out = np.zeros((n * step + overlap, n * step + overlap, source.shape[2]))
    field_w = source.shape[1] - block + 1
    for i in range(n):
        for j in range(n):
            y, x = i * step, j * step
            if i == 0 and j == 0:
                index = int(rng.integers((source.shape[0] - block + 1) * field_w))
            else:
                mask = np.zeros((block, block))
                if j:
                    mask[:, :overlap] = 1.0
                if i:
                    mask[:overlap, :] = 1.0
                cost = naive_costs(source, out[y : y + block, x : x + block], mask).ravel()
                accepted = np.flatnonzero(cost <= (1 + tolerance) * cost.min())
                index = int(accepted[rng.integers(accepted.size)])
            sy, sx = divmod(index, field_w)
            out[y : y + block, x : x + block] = source[sy : sy + block, sx : sx + block]
    return out[:size, :size]


# --- one case, in its own process ----------------------------------------------------------


def max_rss_bytes() -> int:
    """Peak resident set size of this process so far (``ru_maxrss`` is KiB on Linux)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak if sys.platform == "darwin" else peak * 1024


def run_case(case: Case, repeat: int, naive: bool) -> CaseResult:
    """Time and measure one case; meant to run in a fresh process (see ``--one``)."""
    texture = case.load()
    size = (case.size, case.size)
    baseline_rss = max_rss_bytes()

    engine: list[float] = []
    wall: list[float] = []
    stages: dict[str, list[float]] = {stage: [] for stage in STAGES}
    result = None
    for _ in range(repeat):
        start = time.perf_counter()
        result = quilting.synthesize(texture, size, block=BLOCK)
        wall.append(time.perf_counter() - start)
        engine.append(result.timings["total"])
        for stage in STAGES:
            stages[stage].append(result.timings.get(stage, 0.0))
    peak_rss = max_rss_bytes() - baseline_rss
    assert result is not None and result.stats is not None

    tracemalloc.start()
    quilting.synthesize(texture, size, block=BLOCK)
    traced_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()

    random_s = statistics.median(
        quilting.synthesize(texture, size, block=BLOCK, mode="random").timings["total"]
        for _ in range(repeat)
    )
    naive_runs = []
    for _ in range(repeat if naive else 0):
        start = time.perf_counter()
        naive_quilt(texture, case.size, BLOCK)
        naive_runs.append(time.perf_counter() - start)

    grid = result.layout.passes[0].grid
    return CaseResult(
        case=case.name,
        texture=f"{case.texture} {texture.shape[1]}x{texture.shape[0]}",
        channels=1 if texture.ndim == 2 else texture.shape[2],
        size=case.size,
        blocks=grid.rows * grid.cols,
        engine_s=statistics.median(engine),
        wall_s=statistics.median(wall),
        min_wall_s=min(wall),
        stages_s={stage: statistics.median(times) for stage, times in stages.items()},
        peak_rss_mib=peak_rss / MIB,
        tracemalloc_mib=traced_peak / MIB,
        random_s=random_s,
        naive_s=statistics.median(naive_runs) if naive_runs else None,
        seam_error_mean=result.stats.seam_error_mean,
        largest_copy=result.stats.largest_copy,
        unused=result.stats.unused,
    )


def run_in_subprocess(name: str, repeat: int, naive: bool) -> CaseResult:
    """Run ``--one name`` in a fresh interpreter and read its JSON line back."""
    script = str(Path(__file__).resolve())
    command = [sys.executable, script, "--one", name, "--repeat", str(repeat)]
    if naive:
        command.append("--naive")
    done = subprocess.run(command, stdout=subprocess.PIPE, text=True, check=True)
    return CaseResult(**json.loads(done.stdout.strip().splitlines()[-1]))


# --- report --------------------------------------------------------------------------------


def verdict(result: CaseResult) -> tuple[str, str]:
    """The case's targets as text and PASS / MISS (``-`` when the issue names none)."""
    case = CASES[result.case]
    targets, ok = [], True
    if case.target_s is not None:
        targets.append(f"<={case.target_s:g} s")
        ok &= result.wall_s <= case.target_s
    if case.target_mib is not None:
        targets.append(f"<={case.target_mib:g} MiB")
        ok &= result.peak_rss_mib <= case.target_mib
    if not targets:
        return "-", "-"
    return ", ".join(targets), "PASS" if ok else "MISS"


def machine() -> dict[str, object]:
    return benchtools.machine(numpy=np.__version__, scipy=scipy.__version__)


def report(results: list[CaseResult], repeat: int) -> str:
    main_rows = []
    for r in results:
        target, ok = verdict(r)
        main_rows.append(
            [r.case, r.texture, str(r.channels), f"{r.size}x{r.size}", str(r.blocks)]
            + [f"{x:.3f}" for x in (r.engine_s, r.wall_s, r.min_wall_s)]
            + [f"{r.peak_rss_mib:.1f}", f"{r.tracemalloc_mib:.1f}"]
            + [f"{r.stages_s[s]:.3f}" for s in STAGES]
            + [target, ok]
        )
    main = benchtools.table(
        [
            "case",
            "texture",
            "ch",
            "output",
            "blocks",
            "engine s",
            "wall s",
            "min s",
            "RSS MiB",
            "traced MiB",
            *STAGES,
            "target",
            "result",
        ],
        main_rows,
        left=2,
    )
    base_rows = [
        [r.case, f"{r.engine_s:.3f}", f"{r.random_s:.3f}", f"{r.engine_s / r.random_s:.2f}"]
        + (
            ["-", "-", "-"]
            if r.naive_s is None
            else [
                f"{r.naive_s:.3f}",
                f"{r.engine_s / r.naive_s:.3f}",
                f"{r.naive_s / r.engine_s:.1f}x",
            ]
        )
        for r in results
    ]
    base = benchtools.table(
        ["case", "quilting s", "random s", "quilt/random", "naive s", "quilt/naive", "speedup"],
        base_rows,
    )
    return (
        f"medians of {repeat} run(s); times in seconds; memory: peak of one call\n\n{main}\n\n"
        f"baselines (same run): random = mode='random' engine time; naive = per-block "
        f"full-size float64 FFT quilting, wall time\n\n{base}"
    )


def main(argv: list[str] | None = None) -> int:
    parser = benchtools.parser(__doc__)
    parser.add_argument("--repeat", type=int, default=5, help="timed runs per case (default 5)")
    parser.add_argument("--quick", action="store_true", help="1 run, 512 cases only")
    parser.add_argument("--full-baseline", action="store_true", help="naive baseline at 2048 too")
    parser.add_argument("--one", choices=sorted(CASES), help=argparse.SUPPRESS)
    parser.add_argument("--naive", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    repeat = max(1, 1 if args.quick else args.repeat)

    if args.one:
        print(json.dumps(asdict(run_case(CASES[args.one], repeat, args.naive))))
        return 0

    info = machine()
    benchtools.show_machine(info)
    names = [n for n in CASES if not args.quick or CASES[n].size == 512]
    results = []
    for name in names:
        print(f"running {name} ...", file=sys.stderr, flush=True)
        naive = args.full_baseline or CASES[name].size < 2048
        results.append(run_in_subprocess(name, repeat, naive))
    print(report(results, repeat))
    benchtools.write_json(
        args.json, {"machine": info, "repeat": repeat, "results": [asdict(r) for r in results]}
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
