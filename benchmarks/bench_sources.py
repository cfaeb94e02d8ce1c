"""Several examples, rotations and mirrors, and Wang tiles: quality and cost against one example.

Every synthesis here is 512x512 (``--quick``: 256x256) from 128x128 samples, with the engine's
defaults (block 48, overlap 8, cut mode, Poisson-blended seams) and the ``fft`` backend. The
samples are the top-left 128x128 of each texture. Isotropic textures: ``gravel``, ``grass``
(from above) and ``hubble`` (the deep field) of ``tests/data`` and ``stones``, the procedural
Voronoi cobbles of ``quality_textures.py`` (isotropic by construction: no light direction,
which the gravel photo has); anisotropic, for contrast: ``brick`` and ``wood`` (136x136, the
only one too small for three crops).

Figures are texeval's (``--texeval PATH``; by default :data:`benchtools.TEXEVAL`; loaded by
path, Portilla-Simoncelli statistics and the coarse scale off; its columns are left out when
it is absent): ``coh_p95`` (95th percentile of the nearest-source-patch distance of 8x8 output
patches, relative to the source's own novelty; lower = closer to the source), ``seam_grad``
(colour step across the boundaries between verbatim copies over the source's ordinary
neighbour step; about 1 = invisible), ``seam_excess``, ``hf_excess``, ``copy_mean`` and
``copy_max`` (mean and largest size of the regions copied verbatim, as a share of the sample;
texeval looks for copies of the sample as it is, not turned or mirrored).

1. Transforms
    ``transforms='none'``, ``'flips'``, ``'rotations'``, ``'all'`` on every texture, seeds 1..N
    (``--seeds``, default 3); each figure the median over seeds, ``x none`` the median over
    seeds of the ratio to 'none' with the same seed, ``Δ none`` the median difference. The
    ``any`` columns are texeval's copy figures against an atlas of the sample's transformed
    copies (:class:`quilting.core.sources.SourceSet`, the transforms of the run), rescaled to
    shares of one sample: they also count the copies that were turned or mirrored.
    ``none's coh_p95 any`` is the same seed's ``'none'`` output scored against that same
    atlas, and the ``any`` columns' ``Δ none`` and ``x none`` compare with it: texeval divides
    each distance by the reference's own novelty (its leave-one-out nearest-patch distances),
    which the atlas changes (the deep field's 95th percentile falls from 0.149 for the sample
    to 0.061 for the atlas of ``'all'``), so an output scored against the atlas is only
    comparable with another output scored against the atlas.
    ``engine copy`` is ``result.stats.largest_copy`` (a share of the engine's atlas,
    ``layout.source_shape``) rescaled to the sample too: the largest region made of
    continuing blocks, in any orientation, exact from the layout; ``engine used`` is
    ``1 - result.stats.unused`` times the atlas's area over the sample's: how many samples'
    worth of distinct source pixels the output shows (at most 1 without transforms);
    ``mirror pairs`` (:func:`mirror_pairs`) is the share of neighbouring blocks that meet as
    reflections of each other (kaleidoscope patterns; 0 without mirrors).
    Goals: on the isotropic textures, 'all' halves ``copy_max`` (median over the isotropic
    textures of the per-texture ``x none`` <= 0.5) and ``coh_p95`` is no worse (``Δ none``
    <= 0 for each, the median over seeds). The coherence verdict is printed twice: against
    the sample as it is (where a turned patch is new by construction) and against the
    transformed copies (both outputs scored against the same atlas: is each output patch as
    close to the material the engine was given?).

2. Three examples
    Three disjoint 128x128 crops of the same 256x256 photo (top-left, top-right,
    bottom-centre: ``CROPS``) against the first alone, and the three with ``transforms='all'``;
    every output scored against the whole 256x256 photo (so the same reference for all), copy
    figures rescaled to shares of one 128x128 example; ``engine copy`` and ``engine used`` as
    in section 1, in 128x128 examples.

3. Weights
    The three crops with ``weights`` None, [2, 1, 1] and [4, 1, 1], seeds 1..5: the share of
    the blocks of ``layout.provenance()`` that come from each example, the mean over seeds,
    beside ``w / sum(w)``, the share if every example offered as many acceptable blocks.

4. Time
    gravel (gray) and hubble (RGB): one 128x128 sample with each preset, the three crops with
    none and 'all', and the whole 256x256 photo as one example (4x the area, no transforms).
    Every case is called once untimed, then ``--repeats`` rounds (default 5) run every case
    once in turn; the medians of the wall time around ``quilting.synthesize`` and of the
    engine's ``costs`` stage, ``x none`` their ratio to the one-sample 'none' case's of the
    same texture, and the atlas (``layout.source_shape``) and its area over one sample's.
    A least-squares line ``wall = a + b * area`` over the cases of a texture says how the cost
    grows with the source area.

5. Wang tiles
    ``quilting.wang_tiles(sample, colors=2, tile=256, seed=1)`` (16 tiles of 256x256) on gravel
    and hubble: one untimed call (numba compiled), then ``--repeats`` calls; the median of
    ``timings`` (material: quilting the 256x1024 texture the diamonds come from; cuts: the
    minimum cuts along the diagonals; tiles: cutting and blending the tiles) against the
    target of 3 s. Quality: a 6x6 arrangement (``arrange(6, 6, seed=1)``) rendered (1536x1536)
    against ``quilting.synthesize(sample, (1536, 1536), seed=1)``: texeval against the sample,
    and this script's steps, each the mean |difference| of luminance across a set of
    neighbour pairs over that across every other pair (about 1 = like any other line):
    ``join step`` across the tile joins (for the plain synthesis, the same lines of a 256 px
    grid), ``cut step`` across the cuts inside the tiles (pairs whose pixels show different
    diamonds), ``corner step`` across the joins within 1 px (the corner pixel's pairs) and
    within 8 px of the inner corners where four tiles meet. The edge rule: every neighbouring
    pair of the arrangement agrees on its shared edge (``quilting.core.wang.edge_rule_kept``,
    with and without ``wrap``), and ``edge mismatch``: across the tiles of the set that share
    an edge colour, the largest difference (in 8-bit levels) of that edge's pixels, away from
    the corners (8 px) and within them; 0 means tiles meet pixel for pixel; the same for the
    set made with ``blend='none'`` (the cuts inside the tiles not blended), whose edges are
    the diamonds' pixels unchanged.

``--quick`` is a smoke run: gravel and brick, one seed, 256x256 outputs, 3 repeats, Wang tiles
of gravel only.

Run from the repository root::

    .venv/bin/python benchmarks/bench_sources.py                 # about 9 minutes on 2 cores
    .venv/bin/python benchmarks/bench_sources.py --quick         # about 1.5 minutes
    .venv/bin/python benchmarks/bench_sources.py --seeds 5 --json sources.json
"""

