"""Benchmark of ``quilting.transfer``: speed, peak memory and quality against the issue's target.

Measures, for each case (texture onto a target, block 24, mode ``cut``, seed 0, backend
``--backend``, fft by default):

* the median and the minimum over ``--repeat`` runs of the wall time around the call, the
  median engine time (``Result.timings["total"]``) and of every stage (costs, select, seams,
  paste, render + stats); wall minus engine is what happens before the engine starts, mostly
  the correspondence maps;
* the peak memory of one call: the peak RSS increase of a fresh process over its RSS after
  imports and loading the images (``VmHWM`` after a reset through /proc/self/clear_refs;
  ``ru_maxrss`` is useless in a child, it keeps the parent's peak across exec), and the
  tracemalloc peak of one extra, untimed call (numpy reports its allocations to tracemalloc);
* a floor from the same run, since only same-run comparisons mean anything on a noisy
  machine: ``quilting.synthesize`` of the same output size on every pass's grid (same block,
  overlap and so the same number of blocks, no guidance), medians summed over the passes; the
  last pass's grid alone is shown too (for N = 1 the two are the same);
* the blocks placed over all passes, the correspondence error and the mean seam error.

Cases: the gravel texture (256x256 gray) onto the camera target (256x256 gray) with N = 1 and
N = 3 passes, onto the camera upscaled 2x (``scipy.ndimage.zoom``, order 1, rounded and
clipped to uint8: 512x512) with N = 3 (the headline: the issue's target is <= 3 s on the wall
median) with the ``luminance``, ``blurred`` and ``orientation`` correspondences, and the wood
texture (136x136 RGB) onto the chelsea target (451x300 RGB) with N = 3. ``blurred`` and
``orientation`` take another path through the fft backend (no folding of the guide into the
source kernel: one joint inverse transform).

Backends: gravel onto the camera downscaled 4x (64x64, 9 blocks, N = 1) with ``fft``,
``reference`` (direct sums; at most 3 runs) and ``gl`` when it starts, and whether they gave
the same image bytes. With ``--gpu``, or when ``gl`` reports a hardware renderer (not llvmpipe,
softpipe or swrast), every case also runs with ``gl``.

Quality (one run each, in this process): camera 256x256, N = 1 with alpha 0.1, 0.5 and 0.9, and
N = 3 with the default alpha schedule: the Pearson correlation of the output's and the
target's luminance, both blurred by a Gaussian of sigma 2 (structure, not grain); lower alpha
weighs fidelity more and should correlate better. Also the correspondence and seam errors.

Each timed case runs in its own subprocess (this script with the hidden ``--one CASE``), so the
memory figures are not polluted by earlier cases. Images come from ``tests/data``; the chelsea
target is ``examples/cat.png`` (the same photo; the tables call it ``target_chelsea``).

Run from the repository root::

    .venv/bin/python benchmarks/bench_transfer.py               # all cases, 5 runs each
    .venv/bin/python benchmarks/bench_transfer.py --quick       # 256 N=1 and 64x64: smoke test
    .venv/bin/python benchmarks/bench_transfer.py --repeat 9 --json transfer.json
    .venv/bin/python benchmarks/bench_transfer.py --gpu         # also gl, even on llvmpipe
"""

from __future__ import annotations

import argparse
import hashlib
import json
import statistics
import subprocess
import sys
import time
import tracemalloc
from dataclasses import asdict, dataclass, field
from pathlib import Path

import benchtools
import numpy as np
import scipy
from bench_backends import probe
from bench_synthesis import max_rss_bytes
from benchtools import fmt
from numpy.typing import NDArray
from scipy import ndimage

