"""Speed of ``quilting.synthesize`` against two peers in the same run: a plain numpy quilter
and bmquilting.

The peers:

* ``numpy (plain)``: :func:`plain_quilt` below, the baseline: Efros & Freeman's image quilting
  the straightforward way, in numpy and scipy (per block, per channel float64
  ``scipy.signal.fftconvolve``; a plain dynamic programme for the cut; one thread).
* ``bmquilting``: github.com/bmad4ever/bmquilting (OpenCV ``matchTemplate`` search, A* seams,
  adaptive seam blur), called as
  ``bmquilting.square.generate_texture([texture], SquarePatchingConfig.with_seams(
  block_size=48, overlap=8, tolerance=0.1, blend=True), out_h, out_w, seed=1)``: its
  sequential generator (not ``generate_texture_parallel``, which forks 4+ processes) with its
  default config for seams, adaptive seam blur on. It takes the uint8 texture as it is (it
  converts to float32 in [0, 1] and back itself). Its tolerance is the paper's rule, like
  :func:`plain_quilt`'s: candidates within ``(1 + 0.1) x`` the best, one drawn uniformly.

quilting runs as ``quilting.synthesize(texture, (n, n), block=48, seed=1, backend="fft")``
(overlap by default ``48 // 6 = 8``; tolerance 0.1, floor of 3 candidates), once with its
default ``blend="poisson"`` (the reference of every ratio) and once with ``blend="none"``.

Preparing bmquilting (outside the checkout, never copied into it; it needs Python 3.12 for
its PEP 695 ``type X = Y`` aliases, so the copy gets them rewritten to ``X = Y`` for 3.11)::

    # MIRROR: a git mirror of github.com/bmad4ever/bmquilting (here f779c60)
    mkdir -p /tmp/peers/bmquilting
    git --git-dir=MIRROR archive HEAD | tar -x -C /tmp/peers/bmquilting
    git --git-dir=MIRROR rev-parse --short HEAD > /tmp/peers/bmquilting/COMMIT
    python3.11 - <<'EOF'
    import pathlib, re
    for p in pathlib.Path("/tmp/peers/bmquilting/src/bmquilting").rglob("*.py"):
        p.write_text(re.sub(r"(?m)^(\\s*)type ([A-Za-z_]\\w*) = ", r"\\1\\2 = ", p.read_text()))
    EOF
    python3.11 -m venv /tmp/peers/venv
    /tmp/peers/venv/bin/pip install "numpy<2.4" joblib opencv-python-headless pyastar2d \\
        scikit-learn "numba>=0.62.1" pillow

(its pyproject's dependencies, OpenCV headless, its optional ``fast`` extra numba, and
Pillow to read and write PNGs as the other tools do; bmquilting itself is put on
``sys.path`` from ``--bm-path``/src). Without it, or without ``--bm-python``, the peer is
skipped with a word saying so.

Measures, from ``tests/data/hubble.png`` (256x256 RGB) into n x n outputs (``--sizes``),
block 48, overlap 8, seed 1:

* in-call: each row's tool lives in one persistent subprocess (quilting and the numpy
  quilter in this interpreter, bmquilting in ``--bm-python``) for the whole run. quilting
  first calls ``quilting.warm_up()`` and makes one small untimed synthesis. At each size every
  process makes one untimed call, then ``--repeat`` timed calls, the processes taking turns
  call by call (round by round), so that the machine's load falls on all alike; the time is
  around the synthesizing call alone, the texture already in memory.
* whole process: the wall time of a fresh process (this script with ``--process``) that
  imports the tool, reads the PNG, synthesizes, writes a PNG; ``--repeat`` of them per row and
  size, taking turns the same way.

Nothing runs in parallel. Columns: ``size`` the output side; ``tool`` the row; ``median s``
the median of the timed runs in seconds; ``range s`` their fastest and slowest; ``x quilting``
the row's median over quilting's default row (``blend="poisson"``) at that size: above 1 =
slower than quilting. Threads: quilting's FFT backend uses ``min(2, cores)``, OpenCV its
default (all cores), the numpy quilter one.

Run from the repository root::

    .venv/bin/python benchmarks/bench_peers.py
    .venv/bin/python benchmarks/bench_peers.py --sizes 512 --repeat 5 --peers numpy
    .venv/bin/python benchmarks/bench_peers.py --keep /tmp/peers/out   # keep the PNGs
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import importlib.util
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, Literal

import benchtools
import numpy as np
from numpy.typing import NDArray

ROOT = Path(__file__).resolve().parents[1]
TEXTURE = ROOT / "tests" / "data" / "hubble.png"
BLOCK = 48
OVERLAP = 8
TOLERANCE = 0.1
SEED = 1
#: Starts every line a worker answers with: the peers may print to stdout too.
REPLY = "@@bench_peers "
#: The rows, in the tables' order.
KINDS = ("quilting", "quilting-none", "numpy", "bmquilting")
LABELS = {
    "quilting": "quilting",
    "quilting-none": "quilting blend=none",
    "numpy": "numpy (plain)",
    "bmquilting": "bmquilting",
}

Pixels = NDArray[np.uint8]
Synthesizer = Callable[[int], Pixels]  # output side -> an RGB uint8 image of that size


# --- the baseline --------------------------------------------------------------------------


def vertical_cut(error: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Where the new block wins in a vertical overlap strip (``rows x overlap``): right of
    (and on) the minimum-error path from the top row to the bottom one, by dynamic
    programming (each step to one of the three neighbours below)."""
    rows, width = error.shape
    total = error.copy()
    pad = np.full(1, np.inf)
    for r in range(1, rows):
        above = total[r - 1]
        best = np.minimum(above, np.concatenate([pad, above[:-1]]))
        total[r] += np.minimum(best, np.concatenate([above[1:], pad]))
    path = np.empty(rows, dtype=np.intp)
    path[-1] = int(np.argmin(total[-1]))
    for r in range(rows - 2, -1, -1):
        low = max(int(path[r + 1]) - 1, 0)
        path[r] = low + int(np.argmin(total[r, low : int(path[r + 1]) + 2]))
    new: NDArray[np.bool_] = np.arange(width)[None, :] >= path[:, None]
    return new


