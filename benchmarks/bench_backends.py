"""Benchmark of the cost backends fft, reference and gl: per-block and whole-synthesis time.

Measures, in one run (compare only figures measured in the same run):

* per-block cost time: for textures of 128..1024 pixels a side (hubble.png, RGB, extended by
  symmetric padding) and blocks 32 and 64, a batch of requests as the engine makes them
  (L-shaped overlap masks; templates made of two unrelated source blocks, so no candidate
  matches exactly). Each run calls ``prepare`` (per job: spectra, uploads), one request once
  (``first``: per-mask caches, first dispatch), then, timed per block, the batch through
  ``shortlists(requests, 0.1, 3)`` (what the engine calls per wavefront level) and through the
  dense ``fields``. ``fft`` and ``gl`` get 8 requests per call; ``reference`` scores requests
  one at a time whatever the batch, so it gets 1 to fit the budget;
* whole-synthesis time: 512x512 from gravel (gray) and hubble (RGB) crops of 128 and 256,
  blocks 32 and 64, seed 0: the engine time (``Result.timings["total"]``) split into costs
  (the backend), select (exact re-scoring, tolerance rule), seams, paste and the rest (render,
  stats); and whether every backend that ran gave the same image bytes, as the project
  guarantees (every backend picks exactly the blocks ``reference`` picks);
* with ``--gpu``, or when the ``gl`` backend reports a hardware renderer (not llvmpipe,
  softpipe or swrast): 2048x2048 and 8192x8192 from hubble 256x256, block 48, ``gl`` and
  ``fft``, against the issue's targets for an H100-class GPU (``gl`` engine time <= 0.15 s and
  <= 2 s), with where the time goes: costs (GPU kernels and the readback of the shortlists)
  against select, seams and paste on the CPU.

Every cell (one backend, one case) gets ``--budget`` seconds of wall time (``--gpu-budget``
for the GPU cases). One run is predicted first: in the per-block table from the same
backend's run at the next smaller texture (scaled by pixel or candidate count, whichever grows
more), in the synthesis tables from a one-call probe (per-block time x blocks). A cell
predicted over budget is skipped and shown as ``skip (>Ns, est. Ms)``; otherwise it runs up
to ``--repeat`` times while the budget lasts (the ``runs`` column), after an untimed warm-up
when ``repeat + 1`` runs are predicted to fit. Figures are medians over the runs. A backend
that cannot start is reported as ``<name>: unavailable: <reason>`` and its cells are ``-``.
Ratios (``vs fft``) are against ``fft`` in the same run.

Run from the repository root::

    .venv/bin/python benchmarks/bench_backends.py                  # all cases, <= 5 runs each
    .venv/bin/python benchmarks/bench_backends.py --quick          # one small case per table
    .venv/bin/python benchmarks/bench_backends.py --budget 60 --repeat 9 --json backends.json
    .venv/bin/python benchmarks/bench_backends.py --gpu            # GPU cases even on llvmpipe
"""

from __future__ import annotations

import functools
import hashlib
import math
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from importlib import metadata
from pathlib import Path
from typing import TypeVar

import benchtools
import numpy as np
import scipy
from benchtools import fmt
from numpy.typing import NDArray

import quilting
from quilting.backends import get_backend
from quilting.core.fields import CostBackend, CostRequest
from quilting.core.grid import Grid, Overlap
from quilting.core.pixels import to_working

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
BACKENDS = ("fft", "reference", "gl")
TOLERANCE = 0.1
MIN_CANDIDATES = 3
BATCH = {"fft": 8, "reference": 1, "gl": 8}  # requests per call in the per-block table
BLOCK_SIZES = (128, 256, 512, 1024)
BLOCKS = (32, 64)
SYNTH_OUTPUT = 512
GPU_BLOCK = 48
GPU_TARGETS = {2048: 0.15, 8192: 2.0}  # gl engine time, seconds (H100-class GPU)
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "software rasterizer")
OTHER = ("render", "stats")