import quilting
from quilting.core.options import Correspondence
from quilting.core.pixels import luminance, to_working

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
#: The images of the repository outside tests/data.
ELSEWHERE = {"target_chelsea": ROOT / "examples" / "cat.png"}
BLOCK = 24
SEED = 0
REFERENCE_RUNS = 3  # most timed runs of the reference backend (seconds per run)
STAGES = ("costs", "select", "seams", "paste")
OTHER = ("render", "stats")
QUALITY_SIGMA = 2.0
QUALITY_ALPHAS = (0.1, 0.5, 0.9)
MIB = 1024 * 1024


# --- images --------------------------------------------------------------------------------


def find(name: str) -> Path:
    """``tests/data/<name>.png``, or the file of the repository that ``ELSEWHERE`` names."""
    path = ELSEWHERE.get(name, DATA / f"{name}.png")
    if not path.is_file():
        raise FileNotFoundError(f"{name}: {path} is missing")
    return path


def label(name: str, image: NDArray[np.generic]) -> str:
    return f"{name} {image.shape[1]}x{image.shape[0]}"


def scaled(image: NDArray[np.generic], scale: float) -> NDArray[np.generic]:
    """``image`` zoomed by ``scale`` (bilinear: order 1), rounded and clipped to its dtype."""
    if scale == 1:
        return image
    factors = (scale, scale) + (1,) * (image.ndim - 2)
    zoomed = ndimage.zoom(image.astype(np.float64), factors, order=1)
    if image.dtype.kind != "u":
        clipped: NDArray[np.generic] = np.clip(zoomed, 0.0, 1.0).astype(image.dtype)
        return clipped
    top = {np.dtype(np.uint8): 255, np.dtype(np.uint16): 65535}[image.dtype]
    rounded: NDArray[np.generic] = np.clip(np.round(zoomed), 0, top).astype(image.dtype)
    return rounded


# --- memory --------------------------------------------------------------------------------


def status_kib(key: str) -> int | None:
    """A ``VmXXX`` line of /proc/self/status in KiB, None off Linux."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return None


def rss_baseline() -> int:
    """Bytes to measure the peak RSS from: the RSS now, after resetting the high-water mark.

    ``ru_maxrss`` is no use in a child process: exec keeps the parent's peak there, so a
    child of a big parent shows no growth at all. Linux resets the peak (``VmHWM``) when 5
    is written to /proc/self/clear_refs; without that, the peak so far (``VmHWM``, else
    ``ru_maxrss``).
    """
    try:
        Path("/proc/self/clear_refs").write_text("5")
        now = status_kib("VmRSS")
    except OSError:
        now = status_kib("VmHWM")
    return max_rss_bytes() if now is None else now * 1024


def rss_peak() -> int:
    """Bytes: the process's peak RSS since :func:`rss_baseline`."""
    peak = status_kib("VmHWM")
    return max_rss_bytes() if peak is None else peak * 1024


@dataclass(frozen=True)
class Case:
    name: str
    texture: str
    target: str
    scale: float  # zoom of the target
    iterations: int
    correspondence: Correspondence = "luminance"
    target_s: float | None = None  # wall median, seconds
    quick: bool = False  # part of --quick
    floor: bool = True  # time the synthesis floor

    def load(self) -> tuple[NDArray[np.generic], NDArray[np.generic], str, str]:
        """Texture, target and their labels."""
        texture_path, target_path = find(self.texture), find(self.target)
        texture = quilting.read_image(texture_path)
        target = quilting.read_image(target_path)
        target_label = label(self.target, target)
        target = scaled(target, self.scale)
        if self.scale != 1:
            target_label += f" x{self.scale:g} = {target.shape[1]}x{target.shape[0]}"
        return texture, target, label(self.texture, texture), target_label


CASES = {
    case.name: case
    for case in (
        Case("camera256-N1", "gravel", "target_camera", 1, 1, quick=True),
        Case("camera256-N3", "gravel", "target_camera", 1, 3),
        Case("camera512-N3", "gravel", "target_camera", 2, 3, target_s=3.0),
        Case("camera512-N3-blurred", "gravel", "target_camera", 2, 3, "blurred"),
        Case("camera512-N3-orientation", "gravel", "target_camera", 2, 3, "orientation"),
        Case("chelsea-N3-rgb", "wood", "target_chelsea", 1, 3),
    )
}
TINY = Case("camera64-N1", "gravel", "target_camera", 0.25, 1, quick=True, floor=False)
ALL_CASES = {**CASES, TINY.name: TINY}


