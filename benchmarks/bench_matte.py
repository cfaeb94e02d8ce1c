"""Benchmark of texture matting (alpha quilting and texture matting paper, §3): a 512x512
target with two layers, time and memory.

The target is a Lambertian sphere rendered with numpy: ``--size`` square (512 by default), gray
uint8, radius 0.45 of the side, albedo 0.8 plus ambient 0.05 (n . S clipped at 0), lit from
the upper left (towards the light (-1, 1, 1.2), x right, y up, z towards the viewer), on a
background of 0.08, its outline anti-aliased by the pixels' coverage; the silhouette is that
coverage. The layers are ``brick.png`` (256x256 gray, opaque) and ``cloud_rgba.png`` (192x192
RGBA, alpha quilting), from ``tests/data``. Every call: block 48, seed 0, the matting defaults
(8 clusters, smoothing 2, min_z 0.1, scale 1, ambient 0), backend ``fft`` (``--backend`` for
another). Cases:

* ``two layers``: brick under the cloud, normals and light from the target's shading: the
  issue's case;
* ``one layer``: brick alone;
* ``two layers, normals given``: the sphere's exact normal map passed as ``normals`` (no shape
  from shading: the light is still fitted, the surface still clustered);
* ``quilting two layers`` and ``quilting one layer``, the baselines: ``quilting.synthesize`` of
  the same layers at the layer size matting quilts them at (the silhouette's bounding box,
  tileable both ways, with the seeds matting derives for them), one call per layer.

For each case: the median and minimum wall time over ``--repeat`` timed runs after a warm-up
(the cases take turns, so a slow spell of the noisy machine hits them alike); for matting the
median of each stage of ``MatteResult.timings`` (``layers``: quilting the layers, ``surface``:
normals, light and clusters, ``lay``: sampling, shading and compositing), the wall median as a
ratio to the quilting baseline of the same layers and the difference (what matting costs
beyond quilting its layers); the tracemalloc peak of one more call (numpy reports its
allocations); and for matting the mean angle between the normals used and the sphere's exact
normals over the silhouette, and between the light used and the true one.

Run from the repository root::

    .venv/bin/python benchmarks/bench_matte.py             # 5 runs per case
    .venv/bin/python benchmarks/bench_matte.py --repeat 2  # quicker
    .venv/bin/python benchmarks/bench_matte.py --backend gl  # on a GPU
"""

from __future__ import annotations

import statistics
import time
import tracemalloc
from collections.abc import Callable
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

import benchtools
import numpy as np
from numpy.typing import NDArray

import quilting

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
BLOCK = 48
SEED = 0
#: Towards the light: upper left, in front (x right, y up, z towards the viewer).
LIGHT = (-1.0, 1.0, 1.2)
ALBEDO = 0.8
AMBIENT = 0.05
BACKGROUND = 0.08


@dataclass(frozen=True)
class Scene:
    """The rendered target and what matting should find in it.

    Attributes
    ----------
    target : ndarray, shape (N, N), uint8
        The shaded sphere on its background.
    silhouette : ndarray, shape (N, N), uint8
        Coverage of the sphere (255 inside, partial at the outline, 0 outside).
    normals : ndarray, shape (N, N, 3), float32
        The exact unit normals, (0, 0, 1) outside.
    inside : ndarray, shape (N, N), bool
        Pixels at least half covered (where matting reads the surface).
    light : ndarray, shape (3,), float64
        Unit direction towards the light.
    """

    target: NDArray[np.uint8]
    silhouette: NDArray[np.uint8]
    normals: NDArray[np.float32]
    inside: NDArray[np.bool_]
    light: NDArray[np.float64]


def render_sphere(size: int) -> Scene:
    """A Lambertian sphere of radius ``0.45 size`` in a ``size`` x ``size`` image.

    Parameters
    ----------
    size : int
        Side of the image in pixels.

    Returns
    -------
    Scene
    """
    radius = 0.45 * size
    centre = size / 2
    grid = (np.arange(size) + 0.5 - centre) / radius
    x = grid[None, :]
    y = -grid[:, None]  # y up
    distance = np.sqrt(x**2 + y**2)
    cover = np.clip((1.0 - distance) * radius + 0.5, 0.0, 1.0)
    # Outline pixels take the normal of the nearest point just inside the rim.
    scale = np.minimum(1.0, 0.999 / np.maximum(distance, 1e-12))
    nx, ny = x * scale, y * scale
    normals = np.stack(np.broadcast_arrays(nx, ny, np.sqrt(1.0 - nx**2 - ny**2)), axis=-1)
    light = np.asarray(LIGHT) / np.linalg.norm(LIGHT)
    shade = ALBEDO * np.clip(normals @ light, 0.0, None) + AMBIENT
    value = cover * shade + (1.0 - cover) * BACKGROUND
    normals[cover == 0] = (0.0, 0.0, 1.0)
    return Scene(
        target=np.rint(value * 255).astype(np.uint8),
        silhouette=np.rint(cover * 255).astype(np.uint8),
        normals=normals.astype(np.float32),
        inside=cover >= 0.5,
        light=light,
    )