def plain_quilt(
    texture: NDArray[np.uint8],
    size: tuple[int, int],
    block: int = BLOCK,
    overlap: int = OVERLAP,
    tolerance: float = TOLERANCE,
    seed: int = SEED,
) -> Pixels:
    """The baseline: Efros & Freeman's image quilting written the straightforward way.

    Blocks in raster order. For each, the overlap SSD at every candidate position of the
    texture, ``sum M S^2 - 2 (M T) corr S + sum M T^2`` with M the left, top or L-shaped
    overlap mask and T the output under the block, by float64 ``scipy.signal.fftconvolve``
    per channel (``sum M S^2`` depends only on the mask: computed once for each of the 3);
    the candidates within ``(1 + tolerance) x`` the best, one drawn uniformly; the minimum
    error boundary cut of the overlap error by :func:`vertical_cut` (the top strip
    transposed; for an L the new block wins where it wins both cuts, which cross in the
    corner square); the block pasted where it wins. The first block is drawn uniformly.
    """
    from scipy.signal import fftconvolve

    source = texture.astype(np.float64).reshape(texture.shape[0], texture.shape[1], -1)
    squares = (source**2).sum(axis=2)
    rng = np.random.default_rng(seed)
    step = block - overlap
    rows = max(1, math.ceil((size[0] - overlap) / step))
    cols = max(1, math.ceil((size[1] - overlap) / step))
    out = np.zeros((rows * step + overlap, cols * step + overlap, source.shape[2]))
    fields = (source.shape[0] - block + 1, source.shape[1] - block + 1)
    energies: dict[tuple[bool, bool], NDArray[np.float64]] = {}
    for row in range(rows):
        for col in range(cols):
            left, top = col > 0, row > 0
            target = out[row * step : row * step + block, col * step : col * step + block]
            if not (left or top):
                y, x = int(rng.integers(fields[0])), int(rng.integers(fields[1]))
                target[:] = source[y : y + block, x : x + block]
                continue
            mask = np.zeros((block, block))
            if left:
                mask[:, :overlap] = 1.0
            if top:
                mask[:overlap, :] = 1.0
            if (left, top) not in energies:
                energies[left, top] = fftconvolve(squares, mask[::-1, ::-1], mode="valid")
            masked = target * mask[:, :, None]
            cross = fftconvolve(source, masked[::-1, ::-1], mode="valid", axes=(0, 1))
            cost = energies[left, top] - 2.0 * cross.sum(axis=2) + float((masked * target).sum())
            # FFT round-off leaves tiny negatives where the match is exact.
            np.maximum(cost, 0.0, out=cost)
            ys, xs = np.nonzero(cost <= (1.0 + tolerance) * cost.min())
            pick = int(rng.integers(ys.size))
            y, x = int(ys[pick]), int(xs[pick])
            patch = source[y : y + block, x : x + block]
            error = ((target - patch) ** 2).sum(axis=2)
            new = np.ones((block, block), dtype=bool)
            if left:
                new[:, :overlap] &= vertical_cut(error[:, :overlap])
            if top:
                new[:overlap, :] &= vertical_cut(error[:overlap, :].T).T
            target[new] = patch[new]
    return out[: size[0], : size[1]].astype(np.uint8)


