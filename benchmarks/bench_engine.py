"""Engine time per stage, this checkout against earlier commits, in the same run (issue 21).

Each tree (this checkout, and every ``--against REV``, checked out as a git worktree in the
system's temporary directory, outside the checkout) runs every case in a subprocess of its own, its
``server/`` first on ``sys.path``; the trees take turns case by case and round by round, so
the machine's load falls on all of them alike. A subprocess makes one untimed call (numba's
kernels loaded, caches warm), then ``--repeat`` timed ones, and reports the median of the
engine time (``Result.timings["total"]``) and of every stage. The table gives, per case and
tree, the median over the rounds of those medians, and each tree's engine time over this
checkout's (``x``: above 1 = slower than this checkout).

Cases (``--cases``, comma-separated; default all but the 8192² and quality ones):

* ``512-rgb``, ``1024-rgb``, ``2048-rgb``: from the 256² RGB ``hubble.png``;
* ``512-gray``, ``1024-gray``, ``2048-gray``: from the 256² gray ``gravel.png``;
* ``8192-gray``, ``8192-rgb``: the largest (minutes on 2 cores; only when named);
* ``512-rgba``: from the 192² RGBA ``cloud_rgba.png``, alpha quilting (factored sampling);
* ``quality``: every texture of ``benchmarks/quality_textures.py`` (photos and procedural)
  at 512², block by the quality benchmark's rule (issue 20's time goal: the defaults against
  the cut before issue 20, ``--against febe3ac``);
* ``startup``: a fresh worker's first job (issue 21): in a new process, the seconds of
  ``import quilting``, of ``quilting.warm_up()`` (the kernels from numba's cache, compiled on
  the first run), of the first 256² job from the 256² gray ``gravel.png`` and of a second one;
  its own table, one subprocess per round (``--repeat`` does not apply).

Block 48, defaults otherwise, seed 1, ``backend="fft"``.
::

    .venv/bin/python benchmarks/bench_engine.py --against 8e0650f
    .venv/bin/python benchmarks/bench_engine.py --against febe3ac --cases quality --repeat 3
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import benchtools

ROOT = Path(__file__).resolve().parents[1]
#: Outside the checkout, so that nothing scanning it (tests, linters) meets the old trees.
WORKTREES = Path(tempfile.gettempdir()) / "quilting-bench-worktrees"
DATA = ROOT / "tests" / "data"
#: ``blend``: the seam blend's own seconds, which ``paste`` held before the blend ran beside
#: the next level (a tree without the stage reports 0 and its blend under ``paste``); on the
#: blend's thread they overlap the other stages, so the stages may add up to more than the total.
STAGES = ("costs", "select", "seams", "paste", "blend", "render", "stats")
STARTUP = ("import", "warm_up", "first job", "second job")
SIZES = {
    "512-rgb": ("hubble.png", 512),
    "1024-rgb": ("hubble.png", 1024),
    "2048-rgb": ("hubble.png", 2048),
    "512-gray": ("gravel.png", 512),
    "1024-gray": ("gravel.png", 1024),
    "2048-gray": ("gravel.png", 2048),
    "8192-gray": ("gravel.png", 8192),
    "8192-rgb": ("hubble.png", 8192),
    "512-rgba": ("cloud_rgba.png", 512),
    "512-rgb-tileable": ("hubble.png", 512),
    "2048-rgb-tileable": ("hubble.png", 2048),
}
#: The options of the cases beyond the defaults (block 48, seed 1, ``fft``).
CASE_OPTIONS: dict[str, dict[str, Any]] = {
    "512-rgb-tileable": {"tileable": "both"},
    "2048-rgb-tileable": {"tileable": "both"},
}
DEFAULT_CASES = "512-rgb,1024-rgb,2048-rgb,512-gray,1024-gray,2048-gray,512-rgba"


def quality_textures() -> dict[str, Any]:
    """The quality benchmark's textures (name -> array) and its block rule."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import numpy as np
    import quality_textures as qt
    from PIL import Image

    found: dict[str, Any] = {}
    for name, path in qt.photos().items():
        found[name] = np.asarray(Image.open(path))
    for name in qt.procedural_names():
        found[name] = qt.procedural(name)
    return found


def run_startup() -> dict[str, dict[str, float]]:
    """In a fresh subprocess: the seconds of each step of a worker's start (:data:`STARTUP`)."""
    import time

    started = time.perf_counter()
    import quilting

    imported = time.perf_counter()
    # Trees from before the kernels have no warm_up: their first job pays what it loads.
    warm_up = getattr(quilting, "warm_up", None)
    if warm_up is not None:
        warm_up()
    warm = time.perf_counter()
    texture = quilting.read_image(DATA / "gravel.png")
    times = []
    for _ in range(2):
        tick = time.perf_counter()
        quilting.synthesize(texture, (256, 256), block=48, seed=1, backend="fft")
        times.append(time.perf_counter() - tick)
    steps = (imported - started, warm - imported, *times)
    return {"startup": dict(zip(STARTUP, steps, strict=True))}