from __future__ import annotations

import datetime
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

import benchtools
import numpy as np
import quality_textures
import scipy
from bench_quality import load_texeval, luminance, rgb01
from numpy.typing import NDArray

import quilting
from quilting.core.grid import Grid
from quilting.core.sources import PRESETS, TRANSFORMS, SourceSet
from quilting.core.wang import edge_rule_kept

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
TEXEVAL = benchtools.TEXEVAL
BACKEND = "fft"
SAMPLE = 128
SIZE = 512
QUICK_SIZE = 256
ISOTROPIC = ("gravel", "grass", "hubble", "stones")
ANISOTROPIC = ("brick", "wood")
PRESET_NAMES = ("none", "flips", "rotations", "all")
#: Top-left corners of the three disjoint 128x128 crops of a 256x256 photo.
CROPS = ((0, 0), (0, 128), (128, 64))
WEIGHTS: tuple[tuple[int, int, int] | None, ...] = (None, (2, 1, 1), (4, 1, 1))
WEIGHT_SEEDS = 5
TIME_TEXTURES = ("gravel", "hubble")
WANG_TEXTURES = ("gravel", "hubble", "stones")
WANG_TILE = 256
WANG_COLORS = 2
WANG_GRID = 6
WANG_TARGET_S = 3.0
#: Pixels from a tile's corner left out of the edge mismatch's "away from the corners".
CORNER = 8
#: :func:`mirror_pairs`: strip width, threshold against the typical figure, random places.
MIRROR_WIDTH = 12
MIRROR_FACTOR = 0.3
MIRROR_SAMPLES = 300
#: The texeval figures of the synthesis tables.
FIGURES = ("coh_p95", "seam_grad", "copy_mean", "copy_max")
#: The texeval figures of the Wang table.
WANG_FIGURES = ("coh_p95", "seam_grad", "seam_excess", "hf_excess", "copy_mean", "copy_max")

Image = NDArray[Any]


# --- inputs and scoring -----------------------------------------------------------------------


def photo(name: str) -> Image:
    """The whole texture: ``tests/data/<name>.png``, or a procedural one of
    ``quality_textures.py``."""
    path = DATA / f"{name}.png"
    image: Image = (
        quilting.read_image(path) if path.is_file() else quality_textures.procedural(name)
    )
    return image


def crop(image: Image, corner: tuple[int, int] = (0, 0), side: int = SAMPLE) -> Image:
    y, x = corner
    return np.ascontiguousarray(image[y : y + side, x : x + side])


def kind(name: str) -> str:
    return "isotropic" if name in ISOTROPIC else "anisotropic"


def transform_atlas(sample: Image, preset: str) -> Image:
    """The sample's transformed copies laid side by side, 1 px of black between them: what
    texeval is given to find copies in any orientation."""
    view = sample if sample.ndim == 3 else sample[..., None]
    plan = SourceSet.plan([(view.shape[0], view.shape[1])], PRESETS[preset])
    atlas: Image = plan.build([view])
    return atlas


class Scorer:
    """texeval's figures of an output against a source; {} when texeval is absent."""

    def __init__(self, path: Path | None) -> None:
        self.module: ModuleType | None = load_texeval(path)
        self.calls = 0
        self.seconds = 0.0

    def __bool__(self) -> bool:
        return self.module is not None

    def __call__(self, source: Image, output: Image) -> dict[str, float | None]:
        if self.module is None:
            return {}
        started = time.perf_counter()
        figures: dict[str, Any] = self.module.evaluate(
            rgb01(source), rgb01(output), use_ps=False, coarse=False
        )
        self.calls += 1
        self.seconds += time.perf_counter() - started
        return {k: v for k, v in figures.items() if isinstance(v, float | int) or v is None}


def area(shape: Sequence[int]) -> int:
    return int(shape[0]) * int(shape[1])


def rescaled(figures: dict[str, float | None], factor: float) -> dict[str, float | None]:
    """The copy figures (shares of the source scored against) as shares of one sample."""
    return {
        k: (None if figures.get(k) is None else float(figures[k] or 0.0) * factor)
        for k in ("copy_mean", "copy_max")
    }


def median(values: Sequence[float | None]) -> float | None:
    present = [v for v in values if v is not None]
    return statistics.median(present) if present else None


def digits(header: str) -> int:
    """Decimals of a table's column: times whole, ratios and samples 2, copies 4, else 3."""
    if header == "engine ms":
        return 0
    if " x " in header or "used" in header:
        return 2
    return 4 if "copy" in header else 3


def cell(value: float | None, digits: int = 3) -> str:
    return benchtools.fmt(value, digits)


def synth(texture: Any, size: int, seed: int, **options: Any) -> quilting.Result:
    result: quilting.Result = quilting.synthesize(
        texture, (size, size), seed=seed, backend=BACKEND, **options
    )
    return result