# --- the tools, inside a worker or a fresh process -----------------------------------------


def read_png(path: Path) -> Pixels:
    from PIL import Image

    with Image.open(path) as image:
        pixels: Pixels = np.asarray(image.convert("RGB"))
    return pixels


def write_png(pixels: Pixels, path: Path) -> None:
    from PIL import Image

    Image.fromarray(pixels).save(path)


def make_tool(kind: str, bm_path: Path, texture: Pixels) -> tuple[Synthesizer, dict[str, str]]:
    """Import ``kind``'s tool; its synthesizer and the versions of what it runs on."""
    if kind in ("quilting", "quilting-none"):
        import scipy

        import quilting

        blend: Literal["poisson", "none"] = "poisson" if kind == "quilting" else "none"

        def by_quilting(side: int) -> Pixels:
            result = quilting.synthesize(
                texture, (side, side), block=BLOCK, seed=SEED, backend="fft", blend=blend
            )
            return np.asarray(result.image, dtype=np.uint8)

        versions = {"numpy": np.__version__, "scipy": scipy.__version__}
        return by_quilting, {**versions, "numba": importlib.import_module("numba").__version__}
    if kind == "numpy":
        import scipy

        def by_numpy(side: int) -> Pixels:
            return plain_quilt(texture, (side, side))

        return by_numpy, {"numpy": np.__version__, "scipy": scipy.__version__}
    if kind == "bmquilting":
        sys.path.insert(0, str(bm_path / "src"))
        # Imported by name: it lives outside both the checkout and the project's venv.
        square = importlib.import_module("bmquilting.square")
        cv2 = importlib.import_module("cv2")
        config = square.SquarePatchingConfig.with_seams(
            block_size=BLOCK, overlap=OVERLAP, tolerance=TOLERANCE, blend=True
        )

        def by_bmquilting(side: int) -> Pixels:
            image, _seams = square.generate_texture([texture], config, side, side, SEED)
            return np.asarray(image, dtype=np.uint8)

        commit = bm_path / "COMMIT"
        versions = {
            "bmquilting": commit.read_text().strip() if commit.exists() else "unknown commit",
            "numpy": np.__version__,
            "opencv": str(cv2.__version__),
            "python": sys.version.split()[0],
        }
        # Its optional numba kernels: used when importable.
        if importlib.util.find_spec("numba") is not None:
            versions["numba"] = importlib.import_module("numba").__version__
        return by_bmquilting, versions
    raise SystemExit(f"unknown tool {kind}")


def checked(image: Pixels, side: int) -> Pixels:
    if image.shape != (side, side, 3) or image.dtype != np.uint8:
        raise SystemExit(f"wrong output: {image.shape} {image.dtype}, wanted ({side}, {side}, 3)")
    return image


