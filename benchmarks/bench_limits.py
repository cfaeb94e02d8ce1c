"""Benchmark of the cost model: predicted against measured peak memory and time.

Each case runs in a fresh process (its peak resident memory, VmHWM, is then the job's own)
through the public API, with the batch the cost model picks, and prints beside what it
measured what :mod:`quilting.core.budget` predicted before the job started: textures 64²…2048²
into outputs 512²…8192², gray and RGB, a noise texture (every candidate a near tie, the
shortlists' worst case), transfers, alpha quilting, a matte and ``/tile`` calls (decode, make
tileable, encode: :func:`quilting.core.budget.estimate_tile`) up to 5000². A budget case
checks that a job the model refuses is refused before any work, and that a job run under a
budget stays in it.

    .venv/bin/python benchmarks/bench_limits.py            # every case (about 10 minutes)
    .venv/bin/python benchmarks/bench_limits.py --quick    # the small cases
    .venv/bin/python benchmarks/bench_limits.py --fit      # and refit the time coefficients

Times are the job's CPU seconds (what the model predicts: a worker with a core to itself);
the wall time on a shared 2-core machine is noisy and is shown beside them. Memory is not noisy.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from benchtools import machine, markdown

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, sys, time
import numpy as np
from PIL import Image
import quilting
from quilting.core import budget as model

case = json.loads(sys.argv[1])
root = case["root"]

def texture(name, side, channels):
    mode = {1: "L", 3: "RGB", 4: "RGBA"}[channels]
    image = Image.open(f"{root}/{name}").convert(mode)
    if side:
        image = image.resize((side, side), Image.BICUBIC)
    array = np.asarray(image)
    if case.get("noise"):
        array = np.random.default_rng(0).integers(0, 256, array.shape, dtype=np.uint8)
    return array

def hwm():
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM"):
            return int(line.split()[1]) * 1024

op = case["op"]
limit = case.get("budget")
budget = None if limit is None else quilting.Budget(memory_bytes=limit)
import resource
usage = resource.getrusage(resource.RUSAGE_SELF)
case["cpu_before"] = usage.ru_utime + usage.ru_stime
started = time.perf_counter()
options = dict(block=case["block"], seed=1, backend="fft", budget=budget)
tex = None if op == "tile" else texture(case["texture"], case["side"], case["channels"])
try:
    if op == "tile":
        # What a /tile sandbox call does: decode, make tileable, encode.
        from quilting.core.options import TileOptions
        from quilting.io import image_header
        from quilting.service.jobs import PixelLimits
        from quilting.service.sandbox_process import tile_png
        data = open(case["png"], "rb").read()
        header = image_header(data, max_pixels=1 << 40)
        planned = model.estimate_tile(
            (header.height, header.width, header.channels), itemsize=header.bit_depth // 8,
            budget=budget, extra_bytes=len(data))
        passes = None
        tile_png(data, TileOptions(), PixelLimits(1 << 40, 1 << 40, 1 << 20))
        result = None
    elif op == "synthesize":
        opts = quilting.SynthesisOptions(block=case["block"])
        planned = model.estimate_synthesis(
            opts, tex.shape[:2] + (tex.shape[2] if tex.ndim == 3 else 1,),
            (case["out"], case["out"]), backend="fft", itemsize=tex.dtype.itemsize,
            budget=budget)
        passes = model.synthesis_passes(
            tex.shape[:2] + (tex.shape[2] if tex.ndim == 3 else 1,),
            (case["out"], case["out"]), opts, "fft")
        result = quilting.synthesize(tex, (case["out"], case["out"]), **options)
    elif op == "transfer":
        target = texture(case["target"], case["out"], case["channels"])
        opts = quilting.TransferOptions(block=case["block"], iterations=case["iterations"])
        planned = model.estimate_transfer(
            opts, tex.shape[:2] + (tex.shape[2] if tex.ndim == 3 else 1,), target.shape[:2],
            backend="fft", itemsize=tex.dtype.itemsize, budget=budget)
        passes = model.transfer_passes(
            tex.shape[:2] + (tex.shape[2] if tex.ndim == 3 else 1,), target.shape[:2], opts,
            "fft", 1)
        result = quilting.transfer(tex, target, iterations=case["iterations"], **options)
    else:
        target = np.asarray(Image.open(f"{root}/examples/matte_target.png"))
        silhouette = np.asarray(Image.open(f"{root}/examples/matte_silhouette.png"))
        from quilting.core.matte import estimate_matte, matte_inputs
        opts = quilting.MatteOptions(block=case["block"], seed=1)
        inputs = matte_inputs(opts, target, [tex], silhouette, None)
        planned = estimate_matte(
            opts, target.shape[:2], [(v.shape, v.dtype.itemsize) for v, _ in inputs.layers],
            inputs.layer_size, budget=budget)
        passes = None
        result = quilting.matte(target, [tex], silhouette=silhouette, **options)
except quilting.JobTooLargeError as exc:
    print(json.dumps({"refused": exc.message, "seconds": time.perf_counter() - started,
                      "peak": hwm()}))
    sys.exit(0)
seconds = time.perf_counter() - started
target_size = (case["out"], case["out"]) if op == "synthesize" else (
    (0, 0) if op == "tile" else (target.shape[0], target.shape[1]))
import resource
usage = resource.getrusage(resource.RUSAGE_SELF)
cpu = usage.ru_utime + usage.ru_stime - case["cpu_before"]
timings = {} if result is None else (
    result.timings if op != "matte" else result.layers[0].timings)
print(json.dumps({
    "peak": hwm(), "seconds": seconds, "cpu": cpu, "timings": timings,
    "predicted_peak": None if planned is None else planned.peak_bytes,
    "bound": None if planned is None else planned.bound_bytes,
    "predicted_seconds": None if planned is None else planned.seconds,
    "batch": None if planned is None else planned.batch,
    "features": None if passes is None else model.time_features(passes, target_size),
}))
"""