def run_one(case: str, repeat: int) -> dict[str, dict[str, float]]:
    """In the subprocess: time ``case`` with the ``quilting`` on sys.path."""
    if case == "startup":
        return run_startup()
    import numpy as np
    from PIL import Image

    import quilting

    jobs: list[tuple[str, Any, int, int]] = []
    if case == "quality":
        for name, texture in quality_textures().items():
            side = min(np.shape(texture)[:2])
            jobs.append((name, texture, 512, max(16, min(48, side // 3))))
    else:
        file, size = SIZES[case]
        jobs.append((case, np.asarray(Image.open(DATA / file)), size, 48))
    options = CASE_OPTIONS.get(case, {})
    out: dict[str, dict[str, float]] = {}
    for name, texture, size, block in jobs:

        def call(texture: Any = texture, size: int = size, block: int = block) -> dict[str, float]:
            result = quilting.synthesize(
                texture, (size, size), block=block, seed=1, backend="fft", **options
            )
            return dict(result.timings)

        call()  # kernels loaded, caches warm
        runs = [call() for _ in range(repeat)]
        out[name] = {
            key: statistics.median(run.get(key, 0.0) for run in runs) for key in ("total", *STAGES)
        }
    return out


def tree_of(rev: str) -> Path:
    """A worktree of ``rev`` (made once, kept in :data:`WORKTREES`)."""
    commit = subprocess.run(
        ["git", "rev-parse", "--short", rev], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.strip()
    path = WORKTREES / commit
    if not path.exists():
        WORKTREES.mkdir(parents=True, exist_ok=True)
        subprocess.run(
            ["git", "worktree", "add", "--detach", str(path), commit],
            cwd=ROOT, check=True, capture_output=True,
        )  # fmt: skip
    return path


def measure(tree: Path, case: str, repeat: int) -> dict[str, dict[str, float]] | None:
    """The figures of ``case`` in ``tree``, or None (with the error printed) if it failed
    there: an old tree may lack what a case asks for, and the other trees' figures stay."""
    env = {**os.environ, "PYTHONPATH": str(tree / "server")}
    done = subprocess.run(
        [sys.executable, __file__, "--one", case, "--repeat", str(repeat)],
        env=env, capture_output=True, text=True, cwd=tree,
    )  # fmt: skip
    if done.returncode != 0:
        print(f"{tree}: {case} failed:\n{done.stderr[-3000:]}", flush=True)
        if tree == ROOT:
            raise SystemExit(1)
        return None
    result: dict[str, dict[str, float]] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--against", action="append", default=[], metavar="REV")
    parser.add_argument("--cases", default=DEFAULT_CASES)
    parser.add_argument("--repeat", type=int, default=3, help="timed calls per subprocess")
    parser.add_argument("--rounds", type=int, default=3, help="subprocesses per case and tree")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--one", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(run_one(args.one, args.repeat)))
        return

    import numpy
    import scipy

    trees = {"this checkout": ROOT, **{rev: tree_of(rev) for rev in args.against}}
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    unknown = [c for c in cases if c not in ("quality", "startup") and c not in SIZES]
    if unknown:
        parser.error(f"unknown cases {unknown}; known: {sorted(SIZES)}, quality and startup")
    print("machine:", benchtools.machine(numpy=numpy.__version__, scipy=scipy.__version__))
    print("this checkout:", benchtools.source_tree(ROOT))
    # figures[case][tree][job] = list of per-round stage medians
    figures: dict[str, dict[str, dict[str, list[dict[str, float]]]]] = {}
    for case in cases:
        per_tree = figures.setdefault(case, {name: {} for name in trees})
        for _ in range(args.rounds):
            for name, tree in trees.items():
                for job, stages in (measure(tree, case, args.repeat) or {}).items():
                    per_tree[name].setdefault(job, []).append(stages)
        print(f"  {case} done", flush=True)

    headers = ["case", "tree", "engine s", "x", *[f"{s} s" for s in STAGES]]
    rows = []
    summary: dict[str, object] = {}
    startup = figures.pop("startup", None)
    for case, per_tree in figures.items():
        medians = {
            name: {
                job: {k: statistics.median(r[k] for r in rounds) for k in rounds[0]}
                for job, rounds in jobs.items()
            }
            for name, jobs in per_tree.items()
            if jobs
        }
        base = medians["this checkout"]
        for name, jobs in medians.items():
            # A case of many textures: the median over textures of each figure, and of the
            # per-texture time ratio.
            ratio = statistics.median(jobs[j]["total"] / base[j]["total"] for j in jobs)
            cell = {k: statistics.median(jobs[j][k] for j in jobs) for k in ("total", *STAGES)}
            rows.append(
                [case, name, f"{cell['total']:.3f}", f"{ratio:.2f}"]
                + [f"{cell[s]:.3f}" for s in STAGES]
            )
            summary.setdefault(case, {})[name] = {"median": cell, "x": ratio, "jobs": jobs}  # type: ignore[index]
    if rows:
        print()
        print(benchtools.markdown(headers, rows, left=2))
    if startup is not None:
        print()
        print(f"a fresh process, medians over {args.rounds} rounds (seconds):\n")
        lines = []
        for name, started in startup.items():
            if not started:
                continue
            steps = {k: statistics.median(r[k] for r in started["startup"]) for k in STARTUP}
            lines.append([name, *(f"{steps[k]:.3f}" for k in STARTUP)])
            summary.setdefault("startup", {})[name] = steps  # type: ignore[index]
        print(benchtools.markdown(["tree", *STARTUP], lines))
    print("\nload average at the end:", [round(x, 2) for x in os.getloadavg()])
    if args.json:
        args.json.write_text(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