def reply(message: dict[str, Any]) -> None:
    print(REPLY + json.dumps(message), flush=True)


def serve(kind: str, bm_path: Path) -> None:
    """The persistent worker: a side on each line of stdin, the seconds of one call back."""
    synthesize, versions = make_tool(kind, bm_path, read_png(TEXTURE))
    if kind.startswith("quilting"):
        import quilting

        # Kernels compiled or loaded, caches warm, before anything is timed.
        if hasattr(quilting, "warm_up"):
            quilting.warm_up()
        synthesize(2 * BLOCK)
    reply({"ready": True, "versions": versions})
    for line in sys.stdin:
        side = int(line)
        start = time.perf_counter()
        image = synthesize(side)
        seconds = time.perf_counter() - start
        checked(image, side)
        reply({"seconds": seconds})


def one_process(kind: str, bm_path: Path, side: int, save: Path) -> None:
    """The whole-process measure's process: import, read, synthesize, write."""
    synthesize, _ = make_tool(kind, bm_path, read_png(TEXTURE))
    write_png(checked(synthesize(side), side), save)


# --- the driver ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Tool:
    kind: str
    python: str
    env: dict[str, str]

    def argv(self, bm_path: Path, *args: str) -> list[str]:
        return [self.python, __file__, "--bm-path", str(bm_path), *args]


class Worker:
    """A tool's persistent subprocess (see :func:`serve`); its stderr goes to a file."""

    def __init__(self, tool: Tool, bm_path: Path, log: IO[str]) -> None:
        self.log = log
        self.process = subprocess.Popen(
            tool.argv(bm_path, "--worker", tool.kind),
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log,
            text=True, env=tool.env, cwd=ROOT,
        )  # fmt: skip

    def answer(self) -> dict[str, Any]:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            if line.startswith(REPLY):
                message: dict[str, Any] = json.loads(line[len(REPLY) :])
                return message
        self.process.wait()
        self.log.flush()
        self.log.seek(0)
        raise RuntimeError(f"exited {self.process.returncode}:\n{self.log.read()[-3000:]}")

    def call(self, side: int) -> float:
        assert self.process.stdin is not None
        self.process.stdin.write(f"{side}\n")
        self.process.stdin.flush()
        seconds: float = self.answer()["seconds"]
        return seconds

    def close(self) -> None:
        if self.process.stdin is not None:
            self.process.stdin.close()
        self.process.wait()


def whole_process(tool: Tool, bm_path: Path, side: int, save: Path) -> float:
    argv = tool.argv(bm_path, "--process", tool.kind, "--size", str(side), "--save", str(save))
    start = time.perf_counter()
    done = subprocess.run(argv, capture_output=True, text=True, env=tool.env, cwd=ROOT)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{LABELS[tool.kind]} at {side}: failed:\n{done.stderr[-3000:]}")
    return seconds