#: (label, case) pairs. ``side`` 0 keeps the file's size.
CASES: list[tuple[str, dict[str, Any]]] = [
    ("64² RGB → 512²", {"side": 64, "out": 512, "block": 24}),
    ("128² RGB → 1024²", {"side": 128, "out": 1024, "block": 32}),
    ("256² RGB → 512²", {"side": 256, "out": 512}),
    ("256² RGB → 2048²", {"side": 256, "out": 2048}),
    ("256² gray → 2048²", {"side": 256, "out": 2048, "channels": 1}),
    ("512² RGB → 1024²", {"side": 512, "out": 1024}),
    ("1024² RGB → 1024²", {"side": 1024, "out": 1024}),
    ("2048² RGB → 512²", {"side": 2048, "out": 512, "block": 96}),
    ("noise 512² RGB → 512²", {"side": 512, "out": 512, "noise": True}),
    ("256² RGB → 4096²", {"side": 256, "out": 4096}),
    ("256² RGB → 8192²", {"side": 256, "out": 8192}),
    ("256² gray → 8192²", {"side": 256, "out": 8192, "channels": 1}),
    (
        "transfer 256² → 512², 1 pass",
        {"op": "transfer", "side": 256, "out": 512, "block": 24, "iterations": 1},
    ),
    (
        "transfer 256² → 1024², 3 passes",
        {"op": "transfer", "side": 256, "out": 1024, "block": 24, "iterations": 3},
    ),
    (
        "alpha 256² RGBA → 1024²",
        {"texture": "tests/data/cloud_rgba.png", "side": 256, "out": 1024, "channels": 4},
    ),
    ("matte, one 256² layer", {"op": "matte", "side": 256, "texture": "examples/brick.png"}),
    ("/tile 2000² gray", {"op": "tile", "side": 2000, "channels": 1}),
    ("/tile 2000² RGB", {"op": "tile", "side": 2000}),
    ("/tile 2000² RGBA 16-bit", {"op": "tile", "side": 2000, "channels": 4, "depth": 16}),
    ("/tile 4000² RGB", {"op": "tile", "side": 4000}),
    ("/tile 5000² RGB", {"op": "tile", "side": 5000}),
    ("/tile 5000² RGBA 16-bit", {"op": "tile", "side": 5000, "channels": 4, "depth": 16}),
    ("budget 1 GiB: 1024² RGB → 1024²", {"side": 1024, "out": 1024, "budget": 1 << 30}),
    ("budget 1 GiB: 4096² RGB → 1024²", {"side": 4096, "out": 1024, "budget": 1 << 30}),
]
QUICK = {
    "64² RGB → 512²",
    "256² RGB → 512²",
    "256² RGB → 2048²",
    "512² RGB → 1024²",
    "transfer 256² → 512², 1 pass",
    "budget 1 GiB: 4096² RGB → 1024²",
    "/tile 2000² RGB",
}


def tile_png(side: int, channels: int, depth: int) -> Path:
    """A photograph (hubble) resized to ``side``², as the PNG a /tile case uploads."""
    from PIL import Image

    from quilting.io import encode_png

    path = Path(tempfile.gettempdir()) / f"bench_limits_tile_{side}_{channels}_{depth}.png"
    if not path.exists():
        mode = {1: "L", 3: "RGB", 4: "RGBA"}[channels]
        image = Image.open(ROOT / "tests" / "data" / "hubble.png").convert(mode)
        array = np.asarray(image.resize((side, side), Image.Resampling.BICUBIC))
        if depth == 16:
            array = array.astype(np.uint16) * 257
        path.write_bytes(encode_png(array))
    return path