# --- one case, in its own process ----------------------------------------------------------


@dataclass
class CaseResult:
    case: str
    backend: str
    texture: str = ""
    target: str = ""
    channels: int = 0
    passes: list[str] = field(default_factory=list)  # "block/overlap rows x cols"
    blocks: int = 0  # over all passes
    runs: int = 0
    wall_s: float | None = None  # medians over the timed runs unless said otherwise
    min_wall_s: float | None = None
    engine_s: float | None = None
    stages_s: dict[str, float] = field(default_factory=dict)
    peak_rss_mib: float | None = None
    tracemalloc_mib: float | None = None
    floor_pass_s: list[float] = field(default_factory=list)  # synthesize wall, per pass grid
    correspondence_error: float | None = None
    seam_error_mean: float | None = None
    digest: str | None = None  # sha256 of the image bytes, the same in every run
    renderer: str | None = None
    note: str = ""


def run_case(case: Case, backend: str, repeat: int) -> CaseResult:
    """Time and measure one case; meant to run in a fresh process (see ``--one``)."""
    texture, target, texture_label, target_label = case.load()
    baseline_rss = rss_baseline()

    def once() -> quilting.Result:
        return quilting.transfer(
            texture,
            target,
            block=BLOCK,
            iterations=case.iterations,
            correspondence=case.correspondence,
            seed=SEED,
            backend=backend,
        )

    runs = min(repeat, REFERENCE_RUNS) if backend == "reference" else repeat
    wall: list[float] = []
    timings: list[dict[str, float]] = []
    digests = set()
    result = None
    for _ in range(runs):
        start = time.perf_counter()
        result = once()
        wall.append(time.perf_counter() - start)
        timings.append(result.timings)
        digests.add(hashlib.sha256(result.image.tobytes()).hexdigest())
    peak_rss = rss_peak() - baseline_rss
    assert result is not None and result.stats is not None
    if backend != "auto" and result.backend != backend:
        raise RuntimeError(f"asked for backend {backend!r}, the engine used {result.backend!r}")

    traced = None
    if backend != "reference":  # tracemalloc slows the direct sums down too much
        tracemalloc.start()
        once()
        traced = tracemalloc.get_traced_memory()[1] / MIB
        tracemalloc.stop()

    grids = [p.grid for p in result.layout.passes]
    floor = []
    for grid in grids if case.floor else []:
        floor_runs = []
        for _ in range(runs):
            start = time.perf_counter()
            quilting.synthesize(
                texture,
                target.shape[:2],
                block=grid.block,
                overlap=grid.overlap,
                seed=SEED,
                backend=backend,
            )
            floor_runs.append(time.perf_counter() - start)
        floor.append(statistics.median(floor_runs))

    stages = sorted({s for t in timings for s in t})
    return CaseResult(
        case=case.name,
        backend=backend,
        texture=texture_label,
        target=target_label,
        channels=1 if texture.ndim == 2 else texture.shape[2],
        passes=[f"{g.block}/{g.overlap} {g.rows}x{g.cols}" for g in grids],
        blocks=sum(g.rows * g.cols for g in grids),
        runs=runs,
        wall_s=statistics.median(wall),
        min_wall_s=min(wall),
        engine_s=statistics.median(t["total"] for t in timings),
        stages_s={s: statistics.median(t.get(s, 0.0) for t in timings) for s in stages},
        peak_rss_mib=peak_rss / MIB,
        tracemalloc_mib=traced,
        floor_pass_s=floor,
        correspondence_error=result.stats.correspondence_error,
        seam_error_mean=result.stats.seam_error_mean,
        digest=digests.pop() if len(digests) == 1 else "runs differ",
        renderer=result.renderer,
    )