def rows_of(times: dict[int, dict[str, list[float]]]) -> list[list[str]]:
    rows = []
    for side, per_tool in times.items():
        reference = statistics.median(per_tool["quilting"])
        for kind, runs in per_tool.items():
            median = statistics.median(runs)
            rows.append(
                [
                    f"{side}x{side}",
                    LABELS[kind],
                    f"{median:.3f}",
                    f"{min(runs):.3f}-{max(runs):.3f}",
                    f"{median / reference:.2f}",
                ]
            )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="512,1024,2048", help="output sides, comma-separated")
    parser.add_argument("--repeat", type=int, default=3, help="timed runs per row and size")
    parser.add_argument("--peers", default="numpy,bmquilting", help="of numpy, bmquilting")
    parser.add_argument("--bm-python", type=Path, default=Path("/tmp/peers/venv/bin/python"))
    parser.add_argument("--bm-path", type=Path, default=Path("/tmp/peers/bmquilting"))
    parser.add_argument("--keep", type=Path, help="folder for the whole-process PNGs")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("--process", help=argparse.SUPPRESS)
    parser.add_argument("--size", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--save", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        serve(args.worker, args.bm_path)
        return
    if args.process:
        one_process(args.process, args.bm_path, args.size, args.save)
        return

    sides = [int(s) for s in args.sizes.split(",") if s.strip()]
    peers = [p.strip() for p in args.peers.split(",") if p.strip()]
    if any(side < BLOCK for side in sides) or args.repeat < 1:
        parser.error(f"sizes must be at least {BLOCK}, --repeat at least 1")
    if unknown := set(peers) - {"numpy", "bmquilting"}:
        parser.error(f"unknown peers {sorted(unknown)}; known: numpy, bmquilting")
    started = time.perf_counter()
    import scipy

    print("machine:", benchtools.machine(numpy=np.__version__, scipy=scipy.__version__))
    print("quilting:", benchtools.source_tree(ROOT))
    env = {**os.environ, "PYTHONPATH": str(ROOT / "server")}
    tools = [Tool("quilting", sys.executable, env), Tool("quilting-none", sys.executable, env)]
    if "numpy" in peers:
        tools.append(Tool("numpy", sys.executable, env))
    if "bmquilting" in peers:
        if not args.bm_python.exists():
            print(f"bmquilting: skipped, no Python at {args.bm_python} (see the docstring)")
        elif not (args.bm_path / "src" / "bmquilting").is_dir():
            print(f"bmquilting: skipped, no copy at {args.bm_path} (see the docstring)")
        else:
            bm_env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
            tools.append(Tool("bmquilting", str(args.bm_python), bm_env))

    keep = args.keep or Path(tempfile.mkdtemp(prefix="bench-peers-"))
    keep.mkdir(parents=True, exist_ok=True)
    with contextlib.ExitStack() as stack:
        workers: dict[str, Worker] = {}
        for tool in tools:
            worker = Worker(tool, args.bm_path, stack.enter_context(tempfile.TemporaryFile("w+")))
            # Never leave a worker behind when the run stops early.
            stack.callback(worker.process.kill)
            try:
                versions = worker.answer()["versions"]
            except RuntimeError as failure:
                if tool.kind != "bmquilting":
                    raise SystemExit(f"{LABELS[tool.kind]}: {failure}") from None
                print(f"bmquilting: skipped, its worker did not start: {failure}")
                continue
            workers[tool.kind] = worker
            print(f"{LABELS[tool.kind]}:", versions)
        tools = [tool for tool in tools if tool.kind in workers]

        in_call: dict[int, dict[str, list[float]]] = {}
        whole: dict[int, dict[str, list[float]]] = {}
        for side in sides:
            for worker in workers.values():
                worker.call(side)  # untimed: this size's first call
            in_call[side] = {tool.kind: [] for tool in tools}
            for _ in range(args.repeat):
                for tool in tools:
                    in_call[side][tool.kind].append(workers[tool.kind].call(side))
            whole[side] = {tool.kind: [] for tool in tools}
            for _ in range(args.repeat):
                for tool in tools:
                    save = keep / f"{tool.kind}-{side}.png"
                    whole[side][tool.kind].append(whole_process(tool, args.bm_path, side, save))
            elapsed = time.perf_counter() - started
            print(f"  {side}x{side} done ({elapsed:.0f} s so far)", flush=True)
        for worker in workers.values():
            worker.close()

    headers = ["size", "tool", "median s", "range s", "x quilting"]
    print(f"\nIn-call time (median of {args.repeat}, after one untimed call):\n")
    print(benchtools.markdown(headers, rows_of(in_call), left=2))
    print(f"\nWhole process: import, read PNG, synthesize, write PNG (median of {args.repeat}):\n")
    print(benchtools.markdown(headers, rows_of(whole), left=2))
    if args.keep:
        print("\noutputs:", keep)
    else:
        shutil.rmtree(keep)
    print("load average at the end:", [round(x, 2) for x in os.getloadavg()])
    print(f"total: {time.perf_counter() - started:.0f} s")


if __name__ == "__main__":
    main()
