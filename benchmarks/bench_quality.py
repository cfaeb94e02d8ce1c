"""Quality of synthesis and transfer over many textures, per variant of the options (issue 20).

A *variant* is a name and a set of keyword options for :func:`quilting.synthesize` (or, with
``--transfer``, :func:`quilting.transfer`), given on the command line as ``NAME:KEY=VALUE,...``::

    --variant none:blend=none             # the baseline of 'time x': always put it first
    --variant poisson:                    # today's defaults (blend="poisson")
    --variant o4:overlap_frac=1/4         # overlap = round(block / 4), half up
    --variant tol:tolerance=0.2,min_candidates=1
    --variant x:feathered=true            # an option the engine does not take: refused

``overlap_frac`` is the benchmark's own: the overlap in pixels is ``round(block * frac)``
(rounding half up), since the engine takes ``overlap`` in pixels and the block differs from
texture to texture. Values are parsed as None (``None`` or ``null``: lower-case ``none`` is
text, a value of ``blend``), true/false, int or float, else kept as text. An option the
function does not take, or a value it refuses, stops the benchmark before it starts (every
variant is tried once on a small output first). The first variant is the baseline of
the ``time x`` column; with no ``--variant`` the only variant is ``cut:``.

Synthesis (the default mode)
    Every texture (the repository's photos and the procedural textures of
    ``quality_textures.py``; ``--textures a,b`` picks some) is quilted to 512x512 at two block
    sizes: the issue's rule ``block = max(16, min(48, side // 3))`` (48 for the 192² and 256²
    textures, 45 for the 136² wood) and 32; seed 1 (``--seeds N``: seeds 1..N, figures
    averaged over the seeds of a texture). Each run is timed by the engine
    (``result.timings["total"]``) and scored by texeval (``--texeval PATH``; by default
    :data:`benchtools.TEXEVAL`, the file ``QUILTING_TEXEVAL`` names, e.g.
    the build machines' copy; without it only this script's own
    figures are reported; loaded by path,
    Portilla-Simoncelli statistics and the coarse-scale coherence off) and by this script's
    band/core gradient ratio (:func:`band_core_ratio`). Per block size a table: one row per
    variant, each figure the median over textures, and ``time x`` the median over
    textures of the variant's engine time over the baseline's (same texture, same seed, same
    run; the variants of one texture run one after the other). ``--per-texture`` adds the
    table of every texture.

Transfer (``--transfer``)
    ``quilting.transfer(texture, target, seed=1, **variant)`` for the gravel and wood textures
    (``--textures``) onto ``tests/data/target_camera.png`` (256² gray) and ``examples/cat.png``
    (the 451x300 RGB "chelsea" target), reporting the likeness (Pearson r between the
    Gaussian-blurred, sigma 2, luminance of output and target), texeval's ``hf_excess`` of the
    output against the texture and the same for a plain synthesis from the same texture at the
    target's size (block: the transfer's first-pass block, 24 by default; the variant's options
    that ``synthesize`` also takes, such as ``overlap``, go to it too), their difference
    (issue 20 wants ``|transfer - synthesis| <= 0.2``), the band/core ratio of the last pass
    and the engine time.

Figures (texeval's docstring has the details; lower is better unless said):
``seam_grad`` (mean squared colour step across the boundaries between verbatim-copied
regions over the source's mean squared neighbour difference; ~1 ideal), ``seam_excess``
(extra gradient energy on those boundaries; 0 ideal), ``coh_p95`` (95th percentile of the
nearest-source-patch distance of 8x8 output patches, relative to the source's own novelty),
``copy_mean`` and ``copy_max`` (size of verbatim-copied regions as a share of the source),
``hf_excess`` (log2 of the output's luminance gradient energy over the source's; signed, 0
ideal), ``band/core`` (this script's: 1 = the overlap bands have the same gradient energy as
the rest of the blocks), ``edge run`` (this script's, :func:`edge_runs`: the share of the seams'
length running straight along a band's edge for 5 pixels or more; 0 ideal). texeval reports
the seam figures as n/a when less than a quarter of an output is verbatim copy; a median over
fewer textures than the others is marked ``*``.
Without texeval (or without scikit-image, which it uses for two figures not reported here)
the script says so and reports what it can.

``--legacy`` prints the two tables this script printed before issue 20 instead: mean seam
error of ``random``/``overlap``/``cut`` and the largest verbatim copy against
``min_candidates`` (brick, gravel, hubble; block 48; means over ``--seeds``, default 3).

Run from the repository root::

    .venv/bin/python benchmarks/bench_quality.py --quick                   # 3 textures, 256²
    .venv/bin/python benchmarks/bench_quality.py --variant cut: --variant o4:overlap_frac=1/4
    .venv/bin/python benchmarks/bench_quality.py --textures gravel,bricks --per-texture
    .venv/bin/python benchmarks/bench_quality.py --json quality.json
    .venv/bin/python benchmarks/bench_quality.py --transfer --variant it1:iterations=1 \\
        --variant it3:iterations=3
    .venv/bin/python benchmarks/bench_quality.py --legacy
"""

