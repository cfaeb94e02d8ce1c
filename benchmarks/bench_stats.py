"""Benchmark of the statistics stage (``result.stats``): memory and time, before and after.

Compares, in one run, the repetition measure (largest verbatim copy, unused share) of this
checkout against the same function of an earlier commit (default: the last commit before the
banded computation), on the same layouts, and checks that both give the same figures. Then
runs whole 8192x8192 syntheses from 256x256 gray and RGB textures in a fresh process for each
version (a git worktree of the earlier commit) and reports their peak RSS and the stats
stage's share of the engine time.

    .venv/bin/python benchmarks/bench_stats.py            # full: 2048², 4096², 8192²
    .venv/bin/python benchmarks/bench_stats.py --quick    # 1024² and 2048², no whole runs

Memory of the stage is measured with tracemalloc (numpy reports its buffers to it), so the
figure is the stage's own peak above what was allocated before it, free of the noise of a
shared machine; times are medians of repeated runs.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path
from types import ModuleType
from typing import Any

import quilting
from quilting.core import stats

ROOT = Path(__file__).resolve().parents[1]
TEXTURE = ROOT / "tests" / "data" / "gravel.png"
#: The whole runs: a gray and an RGB texture, 256x256 each.
WHOLE_TEXTURES = ("gravel", "hubble")
#: The commit whose stats.py computed the whole output at once.
BEFORE = "95209b1"

WHOLE_RUN = """
import json, sys
import numpy as np
import quilting
texture = quilting.read_image(sys.argv[1])
size = int(sys.argv[2])
result = quilting.synthesize(texture, (size, size), block=48, seed=1)
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
        ["git", "-C", str(ROOT), "show", f"{rev}:server/quilting/core/stats.py"],
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


def _whole_runs(rev: str, size: int) -> list[tuple[str, str, dict[str, Any]]]:
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "before"
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(tree), rev],
            check=True,
        )
        try:
            for name in WHOLE_TEXTURES:
                texture = ROOT / "tests" / "data" / f"{name}.png"
                for label, server in (("before", tree / "server"), ("after", ROOT / "server")):
                    out = subprocess.run(
                        [sys.executable, "-c", WHOLE_RUN, str(texture), str(size)],
                        check=True,
                        capture_output=True,
                        text=True,
                        env={"PYTHONPATH": str(server), "PATH": "/usr/bin:/bin"},
                    ).stdout
                    runs.append((name, label, json.loads(out)))
        finally:
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=True
            )
    return runs


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, no whole runs")
    parser.add_argument("--before", default=BEFORE, help=f"earlier commit (default {BEFORE})")
    args = parser.parse_args()
    old = _old_stats(args.before)
    texture = quilting.read_image(TEXTURE)
    sizes = (1024, 2048) if args.quick else (2048, 4096, 8192)
    print("| output | before: time | before: peak | after: time | after: peak | time x | "
          "memory x | same figures |")
    print("|---|---:|---:|---:|---:|---:|---:|---|")
    for size in sizes:
        # Random mode makes a layout fast; the stage's cost depends on the output's size.
        layout = quilting.synthesize(texture, (size, size), block=48, seed=1, mode="random").layout
        repeats = 3 if size >= 8192 else 5
        t_old, m_old, v_old = _measure(old.repetition, layout, repeats)
        t_new, m_new, v_new = _measure(stats.repetition, layout, repeats)
        print(
            f"| {size}² | {t_old:.2f} s | {m_old / 2**20:.0f} MiB | {t_new:.2f} s | "
            f"{m_new / 2**20:.0f} MiB | {t_old / t_new:.2f} | {m_old / m_new:.1f} | "
            f"{'yes' if v_old == v_new else f'NO: {v_old} vs {v_new}'} |"
        )
    if args.quick:
        return 0
    print()
    print("Whole synthesis, 8192² from a 256² texture, block 48, fft, one fresh process each")
    print("(peak RSS: the child's VmHWM):")
    print("| texture | code | peak RSS | engine time | stats | stats share | same image |")
    print("|---|---|---:|---:|---:|---:|---|")
    runs = _whole_runs(args.before, 8192)
    for name, label, run in runs:
        shas = {other["sha"] for texture, _, other in runs if texture == name}
        total, spent = run["timings"]["total"], run["timings"]["stats"]
        print(
            f"| {name} | {label} | {run['peak'] / 2**30:.2f} GiB | {total:.1f} s | "
            f"{spent:.2f} s | {spent / total:.1%} | {'yes' if len(shas) == 1 else 'NO'} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