def run_in_subprocess(name: str, backend: str, repeat: int) -> CaseResult:
    """Run ``--one name`` in a fresh interpreter and read its JSON line back."""
    print(f"running {name} with {backend} ...", file=sys.stderr, flush=True)
    script = str(Path(__file__).resolve())
    command = [sys.executable, script, "--one", name, "--backend", backend]
    command += ["--repeat", str(repeat)]
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        lines = done.stderr.strip().splitlines() or [f"exit status {done.returncode}"]
        print(done.stderr, file=sys.stderr, flush=True)
        return CaseResult(name, backend, note="error: " + lines[-1])
    return CaseResult(**json.loads(done.stdout.strip().splitlines()[-1]))


# --- quality -------------------------------------------------------------------------------


@dataclass
class QualityRow:
    iterations: int
    alpha: str
    correlation: float
    correspondence_error: float
    seam_error_mean: float
    largest_copy: float


def structure(image: NDArray[np.generic]) -> NDArray[np.float64]:
    """Luminance blurred by a Gaussian of sigma :data:`QUALITY_SIGMA`, float64."""
    view = image.reshape(image.shape[0], image.shape[1], -1)
    blurred: NDArray[np.float64] = ndimage.gaussian_filter(
        luminance(to_working(view)).astype(np.float64), QUALITY_SIGMA
    )
    return blurred


def bench_quality(backend: str) -> tuple[str, str, list[QualityRow]]:
    """The alpha sweep (N = 1) and N = 3 on the 256x256 camera case, seed 0."""
    texture, target, texture_label, target_label = CASES["camera256-N1"].load()
    wanted = structure(target).ravel()
    settings: list[tuple[int, float | None]] = [(1, a) for a in QUALITY_ALPHAS] + [(3, None)]
    rows = []
    for iterations, alpha in settings:
        print(f"quality: N={iterations} alpha={alpha} ...", file=sys.stderr, flush=True)
        result = quilting.transfer(
            texture,
            target,
            block=BLOCK,
            iterations=iterations,
            alpha=alpha,
            seed=SEED,
            backend=backend,
        )
        stats = result.stats
        assert stats.correspondence_error is not None
        correlation = float(np.corrcoef(structure(result.image).ravel(), wanted)[0, 1])
        shown = f"{alpha:g}" if alpha is not None else "0.1 -> 0.9 (default)"
        rows.append(
            QualityRow(
                iterations,
                shown,
                correlation,
                stats.correspondence_error,
                stats.seam_error_mean,
                stats.largest_copy,
            )
        )
    return texture_label, target_label, rows


# --- report --------------------------------------------------------------------------------


def verdict(r: CaseResult) -> tuple[str, str]:
    target = ALL_CASES[r.case].target_s
    if target is None or r.wall_s is None:
        return "-", "-"
    return f"<={target:g} s", "PASS" if r.wall_s <= target else "MISS"


def stage(r: CaseResult, *names: str) -> float | None:
    return None if r.engine_s is None else sum(r.stages_s.get(n, 0.0) for n in names)


def report_time(results: list[CaseResult]) -> str:
    rows = []
    for r in results:
        case = ALL_CASES[r.case]
        costs = stage(r, "costs")
        outside = None if r.wall_s is None or r.engine_s is None else r.wall_s - r.engine_s
        share = "-" if costs is None or not r.engine_s else f"{100 * costs / r.engine_s:.0f} %"
        rows.append(
            [r.case, r.backend, r.target or "-", str(case.iterations), case.correspondence]
            + [str(r.blocks) if r.blocks else "-", str(r.runs) if r.runs else "-"]
            + [fmt(x) for x in (r.wall_s, r.min_wall_s, r.engine_s)]
            + [fmt(stage(r, s)) for s in STAGES]
            + [
                fmt(stage(r, *OTHER)),
                fmt(outside),
                share,
                *verdict(r),
                r.note,
            ]
        )
    headers = ["case", "backend", "target", "N", "correspondence", "blocks", "runs", "wall s"]
    headers += ["min s", "engine s", *STAGES, "render+stats", "maps etc.", "costs share"]
    return benchtools.table([*headers, "target", "result", "note"], rows, left=5)