T = TypeVar("T")


# --- backends ------------------------------------------------------------------------------


@dataclass
class Availability:
    name: str
    available: bool
    reason: str  # why not, when unavailable
    renderer: str | None = None  # gl only: the OpenGL renderer string, when the backend tells

    @property
    def hardware(self) -> bool:
        """Whether ``renderer`` names a real GPU rather than a software rasterizer."""
        text = (self.renderer or "").lower()
        return bool(text) and not any(soft in text for soft in SOFTWARE_RENDERERS)


def describe(error: BaseException) -> str:
    return f"{type(error).__name__}: {error}"


def probe(name: str) -> Availability:
    """Start the backend once; for ``gl`` also read its renderer string (after a tiny job)."""
    try:
        backend = get_backend(name)
    except Exception as exc:  # a backend that cannot start, whatever the reason
        return Availability(name, False, describe(exc))
    renderer = getattr(backend, "renderer", None)
    try:
        if name == "gl" and renderer is None:  # perhaps known only once a context is up
            backend.prepare(np.zeros((16, 16, 3), dtype=np.float32), 8)
            renderer = getattr(backend, "renderer", None)
            backend.close()
    except Exception as exc:
        return Availability(name, False, describe(exc))
    return Availability(name, True, "", None if renderer is None else str(renderer))


# --- sampling within a budget --------------------------------------------------------------


def sample(run: Callable[[], T], estimate_s: float, budget_s: float, repeat: int) -> list[T]:
    """Up to ``repeat`` results of ``run`` within ``budget_s`` of wall time, after a warm-up.

    The caller has checked ``estimate_s`` (one run, predicted; 0 when unknown) against the
    budget. The warm-up is made only when it is cheap (``(repeat + 1) * estimate_s`` fits); it
    is dropped when a later run fits, else it is the only result.
    """
    warm = estimate_s * (repeat + 1) <= budget_s
    results: list[T] = []
    spent = last = 0.0
    while len(results) < repeat + warm and (not results or spent + last <= budget_s):
        start = time.perf_counter()
        results.append(run())
        last = time.perf_counter() - start
        spent += last
    return results[1:] if warm and len(results) > 1 else results


def skip_note(budget_s: float, estimate_s: float) -> str:
    known = f", est. {estimate_s:.0f}s" if math.isfinite(estimate_s) else ""
    return f"skip (>{budget_s:g}s{known})"


# --- textures ------------------------------------------------------------------------------


def load(name: str, side: int) -> NDArray[np.generic]:
    """``tests/data/<name>.png`` cropped to, or extended by mirroring to, ``side`` x ``side``."""
    image = quilting.read_image(DATA / f"{name}.png")
    if image.shape[0] < side or image.shape[1] < side:
        extra = [(0, max(0, side - image.shape[0])), (0, max(0, side - image.shape[1]))]
        image = np.pad(image, extra + [(0, 0)] * (image.ndim - 2), mode="symmetric")
    return np.ascontiguousarray(image[:side, :side])


def working(texture: NDArray[np.generic]) -> NDArray[np.float32]:
    """The engine's working format: (H, W, C) float32 in [0, 1]."""
    return to_working(texture.reshape(texture.shape[0], texture.shape[1], -1))