def progress(text: str) -> None:
    print(f"  {text}", file=sys.stderr, flush=True)


# --- 1. transforms ------------------------------------------------------------------------------


@dataclass
class Run:
    """One synthesis and its figures."""

    texture: str
    variant: str
    seed: int
    engine_s: float
    atlas: tuple[int, int]
    figures: dict[str, float | None] = field(default_factory=dict)
    any: dict[str, float | None] = field(default_factory=dict)
    # The same seed's 'none' output scored against this run's atlas: the baseline on the
    # same reference (texeval divides by the reference's own novelty, which the atlas changes).
    none_any: dict[str, float | None] = field(default_factory=dict)
    engine_copy: float = 0.0  # largest verbatim copy, as a share of one sample
    engine_used: float = 0.0  # distinct source pixels the output shows, in samples
    mirror_pairs: float = 0.0  # share of neighbouring blocks that are reflections of each other


def transform_runs(
    names: Sequence[str], seeds: Sequence[int], size: int, scorer: Scorer
) -> list[Run]:
    runs = []
    for name in names:
        sample = crop(photo(name))
        atlases = {p: transform_atlas(sample, p) for p in PRESET_NAMES[1:]}
        for seed in seeds:
            plain: Image | None = None  # the 'none' output, PRESET_NAMES's first
            for preset in PRESET_NAMES:
                result = synth(sample, size, seed, transforms=preset)
                if preset == "none":
                    plain = result.image
                atlas = tuple(result.layout.source_shape)
                scale = area(atlas) / SAMPLE**2
                run = Run(
                    name,
                    preset,
                    seed,
                    result.timings["total"],
                    (atlas[0], atlas[1]),
                    engine_copy=result.stats.largest_copy * scale,
                    engine_used=(1.0 - result.stats.unused) * scale,
                    mirror_pairs=mirror_pairs(result.image, result.layout.passes[-1].grid),
                )
                run.figures = scorer(sample, result.image)
                if preset == "none":
                    run.any = dict(run.figures)
                    run.none_any = dict(run.figures)
                elif scorer and plain is not None:
                    source = atlases[preset]
                    factor = area(source.shape) / SAMPLE**2
                    figures = scorer(source, result.image)
                    run.any = {**figures, **rescaled(figures, factor)}
                    figures = scorer(source, plain)
                    run.none_any = {**figures, **rescaled(figures, factor)}
                runs.append(run)
            progress(f"transforms: {name} seed {seed} done")
    return runs


def mirror_pairs(image: Image, grid: Grid, width: int = MIRROR_WIDTH) -> float:
    """Share of the pairs of neighbouring blocks that meet as reflections of each other.

    For each pair of blocks side by side (and, on the transposed image, one above the other)
    on ``grid``, the smallest mean |difference| of luminance, over the block's rows, between
    the ``width`` columns before an axis and the ``width`` columns after it read backwards, the
    axis anywhere in their overlap band; a pair is mirrored when that is below
    ``MIRROR_FACTOR`` times the median of the same figure at ``MIRROR_SAMPLES`` random places
    of the image (where no pair meets). A mirrored copy of a block beside its own
    continuation is a cheap seam on smooth textures, and the output shows kaleidoscope
    patterns; without mirrors the share is 0.
    """
    lum = luminance(image)
    block, step, overlap = grid.block, grid.step, grid.overlap

    def smallest(view: NDArray[np.float64], top: int, band: int) -> float | None:
        rows = view[top : top + block]
        found = [
            float(np.abs(rows[:, a - width : a] - rows[:, a : a + width][:, ::-1]).mean())
            for a in range(band, band + overlap + 1)
            if width <= a <= view.shape[1] - width
        ]
        return min(found) if found else None

    rng = np.random.default_rng(0)
    pairs: list[float] = []
    elsewhere: list[float] = []
    for view in (lum, np.ascontiguousarray(lum.T)):
        height, width_px = view.shape
        for top in range(0, height - block + 1, step):
            for band in range(step, width_px - width, step):
                if (value := smallest(view, top, band)) is not None:
                    pairs.append(value)
        for _ in range(MIRROR_SAMPLES):
            top = int(rng.integers(0, height - block + 1))
            band = int(rng.integers(width, width_px - width - overlap))
            if (value := smallest(view, top, band)) is not None:
                elsewhere.append(value)
    if not pairs or not elsewhere:
        return float("nan")
    typical = float(np.median(elsewhere))
    return float(np.mean(np.array(pairs) < MIRROR_FACTOR * typical))


def ratio_to(
    runs: Sequence[Run],
    baseline: str,
    value: Callable[[Run], float | None],
    difference: bool,
    against: Callable[[Run], float | None] | None = None,
) -> dict[tuple[str, str], float | None]:
    """(texture, variant) -> the median over seeds of value / baseline's (or value - baseline's)
    with the same seed; ``against``, where given, reads the baseline's figure from the run
    itself (the baseline scored against the run's own reference)."""
    base = {(r.texture, r.seed): value(r) for r in runs if r.variant == baseline}
    out: dict[tuple[str, str], list[float]] = {}
    for r in runs:
        mine = value(r)
        theirs = base.get((r.texture, r.seed)) if against is None else against(r)
        if mine is None or theirs is None or (not difference and theirs == 0):
            continue
        out.setdefault((r.texture, r.variant), []).append(
            mine - theirs if difference else mine / theirs
        )
    return {k: statistics.median(v) for k, v in out.items()}