from __future__ import annotations

import contextlib
import datetime
import functools
import importlib.util
import inspect
import json
import math
import statistics
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from types import ModuleType
from typing import Any

import benchtools
import numpy as np
import quality_textures
import scipy
from numpy.typing import NDArray
from scipy import ndimage

import quilting
from quilting.core.grid import Grid
from quilting.core.layout import LayoutPass

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
#: Where texeval is looked for unless ``--texeval`` says: the team's tools beside the checkout
#: (a clone elsewhere passes its own copy, or runs without texeval's figures).
TEXEVAL = benchtools.TEXEVAL
#: The figures of texeval reported in the tables, in order.
#: Shortest run of a seam along a band's edge that :func:`edge_runs` counts.
EDGE_RUN = 5
FIGURES = ("seam_grad", "seam_excess", "coh_p95", "copy_mean", "copy_max", "hf_excess")
#: The second block size of the synthesis tables (the first is the issue's rule).
SECOND_BLOCK = 32
QUICK_TEXTURES = ("gravel", "bricks", "drift")
TRANSFER_TEXTURES = ("gravel", "wood")
TRANSFER_TARGETS = {
    "camera": DATA / "target_camera.png",
    "chelsea": ROOT / "examples" / "cat.png",
}
LIKENESS_SIGMA = 2.0
#: Options a variant may not set: the benchmark sets them per run.
RESERVED = {
    "synthesize": {"texture", "size", "seed", "block", "progress"},
    "transfer": {"texture", "target", "seed", "progress"},
}
#: Rec. 601 weights, as the engine's own luminance.
LUMA = (0.299, 0.587, 0.114)

Image = NDArray[Any]


# --- variants -----------------------------------------------------------------------------


@dataclass(frozen=True)
class Variant:
    """A name and the keyword options it passes; ``overlap_frac`` resolved per block."""

    name: str
    options: dict[str, Any] = field(default_factory=dict)
    overlap_frac: Fraction | None = None

    def kwargs(self, block: int) -> dict[str, Any]:
        """The keyword options for a run at ``block`` (``overlap`` from ``overlap_frac``)."""
        options = dict(self.options)
        if self.overlap_frac is not None:
            options["overlap"] = math.floor(block * self.overlap_frac + Fraction(1, 2))
        return options

    def describe(self) -> str:
        parts = [f"{k}={v}" for k, v in self.options.items()]
        if self.overlap_frac is not None:
            parts.insert(0, f"overlap_frac={self.overlap_frac}")
        return ", ".join(parts) or "defaults"


def _value(text: str) -> Any:
    """A variant's option value: None (``null``; ``None`` with a capital, since ``none`` is a
    value of ``blend``), a bool, an int, a float, or the text itself."""
    low = text.strip().lower()
    if low == "null" or text.strip() == "None":
        return None
    if low in ("true", "false"):
        return low == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text.strip()


def parse_variant(text: str) -> Variant:
    """``NAME`` or ``NAME:KEY=VALUE,KEY=VALUE`` as a :class:`Variant`.

    Raises
    ------
    ValueError
        For a malformed specification (no name, an item without ``=``, a repeated key, an
        ``overlap_frac`` that is not a fraction in (0, 1/2), or both ``overlap`` and
        ``overlap_frac``).
    """
    name, _, rest = text.partition(":")
    name = name.strip()
    if not name:
        raise ValueError(f"variant {text!r} has no name (NAME:KEY=VALUE,...)")
    options: dict[str, Any] = {}
    frac: Fraction | None = None
    for item in filter(None, (part.strip() for part in rest.split(","))):
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"variant {name!r}: {item!r} is not KEY=VALUE")
        if key in options or (key == "overlap_frac" and frac is not None):
            raise ValueError(f"variant {name!r}: {key!r} given twice")
        if key == "overlap_frac":
            try:
                frac = Fraction(raw.strip())
            except (ValueError, ZeroDivisionError):
                raise ValueError(
                    f"variant {name!r}: overlap_frac={raw!r} is not a number or a fraction a/b"
                ) from None
            if not 0 < frac < Fraction(1, 2):
                raise ValueError(f"variant {name!r}: overlap_frac={raw} is not in (0, 1/2)")
        else:
            options[key] = _value(raw)
    if frac is not None and "overlap" in options:
        raise ValueError(f"variant {name!r}: give overlap or overlap_frac, not both")
    return Variant(name, options, frac)