def make_requests(source: NDArray[np.float32], block: int, count: int) -> list[CostRequest]:
    """``count`` L-overlap requests: a source block under the top strip of another one."""
    overlap = max(1, block // 6)
    mask = Grid(block=block, overlap=overlap, rows=2, cols=2).overlap_mask(Overlap.BOTH)
    rng = np.random.default_rng(0)
    span = (source.shape[0] - block + 1, source.shape[1] - block + 1)
    requests = []
    for _ in range(count):
        (y1, y2), (x1, x2) = rng.integers(span[0], size=2), rng.integers(span[1], size=2)
        template = source[y1 : y1 + block, x1 : x1 + block].copy()
        template[:overlap] = source[y2 : y2 + overlap, x2 : x2 + block]
        requests.append(CostRequest(template, mask))
    return requests


def per_block_probe(backend: CostBackend, source: NDArray[np.float32], block: int) -> float:
    """Seconds per block of one ``shortlists`` call (after a priming call): for estimates."""
    requests = make_requests(source, block, BATCH.get(backend.name, 8))
    backend.prepare(source, block)
    try:
        backend.shortlists(requests[:1], TOLERANCE, MIN_CANDIDATES)  # caches, first dispatch
        start = time.perf_counter()
        backend.shortlists(requests, TOLERANCE, MIN_CANDIDATES)
        return (time.perf_counter() - start) / len(requests)
    finally:
        backend.close()


# --- per-block cost time -------------------------------------------------------------------


@dataclass
class BlockCell:
    texture: int
    block: int
    backend: str
    requests: int
    runs: int = 0
    run_s: float | None = None  # median wall time of one whole run (for estimates)
    prepare_ms: float | None = None  # per job
    first_ms: float | None = None  # the first call (one request) after prepare
    shortlists_ms: float | None = None  # per block
    fields_ms: float | None = None  # per block
    note: str = ""


def block_run(
    backend: CostBackend, source: NDArray[np.float32], block: int, requests: list[CostRequest]
) -> tuple[float, float, float, float, float]:
    """One run: prepare, first call, batch shortlists, batch fields; seconds of each, total."""
    start = time.perf_counter()
    backend.prepare(source, block)
    try:
        prepared = time.perf_counter()
        backend.shortlists(requests[:1], TOLERANCE, MIN_CANDIDATES)
        first = time.perf_counter()
        backend.shortlists(requests, TOLERANCE, MIN_CANDIDATES)
        listed = time.perf_counter()
        backend.fields(requests)
        dense = time.perf_counter()
    finally:
        backend.close()
    n = len(requests)
    return (
        prepared - start,
        first - prepared,
        (listed - first) / n,
        (dense - listed) / n,
        time.perf_counter() - start,
    )


def growth(block: int, smaller: int, larger: int) -> float:
    """Predicted cost ratio between two texture sides: the larger of the pixel ratio (FFTs)
    and the candidate ratio (direct sums)."""
    return max(larger / smaller, (larger - block + 1) / (smaller - block + 1)) ** 2


def bench_blocks(
    available: dict[str, Availability],
    sizes: Sequence[int],
    blocks: Sequence[int],
    repeat: int,
    budget_s: float,
) -> list[BlockCell]:
    textures = {side: working(load("hubble", side)) for side in sizes}
    cells: list[BlockCell] = []
    for name in BACKENDS:
        if not available[name].available:
            cells += [
                BlockCell(side, block, name, BATCH[name], note="unavailable")
                for side in sizes
                for block in blocks
            ]
            continue
        backend = get_backend(name)
        for block in blocks:
            previous: BlockCell | None = None
            for side in sizes:
                cell = BlockCell(side, block, name, BATCH[name])
                cells.append(cell)
                if block > side:
                    cell.note = "block > texture"
                    continue
                estimate = 0.0  # unknown: the smallest size, or the previous one failed
                if previous is not None and previous.run_s is not None:
                    estimate = previous.run_s * growth(block, previous.texture, side)
                elif previous is not None and previous.note.startswith("skip"):
                    estimate = math.inf
                if estimate > budget_s:
                    cell.note = skip_note(budget_s, estimate)
                    previous = cell
                    continue
                print(f"blocks: {name} {side} b{block} ...", file=sys.stderr, flush=True)
                source = textures[side]
                requests = make_requests(source, block, BATCH[name])
                try:
                    once = functools.partial(block_run, backend, source, block, requests)
                    runs = sample(once, estimate, budget_s, repeat)
                except Exception as exc:
                    cell.note = "error: " + describe(exc)
                    print(f"  {cell.note}", file=sys.stderr, flush=True)
                    previous = cell
                    continue
                cell.runs = len(runs)
                cell.prepare_ms, cell.first_ms, cell.shortlists_ms, cell.fields_ms = (
                    1000 * statistics.median(run[k] for run in runs) for k in range(4)
                )
                cell.run_s = statistics.median(run[4] for run in runs)
                previous = cell
    return cells


def ratio(value: float | None, base: float | None) -> str:
    return "-" if value is None or not base else f"{value / base:.2f}"


def report_blocks(cells: list[BlockCell]) -> str:
    fft = {(c.texture, c.block): c for c in cells if c.backend == "fft"}
    order = {name: k for k, name in enumerate(BACKENDS)}
    rows = []
    for c in sorted(cells, key=lambda c: (c.block, c.texture, order[c.backend])):
        base = fft.get((c.texture, c.block))
        rows.append(
            [
                f"{c.texture}x{c.texture}",
                str(c.block),
                c.backend,
                str(c.requests),
                str(c.runs) if c.runs else "-",
                fmt(c.prepare_ms, 2),
                fmt(c.first_ms, 2),
                fmt(c.shortlists_ms, 3),
                fmt(c.fields_ms, 3),
                ratio(c.shortlists_ms, base.shortlists_ms if base else None),
                ratio(c.fields_ms, base.fields_ms if base else None),
                c.note,
            ]
        )
    return benchtools.table(
        [
            "texture",
            "block",
            "backend",
            "batch",
            "runs",
            "prepare ms",
            "first ms",
            "shortlists ms/block",
            "fields ms/block",
            "vs fft",
            "fields vs fft",
            "note",
        ],
        rows,
        left=3,
    )


# --- whole synthesis -----------------------------------------------------------------------


@dataclass(frozen=True)
class SynthCase:
    texture: str
    side: int
    output: int
    block: int
    target_s: float | None = None  # gl engine time (GPU cases)

    @property
    def name(self) -> str:
        return f"{self.output}-{self.texture}{self.side}-b{self.block}"

    @property
    def scored(self) -> int:
        """Blocks that need a cost field (all but the first)."""
        grid = Grid.covering(self.output, self.output, self.block, max(1, self.block // 6))
        return grid.rows * grid.cols - 1


@dataclass
class SynthCell:
    case: str
    backend: str
    channels: int
    runs: int = 0
    engine_s: float | None = None
    wall_s: float | None = None
    stages_s: dict[str, float] = field(default_factory=dict)
    renderer: str | None = None
    digest: str | None = None  # sha256 of the image bytes, the same in every run
    note: str = ""


def synth_run(
    texture: NDArray[np.generic], case: SynthCase, name: str
) -> tuple[float, dict[str, float], str, str | None]:
    start = time.perf_counter()
    result = quilting.synthesize(
        texture, (case.output, case.output), block=case.block, backend=name, seed=0
    )
    wall = time.perf_counter() - start
    if result.backend != name:
        raise RuntimeError(f"asked for backend {name!r}, the engine used {result.backend!r}")
    digest = hashlib.sha256(result.image.tobytes()).hexdigest()
    renderer = getattr(result, "renderer", None)
    return wall, dict(result.timings), digest, None if renderer is None else str(renderer)


def bench_synthesis(
    available: dict[str, Availability],
    cases: Sequence[SynthCase],
    names: Sequence[str],
    repeat: int,
    budget_s: float,
) -> list[SynthCell]:
    """Every case with every backend in ``names``; one run is estimated by a one-call probe."""
    cells: list[SynthCell] = []
    for case in cases:
        texture = load(case.texture, case.side)
        channels = 1 if texture.ndim == 2 else texture.shape[2]
        for name in names:
            cell = SynthCell(case.name, name, channels)
            cells.append(cell)
            if not available[name].available:
                cell.note = "unavailable"
                continue
            print(f"synthesis: {name} {case.name} ...", file=sys.stderr, flush=True)
            try:
                per_block = per_block_probe(get_backend(name), working(texture), case.block)
                estimate = per_block * case.scored
                if estimate > budget_s:
                    cell.note = skip_note(budget_s, estimate)
                    continue
                once = functools.partial(synth_run, texture, case, name)
                runs = sample(once, estimate, budget_s, repeat)
            except Exception as exc:
                cell.note = "error: " + describe(exc)
                print(f"  {cell.note}", file=sys.stderr, flush=True)
                continue
            cell.runs = len(runs)
            cell.wall_s = statistics.median(run[0] for run in runs)
            cell.engine_s = statistics.median(run[1]["total"] for run in runs)
            stages = sorted({stage for run in runs for stage in run[1]} - {"total"})
            cell.stages_s = {
                s: statistics.median(run[1].get(s, 0.0) for run in runs) for s in stages
            }
            digests = {run[2] for run in runs}
            cell.digest = digests.pop() if len(digests) == 1 else "runs differ"
            cell.renderer = runs[0][3]
    return cells


def identical(cells: list[SynthCell], case: str) -> str:
    """``yes`` / ``no`` with the backends compared, for one case."""
    ran = [c for c in cells if c.case == case and c.digest is not None]
    names = ", ".join(c.backend for c in ran)
    if any(c.digest == "runs differ" for c in ran):
        return f"no: runs of one backend differ ({names})"
    if len(ran) < 2:
        return f"- (only {names or 'none'} ran)"
    return ("yes" if len({c.digest for c in ran}) == 1 else "no") + f" ({names})"


def stage(cell: SynthCell, *names: str) -> float | None:
    if cell.engine_s is None:
        return None
    return sum(cell.stages_s.get(n, 0.0) for n in names)


def report_synthesis(cells: list[SynthCell], cases: Sequence[SynthCase], gpu: bool) -> str:
    fft = {c.case: c for c in cells if c.backend == "fft"}
    targets = {case.name: case.target_s for case in cases}
    rows = []
    for c in cells:
        base = fft.get(c.case)
        costs, total = stage(c, "costs"), c.engine_s
        row = [
            c.case,
            str(c.channels),
            c.backend,
            str(c.runs) if c.runs else "-",
            fmt(c.engine_s, 3),
            fmt(c.wall_s, 3),
            ratio(c.engine_s, base.engine_s if base else None),
            fmt(costs, 3),
            fmt(stage(c, "select"), 3),
            fmt(stage(c, "seams"), 3),
            fmt(stage(c, "paste"), 3),
            fmt(stage(c, *OTHER), 3),
            "-" if costs is None or not total else f"{100 * costs / total:.0f} %",
        ]
        if gpu:
            target = targets.get(c.case) if c.backend == "gl" else None
            verdict = (
                "-" if target is None or total is None else "PASS" if total <= target else "FAIL"
            )
            row += ["-" if target is None else f"<={target:g} s", verdict]
        rows.append([*row, c.note])
    headers = [
        "case",
        "ch",
        "backend",
        "runs",
        "engine s",
        "wall s",
        "vs fft",
        "costs" + (" (GPU+readback for gl)" if gpu else ""),
        "select",
        "seams",
        "paste",
        "render+stats",
        "costs share",
    ]
    if gpu:
        headers += ["target", "result"]
    table = benchtools.table([*headers, "note"], rows, left=3)
    lines = [f"  {case.name}: identical: {identical(cells, case.name)}" for case in cases]
    return table + "\n\nsame image bytes for the same seed across backends:\n" + "\n".join(lines)


# --- main ----------------------------------------------------------------------------------


def machine() -> dict[str, object]:
    try:
        moderngl = metadata.version("moderngl")
    except metadata.PackageNotFoundError:
        moderngl = "not installed"
    return benchtools.machine(numpy=np.__version__, scipy=scipy.__version__, moderngl=moderngl)


def synthesis_cases(quick: bool) -> list[SynthCase]:
    cases = [
        SynthCase(texture, side, SYNTH_OUTPUT, block)
        for side in (128, 256)
        for texture in ("gravel", "hubble")
        for block in BLOCKS
    ]
    return cases[:1] if quick else cases


def gpu_cases(quick: bool) -> list[SynthCase]:
    cases = [
        SynthCase("hubble", 256, out, GPU_BLOCK, target) for out, target in GPU_TARGETS.items()
    ]
    return cases[:1] if quick else cases


def main(argv: list[str] | None = None) -> int:
    parser = benchtools.parser(__doc__)
    parser.add_argument(
        "--repeat", type=int, default=5, help="most timed runs per cell (default 5)"
    )
    parser.add_argument("--quick", action="store_true", help="one small case per table, 1 run")
    parser.add_argument(
        "--budget", type=float, default=20.0, help="wall seconds per cell (default 20)"
    )
    parser.add_argument(
        "--gpu", action="store_true", help="add the 2048/8192 cases even without a hardware GPU"
    )
    parser.add_argument(
        "--gpu-budget", type=float, default=120.0, help="wall seconds per GPU-case cell (120)"
    )
    args = parser.parse_args(argv)
    repeat = max(1, 1 if args.quick else args.repeat)
    started = time.perf_counter()

    info = machine()
    benchtools.show_machine(info)
    available = {name: probe(name) for name in BACKENDS}
    for a in available.values():
        if not a.available:
            print(f"{a.name}: unavailable: {a.reason}", flush=True)
    gl = available["gl"]
    if gl.available:
        kind = "hardware" if gl.hardware else "software" if gl.renderer else "unknown"
        print(f"gl: renderer: {gl.renderer or 'not reported'} ({kind})", flush=True)
    gpu = args.gpu or gl.hardware

    sizes, blocks = (BLOCK_SIZES[:1], BLOCKS[:1]) if args.quick else (BLOCK_SIZES, BLOCKS)
    block_cells = bench_blocks(available, sizes, blocks, repeat, args.budget)
    cases = synthesis_cases(args.quick)
    synth_cells = bench_synthesis(available, cases, BACKENDS, repeat, args.budget)
    big = gpu_cases(args.quick) if gpu else []
    gpu_cells = bench_synthesis(available, big, ("gl", "fft"), repeat, args.gpu_budget)

    print(
        f"\nper-block cost time: hubble RGB, L masks, tolerance {TOLERANCE}, "
        f"min_candidates {MIN_CANDIDATES}; medians of up to {repeat} run(s), "
        f"budget {args.budget:g} s per cell\n"
        "prepare = per job; first = first call after prepare (1 request); shortlists = the "
        "engine's call, per block; fields = dense fields, per block; vs fft = shortlists "
        "ratio\n"
    )
    print(report_blocks(block_cells))
    print(
        f"\nwhole synthesis: {SYNTH_OUTPUT}x{SYNTH_OUTPUT}, seed 0, mode cut; seconds, medians; "
        "engine = Result.timings['total']; vs fft = engine ratio\n"
    )
    print(report_synthesis(synth_cells, cases, gpu=False))
    if gpu:
        print(
            f"\nGPU cases: hubble 256x256, block {GPU_BLOCK}; targets are gl engine time on an "
            f"H100-class GPU; budget {args.gpu_budget:g} s per cell; costs = the backend "
            "(GPU kernels + readback for gl), select/seams/paste/render+stats = CPU\n"
        )
        print(report_synthesis(gpu_cells, big, gpu=True))
    elapsed = benchtools.wall_time(started)
    benchtools.write_json(
        args.json,
        {
            "machine": info,
            "backends": [asdict(a) for a in available.values()],
            "repeat": repeat,
            "budget_s": args.budget,
            "gpu_budget_s": args.gpu_budget,
            "blocks": [asdict(c) for c in block_cells],
            "synthesis": [asdict(c) for c in synth_cells],
            "gpu": [asdict(c) for c in gpu_cells],
            "wall_s": elapsed,
        },
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