def transform_tables(runs: Sequence[Run], scored: bool) -> tuple[str, str, dict[str, Any]]:
    """Table a: texeval against the sample as it is (the issue's figures); table b: against
    the atlas of its transformed copies, and the engine's own largest copy."""

    def fig(name: str) -> Callable[[Run], float | None]:
        return lambda r: r.figures.get(name)

    def anyfig(name: str) -> Callable[[Run], float | None]:
        return lambda r: r.any.get(name)

    def noneany(name: str) -> Callable[[Run], float | None]:
        return lambda r: r.none_any.get(name)

    ratios = {
        "copy_mean x none": ratio_to(runs, "none", fig("copy_mean"), difference=False),
        "copy_max x none": ratio_to(runs, "none", fig("copy_max"), difference=False),
        "coh_p95 Δ none": ratio_to(runs, "none", fig("coh_p95"), difference=True),
        "coh_p95 any Δ none": ratio_to(
            runs, "none", anyfig("coh_p95"), difference=True, against=noneany("coh_p95")
        ),
        "copy_max any x none": ratio_to(
            runs, "none", anyfig("copy_max"), difference=False, against=noneany("copy_max")
        ),
        "engine copy x none": ratio_to(runs, "none", lambda r: r.engine_copy, difference=False),
    }
    first = ["texture", "kind", "transforms", "atlas"]
    plain = [*FIGURES, "copy_mean x none", "copy_max x none", "coh_p95 Δ none", "engine ms"]
    turned = ["coh_p95 any", "none's coh_p95 any", "coh_p95 any Δ none", "seam_grad any"]
    turned += ["copy_mean any", "copy_max any", "copy_max any x none"]
    engine = ["engine copy", "engine copy x none", "engine used", "mirror pairs"]
    headers_a = first + (plain if scored else ["engine ms"])
    headers_b = first + (turned if scored else []) + engine
    rows_a: list[list[str]] = []
    rows_b: list[list[str]] = []
    summary: dict[str, Any] = {}
    for name in dict.fromkeys(r.texture for r in runs):
        for preset in PRESET_NAMES:
            mine = [r for r in runs if (r.texture, r.variant) == (name, preset)]
            key = (name, preset)
            record: dict[str, float | None] = {k: v.get(key) for k, v in ratios.items()}
            for f in FIGURES:
                record[f] = median([r.figures.get(f) for r in mine])
                record[f"{f} any"] = median([r.any.get(f) for r in mine])
                record[f"none's {f} any"] = median([r.none_any.get(f) for r in mine])
            record["engine copy"] = median([r.engine_copy for r in mine])
            record["engine used"] = median([r.engine_used for r in mine])
            record["mirror pairs"] = median([r.mirror_pairs for r in mine])
            record["engine ms"] = median([r.engine_s * 1000 for r in mine])
            head = [name, kind(name), preset, "x".join(map(str, mine[0].atlas))]
            for headers, rows in ((headers_a, rows_a), (headers_b, rows_b)):
                row = list(head)
                row += [cell(record[h], digits(h)) for h in headers[4:]]
                rows.append(row)
            summary[f"{name}/{preset}"] = record
    return (
        benchtools.markdown(headers_a, rows_a, left=3),
        benchtools.markdown(headers_b, rows_b, left=3),
        summary,
    )


def no_worse(names: Sequence[str], deltas: Sequence[float | None]) -> str:
    """Each texture's difference to 'none' and the verdict on "no worse" (every one <= 0)."""
    worse = [n for n, d in zip(names, deltas, strict=True) if d is None or d > 0]
    shown = ", ".join(f"{n} {d:+.3f}" for n, d in zip(names, deltas, strict=True) if d is not None)
    return f"{shown} (goal <= 0: {'PASS' if not worse else 'FAIL on ' + ', '.join(worse)})"


def transform_verdicts(summary: dict[str, Any], names: Sequence[str]) -> list[str]:
    iso = [n for n in names if n in ISOTROPIC]
    lines = []
    if (
        not iso
        or f"{iso[0]}/all" not in summary
        or summary[f"{iso[0]}/all"].get("copy_max x none") is None
    ):
        return ["goals: not checked (no isotropic texture, or no texeval)"]
    for preset in PRESET_NAMES[1:]:
        ratios = [summary[f"{n}/{preset}"]["copy_max x none"] for n in iso]
        deltas = [summary[f"{n}/{preset}"]["coh_p95 Δ none"] for n in iso]
        anys = [summary[f"{n}/{preset}"]["copy_max any x none"] for n in iso]
        coh_any = [summary[f"{n}/{preset}"]["coh_p95 any Δ none"] for n in iso]
        m = median(ratios)
        ok = m is not None and m <= 0.5
        lines.append(
            f"{preset:>9}: copy_max x none on the isotropic textures "
            f"{', '.join(f'{n} {cell(r, 2)}' for n, r in zip(iso, ratios, strict=True))}; "
            f"median {cell(m, 2)} (goal <= 0.5: {'PASS' if ok else 'FAIL'}); any orientation "
            f"median {cell(median(anys), 2)}; coh_p95 Δ none against the sample as it is "
            f"{no_worse(iso, deltas)}; against the transformed copies (both outputs scored "
            f"against the same atlas) {no_worse(iso, coh_any)}"
        )
    return lines


# --- 2. three examples --------------------------------------------------------------------------


EXAMPLE_VARIANTS: dict[str, tuple[int, str]] = {
    "one": (1, "none"),
    "three": (3, "none"),
    "three, all": (3, "all"),
}


def example_runs(
    names: Sequence[str], seeds: Sequence[int], size: int, scorer: Scorer
) -> list[Run]:
    runs = []
    for name in names:
        whole = photo(name)
        crops = [crop(whole, corner) for corner in CROPS]
        factor = area(whole.shape) / SAMPLE**2
        for seed in seeds:
            for variant, (count, preset) in EXAMPLE_VARIANTS.items():
                texture = crops[0] if count == 1 else crops[:count]
                result = synth(texture, size, seed, transforms=preset)
                atlas = tuple(result.layout.source_shape)
                run = Run(
                    name,
                    variant,
                    seed,
                    result.timings["total"],
                    (atlas[0], atlas[1]),
                    engine_copy=result.stats.largest_copy * area(atlas) / SAMPLE**2,
                    engine_used=(1.0 - result.stats.unused) * area(atlas) / SAMPLE**2,
                )
                figures = scorer(whole, result.image)
                run.figures = {**figures, **rescaled(figures, factor)} if figures else {}
                runs.append(run)
            progress(f"examples: {name} seed {seed} done")
    return runs