def run_case(case: dict[str, Any]) -> dict[str, Any]:
    full = {
        "op": "synthesize",
        "texture": "tests/data/gravel.png",
        "target": "tests/data/target_camera.png",
        "channels": 3,
        "block": 48,
        "root": str(ROOT),
        **case,
    }
    if full["op"] == "tile":
        full["png"] = str(tile_png(full["side"], full["channels"], full.get("depth", 8)))
    done = subprocess.run(
        [sys.executable, "-c", CHILD, json.dumps(full)],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    if done.returncode:
        raise SystemExit(f"case {case} failed:\n{done.stderr}")
    answer: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    return answer


def print_fit(fitted: list[tuple[dict[str, float], float]]) -> None:
    """Least-squares (non-negative) SECONDS_PER coefficients for the measured CPU seconds,
    weighted so that every case counts by its relative error."""
    from scipy.optimize import nnls

    keys = [k for k in fitted[0][0] if any(f[k] for f, _ in fitted)]
    design = np.array([[f[k] / cpu for k in keys] for f, cpu in fitted])
    solution, _ = nnls(design, np.ones(len(fitted)))
    print("\nfitted SECONDS_PER (CPU seconds):")
    for key, value in zip(keys, solution, strict=True):
        print(f"    {key!r}: {value:.3g},")
    predicted = design @ solution
    print("fitted CPU / predicted:", " ".join(f"{1 / p:.2f}" for p in predicted))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="the small cases only")
    parser.add_argument("--repeat", type=int, default=1, help="runs per case (median time)")
    parser.add_argument("--only", metavar="TEXT", help="the cases whose label holds TEXT")
    parser.add_argument("--fit", action="store_true", help="refit SECONDS_PER to the CPU times")
    parser.add_argument("--json", metavar="PATH", help="also write every run's figures here")
    args = parser.parse_args()
    saved: dict[str, list[dict[str, Any]]] = {}
    rows = []
    worst_memory = 0.0
    worst_time = 0.0
    fitted: list[tuple[dict[str, float], float]] = []
    for label, case in CASES:
        if (args.quick and label not in QUICK) or (args.only and args.only not in label):
            continue
        runs = [run_case(case) for _ in range(max(1, args.repeat))]
        saved[label] = runs
        if args.json:
            Path(args.json).write_text(json.dumps(saved, indent=1))
        first = runs[0]
        if "refused" in first:
            rows.append(
                [label, "-", "refused", "-", "-", "-", "-", f"{first['seconds']:.2f}", "-", "-"]
            )
            print(f"  {label}: refused in {first['seconds']:.2f} s: {first['refused']}")
            continue
        peak = statistics.median(r["peak"] for r in runs)
        seconds = statistics.median(r["seconds"] for r in runs)
        predicted = first["predicted_peak"]
        if predicted is None:
            rows.append(
                [label, "-", "-", "-", f"{peak / 2**20:.0f}", "-", "-", f"{seconds:.1f}", "-", "-"]
            )
            continue
        cpu = statistics.median(r["cpu"] for r in runs)
        if first.get("features") and not case.get("noise"):
            fitted.append((first["features"], cpu))
        memory_ratio = peak / predicted
        time_ratio = cpu / first["predicted_seconds"]
        worst_memory = max(worst_memory, abs(memory_ratio - 1))
        worst_time = max(worst_time, abs(np.log(time_ratio)))
        rows.append(
            [
                label,
                str(first["batch"]),
                f"{predicted / 2**20:.0f}",
                f"{first['bound'] / 2**20:.0f}",
                f"{peak / 2**20:.0f}",
                f"{memory_ratio:.2f}",
                f"{first['predicted_seconds']:.1f}",
                f"{seconds:.1f}",
                f"{cpu:.1f}",
                f"{time_ratio:.2f}",
            ]
        )
        if peak > first["bound"]:
            print(f"  {label}: OVER THE BOUND: {peak / 2**20:.0f} MiB")
        if case.get("budget") and peak > case["budget"]:
            print(f"  {label}: OVER BUDGET: {peak / 2**20:.0f} MiB")
    headers = [
        "case",
        "batch",
        "predicted MiB",
        "bound MiB",
        "measured MiB",
        "measured / predicted",
        "predicted s",
        "wall s",
        "CPU s",
        "CPU / predicted",
    ]
    print(markdown(headers, rows))
    print(
        f"\nworst memory deviation {worst_memory:.0%}; worst time ratio x{np.exp(worst_time):.2f}"
    )
    if args.fit and fitted:
        print_fit(fitted)
    print("machine:", json.dumps(machine(numpy=np.__version__)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
