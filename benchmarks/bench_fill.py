"""Benchmark of quilting.fill (inpainting) and make_tileable(method="fill"): speed, memory, quality.

The photograph: there is no 1024² photo in the repository, so the 451x300 "chelsea" cat
(``examples/cat.png``) is upscaled (Pillow bicubic) to 1536x1024 and its centre 1024x1024
cropped. Holes are centred:
a square of 5 %, 20 % and 50 % of the image, and an irregular blob of 20 % (a radial falloff
plus smoothed noise, thresholded, its largest piece with its holes closed: :func:`blob`).

Speed and memory (section 1)
    ``quilting.fill(photo, mask)`` with the default options for each hole, against plain
    synthesis (``quilting.synthesize``) of a square of as many pixels as the hole from the
    photo's top-left 256² crop, on the fill's grid (block 32, overlap 8, the fill's defaults;
    synthesis would take block 48 / overlap 8 by default), and ``fill(photo, mask,
    texture=crop)`` for the 20 % square (the same fill, blocks taken from the 256² crop: what
    the fill costs with synthesis's source size). Every case is called once untimed, then
    ``--repeats`` rounds run every case once in turn (so a slow spell of a noisy machine hits
    them alike); the tables give medians of the wall time around the call and of the engine's
    own stages (``select`` includes ``costs``: the engine's clock counts the search in both),
    and ``x synth``, the fill's wall median over the same-area synthesis's, same run. Memory: each
    case once more in a fresh interpreter (this script with the hidden ``--memory``): the
    peak RSS of one call over the RSS just before it, the peak (``VmHWM``) reset after
    imports, loading and a small warm-up call (:func:`memory_of`; ``bench_synthesis.py``
    takes ``ru_maxrss`` without a warm-up, which here would count numba's loading), and the
    tracemalloc peak of one more call (numpy reports its allocations to tracemalloc). The
    issue's target, a 1024² photo with a 20 % hole in <= 2 s on this machine, is checked
    against the wall medians of the two 20 % holes. One more case: ``extend`` of the photo by
    a sixteenth of its side on each side (64 px at 1024²: 26.6 % of the input's pixels added,
    21 % of the output), against the synthesis of as many pixels.

Exact search (section 2)
    The 20 % square once with ``search_scale=1`` (every source block scored at full size) and
    once with the default (0: coarse-to-fine at block // 8 = 4 for a source above 512²), back
    to back; wall times, their ratio, the mean squared difference across the cuts
    (``seam_error``) and the share of hole pixels that differ.

Quality (section 3)
    gravel and grass (256² gray) quilted to 512² (``synthesize``, seed 1, defaults); a 20 %
    hole cut from that image (a centred square, and the blob) and filled (defaults, seed 1).
    texeval (``--texeval PATH``, default :data:`benchtools.TEXEVAL`,
    run as a script in a subprocess, ``--json --no-ps``; the section's texeval columns are
    left out when it is absent) compares against the 256² texture: ``coh_p95``, ``seam_grad``,
    ``seam_excess`` and ``hf_excess``, and this script's ``edge step``: the mean |difference|
    across the hole's border (4-neighbour pairs with one pixel in the hole) over that across
    every other pair of the same window (about 1: the border looks like any other line). All are
    taken on a crop: the hole's bounding box grown by 16 px (half a block) on each side, so the
    filled pixels and the border where they meet the kept ones, and little else (on the whole
    512² four fifths would be the untouched synthesis, diluting any difference five times).
    The reference (``plain``) is the same window of the image before the hole was cut: a plain
    synthesis of the same size from the same texture, whose border pairs are ordinary
    neighbours.

Peers (section 4)
    ``resynthesizer`` (PyPI, the GIMP Resynthesizer engine of P. Harrison, "Image Texture Tools",
    PhD thesis, Monash University 2005, through ctypes; GPL-3.0; only ever imported here), when
    it imports: its fill (``getDefaultParams()`` with the two "make tileable" flags off, as
    GIMP's heal-selection sets them) of the photo's 20 % square (once: it takes about 50 s)
    timed against quilting's median from section 1, and of gravel's square, scored as in
    section 3. When it does not import, the reason is printed and the section skipped.
    Side-by-side pictures (hole in magenta | quilting | resynthesizer) go to ``--out``.

make_tileable (section 5)
    ``make_tileable(image, method=...)`` with ``"cut"`` and ``"fill"`` (other options default)
    on brick, gravel (256² gray) and wood (136² RGB) of ``tests/data``: median wall time
    (one untimed call, then the methods in turn), and the output tiled 2x2 scored by texeval
    against the input (``seam_grad``, ``seam_excess``, ``coh_p95``) and by ``wrap step``, the
    mean |difference| across the two joins of the 2x2 tiling over that across every other pair
    of neighbours (as ``bench_tile_blend.py``; about 1: the wrap looks like any other line).

``--quick`` is a smoke run: a 512² photo (the same upscale, cropped), a 128² crop, one repeat,
no exact search, quality on gravel at 256², make_tileable on brick only, the peer on gravel
only. ``--out DIR`` writes the pictures (fills, peers, 2x2 tilings); none by default.

Run from the repository root::

    .venv/bin/python benchmarks/bench_fill.py                       # about 4 minutes
    .venv/bin/python benchmarks/bench_fill.py --quick               # about 1.5 minutes
    .venv/bin/python benchmarks/bench_fill.py --repeats 3 --out /tmp/fill --json fill.json
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from collections.abc import Callable
from dataclasses import asdict, dataclass
from importlib.metadata import version
from pathlib import Path
from types import ModuleType
from typing import Any

import benchtools
import numpy as np
import scipy
from numpy.typing import NDArray
from PIL import Image as PILImage
from scipy import ndimage

import quilting

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
#: The photograph (the scikit-image "chelsea" cat, 451x300, CC0).
CAT = ROOT / "examples" / "cat.png"
TEXEVAL = benchtools.TEXEVAL
MIB = 1024 * 1024
#: The issue's target: a 1024² photo with a 20 % hole filled in at most this many seconds.
TARGET_S = 2.0
#: The fill's defaults, which the same-area synthesis uses as its grid.
FILL_BLOCK, FILL_OVERLAP = 32, 8
#: Margin of the quality crop around the hole's bounding box (half the fill's block).
MARGIN = 16
STAGES = ("costs", "select", "seams", "paste", "render")
#: The pixels extend adds (a sixteenth of the side on each side) over the input's.
EXTENDED = (1 + 2 / 16) ** 2 - 1
#: The hole shown in the "before" panels.
MAGENTA = (255, 0, 255)

Image = NDArray[Any]


# --- inputs ---------------------------------------------------------------------------------


def photo(side: int) -> Image:
    """The cat photograph upscaled (bicubic) to a height of ``side`` and centre-cropped square."""
    cat = PILImage.open(CAT).convert("RGB")
    width = round(cat.width * side / cat.height)
    big = np.asarray(cat.resize((width, side), PILImage.Resampling.BICUBIC))
    left = (width - side) // 2
    return np.ascontiguousarray(big[:, left : left + side])


def square(side: int, fraction: float) -> NDArray[np.bool_]:
    """A centred square hole of ``round(side * sqrt(fraction))`` px in a ``side``² image."""
    hole = round(side * math.sqrt(fraction))
    top = (side - hole) // 2
    mask = np.zeros((side, side), dtype=bool)
    mask[top : top + hole, top : top + hole] = True
    return mask


def blob(side: int, fraction: float, seed: int = 3) -> NDArray[np.bool_]:
    """An irregular centred hole of ``fraction`` (within half a percent) of a ``side``² image.

    The distance from the centre plus Gaussian-smoothed noise (sigma side / 24), thresholded,
    the largest connected piece with its holes closed: one ragged blob with lobes and bays,
    the same for a given seed. The threshold is corrected a few times for what the last two
    steps add or remove.
    """
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:side, 0:side] / side - 0.5
    noise = ndimage.gaussian_filter(rng.standard_normal((side, side)), side / 24)
    field = np.hypot(y, x) + noise / noise.std() * 0.08
    level = fraction
    mask = np.zeros((side, side), dtype=bool)
    for _ in range(8):
        labels, _ = ndimage.label(field <= np.quantile(field, level))
        sizes = np.bincount(labels.ravel())[1:]
        mask = ndimage.binary_fill_holes(labels == 1 + int(np.argmax(sizes)))
        got = float(mask.mean())
        if abs(got - fraction) <= 0.005:
            break
        level *= fraction / got
    return mask


def hole_mask(shape: str, side: int, fraction: float) -> NDArray[np.bool_]:
    return square(side, fraction) if shape == "square" else blob(side, fraction)


def texture(name: str) -> Image:
    image: Image = quilting.read_image(DATA / f"{name}.png")
    return image


# --- figures ----------------------------------------------------------------------------------


def colour(image: Image) -> NDArray[np.float64]:
    """The colour channels as float64 (H, W, C) in 8-bit steps (alpha left out)."""
    values = image.astype(np.float64)
    values = values[..., None] if values.ndim == 2 else values
    return values[..., :3]


def edge_step(image: Image, hole: NDArray[np.bool_]) -> float:
    """Mean |difference| across the hole's border over that across every other neighbour pair.

    Pairs of 4-neighbours with exactly one pixel in ``hole`` form the border; the figure is
    their mean absolute colour difference over the mean of all other pairs of ``image``.
    """
    values = colour(image)
    across = other = 0.0
    n_across = n_other = 0
    for axis in (0, 1):
        step = np.abs(np.diff(values, axis=axis)).mean(axis=2)
        border = np.diff(hole.astype(np.int8), axis=axis) != 0
        across += float(step[border].sum())
        n_across += int(border.sum())
        other += float(step[~border].sum())
        n_other += int((~border).sum())
    if not n_across or not other:
        return float("nan")
    return (across / n_across) / (other / n_other)


def wrap_step(image: Image) -> float:
    """Mean |difference| across the joins of ``image`` tiled 2x2 over that across every other
    pair of neighbours (as ``bench_tile_blend.py``'s wrap step)."""
    values = colour(image)
    joins = np.concatenate(
        [
            np.abs(values[:, 0] - values[:, -1]).mean(axis=-1).ravel(),
            np.abs(values[0] - values[-1]).mean(axis=-1).ravel(),
        ]
    )
    inner = np.concatenate([np.abs(np.diff(values, axis=k)).mean(axis=-1).ravel() for k in (0, 1)])
    return float(joins.mean() / inner.mean())


class Texeval:
    """texeval run as a script from its path (``--json --no-ps``), or nothing when absent."""

    FIGURES = ("coh_p95", "seam_grad", "seam_excess", "hf_excess")

    def __init__(self, path: Path | None) -> None:
        self.path = path if path is not None and path.is_file() else None
        self.calls = 0
        self.seconds = 0.0
        if self.path is None:
            print(f"note: no texeval ({path or 'QUILTING_TEXEVAL unset'}): its columns are "
                  "left out", flush=True)  # fmt: skip

    def __bool__(self) -> bool:
        return self.path is not None

    def __call__(self, source: Image, output: Image) -> dict[str, Any]:
        """texeval's figures of ``output`` against ``source``; {} without texeval."""
        if self.path is None:
            return {}
        started = time.perf_counter()
        with tempfile.TemporaryDirectory(prefix="bench_fill_") as folder:
            src, out = Path(folder) / "source.png", Path(folder) / "output.png"
            quilting.write_image(src, np.ascontiguousarray(source))
            quilting.write_image(out, np.ascontiguousarray(output))
            command = [sys.executable, str(self.path), str(src), str(out), "--json", "--no-ps"]
            done = subprocess.run(command, capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"texeval failed ({done.returncode}):\n{done.stderr[-2000:]}")
        self.calls += 1
        self.seconds += time.perf_counter() - started
        figures: dict[str, Any] = json.loads(done.stdout)
        return figures


def cell(value: Any, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    return f"{value:.{digits}f}"


def save(out: Path | None, name: str, image: Image) -> None:
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        quilting.write_image(out / name, np.ascontiguousarray(image))


def shown(image: Image, hole: NDArray[np.bool_]) -> Image:
    """``image`` as RGB uint8 with ``hole`` painted magenta (a "before" panel)."""
    rgb = colour(image).astype(np.uint8)
    rgb = np.repeat(rgb, 3, axis=2) if rgb.shape[2] == 1 else rgb.copy()
    rgb[hole] = MAGENTA
    return rgb


def side_by_side(panels: list[Image], width: int) -> Image:
    """RGB panels scaled to ``width`` px each (bicubic when shrinking), 8 px white between."""
    scaled = []
    for panel in panels:
        rgb = colour(panel).astype(np.uint8)
        rgb = np.repeat(rgb, 3, axis=2) if rgb.shape[2] == 1 else rgb
        pil = PILImage.fromarray(np.ascontiguousarray(rgb))
        height = round(pil.height * width / pil.width)
        scaled.append(np.asarray(pil.resize((width, height), PILImage.Resampling.BICUBIC)))
    gap = np.full((scaled[0].shape[0], 8, 3), 255, dtype=np.uint8)
    parts: list[Image] = []
    for k, panel in enumerate(scaled):
        parts += [gap, panel] if k else [panel]
    return np.concatenate(parts, axis=1)


# --- section 1: speed and memory ------------------------------------------------------------


@dataclass(frozen=True)
class Case:
    """One timed call: a fill of the photo, the same fill from the crop, or a synthesis."""

    name: str
    kind: str  # "fill", "fill-texture", "extend" or "synth"
    fraction: float
    shape: str  # "square" or "blob" (the hole; for synth, the hole whose area it matches)


CASES = (
    Case("fill 5% square", "fill", 0.05, "square"),
    Case("fill 20% square", "fill", 0.20, "square"),
    Case("fill 20% blob", "fill", 0.20, "blob"),
    Case("fill 50% square", "fill", 0.50, "square"),
    Case("fill 20% square, texture=crop", "fill-texture", 0.20, "square"),
    Case("extend +1/16 each side", "extend", EXTENDED, "square"),
    Case("synth = 5% area", "synth", 0.05, "square"),
    Case("synth = 20% area", "synth", 0.20, "square"),
    Case("synth = 50% area", "synth", 0.50, "square"),
    Case("synth = extend area", "synth", EXTENDED, "square"),
)
#: The same-area synthesis of each fill case.
PAIRS = {
    "fill 5% square": "synth = 5% area",
    "fill 20% square": "synth = 20% area",
    "fill 20% blob": "synth = 20% area",
    "fill 50% square": "synth = 50% area",
    "fill 20% square, texture=crop": "synth = 20% area",
    "extend +1/16 each side": "synth = extend area",
}


def prepare(case: Case, side: int, crop: int) -> tuple[Callable[[], Any], int]:
    """The call of a case (inputs built once) and its area in pixels."""
    image = photo(side)
    if case.kind == "extend":
        margin = side // 16
        added = (side + 2 * margin) ** 2 - side**2
        return lambda: quilting.extend(
            image, top=margin, bottom=margin, left=margin, right=margin
        ), added
    mask = hole_mask(case.shape, side, case.fraction)
    area = int(mask.sum())
    if case.kind == "fill":
        return lambda: quilting.fill(image, mask), area
    source = np.ascontiguousarray(image[:crop, :crop])
    if case.kind == "fill-texture":
        return lambda: quilting.fill(image, mask, texture=source), area
    out = round(math.sqrt(area))
    return (
        lambda: quilting.synthesize(
            source, (out, out), block=FILL_BLOCK, overlap=FILL_OVERLAP, seed=1
        ),
        out * out,
    )


def status_bytes(field: str) -> int:
    """A kB line of this process's ``/proc/self/status`` (``VmRSS``, ``VmHWM``), in bytes."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) * 1024
    raise KeyError(field)


def max_rss_bytes() -> int:
    """Peak resident set size of this process so far (``ru_maxrss`` is KiB on Linux)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak if sys.platform == "darwin" else peak * 1024


def memory_of(case: Case, side: int, crop: int) -> dict[str, float]:
    """Peak RSS increase of one call and tracemalloc peak of another; in a fresh process.

    The peak RSS (``VmHWM``) is reset (``5`` written to ``/proc/self/clear_refs``, Linux 4.0
    and later) after imports, loading and a small warm-up call, so that what numba and the
    imports took and gave back before does not hide the call's own peak; the figure is the
    peak during the call over the RSS just before it. Where ``clear_refs`` cannot be written
    (not Linux), the increase of ``ru_maxrss`` over the call, as ``bench_synthesis.py``.
    """
    call, _ = prepare(case, side, crop)
    small = photo(128)
    quilting.fill(small, square(128, 0.2))  # compiled kernels loaded before the baseline
    quilting.synthesize(small[:64, :64], (96, 96), block=FILL_BLOCK, overlap=FILL_OVERLAP)
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:  # not Linux: the peak so far is the baseline (numba's loading may hide)
        baseline = max_rss_bytes()
        call()
        rss = max_rss_bytes() - baseline
    else:
        baseline = status_bytes("VmRSS")
        call()
        rss = status_bytes("VmHWM") - baseline
    tracemalloc.start()
    call()
    traced = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return {"rss_mib": rss / MIB, "traced_mib": traced / MIB}


def memory_in_subprocess(case: Case, side: int, crop: int) -> dict[str, float]:
    command = [
        sys.executable,
        str(Path(__file__).resolve()),
        "--memory",
        case.name,
        "--side",
        str(side),
        "--crop",
        str(crop),
    ]
    done = subprocess.run(command, stdout=subprocess.PIPE, text=True, check=True)
    figures: dict[str, float] = json.loads(done.stdout.strip().splitlines()[-1])
    return figures


@dataclass
class Timed:
    case: str
    kind: str
    area: int
    blocks: int
    wall_s: float
    min_s: float
    engine_s: float
    stages_s: dict[str, float]
    rss_mib: float
    traced_mib: float


def speed(side: int, crop: int, repeats: int) -> list[Timed]:
    calls = {case.name: prepare(case, side, crop) for case in CASES}
    results: dict[str, Any] = {}
    for case in CASES:  # untimed first calls
        results[case.name] = calls[case.name][0]()
    wall: dict[str, list[float]] = {case.name: [] for case in CASES}
    engine: dict[str, list[dict[str, float]]] = {case.name: [] for case in CASES}
    for round_ in range(repeats):
        for case in CASES:
            start = time.perf_counter()
            result = calls[case.name][0]()
            wall[case.name].append(time.perf_counter() - start)
            engine[case.name].append(dict(result.timings))
        print(f"  speed: round {round_ + 1}/{repeats} done", file=sys.stderr, flush=True)
    timed = []
    for case in CASES:
        memory = memory_in_subprocess(case, side, crop)
        result = results[case.name]
        if case.kind == "synth":
            grid = result.layout.passes[0].grid
            blocks = grid.rows * grid.cols
        else:
            blocks = result.blocks
        runs = engine[case.name]
        timed.append(
            Timed(
                case=case.name,
                kind=case.kind,
                area=calls[case.name][1],
                blocks=blocks,
                wall_s=statistics.median(wall[case.name]),
                min_s=min(wall[case.name]),
                engine_s=statistics.median(r["total"] for r in runs),
                stages_s={s: statistics.median(r.get(s, 0.0) for r in runs) for s in STAGES},
                rss_mib=memory["rss_mib"],
                traced_mib=memory["traced_mib"],
            )
        )
        print(f"  memory: {case.name} done", file=sys.stderr, flush=True)
    return timed


def speed_table(timed: list[Timed], side: int) -> tuple[str, list[str]]:
    by_name = {t.case: t for t in timed}
    rows = []
    for t in timed:
        ratio = t.wall_s / by_name[PAIRS[t.case]].wall_s if t.case in PAIRS else None
        rows.append(
            [
                t.case,
                f"{100 * t.area / side**2:.1f}",
                str(t.area),
                str(t.blocks),
                f"{t.wall_s:.3f}",
                f"{t.min_s:.3f}",
                f"{t.engine_s:.3f}",
                *(f"{t.stages_s[s]:.3f}" for s in STAGES),
                f"{t.rss_mib:.1f}",
                f"{t.traced_mib:.1f}",
                "-" if ratio is None else f"{ratio:.2f}",
            ]
        )
    headers = [
        "case",
        "area %",
        "pixels",
        "blocks",
        "wall s",
        "min s",
        "engine s",
        *(f"{s} s" for s in STAGES),
        "RSS MiB",
        "traced MiB",
        "x synth",
    ]
    verdicts = []
    for name in ("fill 20% square", "fill 20% blob"):
        t = by_name[name]
        ok = t.wall_s <= TARGET_S
        over = f" (+{t.wall_s - TARGET_S:.2f} s, {t.wall_s / TARGET_S:.2f}x the target)"
        head = f"target 1024² photo, {name[5:]} hole <= {TARGET_S:g} s (wall median): "
        if side == 1024:
            verdicts.append(f"{head}{t.wall_s:.2f} s {'PASS' if ok else 'MISS' + over}")
        else:
            verdicts.append(f"{head}not checked ({t.wall_s:.2f} s at {side}²)")
    return benchtools.markdown(headers, rows), verdicts


# --- section 2: exact search ------------------------------------------------------------------


def exact_search(side: int) -> str:
    image = photo(side)
    mask = square(side, 0.20)
    runs = {}
    for scale in (1, 0):
        start = time.perf_counter()
        result = quilting.fill(image, mask, search_scale=scale)
        runs[scale] = (time.perf_counter() - start, result)
        print(f"  exact search: search_scale={scale} done", file=sys.stderr, flush=True)
    exact_image = runs[1][1].image
    default_image = runs[0][1].image
    differ = float(np.any(exact_image != default_image, axis=-1)[mask].mean())
    rows = [
        [
            "search_scale=1 (exact)",
            f"{runs[1][0]:.2f}",
            f"{runs[1][0] / runs[0][0]:.2f}",
            f"{runs[1][1].seam_error:.5f}",
            "-",
        ],
        [
            "search_scale=0 (default: 4 here)",
            f"{runs[0][0]:.2f}",
            "1.00",
            f"{runs[0][1].seam_error:.5f}",
            f"{100 * differ:.1f}",
        ],
    ]
    headers = ["search", "wall s", "x default", "seam_error", "hole px differing %"]
    return benchtools.markdown(headers, rows)


# --- sections 3 and 4: quality and the peer -------------------------------------------------


def load_peer() -> tuple[ModuleType | None, str]:
    """resynthesizer, or None and why it is not there."""
    try:
        # By name: an optional peer (GPL-3.0), imported here only, untyped or absent.
        peer = importlib.import_module("resynthesizer")
    except Exception as exc:  # ImportError, or OSError from its shared library
        return None, f"{type(exc).__name__}: {exc}"
    return peer, ""


def peer_fill(peer: ModuleType, image: Image, hole: NDArray[np.bool_]) -> tuple[Image, float]:
    """resynthesizer's fill of ``hole`` (GIMP heal-selection's flags), as ``image``'s channels."""
    params = peer.getDefaultParams()
    params.isMakeSeamlesslyTileableHorizontally = 0
    params.isMakeSeamlesslyTileableVertically = 0
    rgb = colour(image).astype(np.uint8)
    rgb = np.repeat(rgb, 3, axis=2) if rgb.shape[2] == 1 else rgb
    start = time.perf_counter()
    done = peer.resynthesize(
        PILImage.fromarray(np.ascontiguousarray(rgb)),
        PILImage.fromarray(hole.astype(np.uint8) * 255),
        params,
    )
    seconds = time.perf_counter() - start
    out = np.asarray(done.convert("RGB"))
    if image.ndim == 2:
        return np.ascontiguousarray(out[..., 0]), seconds
    return out, seconds


def window(hole: NDArray[np.bool_]) -> tuple[slice, slice]:
    """The hole's bounding box grown by :data:`MARGIN` on each side, inside the image."""
    rows, cols = np.flatnonzero(hole.any(axis=1)), np.flatnonzero(hole.any(axis=0))
    height, width = hole.shape
    return (
        slice(max(0, rows[0] - MARGIN), min(height, rows[-1] + 1 + MARGIN)),
        slice(max(0, cols[0] - MARGIN), min(width, cols[-1] + 1 + MARGIN)),
    )


def quality(
    names: tuple[str, ...],
    size: int,
    texeval: Texeval,
    peer: ModuleType | None,
    out: Path | None,
) -> tuple[str, list[dict[str, Any]]]:
    rows: list[list[str]] = []
    records: list[dict[str, Any]] = []
    for name in names:
        source = texture(name)
        base = quilting.synthesize(source, (size, size), seed=1).image
        save(out, f"quality_{name}_plain.png", base)
        for shape in ("square", "blob"):
            hole = hole_mask(shape, size, 0.20)
            start = time.perf_counter()
            filled = quilting.fill(base, hole, seed=1).image
            fill_s = time.perf_counter() - start
            outputs = {"plain": (base, None), "fill": (filled, fill_s)}
            if peer is not None and shape == "square":
                outputs["resynthesizer"] = peer_fill(peer, base, hole)
            panels = [shown(base, hole), filled]
            if "resynthesizer" in outputs:
                panels.append(outputs["resynthesizer"][0])
            save(out, f"quality_{name}_{shape}.png", side_by_side(panels, size))
            view = window(hole)
            for method, (image, seconds) in outputs.items():
                part = image[view]
                figures = texeval(source, part)
                record = {
                    "texture": name,
                    "hole": shape,
                    "area %": round(100 * float(hole.mean()), 1),
                    "crop": f"{part.shape[1]}x{part.shape[0]}",
                    "method": method,
                    "seconds": seconds,
                    "edge step": edge_step(part, hole[view]),
                    **{k: figures.get(k) for k in Texeval.FIGURES},
                }
                records.append(record)
                scores = [
                    cell(record[k], 4 if k == "seam_excess" else 3)
                    for k in Texeval.FIGURES
                    if texeval
                ]
                rows.append(
                    [
                        name,
                        f"{shape} {record['area %']:.1f}%",
                        str(record["crop"]),
                        method,
                        *scores,
                        cell(record["edge step"], 2),
                        "-" if seconds is None else f"{seconds:.2f}",
                    ]
                )
            print(f"  quality: {name} {shape} done", file=sys.stderr, flush=True)
    headers = [
        "texture",
        "hole",
        "crop",
        "method",
        *(Texeval.FIGURES if texeval else ()),
        "edge step",
        "fill s",
    ]
    return benchtools.markdown(headers, rows, left=4), records


def peer_photo(
    peer: ModuleType, side: int, quilting_s: float, out: Path | None
) -> tuple[str, dict[str, Any]]:
    image = photo(side)
    hole = square(side, 0.20)
    ours = quilting.fill(image, hole).image
    theirs, seconds = peer_fill(peer, image, hole)
    save(out, "peer_photo.png", side_by_side([shown(image, hole), ours, theirs], 512))
    rows = [
        ["quilting.fill (defaults), median of section 1", f"{quilting_s:.2f}", "1.00"],
        ["resynthesizer (once)", f"{seconds:.2f}", f"{seconds / quilting_s:.1f}"],
    ]
    table = benchtools.markdown(["20 % square of the photo", "wall s", "x quilting"], rows)
    return table, {"resynthesizer_s": seconds, "quilting_s": quilting_s}


# --- section 5: make_tileable -----------------------------------------------------------------


def tileable(
    names: tuple[str, ...], repeats: int, texeval: Texeval, out: Path | None
) -> tuple[str, list[dict[str, Any]]]:
    rows: list[list[str]] = []
    records: list[dict[str, Any]] = []
    methods = ("cut", "fill")
    for name in names:
        image = texture(name)
        results = {m: quilting.make_tileable(image, method=m) for m in methods}
        times: dict[str, list[float]] = {m: [] for m in methods}
        for _ in range(repeats):
            for m in methods:
                start = time.perf_counter()
                quilting.make_tileable(image, method=m)
                times[m].append(time.perf_counter() - start)
        tiles = {m: np.tile(colour(results[m].image), (2, 2, 1)).astype(np.uint8) for m in methods}
        save(out, f"tile_{name}.png", side_by_side([tiles["cut"], tiles["fill"]], 2 * 256))
        base = statistics.median(times["cut"])
        for m in methods:
            median = statistics.median(times[m])
            figures = texeval(image, tiles[m])
            record = {
                "image": name,
                "method": m,
                "ms": 1000 * median,
                "x cut": median / base,
                "wrap step": wrap_step(results[m].image),
                **{k: figures.get(k) for k in ("seam_grad", "seam_excess", "coh_p95")},
            }
            records.append(record)
            height, width = image.shape[:2]
            channels = 1 if image.ndim == 2 else image.shape[2]
            rows.append(
                [
                    name,
                    f"{width}x{height}x{channels}",
                    m,
                    f"{record['ms']:.1f}",
                    f"{record['x cut']:.2f}",
                    *(
                        [
                            cell(record["seam_grad"]),
                            cell(record["seam_excess"], 4),
                            cell(record["coh_p95"]),
                        ]
                        if texeval
                        else []
                    ),
                    f"{record['wrap step']:.2f}",
                ]
            )
        print(f"  make_tileable: {name} done", file=sys.stderr, flush=True)
    headers = ["image", "size", "method", "time ms", "x cut"]
    headers += ["seam_grad 2x2", "seam_excess 2x2", "coh_p95 2x2"] if texeval else []
    headers += ["wrap step"]
    return benchtools.markdown(headers, rows, left=3), records


# --- main -------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    parser = benchtools.parser(__doc__)
    parser.add_argument("--quick", action="store_true", help="a small, fast smoke run")
    parser.add_argument("--repeats", type=int, default=5, help="timed rounds (default 5)")
    parser.add_argument("--texeval", type=Path, default=TEXEVAL, metavar="PATH")
    parser.add_argument("--out", type=Path, metavar="DIR", help="write the pictures here")
    parser.add_argument("--memory", help=argparse.SUPPRESS)
    parser.add_argument("--side", type=int, default=1024, help=argparse.SUPPRESS)
    parser.add_argument("--crop", type=int, default=256, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)

    if args.memory:
        case = next(c for c in CASES if c.name == args.memory)
        print(json.dumps(memory_of(case, args.side, args.crop)))
        return 0

    started = time.perf_counter()
    side, crop = (512, 128) if args.quick else (1024, 256)
    repeats = 1 if args.quick else max(1, args.repeats)
    peer, why = load_peer()
    versions = {
        "quilting": quilting.__version__,
        "numpy": np.__version__,
        "scipy": scipy.__version__,
    }
    if peer is not None:
        versions["resynthesizer"] = version("resynthesizer")
    info = benchtools.machine(**versions)
    benchtools.show_machine(info)
    print(f"source: {benchtools.source_tree(ROOT)}")
    print(
        f"photo: target_chelsea (451x300) upscaled bicubic to {side * 3 // 2}x{side}, centre "
        f"{side}x{side} cropped (no {side}² photo on this machine); {repeats} timed round(s)"
    )
    texeval = Texeval(args.texeval)
    payload: dict[str, Any] = {"machine": info, "side": side, "repeats": repeats}

    print(f"\n## 1. fill vs same-area synthesis ({side}² photo, defaults)\n", flush=True)
    timed = speed(side, crop, repeats)
    table, verdicts = speed_table(timed, side)
    print(table)
    print()
    print("\n".join(verdicts), flush=True)
    payload["speed"] = [asdict(t) for t in timed]
    payload["verdicts"] = verdicts

    if not args.quick:
        print(f"\n## 2. exact search vs the default (20 % square, {side}² photo, once each)\n")
        print(exact_search(side), flush=True)

    print("\n## 3. quality of the fill (20 % holes in a 512² synthesis; texeval vs texture)\n")
    if peer is None:
        print(f"note: resynthesizer not importable ({why}): no peer rows")
    textures: tuple[str, ...] = ("gravel",) if args.quick else ("gravel", "grass")
    table, records = quality(textures, 256 if args.quick else 512, texeval, peer, args.out)
    print(table, flush=True)
    payload["quality"] = records

    print("\n## 4. peer: resynthesizer\n")
    if peer is None:
        print(f"skipped: resynthesizer does not import here: {why}")
    elif args.quick:
        print("quick run: the peer only in section 3's rows")
    else:
        fill_s = next(t.wall_s for t in timed if t.case == "fill 20% square")
        table, figures = peer_photo(peer, side, fill_s, args.out)
        print(table, flush=True)
        payload["peer"] = figures

    print("\n## 5. make_tileable: method='cut' vs 'fill' (the output tiled 2x2)\n")
    tiled: tuple[str, ...] = ("brick",) if args.quick else ("brick", "gravel", "wood")
    table, records = tileable(tiled, repeats, texeval, args.out)
    print(table, flush=True)
    payload["tileable"] = records

    if texeval:
        print(f"\ntexeval: {texeval.calls} calls, {texeval.seconds:.0f} s in all")
    payload["wall_s"] = benchtools.wall_time(started)
    benchtools.write_json(args.json, payload)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