def example_table(runs: Sequence[Run], scored: bool) -> tuple[str, dict[str, Any]]:
    def fig(name: str) -> Callable[[Run], float | None]:
        return lambda r: r.figures.get(name)

    copy_x = ratio_to(runs, "one", fig("copy_max"), difference=False)
    mean_x = ratio_to(runs, "one", fig("copy_mean"), difference=False)
    coh_d = ratio_to(runs, "one", fig("coh_p95"), difference=True)
    engine_x = ratio_to(runs, "one", lambda r: r.engine_copy, difference=False)
    headers = ["texture", "examples", "atlas"]
    if scored:
        headers += [*FIGURES, "copy_mean x one", "copy_max x one", "coh_p95 Δ one"]
    headers += ["engine copy", "engine copy x one", "engine used", "engine ms"]
    rows, summary = [], {}
    for name in dict.fromkeys(r.texture for r in runs):
        for variant in EXAMPLE_VARIANTS:
            mine = [r for r in runs if (r.texture, r.variant) == (name, variant)]
            key = (name, variant)
            record: dict[str, float | None] = {}
            if scored:
                for f in FIGURES:
                    record[f] = median([r.figures.get(f) for r in mine])
                record["copy_mean x one"] = mean_x.get(key)
                record["copy_max x one"] = copy_x.get(key)
                record["coh_p95 Δ one"] = coh_d.get(key)
            record["engine copy"] = median([r.engine_copy for r in mine])
            record["engine copy x one"] = engine_x.get(key)
            record["engine used"] = median([r.engine_used for r in mine])
            record["engine ms"] = median([r.engine_s * 1000 for r in mine])
            row = [name, variant, "x".join(map(str, mine[0].atlas))]
            row += [cell(record[h], digits(h)) for h in headers[3:]]
            rows.append(row)
            summary[f"{name}/{variant}"] = record
    return benchtools.markdown(headers, rows, left=3), summary


# --- 3. weights ---------------------------------------------------------------------------------


def weight_table(names: Sequence[str], seeds: Sequence[int], size: int) -> tuple[str, Any]:
    headers = ["texture", "weights", "expected shares", "block shares (mean over seeds)", "blocks"]
    rows, records = [], []
    for name in names:
        whole = photo(name)
        crops = [crop(whole, corner) for corner in CROPS]
        for weights in WEIGHTS:
            shares, blocks = [], 0
            for seed in seeds:
                options: dict[str, Any] = {} if weights is None else {"weights": list(weights)}
                result = synth(crops, size, seed, **options)
                example = result.layout.provenance()["example"].ravel()
                blocks += example.size
                shares.append(np.bincount(example, minlength=3) / example.size)
            mean = np.mean(shares, axis=0)
            w = np.array(weights or (1, 1, 1), dtype=np.float64)
            expected = w / w.sum()
            rows.append(
                [
                    name,
                    "None" if weights is None else str(list(weights)),
                    " / ".join(f"{e:.2f}" for e in expected),
                    " / ".join(f"{s:.2f}" for s in mean),
                    str(blocks),
                ]
            )
            records.append(
                {"texture": name, "weights": weights, "shares": mean.tolist(), "blocks": blocks}
            )
        progress(f"weights: {name} done")
    return benchtools.markdown(headers, rows, left=2), records


# --- 4. time ------------------------------------------------------------------------------------


@dataclass
class Timed:
    texture: str
    case: str
    atlas: tuple[int, int]
    area_x: float
    wall_s: list[float] = field(default_factory=list)
    costs_s: list[float] = field(default_factory=list)


def time_cases(whole: Image) -> dict[str, tuple[Any, str]]:
    """Case -> (texture argument, transforms)."""
    sample = crop(whole)
    crops = [crop(whole, corner) for corner in CROPS]
    cases: dict[str, tuple[Any, str]] = {f"one {SAMPLE}², {p}": (sample, p) for p in PRESET_NAMES}
    cases[f"three {SAMPLE}², none"] = (crops, "none")
    cases[f"three {SAMPLE}², all"] = (crops, "all")
    side = whole.shape[0]
    cases[f"one {side}², none"] = (np.ascontiguousarray(whole[:side, :side]), "none")
    return cases