def check_names(variants: Sequence[Variant], function: Callable[..., Any]) -> None:
    """Refuse options ``function`` does not take, and those the benchmark sets itself.

    Raises
    ------
    ValueError
        Naming the variant, the option and what ``function`` takes.
    """
    kind = function.__name__
    accepted = set(inspect.signature(function).parameters) - RESERVED[kind]
    for variant in variants:
        for key in variant.options:
            if key in RESERVED[kind]:
                raise ValueError(
                    f"variant {variant.name!r}: {key!r} is set by the benchmark, not a variant"
                )
            if key not in accepted:
                raise ValueError(
                    f"variant {variant.name!r}: quilting.{kind} takes no option {key!r} "
                    f"(it takes overlap_frac and {', '.join(sorted(accepted))})"
                )
    names = [v.name for v in variants]
    if len(set(names)) != len(names):
        raise ValueError(f"variant names repeat: {', '.join(names)}")


# --- images and the project's own figures -----------------------------------------------------


def working(image: Image) -> NDArray[np.float64]:
    """An image as float64 (H, W, C) in [0, 1] (uint8 / uint16 scaled, floats as they are)."""
    view = image.reshape(image.shape[0], image.shape[1], -1)
    if view.dtype == np.uint8:
        return view.astype(np.float64) / 255.0
    if view.dtype == np.uint16:
        return view.astype(np.float64) / 65535.0
    return view.astype(np.float64)


def luminance(image: Image) -> NDArray[np.float64]:
    """Luminance (H, W) in [0, 1]: gray as it is, RGB(A) by Rec. 601 weights (alpha ignored)."""
    view = working(image)
    if view.shape[2] < 3:
        return np.ascontiguousarray(view[..., 0])
    luma: NDArray[np.float64] = (
        LUMA[0] * view[..., 0] + LUMA[1] * view[..., 1] + LUMA[2] * view[..., 2]
    )
    return luma


def rgb01(image: Image) -> NDArray[np.float32]:
    """What texeval compares: float32 RGB (H, W, 3) in [0, 1], gray repeated, alpha dropped."""
    view = working(image)
    if view.shape[2] < 3:
        view = np.repeat(view[..., :1], 3, axis=2)
    return np.ascontiguousarray(view[..., :3], dtype=np.float32)


def band_mask(grid: Grid, shape: tuple[int, int]) -> NDArray[np.bool_]:
    """Pixels of an output of ``shape`` (its canvas cropped) inside an overlap strip of ``grid``.

    Block (i, j) sits at (i * step, j * step); the strip it shares with its left neighbour is
    the columns ``j * step .. j * step + overlap - 1`` (j >= 1), with its upper neighbour the
    rows ``i * step .. i * step + overlap - 1`` (i >= 1). Across the wrap of a torus the last
    column (row) overlaps the first over the grid's wrap overlap. The strips run the whole
    height (width) of the canvas; every other pixel is in a block's core.
    """
    cols = np.zeros(grid.width, dtype=bool)
    rows = np.zeros(grid.height, dtype=bool)
    for j in range(1, grid.cols):
        cols[j * grid.step : j * grid.step + grid.overlap] = True
    for i in range(1, grid.rows):
        rows[i * grid.step : i * grid.step + grid.overlap] = True
    wrap_y, wrap_x = grid.wrap_overlap
    cols[:wrap_x] = True
    rows[:wrap_y] = True
    height, width = shape
    mask: NDArray[np.bool_] = rows[:height, None] | cols[None, :width]
    return mask


def band_core_ratio(image: Image, grid: Grid) -> float:
    """Gradient energy in the overlap bands over that in the block cores: 1 = seams invisible.

    The squared gradient of the luminance L by forward differences,
    ``g[y, x] = (L[y, x + 1] - L[y, x])**2 + (L[y + 1, x] - L[y, x])**2``, is averaged over the
    pixels whose stencil (the pixel, its right and its lower neighbour) touches an overlap
    strip of ``grid`` (the bands of :func:`band_mask`, where the seams run; a cut at the very
    edge of a strip makes a step between the strip and the pixel beside it, which so counts as
    band) and over the other pixels (the block cores); the figure is the first mean over the
    second. A seam adds gradient energy inside the bands, so it reads above 1; a blur along the
    seams reads below 1; a texture whose gradient does not depend on the position (a ramp, or
    noise) reads 1. An image with no gradient in its cores (flat) gives NaN.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        An output (uint8, uint16 or float in [0, 1]).
    grid : Grid
        The grid it was quilted on: ``result.layout.passes[-1].grid``.
    """
    lum = luminance(image)
    band = band_mask(grid, (lum.shape[0], lum.shape[1]))
    energy = np.diff(lum, axis=1)[:-1, :] ** 2 + np.diff(lum, axis=0)[:, :-1] ** 2
    touches = band[:-1, :-1] | band[:-1, 1:] | band[1:, :-1]
    band_energy, core_energy = energy[touches], energy[~touches]
    if len(band_energy) == 0 or len(core_energy) == 0 or not core_energy.any():
        return float("nan")
    return float(band_energy.mean() / core_energy.mean())