def report_memory(results: list[CaseResult]) -> str:
    rows = []
    for r in results:
        floor_all = sum(r.floor_pass_s) if r.floor_pass_s else None
        floor_last = r.floor_pass_s[-1] if r.floor_pass_s else None
        rows.append(
            [
                r.case,
                r.backend,
                r.texture or "-",
                ", ".join(r.passes) or "-",
                fmt(r.peak_rss_mib, 1),
                fmt(r.tracemalloc_mib, 1),
                fmt(floor_last),
                fmt(floor_all),
                "-" if not floor_all or r.wall_s is None else f"{r.wall_s / floor_all:.2f}",
                "-" if not floor_last or r.wall_s is None else f"{r.wall_s / floor_last:.2f}",
                fmt(r.correspondence_error, 5),
                fmt(r.seam_error_mean, 5),
            ]
        )
    headers = ["case", "backend", "texture", "passes (block/overlap rows x cols)", "RSS MiB"]
    headers += ["traced MiB", "synth last s", "synth all s", "vs all", "vs last"]
    return benchtools.table([*headers, "corr. error", "seam error"], rows, left=4)


def report_backends(results: list[CaseResult]) -> str:
    walls = {r.backend: r.wall_s for r in results if r.wall_s}
    rows = []
    for r in results:
        reference, fft = walls.get("reference"), walls.get("fft")
        rows.append(
            [r.backend, r.renderer or "-", str(r.runs) if r.runs else "-"]
            + [fmt(x) for x in (r.wall_s, r.engine_s, stage(r, "costs"))]
            + [
                "-" if not (reference and r.wall_s) else f"{reference / r.wall_s:.1f}x",
                "-" if not (fft and r.wall_s) else f"{r.wall_s / fft:.2f}",
                "-" if r.digest is None else r.digest[:12],
                r.note,
            ]
        )
    table = benchtools.table(
        [
            "backend",
            "renderer",
            "runs",
            "wall s",
            "engine s",
            "costs",
            "speedup vs reference",
            "vs fft",
            "image sha256",
            "note",
        ],
        rows,
        left=2,
    )
    digests = [r.digest for r in results if r.digest is not None]
    if len(digests) < 2 or "runs differ" in digests:
        same = "- (runs of one backend differ)" if "runs differ" in digests else "-"
    else:
        same = "yes" if len(set(digests)) == 1 else "no"
    names = ", ".join(r.backend for r in results if r.digest is not None)
    return f"{table}\n\nsame image bytes across backends: {same} ({names})"


def report_quality(texture: str, target: str, rows: list[QualityRow]) -> str:
    table = benchtools.table(
        ["N", "alpha", "correlation", "corr. error", "seam error", "largest copy"],
        [
            [
                str(q.iterations),
                q.alpha,
                f"{q.correlation:.4f}",
                f"{q.correspondence_error:.5f}",
                f"{q.seam_error_mean:.5f}",
                f"{q.largest_copy:.3f}",
            ]
            for q in rows
        ],
        left=2,
    )
    return (
        f"quality: {texture} onto {target}, block {BLOCK}, seed {SEED}; correlation = Pearson "
        f"r of output and target luminance, both Gaussian-blurred (sigma {QUALITY_SIGMA:g}); "
        "corr. error = mean squared luminance difference (after remapping); seam error = "
        "mean over the last pass's seam pixels\n\n" + table
    )


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown"


def machine() -> dict[str, object]:
    return benchtools.machine(cpu=cpu_model(), numpy=np.__version__, scipy=scipy.__version__)