def timing(
    names: Sequence[str], size: int, repeats: int
) -> tuple[str, list[str], list[dict[str, Any]]]:
    timed: list[Timed] = []
    for name in names:
        cases = time_cases(photo(name))
        mine: dict[str, Timed] = {}
        for case, (texture, preset) in cases.items():  # warm-up, untimed
            result = synth(texture, size, 1, transforms=preset)
            atlas = tuple(result.layout.source_shape)
            mine[case] = Timed(name, case, (atlas[0], atlas[1]), area(atlas) / SAMPLE**2)
        for _ in range(repeats):
            for case, (texture, preset) in cases.items():
                started = time.perf_counter()
                result = synth(texture, size, 1, transforms=preset)
                mine[case].wall_s.append(time.perf_counter() - started)
                mine[case].costs_s.append(result.timings.get("costs", 0.0))
        timed += mine.values()
        progress(f"time: {name} done")
    headers = ["texture", "case", "atlas", "area x", "wall ms", "min ms", "x none", "costs ms"]
    headers += ["costs x none", "x none / area x"]
    rows, fits, records = [], [], []
    for name in names:
        mine_list = [t for t in timed if t.texture == name]
        base = mine_list[0]
        base_wall = statistics.median(base.wall_s)
        base_costs = statistics.median(base.costs_s)
        for t in mine_list:
            wall = statistics.median(t.wall_s)
            costs = statistics.median(t.costs_s)
            rows.append(
                [
                    name,
                    t.case,
                    "x".join(map(str, t.atlas)),
                    f"{t.area_x:.2f}",
                    f"{wall * 1000:.0f}",
                    f"{min(t.wall_s) * 1000:.0f}",
                    f"{wall / base_wall:.2f}",
                    f"{costs * 1000:.0f}",
                    f"{costs / base_costs:.2f}" if base_costs else "-",
                    f"{wall / base_wall / t.area_x:.2f}",
                ]
            )
            records.append({**asdict(t), "wall_median_s": wall, "costs_median_s": costs})
        xs = np.array([t.area_x for t in mine_list])
        ys = np.array([statistics.median(t.wall_s) for t in mine_list])
        slope, intercept = np.polyfit(xs, ys, 1)
        fits.append(
            f"{name}: wall ≈ {intercept * 1000:.0f} ms + {slope * 1000:.0f} ms per {SAMPLE}² of "
            f"atlas (least squares over the {len(xs)} cases; 'none' = {base_wall * 1000:.0f} ms)"
        )
    return benchtools.markdown(headers, rows, left=3), fits, records


# --- 5. Wang tiles ------------------------------------------------------------------------------


def step_ratio(
    lum: NDArray[np.float64], across_x: NDArray[np.bool_], across_y: NDArray[np.bool_]
) -> float:
    """Mean |difference| over the chosen neighbour pairs over that over every other pair.

    ``across_x`` (H, W - 1) marks the pairs (y, x)-(y, x + 1), ``across_y`` (H - 1, W) the pairs
    (y, x)-(y + 1, x)."""
    dx = np.abs(np.diff(lum, axis=1))
    dy = np.abs(np.diff(lum, axis=0))
    chosen = np.concatenate([dx[across_x], dy[across_y]])
    other = np.concatenate([dx[~across_x], dy[~across_y]])
    return float(chosen.mean() / other.mean()) if chosen.size and other.mean() > 0 else float("nan")


def join_masks(shape: tuple[int, int], tile: int) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    height, width = shape
    across_x = np.zeros((height, width - 1), dtype=bool)
    across_y = np.zeros((height - 1, width), dtype=bool)
    across_x[:, tile - 1 :: tile] = True
    across_y[tile - 1 :: tile, :] = True
    return across_x, across_y


