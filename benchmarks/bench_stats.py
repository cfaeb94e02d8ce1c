"""Benchmark of the statistics stage (``result.stats``): its time, share and memory, before/after.

Two parts, both comparing this checkout's ``quilting.core.stats`` with the same module at an
earlier commit (default: 7f13b49, the last commit before the cell-by-cell ownership map and
the run-length reading of it):

1. The stage alone, in this process: the repetition measure (largest verbatim copy, unused
   share) of both versions on the same layouts, median seconds of repeated calls, the
   stage's own tracemalloc peak (numpy reports its buffers to it, so the figure is free of
   the noise of a shared machine), and whether both give the same figures.
2. Whole syntheses from 256x256 gray (gravel) and RGB (hubble) textures, block 48, seed 1,
   in three layouts (``--layouts``: plain, ``tileable="both"``, ``mode="walk"``), one fresh
   process a run, before and after interleaved: the stats stage's seconds and share of the
   engine time (``result.timings``), medians of ``--runs`` runs, and the largest peak RSS of
   those runs (the child's VmHWM). Both run from git worktrees of the earlier commit, the
   "after" one with this checkout's stage modules (``STAGE``: ``core/stats.py`` and the
   ``grid``, ``walk`` and ``layout`` modules it renders with) copied in, so that only those
   differ (other uncommitted work in the tree changes neither), which works while those
   modules need nothing newer than the earlier commit has; or, with ``--after REV``, from a
   worktree of that commit as it is. The image bytes and the figures must be the same.

    .venv/bin/python benchmarks/bench_stats.py             # stage 2048²..8192², whole 2048²
    .venv/bin/python benchmarks/bench_stats.py --quick     # stage 1024², 2048²; no whole runs
    .venv/bin/python benchmarks/bench_stats.py --whole 2048 --runs 5 --before 4d410c0
    .venv/bin/python benchmarks/bench_stats.py --whole 2048 8192 --layouts plain  # issue 19/3

Part 1's "before" module renders with this checkout's ``grid`` and ``walk`` modules (it is
loaded beside them), so only part 2 compares whole versions of the stage's code.

The figures are exact in both versions (no approximation): "same figures" compares
``largest_copy`` and ``unused`` for equality, not within a tolerance.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import scipy

import quilting
from quilting.core import stats

ROOT = Path(__file__).resolve().parents[1]
TEXTURE = ROOT / "tests" / "data" / "gravel.png"
#: The whole runs: a gray and an RGB texture, 256x256 each.
WHOLE_TEXTURES = ("gravel", "hubble")
#: The commit before this stage was rewritten (cell-by-cell ownership, runs).
BEFORE = "7f13b49"
STATS = Path("server") / "quilting" / "core" / "stats.py"
#: The modules of the stats stage's code: copied into the "after" worktree.
STAGE = tuple(
    Path("server") / "quilting" / "core" / name
    for name in ("stats.py", "grid.py", "walk.py", "layout.py")
)
#: The whole runs' layouts: synthesize's options for each.
LAYOUTS: dict[str, dict[str, Any]] = {
    "plain": {},
    "tileable": {"tileable": "both"},
    "walk": {"mode": "walk"},
}

WHOLE_RUN = """
import json, sys
import numpy as np
import quilting
texture = quilting.read_image(sys.argv[1])
size = int(sys.argv[2])
result = quilting.synthesize(texture, (size, size), block=48, seed=1, **json.loads(sys.argv[3]))
# VmHWM, not ru_maxrss: Linux carries ru_maxrss over exec, so a child of a large parent
# would report the parent's peak.
peak = next(int(line.split()[1]) * 1024 for line in open("/proc/self/status")
            if line.startswith("VmHWM"))
print(json.dumps({"peak": peak, "timings": result.timings,
                  "largest_copy": result.stats.largest_copy, "unused": result.stats.unused,
                  "sha": __import__("hashlib").sha256(result.image.tobytes()).hexdigest()}))
"""


def _old_stats(rev: str) -> ModuleType:
    """``quilting.core.stats`` as it was at ``rev``, loaded beside the current one."""
    source = subprocess.run(
        ["git", "-C", str(ROOT), "show", f"{rev}:{STATS.as_posix()}"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    path = Path(tempfile.mkdtemp()) / "stats_before.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location("stats_before", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def _measure(function: Any, layout: quilting.Layout, repeats: int) -> tuple[float, int, Any]:
    """Median seconds, tracemalloc peak bytes, and the value of ``function(layout)``."""
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        value = function(layout)
        times.append(time.perf_counter() - started)
    tracemalloc.start()
    function(layout)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return statistics.median(times), peak, value


def _stage(old: ModuleType, sizes: tuple[int, ...]) -> None:
    texture = quilting.read_image(TEXTURE)
    print("The stage alone (repetition), 256² gravel, block 48:")
    print(
        "| layout | path | before: time | before: peak | after: time | after: peak | "
        "time x | same figures |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---|")
    # Random mode makes a plain layout fast; the stage's cost depends on the output's size.
    # A plain layout's map is rendered and read band by band ("plain"); tileable and walk
    # layouts' whole, cell by cell of the unrolled grid ("cells"; before: pasted group by
    # group).
    cases: list[tuple[str, int, dict[str, Any]]] = [
        (f"{size}² random", size, {"mode": "random"}) for size in sizes
    ]
    cases += [
        (f"{sizes[0]}² random tileable", sizes[0], {"mode": "random", "tileable": "both"}),
        (f"{sizes[0]}² walk", sizes[0], {"mode": "walk"}),
    ]
    for name, size, options in cases:
        layout = quilting.synthesize(texture, (size, size), block=48, seed=1, **options).layout
        last = layout.passes[-1]
        path = (
            "plain"
            if stats._plain_cover(last)
            else "cells"
            if stats._cell_cover(last)
            else "pasted"
        )
        repeats = 3 if size >= 8192 else 5
        t_old, m_old, v_old = _measure(old.repetition, layout, repeats)
        t_new, m_new, v_new = _measure(stats.repetition, layout, repeats)
        print(
            f"| {name} | {path} | {t_old:.3f} s | {m_old / 2**20:.0f} MiB | {t_new:.3f} s | "
            f"{m_new / 2**20:.0f} MiB | {t_old / t_new:.1f} | "
            f"{'yes' if v_old == v_new else f'NO: {v_old} vs {v_new}'} |",
            flush=True,
        )


def _worktrees(rev: str, after: str | None, tmp: Path) -> dict[str, Path]:
    """Worktrees: "before" of ``rev`` as it is; "after" of ``after`` as it is, or (None) of
    ``rev`` with this checkout's stage modules (``STAGE``) copied in."""
    trees = {label: tmp / label for label in ("before", "after")}
    for label, tree in trees.items():
        commit = after if label == "after" and after is not None else rev
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(tree), commit],
            check=True,
        )
    if after is None:
        for module in STAGE:
            shutil.copyfile(ROOT / module, trees["after"] / module)
    return trees