def angle_deg(a: NDArray[np.floating], b: NDArray[np.floating]) -> NDArray[np.float64]:
    """Angles in degrees between unit vectors along the last axis."""
    cosine = np.clip((np.asarray(a, np.float64) * b).sum(axis=-1), -1.0, 1.0)
    degrees: NDArray[np.float64] = np.degrees(np.arccos(cosine))
    return degrees


def layer_seeds(count: int) -> list[int]:
    """The seeds matting quilts its layers with (layer k: ``SeedSequence([seed, k])``)."""
    return [
        int(np.random.SeedSequence([SEED, k]).generate_state(1, np.uint64)[0]) for k in range(count)
    ]


def quilt_layers(
    layers: list[NDArray[np.generic]], size: tuple[int, int], backend: str
) -> list[quilting.Result]:
    """The baseline: each layer quilted as matting does it, tileable, at the layer size.

    Parameters
    ----------
    layers : list of ndarray
        The layer textures, bottom first.
    size : (int, int)
        The layer size (height, width) matting uses.
    backend : str
        Cost backend.

    Returns
    -------
    list of quilting.Result
    """
    return [
        quilting.synthesize(layer, size, block=BLOCK, seed=seed, backend=backend, tileable="both")
        for layer, seed in zip(layers, layer_seeds(len(layers)), strict=True)
    ]


def main() -> None:
    """Time the cases, then print the machine and the table."""
    args = benchtools.engine_parser(__doc__).parse_args()
    scene = render_sphere(args.size)
    brick = quilting.read_image(DATA / "brick.png")
    cloud = quilting.read_image(DATA / "cloud_rgba.png")
    two, one = [brick, cloud], [brick]

    def matting(layers: list[NDArray[np.generic]], given: bool) -> quilting.MatteResult:
        return quilting.matte(
            scene.target,
            layers,
            silhouette=scene.silhouette,
            normals=scene.normals if given else None,
            block=BLOCK,
            seed=SEED,
            backend=args.backend,
        )

    probe = matting(two, False)
    size = (probe.layers[0].image.shape[0], probe.layers[0].image.shape[1])
    same = all(
        np.array_equal(mine.image, theirs.image)
        for mine, theirs in zip(quilt_layers(two, size, args.backend), probe.layers, strict=True)
    )
    matte_cases: dict[str, Callable[[], quilting.MatteResult]] = {
        "two layers": lambda: matting(two, False),
        "one layer": lambda: matting(one, False),
        "two layers, normals given": lambda: matting(two, True),
    }
    baselines: dict[str, Callable[[], list[quilting.Result]]] = {
        "quilting two layers": lambda: quilt_layers(two, size, args.backend),
        "quilting one layer": lambda: quilt_layers(one, size, args.backend),
    }
    base_of = {
        "two layers": "quilting two layers",
        "one layer": "quilting one layer",
        "two layers, normals given": "quilting two layers",
    }
    cases: dict[str, Callable[[], object]] = {**matte_cases, **baselines}

    print(benchtools.machine(numpy=np.__version__, scipy=metadata.version("scipy")))
    print(
        f"{args.size}x{args.size} gray Lambertian sphere (radius {0.45 * args.size:g}), layers "
        f"brick 256x256 gray + cloud_rgba 192x192 RGBA quilted at {size[1]}x{size[0]} "
        f"(tileable), block {BLOCK}, seed {SEED}, {args.backend}"
    )
    print(f"baseline layers identical to matting's: {'yes' if same else 'no'}")

    times: dict[str, list[float]] = {name: [] for name in cases}
    stages: dict[str, dict[str, list[float]]] = {
        name: {"layers": [], "surface": [], "lay": []} for name in matte_cases
    }
    for call in cases.values():
        call()  # warm-up
    for _ in range(args.repeat):
        for name, call in cases.items():
            start = time.perf_counter()
            result = call()
            times[name].append(time.perf_counter() - start)
            if isinstance(result, quilting.MatteResult):
                for stage, spent in stages[name].items():
                    spent.append(result.timings[stage])

    rows = []
    for name, call in cases.items():
        tracemalloc.start()
        result = call()
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        median = statistics.median(times[name])
        row = [name, str(len(times[name])), f"{median:.3f}", f"{min(times[name]):.3f}"]
        if isinstance(result, quilting.MatteResult):
            base = statistics.median(times[base_of[name]])
            split = [f"{statistics.median(stages[name][s]):.3f}" for s in stages[name]]
            error = angle_deg(result.normals[scene.inside], scene.normals[scene.inside])
            light = float(angle_deg(np.asarray(result.light), scene.light))
            row += [f"{median / base:.2f}", f"{median - base:+.3f}", *split]
            row += [f"{peak / 2**20:.1f}", f"{error.mean():.1f}", f"{light:.1f}"]
        else:
            row += ["1.00", "-", "-", "-", "-", f"{peak / 2**20:.1f}", "-", "-"]
        rows.append(row)
    headers = ["case", "runs", "median s", "min s", "vs quilting", "beyond s"]
    headers += ["layers s", "surface s", "lay s", "traced MiB", "normals deg", "light deg"]
    print(benchtools.table(headers, rows))


if __name__ == "__main__":
    main()