def edge_runs(layout_pass: LayoutPass, shortest: int = EDGE_RUN) -> float:
    """Share of the seams' length that runs straight along an overlap band's edge.

    A block's vertical seam is its ``cut_cols`` from the meeting point down (all rows without a
    top overlap), its horizontal seam its ``cut_rows`` from the meeting point right; a seam
    pixel is *on the edge* when the cut is at the band's first or last column (row), 0 or
    ``overlap - 1``. The figure is the number of seam pixels in runs of at least ``shortest``
    consecutive pixels on the same edge over all seam pixels: the dead-straight cuts that
    issue 20 part 2 wants gone (0 = none). Tileable wraps' far cuts are not counted.

    Parameters
    ----------
    layout_pass : LayoutPass
        ``result.layout.passes[-1]`` of a cut-mode result.
    shortest : int
        Shortest run counted.
    """
    grid = layout_pass.grid
    last = grid.overlap - 1
    total = straight = 0
    for i in range(grid.rows):
        for j in range(grid.cols):
            vertical = layout_pass.cut_cols[i, j].astype(np.intp)
            horizontal = layout_pass.cut_rows[i, j].astype(np.intp)
            seams = []
            if j > 0:
                seams.append(vertical[int(horizontal[0]) if i > 0 else 0 :])
            if i > 0:
                seams.append(horizontal[int(vertical[0]) if j > 0 else 0 :])
            for seam in seams:
                total += seam.size
                # Runs of equal values: where the value changes, a run ends.
                bounds = np.flatnonzero(np.diff(seam)) + 1
                for run in np.split(seam, bounds):
                    if run.size >= shortest and run[0] in (0, last):
                        straight += run.size
    return straight / total if total else float("nan")


def likeness(output: Image, target: Image) -> float:
    """Pearson r of the output's and the target's luminance, each Gaussian-blurred (sigma 2)."""
    a = ndimage.gaussian_filter(luminance(output), LIKENESS_SIGMA).ravel()
    b = ndimage.gaussian_filter(luminance(target), LIKENESS_SIGMA).ravel()
    return float(np.corrcoef(a, b)[0, 1])