def _whole(
    rev: str, after: str | None, sizes: tuple[int, ...], layouts: tuple[str, ...], runs: int
) -> None:
    print()
    print(
        f"Whole synthesis from 256² textures, block 48, seed 1, fft, one fresh process a run, "
        f"{runs} run(s) each, before and after interleaved; medians, peak = largest VmHWM:"
    )
    print(
        "| output | layout | texture | code | engine time | stats | stats x | stats share | "
        "peak RSS | largest_copy | unused | same image and figures |"
    )
    print("|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---|")
    with tempfile.TemporaryDirectory() as tmp:
        trees = _worktrees(rev, after, Path(tmp))
        try:
            cases = [(s, lay, name) for s in sizes for lay in layouts for name in WHOLE_TEXTURES]
            for size, layout, name in cases:
                texture = ROOT / "tests" / "data" / f"{name}.png"
                options = json.dumps(LAYOUTS[layout])
                found: dict[str, list[dict[str, Any]]] = {"before": [], "after": []}
                for _ in range(runs):
                    for label, tree in trees.items():
                        run = subprocess.run(
                            [sys.executable, "-c", WHOLE_RUN, str(texture), str(size), options],
                            capture_output=True,
                            text=True,
                            env={"PYTHONPATH": str(tree / "server"), "PATH": "/usr/bin:/bin"},
                        )
                        if run.returncode:
                            # Say why: a copied module may need a newer sibling (use --after).
                            raise SystemExit(f"{label} run failed:\n{run.stderr}")
                        found[label].append(json.loads(run.stdout))
                same = {
                    (run["sha"], run["largest_copy"], run["unused"])
                    for results in found.values()
                    for run in results
                }
                spent = {
                    label: statistics.median(r["timings"]["stats"] for r in results)
                    for label, results in found.items()
                }
                for label, results in found.items():
                    total = statistics.median(r["timings"]["total"] for r in results)
                    share = statistics.median(
                        r["timings"]["stats"] / r["timings"]["total"] for r in results
                    )
                    peak = max(r["peak"] for r in results)
                    ratio = f"{spent['before'] / spent['after']:.1f}" if label == "after" else ""
                    print(
                        f"| {size}² | {layout} | {name} | {label} | {total:.2f} s | "
                        f"{spent[label]:.3f} s | {ratio} | {share:.1%} | {peak / 2**20:.0f} MiB | "
                        f"{results[0]['largest_copy']:.6f} | {results[0]['unused']:.6f} | "
                        f"{'yes' if len(same) == 1 else 'NO'} |",
                        flush=True,
                    )
        finally:
            for tree in trees.values():
                subprocess.run(
                    ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)],
                    check=True,
                )


def _cpu() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as info:
            names = [line.split(":", 1)[1].strip() for line in info if line.startswith("model")]
        return next(name for name in names if not name.isdigit())
    except (OSError, StopIteration):
        return platform.processor() or platform.machine()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, no whole runs")
    parser.add_argument("--before", default=BEFORE, help=f"earlier commit (default {BEFORE})")
    parser.add_argument(
        "--after",
        default=None,
        help="a commit for the whole runs' after side as it is (default: --before's with this "
        "checkout's stage modules)",
    )
    parser.add_argument(
        "--whole",
        type=int,
        nargs="*",
        default=[2048],
        help="output sizes of the whole runs (default 2048; none: skip them)",
    )
    parser.add_argument(
        "--layouts",
        nargs="+",
        choices=tuple(LAYOUTS),
        default=list(LAYOUTS),
        help="layouts of the whole runs (default all: plain, tileable both, walk)",
    )
    parser.add_argument("--runs", type=int, default=3, help="whole runs per case (default 3)")
    args = parser.parse_args()
    print(
        f"Machine: {_cpu()}, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at "
        f"the start; Python {platform.python_version()}, numpy {np.__version__}, "
        f"scipy {scipy.__version__}"
    )
    _stage(_old_stats(args.before), (1024, 2048) if args.quick else (2048, 4096, 8192))
    if not args.quick and args.whole:
        _whole(args.before, args.after, tuple(args.whole), tuple(args.layouts), args.runs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