def main(argv: list[str] | None = None) -> int:
    parser = benchtools.parser(__doc__)
    parser.add_argument("--repeat", type=int, default=5, help="timed runs per case (default 5)")
    parser.add_argument("--quick", action="store_true", help="1 run, 256 N=1 and 64x64 only")
    parser.add_argument(
        "--backend",
        default="fft",
        choices=("fft", "gl", "reference", "auto"),
        help="backend of the main cases and the quality runs (default fft)",
    )
    parser.add_argument(
        "--gpu", action="store_true", help="also run every case with gl, even on llvmpipe"
    )
    parser.add_argument("--one", choices=sorted(ALL_CASES), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    repeat = max(1, 1 if args.quick else args.repeat)

    if args.one:
        print(json.dumps(asdict(run_case(ALL_CASES[args.one], args.backend, repeat))))
        return 0

    started = time.perf_counter()
    info = machine()
    benchtools.show_machine(info)
    tree = benchtools.source_tree(ROOT)
    print(f"source: {tree}", flush=True)
    gl = probe("gl")
    if gl.available:
        kind = "hardware" if gl.hardware else "software" if gl.renderer else "unknown"
        print(f"gl: renderer: {gl.renderer or 'not reported'} ({kind})", flush=True)
    else:
        print(f"gl: unavailable: {gl.reason}", flush=True)
    backends = [args.backend]
    if (args.gpu or gl.hardware) and args.backend != "gl":
        backends.append("gl")

    names = [n for n, c in CASES.items() if c.quick or not args.quick]
    results = [run_in_subprocess(n, b, repeat) for n in names for b in backends]
    tiny_backends = ["fft", "reference"] + (["gl"] if gl.available else [])
    tiny = [run_in_subprocess(TINY.name, b, repeat) for b in tiny_backends]
    quality = bench_quality(args.backend)

    target = CASES["camera512-N3"]
    print(
        f"\ntexture transfer, block {BLOCK} (later passes 2/3 smaller each), mode cut, seed "
        f"{SEED}; seconds, medians of {repeat} run(s) unless said; the 512x512 target is "
        f"target_camera.png upscaled {target.scale:g}x by scipy.ndimage.zoom (order 1), "
        "rounded and clipped to uint8\n"
        "wall = around the call; engine = Result.timings['total']; maps etc. = wall - engine "
        "(correspondence maps, validation); target = the issue's, checked on the wall median\n"
    )
    print(report_time(results))
    print(
        "\nmemory (one call): RSS = peak RSS increase of a fresh process over its RSS after "
        "loading the images (VmHWM); traced = tracemalloc peak of one extra call\n"
        "floor (same run): quilting.synthesize of the same output size on each pass's grid, "
        "wall medians; synth all = summed over the passes (the same blocks), synth last = the "
        "last pass's grid only; vs = transfer wall / floor\n"
        "corr. error = Result.stats.correspondence_error (mean squared difference of the maps: "
        "luminance, blurred luminance, or orientation, not comparable across kinds); seam "
        "error = mean over the last pass's seam pixels\n"
    )
    print(report_memory(results))
    print(
        f"\nbackends: {TINY.texture} onto {TINY.target} downscaled {1 / TINY.scale:g}x "
        f"(64x64, order 1), N = 1; reference at most {REFERENCE_RUNS} run(s); speedup = "
        "reference wall / wall; vs fft = wall / fft wall\n"
    )
    print(report_backends(tiny))
    print()
    print(report_quality(*quality))
    elapsed = benchtools.wall_time(started)
    benchtools.write_json(
        args.json,
        {
            "machine": info,
            "source": tree,
            "gl": asdict(gl),
            "repeat": repeat,
            "cases": [asdict(r) for r in results],
            "backends": [asdict(r) for r in tiny],
            "quality": [asdict(q) for q in quality[2]],
            "wall_s": elapsed,
        },
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