def corner_masks(
    shape: tuple[int, int], tile: int, reach: int = 2
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """The join pairs within ``reach`` px of an inner corner where four tiles meet."""
    across_x, across_y = join_masks(shape, tile)
    near = np.zeros(shape, dtype=bool)
    for y in range(tile, shape[0], tile):
        for x in range(tile, shape[1], tile):
            near[y - reach : y + reach, x - reach : x + reach] = True
    return across_x & near[:, :-1], across_y & near[:-1, :]


def edge_mismatch(tiles: Image, edges: NDArray[np.intp]) -> tuple[int, int]:
    """Largest difference (8-bit levels) of an edge's pixels between tiles that share its
    colour: away from the corners, and within ``CORNER`` px of them."""
    values = tiles.astype(np.int32)
    values = values if values.ndim == 4 else values[..., None]
    sides = (values[:, 0], values[:, :, -1], values[:, -1], values[:, :, 0])  # n, e, s, w
    inner = outer = 0
    for k, side in enumerate(sides):
        for colour in np.unique(edges[:, k]):
            same = side[edges[:, k] == colour]
            spread = (same.max(axis=0) - same.min(axis=0)).max(axis=-1)
            inner = max(inner, int(spread[CORNER:-CORNER].max()))
            outer = max(outer, int(np.concatenate([spread[:CORNER], spread[-CORNER:]]).max()))
    return inner, outer


def wang(
    names: Sequence[str], repeats: int, scorer: Scorer
) -> tuple[str, str, list[str], list[dict[str, Any]]]:
    time_rows, quality_rows, verdicts, records = [], [], [], []
    for name in names:
        sample = crop(photo(name))

        def make(sample: Image = sample) -> Any:
            return quilting.wang_tiles(
                sample, colors=WANG_COLORS, tile=WANG_TILE, seed=1, backend=BACKEND
            )

        make()  # numba compiled, caches warm
        made, walls = [], []
        for _ in range(repeats):
            started = time.perf_counter()
            made.append(make())
            walls.append(time.perf_counter() - started)
        tiles = made[-1]
        stages = {k: statistics.median([m.timings[k] for m in made]) for k in tiles.timings}
        wall = statistics.median(walls)
        time_rows.append(
            [
                name,
                f"{len(tiles.tiles)} x {WANG_TILE}²",
                f"{wall:.2f}",
                f"{min(walls):.2f}",
                *(f"{stages[k]:.2f}" for k in ("material", "cuts", "tiles", "total")),
            ]
        )
        verdicts.append(
            f"{name}: {len(tiles.tiles)} tiles of {WANG_TILE}² in {wall:.2f} s (median of "
            f"{repeats}) <= {WANG_TARGET_S:g} s: {'PASS' if wall <= WANG_TARGET_S else 'FAIL'}"
        )
        arrangement = tiles.arrange(WANG_GRID, WANG_GRID, seed=1)
        rendered = tiles.render(arrangement)
        wrapped = tiles.arrange(WANG_GRID, WANG_GRID, seed=1, wrap=True)
        rule = edge_rule_kept(tiles.edges, arrangement)
        rule_wrap = edge_rule_kept(tiles.edges, wrapped, wrap=True)
        inner, outer = edge_mismatch(tiles.tiles, tiles.edges)
        unblended = quilting.wang_tiles(
            sample, colors=WANG_COLORS, tile=WANG_TILE, seed=1, backend=BACKEND, blend="none"
        )
        raw_inner, raw_outer = edge_mismatch(unblended.tiles, unblended.edges)
        side = WANG_GRID * WANG_TILE
        plain = synth(sample, side, 1).image
        labels = tiles.render(arrangement, tiles.labels)
        cut_x = (np.diff(labels.astype(np.int16), axis=1) != 0) & ~join_masks(
            labels.shape, WANG_TILE
        )[0]
        cut_y = (np.diff(labels.astype(np.int16), axis=0) != 0) & ~join_masks(
            labels.shape, WANG_TILE
        )[1]
        used = len(np.unique(arrangement))
        for label, image in (("wang 6x6", rendered), ("plain synthesis", plain)):
            lum = luminance(image)
            joins = step_ratio(lum, *join_masks(lum.shape, WANG_TILE))
            corner = step_ratio(lum, *corner_masks(lum.shape, WANG_TILE, 1))
            corners = step_ratio(lum, *corner_masks(lum.shape, WANG_TILE, CORNER))
            cuts = step_ratio(lum, cut_x, cut_y) if label.startswith("wang") else None
            figures = scorer(sample, image)
            row = [name, label, f"{image.shape[1]}x{image.shape[0]}"]
            row += [cell(figures.get(f), 4 if "copy" in f or f == "seam_excess" else 3)
                    for f in WANG_FIGURES] if scorer else []  # fmt: skip
            row += [f"{joins:.3f}", f"{corner:.3f}", f"{corners:.3f}", cell(cuts)]
            quality_rows.append(row)
            records.append(
                {
                    "texture": name,
                    "output": label,
                    "figures": figures,
                    "join_step": joins,
                    "corner_step_1px": corner,
                    "corner_step": corners,
                    "cut_step": cuts,
                }
            )
        verdicts.append(
            f"{name}: edge rule kept by the 6x6 arrangement: {rule}, by a wrapped one: "
            f"{rule_wrap}; {used} of {len(tiles.tiles)} tiles used; edge mismatch between "
            f"tiles sharing a colour: {inner} levels away from the corners, {outer} within "
            f"{CORNER} px of them (blend='none': {raw_inner} and {raw_outer})"
        )
        records.append(
            {
                "texture": name,
                "wall_s": walls,
                "stages_median_s": stages,
                "edge_rule": rule,
                "edge_rule_wrap": rule_wrap,
                "edge_mismatch": [inner, outer],
                "edge_mismatch_unblended": [raw_inner, raw_outer],
            }
        )
        progress(f"wang: {name} done")
    time_headers = ["texture", "tiles", "wall s", "min s", "material s", "cuts s", "tiles s"]
    time_headers += ["total s"]
    quality_headers = ["texture", "output", "size"]
    quality_headers += list(WANG_FIGURES) if scorer else []
    quality_headers += ["join step", "corner step 1 px", f"corner step {CORNER} px", "cut step"]
    return (
        benchtools.markdown(time_headers, time_rows, left=2),
        benchtools.markdown(quality_headers, quality_rows, left=3),
        verdicts,
        records,
    )


# --- main ---------------------------------------------------------------------------------------


#: The sections of the report, in order (``--only``).
SECTIONS = ("transforms", "examples", "weights", "time", "wang", "continuation")


def continuation_table(
    names: Sequence[str], seeds: Sequence[int], size: int, scorer: Scorer
) -> tuple[str, list[str], list[dict[str, Any]]]:
    """``continuation='avoid'`` against the default, without transforms and with 'all': the
    texeval figures against the sample as it is, ratios to the default without transforms
    (the issue's baseline), medians over seeds."""
    variants = [("none", "allow"), ("all", "allow"), ("none", "avoid"), ("all", "avoid")]
    records: list[dict[str, Any]] = []
    rows = []
    verdicts = []
    for name in names:
        sample = crop(photo(name))
        figures: dict[tuple[str, str], list[dict[str, float | None]]] = {v: [] for v in variants}
        seconds: dict[tuple[str, str], list[float]] = {v: [] for v in variants}
        for seed in seeds:
            for preset, rule in variants:
                result = synth(sample, size, seed, transforms=preset, continuation=rule)
                seconds[(preset, rule)].append(result.timings["total"])
                found = scorer(sample, result.image)
                figures[(preset, rule)].append(found)
                records.append({"texture": name, "transforms": preset, "continuation": rule,
                                "seed": seed, **found})  # fmt: skip
            progress(f"continuation: {name} seed {seed} done")
        base = figures[("none", "allow")]
        for preset, rule in variants:
            runs = figures[(preset, rule)]
            ratio = median([
                (r.get("copy_max") or 0.0) / (b.get("copy_max") or 1.0) if b.get("copy_max")
                else None
                for r, b in zip(runs, base, strict=True)
            ])  # fmt: skip
            delta = median([
                (r.get("coh_p95") or 0) - (b.get("coh_p95") or 0) if b.get("coh_p95") else None
                for r, b in zip(runs, base, strict=True)
            ])  # fmt: skip
            rows.append(
                f"| {name} | {preset} | {rule} | {cell(median([r.get('coh_p95') for r in runs]))} "
                f"| {cell(median([r.get('seam_grad') for r in runs]))} "
                f"| {cell(median([r.get('copy_mean') for r in runs]), 4)} "
                f"| {cell(median([r.get('copy_max') for r in runs]), 4)} | {cell(ratio, 2)} "
                f"| {cell(delta)} | {1000 * float(np.median(seconds[(preset, rule)])):.0f} |"
            )
            if (preset, rule) == ("all", "avoid") and ratio is not None:
                verdicts.append(
                    f"{name}: copy_max, all + avoid x none + allow {ratio:.2f} (goal <= 0.5: "
                    f"{'met' if ratio <= 0.5 else 'FAIL'})"
                )
    header = (
        "| texture | transforms | continuation | coh_p95 | seam_grad | copy_mean | copy_max "
        "| copy_max x none, allow | coh_p95 Δ none, allow | engine ms |\n"
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|"
    )
    return header + "\n" + "\n".join(rows), verdicts, records


def main(argv: list[str] | None = None) -> int:
    parser = benchtools.parser(__doc__, json_help="write every figure here")
    parser.add_argument("--quick", action="store_true", help="a small, fast smoke run")
    parser.add_argument("--seeds", type=int, default=3, help="seeds 1..N (default 3)")
    parser.add_argument("--repeats", type=int, default=5, help="timed rounds (default 5)")
    parser.add_argument(
        "--texeval", type=Path, default=TEXEVAL, metavar="PATH", help=f"default {TEXEVAL}"
    )
    parser.add_argument(
        "--only",
        choices=SECTIONS,
        action="append",
        help="run only this section (repeatable; default: all of them)",
    )
    args = parser.parse_args(argv)
    chosen = set(args.only or SECTIONS)

    started = time.perf_counter()
    quick = args.quick
    seeds = [1] if quick else list(range(1, max(1, args.seeds) + 1))
    repeats = 3 if quick else max(3, args.repeats)
    size = QUICK_SIZE if quick else SIZE
    textures = ("gravel", "brick") if quick else ISOTROPIC + ANISOTROPIC
    three = [n for n in textures if min(photo(n).shape[:2]) >= 2 * SAMPLE]
    info = benchtools.machine(
        quilting=quilting.__version__, numpy=np.__version__, scipy=scipy.__version__
    )
    benchtools.show_machine(info)
    print(f"date: {datetime.date.today().isoformat()}, commit {benchtools.source_tree(ROOT)}")
    print("command: bench_sources.py " + " ".join(argv if argv is not None else sys.argv[1:]))
    print(
        f"synthesis {size}x{size} from {SAMPLE}x{SAMPLE} samples (top-left crops), engine "
        f"defaults, backend {BACKEND}; seeds {seeds[0]}..{seeds[-1]}; transforms in "
        f"'all': {', '.join(TRANSFORMS)}",
        flush=True,
    )
    scorer = Scorer(args.texeval)
    payload: dict[str, Any] = {"machine": info, "size": size, "seeds": seeds}

    if "transforms" in chosen:
        print("\n## 1. transforms against none (medians over seeds)\n", flush=True)
        runs = transform_runs(textures, seeds, size, scorer)
        table_a, table_b, summary = transform_tables(runs, bool(scorer))
        print("a. against the sample as it is (texeval's figures, the issue's goals):\n")
        print(table_a + "\n")
        print("b. against the sample's transformed copies (any orientation), and the engine's:\n")
        print(table_b + "\n")
        print("\n".join(transform_verdicts(summary, textures)), flush=True)
        payload["transforms"] = {"runs": [asdict(r) for r in runs], "summary": summary}

    if "examples" in chosen:
        print(
            f"\n## 2. three {SAMPLE}² crops of one photo against one (scored against the whole "
            "photo; copies in shares of one example)\n",
            flush=True,
        )
        runs = example_runs(three, seeds, size, scorer)
        table, summary = example_table(runs, bool(scorer))
        print(table, flush=True)
        payload["examples"] = {"runs": [asdict(r) for r in runs], "summary": summary}

    if "weights" in chosen:
        print("\n## 3. weights: share of the blocks per example (layout.provenance())\n")
        weight_seeds = list(range(1, (2 if quick else WEIGHT_SEEDS) + 1))
        iso_three = [n for n in three if n in ISOTROPIC]
        table, records = weight_table(iso_three[:1] if quick else iso_three, weight_seeds, size)
        print(f"seeds 1..{weight_seeds[-1]}, the three crops of section 2\n")
        print(table, flush=True)
        payload["weights"] = records

    if "time" in chosen:
        print(f"\n## 4. time against one example ({size}x{size}; medians of {repeats} rounds)\n")
        names: Sequence[str] = TIME_TEXTURES[:1] if quick else TIME_TEXTURES
        table, fits, records = timing(names, size, repeats)
        print(table + "\n")
        print("\n".join(fits), flush=True)
        payload["time"] = records

    if "wang" in chosen:
        print(
            f"\n## 5. Wang tiles: colors={WANG_COLORS}, tile={WANG_TILE} from a {SAMPLE}² sample "
            f"(median of {repeats} warm calls; quality of a {WANG_GRID}x{WANG_GRID} arrangement)\n",
            flush=True,
        )
        names = WANG_TEXTURES[:1] if quick else WANG_TEXTURES
        time_table, quality_table, verdicts, records = wang(names, repeats, scorer)
        print(time_table + "\n")
        print(quality_table + "\n")
        print("\n".join(verdicts))
        payload["wang"] = records

    if "continuation" in chosen:
        print(
            "\n## 6. continuation='avoid' (no block continues its neighbour's source "
            "verbatim), without transforms and with 'all'\n",
            flush=True,
        )
        names = ISOTROPIC[:1] if quick else ISOTROPIC
        table, verdicts, records = continuation_table(names, seeds, size, scorer)
        print(table + "\n")
        print("\n".join(verdicts), flush=True)
        payload["continuation"] = records

    if scorer:
        print(f"\ntexeval: {scorer.calls} calls, {scorer.seconds:.0f} s in all")
    payload["wall_s"] = benchtools.wall_time(started)
    print(f"load average at the end: {benchtools.machine()['loadavg']}")
    benchtools.write_json(args.json, payload)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