def rule_block(texture: Image) -> int:
    """The issue's block size for a texture: ``max(16, min(48, side // 3))``."""
    side = int(min(texture.shape[0], texture.shape[1]))
    return max(16, min(48, side // 3))


# --- texeval ----------------------------------------------------------------------------------


def load_texeval(path: Path | None = TEXEVAL) -> ModuleType | None:
    """texeval from ``path`` (loaded by path), or None with a note when it is not there.

    texeval computes two global figures (``color_swd``, ``lbp_chi2``) with scikit-image; when
    that is missing they are replaced by NaN (none of them is reported here).
    """
    if path is None or not path.is_file():
        print(f"note: no texeval ({path or 'QUILTING_TEXEVAL unset'}): only the project's own "
              "figures", flush=True)  # fmt: skip
        return None
    spec = importlib.util.spec_from_file_location("texeval", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    if importlib.util.find_spec("skimage") is None:
        print("note: no scikit-image: texeval's color_swd and lbp_chi2 are NaN", flush=True)

        def unavailable(*args: Any, **kwargs: Any) -> float:
            return float("nan")

        setattr(module, "color_swd", unavailable)  # noqa: B010 (a module loaded by path)
        setattr(module, "lbp_chi2", unavailable)  # noqa: B010
    return module


def texeval_figures(texeval: ModuleType | None, source: Image, output: Image) -> dict[str, Any]:
    """texeval's figures of ``output`` against ``source`` (no PS statistics, no coarse scale)."""
    if texeval is None:
        return {}
    figures: dict[str, Any] = texeval.evaluate(
        rgb01(source), rgb01(output), use_ps=False, coarse=False
    )
    return figures


# --- textures ---------------------------------------------------------------------------------


def all_textures() -> dict[str, tuple[str, Callable[[], Image]]]:
    """Name -> (kind, loader) of every texture: the photos first, then the procedural ones."""
    found: dict[str, tuple[str, Callable[[], Image]]] = {}
    for name, path in quality_textures.photos().items():
        found[name] = ("photo", functools.partial(quilting.read_image, path))
    for name in quality_textures.procedural_names():
        found[name] = ("procedural", functools.partial(quality_textures.procedural, name))
    return found


def pick_textures(
    asked: str | None, default: Sequence[str] | None
) -> dict[str, tuple[str, Callable[[], Image]]]:
    """The textures named in ``asked`` (comma-separated), else ``default``, else all."""
    available = all_textures()
    names = asked.split(",") if asked else list(default or available)
    unknown = [n for n in names if n not in available]
    if unknown:
        raise ValueError(
            f"unknown texture(s) {', '.join(unknown)}; there are {', '.join(available)}"
        )
    return {n: available[n] for n in names}


# --- runs -------------------------------------------------------------------------------------


@dataclass
class Run:
    """One output: where it came from and every figure."""

    texture: str
    kind: str
    block_label: str
    block: int
    variant: str
    seed: int
    options: dict[str, Any]
    engine_s: float
    band_core: float
    figures: dict[str, Any]
    extra: dict[str, Any] = field(default_factory=dict)

    def figure(self, name: str) -> float | None:
        if name == "band/core":
            return self.band_core
        if name == "engine s":
            return self.engine_s
        value = self.figures.get(name, self.extra.get(name))
        if value is None or (isinstance(value, float) and math.isnan(value)):
            return None
        return float(value)


@contextlib.contextmanager
def _naming(variant: Variant) -> Iterator[None]:
    """Re-raise the engine's refusal of a variant's option as a ValueError naming the variant."""
    try:
        yield
    except (quilting.QuiltingError, TypeError) as exc:
        raise ValueError(
            f"variant {variant.name!r} ({variant.describe()}): {type(exc).__name__}: {exc}"
        ) from None


def dry_run(variants: Sequence[Variant], texture: Image, blocks: Sequence[int]) -> None:
    """Each variant once on a small output at every block size: refused values stop us here."""
    for variant in variants:
        for block in blocks:
            try:
                quilting.synthesize(
                    texture, (2 * block, 2 * block), block=block, seed=1, **variant.kwargs(block)
                )
            except (quilting.QuiltingError, TypeError, ValueError) as exc:
                raise ValueError(
                    f"variant {variant.name!r} ({variant.describe()}) at block {block}: "
                    f"{type(exc).__name__}: {exc}"
                ) from None


def synthesis_runs(
    textures: dict[str, tuple[str, Callable[[], Image]]],
    variants: Sequence[Variant],
    blocks: Sequence[str],
    size: int,
    seeds: Sequence[int],
    texeval: ModuleType | None,
    save: Path | None,
) -> list[Run]:
    """Every texture x block size x seed x variant, variants of one texture back to back."""
    runs: list[Run] = []
    for name, (kind, load) in textures.items():
        texture = load()
        sizes = {label: rule_block(texture) if label == "rule" else int(label) for label in blocks}
        dry_run(variants, texture, sorted(set(sizes.values())))
        for label, block in sizes.items():
            for seed in seeds:
                for variant in variants:
                    options = variant.kwargs(block)
                    with _naming(variant):
                        result = quilting.synthesize(
                            texture, (size, size), block=block, seed=seed, **options
                        )
                    grid = result.layout.passes[-1].grid
                    run = Run(
                        texture=name,
                        kind=kind,
                        block_label=label,
                        block=block,
                        variant=variant.name,
                        seed=seed,
                        options={**options, "overlap": grid.overlap},
                        engine_s=float(result.timings["total"]),
                        band_core=band_core_ratio(result.image, grid),
                        figures=texeval_figures(texeval, texture, result.image),
                        extra={"edge run": edge_runs(result.layout.passes[-1])},
                    )
                    runs.append(run)
                    if save is not None:
                        save.mkdir(parents=True, exist_ok=True)
                        quilting.write_image(
                            save / f"{name}_b{block}_s{seed}_{variant.name}.png", result.image
                        )
                    shown = " ".join(
                        f"{k}={_fmt(run.figure(k))}" for k in ("seam_grad", "coh_p95", "band/core")
                    )
                    print(
                        f"  {name:<11} block {block:2d} seed {seed} {variant.name:<10} "
                        f"{run.engine_s:6.3f} s  {shown}",
                        file=sys.stderr,
                        flush=True,
                    )
    return runs


def transfer_runs(
    textures: dict[str, tuple[str, Callable[[], Image]]],
    variants: Sequence[Variant],
    seeds: Sequence[int],
    texeval: ModuleType | None,
    save: Path | None,
) -> list[Run]:
    """Every texture x target x seed x variant; the plain synthesis of each once per options."""
    default_block = int(inspect.signature(quilting.transfer).parameters["block"].default)
    shared = set(inspect.signature(quilting.synthesize).parameters) - RESERVED["synthesize"]
    targets = {name: quilting.read_image(path) for name, path in TRANSFER_TARGETS.items()}
    runs: list[Run] = []
    plain: dict[str, tuple[float, float]] = {}
    for name, (kind, load) in textures.items():
        texture = load()
        for target_name, target in targets.items():
            for seed in seeds:
                for variant in variants:
                    block = int(variant.options.get("block", default_block))
                    options = variant.kwargs(block)
                    with _naming(variant):
                        result = quilting.transfer(texture, target, seed=seed, **options)
                    grid = result.layout.passes[-1].grid
                    figures = texeval_figures(texeval, texture, result.image)
                    synth_options = {k: v for k, v in options.items() if k in shared}
                    key = json.dumps(
                        [name, target.shape[:2], block, seed, synth_options],
                        sort_keys=True,
                        default=str,
                    )
                    if key not in plain:
                        synth = quilting.synthesize(
                            texture, target.shape[:2], block=block, seed=seed, **synth_options
                        )
                        hf = texeval_figures(texeval, texture, synth.image).get("hf_excess")
                        plain[key] = (
                            float("nan") if hf is None else float(hf),
                            float(synth.timings["total"]),
                        )
                    synth_hf, synth_s = plain[key]
                    transfer_hf = figures.get("hf_excess")
                    gap = None if transfer_hf is None else float(transfer_hf) - synth_hf
                    run = Run(
                        texture=name,
                        kind=kind,
                        block_label=target_name,
                        block=block,
                        variant=variant.name,
                        seed=seed,
                        options={**options, "overlap": result.layout.passes[0].grid.overlap},
                        engine_s=float(result.timings["total"]),
                        band_core=band_core_ratio(result.image, grid),
                        figures=figures,
                        extra={
                            "likeness": likeness(result.image, target),
                            "synth_hf_excess": synth_hf,
                            "hf_gap": gap,
                            "synth_engine_s": synth_s,
                            "last_block": grid.block,
                            "passes": len(result.layout.passes),
                        },
                    )
                    runs.append(run)
                    if save is not None:
                        save.mkdir(parents=True, exist_ok=True)
                        quilting.write_image(
                            save / f"{name}_{target_name}_s{seed}_{variant.name}.png", result.image
                        )
                    print(
                        f"  {name:<8} -> {target_name:<8} seed {seed} {variant.name:<10} "
                        f"{run.engine_s:6.3f} s  likeness {run.extra['likeness']:.3f}  "
                        f"hf {_fmt(transfer_hf)} vs {_fmt(synth_hf)}",
                        file=sys.stderr,
                        flush=True,
                    )
    return runs


# --- tables -----------------------------------------------------------------------------------


def _fmt(value: float | None, digits: int = 3) -> str:
    if value is None or math.isnan(value):
        return "n/a"
    return f"{value:.{digits}f}"


DIGITS = {"seam_excess": 4, "copy_mean": 4, "copy_max": 4}


def _mean(values: Sequence[float | None]) -> float | None:
    present = [v for v in values if v is not None and not math.isnan(v)]
    return statistics.fmean(present) if present else None


def per_texture(
    runs: Sequence[Run], baseline: str, columns: Sequence[str]
) -> dict[tuple[str, str, str], dict[str, float | None]]:
    """(block label, texture, variant) -> each column averaged over seeds, and ``time x``."""
    base = {(r.block_label, r.texture, r.seed): r.engine_s for r in runs if r.variant == baseline}
    cells: dict[tuple[str, str, str], list[Run]] = {}
    for r in runs:
        cells.setdefault((r.block_label, r.texture, r.variant), []).append(r)
    table: dict[tuple[str, str, str], dict[str, float | None]] = {}
    for key, group in cells.items():
        row = {c: _mean([r.figure(c) for r in group]) for c in columns}
        row["time x"] = _mean(
            [r.engine_s / base[(r.block_label, r.texture, r.seed)] for r in group]
        )
        table[key] = row
    return table


def summary_table(
    runs: Sequence[Run], variants: Sequence[Variant], label: str, columns: Sequence[str]
) -> tuple[list[str], list[list[str]], dict[str, dict[str, float | None]]]:
    """Rows = variants, each column the median over textures of the per-texture means."""
    cells = per_texture(runs, variants[0].name, columns)
    textures = sorted({t for (lab, t, _) in cells if lab == label})
    headers = ["variant", "options", *columns, "time x"]
    rows: list[list[str]] = []
    medians: dict[str, dict[str, float | None]] = {}
    for variant in variants:
        medians[variant.name] = {}
        row = [variant.name, variant.describe()]
        for column in [*columns, "time x"]:
            values = [
                cells[(label, t, variant.name)][column]
                for t in textures
                if (label, t, variant.name) in cells
            ]
            present = [v for v in values if v is not None]
            median = statistics.median(present) if present else None
            medians[variant.name][column] = median
            text = _fmt(median, DIGITS.get(column, 3 if column != "time x" else 2))
            if present and len(present) < len(textures):
                text += "*"
            row.append(text)
        rows.append(row)
    return headers, rows, medians


def per_texture_rows(
    runs: Sequence[Run], variants: Sequence[Variant], label: str, columns: Sequence[str]
) -> tuple[list[str], list[list[str]]]:
    cells = per_texture(runs, variants[0].name, columns)
    block = {(r.block_label, r.texture): (r.block, r.options.get("overlap")) for r in runs}
    textures = list(dict.fromkeys(r.texture for r in runs if r.block_label == label))
    headers = ["texture", "variant", "block", "overlap", *columns, "time x"]
    rows = []
    for t in textures:
        for variant in variants:
            row = cells.get((label, t, variant.name))
            if row is None:
                continue
            overlap = next(
                r.options.get("overlap")
                for r in runs
                if (r.block_label, r.texture, r.variant) == (label, t, variant.name)
            )
            rows.append(
                [
                    t,
                    variant.name,
                    str(block[(label, t)][0]),
                    str(overlap),
                    *(_fmt(row[c], DIGITS.get(c, 3)) for c in columns),
                    _fmt(row["time x"], 2),
                ]
            )
    return headers, rows


def transfer_tables(runs: Sequence[Run], variants: Sequence[Variant]) -> tuple[str, str]:
    """Every case, and a summary per variant."""
    columns = ["likeness", "hf_excess", "synth_hf_excess", "hf_gap", "band/core", "engine s"]
    cells = per_texture(runs, variants[0].name, columns)
    headers = ["texture", "target", "variant", "passes", "last block", *columns, "time x"]
    rows = []
    cases = list(dict.fromkeys((r.texture, r.block_label) for r in runs))
    meta = {(r.texture, r.block_label, r.variant): r.extra for r in runs}
    for texture, target in cases:
        for variant in variants:
            row = cells[(target, texture, variant.name)]
            extra = meta[(texture, target, variant.name)]
            rows.append(
                [
                    texture,
                    target,
                    variant.name,
                    str(extra["passes"]),
                    str(extra["last_block"]),
                    *(_fmt(row[c]) for c in columns),
                    _fmt(row["time x"], 2),
                ]
            )
    detail = benchtools.markdown(headers, rows, left=3)
    s_headers = [
        "variant",
        "options",
        "likeness median",
        "likeness min",
        "abs hf_gap median",
        "abs hf_gap max",
        "cases abs hf_gap <= 0.2",
        "band/core median",
        "time x median",
    ]
    s_rows = []
    for variant in variants:
        mine = [cells[(tg, tx, variant.name)] for tx, tg in cases]
        like = [c["likeness"] for c in mine if c["likeness"] is not None]
        gaps = [abs(c["hf_gap"]) for c in mine if c["hf_gap"] is not None]
        bands = [c["band/core"] for c in mine if c["band/core"] is not None]
        times = [c["time x"] for c in mine if c["time x"] is not None]
        s_rows.append(
            [
                variant.name,
                variant.describe(),
                _fmt(statistics.median(like) if like else None),
                _fmt(min(like) if like else None),
                _fmt(statistics.median(gaps) if gaps else None),
                _fmt(max(gaps) if gaps else None),
                f"{sum(g <= 0.2 for g in gaps)} / {len(mine)}" if gaps else "n/a",
                _fmt(statistics.median(bands) if bands else None),
                _fmt(statistics.median(times) if times else None, 2),
            ]
        )
    return detail, benchtools.markdown(s_headers, s_rows, left=2)


# --- the legacy tables ------------------------------------------------------------------------

LEGACY_TEXTURES = ("brick", "gravel", "hubble")


def legacy(size_px: int, n_seeds: int) -> None:
    """The two tables of this script before issue 20 (means over seeds 1..n_seeds)."""
    seeds = range(1, n_seeds + 1)
    size = (size_px, size_px)
    textures = {name: quilting.read_image(DATA / f"{name}.png") for name in LEGACY_TEXTURES}

    def mean(values: list[float]) -> float:
        return float(np.mean(values))

    print(f"output {size_px}x{size_px}, block 48, means over {n_seeds} seeds\n")
    print("mean seam error (squared difference per seam pixel, values in [0, 1])")
    print(f"{'texture':<8} {'random':>9} {'overlap':>9} {'cut':>9}  cut/random")
    for name, texture in textures.items():
        row = {
            mode: mean(
                [
                    quilting.synthesize(texture, size, mode=mode, seed=s).stats.seam_error_mean
                    for s in seeds
                ]
            )
            for mode in ("random", "overlap", "cut")
        }
        print(
            f"{name:<8} {row['random']:9.5f} {row['overlap']:9.5f} {row['cut']:9.5f}"
            f"  {row['cut'] / row['random']:9.3f}"
        )

    print("\nlargest verbatim copy (share of the texture) / mean seam error, by min_candidates")
    ks = (1, 2, 3, 5)
    print(f"{'texture':<8} " + " ".join(f"{'k=' + str(k):>17}" for k in ks))
    for name, texture in textures.items():
        cells = []
        for k in ks:
            stats = [
                quilting.synthesize(texture, size, min_candidates=k, seed=s).stats for s in seeds
            ]
            copy = mean([st.largest_copy for st in stats])
            seam = mean([st.seam_error_mean for st in stats])
            cells.append(f"{copy:7.3f} / {seam:7.5f}")
        print(f"{name:<8} " + " ".join(f"{c:>17}" for c in cells))


# --- main -------------------------------------------------------------------------------------


def _jsonable(value: Any) -> Any:
    if isinstance(value, float) and math.isnan(value):
        return None
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, Fraction):
        return str(value)
    return value


def main(argv: list[str] | None = None) -> int:
    parser = benchtools.parser(__doc__, json_help="write every figure here")
    parser.add_argument(
        "--variant",
        action="append",
        default=[],
        metavar="NAME:KEY=VALUE,...",
        help="a variant (repeat; the first is the baseline; default: cut:)",
    )
    parser.add_argument("--textures", help="comma-separated texture names (default: all)")
    parser.add_argument("--size", type=int, help="output side (default 512; --quick 256)")
    parser.add_argument(
        "--blocks",
        help=f"comma-separated block sizes, 'rule': the issue's rule (default rule,{SECOND_BLOCK})",
    )
    parser.add_argument("--seeds", type=int, help="seeds 1..N (default 1; --legacy 3)")
    parser.add_argument("--quick", action="store_true", help="3 textures, 256², the rule block")
    parser.add_argument("--per-texture", action="store_true", help="also every texture's table")
    parser.add_argument("--transfer", action="store_true", help="texture transfer instead")
    parser.add_argument(
        "--texeval",
        type=Path,
        default=TEXEVAL,
        metavar="PATH",
        help=f"texeval.py (default {TEXEVAL})",
    )
    parser.add_argument("--save", type=Path, metavar="DIR", help="write every output PNG here")
    parser.add_argument("--legacy", action="store_true", help="the two tables of before issue 20")
    args = parser.parse_args(argv)

    if args.legacy:
        legacy(args.size or 512, args.seeds or 3)
        return 0
    seeds = list(range(1, (args.seeds or 1) + 1))
    try:
        variants = [parse_variant(v) for v in args.variant] or [parse_variant("cut:")]
        check_names(variants, quilting.transfer if args.transfer else quilting.synthesize)
        default = TRANSFER_TEXTURES if args.transfer else QUICK_TEXTURES if args.quick else None
        blocks = (args.blocks or ("rule" if args.quick else f"rule,{SECOND_BLOCK}")).split(",")
        if not all(b == "rule" or (b.isdigit() and int(b) >= 3) for b in blocks):
            raise ValueError(f"--blocks {args.blocks}: each one 'rule' or a block size >= 3")
        textures = pick_textures(args.textures, default)
    except ValueError as exc:
        print(f"bench_quality: {exc}", file=sys.stderr)
        return 2

    started = time.perf_counter()
    info = benchtools.machine(
        quilting=quilting.__version__, numpy=np.__version__, scipy=scipy.__version__
    )
    benchtools.show_machine(info)
    print(f"date: {datetime.date.today().isoformat()}, commit {benchtools.source_tree(ROOT)}")
    print("command: bench_quality.py " + " ".join(argv if argv is not None else sys.argv[1:]))
    print("variants: " + "; ".join(f"{v.name} = {v.describe()}" for v in variants), flush=True)
    texeval = load_texeval(args.texeval)
    report: dict[str, Any] = {"machine": info, "variants": [v.__dict__ for v in variants]}

    try:
        if args.transfer:
            runs = transfer_runs(textures, variants, seeds, texeval, args.save)
            detail, summary = transfer_tables(runs, variants)
            print(
                f"\ntransfer onto {', '.join(TRANSFER_TARGETS)}, seeds {seeds[0]}..{seeds[-1]}; "
                "hf_gap = hf_excess(transfer) - hf_excess(plain synthesis at the target's size)"
            )
            print("\n" + detail + "\n\n" + summary)
        else:
            size = args.size or (256 if args.quick else 512)
            runs = synthesis_runs(textures, variants, blocks, size, seeds, texeval, args.save)
            columns = [*FIGURES, "band/core", "edge run", "engine s"]
            print(
                f"\nsynthesis {size}x{size}, {len(textures)} textures, seeds "
                f"{seeds[0]}..{seeds[-1]}; medians over textures; time x = engine time over "
                f"{variants[0].name}'s (same texture and seed)"
            )
            report["summary"] = {}
            for label in blocks:
                used = sorted({r.block for r in runs if r.block_label == label})
                title = "the issue's rule" if label == "rule" else label
                print(f"\nblock {title} ({', '.join(map(str, used))} px):\n")
                headers, rows, medians = summary_table(runs, variants, label, columns)
                report["summary"][label] = medians
                print(benchtools.markdown(headers, rows, left=2))
                if args.per_texture:
                    headers, rows = per_texture_rows(runs, variants, label, columns)
                    print("\n" + benchtools.markdown(headers, rows, left=2))
    except (quilting.QuiltingError, TypeError, ValueError) as exc:
        print(f"bench_quality: {exc}", file=sys.stderr)
        return 2

    elapsed = time.perf_counter() - started
    print(f"\n{len(runs)} runs in {elapsed:.0f} s; load average at the end {info_load()}")
    if args.json:
        report["runs"] = [r.__dict__ for r in runs]
        report["elapsed_s"] = elapsed
        args.json.write_text(json.dumps(_jsonable(report), indent=1, default=str) + "\n")
    return 0


def info_load() -> str:
    load = benchtools.machine()["loadavg"]
    return str(load)


if __name__ == "__main__":
    sys.exit(main())
